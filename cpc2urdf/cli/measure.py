"""``cpc2urdf measure IMAGES_DIR ...``: measurement files from images.

Stage 1 (stereo rig looking at the head's plates)::

    cpc2urdf measure IMAGES_DIR --rig rig.yaml [--joints joints.csv] [--robot iis_head] \\
        -o measurements.json [--on-error skip|skip-record|stop]

Either stage can use standard boards instead of the circle plates and the 25-disk target
(``--board``: chessboard, ChArUco, asymmetric circle grid; ``docs/images.md``).

Stage 2 (the head's cameras looking at the 25-disk target), hand poses from an identified model::

    cpc2urdf measure IMAGES_DIR --stage2 --model identified.json [--camera NAME=intrinsics.yaml ...] \\
        -o OUT_DIR [--on-error skip|stop]

The folder layouts, ``joints.csv`` and the rig/camera files are documented in ``docs/images.md``.

Every argument and input file that can be checked before the images are measured is checked
first (rig, robot, model, cameras and their hand frames, the output path), so that bad input is
refused with one line before any progress is shown.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from cpc2urdf.identification.vision.boards.board import Board


def add_parser(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = subparsers.add_parser(
        "measure",
        help="measure plate poses (stereo) or target poses (head cameras) from images",
        description="Detect the calibration plates in stereo images (IMAGES_DIR/left, IMAGES_DIR/right) "
        "and write a cpc2urdf/measurements@1 file of T_world_<plate> (world = left rig camera); or, "
        "with --stage2, detect the 25-disk target in the head cameras' images (IMAGES_DIR/<camera>) "
        "and write one cpc2urdf/handeye-poses@1 file per camera (T_camera_target by solvePnP, "
        "T_base_hand from --model). See docs/images.md.",
    )
    p.add_argument("images", metavar="IMAGES_DIR", help="folder of images (see docs/images.md)")
    p.add_argument(
        "-o",
        "--output",
        required=True,
        help="measurement file to write (stage 1), or output folder (--stage2)",
    )
    p.add_argument("--joints", help="joint readings CSV (default IMAGES_DIR/joints.csv)")
    p.add_argument(
        "--on-error",
        choices=("skip", "skip-record", "stop"),
        default="skip",
        help="a plate not found or ambiguous: skip that plate (default), skip the whole "
        "record, or stop (exit 2); skips are listed on stderr and in the output",
    )
    p.add_argument(
        "--no-bias-correction",
        action="store_true",
        help="do not remove the ellipse-centre offset of the circles' images",
    )
    p.add_argument(
        "--board",
        action="append",
        default=[],
        metavar="[FRAME=]FILE",
        help="a standard board (cpc2urdf/board@1: chessboard, ChArUco, circle grid; docs/images.md) "
        "instead of the default circle plates / 25-disk target: with --stage2 one FILE, the target; "
        "stage 1 FRAME=FILE per plate frame (several plates: ChArUco boards with distinct marker ids)",
    )
    g1 = p.add_argument_group("stage 1 (stereo rig)")
    g1.add_argument("--rig", help="stereo rig file: OpenCV FileStorage YAML with K1 D1 K2 D2 R T")
    g1.add_argument(
        "--robot", default="iis_head", help="shipped robot name or spec file (default iis_head)"
    )
    g2 = p.add_argument_group("stage 2 (head cameras)")
    g2.add_argument("--stage2", action="store_true", help="measure the head cameras' target images")
    g2.add_argument("--model", help="identified model file (gives T_base_hand)")
    g2.add_argument(
        "--camera",
        action="append",
        default=[],
        metavar="NAME=FILE",
        help="a camera frame and its intrinsics (OpenCV FileStorage: K, D, image_size); "
        "default: every IMAGES_DIR/<camera>.yaml next to an IMAGES_DIR/<camera>/ folder",
    )
    p.set_defaults(run=run, read=default_joints)


def default_joints(args: argparse.Namespace) -> dict[str, str]:
    """The joint readings read without being named (checked against ``-o`` before the command runs)."""
    import os

    return (
        {}
        if args.joints
        else {"joints (default IMAGES_DIR/joints.csv)": os.path.join(args.images, "joints.csv")}
    )


def _report(problems: list[str], limit: int = 20) -> None:
    import sys

    for line in problems[:limit]:
        print(f"  skipped: {line}", file=sys.stderr)
    if len(problems) > limit:
        print(
            f"  ... and {len(problems) - limit} more (all listed in the output's provenance)",
            file=sys.stderr,
        )


def run(args: argparse.Namespace) -> int:
    if args.stage2:
        return _run_stage2(args)
    from cpc2urdf.errors import ConfigurationError
    from cpc2urdf.files.jsonio import check_output_path
    from cpc2urdf.files.measurements import save_measurements
    from cpc2urdf.files.robot_ref import load_robot
    from cpc2urdf.identification.vision.joints_csv import urdf_joint_columns
    from cpc2urdf.identification.vision.measure_stereo import measure_stereo_images
    from cpc2urdf.identification.vision.rig_file import load_rig

    if not args.rig:
        raise ConfigurationError(
            "stage 1 needs --rig rig.yaml (or pass --stage2 for the head cameras)"
        )
    rig = load_rig(args.rig)
    spec = load_robot(args.robot)
    boards = _plate_boards(args.board, [f.name for f in spec.structure.frames if f.kind == "plate"])
    check_output_path(args.output)
    res = measure_stereo_images(
        args.images,
        rig,
        spec.structure,
        joints=args.joints,
        on_error=args.on_error,
        boards=boards,
        correct_bias=not args.no_bias_correction,
        robot_ref=args.robot,
        show_progress=True,
        joint_aliases=urdf_joint_columns(spec),
    )
    ms = res.measurements
    path = save_measurements(ms, args.output)
    n_plates = sum(int(ms.has_pose(f).sum()) for f in ms.poses)
    fits = [v for f in ms.fit_rms for v in ms.fit_rms[f] if v == v]
    print(
        f"wrote {path}: {ms.n_records} records, {n_plates} plate poses"
        + (f", registration RMS median {sorted(fits)[len(fits) // 2] * 1e3:.3f} mm" if fits else "")
        + (f"; skipped {len(res.problems)} (see stderr)" if res.problems else "")
    )
    _report(res.problems)
    return 0


def _run_stage2(args: argparse.Namespace) -> int:
    from cpc2urdf.errors import ConfigurationError, OutputError
    from cpc2urdf.files.robot_ref import load_model
    from cpc2urdf.identification.handeye.head_images import write_handeye_files
    from cpc2urdf.identification.handeye.stage2 import HAND_OF_CAMERA
    from cpc2urdf.identification.vision.joints_csv import urdf_joint_columns
    from cpc2urdf.identification.vision.measure_head import HeadCamera, measure_head_images
    from cpc2urdf.identification.vision.rig_file import load_camera

    if not args.model:
        raise ConfigurationError("--stage2 needs --model identified.json (it gives T_base_hand)")
    model = load_model(args.model)
    images = Path(args.images)
    files: dict[str, Path] = {}
    for item in args.camera:
        name, sep, f = item.partition("=")
        if not sep or not name or not f:
            raise ConfigurationError(f"--camera expects NAME=FILE, got {item!r}")
        files[name] = Path(f)
    if not files:
        files = {
            c: images / f"{c}.yaml"
            for c in HAND_OF_CAMERA
            if (images / c).is_dir() and (images / f"{c}.yaml").is_file()
        }
        if not files:
            raise ConfigurationError(
                f"no camera found: expected {images}/<camera>/ image folders with {images}/<camera>.yaml "
                f"intrinsics for cameras {', '.join(HAND_OF_CAMERA)}, or --camera NAME=FILE (no intrinsics? "
                f"cpc2urdf calibrate camera {images}/<camera> --board BOARD -o {images}/<camera>.yaml)"
            )
    for c in files:  # write_handeye_files needs each camera's hand frame in the model
        if c not in HAND_OF_CAMERA:
            raise ConfigurationError(
                f"no hand frame known for camera {c!r}; known: {sorted(HAND_OF_CAMERA)}"
            )
        model.structure.frame(HAND_OF_CAMERA[c])
    cams = {c: HeadCamera(*load_camera(f)) for c, f in files.items()}
    board = None
    if args.board:
        from cpc2urdf.identification.vision.boards.board_file import load_board

        if len(args.board) > 1 or "=" in args.board[0]:
            raise ConfigurationError(
                f"--stage2 takes one --board FILE (the target), got {' '.join(args.board)}"
            )
        board = load_board(args.board[0])
        if board.pose_ambiguity:
            raise ConfigurationError(
                f"{args.board[0]}: {board.pose_ambiguity}, so it gives no unique target pose; "
                "use a ChArUco board, an asymmetric circle grid or an odd x even chessboard"
            )
    out = Path(args.output)
    if out.exists() and not out.is_dir():
        raise OutputError(
            f"{out}: --stage2 writes one file per camera into a folder; this is a file"
        )
    if not out.exists() and not out.parent.is_dir():
        raise OutputError(f"{out}: parent folder {out.parent} does not exist")
    res = measure_head_images(
        images,
        cams,
        model.structure,
        joints=args.joints,
        on_error=args.on_error,
        board=board,
        joint_aliases=urdf_joint_columns(model),
        correct_bias=not args.no_bias_correction,
        show_progress=True,
    )
    if not out.exists():
        out.mkdir()
    paths = write_handeye_files(res, model, out)
    for c, p in paths.items():
        rms = res.reprojection_rms[c]
        print(
            f"wrote {p}: {len(rms)} target poses, reprojection RMS median {float(sorted(rms)[len(rms) // 2]):.3f} px"
        )
    if res.problems:
        print(f"skipped {len(res.problems)} images (see stderr)")
    _report(res.problems)
    return 0


def _plate_boards(items: list[str], plates: list[str]) -> dict[str, Board] | None:
    """``--board FRAME=FILE`` (or one ``FILE`` for a robot with one plate) -> frame -> board."""
    if not items:
        return None
    from cpc2urdf.errors import ConfigurationError
    from cpc2urdf.identification.vision.boards.board_file import load_board

    out: dict[str, Board] = {}
    for item in items:
        frame, sep, f = item.rpartition("=")
        if not sep:
            if len(plates) != 1:
                raise ConfigurationError(
                    f"--board {item}: the robot has plates {', '.join(plates)}; "
                    "say which one with --board FRAME=FILE"
                )
            frame = plates[0]
        if frame in out:
            raise ConfigurationError(f"--board: two boards for {frame}")
        out[frame] = load_board(f)
    return out
