"""`cpc2urdf gaze`: exit codes 0 (fixated) / 1 (unreachable) / 2 (bad input), JSON output."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from gaze_heads import model_pointing_errors

from cpc2urdf.cli import gaze as cli_gaze
from cpc2urdf.cli import main
from cpc2urdf.files.robot_ref import load_model
from cpc2urdf.tolerances import GAZE_POINTING_TOL
from cpc2urdf.urdf.document import write_urdf
from cpc2urdf.validation import gaze

AHEAD = ["-0.6", "-0.6", "0.7"]


def test_constants_match_the_solver():
    assert cli_gaze.POLICIES == gaze.POLICIES
    assert cli_gaze.DEFAULT_CAMERAS == gaze.DEFAULT_CAMERAS


def test_fixates_shipped_head_json(capsys):
    assert main(["gaze", "iis_head", "--target", *AHEAD, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["reachable"] and out["status"] == "fixated"
    assert max(out["pointing_error_rad"].values()) < GAZE_POINTING_TOL
    assert np.allclose(out["fixation_point"], [-0.6, -0.6, 0.7], atol=1e-9)


def test_urdf_file_and_policies(tmp_path, capsys):
    path = write_urdf(load_model("iis_head"), tmp_path / "head.urdf")
    for policy in ("cyclopean", "min-motion"):
        assert main(["gaze", str(path), "--target", *AHEAD, "--policy", policy]) == 0, policy
        assert "fixated" in capsys.readouterr().out
    q = ["0.5", "0.25", "1.6", "0.03", "0.7", "0.86"]
    assert (
        main(["gaze", str(path), "--target", *AHEAD, "--policy", "min-motion", "--q-current", *q])
        == 0
    )
    capsys.readouterr()


def test_q_current_by_name(capsys):
    """--q-current NAME=VALUE: the named joints at those readings, the others at the middle of
    their limits; the same answer as the full list in the solver's joint order."""
    from cpc2urdf.api import gaze_solver

    solver = gaze_solver("iis_head")
    q = solver.home.copy()
    q[solver.robot.joint_index("pan")] = 1.2
    argv = [
        "gaze",
        "iis_head",
        "--target",
        *AHEAD,
        "--policy",
        "eyes-only",
        "--json",
        "--q-current",
    ]
    assert main([*argv, "pan=1.2"]) in (0, 1)
    by_name = json.loads(capsys.readouterr().out)
    assert main([*argv, *map(repr, q.tolist())]) in (0, 1)
    by_order = json.loads(capsys.readouterr().out)
    assert by_name == by_order
    assert by_name["joints"]["pan"] == pytest.approx(1.2)  # eyes-only: the neck stays where it is


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
        [
            "gaze",
            "iis_head",
            "--target",
            "1",
            "2",
            "3",
            "--q-current",
            "0",
            "0",
            "9",
            "0",
            "0",
            "0",
        ],
        ["gaze", "iis_head", "--target", "1", "2", "3", "--policy", "nope"],
        ["gaze", "iis_head", "--target", "1", "2", "3", "--cameras", "camera_left_optical", "nope"],
        ["gaze", "iis_head", "--target", "1", "2", "3", "--focal-px", "0"],
        ["gaze", "iis_head", "--target", "1", "2", "3", "--tolerance", "nan"],
        ["gaze", "iis_head", "--target", "1", "2", "3", "--tolerance", "1e-3", "--focal-px", "500"],
        ["gaze", "iis_head", "--target", "1", "2", "3", "--min-distance", "-0.1"],
        ["gaze", "iis_head", "--target", "1", "2", "3", "--min-distance", "nan"],
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
    argv = [
        "gaze",
        "iis_head",
        "--target",
        *AHEAD,
        "--camera",
        "camera_left_optical",
        "--joints",
        "pan",
        "tilt",
        "vergence_left",
    ]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "fixated" in out.splitlines()[0] and "pointing error:" in out
    assert main([*argv[:-3], "nope"]) == 2
    assert "nope" in capsys.readouterr().err
    assert (
        main([*argv, "--min-distance", "0"]) == 0
    )  # no minimum viewing distance: same answer ahead
    assert capsys.readouterr().out == out


def test_report_of_the_head_alone(capsys):
    """--report without a target: the head's kind and whether its eyes can fixate exactly, exit 0;
    with --json the same as data; with neither --target nor --report: bad input."""
    assert main(["gaze", "iis_head", "--report"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("gaze head (camera_left_optical, camera_right_optical): binocular")
    assert (
        "the two eyes' axes can meet exactly: 200 of 200 targets 0.4-3 m ahead fixated" in out[1]
        and len(out) == 2
    )
    assert main(["gaze", "iis_head", "--report", "--json"]) == 0
    head = json.loads(capsys.readouterr().out)["head"]
    assert head["kind"] == "binocular" and head["exact"] is True
    assert head["disparity"]["max_rad"] < 1e-9 and head["disparity"]["targets"] == 200
    assert main(["gaze", "iis_head"]) == 2
    assert "--report" in capsys.readouterr().err


def test_report_of_a_calibrated_head_names_its_disparity(tmp_path, capsys):
    """A calibrated IIS-head (eyes mounted a little off): cannot fixate exactly, its vertical
    disparity reported once (median and max over the workspace ahead), then the solution."""
    from cpc2urdf.files.model_file import save_model
    from cpc2urdf.identification.simulation.heads import calibrated_iis_head
    from cpc2urdf.validation.gaze import GazeSolver

    model = calibrated_iis_head(0)
    path = save_model(model, tmp_path / "calibrated.json")
    assert main(["gaze", str(path), "--report", "--target", "0.1", "-0.4", "0.8", "--json"]) == 1
    data = json.loads(capsys.readouterr().out)
    head, sol = data["head"], data["solution"]
    assert head["exact"] is False and sol["status"] == "disparity"
    expected = GazeSolver.from_model(model).disparity_report(200, 0)
    assert head["disparity"]["median_rad"] == pytest.approx(expected["median_rad"], rel=1e-9)
    assert 1e-4 < head["disparity"]["median_rad"] <= head["disparity"]["max_rad"] < 0.05
    assert main(["gaze", str(path), "--report"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].endswith(
        "moving pan, tilt, vergence_left, vergence_right"
    )  # what the solver moves: not the table
    assert (
        "meet only on a curve (vertical disparity): with the head facing the target (cyclopean policy)"
        in out[1]
    )
    assert (
        "over 200 of 200 targets 0.4-3 m ahead (200 answered with status disparity, 0 within the tolerance)"
        in out[1]
    )
    # the head can still fixate exactly, turned away from the target: said, and checked on the CPC model's FK
    assert (
        "fixation alone (policy min-motion) fixates" in out[2]
        and "from the facing posture" in out[2]
    )
    assert main(["gaze", str(path), "--report", "--json"]) == 0
    alone = json.loads(capsys.readouterr().out)["head"]["fixation_alone"]
    assert alone["fixated"] >= 150 and alone["turn_median_rad"] > math.radians(5.0)
    solver = GazeSolver.from_model(model)
    P = solver.ahead_targets(200, 0)[:5]
    Q = np.array([solver.solve(p, policy="min-motion").q for p in P])
    assert np.max(model_pointing_errors(model, Q, P)) < 1e-9
    # the report follows the tolerance: every target within 0.01 rad counts as fixated
    assert main(["gaze", str(path), "--report", "--tolerance", "0.01"]) == 0
    assert "(0 answered with status disparity, 200 within the tolerance)" in capsys.readouterr().out
    # the same joints named: the compiled solver alone, no min-motion of its own to compare with
    assert (
        main(
            [
                "gaze",
                str(path),
                "--report",
                "--json",
                "--joints",
                "pan",
                "tilt",
                "vergence_left",
                "vergence_right",
            ]
        )
        == 0
    )
    assert "fixation_alone" not in json.loads(capsys.readouterr().out)["head"]
    # the eyes alone point at none of the targets ahead: no claim about exactness
    assert main(["gaze", str(path), "--report", "--joints", "vergence_left", "vergence_right"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert (
        out[1]
        == "  none of 200 targets 0.4-3 m ahead is pointed at with the moving joints (no_solution 200)"
    )


def test_text_output_lists_the_head_joints(capsys):
    """On a whole robot (TIAGo: 48 joints) the text answer lists the joints on the camera's path
    and counts the others; --json lists every joint."""
    from gaze_heads import ERD

    urdf = str(ERD / "tiago_description/robots/tiago.urdf")
    argv = ["gaze", urdf, "--camera", "xtion_rgb_optical_frame", "--target", "2", "0.3", "1.0"]
    assert main(argv) == 0
    out = capsys.readouterr().out
    listed = [
        line.split()[0]
        for line in out.splitlines()
        if line.startswith("  ") and not line.startswith("  (")
    ]
    assert set(listed) == {"torso_lift_joint", "head_1_joint", "head_2_joint"}, out
    assert "(45 other joints, off the cameras' paths" in out
    assert main([*argv, "--json"]) == 0
    assert len(json.loads(capsys.readouterr().out)["joints"]) == 48


def test_a_misspelt_camera_on_a_whole_robot_names_the_closest_frames(capsys):
    """TIAGo has 156 frames: the one line names the most alike, not all of them."""
    from gaze_heads import ERD

    urdf = str(ERD / "tiago_description/robots/tiago.urdf")
    assert main(["gaze", urdf, "--camera", "xtion_rgb_optical", "--target", "2", "0.3", "1.0"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and len(err) < 600, err
    assert (
        "unknown frame 'xtion_rgb_optical'; closest known frames: " in err
        and "xtion_rgb_optical_frame" in err
    )
    assert "(of 156)" in err


def test_a_urdf_not_named_urdf_is_read_as_one(tmp_path, capsys):
    """A URDF saved as .xml, or with no suffix, is read as a URDF (its text is XML), not refused
    as 'not valid JSON'; a .json file is still read as JSON."""
    text = write_urdf(load_model("iis_head"), tmp_path / "head.urdf").read_text()
    for name in ("head.xml", "head"):
        (tmp_path / name).write_text(text)
        assert main(["gaze", str(tmp_path / name), "--target", *AHEAD]) == 0, name
        assert "fixated" in capsys.readouterr().out
    (tmp_path / "head.json").write_text(text)
    assert main(["gaze", str(tmp_path / "head.json"), "--target", *AHEAD]) == 2
    assert "head.json: not valid JSON" in capsys.readouterr().err


@pytest.mark.parametrize("q", [["x"], ["pan=9"], ["neck=0.1"], ["0.5", "0.25"]])
def test_a_bad_q_current_is_refused_before_any_output(q, capsys):
    """With --report, a bad --q-current used to be refused after the report was printed."""
    assert main(["gaze", "iis_head", "--report", "--target", *AHEAD, "--q-current", *q]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and len(captured.err.strip().splitlines()) == 1
