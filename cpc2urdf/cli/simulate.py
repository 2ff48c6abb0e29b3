"""``cpc2urdf simulate ROBOT -o DIR``: a simulated stage-1 experiment as files.

Writes ``DIR/measurements.json`` (the one-joint-at-a-time protocol with noise),
``DIR/truth.json`` (the true robot as a model file) and ``DIR/heldout.json`` (random
configurations inside the calibration range with their true poses). See docs/measurements.md.
``--markers K`` makes them position-only data (``cpc2urdf/measurements@2``): K seeded markers on
each measured frame of the same true robot, their points with ``--marker-sigma-mm`` noise at the
same configurations, and their true points in the held-out file.

``--cameras LINK [LINK ...]`` (a URDF robot) simulates stage 2 instead: hand-eye pose files of
those camera links and their true mounts (docs/handeye.md). With ``--board BOARD.json --images DIR``
it renders what those cameras see of the board instead (fixed in the world, or held by
``--board-link LINK``, a gripper), for a one-stage calibration of the head by its own cameras:
the folder ``measure`` reads, plus the truth
(:mod:`~cpc2urdf.identification.simulation.selfcal_experiment`).

A URDF robot needs ``--measure LINK [LINK ...]``: the links the rig measures (plate, marker or
camera links on fixed joints, docs/urdf.md). The records then read only the joints on the paths
from the root to them, in the URDF's names, and ``cpc2urdf identify`` / ``export`` write the
calibrated URDF back. A link that is not in the URDF, is its root or is moved by a joint directly
is refused in one line before anything is written.
"""

from __future__ import annotations

import argparse
import math
import os
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from cpc2urdf.files.measurements import MeasurementSet
    from cpc2urdf.files.spec import RobotSpec
    from cpc2urdf.identification.simulation.stage1_experiment import Experiment


FILES = ("measurements.json", "truth.json", "heldout.json")  # what simulate writes into its folder


def add_parser(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = subparsers.add_parser(
        "simulate",
        help="simulate a stage-1 calibration experiment (measurements, truth, held-out set)",
        description="Simulate measuring a robot's calibration plates with a stereo rig while moving one "
        "joint at a time (Shih et al. sec. 4.1): a true robot = nominal + random geometric error, "
        "placed ~1.5 m in front of a 600 mm-baseline rig. Writes DIR/measurements.json, "
        "DIR/truth.json and DIR/heldout.json. Same seed, same files.",
    )
    p.add_argument(
        "robot",
        help="shipped robot name (e.g. iis_head), robot spec/model file with nominal geometry, "
        "or a URDF (then name the measured links with --measure)",
    )
    p.add_argument(
        "--measure",
        nargs="+",
        metavar="LINK",
        default=None,
        help="URDF robot: the links the rig measures (plate, marker or camera links, each on a fixed "
        "joint); the records have readings for the joints on the paths from the root to them only",
    )
    p.add_argument(
        "--cameras",
        nargs="+",
        metavar="LINK",
        default=None,
        help="URDF robot: simulate stage 2 (hand-eye) of these camera links instead, optical "
        "(z forward) or body (x forward; LINK:optical or LINK:body where the URDF cannot tell); "
        "writes DIR/handeye_<LINK>.json per camera and the true mounts DIR/handeye_truth.json, "
        "DIR/handeye_truth.urdf (docs/handeye.md)",
    )
    p.add_argument(
        "--board",
        metavar="BOARD.json",
        default=None,
        help="--cameras: render the cameras' images of this board (cpc2urdf/board@1) into --images "
        "DIR instead of writing hand-eye poses",
    )
    p.add_argument(
        "--board-link",
        metavar="LINK",
        default=None,
        help="--board: the URDF link holding the board (a gripper); default: the board is fixed "
        "in front of the cameras",
    )
    p.add_argument(
        "--images",
        metavar="DIR",
        default=None,
        help="--board: the images folder to write (created if missing; instead of -o)",
    )
    p.add_argument(
        "--poses",
        type=int,
        default=20,
        metavar="N",
        help="--cameras: configurations with the target (or --board) in view of every camera "
        "(default 20)",
    )
    p.add_argument(
        "--pixel-noise",
        type=float,
        default=0.1,
        metavar="PX",
        help="--cameras: std of each disk-centre image coordinate [px] (default 0.1)",
    )
    p.add_argument(
        "--camera-error-mm",
        type=float,
        default=5.0,
        help="--cameras: true mounts moved by up to this per axis [mm] (default 5)",
    )
    p.add_argument(
        "--camera-error-deg",
        type=float,
        default=3.0,
        help="--cameras: true mounts turned by this about a random axis [deg] (default 3)",
    )
    p.add_argument(
        "-o", "--output", metavar="DIR", help="output folder (created if missing; required)"
    )
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument(
        "--M", type=int, default=9, help="values per joint over its calibration range (default 9)"
    )
    p.add_argument(
        "--noise",
        choices=("fig10", "stereo", "none"),
        default=None,
        help="fig10: Gaussian pose noise (Shih et al. Fig. 10); stereo: pixel noise -> "
        "triangulation -> registration; none (default fig10, or the plan's with --plan)",
    )
    p.add_argument(
        "--sigma-mm",
        type=float,
        default=None,
        help="fig10: std of each translation entry [mm] (default 0.5, or the plan's with --plan)",
    )
    p.add_argument(
        "--sigma-deg",
        type=float,
        default=None,
        help="fig10: std of the rotation error angle about a random axis [deg] (default 0.5, or the plan's)",
    )
    p.add_argument(
        "--pixel-sigma",
        type=float,
        default=None,
        help="stereo: std of each circle-centre pixel coordinate [px] (default 0.15, or the plan's)",
    )
    p.add_argument(
        "--geometry-error-mm",
        type=float,
        default=1.0,
        help="true robot: std of each CPC offset component error [mm] (default 1)",
    )
    p.add_argument(
        "--geometry-error-deg",
        type=float,
        default=0.5,
        help="true robot: std of each CPC axis/placement rotation error [deg] (default 0.5)",
    )
    p.add_argument(
        "--heldout", type=int, default=50, metavar="N", help="held-out configurations (default 50)"
    )
    p.add_argument(
        "--range",
        action="append",
        default=[],
        metavar="JOINT=LO:HI",
        help="calibration range of a joint in mm or deg (repeatable; default: the spec's)",
    )
    p.add_argument(
        "--baseline-mm", type=float, default=600.0, help="rig baseline [mm] (default 600)"
    )
    p.add_argument(
        "--distance-mm",
        type=float,
        default=1500.0,
        help="distance from the rig to the plates [mm] (default 1500)",
    )
    p.add_argument(
        "--focal-px",
        type=float,
        default=1600.0,
        help="rig focal length [px], 1280x1024 images (default 1600)",
    )
    p.add_argument(
        "--allow-out-of-view",
        action="store_true",
        help="do not fail when a plate leaves a camera's view (stereo noise then loses circles)",
    )
    p.add_argument(
        "--plan",
        metavar="PLAN.json",
        help="measure the configurations of a plan (cpc2urdf plan) instead of the one-joint protocol "
        "(with --board --images: render them, the board where the plan put it), "
        "from where the plan put the robot, with the plan's rig and noise (unless --sigma-mm/--sigma-deg "
        "are given); --M, --range and the rig options then do not apply",
    )
    p.add_argument(
        "--markers",
        type=int,
        default=None,
        metavar="K",
        help="position-only data instead of poses: K markers at random 5-15 cm from each measured "
        "frame, their points measured with --marker-sigma-mm noise (a cpc2urdf/measurements@2 file; "
        "--noise and its sigmas then do not apply; the held-out file holds the markers' true points)",
    )
    p.add_argument(
        "--marker-sigma-mm",
        type=float,
        default=0.1,
        help="--markers: std of each marker point coordinate [mm] (default 0.1)",
    )
    p.set_defaults(run=run, written=written_files)


def written_files(args: argparse.Namespace) -> dict[str, str]:
    """The files written into the output folder (checked against the inputs before the command runs)."""
    names: tuple[str, ...] = FILES
    if args.images:
        names = IMAGE_FILES
        return {f"--images (its {name})": os.path.join(args.images, name) for name in names}
    if args.cameras:
        from cpc2urdf.identification.handeye.urdf_stage2 import TRUTH_FILES, pose_file_name

        names = (*(pose_file_name(c) for c in args.cameras), *TRUTH_FILES)
    return {f"-o (its {name})": os.path.join(args.output, name) for name in names}


IMAGE_FILES = (
    "joints.csv",
    "board.json",
    "selfcal_truth.json",
    "truth_model.json",
    "nominal_model.json",
)  # what --images writes besides each camera's folder and .yaml


def _run_images(args: argparse.Namespace) -> int:
    """``--cameras --board --images``: what a URDF robot's cameras see of a board, as images."""

    from cpc2urdf.argparsing import check_outputs_are_not_inputs
    from cpc2urdf.errors import ConfigurationError, OutputError
    from cpc2urdf.files.robot_ref import is_urdf_ref
    from cpc2urdf.identification.planning.selfcal_plan_file import render_head_images
    from cpc2urdf.identification.vision.boards.board_file import load_board

    for flag, needs in (("board", "images"), ("images", "board"), ("board_link", "board")):
        if getattr(args, flag) is not None and getattr(args, needs) is None:
            raise ConfigurationError(
                f"--{flag.replace('_', '-')} needs --{needs} (--cameras LINK --board BOARD.json "
                "--images DIR)"
            )
    if not args.cameras:
        raise ConfigurationError(
            "--board renders the images of camera links: name them with --cameras"
        )
    if not is_urdf_ref(args.robot):
        raise ConfigurationError(f"--board needs a URDF robot; {args.robot!r} is not a URDF")
    for flag in ("measure", "markers", "output"):
        if getattr(args, flag) is not None:
            what = "-o (the folder is --images DIR)" if flag == "output" else f"--{flag}"
            raise ConfigurationError(f"--board --images renders images; it takes no {what}")
    if args.poses < 1:
        raise ConfigurationError(f"--poses must be at least 1, got {args.poses}")
    if args.seed < 0:
        raise ConfigurationError(f"--seed must be a non-negative integer, got {args.seed}")
    if Path(args.images).exists() and not Path(args.images).is_dir():
        raise OutputError(f"{args.images}: exists and is not a folder")
    args.output = args.images  # so that the outputs are checked against the inputs
    check_outputs_are_not_inputs(args)
    scene, q = render_head_images(
        args.robot,
        args.cameras,
        load_board(args.board),
        args.images,
        board_link=args.board_link,
        plan=args.plan,
        poses=args.poses,
        seed=args.seed,
        sigma_t=args.geometry_error_mm / 1000,
        sigma_r=math.radians(args.geometry_error_deg),
    )
    where = f"held by {args.board_link}" if args.board_link else "fixed in the world"
    print(
        f"wrote {args.images}: {len(q)} records x {len(scene.cameras)} cameras "
        f"({', '.join(scene.camera_links)}), the board {where}; the truth in selfcal_truth.json, "
        "truth_model.json"
    )
    return 0


def _run_handeye(args: argparse.Namespace, out: Path) -> int:
    """``--cameras``: stage 2 of a URDF robot's cameras, as pose files and the true mounts."""
    from cpc2urdf.api import simulate
    from cpc2urdf.errors import ConfigurationError
    from cpc2urdf.files.robot_ref import is_urdf_ref
    from cpc2urdf.identification.handeye.urdf_stage2 import write_simulation

    if not is_urdf_ref(args.robot):
        raise ConfigurationError(
            f"--cameras names camera links of a URDF robot; {args.robot!r} is not a URDF"
        )
    for flag in ("measure", "plan", "markers"):
        if getattr(args, flag) is not None:
            raise ConfigurationError(f"--cameras simulates stage 2; it takes no --{flag}")
    for flag in ("pixel_noise", "camera_error_mm", "camera_error_deg"):
        v = getattr(args, flag)
        if not (math.isfinite(v) and v >= 0):
            raise ConfigurationError(
                f"--{flag.replace('_', '-')} must be a finite number >= 0, got {v:g}"
            )
    if args.seed < 0:
        raise ConfigurationError(f"--seed must be a non-negative integer, got {args.seed}")
    sim = simulate(
        args.robot,
        cameras=args.cameras,
        seed=args.seed,
        poses=args.poses,
        pixel_noise=args.pixel_noise,
        camera_error_mm=args.camera_error_mm,
        camera_error_deg=args.camera_error_deg,
    )
    paths = write_simulation(sim, out)
    print(f"wrote {', '.join(str(p) for p in paths)}")
    for link, cam in sim.rig.cameras.items():
        optical = "" if cam.optical == link else f", optical frame {cam.optical or 'REP-103 turn'}"
        print(
            f"  {link}: {cam.convention} link on {cam.hand} (joint {cam.mount.name}{optical}); "
            f"{len(sim.q)} configurations, pixel noise {sim.pixel_noise:g} px"
        )
    return 0


DEFAULT_SIGMA_MM = 0.5  # Fig. 10
DEFAULT_SIGMA_DEG = 0.5
DEFAULT_NOISE = "fig10"
DEFAULT_PIXEL_SIGMA = 0.15  # [px]


def _as_markers(
    exp: Experiment, k: int, sigma_p: float, seed: int
) -> tuple[MeasurementSet, MeasurementSet]:
    """The experiment as position-only data (``cpc2urdf/measurements@2``): ``k`` seeded random
    markers on each measured frame of the true robot, their points at the protocol's configurations
    with ``sigma_p`` [m] noise per coordinate, and their true points at the held-out ones."""
    import dataclasses

    import numpy as np

    from cpc2urdf.identification.simulation.marker_points import place_markers_on, simulate_markers

    truth, measured, heldout = exp
    rng = np.random.default_rng(
        [seed, 1]
    )  # its own stream: the true robot and q stay those of the pose data
    frames = [f for f in truth.structure.frame_names if f in measured.poses]
    markers = place_markers_on(truth, {f: k for f in frames}, rng)
    sets = []
    for ms, sigma in ((measured, sigma_p), (heldout, 0.0)):
        pts = simulate_markers(truth, markers, ms.q, sigma_p=sigma, rng=rng, robot=ms.robot)
        noise = pts.metadata.get("noise", {"model": "none"})
        kind = "marker points" if sigma else "TRUE marker points (no noise)"
        metadata = {
            **ms.metadata,
            "noise": noise,
            "description": ms.metadata["description"].replace("measurements", kind)
            if sigma
            else f"held-out configurations of {truth.structure.name} with {kind}",
        }
        sets.append(
            dataclasses.replace(
                pts, source=ms.source, labels=ms.labels, metadata=metadata, spec=ms.spec
            )
        )
    return sets[0], sets[1]


def _simulate_plan(args: argparse.Namespace, spec: RobotSpec, ref: str) -> Experiment:
    """The experiment of ``--plan``: the plan's configurations, rig and placement (its noise unless
    ``--sigma-mm``/``--sigma-deg`` are given on the command line)."""
    from cpc2urdf.identification.planning.experiment import simulate_from_plan
    from cpc2urdf.identification.planning.plan_file import load_plan

    plan = load_plan(args.plan, spec.structure)
    if (
        plan.markers and args.markers is None
    ):  # a marker plan: its markers (same K and seed: same places)
        args.markers, args.marker_sigma_mm = plan.markers, plan.marker_sigma * 1e3
    if plan.markers and (args.markers, args.seed) != (plan.markers, plan.marker_seed):
        print(
            f"note: {args.plan} was planned for {plan.markers} markers per frame placed with seed {plan.marker_seed}; "
            f"--markers {args.markers} --seed {args.seed} places other markers"
        )
    return simulate_from_plan(
        spec.nominal_model(),
        plan,
        seed=args.seed,
        noise=args.noise,
        sigma_t=None if args.sigma_mm is None else args.sigma_mm / 1000,
        sigma_r=None if args.sigma_deg is None else math.radians(args.sigma_deg),
        geometry_error_t=args.geometry_error_mm / 1000,
        geometry_error_r=math.radians(args.geometry_error_deg),
        pixel_sigma=args.pixel_sigma,
        n_heldout=args.heldout,
        require_view=not args.allow_out_of_view,
        robot_ref=ref,
    )


def run(args: argparse.Namespace) -> int:
    from cpc2urdf.cli._ranges import parse_ranges
    from cpc2urdf.errors import ConfigurationError, OutputError
    from cpc2urdf.files.jsonio import dumps, make_folder, write_all_atomic
    from cpc2urdf.files.measurements import measurements_to_json
    from cpc2urdf.files.model_file import model_to_json
    from cpc2urdf.files.robot_ref import load_robot, looks_like_path
    from cpc2urdf.identification.simulation.stage1_experiment import (
        measured_robot,
        simulate_experiment,
    )
    from cpc2urdf.identification.vision.stereo import StereoRig

    if args.board is not None or args.images is not None or args.board_link is not None:
        return _run_images(args)
    if args.output is None:
        raise ConfigurationError("the following arguments are required: -o/--output")
    out = Path(args.output)
    if out.exists() and not out.is_dir():
        raise OutputError(f"{out}: exists and is not a folder")
    if args.cameras:
        return _run_handeye(args, out)
    if args.M < 2:
        raise ConfigurationError(f"--M must be at least 2, got {args.M}")
    if args.heldout < 1:  # a measurement file needs at least one record
        raise ConfigurationError(f"--heldout must be at least 1, got {args.heldout}")
    for flag in ("baseline_mm", "distance_mm", "focal_px"):
        v = getattr(args, flag)
        if not (math.isfinite(v) and v > 0):
            raise ConfigurationError(
                f"--{flag.replace('_', '-')} must be a positive number, got {v:g}"
            )
    plan_noise = args.plan is not None
    if not plan_noise:  # the protocol's defaults; with --plan, the plan's own noise unless given
        args.noise = DEFAULT_NOISE if args.noise is None else args.noise
        args.pixel_sigma = DEFAULT_PIXEL_SIGMA if args.pixel_sigma is None else args.pixel_sigma
        args.sigma_mm = DEFAULT_SIGMA_MM if args.sigma_mm is None else args.sigma_mm
        args.sigma_deg = DEFAULT_SIGMA_DEG if args.sigma_deg is None else args.sigma_deg
    for flag in (
        "sigma_mm",
        "sigma_deg",
        "pixel_sigma",
        "geometry_error_mm",
        "geometry_error_deg",
        "marker_sigma_mm",
    ):
        v = getattr(args, flag)
        if v is not None and not (math.isfinite(v) and v >= 0):
            raise ConfigurationError(
                f"--{flag.replace('_', '-')} must be a finite number >= 0, got {v:g}"
            )
    if args.seed < 0:  # numpy's seed sequences take non-negative integers only
        raise ConfigurationError(f"--seed must be a non-negative integer, got {args.seed}")
    if args.markers is not None and args.markers < 1:
        raise ConfigurationError(
            f"--markers must be at least 1 (markers per measured frame), got {args.markers}"
        )
    spec = measured_robot(load_robot(args.robot), args.robot, args.measure)
    # A robot file is referred to relative to DIR, so the files can move together.
    text = str(args.robot)
    is_path = looks_like_path(text)
    ref = os.path.relpath(os.path.abspath(text), os.path.abspath(out)) if is_path else text
    if args.plan:
        exp = _simulate_plan(args, spec, ref)
    else:
        rig = StereoRig.verged(
            baseline=args.baseline_mm / 1000,
            distance=args.distance_mm / 1000,
            focal_px=args.focal_px,
        )
        exp = simulate_experiment(
            spec,
            seed=args.seed,
            M=args.M,
            noise=args.noise,
            sigma_t=args.sigma_mm / 1000,
            sigma_r=math.radians(args.sigma_deg),
            pixel_sigma=args.pixel_sigma,
            geometry_error_t=args.geometry_error_mm / 1000,
            geometry_error_r=math.radians(args.geometry_error_deg),
            n_heldout=args.heldout,
            rig=rig,
            ranges=parse_ranges(args.range, spec),
            require_view=not args.allow_out_of_view,
            robot_ref=ref,
            show_progress=(args.M * spec.structure.n_joints + args.heldout) > 5000,
        )
    measured, heldout = exp.measured, exp.heldout
    if args.markers:
        measured, heldout = _as_markers(exp, args.markers, args.marker_sigma_mm * 1e-3, args.seed)
    # Everything is computed before anything is written; each file is written atomically.
    texts = dict(
        zip(
            FILES,
            (
                dumps(measurements_to_json(measured)),
                dumps(model_to_json(exp.truth)),
                dumps(measurements_to_json(heldout)),
            ),
            strict=True,
        )
    )
    make_folder(out)
    write_all_atomic({out / name: t for name, t in texts.items()})
    view = exp.measured.metadata["provenance"]["view"]
    stated = exp.measured.metadata.get("noise") or {}
    model = stated.get("model", "none")
    if model == "fig10":
        noise = f"fig10 noise {1e3 * stated.get('sigma_t_m', 0.0):g} mm / {math.degrees(stated.get('sigma_r_rad', 0.0)):g} deg"
    elif model == "stereo":
        noise = f"stereo noise {stated.get('pixel_sigma_px', args.pixel_sigma):g} px"
    else:
        noise = "no noise"
    if args.markers:
        noise = f"{len(measured.markers)} markers, point noise {args.marker_sigma_mm:g} mm"
    where = ""
    if "distance_range_m" in view:
        where = (
            f"; plates {view['distance_range_m'][0]:.2f}-{view['distance_range_m'][1]:.2f} m from the rig, "
            f">= {view['min_margin_px']:.0f} px inside the images"
        )
    source = f", the configurations of {args.plan}" if args.plan else ""
    print(
        f"wrote {out}/measurements.json ({measured.n_records} records{source}, {noise}), {out}/truth.json, "
        f"{out}/heldout.json ({heldout.n_records} records){where}"
    )
    return 0
