"""``cpc2urdf view``: the page it writes (checked in headless Chromium), serving until Ctrl-C,
and one clear line with exit code 2 for bad input."""

from __future__ import annotations

import re
import signal
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import matplotlib.image
import pytest
from test_view import (
    SIZE,
    TARGET,
    calibrated_head,
    check_picture,
    measurements_of,
    require_chromium,
)

from cpc2urdf.cli import main
from cpc2urdf.files.measurements import save_measurements
from cpc2urdf.files.model_file import save_model
from cpc2urdf.files.robot_ref import load_model
from cpc2urdf.urdf.document import write_urdf
from cpc2urdf.validation.view import build_view, screenshot_html, static_visualizer


def test_view_is_a_registered_command(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["view", "--help"]) == 0
    assert "--target" in capsys.readouterr().out


@pytest.mark.slow
def test_html_page_with_screenshot_in_chromium(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    require_chromium()
    html, png = tmp_path / "head.html", tmp_path / "head.png"
    t0 = time.perf_counter()
    assert main(["view", "iis_head", "--html", str(html), "--screenshot", str(png)]) == 0
    out = capsys.readouterr().out
    assert f"wrote {html}" in out and f"wrote {png}" in out
    print(f"view + Chromium screenshot: {time.perf_counter() - t0:.1f} s")
    # Without a target: the head, and no target colour (the negative control of test_view).
    check_picture(png, None, target=False)
    assert "<script src" not in html.read_text()


def test_html_with_target_nominal_measurements_and_q(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cal = calibrated_head()
    model_path = save_model(cal, tmp_path / "calibrated.json")
    urdf = write_urdf(load_model("iis_head"), tmp_path / "nominal.urdf")
    meas = save_measurements(
        measurements_of(load_model("iis_head")), tmp_path / "meas.json", robot="iis_head"
    )
    html = tmp_path / "view.html"
    argv = ["view", str(model_path), "--target", *map(str, TARGET), "--nominal", str(urdf)]
    argv += ["--measurements", str(meas), "--q", "pan=1.5", "tilt=0.5", "--html", str(html)]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "target" in out and "ghost:" in out and "measurements: 24 plate positions" in out
    assert html.stat().st_size > 100_000  # meshcat's viewer script is inline


def test_html_with_a_target_on_a_rigid_pair_and_on_one_camera(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A rigid stereo pair (its cyclopean axis is pointed: one pointing error) and a one-camera
    head (look-at) with --target: the page, and the summary's error per solved axis."""
    from gaze_heads import STEREO_PAN_TILT

    urdf = tmp_path / "stereo.urdf"
    urdf.write_text(STEREO_PAN_TILT)
    target = ["--target", "2", "0.5", "1.2"]
    pair, one = tmp_path / "pair.html", tmp_path / "one.html"
    argv = ["view", str(urdf), "--cameras", "left_optical", "right_optical", *target]
    assert main([*argv, "--html", str(pair)]) == 0
    out = capsys.readouterr().out
    assert "fixated" in out and "pointing error cyclopean axis" in out
    assert pair.stat().st_size > 100_000
    assert main(["view", str(urdf), "--camera", "left_optical", *target, "--html", str(one)]) == 0
    out = capsys.readouterr().out
    assert "fixated" in out and "pointing error left_optical" in out
    assert one.stat().st_size > 100_000
    # --cameras takes exactly two, before the robot as well
    assert (
        main(
            [
                "view",
                "--cameras",
                "left_optical",
                "right_optical",
                str(urdf),
                *target,
                "--html",
                str(pair),
            ]
        )
        == 0
    )
    assert "pointing error cyclopean axis" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["missing.json"], "missing.json"),
        (
            ["iis_head", "--camera", "a", "b", "c"],
            "--camera takes one or two optical frames, got 3",
        ),
        (["missing.urdf"], "missing.urdf: no such file"),
        (["iis_head", "--target", "1", "2", "x"], "must be numbers, got 'x'"),
        (["iis_head", "--target", "1", "2"], "expected 3 arguments"),
        (["iis_head", "--target", "1", "nan", "2"], "must be finite"),
        (
            [
                "iis_head",
                "--target",
                "-0.3",
                "-0.4",
                "0.66",
                "--cameras",
                "camera_left_optical",
                "eye",
            ],
            "unknown frame 'eye'",
        ),
        (["iis_head", "--q", "neck=0.1"], "unknown joint 'neck'"),
        (["iis_head", "--q", "1", "2"], "needs 6 values"),
        (["iis_head", "--q", "pan=4"], "outside its limits"),
        (["iis_head", "--nominal", "nothere.urdf"], "nothere.urdf: no such file"),
        (["iis_head", "--measurements", "nothere.json"], "nothere.json"),
        (["iis_head", "--screenshot", "x.png"], "--screenshot needs --html"),
    ],
)
def test_bad_input_one_line_exit_2(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    args: list[str],
    message: str,
) -> None:
    monkeypatch.chdir(tmp_path)
    html = tmp_path / "out.html"
    html_args = [] if "--screenshot" in args else ["--html", str(html)]
    assert main(["view", *args, *html_args]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1, err
    assert not html.exists()  # no partial output
    assert list(tmp_path.iterdir()) == []


def test_measured_frame_the_robot_lacks(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    no_plates = save_model(load_model("iis_head").without_frames(["plate"]), tmp_path / "cams.json")
    meas = save_measurements(
        measurements_of(load_model("iis_head"), n=2), tmp_path / "m.json", robot="iis_head"
    )
    html = tmp_path / "out.html"
    assert main(["view", str(no_plates), "--measurements", str(meas), "--html", str(html)]) == 2
    assert "unknown frame 'plate_left'" in capsys.readouterr().err
    assert not html.exists()


def test_output_folder_missing(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["view", "iis_head", "--html", str(tmp_path / "no" / "v.html")]) == 2
    assert "does not exist" in capsys.readouterr().err


def _served_url(proc: subprocess.Popen[str], timeout: float) -> tuple[str | None, list[str]]:
    """The URL a served ``cpc2urdf view`` prints ("serving at URL"), read from its output within
    ``timeout`` [s] (None if it exited or did not print it), and the lines read until then."""
    deadline = time.monotonic() + timeout
    lines: list[str] = []
    while time.monotonic() < deadline and proc.poll() is None:
        line = proc.stdout.readline()  # type: ignore[union-attr]
        lines.append(line)
        m = re.search(r"serving at (http://\S+)", line)
        if m:
            return m.group(1), lines
    return None, lines


@pytest.mark.slow
def test_serves_until_interrupted(tmp_path: Path) -> None:
    """Without --html: prints the URL, the page is served, Ctrl-C stops it (exit 0, server gone)."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "cpc2urdf", "view", "iis_head", "--target", *map(str, TARGET)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=tmp_path,
    )
    try:
        url, lines = _served_url(proc, 60.0)
        assert url is not None, "".join(lines) + (
            proc.stderr.read() if proc.poll() is not None else ""
        )  # type: ignore[union-attr]
        assert "fixated" in "".join(lines)
        with urllib.request.urlopen(url, timeout=10) as r:
            assert r.status == 200 and b"meshcat" in r.read().lower()
        # The served scene, as a browser sees it through meshcat's websocket.
        require_chromium()
        png = screenshot_html(url, tmp_path / "live.png", size=SIZE, budget_ms=3000)
        check_picture(png, build_view(static_visualizer(), "iis_head", target=TARGET), target=True)
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=30)
        assert proc.returncode == 0, err
        assert "stopped" in out
        with pytest.raises(OSError):
            urllib.request.urlopen(url, timeout=2)
    finally:
        if proc.poll() is None:  # SIGTERM first: the command then stops meshcat's server too
            proc.terminate()
            try:
                proc.communicate(timeout=15)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.communicate()


def test_bad_input_in_serve_mode_fails_before_serving(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["view", "iis_head", "--target", "1", "1", "1", "--cameras", "left", "right"]) == 2
    captured = capsys.readouterr()
    assert "unknown frame 'left'" in captured.err and len(captured.err.strip().splitlines()) == 1
    assert "http" not in captured.out  # no server was started


# ---- meshes and change colours ------------------------------------------------------------------


@pytest.mark.parametrize(
    ("filename", "extra", "message"),
    [
        (
            "package://nowhere/a.stl",
            [],
            "link 'l0': mesh 'package://nowhere/a.stl' not found: no package 'nowhere'",
        ),
        ("meshes/missing.stl", [], "link 'l0': mesh 'meshes/missing.stl' not found (no file"),
        ("garbage.stl", [], "link 'l0': mesh 'garbage.stl' cannot be read ("),
        ("garbage.stl", ["--package-path", "nodir"], "nodir: no such folder"),
    ],
)
def test_meshes_that_do_not_resolve_one_line_exit_2(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    filename: str,
    extra: list[str],
    message: str,
) -> None:
    from test_view_meshes import urdf_with_meshes

    (tmp_path / "garbage.stl").write_bytes(b"not a mesh")
    urdf = urdf_with_meshes(tmp_path / "r.urdf", [(filename, "1 0 0 1")])
    html = tmp_path / "out.html"
    assert main(["view", str(urdf), *extra, "--html", str(html)]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1, err
    assert not html.exists()


def test_tiago_elsewhere_with_package_path_and_nominal(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A 'calibrated' TIAGo written outside its package (head_1_joint moved 5 mm) finds its
    meshes only through --package-path; against the nominal TIAGo its head links moved 5 mm."""
    import xml.etree.ElementTree as ET

    from test_view_meshes import SHARE, TIAGO

    root = ET.parse(TIAGO).getroot()
    origin = next(j for j in root.findall("joint") if j.get("name") == "head_1_joint").find(
        "origin"
    )
    xyz = [float(v) for v in origin.get("xyz").split()]  # type: ignore[union-attr]
    origin.set("xyz", " ".join(repr(v) for v in (xyz[0] + 0.005, xyz[1], xyz[2])))  # type: ignore[union-attr]
    cal = tmp_path / "calibrated.urdf"
    cal.write_text(ET.tostring(root, encoding="unicode"))
    html = tmp_path / "tiago.html"
    argv = ["view", str(cal), "--nominal", str(TIAGO), "--no-sweep", "--html", str(html)]
    assert main(argv) == 2
    assert "no package 'example-robot-data'" in capsys.readouterr().err and not html.exists()
    assert main([*argv, "--package-path", str(SHARE)]) == 0
    out = capsys.readouterr().out
    assert "visuals: 65, of which 44 meshes" in out and "all resolved" in out
    assert "head_1_link 5 mm (origin 5 mm, 0 deg)" in out and "0 >= 10 mm (red)" in out
    assert 'id="cpc2urdf-legend"' in html.read_text()


def test_keep_colours(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    model = save_model(calibrated_head(), tmp_path / "cal.json")
    html = tmp_path / "v.html"
    assert (
        main(["view", str(model), "--nominal", "iis_head", "--keep-colours", "--html", str(html)])
        == 0
    )
    out = capsys.readouterr().out
    assert "translucent green" in out and "calibration moved" not in out
    assert "cpc2urdf-legend" not in html.read_text()


@pytest.mark.slow
def test_serves_the_reachable_region(tmp_path: Path) -> None:
    """``view ROBOT --reach`` without --html: the region's counts and notes printed (a served view
    has no legend), and the region in the served scene (green points in the browser's picture)."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "cpc2urdf", "view", "iis_head", "--reach", "--no-sweep"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=tmp_path,
    )
    try:
        url, lines = _served_url(proc, 90.0)
        text = "".join(lines)
        assert url is not None, text
        assert "reachable region: 14800 targets (shell grid):" in text and "fixated (green)" in text
        assert (
            "reachable region: moving pan, tilt, vergence_left, vergence_right; held where shown"
            in text
        )
        require_chromium()
        img = matplotlib.image.imread(
            str(screenshot_html(url, tmp_path / "live.png", size=SIZE, budget_ms=3000))
        )
        green = (img[..., 1] > img[..., 0] + 0.2) & (img[..., 1] > img[..., 2] + 0.1)
        assert green.mean() > 0.02, f"region green on {green.mean():.2%} of the served picture"
        proc.send_signal(signal.SIGINT)
        proc.communicate(timeout=30)
        assert proc.returncode == 0
    finally:
        if proc.poll() is None:
            proc.terminate()
            try:
                proc.communicate(timeout=15)
            except subprocess.TimeoutExpired:
                proc.kill()
