"""Rank analysis: full rank for the protocol, named and explained deficiency when a joint never moved."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from refine_sim import measure, perturbed, protocol_q, random_q

from cpc2urdf.files.robot_ref import load_model
from cpc2urdf.identification.kinematics.identifiability import (
    IdentifiabilityWarning,
    analyze_jacobian,
    triangular_factor,
)
from cpc2urdf.identification.kinematics.refine import refine
from cpc2urdf.identification.kinematics.uncertainty import predicted_position_std

PLATES = ("plate_left", "plate_right")
SIGMA_T, SIGMA_R = 0.5e-3, np.radians(0.5)


@pytest.fixture(scope="module")
def head():
    return load_model("iis_head")


def test_triangular_factor_has_the_singular_values_of_its_matrix():
    rng = np.random.default_rng(0)
    A = rng.normal(size=(200, 12)) * np.logspace(0, -6, 12)
    A[:, 7] = A[:, 2] - 2.0 * A[:, 5]  # exactly rank-deficient
    R = triangular_factor(A)
    np.testing.assert_allclose(R.T @ R, A.T @ A, atol=1e-12)
    np.testing.assert_allclose(
        np.linalg.svd(R, compute_uv=False), np.linalg.svd(A, compute_uv=False), atol=1e-13
    )


def test_protocol_data_determine_all_32(head):
    rng = np.random.default_rng(0)
    truth = perturbed(head, rng)
    res = refine(truth, measure(truth, protocol_q(truth, 9), rng, SIGMA_T, SIGMA_R))
    rep = res.identifiability
    assert rep.full_rank and rep.rank == 32 and not rep.undetermined and not rep.warnings
    assert np.isfinite(rep.condition_number) and 1.0 < rep.condition_number < 1e4
    assert np.all(np.diff(rep.singular_values) <= 0)


def test_joint_never_moved_is_named_with_its_reason(head):
    rng = np.random.default_rng(1)
    truth = perturbed(head, rng)
    q = protocol_q(truth, 6)
    tilt = head.structure.joint_index("tilt")
    q = q[q[:, tilt] == q[0, tilt]]  # drop the tilt sweep: tilt stays at q0
    ms = measure(truth, q, rng, 0.0, 0.0)
    with pytest.warns(IdentifiabilityWarning, match="tilt") as record:
        res = refine(perturbed(truth, rng, 1e-3, 0.003), ms, SIGMA_T, SIGMA_R)
    rep = res.identifiability
    assert rep.rank == 28 and rep.null_space.shape == (32, 4)
    assert {"tilt.b_x", "tilt.b_y", "tilt.l_x", "tilt.l_y"} <= set(rep.undetermined)
    assert "never moved" in rep.reasons["tilt"] and "'tilt'" in rep.reasons["tilt"]
    assert any("never moved" in str(w.message) for w in record)
    # No silently wrong number: undetermined parameters have no standard deviation ...
    std = res.covariance.std
    for name in ("tilt.b_x", "tilt.l_y"):
        assert np.isnan(std[res.parametrization.index(name)])
    assert np.isfinite(std[res.parametrization.index("table_x.b_x")])
    # ... the fit still reproduces every record (the data are consistent) ...
    assert res.translation_rms < 1e-9
    # ... and predictions are determined only where tilt stays at its one reading.
    q_same = random_q(truth, 5, rng)
    q_same[:, tilt] = q[0, tilt]
    q_other = q_same.copy()
    q_other[:, tilt] += 0.2
    assert np.all(np.isfinite(predicted_position_std(res.model, q_same)["plate_left"]))
    assert np.all(np.isinf(predicted_position_std(res.model, q_other)["plate_left"]))


def test_one_plate_never_measured_is_reported(head):
    rng = np.random.default_rng(2)
    truth = perturbed(head, rng)
    ms = measure(truth, protocol_q(truth, 4), rng, 0.0, 0.0)
    ms.poses["plate_right"][:] = np.nan
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # fitting the measured plate only is fully determined
        res = refine(perturbed(truth, rng, 1e-3, 0.003), ms)
    assert res.parametrization.frames == ("plate_left",) and res.identifiability.rank == 22


def test_report_on_a_hand_made_jacobian():
    rng = np.random.default_rng(3)
    J = rng.normal(size=(30, 4))
    J[:, 3] = 0.0  # this parameter does nothing
    with pytest.warns(IdentifiabilityWarning, match=r"c\.x"):
        rep = analyze_jacobian(
            J, ["a.x", "a.y", "b.x", "c.x"], reasons={"c": "frame 'c' has no measured pose"}
        )
    assert rep.rank == 3 and rep.undetermined == ["c.x"] and np.isinf(rep.condition_number)
    assert "frame 'c' has no measured pose" in rep.warnings[0]
    J[:, 3] = J[:, 0] + 1e-7 * rng.normal(size=30)  # nearly collinear: determined only in principle
    with pytest.warns(IdentifiabilityWarning, match="poorly determined"):
        rep = analyze_jacobian(J, ["a.x", "a.y", "b.x", "c.x"])
    assert rep.rank == 4 and rep.condition_number > 1e6
    with pytest.raises(ValueError, match="names"):
        analyze_jacobian(J, ["a.x"])
