""":class:`GazeSolver`: joint readings that point both cameras' optical axes at a 3D target.

One :meth:`GazeSolver.solve` call:

1. **Initial guess** (:mod:`~cpc2urdf.validation.gaze.guess`), on a redundant head with the
   cyclopean policy refined to first order; ``min-motion`` and ``eyes-only`` start from
   ``q_current``, :meth:`GazeSolver.track` from the previous solution.
2. **Policy phase**: task-priority Gauss-Newton (:mod:`~cpc2urdf.validation.gaze.gauss_newton`)
   with fixation first and the redundancy policy (:mod:`~cpc2urdf.validation.gaze.policies`) in
   its null space; skipped when fixation leaves no freedom to choose with (a calibrated head).
3. **Fixation alone**: if that does not fixate (the policy held a weak direction fixation
   needed, or a limit blocked the preferred configuration), the same iteration runs on fixation
   alone. If it ends in a local minimum, up to :data:`RETRIES` further starts with the eyes
   already turned are tried, and the best result is kept.
4. **Answer** (:mod:`~cpc2urdf.validation.gaze.result`).
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike
from scipy.sparse.csgraph import connected_components

from cpc2urdf.errors import ConfigurationError
from cpc2urdf.model import CPCModel
from cpc2urdf.tolerances import GAZE_PIXEL_FRACTION, GAZE_POINTING_TOL
from cpc2urdf.transforms import Array
from cpc2urdf.urdf.pinocchio import PinocchioRobot
from cpc2urdf.validation.gaze.batch import CompiledGaze, GazeBatch
from cpc2urdf.validation.gaze.chain import (
    KIND_BINOCULAR,
    PRISMATIC,
    Coupling,
    HeadChain,
    build_chain,
    home_readings,
)
from cpc2urdf.validation.gaze.fixation import (
    FixationState,
    evaluate_fixation,
    fixation_redundancy,
    target_point,
)
from cpc2urdf.validation.gaze.gauss_newton import (
    FLOOR_RESIDUAL,
    MAX_ITERATIONS,
    ActiveSetGaussNewton,
)
from cpc2urdf.validation.gaze.guess import GuessTable
from cpc2urdf.validation.gaze.head import DEFAULT_CAMERAS, GazeHead, Index
from cpc2urdf.validation.gaze.kernels import FAR_TARGET, S_NOT_FINITE
from cpc2urdf.validation.gaze.policies import (
    DEFAULT_VIEWING_DISTANCE,
    POLICIES,
    check_policy,
    free_joints,
)
from cpc2urdf.validation.gaze.result import (
    GazeSolution,
    solution_from_flat,
    solution_from_state,
)
from cpc2urdf.validation.gaze.tracking import SaccadeRule, Trajectory, track

_FLOAT64 = np.dtype(np.float64)  # numpy's one float64 descriptor: an `is` test (not ==, ~2x slower)

RETRIES = 2  # further starts tried when the first one ends in a local minimum
# [-]: most neck joints (revolute joints shared by both eyes) of a head the Python solver takes.
# Its start table (guess.GuessTable) is a grid over the neck readings, 37 x 13^(k-1) x 5 rows for
# k neck joints, each made by FK: 2,405 rows for a pan-tilt neck (the IIS-head), 31,265 for a
# yaw-pitch-roll neck (2.3 s to build), 406,445 for 4 (a CLI call took 42 s), 886 million for
# iCub's torso, neck and eye tilt (7: more memory than the machine has). A head with more gets
# the compiled solver alone, as every other shape does.
PYTHON_SOLVER_MAX_NECK = 3


def pointing_tolerance(tolerance: float | None = None, focal_px: float | None = None) -> float:
    """The pointing error [rad] below which an axis counts as on its target: ``tolerance``
    itself; else, with the cameras' focal length ``focal_px`` [px] known (the smaller of the
    two), :data:`~cpc2urdf.tolerances.GAZE_PIXEL_FRACTION` of a pixel at the image centre,
    ``atan(0.1 / focal_px)`` (2e-4 rad at 500 px); else
    :data:`~cpc2urdf.tolerances.GAZE_POINTING_TOL` (exact fixation).

    Raises:
        ConfigurationError: Both given, or either not a positive finite number.
    """
    if tolerance is not None and focal_px is not None:
        raise ConfigurationError("give a pointing tolerance [rad] or the cameras' focal length [px], not both")
    if tolerance is not None:
        if not (math.isfinite(tolerance) and tolerance > 0):
            raise ConfigurationError(f"the pointing tolerance must be a positive number of radians, got {tolerance}")
        return float(tolerance)
    if focal_px is not None:
        if not (math.isfinite(focal_px) and focal_px > 0):
            raise ConfigurationError(f"the focal length must be a positive number of pixels, got {focal_px}")
        return math.atan(GAZE_PIXEL_FRACTION / focal_px)
    return GAZE_POINTING_TOL


class GazeSolver:
    """Gaze inverse kinematics on the Pinocchio model of a URDF.

    Args:
        urdf: URDF text, the path of a URDF file, or a :class:`PinocchioRobot` already loaded
            (its model is used, not copied).
        cameras: Names of the left and right camera optical frames (z along the optical axis).
        viewing_distance: Preferred distance [m] from the cyclopean point to the target for the
            ``"use-table"`` policy.
        joints, coupling, rigid: Which joints may move, a stated coupling, and what a rigid
            pair points (see :func:`~cpc2urdf.api.gaze_solver`).
        tolerance: Pointing error [rad] below which a target counts as fixated.
        focal_px: Instead of ``tolerance``: the cameras' focal length [px]; fixated within
            :data:`~cpc2urdf.tolerances.GAZE_PIXEL_FRACTION` of a pixel
            (:func:`pointing_tolerance`). Neither: exact fixation (``GAZE_POINTING_TOL``).
        min_distance: Nearest [m] the policy brings a camera to the target where the pointing
            task leaves it the choice (a camera on an arm); 0: no limit; None:
            :data:`~cpc2urdf.validation.gaze.batch.MIN_VIEWING_DISTANCE` (0.1 m). A target only a
            nearer camera can fixate is still fixated.

    Raises:
        ConfigurationError: Both ``tolerance`` and ``focal_px``, or either not positive;
            ``min_distance`` negative or not finite.
        InputFileError: An unreadable URDF, or joints with more than one degree of freedom
            (continuous, floating, planar).
        UnknownNameError: A camera frame the URDF does not have.
        SpecError: A joint without finite limits, or the two cameras share every joint (no eye
            joints).

    Attributes:
        head: The :class:`~cpc2urdf.validation.gaze.head.GazeHead` (joint classes, limits, the
            Pinocchio ``model`` and ``data``), whose main attributes the solver repeats:
            ``model``, ``data``, ``cameras``, ``joint_names``, ``joint_kinds``, ``n``, ``lower``,
            ``upper``, ``velocity_limit``, ``home``, ``baseline``.
        redundant: Whether fixation by neck and eyes leaves spare freedom for the policy.
        tolerance: Pointing error [rad] below which a target counts as fixated.
        min_distance: Nearest [m] the compiled solver's policy brings a camera to the target.
    """

    def __init__(
        self,
        urdf: str | os.PathLike[str] | PinocchioRobot,
        cameras: Sequence[str] = DEFAULT_CAMERAS,
        *,
        viewing_distance: float = DEFAULT_VIEWING_DISTANCE,
        joints: Sequence[str] | None = None,
        coupling: Coupling | None = None,
        rigid: str = "cyclopean",
        tolerance: float | None = None,
        focal_px: float | None = None,
        min_distance: float | None = None,
    ) -> None:
        tolerance = pointing_tolerance(tolerance, focal_px)
        self.tolerance = tolerance
        # continuous joints read as revolute without limits: a robot's wheels are off the head's
        # paths; one on a path is refused by build_chain (no finite limits), naming it
        robot = urdf if isinstance(urdf, PinocchioRobot) else PinocchioRobot.from_urdf(urdf, continuous_as_revolute=True)
        if robot.cpc_model is not None:
            for name in cameras:
                robot.cpc_model.structure.frame(name)  # UnknownNameError with the model's frame names
        self.robot = robot
        self.cameras = tuple(cameras)
        self.joint_names = robot.joint_names
        self.joint_kinds = dict(zip(robot.joint_names, robot.joint_kinds, strict=True))
        self.n = robot.n_joints
        # The compiled solver: every head shape (one camera, two eyes, a rigid pair, couplings).
        self.chain: HeadChain = build_chain(robot, self.cameras, joints, coupling, rigid)
        self._coupling, self._rigid = coupling, rigid
        self._engines: dict[str, CompiledGaze] = {}
        self.compiled = CompiledGaze(self.chain, tolerance, min_distance=min_distance)
        self.min_distance = self.compiled.min_distance
        # The Python solver with its four policies: two independent eyes, every joint free.
        self._head: GazeHead | None = None
        if self.chain.kind == KIND_BINOCULAR and joints is None and coupling is None and self._neck_and_eyes():
            head = GazeHead(robot, self.cameras)
            if len(head.neck) <= PYTHON_SOLVER_MAX_NECK:
                self._legacy(head, viewing_distance)
        if self._head is None:
            self.lower = robot.lower.copy()
            self.upper = robot.upper.copy()
            self.velocity_limit = robot.velocity_limit.copy()
            self.home = home_readings(robot)
            self.baseline = self.compiled.baseline
            self.redundant = False
            self.model = robot.model
            self.data = robot.model.createData()
        # the cyclopean policy of a head that cannot fixate exactly: the compiled near-null
        # posture over neck and eyes (the table stays, as in the Python solver's policy)
        self._posture: CompiledGaze | None = None
        if self._head is not None and self.compiled.disparity_head:
            free = self._free_joints["cyclopean"]
            self._posture = CompiledGaze(
                build_chain(robot, self.cameras, [self.joint_names[i] for i in free]), tolerance,
                min_distance=min_distance,
            )
        # the cyclopean policy of a head that can: the compiled loop over neck and eyes with the
        # Python solver's secondary task, zero version (then the weighted home)
        self._version: CompiledGaze | None = None
        if self._head is not None and self._posture is None:
            free = self._free_joints["cyclopean"]
            vchain = build_chain(robot, self.cameras, [self.joint_names[i] for i in free])
            row = self._head.version_row
            vrow = np.array([row[robot.joint_index(v)] for v in vchain.variables])
            self._version = CompiledGaze(vchain, tolerance, vrow, min_distance)
        # the compiled solver of the cyclopean policy (solve_checked's choice; solve_many's)
        self._fast: CompiledGaze = self._posture or self._version or self.compiled

    def _neck_and_eyes(self) -> bool:
        """Whether every robot joint has finite limits (the Python solver's assumption)."""
        return bool(np.all(np.isfinite(self.robot.lower)) and np.all(np.isfinite(self.robot.upper)))

    def _legacy(self, head: GazeHead, viewing_distance: float) -> None:
        self._head = head
        self.model = head.model
        self.data = head.data
        self.lower = head.lower
        self.upper = head.upper
        self.velocity_limit = head.velocity_limit
        self.home = head.home
        self.baseline = head.baseline
        self._engine = ActiveSetGaussNewton(head, float(viewing_distance))
        self.redundant, converge_sign = fixation_redundancy(head, free_joints(head, "cyclopean"))
        self._guesses = GuessTable(head, converge_sign)
        self._free_joints = {policy: free_joints(head, policy) for policy in POLICIES}
        self._fixed_joints = {policy: np.setdiff1d(np.arange(self.n), free) for policy, free in self._free_joints.items()}
        left, right = head.camera_poses(head.home)
        self._centre: Array = 0.5 * (left[:3, 3] + right[:3, 3])  # cyclopean point at home (world) [m]

    @property
    def head(self) -> GazeHead:
        """The two-eye :class:`GazeHead` of the Python solver (its four policies, tracking).

        Raises:
            ConfigurationError: A head of another shape (one camera, a rigid pair, stated joints or
                a coupling, a joint without finite limits, more than
                :data:`PYTHON_SOLVER_MAX_NECK` revolute joints shared by the eyes): only the
                compiled solver (:meth:`solve`, :meth:`solve_many`) serves it.
        """
        if self._head is None:
            raise ConfigurationError(
                f"head {self.robot.name!r} ({self.chain.kind}, cameras {list(self.cameras)}) has only the compiled "
                "solver: solve() with the cyclopean or min-motion policy, and solve_many()"
            )
        return self._head

    @property
    def moving(self) -> tuple[str, ...]:
        """What :meth:`solve_many` and the cyclopean policy move: the names of the compiled
        solve's unknowns (joints, or a coupling's variables; an IIS-shaped head's table stays)."""
        return self._fast.chain.variables

    @property
    def kind(self) -> str:
        """The head's shape: ``"look-at"``, ``"binocular"`` or ``"rigid-stereo"``."""
        return self.chain.kind

    @property
    def disparity_head(self) -> bool:
        """Whether the head's two eyes cannot fixate exactly (their optical axes do not sweep one
        plane): :meth:`disparity_report` says by how much."""
        return self.compiled.disparity_head

    def disparity_report(self, n: int = 400, seed: int = 0) -> dict[str, object]:
        """The pointing error the cyclopean policy leaves over a workspace ahead (the head
        facing each target; :meth:`~cpc2urdf.validation.gaze.batch.CompiledGaze.disparity_report`)."""
        return (self._posture or self.compiled).disparity_report(n, seed)

    def ahead_targets(self, n: int = 400, seed: int = 0) -> Array:
        """The targets of :meth:`disparity_report` (world) [m], shape (n, 3)
        (:meth:`~cpc2urdf.validation.gaze.batch.CompiledGaze.ahead_targets`)."""
        return (self._posture or self.compiled).ahead_targets(n, seed)

    def solve_many(self, targets: ArrayLike, q_current: ArrayLike | None = None) -> GazeBatch:
        """Every target (rows of ``targets`` (N, 3), world [m]) through the compiled loop, from
        ``q_current`` (shape (n,); None: the middle of the limits); joints the head may not move
        stay at ``q_current``. Target by target the answer of :meth:`solve` with its default
        (cyclopean) policy: on the IIS-head the table stays. See
        :class:`~cpc2urdf.validation.gaze.batch.GazeBatch`.

        Raises:
            ConfigurationError: Targets not (N, 3) or not finite, or bad ``q_current``.
        """
        qc = self.check_q(q_current)
        return self._fast.solve_many(targets, qc)

    def check_q(self, q: ArrayLike | Mapping[str, float] | None) -> Array | None:
        """Readings ``q_current`` as an in-limit array of shape (n,), or None
        (:meth:`GazeHead.check_q`)."""
        if self._head is not None:
            return self._head.check_q(q)
        if q is None:
            return None
        return GazeHead.check_readings(self.robot, q)

    @classmethod
    def from_model(
        cls,
        model: CPCModel,
        cameras: Sequence[str] = DEFAULT_CAMERAS,
        *,
        viewing_distance: float = DEFAULT_VIEWING_DISTANCE,
    ) -> GazeSolver:
        """A solver for a :class:`cpc2urdf.model.CPCModel` (via its URDF)."""
        return cls(PinocchioRobot.from_model(model), cameras, viewing_distance=viewing_distance)

    @classmethod
    def from_urdf(
        cls,
        urdf: str | os.PathLike[str],
        cameras: Sequence[str] = DEFAULT_CAMERAS,
        *,
        viewing_distance: float = DEFAULT_VIEWING_DISTANCE,
    ) -> GazeSolver:
        """A solver for URDF text or a URDF file (:meth:`PinocchioRobot.from_urdf`)."""
        return cls(PinocchioRobot.from_urdf(urdf), cameras, viewing_distance=viewing_distance)

    @property
    def viewing_distance(self) -> float:
        """Preferred distance [m] from the cyclopean point to the target (``"use-table"``)."""
        self.head  # noqa: B018 (ConfigurationError on a head without the Python solver)
        return self._engine.viewing_distance

    @viewing_distance.setter
    def viewing_distance(self, value: float) -> None:
        self.head  # noqa: B018
        self._engine.viewing_distance = float(value)

    def free_joints(self, policy: str) -> Index:
        """Indices (into ``q``) of the joints ``policy`` lets move (on a head with only the
        compiled solver: the joints it may move, whatever the policy)."""
        check_policy(policy)
        if self._head is None:
            return np.flatnonzero(np.abs(self.chain.robot_A).sum(axis=1) > 0)
        return self._free_joints[policy]

    @property
    def path_joints(self) -> Index:
        """Indices (into ``q``) of the joints on the cameras' paths: the only ones that move a camera."""
        return np.unique(self.chain.joint_index)

    @property
    def motion_groups(self) -> tuple[Index, ...]:
        """Robot joints (indices into ``q``) that move only together: a URDF ``<mimic>`` follower
        with its driver, the joints of a stated coupling (readings ``q = A u + b`` sharing an
        unknown). Groups of two or more joints; the other joints move on their own."""
        A = (np.abs(self.chain.robot_A) > 0.0).astype(float)
        _, label = connected_components(A @ A.T > 0.0, directed=False)  # joints linked by a shared unknown
        groups = (np.flatnonzero(label == k) for k in np.unique(label))
        return tuple(g for g in groups if len(g) > 1)

    def evaluate(self, q: ArrayLike, p_world: ArrayLike, jacobian: bool = True) -> FixationState:
        """The fixation state (residual ``r``, shape (6,), ``|r|^2``, the target in each camera
        frame, and the (6, n) Jacobian ``J``) at readings ``q`` (shape (n,)) for target
        ``p_world`` (world) [m], shape (3,); the Jacobian now (``jacobian``) or when first used.
        Not checked beyond their conversion to float arrays: ``q`` and ``p_world`` must be finite.

        Raises:
            ConfigurationError: A head without the Python solver (see :attr:`head`): the
                compiled solver's answers carry their pointing errors instead.
        """
        return evaluate_fixation(self.head, np.asarray(q, dtype=float), np.asarray(p_world, dtype=float), jacobian)

    def initial_guess(self, p_world: ArrayLike, q_current: ArrayLike | None = None) -> Array:
        """The geometric starting point of :meth:`solve` (table from ``q_current`` or home).

        The neck readings of the precomputed grid whose cyclopean ray passes closest to the
        target (angle seen from the cyclopean point), refined to first order, and the eyes
        converged symmetrically on the target's distance (the default policy's start).
        """
        p = target_point(p_world)
        qc = self.head.check_q(q_current)
        q = (self.home if qc is None else qc).copy()
        return self._guesses.guess(self._solved_target(p), q, refine=self.redundant)

    def solve(
        self,
        p_world: ArrayLike,
        q_current: ArrayLike | Mapping[str, float] | None = None,
        policy: str = "cyclopean",
        *,
        q_start: ArrayLike | None = None,
        max_iterations: int = MAX_ITERATIONS,
    ) -> GazeSolution:
        """Joint readings that fixate ``p_world`` with both cameras. Moves nothing.

        Args:
            p_world: Target in ``world`` [m], shape (3,).
            q_current: Current readings [rad]/[m], shape (n,) or ``{joint: reading}``; the table
                (and for ``"eyes-only"`` the neck) stays here; ``"min-motion"`` moves least from
                here. None: the middle of every joint's limits.
            policy: One of :data:`~cpc2urdf.validation.gaze.policies.POLICIES`.
            q_start: Optional starting point of the iteration (e.g. the previous solution when
                tracking), shape (n,); fixed joints are taken from ``q_current`` regardless.
            max_iterations: Gauss-Newton iteration cap.

        Returns:
            A :class:`GazeSolution`; unreachable targets give ``reachable=False`` with the best
            in-limit readings and the residual, never an exception.

        Raises:
            ConfigurationError: a target or ``q_current`` with NaN/inf or the wrong shape, a
                reading outside the limits, or an unknown policy.
        """
        if q_current is None and q_start is None and policy == "cyclopean":
            # a control loop's call: straight to the compiled solve (what solve_checked picks). A
            # float (3,) array is copied (under the GIL: another thread may be writing it while
            # the kernel runs without) and not checked here: the kernel checks that it is finite
            # and keeps it in the answer (~2 of ~21 us a solve less than target_point's checks)
            comp = self._fast
            plain = type(p_world) is np.ndarray and p_world.dtype is _FLOAT64 and p_world.shape == (3,)
            p = p_world.copy() if plain else target_point(p_world)  # type: ignore[union-attr]
            out = comp.solve_target(p)
            if out[0] == S_NOT_FINITE:
                target_point(p)  # raises, naming the coordinates
            return solution_from_flat(self.joint_names, out, comp.S, policy)
        check_policy(policy)
        p = target_point(p_world)
        qc = self.check_q(q_current)
        return self.solve_checked(p, qc, policy, q_start, max_iterations)

    def solve_checked(
        self, p: Array, qc: Array | None, policy: str, q_start: ArrayLike | None, max_iterations: int
    ) -> GazeSolution:
        """:meth:`solve` on a checked target ``p`` and checked in-limit readings ``qc`` (or None):
        the entry of :meth:`track`, which does not re-check the readings it produced itself.

        The compiled solver answers on a head of another shape than two independent eyes, and
        for the cyclopean policy on every head (zero version in the null space of fixation
        where the head can fixate exactly; the near-null posture where it cannot,
        :attr:`disparity_head`); the Python solver answers the other policies ("min-motion",
        "eyes-only", "use-table") on two independent eyes."""
        if self._head is None:
            return self._solve_compiled(p, qc, policy, q_start)
        if policy == "cyclopean":
            return self._solve_compiled(p, qc, policy, q_start, self._posture or self._version)
        return self._solve_python(p, qc, policy, q_start, max_iterations)

    def _solve_compiled(
        self, p: Array, qc: Array | None, policy: str, q_start: ArrayLike | None = None,
        comp: CompiledGaze | None = None,
    ) -> GazeSolution:
        comp = comp or self._policy_engine(policy)
        qs = None
        if q_start is not None:
            qs = np.asarray(q_start, dtype=float)
            if qs.shape != (self.n,) or not np.all(np.isfinite(qs)):
                raise ConfigurationError(f"q_start must be {self.n} finite readings, got shape {qs.shape}")
        out = comp.solve_point(p, qc, qs)
        if out[0] == S_NOT_FINITE:  # a caller that skipped the check (solve_checked's contract)
            target_point(p)  # raises, naming the coordinates
        return solution_from_flat(self.joint_names, out, comp.S, policy)

    def _policy_engine(self, policy: str) -> CompiledGaze:
        """The compiled solver of ``policy`` (made on first use)."""
        engine = self._engines.get(policy)
        if engine is None:
            engine = self._engines[policy] = self._make_engine(policy)
        return engine

    def _make_engine(self, policy: str) -> CompiledGaze:
        chain = self.chain
        if policy == "cyclopean":
            return self._fast
        if policy == "min-motion":
            if self._head is None:
                return self._posture or self.compiled
            # the table stays; Euclidean in the readings; exact fixation wherever it exists
            K = range(len(chain.joint_index))
            moved = [k for k in K if not (chain.anc[0, k] and chain.anc[1, k] and chain.jtype[k] == PRISMATIC)]
        else:  # eyes-only
            if chain.kind != KIND_BINOCULAR:
                raise ConfigurationError(f"policy 'eyes-only' needs two eyes; this head is {chain.kind}")
            moved = [k for k in range(len(chain.joint_index)) if chain.anc[0, k] != chain.anc[1, k]]
        names = [self.joint_names[chain.joint_index[k]] for k in moved]
        if chain.moving:
            names = [nm for nm in names if nm in chain.moving]
        sub = build_chain(self.robot, self.cameras, names, self._coupling, self._rigid)
        sub.weight = np.ones(sub.m)
        return CompiledGaze(sub, self.tolerance, min_distance=self.min_distance, exact=True)

    def _solve_python(
        self, p: Array, qc: Array | None, policy: str, q_start: ArrayLike | None, max_iterations: int
    ) -> GazeSolution:
        q_ref = self.home.copy() if qc is None else qc
        free = self._free_joints[policy]
        p_solve = self._solved_target(p)
        if q_start is not None:
            q0 = np.clip(np.asarray(q_start, dtype=float).reshape(self.n), self.lower, self.upper)
            fixed = self._fixed_joints[policy]
            q0[fixed] = q_ref[fixed]
        elif policy == "eyes-only":
            q0 = q_ref.copy()
        elif policy == "min-motion" and qc is not None:
            q0 = q_ref.copy()
        else:
            # The refined start saves about one iteration. Only for the cyclopean policy on a
            # redundant head: the use-table and min-motion policies stop once fixation stalls,
            # and need the iterations of a coarser start to move the table or the neck where
            # they want; on a calibrated head it saves nothing (the first step along the weak
            # direction dominates) and loses a few near-fold targets (seeds 2 and 4: 0.5 % and
            # 1.1 % of 1,000 targets).
            q0 = self._guesses.guess(p_solve, q_ref, refine=policy == "cyclopean" and self.redundant)
        q, it, st = self._solve_from(p_solve, q0, q_ref, policy, free, max_iterations)
        if st.rr > FLOOR_RESIDUAL and policy != "eyes-only" and q_start is None:
            # Local minimum against a limit (e.g. pan at 0 deg while the eyes would have to
            # turn far): retry from the best grid starts with the eyes already turned.
            for rank in range(1, RETRIES + 1):
                q1, it1, st1 = self._solve_from(
                    p_solve, self._guesses.guess(p_solve, q_ref, rank), q_ref, policy, free, max_iterations
                )
                it += it1
                if st1.rr < st.rr:
                    q, st = q1, st1
                if st.rr <= FLOOR_RESIDUAL:
                    break
        if p_solve is not p:  # the answer is judged on the target itself
            st = evaluate_fixation(self.head, q, p, jacobian=False)
        return solution_from_state(self.head, p, q, it, policy, st, self.tolerance)

    def _solved_target(self, p: Array) -> Array:
        """The point the iteration aims at for target ``p`` (world) [m], shape (3,): ``p`` itself,
        or for a target with a coordinate beyond :data:`FAR_TARGET` the point on the ray from the
        head's centre (cyclopean point at home) through ``p`` at that distance.

        Seen from any camera, the two differ in direction by less than the head's reach over
        :data:`FAR_TARGET` (~1e-15 rad), below the rounding of a direction at that distance;
        beyond it the guess table and the policies would square coordinates out of the float
        range. The answer is still judged on ``p`` (:func:`evaluate_fixation` scales far
        targets).
        """
        px, py, pz = p.tolist()
        if max(abs(px), abs(py), abs(pz)) <= FAR_TARGET:
            return p
        d = p - self._centre
        d = d / np.max(np.abs(d))  # components in [-1, 1]: no overflow in the norm
        return self._centre + FAR_TARGET * (d / math.sqrt(float(d @ d)))

    def _solve_from(
        self, p: Array, q0: Array, q_ref: Array, policy: str, free: Index, max_iterations: int
    ) -> tuple[Array, int, FixationState]:
        engine = self._engine
        if self.redundant or policy == "use-table":
            q, it, st = engine.iterate(p, q0, q_ref, policy, free, max_iterations, secondary=True)
        else:  # the policy has no freedom to choose with: see fixation_redundancy
            q, it, st = q0, 0, evaluate_fixation(self.head, q0, p, jacobian=False)
        if st.rr > FLOOR_RESIDUAL and it < max_iterations:
            # Phase 2: fixation alone. Reached when the policy's preferred configuration does
            # not fixate: on a calibrated head (fixation has no spare freedom, only a weak
            # direction the policy was holding) or where a limit blocks the preferred one.
            q, it2, st = engine.iterate(p, q, q_ref, policy, free, max_iterations - it, secondary=False, st=st)
            it += it2
        return q, it, st

    def track(
        self,
        targets: ArrayLike,
        dt: float,
        max_velocity: ArrayLike | Mapping[str, float] | None = None,
        *,
        q_current: ArrayLike | None = None,
        policy: str = "cyclopean",
        saccades: SaccadeRule | None = None,
    ) -> Trajectory:
        """Follow a moving target (:func:`cpc2urdf.validation.gaze.tracking.track`), on any head shape.

        Args:
            targets: Target positions (world) [m], shape (T, 3), one per sample.
            dt: Sample period [s].
            max_velocity: Speed limits (see :class:`~cpc2urdf.validation.gaze.tracking.GazeTracker`):
                ``{joint: limit}``, per joint (shape (n,)), or a scalar over joints of one kind;
                None: the URDF velocity limits.
            q_current: Readings at the first sample, shape (n,); None: the first solution.
            policy: Redundancy policy.
            saccades: None: smooth pursuit only; a :class:`~cpc2urdf.validation.gaze.tracking.SaccadeRule`:
                minimum-jerk saccades too.
        """
        return track(self, targets, dt, max_velocity, q_current=q_current, policy=policy, saccades=saccades)

    def camera_poses(self, q: ArrayLike) -> tuple[Array, ...]:
        """``T_world_<camera>`` (4, 4) of each named camera (optical frame), in ``cameras`` order,
        at readings ``q`` (shape (n,)): the forward kinematics of the head's chain (on a two-eye
        head with every joint free, Pinocchio's, as before: the same to rounding)."""
        if self._head is not None:
            return self._head.camera_poses(q)
        qa = self.check_q(q)
        assert qa is not None
        R, o = self.compiled.camera_poses(qa)
        out = []
        for c in range(len(self.cameras)):
            T = np.eye(4)
            T[:3, :3] = R[c]
            T[:3, 3] = o[c]
            out.append(T)
        return tuple(out)

    def pointing_errors(self, q: Array, p: Array) -> Array:
        """Angle [rad] between each solved axis (two eyes: left, right; one camera or a rigid
        pair: its axis) at checked readings ``q`` (shape (n,)) and the direction to the checked
        target ``p`` (world) [m], shape (3,): what tracking reports of a commanded posture."""
        return self.compiled.pointing_errors(q, p)

def solver_for(
    ref: str | os.PathLike[str] | CPCModel,
    cameras: Sequence[str] = DEFAULT_CAMERAS,
    *,
    viewing_distance: float = DEFAULT_VIEWING_DISTANCE,
    joints: Sequence[str] | None = None,
    coupling: Coupling | None = None,
    rigid: str = "cyclopean",
    tolerance: float | None = None,
    focal_px: float | None = None,
    min_distance: float | None = None,
) -> GazeSolver:
    """A solver for a ``.urdf`` file (any case), a model file, a robot spec, a shipped robot name
    or a :class:`~cpc2urdf.model.CPCModel` (:meth:`PinocchioRobot.load`; ``continuous`` joints off
    the cameras' paths, e.g. a mobile base's wheels, are read as unlimited revolute ones)."""
    return GazeSolver(
        PinocchioRobot.load(ref, continuous_as_revolute=True), cameras, viewing_distance=viewing_distance,
        joints=joints, coupling=coupling, rigid=rigid, tolerance=tolerance, focal_px=focal_px,
        min_distance=min_distance,
    )


__all__ = ["FAR_TARGET", "RETRIES", "GazeSolver", "pointing_tolerance", "solver_for"]
