"""The reachable region in the 3D view (cpc2urdf/validation/view/region.py, ``cpc2urdf reach
--html``): every target drawn where the solver put it, in its category's colour, checked in the
recorded scene; a model identified from a user's URDF (drawn in the URDF's root frame and names)
gets the region at the same place relative to its camera; and the page in headless Chromium shows
the fixated points where the viewer camera projects them."""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace

import matplotlib.image
import numpy as np
import pytest
from test_view import SIZE, decoded, hue_mask, require_chromium

from cpc2urdf.api import write_view
from cpc2urdf.cli import main
from cpc2urdf.files.robot_ref import load_model
from cpc2urdf.validation.gaze import GazeSolver, solver_for
from cpc2urdf.validation.gaze.chain import mid_limits
from cpc2urdf.validation.gaze.reachable import (
    CATEGORY_COLOURS,
    REGION_CATEGORIES,
    make_grid,
    reachable_region,
)
from cpc2urdf.validation.view import (
    build_view,
    load_view_robot,
    screenshot_html,
    static_view_html,
    static_visualizer,
)
from cpc2urdf.validation.view.region import (
    OTHER_OPACITY,
    POINTED,
    REGION_NODE,
    framing_points,
    point_sizes,
)

CAMERAS = ("camera_left_optical", "camera_right_optical")


def clouds(window: object) -> dict[str, list[dict[str, object]]]:
    """Category -> its drawn clouds in grid order (``reach/<category>/<k>``, k the grid's first
    axis), each {"k": k, "position": (K, 3), "color": (K, 3), "material": dict}."""
    out: dict[str, list[dict[str, object]]] = {}
    for path, entry in decoded(window).items():
        parts = path.split("/")
        if len(parts) == 5 and parts[2] == REGION_NODE and "object" in entry:
            obj = entry["object"]
            attrs = obj["geometries"][0]["data"]["attributes"]  # type: ignore[index]
            arrays = {
                k: np.frombuffer(attrs[k]["array"].data, dtype=np.float32).reshape(-1, 3)  # type: ignore[index]
                for k in ("position", "color")
            }
            out.setdefault(parts[3], []).append(
                {"k": int(parts[4]), **arrays, "material": obj["materials"][0]}
            )  # type: ignore[index]
    return {c: sorted(v, key=lambda e: e["k"]) for c, v in out.items()}


def positions(cloud_list: list[dict[str, object]]) -> np.ndarray:
    return np.concatenate([c["position"] for c in cloud_list])  # type: ignore[misc]


@pytest.fixture(scope="module")
def nominal_region():
    solver = GazeSolver.from_model(load_model("iis_head"))
    return reachable_region(solver, make_grid(solver, "shell", 0.3, 2.5, (4, 9, 7)))


def test_every_target_is_drawn_where_the_solver_put_it(nominal_region):
    """The IIS-head's spec: solver and view load one model, so each category's cloud holds
    exactly its targets, at their points (float32), in the PNG's colour; the fixated ones opaque,
    the others (not pointed at) translucent; the summary and the page's legend give the counts."""
    r = nominal_region
    vis = static_visualizer()
    page, summary = static_view_html(
        load_view_robot("iis_head"), region=r, sweep=False, region_notes=["moving pan, tilt"]
    )
    build_view(vis, "iis_head", region=r, sweep=False)
    drawn = clouds(vis.window)
    counts = r.counts()
    assert 0 < counts["fixated"] < r.points.shape[0] and counts["joint_limits"] > 0
    assert set(drawn) == {c for c, k in counts.items() if k}
    distance = np.linalg.norm(r.grid.points_head, axis=1)
    sizes = point_sizes(r)
    for k, name in enumerate(REGION_CATEGORIES):
        if name not in drawn:
            continue
        mask = r.category == k
        np.testing.assert_allclose(positions(drawn[name]), r.points[mask], atol=1e-6)
        for cloud in drawn[name]:
            P = cloud["position"]
            np.testing.assert_allclose(
                cloud["color"], np.tile(CATEGORY_COLOURS[name], (len(P), 1)), atol=1e-7
            )
            # each cloud holds one shell: its distance, its point size
            d = distance[mask][np.isclose(distance[mask], r.grid.axes[0][cloud["k"]])]
            assert len(d) == len(P)
            material = cloud["material"]
            assert material["size"] == pytest.approx(sizes[cloud["k"]])
            assert material.get("opacity", 1.0) == (1.0 if name in POINTED else OTHER_OPACITY)
    assert summary.region is not None and summary.region.counts == counts
    assert summary.region.offset < 1e-12  # one model: the same world
    assert (
        f"fixated: {counts['fixated']}" in page
        and f"joint limits: {counts['joint_limits']}" in page
    )
    assert "moving pan, tilt" in page and "reachable region" in summary.format()
    # 0.4 of the smaller angular spacing (elevation: 20 deg; azimuth 22.5 deg) at each distance,
    # at most 0.8 of the distances' spacing (0.733 m) and 0.05 of the far range (2.5 m)
    np.testing.assert_allclose(sizes, np.minimum(0.4 * r.grid.axes[0] * math.radians(20.0), 0.125))
    dense = make_grid(GazeSolver.from_model(load_model("iis_head")), "shell", 0.2, 3.0, (101, 9, 7))
    radial = point_sizes(SimpleNamespace(grid=dense))  # type: ignore[arg-type]
    assert radial.max() == pytest.approx(0.8 * 0.028)  # 101 distances 28 mm apart
    assert summary.region.point_sizes == pytest.approx((sizes.min(), sizes.max()))


def test_the_view_frames_the_whole_region(nominal_region):
    """The outer faces of the grid frame the view: every target's extreme along each head axis
    is among them, and every target projects into the screenshot's window."""
    r = nominal_region
    outer = framing_points(r, r.points)
    ph = r.grid.frame.from_world(outer)
    assert np.allclose(ph.max(axis=0), r.grid.points_head.max(axis=0))
    assert np.allclose(ph.min(axis=0), r.grid.points_head.min(axis=0))
    _, summary = static_view_html(load_view_robot("iis_head"), region=r, sweep=False)
    uv = np.array([summary.pixel(p, *SIZE) for p in r.points])
    assert (uv >= 0).all() and (uv[:, 0] <= SIZE[0]).all() and (uv[:, 1] <= SIZE[1]).all()


def test_a_model_identified_from_a_users_urdf_gets_the_region_on_its_camera(tmp_path: Path) -> None:
    """TIAGo identified with a plate (its frame pointed as the 'camera'): the view draws the
    written-back URDF in its root link's frame and names (torso_lift_joint, not torso_lift); the
    region is drawn at the same place relative to that frame as the solver put it relative to the
    model's, at the home posture; the change of world between the two is reported."""
    from test_view_meshes import SHARE
    from test_view_writeback import identified_tiago

    _, model, model_file = identified_tiago(tmp_path)
    solver = solver_for(model_file, ("calib_plate",))
    r = reachable_region(solver, make_grid(solver, "shell", 0.5, 2.0, (3, 7, 5)))
    robot = load_view_robot(model_file, package_dirs=[SHARE])
    assert "torso_lift_joint" in robot.joint_names and "torso_lift" in solver.joint_names
    vis = static_visualizer()
    summary = build_view(vis, robot, region=r, cameras=("calib_plate",), sweep=False)
    drawn_clouds = clouds(vis.window)
    drawn = np.concatenate(
        [positions(drawn_clouds[c]) for c in REGION_CATEGORIES if c in drawn_clouds]
    )
    order = np.concatenate([np.flatnonzero(r.category == k) for k in range(len(REGION_CATEGORIES))])
    T_view = robot.link_poses(robot.default_q())["calib_plate"]
    T_model = model.fk(mid_limits(solver.lower, solver.upper), ["calib_plate"])["calib_plate"]
    in_view = (drawn.astype(float) - T_view[:3, 3]) @ T_view[:3, :3]
    in_model = (r.points[order] - T_model[:3, 3]) @ T_model[:3, :3]
    np.testing.assert_allclose(in_view, in_model, atol=2e-6)  # float32 points
    moved = np.linalg.norm((r.points[order] - drawn.astype(float)), axis=1).max()
    assert summary.region is not None and summary.region.offset == pytest.approx(moved, abs=1e-5)
    assert (
        moved > 1e-3
        and f"{1e3 * summary.region.offset:.3g} mm from the solver's" in summary.region.moved()
    )
    assert summary.region.moved() in summary.format()


@pytest.mark.slow
def test_cli_reach_html_and_the_page_in_headless_chromium(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``reach --html --screenshot`` writes the PNG, the page and its picture; in the picture the
    fixated targets are green where the viewer camera projects them, and the translucent
    joint-limit ones blue; the legend is in the page."""
    require_chromium()
    args = ["--samples", "4", "9", "7", "--range", "0.3", "2.5"]
    png, page, shot = tmp_path / "r.png", tmp_path / "r.html", tmp_path / "v.png"
    assert (
        main(
            [
                "reach",
                "iis_head",
                *args,
                "-o",
                str(png),
                "--html",
                str(page),
                "--screenshot",
                str(shot),
            ]
        )
        == 0
    )
    out = capsys.readouterr().out
    assert f"{page}: the region in the 3D view" in out and str(shot) in out
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.html", "r.png", "v.png"]
    text = page.read_text()
    assert (
        "reachable region" in text
        and "fixated: " in text
        and "moving pan, tilt, vergence_left" in text
    )
    # the same page through the API, for where each target lands on screen
    solver = GazeSolver.from_model(load_model("iis_head"))
    r = reachable_region(solver, make_grid(solver, "shell", 0.3, 2.5, (4, 9, 7)))
    summary = write_view("iis_head", tmp_path / "api.html", region=r)
    assert summary.region is not None and summary.region.counts == r.counts()
    img = matplotlib.image.imread(
        str(screenshot_html(tmp_path / "api.html", tmp_path / "api.png", size=SIZE))
    )[..., :3]
    # green, also seen through the translucent blue points in front ((0.15, 0.58, 0.33))
    green = (img[..., 1] > img[..., 0] + 0.2) & (img[..., 1] > img[..., 2] + 0.1)
    blue = hue_mask(img, CATEGORY_COLOURS["joint_limits"], 15.0) | (
        (img[..., 2] > img[..., 0] + 0.08) & (img[..., 2] > img[..., 1] + 0.02)
    )  # blended with the background
    # the nearest shell (0.3 m) lies among the head's parts, which hide some of it
    away = np.linalg.norm(r.grid.points_head, axis=1) > 0.5
    fixated = (r.category == REGION_CATEGORIES.index("fixated")) & away

    def hits(mask: np.ndarray, points: np.ndarray) -> float:
        ok = []
        for p in points:
            u, v = summary.pixel(p, *SIZE)
            if (
                40 < v < SIZE[1] - 130 and 4 < u < SIZE[0] - 4
            ):  # away from the controls bar and the legends
                ok.append(mask[int(v) - 2 : int(v) + 3, int(u) - 2 : int(u) + 3].any())
        assert len(ok) > 20
        return float(np.mean(ok))

    assert hits(green, r.points[fixated]) > 0.95
    limits = (r.category == REGION_CATEGORIES.index("joint_limits")) & away
    assert hits(blue, r.points[limits]) > 0.5  # translucent, some behind fixated ones


@pytest.mark.parametrize(
    "extra, match",
    [
        (["--screenshot", "{d}/v.png"], "--screenshot needs --html"),
        (["--package-path", "{d}"], "--package-path needs --html"),
        (["--html", "{d}/v.html", "--screenshot", "{d}/r.png"], "the same file as -o"),
        (["--html", "{d}/v.html", "--json", "{d}/v.html"], "the same file as --json"),
        (["--html", "{d}/v.html", "--screenshot", "{d}/v.jpg"], "expected a .png path"),
        (["--html", "{d}/missing/v.html"], "missing"),
        (["--html", "{d}/v.txt"], "expected an .html path"),
    ],
)
def test_cli_reach_html_bad_input(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], extra: list[str], match: str
) -> None:
    argv = [
        "reach",
        "iis_head",
        "--samples",
        "2",
        "3",
        "3",
        "-o",
        str(tmp_path / "r.png"),
        *(a.format(d=tmp_path) for a in extra),
    ]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and match in err[0], err
    assert list(tmp_path.iterdir()) == []  # nothing written


def test_a_far_region_moves_the_viewer_cameras_far_plane() -> None:
    """meshcat's camera draws nothing beyond 100 m: a grid out to 1 km moves the far plane to
    twice the farthest target's distance from the viewer camera; the head's usual region keeps
    meshcat's own."""
    from cpc2urdf.validation.view.camera import VIEWER_FAR

    solver = GazeSolver.from_model(load_model("iis_head"))
    far: dict[float, object] = {}
    for reach_far in (3.0, 1000.0):
        r = reachable_region(
            solver, make_grid(solver, "shell", reach_far / 10, reach_far, (2, 5, 3))
        )
        vis = static_visualizer()
        summary = build_view(vis, "iis_head", region=r, sweep=False)
        props = decoded(vis.window)["/Cameras/default/rotated/<object>"]["properties"]
        far[reach_far] = [p["value"] for p in props if p["property"] == "far"]  # type: ignore[index]
        farthest = np.linalg.norm(r.points - summary.camera_position, axis=1).max()
    assert far[3.0] == []
    assert len(far[1000.0]) == 1 and far[1000.0][0] == pytest.approx(2 * farthest, rel=1e-6)  # type: ignore[index]
    assert far[1000.0][0] > 10 * VIEWER_FAR  # type: ignore[index]


def test_cli_reach_screenshot_without_chromium_fails_before_solving(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    from cpc2urdf.validation.gaze import reachable as reach

    monkeypatch.setenv("CPC2URDF_CHROMIUM", str(tmp_path / "no-chromium"))
    monkeypatch.setattr(
        reach, "reachable_region", lambda *a, **k: pytest.fail("solved before checking Chromium")
    )
    argv = [
        "reach",
        "iis_head",
        "-o",
        str(tmp_path / "r.png"),
        "--html",
        str(tmp_path / "r.html"),
        "--screenshot",
        str(tmp_path / "v.png"),
    ]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--screenshot needs Chromium" in err[0]
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("command", ["reach", "view"])
def test_a_failed_screenshot_writes_nothing_and_names_the_users_png(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
    command: str,
) -> None:
    """A Chromium that fails: one line naming the --screenshot path (not a temporary file), and
    neither the page nor anything else written (the page used to be written first)."""
    browser = tmp_path / "bin" / "chromium"
    browser.parent.mkdir()
    browser.write_text("#!/bin/sh\necho 'GPU process crashed' >&2\nexit 1\n")
    browser.chmod(0o755)
    monkeypatch.setenv("CPC2URDF_CHROMIUM", str(browser))
    out = tmp_path / "out"
    out.mkdir()
    extra = (
        ["--samples", "2", "3", "3", "-o", str(out / "r.png")]
        if command == "reach"
        else ["--no-sweep"]
    )
    argv = [
        command,
        "iis_head",
        *extra,
        "--html",
        str(out / "v.html"),
        "--screenshot",
        str(out / "v.png"),
    ]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert (
        len(err) == 1
        and f"{out / 'v.png'}: Chromium failed (exit 1): GPU process crashed" in err[0]
    ), err
    assert list(out.iterdir()) == []


def test_cli_view_reach_draws_reachs_default_region(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``view ROBOT --reach``: the default grid of ``reach``, solved on the robot as drawn, with
    the fixation of --target; the same counts as ``reach``'s JSON."""
    page = tmp_path / "v.html"
    assert (
        main(
            [
                "view",
                "iis_head",
                "--reach",
                "--target",
                "-0.3",
                "-0.4",
                "0.66",
                "--no-sweep",
                "--html",
                str(page),
            ]
        )
        == 0
    )
    out = capsys.readouterr().out
    assert (
        main(
            ["reach", "iis_head", "-o", str(tmp_path / "r.png"), "--json", str(tmp_path / "r.json")]
        )
        == 0
    )
    capsys.readouterr()
    import json

    counts = json.loads((tmp_path / "r.json").read_text())["counts"]
    from cpc2urdf.validation.view.region import COLOUR_NAMES

    parts = ", ".join(
        f"{k} {c.replace('_', ' ')} ({COLOUR_NAMES[c]})" for c, k in counts.items() if k
    )
    assert f"reachable region: {sum(counts.values())} targets (shell grid): {parts};" in out
    assert "target [-0.3  -0.4   0.66] m: fixated" in out
    text = page.read_text()
    assert (
        f"fixated: {counts['fixated']}" in text
        and "held where shown: table_x=0.5, table_y=0.25" in text
    )


def test_view_reach_holds_the_joints_where_shown(tmp_path: Path) -> None:
    """With --q moving a held joint (the IIS-head's table), the region is laid out about the
    cameras as drawn and solved with the table there: its origin is the drawn cameras' mid-point,
    and every fixated target is fixated by the answer's readings with the table where shown."""
    robot = load_view_robot("iis_head")
    shown = robot.q_from({"table_x": 0.0, "table_y": 0.0})
    solver = GazeSolver(robot.pinocchio, CAMERAS)
    r = reachable_region(
        solver, make_grid(solver, "shell", 0.4, 2.0, (3, 7, 5), q=shown), q_current=shown
    )
    vis = static_visualizer()
    summary = build_view(vis, robot, q={"table_x": 0.0, "table_y": 0.0}, region=r, sweep=False)
    T = robot.link_poses(shown)
    mid = 0.5 * (T[CAMERAS[0]][:3, 3] + T[CAMERAS[1]][:3, 3])
    np.testing.assert_allclose(r.grid.frame.origin, mid, atol=1e-12)
    assert summary.region is not None and summary.region.offset < 1e-12
    table = [robot.joint_names.index(j) for j in ("table_x", "table_y")]
    assert np.all(r.q[:, table] == 0.0)
    fixated = r.category == REGION_CATEGORIES.index("fixated")
    assert fixated.sum() > 20
    for q, p in zip(r.q[fixated], r.points[fixated], strict=True):
        Tq = robot.link_poses(q)
        for cam in CAMERAS:
            d = Tq[cam][:3, :3].T @ (p - Tq[cam][:3, 3])
            assert math.atan2(math.hypot(d[0], d[1]), d[2]) < 1e-8


def test_cli_view_reach_lays_the_grid_out_as_reach_does(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``--q`` holds the joints that do not move (the table) where shown; a moving one turned by
    --q (pan) does not turn the grid, nor does --target: the region is the one laid out with the
    moving joints at the middle of their limits (with pan turned the grid lost 166 fixated)."""
    page = tmp_path / "v.html"
    assert (
        main(
            [
                "view",
                "iis_head",
                "--reach",
                "--q",
                "table_x=0.1",
                "table_y=0.4",
                "pan=2.0",
                "--target",
                "-0.3",
                "-0.4",
                "0.66",
                "--no-sweep",
                "--html",
                str(page),
            ]
        )
        == 0
    )
    out = capsys.readouterr().out
    robot = load_view_robot("iis_head")
    posture = robot.q_from({"table_x": 0.1, "table_y": 0.4})
    solver = GazeSolver(robot.pinocchio, CAMERAS)
    r = reachable_region(solver, make_grid(solver, q=posture), q_current=posture)
    assert f"{r.counts()['fixated']} fixated (green)" in out
    assert (
        "held where shown: table_x=0.1, table_y=0.4" in out
        and "held where shown: table_x=0.1" in page.read_text()
    )
