"""What ``cpc2urdf plan ROBOT --cameras LINK ... --board BOARD.json --poses N`` writes.

A one-stage plan (:mod:`selfcal_plan`) in the plan file format ``cpc2urdf/plan@1``
(:mod:`plan_file`): the same ``robot``, ``units``, ``joints`` and ``configurations``; the
``measured_frames`` are the cameras; ``setup`` says ``"noise": {"model": "pixels", "sigma_px": S}``,
the cameras (link, K, D, image size), the board (``cpc2urdf/board@1`` fields in metres), the board's
frame (null: fixed in the world, ``T_world_base`` is then the base in the board's frame) and the
planning margins; ``prediction`` holds each camera's predicted RMS position [mm] and rotation
[deg] error in the board's frame over the held-out configurations, and ``random`` the same for
random plans of N candidates. Next to it, ``plan.csv``: the configurations as a joints CSV (a URDF
robot's joints by the URDF's names), to send to the robot and name the images after.
:func:`~plan_file.load_plan` refuses such a file in one line (it is not a stage-1 plan);
:func:`load_selfcal_plan` reads its configurations.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from cpc2urdf.errors import ConfigurationError, InputFileError, OutputError
from cpc2urdf.files.jsonio import dumps, read_json, require_format, write_all_atomic
from cpc2urdf.files.spec import RobotSpec
from cpc2urdf.files.units import Units
from cpc2urdf.identification.handeye.stage2 import DEFAULT_INTRINSICS
from cpc2urdf.identification.planning.outputs import joints_csv_text, output_paths
from cpc2urdf.identification.planning.pixel_setup import DEFAULT_SIGMA, PixelSetup, board_in_front
from cpc2urdf.identification.planning.plan_file import (
    PLAN_FORMAT,
    SELFCAL_NOISE_MODEL,
    joints_json,
    parse_configurations,
)
from cpc2urdf.identification.planning.selfcal_plan import SelfcalPlan, plan_selfcal
from cpc2urdf.identification.selfcal.pixel_problem import CameraModel
from cpc2urdf.identification.simulation.selfcal_experiment import SelfcalScene
from cpc2urdf.identification.simulation.truth import (
    DEFAULT_GEOMETRY_ERROR_R,
    DEFAULT_GEOMETRY_ERROR_T,
)
from cpc2urdf.identification.vision.boards.board import Board
from cpc2urdf.identification.vision.joints_csv import urdf_joint_columns
from cpc2urdf.model import RobotStructure
from cpc2urdf.transforms import Array


@dataclass
class SelfcalOutputs:
    """A one-stage plan and the texts of its files."""

    plan: SelfcalPlan
    setup: PixelSetup
    doc: dict[str, Any]
    csv_text: str


def selfcal_setup(
    spec: RobotSpec,
    cameras: Sequence[str],
    board: Board,
    *,
    board_link: str | None = None,
    intrinsics: Sequence[CameraModel] | None = None,
    sigma: float = DEFAULT_SIGMA,
    distance: float | None = None,
    ranges: Mapping[str, tuple[float, float]] | None = None,
) -> tuple[PixelSetup, dict[str, str]]:
    """The planning setup of a robot's ``cameras`` (a URDF's links, ``LINK:optical``/``LINK:body``
    where it cannot tell, or a spec's optical frames) and ``board``, fixed in front of the cameras
    (:func:`board_in_front`, ``distance``) or, with ``board_link``, held by that link: a URDF's
    board is placed as the simulator places it (facing the cameras at a presentation
    configuration found by search, candidates walked from there); a spec's is that frame.
    Also: camera frame -> the name the user gave.

    Raises:
        ConfigurationError, InputFileError: A camera or board link the robot lacks; intrinsics
            not one per camera; a bad sigma or distance.
    """
    from cpc2urdf.urdf.camera_mounts import frame_name, optical_frames_model
    from cpc2urdf.urdf.robot import UrdfRobot

    if not (math.isfinite(sigma) and sigma > 0):
        raise ConfigurationError(f"corner noise must be a positive number of px, got {sigma}")
    if distance is not None and not (math.isfinite(distance) and distance > 0):
        raise ConfigurationError(f"--board-distance must be a positive number of m, got {distance}")
    if intrinsics is not None and len(intrinsics) != len(cameras):
        raise ConfigurationError(
            f"{len(intrinsics)} intrinsics files for {len(cameras)} cameras: give one per camera"
        )
    start = None
    if isinstance(spec, UrdfRobot) and board_link:  # the simulator's: facing the camera in front
        from cpc2urdf.identification.simulation.selfcal_experiment import selfcal_scene

        assert spec.tree is not None
        scene = selfcal_scene(
            spec.tree, cameras, board=board, board_link=board_link, sigma_t=0.0, sigma_r=0.0
        )
        model, board_frame, start = scene.nominal, scene.board_frame, scene.presentation
        names = dict(zip(scene.cameras, scene.camera_links, strict=True))
    elif isinstance(spec, UrdfRobot):
        assert spec.tree is not None
        model, cams = optical_frames_model(spec.tree, cameras, board_link)
        names = {frame_name(model, spec.tree, link): link for link in cams}
        board_frame = None
    else:
        model = spec.nominal_model()
        frames = model.structure.frame_names
        for f in [*cameras, *([board_link] if board_link else [])]:
            if f not in frames:
                raise ConfigurationError(
                    f"{f!r} is not a frame of robot {model.structure.name!r} ({list(frames)})"
                )
        names, board_frame = {c: c for c in cameras}, board_link
    default = CameraModel(
        DEFAULT_INTRINSICS.K,
        DEFAULT_INTRINSICS.D,
        (DEFAULT_INTRINSICS.width, DEFAULT_INTRINSICS.height),
    )
    cam = dict(zip(names, intrinsics or [default] * len(names), strict=True))
    if board_frame is None:
        model = board_in_front(model, cam, board, distance)
    r = model.structure.calibration_ranges(ranges)
    return PixelSetup(model, cam, board, board_frame, sigma, r, start=start), names


def _joint_board(setup: PixelSetup, u: Units) -> list[list[float]]:
    """A held board's placement on its link, in the model's frame of that link's joint (file
    units): what ``simulate --plan`` renders."""
    assert setup.board_frame is not None
    T = setup.nominal.frames[setup.board_frame].matrix().copy()
    T[:3, 3] /= u.length
    return [[float(v) for v in row] for row in T]


def selfcal_plan_to_json(
    plan: SelfcalPlan, setup: PixelSetup, *, robot: str, names: Mapping[str, str], seed: int
) -> dict[str, Any]:
    """The plan file's content (module docstring); joints in mm / deg."""

    u = Units("mm", "deg")
    s = setup.nominal.structure
    scale = np.array([u.joint_scale(j.type) for j in s.joints])
    T = setup.nominal.T_world_base().copy()
    T[:3, 3] /= u.length
    lo_hi = setup.calibration_ranges()
    rand = [r for r in plan.random if math.isfinite(r.position_rms)]
    return {
        "format": PLAN_FORMAT,
        "robot": robot,
        "units": u.to_json(),
        "joints": joints_json(setup.nominal, u),
        "measured_frames": list(setup.cameras),
        "strategy": "I-optimal",
        "one_joint": False,
        "configurations": [
            {"label": lab, "q": [float(v) for v in q / scale]}
            for lab, q in zip(plan.labels, plan.q, strict=True)
        ],
        "setup": {
            "kind": "selfcal",
            "noise": {"model": SELFCAL_NOISE_MODEL, "sigma_px": setup.sigma},
            "cameras": {
                c: {"name": names.get(c, c), "K": m.K.tolist(), "D": m.D.tolist()}
                | {"image_size": list(m.image_size)}
                for c, m in setup.cameras.items()
            },
            "board": setup.board.to_json(),
            "board_frame": setup.board_frame,
            "T_world_base": T.tolist(),
            **({"T_joint_board": _joint_board(setup, u)} if setup.board_frame else {}),
            "ranges": {
                j.name: [float(v) for v in lo_hi[i] / scale[i]] for i, j in enumerate(s.joints)
            },
            "margins": {
                "margin_px": setup.margin_px,
                "max_angle_deg": math.degrees(setup.max_angle),
                "min_point_px": setup.point_px,
            },
        },
        "task_region": {"kind": "board in view", "n": int(len(plan.heldout))},
        "candidates": {
            "kind": "random",
            "n": plan.candidates[0],
            "drawn": plan.candidates[1],
            "seed": seed,
        },
        "prediction": plan.prediction.to_json(),
        "random": {
            "plans": len(plan.random),
            "position_rms_mm_median": float(np.median([r.position_rms for r in rand])) * 1e3
            if rand
            else None,
            "orientation_rms_deg_median": (
                math.degrees(float(np.median([r.rotation_rms for r in rand]))) if rand else None
            ),
        },
        "target_error_mm": None,
        "curve": [],
    }


def plan_selfcal_robot(
    spec: RobotSpec,
    cameras: Sequence[str],
    board: Board,
    n: int,
    *,
    robot_ref: str,
    board_link: str | None = None,
    intrinsics: Sequence[CameraModel] | None = None,
    sigma: float = DEFAULT_SIGMA,
    distance: float | None = None,
    ranges: Mapping[str, tuple[float, float]] | None = None,
    n_candidates: int = 500,
    seed: int = 0,
) -> SelfcalOutputs:
    """``cpc2urdf plan --cameras``' one call: setup, plan, file texts (nothing written)."""
    setup, names = selfcal_setup(
        spec,
        cameras,
        board,
        board_link=board_link,
        intrinsics=intrinsics,
        sigma=sigma,
        distance=distance,
        ranges=ranges,
    )
    plan = plan_selfcal(setup, n, n_candidates=n_candidates, seed=seed)
    doc = selfcal_plan_to_json(plan, setup, robot=robot_ref, names=names, seed=seed)
    columns = {c: u for u, c in urdf_joint_columns(setup.nominal).items()}
    return SelfcalOutputs(
        plan, setup, doc, joints_csv_text(setup.nominal.structure, plan.q, plan.labels, columns)
    )


def write_selfcal_plan(out: SelfcalOutputs, path: str | os.PathLike[str]) -> tuple[Path, Path]:
    """Write ``plan.json`` and ``plan.csv``, both or neither."""
    json_path, csv_path, _ = output_paths(path)
    try:
        text = dumps(out.doc)
    except ValueError as e:
        raise OutputError(f"{json_path}: refusing to write non-finite numbers ({e})") from e
    write_all_atomic({json_path: text, csv_path: out.csv_text})
    return json_path, csv_path


@dataclass
class LoadedSelfcalPlan:
    """A one-stage plan file's configurations (SI), what it predicted (mm / deg) and where the
    board is [m]: fixed, the base's pose in the board's frame; held, the board's placement in
    the model's frame of its link's joint."""

    q: Array
    labels: list[str]
    joint_names: list[str]
    cameras: list[str]
    board_frame: str | None
    prediction: dict[str, Any]
    T_board_base: Array | None = None
    T_joint_board: Array | None = None


def load_selfcal_plan(
    path: str | os.PathLike[str], structure: RobotStructure | None = None
) -> LoadedSelfcalPlan:
    """Read a one-stage plan file (``q`` in the structure's joint order when given).

    Raises:
        InputFileError: Naming the file and the field; a stage-1 plan file.
    """
    p = Path(path)
    doc = require_format(read_json(p), PLAN_FORMAT, p)
    setup = doc.get("setup")
    if not isinstance(setup, dict) or setup.get("kind") != "selfcal":
        raise InputFileError(
            p, "not a one-stage plan (setup.kind is not 'selfcal'): read it with load_plan"
        )
    try:
        q, labels, names, _, _ = parse_configurations(doc, structure)
    except ValueError as e:
        raise InputFileError(p, str(e)) from None
    cams = doc.get("measured_frames")
    if not isinstance(cams, list) or not cams or not all(isinstance(c, str) for c in cams):
        raise InputFileError(p, "measured_frames must be the cameras' frame names")
    pred = doc.get("prediction")
    key = "T_world_base" if setup.get("board_frame") is None else "T_joint_board"
    T = np.asarray(setup.get(key), dtype=float)  # a fixed board: the plan's world is the board
    if T.shape != (4, 4) or not np.isfinite(T).all():
        raise InputFileError(p, f"setup.{key} must be a 4 x 4 matrix")
    T[:3, 3] *= Units.from_json(doc.get("units")).length
    held = setup.get("board_frame") is not None
    return LoadedSelfcalPlan(
        q,
        labels,
        names,
        cams,
        setup.get("board_frame"),
        pred if isinstance(pred, dict) else {},
        None if held else T,
        T if held else None,
    )


def render_head_images(
    urdf: str | os.PathLike[str],
    cameras: Sequence[str],
    board: Board,
    folder: str | os.PathLike[str],
    *,
    board_link: str | None = None,
    plan: str | os.PathLike[str] | None = None,
    poses: int = 20,
    seed: int = 0,
    sigma_t: float = DEFAULT_GEOMETRY_ERROR_T,
    sigma_r: float = DEFAULT_GEOMETRY_ERROR_R,
) -> tuple[SelfcalScene, Array]:
    """Render what ``urdf``'s cameras see of ``board`` into ``folder`` (``cpc2urdf simulate
    --cameras --board --images``): a true robot ``sigma_t`` / ``sigma_r`` off the URDF, at a
    plan's configurations with its board (``plan``), or at ``poses`` configurations of the
    simulator's walk. Returns the scene (the truth, the board's placement) and the joint
    readings, shape (N, n).

    Raises:
        ConfigurationError: A plan for another board placement or other cameras; a board that
            gives no unique pose.
    """
    from cpc2urdf.identification.simulation import selfcal_experiment as sx

    if board.pose_ambiguity:
        raise ConfigurationError(f"{board.name}: {board.pose_ambiguity}; use another board")
    loaded = load_selfcal_plan(plan) if plan is not None else None
    placement = None
    if loaded is not None:  # the plan's board: fixed where it planned it, or on the link
        if (loaded.T_board_base is None) != (board_link is not None):
            held = loaded.T_board_base is None
            raise ConfigurationError(
                f"{plan} was planned for a board {'held' if held else 'fixed'}; "
                + ("name the link holding it" if held else "it is not held")
            )
        placement = (
            loaded.T_joint_board
            if loaded.T_board_base is None
            else np.linalg.inv(loaded.T_board_base)
        )
    scene = sx.selfcal_scene(
        Path(urdf),
        cameras,
        board=board,
        board_link=board_link,
        seed=seed,
        sigma_t=sigma_t,
        sigma_r=sigma_r,
        placement=placement,
    )
    if loaded is not None:
        if sorted(loaded.cameras) != sorted(scene.cameras):
            raise ConfigurationError(f"{plan} was planned for cameras {loaded.cameras}")
        q = loaded.q[:, [loaded.joint_names.index(j) for j in scene.truth.structure.joint_names]]
    else:
        q = sx.selfcal_configurations(scene, poses, np.random.default_rng([seed, 2]))
    sx.render_selfcal_experiment(Path(folder), scene, q, seed=seed)
    return scene, q


__all__ = [
    "LoadedSelfcalPlan",
    "SelfcalOutputs",
    "load_selfcal_plan",
    "plan_selfcal_robot",
    "render_head_images",
    "selfcal_plan_to_json",
    "selfcal_setup",
    "write_selfcal_plan",
]
