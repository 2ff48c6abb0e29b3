"""FIGAROH's calibration CSV (one row per posture) -> a :class:`~cpc2urdf.files.measurements.MeasurementSet`.

FIGAROH (and its example data) writes one row per static posture: measured points
``x1,y1,z1, …, xK,yK,zK`` [m] in the measuring frame, or 6-D poses ``x1,y1,z1,phix1,phiy1,phiz1``
(orientation as URDF roll-pitch-yaw, ``R = Rz(phiz) Ry(phiy) Rx(phix)``), then one column per
joint named as in the URDF [rad] / [m]. A time column ``t`` is ignored; any other column is
refused, naming it.

A reading up to :data:`LIMIT_TOLERANCE_M` / :data:`LIMIT_TOLERANCE_RAD` past a URDF limit is
accepted and said in the set's ``notes``; a revolute reading a whole number of turns outside the
limits is wrapped into them and said; further out is refused (wrong unit or column).

Points become markers ``m1 … mK`` on the measured link with unknown positions; a marker whose
column repeats another's in every row (a tracker that filled a lost marker with its neighbour) is
dropped and named in the set's ``notes``. A 6-D pose is the measured pose of the link's frame up
to a fixed unknown transform (a tool or camera on it): identification fits that transform.
"""

from __future__ import annotations

import csv
import math
import os
import re
from pathlib import Path

import numpy as np

from cpc2urdf.errors import InputFileError
from cpc2urdf.files.measurements import UNKNOWN_MOUNTS, Marker, MeasurementSet
from cpc2urdf.model import Joint
from cpc2urdf.transforms import homogeneous, matrix_from_rpy
from cpc2urdf.urdf.robot import UrdfRobot

IGNORED_COLUMNS = ("t",)
# A reading this far past a URDF limit is taken as it is (a limit set slightly inside the travel),
# and said; further is refused as a wrong unit or column. A revolute reading 360 deg away from
# the limits' range is wrapped into it, and said.
LIMIT_TOLERANCE_M = 1e-3  # [m]
LIMIT_TOLERANCE_RAD = math.radians(1.0)  # [rad]
_POINT = re.compile(r"^(x|y|z|phix|phiy|phiz)(\d+)$")


def _within_limits(
    v: np.ndarray, joint: Joint, name: str, path: Path, lines: list[int]
) -> tuple[np.ndarray, list[str]]:
    """Readings ``v`` of ``joint`` (from the file's ``lines``) with 360-deg wraps undone, and what
    was said about them."""
    tol = LIMIT_TOLERANCE_M if joint.type == "prismatic" else LIMIT_TOLERANCE_RAD
    lo, hi = joint.lower, joint.upper
    out, notes = v.copy(), []
    if joint.type == "revolute":  # the fewest whole turns that bring a reading within the limits
        up = np.ceil((lo - tol - v) / (2 * math.pi))  # > 0 for a reading below the range
        down = np.floor((hi + tol - v) / (2 * math.pi))  # < 0 for a reading above it
        turns = np.where(up > 0, up, np.where(down < 0, down, 0.0))
        wrapped = v + 2 * math.pi * turns
        ok = (wrapped >= lo - tol) & (wrapped <= hi + tol) & (turns != 0)
        out[ok] = wrapped[ok]
        if ok.any():
            notes.append(
                f"{name}: {int(ok.sum())} reading(s) wrapped by a multiple of 360 deg into its limits"
            )
    bad = np.flatnonzero((out < lo - tol) | (out > hi + tol))
    if len(bad):
        i = int(bad[0])
        raise InputFileError(
            path,
            f"row {lines[i]}, column {name!r}: {v[i]:.6g} is outside the URDF limits "
            f"[{lo:.6g}, {hi:.6g}] by more than {tol:.3g} (wrong units or column?)",
        )
    past = np.maximum(out - hi, lo - out)
    if (past > 0).any():
        unit = "mm" if joint.type == "prismatic" else "deg"
        size = past.max() * (1e3 if joint.type == "prismatic" else 180 / math.pi)
        notes.append(
            f"{name}: {int((past > 0).sum())} reading(s) up to {size:.3g} {unit} past its URDF limits "
            f"(accepted: within {LIMIT_TOLERANCE_M * 1e3:g} mm / {math.degrees(LIMIT_TOLERANCE_RAD):g} deg)"
        )
    return out, notes


def load_figaroh_csv(
    path: str | os.PathLike[str], robot: UrdfRobot, link: str, *, robot_ref: str | None = None
) -> MeasurementSet:
    """Read a FIGAROH calibration CSV of ``robot`` (a URDF robot) whose points ride on ``link``.

    Raises:
        InputFileError: Unreadable file, no rows, a column that is neither a point coordinate, a
            joint of the URDF nor ``t``, an incomplete point (``x2`` without ``z2``), a cell that
            is not a number (file, row, column).
    """
    p = Path(path)
    try:
        rows = list(csv.reader(p.read_text(encoding="utf-8-sig").splitlines()))
    except OSError as e:
        raise InputFileError(p, f"cannot read ({e.strerror})") from e
    if len(rows) < 2:
        raise InputFileError(p, "expected a header row and at least one row of numbers")
    header = [c.strip() for c in rows[0]]
    assert robot.tree is not None and robot.names is not None
    sub = robot.restricted([link])
    assert sub.names is not None
    cpc_of = sub.names.joints
    points: dict[int, dict[str, int]] = {}
    joints: dict[str, int] = {}
    for i, c in enumerate(header):
        m = _POINT.match(c)
        if m:
            points.setdefault(int(m.group(2)), {})[m.group(1)] = i
        elif c in robot.tree.joints:
            if cpc_of.get(c) in sub.structure.joint_names:
                joints[cpc_of[c]] = i
        elif c not in IGNORED_COLUMNS:
            raise InputFileError(
                p,
                f"column {c!r} is neither a point coordinate (x1, y1, z1[, phix1, phiy1, "
                f"phiz1] ...) nor a joint of {robot.tree.source}",
            )
    missing = [j for j in sub.structure.joint_names if j not in joints]
    if missing:
        raise InputFileError(
            p, f"no column for joint {sub.names.urdf_joint(missing[0])!r} on the path to {link!r}"
        )
    body = [
        (k + 2, row) for k, row in enumerate(rows[1:]) if any(c.strip() for c in row)
    ]  # (line, cells)
    if not body:
        raise InputFileError(p, "expected a header row and at least one row of numbers")
    data = np.full((len(body), len(header)), np.nan)
    for r, (line, row) in enumerate(body):
        if len(row) != len(header):
            raise InputFileError(p, f"row {line}: {len(row)} cells, the header has {len(header)}")
        for i, v in enumerate(row):
            try:
                data[r, i] = float(v)
            except ValueError:
                raise InputFileError(
                    p, f"row {line}, column {header[i]!r}: {v!r} is not a number"
                ) from None
            if not math.isfinite(data[r, i]):
                raise InputFileError(
                    p, f"row {line}, column {header[i]!r}: {v!r} is not a finite number"
                )
    q = data[:, [joints[j] for j in sub.structure.joint_names]]
    notes: list[str] = []
    for k, j in enumerate(sub.structure.joints):
        q[:, k], said = _within_limits(
            q[:, k], j, sub.names.urdf_joint(j.name), p, [line for line, _ in body]
        )
        notes += said
    frame = sub.names.links[link]
    poses: dict[str, np.ndarray] = {}
    markers: dict[str, Marker] = {}
    marker_points: dict[str, np.ndarray] = {}
    for k in sorted(points):
        cols = points[k]
        if set(cols) >= {"phix", "phiy", "phiz", "x", "y", "z"}:
            T = np.stack(
                [
                    homogeneous(
                        matrix_from_rpy(data[r, [cols["phix"], cols["phiy"], cols["phiz"]]]),
                        data[r, [cols["x"], cols["y"], cols["z"]]],
                    )
                    for r in range(len(data))
                ]
            )
            if poses:
                raise InputFileError(
                    p, f"more than one 6-D pose per row (point {k}): one measured frame is read"
                )
            poses[frame] = T
        elif set(cols) == {"x", "y", "z"}:
            Y = data[:, [cols["x"], cols["y"], cols["z"]]]
            twin = next((n for n, other in marker_points.items() if np.array_equal(other, Y)), None)
            if twin is not None:
                notes.append(f"marker {k} repeats {twin} in every row: dropped")
                continue
            name = f"m{k}"
            markers[name] = Marker(name, frame)
            marker_points[name] = Y
        else:
            raise InputFileError(
                p,
                f"point {k}: columns {sorted(cols)}; expected x{k}, y{k}, z{k} "
                f"(and phix{k}, phiy{k}, phiz{k} for a 6-D pose)",
            )
    metadata: dict[str, object] = {UNKNOWN_MOUNTS: [frame]} if poses else {}
    if notes:
        metadata["notes"] = notes
    ms = MeasurementSet.from_arrays(
        sub.structure,
        q,
        poses,
        robot=robot_ref,
        source=str(p),
        markers=markers,
        marker_points=marker_points,
        metadata=metadata,
    )
    ms.spec = sub
    return ms


__all__ = ["load_figaroh_csv"]
