"""Joint readings of an images folder: ``joints.csv``.

One row per record: a ``record`` column naming the record's image files (without extension),
optionally a ``label`` column, and one column per joint, whose header may carry the unit in
brackets (``m``, ``cm``, ``mm`` for prismatic joints, ``rad``, ``deg`` for revolute ones; no
bracket: SI)::

    record,label,table_x[mm],table_y[mm],pan[deg],tilt[deg],vergence_left[deg],vergence_right[deg]
    0000,q0,500,250,90,30,45,45

A URDF robot's joints may be named as in the URDF (``head_1_joint``, what ``/joint_states`` and
``cpc2urdf plan`` use) or as in the model (``head_1``): :func:`urdf_joint_columns`. Lines starting
with ``#`` and blank lines are ignored. See ``docs/images.md``.
"""

from __future__ import annotations

import csv
import io
import math
import re
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cpc2urdf.errors import InputFileError
from cpc2urdf.files.jsonio import read_text_file, write_atomic
from cpc2urdf.files.spec import RobotSpec
from cpc2urdf.files.units import ANGLE_UNITS, LENGTH_UNITS
from cpc2urdf.model import CPCModel, RobotStructure
from cpc2urdf.urdf.robot import UrdfRobot, urdf_source

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


def read_joints_csv(
    path: str | Path,
    structure: RobotStructure,
    *,
    aliases: Mapping[str, str] | None = None,
    ignore: Collection[str] = (),
) -> JointTable:
    """Read a ``joints.csv`` (see the module docstring); joint values in SI ([m], [rad]).

    Args:
        path: The file.
        structure: The robot: one column per joint.
        aliases: Other column names for its joints (column name -> joint name), e.g. a URDF
            robot's own joint names (:func:`urdf_joint_columns`), which ``cpc2urdf plan`` writes.
        ignore: Columns of other joints of the same robot, skipped (a ROS ``joint_states`` has
            every joint; the calibration needs those on its paths).

    Raises:
        InputFileError: Naming the file, the row and the column: missing/unknown/duplicate
            columns, a unit that does not fit the joint, a non-number, a reading outside its
            joint's limits, a duplicate record.
    """
    p = Path(path)
    alias = {
        a: j
        for a, j in (aliases or {}).items()
        if j in structure.joint_names and a not in structure.joint_names
    }
    text = read_text_file(p, "a CSV file", encoding="utf-8-sig")
    rows = [
        r for r in csv.reader(io.StringIO(text)) if r and not (len(r) == 1 and not r[0].strip())
    ]
    rows = [r for r in rows if not r[0].lstrip().startswith("#")]
    if not rows:
        raise InputFileError(
            p, "empty; expected a header 'record,<joint>[unit],...' and one row per record"
        )
    names, scales = [], []
    for col, h in enumerate(rows[0]):
        m = _HEADER.match(h)
        if not m:
            raise InputFileError(
                p,
                f"column {col + 1} header {h!r} must be a name, optionally with a unit like pan[deg]",
            )
        names.append(m.group(1))
        scales.append(m.group(2))
    if len(set(names)) != len(names):
        raise InputFileError(p, f"duplicate column in header {rows[0]}")
    keep = [
        i
        for i, n in enumerate(names)
        if n not in ignore or n in structure.joint_names or n in alias
    ]
    if len(keep) < len(names):
        rows = [[r[i] for i in keep if i < len(r)] for r in rows]
        names, scales = [names[i] for i in keep], [scales[i] for i in keep]
    if "record" not in names:
        raise InputFileError(p, "missing column 'record' (the image file name without extension)")
    joint_cols = [n for n in names if n not in ("record", "label")]
    unknown = [n for n in joint_cols if n not in structure.joint_names and n not in alias]
    if unknown:
        also = f" (or {', '.join(alias)})" if alias else ""
        raise InputFileError(
            p,
            f"unknown joint column {unknown[0]!r}; joints of {structure.name}: "
            f"{', '.join(structure.joint_names)}{also}",
        )
    column = {alias.get(n, n): n for n in joint_cols}  # joint -> its column
    if len(column) != len(joint_cols):
        twice = next(j for j in column if sum(alias.get(n, n) == j for n in joint_cols) > 1)
        raise InputFileError(
            p,
            f"joint {twice!r} has two columns: "
            f"{' and '.join(n for n in joint_cols if alias.get(n, n) == twice)}",
        )
    missing = [n for n in structure.joint_names if n not in column]
    if missing:
        raise InputFileError(
            p,
            f"missing joint column {next((a for a, j in alias.items() if j == missing[0]), missing[0])!r} "
            "(every joint needs a reading)",
        )
    factor = {}
    for n, unit in zip(names, scales, strict=True):
        if n in ("record", "label"):
            continue
        jt = structure.joint(alias.get(n, n)).type
        table = LENGTH_UNITS if jt == "prismatic" else ANGLE_UNITS
        if unit is None:
            factor[n] = 1.0
        elif unit not in table:
            raise InputFileError(
                p,
                f"column {n}: unit [{unit}] does not fit a {jt} joint; use one of {sorted(table)}",
            )
        else:
            factor[n] = table[unit]
    records, labels, qs = [], [], []
    for k, row in enumerate(rows[1:], start=2):
        if len(row) != len(names):
            raise InputFileError(
                p, f"row {k}: {len(row)} values, the header has {len(names)} columns"
            )
        d = dict(zip(names, (v.strip() for v in row), strict=True))
        rec = d["record"]
        if not rec or "/" in rec or "\\" in rec:
            raise InputFileError(
                p, f"row {k}: record must be a file name without folders, got {rec!r}"
            )
        if rec in records:
            raise InputFileError(p, f"row {k}: record {rec!r} appears twice")
        q = []
        for j in structure.joints:
            n = column[j.name]
            try:
                v = float(d[n])
            except ValueError:
                raise InputFileError(
                    p, f"row {k} (record {rec}): {n} must be a number, got {d[n]!r}"
                ) from None
            if not math.isfinite(v):
                raise InputFileError(p, f"row {k} (record {rec}): {n} must be finite, got {d[n]!r}")
            if not (j.lower - LIMIT_SLACK <= v * factor[n] <= j.upper + LIMIT_SLACK):
                unit = scales[names.index(n)] or ("m" if j.type == "prismatic" else "rad")
                lo, hi = j.lower / factor[n], j.upper / factor[n]
                raise InputFileError(
                    p,
                    f"row {k} (record {rec}): {n} = {d[n]} {unit} is outside the joint limits "
                    f"[{lo:.6g}, {hi:.6g}] {unit} (wrong units?)",
                )
            q.append(v * factor[n])
        records.append(rec)
        labels.append(d.get("label") or rec)
        qs.append(q)
    if not records:
        raise InputFileError(p, "has a header but no records")
    return JointTable(records, labels, np.array(qs))


def write_joints_csv(
    path: str | Path,
    structure: RobotStructure,
    records: Sequence[str],
    q: ArrayLike,
    labels: Sequence[str] | None = None,
    *,
    length: str = "mm",
    angle: str = "deg",
    columns: Mapping[str, str] | None = None,
) -> Path:
    """Write a ``joints.csv`` atomically (lengths in ``length``, angles in ``angle``; ``columns``:
    joint name -> column name, e.g. a URDF robot's own joint names)."""
    qq = np.asarray(q, dtype=float)
    col = columns or {}
    head = ["record", "label"] + [
        f"{col.get(j.name, j.name)}[{length if j.type == 'prismatic' else angle}]"
        for j in structure.joints
    ]
    scale = [
        LENGTH_UNITS[length] if j.type == "prismatic" else ANGLE_UNITS[angle]
        for j in structure.joints
    ]
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(head)
    for i, rec in enumerate(records):
        lab = labels[i] if labels is not None else rec
        w.writerow([rec, lab] + [repr(float(v / s)) for v, s in zip(qq[i], scale, strict=True)])
    return write_atomic(path, buf.getvalue())


def urdf_joint_columns(robot: RobotSpec | CPCModel) -> dict[str, str]:
    """A URDF robot's own joint names -> the model's (``head_1_joint`` -> ``head_1``), for the
    joints of ``robot`` (a :class:`~cpc2urdf.urdf.robot.UrdfRobot` or a model made from a URDF);
    empty for other robots. ``aliases`` of :func:`read_joints_csv`."""
    joints = robot.structure.joint_names
    if isinstance(robot, UrdfRobot) and robot.names is not None:
        return {u: c for u, c in robot.names.joints.items() if c in joints and u != c}
    src = urdf_source(robot) if isinstance(robot, CPCModel) else None
    return (
        {u: c for c, u in src.joints.items() if c in joints and u != c} if src is not None else {}
    )


__all__ = ["JointTable", "read_joints_csv", "urdf_joint_columns", "write_joints_csv"]
