"""Following a moving target: warm-started gaze solves, smooth pursuit and minimum-jerk saccades.

Every sample solves for the target, warm-started from the previous answer (unless that misses
the new target by more than :data:`WARM_START_ANGLE`: the target jumped), and moves the
commanded readings towards that answer:

- **Smooth pursuit** (always): at most ``max_velocity * dt`` per joint and sample.
- **Saccades** (optional, :class:`SaccadeRule`), as the iCub gaze controller makes them: when
  the commanded posture misses the target by more than the rule's threshold (more than the
  solver's answer misses it), the head jumps to that answer along the minimum-jerk profile in
  joint space (Flash and Hogan 1985)::

      q(t) = q0 + (q1 - q0) (10 s^3 - 15 s^4 + 6 s^5),    s = t / T,

  zero velocity and acceleration at both ends, a symmetric bell of velocity with its peak
  ``15/8 |q1 - q0| / T`` at ``s = 1/2`` and a peak acceleration ``10/sqrt(3) |q1 - q0| / T^2``
  at ``s = (3 -+ sqrt(3)) / 6``. The duration ``T`` is the shortest whole number of samples at
  which no joint exceeds its velocity limit (nor, when given, its acceleration limit), and at
  least the rule's ``min_duration``. The last sample of a saccade is exactly the answer it aimed
  at; smooth pursuit takes over from there. A saccade starts only towards an answer that points
  at the target (status ``fixated``, or ``disparity`` on a head that cannot fixate exactly); an
  unreachable target is pursued. A saccade starts only from rest (the last commanded step at
  most :data:`REST_FRACTION` of every joint's speed limit): a head already pursuing at speed
  keeps pursuing, and a saccade's zero start velocity is the commanded one. A saccade whose
  target moves on ends: every ``reaim_interval`` it checks its end point, and when that misses
  the sample's target by more than the threshold (and :data:`STALE_FLOOR`) beyond the sample's
  own answer, or that answer no longer points at the target, pursuit takes over from the
  commanded readings (towards the new answer, velocity-limited), and a new saccade may start
  after another ``reaim_interval``. Readings stay continuous and inside the limits; the
  commanded velocity can step at that sample by up to twice the speed limits (a reversal at a
  saccade's peak speed).

Pursuit moves joints that move only together (a URDF ``<mimic>`` follower and its driver, the
joints of a stated coupling: :attr:`WarmStartSolver.motion_groups`) by one common fraction of
their steps, so their relation holds on every sample; the other joints move on their own. The
acceleration limit of a :class:`SaccadeRule` bounds its saccades only: pursuit is
velocity-limited.

:class:`GazeTracker` is one control loop (``step`` per sample); :func:`track` runs it over a
whole target trajectory.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cpc2urdf.errors import ConfigurationError
from cpc2urdf.transforms import Array
from cpc2urdf.validation.gaze.options import check_policy, target_point
from cpc2urdf.validation.gaze.result import STATUS_DISPARITY, STATUS_FIXATED, GazeSolution

MIN_JERK_PEAK_VELOCITY = 15.0 / 8.0  # peak of d/ds (10 s^3 - 15 s^4 + 6 s^5), at s = 1/2
MIN_JERK_PEAK_ACCELERATION = 10.0 / math.sqrt(3.0)  # peak of its |d2/ds2|, at s = (3 -+ sqrt 3) / 6
SACCADE_STATUSES = (
    STATUS_FIXATED,
    STATUS_DISPARITY,
)  # answers a saccade aims at: they point at the target
DEFAULT_SACCADE_THRESHOLD = math.radians(5.0)  # [rad]: pointing error that starts a saccade
DEFAULT_SACCADE_MIN_DURATION = 0.02  # [s]: the shortest saccade
DEFAULT_REAIM_INTERVAL = 0.02  # [s]: a saccade under way checks its aim this often
REST_FRACTION = 0.1  # [-]: a saccade starts only when the last step is at most this of every joint's speed limit
STALE_FLOOR = 1e-6  # [rad]: a saccade's end point must miss by more than this beyond the answer to end it (not rounding)
WARM_START_ANGLE = math.radians(
    5.0
)  # [rad]: a last answer missing the new target by more is not a start
LOCK_TOL = 1e-15  # [rad]/[m]: commanded readings this close to the answer are locked on it


class WarmStartSolver(Protocol):
    """What tracking needs of a solver (:class:`~cpc2urdf.validation.gaze.GazeSolver`, any head shape)."""

    @property
    def joint_names(self) -> tuple[str, ...]:
        """The robot's joints, in the order of the readings."""
        ...

    @property
    def velocity_limit(self) -> Array:
        """Per-joint URDF velocity limits [rad/s]/[m/s], shape (n,)."""
        ...

    @property
    def joint_kinds(self) -> Mapping[str, str]:
        """``{joint: "revolute" | "prismatic"}``."""
        ...

    @property
    def motion_groups(self) -> tuple[NDArray[np.intp], ...]:
        """Robot joints (indices into the readings) that move only together (mimic, coupling)."""
        ...

    def free_joints(self, policy: str) -> NDArray[np.intp]:
        """Indices of the joints ``policy`` lets move."""
        ...

    @property
    def path_joints(self) -> NDArray[np.intp]:
        """Indices of the joints on the cameras' paths (the others never move a camera)."""
        ...

    def check_q(self, q: ArrayLike | None) -> Array | None:
        """Readings as an in-limit array of shape (n,), or None."""
        ...

    def pointing_errors(self, q: Array, p: Array) -> Array:
        """Pointing error [rad] of each solved axis at readings ``q`` for target ``p``."""
        ...

    def solve_checked(
        self, p: Array, qc: Array | None, policy: str, q_start: ArrayLike | None
    ) -> GazeSolution:
        """A solve of a checked target ``p`` from checked readings ``qc``, started at ``q_start``."""
        ...


def _is_real(x: object) -> bool:
    """A real number (numpy's too), not a bool."""
    return isinstance(x, numbers.Real) and not isinstance(x, (bool, np.bool_))


def minimum_jerk(s: ArrayLike) -> tuple[Array, Array, Array]:
    """The minimum-jerk profile and its first two derivatives by ``s`` at ``s`` in [0, 1].

    ``f(s) = 10 s^3 - 15 s^4 + 6 s^5`` (Flash and Hogan 1985, with zero boundary
    velocities and accelerations): ``f(0) = 0``, ``f(1) = 1``, ``f' = f'' = 0`` at both ends.

    Returns:
        ``(f, df/ds, d2f/ds2)``, each of the shape of ``s``.
    """
    x = np.clip(np.asarray(s, dtype=float), 0.0, 1.0)
    f = x**3 * (10.0 + x * (-15.0 + 6.0 * x))
    df = 30.0 * x**2 * (1.0 - x) ** 2
    ddf = 60.0 * x * (1.0 - x) * (1.0 - 2.0 * x)
    return f, df, ddf


@dataclass(frozen=True)
class SaccadeRule:
    """When a saccade starts and how long it lasts (see the module docstring).

    Attributes:
        threshold: A saccade starts when the commanded posture's pointing error at the new
            target exceeds the solver's answer's by more than this [rad] (max over the cameras).
        max_acceleration: Per-joint acceleration limit [rad/s^2]/[m/s^2], shape (n,) or a scalar;
            None: none (URDFs carry no acceleration limits), the velocity limits alone set the
            duration.
        min_duration: The shortest saccade [s].
        reaim_interval: How often a saccade under way checks its end point [s], and how long
            pursuit runs after one is ended before a new saccade may start.
    """

    threshold: float = DEFAULT_SACCADE_THRESHOLD
    max_acceleration: float | tuple[float, ...] | None = None
    min_duration: float = DEFAULT_SACCADE_MIN_DURATION
    reaim_interval: float = DEFAULT_REAIM_INTERVAL

    def duration(self, delta: Array, max_velocity: Array, dt: float) -> int:
        """Samples of a saccade over ``delta`` (shape (n,)) [rad]/[m]: the fewest whole samples of
        ``dt`` [s] whose minimum-jerk profile stays within ``max_velocity`` (shape (n,); joints
        with 0 do not move) and the acceleration limits, and lasts at least ``min_duration``; at
        least one."""
        a = np.abs(delta)
        vmax = np.asarray(max_velocity, dtype=float)
        moving = vmax > 0.0
        T = max(
            self.min_duration,
            float(np.max(MIN_JERK_PEAK_VELOCITY * a[moving] / vmax[moving], initial=0.0)),
        )
        if self.max_acceleration is not None:
            amax = np.broadcast_to(np.asarray(self.max_acceleration, dtype=float), a.shape)
            T = max(T, math.sqrt(float(np.max(MIN_JERK_PEAK_ACCELERATION * a / amax))))
        # the continuous peaks bound the sampled ones: a sample's mean velocity is at most the peak
        return max(1, math.ceil(T / dt - 1e-9))

    def check(self, n: int) -> None:
        """:class:`ConfigurationError` unless the rule's numbers are usable for ``n`` joints."""
        if not (_is_real(self.threshold) and 0.0 <= self.threshold < math.pi):
            raise ConfigurationError(
                f"saccade threshold must be an angle in [0, pi) [rad] (a pointing error never exceeds pi: "
                f"no saccade would start; degrees? math.radians), got {self.threshold!r}"
            )
        if not (
            _is_real(self.min_duration)
            and math.isfinite(self.min_duration)
            and self.min_duration >= 0.0
        ):
            raise ConfigurationError(
                f"saccade min_duration must be finite and >= 0 [s], got {self.min_duration!r}"
            )
        if not (
            _is_real(self.reaim_interval)
            and math.isfinite(self.reaim_interval)
            and self.reaim_interval > 0.0
        ):
            raise ConfigurationError(
                f"saccade reaim_interval must be finite and > 0 [s], got {self.reaim_interval!r}"
            )
        if self.max_acceleration is not None:
            try:
                raw = np.asarray(self.max_acceleration)
                if raw.dtype.kind not in "iuf":  # not bools, strings or objects
                    raise TypeError(raw.dtype)
                amax = np.broadcast_to(raw.astype(float), (n,))
            except (TypeError, ValueError) as e:
                raise ConfigurationError(
                    f"saccade max_acceleration must be a scalar or {n} values, got {self.max_acceleration!r}"
                ) from e
            if not (np.all(np.isfinite(amax)) and np.all(amax > 0)):
                raise ConfigurationError(
                    f"saccade max_acceleration must be positive and finite, got {amax.tolist()}"
                )


@dataclass(frozen=True)
class TrackingStep:
    """One sample of :class:`GazeTracker`.

    Attributes:
        q: Commanded readings [rad]/[m], shape (n,).
        goal: The solver's answer for this sample's target, shape (n,).
        reachable: Whether the target could be fixated.
        pointing_error: Pointing error of the *commanded* ``q`` per camera [rad].
        locked: The commanded ``q`` equals the goal.
        saccade: This sample is part of a saccade.
    """

    q: Array
    goal: Array
    reachable: bool
    pointing_error: Array
    locked: bool
    saccade: bool


class Saccade:
    """A saccade under way: the minimum-jerk profile from ``q0`` to ``goal`` over ``n_samples``
    samples of ``dt``, sampled from its start."""

    def __init__(self, q0: Array, goal: Array, n_samples: int) -> None:
        self.q0 = q0.copy()
        self.goal = goal.copy()
        self.n_samples = n_samples
        self.done = 0  # samples commanded
        self.last_check = 0  # the sample of its start or of the last check of its end point

    def next_sample(self) -> Array:
        """The next commanded readings; the last sample is exactly ``goal``."""
        self.done += 1
        if self.done >= self.n_samples:
            return self.goal.copy()
        f, _, _ = minimum_jerk(self.done / self.n_samples)
        return self.q0 + (self.goal - self.q0) * float(f)

    @property
    def finished(self) -> bool:
        """Whether its last sample has been commanded."""
        return self.done >= self.n_samples


class GazeTracker:
    """A 1 kHz-style gaze control loop: one :meth:`step` per sample.

    Args:
        solver: The gaze solver (warm-started solves).
        dt: Sample period [s].
        max_velocity: Speed limits [rad/s] (revolute) / [m/s] (prismatic): ``{joint: limit}``
            for some joints (the others keep their URDF limits), per joint (shape (n,)), or one
            scalar for every joint (refused when the joints the head moves mix revolute and
            prismatic ones: one number in two units); None: the URDF velocity limits.
        q_current: Readings at the first sample, shape (n,); None: the first solution (the
            first command jumps there).
        policy: Redundancy policy (see :data:`~cpc2urdf.validation.gaze.options.POLICIES`).
        saccades: None: smooth pursuit only; a :class:`SaccadeRule`: minimum-jerk saccades too.

    Raises:
        ConfigurationError: A bad ``dt``, speed limit (a joint the head moves with no positive
            finite limit is named), ``q_current``, policy or saccade rule.
    """

    def __init__(
        self,
        solver: WarmStartSolver,
        dt: float,
        max_velocity: ArrayLike | Mapping[str, float] | None = None,
        *,
        q_current: ArrayLike | None = None,
        policy: str = "cyclopean",
        saccades: SaccadeRule | None = None,
    ) -> None:
        check_policy(policy)
        if not (_is_real(dt) and math.isfinite(dt) and dt > 0):
            raise ConfigurationError(f"dt must be a positive number of seconds, got {dt!r}")
        if saccades is not None and not isinstance(saccades, SaccadeRule):
            raise ConfigurationError(f"saccades must be None or a SaccadeRule, got {saccades!r}")
        n = len(solver.joint_names)
        # the joints this policy moves that move a camera (a policy may free off-path joints too: they keep still)
        moved = np.intersect1d(solver.free_joints(policy), solver.path_joints)
        vmax = speed_limits(solver, max_velocity, moved)
        if saccades is not None:
            saccades.check(n)
        self.solver = solver
        self.joint_names = solver.joint_names
        self.dt = float(dt)
        self.policy = policy
        self.saccades = saccades
        self.max_velocity: Array = vmax
        self._step_limit: Array = self.max_velocity * self.dt
        self._groups = solver.motion_groups
        self.q: Array | None = solver.check_q(
            q_current
        )  # commanded readings; None before the first sample
        self.goal: Array | None = None
        self._saccade: Saccade | None = None  # the saccade under way
        self._pursuit_only = 0  # samples before a saccade may start again (after one was ended)
        self._last_step: Array | None = None  # the last commanded change of the readings
        self._reaim_samples = (
            0 if saccades is None else max(1, round(saccades.reaim_interval / self.dt))
        )

    @property
    def in_saccade(self) -> bool:
        """Whether a saccade is under way (the next sample continues it, unless its check ends it)."""
        return self._saccade is not None

    def step(self, p_world: ArrayLike) -> TrackingStep:
        """Advance one sample towards target ``p_world`` (world) [m], shape (3,)."""
        return self.step_checked(target_point(p_world))

    def step_checked(self, p: Array) -> TrackingStep:
        """:meth:`step` for a checked finite target ``p`` of shape (3,)."""
        q_prev = self.q
        q_start = self.goal
        if q_start is not None and self._miss(q_start, p) > WARM_START_ANGLE:
            q_start = None  # the target jumped: the solver's own start beats the last answer
        # q_prev stays between in-limit readings, so it need not be checked again
        sol = self.solver.solve_checked(
            p, None if q_prev is None else q_prev.copy(), self.policy, q_start
        )
        goal = sol.q
        self.goal = goal
        aims = sol.status in SACCADE_STATUSES  # an answer that points at the target
        sac = self._saccade
        if (
            q_prev is not None
            and sac is not None
            and sac.done - sac.last_check >= self._reaim_samples
        ):
            sac.last_check = sac.done
            if not aims or self._saccade_stale(p, sol):
                # the target moved on (or can no longer be pointed at): pursuit from here, a new
                # saccade only after another interval
                self._saccade = None
                self._pursuit_only = self._reaim_samples
        in_saccade = False
        if q_prev is None:
            q_cmd = goal.copy()
        elif self._saccade is not None:
            q_cmd = self._saccade_sample()
            in_saccade = True
        elif (
            self.saccades is not None
            and aims
            and self._pursuit_only == 0
            and self._at_rest()
            and self._saccade_wanted(q_prev, p, sol)
        ):
            self._saccade = Saccade(
                q_prev, goal, self.saccades.duration(goal - q_prev, self.max_velocity, self.dt)
            )
            q_cmd = self._saccade_sample()
            in_saccade = True
        else:
            q_cmd = self._pursuit(q_prev, goal)
        self._pursuit_only = max(0, self._pursuit_only - 1)
        locked = bool(np.all(np.abs(goal - q_cmd) <= LOCK_TOL))
        if locked:
            q_cmd = goal.copy()
        self._last_step = q_cmd - q_prev if q_prev is not None else None
        self.q = q_cmd
        return TrackingStep(
            q_cmd, goal, sol.reachable, self.solver.pointing_errors(q_cmd, p), locked, in_saccade
        )

    def _pursuit(self, q_prev: Array, goal: Array) -> Array:
        """Smooth pursuit: at most ``max_velocity * dt`` per joint; joints that move only
        together (:attr:`WarmStartSolver.motion_groups`) by one fraction of their steps."""
        step = goal - q_prev
        q_cmd = q_prev + np.clip(step, -self._step_limit, self._step_limit)
        for g in self._groups:
            big = np.abs(step[g])
            with np.errstate(divide="ignore"):
                k = float(np.min(np.where(big > 0.0, self._step_limit[g] / big, np.inf)))
            if k < 1.0:
                q_cmd[g] = q_prev[g] + k * step[g]
        return q_cmd

    def _miss(self, q: Array, p: Array) -> float:
        """The largest pointing error [rad] of readings ``q`` at target ``p``."""
        return float(np.max(self.solver.pointing_errors(q, p)))

    def _at_rest(self) -> bool:
        """Whether the last commanded step is at most :data:`REST_FRACTION` of every joint's
        speed limit (a head pursuing at speed is not: a saccade from rest would stop it)."""
        step = self._last_step
        return step is None or bool(
            np.all(np.abs(step) <= REST_FRACTION * self._step_limit + 1e-15)
        )

    def _saccade_wanted(self, q_prev: Array, p: Array, sol: GazeSolution) -> bool:
        assert self.saccades is not None
        gain = self._miss(q_prev, p) - float(np.max(sol.pointing_error))
        return gain > self.saccades.threshold

    def _saccade_stale(self, p: Array, sol: GazeSolution) -> bool:
        """Whether the saccade under way ends off this sample's target: its end point misses
        ``p`` by more than the threshold beyond the sample's answer ``sol``."""
        assert self._saccade is not None and self.saccades is not None
        gain = self._miss(self._saccade.goal, p) - float(np.max(sol.pointing_error))
        return gain > max(self.saccades.threshold, STALE_FLOOR)

    def _saccade_sample(self) -> Array:
        """The next sample of the saccade under way; its last one is exactly its end."""
        assert self._saccade is not None
        q = self._saccade.next_sample()
        if self._saccade.finished:
            self._saccade = None
        return q


def speed_limits(
    solver: WarmStartSolver,
    max_velocity: ArrayLike | Mapping[str, float] | None,
    moved: NDArray[np.intp],
) -> Array:
    """Per-joint speed limits [rad/s]/[m/s], shape (n,), from ``max_velocity`` (see
    :class:`GazeTracker`) and the URDF's, checked on the joints the head moves (``moved``):
    each a positive finite limit. Joints it does not move get 0 (they never move).

    Raises:
        ConfigurationError: A malformed ``max_velocity``, an unknown joint name, a scalar over
            revolute and prismatic joints together, or a moved joint without a usable limit
            (named, with where its limit came from).
    """
    names = solver.joint_names
    n = len(names)
    vmax = np.array(solver.velocity_limit, dtype=float)
    given = np.zeros(n, dtype=bool)
    if isinstance(max_velocity, Mapping):
        for name, value in max_velocity.items():
            if name not in names:
                raise ConfigurationError(f"max_velocity names an unknown joint {name!r}")
            if not _is_real(value):
                raise ConfigurationError(
                    f"max_velocity[{name!r}] must be a number [rad/s]/[m/s], got {value!r}"
                )
            i = names.index(name)
            vmax[i] = float(value)
            given[i] = True
    elif max_velocity is not None:
        try:
            raw = np.asarray(max_velocity)
            if raw.dtype.kind not in "iuf":  # not bools, strings or objects
                raise TypeError(raw.dtype)
            v = raw.astype(float)
            vmax = np.array(np.broadcast_to(v, (n,)))
        except (TypeError, ValueError) as e:
            raise ConfigurationError(
                f"max_velocity must be a scalar, {n} values or {{joint: limit}}, got {max_velocity!r}"
            ) from e
        given[:] = True
        if v.ndim == 0:
            kinds = {solver.joint_kinds[names[i]] for i in moved.tolist()}
            if len(kinds) > 1:
                prismatic = [
                    names[i] for i in moved.tolist() if solver.joint_kinds[names[i]] == "prismatic"
                ]
                raise ConfigurationError(
                    f"a scalar max_velocity would be rad/s on revolute joints and m/s on prismatic ones "
                    f"({', '.join(prismatic)}): give {{joint: limit}} or {n} values"
                )
    bad = [i for i in moved.tolist() if not (math.isfinite(vmax[i]) and vmax[i] > 0.0)]
    if bad:
        i = bad[0]
        where = "max_velocity" if given[i] else "its URDF <limit velocity>"
        raise ConfigurationError(
            f"joint {names[i]!r} moves the cameras but its speed limit is {float(vmax[i])} (from {where}): "
            f"give it a positive limit in max_velocity={{{names[i]!r}: ...}}"
        )
    out = np.zeros(n)
    out[moved] = vmax[moved]
    return out


@dataclass(frozen=True)
class Trajectory:
    """The result of :meth:`~cpc2urdf.validation.gaze.GazeSolver.track` and :func:`track`.

    Attributes:
        t: Sample times [s], shape (T,).
        q: Commanded joint readings [rad]/[m], shape (T, n): velocity-limited steps (and, with
            saccades, minimum-jerk jumps) towards ``q_goal``.
        q_goal: The solved (warm-started) fixating readings per sample, shape (T, n).
        reachable: Whether each target could be fixated, shape (T,).
        pointing_error: Per-sample pointing error of the *commanded* ``q``, shape (T, cameras) [rad].
        locked: Per-sample flag: the commanded ``q`` equals the goal (not velocity-limited), shape (T,).
        joint_names: Names of the joints, in the order of the columns of ``q``.
        saccade: Per-sample flag: the sample is part of a saccade, shape (T,).
    """

    t: Array
    q: Array
    q_goal: Array
    reachable: NDArray[np.bool_]
    pointing_error: Array
    locked: NDArray[np.bool_]
    joint_names: tuple[str, ...]
    saccade: NDArray[np.bool_]


def track(
    solver: WarmStartSolver,
    targets: ArrayLike,
    dt: float,
    max_velocity: ArrayLike | Mapping[str, float] | None = None,
    *,
    q_current: ArrayLike | None = None,
    policy: str = "cyclopean",
    saccades: SaccadeRule | None = None,
) -> Trajectory:
    """Follow a moving target: a :class:`GazeTracker` run over every sample.

    Each sample solves for the target from the previous goal (about three iterations when the
    target moves little), then moves the commanded readings towards the goal by at most
    ``max_velocity * dt`` per joint, or along a minimum-jerk saccade (``saccades``).

    Args:
        solver: The gaze solver.
        targets: Target positions (world) [m], shape (T, 3), one per sample.
        dt: Sample period [s].
        max_velocity: Speed limits (see :class:`GazeTracker`): ``{joint: limit}``, per joint
            (shape (n,)), or a scalar over joints of one kind; None: the URDF velocity limits.
        q_current: Readings at the first sample, shape (n,); None: the first solution.
        policy: Redundancy policy (see :data:`~cpc2urdf.validation.gaze.options.POLICIES`).
        saccades: None: smooth pursuit only; a :class:`SaccadeRule`: minimum-jerk saccades too.

    Returns:
        A :class:`Trajectory`.
    """
    P = np.array(targets, dtype=float, order="C")  # rows: plain (3,) arrays, as target_point gives
    if P.ndim != 2 or P.shape[1] != 3 or P.shape[0] == 0:
        raise ConfigurationError(f"targets must have shape (T, 3) [m], got shape {P.shape}")
    if not np.all(np.isfinite(P)):
        raise ConfigurationError("targets contain NaN or inf")
    tracker = GazeTracker(
        solver, dt, max_velocity, q_current=q_current, policy=policy, saccades=saccades
    )
    steps = [tracker.step_checked(p) for p in P]
    T = P.shape[0]
    return Trajectory(
        t=np.arange(T, dtype=float) * float(dt),
        q=np.array([s.q for s in steps]),
        q_goal=np.array([s.goal for s in steps]),
        reachable=np.array([s.reachable for s in steps], dtype=bool),
        pointing_error=np.array([s.pointing_error for s in steps]),
        locked=np.array([s.locked for s in steps], dtype=bool),
        joint_names=tuple(tracker.joint_names),
        saccade=np.array([s.saccade for s in steps], dtype=bool),
    )


__all__ = [
    "DEFAULT_SACCADE_MIN_DURATION",
    "DEFAULT_SACCADE_THRESHOLD",
    "LOCK_TOL",
    "WARM_START_ANGLE",
    "MIN_JERK_PEAK_ACCELERATION",
    "MIN_JERK_PEAK_VELOCITY",
    "DEFAULT_REAIM_INTERVAL",
    "REST_FRACTION",
    "STALE_FLOOR",
    "SACCADE_STATUSES",
    "GazeTracker",
    "SaccadeRule",
    "TrackingStep",
    "Trajectory",
    "WarmStartSolver",
    "minimum_jerk",
    "speed_limits",
    "track",
    "Saccade",
]
