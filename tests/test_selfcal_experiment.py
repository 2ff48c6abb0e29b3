"""Simulated images for a head calibrated by its own cameras (selfcal_experiment.py): TALOS and TIAGo
from example-robot-data, the board fixed in the world or held in TIAGo's hand."""

from __future__ import annotations

import json
import math
import sysconfig
from pathlib import Path

import numpy as np
import pytest

from cpc2urdf.errors import ConfigurationError, DegenerateDataError, InputFileError
from cpc2urdf.files.robot_ref import load_model
from cpc2urdf.identification.handeye.stage2 import DEFAULT_INTRINSICS, CameraIntrinsics
from cpc2urdf.identification.simulation.design import farthest_points, walk_configurations
from cpc2urdf.identification.simulation.selfcal_experiment import (
    TRUTH_FORMAT,
    SelfcalScene,
    exact_corners,
    in_view,
    joint_coverage,
    render_selfcal_experiment,
    selfcal_configurations,
    selfcal_scene,
)
from cpc2urdf.identification.simulation.visibility import board_in_view
from cpc2urdf.identification.vision.boards.board import Board
from cpc2urdf.identification.vision.boards.board_file import load_board
from cpc2urdf.identification.vision.boards.board_poses import board_pose
from cpc2urdf.identification.vision.image_folders import read_grey
from cpc2urdf.identification.vision.measure_head import HeadCamera, measure_head_images
from cpc2urdf.identification.vision.render import PinholeView
from cpc2urdf.identification.vision.rig_file import load_camera
from cpc2urdf.transforms import homogeneous, inverse

ROBOTS = Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix/share/example-robot-data/robots"
TALOS = ROBOTS / "talos_data/robots/talos_reduced.urdf"
TIAGO = ROBOTS / "tiago_description/robots/tiago.urdf"
HAND = "hand_grasping_frame"  # TIAGo's (Hey5 hand) grasp frame, fixed to the wrist
CHARUCO = Board(
    "charuco", (5, 4), square_size=0.04, marker_size=0.03, dictionary="DICT_4X4_50", margin=0.01
)
CHESS = Board("chessboard", (6, 5), square_size=0.03, margin=0.015)  # 6 + 5 odd: a unique pose
MAX_CORNER_RMS_PX = 0.3  # detected vs true corners on rendered images (blur 0.7 px, noise 2 levels)


@pytest.fixture(scope="module")
def held() -> SelfcalScene:
    return selfcal_scene(TIAGO, ["xtion_link"], board=CHARUCO, board_link=HAND, seed=1)


def _measure(folder: Path, scene: SelfcalScene) -> tuple[int, float]:
    """Records ``measure_head`` measured in every camera, and the detector's corner error: RMS per
    coordinate of the corners found vs :func:`exact_corners` [px]."""
    model = load_model(folder / "nominal_model.json")
    board = load_board(folder / "board.json")
    links = scene.camera_links  # the sub-folders are named as the user names the cameras
    cams = {c: HeadCamera(*load_camera(folder / f"{c}.yaml")) for c in links}
    found = measure_head_images(folder, cams, model.structure, board=board, on_error="stop")
    q = np.array([[float(v) for v in r] for r in found.q[links[0]]])
    exact = exact_corners(scene, q)
    res = []
    for c, link in zip(scene.cameras, links, strict=True):
        for i in range(len(q)):
            img = read_grey(folder / link / f"{i:04d}.png")
            p = board_pose(img, cams[link].K, cams[link].D, board)
            assert not isinstance(p, Exception), p
            assert len(p.ids) == board.n_points
            res.append(p.uv - exact[c][i][p.ids])
    return min(len(v) for v in found.labels.values()), float(np.sqrt(np.mean(np.square(res))))


def _independent_view_check(scene: SelfcalScene, q: np.ndarray, max_angle_deg: float) -> None:
    """Every camera sees every board point inside the image, the printed face towards it."""
    K, w, h = DEFAULT_INTRINSICS.K, DEFAULT_INTRINSICS.width, DEFAULT_INTRINSICS.height
    T_world_board = scene.board_poses(q)
    for c in scene.cameras:
        T_world_cam = scene.truth.fk_frame(c, q)
        for Tc, Tb in zip(T_world_cam, T_world_board, strict=True):
            T = np.linalg.inv(Tc) @ Tb
            p = scene.board.object_points() @ T[:3, :3].T + T[:3, 3]
            assert np.all(p[:, 2] > 0.1)
            uv = p[:, :2] / p[:, 2:] * K[[0, 1], [0, 1]] + K[:2, 2]
            assert np.all((uv > 0) & (uv < [w - 1, h - 1]))
            to_camera = -T[:3, 3] / np.linalg.norm(T[:3, 3])
            assert math.degrees(math.acos(T[:3, 2] @ to_camera)) < max_angle_deg


def test_talos_fixed_board_images_round_trip(tmp_path: Path) -> None:
    """TALOS's head camera, a fixed chessboard: the folder measure_head reads, every image measured,
    corners within the detector's noise of the truth, the truth files consistent with the scene."""
    scene = selfcal_scene(TALOS, ["rgbd_link"], board=CHESS, seed=0)
    assert scene.board_frame is None and scene.T_world_board is not None
    assert scene.cameras == ("rgbd_frame",)  # the optical frame of body link rgbd_link
    q = selfcal_configurations(scene, 4, np.random.default_rng(0))
    paths = render_selfcal_experiment(tmp_path / "talos", scene, q, seed=1)
    names = sorted(p.name for p in (tmp_path / "talos").iterdir())
    assert names == [
        "board.json",
        "joints.csv",
        "nominal_model.json",
        "rgbd_link",
        "rgbd_link.yaml",
        "selfcal_truth.json",
        "truth_model.json",
    ]
    assert set(paths) >= {"rgbd_frame", "joints", "board", "selfcal_truth", "truth_model"}
    n, rms = _measure(tmp_path / "talos", scene)
    assert n == 4
    assert rms < MAX_CORNER_RMS_PX
    doc = json.loads((tmp_path / "talos" / "selfcal_truth.json").read_text())
    assert doc["format"] == TRUTH_FORMAT and doc["board_frame"] is None
    assert doc["cameras"] == ["rgbd_frame"] and Path(doc["urdf"]) == TALOS.resolve()
    np.testing.assert_allclose(doc["T_world_board"], scene.T_world_board)
    truth = load_model(tmp_path / "talos" / "truth_model.json")
    np.testing.assert_allclose(
        truth.fk_frame("rgbd_frame", q), scene.truth.fk_frame("rgbd_frame", q), atol=1e-9
    )


def test_configurations_keep_the_board_in_view_of_both_cameras() -> None:
    """TIAGo's two xtion optical frames, a fixed board: every camera sees the whole board, face
    on within 60 deg, at every configuration; each joint moves over a good part of its range."""
    scene = selfcal_scene(
        TIAGO, ["xtion_rgb_optical_frame", "xtion_depth_optical_frame"], board=CHARUCO, seed=2
    )
    assert len(scene.cameras) == 2
    q = selfcal_configurations(scene, 8, np.random.default_rng(3))
    assert q.shape == (8, scene.truth.structure.n_joints)
    assert in_view(scene, q).all()
    _independent_view_check(scene, q, 60.0)
    assert min(joint_coverage(scene, q).values()) > 0.3


def test_truth_differs_from_the_urdf_everywhere(held: SelfcalScene) -> None:
    """The true joints, camera mount and board placement all differ from the nominal ones by
    about the perturbation (1 mm, 0.5 deg)."""
    for group in ("joints", "frames"):
        nominal, truth = getattr(held.nominal, group), getattr(held.truth, group)
        for name in nominal:
            d = inverse(nominal[name].matrix()) @ truth[name].matrix()
            assert 1e-5 < np.linalg.norm(d[:3, 3]) + np.linalg.norm(d[:3, :3] - np.eye(3)) < 0.05
    assert set(held.nominal.frames) == {"xtion_frame", "board"}


def test_held_board_on_the_hand(held: SelfcalScene, tmp_path: Path) -> None:
    """TIAGo holds the board: it hangs on the last arm joint, faces the camera at the presentation
    configuration, every joint of head, torso and arm moves, and the images round-trip."""
    assert held.board_frame == "board" and held.T_world_board is None
    assert held.nominal.structure.frame("board").parent == "arm_7"
    T = held.T_camera_board(held.cameras[0], held.presentation)[0]
    assert T[2, 3] == pytest.approx(0.6, abs=0.02) and T[2, 2] < -0.99  # ahead, facing it
    q = selfcal_configurations(held, 6, np.random.default_rng(0))
    coverage = joint_coverage(held, q)
    assert set(coverage) == {"torso_lift", "head_1", "head_2"} | {f"arm_{i}" for i in range(1, 8)}
    assert min(coverage.values()) > 0.25, coverage
    render_selfcal_experiment(tmp_path / "held", held, q[:3], seed=0)
    n, rms = _measure(tmp_path / "held", held)
    assert n == 3 and rms < MAX_CORNER_RMS_PX
    doc = json.loads((tmp_path / "held" / "selfcal_truth.json").read_text())
    assert doc["board_frame"] == "board" and doc["T_world_board"] is None
    assert doc["board_link"] == HAND


def test_held_board_moves_with_the_arm(held: SelfcalScene, tmp_path: Path) -> None:
    """Moving one arm joint alone moves the board's pixels; the image changes with them."""
    q = np.stack([held.presentation, held.presentation])
    q[1, held.truth.structure.joint_index("arm_1")] += 0.03
    assert in_view(held, q).all()
    uv = exact_corners(held, q)[held.cameras[0]]
    assert np.linalg.norm(uv[1] - uv[0], axis=1).min() > 2.0
    render_selfcal_experiment(tmp_path / "arm", held, q, noise_sigma=0.0, seed=0)
    a, b = (read_grey(tmp_path / "arm" / held.camera_links[0] / f"{i:04d}.png") for i in (0, 1))
    assert np.abs(a.astype(int) - b.astype(int)).max() > 100


def test_bad_inputs() -> None:
    """A board too large to see whole, a link the URDF lacks, intrinsics for the wrong camera."""
    huge = Board("chessboard", (13, 10), square_size=0.1)
    big = selfcal_scene(TIAGO, ["xtion_link"], board=huge)
    with pytest.raises(DegenerateDataError, match=r"tiago, cameras \['xtion_link'\]: the board"):
        selfcal_configurations(big, 3, np.random.default_rng(0))
    with pytest.raises(InputFileError, match="no_such_link"):
        selfcal_scene(TIAGO, ["xtion_link"], board=CHARUCO, board_link="no_such_link")
    scene = selfcal_scene(TIAGO, ["xtion_link"], board=CHARUCO)
    with pytest.raises(ConfigurationError, match=r"no intrinsics for cameras \['xtion_frame'\]"):
        exact_corners(scene, scene.presentation, {"other": DEFAULT_INTRINSICS})
    with pytest.raises(ConfigurationError, match="distance"):
        selfcal_scene(TIAGO, ["xtion_link"], board=CHARUCO, distance=-1.0)
    with pytest.raises(ConfigurationError, match="at least one"):
        selfcal_configurations(scene, 0, np.random.default_rng(0))


def test_per_camera_intrinsics(tmp_path: Path) -> None:
    """A mapping gives each camera its own intrinsics, written to its .yaml."""
    scene = selfcal_scene(TIAGO, ["xtion_link"], board=CHARUCO, seed=4)
    wide = CameraIntrinsics(fx=400.0, fy=400.0, dist=(-0.05, 0.01, 0.0, 0.0, 0.0))
    q = scene.presentation[None]
    uv = exact_corners(scene, q, {"xtion_frame": wide})["xtion_frame"]
    assert not np.allclose(uv, exact_corners(scene, q)["xtion_frame"])
    render_selfcal_experiment(tmp_path / "w", scene, q, intrinsics={"xtion_frame": wide})
    K, D, size = load_camera(tmp_path / "w" / "xtion_link.yaml")
    np.testing.assert_allclose(K, wide.K)
    np.testing.assert_allclose(D, wide.D)


def test_board_in_view_limits() -> None:
    """The vectorised check: face towards the camera, angle and size limits, in the image."""
    view = PinholeView(DEFAULT_INTRINSICS.K, DEFAULT_INTRINSICS.D, (640, 480))
    facing = homogeneous(np.diag([1.0, -1.0, -1.0]), np.array([0.0, 0.0, 0.6]))
    back = homogeneous(np.eye(3), np.array([0.0, 0.0, 0.6]))
    c, s = math.cos(math.radians(70)), math.sin(math.radians(70))
    tilted = facing @ homogeneous(np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]), np.zeros(3))
    far = homogeneous(np.diag([1.0, -1.0, -1.0]), np.array([0.0, 0.0, 3.0]))
    aside = homogeneous(np.diag([1.0, -1.0, -1.0]), np.array([0.5, 0.0, 0.6]))
    ok = board_in_view(view, CHARUCO, np.array([facing, back, tilted, far, aside]))
    assert ok.tolist() == [True, False, True, True, False]
    strict = board_in_view(
        view,
        CHARUCO,
        np.array([facing, tilted, far]),
        max_angle=math.radians(60),
        min_point_px=25,
    )
    assert strict.tolist() == [True, False, False]


def test_walk_stays_usable_and_spread_reaches_the_ends() -> None:
    rng = np.random.default_rng(0)
    ranges = np.array([[-1.0, 1.0], [0.0, 2.0]])

    def usable(q: np.ndarray) -> np.ndarray:
        return np.abs(q[:, 0]) + np.abs(q[:, 1] - 1.0) < 0.5

    visited = walk_configurations(usable, [0.0, 1.0], ranges, rng, 300)
    assert usable(visited).all() and len(visited) > 100
    line = np.linspace(0.0, 1.0, 11)[:, None]
    picked = farthest_points(line, 3, np.array([[0.0, 1.0]]), rng)
    assert {0.0, 1.0} <= set(picked.ravel().tolist())


def test_cli_simulate_images(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``cpc2urdf simulate TIAGO --cameras xtion_link --board B --board-link HAND --images DIR``
    writes the folder; bad input gets one line and exit 2, before anything is written."""
    from cpc2urdf.cli import main
    from cpc2urdf.identification.vision.boards.board_file import save_board

    board = save_board(CHARUCO, tmp_path / "charuco.json")
    out = tmp_path / "images"
    argv = ["simulate", str(TIAGO), "--cameras", "xtion_link", "--board", str(board)]
    held = [*argv, "--board-link", HAND, "--images", str(out), "--poses", "3", "--seed", "5"]
    assert main(held) == 0
    assert "3 records x 1 cameras (xtion_link), the board held by" in capsys.readouterr().out
    assert len(list((out / "xtion_link").glob("*.png"))) == 3
    assert json.loads((out / "selfcal_truth.json").read_text())["board_link"] == HAND
    capsys.readouterr()
    bad = [
        ([*argv, "--images", str(tmp_path / "x"), "-o", str(tmp_path / "y")], "takes no -o"),
        (argv, "--board needs --images"),
        ([*argv, "--images", str(out / "board.json")], "exists and is not a folder"),
        (
            ["simulate", "iis_head", "--cameras", "c", "--board", str(board), "--images", "z"],
            "URDF",
        ),
        ([*argv, "--board-link", "nope", "--images", str(tmp_path / "x")], "no link 'nope'"),
        ([*argv, "--images", str(tmp_path / "x"), "--poses", "0"], "--poses"),
    ]
    for args, expected in bad:
        assert main(args) == 2, args
        err = capsys.readouterr().err
        assert expected in err and err.count("\n") == 1, err
    assert not (tmp_path / "x").exists() and not (tmp_path / "y").exists()
    save_board(Board("chessboard", (6, 6), square_size=0.03), tmp_path / "sym.json")
    sym = [*argv[:-1], str(tmp_path / "sym.json"), "--images", str(tmp_path / "x")]
    assert main(sym) == 2
    assert "180 deg" in capsys.readouterr().err
