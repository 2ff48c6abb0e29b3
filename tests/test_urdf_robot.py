"""A user's URDF as the robot description: the CPC tree of a URDF (TIAGo's head, a small robot
with the awkward cases), its forward kinematics against Pinocchio's, the measured sub-tree read
from a measurement file, the model file's ``urdf`` section, and bad input named in one line."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from urdf_cases import SMALL, TIAGO_HEAD, pinocchio_poses, simulate, tiago_with_plate, write

from cpc2urdf.cli import main
from cpc2urdf.errors import InputFileError
from cpc2urdf.files.measurements import load_measurements, save_measurements
from cpc2urdf.files.model_file import model_from_json, model_to_json
from cpc2urdf.files.robot_ref import load_model, load_robot
from cpc2urdf.urdf.robot import NameMap, UrdfRobot, load_urdf_robot, urdf_source
from cpc2urdf.urdf.tree import read_urdf_tree

EXACT = 1e-12  # [m] and [-]: the mapping is exact; only rounding differs


def _line(text: str, tag: str) -> int:
    """Line number of ``tag`` in ``text``."""
    return text[: text.index(tag)].count("\n") + 1


FLOAT_LINE = _line(SMALL, '<joint name="float_joint"')
HEAD_LINE = _line(SMALL, '<joint name="head_joint"')


@pytest.fixture(scope="module")
def tiago(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tiago_with_plate(tmp_path_factory.mktemp("tiago"))


@pytest.fixture(scope="module")
def small(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write(tmp_path_factory.mktemp("small"), "small.urdf", SMALL)


def _readings(robot: UrdfRobot, q: np.ndarray) -> dict[str, float]:
    assert robot.names is not None
    return {
        robot.names.urdf_joint(n): float(v)
        for n, v in zip(robot.structure.joint_names, q, strict=True)
    }


def test_a_urdf_path_is_a_robot_everywhere(tiago: Path) -> None:
    robot = load_robot(str(tiago))
    assert isinstance(robot, UrdfRobot) and robot.measured is None
    assert load_model(tiago).structure.joint_names == robot.structure.joint_names
    source = urdf_source(robot.nominal_model())
    assert (
        source is not None
        and source.path == str(tiago.resolve())
        and source.root == "base_footprint"
    )


def test_measured_subtree_of_tiago_head(tiago: Path) -> None:
    robot = load_urdf_robot(tiago, ["calib_plate"])
    s = robot.structure
    assert [robot.names.urdf_joint(n) for n in s.joint_names] == list(TIAGO_HEAD)  # type: ignore[union-attr]
    assert [(j.name, j.type, j.parent) for j in s.joints] == [
        ("torso_lift", "prismatic", "base"),
        ("head_1", "revolute", "torso_lift"),
        ("head_2", "revolute", "head_1"),
    ]
    assert s.frame_names == ("calib_plate",) and s.frame("calib_plate").parent == "head_2"
    head_2 = read_urdf_tree(tiago).joints["head_2_joint"]
    assert (s.joint("head_2").lower, s.joint("head_2").upper) == (head_2.lower, head_2.upper)


def test_nominal_forward_kinematics_is_pinocchios(tiago: Path) -> None:
    """Every link the model covers, whole robot and measured sub-tree, where urdfdom puts it."""
    rng = np.random.default_rng(0)
    for robot in (load_urdf_robot(tiago), load_urdf_robot(tiago, ["calib_plate"])):
        model, names = robot.nominal_model(), robot.names
        assert names is not None
        s = model.structure
        for q in rng.uniform(s.lower, s.upper, (3, s.n_joints)):
            links = [names.urdf_link(f) for f in s.frame_names]
            ref = pinocchio_poses(tiago, _readings(robot, q), links)
            T = model.fk(q)
            assert max(np.abs(T[f] - ref[names.urdf_link(f)]).max() for f in s.frame_names) < EXACT


def test_awkward_axes_and_joint_types(small: Path) -> None:
    """A non-unit prismatic axis, a continuous joint along -z with no origin, a tilted axis, two
    fixed joints folded in, floating and planar joints off the path."""
    robot = load_urdf_robot(small, ["marker"])
    s = robot.structure
    # turret_joint and head_joint lose the suffix; "turret" and "head" are links' (legal) names
    assert s.joint_names == ("slide", "turret_axis", "head_axis")
    turret = s.joint("turret_axis")
    assert (turret.type, turret.lower, turret.upper) == ("revolute", -math.pi, math.pi)
    rng = np.random.default_rng(1)
    for q in rng.uniform(s.lower, s.upper, (5, 3)):
        ref = pinocchio_poses(small, _readings(robot, q), ["marker"])["marker"]
        assert np.abs(robot.nominal_model().fk(q, ["marker"])["marker"] - ref).max() < EXACT


def test_names_keep_what_is_legal_and_never_clash(tiago: Path) -> None:
    names = NameMap.of(read_urdf_tree(tiago))
    assert names.joints["head_1_joint"] == "head_1" and names.links["calib_plate"] == "calib_plate"
    assert names.links["head_1_link"] == "head_1_frame"  # "head_1" is the joint's
    assert names.links["base_link"] == "base_frame"  # "base" is reserved
    assert names.links["xtion_rgb_optical_frame"] == "xtion_rgb_optical_frame"
    every = list(names.joints.values()) + list(names.links.values())
    assert len(set(every)) == len(every)


def test_measurement_file_needs_only_the_joints_on_the_path(tiago: Path, tmp_path: Path) -> None:
    robot = load_urdf_robot(tiago, ["calib_plate"])
    simulate(robot, np.random.default_rng(2), tmp_path / "m.json", M=3)
    doc = json.loads((tmp_path / "m.json").read_text())
    assert set(doc["records"][0]["joints"]) == set(TIAGO_HEAD) and set(
        doc["records"][0]["poses"]
    ) == {"calib_plate"}
    (tmp_path / "tiago_plate.urdf").write_text(tiago.read_text())
    doc["records"][0]["joints"]["arm_1_joint"] = (
        0.3  # a whole /joint_states: other joints are ignored
    )
    (tmp_path / "m.json").write_text(json.dumps(doc))
    ms = load_measurements(tmp_path / "m.json")
    assert isinstance(ms.spec, UrdfRobot) and ms.structure.joint_names == (
        "torso_lift",
        "head_1",
        "head_2",
    )
    save_measurements(ms, tmp_path / "again.json")
    again = json.loads((tmp_path / "again.json").read_text())
    assert set(again["records"][0]["joints"]) == set(TIAGO_HEAD)
    np.testing.assert_array_equal(load_measurements(tmp_path / "again.json").q, ms.q)


def test_model_file_keeps_the_urdf_section(tiago: Path) -> None:
    model = load_urdf_robot(tiago, ["calib_plate"]).nominal_model()
    doc = json.loads(json.dumps(model_to_json(model)))
    assert doc["urdf"]["root"] == "base_footprint"
    assert {e["urdf"] for e in doc["urdf"]["joints"]} == set(TIAGO_HEAD)
    back = model_from_json(doc, "m.json")
    assert urdf_source(back) == urdf_source(model)
    del doc["urdf"]
    assert urdf_source(model_from_json(doc, "m.json")) is None  # old files still read


@pytest.mark.parametrize(
    ("links", "message"),
    [
        (["nope"], "no link 'nope' (a measured link)"),
        (
            ["floater"],
            f"joint 'float_joint' (floating, line {FLOAT_LINE}) is on the path from the root link 'base_link' "
            "to the measured link 'floater'",
        ),
        (["planar_thing"], "joint 'planar_joint' (planar"),
        (
            ["head"],
            f"measured link 'head' is moved by joint 'head_joint' (revolute, line {HEAD_LINE}) directly",
        ),
        (["base_link"], "link 'base_link' is the root of the tree"),
    ],
)
def test_links_that_cannot_be_measured_are_named(
    small: Path, links: list[str], message: str
) -> None:
    with pytest.raises(InputFileError) as e:
        load_urdf_robot(small, links)
    assert (
        str(e.value).startswith(f"{small}: ")
        and message in str(e.value)
        and "\n" not in str(e.value)
    )


def _identify_cli(tmp_path: Path, doc: dict, capsys: pytest.CaptureFixture[str]) -> str:
    (tmp_path / "m.json").write_text(json.dumps(doc))
    out = tmp_path / "model.json"
    assert main(["identify", str(tmp_path / "m.json"), "-o", str(out)]) == 2
    assert not out.exists()
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    return err


def test_bad_urdf_input_to_identify_is_one_line_exit_2(
    small: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    urdf = write(tmp_path, "small.urdf", SMALL)
    robot = load_urdf_robot(urdf, ["marker"])
    simulate(robot, np.random.default_rng(3), tmp_path / "m.json", M=3)
    doc = json.loads((tmp_path / "m.json").read_text())
    bad = json.loads(json.dumps(doc))
    bad["records"][1]["poses"]["markr"] = bad["records"][1]["poses"]["marker"]
    assert "m.json: records[1].poses: 'markr' is not a link of" in _identify_cli(
        tmp_path, bad, capsys
    )
    bad = json.loads(json.dumps(doc))
    bad["records"][0]["poses"]["floater"] = bad["records"][0]["poses"]["marker"]
    assert f"joint 'float_joint' (floating, line {FLOAT_LINE}) is on the path" in _identify_cli(
        tmp_path, bad, capsys
    )
    bad = json.loads(json.dumps(doc))
    del bad["records"][2]["joints"]["head_joint"]
    assert "records[2].joints lacks ['head_joint']" in _identify_cli(tmp_path, bad, capsys)
    bad = json.loads(json.dumps(doc))
    bad["records"][0]["joints"]["neck"] = 0.0
    assert "records[0].joints: unknown joint 'neck'" in _identify_cli(tmp_path, bad, capsys)
    urdf.write_text(
        SMALL.replace(
            '<joint name="slide" type="prismatic">', '<joint name="slide" type="prismatic"'
        )
    )
    err = _identify_cli(tmp_path, doc, capsys)
    assert "m.json: robot 'small.urdf':" in err and "small.urdf: not well-formed XML" in err
