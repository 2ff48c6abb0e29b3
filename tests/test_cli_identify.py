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
from cpc2urdf.files.jsonio import write_json
from cpc2urdf.files.measurements import MeasurementSet, measurements_to_json
from cpc2urdf.files.robot_ref import load_model
from cpc2urdf.identification.simulation.design import protocol_q
from cpc2urdf.identification.simulation.random_robots import random_model
from cpc2urdf.model import CPCModel
from cpc2urdf.tolerances import FK_AGREEMENT_TOL


def _spec_doc(model: CPCModel) -> dict[str, Any]:
    """A robot spec with the tree only (no nominal geometry), in mm and degrees."""
    joints = []
    for j in model.structure.joints:
        scale = 1e3 if j.type == "prismatic" else 180 / np.pi
        joints.append(
            {
                "name": j.name,
                "type": j.type,
                "parent": j.parent,
                "lower": j.lower * scale,
                "upper": j.upper * scale,
            }
        )
    frames = [{"name": f.name, "parent": f.parent, "kind": f.kind} for f in model.structure.frames]
    return {
        "format": "cpc2urdf/robot@1",
        "name": "my_arm",
        "units": {"length": "mm", "angle": "deg"},
        "joints": joints,
        "frames": frames,
    }


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
    assert (
        main(
            ["identify", str(tmp / "measurements.json"), "-o", str(out), "--method", "closed-form"]
        )
        == 0
    )
    text = capsys.readouterr().out
    assert (
        "closed-form identification of 'my_arm'" in text and "dropped" in text
    )  # camera: no nominal
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


@pytest.mark.parametrize(
    "how,message",
    [
        ("never_moved", "joint 'j0' has fewer than two distinct readings"),
        ("no_q0", "no reference configuration q0"),
        ("several", "moved several joints away from the reference configuration"),
        ("no_poses", "moves no measured frame (no pose of plate0"),
    ],
)
def test_degenerate_data_is_named_with_exit_code_2(
    user_robot, capsys, how: str, message: str
) -> None:  # type: ignore[no-untyped-def]
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


@pytest.mark.slow
def test_user_robot_mistakes_are_named_without_noise_statement_or_nominal(
    user_robot, capsys
) -> None:  # type: ignore[no-untyped-def]
    """A spec without geometry, noise-free data without a noise statement: the refits still tell a
    swapped pair of plates (which the closed form cannot even fit as read), transposed rotations,
    radians labelled degrees and an off-by-one pairing (the fix loses q0: refitted from the fit as
    read), and the prismatic joints' travel against their limits tells the length unit."""
    import stage1_mistakes as sm

    truth, tmp, doc = user_robot
    plates = [f.name for f in truth.structure.frames if f.kind == "plate"]
    assert any(j.type == "prismatic" for j in truth.structure.joints)
    cases = [
        (
            sm.plates_swapped(doc, plates[0], plates[1]),
            f"the poses of {plates[0]} and {plates[1]} look swapped",
        ),
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


# ---- marker data: simulate --markers, the tracker CSV route, what identify prints ----------------


@pytest.fixture(scope="module")
def marker_sim(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``simulate iis_head --markers 3`` (M = 5, 10 held-out configurations)."""
    out = tmp_path_factory.mktemp("markers") / "sim"
    assert (
        main(
            [
                "simulate",
                "iis_head",
                "-o",
                str(out),
                "--markers",
                "3",
                "--M",
                "5",
                "--heldout",
                "10",
            ]
        )
        == 0
    )
    return out


def _heldout_marker_rms(model: CPCModel, held: MeasurementSet) -> float:
    """RMS distance [m] between the model's predicted marker points and the held-out (true) ones."""
    from cpc2urdf.identification.kinematics.points.point_identify import marker_positions

    pos = marker_positions(model)
    assert set(pos) == set(held.markers)
    T = model.fk(held.q, sorted({f for f, _ in pos.values()}))
    d = [
        np.linalg.norm(T[f][:, :3, :3] @ p + T[f][:, :3, 3] - held.marker_points[m], axis=1)
        for m, (f, p) in pos.items()
    ]
    return float(np.sqrt(np.mean(np.square(np.concatenate(d)))))


def test_simulated_marker_data_identify_and_predict_the_heldout_points(
    marker_sim: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``simulate --markers 3`` writes position-only files (@2; the held-out one with the true points);
    ``identify`` starts from the circle-point closed form, prints no rotation column, and predicts
    the held-out points better than one measurement's noise (the fit averages 31 records)."""
    from cpc2urdf.files.measurements import load_measurements

    doc = json.loads((marker_sim / "measurements.json").read_text())
    held_doc = json.loads((marker_sim / "heldout.json").read_text())
    assert doc["format"] == held_doc["format"] == "cpc2urdf/measurements@2"
    assert len(doc["markers"]) == 6 and doc["noise"]["sigma_p_m"] == pytest.approx(1e-4)
    assert held_doc["noise"] == {"model": "none"} and doc["markers"] == held_doc["markers"]
    assert all("poses" not in r for r in doc["records"] + held_doc["records"])
    capsys.readouterr()
    out = tmp_path / "model.json"
    assert main(["identify", str(marker_sim / "measurements.json"), "-o", str(out)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith(f"wrote {out}: refined identification of 'iis_head' from 31 records")
    assert lines[1] == "  start: circle-point"
    assert sum("fit residual rms" in x for x in lines) == 6 and not any(
        "deg rms" in x for x in lines
    )
    model, truth = load_model(out), load_model(marker_sim / "truth.json")
    held = load_measurements(marker_sim / "heldout.json")
    nominal = load_model("iis_head").with_params(world_to_base=truth.world_to_base)
    assert _heldout_marker_rms(model, held) < 1e-4  # sigma_p: --marker-sigma-mm 0.1
    # The truth's markers, placed on the nominal robot, miss by the geometric error (~mm): the fit
    # did learn the robot.
    assert _heldout_marker_rms(model, held) < 0.1 * _heldout_marker_rms(
        nominal.with_params(metadata=model.metadata), held
    )


def test_pose_data_print_the_start_and_the_rotation_column(user_robot, capsys) -> None:  # type: ignore[no-untyped-def]
    _, tmp, _ = user_robot
    assert main(["identify", str(tmp / "measurements.json"), "-o", str(tmp / "m.json")]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[1] == "  start: closed-form" and "deg rms" in lines[2]


def _as_csv(ms: MeasurementSet, path: Path) -> Path:
    """A tracker export of a marker set: one file, ``config,marker,x,y,z,<joints>`` in mm and deg."""
    import csv

    s = ms.structure
    scale = [1e3 if j.type == "prismatic" else 180 / np.pi for j in s.joints]
    with path.open("w", newline="") as fh:
        fh.write("# units: length=mm angle=deg\n")
        w = csv.writer(fh)
        w.writerow(["config", "marker", "x", "y", "z", *s.joint_names])
        for i, label in enumerate(ms.labels):
            for m, Y in ms.marker_points.items():
                if np.all(np.isfinite(Y[i])):
                    w.writerow(
                        [
                            label,
                            m,
                            *(repr(float(v) * 1e3) for v in Y[i]),
                            *(repr(float(v) * k) for v, k in zip(ms.q[i], scale, strict=True)),
                        ]
                    )
    return path


def test_tracker_csv_route_gives_the_model_of_the_same_data_as_a_file(
    marker_sim: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``identify tracker.csv --robot iis_head --marker NAME=LINK ...``: the same points as the
    measurement file give the same model (the CSV does not state the noise: a-posteriori scale, same
    estimate)."""
    from cpc2urdf.files.measurements import load_measurements
    from cpc2urdf.identification.kinematics.points.point_identify import marker_positions

    ms = load_measurements(marker_sim / "measurements.json")
    csv_path = _as_csv(ms, tmp_path / "tracker.csv")
    links = [f"--marker={m}={mk.frame}" for m, mk in ms.markers.items()]
    assert (
        main(["identify", str(marker_sim / "measurements.json"), "-o", str(tmp_path / "a.json")])
        == 0
    )
    assert (
        main(
            [
                "identify",
                str(csv_path),
                "-o",
                str(tmp_path / "b.json"),
                "--robot",
                "iis_head",
                *links,
            ]
        )
        == 0
    )
    assert "start: circle-point" in capsys.readouterr().out
    a, b = load_model(tmp_path / "a.json"), load_model(tmp_path / "b.json")
    Q = np.random.default_rng(5).uniform(
        a.structure.lower, a.structure.upper, (20, a.structure.n_joints)
    )
    Ta, Tb = a.fk(Q), b.fk(Q)
    for f in Ta:
        assert np.max(np.abs(Ta[f] - Tb[f])) < 1e-6
    pa, pb = marker_positions(a), marker_positions(b)
    assert all(np.max(np.abs(pa[m][1] - pb[m][1])) < 1e-6 for m in pa)


@pytest.mark.parametrize(
    ("extra", "words"),
    [
        ((), "a tracker CSV export needs --robot"),
        (("--robot", "iis_head"), "a tracker CSV export needs --marker NAME=LINK"),
        (
            ("--robot", "iis_head", "--marker", "plate_left_m0"),
            "--marker 'plate_left_m0': expected NAME=LINK",
        ),
        (
            ("--robot", "iis_head", "--marker", "a=plate_left", "--marker", "a=plate_right"),
            "--marker 'a' is given twice",
        ),
        (
            (
                "--robot",
                "iis_head",
                "--marker",
                "plate_left_m0=elbow",
                *(
                    f"--marker=plate_{s}_m{k}=plate_{s}"
                    for s in ("left", "right")
                    for k in range(3)
                    if (s, k) != ("left", 0)
                ),
            ),
            "unknown frame 'elbow'",
        ),
        (
            ("--robot", "iis_head", "--marker", "plate_left_m0=plate_left"),
            "marker 'plate_left_m1' has no link",
        ),
        (("--robot", "iis_head", "--units-length", "inch"), "invalid choice: 'inch'"),
    ],
)
def test_tracker_csv_route_refuses_bad_input_in_one_line(
    marker_sim: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    extra: tuple[str, ...],
    words: str,
) -> None:
    from cpc2urdf.files.measurements import load_measurements

    csv_path = _as_csv(
        load_measurements(marker_sim / "measurements.json"), tmp_path / "tracker.csv"
    )
    out = tmp_path / "m.json"
    assert main(["identify", str(csv_path), "-o", str(out), *extra]) == 2
    err = capsys.readouterr().err
    assert words in err and err.count("\n") == 1, err
    assert not out.exists()


def test_csv_options_on_a_measurement_file_are_refused(
    marker_sim: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "m.json"
    assert (
        main(
            [
                "identify",
                str(marker_sim / "measurements.json"),
                "-o",
                str(out),
                "--marker",
                "a=plate_left",
            ]
        )
        == 2
    )
    assert "--marker applies to a tracker CSV export (.csv)" in capsys.readouterr().err
    assert not out.exists()
