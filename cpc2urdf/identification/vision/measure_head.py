"""Stage-2 measurements from images: the head cameras' images of the target -> target poses.

The head's own cameras photograph the 25-disk target (Shih et al. sec. 5), or a standard board
(chessboard, ChArUco, asymmetric circle grid: ``board=``). The folder layout
(``docs/images.md``)::

    IMAGES_DIR/
      camera_left_optical/<record>.png
      camera_right_optical/<record>.png
      joints.csv

:func:`measure_head_images` gives ``T_camera_target`` per camera and record by ``cv2.solvePnP``
(:func:`~cpc2urdf.identification.vision.plate_poses.target_pose`), with the joint readings of the
records. With an identified model these become hand-eye poses
(:mod:`cpc2urdf.identification.handeye.head_images`), the input of ``cpc2urdf handeye``. An image
that cannot be measured is handled by the ``on_error`` policy of
:mod:`~cpc2urdf.identification.vision.image_folders`.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from cpc2urdf.errors import ConfigurationError, DegenerateDataError, InputFileError
from cpc2urdf.identification.vision.boards.board import Board
from cpc2urdf.identification.vision.boards.board_poses import BoardPose, board_pose
from cpc2urdf.identification.vision.detect import DetectionError
from cpc2urdf.identification.vision.image_folders import (
    RecordError,
    check_on_error,
    find_image,
    read_grey,
    report_problem,
)
from cpc2urdf.identification.vision.joints_csv import read_joints_csv
from cpc2urdf.identification.vision.plate_poses import MAX_PNP_RMS_PX, TargetPose, target_pose
from cpc2urdf.identification.vision.targets import PlateDesign, target_design
from cpc2urdf.model import RobotStructure
from cpc2urdf.progress import progress_checked

Array = NDArray[np.float64]


@dataclass
class HeadCamera:
    """A head camera's intrinsics (OpenCV model).

    Attributes:
        K: Camera matrix [px], shape (3, 3).
        D: Distortion coefficients, shape (5,).
        image_size: (width, height) [px].
    """

    K: Array
    D: Array
    image_size: tuple[int, int]


@dataclass
class HeadImageMeasurement:
    """What :func:`measure_head_images` returns.

    Attributes:
        labels: Per camera, the labels of the records used.
        q: Per camera, the joint readings of those records, shape (N_c, n).
        T_camera_target: Per camera, solvePnP target poses, shape (N_c, 4, 4).
        reprojection_rms: Per camera, the RMS reprojection error per record [px], shape (N_c,).
        problems: Skipped images with the reason.
        corners: With a standard board: per camera and record, the detected points' ids and
            pixels (``BoardPose.ids``, ``BoardPose.uv``), for a fit on pixels.
    """

    labels: dict[str, list[str]]
    q: dict[str, Array]
    T_camera_target: dict[str, Array]
    reprojection_rms: dict[str, Array]
    problems: list[str]
    corners: dict[str, list[tuple[NDArray[np.intp], Array]]] = field(default_factory=dict)


def measure_head_images(
    images_dir: str | Path,
    cameras: Mapping[str, HeadCamera],
    structure: RobotStructure,
    *,
    joints: str | Path | None = None,
    design: PlateDesign | None = None,
    board: Board | None = None,
    on_error: str = "skip",
    correct_bias: bool = True,
    show_progress: bool = False,
    joint_aliases: Mapping[str, str] | None = None,
    other_joints: Collection[str] = (),
    max_rms_px: float = MAX_PNP_RMS_PX,
) -> HeadImageMeasurement:
    """Stage-2 target poses ``T_camera_target`` from the head cameras' images.

    Args:
        images_dir: Folder with one sub-folder per camera (named like the camera frame) and
            ``joints.csv``.
        cameras: Camera frame name -> intrinsics.
        structure: The robot (for the joint columns).
        joints: The ``joints.csv`` (default ``images_dir/joints.csv``).
        design: The target (default :func:`~cpc2urdf.identification.vision.targets.target_design`).
        board: A standard board as the target instead (:mod:`~cpc2urdf.identification.vision.boards.board`;
            OpenCV's detector, :func:`~cpc2urdf.identification.vision.boards.board_poses.board_pose`).
        on_error: ``"skip"``/``"skip-record"`` (the image) or ``"stop"``.
        correct_bias: Remove the ellipse-centre offset before the final solvePnP.
        show_progress: Progress bar on stderr.
        joint_aliases: Other names of the joint columns (a URDF's own joint names,
            :func:`~cpc2urdf.identification.vision.joints_csv.urdf_joint_columns`).
        other_joints: Columns of the robot's other joints, skipped.
        max_rms_px: A board's PnP pose must reproject within this [px] RMS (wrong intrinsics
            otherwise; a fit that refines them takes a looser limit).

    Raises:
        InputFileError, DetectionError, DegenerateDataError: as
            :func:`~cpc2urdf.identification.vision.measure_stereo.measure_stereo_images`.
        ConfigurationError: A board that gives no unique pose (symmetric circle grid).
    """
    check_on_error(on_error)
    if board is not None and board.pose_ambiguity:
        raise ConfigurationError(
            f"{board.name}: {board.pose_ambiguity}, so it gives no unique target pose; "
            "use a ChArUco board, an asymmetric circle grid or an odd x even chessboard"
        )
    root = Path(images_dir)
    if not root.is_dir():
        raise InputFileError(root, "no such images folder")
    if not cameras:
        raise ConfigurationError("no head camera given")
    for c in cameras:
        if not (root / c).is_dir():
            raise InputFileError(root, f"missing sub-folder {c}/ for camera {c}")
    table = read_joints_csv(
        joints or root / "joints.csv", structure, aliases=joint_aliases, ignore=other_joints
    )
    design = design or target_design()
    target = board.name if board is not None else design.name
    problems: list[str] = []
    out_l: dict[str, list[str]] = {c: [] for c in cameras}
    out_q: dict[str, list[Array]] = {c: [] for c in cameras}
    out_T: dict[str, list[Array]] = {c: [] for c in cameras}
    out_r: dict[str, list[float]] = {c: [] for c in cameras}
    out_c: dict[str, list[tuple[NDArray[np.intp], Array]]] = {c: [] for c in cameras}
    jobs = [(i, c) for i in range(len(table.records)) for c in cameras]
    # The bar's "done" line only once the records are known to be usable (progress_checked).
    with progress_checked(jobs, "measure", show_progress) as bar:
        for i, c in bar:
            rec = table.records[i]
            cam = cameras[c]
            path = find_image(root / c, rec)
            try:
                if path is None:
                    raise RecordError(f"{c}/{rec}.*", target, "no image file")
                img = read_grey(path)
            except InputFileError as e:
                report_problem(RecordError(e.path, target, e.problem), on_error, problems)
                continue
            except RecordError as e:
                report_problem(e, on_error, problems)
                continue
            if (img.shape[1], img.shape[0]) != tuple(cam.image_size):
                report_problem(
                    RecordError(
                        str(path),
                        target,
                        f"image is {img.shape[1]} x {img.shape[0]} px, the camera file says "
                        f"{cam.image_size[0]} x {cam.image_size[1]}",
                    ),
                    on_error,
                    problems,
                )
                continue
            r: TargetPose | BoardPose | DetectionError
            if board is not None:
                r = board_pose(
                    img, cam.K, cam.D, board, image_name=str(path), max_rms_px=max_rms_px
                )
            else:
                r = target_pose(
                    img, cam.K, cam.D, design, image_name=str(path), correct_bias=correct_bias
                )
            if isinstance(r, DetectionError):
                report_problem(r, on_error, problems)
                continue
            out_l[c].append(table.labels[i])
            out_q[c].append(table.q[i])
            out_T[c].append(r.T_camera_board if isinstance(r, BoardPose) else r.T_camera_target)
            out_r[c].append(r.reprojection_rms)
            if isinstance(r, BoardPose):
                out_c[c].append((r.ids, r.uv))
        for c in cameras:
            if len(out_T[c]) < 3:
                raise DegenerateDataError(
                    f"{root}: camera {c} saw the target in {len(out_T[c])} records; a calibration needs at least 3"
                    + (f"; first problem: {problems[0]}" if problems else "")
                )
    return HeadImageMeasurement(
        out_l,
        {c: np.array(v) for c, v in out_q.items()},
        {c: np.array(v) for c, v in out_T.items()},
        {c: np.array(v) for c, v in out_r.items()},
        problems,
        out_c if board is not None else {},
    )


__all__ = ["HeadCamera", "HeadImageMeasurement", "measure_head_images"]
