"""The nominal IIS-head reproduces the Table 3 DH chain exactly (independent DH code here)."""

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from cpc2urdf.dh import cpc_from_dh
from cpc2urdf.files.robot_ref import load_model
from cpc2urdf.model import BASE, CPCModel, Frame, Joint, RobotStructure

D = math.radians
# Shih et al. Table 3: (theta, d, alpha, a) with the joint variable in theta (R) or d (P). [mm, deg]
TABLE_3 = {
    "table_x": ("P", 0.0, None, -90.0, 0.0),
    "table_y": ("P", 90.0, None, -90.0, 0.0),
    "pan": ("R", None, 450.0, -90.0, 0.0),
    "tilt": ("R", None, 150.0, 85.0, 50.0),
    "vergence_left": ("R", None, 100.0, 0.0, 0.0),
    "vergence_right": ("R", None, 250.0, 35.0, 70.0),
}


def independent_dh(theta: float, d: float, a: float, alpha: float) -> np.ndarray:
    """A = Rot_z(theta) Trans_z(d) Trans_x(a) Rot_x(alpha), built from scipy rotations."""

    def rot(axis: str, ang: float) -> np.ndarray:
        T = np.eye(4)
        T[:3, :3] = Rotation.from_euler(axis, ang).as_matrix()
        return T

    def tr(v) -> np.ndarray:
        T = np.eye(4)
        T[:3, 3] = v
        return T

    return rot("z", theta) @ tr([0, 0, d]) @ tr([a, 0, 0]) @ rot("x", alpha)


def A(joint: str, q: float) -> np.ndarray:
    kind, theta, d, alpha, a = TABLE_3[joint]
    if kind == "P":
        return independent_dh(D(theta), q, a / 1000, D(alpha))
    return independent_dh(q, d / 1000, a / 1000, D(alpha))


def test_nominal_iis_head_is_table_3_dh_chain():
    model = load_model("iis_head")
    s = model.structure
    assert s.joint_names == ("table_x", "table_y", "pan", "tilt", "vergence_left", "vergence_right")
    np.testing.assert_array_equal(model.T_world_base(), np.eye(4))  # world = base
    rng = np.random.default_rng(0)
    Q = rng.uniform(s.lower, s.upper, size=(300, 6))
    fk = model.fk(Q)
    for k, q in enumerate(Q):
        qd = dict(zip(s.joint_names, q, strict=False))
        trunk = (
            A("table_x", qd["table_x"])
            @ A("table_y", qd["table_y"])
            @ A("pan", qd["pan"])
            @ A("tilt", qd["tilt"])
        )
        np.testing.assert_allclose(
            fk["plate_left"][k], trunk @ A("vergence_left", qd["vergence_left"]), atol=1e-12
        )
        np.testing.assert_allclose(
            fk["plate_right"][k], trunk @ A("vergence_right", qd["vergence_right"]), atol=1e-12
        )


def test_iis_head_limits_are_table_2():
    s = load_model("iis_head").structure
    lim = {j.name: (j.lower, j.upper) for j in s.joints}
    assert lim["table_x"] == pytest.approx((0.0, 1.0))
    assert lim["table_y"] == pytest.approx((0.0, 0.5))
    assert lim["pan"] == pytest.approx((0.0, math.pi))
    assert lim["tilt"] == pytest.approx((0.0, D(60)))
    assert lim["vergence_left"] == pytest.approx((0.0, D(90)))
    assert lim["vergence_right"] == pytest.approx((0.0, D(90)))


def _dh_chain_model(rows, types) -> CPCModel:
    joints = [
        Joint(f"j{i}", t, BASE if i == 0 else f"j{i - 1}", -3, 3) for i, t in enumerate(types)
    ]
    s = RobotStructure("dh", joints, [Frame("tool", f"j{len(rows) - 1}")])
    params = {"j0": cpc_from_dh(0, 0, 0, 0)}
    for i in range(1, len(rows)):
        th, d, a, al = rows[i - 1]
        params[f"j{i}"] = cpc_from_dh(
            0 if types[i - 1] == "revolute" else th, 0 if types[i - 1] == "prismatic" else d, a, al
        )
    th, d, a, al = rows[-1]
    tool = cpc_from_dh(
        0 if types[-1] == "revolute" else th, 0 if types[-1] == "prismatic" else d, a, al
    )
    return CPCModel(s, cpc_from_dh(0, 0, 0, 0), params, {"tool": tool})


@pytest.mark.parametrize("seed", range(20))
def test_cpc_from_dh_exact_for_random_chains_including_parallel_axes(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 7))
    types = [str(rng.choice(["revolute", "prismatic"])) for _ in range(n)]
    # alpha in {0 (parallel), pi (anti-parallel), +-pi/2, random}
    alphas = rng.choice(
        [0.0, math.pi, -math.pi, math.pi / 2, -math.pi / 2, 1e-9, rng.uniform(-3, 3)], size=n
    )
    rows = [
        (rng.uniform(-3, 3), rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5), float(al))
        for al in alphas
    ]
    model = _dh_chain_model(rows, types)
    for q in rng.uniform(-3, 3, size=(20, n)):
        T = np.eye(4)
        for i, (th, d, a, al) in enumerate(rows):
            T = T @ (
                independent_dh(q[i], d, a, al)
                if types[i] == "revolute"
                else independent_dh(th, q[i], a, al)
            )
        np.testing.assert_allclose(model.fk_frame("tool", q), T, atol=1e-12)


def test_cpc_from_dh_is_continuous_where_dh_is_not():
    # Two nearly parallel axes: DH's common normal jumps, the CPC constants of C_i do not.
    p0 = cpc_from_dh(0.0, 0.2, 0.1, 0.0)
    p1 = cpc_from_dh(0.0, 0.2, 0.1, 1e-9)
    assert np.max(np.abs(p0.to_vector() - p1.to_vector())) < 1e-8
