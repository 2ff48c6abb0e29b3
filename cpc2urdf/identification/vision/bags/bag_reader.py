"""Reading a ROS bag: open it, check its topics, decode its messages, place them in time.

A rosbag1 ``.bag`` file or a rosbag2 folder is read with the ``rosbags`` package (no ROS
install). Every message is placed at its header stamp; a message whose stamp is zero (the
publisher did not fill it) is placed at the time the bag recorded it. :func:`read_bag` returns
each joint's readings from ``sensor_msgs/JointState`` and the measurement messages (poses or
images) that the pairing (:mod:`bag_sync`) groups into samples. See ``docs/bags.md``.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cpc2urdf.errors import InputFileError

Array = NDArray[np.float64]

JOINT_STATES_TOPIC = "/joint_states"
NS = 1_000_000_000  # [ns per s]
POSE_TYPES = ("geometry_msgs/PoseStamped", "geometry_msgs/TransformStamped", "tf2_msgs/TFMessage")
IMAGE_TYPES = ("sensor_msgs/Image", "sensor_msgs/CompressedImage")
JOINT_STATE_TYPE = "sensor_msgs/JointState"


def strip_frame_id(name: str) -> str:
    """A tf frame id without the leading '/' ROS 1 allowed."""
    return name.lstrip("/")


def short_type(msgtype: str) -> str:
    """``sensor_msgs/msg/JointState`` (rosbag2) and ``sensor_msgs/JointState`` (rosbag1) -> the latter."""
    return msgtype.replace("/msg/", "/")


@contextmanager
def open_bag(bag: Path) -> Iterator[Any]:
    try:
        from rosbags.highlevel import AnyReader, AnyReaderError
        from rosbags.typesys import Stores, get_typestore
    except ModuleNotFoundError as e:  # the `ros` extra
        raise ModuleNotFoundError(
            "reading ROS bags requires rosbags: pip install cpc2urdf[ros]"
        ) from e
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
        raise InputFileError(
            bag, f"not a readable ROS bag (expected a rosbag1 .bag file or a rosbag2 folder): {why}"
        ) from e
    try:
        yield reader
    finally:
        reader.close()


def check_topic(reader: Any, bag: Path, topic: str, types: Sequence[str], what: str) -> None:
    """Refuse a topic the bag lacks (naming the topics it has) or of the wrong message type."""
    topics: Mapping[str, Any] = reader.topics
    if topic not in topics:
        have = (
            ", ".join(f"{t} ({short_type(i.msgtype or '?')})" for t, i in sorted(topics.items()))
            or "none"
        )
        raise InputFileError(bag, f"no topic {topic!r} ({what}); the bag has {have}")
    msgtype = short_type(topics[topic].msgtype or "?")
    if msgtype not in types:
        raise InputFileError(
            bag, f"topic {topic} is {msgtype}, expected {' or '.join(types)} ({what})"
        )


def stamp_ns(header: Any, bag_time_ns: int) -> tuple[int, bool]:
    """The header stamp [ns], or the bag's record time when the stamp is zero (unset); and
    whether the header's stamp was used."""
    st = header.stamp
    ns = int(st.sec) * NS + int(getattr(st, "nanosec", getattr(st, "nsec", 0)))
    return (ns, True) if ns != 0 else (int(bag_time_ns), False)


@dataclass
class Series:
    """One joint's readings: stamps [ns] and values [m]/[rad], sorted by stamp."""

    t: NDArray[np.int64]
    v: Array


@dataclass
class Message:
    t: int  # [ns]
    key: str  # frame or camera
    value: Any  # (4, 4) pose, or None (an image, read again when it is written)
    topic: str
    index: int  # the message's index on its topic

    @property
    def where(self) -> str:
        return f"{self.topic} message {self.index}"


def read_bag(
    bag: Path,
    joint_topic: str,
    joints: Sequence[str],
    sources: Mapping[str, tuple[str, Sequence[str]]],
    read_one: Any,
) -> tuple[dict[str, Series], list[Message], int]:
    """Read the joint states and the measurement messages.

    ``sources`` maps each measurement topic to (what it is for, accepted types); ``read_one(topic,
    msgtype, msg, t_bag, index)`` turns one message into ``[(stamp or None, key, value)]``.
    """
    with open_bag(bag) as reader:
        check_topic(reader, bag, joint_topic, (JOINT_STATE_TYPE,), "joint readings")
        for topic, (what, types) in sources.items():
            check_topic(reader, bag, topic, types, what)
        wanted = {joint_topic, *sources}
        conns = [c for c in reader.connections if c.topic in wanted]
        series: dict[str, list[tuple[int, float]]] = {}
        messages: list[Message] = []
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
                t, stamped = stamp_ns(msg.header, t_bag)
                n_bag_time += not stamped
                pos = np.asarray(msg.position, dtype=float)
                if len(pos) == 0:  # an effort-only publisher: no readings
                    continue
                if len(pos) != len(msg.name):
                    raise InputFileError(
                        bag, f"{where}: {len(msg.name)} joint names but {len(pos)} positions"
                    )
                for name, value in zip(msg.name, pos.tolist(), strict=True):
                    if np.isfinite(value):  # NaN: the driver has no reading of that joint now
                        series.setdefault(str(name), []).append((t, value))
            if conn.topic in sources:
                for stamp, key, value in read_one(
                    conn.topic, short_type(conn.msgtype), msg, t_bag, where
                ):
                    n_bag_time += stamp is None
                    messages.append(
                        Message(t_bag if stamp is None else stamp, key, value, conn.topic, k)
                    )
    missing = [j for j in joints if j not in series]
    if missing:
        have = ", ".join(sorted(series)) or "no positions"
        raise InputFileError(
            bag,
            f"{joint_topic} has no reading of joint {missing[0]!r} (the robot needs "
            f"{', '.join(joints)}); its messages name {have}",
        )
    out = {}
    for j in joints:
        arr = sorted(series[j])
        out[j] = Series(
            np.array([a for a, _ in arr], dtype=np.int64), np.array([b for _, b in arr])
        )
    return out, messages, n_bag_time


__all__ = [
    "IMAGE_TYPES",
    "JOINT_STATES_TOPIC",
    "JOINT_STATE_TYPE",
    "NS",
    "POSE_TYPES",
    "Message",
    "Series",
    "check_topic",
    "open_bag",
    "read_bag",
    "short_type",
    "stamp_ns",
    "strip_frame_id",
]
