"""Joint readings of an images folder: ``joints.csv``.

One row per record: a ``record`` column naming the record's image files (without extension),
optionally a ``label`` column, and one column per joint, whose header may carry the unit in
brackets (``m``, ``cm``, ``mm`` for prismatic joints, ``rad``, ``deg`` for revolute ones; no
bracket: SI)::

    record,label,table_x[mm],table_y[mm],pan[deg],tilt[deg],vergence_left[deg],vergence_right[deg]
    0000,q0,500,250,90,30,45,45

Lines starting with ``#`` and blank lines are ignored. See ``docs/images.md``.
"""

from __future__ import annotations

import csv
import io
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cpc2urdf.errors import InputFileError
from cpc2urdf.fileio import read_text_file, write_atomic
from cpc2urdf.model import RobotStructure
from cpc2urdf.units import ANGLE_UNITS, LENGTH_UNITS

Array = NDArray[np.float64]

LIMIT_SLACK = 1e-9  # [m] or [rad]: a reading this far outside its joint's limits is still accepted, as in measurement files
_HEADER = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_.-]*)\s*(?:\[\s*([A-Za-z]+)\s*\])?\s*$")


@dataclass
class JointTable:
    """The rows of a ``joints.csv``.

    Attributes:
        records: Image file stems, one per row.
        labels: Labels (the ``label`` column, else the record names).
        q: Joint readings [m]/[rad], shape (N, n), in ``structure.joint_names`` order.
    """

    records: list[str]
    labels: list[str]
    q: Array


def read_joints_csv(path: str | Path, structure: RobotStructure) -> JointTable:
    """Read a ``joints.csv`` (see the module docstring); joint values in SI ([m], [rad]).

    Raises:
        InputFileError: Naming the file, the row and the column: missing/unknown/duplicate
            columns, a unit that does not fit the joint, a non-number, a reading outside its
            joint's limits, a duplicate record.
    """
    p = Path(path)
    text = read_text_file(p, "a CSV file", encoding="utf-8-sig")
    rows = [r for r in csv.reader(io.StringIO(text)) if r and not (len(r) == 1 and not r[0].strip())]
    rows = [r for r in rows if not r[0].lstrip().startswith("#")]
    if not rows:
        raise InputFileError(p, "empty; expected a header 'record,<joint>[unit],...' and one row per record")
    names, scales = [], []
    for col, h in enumerate(rows[0]):
        m = _HEADER.match(h)
        if not m:
            raise InputFileError(p, f"column {col + 1} header {h!r} must be a name, optionally with a unit like pan[deg]")
        names.append(m.group(1))
        scales.append(m.group(2))
    if len(set(names)) != len(names):
        raise InputFileError(p, f"duplicate column in header {rows[0]}")
    if "record" not in names:
        raise InputFileError(p, "missing column 'record' (the image file name without extension)")
    joint_cols = [n for n in names if n not in ("record", "label")]
    unknown = [n for n in joint_cols if n not in structure.joint_names]
    if unknown:
        raise InputFileError(p, f"unknown joint column {unknown[0]!r}; joints of {structure.name}: {', '.join(structure.joint_names)}")
    missing = [n for n in structure.joint_names if n not in names]
    if missing:
        raise InputFileError(p, f"missing joint column {missing[0]!r} (every joint needs a reading)")
    factor = {}
    for n, unit in zip(names, scales, strict=True):
        if n in ("record", "label"):
            continue
        jt = structure.joint(n).type
        table = LENGTH_UNITS if jt == "prismatic" else ANGLE_UNITS
        if unit is None:
            factor[n] = 1.0
        elif unit not in table:
            raise InputFileError(p, f"column {n}: unit [{unit}] does not fit a {jt} joint; use one of {sorted(table)}")
        else:
            factor[n] = table[unit]
    records, labels, qs = [], [], []
    for k, row in enumerate(rows[1:], start=2):
        if len(row) != len(names):
            raise InputFileError(p, f"row {k}: {len(row)} values, the header has {len(names)} columns")
        d = dict(zip(names, (v.strip() for v in row), strict=True))
        rec = d["record"]
        if not rec or "/" in rec or "\\" in rec:
            raise InputFileError(p, f"row {k}: record must be a file name without folders, got {rec!r}")
        if rec in records:
            raise InputFileError(p, f"row {k}: record {rec!r} appears twice")
        q = []
        for n in structure.joint_names:
            try:
                v = float(d[n])
            except ValueError:
                raise InputFileError(p, f"row {k} (record {rec}): {n} must be a number, got {d[n]!r}") from None
            if not math.isfinite(v):
                raise InputFileError(p, f"row {k} (record {rec}): {n} must be finite, got {d[n]!r}")
            j = structure.joint(n)
            if not (j.lower - LIMIT_SLACK <= v * factor[n] <= j.upper + LIMIT_SLACK):
                unit = scales[names.index(n)] or ("m" if j.type == "prismatic" else "rad")
                lo, hi = j.lower / factor[n], j.upper / factor[n]
                raise InputFileError(p, f"row {k} (record {rec}): {n} = {d[n]} {unit} is outside the joint limits "
                                        f"[{lo:.6g}, {hi:.6g}] {unit} (wrong units?)")
            q.append(v * factor[n])
        records.append(rec)
        labels.append(d.get("label") or rec)
        qs.append(q)
    if not records:
        raise InputFileError(p, "has a header but no records")
    return JointTable(records, labels, np.array(qs))


def write_joints_csv(
    path: str | Path, structure: RobotStructure, records: Sequence[str], q: ArrayLike,
    labels: Sequence[str] | None = None, *, length: str = "mm", angle: str = "deg",
) -> Path:
    """Write a ``joints.csv`` atomically (lengths in ``length``, angles in ``angle``)."""
    qq = np.asarray(q, dtype=float)
    head = ["record", "label"] + [
        f"{j.name}[{length if j.type == 'prismatic' else angle}]" for j in structure.joints
    ]
    scale = [LENGTH_UNITS[length] if j.type == "prismatic" else ANGLE_UNITS[angle] for j in structure.joints]
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(head)
    for i, rec in enumerate(records):
        lab = labels[i] if labels is not None else rec
        w.writerow([rec, lab] + [repr(float(v / s)) for v, s in zip(qq[i], scale, strict=True)])
    return write_atomic(path, buf.getvalue())


__all__ = ["JointTable", "read_joints_csv", "write_joints_csv"]
