"""Gaze never raises on a finite target: a seeded fuzz of ``GazeSolver.solve``.

Every solve of a finite target must return a :class:`GazeSolution` (fixated or not) without an
exception or a numpy warning, with readings that are finite and inside the limits, the fixed
joints of its policy where they were, finite residuals, a status consistent with ``reachable``,
and pointing errors that the CPC model's own forward kinematics (not Pinocchio) confirms.

Targets, per head (the nominal IIS-head and a calibrated one, ``calibrated_iis_head(0)``):

- uniform in a 4 m cube centred on the cyclopean point at home (policies mixed, half cyclopean);
- from seeded configurations (home, all-lower, all-upper, then random ones with a quarter of the
  joints exactly at a limit): each camera centre exactly and 1e-15..1e-3 m from it, the eyes'
  rotation centres (origin of each eye's first joint) and their midpoint, points on each optical
  axis (behind the camera, on it and up to 1 km ahead), points behind the head, points at
  log-spaced distances 1e-9..1e6 m from the head and 1e7..1e300 m (astronomically far), and the
  closest point of the two optical axes at readings on the limits. These are solved from those
  readings (``q_current``, and for half of them ``q_start`` too), so an iteration starts *on* a
  camera centre.

Numpy floating-point errors (overflow, division by zero, invalid) are raised, warnings are
errors; underflow is left as numpy's default ignores it (the correctly rounded result).

Size: by default :data:`FAST_CUBE` cube targets and :data:`FAST_CONFIGS` configurations per head
(about 950 solves per head, ~10 s in all). ``CPC2URDF_GAZE_FUZZ_TARGETS=100000`` runs the full
fuzz: that many cube targets plus the special targets of :data:`FULL_CONFIGS` configurations per
head (about 112,000 solves per head), split over the machine's cores: about 17 CPU-minutes for
both heads (random cube targets are mostly out of reach and cost ~4.5 ms each).
"""

from __future__ import annotations

import math
import os
import warnings
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass

import numpy as np
import pytest

from cpc2urdf.files.robot_ref import load_model
from cpc2urdf.identification.simulation.heads import calibrated_iis_head
from cpc2urdf.model import CPCModel
from cpc2urdf.tolerances import GAZE_POINTING_TOL
from cpc2urdf.validation.gaze import (
    POLICIES,
    STATUSES,
    GazeSolution,
    GazeSolver,
)
from cpc2urdf.validation.gaze.batch import MAX_SOLVE_ITERATIONS

CAMERAS = ("camera_left_optical", "camera_right_optical")
FAST_CUBE = 600  # cube targets per head by default
FAST_CONFIGS = 6  # configurations whose special targets are solved, per head, by default
FULL_CONFIGS = 200  # ... in the full fuzz
CUBE_HALF = 2.0  # [m]: half the side of the cube
SEED = 14
FK_MIN_DISTANCE = 1e-3  # [m]: the FK cross-check skips targets this close to a camera centre
FK_MAX_DISTANCE = 1e7  # [m]: ... and targets beyond this (float rounding of p - o)
FK_TOL = 1e-9  # [rad]: reported pointing error vs the CPC model's FK


def _size() -> tuple[int, int]:
    """(cube targets, configurations) per head: the default, or the full fuzz from the environment."""
    n = os.environ.get("CPC2URDF_GAZE_FUZZ_TARGETS")
    return (FAST_CUBE, FAST_CONFIGS) if n is None else (int(n), FULL_CONFIGS)


@dataclass
class Cases:
    """Solve calls: target ``p`` (N, 3), policy index (N,), ``q_current`` (N, n) or NaN rows for
    None, ``use_start`` (N,) whether ``q_current`` is also the start, and each target's class."""

    p: np.ndarray
    policy: np.ndarray
    q_current: np.ndarray
    use_start: np.ndarray
    kind: np.ndarray

    def __len__(self) -> int:
        return len(self.p)

    def chunks(self, k: int) -> Iterator[Cases]:
        for idx in np.array_split(np.arange(len(self)), k):
            yield Cases(
                self.p[idx],
                self.policy[idx],
                self.q_current[idx],
                self.use_start[idx],
                self.kind[idx],
            )


def _model(name: str) -> CPCModel:
    return load_model("iis_head") if name == "nominal" else calibrated_iis_head(0)


def _unit(rng: np.random.Generator, n: int) -> np.ndarray:
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def _configurations(solver: GazeSolver, rng: np.random.Generator, n: int) -> np.ndarray:
    """home, all-lower, all-upper, then random readings with a quarter of the joints at a limit."""
    lo, hi = solver.lower, solver.upper
    Q = lo + (hi - lo) * rng.random((max(n - 3, 0), solver.n))
    at = rng.random(Q.shape) < 0.25
    upper = rng.random(Q.shape) < 0.5
    Q = np.where(at & upper, hi, np.where(at, lo, Q))
    return np.vstack([solver.home, lo, hi, Q])[:n]


def make_cases(solver: GazeSolver, n_cube: int, n_configs: int, seed: int = SEED) -> Cases:
    """The seeded fuzz targets of one head (module docstring)."""
    rng = np.random.default_rng(seed)
    import pinocchio as pin

    n = solver.n
    model, data = solver.robot.model, solver.robot.model.createData()
    none = np.full(n, np.nan)
    left, right = solver.camera_poses(solver.home)
    centre = 0.5 * (left[:3, 3] + right[:3, 3])
    P = [centre + rng.uniform(-CUBE_HALF, CUBE_HALF, (n_cube, 3))]
    pol = [
        np.where(np.arange(n_cube) % 2 == 0, 0, 1 + (np.arange(n_cube) // 2) % (len(POLICIES) - 1))
    ]
    Qc = [np.tile(none, (n_cube, 1))]
    qc_rows = solver.lower + (solver.upper - solver.lower) * rng.random((n_cube, n))
    pol_needs_q = np.isin(pol[0], [POLICIES.index("min-motion"), POLICIES.index("eyes-only")])
    Qc[0][pol_needs_q] = qc_rows[pol_needs_q]
    start = [np.zeros(n_cube, dtype=bool)]
    kinds = [np.full(n_cube, "cube")]
    ch = solver.chain  # each eye's first joint: the first on one camera's path only
    eye_joint_ids = [
        int(ch.joint_index[np.flatnonzero(ch.anc[c] & ~ch.anc[1 - c])[0]]) + 1 for c in (0, 1)
    ]
    for j, q in enumerate(_configurations(solver, rng, n_configs)):
        pin.forwardKinematics(model, data, q)
        eyes = [data.oMi[i].translation.copy() for i in eye_joint_ids]
        Ts = solver.camera_poses(q)
        o = [T[:3, 3] for T in Ts]
        z = [T[:3, 2] for T in Ts]
        c = 0.5 * (o[0] + o[1])
        d = z[0] + z[1]
        d = d / np.linalg.norm(d) if np.linalg.norm(d) > 1e-9 else z[0]
        pts: list[tuple[str, np.ndarray]] = []
        for k in range(2):
            pts.append(("camera centre", o[k]))
            pts += [
                ("near a camera centre", o[k] + r * _unit(rng, 1)[0])
                for r in (1e-15, 1e-12, 1e-9, 1e-6, 1e-3)
            ]
            pts += [
                ("eye rotation centre", eyes[k]),
                ("near an eye rotation centre", eyes[k] + 1e-9 * _unit(rng, 1)[0]),
            ]
            pts += [
                ("optical axis", o[k] + t * z[k])
                for t in (-1.0, -1e-3, 1e-9, 1e-3, 0.05, 0.5, 3.0, 1e3)
            ]
        pts.append(("eye rotation centre", 0.5 * (eyes[0] + eyes[1])))
        pts += [("behind the head", c - t * d) for t in (0.01, 0.3, 1.0, 10.0)]
        pts += [
            ("1e-9..1e6 m from the head", c + r * u)
            for r, u in zip(np.geomspace(1e-9, 1e6, 16), _unit(rng, 16), strict=True)
        ]
        pts += [
            ("astronomically far", c + r * u)
            for r, u in zip(np.geomspace(1e7, 1e300, 4), _unit(rng, 4), strict=True)
        ]
        w = o[0] - o[1]
        a, b, cc = z[0] @ z[0], z[0] @ z[1], z[1] @ z[1]
        den = a * cc - b * b
        if den > 1e-12:  # the axes' closest point at these (limit) readings
            t0 = (b * (z[1] @ w) - cc * (z[0] @ w)) / den
            t1 = (a * (z[1] @ w) - b * (z[0] @ w)) / den
            pts.append(("joint-limit boundary", 0.5 * (o[0] + t0 * z[0] + o[1] + t1 * z[1])))
        pts.append(("joint-limit boundary", o[0] + 0.7 * z[0]))
        m = len(pts)
        P.append(np.array([p for _, p in pts]))
        kinds.append(np.array([k for k, _ in pts]))
        pol.append((np.arange(m) + j) % len(POLICIES))
        Qc.append(np.tile(q, (m, 1)))
        start.append((np.arange(m) + j) % 2 == 1)
    return Cases(
        np.vstack(P),
        np.concatenate(pol),
        np.vstack(Qc),
        np.concatenate(start),
        np.concatenate(kinds),
    )


def solve_cases(
    solver: GazeSolver, cases: Cases
) -> tuple[list[str], np.ndarray, np.ndarray, np.ndarray]:
    """Solve every case under strict floating-point checks.

    Returns ``(failures, Q, errors, solved)``: one line per contract violation, the readings
    (N, n), the reported pointing errors (N, 2) and which cases returned an answer (N,).
    """
    failures: list[str] = []
    N, n = len(cases), solver.n
    Q = np.full((N, n), np.nan)
    E = np.full((N, 2), np.nan)
    solved = np.zeros(N, dtype=bool)
    cap = MAX_SOLVE_ITERATIONS
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with np.errstate(over="raise", divide="raise", invalid="raise", under="ignore"):
            for i in range(N):
                p, policy = cases.p[i], POLICIES[int(cases.policy[i])]
                qc = None if np.isnan(cases.q_current[i, 0]) else cases.q_current[i]
                what = f"{cases.kind[i]} target {p.tolist()} ({policy}, q_current={None if qc is None else qc.tolist()})"
                try:
                    sol = solver.solve(p, qc, policy, q_start=qc if cases.use_start[i] else None)
                except Exception as e:  # noqa: BLE001 (the contract under test: nothing raises)
                    failures.append(f"{what}: raised {type(e).__name__}: {e}")
                    continue
                problem = _contract(solver, sol, qc, policy, cap)
                if problem:
                    failures.append(f"{what}: {problem}")
                    continue
                Q[i], E[i], solved[i] = sol.q, sol.pointing_error, True
    return failures, Q, E, solved


def _contract(
    solver: GazeSolver, sol: GazeSolution, qc: np.ndarray | None, policy: str, cap: int
) -> str:
    """What is wrong with one answer, or ''."""
    q = sol.q
    if not isinstance(sol, GazeSolution) or q.shape != (solver.n,):
        return f"not a GazeSolution of shape ({solver.n},)"
    if not np.all(np.isfinite(q)):
        return f"non-finite readings {q.tolist()}"
    if np.any(q < solver.lower) or np.any(q > solver.upper):
        return f"readings {q.tolist()} outside the limits"
    ref = solver.home if qc is None else qc
    fixed = np.setdiff1d(np.arange(solver.n), solver.free_joints(policy))
    if np.any(q[fixed] != ref[fixed]):
        return f"{policy} moved a fixed joint: {q.tolist()} from {ref.tolist()}"
    if sol.status not in STATUSES or sol.reachable != (sol.status == "fixated"):
        return f"status {sol.status!r} with reachable={sol.reachable}"
    e, m = sol.pointing_error, sol.miss_distance
    if not (np.all(np.isfinite(e)) and np.all(e >= 0) and np.all(e <= math.pi)):
        return f"pointing error {e.tolist()}"
    if not (np.all(np.isfinite(m)) and np.all(m >= 0)):
        return f"miss distance {m.tolist()}"
    if sol.reachable != bool(e.max() <= GAZE_POINTING_TOL):
        return f"reachable={sol.reachable} with pointing error {e.tolist()}"
    if not 0 <= sol.iterations <= cap or not math.isfinite(sol.vergence):
        return f"iterations {sol.iterations}, vergence {sol.vergence}"
    return ""


def _fk_errors(model: CPCModel, Q: np.ndarray, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pointing error of each eye [rad] and distance to each camera centre [m], each (N, 2),
    from the CPC model's FK."""
    T = model.fk(Q, CAMERAS)
    err, dist = [], []
    for cam in CAMERAS:
        R, o = T[cam][:, :3, :3], T[cam][:, :3, 3]
        pc = np.einsum("nji,nj->ni", R, P - o)
        err.append(np.arctan2(np.hypot(pc[:, 0], pc[:, 1]), pc[:, 2]))
        dist.append(np.linalg.norm(pc, axis=1))
    return np.stack(err, axis=1), np.stack(dist, axis=1)


_WORKER: dict[str, GazeSolver] = {}


def _solve_chunk(
    name: str, model: CPCModel, cases: Cases
) -> tuple[list[str], np.ndarray, np.ndarray, np.ndarray]:
    if name not in _WORKER:  # one solver per head and worker process
        _WORKER[name] = GazeSolver.from_model(model)
    return solve_cases(_WORKER[name], cases)


def fuzz(
    name: str, model: CPCModel, n_cube: int, n_configs: int
) -> tuple[Cases, list[str], np.ndarray, np.ndarray, np.ndarray]:
    """Make and solve the cases of head ``name`` (``model``); over the machine's cores when large."""
    solver = GazeSolver.from_model(model)
    cases = make_cases(solver, n_cube, n_configs)
    workers = min(os.cpu_count() or 1, 8)
    if len(cases) < 20_000 or workers == 1:
        return (cases, *solve_cases(solver, cases))
    failures: list[str] = []
    parts = []
    with ProcessPoolExecutor(workers) as pool:
        k = 4 * workers
        for f, Q, E, ok in pool.map(_solve_chunk, [name] * k, [model] * k, cases.chunks(k)):
            failures += f
            parts.append((Q, E, ok))
    Q, E, ok = (np.concatenate(x) for x in zip(*parts, strict=True))
    return cases, failures, Q, E, ok


@pytest.mark.parametrize("name", ["nominal", "calibrated"])
def test_every_finite_target_gets_an_answer(name):
    n_cube, n_configs = _size()
    model = _model(name)
    cases, failures, Q, E, solved = fuzz(name, model, n_cube, n_configs)
    assert len(cases) >= n_cube + 50 * n_configs  # every class is there
    assert not failures, (
        f"{name}: {len(failures)} of {len(cases)} targets break the contract, e.g.\n"
        + "\n".join(failures[:10])
    )
    assert solved.all()
    # The reported pointing errors (Pinocchio on the URDF) agree with the CPC model's own FK.
    near = np.abs(cases.p).max(axis=1) < FK_MAX_DISTANCE
    err, dist = _fk_errors(model, Q[near], cases.p[near])
    E = E[near]
    check = np.all(dist > FK_MIN_DISTANCE, axis=1)
    assert check.sum() > 0.8 * len(cases)
    worst = np.abs(err[check] - E[check]).max()
    assert worst < FK_TOL, f"{name}: reported pointing error off the FK by {worst:.3g} rad"
    # Targets on a camera centre at the answer are counted as missed by pi, never as fixated.
    on_centre = np.any(dist < 0.5e-9, axis=1)
    assert on_centre.any()
    assert np.all(np.where(dist[on_centre] < 0.5e-9, E[on_centre] == math.pi, True))


def test_tracking_through_camera_centres_and_far_away():
    """A trajectory through both camera centres (at home), an eye rotation centre and out to
    1e6 m: every sample answered, readings finite, inside the limits and velocity-limited."""
    solver = GazeSolver.from_model(load_model("iis_head"))
    left, right = solver.camera_poses(solver.home)
    o0, o1 = left[:3, 3], right[:3, 3]
    t = np.linspace(0.0, 1.0, 61)[:, None]
    P = np.vstack(
        [
            o0 + (t - 0.5) * np.array([0.0, 0.0, 0.2]),
            o0 + t * (o1 - o0),
            o1 + np.geomspace(1e-9, 1e6, len(t))[:, None] * left[:3, 2],
        ]
    )
    P[len(t) // 2] = o0  # exactly on the centre
    vmax = np.array([0.1, 0.1, 1.0, 1.0, 2.0, 2.0])
    dt = 1e-2
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with np.errstate(over="raise", divide="raise", invalid="raise", under="ignore"):
            for policy in POLICIES:
                tr = solver.track(P, dt, vmax, q_current=solver.home, policy=policy)
                assert np.all(np.isfinite(tr.q)) and np.all(np.isfinite(tr.q_goal))
                assert np.all(tr.q >= solver.lower) and np.all(tr.q <= solver.upper)
                assert np.all(np.isfinite(tr.pointing_error)) and np.all(
                    tr.pointing_error <= math.pi
                )
                v = np.abs(np.diff(np.vstack([solver.home, tr.q]), axis=0)) / dt
                assert np.all(v <= vmax * (1 + 1e-12)), policy


# ---- every head shape, through the compiled batch solver -------------------------------------

SHAPE_FAST_CUBE = 300  # cube targets per head shape by default
SHAPE_FAST_CONFIGS = 4  # configurations whose special targets are solved, by default


def _shape_cases(
    solver: GazeSolver, rng: np.random.Generator, n_cube: int, n_configs: int
) -> list[tuple[np.ndarray | None, np.ndarray]]:
    """``[(q_current or None, targets (k, 3))]``: cube targets from the middle of the limits, then
    per configuration its special targets (camera centres and near them, on and behind each
    optical axis, 1e-9..1e6 m and astronomically far)."""
    comp, chain = solver.compiled, solver.chain
    R, o = comp._fk(comp.home_u)
    centre = o[: len(solver.cameras)].mean(axis=0)
    out: list[tuple[np.ndarray | None, np.ndarray]] = [
        (None, centre + rng.uniform(-CUBE_HALF, CUBE_HALF, (n_cube, 3)))
    ]
    lo, hi = chain.lower, chain.upper
    for k in range(n_configs):
        u = comp.home_u if k == 0 else lo + (hi - lo) * rng.random(chain.m)
        if k > 1:
            at = rng.random(chain.m) < 0.25
            u = np.where(at, np.where(rng.random(chain.m) < 0.5, hi, lo), u)
        q = chain.q_from_u(u)
        q = np.clip(q, solver.lower, solver.upper)
        R, o = comp._fk(chain.u_from_q(q), comp.b_for(q))
        pts = []
        for c in range(len(o)):
            pts.append(o[c])
            pts += [o[c] + r * _unit(rng, 1)[0] for r in (1e-15, 1e-12, 1e-9, 1e-6, 1e-3)]
            pts += [o[c] + t * R[c][:, 2] for t in (-1.0, -1e-3, 1e-9, 1e-3, 0.05, 0.5, 3.0, 1e3)]
        pts += [
            o[0] + r * v for r, v in zip(np.geomspace(1e-9, 1e6, 16), _unit(rng, 16), strict=True)
        ]
        pts += [
            o[0] + r * v for r, v in zip(np.geomspace(1e7, 1e300, 4), _unit(rng, 4), strict=True)
        ]
        pts += [np.array([1.7e308, -1.7e308, 0.0])]
        out.append((q, np.array(pts)))
    return out


@pytest.mark.parametrize(
    "shape",
    ["tiago", "talos", "icub", "stereo_pan_tilt", "panda_camera", "iis_nominal", "iis_calibrated"],
)
def test_every_head_shape_answers_every_finite_target(shape, tmp_path):
    """The compiled solver's contract on every head shape: an answer for every finite target,
    finite and inside the limits, joints it may not move where they were, statuses consistent
    with the pointing errors, and those errors confirmed by Pinocchio's FK (not the compiled
    one) for targets 1e-3..1e7 m from the cameras."""
    import pinocchio as pin
    from gaze_heads import head_case

    solver = head_case(shape, tmp_path).solver
    n = os.environ.get("CPC2URDF_GAZE_FUZZ_TARGETS")
    n_cube, n_configs = (
        (SHAPE_FAST_CUBE, SHAPE_FAST_CONFIGS) if n is None else (int(n), FULL_CONFIGS // 4)
    )
    rng = np.random.default_rng(SEED)
    chain = solver.chain
    data = solver.robot.model.createData()
    axes = chain.solve_cameras.tolist()
    fids = [solver.robot.frame_id(c) for c in solver.cameras]
    total = 0
    for qc, P in _shape_cases(solver, rng, n_cube, n_configs):
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            with np.errstate(over="raise", divide="raise", invalid="raise", under="ignore"):
                b = solver.solve_many(P, qc)
        total += len(P)
        assert np.all(np.isfinite(b.q)), shape
        assert np.all(b.q >= solver.lower) and np.all(b.q <= solver.upper), shape
        ref = solver.home if qc is None else qc
        still = np.abs(chain.robot_A).sum(axis=1) == 0
        assert np.all(b.q[:, still] == ref[still]), shape
        assert (
            np.all(np.isfinite(b.pointing_error))
            and np.all(b.pointing_error >= 0)
            and np.all(b.pointing_error <= math.pi)
        )
        assert np.array_equal(b.reachable, b.pointing_error.max(axis=1) <= b.tolerance)
        assert np.array_equal(b.reachable, b.status == 0)
        # the reported errors against Pinocchio's FK of the answers
        for i in range(len(P)):
            pin.framesForwardKinematics(solver.robot.model, data, b.q[i])
            T = [data.oMf[f] for f in fids]
            for s, c in enumerate(axes):
                if c < len(fids):
                    o, z = T[c].translation, T[c].rotation[:, 2]
                else:
                    o = 0.5 * (T[0].translation + T[1].translation)
                    z = T[0].rotation[:, 2] + T[1].rotation[:, 2]
                    z = z / np.linalg.norm(z)
                d = P[i] - o
                if np.abs(d).max() < FK_MAX_DISTANCE and np.linalg.norm(d) > 1e-3:
                    e = math.atan2(np.linalg.norm(np.cross(z, d)), z @ d)
                    assert abs(e - b.pointing_error[i, s]) < FK_TOL, (
                        shape,
                        P[i].tolist(),
                        e,
                        b.pointing_error[i, s],
                    )
    assert total >= n_cube + 35 * n_configs  # every class is there


@pytest.mark.parametrize(
    "shape", ["tiago", "talos", "icub", "stereo_pan_tilt", "panda_camera", "iis_nominal"]
)
def test_every_head_shape_exact_on_reachable_targets(shape, tmp_path):
    """Fixatable targets (sampled in-limit readings, tests/gaze_heads.py): every one fixated
    inside the limits, exact to GAZE_POINTING_TOL on yourdfpy's FK. 100 per head by default;
    10,000 in the full fuzz (``CPC2URDF_GAZE_FUZZ_TARGETS`` set)."""
    from gaze_heads import head_case, pointing_errors, yourdfpy_axes

    case = head_case(shape, tmp_path)
    n = 100 if os.environ.get("CPC2URDF_GAZE_FUZZ_TARGETS") is None else 10_000
    P, _ = case.reachable_targets(n, seed=SEED)
    b = case.solver.solve_many(P)
    assert b.reachable.all(), (shape, b.counts())
    assert np.all(b.q >= case.solver.lower) and np.all(b.q <= case.solver.upper)
    O, Z = yourdfpy_axes(case, b.q)
    err = pointing_errors(O, Z, P)
    assert err.max() < GAZE_POINTING_TOL, (shape, float(err.max()))
    print(
        f"{shape}: {n} targets, worst {err.max():.3g} rad on yourdfpy, median iterations {np.median(b.iterations):.0f}"
    )
