"""Experiment design: which configurations a stage-1 experiment measures (Shih et al. sec. 4.1).

One rule for the **calibration range** of a joint (the part of its travel that measurements use),
applied by every simulator, study and test helper:

1. a range given by the caller (``overrides``, e.g. ``cpc2urdf simulate --range``), else
2. the robot spec's ``calibration_range`` (the shipped IIS-head has one for every joint), else
3. the middle ``DEFAULT_RANGE_SHARE`` (one half) of the joint limits, centred on their middle: a
   spec that does not say where the plates stay in view gets the central part of each joint's
   travel, where a head's plates face forward; the extremes of the limits would often turn them
   edge-on or out of the cameras' view.

The **one-joint-at-a-time protocol** (sec. 4.1, Fig. 8): one record at ``q0``, the middle of every
joint's calibration range, then, for each joint in turn, ``M`` values evenly spread over its
calibration range (ends included) with the other joints at ``q0``: ``n M + 1`` records (6M+1 for
the IIS-head; the paper chooses M = 9). Held-out and random-design experiments draw
configurations uniformly in the box of calibration ranges (:func:`random_configurations`).
Where only a thin part of the box is usable (a board every camera must see), :func:`walk_configurations`
explores it from a usable start and :func:`farthest_points` spreads a selection over it.

Example::

    s = load_robot("iis_head").structure
    ranges = calibration_ranges(s)                          # (6, 2) [m]/[rad]
    q, labels = protocol_configurations(ranges, 9, s.joint_names)   # (55, 6), "q0", "pan 3/9", ...
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cpc2urdf.errors import ConfigurationError
from cpc2urdf.model import DEFAULT_RANGE_SHARE, CPCModel, RobotStructure

Array = NDArray[np.float64]

DEFAULT_M = 9  # sec. 6: "we choose to use nine measurements for each joint"
PROTOCOL_JITTER = (
    0.2  # [-]: largest random shift of a protocol value, as a share of the value spacing
)


def calibration_ranges(
    structure: RobotStructure, overrides: Mapping[str, tuple[float, float]] | None = None
) -> Array:
    """Per joint ``[lo, hi]`` [m]/[rad], shape (n, 2): the robot's one calibration-range rule,
    :meth:`cpc2urdf.model.RobotStructure.calibration_ranges` (overrides, else the spec's
    ``calibration_range``, else the middle half of the limits)."""
    return structure.calibration_ranges(overrides)


def protocol_configurations(
    ranges: ArrayLike,
    M: int,
    joint_names: Sequence[str],
    *,
    rng: np.random.Generator | None = None,
    limits: ArrayLike | None = None,
) -> tuple[Array, list[str]]:
    """The one-joint-at-a-time protocol of sec. 4.1.

    Args:
        ranges: Per joint ``[lo, hi]`` [m]/[rad], shape (n, 2).
        M: Values per joint (>= 2), evenly spaced over its range, ends included.
        joint_names: Names for the labels, length n.
        rng: If given, every value of joint i moves by ``U(-PROTOCOL_JITTER, PROTOCOL_JITTER)``
            times its range width over ``M`` (an uneven sweep, as a real operator's), drawn joint
            by joint; ``q0`` stays the middle of the ranges.
        limits: Per joint ``[lower, upper]`` [m]/[rad], shape (n, 2): jittered values are
            clipped to these (default: ``ranges``).

    Returns:
        ``(q, labels)``: q of shape (n M + 1, n), first ``q0`` (the middle of every range), then
        joint 0's M values, joint 1's, ...; labels ``"q0"``, ``"<joint> k/M"``.

    Raises:
        ConfigurationError: ``M < 2``.
    """
    r = np.asarray(ranges, dtype=float)
    if M < 2:
        raise ConfigurationError(f"M must be at least 2 values per joint, got {M}")
    lim = r if limits is None else np.asarray(limits, dtype=float)
    q0 = r.mean(axis=1)
    qs, labels = [q0], ["q0"]
    for i, name in enumerate(joint_names):
        values = np.linspace(r[i, 0], r[i, 1], M)
        if rng is not None:
            values = (
                values + rng.uniform(-PROTOCOL_JITTER, PROTOCOL_JITTER, M) * (r[i, 1] - r[i, 0]) / M
            )
            values = np.clip(values, lim[i, 0], lim[i, 1])
        for k, v in enumerate(values):
            q = q0.copy()
            q[i] = v
            qs.append(q)
            labels.append(f"{name} {k + 1}/{M}")
    return np.array(qs), labels


def protocol_q(
    robot: CPCModel | RobotStructure, M: int, rng: np.random.Generator | None = None
) -> Array:
    """The protocol's configurations for a robot: :func:`protocol_configurations` over its
    :func:`calibration_ranges`, jittered values (``rng``) clipped to the joint limits.

    Args:
        robot: The robot (model or structure).
        M: Values per joint (>= 2).
        rng: Random generator for an uneven sweep (None: evenly spaced).

    Returns:
        Configurations [m]/[rad], shape (n M + 1, n).
    """
    s = robot.structure if isinstance(robot, CPCModel) else robot
    limits = np.column_stack([s.lower, s.upper])
    return protocol_configurations(calibration_ranges(s), M, s.joint_names, rng=rng, limits=limits)[
        0
    ]


def random_configurations(ranges: ArrayLike, n: int, rng: np.random.Generator) -> Array:
    """``n`` configurations uniform in the box ``ranges`` (shape (n_joints, 2)), shape (n, n_joints)."""
    r = np.asarray(ranges, dtype=float)
    return r[:, 0] + (r[:, 1] - r[:, 0]) * rng.random((n, r.shape[0]))


def walk_configurations(
    usable: Callable[[Array], NDArray[np.bool_]],
    start: ArrayLike,
    ranges: ArrayLike,
    rng: np.random.Generator,
    steps: int,
    line_points: int = 24,
) -> Array:
    """The configurations a random walk in the box ``ranges`` (n, 2) visits, starting at the
    usable ``start`` (n,): each step tries ``line_points`` points on a random line through the
    current configuration (of a random length, up to the whole box, clipped to it) and moves to
    one that ``usable`` (a batch (K, n) -> (K,) bool) accepts. Shape (visited, n), distinct rows."""
    lo, hi = np.asarray(ranges, dtype=float).T
    span = np.where(hi > lo, hi - lo, 1.0)
    u = np.clip((np.asarray(start, dtype=float) - lo) / span, 0.0, 1.0)
    visited = [u]
    for _ in range(steps):
        v = rng.normal(size=len(u))
        t = 10.0 ** rng.uniform(-2.0, 0.3) * np.linspace(-1.0, 1.0, line_points)
        cand = np.clip(u + t[:, None] * v / np.linalg.norm(v), 0.0, 1.0)
        good = np.flatnonzero(usable(lo + cand * span))
        if good.size:
            u = cand[rng.choice(good)]
            visited.append(u)
    return np.asarray(lo + np.unique(np.array(visited), axis=0) * span, dtype=float)


def farthest_points(q: ArrayLike, n: int, ranges: ArrayLike, rng: np.random.Generator) -> Array:
    """``n`` of the configurations ``q`` (K, n_joints), K >= n, spread by farthest-point selection
    (a random first, then each the farthest from those chosen, in units of the ranges (n_joints, 2)).
    Shape (n, n_joints)."""
    qq = np.asarray(q, dtype=float)
    lo, hi = np.asarray(ranges, dtype=float).T
    u = qq / np.where(hi > lo, hi - lo, 1.0)
    pick = [int(rng.integers(len(u)))]
    d = np.linalg.norm(u - u[pick[0]], axis=1)
    while len(pick) < n:
        pick.append(int(np.argmax(d)))
        d = np.minimum(d, np.linalg.norm(u - u[pick[-1]], axis=1))
    return qq[pick]


def measured_frames(structure: RobotStructure) -> list[str]:
    """The frames stage 1 measures: those of kind ``"plate"``."""
    return [f.name for f in structure.frames if f.kind == "plate"]


__all__ = [
    "DEFAULT_M",
    "DEFAULT_RANGE_SHARE",
    "PROTOCOL_JITTER",
    "calibration_ranges",
    "farthest_points",
    "measured_frames",
    "protocol_configurations",
    "protocol_q",
    "random_configurations",
    "walk_configurations",
]
