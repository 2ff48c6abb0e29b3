"""``cpc2urdf bag BAG ...``: measurement files from a ROS bag (``docs/bags.md``).

Poses of measured frames (stage 1 measurement file)::

    cpc2urdf bag BAG --robot iis_head --pose plate_left=/mocap/plate_left \\
        --pose plate_right=/tf:world:plate_right -o measurements.json

Stage-2 target poses in the head's cameras (a marker detector's output) -> hand-eye pose files,
with ``T_base_hand`` from the identified model (as ``cpc2urdf measure --stage2``)::

    cpc2urdf bag BAG --model identified.json --target camera_left_optical=/left/target_pose -o OUT_DIR

Images (the folder ``cpc2urdf measure`` reads)::

    cpc2urdf bag BAG --robot iis_head --image left=/rig/left/image_raw \\
        --image right=/rig/right/image_raw -o IMAGES_DIR
"""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from cpc2urdf.identification.vision.bags.bag_source import SyncRule

# The library's defaults (identification/vision/bags/bag_sync.py, bag_reader.py), repeated so that `--help` does not load
# numpy and OpenCV; tests/test_bags.py checks that they agree.
JOINT_STATES_TOPIC = "/joint_states"
SYNC_TOLERANCE = 0.02  # [s]
REST_WINDOW = 0.1  # [s]
REST_TOLERANCE_MM = 0.01  # [mm]
REST_TOLERANCE_DEG = 0.01  # [deg]


def add_parser(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = subparsers.add_parser(
        "bag",
        help="measurement file (poses), hand-eye pose files or images folder from a ROS bag",
        description="Read sensor_msgs/JointState and either pose topics (PoseStamped, TransformStamped, "
        "tf2_msgs/TFMessage) -> a cpc2urdf/measurements@1 file (--pose) or hand-eye pose files (--target), "
        "or image topics (Image, CompressedImage) -> an images folder for `cpc2urdf measure`. Each measurement is paired with the nearest joint "
        "reading (header stamps; a zero stamp uses the bag's record time) and kept only if the joints "
        "were at rest around it. See docs/bags.md.",
    )
    p.add_argument("bag", metavar="BAG", help="rosbag1 .bag file or rosbag2 folder")
    p.add_argument(
        "-o",
        "--output",
        required=True,
        help="measurement file (--pose), folder for the hand-eye pose files (--target) or new images "
        "folder (--image)",
    )
    p.add_argument(
        "--robot",
        default="iis_head",
        help="shipped robot name, spec, model or URDF file (default iis_head)",
    )
    p.add_argument(
        "--pose",
        action="append",
        default=[],
        metavar="FRAME=TOPIC[:PARENT:CHILD]",
        help="a measured frame and its pose topic; for a tf topic name the transform PARENT:CHILD",
    )
    p.add_argument(
        "--target",
        action="append",
        default=[],
        metavar="CAMERA=TOPIC[:PARENT:CHILD]",
        help="a head camera frame and the topic of the stage-2 target's pose in it (needs --model)",
    )
    p.add_argument("--model", help="identified model file: gives T_base_hand for --target")
    p.add_argument(
        "--image",
        action="append",
        default=[],
        metavar="CAMERA=TOPIC",
        help="a camera folder (left, right, or a head camera frame) and its image topic",
    )
    p.add_argument(
        "--joint-states",
        default=JOINT_STATES_TOPIC,
        metavar="TOPIC",
        help=f"sensor_msgs/JointState topic (default {JOINT_STATES_TOPIC})",
    )
    p.add_argument(
        "--sync-tolerance",
        type=float,
        default=SYNC_TOLERANCE,
        metavar="S",
        help=f"largest gap [s] between a measurement and each joint's nearest reading, and between "
        f"the messages of one sample (default {SYNC_TOLERANCE:g})",
    )
    p.add_argument(
        "--rest-window",
        type=float,
        default=REST_WINDOW,
        metavar="S",
        help=f"joint readings within this many seconds of a measurement must agree (default "
        f"{REST_WINDOW:g}; 0: no rest check)",
    )
    p.add_argument(
        "--rest-tolerance-mm",
        type=float,
        default=REST_TOLERANCE_MM,
        metavar="MM",
        help=f"agreement of a prismatic joint's readings (default {REST_TOLERANCE_MM:g} mm)",
    )
    p.add_argument(
        "--rest-tolerance-deg",
        type=float,
        default=REST_TOLERANCE_DEG,
        metavar="DEG",
        help=f"agreement of a revolute joint's readings (default {REST_TOLERANCE_DEG:g} deg)",
    )
    p.set_defaults(run=run)


def _report(skipped: list[str], in_output: bool, limit: int = 20) -> None:
    """List the skipped samples on stderr (all of them when the output does not keep the list)."""
    limit = limit if in_output else len(skipped)
    for line in skipped[:limit]:
        print(f"  skipped: {line}", file=sys.stderr)
    if len(skipped) > limit:
        print(
            f"  ... and {len(skipped) - limit} more (all listed in the output's provenance)",
            file=sys.stderr,
        )


def run(args: argparse.Namespace) -> int:
    import math

    from cpc2urdf.errors import ConfigurationError
    from cpc2urdf.files.jsonio import check_output_path
    from cpc2urdf.files.measurements import save_measurements
    from cpc2urdf.files.robot_ref import load_robot
    from cpc2urdf.identification.vision.bags.bag_source import (
        ImageTopic,
        PoseTopic,
        SyncRule,
        image_folder_from_bag,
        measurements_from_bag,
    )

    if sum(map(bool, (args.pose, args.target, args.image))) != 1:
        raise ConfigurationError(
            "give --pose FRAME=TOPIC (a measurement file), --target CAMERA=TOPIC (hand-eye pose "
            "files) or --image CAMERA=TOPIC (an images folder): one of the three, not both or none"
        )
    if args.model and not args.target:
        raise ConfigurationError(
            "--model is for --target (it gives T_base_hand); with --pose/--image use --robot"
        )
    rule = SyncRule(
        args.sync_tolerance,
        args.rest_window,
        args.rest_tolerance_mm * 1e-3,
        math.radians(args.rest_tolerance_deg),
    )
    if args.target:
        return _run_targets(args, rule)
    robot = load_robot(args.robot)
    if args.pose:
        poses = [PoseTopic.parse(t) for t in args.pose]
        check_output_path(args.output)
        res = measurements_from_bag(
            args.bag, robot, poses, robot_ref=args.robot, joint_topic=args.joint_states, rule=rule
        )
        path = save_measurements(res.measurements, args.output)
        what, s = f"{res.measurements.n_records} records", res.samples
    else:
        images = [ImageTopic.parse(t) for t in args.image]
        out = image_folder_from_bag(
            args.bag, robot, images, args.output, joint_topic=args.joint_states, rule=rule
        )
        path, what, s = (
            out.folder,
            f"{len(out.records)} records of {', '.join(i.camera for i in images)}",
            out.samples,
        )
    print(
        f"wrote {path}: {what} from {s.n_messages} messages"
        + (
            f"; {s.bag_time_messages} messages without header stamp placed at the bag's time"
            if s.bag_time_messages
            else ""
        )
        + (f"; skipped {len(s.skipped)} (see stderr)" if s.skipped else "")
    )
    _report(s.skipped, in_output=True)
    return 0


def _run_targets(args: argparse.Namespace, rule: SyncRule) -> int:
    from pathlib import Path

    from cpc2urdf.errors import ConfigurationError, OutputError
    from cpc2urdf.files.robot_ref import load_model
    from cpc2urdf.identification.handeye.head_images import write_handeye_files
    from cpc2urdf.identification.handeye.stage2 import HAND_OF_CAMERA
    from cpc2urdf.identification.vision.bags.bag_source import PoseTopic, target_poses_from_bag

    if not args.model:
        raise ConfigurationError("--target needs --model identified.json (it gives T_base_hand)")
    model = load_model(args.model)
    targets = [PoseTopic.parse(t) for t in args.target]
    for t in targets:  # write_handeye_files needs each camera's hand frame in the model
        if t.frame not in HAND_OF_CAMERA:
            raise ConfigurationError(
                f"--target {t.frame}: no hand frame known for this camera; known: "
                f"{', '.join(sorted(HAND_OF_CAMERA))}"
            )
        model.structure.frame(HAND_OF_CAMERA[t.frame])
    out = Path(args.output)
    if out.exists() and not out.is_dir():
        raise OutputError(
            f"{out}: --target writes one file per camera into a folder; this is a file"
        )
    if not out.exists() and not out.parent.is_dir():
        raise OutputError(f"{out}: parent folder {out.parent} does not exist")
    res = target_poses_from_bag(args.bag, model, targets, joint_topic=args.joint_states, rule=rule)
    if not out.exists():
        out.mkdir()
    paths = write_handeye_files(res.measurement, model, out)
    s = res.samples
    for c, p in paths.items():
        print(f"wrote {p}: {len(res.measurement.labels[c])} target poses")
    if s.bag_time_messages:
        print(f"{s.bag_time_messages} messages without header stamp placed at the bag's time")
    if s.skipped:
        print(f"skipped {len(s.skipped)} (see stderr)")
    _report(s.skipped, in_output=False)
    return 0
