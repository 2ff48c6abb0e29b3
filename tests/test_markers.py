"""Position-only data (marker points): the measurement format @2, the point residuals' Jacobian, the
circle-point start and the refinement on the IIS-head and on TIAGo (a URDF no one here wrote):
exact recovery on noise-free data, held-out error against a maximum-likelihood fit started from the
truth, what point data cannot determine, and the refusals."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest
from urdf_cases import TIAGO

from cpc2urdf.cli import main
from cpc2urdf.errors import DegenerateDataError, InconsistentDataError, InputFileError
from cpc2urdf.files.measurements import (
    MEASUREMENTS_FORMAT,
    MEASUREMENTS_FORMAT_2,
    measurements_from_json,
    measurements_to_json,
    save_measurements,
)
from cpc2urdf.files.robot_ref import load_robot
from cpc2urdf.identification.kinematics.methods import identify
from cpc2urdf.identification.kinematics.parametrization import Parametrization
from cpc2urdf.identification.kinematics.points.circle_point import circle_point_start
from cpc2urdf.identification.kinematics.points.point_identify import marker_positions
from cpc2urdf.identification.kinematics.points.point_problem import PointChart, PointProblem
from cpc2urdf.identification.kinematics.points.point_refine import refine_points
from cpc2urdf.identification.simulation.design import protocol_q, random_configurations
from cpc2urdf.identification.simulation.marker_points import place_markers_on, simulate_markers
from cpc2urdf.identification.simulation.truth import perturbed_model
from cpc2urdf.model import CPCModel
from cpc2urdf.urdf.robot import load_urdf_robot

EXACT = 1e-9  # [m], [rad]: noise-free recovery
# identify and the maximum-likelihood fit started from the truth reach the same optimum (measured:
# held-out RMS ratio 0.999999995 on the IIS-head, 1 - 1e-12 on TIAGo; predicted marker positions 1.2e-11 m
# and 1e-15 m apart; joint parameters modulo the gauge 4.2e-10 and 2e-14 apart):
SAME_RMS = 1e-6  # [-]: |held-out RMS of identify / of the ML fit - 1|
SAME_POINTS = 1e-9  # [m]: their predicted marker positions at held-out configurations
SAME_JOINTS = 1e-8  # [m], [rad]: their joint parameters in identify's chart (modulo the gauge)

# A marker link on TIAGo's head (how a user adds a tracker reflector mount).
MARKER_LINK = """  <link name="tracker_mount"/>
  <joint name="tracker_mount_joint" type="fixed">
    <parent link="head_2_link"/>
    <child link="tracker_mount"/>
    <origin xyz="0.08 0.0 0.12" rpy="0.0 0.3 0.1"/>
  </joint>
"""


def tiago_with_marker_link(folder: Path) -> Path:
    text = TIAGO.read_text()
    end = text.rindex("</robot>")
    path = folder / "tiago_markers.urdf"
    path.write_text(text[:end] + MARKER_LINK + text[end:])
    return path


@pytest.fixture(scope="module")
def iis() -> tuple[CPCModel, CPCModel, dict[str, tuple[str, np.ndarray]]]:
    nominal = load_robot("iis_head").nominal_model()
    rng = np.random.default_rng(0)
    truth = perturbed_model(nominal, rng, 1e-3, np.radians(0.5))
    return nominal, truth, place_markers_on(truth, {"plate_left": 2, "plate_right": 2}, rng)


@pytest.fixture(scope="module")
def tiago(
    tmp_path_factory: pytest.TempPathFactory,
) -> tuple[Path, CPCModel, CPCModel, dict[str, tuple[str, np.ndarray]]]:
    folder = tmp_path_factory.mktemp("tiago_markers")
    urdf = tiago_with_marker_link(folder)
    robot = load_urdf_robot(urdf, ["tracker_mount"])
    nominal = robot.nominal_model()
    rng = np.random.default_rng(1)
    truth = perturbed_model(nominal, rng, 1e-3, np.radians(0.5))
    frame = robot.cpc_frame("tracker_mount")
    assert frame is not None
    markers = place_markers_on(truth, {frame: 3}, rng)
    return urdf, nominal, truth, markers


def heldout_points(
    model: CPCModel, positions: dict[str, tuple[str, np.ndarray]], q: np.ndarray
) -> np.ndarray:
    """World positions of every marker at configurations ``q``, shape (M, N, 3)."""
    frames = list(dict.fromkeys(f for f, _ in positions.values()))
    T = model.fk(q, frames)
    return np.stack([T[f][:, :3, :3] @ p + T[f][:, :3, 3] for f, p in positions.values()])


def heldout_error(
    model: CPCModel, truth: CPCModel, markers: dict[str, tuple[str, np.ndarray]], q: np.ndarray
) -> np.ndarray:
    """Distances between the identified model's marker positions and the true ones, (M, N) [m]."""
    got = heldout_points(model, {m: marker_positions(model)[m] for m in markers}, q)
    return np.linalg.norm(got - heldout_points(truth, markers, q), axis=2)


def joint_blocks_modulo_gauge(model: CPCModel, truth: CPCModel, frames: list[str]) -> np.ndarray:
    """The truth's joint parameters in the identified model's chart (0 = the same axis lines)."""
    chart = Parametrization(model, frames)
    x = chart.vector_from_model(truth)
    return np.concatenate([x[b.slice] for b in chart.blocks if b.kind != "frame"])


# ---- the file format -----------------------------------------------------------------------------


def test_format_2_round_trip_and_format_1_unchanged(iis, tmp_path):
    nominal, truth, markers = iis
    q = protocol_q(truth, 3)
    ms = simulate_markers(truth, markers, q, robot="iis_head", known=["plate_left_m0"])
    doc = measurements_to_json(ms)
    assert doc["format"] == MEASUREMENTS_FORMAT_2
    assert (
        doc["markers"]["plate_left_m0"]["link"] == "plate_left"
        and "position" in doc["markers"]["plate_left_m0"]
    )
    assert "position" not in doc["markers"]["plate_right_m1"]
    back = measurements_from_json(json.loads(json.dumps(doc)), "<doc>")
    assert back.markers == ms.markers
    for m in markers:
        np.testing.assert_array_equal(back.marker_points[m], ms.marker_points[m])
    # In mm, with a marker unseen in one record.
    doc["units"] = {"length": "mm", "angle": "rad"}
    for rec in doc["records"]:
        for k, v in rec["markers"].items():
            rec["markers"][k] = [c * 1e3 for c in v]
        for k in rec["joints"]:
            if k.startswith("table"):
                rec["joints"][k] *= 1e3
    doc["markers"]["plate_left_m0"]["position"] = [
        c * 1e3 for c in doc["markers"]["plate_left_m0"]["position"]
    ]
    doc["records"][2]["markers"]["plate_right_m0"] = None
    mm = measurements_from_json(doc, "<mm>")
    np.testing.assert_allclose(
        mm.marker_points["plate_left_m1"], ms.marker_points["plate_left_m1"], rtol=0, atol=1e-15
    )
    assert (
        not mm.has_marker("plate_right_m0")[2]
        and mm.has_marker("plate_right_m0").sum() == len(q) - 1
    )
    # A set without markers is still written and read as @1, byte for byte as before.
    poses = MEASUREMENTS_FORMAT
    pose_set = measurements_from_json(
        {
            "format": poses,
            "robot": "iis_head",
            "records": [
                {
                    "joints": truth.structure.q_to_dict(q[0]),
                    "poses": {"plate_left": {"matrix": truth.fk(q[0])["plate_left"].tolist()}},
                }
            ],
        },
        "<pose>",
    )
    assert not pose_set.markers and not pose_set.has_points
    assert measurements_to_json(pose_set)[
        "format"
    ] == poses and "markers" not in measurements_to_json(pose_set)
    # @1 does not know markers.
    doc1 = dict(doc, format=poses)
    with pytest.raises(InputFileError, match="unknown keys \\['markers'\\]"):
        measurements_from_json(doc1, "<v1>")


def test_marker_on_a_link_the_robot_does_not_have(iis, tiago):
    _, truth, markers = iis
    doc = measurements_to_json(
        simulate_markers(truth, markers, protocol_q(truth, 2), robot="iis_head")
    )
    doc["markers"]["plate_left_m0"]["link"] = "head_2_link"
    with pytest.raises(
        InputFileError, match="markers.plate_left_m0.link: unknown frame 'head_2_link'"
    ):
        measurements_from_json(doc, "<doc>")
    urdf, _, t_truth, t_markers = tiago
    robot = load_urdf_robot(urdf, ["tracker_mount"])
    ms = simulate_markers(t_truth, t_markers, protocol_q(t_truth, 2), robot=urdf.name)
    ms.spec = robot
    doc = measurements_to_json(ms)
    assert next(iter(doc["markers"].values()))["link"] == "tracker_mount"
    next(iter(doc["markers"].values()))["link"] = "no_such_link"
    with pytest.raises(
        InputFileError, match="markers.tracker_mount_m0.link: 'no_such_link' is not a link of"
    ):
        measurements_from_json(doc, str(urdf.parent / "m.json"))


# ---- the Jacobian --------------------------------------------------------------------------------


def test_point_jacobian_matches_finite_differences(iis):
    _, truth, markers = iis
    rng = np.random.default_rng(4)
    q = random_configurations(truth.structure.calibration_ranges(), 12, rng)
    ms = simulate_markers(truth, markers, q, sigma_p=0.2e-3, rng=rng, known=["plate_left_m0"])
    pos = {m: p + rng.normal(scale=0.01, size=3) for m, (_, p) in markers.items()}
    chart = PointChart(truth, [ms.markers[m] for m in markers], pos)
    use = {m: ms.has_marker(m) for m in markers}
    problem = PointProblem(chart, q, ms.marker_points, use, 0.2e-3)
    x = rng.normal(scale=0.02, size=chart.n_params)
    J = problem.jacobian(x)
    h = 1e-7
    Jn = np.column_stack(
        [
            (problem.residuals(x + h * e) - problem.residuals(x - h * e)) / (2 * h)
            for e in np.eye(chart.n_params)
        ]
    )
    # The known marker's frame is free (its 6 placement parameters), the unknown markers' 3 each.
    assert chart.n_params == 20 + 6 + 3 * 3
    np.testing.assert_allclose(J, Jn, rtol=0, atol=1e-5 * np.abs(J).max())


# ---- exact recovery ------------------------------------------------------------------------------


@pytest.mark.parametrize("configs", ["protocol", "free"])
def test_iis_head_noise_free_exact(iis, configs):
    nominal, truth, markers = iis
    s = truth.structure
    q = (
        protocol_q(truth, 5)
        if configs == "protocol"
        else random_configurations(s.calibration_ranges(), 31, np.random.default_rng(2))
    )
    ms = simulate_markers(truth, markers, q, robot="iis_head")
    model = identify(ms, nominal=nominal)
    assert model.metadata.provenance.details["start"] == (
        "circle-point" if configs == "protocol" else "nominal"
    )
    q_held = random_configurations(s.calibration_ranges(), 40, np.random.default_rng(9))
    assert heldout_error(model, truth, markers, q_held).max() < EXACT
    np.testing.assert_allclose(
        joint_blocks_modulo_gauge(model, truth, ["plate_left", "plate_right"]), 0, atol=EXACT
    )
    # The plates' placement is what point data cannot see; the model says so.
    assert any("plate_left: its placement on its link" in n for n in model.metadata.notes)


def test_circle_point_start_is_exact_without_a_nominal_model(iis):
    _, truth, markers = iis
    ms = simulate_markers(truth, markers, protocol_q(truth, 3))
    start = circle_point_start(ms, None, 0.5e-3)
    assert start.model.T_world_base().tolist() == np.eye(4).tolist()
    q_held = random_configurations(
        truth.structure.calibration_ranges(), 20, np.random.default_rng(3)
    )
    got = heldout_points(
        start.model, {m: (f, start.positions[m]) for m, (f, _) in markers.items()}, q_held
    )
    assert np.abs(got - heldout_points(truth, markers, q_held)).max() < EXACT
    for j in truth.structure.joint_names:  # every axis direction, in world at q0
        _, axis = truth.joint_axes_world(start.protocol.q0)
        np.testing.assert_allclose(
            start.axes[j][0], axis[0, truth.structure.joint_index(j)], atol=EXACT
        )


def test_known_markers_fix_the_frame(iis):
    """Three markers of known position on a plate determine its whole placement."""
    nominal, truth, _ = iis
    rng = np.random.default_rng(7)
    markers = place_markers_on(truth, {"plate_left": 3, "plate_right": 3}, rng)
    ms = simulate_markers(
        truth,
        markers,
        protocol_q(truth, 4),
        robot="iis_head",
        known=["plate_left_m0", "plate_left_m1", "plate_left_m2"],
    )
    model = identify(ms, nominal=nominal)
    q = random_configurations(truth.structure.calibration_ranges(), 10, rng)
    T, Tt = model.fk(q, ["plate_left"])["plate_left"], truth.fk(q, ["plate_left"])["plate_left"]
    assert np.abs(T - Tt).max() < EXACT
    assert not any("plate_left: its placement" in n for n in model.metadata.notes)


def test_tiago_noise_free_exact(tiago):
    urdf, nominal, truth, markers = tiago
    robot = load_urdf_robot(urdf, ["tracker_mount"])
    s = truth.structure
    for q, start in (
        (protocol_q(truth, 5), "circle-point"),
        (random_configurations(s.calibration_ranges(), 15, np.random.default_rng(5)), "nominal"),
    ):
        ms = simulate_markers(truth, markers, q, robot=urdf.name)
        ms.spec = robot
        model = identify(ms, nominal=nominal)
        assert model.metadata.provenance.details["start"] == start
        q_held = random_configurations(s.calibration_ranges(), 30, np.random.default_rng(8))
        assert heldout_error(model, truth, markers, q_held).max() < EXACT
        frame = next(iter(markers.values()))[0]
        np.testing.assert_allclose(joint_blocks_modulo_gauge(model, truth, [frame]), 0, atol=EXACT)


# ---- with noise: the optimum of the maximum-likelihood fit started from the truth ------------


def _ml_from_truth(truth: CPCModel, ms, markers) -> CPCModel:
    res = refine_points(truth, ms, {m: p for m, (_, p) in markers.items()}, 0.2e-3, warn=False)
    prov = {
        m: {"frame": f, "position_m": res.positions[m].tolist()} for m, (f, _) in markers.items()
    }
    from cpc2urdf.model_metadata import Provenance

    return res.model.with_params(
        metadata=res.model.metadata.replace(provenance=Provenance("ml", details={"markers": prov}))
    )


@pytest.mark.parametrize("robot", ["iis_head", "tiago"])
def test_noisy_heldout_within_ml_from_truth(iis, tiago, robot):
    if robot == "iis_head":
        nominal, truth, markers = iis
        ref, spec = "iis_head", None
    else:
        urdf, nominal, truth, markers = tiago
        ref, spec = urdf.name, load_urdf_robot(urdf, ["tracker_mount"])
    rng = np.random.default_rng(11)
    ms = simulate_markers(truth, markers, protocol_q(truth, 6), sigma_p=0.2e-3, rng=rng, robot=ref)
    ms.spec = spec or ms.spec
    model = identify(ms, nominal=nominal)
    q_held = random_configurations(
        truth.structure.calibration_ranges(), 50, np.random.default_rng(12)
    )
    ml_model = _ml_from_truth(truth, ms, markers)
    ours = float(np.sqrt(np.mean(heldout_error(model, truth, markers, q_held) ** 2)))
    ml = float(np.sqrt(np.mean(heldout_error(ml_model, truth, markers, q_held) ** 2)))
    assert ours > 0 and abs(ours / ml - 1) < SAME_RMS, (ours, ml)
    # The same optimum, not only the same error: the same predictions and the same joint axes.
    got, ref = (
        heldout_points(m, {k: marker_positions(m)[k] for k in markers}, q_held)
        for m in (model, ml_model)
    )
    assert np.linalg.norm(got - ref, axis=2).max() < SAME_POINTS
    frames = list(dict.fromkeys(f for f, _ in markers.values()))
    assert np.abs(joint_blocks_modulo_gauge(model, ml_model, frames)).max() < SAME_JOINTS
    assert model.metadata.provenance.details["consistency"]["consistent"]


# ---- identifiability -----------------------------------------------------------------------------


def test_one_known_marker_leaves_the_frame_rotation_undetermined(iis):
    _, truth, _ = iis
    rng = np.random.default_rng(5)
    markers = place_markers_on(truth, {"plate_left": 2, "plate_right": 1}, rng)
    ms = simulate_markers(
        truth, markers, protocol_q(truth, 4), robot="iis_head", known=["plate_right_m0"]
    )
    start = circle_point_start(ms, None, 0.5e-3)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = refine_points(start.model, ms, start.positions, 0.5e-3, warn=False)
    rep = res.identifiability
    assert rep.rank == rep.n_params - 3  # the plate turns about the marker: 3 free rotations
    assert {n for n in rep.undetermined if n.startswith("plate_right.")} >= {
        "plate_right.b_x",
        "plate_right.b_y",
        "plate_right.beta",
    }
    assert any(
        "plate_right: 1 marker(s) of known position cannot fix its orientation" in u
        for u in res.undetermined
    )


# ---- refusals ------------------------------------------------------------------------------------


def _cli(args: list[str], capsys) -> tuple[int, str]:
    code = main(args)
    err = capsys.readouterr().err.strip()
    return code, err


def test_cli_identifies_point_files_and_refuses_bad_ones(iis, tmp_path, capsys):
    nominal, truth, markers = iis
    q = protocol_q(truth, 4)
    ms = simulate_markers(
        truth, markers, q, robot="iis_head", sigma_p=0.1e-3, rng=np.random.default_rng(1)
    )
    good = tmp_path / "points.json"
    save_measurements(ms, good)
    out = tmp_path / "model.json"
    assert main(["identify", str(good), "-o", str(out)]) == 0
    assert json.loads(out.read_text())["provenance"]["start"] == "circle-point"
    capsys.readouterr()
    doc = json.loads(good.read_text())

    def refused(mutate, match: str) -> None:
        d = json.loads(json.dumps(doc))
        mutate(d)
        path = tmp_path / "bad.json"
        path.write_text(json.dumps(d))
        target = tmp_path / "never.json"
        code, err = _cli(["identify", str(path), "-o", str(target)], capsys)
        assert code == 2 and len(err.splitlines()) == 1 and match in err, err
        assert not target.exists()

    # A marker on a link the robot does not have.
    refused(lambda d: d["markers"]["plate_left_m0"].update(link="elbow"), "unknown frame 'elbow'")

    # Too few markers for a joint: nothing on the right plate, so vergence_right moves no marker.
    def no_right(d):
        for k in ("plate_right_m0", "plate_right_m1"):
            del d["markers"][k]
        for r in d["records"]:
            r["markers"] = {
                k: v for k, v in r["markers"].items() if not k.startswith("plate_right")
            }

    refused(no_right, "too few markers for joint 'vergence_right'")

    # A marker seen on the wrong link: plate_right_m1 declared on plate_left.
    refused(
        lambda d: d["markers"]["plate_right_m1"].update(link="plate_left"),
        "marker 'plate_right_m1' is declared on 'plate_left'",
    )

    # A gross outlier.
    def outlier(d):
        d["records"][5]["markers"]["plate_left_m1"][2] += 0.005

    refused(outlier, "outlier: record 5 marker 'plate_left_m1' is ")


def test_unit_mistake_is_named(iis):
    nominal, truth, markers = iis
    q = random_configurations(truth.structure.calibration_ranges(), 30, np.random.default_rng(2))
    ms = simulate_markers(truth, markers, q, robot="iis_head")
    ms.marker_points = {m: Y * 1e3 for m, Y in ms.marker_points.items()}  # mm read as m
    with pytest.raises((InconsistentDataError, DegenerateDataError), match="in mm but read as m"):
        identify(ms, nominal=nominal)


def test_robust_method_drops_a_gross_outlier_and_names_it(iis):
    nominal, truth, markers = iis
    ms = simulate_markers(
        truth,
        markers,
        protocol_q(truth, 5),
        robot="iis_head",
        sigma_p=0.1e-3,
        rng=np.random.default_rng(6),
    )
    ms.marker_points["plate_right_m0"][7] += [0.0, 0.004, 0.0]
    with pytest.raises(InconsistentDataError, match="outlier: record 7 marker 'plate_right_m0'"):
        identify(ms, nominal=nominal)
    model = identify(ms, "refined-robust", nominal=nominal)
    assert [n for n in model.metadata.notes if n.startswith("outlier:")] == [
        next(
            n
            for n in model.metadata.notes
            if n.startswith("outlier: record 7 marker 'plate_right_m0'")
        )
    ]
    assert model.metadata.provenance.details["consistency"]["consistent"]
    clean = identify(
        simulate_markers(truth, markers, protocol_q(truth, 5), robot="iis_head"), nominal=nominal
    )
    q = random_configurations(truth.structure.calibration_ranges(), 20, np.random.default_rng(1))
    assert (
        heldout_error(model, truth, markers, q).max() < 0.5e-3
        and heldout_error(clean, truth, markers, q).max() < EXACT
    )


@pytest.mark.parametrize("noise", [True, False])
def test_marker_on_the_wrong_link_at_free_configurations_is_named(iis, noise):
    """Without the protocol's sweeps, the fit shows it: that marker's points do not fit, the others do."""
    nominal, truth, markers = iis
    q = random_configurations(truth.structure.calibration_ranges(), 30, np.random.default_rng(21))
    ms = simulate_markers(
        truth,
        markers,
        q,
        robot="iis_head",
        sigma_p=0.1e-3 if noise else 0.0,
        rng=np.random.default_rng(22),
    )
    ms.markers["plate_right_m1"] = ms.markers["plate_right_m1"].__class__(
        "plate_right_m1", "plate_left"
    )
    with pytest.raises(
        InconsistentDataError,
        match="marker 'plate_right_m1' does not move with the link it is "
        "declared on \\('plate_left'\\)",
    ):
        identify(ms, nominal=nominal)
