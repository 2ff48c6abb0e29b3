"""Stage-1 measurements: joint readings with measured frame poses (``cpc2urdf/measurements@1``)
or marker points (``cpc2urdf/measurements@2``).

In memory a :class:`MeasurementSet` holds N records of one robot: the readings ``q`` (N, n) and,
per measured frame, ``T_world_<frame>`` (N, 4, 4), NaN where a record lacks that frame. On disk::

    {"format": "cpc2urdf/measurements@1",
     "robot": "iis_head",                       # shipped robot name, or a robot spec/model/URDF file
     "units": {"length": "mm", "angle": "deg"}, # optional, default m/rad
     "description": "...",                      # optional, free text
     "noise": {...}, "provenance": {...},       # optional, free-form, round-tripped
     "records": [
       {"label": "q0",                                          # optional
        "joints": {"table_x": 500, "pan": 90, ...},             # every joint, file units
        "poses": {"plate_left": {"matrix": [[...], ...]},       # T_world_<frame>
                  "plate_right": {"xyz": [...], "quat_xyzw": [...]}},
        "points": {"plate_left": [[x, y, z], ..., null, ...]}}  # measured circle centres
     ]}

A record's ``points`` give a plate's measured circle centres in world, one per entry of the
plate's ``layout`` (same order; ``null`` for a circle that was not seen). The pose is then
estimated on load by rigid registration (Shih et al. sec. 3.3) unless the record also gives it
under ``poses`` (a given pose wins; the points are kept). See ``docs/measurements.md``.

With a URDF robot (``"robot": "robot.urdf"``, :mod:`cpc2urdf.urdf.robot`) the frames are link
names of the URDF and the joints its joint names; the robot is the sub-tree on the paths from the
root to the links the records measure (their ``poses``/``points`` keys), so a record needs
readings only for the joints on those paths. Readings of other joints of the URDF (a whole
``/joint_states`` message) are accepted and ignored. In memory the set uses the model's names
(:class:`~cpc2urdf.urdf.robot.NameMap`); files use the URDF's.

**Position-only data** (``cpc2urdf/measurements@2``: everything of ``@1`` plus markers). A laser
tracker, motion capture or a touch probe gives 3-D points of markers fixed to links, not poses::

    {"format": "cpc2urdf/measurements@2", "robot": ..., "units": ...,
     "markers": {"m1": {"link": "head_2_link"},                      # position on the link unknown
                 "m2": {"link": "head_2_link", "position": [x, y, z]}},  # known, in the link's frame
     "records": [{"joints": {...}, "markers": {"m1": [x, y, z], "m2": null}}]}

A marker's ``link`` is a frame of the robot (a spec robot's frame, e.g. ``plate_left``; a URDF
link, which then becomes a measured link of the sub-tree); its ``position`` (file units, in that
frame) is optional: without it the marker's position is identified. In memory the set holds
:attr:`MeasurementSet.markers` (:class:`Marker`) and ``marker_points`` (N, 3) per marker, NaN
where a record did not see it. An ``@1`` file reads exactly as before, and a set without markers
is written as ``@1``.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cpc2urdf.errors import Cpc2UrdfError, InputFileError, UnknownNameError
from cpc2urdf.files.jsonio import finite_float, read_json, require_format, write_json
from cpc2urdf.files.poses import pose_from_json, pose_to_json
from cpc2urdf.files.robot_ref import load_robot
from cpc2urdf.files.spec import RobotSpec
from cpc2urdf.files.units import Units
from cpc2urdf.model import RobotStructure
from cpc2urdf.registration import plate_pose_from_points, registration_rms
from cpc2urdf.urdf.robot import UrdfRobot

MEASUREMENTS_FORMAT = "cpc2urdf/measurements@1"
# The version with marker points (position-only data); a superset of @1.
MEASUREMENTS_FORMAT_2 = "cpc2urdf/measurements@2"
MEASUREMENTS_FORMATS = (MEASUREMENTS_FORMAT, MEASUREMENTS_FORMAT_2)
# Free-form top-level sections that round-trip untouched in MeasurementSet.metadata.
OPTIONAL_SECTIONS = ("description", "noise", "provenance", "notes")
_RECORD_KEYS = {"label", "joints", "poses", "points"}
_RECORD_KEYS_2 = _RECORD_KEYS | {"markers"}
_MARKER_KEYS = {"link", "position"}


# ``MeasurementSet.metadata`` key: measured frames whose mount on their link nobody measured (a tool
# or camera on the link): identification fits it freely instead of keeping it near the URDF's.
UNKNOWN_MOUNTS = "unknown_mounts"


@dataclass(frozen=True)
class Marker:
    """A marker (a tracker's reflector, a mocap ball, a probed point) fixed to a frame of the robot.

    Attributes:
        name: The marker's name (as in the file).
        frame: The model frame it is fixed to (a URDF robot: the frame of that link).
        position: Its position in that frame [m], shape (3,), or None when it is to be identified.
    """

    name: str
    frame: str
    position: tuple[float, float, float] | None = None

    @property
    def known(self) -> bool:
        return self.position is not None


@dataclass
class MeasurementSet:
    """N records of joint readings with measured frame poses, for one robot.

    Attributes:
        structure: The robot's tree (joint order = column order of ``q``).
        q: Joint readings [m] / [rad], shape (N, n), in ``structure.joint_names`` order.
        poses: Frame name -> measured ``T_world_<frame>``, shape (N, 4, 4); all-NaN matrices
            where a record lacks that frame.
        source: Where the set came from (a file path, or ``"<memory>"``); errors name it.
        robot: How the robot is referred to in files (a shipped name or a spec/model path), or
            None if the set was built in memory without one (then it cannot be saved).
        labels: One label per record (``"record i"`` when the file gives none).
        points: Plate name -> measured circle centres in world [m], shape (N, K, 3) in the
            plate's layout order, NaN where not measured. Only plates whose points were given.
        fit_rms: Plate name -> RMS distance [m] between the measured points and the layout
            placed at the record's pose, shape (N,) (NaN where the record has no points).
        metadata: Free-form file sections (``description``, ``noise``, ``provenance``, ``notes``).
        spec: The robot the file refers to, as resolved when it was read (its nominal geometry
            is what identification starts from and keeps unmeasured frames with), or None.
        markers: Marker name -> :class:`Marker` (the frame it is on, its position if known).
        marker_points: Marker name -> measured world positions [m], shape (N, 3), NaN where a
            record did not see it (position-only data).
    """

    structure: RobotStructure
    q: NDArray[np.float64]
    poses: dict[str, NDArray[np.float64]]
    source: str = "<memory>"
    robot: str | None = None
    labels: list[str] = field(default_factory=list)
    points: dict[str, NDArray[np.float64]] = field(default_factory=dict)
    fit_rms: dict[str, NDArray[np.float64]] = field(default_factory=dict)
    metadata: dict[str, Any] = field(default_factory=dict)
    spec: RobotSpec | None = None
    markers: dict[str, Marker] = field(default_factory=dict)
    marker_points: dict[str, NDArray[np.float64]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        s = self.structure
        self.q = np.array(self.q, dtype=float)
        if self.q.ndim != 2 or self.q.shape[1] != s.n_joints:
            raise ValueError(f"q must have shape (N, {s.n_joints}), got {self.q.shape}")
        N = self.q.shape[0]
        if not self.labels:
            self.labels = [f"record {i}" for i in range(N)]
        if len(self.labels) != N:
            raise ValueError(f"need {N} labels, got {len(self.labels)}")
        for name, T in list(self.poses.items()):
            s.frame(name)
            T = np.asarray(T, dtype=float)
            if T.shape != (N, 4, 4):
                raise ValueError(f"poses[{name!r}] must have shape ({N}, 4, 4), got {T.shape}")
            self.poses[name] = T
        for name, P in list(self.points.items()):
            layout = s.frame(name).layout
            P = np.asarray(P, dtype=float)
            if layout is None or P.shape != (N, len(layout), 3):
                raise ValueError(
                    f"points[{name!r}] must have shape (N, K, 3) for a plate with a layout"
                )
            self.points[name] = P
        for name, m in self.markers.items():
            s.frame(m.frame)
            if m.position is not None and len(m.position) != 3:
                raise ValueError(f"marker {name!r}: position must have 3 entries")
        for name, Y in list(self.marker_points.items()):
            if name not in self.markers:
                raise ValueError(
                    f"marker_points[{name!r}]: no such marker (markers: {sorted(self.markers)})"
                )
            Y = np.asarray(Y, dtype=float)
            if Y.shape != (N, 3):
                raise ValueError(f"marker_points[{name!r}] must have shape ({N}, 3), got {Y.shape}")
            self.marker_points[name] = Y

    # ---- queries -------------------------------------------------------------------------------

    @property
    def n_records(self) -> int:
        return int(self.q.shape[0])

    def __len__(self) -> int:
        return self.n_records

    @property
    def frames(self) -> list[str]:
        """Frames with at least one measured pose, in the structure's frame order."""
        return [
            f
            for f in self.structure.frame_names
            if f in self.poses and bool(self.has_pose(f).any())
        ]

    def has_pose(self, frame: str) -> NDArray[np.bool_]:
        """Which records measured ``frame``: boolean array of shape (N,)."""
        self.structure.frame(frame)  # UnknownNameError for a typo
        if frame not in self.poses:
            return np.zeros(self.n_records, dtype=bool)
        return np.all(np.isfinite(self.poses[frame]), axis=(1, 2))

    @property
    def has_points(self) -> bool:
        """True when the set holds marker points (position-only data)."""
        return any(bool(self.has_marker(m).any()) for m in self.marker_points)

    def has_marker(self, marker: str) -> NDArray[np.bool_]:
        """Which records saw ``marker``: boolean array of shape (N,)."""
        if marker not in self.marker_points:
            return np.zeros(self.n_records, dtype=bool)
        return np.all(np.isfinite(self.marker_points[marker]), axis=1)

    @property
    def marker_frames(self) -> list[str]:
        """Frames carrying a marker seen at least once, in the structure's frame order."""
        used = {self.markers[m].frame for m in self.marker_points if self.has_marker(m).any()}
        return [f for f in self.structure.frame_names if f in used]

    def markers_on(self, frame: str) -> list[str]:
        """Names of the markers on ``frame`` seen at least once."""
        return [
            m
            for m in self.marker_points
            if self.markers[m].frame == frame and self.has_marker(m).any()
        ]

    def subset(self, index: ArrayLike) -> MeasurementSet:
        """The records selected by ``index`` (integer indices or a boolean mask of shape (N,))."""
        idx = np.arange(self.n_records)[np.asarray(index)]
        return MeasurementSet(
            self.structure,
            self.q[idx],
            {k: v[idx] for k, v in self.poses.items()},
            self.source,
            self.robot,
            [self.labels[int(i)] for i in idx],
            {k: v[idx] for k, v in self.points.items()},
            {k: v[idx] for k, v in self.fit_rms.items()},
            dict(self.metadata),
            self.spec,
            dict(self.markers),
            {k: v[idx] for k, v in self.marker_points.items()},
        )

    @classmethod
    def from_arrays(
        cls,
        structure: RobotStructure,
        q: ArrayLike,
        poses: Mapping[str, ArrayLike],
        *,
        robot: str | None = None,
        labels: Sequence[str] | None = None,
        metadata: Mapping[str, Any] | None = None,
        source: str = "<memory>",
        markers: Mapping[str, Marker] | None = None,
        marker_points: Mapping[str, ArrayLike] | None = None,
    ) -> MeasurementSet:
        """Build a set from arrays (copies them). ``q``: (N, n); each pose array: (N, 4, 4);
        each marker's points: (N, 3) [m] in world."""
        return cls(
            structure,
            np.array(q, dtype=float),
            {k: np.array(v, dtype=float) for k, v in poses.items()},
            source,
            robot,
            list(labels or []),
            metadata=dict(metadata or {}),
            markers=dict(markers or {}),
            marker_points={k: np.array(v, dtype=float) for k, v in (marker_points or {}).items()},
        )


# ---- reading ------------------------------------------------------------------------------------


def _resolve_robot(ref: Any, base_dir: Path | None) -> RobotSpec:
    if not isinstance(ref, str) or not ref:
        raise ValueError(f"'robot' must be a shipped robot name or a robot file path, got {ref!r}")
    return load_robot(ref, relative_to=base_dir)


def measurements_from_json(
    doc: Any,
    source: str = "<measurements>",
    *,
    robot: RobotSpec | None = None,
    base_dir: str | os.PathLike[str] | None = None,
) -> MeasurementSet:
    """Parse a ``cpc2urdf/measurements@1`` or ``@2`` (with markers) document.

    Args:
        doc: The parsed JSON document.
        source: Name used in error messages (the file path).
        robot: Use this robot instead of resolving the document's ``robot`` field.
        base_dir: Folder against which a relative robot path is tried first (default: the
            folder of ``source`` if it is a file path).

    Raises:
        InputFileError: Naming ``source``, the record index and the field: wrong format tag,
            unknown/missing joints, unknown frames, a record without poses or points, a
            non-orthonormal matrix, NaN, unknown units, degenerate circle points, a marker on a
            link the robot does not have.
    """
    try:
        tag = doc.get("format") if isinstance(doc, Mapping) else None
        if isinstance(doc, Mapping) and tag not in MEASUREMENTS_FORMATS:
            raise InputFileError(
                source,
                f"format is {tag!r}, expected {MEASUREMENTS_FORMAT!r} (poses) or "
                f"{MEASUREMENTS_FORMAT_2!r} (with markers)",
            )
        d = require_format(
            doc,
            MEASUREMENTS_FORMAT_2 if tag == MEASUREMENTS_FORMAT_2 else MEASUREMENTS_FORMAT,
            source,
        )
        version = 2 if tag == MEASUREMENTS_FORMAT_2 else 1
        allowed = {"format", "robot", "units", "records", *OPTIONAL_SECTIONS} | (
            {"markers"} if version == 2 else set()
        )
        unknown = set(d) - allowed
        if unknown:
            raise ValueError(f"unknown keys {sorted(unknown)}; expected some of {sorted(allowed)}")
        units = Units.from_json(d.get("units"))
        if "noise" in d:
            _check_noise(d["noise"])
        if robot is None:
            if "robot" not in d:
                raise ValueError(
                    "lacks 'robot' (a shipped robot name or a robot spec/model file path)"
                )
            if base_dir is None and source and not source.startswith("<"):
                base_dir = Path(source).parent
            robot = _resolve_robot(d["robot"], Path(base_dir) if base_dir is not None else None)
        ref = d.get("robot") if isinstance(d.get("robot"), str) else robot.source
        records = d.get("records")
        if not isinstance(records, list) or not records:
            raise ValueError("'records' must be a non-empty list of records")
        marker_defs = _marker_links(d.get("markers", {})) if version == 2 else {}
        if isinstance(robot, UrdfRobot):
            robot = robot.restricted(_measured_links(records, robot, marker_defs))
        ms = _parse_records(
            records,
            robot.structure,
            units,
            source,
            ref,
            d,
            _FileNames.of(robot),
            version,
            marker_defs,
        )
        ms.spec = robot
        return ms
    except InputFileError as e:
        if e.path == str(source):
            raise
        # An error in the referenced robot file: say which measurement file pointed at it.
        raise InputFileError(source, f"robot {d.get('robot')!r}: {e}") from e
    except (ValueError, Cpc2UrdfError) as e:
        raise InputFileError(source, str(e)) from e


@dataclass(frozen=True)
class _FileNames:
    """How a file names the joints and frames of a structure (the URDF's names for a URDF robot).

    Attributes:
        joints: Model joint -> name in the file.
        frames: Model frame -> name in the file.
        ignored: Joint names a record may give that the model does not have (a URDF's other joints).
        subtree: True when the structure is the measured sub-tree of a URDF.
    """

    joints: Mapping[str, str]
    frames: Mapping[str, str]
    ignored: frozenset[str] = frozenset()
    subtree: bool = False

    @classmethod
    def of(cls, robot: RobotSpec | None, s: RobotStructure | None = None) -> _FileNames:
        """The names of ``s`` (default: ``robot``'s structure) in a file about ``robot``."""
        s = s if s is not None else robot.structure if robot is not None else None
        assert s is not None
        if isinstance(robot, UrdfRobot) and robot.names is not None and robot.tree is not None:
            joints = {n: robot.names.urdf_joint(n) for n in s.joint_names}
            return cls(
                joints,
                {n: robot.names.urdf_link(n) for n in s.frame_names},
                frozenset(robot.tree.joints) - set(joints.values()),
                True,
            )
        return cls({n: n for n in s.joint_names}, {n: n for n in s.frame_names})

    def frame(self, name: str) -> str | None:
        """The model frame a file's frame name stands for, or None."""
        return next((m for m, f in self.frames.items() if f == name), None)


# The ``noise`` entries identification trusts (``noise_from_metadata``, ``marker_sigma``): SI units.
NOISE_SIGMAS = {
    "sigma_t_m": "the std of each translation entry [m]",
    "sigma_r_rad": "the std of the rotation error angle [rad]",
    "sigma_p_m": "the std of each marker point coordinate [m]",
}


def _check_noise(section: Any) -> None:
    """A stated noise is a positive number in SI units: a wrong one would silently turn the
    covariance and the consistency gate into "noise unknown".

    Raises:
        ValueError: Naming ``noise.<key>`` and what is expected.
    """
    if not isinstance(section, Mapping):
        raise ValueError(
            f'noise must be an object such as {{"sigma_t_m": 0.0005, "sigma_r_rad": 0.0087}}, '
            f"got {section!r}"
        )
    for key, meaning in NOISE_SIGMAS.items():
        if key not in section:
            continue
        v = section[key]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not (np.isfinite(v) and v > 0):
            raise ValueError(f"noise.{key}: expected a positive number, {meaning}, got {v!r}")


def _marker_links(section: Any) -> dict[str, Mapping[str, Any]]:
    """The ``markers`` section's entries, checked for shape (links are checked against the robot later)."""
    if not isinstance(section, Mapping) or not section:
        raise ValueError(
            '\'markers\' must be a non-empty object {marker name: {"link": ..., "position"?: [x, y, z]}}'
        )
    out: dict[str, Mapping[str, Any]] = {}
    for name, m in section.items():
        if not isinstance(m, Mapping) or not isinstance(m.get("link"), str):
            raise ValueError(
                f"markers.{name} must be an object with a 'link' (the link the marker is fixed to)"
            )
        extra = set(m) - _MARKER_KEYS
        if extra:
            raise ValueError(
                f"markers.{name} has unknown keys {sorted(extra)}; expected some of {sorted(_MARKER_KEYS)}"
            )
        out[str(name)] = m
    return out


def _measured_links(
    records: list[Any], robot: UrdfRobot, markers: Mapping[str, Mapping[str, Any]] | None = None
) -> list[str]:
    """The URDF links the records measure (``poses`` and ``points`` keys, and the links of the
    markers), in order of appearance.

    Raises:
        ValueError: A key or a marker's link that is not a link of the URDF, naming it.
    """
    assert robot.tree is not None
    links: list[str] = []
    for name, m in (markers or {}).items():
        if not robot.tree.has_link(m["link"]):
            raise ValueError(
                f"markers.{name}.link: {m['link']!r} is not a link of {robot.tree.source}"
            )
        links.append(m["link"])
    for i, rec in enumerate(records):
        for key in ("poses", "points"):
            named = rec.get(key) if isinstance(rec, Mapping) else None
            for name in named if isinstance(named, Mapping) else ():
                if not robot.tree.has_link(name):
                    raise ValueError(
                        f"records[{i}].{key}: {name!r} is not a link of {robot.tree.source} "
                        "(measured frames are URDF link names)"
                    )
                links.append(name)
    return list(dict.fromkeys(links))


def _parse_records(
    records: list[Any],
    s: RobotStructure,
    units: Units,
    source: str,
    robot_ref: str | None,
    doc: Mapping[str, Any],
    names: _FileNames | None = None,
    version: int = 1,
    marker_defs: Mapping[str, Mapping[str, Any]] | None = None,
) -> MeasurementSet:
    names = names or _FileNames.of(None, s)
    markers: dict[str, Marker] = {}
    for mname, m in (marker_defs or {}).items():
        frame = _known_frame(s, names, m["link"], f"markers.{mname}.link").name
        pos = m.get("position")
        if pos is not None:
            if not isinstance(pos, list) or len(pos) != 3:
                raise ValueError(
                    f"markers.{mname}.position must be [x, y, z] (file units, in the link's frame), got {pos!r}"
                )
            pos = tuple(
                finite_float(v, f"markers.{mname}.position[{c}]") * units.length
                for c, v in enumerate(pos)
            )
        markers[mname] = Marker(mname, frame, pos)
    record_keys = _RECORD_KEYS_2 if version == 2 else _RECORD_KEYS

    N, n = len(records), s.n_joints
    q = np.empty((N, n))
    labels: list[str] = []
    poses: dict[str, NDArray[np.float64]] = {}
    points: dict[str, NDArray[np.float64]] = {}
    marker_points: dict[str, NDArray[np.float64]] = {}

    def slot(
        store: dict[str, NDArray[np.float64]], name: str, shape: tuple[int, ...]
    ) -> NDArray[np.float64]:
        if name not in store:
            store[name] = np.full((N, *shape), np.nan)
        return store[name]

    file_joints = [names.joints[n] for n in s.joint_names]
    for i, rec in enumerate(records):
        where = f"records[{i}]"
        if not isinstance(rec, Mapping):
            raise ValueError(f"{where} must be an object with 'joints' and 'poses' and/or 'points'")
        extra = set(rec) - record_keys
        if extra:
            raise ValueError(
                f"{where} has unknown keys {sorted(extra)}; expected some of {sorted(record_keys)}"
            )
        label = rec.get("label", f"record {i}")
        if not isinstance(label, str):
            raise ValueError(f"{where}.label must be a string, got {label!r}")
        labels.append(label)
        q[i] = _record_joints(rec.get("joints"), where, s, names, file_joints, units)
        rec_poses = rec.get("poses", {})
        rec_points = rec.get("points", {})
        if not isinstance(rec_poses, Mapping):
            raise ValueError(f"{where}.poses must be an object {{frame name: pose}}")
        if not isinstance(rec_points, Mapping):
            raise ValueError(f"{where}.points must be an object {{plate name: [[x, y, z], ...]}}")
        rec_markers = rec.get("markers", {})
        if not isinstance(rec_markers, Mapping):
            raise ValueError(
                f"{where}.markers must be an object {{marker name: [x, y, z] or null}}"
            )
        if not rec_poses and not rec_points and not rec_markers:
            what = (
                "no 'poses', 'points' or 'markers'"
                if version == 2
                else "no 'poses' and no 'points'"
            )
            raise ValueError(f"{where} has {what}: a record must measure at least one frame")
        for key, y in rec_markers.items():
            if key not in markers:
                raise ValueError(
                    f"{where}.markers: unknown marker {key!r}; the 'markers' section names "
                    f"{', '.join(markers) or 'none'}"
                )
            if y is None:
                continue
            if not isinstance(y, list) or len(y) != 3:
                raise ValueError(f"{where}.markers.{key} must be [x, y, z] or null, got {y!r}")
            slot(marker_points, key, (3,))[i] = [
                finite_float(v, f"{where}.markers.{key}[{c}]") * units.length
                for c, v in enumerate(y)
            ]
        for key, obj in rec_poses.items():
            name = _known_frame(s, names, key, f"{where}.poses").name
            slot(poses, name, (4, 4))[i] = pose_from_json(obj, units, f"{where}.poses.{key}")
        for key, pts in rec_points.items():
            frame = _known_frame(s, names, key, f"{where}.points")
            name = frame.name
            if frame.layout is None:
                raise ValueError(
                    f"{where}.points.{key}: frame {key!r} has no circle 'layout' in the robot spec, "
                    "so its pose cannot be estimated from points"
                )
            K = len(frame.layout)
            if not isinstance(pts, list) or len(pts) != K:
                raise ValueError(
                    f"{where}.points.{key} must list {K} points [x, y, z] (null for an unseen circle), "
                    f"one per layout circle"
                )
            P = slot(points, name, (K, 3))
            for k, p in enumerate(pts):
                if p is None:
                    continue
                if not isinstance(p, list) or len(p) != 3:
                    raise ValueError(
                        f"{where}.points.{key}[{k}] must be [x, y, z] or null, got {p!r}"
                    )
                P[i, k] = [
                    finite_float(v, f"{where}.points.{key}[{k}][{c}]") * units.length
                    for c, v in enumerate(p)
                ]
    # Poses from points (sec. 3.3) where the record did not give the pose itself.
    fit_rms: dict[str, NDArray[np.float64]] = {}
    for name, P in points.items():
        layout = np.array(s.frame(name).layout)
        have = np.any(np.isfinite(P[..., 0]), axis=1)
        T = slot(poses, name, (4, 4))
        rms = np.full(N, np.nan)
        for i in np.flatnonzero(have).tolist():
            if not np.all(np.isfinite(T[i])):
                T[i] = plate_pose_from_points(
                    layout, P[i], what=f"records[{i}].points.{names.frames[name]}"
                )
            rms[i] = registration_rms(T[i], layout, P[i])
        fit_rms[name] = rms
    metadata = {k: doc[k] for k in OPTIONAL_SECTIONS if k in doc}
    return MeasurementSet(
        s,
        q,
        poses,
        source,
        robot_ref,
        labels,
        points,
        fit_rms,
        metadata,
        markers=markers,
        marker_points=marker_points,
    )


def _record_joints(
    joints: Any,
    where: str,
    s: RobotStructure,
    names: _FileNames,
    file_joints: list[str],
    units: Units,
) -> list[float]:
    """A record's joint readings in model order and SI units, checked against the joints and
    limits; ``file_joints``: the model's joints as the file names them."""
    if not isinstance(joints, Mapping):
        raise ValueError(f"{where}.joints must be an object {{joint name: reading}}")
    for name in joints:
        if name not in file_joints and name not in names.ignored:
            raise ValueError(
                f"{where}.joints: unknown joint {name!r}; robot {s.name!r} has {', '.join(file_joints)}"
            )
    missing = [j for j in file_joints if j not in joints]
    if missing:
        need = (
            "every joint on the paths from the root to the measured links"
            if names.subtree
            else "every joint"
        )
        raise ValueError(f"{where}.joints lacks {missing} ({need} needs a reading)")
    row: list[float] = []
    for j in s.joints:
        key = names.joints[j.name]
        v = finite_float(joints[key], f"{where}.joints.{key}") * units.joint_scale(j.type)
        if not (j.lower - 1e-9 <= v <= j.upper + 1e-9):
            unit = units.length_name if j.type == "prismatic" else units.angle_name
            scale = units.joint_scale(j.type)
            raise ValueError(
                f"{where}.joints.{key} = {joints[key]} {unit} is outside the joint limits "
                f"[{j.lower / scale:.6g}, {j.upper / scale:.6g}] {unit} (wrong units?)"
            )
        row.append(v)
    return row


def _known_frame(s: RobotStructure, names: _FileNames, key: str, where: str) -> Any:
    try:
        return s.frame(names.frame(key) or key)
    except UnknownNameError:
        raise ValueError(
            f"{where}: unknown frame {key!r}; robot {s.name!r} has {', '.join(names.frames.values())}"
        ) from None


def load_measurements(
    path: str | os.PathLike[str], *, robot: RobotSpec | None = None
) -> MeasurementSet:
    """Read a measurement file (see the module docstring and ``docs/measurements.md``).

    Args:
        path: The ``cpc2urdf/measurements@1`` JSON file.
        robot: Use this robot instead of the file's ``robot`` reference.

    Raises:
        InputFileError: Naming the file, the record index and the field.
    """
    return measurements_from_json(read_json(path), str(path), robot=robot)


# ---- writing ------------------------------------------------------------------------------------


def measurements_to_json(ms: MeasurementSet, *, robot: str | None = None) -> dict[str, Any]:
    """The set as a ``cpc2urdf/measurements@1`` document in SI units (full precision), or ``@2``
    when it has markers; for a set of a URDF robot (``ms.spec``), with the URDF's joint and link names.

    Args:
        ms: The measurements.
        robot: Robot reference to write (default ``ms.robot``).

    Raises:
        ValueError: No robot reference to write.
    """
    ref = robot or ms.robot
    if not ref:
        raise ValueError(
            "the measurement set has no robot reference (pass robot='iis_head' or a spec path)"
        )
    s = ms.structure
    names = _FileNames.of(ms.spec, s)
    records = []
    for i in range(ms.n_records):
        joints = {names.joints[n]: v for n, v in s.q_to_dict(ms.q[i]).items()}
        rec: dict[str, Any] = {"label": ms.labels[i], "joints": joints}
        poses = {
            names.frames[f]: pose_to_json(ms.poses[f][i])
            for f in s.frame_names
            if f in ms.poses and ms.has_pose(f)[i]
        }
        if poses:
            rec["poses"] = poses
        pts = {}
        for f in s.frame_names:
            if f in ms.points and np.any(np.isfinite(ms.points[f][i])):
                pts[names.frames[f]] = [
                    None if not np.all(np.isfinite(p)) else [float(v) for v in p]
                    for p in ms.points[f][i]
                ]
        if pts:
            rec["points"] = pts
        seen = {
            m: [float(v) for v in Y[i]] for m, Y in ms.marker_points.items() if ms.has_marker(m)[i]
        }
        if seen:
            rec["markers"] = seen
        records.append(rec)
    version_2 = bool(ms.markers)
    doc: dict[str, Any] = {
        "format": MEASUREMENTS_FORMAT_2 if version_2 else MEASUREMENTS_FORMAT,
        "robot": ref,
        "units": {"length": "m", "angle": "rad"},
    }
    for k in OPTIONAL_SECTIONS:
        if k in ms.metadata:
            doc[k] = ms.metadata[k]
    if version_2:
        doc["markers"] = {
            m.name: {
                "link": names.frames[m.frame],
                **({"position": [float(v) for v in m.position]} if m.position is not None else {}),
            }
            for m in ms.markers.values()
        }
    doc["records"] = records
    return doc


def save_measurements(
    ms: MeasurementSet, path: str | os.PathLike[str], *, robot: str | None = None
) -> Path:
    """Write ``ms`` atomically as a measurement file (SI units; poses as matrices).

    Args:
        ms: The measurements.
        path: Output file.
        robot: Robot reference to write (default ``ms.robot``); a relative path is resolved
            against the measurement file's folder when read back.
    """
    try:
        doc = measurements_to_json(ms, robot=robot)
    except ValueError as e:
        from cpc2urdf.errors import OutputError

        raise OutputError(f"{path}: {e}") from e
    return write_json(path, doc)


__all__ = [
    "MEASUREMENTS_FORMAT",
    "MEASUREMENTS_FORMATS",
    "MEASUREMENTS_FORMAT_2",
    "UNKNOWN_MOUNTS",
    "Marker",
    "MeasurementSet",
    "load_measurements",
    "measurements_from_json",
    "measurements_to_json",
    "save_measurements",
]
