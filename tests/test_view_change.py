"""How far calibration moved each link (calibrated vs nominal, links matched by name): the rule,
the colour scale, the numbers in the ViewSummary against the CPC model's own FK, the colours in
the scene and the legend in the page."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from test_view import calibrated_head, decoded

from cpc2urdf.files.robot_ref import load_model
from cpc2urdf.model import CPCParams
from cpc2urdf.urdf.document import HEAD_RGBA
from cpc2urdf.validation.view import (
    CHANGE_GHOST_RGBA,
    CHANGE_GREEN,
    CHANGE_LEVER,
    CHANGE_RED,
    GHOST_RGBA,
    build_view,
    change_rgba,
    load_view_robot,
    static_view_html,
    static_visualizer,
)
from cpc2urdf.validation.view.change import (
    GREEN_RGBA,
    RED_RGBA,
    UNMATCHED_RGBA,
    YELLOW_RGBA,
    link_change,
)
from cpc2urdf.validation.view.geometry import hex_colour

FRAMES = ("plate_left", "plate_right", "camera_left_optical", "camera_right_optical")


def pose(
    rotvec: tuple[float, float, float] = (0, 0, 0), p: tuple[float, float, float] = (0, 0, 0)
) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    T[:3, 3] = p
    return T


def test_rule_translation_rotation_and_size() -> None:
    T_nom = pose((0.3, -0.2, 0.1), (0.5, 0.1, 0.9))
    # A pure translation moves every point alike.
    c = link_change("a", pose(p=(0.002, 0, 0)) @ T_nom, T_nom, np.zeros((0, 3)))
    assert c.translation == pytest.approx(0.002, abs=1e-15) and c.rotation == pytest.approx(
        0, abs=1e-15
    )
    assert c.displacement == pytest.approx(0.002, abs=1e-15)
    # A rotation about the link origin moves a point at r by 2 r sin(theta / 2): the farthest
    # visual corner (0.3 m) when the link is big, the 0.1 m lever when it has no visuals.
    theta = math.radians(1.0)
    T_cal = T_nom @ pose((0, 0, theta))
    big = link_change("b", T_cal, T_nom, np.array([[0.3, 0.0, 0.0], [0.0, 0.05, 0.0]]))
    bare = link_change("c", T_cal, T_nom, np.zeros((0, 3)))
    assert big.rotation == pytest.approx(theta, rel=1e-12) and big.translation < 1e-15
    assert big.displacement == pytest.approx(2 * 0.3 * math.sin(theta / 2), rel=1e-12)
    assert bare.displacement == pytest.approx(2 * CHANGE_LEVER * math.sin(theta / 2), rel=1e-12)
    assert (
        abs(bare.displacement - 1.75e-3) < 5e-5
    )  # the documented "1 deg ~ 1.7 mm" (0.1 m x 1 deg)
    # Tiny rotations keep their precision (no arccos near 1).
    tiny = link_change("d", T_nom @ pose((1e-9, 0, 0)), T_nom, np.zeros((0, 3)))
    assert tiny.rotation == pytest.approx(1e-9, rel=1e-6)


def test_colour_scale() -> None:
    assert change_rgba(0.0) == change_rgba(0.5e-3) == change_rgba(CHANGE_GREEN) == GREEN_RGBA
    assert change_rgba(CHANGE_RED) == change_rgba(1.0) == RED_RGBA
    assert np.allclose(change_rgba(math.sqrt(CHANGE_GREEN * CHANGE_RED)), YELLOW_RGBA)
    d = np.geomspace(CHANGE_GREEN, CHANGE_RED, 50)
    rgb = np.array([change_rgba(x)[:3] for x in d])
    # Green -> yellow: red rises; yellow -> red: green falls.
    assert np.all(np.diff(rgb[:25, 0]) >= 0) and np.all(np.diff(rgb[25:, 1]) <= 0)


def shifted_tilt(dx: float = 0.012) -> object:
    """The nominal IIS-head with the tilt joint's position moved ``dx`` [m] (x): every link
    below tilt moves by the same translation; nothing above it moves."""
    m = load_model("iis_head")
    p = m.joints["tilt"]
    return m.with_params(joints={"tilt": CPCParams(p.b, p.beta, tuple(np.array(p.l) + [dx, 0, 0]))})


def link_colours(scene: dict[str, dict[str, object]]) -> dict[str, set[int]]:
    out: dict[str, set[int]] = {}
    for path, e in scene.items():
        parts = path.split("/")
        if (
            len(parts) == 5
            and parts[2] == "head"
            and "object" in e
            and parts[4] not in ("triad", "ray")
        ):
            out.setdefault(parts[3], set()).add(e["object"]["materials"][0]["color"])  # type: ignore[index]
    return out


def test_summary_numbers_agree_with_the_cpc_model() -> None:
    cal = calibrated_head(seed=3, joints=("pan", "tilt"))
    nominal = load_model("iis_head")
    vis = static_visualizer()
    q = {"pan": 1.2, "tilt": 0.4}
    summary = build_view(vis, cal, q=q, ghost=nominal, sweep=False)
    qv = np.array([summary.q[j] for j in cal.structure.joint_names])
    T_cal, T_nom = cal.fk(qv), nominal.fk(qv)
    for f in FRAMES:
        c = summary.link_changes[f]
        assert c.translation == pytest.approx(
            np.linalg.norm(T_cal[f][:3, 3] - T_nom[f][:3, 3]), abs=1e-9
        )
        angle = Rotation.from_matrix(T_nom[f][:3, :3].T @ T_cal[f][:3, :3]).magnitude()
        assert c.rotation == pytest.approx(angle, abs=1e-9)
        assert c.translation <= c.displacement <= c.translation + 2 * math.sin(c.rotation / 2) * 1.0
    # The root does not move; each link is painted with the colour of its own change.
    assert summary.link_changes["base"].displacement < 1e-12
    colours = link_colours(decoded(vis.window))
    for link, c in summary.link_changes.items():
        if link in colours:
            assert colours[link] == {hex_colour(change_rgba(c.displacement))}, link
    assert "calibration moved" in summary.format()


def test_shifted_tilt_colours_and_ghost() -> None:
    vis = static_visualizer()
    robot = load_view_robot(shifted_tilt())
    summary = build_view(vis, robot, ghost="iis_head", sweep=False)
    moved = {ln for ln, c in summary.link_changes.items() if c.displacement > 1e-9}
    assert moved == set(robot.links_below("tilt")) and set(FRAMES) <= moved
    # Both in one world (their bases coincide): compared there, not re-aligned.
    assert summary.ghost_anchor == "base" and not summary.ghost_aligned
    assert all(summary.link_changes[ln].displacement < 1e-12 for ln in set(robot.links) - moved)
    for ln in moved:
        c = summary.link_changes[ln]
        assert c.displacement == pytest.approx(0.012, abs=1e-9) and c.rotation < 1e-12
    scene = decoded(vis.window)
    colours = link_colours(scene)
    assert colours["plate_left"] == {hex_colour(RED_RGBA)}
    assert colours["base"] == {hex_colour(GREEN_RGBA)}
    ghosts = {
        e["object"]["materials"][0]["color"]
        for p, e in scene.items()
        if p.startswith("/meshcat/ghost/") and "object" in e
    }  # type: ignore[index]
    assert ghosts == {hex_colour(CHANGE_GHOST_RGBA)}  # not on the green-yellow-red scale
    # Links the ghost lacks are grey and listed.
    vis = static_visualizer()
    s2 = build_view(
        vis, shifted_tilt(), ghost=load_model("iis_head").without_frames(["plate"]), sweep=False
    )
    assert set(s2.unmatched_links) == {"plate_left", "plate_right"}
    assert link_colours(decoded(vis.window))["plate_left"] == {hex_colour(UNMATCHED_RGBA)}
    # Keeping the URDF colours: no numbers, the head's own colour, the ghost green.
    vis = static_visualizer()
    s3 = build_view(vis, shifted_tilt(), ghost="iis_head", sweep=False, change_colours=False)
    assert not s3.link_changes and "translucent green" in s3.format()
    assert hex_colour(HEAD_RGBA) in set().union(*link_colours(decoded(vis.window)).values())
    assert hex_colour(GHOST_RGBA) in {
        e["object"]["materials"][0]["color"]
        for p, e in decoded(vis.window).items()
        if p.startswith("/meshcat/ghost/") and "object" in e
    }  # type: ignore[index]


def test_legend_in_the_page_only_with_a_ghost() -> None:
    html, summary = static_view_html(shifted_tilt(), ghost="iis_head", sweep=False)
    assert 'id="cpc2urdf-legend"' in html and "How far calibration moved each link" in html
    top = summary.largest_changes(1)[0]
    assert top.link in html and f"{1e3 * top.displacement:.3g} mm" in html
    html, _ = static_view_html(shifted_tilt(), sweep=False)
    assert "cpc2urdf-legend" not in html
