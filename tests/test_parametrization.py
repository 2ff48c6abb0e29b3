"""The minimal chart: counts and names, exact conversions, analytic pose Jacobian vs finite differences."""

from __future__ import annotations

import numpy as np
import pytest
from refine_sim import perturbed, random_q

from cpc2urdf.errors import UnknownNameError
from cpc2urdf.files.robot_ref import load_model
from cpc2urdf.identification.kinematics.parametrization import Parametrization
from cpc2urdf.tolerances import FK_AGREEMENT_TOL
from random_trees import random_tree

PLATES = ("plate_left", "plate_right")


@pytest.fixture(scope="module")
def head():
    return load_model("iis_head")


def test_iis_head_has_32_named_parameters(head):
    p = Parametrization(head, PLATES)
    assert p.n_params == 32
    assert p.counts() == {"revolute": 16, "prismatic": 4, "frame": 12, "total": 32}
    assert p.names[:2] == ("table_x.b_x", "table_x.b_y")
    for name in (
        "tilt.b_x",
        "tilt.l_y",
        "vergence_right.l_x",
        "plate_left.l_z",
        "plate_right.beta",
    ):
        assert name in p.names
    assert "tilt.l_z" not in p.names and "table_y.l_x" not in p.names  # gauge, not parameters
    assert p.units[p.index("plate_left.l_z")] == "m" and p.units[p.index("tilt.b_x")] == "rad"
    # One plate only: its branch's joints, not the other vergence joint.
    assert Parametrization(head, ["plate_left"]).n_params == 4 + 12 + 6


def test_zero_vector_is_the_reference(head):
    p = Parametrization(head, PLATES)
    q = random_q(head, 10, np.random.default_rng(0))
    a, b = p.model_from_vector(np.zeros(32)).fk(q, PLATES), head.fk(q, PLATES)
    for f in PLATES:
        np.testing.assert_allclose(a[f], b[f], atol=1e-15)


def _same_geometry(p: Parametrization, m1, m2, q) -> None:
    """Same measured-frame poses and same revolute axis lines at every configuration."""
    for f in p.frames:
        np.testing.assert_allclose(m1.fk(q, [f])[f], m2.fk(q, [f])[f], atol=FK_AGREEMENT_TOL)
    s = m1.structure
    pa, da = m1.joint_axes_world(q)
    pb, db = m2.joint_axes_world(q)
    for j in p.joints:
        i = s.joint_index(j)
        np.testing.assert_allclose(da[:, i], db[:, i], atol=FK_AGREEMENT_TOL)
        if s.joint(j).type == "revolute":  # the line itself, not just its direction
            np.testing.assert_allclose(
                np.cross(pa[:, i] - pb[:, i], db[:, i]), 0.0, atol=FK_AGREEMENT_TOL
            )


def test_vector_from_model_aligns_any_gauge_iis_head(head):
    rng = np.random.default_rng(0)
    p = Parametrization(head, PLATES)
    for _ in range(5):
        truth = perturbed(head, rng, 0.02, 0.1)  # gauge (world_to_base, beta, l_z) moved too
        x = p.vector_from_model(truth)
        _same_geometry(p, p.model_from_vector(x), truth, random_q(head, 20, rng))
        # and the chart is its own inverse
        np.testing.assert_allclose(p.vector_from_model(p.model_from_vector(x)), x, atol=1e-12)


@pytest.mark.parametrize("seed", range(8))
def test_vector_from_model_random_trees(seed):
    rng = np.random.default_rng(seed)
    ref = random_tree(rng)
    frames = ref.structure.frame_names
    p = Parametrization(ref, frames)
    s = ref.structure
    n_rev = sum(s.joint(j).type == "revolute" for j in p.joints)
    assert p.n_params == 4 * n_rev + 2 * (len(p.joints) - n_rev) + 6 * len(frames)
    other = perturbed(ref, rng, 0.01, 0.05)
    x = p.vector_from_model(other)
    q = rng.uniform(s.lower, s.upper, size=(15, s.n_joints))
    _same_geometry(p, p.model_from_vector(x), other, q)


def _fd_pose_jacobian(p: Parametrization, x, q, eps=1e-6):
    cols = []
    for e in np.eye(p.n_params):
        Tp = p.model_from_vector(x + eps * e).fk(q, p.frames)
        Tm = p.model_from_vector(x - eps * e).fk(q, p.frames)
        T0 = p.model_from_vector(x).fk(q, p.frames)
        col = {}
        for f in p.frames:
            dp = (Tp[f][:, :3, 3] - Tm[f][:, :3, 3]) / (2 * eps)
            W = (
                (Tp[f][:, :3, :3] - Tm[f][:, :3, :3])
                / (2 * eps)
                @ np.swapaxes(T0[f][:, :3, :3], 1, 2)
            )
            col[f] = np.concatenate([dp, np.stack([W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]], 1)], 1)
        cols.append(col)
    return {f: np.stack([c[f] for c in cols], axis=2) for f in p.frames}


def test_pose_jacobian_matches_finite_differences_iis_head(head):
    rng = np.random.default_rng(1)
    p = Parametrization(perturbed(head, rng), PLATES)
    x = rng.normal(0.0, 0.05, p.n_params)  # away from the chart centre
    q = random_q(head, 6, rng)
    _, D = p.pose_jacobian(x, q)
    Dn = _fd_pose_jacobian(p, x, q)
    for f in PLATES:
        np.testing.assert_allclose(D[f], Dn[f], atol=2e-8)


@pytest.mark.parametrize("seed", range(4))
def test_pose_jacobian_matches_finite_differences_random_trees(seed):
    rng = np.random.default_rng(100 + seed)
    ref = random_tree(rng)
    p = Parametrization(ref, ref.structure.frame_names)
    x = rng.normal(0.0, 0.05, p.n_params)
    s = ref.structure
    q = rng.uniform(s.lower, s.upper, size=(4, s.n_joints))
    _, D = p.pose_jacobian(x, q)
    Dn = _fd_pose_jacobian(p, x, q)
    for f in p.frames:
        np.testing.assert_allclose(D[f], Dn[f], atol=2e-8)


def test_bad_input(head):
    with pytest.raises(UnknownNameError):
        Parametrization(head, ["plate_middle"])
    p = Parametrization(head, PLATES)
    with pytest.raises(ValueError, match=r"shape \(32,\)"):
        p.model_from_vector(np.zeros(31))
