"""AX = ZB solvers (identification/robot_world.py): Li's Kronecker and dual quaternion methods,
Zhuang's quaternion method, the joint refinement; against the truth and OpenCV."""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from test_handeye import EXACT, add_noise, make_data, random_pose

from cpc2urdf.cli import main
from cpc2urdf.errors import DegenerateDataError
from cpc2urdf.identification.handeye.axzb import align_quaternion_signs, refine, solve_kronecker
from cpc2urdf.identification.handeye.solvers import (
    ALL_METHODS,
    ROBOT_WORLD_METHODS,
    calibrate,
    calibrate_robot_world,
)
from cpc2urdf.transforms import (
    homogeneous,
    inverse,
    quat_left_matrix,
    quat_right_matrix,
    quat_wxyz_from_matrix,
    rotation_error,
)


@pytest.mark.parametrize("method", ALL_METHODS)
def test_noise_free_recovery(method: str) -> None:
    rng = np.random.default_rng(0)
    X, Z, H, C = make_data(rng)
    r = calibrate(H, C, method)
    assert np.abs(r.X - X).max() < EXACT
    assert np.abs(r.Z - Z).max() < EXACT
    assert r.rms_translation() < EXACT and r.rms_rotation() < EXACT


@pytest.mark.parametrize("seed", range(5))
def test_noise_free_recovery_minimal_three_poses(seed: int) -> None:
    rng = np.random.default_rng(seed)
    X, Z, H, C = make_data(rng, 3)
    for method in ROBOT_WORLD_METHODS:
        r = calibrate_robot_world(H, C, method)
        assert np.abs(r.X - X).max() < 1e-8, method
        assert np.abs(r.Z - Z).max() < 1e-8, method


# OpenCV: calibrateRobotWorldHandEye(R_world2cam, t_world2cam, R_base2gripper, t_base2gripper)
# -> (R_base2world, t_base2world, R_gripper2cam, t_gripper2cam), "a2b" mapping a-coordinates to b.
# Its "world" is our target: world2cam = T_camera_target; base2gripper = T_hand_base =
# inv(T_base_hand); base2world = T_target_base = inv(Z); gripper2cam = T_camera_hand = inv(X).
def opencv_robot_world(H: np.ndarray, C: np.ndarray, method: int) -> tuple[np.ndarray, np.ndarray]:
    Hi = inverse(H)
    R_bw, t_bw, R_gc, t_gc = cv2.calibrateRobotWorldHandEye(
        C[:, :3, :3], C[:, :3, 3], Hi[:, :3, :3], Hi[:, :3, 3], method=method
    )
    return inverse(homogeneous(R_gc, t_gc.ravel())), inverse(homogeneous(R_bw, t_bw.ravel()))


@pytest.mark.parametrize(
    "cv_method", [cv2.CALIB_ROBOT_WORLD_HAND_EYE_LI, cv2.CALIB_ROBOT_WORLD_HAND_EYE_SHAH]
)
def test_agrees_with_opencv_noise_free(cv_method: int) -> None:
    rng = np.random.default_rng(1)
    X, Z, H, C = make_data(rng)
    X_cv, Z_cv = opencv_robot_world(H, C, cv_method)
    assert np.abs(X_cv - X).max() < EXACT and np.abs(Z_cv - Z).max() < EXACT
    for method in ROBOT_WORLD_METHODS:
        r = calibrate_robot_world(H, C, method)
        assert np.abs(r.X - X_cv).max() < EXACT and np.abs(r.Z - Z_cv).max() < EXACT


def test_kronecker_equals_opencv_li_in_its_frame() -> None:
    # OpenCV's LI solves the inverted equation (T_camera_target inv(Z) = inv(X) T_hand_base): fed
    # those matrices, our Kronecker solver is the same least-squares problem, even with noise.
    rng = np.random.default_rng(2)
    _, _, H, C = make_data(rng, 10)
    C = add_noise(rng, C, 0.01, 0.003)
    X_cv, Z_cv = opencv_robot_world(H, C, cv2.CALIB_ROBOT_WORLD_HAND_EYE_LI)
    Xp, Zp = solve_kronecker(C, inverse(H))  # A' = T_camera_target, B' = T_hand_base
    assert np.abs(inverse(Xp) - Z_cv).max() < 1e-9
    assert np.abs(inverse(Zp) - X_cv).max() < 1e-9


@pytest.mark.parametrize("method", ROBOT_WORLD_METHODS)
def test_noisy_data_close(method: str) -> None:
    rng = np.random.default_rng(3)
    X, Z, H, C = make_data(rng, 20)
    C = add_noise(rng, C, math.radians(0.1), 0.0005)
    r = calibrate_robot_world(H, C, method)
    assert rotation_error(r.X[:3, :3], X[:3, :3]) < math.radians(0.3)
    assert np.linalg.norm(r.X[:3, 3] - X[:3, 3]) < 0.005
    assert np.linalg.norm(r.Z[:3, 3] - Z[:3, 3]) < 0.005


def test_refinement_lowers_its_cost() -> None:
    rng = np.random.default_rng(4)
    X, Z, H, C = make_data(rng, 12)
    C = add_noise(rng, C, math.radians(0.3), 0.002)
    B = inverse(C)
    X0, Z0 = solve_kronecker(H, B)

    def cost(Xe: np.ndarray, Ze: np.ndarray) -> float:
        AX, ZB = H @ Xe, Ze @ B
        rot = Rotation.from_matrix((inverse(AX) @ ZB)[:, :3, :3]).as_rotvec() * 0.1
        return float(np.sum((AX[:, :3, 3] - ZB[:, :3, 3]) ** 2) + np.sum(rot**2))

    X1, Z1 = refine(H, B, X0, Z0)
    assert cost(X1, Z1) < cost(X0, Z0)
    # stationary: refining again from the optimum does not move it
    X2, Z2 = refine(H, B, X1, Z1)
    assert np.abs(X2 - X1).max() < 1e-7 and np.abs(Z2 - Z1).max() < 1e-7


def test_zhuang_refuses_hand_rotation_near_180() -> None:
    rng = np.random.default_rng(0)
    X, Z, H, _ = make_data(rng, 6)
    H[2, :3, :3] = Rotation.from_rotvec(np.array([0.0, 0.6, 0.8]) * math.radians(179.7)).as_matrix()
    C = inverse(X)[None] @ inverse(H) @ Z[None]
    with pytest.raises(DegenerateDataError, match=r"zhuang.*poses \[2\].*180"):
        calibrate_robot_world(H, C, "zhuang")
    for method in ("kronecker", "dual_quaternion"):  # the other methods do not care
        assert np.abs(calibrate_robot_world(H, C, method).X - X).max() < EXACT
    H[2, :3, :3] = Rotation.from_rotvec(np.array([0.0, 0.6, 0.8]) * math.radians(175.0)).as_matrix()
    C = inverse(X)[None] @ inverse(H) @ Z[None]
    r = calibrate_robot_world(H, C, "zhuang")
    assert any("within 10 deg of 180" in w for w in r.warnings)


def test_dual_quaternion_with_quaternion_sign_flips() -> None:
    # Poses whose quaternions have w < 0 under a naive convention, and a target 180 deg away.
    rng = np.random.default_rng(6)
    X = random_pose(rng, scale=0.1)
    Z = homogeneous(Rotation.from_rotvec([math.pi, 0.0, 0.0]).as_matrix(), [0.5, 0.2, 1.0])
    H = np.array([random_pose(rng, max_angle=3.1) for _ in range(8)])
    C = inverse(X)[None] @ inverse(H) @ Z[None]
    r = calibrate_robot_world(H, C, "dual_quaternion")
    assert np.abs(r.X - X).max() < EXACT and np.abs(r.Z - Z).max() < EXACT


def test_quaternion_signs_aligned_through_hubs_beyond_32_poses() -> None:
    # 300 poses rotating up to 178 deg, quaternion signs scrambled: the hubs (O(N)) align them.
    rng = np.random.default_rng(7)
    X = random_pose(rng, scale=0.1)
    Z = homogeneous(Rotation.from_rotvec([math.pi, 0.0, 0.0]).as_matrix(), [0.5, 0.2, 1.0])
    H = np.array([random_pose(rng, max_angle=3.1) for _ in range(300)])
    C = inverse(X)[None] @ inverse(H) @ Z[None]
    qa = quat_wxyz_from_matrix(H[:, :3, :3]) * rng.choice([-1.0, 1.0], (300, 1))
    qb = quat_wxyz_from_matrix(inverse(C)[:, :3, :3]) * rng.choice([-1.0, 1.0], (300, 1))
    a, b = align_quaternion_signs(qa, qb)
    assert np.allclose(np.abs(a), np.abs(qa)) and np.allclose(np.abs(b), np.abs(qb))
    x = quat_wxyz_from_matrix(X[:3, :3])
    z = quat_wxyz_from_matrix(Z[:3, :3])
    lhs = np.array([quat_left_matrix(ak) @ x for ak in a])  # a x = +-(z b), one sign for all
    rhs = np.array([quat_right_matrix(bk) @ z for bk in b])
    s = np.sign(np.einsum("ki,ki->k", lhs, rhs))
    assert np.all(s == s[0]) and np.abs(lhs - s[0] * rhs).max() < 1e-12
    r = calibrate_robot_world(H, C, "dual_quaternion")
    assert np.abs(r.X - X).max() < EXACT and np.abs(r.Z - Z).max() < EXACT


@pytest.mark.parametrize("method", ROBOT_WORLD_METHODS)
def test_degenerate_inputs(method: str) -> None:
    rng = np.random.default_rng(0)
    X, Z, H, C = make_data(rng, 6)
    with pytest.raises(DegenerateDataError, match="at least 3"):
        calibrate_robot_world(H[:2], C[:2], method)
    with pytest.raises(DegenerateDataError, match="inconsistent directions"):
        calibrate_robot_world(H, inverse(C), method)
    Hp = np.array(
        [
            homogeneous(Rotation.from_euler("z", a).as_matrix(), rng.uniform(-0.5, 0.5, 3))
            for a in np.linspace(0, 1.5, 6)
        ]
    )
    Cp = inverse(X)[None] @ inverse(Hp) @ Z[None]
    if method == "ml":  # the determined part, the rest named
        warnings = calibrate_robot_world(Hp, Cp, method).warnings
        assert warnings[0].startswith("partly determined: rotations about parallel axes")
        assert any(w.startswith("undetermined by these poses") for w in warnings)
        return
    with pytest.raises(DegenerateDataError, match="parallel axes"):
        calibrate_robot_world(Hp, Cp, method)


def test_unknown_method() -> None:
    rng = np.random.default_rng(0)
    _, _, H, C = make_data(rng, 4)
    with pytest.raises(ValueError, match="unknown method"):
        calibrate(H, C, "magic")


def test_tsai_and_park_martin_survive_motions_near_180_deg() -> None:
    # Pairs of poses 179.9 deg apart: noise flips the axis sign of some B relative to their A.
    rng = np.random.default_rng(7)
    X, Z, H, _ = make_data(rng, 10)
    for k in range(0, 10, 2):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        H[k + 1, :3, :3] = (
            Rotation.from_rotvec(axis * math.radians(179.9)).as_matrix() @ H[k, :3, :3]
        )
    C = add_noise(rng, inverse(X)[None] @ inverse(H) @ Z[None], math.radians(0.2), 0.0005)
    for method in ("tsai", "park_martin", "daniilidis"):
        r = calibrate(H, C, method)
        assert rotation_error(r.X[:3, :3], X[:3, :3]) < math.radians(0.3), method


def test_daniilidis_matches_signs_of_motions_near_180_deg() -> None:
    # Li et al.'s setup, 100 poses: many relative motions near 180 deg, whose scalar parts noise
    # makes a coin toss. Matched by a first estimate, X's translation error halves (0.60 -> 0.30 mm
    # over 40 seeds) and no longer depends on which pairs are used.
    from cpc2urdf.identification.handeye.axxb import (
        motion_pairs,
        relative_motions,
        solve_daniilidis,
    )
    from cpc2urdf.studies.li2010 import X_TRUE, simulate

    rng = np.random.default_rng(0)
    err: dict[str, list[float]] = {"all": [], "ours": []}
    for _ in range(10):
        A, B = simulate(100, rng, "AB")
        for kind, pairs in (("all", np.triu_indices(100, k=1)), ("ours", motion_pairs(100))):
            X = solve_daniilidis(*relative_motions(A, inverse(B), pairs))
            err[kind].append(float(np.linalg.norm(X[:3, 3] - X_TRUE[:3, 3])))
    assert np.mean(err["all"]) < 0.4e-3 and np.mean(err["ours"]) < 0.4e-3, err


def test_li2010_study_runs_tiny(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from cpc2urdf.studies import li2010 as st

    res = st.run_study(repeats=1, pose_counts=(3, 5), ratio_counts=(4,))
    assert {r["method"] for r in res["rows"]} == set(st.PAPER_METHODS + st.EXTRA_METHODS)
    assert all(
        r["X_rot"] < 0.1 and r["Z_mm"] < 50 for r in res["rows"] if r["method"] != "kronecker_mm"
    )
    report = st.format_report(res)
    assert "Kronecker < dual quaternion < quaternion" in report and "Tsai/TSAI" in report
    # noise-free sanity of the metric: the truth has zero error
    assert st.pose_errors(st.X_TRUE, st.Z_TRUE) == {
        "X_rot": 0.0,
        "X_mm": 0.0,
        "Z_rot": 0.0,
        "Z_mm": 0.0,
    }
    assert (
        main(["study", "li2010", "--repeats", "1", "--max-poses", "3", "--out", str(tmp_path)]) == 0
    )
    assert (tmp_path / "li2010.md").exists() and (
        tmp_path / "li2010_fig1c.png"
    ).stat().st_size > 1000
    assert main(["study", "li2010", "--repeats", "0", "--out", str(tmp_path)]) == 2


def test_kronecker_length_unit() -> None:
    rng = np.random.default_rng(8)
    X, Z, H, C = make_data(rng, 6)
    Xm, Zm = solve_kronecker(H, inverse(C), length_unit=1e-3)
    assert np.abs(Xm - X).max() < EXACT and np.abs(Zm - Z).max() < EXACT
    # with noise, the unit changes the answer (the least squares is not unit-invariant) ...
    Cn = add_noise(rng, C, 0.01, 0.002)
    Xa, _ = solve_kronecker(H, inverse(Cn))
    Xb, _ = solve_kronecker(H, inverse(Cn), length_unit=1e-3)
    assert np.abs(Xa - Xb).max() > 1e-6
    # ... and solving in mm equals solving data given in mm
    S, Si = np.diag([1e3, 1e3, 1e3, 1.0]), np.diag([1e-3, 1e-3, 1e-3, 1.0])
    Xc, _ = solve_kronecker(S @ H @ Si, S @ inverse(Cn) @ Si)
    assert np.abs(Si @ Xc @ S - Xb).max() < 1e-9
