"""``cpc2urdf bench gaze`` (cpc2urdf/studies/bench_gaze.py): a smoke run with tiny sizes (no
timing assertions), and the pieces the numbers rest on: the generic targets are fixatable on an
FK independent of Pinocchio (yourdfpy), and the generic reference's Jacobian is the residual's
derivative (finite differences)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cpc2urdf.cli import main
from cpc2urdf.studies.bench_gaze import REAL_HEADS, _real_urdf, bench_head, tracking_targets
from cpc2urdf.tolerances import GAZE_POINTING_TOL
from cpc2urdf.validation.crosscheck import yourdfpy_pose
from cpc2urdf.validation.gaze.reference import (
    SolvedAxes,
    audit_targets,
    generic_reachable_targets,
    generic_unreachable_targets,
    missed_targets,
)

KEYS = (
    "kin_us",
    "median_us",
    "p99_us",
    "median_kin",
    "p99_kin",
    "success",
    "disparity",
    "unreachable_median_us",
    "unreachable_ratio",
    "reference_median_us",
    "reference_success",
    "ratio",
    "batch_targets_per_s",
    "aims",
    "p99_cpu_us",
    "p99_cpu_kin",
    "audit_targets",
    "audit_unfixated",
    "audit_missed",
    "after_reference_median_us",
    "ratio_blocks",
    "blocks_median_us",
    "blocks_reference_median_us",
    "kin_after_reference_us",
)


@pytest.fixture(scope="module")
def tiago():
    return bench_head("tiago")


def test_bench_runs_tiny(tmp_path, capsys):
    out = tmp_path / "bench.json"
    argv = [
        "bench",
        "gaze",
        "--targets",
        "4",
        "--unreachable",
        "2",
        "--reference",
        "2",
        "--track-seconds",
        "0.02",
        "--heads",
        "nominal",
        "tiago",
        "--audit",
        "40",
        "--json",
        str(out),
    ]
    assert main(argv) == 0
    res = json.loads(out.read_text())
    assert list(res) == ["nominal", "tiago"]
    for r in res.values():
        for key in KEYS:
            assert key in r
        assert (
            r["kin_us"] > 0
            and r["median_kin"] > 0
            and r["ratio"] > 0
            and r["batch_targets_per_s"] > 0
        )
        assert r["ratio"] == pytest.approx(
            r["reference_median_us"] / r["after_reference_median_us"]
        )
        assert r["ratio_blocks"] == pytest.approx(
            r["blocks_reference_median_us"] / r["blocks_median_us"]
        )
        assert r["after_reference_median_us"] > 0 and r["kin_after_reference_us"] > 0
        assert r["success"] + r["disparity"] == 1.0 and r["reference_success"] == 1.0
        assert r["unreachable_fixated"] == 0
        assert r["audit_targets"] == 40 and 0 < r["audit_unfixated"] < 40 and r["audit_missed"] == 0
    for name in ("nominal", "tiago"):  # every head shape tracks (TIAGo: one camera)
        assert res[name]["track_steps"] == 20 and res[name]["track_saccade_steps"] >= 0
    table = capsys.readouterr().out
    assert "vs scipy" in table and "vs placo" in table and "nominal" in table and "tiago" in table
    for name in ("nominal", "tiago"):
        assert f"vs scipy on {name}: " in table and "in alternating blocks of" in table
    for r in res.values():  # placo's reference ran (where it imports) or says why not
        assert r["placo"] == "ran" or "vs placo n/a: " + r["placo"] in table


def test_bench_urdf_head(tmp_path, capsys):
    path, cams = _real_urdf("talos")
    out = tmp_path / "b.json"
    argv = [
        "bench",
        "gaze",
        "--targets",
        "3",
        "--unreachable",
        "0",
        "--reference",
        "1",
        "--heads",
        "nominal",
        "--track-seconds",
        "0.01",
        "--urdf",
        path,
        "--camera",
        *cams,
        "--json",
        str(out),
    ]
    assert main(argv) == 0
    assert list(json.loads(out.read_text())) == ["nominal", "talos_reduced"]


def test_the_audit_finds_fixatable_targets_called_unreachable(tiago):
    """missed_targets solves each target marked unfixated again from random postures (each a
    warm start, the table's starts after it): told that reachable targets were not fixated, it
    counts every one of them, and only those marked; targets behind the head, which the pan
    cannot turn to, it never counts. audit_targets fill the 6 m cube about the head."""
    solver = tiago.solver
    axes = SolvedAxes(solver)
    P, _ = generic_reachable_targets(axes, 12, seed=3)
    assert missed_targets(solver, P, np.zeros(12, dtype=bool)).tolist() == list(range(12))
    assert (
        missed_targets(solver, P, np.ones(12, dtype=bool)).size == 0
    )  # only the unfixated are audited
    behind = generic_unreachable_targets(solver, 12, seed=3)
    assert missed_targets(solver, behind, np.zeros(12, dtype=bool)).size == 0
    A = audit_targets(axes, 200, seed=1)
    O, _ = axes.axes(axes.home[None])
    assert np.abs(A - O[0].mean(axis=0)).max() <= 3.0 and np.ptp(A, axis=0).min() > 5.0


@pytest.mark.parametrize(
    "argv",
    [
        ["--urdf", "x.urdf"],
        ["--camera", "c"],
        ["--targets", "0"],
        ["--track-seconds", "0"],
        ["--heads", "nope"],
        ["--audit", "-1"],
    ],
)
def test_bench_bad_input(tmp_path, capsys, argv):
    out = tmp_path / "b.json"
    assert main(["bench", "gaze", *argv, "--json", str(out)]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1
    assert not out.exists()


def test_generic_targets_fixatable_on_yourdfpy(tiago):
    """The look-at targets lie on the camera's optical axis at the sampled readings, by yourdfpy."""
    import yourdfpy

    axes = SolvedAxes(tiago.solver)
    P, Q = generic_reachable_targets(axes, 20, seed=1)
    chain = tiago.solver.chain
    assert np.all(Q[:, chain.joint_index] >= tiago.solver.lower[chain.joint_index])
    path, (cam,) = _real_urdf("tiago")
    robot = yourdfpy.URDF.load(path, load_meshes=False, build_collision_scene_graph=False)
    names = tiago.solver.joint_names
    order = [names.index(j) for j in robot.actuated_joint_names]
    for p, q in zip(P, Q, strict=True):
        robot.update_cfg(q[order])
        T = yourdfpy_pose(robot, cam, robot.base_link)
        d = T[:3, :3].T @ (p - T[:3, 3])
        assert np.arctan2(np.hypot(d[0], d[1]), d[2]) < GAZE_POINTING_TOL
        assert 0.3 <= np.linalg.norm(d) <= 3.0


def test_reference_jacobian_by_finite_differences(tiago):
    axes = SolvedAxes(tiago.solver)
    P, Q = generic_reachable_targets(axes, 3, seed=2)
    rng = np.random.default_rng(0)
    n = tiago.solver.n
    movable = tiago.solver.chain.joint_index
    for p, q in zip(P + 0.05 * rng.normal(size=P.shape), Q, strict=True):
        r, J = axes.residual(q, p, True)
        assert J is not None and J.shape == (3, n)
        h = 1e-6
        for k in movable:
            dq = np.zeros(n)
            dq[k] = h
            fd = (axes.residual(q + dq, p, False)[0] - axes.residual(q - dq, p, False)[0]) / (2 * h)
            np.testing.assert_allclose(J[:, k], fd, atol=1e-7)


def test_tracking_targets_stay_inside():
    lo, hi = np.array([0.0, -1.0, -np.inf]), np.array([1.0, 1.0, np.inf])
    P = np.arange(12.0).reshape(4, 3)
    Q = np.array([[0.5, 0.0, 7.0], [0.1, 0.0, 0.0], [0.6, 0.4, -3.0], [0.5, -0.9, 0.0]])
    T = tracking_targets(lo, hi, P, Q, 2.5)
    assert T.shape == (2500, 3)
    # rows 1 and 3 lie outside the middle half of a limited joint: the centres cycle rows 0 and 2
    for k, centre in enumerate((P[0], P[2], P[0])):
        d = np.linalg.norm(T[1000 * k : 1000 * (k + 1)] - centre, axis=1)
        np.testing.assert_allclose(d, 0.05, atol=1e-12)


def test_real_heads_known():
    assert set(REAL_HEADS) == {"tiago", "talos"}


def test_block_run_alternates_blocks_of_ours_and_the_reference():
    """``_block_run``: each block of targets solved by us back to back, then by the reference,
    with one kinematics call right after each reference solve; every target once by each."""
    from cpc2urdf.studies.bench_gaze import REFERENCE_BLOCK, _block_run

    calls = []

    class Ours:
        def solve(self, p):
            calls.append(("ours", int(p[0])))

    def reference(p):
        calls.append(("scipy", int(p[0])))

    def kin(i):
        calls.append(("kin", i))
        return 1e-6

    n = 2 * REFERENCE_BLOCK + 3
    P = np.arange(n, dtype=float)[:, None] * np.ones(3)
    r = _block_run(Ours(), P, reference, kin)
    expected = []
    for a in range(0, n, REFERENCE_BLOCK):
        block = range(a, min(a + REFERENCE_BLOCK, n))
        expected += [("ours", i) for i in block]
        for i in block:
            expected += [("scipy", i), ("kin", i)]
    assert calls == expected
    assert r["kin_after_reference_us"] == pytest.approx(1.0)
    assert r["ratio_blocks"] == pytest.approx(
        r["blocks_reference_median_us"] / r["blocks_median_us"]
    )


class _FakeClock:
    """``time.perf_counter`` that moves only when a stub says so: a timed region's length is
    the sum of what the calls inside it add."""

    def __init__(self):
        self.t = 0.0
        self.perf_counter = lambda: self.t

    def spend(self, seconds):
        self.t += seconds


def test_block_run_times_each_solver_alone(monkeypatch):
    """Our block's time is our solves' alone, scipy's its solves' alone (not the kinematics
    call after each), the unit is the kinematics call's own return value."""
    from types import SimpleNamespace

    from cpc2urdf.studies import bench_gaze

    clock = _FakeClock()
    monkeypatch.setattr(bench_gaze, "time", SimpleNamespace(perf_counter=clock.perf_counter))
    ours = SimpleNamespace(solve=lambda p: clock.spend(2e-6 * (1.0 + p[0])))  # 2-4 us, median 3 us
    P = np.linspace(0.0, 1.0, 31)[:, None] * np.ones(3)

    def reference(p):
        clock.spend(600e-6)

    def kin(i):
        clock.spend(1.0)  # a kinematics call counted in the reference's time would show
        return 5e-6

    r = bench_gaze._block_run(ours, P, reference, kin)
    assert r["blocks_median_us"] == pytest.approx(3.0)
    assert r["blocks_reference_median_us"] == pytest.approx(600.0)
    assert r["ratio_blocks"] == pytest.approx(200.0)
    assert r["kin_after_reference_us"] == pytest.approx(5.0)
