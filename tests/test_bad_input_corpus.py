"""The bad-input corpus: every command, refused the way the README promises.

Each case of :data:`bad_inputs.CASES` runs ``cpc2urdf.cli.main(argv)`` in-process in its own folder
and must give exit code 2, exactly one line on stderr starting ``cpc2urdf <command>: error:`` that
names the file, field, joint or option at fault, no traceback, and leave the folder (and the shared
clean inputs) exactly as they were: no output, no temporary file. A few cases run the installed
console script to show that the real process behaves the same.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import re
import shutil
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np
import pytest
from bad_inputs import CASES, Case, Corpus, write_content

import cpc2urdf
from cpc2urdf.cli import COMMANDS, main
from cpc2urdf.files.jsonio import read_json, write_json

PLACEHOLDERS = (
    "meas",
    "heldout",
    "model",
    "urdf",
    "spec",
    "poses",
    "images",
    "rig",
    "joints",
    "camera",
)
IMAGE_SIZE = (64, 48)  # [px] width, height: blank images, nothing to detect


def _quiet_main(argv: list[str]) -> int:
    with contextlib.redirect_stdout(io.StringIO()):
        return main(argv)


def _blank_images(d: Path) -> None:
    """A stage-1 and stage-2 image folder of 4 records of blank images, with its rig, joint
    readings and camera files (as in test_cli_measure)."""
    from cpc2urdf.files.robot_ref import load_robot
    from cpc2urdf.identification.vision.joints_csv import write_joints_csv
    from cpc2urdf.identification.vision.rig_file import save_camera, save_rig
    from cpc2urdf.identification.vision.stereo import StereoRig

    structure = load_robot("iis_head").structure
    K = np.array([[60.0, 0.0, 32.0], [0.0, 60.0, 24.0], [0.0, 0.0, 1.0]])
    cameras = ("camera_left_optical", "camera_right_optical")
    for sub in ("left", "right", *cameras):
        (d / sub).mkdir(parents=True)
        for i in range(4):
            cv2.imwrite(str(d / sub / f"{i:04d}.png"), np.zeros(IMAGE_SIZE[::-1], np.uint8))
    q = np.tile((structure.lower + structure.upper) / 2, (4, 1))
    write_joints_csv(d / "joints.csv", structure, [f"{i:04d}" for i in range(4)], q)
    save_rig(
        StereoRig(
            K, np.zeros(5), K, np.zeros(5), np.eye(3), np.array([-0.6, 0.0, 0.0]), IMAGE_SIZE
        ),
        d / "rig.yaml",
    )
    for c in cameras:
        save_camera(K, np.zeros(5), IMAGE_SIZE, d / f"{c}.yaml")


@pytest.fixture(scope="session")
def corpus(tmp_path_factory: pytest.TempPathFactory) -> Corpus:
    """The clean inputs, built once: ``simulate`` (10 held-out records), ``identify``, ``export``."""
    import handeye_mistakes as hm

    from cpc2urdf.robots import spec_path

    root = tmp_path_factory.mktemp("corpus")
    assert _quiet_main(["simulate", "iis_head", "-o", str(root / "sim"), "--heldout", "10"]) == 0
    assert (
        _quiet_main(
            ["identify", str(root / "sim" / "measurements.json"), "-o", str(root / "model.json")]
        )
        == 0
    )
    assert _quiet_main(["export", "iis_head", "-o", str(root / "head.urdf")]) == 0
    spec = spec_path("iis_head")
    assert spec is not None
    shutil.copy(spec, root / "iis_head.json")
    write_json(root / "poses.json", hm.clean_document())
    _blank_images(root / "images")
    paths = {
        "meas": root / "sim" / "measurements.json",
        "heldout": root / "sim" / "heldout.json",
        "model": root / "model.json",
        "urdf": root / "head.urdf",
        "spec": root / "iis_head.json",
        "poses": root / "poses.json",
        "images": root / "images",
        "rig": root / "images" / "rig.yaml",
        "joints": root / "images" / "joints.csv",
        "camera": root / "images" / "camera_left_optical.yaml",
    }
    assert set(paths) == set(PLACEHOLDERS)
    return Corpus(
        paths=paths,
        meas=read_json(paths["meas"]),
        heldout=read_json(paths["heldout"]),
        model=read_json(paths["model"]),
        spec=read_json(paths["spec"]),
        poses=read_json(paths["poses"]),
        urdf=paths["urdf"].read_text(),
        rig=paths["rig"].read_text(),
        joints=paths["joints"].read_text(),
        camera=paths["camera"].read_text(),
    )


def _snapshot(folder: Path) -> dict[str, tuple[int, int]]:
    """Every file and folder under ``folder`` (hidden ones too): size and modification time."""
    return {
        str(p.relative_to(folder)): (p.stat().st_size, p.stat().st_mtime_ns)
        for p in folder.rglob("*")
    }


def _fill(text: str, corpus: Corpus, tmp: Path, bad: Path) -> str:
    text = (
        text.replace("{bad}", str(bad))
        .replace("{tmp}", str(tmp))
        .replace("{out}", str(tmp / "out"))
    )
    for key in PLACEHOLDERS:
        text = text.replace("{" + key + "}", str(corpus.paths[key]))
    return text


@contextlib.contextmanager
def _prepared(case: Case, corpus: Corpus, tmp: Path) -> Iterator[tuple[list[str], str]]:
    """The case's folder with ``{bad}`` written; yields ``(argv, expected)``."""
    bad = tmp / case.name
    if case.bad is not None:
        write_content(bad, case.bad(corpus))
    yield [_fill(a, corpus, tmp, bad) for a in case.argv], _fill(case.expected, corpus, tmp, bad)


def _prefix(case: Case) -> re.Pattern[str]:
    """``cpc2urdf COMMAND: error:`` (a study's or benchmark's own parser adds its name)."""
    if case.command not in COMMANDS:
        return re.compile(r"cpc2urdf: error: ")
    return re.compile(rf"cpc2urdf {case.command}( \S+)?: error: ")


def test_the_corpus_walks_every_command() -> None:
    assert len(CASES) >= 150
    per_command = {c: sum(case.command == c for case in CASES) for c in COMMANDS}
    assert all(n >= 5 for n in per_command.values()), per_command


@pytest.mark.parametrize("case", [pytest.param(c, id=c.id) for c in CASES])
def test_bad_input_is_refused_in_one_line(
    case: Case,
    corpus: Corpus,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.chdir(tmp_path)  # a relative default output (demo-out, study_*) would land here
    shared = _snapshot(corpus.paths["model"].parent)
    with _prepared(case, corpus, tmp_path) as (argv, expected):
        before = _snapshot(tmp_path)
        capsys.readouterr()
        code = main(argv)
        err = capsys.readouterr().err
        lines = err.strip().splitlines()
        assert "Traceback" not in err, err
        assert code == 2, (code, err)
        assert len(lines) == 1, err
        assert _prefix(case).match(lines[0]), lines[0]
        assert expected in lines[0], (expected, lines[0])
        assert _snapshot(tmp_path) == before, "the command wrote into the case's folder"
    assert _snapshot(corpus.paths["model"].parent) == shared, (
        "the command changed the shared inputs"
    )


# ---- the real console script: the same exit code and line, no traceback --------------------------

SCRIPT_CASES = ("identify-deep", "handeye-hand-inverted", "check-not-xml", "simulate-M-zero")


def _console_script() -> list[str]:
    exe = shutil.which("cpc2urdf")
    return [exe] if exe else [sys.executable, "-m", "cpc2urdf"]


@pytest.mark.parametrize("case_id", SCRIPT_CASES)
def test_the_console_script_refuses_the_same_way(
    case_id: str, corpus: Corpus, tmp_path: Path
) -> None:
    case = next(c for c in CASES if c.id == case_id)
    with _prepared(case, corpus, tmp_path) as (argv, expected):
        before = _snapshot(tmp_path)
        # the checkout this test imports, whatever the folder the script runs in
        root = str(Path(cpc2urdf.__file__).resolve().parent.parent)
        env = {
            **os.environ,
            "CPC2URDF_PROGRESS": "0",
            "PYTHONPATH": os.pathsep.join([root, *filter(None, [os.environ.get("PYTHONPATH")])]),
        }
        proc = subprocess.run(
            [*_console_script(), *argv], capture_output=True, text=True, cwd=tmp_path, env=env
        )
        assert "Traceback" not in proc.stderr, proc.stderr
        assert proc.returncode == 2, proc.stderr
        lines = proc.stderr.strip().splitlines()
        assert len(lines) == 1 and _prefix(case).match(lines[0]) and expected in lines[0], (
            proc.stderr
        )
        assert _snapshot(tmp_path) == before


# ---- finite targets at the edge of float range: an answer (0 or 1) or a refusal, never a traceback --


def _strict_json(text: str) -> object:
    def refuse(name: str) -> object:
        raise ValueError(f"{name} in the JSON output")

    return json.loads(text, parse_constant=refuse)


@pytest.mark.parametrize(
    "target, extra",
    [
        pytest.param(
            ("-1.7e308", "0", "0"), (), id="huge-negative"
        ),  # was "argument --target: expected 3 arguments"
        pytest.param(
            ("1.7e308", "1.7e308", "0"), ("--json",), id="overflowing-norm-json"
        ),  # wrote Infinity
    ],
)
def test_gaze_extreme_finite_targets(
    target: tuple[str, ...], extra: tuple[str, ...], capsys: pytest.CaptureFixture[str]
) -> None:
    code = main(["gaze", "iis_head", "--target", *target, *extra])
    out, err = capsys.readouterr()
    assert "Traceback" not in err
    if code == 2:  # refused as out of range: one line naming the target
        assert len(err.strip().splitlines()) == 1 and "target" in err, err
    else:
        assert code in (0, 1) and err == "", (code, err)
        if "--json" in extra:
            _strict_json(out)
