""":class:`GazeSolver`: joint readings that point a head's cameras' optical axes at a 3D target.

Every solve runs the compiled loop (:mod:`~cpc2urdf.validation.gaze.batch`,
:mod:`~cpc2urdf.validation.gaze.kernels`) on the head's :class:`~cpc2urdf.validation.gaze.chain.HeadChain`;
each policy (:data:`~cpc2urdf.validation.gaze.options.POLICIES`) is one compiled solver over
the unknowns it moves, made on first use:

- ``cyclopean``: every joint on the cameras' paths, in the weighted metric of
  :mod:`~cpc2urdf.validation.gaze.batch`. On two eyes on a neck of at most
  :data:`VERSION_POLICY_MAX_NECK` joints, with nothing stated about the joints (the IIS-head's
  shape), the table stays and a zero-version task holds the eyes turned equally and oppositely;
  on such a head that cannot fixate exactly, the near-null posture (status ``disparity``).
- ``min-motion``: on that shape, neck and eyes (the table stays), Euclidean in their readings,
  exact fixation wherever the eyes' axes can meet; on other heads the cyclopean solver.
- ``eyes-only``: the joints on one camera's path only.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike
from scipy.sparse.csgraph import connected_components

from cpc2urdf.errors import ConfigurationError
from cpc2urdf.model import CPCModel
from cpc2urdf.transforms import Array
from cpc2urdf.urdf.pinocchio import PinocchioRobot
from cpc2urdf.validation.gaze.batch import CompiledGaze, GazeBatch
from cpc2urdf.validation.gaze.chain import (
    KIND_BINOCULAR,
    PRISMATIC,
    REVOLUTE,
    HeadChain,
    build_chain,
    home_readings,
)
from cpc2urdf.validation.gaze.kernels import FAR_TARGET, S_NOT_FINITE, interpreted
from cpc2urdf.validation.gaze.options import (
    DEFAULT_CAMERAS,
    GazeOptions,
    Index,
    check_policy,
    check_readings,
    target_point,
)
from cpc2urdf.validation.gaze.result import GazeSolution, solution_from_flat
from cpc2urdf.validation.gaze.tracking import SaccadeRule, Trajectory, track

_FLOAT64 = np.dtype(np.float64)  # numpy's one float64 descriptor: an `is` test (not ==, ~2x slower)

# [-]: most revolute joints shared by two eyes (a neck) for which the cyclopean policy holds the
# table and the version at zero: the IIS-head (pan, tilt) and necks like it. Heads with more
# (iCub's torso, neck and eye tilt; TALOS) keep the weighted posture over every path joint.
VERSION_POLICY_MAX_NECK = 3


_SWAPPED = interpreted._swapped  # non-empty while the kernels run as Python (the first use)


class GazeSolver:
    """Gaze inverse kinematics on the Pinocchio model of a URDF, every head shape and policy.

    Args:
        urdf: URDF text, the path of a URDF file, or a :class:`PinocchioRobot` already loaded
            (its model is used, not copied).
        cameras: Names of one or two camera optical frames (z along the optical axis).
        options: Which joints move, the tolerance, ... (:class:`GazeOptions`; None: defaults).
        fields: :class:`GazeOptions` fields (``joints=...``, ``tolerance=...``), over ``options``.

    Raises:
        InputFileError: An unreadable URDF, or joints with more than one degree of freedom
            (continuous, floating, planar).
        UnknownNameError: A camera frame the URDF does not have.
        SpecError: A joint on the cameras' paths without finite limits, or no joint that moves
            a camera.

    Attributes:
        robot, cameras, joint_names, joint_kinds, n: The robot, the camera frames, its joints
            (Pinocchio's order), ``{joint: "revolute" | "prismatic"}`` and their number.
        lower, upper, velocity_limit, home: Per joint, shape (n,): limits, URDF velocity limits
            and the middle of the limits.
        baseline: Distance [m] between the two cameras at ``home`` (0 for one camera).
        options, tolerance, min_distance: The options and what they resolve to ([rad], [m]).
        chain, compiled: The head's chain of every path joint and its compiled solver.
    """

    def __init__(
        self,
        urdf: str | os.PathLike[str] | PinocchioRobot,
        cameras: Sequence[str] = DEFAULT_CAMERAS,
        options: GazeOptions | None = None,
        **fields: Any,
    ) -> None:
        opts = _options(options, fields)
        interpreted.compile_in_background()  # the first use after an install: see kernels.interpreted
        self.options = opts
        self.tolerance = opts.tolerance_rad
        # continuous joints read as revolute without limits: a robot's wheels are off the head's
        # paths; one on a path is refused by build_chain (no finite limits), naming it
        robot = (
            urdf
            if isinstance(urdf, PinocchioRobot)
            else PinocchioRobot.from_urdf(urdf, continuous_as_revolute=True)
        )
        if robot.cpc_model is not None:
            for name in cameras:
                robot.cpc_model.structure.frame(
                    name
                )  # UnknownNameError with the model's frame names
        self.robot = robot
        self.cameras = tuple(cameras)
        self.joint_names = robot.joint_names
        self.joint_kinds = dict(zip(robot.joint_names, robot.joint_kinds, strict=True))
        self.n = robot.n_joints
        self.chain: HeadChain = build_chain(
            robot, self.cameras, opts.joints, opts.coupling, opts.rigid
        )
        self.compiled = CompiledGaze(self.chain, self.tolerance, min_distance=opts.min_distance)
        self.min_distance = self.compiled.min_distance
        self.lower = robot.lower.copy()
        self.upper = robot.upper.copy()
        self.velocity_limit = robot.velocity_limit.copy()
        self.home = home_readings(robot)
        self.baseline = self.compiled.baseline
        self.model = robot.model
        self.data = robot.model.createData()
        self._engines: dict[str, CompiledGaze] = {}
        self._fast = self._policy_engine("cyclopean")  # a control loop's solver

    # ---- the compiled solver of each policy ----

    def _version_shaped(self) -> bool:
        """Whether the cyclopean policy holds the table and the version (see the module docstring)."""
        ch, opts = self.chain, self.options
        if ch.kind != KIND_BINOCULAR or opts.joints is not None or opts.coupling is not None:
            return False
        if not (np.all(np.isfinite(self.robot.lower)) and np.all(np.isfinite(self.robot.upper))):
            return False
        neck = ch.anc[0] & ch.anc[1] & (ch.jtype == REVOLUTE)
        return int(neck.sum()) <= VERSION_POLICY_MAX_NECK

    def _policy_engine(self, policy: str) -> CompiledGaze:
        """The compiled solver of ``policy`` (made on first use).

        Raises:
            ConfigurationError: ``eyes-only`` on a head without two eyes.
        """
        engine = self._engines.get(policy)
        if engine is None:
            engine = self._engines[policy] = self._make_engine(policy)
        return engine

    def _make_engine(self, policy: str) -> CompiledGaze:
        ch = self.chain
        K = range(len(ch.joint_index))
        if policy == "eyes-only":
            if ch.kind != KIND_BINOCULAR:
                raise ConfigurationError(
                    f"policy 'eyes-only' needs two eyes; this head is {ch.kind} (cameras {list(self.cameras)})"
                )
            moved = [k for k in K if ch.anc[0, k] != ch.anc[1, k]]
        elif not self._version_shaped():
            return self._fast if policy == "min-motion" else self.compiled
        else:  # the table stays
            moved = [
                k for k in K if not (ch.anc[0, k] and ch.anc[1, k] and ch.jtype[k] == PRISMATIC)
            ]
        names = [
            self.joint_names[ch.joint_index[k]]
            for k in moved
            if self.joint_names[ch.joint_index[k]] in ch.moving
        ]
        sub = build_chain(
            self.robot, self.cameras, names, self.options.coupling, self.options.rigid
        )
        mind = self.options.min_distance
        if policy == "cyclopean":
            if self.compiled.disparity_head:  # the near-null posture
                return CompiledGaze(sub, self.tolerance, min_distance=mind)
            return CompiledGaze(sub, self.tolerance, self._version_row(sub), mind)
        sub.weight = np.ones(sub.m)  # Euclidean in the readings
        return CompiledGaze(sub, self.tolerance, min_distance=mind, exact=True)

    def _version_row(self, sub: HeadChain) -> Array:
        """The version ``(eye_L - home_L) + s (eye_R - home_R)`` of the first eye joint of each
        side as a row over the unknowns of ``sub`` (``s``: +1 where the two turn about nearly the
        same world direction at home, else -1)."""
        ch = self.chain
        e0, e1 = (
            int(ch.joint_index[np.flatnonzero(ch.anc[c] & ~ch.anc[1 - c])[0]]) for c in (0, 1)
        )
        data = self.model.createData()
        pin.computeJointJacobians(self.model, data, self.home)
        a0, a1 = (pin.getJointJacobian(self.model, data, e + 1, pin.WORLD)[3:, e] for e in (e0, e1))
        row = np.zeros(self.n)
        row[e0], row[e1] = 1.0, 1.0 if float(a0 @ a1) >= 0.0 else -1.0
        return np.array([row[self.robot.joint_index(v)] for v in sub.variables])

    # ---- what the head is ----

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
        return self._fast.disparity_report(n, seed)

    def ahead_targets(self, n: int = 400, seed: int = 0) -> Array:
        """The targets of :meth:`disparity_report` (world) [m], shape (n, 3)
        (:meth:`~cpc2urdf.validation.gaze.batch.CompiledGaze.ahead_targets`)."""
        return self._fast.ahead_targets(n, seed)

    def free_joints(self, policy: str) -> Index:
        """Indices (into ``q``) of the joints ``policy`` lets move.

        Raises:
            ConfigurationError: An unknown policy, or ``eyes-only`` on a head without two eyes.
        """
        check_policy(policy)
        return np.flatnonzero(np.abs(self._policy_engine(policy).chain.robot_A).sum(axis=1) > 0)

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
        _, label = connected_components(
            A @ A.T > 0.0, directed=False
        )  # joints linked by a shared unknown
        groups = (np.flatnonzero(label == k) for k in np.unique(label))
        return tuple(g for g in groups if len(g) > 1)

    def check_q(self, q: ArrayLike | Mapping[str, float] | None) -> Array | None:
        """Readings ``q_current`` (shape (n,) or ``{joint: reading}`` naming every joint) as an
        in-limit array of shape (n,), or None (:func:`~cpc2urdf.validation.gaze.options.check_readings`)."""
        if q is None:
            return None
        return check_readings(self.joint_names, self.lower, self.upper, q)

    # ---- solving ----

    def solve(
        self,
        p_world: ArrayLike,
        q_current: ArrayLike | Mapping[str, float] | None = None,
        policy: str = "cyclopean",
        *,
        q_start: ArrayLike | None = None,
    ) -> GazeSolution:
        """Joint readings that fixate ``p_world`` with the head's cameras. Moves nothing.

        Args:
            p_world: Target in ``world`` [m], shape (3,).
            q_current: Current readings [rad]/[m], shape (n,) or ``{joint: reading}``; the joints
                the policy does not move stay here; ``"min-motion"`` moves least from here.
                None: the middle of every joint's limits.
            policy: One of :data:`~cpc2urdf.validation.gaze.options.POLICIES`.
            q_start: Optional starting point (e.g. the previous solution when tracking), shape (n,).

        Returns:
            A :class:`GazeSolution`; unreachable targets give ``reachable=False`` with the best
            in-limit readings and the residual, never an exception.

        Raises:
            ConfigurationError: a target or ``q_current`` with NaN/inf or the wrong shape, a
                reading outside the limits, an unknown policy, or ``eyes-only`` without two eyes.
        """
        if _SWAPPED:
            interpreted.compiled_now()
        if q_current is None and q_start is None and policy == "cyclopean":
            # a control loop's call: straight to the compiled solve. A float (3,) array is copied
            # (under the GIL: another thread may be writing it while the kernel runs without)
            # and not checked here: the kernel checks that it is finite and keeps it in the answer
            comp = self._fast
            plain = (
                type(p_world) is np.ndarray and p_world.dtype is _FLOAT64 and p_world.shape == (3,)
            )
            p = p_world.copy() if plain else target_point(p_world)  # type: ignore[union-attr]
            out = comp.solve_target(p)
            if out[0] == S_NOT_FINITE:
                target_point(p)  # raises, naming the coordinates
            return solution_from_flat(self.joint_names, out, comp.S, policy)
        check_policy(policy)
        return self.solve_checked(target_point(p_world), self.check_q(q_current), policy, q_start)

    def solve_checked(
        self, p: Array, qc: Array | None, policy: str, q_start: ArrayLike | None
    ) -> GazeSolution:
        """:meth:`solve` on a checked target ``p`` and checked in-limit readings ``qc`` (or None):
        the entry of :meth:`track`, which does not re-check the readings it produced itself."""
        comp = self._policy_engine(policy)
        qs = None
        if q_start is not None:
            qs = np.asarray(q_start, dtype=float)
            if qs.shape != (self.n,) or not np.all(np.isfinite(qs)):
                raise ConfigurationError(
                    f"q_start must be {self.n} finite readings, got shape {qs.shape}"
                )
        out = comp.solve_point(p, qc, qs)
        if out[0] == S_NOT_FINITE:  # a caller that skipped the check (solve_checked's contract)
            target_point(p)  # raises, naming the coordinates
        return solution_from_flat(self.joint_names, out, comp.S, policy)

    def solve_many(self, targets: ArrayLike, q_current: ArrayLike | None = None) -> GazeBatch:
        """Every target (rows of ``targets`` (N, 3), world [m]) through the compiled loop, from
        ``q_current`` (shape (n,); None: the middle of the limits); joints the head may not move
        stay at ``q_current``. Target by target the answer of :meth:`solve` with its default
        (cyclopean) policy. See :class:`~cpc2urdf.validation.gaze.batch.GazeBatch`.

        Raises:
            ConfigurationError: Targets not (N, 3) or not finite, or bad ``q_current``.
        """
        if _SWAPPED:
            interpreted.compiled_now()
        return self._fast.solve_many(targets, self.check_q(q_current))

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
        """Follow a moving target (:func:`cpc2urdf.validation.gaze.tracking.track`).

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
        return track(
            self, targets, dt, max_velocity, q_current=q_current, policy=policy, saccades=saccades
        )

    def camera_poses(self, q: ArrayLike) -> tuple[Array, ...]:
        """``T_world_<camera>`` (4, 4) of each named camera (optical frame), in ``cameras`` order,
        at in-limit readings ``q`` (shape (n,)): the forward kinematics of the head's chain."""
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

    @classmethod
    def from_model(
        cls,
        model: CPCModel,
        cameras: Sequence[str] = DEFAULT_CAMERAS,
        options: GazeOptions | None = None,
    ) -> GazeSolver:
        """A solver for a :class:`cpc2urdf.model.CPCModel` (via its URDF)."""
        return cls(PinocchioRobot.from_model(model), cameras, options)

    @classmethod
    def from_urdf(
        cls,
        urdf: str | os.PathLike[str],
        cameras: Sequence[str] = DEFAULT_CAMERAS,
        options: GazeOptions | None = None,
    ) -> GazeSolver:
        """A solver for URDF text or a URDF file (:meth:`PinocchioRobot.from_urdf`)."""
        return cls(PinocchioRobot.from_urdf(urdf), cameras, options)


def solver_for(
    ref: str | os.PathLike[str] | CPCModel,
    cameras: Sequence[str] = DEFAULT_CAMERAS,
    options: GazeOptions | None = None,
    **fields: Any,
) -> GazeSolver:
    """A solver for a ``.urdf`` file (any case), a model file, a robot spec, a shipped robot name
    or a :class:`~cpc2urdf.model.CPCModel` (:meth:`PinocchioRobot.load`; ``continuous`` joints off
    the cameras' paths, e.g. a mobile base's wheels, are read as unlimited revolute ones).

    ``fields``: :class:`GazeOptions` fields (``joints=...``, ``tolerance=...``), over ``options``.
    """
    opts = _options(options, fields)
    return GazeSolver(PinocchioRobot.load(ref, continuous_as_revolute=True), cameras, opts)


def _options(options: GazeOptions | None, fields: dict[str, Any]) -> GazeOptions:
    """``options`` (None: the defaults) with ``fields`` over it.

    Raises:
        ConfigurationError: A field :class:`GazeOptions` does not have, or a bad value.
    """
    opts = GazeOptions() if options is None else options
    if not fields:
        return opts
    unknown = sorted(set(fields) - {f.name for f in dataclasses.fields(GazeOptions)})
    if unknown:
        raise ConfigurationError(
            f"unknown gaze option {unknown[0]!r}; expected one of "
            f"{', '.join(f.name for f in dataclasses.fields(GazeOptions))}"
        )
    return dataclasses.replace(opts, **fields)


__all__ = ["FAR_TARGET", "VERSION_POLICY_MAX_NECK", "GazeOptions", "GazeSolver", "solver_for"]
