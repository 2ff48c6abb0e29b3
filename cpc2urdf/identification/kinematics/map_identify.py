"""``cpc2urdf identify --method map``: calibrate a URDF robot about its own URDF (:func:`calibrate`).

1. The levels (the URDF as it is, joint offsets, offsets and geometry, and joint compliance when
   the joints' gravity loads are given) are fitted by maximum a posteriori about the URDF and one
   is chosen by leave-one-record-out cross-validation (:func:`prior_fit.select_model`).
2. The gate (:mod:`map_gate`) names isolated outliers or, against a stated noise, unmodelled
   error. When the fit fails (beyond a stated noise, or residuals over :data:`FAILED_FIT_M`), a
   joint read from the horizontal (a parallel pair's child reported as the sum of the two) is
   tested, and named when undoing it explains the data.
3. Over the whole joint range, a joint the data cannot vouch for keeps the URDF's values.

The model's provenance holds the levels' left-out errors, the noise the residuals show, each
marker's position, each joint's data share, the gate's verdict, the whole-range comparison and
whether the calibration beats the URDF; when it does not, the model is the URDF's own geometry
with only the measuring frame fitted, and its notes say so.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from cpc2urdf.errors import DegenerateDataError, InconsistentDataError
from cpc2urdf.files.measurements import MeasurementSet
from cpc2urdf.identification.kinematics.gate.map_gate import GateReport, check
from cpc2urdf.identification.kinematics.prior_fit import (
    LEVELS,
    MapFit,
    Noise,
    Selection,
    Tolerances,
    first_point,
    fit_map,
    readings_within_limits,
    select_model,
)
from cpc2urdf.model import CPCModel
from cpc2urdf.model_metadata import Provenance
from cpc2urdf.transforms import Array
from cpc2urdf.urdf.robot import UrdfRobot

RANGE_SAMPLES = 500  # [-]: seeded readings within the limits for the whole-range comparison
SWEEP_SAMPLES = 101  # [-]: readings of one joint's sweep over its limits
# A joint whose sweep over its whole range moves the calibrated prediction away from the URDF's,
# beyond what it does over the data's span, by more than this x the left-out RMS (and at least
# WILD_DIVERGENCE_M) is kept at the URDF: the data cannot vouch for it there.
DIVERGENCE_FACTOR = 5.0  # [-]
WILD_DIVERGENCE_M = 0.02  # [m]

# A joint whose data share (1 - posterior / prior variance) is below this is named as barely
# determined by the data: the prior, that is the URDF, holds it.
BARELY = 0.25  # [-]

# A fit whose residuals scatter by more than this [m] is no working setup's: its likely mistakes are
# tested (as they are when a stated noise is exceeded).
FAILED_FIT_M = 0.01
# Axes this parallel (|cos|) make a pair whose child a controller may report from the horizontal.
PARALLEL_COS = 0.999
# Undoing a likely mistake must lower the residual noise this many fold to name it.
COUPLED_GAIN = 3.0

NOT_BETTER = (
    "no calibration predicts left-out records better than the URDF as it is: its joints are kept, "
    "only the measuring frame{what} fitted"
)


def _details(sel: Selection, ms: MeasurementSet) -> dict[str, object]:
    fit = sel.fit
    markers = {m: (ms.markers[m].frame, p) for m, p in fit.markers.items()}
    return {
        "reference": "maximum a posteriori about the URDF (prior: manufacturing tolerances), level chosen by "
        "leave-one-record-out cross-validation",
        "chosen_level": fit.level,
        "cross_validation_rms_m": {lv: sel.fits[lv].loo_rms_m for lv in LEVELS if lv in sel.fits},
        "fit_rms_m": fit.rms_m,
        "noise_residuals": {
            "position_m": fit.residual_noise.position_m,
            "rotation_rad": fit.residual_noise.rotation_rad,
        },
        "effective_parameters": fit.dof,
        "calibrated_joints": list(fit.joints),
        "data_share": fit.data_share,
        "offsets_rad_or_m": {
            j: float(xi[5] if fit.model.structure.joint(j).type == "revolute" else xi[2])
            for j, xi in fit.perturbations.items()
        },
        "compliance": fit.compliance,
        "markers": {
            m: {"frame": frame, "position_m": [float(v) for v in p]}
            for m, (frame, p) in markers.items()
        },
    }


def _gate(
    sel: Selection,
    nominal: CPCModel,
    ms: MeasurementSet,
    loads: Array | None,
    tolerances: Tolerances | None,
    noise: Noise | None,
) -> GateReport:
    """:func:`map_gate.check` on the chosen fit (noise estimated), refitting its level on the
    records kept; ``noise`` is the stated noise it is checked against."""

    def refit(kept: np.ndarray) -> MapFit:
        return fit_map(
            nominal,
            ms.subset(kept),
            sel.chosen,
            sel.fit.joints,
            tolerances,
            loads=None if loads is None else loads[kept],
        )

    return check(sel.fit, refit, noise, ms.labels)


def _shown(ms: MeasurementSet, joint: str) -> str:
    """How the user names ``joint``: its URDF name for a URDF robot."""
    robot = ms.spec
    if isinstance(robot, UrdfRobot) and robot.names is not None:
        return robot.names.urdf_joint(joint)
    return joint


def _parallel_pairs(nominal: CPCModel, joints: Sequence[str]) -> list[tuple[str, str]]:
    """Calibrated revolute joints whose parent is a calibrated revolute joint with a parallel axis
    (a parallelogram's or a planar arm's: a controller may report the child's angle from the
    horizontal, the sum of the two)."""
    s = nominal.structure
    axis, _ = nominal.link_poses(np.zeros(s.n_joints))
    out = []
    for j in joints:
        parent = s.joint(j).parent
        if parent in joints and s.joint(j).type == s.joint(parent).type == "revolute":
            a, b = axis[0, s.joint_index(j), :3, 2], axis[0, s.joint_index(parent), :3, 2]
            if abs(float(a @ b)) > PARALLEL_COS:
                out.append((parent, j))
    return out


def _coupled_reading(
    sel: Selection, nominal: CPCModel, ms: MeasurementSet, tolerances: Tolerances | None
) -> str | None:
    """The failed fit explained by a joint read relative to its parallel parent (``q_j + q_p`` or
    ``q_j - q_p``), or None: the chosen level refitted with each reading undone must lower the
    residual noise :data:`COUPLED_GAIN` fold."""
    s = ms.structure
    before = sel.fit.residual_noise.position_m
    for parent, j in _parallel_pairs(nominal, sel.fit.joints):
        for sign, how in ((1.0, "+"), (-1.0, "-")):
            q = ms.q.copy()
            q[:, s.joint_index(j)] -= sign * ms.q[:, s.joint_index(parent)]
            after = fit_map(
                nominal, replace(ms, q=q), sel.chosen, sel.fit.joints, tolerances
            ).residual_noise.position_m
            if after * COUPLED_GAIN < before:
                a, b = _shown(ms, j), _shown(ms, parent)
                return (
                    f"joint {a!r} seems read relative to joint {b!r} (the reading is {a} {how} {b}, as a "
                    f"controller reporting the angle from the horizontal gives): with {a} "
                    f"{'-' if sign > 0 else '+'} {b} the fit's residuals fall from {before * 1e3:.3g} mm to "
                    f"{after * 1e3:.3g} mm"
                )
    return None


def range_report(fit: MapFit, urdf: MapFit, ms: MeasurementSet, seed: int = 0) -> dict[str, object]:
    """How far the calibrated geometry's prediction of the first measured point moves from the
    URDF's (``urdf``: the URDF as it is, placed by the same data) over the whole joint range:
    ``"whole_range_m"`` (median, p95, max over :data:`RANGE_SAMPLES` seeded readings within the
    limits), and per calibrated joint, swept over its limits with the others at the data's median,
    the largest divergence within the data's span and over the whole range (``"joints"``)."""
    s = ms.structure
    lo = np.array([j.lower for j in s.joints])
    hi = np.array([j.upper for j in s.joints])
    Q = readings_within_limits(s, RANGE_SAMPLES, seed)
    d = np.linalg.norm(first_point(fit, ms, Q) - first_point(urdf, ms, Q), axis=1)
    joints: dict[str, dict[str, float]] = {}
    mid = np.median(ms.q, axis=0)
    for j in fit.joints:
        k = s.joint_index(j)
        sweep = np.tile(mid, (SWEEP_SAMPLES, 1))
        sweep[:, k] = np.linspace(lo[k], hi[k], SWEEP_SAMPLES)
        dj = np.linalg.norm(first_point(fit, ms, sweep) - first_point(urdf, ms, sweep), axis=1)
        inside = (sweep[:, k] >= ms.q[:, k].min()) & (sweep[:, k] <= ms.q[:, k].max())
        joints[j] = {
            "data_span": float(np.ptp(ms.q[:, k])),
            "range": float(hi[k] - lo[k]),
            "within_data_m": float(dj[inside].max()) if inside.any() else 0.0,
            "whole_range_m": float(dj.max()),
        }
    return {
        "whole_range_m": {
            "median": float(np.median(d)),
            "p95": float(np.percentile(d, 95)),
            "max": float(d.max()),
        },
        "joints": joints,
    }


def _wild(report: dict[str, object], fit: MapFit) -> list[str]:
    """Joints whose whole range takes the prediction far from the URDF's beyond the data's span."""
    joints = report["joints"]
    assert isinstance(joints, dict)
    limit = max(DIVERGENCE_FACTOR * fit.loo_rms_m, WILD_DIVERGENCE_M)
    return [j for j, r in joints.items() if r["whole_range_m"] - r["within_data_m"] > limit]


@dataclass(frozen=True, eq=False)
class Calibration:
    """A calibration about the URDF, through the gate and the whole-range check.

    Attributes:
        selection: The chosen fit and the levels' fits.
        gate: What the gate found.
        whole_range: :func:`range_report` of the chosen fit.
        notes: What the user should read.
        chosen_by_cv: False when the level was given (no cross-validation chose it).
    """

    selection: Selection
    gate: GateReport
    whole_range: dict[str, object]
    notes: tuple[str, ...]
    chosen_by_cv: bool = True

    @property
    def fit(self) -> MapFit:
        return self.selection.fit


def calibrate(
    ms: MeasurementSet,
    nominal: CPCModel,
    *,
    loads: Array | None = None,
    joints: Sequence[str] | None = None,
    tolerances: Tolerances | None = None,
    noise: Noise | None = None,
    accept_inconsistent: bool = False,
    level: str | None = None,
) -> Calibration:
    """Choose and fit the level (module docstring), through the gate (:mod:`map_gate`); joints
    the data cannot vouch for over their whole range keep the URDF's values.

    Args:
        noise: The measurement noise if the user states it (else estimated from the data).
        accept_inconsistent: Keep the fit of data the gate refuses (without the outliers it
            named), with the cause in the notes.
        level: Fit this level of :data:`LEVELS` alone instead of choosing one (no cross-validation).

    Raises:
        InconsistentDataError: Isolated outliers (named), or residuals beyond chance for the stated
            noise (unmodelled error, named with its size).
    """

    def choose(m: MeasurementSet, L: Array | None, noise: Noise | None = None) -> Selection:
        if level is None:
            return select_model(nominal, m, joints, tolerances, L, noise=noise)
        fits = {
            lv: fit_map(
                nominal, m, lv, joints, tolerances, noise, estimate_noise=noise is None, loads=L
            )
            for lv in dict.fromkeys(("frames", level))
        }  # the URDF as it is: the whole-range yardstick
        return Selection(fits[level], fits)

    sel = choose(ms, loads)  # the gate judges with the noise the data show
    gate = _gate(sel, nominal, ms, loads, tolerances, noise)
    failed = (
        not gate.consistent and not gate.outliers
    ) or sel.fit.residual_noise.position_m > FAILED_FIT_M
    coupled = _coupled_reading(sel, nominal, ms, tolerances) if failed else None
    if (
        coupled is not None
    ):  # a likely mistake explains the data: name it, whatever accept_inconsistent says
        raise InconsistentDataError(f"{ms.source}: {coupled}", gate)
    if not gate.consistent and not accept_inconsistent:
        raise InconsistentDataError(f"{ms.source}: {gate.cause}", gate)
    kept = np.setdiff1d(np.arange(ms.n_records), gate.outliers)
    used, used_loads = ms.subset(kept), None if loads is None else loads[kept]
    if gate.outliers or noise is not None:
        sel = choose(used, used_loads, noise)
    notes = list(ms.metadata.get("notes", [])) if isinstance(ms.metadata.get("notes"), list) else []
    if not gate.consistent:
        notes.append(f"INCONSISTENT DATA, kept with --accept-inconsistent: {gate.cause}")
    report = range_report(sel.fit, sel.fits["frames"], used)
    wild = _wild(report, sel.fit) if sel.beats_urdf else []
    if wild:  # the data cannot vouch for these joints over their range: keep them at the URDF
        vouched = [j for j in sel.fit.joints if j not in wild]
        fit = (
            sel.fits["frames"]
            if not vouched
            else fit_map(
                nominal,
                used,
                sel.chosen,
                vouched,
                tolerances,
                noise,
                estimate_noise=noise is None,
                loads=used_loads,
            )
        )
        sel = Selection(fit, {**sel.fits, sel.chosen: fit})
        notes.append(
            f"kept at the URDF's values: {', '.join(_shown(ms, j) for j in wild)} (over their whole range the calibrated "
            "prediction would leave the URDF's far beyond what the data cover)"
        )
        report = range_report(sel.fit, sel.fits["frames"], used)
    if level is None and not sel.beats_urdf:
        what = " and the markers were" if ms.marker_points else " and the measured frame were"
        notes.append(NOT_BETTER.format(what=what))
    weak = [j for j, s in sel.fit.data_share.items() if s < BARELY]
    if weak and sel.beats_urdf:
        notes.append(
            f"the data barely determine {', '.join(_shown(ms, j) for j in weak)}: kept near the URDF by the prior "
            f"(data share {', '.join(f'{sel.fit.data_share[j]:.2f}' for j in weak)})"
        )
    n = sel.fit.residual_noise
    notes.append(
        f"noise {'the residuals show' if noise else 'estimated from the data'}: {n.position_m * 1e3:.3f} mm"
        + (f", {math.degrees(n.rotation_rad):.3f} deg" if ms.frames else "")
    )
    return Calibration(sel, gate, report, tuple(notes), level is None)


def identify_map(ms: MeasurementSet, nominal: CPCModel | None, **options: Any) -> CPCModel:
    """The calibrated model of :func:`calibrate` (same options), with its provenance: the levels'
    left-out errors, the estimated noise, markers, data shares, the gate and the whole range.

    Raises:
        DegenerateDataError: No nominal model (a URDF or a spec with geometry) to calibrate about.
        InconsistentDataError: As :func:`calibrate`.
    """
    if nominal is None:
        raise DegenerateDataError(
            f"{ms.source}: --method map calibrates about a nominal model; the robot "
            "has no geometry (give its URDF)"
        )
    cal = calibrate(ms, nominal, **options)
    gate = cal.gate
    details = {
        **_details(cal.selection, ms),
        "whole_range": cal.whole_range,
        "beats_urdf": cal.selection.beats_urdf if cal.chosen_by_cv else None,
        "consistency": {
            "consistent": gate.consistent,
            "cause": gate.cause,
            "outlier_records": [ms.labels[i] for i in gate.outliers],
        },
    }
    prov = Provenance(method="map", measurements=ms.source, robot=ms.robot, details=details)
    model = cal.fit.model
    return model.with_params(metadata=model.metadata.replace(provenance=prov, notes=cal.notes))


__all__ = [
    "DIVERGENCE_FACTOR",
    "NOT_BETTER",
    "Calibration",
    "calibrate",
    "identify_map",
    "range_report",
]
