"""The view of a model identified from a user's URDF (TIAGo, example-robot-data, with a plate):
the robot's own meshes on its calibrated links (the written-back URDF, in memory), the user's URDF
as the ghost, links coloured by how far calibration moved them, its measurements on its plate;
and a model against its own
gravity-aligned export: compared relative to ``base``, nothing moved."""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib.image
import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from test_view import SIZE, decoded, hue_mask, near, require_chromium
from test_view_meshes import SHARE
from urdf_cases import pinocchio_poses, simulate, tiago_with_plate

from cpc2urdf.cli import main
from cpc2urdf.files.measurements import load_measurements
from cpc2urdf.files.model_file import save_model
from cpc2urdf.files.robot_ref import load_model
from cpc2urdf.identification.kinematics.methods import identify
from cpc2urdf.model import CPCModel, CPCParams
from cpc2urdf.tolerances import FK_AGREEMENT_TOL
from cpc2urdf.urdf.origins import urdf_link_poses, writeback_plan
from cpc2urdf.urdf.robot import attach_urdf_source, load_urdf_robot
from cpc2urdf.validation.view import (
    build_view,
    change_rgba,
    load_view_robot,
    screenshot_html,
    static_view_html,
    static_visualizer,
    write_view_html,
)
from cpc2urdf.validation.view.change import GREEN_RGBA
from cpc2urdf.validation.view.view_robot import own_nominal

TIAGO_MESHES = SHARE / "example-robot-data" / "robots" / "tiago_description" / "meshes"


def identified_tiago(folder: Path) -> tuple[Path, CPCModel, Path]:
    """TIAGo with a ``calib_plate`` link (its URDF in ``folder``), the model identified from
    noise-free measurements of a perturbed truth of its head, and that model's file."""
    urdf = tiago_with_plate(folder)
    simulate(load_urdf_robot(urdf, ["calib_plate"]), np.random.default_rng(0), folder / "m.json")
    ms = load_measurements(folder / "m.json")
    model = attach_urdf_source(identify(ms), ms.spec)
    return urdf, model, save_model(model, folder / "model.json")


@pytest.fixture(scope="module")
def tiago(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, CPCModel, Path]:
    return identified_tiago(tmp_path_factory.mktemp("tiago_view"))


def test_meshes_sit_on_their_calibrated_links(tiago: tuple[Path, CPCModel, Path]) -> None:
    urdf, model, model_file = tiago
    robot = load_view_robot(model_file, package_dirs=[SHARE])
    ghost = load_view_robot(urdf, package_dirs=[SHARE])
    vis = static_visualizer()
    summary = build_view(vis, robot, ghost=ghost, sweep=False)
    # The robot's own 44 STL meshes, from their package.
    assert robot.meshes.n_meshes == 44
    assert all(
        m.path.is_file() and m.path.is_relative_to(TIAGO_MESHES.resolve())
        for m in robot.meshes.meshes
    )
    assert "written back into" in robot.source and robot.kinds["calib_plate"] == "plate"
    # Every link on the calibrated paths drawn where the model puts it (urdf_link_poses), every
    # ghost link where Pinocchio puts it in the user's own file, at the shown readings.
    plan = writeback_plan(model)
    q = [summary.q[plan.source.joints[n]] for n in model.structure.joint_names]
    model_poses = urdf_link_poses(model, plan, q)
    nominal = pinocchio_poses(urdf, summary.q, list(robot.links))
    scene = decoded(vis.window)
    assert list(model_poses) == [
        "base_footprint",
        "base_link",
        "torso_fixed_link",
        "torso_lift_link",
        "head_1_link",
        "head_2_link",
        "calib_plate",
    ]
    for link, T in model_poses.items():
        assert np.abs(scene[f"/meshcat/head/{link}"]["transform"] - T).max() < FK_AGREEMENT_TOL, (
            link
        )
    for link in robot.links:
        assert (
            np.abs(scene[f"/meshcat/ghost/{link}"]["transform"] - nominal[link]).max()
            < FK_AGREEMENT_TOL
        ), link
    assert any(
        p.startswith("/meshcat/head/head_2_link/") and "object" in e for p, e in scene.items()
    )
    # Colours by how far calibration moved each link: the user's root is the anchor (one world),
    # the head links moved by what the poses say, links no calibrated joint carries not at all.
    assert summary.ghost_anchor == "base_footprint" and not summary.ghost_aligned
    assert np.array_equal(summary.ghost_offset, np.eye(4))
    for link in ("head_1_link", "head_2_link", "calib_plate"):
        c = summary.link_changes[link]
        assert c.translation == pytest.approx(
            np.linalg.norm(model_poses[link][:3, 3] - nominal[link][:3, 3]), abs=1e-12
        )
        assert c.displacement > 1e-4
    for link in ("base_link", "wheel_left_link", "rgbd_laser_link", "torso_fixed_link"):
        assert summary.link_changes[link].displacement < 1e-12, link
    assert summary.link_changes["arm_1_link"].displacement > 1e-5  # carried by the torso lift
    assert not summary.unmatched_links


def test_cli_view_of_the_model_draws_the_meshes(
    tiago: tuple[Path, CPCModel, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    urdf, _, model_file = tiago
    html = tmp_path / "tiago.html"
    argv = ["view", str(model_file), "--nominal", str(urdf), "--no-sweep", "--html", str(html)]
    assert main(argv) == 2  # its meshes are under package://example-robot-data, not beside the copy
    err = capsys.readouterr().err
    assert (
        "no package 'example-robot-data'" in err
        and len(err.strip().splitlines()) == 1
        and not html.exists()
    )
    # --nominal without a value: the URDF the model was identified from.
    argv = [
        "view",
        str(model_file),
        "--nominal",
        "--package-path",
        str(SHARE),
        "--no-sweep",
        "--html",
        str(html),
    ]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert f"ghost: {urdf} (translucent blue" in out
    assert "visuals: 65, of which 44 meshes" in out and "all resolved" in out
    assert "ghost aligned: none, compared in one world ('base_footprint' 0 mm, 0 deg apart)" in out
    page = html.read_text()
    assert 'id="cpc2urdf-legend"' in page and "same joint readings, in one world" in page
    assert (
        main(["view", "iis_head", "--nominal", "--html", str(html)]) == 2
    )  # not identified from a URDF
    assert (
        "--nominal without OTHER is the URDF a model was identified from" in capsys.readouterr().err
    )


def rig_placed(model: CPCModel, dx: float = 0.0) -> CPCModel:
    """``model`` where a measuring rig sees it: 1.5 m away (plus ``dx`` [m] along x), its base
    tilted 122 deg (the demo's)."""
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(math.radians(122.0) * np.array([0.6, 0.0, 0.8])).as_matrix()
    T[:3, 3] = [0.2 + dx, -0.3, 1.5]
    return model.with_params(world_to_base=CPCParams.from_matrix(T))


@pytest.mark.parametrize("mount", ["base", "rig"])
def test_model_against_its_own_export_moved_nothing(
    mount: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The export's world is gravity-aligned at the base (or the rig): every link of the head is
    where the model puts it, aligned on ``base`` (the worlds above it not compared) or, with the
    rig, in the one world."""
    model_file = save_model(rig_placed(load_model("iis_head")), tmp_path / "model.json")
    exported = tmp_path / "head.urdf"
    assert main(["export", str(model_file), "-o", str(exported), "--mount", mount]) == 0
    capsys.readouterr()
    html, summary = static_view_html(str(model_file), ghost=str(exported), sweep=False)
    assert summary.ghost_anchor == "base" and summary.ghost_aligned == (mount == "base")
    offset = float(np.linalg.norm(summary.ghost_offset[:3, 3]))
    assert (
        offset > 1.0 if mount == "base" else offset < 1e-12
    )  # the worlds differ by the rig placement
    assert ("world" in summary.link_changes) == (mount == "rig") and not summary.unmatched_links
    assert len(summary.link_changes) == (13 if mount == "base" else 14)
    assert max(c.displacement for c in summary.link_changes.values()) < 1e-9
    assert (
        "relative to link base" if mount == "base" else "same joint readings, in one world"
    ) in html
    # The ghost is drawn where it is compared: on the head, link by link.
    vis = static_visualizer()
    build_view(vis, str(model_file), ghost=str(exported), sweep=False)
    scene = decoded(vis.window)
    for link in summary.link_changes:
        head, ghost = (
            scene[f"/meshcat/head/{link}"]["transform"],
            scene[f"/meshcat/ghost/{link}"]["transform"],
        )
        assert np.abs(head - ghost).max() < 1e-9, link


def test_one_world_unless_the_bases_are_worlds_apart(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """A model 10 mm from another in the same rig (a calibrated head and the true one): compared
    in that world, the 10 mm on every link; against the spec's nominal head (at the origin) the
    worlds are 1.5 m apart: aligned on base, nothing moved. --align overrides."""
    nominal = load_model("iis_head")
    near_a, near_b = rig_placed(nominal), rig_placed(nominal, dx=0.01)
    s = build_view(
        static_visualizer(), load_view_robot(near_a), ghost=load_view_robot(near_b), sweep=False
    )
    assert (
        not s.ghost_aligned and "compared in one world ('base' 10 mm, 0 deg apart)" in s.alignment()
    )
    assert all(
        c.translation == pytest.approx(0.01, abs=1e-12)
        for c in s.link_changes.values()
        if c.link != "world"
    )
    s = build_view(
        static_visualizer(),
        load_view_robot(near_a),
        ghost=load_view_robot(near_b),
        sweep=False,
        align="base",
    )
    assert s.ghost_aligned and max(c.displacement for c in s.link_changes.values()) < 1e-12
    s = build_view(static_visualizer(), load_view_robot(near_a), ghost="iis_head", sweep=False)
    assert s.ghost_aligned and max(c.displacement for c in s.link_changes.values()) < 1e-12
    s = build_view(
        static_visualizer(), load_view_robot(near_a), ghost="iis_head", sweep=False, align="world"
    )
    assert (
        not s.ghost_aligned
        and min(c.displacement for c in s.link_changes.values() if c.link != "world") > 1.0
    )
    model_file = save_model(near_a, tmp_path / "a.json")
    argv = [
        "view",
        str(model_file),
        "--nominal",
        "iis_head",
        "--no-sweep",
        "--html",
        str(tmp_path / "v.html"),
    ]
    assert main([*argv, "--align", "sideways"]) == 2
    assert "invalid choice: 'sideways'" in capsys.readouterr().err
    assert main(argv) == 0
    assert "ghost aligned: on link 'base', poses compared relative to it" in capsys.readouterr().out


def test_measurements_of_the_model_land_on_its_plate(tiago: tuple[Path, CPCModel, Path]) -> None:
    """The measurements (the rig's world, the model's joint names) drawn on the written-back
    TIAGo (its root link's frame, its URDF joint names): noise-free data of an exactly
    identified model, so every measured plate sits on the predicted one."""
    urdf, _, model_file = tiago
    ms = load_measurements(urdf.parent / "m.json")
    summary = build_view(
        static_visualizer(),
        load_view_robot(model_file, package_dirs=[SHARE]),
        measurements=ms,
        sweep=False,
    )
    assert summary.n_measured == len(ms.q) and summary.residual_max < 1e-9


@pytest.mark.slow
def test_tiago_model_in_headless_chromium(
    tiago: tuple[Path, CPCModel, Path], tmp_path: Path
) -> None:
    """The page as a browser shows it: the hand, which the calibrated torso lift carried about
    2.4 mm, in its change colour (yellow-green), the base, which nothing moved, green."""
    require_chromium()
    _, _, model_file = tiago
    html = tmp_path / "tiago.html"
    robot = load_view_robot(model_file, package_dirs=[SHARE])
    ghost = load_view_robot(own_nominal(robot), package_dirs=[SHARE])
    summary = write_view_html(html, robot, ghost=ghost, sweep=False)
    hand = summary.link_changes["hand_palm_link"]
    assert 1e-3 < hand.displacement < 3.2e-3  # between green and yellow
    img = matplotlib.image.imread(str(screenshot_html(html, tmp_path / "tiago.png", size=SIZE)))[
        ..., :3
    ]
    T = robot.link_poses(robot.q_from(summary.q))
    moved, still = (
        hue_mask(img, change_rgba(hand.displacement), 8.0),
        hue_mask(img, GREEN_RGBA, 30.0),
    )  # under the blue ghost: bluer
    uv_hand, uv_base = (
        summary.pixel(T[ln][:3, 3], *SIZE) for ln in ("hand_palm_link", "base_link")
    )
    assert near(moved, uv_hand) > 300 and near(moved, uv_hand) > 3 * near(still, uv_hand)
    assert near(still, uv_base, 100.0) > 3000 and near(still, uv_base, 100.0) > 3 * near(
        moved, uv_base, 100.0
    )
