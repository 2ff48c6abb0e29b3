"""Gaze IK (cpc2urdf/validation/gaze/).

Fixation is checked by FK the solver does not use: the CPC model's own vectorised FK for every
solution, and yourdfpy on the same URDF file for a seeded random subset (yourdfpy costs ~1 ms
per configuration, too slow for all 20,000 within the test budget). Reachable targets come from
``heads.reachable_targets``: sampled readings whose two optical axes meet (see its module
docstring), so every one of them is fixatable by construction.
"""

from __future__ import annotations

import math
import multiprocessing
import os
import sys
import threading

import numpy as np
import pytest
from gaze_heads import IIS_CAMERAS as CAMERAS
from gaze_heads import model_pointing_errors

from cpc2urdf.errors import ConfigurationError, InputFileError, SpecError, UnknownNameError
from cpc2urdf.files.robot_ref import load_model
from cpc2urdf.identification.simulation.heads import (
    calibrated_iis_head,
    reachable_targets,
    too_close_targets,
    unreachable_targets,
)
from cpc2urdf.tolerances import GAZE_POINTING_TOL
from cpc2urdf.urdf.document import write_urdf
from cpc2urdf.urdf.pinocchio import PinocchioRobot
from cpc2urdf.validation.crosscheck import yourdfpy_pose
from cpc2urdf.validation.gaze import POLICIES, GazeSolver, solver_for

N_TARGETS = 10_000
N_YOURDFPY = 300
N_UNREACHABLE = 150
AHEAD = np.array([-0.6, -0.6, 0.7])


@pytest.fixture(scope="module")
def nominal():
    return load_model("iis_head")


@pytest.fixture(scope="module")
def solver(nominal):
    return GazeSolver.from_model(nominal)


@pytest.fixture(scope="module", params=["nominal", "calibrated"])
def head(request, tmp_path_factory):
    model = load_model("iis_head") if request.param == "nominal" else calibrated_iis_head(0)
    path = write_urdf(model, tmp_path_factory.mktemp(request.param) / "head.urdf")
    return request.param, model, path, GazeSolver(path)


def _errors_yourdfpy(path, solver, Q, P):
    import yourdfpy

    robot = yourdfpy.URDF.load(str(path), load_meshes=False, build_collision_scene_graph=False)
    order = [solver.joint_names.index(n) for n in robot.actuated_joint_names]
    out = np.empty((len(Q), 2))
    for k, (q, p) in enumerate(zip(Q, P, strict=True)):
        robot.update_cfg(q[order])
        for e, cam in enumerate(CAMERAS):
            T = yourdfpy_pose(robot, cam, "world")
            pc = T[:3, :3].T @ (p - T[:3, 3])
            out[k, e] = math.atan2(math.hypot(pc[0], pc[1]), pc[2])
    return out


def test_reachable_targets_all_fixated_within_limits(head):
    """10,000 seeded reachable targets per head: every solution fixates to < 1e-9 rad per eye.

    On the calibrated head the cyclopean policy answers with its posture and the head's
    disparity (tests/test_gaze_heads.py); fixation alone (``min-motion``) finds the exact
    fixation these targets have by construction, however far it swings the head."""
    name, model, path, solver = head
    P, Q_made = reachable_targets(model, N_TARGETS, seed=1)
    # the construction itself is sound: its readings fixate its targets
    assert np.all(model_pointing_errors(model, Q_made, P) < GAZE_POINTING_TOL)
    policy = "min-motion" if solver.disparity_head else "cyclopean"
    sols = [solver.solve(p, policy=policy) for p in P]
    failed = [i for i, s in enumerate(sols) if not s.reachable]
    assert not failed, f"{name}: {len(failed)} reachable targets not fixated, e.g. {P[failed[0]]}"
    Q = np.array([s.q for s in sols])
    assert np.all(Q >= solver.lower) and np.all(Q <= solver.upper)
    err = model_pointing_errors(model, Q, P)
    assert err.max() < GAZE_POINTING_TOL, f"{name}: worst {err.max():.3g} rad"
    reported = np.array([s.pointing_error for s in sols])
    assert np.allclose(reported, err, atol=1e-12)
    pick = np.random.default_rng(0).choice(N_TARGETS, N_YOURDFPY, replace=False)
    err_y = _errors_yourdfpy(path, solver, Q[pick], P[pick])
    assert err_y.max() < GAZE_POINTING_TOL
    # cyclopean and min-motion policies: the table never moves
    assert np.all(Q[:, :2] == solver.home[:2])


def test_unreachable_targets_all_reported(head):
    name, model, _, solver = head
    U = unreachable_targets(model, N_UNREACHABLE, seed=2)
    for p in U:
        s = solver.solve(p)
        assert not s.reachable, f"{name}: {p} reported fixated"
        assert s.status != "fixated" and s.pointing_error.max() > GAZE_POINTING_TOL
        assert np.all(s.q >= solver.lower) and np.all(s.q <= solver.upper)
        assert np.all(np.isfinite(s.pointing_error)) and np.all(np.isfinite(s.miss_distance))
        # the report is of the returned readings (the CPC model's FK)
        T = model.fk(s.q, CAMERAS)
        for e, cam in enumerate(CAMERAS):
            pc = T[cam][:3, :3].T @ (p - T[cam][:3, 3])
            miss = math.hypot(pc[0], pc[1]) if pc[2] >= 0 else float(np.linalg.norm(pc))
            assert (
                abs(s.miss_distance[e] - miss) < 1e-9
                and abs(s.pointing_error[e] - math.atan2(math.hypot(pc[0], pc[1]), pc[2])) < 1e-9
            ), (name, p, cam)
    # with the head still, targets inside the cameras' orbit about the vergence axis
    q = solver.solve(AHEAD).q
    for p in too_close_targets(model, q, 100, seed=3):
        s = solver.solve(p, q, "eyes-only")
        assert not s.reachable and np.all(s.q[:4] == q[:4])


def test_cyclopean_on_nominal(nominal, solver):
    sol = solver.solve(AHEAD)
    assert sol.reachable and sol.status == "fixated"
    assert np.all(model_pointing_errors(nominal, sol.q, AHEAD) < GAZE_POINTING_TOL)
    assert np.all(sol.q[:2] == solver.home[:2])
    # zero version: the eyes turn equally and oppositely from home
    assert abs((sol.q[4] - solver.home[4]) + (sol.q[5] - solver.home[5])) < 1e-9
    assert np.linalg.norm(sol.fixation_point - AHEAD) < 1e-9
    # reported geometry agrees with the CPC model
    T = nominal.fk(sol.q, CAMERAS)
    z = [T[c][:3, 2] for c in CAMERAS]
    assert abs(sol.vergence - math.acos(z[0] @ z[1])) < 1e-9
    assert sol.miss_distance.max() < 1e-9 and sol.at_limit == ()
    assert set(sol.joints) == set(nominal.structure.joint_names)
    assert sol.to_json()["reachable"] is True


def test_policies(nominal, solver):
    q0 = solver.solve(AHEAD).q
    q_cur = q0 + np.array([0.0, 0.0, 0.05, 0.02, -0.03, 0.04])
    near = AHEAD + np.array([0.0, 0.02, 0.0])
    mm = solver.solve(near, q_cur, "min-motion")
    cy = solver.solve(near, q_cur, "cyclopean")
    assert mm.reachable and cy.reachable
    assert np.linalg.norm(mm.q - q_cur) <= np.linalg.norm(cy.q - q_cur) + 1e-12
    assert np.all(mm.q[:2] == q_cur[:2])
    # eyes-only: head and table stay; a target the eyes alone can reach (from the cyclopean
    # solution, along the left eye's optical axis) is fixated, one above the eye plane is not
    T = nominal.fk(q0, CAMERAS)
    o, z = T[CAMERAS[0]][:3, 3], T[CAMERAS[0]][:3, 2]
    plane_target = o + 0.8 * z
    eo = solver.solve(plane_target, q0, "eyes-only")
    assert eo.reachable and np.all(eo.q[:4] == q0[:4])
    up = solver.solve(AHEAD + np.array([0.2, 0.0, 0.0]), q0, "eyes-only")
    assert not up.reachable and np.all(up.q[:4] == q0[:4])
    assert set(POLICIES) == {"cyclopean", "min-motion", "eyes-only"}


def test_limits_are_constraints_not_a_clamp(nominal, solver):
    """A target whose cyclopean solution would need pan beyond 180 deg is still fixated exactly,
    by verging more (the limit constrains the solve)."""
    P, Q = reachable_targets(nominal, 4000, seed=5)
    pan = Q[:, 2]
    i = int(np.argmax(pan))  # a target the construction fixates with pan near its limit
    sol = solver.solve(P[i])
    assert sol.reachable
    assert np.all(sol.q >= solver.lower) and np.all(sol.q <= solver.upper)


def test_tracking_circle_1khz(nominal, solver):
    """A target circling at 1 kHz: never faster than the limit, locked on after the first samples."""
    dt = 1e-3
    t = np.arange(1000) * dt
    centre = AHEAD + np.array([0.3, 0.0, 0.0])  # tilt ~21 deg: well inside the limits
    radius = 0.05
    w = 2 * math.pi  # [rad/s]: one turn per second
    P = centre + radius * np.stack([np.cos(w * t), np.sin(w * t), np.zeros_like(t)], axis=1)
    vmax = np.array([0.1, 0.1, 1.0, 1.0, 2.0, 2.0])
    q_start = solver.solve(P[0]).q
    tr = solver.track(P, dt, vmax, q_current=q_start)
    v = np.abs(np.diff(np.vstack([q_start, tr.q]), axis=0)) / dt
    assert np.all(v <= vmax * (1 + 1e-12))
    assert tr.reachable.all() and tr.locked.all()
    assert tr.pointing_error.max() < GAZE_POINTING_TOL
    assert np.all(model_pointing_errors(nominal, tr.q[::50], P[::50]) < GAZE_POINTING_TOL)
    # a slow head lags: velocity-limited, not locked, but never over the limit
    slow = vmax / 50
    tr2 = solver.track(P, dt, slow, q_current=q_start)
    v2 = np.abs(np.diff(np.vstack([q_start, tr2.q]), axis=0)) / dt
    assert np.all(v2 <= slow * (1 + 1e-12)) and not tr2.locked.all()


def test_bad_input(solver, tmp_path):
    for bad in ([np.nan, 0, 0], [0, 0], [[0, 0, 1]], [0, np.inf, 1], "abc", None):
        with pytest.raises(ConfigurationError):
            solver.solve(bad)
    with pytest.raises(ConfigurationError, match="policy"):
        solver.solve(AHEAD, policy="nope")
    with pytest.raises(ConfigurationError, match="shape"):
        solver.solve(AHEAD, q_current=[0, 0, 0])
    with pytest.raises(ConfigurationError, match="outside"):
        solver.solve(AHEAD, q_current=[0, 0, 9, 0, 0, 0])
    with pytest.raises(ConfigurationError):
        solver.track(np.zeros((3, 2)), 1e-3)
    with pytest.raises(ConfigurationError):
        solver.track(np.zeros((3, 3)), -1.0)
    with pytest.raises(UnknownNameError):
        GazeSolver.from_model(load_model("iis_head"), ("camera_left_optical", "nope"))
    path = write_urdf(load_model("iis_head"), tmp_path / "head.urdf")
    with pytest.raises(UnknownNameError, match="nope"):
        GazeSolver(path, ("nope", "camera_right_optical"))
    with pytest.raises(UnknownNameError):
        GazeSolver("<robot name='x'><link name='a'/></robot>")
    with pytest.raises(InputFileError):
        GazeSolver(str(tmp_path / "missing.xml"))
    xml = tmp_path / "head.xml"  # any file name: a string not starting with '<' is a path
    xml.write_text(path.read_text())
    assert GazeSolver(str(xml)).solve(AHEAD).reachable
    continuous = (
        "<robot name='x'><link name='a'/><link name='camera_left_optical'/><link name='camera_right_optical'/>"
        "<joint name='j' type='continuous'><parent link='a'/><child link='camera_left_optical'/></joint>"
        "<joint name='k' type='fixed'><parent link='a'/><child link='camera_right_optical'/></joint></robot>"
    )
    # a continuous joint is read as revolute without limits (a base's wheels are off a head's
    # paths); on a camera's path it is refused, naming it
    with pytest.raises(SpecError, match=r"joints \['j'\] need finite <limit lower/upper>"):
        GazeSolver(continuous)


def test_every_form_of_a_target_gets_the_same_answer(solver):
    """solve() copies a float (3,) array and leaves its check to the kernel (which checks
    finiteness and keeps the target): every other form of the same point (list, ints,
    float32, read-only, a strided view, big-endian) gets the same answer, a non-finite one the
    same one-line error, and the answer's target is not the caller's array."""
    ref = solver.solve(np.array([-0.6, -0.6, 0.7]))
    grid = np.zeros((3, 2))
    grid[:, 1] = [-0.6, -0.6, 0.7]
    ro = np.array([-0.6, -0.6, 0.7])
    ro.flags.writeable = False
    for form in (
        [-0.6, -0.6, 0.7],
        (-0.6, -0.6, 0.7),
        np.array([-0.6, -0.6, 0.7], dtype=">f8"),
        ro,
        grid[:, 1],
        np.array([-0.6, -0.6, 0.7])[None][0],
    ):
        sol = solver.solve(form)
        assert (
            np.array_equal(sol.q, ref.q)
            and sol.status == ref.status
            and np.array_equal(sol.target, ref.target)
        )
    assert solver.solve(np.array([0, 0, 1], dtype=np.int64)).target.tolist() == [0.0, 0.0, 1.0]
    p = np.array([-0.6, -0.6, 0.7])
    sol = solver.solve(p)
    p[:] = 9.0
    assert sol.target.tolist() == [-0.6, -0.6, 0.7]
    q = sol.q.copy()
    other = solver.solve(np.array([0.3, -0.9, 0.6]))  # each answer its own array
    assert np.array_equal(sol.q, q) and not np.array_equal(other.q, q)
    for bad in (
        np.array([np.nan, 0.0, 1.0]),
        np.array([0.0, -np.inf, 1.0]),
        np.array([0.0, 0.0, np.inf]),
    ):
        with pytest.raises(ConfigurationError, match=r"target must be finite, got \["):
            solver.solve(bad)


def _batch_in_child(solver, P, queue):
    queue.put(solver.solve_many(P).q)


@pytest.mark.skipif(not hasattr(os, "fork"), reason="fork only")
def test_batch_in_a_forked_child(solver):
    """A process forked after a threaded batch (multiprocessing's default on Linux) inherits the
    thread pool without its threads: its own batch must still run (it hung before the pool was
    dropped at fork), with the parent's answers."""
    P = AHEAD + np.random.default_rng(0).normal(0, 0.05, (300, 3))
    comp = solver._policy_engine("cyclopean")
    threads = comp.threads
    comp.threads = 2  # threaded on any machine: the pool exists after this batch
    try:
        parent = solver.solve_many(P)
        ctx = multiprocessing.get_context("fork")
        queue = ctx.Queue()
        child = ctx.Process(target=_batch_in_child, args=(solver, P, queue))
        child.start()
        try:
            q = queue.get(timeout=120)
        finally:
            child.join(10)
            if child.is_alive():
                child.kill()
    finally:
        comp.threads = threads
    assert np.array_equal(q, parent.q)


_LEAK_CHECK = """
import numpy as np
from numba.core.runtime import rtsys
from cpc2urdf.files.robot_ref import load_model
from cpc2urdf.identification.simulation.heads import reachable_targets, unreachable_targets
from cpc2urdf.validation.gaze import GazeSolver

model = load_model("iis_head")
s = GazeSolver.from_model(model)
P, Q = reachable_targets(model, 60, 0)
T = np.concatenate([P, unreachable_targets(model, 20, 0), [[1e300, 2e300, 1e300], [np.nan, 0.0, 0.0]]])
comp = s._policy_engine("cyclopean")


def every_path():
    comp.solve_many(T[:-1])                                   # one call per core
    for p in T[:-1]:
        s.solve(p)                                            # the control loop's call
    for p, q0, q1 in zip(P[:20], Q[:20], Q[1:21]):
        s.solve(p, q_current=q0, q_start=q1)                  # readings and a warm start
    try:
        s.solve(T[-1])                                        # refused in the kernel, raised here
    except Exception:
        pass


def live():
    st = rtsys.get_allocation_stats()
    return st.alloc - st.free, st.mi_alloc - st.mi_free


every_path()
before = live()
for _ in range(5):
    every_path()
print(before, live())
"""


def test_the_compiled_solve_releases_every_array():
    """The solve's inner kernels run without numba's reference counting (kernels.py,
    ``kernel_without_refcounts``): one that called a function returning a new array would leak
    it on every solve. numba's own allocation counts (NUMBA_NRT_STATS, read at its start: a
    fresh process) must not grow over repeated solves through every path of the kernel: a
    batch, single solves (reachable, unreachable with the fallback, an astronomically far
    target, one with NaN) and solves from readings with a warm start."""
    import subprocess

    env = dict(os.environ, NUMBA_NRT_STATS="1")
    done = subprocess.run(
        [sys.executable, "-c", _LEAK_CHECK], env=env, capture_output=True, text=True, timeout=600
    )
    assert done.returncode == 0, done.stderr[-2000:]
    before, after = done.stdout.strip().splitlines()[-1].split(") (")
    assert before + ")" == "(" + after, (
        f"live numba allocations (arrays, meminfos) grew: {done.stdout.strip()}"
    )


def _kernel_calls_with_another_signature() -> list[str]:
    """Calls, inside ``kernels.py``, of a kernel that is not inlined which would make numba compile
    another copy of it: an omitted argument (typed as its default) or a module integer constant
    or integer literal (typed as a literal). A literal bool is allowed: it selects a branch of a
    small kernel at compile time (``residual``'s ``want_jac``)."""
    import ast
    import inspect

    from cpc2urdf.validation.gaze import kernels

    tree = ast.parse(inspect.getsource(kernels))
    constants = set()
    for node in tree.body:
        if not isinstance(node, ast.Assign):
            continue
        for target in node.targets:  # NAME = 1, A, B = 1, 2
            if isinstance(target, ast.Tuple) and isinstance(node.value, ast.Tuple):
                pairs = list(zip(target.elts, node.value.elts, strict=True))
            else:
                pairs = [(target, node.value)]
            constants |= {
                n.id
                for n, v in pairs
                if isinstance(n, ast.Name) and isinstance(v, ast.Constant) and type(v.value) is int
            }
    functions = {n.name: n for n in tree.body if isinstance(n, ast.FunctionDef)}

    def decorated(fn: ast.FunctionDef, kinds: tuple[str, ...]) -> bool:
        return any(isinstance(d, ast.Name) and d.id in kinds for d in fn.decorator_list)

    compiled = {
        name
        for name, fn in functions.items()
        if decorated(fn, ("kernel", "kernel_without_refcounts"))
    }
    found = []
    for name, fn in functions.items():
        if not decorated(fn, ("kernel", "kernel_without_refcounts", "inline_kernel")):
            continue  # Python calls a kernel with its ints typed int64, never a literal
        for call in ast.walk(fn):
            if not (
                isinstance(call, ast.Call)
                and isinstance(call.func, ast.Name)
                and call.func.id in compiled
            ):
                continue
            n_params = len(functions[call.func.id].args.args)
            where = f"{name} -> {call.func.id} (line {call.lineno})"
            if len(call.args) != n_params or call.keywords:
                found.append(f"{where}: {len(call.args)} of {n_params} arguments")
            for a in call.args:
                if isinstance(a, ast.Name) and a.id in constants:
                    found.append(f"{where}: the constant {a.id}")
                elif isinstance(a, ast.Constant) and type(a.value) is int:
                    found.append(f"{where}: the literal {a.value}")
    return found


def test_every_kernel_is_compiled_for_one_signature():
    """numba compiles a kernel once per argument signature, and types a module constant as a
    literal and an omitted argument as its default: ``solve_one`` once called ``_iterate`` (~85 kB
    of machine code) with four signatures, four copies that doubled the cold compile (183 s ->
    87 s without them) and that a solve after other work fetched from memory. The calls between
    the kernels that are not inlined pass every argument, and no integer constant."""
    assert _kernel_calls_with_another_signature() == []


def test_a_target_written_by_another_thread_during_solve(solver):
    """solve() copies the caller's array before the kernel runs without the GIL: with another
    thread writing it (a finite target, then NaN, over and over), every call either refuses a
    NaN target or answers the finite one, readings and target alike (without the copy, answers
    mixed the two, and a NaN seen by the kernel but gone by the check came back as an answer)."""
    A = np.array([-0.6, -0.6, 0.7])
    ref = solver.solve(A)
    shared = A.copy()
    stop = threading.Event()

    def writer():
        nan = np.array([np.nan, -0.6, 0.7])
        while not stop.is_set():
            shared[:] = nan
            shared[:] = A

    interval = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)
    thread = threading.Thread(target=writer)
    thread.start()
    answered = 0
    try:
        for _ in range(400):
            try:
                sol = solver.solve(shared)
            except ConfigurationError as e:
                assert "target must be finite" in str(e)
                continue
            answered += 1
            assert (
                np.array_equal(sol.target, A)
                and np.array_equal(sol.q, ref.q)
                and sol.status == ref.status
            )
    finally:
        stop.set()
        thread.join()
        sys.setswitchinterval(interval)
    assert answered > 0


def test_target_on_camera_centre_is_not_fixated(nominal, solver):
    """A target on a camera centre has no direction: that eye counts as missed by pi, the
    status says too close, and the readings stay finite (the iteration used to start from an
    infinite Jacobian there and return NaN readings, or raise LinAlgError)."""
    for q in (solver.home, solver.lower, solver.upper):
        left, right = solver.camera_poses(q)
        for k, T in enumerate((left, right)):
            for policy in POLICIES:
                with np.errstate(over="raise", invalid="raise", divide="raise"):
                    sol = solver.solve(T[:3, 3], q, policy, q_start=q)
                assert np.all(np.isfinite(sol.q)), (policy, k)
                assert np.all(sol.q >= solver.lower) and np.all(sol.q <= solver.upper)
                if policy == "eyes-only":  # the camera cannot leave its centre
                    assert not sol.reachable and sol.status == "too_close"
                    assert sol.pointing_error[k] == math.pi
            sol = solver.solve(T[:3, 3], q, "eyes-only")  # from its table: the eye may turn off it
            assert not sol.reachable and np.all(np.isfinite(sol.q))


# Reachable (each is fixated at the readings after it) only with an eye at its lower bound and
# tilt 0.03 rad below its limit: the weighted home's pull of the eyes to their middle led
# pointing into the corner pan = 0, tilt at its limit (joint_limits, 0.27 / 0.42 deg); 2 of
# 40,000 heads.reachable_targets (seeds 10-19, indices 3072 of seed 11, 3054 of seed 18)
CORNER_TARGETS = (
    (
        [-0.3156096808719948, 0.1461449846005398, 0.21604715033419486],
        [
            0.5,
            0.25,
            0.24914717090413305,
            1.0205095036362168,
            0.00520147806113107,
            0.47137090259605297,
        ],
    ),
    (
        [-0.3473969614746056, 0.13481412892199035, 0.23582311840347847],
        [0.5, 0.25, 0.13994656096534083, 1.01630261109377, 0.0372579384869882, 0.635520248693666],
    ),
)


def test_cyclopean_fixates_targets_reachable_only_near_a_corner_of_the_limits(nominal, solver):
    """The cyclopean solve and solve_many fixate them, inside the limits; the reported errors,
    misses and fixation point are those of the returned readings."""
    P = np.array([p for p, _ in CORNER_TARGETS])
    for p, q_ref in CORNER_TARGETS:
        assert np.all(
            model_pointing_errors(nominal, np.array(q_ref), np.array(p)) < GAZE_POINTING_TOL
        )
    batch = solver.solve_many(P)
    assert batch.reachable.all(), batch.counts()
    for i, p in enumerate(P):
        sol = solver.solve(p)
        assert sol.status == "fixated", (sol.status, sol.pointing_error)
        assert np.array_equal(sol.q, batch.q[i])
        assert np.all(sol.q >= solver.lower) and np.all(sol.q <= solver.upper)
        assert np.all(model_pointing_errors(nominal, sol.q, p) < GAZE_POINTING_TOL)
        assert sol.miss_distance.max() < 1e-9 and np.linalg.norm(sol.fixation_point - p) < 1e-9


def test_issue_14_targets_are_answered():
    """The targets a fuzz once broke on (and one of each exception class the fuzz found before the fix)
    get an answer; these are out of reach of the cyclopean policy (multi-start least squares
    finds no better residual than ~0.04 and ~0.07), and say so."""
    solver = solver_for("iis_head")
    for p in (
        [-0.43113785, -0.00847718, 0.49782345],
        [-0.5193035806142361, 0.2288544102489361, 0.740739145620153],
    ):
        with np.errstate(over="raise", invalid="raise", divide="raise"):
            sol = solver.solve(p)
        assert not sol.reachable and sol.status in ("too_close", "joint_limits")
        assert (
            np.all(np.isfinite(sol.q))
            and np.all(sol.q >= solver.lower)
            and np.all(sol.q <= solver.upper)
        )
        assert sol.pointing_error.max() > 0.08


def test_astronomically_far_targets(solver):
    """Targets up to the largest float are solved for their direction and judged on the target
    itself: far ahead is fixated, behind is not, and nothing overflows."""
    left, right = solver.camera_poses(solver.home)
    centre = 0.5 * (left[:3, 3] + right[:3, 3])
    ahead = (AHEAD - centre) / np.linalg.norm(AHEAD - centre)
    near = solver.solve(centre + 1e9 * ahead)
    for r in (1e16, 1e100, 1e300):
        with np.errstate(over="raise", invalid="raise", divide="raise"):
            sol = solver.solve(centre + r * ahead)
        assert sol.reachable and sol.pointing_error.max() < GAZE_POINTING_TOL, r
        assert np.allclose(sol.q, near.q, atol=1e-8)
        assert np.all(np.isfinite(sol.miss_distance))
    for p in ([1.7e308, -1.7e308, 1.7e308], [-1.7e308, -1.7e308, -1.7e308], [5e-324, 0.0, 0.0]):
        with np.errstate(over="raise", invalid="raise", divide="raise"):
            for policy in POLICIES:
                sol = solver.solve(p, None, policy)
                assert np.all(np.isfinite(sol.q)) and np.all(np.isfinite(sol.pointing_error)), (
                    p,
                    policy,
                )
                assert sol.reachable == (sol.status == "fixated")
    assert not solver.solve(centre - 1e300 * ahead).reachable
    # beyond the largest float (|p_cam| > 1.8e308) the angles still come from the direction
    huge = np.array([-1.7e308, -1.7e308, 1.7e308])
    a, b = solver.solve(huge, None, "eyes-only"), solver.solve(huge * 1e-8, None, "eyes-only")
    assert np.array_equal(a.q, b.q) and np.allclose(
        a.pointing_error, b.pointing_error, rtol=0, atol=1e-12
    )


def test_one_robot_resolver_and_one_pinocchio_model(tmp_path):
    """``HEAD.URDF`` is a URDF for the gaze solver as for the view (one rule, robot_ref), and a
    solver on a loaded PinocchioRobot uses that model rather than parsing the URDF again."""
    path = write_urdf(load_model("iis_head"), tmp_path / "HEAD.URDF")
    robot = PinocchioRobot.load(path)
    assert robot.cpc_model is None and robot.source == str(path)
    solver = GazeSolver(robot)
    assert solver.model is robot.model and solver.data is not None
    assert solver_for(str(path)).solve(AHEAD).reachable
    assert (
        solver.solve(AHEAD).q.tolist()
        == GazeSolver.from_model(load_model("iis_head")).solve(AHEAD).q.tolist()
    )
    # Pinocchio's getFrameId returns nframes for an unknown name; the robot checks names itself
    with pytest.raises(UnknownNameError, match="unknown frame 'nope'"):
        robot.frame_id("nope")
    with pytest.raises(UnknownNameError, match="unknown joint 'neck'"):
        robot.joint_index("neck")
