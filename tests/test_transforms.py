import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from cpc2urdf.transforms import (
    cpc_rotation,
    inverse,
    matrix_from_rpy,
    project_to_rotation,
    rot_z,
    rotation_error,
    rpy_from_matrix,
    trans,
)


def test_cpc_rotation_is_rotation_about_k_by_phi():
    # eq. (4) == Rot(k, phi), k = z x b / |z x b|, phi = acos(b_z)
    rng = np.random.default_rng(0)
    for _ in range(200):
        b = rng.normal(size=3)
        b /= np.linalg.norm(b)
        k = np.cross([0, 0, 1], b)
        R_ref = Rotation.from_rotvec(k / np.linalg.norm(k) * math.acos(b[2])).as_matrix()
        np.testing.assert_allclose(cpc_rotation(b), R_ref, atol=1e-12)
        np.testing.assert_allclose(cpc_rotation(b) @ [0, 0, 1], b, atol=1e-15)


@pytest.mark.parametrize("eps", [0.0, 1e-14, 1e-9, 1e-7, 1e-5])
def test_cpc_rotation_near_antiparallel_stays_exact(eps):
    b = np.array([math.sin(eps), 0.0, -math.cos(eps)])
    R = cpc_rotation(b)
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-14)
    np.testing.assert_allclose(R @ [0, 0, 1], b, atol=1e-14)
    assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-14)


def test_rpy_round_trip_including_gimbal_lock():
    rng = np.random.default_rng(1)
    mats = [Rotation.random(random_state=k).as_matrix() for k in range(200)]
    for p in (math.pi / 2, -math.pi / 2, math.pi / 2 - 1e-9, -math.pi / 2 + 1e-12):
        mats.append(matrix_from_rpy([rng.uniform(-3, 3), p, rng.uniform(-3, 3)]))
    for R in mats:
        R2 = matrix_from_rpy(rpy_from_matrix(R))
        assert np.max(np.abs(R2 - R)) < 1e-15 * 8


def test_matrix_from_rpy_matches_scipy_extrinsic_xyz():
    rpy = [0.3, -1.1, 2.5]
    np.testing.assert_allclose(
        matrix_from_rpy(rpy), Rotation.from_euler("xyz", rpy).as_matrix(), atol=1e-15
    )


def test_vectorised_rot_z_and_inverse():
    th = np.linspace(-3, 3, 7)
    T = rot_z(th) @ trans(np.ones((7, 3)))
    assert T.shape == (7, 4, 4)
    np.testing.assert_allclose(inverse(T) @ T, np.broadcast_to(np.eye(4), (7, 4, 4)), atol=1e-15)
    np.testing.assert_allclose(rot_z(0.4), rot_z(np.array([0.4]))[0])


def test_rotation_error_small_and_large_angles():
    for a in (1e-12, 1e-6, 0.5, math.pi - 1e-9):
        R = Rotation.from_rotvec([0, a, 0]).as_matrix()
        assert rotation_error(np.eye(3), R) == pytest.approx(a, rel=1e-6, abs=1e-15)


def test_project_to_rotation_is_nearest():
    rng = np.random.default_rng(2)
    R = Rotation.random(random_state=3).as_matrix()
    M = R + 1e-3 * rng.normal(size=(3, 3))
    P = project_to_rotation(M)
    np.testing.assert_allclose(P.T @ P, np.eye(3), atol=1e-14)
    # nearest: no other rotation (the true one, small perturbations of P) is closer to M
    assert np.linalg.norm(P - M) <= np.linalg.norm(R - M)
    for _k in range(20):
        Q = Rotation.from_rotvec(1e-4 * rng.normal(size=3)).as_matrix() @ P
        assert np.linalg.norm(P - M) <= np.linalg.norm(Q - M)
