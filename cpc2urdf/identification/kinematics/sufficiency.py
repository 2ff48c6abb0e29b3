"""Do the records suffice to identify the robot? Checked before any solver runs.

Every identification method needs, whatever the design of the experiment:

- every joint moved: at least two distinct readings among the records that measure a frame it
  moves (a revolute axis line and a prismatic direction are fixed by two readings; sec. 4.1's
  protocol takes ``M`` more), and every joint moving some measured frame;
- as many equations as parameters: 6 per distinct measured pose (a frame at a distinct
  configuration) against :func:`closed_form.count_parameters` (32 for the IIS-head);
- no record counted twice: a record that repeats another to the last digit (readings and poses)
  is a copy, not a second measurement (real measurements never repeat their noise), and would
  make the fit and its covariance over-confident. Noise-free simulated data repeat their poses
  wherever they repeat a configuration, so copies are refused here only when the records show
  noise (two records at one configuration with different poses); the consistency gate refuses
  them after the fit when its residuals are not exact (:func:`check_no_copies`).

:func:`check_data_suffice` raises :class:`~cpc2urdf.errors.DegenerateDataError` with one line
naming the joints or records and how many more measurements are needed. Readings within
:data:`protocol.READING_TOL` count as one (a joint driven back may read a count off).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cpc2urdf.errors import DegenerateDataError
from cpc2urdf.files.measurements import MeasurementSet
from cpc2urdf.identification.kinematics.closed_form import count_parameters
from cpc2urdf.identification.kinematics.protocol import joint_tolerances
from cpc2urdf.tolerances import FK_AGREEMENT_TOL

PROTOCOL_HINT = "one joint at a time from q0, Shih et al. sec. 4.1"


def _count_distinct(values: NDArray[np.float64], tol: float) -> int:
    """Number of clusters of sorted ``values`` whose neighbours are more than ``tol`` apart."""
    if values.size == 0:
        return 0
    v = np.sort(values)
    return int(1 + np.sum(np.diff(v) > tol))


def distinct_configurations(q: NDArray[np.float64], tol: NDArray[np.float64]) -> NDArray[np.int64]:
    """Index of the first record at the same configuration (within ``tol`` per joint), shape (N,)."""
    first = np.arange(len(q))
    for i in range(1, len(q)):
        same = np.flatnonzero(np.all(np.abs(q[:i] - q[i]) <= tol, axis=1))
        if same.size:
            first[i] = first[same[0]]
    return first


def _name(ms: MeasurementSet, i: int) -> str:
    label = ms.labels[i]
    return f"record {i}" if label == f"record {i}" else f"record {i} ({label})"


def _records(ms: MeasurementSet, idx: list[int], most: int = 3) -> str:
    shown = ", ".join(_name(ms, i) for i in idx[:most])
    return shown + (f" and {len(idx) - most} more" if len(idx) > most else "")


def _reading(ms: MeasurementSet, joint: int, value: float) -> str:
    j = ms.structure.joints[joint]
    return f"{math.degrees(value):.6g} deg" if j.type == "revolute" else f"{value * 1e3:.6g} mm"


def exact_copies(ms: MeasurementSet) -> list[tuple[int, int]]:
    """``(copy, original)`` pairs of records whose readings and poses are bit-identical."""
    seen: dict[bytes, int] = {}
    pairs = []
    frames = sorted(ms.poses)
    for i in range(ms.n_records):
        key = ms.q[i].tobytes() + b"".join(ms.poses[f][i].tobytes() for f in frames)
        if key in seen:
            pairs.append((i, seen[key]))
        else:
            seen[key] = i
    return pairs


def check_data_suffice(ms: MeasurementSet, tol: ArrayLike | None = None) -> None:
    """Refuse records that cannot determine the robot, before any solver runs.

    Args:
        ms: The measurements.
        tol: Readings closer than this are equal [rad]/[m], scalar or per joint (n,); default
            :data:`protocol.READING_TOL` by joint type.

    Raises:
        DegenerateDataError: One line naming what is missing (see the module docstring).
    """
    s = ms.structure
    src = ms.source
    tols = joint_tolerances(s, tol)
    frames = ms.frames
    if ms.n_records == 0 or not frames:
        raise DegenerateDataError(f"{src}: no record has a measured pose")
    first = distinct_configurations(ms.q, tols)
    n_configs = int(len(np.unique(first)))
    # Every joint must move a measured frame, at two distinct readings at least.
    unseen, still = [], []
    for k, j in enumerate(s.joints):
        below = [f for f in frames if j.name in s.path_to(f)]
        if not below:
            downstream = [f.name for f in s.frames if j.name in s.path_to(f.name)]
            unseen.append(
                f"joint {j.name!r} moves no measured frame (no pose of "
                f"{', '.join(downstream) or 'any frame'} in any record)"
            )
            continue
        rows = np.zeros(ms.n_records, dtype=bool)
        for f in below:
            rows |= ms.has_pose(f)
        if _count_distinct(ms.q[rows, k], float(tols[k])) < 2:
            still.append((j.name, k, int(rows.sum()), below))
    if unseen:
        raise DegenerateDataError(
            f"{src}: {unseen[0]}"
            + (f" (and {len(unseen) - 1} more joints)" if len(unseen) > 1 else "")
            + "; measure a frame that it moves"
        )
    if still:
        copies = ms.n_records - n_configs
        at_one = f"all {ms.n_records} records are at {'one configuration' if n_configs == 1 else f'{n_configs} configurations'}"
        if copies:
            at_one += f" ({copies} repeat another record's readings)"
        if len(still) == 1:
            name, k, n, below = still[0]
            msg = (
                f"joint {name!r} has fewer than two distinct readings (all {n} records that measure "
                f"{', '.join(below)} read {_reading(ms, k, ms.q[np.argmax(ms.has_pose(below[0])), k])}): it "
                f"never moves, so its axis cannot be identified; measure it at >= 1 more reading ({PROTOCOL_HINT})"
            )
        elif len(still) == s.n_joints:
            msg = (
                f"no joint moves: {at_one}; the {s.n_joints} joints ({', '.join(n for n, *_ in still)}) each have fewer "
                f"than two distinct readings: measure each at >= 1 more reading ({PROTOCOL_HINT})"
            )
        else:
            msg = (
                f"joints {', '.join(repr(n) for n, *_ in still)} have fewer than two distinct readings in the records "
                f"that measure their frames: they never move; measure each at >= 1 more reading ({PROTOCOL_HINT})"
            )
        raise DegenerateDataError(f"{src}: {msg}")
    # As many equations (6 per distinct measured pose) as parameters.
    P = count_parameters(s, frames)["total"]
    poses = sum(len(np.unique(first[ms.has_pose(f)])) for f in frames)
    if 6 * poses < P:
        need = math.ceil((P - 6 * poses) / (6 * len(frames)))
        repeats = [i for i in range(ms.n_records) if first[i] != i]
        rep = f"; {_records(ms, repeats)} repeat earlier configurations" if repeats else ""
        raise DegenerateDataError(
            f"{src}: too few distinct configurations: {n_configs} among {ms.n_records} records{rep}; their {poses} "
            f"distinct poses give {6 * poses} equations for the {P} parameters of {s.name!r}: measure >= {need} more "
            f"configurations ({PROTOCOL_HINT})"
        )
    if noise_evident(ms, first):
        check_no_copies(ms)


def noise_evident(ms: MeasurementSet, first: NDArray[np.int64] | None = None) -> bool:
    """True when two records at one configuration measured poses more than
    :data:`~cpc2urdf.tolerances.FK_AGREEMENT_TOL` apart: the data are noisy, so records that agree
    to the last digit are copies. (Noise-free simulated data repeat their poses, up to rounding,
    wherever they repeat a configuration.)"""
    if first is None:
        first = distinct_configurations(ms.q, joint_tolerances(ms.structure))
    for f, T in ms.poses.items():
        ok = ms.has_pose(f)
        for i in np.flatnonzero(ok & (first != np.arange(ms.n_records))):
            j = int(first[i])
            if ok[j] and np.max(np.abs(T[i] - T[j])) > FK_AGREEMENT_TOL:
                return True
    return False


def check_no_copies(ms: MeasurementSet) -> None:
    """Refuse records that repeat another's readings and poses to the last digit.

    Raises:
        DegenerateDataError: Naming the first copy and its original, and how many copies.
    """
    copies_of = exact_copies(ms)
    if copies_of:
        c, o = copies_of[0]
        more = f" (and {len(copies_of) - 1} more copies)" if len(copies_of) > 1 else ""
        raise DegenerateDataError(
            f"{ms.source}: {_name(ms, c)} repeats {_name(ms, o)} to the last digit (readings and poses){more}: "
            f"a copied record, not a new measurement, would make the fit over-confident; remove the "
            f"{len(copies_of)} {'copy' if len(copies_of) == 1 else 'copies'} (to repeat a configuration, measure it again)"
        )


__all__ = [
    "PROTOCOL_HINT",
    "check_data_suffice",
    "check_no_copies",
    "distinct_configurations",
    "exact_copies",
    "noise_evident",
]
