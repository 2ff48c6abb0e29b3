"""Images for a head calibrated by its own cameras: any URDF robot, a board fixed or held.

1. :func:`selfcal_scene`: the URDF's sub-tree to the camera links (and to ``board_link``, a gripper,
   for a held board) in CPC form with the cameras' optical frames (:func:`~cpc2urdf.identification.
   handeye.urdf_stage2.camera_rig`), and a "true" robot whose joints, camera mounts and board
   placement all differ (:func:`~cpc2urdf.identification.simulation.truth.perturbed_model`). A
   fixed board faces the cameras ``distance`` ahead at home; a held board is fixed to the gripper
   so that it does so at a *presentation* configuration (a seeded search over all joints).
2. :func:`selfcal_configurations`: configurations where every camera sees the whole board
   (:func:`~cpc2urdf.identification.simulation.visibility.board_in_view`), explored by a seeded
   random walk from there and spread by farthest-point selection (excitation).
3. :func:`render_selfcal_experiment`: the folder ``measure_head`` reads (``<camera link>/<record>.png``,
   ``<camera link>.yaml``, ``joints.csv``) plus ``board.json``, ``selfcal_truth.json``
   (:data:`TRUTH_FORMAT`), ``truth_model.json`` and ``nominal_model.json``.
4. :func:`exact_corners`: the true pixels of the board's points, to score a detector.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cpc2urdf.errors import ConfigurationError, DegenerateDataError
from cpc2urdf.files.jsonio import make_folder, write_json
from cpc2urdf.files.model_file import save_model
from cpc2urdf.identification.handeye.stage2 import (
    DEFAULT_INTRINSICS,
    CameraIntrinsics,
    default_target_placement,
    home_configuration,
)
from cpc2urdf.identification.handeye.urdf_stage2 import camera_rig
from cpc2urdf.identification.simulation.design import farthest_points, walk_configurations
from cpc2urdf.identification.simulation.image_experiment import write_camera_images
from cpc2urdf.identification.simulation.truth import (
    DEFAULT_GEOMETRY_ERROR_R,
    DEFAULT_GEOMETRY_ERROR_T,
    perturbed_model,
)
from cpc2urdf.identification.simulation.visibility import board_in_view
from cpc2urdf.identification.vision.boards.board import Board
from cpc2urdf.identification.vision.boards.board_file import save_board
from cpc2urdf.identification.vision.render import PinholeView, render_board_view
from cpc2urdf.model import CPCModel, CPCParams, Frame
from cpc2urdf.transforms import Array, inverse
from cpc2urdf.urdf.robot import NameMap
from cpc2urdf.urdf.tree import UrdfTree, read_urdf_tree

TRUTH_FORMAT = "cpc2urdf/selfcal-truth@1"
BOARD_FRAME = "board"
DEFAULT_DISTANCE = 0.6  # [m] board ahead of the cameras (home / presentation)
STANDOFF = 0.05  # [m] a held board is this much nearer the cameras than the gripper's origin
MAX_VIEW_ANGLE_DEG = 60.0  # board normal vs line of sight
MIN_POINT_PX = {"charuco": 25.0}  # neighbouring points this far apart in the image [px] (markers
DEFAULT_MIN_POINT_PX = 10.0  # need ~4 px per bit); other boards: DEFAULT_MIN_POINT_PX
SECONDS_PER_IMAGE = 0.04  # rendering a 640 x 480 board view, for the progress bar's choice


@dataclass(frozen=True)
class SelfcalScene:
    """A robot, its head cameras and a board (module docstring).

    Attributes:
        urdf, board, seed, sigma_t, sigma_r: As given to :func:`selfcal_scene`.
        nominal: The URDF's sub-tree in CPC form: camera optical frames (kind ``camera``) and, when
            held, ``board`` (kind ``frame``) on the gripper's link. ``truth``: it perturbed.
        cameras, camera_links: The cameras' optical frames in the models and their URDF links.
        board_frame, board_link: ``"board"`` and the URDF link holding it; None, None when fixed.
        T_world_board: A fixed board's true pose in ``truth``'s world [m]; None when held.
        presentation: Home (fixed board) or the presentation (held), shape (n,).
    """

    urdf: Path
    nominal: CPCModel
    truth: CPCModel
    cameras: tuple[str, ...]
    camera_links: tuple[str, ...]
    board: Board
    board_frame: str | None
    board_link: str | None
    T_world_board: Array | None
    presentation: Array
    seed: int
    sigma_t: float
    sigma_r: float

    @property
    def robot(self) -> str:
        """The robot's name (the URDF's)."""
        return self.nominal.structure.name

    def board_poses(self, q: ArrayLike, model: CPCModel | None = None) -> Array:
        """``T_world_board`` at configurations ``q`` (N, n) in ``model`` (default the truth), (N, 4, 4)."""
        qq = np.atleast_2d(np.asarray(q, dtype=float))
        if self.board_frame is None:
            assert self.T_world_board is not None
            return np.broadcast_to(self.T_world_board, (len(qq), 4, 4)).copy()
        return (model or self.truth).fk_frame(self.board_frame, qq)

    def T_camera_board(self, camera: str, q: ArrayLike, model: CPCModel | None = None) -> Array:
        """The board in ``camera``'s optical frame at configurations ``q`` (N, n), (N, 4, 4)."""
        qq = np.atleast_2d(np.asarray(q, dtype=float))
        m = model or self.truth
        return inverse(m.fk_frame(camera, qq)) @ self.board_poses(qq, m)


def selfcal_scene(
    urdf: str | Path | UrdfTree,
    cameras: Sequence[str],
    *,
    board: Board,
    board_link: str | None = None,
    seed: int = 0,
    sigma_t: float = DEFAULT_GEOMETRY_ERROR_T,
    sigma_r: float = DEFAULT_GEOMETRY_ERROR_R,
    distance: float = DEFAULT_DISTANCE,
    placement: ArrayLike | None = None,
) -> SelfcalScene:
    """The scene of a head seeing ``board`` (module docstring).

    Args:
        urdf: The robot.
        cameras: Camera links (``LINK:optical``/``LINK:body`` where the URDF cannot tell).
        board: The board.
        board_link: The URDF link that holds the board (a gripper); None: the board is fixed.
        seed: Seed of the presentation search and of the truth.
        sigma_t, sigma_r: The truth's geometric errors [m] per CPC offset, [rad].
        distance: How far ahead of the cameras the board is at home / presentation [m].
        placement: The board's nominal placement instead (a plan's): ``T_base_board`` when fixed;
            when held, its pose in the model's frame of ``board_link``'s joint; shape (4, 4) [m].

    Raises:
        InputFileError: As :func:`~cpc2urdf.identification.handeye.urdf_stage2.camera_rig` (also
            for the board link). ConfigurationError: A bad distance or sigma; a camera board link.
    """
    if not (math.isfinite(distance) and distance > 0):
        raise ConfigurationError(f"board distance must be a finite number > 0, got {distance:g}")
    for what, v in (("sigma_t", sigma_t), ("sigma_r", sigma_r)):
        if not (math.isfinite(v) and v >= 0):
            raise ConfigurationError(f"{what} must be a finite number >= 0, got {v:g}")
    tree = urdf if isinstance(urdf, UrdfTree) else read_urdf_tree(urdf)
    rig = camera_rig(tree, cameras, holding=board_link)
    links = tuple(rig.cameras)
    cams = tuple(rig.optical[link] for link in links)
    if board_link in rig.cameras or BOARD_FRAME in cams:
        raise ConfigurationError(f"board link {board_link!r} is one of the cameras {list(links)}")
    search, perturb = (np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(2))
    base = rig.model.without_frames(["frame"])  # the camera optical frames (and the gripper's)
    T_world_board: Array | None = None
    if board_link is None:
        nominal = base
        truth = perturbed_model(nominal, perturb, sigma_t, sigma_r)
        start = home_configuration(truth)
        T_base_board = (
            default_target_placement(truth, cams, distance)
            if placement is None
            else np.asarray(placement, dtype=float)
        )
        T_world_board = truth.T_world_base() @ T_base_board
    else:
        grip = NameMap.of(tree).links[board_link]
        if placement is None:
            start = _presentation(base, cams, grip, distance + STANDOFF, search)
            nominal = _with_held_board(base, cams, grip, start)
        else:  # as given, in the frame of the link's joint
            start = home_configuration(base)
            nominal = base.without_frames(["plate"]).with_frame(
                Frame(BOARD_FRAME, base.structure.frame(grip).parent, "frame"),
                CPCParams.from_matrix(np.asarray(placement, dtype=float)),
            )
        truth = perturbed_model(nominal, perturb, sigma_t, sigma_r)
    return SelfcalScene(
        Path(tree.source),
        nominal,
        truth,
        cams,
        links,
        board,
        None if board_link is None else BOARD_FRAME,
        board_link,
        T_world_board,
        start,
        seed,
        sigma_t,
        sigma_r,
    )


def _presentation(
    model: CPCModel, cameras: Sequence[str], grip: str, distance: float, rng: np.random.Generator
) -> Array:
    """A configuration with frame ``grip`` ``distance`` ahead of every camera, near its optical
    axis, the joints near the middle of their calibration ranges: the best of random draws over
    the ranges, then refined by shrinking random steps around it."""
    lo, hi = model.structure.calibration_ranges().T
    u = rng.uniform(size=(4096, len(lo)))
    best = u[0]
    for step in (0.0, 0.1, 0.03, 0.01):
        if step > 0:
            u = np.clip(best + step * rng.normal(size=(512, len(lo))), 0.0, 1.0)
            u[0] = best
        q = lo + u * (hi - lo)
        fk = model.fk(q, [*cameras, grip])
        cost = 0.25 * np.mean((2 * u - 1) ** 2, axis=1)
        for c in cameras:
            p = np.einsum("nji,nj->ni", fk[c][:, :3, :3], fk[grip][:, :3, 3] - fk[c][:, :3, 3])
            z = p[:, 2]
            off = np.hypot(p[:, 0], p[:, 1]) / np.maximum(z, 1e-9)
            cost += np.where(z > 0, np.abs(z - distance) / distance + off, np.inf) / len(cameras)
        best = u[int(np.argmin(cost))]
    return lo + best * (hi - lo)


def _with_held_board(model: CPCModel, cameras: Sequence[str], grip: str, q: Array) -> CPCModel:
    """``model`` with the board (frame :data:`BOARD_FRAME`) on ``grip``'s link, placed so that at
    ``q`` it faces the cameras on their mean optical axis, :data:`STANDOFF` nearer to them than
    ``grip``'s origin; ``grip``'s own frame dropped."""
    fk = model.fk(q, [*cameras, grip])
    d = np.mean([fk[c][:3, 2] for c in cameras], axis=0)
    d /= np.linalg.norm(d)
    centre = np.mean([fk[c][:3, 3] for c in cameras], axis=0)
    depth = (fk[grip][:3, 3] - centre) @ d - STANDOFF
    T_world_board = model.T_world_base() @ default_target_placement(model, cameras, depth, q)
    parent = model.structure.frame(grip).parent
    T_world_parent = fk[grip] @ inverse(model.frames[grip].matrix())
    T_parent_board = inverse(T_world_parent) @ T_world_board
    return model.without_frames(["plate"]).with_frame(
        Frame(BOARD_FRAME, parent, "frame"), CPCParams.from_matrix(T_parent_board)
    )


def _intrinsics(
    scene: SelfcalScene, intrinsics: CameraIntrinsics | Mapping[str, CameraIntrinsics]
) -> dict[str, CameraIntrinsics]:
    """Camera frame -> its intrinsics (one for all, or a mapping that names every camera)."""
    if isinstance(intrinsics, CameraIntrinsics):
        return dict.fromkeys(scene.cameras, intrinsics)
    missing = [c for c in scene.cameras if c not in intrinsics]
    if missing:
        raise ConfigurationError(f"no intrinsics for cameras {missing} of {scene.robot}")
    return {c: intrinsics[c] for c in scene.cameras}


def in_view(
    scene: SelfcalScene,
    q: ArrayLike,
    intrinsics: CameraIntrinsics | Mapping[str, CameraIntrinsics] = DEFAULT_INTRINSICS,
    *,
    max_angle_deg: float = MAX_VIEW_ANGLE_DEG,
    min_point_px: float | None = None,
    margin_px: float = 10.0,
) -> NDArray[np.bool_]:
    """Per configuration of ``q`` (N, n): every camera of the truth sees the whole board
    (:func:`~cpc2urdf.identification.simulation.visibility.board_in_view`). Shape (N,)."""
    qq = np.atleast_2d(np.asarray(q, dtype=float))
    px = MIN_POINT_PX.get(scene.board.kind, DEFAULT_MIN_POINT_PX)
    ok = np.ones(len(qq), dtype=bool)
    for c, intr in _intrinsics(scene, intrinsics).items():
        view = PinholeView(intr.K, intr.D, (intr.width, intr.height))
        ok &= board_in_view(
            view,
            scene.board,
            scene.T_camera_board(c, qq),
            margin_px=margin_px,
            max_angle=math.radians(max_angle_deg),
            min_point_px=px if min_point_px is None else min_point_px,
        )
    return ok


def selfcal_configurations(
    scene: SelfcalScene,
    n: int,
    rng: np.random.Generator,
    *,
    intrinsics: CameraIntrinsics | Mapping[str, CameraIntrinsics] = DEFAULT_INTRINSICS,
    max_angle_deg: float = MAX_VIEW_ANGLE_DEG,
    min_point_px: float | None = None,
    steps: int | None = None,
) -> Array:
    """``n`` joint readings (``structure.joint_names`` order), shape (n, n_joints), at which every
    camera sees the whole board (:func:`in_view`), spread over the calibration ranges.

    A random walk of ``steps`` (default ``max(400, 40 n)``) steps from ``scene.presentation``
    (:func:`~cpc2urdf.identification.simulation.design.walk_configurations`), then ``n`` of the
    configurations it visited by farthest-point selection: the widest excitation visibility allows.

    Raises:
        ConfigurationError: ``n`` < 1. DegenerateDataError: The board out of view at the start,
            or fewer than ``n`` configurations found (names the robot and the cameras).
    """
    if n < 1:
        raise ConfigurationError(f"ask for at least one configuration, got {n}")
    ranges = scene.truth.structure.calibration_ranges()

    def usable(q: Array) -> NDArray[np.bool_]:
        return in_view(scene, q, intrinsics, max_angle_deg=max_angle_deg, min_point_px=min_point_px)

    where = f"{scene.robot}, cameras {list(scene.camera_links)}"
    if not usable(scene.presentation[None])[0]:
        raise DegenerateDataError(
            f"{where}: the board is not wholly in view of every camera at the start configuration; "
            "use a smaller board, another distance, or wider images"
        )
    pool = walk_configurations(usable, scene.presentation, ranges, rng, steps or max(400, 40 * n))
    if len(pool) < n:
        raise DegenerateDataError(
            f"{where}: only {len(pool)} of {n} configurations keep the whole board in view"
        )
    return farthest_points(pool, n, ranges, rng)


def joint_coverage(scene: SelfcalScene, q: ArrayLike) -> dict[str, float]:
    """Per joint, the share of its calibration range that ``q`` (N, n) spans (max - min)."""
    qq = np.atleast_2d(np.asarray(q, dtype=float))
    lo, hi = scene.truth.structure.calibration_ranges().T
    spread = (qq.max(axis=0) - qq.min(axis=0)) / np.where(hi > lo, hi - lo, 1.0)
    return dict(zip(scene.truth.structure.joint_names, spread.tolist(), strict=True))


def exact_corners(
    scene: SelfcalScene,
    q: ArrayLike,
    intrinsics: CameraIntrinsics | Mapping[str, CameraIntrinsics] = DEFAULT_INTRINSICS,
    model: CPCModel | None = None,
) -> dict[str, Array]:
    """Camera frame -> the true pixels of the board's points (``board.object_points()``, id =
    row) at each configuration of ``q`` (N, n), by ``cv2.projectPoints`` with the camera's K, D in
    ``model`` (default the truth). Shape (N, n_points, 2) per camera."""
    qq = np.atleast_2d(np.asarray(q, dtype=float))
    obj = scene.board.object_points()
    out: dict[str, Array] = {}
    for c, i in _intrinsics(scene, intrinsics).items():
        T = scene.T_camera_board(c, qq, model)  # PinholeView.project: cv2.projectPoints
        out[c] = np.array([PinholeView(i.K, i.D, (i.width, i.height), t).project(obj) for t in T])
    return out


def render_selfcal_experiment(
    folder: str | Path,
    scene: SelfcalScene,
    q: ArrayLike,
    *,
    intrinsics: CameraIntrinsics | Mapping[str, CameraIntrinsics] = DEFAULT_INTRINSICS,
    blur_sigma: float = 0.7,
    noise_sigma: float = 2.0,
    seed: int = 0,
    show_progress: bool | None = None,
) -> dict[str, Path]:
    """Render what the truth's cameras see of the board at ``q`` (N, n) and write ``folder``
    (module docstring). ``show_progress``: a bar on stderr (default: when rendering takes over
    ~2 s). Returns the written files by role (camera frame -> its ``.yaml``, ``joints``,
    ``board``, ``selfcal_truth``, ``truth_model``, ``nominal_model``)."""
    qq = scene.truth.structure.check_q(np.atleast_2d(np.asarray(q, dtype=float)))
    intr = _intrinsics(scene, intrinsics)
    out = make_folder(folder)
    T_world_board = scene.board_poses(qq)
    rng = np.random.default_rng(seed)

    def image(view: PinholeView, i: int) -> NDArray[np.uint8]:
        return render_board_view(
            view,
            [(scene.board, T_world_board[i])],
            blur_sigma=blur_sigma,
            noise_sigma=noise_sigma,
            rng=rng,
        )

    if show_progress is None:
        show_progress = len(qq) * len(intr) * SECONDS_PER_IMAGE > 2.0
    folders = dict(zip(scene.cameras, scene.camera_links, strict=True))  # as the user names them
    paths = write_camera_images(
        out, scene.truth, intr, qq, image, show_progress=show_progress, folders=folders
    )
    paths["board"] = save_board(scene.board, out / "board.json")
    paths["truth_model"] = save_model(scene.truth, out / "truth_model.json")
    paths["nominal_model"] = save_model(scene.nominal, out / "nominal_model.json")
    doc = _truth_document(scene, intr, blur_sigma, noise_sigma, seed)
    paths["selfcal_truth"] = write_json(out / "selfcal_truth.json", doc)
    return paths


def _truth_document(
    scene: SelfcalScene,
    intrinsics: Mapping[str, CameraIntrinsics],
    blur: float,
    noise: float,
    seed: int,
) -> dict[str, Any]:
    """``selfcal_truth.json`` (:data:`TRUTH_FORMAT`, SI units)."""
    return {
        "format": TRUTH_FORMAT,
        "description": f"simulated self-calibration of {scene.robot}: the true robot is "
        "truth_model.json, the URDF's nominal_model.json",
        "urdf": str(scene.urdf.resolve()),
        "robot": scene.robot,
        "cameras": list(scene.cameras),
        "camera_links": list(scene.camera_links),
        "board_frame": scene.board_frame,
        "board_link": scene.board_link,
        "T_world_board": None if scene.T_world_board is None else scene.T_world_board.tolist(),
        "presentation": scene.truth.structure.q_to_dict(scene.presentation),
        "intrinsics": {
            c: {"K": i.K.tolist(), "D": i.D.tolist(), "image_size": [i.width, i.height]}
            for c, i in intrinsics.items()
        },
        "blur_sigma_px": blur,
        "noise_sigma_grey_levels": noise,
        "render_seed": seed,
        "scene_seed": scene.seed,
        "sigma_t": scene.sigma_t,
        "sigma_r": scene.sigma_r,
        "units": {"length": "m", "angle": "rad"},
    }


__all__ = [
    "BOARD_FRAME",
    "TRUTH_FORMAT",
    "SelfcalScene",
    "exact_corners",
    "in_view",
    "joint_coverage",
    "render_selfcal_experiment",
    "selfcal_configurations",
    "selfcal_scene",
]
