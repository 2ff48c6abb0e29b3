"""The consistency gate of hand-eye / robot-world calibration: do the poses agree with ``A X = Z B``?

A solver always returns *some* X and Z. :func:`check_consistency` asks whether the poses agree
with the equation and with their noise, and if not, which input mistake explains them. It judges
the data with its own fits (:mod:`~cpc2urdf.identification.handeye.gate.reference_fit`), so the verdict
does not depend on the solver the user chose (``cpc2urdf handeye --method all`` gets one verdict).

The noise is the one the pose file states (:class:`~cpc2urdf.identification.handeye.pose_noise.PoseNoise`),
or, without a statement, estimated from the residuals of a robust (Cauchy-loss) fit
(:func:`~cpc2urdf.identification.handeye.pose_noise.estimate_noise`). The tests, in this order, at a
total false-alarm probability :data:`FALSE_ALARM` (a third each to 1, 3 and 4; Bonferroni within):

1. **Tested mistakes** (:data:`~cpc2urdf.identification.handeye.gate.mistakes.MISTAKES`): each is
   undone and the data solved again (:func:`~cpc2urdf.identification.handeye.gate.reference_fit.quick_fit`).
   A mistake explains the data when undoing it shrinks the residual variance beyond chance (F
   quantile) and at least :data:`EXPLAIN_FACTOR` times. Variance: with stated noise ``chi2 / dof``
   of the whitened residuals; without, the geometric mean of the position (relative to the
   camera-target distance, so that a length unit cancels) and rotation residual variances. Fixes
   that fit as well as the best (undoing one list's inversion vs the other's, one list's length
   unit vs the other's) are told apart by plausibility: the camera within
   :data:`MAX_CAMERA_OFFSET` of the hand, the camera-target distance within :data:`WORKING_DISTANCE`.
2. **Physical plausibility** of the data as given: a camera-target distance outside
   :data:`WORKING_DISTANCE` (both lists in a wrong length unit), or the camera farther than
   :data:`MAX_CAMERA_OFFSET` from the hand while reading both lists inverted puts it near (both
   lists inverted is an exact symmetry of ``A X = Z B`` that swaps X and Z: only plausibility can
   see it).
3. **Gross outliers**: the leverage-corrected residual of every pose in the weighted fit, screened
   against the noise and confirmed by refitting without the candidates (mean-shift outlier test:
   chi-square with stated noise, F without, at ``alpha / N`` per pose); without a noise statement
   an outlier must also be :data:`GROSS_FACTOR` times the other poses' RMS residual. With stated
   noise, outliers explain the data only if the other poses then agree with the statement.
4. **The residual level** against the stated noise: ``chi2`` of the weighted fit against the
   chi-square distribution with ``6 N - 12`` degrees of freedom, both tails (far above: inconsistent;
   far below: the statement or the length unit is wrong). Without a statement, residuals above
   :data:`IMPLAUSIBLE_RESIDUAL` of the camera-target distance or :data:`IMPLAUSIBLE_ANGLE` are
   refused: no working setup gives them.

The degenerate-data refusals (fewer than 3 poses, tiny rotations, parallel axes:
:func:`~cpc2urdf.identification.handeye.axxb.check_degenerate`) come first; the gate needs data
that determine X and Z. Measured false alarms on clean simulated data: ``tests/handeye_gate_trials.py``
and ``docs/handeye.md``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray
from scipy.stats import chi2, f

from cpc2urdf.identification.handeye.axxb import MIN_POSES
from cpc2urdf.identification.handeye.gate.gate_report import ESTIMATED, STATED, ConsistencyReport
from cpc2urdf.identification.handeye.gate.mistakes import MISTAKES, Mistake
from cpc2urdf.identification.handeye.gate.reference_fit import (
    NUMERIC_ANGLE,
    NUMERIC_POSITION,
    WeightedFit,
    leverage_blocks,
    quick_fit,
    residual_vectors,
    weighted_fit,
    whitened,
)
from cpc2urdf.identification.handeye.pose_noise import PoseNoise, residual_covariance
from cpc2urdf.transforms import Array

#: Probability that the gate refuses consistent data: one third each to the tested mistakes, the
#: outlier test and the residual level against a stated noise.
FALSE_ALARM = 1e-4
#: A fix must shrink the residual variance at least this many times to explain the data.
EXPLAIN_FACTOR = 10.0
#: Fits within this factor of each other fit "as well" (then plausibility decides).
TIE_FACTOR = 2.0
MAX_CAMERA_OFFSET = 0.5  # [m]: |t_X|, camera origin from the hand frame's origin
WORKING_DISTANCE = (0.02, 20.0)  # [m]: median camera-target distance |t_C| of a usable setup
IMPLAUSIBLE_RESIDUAL = (
    0.2  # RMS position residual / median camera-target distance (no noise statement)
)
IMPLAUSIBLE_ANGLE = math.radians(20.0)  # [rad] RMS rotation residual (no noise statement)
LARGE_RESIDUAL = 0.01  # a warning above this fraction of the camera-target distance ...
LARGE_ANGLE = math.radians(1.0)  # ... or this RMS angle [rad]
MIN_POSES_FOR_OUTLIERS = 5
#: Without a noise statement, a gross outlier's position or rotation residual is also this many
#: times the other poses' RMS: the estimated noise model (isotropic, growing with the distance)
#: does not capture every pose's solvePnP precision (a far, nearly face-on view is worse), and in
#: 1200 clean stage-2 simulations one pose reached 9.7 times (docs/handeye.md).
GROSS_FACTOR = 15.0
_CHI2_6_MEDIAN = float(chi2.median(6))


@dataclass(frozen=True)
class _Candidate:
    """The data as given (``mistake=None``) or with one mistake undone, solved by the quick fit."""

    mistake: Mistake | None
    kept: NDArray[np.intp]
    X: Array
    Z: Array
    level: float  # residual variance (see the module docstring)
    dof: int
    rms_t: float  # [m]
    rms_r: float  # [rad]
    distance: float  # median camera-target distance [m]

    @property
    def problems(self) -> list[str]:
        """What is physically implausible about this reading of the data."""
        out = []
        lo, hi = WORKING_DISTANCE
        if not lo <= self.distance <= hi:
            out.append(
                f"the camera {_length(self.distance)} from the target (expected {lo:g} to {hi:g} m)"
            )
        offset = float(np.linalg.norm(self.X[:3, 3]))
        if offset > MAX_CAMERA_OFFSET:
            out.append(
                f"the camera {_length(offset)} from the hand (at most {MAX_CAMERA_OFFSET:g} m expected)"
            )
        return out

    def residuals(self) -> str:
        return f"{_length(self.rms_t)} / {math.degrees(self.rms_r):.3g} deg RMS"


def _length(x: float) -> str:
    return f"{x:.3g} m" if abs(x) >= 1.0 else f"{x * 1e3:.3g} mm"


def _evaluate(
    H: Array, C: Array, noise: PoseNoise | None, mistake: Mistake | None
) -> _Candidate | None:
    """Undo ``mistake`` and solve with the quick fit; None if too few poses remain."""
    Hm, Cm, kept = (
        mistake.undo(H, C) if mistake is not None else (H, C, np.arange(len(H), dtype=np.intp))
    )
    n = len(kept)
    if n < MIN_POSES:
        return None
    X, Z = quick_fit(Hm, Cm)
    e_t, e_r = residual_vectors(Hm, Cm, X, Z)
    distance = max(float(np.median(np.linalg.norm(Cm[:, :3, 3], axis=-1))), NUMERIC_POSITION)
    if noise is not None:
        L = np.linalg.cholesky(residual_covariance(noise, Hm, Cm, X, Z))
        w = np.linalg.solve(L, np.concatenate([e_t, e_r], axis=-1)[..., None])
        dof = 6 * n - 12
        level = float(np.sum(w**2)) / dof
    else:
        dof = 3 * n - 6
        ms_t = max(float(np.sum(e_t**2)) / distance**2 / dof, (NUMERIC_POSITION / distance) ** 2)
        ms_r = max(float(np.sum(e_r**2)) / dof, NUMERIC_ANGLE**2)
        level = math.sqrt(ms_t * ms_r)
    rms_t = float(np.sqrt(np.mean(np.sum(e_t**2, axis=-1))))
    rms_r = float(np.sqrt(np.mean(np.sum(e_r**2, axis=-1))))
    return _Candidate(mistake, kept, X, Z, level, dof, rms_t, rms_r, distance)


def _explaining(given: _Candidate, alts: list[_Candidate], alpha: float) -> list[_Candidate]:
    """Alternatives whose fit beats the data as given beyond chance, best (plausible, smallest) first."""
    out = []
    for a in alts:
        assert a.mistake is not None
        if a.mistake.symmetric:
            continue
        threshold = max(float(f.isf(alpha / len(alts), given.dof, a.dof)), EXPLAIN_FACTOR)
        if given.level / a.level >= threshold:
            out.append(a)
    return sorted(out, key=lambda a: (len(a.problems), a.level))


def _ties(best: _Candidate, alts: list[_Candidate]) -> str:
    """Evidence about the alternatives that fit as well as ``best``: why they are less likely."""
    notes = []
    for a in alts:
        if a is best or a.mistake is None or a.level > TIE_FACTOR * best.level:
            continue
        why = "; ".join(a.problems)
        code = a.mistake.code
        notes.append(
            f"undoing {code} instead fits as well but puts {why}" if why else f"{code} fits as well"
        )
    return "; " + "; ".join(notes) if notes else ""


def _outliers(
    H: Array, C: Array, noise: PoseNoise | None, fit: WeightedFit, alpha: float
) -> tuple[list[int], WeightedFit | None]:
    """Gross outlier poses (indices) and the fit without them.

    Screen: leverage-corrected residuals ``d_k = w_k^T (I - P_kk)^-1 w_k`` against a robust
    (median) noise level (or the stated one). Confirm: refit without the candidates and test each
    candidate's prediction error ``w_o^T (I + J_o G J_o^T)^-1 w_o`` (chi-square with 6 degrees of
    freedom under a stated noise, F(6, dof) with the inliers' estimated one), at ``alpha / N`` each.
    """
    n = len(H)
    if n < MIN_POSES_FOR_OUTLIERS:
        return [], None
    P = leverage_blocks(fit.jac)
    d = np.einsum("ni,nij,nj->n", fit.w, np.linalg.pinv(np.eye(6) - P), fit.w)
    # The estimated noise is fitted to these residuals (s2 ~ 1) unless it sits at its floor
    # (noise-free data): then the floor is the noise, s2 = 1.
    s2 = 1.0 if noise is not None else max(float(np.median(d)) / _CHI2_6_MEDIAN, 1.0)
    q = float(chi2.isf(alpha / n, 6))
    room = n - max(MIN_POSES + 1, math.ceil(n / 2))
    cand = [int(k) for k in np.argsort(-d) if d[k] / s2 > q][: max(room, 0)]
    if not cand:
        return [], None
    inl = np.array([k for k in range(n) if k not in cand])
    fit_in = weighted_fit(H[inl], C[inl], noise, start=(fit.X, fit.Z))
    G = np.linalg.pinv(fit_in.jac.T @ fit_in.jac)
    dof = 6 * len(inl) - 12
    s2_in = max(fit_in.chi2 / dof, 1.0)
    w_o, J_o = whitened(H[cand], C[cand], fit_in.X, fit_in.Z, fit_in.noise)
    J_o = J_o.reshape(len(cand), 6, 12)
    e_t, e_r = residual_vectors(H[cand], C[cand], fit_in.X, fit_in.Z)
    big_t = np.linalg.norm(e_t, axis=-1) > max(GROSS_FACTOR * _rms(fit_in.e_t), NUMERIC_POSITION)
    big_r = np.linalg.norm(e_r, axis=-1) > max(GROSS_FACTOR * _rms(fit_in.e_r), NUMERIC_ANGLE)
    confirmed = []
    for i, k in enumerate(cand):
        V = np.eye(6) + J_o[i] @ G @ J_o[i].T
        dk = float(w_o[i] @ np.linalg.solve(V, w_o[i]))
        p = float(chi2.sf(dk, 6)) if noise is not None else float(f.sf(dk / (6.0 * s2_in), 6, dof))
        if p < alpha / n and (noise is not None or big_t[i] or big_r[i]):
            confirmed.append(k)
    if not confirmed:
        return [], None
    if len(confirmed) < len(cand):
        inl = np.array([k for k in range(n) if k not in confirmed])
        fit_in = weighted_fit(H[inl], C[inl], noise, start=(fit_in.X, fit_in.Z))
    return sorted(confirmed), fit_in


def _rms(e: Array) -> float:
    return float(np.sqrt(np.mean(np.sum(e**2, axis=-1))))


def _refuse(
    verdict: ConsistencyReport,
    code: str,
    cause: str,
    evidence: str,
    fix: str,
    outliers: tuple[str, ...] = (),
) -> ConsistencyReport:
    """The verdict turned into a refusal with the cause named."""
    return replace(
        verdict,
        consistent=False,
        code=code,
        cause=cause,
        evidence=evidence,
        fix=fix,
        outliers=outliers,
    )


def _mistake_refusal(
    verdict: ConsistencyReport,
    given: _Candidate,
    explaining: list[_Candidate],
    alts: list[_Candidate],
) -> ConsistencyReport | None:
    """Test 1: the refusal naming the tested mistake that best explains the data, if any."""
    if not explaining:
        return None
    best = explaining[0]
    assert best.mistake is not None
    ties = _ties(best, alts)
    evidence = f"residuals {given.residuals()} as given, {best.residuals()} with it undone{ties}"
    return _refuse(verdict, best.mistake.code, best.mistake.cause, evidence, best.mistake.fix)


def _plausibility_refusal(
    verdict: ConsistencyReport, given: _Candidate, alts: list[_Candidate]
) -> ConsistencyReport | None:
    """Test 2: refuse data physically implausible as given (a plausible reading named if any)."""
    if not given.problems:
        return None
    readings = [
        a
        for a in alts
        if a.mistake is not None
        and not a.problems
        and (a.mistake.symmetric or a.level <= TIE_FACTOR * given.level)
    ]
    if readings:
        best = min(readings, key=lambda a: a.level)
        assert best.mistake is not None
        return _refuse(
            verdict,
            best.mistake.code,
            best.mistake.cause,
            f"as given the solution puts {'; '.join(given.problems)}",
            best.mistake.fix,
        )
    if not WORKING_DISTANCE[0] <= given.distance <= WORKING_DISTANCE[1]:
        return _refuse(
            verdict,
            "implausible",
            "implausible lengths",
            f"the solution puts {'; '.join(given.problems)}",
            "check the length unit of the poses",
        )
    return None


def _outlier_refusal(
    verdict: ConsistencyReport,
    H: Array,
    C: Array,
    noise: PoseNoise | None,
    fit: WeightedFit,
    alpha: float,
    names: list[str],
) -> ConsistencyReport | None:
    """Test 3: refuse gross outliers (with stated noise, only if the rest then agrees with it)."""
    n = len(H)
    out, fit_in = _outliers(H, C, noise, fit, alpha)
    if (
        out and noise is not None
    ):  # outliers explain the data only if the rest agrees with the statement
        assert fit_in is not None
        dof_in = 6 * (n - len(out)) - 12
        if not alpha / 2 <= float(chi2.sf(fit_in.chi2, dof_in)) <= 1.0 - alpha / 2:
            out = []
    if not out:
        return None
    assert fit_in is not None
    o = np.array(out)
    e_t, e_r = residual_vectors(H[o], C[o], fit_in.X, fit_in.Z)
    worst = ", ".join(
        f"{names[k]} {_length(float(np.linalg.norm(e_t[i])))} / "
        f"{math.degrees(float(np.linalg.norm(e_r[i]))):.3g} deg"
        for i, k in enumerate(out)
    )
    evidence = (
        f"residuals {worst}; the other {n - len(out)} poses "
        f"{_length(_rms(fit_in.e_t))} / {math.degrees(_rms(fit_in.e_r)):.3g} deg RMS"
    )
    return _refuse(
        verdict,
        "outliers",
        f"gross outliers: {', '.join(names[k] for k in out)}",
        evidence,
        "remove or re-measure these poses",
        tuple(names[k] for k in out),
    )


def check_consistency(
    T_base_hand: Array,
    T_camera_target: Array,
    *,
    noise: PoseNoise | None = None,
    labels: Sequence[str] | None = None,
    false_alarm: float = FALSE_ALARM,
) -> ConsistencyReport:
    """Test hand-eye poses against ``A X = Z B`` and their noise; name the most likely mistake.

    Args:
        T_base_hand: Hand poses in the robot base frame, shape (N, 4, 4) [m] (validated, N >= 3,
            not degenerate).
        T_camera_target: Target poses in the camera frame, shape (N, 4, 4) [m].
        noise: The noise the pose file states, or None (estimated from the data).
        labels: One name per pose (outliers are named by them); default ``pose k``.
        false_alarm: Probability of refusing consistent data.

    Returns:
        The verdict; ``report.consistent`` is False with the cause named when the data are
        inconsistent beyond chance.
    """
    H, C = np.asarray(T_base_hand, dtype=float), np.asarray(T_camera_target, dtype=float)
    n = len(H)
    names = list(labels) if labels is not None else [f"pose {k}" for k in range(n)]
    alpha = false_alarm / 3.0
    kind = STATED if noise is not None else ESTIMATED
    given = _evaluate(H, C, noise, None)
    assert given is not None
    alts = [a for m in MISTAKES if (a := _evaluate(H, C, noise, m)) is not None]
    improvements = tuple(
        (a.mistake.code, given.level / a.level) for a in alts if a.mistake is not None
    )
    dof = 6 * n - 12
    fits: list[WeightedFit] = []

    def reference() -> WeightedFit:  # the weighted fit, computed once and only when needed
        if not fits:
            fits.append(weighted_fit(H, C, noise, robust=True))
        return fits[0]

    p_high = float(chi2.sf(reference().chi2, dof)) if noise is not None else 1.0
    p_low = float(chi2.cdf(reference().chi2, dof)) if noise is not None else 1.0
    ratio = math.sqrt(reference().chi2 / dof) if noise is not None else math.nan
    verdict = ConsistencyReport(
        True,
        noise=kind,
        rms_translation=given.rms_t,
        rms_rotation=given.rms_r,
        noise_ratio=ratio,
        alternatives=improvements,
        false_alarm=false_alarm,
    )

    # 1. a tested mistake explains the data (unless the data already agree with a stated noise)
    level_ok = noise is None or (p_high >= alpha / 2 and p_low >= alpha / 2)
    explaining = [] if noise is not None and level_ok else _explaining(given, alts, alpha)
    refusal = _mistake_refusal(verdict, given, explaining, alts)
    if refusal is not None:
        return refusal

    # 2. physically implausible as given, while an equally good reading is plausible
    refusal = _plausibility_refusal(verdict, given, alts)
    if refusal is not None:
        return refusal

    # 3. gross outliers
    fit = reference()
    verdict = replace(verdict, rms_translation=_rms(fit.e_t), rms_rotation=_rms(fit.e_r))
    refusal = _outlier_refusal(verdict, H, C, noise, fit, alpha, names)
    if refusal is not None:
        return refusal

    # 4. the residual level
    if noise is not None and p_high < alpha / 2:
        tried = max(improvements, key=lambda c: c[1])
        return _refuse(
            verdict,
            "noise_exceeded",
            f"residuals {ratio:.3g}x the stated noise",
            f"chi2 = {fit.chi2:.4g} for {dof} degrees of freedom, p = {p_high:.2g}; no tested "
            f"mistake explains it (best: {tried[0]}, variance x{1 / tried[1]:.3g})",
            "check the pairing of the poses and the kinematic model, or state the noise",
        )
    if noise is not None and p_low < alpha / 2:
        return _refuse(
            verdict,
            "below_noise",
            f"residuals {ratio:.3g}x the stated noise, far below it",
            f"chi2 = {fit.chi2:.4g} for {dof} degrees of freedom, p = {p_low:.2g}",
            "check the noise statement and the length unit",
        )
    if noise is None and (
        given.rms_t > IMPLAUSIBLE_RESIDUAL * given.distance or given.rms_r > IMPLAUSIBLE_ANGLE
    ):
        return _refuse(
            verdict,
            "implausible",
            "residuals too large for any working setup",
            f"{given.residuals()} at a camera-target distance of {_length(given.distance)}; "
            "no tested mistake explains them",
            "check the pairing of the poses, the kinematic model and the camera calibration",
        )
    return _accept(verdict, given, fit, noise, ratio)


def _accept(
    verdict: ConsistencyReport,
    given: _Candidate,
    fit: WeightedFit,
    noise: PoseNoise | None,
    ratio: float,
) -> ConsistencyReport:
    """The consistent verdict: the residual evidence and the warnings about the solution."""
    evidence = f"residuals {_length(_rms(fit.e_t))} / {math.degrees(_rms(fit.e_r)):.3g} deg RMS"
    if noise is not None:
        evidence += f", {ratio:.3g}x the stated noise"
    warnings = [f"implausible solution: it puts {p}" for p in given.problems]
    if noise is None and (
        given.rms_t > LARGE_RESIDUAL * given.distance or given.rms_r > LARGE_ANGLE
    ):
        warnings.append(
            f"large residuals ({given.residuals()} at a camera-target distance of "
            f"{_length(given.distance)}): poses out of sync, outliers or a wrong kinematic model?"
        )
    return replace(verdict, evidence=evidence, warnings=tuple(warnings))


__all__ = [
    "EXPLAIN_FACTOR",
    "GROSS_FACTOR",
    "FALSE_ALARM",
    "IMPLAUSIBLE_ANGLE",
    "IMPLAUSIBLE_RESIDUAL",
    "LARGE_ANGLE",
    "LARGE_RESIDUAL",
    "MAX_CAMERA_OFFSET",
    "MIN_POSES_FOR_OUTLIERS",
    "TIE_FACTOR",
    "WORKING_DISTANCE",
    "check_consistency",
]
