"""Measurement files: the issue's example, round trips, points -> poses, and clear errors."""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from cpc2urdf.errors import InputFileError, UnknownNameError
from cpc2urdf.files.measurements import (
    MeasurementSet,
    load_measurements,
    measurements_from_json,
    save_measurements,
)
from cpc2urdf.files.robot_ref import load_robot

EXAMPLE: dict[str, Any] = {
    "format": "cpc2urdf/measurements@1",
    "robot": "iis_head",
    "units": {"length": "m", "angle": "rad"},
    "records": [
        {
            "joints": {
                "table_x": 0.5,
                "table_y": 0.25,
                "pan": 1.57,
                "tilt": 0.52,
                "vergence_left": 0.78,
                "vergence_right": 0.78,
            },
            "poses": {
                "plate_left": {"matrix": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]},
                "plate_right": {"xyz": [0.1, 0.0, 1.5], "quat_xyzw": [0, 0, 0, 1]},
            },
        }
    ],
}


def _write(tmp_path: Path, doc: Any, name: str = "m.json") -> Path:
    p = tmp_path / name
    p.write_text(json.dumps(doc))
    return p


def test_issue_example_is_accepted(tmp_path: Path) -> None:
    ms = load_measurements(_write(tmp_path, EXAMPLE))
    assert ms.q.shape == (1, 6)
    assert ms.structure.joint_names == (
        "table_x",
        "table_y",
        "pan",
        "tilt",
        "vergence_left",
        "vergence_right",
    )
    np.testing.assert_array_equal(ms.q[0], [0.5, 0.25, 1.57, 0.52, 0.78, 0.78])
    np.testing.assert_array_equal(ms.poses["plate_left"][0], np.eye(4))
    np.testing.assert_allclose(ms.poses["plate_right"][0][:3, 3], [0.1, 0.0, 1.5])
    assert ms.has_pose("plate_left").tolist() == [True]
    assert ms.has_pose("camera_left_optical").tolist() == [False]
    assert ms.frames == ["plate_left", "plate_right"]
    with pytest.raises(UnknownNameError):
        ms.has_pose("plate_middle")


def test_mm_deg_units_and_missing_frames(tmp_path: Path) -> None:
    doc = copy.deepcopy(EXAMPLE)
    doc["units"] = {"length": "mm", "angle": "deg"}
    doc["records"][0]["joints"] = {
        "table_x": 500,
        "table_y": 250,
        "pan": 90,
        "tilt": 30,
        "vergence_left": 45,
        "vergence_right": 45,
    }
    doc["records"][0]["poses"]["plate_right"] = {"xyz": [100, 0, 1500], "rpy": [0, 0, 90]}
    doc["records"].append(
        {
            "label": "left only",
            "joints": doc["records"][0]["joints"],
            "poses": {"plate_left": doc["records"][0]["poses"]["plate_left"]},
        }
    )
    ms = load_measurements(_write(tmp_path, doc))
    np.testing.assert_allclose(ms.q[0], [0.5, 0.25, np.pi / 2, np.pi / 6, np.pi / 4, np.pi / 4])
    np.testing.assert_allclose(ms.poses["plate_right"][0][:3, 3], [0.1, 0.0, 1.5])
    np.testing.assert_allclose(ms.poses["plate_right"][0][:2, :2], [[0, -1], [1, 0]], atol=1e-15)
    assert ms.has_pose("plate_right").tolist() == [True, False]
    assert np.isnan(ms.poses["plate_right"][1]).all()
    assert ms.labels == ["record 0", "left only"]


def test_round_trip_is_exact(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    spec = load_robot("iis_head")
    model = spec.nominal_model()
    s = spec.structure
    lo, hi = s.lower, s.upper
    q = lo + (hi - lo) * rng.random((7, s.n_joints))
    poses = model.fk(q, ["plate_left", "plate_right"])
    poses["plate_right"][3] = np.nan
    ms = MeasurementSet.from_arrays(
        s, q, poses, robot="iis_head", metadata={"noise": {"model": "none"}}
    )
    path = save_measurements(ms, tmp_path / "out.json")
    back = load_measurements(path)
    np.testing.assert_array_equal(back.q, ms.q)
    for f in ("plate_left", "plate_right"):
        np.testing.assert_array_equal(back.has_pose(f), ms.has_pose(f))
        ok = ms.has_pose(f)
        np.testing.assert_array_equal(back.poses[f][ok], ms.poses[f][ok])
    assert back.metadata == {"noise": {"model": "none"}}
    sub = back.subset(back.has_pose("plate_right"))
    assert sub.n_records == 6 and sub.has_pose("plate_right").all()


def test_points_give_the_pose_by_registration(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    spec = load_robot("iis_head")
    model = spec.nominal_model()
    q = spec.structure.q_from_dict(EXAMPLE["records"][0]["joints"])
    T = model.fk_frame("plate_left", q)
    layout = np.array(spec.structure.frame("plate_left").layout)
    p_world = layout @ T[:3, :3].T + T[:3, 3]
    pts: list[Any] = [list(p * 1000) for p in p_world]  # in mm
    pts[4] = None  # an occluded circle
    doc = {
        "format": "cpc2urdf/measurements@1",
        "robot": "iis_head",
        "units": {"length": "mm", "angle": "rad"},
        "records": [
            {
                "joints": {
                    k: v * (1000 if k.startswith("table") else 1)
                    for k, v in EXAMPLE["records"][0]["joints"].items()
                },
                "points": {"plate_left": pts},
            }
        ],
    }
    ms = load_measurements(_write(tmp_path, doc))
    np.testing.assert_allclose(ms.poses["plate_left"][0], T, atol=1e-12)
    assert ms.fit_rms["plate_left"][0] < 1e-12
    assert np.isnan(ms.points["plate_left"][0, 4]).all()
    # Saved with points and pose; the given pose wins on reload and the points survive.
    ms.poses["plate_left"][0, :3, 3] += rng.normal(size=3) * 1e-3
    back = load_measurements(save_measurements(ms, tmp_path / "again.json"))
    np.testing.assert_array_equal(back.poses["plate_left"], ms.poses["plate_left"])
    np.testing.assert_array_equal(
        np.isnan(back.points["plate_left"]), np.isnan(ms.points["plate_left"])
    )


def test_robot_path_relative_to_the_file(tmp_path: Path) -> None:
    from cpc2urdf.files.model_file import save_model

    save_model(load_robot("iis_head").nominal_model(), tmp_path / "truth.json")
    doc = copy.deepcopy(EXAMPLE)
    doc["robot"] = "truth.json"
    sub = tmp_path / "sub"
    sub.mkdir()
    doc["robot"] = "../truth.json"
    ms = load_measurements(_write(sub, doc))
    assert ms.robot == "../truth.json"


def _bad(mutate: Any) -> dict[str, Any]:
    doc = copy.deepcopy(EXAMPLE)
    mutate(doc)
    return doc


def _set(path: list[Any], value: Any) -> Any:
    def f(doc: Any) -> None:
        d = doc
        for k in path[:-1]:
            d = d[k]
        d[path[-1]] = value

    return f


def _delete(path: list[Any]) -> Any:
    def f(doc: Any) -> None:
        d = doc
        for k in path[:-1]:
            d = d[k]
        del d[path[-1]]

    return f


BAD_CASES = {
    "wrong format": (
        _set(["format"], "cpc2urdf/measurements@3"),
        "expected 'cpc2urdf/measurements@1' (poses) or 'cpc2urdf/measurements@2' (with markers)",
    ),
    "unknown joint": (
        _set(["records", 0, "joints", "roll"], 0.1),
        "records[0].joints: unknown joint 'roll'",
    ),
    "missing joint": (
        _delete(["records", 0, "joints", "tilt"]),
        "records[0].joints lacks ['tilt']",
    ),
    "unknown frame": (
        _set(["records", 0, "poses", "plate_top"], {"xyz": [0, 0, 0], "quat_xyzw": [0, 0, 0, 1]}),
        "records[0].poses: unknown frame 'plate_top'",
    ),
    "no poses": (_set(["records", 0, "poses"], {}), "records[0] has no 'poses' and no 'points'"),
    "not orthonormal": (
        _set(["records", 0, "poses", "plate_left", "matrix", 0, 0], 1.1),
        "records[0].poses.plate_left.matrix rotation part is not orthonormal",
    ),
    "string number": (
        _set(["records", 0, "joints", "pan"], "1.57"),
        "records[0].joints.pan must be a number",
    ),
    "wrong unit name": (_set(["units"], {"length": "inch"}), "units.length must be one of"),
    "degrees in a rad file": (
        _set(["records", 0, "joints", "pan"], 90.0),
        "records[0].joints.pan = 90.0 rad is outside the joint limits",
    ),
    "unknown robot": (_set(["robot"], "no_such_head"), "no_such_head"),
    "bad points": (
        _set(["records", 0, "points"], {"plate_left": [[0, 0, 0]]}),
        "records[0].points.plate_left must list 9",
    ),
    "collinear points": (
        _set(
            ["records", 0],
            {
                "joints": EXAMPLE["records"][0]["joints"],
                "points": {"plate_left": [[0, 0, k] for k in range(9)]},
            },
        ),
        "records[0].points.plate_left: the measured points are collinear",
    ),
    "empty records": (_set(["records"], []), "'records' must be a non-empty list"),
    "noise negative": (
        _set(["noise"], {"sigma_t_m": -5e-4, "sigma_r_rad": 0.0087}),
        "noise.sigma_t_m: expected a positive number, the std of each translation entry [m], got -0.0005",
    ),
    "noise zero": (
        _set(["noise"], {"sigma_t_m": 5e-4, "sigma_r_rad": 0}),
        "noise.sigma_r_rad: expected a positive number, the std of the rotation error angle [rad], got 0",
    ),
    "noise with a unit": (
        _set(["noise"], {"sigma_t_m": "0.5 mm"}),
        "noise.sigma_t_m: expected a positive number",
    ),
    "noise infinite": (
        _set(["noise"], {"sigma_p_m": float("inf")}),
        "noise.sigma_p_m: non-finite number Infinity",
    ),
    "noise marker negative": (
        _set(["noise"], {"sigma_p_m": -1e-4}),
        "noise.sigma_p_m: expected a positive number, the std of each marker point coordinate [m]",
    ),
    "noise true": (
        _set(["noise"], {"sigma_p_m": True}),
        "noise.sigma_p_m: expected a positive number",
    ),
    "noise not an object": (_set(["noise"], 0.0005), "noise must be an object"),
}


@pytest.mark.parametrize("case", sorted(BAD_CASES))
def test_bad_input_names_file_record_and_field(tmp_path: Path, case: str) -> None:
    mutate, expected = BAD_CASES[case]
    path = _write(tmp_path, _bad(mutate))
    with pytest.raises(InputFileError) as err:
        load_measurements(path)
    msg = str(err.value)
    assert msg.startswith(str(path)), msg
    assert expected in msg, msg
    assert "\n" not in msg


def test_nan_in_a_file_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "nan.json"
    path.write_text(json.dumps(EXAMPLE).replace("0.52", "NaN"))
    with pytest.raises(InputFileError, match="non-finite number NaN"):
        load_measurements(path)


def test_in_memory_document_names_its_source() -> None:
    with pytest.raises(InputFileError, match=r"^mine: records\[0\].joints lacks"):
        measurements_from_json(_bad(_delete(["records", 0, "joints", "pan"])), "mine")


def test_a_stated_noise_is_kept_and_other_noise_entries_are_free(tmp_path: Path) -> None:
    """Positive sigmas are read as written; entries other than the three sigmas (the model's name,
    a pixel noise) stay free-form."""
    noise = {
        "model": "fig10",
        "sigma_t_m": 5e-4,
        "sigma_r_rad": 0.0087,
        "pixel_sigma_px": 0,
        "note": "rig A",
    }
    ms = load_measurements(_write(tmp_path, {**EXAMPLE, "noise": noise}))
    assert ms.metadata["noise"] == noise
