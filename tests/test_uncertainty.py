"""Parameter covariance and its propagation to frame positions; the model-file section."""

from __future__ import annotations

import numpy as np
import pytest
from refine_sim import measure, perturbed, protocol_q, random_q

from cpc2urdf.files.model_file import save_model
from cpc2urdf.files.robot_ref import load_model
from cpc2urdf.identification.kinematics.parametrization import Parametrization
from cpc2urdf.identification.kinematics.problem import IdentificationProblem
from cpc2urdf.identification.kinematics.refine import refine
from cpc2urdf.identification.kinematics.uncertainty import (
    Covariance,
    NoUncertaintyError,
    covariance_of_model,
    position_covariance,
    predicted_position_std,
)
from cpc2urdf.model_metadata import ModelMetadata

PLATES = ("plate_left", "plate_right")
SIGMA_T, SIGMA_R = 0.5e-3, np.radians(0.5)


@pytest.fixture(scope="module")
def data():
    head = load_model("iis_head")
    rng = np.random.default_rng(0)
    truth = perturbed(head, rng)
    ms = measure(truth, protocol_q(truth, 9), rng, SIGMA_T, SIGMA_R)
    return truth, ms, refine(perturbed(truth, rng, 1e-3, 0.003), ms, SIGMA_T, SIGMA_R)


@pytest.fixture(scope="module")
def refined(data):
    truth, _, res = data
    return truth, res


def test_known_sigma_covariance_is_the_inverse_normal_matrix(data):
    _, ms, res = data
    # J at the optimum, rebuilt independently of covariance_from_jacobian (plain inverse here).
    use = {f: ms.has_pose(f) for f in PLATES}
    chart = Parametrization(res.model, PLATES)
    J = IdentificationProblem(chart, ms.q, ms.poses, use, SIGMA_T, SIGMA_R).jacobian(np.zeros(32))
    C = np.linalg.inv(J.T @ J)
    # Entries far below the largest carry cond(J^T J) (~2e5) times float eps of it: compare them
    # at that scale, the large ones to 1e-6 relative.
    np.testing.assert_allclose(res.covariance.matrix, C, rtol=1e-6, atol=1e-12 * np.abs(C).max())
    assert res.covariance.scale == "known" and 0.7 < res.covariance.variance_factor < 1.3


def test_a_posteriori_scale(refined):
    truth, res = refined
    rng = np.random.default_rng(1)
    ms = measure(truth, protocol_q(truth, 9), rng, SIGMA_T, SIGMA_R)
    known = refine(res.start, ms, SIGMA_T, SIGMA_R)
    post = refine(res.start, ms, SIGMA_T, SIGMA_R, covariance_scale="a_posteriori")
    np.testing.assert_allclose(
        post.covariance.matrix,
        known.covariance.variance_factor * known.covariance.matrix,
        rtol=1e-9,
    )
    # Sigmas 2x too large: the variance factor says so (about 1/4).
    big = refine(res.start, ms, 2 * SIGMA_T, 2 * SIGMA_R)
    assert 0.15 < big.covariance.variance_factor < 0.35


def test_position_std_agrees_with_sampling_the_parameters(refined):
    """Independent check of the propagation: sample x ~ N(0, C), push through the forward kinematics."""
    _, res = refined
    model, cov = res.model, res.covariance
    rng = np.random.default_rng(2)
    q = random_q(model, 4, rng)
    pred = predicted_position_std(model, q)
    chart = Parametrization(model, PLATES)
    L = np.linalg.cholesky(cov.matrix + 1e-30 * np.eye(32))
    p0 = model.fk(q, PLATES)
    dev = {f: [] for f in PLATES}
    for _ in range(400):
        m = chart.model_from_vector(L @ rng.normal(size=32))
        T = m.fk(q, PLATES)
        for f in PLATES:
            dev[f].append(np.linalg.norm(T[f][:, :3, 3] - p0[f][:, :3, 3], axis=1) ** 2)
    for f in PLATES:
        sampled = np.sqrt(np.mean(dev[f], axis=0))
        np.testing.assert_allclose(pred[f], sampled, rtol=0.12)
        assert np.all((pred[f] > 1e-5) & (pred[f] < 1e-3))  # tens to hundreds of micrometres
    noisy = predicted_position_std(model, q, measurement_noise=True)
    np.testing.assert_allclose(noisy["plate_left"] ** 2, pred["plate_left"] ** 2 + 3 * SIGMA_T**2)
    Sigma, det = position_covariance(model, cov, q, ["plate_left"])
    assert Sigma["plate_left"].shape == (4, 3, 3) and det["plate_left"].all()


def test_model_file_round_trip(refined, tmp_path):
    _, res = refined
    path = save_model(res.model, tmp_path / "refined.json")
    loaded = load_model(path)
    cov = covariance_of_model(loaded)
    assert cov.names == res.parametrization.names and cov.frames == PLATES
    np.testing.assert_allclose(cov.matrix, res.covariance.matrix, rtol=1e-12)
    q = random_q(loaded, 3, np.random.default_rng(3))
    a, b = predicted_position_std(loaded, q), predicted_position_std(res.model, q)
    for f in PLATES:
        np.testing.assert_allclose(a[f], b[f], rtol=1e-8)
    details = loaded.metadata.uncertainty.details
    assert details["identifiability"]["rank"] == 32 and details["outliers"] == []
    assert Covariance.from_json(loaded.metadata.uncertainty.to_json()).scale == "known"


def test_missing_or_bad_section(refined):
    _, res = refined
    q = random_q(res.model, 2, np.random.default_rng(4))
    bare = res.model.with_params(metadata=ModelMetadata())
    with pytest.raises(NoUncertaintyError, match="no 'uncertainty' section"):
        predicted_position_std(bare, q)
    # a broken section is refused when it is read (a model file never carries one past loading)
    with pytest.raises(NoUncertaintyError, match="bad 'uncertainty' section"):
        Covariance.from_json({"format": "something-else"})
    with pytest.raises(NoUncertaintyError, match="was not identified"):
        predicted_position_std(res.model, q, ["camera_left_optical"])
