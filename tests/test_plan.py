"""Experiment planning: prediction, optimal selection, plan files and the command."""

from __future__ import annotations

import itertools
import json
import math
from pathlib import Path

import numpy as np
import pytest

from cpc2urdf.cli import main
from cpc2urdf.errors import ConfigurationError, InputFileError
from cpc2urdf.files.measurements import MeasurementSet, load_measurements
from cpc2urdf.files.robot_ref import load_model, load_robot
from cpc2urdf.identification.kinematics.parametrization import Parametrization
from cpc2urdf.identification.kinematics.protocol import recognise_protocol
from cpc2urdf.identification.kinematics.uncertainty import cramer_rao_covariance
from cpc2urdf.identification.planning.experiment import heldout_errors, simulate_plan
from cpc2urdf.identification.planning.information import task_sensitivity
from cpc2urdf.identification.planning.measuring import MeasuringSetup, measuring_setup
from cpc2urdf.identification.planning.optimal import select
from cpc2urdf.identification.planning.plan_file import load_plan
from cpc2urdf.identification.planning.plan_selection import (
    Planner,
    candidate_configurations,
    make_plan,
    task_configurations,
)
from cpc2urdf.identification.planning.prediction import predict_plan
from cpc2urdf.identification.simulation.design import protocol_q


@pytest.fixture(scope="module")
def setup() -> MeasuringSetup:
    return measuring_setup(load_robot("iis_head").nominal_model())


@pytest.fixture(scope="module")
def planner(setup: MeasuringSetup) -> Planner:
    return Planner(
        setup, candidate_configurations(setup, 120, seed=3), task_configurations(setup, n=40)
    )


def test_prediction_is_the_cramer_rao_bound_propagated_to_the_task(setup: MeasuringSetup) -> None:
    q = protocol_q(setup.nominal, 3)
    q_task = task_configurations(setup, n=30)
    pred = predict_plan(setup, q, q_task)
    chart, C = cramer_rao_covariance(setup.nominal, q, setup.frames, setup.sigma_t, setup.sigma_r)
    np.testing.assert_allclose(pred.covariance, C, rtol=1e-8, atol=1e-8 * np.abs(C).max())
    # Propagation by finite differences of the frames' positions along each parameter.
    x0 = np.zeros(chart.n_params)
    h = 1e-7
    G = []
    for k in range(chart.n_params):
        x = x0.copy()
        x[k] = h
        Tp = chart.model_from_vector(x).fk(q_task, setup.frames)
        Tm = chart.model_from_vector(-x).fk(q_task, setup.frames)
        G.append(
            np.stack([(Tp[f][:, :3, 3] - Tm[f][:, :3, 3]) / (2 * h) for f in setup.frames], axis=1)
        )
    Gfd = np.stack(G, axis=-1)  # (N, F, 3, P)
    ms = np.einsum("nfip,pq,nfiq->nf", Gfd, C, Gfd).mean()
    assert pred.position_rms == pytest.approx(math.sqrt(ms), rel=1e-5)
    assert pred.rank == pred.n_params == 32 and not pred.free_combinations
    assert pred.position_rms_per_frame.keys() == set(setup.frames)


def test_a_plan_that_never_moves_a_joint_names_what_it_leaves_free(setup: MeasuringSetup) -> None:
    q = protocol_q(setup.nominal, 3)
    pan = setup.nominal.structure.joint_names.index("pan")
    q = q[np.isclose(q[:, pan], q[0, pan])]  # pan never moves
    pred = predict_plan(setup, q, task_configurations(setup, n=10))
    assert pred.rank < pred.n_params
    assert any(name.startswith("pan.") for name in pred.undetermined)
    assert pred.free_combinations and math.isinf(pred.position_rms)


def test_woodbury_gains_are_the_direct_criterion_differences(planner: Planner) -> None:
    from cpc2urdf.identification.planning.optimal import _gains

    Jc, A = planner.Jc, planner.task.A_p
    M = np.einsum("kmp,kmq->pq", Jc[:10], Jc[:10])
    Minv = np.linalg.inv(M)
    direct_i = [np.trace(A @ Minv) - np.trace(A @ np.linalg.inv(M + J.T @ J)) for J in Jc[10:20]]
    direct_d = [np.linalg.slogdet(M + J.T @ J)[1] - np.linalg.slogdet(M)[1] for J in Jc[10:20]]
    np.testing.assert_allclose(_gains(Minv, Jc[10:20], A, "I"), direct_i, rtol=1e-7)
    np.testing.assert_allclose(_gains(Minv, Jc[10:20], A, "D"), direct_d, rtol=1e-7)


def test_exchange_against_brute_force(planner: Planner) -> None:
    A = planner.task.A_p
    for first in (0, 9, 18):
        Jc = planner.Jc[first : first + 9]
        info = np.einsum("kmp,kmq->kpq", Jc, Jc)
        for criterion in ("I", "D"):
            values = sorted(
                float(np.trace(np.linalg.solve(info[list(c)].sum(0), A)))
                if criterion == "I"
                else float(-np.linalg.slogdet(info[list(c)].sum(0))[1])
                for c in itertools.combinations(range(9), 4)
            )
            sel = select(Jc, 4, criterion=criterion, A=A)
            greedy = select(Jc, 4, criterion=criterion, A=A, exchange=False)
            assert sel.value <= greedy.value
            # Fedorov exchange is a local search: it may stop one swap short of the global optimum.
            # The ridge (RIDGE = 1e-9 of the information's scale) moves the values by < 1e-4 (relative).
            if criterion == "I":
                assert values[0] * (1 - 1e-4) <= sel.value <= 1.05 * values[0]
            else:  # D-efficiency (det M / det M_best)^(1/P) of at least 0.99
                assert values[0] - 1e-4 <= sel.value <= values[0] - 32 * math.log(0.99)


def test_optimal_plans_are_measurable_and_beat_the_protocol(
    setup: MeasuringSetup, planner: Planner
) -> None:
    n = 19
    q_i, _ = planner.design("I-optimal", n)
    q_p, _ = planner.design("protocol", n)
    assert setup.measurable(q_i).all()
    assert not setup.problems(q_i, [str(i) for i in range(n)])
    assert planner.predict(q_i).position_rms < 0.7 * planner.predict(q_p).position_rms
    with pytest.raises(ConfigurationError, match="protocol has 6 M \\+ 1"):
        planner.design("protocol", 20)


def test_one_joint_plan_keeps_the_protocol_structure(setup: MeasuringSetup) -> None:
    res = make_plan(
        setup,
        n=13,
        q_task=task_configurations(setup, n=30),
        one_joint=True,
        n_candidates=60,
        curve_ns=[13],
    )
    ms = MeasurementSet.from_arrays(
        setup.nominal.structure, res.q, setup.nominal.fk(res.q, setup.frames)
    )
    proto = recognise_protocol(ms)
    assert proto is not None
    assert res.labels[0] == "q0" and setup.measurable(res.q).all()
    assert {c.strategy for c in res.curve} == {"I-optimal", "D-optimal", "protocol"}


def test_noise_free_plan_is_identified_exactly(setup: MeasuringSetup, planner: Planner) -> None:
    q, labels = planner.design("I-optimal", 13)
    q_task = task_configurations(setup, n=20)
    exp = simulate_plan(setup, q, labels, seed=2, noise="none", q_heldout=q_task)
    e = heldout_errors(exp, load_robot("iis_head").nominal_model())
    assert e.start == "nominal"
    assert e.position.max() < 1e-8 and e.angle.max() < 1e-8


def test_smallest_n_reaches_the_target_and_one_fewer_does_not(planner: Planner) -> None:
    target = 0.4e-3
    n = planner.smallest_n(target)
    assert planner.predict(planner.design("I-optimal", n)[0]).position_rms <= target
    assert planner.predict(planner.design("I-optimal", n - 1)[0]).position_rms > target
    with pytest.raises(ConfigurationError, match="not reached"):
        planner.smallest_n(1e-6)


def test_task_sensitivity_matches_the_chart(setup: MeasuringSetup) -> None:
    chart = Parametrization(setup.nominal, setup.frames)
    q = task_configurations(setup, n=5)
    t = task_sensitivity(chart, q, setup.frames)
    assert t.A_p.shape == (32, 32) and np.allclose(t.A_p, t.A_p.T)
    assert np.trace(t.A_p) == pytest.approx(np.sum(t.G_p**2) / (5 * 2))


def test_cli_writes_plan_csv_png_and_the_plan_loads(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from cpc2urdf.identification.vision.joints_csv import read_joints_csv

    out = tmp_path / "plan.json"
    assert (
        main(
            ["plan", "iis_head", "--n", "13", "--candidates", "40", "--curve", "13", "-o", str(out)]
        )
        == 0
    )
    assert "predicted RMS error" in capsys.readouterr().out
    doc = json.loads(out.read_text())
    assert doc["format"] == "cpc2urdf/plan@1" and len(doc["configurations"]) == 13
    assert (tmp_path / "plan.png").read_bytes()[:4] == b"\x89PNG"
    s = load_robot("iis_head").structure
    plan = load_plan(out, s)
    table = read_joints_csv(tmp_path / "plan.csv", s)
    np.testing.assert_allclose(table.q, plan.q, atol=1e-9)
    assert plan.q.shape == (13, 6) and plan.sigma_t == pytest.approx(0.5e-3)
    assert doc["prediction"]["position_rms_mm"] > 0 and doc["prediction"]["rank"] == 32


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--n", "0"], "--n must be at least 1"),
        (["--target-error", "-1"], "--target-error must be a positive"),
        (["--n", "5", "--sigma-mm", "nan"], "--sigma-mm must be a positive"),
        (
            ["--n", "5", "--noise", "stereo", "--pixel-sigma", "0"],
            "--pixel-sigma must be a positive",
        ),
        (["--n", "5", "--measure", "nope"], "'nope' is not a frame"),
        (["--n", "5", "--rig", "missing.yaml"], "missing.yaml"),
        (["--n", "5", "--range", "pan=1"], "--range"),
        (["--n", "5", "--curve", "a"], "--curve"),
        (["--n", "5", "--task-region", "missing.csv"], "missing.csv"),
    ],
)
def test_cli_bad_input_one_line_exit_2_nothing_written(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], message: str
) -> None:
    out = tmp_path / "plan.json"
    assert main(["plan", "iis_head", *argv, "--candidates", "30", "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert list(tmp_path.iterdir()) == []


def test_load_plan_refuses_bad_files(tmp_path: Path) -> None:
    s = load_robot("iis_head").structure
    assert (
        main(
            [
                "plan",
                "iis_head",
                "--n",
                "13",
                "--candidates",
                "40",
                "--curve",
                "13",
                "-o",
                str(tmp_path / "p.json"),
            ]
        )
        == 0
    )
    doc = json.loads((tmp_path / "p.json").read_text())
    bad = tmp_path / "bad.json"
    for change, message in (
        (lambda d: d.update(format="cpc2urdf/plan@9"), "format"),
        (
            lambda d: d["configurations"][2].update(q=[1, 2]),
            r"configurations\[2\].q must be a list of 6",
        ),
        (lambda d: d["joints"][0].update(name="other"), "do not match robot"),
        (lambda d: d["configurations"][0]["q"].__setitem__(2, 1e4), "outside its limits"),
        (lambda d: d["setup"].update(T_world_base=[[1, 0, 0, 0]] * 4), "not a rigid transform"),
    ):
        d = json.loads(json.dumps(doc))
        change(d)
        bad.write_text(json.dumps(d))
        with pytest.raises(InputFileError, match=message):
            load_plan(bad, s)


def test_tiago_urdf_plan_through_the_cli(tmp_path: Path) -> None:
    from urdf_cases import tiago_with_plate

    urdf = tiago_with_plate(tmp_path)
    out = tmp_path / "tiago_plan.json"
    argv = [
        "plan",
        str(urdf),
        "--measure",
        "calib_plate",
        "--n",
        "10",
        "--candidates",
        "40",
        "--curve",
        "10",
    ]
    assert main([*argv, "-o", str(out)]) == 0
    doc = json.loads(out.read_text())
    assert doc["measured_frames"] == ["calib_plate"] and doc["prediction"]["rank"] == 16
    assert [j["name"] for j in doc["joints"]] == ["torso_lift", "head_1", "head_2"]
    assert [j["urdf_joint"] for j in doc["joints"]] == [
        "torso_lift_joint",
        "head_1_joint",
        "head_2_joint",
    ]
    assert doc["urdf"]["measured_links"] == ["calib_plate"]
    # plan.csv goes to the robot: the URDF's joint names (its /joint_states names), read back
    # with the robot's name mapping as the same configurations as plan.json.
    from cpc2urdf.identification.vision.joints_csv import read_joints_csv, urdf_joint_columns

    header = (tmp_path / "tiago_plan.csv").read_text().splitlines()[0]
    assert header == "record,label,torso_lift_joint[mm],head_1_joint[deg],head_2_joint[deg]"
    robot = load_robot(str(urdf)).restricted(["calib_plate"])
    assert urdf_joint_columns(robot) == {
        "torso_lift_joint": "torso_lift",
        "head_1_joint": "head_1",
        "head_2_joint": "head_2",
    }
    plan = load_plan(out, robot.structure)
    table = read_joints_csv(
        tmp_path / "tiago_plan.csv", robot.structure, aliases=urdf_joint_columns(robot)
    )
    np.testing.assert_allclose(table.q, plan.q, atol=1e-9)
    # The URDF's names in --range (as simulate takes them) and the CSV as a task region.
    lim = math.degrees(robot.structure.joint("head_1").upper)
    again = tmp_path / "again.json"
    assert (
        main(
            [
                *argv,
                "--range",
                f"head_1_joint=-{lim / 2:g}:{lim / 2:g}",
                "--task-region",
                str(tmp_path / "tiago_plan.csv"),
                "-o",
                str(again),
            ]
        )
        == 0
    )
    doc2 = json.loads(again.read_text())
    assert doc2["task_region"] == {"kind": "configurations", "n": 10}
    head_1 = np.array([c["q"][1] for c in doc2["configurations"]])
    assert np.all(np.abs(head_1) <= lim / 2 + 1e-9)
    assert (
        main(["plan", str(urdf), "--n", "10", "-o", str(tmp_path / "x.json")]) == 2
    )  # no --measure
    assert not (tmp_path / "x.json").exists()


def test_a_plan_file_is_simulated_where_the_plan_put_the_robot(tmp_path: Path) -> None:
    from cpc2urdf.identification.planning.experiment import simulate_from_plan

    out = tmp_path / "p.json"
    assert (
        main(
            ["plan", "iis_head", "--n", "13", "--candidates", "40", "--curve", "13", "-o", str(out)]
        )
        == 0
    )
    spec = load_robot("iis_head")
    plan = load_plan(out, spec.structure)
    exp = simulate_from_plan(spec.nominal_model(), plan, seed=4, noise="none", n_heldout=5)
    np.testing.assert_allclose(exp.measured.q, plan.q)
    assert exp.measured.n_records == 13 and exp.heldout.n_records == 5
    e = heldout_errors(exp, spec.nominal_model())
    assert e.position.max() < 1e-8


def test_plan_files_get_one_mode_and_are_written_all_or_nothing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The PNG has the JSON's and CSV's mode (what open() gives), and an I/O failure on the last of
    the three leaves none of them."""
    import os

    argv = ["plan", "iis_head", "--n", "13", "--candidates", "40", "--curve", "13", "-o"]
    assert main([*argv, str(tmp_path / "plan.json")]) == 0
    (tmp_path / "plain").write_text("x")
    modes = {p.name: p.stat().st_mode & 0o777 for p in tmp_path.iterdir()}
    assert modes["plan.png"] == modes["plan.json"] == modes["plan.csv"] == modes["plain"]
    real, calls = os.replace, []

    def third_fails(src: str, dst: str | os.PathLike[str]) -> None:
        if str(src).endswith(".tmp"):
            calls.append(dst)
            if len(calls) == 3:
                raise OSError(28, "No space left on device")
        real(src, dst)

    monkeypatch.setattr(os, "replace", third_fails)
    out = tmp_path / "new" / "plan.json"
    out.parent.mkdir()
    assert main([*argv, str(out)]) == 2
    assert len(calls) == 3 and list(out.parent.iterdir()) == []


def test_the_curve_is_in_mm_and_deg_whatever_the_file_units() -> None:
    from cpc2urdf.files.units import Units
    from cpc2urdf.identification.planning.outputs import plan_robot
    from cpc2urdf.identification.planning.plan_file import plan_to_json

    out = plan_robot(
        load_robot("iis_head"), robot_ref="iis_head", n=13, n_candidates=40, curve_ns=[13]
    )
    si = plan_to_json(
        out.result,
        out.setup,
        robot="iis_head",
        task_region={},
        candidates={},
        units=Units("m", "rad"),
    )
    assert si["units"] == {"length": "m", "angle": "rad"}
    assert si["curve"] == out.doc["curve"] and si["prediction"] == out.doc["prediction"]
    for c, p in zip(si["curve"], out.result.curve, strict=True):
        assert c["position_rms_mm"] == pytest.approx(p.position_rms * 1e3, rel=1e-12)
        assert c["orientation_rms_deg"] == pytest.approx(math.degrees(p.orientation_rms), rel=1e-12)
    # the plan itself is a point of its own curve: same number in both sections
    this = next(c for c in si["curve"] if c["strategy"] == out.result.strategy and c["n"] == 13)
    assert this["position_rms_mm"] == pytest.approx(si["prediction"]["position_rms_mm"], rel=1e-9)
    # the configurations follow the units
    np.testing.assert_allclose(
        np.array([c["q"] for c in si["configurations"]]), out.result.q, atol=0
    )


def test_simulate_measures_a_plan_and_identify_reaches_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``cpc2urdf plan`` → ``simulate --plan`` → ``identify``: the simulated records are exactly the
    plan's configurations, noise-free data are identified exactly, and a bad plan is one line."""
    plan = tmp_path / "plan.json"
    assert (
        main(
            [
                "plan",
                "iis_head",
                "--n",
                "13",
                "--candidates",
                "120",
                "--curve",
                "13",
                "-o",
                str(plan),
            ]
        )
        == 0
    )
    sim = tmp_path / "sim"
    assert (
        main(
            [
                "simulate",
                "iis_head",
                "--plan",
                str(plan),
                "--noise",
                "none",
                "--heldout",
                "10",
                "-o",
                str(sim),
            ]
        )
        == 0
    )
    loaded = load_plan(plan, load_robot("iis_head").structure)
    ms = load_measurements(sim / "measurements.json")
    np.testing.assert_allclose(ms.q, loaded.q, atol=1e-12)
    model = tmp_path / "model.json"
    assert main(["identify", str(sim / "measurements.json"), "-o", str(model)]) == 0
    heldout = load_measurements(sim / "heldout.json")
    fk = load_model(model).fk(heldout.q)
    for frame, poses in heldout.poses.items():
        assert np.abs(fk[frame][:, :3, 3] - poses[:, :3, 3]).max() < 1e-9
    capsys.readouterr()
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({**json.loads(plan.read_text()), "format": "cpc2urdf/plan@9"}))
    assert main(["simulate", "iis_head", "--plan", str(bad), "-o", str(tmp_path / "x")]) == 2
    assert (
        main(
            [
                "simulate",
                "iis_head",
                "--plan",
                str(tmp_path / "none.json"),
                "-o",
                str(tmp_path / "y"),
            ]
        )
        == 2
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and "bad.json" in err[0] and "plan@9" in err[0] and "none.json" in err[1]
    assert not (tmp_path / "x").exists() and not (tmp_path / "y").exists()


# ---- stereo pixel noise (per-view pose covariance) ------------------------------------------------


@pytest.fixture(scope="module")
def stereo_setup(setup: MeasuringSetup) -> MeasuringSetup:
    return measuring_setup(
        setup.nominal, noise="stereo", pixel_sigma=0.15, world_to_base=setup.nominal.world_to_base
    )


def test_stereo_pose_covariance_matches_a_monte_carlo_of_the_simulator(
    stereo_setup: MeasuringSetup,
) -> None:
    from cpc2urdf.identification.planning.stereo_views import pose_error, stereo_pose_covariance
    from cpc2urdf.identification.simulation.measurement_noise import stereo_noise

    s = stereo_setup
    q = protocol_q(s.nominal, 3)[[0, 5, 12]]
    f = s.frames[1]
    T = s.nominal.fk(q, [f])[f]
    layout = np.array(s.nominal.structure.frame(f).layout)
    C = stereo_pose_covariance(T, layout, s.rig, s.pixel_sigma)
    n = 1500
    Tn = np.repeat(T, n, axis=0)
    meas, _ = stereo_noise(Tn, layout, s.rig, s.pixel_sigma, np.random.default_rng(7))
    E = pose_error(meas, Tn).reshape(len(T), n, 6)
    for i in range(len(T)):
        Cm = np.cov(E[i].T)
        # Each entry's std within 10 % (the Monte Carlo's own standard error is ~2 %).
        np.testing.assert_allclose(np.sqrt(np.diag(Cm)), np.sqrt(np.diag(C[i])), rtol=0.10)
        # And the whole matrix: the sample covariance whitened by the prediction is ~ I.
        L = np.linalg.cholesky(C[i])
        W = np.linalg.solve(L, np.linalg.solve(L, Cm).T)
        assert np.all(np.abs(np.linalg.eigvalsh(W) - 1.0) < 0.15)
    # Oblique and far views are worse: the covariance differs between views (not one scalar).
    assert np.ptp([np.trace(c[:3, :3]) for c in C]) > 0.05 * np.trace(C[0, :3, :3])


def test_sandwich_is_the_bound_when_the_weights_are_the_noise(stereo_setup: MeasuringSetup) -> None:
    from cpc2urdf.identification.planning.information import StereoPoseMeasurement
    from cpc2urdf.identification.planning.prediction import predict_from_jacobian

    s = stereo_setup
    m = s.measurement()
    assert isinstance(m, StereoPoseMeasurement)
    chart = Parametrization(s.nominal, s.frames)
    q = protocol_q(s.nominal, 2)
    task = task_sensitivity(chart, task_configurations(s, n=20), s.frames)
    Jw, S = m.pipeline(chart, q)
    # With residuals of unit covariance the weighted LS is the ML estimate: sandwich = Cramér-Rao.
    eye = np.broadcast_to(np.eye(6), S.shape)
    a = predict_from_jacobian(Jw, chart, task, s.frames, s.sigma_t, s.sigma_r, pipeline=(Jw, eye))
    b = predict_from_jacobian(Jw, chart, task, s.frames, s.sigma_t, s.sigma_r)
    np.testing.assert_allclose(
        a.covariance, b.covariance, rtol=1e-9, atol=1e-12 * np.abs(b.covariance).max()
    )
    # Whitened rows give the per-view-weighted bound, never above the pipeline's sandwich.
    p = predict_plan(s, q, task_configurations(s, n=20))
    assert p.bound_position_rms <= p.position_rms
    Jwhite = m.weighted_jacobian(chart, q).reshape(-1, chart.n_params)
    assert np.allclose(
        np.linalg.inv(Jwhite.T @ Jwhite),
        predict_from_jacobian(Jwhite, chart, task, s.frames, s.sigma_t, s.sigma_r).covariance,
        rtol=1e-6,
        atol=1e-14,
    )


def test_stereo_prediction_matches_simulated_stereo_experiments(
    stereo_setup: MeasuringSetup,
) -> None:
    s = stereo_setup
    q_task = task_configurations(s, n=60)
    q = protocol_q(s.nominal, 2)
    pred = predict_plan(s, q, q_task)
    ms = []
    for seed in range(12):
        exp = simulate_plan(s, q, seed=seed, noise="stereo", q_heldout=q_task, require_view=False)
        assert exp.measured.metadata["noise"] == {"model": "stereo", "pixel_sigma_px": 0.15}
        ms.append(np.mean(heldout_errors(exp, s.nominal).position ** 2))
    observed = math.sqrt(float(np.mean(ms)))
    # 12 experiments: the observed RMS has a ~7 % standard error; the 100-trial study is in docs/planning.md.
    assert observed == pytest.approx(pred.position_rms, rel=0.2)
    assert observed > 1.3 * pred.bound_position_rms  # the scalar weighting does lose accuracy


def test_a_stereo_plan_carries_its_noise_to_the_file_and_the_simulation(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from cpc2urdf.identification.planning.experiment import simulate_from_plan

    out = tmp_path / "p.json"
    assert (
        main(
            [
                "plan",
                "iis_head",
                "--n",
                "13",
                "--candidates",
                "40",
                "--curve",
                "13",
                "--noise",
                "stereo",
                "--pixel-sigma",
                "0.2",
                "-o",
                str(out),
            ]
        )
        == 0
    )
    assert "per-view weights would reach" in capsys.readouterr().out
    doc = json.loads(out.read_text())
    assert (
        doc["setup"]["noise"]["model"] == "stereo"
        and doc["setup"]["noise"]["pixel_sigma_px"] == 0.2
    )
    assert doc["prediction"]["bound_position_rms_mm"] < doc["prediction"]["position_rms_mm"]
    spec = load_robot("iis_head")
    plan = load_plan(out, spec.structure)
    assert plan.noise == "stereo" and plan.pixel_sigma == pytest.approx(0.2)
    exp = simulate_from_plan(spec.nominal_model(), plan, seed=2, n_heldout=3)
    assert exp.measured.metadata["noise"] == {"model": "stereo", "pixel_sigma_px": 0.2}
    doc["setup"]["noise"]["pixel_sigma_px"] = -1
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(doc))
    with pytest.raises(InputFileError, match="pixel_sigma_px"):
        load_plan(bad)


# ---- marker (position-only) setups --------------------------------------------------------------


@pytest.fixture(scope="module")
def marker_setup(setup: MeasuringSetup) -> MeasuringSetup:
    return measuring_setup(
        setup.nominal,
        markers=2,
        marker_sigma=0.1e-3,
        marker_seed=3,
        world_to_base=setup.nominal.world_to_base,
    )


def test_marker_prediction_is_the_point_problems_bound(marker_setup: MeasuringSetup) -> None:
    from cpc2urdf.identification.kinematics.points.point_problem import PointProblem
    from cpc2urdf.identification.planning.marker_setup import MarkerMeasurement

    s = marker_setup
    m = s.measurement()
    assert isinstance(m, MarkerMeasurement) and len(m.markers) == 4
    q = protocol_q(s.nominal, 2)
    q_task = task_configurations(s, n=15)
    pred = predict_plan(s, q, q_task)
    # Direct: the point problem's whole Jacobian (no regrouping), its inverse information, and
    # finite differences of the markers' task points along each parameter.
    chart = m.point_chart(s.nominal)
    names = [mk.name for mk in chart.markers]
    y = {n: np.zeros((len(q), 3)) for n in names}
    J = PointProblem(
        chart, q, y, {n: np.ones(len(q), bool) for n in names}, s.marker_sigma
    ).jacobian(np.zeros(chart.n_params))
    C = np.linalg.inv(J.T @ J)
    np.testing.assert_allclose(pred.covariance, C, rtol=1e-6, atol=1e-9 * np.abs(C).max())
    h = 1e-7
    G = []
    for k in range(chart.n_params):
        x = np.zeros(chart.n_params)
        x[k] = h
        pts = []
        for sign in (1, -1):
            model, pos = chart.model_from_vector(sign * x), chart.positions_from_vector(sign * x)
            T = model.fk(q_task, [m.markers[n][0] for n in names])
            pts.append(
                np.stack(
                    [
                        T[m.markers[n][0]][:, :3, :3] @ pos[n] + T[m.markers[n][0]][:, :3, 3]
                        for n in names
                    ],
                    axis=1,
                )
            )
        G.append((pts[0] - pts[1]) / (2 * h))
    Gfd = np.stack(G, axis=-1)  # (K, markers, 3, P)
    assert pred.position_rms == pytest.approx(
        math.sqrt(np.einsum("nfip,pq,nfiq->nf", Gfd, C, Gfd).mean()), rel=1e-5
    )
    assert math.isnan(pred.orientation_rms) and pred.rank == pred.n_params


def test_marker_prediction_matches_simulated_marker_experiments(
    marker_setup: MeasuringSetup,
) -> None:
    from cpc2urdf.identification.planning.experiment import (
        heldout_point_errors,
        simulate_plan_markers,
    )

    s = marker_setup
    q_task = task_configurations(s, n=40)
    q = protocol_q(s.nominal, 2)
    pred = predict_plan(s, q, q_task)
    ms, starts = [], set()
    for seed in range(8):
        err, start = heldout_point_errors(
            simulate_plan_markers(s, q, seed=seed, q_heldout=q_task), s.nominal
        )
        ms.append(np.mean(err**2))
        starts.add(start)
    assert starts <= {"circle-point", "nominal (circle-point refused)"}
    # 8 experiments: ~8 % standard error on the observed RMS; the 100-trial study is in docs/planning.md.
    assert math.sqrt(float(np.mean(ms))) == pytest.approx(pred.position_rms, rel=0.25)


def test_a_marker_plan_names_the_markers_simulate_places(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "p.json"
    assert (
        main(
            [
                "plan",
                "iis_head",
                "--n",
                "13",
                "--candidates",
                "40",
                "--curve",
                "13",
                "--markers",
                "2",
                "--marker-seed",
                "4",
                "-o",
                str(out),
            ]
        )
        == 0
    )
    assert "marker point" in capsys.readouterr().out
    plan = load_plan(out, load_robot("iis_head").structure)
    assert (plan.markers, plan.marker_seed, plan.marker_sigma) == (2, 4, pytest.approx(0.1e-3))
    sim = tmp_path / "sim"
    assert main(["simulate", "iis_head", "--plan", str(out), "--seed", "4", "-o", str(sim)]) == 0
    held = load_measurements(sim / "heldout.json")
    truth = load_model(sim / "truth.json")
    positions = json.loads(out.read_text())["setup"]["markers"]["positions"]
    assert set(positions) == set(held.marker_points)
    for name, v in positions.items():
        T = truth.fk(held.q, [v["frame"]])[v["frame"]]
        y = T[:, :3, :3] @ (np.array(v["position_mm"]) / 1e3) + T[:, :3, 3]
        np.testing.assert_allclose(y, held.marker_points[name], atol=1e-12)


def test_a_joint_the_plan_holds_stays_held_through_simulate_and_identify(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """``plan --range table_x=0:0``: the plan file records its ranges, ``simulate --plan`` keeps the
    joint still in the held-out set too, and ``identify --method map`` keeps it at the nominal."""
    import json

    from cpc2urdf.cli import main
    from cpc2urdf.files.robot_ref import load_model

    plan, sim, model = tmp_path / "plan.json", tmp_path / "sim", tmp_path / "model.json"
    assert main(["plan", "iis_head", "--n", "30", "--range", "table_x=0:0", "-o", str(plan)]) == 0
    assert json.loads(plan.read_text())["setup"]["ranges"]["table_x"] == [0.0, 0.0]
    assert main(["simulate", "iis_head", "--plan", str(plan), "-o", str(sim)]) == 0
    for name in ("measurements.json", "heldout.json"):
        assert {
            r["joints"]["table_x"] for r in json.loads((sim / name).read_text())["records"]
        } == {0.0}
    assert (
        main(["identify", str(sim / "measurements.json"), "--method", "map", "-o", str(model)]) == 0
    )
    identified = load_model(model)
    assert "table_x" not in identified.metadata.provenance.details["calibrated_joints"]
    nominal = load_model("iis_head")
    assert identified.joints["table_x"].matrix() == pytest.approx(
        nominal.joints["table_x"].matrix(), abs=0
    )
