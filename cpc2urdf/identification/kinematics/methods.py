"""Identification methods by name, and the metadata every identified model file carries.

``cpc2urdf identify --method NAME`` looks the method up in :data:`METHODS`. A method is a function
``(measurements, nominal_or_None) -> CPCModel`` whose model's ``metadata``
(:class:`~cpc2urdf.model_metadata.ModelMetadata`) holds at least a ``provenance`` and may hold
``notes``; :func:`identify` adds the fit ``residuals`` (per record and per branch) for every method
alike. To add a method,
add one entry to :data:`METHODS`.

The CLI's default, "closed form, then refine", is :func:`identify_refined`: it starts the
maximum-likelihood refinement (:mod:`refine`) from the closed form (:mod:`closed_form`), or from
the nominal model placed in world (:func:`align_base`) when the records do not follow the
one-joint-at-a-time protocol.

The closed form and the refinement are imported inside the methods that run them: the CLI builds
its parser from :data:`METHODS`, and scipy's optimiser should not slow down every command.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from cpc2urdf.errors import Cpc2UrdfError, DegenerateDataError
from cpc2urdf.identification.kinematics.problem import DEFAULT_SIGMA_R, DEFAULT_SIGMA_T
from cpc2urdf.measurements import MeasurementSet
from cpc2urdf.model import CPCModel, CPCParams
from cpc2urdf.model_metadata import FrameResiduals, Provenance, RecordResiduals, Residuals
from cpc2urdf.transforms import rotation_error

Method = Callable[[MeasurementSet, "CPCModel | None"], CPCModel]


def closed_form(ms: MeasurementSet, nominal: CPCModel | None) -> CPCModel:
    """Shih et al. sec. 4.2, generalised to trees (:mod:`cpc2urdf.identification.kinematics.closed_form`)."""
    from cpc2urdf.identification.kinematics.closed_form import identify_closed_form, provenance
    from cpc2urdf.identification.kinematics.protocol import recognise_protocol

    protocol = recognise_protocol(ms)
    model, details = identify_closed_form(ms, nominal, protocol=protocol)
    meta = model.metadata.replace(provenance=provenance(ms, protocol, details), notes=tuple(details.notes))
    return model.with_params(metadata=meta)


def noise_from_metadata(metadata: dict[str, Any]) -> tuple[float, float, bool]:
    """``(sigma_t, sigma_r, known)`` from a measurement set's ``noise`` section.

    The simulator writes ``{"model": "fig10", "sigma_t_m": ..., "sigma_r_rad": ...}``; then the
    sigmas are known. Otherwise (real data, stereo pixel noise) the paper's 0.5 mm / 0.5 deg set
    the relative weights and ``known`` is False (use the a-posteriori covariance scale).
    """
    noise = metadata.get("noise") if isinstance(metadata, dict) else None
    if isinstance(noise, dict):
        st, sr = noise.get("sigma_t_m"), noise.get("sigma_r_rad")
        if isinstance(st, (int, float)) and isinstance(sr, (int, float)) and st > 0 and sr > 0:
            return float(st), float(sr), True
    return DEFAULT_SIGMA_T, DEFAULT_SIGMA_R, False


def _carry_frames(refined: CPCModel, start: CPCModel, fitted: list[str]) -> CPCModel:
    """Unfitted frames (cameras) keep their pose relative to a fitted frame on the same link."""
    s = refined.structure
    moved = {}
    for f in s.frames:
        if f.name in fitted:
            continue
        anchor = next((g for g in fitted if s.frame(g).parent == f.parent), None)
        if anchor is None:
            continue
        T_link_anchor_old = start.frames[anchor].matrix()
        T_link_anchor_new = refined.frames[anchor].matrix()
        T = T_link_anchor_new @ np.linalg.solve(T_link_anchor_old, start.frames[f.name].matrix())
        moved[f.name] = CPCParams.from_matrix(T)
    return refined.with_params(frames=moved) if moved else refined


def align_base(model: CPCModel, ms: MeasurementSet, frames: list[str]) -> CPCModel:
    """``model`` with ``T_world_base`` re-fitted so its frame origins best match the measured ones.

    A nominal model usually does not know where the robot stands in the measuring system's
    world; the chart of :class:`Parametrization` keeps ``T_world_base`` fixed (gauge), so a start
    must be placed first. Kabsch/Arun fit of all measured origins (sec. 3.3's registration).
    """
    T_pred = model.fk(ms.q, frames)
    a, b = [], []
    for f in frames:
        ok = ms.has_pose(f)
        a.append(T_pred[f][ok, :3, 3])
        b.append(ms.poses[f][ok, :3, 3])
    A, B = np.concatenate(a), np.concatenate(b)
    ca, cb = A.mean(0), B.mean(0)
    U, _, Vt = np.linalg.svd((A - ca).T @ (B - cb))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0])
    R = Vt.T @ D @ U.T
    G = np.eye(4)
    G[:3, :3], G[:3, 3] = R, cb - R @ ca
    return model.with_params(world_to_base=CPCParams.from_matrix(G @ model.T_world_base()))


def identify_refined(ms: MeasurementSet, nominal: CPCModel | None = None, *, robust: bool = False) -> CPCModel:
    """``cpc2urdf identify --method refined``: closed form, then :func:`refine.refine` on every record.

    Starts from the closed form (one-joint-at-a-time data); if the records do not follow that
    protocol and a nominal model is given, starts from the nominal model instead (arbitrary
    configurations). Noise sigmas come from the measurement file's ``noise`` section when it
    states them (then the covariance trusts them), else 0.5 mm / 0.5 deg with the a-posteriori
    covariance scale. Unmeasured frames (cameras) keep their pose relative to the plate on their
    link. The model carries ``provenance`` (with the start's), ``uncertainty`` and ``notes``.

    Raises:
        DegenerateDataError: Neither the closed form nor a nominal model can start it.
    """
    from cpc2urdf.identification.kinematics.refine import refine

    notes: list[str] = []
    try:
        start = closed_form(ms, nominal)
        start_method = "closed-form"
    except DegenerateDataError as e:
        if nominal is None:
            raise DegenerateDataError(
                f"refined identification needs a start: the closed form failed ({e}) and the robot "
                "has no nominal geometry"
            ) from e
        fitted = [f for f in nominal.structure.frame_names if f in ms.poses and ms.has_pose(f).any()]
        start, start_method = align_base(nominal, ms, fitted), "nominal"
        notes.append(
            f"closed form not applicable ({e}); refinement started from the nominal model placed "
            "in world by a rigid fit of the measured plate origins"
        )
    sigma_t, sigma_r, known = noise_from_metadata(ms.metadata)
    fitted = [f for f in start.structure.frame_names if f in ms.poses and ms.has_pose(f).any()]
    res = refine(start, ms, sigma_t, sigma_r, robust=robust, frames=fitted,
                 covariance_scale="known" if known else "a_posteriori", warn=False)
    model = _carry_frames(res.model, start, fitted)
    start_prov = start.metadata.provenance if start_method == "closed-form" else None
    prov = Provenance(
        method="refined-robust" if robust else "refined",
        measurements=ms.source,
        robot=ms.robot,
        details={
            **(start_prov.details if start_prov is not None else {}),
            "reference": "weighted least squares of every record (eq. (23) with the Fig. 10 noise "
            "weights), started from " + start_method,
            "start": start_method,
            "sigma_t_m": sigma_t,
            "sigma_r_rad": sigma_r,
            "sigma_source": "measurement file noise section" if known else "default (paper's 0.5 mm / 0.5 deg)",
            "identified_parameters": res.parametrization.counts(),
            "refinement_time_s": res.seconds,
            "outlier_records": res.outlier_records,
        },
    )
    notes += list(start.metadata.notes) if start_method == "closed-form" else []
    notes += [f"outlier: {o.describe()}" for o in res.outliers]
    notes += [f"identifiability: {w}" for w in res.identifiability.warnings]
    if res.covariance.variance_factor > 25.0:
        notes.append(
            f"fit residuals are {np.sqrt(res.covariance.variance_factor):.0f}x the stated noise: wrong "
            "sigmas, gross outliers (try --method refined-robust) or a start too far from the robot"
        )
    if not known:
        notes.append(
            f"noise sigmas not given: covariance scaled by the variance factor "
            f"{res.covariance.variance_factor:.3g}"
        )
    return model.with_params(metadata=model.metadata.replace(provenance=prov, notes=tuple(notes)))


def refined(ms: MeasurementSet, nominal: CPCModel | None) -> CPCModel:
    """Closed form, then weighted least squares of every record (:func:`identify_refined`)."""
    return identify_refined(ms, nominal)


def refined_robust(ms: MeasurementSet, nominal: CPCModel | None) -> CPCModel:
    """As ``refined``, rejecting gross outliers (named in the model's notes)."""
    return identify_refined(ms, nominal, robust=True)


METHODS: dict[str, Method] = {
    "closed-form": closed_form,
    "refined": refined,
    "refined-robust": refined_robust,
}


def residuals(model: CPCModel, ms: MeasurementSet) -> Residuals:
    """Fit residuals of ``model`` on ``ms``: per branch (measured frame) and per record.

    Translation = distance between the measured and predicted origins [m], rotation = angle
    between the measured and predicted orientations [rad].
    """
    frames = [f for f in ms.frames if f in model.structure.frame_names]
    T = model.fk(ms.q, frames) if frames else {}
    per_frame: dict[str, FrameResiduals] = {}
    per_record: list[dict[str, tuple[float, float]]] = [{} for _ in ms.labels]
    for f in frames:
        ok = ms.has_pose(f)
        dt = np.linalg.norm(T[f][ok, :3, 3] - ms.poses[f][ok, :3, 3], axis=1)
        dr = rotation_error(T[f][ok, :3, :3], ms.poses[f][ok, :3, :3])
        per_frame[f] = FrameResiduals(
            records=int(ok.sum()),
            rms_translation_m=float(np.sqrt(np.mean(dt**2))),
            max_translation_m=float(np.max(dt)),
            rms_rotation_rad=float(np.sqrt(np.mean(dr**2))),
            max_rotation_rad=float(np.max(dr)),
        )
        for i, a, b in zip(np.flatnonzero(ok), dt, dr, strict=True):
            per_record[int(i)][f] = (float(a), float(b))
    return Residuals(per_frame, tuple(RecordResiduals(lb, r) for lb, r in zip(ms.labels, per_record, strict=True)))


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
    meta = model.metadata
    if meta.provenance is None:
        meta = meta.replace(provenance=Provenance(method=method, measurements=ms.source, robot=ms.robot))
    return model.with_params(metadata=meta.replace(residuals=residuals(model, ms)))


__all__ = [
    "DEFAULT_METHOD",
    "METHODS",
    "Method",
    "align_base",
    "closed_form",
    "identify",
    "identify_refined",
    "noise_from_metadata",
    "residuals",
]
