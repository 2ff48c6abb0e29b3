"""Pose topics of a bag: which topic carries which frame's pose, and reading them as ``T_world_<frame>``.

A measured frame's pose comes as ``geometry_msgs/PoseStamped``, ``geometry_msgs/TransformStamped``
or one transform of a ``tf2_msgs/TFMessage`` (named ``PARENT:CHILD``). Every pose must be
expressed in one frame (the measuring world), or, for a camera's target poses, each camera's in
one frame. A non-finite pose (the instrument lost the frame) is left out and listed. ROS messages
are SI (m, rad; REP-103). See ``docs/bags.md``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cpc2urdf.errors import ConfigurationError, InputFileError
from cpc2urdf.files.poses import pose_from_json
from cpc2urdf.files.spec import RobotSpec
from cpc2urdf.files.units import Units
from cpc2urdf.identification.vision.bags.bag_reader import (
    NS,
    POSE_TYPES,
    Message,
    read_bag,
    stamp_ns,
    strip_frame_id,
)
from cpc2urdf.identification.vision.bags.bag_sync import (
    BagSamples,
    SyncRule,
    group_messages,
    pair_samples,
    stamp_label,
)
from cpc2urdf.urdf.robot import UrdfRobot

Array = NDArray[np.float64]


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
        if (
            not sep
            or not frame
            or not parts[0]
            or len(parts) not in (1, 3)
            or (len(parts) == 3 and not all(parts))
        ):
            raise ConfigurationError(
                f"--pose expects FRAME=TOPIC or FRAME=TOPIC:PARENT:CHILD (a tf topic), got {text!r}"
            )
        return (
            cls(frame, parts[0], *(strip_frame_id(p) for p in parts[1:]))
            if len(parts) == 3
            else cls(frame, parts[0])
        )

    def describe(self) -> str:
        return f"{self.topic} ({self.parent} -> {self.child})" if self.parent else self.topic


def check_frames(robot: RobotSpec, frames: Sequence[str]) -> None:
    for f in frames:
        if isinstance(robot, UrdfRobot) and robot.tree is not None:
            if not robot.tree.has_link(f):
                raise ConfigurationError(f"--pose {f}: not a link of {robot.tree.source}")
        elif f not in robot.structure.frame_names:
            raise ConfigurationError(
                f"--pose {f}: unknown frame; robot {robot.structure.name!r} has "
                f"{', '.join(robot.structure.frame_names)}"
            )


def pose_reader(
    sources: Sequence[PoseTopic], bag: Path, shared_world: bool = True
) -> tuple[Any, Any, list[str]]:
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
        seen.setdefault(strip_frame_id(frame_id), where)
        if len(seen) > 1:
            (a, wa), (b, wb) = list(seen.items())[:2]
            which = (
                "every pose must be expressed in the one measuring world"
                if shared_world
                else f"every pose of {key} must be expressed in one frame"
            )
            raise InputFileError(
                bag, f"poses in different frames: {wa} is in {a!r}, {wb} in {b!r}; {which}"
            )

    def T_from(pos: Any, rot: Any, where: str) -> Array | None:
        values = [pos.x, pos.y, pos.z, rot.x, rot.y, rot.z, rot.w]
        if not np.all(np.isfinite(np.array(values, dtype=float))):
            lost.append(f"{where}: pose is not finite (the instrument lost the frame?)")
            return None
        try:
            return pose_from_json(
                {
                    "xyz": [float(pos.x), float(pos.y), float(pos.z)],
                    "quat_xyzw": [float(rot.x), float(rot.y), float(rot.z), float(rot.w)],
                },
                Units(),
                where,
            )
        except ValueError as e:
            raise InputFileError(bag, str(e)) from e

    def read_one(
        topic: str, msgtype: str, msg: Any, t_bag: int, where: str
    ) -> list[tuple[int | None, str, Array]]:
        out: list[tuple[int | None, str, Array]] = []
        if msgtype == "tf2_msgs/TFMessage":
            bare = [s.frame for s in by_topic[topic] if s.parent is None]
            if bare:
                raise InputFileError(
                    bag,
                    f"topic {topic} is {msgtype}: say which transform is {bare[0]} with "
                    f"--pose {bare[0]}={topic}:PARENT:CHILD",
                )
            for k, tr in enumerate(msg.transforms):
                parent, child = (
                    strip_frame_id(tr.header.frame_id),
                    strip_frame_id(tr.child_frame_id),
                )
                tf_seen.setdefault(topic, set()).add(f"{parent} -> {child}")
                for s in by_topic[topic]:
                    if (parent, child) == (s.parent, s.child):
                        t, stamped = stamp_ns(tr.header, t_bag)
                        T = T_from(
                            tr.transform.translation,
                            tr.transform.rotation,
                            f"{where}.transforms[{k}]",
                        )
                        if T is not None:
                            out.append((t if stamped else None, s.frame, T))
            return out
        if msgtype == "geometry_msgs/TransformStamped":
            pos, rot = msg.transform.translation, msg.transform.rotation
        else:
            pos, rot = msg.pose.position, msg.pose.orientation
        targets = by_topic[topic]
        if targets[0].parent is not None:
            raise InputFileError(
                bag, f"topic {topic} is {msgtype}: PARENT:CHILD applies to tf topics only"
            )
        if len(targets) > 1:
            raise InputFileError(
                bag,
                f"topic {topic} is {msgtype}, the pose of one frame, but --pose gives it for "
                f"{' and '.join(s.frame for s in targets)}",
            )
        t, stamped = stamp_ns(msg.header, t_bag)
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
                raise InputFileError(
                    bag,
                    f"topic {s.topic} has no transform {s.parent} -> {s.child} (for "
                    f"{s.frame}); it has {have}",
                )
            world(s.parent, f"{s.topic} ({s.parent} -> {s.child})", s.frame)

    return read_one, check_tf, lost


def pose_samples(
    bag: Path,
    topics: Sequence[PoseTopic],
    what: str,
    joint_topic: str,
    joints: Sequence[str],
    kinds: dict[str, str],
    rule: SyncRule,
    *,
    shared_world: bool = True,
) -> tuple[BagSamples, list[list[Message]], list[int]]:
    """Read pose topics and joint states and pair them into samples (:mod:`bag_sync`).

    Args:
        bag: The bag.
        topics: The pose topics (:func:`pose_reader`, with ``shared_world``).
        what: What a topic holds, with ``{frame}`` for its frame (``"poses of {frame}"``), for messages.
        joint_topic: The joint states topic.
        joints: The joint names to read; ``kinds`` their types.
        rule: Sync and rest rule.

    Returns:
        ``(samples, groups, kept)``: the kept samples (skip lines include the lost poses), all
        message groups, and the indices in ``groups`` of the kept ones.

    Raises:
        InputFileError: As :func:`read_bag` and :func:`pair_samples`; every sample skipped.
    """
    read_one, check_tf, lost = pose_reader(topics, bag, shared_world=shared_world)
    sources = {t.topic: (what.format(frame=t.frame), POSE_TYPES) for t in topics}
    series, messages, n_bag_time = read_bag(bag, joint_topic, joints, sources, read_one)
    check_tf()
    groups = group_messages(messages, int(round(rule.sync_tolerance * NS)))
    stamps, q, skipped, kept = pair_samples(bag, groups, series, kinds, rule, joint_topic)
    skipped = lost + skipped
    if not kept:
        raise InputFileError(
            bag,
            f"no sample with the joints at rest ({len(groups)} samples skipped; first: "
            f"{skipped[0] if skipped else 'none'})",
        )
    samples = BagSamples(
        stamps,
        [stamp_label(t) for t in stamps],
        q,
        list(joints),
        skipped,
        n_bag_time,
        len(messages),
    )
    return samples, groups, kept


__all__ = ["PoseTopic", "check_frames", "pose_reader", "pose_samples"]
