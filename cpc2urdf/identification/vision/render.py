"""Synthetic camera images of calibration plates, so the detector runs on real pixels.

The renderer draws planar targets -- standard boards (:func:`render_board_view`: chessboard,
ChArUco, circle grids, :mod:`~cpc2urdf.identification.vision.boards.board`), the stage-1 end-effector plates (dark circles on a light
plate, Shih et al. sec. 3.2, Fig. 7) and the stage-2 disk target (light disks on a black plate,
sec. 5, Fig. 9) -- into a grey-level image of a pinhole camera with OpenCV's lens distortion
model. It works backwards from pixels to the plate plane: every pixel (or sub-pixel sample) is
undistorted (``cv2.undistortPointsIter``), cast as a ray, intersected with the plate plane and
classified (outside the plate, on the plate, inside a circle). Pixels whose footprint touches an
edge (circle or plate outline) are supersampled ``supersample x supersample`` times, so the grey
level is the area coverage of the projected shape (anti-aliasing), and the intensity centroid of
a rendered circle is the centroid of its true image ellipse to a few thousandths of a pixel
(``tests/test_render.py`` measures it). Optional Gaussian blur (optics), Gaussian grey-level noise
(sensor) and 8-bit quantisation follow.

Plates are opaque and one-sided: the circles are printed on the face whose normal is the plate's
+z axis; a plate seen from behind is drawn as a blank grey back. Plates occlude each other in
depth order (painter's algorithm by the depth of their origins).

The targets themselves (:class:`~cpc2urdf.identification.vision.targets.PlateDesign`, the
IIS-head plates and the stage-2 disk target) are defined in
:mod:`cpc2urdf.identification.vision.targets`.

Frames: ``T_camera_world`` maps world points into the camera's REP-103 optical frame (z forward,
x right, y down), as OpenCV's ``rvec, tvec``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TypeVar

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from cpc2urdf.identification.vision.boards.board import Board
from cpc2urdf.identification.vision.targets import PlateDesign

_T = TypeVar("_T", PlateDesign, Board)

Array = NDArray[np.float64]

BACKGROUND_LEVEL = 0.25  # [-] grey level of the scene behind the plates (0 black .. 1 white)
PLATE_BACK_LEVEL = 0.5  # [-] grey level of a plate seen from behind
NEAR_CLIP = 0.02  # [m] plates closer to (or behind) a camera than this are not drawn
_UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-12)


@dataclass(frozen=True)
class PinholeView:
    """One camera: intrinsics, distortion, image size and pose.

    Attributes:
        K: Camera matrix [px], shape (3, 3).
        D: OpenCV distortion coefficients (k1, k2, p1, p2[, k3, ...]), shape (n,); may be empty.
        image_size: (width, height) [px].
        T_camera_world: World -> camera optical frame, shape (4, 4).
    """

    K: Array
    D: Array
    image_size: tuple[int, int]
    T_camera_world: Array = field(default_factory=lambda: np.eye(4))

    def project(self, p_world: ArrayLike) -> Array:
        """Pixel coordinates (with distortion) of world points, shape (N, 2); points [m] (N, 3)."""
        p = np.asarray(p_world, dtype=float).reshape(-1, 3)
        R = self.T_camera_world[:3, :3]
        t = self.T_camera_world[:3, 3]
        rvec, _ = cv2.Rodrigues(R)
        uv, _ = cv2.projectPoints(p, rvec, t, self.K, _dist(self.D))
        return np.asarray(uv, dtype=float).reshape(-1, 2)

    def undistort_pixels(self, uv: ArrayLike) -> Array:
        """Normalised image coordinates (x/z, y/z) of distorted pixels, shape (N, 2)."""
        pts = np.ascontiguousarray(np.asarray(uv, dtype=np.float64).reshape(-1, 1, 2))
        if pts.shape[0] == 0:
            return np.zeros((0, 2))
        if not np.any(self.D):
            K = self.K
            x = (pts[:, 0, 0] - K[0, 2] - K[0, 1] * (pts[:, 0, 1] - K[1, 2]) / K[1, 1]) / K[0, 0]
            y = (pts[:, 0, 1] - K[1, 2]) / K[1, 1]
            return np.stack([x, y], axis=1)
        out = cv2.undistortPointsIter(pts, self.K, _dist(self.D), None, None, _UNDISTORT_CRITERIA)  # type: ignore[call-overload]
        return np.asarray(out, dtype=float).reshape(-1, 2)


def _dist(D: Array) -> Array:
    d = np.asarray(D, dtype=float).ravel()
    return d if d.size else np.zeros(4)


# ---- rendering ----------------------------------------------------------------------------------


def _plane_coords(
    view: PinholeView, T_camera_plate: Array, uv: Array
) -> tuple[Array, NDArray[np.bool_]]:
    """Plate-frame (x, y) [m] of the points seen at pixels ``uv`` (N, 2), and a validity mask."""
    xn = view.undistort_pixels(uv)
    d = np.concatenate([xn, np.ones((xn.shape[0], 1))], axis=1)  # rays in camera frame
    R = T_camera_plate[:3, :3]
    t = T_camera_plate[:3, 3]
    n = R[:, 2]
    denom = d @ n
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = (n @ t) / denom
    ok = np.isfinite(lam) & (lam > 0)
    P = d * np.where(ok, lam, 0.0)[:, None]
    xy = (P - t) @ R[:, :2]  # R^T (P - t), first two components
    return xy, ok


def _circle_distances(design: PlateDesign, xy: Array) -> tuple[Array, NDArray[np.intp]]:
    """Per point (N, 2): signed distance [m] to the nearest circle edge (< 0 inside) and that
    circle's index. Circles are smaller than half their spacing, so the nearest edge is the
    nearest (radius-corrected) circle's."""
    dist = np.empty(xy.shape[0])
    idx = np.empty(xy.shape[0], dtype=np.intp)
    c = design.layout[:, :2]
    for s0 in range(0, xy.shape[0], 32768):  # chunks keep the (n, K) temporaries small
        p = xy[s0 : s0 + 32768]
        d = np.sqrt((p[:, 0:1] - c[:, 0]) ** 2 + (p[:, 1:2] - c[:, 1]) ** 2) - design.radii
        k = np.argmin(np.abs(d), axis=1)
        idx[s0 : s0 + 32768] = k
        dist[s0 : s0 + 32768] = d[np.arange(len(k)), k]
    return dist, idx


def _outline_distance(design: PlateDesign, xy: Array) -> tuple[NDArray[np.bool_], Array]:
    """Per point (N, 2): inside the plate outline (bool) and distance [m] to its nearest edge
    (exact near the edges, a lower bound elsewhere)."""
    x0, x1, y0, y1 = design.outline
    x, y = xy[:, 0], xy[:, 1]
    inside = (x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)
    dx = np.minimum(np.abs(x - x0), np.abs(x - x1))
    dy = np.minimum(np.abs(y - y0), np.abs(y - y1))
    dist = np.minimum(
        np.where((y >= y0) & (y <= y1), dx, np.hypot(dx, dy)),
        np.where((x >= x0) & (x <= x1), dy, np.hypot(dx, dy)),
    )
    return inside, dist


@dataclass(frozen=True)
class _PlanePatch:
    """The pixels around a plane's projected outline, with where each ray meets the plane."""

    box: tuple[int, int, int, int]  # u0, u1, v0, v1 (inclusive)
    xy: Array  # (N, 2) plane coordinates [m] of the pixel centres (1e3 where the ray misses)
    ok: NDArray[np.bool_]  # (N,) the ray meets the plane in front of the camera
    J: Array  # (N, 2, 2) d(x, y)/d(u, v): rows x, y; columns d/du, d/dv
    front: bool  # the camera is on the plane's +z side

    def composite(self, img: Array, alpha: Array, premult: Array) -> None:
        """Blend premultiplied levels of coverage ``alpha`` (both (N,)) over ``img`` in place."""
        u0, u1, v0, v1 = self.box
        region = img[v0 : v1 + 1, u0 : u1 + 1]
        region *= 1.0 - alpha.reshape(region.shape)
        region += premult.reshape(region.shape)


def _plane_patch(view: PinholeView, T_camera_plane: Array, corners: Array) -> _PlanePatch | None:
    """Pixels covering the plane quad ``corners`` (4, 3) [m, plane frame], or None when the quad is
    (partly) behind the camera (a real camera would not see it whole either) or off the image."""
    w, h = view.image_size
    T_cp = T_camera_plane
    corners_c = corners @ T_cp[:3, :3].T + T_cp[:3, 3]
    if np.any(corners_c[:, 2] < NEAR_CLIP):
        return None
    front = bool(-T_cp[:3, 3] @ T_cp[:3, 2] > 0)  # camera on the +z side of the plane
    # Bounding box of the projected outline (densely sampled edges, for distortion), padded.
    s = np.linspace(0.0, 1.0, 33)[:, None]
    edges = np.concatenate(
        [corners_c[i] * (1 - s) + corners_c[(i + 1) % 4] * s for i in range(4)], axis=0
    )
    uv_edges = PinholeView(view.K, view.D, view.image_size).project(edges)
    u0 = max(int(np.floor(uv_edges[:, 0].min())) - 3, 0)
    u1 = min(int(np.ceil(uv_edges[:, 0].max())) + 3, w - 1)
    v0 = max(int(np.floor(uv_edges[:, 1].min())) - 3, 0)
    v1 = min(int(np.ceil(uv_edges[:, 1].max())) + 3, h - 1)
    if u1 < u0 or v1 < v0:
        return None
    us, vs = np.meshgrid(np.arange(u0, u1 + 1, dtype=float), np.arange(v0, v1 + 1, dtype=float))
    uv = np.stack([us.ravel(), vs.ravel()], axis=1)
    xy, ok = _plane_coords(view, T_cp, uv)
    xy = np.where(ok[:, None], xy, 1e3)  # rays that miss the plane: far outside the plate
    # Plane size of a pixel: d(x, y)/d(u, v) by central differences.
    gx = np.stack(list(np.gradient(xy[:, 0].reshape(us.shape))), axis=-1).reshape(-1, 2)
    gy = np.stack(list(np.gradient(xy[:, 1].reshape(us.shape))), axis=-1).reshape(-1, 2)
    J = np.stack([gx[:, ::-1], gy[:, ::-1]], axis=1)
    return _PlanePatch((u0, u1, v0, v1), xy, ok, J, front)


def _render(
    view: PinholeView,
    items: Sequence[tuple[_T, ArrayLike]],
    draw: Callable[[Array, PinholeView, _T, Array, int], None],
    background: float,
    supersample: int,
    blur_sigma: float,
    noise_sigma: float,
    rng: np.random.Generator | None,
    who: str,
) -> NDArray[np.uint8]:
    """Draw ``items`` far to near with ``draw``, then blur, add noise and quantise to 8 bits."""
    w, h = view.image_size
    img = np.full((h, w), float(background))
    order = sorted(
        items, key=lambda p: -float((view.T_camera_world @ np.asarray(p[1], dtype=float))[2, 3])
    )
    for item, T in order:
        draw(img, view, item, np.asarray(T, dtype=float), supersample)
    img *= 255.0
    if blur_sigma > 0:
        img = cv2.GaussianBlur(img, (0, 0), blur_sigma, borderType=cv2.BORDER_REPLICATE)
    if noise_sigma > 0:
        if rng is None:
            raise ValueError(f"{who}: noise_sigma > 0 needs a seeded rng")
        img = img + rng.normal(0.0, noise_sigma, img.shape)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def _draw_plate(
    img: Array, view: PinholeView, design: PlateDesign, T_world_plate: Array, supersample: int
) -> None:
    """Composite one plate into ``img`` (float, shape (h, w)) in place."""
    patch = _plane_patch(view, view.T_camera_world @ T_world_plate, design.outline_corners())
    if patch is None:
        return
    xy, ok, J, front = patch.xy, patch.ok, patch.J, patch.front
    inside, d_outline = _outline_distance(design, xy)
    if front:
        d_circle, nearest = _circle_distances(design, xy)
        level = np.where(d_circle <= 0, design.dot_level, design.plate_level)
    else:
        d_circle, nearest = np.full(len(xy), np.inf), np.zeros(len(xy), dtype=np.intp)
        level = np.full(len(xy), PLATE_BACK_LEVEL)
    alpha = inside.astype(float)
    premult = alpha * level
    scale = np.sqrt(np.sum(J**2, axis=(1, 2)))  # Frobenius >= the larger singular value
    near = ok & (np.minimum(d_outline, np.abs(d_circle)) <= scale)
    if supersample > 1 and np.any(near):
        offs = (np.arange(supersample) + 0.5) / supersample - 0.5
        ou, ov = np.meshgrid(offs, offs)
        duv = np.stack([ou.ravel(), ov.ravel()], axis=1)  # (S, 2) sub-pixel offsets
        # Sub-samples from the pixel centre and the local Jacobian: the plane coordinates are a
        # smooth function of (u, v), so the 2nd-order error over half a pixel is ~1e-6 px.
        sxy = xy[near][:, None, :] + np.einsum("nij,sj->nsi", J[near], duv)  # (n, S, 2)
        s_in = _outline_distance(design, sxy.reshape(-1, 2))[0].reshape(sxy.shape[:2])
        if front:
            c = design.layout[nearest[near], :2]
            r = design.radii[nearest[near]]
            s_dot = np.sum((sxy - c[:, None, :]) ** 2, axis=2) <= (r * r)[:, None]
            s_level = np.where(s_dot, design.dot_level, design.plate_level)
        else:
            s_level = np.full(s_in.shape, PLATE_BACK_LEVEL)
        alpha[near] = s_in.mean(axis=1)
        premult[near] = (s_in * s_level).mean(axis=1)
    patch.composite(img, alpha, premult)


def render_view(
    view: PinholeView,
    plates: Sequence[tuple[PlateDesign, ArrayLike]],
    *,
    background: float = BACKGROUND_LEVEL,
    supersample: int = 8,
    blur_sigma: float = 0.0,
    noise_sigma: float = 0.0,
    rng: np.random.Generator | None = None,
) -> NDArray[np.uint8]:
    """Render plates seen by one camera as an 8-bit grey image.

    Args:
        view: The camera.
        plates: (design, ``T_world_plate`` of shape (4, 4)) pairs.
        background: Grey level behind the plates (0..1).
        supersample: Sub-samples per axis at edge pixels (anti-aliasing; 8 gives 64 samples).
        blur_sigma: Gaussian blur [px] (0: none).
        noise_sigma: Standard deviation of additive Gaussian noise [grey levels of 255].
        rng: Random generator for the noise (required when ``noise_sigma > 0``).

    Returns:
        Image, shape (height, width), dtype uint8.
    """
    return _render(
        view,
        plates,
        _draw_plate,
        background,
        supersample,
        blur_sigma,
        noise_sigma,
        rng,
        "render_view",
    )


def _draw_board(
    img: Array, view: PinholeView, board: Board, T_world_board: Array, supersample: int
) -> None:
    """Composite one standard board (:mod:`~cpc2urdf.identification.vision.boards.board`) into ``img``
    in place. Pixels where the board's texture changes (its centre and four corners disagree) are
    supersampled (``supersample`` x ``supersample`` samples from the local Jacobian of the plane
    coordinates, as :func:`_draw_plate` does at edges); the others take their centre's level."""
    patch = _plane_patch(view, view.T_camera_world @ T_world_board, board.outline_corners())
    if patch is None:
        return
    xy, ok, J, front = patch.xy, patch.ok, patch.J, patch.front
    x0, x1, y0, y1 = board.outline

    def shade(duv: Array, idx: NDArray[np.intp]) -> tuple[Array, Array]:
        """Coverage and premultiplied level of pixels ``idx`` from sub-samples at offsets ``duv`` (S, 2)."""
        a_out, p_out = np.zeros(len(idx)), np.zeros(len(idx))
        for c0 in range(0, len(idx), 8192):  # chunks keep the (n, S) samples small
            sl = idx[c0 : c0 + 8192]
            Js = J[sl]
            sx = (
                xy[sl, 0:1] + Js[:, 0, 0:1] * duv[:, 0] + Js[:, 0, 1:2] * duv[:, 1]
            )  # (n, S); einsum is 5x slower
            sy = xy[sl, 1:2] + Js[:, 1, 0:1] * duv[:, 0] + Js[:, 1, 1:2] * duv[:, 1]
            flat = np.stack([sx.ravel(), sy.ravel()], axis=1)
            inside = (
                (flat[:, 0] >= x0) & (flat[:, 0] <= x1) & (flat[:, 1] >= y0) & (flat[:, 1] <= y1)
            ).astype(float)
            level = board.reflectance(flat) if front else np.full(len(flat), PLATE_BACK_LEVEL)
            a_out[c0 : c0 + 8192] = inside.reshape(sx.shape).mean(axis=1)
            p_out[c0 : c0 + 8192] = (inside * level).reshape(sx.shape).mean(axis=1)
        return a_out, p_out

    # A pixel whose centre and four corners agree is uniform (the board's features are several
    # pixels wide); only the others are supersampled.
    probe = np.array([[0.0, 0.0], [-0.5, -0.5], [0.5, -0.5], [-0.5, 0.5], [0.5, 0.5]])
    every = np.arange(len(xy))
    at_probes = [shade(probe[k : k + 1], every) for k in range(5)]
    a5 = np.stack([a for a, _ in at_probes], axis=1)
    p5 = np.stack([p for _, p in at_probes], axis=1)
    alpha, premult = a5[:, 0].copy(), p5[:, 0].copy()
    mixed = np.flatnonzero((np.ptp(a5, axis=1) > 0) | (np.ptp(p5, axis=1) > 0))
    n = max(int(supersample), 1)
    offs = (np.arange(n) + 0.5) / n - 0.5
    ou, ov = np.meshgrid(offs, offs)
    alpha[mixed], premult[mixed] = shade(np.stack([ou.ravel(), ov.ravel()], axis=1), mixed)
    alpha[~ok] = 0.0
    premult[~ok] = 0.0
    patch.composite(img, alpha, premult)


def render_board_view(
    view: PinholeView,
    boards: Sequence[tuple[Board, ArrayLike]],
    *,
    background: float = BACKGROUND_LEVEL,
    supersample: int = 6,
    blur_sigma: float = 0.0,
    noise_sigma: float = 0.0,
    rng: np.random.Generator | None = None,
) -> NDArray[np.uint8]:
    """Render standard boards seen by one camera as an 8-bit grey image (as :func:`render_view`).

    Args:
        view: The camera.
        boards: (board, ``T_world_board`` of shape (4, 4)) pairs; the board frame is
            :mod:`~cpc2urdf.identification.vision.boards.board`' (printed face towards +z).
        background: Grey level behind the boards (0..1).
        supersample: Sub-samples per axis at pixels where the board's texture changes.
        blur_sigma: Gaussian blur [px] (0: none).
        noise_sigma: Standard deviation of additive Gaussian noise [grey levels of 255].
        rng: Random generator for the noise (required when ``noise_sigma > 0``).

    Returns:
        Image, shape (height, width), dtype uint8.
    """
    return _render(
        view,
        boards,
        _draw_board,
        background,
        supersample,
        blur_sigma,
        noise_sigma,
        rng,
        "render_board_view",
    )


def circle_centres_px(view: PinholeView, design: PlateDesign, T_world_plate: ArrayLike) -> Array:
    """True projected circle centres (with distortion) [px], shape (K, 2): the detector's truth."""
    T = np.asarray(T_world_plate, dtype=float)
    p_world = design.layout @ T[:3, :3].T + T[:3, 3]
    return view.project(p_world)


def hidden_circles(
    view: PinholeView, plates: Sequence[tuple[PlateDesign, ArrayLike]], *, margin_px: float = 3.0
) -> dict[str, int]:
    """How many circles of each plate the camera cannot measure cleanly.

    A circle counts as hidden when it is behind the camera, within ``margin_px`` plus its radius
    of the image border, or within that distance of the outline of a plate drawn in front of it
    (the renderer's depth order), or when its plate shows the camera its back.

    Args:
        view: The camera.
        plates: (design, ``T_world_plate``) pairs.
        margin_px: Clearance required [px].

    Returns:
        Plate name -> number of hidden circles (0 .. K).
    """
    w, h = view.image_size
    items = [(d, np.asarray(T, dtype=float)) for d, T in plates]
    depth = [float((view.T_camera_world @ T)[2, 3]) for _, T in items]
    polys = []
    for d, T in items:
        T_cp = view.T_camera_world @ T
        c = d.outline_corners() @ T_cp[:3, :3].T + T_cp[:3, 3]
        s = np.linspace(0.0, 1.0, 17)[:, None]
        edge = np.concatenate([c[i] * (1 - s) + c[(i + 1) % 4] * s for i in range(4)])
        ok = bool(np.all(edge[:, 2] > NEAR_CLIP))
        polys.append(
            PinholeView(view.K, view.D, view.image_size).project(edge).astype(np.float32)
            if ok
            else None
        )
    out: dict[str, int] = {}
    for a, (d, T) in enumerate(items):
        T_cp = view.T_camera_world @ T
        pc = d.layout @ T_cp[:3, :3].T + T_cp[:3, 3]
        if np.any(pc[:, 2] < NEAR_CLIP) or -T_cp[:3, 3] @ T_cp[:3, 2] <= 0:
            out[d.name] = d.n_circles
            continue
        uv = view.project(d.layout @ T[:3, :3].T + T[:3, 3])
        r_px = d.radii * view.K[0, 0] / pc[:, 2]
        clear = r_px + margin_px
        hidden = (
            (uv[:, 0] < clear)
            | (uv[:, 0] > w - 1 - clear)
            | (uv[:, 1] < clear)
            | (uv[:, 1] > h - 1 - clear)
        )
        for b, poly in enumerate(polys):
            if b == a or poly is None or depth[b] >= depth[a]:
                continue
            for i in range(d.n_circles):
                dist = cv2.pointPolygonTest(poly, (float(uv[i, 0]), float(uv[i, 1])), True)
                hidden[i] |= dist > -clear[i]
        out[d.name] = int(hidden.sum())
    return out


def occluded_circles(
    camera_centre: ArrayLike,
    focal_px: float,
    plates: Sequence[tuple[PlateDesign, ArrayLike]],
    *,
    margin_px: float = 0.0,
) -> dict[str, NDArray[np.bool_]]:
    """Which circles a camera cannot see because of the plates themselves, for N poses at once.

    A 3-D ray test (vectorised over configurations, unlike :func:`hidden_circles`, which tests
    one image against the renderer's depth order): circle ``k`` of plate ``a`` is hidden when
    plate ``a`` shows the camera its back (the camera is not on its +z side), or when the ray
    from the camera centre to the circle centre crosses another plate's plane between the two
    inside that plate's outline grown by a clearance. The clearance is the circle's radius and
    ``margin_px`` pixels, both scaled to the distance of the crossing, so a circle counts as
    hidden when its image comes within ``margin_px`` of the occluding plate's image.

    Args:
        camera_centre: Optical centre of the camera in world [m], shape (3,).
        focal_px: Focal length [px] (converts ``margin_px`` to metres at a distance).
        plates: (design, ``T_world_plate`` of shape (N, 4, 4) or (4, 4)) pairs; all with the
            same N.
        margin_px: Clearance required between a circle's image and another plate's image [px].

    Returns:
        Plate name -> hidden mask of shape (N, K).
    """
    c = np.asarray(camera_centre, dtype=float).reshape(3)
    items = [(d, np.asarray(T, dtype=float).reshape(-1, 4, 4)) for d, T in plates]
    out: dict[str, NDArray[np.bool_]] = {}
    for a, (d, T) in enumerate(items):
        p = np.einsum("nij,kj->nki", T[:, :3, :3], d.layout) + T[:, None, :3, 3]  # (N, K, 3)
        back = np.einsum("ni,ni->n", c - T[:, :3, 3], T[:, :3, 2]) <= 0
        hidden = np.repeat(back[:, None], d.n_circles, axis=1)
        ray = p - c  # camera -> circle centre, (N, K, 3)
        length = np.linalg.norm(ray, axis=2)
        for b, (db, Tb) in enumerate(items):
            if b == a:
                continue
            n, o = Tb[:, :3, 2], Tb[:, :3, 3]
            den = np.einsum("nki,ni->nk", ray, n)
            with np.errstate(divide="ignore", invalid="ignore"):
                s = np.einsum("ni,ni->n", o - c, n)[:, None] / den  # crossing at c + s ray
            crosses = np.isfinite(s) & (s > 0) & (s < 1)
            s = np.where(crosses, s, 0.0)
            x = c + s[..., None] * ray - o[:, None, :]
            local = np.einsum("nji,nkj->nki", Tb[:, :3, :3], x)  # R^T (x - o): plate-b frame
            clear = s * (d.radii[None, :] + margin_px * length / focal_px)
            x0, x1, y0, y1 = db.outline
            inside = (
                (local[..., 0] > x0 - clear)
                & (local[..., 0] < x1 + clear)
                & (local[..., 1] > y0 - clear)
                & (local[..., 1] < y1 + clear)
            )
            hidden |= crosses & inside
        out[d.name] = hidden
    return out


__all__ = [
    "BACKGROUND_LEVEL",
    "NEAR_CLIP",
    "PLATE_BACK_LEVEL",
    "PinholeView",
    "circle_centres_px",
    "hidden_circles",
    "occluded_circles",
    "render_board_view",
    "render_view",
]
