"""The answer of a gaze solve: :class:`GazeSolution` and why a target is not fixated.

``reachable`` is True when both eyes point at the target to within
:data:`cpc2urdf.tolerances.GAZE_POINTING_TOL` (which implies in front of the cameras), inside
the limits. Otherwise the readings are the best in-limit configuration found (least sum of the
squared residuals of the two eyes), with the residuals, and ``status`` says why.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from typing import Any

from cpc2urdf.transforms import Array

STATUS_FIXATED = "fixated"
STATUS_LIMITS = (
    "joint_limits"  # the best in-limit configuration does not fixate; a joint is at a limit
)
STATUS_BEHIND = "behind"  # an eye would have to look away from the target
STATUS_TOO_CLOSE = "too_close"  # the target is closer to the cameras than their baseline
STATUS_NO_SOLUTION = "no_solution"  # no limit active, yet the two eyes cannot both fixate
STATUS_DISPARITY = (
    "disparity"  # the head's eyes cannot fixate exactly: the policy's posture, residual split
)
STATUSES = (
    STATUS_FIXATED,
    STATUS_LIMITS,
    STATUS_BEHIND,
    STATUS_TOO_CLOSE,
    STATUS_NO_SOLUTION,
    STATUS_DISPARITY,
)


@dataclass(frozen=True)
class GazeSolution:
    """The answer of :meth:`~cpc2urdf.validation.gaze.GazeSolver.solve`. Nothing is moved.

    Attributes:
        q: Joint readings [rad]/[m], shape (n,), in ``joint_names`` order; always inside the limits.
        joint_names: Names of the joints, in the order of ``q``.
        reachable: True if both eyes point at the target to within
            :data:`cpc2urdf.tolerances.GAZE_POINTING_TOL` (which implies in front of the cameras).
        status: One of :data:`STATUSES`: ``"fixated"`` or why not.
        pointing_error: Angle between each optical axis and the direction to the target [rad],
            shape (2,) (left, right) on two eyes; shape (1,) on a one-camera head or a rigid pair
            (its cyclopean axis, or the master eye).
        miss_distance: Distance from the target to each optical ray (half-line in front of the
            camera) [m], same shape.
        fixation_point: Midpoint of the closest points of the two optical axes (world) [m],
            shape (3,), or None when the axes are parallel.
        vergence: Angle between the two optical axes [rad].
        at_limit: Names of the joints at one of their limits.
        iterations: Gauss-Newton iterations used.
        policy: The redundancy policy used.
        target: The target (world) [m], shape (3,).
    """

    q: Array
    joint_names: tuple[str, ...]
    reachable: bool
    status: str
    pointing_error: Array
    miss_distance: Array
    fixation_point: Array | None
    vergence: float
    at_limit: tuple[str, ...]
    iterations: int
    policy: str
    target: Array

    @property
    def joints(self) -> dict[str, float]:
        """``{joint name: reading}`` [rad]/[m]."""
        return {n: float(v) for n, v in zip(self.joint_names, self.q, strict=True)}

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dict (SI units); a value beyond the float range (the miss distance of a
        target beyond ~1e308 m) is written as null, never as ``Infinity``."""
        names = (
            ("left", "right")
            if len(self.pointing_error) == 2
            else tuple(f"axis{k}" for k in range(len(self.pointing_error)))
        )
        return {
            "target": self.target.tolist(),
            "policy": self.policy,
            "reachable": self.reachable,
            "status": self.status,
            "joints": self.joints,
            "pointing_error_rad": {
                k: _finite(v) for k, v in zip(names, self.pointing_error.tolist(), strict=True)
            },
            "miss_distance_m": {
                k: _finite(v) for k, v in zip(names, self.miss_distance.tolist(), strict=True)
            },
            "fixation_point": None
            if self.fixation_point is None
            else [_finite(v) for v in self.fixation_point.tolist()],
            "vergence_rad": _finite(self.vergence),
            "at_limit": list(self.at_limit),
            "iterations": self.iterations,
        }


def _finite(v: float) -> float | None:
    """``v``, or None when it is not finite (JSON has no inf)."""
    return float(v) if math.isfinite(v) else None


class _FlatSolution(GazeSolution):
    """A :class:`GazeSolution` read from a compiled solve's output row (one array): each field
    is computed on first use and then kept (:func:`functools.cached_property` on a frozen
    dataclass: the value goes straight into the instance's ``__dict__``). A control loop reads
    two or three fields of an answer; building all twelve took ~3 us of a ~25 us solve."""

    def __repr__(self) -> str:  # the public class's name, not this one's
        return "GazeSolution" + GazeSolution.__repr__(self)[len(type(self).__qualname__) :]

    _a: Array  # the output row (status, iterations, readings, errors, misses, fixation point, vergence, limit flags, target)
    _S: int  # solved axes

    @cached_property
    def q(self) -> Array:  # type: ignore[override]
        return self._a[2 : 2 + len(self.joint_names)]

    @cached_property
    def status(self) -> str:  # type: ignore[override]
        return STATUSES[int(self._a[0])]  # the kernels' status codes index STATUSES

    @cached_property
    def reachable(self) -> bool:  # type: ignore[override]
        return int(self._a[0]) == 0

    @cached_property
    def iterations(self) -> int:  # type: ignore[override]
        return int(self._a[1])

    @cached_property
    def pointing_error(self) -> Array:  # type: ignore[override]
        o = 2 + len(self.joint_names)
        return self._a[o : o + self._S]

    @cached_property
    def miss_distance(self) -> Array:  # type: ignore[override]
        o = 2 + len(self.joint_names) + self._S
        return self._a[o : o + self._S]

    @cached_property
    def fixation_point(self) -> Array | None:  # type: ignore[override]
        f = 2 + len(self.joint_names) + 2 * self._S
        return None if math.isnan(self._a[f]) else self._a[f : f + 3]

    @cached_property
    def vergence(self) -> float:  # type: ignore[override]
        return float(self._a[4 + len(self.joint_names) + 2 * self._S + 1])

    @cached_property
    def target(self) -> Array:  # type: ignore[override]
        return self._a[-3:]

    @cached_property
    def at_limit(self) -> tuple[str, ...]:  # type: ignore[override]
        flags = self._a[6 + len(self.joint_names) + 2 * self._S : -3].tolist()
        return tuple(name for name, hit in zip(self.joint_names, flags, strict=True) if hit)


def solution_from_flat(
    robot_names: tuple[str, ...], out: Array, S: int, policy: str
) -> GazeSolution:
    """The :class:`GazeSolution` of a compiled solve from its output ``out`` (kept, not copied:
    pass an array no one else holds) of :func:`~cpc2urdf.validation.gaze.kernels.solve_flat`
    (``S`` solved axes; ``fixated`` iff every pointing error is within the tolerance): its
    fields read from it when first used (the frozen dataclass filled without its generated
    ``__init__``)."""
    sol = object.__new__(_FlatSolution)
    sol.__dict__.update(_a=out, _S=S, joint_names=robot_names, policy=policy)
    return sol


__all__ = [
    "STATUSES",
    "STATUS_DISPARITY",
    "STATUS_BEHIND",
    "STATUS_FIXATED",
    "STATUS_LIMITS",
    "STATUS_NO_SOLUTION",
    "STATUS_TOO_CLOSE",
    "GazeSolution",
    "solution_from_flat",
]
