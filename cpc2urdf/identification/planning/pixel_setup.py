"""What a head's cameras see of a board, for planning a one-stage calibration (SI units).

:class:`PixelSetup` is the planner's scene: the nominal model with the cameras' optical frames (a
fixed board's world is the board, ``T_world_board = I``, as the pixel fit's; a held board is a
model frame), the cameras' intrinsics, the board, the corner noise and the planning margins.
:func:`board_seen` says which cameras see the whole board (the board's outline ``margin_px``
inside the image, in front, printed face +z towards the camera within ``max_angle``, neighbouring
points ``min_point_px`` apart: :func:`~cpc2urdf.identification.simulation.visibility.board_in_view`)
and :func:`draw_configurations` draws configurations where all do. :func:`board_in_front` places a
fixed board; :func:`setup_from_scene` is the setup of a simulated scene
(:mod:`~cpc2urdf.identification.simulation.selfcal_experiment`) at its nominal model.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cpc2urdf.errors import DegenerateDataError
from cpc2urdf.identification.handeye.stage2 import (
    DEFAULT_INTRINSICS,
    CameraIntrinsics,
    default_target_placement,
)
from cpc2urdf.identification.selfcal.pixel_problem import CameraModel
from cpc2urdf.identification.simulation.design import walk_configurations
from cpc2urdf.identification.simulation.selfcal_experiment import SelfcalScene
from cpc2urdf.identification.simulation.visibility import board_in_view
from cpc2urdf.identification.vision.boards.board import Board
from cpc2urdf.identification.vision.render import PinholeView
from cpc2urdf.model import CPCModel, CPCParams
from cpc2urdf.transforms import Array, inverse

DEFAULT_SIGMA = 0.15  # [px] corner noise per pixel coordinate
VIEW_MARGIN_PX = 20.0  # [px] the board's outline this far inside every image
# Planning margins, a little stricter than the simulator's (selfcal_experiment: 10 px, 60 deg,
# 10 px; 25 px for ChArUco), since the real robot is a few px off its nominal model.
MAX_VIEW_ANGLE = math.radians(55.0)  # [rad] board normal vs line of sight
MIN_POINT_PX = 12.0  # [px] neighbouring points at least this far apart in the image
MIN_POINT_PX_CHARUCO = 30.0  # [px] ChArUco's markers need ~4 px per bit
DRAWS_PER_CANDIDATE = 200  # random configurations tried per candidate wanted, at most
BOARD_IMAGE_SHARE = 1.0 / 3.0  # [-] a fixed board's default width in the image


@dataclass(frozen=True)
class PixelSetup:
    """A head, its cameras and a board, for planning (SI units).

    Attributes:
        nominal: The model with the cameras' optical frames (and a held board's frame); a fixed
            board's model has its world at the board (``T_world_board = I``).
        cameras: Camera frame -> intrinsics.
        board: The board (corners :meth:`Board.object_points` in its frame).
        board_frame: None for a board fixed in the world; else the model frame it is.
        sigma: Corner noise per pixel coordinate [px].
        ranges: Calibration ranges, shape (n, 2) [m]/[rad] (default the model's).
        margin_px, max_angle, min_point_px: Planning margins of :func:`board_seen` (default
            :data:`MIN_POINT_PX`, ChArUco :data:`MIN_POINT_PX_CHARUCO`).
        start: A configuration where every camera sees the board: where candidates are walked
            from when few uniform draws see it (a board held by an arm), shape (n,).
    """

    nominal: CPCModel
    cameras: dict[str, CameraModel]
    board: Board
    board_frame: str | None = None
    sigma: float = DEFAULT_SIGMA
    ranges: Array | None = None
    margin_px: float = VIEW_MARGIN_PX
    max_angle: float = MAX_VIEW_ANGLE
    min_point_px: float | None = None
    start: Array | None = None

    @property
    def frames(self) -> list[str]:
        """The chart's measured frames: the cameras, then a held board."""
        return list(self.cameras) + ([self.board_frame] if self.board_frame else [])

    @property
    def point_px(self) -> float:
        """The smallest distance between neighbouring points in an image [px]."""
        if self.min_point_px is not None:
            return self.min_point_px
        return MIN_POINT_PX_CHARUCO if self.board.kind == "charuco" else MIN_POINT_PX

    def calibration_ranges(self) -> Array:
        r = self.ranges if self.ranges is not None else self.nominal.structure.calibration_ranges()
        return np.asarray(r, dtype=float)

    def camera_board(self, q: ArrayLike) -> dict[str, Array]:
        """Camera -> ``T_camera_board`` at configurations ``q`` (N, n), shape (N, 4, 4)."""
        T = self.nominal.fk(np.atleast_2d(np.asarray(q, dtype=float)), self.frames)
        Tb = T[self.board_frame] if self.board_frame else np.eye(4)
        return {c: inverse(T[c]) @ Tb for c in self.cameras}


def board_in_front(
    model: CPCModel, cameras: dict[str, CameraModel], board: Board, distance: float | None = None
) -> CPCModel:
    """``model`` with its world at a board fixed ``distance`` [m] ahead of the cameras at the
    middle of the calibration ranges, facing them (default: where the board's width spans
    :data:`BOARD_IMAGE_SHARE` of the first camera's image)."""
    if distance is None:
        cam = next(iter(cameras.values()))
        x0, x1, _, _ = board.outline
        distance = cam.K[0, 0] * (x1 - x0) / (BOARD_IMAGE_SHARE * cam.image_size[0])
    T_base_board = default_target_placement(model, list(cameras), distance)
    return model.with_params(world_to_base=CPCParams.from_matrix(inverse(T_base_board)))


def board_seen(setup: PixelSetup, q: ArrayLike, *, margins: bool = True) -> NDArray[np.bool_]:
    """Per configuration and camera, whether it sees the whole board, shape (N, cameras).

    ``margins=False``: the whole board in the image, in front and facing (what a detector could
    find) instead of the planning margins."""
    T = setup.camera_board(q)
    lim = {"margin_px": 0.0}
    if margins:
        lim = {"margin_px": setup.margin_px, "max_angle": setup.max_angle}
        lim["min_point_px"] = setup.point_px
    out = []
    for c, cam in setup.cameras.items():
        view = PinholeView(cam.K, cam.D, cam.image_size)
        out.append(board_in_view(view, setup.board, T[c], **lim))
    return np.stack(out, axis=1)


def draw_configurations(setup: PixelSetup, n: int, rng: np.random.Generator) -> tuple[Array, int]:
    """``n`` configurations where every camera sees the whole board (:func:`board_seen`), shape
    (n, joints), and how many were tried: uniform in the calibration ranges, or, when few of those
    see it and the setup has a ``start``, a random walk from there through the usable part of the
    ranges (:func:`~cpc2urdf.identification.simulation.design.walk_configurations`), ``n`` of its
    visits drawn at random.

    Raises:
        DegenerateDataError: Fewer than ``n`` in ``DRAWS_PER_CANDIDATE * n`` draws (or visits).
    """
    lo, hi = setup.calibration_ranges().T

    def usable(q: Array) -> NDArray[np.bool_]:
        return np.asarray(board_seen(setup, q).all(axis=1), dtype=bool)

    kept: list[Array] = []
    drawn, batch = 0, max(4 * n, 256)
    limit = DRAWS_PER_CANDIDATE * n if setup.start is None else 20 * batch
    while sum(len(k) for k in kept) < n and drawn < limit:
        q = rng.uniform(lo, hi, (batch, len(lo)))
        drawn += batch
        kept.append(q[usable(q)])
    got = np.concatenate(kept)
    if len(got) < n and setup.start is not None and usable(setup.start[None])[0]:
        visited = walk_configurations(usable, setup.start, np.stack([lo, hi], 1), rng, 4 * n)
        drawn += 4 * n * 24
        got = visited[rng.permutation(len(visited))]
    if len(got) < n:
        raise DegenerateDataError(
            f"only {len(got)} of {drawn} random configurations let every camera "
            f"({', '.join(setup.cameras)}) see the whole board; {n} wanted: move the board or "
            "change the calibration ranges"
        )
    return got[:n], drawn


def setup_from_scene(
    scene: SelfcalScene,
    intrinsics: CameraIntrinsics | Mapping[str, CameraIntrinsics] = DEFAULT_INTRINSICS,
    sigma: float = DEFAULT_SIGMA,
) -> PixelSetup:
    """The planning setup of a simulated scene at its *nominal* model (a fixed board where the
    scene puts it: the model's world moved to the board)."""
    intr = {
        c: intrinsics if isinstance(intrinsics, CameraIntrinsics) else intrinsics[c]
        for c in scene.cameras
    }
    cams = {c: CameraModel(i.K, i.D, (i.width, i.height)) for c, i in intr.items()}
    model = scene.nominal
    if scene.board_frame is None:
        assert scene.T_world_board is not None
        T_board_base = inverse(scene.T_world_board) @ model.T_world_base()
        model = model.with_params(world_to_base=CPCParams.from_matrix(T_board_base))
    return PixelSetup(model, cams, scene.board, scene.board_frame, sigma, start=scene.presentation)


__all__ = [
    "BOARD_IMAGE_SHARE",
    "DEFAULT_SIGMA",
    "MAX_VIEW_ANGLE",
    "MIN_POINT_PX",
    "MIN_POINT_PX_CHARUCO",
    "VIEW_MARGIN_PX",
    "PixelSetup",
    "board_in_front",
    "board_seen",
    "draw_configurations",
    "setup_from_scene",
]
