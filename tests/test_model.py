import math

import numpy as np
import pytest

from cpc2urdf.errors import ConfigurationError, SpecError, UnknownNameError
from cpc2urdf.files.robot_ref import load_model
from cpc2urdf.model import BASE, CPCModel, CPCParams, Frame, Joint, RobotStructure
from random_trees import random_tree


def test_cpc_params_round_trip_any_transform():
    rng = np.random.default_rng(0)
    from scipy.spatial.transform import Rotation

    for k in range(200):
        T = np.eye(4)
        T[:3, :3] = Rotation.random(random_state=k).as_matrix()
        T[:3, 3] = rng.normal(size=3)
        np.testing.assert_allclose(CPCParams.from_matrix(T).matrix(), T, atol=1e-14)


def test_cpc_params_reject_nan_and_non_unit():
    with pytest.raises(SpecError, match="finite"):
        CPCParams((0, 0, 1), float("nan"), (0, 0, 0))
    with pytest.raises(SpecError, match="unit vector"):
        CPCParams((0, 0, 2), 0.0, (0, 0, 0))


def test_link_transform_is_eq_5():
    # T_{i-1,i} = Q_i(q_i) R_i Rot(z, beta_i) Trans(l_i): axis of the child = parent link @ E.
    rng = np.random.default_rng(1)
    m = random_tree(rng, 5, 2)
    q = rng.uniform(m.structure.lower, m.structure.upper)
    axis, link = m.link_poses(q)
    for i, j in enumerate(m.structure.joints):
        Q = np.eye(4)
        if j.type == "revolute":
            c, s = math.cos(q[i]), math.sin(q[i])
            Q[:2, :2] = [[c, -s], [s, c]]
        else:
            Q[2, 3] = q[i]
        np.testing.assert_allclose(link[0, i], axis[0, i] @ Q, atol=1e-14)
        parent = (
            m.T_world_base() if j.parent == BASE else link[0, m.structure.joint_index(j.parent)]
        )
        np.testing.assert_allclose(axis[0, i], parent @ m.joints[j.name].matrix(), atol=1e-14)


def test_fk_vectorised_equals_one_at_a_time():
    rng = np.random.default_rng(2)
    for _ in range(10):
        m = random_tree(rng)
        s = m.structure
        Q = rng.uniform(s.lower, s.upper, size=(17, s.n_joints))
        many = m.fk(Q)
        for k in range(len(Q)):
            one = m.fk(Q[k])
            for f in s.frame_names:
                np.testing.assert_allclose(many[f][k], one[f], atol=1e-15)
        one = m.fk(s.q_to_dict(Q[0]))
        np.testing.assert_allclose(one[s.frame_names[0]], many[s.frame_names[0]][0], atol=0)


def test_branches_share_the_trunk():
    m = load_model("iis_head")
    q = np.radians([0, 0, 90, 30, 10, 80])
    q[:2] = [0.3, 0.2]
    _, link = m.link_poses(q)
    q2 = q.copy()
    q2[4] += 0.5  # moving the left vergence joint must not move the right plate
    a, b = m.fk(q), m.fk(q2)
    np.testing.assert_array_equal(a["plate_right"], b["plate_right"])
    assert not np.allclose(a["plate_left"], b["plate_left"])


def test_structure_errors_are_named():
    J = Joint
    with pytest.raises(SpecError, match="parent 'nope'"):
        RobotStructure("r", [J("a", "revolute", "nope")], [])
    with pytest.raises(SpecError, match="lower limit 2"):
        RobotStructure("r", [J("a", "revolute", BASE, 2.0, 1.0)], [])
    with pytest.raises(SpecError, match="do not connect"):
        RobotStructure(
            "r", [J("a", "revolute", BASE), J("b", "revolute", "c"), J("c", "revolute", "b")], []
        )
    with pytest.raises(SpecError, match="revolute or prismatic"):
        RobotStructure("r", [J("a", "continuous", BASE)], [])
    with pytest.raises(SpecError, match="used twice"):
        RobotStructure("r", [J("a", "revolute", BASE)], [Frame("a", "a")])
    with pytest.raises(SpecError, match="reserved"):
        RobotStructure("r", [J("world", "revolute", BASE)], [])
    with pytest.raises(SpecError, match="finite"):
        RobotStructure("r", [J("a", "revolute", BASE, float("nan"), 1.0)], [])


def test_unknown_names_and_bad_configurations():
    m = load_model("iis_head")
    with pytest.raises(UnknownNameError, match="unknown frame 'plate_middle'.*plate_left"):
        m.fk(np.zeros(6), ["plate_middle"])
    with pytest.raises(UnknownNameError, match="unknown joint 'elbow'"):
        m.structure.q_from_dict({"elbow": 0.0})
    with pytest.raises(ConfigurationError, match="shape"):
        m.fk(np.zeros(5))
    with pytest.raises(ConfigurationError, match="NaN"):
        m.fk(np.full(6, np.nan))
    with pytest.raises(ConfigurationError, match="'pan'.*outside"):
        m.structure.check_q(np.array([0, 0, -1, 0, 0, 0.0]), limits=True)


def test_model_requires_geometry_for_every_name():
    s = RobotStructure("r", [Joint("a", "revolute")], [Frame("f", "a")])
    with pytest.raises(SpecError, match="no geometry for \\['f'\\]"):
        CPCModel(s, CPCParams(), {"a": CPCParams()}, {})


def test_frames_on_the_base_have_the_batch_shape():
    s = RobotStructure("r", [Joint("a", "revolute")], [Frame("fixed", BASE), Frame("tip", "a")])
    m = CPCModel(
        s,
        CPCParams(l=(1.0, 0, 0)),
        {"a": CPCParams()},
        {"fixed": CPCParams(l=(0, 2.0, 0)), "tip": CPCParams()},
    )
    one = m.fk(np.array([0.3]))["fixed"]
    many = m.fk(np.zeros((4, 1)))["fixed"]
    assert one.shape == (4, 4) and many.shape == (4, 4, 4)
    np.testing.assert_allclose(one[:3, 3], [1.0, 2.0, 0.0])
    np.testing.assert_allclose(many[2], one)
