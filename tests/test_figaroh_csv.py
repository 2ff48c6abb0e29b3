"""FIGAROH's calibration CSV (:mod:`cpc2urdf.files.figaroh_csv`) and ``cpc2urdf identify`` on it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cpc2urdf.cli import main
from cpc2urdf.errors import InputFileError
from cpc2urdf.files.figaroh_csv import load_figaroh_csv
from cpc2urdf.files.robot_ref import load_model
from cpc2urdf.studies.real_data import DATA
from cpc2urdf.transforms import matrix_from_rpy
from cpc2urdf.urdf.robot import load_urdf_robot

TIAGO = DATA / "tiago" / "tiago_48_schunk.urdf"
TIAGO_CSV = DATA / "tiago" / "qualysis_base_hand_calibration.csv"
UR10 = DATA / "ur10" / "ur10_robot.urdf"
UR10_CSV = DATA / "ur10" / "calibration.csv"


def test_markers_are_read_and_a_repeated_marker_is_dropped() -> None:
    ms = load_figaroh_csv(TIAGO_CSV, load_urdf_robot(TIAGO), "wrist_ft_tool_link")
    assert sorted(ms.markers) == ["m1", "m2", "m3"]  # marker 4 repeats marker 3 in every row
    assert ms.metadata["notes"] == [
        "torso_lift_joint: 1 reading(s) up to 0.184 mm past its URDF limits (accepted: within 1 mm / 1 deg)",
        "marker 4 repeats m3 in every row: dropped",
    ]
    first = TIAGO_CSV.read_text().splitlines()[1].split(",")
    assert np.allclose(ms.marker_points["m2"][0], [float(v) for v in first[3:6]])
    assert ms.structure.joint_names[0] == "torso_lift" and ms.q[0, 0] == float(first[12])


def test_six_d_poses_are_urdf_rpy() -> None:
    ms = load_figaroh_csv(UR10_CSV, load_urdf_robot(UR10), "tool0")
    row = [float(v) for v in UR10_CSV.read_text().splitlines()[1].split(",")]
    T = ms.poses["tool0"][0]
    assert np.allclose(T[:3, 3], row[:3])
    assert np.allclose(T[:3, :3], matrix_from_rpy(row[3:6]))


JOINTS = "torso_lift_joint," + ",".join(f"arm_{i}_joint" for i in range(1, 8))


@pytest.mark.parametrize(
    ("header", "row", "says"),
    [
        ("x1,y1,z1,bogus," + JOINTS, "0,0,0,1" + ",0.1" * 8, "column 'bogus' is neither"),
        (
            "x1,y1,z1," + JOINTS.replace(",arm_7_joint", ""),
            "0,0,0" + ",0.1" * 7,
            "no column for joint 'arm_7_joint'",
        ),
        ("x1,y1," + JOINTS, "0,0" + ",0.1" * 8, "point 1: columns ['x', 'y']"),
        (
            "x1,y1,z1," + JOINTS,
            "0,0,zero" + ",0.1" * 8,
            "row 2, column 'z1': 'zero' is not a number",
        ),
    ],
)
def test_bad_files_get_one_line(tmp_path: Path, header: str, row: str, says: str) -> None:
    p = tmp_path / "bad.csv"
    p.write_text(f"{header}\n{row}\n")
    with pytest.raises(InputFileError, match=says.replace("[", r"\[").replace("]", r"\]")):
        load_figaroh_csv(p, load_urdf_robot(TIAGO), "wrist_ft_tool_link")


def _edited(tmp_path: Path, column: int, row: int, add: float) -> Path:
    lines = TIAGO_CSV.read_text().splitlines()
    cells = lines[row].split(",")
    cells[column] = repr(float(cells[column]) + add)
    lines[row] = ",".join(cells)
    path = tmp_path / "edited.csv"
    path.write_text("\n".join(lines) + "\n")
    return path


def test_wrapped_readings_are_unwrapped_and_far_ones_refused(tmp_path: Path) -> None:
    robot = load_urdf_robot(TIAGO)
    clean = load_figaroh_csv(TIAGO_CSV, robot, "wrist_ft_tool_link")
    wrapped = load_figaroh_csv(
        _edited(tmp_path, 13, 3, 2 * np.pi), robot, "wrist_ft_tool_link"
    )  # arm_1_joint
    assert np.allclose(wrapped.q, clean.q)
    assert (
        "arm_1_joint: 1 reading(s) wrapped by a multiple of 360 deg into its limits"
        in wrapped.metadata["notes"]
    )
    with pytest.raises(
        InputFileError, match=r"row 3, column 'torso_lift_joint': .* outside the URDF limits"
    ):
        load_figaroh_csv(_edited(tmp_path, 12, 2, 0.5), robot, "wrist_ft_tool_link")


def test_identify_calibrates_about_the_urdf_and_writes_it_back(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "tiago.json"
    assert (
        main(
            [
                "identify",
                str(TIAGO_CSV),
                "--robot",
                str(TIAGO),
                "--link",
                "wrist_ft_tool_link",
                "-o",
                str(out),
            ]
        )
        == 0
    )
    text = capsys.readouterr().out
    assert "chosen: geometry" in text and "marker 4 repeats m3" in text
    model = load_model(out)
    assert model.metadata.provenance is not None and model.metadata.provenance.method == "map"
    urdf = tmp_path / "tiago.urdf"
    assert main(["export", str(out), "-o", str(urdf)]) == 0
    from cpc2urdf.urdf.tree import read_urdf_tree

    before, after = read_urdf_tree(TIAGO), read_urdf_tree(urdf)
    changed = {
        j
        for j in before.joints
        if before.joints[j].xyz != after.joints[j].xyz
        or before.joints[j].rpy != after.joints[j].rpy
    }
    assert changed and changed <= {"torso_lift_joint", *(f"arm_{i}_joint" for i in range(1, 8))}
    pose_before, pose_after = before.fk(), after.fk()
    for link in before.links:  # links whose path holds no changed joint stay where they were
        if not {j.name for j in before.path(link)} & changed:
            assert np.abs(pose_before[link] - pose_after[link]).max() < 1e-12, link


def test_identify_says_when_the_urdf_is_as_good(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Markers made from the URDF itself, 1 mm noise: nothing beats it; exit code 3, model written."""
    robot = load_urdf_robot(TIAGO)
    ms = load_figaroh_csv(TIAGO_CSV, robot, "wrist_ft_tool_link")
    model = ms.spec.nominal_model()
    T = model.fk(ms.q, ["wrist_ft_tool"])["wrist_ft_tool"]
    rng = np.random.default_rng(1)
    lines = ["x1,y1,z1," + ",".join(robot.names.urdf_joint(j) for j in ms.structure.joint_names)]
    for i, q in enumerate(ms.q):
        p = T[i, :3, :3] @ [0.05, 0.02, 0.1] + T[i, :3, 3] + rng.normal(0, 1e-3, 3)
        lines.append(",".join(f"{v:.9f}" for v in (*p, *q)))
    csv = tmp_path / "urdf_made.csv"
    csv.write_text("\n".join(lines) + "\n")
    out = tmp_path / "m.json"
    assert (
        main(
            [
                "identify",
                str(csv),
                "--robot",
                str(TIAGO),
                "--link",
                "wrist_ft_tool_link",
                "-o",
                str(out),
            ]
        )
        == 3
    )
    assert (
        "no calibration predicts left-out records better than the URDF" in capsys.readouterr().out
    )
    assert out.exists()


@pytest.mark.parametrize(
    ("lower", "upper", "reading", "expected"),
    [
        (-np.pi, np.pi, 3.5, 3.5 - 2 * np.pi),  # less than half a turn past the upper limit
        (-np.pi, np.pi, 5.0, 5.0 - 2 * np.pi),
        (0.0, 2 * np.pi, -0.5, 2 * np.pi - 0.5),
        (-2.0, 2.0, 2.0 + 4 * np.pi, 2.0),  # two turns
    ],
)
def test_readings_are_unwrapped_by_the_fewest_turns(
    lower: float, upper: float, reading: float, expected: float
) -> None:
    from cpc2urdf.files.figaroh_csv import _within_limits
    from cpc2urdf.model import Joint

    q, notes = _within_limits(
        np.array([0.0, reading]),
        Joint("j", "revolute", "base", lower, upper),
        "j",
        Path("x.csv"),
        [2, 3],
    )
    assert q[1] == pytest.approx(expected, abs=1e-12) and q[0] == 0.0
    assert notes == ["j: 1 reading(s) wrapped by a multiple of 360 deg into its limits"]


def test_a_short_row_is_named(tmp_path: Path) -> None:
    lines = TIAGO_CSV.read_text().splitlines()
    lines[4] = ",".join(lines[4].split(",")[:-1])
    path = tmp_path / "short.csv"
    path.write_text("\n".join(lines[:3] + [""] + lines[3:]) + "\n")  # a blank line is passed over
    with pytest.raises(InputFileError, match=r"row 6: 19 cells, the header has 20"):
        load_figaroh_csv(path, load_urdf_robot(TIAGO), "wrist_ft_tool_link")


@pytest.mark.parametrize(
    ("args", "code", "says"),
    [
        (["--joints", ","], 2, "--joints: name at least one joint"),
        (["--noise", "1"], 2, "the data are frame poses; give their orientation noise too"),
        (["--level", "frames"], 0, "chosen: frames"),
    ],
)
def test_identify_options(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str], code: int, says: str
) -> None:
    out = tmp_path / "u.json"
    assert (
        main(
            [
                "identify",
                str(UR10_CSV),
                "--robot",
                str(UR10),
                "--link",
                "tool0",
                "-o",
                str(out),
                *args,
            ]
        )
        == code
    )
    captured = capsys.readouterr()
    assert says in captured.out + captured.err
    assert out.exists() == (code == 0)
    if code == 2:
        assert len(captured.err.strip().splitlines()) == 1 and "Traceback" not in captured.err
