"""Identification methods by name, and the metadata every identified model file carries.

``cpc2urdf identify --method NAME`` looks the method up in :data:`METHODS`. A method is a function
``(measurements, nominal_or_None) -> CPCModel`` whose model's ``metadata`` holds at least a
``provenance`` section (``{"method": NAME, ...}``) and may hold ``notes``; :func:`identify` adds
the ``residuals`` section (per record and per branch) for every method alike. To add a method,
add one entry to :data:`METHODS`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from cpc2urdf.errors import Cpc2UrdfError
from cpc2urdf.measurements import MeasurementSet
from cpc2urdf.model import CPCModel
from cpc2urdf.transforms import rotation_error

Method = Callable[[MeasurementSet, "CPCModel | None"], CPCModel]


def closed_form(ms: MeasurementSet, nominal: CPCModel | None) -> CPCModel:
    """Shih et al. sec. 4.2, generalised to trees (:mod:`cpc2urdf.identification.kinematics.closed_form`)."""
    from cpc2urdf.identification.kinematics.closed_form import identify_closed_form, provenance
    from cpc2urdf.identification.kinematics.protocol import recognise_protocol

    protocol = recognise_protocol(ms)
    model, details = identify_closed_form(ms, nominal, protocol=protocol)
    meta = dict(model.metadata)
    meta["provenance"] = provenance(ms, protocol, details)
    if details.notes:
        meta["notes"] = list(details.notes)
    return model.with_params(metadata=meta)


def refined(ms: MeasurementSet, nominal: CPCModel | None) -> CPCModel:
    """Closed form, then weighted least squares of every record (:mod:`cpc2urdf.identification.kinematics.refine`)."""
    from cpc2urdf.identification.kinematics.refine import identify_refined

    return identify_refined(ms, nominal)


def refined_robust(ms: MeasurementSet, nominal: CPCModel | None) -> CPCModel:
    """As ``refined``, rejecting gross outliers (named in the model's notes)."""
    from cpc2urdf.identification.kinematics.refine import identify_refined

    return identify_refined(ms, nominal, robust=True)


METHODS: dict[str, Method] = {
    "closed-form": closed_form,
    "refined": refined,
    "refined-robust": refined_robust,
}


def residuals(model: CPCModel, ms: MeasurementSet) -> dict[str, Any]:
    """Fit residuals of ``model`` on ``ms``: per branch (measured frame) and per record.

    Returns:
        ``{"per_frame": {frame: {"rms_translation_m", "max_translation_m", "rms_rotation_rad",
        "max_rotation_rad", "records"}}, "per_record": [{"label", frame: {"translation_m",
        "rotation_rad"}}, ...]}``: translation = distance between the measured and predicted
        origins [m], rotation = angle between the measured and predicted orientations [rad].
    """
    frames = [f for f in ms.frames if f in model.structure.frame_names]
    T = model.fk(ms.q, frames) if frames else {}
    per_frame: dict[str, Any] = {}
    per_record: list[dict[str, Any]] = [{"label": lb} for lb in ms.labels]
    for f in frames:
        ok = ms.has_pose(f)
        dt = np.linalg.norm(T[f][ok, :3, 3] - ms.poses[f][ok, :3, 3], axis=1)
        dr = rotation_error(T[f][ok, :3, :3], ms.poses[f][ok, :3, :3])
        per_frame[f] = {
            "records": int(ok.sum()),
            "rms_translation_m": float(np.sqrt(np.mean(dt**2))),
            "max_translation_m": float(np.max(dt)),
            "rms_rotation_rad": float(np.sqrt(np.mean(dr**2))),
            "max_rotation_rad": float(np.max(dr)),
        }
        for i, a, b in zip(np.flatnonzero(ok), dt, dr, strict=True):
            per_record[int(i)][f] = {"translation_m": float(a), "rotation_rad": float(b)}
    return {"per_frame": per_frame, "per_record": per_record}


DEFAULT_METHOD = "refined"


def identify(ms: MeasurementSet, method: str = DEFAULT_METHOD, nominal: CPCModel | None = None) -> CPCModel:
    """Run ``METHODS[method]`` and attach the ``residuals`` section.

    Args:
        ms: The measurements.
        method: A name in :data:`METHODS`; the default is the CLI's (closed form, then
            maximum-likelihood refinement).
        nominal: The nominal model (keeps unmeasured frames such as cameras, and fixes what the
            data leave open); default: the nominal model of the robot ``ms`` was read with.

    Raises:
        Cpc2UrdfError: Unknown method name.
        DegenerateDataError: The data cannot determine the robot.
    """
    if method not in METHODS:
        raise Cpc2UrdfError(f"unknown identification method {method!r}; known: {', '.join(METHODS)}")
    if nominal is None and ms.spec is not None and ms.spec.nominal is not None:
        nominal = ms.spec.nominal_model()
    model = METHODS[method](ms, nominal)
    meta = dict(model.metadata)
    meta.setdefault("provenance", {"method": method})
    meta["residuals"] = residuals(model, ms)
    return model.with_params(metadata=meta)


__all__ = ["DEFAULT_METHOD", "METHODS", "Method", "closed_form", "identify", "residuals"]
