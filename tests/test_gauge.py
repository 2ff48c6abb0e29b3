"""Frames stay on the parts: the gauge the data cannot see is chosen closest to the nominal model."""

from __future__ import annotations

import numpy as np
import pytest

from cpc2urdf.files.robot_ref import load_model
from cpc2urdf.identification.kinematics.closed_form import identify_closed_form
from cpc2urdf.identification.kinematics.gauge import (
    align_to_nominal,
    apply_gauge,
    gauge_size,
    gauge_transforms,
)
from cpc2urdf.identification.simulation.random_robots import random_model
from cpc2urdf.identification.simulation.stage1_experiment import simulate_experiment

EXACT = 1e-12  # [m]


@pytest.mark.parametrize("seed", range(6))
def test_a_gauge_move_changes_no_frame_and_moves_each_link_by_its_own_g(seed):
    rng = np.random.default_rng(seed)
    model = random_model(rng, 6, p_prismatic=0.4, extra_plates=1, cameras=1)
    g = rng.normal(0.0, 0.3, gauge_size(model))
    moved = apply_gauge(model, g)
    q = rng.uniform(
        model.structure.lower, model.structure.upper, size=(5, model.structure.n_joints)
    )
    a, b = model.fk(q), moved.fk(q)
    for f in a:
        np.testing.assert_allclose(b[f], a[f], rtol=0, atol=EXACT, err_msg=f)
    _, G = gauge_transforms(model, g)
    _, link_a = model.link_poses(q)
    _, link_b = moved.link_poses(q)
    for i, name in enumerate(model.structure.joint_names):
        np.testing.assert_allclose(
            link_b[:, i], link_a[:, i] @ G[name], rtol=0, atol=EXACT, err_msg=name
        )


def test_alignment_undoes_a_scrambled_gauge_exactly():
    nominal = load_model("iis_head")
    rng = np.random.default_rng(3)
    scrambled = apply_gauge(nominal, rng.normal(0.0, 0.5, gauge_size(nominal)))
    back = align_to_nominal(scrambled, nominal)
    q = nominal.structure.calibration_ranges().mean(axis=1)
    _, a = back.link_poses(q)
    _, b = nominal.link_poses(q)
    Ta, Tb = back.world_to_base.matrix(), nominal.world_to_base.matrix()
    np.testing.assert_allclose(np.linalg.inv(Ta) @ a[0], np.linalg.inv(Tb) @ b[0], atol=1e-9)


@pytest.mark.parametrize("seed", range(3))
def test_identified_links_sit_on_the_true_parts(seed):
    # The closed form alone puts base, table and pan frames ~1.37 m from the true head's; after
    # alignment every link frame is within 3x of how far the truth is from the drawing.
    nominal = load_model("iis_head")
    truth, ms, held = simulate_experiment("iis_head", seed=seed, n_heldout=10, noise="none")
    model, _ = identify_closed_form(ms, nominal)
    aligned = align_to_nominal(model, nominal)
    q = held.q
    frames = ["plate_left", "plate_right", "camera_left_optical", "camera_right_optical"]
    before, after = model.fk(q, frames), aligned.fk(q, frames)
    for f in frames:
        np.testing.assert_allclose(after[f], before[f], rtol=0, atol=EXACT)
    _, L_model = model.link_poses(q)
    _, L_aligned = aligned.link_poses(q)
    _, L_truth = truth.link_poses(q)
    _, L_nominal = nominal.link_poses(q)
    nominal_in_world = np.einsum(
        "ij,nkjl->nkil",
        truth.world_to_base.matrix() @ np.linalg.inv(nominal.world_to_base.matrix()),
        L_nominal,
    )

    def dist(X, Y):
        return np.linalg.norm(X[..., :3, 3] - Y[..., :3, 3], axis=-1).max(axis=0)

    assert dist(L_model, L_truth).max() > 1.0  # the problem: a metre off before
    true_error = dist(nominal_in_world, L_truth)
    assert dist(L_aligned, L_truth).max() <= 3.0 * true_error.max()
    assert dist(L_aligned, L_truth).max() < 0.01
