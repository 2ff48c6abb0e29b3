"""Circle-plate detection: images of calibration plates to identified circle centres.

Stage 1 (Shih et al. sec. 3): each stereo image shows the head's two nine-circle plates; stage 2
(sec. 5): a head camera's image shows the 25-disk target. For each image we

1. find the circles as blobs (Otsu threshold, connected components, shape filter) and measure
   each centre to sub-pixel accuracy as the centroid of the local grey-level contrast (the
   centroid of the blob's coverage, i.e. the centre of its image ellipse);
2. undistort the centres to ideal pinhole pixels and group them into plates (single-linkage
   clustering at a distance set by the circles' own size);
3. identify which blob is which circle: the plate's outline corners (convex hull) are matched in
   every cyclic order that keeps the printed face towards the camera, a homography predicts all
   circles, and the enlarged *marker* circle (see ``targets.PlateDesign``) must land where the
   layout puts it. This is invariant to in-plane rotation and tells the two plates apart; a
   pattern that stays ambiguous is reported, never guessed.

The poses of the plates follow from these centres in
:mod:`cpc2urdf.identification.vision.plate_poses` (stereo triangulation and registration, PnP).

Failures are values, not crashes: :func:`detect_plates` returns, per plate, either a
:class:`PlateMatch` or a :class:`DetectionError` that names the image, the plate and the reason,
so the caller can skip the record or stop.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import linear_sum_assignment

from cpc2urdf.errors import Cpc2UrdfError
from cpc2urdf.identification.vision.targets import PlateDesign

Array = NDArray[np.float64]

MIN_CONTRAST = 20.0  # [grey levels] an image whose (5x5-blurred) range is smaller is blank
MIN_BLOB_RADIUS = 2.0  # [px] smaller blobs are noise
FILL_RANGE = (0.75, 1.25)  # blob pixel area / area of its moment ellipse
MIN_AXIS_RATIO = 0.2  # [-] minor/major axis of a circle's image (plates tilted < ~78 deg)
WINDOW_MARGIN = 3  # [px] the centroid window extends this far beyond the thresholded blob
LINK_FACTOR = 1.6  # clustering links blobs closer than this x (pitch / radius) x blob radius
MATCH_TOL = 0.25  # [-] max homography residual / smallest projected circle spacing
MARKER_TOL = 0.35  # [-] max |log(area / predicted area)| of any circle for an accepted match
_AMBIGUOUS = "circle orderings fit equally"
_UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-12)


class DetectionError(Cpc2UrdfError):
    """A plate (or target) could not be measured in an image.

    Attributes:
        image: The image (file name or label).
        plate: The plate's frame name.
        reason: Why, in words.
    """

    def __init__(self, image: str, plate: str, reason: str) -> None:
        self.image = image
        self.plate = plate
        self.reason = reason
        super().__init__(f"{image}: {plate}: {reason}")


class PlateNotFoundError(DetectionError):
    """No group of circles in the image matches the plate (missing, cut off, blank image)."""


class PlateAmbiguousError(DetectionError):
    """Several groups or several orderings fit the plate equally well."""


class InconsistentDetectionError(DetectionError):
    """The plate was found in both images but the measurements disagree (wrong rig file?)."""


# ---- blobs ----------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Blob:
    """One candidate circle image.

    Attributes:
        uv: Sub-pixel centre (grey-level centroid) in the raw image [px], shape (2,).
        area: Coverage area [px^2] (contrast-weighted, so anti-aliased edges count partly).
        radius: Equivalent radius ``sqrt(area / pi)`` [px].
        touches_border: The blob's window reaches the image border (it may be cut off).
    """

    uv: Array
    area: float
    radius: float
    touches_border: bool


def image_contrast(image: NDArray[np.uint8]) -> float:
    """Grey-level range of the image after a 5x5 box blur (which removes most pixel noise)."""
    b = cv2.blur(image, (5, 5))
    return float(int(b.max()) - int(b.min()))


def find_blobs(image: ArrayLike, *, dark: bool) -> list[Blob]:
    """Find roughly elliptical blobs darker (``dark=True``) or lighter than their surroundings.

    Args:
        image: Grey image, shape (h, w), uint8.
        dark: Polarity of the circles.

    Returns:
        The blobs, with sub-pixel centres in raw (distorted) pixel coordinates.
    """
    img = np.asarray(image)
    h, w = img.shape
    imgf = img.astype(float)
    _, mask = cv2.threshold(
        img, 0, 255, (cv2.THRESH_BINARY_INV if dark else cv2.THRESH_BINARY) | cv2.THRESH_OTSU
    )
    n, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    if n <= 1:
        return []
    # Nearest foreground component of every pixel: a blob's window never takes pixels that are
    # closer to another component (a neighbouring circle, the background around the plate).
    inv = np.where(mask > 0, 0, 255).astype(np.uint8)
    _, voronoi = cv2.distanceTransformWithLabels(
        inv, cv2.DIST_L2, 5, labelType=cv2.DIST_LABEL_CCOMP
    )
    area_px = stats[1:, cv2.CC_STAT_AREA]
    max_area = 0.05 * h * w
    candidates = (
        np.flatnonzero((area_px >= math.pi * MIN_BLOB_RADIUS**2) & (area_px <= max_area)) + 1
    )
    kernel_in = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * WINDOW_MARGIN + 1,) * 2)
    kernel_out = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * WINDOW_MARGIN + 5,) * 2)
    pad = WINDOW_MARGIN + 3
    sign = 1.0 if dark else -1.0
    blobs: list[Blob] = []
    for lab in candidates:
        x, y, bw, bh, area = stats[lab]
        x0, y0 = max(x - pad, 0), max(y - pad, 0)
        x1, y1 = min(x + bw + pad, w), min(y + bh + pad, h)
        own = (labels[y0:y1, x0:x1] == lab).astype(np.uint8)
        m = cv2.moments(own, binaryImage=True)
        mu20, mu02, mu11 = m["mu20"] / m["m00"], m["mu02"] / m["m00"], m["mu11"] / m["m00"]
        tr, det = mu20 + mu02, mu20 * mu02 - mu11 * mu11
        disc = math.sqrt(max(tr * tr / 4 - det, 0.0))
        l1, l2 = tr / 2 + disc, max(tr / 2 - disc, 0.0)
        a, b = 2 * math.sqrt(l1), 2 * math.sqrt(l2)
        if a <= 0 or b / a < MIN_AXIS_RATIO:
            continue
        fill = area / (math.pi * a * b) if b > 0 else 0.0
        if not FILL_RANGE[0] <= fill <= FILL_RANGE[1]:
            continue
        # The Voronoi label of this blob: read it at one of its own pixels.
        iy, ix = np.argwhere(own)[0]
        cell = voronoi[y0:y1, x0:x1] == voronoi[y0 + iy, x0 + ix]
        others = (labels[y0:y1, x0:x1] != 0) & (own == 0)
        win = (cv2.dilate(own, kernel_in) > 0) & cell & ~others
        ring = (
            (cv2.dilate(own, kernel_out) > 0) & ~(cv2.dilate(own, kernel_in) > 0) & cell & ~others
        )
        patch = imgf[y0:y1, x0:x1]
        if ring.sum() < 8:
            continue
        bg = float(np.median(patch[ring]))
        inner = cv2.erode(own, np.ones((3, 3), np.uint8)) > 0
        fg = float(np.median(patch[inner])) if inner.any() else float(patch[own > 0].mean())
        contrast = sign * (bg - fg)
        if contrast <= 0:
            continue
        wts = sign * (bg - patch) * win
        s = wts.sum()
        if s <= 0:
            continue
        vv, uu = np.mgrid[y0:y1, x0:x1]
        uv = np.array([(wts * uu).sum() / s, (wts * vv).sum() / s])
        cov_area = float(s / contrast)
        touches = x0 == 0 or y0 == 0 or x1 == w or y1 == h
        blobs.append(Blob(uv, cov_area, math.sqrt(max(cov_area, 0.0) / math.pi), touches))
    return blobs


def undistort_to_pixels(uv: ArrayLike, K: ArrayLike, D: ArrayLike) -> Array:
    """Raw pixels -> ideal (distortion-free) pixels of the same camera matrix, shape (N, 2)."""
    pts = np.ascontiguousarray(np.asarray(uv, dtype=np.float64).reshape(-1, 1, 2))
    if pts.shape[0] == 0:
        return np.zeros((0, 2))
    Km = np.asarray(K, dtype=float)
    Dm = np.asarray(D, dtype=float).ravel()
    if not np.any(Dm):
        return pts.reshape(-1, 2).copy()
    out = cv2.undistortPointsIter(pts, Km, Dm, None, Km, _UNDISTORT_CRITERIA)  # type: ignore[call-overload]
    return np.asarray(out, dtype=float).reshape(-1, 2)


# ---- grouping and identification -----------------------------------------------------------------


def _clusters(uv: Array, radius: Array, link_ratio: float) -> list[list[int]]:
    """Single-linkage clusters: i~j when |uv_i - uv_j| < link_ratio * min(r_i, r_j)."""
    n = uv.shape[0]
    if n == 0:
        return []
    d = np.linalg.norm(uv[:, None] - uv[None], axis=-1)
    link = d < link_ratio * np.minimum(radius[:, None], radius[None])
    parent = list(range(n))

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for i, j in zip(*np.nonzero(np.triu(link, 1)), strict=True):
        parent[find(int(i))] = find(int(j))
    groups: dict[int, list[int]] = {}
    for i in range(n):
        groups.setdefault(find(i), []).append(i)
    return sorted(groups.values(), key=lambda g: -len(g))


def _split(uv: Array, group: list[int], k: int, size: int) -> list[list[int]]:
    """Candidate plates in a group of points that holds ``k`` touching plates of ``size`` circles:
    k-means centres (seeded, so reproducible), each with the ``size`` points nearest to it.
    Candidates may overlap; identification decides which fit."""
    from scipy.cluster.vq import kmeans2

    g = np.array(group)
    pts = uv[g]
    centres, _ = kmeans2(pts, k, minit="++", seed=0)
    out = []
    for c in centres:
        near = np.argsort(np.linalg.norm(pts - c, axis=1))[:size]
        out.append(sorted(g[near].tolist()))
    return out


def _strict_hull(pts: Array, min_turn_deg: float = 12.0) -> list[int]:
    """Indices of the convex-hull corners of ``pts`` (N, 2), dropping near-collinear ones."""
    hull: list[int] = [
        int(i) for i in cv2.convexHull(pts.astype(np.float32), returnPoints=False).ravel()
    ]
    changed = True
    while changed and len(hull) > 3:
        changed = False
        for k in range(len(hull)):
            a, b, c = pts[hull[k - 1]], pts[hull[k]], pts[hull[(k + 1) % len(hull)]]
            u, v = b - a, c - b
            cosang = float(u @ v / (np.linalg.norm(u) * np.linalg.norm(v) + 1e-300))
            if math.degrees(math.acos(min(1.0, max(-1.0, cosang)))) < min_turn_deg:
                del hull[k]
                changed = True
                break
    return hull


def _apply_h(H: Array, xy: Array) -> Array:
    p = np.concatenate([xy, np.ones((xy.shape[0], 1))], axis=1) @ H.T
    return p[:, :2] / p[:, 2:3]


def _jacobian_det(H: Array, xy: Array) -> Array:
    """det d(u, v)/d(x, y) of the homography at plate points (N, 2)."""
    w = xy @ H[2, :2] + H[2, 2]
    # For a projective map, det J = det(H) / w^3.
    return np.linalg.det(H) / w**3


@dataclass
class PlateMatch:
    """A plate identified in one image.

    Attributes:
        plate: Frame name.
        uv: Raw circle centres in layout order [px], shape (K, 2).
        uv_ideal: The same, undistorted to ideal pinhole pixels, shape (K, 2).
        H: Homography plate (x, y) [m] -> ideal pixels, shape (3, 3).
        rms_px: RMS homography residual [px].
        size_score: Largest |log(area / predicted area)| over the circles [-].
    """

    plate: str
    uv: Array
    uv_ideal: Array
    H: Array
    rms_px: float
    size_score: float


def _match_design(
    design: PlateDesign, uv_ideal: Array, area: Array
) -> tuple[list[tuple[float, Array, Array, float]], str]:
    """Every ordering of the detected points that fits the design: (size score, perm, H, rms)."""
    L = design.layout[:, :2]
    iL = _strict_hull(L)
    iD = _strict_hull(uv_ideal)
    m = len(iL)
    if m < 4:
        return [], f"the layout's outline has {m} corners; identification needs at least 4"
    if len(iD) != m:
        return [], f"the circles' outline has {len(iD)} corners, the plate's has {m}"
    fits: list[tuple[float, Array, Array, float]] = []
    worst = math.inf
    for d in (1, -1):
        for s in range(m):
            dst = uv_ideal[[iD[(s + d * i) % m] for i in range(m)]]
            H0, _ = cv2.findHomography(L[iL], dst, 0)
            if H0 is None:
                continue
            pred = _apply_h(np.asarray(H0, dtype=float), L)
            cost = np.linalg.norm(pred[:, None] - uv_ideal[None], axis=-1)
            rows, cols = linear_sum_assignment(cost)
            perm = cols[np.argsort(rows)]
            H_, _ = cv2.findHomography(L, uv_ideal[perm], 0)
            if H_ is None:
                continue
            H = np.asarray(H_, dtype=float)
            pred = _apply_h(H, L)
            res = np.linalg.norm(pred - uv_ideal[perm], axis=1)
            dp = np.linalg.norm(pred[:, None] - pred[None], axis=-1)
            spacing = float(np.min(dp[dp > 0]))
            worst = min(worst, float(res.max()) / spacing)
            if res.max() > MATCH_TOL * spacing:
                continue
            if np.any(_jacobian_det(H, L) >= 0):
                continue  # mirrored: the printed face would point away from the camera
            pred_area = math.pi * design.radii**2 * np.abs(_jacobian_det(H, L))
            logr = np.log(np.maximum(area[perm], 1e-9) / pred_area)
            score = float(np.max(np.abs(logr - np.median(logr))))
            fits.append((score, perm, H, float(np.sqrt(np.mean(res**2)))))
    if not fits:
        why = "no ordering of the circles fits the layout"
        if math.isfinite(worst):
            why += f" (best residual {worst:.2f} x circle spacing)"
        return [], why
    return fits, ""


def _unique(
    fits: list[tuple[float, Array, Array, float]],
) -> tuple[tuple[float, Array, Array, float] | None, int]:
    ok = [f for f in fits if f[0] <= MARKER_TOL]
    distinct = {tuple(f[1].tolist()) for f in ok}
    if len(distinct) == 1:
        return ok[0], 1
    return None, len(distinct)


def detect_plates(
    image: ArrayLike,
    K: ArrayLike,
    D: ArrayLike,
    designs: Sequence[PlateDesign],
    *,
    image_name: str = "image",
) -> dict[str, PlateMatch | DetectionError]:
    """Find and identify each plate of ``designs`` in one image.

    Args:
        image: Grey image, shape (h, w), uint8 (colour images: convert first).
        K: Camera matrix [px], shape (3, 3).
        D: Distortion coefficients, shape (n,).
        designs: The plates that may be visible.
        image_name: Used in error messages.

    Returns:
        For every design name, a :class:`PlateMatch` or the :class:`DetectionError` saying why not.
    """
    img = np.asarray(image)
    out: dict[str, PlateMatch | DetectionError] = {}
    if img.ndim != 2 or img.dtype != np.uint8:
        for d in designs:
            out[d.name] = PlateNotFoundError(
                image_name, d.name, f"expected an 8-bit grey image, got {img.dtype} {img.shape}"
            )
        return out
    contrast = image_contrast(img)
    if contrast < MIN_CONTRAST:
        for d in designs:
            out[d.name] = PlateNotFoundError(
                image_name,
                d.name,
                f"blank image (grey-level range {contrast:.0f} < {MIN_CONTRAST:.0f})",
            )
        return out
    Km = np.asarray(K, dtype=float)
    Dm = np.asarray(D, dtype=float)
    candidates: dict[str, list[tuple[PlateMatch, float]]] = {d.name: [] for d in designs}
    notes: dict[str, list[str]] = {d.name: [] for d in designs}
    ambiguous: set[str] = set()
    for dark in sorted({d.dark_dots for d in designs}):
        group_designs = [d for d in designs if d.dark_dots == dark]
        blobs = find_blobs(img, dark=dark)
        if not blobs:
            for d in group_designs:
                notes[d.name].append("no circles found")
            continue
        uv = np.array([b.uv for b in blobs])
        rad = np.array([b.radius for b in blobs])
        area = np.array([b.area for b in blobs])
        border = np.array([b.touches_border for b in blobs])
        ideal = undistort_to_pixels(uv, Km, Dm)
        ratio = max(_pitch(d) / float(np.min(d.radii)) for d in group_designs)
        n_needed = {d.n_circles for d in group_designs}
        clusters = _clusters(ideal, rad, LINK_FACTOR * ratio)
        groups: list[list[int]] = []
        for grp in clusters:
            groups.append(grp)
            # Plates that touch in the image form one group: also try it split into plates.
            for n in sorted(n_needed):
                k = int(round(len(grp) / n))
                if len(grp) > n and k >= 2:
                    groups.extend(_split(ideal, grp, k, n))
        groups = [list(t) for t in dict.fromkeys(tuple(sorted(g)) for g in groups)]  # no duplicates
        # Notes per (plate, group): a group that turns out to be another plate is no news.
        group_notes: dict[str, list[tuple[frozenset[int], str]]] = {
            d.name: [] for d in group_designs
        }
        claimed: dict[frozenset[int], str] = {}
        for grp in groups:
            g = np.array(grp)
            key = frozenset(grp)
            for d in group_designs:
                if len(g) != d.n_circles:
                    continue
                fits, why = _match_design(d, ideal[g], area[g])
                best, n_ok = _unique(fits)
                at = f"group of {len(g)} circles near ({uv[g, 0].mean():.0f}, {uv[g, 1].mean():.0f}) px"
                if best is None:
                    if n_ok > 1:
                        group_notes[d.name].append(
                            (key, f"{at}: {n_ok} {_AMBIGUOUS} (marker circle not distinguishable)")
                        )
                    elif why:
                        group_notes[d.name].append((key, f"{at}: {why}"))
                    elif fits:
                        group_notes[d.name].append(
                            (
                                key,
                                f"{at}: circle sizes do not match the plate's marker (score {min(f[0] for f in fits):.2f})",
                            )
                        )
                    continue
                score, perm, H, rms = best
                idx = g[perm]
                if border[idx].any():
                    group_notes[d.name].append((key, f"{at}: a circle touches the image border"))
                    continue
                claimed[key] = d.name
                candidates[d.name].append(
                    (PlateMatch(d.name, uv[idx], ideal[idx], H, rms, score), score)
                )
        sizes = [len(c) for c in clusters]
        for d in group_designs:
            if candidates[d.name]:
                continue
            notes[d.name] += [t for k, t in group_notes[d.name] if not any(k & c for c in claimed)]
            if any(_AMBIGUOUS in t for t in notes[d.name]):
                ambiguous.add(d.name)
            if not notes[d.name]:
                partial = [s for s in sizes if 3 <= s < d.n_circles]
                others = sorted(set(claimed.values()))
                if partial:
                    notes[d.name].append(
                        f"found groups of {partial} circles, fewer than {d.n_circles} (plate partly outside the image or occluded?)"
                    )
                elif others:
                    notes[d.name].append(
                        f"not in the image (the circles found are {', '.join(others)})"
                    )
                else:
                    notes[d.name].append(
                        f"no group of {d.n_circles} circles (groups found: {sizes or 'none'})"
                    )
    for d in designs:
        c = candidates[d.name]
        if len(c) == 1:
            out[d.name] = c[0][0]
        elif len(c) > 1:
            out[d.name] = PlateAmbiguousError(
                image_name, d.name, f"{len(c)} groups of circles match this plate"
            )
        else:
            kind = PlateAmbiguousError if d.name in ambiguous else PlateNotFoundError
            out[d.name] = kind(
                image_name, d.name, "; ".join(dict.fromkeys(notes[d.name])) or "not found"
            )
    return out


def _pitch(d: PlateDesign) -> float:
    L = d.layout[:, :2]
    dist = np.linalg.norm(L[:, None] - L[None], axis=-1)
    return float(np.min(dist[dist > 0]))


__all__ = [
    "Blob",
    "DetectionError",
    "InconsistentDetectionError",
    "PlateAmbiguousError",
    "PlateMatch",
    "PlateNotFoundError",
    "detect_plates",
    "find_blobs",
    "image_contrast",
    "undistort_to_pixels",
]
