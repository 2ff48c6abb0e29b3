"""ROS bags as a measurement source: joint states plus poses or images, paired by time stamps.

A ROS user records the robot's ``sensor_msgs/JointState`` (``/joint_states``) together with what
the measuring instrument publishes: poses of the measured frames (``geometry_msgs/PoseStamped``,
``geometry_msgs/TransformStamped`` or a transform of a ``tf2_msgs/TFMessage``, e.g. a motion
capture system or a tracker driver), or images of the plates (``sensor_msgs/Image``,
``sensor_msgs/CompressedImage``). This module reads such a bag (rosbag1 ``.bag`` or a rosbag2
folder, with the ``rosbags`` package, no ROS install) and writes what the rest of the toolkit
reads:

- poses -> a ``cpc2urdf/measurements@1`` set (:func:`measurements_from_bag`), the poses being
  ``T_world_<frame>`` with ``world`` = the frame the messages are expressed in;
- poses of the stage-2 target in the head's cameras (a marker detector's output) -> the
  pairs of joint readings and ``T_camera_target`` from which the hand-eye pose files are written
  (:func:`target_poses_from_bag`, as ``cpc2urdf measure --stage2`` does from images);
- images -> an images folder (``<camera>/<record>.png`` plus ``joints.csv``) that
  ``cpc2urdf measure`` reads (:func:`image_folder_from_bag`).

**Time.** Every message is placed at its header stamp; a message whose stamp is zero (the
publisher did not fill it) is placed at the time the bag recorded it, and the number of such
messages is reported (:attr:`BagSamples.bag_time_messages`). Measurement messages (poses of
different frames, or images of different cameras) whose stamps lie within ``sync_tolerance`` of
the first of them form one **sample** (a frame or camera seen twice starts a new sample).

**Pairing and rest.** A sample's stamp is the mean of its messages' stamps. For each joint the
reading nearest to it is used; it must be within ``sync_tolerance``, else the bag is refused
(naming the sample, the joint and the gap). The joints must be at rest around the sample: every
reading of each joint within ``rest_window`` of the stamp must agree with the one used within
``rest_tolerance_m`` (prismatic) / ``rest_tolerance_rad`` (revolute), and there must be readings
strictly before and strictly after the stamp inside the window; otherwise the sample is skipped
and listed. ``rest_window = 0`` turns the rest check off (one reading per configuration).

**Units.** ROS messages are SI (m, rad; REP-103); so are our files as written here.
See ``docs/bags.md``.
"""

from __future__ import annotations

import os
import re
import shutil
import tempfile
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from cpc2urdf.errors import ConfigurationError, InputFileError, OutputError
from cpc2urdf.fileio import write_json
from cpc2urdf.identification.vision.image_folders import write_image
from cpc2urdf.identification.vision.joints_csv import write_joints_csv
from cpc2urdf.identification.vision.measure_head import HeadImageMeasurement
from cpc2urdf.measurements import MeasurementSet, measurements_from_json
from cpc2urdf.model import CPCModel
from cpc2urdf.poses import pose_from_json, pose_to_json
from cpc2urdf.spec import RobotSpec
from cpc2urdf.units import Units
from cpc2urdf.urdf_robot import UrdfRobot, urdf_source

Array = NDArray[np.float64]

JOINT_STATES_TOPIC = "/joint_states"
SYNC_TOLERANCE = 0.02  # [s]: a measurement's nearest joint reading, and the messages of one sample, this close
REST_WINDOW = 0.1  # [s]: joint readings this close to a sample must show the joint at rest
REST_TOLERANCE_M = 1e-5  # [m]: a prismatic joint at rest varies less than this over the rest window
REST_TOLERANCE_RAD = 1.7453292519943296e-4  # [rad] (0.01 deg): same for a revolute joint

BAG_PROVENANCE = "bag_provenance.json"  # in an images folder: the bag, topics, rule and skipped samples
_NS = 1_000_000_000
_POSE_TYPES = ("geometry_msgs/PoseStamped", "geometry_msgs/TransformStamped", "tf2_msgs/TFMessage")
_IMAGE_TYPES = ("sensor_msgs/Image", "sensor_msgs/CompressedImage")
_JOINT_STATE_TYPE = "sensor_msgs/JointState"


# ---- what to read ------------------------------------------------------------------------------


@dataclass(frozen=True)
class PoseTopic:
    """Where a measured frame's pose is in the bag.

    Attributes:
        frame: The robot frame (a spec frame, or a URDF link) whose ``T_world_<frame>`` it is.
        topic: A ``PoseStamped``, ``TransformStamped`` or ``TFMessage`` topic.
        parent: For a ``TFMessage`` topic: the transform's parent frame id (the measuring world).
        child: For a ``TFMessage`` topic: the transform's child frame id.
    """

    frame: str
    topic: str
    parent: str | None = None
    child: str | None = None

    @classmethod
    def parse(cls, text: str) -> PoseTopic:
        """``FRAME=TOPIC`` or, for a TF topic, ``FRAME=TOPIC:PARENT:CHILD`` (ROS names have no ':')."""
        frame, sep, rest = text.partition("=")
        parts = rest.split(":")
        if not sep or not frame or not parts[0] or len(parts) not in (1, 3) or (len(parts) == 3 and not all(parts)):
            raise ConfigurationError(f"--pose expects FRAME=TOPIC or FRAME=TOPIC:PARENT:CHILD (a tf topic), got {text!r}")
        return cls(frame, parts[0], *(_frame_id(p) for p in parts[1:])) if len(parts) == 3 else cls(frame, parts[0])

    def describe(self) -> str:
        return f"{self.topic} ({self.parent} -> {self.child})" if self.parent else self.topic


@dataclass(frozen=True)
class ImageTopic:
    """Where a camera's images are in the bag: ``camera`` names the sub-folder (``left``,
    ``right``, or a head camera frame such as ``camera_left_optical``)."""

    camera: str
    topic: str

    @classmethod
    def parse(cls, text: str) -> ImageTopic:
        """``CAMERA=TOPIC``."""
        camera, sep, topic = text.partition("=")
        if not sep or not camera or not topic or "/" in camera or camera in (".", ".."):
            raise ConfigurationError(f"--image expects CAMERA=TOPIC (CAMERA a folder name: left, right or a "
                                     f"camera frame), got {text!r}")
        return cls(camera, topic)


@dataclass(frozen=True)
class SyncRule:
    """How measurements are paired with joint readings (module docstring).

    Attributes:
        sync_tolerance: [s] the largest gap between a sample and each joint's nearest reading,
            and between the messages of one sample.
        rest_window: [s] readings this close to a sample must agree (0: no rest check).
        rest_tolerance_m: [m] agreement of a prismatic joint's readings.
        rest_tolerance_rad: [rad] agreement of a revolute joint's readings.
    """

    sync_tolerance: float = SYNC_TOLERANCE
    rest_window: float = REST_WINDOW
    rest_tolerance_m: float = REST_TOLERANCE_M
    rest_tolerance_rad: float = REST_TOLERANCE_RAD

    def __post_init__(self) -> None:
        for name in ("sync_tolerance", "rest_window", "rest_tolerance_m", "rest_tolerance_rad"):
            v = getattr(self, name)
            if not np.isfinite(v) or v < 0 or (name == "sync_tolerance" and v == 0):
                raise ConfigurationError(f"{name} must be a finite number >= 0 (> 0 for sync_tolerance), got {v!r}")


# ---- what comes out ----------------------------------------------------------------------------


@dataclass
class BagSamples:
    """Samples of a bag paired with joint readings.

    Attributes:
        stamps_ns: Each kept sample's stamp [ns since the epoch], shape (N,).
        labels: One label per kept sample (``t=<sec>.<nsec>``).
        q: Joint readings [m]/[rad], shape (N, n), in the order of ``joints``.
        joints: The joint names (as ``/joint_states`` names them).
        skipped: One line per sample left out (joints moving, a camera missing), naming it and why.
        bag_time_messages: How many messages had no header stamp and were placed at the bag's time.
        n_messages: Measurement messages read (poses or images).
    """

    stamps_ns: list[int]
    labels: list[str]
    q: Array
    joints: list[str]
    skipped: list[str] = field(default_factory=list)
    bag_time_messages: int = 0
    n_messages: int = 0


@dataclass
class BagMeasurements:
    """What :func:`measurements_from_bag` returns: the set, and how it was paired."""

    measurements: MeasurementSet
    samples: BagSamples


@dataclass
class BagTargets:
    """What :func:`target_poses_from_bag` returns: per camera, the readings and target poses
    (``reprojection_rms`` is NaN: a bag carries no image points), and how they were paired."""

    measurement: HeadImageMeasurement
    samples: BagSamples


@dataclass
class BagImages:
    """What :func:`image_folder_from_bag` wrote: the folder, its records, and how they were paired."""

    folder: Path
    records: list[str]
    samples: BagSamples


# ---- reading a bag -----------------------------------------------------------------------------


def _frame_id(name: str) -> str:
    """A tf frame id without the leading '/' ROS 1 allowed."""
    return name.lstrip("/")


def _short_type(msgtype: str) -> str:
    """``sensor_msgs/msg/JointState`` (rosbag2) and ``sensor_msgs/JointState`` (rosbag1) -> the latter."""
    return msgtype.replace("/msg/", "/")


@contextmanager
def _open_bag(bag: Path) -> Iterator[Any]:
    try:
        from rosbags.highlevel import AnyReader, AnyReaderError
        from rosbags.typesys import Stores, get_typestore
    except ModuleNotFoundError as e:  # the `ros` extra
        raise ModuleNotFoundError("reading ROS bags requires rosbags: pip install cpc2urdf[ros]") from e
    if not bag.exists():
        raise InputFileError(bag, "no such bag (expected a rosbag1 .bag file or a rosbag2 folder)")
    if bag.is_dir() and not (bag / "metadata.yaml").is_file():
        raise InputFileError(bag, "a folder without metadata.yaml is not a rosbag2 bag")
    # Bags that do not embed their message definitions (old rosbag2) are read with ROS 2's.
    try:
        reader = AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_HUMBLE))
        reader.open()
    except (AnyReaderError, OSError, ValueError, KeyError) as e:
        why = str(e).splitlines()[0] if str(e) else type(e).__name__
        raise InputFileError(bag, f"not a readable ROS bag (expected a rosbag1 .bag file or a rosbag2 folder): {why}") from e
    try:
        yield reader
    finally:
        reader.close()


def _check_topic(reader: Any, bag: Path, topic: str, types: Sequence[str], what: str) -> None:
    """Refuse a topic the bag lacks (naming the topics it has) or of the wrong message type."""
    topics: Mapping[str, Any] = reader.topics
    if topic not in topics:
        have = ", ".join(f"{t} ({_short_type(i.msgtype or '?')})" for t, i in sorted(topics.items())) or "none"
        raise InputFileError(bag, f"no topic {topic!r} ({what}); the bag has {have}")
    msgtype = _short_type(topics[topic].msgtype or "?")
    if msgtype not in types:
        raise InputFileError(bag, f"topic {topic} is {msgtype}, expected {' or '.join(types)} ({what})")


def _stamp_ns(header: Any, bag_time_ns: int) -> tuple[int, bool]:
    """The header stamp [ns], or the bag's record time when the stamp is zero (unset); and
    whether the header's stamp was used."""
    st = header.stamp
    ns = int(st.sec) * _NS + int(getattr(st, "nanosec", getattr(st, "nsec", 0)))
    return (ns, True) if ns != 0 else (int(bag_time_ns), False)


@dataclass
class _Series:
    """One joint's readings: stamps [ns] and values [m]/[rad], sorted by stamp."""

    t: NDArray[np.int64]
    v: Array


@dataclass
class _Message:
    t: int  # [ns]
    key: str  # frame or camera
    value: Any  # (4, 4) pose, or None (an image, read again when it is written)
    topic: str
    index: int  # the message's index on its topic

    @property
    def where(self) -> str:
        return f"{self.topic} message {self.index}"


def _read(
    bag: Path, joint_topic: str, joints: Sequence[str], sources: Mapping[str, tuple[str, Sequence[str]]],
    read_one: Any,
) -> tuple[dict[str, _Series], list[_Message], int]:
    """Read the joint states and the measurement messages.

    ``sources`` maps each measurement topic to (what it is for, accepted types); ``read_one(topic,
    msgtype, msg, t_bag, index)`` turns one message into ``[(stamp or None, key, value)]``.
    """
    with _open_bag(bag) as reader:
        _check_topic(reader, bag, joint_topic, (_JOINT_STATE_TYPE,), "joint readings")
        for topic, (what, types) in sources.items():
            _check_topic(reader, bag, topic, types, what)
        wanted = {joint_topic, *sources}
        conns = [c for c in reader.connections if c.topic in wanted]
        series: dict[str, list[tuple[int, float]]] = {}
        messages: list[_Message] = []
        counts: dict[str, int] = {}
        n_bag_time = 0
        for conn, t_bag, raw in reader.messages(connections=conns):
            k = counts.get(conn.topic, 0)
            counts[conn.topic] = k + 1
            where = f"{conn.topic} message {k}"
            try:
                msg = reader.deserialize(raw, conn.msgtype)
            except Exception as e:  # a corrupt record: rosbags raises several types
                raise InputFileError(bag, f"{where}: cannot be decoded ({e})") from e
            if conn.topic == joint_topic:
                t, stamped = _stamp_ns(msg.header, t_bag)
                n_bag_time += not stamped
                pos = np.asarray(msg.position, dtype=float)
                if len(pos) == 0:  # an effort-only publisher: no readings
                    continue
                if len(pos) != len(msg.name):
                    raise InputFileError(bag, f"{where}: {len(msg.name)} joint names but {len(pos)} positions")
                for name, value in zip(msg.name, pos.tolist(), strict=True):
                    if np.isfinite(value):  # NaN: the driver has no reading of that joint now
                        series.setdefault(str(name), []).append((t, value))
            if conn.topic in sources:
                for stamp, key, value in read_one(conn.topic, _short_type(conn.msgtype), msg, t_bag, where):
                    n_bag_time += stamp is None
                    messages.append(_Message(t_bag if stamp is None else stamp, key, value, conn.topic, k))
    missing = [j for j in joints if j not in series]
    if missing:
        have = ", ".join(sorted(series)) or "no positions"
        raise InputFileError(bag, f"{joint_topic} has no reading of joint {missing[0]!r} (the robot needs "
                                  f"{', '.join(joints)}); its messages name {have}")
    out = {}
    for j in joints:
        arr = sorted(series[j])
        out[j] = _Series(np.array([a for a, _ in arr], dtype=np.int64), np.array([b for _, b in arr]))
    return out, messages, n_bag_time


def _group(messages: list[_Message], tol_ns: int) -> list[list[_Message]]:
    """Messages within ``tol_ns`` of a sample's first message form that sample; a key seen
    twice starts a new sample."""
    groups: list[list[_Message]] = []
    for m in sorted(messages, key=lambda m: (m.t, m.key)):
        g = groups[-1] if groups else None
        if g is None or m.t - g[0].t > tol_ns or any(x.key == m.key for x in g):
            groups.append([m])
        else:
            g.append(m)
    return groups


def _label(t_ns: int) -> str:
    return f"t={t_ns // _NS}.{t_ns % _NS:09d}"


def _pair(
    bag: Path, groups: list[list[_Message]], series: Mapping[str, _Series], kinds: Mapping[str, str],
    rule: SyncRule, joint_topic: str,
) -> tuple[list[int], Array, list[str], list[int]]:
    """Joint readings of each sample (nearest reading, rest check); returns kept stamps, q, skip
    lines and the kept groups' indices.

    Raises:
        InputFileError: A sample with no reading of some joint within the sync tolerance.
    """
    tol = int(round(rule.sync_tolerance * _NS))
    window = int(round(rule.rest_window * _NS))
    stamps, rows, skipped, kept = [], [], [], []
    for gi, g in enumerate(groups):
        t = sum(m.t for m in g) // len(g)  # integer ns: a float would lose them
        what = f"sample {gi} ({_label(t)}: {', '.join(m.where for m in g)})"
        q, why = [], ""
        for j, s in series.items():
            i = int(np.searchsorted(s.t, t))
            near = min((k for k in (i - 1, i) if 0 <= k < len(s.t)), key=lambda k: abs(int(s.t[k]) - t))
            gap = abs(int(s.t[near]) - t)
            if gap > tol:
                raise InputFileError(bag, f"{what}: no {joint_topic} reading of {j} within the sync tolerance "
                                          f"{rule.sync_tolerance:g} s (nearest {gap / _NS:.6g} s away); "
                                          "unsynchronised clocks or a gap in the recording?")
            q.append(float(s.v[near]))
            if window > 0 and not why:
                inside = (s.t >= t - window) & (s.t <= t + window)
                if not (np.any(inside & (s.t < t)) and np.any(inside & (s.t > t))):
                    why = (f"{j} has no reading both before and after it within the rest window "
                           f"{rule.rest_window:g} s, so rest cannot be checked")
                else:
                    spread = float(np.max(np.abs(s.v[inside] - s.v[near])))
                    limit = rule.rest_tolerance_m if kinds[j] == "prismatic" else rule.rest_tolerance_rad
                    if spread > limit:
                        unit, scale = ("mm", 1e3) if kinds[j] == "prismatic" else ("deg", 180 / np.pi)
                        why = (f"{j} moved {spread * scale:.4g} {unit} within {rule.rest_window:g} s "
                               f"(rest tolerance {limit * scale:.4g} {unit})")
        if why:
            skipped.append(f"{what}: joints not at rest: {why}")
            continue
        stamps.append(t)
        rows.append(q)
        kept.append(gi)
    return stamps, np.array(rows, dtype=float).reshape(len(rows), len(series)), skipped, kept


def _joint_names(robot: RobotSpec | CPCModel, frames: Sequence[str]) -> tuple[list[str], dict[str, str], dict[str, str]]:
    """The ``/joint_states`` names the robot needs (a URDF: the joints on the paths to ``frames``;
    a model made from a URDF: the URDF's names of its joints), their types, and the model name of each."""
    if isinstance(robot, UrdfRobot) and robot.names is not None:
        r = robot.restricted(frames) if frames else robot
        assert r.names is not None
        names = {r.names.urdf_joint(n): n for n in r.structure.joint_names}
        s = r.structure
    elif isinstance(robot, CPCModel):
        s = robot.structure
        src = urdf_source(robot)
        names = {(src.joints.get(n, n) if src is not None else n): n for n in s.joint_names}
    else:
        s = robot.structure
        names = {n: n for n in s.joint_names}
    kinds = {f: s.joint(m).type for f, m in names.items()}
    return list(names), kinds, names


def _check_frames(robot: RobotSpec, frames: Sequence[str]) -> None:
    for f in frames:
        if isinstance(robot, UrdfRobot) and robot.tree is not None:
            if not robot.tree.has_link(f):
                raise ConfigurationError(f"--pose {f}: not a link of {robot.tree.source}")
        elif f not in robot.structure.frame_names:
            raise ConfigurationError(f"--pose {f}: unknown frame; robot {robot.structure.name!r} has "
                                     f"{', '.join(robot.structure.frame_names)}")


# ---- poses -------------------------------------------------------------------------------------


def _pose_reader(sources: Sequence[PoseTopic], bag: Path, shared_world: bool = True) -> tuple[Any, Any, list[str]]:
    """``read_one`` for pose topics (each message -> [(stamp, frame, T_world_frame)]), checking
    that every pose is expressed in the same frame (the measuring world; or, without
    ``shared_world``, that each frame's poses are, e.g. a camera's optical frame); ``check_tf()``,
    to call after reading, which refuses a tf transform the topic never carried; and the list to
    which ``read_one`` adds the messages it leaves out (a non-finite pose: the instrument lost the frame)."""
    by_topic: dict[str, list[PoseTopic]] = {}
    for s in sources:
        by_topic.setdefault(s.topic, []).append(s)
    worlds: dict[str, dict[str, str]] = {}  # group -> world frame id -> first message in it
    tf_seen: dict[str, set[str]] = {}
    lost: list[str] = []

    def world(frame_id: str, where: str, key: str) -> None:
        seen = worlds.setdefault("world" if shared_world else key, {})
        seen.setdefault(_frame_id(frame_id), where)
        if len(seen) > 1:
            (a, wa), (b, wb) = list(seen.items())[:2]
            which = "every pose must be expressed in the one measuring world" if shared_world else \
                f"every pose of {key} must be expressed in one frame"
            raise InputFileError(bag, f"poses in different frames: {wa} is in {a!r}, {wb} in {b!r}; {which}")

    def T_from(pos: Any, rot: Any, where: str) -> Array | None:
        values = [pos.x, pos.y, pos.z, rot.x, rot.y, rot.z, rot.w]
        if not np.all(np.isfinite(np.array(values, dtype=float))):
            lost.append(f"{where}: pose is not finite (the instrument lost the frame?)")
            return None
        try:
            return pose_from_json({"xyz": [float(pos.x), float(pos.y), float(pos.z)],
                                   "quat_xyzw": [float(rot.x), float(rot.y), float(rot.z), float(rot.w)]},
                                  Units(), where)
        except ValueError as e:
            raise InputFileError(bag, str(e)) from e

    def read_one(topic: str, msgtype: str, msg: Any, t_bag: int, where: str) -> list[tuple[int | None, str, Array]]:
        out: list[tuple[int | None, str, Array]] = []
        if msgtype == "tf2_msgs/TFMessage":
            bare = [s.frame for s in by_topic[topic] if s.parent is None]
            if bare:
                raise InputFileError(bag, f"topic {topic} is {msgtype}: say which transform is {bare[0]} with "
                                          f"--pose {bare[0]}={topic}:PARENT:CHILD")
            for k, tr in enumerate(msg.transforms):
                parent, child = _frame_id(tr.header.frame_id), _frame_id(tr.child_frame_id)
                tf_seen.setdefault(topic, set()).add(f"{parent} -> {child}")
                for s in by_topic[topic]:
                    if (parent, child) == (s.parent, s.child):
                        t, stamped = _stamp_ns(tr.header, t_bag)
                        T = T_from(tr.transform.translation, tr.transform.rotation, f"{where}.transforms[{k}]")
                        if T is not None:
                            out.append((t if stamped else None, s.frame, T))
            return out
        if msgtype == "geometry_msgs/TransformStamped":
            pos, rot = msg.transform.translation, msg.transform.rotation
        else:
            pos, rot = msg.pose.position, msg.pose.orientation
        targets = by_topic[topic]
        if targets[0].parent is not None:
            raise InputFileError(bag, f"topic {topic} is {msgtype}: PARENT:CHILD applies to tf topics only")
        if len(targets) > 1:
            raise InputFileError(bag, f"topic {topic} is {msgtype}, the pose of one frame, but --pose gives it for "
                                      f"{' and '.join(s.frame for s in targets)}")
        t, stamped = _stamp_ns(msg.header, t_bag)
        world(msg.header.frame_id, where, targets[0].frame)
        T = T_from(pos, rot, where)
        if T is not None:
            out.append((t if stamped else None, targets[0].frame, T))
        return out

    def check_tf() -> None:
        for s in sources:
            if s.parent is None:
                continue
            seen = tf_seen.get(s.topic, set())
            if f"{s.parent} -> {s.child}" not in seen:
                have = ", ".join(sorted(seen)) or "no transforms"
                raise InputFileError(bag, f"topic {s.topic} has no transform {s.parent} -> {s.child} (for "
                                          f"{s.frame}); it has {have}")
            world(s.parent, f"{s.topic} ({s.parent} -> {s.child})", s.frame)

    return read_one, check_tf, lost


def measurements_from_bag(
    bag: str | os.PathLike[str],
    robot: RobotSpec,
    poses: Sequence[PoseTopic],
    *,
    robot_ref: str,
    joint_topic: str = JOINT_STATES_TOPIC,
    rule: SyncRule | None = None,
) -> BagMeasurements:
    """A stage-1 measurement set from a bag's joint states and pose topics.

    Args:
        bag: A rosbag1 ``.bag`` file or a rosbag2 folder.
        robot: The robot (spec, model or URDF): which joints need readings, which frames exist.
        poses: The measured frames and their topics (at least one).
        robot_ref: How the measurement file names the robot.
        joint_topic: The ``sensor_msgs/JointState`` topic.
        rule: Synchronisation and rest rule (default :class:`SyncRule`).

    Returns:
        The set (``T_world_<frame>``, world = the frame the poses are expressed in; one record per
        kept sample; its ``provenance`` states the bag, topics, rule and skipped samples) and the
        pairing.

    Raises:
        InputFileError: Not a bag, a topic missing or of the wrong type, a joint never read, a
            sample without a joint reading within the tolerance, poses in different frames, a
            reading outside the joint limits; every sample skipped.
        ConfigurationError: An unknown frame, the same frame twice.
    """
    rule = rule or SyncRule()
    path = Path(bag)
    if not poses:
        raise ConfigurationError("no pose topic: give at least one --pose FRAME=TOPIC")
    frames = [p.frame for p in poses]
    if len(set(frames)) != len(frames):
        raise ConfigurationError(f"--pose: frame {next(f for f in frames if frames.count(f) > 1)!r} given twice")
    _check_frames(robot, frames)
    joints, kinds, _ = _joint_names(robot, frames)
    read_one, check_tf, lost = _pose_reader(poses, path)
    sources = {p.topic: (f"poses of {p.frame}", _POSE_TYPES) for p in poses}
    series, messages, n_bag_time = _read(path, joint_topic, joints, sources, read_one)
    check_tf()
    groups = _group(messages, int(round(rule.sync_tolerance * _NS)))
    stamps, q, skipped, kept = _pair(path, groups, series, kinds, rule, joint_topic)
    skipped = lost + skipped
    if not kept:
        raise InputFileError(path, f"no sample with the joints at rest ({len(groups)} samples skipped; first: "
                                   f"{skipped[0] if skipped else 'none'})")
    samples = BagSamples(stamps, [_label(t) for t in stamps], q, joints, skipped, n_bag_time, len(messages))
    records = []
    for row, gi, label in zip(q, kept, samples.labels, strict=True):
        records.append({"label": label, "joints": dict(zip(joints, row.tolist(), strict=True)),
                        "poses": {m.key: pose_to_json(m.value) for m in groups[gi]}})
    doc = {"format": "cpc2urdf/measurements@1", "robot": robot_ref, "units": {"length": "m", "angle": "rad"},
           "provenance": _provenance(path, joint_topic, rule, samples,
                                     {p.frame: p.describe() for p in poses}, "poses"),
           "records": records}
    try:
        ms = measurements_from_json(doc, str(path), robot=robot)
    except InputFileError as e:  # name the sample, not the index of a record the bag does not have
        problem = re.sub(r"records\[(\d+)\]\.?", lambda m: f"sample {samples.labels[int(m.group(1))]}: ", e.problem)
        raise InputFileError(path, problem) from e
    ms.robot = robot_ref
    return BagMeasurements(ms, samples)


def _provenance(bag: Path, joint_topic: str, rule: SyncRule, samples: BagSamples, topics: Mapping[str, str],
                kind: str) -> dict[str, Any]:
    return {"source": "ros bag", "bag": str(bag), "joint_states": joint_topic, kind: dict(topics),
            "sync_tolerance_s": rule.sync_tolerance, "rest_window_s": rule.rest_window,
            "rest_tolerance_m": rule.rest_tolerance_m, "rest_tolerance_rad": rule.rest_tolerance_rad,
            "messages": samples.n_messages, "messages_at_bag_time": samples.bag_time_messages,
            "skipped": list(samples.skipped)}


def target_poses_from_bag(
    bag: str | os.PathLike[str],
    model: CPCModel,
    targets: Sequence[PoseTopic],
    *,
    joint_topic: str = JOINT_STATES_TOPIC,
    rule: SyncRule | None = None,
) -> BagTargets:
    """Stage-2 pairs from a bag: per camera, the target's pose ``T_camera_target`` (a marker
    detector's output, in the camera's optical frame) with the joint readings at that moment.

    ``targets`` maps each camera frame of the model (``PoseTopic.frame``, e.g.
    ``camera_left_optical``) to its topic. The cameras need not be synchronised: a sample holds
    the cameras whose messages fall within the sync tolerance, and each camera's records are the
    samples it is in. The joints are ``model``'s (a model made from a URDF: the URDF's names).

    Raises:
        InputFileError: As :func:`measurements_from_bag`; a camera's poses in two frames.
        ConfigurationError: No target topic, a camera twice.
    """
    rule = rule or SyncRule()
    path = Path(bag)
    if not targets:
        raise ConfigurationError("no target topic: give at least one --target CAMERA=TOPIC")
    cams = [t.frame for t in targets]
    if len(set(cams)) != len(cams):
        raise ConfigurationError(f"--target: camera {next(c for c in cams if cams.count(c) > 1)!r} given twice")
    joints, kinds, names = _joint_names(model, [])
    read_one, check_tf, lost = _pose_reader(targets, path, shared_world=False)
    sources = {t.topic: (f"target poses in {t.frame}", _POSE_TYPES) for t in targets}
    series, messages, n_bag_time = _read(path, joint_topic, joints, sources, read_one)
    check_tf()
    groups = _group(messages, int(round(rule.sync_tolerance * _NS)))
    stamps, q, skipped, kept = _pair(path, groups, series, kinds, rule, joint_topic)
    skipped = lost + skipped
    if not kept:
        raise InputFileError(path, f"no sample with the joints at rest ({len(groups)} samples skipped; first: "
                                   f"{skipped[0] if skipped else 'none'})")
    samples = BagSamples(stamps, [_label(t) for t in stamps], q, joints, skipped, n_bag_time, len(messages))
    order = [joints.index(next(f for f, m in names.items() if m == n)) for n in model.structure.joint_names]
    labels: dict[str, list[str]] = {c: [] for c in cams}
    rows: dict[str, list[Array]] = {c: [] for c in cams}
    poses: dict[str, list[Array]] = {c: [] for c in cams}
    for k, gi in enumerate(kept):
        for m in groups[gi]:
            labels[m.key].append(samples.labels[k])
            rows[m.key].append(q[k, order])
            poses[m.key].append(m.value)
    unseen = [c for c in cams if not labels[c]]
    if unseen:
        raise InputFileError(path, f"no usable target pose of {unseen[0]} (every sample with it was skipped)")
    n = model.structure.n_joints
    meas = HeadImageMeasurement(labels, {c: np.array(rows[c]).reshape(-1, n) for c in cams},
                                {c: np.array(poses[c]) for c in cams}, {c: np.full(len(labels[c]), np.nan) for c in cams},
                                list(skipped))
    return BagTargets(meas, samples)


# ---- images ------------------------------------------------------------------------------------

# sensor_msgs/Image encodings we write losslessly: (channels, dtype, cv2 conversion to BGR or None).
_ENCODINGS: dict[str, tuple[int, Any, int | None]] = {
    "mono8": (1, np.uint8, None), "8UC1": (1, np.uint8, None),
    "mono16": (1, np.uint16, None), "16UC1": (1, np.uint16, None),
    "bgr8": (3, np.uint8, None), "8UC3": (3, np.uint8, None),
    "rgb8": (3, np.uint8, cv2.COLOR_RGB2BGR),
    "bgra8": (4, np.uint8, None), "rgba8": (4, np.uint8, cv2.COLOR_RGBA2BGRA),
}
_COMPRESSED = {"png": ".png", "jpeg": ".jpg", "jpg": ".jpg", "tiff": ".tif", "bmp": ".bmp"}


def _image_from_msg(msg: Any, where: str, bag: Path) -> NDArray[Any]:
    """A ``sensor_msgs/Image`` as an array OpenCV writes (grey, BGR or BGRA)."""
    enc = str(msg.encoding)
    if enc not in _ENCODINGS:
        raise InputFileError(bag, f"{where}: image encoding {enc!r} is not supported; expected one of "
                                  f"{', '.join(_ENCODINGS)}")
    ch, dtype, conv = _ENCODINGS[enc]
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    item = np.dtype(dtype).itemsize
    data = np.asarray(msg.data, dtype=np.uint8)
    if h <= 0 or w <= 0 or step < w * ch * item or data.size < h * step:
        raise InputFileError(bag, f"{where}: {data.size} bytes do not hold a {w} x {h} {enc} image with step {step}")
    rows = data[: h * step].reshape(h, step)[:, : w * ch * item]
    img = rows.copy().view(np.dtype(dtype).newbyteorder(">" if msg.is_bigendian else "<")).astype(dtype)
    img = img.reshape(h, w, ch) if ch > 1 else img.reshape(h, w)
    if conv is not None:
        img = cv2.cvtColor(img, conv)
    return img


def _compressed_suffix(msg: Any, where: str, bag: Path) -> str:
    # The format field is e.g. "png", "jpeg", or "bgr8; jpeg compressed bgr8" (image_transport).
    fmt = str(msg.format).lower()
    for key, suffix in _COMPRESSED.items():
        if key in fmt:
            return suffix
    raise InputFileError(bag, f"{where}: compressed format {msg.format!r} is not one of {', '.join(_COMPRESSED)}")


@contextmanager
def _new_folder(out: Path) -> Iterator[Path]:
    """A temporary folder next to ``out`` renamed to ``out`` on success, removed on failure."""
    if out.exists() and not (out.is_dir() and not any(out.iterdir())):
        raise OutputError(f"{out}: already exists; give a new (or empty) folder")
    parent = out.parent if str(out.parent) else Path(".")
    if not parent.is_dir():
        raise OutputError(f"{out}: parent folder {parent} does not exist")
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=parent))
    try:
        yield tmp
        if out.exists():
            out.rmdir()
        os.replace(tmp, out)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)


def image_folder_from_bag(
    bag: str | os.PathLike[str],
    robot: RobotSpec,
    images: Sequence[ImageTopic],
    out: str | os.PathLike[str],
    *,
    joint_topic: str = JOINT_STATES_TOPIC,
    rule: SyncRule | None = None,
) -> BagImages:
    """Write an images folder (``out/<camera>/<record>.<ext>`` and ``out/joints.csv``, SI units;
    ``out/bag_provenance.json``: the bag, topics, rule and skipped samples) from a bag's image
    topics and joint states; ``cpc2urdf measure`` reads it (``docs/images.md``).

    A sample needs an image of every camera; one without is skipped and listed. Raw images are
    written as PNG (lossless), compressed ones as the bytes the bag holds. The folder appears only
    when everything was written (nothing is left behind on an error).

    Raises:
        InputFileError: As :func:`measurements_from_bag`, plus an unsupported image encoding.
        OutputError: ``out`` exists and is not an empty folder, or its parent is missing.
    """
    rule = rule or SyncRule()
    path, out_p = Path(bag), Path(out)
    if not images:
        raise ConfigurationError("no image topic: give at least one --image CAMERA=TOPIC")
    cams = [c.camera for c in images]
    if len(set(cams)) != len(cams):
        raise ConfigurationError(f"--image: camera {next(c for c in cams if cams.count(c) > 1)!r} given twice")
    topics = [c.topic for c in images]
    if len(set(topics)) != len(topics):
        raise ConfigurationError(f"--image: topic {next(t for t in topics if topics.count(t) > 1)!r} given for two cameras")
    if out_p.exists() and not (out_p.is_dir() and not any(out_p.iterdir())):
        raise OutputError(f"{out_p}: already exists; give a new (or empty) folder")
    joints, kinds, model_names = _joint_names(robot, [])
    by_topic: dict[str, list[str]] = {}
    for c in images:
        by_topic.setdefault(c.topic, []).append(c.camera)

    def read_one(topic: str, msgtype: str, msg: Any, t_bag: int, where: str) -> list[tuple[int | None, str, Any]]:
        # Only the stamp now: the images are read again when they are written (a bag's images
        # need not fit in memory).
        t, stamped = _stamp_ns(msg.header, t_bag)
        return [(t if stamped else None, cam, None) for cam in by_topic[topic]]

    sources = {c.topic: (f"images of {c.camera}", _IMAGE_TYPES) for c in images}
    series, messages, n_bag_time = _read(path, joint_topic, joints, sources, read_one)
    groups = _group(messages, int(round(rule.sync_tolerance * _NS)))
    incomplete = []
    complete = []
    for gi, g in enumerate(groups):
        missing = [c for c in cams if c not in {m.key for m in g}]
        if missing:
            incomplete.append(f"sample {gi} ({_label(g[0].t)}: {', '.join(m.where for m in g)}): no image of "
                              f"{', '.join(missing)} within {rule.sync_tolerance:g} s")
        else:
            complete.append(g)
    stamps, q, skipped, kept = _pair(path, complete, series, kinds, rule, joint_topic)
    skipped = incomplete + skipped
    if not kept:
        raise InputFileError(path, f"no sample with every camera's image and the joints at rest ({len(groups)} "
                                   f"samples skipped; first: {skipped[0] if skipped else 'none'})")
    samples = BagSamples(stamps, [_label(t) for t in stamps], q, joints, skipped, n_bag_time, len(messages))
    records = [f"{k:04d}" for k in range(len(kept))]
    s = robot.structure
    order = [joints.index(next(f for f, m in model_names.items() if m == n)) for n in s.joint_names]
    for k, j in enumerate(s.joints):  # what `cpc2urdf measure` would refuse, refused before writing
        bad = np.flatnonzero((q[:, order[k]] < j.lower - 1e-9) | (q[:, order[k]] > j.upper + 1e-9))
        if bad.size:
            i = int(bad[0])
            raise InputFileError(path, f"{samples.labels[i]}: {joints[order[k]]} = {q[i, order[k]]:.6g} is outside "
                                       f"the joint limits [{j.lower:.6g}, {j.upper:.6g}] (m or rad)")
    wanted = {(m.topic, m.index): (m.key, rec) for rec, gi in zip(records, kept, strict=True) for m in complete[gi]}
    with _new_folder(out_p) as tmp:
        for cam in cams:
            (tmp / cam).mkdir()
        with _open_bag(path) as reader:
            counts: dict[str, int] = {}
            for conn, _, raw in reader.messages(connections=[c for c in reader.connections if c.topic in by_topic]):
                k = counts.get(conn.topic, 0)
                counts[conn.topic] = k + 1
                if (conn.topic, k) not in wanted:
                    continue
                where = f"{conn.topic} message {k}"
                msg = reader.deserialize(raw, conn.msgtype)
                cam, rec = wanted[(conn.topic, k)]
                if _short_type(conn.msgtype) == "sensor_msgs/CompressedImage":
                    data = np.asarray(msg.data, dtype=np.uint8)
                    suffix = _compressed_suffix(msg, where, path)
                    if data.size == 0 or cv2.imdecode(data, cv2.IMREAD_UNCHANGED) is None:
                        raise InputFileError(path, f"{where}: the compressed image ({msg.format}) cannot be decoded")
                    (tmp / cam / f"{rec}{suffix}").write_bytes(data.tobytes())
                else:
                    write_image(tmp / cam / f"{rec}.png", _image_from_msg(msg, where, path))
        write_joints_csv(tmp / "joints.csv", s, records, q[:, order], samples.labels, length="m", angle="rad")
        write_json(tmp / BAG_PROVENANCE, _provenance(path, joint_topic, rule, samples,
                                                     {c.camera: c.topic for c in images}, "images"))
    return BagImages(out_p, records, samples)


__all__ = [
    "BAG_PROVENANCE",
    "JOINT_STATES_TOPIC",
    "REST_TOLERANCE_M",
    "REST_TOLERANCE_RAD",
    "REST_WINDOW",
    "SYNC_TOLERANCE",
    "BagImages",
    "BagMeasurements",
    "BagSamples",
    "BagTargets",
    "ImageTopic",
    "PoseTopic",
    "SyncRule",
    "image_folder_from_bag",
    "measurements_from_bag",
    "target_poses_from_bag",
]
