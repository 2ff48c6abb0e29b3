"""The Python API: the whole pipeline, with the same defaults as the command line.

Every ``cpc2urdf`` command is a thin layer over one function here; ``import cpc2urdf`` re-exports
them all. A typical session::

    import cpc2urdf

    ms = cpc2urdf.load_measurements("measurements.json")   # resolves the robot the file names
    model = cpc2urdf.identify(ms)                           # closed form + ML refinement
    model = cpc2urdf.calibrate_cameras(model, "handeye_camera_left_optical.json")
    cpc2urdf.save_model(model, "model.json")
    cpc2urdf.export_urdf(model, "head.urdf")
    assert cpc2urdf.check_urdf(model, "head.urdf").ok

Conventions: SI units (m, rad); ``T_a_b`` is the pose of frame b in frame a; camera optical
frames follow REP-103 (z forward, x right, y down). The layers, and where each concept lives, are
described in ``docs/architecture.md``.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, overload

import numpy as np
from numpy.typing import ArrayLike

from cpc2urdf.api.cameras import (
    calibrate_cameras,
    calibrate_head,
    camera_mount,
    load_handeye_poses,
    solve_handeye,
)
from cpc2urdf.errors import ConfigurationError, UnknownNameError
from cpc2urdf.files.measurements import MeasurementSet, load_measurements
from cpc2urdf.files.model_file import save_model
from cpc2urdf.files.robot_ref import RobotRef, is_urdf_ref, load_model, load_robot
from cpc2urdf.files.spec import RobotSpec
from cpc2urdf.model import CPCModel

if TYPE_CHECKING:  # the stages are imported inside the functions that use them
    from cpc2urdf.identification.handeye.urdf_stage2 import HandEyeSimulation
    from cpc2urdf.identification.planning.outputs import PlanOutputs
    from cpc2urdf.identification.planning.plan_file import LoadedPlan
    from cpc2urdf.identification.planning.selfcal_plan_file import SelfcalOutputs
    from cpc2urdf.identification.simulation.selfcal_experiment import SelfcalScene
    from cpc2urdf.identification.simulation.stage1_experiment import Experiment
    from cpc2urdf.model import RobotStructure
    from cpc2urdf.urdf.report import CalibrationReport
    from cpc2urdf.validation.crosscheck import CrossCheckReport
    from cpc2urdf.validation.gaze import GazeSolver
    from cpc2urdf.validation.gaze.options import GazeOptions
    from cpc2urdf.validation.gaze.reachable import Region
    from cpc2urdf.validation.heldout import BranchAccuracy
    from cpc2urdf.validation.view import ViewRobot, ViewSummary

PathLike = str | os.PathLike[str]


def load_marker_csv(
    points_csv: PathLike,
    robot: RobotRef,
    markers: Mapping[str, str],
    *,
    joints_csv: PathLike | None = None,
    known_positions: Mapping[str, Sequence[float]] | None = None,
    length: str | None = None,
    angle: str | None = None,
    noise_sigma_p: float | None = None,
) -> MeasurementSet:
    """A tracker's CSV export (``docs/measurements.md``, position-only data) as measurements for
    :func:`identify`.

    Args:
        points_csv: One row per configuration and marker: ``config,marker,x,y,z[,<joint>...]``.
        robot: The robot (shipped name, spec, or URDF path).
        markers: The link each marker is fixed to, ``{marker: link}``.
        joints_csv: The joint readings, ``config,<joint>...``, when they are not in ``points_csv``.
        known_positions: Markers whose position on their link is known [file units]; the others
            are identified.
        length, angle: The files' units when no ``# units:`` header states them (``mm``, ``deg``...).
        noise_sigma_p: The instrument's noise per coordinate [m], if known.
    """
    from cpc2urdf.files.marker_csv import load_marker_csv as _load_marker_csv

    return _load_marker_csv(
        points_csv,
        load_robot(robot),
        markers,
        robot_ref=os.fspath(robot) if isinstance(robot, (str, os.PathLike)) else None,
        joints_csv=joints_csv,
        known_positions=known_positions,
        length=length,
        angle=angle,
        noise_sigma_p=noise_sigma_p,
    )


def measurements_from_bag(
    bag: PathLike,
    poses: Mapping[str, str],
    *,
    robot: RobotRef = "iis_head",
    joint_topic: str = "/joint_states",
    sync_tolerance: float = 0.02,
    rest_window: float = 0.1,
) -> MeasurementSet:
    """Stage-1 measurements from a ROS bag (``cpc2urdf bag --pose``): joint states paired with pose
    topics by header stamps (``docs/bags.md``); samples taken while a joint moved are skipped.

    Args:
        bag: A rosbag1 ``.bag`` file or a rosbag2 folder.
        poses: ``{frame: "topic"}`` (PoseStamped, TransformStamped) or ``{frame: "topic:parent:child"}`` (tf).
        robot: Shipped name, spec or URDF path.
        joint_topic: The ``sensor_msgs/JointState`` topic.
        sync_tolerance: Largest gap [s] between a pose and the joint state paired with it.
        rest_window: Every joint reading within this time [s] of a sample must agree with it (0: off).
    """
    from cpc2urdf.identification.vision.bags.bag_source import PoseTopic, SyncRule
    from cpc2urdf.identification.vision.bags.bag_source import measurements_from_bag as _from_bag

    topics = [PoseTopic.parse(f"{frame}={topic}") for frame, topic in poses.items()]
    rule = SyncRule(sync_tolerance=sync_tolerance, rest_window=rest_window)
    ref = os.fspath(robot) if isinstance(robot, (str, os.PathLike)) else "robot"
    return _from_bag(
        bag, load_robot(robot), topics, robot_ref=ref, joint_topic=joint_topic, rule=rule
    ).measurements


@overload
def simulate(
    robot: RobotRef = ...,
    *,
    measure: Sequence[str] | None = ...,
    seed: int = ...,
    M: int = ...,
    sigma_mm: float = ...,
    sigma_deg: float = ...,
    heldout: int = ...,
    cameras: None = ...,
    poses: int = ...,
    pixel_noise: float = ...,
    camera_error_mm: float = ...,
    camera_error_deg: float = ...,
    board: None = ...,
    board_link: None = ...,
    plan: None = ...,
    images: None = ...,
) -> Experiment: ...


@overload
def simulate(
    robot: RobotRef = ...,
    *,
    measure: Sequence[str] | None = ...,
    seed: int = ...,
    M: int = ...,
    sigma_mm: float = ...,
    sigma_deg: float = ...,
    heldout: int = ...,
    cameras: Sequence[str],
    poses: int = ...,
    pixel_noise: float = ...,
    camera_error_mm: float = ...,
    camera_error_deg: float = ...,
    board: None = ...,
    board_link: None = ...,
    plan: None = ...,
    images: None = ...,
) -> HandEyeSimulation: ...


@overload
def simulate(
    robot: RobotRef = ...,
    *,
    measure: Sequence[str] | None = ...,
    seed: int = ...,
    M: int = ...,
    sigma_mm: float = ...,
    sigma_deg: float = ...,
    heldout: int = ...,
    cameras: Sequence[str],
    poses: int = ...,
    pixel_noise: float = ...,
    camera_error_mm: float = ...,
    camera_error_deg: float = ...,
    board: PathLike,
    board_link: str | None = ...,
    plan: PathLike | None = ...,
    images: PathLike,
) -> SelfcalScene: ...


def simulate(
    robot: RobotRef = "iis_head",
    *,
    measure: Sequence[str] | None = None,
    seed: int = 0,
    M: int = 9,
    sigma_mm: float = 0.5,
    sigma_deg: float = 0.5,
    heldout: int = 50,
    cameras: Sequence[str] | None = None,
    poses: int = 20,
    pixel_noise: float = 0.1,
    camera_error_mm: float = 5.0,
    camera_error_deg: float = 3.0,
    board: PathLike | None = None,
    board_link: str | None = None,
    plan: PathLike | None = None,
    images: PathLike | None = None,
) -> Experiment | HandEyeSimulation | SelfcalScene:
    """A simulated stage-1 experiment in memory (``cpc2urdf simulate``): a true robot (the nominal
    one with random geometric error), its plates measured with Fig. 10 pose noise while one joint
    moves at a time, and held-out configurations with their true poses. With ``cameras``, stage 2
    of a URDF robot's cameras instead (``cpc2urdf simulate ROBOT.urdf --cameras``, docs/handeye.md).

    Args:
        robot: Shipped name, spec, model file or URDF path (a URDF needs ``measure`` or ``cameras``).
        measure: A URDF's measured links (plate, marker or camera links on fixed joints).
        seed: Seed of everything random (the same seed gives the same experiment).
        M: Values per joint over its calibration range.
        sigma_mm, sigma_deg: The pose noise (translation per entry, rotation angle).
        heldout: Held-out configurations.
        cameras: A URDF's camera links, optical (z forward) or body (x forward); ``LINK:optical``
            or ``LINK:body`` where the file cannot tell.
        poses: Stage 2: configurations in which every camera sees the 25-disk target.
        pixel_noise: Stage 2: std of the image noise per coordinate [px].
        camera_error_mm, camera_error_deg: Stage 2: the true mounts are the URDF's moved by up to
            this per axis and turned by this about a random axis.
        board, board_link, plan, images: With ``cameras``: render the cameras' images of this
            board (its file), fixed or held by ``board_link``, into the folder ``images``, at a
            one-stage plan's configurations (``plan``) or ``poses`` of the simulator's own, the
            robot 1 mm / 0.5 deg off the URDF (``simulate --board --images``, docs/selfcal.md).

    Returns:
        ``(truth, measured, heldout)``, as :class:`cpc2urdf.identification.simulation.stage1_experiment.Experiment`;
        with ``cameras`` a :class:`~cpc2urdf.identification.handeye.urdf_stage2.HandEyeSimulation`
        (hand-eye poses per camera, the true mounts).
    """
    from cpc2urdf.identification.simulation.stage1_experiment import (
        measured_robot,
        simulate_experiment,
    )

    ref = os.fspath(robot) if isinstance(robot, (str, os.PathLike)) else None
    if images is not None or board is not None:
        from cpc2urdf.identification.planning.selfcal_plan_file import render_head_images
        from cpc2urdf.identification.vision.boards.board_file import load_board

        if (
            cameras is None
            or board is None
            or images is None
            or ref is None
            or not is_urdf_ref(ref)
        ):
            raise ConfigurationError("images need a URDF path, cameras=, board= and images=")
        scene, _ = render_head_images(
            ref,
            cameras,
            load_board(board),
            images,
            board_link=board_link,
            plan=plan,
            poses=poses,
            seed=seed,
        )
        return scene
    if cameras is not None:
        from cpc2urdf.identification.handeye.urdf_stage2 import simulate_handeye

        if measure is not None or ref is None or not is_urdf_ref(ref):
            raise ConfigurationError(
                "cameras= simulates stage 2 of a URDF robot: give a URDF path and no measure="
            )
        return simulate_handeye(
            ref,
            cameras,
            n_poses=poses,
            pixel_noise=pixel_noise,
            seed=seed,
            translation=camera_error_mm / 1000,
            rotation=float(np.radians(camera_error_deg)),
        )
    spec = measured_robot(load_robot(robot), ref or "robot", measure, option="measure=")
    exp = simulate_experiment(
        spec,
        seed=seed,
        M=M,
        sigma_t=sigma_mm / 1000,
        sigma_r=np.radians(sigma_deg),
        n_heldout=heldout,
        robot_ref=ref,
    )
    # the sets keep their robot, as when read from the files `cpc2urdf simulate` writes
    return exp._replace(
        measured=dataclasses.replace(exp.measured, spec=spec),
        heldout=dataclasses.replace(exp.heldout, spec=spec),
    )


def identify(
    measurements: MeasurementSet | PathLike,
    method: str = "refined",
    nominal: CPCModel | None = None,
    *,
    robot: RobotRef | None = None,
    accept_inconsistent: bool = False,
    level: str | None = None,
    joints: Sequence[str] | None = None,
) -> CPCModel:
    """Identify a robot's CPC model from stage-1 measurements (``cpc2urdf identify``).

    Args:
        measurements: A :class:`MeasurementSet` or a ``cpc2urdf/measurements@1`` file.
        method: One of :data:`METHODS` (default ``"refined"``: the closed form of Shih et al.
            sec. 4.2, then maximum-likelihood refinement of every record).
        nominal: Nominal model that keeps unmeasured frames (cameras) and fixes what the data
            leave open; default: the nominal model of the robot the measurements name.
        robot: With a file path: use this robot instead of the file's ``"robot"``.
        accept_inconsistent: Keep a model whose data fail the consistency gate (the diagnosis is
            stored in its notes and provenance) instead of raising.
        level: With ``method="map"``: fit this level alone (``frames``, ``offsets``, ``geometry``,
            ``compliance``) instead of choosing one by cross-validation.
        joints: With ``method="map"``: the joints to calibrate (URDF names); every other joint
            keeps the URDF's values (default: those the data move on the paths to the measured links).

    Returns:
        The identified model; ``model.metadata`` (typed sections) holds ``provenance``, ``residuals``,
        ``uncertainty`` (refined methods) and ``notes``.
    """
    from cpc2urdf.identification.kinematics.methods import identify as _identify
    from cpc2urdf.urdf.robot import attach_urdf_source

    if isinstance(measurements, MeasurementSet):
        if robot is not None:
            raise ConfigurationError(
                "robot= applies to a measurement file path, not to a MeasurementSet"
            )
        ms = measurements
    else:
        ms = load_measurements(measurements, robot=load_robot(robot) if robot is not None else None)
    loads = _gravity_loads(ms) if method == "map" and level in (None, "compliance") else None
    model = _identify(
        ms,
        method,
        nominal,
        accept_inconsistent=accept_inconsistent,
        loads=loads,
        level=level,
        joints=None if joints is None else _cpc_joints(ms, joints),
    )
    return attach_urdf_source(model, ms.spec)


def _gravity_loads(ms: MeasurementSet) -> Any:
    """The joints' gravity loads for the compliance level (Pinocchio, loaded only for it)."""
    from cpc2urdf.urdf.pinocchio import gravity_loads

    return gravity_loads(ms)


def _cpc_joints(ms: MeasurementSet, joints: Sequence[str]) -> list[str]:
    """The model's names of ``joints`` (a URDF robot's URDF names, or the model's own)."""
    from cpc2urdf.urdf.robot import UrdfRobot

    s = ms.structure
    robot = ms.spec
    urdf_names = (
        robot.names.joints if isinstance(robot, UrdfRobot) and robot.names is not None else {}
    )
    out = []
    for j in joints:
        name = urdf_names.get(j, j)
        if name not in s.joint_names:
            known = (
                [u for u, c in urdf_names.items() if c in s.joint_names]
                if urdf_names
                else list(s.joint_names)
            )
            raise UnknownNameError("joint", j, known)
        out.append(name)
    return out


def load_plan(path: PathLike, structure: RobotStructure | None = None) -> LoadedPlan:
    """Read a ``cpc2urdf/plan@1`` file (``docs/planning.md``); with ``structure``, the plan's joints
    must be exactly that robot's and ``q`` comes in its joint order."""
    from cpc2urdf.identification.planning.plan_file import load_plan as _load

    return _load(path, structure)


def export_urdf(
    model: CPCModel | RobotRef,
    path: PathLike,
    *,
    source: str | None = None,
    urdf: PathLike | None = None,
    mount: str = "base",
    up: ArrayLike | None = None,
) -> Path:
    """Write the URDF of a model, robot spec or shipped robot atomically (``cpc2urdf export``).

    A model identified from a user's URDF (or that URDF itself) is written back into THAT URDF:
    only the calibrated joints' origins change, with a calibration report next to it
    (``docs/urdf.md``); ``urdf`` names the copy to write into (default: the file it came from).
    Otherwise a simulation-ready URDF (inertials at the spec's density or masses, collisions,
    camera body frames): root ``world`` gravity-aligned at the base (``mount="base"``, the spec's
    ``up`` or ``up`` given here, in base coordinates) or the measuring rig (``mount="rig"``);
    ``source`` (default: the reference, when ``model`` is one) is named in the header.
    """
    from cpc2urdf.identification.kinematics.origin_uncertainty import origin_uncertainty
    from cpc2urdf.urdf.document import write_urdf
    from cpc2urdf.urdf.export_plan import plan_export
    from cpc2urdf.urdf.robot import urdf_source
    from cpc2urdf.urdf.writeback import write_calibrated_urdf

    plan = plan_export(model if not isinstance(model, RobotSpec) else model.nominal_model(), up=up)
    m = plan.model
    if urdf_source(m) is not None:
        return write_calibrated_urdf(
            m,
            Path(path),
            urdf=None if urdf is None else Path(urdf),
            uncertainty=origin_uncertainty(m),
        )
    if source is None and not isinstance(model, CPCModel | RobotSpec):
        source = os.fspath(model)
    return write_urdf(m, Path(path), source=source, mount=mount, physical=plan.physical)


def calibration_report(
    model: CPCModel | RobotRef, *, urdf: PathLike | None = None
) -> CalibrationReport:
    """What calibration changed in the URDF the model came from, per joint in mm and degrees,
    with 1-sigma from the model's covariance (``docs/urdf.md``)."""
    from cpc2urdf.identification.kinematics.origin_uncertainty import origin_uncertainty
    from cpc2urdf.urdf.origins import writeback_plan
    from cpc2urdf.urdf.report import calibration_report as _calibration_report

    m = model if isinstance(model, CPCModel) else load_model(model)
    plan = writeback_plan(m, None if urdf is None else Path(urdf))
    return _calibration_report(m, plan=plan, uncertainty=origin_uncertainty(m, plan))


def check_urdf(
    model: CPCModel | RobotRef, urdf: PathLike, configurations: int = 100, seed: int = 0
) -> CrossCheckReport:
    """FK of every frame of ``urdf`` by Pinocchio and yourdfpy against the CPC model, and urdfdom's
    parse of the tree, at ``configurations`` seeded random readings (``cpc2urdf check``).

    ``report.ok`` is True when all agree within :data:`cpc2urdf.tolerances.FK_AGREEMENT_TOL`.
    For a model identified from a user's URDF, ``urdf`` is the written-back file: every link on the
    calibrated paths is compared by the URDF's own link names (``cross_check_writeback``).
    """
    if configurations < 1:
        raise ConfigurationError(f"configurations must be at least 1, got {configurations}")
    from cpc2urdf.validation.crosscheck import cross_check

    m = model if isinstance(model, CPCModel) else load_model(model)
    return cross_check(m, urdf, configurations, seed)


def accuracy(
    model: CPCModel | RobotRef,
    measurements: MeasurementSet | PathLike,
    *,
    accept_inconsistent: bool = False,
) -> dict[str, BranchAccuracy]:
    """Held-out accuracy (Table 4 of Shih et al.; ``cpc2urdf accuracy``) of every frame the model has
    and the measurements hold, and of every marker the model identified, with the error the model's
    covariance predicts when it has one.

    Raises:
        DegenerateDataError: The joints differ, or no measured frame or marker is in the model.
        InconsistentDataError: The observed errors are far from the model's own prediction (unless
            ``accept_inconsistent``), naming the likely cause.
    """
    from cpc2urdf.validation.heldout import accuracy as _accuracy

    m = model if isinstance(model, CPCModel) else load_model(model)
    ms = (
        measurements
        if isinstance(measurements, MeasurementSet)
        else load_measurements(measurements)
    )
    return _accuracy(m, ms, accept_inconsistent=accept_inconsistent)


def plan_experiment(
    robot: RobotRef,
    *,
    n: int | None = None,
    target_error_mm: float | None = None,
    measure: Sequence[str] | None = None,
    sigma_mm: float = 0.5,
    sigma_deg: float = 0.5,
    one_joint: bool = False,
    task_region: str | ArrayLike = "calibration",
    candidates: int = 500,
    seed: int = 0,
    cameras: Sequence[str] | None = None,
    board: PathLike | None = None,
    board_link: str | None = None,
    output: PathLike | None = None,
) -> PlanOutputs | SelfcalOutputs:
    """The I-optimal measurement plan for ``robot`` and its predicted accuracy (``cpc2urdf plan``).

    Exactly one of ``n`` (configurations to measure) and ``target_error_mm`` (the smallest plan
    whose predicted held-out RMS position error over the task region reaches it) is given.
    Returns the plan (``.result``: configurations, prediction, the curve per strategy) and the texts
    of its files (``.doc`` for ``plan.json``, ``.csv_text``, ``.png``); nothing is written.

    Args:
        robot: Shipped name, spec or URDF path (a URDF needs ``measure``).
        measure: The measured links of a URDF (default: the spec's plates).
        sigma_mm, sigma_deg: The pose noise of the measuring rig.
        one_joint: Keep the one-joint-at-a-time structure the closed form needs.
        task_region: ``"calibration"`` (the calibration ranges), ``"limits"`` or task configurations (N, n) [SI].
        candidates: Size of the seeded candidate set.
        cameras, board, board_link: A one-stage plan instead (``plan --cameras --board``,
            docs/selfcal.md): configurations where the camera links see the board (its file),
            fixed or held by ``board_link``, minimising the predicted camera-pose error (``n``).
        output: Write the plan's files there (``plan.json``, ``plan.csv``), all or none.
    """
    from cpc2urdf.identification.planning.outputs import plan_robot, write_plan_outputs

    if cameras is not None:
        from cpc2urdf.identification.planning.selfcal_plan_file import (
            plan_selfcal_robot,
            write_selfcal_plan,
        )
        from cpc2urdf.identification.vision.boards.board_file import load_board

        if board is None or n is None:
            raise ConfigurationError("a one-stage plan (cameras=) needs board= and n=")
        one = plan_selfcal_robot(
            load_robot(robot),
            cameras,
            load_board(board),
            n,
            robot_ref=os.fspath(robot) if isinstance(robot, (str, os.PathLike)) else "robot",
            board_link=board_link,
            n_candidates=candidates,
            seed=seed,
        )
        if output is not None:
            write_selfcal_plan(one, output)
        return one
    out = plan_robot(
        load_robot(robot),
        robot_ref=os.fspath(robot) if isinstance(robot, (str, os.PathLike)) else "robot",
        measured=measure,
        sigma_t=sigma_mm / 1000,
        sigma_r=np.radians(sigma_deg),
        n=n,
        target_error=None if target_error_mm is None else target_error_mm / 1000,
        one_joint=one_joint,
        task_region=task_region,
        n_candidates=candidates,
        seed=seed,
    )
    if output is not None:
        write_plan_outputs(out, output)
    return out


def gaze_solver(
    robot: CPCModel | RobotRef,
    cameras: Sequence[str] = ("camera_left_optical", "camera_right_optical"),
    options: GazeOptions | None = None,
    **fields: Any,
) -> GazeSolver:
    """A gaze solver (``cpc2urdf gaze``) for a model, model file, robot spec, shipped robot or
    URDF path, pointing the optical axes of ``cameras``. Build it once; ``solve`` then runs at
    control rate.

    Args:
        robot: The head.
        cameras: One or two camera optical frames (REP-103). One camera: look-at; two on
            independent eyes: binocular fixation; two rigidly coupled: see ``GazeOptions.rigid``.
        options: How the solver treats the head
            (:class:`~cpc2urdf.validation.gaze.options.GazeOptions`: the joints that may move, a
            coupling, the rigid-pair mode, the pointing tolerance or the focal length, the minimum
            viewing distance); its fields may also be given as keywords (``joints=[...]``).
    """
    from cpc2urdf.validation.gaze import solver_for

    ref = robot.nominal_model() if isinstance(robot, RobotSpec) else robot
    return solver_for(ref, cameras, options, **fields)


def reachable_region(
    robot: CPCModel | RobotRef,
    cameras: Sequence[str] = ("camera_left_optical", "camera_right_optical"),
    *,
    grid: str = "shell",
    near: float = 0.2,
    far: float = 3.0,
    samples: Sequence[int] = (16, 37, 25),
) -> Region:
    """Where a head's cameras can fixate (``cpc2urdf reach``): a grid of targets in front of it
    (``grid`` ``"shell"`` or ``"box"``, ``near``-``far`` [m] from the cameras), each solved by the
    batch solver and sorted into fixated, disparity-limited, joint limits, behind or too close."""
    from cpc2urdf.validation.gaze.reachable import make_grid
    from cpc2urdf.validation.gaze.reachable import reachable_region as _reachable_region

    solver = gaze_solver(robot, cameras)
    return _reachable_region(solver, make_grid(solver, grid, near, far, samples))


def write_view(
    robot: CPCModel | RobotRef,
    path: PathLike,
    *,
    target: ArrayLike | None = None,
    q: ArrayLike | None = None,
    ghost: CPCModel | RobotRef | None = None,
    package_dirs: Sequence[PathLike] = (),
    change_colours: bool = True,
    align: str = "auto",
    region: Region | None = None,
) -> ViewSummary:
    """A self-contained meshcat page of the robot (``cpc2urdf view --html``; with ``region``,
    ``cpc2urdf reach --html``).

    Args:
        robot: A model, model file, spec, shipped robot or URDF (drawn with its own meshes).
        path: The HTML file to write (atomically).
        target: A 3D point [m] (world) to fixate and draw, with the gaze solution.
        q: The configuration to show (default: the gaze solution or the middle of the limits).
        ghost: The nominal model drawn translucent; with ``change_colours`` every link is
            coloured by how far calibration moved it from the ghost's (legend in the page).
        package_dirs: Folders where ``package://NAME/...`` mesh paths are looked up first.
        change_colours: Colour links by their change from ``ghost`` (else keep URDF colours).
        align: Where the ghost is put: ``"world"`` (both models in one world), ``"base"`` (on the
            robot's base link), or ``"auto"`` (on the base only when the two worlds differ by at
            least 50 mm or 5 degrees, e.g. a model in the rig's world against its gravity-aligned
            export). The page's legend says which was used.
        region: A reachable region of this robot (:func:`reachable_region`), drawn as one point
            cloud per category (:mod:`cpc2urdf.validation.view.region`), with its legend.
    """
    from cpc2urdf.validation.view import load_view_robot, write_view_html
    from cpc2urdf.validation.view.region import view_cameras

    def view_robot(ref: CPCModel | RobotRef) -> ViewRobot:
        src = ref.nominal_model() if isinstance(ref, RobotSpec) else ref
        return load_view_robot(src, package_dirs=tuple(os.fspath(p) for p in package_dirs))

    shown = view_robot(robot)
    options: dict[str, Any] = {}
    if region is not None:
        options["region"] = region
        options["cameras"] = view_cameras(shown, region.cameras)
    return write_view_html(
        path,
        shown,
        target=target,
        q=q,
        ghost=None if ghost is None else view_robot(ghost),
        change_colours=change_colours,
        align=align,
        **options,
    )


__all__ = [
    "accuracy",
    "calibrate_cameras",
    "calibrate_head",
    "calibration_report",
    "camera_mount",
    "check_urdf",
    "export_urdf",
    "gaze_solver",
    "identify",
    "load_handeye_poses",
    "load_marker_csv",
    "load_measurements",
    "load_model",
    "load_plan",
    "load_robot",
    "measurements_from_bag",
    "plan_experiment",
    "reachable_region",
    "save_model",
    "simulate",
    "solve_handeye",
    "write_view",
]
