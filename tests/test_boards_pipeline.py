"""Standard boards in both stages, from rendered images through ``cpc2urdf measure --board``.

Stage 2: ChArUco board as the head cameras' target -> hand-eye pose files -> camera frames,
compared with the same calibration from the exact poses disturbed by the detector's own pixel
noise. Stage 1: two ChArUco boards (disjoint marker ids) as the head's plates, measured by the
stereo rig (triangulated corners + registration). Bad input: one line, exit 2, nothing written.
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy.stats import chi2

from cpc2urdf.cli import main
from cpc2urdf.files.measurements import load_measurements
from cpc2urdf.files.model_file import save_model
from cpc2urdf.identification.handeye.pose_file import load_handeye_poses
from cpc2urdf.identification.handeye.stage2 import (
    DEFAULT_INTRINSICS,
    Stage2Observations,
    calibrate_cameras,
    camera_errors,
)
from cpc2urdf.identification.simulation.image_experiment import (
    render_board_experiment,
    render_head_board_experiment,
)
from cpc2urdf.identification.simulation.stage1_experiment import simulate_experiment
from cpc2urdf.identification.vision.boards.board_file import board_from_json, save_board
from cpc2urdf.identification.vision.boards.board_poses import board_pose, detect_board, solve_pnp
from cpc2urdf.identification.vision.joints_csv import read_joints_csv
from cpc2urdf.model import CPCModel
from cpc2urdf.transforms import inverse, rotation_error

# "As accurate as from exact poses with the same noise": the image result is not worse than this
# quantile of the reference (exact poses + the detector's measured pixel noise, the same pipeline)
# over this many draws; were both the same distribution, it would be above it in 10 % of seeds.
REFERENCE_DRAWS = 20
REFERENCE_QUANTILE = 0.9
CAMERAS = ("camera_left_optical", "camera_right_optical")
TARGET = {
    "format": "cpc2urdf/board@1",
    "kind": "charuco",
    "squares": [7, 5],
    "square_size": 30,
    "marker_size": 22,
    "dictionary": "DICT_5X5_100",
    "units": "mm",
}

pytestmark = pytest.mark.slow  # long end-to-end runs; CI runs them


def plate_board(first: int) -> dict[str, object]:
    """A 160 mm ChArUco plate: 4 x 4 squares of 40 mm, 4x4-bit markers ~5 px per bit at 1.5 m."""
    return {
        "format": "cpc2urdf/board@1",
        "kind": "charuco",
        "squares": [4, 4],
        "square_size": 40,
        "marker_size": 30,
        "dictionary": "DICT_4X4_50",
        "first_marker_id": first,
        "margin": 10,
        "units": "mm",
    }


@pytest.fixture(scope="module")
def truth() -> CPCModel:
    return simulate_experiment("iis_head", seed=0, M=2, noise="none", n_heldout=1)[0]


@pytest.fixture(scope="module")
def head(truth: CPCModel, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, Path]:
    root = tmp_path_factory.mktemp("head_board")
    board = save_board(board_from_json(TARGET, "charuco.json"), root / "charuco.json")
    render_head_board_experiment(
        root / "head", truth, board_from_json(TARGET, "charuco.json"), n_poses=6, seed=3
    )
    return root / "head", board, save_model(truth, root / "truth.json")


def _true_C(truth: CPCModel, head: Path, cam: str, q: np.ndarray) -> np.ndarray:
    T_base_target = np.array(json.loads((head / "target_truth.json").read_text())["T_base_target"])
    T_base_cam = inverse(truth.T_world_base())[None] @ truth.fk_frame(cam, q)
    return np.asarray(inverse(T_base_cam) @ T_base_target)


def _detector_sigma(truth: CPCModel, folder: Path, board_file: Path, q: np.ndarray) -> float:
    """The detector's pixel noise on the stage-2 images: RMS per coordinate of the detected
    corners vs their true projections [px]."""
    from cpc2urdf.identification.vision.boards.board_file import load_board

    board = load_board(board_file)
    intr = DEFAULT_INTRINSICS
    res = []
    for cam in CAMERAS:
        for i, C in enumerate(_true_C(truth, folder, cam, q)):
            d = detect_board(
                cv2.imread(str(folder / cam / f"{i:04d}.png"), cv2.IMREAD_GRAYSCALE), board
            )
            assert not isinstance(d, Exception), d
            uv, _ = cv2.projectPoints(
                board.object_points()[d.ids], cv2.Rodrigues(C[:3, :3])[0], C[:3, 3], intr.K, intr.D
            )
            res.append(d.uv - uv.reshape(-1, 2))
    return float(np.sqrt(np.mean(np.concatenate(res) ** 2)))


def test_stage2_board_images_to_handeye_files(
    truth: CPCModel, head: tuple[Path, Path, Path], tmp_path: Path
) -> None:
    """The target poses in the hand-eye files are within what the detector's pixel noise predicts
    through the PnP Jacobian (mean squared Mahalanobis distance per dof, chi-square)."""
    from scipy.spatial.transform import Rotation

    from cpc2urdf.identification.vision.boards.board_file import load_board
    from cpc2urdf.identification.vision.boards.board_poses import pnp_pose_covariance

    folder, board, model = head
    out = tmp_path / "poses"
    assert (
        main(
            [
                "measure",
                str(folder),
                "--stage2",
                "--board",
                str(board),
                "--model",
                str(model),
                "-o",
                str(out),
            ]
        )
        == 0
    )
    q = read_joints_csv(folder / "joints.csv", truth.structure).q
    sigma = _detector_sigma(truth, folder, board, q)
    P = load_board(board).object_points()
    m = []
    for cam in CAMERAS:
        poses = load_handeye_poses(out / f"handeye_{cam}.json")
        C = _true_C(truth, folder, cam, q)
        assert len(poses.T_camera_target) == 6
        for Te, Ct in zip(poses.T_camera_target, C, strict=True):
            e = np.concatenate(
                [Rotation.from_matrix(Te[:3, :3] @ Ct[:3, :3].T).as_rotvec(), Te[:3, 3] - Ct[:3, 3]]
            )
            cov = pnp_pose_covariance(DEFAULT_INTRINSICS.K, DEFAULT_INTRINSICS.D, Ct, P, sigma)
            m.append(e @ np.linalg.solve(cov, e) / 6)
    # sum(6 m) is chi2(6 x 12 = 72) under the prediction: mean(m) below its 99.9 % quantile / 72, 1.59
    # (measured 1.11)
    assert np.mean(m) < chi2.ppf(0.999, 6 * len(m)) / (6 * len(m)), (sigma, m)


def test_camera_frames_from_board_images_as_accurate_as_exact_poses_with_the_same_noise(
    truth: CPCModel, head: tuple[Path, Path, Path]
) -> None:
    from cpc2urdf.identification.handeye.head_images import stage2_observations
    from cpc2urdf.identification.vision.boards.board_file import load_board
    from cpc2urdf.identification.vision.measure_head import HeadCamera, measure_head_images
    from cpc2urdf.identification.vision.rig_file import load_camera

    folder, board_file, _ = head
    board = load_board(board_file)
    cams = {c: HeadCamera(*load_camera(folder / f"{c}.yaml")) for c in CAMERAS}
    obs = stage2_observations(measure_head_images(folder, cams, truth.structure, board=board), cams)
    model, _ = calibrate_cameras(truth.without_frames(["camera"]), obs, "tsai")
    from_images = camera_errors(model, truth, list(CAMERAS))
    sigma = _detector_sigma(truth, folder, board_file, obs.q)
    intr = DEFAULT_INTRINSICS
    P = board.object_points()
    # reference: the exact target poses' corners + Gaussian noise sigma, solvePnP, the same calibration
    ref = []
    for k in range(REFERENCE_DRAWS):
        rng = np.random.default_rng(100 + k)
        poses = {}
        for cam in CAMERAS:
            Ts = []
            for C in _true_C(truth, folder, cam, obs.q):
                uv, _ = cv2.projectPoints(P, cv2.Rodrigues(C[:3, :3])[0], C[:3, 3], intr.K, intr.D)
                Ts.append(
                    solve_pnp(
                        P, uv.reshape(-1, 2) + rng.normal(0.0, sigma, (len(P), 2)), intr.K, intr.D
                    )[0]
                )
            poses[cam] = np.array(Ts)
        obs_k = Stage2Observations(obs.q, poses, {}, intr, sigma, obs.T_base_target)
        ref.append(
            camera_errors(
                calibrate_cameras(truth.without_frames(["camera"]), obs_k, "tsai")[0],
                truth,
                list(CAMERAS),
            )
        )
    for cam in CAMERAS:  # measured: left 2.6 mm / 0.0063 rad above ~70 % of the draws, right 1.4 mm / 0.0026 above 10 %
        for i in (0, 1):  # position, rotation
            draws = [r[cam][i] for r in ref]
            assert from_images[cam][i] <= np.quantile(draws, REFERENCE_QUANTILE), (
                cam,
                i,
                from_images[cam],
                sorted(draws),
            )


@pytest.fixture(scope="module")
def stage1(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, Path]:
    root = tmp_path_factory.mktemp("stage1_boards")
    boards = {
        "plate_left": board_from_json(plate_board(0), "left.json"),
        "plate_right": board_from_json(plate_board(8), "right.json"),
    }
    files = [save_board(b, root / f"{f}.json") for f, b in boards.items()]
    render_board_experiment(root / "images", boards, M=2, n_heldout=20, seed=0, supersample=4)
    return root / "images", files[0], files[1]


def test_stage1_board_plates_through_the_stereo_rig(
    stage1: tuple[Path, Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder, left, right = stage1
    out = tmp_path / "m.json"
    assert (
        main(
            [
                "measure",
                str(folder),
                "--rig",
                str(folder / "rig.yaml"),
                "--board",
                f"plate_left={left}",
                "--board",
                f"plate_right={right}",
                "-o",
                str(out),
            ]
        )
        == 0
    )
    ms = load_measurements(out)
    exact = load_measurements(folder / "exact.json")
    assert ms.n_records == exact.n_records == 13
    # the detector's pixel noise: corners of the views measured vs the true projections, both cameras
    from cpc2urdf.identification.simulation.measurement_noise import stereo_noise
    from cpc2urdf.identification.vision.boards.board_file import load_board
    from cpc2urdf.identification.vision.rig_file import load_rig

    rig = load_rig(folder / "rig.yaml")
    boards = {"plate_left": load_board(left), "plate_right": load_board(right)}
    res = []
    for i in range(exact.n_records):
        for k, side in enumerate(("left", "right")):
            img = cv2.imread(str(folder / side / f"{i:04d}.png"), cv2.IMREAD_GRAYSCALE)
            for f, b in boards.items():
                d = board_pose(img, *((rig.K1, rig.D1) if k == 0 else (rig.K2, rig.D2)), b)
                if isinstance(
                    d, Exception
                ):  # refused (e.g. a view 60 deg off face-on): not in the file either
                    continue
                T = exact.poses[f][i]
                uv = rig.project(b.object_points()[d.ids] @ T[:3, :3].T + T[:3, 3])[k]
                res.append(d.uv - uv)
    sigma = float(np.sqrt(np.mean(np.concatenate(res) ** 2)))
    assert sigma < 0.1, sigma
    for f, b in boards.items():
        ok = ms.has_pose(f)
        # plate_left: 4 of 13 views refused (plate_right hides some of its corners, or too oblique)
        assert ok.sum() >= 9, (f, capsys.readouterr().err)
        # prediction: the same true poses through the rig with Gaussian pixel noise sigma (200 draws)
        Tm, _ = stereo_noise(
            np.repeat(exact.poses[f][ok], 200, axis=0),
            b.object_points(),
            rig,
            sigma,
            np.random.default_rng(0),
        )
        T_true = np.repeat(exact.poses[f][ok], 200, axis=0)
        pred_t = np.sqrt(np.mean(np.sum((Tm[:, :3, 3] - T_true[:, :3, 3]) ** 2, axis=1)))
        pred_r = np.sqrt(np.mean(rotation_error(Tm[:, :3, :3], T_true[:, :3, :3]) ** 2))
        d = np.linalg.norm(ms.poses[f][ok, :3, 3] - exact.poses[f][ok, :3, 3], axis=1)
        a = rotation_error(ms.poses[f][ok, :3, :3], exact.poses[f][ok, :3, :3])
        # within 3x the predicted RMS (a 3-D error beyond 3 sigma-RMS is rare: < 1 %)
        assert d.max() < 3 * pred_t and a.max() < 3 * pred_r, (
            f,
            sigma,
            d,
            pred_t,
            np.degrees(a),
            np.degrees(pred_r),
        )
    assert "plate_boards" in json.dumps(ms.metadata["provenance"])
    # identification (closed form) from the board images is as accurate as from the exact poses of
    # the same records and plates with the same pixel noise (REFERENCE_DRAWS draws; measured: 0.11 mm,
    # above 10 % (plate_left) and 5 % (plate_right) of the draws)
    from cpc2urdf.files.measurements import MeasurementSet
    from cpc2urdf.identification.kinematics.closed_form import identify_closed_form
    from cpc2urdf.validation.heldout import accuracy

    held = load_measurements(folder / "heldout.json")

    def score(m: MeasurementSet) -> dict[str, float]:
        return {f: a.rms for f, a in accuracy(identify_closed_form(m)[0], held).items()}

    from_images = score(ms)
    ref = []
    for k in range(REFERENCE_DRAWS):
        rk = np.random.default_rng(1000 + k)
        poses = {}
        for f, b in boards.items():
            P = stereo_noise(exact.poses[f], b.object_points(), rig, sigma, rk)[0]
            P[~ms.has_pose(f)] = np.nan
            poses[f] = P
        ref.append(score(MeasurementSet(exact.structure, exact.q, poses, labels=exact.labels)))
    for f in boards:
        draws = [r[f] for r in ref]
        assert from_images[f] <= np.quantile(draws, REFERENCE_QUANTILE), (
            f,
            from_images[f],
            sorted(draws),
        )


def test_board_bad_input_one_line_exit_2(
    stage1: tuple[Path, Path, Path],
    head: tuple[Path, Path, Path],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    folder, left, _ = stage1
    out = tmp_path / "m.json"

    def refused(argv: list[str], message: str) -> None:
        assert main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert message in err and "\n" not in err and not out.exists(), err

    base = ["measure", str(folder), "--rig", str(folder / "rig.yaml"), "-o", str(out)]
    # two plates with the same marker ids
    refused(
        [*base, "--board", f"plate_left={left}", "--board", f"plate_right={left}"],
        "share marker ids of DICT_4X4_50",
    )
    # chessboards cannot be told apart
    chess = tmp_path / "chess.json"
    chess.write_text(
        json.dumps(
            {
                "format": "cpc2urdf/board@1",
                "kind": "chessboard",
                "pattern_size": [5, 4],
                "square_size": 20,
                "units": "mm",
            }
        )
    )
    refused(
        [*base, "--board", f"plate_left={chess}", "--board", f"plate_right={chess}"],
        "ChArUco boards with disjoint marker ids",
    )
    refused([*base, "--board", str(left)], "say which one with --board FRAME=FILE")
    refused([*base, "--board", f"plate_middle={left}"], "has no frame 'plate_middle'")
    # the board is not in the images (wrong marker ids): named, with --on-error stop
    other = tmp_path / "other.json"
    other.write_text(json.dumps({**plate_board(30)}))
    refused(
        [*base, "--board", f"plate_left={other}", "--on-error", "stop"],
        "plate_left: board not found",
    )
    # stage 2: a symmetric circle grid gives no pose; a board file with a wrong field
    hfolder, _, model = head
    sym = tmp_path / "sym.json"
    sym.write_text(
        json.dumps(
            {
                "format": "cpc2urdf/board@1",
                "kind": "circles",
                "pattern_size": [7, 5],
                "spacing": 25,
                "circle_radius": 7,
                "units": "mm",
            }
        )
    )
    hout = tmp_path / "poses"
    argv = ["measure", str(hfolder), "--stage2", "--model", str(model), "-o", str(hout), "--board"]
    assert main([*argv, str(sym)]) == 2
    assert "looks the same rotated by 180 deg" in capsys.readouterr().err and not hout.exists()
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({**TARGET, "dictionary": "DICT_5X5_10"}))
    assert main([*argv, str(bad)]) == 2
    assert (
        "bad.json: dictionary must be an OpenCV ArUco dictionary name" in capsys.readouterr().err
        and not hout.exists()
    )


def test_plate_boards_from_prefix_dictionaries_are_told_apart_by_id() -> None:
    """OpenCV's DICT_4X4_50 is the first 50 markers of DICT_4X4_100/250/1000: two plates with
    those dictionaries and overlapping ids would be confused in one image, and are refused; a
    different marker size (5x5) or disjoint ids are fine."""
    import cv2

    from cpc2urdf.errors import ConfigurationError
    from cpc2urdf.files.robot_ref import load_model
    from cpc2urdf.identification.vision.boards.board import Board
    from cpc2urdf.identification.vision.measure_stereo import check_plate_boards, dictionary_family

    small = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50).bytesList
    large = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_1000).bytesList
    assert np.array_equal(small, large[:50])  # the fact the check relies on
    assert dictionary_family("DICT_4X4_250") == dictionary_family("DICT_4X4_50") == "DICT_4X4"
    assert dictionary_family("DICT_ARUCO_ORIGINAL") == "DICT_ARUCO_ORIGINAL"

    def charuco(dictionary: str, first: int) -> Board:
        return Board(
            "charuco",
            (5, 4),
            square_size=0.02,
            marker_size=0.015,
            dictionary=dictionary,
            first_marker_id=first,
        )

    structure = load_model("iis_head").structure
    n = charuco("DICT_4X4_50", 0).n_markers
    with pytest.raises(
        ConfigurationError,
        match=r"share marker ids of DICT_4X4_100 and DICT_4X4_50|"
        r"share marker ids of DICT_4X4_50 and DICT_4X4_100",
    ):
        check_plate_boards(
            {"plate_left": charuco("DICT_4X4_50", 0), "plate_right": charuco("DICT_4X4_100", 2)},
            structure,
        )
    ok = check_plate_boards(
        {"plate_left": charuco("DICT_4X4_50", 0), "plate_right": charuco("DICT_4X4_100", n)},
        structure,
    )
    assert set(ok) == {"plate_left", "plate_right"}
    check_plate_boards(
        {"plate_left": charuco("DICT_4X4_50", 0), "plate_right": charuco("DICT_5X5_50", 0)},
        structure,
    )
