"""The stereo rig: OpenCV conventions, projection, triangulation, field of view, files."""

from __future__ import annotations

import numpy as np
import pytest

from cpc2urdf.identification.vision.stereo import StereoRig
from cpc2urdf.transforms import inverse


def test_default_rig_is_the_papers_geometry() -> None:
    rig = StereoRig.verged()
    assert rig.baseline == pytest.approx(0.6, abs=1e-12)
    # The optical axes meet 1.5 m in front of the baseline's middle: that point projects onto
    # both principal points.
    T_wr = rig.T_world_camera("right")
    middle = T_wr[:3, 3] / 2
    theta = np.arctan2(0.3, 1.5)
    fixation = np.array([0.0, 0.0, np.hypot(0.3, 1.5)])  # on the left optical axis
    assert np.linalg.norm(fixation - middle) == pytest.approx(1.5, abs=1e-12)
    uv1, uv2 = rig.project(fixation)
    np.testing.assert_allclose(uv1, rig.K1[:2, 2], atol=1e-9)
    np.testing.assert_allclose(uv2, rig.K2[:2, 2], atol=1e-9)
    # Verged inward: the right camera looks left (towards -x of the left camera).
    assert T_wr[0, 2] == pytest.approx(-np.sin(2 * theta))
    # OpenCV convention x_right = R x_left + T.
    np.testing.assert_allclose(
        inverse(T_wr), np.block([[rig.R, rig.T[:, None]], [np.zeros((1, 3)), 1.0]])
    )


def test_projection_matches_the_pinhole_formula_without_distortion() -> None:
    rng = np.random.default_rng(0)
    rig = StereoRig.verged(distortion=np.zeros(5))
    p = rng.normal(0.0, 0.2, (50, 3)) + [0.0, 0.0, 1.5]
    uv1, uv2 = rig.project(p)
    for uv, K, T in ((uv1, rig.K1, np.eye(4)), (uv2, rig.K2, inverse(rig.T_world_camera("right")))):
        pc = p @ T[:3, :3].T + T[:3, 3]
        h = pc @ K.T
        np.testing.assert_allclose(uv, h[:, :2] / h[:, 2:], atol=1e-9)


def test_triangulation_inverts_projection_with_distortion() -> None:
    rng = np.random.default_rng(0)
    rig = StereoRig.verged()
    p = rng.normal(0.0, 0.15, (4, 9, 3)) + [0.0, 0.0, 1.5]
    uv1, uv2 = rig.project(p)
    assert uv1.shape == (4, 9, 2)
    np.testing.assert_allclose(rig.triangulate(uv1, uv2), p, atol=1e-9)
    uv1[0, 3] = np.nan
    out = rig.triangulate(uv1, uv2)
    assert np.isnan(out[0, 3]).all() and np.isfinite(out[1]).all()


def test_in_view() -> None:
    rig = StereoRig.verged()
    p = np.array([[0.0, 0.0, 1.5], [0.0, 0.0, -1.5], [2.0, 0.0, 1.5], [0.0, 0.0, 0.01]])
    assert rig.in_view(p).tolist() == [True, False, False, False]
    uv, _ = rig.project(p[0])
    assert not rig.in_view(p[0], margin_px=float(uv[0]) + 1)


def test_json_round_trip_and_errors() -> None:
    rig = StereoRig.verged(baseline=0.5, focal_px=1200.0)
    back = StereoRig.from_json(rig.to_json())
    for k in ("K1", "D1", "K2", "D2", "R", "T"):
        np.testing.assert_array_equal(getattr(back, k), getattr(rig, k))
    assert back.image_size == rig.image_size
    bad = rig.to_json()
    bad["D1"] = [0.0, 0.0]
    with pytest.raises(ValueError, match="rig.D1 must be a list of 5 numbers"):
        StereoRig.from_json(bad)
    with pytest.raises(ValueError, match="R must be a rotation"):
        StereoRig(rig.K1, rig.D1, rig.K2, rig.D2, 2 * rig.R, rig.T)


def test_stereo_study_runs_small_and_matches_first_order_depth(tmp_path) -> None:  # type: ignore[no-untyped-def]
    from cpc2urdf.cli import main
    from cpc2urdf.studies.stereo_noise import run_study

    result = run_study(samples=300, pixel_sigmas=(0.1, 0.5))
    for row in result["rows"]:
        assert row["depth_rms_mm"] == pytest.approx(row["depth_pred_mm"], rel=0.1)
        assert row["plate_pos_rms_mm"] < row["circle_rms_mm"]
    assert result["rows"][1]["circle_rms_mm"] == pytest.approx(
        5 * result["rows"][0]["circle_rms_mm"], rel=0.15
    )
    assert main(["study", "stereo", "--samples", "5", "--out", str(tmp_path)]) == 0
    assert (tmp_path / "stereo_noise.png").stat().st_size > 1000
    assert "| 0.50 |" in (tmp_path / "stereo_noise.md").read_text()
