"""Hand-eye from pose streams: pairing at a clock offset, its estimate, the CSV/TUM readers and
``cpc2urdf handeye ROBOT [CAMERA]`` (identification/handeye/streams.py, stream_files.py)."""

from __future__ import annotations

import csv
import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from cpc2urdf.api import load_handeye_poses, solve_handeye
from cpc2urdf.cli import main
from cpc2urdf.identification.handeye.solvers import calibrate
from cpc2urdf.identification.handeye.stream_files import read_pose_stream
from cpc2urdf.identification.handeye.streams import PoseStream, pair_streams, select_keyframes
from cpc2urdf.transforms import homogeneous, inverse

OFFSET = 0.037  # [s] t_camera = t_robot + OFFSET
X_TRUE = homogeneous(Rotation.from_rotvec([0.1, -0.2, 0.3]).as_matrix(), [0.03, 0.04, 0.08])
Z_TRUE = homogeneous(Rotation.from_rotvec([2.0, 0.1, -0.4]).as_matrix(), [0.8, 0.1, 0.3])


def hand(t: np.ndarray) -> np.ndarray:
    """A smooth T_base_hand trajectory rotating about three axes."""
    rv = np.stack([0.6 * np.sin(0.9 * t), 0.5 * np.sin(1.3 * t + 1), 0.7 * np.sin(0.7 * t + 2)], 1)
    p = np.stack(
        [0.4 + 0.1 * np.sin(0.8 * t), 0.1 * np.sin(1.1 * t + 0.5), 0.5 + 0.08 * np.sin(0.6 * t)], 1
    )
    T = np.tile(np.eye(4), (len(t), 1, 1))
    T[:, :3, :3], T[:, :3, 3] = Rotation.from_rotvec(rv).as_matrix(), p
    return T


def streams(duration: float = 12.0) -> tuple[PoseStream, PoseStream]:
    """Robot at 125 Hz, camera at 30 Hz stamped OFFSET late, every 7th camera frame unmeasured."""
    t_robot = np.arange(0.0, duration, 1 / 125)
    t_true = np.arange(0.013, duration, 1 / 30)
    C = inverse(hand(t_true) @ X_TRUE) @ Z_TRUE  # T_base_hand X T_camera_target = Z
    C[::7] = np.nan
    return PoseStream(t_robot, hand(t_robot)), PoseStream(t_true + OFFSET, C)


def pq(T: np.ndarray) -> np.ndarray:
    """(N, 7) x, y, z, qw, qx, qy, qz (KinHEC's w-first order); NaN rows stay NaN."""
    out = np.full((len(T), 7), np.nan)
    ok = np.isfinite(T).all(axis=(1, 2))
    out[ok, :3] = T[ok, :3, 3]
    out[ok, 3:] = Rotation.from_matrix(T[ok, :3, :3]).as_quat(scalar_first=True)
    return out


def write_kinhec(folder: Path, robot: PoseStream, camera: PoseStream) -> Path:
    """The two streams in KinHEC's CSV export layout; ground-truth columns hold decoys."""
    comps = ("px", "py", "pz", "qw", "qx", "qy", "qz")
    decoy = np.tile([9.0, 9.0, 9.0, 1.0, 0.0, 0.0, 0.0], (1, 1))
    rows = [["t", "q1_meas", "q1_gt"] + [f"base_ee_{k}_{c}" for k in ("gt", "meas") for c in comps]]
    for t, v in zip(robot.t, pq(robot.T), strict=True):
        rows.append([_num(t), "0.1", "0.1", *map(_num, decoy[0]), *map(_num, v)])
    _write(folder / "seq_robot.csv", rows)
    names = ["base_ee_gt", "cam_target_gt", "cam_target_meas"]
    rows = [["t", "t_gt", *[f"{n}_{c}" for n in names for c in comps], "visible", "outlier"]]
    for t, v in zip(camera.t, pq(camera.T), strict=True):
        meas = ["" if np.isnan(x) else _num(x) for x in v]
        rows.append(
            [_num(t), _num(t), *map(_num, decoy[0]), *map(_num, decoy[0]), *meas, "True", "True"]
        )
    _write(folder / "seq_camera.csv", rows)
    return folder / "seq_robot.csv"


def _num(x: float) -> str:
    return repr(float(x))


def _write(path: Path, rows: list[list[str]]) -> None:
    with path.open("w", newline="") as f:
        csv.writer(f).writerows(rows)


def test_known_offset_and_X_recovered_from_noise_free_streams() -> None:
    robot, camera = streams()
    t, H, C, pairing = pair_streams(robot, camera)
    assert pairing.how == "estimated"
    assert abs(pairing.coarse - OFFSET) < 2e-3  # cross-correlation on a 2 ms grid
    assert abs(pairing.time_offset - OFFSET) < 1e-6 and pairing.sigma < 1e-5
    assert pairing.n_camera == len(camera.t) - len(camera.t[::7]) == pairing.n_paired
    assert 20 < pairing.n_keyframes < pairing.n_paired
    result = calibrate(H, C, "kronecker")
    assert np.abs(result.X - X_TRUE).max() < 2e-6 and np.abs(result.Z - Z_TRUE).max() < 5e-6


def test_given_offset_row_paired_and_outside_frames_dropped() -> None:
    robot, camera = streams()
    *_, pairing = pair_streams(robot, camera, 0.2, keyframes=False)
    assert pairing.how == "given" and pairing.sigma is None
    assert pairing.n_paired < pairing.n_camera  # the last frames fall after the robot's end
    same = PoseStream(robot.t, inverse(robot.T @ X_TRUE) @ Z_TRUE)
    t, H, C, pairing = pair_streams(robot, same)
    assert pairing.how == "row-paired" and pairing.time_offset == 0.0
    assert np.array_equal(H, robot.T[np.searchsorted(robot.t, t)])


def test_keyframes_are_5_deg_or_2_cm_apart_at_most_200() -> None:
    T = np.tile(np.eye(4), (10, 1, 1))
    T[:, 0, 3] = np.arange(10) * 0.011  # 11 mm steps: every second pose is 2 cm on
    assert select_keyframes(T).tolist() == [0, 2, 4, 6, 8]
    T[5, :3, :3] = Rotation.from_rotvec([0, 0, np.radians(6)]).as_matrix()
    assert select_keyframes(T).tolist() == [0, 2, 4, 5, 6, 8]
    assert len(select_keyframes(T, max_keyframes=3)) == 3


def test_kinhec_csv_export_read_and_solved_through_the_command(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    robot, camera = streams()
    path = write_kinhec(tmp_path, robot, camera)
    assert main(["handeye", str(path), "--method", "kronecker"]) == 0
    out = capsys.readouterr().out
    assert "seq_camera.csv" in out and "clock offset t_camera - t_robot = +37.000 ±" in out
    assert f"{len(camera.t) - len(camera.t[::7])} camera frames with a target pose" in out
    assert main(["handeye", str(path), "--method", "kronecker", "--json"]) == 0
    streams_doc = json.loads(capsys.readouterr().out)["streams"]
    assert streams_doc["how"] == "estimated" and abs(streams_doc["time_offset"] - OFFSET) < 1e-6
    data = load_handeye_poses(path)  # measured columns only: the decoys would not fit
    assert data.labels[0].startswith("t=") and data.pairing is not None
    assert np.abs(solve_handeye(data, "kronecker").X - X_TRUE).max() < 2e-6


def test_generic_csv_any_quaternion_order_and_units_and_tum(tmp_path: Path) -> None:
    robot, _ = streams(3.0)
    v = pq(robot.T)
    rows = [["time_ms", "qw", "qx", "qy", "qz", "x_mm", "y_mm", "z_mm"]]
    rows += [
        [_num(t * 1e3), *map(_num, r[3:]), *map(_num, r[:3] * 1e3)]
        for t, r in zip(robot.t, v, strict=True)
    ]
    _write(tmp_path / "r.csv", rows)
    tum = tmp_path / "r.tum"
    tum.write_text(
        "# timestamp tx ty tz qx qy qz qw\n"
        + "".join(
            f"{t:.9f} " + " ".join(f"{x:.9f}" for x in (*r[:3], *r[4:], r[3])) + "\n"
            for t, r in zip(robot.t, v, strict=True)
        )
    )
    ros = tmp_path / "ros.csv"  # rostopic echo -p: stamps in ns, field names
    names = [
        f"field.pose.{k}.{c}"
        for k, cs in (("position", "xyz"), ("orientation", "xyzw"))
        for c in cs
    ]
    rows = [["%time", "field.header.stamp", *names]]
    rows += [
        [str(int(t * 1e9) + 5), str(int(round(t * 1e9))), *map(_num, (*r[:3], *r[4:], r[3]))]
        for t, r in zip(robot.t, v, strict=True)
    ]
    _write(ros, rows)
    for f, tol in ((tmp_path / "r.csv", 1e-12), (tum, 1e-8), (ros, 1e-12)):
        s = read_pose_stream(f, "robot")
        assert np.abs(s.t - robot.t).max() < tol and np.abs(s.T - robot.T).max() < tol


def test_eye_to_hand_maps_the_marker_on_the_hand(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    robot, camera = streams()
    # the fixed camera sees the marker: T_camera_marker = inv(T_base_camera) T_base_hand T_hand_marker
    marker = PoseStream(camera.t, inverse(camera.T))
    path = write_kinhec(tmp_path, robot, marker)
    assert main(["handeye", str(path), "--eye-to-hand", "--method", "kronecker"]) == 0
    assert "X = T_hand_marker" in capsys.readouterr().out
    data = load_handeye_poses(path, eye_to_hand=True)
    assert data.pairing is not None and data.pairing.eye_to_hand
    assert np.abs(solve_handeye(data, "kronecker").X - X_TRUE).max() < 2e-6


def _bad(
    tmp_path: Path, header: list[str], rows: list[list[str]], capsys: pytest.CaptureFixture[str]
) -> str:
    robot, camera = streams(3.0)
    write_kinhec(tmp_path, robot, camera)
    _write(tmp_path / "bad.csv", [header, *rows])
    assert main(["handeye", str(tmp_path / "bad.csv"), str(tmp_path / "seq_camera.csv")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "bad.csv" in err and "Traceback" not in err
    return err


GOOD = ["0.0", "0", "0", "0", "0", "0", "0", "1"]
HEADER = ["t", "x", "y", "z", "qx", "qy", "qz", "qw"]


@pytest.mark.parametrize(
    ("header", "rows", "expected"),
    [
        (HEADER[:-1], [GOOD[:-1]], "no column qw"),
        (
            HEADER,
            [GOOD, ["0.1", "0", "nan", "0", "0", "0", "0", "1"]],
            "line 3, column y: expected a number",
        ),
        (
            HEADER,
            [GOOD, ["0.1", "0", "", "0", "0", "0", "0", "1"]],
            "line 3, column y: expected a number",
        ),
        (
            HEADER,
            [GOOD, ["0.2", *GOOD[1:]], ["0.1", *GOOD[1:]]],
            "line 4, column t: times must increase",
        ),
        (
            HEADER,
            [GOOD, ["0.1", "0", "0", "0", "0", "0", "0", "0.8"]],
            "line 3, columns qx, qy, qz, qw: expected a unit quaternion, norm is 0.8",
        ),
        (
            HEADER,
            [GOOD, ["0.1", "0", "zero", "0", "0", "0", "0", "1"]],
            "line 3, column y: expected a number, got 'zero'",
        ),
    ],
)
def test_bad_stream_gives_one_line_and_exit_2(
    tmp_path: Path,
    header: list[str],
    rows: list[list[str]],
    expected: str,
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert expected in _bad(tmp_path, header, rows, capsys)


def test_camera_row_half_measured_and_pose_file_with_stream_options_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    robot, camera = streams(3.0)
    path = write_kinhec(tmp_path, robot, camera)
    cam = tmp_path / "seq_camera.csv"
    lines = cam.read_text().splitlines()
    cells = lines[1].split(",")  # frame 0 is unmeasured (NaN): give it half a pose
    cells[lines[0].split(",").index("cam_target_meas_px")] = "0.5"
    cam.write_text("\n".join([lines[0], ",".join(cells), *lines[2:]]) + "\n")
    assert main(["handeye", str(path)]) == 2
    err = capsys.readouterr().err
    assert (
        "seq_camera.csv: line 2, column cam_target_meas_py: expected a number (a frame without"
        in err
    )
    json_file = tmp_path / "p.json"
    json_file.write_text('{"format": "cpc2urdf/handeye-poses@1", "records": []}')
    assert main(["handeye", str(json_file), "--time-offset", "0.1"]) == 2
    assert "a pose file pairs its poses already" in capsys.readouterr().err


@pytest.mark.slow
def test_kinhec_temporal_sequence_offset_within_2_ms(tmp_path: Path) -> None:
    """A real KinHEC export, when kinhec and its small data set are installed."""
    pytest.importorskip("kinhec")
    data = Path("/work/kinhec/data_small")
    if not (data / "sequences.parquet").exists() or shutil.which("kinhec") is None:
        pytest.skip("no KinHEC data set")
    seq = "temporal-000020"  # ur5, 30 Hz camera, offset 100 ms
    subprocess.run(
        ["kinhec", "export", str(data), seq, "--format", "csv", "--out", str(tmp_path)], check=True
    )
    poses = load_handeye_poses(tmp_path / f"{seq}_robot.csv")
    assert poses.pairing is not None and abs(poses.pairing.time_offset - 0.1) < 2e-3
