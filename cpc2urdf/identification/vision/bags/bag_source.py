"""ROS bags as a measurement source: joint states plus poses or images, paired by time stamps.

A ROS user records the robot's ``sensor_msgs/JointState`` (``/joint_states``) together with what
the measuring instrument publishes: poses of the measured frames (``geometry_msgs/PoseStamped``,
``geometry_msgs/TransformStamped`` or a transform of a ``tf2_msgs/TFMessage``, e.g. a motion
capture system or a tracker driver), or images of the plates (``sensor_msgs/Image``,
``sensor_msgs/CompressedImage``). A bag (rosbag1 ``.bag`` or a rosbag2 folder) becomes what the
rest of the toolkit reads:

- poses -> a ``cpc2urdf/measurements@1`` set (:func:`measurements_from_bag`, here), the poses
  being ``T_world_<frame>`` with ``world`` = the frame the messages are expressed in;
- poses of the stage-2 target in the head's cameras (a marker detector's output) -> the
  pairs of joint readings and ``T_camera_target`` from which the hand-eye pose files are written
  (:func:`target_poses_from_bag`, here, as ``cpc2urdf measure --stage2`` does from images);
- images -> an images folder (``<camera>/<record>.png`` plus ``joints.csv``) that
  ``cpc2urdf measure`` reads (:func:`~cpc2urdf.identification.vision.bags.bag_images.image_folder_from_bag`).

The parts: reading the bag (:mod:`bag_reader`: open, topics, decoding, stamps), pairing
measurements with joint readings (:mod:`bag_sync`: samples, nearest reading, rest rule), pose
topics (:mod:`bag_poses`) and image topics (:mod:`bag_images`). Every reading must lie within its
joint's limits, checked before anything is written. ROS messages are SI (m, rad; REP-103); so are
our files as written here. This module also re-exports the public names of the parts, so
``from cpc2urdf.identification.vision.bags.bag_source import ...`` gives the whole bag API. See ``docs/bags.md``.
"""

from __future__ import annotations

import os
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from cpc2urdf.errors import InputFileError
from cpc2urdf.files.measurements import MeasurementSet, measurements_from_json
from cpc2urdf.files.poses import pose_to_json
from cpc2urdf.files.spec import RobotSpec
from cpc2urdf.identification.vision.bags.bag_images import (
    BAG_PROVENANCE,
    BagImages,
    ImageTopic,
    image_folder_from_bag,
)
from cpc2urdf.identification.vision.bags.bag_poses import PoseTopic, check_frames, pose_samples
from cpc2urdf.identification.vision.bags.bag_reader import JOINT_STATES_TOPIC
from cpc2urdf.identification.vision.bags.bag_sync import (
    REST_TOLERANCE_M,
    REST_TOLERANCE_RAD,
    REST_WINDOW,
    SYNC_TOLERANCE,
    BagSamples,
    SyncRule,
    check_limits,
    check_topic_options,
    joint_names_for,
    provenance,
)
from cpc2urdf.identification.vision.measure_head import HeadImageMeasurement
from cpc2urdf.model import CPCModel

Array = NDArray[np.float64]


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
    frames = [p.frame for p in poses]
    check_topic_options(frames, "--pose", "pose", "frame", "FRAME=TOPIC")
    check_frames(robot, frames)
    joints, kinds, _ = joint_names_for(robot, frames)
    samples, groups, kept = pose_samples(
        path, poses, "poses of {frame}", joint_topic, joints, kinds, rule
    )
    records = []
    for row, gi, label in zip(samples.q, kept, samples.labels, strict=True):
        records.append(
            {
                "label": label,
                "joints": dict(zip(joints, row.tolist(), strict=True)),
                "poses": {m.key: pose_to_json(m.value) for m in groups[gi]},
            }
        )
    doc = {
        "format": "cpc2urdf/measurements@1",
        "robot": robot_ref,
        "units": {"length": "m", "angle": "rad"},
        "provenance": provenance(
            path, joint_topic, rule, samples, {p.frame: p.describe() for p in poses}, "poses"
        ),
        "records": records,
    }
    try:
        ms = measurements_from_json(doc, str(path), robot=robot)
    except InputFileError as e:  # name the sample, not the index of a record the bag does not have
        problem = re.sub(
            r"records\[(\d+)\]\.?",
            lambda m: f"sample {samples.labels[int(m.group(1))]}: ",
            e.problem,
        )
        raise InputFileError(path, problem) from e
    ms.robot = robot_ref
    return BagMeasurements(ms, samples)


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
        InputFileError: As :func:`measurements_from_bag` (a reading outside the joint limits
            included); a camera's poses in two frames.
        ConfigurationError: No target topic, a camera twice.
    """
    rule = rule or SyncRule()
    path = Path(bag)
    cams = [t.frame for t in targets]
    check_topic_options(cams, "--target", "target", "camera", "CAMERA=TOPIC")
    joints, kinds, names = joint_names_for(model, [])
    samples, groups, kept = pose_samples(
        path,
        targets,
        "target poses in {frame}",
        joint_topic,
        joints,
        kinds,
        rule,
        shared_world=False,
    )
    q = samples.q
    order = [
        joints.index(next(f for f, m in names.items() if m == n))
        for n in model.structure.joint_names
    ]
    check_limits(
        path, model.structure, q, order, joints, samples.labels
    )  # as the hand-eye pose files would
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
        raise InputFileError(
            path, f"no usable target pose of {unseen[0]} (every sample with it was skipped)"
        )
    n = model.structure.n_joints
    meas = HeadImageMeasurement(
        labels,
        {c: np.array(rows[c]).reshape(-1, n) for c in cams},
        {c: np.array(poses[c]) for c in cams},
        {c: np.full(len(labels[c]), np.nan) for c in cams},
        list(samples.skipped),
    )
    return BagTargets(meas, samples)


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
