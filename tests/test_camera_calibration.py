"""``cpc2urdf calibrate camera|rig``: calibrateCamera / stereoCalibrate on rendered board images
recover the simulated intrinsics and rig within what the pixel noise predicts; the files they
write are the ones ``measure`` reads; bad input is one line, exit 2, nothing written."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from cpc2urdf.cli import main
from cpc2urdf.identification.handeye.stage2 import CameraIntrinsics
from cpc2urdf.identification.simulation.image_experiment import render_board_calibration
from cpc2urdf.identification.vision.boards.board_file import board_from_json, save_board
from cpc2urdf.identification.vision.boards.board_poses import detect_board
from cpc2urdf.identification.vision.render import PinholeView
from cpc2urdf.identification.vision.rig_file import load_camera, load_rig, save_rig
from cpc2urdf.identification.vision.stereo import StereoRig
from cpc2urdf.transforms import inverse

CHARUCO = {
    "format": "cpc2urdf/board@1",
    "kind": "charuco",
    "squares": [7, 5],
    "square_size": 30,
    "marker_size": 22,
    "dictionary": "DICT_5X5_100",
    "units": "mm",
}
CAMERA = CameraIntrinsics(fx=500.0, fy=500.0, cx=319.5, cy=239.5, dist=(-0.1, 0.05, 0.0, 0.0, 0.0))
RIG = StereoRig.verged(
    baseline=0.3,
    distance=1.0,
    focal_px=800.0,
    image_size=(640, 512),
    distortion=(-0.05, 0.02, 0, 0, 0),
)
RIG_BOARD = {**CHARUCO, "square_size": 45, "marker_size": 33}


@pytest.fixture(scope="module")
def camera_views(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, np.ndarray]:
    root = tmp_path_factory.mktemp("cam")
    board = save_board(board_from_json(CHARUCO, "charuco.json"), root / "board.json")
    T = render_board_calibration(
        root / "views", board_from_json(CHARUCO, "charuco.json"), camera=CAMERA, n_views=8, seed=0
    )
    return root / "views", board, T


@pytest.fixture(scope="module")
def rig_views(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, np.ndarray]:
    root = tmp_path_factory.mktemp("rig")
    b = board_from_json(RIG_BOARD, "charuco45.json")
    board = save_board(b, root / "board.json")
    T = render_board_calibration(root / "views", b, rig=RIG, n_views=7, seed=1, distance=(0.8, 1.2))
    return root / "views", board, T


def _corner_sigma(
    folder: Path, board_file: Path, view: PinholeView, T_world_board: np.ndarray
) -> float:
    """RMS error per coordinate of the detected corners vs their true projections [px]."""
    from cpc2urdf.identification.vision.boards.board_file import load_board

    b = load_board(board_file)
    res = []
    for i, T in enumerate(T_world_board):
        img = cv2.imread(str(folder / f"{i:04d}.png"), cv2.IMREAD_GRAYSCALE)
        d = detect_board(img, b)
        assert not isinstance(d, Exception), d
        p = b.object_points()[d.ids]
        res.append(d.uv - view.project(p @ T[:3, :3].T + T[:3, 3]))
    return float(np.sqrt(np.mean(np.concatenate(res) ** 2)))


def test_calibrate_camera_recovers_the_intrinsics(
    camera_views: tuple[Path, Path, np.ndarray], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder, board, _ = camera_views
    out = tmp_path / "camera.yaml"
    assert main(["calibrate", "camera", str(folder), "--board", str(board), "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "0000.png:" in printed and "views, RMS" in printed  # every view's error is reported
    K, D, size = load_camera(out)
    assert size == (640, 480)
    # OpenCV's standard deviations from the residuals: the errors are within 3 of them
    from cpc2urdf.identification.vision.boards.board_file import load_board
    from cpc2urdf.identification.vision.camera_calibration import calibrate_camera_images

    cal = calibrate_camera_images(folder, load_board(board))
    err = np.array(
        [
            K[0, 0] - CAMERA.fx,
            K[1, 1] - CAMERA.fy,
            K[0, 2] - CAMERA.cx,
            K[1, 2] - CAMERA.cy,
            D[0] - CAMERA.dist[0],
            D[1] - CAMERA.dist[1],
            D[2],
            D[3],
        ]
    )
    assert np.all(np.abs(err) < 3.0 * cal.std_intrinsics[:8]), (err, cal.std_intrinsics[:8])
    assert cal.rms < 0.1 and not cal.outliers


def _mc_rig_spread(
    T_world_board: np.ndarray, board_file: Path, sigma: float, draws: int = 12
) -> tuple[float, float]:
    """Monte Carlo on exact corners: std of the baseline error [m] and of the rotation error [rad]
    of the same calibration pipeline with Gaussian pixel noise ``sigma`` on the true projections."""
    from cpc2urdf.identification.vision.boards.board_file import load_board

    b = load_board(board_file)
    P = b.object_points()
    views = [
        PinholeView(K, Dd, RIG.image_size, inverse(RIG.T_world_camera(w)))
        for w, K, Dd in (("left", RIG.K1, RIG.D1), ("right", RIG.K2, RIG.D2))
    ]
    rng = np.random.default_rng(7)
    dt, dr = [], []
    for _ in range(draws):
        obj, pts = [], [[], []]
        for T in T_world_board:
            pw = P @ T[:3, :3].T + T[:3, 3]
            obj.append(P.astype(np.float32).reshape(-1, 1, 3))
            for k, v in enumerate(views):
                pts[k].append(
                    (v.project(pw) + rng.normal(0, sigma, (len(P), 2)))
                    .astype(np.float32)
                    .reshape(-1, 1, 2)
                )
        mono = [
            cv2.calibrateCamera(
                obj, p, RIG.image_size, np.eye(3), np.zeros(5), flags=cv2.CALIB_FIX_K3
            )[1:3]
            for p in pts
        ]
        r = cv2.stereoCalibrate(
            obj,
            pts[0],
            pts[1],
            mono[0][0],
            mono[0][1],
            mono[1][0],
            mono[1][1],
            RIG.image_size,
            flags=cv2.CALIB_USE_INTRINSIC_GUESS | cv2.CALIB_FIX_K3,
        )
        dt.append(np.asarray(r[6]).ravel() - RIG.T)
        dr.append(Rotation.from_matrix(np.asarray(r[5]) @ RIG.R.T).as_rotvec())
    return float(np.sqrt(np.mean(np.square(dt)))), float(np.sqrt(np.mean(np.square(dr))))


def test_calibrate_rig_recovers_the_rig_and_round_trips(
    rig_views: tuple[Path, Path, np.ndarray], tmp_path: Path
) -> None:
    folder, board, T = rig_views
    out = tmp_path / "rig.yaml"
    assert main(["calibrate", "rig", str(folder), "--board", str(board), "-o", str(out)]) == 0
    rig = load_rig(out)  # the reader measure uses
    assert rig.image_size == RIG.image_size
    sigma = _corner_sigma(
        folder / "left", board, PinholeView(RIG.K1, RIG.D1, RIG.image_size, np.eye(4)), T
    )
    sd_t, sd_r = _mc_rig_spread(T, board, sigma)
    err_t = np.abs(rig.T - RIG.T)
    err_r = np.abs(Rotation.from_matrix(rig.R @ RIG.R.T).as_rotvec())
    # within 4 standard deviations of the Monte Carlo on exact corners with the detector's noise
    assert err_t.max() < 4 * sd_t and err_r.max() < 4 * sd_r, (sigma, err_t, sd_t, err_r, sd_r)
    np.testing.assert_allclose(rig.K1, RIG.K1, atol=3.0)
    # round trip of the written rig through save_rig/load_rig (units, extra keys ignored by the reader)
    again = load_rig(save_rig(rig, tmp_path / "again.yaml", units="cm", extra=[("rms", 0.1)]))
    for a, b in ((again.K1, rig.K1), (again.D2, rig.D2), (again.R, rig.R), (again.T, rig.T)):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-14)


def _no_output(out: Path, capsys: pytest.CaptureFixture[str]) -> str:
    err = capsys.readouterr().err.strip()
    assert not out.exists() and "\n" not in err and "Traceback" not in err, err
    return err


def test_bad_input_one_line_exit_2_nothing_written(
    camera_views: tuple[Path, Path, np.ndarray], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder, board, _ = camera_views
    out = tmp_path / "camera.yaml"
    bad = tmp_path / "bad"
    bad.mkdir()
    for f in sorted(folder.glob("*.png"))[:4]:
        (bad / f.name).write_bytes(f.read_bytes())
    # a view without the board: named
    cv2.imwrite(str(bad / "0009.png"), np.full((480, 640), 90, np.uint8))
    assert main(["calibrate", "camera", str(bad), "--board", str(board), "-o", str(out)]) == 2
    assert "0009.png: charuco.json: board not found" in _no_output(out, capsys)
    # ... skipped with --on-error skip, and listed
    assert (
        main(
            [
                "calibrate",
                "camera",
                str(bad),
                "--board",
                str(board),
                "-o",
                str(out),
                "--on-error",
                "skip",
            ]
        )
        == 0
    )
    assert "skipped:" in capsys.readouterr().err
    out.unlink()
    # images of different sizes
    cv2.imwrite(str(bad / "0009.png"), np.full((240, 320), 90, np.uint8))
    assert main(["calibrate", "camera", str(bad), "--board", str(board), "-o", str(out)]) == 2
    assert "0009.png: image is 320 x 240 px, the first image is 640 x 480 px" in _no_output(
        out, capsys
    )
    # a board file with a wrong field
    wrong = tmp_path / "wrong.json"
    wrong.write_text(json.dumps({**CHARUCO, "marker_size": 40}))
    assert main(["calibrate", "camera", str(folder), "--board", str(wrong), "-o", str(out)]) == 2
    assert "wrong.json: marker_size must be smaller than square_size" in _no_output(out, capsys)
    # too few views
    few = tmp_path / "few"
    few.mkdir()
    for f in sorted(folder.glob("*.png"))[:2]:
        (few / f.name).write_bytes(f.read_bytes())
    assert main(["calibrate", "camera", str(few), "--board", str(board), "-o", str(out)]) == 2
    assert "the board was found in 2 views; camera calibration needs at least 3" in _no_output(
        out, capsys
    )
    # a symmetric circle grid cannot match the two cameras' points
    sym = tmp_path / "sym.json"
    sym.write_text(
        json.dumps(
            {
                "format": "cpc2urdf/board@1",
                "kind": "circles",
                "pattern_size": [7, 5],
                "spacing": 0.025,
                "circle_radius": 0.007,
            }
        )
    )
    assert main(["calibrate", "rig", str(folder), "--board", str(sym), "-o", str(out)]) == 2
    assert "looks the same rotated by 180 deg" in _no_output(out, capsys)
    # a rig folder with a view in only one camera
    rig_dir = tmp_path / "rigdir"
    (rig_dir / "left").mkdir(parents=True)
    (rig_dir / "right").mkdir()
    cv2.imwrite(str(rig_dir / "left" / "a.png"), np.zeros((48, 64), np.uint8))
    assert main(["calibrate", "rig", str(rig_dir), "--board", str(board), "-o", str(out)]) == 2
    assert "no images in the folder" in _no_output(out, capsys)
    cv2.imwrite(str(rig_dir / "right" / "b.png"), np.zeros((48, 64), np.uint8))
    assert main(["calibrate", "rig", str(rig_dir), "--board", str(board), "-o", str(out)]) == 2
    assert "no right/ image of view 'a'" in _no_output(out, capsys)
