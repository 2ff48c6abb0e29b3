"""Maximum-likelihood refinement: nonlinear weighted least squares of all parameters at once.

The closed form (sec. 4 of Shih et al.) solves the identification in steps, each from part of the
data, so it is not the best estimate the data allow. :func:`refine` minimises the paper's eq. (23)
with the noise model's weights (:class:`~cpc2urdf.identification.kinematics.problem.IdentificationProblem`:
residuals, units and Jacobian) over every record and every measured frame, in the minimal chart of
:mod:`parametrization` (32 parameters for the IIS-head) centred on the start model (the closed
form). Solver: ``scipy.optimize.least_squares`` (MINPACK Levenberg-Marquardt, Jacobian column
scaling). The estimate's covariance and identifiability come with the result (:mod:`uncertainty`,
:mod:`identifiability`).

Robust mode (``robust=True``): a robust loss (soft-L1 by default, also Cauchy or Huber) on each
pose's weighted residual norm (one loss per pose, so a bad plate pose is one outlier, whatever
its direction) down-weights gross outliers so that they do not drag the fit; then every (record, frame) pose is tested
against the noise model (translation: chi-square with 3 dof; rotation angle: half-normal) and
poses less likely than ``outlier_alpha`` for a good measurement are reported (:class:`Outlier`, by record
index and label) and dropped, and the plain weighted least squares is re-run on the rest (so
the result is the outlier-free estimate when the test is right). A record all of whose poses
are outliers points at a wrong joint reading rather than a mis-detected plate.

"Closed form, then refine" as ``cpc2urdf identify --method refined`` runs it is
:func:`cpc2urdf.identification.kinematics.methods.identify_refined`.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field, replace
from typing import Protocol

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import OptimizeResult, least_squares

from cpc2urdf.errors import DegenerateDataError
from cpc2urdf.files.measurements import MeasurementSet
from cpc2urdf.identification.kinematics.identifiability import (
    IdentifiabilityReport,
    analyze_jacobian,
    data_reasons,
)
from cpc2urdf.identification.kinematics.parametrization import Parametrization
from cpc2urdf.identification.kinematics.problem import (
    DEFAULT_SIGMA_R,
    DEFAULT_SIGMA_T,
    IdentificationProblem,
)
from cpc2urdf.identification.kinematics.uncertainty import (
    Covariance,
    covariance_from_jacobian,
    with_uncertainty,
)
from cpc2urdf.model import CPCModel
from cpc2urdf.transforms import Array

# Per-pose outlier test: probability that a good pose is flagged.
OUTLIER_ALPHA = 1e-4  # [-]
# Robust loss on each pose's weighted residual norm |r_b| (chi with 6 dof for a good pose): the
# loss turns from quadratic to robust around this norm, the 95 % point of a good pose.
ROBUST_SCALE = 3.55  # [-]
# Re-centre the chart when a local axis update exceeds this (|(db_x, db_y)| ~ sin of the turn).
RECENTRE_TILT = 0.3  # [-]
MAX_RECENTRES = 4
# Solver tolerances (relative): tight enough to recover noise-free data to ~1e-12 m.
SOLVER_TOL = 1e-12  # [-]
# A solver run that lowers the cost by less than this (relative) in STALL_NFEV evaluations is
# stopped as stalled (it crawls on data the model cannot explain).
STALL_NFEV = 20
STALL_DECREASE = 1e-3  # [-]
# ... but only while the weighted residuals' mean square exceeds this (1 for data that fit their
# noise): a fit at its noise (or at rounding, noise-free) is left to the solver's tolerances.
STALL_VARIANCE_FACTOR = 10.0  # [-]


@dataclass(frozen=True)
class Outlier:
    """A measured pose the robust test rejected.

    Attributes:
        record: Record index in the measurement set.
        label: The record's label.
        frame: Frame whose pose was rejected.
        translation_error: Position residual [m] at the final (outlier-free) fit.
        rotation_error: Rotation residual angle [rad] at the final fit.
        p_value: Probability that a good pose is this far off (the smaller of the translation
            and rotation tests, Bonferroni-doubled).
    """

    record: int
    label: str
    frame: str
    translation_error: float
    rotation_error: float
    p_value: float

    def describe(self) -> str:
        return (
            f"record {self.record} ({self.label}) {self.frame}: {self.translation_error * 1e3:.2f} mm, "
            f"{np.degrees(self.rotation_error):.2f} deg  (p = {self.p_value:.1e})"
        )


@dataclass
class RefinementResult:
    """What :func:`refine` returns.

    Attributes:
        model: The refined model; ``metadata.uncertainty`` is its covariance, whose ``details``
            carry the refinement's report (settings, identifiability, outliers).
        start: The model it started from.
        parametrization: The chart centred on ``model`` (names, units, counts).
        covariance: Parameter covariance in that chart (:mod:`uncertainty`).
        identifiability: Rank analysis of the weighted Jacobian at the optimum.
        outliers: Poses rejected in robust mode (empty otherwise).
        sigma_t: Translation noise used for the weights [m].
        sigma_r: Rotation-angle noise used for the weights [rad].
        cost: Half the sum of squared weighted residuals at the optimum (used poses only).
        n_poses: Measured poses used (after outlier rejection).
        translation_rms: RMS position residual of the used poses [m].
        rotation_rms: RMS rotation residual angle of the used poses [rad].
        iterations: Solver function evaluations (all stages).
        seconds: Wall time of the refinement [s].
        success: The solver reported convergence.
        message: The solver's message.
        residuals: Per frame, per record: position and rotation residual at the optimum (NaN
            where not measured), ``{frame: (N, 2)}`` in [m] and [rad].
    """

    model: CPCModel
    start: CPCModel
    parametrization: Parametrization
    covariance: Covariance
    identifiability: IdentifiabilityReport
    outliers: list[Outlier]
    sigma_t: float
    sigma_r: float
    cost: float
    n_poses: int
    translation_rms: float
    rotation_rms: float
    iterations: int
    seconds: float
    success: bool
    message: str
    residuals: dict[str, Array] = field(default_factory=dict)

    @property
    def outlier_records(self) -> list[int]:
        """Sorted record indices with at least one rejected pose."""
        return sorted({o.record for o in self.outliers})

    def summary(self) -> str:
        """A few lines for a terminal."""
        c = self.parametrization.counts()
        lines = [
            f"refined {c['total']} parameters ({c['revolute']} revolute-axis, {c['prismatic']} "
            f"prismatic-direction, {c['frame']} frame) from {self.n_poses} poses in "
            f"{self.seconds * 1e3:.0f} ms ({self.iterations} evaluations)",
            f"residual RMS: {self.translation_rms * 1e3:.3f} mm, {np.degrees(self.rotation_rms):.3f} deg; "
            f"variance factor {self.covariance.variance_factor:.3f} (1 if sigma_t = "
            f"{self.sigma_t * 1e3:g} mm, sigma_r = {np.degrees(self.sigma_r):g} deg are right)",
        ]
        if self.outliers:
            lines.append(
                f"outliers ({len(self.outliers)} poses in records {self.outlier_records}):"
            )
            lines += ["  " + o.describe() for o in self.outliers]
        if self.identifiability.warnings:
            lines += ["warning: " + w for w in self.identifiability.warnings]
        return "\n".join(lines)


def _max_tilt(chart: Parametrization, x: Array) -> float:
    """Largest local axis turn ``|(db_x, db_y)|`` of any block of ``x``."""
    tilts = [np.hypot(x[b.start], x[b.start + 1]) for b in chart.blocks]
    return float(max(tilts)) if tilts else 0.0


class LeastSquaresProblem(Protocol):
    """What the solver needs: weighted residuals and their Jacobian at chart coordinates ``x``."""

    def residuals(self, x: Array) -> Array: ...

    def jacobian(self, x: Array) -> Array: ...


def _solve(problem: LeastSquaresProblem, x0: Array, max_nfev: int | None) -> OptimizeResult:
    # MINPACK's Levenberg-Marquardt: no BLAS-threaded SVD per step (trf's SVD of the 660 x 32
    # Jacobian costs 10-40x more on a loaded machine), and robust losses are folded into the
    # residuals (IdentificationProblem.robustified), so one solver serves both modes.
    # Run in chunks of STALL_NFEV evaluations and stop when a chunk lowers the cost by less than
    # STALL_DECREASE while the residuals are still far above the noise (STALL_VARIANCE_FACTOR):
    # data the model cannot explain make LM crawl along a valley for hundreds of evaluations (the
    # consistency gate refuses them whatever the exact optimum); a fit that converges (a few
    # evaluations from the closed form) is untouched.
    x = np.asarray(x0, dtype=float)
    r0 = problem.residuals(x)
    cost, crawl = 0.5 * float(r0 @ r0), 0.5 * STALL_VARIANCE_FACTOR * len(r0)
    total = 0
    while True:
        left = None if max_nfev is None else max(1, max_nfev - total)
        chunk = (STALL_NFEV if left is None else min(STALL_NFEV, left)) if cost > crawl else left
        sol = least_squares(
            problem.residuals,
            x,
            jac=problem.jacobian,
            method="lm",
            x_scale="jac",
            xtol=SOLVER_TOL,
            ftol=SOLVER_TOL,
            gtol=SOLVER_TOL,
            max_nfev=chunk,
        )
        total += int(sol.nfev)
        stalled = cost > crawl and cost - float(sol.cost) < STALL_DECREASE * cost
        x, cost = sol.x, float(sol.cost)
        if sol.status != 0 or chunk == left or stalled:
            if stalled and sol.status == 0:
                sol.message = f"stopped: {STALL_NFEV} evaluations lowered the cost by less than {STALL_DECREASE:g}"
            sol.nfev = total
            return sol


# The solver, for the other problems of the package (position-only data, :mod:`point_refine`).
solve_least_squares = _solve


def _drop_outliers(
    problem_for: Callable[[dict[str, NDArray[np.bool_]]], IdentificationProblem],
    seen: dict[str, NDArray[np.bool_]],
    x: Array,
    max_nfev: int | None,
    outlier_alpha: float,
    labels: Sequence[str],
) -> tuple[Array, OptimizeResult, dict[str, NDArray[np.bool_]], list[Outlier], int]:
    """Robust mode: reject the poses whose test fails at ``outlier_alpha``, refit plainly, re-test
    every pose, until the rejected set is stable. Returns the estimate, the last solve, the poses
    used, the outliers and the solver evaluations spent."""
    all_poses = problem_for(seen)
    rejected: set[tuple[str, int]] = set()
    use, sol, nfev = dict(seen), OptimizeResult(success=True, message=""), 0
    for it in range(5):
        pv = all_poses.pose_p_values(x)
        now = {
            (f, int(all_poses.rows[f][i]))
            for f in pv
            for i in np.flatnonzero(pv[f] < outlier_alpha)
        }
        if now == rejected and it > 0:
            break
        rejected = now
        use = {f: m.copy() for f, m in seen.items()}
        for f, k in rejected:
            use[f][k] = False
        if not any(u.any() for u in use.values()):
            raise DegenerateDataError(
                "robust mode rejected every pose: are sigma_t/sigma_r far too small?"
            )
        sol = _solve(problem_for(use), x, max_nfev)
        x, nfev = sol.x, nfev + sol.nfev
    blocks = all_poses.residual_blocks(x)
    pv = all_poses.pose_p_values(x)
    outliers = []
    for f, k in sorted(rejected, key=lambda t: (t[1], t[0])):
        i = int(np.searchsorted(all_poses.rows[f], k))
        dp, dr = blocks[f]
        outliers.append(
            Outlier(
                k,
                str(labels[k]),
                f,
                float(np.linalg.norm(dp[i])),
                float(np.linalg.norm(dr[i])),
                float(pv[f][i]),
            )
        )
    return x, sol, use, outliers, nfev


# ---- public API ----------------------------------------------------------------------------------


def refine(
    model: CPCModel,
    measurements: MeasurementSet,
    sigma_t: float = DEFAULT_SIGMA_T,
    sigma_r: float = DEFAULT_SIGMA_R,
    robust: bool = False,
    *,
    frames: Iterable[str] | None = None,
    covariance_scale: str = "known",
    robust_loss: str = "soft_l1",
    outlier_alpha: float = OUTLIER_ALPHA,
    max_nfev: int | None = 200,
    warn: bool = True,
) -> RefinementResult:
    """Weighted least-squares refinement of every identifiable parameter of ``model``.

    Args:
        model: Start (typically the closed-form estimate); its gauge is kept.
        measurements: Records ``q`` (N, n) [rad]/[m] and measured ``T_world_<frame>`` poses.
        sigma_t: Standard deviation of each measured translation entry [m].
        sigma_r: Standard deviation of the measured rotation error's angle [rad] (Fig. 10).
        robust: Find and drop gross outliers (see module doc).
        frames: Frames to fit (default: every frame with a measured pose).
        covariance_scale: ``"known"`` (trust the sigmas) or ``"a_posteriori"`` (scale the
            covariance by the variance factor); see :mod:`uncertainty`.
        robust_loss: Robust loss for robust mode (``"soft_l1"``, ``"huber"``, ``"cauchy"``; see
            :meth:`IdentificationProblem.robustified`).
        outlier_alpha: Probability that the test rejects a good pose.
        max_nfev: Cap on solver evaluations per stage.
        warn: Issue :class:`IdentifiabilityWarning` for undetermined parameters.

    Returns:
        A :class:`RefinementResult`; ``result.model`` carries the ``uncertainty`` section.

    Raises:
        DegenerateDataError: No measured pose, or non-positive sigmas.
    """
    t0 = time.perf_counter()
    if not (sigma_t > 0 and sigma_r > 0 and np.isfinite(sigma_t) and np.isfinite(sigma_r)):
        raise DegenerateDataError(
            f"noise sigmas must be positive, got sigma_t={sigma_t}, sigma_r={sigma_r}"
        )
    s = model.structure
    q = s.check_q(measurements.q)
    q = np.atleast_2d(q)
    if frames is None:
        frames = [
            f for f in s.frame_names if f in measurements.poses and measurements.has_pose(f).any()
        ]
    frames = list(frames)
    if not frames:
        raise DegenerateDataError("no measured poses to refine against")
    seen = {f: np.asarray(measurements.has_pose(f), dtype=bool) for f in frames}
    chart = Parametrization(model, frames)
    poses = {f: np.asarray(measurements.poses[f], dtype=float) for f in frames}

    def problem_for(use: dict[str, NDArray[np.bool_]]) -> IdentificationProblem:
        return IdentificationProblem(chart, q, poses, use, sigma_t, sigma_r)

    nfev = 0
    outliers: list[Outlier] = []
    use = dict(seen)
    # First fit; re-centre the chart on the current estimate while it has turned some axis by
    # more than RECENTRE_TILT (a start far from the robot), so the local updates stay small.
    x = np.zeros(chart.n_params)
    for _ in range(MAX_RECENTRES + 1):
        first = problem_for(use)
        sol = _solve(first.robustified(robust_loss, ROBUST_SCALE) if robust else first, x, max_nfev)
        x, nfev = sol.x, nfev + sol.nfev
        if _max_tilt(chart, x) < RECENTRE_TILT:
            break
        chart = Parametrization(chart.model_from_vector(x), frames)
        x = np.zeros(chart.n_params)
    if robust:
        labels = measurements.labels or [f"record {i}" for i in range(len(q))]
        x, sol, use, outliers, more = _drop_outliers(
            problem_for, seen, x, max_nfev, outlier_alpha, labels
        )
        nfev += more

    refined = chart.model_from_vector(x)
    # Everything below is about the refined model in its own chart (x = 0 there).
    final_chart = Parametrization(refined, frames)
    final = IdentificationProblem(final_chart, q, poses, use, sigma_t, sigma_r)
    x0 = np.zeros(final_chart.n_params)
    r = final.residuals(x0)
    J = final.jacobian(x0)
    reasons = data_reasons(final_chart, q, use)
    ident = analyze_jacobian(J, final_chart.names, reasons=reasons, warn=warn)
    cov = covariance_from_jacobian(
        J, final_chart, residuals=r, sigma_t=sigma_t, sigma_r=sigma_r, scale=covariance_scale
    )
    blocks = problem_for(seen).residual_blocks(x)
    res_table: dict[str, Array] = {}
    dps, drs = [], []
    for f in frames:
        tab = np.full((len(q), 2), np.nan)
        rows = np.flatnonzero(seen[f])
        dp, dr = blocks[f]
        tab[rows, 0] = np.linalg.norm(dp, axis=1)
        tab[rows, 1] = np.linalg.norm(dr, axis=1)
        res_table[f] = tab
        keep = use[f][rows]
        dps.append(dp[keep])
        drs.append(dr[keep])
    dp_all, dr_all = np.concatenate(dps), np.concatenate(drs)
    seconds = time.perf_counter() - t0
    # Model files keep only known sections: the refinement's report travels with the covariance.
    cov = replace(
        cov,
        details={
            "refinement": {
                "method": "weighted least squares (scipy least_squares, Levenberg-Marquardt)"
                + (", robust" if robust else ""),
                "parameters": final_chart.n_params,
                "gauge": final_chart.gauge_description(),
                "poses_used": final.n_poses,
                "seconds": seconds,
            },
            "identifiability": ident.to_json(),
            "outliers": [o.__dict__ for o in outliers],
        },
    )
    refined = with_uncertainty(refined, cov)
    if not sol.success and warn:
        warnings.warn(f"refinement did not converge: {sol.message}", RuntimeWarning, stacklevel=2)
    return RefinementResult(
        model=refined,
        start=model,
        parametrization=final_chart,
        covariance=cov,
        identifiability=ident,
        outliers=outliers,
        sigma_t=float(sigma_t),
        sigma_r=float(sigma_r),
        cost=0.5 * float(r @ r),
        n_poses=final.n_poses,
        translation_rms=float(np.sqrt(np.mean(np.sum(dp_all**2, axis=1)))),
        rotation_rms=float(np.sqrt(np.mean(np.sum(dr_all**2, axis=1)))),
        iterations=int(nfev),
        seconds=seconds,
        success=bool(sol.success),
        message=str(sol.message),
        residuals=res_table,
    )


__all__ = [
    "MAX_RECENTRES",
    "OUTLIER_ALPHA",
    "RECENTRE_TILT",
    "ROBUST_SCALE",
    "SOLVER_TOL",
    "STALL_DECREASE",
    "STALL_NFEV",
    "STALL_VARIANCE_FACTOR",
    "LeastSquaresProblem",
    "Outlier",
    "RefinementResult",
    "refine",
    "solve_least_squares",
]
