"""Following a moving target: warm-started gaze solves and a velocity-limited trajectory."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cpc2urdf.errors import ConfigurationError
from cpc2urdf.transforms import Array
from cpc2urdf.validation.gaze.fixation import evaluate_fixation, pointing_errors
from cpc2urdf.validation.gaze.gauss_newton import MAX_ITERATIONS
from cpc2urdf.validation.gaze.head import GazeHead
from cpc2urdf.validation.gaze.policies import check_policy
from cpc2urdf.validation.gaze.result import GazeSolution


class WarmStartSolver(Protocol):
    """What tracking needs of a solver (:class:`~cpc2urdf.validation.gaze.GazeSolver`)."""

    head: GazeHead

    def solve_checked(
        self, p: Array, qc: Array | None, policy: str, q_start: ArrayLike | None, max_iterations: int
    ) -> GazeSolution:
        """A solve of a checked target ``p`` from checked readings ``qc``, started at ``q_start``."""
        ...


@dataclass(frozen=True)
class Trajectory:
    """The result of :meth:`~cpc2urdf.validation.gaze.GazeSolver.track`.

    Attributes:
        t: Sample times [s], shape (T,).
        q: Commanded joint readings [rad]/[m], shape (T, n): velocity-limited steps towards
            ``q_goal``.
        q_goal: The solved (warm-started) fixating readings per sample, shape (T, n).
        reachable: Whether each target could be fixated, shape (T,).
        pointing_error: Per-sample pointing error of the *commanded* ``q``, shape (T, 2) [rad].
        locked: Per-sample flag: the commanded ``q`` equals the goal (not velocity-limited), shape (T,).
        joint_names: Names of the joints, in the order of the columns of ``q``.
    """

    t: Array
    q: Array
    q_goal: Array
    reachable: NDArray[np.bool_]
    pointing_error: Array
    locked: NDArray[np.bool_]
    joint_names: tuple[str, ...]


def track(
    solver: WarmStartSolver,
    targets: ArrayLike,
    dt: float,
    max_velocity: ArrayLike | None = None,
    *,
    q_current: ArrayLike | None = None,
    policy: str = "cyclopean",
) -> Trajectory:
    """Follow a moving target: warm-started solves and a velocity-limited joint trajectory.

    Each sample solves for the target from the previous goal (one or two iterations when the
    target moves little), then moves the commanded readings towards the goal by at most
    ``max_velocity * dt`` per joint.

    Args:
        solver: The gaze solver.
        targets: Target positions (world) [m], shape (T, 3), one per sample.
        dt: Sample period [s].
        max_velocity: Per-joint speed limit [rad/s]/[m/s], shape (n,) or a scalar; None: the
            URDF velocity limits.
        q_current: Readings at the first sample, shape (n,); None: the first solution.
        policy: Redundancy policy (see :data:`~cpc2urdf.validation.gaze.policies.POLICIES`).

    Returns:
        A :class:`Trajectory`.
    """
    check_policy(policy)
    P = np.asarray(targets, dtype=float)
    if P.ndim != 2 or P.shape[1] != 3 or P.shape[0] == 0:
        raise ConfigurationError(f"targets must have shape (T, 3) [m], got shape {P.shape}")
    if not np.all(np.isfinite(P)):
        raise ConfigurationError("targets contain NaN or inf")
    if not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt > 0):
        raise ConfigurationError(f"dt must be a positive number of seconds, got {dt!r}")
    head = solver.head
    n = head.n
    vmax = head.velocity_limit if max_velocity is None else np.broadcast_to(
        np.asarray(max_velocity, dtype=float), (n,)
    )
    if not (np.all(np.isfinite(vmax)) and np.all(vmax > 0)):
        raise ConfigurationError(f"max_velocity must be positive and finite, got {np.asarray(vmax).tolist()}")
    qc = head.check_q(q_current)
    T = P.shape[0]
    Q = np.empty((T, n))
    G = np.empty((T, n))
    ok = np.zeros(T, dtype=bool)
    err = np.empty((T, 2))
    locked = np.zeros(T, dtype=bool)
    step = vmax * dt
    q_cmd = qc
    goal: Array | None = None
    for k in range(T):
        # targets and readings are checked above; q_cmd stays between in-limit readings
        sol = solver.solve_checked(P[k], None if q_cmd is None else q_cmd.copy(), policy, goal, MAX_ITERATIONS)
        goal = sol.q
        if q_cmd is None:
            q_cmd = goal.copy()
        delta = np.clip(goal - q_cmd, -step, step)
        q_cmd = q_cmd + delta
        locked[k] = bool(np.all(np.abs(goal - q_cmd) <= 1e-15))
        if locked[k]:
            q_cmd = goal.copy()
        G[k] = goal
        Q[k] = q_cmd
        ok[k] = sol.reachable
        st = evaluate_fixation(head, q_cmd, P[k], jacobian=False)
        err[k] = pointing_errors(st)
    return Trajectory(np.arange(T, dtype=float) * float(dt), Q, G, ok, err, locked, head.joint_names)


__all__ = ["Trajectory", "WarmStartSolver", "track"]
