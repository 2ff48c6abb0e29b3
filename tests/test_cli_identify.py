"""``cpc2urdf identify``: a user-defined robot (spec only, no nominal geometry) end to end, the
model file's sections, and every kind of degenerate data named with exit code 2 and no output."""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from cpc2urdf.cli import main
from cpc2urdf.fileio import write_json
from cpc2urdf.identification.simulation.design import protocol_q
from cpc2urdf.identification.simulation.random_robots import random_model
from cpc2urdf.measurements import MeasurementSet, measurements_to_json
from cpc2urdf.model import CPCModel
from cpc2urdf.robot_ref import load_model
from cpc2urdf.tolerances import FK_AGREEMENT_TOL


def _spec_doc(model: CPCModel) -> dict[str, Any]:
    """A robot spec with the tree only (no nominal geometry), in mm and degrees."""
    joints = []
    for j in model.structure.joints:
        scale = 1e3 if j.type == "prismatic" else 180 / np.pi
        joints.append({"name": j.name, "type": j.type, "parent": j.parent,
                       "lower": j.lower * scale, "upper": j.upper * scale})
    frames = [{"name": f.name, "parent": f.parent, "kind": f.kind} for f in model.structure.frames]
    return {"format": "cpc2urdf/robot@1", "name": "my_arm", "units": {"length": "mm", "angle": "deg"},
            "joints": joints, "frames": frames}


@pytest.fixture()
def user_robot(tmp_path: Path) -> tuple[CPCModel, Path, dict[str, Any]]:
    rng = np.random.default_rng(11)
    truth = random_model(rng, 5, serial=False, p_branch=0.6, cameras=1, name="my_arm")
    while len([f for f in truth.structure.frames if f.kind == "plate"]) < 2:
        truth = random_model(rng, 5, serial=False, p_branch=0.6, cameras=1, name="my_arm")
    write_json(tmp_path / "my_arm.json", _spec_doc(truth))
    plates = [f.name for f in truth.structure.frames if f.kind == "plate"]
    q = protocol_q(truth, 4, rng)
    ms = MeasurementSet.from_arrays(truth.structure, q, truth.fk(q, plates))
    doc = measurements_to_json(ms, robot="my_arm.json")
    write_json(tmp_path / "measurements.json", doc)
    Q = rng.uniform(truth.structure.lower, truth.structure.upper, (20, truth.structure.n_joints))
    held = MeasurementSet.from_arrays(truth.structure, Q, truth.fk(Q, plates))
    write_json(tmp_path / "heldout.json", measurements_to_json(held, robot="my_arm.json"))
    return truth, tmp_path, doc


def test_user_robot_identifies_end_to_end(user_robot, capsys) -> None:  # type: ignore[no-untyped-def]
    truth, tmp, _ = user_robot
    out = tmp / "model.json"
    assert main(["identify", str(tmp / "measurements.json"), "-o", str(out), "--method", "closed-form"]) == 0
    text = capsys.readouterr().out
    assert "closed-form identification of 'my_arm'" in text and "dropped" in text  # camera: no nominal
    model = load_model(out)
    plates = [f.name for f in truth.structure.frames if f.kind == "plate"]
    assert model.structure.frame_names == tuple(plates)
    s = truth.structure
    Q = np.random.default_rng(2).uniform(s.lower, s.upper, (50, s.n_joints))
    A, B = truth.fk(Q, plates), model.fk(Q, plates)
    for f in plates:
        assert np.max(np.abs(A[f] - B[f])) < FK_AGREEMENT_TOL
    doc = json.loads(out.read_text())
    assert doc["provenance"]["method"] == "closed-form"
    assert doc["provenance"]["records"] == len(doc["residuals"]["per_record"])
    assert set(doc["residuals"]["per_frame"]) == set(plates)
    assert all(r["max_translation_m"] < 1e-9 for r in doc["residuals"]["per_frame"].values())
    assert main(["accuracy", str(out), str(tmp / "heldout.json"), "--json"]) == 0
    acc = json.loads(capsys.readouterr().out)
    assert all(b["max_mm"] < 1e-6 for b in acc.values())
    assert main(["export", str(out), "-o", str(tmp / "my_arm.urdf")]) == 0


def _break(doc: dict[str, Any], how: str) -> dict[str, Any]:
    d = copy.deepcopy(doc)
    recs = d["records"]
    joints = list(recs[0]["joints"])
    if how == "never_moved":  # keep q0 and drop every record of the first joint's sweep
        q0 = recs[0]["joints"]
        d["records"] = [r for r in recs if r["joints"][joints[0]] == q0[joints[0]]]
    elif how == "no_q0":
        d["records"] = recs[1:]
    elif how == "several":
        recs[-1]["joints"][joints[0]] = recs[1]["joints"][joints[0]]
    elif how == "no_poses":
        frame = next(iter(recs[0]["poses"]))
        for r in recs:
            r["poses"].pop(frame, None)
        d["records"] = [r for r in recs if r["poses"]]
    return d


@pytest.mark.parametrize("how,message", [
    ("never_moved", "joint 'j0' has fewer than two distinct readings"),
    ("no_q0", "no reference configuration q0"),
    ("several", "moved several joints away from the reference configuration"),
    ("no_poses", "moves no measured frame (no pose of plate0"),
])
def test_degenerate_data_is_named_with_exit_code_2(user_robot, capsys, how: str, message: str) -> None:  # type: ignore[no-untyped-def]
    _, tmp, doc = user_robot
    write_json(tmp / "bad.json", _break(doc, how))
    out = tmp / "bad_model.json"
    assert main(["identify", str(tmp / "bad.json"), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1, err
    assert not out.exists()


def test_unknown_method_and_missing_file(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    assert main(["identify", "nope.json", "-o", str(tmp_path / "m.json"), "--method", "magic"]) == 2
    assert main(["identify", str(tmp_path / "nope.json"), "-o", str(tmp_path / "m.json")]) == 2
    assert "nope.json: no such file" in capsys.readouterr().err


def test_default_method_is_refined_and_exact_on_noise_free_data(user_robot, capsys) -> None:  # type: ignore[no-untyped-def]
    truth, tmp, _ = user_robot
    out = tmp / "refined.json"
    assert main(["identify", str(tmp / "measurements.json"), "-o", str(out)]) == 0
    assert "refined identification of 'my_arm'" in capsys.readouterr().out
    model = load_model(out)
    assert model.metadata.uncertainty is not None
    plates = [f.name for f in truth.structure.frames if f.kind == "plate"]
    s = truth.structure
    Q = np.random.default_rng(3).uniform(s.lower, s.upper, (50, s.n_joints))
    A, B = truth.fk(Q, plates), model.fk(Q, plates)
    for f in plates:
        assert np.max(np.abs(A[f] - B[f])) < FK_AGREEMENT_TOL


def test_user_robot_mistakes_are_named_without_noise_statement_or_nominal(user_robot, capsys) -> None:  # type: ignore[no-untyped-def]
    """A spec without geometry, noise-free data without a noise statement: the refits still tell a
    swapped pair of plates (which the closed form cannot even fit as read), transposed rotations,
    radians labelled degrees and an off-by-one pairing (the fix loses q0: refitted from the fit as
    read), and the prismatic joints' travel against their limits tells the length unit."""
    import stage1_mistakes as sm

    truth, tmp, doc = user_robot
    plates = [f.name for f in truth.structure.frames if f.kind == "plate"]
    assert any(j.type == "prismatic" for j in truth.structure.joints)
    cases = [
        (sm.plates_swapped(doc, plates[0], plates[1]), f"the poses of {plates[0]} and {plates[1]} look swapped"),
        (sm.metres_as_mm(doc), "lengths look like metres labelled mm"),
        (sm.rotations_transposed(doc), "the rotation blocks look transposed"),
        (sm.radians_as_degrees(doc), "revolute readings look like radians labelled deg"),
        (sm.next_record_poses(doc), "readings look paired with the next record's poses"),
    ]
    for k, (bad, words) in enumerate(cases):
        write_json(tmp / f"bad{k}.json", bad)
        out = tmp / f"bad{k}_model.json"
        assert main(["identify", str(tmp / f"bad{k}.json"), "-o", str(out)]) == 2
        err = capsys.readouterr().err
        assert words in err and err.count("\n") == 1, err
        assert not out.exists()
