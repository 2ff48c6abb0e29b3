"""Tracker exports (CSV) of marker points -> a ``cpc2urdf/measurements@2`` document.

Laser trackers and motion-capture software export one row per (configuration, marker). Two
layouts are accepted:

1. **one file**: ``config,marker,x,y,z,<joint>,<joint>,...``: every row carries the joint
   readings of its configuration (rows of one configuration must agree on them);
2. **two files**: points ``config,marker,x,y,z`` and joints ``config,<joint>,<joint>,...`` (one
   row per configuration), joined on ``config``.

Column names are matched exactly (joint columns are the robot's joint names, the URDF's for a
URDF robot; a URDF's other joints are accepted and ignored by the measurement reader); any other
column is refused, naming it. Units: a first line ``# units: length=mm angle=deg`` in a file, or
the ``length``/``angle`` arguments (an argument and a header that disagree are refused); default
m and rad. Which link each marker is on (and, optionally, its known position in that link's
frame, in the same length unit) is given by the caller: a tracker export does not say.
Configurations keep the order of their first row; ``config`` values become the records' labels.
"""

from __future__ import annotations

import csv
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from cpc2urdf.errors import InputFileError
from cpc2urdf.files.measurements import (
    MEASUREMENTS_FORMAT_2,
    MeasurementSet,
    measurements_from_json,
)
from cpc2urdf.files.spec import RobotSpec

POINT_COLUMNS = ("config", "marker", "x", "y", "z")


def _read(
    path: Path, length: str | None, angle: str | None
) -> tuple[list[dict[str, str]], list[str], dict[str, str]]:
    try:
        text = path.read_text(encoding="utf-8-sig")
    except OSError as e:
        raise InputFileError(path, f"cannot read ({e.strerror})") from e
    lines = text.splitlines()
    units: dict[str, str] = {}
    while lines and lines[0].lstrip().startswith("#"):
        head = lines.pop(0).lstrip("# ").strip()
        if head.lower().startswith("units:"):
            for item in head[6:].replace(",", " ").split():
                key, _, value = item.partition("=")
                if key not in ("length", "angle") or not value:
                    raise InputFileError(
                        path, f"units header item {item!r}: expected length=UNIT or angle=UNIT"
                    )
                units[key] = value
    for key, given in (("length", length), ("angle", angle)):
        if given is not None:
            if key in units and units[key] != given:
                raise InputFileError(
                    path, f"header says {key}={units[key]} but {given} was asked for"
                )
            units[key] = given
    reader = csv.DictReader(lines)
    if not reader.fieldnames:
        raise InputFileError(path, "empty file: expected a header row")
    cols = [c.strip() for c in reader.fieldnames]
    rows = [{(k or "").strip(): (v or "").strip() for k, v in r.items()} for r in reader]
    if not rows:
        raise InputFileError(path, "no data rows")
    return rows, cols, units


def _number(path: Path, row: int, col: str, text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise InputFileError(
            path, f"row {row + 2}, column {col!r}: {text!r} is not a number"
        ) from None
    if v != v or v in (float("inf"), float("-inf")):
        raise InputFileError(path, f"row {row + 2}, column {col!r}: not finite")
    return v


def marker_csv_document(
    points_csv: str | os.PathLike[str],
    robot: str,
    markers: Mapping[str, str],
    *,
    joints_csv: str | os.PathLike[str] | None = None,
    joint_names: Sequence[str],
    known_positions: Mapping[str, Sequence[float]] | None = None,
    length: str | None = None,
    angle: str | None = None,
) -> dict[str, Any]:
    """The ``cpc2urdf/measurements@2`` document of a tracker export (module docstring).

    Args:
        points_csv: The points file (layout 1 or 2).
        robot: Robot reference written into the document.
        markers: Marker name -> link (frame) it is fixed to.
        joints_csv: The joints file of layout 2.
        joint_names: Joint column names the robot accepts (file names).
        known_positions: Marker -> position in its link's frame (file length unit).
        length: Length unit of the files (``m``, ``mm``, ...), if no header states it.
        angle: Angle unit (``rad``, ``deg``), if no header states it.

    Raises:
        InputFileError: Naming the file, row and column: unknown columns, missing columns, a
            marker with no link, readings that differ within one configuration, a configuration
            with no joint readings, a repeated (configuration, marker).
    """
    ppath = Path(points_csv)
    rows, cols, units = _read(ppath, length, angle)
    allowed_joints = set(joint_names)
    for c in POINT_COLUMNS:
        if c not in cols:
            raise InputFileError(
                ppath,
                f"lacks column {c!r}; expected {', '.join(POINT_COLUMNS)}"
                + ("" if joints_csv else " and joint columns"),
            )
    extra = [c for c in cols if c not in POINT_COLUMNS]
    joints_here = [c for c in extra if c in allowed_joints]
    unknown = [c for c in extra if c not in allowed_joints]
    if unknown:
        raise InputFileError(
            ppath,
            f"unknown column {unknown[0]!r}; expected {', '.join(POINT_COLUMNS)}"
            + (
                " only (joints come from the joints file)"
                if joints_csv
                else " and joint columns (" + ", ".join(sorted(allowed_joints)) + ")"
            ),
        )
    readings: dict[str, dict[str, float]] = {}
    if joints_csv is not None:
        if joints_here:
            raise InputFileError(
                ppath,
                f"column {joints_here[0]!r}: joint readings are in the joints file {joints_csv}",
            )
        jpath = Path(joints_csv)
        jrows, jcols, junits = _read(jpath, length, angle)
        for k, v in junits.items():
            if units.setdefault(k, v) != v:
                raise InputFileError(
                    jpath, f"units {k}={v} differ from the points file's {units[k]}"
                )
        if "config" not in jcols:
            raise InputFileError(jpath, "lacks column 'config'")
        bad = [c for c in jcols if c != "config" and c not in allowed_joints]
        if bad:
            raise InputFileError(
                jpath,
                f"unknown column {bad[0]!r}; expected config and joint columns "
                f"({', '.join(sorted(allowed_joints))})",
            )
        for i, r in enumerate(jrows):
            if r["config"] in readings:
                raise InputFileError(
                    jpath, f"row {i + 2}: configuration {r['config']!r} appears twice"
                )
            readings[r["config"]] = {c: _number(jpath, i, c, r[c]) for c in jcols if c != "config"}
    elif not joints_here:
        raise InputFileError(
            ppath, "no joint columns: give the joint readings as columns or in a joints file"
        )
    points: dict[str, dict[str, list[float]]] = {}
    for i, r in enumerate(rows):
        cfg, name = r["config"], r["marker"]
        if name not in markers:
            raise InputFileError(
                ppath,
                f"row {i + 2}: marker {name!r} has no link; known markers: "
                f"{', '.join(markers) or 'none'}",
            )
        xyz = [_number(ppath, i, c, r[c]) for c in ("x", "y", "z")]
        if joints_csv is None:
            q = {c: _number(ppath, i, c, r[c]) for c in joints_here}
            if cfg in readings and readings[cfg] != q:
                raise InputFileError(
                    ppath,
                    f"row {i + 2}: configuration {cfg!r} has other joint readings than its first row",
                )
            readings.setdefault(cfg, q)
        elif cfg not in readings:
            raise InputFileError(
                ppath, f"row {i + 2}: configuration {cfg!r} is not in the joints file {joints_csv}"
            )
        seen = points.setdefault(cfg, {})
        if name in seen:
            raise InputFileError(
                ppath, f"row {i + 2}: marker {name!r} appears twice in configuration {cfg!r}"
            )
        seen[name] = xyz
    defs: dict[str, Any] = {}
    for name, link in markers.items():
        defs[name] = {"link": link}
        if known_positions and name in known_positions:
            defs[name]["position"] = [float(v) for v in known_positions[name]]
    records = [
        {"label": cfg, "joints": readings[cfg], "markers": pts} for cfg, pts in points.items()
    ]
    doc: dict[str, Any] = {
        "format": MEASUREMENTS_FORMAT_2,
        "robot": robot,
        "markers": defs,
        "records": records,
    }
    if units:
        doc["units"] = units
    return doc


def load_marker_csv(
    points_csv: str | os.PathLike[str],
    robot: RobotSpec,
    markers: Mapping[str, str],
    *,
    robot_ref: str | None = None,
    joints_csv: str | os.PathLike[str] | None = None,
    known_positions: Mapping[str, Sequence[float]] | None = None,
    length: str | None = None,
    angle: str | None = None,
    noise_sigma_p: float | None = None,
) -> MeasurementSet:
    """Read a tracker export as a :class:`MeasurementSet` (see :func:`marker_csv_document`).

    Args:
        robot: The robot (its joint names, or the URDF's, are the joint columns).
        robot_ref: How files refer to the robot (default: its source).
        noise_sigma_p: The tracker's noise per coordinate [m], written as ``noise.sigma_p_m``.

    Raises:
        InputFileError: Naming the file, row and column (see :func:`marker_csv_document`), or
            a measurement-file error (a marker on a link the robot does not have).
    """
    from cpc2urdf.urdf.robot import UrdfRobot

    if isinstance(robot, UrdfRobot) and robot.tree is not None:
        names: list[str] = list(robot.tree.joints)
    else:
        names = list(robot.structure.joint_names)
    ref = robot_ref or robot.source or robot.structure.name
    doc = marker_csv_document(
        points_csv,
        ref,
        markers,
        joints_csv=joints_csv,
        joint_names=names,
        known_positions=known_positions,
        length=length,
        angle=angle,
    )
    if noise_sigma_p is not None:
        doc["noise"] = {"model": "isotropic points", "sigma_p_m": float(noise_sigma_p)}
    return measurements_from_json(doc, str(points_csv), robot=robot)


__all__ = ["POINT_COLUMNS", "load_marker_csv", "marker_csv_document"]
