"""Standard boards in images: OpenCV's detectors, then ``T_camera_board`` or ``T_world_board``.

Detection uses OpenCV's own detectors (:func:`detect_board`): ``cv2.findChessboardCornersSB``
(falling back to ``cv2.findChessboardCorners`` + ``cv2.cornerSubPix``), ``cv2.aruco.CharucoDetector``
and ``cv2.findCirclesGrid``. Their point order is not always the board's (a grid can come out
rotated by 180 deg or mirrored), so :func:`board_pose` tries the grid's symmetries: it keeps the
orderings that show the camera the printed face and reproject within :data:`MAX_PNP_RMS_PX`, and
among those the one whose predicted black and white squares match the image; a board that stays
ambiguous (a symmetric circle grid) is refused, never guessed (:attr:`Board.pose_ambiguity`).

Poses: one camera (:func:`board_pose`): ``cv2.solvePnP`` (IPPE for the planar board) refined
by ``cv2.solvePnPRefineLM``; a stereo rig (:func:`stereo_board_pose`): the corners both cameras
see, matched by id, are triangulated (``StereoRig.triangulate``) and the board's points are
registered to them (Arun, Shih et al. eqs. (16)-(22)) -> ``T_world_board``. The error the pixel
noise predicts for a single-camera pose is :func:`pnp_pose_covariance` (the PnP Jacobian).

Failures are values: every function returns a result or a
:class:`~cpc2urdf.identification.vision.detect.DetectionError` naming the image, the board and the
reason (board not found, too few corners, ambiguous, geometry inconsistent).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from cpc2urdf.errors import Cpc2UrdfError
from cpc2urdf.identification.vision.boards.board import Board
from cpc2urdf.identification.vision.detect import (
    DetectionError,
    InconsistentDetectionError,
    PlateAmbiguousError,
    PlateNotFoundError,
    find_blobs,
)
from cpc2urdf.identification.vision.plate_poses import (
    MAX_EPIPOLAR_PX,
    MAX_FIT_RMS,
    MAX_PNP_RMS_PX,
    StereoPlatePose,
    ellipse_centre_offset,
)
from cpc2urdf.identification.vision.stereo import StereoRig
from cpc2urdf.identification.vision.targets import PlateDesign
from cpc2urdf.registration import plate_pose_from_points, registration_rms
from cpc2urdf.transforms import homogeneous

Array = NDArray[np.float64]

MIN_BOARD_POINTS = 6  # a ChArUco view with fewer corners is refused (PnP needs >= 4 non-collinear)
MIN_SPREAD = 0.05  # [-] smallest singular value / largest of the centred corners: below it they are collinear
_SUBPIX_CRITERIA = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-6)
_LM_CRITERIA = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-15)


@dataclass
class BoardDetection:
    """A board's points found in one image.

    Attributes:
        ids: Point ids (indices into :meth:`Board.object_points`), shape (N,).
        uv: Pixel coordinates (distorted, as in the image) [px], shape (N, 2).
    """

    ids: NDArray[np.intp]
    uv: Array


@dataclass
class BoardPose:
    """A board seen by one camera.

    Attributes:
        T_camera_board: Pose of the board in the camera's optical frame, shape (4, 4).
        ids: Point ids used, shape (N,).
        uv: Detected points [px], shape (N, 2).
        reprojection_rms: RMS reprojection error [px].
    """

    T_camera_board: Array
    ids: NDArray[np.intp]
    uv: Array
    reprojection_rms: float


# ---- detection -----------------------------------------------------------------------------------


def _not_found(image_name: str, board: Board, what: str) -> PlateNotFoundError:
    return PlateNotFoundError(image_name, board.name, what)


def detect_board(
    image: ArrayLike, board: Board, *, image_name: str = "image"
) -> BoardDetection | DetectionError:
    """Find ``board``'s points in a grey image with OpenCV's detector for its kind.

    The order of a grid's points may still be one of the grid's symmetries (module docstring);
    :func:`board_pose` resolves it. ChArUco ids are the board's.

    Returns:
        The points, or a :class:`PlateNotFoundError` (board not in the image, fewer than
        :data:`MIN_BOARD_POINTS` ChArUco corners, collinear corners).
    """
    img = np.ascontiguousarray(np.asarray(image, dtype=np.uint8))
    cols, rows = board.size
    if board.kind == "chessboard":
        ok, corners = cv2.findChessboardCornersSB(
            img, (cols, rows), flags=cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY
        )
        if not ok:
            ok, corners = cv2.findChessboardCorners(
                img, (cols, rows), flags=cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
            )
        if not ok:
            return _not_found(
                image_name,
                board,
                f"board not found (no chessboard of {cols} x {rows} inner corners)",
            )
        # cornerSubPix after either detector: on rendered views it halves findChessboardCornersSB's
        # corner error (0.09 -> 0.04 px RMS). Its window stays inside one square.
        c = np.asarray(corners, dtype=np.float32).reshape(-1, 1, 2)
        grid = c.reshape(rows, cols, 2)
        step = min(
            np.linalg.norm(np.diff(grid, axis=1), axis=2).min(),
            np.linalg.norm(np.diff(grid, axis=0), axis=2).min(),
        )
        win = int(np.clip(step / 3.0, 2, 7))
        corners = cv2.cornerSubPix(img, c, (win, win), (-1, -1), _SUBPIX_CRITERIA)
        return BoardDetection(
            np.arange(cols * rows), np.asarray(corners, dtype=float).reshape(-1, 2)
        )
    if board.kind == "charuco":
        det = cv2.aruco.CharucoDetector(board.charuco_board())
        corners, ids, _, marker_ids = det.detectBoard(img)
        n = 0 if ids is None else len(ids)
        if n == 0:
            seen = 0 if marker_ids is None else len(marker_ids)
            return _not_found(
                image_name,
                board,
                f"board not found (ChArUco {cols} x {rows} squares, {board.dictionary}, "
                f"ids {board.first_marker_id}..{board.first_marker_id + board.n_markers - 1}; "
                f"{seen} of its markers seen)",
            )
        if n < MIN_BOARD_POINTS:
            return _not_found(
                image_name,
                board,
                f"too few ChArUco corners ({n} < {MIN_BOARD_POINTS}; board partly hidden?)",
            )
        uv = np.asarray(corners, dtype=float).reshape(-1, 2)
        xy = board.object_points()[np.asarray(ids).ravel(), :2]
        sv = np.linalg.svd(xy - xy.mean(0), compute_uv=False)
        if sv[1] < MIN_SPREAD * sv[0]:
            return _not_found(
                image_name,
                board,
                f"the {n} ChArUco corners seen lie on one line (no pose from them)",
            )
        return BoardDetection(np.asarray(ids, dtype=np.intp).ravel(), uv)
    flags = (
        cv2.CALIB_CB_ASYMMETRIC_GRID
        if board.kind == "asymmetric_circles"
        else cv2.CALIB_CB_SYMMETRIC_GRID
    )
    ok, centres = cv2.findCirclesGrid(img, (cols, rows), flags=flags)
    if not ok:
        which = "asymmetric" if board.kind == "asymmetric_circles" else "symmetric"
        return _not_found(
            image_name, board, f"board not found (no {which} grid of {cols} x {rows} circles)"
        )
    uv = np.asarray(centres, dtype=float).reshape(-1, 2)
    # findCirclesGrid's centres are centroids of thresholded blobs; the plates' detector measures
    # the centroid of each blob's grey-level coverage instead (detect.find_blobs), which is the
    # centre of the circle's image ellipse without a threshold's bias: take it where it matches.
    blobs = find_blobs(img, dark=True)
    if blobs:
        buv = np.array([b.uv for b in blobs])
        d = np.linalg.norm(uv[:, None, :] - buv[None], axis=2)
        k = np.argmin(d, axis=1)
        near = d[np.arange(len(uv)), k] < 0.5
        uv[near] = buv[k[near]]
    return BoardDetection(np.arange(cols * rows), uv)


# ---- one camera: PnP -----------------------------------------------------------------------------


def solve_pnp(obj: Array, uv: Array, K: Array, D: Array) -> tuple[Array, float]:
    """``T_camera_board`` of points ``obj`` (N, 3) seen at ``uv`` (N, 2) (IPPE, then LM), and the RMS
    reprojection error [px]."""
    o = np.ascontiguousarray(obj, dtype=np.float64).reshape(-1, 1, 3)
    p = np.ascontiguousarray(uv, dtype=np.float64).reshape(-1, 1, 2)
    ok, rvec, tvec = cv2.solvePnP(o, p, K, D, flags=cv2.SOLVEPNP_IPPE)
    if not ok:
        raise ValueError("solvePnP failed")
    rvec, tvec = cv2.solvePnPRefineLM(o, p, K, D, rvec, tvec, criteria=_LM_CRITERIA)
    proj, _ = cv2.projectPoints(o, rvec, tvec, K, D)
    rms = float(np.sqrt(np.mean(np.sum((proj.reshape(-1, 2) - uv) ** 2, axis=1))))
    return homogeneous(cv2.Rodrigues(rvec)[0], tvec.ravel()), rms


def _grid_orderings(board: Board) -> list[NDArray[np.intp]]:
    """Permutations of a full grid's point order under its symmetries: identity, 180 deg, and the
    two mirrors (a mirrored order shows the camera the back of the board and is dropped)."""
    cols, rows = board.size
    g = np.arange(cols * rows).reshape(rows, cols)
    return [g.ravel(), g[::-1, ::-1].ravel(), g[:, ::-1].ravel(), g[::-1, :].ravel()]


def _texture_score(image: NDArray[np.uint8], board: Board, T: Array, K: Array, D: Array) -> float:
    """Correlation of the image with the board's printed black/white at the square centres (or
    circle centres and the gaps between them) predicted by pose ``T``: > 0 when the pose is right."""
    pts = board.object_points()[:, :2]
    s = board.point_spacing
    probes = np.concatenate(
        [
            pts + [0.5 * s, 0.5 * s],
            pts - [0.5 * s, 0.5 * s],
            pts + [0.5 * s, -0.5 * s],
            pts - [0.5 * s, -0.5 * s],
        ]
    )
    x0, x1, y0, y1 = board.outline
    probes = probes[
        (probes[:, 0] > x0) & (probes[:, 0] < x1) & (probes[:, 1] > y0) & (probes[:, 1] < y1)
    ]
    expected = board.reflectance(probes)
    rvec, _ = cv2.Rodrigues(T[:3, :3])
    uv, _ = cv2.projectPoints(
        np.concatenate([probes, np.zeros((len(probes), 1))], 1), rvec, T[:3, 3], K, D
    )
    uv = np.rint(uv.reshape(-1, 2)).astype(int)
    h, w = image.shape
    keep = (uv[:, 0] >= 1) & (uv[:, 0] < w - 1) & (uv[:, 1] >= 1) & (uv[:, 1] < h - 1)
    if keep.sum() < 2:
        return 0.0
    vals = np.array([image[v - 1 : v + 2, u - 1 : u + 2].mean() for u, v in uv[keep]])
    e = expected[keep] - expected[keep].mean()
    return float(np.sum((vals - vals.mean()) * e))


def board_pose(
    image: ArrayLike,
    K: ArrayLike,
    D: ArrayLike,
    board: Board,
    *,
    image_name: str = "image",
    max_rms_px: float = MAX_PNP_RMS_PX,
    allow_symmetric: bool = False,
) -> BoardPose | DetectionError:
    """``T_camera_board`` of a standard board in one image (module docstring).

    Args:
        image: Grey image, uint8, shape (h, w).
        K: Camera matrix [px], shape (3, 3).
        D: Distortion coefficients, shape (n,).
        board: The board.
        image_name: For messages.
        max_rms_px: Refuse a pose whose reprojection RMS exceeds this [px] (wrong intrinsics).
        allow_symmetric: Return one of the equally fitting poses of an ambiguous board (for
            tests that compare up to the board's symmetry) instead of refusing it.

    Returns:
        The pose, or the :class:`DetectionError` saying why not.
    """
    img = np.asarray(image, dtype=np.uint8)
    Km = np.asarray(K, dtype=float)
    Dm = np.asarray(D, dtype=float).ravel()
    if board.pose_ambiguity and not allow_symmetric:
        return PlateAmbiguousError(
            image_name,
            board.name,
            f"{board.pose_ambiguity}, so it gives no unique pose "
            "(use it for camera calibration; for poses use ChArUco or an asymmetric circle grid)",
        )
    found = detect_board(img, board, image_name=image_name)
    if isinstance(found, DetectionError):
        return found
    obj = board.object_points()
    orders = [np.arange(len(found.ids))] if board.kind == "charuco" else _grid_orderings(board)
    fits: list[tuple[Array, float, NDArray[np.intp]]] = []
    for order in orders:
        ids = found.ids[order]
        try:
            T, rms = solve_pnp(obj[ids], found.uv, Km, Dm)
        except (ValueError, cv2.error):
            continue
        faces = -T[:3, 3] @ T[:3, 2] > 0
        if faces and rms <= max_rms_px:
            fits.append((T, rms, ids))
    if not fits:
        return InconsistentDetectionError(
            image_name,
            board.name,
            f"no pose of the board reprojects its {len(found.ids)} "
            f"points within {max_rms_px} px RMS with the printed face towards the camera "
            "(wrong intrinsics, or wrong board file?)",
        )
    if len(fits) > 1:
        scores = [_texture_score(img, board, T, Km, Dm) for T, _, _ in fits]
        best = int(np.argmax(scores))
        if board.pose_ambiguity is None:
            others = [s for i, s in enumerate(scores) if i != best]
            if scores[best] <= 0 or max(others) > 0.5 * scores[best]:
                return PlateAmbiguousError(
                    image_name,
                    board.name,
                    f"{len(fits)} orientations of the board fit equally "
                    "(its black and white squares do not tell them apart)",
                )
        fits = [fits[best]]
    T, rms, ids = fits[0]
    uv = found.uv
    if board.kind in ("circles", "asymmetric_circles"):
        # A circle's image is an ellipse whose centre is not the projected centre (perspective):
        # predict the offset from this pose and solve again, as for the plates (plate_poses.py).
        uv = uv - _distorted_offset(Km, Dm, T, board)[ids]
        T, rms = solve_pnp(obj[ids], uv, Km, Dm)
    order = np.argsort(ids)
    return BoardPose(T, ids[order], uv[order], rms)


def _distorted_offset(K: Array, D: Array, T_camera_board: Array, board: Board) -> Array:
    """The ellipse-centre offset of every circle in *distorted* pixels, shape (N, 2): the ideal
    offset (:func:`~cpc2urdf.identification.vision.plate_poses.ellipse_centre_offset`) carried
    through the lens distortion (difference of the distorted ends; the first-order shortcut of
    the plates is off by up to the distortion's Jacobian, 10-20 % at k1 = -0.1)."""
    off = ellipse_centre_offset(K, T_camera_board, circle_design(board))
    p = board.object_points() @ T_camera_board[:3, :3].T + T_camera_board[:3, 3]
    centre = p[:, :2] / p[:, 2:3]
    shifted = centre + off / np.array(
        [K[0, 0], K[1, 1]]
    )  # ideal px -> normalised (K has no skew here)
    pts = np.concatenate([np.concatenate([centre, shifted]), np.ones((2 * len(p), 1))], axis=1)
    uv, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), K, D)
    uv = uv.reshape(-1, 2)
    return np.asarray(uv[len(p) :] - uv[: len(p)], dtype=float)


def circle_design(board: Board) -> PlateDesign:
    """A circle grid as a :class:`~cpc2urdf.identification.vision.targets.PlateDesign` (its circles
    in the board frame), for :func:`~cpc2urdf.identification.vision.plate_poses.ellipse_centre_offset`."""
    return PlateDesign(
        board.name,
        board.object_points(),
        np.full(board.n_points, board.circle_radius),
        board.outline,
    )


def pnp_pose_covariance(
    K: ArrayLike, D: ArrayLike, T_camera_board: ArrayLike, p_board: ArrayLike, sigma_px: float
) -> Array:
    """Covariance of a PnP pose from independent pixel noise ``sigma_px`` [px] per coordinate:
    ``sigma^2 (J^T J)^-1`` with ``J`` the Jacobian of the projections (central differences of
    ``cv2.projectPoints``) with respect to ``(rotation vector in the camera frame [rad],
    translation [m])``: ``R' = exp([w]) R``, ``t' = t + dt``. Shape (6, 6)."""
    Km, Dm = np.asarray(K, dtype=float), np.asarray(D, dtype=float).ravel()
    T = np.asarray(T_camera_board, dtype=float)
    obj = np.ascontiguousarray(np.asarray(p_board, dtype=float).reshape(-1, 3))

    def proj(x: Array) -> Array:
        R = cv2.Rodrigues(x[:3])[0] @ T[:3, :3]
        uv, _ = cv2.projectPoints(obj, cv2.Rodrigues(R)[0], T[:3, 3] + x[3:], Km, Dm)
        return np.asarray(uv, dtype=float).ravel()

    h = 1e-7
    J = np.stack([(proj(h * e) - proj(-h * e)) / (2 * h) for e in np.eye(6)], axis=1)
    return float(sigma_px) ** 2 * np.linalg.inv(J.T @ J)


# ---- stereo rig: triangulation + registration -----------------------------------------------------


def common_points(a: BoardPose, b: BoardPose) -> tuple[NDArray[np.intp], Array, Array]:
    """The point ids two views of one board share (sorted) and their pixels in ``a`` and in ``b``,
    shapes (N,), (N, 2), (N, 2)."""
    both = np.intersect1d(a.ids, b.ids)
    return both, a.uv[np.searchsorted(a.ids, both)], b.uv[np.searchsorted(b.ids, both)]


def stereo_board_pose(
    image_left: ArrayLike,
    image_right: ArrayLike,
    rig: StereoRig,
    board: Board,
    *,
    names: tuple[str, str] = ("left", "right"),
    max_epipolar_px: float = MAX_EPIPOLAR_PX,
    max_fit_rms: float = MAX_FIT_RMS,
) -> StereoPlatePose | DetectionError:
    """``T_world_board`` of a board seen by a stereo rig (world = left camera): each image's pose
    fixes the point ids (:func:`board_pose`), the points both see are triangulated and the board's
    points registered to them (Arun). Checks as
    :func:`~cpc2urdf.identification.vision.plate_poses.stereo_plate_poses` (epipolar RMS, fit RMS,
    printed face towards the rig)."""
    a = board_pose(image_left, rig.K1, rig.D1, board, image_name=names[0])
    if isinstance(a, DetectionError):
        return a
    b = board_pose(image_right, rig.K2, rig.D2, board, image_name=names[1])
    if isinstance(b, DetectionError):
        return b
    both, uv_l, uv_r = common_points(a, b)
    where = f"{names[0]} + {names[1]}"
    if len(both) < MIN_BOARD_POINTS:
        return PlateNotFoundError(
            where,
            board.name,
            f"too few corners seen by both cameras ({len(both)} < {MIN_BOARD_POINTS})",
        )
    p = rig.triangulate(uv_l, uv_r)
    obj = board.object_points()[both]
    try:
        T = plate_pose_from_points(obj, p, what=board.name)
    except Cpc2UrdfError as e:
        return InconsistentDetectionError(where, board.name, str(e))
    rms = float(registration_rms(T, obj, p))
    pl, pr = rig.project(p)
    epi = float(
        np.sqrt(np.mean(np.concatenate([np.sum((pl - uv_l) ** 2, 1), np.sum((pr - uv_r) ** 2, 1)])))
    )
    if epi > max_epipolar_px:
        return InconsistentDetectionError(
            where,
            board.name,
            f"left and right corners disagree by {epi:.2f} px RMS after "
            f"triangulation (> {max_epipolar_px} px): wrong rig file, or left/right images swapped?",
        )
    if rms > max_fit_rms:
        return InconsistentDetectionError(
            where,
            board.name,
            f"the board fits the triangulated corners with {rms * 1e3:.2f} mm "
            f"RMS (> {max_fit_rms * 1e3:.2f} mm): wrong rig file (baseline, units) or board size?",
        )
    return StereoPlatePose(board.name, T, p, uv_l, uv_r, rms, epi, 0.0)


__all__ = [
    "MIN_BOARD_POINTS",
    "BoardDetection",
    "BoardPose",
    "board_pose",
    "circle_design",
    "common_points",
    "detect_board",
    "pnp_pose_covariance",
    "solve_pnp",
    "stereo_board_pose",
]
