"""Gaze IK (validation/gaze.py): fixation checked by independent FK, limits, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from cpc2urdf.errors import ConfigurationError, UnknownNameError
from cpc2urdf.model_file import load_model
from cpc2urdf.tolerances import GAZE_POINTING_TOL
from cpc2urdf.validation.gaze import GazeSolver


@pytest.fixture(scope="module")
def nominal():
    return load_model("iis_head")


@pytest.fixture(scope="module")
def solver(nominal):
    return GazeSolver.from_model(nominal)


def _errors(model, q, p):
    """Pointing error of each eye [rad] from the CPC model's own FK (not Pinocchio)."""
    T = model.fk(q)
    out = []
    for cam in ("camera_left_optical", "camera_right_optical"):
        pc = T[cam][:3, :3].T @ (p - T[cam][:3, 3])
        out.append(np.arctan2(np.hypot(pc[0], pc[1]), pc[2]))
    return np.array(out)


def test_fixates_a_target_ahead(nominal, solver):
    p = np.array([-0.6, -0.6, 0.7])
    sol = solver.solve(p)
    assert sol.reachable and sol.status == "fixated"
    assert np.all(_errors(nominal, sol.q, p) < GAZE_POINTING_TOL)
    assert np.all(sol.q >= solver.lower) and np.all(sol.q <= solver.upper)
    # cyclopean: table unmoved (home), zero version
    assert np.allclose(sol.q[:2], solver.home[:2])
    assert abs((sol.q[4] - solver.home[4]) + (sol.q[5] - solver.home[5])) < 1e-9
    assert np.linalg.norm(sol.fixation_point - p) < 1e-9
    assert set(sol.joints) == set(nominal.structure.joint_names)


def test_bad_input(solver):
    for bad in ([np.nan, 0, 0], [0, 0], [[0, 0, 1]], [0, np.inf, 1], "abc"):
        with pytest.raises(ConfigurationError):
            solver.solve(bad)
    with pytest.raises(ConfigurationError):
        solver.solve([0, 0, 1], policy="nope")
    with pytest.raises(ConfigurationError):
        solver.solve([0, 0, 1], q_current=[0, 0, 0])
    with pytest.raises(UnknownNameError):
        GazeSolver.from_model(load_model("iis_head"), ("camera_left_optical", "nope"))
