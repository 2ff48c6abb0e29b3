"""Many targets at once through the compiled loop: :class:`CompiledGaze` and :class:`GazeBatch`.

:class:`CompiledGaze` holds a head's :class:`~cpc2urdf.validation.gaze.chain.HeadChain`, its
table of starts (the policy's own answers for targets along the axes of seeded samples of the
unknowns, each with its cyclopean centre and axis) and whether it can fixate exactly (:meth:`CompiledGaze.disparity_report`).
:meth:`CompiledGaze.solve_point` runs :func:`~cpc2urdf.validation.gaze.kernels.solve_flat` on
one target (one compiled call: the head and the answer as flat arrays) with an optional warm
start (what :meth:`GazeSolver.solve` and tracking use); :meth:`CompiledGaze.solve_many` runs
the same solve over every target in one call
(:func:`~cpc2urdf.validation.gaze.kernels.solve_flat_many`, one call per core, the rows dealt
round-robin).

The policy (priority 2, in the near-null space of the pointing error): the posture nearest the
reference readings (``q_current``, or the middle of the limits) in a weighted metric where one
radian of a joint shared by both cameras (the neck) costs 1, of an eye joint
:data:`~cpc2urdf.validation.gaze.chain.EYE_WEIGHT` and one metre of a prismatic joint
:data:`~cpc2urdf.validation.gaze.chain.PRISMATIC_WEIGHT`: the neck turns to face the target and
the eyes stay near their middle (the cyclopean axis faces the target), the table stays. The
policy keeps the solved camera nearest the target at least ``min_distance`` from it where its
null space can (:data:`MIN_VIEWING_DISTANCE` unless stated; the zero-version task outranks it):
on a redundant chain (a camera on an arm) the
nearest posture can lie beyond the target along the optical axis, and the walk towards it would
end with the camera on the target. A target that only a nearer camera can fixate is still
fixated (the limit is the policy's, not a reachability test).
"""

from __future__ import annotations

import math
import os
import threading
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cpc2urdf.errors import ConfigurationError
from cpc2urdf.tolerances import GAZE_POINTING_TOL
from cpc2urdf.transforms import Array
from cpc2urdf.validation.gaze import kernels
from cpc2urdf.validation.gaze.chain import KIND_BINOCULAR, HeadChain
from cpc2urdf.validation.gaze.result import STATUSES

BATCH_STATUSES = STATUSES  # indexed by the kernels' status codes (kernels.S_FIXATED, ...)
TABLE_SIZE = 256  # starts in the table
TABLE_SEED = 0
TABLE_TARGET_DISTANCE = (
    1.0  # [m]: each table entry is the policy's answer for a target this far along its axis
)
N_STARTS = 3  # starts tried per target at most (a further one only if undecided)
BATCH_MAX_ITERATIONS = 60
# most iterations one solve_point reports: its starts, each a policy phase and a polish, twice
# with the zero-version fallback
MAX_SOLVE_ITERATIONS = 2 * N_STARTS * (BATCH_MAX_ITERATIONS + kernels.POLISH_ITERATIONS)
EXACT_NULL = 1e-12  # [-]: null_rel on heads that can fixate exactly
VERSION_WEIGHT = (
    1e8  # [-]: zero-version task vs the weighted home (scaled unknowns; effectively a constraint)
)
# [-]: largest weak eigenvalue ratio (4th / 1st of the pointing task at home) of a binocular head
# that cannot fixate exactly: above it, the 4th direction is the head's to point with
WEAK_RATIO = 1e-4
# [-]: null_rel on binocular heads that cannot fixate exactly: the weak direction is the policy's.
# It must lie above the weak ratio at every posture the policy reaches, not just at home (demo heads,
# seeds 0-9: up to 1.5e-5; at 1e-5, seed 2's neck swung 40 deg away from every target ahead for 0.6
# deg less disparity), and below the 3rd ratio, which is near 0.1 but falls towards 1e-3 near the
# limits (at 1e-3, 0.1-1.5 % of calibrated_iis_head(0-2)'s reachable targets ended at a limit).
NEAR_NULL = 2.0 * WEAK_RATIO
MIN_VIEWING_DISTANCE = 0.1  # [m]: default nearest approach of a camera to its target the policy makes (a camera's near focus)
THREADED_BATCH = 64  # targets per thread from which solve_many splits the work over the cores

_POOLS: dict[int, ThreadPoolExecutor] = {}
_POOLS_LOCK = threading.Lock()


def _after_fork_in_child() -> None:
    """A forked child (multiprocessing's default on Linux) inherits the pools without their
    threads (work queued there would never run) and the lock as it was (held, if another
    thread was making a pool): it starts with no pools (made on first use) and a free lock."""
    global _POOLS_LOCK
    _POOLS.clear()
    _POOLS_LOCK = threading.Lock()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_after_fork_in_child)


def _pool(threads: int) -> ThreadPoolExecutor:
    """The process's pool of ``threads`` worker threads for :meth:`CompiledGaze.solve_many`,
    made on first use and kept (starting two threads costs ~0.1-0.3 ms, a tenth of a
    2,000-target batch's time on a loaded machine); one pool however many threads ask first."""
    with _POOLS_LOCK:
        pool = _POOLS.get(threads)
        if pool is None:
            pool = _POOLS[threads] = ThreadPoolExecutor(threads, thread_name_prefix="cpc2urdf-gaze")
    return pool


@dataclass(frozen=True)
class GazeBatch:
    """The answers of :meth:`CompiledGaze.solve_many` for N targets.

    Attributes:
        q: Readings [rad]/[m], shape (N, n), in ``joint_names`` order; inside the limits.
        reachable: Pointing error of every solved axis within ``tolerance``, shape (N,).
        pointing_error: Angle between each solved optical axis and the target [rad], shape
            (N, S); the solved axes are ``axes`` (the cameras; for a rigid pair the cyclopean
            axis or the master eye).
        status: Code per target, shape (N,): an index into ``status_names``.
        status_names: The names of the codes (:data:`BATCH_STATUSES`).
        iterations: Gauss-Newton iterations per target, shape (N,).
        joint_names: The robot's joints.
        axes: Names of the solved axes.
        tolerance: [rad] below which an axis counts as on the target.
    """

    q: Array
    reachable: NDArray[np.bool_]
    pointing_error: Array
    status: NDArray[np.int8]
    status_names: tuple[str, ...]
    iterations: NDArray[np.int32]
    joint_names: tuple[str, ...]
    axes: tuple[str, ...]
    tolerance: float

    def status_of(self, i: int) -> str:
        """The status name of target ``i``."""
        return self.status_names[int(self.status[i])]

    def counts(self) -> dict[str, int]:
        """``{status name: number of targets}``."""
        return {name: int(np.sum(self.status == k)) for k, name in enumerate(self.status_names)}


class CompiledGaze:
    """The compiled gaze solver of one head (see the module docstring).

    Args:
        chain: The head.
        tolerance: [rad] pointing error below which an axis is on the target; None:
            :data:`~cpc2urdf.tolerances.GAZE_POINTING_TOL`.
        version_row: The zero-version task's row over the unknowns (None: no such task).
        min_distance: [m] nearest the policy brings a solved camera to the target (0: no
            limit); None: :data:`MIN_VIEWING_DISTANCE`.
        policy_table: True: the table of starts holds the policy's own answers (see
            :meth:`_policy_table`; ``table_targets`` their targets); False: the seeded samples
            alone (for comparison).
        exact: On two eyes that cannot fixate exactly (:attr:`disparity_head`): True solves
            pointing alone along every direction, the weak one too (exact fixation where the
            eyes' axes can meet, however far the neck turns); False leaves the weak direction
            to the policy (the posture facing the target, status ``disparity``).

    Raises:
        ConfigurationError: ``min_distance`` negative or not finite.
    """

    def __init__(
        self,
        chain: HeadChain,
        tolerance: float | None = None,
        version_row: Array | None = None,
        min_distance: float | None = None,
        policy_table: bool = True,
        exact: bool = False,
    ) -> None:
        self.chain = chain
        self.exact = exact
        self.min_distance = MIN_VIEWING_DISTANCE if min_distance is None else float(min_distance)
        if not (math.isfinite(self.min_distance) and self.min_distance >= 0.0):
            raise ConfigurationError(
                f"min_distance must be a finite distance >= 0 [m], got {min_distance!r}"
            )
        self.ch = kernels.pack(chain, version_row, VERSION_WEIGHT, self.min_distance)
        self.version_row = version_row
        self.tolerance = GAZE_POINTING_TOL if tolerance is None else float(tolerance)
        self.sw = np.sqrt(chain.weight)
        self.home_u = 0.5 * (chain.lower + chain.upper)
        self._ws = kernels.workspace(chain)
        self.S = len(chain.solve_cameras)
        names = chain.cameras
        self.axes: tuple[str, ...] = tuple(
            names[c] if c < len(names) else "cyclopean" for c in chain.solve_cameras.tolist()
        )
        self._table()
        self._held = np.abs(chain.A).sum(axis=1) == 0  # chain joints that may not move
        self._held_index = chain.joint_index[self._held]
        self._still = np.abs(chain.robot_A).sum(axis=1) == 0  # robot joints the head does not move
        robot = chain.robot
        self.baseline = self._baseline()
        self.disparity_head = False
        self.null_rel = EXACT_NULL
        if chain.kind == KIND_BINOCULAR:
            self.disparity_head = self._weak_direction() > 0.0
            if self.disparity_head and not exact:
                self.null_rel = NEAR_NULL
        self.n = len(robot.joint_names)
        self.threads = max(
            1,
            len(os.sched_getaffinity(0))
            if hasattr(os, "sched_getaffinity")
            else os.cpu_count() or 1,
        )
        self._qin = np.zeros(
            2 * self.n
        )  # never written: the kernel's q_current/q_start when neither is given
        self._out_size = kernels.out_size(self.n, self.S)
        self._home_centre = self._centre()
        self._pack()
        self.table_targets = np.full(
            (TABLE_SIZE, 3), np.nan
        )  # the policy table's targets (NaN: a seeded entry)
        if policy_table:
            self._policy_table()
        self.structural_null = self._structural_null()
        if (
            self.structural_null
        ):  # the kernels' null cut near a fixating posture (kernels.BINOCULAR_NULL)
            self.ch[13][3] = kernels.BINOCULAR_NULL
        if policy_table or self.structural_null:
            self._pack()  # the kernels' copy of the head: the new table and null cut

    def _pack(self) -> None:
        """The head as two flat arrays (``F``, ``I``): one solve is one call of
        :func:`~cpc2urdf.validation.gaze.kernels.solve_flat`."""
        chain = self.chain
        robot = chain.robot
        self.F, self.I = kernels.pack_flat(
            self.ch,
            chain.lower,
            chain.upper,
            self.sw,
            self._table_T,
            (chain.robot_A, chain.robot_b, robot.lower, robot.upper, chain.robot_pinv),
            chain.joint_index,
            self._held,
            self._still,
            N_STARTS,
            BATCH_MAX_ITERATIONS,
            self.null_rel,
            self.tolerance,
            self.baseline,
            self.disparity_head and not self.exact,
            self._home_centre,
        )
        # per thread, its solve_flat workspace (see _scratch), made again with the head: the
        # reference posture's cached scores are of the table packed here
        self._local = threading.local()

    def _fk(self, u: Array, b: Array | None = None) -> tuple[Array, Array]:
        ws = self._ws
        kernels.fk(
            self.ch, np.ascontiguousarray(u, dtype=float), self.chain.b if b is None else b, *ws[:5]
        )
        return ws[3].copy(), ws[4].copy()

    def _baseline(self) -> float:
        if len(self.chain.cameras) < 2:
            return 0.0
        _, o = self._fk(self.home_u)
        return float(np.linalg.norm(o[0] - o[1]))

    def _table(self) -> None:
        """The seeded table of starts: the joints shared by the cameras (weight under 10: not
        the eyes, not prismatic) uniform in their bounds, the others at home. A head without
        such a joint (two eyes each on its own joints, no neck) spreads its revolute eyes instead.

        Without that its 256 entries were all home, and so were a solve's every start: two eyes
        each on a roll (about the head's forward axis) and a tilt, at home, look along the roll
        axis, where the roll does not move the optical axis (a gimbal singularity). A target
        straight ahead but off to one side needs the roll turned, which no step from there
        finds: 4 / 45 of 400 exactly reachable targets 0.5-5 / 5-60 km ahead were `no_solution`
        (tests' ``_ahead``, seed 2), and the policy table kept the seeded one (its targets,
        straight ahead, failed alike); now 0 / 13, the 13 every target within 1.1e-6 rad of an
        eye's roll axis (under the null cut: docs/gaze.md, Known limits). The cost, on
        two pan-tilt eyes without a neck: 35 of 2,109 unreachable targets' best answers worse
        (median 2.6 deg), none better; iterations 15.1 -> 10.4."""
        ch = self.chain
        rng = np.random.default_rng(TABLE_SEED)
        U = np.tile(self.home_u, (TABLE_SIZE, 1))
        revolute = [v for v in range(ch.m) if ch.weight[v] < 10.0]
        spread = [v for v in revolute if not ch.eye[v]] or [
            v for v in revolute if ch.lower[v] < ch.upper[v]
        ]
        for v in spread:
            U[:, v] = rng.uniform(ch.lower[v], ch.upper[v], TABLE_SIZE)
        self._set_table(U)

    def _set_table(self, U: Array) -> None:
        """Table entries ``U`` (G, m) with each one's cyclopean centre and axis (world)."""
        ch = self.chain
        cams = ch.solve_cameras
        O = np.empty((len(U), 3))
        Z = np.empty((len(U), 3))
        for g in range(len(U)):
            R, o = self._fk(U[g])
            O[g] = o[cams].mean(axis=0)
            z = R[cams][:, :, 2].sum(axis=0)
            Z[g] = z / max(float(np.linalg.norm(z)), 1e-300)
        self.table_u, self.table_o, self.table_z = U, O, Z
        # the kernels' layout: one column per entry
        self._table_T = (
            np.ascontiguousarray(U.T),
            np.ascontiguousarray(O.T),
            np.ascontiguousarray(Z.T),
        )

    def _policy_table(self) -> None:
        """Each seeded entry replaced by the policy's own answer (from the middle of the limits)
        for a target :data:`TABLE_TARGET_DISTANCE` along the entry's cyclopean axis, where the
        head points at it (fixated, or a disparity head's near-null posture); the others stay.

        A seeded entry faces its direction with the other joints anywhere in their limits, so
        on a redundant head the policy phase walked far along the null space from it (iCub:
        12.6 iterations a reachable target); the policy's answer for a nearby direction is close
        to the answer wanted (10.1), and the policy's local minimum reached from it is more often
        the lower one. Built for the middle of the limits (no
        ``q_current``): from other readings, or with held joints elsewhere, it helps less."""
        P, status, answers = self._solve_along_table(TABLE_SIZE)
        pointed = (status == kernels.S_FIXATED) | (status == kernels.S_DISPARITY)
        U = self.table_u.copy()
        U[pointed] = answers[pointed]
        self.table_targets[pointed] = P[pointed]
        self._set_table(U)  # the kernels get it at the constructor's one repack

    def _solve_along_table(self, count: int) -> tuple[Array, Array, Array]:
        """Targets :data:`TABLE_TARGET_DISTANCE` along the first ``count`` table entries' axes
        (world, (count, 3)), solved from the middle of the limits: their status codes and
        answers' unknowns (count, m). On this thread (a few ms): a solver built inside a pool
        worker would otherwise wait on the pool it occupies."""
        P = np.ascontiguousarray((self.table_o + TABLE_TARGET_DISTANCE * self.table_z)[:count])
        OUT = np.empty((len(P), self._out_size))
        kernels.solve_flat_many(self.F, self.I, P, np.zeros(2 * self.n), kernels.MODE_FALLBACK, OUT)
        U = np.array([self.chain.u_from_q(q) for q in OUT[:, 2 : 2 + self.n]])
        return P, OUT[:, 0], U

    def _structural_null(self, sample: int = 64) -> bool:
        """Whether two eyes lose their 4th pointing direction at every fixating posture (their
        axes sweep one plane: iCub, the nominal IIS-head): at up to ``sample`` table entries that
        fixate their targets, the 4th eigenvalue of ``J_x J_x^T`` (``J_x = J / sw``) at most
        :data:`~cpc2urdf.validation.gaze.kernels.STRUCTURAL_NULL` of the 1st (rounding: 1e-16 on
        those heads; with the seeded table alone, at answers to targets along its first entries'
        axes). Not on two eyes each on its own roll and tilt (the roll is a real pointing
        direction, small only near straight ahead), nor with fewer than four unknowns."""
        chain = self.chain
        if chain.kind != KIND_BINOCULAR or self.disparity_head or chain.m < 2 * self.S:
            return False
        pointed = np.isfinite(self.table_targets[:, 0])
        if pointed.any():
            U, P = self.table_u[pointed], self.table_targets[pointed]
        else:  # the seeded table alone: solve targets along its first entries' axes
            P, status, U = self._solve_along_table(sample)
            fixated = status == kernels.S_FIXATED
            U, P = U[fixated], P[fixated]
        if len(P) == 0:
            return False
        ws = self._ws
        for g in range(0, len(P), max(1, len(P) // sample)):
            kernels.residual(self.ch, U[g].copy(), chain.b, P[g], ws[7], ws[8], True, *ws[:7])
            Jx = ws[8] / self.sw
            lam = np.linalg.eigvalsh(Jx @ Jx.T)  # ascending
            if lam[0] > kernels.STRUCTURAL_NULL * lam[-1]:
                return False
        return True

    def _weak_direction(self) -> float:
        """The weak eigenvalue ratio of the pointing task at home with both eyes on the closest
        point of their axes: 0 if the pointing task leaves an exact null space or is square,
        else ``l_min / l_max`` of the non-null part (a binocular head that cannot fixate
        exactly; its vertical disparity is :meth:`disparity_report`)."""
        R, o = self._fk(self.home_u)
        z0, z1 = R[0][:, 2], R[1][:, 2]
        # a point ahead of both at 1 m
        p = 0.5 * (o[0] + o[1]) + 1.0 * (z0 + z1) / max(float(np.linalg.norm(z0 + z1)), 1e-12)
        ws = self._ws
        kernels.residual(self.ch, self.home_u.copy(), self.chain.b, p, ws[7], ws[8], True, *ws[:7])
        J = ws[8] / self.sw
        sv = np.linalg.svd(J, compute_uv=False)
        sv = sv[sv > 1e-7 * sv[0]]
        # binocular pointing has rank 3 when the eyes sweep one plane (an exact null space for
        # the 4th condition) and rank 4 otherwise: a weak 4th singular value is disparity
        if len(sv) >= 4 and sv[3] ** 2 < WEAK_RATIO * sv[0] ** 2 and self.chain.m > 3:
            return float((sv[3] / sv[0]) ** 2)
        return 0.0

    def targets(self, targets: ArrayLike) -> Array:
        """Checked targets (N, 3), a C-contiguous copy (the kernel pulls far ones in along
        their ray from the head's centre to :data:`~cpc2urdf.validation.gaze.kernels.FAR_TARGET`)."""
        try:
            P = np.array(targets, dtype=float)
        except (TypeError, ValueError) as e:
            raise ConfigurationError(f"targets must be an (N, 3) array [m], got {targets!r}") from e
        if P.ndim != 2 or P.shape[1] != 3:
            raise ConfigurationError(f"targets must have shape (N, 3) [m], got shape {P.shape}")
        if not np.all(np.isfinite(P)):
            raise ConfigurationError("targets contain NaN or inf")
        return np.ascontiguousarray(P)

    def _centre(self) -> Array:
        _, o = self._fk(self.home_u)
        return o[self.chain.solve_cameras].mean(axis=0)  # type: ignore[no-any-return]

    def b_for(self, q_current: Array | None) -> Array:
        """The chain's constant part ``b`` for readings ``q_current`` (shape (n,); None: the
        middle of the limits): chain joints that may not move stay at their reading."""
        ch = self.chain
        if q_current is None:
            return ch.b
        b = ch.b.copy()
        b[self._held] = q_current[self._held_index]
        return b

    def camera_poses(self, q: Array) -> tuple[Array, Array]:
        """World rotations (C, 3, 3) and centres (C, 3) of the cameras (the named ones in order;
        a rigid pair's virtual cyclopean camera last) at robot readings ``q`` (shape (n,),
        in-limit; readings off a coupling are taken at their least-squares unknowns)."""
        ws = self._ws
        kernels.fk(self.ch, self.chain.u_from_q(q), self.b_for(q), *ws[:5])
        return ws[3].copy(), ws[4].copy()

    def pointing_errors(self, q: Array, p: Array) -> Array:
        """Angle [rad] between each solved axis (``axes``) at robot readings ``q`` (shape (n,))
        and the direction to target ``p`` (world) [m], shape (S,); pi for a target on a centre.
        Far targets are scaled by a power of two first (no overflow)."""
        R, o = self.camera_poses(q)
        px, py, pz = p.tolist()
        out = np.empty(self.S)
        for s, c in enumerate(self.chain.solve_cameras.tolist()):
            (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = R[c].tolist()
            ox, oy, oz = o[c].tolist()
            dx, dy, dz = px - ox, py - oy, pz - oz
            big = max(abs(dx), abs(dy), abs(dz))
            if big > 1e150:
                f = math.ldexp(1.0, -math.frexp(big)[1])
                dx, dy, dz = dx * f, dy * f, dz * f
            x = r00 * dx + r10 * dy + r20 * dz
            y = r01 * dx + r11 * dy + r21 * dz
            z = r02 * dx + r12 * dy + r22 * dz
            out[s] = kernels.pointing_error(x, y, z)
        return out

    def solve_target(self, p: Array) -> Array:
        """:meth:`solve_point` without readings or warm start, on a plain array ``p`` (float,
        shape (3,), C-contiguous and writeable: what the kernel is compiled for; no one may
        write it during the call, which runs without the GIL): a control loop's call, nothing
        checked or copied in Python."""
        f, ints = self._scratch()
        out = np.empty(self._out_size)
        kernels.solve_flat(self.F, self.I, p, self._qin, kernels.MODE_FALLBACK, out, f, ints)
        return out

    def solve_point(self, p: Array, q_current: Array | None, q_start: Array | None = None) -> Array:
        """One target ``p`` (float, shape (3,); a coordinate that is not finite is answered
        with status :data:`~cpc2urdf.validation.gaze.kernels.S_NOT_FINITE`) from checked
        in-limit readings ``q_current`` (shape (n,) or None: the middle of the limits),
        warm-started at readings ``q_start`` (shape (n,)) when given: a new array, the output of
        :func:`~cpc2urdf.validation.gaze.kernels.solve_flat` (status, iterations, readings,
        errors, misses, fixation point, vergence, limit flags, the target)."""
        if (
            not p.flags.carray
        ):  # a view, read-only: the kernel takes (and is compiled for) a plain array
            p = np.array(p, dtype=float)
        if q_current is None and q_start is None:
            return self.solve_target(p)
        mode = kernels.MODE_FALLBACK
        qin = np.empty(2 * self.n)
        if q_current is not None:
            qin[: self.n] = q_current
            mode |= kernels.MODE_Q_CURRENT
        if q_start is not None:
            qin[self.n :] = q_start
            mode |= kernels.MODE_WARM_START
        f, ints = self._scratch()
        out = np.empty(self._out_size)
        kernels.solve_flat(self.F, self.I, p, qin, mode, out, f, ints)
        return out

    def __getstate__(self) -> dict[str, Any]:
        """Pickled and copied without the threads' workspaces (a ``threading.local`` cannot be
        pickled, and a copy's threads make their own)."""
        state = self.__dict__.copy()
        del state["_local"]
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._local = threading.local()

    def _scratch(self) -> tuple[Array, Array]:
        """This thread's workspace buffers for :func:`~cpc2urdf.validation.gaze.kernels.solve_flat`
        (made on its first solve): a single solve allocates no workspace and scores the
        reference posture only when it changes. One pair a thread, since the kernel runs
        without the GIL: two threads solving on one solver never share a buffer."""
        try:
            return self._local.scratch  # type: ignore[no-any-return]
        except AttributeError:
            self._local.scratch = kernels.scratch(self.I)
            return self._local.scratch  # type: ignore[no-any-return]

    def solve_many(self, targets: ArrayLike, q_current: ArrayLike | None = None) -> GazeBatch:
        """Every target (rows of ``targets``, world [m]) from ``q_current`` (robot readings,
        shape (n,); None: the middle of the limits): a :class:`GazeBatch`, target by target
        the answer of :meth:`solve_point` (one compiled call for all)."""
        P = self.targets(targets)
        N = P.shape[0]
        n = self.n
        qin = np.zeros(2 * n)
        mode = kernels.MODE_FALLBACK
        if q_current is not None:
            Q = np.asarray(q_current, dtype=float)
            if Q.shape != (n,) or not np.all(np.isfinite(Q)):
                raise ConfigurationError(
                    f"q_current must be {n} finite readings, got shape {Q.shape}"
                )
            qin[:n] = Q
            mode |= kernels.MODE_Q_CURRENT
        OUT = np.empty((N, self._out_size))
        threads = min(self.threads, N // THREADED_BATCH)
        if threads > 1:
            # the kernel releases the GIL: one thread per core, each on an equal share. Rows are
            # dealt round-robin (row i to thread i mod threads), not in blocks: neighbouring
            # targets cost alike (a workspace map's unreachable region is a run of rows, an
            # unreachable target costs ~4 reachable ones), so blocks left one core idle for up
            # to a third of the call (bench nominal IIS-head, 2,000 reachable + 200 unreachable,
            # 2 cores: 88k -> 111k targets/s with the persistent pool below)
            dealt = [np.arange(k, N, threads) for k in range(threads)]
            order = np.concatenate(dealt)
            ends = np.cumsum([len(rows) for rows in dealt]).tolist()
            shares = list(zip([0, *ends[:-1]], ends, strict=True))
            T = np.ascontiguousarray(P[order])
            OUT_dealt = np.empty_like(OUT)
            list(
                _pool(threads).map(
                    lambda ab: kernels.solve_flat_many(
                        self.F, self.I, T[ab[0] : ab[1]], qin, mode, OUT_dealt[ab[0] : ab[1]]
                    ),
                    shares,
                )
            )
            OUT[order] = OUT_dealt
        elif N:
            kernels.solve_flat_many(self.F, self.I, P, qin, mode, OUT)
        o = 2 + n
        st = OUT[:, 0].astype(np.int8)
        return GazeBatch(
            q=OUT[:, 2:o].copy(),
            reachable=st == kernels.S_FIXATED,
            pointing_error=OUT[:, o : o + self.S].copy(),
            status=st,
            status_names=BATCH_STATUSES,
            iterations=OUT[:, 1].astype(np.int32),
            joint_names=self.chain.robot.joint_names,
            axes=self.axes,
            tolerance=self.tolerance,
        )

    def ahead_targets(self, n: int = 400, seed: int = 0) -> Array:
        """``n`` seeded targets (world) [m], shape (n, 3): 0.4-3 m in front of the home cyclopean
        centre, within 30 deg of the home cyclopean axis (uniform over that cone's solid angle
        near the axis)."""
        rng = np.random.default_rng(seed)
        R, o = self._fk(self.home_u)
        cams = self.chain.solve_cameras
        c = o[cams].mean(axis=0)
        z = R[cams][:, :, 2].sum(axis=0)
        z /= np.linalg.norm(z)
        x = np.cross(z, [0.0, 0.0, 1.0] if abs(z[2]) < 0.9 else [1.0, 0.0, 0.0])
        x /= np.linalg.norm(x)
        y = np.cross(z, x)
        ang = np.radians(30.0) * np.sqrt(rng.uniform(0, 1, n))
        phi = rng.uniform(0, 2 * math.pi, n)
        dist = rng.uniform(0.4, 3.0, n)
        d = np.cos(ang)[:, None] * z + np.sin(ang)[:, None] * (
            np.cos(phi)[:, None] * x + np.sin(phi)[:, None] * y
        )
        return c + dist[:, None] * d  # type: ignore[no-any-return]

    def disparity_report(self, n: int = 400, seed: int = 0) -> dict[str, Any]:
        """The pointing error this solver leaves over a workspace ahead (:meth:`ahead_targets`),
        each target solved: on a head that cannot fixate exactly, the policy's posture (the
        cyclopean axis facing the target) and the residual it leaves, not the least the head
        could reach turned another way (``cpc2urdf.validation.gaze.head_report`` measures that).

        Returns:
            ``{"exact", "median_rad", "p95_rad", "max_rad", "targets", "answered", "statuses"}``:
            ``exact`` whether the head can fixate exactly (no weak direction at home); the error
            statistics (max over the two eyes) [rad] over the ``answered`` targets (status
            fixated or disparity: those the policy points at; None if there is none); the
            count of each status.
        """
        batch = self.solve_many(self.ahead_targets(n, seed))
        e = batch.pointing_error.max(axis=1)
        names = list(batch.status_names)
        pointed = np.isin(batch.status, [names.index("fixated"), names.index("disparity")])
        ep = e[pointed]
        return {
            "exact": not self.disparity_head,
            "median_rad": float(np.median(ep)) if ep.size else None,
            "p95_rad": float(np.quantile(ep, 0.95)) if ep.size else None,
            "max_rad": float(ep.max()) if ep.size else None,
            "targets": n,
            "answered": int(ep.size),
            "statuses": batch.counts(),
        }


__all__ = [
    "BATCH_MAX_ITERATIONS",
    "BATCH_STATUSES",
    "EXACT_NULL",
    "MAX_SOLVE_ITERATIONS",
    "VERSION_WEIGHT",
    "NEAR_NULL",
    "WEAK_RATIO",
    "N_STARTS",
    "TABLE_SIZE",
    "CompiledGaze",
    "GazeBatch",
]
