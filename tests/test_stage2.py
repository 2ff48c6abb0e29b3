"""Stage-2 pipeline (identification/handeye/stage2.py): simulated cameras, solvePnP, hand-eye, model."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from cpc2urdf.cli import main
from cpc2urdf.errors import DegenerateDataError
from cpc2urdf.files.model_file import model_to_json, save_model
from cpc2urdf.files.robot_ref import load_model
from cpc2urdf.identification.handeye import stage2 as s2
from cpc2urdf.identification.vision import targets
from cpc2urdf.transforms import inverse
from cpc2urdf.urdf.document import urdf_from_model

CAMERAS = ("camera_left_optical", "camera_right_optical")


@pytest.fixture(scope="module")
def nominal_and_truth() -> tuple[object, object]:
    nominal = load_model("iis_head")
    truth = s2.perturb_cameras(nominal, np.random.default_rng(1))
    return nominal, truth


def test_target_definition() -> None:
    L = targets.TARGET_LAYOUT
    assert L.shape == (25, 3) and np.allclose(L[:, 2], 0.0)
    assert np.allclose(L.mean(axis=0), 0.0)
    assert np.allclose(L[1] - L[0], [targets.TARGET_PITCH, 0, 0]) and np.allclose(
        L[5] - L[0], [0, targets.TARGET_PITCH, 0]
    )
    assert np.all(
        np.abs(L[:, :2]) + targets.TARGET_MARKER_RADIUS < np.array(targets.TARGET_SIZE) / 2
    )
    K = s2.DEFAULT_INTRINSICS.K
    assert K.shape == (3, 3) and s2.DEFAULT_INTRINSICS.D.shape == (5,)


def test_pnp_exact_without_noise() -> None:
    rng = np.random.default_rng(0)
    from scipy.spatial.transform import Rotation

    for _ in range(5):
        R = Rotation.from_euler(
            "xyz", [math.pi + rng.normal(0, 0.3), rng.normal(0, 0.3), rng.uniform(-3, 3)]
        ).as_matrix()
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = R, [rng.normal(0, 0.03), rng.normal(0, 0.03), 0.4]
        uv, ok = s2.project_target(T)
        assert ok
        assert np.abs(s2.pose_from_image_points(uv) - T).max() < 1e-9


def test_default_placement_faces_cameras(nominal_and_truth: tuple) -> None:
    nominal, _ = nominal_and_truth
    T = s2.default_target_placement(nominal)
    q = s2.home_configuration(nominal)[None]
    for c in CAMERAS:
        T_cam_target = inverse(inverse(nominal.T_world_base()) @ nominal.fk_frame(c, q)[0]) @ T
        assert s2.project_target(T_cam_target)[1]


@pytest.mark.parametrize("method", ["tsai", "kronecker"])
def test_exact_recovery_without_noise(nominal_and_truth: tuple, method: str) -> None:
    _, truth = nominal_and_truth
    identified = truth.without_frames(["camera"])  # stage 1 knows no cameras
    r = s2.run_stage2(identified, truth, n_poses=8, pixel_noise=0.0, method=method, seed=3)
    for c in CAMERAS:
        frame = r.model.structure.frame(c)
        assert frame.kind == "camera" and frame.parent == truth.structure.frame(c).parent
        assert np.abs(r.model.frames[c].matrix() - truth.frames[c].matrix()).max() < 1e-8
        et, er = r.errors[c]
        assert et < 1e-8 and er < 1e-8
        assert r.results[c].rms_translation() < 1e-8
    hd = r.model.metadata.handeye
    assert hd["camera_left_optical"].hand == "plate_left" and hd["camera_left_optical"].n_poses == 8
    # the camera frame pose = T_link_plate @ X
    X = hd["camera_right_optical"].T_hand_camera
    assert (
        np.abs(
            truth.frames["plate_right"].matrix() @ X - truth.frames["camera_right_optical"].matrix()
        ).max()
        < 1e-8
    )


def test_model_file_and_urdf_carry_the_cameras(nominal_and_truth: tuple, tmp_path: Path) -> None:
    nominal, truth = nominal_and_truth
    r = s2.run_stage2(nominal, truth, n_poses=6, pixel_noise=0.0, seed=4)
    path = save_model(r.model, tmp_path / "calibrated.json")
    back = load_model(path)
    assert back.metadata.handeye.keys() == set(CAMERAS) and "handeye" in model_to_json(r.model)
    for c in CAMERAS:
        np.testing.assert_array_equal(
            back.metadata.handeye[c].T_hand_camera, r.model.metadata.handeye[c].T_hand_camera
        )
    for c in CAMERAS:
        assert np.abs(back.frames[c].matrix() - truth.frames[c].matrix()).max() < 1e-8
    assert 'link name="camera_left_optical"' in urdf_from_model(back)


def test_noise_gives_small_errors(nominal_and_truth: tuple) -> None:
    nominal, truth = nominal_and_truth
    r = s2.run_stage2(nominal, truth, n_poses=20, pixel_noise=0.1, seed=0)
    for c in CAMERAS:
        et, er = r.errors[c]
        assert 1e-6 < et < 0.01 and er < math.radians(1.0)
        assert 1e-6 < r.results[c].rms_translation() < 0.02
    assert "error vs truth" in r.summary()


def test_too_few_poses_names_the_camera(nominal_and_truth: tuple) -> None:
    nominal, truth = nominal_and_truth
    with pytest.raises(DegenerateDataError, match="camera_left_optical: 2 poses"):
        s2.run_stage2(nominal, truth, n_poses=2, pixel_noise=0.0)


def test_unreachable_target_is_explained(nominal_and_truth: tuple) -> None:
    nominal, truth = nominal_and_truth
    behind = s2.default_target_placement(truth, distance=-0.5)
    with pytest.raises(DegenerateDataError, match="see the whole target"):
        s2.run_stage2(nominal, truth, n_poses=3, T_base_target=behind)


def test_pose_files_feed_the_cli(
    nominal_and_truth: tuple, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    nominal, truth = nominal_and_truth
    r = s2.run_stage2(nominal, truth, n_poses=6, pixel_noise=0.0, seed=5)
    paths = s2.write_pose_files(r, tmp_path)
    assert main(["handeye", str(paths["camera_left_optical"]), "--method", "tsai", "--json"]) == 0
    import json

    X = np.array(json.loads(capsys.readouterr().out)["X"]["matrix"])
    assert np.abs(X - r.results["camera_left_optical"].X).max() < 1e-9
