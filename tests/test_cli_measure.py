"""``cpc2urdf measure`` on bad input: the one error line is all there is on stderr (no progress line
before it), nothing on stdout, no output; what can be checked before measuring is checked first.

The images are tiny blank ones (nothing to detect), so each case takes milliseconds; the progress
bar is switched on (``CPC2URDF_PROGRESS=1``, which prints its "done" line off a terminal)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from cpc2urdf.cli import main
from cpc2urdf.files.robot_ref import load_robot
from cpc2urdf.identification.vision.joints_csv import write_joints_csv
from cpc2urdf.identification.vision.rig_file import save_camera, save_rig
from cpc2urdf.identification.vision.stereo import StereoRig

SIZE = (64, 48)  # [px] width, height
K = np.array([[60.0, 0.0, 32.0], [0.0, 60.0, 24.0], [0.0, 0.0, 1.0]])
CAMERAS = ("camera_left_optical", "camera_right_optical")


@pytest.fixture
def blank(tmp_path: Path) -> Path:
    """A stage-1 and stage-2 image folder of 4 records whose images are blank."""
    structure = load_robot("iis_head").structure
    d = tmp_path / "images"
    for sub in ("left", "right", *CAMERAS):
        (d / sub).mkdir(parents=True)
        for i in range(4):
            cv2.imwrite(str(d / sub / f"{i:04d}.png"), np.zeros(SIZE[::-1], np.uint8))
    q = np.tile((structure.lower + structure.upper) / 2, (4, 1))
    write_joints_csv(d / "joints.csv", structure, [f"{i:04d}" for i in range(4)], q)
    save_rig(
        StereoRig(K, np.zeros(5), K, np.zeros(5), np.eye(3), np.array([-0.6, 0.0, 0.0]), SIZE),
        d / "rig.yaml",
    )
    for c in CAMERAS:
        save_camera(K, np.zeros(5), SIZE, d / f"{c}.yaml")
    return d


def _one_line(capsys: pytest.CaptureFixture[str], expected: str) -> None:
    cap = capsys.readouterr()
    assert cap.out == "", cap.out
    err = cap.err.splitlines()
    assert (
        len(err) == 1 and err[0].startswith("cpc2urdf measure: error: ") and expected in err[0]
    ), cap.err
    assert "measure:" not in err[0].removeprefix(
        "cpc2urdf measure: error: "
    )  # no progress line mixed in


@pytest.mark.parametrize(
    "extra, expected",
    [
        ([], "no plate could be measured in any of the 4 records"),
        (["--on-error", "stop"], "plate_left: blank image"),
        (["--on-error", "skip-record"], "no plate could be measured in any of the 4 records"),
    ],
)
def test_stage1_refusal_is_the_only_line(
    blank: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
    extra: list[str],
    expected: str,
) -> None:
    monkeypatch.setenv("CPC2URDF_PROGRESS", "1")
    out = blank.parent / "m.json"
    assert (
        main(["measure", str(blank), "--rig", str(blank / "rig.yaml"), "-o", str(out), *extra]) == 2
    )
    _one_line(capsys, expected)
    assert not out.exists()


@pytest.mark.parametrize(
    "output, expected",
    [
        ("missing/m.json", "cannot write, folder {tmp}/missing does not exist"),
        (".", "{tmp}: is a folder, expected a file path"),
    ],
)
def test_stage1_output_is_checked_before_measuring(
    blank: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
    output: str,
    expected: str,
) -> None:
    monkeypatch.setenv("CPC2URDF_PROGRESS", "1")
    tmp = blank.parent
    assert (
        main(["measure", str(blank), "--rig", str(blank / "rig.yaml"), "-o", str(tmp / output)])
        == 2
    )
    _one_line(capsys, expected.replace("{tmp}", str(tmp)))


def test_stage2_refusal_is_the_only_line(
    blank: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("CPC2URDF_PROGRESS", "1")
    out = blank.parent / "poses"
    assert main(["measure", str(blank), "--stage2", "--model", "iis_head", "-o", str(out)]) == 2
    _one_line(
        capsys,
        "camera camera_left_optical saw the target in 0 records; a calibration needs at least 3",
    )
    assert not out.exists()


@pytest.mark.parametrize(
    "args, expected",
    [
        (
            ["--camera", "zoom_cam={images}/camera_left_optical.yaml"],
            "no hand frame known for camera 'zoom_cam'",
        ),
        (["-o", "{tmp}/missing/poses"], "parent folder {tmp}/missing does not exist"),
    ],
)
def test_stage2_arguments_are_checked_before_measuring(
    blank: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
    args: list[str],
    expected: str,
) -> None:
    monkeypatch.setenv("CPC2URDF_PROGRESS", "1")
    tmp = blank.parent
    argv = [
        "measure",
        str(blank),
        "--stage2",
        "--model",
        "iis_head",
        "-o",
        str(tmp / "poses"),
        *args,
    ]
    assert main([a.replace("{images}", str(blank)).replace("{tmp}", str(tmp)) for a in argv]) == 2
    _one_line(capsys, expected.replace("{tmp}", str(tmp)))
    assert not (tmp / "poses").exists()
