"""OpenCV FileStorage rig files: round trip, aliases, units, and clear errors on bad files."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from cpc2urdf.errors import InputFileError, OutputError
from cpc2urdf.identification.vision.rig_file import load_rig, save_rig
from cpc2urdf.identification.vision.stereo import StereoRig


def _write(path: Path, **entries: object) -> Path:
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    for k, v in entries.items():
        fs.write(k, v)
    fs.release()
    return path


def _rig_entries(rig: StereoRig, scale: float = 1.0) -> dict[str, object]:
    return {
        "K1": rig.K1,
        "D1": rig.D1.reshape(1, 5),
        "K2": rig.K2,
        "D2": rig.D2.reshape(1, 5),
        "R": rig.R,
        "T": (rig.T * scale).reshape(3, 1),
    }


def test_round_trip_in_mm(tmp_path: Path) -> None:
    rig = StereoRig.verged()
    path = save_rig(rig, tmp_path / "rig.yaml", units="mm")
    text = path.read_text()
    assert "units: mm" in text and "!!opencv-matrix" in text
    back = load_rig(path)
    for k in ("K1", "D1", "K2", "D2", "R", "T"):
        np.testing.assert_allclose(getattr(back, k), getattr(rig, k), atol=1e-12)
    assert back.image_size == rig.image_size


def test_reads_what_stereo_calibrate_users_write(tmp_path: Path) -> None:
    # OpenCV's stereo_calib.cpp sample: M1/M2, 8 distortion terms (rational, here zero), no size.
    rig = StereoRig.verged()
    e = _rig_entries(rig)
    e["M1"], e["M2"] = e.pop("K1"), e.pop("K2")
    e["D1"] = np.concatenate([rig.D1, np.zeros(3)]).reshape(1, 8)
    path = _write(tmp_path / "intrinsics_and_extrinsics.yml", **e)
    with pytest.raises(InputFileError, match="image_size"):
        load_rig(path)
    back = load_rig(path, image_size=(1280, 1024))
    np.testing.assert_allclose(back.K1, rig.K1)
    np.testing.assert_allclose(back.D1, rig.D1)
    with pytest.raises(InputFileError, match="differs"):
        _write(tmp_path / "sized.yml", **_rig_entries(rig), image_size=np.array([[640, 480]]))
        load_rig(tmp_path / "sized.yml", image_size=(1280, 1024))


def test_hand_written_yaml_without_header(tmp_path: Path) -> None:
    p = tmp_path / "rig.yaml"
    p.write_text(
        "K1: [1000, 0, 320, 0, 1000, 240, 0, 0, 1]\nD1: [0, 0, 0, 0]\n"
        "K2: [1000, 0, 320, 0, 1000, 240, 0, 0, 1]\nD2: [0, 0, 0, 0, 0]\n"
        "R: [1, 0, 0, 0, 1, 0, 0, 0, 1]\nT: [-600, 0, 0]\nunits: mm\nimage_size: [640, 480]\n"
    )
    rig = load_rig(p)
    np.testing.assert_allclose(rig.T, [-0.6, 0, 0])
    assert rig.image_size == (640, 480) and rig.D1.shape == (5,)


@pytest.mark.parametrize(
    ("mutate", "match"),
    [
        (lambda e: e.pop("D2"), "missing key D2"),
        (lambda e: e.pop("R"), "missing key R"),
        (lambda e: e.update(K1=np.eye(2)), "K1 must have 3 x 3 values"),
        (lambda e: e.update(T=np.ones((2, 1))), "T must have 3 values"),
        (lambda e: e.update(R=np.diag([1.0, 1.0, -1.0])), "R is not a rotation"),
        (lambda e: e.update(K2=-np.eye(3)), "K2 is not a camera matrix"),
        (lambda e: e.update(D1=np.ones((1, 7))), "D1 must have 4, 5, 8, 12 or 14"),
        (lambda e: e.update(D1=np.ones((1, 8))), "rational"),
        (lambda e: e.update(T=np.array([[-588.0], [0.0], [118.0]])), "add 'units: mm'"),
        (lambda e: e.update(K1=np.full((3, 3), np.nan)), "K1 contains NaN"),
        (lambda e: e.update(units="inch"), "units must be one of"),
    ],
)
def test_bad_rig_files_name_the_key(tmp_path: Path, mutate: object, match: str) -> None:
    e = _rig_entries(StereoRig.verged())
    e["image_size"] = np.array([[1280, 1024]])
    mutate(e)  # type: ignore[operator]
    path = _write(tmp_path / "rig.yaml", **e)
    with pytest.raises(InputFileError, match=match):
        load_rig(path)


def test_corrupt_missing_and_binary_files(tmp_path: Path) -> None:
    good = save_rig(StereoRig.verged(), tmp_path / "good.yaml")
    truncated = tmp_path / "truncated.yaml"
    truncated.write_text(good.read_text()[:300])
    with pytest.raises(InputFileError, match="not a readable OpenCV FileStorage"):
        load_rig(truncated)
    binary = tmp_path / "rig.png"
    binary.write_bytes(b"\x89PNG\r\n\x1a\n\x00\x00\x00")
    with pytest.raises(InputFileError, match="binary"):
        load_rig(binary)
    with pytest.raises(InputFileError, match="no such file"):
        load_rig(tmp_path / "nope.yaml")
    with pytest.raises(InputFileError, match="folder"):
        load_rig(tmp_path)
    with pytest.raises(OutputError, match="does not exist"):
        save_rig(StereoRig.verged(), tmp_path / "no" / "rig.yaml")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["good.yaml", "rig.png", "truncated.yaml"]


@pytest.mark.parametrize(
    ("name", "text", "expected"),
    [
        # OpenCV's parsers recurse without a limit: these crashed the process (exit 139) before
        ("deep.json", '{"K1": ' + "[" * 100000 + "1" + "]" * 100000 + "}", "levels deep"),
        ("deep.yaml", "K1:\n" + "- " * 5000 + "1\n", "levels deep"),
        # a mapping where a matrix belongs made node.mat() raise cv2.error (a traceback)
        ("map.yaml", "%YAML:1.0\n---\nK1:\n  a:\n    b: 1\n", "K1 is not a matrix"),
    ],
    ids=["deep.json", "deep.yaml", "map.yaml"],
)
def test_hostile_rig_files_are_refused_in_one_line(tmp_path, name, text, expected):
    import subprocess
    import sys

    (tmp_path / "imgs").mkdir()
    (tmp_path / name).write_text(text)
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "cpc2urdf",
            "measure",
            str(tmp_path / "imgs"),
            "--rig",
            str(tmp_path / name),
            "-o",
            str(tmp_path / "m.json"),
        ],
        capture_output=True,
        text=True,
    )
    assert (
        r.returncode == 2
        and r.stderr.count("\n") == 1
        and expected in r.stderr
        and "Traceback" not in r.stderr
    )
    assert not (tmp_path / "m.json").exists()
