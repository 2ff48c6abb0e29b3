"""Benchmark: the gaze solver per head shape, against one Pinocchio FK + two frame Jacobians
and against a generic bounded least-squares IK on the same model, in one run.

Per head (:data:`HEADS`: the IIS-head nominal and calibrated, TIAGo and TALOS from
example-robot-data; ``--urdf FILE --camera ...`` adds any other), it reports:

- ``kin``: the median time of one Pinocchio forward kinematics plus two frame Jacobians from
  Python, measured before and after the solves; every time below is also given as a ratio to it;
- median and p99 time of one ``solve`` per reachable target, the success on them (fixated, or
  answered with the head's own disparity on a head that cannot fixate exactly), and the
  unreachable targets' median over the reachable one;
- the reference (:func:`scipy.optimize.least_squares`, trust-region reflective, bounds as
  bounds) on the same residual (per solved axis ``u - e_z``) with Pinocchio frame Jacobians, each
  target right after ours (so both see the same load); the ratio of the medians;
- where placo imports (it is not one of our dependencies: :mod:`cpc2urdf.studies.placo_reference`),
  a second reference: placo's axis-align task stepped to 1e-9 rad or its floor, each target right
  after ours from the same start as scipy's; the ratio of the medians and how close its answers
  point (by Pinocchio on our model); else the reason it did not run;
- batch throughput (targets/s of one ``solve_many`` over all the targets, best of 7);
- the 1 kHz tracking loop (:class:`~cpc2urdf.validation.gaze.tracking.GazeTracker`, smooth
  pursuit and minimum-jerk saccades) on every head: the p99 of one step
  against its 1 ms deadline, by the wall clock and by this thread's CPU time.
- the audit of "unreachable": random targets in a 6 m cube about the head (most out of reach);
  each one answered as not fixated is solved again from 20 random postures, and ``missed``
  counts those that one of them fixates (a fixatable target the solver called unreachable; a
  lower bound).

Targets are built *independently of the solver*. On the IIS-heads from the CPC model's own
forward kinematics (:meth:`cpc2urdf.model.CPCModel.fk`), so a target is reachable by
construction:

- sample neck and left-eye readings uniformly inside the limits (table at home);
- nominal head: sample the right eye too; the two optical axes are coplanar, so they meet at a
  point: the target (kept if it lies in front of both cameras, 0.15-5 m away);
- calibrated head: the two eyes no longer sweep one plane, so for a sampled left eye only
  particular right-eye readings make the axes meet: we find them by bisection on the signed
  distance between the two axes over the right eye's range, and keep the meeting point under the
  same conditions.

On other heads (:func:`generic_reachable_targets`) from sampled readings through Pinocchio: a
point 0.3-3 m along the one solved axis, or where two solved axes meet.

The calibrated IIS-head is the nominal one with every joint's and frame's CPC constants perturbed
(seeded; 0.1 deg, 0.5 mm) and then the right camera trimmed in pitch (a rotation about its own x
axis) so that both optical axes meet at a point straight ahead at the home posture: the vertical
alignment every stereo head gets when mounted. Without the trim, a random perturbation often
leaves no fixable point in front of the cameras at all (the two eyes' planes cross behind them).

    cpc2urdf bench gaze [--targets 2000] [--unreachable 200] [--reference 300] [--track-seconds 4]
                        [--heads nominal calibrated tiago talos] [--urdf FILE --camera FRAME ...]
                        [--audit 1500] [--seed 0] [--json out.json]
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from cpc2urdf.argparsing import OneLineParser, check_outputs_are_not_inputs
from cpc2urdf.errors import DegenerateDataError
from cpc2urdf.identification.simulation.heads import (
    calibrated_iis_head,
    reachable_targets,
    unreachable_targets,
)
from cpc2urdf.model import CPCModel
from cpc2urdf.studies.placo_reference import FLOOR as PLACO_FLOOR
from cpc2urdf.studies.placo_reference import placo_reference
from cpc2urdf.studies.placo_reference import summary as placo_summary
from cpc2urdf.validation.gaze.reference import (
    AUDIT_HALF_WIDTH,
    AUDIT_STARTS,
    SolvedAxes,
    audit_targets,
    generic_reachable_targets,
    generic_reference_solver,
    generic_unreachable_targets,
    missed_targets,
)

if TYPE_CHECKING:
    from cpc2urdf.validation.gaze import GazeSolver

Array = NDArray[np.float64]
# the real robot heads in example-robot-data: URDF (under its robots/ folder) and camera frame
REAL_HEADS = {
    "tiago": ("tiago_description/robots/tiago.urdf", ("xtion_rgb_optical_frame",)),
    "talos": ("talos_data/robots/talos_reduced.urdf", ("rgbd_rgb_optical_frame",)),
}
HEADS = (
    "nominal",
    "calibrated",
    *REAL_HEADS,
)  # nominal: the IIS-head; calibrated: calibrated_iis_head(seed)
TRACK_DT = 1e-3  # [s]: the tracking loop's period
TRACK_DEADLINE = TRACK_DT  # [s]: a tracking step must end within its period
TRACK_RADIUS = 0.05  # [m]: the tracked target circles this far about a reachable target
TRACK_HOLD = 1.0  # [s]: then jumps to the next one (a saccade)
TRACK_POOL = 200  # reachable targets the tracked target's centres are chosen from
REFERENCE_BLOCK = 25  # targets a block when the reference and ours alternate in blocks (_block_run)


KIN_BLOCK = 100  # solves timed between two blocks of as many kinematics calls


def kinematics_timer(solver: GazeSolver, n: int = 2000, seed: int = 0) -> Callable[[int], float]:
    """A function ``i -> seconds`` that times one Pinocchio forward kinematics plus two frame
    Jacobians (the cameras', LOCAL) from Python, on its own ``Data``, at the ``i``-th (mod
    ``n``) of ``n`` seeded in-limit readings: the unit the solve times are given in."""
    import pinocchio as pin

    model = solver.model
    data = model.createData()
    cams = list(solver.cameras)
    f0, f1 = model.getFrameId(cams[0]), model.getFrameId(cams[-1])
    rng = np.random.default_rng(seed)
    lo, hi = solver.lower, solver.upper
    limited = np.isfinite(lo) & np.isfinite(hi)
    span = np.where(limited, hi - lo, 2.0 * math.pi)  # an unlimited joint: any turn
    Q = list(np.where(limited, lo, -math.pi) + span * rng.random((n, solver.n)))
    local = pin.LOCAL
    clock = time.perf_counter

    def one(i: int) -> float:
        q = Q[i % n]
        t0 = clock()
        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacements(model, data)
        pin.getFrameJacobian(model, data, f0, local)
        pin.getFrameJacobian(model, data, f1, local)
        return clock() - t0

    return one


def kinematics_call_us(solver: GazeSolver, n: int = 2000, seed: int = 0) -> float:
    """Median time [us] of one Pinocchio forward kinematics plus two frame Jacobians
    (:func:`kinematics_timer`) over ``n`` seeded readings."""
    one = kinematics_timer(solver, n, seed)
    return float(np.median([one(i) for i in range(n)]) * 1e6)


def _solve_times(
    solver: GazeSolver, P: Array, kin: Callable[[int], float] | None = None
) -> tuple[Array, NDArray[np.bool_], Array, Array, Array]:
    """Time [s], reachable flag and iterations of one ``solve`` per target (the latency a caller
    sees), the thread's CPU time [s] of each (without the time the process waited for a core:
    on a shared machine the scheduler's preemptions, ~4 ms each, set the wall-clock p99), and,
    with ``kin`` (:func:`kinematics_timer`), the unit measured in blocks between the solves:
    before every :data:`KIN_BLOCK` solves, :data:`KIN_BLOCK` kinematics calls back to back (a
    machine whose speed drifts during the run moves both; back to back, the calls run as warm
    as they can, the smallest unit, unlike one call squeezed between two solves)."""
    n = P.shape[0]
    times = np.empty(n)
    cpu = np.empty(n)
    kin_times = np.empty(n if kin is not None else 0)
    ok = np.zeros(n, dtype=bool)
    iters = np.empty(n)
    clock, cpu_clock = time.perf_counter, time.thread_time
    for i, p in enumerate(P):
        if kin is not None and i % KIN_BLOCK == 0:
            for j in range(i, min(i + KIN_BLOCK, n)):
                kin_times[j] = kin(j)
        c0 = cpu_clock()
        t0 = clock()
        sol = solver.solve(p)
        times[i] = clock() - t0
        cpu[i] = cpu_clock() - c0
        ok[i] = sol.reachable
        iters[i] = sol.iterations
    return times, ok, iters, cpu, kin_times


def _after_ours(
    solver: GazeSolver,
    P: Array,
    reference: Callable[[Array], Any],
    check: Callable[[Array, Any], Any],
) -> tuple[Array, Array, list[Any]]:
    """Every target of ``P`` solved by us, then at once by ``reference`` (``p -> answer``), whose
    answer ``check(p, answer)`` judges untimed before the next target (so both see the same
    load on a shared machine): our times [s], the reference's [s], and the checks."""
    n = P.shape[0]
    times, ours = np.empty(n), np.empty(n)
    checks = []
    clock = time.perf_counter
    for i, p in enumerate(P):
        t0 = clock()
        solver.solve(p)
        t1 = clock()
        answer = reference(p)
        times[i], ours[i] = clock() - t1, t1 - t0
        checks.append(check(p, answer))
    return ours, times, checks


def _reference_start(solver: GazeSolver, axes: SolvedAxes) -> Callable[[Array], Array]:
    """Where the references start for target ``p``: the middle of the limits (``axes``)."""
    home = axes.home
    return lambda p: home


def _reference_run(
    solver: GazeSolver, P: Array, kin: Callable[[int], float], axes: SolvedAxes | None = None
) -> tuple[Array, NDArray[np.bool_], Array, str, dict[str, float]]:
    """scipy ``least_squares`` on every target of ``P``, each right after one ``solve`` of ours
    (:func:`_after_ours`): the reference's time [s] and success, our time [s] on the same
    targets, where the reference starts, and :func:`_block_run`'s numbers on the same targets.

    The reference starts from the middle of the limits over the solver's unknowns
    (:func:`_generic_reference_solver`; ``axes``: the solver's :class:`SolvedAxes`, made here
    when None)."""
    from cpc2urdf.tolerances import GAZE_POINTING_TOL

    solved = axes if axes is not None else SolvedAxes(solver)
    ref = generic_reference_solver(solved)
    start = _reference_start(solver, solved)
    where = "the middle of the limits"

    def fixated(p: Array, q: Array) -> bool:
        return bool(np.max(solved.pointing_errors(q, p)) <= GAZE_POINTING_TOL)

    def reference(p: Array) -> Array:
        return ref(p, start(p))[0]

    ours, times, checks = _after_ours(solver, P, reference, fixated)
    return times, np.array(checks, dtype=bool), ours, where, _block_run(solver, P, reference, kin)


def _block_run(
    solver: GazeSolver, P: Array, reference: Callable[[Array], Array], kin: Callable[[int], float]
) -> dict[str, float]:
    """The scipy ratio timed the other way: the targets of ``P`` in blocks of
    :data:`REFERENCE_BLOCK`, each block solved by us back to back, then by the ``reference``
    back to back (blocks alternate, so both still see the same load), with one kinematics
    call (``kin``, the unit) right after each reference solve.

    Right after a scipy solve any compiled code runs slower than in a loop of its own: the
    interpreter has just run through other code and data. The per-target ratio
    (:func:`_reference_run`) charges that to our solve alone; here each solver runs warm, as the
    unit ``kin_us`` is timed, and ``kin_after_reference_us`` is the unit in nearly the state our
    solve is timed in there (where a success check follows the scipy solve first). Returns the
    medians [us] and ``ratio_blocks`` (reference over ours)."""
    n = P.shape[0]
    ours, times, kin_after = np.empty(n), np.empty(n), np.empty(n)
    clock = time.perf_counter
    for a in range(0, n, REFERENCE_BLOCK):
        block = range(a, min(a + REFERENCE_BLOCK, n))
        for i in block:
            t0 = clock()
            solver.solve(P[i])
            ours[i] = clock() - t0
        for i in block:
            t0 = clock()
            reference(P[i])
            times[i] = clock() - t0
            kin_after[i] = kin(i)
    return {
        "blocks_median_us": float(np.median(ours) * 1e6),
        "blocks_reference_median_us": float(np.median(times) * 1e6),
        "ratio_blocks": float(np.median(times) / np.median(ours)),
        "kin_after_reference_us": float(np.median(kin_after) * 1e6),
    }


def _placo_run(solver: GazeSolver, axes: SolvedAxes, P: Array) -> dict[str, Any]:
    """placo's axis-align reference (:mod:`cpc2urdf.studies.placo_reference`) on every target
    of ``P``, each right after one ``solve`` of ours (:func:`_after_ours`), from the scipy
    reference's start: its median time and ratio to ours, the same for the time in placo's own
    calls alone (its QP steps and kinematics, without the Python that drives them), its median
    steps, and its accuracy (the answers' pointing errors by Pinocchio on the solver's model,
    not by placo); or ``{"placo": reason}`` when it cannot run."""
    ref = placo_reference(solver)
    if isinstance(ref, str):
        return {"placo": ref}
    start = _reference_start(solver, axes)

    def reference(p: Array) -> tuple[Array, int, float]:
        q, k = ref.solve(p, start(p))
        return q, k, ref.core_seconds

    def check(p: Array, answer: tuple[Array, int, float]) -> tuple[float, int, float]:
        q, k, core = answer
        return float(np.max(axes.pointing_errors(q, p))), k, core

    ours, times, checks = _after_ours(solver, P, reference, check)
    errors, steps, core = (np.array(x, dtype=float) for x in zip(*checks, strict=True))
    return {
        "placo": "ran",
        "placo_median_us": float(np.median(times) * 1e6),
        "placo_steps_median": float(np.median(steps)),
        "placo_ratio": float(np.median(times) / np.median(ours)),
        "placo_core_median_us": float(
            np.median(core) * 1e6
        ),  # in placo's own calls: QP steps, kinematics
        "placo_core_ratio": float(np.median(core) / np.median(ours)),
        **placo_summary(errors),
    }


def _batch_throughput(solver: GazeSolver, P: Array, repeats: int = 7) -> tuple[float, str]:
    """Targets per second of one batch solve of ``P`` (best of ``repeats``), and the path used:
    ``"solve_many"`` or ``"loop"`` (one ``solve`` per target, where the solver has no batch entry)."""
    from cpc2urdf.validation.gaze.reachable import solve_batch

    best = math.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        solve_batch(solver, P)
        best = min(best, time.perf_counter() - t0)
    path = "solve_many" if hasattr(solver, "solve_many") else "loop"
    return float(P.shape[0] / best), path


def tracking_targets(
    lower: Array, upper: Array, P: Array, Q: Array, seconds: float, dt: float = TRACK_DT
) -> Array:
    """A 1 kHz target trajectory through reachable targets ``P`` (world) [m], shape (T, 3): it
    circles (:data:`TRACK_RADIUS`, one turn per second) about one of them, and every
    :data:`TRACK_HOLD` s jumps to circle about the next, so that saccades start.

    Only targets whose readings ``Q`` (shape (N, n)) lie in the middle half of every joint's
    range (``lower``, ``upper``, shape (n,); unlimited joints pass) are used, so that the circle
    about them stays reachable.

    Raises:
        DegenerateDataError: None of ``P`` is that far inside the limits.
    """
    lo, hi = lower, upper
    with np.errstate(invalid="ignore"):
        inside = (Q >= lo + 0.25 * (hi - lo)) & (Q <= hi - 0.25 * (hi - lo))
    inner = np.all(inside | ~np.isfinite(hi - lo), axis=1)
    P = P[inner]
    if P.shape[0] == 0:
        raise DegenerateDataError(
            "no reachable target has readings in the middle half of every joint's range; "
            "use more --targets for the tracking run"
        )
    T = max(1, int(round(seconds / dt)))
    t = np.arange(T) * dt
    k = (t // TRACK_HOLD).astype(int) % P.shape[0]
    w = 2.0 * math.pi
    offset = TRACK_RADIUS * np.stack([np.cos(w * t), np.sin(w * t), np.zeros_like(t)], axis=1)
    return P[k] + offset


def _tracking_step_times(solver: GazeSolver, targets: Array) -> tuple[Array, Array, int, float]:
    """Wall and CPU time [s] of every :meth:`GazeTracker.step` over ``targets`` (minimum-jerk
    saccades on, the URDF speed limits), the number of saccade samples and the largest pointing
    error [rad] of the commanded readings where locked on. The CPU time (this thread's) leaves
    out the time the process waited for a core."""
    from cpc2urdf.validation.gaze.tracking import GazeTracker, SaccadeRule

    # warm up on a tracker of its own: a process's first step loads the code it alone uses (~3 ms
    # once, like the first solve's; not a step of the loop)
    GazeTracker(solver, TRACK_DT, saccades=SaccadeRule()).step_checked(targets[0])
    tracker = GazeTracker(solver, TRACK_DT, saccades=SaccadeRule())
    wall = np.empty(targets.shape[0])
    cpu = np.empty(targets.shape[0])
    saccade = 0
    worst = 0.0
    clock, cpu_clock = time.perf_counter, time.thread_time
    for i, p in enumerate(targets):
        c0 = cpu_clock()
        t0 = clock()
        s = tracker.step_checked(p)
        wall[i] = clock() - t0
        cpu[i] = cpu_clock() - c0
        saccade += s.saccade
        if s.locked:
            worst = max(worst, float(np.max(s.pointing_error)))
    return wall, cpu, saccade, worst


@dataclass
class BenchHead:
    """A head of the benchmark: its solver, and the CPC model of an IIS-head (whose targets come
    from :func:`reachable_targets` / :func:`unreachable_targets`), else None (generic targets)."""

    name: str
    solver: GazeSolver
    model: CPCModel | None = None


def _real_urdf(name: str) -> tuple[str, tuple[str, ...]]:
    """The URDF path and camera of a real robot head in example-robot-data."""
    import sysconfig
    from pathlib import Path

    from cpc2urdf.errors import InputFileError

    rel, cams = REAL_HEADS[name]
    path = (
        Path(sysconfig.get_paths()["purelib"])
        / "cmeel.prefix/share/example-robot-data/robots"
        / rel
    )
    if not path.is_file():
        raise InputFileError(
            path,
            f"no such file (head {name!r} needs example-robot-data: pip install example-robot-data)",
        )
    return str(path), cams


def bench_head(
    name: str, seed: int = 0, urdf: str | None = None, cameras: tuple[str, ...] = ()
) -> BenchHead:
    """The head ``name`` (:data:`HEADS`), or with ``urdf`` any URDF and its ``cameras``."""
    from cpc2urdf.files.robot_ref import load_model
    from cpc2urdf.urdf.pinocchio import PinocchioRobot
    from cpc2urdf.validation.gaze import GazeSolver

    if urdf is not None:
        robot = PinocchioRobot.from_urdf(urdf, continuous_as_revolute=True)
        return BenchHead(name, GazeSolver(robot, cameras))
    if name in ("nominal", "calibrated"):
        model = load_model("iis_head") if name == "nominal" else calibrated_iis_head(seed)
        return BenchHead(name, GazeSolver.from_model(model), model)
    if name in REAL_HEADS:
        path, cams = _real_urdf(name)
        return BenchHead(
            name, GazeSolver(PinocchioRobot.from_urdf(path, continuous_as_revolute=True), cams)
        )
    from cpc2urdf.errors import ConfigurationError

    raise ConfigurationError(f"unknown head {name!r}; expected one of {', '.join(HEADS)}")


def run_head(
    head: BenchHead,
    n: int = 2000,
    seed: int = 0,
    *,
    unreachable: int = 200,
    reference: int = 300,
    track_seconds: float = 4.0,
    audit: int = 1500,
) -> dict[str, Any]:
    """Every number of ``cpc2urdf bench gaze`` for one head (see :func:`run_benchmark`)."""
    from cpc2urdf.validation.gaze.reachable import solve_batch

    solver = head.solver
    axes = SolvedAxes(solver)
    if head.model is not None:
        P, Q = reachable_targets(head.model, n, seed)
        U = unreachable_targets(head.model, unreachable, seed) if unreachable else np.zeros((0, 3))
    else:
        P, Q = generic_reachable_targets(axes, n, seed)
        U = (
            generic_unreachable_targets(solver, unreachable, seed)
            if unreachable
            else np.zeros((0, 3))
        )
    solver.solve(P[0])  # warm up: first-call costs (caches, compiled code)
    solve_batch(solver, P[:2])
    kin = kinematics_timer(solver, seed=seed)
    times, ok, iters, cpu, kin_times = _solve_times(solver, P, kin)
    statuses = solve_batch(solver, P).status
    utimes, uok, _, _, _ = _solve_times(solver, U)
    m_ref = min(n, reference)
    rtimes, rok, otimes, reference_start, blocks = _reference_run(solver, P[:m_ref], kin, axes)
    placo = _placo_run(solver, axes, P[:m_ref])
    rate, path = _batch_throughput(solver, np.concatenate([P, U]))
    # every head shape tracks (one camera and rigid pairs through the chain's FK); centres for the tracked target: a pool of TRACK_POOL reachable targets at least
    Pt, Qt = (
        (P, Q)
        if n >= TRACK_POOL
        else (
            reachable_targets(head.model, TRACK_POOL, seed + 1)
            if head.model is not None
            else generic_reachable_targets(axes, TRACK_POOL, seed + 1)
        )
    )
    ttimes, tcpu, n_saccade, track_err = _tracking_step_times(
        solver, tracking_targets(solver.lower, solver.upper, Pt, Qt, track_seconds)
    )
    track: dict[str, Any] = {
        "track_steps": int(ttimes.size),
        "track_saccade_steps": int(n_saccade),
        "track_locked_error_max_rad": track_err,
        "track_median_us": float(np.median(ttimes) * 1e6),
        "track_p99_us": float(np.percentile(ttimes, 99) * 1e6),
        "track_max_us": float(np.max(ttimes) * 1e6),
        "track_over_deadline": int(np.sum(ttimes > TRACK_DEADLINE)),
        "track_cpu_p99_us": float(np.percentile(tcpu, 99) * 1e6),
        "track_cpu_max_us": float(np.max(tcpu) * 1e6),
        "track_cpu_over_deadline": int(np.sum(tcpu > TRACK_DEADLINE)),
    }
    # how often a fixatable target is called unreachable (not on a head that fixates nothing exactly)
    audited = audit if audit and not getattr(solver, "disparity_head", False) else 0
    a_unfixated = a_missed = 0
    if audited:
        A = audit_targets(axes, audited, seed)
        a_reachable = solve_batch(solver, A).reachable
        a_unfixated = int(np.sum(~a_reachable))
        a_missed = int(missed_targets(solver, A, a_reachable, seed=seed).size)
    kin_us = float(np.median(kin_times) * 1e6)
    median_us = float(np.median(times) * 1e6)
    p99_us = float(np.percentile(times, 99) * 1e6)
    u_median = (
        float(np.median(utimes) * 1e6) if utimes.size else None
    )  # None: no unreachable targets
    disparity = float(np.mean(statuses == "disparity"))
    r: dict[str, Any] = {
        "kind": str(solver.kind) if hasattr(solver, "kind") else "binocular",
        "targets": n,
        "kin_us": kin_us,
        "median_us": median_us,
        "p99_us": p99_us,
        "median_kin": median_us / kin_us,
        "p99_kin": p99_us / kin_us,
        "p99_cpu_us": float(np.percentile(cpu, 99) * 1e6),
        "p99_cpu_kin": float(np.percentile(cpu, 99) * 1e6) / kin_us,
        "success": float(ok.mean()),
        "disparity": disparity,
        "iterations_median": float(np.median(iters)),
        "unreachable_targets": int(U.shape[0]),
        "unreachable_fixated": int(uok.sum()),
        "unreachable_median_us": u_median,
        "unreachable_ratio": None if u_median is None else u_median / median_us,
        "reference_targets": m_ref,
        "reference_start": reference_start,
        "reference_median_us": float(np.median(rtimes) * 1e6),
        "reference_p99_us": float(np.percentile(rtimes, 99) * 1e6),
        "reference_success": float(rok.mean()),
        "ratio": float(np.median(rtimes) / np.median(otimes)),  # same targets, interleaved
        "after_reference_median_us": float(
            np.median(otimes) * 1e6
        ),  # ours, each right after a scipy solve
        **blocks,
        **placo,
        "batch_targets": int(P.shape[0] + U.shape[0]),
        "batch_targets_per_s": rate,
        "batch_path": path,
        "audit_targets": audited,
        "audit_unfixated": a_unfixated,
        "audit_missed": a_missed,
        **track,
    }
    r["aims"] = {
        "median_le_10_kin": r["median_kin"] <= 10.0,
        "p99_le_40_kin": r["p99_kin"] <= 40.0,
        "unreachable_le_5_reachable": u_median is not None and r["unreachable_ratio"] <= 5.0,
        "success_100": r["success"] + r["disparity"] == 1.0,
        "ge_100x_scipy": r["ratio"] >= 100.0,
        **({"ge_100x_placo": r["placo_ratio"] >= 100.0} if "placo_ratio" in r else {}),
        "batch_ge_100k_per_s": rate >= 100_000.0,
        "track_p99_within_deadline": bool(track) and r["track_p99_us"] <= TRACK_DEADLINE * 1e6,
    }
    return r


def run_benchmark(
    n: int = 2000,
    seed: int = 0,
    heads: tuple[str, ...] = HEADS,
    *,
    unreachable: int = 200,
    reference: int = 300,
    track_seconds: float = 4.0,
    urdf: str | None = None,
    cameras: tuple[str, ...] = (),
    audit: int = 1500,
) -> dict[str, Any]:
    """Every number of ``cpc2urdf bench gaze``, per head, in one run.

    Args:
        n: Reachable targets per head (IIS-heads: :func:`reachable_targets`; others:
            :func:`generic_reachable_targets`).
        seed: Seed of the targets and of the calibrated head's errors.
        heads: Names from :data:`HEADS`.
        unreachable: Unreachable targets per head (:func:`unreachable_targets`,
            :func:`generic_unreachable_targets`).
        reference: How many of the reachable targets the scipy reference solves.
        track_seconds: Length of the 1 kHz tracking run [s] (every head).
        urdf: Also this URDF (named by its file stem), with ``cameras``.
        cameras: The camera frames of ``urdf``.
        audit: Random targets per head (:func:`audit_targets`) whose unfixated answers are
            solved again from :data:`AUDIT_STARTS` random postures (:func:`missed_targets`); 0:
            none. Not on a head that cannot fixate exactly.

    Returns:
        ``{head: {...}}``: the kinematics unit ``kin_us`` (one FK + two frame Jacobians, measured
        before and after the solves), ``median_us``/``p99_us`` and as ratios to it
        (``median_kin``, ``p99_kin``), ``success`` (fixated) and ``disparity`` (answered with the
        head's own disparity) on reachable targets, ``iterations_median``,
        ``unreachable_median_us`` and ``unreachable_ratio`` (to the reachable median), the
        scipy reference's ``reference_median_us``/``reference_success`` and ``ratio`` (its
        median over ours on the same targets, each of ours right after one of its solves:
        ``after_reference_median_us``), the same timed in alternating blocks
        (:func:`_block_run`: ``ratio_blocks``, ``blocks_median_us``,
        ``blocks_reference_median_us``) with the unit right after a scipy solve
        (``kin_after_reference_us``), ``batch_targets_per_s`` and ``batch_path``,
        ``track_p99_us``/``track_max_us``/``track_over_deadline`` (steps over
        :data:`TRACK_DEADLINE`; wall clock, and ``track_cpu_*`` this thread's CPU time), the
        audit's ``audit_targets``, ``audit_unfixated`` (answered as not fixated) and
        ``audit_missed`` (of those, fixated from another start), and ``aims`` (the issue's
        aims, each True/False).
    """
    import os

    names = list(heads)
    if urdf is not None:
        names.append(os.path.splitext(os.path.basename(urdf))[0])
    results: dict[str, Any] = {}
    for name in names:
        is_urdf = urdf is not None and name == names[-1] and name not in heads
        head = bench_head(name, seed, urdf if is_urdf else None, cameras)
        results[name] = run_head(
            head,
            n,
            seed,
            unreachable=unreachable,
            reference=reference,
            track_seconds=track_seconds,
            audit=audit,
        )
    return results


def _ratio(x: float | None) -> str:
    return f"{'n/a':>9s}" if x is None else f"{x:8.1f}x"


def format_table(res: dict[str, Any]) -> str:
    """The table ``cpc2urdf bench gaze`` prints: one row per head; times as ratios to one FK +
    two frame Jacobians (``kin``), the issue's aims under the header."""
    head = (
        f"{'head':13s} {'kind':12s} {'kin us':>7s} {'median':>9s} {'p99':>9s} {'p99 cpu':>9s} {'unreach':>9s} {'success':>8s} "
        f"{'iters':>5s} {'vs scipy':>9s} {'vs placo':>9s} {'batch/s':>9s} {'track p99':>10s} {'cpu p99':>8s} {'over 1ms':>8s} {'missed':>10s}"
    )
    aims = (
        f"{'aim':13s} {'':12s} {'':>7s} {'<=10x':>9s} {'<=40x':>9s} {'':>9s} {'<=5x':>9s} {'1.0':>8s} {'':>5s} "
        f"{'>=100x':>9s} {'>=100x':>9s} {'>=100000':>9s} {'<=1000us':>10s} {'':>8s} {'0':>8s} {'0':>10s}"
    )
    lines = [head, aims]
    for name, r in res.items():
        success = r["success"] + r["disparity"]
        track = (
            f"{r['track_p99_us']:8.0f}us {r['track_cpu_p99_us']:6.0f}us {r['track_over_deadline']:8d}"
            if "track_p99_us" in r
            else f"{'n/a':>10s} {'n/a':>8s} {'n/a':>8s}"
        )
        missed = f"{r['audit_missed']}/{r['audit_unfixated']}" if r.get("audit_targets") else "n/a"
        lines.append(
            f"{name:13s} {r['kind']:12s} {r['kin_us']:7.2f} {r['median_kin']:8.1f}x {r['p99_kin']:8.1f}x {r['p99_cpu_kin']:8.1f}x "
            f"{_ratio(r['unreachable_ratio'])} {success:8.4f} {r['iterations_median']:5.0f} "
            f"{r['ratio']:8.1f}x {_ratio(r.get('placo_ratio'))} {r['batch_targets_per_s']:9.0f} {track} {missed:>10s}"
        )
    lines.append(
        "kin: one Pinocchio FK + two frame Jacobians [us], in blocks of 100 between the solves; median/p99: one solve per reachable "
        "target, over kin (p99 cpu: by this thread's CPU time); unreach: unreachable median over reachable median; success: fixated, or "
        "answered with the head's disparity; vs scipy: least_squares median over ours, same targets; "
        "vs placo: placo's axis-align steps from Python (to 1e-9 rad or its floor, or until the error stops falling) median over ours, same targets; "
        "batch/s: "
        + ", ".join(f"{n} via {r['batch_path']}" for n, r in res.items())
        + "; track: one 1 kHz step (solve + pursuit/saccade), wall and CPU time"
        + f"; missed: random targets (a {2 * AUDIT_HALF_WIDTH:g} m cube about the head) answered as not fixated "
        f"that one of {AUDIT_STARTS} random starts fixates, of all answered so (n/a: not audited: --audit 0, or a head "
        "that cannot fixate exactly)"
    )
    for name, r in res.items():
        if "ratio_blocks" not in r:  # a row made without the block run
            continue
        lines.append(
            f"vs scipy on {name}: {r['ratio']:.1f}x a target at a time (scipy {r['reference_median_us']:.0f} us, ours "
            f"{r['after_reference_median_us']:.1f} us right after each scipy solve, where one FK + two Jacobians takes "
            f"{r['kin_after_reference_us']:.2f} us, {r['kin_after_reference_us'] / r['kin_us']:.1f}x kin), "
            f"{r['ratio_blocks']:.1f}x in alternating blocks of {REFERENCE_BLOCK} (scipy "
            f"{r['blocks_reference_median_us']:.0f} us, ours {r['blocks_median_us']:.1f} us)"
        )
    for name, r in res.items():
        if r.get("placo") == "ran":
            lines.append(
                f"placo on {name}: within 1e-9 rad on {r['placo_success']:.1%} of the targets, within its floor "
                f"({PLACO_FLOOR:g} rad) on {r['placo_within_floor']:.1%}, over 1e-4 rad on {r['placo_over_1e-4']:.1%}; "
                f"median error {r['placo_error_median_rad']:.1e} rad, {r['placo_steps_median']:.0f} steps, "
                f"{r['placo_median_us']:.0f} us, of which {r['placo_core_median_us']:.0f} us in placo's own calls "
                f"({r['placo_core_ratio']:.1f}x ours)"
            )
    reasons = sorted({r["placo"] for r in res.values() if r.get("placo", "ran") != "ran"})
    lines.extend(f"vs placo n/a: {why}" for why in reasons)
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """``cpc2urdf bench gaze``: print the table (and optionally write JSON)."""
    from cpc2urdf.errors import ConfigurationError

    parser = OneLineParser(prog="cpc2urdf bench gaze", description=__doc__.split("\n")[0])
    parser.add_argument(
        "--targets", type=int, default=2000, help="reachable targets per head (default 2000)"
    )
    parser.add_argument(
        "--unreachable", type=int, default=200, help="unreachable targets per head (default 200)"
    )
    parser.add_argument(
        "--reference",
        type=int,
        default=300,
        help="targets the scipy reference solves (default 300)",
    )
    parser.add_argument(
        "--track-seconds",
        type=float,
        default=4.0,
        help="length of the 1 kHz tracking run [s] (default 4)",
    )
    parser.add_argument(
        "--heads", nargs="+", choices=HEADS, default=list(HEADS), help="heads (default all)"
    )
    parser.add_argument(
        "--urdf", help="also this head (a URDF file; named by its file stem), with --camera"
    )
    parser.add_argument(
        "--camera",
        nargs="+",
        default=[],
        metavar="FRAME",
        help="--urdf: its one or two camera frames",
    )
    parser.add_argument(
        "--audit",
        type=int,
        default=1500,
        help="random targets per head whose unfixated answers are tried again from "
        f"{AUDIT_STARTS} random starts (default 1500; 0: none)",
    )
    parser.add_argument(
        "--seed", type=int, default=0, help="seed of targets and calibration errors"
    )
    parser.add_argument("--json", help="also write the numbers to this JSON file")
    args = parser.parse_args(argv)
    check_outputs_are_not_inputs(args)
    if (args.urdf is None) != (not args.camera):
        raise ConfigurationError(
            "--urdf and --camera go together: a URDF file and its one or two camera frames"
        )
    if args.targets < 1 or args.reference < 1 or args.unreachable < 0 or args.audit < 0:
        raise ConfigurationError(
            "--targets and --reference must be at least 1, --unreachable and --audit at least 0"
        )
    if not (math.isfinite(args.track_seconds) and args.track_seconds >= TRACK_DT):
        raise ConfigurationError(
            f"--track-seconds must be at least {TRACK_DT:g} s, got {args.track_seconds}"
        )
    if args.json:
        from cpc2urdf.files.jsonio import check_output_path

        check_output_path(args.json)
    res = run_benchmark(
        args.targets,
        args.seed,
        tuple(args.heads),
        unreachable=args.unreachable,
        reference=args.reference,
        track_seconds=args.track_seconds,
        urdf=args.urdf,
        cameras=tuple(args.camera),
        audit=args.audit,
    )
    print(format_table(res))
    if args.json:
        from cpc2urdf.files.jsonio import write_json

        write_json(args.json, res)
    return 0


__all__ = [
    "HEADS",
    "REAL_HEADS",
    "BenchHead",
    "TRACK_DEADLINE",
    "TRACK_DT",
    "TRACK_HOLD",
    "TRACK_POOL",
    "TRACK_RADIUS",
    "bench_head",
    "format_table",
    "kinematics_call_us",
    "kinematics_timer",
    "main",
    "run_benchmark",
    "run_head",
    "tracking_targets",
]
