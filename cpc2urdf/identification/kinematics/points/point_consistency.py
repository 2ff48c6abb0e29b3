"""The consistency gate for position-only data: the point fit against the data's own noise.

The idea of :mod:`consistency` applied to marker points (docs/identification.md, "Consistency
gate"): a fit whose residuals disagree with the stated noise is not a result.

- **gross outliers**: each point's ``|y - y_pred|^2 / sigma_p^2`` is chi-square with 3 dof for a
  good point; points beyond the Bonferroni level :data:`~verdict.FALSE_ALARM` / (2 n) are named
  (record label, marker, distance). Without a noise statement, a point more than
  :data:`~verdict.OUTLIER_RATIO` times the median point residual (and more than 1 mm) is one;
- **the whole fit** (with a noise statement, ``noise.sigma_p_m``): the weighted sum of squares
  against chi-square with the fit's degrees of freedom, both tails at ``FALSE_ALARM / 2``;
- **a marker on the wrong link**: when a test fails (without a noise statement: when some point is
  more than :data:`MIN_OUTLIER_M` off, and the others must then fit
  :data:`~verdict.MIN_IMPROVEMENT` times better), the fit is redone without each of the
  :data:`WRONG_LINK_CANDIDATES` worst markers in turn; if the others then pass and most of that
  marker's points (at least :data:`WRONG_LINK_MIN_POINTS`), placed on its declared link by that
  fit, fail the point test, the marker is named: it does not move with the link it is declared on;
- **units**: the measured points' extent against the nominal model's (its marker frames' origins
  at the same configurations), and, when a test fails, the points rescaled by each plausible unit
  mistake and refitted: a scale that makes the fit consistent is named (``mm read as m``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.special import gammainc, gammaincc

from cpc2urdf.errors import DegenerateDataError, InconsistentDataError
from cpc2urdf.files.measurements import MeasurementSet
from cpc2urdf.identification.kinematics.gate.verdict import (
    FALSE_ALARM,
    MIN_IMPROVEMENT,
    OUTLIER_RATIO,
)
from cpc2urdf.model import CPCModel

# Point residual below which no outlier is declared without a noise statement [m].
MIN_OUTLIER_M = 1e-3
# Plausible unit mistakes: factor the points must be multiplied by to be right, and the name.
UNIT_MISTAKES: tuple[tuple[float, str], ...] = (
    (1e-3, "the points are in mm but read as m"),
    (1e-2, "the points are in cm but read as m"),
    (2.54e-2, "the points are in inches but read as m"),
    (1e3, "the points are in m but read as mm"),
)
# The measured extent may differ from the nominal one by markers placed around the frames.
EXTENT_RATIO = 5.0  # [-]
EXTENT_SLACK = 0.5  # [m]
# A marker is named as on the wrong link when at least this many of its points, and most of them, are off.
WRONG_LINK_MIN_POINTS = 3
# Markers (worst first) refitted without, to find one on the wrong link.
WRONG_LINK_CANDIDATES = 3


@dataclass
class PointConsistency:
    """The gate's verdict on a point fit.

    Attributes:
        consistent: No test failed.
        cause: One line naming the failed test and its most likely cause ("" when consistent).
        tests: Test name -> JSON-ready evidence.
        outliers: ``(record, label, marker, distance [m])`` of the points rejected.
    """

    consistent: bool
    cause: str = ""
    tests: dict[str, Any] = field(default_factory=dict)
    outliers: list[tuple[int, str, str, float]] = field(default_factory=list)

    def to_json(self) -> dict[str, Any]:
        return {
            "consistent": self.consistent,
            "tests": self.tests,
            **({"diagnosis": {"cause": self.cause}} if not self.consistent else {}),
            "outliers": [
                {"record": r, "label": lb, "marker": m, "distance_m": d}
                for r, lb, m, d in self.outliers
            ],
        }

    def error(self) -> InconsistentDataError:
        return InconsistentDataError(
            f"the marker points are inconsistent with the fitted model: {self.cause}", self
        )


def _extent(points: list[np.ndarray]) -> float:
    P = np.concatenate(points)
    return float(np.linalg.norm(P.max(0) - P.min(0))) if len(P) else 0.0


def extent_check(ms: MeasurementSet, nominal: CPCModel | None) -> str | None:
    """A unit mistake read off the points' size against the nominal robot's, or None."""
    if nominal is None or nominal.structure.joint_names != ms.structure.joint_names:
        return None
    names = [m for m in ms.marker_points if ms.has_marker(m).any()]
    frames = list(dict.fromkeys(ms.markers[m].frame for m in names))
    T = nominal.fk(ms.q, frames)
    nom = _extent([T[ms.markers[m].frame][ms.has_marker(m), :3, 3] for m in names])
    meas = _extent([ms.marker_points[m][ms.has_marker(m)] for m in names])
    if nom < 0.05:
        return None
    if meas <= EXTENT_RATIO * (nom + EXTENT_SLACK) and meas >= nom / EXTENT_RATIO - EXTENT_SLACK:
        return None
    for k, why in UNIT_MISTAKES:
        if nom / 2 - EXTENT_SLACK <= k * meas <= 2 * nom + EXTENT_SLACK:
            return (
                f"{why}: the points span {meas:.4g} m where the nominal robot's marked links span "
                f"{nom:.3g} m at the same configurations (state units.length in the file)"
            )
    return (
        f"the points span {meas:.4g} m where the nominal robot's marked links span {nom:.3g} m at the same "
        "configurations: wrong units or wrong robot?"
    )


def _point_outliers(
    ms: MeasurementSet,
    residuals: dict[str, np.ndarray],
    sigma_p: float,
    known: bool,
    scale_from: dict[str, np.ndarray] | None = None,
) -> list[tuple[int, str, str, float]]:
    """Points failing the per-point test; without a noise statement the median is taken over ``scale_from``."""
    d = np.concatenate([v[np.isfinite(v)] for v in residuals.values()])
    ref = np.concatenate([v[np.isfinite(v)] for v in (scale_from or residuals).values()])
    n = len(d)
    limit = max(OUTLIER_RATIO * float(np.median(ref)), MIN_OUTLIER_M) if len(ref) else MIN_OUTLIER_M
    out: list[tuple[int, str, str, float]] = []
    for m, v in residuals.items():
        for i in np.flatnonzero(np.isfinite(v)):
            z = float(v[i])
            if known:
                bad = float(gammaincc(1.5, 0.5 * z * z / sigma_p**2)) < FALSE_ALARM / (
                    2 * max(n, 1)
                )
            else:
                bad = z > limit
            if bad:
                out.append((int(i), ms.labels[int(i)], m, z))
    return out


def _chi2_passed(sum_squares: float, dof: int) -> bool:
    return (
        min(float(gammaincc(dof / 2, sum_squares / 2)), float(gammainc(dof / 2, sum_squares / 2)))
        >= FALSE_ALARM / 2
    )


def check_point_consistency(
    ms: MeasurementSet,
    residuals: dict[str, np.ndarray],
    sigma_p: float,
    known: bool,
    sum_squares: float,
    dof: int,
    nominal: CPCModel | None,
    refit: Callable[[MeasurementSet], tuple[float, int]] | None = None,
    refit_without: Callable[[str], tuple[dict[str, np.ndarray], float, int]] | None = None,
) -> PointConsistency:
    """Test a point fit against the data's noise.

    Args:
        ms: The measurements.
        residuals: Marker -> per record 3-D residual [m], shape (N,), NaN where unseen.
        sigma_p: Noise per coordinate [m] behind the weights.
        known: The file states ``sigma_p`` (else only the outlier and size tests run).
        sum_squares: Weighted sum of squared residuals of the fit.
        dof: Its degrees of freedom.
        nominal: The nominal model (size yardstick), or None.
        refit: Fit of rescaled data -> (sum of squares, dof), to diagnose a unit mistake.
        refit_without: Fit without one marker -> (residuals of every marker, the left-out one
            placed on its declared frame by that fit; sum of squares; dof), to diagnose a marker
            on the wrong link.
    """
    tests: dict[str, Any] = {}
    unit = extent_check(ms, nominal)
    tests["size"] = {"passed": unit is None, **({"finding": unit} if unit else {})}
    if unit:
        return PointConsistency(False, unit, tests)
    d = np.concatenate([v[np.isfinite(v)] for v in residuals.values()])
    outliers = _point_outliers(ms, residuals, sigma_p, known)
    tests["outliers"] = {"count": len(outliers), "passed": not outliers}
    if known:
        p_hi = float(gammaincc(dof / 2, sum_squares / 2))
        p_lo = float(gammainc(dof / 2, sum_squares / 2))
        tests["chi_square"] = {
            "sum_squares": sum_squares,
            "dof": dof,
            "p_upper": p_hi,
            "p_lower": p_lo,
            "passed": min(p_hi, p_lo) >= FALSE_ALARM / 2,
        }
    failed = bool(outliers) or (known and not tests["chi_square"]["passed"])
    # Without a noise statement, a fit off by more than MIN_OUTLIER_M anywhere is checked too.
    suspect = failed or (not known and len(d) > 0 and float(d.max()) > MIN_OUTLIER_M)
    if suspect and refit_without is not None and len(residuals) > 1:
        # A marker on another link: without it the rest fit, and most of its points do not.
        order = sorted(residuals, key=lambda k: -float(np.nanmean(residuals[k] ** 2)))
        for m in order[:WRONG_LINK_CANDIDATES]:
            n_m = int(np.isfinite(residuals[m]).sum())
            if n_m < WRONG_LINK_MIN_POINTS:
                continue
            try:
                res2, ss2, dof2 = refit_without(m)
            except DegenerateDataError:
                continue
            others = {k: v for k, v in res2.items() if k != m}
            if _point_outliers(ms, others, sigma_p, known) or (
                known and not _chi2_passed(ss2, dof2)
            ):
                continue
            if not known:  # the others must fit MIN_IMPROVEMENT times better without it
                before = np.concatenate([v[np.isfinite(v)] for k, v in residuals.items() if k != m])
                after = np.concatenate([v[np.isfinite(v)] for v in others.values()])
                if MIN_IMPROVEMENT * float(np.sqrt(np.mean(after**2))) > float(
                    np.sqrt(np.mean(before**2))
                ):
                    continue
            off = len(_point_outliers(ms, {m: res2[m]}, sigma_p, known, scale_from=others))
            if off >= WRONG_LINK_MIN_POINTS and 2 * off > n_m:
                return PointConsistency(
                    False, _wrong_link(ms, m, off, n_m, res2[m]), tests, outliers
                )
    if outliers:
        outliers.sort(key=lambda o: -o[3])
        first = outliers[0]
        more = f" (and {len(outliers) - 1} more points)" if len(outliers) > 1 else ""
        where = first[1] if first[1] == f"record {first[0]}" else f"{first[1]} (record {first[0]})"
        return PointConsistency(
            False,
            f"outlier: {where} marker {first[2]!r} is "
            f"{first[3] * 1e3:.3g} mm from the fit{more}"
            + (f", noise {sigma_p * 1e3:.3g} mm" if known else ""),
            tests,
            outliers,
        )
    if known and not tests["chi_square"]["passed"]:
        ratio = float(np.sqrt(sum_squares / max(dof, 1)))
        if refit is not None and ratio > 1:
            for k, why in UNIT_MISTAKES:
                try:
                    ss, df = refit(scaled(ms, k))
                except DegenerateDataError:
                    continue
                if _chi2_passed(ss, df):
                    return PointConsistency(
                        False, f"{why} (rescaled, the fit matches the stated noise)", tests
                    )
        side = "above" if ratio > 1 else "below"
        return PointConsistency(
            False,
            f"the point residuals (rms {np.sqrt(np.mean(d**2)) * 1e3:.3g} mm) are {ratio:.3g}x the stated noise "
            f"sigma_p = {sigma_p * 1e3:.3g} mm per coordinate, {side} it beyond chance (p = "
            f"{min(tests['chi_square']['p_upper'], tests['chi_square']['p_lower']):.1e}): wrong noise statement, "
            "a marker on another link, or a wrong joint reading",
            tests,
        )
    return PointConsistency(True, "", tests)


def _wrong_link(ms: MeasurementSet, m: str, n_off: int | None, n: int, v: np.ndarray) -> str:
    share = (
        f"{n_off} of its {n} points are off the fit"
        if n_off is not None
        else f"its {n} points are off the fit"
    )
    return (
        f"marker {m!r} does not move with the link it is declared on ({ms.markers[m].frame!r}): {share} "
        f"(median {float(np.nanmedian(v)) * 1e3:.3g} mm) while the other markers fit: it is on another link"
    )


def scaled(ms: MeasurementSet, k: float) -> MeasurementSet:
    """``ms`` with every marker point (and known marker position) multiplied by ``k``."""
    from dataclasses import replace

    out = ms.subset(np.arange(ms.n_records))
    out.marker_points = {m: Y * k for m, Y in ms.marker_points.items()}
    out.markers = {
        m: replace(
            mk,
            position=None
            if mk.position is None
            else (mk.position[0] * k, mk.position[1] * k, mk.position[2] * k),
        )
        for m, mk in ms.markers.items()
    }
    return out


__all__ = [
    "EXTENT_RATIO",
    "MIN_OUTLIER_M",
    "UNIT_MISTAKES",
    "WRONG_LINK_MIN_POINTS",
    "WRONG_LINK_CANDIDATES",
    "PointConsistency",
    "check_point_consistency",
    "extent_check",
    "scaled",
]
