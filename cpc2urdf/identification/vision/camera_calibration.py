"""Camera and stereo-rig calibration from board images (``cv2.calibrateCamera``, ``cv2.stereoCalibrate``).

For users without intrinsics: the head's cameras from their stage-2 board images
(:func:`calibrate_camera_images`), and the measuring rig from board images taken by both of its
cameras (:func:`calibrate_rig_images`), written as the camera and rig files
:mod:`~cpc2urdf.identification.vision.rig_file` reads. Folder layouts (``docs/images.md``)::

    CAMERA_DIR/<view>.png                 one camera
    RIG_DIR/left/<view>.png               a stereo rig: the same <view> names in both folders
    RIG_DIR/right/<view>.png

Every view's reprojection error is reported, and views are named when the board is not found
(handled by ``on_error``: ``"stop"`` raises, ``"skip"`` leaves the view out) or when their error
exceeds :data:`OUTLIER_FACTOR` x the median (listed in :attr:`CameraCalibration.outliers`; the
user decides). Distortion is OpenCV's 5-term model with ``k3`` fixed at 0 unless ``fix_k3=False``
(a few views do not determine ``k3``).

A stereo calibration needs the same point ids in both images of a view, so the board must give a
unique orientation (:attr:`Board.pose_ambiguity`): each camera is calibrated alone first, its
intrinsics fix every view's orientation (:func:`~cpc2urdf.identification.vision.boards.board_poses.board_pose`),
then ``cv2.stereoCalibrate`` refines all parameters together from those intrinsics.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from cpc2urdf.errors import ConfigurationError, DegenerateDataError, InputFileError
from cpc2urdf.identification.vision.boards.board import Board
from cpc2urdf.identification.vision.boards.board_poses import (
    MIN_BOARD_POINTS,
    board_pose,
    common_points,
    detect_board,
)
from cpc2urdf.identification.vision.detect import DetectionError
from cpc2urdf.identification.vision.image_folders import (
    IMAGE_EXTENSIONS,
    check_on_error,
    read_grey,
    report_problem,
)
from cpc2urdf.identification.vision.stereo import StereoRig

Array = NDArray[np.float64]

OUTLIER_FACTOR = 3.0  # a view reprojecting worse than this x the median view is named
MIN_VIEWS = 3  # calibrateCamera with fewer board views is refused
_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-12)


@dataclass
class CameraCalibration:
    """What :func:`calibrate_camera_images` returns.

    Attributes:
        K: Camera matrix [px], shape (3, 3).
        D: Distortion (k1, k2, p1, p2, k3), shape (5,).
        image_size: (width, height) [px].
        rms: Overall RMS reprojection error [px].
        view_rms: Per view used (file name), its RMS reprojection error [px].
        std_intrinsics: OpenCV's standard deviations of (fx, fy, cx, cy, k1, k2, p1, p2, k3) from
            the residuals (``calibrateCameraExtended``).
        outliers: Views whose error exceeds :data:`OUTLIER_FACTOR` x the median (one line each).
        problems: Views left out (board not found), one line each.
    """

    K: Array
    D: Array
    image_size: tuple[int, int]
    rms: float
    view_rms: dict[str, float]
    std_intrinsics: Array
    outliers: list[str] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)


@dataclass
class RigCalibration:
    """What :func:`calibrate_rig_images` returns.

    Attributes:
        rig: The rig (world = left camera; ``x_right = R x_left + T``).
        rms: Overall RMS reprojection error of ``cv2.stereoCalibrate`` [px].
        view_rms: Per view, (left, right) RMS reprojection errors [px].
        left, right: The single-camera calibrations it started from.
        outliers: Views whose error exceeds :data:`OUTLIER_FACTOR` x the median.
        problems: Views left out, one line each.
    """

    rig: StereoRig
    rms: float
    view_rms: dict[str, tuple[float, float]]
    left: CameraCalibration
    right: CameraCalibration
    outliers: list[str] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)


def list_images(folder: str | Path) -> list[Path]:
    """The image files of ``folder`` (:data:`IMAGE_EXTENSIONS`), sorted by name.

    Raises:
        InputFileError: Not a folder, or no image in it.
    """
    root = Path(folder)
    if not root.is_dir():
        raise InputFileError(root, "no such images folder")
    files = sorted(
        p for p in root.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_EXTENSIONS
    )
    if not files:
        raise InputFileError(
            root, f"no images in the folder (looked for {', '.join(IMAGE_EXTENSIONS)})"
        )
    return files


def _read_same_size(
    paths: Sequence[Path], size: tuple[int, int] | None
) -> tuple[list[NDArray[np.uint8]], tuple[int, int]]:
    imgs = []
    for p in paths:
        img = read_grey(p)
        this = (int(img.shape[1]), int(img.shape[0]))
        if size is None:
            size = this
        elif this != size:
            raise InputFileError(
                p,
                f"image is {this[0]} x {this[1]} px, the first image is {size[0]} x {size[1]} px "
                "(all views of one camera must have one size)",
            )
        imgs.append(img)
    assert size is not None
    return imgs, size


def _outliers(view_rms: dict[str, float]) -> list[str]:
    med = float(np.median(list(view_rms.values())))
    return [
        f"{name}: reprojection error {e:.3f} px RMS > {OUTLIER_FACTOR:g} x the median view ({med:.3f} px)"
        for name, e in view_rms.items()
        if e > OUTLIER_FACTOR * med
    ]


def _flags(fix_k3: bool) -> int:
    return cv2.CALIB_FIX_K3 if fix_k3 else 0


def _detect_views(
    board: Board,
    paths: Sequence[Path],
    names: Sequence[str],
    imgs: Sequence[NDArray[np.uint8]],
    on_error: str,
    problems: list[str],
) -> tuple[list[Array], list[Array], list[str]]:
    """The board's points in each view (object points, pixels, the view's name), for every view
    where it is found; the others go to :func:`report_problem` (raised or listed in ``problems``)."""
    obj: list[Array] = []
    pts: list[Array] = []
    found_in: list[str] = []
    for path, name, img in zip(paths, names, imgs, strict=True):
        found = detect_board(img, board, image_name=str(path))
        if isinstance(found, DetectionError):
            report_problem(found, on_error, problems)
            continue
        obj.append(board.object_points()[found.ids])
        pts.append(found.uv)
        found_in.append(name)
    return obj, pts, found_in


def _calibrate(
    obj: list[Array],
    img: list[Array],
    size: tuple[int, int],
    names: list[str],
    fix_k3: bool,
    problems: list[str],
) -> CameraCalibration:
    if len(obj) < MIN_VIEWS:
        raise DegenerateDataError(
            f"the board was found in {len(obj)} views; camera calibration needs at least {MIN_VIEWS}"
            + (f"; first problem: {problems[0]}" if problems else "")
        )
    o = [np.ascontiguousarray(x, dtype=np.float32).reshape(-1, 1, 3) for x in obj]
    p = [np.ascontiguousarray(x, dtype=np.float32).reshape(-1, 1, 2) for x in img]
    rms, K, D, _, _, std_i, _, per_view = cv2.calibrateCameraExtended(
        o, p, size, np.eye(3), np.zeros(5), flags=_flags(fix_k3), criteria=_CRITERIA
    )
    view_rms = {n: float(e) for n, e in zip(names, np.asarray(per_view).ravel(), strict=True)}
    D5 = np.zeros(5)
    D5[: min(5, np.asarray(D).size)] = np.asarray(D, dtype=float).ravel()[:5]
    return CameraCalibration(
        np.asarray(K, dtype=float),
        D5,
        size,
        float(rms),
        view_rms,
        np.asarray(std_i, dtype=float).ravel()[:9],
        _outliers(view_rms),
        list(problems),
    )


def calibrate_camera_images(
    images: str | Path | Sequence[Path],
    board: Board,
    *,
    on_error: str = "stop",
    fix_k3: bool = True,
    image_size: tuple[int, int] | None = None,
) -> CameraCalibration:
    """Intrinsics of one camera from its views of ``board`` (``cv2.calibrateCameraExtended``).

    Args:
        images: A folder of images or a list of image files.
        board: The board (any kind; orientation does not matter for intrinsics).
        on_error: ``"stop"`` (a view without the board raises) or ``"skip"`` (left out, listed).
        fix_k3: Keep ``k3 = 0``.
        image_size: Required (width, height) [px], e.g. from a camera file; default the first image's.

    Raises:
        InputFileError: No images, an unreadable image, images of different sizes.
        DetectionError: With ``on_error="stop"``, the first view without the board.
        DegenerateDataError: Fewer than :data:`MIN_VIEWS` usable views.
    """
    check_on_error(on_error)
    paths = list_images(images) if isinstance(images, (str, Path)) else list(images)
    imgs, size = _read_same_size(paths, image_size)
    problems: list[str] = []
    obj, pts, names = _detect_views(board, paths, [p.name for p in paths], imgs, on_error, problems)
    return _calibrate(obj, pts, size, names, fix_k3, problems)


def calibrate_rig_images(
    folder: str | Path,
    board: Board,
    *,
    on_error: str = "stop",
    fix_k3: bool = True,
) -> RigCalibration:
    """A stereo rig from views of ``board`` in ``folder/left`` and ``folder/right`` (same names).

    Each camera is calibrated alone (:func:`calibrate_camera_images`), every view's point ids are
    fixed by its pose (:func:`board_pose`, so the board must be orientation-unique), the ids both
    images of a view show are kept, and ``cv2.stereoCalibrateExtended`` refines the intrinsics and
    ``R``, ``T`` together (``x_right = R x_left + T``).

    Raises:
        ConfigurationError: A board without a unique orientation (symmetric circle grid).
        InputFileError: Missing ``left/`` or ``right/``, a view in only one of them, images of
            different sizes.
        DetectionError: With ``on_error="stop"``, the first view where a camera misses the board.
        DegenerateDataError: Fewer than :data:`MIN_VIEWS` usable views.
    """
    check_on_error(on_error)
    if board.pose_ambiguity:
        raise ConfigurationError(
            f"{board.name}: {board.pose_ambiguity}, so the two cameras' points cannot be matched; "
            "calibrate a rig with a ChArUco board, an asymmetric circle grid or an odd x even chessboard"
        )
    root = Path(folder)
    if not root.is_dir():
        raise InputFileError(root, "no such images folder")
    sides = {}
    for sub in ("left", "right"):
        if not (root / sub).is_dir():
            raise InputFileError(
                root, f"missing sub-folder {sub}/ (expected left/<view>.png and right/<view>.png)"
            )
        sides[sub] = {p.stem: p for p in list_images(root / sub)}
    for one, other in (("left", "right"), ("right", "left")):
        lone = sorted(set(sides[one]) - set(sides[other]))
        if lone:
            raise InputFileError(
                sides[one][lone[0]],
                f"no {other}/ image of view {lone[0]!r} (every view needs both images)",
            )
    views = sorted(sides["left"])
    imgs_l, size = _read_same_size([sides["left"][v] for v in views], None)
    imgs_r, _ = _read_same_size([sides["right"][v] for v in views], size)
    problems: list[str] = []
    # 1. each camera alone, from every view where it finds the board
    mono = []
    for side, imgs in (("left", imgs_l), ("right", imgs_r)):
        obj, pts, names = _detect_views(
            board, [sides[side][v] for v in views], views, imgs, on_error, problems
        )
        mono.append(_calibrate(obj, pts, size, names, fix_k3, []))
    left, right = mono
    # 2. point ids fixed by each view's pose; 3. stereoCalibrate from the single-camera intrinsics
    obj_s, pl_s, pr_s, names_s = [], [], [], []
    for v, il, ir in zip(views, imgs_l, imgs_r, strict=True):
        a = board_pose(
            il, left.K, left.D, board, image_name=str(sides["left"][v]), max_rms_px=np.inf
        )
        b = board_pose(
            ir, right.K, right.D, board, image_name=str(sides["right"][v]), max_rms_px=np.inf
        )
        bad = [r for r in (a, b) if isinstance(r, DetectionError)]
        if bad:
            if str(bad[0]) not in problems:
                report_problem(bad[0], on_error, problems)
            continue
        assert not isinstance(a, DetectionError) and not isinstance(b, DetectionError)
        both, uv_l, uv_r = common_points(a, b)
        if len(both) < MIN_BOARD_POINTS:
            report_problem(
                DetectionError(
                    f"{sides['left'][v]} + {sides['right'][v]}",
                    board.name,
                    f"too few corners seen by both cameras ({len(both)} < {MIN_BOARD_POINTS})",
                ),
                on_error,
                problems,
            )
            continue
        obj_s.append(
            np.ascontiguousarray(board.object_points()[both], dtype=np.float32).reshape(-1, 1, 3)
        )
        pl_s.append(np.ascontiguousarray(uv_l, dtype=np.float32).reshape(-1, 1, 2))
        pr_s.append(np.ascontiguousarray(uv_r, dtype=np.float32).reshape(-1, 1, 2))
        names_s.append(v)
    if len(obj_s) < MIN_VIEWS:
        raise DegenerateDataError(
            f"{root}: both cameras saw the board in {len(obj_s)} views; rig calibration needs at least "
            f"{MIN_VIEWS}" + (f"; first problem: {problems[0]}" if problems else "")
        )
    flags = cv2.CALIB_USE_INTRINSIC_GUESS | _flags(fix_k3)
    res = cv2.stereoCalibrateExtended(
        obj_s,
        pl_s,
        pr_s,
        left.K.copy(),
        left.D.copy(),
        right.K.copy(),
        right.D.copy(),
        size,
        np.eye(3),
        np.zeros((3, 1)),
        flags=flags,
        criteria=_CRITERIA,
    )
    rms, K1, D1, K2, D2, R, T = res[:7]
    per_view = np.asarray(res[-1], dtype=float).reshape(-1, 2)
    view_rms = {v: (float(e[0]), float(e[1])) for v, e in zip(names_s, per_view, strict=True)}
    rig = StereoRig(
        np.asarray(K1, dtype=float),
        np.asarray(D1, dtype=float).ravel()[:5],
        np.asarray(K2, dtype=float),
        np.asarray(D2, dtype=float).ravel()[:5],
        np.asarray(R, dtype=float),
        np.asarray(T, dtype=float).ravel(),
        size,
    )
    outliers = _outliers({v: max(e) for v, e in view_rms.items()})
    return RigCalibration(rig, float(rms), view_rms, left, right, outliers, problems)


__all__ = [
    "MIN_VIEWS",
    "OUTLIER_FACTOR",
    "CameraCalibration",
    "RigCalibration",
    "calibrate_camera_images",
    "calibrate_rig_images",
    "list_images",
]
