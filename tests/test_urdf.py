"""Round trip model -> URDF -> Pinocchio / yourdfpy -> FK, over random trees (hypothesis)."""

import re
import xml.etree.ElementTree as ET

import numpy as np
import pinocchio as pin
import pytest
import yourdfpy
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cpc2urdf.robot_ref import load_model
from cpc2urdf.tolerances import FK_AGREEMENT_TOL
from cpc2urdf.urdf import link_name, urdf_from_model, write_urdf
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
            T_ydf = robot.get_transform(frame_to=name, frame_from="world")
            assert np.max(np.abs(T_pin - T[k])) < FK_AGREEMENT_TOL, name
            assert np.max(np.abs(T_ydf - T[k])) < FK_AGREEMENT_TOL, name


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
        "world", "base", "plate_left", "plate_right", "camera_left_optical", "camera_right_optical"
    }
    # root link is world: it is nobody's child
    children = {j.find("child").get("link") for j in root.findall("joint")}
    assert "world" not in children
    write_urdf(model, tmp_path / "h.urdf")
    _all_poses_agree(model, tmp_path / "h.urdf", np.vstack([model.structure.lower, model.structure.upper]))


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
