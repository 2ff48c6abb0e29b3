"""``cpc2urdf identify --method map``: calibrate a URDF robot about its own URDF, the model chosen by
cross-validation (:mod:`prior_fit`).

The levels (the URDF as it is, joint offsets, offsets and geometry, and joint compliance when the
joints' gravity loads are given) are each fitted by maximum a posteriori about the URDF; the
simplest level whose leave-one-record-out error is best is kept (:func:`prior_fit.select_model`).
The model's provenance holds the cross-validation table, the estimated noise, each marker's
position, each joint's share of data versus prior, and whether the calibration beats the URDF;
when it does not, the model is the URDF's own geometry with only the measuring frame fitted, and
its notes say so.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from cpc2urdf.errors import DegenerateDataError, InconsistentDataError
from cpc2urdf.identification.kinematics.map_gate import GateReport, RecordErrors, check
from cpc2urdf.identification.kinematics.prior_fit import (
    LEVELS,
    MapFit,
    Noise,
    Selection,
    Tolerances,
    fit_map,
    record_errors,
    select_model,
)
from cpc2urdf.measurements import MeasurementSet
from cpc2urdf.model import CPCModel
from cpc2urdf.model_metadata import Provenance
from cpc2urdf.transforms import Array

NOT_BETTER = ("no calibration predicts left-out records better than the URDF as it is: its joints are kept, "
              "only the measuring frame{what} fitted")


def _details(sel: Selection) -> dict[str, object]:
    fit = sel.fit
    return {
        "reference": "maximum a posteriori about the URDF (prior: manufacturing tolerances), level chosen by "
                     "leave-one-record-out cross-validation",
        "chosen_level": fit.level,
        "beats_urdf": sel.beats_urdf,
        "cross_validation_rms_m": {lv: sel.fits[lv].loo_rms_m for lv in LEVELS if lv in sel.fits},
        "fit_rms_m": fit.rms_m,
        "noise_residuals": {"position_m": fit.residual_noise.position_m, "rotation_rad": fit.residual_noise.rotation_rad},
        "effective_parameters": fit.dof,
        "calibrated_joints": list(fit.joints),
        "data_share": fit.data_share,
        "offsets_rad_or_m": {j: float(xi[5] if fit.model.structure.joint(j).type == "revolute" else xi[2])
                             for j, xi in fit.perturbations.items()},
        "compliance": fit.compliance,
        "markers": {m: {"position_m": [float(v) for v in p]} for m, p in fit.markers.items()},
    }


def _gate(sel: Selection, nominal: CPCModel, ms: MeasurementSet, loads: Array | None, tolerances: Tolerances | None,
          noise: Noise | None) -> GateReport:
    """:func:`map_gate.check` on the chosen fit (noise estimated), refitting its level without the
    records dropped; ``noise`` is the stated noise it is checked against."""

    def refit(drop: np.ndarray) -> tuple[MapFit, RecordErrors]:
        keep = np.setdiff1d(np.arange(ms.n_records), drop)
        f = fit_map(nominal, ms.subset(keep), sel.chosen, sel.fit.joints, tolerances,
                    loads=None if loads is None else loads[keep])
        sq, count = np.zeros(ms.n_records), np.zeros(ms.n_records)
        sq[keep], count[keep] = f.loo_sq_m2, f.loo_points
        sq[drop], count[drop] = record_errors(f, ms.subset(drop), None if loads is None else loads[drop])
        return f, (sq, count)

    return check(sel.fit, refit, noise, ms.labels)


def identify_map(ms: MeasurementSet, nominal: CPCModel | None, *, loads: Array | None = None,
                 joints: Sequence[str] | None = None, tolerances: Tolerances | None = None,
                 noise: Noise | None = None, accept_inconsistent: bool = False, level: str | None = None) -> CPCModel:
    """The calibrated model (module docstring), through the gate (:mod:`map_gate`).

    Args:
        noise: The measurement noise if the user states it (else estimated from the data).
        accept_inconsistent: Keep the model of data the gate refuses (fitted without the outliers
            it named), with the cause in its notes.
        level: Fit this level of :data:`LEVELS` alone instead of choosing one (no cross-validation).

    Raises:
        DegenerateDataError: No nominal model (a URDF or a spec with geometry) to calibrate about.
        InconsistentDataError: Isolated outliers (named), or residuals beyond chance for the stated
            noise (unmodelled error, named with its size).
    """
    if nominal is None:
        raise DegenerateDataError(f"{ms.source}: --method map calibrates about a nominal model; the robot "
                                  "has no geometry (give its URDF)")
    def choose(m: MeasurementSet, L: Array | None, noise: Noise | None = None) -> Selection:
        if level is None:
            return select_model(nominal, m, joints, tolerances, L, noise=noise)
        fit = fit_map(nominal, m, level, joints, tolerances, noise, estimate_noise=noise is None, loads=L)
        return Selection(fit, {level: fit})

    sel = choose(ms, loads)  # the gate judges with the noise the data show
    gate = _gate(sel, nominal, ms, loads, tolerances, noise)
    if not gate.consistent and not accept_inconsistent:
        raise InconsistentDataError(f"{ms.source}: {gate.cause}", gate)
    if gate.outliers or noise is not None:
        keep = np.setdiff1d(np.arange(ms.n_records), gate.outliers)
        sel = choose(ms.subset(keep), None if loads is None else loads[keep], noise)
    notes = list(ms.metadata.get("notes", [])) if isinstance(ms.metadata.get("notes"), list) else []
    if not gate.consistent:
        notes.append(f"INCONSISTENT DATA, kept with --accept-inconsistent: {gate.cause}")
    if not sel.beats_urdf:
        what = " and the markers were" if ms.marker_points else " and the measured frame were"
        notes.append(NOT_BETTER.format(what=what))
    weak = [j for j, s in sel.fit.data_share.items() if s < 0.5]
    if weak and sel.beats_urdf:
        notes.append(f"the data barely determine {', '.join(weak)}: kept near the URDF by the prior "
                     f"(data share {', '.join(f'{sel.fit.data_share[j]:.2f}' for j in weak)})")
    n = sel.fit.residual_noise
    notes.append(f"noise {'the residuals show' if noise else 'estimated from the data'}: {n.position_m * 1e3:.3f} mm"
                 + (f", {math.degrees(n.rotation_rad):.3f} deg" if ms.frames else ""))
    details = {**_details(sel), "consistency": {"consistent": gate.consistent, "cause": gate.cause,
                                                "outlier_records": [ms.labels[i] for i in gate.outliers]}}
    prov = Provenance(method="map", measurements=ms.source, robot=ms.robot, details=details)
    model = sel.fit.model
    return model.with_params(metadata=model.metadata.replace(provenance=prov, notes=tuple(notes)))


__all__ = ["NOT_BETTER", "identify_map"]
