"""The hand-eye consistency gate (identification/handeye/gate/ and its helpers): noise
propagation and estimation, the tested mistakes, outliers, the residual level, and the command's
refusals (``cpc2urdf handeye``: exit 2, one line, the cause named, no model written)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from handeye_mistakes import (
    MISTAKES,
    OUTLIERS,
    X_TRUE,
    Z_TRUE,
    clean_document,
    clean_poses,
    outliers,
)
from scipy.spatial.transform import Rotation

from cpc2urdf.cli import main
from cpc2urdf.errors import DegenerateDataError, InputFileError
from cpc2urdf.files.robot_ref import load_model
from cpc2urdf.files.units import Units
from cpc2urdf.identification.handeye import stage2 as s2
from cpc2urdf.identification.handeye.gate import mistakes as mk
from cpc2urdf.identification.handeye.gate.gate_report import InconsistentPosesError
from cpc2urdf.identification.handeye.gate.handeye_gate import check_consistency
from cpc2urdf.identification.handeye.gate.reference_fit import (
    residual_vectors,
)
from cpc2urdf.identification.handeye.pose_file import (
    handeye_poses_from_json,
    load_handeye_poses,
    save_handeye_poses,
)
from cpc2urdf.identification.handeye.pose_noise import (
    PoseNoise,
    estimate_noise,
    residual_covariance,
)
from cpc2urdf.identification.handeye.solvers import ALL_METHODS, Gate, calibrate, calibrate_poses
from cpc2urdf.transforms import homogeneous, inverse, matrix_from_rotvec, rotvec_from_matrix

NOISE = PoseNoise(0.0001, math.radians(0.02), 0.0003, math.radians(0.05))  # as handeye_mistakes


def _perturbed(
    rng: np.random.Generator, T: np.ndarray, angle: float, position: float
) -> np.ndarray:
    """The noise model of noise.py: ``R' = Exp(dr) R``, ``p' = p + dp``."""
    out = T.copy()
    out[:, :3, :3] = (
        Rotation.from_rotvec(rng.normal(0.0, angle, (len(T), 3))).as_matrix() @ T[:, :3, :3]
    )
    out[:, :3, 3] += rng.normal(0.0, position, (len(T), 3))
    return out


# ---- the noise model ----------------------------------------------------------------------------


def test_residual_covariance_matches_monte_carlo() -> None:
    rng = np.random.default_rng(0)
    H, C = clean_poses(0, 3)
    C = inverse(X_TRUE)[None] @ inverse(H) @ Z_TRUE[None]  # exact
    noise = PoseNoise(0.0003, math.radians(0.05), 0.0008, math.radians(0.1))
    e = []
    for _ in range(4000):
        e_t, e_r = residual_vectors(
            _perturbed(rng, H, noise.hand_angle, noise.hand_position),
            _perturbed(rng, C, noise.camera_angle, noise.camera_position),
            X_TRUE,
            Z_TRUE,
        )
        e.append(np.concatenate([e_t, e_r], axis=-1))
    S = residual_covariance(noise, H, C, X_TRUE, Z_TRUE)
    for k in range(3):
        emp = np.cov(np.array(e)[:, k].T)
        assert np.abs(emp - S[k]).max() < 0.08 * np.abs(S[k]).max()


def test_estimated_noise_recovers_the_stated_one() -> None:
    rng = np.random.default_rng(1)
    H, C = clean_poses(1, 200)
    C = inverse(X_TRUE)[None] @ inverse(H) @ Z_TRUE[None]
    Hn = _perturbed(rng, H, NOISE.hand_angle, NOISE.hand_position)
    Cn = _perturbed(rng, C, NOISE.camera_angle, NOISE.camera_position)
    e = np.concatenate(residual_vectors(Hn, Cn, X_TRUE, Z_TRUE), axis=-1)
    est = estimate_noise(Hn, Cn, X_TRUE, Z_TRUE, e, 6 * len(H))
    position = math.hypot(NOISE.hand_position, NOISE.camera_position)
    assert est.camera_position == pytest.approx(position, rel=0.2)
    angle = math.hypot(NOISE.hand_angle, NOISE.camera_angle)
    est_angle = math.hypot(est.hand_angle, est.camera_angle, est.camera_angle_per_metre * 1.0)
    assert est_angle == pytest.approx(angle, rel=0.3)


def test_fast_rotation_helpers_match_scipy() -> None:
    r = Rotation.random(2000, random_state=3)
    assert np.abs(rotvec_from_matrix(r.as_matrix()) - r.as_rotvec()).max() < 1e-9
    tiny = Rotation.from_rotvec(np.random.default_rng(0).normal(0, 1e-9, (50, 3)))
    assert np.abs(rotvec_from_matrix(tiny.as_matrix()) - tiny.as_rotvec()).max() < 1e-20
    near_pi = Rotation.from_rotvec(
        np.array([[0.0, 0.0, math.pi - 1e-5], [0.6, 0.0, 0.8]]) * [[1.0], [math.pi - 2e-3]]
    )
    assert np.abs(rotvec_from_matrix(near_pi.as_matrix()) - near_pi.as_rotvec()).max() < 1e-9
    for v in ([0.3, -1.2, 2.0], [1e-10, 0.0, 0.0]):
        assert (
            np.abs(matrix_from_rotvec(np.array(v)) - Rotation.from_rotvec(v).as_matrix()).max()
            < 1e-15
        )


# ---- the pose file's noise section ---------------------------------------------------------------


def test_noise_section_round_trip_in_file_units(tmp_path: Path) -> None:
    H, C = clean_poses(0, 4)
    path = save_handeye_poses(tmp_path / "p.json", H, C, units=Units("mm", "deg"), noise=NOISE)
    doc = json.loads(path.read_text())
    assert doc["noise"]["T_camera_target"]["position"] == pytest.approx(0.3)
    assert doc["noise"]["T_base_hand"]["angle"] == pytest.approx(0.02)
    back = load_handeye_poses(path).noise
    assert back is not None
    assert np.allclose(
        [back.hand_position, back.hand_angle, back.camera_position, back.camera_angle],
        [NOISE.hand_position, NOISE.hand_angle, NOISE.camera_position, NOISE.camera_angle],
    )
    del doc["noise"]  # a file without the section (every file before it existed) still reads
    assert handeye_poses_from_json(doc).noise is None


@pytest.mark.parametrize(
    ("noise", "message"),
    [
        ({"T_base_hand": {"position": 0.1, "angle": 0.01}}, r"noise must have exactly the keys"),
        (
            {"T_base_hand": {"position": 0.1}, "T_camera_target": {"position": 0.1, "angle": 0.1}},
            r"noise.T_base_hand must be \{'position': std, 'angle': std\}",
        ),
        (
            {
                "T_base_hand": {"position": -1, "angle": 0.01},
                "T_camera_target": {"position": 0.1, "angle": 0.1},
            },
            r"noise.T_base_hand.position must be >= 0",
        ),
        (
            {
                "T_base_hand": {"position": "x", "angle": 0.01},
                "T_camera_target": {"position": 0.1, "angle": 0.1},
            },
            r"noise.T_base_hand.position must be a number",
        ),
        (
            {
                "T_base_hand": {"position": 0, "angle": 0},
                "T_camera_target": {"position": 0, "angle": 0.1},
            },
            r"noise: the position and the angle noise must each be > 0",
        ),
    ],
)
def test_bad_noise_section_names_the_field(noise: object, message: str) -> None:
    doc = {**clean_document(0, 4), "noise": noise}
    with pytest.raises(InputFileError, match=r"f\.json: " + message):
        handeye_poses_from_json(doc, "f.json")


# ---- clean data passes ---------------------------------------------------------------------------


def test_clean_data_passes_with_and_without_a_noise_statement() -> None:
    for seed in range(3):
        for n in (3, 5, 12):
            H, C = clean_poses(seed, n)
            for noise in (None, NOISE):
                r = check_consistency(H, C, noise=noise)
                assert r.consistent, (seed, n, noise, r.summary())


def test_clean_stage2_simulation_passes() -> None:
    # The stage-2 pipeline gates every camera (tests/handeye_gate_trials.py runs many more seeds).
    truth = s2.perturb_cameras(load_model("iis_head"), np.random.default_rng(1))
    identified = truth.without_frames(["camera"])
    for seed, (n, px) in enumerate([(5, 0.1), (10, 0.5), (20, 0.2), (20, 0.0)]):
        r = s2.run_stage2(
            identified, truth, n_poses=n, pixel_noise=px, seed=seed, method="park_martin"
        )
        for camera, res in r.results.items():
            assert res.consistency is not None and res.consistency.consistent, (seed, camera)
            details = r.model.metadata.handeye[camera].details
            assert details["consistency"]["consistent"] is True


def test_the_verdict_does_not_depend_on_the_solver() -> None:
    H, C = clean_poses(2, 6)
    C[1] = C[2]  # a desynchronised record: judged alike, whatever the solver
    verdicts = [
        calibrate(H, C, method, gate=Gate(accept_inconsistent=True)).consistency
        for method in ALL_METHODS
    ]
    assert all(v == verdicts[0] for v in verdicts)


# ---- each mistake is named -----------------------------------------------------------------------


@pytest.mark.parametrize("m", mk.MISTAKES, ids=lambda m: m.code)
def test_each_tested_mistake_is_undone_by_its_fix(m: mk.Mistake) -> None:
    # Apply the inverse of every fix to clean poses: the gate names exactly that mistake.
    H, C = clean_poses(4, 10)
    broken = {
        "hand_inverted": lambda: (inverse(H), C),
        "camera_inverted": lambda: (H, inverse(C)),
        "both_inverted": lambda: (inverse(H), inverse(C)),
        "hand_transposed": lambda: (mk._transpose_rotations(H), C),
        "camera_transposed": lambda: (H, mk._transpose_rotations(C)),
        "both_transposed": lambda: (mk._transpose_rotations(H), mk._transpose_rotations(C)),
        "hand_lengths_small": lambda: (mk._scale_lengths(H, 1e-3), C),
        "hand_lengths_large": lambda: (mk._scale_lengths(H, 1e3), C),
        "camera_lengths_small": lambda: (H, mk._scale_lengths(C, 1e-3)),
        "camera_lengths_large": lambda: (H, mk._scale_lengths(C, 1e3)),
        "lengths_small": lambda: (mk._scale_lengths(H, 1e-3), mk._scale_lengths(C, 1e-3)),
        "lengths_large": lambda: (mk._scale_lengths(H, 1e3), mk._scale_lengths(C, 1e3)),
        "paired_next": lambda: (H, np.roll(C, -1, axis=0)),
        "paired_previous": lambda: (H, np.roll(C, 1, axis=0)),
        "hand_quaternion_order": lambda: (_wxyz_as_xyzw(H), C),
        "camera_quaternion_order": lambda: (H, _wxyz_as_xyzw(C)),
    }[m.code]()
    r = check_consistency(*broken)
    assert not r.consistent and r.code == m.code, r.summary()
    Hf, Cf, kept = m.undo(*broken)
    assert check_consistency(Hf, Cf).consistent and len(kept) >= 9


def _wxyz_as_xyzw(T: np.ndarray) -> np.ndarray:
    out = T.copy()
    q = Rotation.from_matrix(T[:, :3, :3]).as_quat()  # x, y, z, w
    out[:, :3, :3] = Rotation.from_quat(
        np.roll(q, 1, axis=-1)
    ).as_matrix()  # read w, x, y, z as x, y, z, w
    return out


def test_quaternion_order_is_recoverable_from_the_rotation() -> None:
    R = Rotation.random(50, random_state=5)
    wrong = Rotation.from_quat(
        np.roll(R.as_quat(), 1, axis=-1) * np.where(np.arange(50) % 2, 1, -1)[:, None]
    )
    assert (
        np.abs(mk.rotation_from_wxyz_read_as_xyzw(wrong.as_matrix()) - R.as_matrix()).max() < 1e-12
    )


def test_stage2_mistakes_are_named() -> None:
    truth = s2.perturb_cameras(load_model("iis_head"), np.random.default_rng(1))
    rng = np.random.default_rng(3)
    T_base_target = s2.default_target_placement(truth)
    q = s2.sample_configurations(truth, 10, rng, T_base_target)
    obs = s2.simulate_observations(truth, q, T_base_target, rng, pixel_noise=0.2)
    C = obs.T_camera_target["camera_left_optical"]
    H = s2.hand_poses(truth, "camera_left_optical", q)
    for code, (Hm, Cm) in {
        "both_inverted": (inverse(H), inverse(C)),
        "camera_inverted": (H, inverse(C)),
        "hand_lengths_small": (mk._scale_lengths(H, 1e-3), C),
        "paired_previous": (H, np.roll(C, 1, axis=0)),
    }.items():
        assert check_consistency(Hm, Cm).code == code


def test_outliers_are_named_by_their_labels() -> None:
    d = handeye_poses_from_json(outliers(clean_document(5)))
    r = check_consistency(d.T_base_hand, d.T_camera_target, labels=d.labels)
    assert r.code == "outliers" and r.outliers == tuple(f"config {k}" for k in OUTLIERS)
    assert "the other 10 poses" in r.evidence


def test_stated_noise_far_from_the_residuals() -> None:
    H, C = clean_poses(6, 10)
    small = PoseNoise(
        NOISE.hand_position / 10,
        NOISE.hand_angle / 10,
        NOISE.camera_position / 10,
        NOISE.camera_angle / 10,
    )
    r = check_consistency(H, C, noise=small)
    assert r.code == "noise_exceeded" and r.noise_ratio > 5 and "the stated noise" in r.cause
    large = PoseNoise(
        NOISE.hand_position * 10,
        NOISE.hand_angle * 10,
        NOISE.camera_position * 10,
        NOISE.camera_angle * 10,
    )
    r = check_consistency(H, C, noise=large)
    assert r.code == "below_noise" and r.noise_ratio < 0.2
    assert check_consistency(H, C, noise=NOISE).consistent


def test_residuals_no_setup_gives_are_refused() -> None:
    H, C = clean_poses(7, 10)
    rng = np.random.default_rng(7)
    C = np.array(
        [
            homogeneous(Rotation.random(random_state=int(s)).as_matrix(), T[:3, 3])
            for s, T in zip(rng.integers(0, 10**6, len(C)), C, strict=True)
        ]
    )  # random rotations
    r = check_consistency(H, C)
    assert r.code == "implausible" and "no tested mistake explains them" in r.evidence


def test_degenerate_data_is_refused_before_the_gate() -> None:
    H, C = clean_poses(0, 6)
    axis = np.array([0.0, 0.0, 1.0])
    Hp = np.array(
        [
            homogeneous(Rotation.from_rotvec(axis * a).as_matrix(), T[:3, 3])
            for a, T in zip(np.linspace(-1, 1, 6), H, strict=True)
        ]
    )
    Cp = inverse(X_TRUE)[None] @ inverse(Hp) @ Z_TRUE[None]
    with pytest.raises(DegenerateDataError, match="parallel axes") as e:
        calibrate(Hp, inverse(Cp), "kronecker", gate=True)
    assert not isinstance(e.value, InconsistentPosesError)


def test_accepted_inconsistent_data_carries_the_diagnosis() -> None:
    H, C = clean_poses(8, 8)
    with pytest.raises(InconsistentPosesError, match="camera poses inverted") as e:
        calibrate(H, inverse(C), "tsai", gate=True)
    assert e.value.report.code == "camera_inverted"
    r = calibrate(H, inverse(C), "tsai", gate=Gate(accept_inconsistent=True))
    assert r.consistency is not None and r.consistency.code == "camera_inverted"
    assert any(
        w.startswith("inconsistent data accepted: inconsistent directions: camera poses")
        for w in r.warnings
    )
    assert r.to_json()["consistency"]["code"] == "camera_inverted"


def test_pose_file_errors_name_the_file(tmp_path: Path) -> None:
    doc = MISTAKES[0][0](clean_document(0))
    path = tmp_path / "hand.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(
        InconsistentPosesError,
        match=r"^.*hand\.json: inconsistent data: inconsistent directions: hand",
    ):
        calibrate_poses(load_handeye_poses(path), "kronecker")


# ---- the command -------------------------------------------------------------------------------


@pytest.mark.parametrize(("mistake", "code", "words"), MISTAKES, ids=[m[1] for m in MISTAKES])
def test_cli_refuses_each_mistake_and_accepts_on_request(
    mistake: object, code: str, words: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    poses = tmp_path / "poses.json"
    poses.write_text(json.dumps(mistake(clean_document(0))))  # type: ignore[operator]
    out = tmp_path / "model.json"
    argv = ["handeye", str(poses), "--model", "iis_head", "-o", str(out)]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "Traceback" not in err
    assert f"{poses}: inconsistent data: " in err and words in err, err
    assert not out.exists()

    assert main([*argv, "--accept-inconsistent"]) == 0
    assert "warning: inconsistent data accepted: " in capsys.readouterr().out
    record = load_model(out).metadata.handeye["camera_left_optical"]
    assert (
        record.details["consistency"]["code"] == code
        and not record.details["consistency"]["consistent"]
    )
    assert any(words in w for w in record.warnings)


def test_cli_drops_outliers_names_them_and_answers(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Two target detections gone wrong (5 deg, 20 mm): every solver answers without them, and
    the command names them; the answer is the clean data's to within its noise."""
    poses = tmp_path / "poses.json"
    poses.write_text(json.dumps(outliers(clean_document(0))))
    assert main(["handeye", str(poses), "--method", "all", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    for name, r in doc["results"].items():
        assert r["consistency"]["consistent"], name
        assert any("2 of" in w and "config 3, config 8" in w for w in r["warnings"]), name


def test_cli_clean_file_passes_and_method_all_refuses_once(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    poses = tmp_path / "poses.json"
    poses.write_text(json.dumps(clean_document(1)))
    assert main(["handeye", str(poses), "--method", "all", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert all(r["consistency"]["consistent"] for r in doc["results"].values())
    poses.write_text(json.dumps(MISTAKES[1][0](clean_document(1))))
    assert main(["handeye", str(poses), "--method", "all"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "camera poses inverted" in err


def test_cli_uses_the_stated_noise(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    H, C = clean_poses(9, 10)
    small = PoseNoise(1e-6, 1e-6, 1e-6, 1e-6)
    path = save_handeye_poses(tmp_path / "p.json", H, C, units=Units("mm", "deg"), noise=small)
    assert main(["handeye", str(path)]) == 2
    assert "the stated noise" in capsys.readouterr().err
    save_handeye_poses(path, H, C, units=Units("mm", "deg"), noise=NOISE)
    assert main(["handeye", str(path), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["consistency"]["noise"] == "stated"
