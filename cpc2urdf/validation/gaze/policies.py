"""Redundancy policies: which joints may move, and the secondary task (priority 2) they solve.

- ``"cyclopean"`` (default): the table stays where it is; neck and eyes move; among the
  fixating configurations the one with zero *version* (the eyes turned equally and oppositely
  from their home readings, the middle of their limits), so the cyclopean axis faces the target
  and the eyes converge symmetrically on it.
- ``"min-motion"``: the table stays; the fixating configuration nearest ``q_current`` (Euclidean
  in the readings of neck and eyes, [rad]).
- ``"eyes-only"``: only the eye joints move (head and table still); reachable only if the target
  happens to lie where the eyes alone can converge.
- ``"use-table"``: every joint may move; zero version, the cyclopean point (midpoint of the camera
  centres) at ``viewing_distance`` [m] from the target, and the least table motion.

The secondary task moves only in the null space of fixation (see
:mod:`cpc2urdf.validation.gaze.gauss_newton`).
"""

from __future__ import annotations

import numpy as np

from cpc2urdf.errors import ConfigurationError
from cpc2urdf.transforms import Array
from cpc2urdf.validation.gaze.fixation import FixationState
from cpc2urdf.validation.gaze.head import GazeHead, Index

POLICIES: tuple[str, ...] = ("cyclopean", "min-motion", "eyes-only", "use-table")
DEFAULT_VIEWING_DISTANCE = 0.6  # [m]: use-table policy, cyclopean point to target
TABLE_TIE_WEIGHT = 1e-4  # [1/m]: use-table, least table motion vs the viewing distance


def check_policy(policy: str) -> None:
    """:class:`ConfigurationError` unless ``policy`` is one of :data:`POLICIES`."""
    if policy not in POLICIES:
        raise ConfigurationError(f"unknown gaze policy {policy!r}; expected one of {', '.join(POLICIES)}")


def free_joints(head: GazeHead, policy: str) -> Index:
    """Indices of the joints ``policy`` lets move (sorted, except ``"eyes-only"``: left eye first)."""
    if policy == "eyes-only":
        return head.eyes_all
    if policy == "use-table":
        return np.arange(head.n)
    return np.sort(np.concatenate([head.neck, head.eyes_all]))


def secondary_task(
    head: GazeHead,
    policy: str,
    q: Array,
    q_ref: Array,
    p: Array,
    st: FixationState,
    viewing_distance: float,
) -> tuple[Array, Array]:
    """Residual (k,) and Jacobian (k, n) of the policy's secondary task.

    Args:
        head: The head.
        policy: One of :data:`POLICIES`.
        q: Readings [rad]/[m], shape (n,).
        q_ref: The reference readings (``q_current``, or home), shape (n,).
        p: The target (world) [m], shape (3,).
        st: The fixation state at ``q``; for ``"use-table"`` with ``st.Jo`` set.
        viewing_distance: ``"use-table"``: cyclopean point to target [m].
    """
    n = head.n
    rows: list[Array] = []
    res: list[float] = []
    if policy in ("cyclopean", "use-table"):
        # version: (eye_L - home_L) + s (eye_R - home_R) = 0, first eye joint of each side
        row = head.version_row
        if policy == "cyclopean":
            return np.array([float(row @ (q - head.home))]), row[None, :]
        rows.append(row)
        res.append(float(row @ (q - head.home)))
    if policy == "use-table":
        # cyclopean point at the viewing distance: d|c - p|/dq through the table's translation
        c = 0.5 * (np.array(st.origins[0]) + np.array(st.origins[1]))
        d = c - p
        dist = float(np.linalg.norm(d))
        row = np.zeros(n)
        assert st.Jo is not None  # set by the iteration for this policy
        Jc = 0.5 * (st.Jo[0] + st.Jo[1])
        row[:] = (d / max(dist, 1e-12)) @ Jc
        rows.append(row)
        res.append(dist - viewing_distance)
        for i in head.table:  # then the least table motion: a tie-breaker, tiny weight
            row = np.zeros(n)
            row[i] = TABLE_TIE_WEIGHT
            rows.append(row)
            res.append(TABLE_TIE_WEIGHT * float(q[i] - q_ref[i]))
    if policy == "min-motion":
        for i in free_joints(head, policy):
            row = np.zeros(n)
            row[i] = 1.0
            rows.append(row)
            res.append(float(q[i] - q_ref[i]))
    if not rows:
        return np.zeros(0), np.zeros((0, n))
    return np.array(res), np.array(rows)


__all__ = [
    "DEFAULT_VIEWING_DISTANCE",
    "POLICIES",
    "TABLE_TIE_WEIGHT",
    "check_policy",
    "free_joints",
    "secondary_task",
]
