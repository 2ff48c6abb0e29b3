"""Model files (``cpc2urdf/model@1``): a nominal or identified robot, ready for URDF export.

Same tree fields as a robot spec (see :mod:`cpc2urdf.files.spec`), but every joint and frame carries
its CPC constants under ``"cpc"`` and ``world_to_base`` is required::

    {
      "format": "cpc2urdf/model@1",
      "name": "iis_head",
      "units": {"length": "m", "angle": "rad"},
      "world_to_base": {"cpc": {"b": [0, 0, 1], "beta": 0, "l": [0, 0, 0]}},
      "joints": [{"name": "table_x", "type": "prismatic", "parent": "base",
                  "lower": 0, "upper": 1, "velocity": 0.1, "effort": 100,
                  "cpc": {"b": [0, 0, 1], "beta": 0, "l": [0, 0, 0]}}, ...],
      "frames": [{"name": "plate_left", "parent": "vergence_left", "kind": "plate",
                  "cpc": {...}}, ...],
      "provenance": {...}, "uncertainty": {...}, "residuals": {...},    # optional, free-form
      "urdf": {"path": "/abs/robot.urdf", "root": "base_footprint", ...}  # optional, see below
    }

A model built from a URDF (:mod:`cpc2urdf.urdf.robot`) carries the optional ``"urdf"`` section:
the source file, its root link, the CPC name of each URDF joint and link it models with each
joint's axis rotation, and the origins and axes the constants were derived from
(:class:`~cpc2urdf.urdf.robot.UrdfSource`), so that ``export`` writes that URDF back with the
calibrated origins (:mod:`cpc2urdf.urdf.writeback`).

Files are written in SI units with full float precision; they may be read in mm/deg.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from cpc2urdf.errors import Cpc2UrdfError, InputFileError
from cpc2urdf.files.jsonio import require_format, write_json
from cpc2urdf.files.spec import (
    cpc_to_json,
    parse_placement,
    parse_tree,
)
from cpc2urdf.files.units import Units
from cpc2urdf.model import BASE, CPCModel
from cpc2urdf.model_metadata import ModelMetadata
from cpc2urdf.urdf.robot import URDF_SECTION, UrdfSource, urdf_source, with_urdf_source

MODEL_FORMAT = "cpc2urdf/model@1"
# Optional sections a model file may carry: CPCModel.metadata (cpc2urdf.model_metadata) types them.
OPTIONAL_SECTIONS = (
    "description",
    "provenance",
    "uncertainty",
    "residuals",
    "handeye",
    "notes",
    URDF_SECTION,
)


def model_from_json(doc: Any, source: str = "<model>") -> CPCModel:
    """Parse a ``cpc2urdf/model@1`` document; errors name ``source`` and the field."""
    try:
        d = require_format(doc, MODEL_FORMAT, source)
        allowed = {
            "format",
            "name",
            "units",
            "world_to_base",
            "joints",
            "frames",
            *OPTIONAL_SECTIONS,
        }
        unknown = set(d) - allowed
        if unknown:
            raise ValueError(f"unknown keys {sorted(unknown)}; expected some of {sorted(allowed)}")
        units = Units.from_json(d.get("units"))
        structure, geo_j, geo_f = parse_tree(d, units)
        if "world_to_base" not in d:
            raise ValueError("lacks 'world_to_base'")
        T_wb = parse_placement(d["world_to_base"], units, "world_to_base")
        joints, frames = {}, {}
        for j, g in zip(structure.joints, geo_j, strict=True):
            if g is None:
                raise ValueError(f"joint {j.name!r} lacks 'cpc'")
            joints[j.name] = parse_placement(g, units, f"joint {j.name!r}")
        for f, g in zip(structure.frames, geo_f, strict=True):
            if g is None:
                raise ValueError(f"frame {f.name!r} lacks 'cpc'")
            frames[f.name] = parse_placement(g, units, f"frame {f.name!r}")
        model = CPCModel(structure, T_wb, joints, frames, ModelMetadata.from_json(d, source))
        if URDF_SECTION in d:
            model = with_urdf_source(model, UrdfSource.from_json(d[URDF_SECTION]))
        return model
    except InputFileError:
        raise
    except (ValueError, Cpc2UrdfError) as e:
        raise InputFileError(source, str(e)) from e


def model_to_json(model: CPCModel) -> dict[str, Any]:
    """The model as a ``cpc2urdf/model@1`` document in SI units."""
    s = model.structure
    joints = []
    for j in s.joints:
        entry: dict[str, Any] = {
            "name": j.name,
            "type": j.type,
            "parent": j.parent,
            "lower": j.lower,
            "upper": j.upper,
            "velocity": j.velocity,
            "effort": j.effort,
        }
        if j.calibration_range is not None:
            entry["calibration_range"] = list(j.calibration_range)
        entry["cpc"] = cpc_to_json(model.joints[j.name])
        joints.append(entry)
    frames = []
    for f in s.frames:
        fe: dict[str, Any] = {"name": f.name, "parent": f.parent, "kind": f.kind}
        if f.layout is not None:
            fe["layout"] = [list(p) for p in f.layout]
        fe["cpc"] = cpc_to_json(model.frames[f.name])
        frames.append(fe)
    doc: dict[str, Any] = {
        "format": MODEL_FORMAT,
        "name": s.name,
        "units": {"length": "m", "angle": "rad"},
        "world_to_base": {"cpc": cpc_to_json(model.world_to_base)},
        "joints": joints,
        "frames": frames,
    }
    doc.update(model.metadata.to_json())
    source = urdf_source(model)
    if source is not None:
        doc[URDF_SECTION] = source.to_json()
    return doc


def save_model(model: CPCModel, path: str | Path) -> Path:
    """Write ``model`` atomically as a model file."""
    return write_json(path, model_to_json(model))


__all__ = ["BASE", "MODEL_FORMAT", "model_from_json", "model_to_json", "save_model"]
