"""Every policy a user can choose, by its behaviour, on the heads where they differ.

Before the Python (Pinocchio) solver was deleted, the compiled engine was compared with it on
these heads: 40 seeded targets each (half on the eyes' meeting curve, half 5 cm off), from
readings at or near the fixating ones. ``min-motion``: same status on 40/40 (nominal IIS-head,
``calibrated_iis_head(0)``, the demo's seed-2 head), both fixated 39/37/0, the compiled answer
never farther from ``q_current`` (by at most 1.2e-9 rad; nearer by up to 2.9e-4 rad where the
Python iteration stopped early), readings within 5e-4 / 3e-10 rad, never a larger error.
``eyes-only``: same readings where both fixated (20/20), same status on 40/39/40 (one
``joint_limits`` vs ``no_solution``, the same error), never a larger error.
"""

from __future__ import annotations

import numpy as np
import pytest

from cpc2urdf.files.robot_ref import load_model
from cpc2urdf.identification.simulation.heads import calibrated_iis_head, reachable_targets
from cpc2urdf.tolerances import GAZE_POINTING_TOL
from cpc2urdf.validation.gaze import GazeSolver

EYES = ["vergence_left", "vergence_right"]


@pytest.fixture(scope="module", params=["nominal", "calibrated"])
def head(request):
    model = load_model("iis_head") if request.param == "nominal" else calibrated_iis_head(0)
    return model, GazeSolver.from_model(model)


def test_min_motion_fixates_nearest_the_current_readings(head):
    """From readings that fixate a target, min-motion stays there; from readings nearby it fixates
    the target, the table still, no farther from them than the cyclopean answer."""
    model, solver = head
    P, Q = reachable_targets(model, 12, 3)
    rng = np.random.default_rng(0)
    for p, q in zip(P, Q, strict=True):
        at = solver.solve(p, q, "min-motion")
        assert at.reachable and np.max(np.abs(at.q - q)) < 1e-6
        qc = np.clip(q + rng.normal(0.0, 0.03, q.shape), solver.lower, solver.upper)
        mm = solver.solve(p, qc, "min-motion")
        assert mm.reachable and np.all(mm.q[:2] == qc[:2])
        cy = solver.solve(p, qc)
        if cy.reachable:
            assert np.linalg.norm(mm.q - qc) <= np.linalg.norm(cy.q - qc) + 1e-9


def test_eyes_only_moves_the_eyes_alone(head):
    _, solver = head
    free = [solver.joint_names[i] for i in solver.free_joints("eyes-only")]
    assert free == EYES
    q = solver.solve([-0.6, -0.6, 0.7]).q
    L, _ = solver.camera_poses(q)
    for p in (L[:3, 3] + 0.8 * L[:3, 2], np.array([-0.4, -0.6, 0.7])):
        sol = solver.solve(p, q, "eyes-only")
        assert np.all(sol.q[:4] == q[:4])
        assert sol.reachable == bool(sol.pointing_error.max() <= GAZE_POINTING_TOL)


def test_policies_on_every_head_shape_never_raise_but_eyes_only_without_eyes(tmp_path):
    """Every public member answers on a one-camera head; eyes-only says it needs two eyes."""
    from gaze_heads import head_case

    from cpc2urdf.errors import ConfigurationError

    case = head_case("tiago", tmp_path)
    solver = case.solver
    p = case.reachable_targets(1, 0)[0][0]
    for policy in ("cyclopean", "min-motion"):
        assert solver.solve(p, None, policy).status in ("fixated", "joint_limits")
        assert len(solver.free_joints(policy))
    assert solver.camera_poses(solver.home)[0].shape == (4, 4)
    with pytest.raises(ConfigurationError, match="two eyes"):
        solver.solve(p, None, "eyes-only")
