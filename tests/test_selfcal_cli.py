"""The one-stage chain of docs/selfcal.md, from the command line and from Python: plan ->
simulate (rendered images) -> identify -> export -> check, on TALOS's head (board fixed) and, in
the slow set, TIAGo's arm and head (board in its gripper). The calibrated URDF must predict the
camera's pose in the board's frame better than the URDF did, and every parser must agree."""

from __future__ import annotations

import json
import sysconfig
from pathlib import Path

import numpy as np
import pytest

import cpc2urdf
from cpc2urdf.api import load_model
from cpc2urdf.cli import main
from cpc2urdf.transforms import inverse

ROBOTS = Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix/share/example-robot-data/robots"
TALOS = ROBOTS / "talos_data/robots/talos_reduced.urdf"
TIAGO = ROBOTS / "tiago_description/robots/tiago.urdf"
BOARD = {
    "format": "cpc2urdf/board@1",
    "kind": "chessboard",
    "pattern_size": [9, 6],
    "square_size": 30,
    "margin": 20,
    "units": "mm",
}


def _chain(tmp: Path, urdf: Path, camera: str, board_link: str | None, poses: int) -> Path:
    board = tmp / "board.json"
    board.write_text(json.dumps(BOARD))
    held = ["--board-link", board_link] if board_link else []
    common = [str(urdf), "--cameras", camera, "--board", str(board), *held]
    assert main(["plan", *common, "--poses", str(poses), "-o", str(tmp / "plan.json")]) == 0
    assert (
        main(["simulate", *common, "--plan", str(tmp / "plan.json"), "--images", str(tmp / "img")])
        == 0
    )
    ident = ["identify", str(tmp / "img"), "--robot", str(urdf), "--cameras", camera, *held]
    assert main([*ident, "-o", str(tmp / "model.json")]) == 0
    assert main(["export", str(tmp / "model.json"), "-o", str(tmp / "cal.urdf")]) == 0
    assert main(["check", str(tmp / "cal.urdf"), "--model", str(tmp / "model.json")]) == 0
    return tmp / "img"


def _camera_in_board(model, frame: str, q, T_world_board=None, board=None):
    T = model.fk_frame(frame, q)
    if board is not None:
        return inverse(model.fk_frame(board, q)) @ T
    return T if T_world_board is None else inverse(T_world_board) @ T


@pytest.fixture(scope="module")
def talos(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _chain(tmp_path_factory.mktemp("talos"), TALOS, "rgbd_link", None, 12)


def test_cli_chain_calibrates_talos_head_better_than_its_urdf(talos: Path, capsys):
    truth = load_model(talos / "truth_model.json")
    doc = json.loads((talos / "selfcal_truth.json").read_text())
    model = load_model(talos.parent / "model.json")
    frame = doc["cameras"][0]
    q = np.random.default_rng(0).uniform(*truth.structure.calibration_ranges().T, (20, 4)) * 0.3
    T_true = _camera_in_board(truth, frame, q, np.array(doc["T_world_board"]))
    # the calibrated model's world is the board; the URDF's is placed by the same images
    est = model.fk_frame("rgbd_frame", q)
    err = np.linalg.norm(est[:, :3, 3] - T_true[:, :3, 3], axis=1).max()
    assert err < 1e-3, err  # sub-millimetre where the URDF is 1 mm / 0.5 deg off per joint
    text = (talos.parent / "cal.urdf").read_text()
    assert text.count("<origin") == TALOS.read_text().count("<origin")  # only origins change
    rows = [line.split() for line in (talos.parent / "cal.report.txt").read_text().splitlines()]
    assert ["rgbd_joint", "camera"] in [r[:2] for r in rows]  # the camera mount, written back


def test_python_quick_start_gives_the_same_model(talos: Path, tmp_path: Path):
    """docs/selfcal.md's Python block: the same plan, images and model as the commands."""
    tmp = talos.parent
    plan = cpc2urdf.plan_experiment(
        TALOS, n=12, cameras=["rgbd_link"], board=tmp / "board.json", output=tmp_path / "plan.json"
    )
    assert (tmp_path / "plan.json").read_text() == (tmp / "plan.json").read_text()
    assert plan.plan.q.shape == (12, 4)
    images = tmp_path / "images"
    cpc2urdf.simulate(
        TALOS,
        cameras=["rgbd_link"],
        board=tmp / "board.json",
        plan=tmp / "plan.json",
        images=images,
    )
    model = cpc2urdf.calibrate_head(images, TALOS, ["rgbd_link"])
    cpc2urdf.export_urdf(model, tmp_path / "cal.urdf")
    assert cpc2urdf.check_urdf(model, tmp_path / "cal.urdf").ok
    cli = load_model(tmp / "model.json")
    q = np.zeros((1, 4))
    assert np.allclose(model.fk_frame("rgbd_frame", q), cli.fk_frame("rgbd_frame", q), atol=1e-9)


def test_bad_image_folders_get_one_line(talos: Path, tmp_path: Path, capsys):
    out = tmp_path / "m.json"
    cases = [
        (["--robot", str(TALOS), "--cameras", "head_2_link"], "head_2_link"),
        (["--robot", str(TALOS)], "is a folder"),
        (
            ["--robot", str(TALOS), "--cameras", "rgbd_link", "--board", str(tmp_path / "no.json")],
            "no.json",
        ),
    ]
    for extra, said in cases:
        assert main(["identify", str(talos), *extra, "-o", str(out)]) == 2
        err = capsys.readouterr().err
        assert said in err and err.count("\n") == 1, err
    assert not out.exists()


def test_joint_states_with_every_joint_and_too_few_images(talos: Path, tmp_path: Path, capsys):
    """A joints.csv with the robot's other joints too (as a ROS joint_states) is read; three
    images are refused in one line, not with a traceback."""
    import shutil

    folder = tmp_path / "img"
    shutil.copytree(talos, folder)
    rows = (folder / "joints.csv").read_text().splitlines()
    rows = [r + (",arm_left_1_joint" if i == 0 else ",0.1") for i, r in enumerate(rows)]
    (folder / "joints.csv").write_text("\n".join(rows) + "\n")
    argv = ["identify", str(folder), "--robot", str(TALOS), "--cameras", "rgbd_link"]
    assert main([*argv, "-o", str(tmp_path / "m.json")]) == 0
    for png in sorted((folder / "rgbd_link").glob("*.png"))[3:]:
        png.unlink()
    capsys.readouterr()
    assert main([*argv, "-o", str(tmp_path / "m3.json")]) == 2
    err = capsys.readouterr().err
    assert "3 images of the board" in err and err.count("\n") == 1, err
    assert not (tmp_path / "m3.json").exists()


@pytest.mark.slow
def test_cli_chain_calibrates_tiago_arm_and_head_together(tmp_path: Path):
    img = _chain(tmp_path, TIAGO, "xtion_link", "arm_tool_link", 20)
    model = load_model(tmp_path / "model.json")
    notes = " ".join(model.metadata.notes)
    assert "torso_lift" in notes  # on both paths: kept at the URDF's values, and said
    changed = (tmp_path / "cal.report.txt").read_text()
    assert "arm_7_joint" in changed and "head_2_joint" in changed
    assert (img / "xtion_link").is_dir()
