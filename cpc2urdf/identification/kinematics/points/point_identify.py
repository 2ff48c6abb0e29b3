"""Identification from position-only data: what ``cpc2urdf identify`` runs on a file with markers.

Start (:func:`point_refine.point_start`: circle-point closed form on one-joint-at-a-time records,
else the nominal model placed in world), the gauge chosen closest to the nominal model
(:mod:`gauge`; unmeasured frames and frames whose markers are all unknown keep their nominal
placement on their links, the markers re-expressed in them), then the maximum-likelihood
refinement (:func:`point_refine.refine_points`) and the point consistency gate
(:mod:`point_consistency`). The model's provenance names the start (``details["start"]``), the
markers' identified positions with their standard deviations, and what point data cannot
determine; ``method="closed-form"`` stops after the start.
"""

from __future__ import annotations

import numpy as np

from cpc2urdf.errors import Cpc2UrdfError, DegenerateDataError
from cpc2urdf.files.measurements import MeasurementSet
from cpc2urdf.identification.kinematics.points.circle_point import marker_sigma
from cpc2urdf.identification.kinematics.points.point_consistency import (
    PointConsistency,
    check_point_consistency,
)
from cpc2urdf.identification.kinematics.points.point_refine import (
    PointRefinement,
    point_start,
    refine_points,
)
from cpc2urdf.identification.kinematics.start import on_the_parts
from cpc2urdf.model import CPCModel
from cpc2urdf.model_metadata import FrameResiduals, Provenance, RecordResiduals, Residuals
from cpc2urdf.transforms import Array

POINT_METHODS = ("closed-form", "refined", "refined-robust")
# Robust mode: a point less likely than this for a good measurement is dropped and the fit redone.
POINT_OUTLIER_ALPHA = 1e-4  # [-]


def _on_nominal_frames(
    model: CPCModel, nominal: CPCModel | None, ms: MeasurementSet, positions: dict[str, Array]
) -> tuple[CPCModel, dict[str, Array]]:
    """Gauge closest to ``nominal``; frames not fixed by known markers at their nominal placement."""
    if nominal is None or nominal.structure.joint_names != model.structure.joint_names:
        return model, positions
    aligned = on_the_parts(model, nominal)
    fixed_by_known = {ms.markers[m].frame for m in positions if ms.markers[m].known}
    frames = {
        f: nominal.frames[f]
        for f in model.structure.frame_names
        if f not in fixed_by_known and f in nominal.frames
    }
    out = aligned.with_params(frames=frames)
    pos = {}
    for m, p in positions.items():
        f = ms.markers[m].frame
        if f in frames:  # same link: T_world_F' = L E', so p' = E'^-1 E p
            E_old, E_new = aligned.frames[f].matrix(), frames[f].matrix()
            T = np.linalg.solve(E_new, E_old)
            pos[m] = T[:3, :3] @ p + T[:3, 3]
        else:
            pos[m] = p
    return out, pos


def _residuals_section(ms: MeasurementSet, res: dict[str, Array]) -> Residuals:
    per: dict[str, FrameResiduals] = {}
    per_record: list[dict[str, tuple[float, float]]] = [{} for _ in ms.labels]
    for m, v in res.items():
        ok = np.isfinite(v)
        if not ok.any():
            continue
        per[m] = FrameResiduals(
            records=int(ok.sum()),
            rms_translation_m=float(np.sqrt(np.mean(v[ok] ** 2))),
            max_translation_m=float(np.max(v[ok])),
            rms_rotation_rad=0.0,
            max_rotation_rad=0.0,
        )
        for i in np.flatnonzero(ok):
            per_record[int(i)][m] = (float(v[i]), 0.0)
    return Residuals(
        per, tuple(RecordResiduals(lb, r) for lb, r in zip(ms.labels, per_record, strict=True))
    )


def _refine(
    start: CPCModel,
    ms: MeasurementSet,
    pos: dict[str, Array],
    sigma_p: float,
    known: bool,
    robust: bool,
) -> tuple[PointRefinement, list[tuple[int, str]]]:
    scale = "known" if known else "a_posteriori"
    res = refine_points(start, ms, pos, sigma_p, covariance_scale=scale, warn=False)
    dropped: list[tuple[int, str]] = []  # (record, marker)
    if robust:
        from scipy.special import gammaincc

        use = None
        for _ in range(5):
            s0 = 1.0 if known else max(res.variance_factor, 1e-30)
            use = {
                m: ms.has_marker(m)
                & ~(
                    gammaincc(1.5, 0.5 * np.nan_to_num(v, nan=0.0) ** 2 / (sigma_p**2 * s0))
                    < POINT_OUTLIER_ALPHA
                )
                for m, v in res.residuals.items()
            }
            n_drop = sum(int((ms.has_marker(m) & ~u).sum()) for m, u in use.items())
            if n_drop == 0:
                break
            res = refine_points(
                start, ms, pos, sigma_p, covariance_scale=scale, use=use, warn=False
            )
        if use is not None:
            for m, u in use.items():
                dropped += [(int(i), m) for i in np.flatnonzero(ms.has_marker(m) & ~u)]
    return res, dropped


def _placed_residuals(model: CPCModel, ms: MeasurementSet, m: str) -> Array:
    """Residuals (N,) [m] of marker ``m`` on its declared frame of ``model`` (its position: given, or the
    mean of ``T_world_F(q)^-1 y``), NaN where unseen."""
    mk = ms.markers[m]
    ok = ms.has_marker(m)
    T = model.fk(ms.q, [mk.frame])[mk.frame]
    Y = ms.marker_points[m]
    if mk.position is not None:
        p = np.asarray(mk.position, dtype=float)
    else:
        p = np.einsum("nji,nj->ni", T[ok, :3, :3], Y[ok] - T[ok, :3, 3]).mean(0)
    d = np.linalg.norm(Y - (T[:, :3, :3] @ p + T[:, :3, 3]), axis=1)
    return np.where(ok, d, np.nan)


def identify_points(
    ms: MeasurementSet,
    method: str = "refined",
    nominal: CPCModel | None = None,
    *,
    accept_inconsistent: bool = False,
) -> CPCModel:
    """Identify the robot from marker points (module docstring).

    Raises:
        Cpc2UrdfError: Unknown method.
        DegenerateDataError: No start (not the protocol and no nominal model), too few
            markers for a joint, a marker on the wrong link (named).
        InconsistentDataError: The fit fails the point consistency gate (unless
            ``accept_inconsistent``): outliers, residuals beyond the stated noise, a unit mistake.
    """
    if method not in POINT_METHODS:
        raise Cpc2UrdfError(
            f"method {method!r} does not apply to position-only data; use one of {', '.join(POINT_METHODS)}"
        )
    if ms.frames:
        raise DegenerateDataError(
            f"{ms.source}: records with both frame poses and marker points are not supported; "
            "identify from one kind"
        )
    s = ms.structure
    moved = {f: set(s.path_to(f)) for f in ms.marker_frames}
    for j in s.joint_names:
        if not any(j in v for v in moved.values()):
            raise DegenerateDataError(
                f"{ms.source}: too few markers for joint {j!r}: no marker is on a link it moves "
                f"({', '.join(f.name for f in s.frames if j in s.path_to(f.name)) or 'none'}); its axis cannot be identified"
            )
    sigma_p, known = marker_sigma(ms.metadata)
    start, pos, kind, notes = point_start(ms, nominal, sigma_p)
    start, pos = _on_nominal_frames(start, nominal, ms, pos)
    details: dict[str, object] = {
        "start": kind,
        "sigma_p_m": sigma_p,
        "sigma_source": "measurement file noise section"
        if known
        else "default (0.5 mm per coordinate)",
        "data": "position-only (marker points)",
    }
    if method == "closed-form":
        model = start
        names = [m for m in ms.marker_points if ms.has_marker(m).any()]
        res_tab = {}
        T = model.fk(ms.q, list(dict.fromkeys(ms.markers[m].frame for m in names)))
        for m in names:
            Tf = T[ms.markers[m].frame]
            v = np.linalg.norm(
                ms.marker_points[m] - (Tf[:, :3, :3] @ pos[m] + Tf[:, :3, 3]), axis=1
            )
            res_tab[m] = np.where(ms.has_marker(m), v, np.nan)
        details["markers"] = {
            m: {"frame": ms.markers[m].frame, "position_m": [float(v) for v in pos[m]]}
            for m in names
        }
        report = PointConsistency(
            True, "", {"note": "closed form only: the gate tests the refined fit"}
        )
    else:
        res, dropped = _refine(start, ms, pos, sigma_p, known, robust=method == "refined-robust")
        model = res.model
        notes += [
            f"outlier: {ms.labels[i] if ms.labels[i] == f'record {i}' else f'{ms.labels[i]} (record {i})'} marker {m!r}: "
            f"{res.residuals[m][i] * 1e3:.3g} mm"
            for i, m in dropped
        ]
        notes += [f"not determined by point data: {u}" for u in res.undetermined]
        notes += [f"identifiability: {w}" for w in res.identifiability.warnings]
        res_tab = res.residuals
        cov = model.metadata.uncertainty
        details.update(
            {
                "identified_parameters": {
                    "total": res.chart.n_params,
                    "model": res.chart.n_model_params,
                    "markers": res.chart.n_params - res.chart.n_model_params,
                },
                "markers": dict(cov.details.get("markers", {})) if cov is not None else {},
                "not_determined_by_points": res.undetermined,
                "refinement_time_s": res.seconds,
            }
        )

        def refit(other: MeasurementSet) -> tuple[float, int]:
            s2, p2, _, _ = point_start(other, nominal, sigma_p)
            r2 = refine_points(s2, other, p2, sigma_p, warn=False)
            return 2.0 * r2.cost, r2.dof

        def refit_without(m: str) -> tuple[dict[str, Array], float, int]:
            other = ms.subset(np.arange(ms.n_records))
            other.marker_points = {k: v for k, v in ms.marker_points.items() if k != m}
            s2, p2, _, _ = point_start(other, nominal, sigma_p)
            r2 = refine_points(s2, other, p2, sigma_p, warn=False)
            return {**r2.residuals, m: _placed_residuals(r2.model, ms, m)}, 2.0 * r2.cost, r2.dof

        kept = {
            m: np.where(
                np.isin(np.arange(ms.n_records), [i for i, k in dropped if k == m]), np.nan, v
            )
            for m, v in res_tab.items()
        }
        report = check_point_consistency(
            ms, kept, sigma_p, known, 2.0 * res.cost, res.dof, nominal, refit, refit_without
        )
        if not report.consistent and not accept_inconsistent:
            raise report.error()
        if not report.consistent:
            notes.append(f"INCONSISTENT DATA, kept with --accept-inconsistent: {report.cause}")
    prov = Provenance(
        method=method,
        measurements=ms.source,
        robot=ms.robot,
        details={
            **details,
            "consistency": {
                **report.to_json(),
                **({} if report.consistent else {"accepted": True}),
            },
        },
    )
    meta = model.metadata.replace(
        provenance=prov, notes=tuple(notes), residuals=_residuals_section(ms, res_tab)
    )
    return model.with_params(metadata=meta)


def marker_positions(model: CPCModel) -> dict[str, tuple[str, Array]]:
    """Marker name -> (frame, identified position [m]) from a point-identified model's provenance."""
    prov = model.metadata.provenance
    found = prov.details.get("markers", {}) if prov is not None else {}
    return {
        m: (str(d["frame"]), np.asarray(d["position_m"], dtype=float)) for m, d in found.items()
    }


__all__ = ["POINT_METHODS", "POINT_OUTLIER_ALPHA", "identify_points", "marker_positions"]
