"""Gaze tracking (cpc2urdf/validation/gaze/tracking.py): smooth pursuit and minimum-jerk saccades.

The saccade's profile is checked against what defines minimum jerk, not against the formula the
code uses: a degree-5 polynomial fitted to the commanded samples (numpy.polyfit) must reproduce
them, with zero velocity and acceleration at both ends. Fixation after a saccade is checked with
the CPC model's own FK (not Pinocchio, which the solver uses).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from gaze_heads import model_pointing_errors

from cpc2urdf.errors import ConfigurationError
from cpc2urdf.files.robot_ref import load_model
from cpc2urdf.identification.simulation.heads import (
    calibrated_iis_head,
    eyes_coplanar,
    reachable_targets,
)
from cpc2urdf.tolerances import GAZE_POINTING_TOL
from cpc2urdf.validation.crosscheck import yourdfpy_pose
from cpc2urdf.validation.gaze import GazeSolver
from cpc2urdf.validation.gaze.tracking import (
    MIN_JERK_PEAK_ACCELERATION,
    MIN_JERK_PEAK_VELOCITY,
    SACCADE_STATUSES,
    GazeTracker,
    SaccadeRule,
    minimum_jerk,
    track,
)

DT = 1e-3
FAST = 4.0  # the tests' speed limits: the URDF's times this (shorter saccades, shorter tests)


@pytest.fixture(scope="module")
def heads():
    return {}


@pytest.fixture(params=["nominal", "calibrated"])
def head(request, heads):
    """Both heads (a test that needs only the nominal one is parametrized with ``head=["nominal"]``)."""
    if request.param not in heads:
        model = load_model("iis_head") if request.param == "nominal" else calibrated_iis_head(0)
        heads[request.param] = (model, GazeSolver.from_model(model))
    return heads[request.param]


def _assert_on_answer(solver, model, tr, P, where):
    """Samples ``where`` are the solver's answers for their targets, and point as the CPC model's
    FK says; to within the tolerance where the head fixates exactly (nominal)."""
    np.testing.assert_array_equal(tr.q[where], tr.q_goal[where])
    Q, Pw = tr.q[where][::25], P[where][::25]
    err = model_pointing_errors(model, Q, Pw)
    np.testing.assert_allclose(tr.pointing_error[where][::25], err, rtol=1e-6, atol=1e-11)
    if eyes_coplanar(model):
        assert tr.reachable[where].all() and np.all(err < GAZE_POINTING_TOL)


def _two_targets(model):
    """Two reachable targets whose readings are well inside the limits, about 25 deg of pan apart."""
    P, Q = reachable_targets(model, 400, seed=3)
    s = model.structure
    lo, hi = s.lower, s.upper
    inner = np.all((Q >= lo + 0.2 * (hi - lo)) & (Q <= hi - 0.2 * (hi - lo)), axis=1)
    P, Q = P[inner], Q[inner]
    ip = s.joint_index("pan")
    gap = np.abs(np.abs(Q[:, None, ip] - Q[None, :, ip]) - math.radians(25.0))
    i, j = np.unravel_index(int(np.argmin(gap)), gap.shape)
    assert abs(Q[j, ip] - Q[i, ip]) > math.radians(20.0)
    return P[i], P[j]


def test_minimum_jerk_profile_function():
    s = np.linspace(0.0, 1.0, 100_001)
    f, df, ddf = minimum_jerk(s)
    assert f[0] == 0.0 and f[-1] == 1.0
    assert df[0] == df[-1] == ddf[0] == ddf[-1] == 0.0
    h = s[1] - s[0]
    assert (
        np.max(np.abs(np.gradient(f, h)[1:-1] - df[1:-1])) < 1e-8
    )  # derivatives by finite differences
    assert np.max(np.abs(np.gradient(df, h)[1:-1] - ddf[1:-1])) < 1e-7
    np.testing.assert_allclose(df, df[::-1], atol=1e-12)  # a symmetric bell
    assert np.all(np.diff(df[: s.size // 2 + 1]) >= 0) and np.all(np.diff(df[s.size // 2 :]) <= 0)
    assert df.max() == pytest.approx(MIN_JERK_PEAK_VELOCITY, abs=1e-12)
    assert np.abs(ddf).max() == pytest.approx(MIN_JERK_PEAK_ACCELERATION, abs=1e-8)
    assert np.abs(ddf[np.argmax(ddf)] - minimum_jerk((3 - math.sqrt(3)) / 6)[2]) < 1e-8


@pytest.mark.parametrize(
    "head, max_acceleration",
    [("nominal", None), ("calibrated", None), ("nominal", 40.0)],
    indirect=["head"],
)
def test_saccade_is_minimum_jerk_and_locks_on(head, max_acceleration):
    """Static target A, then B: one saccade, min-jerk, within the limits, ending exactly at the answer."""
    model, solver = head
    A, B = _two_targets(model)
    hold = 20
    after = 60
    P = np.vstack([np.repeat(A[None], hold, axis=0), np.repeat(B[None], 600, axis=0)])
    rule = SaccadeRule(max_acceleration=max_acceleration)
    q0 = solver.solve(A).q
    vmax = FAST * solver.velocity_limit
    tr = track(solver, P, DT, vmax, q_current=q0, saccades=rule)
    # one saccade, starting when the target jumps
    sac = np.flatnonzero(tr.saccade)
    assert sac.size and sac[0] == hold and np.all(np.diff(sac) == 1)
    N = sac.size
    start, goal = tr.q[hold - 1], tr.q_goal[hold]
    delta = goal - start
    # the duration rule: the fewest samples within the velocity (and acceleration) limits
    T = max(rule.min_duration, float(np.max(MIN_JERK_PEAK_VELOCITY * np.abs(delta) / vmax)))
    if max_acceleration is not None:
        T = max(
            T,
            math.sqrt(float(np.max(MIN_JERK_PEAK_ACCELERATION * np.abs(delta) / max_acceleration))),
        )
    assert N == math.ceil(T / DT - 1e-9)
    # ends exactly at the solver's answer for the target at its onset
    assert np.array_equal(tr.q[sac[-1]], goal)
    # a quintic through the samples, with zero velocity and acceleration at both ends
    t = np.arange(N + 1) * DT
    seg = tr.q[hold - 1 : sac[-1] + 1]
    k = int(np.argmax(np.abs(delta)))
    poly = np.polynomial.Polynomial.fit(t, seg[:, k], 5)
    assert np.max(np.abs(poly(t) - seg[:, k])) < 1e-9 * abs(delta[k])
    scale_v, scale_a = abs(delta[k]) / t[-1], abs(delta[k]) / t[-1] ** 2
    for end in (0.0, t[-1]):
        assert abs(poly.deriv(1)(end)) < 1e-6 * scale_v
        assert abs(poly.deriv(2)(end)) < 1e-5 * scale_a
    # a symmetric bell of sampled velocity, never over the limit anywhere in the trajectory
    v = np.diff(seg, axis=0) / DT
    np.testing.assert_allclose(v, v[::-1], atol=1e-9 * np.max(np.abs(v)))
    v_all = np.abs(np.diff(np.vstack([q0, tr.q]), axis=0)) / DT
    assert np.all(v_all <= vmax * (1 + 1e-12))
    if (
        max_acceleration is None
    ):  # the shortest such saccade: the limiting joint nearly at its speed limit
        assert np.max(np.abs(v) / vmax) > 0.98
    else:
        a = np.abs(np.diff(seg, n=2, axis=0)) / DT**2
        assert np.all(a <= max_acceleration * (1 + 1e-9))
        assert a.max() > 0.95 * max_acceleration  # here the acceleration limit sets the duration
    # then the eyes lock on B (pursuit of a still target): on the solver's answer, whose pointing
    # error the CPC model's FK confirms (below the tolerance where the head can fixate exactly)
    rest = slice(sac[-1] + 1, sac[-1] + 1 + after)
    assert tr.locked[rest].all() and not tr.saccade[sac[-1] + 1 :].any()
    _assert_on_answer(solver, model, tr, P, rest)


@pytest.mark.parametrize("head", ["nominal"], indirect=True)
def test_saccade_then_pursuit_of_a_moving_target(head):
    """A target circling about A, then about B: a saccade, then smooth pursuit locks on again."""
    model, solver = head
    A, B = _two_targets(model)
    t = np.arange(700) * DT
    centre = np.where((t < 0.1)[:, None], A, B)
    w = 2 * math.pi
    P = centre + 0.03 * np.stack([np.cos(w * t), np.sin(w * t), np.zeros_like(t)], axis=1)
    vmax = FAST * solver.velocity_limit
    tr = track(solver, P, DT, vmax, saccades=SaccadeRule())
    v = np.abs(np.diff(tr.q, axis=0)) / DT
    assert np.all(v <= vmax * (1 + 1e-12))
    sac = np.flatnonzero(tr.saccade)
    assert sac.size and sac[0] == 100 and np.all(np.diff(sac) == 1)
    # the target moves within the threshold during the saccade (no re-aim): afterwards pursuit
    # catches up and stays locked on the moving target
    tail = slice(sac[-1] + 150, None)
    assert tr.q.shape[0] - (sac[-1] + 150) >= 100
    assert tr.locked[tail].all()
    _assert_on_answer(solver, model, tr, P, tail)


@pytest.mark.parametrize("head", ["nominal"], indirect=True)
def test_without_saccades_pursuit_only(head):
    """saccades=None: the velocity-limited pursuit, never a saccade; the tracker's steps are track()."""
    model, solver = head
    A, B = _two_targets(model)
    P = np.vstack([np.repeat(A[None], 20, axis=0), np.repeat(B[None], 200, axis=0)])
    q0 = solver.solve(A).q
    tr = track(solver, P, DT, q_current=q0)
    assert not tr.saccade.any()
    step = solver.velocity_limit * DT
    d = np.abs(np.diff(np.vstack([q0, tr.q]), axis=0))
    assert np.all(d <= step * (1 + 1e-12))
    assert np.any(np.isclose(d[20:], step).any(axis=1))  # the jump is caught up at the limit
    tracker = GazeTracker(solver, DT, q_current=q0)
    Q = np.array([tracker.step(p).q for p in P])
    np.testing.assert_array_equal(Q, tr.q)


@pytest.mark.parametrize("head", ["nominal"], indirect=True)
def test_bad_input(head):
    _, solver = head
    P = np.zeros((3, 3)) + [0.0, 0.0, 1.0]
    for rule in (
        SaccadeRule(threshold=-1.0),
        SaccadeRule(threshold=math.nan),
        SaccadeRule(min_duration=-0.1),
        SaccadeRule(max_acceleration=0.0),
        SaccadeRule(max_acceleration=(1.0, 2.0)),
        SaccadeRule(max_acceleration=math.inf),
    ):
        with pytest.raises(ConfigurationError, match="saccade"):
            track(solver, P, DT, saccades=rule)
    with pytest.raises(ConfigurationError, match="max_velocity"):
        track(solver, P, DT, max_velocity=[1.0, 2.0])
    with pytest.raises(ConfigurationError, match="dt"):
        GazeTracker(solver, 0.0)
    with pytest.raises(ConfigurationError, match="target"):
        GazeTracker(solver, DT).step([0.0, math.nan, 1.0])


@pytest.mark.parametrize("head", ["nominal"], indirect=True)
@pytest.mark.parametrize("turn", ["on", "back"])
def test_a_saccade_whose_target_moves_on_hands_over_to_pursuit(head, turn):
    """A, then B, then C while the saccade to B is under way (C further on, or back past A): at
    its next check (every reaim_interval) the saccade ends, pursuit heads for C's answer from the
    commanded readings, and a new saccade may start only an interval later. Every sample within
    the speed limits and the joint limits, none past the span of the three answers (the old
    ballistic saccade ran on to B's answer); locked on C at the end."""
    model, solver = head
    A, B = _two_targets(model)
    C = B + 0.5 * (B - A) if turn == "on" else A - 0.5 * (B - A)
    hold, jump = 20, 120
    P = np.vstack(
        [
            np.repeat(A[None], hold, axis=0),
            np.repeat(B[None], jump - hold, axis=0),
            np.repeat(C[None], 1500, axis=0),
        ]
    )
    rule = SaccadeRule()
    interval = round(rule.reaim_interval / DT)
    q0 = solver.solve(A).q
    vmax = solver.velocity_limit  # the URDF's: a saccade of ~180 samples
    tr = track(solver, P, DT, vmax, q_current=q0, saccades=rule)
    first = rule.duration(tr.q_goal[hold] - q0, vmax, DT)
    assert first > jump - hold + interval  # the first saccade would run well past the jump
    check = hold + interval * math.ceil((jump - hold) / interval)  # its first check after the jump
    assert tr.saccade[hold:check].all() and not tr.saccade[check : check + interval - 1].any()
    Q = np.vstack([q0, tr.q])
    assert np.all(np.abs(np.diff(Q, axis=0)) / DT <= vmax * (1 + 1e-9))
    assert np.all(tr.q >= solver.lower) and np.all(tr.q <= solver.upper)
    goals = np.vstack([q0, tr.q_goal[hold], tr.q_goal[-1]])
    assert np.all(Q >= goals.min(axis=0) - 1e-12) and np.all(Q <= goals.max(axis=0) + 1e-12)
    assert not np.allclose(tr.q[check:], tr.q_goal[hold])  # never went on to B's answer
    assert tr.locked[-1] and tr.pointing_error[-1].max() < GAZE_POINTING_TOL
    np.testing.assert_array_equal(tr.q[-1], tr.q_goal[-1])


@pytest.mark.parametrize("head", ["nominal"], indirect=True)
def test_no_saccade_towards_a_target_the_head_cannot_point_at(head):
    """A target behind the head: pursued towards the best answer, never a saccade; back ahead
    once the head has come to rest there, a saccade again."""
    model, solver = head
    A, _ = _two_targets(model)
    behind = np.array([0.0, 2.0, 0.7])
    assert solver.solve(behind).status not in SACCADE_STATUSES
    away = 20 + 1500
    P = np.vstack(
        [
            np.repeat(A[None], 20, axis=0),
            np.repeat(behind[None], away - 20, axis=0),
            np.repeat(A[None], 800, axis=0),
        ]
    )
    tr = track(
        solver,
        P,
        DT,
        FAST * solver.velocity_limit,
        q_current=solver.solve(A).q,
        saccades=SaccadeRule(),
    )
    assert not tr.saccade[:away].any() and not tr.reachable[20:away].any()
    assert tr.locked[away - 1]  # at rest on the best answer behind
    assert tr.saccade[away] and tr.locked[-1]


@pytest.mark.parametrize("head", ["nominal"], indirect=True)
def test_a_head_pursuing_at_speed_starts_no_saccade(head):
    """A target running away faster than pursuit follows: the head pursues at its speed limit and
    no saccade starts (one from rest would stop it, then be ended when its end point went stale:
    stop and go every interval, worse than pursuit alone). The commands are pursuit's."""
    model, solver = head
    A, _ = _two_targets(model)
    q0 = solver.solve(A).q
    R, o = solver.camera_poses(q0)[0][:3, :3], solver.camera_poses(q0)[0][:3, 3]
    d = float(np.linalg.norm(A - o))
    t = np.arange(800) * DT
    w = 2 * math.pi * 1.5  # [rad/s] about the left camera: faster than the head turns
    P = o + d * (np.cos(w * t)[:, None] * (A - o) / d + np.sin(w * t)[:, None] * R[:, 0])
    vmax = solver.velocity_limit
    with_saccades = track(solver, P, DT, vmax, q_current=q0, saccades=SaccadeRule())
    pursuit = track(solver, P, DT, vmax, q_current=q0)
    assert not with_saccades.saccade.any()
    np.testing.assert_array_equal(with_saccades.q, pursuit.q)
    assert (
        np.median(pursuit.pointing_error.max(axis=1)) > SaccadeRule().threshold
    )  # it does run away


MIMIC_HEAD = """<?xml version="1.0"?>
<robot name="mimic_head">
  <link name="world"/><link name="lift_link"/><link name="pan_link"/><link name="tilt_link"/>
  <link name="tilt2_link"/><link name="cam_optical"/><link name="gripper"/>
  <joint name="lift" type="prismatic"><origin xyz="0 0 1.0"/><axis xyz="0 0 1"/>
    <parent link="world"/><child link="lift_link"/><limit lower="0" upper="0.3" effort="1" velocity="0.1"/></joint>
  <joint name="pan" type="revolute"><origin xyz="0 0 0.2"/><axis xyz="0 0 1"/>
    <parent link="lift_link"/><child link="pan_link"/><limit lower="-2.5" upper="2.5" effort="1" velocity="2"/></joint>
  <joint name="tilt" type="revolute"><origin xyz="0.02 0 0.08"/><axis xyz="0 1 0"/>
    <parent link="pan_link"/><child link="tilt_link"/><limit lower="-0.6" upper="0.6" effort="1" velocity="2"/></joint>
  <joint name="tilt2" type="revolute"><origin xyz="0.03 0 0.02"/><axis xyz="0 1 0"/>
    <parent link="tilt_link"/><child link="tilt2_link"/><limit lower="-0.3" upper="0.3" effort="1" velocity="2"/>
    <mimic joint="tilt" multiplier="0.5" offset="0"/></joint>
  <joint name="cam_joint" type="fixed"><origin xyz="0.05 0 0.03" rpy="-1.5707963267948966 0 -1.5707963267948966"/>
    <parent link="tilt2_link"/><child link="cam_optical"/></joint>
  <joint name="gripper_joint" type="prismatic"><origin xyz="1 0 0"/><axis xyz="1 0 0"/>
    <parent link="world"/><child link="gripper"/><limit lower="0" upper="0.04" effort="1" velocity="0"/></joint>
</robot>
"""


@pytest.fixture(scope="module")
def mimic_head(tmp_path_factory):
    from cpc2urdf.validation.gaze import solver_for

    path = tmp_path_factory.mktemp("mimic") / "mimic_head.urdf"
    path.write_text(MIMIC_HEAD)
    return path, solver_for(path, ["cam_optical"])


def test_pursuit_keeps_a_mimic_relation(mimic_head):
    """A URDF <mimic> follower moves with its driver on every pursuit sample (one fraction of
    their steps), within both joints' speed limits; the other joints move on their own."""
    _, solver = mimic_head
    names = solver.joint_names
    it, i2, ip = names.index("tilt"), names.index("tilt2"), names.index("pan")
    assert [sorted(g.tolist()) for g in solver.motion_groups] == [sorted([it, i2])]
    a, b = np.array([2.0, 0.0, 1.3]), np.array([0.8, 1.2, 0.7])
    qa = solver.solve(a).q
    P = np.vstack(
        [np.repeat(a[None], 10, axis=0), np.repeat(b[None], 1200, axis=0)]
    )  # tilt: 0.28 rad to go
    vmax = {
        "tilt": 0.3
    }  # the driver slower than its follower's share: the pair moves at the driver's pace
    tr = solver.track(P, DT, vmax, q_current=qa)
    assert np.abs(tr.q[:, i2] - 0.5 * tr.q[:, it]).max() < 1e-12
    step = np.abs(np.diff(np.vstack([qa, tr.q]), axis=0))
    assert np.all(step[:, it] <= 0.3 * DT * (1 + 1e-12)) and np.all(
        step[:, i2] <= 2.0 * DT * (1 + 1e-12)
    )
    assert np.isclose(step[:, ip], 2.0 * DT).any()  # pan alone at its own limit
    assert tr.locked[-1] and tr.reachable[-1]


def test_speed_limits_named_joint_by_joint(mimic_head):
    """max_velocity as {joint: limit}, per joint or one scalar over joints of one kind; a joint the
    head moves needs a positive limit (named when it has none), one it does not move may have
    none (the gripper's URDF velocity="0")."""
    from cpc2urdf.validation.gaze import solver_for
    from cpc2urdf.validation.gaze.tracking import speed_limits

    path, solver = mimic_head
    names = solver.joint_names
    moved = solver.free_joints("cyclopean")
    assert names.index("gripper_joint") not in moved.tolist()
    v = GazeTracker(solver, DT).max_velocity  # URDF limits; the gripper's 0 is not moved
    assert v[names.index("lift")] == 0.1 and v[names.index("gripper_joint")] == 0.0
    v = speed_limits(solver, {"pan": 0.5}, moved)
    assert (
        v[names.index("pan")] == 0.5
        and v[names.index("tilt")] == 2.0
        and v[names.index("lift")] == 0.1
    )
    with pytest.raises(
        ConfigurationError, match="rad/s on revolute joints and m/s on prismatic ones .lift"
    ):
        GazeTracker(solver, DT, 1.0)
    with pytest.raises(ConfigurationError, match="unknown joint 'nope'"):
        GazeTracker(solver, DT, {"nope": 1.0})
    zero = np.ones(len(names))
    zero[names.index("lift")] = 0.0
    with pytest.raises(
        ConfigurationError, match=r"joint .lift. moves the cameras .* \(from max_velocity\)"
    ):
        GazeTracker(solver, DT, zero)
    no_lift_speed = path.with_name("no_lift_speed.urdf")
    no_lift_speed.write_text(
        MIMIC_HEAD.replace(
            'upper="0.3" effort="1" velocity="0.1"', 'upper="0.3" effort="1" velocity="0"'
        )
    )
    with pytest.raises(ConfigurationError, match="joint 'lift' .* URDF <limit velocity>"):
        GazeTracker(solver_for(no_lift_speed, ["cam_optical"]), DT)
    # one kind of joint: a scalar is every moved joint's limit
    pan_tilt = solver_for(path, ["cam_optical"], joints=["pan", "tilt"])
    v = GazeTracker(pan_tilt, DT, 1.5).max_velocity
    assert v[names.index("pan")] == v[names.index("tilt")] == 1.5 and v[names.index("lift")] == 0.0
    # numbers as numpy gives them; not a bool, not a rule of another type, not degrees
    assert GazeTracker(solver, np.float32(1e-3)).dt == pytest.approx(1e-3)
    with pytest.raises(ConfigurationError, match="dt"):
        GazeTracker(solver, True)
    with pytest.raises(ConfigurationError, match="SaccadeRule"):
        GazeTracker(solver, DT, saccades=True)
    with pytest.raises(ConfigurationError, match=r"\[0, pi\)"):
        GazeTracker(solver, DT, saccades=SaccadeRule(threshold=5.0))
    for bad in (True, [True] * len(names), ["1"] * len(names)):
        with pytest.raises(ConfigurationError, match="max_velocity must be"):
            GazeTracker(solver, DT, bad)
    with pytest.raises(ConfigurationError, match="max_acceleration"):
        GazeTracker(solver, DT, saccades=SaccadeRule(max_acceleration="5"))  # type: ignore[arg-type]
    with pytest.raises(ConfigurationError, match="reaim_interval"):
        GazeTracker(solver, DT, saccades=SaccadeRule(reaim_interval=0.0))


# ---- every head shape: one camera (TIAGo), a rigid stereo pair; checked on yourdfpy's FK ----


@pytest.fixture(scope="module", params=["tiago", "stereo_pan_tilt"])
def other_head(request, tmp_path_factory):
    from gaze_heads import head_case

    return head_case(request.param, tmp_path_factory.mktemp(request.param))


def test_tracking_on_one_camera_and_rigid_pair_heads(other_head):
    """GazeSolver.track (with saccades) on heads without two independent eyes: a target that jumps,
    then moves; the commanded readings stay in the limits and under the speed limit (between
    saccades), end locked on a fixated answer, and the pointing error the tracker reports of its
    commanded posture is what yourdfpy's FK (independent of the chain's) gives."""
    from gaze_heads import pointing_errors, yourdfpy_axes

    solver = other_head.solver
    P_reach, _ = other_head.reachable_targets(2, seed=7)
    t = np.linspace(0.0, 1.0, 400)[:, None]
    moving = P_reach[1] + 0.02 * np.hstack([np.sin(3 * t), np.cos(2 * t) - 1.0, 0.0 * t])
    P = np.vstack(
        [np.repeat(P_reach[:1], 100, axis=0), moving, np.repeat(moving[-1:], 600, axis=0)]
    )
    vmax = FAST * solver.velocity_limit
    tr = solver.track(P, DT, vmax, q_current=solver.home, saccades=SaccadeRule())
    assert tr.q.shape == (len(P), solver.n) and tr.joint_names == solver.joint_names
    assert np.all(tr.q >= solver.lower - 1e-12) and np.all(tr.q <= solver.upper + 1e-12)
    assert tr.saccade.any() and tr.reachable.all()
    dq = np.abs(np.diff(tr.q, axis=0))
    pursuit = ~(tr.saccade[1:] | tr.saccade[:-1])
    assert np.all(dq[pursuit] <= vmax * DT * (1 + 1e-9) + 1e-15)
    assert tr.locked[-1] and tr.pointing_error[-1].max() < GAZE_POINTING_TOL
    pick = np.arange(0, len(P), 97)
    O, Z = yourdfpy_axes(other_head, tr.q[pick])
    assert np.allclose(pointing_errors(O, Z, P[pick]), tr.pointing_error[pick], rtol=0, atol=1e-9)


def test_camera_poses_of_any_head_match_yourdfpy(other_head):
    """GazeSolver.camera_poses: the chain's FK of the named optical frames, as yourdfpy has them."""
    import yourdfpy

    solver = other_head.solver
    robot = yourdfpy.URDF.load(
        str(other_head.urdf), load_meshes=False, build_collision_scene_graph=False
    )
    order = [solver.joint_names.index(j) for j in robot.actuated_joint_names]
    rng = np.random.default_rng(2)
    lo, hi = solver.lower, solver.upper
    for _ in range(5):
        q = solver.home.copy()
        moved = solver.free_joints("cyclopean")
        q[moved] = rng.uniform(lo[moved], hi[moved])
        robot.update_cfg(q[order])
        poses = solver.camera_poses(q)
        assert len(poses) == len(other_head.cameras)
        for T, name in zip(poses, other_head.cameras, strict=True):
            assert np.allclose(T, yourdfpy_pose(robot, name, robot.base_link), rtol=0, atol=1e-12)


def test_warm_start_is_honoured(other_head):
    """solve(q_start=...) starts from the given readings: from a nearby answer it fixates the next
    target in fewer iterations than from the table, with the same kind of answer."""
    solver = other_head.solver
    P, _ = other_head.reachable_targets(20, seed=11)
    fewer = 0
    for p in P:
        first = solver.solve(p)
        nearby = p + np.array([0.003, -0.002, 0.001])
        cold, warm = solver.solve(nearby), solver.solve(nearby, q_start=first.q)
        assert warm.reachable and cold.reachable
        assert np.all(warm.q >= solver.lower) and np.all(warm.q <= solver.upper)
        fewer += warm.iterations < cold.iterations
    assert fewer >= len(P) // 2
    with pytest.raises(ConfigurationError):
        solver.solve(P[0], q_start=np.zeros(solver.n + 1))


def test_public_names_are_exported():
    import cpc2urdf.validation.gaze as gaze
    from cpc2urdf.validation.gaze import reachable as reach
    from cpc2urdf.validation.gaze import tracking

    for name in ("GazeTracker", "SaccadeRule", "TrackingStep", "minimum_jerk"):
        assert getattr(gaze, name) is getattr(tracking, name) and name in gaze.__all__
    for name in ("Region", "reachable_region", "make_grid"):
        assert getattr(gaze, name) is getattr(reach, name) and name in gaze.__all__
