"""ROS bags -> our measurement files (``cpc2urdf bag``), against the direct route.

A small simulated experiment is "recorded": the robot rests at each configuration of the
protocol and moves linearly between them, ``/joint_states`` is published at 100 Hz (in two
messages, as two controllers would), and the instrument publishes the plate poses in the rest
periods (one as ``PoseStamped``, one on ``/tf``) plus one while the robot moves. The bag is
written with ``rosbags`` (rosbag2 and rosbag1), and ``cpc2urdf bag`` must give the same records as
the simulated measurement file written directly, skip the sample taken in motion, and refuse bad
bags with one line and nothing written. The image route writes rendered images into a bag and
checks that the folder it gives measures exactly like the rendered folder itself.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_typestore
from scipy.spatial.transform import Rotation

from cpc2urdf.cli import bag as cli_bag
from cpc2urdf.cli import main
from cpc2urdf.errors import InputFileError
from cpc2urdf.files.measurements import MeasurementSet, load_measurements, save_measurements
from cpc2urdf.files.model_file import save_model
from cpc2urdf.files.robot_ref import load_model, load_robot
from cpc2urdf.identification.handeye import stage2 as s2
from cpc2urdf.identification.handeye.head_images import write_handeye_files
from cpc2urdf.identification.handeye.pose_file import load_handeye_poses
from cpc2urdf.identification.simulation.image_experiment import (
    RenderedExperiment,
    render_experiment,
)
from cpc2urdf.identification.simulation.stage1_experiment import simulate_experiment
from cpc2urdf.identification.vision.bags import bag_images
from cpc2urdf.identification.vision.bags import bag_source as bags
from cpc2urdf.identification.vision.joints_csv import read_joints_csv, write_joints_csv
from cpc2urdf.identification.vision.measure_head import HeadImageMeasurement
from cpc2urdf.identification.vision.measure_stereo import measure_stereo_images

TS = get_typestore(Stores.ROS2_HUMBLE)
T0 = 1_700_000_000 * 10**9  # [ns] the recording's start
SEC = 10**9
DT_JS = 10_000_000  # [ns] joint states at 100 Hz
REST, MOVE = SEC, SEC  # [ns] rest at each configuration, then move to the next
POSE_OFFSET = (
    503_000_000  # [ns] the instrument's sample inside a rest period (between two joint readings)
)
SPEC = load_robot("iis_head")
JOINTS = SPEC.structure.joint_names

Msg = tuple[str, str, int, Any]  # topic, message type, bag time [ns], message


def _header(t_ns: int, frame_id: str = "") -> Any:
    return TS.types["std_msgs/msg/Header"](
        stamp=TS.types["builtin_interfaces/msg/Time"](sec=t_ns // SEC, nanosec=t_ns % SEC),
        frame_id=frame_id,
    )


def _joint_state(t_ns: int, names: list[str], values: list[float]) -> Any:
    return TS.types["sensor_msgs/msg/JointState"](
        header=_header(t_ns),
        name=names,
        position=np.array(values, dtype=float),
        velocity=np.zeros(0),
        effort=np.zeros(0),
    )


def _pose_parts(T: np.ndarray) -> tuple[Any, Any]:
    # a NaN pose is what a tracker publishes when it lost the frame
    x, y, z, w = (
        Rotation.from_matrix(T[:3, :3]).as_quat() if np.all(np.isfinite(T)) else [np.nan] * 4
    )
    return (
        TS.types["geometry_msgs/msg/Point"](x=float(T[0, 3]), y=float(T[1, 3]), z=float(T[2, 3])),
        TS.types["geometry_msgs/msg/Quaternion"](x=float(x), y=float(y), z=float(z), w=float(w)),
    )


def _pose_stamped(t_ns: int, T: np.ndarray, world: str = "rig") -> Any:
    p, o = _pose_parts(T)
    return TS.types["geometry_msgs/msg/PoseStamped"](
        header=_header(t_ns, world),
        pose=TS.types["geometry_msgs/msg/Pose"](position=p, orientation=o),
    )


def _tf(t_ns: int, T: np.ndarray, parent: str, child: str) -> Any:
    p, o = _pose_parts(T)
    tr = TS.types["geometry_msgs/msg/Transform"](
        translation=TS.types["geometry_msgs/msg/Vector3"](x=p.x, y=p.y, z=p.z), rotation=o
    )
    ts = TS.types["geometry_msgs/msg/TransformStamped"](
        header=_header(t_ns, parent), child_frame_id=child, transform=tr
    )
    return TS.types["tf2_msgs/msg/TFMessage"](transforms=[ts])


def joint_stream(
    q: np.ndarray,
    *,
    drop: str | None = None,
    joints: tuple[str, ...] = JOINTS,
    others: dict[str, float] | None = None,
) -> list[Msg]:
    """``/joint_states`` at 100 Hz: rest at q[i] during [i (REST + MOVE), + REST], then move linearly
    to q[i + 1]; two publishers (the first two joints, and the rest plus ``others``, joints the
    robot model does not need, at fixed values)."""
    groups = [list(joints[:2]), list(joints[2:])]
    out: list[Msg] = []
    end = len(q) * (REST + MOVE)
    for t in range(-SEC // 2, end, DT_JS):
        i, phase = divmod(t, REST + MOVE)
        i = min(max(i, 0), len(q) - 1)
        if t < 0 or phase <= REST or i == len(q) - 1:
            v = q[i]
        else:
            a = (phase - REST) / MOVE
            v = (1 - a) * q[i] + a * q[i + 1]
        for g in groups:
            names = [j for j in g if j != drop]
            vals = [float(v[joints.index(j)]) for j in names]
            if g is groups[1] and others:
                names, vals = names + list(others), vals + list(others.values())
            out.append(
                (
                    "/joint_states",
                    "sensor_msgs/msg/JointState",
                    T0 + t,
                    _joint_state(T0 + t, names, vals),
                )
            )
    return out


def pose_stream(
    ms: MeasurementSet, *, stamped: bool = True, moving_sample: bool = True
) -> list[Msg]:
    """plate_left as PoseStamped on /rig/plate_left, plate_right on /tf (rig -> plate_right_marker,
    0.5 ms later); one extra sample while the robot moves from configuration 0 to 1."""
    out: list[Msg] = []
    times = [T0 + i * (REST + MOVE) + POSE_OFFSET for i in range(ms.n_records)]
    poses = [(ms.poses["plate_left"][i], ms.poses["plate_right"][i]) for i in range(ms.n_records)]
    if moving_sample:
        times.append(T0 + REST + MOVE // 2 + 3_000_000)
        poses.append(poses[0])
    for t, (TL, TR) in zip(times, poses, strict=True):
        h = t if stamped else 0
        out.append(("/rig/plate_left", "geometry_msgs/msg/PoseStamped", t, _pose_stamped(h, TL)))
        out.append(
            (
                "/tf",
                "tf2_msgs/msg/TFMessage",
                t + 500_000,
                _tf(h and h + 500_000, TR, "rig", "plate_right_marker"),
            )
        )
    return out


def write_bag(path: Path, messages: list[Msg], ros1: bool = False) -> Path:
    conns: dict[str, Any] = {}
    if ros1:
        with Writer1(path) as w:
            for topic, msgtype, t, msg in sorted(messages, key=lambda m: m[2]):
                if topic not in conns:
                    conns[topic] = w.add_connection(topic, msgtype, typestore=TS)
                w.write(conns[topic], t, TS.serialize_ros1(msg, msgtype))
    else:
        with Writer2(path, version=9) as w:
            for topic, msgtype, t, msg in sorted(messages, key=lambda m: m[2]):
                if topic not in conns:
                    conns[topic] = w.add_connection(topic, msgtype, typestore=TS)
                w.write(conns[topic], t, TS.serialize_cdr(msg, msgtype))
    return path


@pytest.fixture(scope="module")
def simulated(tmp_path_factory: pytest.TempPathFactory) -> tuple[MeasurementSet, Path]:
    """The simulated experiment (Fig. 10 noise) and its measurement file written directly."""
    _, ms, _ = simulate_experiment("iis_head", seed=3, M=2, n_heldout=1, robot_ref="iis_head")
    direct = tmp_path_factory.mktemp("direct") / "direct.json"
    save_measurements(ms, direct)
    return ms, direct


POSE_ARGS = [
    "--pose",
    "plate_left=/rig/plate_left",
    "--pose",
    "plate_right=/tf:rig:plate_right_marker",
]


def assert_same_records(a: MeasurementSet, b: MeasurementSet) -> None:
    assert a.n_records == b.n_records
    assert a.structure.joint_names == b.structure.joint_names
    np.testing.assert_array_equal(a.q, b.q)  # the readings are the rest values themselves
    for f in ("plate_left", "plate_right"):
        # quaternion round trip: float rounding only
        np.testing.assert_allclose(a.poses[f], b.poses[f], rtol=0, atol=1e-14)


@pytest.mark.parametrize("ros1", [False, True], ids=["rosbag2", "rosbag1"])
def test_bag_gives_the_direct_measurement_file(
    simulated: tuple[MeasurementSet, Path],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    ros1: bool,
) -> None:
    ms, direct = simulated
    # rosbag1: the instrument leaves the header stamps at zero; they are placed at the bag's time.
    msgs = joint_stream(ms.q) + pose_stream(ms, stamped=not ros1)
    bag = write_bag(tmp_path / ("exp.bag" if ros1 else "exp"), msgs, ros1=ros1)
    out = tmp_path / "m.json"
    assert main(["bag", str(bag), *POSE_ARGS, "-o", str(out)]) == 0
    cap = capsys.readouterr()
    got, ref = load_measurements(out), load_measurements(direct)
    assert_same_records(got, ref)
    assert got.robot == ref.robot == "iis_head"
    assert f"wrote {out}: {ms.n_records} records" in cap.out
    # The sample taken while the robot moved from configuration 0 to 1 is skipped and listed.
    skipped = got.metadata["provenance"]["skipped"]
    assert len(skipped) == 1 and "joints not at rest: table_x moved" in skipped[0]
    assert "skipped: sample 1 (t=1700000001.503" in cap.err
    assert got.metadata["provenance"]["messages_at_bag_time"] == (
        2 * (ms.n_records + 1) if ros1 else 0
    )
    assert got.labels[0] == "t=1700000000.503250000"


def test_rest_check_off_keeps_the_moving_sample(
    simulated: tuple[MeasurementSet, Path], tmp_path: Path
) -> None:
    ms, _ = simulated
    bag = write_bag(tmp_path / "exp", joint_stream(ms.q) + pose_stream(ms))
    res = bags.measurements_from_bag(
        bag,
        SPEC,
        [bags.PoseTopic.parse(a) for a in POSE_ARGS[1::2]],
        robot_ref="iis_head",
        rule=bags.SyncRule(rest_window=0.0),
    )
    assert res.measurements.n_records == ms.n_records + 1 and not res.samples.skipped
    # The moving sample got the reading nearest to it: between configurations 0 and 1.
    k = int(np.argmax(np.abs(ms.q[1] - ms.q[0])))
    lo, hi = sorted((ms.q[0, k], ms.q[1, k]))
    assert lo < res.measurements.q[1, k] < hi


def test_a_lost_frame_is_left_out_and_listed(
    simulated: tuple[MeasurementSet, Path], tmp_path: Path
) -> None:
    ms, _ = simulated
    lost = np.full((4, 4), np.nan)
    msgs = [
        (m[0], m[1], m[2], _pose_stamped(m[2], lost))
        if m[0] == "/rig/plate_left" and m[2] > T0 + 4 * SEC and m[2] < T0 + 5 * SEC
        else m
        for m in pose_stream(ms, moving_sample=False)
    ]
    bag = write_bag(tmp_path / "exp", joint_stream(ms.q) + msgs)
    res = bags.measurements_from_bag(
        bag, SPEC, [bags.PoseTopic.parse(a) for a in POSE_ARGS[1::2]], robot_ref="iis_head"
    )
    got = res.measurements
    assert res.samples.skipped == [
        "/rig/plate_left message 2: pose is not finite (the instrument lost the frame?)"
    ]
    assert got.has_pose("plate_left").tolist() == [k != 2 for k in range(ms.n_records)]
    assert got.has_pose("plate_right").all()
    np.testing.assert_array_equal(got.q, ms.q)


def test_urdf_robot_takes_the_joints_on_the_path_from_a_whole_joint_states(tmp_path: Path) -> None:
    """TIAGo (a URDF no one here wrote) with a plate on its head: /joint_states carries every
    joint the driver has; the file keeps those on the path to the measured link, URDF names."""
    from urdf_cases import TIAGO_HEAD, simulate, tiago_with_plate

    from cpc2urdf.urdf.robot import load_urdf_robot

    urdf = tiago_with_plate(tmp_path)
    robot = load_urdf_robot(urdf, ["calib_plate"])
    simulate(robot, np.random.default_rng(4), tmp_path / "direct.json", M=2)
    ref = load_measurements(tmp_path / "direct.json")
    times = [T0 + i * (REST + MOVE) + POSE_OFFSET for i in range(ref.n_records)]
    msgs = joint_stream(
        ref.q, joints=TIAGO_HEAD, others={"arm_1_joint": 0.3, "wheel_left_joint": 1.0}
    )
    msgs += [
        (
            "/tf",
            "tf2_msgs/msg/TFMessage",
            t,
            _tf(t, ref.poses["calib_plate"][i], "tracker", "calib_plate"),
        )
        for i, t in enumerate(times)
    ]
    bag = write_bag(tmp_path / "tiago", msgs)
    out = tmp_path / "m.json"
    assert (
        main(
            [
                "bag",
                str(bag),
                "--robot",
                str(urdf),
                "--pose",
                "calib_plate=/tf:tracker:calib_plate",
                "-o",
                str(out),
            ]
        )
        == 0
    )
    got = load_measurements(out)
    assert (
        got.structure.joint_names == ref.structure.joint_names == ("torso_lift", "head_1", "head_2")
    )
    np.testing.assert_array_equal(got.q, ref.q)
    np.testing.assert_allclose(
        got.poses["calib_plate"], ref.poses["calib_plate"], rtol=0, atol=1e-14
    )
    assert set(json.loads(out.read_text())["records"][0]["joints"]) == set(TIAGO_HEAD)


def test_cli_defaults_are_the_library_defaults() -> None:
    assert cli_bag.SYNC_TOLERANCE == bags.SYNC_TOLERANCE and cli_bag.REST_WINDOW == bags.REST_WINDOW
    assert cli_bag.JOINT_STATES_TOPIC == bags.JOINT_STATES_TOPIC
    assert cli_bag.REST_TOLERANCE_MM * 1e-3 == pytest.approx(bags.REST_TOLERANCE_M, rel=1e-12)
    assert np.radians(cli_bag.REST_TOLERANCE_DEG) == pytest.approx(
        bags.REST_TOLERANCE_RAD, rel=1e-12
    )


def test_target_poses_give_the_direct_handeye_files(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Stage 2: a marker detector's target poses in the head cameras -> the hand-eye pose files
    that the simulated observations give directly (T_base_hand from the same model)."""
    truth = s2.perturb_cameras(load_model("iis_head"), np.random.default_rng(1))
    rng = np.random.default_rng(3)
    T_base_target = s2.default_target_placement(truth)
    q = s2.sample_configurations(truth, 6, rng, T_base_target)
    obs = s2.simulate_observations(truth, q, T_base_target, rng, pixel_noise=0.2)
    model = truth.without_frames(["camera"])
    model_file = save_model(model, tmp_path / "identified.json")
    cams = ("camera_left_optical", "camera_right_optical")
    direct = tmp_path / "direct"
    direct.mkdir()
    labels = [f"r{k}" for k in range(len(q))]
    write_handeye_files(
        HeadImageMeasurement(
            {c: labels for c in cams},
            {c: q for c in cams},
            dict(obs.T_camera_target),
            {c: np.zeros(len(q)) for c in cams},
            [],
        ),
        model,
        direct,
    )
    times = [T0 + i * (REST + MOVE) + POSE_OFFSET for i in range(len(q))]
    msgs = joint_stream(q)
    for i, t in enumerate(times):  # the cameras are not synchronised: the right one 7 ms later
        msgs.append(
            (
                "/left/target_pose",
                "geometry_msgs/msg/PoseStamped",
                t,
                _pose_stamped(t, obs.T_camera_target[cams[0]][i], cams[0]),
            )
        )
        msgs.append(
            (
                "/tf",
                "tf2_msgs/msg/TFMessage",
                t + 7_000_000,
                _tf(t + 7_000_000, obs.T_camera_target[cams[1]][i], cams[1], "target"),
            )
        )
    bag = write_bag(tmp_path / "stage2", msgs)
    out = tmp_path / "from_bag"
    assert (
        main(
            [
                "bag",
                str(bag),
                "--model",
                str(model_file),
                "--target",
                f"{cams[0]}=/left/target_pose",
                "--target",
                f"{cams[1]}=/tf:{cams[1]}:target",
                "-o",
                str(out),
            ]
        )
        == 0
    )
    assert "wrote" in capsys.readouterr().out
    for c in cams:
        a, b = (
            load_handeye_poses(out / f"handeye_{c}.json"),
            load_handeye_poses(direct / f"handeye_{c}.json"),
        )
        assert a.hand == b.hand and a.camera == b.camera == c and len(a.labels) == len(q)
        np.testing.assert_array_equal(a.T_base_hand, b.T_base_hand)  # same readings, same model
        np.testing.assert_allclose(
            a.T_camera_target, b.T_camera_target, rtol=0, atol=1e-12
        )  # [mm] in the file
    # A camera's poses in two frames are refused.
    bad = [
        m
        if m[0] != "/left/target_pose" or m[2] < T0 + SEC
        else (m[0], m[1], m[2], _pose_stamped(m[2], obs.T_camera_target[cams[0]][0], "camera_link"))
        for m in msgs
    ]
    _refused(
        capsys,
        [
            "bag",
            str(write_bag(tmp_path / "bad", bad)),
            "--model",
            str(model_file),
            "--target",
            f"{cams[0]}=/left/target_pose",
            "-o",
            str(tmp_path / "no"),
        ],
        tmp_path / "no",
        "poses in different frames: /left/target_pose message 0 is in 'camera_left_optical', /left/target_pose "
        "message 1 in 'camera_link'; every pose of camera_left_optical must be expressed in one frame",
    )


def test_target_poses_outside_the_joint_limits_are_refused_before_writing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """As for --pose and --image: a reading outside the limits (pan 1 rad past its upper limit in
    one sample) is refused naming the sample and the joint, and no pose file is written."""
    model = load_model("iis_head")
    model_file = save_model(model, tmp_path / "model.json")
    s = model.structure
    q = np.tile(0.5 * (s.lower + s.upper), (3, 1))
    q[:, 0] += np.array([0.0, 0.05, 0.1])  # three configurations
    pan = s.joint_names.index("pan")
    q[1, pan] = s.upper[pan] + 1.0
    T = np.eye(4)
    T[2, 3] = 1.0  # the target 1 m in front of the camera
    times = [T0 + i * (REST + MOVE) + POSE_OFFSET for i in range(len(q))]
    msgs = joint_stream(q) + [
        (
            "/left/target_pose",
            "geometry_msgs/msg/PoseStamped",
            t,
            _pose_stamped(t, T, "camera_left_optical"),
        )
        for t in times
    ]
    bag = write_bag(tmp_path / "limits", msgs)
    out = tmp_path / "out"
    _refused(
        capsys,
        [
            "bag",
            str(bag),
            "--model",
            str(model_file),
            "--target",
            "camera_left_optical=/left/target_pose",
            "-o",
            str(out),
        ],
        out,
        f"limits: t=1700000002.503000000: pan = {s.upper[pan] + 1.0:.6g} is outside the joint limits "
        f"[{s.lower[pan]:.6g}, {s.upper[pan]:.6g}] (m or rad)",
    )
    # The library refuses it too (the API's route), not only the command.
    with pytest.raises(InputFileError, match="pan = .* is outside the joint limits"):
        bags.target_poses_from_bag(
            bag, model, [bags.PoseTopic.parse("camera_left_optical=/left/target_pose")]
        )


# ---- bad input: one line, exit 2, nothing written ------------------------------------------------------


def _refused(capsys: pytest.CaptureFixture[str], argv: list[str], out: Path, *needles: str) -> str:
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    for n in needles:
        assert n in err, err
    assert not out.exists()
    return err


def test_bad_bags_are_refused(
    simulated: tuple[MeasurementSet, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    ms, _ = simulated
    out = tmp_path / "m.json"
    good = write_bag(tmp_path / "good", joint_stream(ms.q) + pose_stream(ms))

    def run(bag: Path, *extra: str, args: list[str] = POSE_ARGS) -> list[str]:
        return ["bag", str(bag), *args, *extra, "-o", str(out)]

    _refused(capsys, run(tmp_path / "missing"), out, "missing: no such bag")
    text = tmp_path / "notes.bag"
    text.write_text("not a bag\n")
    _refused(capsys, run(text), out, "notes.bag: not a readable ROS bag")
    _refused(
        capsys,
        run(good, args=["--pose", "plate_left=/mocap/plate_left"]),
        out,
        "no topic '/mocap/plate_left' (poses of plate_left); the bag has /joint_states (sensor_msgs/JointState), "
        "/rig/plate_left (geometry_msgs/PoseStamped), /tf (tf2_msgs/TFMessage)",
    )
    _refused(
        capsys,
        run(good, args=["--pose", "plate_left=/joint_states"]),
        out,
        "topic /joint_states is sensor_msgs/JointState, expected geometry_msgs/PoseStamped or "
        "geometry_msgs/TransformStamped or tf2_msgs/TFMessage (poses of plate_left)",
    )
    _refused(
        capsys,
        run(good, "--joint-states", "/tf"),
        out,
        "topic /tf is tf2_msgs/TFMessage, expected sensor_msgs/JointState (joint readings)",
    )
    _refused(
        capsys,
        run(good, args=["--pose", "plate_left=/tf:rig:elsewhere"]),
        out,
        "topic /tf has no transform rig -> elsewhere (for plate_left); it has rig -> plate_right_marker",
    )
    _refused(
        capsys,
        run(good, args=["--pose", "elbow=/rig/plate_left"]),
        out,
        "--pose elbow: unknown frame",
    )
    # Unsynchronised: the instrument's sample is 3.25 ms from the nearest joint reading.
    _refused(
        capsys,
        run(good, "--sync-tolerance", "0.001"),
        out,
        "sample 0 (t=1700000000.503250000: /rig/plate_left message 0, /tf message 0): no /joint_states "
        "reading of table_x within the sync tolerance 0.001 s (nearest 0.00325 s away)",
    )
    # A joint missing from /joint_states.
    no_tilt = write_bag(tmp_path / "no_tilt", joint_stream(ms.q, drop="tilt") + pose_stream(ms))
    _refused(
        capsys,
        run(no_tilt),
        out,
        "/joint_states has no reading of joint 'tilt'",
        "its messages name pan, table_x, table_y, vergence_left, vergence_right",
    )
    # Joint states that stop before the last samples: the gap is named.
    early = [m for m in joint_stream(ms.q) if m[2] < T0 + 3 * (REST + MOVE)]
    stop = write_bag(tmp_path / "stop", early + pose_stream(ms))
    _refused(capsys, run(stop), out, "sample 4 (t=1700000006.503250000", "nearest 0.513")
    # A reading outside the joint limits (pan in degrees, not radians), refused naming the sample.
    deg = [
        (
            m[0],
            m[1],
            m[2],
            _joint_state(
                m[2],
                list(m[3].name),
                [
                    v * 180 / np.pi if n == "pan" else v
                    for n, v in zip(m[3].name, m[3].position, strict=True)
                ],
            ),
        )
        for m in joint_stream(ms.q)
    ]
    _refused(
        capsys,
        run(write_bag(tmp_path / "deg", deg + pose_stream(ms))),
        out,
        "deg: sample t=1700000000.503250000: joints.pan = 90.0 rad is outside the joint limits",
    )
    # Poses in two different worlds.
    msgs = joint_stream(ms.q) + [
        m
        if m[1].endswith("PoseStamped") is False or m[2] < T0 + SEC
        else (m[0], m[1], m[2], _pose_stamped(m[2], ms.poses["plate_left"][0], "map"))
        for m in pose_stream(ms)
    ]
    worlds = write_bag(tmp_path / "worlds", msgs)
    _refused(
        capsys,
        run(worlds),
        out,
        "poses in different frames: /rig/plate_left message 0 is in 'rig', "
        "/rig/plate_left message 1 in 'map'",
    )


# ---- images ------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def rendered(tmp_path_factory: pytest.TempPathFactory) -> RenderedExperiment:
    return render_experiment(
        tmp_path_factory.mktemp("render") / "images", M=2, n_heldout=1, seed=2, supersample=2
    )


def _image_msgs(
    exp: RenderedExperiment, records: list[int], q: np.ndarray, times: list[int] | None = None
) -> list[Msg]:
    """Left images as raw mono8 ``Image``, right ones as PNG ``CompressedImage``, 2 ms apart
    (at ``times`` [ns], default: inside the rest period of configuration i)."""
    out: list[Msg] = []
    for i, r in enumerate(records):
        t = T0 + i * (REST + MOVE) + POSE_OFFSET if times is None else times[i]
        left = cv2.imread(str(exp.folder / "left" / f"{r:04d}.png"), cv2.IMREAD_UNCHANGED)
        h, w = left.shape
        out.append(
            (
                "/rig/left/image_raw",
                "sensor_msgs/msg/Image",
                t,
                TS.types["sensor_msgs/msg/Image"](
                    header=_header(t, "left"),
                    height=h,
                    width=w,
                    encoding="mono8",
                    is_bigendian=0,
                    step=w,
                    data=left.reshape(-1).copy(),
                ),
            )
        )
        png = np.fromfile(str(exp.folder / "right" / f"{r:04d}.png"), dtype=np.uint8)
        out.append(
            (
                "/rig/right/image_raw/compressed",
                "sensor_msgs/msg/CompressedImage",
                t + 2_000_000,
                TS.types["sensor_msgs/msg/CompressedImage"](
                    header=_header(t + 2_000_000, "right"), format="png", data=png
                ),
            )
        )
    return out


IMAGE_ARGS = [
    "--image",
    "left=/rig/left/image_raw",
    "--image",
    "right=/rig/right/image_raw/compressed",
]


def test_image_bag_measures_like_the_rendered_folder(
    rendered: RenderedExperiment, tmp_path: Path
) -> None:
    exp = rendered
    records = [0, 3, 8]
    q = exp.measured.q[records]
    bag = write_bag(tmp_path / "img.bag", joint_stream(q) + _image_msgs(exp, records, q), ros1=True)
    folder = tmp_path / "from_bag"
    assert main(["bag", str(bag), *IMAGE_ARGS, "-o", str(folder)]) == 0
    # The direct route: the rendered images of the same records with their readings.
    direct = tmp_path / "direct"
    for cam in ("left", "right"):
        (direct / cam).mkdir(parents=True)
        for r in records:
            shutil.copy(exp.folder / cam / f"{r:04d}.png", direct / cam / f"{r:04d}.png")
    write_joints_csv(
        direct / "joints.csv",
        SPEC.structure,
        [f"{r:04d}" for r in records],
        q,
        length="m",
        angle="rad",
    )
    prov = json.loads((folder / bags.BAG_PROVENANCE).read_text())
    assert prov["images"] == {
        "left": "/rig/left/image_raw",
        "right": "/rig/right/image_raw/compressed",
    }
    assert prov["skipped"] == [] and prov["messages"] == 2 * len(records)
    table = read_joints_csv(folder / "joints.csv", SPEC.structure)
    np.testing.assert_array_equal(table.q, q)
    for k, r in enumerate(
        records
    ):  # the bag's images are the rendered ones, byte for byte in pixels
        for cam in ("left", "right"):
            a = cv2.imread(str(folder / cam / f"{k:04d}.png"), cv2.IMREAD_UNCHANGED)
            np.testing.assert_array_equal(
                a, cv2.imread(str(exp.folder / cam / f"{r:04d}.png"), cv2.IMREAD_UNCHANGED)
            )
    a = measure_stereo_images(folder, exp.rig, SPEC.structure).measurements
    b = measure_stereo_images(direct, exp.rig, SPEC.structure).measurements
    np.testing.assert_array_equal(a.q, b.q)
    for f in ("plate_left", "plate_right"):
        assert a.has_pose(f).all()
        np.testing.assert_array_equal(a.poses[f], b.poses[f])
    # and cpc2urdf measure accepts the folder as it is
    m = tmp_path / "m.json"
    assert main(["measure", str(folder), "--rig", str(exp.folder / "rig.yaml"), "-o", str(m)]) == 0
    assert load_measurements(m).n_records == len(records)


@pytest.mark.parametrize("encoding", ["mono8", "mono16", "bgr8", "rgb8", "rgba8"])
@pytest.mark.parametrize("bigendian", [0, 1])
def test_raw_image_encodings(encoding: str, bigendian: int) -> None:
    """Image messages (row padding, byte order) decode to what OpenCV would have written."""
    rng = np.random.default_rng(0)
    ch = {"mono8": 1, "mono16": 1, "bgr8": 3, "rgb8": 3, "rgba8": 4}[encoding]
    dtype = np.dtype(np.uint16 if encoding == "mono16" else np.uint8).newbyteorder(
        ">" if bigendian else "<"
    )
    img = rng.integers(0, 60000 if encoding == "mono16" else 255, size=(5, 7, ch)).astype(dtype)
    row = img.reshape(5, -1).view(np.uint8)
    step = row.shape[1] + 3  # padded rows
    data = np.zeros((5, step), np.uint8)
    data[:, : row.shape[1]] = row
    msg = TS.types["sensor_msgs/msg/Image"](
        header=_header(T0),
        height=5,
        width=7,
        encoding=encoding,
        is_bigendian=bigendian,
        step=step,
        data=data.reshape(-1),
    )
    got = bag_images.image_from_msg(msg, "m", Path("b"))
    want = img.astype(img.dtype.newbyteorder("="))
    if encoding == "rgb8":
        want = want[..., ::-1]
    elif encoding == "rgba8":
        want = want[..., [2, 1, 0, 3]]
    np.testing.assert_array_equal(got, want.squeeze(axis=2) if ch == 1 else want)


def test_image_bag_skipped_samples_are_numbered_as_the_bag_has_them(
    rendered: RenderedExperiment, tmp_path: Path
) -> None:
    """Sample 0 lacks its right image, sample 1 is taken while the robot moves: the skip list
    names them 0 and 1 (one numbering over the bag's samples), and the other two are written."""
    records = [0, 3, 8]
    q = rendered.measured.q[records]
    msgs = [
        m
        for m in _image_msgs(rendered, records, q)
        if not (m[0].endswith("compressed") and m[2] < T0 + SEC)
    ]
    msgs += _image_msgs(
        rendered, [0], q[:1], times=[T0 + REST + MOVE // 2]
    )  # while moving from q0 to q1
    bag = write_bag(tmp_path / "img", joint_stream(q) + msgs)
    res = bags.image_folder_from_bag(
        bag, SPEC, [bags.ImageTopic.parse(a) for a in IMAGE_ARGS[1::2]], tmp_path / "out"
    )
    skipped = res.samples.skipped
    assert len(skipped) == 2, skipped
    assert skipped[0].startswith(
        "sample 0 (t=1700000000.503000000: /rig/left/image_raw message 0): no image of right"
    )
    assert (
        skipped[1].startswith("sample 1 (t=1700000001.501000000: ")
        and "joints not at rest" in skipped[1]
    ), skipped
    assert res.records == ["0000", "0001"] and res.samples.labels == [
        "t=1700000002.504000000",
        "t=1700000004.504000000",
    ]
    np.testing.assert_array_equal(
        read_joints_csv(tmp_path / "out" / "joints.csv", SPEC.structure).q, q[1:]
    )


def test_image_bag_bad_input_leaves_no_folder(
    rendered: RenderedExperiment, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    records = [0, 3]
    q = rendered.measured.q[records]
    msgs = _image_msgs(rendered, records, q)
    out = tmp_path / "images"
    only_left = write_bag(
        tmp_path / "left_only", joint_stream(q) + [m for m in msgs if "left" in m[0]]
    )
    err = _refused(
        capsys,
        ["bag", str(only_left), *IMAGE_ARGS, "-o", str(out)],
        out,
        "no topic '/rig/right/image_raw/compressed' (images of right)",
    )
    assert "/rig/left/image_raw (sensor_msgs/Image)" in err

    # An encoding we do not write: refused while writing, and the half-written folder is removed.
    def bad(m: Msg) -> Msg:
        if m[0] != "/rig/left/image_raw" or m[2] <= T0 + SEC:
            return m
        img = m[3]
        bayer_image = TS.types["sensor_msgs/msg/Image"](
            header=img.header,
            height=img.height,
            width=img.width,
            encoding="bayer_rggb8",
            is_bigendian=0,
            step=img.step,
            data=img.data,
        )
        return (m[0], m[1], m[2], bayer_image)

    bayer = write_bag(tmp_path / "bayer", joint_stream(q) + [bad(m) for m in msgs])
    _refused(
        capsys,
        ["bag", str(bayer), *IMAGE_ARGS, "-o", str(out)],
        out,
        "/rig/left/image_raw message 1: image encoding 'bayer_rggb8' is not supported",
    )
    assert not list(tmp_path.glob(".images.*"))
    # An existing folder is not overwritten.
    out.mkdir()
    (out / "keep.txt").write_text("x")
    good = write_bag(tmp_path / "good", joint_stream(q) + msgs)
    assert main(["bag", str(good), *IMAGE_ARGS, "-o", str(out)]) == 2
    assert "already exists" in capsys.readouterr().err
    assert sorted(p.name for p in out.iterdir()) == ["keep.txt"]
