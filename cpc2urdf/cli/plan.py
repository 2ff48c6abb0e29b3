"""``cpc2urdf plan ROBOT (--n N | --target-error MM) -o plan.json``: plan a stage-1 experiment.

``cpc2urdf plan ROBOT --cameras LINK [LINK ...] --board BOARD.json [--board-link LINK] --poses N
-o plan.json``: plan a one-stage calibration of the head by its own cameras (configurations where
every camera sees the whole board, minimising the predicted camera pose error,
:mod:`~cpc2urdf.identification.planning.selfcal_plan`); writes ``plan.json`` and ``plan.csv``.

Chooses the configurations to measure that minimise the predicted held-out position error over a
task region (I-optimal, greedy + Fedorov exchange over candidates the rig can see), predicts the
accuracy before any measurement, and compares with D-optimal selection and the paper's
one-joint-at-a-time protocol. Writes ``plan.json`` (``cpc2urdf/plan@1``), ``plan.csv`` (joints CSV
to send to the robot) and ``plan.png`` (predicted error vs N). See docs/planning.md.
"""

from __future__ import annotations

import argparse
import math
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # numpy is imported inside run (fast `cpc2urdf --help`)
    import numpy as np


def add_parser(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = subparsers.add_parser(
        "plan",
        help="plan the configurations to measure and predict the accuracy (before measuring)",
        description="Plan a stage-1 experiment: N configurations (or the fewest reaching --target-error) that the "
        "rig can measure, chosen to minimise the predicted held-out position error over the task region "
        "(Cramér-Rao bound at the nominal model); compared with D-optimal selection and the paper's "
        "one-joint-at-a-time protocol. Writes PLAN.json, PLAN.csv (joints to send to the robot) and PLAN.png.",
    )
    p.add_argument(
        "robot", help="shipped robot name, robot spec/model file or URDF (with --measure)"
    )
    p.add_argument(
        "-o",
        "--output",
        required=True,
        metavar="PLAN.json",
        help="plan file (PLAN.csv and PLAN.png next to it)",
    )
    size = p.add_mutually_exclusive_group()
    size.add_argument("--n", type=int, help="configurations to plan")
    size.add_argument(
        "--target-error",
        type=float,
        metavar="MM",
        help="plan the fewest configurations whose predicted RMS position error over the task region is <= MM",
    )
    p.add_argument(
        "--measure",
        nargs="+",
        metavar="LINK",
        default=[],
        help="the measured frames: a URDF's links carrying the calibration targets (as for simulate), or a "
        "spec's frames (default: the spec's plates)",
    )
    p.add_argument(
        "--rig",
        metavar="RIG.yaml",
        help="stereo rig file (default: the paper's 600 mm rig at 1.5 m)",
    )
    p.add_argument(
        "--sigma-mm",
        type=float,
        default=0.5,
        help="pose noise: std of each translation entry [mm] (default 0.5)",
    )
    p.add_argument(
        "--sigma-deg",
        type=float,
        default=0.5,
        help="pose noise: std of the rotation error angle [deg] (default 0.5)",
    )
    p.add_argument(
        "--noise",
        choices=("fig10", "stereo"),
        default="fig10",
        help="fig10: pose noise --sigma-mm/--sigma-deg, the same for every view (default); stereo: "
        "--pixel-sigma on each circle centre through the rig, triangulation and registration, so that far "
        "and oblique views count less (needs the plates' circle layouts)",
    )
    p.add_argument(
        "--pixel-sigma",
        type=float,
        default=0.15,
        metavar="PX",
        help="stereo: std of each pixel coordinate of a circle centre; --cameras: of each board corner "
        "[px] (default 0.15)",
    )
    p.add_argument(
        "--markers",
        type=int,
        default=0,
        metavar="K",
        help="position-only data (laser tracker, mocap): K markers of unknown position on each measured "
        "frame, placed as `simulate --markers K --seed MARKER_SEED` places them; the predicted error is then "
        "the markers' point error (default 0: plate poses)",
    )
    p.add_argument(
        "--marker-sigma-mm",
        type=float,
        default=0.1,
        help="--markers: noise per point coordinate [mm] (default 0.1)",
    )
    p.add_argument(
        "--marker-seed",
        type=int,
        default=0,
        help="--markers: seed of their placement; simulate the plan with the same --markers K --seed (default 0)",
    )
    p.add_argument(
        "--one-joint",
        action="store_true",
        help="keep the one-joint-at-a-time structure the closed form needs (q0 plus single-joint moves)",
    )
    p.add_argument(
        "--task-region",
        default="calibration",
        metavar="calibration|limits|TASK.csv",
        help="where the robot must be accurate: the calibration ranges (default), the joint limits, or a "
        "joints CSV of task configurations",
    )
    p.add_argument(
        "--range",
        action="append",
        default=[],
        metavar="JOINT=LO:HI",
        help="calibration range of a joint in mm or deg (repeatable; a URDF robot's joints by their URDF "
        "or model names; default: the spec's)",
    )
    p.add_argument(
        "--candidates", type=int, default=500, help="candidate configurations (default 500)"
    )
    p.add_argument("--grid", action="store_true", help="grid candidates instead of random ones")
    p.add_argument("--seed", type=int, default=0, help="seed of the candidates (default 0)")
    p.add_argument(
        "--curve",
        metavar="N,N,...",
        help="plan sizes of the predicted-error curve (default: the protocol's joints*M+1 for M = 2, 3, 5, 9, "
        "and the plan's N)",
    )
    one = p.add_argument_group(
        "one-stage calibration (the head's own cameras see a board; instead of --n/--target-error)"
    )
    one.add_argument(
        "--cameras",
        nargs="+",
        metavar="LINK",
        default=[],
        help="the head's camera links (a URDF's, LINK:optical or LINK:body where it cannot tell; a "
        "spec's optical frames): plan the configurations where every one sees the whole board",
    )
    one.add_argument("--board", metavar="BOARD.json", help="the board (cpc2urdf/board@1)")
    one.add_argument(
        "--board-link",
        metavar="LINK",
        help="the link holding the board (its frame: origin at the pattern's centre, z out of the "
        "printed face); default: the board is fixed in front of the cameras",
    )
    one.add_argument("--poses", type=int, metavar="N", help="configurations to plan")
    one.add_argument(
        "--board-distance",
        type=float,
        metavar="M",
        help="a fixed board's distance ahead of the cameras at the middle of the ranges [m] "
        "(default: where it spans a third of the image's width)",
    )
    one.add_argument(
        "--intrinsics",
        nargs="+",
        metavar="CAMERA.yaml",
        help="each camera's intrinsics (OpenCV FileStorage, one per --cameras; default 640 x 480, "
        "f = 500 px); --pixel-sigma is the corner noise",
    )
    p.set_defaults(run=run, written=companions)


def companions(args: argparse.Namespace) -> dict[str, str]:
    """The files written next to the plan (checked against the inputs before the command runs)."""
    from pathlib import Path

    plan = Path(args.output)
    if plan.suffix.lower() in (".csv", ".png") or plan.name in ("", ".", ".."):
        return {}  # refused by plan itself, with its own message
    return {
        "-o (its .csv)": str(plan.with_suffix(".csv")),
        "-o (its .png)": str(plan.with_suffix(".png")),
    }


def run(args: argparse.Namespace) -> int:
    from cpc2urdf.cli._ranges import parse_ranges
    from cpc2urdf.errors import ConfigurationError
    from cpc2urdf.files.robot_ref import load_robot
    from cpc2urdf.identification.planning.outputs import (
        output_paths,
        plan_robot,
        robot_for_plan,
        write_plan_outputs,
    )

    output_paths(args.output)  # a bad -o is refused before the work
    if args.cameras or args.poses is not None or args.board or args.board_link:
        return _run_selfcal(args)
    if args.n is None and args.target_error is None:
        raise ConfigurationError(
            "one of the arguments --n --target-error is required (or --cameras, --board and "
            "--poses for a one-stage plan)"
        )
    if args.markers < 0:
        raise ConfigurationError(
            f"--markers must be >= 0 markers per measured frame, got {args.markers}"
        )
    if args.marker_seed < 0:
        raise ConfigurationError(f"--marker-seed must be >= 0, got {args.marker_seed}")
    for flag in ("sigma_mm", "sigma_deg", "pixel_sigma", "marker_sigma_mm"):
        v = getattr(args, flag)
        if not (math.isfinite(v) and v > 0):
            raise ConfigurationError(
                f"--{flag.replace('_', '-')} must be a positive number, got {v}"
            )
    if args.n is not None and args.n < 1:
        raise ConfigurationError(f"--n must be at least 1, got {args.n}")
    if args.target_error is not None and not (
        math.isfinite(args.target_error) and args.target_error > 0
    ):
        raise ConfigurationError(
            f"--target-error must be a positive number of mm, got {args.target_error}"
        )
    if args.candidates < 1:
        raise ConfigurationError(f"--candidates must be at least 1, got {args.candidates}")
    curve_ns = None
    if args.curve:
        try:
            curve_ns = [int(v) for v in args.curve.split(",")]
        except ValueError:
            raise ConfigurationError(
                f"--curve {args.curve!r}: expected plan sizes like 13,19,31"
            ) from None
        if min(curve_ns) < 1:
            raise ConfigurationError(f"--curve {args.curve!r}: plan sizes must be >= 1")
    spec = load_robot(args.robot)
    robot = robot_for_plan(spec, args.measure)
    structure = robot.structure
    rig = None
    if args.rig:
        from cpc2urdf.identification.vision.rig_file import load_rig

        rig = load_rig(args.rig)
    task: str | np.ndarray = args.task_region
    if args.task_region not in ("calibration", "limits"):
        from cpc2urdf.identification.vision.joints_csv import read_joints_csv, urdf_joint_columns

        task = read_joints_csv(args.task_region, structure, aliases=urdf_joint_columns(robot)).q
    out = plan_robot(
        spec,
        robot_ref=str(args.robot),
        measured=args.measure or None,
        rig=rig,
        sigma_t=args.sigma_mm / 1000,
        sigma_r=math.radians(args.sigma_deg),
        ranges=parse_ranges(args.range, robot),
        n=args.n,
        target_error=None if args.target_error is None else args.target_error / 1000,
        one_joint=args.one_joint,
        task_region=task,
        n_candidates=args.candidates,
        grid=args.grid,
        seed=args.seed,
        curve_ns=curve_ns,
        noise=args.noise,
        pixel_sigma=args.pixel_sigma,
        markers=args.markers,
        marker_sigma=args.marker_sigma_mm / 1000,
        marker_seed=args.marker_seed,
    )
    paths = write_plan_outputs(out, args.output)
    pred = out.result.prediction
    what = "marker point" if args.markers else "position"
    print(
        f"plan: {len(out.result.q)} configurations ({out.result.strategy}"
        f"{', one joint at a time' if out.result.one_joint else ''}); predicted RMS error over the task region: "
        f"{_mm(pred.position_rms)} {what}"
        + ("" if args.markers else f", {_deg(pred.orientation_rms)} orientation")
        + "; "
        f"{pred.rank} of {pred.n_params} parameters determined"
    )
    if args.noise == "stereo" and math.isfinite(pred.bound_position_rms):
        print(
            f"  (stereo: predicted for the identification's scalar weights; per-view weights would reach "
            f"{_mm(pred.bound_position_rms)})"
        )
    for line in pred.free_combinations:
        print(f"  undetermined: {line}")
    same = [c for c in out.result.curve if c.n == len(out.result.q)]
    for c in same:
        print(f"  {c.strategy:>10} at N = {c.n}: {_mm(c.position_rms)}")
    print("wrote " + ", ".join(str(p) for p in paths))
    return 0


def _run_selfcal(args: argparse.Namespace) -> int:
    """``--cameras ... --board ... --poses N``: a one-stage plan."""
    from cpc2urdf.cli._ranges import parse_ranges
    from cpc2urdf.errors import ConfigurationError
    from cpc2urdf.files.robot_ref import load_robot
    from cpc2urdf.identification.planning.selfcal_plan_file import (
        plan_selfcal_robot,
        write_selfcal_plan,
    )
    from cpc2urdf.identification.selfcal.pixel_problem import CameraModel
    from cpc2urdf.identification.vision.boards.board_file import load_board
    from cpc2urdf.identification.vision.rig_file import load_camera

    if not args.cameras or not args.board or args.poses is None:
        raise ConfigurationError(
            "a one-stage plan needs --cameras LINK [LINK ...], --board BOARD.json and --poses N"
        )
    stage1 = {
        "--n": args.n is not None,
        "--target-error": args.target_error is not None,
        "--measure": bool(args.measure),
        "--rig": bool(args.rig),
        "--noise": args.noise != "fig10",
        "--markers": args.markers != 0,
        "--one-joint": args.one_joint,
        "--grid": args.grid,
        "--task-region": args.task_region != "calibration",
        "--curve": bool(args.curve),
    }
    given = [k for k, v in stage1.items() if v]
    if given:
        raise ConfigurationError(
            f"{given[0]} is for stage-1 plans; a one-stage plan (--cameras) takes --poses N"
        )
    if args.poses < 1:
        raise ConfigurationError(f"--poses must be at least 1, got {args.poses}")
    if args.candidates < args.poses:
        raise ConfigurationError(
            f"--candidates {args.candidates} is fewer than --poses {args.poses}"
        )
    if not (math.isfinite(args.pixel_sigma) and args.pixel_sigma > 0):
        raise ConfigurationError(f"--pixel-sigma must be a positive number, got {args.pixel_sigma}")
    spec = load_robot(args.robot)
    board = load_board(args.board)
    intrinsics = None
    if args.intrinsics:
        intrinsics = []
        for path in args.intrinsics:
            K, D, size = load_camera(path)
            intrinsics.append(CameraModel(K, D, size))
    out = plan_selfcal_robot(
        spec,
        args.cameras,
        board,
        args.poses,
        robot_ref=str(args.robot),
        board_link=args.board_link,
        intrinsics=intrinsics,
        sigma=args.pixel_sigma,
        distance=args.board_distance,
        ranges=parse_ranges(args.range, spec),
        n_candidates=args.candidates,
        seed=args.seed,
    )
    paths = write_selfcal_plan(out, args.output)
    pred, plan = out.plan.prediction, out.plan
    print(
        f"plan: {len(plan.q)} configurations (I-optimal, one-stage: {len(out.setup.cameras)} cameras "
        f"see the whole board); predicted camera pose error in the board's frame: "
        f"{_mm(pred.position_rms)}, {_deg(pred.rotation_rms)} RMS over {len(plan.heldout)} held-out "
        f"configurations ({len(plan.random)} random plans of {len(plan.q)} candidates: median "
        f"{_mm(plan.random_position_rms())}); {pred.rank} of {pred.n_params} parameters determined"
    )
    print("wrote " + ", ".join(str(p) for p in paths))
    return 0


def _mm(v: float) -> str:
    return f"{v * 1e3:.3f} mm" if math.isfinite(v) else "undetermined"


def _deg(v: float) -> str:
    return f"{math.degrees(v):.3f} deg" if math.isfinite(v) else "undetermined"
