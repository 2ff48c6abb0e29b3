"""The consistency gate after every stage-1 fit: data that disagree with the model are refused,
with the most likely cause named.

A fit whose residuals are far from the data's own noise statement, above **or below**, is not a
result (docs/identification.md, "Consistency gate"). :func:`check_consistency` tests the maximum-
likelihood fit of the data as read (:mod:`fit_statistics`):

- **with a noise statement** (the measurement file's ``noise`` section gives ``sigma_t_m`` and
  ``sigma_r_rad``): chi-square tests of the translation and rotation residuals, both tails, and
  each pose's exact test, at a family-wise false-alarm probability :data:`FALSE_ALARM` (half to
  the four tails, half to the poses, Bonferroni);
- **without one**: each pose against :data:`OUTLIER_RATIO` times its frame's median residual (a
  robust scale), and every likely mistake of :mod:`alternatives` refitted: one that fits
  :data:`MIN_IMPROVEMENT` times better (and beyond the F-test at :data:`FALSE_ALARM`) shows the
  data as read are wrong;
- always: the implied robot size against the nominal model or the joint limits
  (:mod:`plausibility`), which catches a unit mistake that fits perfectly.

When a test fails, the gate **diagnoses by refitting**: every fix of :mod:`alternatives` is
screened with the closed form (milliseconds each), the :data:`SCREENED` most promising are
refined and tested like the data as read, and gross outliers are looked for with the robust
refinement (:func:`refine.refine` ``robust=True``). The fix that makes the data consistent is
named (:class:`Diagnosis`); if none does, the failed test is named. :class:`ConsistencyReport`
holds the verdict; :meth:`ConsistencyReport.error` is the one-line refusal.

The tests and the verdict's types are in :mod:`verdict`, the refits in :mod:`diagnosis`; this
module is the gate and the one place to import them from.
"""

from __future__ import annotations

from collections.abc import Iterable

from cpc2urdf.errors import DegenerateDataError
from cpc2urdf.files.measurements import MeasurementSet
from cpc2urdf.identification.kinematics.gate.alternatives import alternatives
from cpc2urdf.identification.kinematics.gate.diagnosis import (
    diagnose,
    diagnose_unfittable,
    unexplained,
)
from cpc2urdf.identification.kinematics.gate.fit_statistics import fit_statistics
from cpc2urdf.identification.kinematics.gate.verdict import (
    ACCEPT_HINT,
    FALSE_ALARM,
    MAX_OUTLIER_FRACTION,
    MIN_IMPROVEMENT,
    OUTLIER_RATIO,
    SCREENED,
    STATS_NFEV,
    ConsistencyReport,
    Diagnosis,
    Noise,
    evaluate,
    is_exact,
    noise_problems,
)
from cpc2urdf.identification.kinematics.sufficiency import check_no_copies
from cpc2urdf.model import CPCModel


def check_consistency(
    ms: MeasurementSet,
    model: CPCModel,
    nominal: CPCModel | None,
    noise: Noise,
    *,
    drop: Iterable[tuple[str, int]] = (),
) -> ConsistencyReport:
    """Test an identified model against its data (see the module docstring).

    Args:
        ms: The measurements it was identified from.
        model: The identified model (any method's).
        nominal: The robot's nominal model (a size yardstick, and a start for data outside the
            one-joint-at-a-time protocol), or None.
        noise: The stated noise, or the weights assumed without a statement.
        drop: ``(frame, record)`` poses the method already rejected as outliers (tested as
            such: more than :data:`MAX_OUTLIER_FRACTION` of the poses is itself a problem).

    Returns:
        The report; ``report.error()`` is the refusal to raise when it is not consistent.

    Raises:
        DegenerateDataError: The data leave some parameters free (named), or noisy data hold
            copied records.
    """
    drop = list(drop)
    stats = fit_statistics(model, ms, noise.sigma_t, noise.sigma_r, drop=drop, max_nfev=STATS_NFEV)
    if stats.rank < stats.n_params and stats.identifiability is not None:
        ident = stats.identifiability
        owners = sorted({n.rpartition(".")[0] for n in ident.undetermined})
        why = "; ".join(ident.reasons[o] for o in owners if o in ident.reasons)
        raise DegenerateDataError(
            f"{ms.source}: the data determine only {stats.rank} of {stats.n_params} parameters (free combinations "
            f"involve {', '.join(owners)}){': ' + why if why else ''}; measure these joints at more configurations "
            "(one joint at a time from q0, Shih et al. sec. 4.1)"
        )
    if not is_exact(stats):
        check_no_copies(ms)
    share = len(drop) / max(stats.n_poses + len(drop), 1)
    problems, outliers, size = evaluate(stats, noise, ms, nominal, share)
    if not problems and (noise.known or is_exact(stats)):
        return ConsistencyReport(True, ms.source, noise, stats, size=size)
    diagnosis, tested = diagnose(
        ms, nominal, noise, stats, size, bool(outliers) or bool(noise_problems(stats, noise))
    )
    if diagnosis is None and not problems:
        return ConsistencyReport(True, ms.source, noise, stats, tested=tuple(tested), size=size)
    if diagnosis is None:
        diagnosis = unexplained(
            problems, stats, noise, size, len(alternatives(ms)) + 1, outliers, ms
        )
    return ConsistencyReport(
        False,
        ms.source,
        noise,
        stats,
        tuple(problems) or ("a likely mistake fits far better",),
        diagnosis,
        tuple(tested),
        size,
    )


__all__ = [
    "ACCEPT_HINT",
    "FALSE_ALARM",
    "MAX_OUTLIER_FRACTION",
    "MIN_IMPROVEMENT",
    "OUTLIER_RATIO",
    "SCREENED",
    "ConsistencyReport",
    "Diagnosis",
    "Noise",
    "check_consistency",
    "diagnose_unfittable",
]
