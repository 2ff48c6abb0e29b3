"""``cpc2urdf handeye poses.json|ROBOT [CAMERA] --method NAME|all [--json]``: hand-eye / robot-world
calibration from a pose file or two pose streams; ``--model M -o OUT`` adds the camera frame to a
model, ``--urdf ROBOT.urdf --camera LINK -o OUT`` writes the camera link's mount back into a URDF."""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
from typing import Any

X_DIRECTION = "X = T_hand_camera: camera pose in the hand frame (maps camera to hand coordinates)"
Z_DIRECTION = (
    "Z = T_base_target: target pose in the robot base frame (maps target to base coordinates)"
)


X_EYE_TO_HAND = (
    "X = T_hand_marker: marker pose in the hand frame (eye to hand: the camera is fixed, "
    "T_camera_target = inv(T_camera_marker))"
)
Z_EYE_TO_HAND = "Z = T_base_camera: camera pose in the robot base frame"


def _pairing_lines(pairing: Any) -> list[str]:
    """What pairing the streams did: frames, the clock offset and how it was found."""
    off = pairing.time_offset * 1e3
    if pairing.how == "estimated":
        how = (
            f"{off:+.3f} ± {pairing.sigma * 1e3:.3f} ms (estimated: angular-speed cross-"
            f"correlation {pairing.coarse * 1e3:+.3f} ms, refined by the rotation residual)"
        )
    elif pairing.how == "given":
        how = f"{off:+.3f} ms (given)"
    else:
        how = "0 (both streams have the same time stamps: rows paired as they are)"
    return [
        f"streams: {pairing.n_robot} robot poses, {pairing.n_camera} camera frames with a target "
        f"pose, {pairing.n_paired} inside the robot's time span, {pairing.n_keyframes} keyframes "
        "kept (5 deg or 20 mm apart)",
        f"clock offset t_camera - t_robot = {how}; robot poses taken at t_camera - offset",
    ]


def add_parser(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    from cpc2urdf.identification.handeye.solvers import ALL_METHODS, DEFAULT_HANDEYE_METHOD

    p = subparsers.add_parser(
        "handeye",
        help="hand-eye (X = T_hand_camera) and robot-world (Z = T_base_target) calibration",
        description="Solve A X = X B or A X = Z B from a cpc2urdf/handeye-poses@1 file (records "
        "of T_base_hand and T_camera_target), or from a robot and a camera pose stream (CSV or "
        "TUM, each pose with its time; KinHEC's exports) paired at their clock offset, see "
        "docs/handeye.md. Prints X = T_hand_camera, Z = T_base_target and the residual of every "
        "pose in mm and degrees.",
    )
    p.add_argument(
        "poses",
        help="hand-eye pose file (cpc2urdf/handeye-poses@1), or the robot's T_base_hand stream "
        "(CSV: t,x,y,z,qx,qy,qz,qw; TUM; KinHEC's SEQ_robot.csv)",
    )
    p.add_argument(
        "camera_stream",
        nargs="?",
        metavar="CAMERA",
        help="the camera's T_camera_target stream (default: SEQ_camera.* beside SEQ_robot.*)",
    )
    p.add_argument(
        "--time-offset",
        type=float,
        metavar="SECONDS",
        help="known clock offset t_camera - t_robot [s] (robot poses taken at t_camera - offset); "
        "default: estimated, or 0 when both streams have the same time stamps",
    )
    p.add_argument(
        "--eye-to-hand",
        action="store_true",
        help="streams only: the camera is fixed and watches a marker on the hand; the camera "
        "stream is T_camera_marker, X = T_hand_marker, Z = T_base_camera",
    )
    p.add_argument(
        "--method",
        default=DEFAULT_HANDEYE_METHOD,
        choices=[*ALL_METHODS, "all"],
        help=f"solver, or 'all' to compare every solver side by side (default {DEFAULT_HANDEYE_METHOD})",
    )
    p.add_argument(
        "--json", action="store_true", help="print the result as JSON (SI units + mm/deg residuals)"
    )
    p.add_argument(
        "--model", help="model file (or shipped robot) to put the camera frame into; needs -o"
    )
    p.add_argument(
        "-o",
        "--output",
        help="write MODEL with the camera frame added, or with --urdf the calibrated URDF "
        "(atomically)",
    )
    p.add_argument(
        "--urdf",
        metavar="ROBOT.urdf",
        help="write the camera link's mount (--camera: an optical or x-forward body link of this "
        "URDF) back into it as -o, in the link's own convention (docs/handeye.md)",
    )
    p.add_argument(
        "--unknown-scale",
        action="store_true",
        help="the target poses' translations are known up to one factor (a monocular visual "
        "odometry or SLAM trajectory): ml estimates it",
    )
    p.add_argument("--camera", help="camera frame name (default: the pose file's 'camera')")
    p.add_argument("--hand", help="hand frame name in MODEL (default: the pose file's 'hand')")
    p.add_argument(
        "--accept-inconsistent",
        action="store_true",
        help="keep the result of poses the consistency gate finds inconsistent with A X = Z B "
        "(inverted or transposed poses, wrong units, pairing off by one, outliers; see "
        "docs/handeye.md): the diagnosis is printed as a warning and stored in the model",
    )
    p.set_defaults(
        run=run, may_replace=("model",), written=_reports
    )  # -o MODEL: the model updated in place, atomically


def _reports(args: argparse.Namespace) -> dict[str, str]:
    """With --urdf: the calibration report written next to -o (checked against the inputs before
    the command runs)."""
    from cpc2urdf.urdf.report import written_reports

    if getattr(args, "urdf", None) is None or not args.output:
        return {}
    return written_reports(args.output)


def _pose_line(T: Any) -> str:
    from cpc2urdf.transforms import rpy_from_matrix

    xyz = T[:3, 3] * 1e3
    rpy = [math.degrees(v) for v in rpy_from_matrix(T[:3, :3])]
    return (
        f"xyz = [{xyz[0]:10.4f} {xyz[1]:10.4f} {xyz[2]:10.4f}] mm   "
        f"rpy = [{rpy[0]:9.4f} {rpy[1]:9.4f} {rpy[2]:9.4f}] deg"
    )


def _model_to_extend(args: argparse.Namespace, data: Any) -> Any:
    """The model --model names (checked against the poses before solving), or None; with --urdf,
    its camera link and the poses' hand checked before solving (None)."""
    from cpc2urdf.api import camera_mount, load_model
    from cpc2urdf.errors import ConfigurationError
    from cpc2urdf.files.jsonio import check_output_path
    from cpc2urdf.files.robot_ref import is_urdf_ref

    if args.urdf is not None:  # checked before the solve: the camera link and the poses' hand
        if args.model is not None or args.output is None or args.method == "all":
            raise ConfigurationError(
                "--urdf needs -o (the calibrated URDF), one --method (not 'all') and no --model"
            )
        if not is_urdf_ref(args.urdf):
            raise ConfigurationError(
                f"--urdf {args.urdf}: not a URDF (a .urdf file, or XML); a CPC model goes in --model"
            )
        check_output_path(args.output)
        camera_mount(args.urdf, data, camera=args.camera, hand=args.hand)
        return None
    if (args.model is None) != (args.output is None):
        raise ConfigurationError(
            "--model and -o/--output go together (the model to extend and where to write it)"
        )
    if args.model is None:
        return None
    if args.method == "all":
        raise ConfigurationError(
            "--model needs one --method (not 'all') to decide which X to store"
        )
    check_output_path(args.output)  # before the solve, not after it
    model = load_model(args.model)
    camera_mount(model, data, camera=args.camera, hand=args.hand)
    return model


def run(args: argparse.Namespace) -> int:
    from cpc2urdf.api import calibrate_cameras, load_handeye_poses, save_model, solve_handeye
    from cpc2urdf.errors import DegenerateDataError, InconsistentDataError
    from cpc2urdf.identification.handeye.solvers import ALL_METHODS, SOLVERS

    data = load_handeye_poses(
        args.poses,
        args.camera_stream,
        time_offset=args.time_offset,
        eye_to_hand=args.eye_to_hand,
    )
    model = _model_to_extend(args, data)
    methods = list(ALL_METHODS) if args.method == "all" else [args.method]
    results, refused = {}, {}
    for m in methods:
        try:
            results[m] = solve_handeye(
                data,
                m,
                accept_inconsistent=args.accept_inconsistent,
                unknown_scale=args.unknown_scale,
            )
        except InconsistentDataError:
            raise  # the gate judges the data, the same for every solver: names the file already
        except DegenerateDataError as e:
            if len(methods) == 1:
                raise DegenerateDataError(f"{args.poses}: {e}") from e
            refused[m] = str(e)
    if not results:  # every solver refused: the data is the problem, say it once
        raise DegenerateDataError(f"{args.poses}: {next(iter(refused.values()))}")
    if model is not None or args.urdf is not None:  # a model's camera frame, or a URDF's link
        placed = calibrate_cameras(
            model if model is not None else args.urdf,
            data,
            args.method,
            camera=args.camera,
            hand=args.hand,
            result=results[args.method],
            accept_inconsistent=args.accept_inconsistent,
        )
        if model is not None:
            path = save_model(placed, args.output)
            camera, hand = args.camera or data.camera, args.hand or data.hand
        else:  # the camera link's mount origin, in the link's own convention
            from cpc2urdf.api import export_urdf

            path = export_urdf(placed, args.output)

    if args.json:
        doc: dict[str, Any] = {
            "poses": str(args.poses),
            "n_poses": len(data.labels),
            "labels": list(data.labels),
            "units": {"length": "m", "angle": "rad"},
        }
        if args.method == "all":
            doc["results"] = {m: r.to_json() for m, r in results.items()}
            doc["refused"] = refused
        else:
            doc.update(results[args.method].to_json())
        if model is not None or args.urdf is not None:
            doc["wrote"] = str(path)
        if data.pairing is not None:
            doc["streams"] = {  # an infinite sigma (no minimum found) as null: valid JSON
                k: None if isinstance(v, float) and not math.isfinite(v) else v
                for k, v in dataclasses.asdict(data.pairing).items()
            }
        print(json.dumps(doc, indent=2))
        return 0

    n = len(data.labels)
    who = ", ".join(
        x for x in (data.camera and f"camera {data.camera}", data.hand and f"hand {data.hand}") if x
    )
    if data.pairing is None:
        print(f"hand-eye calibration of {args.poses}: {n} poses" + (f" ({who})" if who else ""))
    else:
        print(f"hand-eye calibration of {data.source}: {n} poses" + (f" ({who})" if who else ""))
        for line in _pairing_lines(data.pairing):
            print(f"  {line}")
    eye_to_hand = data.pairing is not None and data.pairing.eye_to_hand
    print(f"  {X_EYE_TO_HAND if eye_to_hand else X_DIRECTION}")
    print(f"  {Z_EYE_TO_HAND if eye_to_hand else Z_DIRECTION}")
    print(
        f"  residual of pose k: {'marker' if eye_to_hand else 'camera'} pose T_base_hand[k] X vs "
        "Z inv(T_camera_target[k]), position [mm] and angle [deg]"
    )
    if len(results) == 1 and not refused:
        ((m, r),) = results.items()
        print(f"\nmethod {m} ({SOLVERS[m].description})")
        print(f"X  {_pose_line(r.X)}")
        for row in r.X[:3]:
            print("     [" + " ".join(f"{v:13.9f}" for v in row[:3]) + f" {row[3] * 1e3:12.6f} mm]")
        print(f"Z  {_pose_line(r.Z)}")
        for row in r.Z[:3]:
            print("     [" + " ".join(f"{v:13.9f}" for v in row[:3]) + f" {row[3] * 1e3:12.6f} mm]")
        print(f"\n{'pose':>20s} {'translation [mm]':>17s} {'rotation [deg]':>15s}")
        for k, lab in enumerate(data.labels):
            print(
                f"{lab:>20s} {r.residual_translation[k] * 1e3:17.4f} {math.degrees(r.residual_rotation[k]):15.4f}"
            )
        print(
            f"{'RMS':>20s} {r.rms_translation() * 1e3:17.4f} {math.degrees(r.rms_rotation()):15.4f}"
        )
        for w in r.warnings:
            print(f"warning: {w}")
        if model is not None:
            print(f"wrote {path}: frame {camera} on the link of {hand} at T_link_{hand} @ X")
        if args.urdf is not None:
            print(f"wrote {path}: the camera link's mount origin, in the link's own convention")
        return 0

    print()
    for m, r in results.items():
        print(f"{m:16s} X  {_pose_line(r.X)}")
        print(f"{'':16s} Z  {_pose_line(r.Z)}")
        print(
            f"{'':16s} RMS residual {r.rms_translation() * 1e3:.4f} mm, "
            f"{math.degrees(r.rms_rotation()):.4f} deg   ({SOLVERS[m].description})"
        )
    for m, why in refused.items():
        print(f"{m:16s} refused: {why}")
    names = list(results)
    print("\nresidual per pose [mm / deg]")
    print(f"{'pose':>20s} " + " ".join(f"{m:>18s}" for m in names))
    for k, lab in enumerate(data.labels):
        cells = [
            f"{results[m].residual_translation[k] * 1e3:8.3f} /{math.degrees(results[m].residual_rotation[k]):8.4f}"
            for m in names
        ]
        print(f"{lab:>20s} " + " ".join(f"{c:>18s}" for c in cells))
    warned = {w for r in results.values() for w in r.warnings}
    for w in sorted(warned):
        print(f"warning: {w}")
    return 0
