"""AX = XB solvers, shared diagnostics and the result type (identification/handeye.py)."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from cpc2urdf.errors import DegenerateDataError
from cpc2urdf.identification.handeye.axxb import (
    MAX_PAIRS_PER_POSE,
    motion_pairs,
    relative_motions,
    rotation_spread,
    solve_daniilidis,
    solve_park_martin,
    solve_tsai,
)
from cpc2urdf.identification.handeye.solvers import (
    ALL_METHODS,
    HAND_EYE_METHODS,
    calibrate,
    calibrate_hand_eye,
)
from cpc2urdf.transforms import homogeneous, inverse, rotation_error

EXACT = 1e-9  # [m] and [-]: noise-free recovery


def random_pose(rng: np.random.Generator, max_angle: float = 2.0, scale: float = 0.5) -> np.ndarray:
    """A rigid transform with rotation angle below ``max_angle`` [rad], translation within ``scale`` [m]."""
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    R = Rotation.from_rotvec(axis * rng.uniform(0.2, max_angle)).as_matrix()
    return homogeneous(R, rng.uniform(-scale, scale, 3))


def make_data(rng: np.random.Generator, n: int = 8) -> tuple[np.ndarray, ...]:
    """Truth X = T_hand_camera, Z = T_base_target, and consistent absolute poses."""
    X = random_pose(rng, scale=0.1)
    Z = random_pose(rng, scale=1.0)
    H = np.array([random_pose(rng) for _ in range(n)])  # T_base_hand
    C = inverse(X)[None] @ inverse(H) @ Z[None]  # T_camera_target closes the loop
    return X, Z, H, C


def add_noise(rng: np.random.Generator, T: np.ndarray, sr: float, st: float) -> np.ndarray:
    out = T.copy()
    for k in range(len(T)):
        d = homogeneous(
            Rotation.from_rotvec(rng.normal(0, sr, 3)).as_matrix(), rng.normal(0, st, 3)
        )
        out[k] = T[k] @ d
    return out


@pytest.mark.parametrize("method", HAND_EYE_METHODS)
def test_noise_free_recovery(method: str) -> None:
    rng = np.random.default_rng(0)
    X, Z, H, C = make_data(rng)
    r = calibrate_hand_eye(H, C, method)
    assert np.abs(r.X - X).max() < EXACT
    assert np.abs(r.Z - Z).max() < EXACT
    assert r.residual_translation.max() < EXACT and r.residual_rotation.max() < EXACT
    assert r.warnings == ()
    assert np.allclose(r.T_hand_camera, r.X) and np.allclose(r.T_base_target, r.Z)


def test_relative_motions_satisfy_ax_xb() -> None:
    rng = np.random.default_rng(0)
    X, _, H, C = make_data(rng, 5)
    A, B = relative_motions(H, C)
    assert len(A) == 10
    assert np.abs(A @ X - X @ B).max() < EXACT


# OpenCV: calibrateHandEye(R_gripper2base, t_gripper2base, R_target2cam, t_target2cam) returns
# cam2gripper. "gripper2base" maps gripper coordinates to base ones: our T_base_hand;
# "target2cam" is T_camera_target; "cam2gripper" is T_hand_camera = X.
OPENCV = {
    "tsai": cv2.CALIB_HAND_EYE_TSAI,
    "park_martin": cv2.CALIB_HAND_EYE_PARK,
    "daniilidis": cv2.CALIB_HAND_EYE_DANIILIDIS,
}


def opencv_hand_eye(H: np.ndarray, C: np.ndarray, method: str) -> np.ndarray:
    R, t = cv2.calibrateHandEye(
        H[:, :3, :3], H[:, :3, 3], C[:, :3, :3], C[:, :3, 3], method=OPENCV[method]
    )
    return homogeneous(R, t.ravel())


@pytest.mark.parametrize("method", HAND_EYE_METHODS)
def test_agrees_with_opencv_noise_free(method: str) -> None:
    rng = np.random.default_rng(1)
    X, _, H, C = make_data(rng)
    X_cv = opencv_hand_eye(H, C, method)
    assert np.abs(X_cv - X).max() < EXACT
    assert np.abs(calibrate_hand_eye(H, C, method).X - X_cv).max() < EXACT


def test_park_martin_matches_opencv_on_noisy_data() -> None:
    # Same algorithm and the same all-pairs motions: identical to rounding even with noise.
    rng = np.random.default_rng(2)
    _, _, H, C = make_data(rng, 10)
    C = add_noise(rng, C, 0.01, 0.002)
    X_cv = opencv_hand_eye(H, C, "park_martin")
    assert np.abs(calibrate_hand_eye(H, C, "park_martin").X - X_cv).max() < 1e-9


@pytest.mark.parametrize("method", HAND_EYE_METHODS)
def test_noisy_data_is_close_and_residuals_reflect_noise(method: str) -> None:
    rng = np.random.default_rng(3)
    X, Z, H, C = make_data(rng, 15)
    C = add_noise(rng, C, math.radians(0.1), 0.0005)
    r = calibrate_hand_eye(H, C, method)
    assert rotation_error(r.X[:3, :3], X[:3, :3]) < math.radians(0.2)
    assert np.linalg.norm(r.X[:3, 3] - X[:3, 3]) < 0.003
    assert 1e-5 < r.rms_translation() < 0.01
    assert r.residual_translation.shape == (15,)


def test_too_few_poses() -> None:
    rng = np.random.default_rng(0)
    _, _, H, C = make_data(rng, 2)
    with pytest.raises(DegenerateDataError, match="2 poses.*at least 3"):
        calibrate_hand_eye(H, C)


def test_mismatched_lengths() -> None:
    rng = np.random.default_rng(0)
    _, _, H, C = make_data(rng, 5)
    with pytest.raises(DegenerateDataError, match="5 hand poses but 4 camera poses"):
        calibrate_hand_eye(H, C[:4])


def test_parallel_axes_only() -> None:
    rng = np.random.default_rng(0)
    X, Z, _, _ = make_data(rng)
    axis = np.array([0.3, -0.2, 0.9]) / np.linalg.norm([0.3, -0.2, 0.9])
    H = np.array(
        [
            homogeneous(Rotation.from_rotvec(axis * a).as_matrix(), rng.uniform(-0.5, 0.5, 3))
            for a in np.linspace(-1.0, 1.0, 6)
        ]
    )
    C = inverse(X)[None] @ inverse(H) @ Z[None]
    rms, axes = rotation_spread(H)
    assert abs(abs(axes[:, 0] @ axis) - 1.0) < 1e-9 and rms[1] < 1e-6
    for method in HAND_EYE_METHODS:
        with pytest.raises(DegenerateDataError, match="parallel axes"):
            calibrate_hand_eye(H, C, method)


def test_tiny_rotations() -> None:
    rng = np.random.default_rng(0)
    X, Z, _, _ = make_data(rng)
    H = np.array(
        [
            homogeneous(
                Rotation.from_rotvec(rng.normal(0, 1e-4, 3)).as_matrix(), rng.uniform(-0.5, 0.5, 3)
            )
            for _ in range(6)
        ]
    )
    C = inverse(X)[None] @ inverse(H) @ Z[None]
    with pytest.raises(DegenerateDataError, match="tiny rotations"):
        calibrate_hand_eye(H, C)


def test_weak_rotation_warns() -> None:
    rng = np.random.default_rng(0)
    X, Z, _, _ = make_data(rng)
    # big rotations about z, and 1 deg about x: determined, but weakly
    H = np.array(
        [
            homogeneous(Rotation.from_euler("zx", [a, b]).as_matrix(), rng.uniform(-0.5, 0.5, 3))
            for a, b in zip(np.linspace(-1, 1, 6), np.radians([0, 1, 0, -1, 0, 1]), strict=True)
        ]
    )
    C = inverse(X)[None] @ inverse(H) @ Z[None]
    r = calibrate_hand_eye(H, C)
    assert np.abs(r.X - X).max() < 1e-8
    assert any("weak data" in w for w in r.warnings)


@pytest.mark.parametrize("which", ["camera", "hand"])
def test_inverted_direction_detected(which: str) -> None:
    rng = np.random.default_rng(0)
    _, _, H, C = make_data(rng)
    if which == "camera":
        C = inverse(C)  # the user passed T_target_camera
    else:
        H = inverse(H)  # the user passed T_hand_base
    with pytest.raises(DegenerateDataError, match="inconsistent directions.*T_target_camera"):
        calibrate_hand_eye(H, C)


def test_inverted_direction_detected_with_noise() -> None:
    rng = np.random.default_rng(4)
    _, _, H, C = make_data(rng, 10)
    C = add_noise(rng, C, math.radians(0.5), 0.001)
    calibrate_hand_eye(H, C)  # consistent: no error
    with pytest.raises(DegenerateDataError, match="inconsistent directions"):
        calibrate_hand_eye(H, inverse(C))


def test_outlier_pose_named() -> None:
    rng = np.random.default_rng(5)
    _, _, H, C = make_data(rng, 12)
    C = add_noise(rng, C, math.radians(0.01), 0.0001)
    C[7] = C[7] @ homogeneous(Rotation.from_rotvec([0.0, 0.05, 0.0]).as_matrix(), [0.02, 0.0, 0.0])
    r = calibrate_hand_eye(H, C, "park_martin")
    assert any(w.startswith("pose 7 is an outlier") for w in r.warnings)
    assert int(np.argmax(r.residual_translation)) == 7


def test_bad_input_shapes() -> None:
    with pytest.raises(ValueError, match="T_base_hand must be a list of 4x4"):
        calibrate_hand_eye(np.zeros((3, 3, 3)), np.zeros((3, 4, 4)))
    H = np.tile(np.eye(4), (3, 1, 1))
    H[1, :3, :3] *= 2.0
    with pytest.raises(ValueError, match=r"T_base_hand\[1\] rotation part"):
        calibrate_hand_eye(H, np.tile(np.eye(4), (3, 1, 1)))
    with pytest.raises(ValueError, match="unknown AX=XB method"):
        calibrate_hand_eye(np.tile(np.eye(4), (3, 1, 1)), np.tile(np.eye(4), (3, 1, 1)), "magic")


def test_result_json_states_directions() -> None:
    rng = np.random.default_rng(0)
    _, _, H, C = make_data(rng, 4)
    doc = calibrate_hand_eye(H, C).to_json()
    assert doc["X"]["direction"].startswith("T_hand_camera")
    assert doc["Z"]["direction"].startswith("T_base_target")
    assert len(doc["residual_translation_mm"]) == 4


def test_opencv_answers_where_we_refuse() -> None:
    # The motivation (opencv#24871, #17986, #20974): on degenerate data OpenCV returns an
    # X far from the truth without raising; we refuse with a reason.
    rng = np.random.default_rng(0)
    X, Z, H, C = make_data(rng, 8)
    axis = np.array([0.3, -0.2, 0.9]) / np.linalg.norm([0.3, -0.2, 0.9])
    Hp = np.array(
        [
            homogeneous(Rotation.from_rotvec(axis * a).as_matrix(), rng.uniform(-0.5, 0.5, 3))
            for a in np.linspace(-1.0, 1.0, 6)
        ]
    )
    cases = [
        (Hp, inverse(X)[None] @ inverse(Hp) @ Z[None], "parallel axes"),
        (H, inverse(C), "inconsistent directions"),
    ]
    for Hc, Cc, reason in cases:
        try:
            X_cv = opencv_hand_eye(Hc, Cc, "tsai")
            assert np.linalg.norm(X_cv[:3, 3] - X[:3, 3]) > 0.01  # silently wrong
        except cv2.error:
            pass  # a future OpenCV may refuse too
        with pytest.raises(DegenerateDataError, match=reason):
            calibrate_hand_eye(Hc, Cc, "tsai")


def test_every_solver_takes_1000_poses_in_seconds_and_little_memory() -> None:
    """``--method all`` on 1,000 poses in seconds within 1 GB. All pairs were 499,500
    relative motions (Daniilidis: ~150 s, the SVD's full left factor once asked 24 GiB at 120
    poses); now 15 pairs per pose and every solver built for all poses at once."""
    import resource
    import time

    rng = np.random.default_rng(1)
    X, Z, H, C = make_data(rng, n=1000)
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss  # [KiB]
    start = time.perf_counter()
    for method in ALL_METHODS:
        r = calibrate(H, C, method)
        assert np.abs(r.X - X).max() < EXACT and np.abs(r.Z - Z).max() < EXACT, method
        assert r.residual_translation.max() < EXACT and r.residual_rotation.max() < EXACT, method
    elapsed = time.perf_counter() - start
    assert elapsed < 15.0  # ~2 s on a shared 2-core machine; all pairs took minutes
    assert (
        resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before < 1_000_000
    )  # under 1 GiB more


def test_motion_pairs_all_up_to_31_poses_then_15_per_pose() -> None:
    for n in (3, 4, 30, 31):
        i, j = motion_pairs(n)
        assert len(i) == n * (n - 1) // 2 and np.all(i < j)
    for n in (32, 33, 100, 1000):
        i, j = motion_pairs(n)
        assert len(i) == MAX_PAIRS_PER_POSE * n  # linear in n
        pairs = {(min(a, b), max(a, b)) for a, b in zip(i.tolist(), j.tolist(), strict=True)}
        assert len(pairs) == len(i) and all(a != b for a, b in pairs)  # each pair once
        assert np.all(np.bincount(np.concatenate([i, j]), minlength=n) == 2 * MAX_PAIRS_PER_POSE)
        assert {1, (n - 1) // 2} <= set(((j - i) % n).tolist())  # consecutive and half a sequence


def test_many_poses_degenerate_still_refused() -> None:
    # 500 poses about one axis, or a pose list inverted: refused by every solver as with all pairs
    # (ml answers what one axis determines).
    rng = np.random.default_rng(0)
    X, Z, _, _ = make_data(rng)
    axis = np.array([0.3, -0.2, 0.9]) / np.linalg.norm([0.3, -0.2, 0.9])
    H = np.array(
        [
            homogeneous(Rotation.from_rotvec(axis * a).as_matrix(), rng.uniform(-0.5, 0.5, 3))
            for a in rng.uniform(-1.5, 1.5, 500)
        ]
    )
    C = inverse(X)[None] @ inverse(H) @ Z[None]
    for method in ALL_METHODS:
        if method == "ml":  # answers the determined part and names the rest
            assert calibrate(H, C, method).warnings[0].startswith("partly determined")
            continue
        with pytest.raises(DegenerateDataError, match="parallel axes"):
            calibrate(H, C, method)
    _, _, H, C = make_data(rng, 500)
    with pytest.raises(DegenerateDataError, match="inconsistent directions"):
        calibrate(H, inverse(C), "tsai")


def test_many_noisy_poses_as_accurate_as_all_pairs() -> None:
    # 60 poses: 900 pairs instead of 1,770; X's error within the seed-to-seed spread of all pairs'.
    err: dict[str, list[tuple[float, float]]] = {"all": [], "ours": []}
    for seed in range(10):
        rng = np.random.default_rng(100 + seed)
        X, _, H, C = make_data(rng, 60)
        Hn, Cn = add_noise(rng, H, 0.002, 0.001), add_noise(rng, C, 0.002, 0.001)
        for kind, pairs in (("all", np.triu_indices(60, k=1)), ("ours", None)):
            A, B = relative_motions(Hn, Cn, pairs)
            for solve in (solve_tsai, solve_park_martin, solve_daniilidis):
                Xe = solve(A, B)
                err[kind].append(
                    (
                        float(rotation_error(Xe[:3, :3], X[:3, :3])),
                        float(np.linalg.norm(Xe[:3, 3] - X[:3, 3])),
                    )
                )
    ours, every = np.mean(err["ours"], axis=0), np.mean(err["all"], axis=0)
    assert np.all(ours < 1.15 * every), (ours, every)
