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

Position-only data (marker points, ``cpc2urdf/measurements@2``) take the same names through
:func:`identify`, which hands them to :func:`point_identify.identify_points` (circle-point start,
point refinement, point consistency gate).

The closed form and the refinement are imported inside the methods that run them: the CLI builds
its parser from :data:`METHODS`, and scipy's optimiser should not slow down every command.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from cpc2urdf.errors import Cpc2UrdfError, DegenerateDataError
from cpc2urdf.files.measurements import MeasurementSet
from cpc2urdf.identification.kinematics.problem import DEFAULT_SIGMA_R, DEFAULT_SIGMA_T
from cpc2urdf.identification.kinematics.start import (
    align_base,
    closed_form_model,
    on_the_parts,
    refinement_start,
)
from cpc2urdf.model import CPCModel, CPCParams
from cpc2urdf.model_metadata import FrameResiduals, Provenance, RecordResiduals, Residuals
from cpc2urdf.transforms import rotation_error

Method = Callable[[MeasurementSet, "CPCModel | None"], CPCModel]


def closed_form(ms: MeasurementSet, nominal: CPCModel | None) -> CPCModel:
    """Shih et al. sec. 4.2, generalised to trees (:mod:`cpc2urdf.identification.kinematics.closed_form`)."""
    return on_the_parts(closed_form_model(ms, nominal), nominal)


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


def identify_refined(
    ms: MeasurementSet, nominal: CPCModel | None = None, *, robust: bool = False
) -> CPCModel:
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

    start, start_method, note = refinement_start(ms, nominal)
    if start_method == "closed-form":
        start = on_the_parts(start, nominal)
    notes: list[str] = [note] if note else []
    sigma_t, sigma_r, known = noise_from_metadata(ms.metadata)
    fitted = [f for f in start.structure.frame_names if f in ms.poses and ms.has_pose(f).any()]
    res = refine(
        start,
        ms,
        sigma_t,
        sigma_r,
        robust=robust,
        frames=fitted,
        covariance_scale="known" if known else "a_posteriori",
        warn=False,
    )
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
            "sigma_source": "measurement file noise section"
            if known
            else "default (paper's 0.5 mm / 0.5 deg)",
            "identified_parameters": res.parametrization.counts(),
            "refinement_time_s": res.seconds,
            "outlier_records": res.outlier_records,
        },
    )
    notes += list(start.metadata.notes) if start_method == "closed-form" else []
    notes += [f"outlier: {o.describe()}" for o in res.outliers]
    notes += [f"identifiability: {w}" for w in res.identifiability.warnings]
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


def map_about_nominal(ms: MeasurementSet, nominal: CPCModel | None) -> CPCModel:
    """Maximum a posteriori about the nominal model, level chosen by cross-validation
    (:func:`map_identify.identify_map`; joint compliance needs the loads :func:`identify` passes)."""
    from cpc2urdf.identification.kinematics.map_identify import identify_map

    return identify_map(ms, nominal)


METHODS: dict[str, Method] = {
    "closed-form": closed_form,
    "map": map_about_nominal,
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
    return Residuals(
        per_frame,
        tuple(RecordResiduals(lb, r) for lb, r in zip(ms.labels, per_record, strict=True)),
    )


DEFAULT_METHOD = "refined"


def _method_outliers(model: CPCModel) -> list[tuple[str, int]]:
    """``(frame, record)`` poses a robust method rejected (from its uncertainty section)."""
    cov = model.metadata.uncertainty
    found = cov.details.get("outliers", []) if cov is not None else []
    return [(str(o["frame"]), int(o["record"])) for o in found]


def identify(
    ms: MeasurementSet,
    method: str = DEFAULT_METHOD,
    nominal: CPCModel | None = None,
    *,
    accept_inconsistent: bool = False,
    loads: np.ndarray | None = None,
    level: str | None = None,
    joints: list[str] | None = None,
) -> CPCModel:
    """Check the data suffice, run ``METHODS[method]``, test the fit against the data's noise
    (:mod:`consistency`) and attach the ``residuals`` section.

    Args:
        ms: The measurements.
        method: A name in :data:`METHODS`; the default is the CLI's (closed form, then
            maximum-likelihood refinement).
        nominal: The nominal model (keeps unmeasured frames such as cameras, fixes what the data
            leave open, and is the size yardstick of the consistency gate); default: the nominal
            model of the robot ``ms`` was read with.
        accept_inconsistent: Keep the model of inconsistent data, with the gate's diagnosis in
            its ``notes`` and its provenance (``details["consistency"]``), instead of refusing.
        loads: For ``map``: each joint's gravity load at each record, shape (N, n) [N m] / [N]
            (adds the joint-compliance level).
        level: For ``map``: fit this level alone (default: chosen by cross-validation).
        joints: For ``map``: the joints to calibrate (default: those the data move).

    Raises:
        Cpc2UrdfError: Unknown method name.
        DegenerateDataError: The data cannot determine the robot (a joint never moved, too few
            distinct configurations, copied records, free parameters), named before any solver
            runs where the records show it.
        InconsistentDataError: The fit disagrees with the data's noise beyond chance (unless
            ``accept_inconsistent``), or the method cannot fit the data as read and a likely
            mistake's fix makes them fit (always); one line naming the most likely cause.
    """
    from cpc2urdf.identification.kinematics.gate.pose_gate import (
        Noise,
        check_consistency,
        diagnose_unfittable,
    )
    from cpc2urdf.identification.kinematics.sufficiency import check_data_suffice

    if method not in METHODS:
        raise Cpc2UrdfError(
            f"unknown identification method {method!r}; known: {', '.join(METHODS)}"
        )
    if nominal is None and ms.spec is not None and ms.spec.nominal is not None:
        nominal = ms.spec.nominal_model()
    if method == "map":
        from cpc2urdf.identification.kinematics.map_identify import identify_map
        from cpc2urdf.identification.kinematics.prior_fit import Noise as StatedNoise

        st, sr, known = noise_from_metadata(ms.metadata)  # sr: the rotation error's angle (Fig. 10)
        model = identify_map(
            ms,
            nominal,
            loads=loads,
            noise=StatedNoise(st, sr / np.sqrt(3.0)) if known else None,
            accept_inconsistent=accept_inconsistent,
            level=level,
            joints=joints,
        )
        return (
            model
            if ms.has_points
            else model.with_params(metadata=model.metadata.replace(residuals=residuals(model, ms)))
        )
    if ms.has_points:  # position-only data (cpc2urdf/measurements@2 markers)
        from cpc2urdf.identification.kinematics.points.point_identify import identify_points

        return identify_points(ms, method, nominal, accept_inconsistent=accept_inconsistent)
    check_data_suffice(ms)
    noise = Noise(*noise_from_metadata(ms.metadata))
    try:
        model = METHODS[method](ms, nominal)
    except DegenerateDataError as e:  # a likely mistake may be why the data cannot be fitted
        found = diagnose_unfittable(ms, nominal, noise, e)
        if found is not None:
            raise found from e
        raise
    report = check_consistency(ms, model, nominal, noise, drop=_method_outliers(model))
    if not report.consistent and not accept_inconsistent:
        raise report.error()
    meta = model.metadata
    prov = meta.provenance or Provenance(method=method, measurements=ms.source, robot=ms.robot)
    consistency = {**report.to_json(), **({} if report.consistent else {"accepted": True})}
    meta = meta.replace(provenance=prov.with_details(consistency=consistency))
    if not report.consistent:
        meta = meta.replace(
            notes=(
                *meta.notes,
                f"INCONSISTENT DATA, kept with --accept-inconsistent: {report.line()}",
            )
        )
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
