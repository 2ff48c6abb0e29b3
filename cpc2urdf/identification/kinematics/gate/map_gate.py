"""The consistency gate of a calibration about the URDF (:mod:`map_identify`), made for real data.

Real robots have error no kinematic model holds (elastic links, backlash, marker bodies): spread
over every record, it is not a mistake in the data, and calling a third of the records outliers
is wrong. So:

1. **Outliers.** Each record is judged by the fit made without it: its studentized left-out
   statistics (:attr:`MapFit.loo_stat`, ``r_i^T (I - H_ii)^-1 r_i`` over its positions and, for
   frame poses, over its orientations; they account for how much the record alone determines) on
   the scale of the median record. A record more than
   :data:`Z_OUTLIER` robust standard deviations (per row) away is an outlier; the worst one is left
   out, the fit made again and the others judged again, until none is that far, and only while
   they stay isolated (at most :data:`MAX_OUTLIER_SHARE` of the records: more is the model's error,
   not outliers). The position and orientation parts of a statistic are taken apart (the cross
   terms between them make each part chi-square only approximately). The outliers are named and the fit is made without them. Data with no such
   record cost no refit.
2. **Stated noise.** When the user states the noise, a fit whose position (or, for frame poses,
   orientation) residuals are beyond chance for it (chi-square with the degrees of freedom the fit
   left them, :data:`NOISE_ALPHA`) is unmodelled error, named with its size (N x the noise), not a
   list of outliers.

Without a stated noise the noise is estimated from the data, and the gate passes whatever has no
isolated outliers.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2

from cpc2urdf.identification.kinematics.prior_fit import MapFit, Noise

Z_OUTLIER = 4.0  # [-]: robust standard deviations (per row) that make a record an outlier
MAX_OUTLIER_SHARE = (
    0.2  # [-]: more records beyond Z_OUTLIER than this is the model's error, not outliers
)
NOISE_ALPHA = 1e-3  # [-]: chance that a fit consistent with the stated noise is refused


@dataclass(frozen=True, eq=False)
class GateReport:
    """What the gate found.

    Attributes:
        fit: The fit to keep (without the outliers when there are any).
        outliers: Records (indices) far beyond the others' scatter and isolated.
        noise_ratio: Residual noise / stated noise (position), or None without a stated noise.
        cause: One line naming why the data are inconsistent, or "".
    """

    fit: MapFit
    outliers: tuple[int, ...]
    noise_ratio: float | None
    cause: str

    @property
    def consistent(self) -> bool:
        return not self.cause


def _z(stat: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """Studentized statistics ``stat`` of ``rows`` rows each, in robust standard deviations per
    row: the median record's chi-square sets the scale (the noise estimate, inflated by outliers,
    cancels)."""
    used = rows > 0
    if not used.any():
        return np.zeros(len(rows))
    r = np.maximum(rows, 1.0)
    stat = np.maximum(stat, 0.0)  # a part of a record's statistic can dip below 0 (cross terms)
    scale = float(np.median((stat / chi2.median(r))[used]))
    return np.where(used, np.sqrt(stat / (max(scale, 1e-300) * r)), 0.0)


def record_z(fit: MapFit) -> np.ndarray:
    """Each record's left-out position and orientation statistics (:attr:`MapFit.loo_stat`,
    :attr:`MapFit.loo_stat_rot`) in robust standard deviations per row, the larger of the two,
    shape (N,)."""
    return np.maximum(
        _z(fit.loo_stat, 3.0 * fit.loo_points), _z(fit.loo_stat_rot, 3.0 * fit.loo_frames)
    )


def check(
    fit: MapFit, refit: Callable[[np.ndarray], MapFit], stated: Noise | None, labels: list[str]
) -> GateReport:
    """The gate (module docstring). ``refit(kept)`` fits again on the records ``kept`` (indices)."""
    n = len(fit.loo_points)
    kept = np.arange(n)
    current = fit
    z = record_z(fit)
    while z.max(initial=0.0) > Z_OUTLIER and n - len(kept) + 1 <= MAX_OUTLIER_SHARE * n:
        kept = np.delete(kept, int(np.argmax(z)))
        current = refit(kept)
        z = record_z(current)
    outliers = tuple(int(i) for i in np.setdiff1d(np.arange(n), kept))
    if z.max(initial=0.0) > Z_OUTLIER:  # not isolated: the model's error, not a few bad records
        outliers, current = (), fit
    ratio, cause = None, ""
    if outliers:
        cause = (
            f"{len(outliers)} isolated outlier record(s), more than {Z_OUTLIER:g} standard deviations from "
            f"the fit made without them: " + ", ".join(labels[i] for i in outliers)
        )
    elif stated is not None:
        shown = current.residual_noise
        m_pos = float(current.loo_points.sum()) * 3
        m_rot = float(current.loo_frames.sum()) * 3
        checks = [
            (
                "position",
                shown.position_m,
                stated.position_m,
                m_pos - current.dof_position,
                1e3,
                "mm per coordinate",
            )
        ]
        if m_rot:
            checks.append(
                (
                    "orientation",
                    shown.rotation_rad,
                    stated.rotation_rad,
                    m_rot - (current.dof - current.dof_position),
                    180 / np.pi,
                    "deg per axis",
                )
            )
        for what, got, want, dof, scale, unit in checks:
            r = got / want
            ratio = r if ratio is None else ratio
            stat = r**2 * max(dof, 1.0)
            if stat > chi2.isf(NOISE_ALPHA, max(dof, 1.0)):
                cause = (
                    f"unmodelled error: the fit's {what} residuals are {r:.1f}x the stated noise "
                    f"({got * scale:.3f} {unit} against {want * scale:.3f} {unit}), spread over the records, "
                    "not a few of them (elastic links, backlash, marker bodies, or the stated noise is too small)"
                )
                break
            if stat < chi2.ppf(NOISE_ALPHA, max(dof, 1.0)):
                cause = (
                    f"the fit's {what} residuals are {1 / r:.1f}x below the stated noise "
                    f"({got * scale:.3f} {unit} against {want * scale:.3f} {unit}): the stated noise is too large"
                )
                break
    return GateReport(current, outliers, ratio, cause)


__all__ = ["MAX_OUTLIER_SHARE", "NOISE_ALPHA", "Z_OUTLIER", "GateReport", "check", "record_z"]
