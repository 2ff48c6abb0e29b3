"""Standard boards: the board file, rendering, OpenCV detection and PnP poses vs the pixel noise.

Each board kind is rendered (blur 0.7 px, grey noise 2/255, lens distortion k1 = -0.1) at random
poses; the detected points are compared with their true projections, which gives the detector's
pixel noise ``sigma``, and the pose errors are compared with what ``sigma`` predicts through the
PnP Jacobian (:func:`pnp_pose_covariance`, itself checked against Monte Carlo on exact points).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

from cpc2urdf.errors import InputFileError
from cpc2urdf.identification.simulation.image_experiment import random_board_poses
from cpc2urdf.identification.vision.boards.board import Board
from cpc2urdf.identification.vision.boards.board_file import board_from_json, load_board, save_board
from cpc2urdf.identification.vision.boards.board_poses import (
    board_pose,
    detect_board,
    pnp_pose_covariance,
    solve_pnp,
)
from cpc2urdf.identification.vision.detect import PlateAmbiguousError, PlateNotFoundError
from cpc2urdf.identification.vision.render import PinholeView, render_board_view
from cpc2urdf.transforms import homogeneous

K = np.array([[500.0, 0.0, 319.5], [0.0, 500.0, 239.5], [0.0, 0.0, 1.0]])
D = np.array([-0.1, 0.05, 0.0, 0.0, 0.0])
VIEW = PinholeView(K, D, (640, 480), np.eye(4))

BOARDS: dict[str, dict[str, Any]] = {
    "chessboard": {"kind": "chessboard", "pattern_size": [9, 6], "square_size": 20},
    "charuco": {
        "kind": "charuco",
        "squares": [7, 5],
        "square_size": 30,
        "marker_size": 22,
        "dictionary": "DICT_5X5_100",
    },
    "asymmetric_circles": {
        "kind": "asymmetric_circles",
        "pattern_size": [4, 11],
        "spacing": 15,
        "circle_radius": 5,
    },
    "circles": {"kind": "circles", "pattern_size": [7, 5], "spacing": 25, "circle_radius": 7},
}


def board(kind: str, **extra: Any) -> Board:
    return board_from_json(
        {"format": "cpc2urdf/board@1", "units": "mm", **BOARDS[kind], **extra}, f"{kind}.json"
    )


def _rotvec_error(T_est: np.ndarray, T_true: np.ndarray) -> np.ndarray:
    return np.asarray(Rotation.from_matrix(T_est[:3, :3] @ T_true[:3, :3].T).as_rotvec())


# ---- the board file -------------------------------------------------------------------------------


@pytest.mark.parametrize("kind", list(BOARDS))
def test_board_file_round_trip(kind: str, tmp_path: Path) -> None:
    b = board(kind)
    path = save_board(b, tmp_path / "b.json")
    again = load_board(path)
    assert again.kind == b.kind and again.size == b.size
    np.testing.assert_allclose(again.object_points(), b.object_points(), atol=1e-12)
    assert again.outline == pytest.approx(b.outline, abs=1e-12)


@pytest.mark.parametrize(
    ("kind", "change", "message"),
    [
        ("chessboard", {"kind": "checkers"}, "kind must be one of chessboard, charuco"),
        ("chessboard", {"square_size": -3}, "square_size must be a positive length"),
        ("chessboard", {"pattern_size": [9]}, "pattern_size must be [cols, rows]"),
        ("chessboard", {"squares": [9, 6]}, "unknown key 'squares' for a chessboard board"),
        ("chessboard", {"units": "inch"}, "units must be one of"),
        (
            "charuco",
            {"marker_size": 35},
            "marker_size must be smaller than square_size (30 mm), got 35",
        ),
        (
            "charuco",
            {"dictionary": "DICT_9X9_1"},
            "dictionary must be an OpenCV ArUco dictionary name",
        ),
        (
            "charuco",
            {"first_marker_id": 90},
            "marker ids 90..106 but DICT_5X5_100 has only 100 markers",
        ),
        ("circles", {"circle_radius": 12}, "circle_radius must be below 0.4 x the distance"),
        ("asymmetric_circles", {"spacing": "15"}, "spacing must be a positive length"),
    ],
)
def test_board_file_bad_field_is_one_line(
    kind: str, change: dict[str, Any], message: str, tmp_path: Path
) -> None:
    doc = {"format": "cpc2urdf/board@1", "units": "mm", **BOARDS[kind], **change}
    path = tmp_path / "board.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(InputFileError) as e:
        load_board(path)
    assert message in str(e.value) and str(path) in str(e.value) and "\n" not in str(e.value)


def test_board_file_missing_key_and_wrong_format(tmp_path: Path) -> None:
    path = tmp_path / "board.json"
    path.write_text(
        json.dumps(
            {
                "format": "cpc2urdf/board@1",
                "kind": "charuco",
                "squares": [5, 5],
                "square_size": 0.03,
            }
        )
    )
    with pytest.raises(InputFileError, match="missing key 'marker_size'"):
        load_board(path)
    path.write_text(json.dumps({"format": "cpc2urdf/plate@1", "kind": "chessboard"}))
    with pytest.raises(InputFileError, match="format is 'cpc2urdf/plate@1'"):
        load_board(path)


def test_board_frame_follows_opencv_points() -> None:
    """Our board frame is OpenCV's with y and z flipped, origin at the pattern centre: the
    ChArUco corners are cv2.aruco's own (float32), in its order."""
    b = board("charuco")
    cv = np.asarray(b.charuco_board().getChessboardCorners()).reshape(-1, 3)
    ours = b.object_points()
    np.testing.assert_allclose(ours[:, 0] - ours[0, 0], cv[:, 0] - cv[0, 0], atol=1e-7)
    np.testing.assert_allclose(ours[:, 1] - ours[0, 1], -(cv[:, 1] - cv[0, 1]), atol=1e-7)
    np.testing.assert_allclose(ours.mean(axis=0)[:2], 0.0, atol=1e-12)
    asym = board("asymmetric_circles").object_points()
    assert np.linalg.norm(asym[1] - asym[0]) == pytest.approx(
        0.030
    )  # (2 j + i % 2) spacing along a row


# ---- poses from rendered images vs the pixel noise -------------------------------------------------


def test_pnp_covariance_matches_monte_carlo() -> None:
    """The Jacobian prediction agrees with solvePnP on exact corners + Gaussian noise (400 draws)."""
    b = board("chessboard")
    T = random_board_poses([VIEW], b, 1, np.random.default_rng(3), distance=(0.45, 0.45))[0]
    uv = VIEW.project(b.object_points() @ T[:3, :3].T + T[:3, 3])
    rng = np.random.default_rng(0)
    errs = []
    for _ in range(400):
        Te, _ = solve_pnp(b.object_points(), uv + rng.normal(0.0, 0.1, uv.shape), K, D)
        errs.append(np.concatenate([_rotvec_error(Te, T), Te[:3, 3] - T[:3, 3]]))
    mc = np.cov(np.array(errs).T)
    pred = pnp_pose_covariance(K, D, T, b.object_points(), 0.1)
    np.testing.assert_allclose(np.sqrt(np.diag(mc)), np.sqrt(np.diag(pred)), rtol=0.12)


@pytest.mark.parametrize("kind", list(BOARDS))
def test_rendered_board_poses_within_the_pixel_noise(kind: str) -> None:
    b = board(kind)
    rng = np.random.default_rng(1)
    poses = random_board_poses([VIEW], b, 4, rng, distance=(0.35, 0.55))
    residuals, errors = [], []
    for T in poses:
        img = render_board_view(VIEW, [(b, T)], blur_sigma=0.7, noise_sigma=2.0, rng=rng)
        r = board_pose(img, K, D, b, allow_symmetric=True)
        assert not isinstance(r, Exception), r
        Te = r.T_camera_board
        if b.pose_ambiguity:  # a symmetric grid: compare with the nearer of the two equal fits
            flipped = Te @ np.diag([-1.0, -1.0, 1.0, 1.0])
            if np.linalg.norm(_rotvec_error(flipped, T)) < np.linalg.norm(_rotvec_error(Te, T)):
                Te = flipped
        truth = VIEW.project(b.object_points() @ T[:3, :3].T + T[:3, 3])
        uv = (
            r.uv
            if not b.pose_ambiguity
            else r.uv[np.argmin(((r.uv[:, None] - truth[None]) ** 2).sum(-1), axis=0)]
        )
        residuals.append(uv - truth[r.ids] if not b.pose_ambiguity else uv - truth)
        errors.append((T, np.concatenate([_rotvec_error(Te, T), Te[:3, 3] - T[:3, 3]]), r.ids))
    res = np.concatenate(residuals)
    sigma = float(np.sqrt(np.mean(res**2)))
    assert sigma < 0.05, sigma  # the detectors' sub-pixel noise on these images [px]
    assert (
        np.abs(res.mean(axis=0)).max() < 0.005
    )  # [px] mean error vector: no systematic offset left
    # Mahalanobis distance of each 6-D pose error under the predicted covariance: mean 6 when the
    # pose is as good as the pixel noise allows (chi-square, 6 dof per view).
    m = [
        e @ np.linalg.solve(pnp_pose_covariance(K, D, T, b.object_points()[ids], sigma), e)
        for T, e, ids in errors
    ]
    # Under the prediction, sum(m) is chi-square with 6 x 4 = 24 dof: mean(m) / 6 < its 99.9 % quantile
    # / 24 = 2.13. Circle grids: their ~0.009 px centre errors are spatially correlated (PnP does not
    # average them out as for independent noise), so their poses' variance is the prediction's times
    # the factor measured over 16 views in docs/images.md (Mahalanobis / 6: 1.49 asymmetric, 3.79
    # symmetric); the same chi-square margin on top: 3.18 and 8.08 (these 4 views: 2.28 and 5.98).
    inflation = {"chessboard": 1.0, "charuco": 1.0, "asymmetric_circles": 1.49, "circles": 3.79}[
        kind
    ]
    dof = 6 * len(errors)
    bound = inflation * chi2.ppf(0.999, dof) / dof
    assert np.mean(m) / 6 < bound, (kind, sigma, np.array(m) / 6)


def test_chessboard_rolled_half_a_turn_gives_the_right_pose() -> None:
    """The corner grid looks the same rolled by 180 deg; the squares' colours decide."""
    b = board("chessboard")
    T0 = homogeneous(np.diag([1.0, -1.0, -1.0]), [0.01, 0.0, 0.45])
    for roll in (0.0, 180.0, 90.0, -90.0):
        T = T0 @ homogeneous(Rotation.from_euler("z", roll, degrees=True).as_matrix(), np.zeros(3))
        r = board_pose(render_board_view(VIEW, [(b, T)], blur_sigma=0.7), K, D, b)
        assert not isinstance(r, Exception), r
        # a wrong orientation is off by 90 or 180 deg; face-on views (no noise, every corner at the
        # same sub-pixel phase) are accurate to ~0.2 deg only, the phase error being common-mode
        assert np.degrees(np.linalg.norm(_rotvec_error(r.T_camera_board, T))) < 1.0


def test_ambiguous_missing_and_partial_boards() -> None:
    blank = np.full((480, 640), 60, np.uint8)
    for kind in BOARDS:
        r = detect_board(blank, board(kind), image_name="blank.png")
        assert isinstance(r, PlateNotFoundError) and str(r).startswith(
            f"blank.png: {kind}.json: board not found"
        )
    sym = board("circles")
    T = homogeneous(np.diag([1.0, -1.0, -1.0]), [0.0, 0.0, 0.5])
    r = board_pose(render_board_view(VIEW, [(sym, T)]), K, D, sym, image_name="sym.png")
    assert isinstance(r, PlateAmbiguousError) and "looks the same rotated by 180 deg" in str(r)
    # a ChArUco board mostly outside the image: too few corners, named
    ch = board("charuco")
    T = homogeneous(np.diag([1.0, -1.0, -1.0]), [0.30, 0.0, 0.4])
    r = detect_board(render_board_view(VIEW, [(ch, T)], blur_sigma=0.7), ch, image_name="edge.png")
    assert isinstance(r, PlateNotFoundError) and "too few ChArUco corners" in str(r), r
    # a ChArUco board with other marker ids is not this board
    other = board("charuco", first_marker_id=40)
    T = homogeneous(np.diag([1.0, -1.0, -1.0]), [0.0, 0.0, 0.45])
    r = detect_board(
        render_board_view(VIEW, [(ch, T)], blur_sigma=0.7), other, image_name="ids.png"
    )
    assert isinstance(r, PlateNotFoundError) and "ids 40..56" in str(r), r


def test_rendered_chessboard_is_its_area_coverage() -> None:
    """Face-on, no distortion, squares aligned with the pixels: each pixel's grey level is the
    exact area of black and white it covers (products of 1-D overlaps). The edges are put on the
    16 x 16 sub-sample grid's boundaries (at 1/16 px steps), where sub-sampling is exact, so only
    the 8-bit rounding remains (an edge between sub-samples would be off by up to 1/32 px)."""
    from cpc2urdf.identification.vision.boards.board import BLACK_LEVEL, WHITE_LEVEL

    b = board("chessboard")
    f, z = 500.0, 0.5
    Kf = np.array([[f, 0.0, 319.5], [0.0, f, 239.5], [0.0, 0.0, 1.0]])
    view = PinholeView(Kf, np.zeros(5), (640, 480), np.eye(4))
    x0, x1, y0, y1 = b.outline
    # square edges at u = 220.8125 + 20 k px, v = 167.4375 + 20 k px: cutting pixels, on the sub-sample grid
    T = homogeneous(
        np.diag([1.0, -1.0, -1.0]),
        [
            (220.8125 - 319.5) * z / f - (x0 + b.margin),
            (167.4375 - 239.5) * z / f + (y1 - b.margin),
            z,
        ],
    )
    img = render_board_view(view, [(b, T)], supersample=16).astype(float)
    # the black squares in image coordinates: square (a, b) of OpenCV's grid, X right, Y down
    s = b.square_size * f / z
    cx = 319.5 + (T[0, 3] + x0 + b.margin) * f / z  # left edge of the squares, px
    cy = 239.5 + (T[1, 3] - (y1 - b.margin)) * f / z  # top edge (camera y = t_y - board y)
    cols, rows = b.size
    u = np.arange(640)[None, :]
    v = np.arange(480)[:, None]
    black = np.zeros((480, 640))
    for a in range(cols + 1):
        for c in range(rows + 1):
            if (a + c) % 2:
                continue
            ox = np.clip(
                np.minimum(u + 0.5, cx + (a + 1) * s) - np.maximum(u - 0.5, cx + a * s), 0, None
            )
            oy = np.clip(
                np.minimum(v + 0.5, cy + (c + 1) * s) - np.maximum(v - 0.5, cy + c * s), 0, None
            )
            black += ox * oy
    ex0, ex1 = 319.5 + (T[0, 3] + x0) * f / z, 319.5 + (T[0, 3] + x1) * f / z
    ey0, ey1 = 239.5 + (T[1, 3] - y1) * f / z, 239.5 + (T[1, 3] - y0) * f / z
    inner = (
        (u > ex0 + 1) & (u < ex1 - 1) & (v > ey0 + 1) & (v < ey1 - 1)
    )  # away from the board's outline
    expected = 255 * (WHITE_LEVEL + (BLACK_LEVEL - WHITE_LEVEL) * black)
    err = np.abs(img - expected)[np.broadcast_to(inner, img.shape)]
    assert err.max() < 0.5 + 1e-6, err.max()  # 8-bit rounding only
