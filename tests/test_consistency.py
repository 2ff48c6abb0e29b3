"""The stage-1 consistency gate: every mistake a user makes refused through ``cpc2urdf identify`` with
exit code 2, one stderr line naming the cause, and no output file; ``--accept-inconsistent`` keeps
the model with the diagnosis in it; clean data pass.

One seeded simulated IIS-head experiment (Fig. 10 noise, stated in the file) serves the module; each
case applies one mistake to its file (:mod:`stage1_mistakes`).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import stage1_mistakes as sm

from cpc2urdf.cli import main
from cpc2urdf.errors import InconsistentDataError
from cpc2urdf.files.jsonio import write_json
from cpc2urdf.files.measurements import measurements_from_json, measurements_to_json
from cpc2urdf.files.robot_ref import load_model
from cpc2urdf.identification.kinematics.gate.fit_statistics import fit_statistics
from cpc2urdf.identification.kinematics.gate.pose_gate import Noise, check_consistency
from cpc2urdf.identification.kinematics.methods import identify
from cpc2urdf.identification.kinematics.start import closed_form_model
from cpc2urdf.identification.simulation.stage1_experiment import simulate_experiment


@pytest.fixture(scope="module")
def experiment():
    return simulate_experiment("iis_head", seed=2, n_heldout=0)


@pytest.fixture(scope="module")
def clean_doc(experiment) -> dict[str, Any]:
    return measurements_to_json(experiment.measured, robot="iis_head")


def refused(
    tmp_path: Path, doc: dict[str, Any], capsys: pytest.CaptureFixture[str], *extra: str
) -> str:
    """Run ``identify`` on ``doc``; assert exit 2, one stderr line, no output; return the line."""
    path, out = tmp_path / "measurements.json", tmp_path / "model.json"
    write_json(path, doc)
    code = main(["identify", str(path), "-o", str(out), *extra])
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert not out.exists()
    assert str(path) in err
    return err


# (mistake, words that must name the cause)
STATED_NOISE_CASES = [
    ("metres_as_mm", ["lengths look like metres labelled mm", "far below", 'fix "units"']),
    (
        "radians_as_degrees",
        ["revolute readings look like radians labelled deg", 'fix "units": "angle"'],
    ),
    ("plates_swapped", ["poses of plate_left and plate_right look swapped"]),
    ("vergence_swapped", ["readings of vergence_left and vergence_right look swapped"]),
    ("poses_inverted", ["poses look inverted", "T_frame_world"]),
    ("rotations_transposed", ["rotation blocks look transposed"]),
    ("quaternion_wxyz", ["quaternions look written w, x, y, z"]),
    ("next_record_poses", ["readings look paired with the next record's poses"]),
    (
        "noise_understated",
        ["fit residuals are", "the stated 0.025 mm / 0.025 deg noise", "none of the"],
    ),
]


@pytest.mark.parametrize(
    "mistake,words", STATED_NOISE_CASES, ids=[c[0] for c in STATED_NOISE_CASES]
)
def test_each_mistake_is_refused_naming_its_cause(
    clean_doc, tmp_path, capsys, mistake: str, words: list[str]
) -> None:
    err = refused(tmp_path, sm.MISTAKES[mistake](clean_doc), capsys)
    for w in words:
        assert w in err, err
    assert "--accept-inconsistent" in err


def test_gross_outliers_are_named_by_the_default_method(clean_doc, tmp_path, capsys) -> None:
    doc, bad = sm.outliers(clean_doc)  # 5 % of the records: one plate 10 mm / 5 deg off
    assert len(bad) == 3
    err = refused(tmp_path, doc, capsys)
    assert f"{len(bad)} records look like gross outliers" in err
    for k in bad:
        assert f" {k} (" in err, err
    assert "refined-robust" in err


def test_refined_robust_drops_the_outliers_and_passes(clean_doc, tmp_path, capsys) -> None:
    doc, bad = sm.outliers(clean_doc)
    write_json(tmp_path / "m.json", doc)
    assert (
        main(
            [
                "identify",
                str(tmp_path / "m.json"),
                "-o",
                str(tmp_path / "r.json"),
                "--method",
                "refined-robust",
            ]
        )
        == 0
    )
    model = load_model(tmp_path / "r.json")
    assert model.metadata.provenance.details["outlier_records"] == bad
    assert model.metadata.provenance.details["consistency"]["consistent"] is True


@pytest.mark.parametrize(
    "mistake,words",
    [
        (
            "metres_as_mm",
            ["lengths look like metres labelled mm", "1/", "the size of the nominal model"],
        ),
        ("plates_swapped", ["poses of plate_left and plate_right look swapped", "RMS"]),
        ("poses_inverted", ["poses look inverted"]),
    ],
)
def test_without_a_noise_statement_size_and_refits_still_name_the_cause(
    clean_doc, tmp_path, capsys, mistake: str, words: list[str]
) -> None:
    doc = sm.MISTAKES[mistake](clean_doc)
    doc.pop("noise")
    err = refused(tmp_path, doc, capsys)
    for w in words:
        assert w in err, err


def test_outliers_without_a_noise_statement_are_named(clean_doc, tmp_path, capsys) -> None:
    doc, bad = sm.outliers(clean_doc)
    doc.pop("noise")
    err = refused(tmp_path, doc, capsys)
    assert "look like gross outliers" in err and all(f" {k} (" in err for k in bad), err


def test_accept_inconsistent_keeps_the_model_with_the_diagnosis(
    clean_doc, tmp_path, capsys
) -> None:
    write_json(tmp_path / "m.json", sm.metres_as_mm(clean_doc))
    out = tmp_path / "model.json"
    assert (
        main(["identify", str(tmp_path / "m.json"), "-o", str(out), "--accept-inconsistent"]) == 0
    )
    text = capsys.readouterr().out
    assert "INCONSISTENT" in text and "lengths look like metres labelled mm" in text
    model = load_model(out)
    assert any(
        n.startswith("INCONSISTENT DATA") and "metres labelled mm" in n
        for n in model.metadata.notes
    )
    c = model.metadata.provenance.details["consistency"]
    assert c["consistent"] is False and c["accepted"] is True
    assert c["diagnosis"]["fix"] == "lengths x1000" and c["diagnosis"]["kind"] == "lengths"
    assert c["fit_over_noise"]["translation"] < 0.01  # the fit is far below the stated noise
    assert (
        json.loads(out.read_text())["provenance"]["consistency"]["diagnosis"]["remedy"]
        == 'fix "units": "length"'
    )


def test_clean_data_pass_and_the_verdict_is_stored(experiment) -> None:
    model = identify(experiment.measured, nominal=load_model("iis_head"))
    c = model.metadata.provenance.details["consistency"]
    assert c["consistent"] is True and c["false_alarm_probability"] == 1e-6
    assert (
        0.8 < c["fit_over_noise"]["translation"] < 1.2
        and 0.8 < c["fit_over_noise"]["rotation"] < 1.2
    )
    assert not any("INCONSISTENT" in n for n in model.metadata.notes)
    assert c["size"]["yardstick"] == "nominal" and 0.9 < c["size"]["ratio"] < 1.1


def test_the_api_raises_with_the_report(clean_doc) -> None:
    ms = measurements_from_json(sm.poses_inverted(clean_doc), "inverted.json")
    with pytest.raises(InconsistentDataError, match="poses look inverted") as e:
        identify(ms, "closed-form")  # any method: the gate tests the data, not the estimator
    report = e.value.report
    assert report.diagnosis.key == "inverted poses" and report.statistics.ratio_t > 10


def test_fit_statistics_match_the_stated_noise_on_clean_data() -> None:
    """Over seeded trials the two chi-square ratios scatter about 1 and the tails are not extreme."""
    ratios = []
    for seed in range(8):
        _, ms, _ = simulate_experiment("iis_head", seed=100 + seed, n_heldout=0)
        s = fit_statistics(closed_form_model(ms, None), ms, 0.5e-3, np.radians(0.5))
        assert min(s.tails().values()) > 1e-4
        assert s.dof_t + 3 * s.dof_r == pytest.approx(6 * s.n_poses - s.n_params, rel=1e-9)
        ratios.append((s.ratio_t, s.ratio_r))
    r = np.array(ratios)
    assert np.all(np.abs(r.mean(axis=0) - 1.0) < 0.1)


def test_stated_noise_twice_too_large_is_refused_as_far_below(experiment) -> None:
    ms = experiment.measured
    model = closed_form_model(ms, None)
    report = check_consistency(ms, model, None, Noise(1e-3, np.radians(1.0), True))
    assert not report.consistent and report.diagnosis.kind == "noise"
    assert "far below the stated 1 mm / 1 deg noise" in report.line()


# ---- degenerate stage-1 data: refused before any solver runs ---------------------------------------

DEGENERATE_CASES = [
    (
        "joint_never_moved",
        sm.joint_never_moved,
        [
            "joint 'tilt' has fewer than two distinct readings",
            "never moves",
            "measure it at >= 1 more reading",
        ],
    ),
    (
        "only_q0",
        sm.only_q0,
        [
            "no joint moves",
            "all 1 records are at one configuration",
            "measure each at >= 1 more reading",
        ],
    ),
    (
        "q0_copies",
        sm.q0_copies,
        ["no joint moves", "all 55 records are at one configuration", "54 repeat"],
    ),
    (
        "duplicated_records",
        sm.duplicated_records,
        ["record 55 (q0) repeats record 0 (q0) to the last digit", "remove the 55 copies"],
    ),
]


@pytest.mark.parametrize(
    "name,mistake,words", DEGENERATE_CASES, ids=[c[0] for c in DEGENERATE_CASES]
)
def test_degenerate_data_are_refused_naming_what_is_missing(
    clean_doc, tmp_path, capsys, name, mistake, words
) -> None:
    err = refused(tmp_path, mistake(clean_doc), capsys)
    for w in words:
        assert w in err, err
    assert "Method 'lm'" not in err


def test_free_parameters_after_the_fit_are_refused_naming_the_joints(experiment) -> None:
    """The pre-solver checks catch a joint that never moved; bypassing them, the gate's own rank
    test after the fit still refuses the data, naming the joints involved."""
    from cpc2urdf.errors import DegenerateDataError
    from cpc2urdf.identification.kinematics.methods import identify_refined

    ms = experiment.measured
    keep = [i for i, label in enumerate(ms.labels) if not label.startswith("tilt")]
    sub = ms.subset(keep)
    nominal = load_model("iis_head")
    model = identify_refined(sub, nominal)  # starts from the nominal model: tilt's sweep is missing
    with pytest.raises(
        DegenerateDataError,
        match=r"the data determine only 28 of 32 parameters .*tilt.*never moved",
    ):
        check_consistency(sub, model, nominal, Noise(0.5e-3, np.radians(0.5), True))
