"""What the stereo rig sees of the plates: the view check of a simulated experiment.

Every circle of every measured plate must project at least ``VIEW_MARGIN_PX`` inside both images,
each plate must face both cameras within ``MAX_VIEW_ANGLE``, and no circle may be hidden by
another plate or by the plate's own back (a 3-D ray test against the plate rectangles,
:func:`~cpc2urdf.identification.vision.render.occluded_circles`, with ``OCCLUSION_MARGIN_PX`` of
clearance). :func:`check_view` reports what fails, per (configuration, plate);
:func:`visible_heldout` draws held-out configurations that pass it (a real validation set holds
only poses the rig can measure). :func:`board_in_view` is the check for one camera and a
standard board, vectorised over poses.

Example::

    view = check_view(truth, StereoRig.verged(), q, ["plate_left", "plate_right"], labels)
    view.ok, view.problems[:3], view.min_margin_px
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cpc2urdf.identification.simulation.design import random_configurations
from cpc2urdf.identification.vision.boards.board import Board
from cpc2urdf.identification.vision.render import PinholeView, occluded_circles
from cpc2urdf.identification.vision.stereo import StereoRig
from cpc2urdf.identification.vision.targets import PlateDesign, robot_plate_designs
from cpc2urdf.model import CPCModel, RobotStructure

Array = NDArray[np.float64]

VIEW_MARGIN_PX = 20.0  # [px]: circles must stay this far inside both images
MAX_VIEW_ANGLE = math.radians(75.0)  # [rad]: plate normal vs line of sight to either camera
OCCLUSION_MARGIN_PX = 3.0  # [px]: a circle's image must stay this far from any other plate's image


def frame_points(structure: RobotStructure, name: str) -> Array:
    """The points of frame ``name`` that the rig must see, in that frame [m], shape (K, 3): its
    circle layout, or its origin (K = 1) if it has none."""
    layout = structure.frame(name).layout
    return np.zeros((1, 3)) if layout is None else np.array(layout, dtype=float)


@dataclass
class ViewReport:
    """How well the rig sees the plates over a set of configurations.

    Attributes:
        ok: Every circle of every plate seen by both cameras, face-on enough, hidden by no other
            plate, in every config.
        problems: One line per (configuration, plate) that fails: out of view or too oblique
            first, then hidden circles.
        min_margin_px: Smallest distance of a circle centre from an image border [px].
        max_view_angle: Largest angle between a plate normal and a line of sight [rad].
        distance_range: Min and max distance of plate origins from the left camera [m].
        unseen: Number of (configuration, plate) pairs outside an image or too oblique.
        hidden: Number of (configuration, plate, camera, circle) sightings blocked by another
            plate or by the plate's own back (:func:`~cpc2urdf.identification.vision.render.
            occluded_circles`).
        hidden_per_config: Those sightings per configuration, shape (N,).
        unseen_per_config: Plates outside an image or too oblique, per configuration, shape (N,).
    """

    ok: bool
    problems: list[str]
    min_margin_px: float
    max_view_angle: float
    distance_range: tuple[float, float]
    unseen: int = 0
    hidden: int = 0
    hidden_per_config: NDArray[np.int64] = field(
        default_factory=lambda: np.zeros(0, dtype=np.int64)
    )
    unseen_per_config: NDArray[np.int64] = field(
        default_factory=lambda: np.zeros(0, dtype=np.int64)
    )


def check_view(
    model: CPCModel,
    rig: StereoRig,
    q: ArrayLike,
    frames: Sequence[str],
    labels: Sequence[str],
    *,
    margin_px: float = VIEW_MARGIN_PX,
    max_angle: float = MAX_VIEW_ANGLE,
    occlusion_margin_px: float | None = OCCLUSION_MARGIN_PX,
    designs: Sequence[PlateDesign] | None = None,
) -> ViewReport:
    """Check that both rig cameras see every circle of every plate in every configuration.

    A (configuration, plate) fails when a circle centre is less than ``margin_px`` inside an
    image, when a line of sight is more than ``max_angle`` off the plate normal, or when a camera
    cannot see a circle because another plate is in the way or the plate shows its back (a 3-D
    ray test against the plate rectangles, with ``occlusion_margin_px`` of clearance).

    Args:
        model: The robot, placed in the rig's world.
        rig: The measuring rig.
        q: Configurations, shape (N, n).
        frames: The plates.
        labels: One label per configuration (for the problem lines).
        margin_px: Required distance of circle centres from the image borders [px].
        max_angle: Largest angle between plate normal and line of sight [rad].
        occlusion_margin_px: Required clearance between a circle's image and any other plate's
            image [px]; None skips the occlusion test.
        designs: Plate outlines for the occlusion test (default: :func:`~cpc2urdf.
            identification.vision.render.robot_plate_designs`, the layout's bounding box + 10 mm).
    """
    qq = np.atleast_2d(np.asarray(q, dtype=float))
    fk = model.fk(qq, frames)
    w, h = rig.image_size
    problems: list[str] = []
    hidden_problems: list[str] = []  # listed after the out-of-view ones
    min_margin, max_ang, dists = math.inf, 0.0, []
    cameras = [
        ("left", rig.T_world_camera("left")[:3, 3], float(rig.K1[0, 0])),
        ("right", rig.T_world_camera("right")[:3, 3], float(rig.K2[0, 0])),
    ]
    occluded: dict[str, list[NDArray[np.bool_]]] = {}
    if occlusion_margin_px is not None:
        by_name = {
            d.name: d
            for d in (robot_plate_designs(model.structure.frames) if designs is None else designs)
        }
        plates = [(by_name[f], fk[f]) for f in frames if f in by_name]
        for _, centre, focal in cameras:
            for f, mask in occluded_circles(
                centre, focal, plates, margin_px=occlusion_margin_px
            ).items():
                occluded.setdefault(f, []).append(mask)
    unseen = 0
    per_config = np.zeros(len(qq), dtype=np.int64)
    unseen_per_config = np.zeros(len(qq), dtype=np.int64)
    for f in frames:
        T = fk[f]
        pts = (
            np.einsum("nij,kj->nki", T[:, :3, :3], frame_points(model.structure, f))
            + T[:, None, :3, 3]
        )
        seen = rig.in_view(pts, margin_px=margin_px)
        uv1, uv2 = rig.project(pts)
        for uv in (uv1, uv2):
            m = np.minimum.reduce([uv[..., 0], w - 1 - uv[..., 0], uv[..., 1], h - 1 - uv[..., 1]])
            min_margin = min(min_margin, float(np.nanmin(m)))
        ang = np.zeros(len(qq))
        for _, c, _ in cameras:
            los = c - T[:, :3, 3]
            los /= np.linalg.norm(los, axis=1, keepdims=True)
            ang = np.maximum(
                ang, np.arccos(np.clip(np.einsum("ni,ni->n", los, T[:, :3, 2]), -1, 1))
            )
        max_ang = max(max_ang, float(ang.max()))
        dists.append(np.linalg.norm(T[:, :3, 3], axis=1))
        blocked = occluded.get(f, [np.zeros(seen.shape, dtype=bool)] * 2)
        per_config += blocked[0].sum(axis=1) + blocked[1].sum(axis=1)
        bad_view = ~seen.all(axis=1) | (ang > max_angle)
        unseen += int(bad_view.sum())
        unseen_per_config += bad_view
        for i in np.flatnonzero(bad_view | blocked[0].any(axis=1) | blocked[1].any(axis=1)):
            if not seen[i].all():
                why = f"{int((~seen[i]).sum())} of {seen.shape[1]} circles outside an image (margin {margin_px:g} px)"
            elif ang[i] > max_angle:
                why = f"seen at {math.degrees(ang[i]):.0f} deg from face-on (limit {math.degrees(max_angle):.0f})"
            else:
                why = "; ".join(
                    f"{int(b[i].sum())} of {b.shape[1]} circles hidden from the {cam} camera by another plate "
                    f"or its own back (clearance {occlusion_margin_px:g} px)"
                    for (cam, _, _), b in zip(cameras, blocked, strict=True)
                    if b[i].any()
                )
                hidden_problems.append(f"{f} at {labels[int(i)]}: {why}")
                continue
            problems.append(f"{f} at {labels[int(i)]}: {why}")
    problems += hidden_problems
    d = np.concatenate(dists)
    return ViewReport(
        not problems,
        problems,
        min_margin,
        max_ang,
        (float(d.min()), float(d.max())),
        unseen,
        int(per_config.sum()),
        per_config,
        unseen_per_config,
    )


def visible_heldout(
    truth: CPCModel,
    rig: StereoRig,
    ranges: ArrayLike,
    n: int,
    frames: Sequence[str],
    rng: np.random.Generator,
    *,
    max_rounds: int = 20,
) -> tuple[Array, int]:
    """``n`` random configurations in ``ranges`` (n_joints, 2) in which the rig sees every circle.

    Draws ``n`` configurations uniformly, then redraws (from ``rng``, in order) those in which
    :func:`check_view` finds a circle hidden by a plate, outside an image or seen too obliquely --
    a real validation set holds only poses the rig can measure -- for at most ``max_rounds``
    rounds; whatever is still unmeasurable then is left for :func:`check_view` to report.

    Args:
        truth: The robot, placed in the rig's world.
        rig: The measuring rig.
        ranges: Per joint ``[lo, hi]`` [m]/[rad], shape (n_joints, 2).
        n: Number of configurations.
        frames: The plates.
        rng: Random generator (the held-out stream).
        max_rounds: Largest number of redraw rounds.

    Returns:
        ``(q, redrawn)``: configurations of shape (n, n_joints) and how many draws were replaced.
    """
    q = random_configurations(ranges, n, rng)
    redrawn = 0
    for _ in range(max_rounds):
        if n == 0:
            break
        view = check_view(truth, rig, q, frames, [str(i) for i in range(n)])
        bad = np.flatnonzero((view.hidden_per_config > 0) | (view.unseen_per_config > 0))
        if bad.size == 0:
            break
        q[bad] = random_configurations(ranges, bad.size, rng)
        redrawn += int(bad.size)
    return q, redrawn


def board_in_view(
    view: PinholeView,
    board: Board,
    T_camera_board: ArrayLike,
    *,
    margin_px: float = 10.0,
    near: float = 0.05,
    max_angle: float = 0.5 * math.pi,
    min_point_px: float = 0.0,
) -> NDArray[np.bool_]:
    """Per pose of ``board`` in the camera's optical frame (shape (4, 4) or (N, 4, 4)): whether the
    camera ``view`` (its intrinsics; its pose is not used) sees the whole board: every outline
    corner at least ``near`` [m] in front and ``margin_px`` inside the image, the printed face
    (+z) towards the camera, less than ``max_angle`` [rad] between its normal and the line of
    sight to its origin, and neighbouring points at least ``min_point_px`` apart in the image
    (along the projected outline's shortest edge). Shape (N,)."""
    T = np.asarray(T_camera_board, dtype=float).reshape(-1, 4, 4)
    R, t = T[:, :3, :3], T[:, :3, 3]
    c = board.outline_corners()
    p = np.einsum("nij,kj->nki", R, c) + t[:, None, :]  # corners in the camera frame, (N, 4, 3)
    dist = np.linalg.norm(t, axis=1)
    ok = np.all(p[..., 2] >= near, axis=1) & (
        -np.einsum("ni,ni->n", t, R[:, :, 2]) > math.cos(max_angle) * dist
    )
    w, h = view.image_size
    with np.errstate(divide="ignore", invalid="ignore"):
        xn = p[..., :2] / p[..., 2:]
    # a lens model's polynomial can fold points far outside the field of view back into the image
    ok &= np.all(np.abs(xn) <= 2.0 * np.array([w / view.K[0, 0], h / view.K[1, 1]]), axis=(1, 2))
    if not ok.any():
        return ok
    uv = np.full(p.shape[:2] + (2,), np.nan)
    uv[ok] = PinholeView(view.K, view.D, view.image_size).project(p[ok]).reshape(-1, 4, 2)
    m = margin_px
    ok &= np.all((uv >= m) & (uv <= np.array([w - 1 - m, h - 1 - m])), axis=(1, 2))
    if min_point_px > 0:
        x0, x1, y0, y1 = board.outline
        edge_px = np.linalg.norm(uv - np.roll(uv, -1, axis=1), axis=2)  # edges 01, 12, 23, 30
        px_per_m = edge_px / np.array([x1 - x0, y1 - y0, x1 - x0, y1 - y0])
        ok &= px_per_m.min(axis=1) * board.point_spacing >= min_point_px
    return ok


__all__ = [
    "MAX_VIEW_ANGLE",
    "OCCLUSION_MARGIN_PX",
    "VIEW_MARGIN_PX",
    "ViewReport",
    "board_in_view",
    "check_view",
    "frame_points",
    "visible_heldout",
]
