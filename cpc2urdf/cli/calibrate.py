"""``cpc2urdf calibrate camera|rig IMAGES_DIR --board board.json -o FILE``: intrinsics from board images.

One command with two modes (one entry in ``cli.COMMANDS``; both take the same board, error policy
and output, and differ only in the folder layout and the file written)::

    cpc2urdf calibrate camera IMAGES_DIR --board board.json -o camera.yaml   # IMAGES_DIR/<view>.png
    cpc2urdf calibrate rig IMAGES_DIR --board board.json -o rig.yaml         # IMAGES_DIR/{left,right}/<view>.png

``camera`` runs ``cv2.calibrateCamera`` and writes the camera file ``cpc2urdf measure --stage2``
reads (``K``, ``D``, ``image_size``); ``rig`` runs ``cv2.stereoCalibrate`` and writes the rig file
``cpc2urdf measure --rig`` reads. Both print every view's reprojection error and name the views
more than 3x the median; a view without the board stops with one line (exit 2) unless
``--on-error skip``. See ``docs/images.md``.
"""

from __future__ import annotations

import argparse


def add_parser(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = subparsers.add_parser(
        "calibrate",
        help="camera intrinsics (calibrateCamera) or a stereo rig (stereoCalibrate) from board images",
        description="Calibrate one camera (mode 'camera': IMAGES_DIR/<view>.png -> camera YAML with K, D, "
        "image_size) or a stereo rig (mode 'rig': IMAGES_DIR/left/<view>.png and IMAGES_DIR/right/<view>.png -> "
        "rig YAML with K1 D1 K2 D2 R T) from images of a standard board (cpc2urdf/board@1). Prints the "
        "reprojection error of every view and names the bad ones. See docs/images.md.",
    )
    p.add_argument("mode", choices=("camera", "rig"), help="one camera, or a stereo rig")
    p.add_argument("images", metavar="IMAGES_DIR", help="folder of board images")
    p.add_argument("--board", required=True, help="board file (cpc2urdf/board@1 JSON)")
    p.add_argument(
        "-o", "--output", required=True, help="camera or rig YAML to write (OpenCV FileStorage)"
    )
    p.add_argument(
        "--on-error",
        choices=("stop", "skip"),
        default="stop",
        help="a view without the board: stop with exit 2 (default) or leave it out (listed)",
    )
    p.add_argument("--k3", action="store_true", help="also estimate k3 (default: k3 = 0)")
    p.add_argument(
        "--units",
        choices=("m", "cm", "mm"),
        default="mm",
        help="unit of T in the rig file (default mm)",
    )
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    import sys

    import numpy as np

    from cpc2urdf.files.jsonio import check_output_path
    from cpc2urdf.identification.vision.boards.board_file import load_board
    from cpc2urdf.identification.vision.camera_calibration import (
        calibrate_camera_images,
        calibrate_rig_images,
    )
    from cpc2urdf.identification.vision.rig_file import save_camera, save_rig

    board = load_board(args.board)
    check_output_path(args.output)
    if args.mode == "camera":
        cam = calibrate_camera_images(
            args.images, board, on_error=args.on_error, fix_k3=not args.k3
        )
        errors = np.array(list(cam.view_rms.values()), dtype=np.float64).reshape(1, -1)
        path = save_camera(
            cam.K,
            cam.D,
            cam.image_size,
            args.output,
            extra=[("rms", cam.rms), ("per_view_reprojection_errors", errors)],
        )
        for name, e in cam.view_rms.items():
            print(f"  {name}: {e:.3f} px")
        print(
            f"wrote {path}: {len(cam.view_rms)} views, RMS {cam.rms:.3f} px, fx {cam.K[0, 0]:.2f} fy {cam.K[1, 1]:.2f} "
            f"cx {cam.K[0, 2]:.2f} cy {cam.K[1, 2]:.2f} px (1-sigma {cam.std_intrinsics[0]:.2f} {cam.std_intrinsics[1]:.2f} "
            f"{cam.std_intrinsics[2]:.2f} {cam.std_intrinsics[3]:.2f})"
        )
        outliers, problems = cam.outliers, cam.problems
    else:
        rig = calibrate_rig_images(args.images, board, on_error=args.on_error, fix_k3=not args.k3)
        errors = np.array(list(rig.view_rms.values()), dtype=np.float64)
        path = save_rig(
            rig.rig,
            args.output,
            units=args.units,
            extra=[("rms", rig.rms), ("per_view_reprojection_errors", errors)],
        )
        for name, (el, er) in rig.view_rms.items():
            print(f"  {name}: left {el:.3f} px, right {er:.3f} px")
        print(
            f"wrote {path}: {len(rig.view_rms)} views, RMS {rig.rms:.3f} px, baseline "
            f"{np.linalg.norm(rig.rig.T) * 1e3:.2f} mm"
        )
        outliers, problems = rig.outliers, rig.problems
    for line in outliers:
        print(f"  bad view: {line}", file=sys.stderr)
    for line in problems:
        print(f"  skipped: {line}", file=sys.stderr)
    return 0
