"""Recognise the one-joint-at-a-time measurement protocol (Shih et al. sec. 4.1, Fig. 8).

The closed-form identification needs records taken at a reference configuration ``q0`` and, for
every joint i, records ``q_ik`` equal to ``q0`` except in joint i. This module finds ``q0`` and
each joint's sweep in a :class:`~cpc2urdf.files.measurements.MeasurementSet` whose records may come in
any order (and may repeat ``q0``), and names what is missing when the data cannot determine the
robot (:class:`~cpc2urdf.errors.DegenerateDataError`):

- a joint with fewer than two distinct readings (never moved);
- no record at the reference configuration ``q0``;
- a record in which several joints moved away from ``q0``;
- a measured frame (a branch's end-effector) with no poses, or none at ``q0``;
- a joint that moves no measured frame, or whose sweep has no pose of any frame it moves.

A frame is measured in a record when the record has its pose or (position-only data,
``cpc2urdf/measurements@2``) sees a marker fixed to it (:func:`frame_seen`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cpc2urdf.errors import DegenerateDataError
from cpc2urdf.files.measurements import MeasurementSet
from cpc2urdf.model import RobotStructure

# Two readings of a joint within this are the same reading: a joint driven back to q0 may read a
# count or two off. The IIS-head's transducers resolve 0.0036-0.005 deg and 0.005 mm (Table 2);
# sweep steps are degrees and centimetres.
READING_TOL = {"revolute": 1e-4, "prismatic": 1e-5}  # [rad], [m]


@dataclass(frozen=True)
class Protocol:
    """Where the one-joint-at-a-time protocol put each record.

    Attributes:
        q0: The reference configuration [rad]/[m], shape (n,).
        reference: Indices of the records at ``q0`` (at least one).
        sweeps: Joint name -> indices of the records where only that joint differs from ``q0``.
        frames: The measured frames (at least one pose), in the structure's frame order.
        frames_below: Joint name -> measured frames that the joint moves.
    """

    q0: NDArray[np.float64]
    reference: tuple[int, ...]
    sweeps: dict[str, tuple[int, ...]]
    frames: tuple[str, ...]
    frames_below: dict[str, tuple[str, ...]]

    def summary(self) -> dict[str, object]:
        """Counts for provenance: reference records and sweep length per joint."""
        return {
            "reference_records": list(self.reference),
            "records_per_joint": {j: len(idx) for j, idx in self.sweeps.items()},
            "frames": list(self.frames),
        }


def _fmt(v: float) -> str:
    return f"{v:.9g}"


def joint_tolerances(
    structure: RobotStructure, tol: ArrayLike | None = None
) -> NDArray[np.float64]:
    """Per joint reading tolerance, shape (n,): ``tol`` (scalar or (n,)), else :data:`READING_TOL`."""
    if tol is None:
        return np.array([READING_TOL[j.type] for j in structure.joints])
    return np.broadcast_to(np.asarray(tol, dtype=float), (structure.n_joints,)).copy()


def _differing(
    q: NDArray[np.float64], q0: NDArray[np.float64], tol: ArrayLike
) -> NDArray[np.bool_]:
    return np.abs(q - q0) > tol


def _mode_configuration(q: NDArray[np.float64], tol: NDArray[np.float64]) -> NDArray[np.float64]:
    """Per joint, the most frequent reading (ties: the one seen first)."""
    q0 = np.empty(q.shape[1])
    for i in range(q.shape[1]):
        col = q[:, i]
        s = np.sort(
            col
        )  # readings within tol of each one: a window of the sorted column, O(N log N)
        counts = np.searchsorted(s, col + tol[i], side="right") - np.searchsorted(
            s, col - tol[i], side="left"
        )
        q0[i] = col[int(np.argmax(counts))]  # argmax returns the first maximum
    return q0


def find_reference(
    q: NDArray[np.float64],
    joint_names: tuple[str, ...],
    labels: list[str] | None = None,
    tol: ArrayLike = 1e-9,
) -> NDArray[np.float64]:
    """The reference configuration ``q0`` of one-joint-at-a-time data.

    ``q0`` is the configuration every record differs from in at most one joint. It is found as
    the per-joint most frequent reading; if that fails (a sweep revisiting one value more often
    than ``q0`` occurs), every record is tried as the reference.

    Args:
        q: Readings, shape (N, n).
        joint_names: Names of the n joints (for messages).
        labels: Record labels (for messages).
        tol: Readings closer than this are equal [rad]/[m], scalar or per joint (n,).

    Raises:
        DegenerateDataError: No record is at ``q0``, or some record moved several joints.
    """
    labels = labels or [f"record {i}" for i in range(len(q))]
    tol = np.broadcast_to(np.asarray(tol, dtype=float), (q.shape[1],))
    mode = _mode_configuration(q, tol)

    def conforming(q0: NDArray[np.float64]) -> NDArray[np.bool_]:
        return np.sum(_differing(q, q0, tol), axis=1) <= 1

    at_mode = np.all(~_differing(q, mode, tol), axis=1)
    if at_mode.any() and conforming(mode).all():
        return mode
    for r in range(len(q)):  # fallback: any record that all others differ from in <= 1 joint
        if conforming(q[r]).all():
            return q[r].copy()
    if not at_mode.any():
        named = ", ".join(f"{n}={_fmt(v)}" for n, v in zip(joint_names, mode, strict=True))
        raise DegenerateDataError(
            f"no reference configuration q0 among the {len(q)} records: the most common reading of "
            f"each joint gives q0 = ({named}) but no record has it; the one-joint-at-a-time "
            "protocol (sec. 4.1) needs a record at q0 and moves one joint at a time away from it"
        )
    bad = np.flatnonzero(~conforming(mode))
    i = int(bad[0])
    moved = [n for n, d in zip(joint_names, _differing(q[i], mode, tol), strict=True) if d]
    more = f" (and {len(bad) - 1} more records)" if len(bad) > 1 else ""
    name = labels[i] if labels[i] == f"record {i}" else f"{labels[i]} (record {i})"
    raise DegenerateDataError(
        f"{name} moved several joints away from the reference configuration q0: "
        f"{', '.join(moved)}{more}; the closed-form identification (sec. 4.1) needs one joint "
        "moved at a time"
    )


def frame_seen(ms: MeasurementSet, frame: str) -> NDArray[np.bool_]:
    """Records (N,) that measured ``frame``: its pose, or a marker fixed to it."""
    seen = ms.has_pose(frame).copy()
    for m in ms.markers_on(frame):
        seen |= ms.has_marker(m)
    return seen


def seen_frames(ms: MeasurementSet) -> tuple[str, ...]:
    """Frames with a pose or a seen marker, in the structure's frame order."""
    have = set(ms.frames) | set(ms.marker_frames)
    return tuple(f for f in ms.structure.frame_names if f in have)


def _frames_below(structure: RobotStructure, frames: tuple[str, ...]) -> dict[str, tuple[str, ...]]:
    below: dict[str, list[str]] = {j: [] for j in structure.joint_names}
    for f in frames:
        for j in structure.path_to(f):
            below[j].append(f)
    return {j: tuple(v) for j, v in below.items()}


def recognise_protocol(ms: MeasurementSet, tol: ArrayLike | None = None) -> Protocol:
    """Find ``q0``, the reference records and each joint's sweep, and check the data suffice.

    Args:
        ms: The measurements (any record order).
        tol: Readings closer than this are equal [rad]/[m], scalar or per joint (n,); default
            :data:`READING_TOL` by joint type.

    Returns:
        The :class:`Protocol`.

    Raises:
        DegenerateDataError: Naming the joint, frame or record: see the module docstring.
    """
    s = ms.structure
    q = ms.q
    tol = joint_tolerances(s, tol)
    if ms.n_records == 0:
        raise DegenerateDataError(f"{ms.source}: no records")
    empty = [f for f in ms.poses if not ms.has_pose(f).any()]
    if empty:
        raise DegenerateDataError(
            f"{ms.source}: frame {empty[0]!r} (a branch's end-effector) has no poses in any record"
        )
    frames = seen_frames(ms)
    if not frames:
        raise DegenerateDataError(f"{ms.source}: no frame has a measured pose")
    for i, j in enumerate(s.joints):
        if np.ptp(q[:, i]) <= tol[i]:
            raise DegenerateDataError(
                f"joint {j.name!r} has fewer than two distinct readings (all {len(q)} records read "
                f"{_fmt(q[0, i])}): it was never moved, so its axis cannot be identified"
            )
    q0 = find_reference(q, s.joint_names, ms.labels, tol)
    diff = _differing(q, q0, tol)
    reference = tuple(int(i) for i in np.flatnonzero(~diff.any(axis=1)))
    sweeps = {
        n: tuple(int(r) for r in np.flatnonzero(diff[:, i])) for i, n in enumerate(s.joint_names)
    }
    for name, idx in sweeps.items():
        if not idx:
            raise DegenerateDataError(
                f"joint {name!r} was not moved away from q0 = {_fmt(q0[s.joint_index(name)])} in any "
                "record, so its axis cannot be identified"
            )
    for f in frames:
        if not frame_seen(ms, f)[list(reference)].any():
            raise DegenerateDataError(
                f"frame {f!r} has no pose at the reference configuration q0 (records "
                f"{', '.join(ms.labels[r] for r in reference)}); every branch needs one"
            )
    below = _frames_below(s, frames)
    for j in s.joints:
        if not below[j.name]:
            downstream = [f.name for f in s.frames if j.name in s.path_to(f.name)]
            what = f"no pose of {', '.join(downstream)}" if downstream else "no frame at all"
            raise DegenerateDataError(
                f"joint {j.name!r} moves no measured frame ({what} downstream), so it cannot be identified"
            )
        seen = np.zeros(len(q), dtype=bool)
        for f in below[j.name]:
            seen |= frame_seen(ms, f)
        if not seen[list(sweeps[j.name])].any():
            raise DegenerateDataError(
                f"joint {j.name!r} was moved in {len(sweeps[j.name])} records but none of the frames it "
                f"moves ({', '.join(below[j.name])}) was measured there"
            )
    return Protocol(q0, reference, sweeps, frames, below)


__all__ = [
    "READING_TOL",
    "Protocol",
    "find_reference",
    "frame_seen",
    "joint_tolerances",
    "seen_frames",
    "recognise_protocol",
]
