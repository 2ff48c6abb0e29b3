"""A folder of head-camera images -> the board's corners per image (:class:`PixelData`).

The layout is stage 2's (``docs/images.md``)::

    IMAGES_DIR/
      <camera link>/<record>.png      one sub-folder per head camera
      <camera link>.yaml              its intrinsics (OpenCV FileStorage, cv2.calibrateCamera)
      joints.csv                      the joint readings of every record
      board.json                      the board (cpc2urdf/board@1), unless given

Each image is read by :func:`~cpc2urdf.identification.vision.measure_head.measure_head_images`
(OpenCV's detector for the board's kind; a grid's orientation resolved by PnP); the detected
points (ellipse-centre corrected for circle grids) are what the pixel fit uses.
"""

from __future__ import annotations

import os
from collections.abc import Collection, Mapping, Sequence
from pathlib import Path

import numpy as np

from cpc2urdf.errors import InputFileError
from cpc2urdf.identification.selfcal.pixel_problem import BoardView, CameraModel, PixelData
from cpc2urdf.identification.vision.boards.board import Board
from cpc2urdf.identification.vision.boards.board_file import load_board
from cpc2urdf.identification.vision.measure_head import HeadCamera, measure_head_images
from cpc2urdf.identification.vision.rig_file import load_camera
from cpc2urdf.model import RobotStructure

BOARD_FILE = "board.json"
PNP_RMS_PX = (
    20.0  # [px] looser than stage 2's: intrinsics a few % off still give the fit its corners
)


def folder_board(
    images_dir: str | os.PathLike[str], board: Board | str | os.PathLike[str] | None
) -> Board:
    """``board``, a board file, or the folder's ``board.json``."""
    if isinstance(board, Board):
        return board
    path = Path(board) if board is not None else Path(images_dir) / BOARD_FILE
    if not path.is_file():
        raise InputFileError(path, "no board file (give --board BOARD.json)")
    return load_board(path)


def folder_cameras(
    images_dir: str | os.PathLike[str],
    cameras: Sequence[str],
    intrinsics: Mapping[str, str | os.PathLike[str]] | None = None,
) -> dict[str, CameraModel]:
    """Each camera's intrinsics: its file in ``intrinsics``, else ``<camera>.yaml`` in the folder."""
    out = {}
    for c in cameras:
        path = Path((intrinsics or {}).get(c) or Path(images_dir) / f"{c}.yaml")
        if not path.is_file():
            raise InputFileError(path, f"no intrinsics file for camera {c}")
        K, D, size = load_camera(path)
        out[c] = CameraModel(K, np.asarray(D, dtype=float), size)
    return out


def read_pixel_data(
    images_dir: str | os.PathLike[str],
    structure: RobotStructure,
    cameras: Mapping[str, CameraModel],
    board: Board,
    *,
    board_frame: str | None = None,
    on_error: str = "skip",
    show_progress: bool = False,
    joint_aliases: Mapping[str, str] | None = None,
    frame_of: Mapping[str, str] | None = None,
    other_joints: Collection[str] = (),
) -> PixelData:
    """The board's corners in every readable image of ``images_dir`` (module docstring).

    ``cameras`` are keyed by their sub-folders (the camera links the user names); ``frame_of``
    maps a sub-folder to the model's camera frame (default: the same name). ``joints.csv``'s
    columns of ``other_joints`` are skipped. A board is kept when its PnP pose reprojects within
    :data:`PNP_RMS_PX` (the fit refines or refuses intrinsics that are off; a misdetected grid is
    its outlier).

    Raises:
        InputFileError, DegenerateDataError, ConfigurationError: As ``measure_head_images``.
    """
    m = measure_head_images(
        Path(images_dir),
        {c: HeadCamera(cam.K, cam.D, cam.image_size) for c, cam in cameras.items()},
        structure,
        board=board,
        on_error=on_error,
        show_progress=show_progress,
        joint_aliases=joint_aliases,
        other_joints=other_joints,
        max_rms_px=PNP_RMS_PX,
    )

    def frame(c: str) -> str:
        return (frame_of or {}).get(c, c)

    labels: list[str] = []
    q: list[np.ndarray] = []
    index: dict[str, int] = {}
    views = []
    for c in cameras:
        found = zip(
            m.labels[c],
            m.q[c],
            m.corners[c],
            m.T_camera_target[c],
            m.reprojection_rms[c],
            strict=True,
        )
        for label, qi, (ids, uv), T, rms in found:
            if label not in index:
                index[label] = len(labels)
                labels.append(label)
                q.append(qi)
            views.append(BoardView(frame(c), index[label], ids, uv, (T, float(rms))))
    return PixelData(
        np.array(q),
        labels,
        views,
        {frame(c): cam for c, cam in cameras.items()},
        board.object_points(),
        board_frame,
        source=str(images_dir),
        notes=list(m.problems),
        names={frame(c): c for c in cameras if frame(c) != c},
    )


__all__ = ["BOARD_FILE", "folder_board", "folder_cameras", "read_pixel_data"]
