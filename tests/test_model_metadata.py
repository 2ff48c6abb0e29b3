"""A model's metadata: typed sections that round-trip through model files unchanged."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cpc2urdf.errors import InputFileError
from cpc2urdf.files.model_file import model_from_json, model_to_json, save_model
from cpc2urdf.files.robot_ref import load_model
from cpc2urdf.model_metadata import (
    FrameResiduals,
    HandEyeRecord,
    ModelMetadata,
    Provenance,
    RecordResiduals,
    Residuals,
)


@pytest.mark.slow
def test_identified_model_file_round_trips_every_section(demo_run, tmp_path):
    demo_dir, _, _ = demo_run
    doc = json.loads((demo_dir / "model.json").read_text())
    assert {"provenance", "residuals", "uncertainty", "handeye"} <= set(doc)
    model = model_from_json(doc, "model.json")
    meta = model.metadata
    assert meta.provenance is not None and meta.provenance.method == "refined"
    assert meta.residuals is not None and set(meta.residuals.per_frame) == {
        "plate_left",
        "plate_right",
    }
    assert meta.uncertainty is not None and meta.uncertainty.matrix.shape == (32, 32)
    assert set(meta.handeye) == {"camera_left_optical", "camera_right_optical"}
    # writing it back gives the same document, section for section
    again = model_to_json(model)
    for key in ("provenance", "residuals", "uncertainty", "handeye", "notes"):
        assert json.dumps(again.get(key), sort_keys=True) == json.dumps(
            doc.get(key), sort_keys=True
        ), key
    path = save_model(model, tmp_path / "again.json")
    assert model_to_json(load_model(path)) == again


def test_sections_are_typed():
    res = Residuals(
        {"plate": FrameResiduals(3, 1e-3, 2e-3, 1e-2, 2e-2)},
        (RecordResiduals("q0", {"plate": (1e-3, 1e-2)}),),
    )
    he = HandEyeRecord(
        "plate", "kronecker", np.eye(4), np.eye(4), np.array([3.0, 4.0]), np.array([0.0, 0.0])
    )
    meta = ModelMetadata(
        description="d",
        provenance=Provenance("refined", "m.json", "iis_head", {"k": 1}),
        residuals=res,
        handeye={"cam": he},
        notes=("a",),
    )
    back = ModelMetadata.from_json(json.loads(json.dumps(meta.to_json())))
    assert back.provenance == meta.provenance and back.residuals == res and back.notes == ("a",)
    assert back.handeye["cam"].rms_translation_mm == pytest.approx(np.sqrt(12.5))
    assert meta.to_json()["handeye"]["cam"]["n_poses"] == 2


@pytest.mark.parametrize(
    ("section", "value", "expected"),
    [
        ("residuals", {"per_frame": {"plate_left": {"records": 3}}}, "bad 'residuals' section"),
        ("handeye", {"camera_left_optical": {"method": "kronecker"}}, "bad 'handeye' section"),
        ("uncertainty", {"format": "other"}, "bad 'uncertainty' section"),
        ("provenance", ["not", "an", "object"], "bad 'provenance' section"),
        ("notes", "one string", "bad 'notes' section"),
    ],
)
def test_a_bad_section_is_refused_naming_it(demo_run, section, value, expected):
    demo_dir, _, _ = demo_run
    doc = json.loads((demo_dir / "model.json").read_text())
    doc[section] = value
    with pytest.raises(InputFileError, match=expected):
        model_from_json(doc, "model.json")
