"""Noise models: Fig. 10 statistics and stereo pixel noise propagated through triangulation."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from cpc2urdf.files.robot_ref import load_robot
from cpc2urdf.identification.simulation.measurement_noise import (
    fig10_noise,
    random_rotations,
    stereo_noise,
)
from cpc2urdf.identification.vision.stereo import StereoRig

LAYOUT = np.array(load_robot("iis_head").structure.frame("plate_left").layout)
N = 20000


def test_random_rotations_have_the_requested_angle_and_isotropic_axes() -> None:
    rng = np.random.default_rng(0)
    sigma = np.radians(0.5)
    v = Rotation.from_matrix(random_rotations(rng, sigma, N)).as_rotvec()
    # Angle ~ N(0, sigma) about a uniform axis: rotvec = angle * axis has covariance sigma^2/3 I.
    assert abs(np.sqrt(np.mean(np.sum(v**2, axis=1))) / sigma - 1) < 0.02
    np.testing.assert_allclose(np.cov(v.T) / (sigma**2 / 3), np.eye(3), atol=0.05)
    np.testing.assert_allclose(v.mean(axis=0) / sigma, 0.0, atol=0.02)


def test_fig10_noise_statistics() -> None:
    rng = np.random.default_rng(0)
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("xyz", [30, -20, 70], degrees=True).as_matrix()
    T[:3, 3] = [0.1, -0.2, 1.5]
    sigma_t, sigma_r = 0.5e-3, np.radians(0.5)
    noisy = fig10_noise(np.broadcast_to(T, (N, 4, 4)), sigma_t, sigma_r, rng)
    dt = noisy[:, :3, 3] - T[:3, 3]
    np.testing.assert_allclose(dt.std(axis=0) / sigma_t, 1.0, atol=0.03)
    np.testing.assert_allclose(dt.mean(axis=0) / sigma_t, 0.0, atol=0.03)
    np.testing.assert_allclose(np.corrcoef(dt.T), np.eye(3), atol=0.03)
    # Pre-multiplied: R_meas = dR R, dR isotropic with angle ~ N(0, sigma_r).
    v = Rotation.from_matrix(noisy[:, :3, :3] @ T[:3, :3].T).as_rotvec()
    assert abs(np.sqrt(np.mean(np.sum(v**2, axis=1))) / sigma_r - 1) < 0.02
    np.testing.assert_allclose(np.cov(v.T) / (sigma_r**2 / 3), np.eye(3), atol=0.05)
    # And it is exactly dR @ R with the documented draw order.
    rng_a, rng_b = np.random.default_rng(5), np.random.default_rng(5)
    one = fig10_noise(T, sigma_t, sigma_r, rng_a)
    dR = random_rotations(rng_b, sigma_r, 1)[0]
    np.testing.assert_allclose(one[:3, :3], dR @ T[:3, :3], atol=1e-15)
    np.testing.assert_allclose(one[:3, 3], T[:3, 3] + rng_b.normal(0.0, sigma_t, 3), atol=1e-15)
    assert np.isnan(fig10_noise(np.full((2, 4, 4), np.nan), sigma_t, sigma_r, rng)).all()


def _face_on_plate() -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("x", 180, degrees=True).as_matrix()  # +z faces the rig
    T[:3, 3] = [0.0, 0.0, 1.53]
    return T


def test_stereo_noise_free_is_exact() -> None:
    rig = StereoRig.verged()
    T = _face_on_plate()[None]
    T_meas, p = stereo_noise(T, LAYOUT, rig, 0.0, np.random.default_rng(0))
    np.testing.assert_allclose(T_meas, T, atol=1e-9)
    np.testing.assert_allclose(p[0], LAYOUT @ T[0, :3, :3].T + T[0, :3, 3], atol=1e-9)


def test_stereo_noise_has_the_covariance_of_the_propagated_pixel_noise() -> None:
    # Independent prediction: first-order propagation of N(0, sigma^2 I) pixel noise through
    # triangulation, with the Jacobian by central finite differences.
    rig = StereoRig.verged()
    sigma = 0.3
    T = _face_on_plate()
    p_true = LAYOUT @ T[:3, :3].T + T[:3, 3]
    T_meas, p = stereo_noise(
        np.broadcast_to(T, (4000, 4, 4)), LAYOUT, rig, sigma, np.random.default_rng(0)
    )
    uv1, uv2 = rig.project(p_true[4])
    x0 = np.concatenate([uv1, uv2])
    J = np.empty((3, 4))
    for k in range(4):
        d = np.zeros(4)
        d[k] = 1e-3
        hi = rig.triangulate((x0 + d)[:2], (x0 + d)[2:])
        lo = rig.triangulate((x0 - d)[:2], (x0 - d)[2:])
        J[:, k] = (hi - lo) / 2e-3
    predicted = sigma**2 * J @ J.T
    sample = np.cov((p[:, 4] - p_true[4]).T)
    np.testing.assert_allclose(np.sqrt(np.diag(sample)), np.sqrt(np.diag(predicted)), rtol=0.05)
    # The plate origin is the mean of 9 circles, so its error is ~1/3 of one circle's.
    e = T_meas[:, :3, 3] - T[:3, 3]
    np.testing.assert_allclose(e.std(axis=0), np.sqrt(np.diag(predicted) / 9), rtol=0.1)
    np.testing.assert_allclose(e.mean(axis=0), 0.0, atol=4 * e.std(axis=0).max() / np.sqrt(4000))


def test_stereo_noise_marks_unseen_circles() -> None:
    rig = StereoRig.verged()
    T = _face_on_plate()
    T[:3, 3] = [5.0, 0.0, 1.5]  # far outside both images
    T_meas, p = stereo_noise(T[None], LAYOUT, rig, 0.1, np.random.default_rng(0))
    assert np.isnan(T_meas).all() and np.isnan(p).all()
