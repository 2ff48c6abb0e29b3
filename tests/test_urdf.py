"""Round trip model -> URDF -> Pinocchio / yourdfpy -> FK, over random trees (hypothesis)."""

import re
import xml.etree.ElementTree as ET

import numpy as np
import pinocchio as pin
import pytest
import yourdfpy
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cpc2urdf.files.robot_ref import load_model
from cpc2urdf.tolerances import FK_AGREEMENT_TOL
from cpc2urdf.urdf.document import link_name, urdf_from_model, write_urdf
from cpc2urdf.validation.crosscheck import yourdfpy_pose
from random_trees import random_tree


def _all_poses_agree(model, urdf_path, Q):
    s = model.structure
    _, link = model.link_poses(Q)
    ref = {link_name(n): link[:, i] for i, n in enumerate(s.joint_names)}
    ref.update(model.fk(Q))
    pm = pin.buildModelFromUrdf(str(urdf_path))
    pd = pm.createData()
    robot = yourdfpy.URDF.load(str(urdf_path), load_meshes=False, build_collision_scene_graph=False)
    order = [s.joint_index(n) for n in robot.actuated_joint_names]
    for k, q in enumerate(Q):
        qp = np.zeros(pm.nq)
        for i, name in enumerate(s.joint_names):
            qp[pm.joints[pm.getJointId(name)].idx_q] = q[i]
        pin.framesForwardKinematics(pm, pd, qp)
        robot.update_cfg(q[order])
        for name, T in ref.items():
            assert pm.existFrame(name)
            T_pin = pd.oMf[pm.getFrameId(name)].homogeneous
            T_ydf = yourdfpy_pose(robot, name, "world")
            assert np.max(np.abs(T_pin - T[k])) < FK_AGREEMENT_TOL, name
            assert np.max(np.abs(T_ydf - T[k])) < FK_AGREEMENT_TOL, name


def test_yourdfpy_poses_follow_moves_below_1e_8(tmp_path):
    """The independent FK follows every move, however small: readings that creep by 3e-9 rad per
    configuration (30 steps, as a solver's answers near a limit can) agree with the model to
    FK_AGREEMENT_TOL at each one. (yourdfpy's ``get_transform`` reads trimesh's scene graph,
    which keeps an edge whose matrix moved by less than 1e-8: it would lag by up to 9e-8 here.)"""
    model = load_model("iis_head")
    path = write_urdf(model, tmp_path / "head.urdf")
    q0 = 0.5 * (model.structure.lower + model.structure.upper)
    Q = np.repeat(q0[None], 30, axis=0)
    Q[:, model.structure.joint_index("pan")] += 3e-9 * np.arange(30)
    _all_poses_agree(model, path, Q)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**31 - 1))
def test_random_trees_cpc_equals_pinocchio_equals_yourdfpy(tmp_path_factory, seed):
    rng = np.random.default_rng(seed)
    model = random_tree(rng)
    path = tmp_path_factory.mktemp("urdf") / "r.urdf"
    write_urdf(model, path)
    s = model.structure
    Q = rng.uniform(s.lower, s.upper, size=(5, s.n_joints))
    _all_poses_agree(model, path, Q)


def test_iis_head_urdf_structure(tmp_path):
    model = load_model("iis_head")
    text = urdf_from_model(model)
    root = ET.fromstring(text)
    assert root.tag == "robot" and root.get("name") == "iis_head"
    joints = {j.get("name"): j for j in root.findall("joint")}
    for name in model.structure.joint_names:
        j = joints[name]
        assert j.get("type") in ("revolute", "prismatic")
        assert j.find("limit") is not None
    assert "continuous" not in text
    assert {lk.get("name") for lk in root.findall("link")} >= {
        "world",
        "base",
        "plate_left",
        "plate_right",
        "camera_left_optical",
        "camera_right_optical",
    }
    # root link is world: it is nobody's child
    children = {j.find("child").get("link") for j in root.findall("joint")}
    assert "world" not in children
    write_urdf(model, tmp_path / "h.urdf")
    _all_poses_agree(
        model, tmp_path / "h.urdf", np.vstack([model.structure.lower, model.structure.upper])
    )


def test_export_is_deterministic():
    model = load_model("iis_head")
    assert urdf_from_model(model) == urdf_from_model(load_model("iis_head"))


def test_numbers_are_written_at_full_precision():
    text = urdf_from_model(load_model("iis_head"))
    # 85 deg written as the shortest repr that round-trips, not a 6-digit rounding
    assert re.search(r'rpy="1\.4835298641951802 ', text)


def test_write_urdf_leaves_no_partial_file(tmp_path):
    from cpc2urdf.errors import OutputError

    with pytest.raises(OutputError, match="does not exist"):
        write_urdf(load_model("iis_head"), tmp_path / "missing" / "h.urdf")
    assert not (tmp_path / "missing").exists()
    assert list(tmp_path.iterdir()) == []


# ---- simulation-ready export: inertials, collisions, names, camera bodies, mounts -------------


def _xml(model, **kw):
    return ET.fromstring(urdf_from_model(model, **kw))


def _joint_T(root, name):
    from cpc2urdf.transforms import matrix_from_rpy

    o = next(j for j in root.findall("joint") if j.get("name") == name).find("origin")
    T = np.eye(4)
    T[:3, :3] = matrix_from_rpy([float(v) for v in o.get("rpy").split()])
    T[:3, 3] = [float(v) for v in o.get("xyz").split()]
    return T


def test_every_link_has_an_inertial_and_element_names_are_unique():
    from cpc2urdf.identification.simulation.random_robots import random_model

    for model in (
        load_model("iis_head"),
        random_model(np.random.default_rng(4), 6, cameras=2, extra_plates=2),
    ):
        root = _xml(model)
        links = root.findall("link")
        assert [lk.find("inertial") is None for lk in links].count(True) == 1  # world only
        assert links[0].get("name") == "world" and links[0].find("inertial") is None
        names = [el.get("name") for tag in ("visual", "collision") for el in root.iter(tag)]
        assert len(names) == len(set(names)) and None not in names
        # solid shapes collide; paint (circles, markers, the base plate) does not
        collisions = {el.get("name") for el in root.iter("collision")}
        assert "table_x_axis_collision" in collisions or model.structure.name != "iis_head"
        assert not any(
            "circle" in n or "marker" in n or n.startswith("base_plate") for n in collisions
        )


def test_camera_body_frames_follow_rep_103():
    model = load_model("iis_head")
    root = _xml(model)
    parent = {
        j.find("child").get("link"): j.find("parent").get("link") for j in root.findall("joint")
    }
    for side in ("left", "right"):
        assert parent[f"camera_{side}_optical"] == f"camera_{side}"
        assert parent[f"camera_{side}"] == f"vergence_{side}_link"
        R = _joint_T(root, f"camera_{side}_optical_joint")[:3, :3]  # optical axes in the body frame
        assert np.allclose(R[:, 2], [1, 0, 0], atol=1e-15)  # z forward = body x
        assert np.allclose(R[:, 0], [0, -1, 0], atol=1e-15)  # x right = body -y
        assert np.allclose(R[:, 1], [0, 0, -1], atol=1e-15)  # y down = body -z
        assert np.all(_joint_T(root, f"camera_{side}_optical_joint")[:3, 3] == 0)
        T = _joint_T(root, f"camera_{side}_joint") @ _joint_T(root, f"camera_{side}_optical_joint")
        assert np.max(np.abs(T - model.frames[f"camera_{side}_optical"].matrix())) < 1e-15


def test_camera_body_names_avoid_taken_names():
    from cpc2urdf.model import Frame, Joint, RobotStructure
    from cpc2urdf.urdf.document import camera_body_names, urdf_link_names

    s = RobotStructure(
        "r",
        [Joint("a", "revolute")],
        [
            Frame("eye_optical", "a", "camera"),
            Frame("eye", "a", "plate"),
            Frame("cam", "a", "camera"),
            Frame("cam_body", "a", "frame"),
            Frame("x_optical_frame", "a", "camera"),
        ],
    )
    assert camera_body_names(s) == {
        "eye_optical": "eye_optical_body",
        "cam": "cam_body_2",
        "x_optical_frame": "x",
    }
    links = urdf_link_names(s)
    assert len(links) == len(set(links)) == 2 + 1 + 5 + 3


def test_mounts_rig_and_base():
    from cpc2urdf.errors import ConfigurationError
    from cpc2urdf.files.robot_ref import load_robot
    from cpc2urdf.identification.simulation.heads import calibrated_iis_head
    from cpc2urdf.model import CPCParams

    spec = load_robot("iis_head")
    model = calibrated_iis_head(0).with_params(
        world_to_base=CPCParams((0.6, 0.0, 0.8), 0.3, (0.1, 0.2, 1.5))
    )
    rig = _joint_T(_xml(model, mount="rig", physical=spec.physical), "base_joint")
    assert np.max(np.abs(rig - model.T_world_base())) < 1e-15
    base = _joint_T(_xml(model, mount="base", physical=spec.physical), "base_joint")
    assert np.all(base[:3, 3] == 0)
    up = spec.physical.up_in_base(model)  # the identified pan axis at zero readings, in base
    assert np.max(np.abs(base[:3, :3] @ up - [0, 0, 1])) < 1e-15
    assert (
        np.max(np.abs(_joint_T(_xml(model, mount="base"), "base_joint") - np.eye(4))) < 1e-15
    )  # default: base z up
    assert urdf_from_model(model) == urdf_from_model(
        model, mount="rig"
    )  # the writer's default keeps the rig
    with pytest.raises(ConfigurationError, match="mount must be one of rig, base"):
        urdf_from_model(model, mount="floor")
    assert "<mujoco>" in urdf_from_model(model) and "<mujoco>" not in urdf_from_model(
        model, mujoco=False
    )


def test_inertials_from_density_or_stated_masses():
    from cpc2urdf.urdf.document import total_mass
    from cpc2urdf.urdf.physical import PhysicalProperties

    model = load_model("iis_head")
    floors = 3e-3  # base (a marker plate) and the two optical frames: nothing solid, 1 g each
    m1000 = total_mass(model)
    assert m1000 - floors == pytest.approx(
        (total_mass(model, PhysicalProperties(density=2000.0)) - floors) / 2, rel=1e-12
    )
    stated = PhysicalProperties(
        masses={"camera_left": 0.35, "camera_left_optical": 0.01, "pan_link": 4.0}
    )
    root = _xml(model, physical=stated)
    mass = {
        lk.get("name"): float(lk.find("inertial/mass").get("value"))
        for lk in root.findall("link")[1:]
    }
    assert (
        mass["camera_left"] == 0.35
        and mass["camera_left_optical"] == 0.01
        and mass["pan_link"] == 4.0
    )
    assert mass["plate_left_link" if "plate_left_link" in mass else "plate_left"] > 0
    assert mass["camera_right_optical"] == 1e-3  # nothing solid: the 1 g floor


def test_spec_states_density_masses_and_up(tmp_path):
    import json

    from cpc2urdf.errors import InputFileError
    from cpc2urdf.files.spec import load_spec
    from cpc2urdf.robots import spec_path

    doc = json.loads(spec_path("iis_head").read_text())
    spec = load_spec(spec_path("iis_head"))
    assert (
        spec.physical.density == 2700
        and spec.physical.up_joint == "pan"
        and spec.physical.masses == {}
    )
    assert np.allclose(spec.physical.up_in_base(spec.nominal_model()), [-1, 0, 0], atol=1e-15)

    def parsed(**changes):
        path = tmp_path / "s.json"
        path.write_text(json.dumps({**doc, **changes}))
        return load_spec(path)

    assert np.allclose(parsed(up=[-2, 0, 0]).physical.up_in_base(spec.nominal_model()), [-1, 0, 0])
    flipped = parsed(up={"joint": "pan", "sign": -1}).physical
    assert np.allclose(flipped.up_in_base(spec.nominal_model()), [1, 0, 0], atol=1e-15)
    assert parsed(masses={"camera_left": 0.3}).physical.masses == {"camera_left": 0.3}
    for changes, problem in [
        ({"masses": {"head": 1.0}}, "'masses' names links ['head'] the URDF does not have"),
        ({"masses": {"pan_link": 0}}, "'masses.pan_link' must be > 0 kg"),
        ({"up": [0, 0, 0]}, "'up' must be a non-zero direction"),
        ({"up": {"joint": "neck"}}, "'up.joint' 'neck' is not a joint of this robot"),
        ({"up": {"joint": "pan", "sign": 2}}, "'up.sign' must be 1 or -1"),
        ({"density": -1}, "'density' must be > 0 kg/m^3"),
        ({"mass": 3}, "unknown keys ['mass']"),
    ]:
        with pytest.raises(InputFileError, match=re.escape(problem)):
            parsed(**changes)


def test_export_cli_mount_and_up(tmp_path, capsys):
    from cpc2urdf.cli import main

    assert main(["export", "iis_head", "-o", str(tmp_path / "rig.urdf"), "--mount", "rig"]) == 0
    assert "root 'world' = the measuring rig" in capsys.readouterr().out
    assert main(["export", "iis_head", "-o", str(tmp_path / "up.urdf"), "--up", "0", "0", "2"]) == 0
    out = capsys.readouterr().out
    assert "up = base (0, 0, 1)" in out and "up from --up" in out and "total mass 2.376 kg" in out
    assert (
        np.max(np.abs(_joint_T(ET.parse(tmp_path / "up.urdf").getroot(), "base_joint") - np.eye(4)))
        == 0
    )
    assert (
        main(["export", "iis_head", "-o", str(tmp_path / "bad.urdf"), "--up", "0", "0", "0"]) == 2
    )
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and "--up must be a non-zero direction" in err[0]
    assert not (tmp_path / "bad.urdf").exists()


def test_check_accepts_both_mounts_and_older_urdfs_but_not_a_moved_base(tmp_path):
    from cpc2urdf.files.robot_ref import load_robot
    from cpc2urdf.transforms import rpy_from_matrix
    from cpc2urdf.validation.crosscheck import cross_check

    model = load_model("iis_head")
    phys = load_robot("iis_head").physical
    for mount in ("rig", "base"):
        write_urdf(model, tmp_path / f"{mount}.urdf", mount=mount, physical=phys)
        assert cross_check(model, tmp_path / f"{mount}.urdf", n=3).ok
    # a URDF of an earlier version: the optical frame straight on the vergence link, no body link
    root = ET.parse(tmp_path / "base.urdf").getroot()
    for side in ("left", "right"):
        root.remove(next(lk for lk in root.findall("link") if lk.get("name") == f"camera_{side}"))
        root.remove(
            next(j for j in root.findall("joint") if j.get("name") == f"camera_{side}_joint")
        )
        joint = next(
            j for j in root.findall("joint") if j.get("name") == f"camera_{side}_optical_joint"
        )
        joint.find("parent").set("link", f"vergence_{side}_link")
        T = model.frames[f"camera_{side}_optical"].matrix()
        joint.find("origin").set("xyz", " ".join(repr(float(v)) for v in T[:3, 3]))
        joint.find("origin").set(
            "rpy", " ".join(repr(float(v)) for v in rpy_from_matrix(T[:3, :3]))
        )
    ET.ElementTree(root).write(tmp_path / "old.urdf")
    report = cross_check(model, tmp_path / "old.urdf", n=3)
    assert report.ok and "camera_left" not in report.frames, report.format()
    moved = (
        (tmp_path / "base.urdf")
        .read_text()
        .replace('<origin xyz="0 0 0"', '<origin xyz="0 0 0.5"', 1)
    )
    (tmp_path / "moved.urdf").write_text(moved)
    report = cross_check(model, tmp_path / "moved.urdf", n=3)
    assert not report.ok and "world -> base is neither the model's T_world_base" in report.format()


def test_export_says_where_the_physical_properties_came_from(tmp_path, capsys):
    import json

    from cpc2urdf.cli import main
    from cpc2urdf.files.model_file import save_model
    from cpc2urdf.model_metadata import Provenance
    from cpc2urdf.robots import spec_path
    from cpc2urdf.urdf.export_plan import plan_export

    model = load_model("iis_head")
    assert plan_export(model).physical_from == "defaults (none stated)"
    lost = model.with_params(
        metadata=model.metadata.replace(provenance=Provenance(method="x", robot="nope.json"))
    )
    plan = plan_export(save_model(lost, tmp_path / "m.json"))
    assert plan.physical_from.startswith(
        "defaults (the model's robot 'nope.json' cannot be read: nope.json: no such file"
    )
    assert (
        plan.physical.density == 1000.0
        and plan.physical.up is None
        and plan.physical.up_joint is None
    )
    found = model.with_params(
        metadata=model.metadata.replace(provenance=Provenance(method="x", robot="iis_head"))
    )
    plan = plan_export(save_model(found.without_frames(["camera"]), tmp_path / "f.json"))
    assert plan.physical_from == "robot iis_head" and plan.physical.up_joint == "pan"
    assert main(["export", str(tmp_path / "m.json"), "-o", str(tmp_path / "m.urdf")]) == 0
    assert (
        "physical properties from defaults (the model's robot 'nope.json' cannot be read"
        in capsys.readouterr().out
    )
    # masses of links this model does not have (its cameras were dropped) are left out, not refused
    doc = json.loads(spec_path("iis_head").read_text())
    (tmp_path / "heavy.json").write_text(
        json.dumps({**doc, "masses": {"camera_left": 0.3, "pan_link": 2.0}})
    )
    heavy = model.with_params(
        metadata=model.metadata.replace(provenance=Provenance(method="x", robot="heavy.json"))
    )
    plan = plan_export(save_model(heavy.without_frames(["camera"]), tmp_path / "h.json"))
    assert plan.physical_from == "robot heavy.json" and dict(plan.physical.masses) == {
        "pan_link": 2.0
    }
