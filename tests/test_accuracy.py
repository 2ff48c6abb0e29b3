"""Table 4 on held-out records: exact models give zero, a known offset gives known numbers."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cpc2urdf.cli import main
from cpc2urdf.errors import DegenerateDataError
from cpc2urdf.identification.simulation.random_robots import random_model
from cpc2urdf.measurements import MeasurementSet, save_measurements
from cpc2urdf.model import CPCParams
from cpc2urdf.model_file import save_model
from cpc2urdf.robot_ref import load_robot
from cpc2urdf.transforms import homogeneous
from cpc2urdf.validation.accuracy import accuracy, format_table


def _heldout(n: int = 30, seed: int = 0) -> tuple[object, MeasurementSet]:
    model = load_robot("iis_head").nominal_model()
    s = model.structure
    rng = np.random.default_rng(seed)
    q = rng.uniform(s.lower, s.upper, (n, s.n_joints))
    return model, MeasurementSet.from_arrays(s, q, model.fk(q, ["plate_left", "plate_right"]), robot="iis_head")


def test_exact_model_has_zero_error() -> None:
    model, ms = _heldout()
    report = accuracy(model, ms)  # type: ignore[arg-type]
    assert set(report) == {"plate_left", "plate_right"}
    for b in report.values():
        assert b.records == 30 and b.max < 1e-12 and b.max_rotation < 1e-9


def test_known_world_offset_gives_known_table() -> None:
    model, ms = _heldout()
    shift = np.array([1e-3, -2e-3, 0.5e-3])
    T = model.world_to_base.matrix()  # type: ignore[attr-defined]
    moved = model.with_params(world_to_base=CPCParams.from_matrix(homogeneous(T[:3, :3], T[:3, 3] + shift)))  # type: ignore[attr-defined]
    for b in accuracy(moved, ms).values():
        np.testing.assert_allclose(b.mean_abs, np.abs(shift), atol=1e-12)
        np.testing.assert_allclose(b.std_abs, 0.0, atol=1e-12)
        assert b.mean == pytest.approx(np.linalg.norm(shift), abs=1e-12)
    text = format_table(accuracy(moved, ms))
    assert "mu_y =   2.000 mm" in text and "mean |e| = 2.291 mm" in text


def test_mismatched_robot_is_refused() -> None:
    _, ms = _heldout()
    other = random_model(np.random.default_rng(0), 3)
    with pytest.raises(DegenerateDataError, match="do not match the model"):
        accuracy(other, ms)


def test_cli_prints_table_and_json(tmp_path, capsys) -> None:  # type: ignore[no-untyped-def]
    model, ms = _heldout(10)
    save_model(model, tmp_path / "m.json")  # type: ignore[arg-type]
    save_measurements(ms, tmp_path / "h.json")
    assert main(["accuracy", str(tmp_path / "m.json"), str(tmp_path / "h.json")]) == 0
    assert "plate_left (10 held-out records)" in capsys.readouterr().out
    assert main(["accuracy", str(tmp_path / "m.json"), str(tmp_path / "h.json"), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["plate_right"]["mean_mm"] < 1e-9
    assert main(["accuracy", str(tmp_path / "m.json"), str(tmp_path / "missing.json")]) == 2
    assert "missing.json: no such file" in capsys.readouterr().err


def test_refined_model_shows_predicted_next_to_observed() -> None:
    """A refined model carries a covariance: accuracy puts its predicted RMS beside the observed
    one; the closed form has none. Averaged over seeds the two agree (here within a factor 1.5)."""
    from cpc2urdf.identification.kinematics.methods import identify
    from cpc2urdf.identification.simulation.simulate import simulate_experiment

    ratios = []
    for seed in range(4):
        truth, measured, heldout = simulate_experiment("iis_head", seed=seed, n_heldout=30)
        cf = accuracy(identify(measured, "closed-form", None), heldout)
        assert all(b.predicted_rms is None for b in cf.values())
        report = accuracy(identify(measured, "refined", None), heldout)
        for b in report.values():
            assert b.predicted_rms is not None and b.to_json()["predicted_rms_mm"] > 0
            ratios.append(b.rms / b.predicted_rms)
        assert "predicted rms" in format_table(report)
    rms_ratio = float(np.sqrt(np.mean(np.square(ratios))))
    assert rms_ratio == pytest.approx(1.0, rel=0.5) and rms_ratio > 1 / 1.5
