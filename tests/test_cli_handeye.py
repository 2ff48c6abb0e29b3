"""``cpc2urdf handeye``: the pose file format and the command (identification/handeye_file.py,
cpc2urdf/cli/handeye.py)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from test_handeye import EXACT, make_data

from cpc2urdf.cli import COMMANDS, main
from cpc2urdf.errors import InputFileError
from cpc2urdf.files.units import Units
from cpc2urdf.identification.handeye.pose_file import (
    HANDEYE_POSES_FORMAT,
    handeye_poses_to_json,
    load_handeye_poses,
    save_handeye_poses,
)
from cpc2urdf.identification.handeye.solvers import ALL_METHODS
from cpc2urdf.transforms import inverse


@pytest.fixture()
def truth_and_file(tmp_path: Path) -> tuple[np.ndarray, np.ndarray, Path]:
    rng = np.random.default_rng(0)
    X, Z, H, C = make_data(rng, 6)
    path = tmp_path / "poses.json"
    save_handeye_poses(
        path, H, C, units=Units("mm", "deg"), camera="camera_left_optical", hand="plate_left"
    )
    return X, Z, path


def test_registered() -> None:
    assert "handeye" in COMMANDS


def test_file_round_trip_in_mm(truth_and_file: tuple[np.ndarray, np.ndarray, Path]) -> None:
    X, Z, path = truth_and_file
    doc = json.loads(path.read_text())
    assert doc["format"] == HANDEYE_POSES_FORMAT and doc["units"] == {
        "length": "mm",
        "angle": "deg",
    }
    data = load_handeye_poses(path)
    assert np.abs(data.T_base_hand @ X @ data.T_camera_target - Z).max() < EXACT
    assert data.camera == "camera_left_optical" and data.labels[0] == "pose 0"


def test_quaternion_records(tmp_path: Path) -> None:
    rng = np.random.default_rng(1)
    _, _, H, C = make_data(rng, 3)
    from scipy.spatial.transform import Rotation

    recs = [
        {
            "T_base_hand": {
                "xyz": (H[k, :3, 3] * 1e3).tolist(),
                "quat_xyzw": Rotation.from_matrix(H[k, :3, :3]).as_quat().tolist(),
            },
            "T_camera_target": {"matrix": C[k].tolist()},
        }
        for k in range(3)
    ]
    doc = {"format": HANDEYE_POSES_FORMAT, "units": {"length": "mm"}, "records": recs}
    # matrix translations are in file units (mm) too
    for k in range(3):
        doc["records"][k]["T_camera_target"]["matrix"] = [
            [*C[k, i, :3].tolist(), C[k, i, 3] * 1e3] for i in range(3)
        ] + [[0, 0, 0, 1]]
    p = tmp_path / "q.json"
    p.write_text(json.dumps(doc))
    data = load_handeye_poses(p)
    assert (
        np.abs(data.T_base_hand - H).max() < 1e-12
        and np.abs(data.T_camera_target - C).max() < 1e-12
    )


def test_cli_single_method_text(
    truth_and_file: tuple[np.ndarray, np.ndarray, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    X, _, path = truth_and_file
    assert main(["handeye", str(path), "--method", "tsai"]) == 0
    out = capsys.readouterr().out
    assert "X = T_hand_camera" in out and "Z = T_base_target" in out
    assert f"{X[0, 3] * 1e3:10.4f}" in out
    assert out.count("pose ") >= 6 and "RMS" in out


def test_cli_json(
    truth_and_file: tuple[np.ndarray, np.ndarray, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    X, Z, path = truth_and_file
    assert main(["handeye", str(path), "--method", "dual_quaternion", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert np.abs(np.array(doc["X"]["matrix"]) - X).max() < EXACT
    assert np.abs(np.array(doc["Z"]["matrix"]) - Z).max() < EXACT
    assert len(doc["residual_rotation_deg"]) == 6 and max(doc["residual_translation_mm"]) < 1e-6


def test_cli_all_side_by_side(
    truth_and_file: tuple[np.ndarray, np.ndarray, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    X, _, path = truth_and_file
    assert main(["handeye", str(path), "--method", "all", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert set(doc["results"]) == set(ALL_METHODS)
    for r in doc["results"].values():
        assert np.abs(np.array(r["X"]["matrix"]) - X).max() < EXACT
    assert main(["handeye", str(path), "--method", "all"]) == 0
    out = capsys.readouterr().out
    assert all(m in out for m in ALL_METHODS) and "residual per pose" in out


def _write(tmp_path: Path, doc: object) -> str:
    p = tmp_path / "bad.json"
    p.write_text(json.dumps(doc))
    return str(p)


def _run_bad(argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "Traceback" not in err
    return err


def test_cli_bad_inputs(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rng = np.random.default_rng(0)
    X, Z, H, C = make_data(rng, 5)
    good = handeye_poses_to_json(H, C)

    assert "no such file" in _run_bad(["handeye", str(tmp_path / "nope.json")], capsys)
    assert "format is" in _run_bad(["handeye", _write(tmp_path, {**good, "format": "x"})], capsys)

    doc = json.loads(json.dumps(good))
    doc["records"][2]["T_target_camera"] = doc["records"][2].pop("T_camera_target")
    err = _run_bad(["handeye", _write(tmp_path, doc)], capsys)
    assert "records[2]" in err and "T_target_camera" in err

    doc = json.loads(json.dumps(good))
    doc["records"][1]["T_base_hand"]["matrix"][0][0] = 2.0
    assert "records[1].T_base_hand.matrix" in _run_bad(["handeye", _write(tmp_path, doc)], capsys)

    two = {**good, "records": good["records"][:2]}
    assert "at least 3" in _run_bad(["handeye", _write(tmp_path, two)], capsys)
    assert "at least 3" in _run_bad(["handeye", _write(tmp_path, two), "--method", "all"], capsys)

    inverted = handeye_poses_to_json(H, inverse(C))
    err = _run_bad(["handeye", _write(tmp_path, inverted), "--method", "tsai"], capsys)
    assert "inconsistent directions" in err and "bad.json" in err

    assert main(["handeye", _write(tmp_path, good), "--method", "magic"]) == 2


def test_file_errors_name_the_field() -> None:
    from cpc2urdf.identification.handeye.pose_file import handeye_poses_from_json

    with pytest.raises(InputFileError, match=r"records\[0\] lacks 'T_camera_target'"):
        handeye_poses_from_json(
            {
                "format": HANDEYE_POSES_FORMAT,
                "records": [{"T_base_hand": {"matrix": np.eye(4).tolist()}}],
            },
            "f.json",
        )
    with pytest.raises(InputFileError, match="non-empty list"):
        handeye_poses_from_json({"format": HANDEYE_POSES_FORMAT, "records": []}, "f.json")


def test_cli_writes_camera_frame_into_model(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from cpc2urdf.files.model_file import save_model
    from cpc2urdf.files.robot_ref import load_model
    from cpc2urdf.identification.handeye import stage2 as s2

    nominal = load_model("iis_head")
    truth = s2.perturb_cameras(nominal, np.random.default_rng(2))
    identified = save_model(truth.without_frames(["camera"]), tmp_path / "identified.json")
    r = s2.run_stage2(truth, truth, n_poses=5, pixel_noise=0.0, seed=1)
    poses = s2.write_pose_files(r, tmp_path)["camera_right_optical"]
    out = tmp_path / "calibrated.json"
    assert (
        main(
            [
                "handeye",
                str(poses),
                "--method",
                "park_martin",
                "--model",
                str(identified),
                "-o",
                str(out),
            ]
        )
        == 0
    )
    assert "wrote" in capsys.readouterr().out
    cal = load_model(out)
    assert cal.structure.frame("camera_right_optical").kind == "camera"
    assert (
        np.abs(
            cal.frames["camera_right_optical"].matrix()
            - truth.frames["camera_right_optical"].matrix()
        ).max()
        < 1e-8
    )
    assert cal.metadata.handeye["camera_right_optical"].method == "park_martin"

    bad = tmp_path / "bad_out.json"
    for argv in (
        ["--model", str(identified)],  # no -o
        ["--model", str(identified), "-o", str(bad), "--method", "all"],
        ["--model", str(identified), "-o", str(bad), "--hand", "nope"],
        ["--model", str(identified), "-o", str(bad), "--camera", "plate_left"],
    ):
        _run_bad(["handeye", str(poses), *argv], capsys)
        assert not bad.exists()


def test_cli_all_reports_a_refusing_solver(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import math

    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(3)
    X, Z, H, _ = make_data(rng, 6)
    H[4, :3, :3] = Rotation.from_rotvec(np.array([0.6, 0.0, 0.8]) * math.radians(179.8)).as_matrix()
    C = inverse(X)[None] @ inverse(H) @ Z[None]
    path = tmp_path / "p.json"
    save_handeye_poses(path, H, C)
    assert main(["handeye", str(path), "--method", "all"]) == 0
    out = capsys.readouterr().out
    assert "zhuang           refused: quaternion method" in out
    assert main(["handeye", str(path), "--method", "zhuang"]) == 2
    assert "180 deg" in capsys.readouterr().err
