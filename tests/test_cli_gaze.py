"""`cpc2urdf gaze`: exit codes 0 (fixated) / 1 (unreachable) / 2 (bad input), JSON output."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cpc2urdf.cli import gaze as cli_gaze
from cpc2urdf.cli import main
from cpc2urdf.robot_ref import load_model
from cpc2urdf.tolerances import GAZE_POINTING_TOL
from cpc2urdf.urdf import write_urdf
from cpc2urdf.validation import gaze

AHEAD = ["-0.6", "-0.6", "0.7"]


def test_constants_match_the_solver():
    assert cli_gaze.POLICIES == gaze.POLICIES
    assert cli_gaze.DEFAULT_CAMERAS == gaze.DEFAULT_CAMERAS
    assert cli_gaze.DEFAULT_VIEWING_DISTANCE == gaze.DEFAULT_VIEWING_DISTANCE


def test_fixates_shipped_head_json(capsys):
    assert main(["gaze", "iis_head", "--target", *AHEAD, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["reachable"] and out["status"] == "fixated"
    assert max(out["pointing_error_rad"].values()) < GAZE_POINTING_TOL
    assert np.allclose(out["fixation_point"], [-0.6, -0.6, 0.7], atol=1e-9)


def test_urdf_file_and_policies(tmp_path, capsys):
    path = write_urdf(load_model("iis_head"), tmp_path / "head.urdf")
    for policy in ("cyclopean", "min-motion", "use-table"):
        assert main(["gaze", str(path), "--target", *AHEAD, "--policy", policy]) == 0, policy
        assert "fixated" in capsys.readouterr().out
    q = ["0.5", "0.25", "1.6", "0.03", "0.7", "0.86"]
    assert main(["gaze", str(path), "--target", *AHEAD, "--policy", "min-motion", "--q-current", *q]) == 0


def test_unreachable_exit_1(capsys):
    assert main(["gaze", "iis_head", "--target", "-0.6", "0.8", "0.7"]) == 1
    out = capsys.readouterr().out
    assert "fixated" not in out.splitlines()[0]
    assert "pointing error" in out


@pytest.mark.parametrize(
    "argv",
    [
        ["gaze", "no_such_head", "--target", "1", "2", "3"],
        ["gaze", "missing.urdf", "--target", "1", "2", "3"],
        ["gaze", "iis_head", "--target", "1", "nan", "3"],
        ["gaze", "iis_head", "--target", "1", "2"],
        ["gaze", "iis_head", "--target", "1", "2", "3", "--q-current", "1", "2"],
        ["gaze", "iis_head", "--target", "1", "2", "3", "--q-current", "0", "0", "9", "0", "0", "0"],
        ["gaze", "iis_head", "--target", "1", "2", "3", "--policy", "nope"],
        ["gaze", "iis_head", "--target", "1", "2", "3", "--cameras", "camera_left_optical", "nope"],
        ["gaze", "iis_head", "--target", "1", "2", "3", "--viewing-distance", "-1"],
    ],
)
def test_bad_input_exit_2(argv, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "error" in err


def test_bad_urdf_exit_2(tmp_path, capsys):
    bad = tmp_path / "bad.urdf"
    bad.write_text("<robot name='x'><link name='a'/><joint name='j' type='continuous'>")
    assert main(["gaze", str(bad), "--target", "1", "2", "3"]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1


def test_bench_gaze_runs_tiny(tmp_path, capsys):
    out = tmp_path / "bench.json"
    assert main(["bench", "gaze", "--targets", "5", "--json", str(out)]) == 0
    res = json.loads(out.read_text())
    for head in ("nominal", "calibrated"):
        r = res[head]  # every reachable target fixated, or answered with the head's disparity
        assert r["success"] + r.get("disparity", 0.0) == 1.0
        assert r["median_us"] > 0 and r["ratio"] > 0
    assert "kin us" in capsys.readouterr().out


def test_negative_and_huge_targets_parse(capsys):
    """``--target -1.7e308 0 0`` is a target, not an option; printed with its digits; JSON finite."""
    assert main(["gaze", "iis_head", "--target", "-1.7e308", "-0", "-1e-3", "--json"]) == 1
    out = json.loads(capsys.readouterr().out)
    assert out["target"] == [-1.7e308, -0.0, -1e-3]
    assert main(["gaze", "iis_head", "--target", "-0.612345678", "-0.6", "0.7"]) == 0
    assert "-0.612345678" in capsys.readouterr().out.splitlines()[0]
    assert main(["gaze", "iis_head", "--target", "-inf", "0", "0"]) == 2


def test_one_camera_and_joints(capsys):
    argv = ["gaze", "iis_head", "--target", *AHEAD, "--camera", "camera_left_optical", "--joints", "pan", "tilt", "vergence_left"]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "fixated" in out.splitlines()[0] and "pointing error:" in out
    assert main([*argv[:-3], "nope"]) == 2
    assert "nope" in capsys.readouterr().err
