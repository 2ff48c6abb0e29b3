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
  at; smooth pursuit takes over from there. The saccade is ballistic: it aims at the answer for
  the target at its onset, and the solves during it only record where the target went.

:class:`GazeTracker` is one control loop (``step`` per sample); :func:`track` runs it over a
whole target trajectory.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cpc2urdf.errors import ConfigurationError
from cpc2urdf.transforms import Array
from cpc2urdf.validation.gaze.fixation import target_point
from cpc2urdf.validation.gaze.gauss_newton import MAX_ITERATIONS
from cpc2urdf.validation.gaze.policies import check_policy
from cpc2urdf.validation.gaze.result import GazeSolution

MIN_JERK_PEAK_VELOCITY = 15.0 / 8.0  # peak of d/ds (10 s^3 - 15 s^4 + 6 s^5), at s = 1/2
MIN_JERK_PEAK_ACCELERATION = 10.0 / math.sqrt(3.0)  # peak of its |d2/ds2|, at s = (3 -+ sqrt 3) / 6
DEFAULT_SACCADE_THRESHOLD = math.radians(5.0)  # [rad]: pointing error that starts a saccade
DEFAULT_SACCADE_MIN_DURATION = 0.02  # [s]: the shortest saccade
WARM_START_ANGLE = math.radians(5.0)  # [rad]: a last answer missing the new target by more is not a start
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

    def check_q(self, q: ArrayLike | None) -> Array | None:
        """Readings as an in-limit array of shape (n,), or None."""
        ...

    def pointing_errors(self, q: Array, p: Array) -> Array:
        """Pointing error [rad] of each solved axis at readings ``q`` for target ``p``."""
        ...

    def solve_checked(
        self, p: Array, qc: Array | None, policy: str, q_start: ArrayLike | None, max_iterations: int
    ) -> GazeSolution:
        """A solve of a checked target ``p`` from checked readings ``qc``, started at ``q_start``."""
        ...


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
    """

    threshold: float = DEFAULT_SACCADE_THRESHOLD
    max_acceleration: float | tuple[float, ...] | None = None
    min_duration: float = DEFAULT_SACCADE_MIN_DURATION

    def duration(self, delta: Array, max_velocity: Array, dt: float) -> int:
        """Samples of a saccade over ``delta`` (shape (n,)) [rad]/[m]: the fewest whole samples of
        ``dt`` [s] whose minimum-jerk profile stays within ``max_velocity`` (shape (n,)) and the
        acceleration limits, and lasts at least ``min_duration``; at least one."""
        a = np.abs(delta)
        T = max(self.min_duration, float(np.max(MIN_JERK_PEAK_VELOCITY * a / max_velocity)))
        if self.max_acceleration is not None:
            amax = np.broadcast_to(np.asarray(self.max_acceleration, dtype=float), a.shape)
            T = max(T, math.sqrt(float(np.max(MIN_JERK_PEAK_ACCELERATION * a / amax))))
        # the continuous peaks bound the sampled ones: a sample's mean velocity is at most the peak
        return max(1, math.ceil(T / dt - 1e-9))

    def check(self, n: int) -> None:
        """:class:`ConfigurationError` unless the rule's numbers are usable for ``n`` joints."""
        if not (math.isfinite(self.threshold) and self.threshold >= 0.0):
            raise ConfigurationError(f"saccade threshold must be a finite angle >= 0 [rad], got {self.threshold!r}")
        if not (math.isfinite(self.min_duration) and self.min_duration >= 0.0):
            raise ConfigurationError(f"saccade min_duration must be finite and >= 0 [s], got {self.min_duration!r}")
        if self.max_acceleration is not None:
            try:
                amax = np.broadcast_to(np.asarray(self.max_acceleration, dtype=float), (n,))
            except ValueError as e:
                raise ConfigurationError(
                    f"saccade max_acceleration must be a scalar or {n} values, got {self.max_acceleration!r}"
                ) from e
            if not (np.all(np.isfinite(amax)) and np.all(amax > 0)):
                raise ConfigurationError(f"saccade max_acceleration must be positive and finite, got {amax.tolist()}")


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


class GazeTracker:
    """A 1 kHz-style gaze control loop: one :meth:`step` per sample.

    Args:
        solver: The gaze solver (warm-started solves).
        dt: Sample period [s].
        max_velocity: Per-joint speed limit [rad/s]/[m/s], shape (n,) or a scalar; None: the URDF
            velocity limits.
        q_current: Readings at the first sample, shape (n,); None: the first solution.
        policy: Redundancy policy (see :data:`~cpc2urdf.validation.gaze.policies.POLICIES`).
        saccades: None: smooth pursuit only; a :class:`SaccadeRule`: minimum-jerk saccades too.

    Raises:
        ConfigurationError: A bad ``dt``, speed limit, ``q_current``, policy or saccade rule.
    """

    def __init__(
        self,
        solver: WarmStartSolver,
        dt: float,
        max_velocity: ArrayLike | None = None,
        *,
        q_current: ArrayLike | None = None,
        policy: str = "cyclopean",
        saccades: SaccadeRule | None = None,
    ) -> None:
        check_policy(policy)
        if not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt > 0):
            raise ConfigurationError(f"dt must be a positive number of seconds, got {dt!r}")
        n = len(solver.joint_names)
        try:
            vmax = solver.velocity_limit if max_velocity is None else np.broadcast_to(
                np.asarray(max_velocity, dtype=float), (n,)
            )
        except ValueError as e:
            raise ConfigurationError(f"max_velocity must be a scalar or {n} values, got {max_velocity!r}") from e
        if not (np.all(np.isfinite(vmax)) and np.all(vmax > 0)):
            raise ConfigurationError(f"max_velocity must be positive and finite, got {np.asarray(vmax).tolist()}")
        if saccades is not None:
            saccades.check(n)
        self.solver = solver
        self.joint_names = solver.joint_names
        self.dt = float(dt)
        self.policy = policy
        self.saccades = saccades
        self.max_velocity: Array = np.array(vmax, dtype=float)
        self._step_limit: Array = self.max_velocity * self.dt
        self.q: Array | None = solver.check_q(q_current)  # commanded readings; None before the first sample
        self.goal: Array | None = None
        # the saccade under way: start, end, number of samples, samples done
        self._saccade: tuple[Array, Array, int] | None = None
        self._saccade_done = 0

    @property
    def in_saccade(self) -> bool:
        """Whether a saccade is under way (the next sample continues it)."""
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
            p, None if q_prev is None else q_prev.copy(), self.policy, q_start, MAX_ITERATIONS
        )
        goal = sol.q
        self.goal = goal
        in_saccade = False
        if q_prev is None:
            q_cmd = goal.copy()
        elif self._saccade is not None:
            q_cmd = self._saccade_sample()
            in_saccade = True
        elif self.saccades is not None and self._saccade_wanted(q_prev, p, sol):
            n_samples = self.saccades.duration(goal - q_prev, self.max_velocity, self.dt)
            self._saccade = (q_prev.copy(), goal.copy(), n_samples)
            self._saccade_done = 0
            q_cmd = self._saccade_sample()
            in_saccade = True
        else:  # smooth pursuit: velocity-limited
            q_cmd = q_prev + np.clip(goal - q_prev, -self._step_limit, self._step_limit)
        locked = bool(np.all(np.abs(goal - q_cmd) <= LOCK_TOL))
        if locked:
            q_cmd = goal.copy()
        self.q = q_cmd
        return TrackingStep(q_cmd, goal, sol.reachable, self.solver.pointing_errors(q_cmd, p), locked, in_saccade)

    def _miss(self, q: Array, p: Array) -> float:
        """The largest pointing error [rad] of readings ``q`` at target ``p``."""
        return float(np.max(self.solver.pointing_errors(q, p)))

    def _saccade_wanted(self, q_prev: Array, p: Array, sol: GazeSolution) -> bool:
        assert self.saccades is not None
        gain = self._miss(q_prev, p) - float(np.max(sol.pointing_error))
        return gain > self.saccades.threshold

    def _saccade_sample(self) -> Array:
        """The next sample of the saccade under way; its last one is exactly its end."""
        assert self._saccade is not None
        q0, q1, n_samples = self._saccade
        self._saccade_done += 1
        k = self._saccade_done
        if k >= n_samples:
            self._saccade = None
            return q1.copy()
        f, _, _ = minimum_jerk(k / n_samples)
        return q0 + (q1 - q0) * float(f)


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
    max_velocity: ArrayLike | None = None,
    *,
    q_current: ArrayLike | None = None,
    policy: str = "cyclopean",
    saccades: SaccadeRule | None = None,
) -> Trajectory:
    """Follow a moving target: a :class:`GazeTracker` run over every sample.

    Each sample solves for the target from the previous goal (one or two iterations when the
    target moves little), then moves the commanded readings towards the goal by at most
    ``max_velocity * dt`` per joint, or along a minimum-jerk saccade (``saccades``).

    Args:
        solver: The gaze solver.
        targets: Target positions (world) [m], shape (T, 3), one per sample.
        dt: Sample period [s].
        max_velocity: Per-joint speed limit [rad/s]/[m/s], shape (n,) or a scalar; None: the
            URDF velocity limits.
        q_current: Readings at the first sample, shape (n,); None: the first solution.
        policy: Redundancy policy (see :data:`~cpc2urdf.validation.gaze.policies.POLICIES`).
        saccades: None: smooth pursuit only; a :class:`SaccadeRule`: minimum-jerk saccades too.

    Returns:
        A :class:`Trajectory`.
    """
    P = np.array(targets, dtype=float, order="C")  # rows: plain (3,) arrays, as target_point gives
    if P.ndim != 2 or P.shape[1] != 3 or P.shape[0] == 0:
        raise ConfigurationError(f"targets must have shape (T, 3) [m], got shape {P.shape}")
    if not np.all(np.isfinite(P)):
        raise ConfigurationError("targets contain NaN or inf")
    tracker = GazeTracker(solver, dt, max_velocity, q_current=q_current, policy=policy, saccades=saccades)
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
    "GazeTracker",
    "SaccadeRule",
    "TrackingStep",
    "Trajectory",
    "WarmStartSolver",
    "minimum_jerk",
    "track",
]
