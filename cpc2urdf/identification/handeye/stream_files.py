"""Pose streams in files: a robot file and a camera file, one pose per row with its time.

Accepted (the header names the columns, in any order, case-insensitive)::

    t,x,y,z,qx,qy,qz,qw                     # CSV, what a ROS user exports (any quaternion order)
    # timestamp tx ty tz qx qy qz qw        # TUM (KinHEC's --format tum); no header: this order
    t,...,base_ee_meas_px,...,base_ee_meas_qz      # KinHEC's CSV export, <id>_robot.csv
    t,...,cam_target_meas_px,...,cam_target_meas_qz  # and <id>_camera.csv

Time columns: ``t``, ``time``, ``timestamp``, ``stamp``; positions ``x``/``tx``/``px`` (and y, z);
quaternions ``qx qy qz qw``. A unit may follow a name: ``t_ns``, ``time[ms]``, ``x_mm``, ``y[cm]``;
default seconds and metres. Of KinHEC's files only the measured columns are read (``*_meas_*``,
quaternions w-first as its header says): never its ground truth or outlier flags. A robot pose
must be in every row; a camera row whose pose cells are all empty or NaN is a frame without a
measurement. Bad input: :class:`InputFileError` naming the file, line, column and what was
expected. Documented in ``docs/handeye.md`` ("Streams and CSV input").
"""

from __future__ import annotations

import csv
import os
import re
from dataclasses import replace
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from cpc2urdf.errors import DegenerateDataError, InputFileError
from cpc2urdf.files.units import LENGTH_UNITS
from cpc2urdf.identification.handeye.pose_file import HandEyePoses
from cpc2urdf.identification.handeye.streams import PoseStream, pair_streams
from cpc2urdf.transforms import inverse

TIME_NAMES = ("t", "time", "timestamp", "stamp", "rostime")
TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}
COMPONENTS = ("x", "y", "z", "qx", "qy", "qz", "qw")
_ALIASES = {"x": ("x", "tx", "px"), "y": ("y", "ty", "py"), "z": ("z", "tz", "pz")}
KINHEC_PREFIX = {"robot": "base_ee_meas_", "camera": "cam_target_meas_"}
TUM_COLUMNS = ("timestamp", "tx", "ty", "tz", "qx", "qy", "qz", "qw")
# `rostopic echo -p`: field.header.stamp and %time (receipt) in ns, field.pose.position.x, ...
_ROS_NAMES = re.compile(
    r"^(?:%time|field\.header\.stamp|.*\b(?:position|translation|orientation|rotation)\.[xyzw])$"
)
QUATERNION_NORM_TOL = 1e-3  # as pose files (files/poses.py)
_NAME_UNIT = re.compile(
    r"^(?P<name>[a-z]+)(?:_(?P<u>[a-z]+)|\s*\[(?P<b>[a-z]+)\])?$"
)  # x_mm, t[ns]


def _ros_name(m: re.Match[str]) -> str:
    name = m[0]
    if name in ("%time", "field.header.stamp"):
        return "rostime_ns" if name == "%time" else "stamp_ns"
    return ("q" if name.split(".")[-2] in ("orientation", "rotation") else "") + name[-1]


def _columns(header: list[str], role: str, where: str) -> tuple[list[int], list[float]]:
    """Indices of t, x, y, z, qx, qy, qz, qw in ``header`` and each one's scale to SI."""
    names = [_ROS_NAMES.sub(_ros_name, h.strip().lower()) for h in header]
    prefix, other = KINHEC_PREFIX[role], KINHEC_PREFIX["camera" if role == "robot" else "robot"]
    found: dict[str, tuple[int, float]] = {}
    if any(n.startswith(prefix) for n in names):  # KinHEC: measured columns only, w-first
        want: dict[str, tuple[str, ...]] = {"t": ("t",)}
        want.update({c: (prefix + "p" + c,) for c in "xyz"})
        want.update({f"q{c}": (prefix + "q" + c,) for c in "xyzw"})
        for i, n in enumerate(names):
            found.setdefault(n, (i, 1.0))
    elif any(n.startswith(other) for n in names):
        raise InputFileError(
            where, f"has KinHEC's {other}* columns, not {prefix}*: give the {role} stream here"
        )
    else:
        want = {"t": TIME_NAMES, **_ALIASES, **{q: (q,) for q in COMPONENTS[3:]}}
        for i, n in enumerate(names):
            m = _NAME_UNIT.match(n)
            if m is None:
                continue
            name, unit = m["name"], m["u"] or m["b"]
            units = TIME_UNITS if name in TIME_NAMES else LENGTH_UNITS if len(name) <= 2 else {}
            if unit is None or unit in units:
                found.setdefault(name, (i, units[unit] if unit else 1.0))
    idx, scale = [], []
    for options in want.values():
        hit = [found[o] for o in options if o in found]
        if not hit:
            raise InputFileError(
                where,
                f"no column {' or '.join(options)}; expected columns t, x, y, z, qx, qy, qz, qw "
                f"(units: t_ns, x_mm, ...) but found {', '.join(h.strip() for h in header)}",
            )
        idx.append(hit[0][0])
        scale.append(hit[0][1])
    return idx, scale


def _rows(path: Path) -> tuple[list[str], list[tuple[int, list[str]]]]:
    """Header and ``(line number, cells)`` of a CSV or whitespace-separated (TUM) file."""
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as e:
        raise InputFileError(path, f"cannot read: {e}") from e
    lines = [(k + 1, s.strip()) for k, s in enumerate(text.splitlines()) if s.strip()]
    if not lines:
        raise InputFileError(path, "empty file; expected a header and one pose per row")
    comments = [s.lstrip("#").split() for _, s in lines if s.startswith("#")]
    data = [(k, s) for k, s in lines if not s.startswith("#")]
    if not data:
        raise InputFileError(path, "no data rows; expected one pose per row")
    if "," in data[0][1]:
        rows = [(k, r) for (k, _), r in zip(data, csv.reader(s for _, s in data), strict=True)]
    else:
        rows = [(k, s.split()) for k, s in data]
    try:
        float(rows[0][1][0])
    except ValueError:
        return rows[0][1], rows[1:]  # a header row
    if "," in data[0][1]:
        raise InputFileError(
            path,
            f"line {rows[0][0]}: expected a header row naming the columns "
            "(t, x, y, z, qx, qy, qz, qw in any order)",
        )
    return next((c for c in reversed(comments) if len(c) >= 8), list(TUM_COLUMNS)), rows


def read_pose_stream(path: str | os.PathLike[str], role: str) -> PoseStream:
    """Read a robot (``role="robot"``: ``T_base_hand``) or camera (``"camera"``:
    ``T_camera_target``) pose stream, SI units.

    Raises:
        InputFileError: A missing column, a cell that is not a number, a robot row without a pose,
            a camera row with a partial pose, times not increasing, a quaternion not of unit norm.
    """
    p = Path(path)
    header, rows = _rows(p)
    idx, scale = _columns(header, role, str(p))
    names = [header[i].strip() for i in idx]
    if not rows:
        raise InputFileError(p, "no data rows; expected one pose per row")
    V = np.full((len(rows), 8), np.nan)
    for r, (line, cells) in enumerate(rows):
        for c, i in enumerate(idx):
            cell = cells[i].strip() if i < len(cells) else ""
            try:
                V[r, c] = float(cell) if cell else np.nan
            except ValueError:
                raise InputFileError(
                    p, f"line {line}, column {names[c]}: expected a number, got {cell!r}"
                ) from None
        missing = ~np.isfinite(V[r])
        c = int(np.argmax(missing))
        if missing.any() and (c == 0 or role == "robot" or not missing[1:].all()):
            need = "a time" if c == 0 else "a number"
            if role == "camera" and c > 0:
                need += " (a frame without a measurement leaves all its pose cells empty)"
            cell = cells[idx[c]] if idx[c] < len(cells) else ""
            raise InputFileError(
                p, f"line {line}, column {names[c]}: expected {need}, got {cell!r}"
            )
    V *= scale
    t, pos, q = V[:, 0], V[:, 1:4], V[:, 4:8]
    bad = np.flatnonzero(np.diff(t) <= 0)
    if len(bad):
        r = int(bad[0]) + 1
        raise InputFileError(
            p,
            f"line {rows[r][0]}, column {names[0]}: times must increase, got {t[r]:.9g} s "
            f"after {t[r - 1]:.9g} s",
        )
    measured = np.isfinite(q).all(axis=1)
    norm = np.linalg.norm(q[measured], axis=1)
    off = np.flatnonzero(np.abs(norm - 1.0) > QUATERNION_NORM_TOL)
    if len(off):
        r = int(np.flatnonzero(measured)[off[0]])
        raise InputFileError(
            p,
            f"line {rows[r][0]}, columns {', '.join(names[4:])}: expected a unit quaternion, "
            f"norm is {norm[off[0]]:.6g}",
        )
    T = np.full((len(t), 4, 4), np.nan)
    T[measured] = np.eye(4)
    T[measured, :3, :3] = Rotation.from_quat(q[measured] / norm[:, None]).as_matrix()
    T[measured, :3, 3] = pos[measured]
    return PoseStream(t, T, str(p))


def camera_file_for(robot_path: str | os.PathLike[str]) -> Path:
    """``SEQ_camera.EXT`` beside ``SEQ_robot.EXT`` (KinHEC's export names)."""
    p = Path(robot_path)
    if "_robot" not in p.stem:
        raise InputFileError(
            p,
            "give the camera stream too (handeye ROBOT CAMERA), or name the files "
            "SEQ_robot.csv and SEQ_camera.csv",
        )
    return p.with_name(p.stem.replace("_robot", "_camera") + p.suffix)


def handeye_poses_from_streams(
    robot: PoseStream,
    camera: PoseStream,
    *,
    time_offset: float | None = None,
    eye_to_hand: bool = False,
    keyframes: bool = True,
) -> HandEyePoses:
    """Pose pairs from two streams (:func:`~cpc2urdf.identification.handeye.streams.pair_streams`),
    labelled ``t=12.345s`` (camera time), the pairing in ``HandEyePoses.pairing``.

    ``eye_to_hand``: the camera is fixed and the target (marker) rides on the hand; the camera
    stream is ``T_camera_marker`` and is inverted, so ``T_base_hand X T_camera_target = Z`` holds
    with ``X = T_hand_marker``, ``Z = T_base_camera``, ``T_camera_target = inv(T_camera_marker)``.
    """
    if eye_to_hand:
        camera = PoseStream(camera.t, inverse(camera.T), camera.source)
    try:
        t, H, C, pairing = pair_streams(robot, camera, time_offset, keyframes=keyframes)
    except DegenerateDataError as e:
        raise DegenerateDataError(f"{robot.source} + {camera.source}: {e}") from e
    return HandEyePoses(
        H,
        C,
        tuple(f"t={v:.3f}s" for v in t),
        source=f"{robot.source} + {camera.source}",
        pairing=replace(pairing, eye_to_hand=eye_to_hand),
    )


def is_pose_file(path: str | os.PathLike[str]) -> bool:
    """A ``.json`` file, or a JSON document under another name, rather than a pose stream (a
    file that cannot be read goes to the JSON reader, which names the problem)."""
    if str(path).lower().endswith(".json"):
        return True
    try:
        with open(path, "rb") as f:
            return f.read(64).lstrip()[:1] in (b"{", b"[")
    except OSError:
        return True


def load_handeye_streams(
    robot_path: str | os.PathLike[str],
    camera_path: str | os.PathLike[str] | None = None,
    *,
    time_offset: float | None = None,
    eye_to_hand: bool = False,
) -> HandEyePoses:
    """Read a robot and a camera stream (``camera_path`` default: :func:`camera_file_for`) and pair
    them (:func:`handeye_poses_from_streams`)."""
    camera = camera_file_for(robot_path) if camera_path is None else Path(camera_path)
    return handeye_poses_from_streams(
        read_pose_stream(robot_path, "robot"),
        read_pose_stream(camera, "camera"),
        time_offset=time_offset,
        eye_to_hand=eye_to_hand,
    )


__all__ = [
    "camera_file_for",
    "handeye_poses_from_streams",
    "is_pose_file",
    "load_handeye_streams",
    "read_pose_stream",
]
