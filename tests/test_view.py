"""The meshcat view: scene contents checked against the CPC model, and the page checked in a
real browser (headless Chromium, software WebGL) by looking at the screenshot's pixels."""

from __future__ import annotations

import colorsys
import math
import re
from pathlib import Path

import matplotlib.image
import numpy as np
import pytest
import umsgpack
from matplotlib.colors import rgb_to_hsv

from cpc2urdf.errors import ConfigurationError, InputFileError, UnknownNameError
from cpc2urdf.files.measurements import MeasurementSet
from cpc2urdf.files.robot_ref import load_model
from cpc2urdf.model import CPCModel, CPCParams
from cpc2urdf.tolerances import FK_AGREEMENT_TOL
from cpc2urdf.urdf.document import HEAD_RGBA, write_urdf
from cpc2urdf.validation.view import (
    GHOST_RGBA,
    TARGET_RGBA,
    StaticWindow,
    build_view,
    find_chromium,
    load_view_robot,
    screenshot_html,
    static_visualizer,
    write_view_html,
)

TARGET = np.array([-0.3, -0.4, 0.66])  # [m] in front of the nominal IIS-head's cameras
SIZE = (1024, 768)


# ---- helpers --------------------------------------------------------------------------------


def calibrated_head(
    seed: int = 0, joints: tuple[str, ...] = ("table_x", "table_y", "pan", "tilt")
) -> CPCModel:
    """The nominal IIS-head with the constants of ``joints`` perturbed (a 'calibrated' head).

    Perturbing only the neck keeps the two eyes' geometry nominal, so targets stay exactly
    fixatable; perturbed vergence axes that no longer share a plane make exact binocular
    fixation impossible (the gaze solver then reports the best in-limit answer, unreachable).
    """
    m = load_model("iis_head")
    rng = np.random.default_rng(seed)
    params = {}
    for name in joints:
        p = m.joints[name]
        b = np.array(p.b) + rng.normal(0.0, 0.01, 3)
        params[name] = CPCParams(
            tuple(b / np.linalg.norm(b)), p.beta, tuple(np.array(p.l) + rng.normal(0, 0.01, 3))
        )
    return m.with_params(joints=params)


def measurements_of(model: CPCModel, n: int = 12, seed: int = 0) -> MeasurementSet:
    """Noise-free plate poses of ``model`` at seeded configurations in the calibration range."""
    s = model.structure
    rng = np.random.default_rng(seed)
    lo = [j.calibration_range[0] for j in s.joints]
    hi = [j.calibration_range[1] for j in s.joints]
    q = rng.uniform(lo, hi, (n, s.n_joints))
    return MeasurementSet.from_arrays(
        s, q, model.fk(q, ["plate_left", "plate_right"]), robot="iis_head"
    )


def decoded(window: StaticWindow) -> dict[str, dict[str, object]]:
    """The recorded scene: path -> {"object": ..., "transform": (4, 4), "properties": [...]}."""
    out: dict[str, dict[str, object]] = {}

    def visit(node: object, path: str) -> None:
        entry: dict[str, object] = {}
        if node.object is not None:  # type: ignore[attr-defined]
            entry["object"] = umsgpack.unpackb(node.object)["object"]  # type: ignore[attr-defined]
        if node.transform is not None:  # type: ignore[attr-defined]
            m = umsgpack.unpackb(node.transform)["matrix"]  # type: ignore[attr-defined]
            entry["transform"] = np.array(m, dtype=float).reshape(4, 4).T  # meshcat: column-major
        entry["properties"] = [umsgpack.unpackb(p) for p in node.properties]  # type: ignore[attr-defined]
        entry["animation"] = node.animation  # type: ignore[attr-defined]
        out[path] = entry
        for k, child in node.items():  # type: ignore[attr-defined]
            visit(child, f"{path}/{k}")

    visit(window.tree, "")
    return out


def colour_mask(img: np.ndarray, rgba: tuple[float, ...], hue_tol_deg: float = 12.0) -> np.ndarray:
    """Pixels of the hue of ``rgba`` (shading changes brightness, not hue), saturated enough."""
    hsv = rgb_to_hsv(np.clip(img[..., :3], 0.0, 1.0))
    h0 = colorsys.rgb_to_hsv(*rgba[:3])[0]
    dh = np.abs((hsv[..., 0] - h0 + 0.5) % 1.0 - 0.5) * 360.0
    return (dh < hue_tol_deg) & (hsv[..., 1] > 0.4) & (hsv[..., 2] > 0.15)


def require_chromium() -> None:
    if find_chromium() is None:
        pytest.fail(
            "Chromium is not installed: the browser test needs it (apt-get install -y chromium, "
            "or set CPC2URDF_CHROMIUM to a Chrome/Chromium executable)"
        )


def check_picture(png: Path, summary: object, *, target: bool, ghost: bool = False) -> None:
    """The screenshot shows the head (its colour, over a plausible area), the target where the
    camera placement says it is, and the ghost when one was given."""
    img = matplotlib.image.imread(str(png))[..., :3]
    assert img.shape[:2] == (SIZE[1], SIZE[0])
    assert img.std() > 0.05, "blank page: WebGL did not render"
    assert len(np.unique((img * 255).astype(np.uint8).reshape(-1, 3), axis=0)) > 200
    head = colour_mask(img, HEAD_RGBA)
    ys, xs = np.nonzero(head)
    assert head.mean() > 0.01, f"head colour covers only {head.mean():.2%} of the picture"
    # The head fills the view: its pixels span a good part of the picture, centred in it.
    assert xs.max() - xs.min() > 0.2 * SIZE[0] and ys.max() - ys.min() > 0.3 * SIZE[1]
    assert 0.2 * SIZE[0] < xs.mean() < 0.8 * SIZE[0] and 0.2 * SIZE[1] < ys.mean() < 0.8 * SIZE[1]
    # Anti-aliased edges between red and blue parts give a few magenta pixels; the target
    # sphere gives hundreds, in one place.
    magenta = colour_mask(img, TARGET_RGBA)
    if target:
        u, v = summary.pixel(summary.target, *SIZE)  # type: ignore[attr-defined]
        rows, cols = np.mgrid[: SIZE[1], : SIZE[0]]
        near = magenta & ((rows - v) ** 2 + (cols - u) ** 2 < 40.0**2)
        assert near.sum() > 100, "target sphere not visible where the target projects"
        # The sphere is drawn where the camera placement projects the target (independent check).
        ty, tx = np.nonzero(near)
        assert math.hypot(tx.mean() - u, ty.mean() - v) < 5.0
    else:
        assert magenta.sum() < 100, "target colour without a target"
    green = colour_mask(img, GHOST_RGBA, hue_tol_deg=20.0)
    if ghost:
        assert green.sum() > 1000, "ghost not visible"


# ---- scene contents (no browser) ------------------------------------------------------------


def test_scene_matches_the_cpc_model_and_the_gaze_fixates() -> None:
    model = calibrated_head()
    vis = static_visualizer()
    summary = build_view(vis, model, target=TARGET.tolist(), sweep=False)
    scene = decoded(vis.window)
    assert summary.gaze is not None
    q = np.array([summary.q[j] for j in model.structure.joint_names])
    T_world = model.fk(q)
    # Shown link poses (sent as float64) = the CPC model's FK, independent of Pinocchio.
    for frame, T in T_world.items():
        shown = scene[f"/meshcat/head/{frame}"]["transform"]
        assert np.allclose(shown, T, atol=FK_AGREEMENT_TOL, rtol=0), frame
    # Triads on every plate and camera frame, visuals on every link.
    for frame in model.structure.frame_names:
        for axis in "xyz":
            assert "object" in scene[f"/meshcat/head/{frame}/triad/{axis}"]
    assert "object" in scene["/meshcat/target"]
    assert np.allclose(scene["/meshcat/target"]["transform"][:3, 3], TARGET, atol=1e-6)
    # Each ray runs along the optical axis to the point nearest the target.
    for cam in ("camera_left_optical", "camera_right_optical"):
        ray = scene[f"/meshcat/head/{cam}/ray"]
        length = ray["object"]["geometries"][0]["height"]
        T = T_world[cam]
        end = T[:3, 3] + length * T[:3, 2]
        d = TARGET - T[:3, 3]
        assert np.linalg.norm(end - (T[:3, 3] + (d @ T[:3, 2]) * T[:3, 2])) < 1e-6
        angle = math.atan2(np.linalg.norm(np.cross(T[:3, 2], d)), d @ T[:3, 2])
        assert angle < 1e-9  # fixated, by the CPC model's FK (independent of the solver)
        assert np.linalg.norm(end - TARGET) < 1e-9
    assert summary.gaze.reachable
    colours = {
        e["object"]["materials"][0]["color"]
        for e in scene.values()
        if "object" in e and "materials" in e["object"]
    }
    head_hex = (
        (round(255 * HEAD_RGBA[0]) << 16)
        | (round(255 * HEAD_RGBA[1]) << 8)
        | round(255 * HEAD_RGBA[2])
    )
    assert head_hex in colours


def test_nominal_head_fixates_and_skewed_eyes_are_reported_unreachable() -> None:
    summary = build_view(static_visualizer(), "iis_head", target=TARGET, sweep=False)
    assert summary.gaze is not None and summary.gaze.reachable
    assert summary.gaze.pointing_error.max() < 1e-9
    assert "fixated" in summary.format()
    skewed = calibrated_head(joints=("vergence_left", "vergence_right"))
    vis = static_visualizer()
    summary = build_view(vis, skewed, target=TARGET, sweep=False)
    assert summary.gaze is not None and not summary.gaze.reachable
    assert "reachable=False" in summary.format()
    assert summary.gaze.pointing_error.min() > 1e-6
    assert "object" in decoded(vis.window)["/meshcat/head/camera_left_optical/ray"]


def test_residuals_agree_with_the_cpc_model() -> None:
    nominal = load_model("iis_head")
    ms = measurements_of(nominal)
    # Viewing the model that made the measurements: zero residuals.
    vis = static_visualizer()
    s0 = build_view(vis, nominal, measurements=ms, sweep=False)
    assert s0.n_measured == 2 * len(ms) and s0.residual_max < 1e-12
    # A calibrated (different) head: the residuals are the CPC model's prediction errors.
    cal = calibrated_head()
    vis = static_visualizer()
    s1 = build_view(vis, cal, measurements=ms, ghost="iis_head", sweep=False)
    pred = cal.fk(ms.q, ["plate_left", "plate_right"])
    r = np.concatenate(
        [
            np.linalg.norm(pred[f][:, :3, 3] - ms.poses[f][:, :3, 3], axis=1)
            for f in ("plate_left", "plate_right")
        ]
    )
    assert math.isclose(s1.residual_max, r.max(), rel_tol=1e-9)
    assert math.isclose(s1.residual_rms, math.sqrt(np.mean(r**2)), rel_tol=1e-9)
    scene = decoded(vis.window)
    bars = [
        p for p in scene if p.startswith("/meshcat/measurements/residual/") and p.count("/") == 4
    ]
    assert len(bars) == len(r)
    lengths = sorted(scene[p]["object"]["geometries"][0]["height"] for p in bars)
    assert np.allclose(lengths, np.sort(r) * s1.residual_scale, rtol=1e-6)
    ghosts = [p for p in scene if p.startswith("/meshcat/ghost/") and "object" in scene[p]]
    assert ghosts and all(scene[p]["object"]["materials"][0]["opacity"] < 1 for p in ghosts)
    # A missing pose (NaN) is skipped, not drawn.
    ms.poses["plate_left"][0] = np.nan
    s2 = build_view(static_visualizer(), cal, measurements=ms, sweep=False)
    assert s2.n_measured == 2 * len(ms) - 1


def test_sweep_starts_at_the_shown_configuration_and_loads_last(tmp_path: Path) -> None:
    html_path = tmp_path / "v.html"
    summary = write_view_html(html_path, "iis_head", target=TARGET)
    html = html_path.read_text()
    # Self-contained: no external script, stylesheet or fetch of anything but inline data.
    assert "<script src" not in html and "<link" not in html
    blobs = re.findall(r'^"([A-Za-z0-9+/=]+)"', html, flags=re.M)
    commands = [umsgpack.unpackb(__import__("base64").b64decode(b)) for b in blobs]
    assert commands[-1]["type"] == "set_animation"  # after every object it animates
    assert commands[-1]["options"]["play"] is False  # the page opens in the gaze configuration
    anims = commands[-1]["animations"]
    shown = load_view_robot("iis_head").link_poses(np.array(list(summary.q.values())))
    for a in anims:
        link = a["path"].split("/")[-1]
        track = {t["name"]: t["keys"] for t in a["clip"]["tracks"]}
        assert np.allclose(track[".position"][0]["value"], shown[link][:3, 3], atol=1e-9)
        assert len(track[".position"]) > 20


def test_bad_input_is_rejected_clearly(tmp_path: Path) -> None:
    with pytest.raises(ConfigurationError, match="three numbers"):
        build_view(static_visualizer(), "iis_head", target=[1.0, 2.0])
    with pytest.raises(ConfigurationError, match="finite"):
        build_view(static_visualizer(), "iis_head", target=[1.0, float("nan"), 2.0])
    with pytest.raises(UnknownNameError, match="unknown frame 'eye'"):
        build_view(
            static_visualizer(), "iis_head", target=TARGET, cameras=("camera_left_optical", "eye")
        )
    with pytest.raises(UnknownNameError, match="unknown joint 'neck'"):
        build_view(static_visualizer(), "iis_head", q={"neck": 0.1})
    with pytest.raises(ConfigurationError, match="outside its limits"):
        build_view(static_visualizer(), "iis_head", q={"pan": -1.0})
    with pytest.raises(InputFileError, match="no such file"):
        load_view_robot(tmp_path / "missing.urdf")
    bad = tmp_path / "bad.urdf"
    bad.write_text("<robot name='x'><link name='a'/><joint name='j' type='revolute'>")
    with pytest.raises(InputFileError, match="bad.urdf"):
        load_view_robot(bad)
    # Measurements of frames the viewed robot lacks.
    no_plates = load_model("iis_head").without_frames(["plate"])
    with pytest.raises(UnknownNameError, match="plate_left"):
        build_view(
            static_visualizer(),
            no_plates,
            measurements=measurements_of(load_model("iis_head"), n=2),
        )


def test_plain_urdf_gets_triads_from_frame_names(tmp_path: Path) -> None:
    urdf = write_urdf(calibrated_head(), tmp_path / "head.urdf")
    robot = load_view_robot(urdf)
    assert robot.kinds["plate_left"] == "plate" and robot.kinds["camera_right_optical"] == "camera"
    vis = static_visualizer()
    build_view(vis, robot, q={"pan": 1.2}, sweep=False)
    scene = decoded(vis.window)
    assert "object" in scene["/meshcat/head/camera_left_optical/triad/z"]


# ---- the page in a real browser ---------------------------------------------------------------


@pytest.mark.slow
def test_page_in_headless_chromium(tmp_path: Path) -> None:
    """The page shows the head, target, ghost and residual bars; its sweep really moves the
    head (pressing play, scripted)."""
    require_chromium()
    cal = calibrated_head()
    html = tmp_path / "view.html"
    ms = measurements_of(load_model("iis_head"), n=6)
    summary = write_view_html(
        html, cal, target=TARGET, ghost="iis_head", measurements=ms, change_colours=False
    )
    still = screenshot_html(html, tmp_path / "still.png", size=SIZE)
    check_picture(still, summary, target=True, ghost=True)
    img = matplotlib.image.imread(str(still))[..., :3]
    assert colour_mask(img, (0.95, 0.05, 0.1), hue_tol_deg=8.0).sum() > 50  # the longest bar, red
    assert summary.residual_max > 0.005  # [m]: the calibrated neck moves the plates

    marker = 'document.title = "cpc2urdf view (loaded)";'
    played = tmp_path / "played.html"
    # Play, then hold the sweep at 1.5 s: the first joint (table_x) at q0 - 40 % of its range.
    # (A free-running sweep screenshot depends on how long the page took to load.)
    seek = " viewer.animator.play(); viewer.animator.pause(); viewer.animator.seek(1.5);"
    played.write_text(html.read_text().replace(marker, marker + seek))
    moved = matplotlib.image.imread(str(screenshot_html(played, tmp_path / "moved.png", size=SIZE)))
    head_still = colour_mask(img, HEAD_RGBA)
    head_moved = colour_mask(moved[..., :3], HEAD_RGBA)
    # At 1.5 s into the sweep the table has moved: the head's pixels are elsewhere, the
    # target (not animated) is not (only the rays ending on it moved).
    assert (head_still ^ head_moved).sum() > 0.3 * head_still.sum()
    u, v = summary.pixel(TARGET, *SIZE)
    rows, cols = np.mgrid[: SIZE[1], : SIZE[0]]
    near = (rows - v) ** 2 + (cols - u) ** 2 < 40.0**2  # [px]: the target sphere's neighbourhood
    t_still = np.argwhere(colour_mask(img, TARGET_RGBA) & near)
    t_moved = np.argwhere(colour_mask(moved[..., :3], TARGET_RGBA) & near)
    assert len(t_moved) > 0.8 * len(t_still) > 80
    assert np.linalg.norm(t_still.mean(axis=0) - t_moved.mean(axis=0)) < 3.0  # [px]


ARM_URDF = """<?xml version="1.0"?>
<robot name="arm">
  <material name="blue"><color rgba="0.15 0.35 0.85 1"/></material>
  <link name="base"><visual><geometry><box size="0.2 0.2 0.05"/></geometry><material name="blue"/></visual></link>
  <joint name="slide" type="prismatic"><parent link="base"/><child link="l1"/><axis xyz="1 0 0"/>
    <limit lower="-0.2" upper="0.2" effort="1" velocity="1"/></joint>
  <link name="l1"><visual><origin xyz="0 0 0.1"/><geometry><cylinder radius="0.03" length="0.2"/></geometry>
    <material name="blue"/></visual></link>
  <joint name="turn" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0 0 0.2"/><axis xyz="0 1 0"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  <link name="l2"><visual><origin xyz="0 0 0.1"/><geometry><sphere radius="0.05"/></geometry></visual></link>
</robot>
"""


def test_any_urdf_robot(tmp_path: Path) -> None:
    """Not a head: world z stays up, the whole robot is framed, visuals sit where Pinocchio says."""
    path = tmp_path / "arm.urdf"
    path.write_text(ARM_URDF)
    vis = static_visualizer()
    summary = build_view(vis, path, q={"slide": 0.1, "turn": 0.5})
    assert np.allclose(summary.up, [0.0, 0.0, 1.0])
    scene = decoded(vis.window)
    T_l2 = scene["/meshcat/head/l2"]["transform"]
    # l2 = Trans(0.1, 0, 0) Trans(0, 0, 0.2) Rot(y, 0.5); its sphere 0.1 m along its z.
    c, s = math.cos(0.5), math.sin(0.5)
    assert np.allclose(T_l2[:3, 3], [0.1, 0.0, 0.2]) and np.allclose(
        T_l2[:3, :3], [[c, 0, s], [0, 1, 0], [-s, 0, c]]
    )
    sphere = [p for p in scene if p.startswith("/meshcat/head/l2/") and "object" in scene[p]]
    assert len(sphere) == 1 and np.allclose(scene[sphere[0]]["transform"][:3, 3], [0.0, 0.0, 0.1])
    # Every link origin is in front of the viewer camera and on screen.
    for link in ("base", "l1", "l2"):
        u, v = summary.pixel(scene[f"/meshcat/head/{link}"]["transform"][:3, 3])
        assert 0 < u < SIZE[0] and 0 < v < SIZE[1]
    path.write_text(ARM_URDF.replace("</robot>", ""))
    with pytest.raises(InputFileError, match="not well-formed XML"):
        load_view_robot(path)
    # A continuous joint is an unlimited revolute joint: shown at 0, swept +-pi.
    path.write_text(ARM_URDF.replace('type="revolute"', 'type="continuous"'))
    robot = load_view_robot(path)
    assert robot.pinocchio.continuous_joints == ("turn",)
    assert robot.pinocchio.upper[1] == math.inf and (robot.lower[1], robot.upper[1]) == (
        -math.pi,
        math.pi,
    )
    assert build_view(static_visualizer(), robot).q["turn"] == 0.0
    path.write_text(ARM_URDF.replace('type="revolute"', 'type="planar"'))
    with pytest.raises(InputFileError, match="joint 'turn' is planar"):
        load_view_robot(path)


# ---- meshes and change colours in a real browser ----------------------------------------------


def hue_mask(img: np.ndarray, rgba: tuple[float, ...], hue_tol_deg: float = 12.0) -> np.ndarray:
    """:func:`colour_mask` for colours of any brightness (dark or light, saturated)."""
    hsv = rgb_to_hsv(np.clip(img[..., :3], 0.0, 1.0))
    h0 = colorsys.rgb_to_hsv(*rgba[:3])[0]
    dh = np.abs((hsv[..., 0] - h0 + 0.5) % 1.0 - 0.5) * 360.0
    return (dh < hue_tol_deg) & (hsv[..., 1] > 0.5) & (hsv[..., 2] > 0.3)


def near(mask: np.ndarray, uv: tuple[float, float], radius: float = 50.0) -> int:
    """How many pixels of ``mask`` lie within ``radius`` [px] of ``uv`` (column, row)."""
    rows, cols = np.mgrid[: mask.shape[0], : mask.shape[1]]
    return int((mask & ((cols - uv[0]) ** 2 + (rows - uv[1]) ** 2 < radius**2)).sum())


@pytest.mark.slow
def test_tiago_meshes_in_headless_chromium(tmp_path: Path) -> None:
    """TIAGo (example-robot-data, 44 STL meshes under package://) drawn from its own meshes:
    the robot covers a plausible area, its orange base ring is where its base link projects, and
    its dark arm and white torso are there."""
    require_chromium()
    from test_view_meshes import TIAGO

    html = tmp_path / "tiago.html"
    tiago = load_view_robot(TIAGO)
    summary = write_view_html(html, tiago, sweep=False)
    img = matplotlib.image.imread(str(screenshot_html(html, tmp_path / "tiago.png", size=SIZE)))[
        ..., :3
    ]
    # The background is a vertical gradient: each row's most common colour.
    background = np.array([np.median(row, axis=0) for row in img])[:, None, :]
    robot = np.abs(img - background).max(axis=2) > 0.06
    ys, xs = np.nonzero(robot)
    assert 0.05 < robot.mean() < 0.6, f"robot covers {robot.mean():.1%}"
    assert ys.max() - ys.min() > 0.6 * SIZE[1] and xs.max() - xs.min() > 0.3 * SIZE[0]
    orange = hue_mask(img, (1.0, 0.5088, 0.0468))  # the URDF's "Orange" of base_cover_link
    T = tiago.link_poses(np.array(list(summary.q.values())))
    assert orange.sum() > 2000
    assert (
        near(orange, summary.pixel(T["base_cover_link"][:3, 3], *SIZE), 200.0) > 0.8 * orange.sum()
    )
    robot[:30] = False  # meshcat's "Open Controls" bar
    dark = (img.max(axis=2) < 0.2) & robot  # Hey5DarkGrey / FlatBlack arm, hand, torso
    white = (img.min(axis=2) > 0.85) & robot & (np.ptp(img, axis=2) < 0.05)  # "White" shells
    assert dark.sum() > 3000 and white.sum() > 8000, (dark.sum(), white.sum())


@pytest.mark.slow
def test_change_colours_in_headless_chromium(tmp_path: Path) -> None:
    """A head whose tilt joint moved 12 mm against the nominal one: the links below tilt red,
    those above green, where they project; the legend's green-yellow-red bar in the page."""
    require_chromium()
    from test_view_change import shifted_tilt

    from cpc2urdf.validation.view.change import GREEN_RGBA, RED_RGBA, YELLOW_RGBA

    html = tmp_path / "change.html"
    cal = load_view_robot(shifted_tilt())
    summary = write_view_html(html, cal, ghost="iis_head", sweep=False)
    img = matplotlib.image.imread(str(screenshot_html(html, tmp_path / "change.png", size=SIZE)))[
        ..., :3
    ]
    T = cal.link_poses(np.array(list(summary.q.values())))
    red, green = (
        hue_mask(img, RED_RGBA, 10.0),
        hue_mask(img, GREEN_RGBA, 30.0),
    )  # under the ghost: bluer
    # (The triads' thin red and green axes are there too, whatever the change.)
    for link in ("plate_left", "camera_left"):  # below tilt: moved 12 mm
        uv = summary.pixel(T[link][:3, 3], *SIZE)
        assert near(red, uv) > 1500 and near(red, uv) > 3 * near(green, uv), link
    for link in ("base", "pan_link"):  # above tilt: did not move
        uv = summary.pixel(T[link][:3, 3], *SIZE)
        assert near(green, uv) > 1500 and near(green, uv) > 3 * near(red, uv), link
    # The legend's bar: one row of the lower left, green at its left end, yellow in the middle,
    # red at its right end.
    yellow = hue_mask(img, YELLOW_RGBA, 10.0)
    bar_rows = [
        y
        for y in range(SIZE[1] // 2, SIZE[1])
        if green[y, 20:30].all() and yellow[y, 175:190].all() and red[y, 335:345].all()
    ]
    assert bar_rows, "no legend bar"
