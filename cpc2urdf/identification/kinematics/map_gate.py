"""The consistency gate of a calibration about the URDF (:mod:`map_identify`), made for real data.

Real robots have error no kinematic model holds (elastic links, backlash, marker bodies): spread
over every record, it is not a mistake in the data, and calling a third of the records outliers
is wrong. So, from the chosen fit's leave-one-record-out residuals (:attr:`MapFit.loo_sq_m2`):

1. **Outliers** are records more than :data:`Z_OUTLIER` robust standard deviations (per
   coordinate, the scale of the median record) from the fit made without them, and only while
   they are isolated (at most :data:`MAX_OUTLIER_SHARE` of the records). Gross outliers pull the
   fit they are in, so when a record is beyond :data:`Z_SUSPECT` the worst
   :data:`MAX_OUTLIER_SHARE` of the records are left out and every record is judged by the fit
   made without them (a trimmed fit); the outliers it finds are named and the fit made without
   them. Data with no record beyond :data:`Z_SUSPECT` cost no refit.
2. **Stated noise.** When the user states the noise, a fit whose residuals are beyond chance for
   it (chi-square, :data:`NOISE_ALPHA`) is unmodelled error, named with its size (N x the noise),
   not a list of outliers.

Without a stated noise the noise is estimated from the data, and the gate passes whatever has no
isolated outliers.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2

from cpc2urdf.identification.kinematics.prior_fit import MapFit, Noise

Z_OUTLIER = 4.0  # [-]: robust standard deviations (per coordinate) that make a record an outlier
Z_SUSPECT = 3.5  # [-]: a record beyond this in the first fit makes the gate look for outliers
MAX_OUTLIER_SHARE = 0.2  # [-]: more records beyond Z_OUTLIER than this is the model's error, not outliers
NOISE_ALPHA = 1e-3  # [-]: chance that a fit consistent with the stated noise is refused
MEDIAN_CHI2_3 = float(chi2.median(3))  # a good record's squared distance / sigma^2, median (3 coordinates)

# Left-out squared distances per record [m^2] and points per record, shape (N,) each.
RecordErrors = tuple[np.ndarray, np.ndarray]


@dataclass(frozen=True, eq=False)
class GateReport:
    """What the gate found.

    Attributes:
        fit: The fit to keep (without the outliers when there are any).
        outliers: Records (indices) far beyond the others' scatter and isolated.
        beyond: Records beyond :data:`Z_OUTLIER` in the first fit (the outliers, or too many to be).
        noise_ratio: Residual noise / stated noise (position), or None without a stated noise.
        cause: One line naming why the data are inconsistent, or "".
    """

    fit: MapFit
    outliers: tuple[int, ...]
    beyond: tuple[int, ...]
    noise_ratio: float | None
    cause: str

    @property
    def consistent(self) -> bool:
        return not self.cause


def record_z(errors: RecordErrors, keep: np.ndarray) -> np.ndarray:
    """Each record's left-out distance in robust standard deviations per coordinate, on the scale
    of the median kept record."""
    sq, points = errors
    per_point = sq / np.maximum(points, 1.0)
    used = points > 0
    sigma2 = float(np.median(per_point[used & keep])) / MEDIAN_CHI2_3
    return np.where(used, np.sqrt(per_point / (3.0 * max(sigma2, 1e-300))), 0.0)


def check(fit: MapFit, refit: Callable[[np.ndarray], tuple[MapFit, RecordErrors]], stated: Noise | None,
          labels: list[str]) -> GateReport:
    """The gate (module docstring). ``refit(dropped)`` fits again without the records ``dropped``
    and gives every record's left-out error (a dropped record's: its error under that fit)."""
    errors: RecordErrors = (fit.loo_sq_m2, fit.loo_points)
    n = int((fit.loo_points > 0).sum())
    z = record_z(errors, np.ones(len(fit.loo_points), bool))
    beyond = np.flatnonzero(z > Z_OUTLIER)
    drop = np.zeros(len(fit.loo_points), bool)
    kept = fit
    if (z > Z_SUSPECT).any():  # gross outliers pull the fit they are in: judge by a trimmed fit
        trimmed = np.argsort(-z)[:max(1, int(MAX_OUTLIER_SHARE * n))]
        _, errors = refit(trimmed)
        drop = record_z(errors, np.ones(len(z), bool)) > Z_OUTLIER
        if 0 < drop.sum() <= MAX_OUTLIER_SHARE * n:
            kept, errors = refit(np.flatnonzero(drop))
        else:
            drop[:] = False
    outliers = tuple(int(i) for i in np.flatnonzero(drop))
    ratio, cause = None, ""
    if outliers:
        cause = (f"{len(outliers)} isolated outlier record(s), more than {Z_OUTLIER:g} standard deviations from "
                 f"the fit made without them: " + ", ".join(labels[i] for i in outliers))
    elif stated is not None:
        m = float(kept.loo_points.sum()) * 3
        ratio = kept.residual_noise.position_m / stated.position_m
        dof = max(m - kept.dof, 1.0)
        chi = ratio**2 * dof
        if chi > chi2.isf(NOISE_ALPHA, dof):
            cause = (f"unmodelled error: the fit's residuals are {ratio:.1f}x the stated noise "
                     f"({kept.residual_noise.position_m * 1e3:.3f} mm against {stated.position_m * 1e3:.3f} mm), "
                     "spread over the records, not a few of them (elastic links, backlash, marker bodies, or "
                     "the stated noise is too small)")
        elif chi < chi2.ppf(NOISE_ALPHA, dof):
            cause = (f"the fit's residuals are {1 / ratio:.1f}x below the stated noise "
                     f"({kept.residual_noise.position_m * 1e3:.3f} mm against {stated.position_m * 1e3:.3f} mm): "
                     "the stated noise is too large")
    return GateReport(kept, outliers, tuple(int(i) for i in beyond), ratio, cause)


__all__ = ["MAX_OUTLIER_SHARE", "NOISE_ALPHA", "Z_OUTLIER", "GateReport", "RecordErrors", "check", "record_z"]
