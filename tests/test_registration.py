"""Arun's SVD registration (Shih et al. sec. 3.3): exact, agrees with scipy, rejects degenerate data."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from cpc2urdf.errors import DegenerateDataError
from cpc2urdf.files.robot_ref import load_robot
from cpc2urdf.registration import (
    plate_pose_from_points,
    registration_rms,
    transforms_from_point_pairs,
)

LAYOUT = np.array(load_robot("iis_head").structure.frame("plate_left").layout)


def _random_pose(rng: np.random.Generator) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.random(random_state=rng).as_matrix()
    T[:3, 3] = rng.normal(0.0, 0.5, 3) + [0, 0, 1.5]
    return T


def _apply(T: np.ndarray, p: np.ndarray) -> np.ndarray:
    return p @ T[:3, :3].T + T[:3, 3]


def test_exact_on_noise_free_plate_points() -> None:
    rng = np.random.default_rng(0)
    for _ in range(50):
        T = _random_pose(rng)
        est = plate_pose_from_points(LAYOUT, _apply(T, LAYOUT))
        np.testing.assert_allclose(est, T, atol=1e-12)
        assert registration_rms(est, LAYOUT, _apply(T, LAYOUT)) < 1e-12


def test_exact_on_general_3d_points_and_batched() -> None:
    rng = np.random.default_rng(0)
    Ts = np.stack([_random_pose(rng) for _ in range(20)])
    a = rng.normal(size=(6, 3))
    b = np.einsum("nij,kj->nki", Ts[:, :3, :3], a) + Ts[:, None, :3, 3]
    np.testing.assert_allclose(transforms_from_point_pairs(a, b), Ts, atol=1e-12)
    np.testing.assert_allclose(
        plate_pose_from_points(LAYOUT, np.stack([_apply(T, LAYOUT) for T in Ts])), Ts, atol=1e-12
    )


def test_agrees_with_scipy_align_vectors_on_noisy_points() -> None:
    rng = np.random.default_rng(0)
    for _ in range(50):
        T = _random_pose(rng)
        p = _apply(T, LAYOUT) + rng.normal(0.0, 1e-3, LAYOUT.shape)
        est = plate_pose_from_points(LAYOUT, p)
        # Independent method: scipy's Kabsch on centred points, translation from the centroids.
        r, _ = Rotation.align_vectors(p - p.mean(0), LAYOUT - LAYOUT.mean(0))
        R = r.as_matrix()
        np.testing.assert_allclose(est[:3, :3], R, atol=1e-10)
        np.testing.assert_allclose(est[:3, 3], p.mean(0) - R @ LAYOUT.mean(0), atol=1e-10)
        assert abs(np.linalg.det(est[:3, :3]) - 1.0) < 1e-12


def test_reflection_case_gives_a_rotation() -> None:
    # Mirror the measured points: the unconstrained SVD optimum V U^T is then a reflection
    # (det -1); the flip must return the best proper rotation, as scipy's does.
    rng = np.random.default_rng(0)
    a = rng.normal(size=(8, 3))
    b = a * [1.0, 1.0, -1.0] + rng.normal(0.0, 1e-3, a.shape)
    H = (a - a.mean(0)).T @ (b - b.mean(0))
    U, _, Vt = np.linalg.svd(H)
    assert np.linalg.det(Vt.T @ U.T) < 0  # the case is really exercised
    est = transforms_from_point_pairs(a, b)
    assert abs(np.linalg.det(est[:3, :3]) - 1.0) < 1e-12
    r, _ = Rotation.align_vectors(b - b.mean(0), a - a.mean(0))
    np.testing.assert_allclose(est[:3, :3], r.as_matrix(), atol=1e-10)


def test_missing_points_are_skipped() -> None:
    rng = np.random.default_rng(0)
    T = _random_pose(rng)
    p = _apply(T, LAYOUT)
    p[[1, 5, 8]] = np.nan
    np.testing.assert_allclose(plate_pose_from_points(LAYOUT, p), T, atol=1e-12)


def test_rejects_too_few_and_collinear_points() -> None:
    rng = np.random.default_rng(0)
    T = _random_pose(rng)
    p = _apply(T, LAYOUT)
    p[3:] = np.nan
    with pytest.raises(DegenerateDataError, match="need at least 3 measured points, got 2") as e:
        p2 = p.copy()
        p2[2] = np.nan
        plate_pose_from_points(LAYOUT, p2, what="records[4].points.plate_left")
    assert "records[4].points.plate_left" in str(e.value)
    line = np.array([[0.0, 0.0, 0.0], [0.01, 0.0, 0.0], [0.03, 0.0, 0.0], [0.05, 0.0, 0.0]])
    with pytest.raises(DegenerateDataError, match="collinear"):
        transforms_from_point_pairs(line, _apply(T, line))
    # Layout row 1, 2, 3 lie on one line (y = -25 mm): only those measured -> collinear.
    p3 = np.full_like(p, np.nan)
    p3[1:4] = _apply(T, LAYOUT[1:4])
    with pytest.raises(DegenerateDataError, match="collinear"):
        plate_pose_from_points(LAYOUT, p3)
    with pytest.raises(DegenerateDataError, match="coincide"):
        transforms_from_point_pairs(np.zeros((4, 3)), np.zeros((4, 3)))


def test_shape_errors() -> None:
    with pytest.raises(ValueError, match="expected 9 measured points"):
        plate_pose_from_points(LAYOUT, np.zeros((8, 3)))
