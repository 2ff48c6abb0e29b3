"""Identification of a URDF's measured sub-tree (TIAGo's head) and write-back of the calibrated
URDF: exact recovery on noise-free data, forward kinematics of the written file (Pinocchio,
yourdfpy) equal to the model's, every element not calibrated unchanged, the calibration report and
its uncertainty, and refusals that write nothing."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from xml.etree import ElementTree as ET

import numpy as np
import pytest
import yourdfpy
from urdf_cases import SMALL, TIAGO_HEAD, pinocchio_poses, simulate, tiago_with_plate, write

from cpc2urdf.errors import InputFileError, OutputError, SpecError
from cpc2urdf.files.measurements import load_measurements
from cpc2urdf.files.model_file import save_model
from cpc2urdf.files.robot_ref import load_model
from cpc2urdf.identification.kinematics.methods import identify
from cpc2urdf.identification.kinematics.origin_uncertainty import origin_uncertainty
from cpc2urdf.identification.kinematics.parametrization import Parametrization
from cpc2urdf.model import CPCModel, CPCParams, Frame
from cpc2urdf.tolerances import FK_AGREEMENT_TOL
from cpc2urdf.transforms import inverse, rotation_error
from cpc2urdf.urdf.origins import plan_for_tree, urdf_link_poses, writeback_plan
from cpc2urdf.urdf.report import report_paths
from cpc2urdf.urdf.robot import attach_urdf_source, load_urdf_robot
from cpc2urdf.urdf.tree import read_urdf_tree
from cpc2urdf.urdf.writeback import write_calibrated_urdf
from cpc2urdf.validation.crosscheck import yourdfpy_pose

EXACT = 1e-12  # [m] and [-]: the written origins reproduce the model to rounding
CALIBRATED = (*TIAGO_HEAD, "calib_plate_joint")


@pytest.fixture(scope="module")
def tiago(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, CPCModel, CPCModel]:
    """TIAGo with a plate, a perturbed truth of its head, and the model identified from
    noise-free one-joint-at-a-time measurements of the plate."""
    folder = tmp_path_factory.mktemp("tiago")
    urdf = tiago_with_plate(folder)
    truth = simulate(
        load_urdf_robot(urdf, ["calib_plate"]), np.random.default_rng(0), folder / "m.json"
    )
    ms = load_measurements(folder / "m.json")
    return urdf, truth, attach_urdf_source(identify(ms), ms.spec)


def _readings(model: CPCModel, q: np.ndarray, names: dict[str, str]) -> dict[str, float]:
    return {names[n]: float(v) for n, v in zip(model.structure.joint_names, q, strict=True)}


def _tree(path: Path) -> ET.Element:
    return ET.parse(
        path, parser=ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))
    ).getroot()


def _differences(a: ET.Element, b: ET.Element, where: str = "robot") -> list[str]:
    """Every element of the two parsed trees whose tag, attributes, text or children differ."""
    out = []
    if (a.tag, a.attrib, (a.text or "").strip()) != (b.tag, b.attrib, (b.text or "").strip()):
        out.append(where)
    if len(a) != len(b):
        return [*out, f"{where}: children"]
    for k, (x, y) in enumerate(zip(a, b, strict=True)):
        out += _differences(
            x,
            y,
            f"{where}/{x.attrib.get('name', x.tag) if isinstance(x.tag, str) else 'comment'}[{k}]",
        )
    return out


def test_identification_of_tiago_head_is_exact(tiago: tuple[Path, CPCModel, CPCModel]) -> None:
    _, truth, model = tiago
    s = truth.structure
    Q = np.random.default_rng(4).uniform(s.lower, s.upper, (30, s.n_joints))
    np.testing.assert_allclose(
        model.fk(Q, ["calib_plate"])["calib_plate"],
        truth.fk(Q, ["calib_plate"])["calib_plate"],
        rtol=0,
        atol=FK_AGREEMENT_TOL,
    )
    (p_m, u_m), (p_t, u_t) = model.joint_axes_world(Q[0]), truth.joint_axes_world(Q[0])
    assert np.abs(u_m - u_t).max() < FK_AGREEMENT_TOL  # every axis direction
    for i in (1, 2):  # the revolute axes are the same lines
        d = p_m[0, i] - p_t[0, i]
        assert np.linalg.norm(d - (d @ u_t[0, i]) * u_t[0, i]) < FK_AGREEMENT_TOL


def test_written_urdf_puts_every_link_where_the_model_does(
    tiago: tuple[Path, CPCModel, CPCModel], tmp_path: Path
) -> None:
    urdf, _, model = tiago
    out = write_calibrated_urdf(model, tmp_path / "calibrated.urdf")
    plan = writeback_plan(model)
    names = dict(plan.source.joints)
    assert list(plan.placements) == [
        "base_footprint",
        "base_link",
        "torso_fixed_link",
        "torso_lift_link",
        "head_1_link",
        "head_2_link",
        "calib_plate",
    ]
    s = model.structure
    T_base_world = inverse(model.T_world_base())
    for q in np.random.default_rng(5).uniform(s.lower, s.upper, (5, s.n_joints)):
        ref = pinocchio_poses(out, _readings(model, q, names), list(plan.placements))
        ours = urdf_link_poses(model, plan, q)
        assert max(np.abs(ours[n] - ref[n]).max() for n in ref) < EXACT
        assert (
            np.abs(
                T_base_world @ model.fk(q, ["calib_plate"])["calib_plate"] - ref["calib_plate"]
            ).max()
            < EXACT
        )


def test_only_the_calibrated_origins_change(
    tiago: tuple[Path, CPCModel, CPCModel], tmp_path: Path
) -> None:
    urdf, _, model = tiago
    out = write_calibrated_urdf(model, tmp_path / "calibrated.urdf")
    diffs = _differences(_tree(urdf), _tree(out))
    assert sorted(diffs) == sorted(
        f"robot/{j}[{k}]/origin[{i}]" for j, k, i in _origin_positions(urdf)
    )
    assert len(diffs) == len(CALIBRATED)
    # Byte for byte: the files differ only inside those four <origin> tags (comments, layout kept).
    before, after = read_urdf_tree(urdf), read_urdf_tree(out)
    assert _without_origins(before) == _without_origins(after)


def _origin_positions(urdf: Path) -> list[tuple[str, int, int]]:
    root = _tree(urdf)
    found = []
    for k, el in enumerate(root):
        if el.tag == "joint" and el.attrib["name"] in CALIBRATED:
            found.append((el.attrib["name"], k, [c.tag for c in el].index("origin")))
    return found


def _without_origins(tree: object) -> bytes:
    data = tree.text.encode()  # type: ignore[attr-defined]
    spans = sorted(
        (tree.joints[j].origin_tag for j in CALIBRATED), key=lambda t: t.start, reverse=True
    )  # type: ignore[attr-defined]
    for t in spans:
        data = data[: t.start] + data[t.end :]
    return data


def test_model_file_round_trip_writes_the_same_urdf(
    tiago: tuple[Path, CPCModel, CPCModel], tmp_path: Path
) -> None:
    _, _, model = tiago
    a = write_calibrated_urdf(model, tmp_path / "a.urdf")
    b = write_calibrated_urdf(
        load_model(save_model(model, tmp_path / "model.json")), tmp_path / "b.urdf"
    )
    assert a.read_bytes() == b.read_bytes()


def test_a_nominal_model_writes_back_the_file_unchanged(
    tiago: tuple[Path, CPCModel, CPCModel], tmp_path: Path
) -> None:
    icub = sorted(Path(sys.prefix, "share/iCub/robots").glob("*/model.urdf"))[0]
    for urdf in (tiago[0], write(tmp_path, "small.urdf", SMALL), icub):
        out = write_calibrated_urdf(load_model(urdf), tmp_path / "copy.urdf")
        assert out.read_text() == read_urdf_tree(urdf).text, urdf


def test_camera_from_handeye_moves_only_its_own_fixed_joint(
    tiago: tuple[Path, CPCModel, CPCModel], tmp_path: Path
) -> None:
    urdf, _, model = tiago
    nominal = load_urdf_robot(urdf).nominal_model().frames["xtion_rgb_optical_frame"].matrix()
    X = np.eye(4)
    X[:3, 3] = [0.004, -0.002, 0.003]
    camera = model.with_frame(
        Frame("xtion_rgb_optical_frame", "head_2", "camera"), CPCParams.from_matrix(nominal @ X)
    )
    out = write_calibrated_urdf(camera, tmp_path / "with_camera.urdf")
    plan = writeback_plan(camera)
    assert [(c.joint.name, c.role) for c in plan.changes][-1] == (
        "xtion_rgb_optical_joint",
        "camera",
    )
    diffs = _differences(_tree(urdf), _tree(out))
    assert len(diffs) == len(CALIBRATED) + 1 and any("xtion_rgb_optical_joint" in d for d in diffs)
    q = np.array([0.1, 0.3, -0.2])
    ref = pinocchio_poses(
        out, _readings(camera, q, dict(plan.source.joints)), ["xtion_rgb_optical_frame"]
    )
    T = (
        inverse(camera.T_world_base())
        @ camera.fk(q, ["xtion_rgb_optical_frame"])["xtion_rgb_optical_frame"]
    )
    assert np.abs(T - ref["xtion_rgb_optical_frame"]).max() < EXACT


def test_awkward_joints_written_back_agree_in_pinocchio_and_yourdfpy(tmp_path: Path) -> None:
    """An origin added where there was none, a non-unit axis made unit, comments and the
    transmission and gazebo tags kept; both parsers agree with the model."""
    urdf = write(tmp_path, "small.urdf", SMALL)
    robot = load_urdf_robot(urdf, ["marker"])
    truth = simulate(
        robot, np.random.default_rng(6), tmp_path / "m.json", M=3
    )  # any model of the sub-tree
    out = write_calibrated_urdf(truth, tmp_path / "calibrated.urdf")
    text = out.read_text()
    assert (
        "<!-- a small robot with the cases the mapping must get right -->" in text
        and "<gazebo reference" in text
    )
    after = read_urdf_tree(out)
    assert after.joints["turret_joint"].origin_tag is not None and after.joints["slide"].axis == (
        0.0,
        1.0,
        0.0,
    )
    plan = writeback_plan(truth)
    names = dict(plan.source.joints)
    y = yourdfpy.URDF.load(
        str(out), load_meshes=False, build_collision_scene_graph=False, load_collision_meshes=False
    )
    s = truth.structure
    for q in np.random.default_rng(7).uniform(s.lower, s.upper, (5, s.n_joints)):
        ours = urdf_link_poses(truth, plan, q)
        readings = _readings(truth, q, names)
        ref = pinocchio_poses(out, readings, list(ours))
        y.update_cfg(readings)
        for n in ours:
            assert np.abs(ours[n] - ref[n]).max() < EXACT
            assert np.abs(ours[n] - yourdfpy_pose(y, n, y.base_link)).max() < EXACT


def test_calibration_report(tiago: tuple[Path, CPCModel, CPCModel], tmp_path: Path) -> None:
    urdf, _, model = tiago
    out = write_calibrated_urdf(model, tmp_path / "calibrated.urdf")
    json_path, text_path = report_paths(out)
    assert (json_path.name, text_path.name) == ("calibrated.report.json", "calibrated.report.txt")
    doc = json.loads(json_path.read_text())
    assert doc["format"] == "cpc2urdf/calibration-report@1" and doc["urdf"] == str(urdf.resolve())
    assert [j["joint"] for j in doc["joints"]] == list(CALIBRATED)
    assert [j["role"] for j in doc["joints"]] == ["joint"] * 3 + ["measured link"]
    plan = writeback_plan(model)
    for entry, change in zip(doc["joints"], plan.changes, strict=True):
        assert entry["translation_mm"] == pytest.approx(
            np.linalg.norm(entry["delta_xyz_mm"]), rel=1e-12
        )
        assert entry["translation_mm"] == pytest.approx(
            1e3 * np.linalg.norm(change.calibrated[:3, 3] - change.joint.origin[:3, 3])
        )
        assert entry["rotation_deg"] == pytest.approx(
            math.degrees(rotation_error(change.joint.origin[:3, :3], change.calibrated[:3, :3]))
        )
    text = text_path.read_text()
    assert all(j in text for j in CALIBRATED) and "4 of 4 calibrated joints changed" in text


def test_origin_uncertainty_is_the_propagated_covariance(
    tiago: tuple[Path, CPCModel, CPCModel], tmp_path: Path
) -> None:
    """Noisy data with stated noise: the report's 1-sigma of each origin equals the spread of the
    origins of models drawn from the model's covariance (Monte Carlo in the model's chart)."""
    urdf = tiago[0]
    simulate(
        load_urdf_robot(urdf, ["calib_plate"]),
        np.random.default_rng(8),
        tmp_path / "m.json",
        sigma_t=0.5e-3,
        sigma_r=math.radians(0.5),
    )
    (tmp_path / "tiago_plate.urdf").write_text(urdf.read_text())
    ms = load_measurements(tmp_path / "m.json")
    model = attach_urdf_source(identify(ms), ms.spec)
    cov = model.metadata.uncertainty
    assert cov is not None and cov.scale == "known" and cov.null_space.size == 0
    plan = writeback_plan(model)
    std = origin_uncertainty(model, plan)
    assert set(std) == set(CALIBRATED)
    chart = Parametrization(model, cov.frames)
    w, V = np.linalg.eigh(cov.matrix)
    draws = np.random.default_rng(9).normal(size=(400, len(w))) * np.sqrt(np.clip(w, 0, None)) @ V.T
    moved = {j: [] for j in CALIBRATED}
    turned = {j: [] for j in CALIBRATED}
    for x in draws:
        for c, c0 in zip(
            plan_for_tree(chart.model_from_vector(x), plan.tree, plan.source).changes,
            plan.changes,
            strict=True,
        ):
            moved[c.joint.name].append(np.sum((c.calibrated[:3, 3] - c0.calibrated[:3, 3]) ** 2))
            turned[c.joint.name].append(
                rotation_error(c0.calibrated[:3, :3], c.calibrated[:3, :3]) ** 2
            )
    for j in CALIBRATED:
        assert std[j].translation is not None and std[j].rotation is not None
        assert math.sqrt(np.mean(moved[j])) == pytest.approx(std[j].translation, rel=0.1), j
        assert math.sqrt(np.mean(turned[j])) == pytest.approx(std[j].rotation, rel=0.1), j
    write_calibrated_urdf(model, tmp_path / "c.urdf", uncertainty=std)
    entry = json.loads(report_paths(tmp_path / "c.urdf")[0].read_text())["joints"][2]
    assert entry["std"]["translation_mm"] == pytest.approx(std["head_2_joint"].translation * 1e3)  # type: ignore[operator]


def _nothing_written(folder: Path) -> bool:
    return not any(p.name.startswith("out") for p in folder.iterdir())


def test_refusals_write_nothing(tiago: tuple[Path, CPCModel, CPCModel], tmp_path: Path) -> None:
    urdf, _, model = tiago
    with pytest.raises(SpecError, match="model 'iis_head' was not built from a URDF"):
        write_calibrated_urdf(load_model("iis_head"), tmp_path / "out.urdf")
    stray = model.with_frame(Frame("cam_x", "head_2", "camera"), CPCParams())
    with pytest.raises(InputFileError, match="the model's frame 'cam_x' is not a link of it"):
        write_calibrated_urdf(stray, tmp_path / "out.urdf")
    with pytest.raises(OutputError, match="does not exist"):
        write_calibrated_urdf(model, tmp_path / "missing" / "out.urdf")
    moved = tmp_path / "moved.urdf"
    text = urdf.read_text()
    moved.write_text(
        text.replace(
            '<origin rpy="1.57079632679 0 0" xyz="0.005 0.0 0.098"/>',
            '<origin rpy="1.57079632679 0 0" xyz="0.006 0.0 0.098"/>',
        )
    )
    with pytest.raises(
        InputFileError,
        match=r"joint 'head_2_joint' \(line \d+\): xyz is \[0.006, 0.0, 0.098\], but "
        r"the model was built from \[0.005, 0.0, 0.098\]",
    ):
        write_calibrated_urdf(model, tmp_path / "out.urdf", urdf=moved)
    moved.write_text(text.replace("<robot name=", "<robot nam="))
    with pytest.raises(InputFileError, match="moved.urdf: "):
        write_calibrated_urdf(model, tmp_path / "out.urdf", urdf=moved)
    with pytest.raises(InputFileError, match="no such file"):
        write_calibrated_urdf(model, tmp_path / "out.urdf", urdf=tmp_path / "gone.urdf")
    assert _nothing_written(tmp_path)
