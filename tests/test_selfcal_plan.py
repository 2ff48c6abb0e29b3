"""Planning a one-stage calibration: information, prediction, I-optimal selection, files, CLI."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from cpc2urdf.cli import main
from cpc2urdf.errors import InputFileError
from cpc2urdf.files.robot_ref import load_model, load_robot
from cpc2urdf.identification.handeye.stage2 import DEFAULT_INTRINSICS as INTR
from cpc2urdf.identification.kinematics.parametrization import Parametrization
from cpc2urdf.identification.planning import pixel_setup as ps
from cpc2urdf.identification.planning import selfcal_plan as sp
from cpc2urdf.identification.planning.plan_file import load_plan
from cpc2urdf.identification.planning.selfcal_plan_file import load_selfcal_plan, selfcal_setup
from cpc2urdf.identification.selfcal.bundle import fit_pixels
from cpc2urdf.identification.selfcal.pixel_problem import BoardView, CameraModel
from cpc2urdf.identification.simulation.selfcal_experiment import (
    selfcal_configurations,
    selfcal_scene,
)
from cpc2urdf.identification.vision.boards.board import Board
from cpc2urdf.identification.vision.boards.board_file import save_board
from cpc2urdf.identification.vision.joints_csv import read_joints_csv
from cpc2urdf.model import CPCParams, Frame
from cpc2urdf.transforms import inverse, rpy_from_matrix

CAMERAS = ("camera_left_optical", "camera_right_optical")
BOARD = Board("chessboard", (9, 6), square_size=0.03, margin=0.01)


def _cameras() -> dict[str, CameraModel]:
    return {c: CameraModel(INTR.K, INTR.D, (INTR.width, INTR.height)) for c in CAMERAS}


@pytest.fixture(scope="module")
def fixed() -> ps.PixelSetup:
    """The IIS-head, a board fixed in front of it (world = the board)."""
    return ps.PixelSetup(
        ps.board_in_front(load_model("iis_head"), _cameras(), BOARD), _cameras(), BOARD
    )


@pytest.fixture(scope="module")
def held() -> ps.PixelSetup:
    """The same board held on the pan link: table and pan are shared by cameras and board."""
    m = load_model("iis_head")
    T_world_board = m.T_world_base() @ inverse(
        ps.board_in_front(m, _cameras(), BOARD).T_world_base()
    )
    _, link = m.link_poses(m.structure.calibration_ranges().mean(axis=1))
    T_pan = link[0, m.structure.joint_index("pan")]
    model = m.with_frame(
        Frame("board", "pan", "plate"), CPCParams.from_matrix(inverse(T_pan) @ T_world_board)
    )
    return ps.PixelSetup(model, _cameras(), BOARD, board_frame="board")


def _relative_pose(setup: ps.PixelSetup, x: np.ndarray, q: np.ndarray) -> dict[str, np.ndarray]:
    chart = Parametrization(setup.nominal, setup.frames)
    return replace(setup, nominal=chart.model_from_vector(x)).camera_board(q)


@pytest.mark.parametrize("which", ["fixed", "held"])
def test_relative_pose_jacobian_matches_finite_differences(which: str, request) -> None:
    setup = request.getfixturevalue(which)
    q, _ = ps.draw_configurations(setup, 3, np.random.default_rng(1))
    G = sp.relative_pose_jacobians(setup, q)
    P = G[CAMERAS[0]].shape[2]
    T0 = _relative_pose(setup, np.zeros(P), q)
    h = 1e-6
    for p in range(P):
        x = np.zeros(P)
        x[p] = h
        T1 = _relative_pose(setup, x, q)
        for c in CAMERAS:
            # the camera in the board's frame: T_board_camera = inv(T_camera_board)
            A0, A1 = inverse(T0[c]), inverse(T1[c])
            dp = (A1[:, :3, 3] - A0[:, :3, 3]) / h
            dr = (
                Rotation.from_matrix(A1[:, :3, :3] @ np.swapaxes(A0[:, :3, :3], 1, 2)).as_rotvec()
                / h
            )
            np.testing.assert_allclose(G[c][:, :3, p], dp, atol=2e-5)
            np.testing.assert_allclose(G[c][:, 3:, p], dr, atol=2e-5)


def test_candidate_factors_are_the_information(fixed: ps.PixelSetup) -> None:
    q, _ = ps.draw_configurations(fixed, 4, np.random.default_rng(2))
    F = sp.candidate_information(fixed, q)
    assert (
        F.shape[1] == 12
    )  # 6 per camera: a view sees only its camera's pose relative to the board
    for i in range(len(q)):
        J, _ = sp._jacobian(fixed, q[i : i + 1], np.ones((1, 2), dtype=bool))
        info = J.T @ J
        np.testing.assert_allclose(F[i].T @ F[i], info, atol=1e-9 * np.abs(info).max())
        assert np.linalg.svd(J, compute_uv=False)[12] < 1e-9 * np.linalg.norm(J, 2)


def test_candidates_see_the_whole_board(fixed: ps.PixelSetup) -> None:
    q, drawn = ps.draw_configurations(fixed, 50, np.random.default_rng(3))
    assert drawn >= 50 and ps.board_seen(fixed, q).all()
    T = fixed.camera_board(q)
    for c in CAMERAS:
        X = BOARD.object_points() @ np.swapaxes(T[c][:, :3, :3], 1, 2) + T[c][:, None, :3, 3]
        assert (X[..., 2] > 0).all()
        assert (np.einsum("ni,ni->n", T[c][:, :3, 2], T[c][:, :3, 3]) < 0).all()  # face +z to it
        uv = X[..., :2] / X[..., 2:] * INTR.fx + [INTR.cx, INTR.cy]
        assert (uv > ps.VIEW_MARGIN_PX).all() and (
            uv[..., 0] < INTR.width - ps.VIEW_MARGIN_PX
        ).all()
    # the same board turned about its x axis: its back faces the cameras, nothing is seen
    flip = np.diag([1.0, -1.0, -1.0, 1.0]) @ fixed.nominal.T_world_base()
    turned = fixed.nominal.with_params(world_to_base=CPCParams.from_matrix(flip))
    assert not ps.board_seen(replace(fixed, nominal=turned), q, margins=False).any()


@pytest.mark.parametrize(
    ("which", "seed", "fits", "bound"), [("fixed", 4, 25, 0.2), ("held", 7, 20, 0.25)]
)
def test_prediction_is_the_fits_error(
    which: str, seed: int, fits: int, bound: float, request
) -> None:
    """The prediction against one-stage fits of noisy exact corners (0.3 px); a held board: relative
    poses only, table and pan not determined."""
    setup = replace(request.getfixturevalue(which), sigma=0.3)
    plan = sp.plan_selfcal(setup, 12, n_candidates=150, n_heldout=40, n_random=0)
    rng = np.random.default_rng(seed)
    data = sp.pixel_data(setup, plan.q, ps.board_seen(setup, plan.q, margins=False))
    T_true = setup.camera_board(plan.heldout)
    sq = {c: [] for c in CAMERAS}
    for _ in range(fits):
        noisy = [
            BoardView(v.camera, v.record, v.ids, v.uv + rng.normal(0, 0.3, v.uv.shape))
            for v in data.views
        ]
        fit = fit_pixels(setup.nominal, replace(data, views=noisy))
        T_fit = replace(setup, nominal=fit.model).camera_board(plan.heldout)
        for c in CAMERAS:
            e = inverse(T_fit[c])[:, :3, 3] - inverse(T_true[c])[:, :3, 3]
            sq[c].append(np.mean(np.sum(e**2, axis=1)))
    for c in CAMERAS:
        ratio = np.sqrt(np.mean(sq[c])) / plan.prediction.position[c]
        assert abs(ratio - 1.0) < bound, (c, ratio)


@pytest.mark.parametrize("which", ["fixed", "held"])
def test_plan_predicts_less_than_random_candidates(which: str, request) -> None:
    setup = request.getfixturevalue(which)
    plan = sp.plan_selfcal(setup, 12, n_candidates=300, n_heldout=100, n_random=10)
    assert len(plan.q) == 12 and ps.board_seen(setup, plan.q).all()
    pred = plan.prediction
    assert all(np.isfinite(list(pred.position.values())))
    assert all(pred.position_rms < r.position_rms for r in plan.random)
    assert pred.position_rms < 0.95 * plan.random_position_rms()
    # the public prediction from the configurations gives the plan's number
    again = sp.predicted_camera_pose_error(setup, plan.q, plan.heldout)
    np.testing.assert_allclose(again.position_rms, pred.position_rms, rtol=1e-6)
    if which == "held":  # table and pan shared by cameras and board: 8 + 6 free directions
        assert pred.rank == pred.n_params - 14


def test_a_plan_that_never_moves_the_tilt_leaves_camera_poses_undetermined(
    fixed: ps.PixelSetup,
) -> None:
    q, _ = ps.draw_configurations(fixed, 60, np.random.default_rng(5))
    q[:, 3] = q[0, 3]
    q = q[ps.board_seen(fixed, q).all(axis=1)]
    heldout, _ = ps.draw_configurations(fixed, 20, np.random.default_rng(6))
    pred = sp.predicted_camera_pose_error(fixed, q, heldout)
    assert pred.rank < pred.n_params and not np.isfinite(pred.position_rms)
    assert sp.predicted_camera_pose_error(fixed, q, q).position_rms < 1.0  # where it was measured


# ---- files and command line ----------------------------------------------------------------------


@pytest.fixture(scope="module")
def board_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return save_board(BOARD, tmp_path_factory.mktemp("board") / "board.json")


def test_cli_plans_a_fixed_board(tmp_path: Path, board_file: Path, capsys) -> None:
    out = tmp_path / "plan.json"
    argv = ["plan", "iis_head", "--cameras", *CAMERAS, "--board", str(board_file), "--poses", "8"]
    assert main([*argv, "--candidates", "120", "-o", str(out)]) == 0
    printed = capsys.readouterr().out.splitlines()
    assert printed[0].startswith("plan: 8 configurations (I-optimal, one-stage")
    assert "predicted camera pose error" in printed[0] and "random plans" in printed[0]
    structure = load_model("iis_head").structure
    plan = load_selfcal_plan(out, structure)
    assert plan.q.shape == (8, 6) and plan.cameras == list(CAMERAS) and plan.board_frame is None
    csv = read_joints_csv(out.with_suffix(".csv"), structure)
    np.testing.assert_allclose(csv.q, plan.q, atol=1e-9)
    assert 0 < plan.prediction["position_rms_mm"] < 5
    with pytest.raises(InputFileError, match="one-stage plan"):
        load_plan(out)
    doc = json.loads(out.read_text())
    assert doc["setup"]["noise"] == {"model": "pixels", "sigma_px": ps.DEFAULT_SIGMA}
    assert doc["random"]["position_rms_mm_median"] > doc["prediction"]["position_rms_mm"]


@pytest.fixture(scope="module")
def iis_urdf(tmp_path_factory: pytest.TempPathFactory) -> Path:
    urdf = tmp_path_factory.mktemp("urdf") / "iis.urdf"
    assert main(["export", "iis_head", "-o", str(urdf)]) == 0
    return urdf


def test_setup_of_a_simulated_scene(iis_urdf: Path) -> None:
    scene = selfcal_scene(iis_urdf, CAMERAS, board=BOARD, distance=0.75)
    setup = ps.setup_from_scene(scene)
    q = selfcal_configurations(scene, 6, np.random.default_rng(0))
    T = setup.camera_board(q)
    for c in scene.cameras:
        np.testing.assert_allclose(T[c], scene.T_camera_board(c, q, scene.nominal), atol=1e-9)
    assert np.isfinite(sp.predicted_camera_pose_error(setup, q, q).position_rms)


def test_cli_plans_a_board_held_by_a_urdf_link(
    tmp_path: Path, board_file: Path, iis_urdf: Path
) -> None:
    """An exported IIS-head URDF with a board link fixed to the pan link, facing the cameras."""
    urdf = tmp_path / "iis.urdf"
    text = iis_urdf.read_text()
    joint = '<joint name="board_joint" type="fixed"><parent link="pan_link"/><child link="board"/>{}</joint><link name="board"/>\n</robot>'
    urdf.write_text(text.replace("</robot>", joint.format("")))
    fixed_setup, _ = selfcal_setup(load_robot(str(urdf)), CAMERAS, BOARD)
    at_pan, _ = selfcal_setup(load_robot(str(urdf)), CAMERAS, BOARD, board_link="board")
    q0 = at_pan.calibration_ranges().mean(axis=1)
    T_world_board = at_pan.nominal.T_world_base() @ inverse(fixed_setup.nominal.T_world_base())
    T = inverse(at_pan.nominal.fk_frame("board", q0)) @ T_world_board
    rpy = rpy_from_matrix(T[:3, :3])
    origin = '<origin xyz="{} {} {}" rpy="{} {} {}"/>'.format(*T[:3, 3], *rpy)
    urdf.write_text(text.replace("</robot>", joint.format(origin)))
    out = tmp_path / "held.json"
    argv = [
        "plan",
        str(urdf),
        "--cameras",
        *CAMERAS,
        "--board",
        str(board_file),
        "--board-link",
        "board",
    ]
    assert main([*argv, "--poses", "10", "--candidates", "120", "-o", str(out)]) == 0
    doc = json.loads(out.read_text())
    assert doc["setup"]["board_frame"] == "board" and len(doc["configurations"]) == 10
    assert doc["prediction"]["rank"] < doc["prediction"]["n_params"]  # table and pan shared
    assert doc["random"]["position_rms_mm_median"] > doc["prediction"]["position_rms_mm"]


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--n", "5"], "--n is for stage-1 plans"),
        (["--measure", "plate_left"], "--measure is for stage-1 plans"),
        (["--poses", "0"], "--poses must be at least 1"),
        (["--intrinsics", "{missing}"], "missing.yaml"),
        (["--board-distance", "-1"], "--board-distance"),
    ],
)
def test_cli_refuses_bad_one_stage_input(
    tmp_path: Path, board_file: Path, capsys, extra: list[str], message: str
) -> None:
    out = tmp_path / "plan.json"
    extra = [e.replace("{missing}", str(tmp_path / "missing.yaml")) for e in extra]
    argv = ["plan", "iis_head", "--cameras", *CAMERAS, "--board", str(board_file)]
    if "--poses" not in extra:
        extra = ["--poses", "6", *extra]
    assert main([*argv, *extra, "--candidates", "60", "-o", str(out)]) == 2
    assert message in capsys.readouterr().err
    assert not out.exists() and not out.with_suffix(".csv").exists()
    assert main(["plan", "iis_head", "--poses", "6", "-o", str(out)]) == 2
    assert "needs --cameras" in capsys.readouterr().err
