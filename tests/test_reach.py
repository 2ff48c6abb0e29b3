"""The reachable region (cpc2urdf/validation/gaze/reachable.py) and ``cpc2urdf reach``.

Fixation of every target the region calls fixated is checked with the CPC model's own FK (not
Pinocchio, which the solver uses); the grid's geometry against the cameras' poses from that FK;
what the IIS-head cannot reach against its tilt range.
"""

from __future__ import annotations

import json
import math

import matplotlib.image
import numpy as np
import pytest
from gaze_heads import IIS_CAMERAS as CAMERAS
from gaze_heads import model_pointing_errors

from cpc2urdf.cli import main
from cpc2urdf.cli import reach as cli_reach
from cpc2urdf.errors import ConfigurationError
from cpc2urdf.files.robot_ref import load_model
from cpc2urdf.identification.simulation.heads import calibrated_iis_head, eyes_coplanar
from cpc2urdf.tolerances import GAZE_POINTING_TOL
from cpc2urdf.validation.gaze import GazeOptions, GazeSolver
from cpc2urdf.validation.gaze import reachable as reach
from cpc2urdf.validation.gaze.reachable import (
    CATEGORY_COLOURS,
    REGION_CATEGORIES,
    box_grid,
    category_of_status,
    draw_region,
    head_frame,
    make_grid,
    reachable_region,
    shell_grid,
)
from cpc2urdf.validation.gaze.reference import SolvedAxes, generic_reference_solver

SAMPLES = (3, 7, 5)  # 105 targets: small enough for a per-target solve loop


@pytest.fixture(scope="module", params=["nominal", "calibrated"])
def head(request):
    model = load_model("iis_head") if request.param == "nominal" else calibrated_iis_head(0)
    return model, GazeSolver.from_model(model)


@pytest.fixture(scope="module")
def region(head):
    model, solver = head
    return model, solver, reachable_region(solver, make_grid(solver, "shell", 0.3, 2.5, SAMPLES))


def test_head_frame_and_grids(head):
    model, solver = head
    frame = head_frame(solver)
    T = model.fk(0.5 * (model.structure.lower + model.structure.upper), CAMERAS)
    L, R = T[CAMERAS[0]], T[CAMERAS[1]]
    np.testing.assert_allclose(frame.origin, 0.5 * (L[:3, 3] + R[:3, 3]), atol=1e-12)
    Rh = frame.R_world_head
    np.testing.assert_allclose(Rh.T @ Rh, np.eye(3), atol=1e-12)
    assert np.linalg.det(Rh) == pytest.approx(1.0)
    forward = L[:3, 2] + R[:3, 2]
    np.testing.assert_allclose(Rh[:, 0], forward / np.linalg.norm(forward), atol=1e-12)
    assert Rh[:, 2] @ (L[:3, 1] + R[:3, 1]) < 0  # z up, against the cameras' y (REP-103: down)
    g = shell_grid(frame, 0.5, 2.0, (4, 5, 3))
    assert g.points.shape == (60, 3) and g.shape == (4, 5, 3)
    ph = frame.from_world(g.points)
    np.testing.assert_allclose(ph, g.points_head, atol=1e-12)
    d = np.linalg.norm(ph, axis=1).reshape(g.shape)
    np.testing.assert_allclose(d, np.broadcast_to(g.axes[0][:, None, None], g.shape), atol=1e-12)
    az = np.arctan2(ph[:, 1], ph[:, 0]).reshape(g.shape)
    np.testing.assert_allclose(az, np.broadcast_to(g.axes[1][None, :, None], g.shape), atol=1e-12)
    assert g.axes[1][0] == pytest.approx(-reach.SHELL_AZIMUTH) and g.axes[2][-1] == pytest.approx(
        reach.SHELL_ELEVATION
    )
    b = box_grid(frame, 0.5, 2.0, (2, 3, 3))
    pb = b.points_head.reshape(2, 3, 3, 3)
    assert pb[..., 0].min() == pytest.approx(0.5) and pb[..., 0].max() == pytest.approx(2.0)
    assert pb[..., 1].max() == pytest.approx(2.0) and pb[..., 2].max() == pytest.approx(1.0)
    for bad in (
        (0.0, 1.0, (3, 3, 3)),
        (2.0, 1.0, (3, 3, 3)),
        (0.5, math.inf, (3, 3, 3)),
        (0.5, 1.0, (1, 3, 3)),
    ):
        with pytest.raises(ConfigurationError):
            shell_grid(frame, *bad)
    with pytest.raises(ConfigurationError, match="grid"):
        make_grid(solver, "cube")


def test_region_statuses_are_true(region):
    """Fixated targets are fixated on an independent FK; targets stopped by the joint limits are
    not fixated by a generic solver either; the calibrated head's disparity is small; the
    categories follow the statuses."""
    model, solver, r = region
    n = r.points.shape[0]
    assert r.status.shape == r.category.shape == r.error.shape == (n,) and r.q.shape == (
        n,
        solver.n,
    )
    assert [REGION_CATEGORIES[c] for c in r.category] == [category_of_status(s) for s in r.status]
    assert np.all(r.q >= solver.lower) and np.all(r.q <= solver.upper)
    counts = r.counts()
    fixated = r.category == REGION_CATEGORIES.index("fixated")
    disparity = r.category == REGION_CATEGORIES.index("disparity")
    limits = r.category == REGION_CATEGORIES.index("joint_limits")
    err = model_pointing_errors(model, r.q, r.points)
    assert np.all(err[fixated] < GAZE_POINTING_TOL)
    np.testing.assert_allclose(
        np.max(err, axis=1)[~fixated], r.error[~fixated], rtol=1e-6, atol=1e-12
    )
    assert np.all(r.error[~fixated] > GAZE_POINTING_TOL)
    if eyes_coplanar(model):  # the nominal head fixates exactly wherever its limits allow
        assert counts["fixated"] >= n // 4 and counts["disparity"] == 0
    else:  # a calibrated head cannot: its error is the vertical disparity, a fraction of a degree
        assert counts["fixated"] == 0 and counts["disparity"] >= n // 4
        assert np.all(r.error[disparity] < math.radians(1.0))
    if not eyes_coplanar(model):  # limits stop the facing posture; fixation may exist turned away
        return
    # a generic solver (scipy least_squares) from several starts does not fixate those the limits stop
    free = solver.free_joints("cyclopean")
    held_table = GazeSolver(
        solver.robot, solver.cameras, GazeOptions(joints=[solver.joint_names[i] for i in free])
    )
    ref = generic_reference_solver(SolvedAxes(held_table))
    rng = np.random.default_rng(0)
    stopped = np.flatnonzero(limits)
    assert stopped.size
    for i in rng.choice(stopped, size=min(5, stopped.size), replace=False):
        starts = [
            solver.home,
            r.q[i],
            *(solver.lower + (solver.upper - solver.lower) * rng.random((3, solver.n))),
        ]
        best = math.inf
        for q0 in starts:
            q = solver.home.copy()
            q[free] = q0[free]  # the table stays, as in the solver
            best = min(
                best,
                float(np.max(model_pointing_errors(model, ref(r.points[i], q)[0], r.points[i]))),
            )
        assert best > GAZE_POINTING_TOL
    # colours for the 3D view, one per point, by category
    c = r.colours()
    assert c.shape == (n, 3)
    for i, name in enumerate(REGION_CATEGORIES):
        assert np.all(c[r.category == i] == CATEGORY_COLOURS[name])
    assert sum(r.counts().values()) == n


def test_category_of_status():
    assert category_of_status("fixated") == "fixated"
    assert category_of_status("joint_limits") == "joint_limits"
    assert category_of_status("behind") == "behind"
    assert category_of_status("too_close") == "too_close"
    assert category_of_status("no_solution") == "no_solution"
    assert category_of_status("disparity") == "disparity"


def test_draw_region(tmp_path):
    """The calibrated head's region (fixated nowhere, disparity and limits): the legend states the
    disparity's error; the CLI test draws the nominal head's."""
    solver = GazeSolver.from_model(calibrated_iis_head(0))
    r = reachable_region(solver, make_grid(solver, "shell", 0.3, 2.5, (2, 7, 3)))
    assert r.counts()["disparity"] > 0
    path = draw_region(r, tmp_path / "region.png", "iis_head")
    img = matplotlib.image.imread(path)
    assert img.ndim == 3 and img.shape[0] > 300 and img.shape[1] > 900
    assert len(np.unique(img.reshape(-1, img.shape[2]), axis=0)) > 10  # something was drawn
    with pytest.raises(ConfigurationError, match="png"):
        draw_region(r, tmp_path / "region.jpg")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["region.png"]


def test_cli_reach_writes_png_and_json(tmp_path, capsys):
    png, js = tmp_path / "r.png", tmp_path / "r.json"
    assert (
        main(
            [
                "reach",
                "iis_head",
                "--samples",
                "2",
                "5",
                "3",
                "--range",
                "0.4",
                "2",
                "-o",
                str(png),
                "--json",
                str(js),
            ]
        )
        == 0
    )
    out = capsys.readouterr().out
    assert str(png) in out and "30 targets" in out
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    doc = json.loads(js.read_text())
    assert doc["format"] == "cpc2urdf/reach@1" and doc["cameras"] == list(CAMERAS)
    assert len(doc["points"]) == len(doc["status"]) == len(doc["pointing_error_rad"]) == 30
    assert doc["grid"]["kind"] == "shell" and doc["grid"]["axes"][0] == [0.4, 2.0]
    assert sum(doc["counts"].values()) == 30
    # the same region through the API
    solver = GazeSolver.from_model(load_model("iis_head"))
    r = reachable_region(solver, make_grid(solver, "shell", 0.4, 2.0, (2, 5, 3)))
    np.testing.assert_allclose(doc["points"], r.points, atol=1e-12)
    assert doc["status"] == r.status.tolist()


@pytest.mark.parametrize(
    "args, match",
    [
        (["iis_head", "-o", "{d}/r.jpg"], "png"),
        (["iis_head", "--range", "2", "1", "-o", "{d}/r.png"], "NEAR < FAR"),
        (["iis_head", "--range", "0", "1", "-o", "{d}/r.png"], "NEAR < FAR"),
        (["iis_head", "--range", "0.2", "nan", "-o", "{d}/r.png"], "NEAR < FAR"),
        (["iis_head", "--samples", "1", "3", "3", "-o", "{d}/r.png"], "samples"),
        (["iis_head", "--camera", "nope", "camera_right_optical", "-o", "{d}/r.png"], "nope"),
        (["no_such_head.urdf", "-o", "{d}/r.png"], "no_such_head"),
        (["iis_head", "-o", "{d}/missing/r.png"], "missing"),
        (["iis_head", "-o", "{d}/r.png", "--json", "{d}/missing/r.json"], "missing"),
        (["iis_head", "--joints", "pan", "neck", "-o", "{d}/r.png"], "unknown joint 'neck'"),
        (["iis_head", "--tolerance", "0", "-o", "{d}/r.png"], "pointing tolerance"),
        (["iis_head", "--focal-px", "nan", "-o", "{d}/r.png"], "focal length"),
        (
            ["iis_head", "--tolerance", "1e-3", "--focal-px", "500", "-o", "{d}/r.png"],
            "not allowed with",
        ),
        (["iis_head", "--min-distance", "-1", "-o", "{d}/r.png"], "min_distance"),
        (
            ["iis_head", "--range", "1", "1e7", "-o", "{d}/r.png"],
            "range must lie within 0.001..1000 m",
        ),
        (
            ["iis_head", "--range", "1e-9", "1e-8", "-o", "{d}/r.png"],
            "range must lie within 0.001..1000 m",
        ),
        (
            ["iis_head", "--samples", "1000", "1000", "1000", "-o", "{d}/r.png"],
            "1000000000 targets; at most 1000000",
        ),
        (["iis_head", "-o", "{d}/r.png", "--json", "{d}/r.png"], "the same file as -o"),
    ],
)
def test_cli_reach_bad_input(tmp_path, capsys, args, match):
    argv = ["reach", "--samples", "2", "3", "3", *(a.format(d=tmp_path) for a in args)]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and match in err[0]
    assert list(tmp_path.iterdir()) == []  # nothing written


def test_slices_are_named_where_they_lie_and_large_grids_solve_in_chunks(monkeypatch):
    """An even number of elevations has no plane at 0: the top view's slice is the nearest
    (-12 deg of 6 over +-60 deg), and says so; a grid solved in chunks under a progress bar gives
    the answers of one batch."""
    solver = GazeSolver.from_model(load_model("iis_head"))
    grid = make_grid(solver, "shell", 0.4, 2.0, (3, 8, 6))
    level, where = reach._slice_mask(grid, 2)
    assert where == "elevation -12 deg" and level.sum() == 3 * 8
    assert np.allclose(
        np.degrees(
            np.arcsin(grid.points_head[level, 2] / np.linalg.norm(grid.points_head[level], axis=1))
        ),
        -12.0,
    )
    assert reach._slice_mask(make_grid(solver, "box", 0.4, 2.0, (3, 5, 4)), 1)[1] == "left 0 m"
    box = make_grid(
        solver, "box", 0.1, 2.9, (2, 19, 19)
    )  # linspace's middle value is -2.2e-16, not 0
    assert reach._slice_mask(box, 1)[1] == "left 0 m" and reach._slice_mask(box, 2)[1] == "up 0 m"
    whole = reachable_region(solver, grid)
    monkeypatch.setattr(reach, "PROGRESS_CHUNK", 50)
    chunked = reachable_region(solver, grid)
    assert np.array_equal(whole.status, chunked.status) and np.array_equal(whole.q, chunked.q)


def test_cli_defaults_match_the_module():
    assert cli_reach.DEFAULT_RANGE == reach.DEFAULT_RANGE
    assert cli_reach.DEFAULT_SAMPLES == reach.DEFAULT_SAMPLES
    assert cli_reach.GRID_KINDS == reach.GRID_KINDS
    assert cli_reach.DEFAULT_CAMERAS == CAMERAS


def _urdf_fk(path, joint_names, q, frame):
    """``T_root_frame`` (4, 4) at readings ``q`` (in ``joint_names`` order): the URDF's joints as
    yourdfpy parses them, chained with numpy and scipy (not Pinocchio, not trimesh's scene graph)."""
    import yourdfpy
    from scipy.spatial.transform import Rotation

    robot = yourdfpy.URDF.load(
        str(path), load_meshes=False, build_scene_graph=False, build_collision_scene_graph=False
    )
    by_child = {j.child: j for j in robot.robot.joints}
    T = np.eye(4)
    link = frame
    while link in by_child:
        j = by_child[link]
        M = np.eye(4)
        if j.type in ("revolute", "continuous"):
            M[:3, :3] = Rotation.from_rotvec(
                np.asarray(j.axis, dtype=float) * q[joint_names.index(j.name)]
            ).as_matrix()
        elif j.type == "prismatic":
            M[:3, 3] = np.asarray(j.axis, dtype=float) * q[joint_names.index(j.name)]
        T = (j.origin if j.origin is not None else np.eye(4)) @ M @ T
        link = j.parent
    return T


def test_region_on_a_real_head(tmp_path):
    """TIAGo (one camera on a pan-tilt, torso lift): fixated targets are fixated on an FK built
    from the URDF without Pinocchio; the others are where the pan-tilt's limits stop it."""
    from gaze_heads import head_case

    case = head_case("tiago", tmp_path)
    solver = case.solver
    (cam,) = case.cameras
    grid = make_grid(solver, "shell", 0.5, 2.5, (3, 9, 5))
    r = reachable_region(solver, grid)
    n = r.points.shape[0]
    names = list(solver.joint_names)
    limited = np.isfinite(solver.lower) & np.isfinite(solver.upper)
    home = np.where(
        limited,
        0.5 * (np.where(limited, solver.lower, 0.0) + np.where(limited, solver.upper, 0.0)),
        0.0,
    )
    T = _urdf_fk(case.urdf, names, home, cam)
    np.testing.assert_allclose(
        grid.frame.origin, T[:3, 3], atol=1e-9
    )  # one camera: the frame sits on it
    np.testing.assert_allclose(grid.frame.R_world_head[:, 0], T[:3, 2], atol=1e-9)
    fixated = r.category == REGION_CATEGORIES.index("fixated")
    assert 0 < fixated.sum() < n and set(r.status.tolist()) <= {"fixated", "joint_limits"}

    def error(i):
        T = _urdf_fk(case.urdf, names, r.q[i], cam)
        d = T[:3, :3].T @ (r.points[i] - T[:3, 3])
        return math.atan2(math.hypot(d[0], d[1]), d[2])

    assert all(error(i) < GAZE_POINTING_TOL for i in np.flatnonzero(fixated)[::3])
    for i in np.flatnonzero(~fixated)[::3]:
        assert error(i) == pytest.approx(r.error[i], rel=1e-6)
    # straight ahead (azimuth and elevation 0) every distance is fixated; what is not lies far
    # to the side or far up/down (pan +-75 deg, tilt -60..+45 deg in TIAGo's URDF)
    idx = np.unravel_index(np.arange(n), grid.shape)
    ahead = (idx[1] == grid.shape[1] // 2) & (idx[2] == grid.shape[2] // 2)
    assert fixated[ahead].all()
    az, el = grid.axes[1][idx[1]], grid.axes[2][idx[2]]
    assert np.all((np.abs(az) > math.radians(60.0)) | (np.abs(el) > math.radians(40.0)) | fixated)
    draw_region(r, tmp_path / "tiago.png", "tiago")
    assert (tmp_path / "tiago.png").stat().st_size > 10_000


def test_cli_reach_takes_the_solver_options_of_gaze(tmp_path, capsys):
    """--focal-px (or --tolerance) and --joints, as gaze takes them: on a calibrated head (its eyes
    cannot fixate exactly: every target 'disparity') a target counts as fixated within 0.1 px of a
    200 px camera; with the neck held (--joints on the eyes only) fewer targets are fixated."""
    from cpc2urdf.files.model_file import save_model
    from cpc2urdf.identification.simulation.heads import calibrated_iis_head

    model = save_model(calibrated_iis_head(0), tmp_path / "calibrated.json")
    grid = ["--samples", "2", "5", "3", "--range", "0.6", "2"]

    def counts(*options):
        js = tmp_path / "r.json"
        assert (
            main(
                [
                    "reach",
                    str(model),
                    *grid,
                    *options,
                    "-o",
                    str(tmp_path / "r.png"),
                    "--json",
                    str(js),
                ]
            )
            == 0
        )
        capsys.readouterr()
        return json.loads(js.read_text())["counts"]

    exact, loose = counts(), counts("--focal-px", "200")
    assert exact.get("fixated", 0) == 0 and exact.get("disparity", 0) > 0
    assert loose.get("fixated", 0) > 0
    doc = json.loads((tmp_path / "r.json").read_text())  # the last run's options are recorded
    assert doc["tolerance_rad"] == pytest.approx(math.atan(0.1 / 200))
    assert (
        doc["moving"] == ["pan", "tilt", "vergence_left", "vergence_right"]
        and doc["min_distance_m"] == 0.1
    )
    assert counts("--tolerance", "1.0")["fixated"] > 0
    eyes = counts("--focal-px", "200", "--joints", "vergence_left", "vergence_right")
    assert eyes.get("fixated", 0) < loose["fixated"]
