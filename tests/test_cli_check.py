"""``cpc2urdf check`` (and ``gaze``) on URDFs that do not parse: exit 2 and one line naming the file
and the element, nothing from urdfdom, Pinocchio or yourdfpy on the terminal; exit 1 (a report)
only for a URDF that parses but disagrees with the model."""

from __future__ import annotations

import os
import re
import stat
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

from cpc2urdf.cli import main
from cpc2urdf.files.robot_ref import load_model
from cpc2urdf.urdf.document import urdf_from_model

HEAD = urdf_from_model(load_model("iis_head"))
# What urdfdom (console_bridge), check_urdf and yourdfpy print themselves.
NATIVE = re.compile(
    r"Error:|at line \d+ in|Using different parsing approach|Successfully Parsed|Document is empty"
)


def _visual_origin(value: str) -> str:
    vis = HEAD.index('<visual name="table_x_axis">')
    origin = HEAD.index('<origin xyz="0 0 0"', vis)
    return HEAD[:origin] + f'<origin xyz="{value}"' + HEAD[origin + len('<origin xyz="0 0 0"') :]


def _in_joint(name: str, old: str, new: str) -> str:
    i = HEAD.index(f'<joint name="{name}"')
    j = HEAD.index("</joint>", i)
    assert old in HEAD[i:j]
    return HEAD[:i] + HEAD[i:j].replace(old, new, 1) + HEAD[j:]


BAD: dict[str, tuple[Callable[[], str | bytes], str]] = {
    "not_xml": (
        lambda: "this is not a URDF",
        "not well-formed XML (syntax error: line 1, column 0)",
    ),
    "empty": (lambda: "", "is empty, expected a URDF file"),
    "binary": (
        lambda: b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR",
        "is a binary file, expected a URDF file",
    ),
    "truncated": (lambda: HEAD[: len(HEAD) // 2], "not well-formed XML ("),
    "utf16": (lambda: HEAD.encode("utf-16"), "is UTF-16 text, expected a URDF file in UTF-8"),
    "missing_link": (
        lambda: HEAD.replace('<parent link="table_x_link"/>', '<parent link="nope"/>'),
        "joint 'table_y': parent link 'nope' is not a link of this URDF",
    ),
    "nan_visual_origin": (
        lambda: _visual_origin("nan 0 0"),
        "link 'table_x_link': visual 'table_x_axis' origin xyz 'nan 0 0' is not finite",
    ),
    "inf_joint_origin": (
        lambda: _in_joint("pan", '<origin xyz="', '<origin xyz="inf 0 0" old="'),
        "joint 'pan': origin xyz 'inf 0 0' is not finite",
    ),
    "overflowing_limit": (
        lambda: _in_joint("tilt", 'upper="', 'upper="1e999" old="'),
        "joint 'tilt': limit upper '1e999' is not finite",
    ),
    "nan_axis": (
        lambda: _in_joint("pan", '<axis xyz="', '<axis xyz="nan 0 1" old="'),
        "joint 'pan': axis xyz 'nan 0 1' is not finite",
    ),
    "nan_box": (
        lambda: HEAD.replace('<box size="0.12 0.12 0.01"/>', '<box size="0.12 0.12 -nan"/>'),
        "link 'base': visual 'base_plate' geometry box size '0.12 0.12 -nan' is not finite",
    ),
    "nan_color": (
        lambda: HEAD.replace('rgba="0.55 0.55 0.55 1.0"', 'rgba="0.55 0.55 0.55 NaN"'),
        "material 'cpc2urdf_base': color rgba '0.55 0.55 0.55 NaN' is not finite",
    ),
    "nan_inertia": (
        lambda: HEAD.replace(
            '<link name="base">',
            '<link name="base"><inertial><mass value="nan"/>'
            '<inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial>',
        ),
        "link 'base': inertial mass value 'nan' is not finite",
    ),
    "zero_axis": (
        lambda: _in_joint("pan", '<axis xyz="', '<axis xyz="0 0 0" old="'),
        "joint 'pan': axis xyz '0 0 0' is zero",
    ),
    "no_limit": (
        lambda: _in_joint("pan", "<limit ", "<nolimit "),
        "joint 'pan' is revolute but has no <limit>",
    ),
    "unknown_type": (
        lambda: _in_joint("pan", 'type="revolute"', 'type="hinge"'),
        "joint 'pan': type 'hinge' is not a URDF joint type",
    ),
    "duplicate_link": (
        lambda: HEAD.replace('<link name="world"/>', '<link name="world"/><link name="world"/>'),
        "link 'world' is defined twice",
    ),
    "two_roots": (
        lambda: HEAD.replace("</robot>", '<link name="lonely"/></robot>'),
        "links 'world', 'lonely' are all roots",
    ),
    "cycle": (
        lambda: HEAD.replace(
            "</robot>",
            '<joint name="b" type="fixed"><parent link="pan_link"/><child link="world"/></joint></robot>',
        ),
        "form a cycle; a URDF is a tree",
    ),
    "capsule": (
        lambda: HEAD.replace('<box size="0.12 0.12 0.01"/>', '<capsule radius="1" length="1"/>'),
        "link 'base': visual 'base_plate' geometry <capsule> is not a URDF shape",
    ),
    "entity": (
        lambda: HEAD.replace("<robot ", '<!DOCTYPE robot [<!ENTITY a "1">]>\n<robot ', 1),
        "declares the XML entity 'a'",
    ),
    "xacro": (
        lambda: _in_joint("pan", '<origin xyz="', '<origin xyz="${x} 0 0" old="'),
        "joint 'pan': origin xyz '${x} 0 0' is not 3 numbers (an unexpanded xacro expression? run xacro first)",
    ),
    "root": (
        lambda: '<sdf version="1.6"><model name="m"/></sdf>',
        "the root element is <sdf>, expected <robot>",
    ),
}


def _write(path: Path, content: str | bytes) -> None:
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(content, encoding="utf-8")


def _one_line(capfd: pytest.CaptureFixture[str], command: str, path: Path, expected: str) -> str:
    cap = capfd.readouterr()
    assert cap.out == "", cap.out
    err = cap.err.splitlines()
    assert len(err) == 1, cap.err
    assert err[0].startswith(f"cpc2urdf {command}: error: {path}: ") and expected in err[0], err[0]
    assert "Traceback" not in cap.err and not NATIVE.search(cap.err), cap.err
    return err[0]


@pytest.mark.parametrize("case", list(BAD))
def test_check_refuses_a_urdf_that_does_not_parse(
    tmp_path: Path, capfd: pytest.CaptureFixture[str], case: str
) -> None:
    make, expected = BAD[case]
    path = tmp_path / "head.urdf"
    _write(path, make())
    before = sorted(tmp_path.iterdir())
    assert main(["check", str(path), "--model", "iis_head", "-n", "3"]) == 2
    _one_line(capfd, "check", path, expected)
    assert sorted(tmp_path.iterdir()) == before


def test_check_names_a_folder_given_as_the_urdf(
    tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    folder = tmp_path / "head.urdf"
    folder.mkdir()
    assert main(["check", str(folder), "--model", "iis_head"]) == 2
    _one_line(capfd, "check", folder, "is a folder, expected a URDF file")


@pytest.mark.parametrize("case", ["not_xml", "nan_visual_origin", "missing_link", "zero_axis"])
def test_gaze_refuses_the_same_urdfs_in_one_line(
    tmp_path: Path, capfd: pytest.CaptureFixture[str], case: str
) -> None:
    make, expected = BAD[case]
    path = tmp_path / "bad.urdf"
    _write(path, make())
    assert main(["gaze", str(path), "--target", "0", "0", "1"]) == 2
    _one_line(capfd, "gaze", path, expected)


def test_a_urdf_that_parses_but_disagrees_is_a_discrepancy(
    tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "head.urdf"
    path.write_text(_in_joint("pan", 'type="revolute"', 'type="continuous"'))
    assert main(["check", str(path), "--model", "iis_head", "-n", "3"]) == 1
    cap = capfd.readouterr()
    assert (
        "joint 'pan' is continuous, expected revolute or prismatic" in cap.out
        and "result: DISCREPANCY" in cap.out
    )
    assert cap.err == "" and not NATIVE.search(cap.out)
    # A URDF without the "world" link the poses are taken from: a discrepancy, not a traceback.
    no_world = re.sub(
        r'<link name="world"/>\s*<joint name="base_joint".*?</joint>', "", HEAD, count=1, flags=re.S
    )
    path.write_text(no_world)
    assert main(["check", str(path), "--model", "iis_head", "-n", "3"]) == 1
    cap = capfd.readouterr()
    assert "frame 'world' missing" in cap.out and cap.err == ""


def test_a_clean_urdf_still_passes_quietly(
    tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "head.urdf"
    path.write_text(HEAD)
    assert main(["check", str(path), "--model", "iis_head", "-n", "3"]) == 0
    cap = capfd.readouterr()
    assert "result: all parsers agree with the CPC model" in cap.out and cap.err == ""


# ---- a parser that still refuses a file the validation accepted: bad input, said in one line ----


def test_pinocchio_complaining_on_stderr_is_captured_and_refused(
    tmp_path: Path, capfd: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    import pinocchio as pin

    real = pin.buildModelFromXML

    def chatty(text: str) -> pin.Model:  # urdfdom reports an error on stderr and goes on
        os.write(
            2,
            b"Error:   Could not parse visual element for Link [base]\n         at line 537 in link.cpp\n",
        )
        return real(text)

    monkeypatch.setattr(pin, "buildModelFromXML", chatty)
    path = tmp_path / "head.urdf"
    path.write_text(HEAD)
    assert main(["check", str(path), "--model", "iis_head", "-n", "3"]) == 2
    line = _one_line(
        capfd,
        "check",
        path,
        "not a URDF Pinocchio can read (Could not parse visual element for Link [base])",
    )
    assert "at line 537" not in line


def test_yourdfpy_failing_is_bad_input(
    tmp_path: Path, capfd: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    import yourdfpy

    def broken(*args: object, **kwargs: object) -> None:
        print("Using different parsing approach.", file=sys.stderr)
        raise ValueError("cannot build the scene graph")

    monkeypatch.setattr(yourdfpy.URDF, "load", staticmethod(broken))
    path = tmp_path / "head.urdf"
    path.write_text(HEAD)
    assert main(["check", str(path), "--model", "iis_head", "-n", "3"]) == 2
    _one_line(capfd, "check", path, "yourdfpy cannot read it (cannot build the scene graph)")


@pytest.mark.parametrize("status", [1, 0])
def test_check_urdf_refusing_is_bad_input(
    tmp_path: Path, capfd: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, status: int
) -> None:
    from cpc2urdf.validation import crosscheck

    fake = tmp_path / "check_urdf"
    # exit 1, or exit 0 with "Successfully Parsed" after an error (urdfdom drops what it cannot read)
    fake.write_text(
        f"#!/bin/sh\necho 'Error:   Unknown geometry type' >&2\necho '         at line 342 in link.cpp' >&2\n"
        f"echo '---------- Successfully Parsed XML ---------------'\nexit {status}\n"
    )
    fake.chmod(fake.stat().st_mode | stat.S_IXUSR)
    monkeypatch.setattr(crosscheck, "check_urdfdom_executable", lambda: str(fake))
    path = tmp_path / "head.urdf"
    path.write_text(HEAD)
    assert main(["check", str(path), "--model", "iis_head", "-n", "3"]) == 2
    _one_line(capfd, "check", path, "urdfdom's check_urdf cannot read it (Unknown geometry type)")


# ---- a model identified from a user's URDF, against the URDF written back from it ----


@pytest.fixture(scope="module")
def tiago_written_back(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, Path]:
    """TIAGo with a plate (its URDF), the model identified from its head, and the calibrated
    URDF written back from that model."""
    from test_view_writeback import identified_tiago

    from cpc2urdf.urdf.writeback import write_calibrated_urdf

    folder = tmp_path_factory.mktemp("tiago_check")
    urdf, model, model_file = identified_tiago(folder)
    return urdf, model_file, write_calibrated_urdf(model, folder / "calibrated.urdf")


def _edit_origin(text: str, joint: str, dx: float) -> str:
    """``text`` with joint ``joint``'s origin moved by ``dx`` [m] along the parent's x."""
    i = text.index(f'<joint name="{joint}"')
    j = text.index("</joint>", i)
    m = re.search(r'xyz="(\S+) ', text[i:j])
    assert m is not None
    x = float(m.group(1))
    return text[:i] + text[i:j].replace(f'xyz="{m.group(1)} ', f'xyz="{x + dx!r} ', 1) + text[j:]


def test_written_back_urdf_agrees_with_its_model(
    tiago_written_back: tuple[Path, Path, Path], capfd: pytest.CaptureFixture[str]
) -> None:
    """Every link on the calibrated paths (links by TIAGo's own names) by Pinocchio and yourdfpy
    where the write-back plan puts it, to 1e-9, at random readings within the limits."""
    from cpc2urdf.api import check_urdf
    from cpc2urdf.tolerances import FK_AGREEMENT_TOL

    _, model_file, calibrated = tiago_written_back
    assert main(["check", str(calibrated), "--model", str(model_file), "-n", "20"]) == 0
    cap = capfd.readouterr()
    assert "7 links of the written-back URDF at 20 configurations" in cap.out
    assert "result: all parsers agree" in cap.out and cap.err == "" and not NATIVE.search(cap.out)
    report = check_urdf(model_file, calibrated, 20, seed=3)
    assert report.ok and report.frames == [
        "base_footprint",
        "base_link",
        "torso_fixed_link",
        "torso_lift_link",
        "head_1_link",
        "head_2_link",
        "calib_plate",
    ]
    fk = {p.parser: p for p in report.parsers if p.max_position_error is not None}
    assert set(fk) == {"pinocchio", "yourdfpy"}
    assert all(
        p.max_position_error < FK_AGREEMENT_TOL and p.max_rotation_error < FK_AGREEMENT_TOL
        for p in fk.values()
    )


def test_user_urdf_checks_against_itself(
    tiago_written_back: tuple[Path, Path, Path], capfd: pytest.CaptureFixture[str]
) -> None:
    """The URDF as its own nominal model: every link reachable from the root (79 on TIAGo)."""
    urdf, _, _ = tiago_written_back
    assert main(["check", str(urdf), "--model", str(urdf), "-n", "3"]) == 0
    assert "79 links of the written-back URDF" in capfd.readouterr().out


@pytest.mark.parametrize(
    ("joint", "named"),
    [
        (
            "head_2_joint",
            "link 'head_2_link' below joint 'head_2_joint'",
        ),  # calibrated: FK names the link
        (
            "torso_fixed_joint",
            "joint 'torso_fixed_joint' (line",
        ),  # folded into the model: the record names it
    ],
)
def test_a_millimetre_edit_is_a_discrepancy_naming_it(
    tiago_written_back: tuple[Path, Path, Path],
    tmp_path: Path,
    capfd: pytest.CaptureFixture[str],
    joint: str,
    named: str,
) -> None:
    _, model_file, calibrated = tiago_written_back
    edited = tmp_path / "edited.urdf"
    edited.write_text(_edit_origin(calibrated.read_text(), joint, 1e-3))
    assert main(["check", str(edited), "--model", str(model_file), "-n", "5"]) == 1
    cap = capfd.readouterr()
    assert named in cap.out and "result: DISCREPANCY" in cap.out and cap.err == ""
    assert re.search(r"pinocchio\s+FAIL worst position 1\.000e-03 m", cap.out)


def test_uncalibrated_urdf_and_missing_link_are_discrepancies(
    tiago_written_back: tuple[Path, Path, Path], tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    urdf, model_file, _ = tiago_written_back
    assert (
        main(["check", str(urdf), "--model", str(model_file), "-n", "3"]) == 1
    )  # the user's own, not calibrated
    assert "link 'torso_lift_link' below joint 'torso_lift_joint'" in capfd.readouterr().out
    no_plate = tmp_path / "no_plate.urdf"
    no_plate.write_text(
        urdf.read_text()
        .replace('link name="calib_plate"', 'link name="calib_x"')
        .replace('child link="calib_plate"', 'child link="calib_x"')
    )
    assert main(["check", str(no_plate), "--model", str(model_file), "-n", "3"]) == 1
    cap = capfd.readouterr()
    assert "the model's frame 'calib_plate' is not a link of it" in cap.out and cap.err == ""


def test_written_back_small_robot_with_every_awkward_joint(
    tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    """urdf_cases.SMALL: a prismatic joint with a non-unit axis, a continuous one along -z without
    <origin>, a tilted revolute axis, two fixed joints to the marker, and floating and planar
    joints off its path (Pinocchio keeps those at their neutral configuration)."""
    import numpy as np
    from urdf_cases import SMALL, write

    from cpc2urdf.files.model_file import save_model
    from cpc2urdf.identification.simulation.truth import perturbed_model
    from cpc2urdf.urdf.robot import load_urdf_robot, urdf_source, with_urdf_source
    from cpc2urdf.urdf.writeback import write_calibrated_urdf

    nominal = load_urdf_robot(write(tmp_path, "small.urdf", SMALL), ["marker"]).nominal_model()
    model = with_urdf_source(
        perturbed_model(nominal, np.random.default_rng(1), 1e-3, 0.01), urdf_source(nominal)
    )
    model_file = save_model(model, tmp_path / "model.json")
    calibrated = write_calibrated_urdf(model, tmp_path / "calibrated.urdf")
    assert main(["check", str(calibrated), "--model", str(model_file), "-n", "10"]) == 0
    out = capfd.readouterr().out
    assert "6 links of the written-back URDF" in out and "result: all parsers agree" in out


# ---- with --gaze-report, a model with two camera frames is a gaze head: reported once ----


def test_check_builds_no_gaze_solver_unless_asked(
    tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    """Without --gaze-report, check neither reports the head nor imports the gaze solver (nothing
    compiled): run in a fresh interpreter, whose modules are then listed."""
    import subprocess
    import sys

    path = tmp_path / "head.urdf"
    path.write_text(HEAD)
    code = (
        "import sys; from cpc2urdf.cli import main; rc = main(['check', sys.argv[1], '--model', 'iis_head', '-n', '3']); "
        "print('GAZE' if any(m.startswith('cpc2urdf.validation.gaze') or m == 'numba' for m in sys.modules) else 'NONE'); "
        "sys.exit(rc)"
    )
    r = subprocess.run(
        [sys.executable, "-c", code, str(path)], capture_output=True, text=True, timeout=600
    )
    assert r.returncode == 0, r.stderr
    assert "gaze head" not in r.stdout and r.stdout.strip().endswith("NONE")


def test_check_reports_the_gaze_head(tmp_path: Path, capfd: pytest.CaptureFixture[str]) -> None:
    """The nominal IIS-head can fixate exactly; a calibrated one cannot, and says by how much
    (the solver's disparity report); the JSON carries the same under ``gaze_head``."""
    import json

    from cpc2urdf.files.model_file import save_model
    from cpc2urdf.identification.simulation.heads import calibrated_iis_head
    from cpc2urdf.urdf.document import write_urdf
    from cpc2urdf.validation.gaze import GazeSolver

    path = tmp_path / "head.urdf"
    path.write_text(HEAD)
    assert main(["check", str(path), "--model", "iis_head", "-n", "3", "--gaze-report"]) == 0
    out = capfd.readouterr().out
    assert "gaze head (camera_left_optical, camera_right_optical): binocular" in out
    assert "the two eyes' axes can meet exactly" in out
    model = calibrated_iis_head(0)
    mpath = save_model(model, tmp_path / "calibrated.json")
    upath = write_urdf(model, tmp_path / "calibrated.urdf")
    assert main(["check", str(upath), "--model", str(mpath), "-n", "3", "--gaze-report"]) == 0
    out = capfd.readouterr().out
    assert "the two eyes' axes meet only on a curve (vertical disparity)" in out
    assert "fixation alone (policy min-motion)" in out
    assert (
        main(["check", str(upath), "--model", str(mpath), "-n", "3", "--json", "--gaze-report"])
        == 0
    )
    head = json.loads(capfd.readouterr().out)["gaze_head"]
    expected = GazeSolver.from_model(model).disparity_report(200, 0)
    assert head["exact"] is False and head["disparity"]["max_rad"] == pytest.approx(
        expected["max_rad"], rel=1e-9
    )
