"""Diagnose inconsistent stage-1 data by refitting their likely mistakes.

When a fit fails the gate's tests (:mod:`verdict`), :func:`diagnose` undoes each likely mistake of
:mod:`alternatives` in turn, screens the fixed data with the closed form (milliseconds each; the
nominal model, else the fit of the data as read, starts a short refinement where the closed form
cannot), refines the :data:`~verdict.SCREENED` most promising and puts them through the same tests,
and looks for gross outliers with the robust refinement (:func:`refine.refine` ``robust=True`` at
the gate's per-pose level). The fix that makes the data consistent is the :class:`~verdict.
Diagnosis`; where several do (swapped plates fit exactly as well as both vergence readings swapped
on a mirror-symmetric head), the one whose data lie closest to the nominal model wins. Without a
noise statement a fix must fit :data:`~verdict.MIN_IMPROVEMENT` times better than the data as read
(and beyond the F-test); a rescaled robot fits exactly as well, so only its size tells.

:func:`unexplained` words the refusal when no fix helps; :func:`diagnose_unfittable` names the fix
when a method cannot fit the data as read at all.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import fdtri

from cpc2urdf.errors import Cpc2UrdfError, DegenerateDataError, InconsistentDataError
from cpc2urdf.files.measurements import MeasurementSet
from cpc2urdf.identification.kinematics.gate.alternatives import Alternative, alternatives
from cpc2urdf.identification.kinematics.gate.fit_statistics import FitStatistics, fit_statistics
from cpc2urdf.identification.kinematics.gate.plausibility import SizeCheck, size_check
from cpc2urdf.identification.kinematics.gate.verdict import (
    FALSE_ALARM,
    MAX_OUTLIER_FRACTION,
    MIN_IMPROVEMENT,
    PROMISING,
    SCREENED,
    STATS_NFEV,
    Diagnosis,
    Noise,
    evaluate,
    noise_problems,
    times,
)
from cpc2urdf.identification.kinematics.parametrization import Parametrization
from cpc2urdf.identification.kinematics.problem import IdentificationProblem
from cpc2urdf.identification.kinematics.start import align_base, measured_frames, refinement_start
from cpc2urdf.model import CPCModel
from cpc2urdf.tolerances import FK_AGREEMENT_TOL


@dataclass
class _Candidate:
    alt: Alternative
    data: MeasurementSet
    start: CPCModel
    score: float


def _screen(
    alt: Alternative,
    ms: MeasurementSet,
    nominal: CPCModel | None,
    noise: Noise,
    fallback: CPCModel | None = None,
) -> _Candidate | None:
    """Apply ``alt`` and fit it cheaply: the closed form, else a short refinement from the nominal
    model placed in world, else from ``fallback`` (the fit of the data as read)."""
    try:
        data = alt.apply(ms)
        try:
            start, kind, _ = refinement_start(data, nominal)
        except DegenerateDataError:
            if fallback is None:
                return None
            start, kind = fallback, "fallback"
        frames = measured_frames(start, data)
        if kind != "closed-form":
            s = fit_statistics(
                start, data, noise.sigma_t, noise.sigma_r, frames=frames, max_nfev=30
            )
            start, chi2_t, chi2_r, n = s.model, s.chi2_t, s.chi2_r, s.n_poses
        else:
            use = {f: data.has_pose(f) for f in frames}
            chart = Parametrization(start, frames)
            blocks = IdentificationProblem(
                chart, data.q, data.poses, use, noise.sigma_t, noise.sigma_r
            ).residual_blocks(np.zeros(chart.n_params))
            chi2_t = float(sum(np.sum(dp**2) for dp, _ in blocks.values())) / noise.sigma_t**2
            chi2_r = float(sum(np.sum(dr**2) for _, dr in blocks.values())) / noise.sigma_r**2
            n = sum(len(dp) for dp, _ in blocks.values())
    except (Cpc2UrdfError, ValueError, ArithmeticError, np.linalg.LinAlgError):
        return None
    if noise.known:  # distance from the stated noise, in either direction
        score = abs(math.log(max(chi2_t / (3 * n), 1e-300))) + abs(
            math.log(max(chi2_r / n, 1e-300))
        )
    else:  # cost per pose in the units of the data as read
        score = (chi2_t / alt.length_factor**2 + 3.0 * chi2_r) / (6 * n)
    return _Candidate(alt, data, start, score) if math.isfinite(score) else None


def _nominal_distance(ms: MeasurementSet, nominal: CPCModel) -> float:
    """RMS distance [m] between the measured frame origins and the nominal model's, placed in
    world by a rigid fit."""
    frames = measured_frames(nominal, ms)
    placed = align_base(nominal, ms, frames)
    T = placed.fk(ms.q, frames)
    d = np.concatenate(
        [
            np.linalg.norm(T[f][ms.has_pose(f), :3, 3] - ms.poses[f][ms.has_pose(f), :3, 3], axis=1)
            for f in frames
        ]
    )
    return float(np.sqrt(np.mean(d**2)))


def _significant(better: FitStatistics, worse: FitStatistics, length_factor: float) -> bool:
    """Without a noise statement: ``better`` fits beyond chance better than ``worse``."""
    d1 = worse.dof_t + worse.dof_r
    d2 = better.dof_t + better.dof_r
    threshold = max(MIN_IMPROVEMENT, float(fdtri(d1, d2, 1.0 - FALSE_ALARM)))
    return worse.variance_factor() > threshold * better.variance_factor(length_factor)


def _fix_evidence(
    alt: Alternative,
    asis: FitStatistics,
    fixed: FitStatistics,
    noise: Noise,
    size: SizeCheck | None,
    fixed_size: SizeCheck | None,
) -> str:
    if noise.known:
        worst = max(
            (asis.ratio_t, "translation"),
            (asis.ratio_r, "rotation"),
            key=lambda x: abs(math.log(x[0])),
        )
        below = " (far below it)" if worst[0] < 1 else ""
        return (
            f"fit {worst[1]} residuals {times(worst[0])} the stated {noise.describe()} noise{below}; "
            f"with {alt.key} the fit is consistent: translation {fixed.ratio_t:.2f}x, rotation "
            f"{fixed.ratio_r:.2f}x the noise"
        )
    if alt.kind == "lengths" and size is not None and fixed_size is not None:
        return f"{size.describe()}; with {alt.key}, {fixed_size.describe().replace('the measured robot is ', 'it is ')}"
    t0, r0 = asis.rms()
    t1, r1 = fixed.rms()
    return (
        f"fit residuals {t0 * 1e3:.3g} mm / {math.degrees(r0):.3g} deg RMS; with {alt.key} "
        f"{t1 * 1e3 / alt.length_factor:.3g} mm / {math.degrees(r1):.3g} deg"
    )


def _robust_outliers(
    stats: FitStatistics, ms: MeasurementSet, noise: Noise
) -> list[tuple[str, int]]:
    """Gross outliers found by the robust refinement from the fit as read."""
    from cpc2urdf.identification.kinematics.refine import refine

    st, sr = noise.sigma_t, noise.sigma_r
    if not noise.known:  # robust scale: medians of chi(3) and half-normal residuals
        t = np.concatenate(list(stats.translation.values()))
        r = np.concatenate(list(stats.rotation.values()))
        st = max(float(np.median(t)) / 1.538, FK_AGREEMENT_TOL)
        sr = max(float(np.median(r)) / 0.6745, FK_AGREEMENT_TOL)
    try:
        res = refine(
            stats.model,
            ms,
            st,
            sr,
            robust=True,
            frames=list(stats.frames),
            warn=False,
            outlier_alpha=FALSE_ALARM / (2 * stats.n_poses),
            max_nfev=STATS_NFEV,
        )
    except (
        Cpc2UrdfError,
        ValueError,
        ArithmeticError,
        np.linalg.LinAlgError,
    ):  # rejected nearly all
        return []
    return [(o.frame, o.record) for o in res.outliers]


def _describe_outliers(
    ms: MeasurementSet, stats: FitStatistics, poses: list[tuple[str, int]]
) -> str:
    records = sorted({k for _, k in poses})
    named = []
    for k in records:
        label = ms.labels[k]
        frames = [f for f, r in poses if r == k]
        named.append(
            f"{k}" + ("" if label == f"record {k}" else f" ({label})") + f" {'+'.join(frames)}"
        )
    return ", ".join(named)


def _outlier_diagnosis(
    ms: MeasurementSet,
    nominal: CPCModel | None,
    noise: Noise,
    stats: FitStatistics,
) -> tuple[Diagnosis, FitStatistics] | None:
    poses = _robust_outliers(stats, ms, noise)
    if not poses or len(poses) > MAX_OUTLIER_FRACTION * stats.n_poses:
        return None
    clean = fit_statistics(
        stats.model,
        ms,
        noise.sigma_t,
        noise.sigma_r,
        frames=stats.frames,
        drop=poses,
        max_nfev=STATS_NFEV,
    )
    problems, more, _ = evaluate(clean, noise, ms, nominal)
    if problems or more:
        return None
    off = []
    for f, k in poses[:3]:
        i = int(np.searchsorted(stats.records[f], k))
        off.append(
            f"{stats.translation[f][i] * 1e3:.3g} mm / {math.degrees(stats.rotation[f][i]):.3g} deg"
        )
    records = tuple(sorted({k for _, k in poses}))
    against = f"the stated {noise.describe()} noise" if noise.known else "the rest's own scatter"
    return Diagnosis(
        "outliers",
        f"{len(records)} record{'s' if len(records) > 1 else ''} look like gross outliers: records "
        f"{_describe_outliers(ms, stats, poses)}",
        f"{', '.join(off)}{' ...' if len(poses) > 3 else ''} off the fit; without them the fit is consistent with {against}",
        "re-measure or remove them (or use --method refined-robust, which drops them)",
        "outliers",
        records,
    ), clean


def diagnose(
    ms: MeasurementSet,
    nominal: CPCModel | None,
    noise: Noise,
    stats: FitStatistics,
    size: SizeCheck | None,
    outliers: bool,
) -> tuple[Diagnosis | None, list[str]]:
    """The fix that makes the data consistent, or None; and the keys of the fixes refitted."""
    screened = [
        c
        for c in (_screen(a, ms, nominal, noise, stats.model) for a in alternatives(ms))
        if c is not None
    ]
    if noise.known:  # the closed form of a consistent fix is within a few times the noise
        finalists = sorted((c for c in screened if c.score < PROMISING), key=lambda c: c.score)[
            :SCREENED
        ]
    else:  # the closed form of a fix that helps fits clearly better than the data as read
        others = [
            c
            for c in screened
            if c.alt.kind != "lengths" and c.score < 0.5 * stats.variance_factor()
        ]
        finalists = sorted(others, key=lambda c: c.score)[:SCREENED]
        # A rescaled robot fits exactly as well: only its size can tell.
        sized = [(c, size_check(c.data, nominal)) for c in screened if c.alt.kind == "lengths"]
        plausible = [(c, s.ratio) for c, s in sized if s is not None and s.plausible]
        if size is not None and not size.plausible and plausible:
            finalists.append(min(plausible, key=lambda cs: abs(math.log(cs[1])))[0])
    tested = []
    best: tuple[float, Diagnosis] | None = None
    for c in finalists:
        tested.append(c.alt.key)
        try:
            fixed = fit_statistics(
                c.start, c.data, noise.sigma_t, noise.sigma_r, max_nfev=STATS_NFEV
            )
        except (Cpc2UrdfError, ValueError, ArithmeticError, np.linalg.LinAlgError):
            continue
        if fixed.rank < fixed.n_params:
            continue
        problems, _, fixed_size = evaluate(fixed, noise, c.data, nominal)
        if problems:
            continue
        if (
            not noise.known
            and c.alt.kind != "lengths"
            and not _significant(fixed, stats, c.alt.length_factor)
        ):
            continue
        # Several fixes can be equally consistent (plates swapped = both vergence readings swapped,
        # for a mirror-symmetric head): the nominal model tells which robot the data are of.
        rank = (
            _nominal_distance(c.data, nominal)
            if nominal is not None
            else fixed.variance_factor(c.alt.length_factor)
        )
        d = Diagnosis(
            c.alt.kind,
            c.alt.cause,
            _fix_evidence(c.alt, stats, fixed, noise, size, fixed_size),
            c.alt.remedy,
            c.alt.key,
        )
        if best is None or rank < best[0]:
            best = (rank, d)
    if best is not None:
        return best[1], tested
    if outliers:
        tested.append("outliers")
        found = _outlier_diagnosis(ms, nominal, noise, stats)
        if found is not None:
            return found[0], tested
    return None, tested


def unexplained(
    problems: list[str],
    stats: FitStatistics,
    noise: Noise,
    size: SizeCheck | None,
    n_tested: int,
    outliers: list[tuple[str, int]],
    ms: MeasurementSet,
) -> Diagnosis:
    """What to say when no tested fix explains the failed tests."""
    what = (
        f"none of the {n_tested} likely mistakes tested (units, swapped frames or joints, inverted or "
        "transposed poses, quaternion order, pairing, outliers) explains it"
    )
    if noise.known and (stats.ratio_t > 1 or stats.ratio_r > 1) and noise_problems(stats, noise):
        worst = max(stats.ratio_t, stats.ratio_r)
        return Diagnosis(
            "noise",
            f"fit residuals are {times(worst)} the stated {noise.describe()} noise",
            f"translation {stats.ratio_t:.3g}x, rotation {stats.ratio_r:.3g}x; {what}",
            "state the measuring noise in the file's 'noise' section, or check that the data are of "
            "this robot",
        )
    if noise.known and noise_problems(stats, noise):
        return Diagnosis(
            "noise",
            f"fit residuals are far below the stated {noise.describe()} noise",
            f"translation {times(stats.ratio_t)}, rotation {times(stats.ratio_r)} of it; {what}",
            "check the file's 'units' and 'noise' sections",
        )
    if size is not None and not size.plausible:
        return Diagnosis(
            "size", f"{size.describe()}", what, "check the file's 'units' and the robot"
        )
    if outliers:
        return Diagnosis(
            "outliers",
            f"{len({k for _, k in outliers})} records are far off the fit: records "
            f"{_describe_outliers(ms, stats, outliers)}",
            what,
            "re-measure or remove them",
            records=tuple(sorted({k for _, k in outliers})),
        )
    return Diagnosis("noise", "; ".join(problems), what, "check the data")


def diagnose_unfittable(
    ms: MeasurementSet, nominal: CPCModel | None, noise: Noise, error: DegenerateDataError
) -> InconsistentDataError | None:
    """When a method cannot fit the data as read at all (the closed form finds no axis where a
    joint turned, say), a likely mistake may be why: refit each fix and return the refusal that
    names the one whose data fit and pass the gate's tests, or None.

    Args:
        ms: The measurements as read.
        nominal: The robot's nominal model, or None.
        noise: The stated noise, or the weights assumed without a statement.
        error: Why the method failed on the data as read.
    """
    screened = [
        c for c in (_screen(a, ms, nominal, noise) for a in alternatives(ms)) if c is not None
    ]
    best: tuple[float, Diagnosis] | None = None
    for c in sorted(screened, key=lambda c: c.score)[:SCREENED]:
        try:
            fixed = fit_statistics(
                c.start, c.data, noise.sigma_t, noise.sigma_r, max_nfev=STATS_NFEV
            )
        except (Cpc2UrdfError, ValueError, ArithmeticError, np.linalg.LinAlgError):
            continue
        problems, _, _ = evaluate(fixed, noise, c.data, nominal)
        if fixed.rank < fixed.n_params or problems:
            continue
        t, r = fixed.rms()
        fit = (
            f"translation {fixed.ratio_t:.2f}x, rotation {fixed.ratio_r:.2f}x the stated noise"
            if noise.known
            else f"residuals {t * 1e3 / c.alt.length_factor:.3g} mm / {math.degrees(r):.3g} deg RMS"
        )
        d = Diagnosis(
            c.alt.kind,
            c.alt.cause,
            f"the data as read cannot be fitted: {error}; with {c.alt.key} they fit, {fit}",
            c.alt.remedy,
            c.alt.key,
        )
        rank = (
            _nominal_distance(c.data, nominal)
            if nominal is not None
            else fixed.variance_factor(c.alt.length_factor)
        )
        if best is None or rank < best[0]:
            best = (rank, d)
    if best is None:
        return None
    return InconsistentDataError(f"{ms.source}: {best[1].line()}")


__all__ = ["diagnose", "diagnose_unfittable", "unexplained"]
