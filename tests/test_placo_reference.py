"""placo's axis-align task as the gaze benchmark's second reference
(cpc2urdf/studies/placo_reference.py). placo is not one of our dependencies (placo 0.10.2 pins
pin==3.8.0): what runs without it is checked here always (the URDF it is given keeps the
kinematics; the heads it cannot state and a missing placo are named), and its answers, by an FK
that is not placo's, where it is installed (docs/gaze.md: a virtual environment of its own)."""

from __future__ import annotations

import sys

import numpy as np
import pytest
from gaze_heads import head_case

from cpc2urdf.identification.simulation.heads import reachable_targets
from cpc2urdf.studies.bench_gaze import bench_head, format_table
from cpc2urdf.studies.placo_reference import (
    FLOOR,
    MAX_STEPS,
    NOT_INSTALLED,
    kinematic_urdf,
    placo_reference,
)
from cpc2urdf.urdf.pinocchio import PinocchioRobot
from cpc2urdf.validation.gaze.reference import SolvedAxes


@pytest.fixture(scope="module")
def tiago_head():
    return bench_head("tiago")


def test_kinematic_urdf_drops_geometry_and_keeps_the_kinematics(tiago_head):
    head = tiago_head
    urdf = head.solver.robot.urdf
    assert urdf is not None and "<collision" in urdf and "<visual" in urdf
    text = kinematic_urdf(urdf)
    assert "<collision" not in text and "<visual" not in text
    a = PinocchioRobot.from_urdf(urdf, continuous_as_revolute=True)
    b = PinocchioRobot.from_urdf(text, continuous_as_revolute=True)
    assert a.joint_names == b.joint_names
    import pinocchio as pin

    cam = head.solver.cameras[0]
    da, db = a.model.createData(), b.model.createData()
    fa, fb = a.frame_id(cam), b.frame_id(cam)
    rng = np.random.default_rng(0)
    for _ in range(5):
        q = rng.uniform(np.maximum(a.lower, -3.0), np.minimum(a.upper, 3.0))
        pin.framesForwardKinematics(a.model, da, q)
        pin.framesForwardKinematics(b.model, db, q)
        np.testing.assert_array_equal(da.oMf[fa].homogeneous, db.oMf[fb].homogeneous)


@pytest.mark.parametrize(
    ("shape", "why"),
    [("icub", "couples, offsets or bounds"), ("stereo_pan_tilt", "cyclopean axis")],
)
def test_heads_placo_cannot_state_are_named(shape, why, tmp_path):
    case = head_case(shape, tmp_path)
    reason = placo_reference(case.solver)
    assert isinstance(reason, str) and why in reason


def test_a_coupling_with_an_offset_is_not_placos(tiago_head):
    """One joint as its own unknown, but offset and bounded by a stated coupling: placo would
    move it within the URDF's limits, not the coupling's bounds."""
    from cpc2urdf.validation.gaze import Coupling, GazeSolver

    coupling = Coupling(("head_1_joint",), ("pan",), [[1.0]], [0.2], [-0.3], [0.3])
    solver = GazeSolver(tiago_head.solver.robot, tiago_head.solver.cameras, coupling=coupling)
    reason = placo_reference(solver)
    assert isinstance(reason, str) and "offsets or bounds" in reason


def test_without_placo_the_bench_says_so(monkeypatch):
    monkeypatch.setitem(sys.modules, "placo", None)  # import placo raises ImportError
    head = bench_head("nominal")
    assert head.solver.robot.urdf is not None
    assert placo_reference(head.solver) == NOT_INSTALLED
    from cpc2urdf.studies.bench_gaze import _placo_run

    res = _placo_run(head.solver, SolvedAxes(head.solver), reachable_targets(head.model, 2, 0)[0])
    assert res == {"placo": NOT_INSTALLED}


def test_the_table_shows_placo_or_why_not():
    row = {
        "kind": "look-at",
        "kin_us": 5.0,
        "median_kin": 1.6,
        "p99_kin": 2.0,
        "p99_cpu_kin": 2.0,
        "unreachable_ratio": 1.5,
        "success": 1.0,
        "disparity": 0.0,
        "iterations_median": 4.0,
        "ratio": 60.0,
        "batch_targets_per_s": 4e5,
        "batch_path": "solve_many",
    }
    ran = {
        **row,
        "placo": "ran",
        "placo_ratio": 9.5,
        "placo_success": 0.1,
        "placo_within_floor": 0.96,
        "placo_over_1e-4": 0.02,
        "placo_error_median_rad": 5e-9,
        "placo_steps_median": 10.0,
        "placo_median_us": 140.0,
        "placo_core_median_us": 50.0,
        "placo_core_ratio": 3.4,
    }
    table = format_table({"a": ran, "b": {**row, "placo": NOT_INSTALLED}})
    lines = table.splitlines()
    header = lines[0].split()
    k = header.index("scipy")
    assert header[k + 1 : k + 3] == [
        "vs",
        "placo",
    ]  # the column after "vs scipy": a row's 11th cell
    assert lines[2].split()[10] == "9.5x" and lines[3].split()[10] == "n/a"
    assert (
        "placo on a: within 1e-9 rad on 10.0% of the targets, within its floor (3e-08 rad) on 96.0%"
        in table
    )
    assert "of which 50 us in placo's own calls (3.4x ours)" in table
    assert f"vs placo n/a: {NOT_INSTALLED}" in table


def test_placo_points_the_cameras():
    """Where placo is installed: its answers on the nominal IIS-head, by Pinocchio on our model
    (not placo's FK), are inside the limits and point both cameras at the target to its floor
    (its task's error is acos(a . t): ~2e-8 rad resolution)."""
    pytest.importorskip("placo")
    head = bench_head("nominal")
    solver = head.solver
    ref = placo_reference(solver)
    assert not isinstance(ref, str)
    P, _ = reachable_targets(head.model, 20, 3)
    axes = SolvedAxes(solver)
    errors = []
    held = np.setdiff1d(np.arange(solver.n), solver.free_joints("cyclopean"))  # the table's joints
    for p in P:
        q0 = solver.home.copy()
        q, steps = ref.solve(p, q0)
        assert 0 < steps <= MAX_STEPS and 0.0 < ref.core_seconds
        assert np.all(q >= solver.lower - 1e-9) and np.all(q <= solver.upper + 1e-9)
        np.testing.assert_array_equal(q[held], q0[held])
        errors.append(np.max(axes.pointing_errors(q, p)))
    assert np.median(errors) <= FLOOR
