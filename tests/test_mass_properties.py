"""Mass properties of primitives: closed forms against a split-and-recombine check (the
parallel-axis theorem), rotation, principal axes, and the physical-tensor test."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from cpc2urdf.errors import SpecError
from cpc2urdf.urdf.mass_properties import FRAME_MASS, combined, frame_floor, is_physical, solid


def _at(xyz, R=None):
    T = np.eye(4)
    T[:3, :3] = np.eye(3) if R is None else R
    T[:3, 3] = xyz
    return T


def test_two_half_boxes_are_the_whole_box_anywhere():
    R = Rotation.from_rotvec([0.3, -0.7, 1.1]).as_matrix()
    T = _at([0.1, -0.2, 0.5], R)
    whole = solid("box", (0.2, 0.1, 0.04), T, 2700.0)
    halves = [solid("box", (0.1, 0.1, 0.04), T @ _at([dx, 0, 0]), 2700.0) for dx in (-0.05, 0.05)]
    both = combined(halves)
    assert (
        both.mass == pytest.approx(whole.mass, rel=1e-14) == pytest.approx(2700 * 0.2 * 0.1 * 0.04)
    )
    assert np.allclose(both.com, [0.1, -0.2, 0.5], atol=1e-15)
    assert np.allclose(both.inertia, whole.inertia, atol=1e-15, rtol=1e-12)
    assert np.allclose(
        whole.inertia,
        R @ np.diag(np.diag(solid("box", (0.2, 0.1, 0.04), np.eye(4), 2700.0).inertia)) @ R.T,
    )


def test_cylinder_and_sphere_closed_forms():
    cyl = solid("cylinder", (0.02, 0.3), np.eye(4), 1000.0)
    m = 1000.0 * np.pi * 0.02**2 * 0.3
    assert cyl.mass == pytest.approx(m)
    assert np.allclose(
        np.diag(cyl.inertia), [m * (3 * 0.02**2 + 0.3**2) / 12] * 2 + [m * 0.02**2 / 2]
    )
    ball = solid("sphere", (0.05,), np.eye(4), 1000.0)
    assert np.allclose(ball.inertia, np.eye(3) * 0.4 * ball.mass * 0.05**2)
    with pytest.raises(SpecError, match="no volume for shape 'cone'"):
        solid("cone", (1.0,), np.eye(4), 1.0)


def test_principal_axes_diagonalise_and_keep_a_diagonal_tensor():
    R0 = Rotation.from_rotvec([0.4, 0.2, -0.9]).as_matrix()
    parts = [
        solid("box", (0.3, 0.05, 0.02), _at([0, 0.1, 0], R0), 1000.0),
        solid("cylinder", (0.01, 0.2), _at([0.05, 0, 0.1]), 1000.0),
    ]
    mp = combined(parts)
    R, moments = mp.principal()
    assert np.linalg.det(R) == pytest.approx(1.0) and np.allclose(R.T @ R, np.eye(3), atol=1e-15)
    assert np.allclose(R @ np.diag(moments) @ R.T, mp.inertia, atol=1e-18, rtol=1e-12)
    assert is_physical(moments)
    aligned = solid("box", (0.3, 0.1, 0.02), np.eye(4), 1000.0)
    R, moments = aligned.principal()
    assert np.array_equal(R, np.eye(3)) and np.array_equal(moments, np.diag(aligned.inertia))


def test_physical_tensors_and_the_floor():
    assert is_physical([1.0, 1.0, 2.0]) and is_physical([1.0, 2.0, 2.5])
    assert (
        not is_physical([1.0, 1.0, 2.1])
        and not is_physical([0.0, 1.0, 1.0])
        and not is_physical([1, 1, np.nan])
    )
    floor = frame_floor()
    assert (
        floor.mass == FRAME_MASS
        and np.allclose(floor.com, 0)
        and is_physical(np.diag(floor.inertia))
    )
    assert np.all(np.diag(floor.inertia) > 1e-15)  # MuJoCo's mjMINVAL
    box = solid("box", (0.1, 0.2, 0.3), np.eye(4), 1000.0)
    heavy = box.with_mass(12.0)
    assert heavy.mass == 12.0 and np.allclose(heavy.inertia, box.inertia * 12.0 / box.mass)
    with pytest.raises(SpecError, match="a link mass must be a finite number > 0 kg"):
        box.with_mass(0.0)
