"""Spec and model files: round trip, units, and one clear error for every kind of bad input."""

import copy
import json

import numpy as np
import pytest

from cpc2urdf.errors import InputFileError
from cpc2urdf.files.model_file import model_to_json, save_model
from cpc2urdf.files.robot_ref import load_model, load_robot
from cpc2urdf.files.spec import load_spec
from cpc2urdf.model_metadata import ModelMetadata, Provenance
from cpc2urdf.robots import available, spec_path
from random_trees import random_tree


def test_shipped_robots():
    assert "iis_head" in available()
    spec = load_robot("iis_head")
    assert spec.nominal is not None
    assert [f.kind for f in spec.structure.frames] == ["plate", "plate", "camera", "camera"]
    assert len(spec.structure.frame("plate_left").layout) == 9
    assert spec.structure.frame("plate_left").layout[0] == (0.0, 0.0, 0.0)  # centre circle = origin


def test_model_round_trip_is_exact(tmp_path):
    rng = np.random.default_rng(0)
    for k in range(10):
        m = random_tree(rng)
        m = m.with_params(
            metadata=ModelMetadata(provenance=Provenance(method="test", details={"k": k}))
        )
        save_model(m, tmp_path / "m.json")
        m2 = load_model(tmp_path / "m.json")
        assert m2.metadata == m.metadata and m2.metadata.provenance.to_json() == {
            "method": "test",
            "k": k,
        }
        Q = rng.uniform(m.structure.lower, m.structure.upper, size=(5, m.structure.n_joints))
        a, b = m.fk(Q), m2.fk(Q)
        for f in a:
            np.testing.assert_array_equal(a[f], b[f])


def test_units_mm_deg_are_converted_once(tmp_path):
    doc = model_to_json(load_model("iis_head"))
    doc["units"] = {"length": "mm", "angle": "deg"}
    for j in doc["joints"]:
        s = 1000.0 if j["type"] == "prismatic" else 180 / np.pi
        for k in ("lower", "upper", "velocity"):
            j[k] *= s
        j.pop("calibration_range")
        j["cpc"]["l"] = [v * 1000 for v in j["cpc"]["l"]]
        j["cpc"]["beta"] = np.degrees(j["cpc"]["beta"])
    for f in doc["frames"]:
        f["cpc"]["l"] = [v * 1000 for v in f["cpc"]["l"]]
        f["cpc"]["beta"] = np.degrees(f["cpc"]["beta"])
        if "layout" in f:
            f["layout"] = [[v * 1000 for v in p] for p in f["layout"]]
    (tmp_path / "mm.json").write_text(json.dumps(doc))
    a, b = load_model("iis_head"), load_model(tmp_path / "mm.json")
    q = np.array([0.5, 0.2, 1.0, 0.5, 0.7, 0.8])
    for f in a.structure.frame_names:
        np.testing.assert_allclose(a.fk(q)[f], b.fk(q)[f], atol=1e-12)
    assert b.structure.joint("pan").upper == pytest.approx(np.pi)


def _base_doc():
    return model_to_json(load_model("iis_head"))


def _mutations():
    def set_(path, value):
        def f(d):
            obj = d
            for key in path[:-1]:
                obj = obj[key]
            obj[path[-1]] = value

        return f

    def delete(path):
        def f(d):
            obj = d
            for key in path[:-1]:
                obj = obj[key]
            del obj[path[-1]]

        return f

    return {
        "format": (set_(["format"], "cpc2urdf/model@9"), "format is 'cpc2urdf/model@9'"),
        "parent": (set_(["joints", 2, "parent"], "nope"), "joint 'pan': parent 'nope'"),
        "lower>upper": (set_(["joints", 3, "lower"], 3.0), "joint 'tilt': lower limit 3.0 > upper"),
        "nan-like": (
            set_(["joints", 3, "cpc", "beta"], "NaN"),
            "joint 'tilt'.cpc.beta must be a number",
        ),
        "b not unit": (
            set_(["frames", 0, "cpc", "b"], [0, 0, 2]),
            "frame 'plate_left'.cpc.b must be a unit vector",
        ),
        "type": (
            set_(["joints", 0, "type"], "continuous"),
            "joint 'table_x'.type must be 'revolute' or 'prismatic'",
        ),
        "no limits": (delete(["joints", 1, "lower"]), "joint 'table_y' lacks 'lower'"),
        "frame parent": (
            set_(["frames", 1, "parent"], "elbow"),
            "frame 'plate_right': parent 'elbow'",
        ),
        "cycle": (set_(["joints", 2, "parent"], "tilt"), "do not connect to 'base'"),
        "units": (set_(["units"], {"length": "inch"}), "units.length must be one of"),
        "unknown key": (set_(["colour"], "red"), "unknown keys ['colour']"),
        "cpc missing": (delete(["joints", 4, "cpc"]), "joint 'vergence_left' lacks 'cpc'"),
        "l short": (
            set_(["joints", 4, "cpc", "l"], [0, 0]),
            "joint 'vergence_left'.cpc.l must be a list of 3 numbers",
        ),
        "dup": (set_(["frames", 1, "name"], "plate_left"), "name 'plate_left' is used twice"),
    }


@pytest.mark.parametrize("case", sorted(_mutations()))
def test_bad_model_files_name_the_problem(tmp_path, case):
    mutate, expected = _mutations()[case]
    doc = copy.deepcopy(_base_doc())
    mutate(doc)
    p = tmp_path / "bad.json"
    p.write_text(json.dumps(doc))
    with pytest.raises(InputFileError) as e:
        load_model(p)
    msg = str(e.value)
    assert str(p) in msg and expected in msg
    assert "\n" not in msg


def test_truncated_and_nan_json(tmp_path):
    text = json.dumps(_base_doc())
    (tmp_path / "t.json").write_text(text[: len(text) // 2])
    with pytest.raises(InputFileError, match="not valid JSON"):
        load_model(tmp_path / "t.json")
    (tmp_path / "n.json").write_text(text.replace('"beta": 0.0', '"beta": NaN', 1))
    with pytest.raises(InputFileError, match="non-finite number NaN"):
        load_model(tmp_path / "n.json")
    with pytest.raises(InputFileError, match="no such file"):
        load_model(tmp_path / "missing.json")


def test_spec_without_geometry_loads_but_has_no_nominal(tmp_path):
    doc = json.loads(spec_path("iis_head").read_text())
    for j in doc["joints"]:
        del j["nominal"]
    for f in doc["frames"]:
        del f["nominal"]
    doc["geometry"] = "cpc"
    (tmp_path / "s.json").write_text(json.dumps(doc))
    spec = load_spec(tmp_path / "s.json")
    assert spec.nominal is None and spec.structure.n_joints == 6
    with pytest.raises(Exception, match="no nominal geometry"):
        spec.nominal_model()


def test_partial_geometry_is_refused(tmp_path):
    doc = json.loads(spec_path("iis_head").read_text())
    del doc["joints"][3]["nominal"]
    (tmp_path / "s.json").write_text(json.dumps(doc))
    with pytest.raises(InputFileError, match="not for \\['tilt'\\]"):
        load_spec(tmp_path / "s.json")
