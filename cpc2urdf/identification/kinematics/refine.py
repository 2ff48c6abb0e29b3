"""Maximum-likelihood refinement: nonlinear weighted least squares of all parameters at once.

The closed form (sec. 4 of Shih et al.) solves the identification in steps, each from part of the
data, so it is not the best estimate the data allow. This module minimises the paper's eq. (23)
with the noise model's weights, over every record (any configurations, not only the
one-joint-at-a-time protocol) and every measured frame:

    r_t = (p_meas - p_pred) / sigma_t                   (3 per measured pose) [-]
    r_r = log(R_meas R_pred^T) / (sigma_r / sqrt(3))    (3 per measured pose) [-]

``p``/``R`` are a frame's origin and rotation in world; ``log`` is the SO(3) logarithm (a rotation
vector in world, matching Fig. 10's noise, which pre-multiplies the rotation). ``sigma_t`` is the
standard deviation of each translation entry [m]; ``sigma_r`` that of the noise rotation's
*angle* [rad] (Fig. 10), whose rotation vector has per-axis standard deviation ``sigma_r /
sqrt(3)``: dividing by that makes every residual unit-variance, so the weighted least-squares
estimate is the maximum-likelihood one for Gaussian noise of that covariance and its covariance
is the Cramér-Rao bound (see :mod:`uncertainty`).

Parameters: the minimal chart of :mod:`parametrization` (32 for the IIS-head), centred on the
start model (the closed form). Jacobian: analytic (spatial twists of the chart, chain rule
through the SO(3) logarithm), checked against finite differences in ``tests/test_refine.py``.
Solver: ``scipy.optimize.least_squares`` (MINPACK Levenberg-Marquardt, Jacobian column scaling).

Robust mode (``robust=True``): a robust loss (soft-L1 by default, also Cauchy or Huber) on each
pose's weighted residual norm (one loss per pose, so a bad plate pose is one outlier, whatever
its direction) down-weights gross outliers so that they do not drag the fit; then every (record, frame) pose is tested
against the noise model (translation: chi-square with 3 dof; rotation angle: half-normal) and
poses less likely than ``outlier_alpha`` for a good measurement are reported (:class:`Outlier`, by record
index and label) and dropped, and the plain weighted least squares is re-run on the rest (so
the result is the outlier-free estimate when the test is right). A record all of whose poses
are outliers points at a wrong joint reading rather than a mis-detected plate.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation
from scipy.special import erfc, gammaincc

from cpc2urdf.errors import DegenerateDataError
from cpc2urdf.identification.kinematics.identifiability import (
    IdentifiabilityReport,
    analyze_jacobian,
    data_reasons,
)
from cpc2urdf.identification.kinematics.parametrization import Parametrization
from cpc2urdf.identification.kinematics.uncertainty import (
    Covariance,
    covariance_from_jacobian,
    with_uncertainty,
)
from cpc2urdf.model import CPCModel, CPCParams, RobotStructure
from cpc2urdf.transforms import Array

# Defaults of the noise model when the caller has none: the paper's choice (sec. 6).
DEFAULT_SIGMA_T = 0.5e-3  # [m]
DEFAULT_SIGMA_R = np.radians(0.5)  # [rad]
# Per-pose outlier test: probability that a good pose is flagged.
OUTLIER_ALPHA = 1e-4  # [-]
# Robust loss on each pose's weighted residual norm |r_b| (chi with 6 dof for a good pose): the
# loss turns from quadratic to robust around this norm, the 95 % point of a good pose.
ROBUST_SCALE = 3.55  # [-]
ROBUST_LOSSES = ("soft_l1", "cauchy", "huber")
# Re-centre the chart when a local axis update exceeds this (|(db_x, db_y)| ~ sin of the turn).
RECENTRE_TILT = 0.3  # [-]
MAX_RECENTRES = 4
# Solver tolerances (relative): tight enough to recover noise-free data to ~1e-12 m.
SOLVER_TOL = 1e-12  # [-]


class Measurements(Protocol):
    """What :func:`refine` needs of a measurement set (:class:`cpc2urdf.measurements.MeasurementSet`)."""

    structure: RobotStructure
    q: NDArray[np.float64]
    poses: dict[str, NDArray[np.float64]]

    def has_pose(self, frame: str) -> NDArray[np.bool_]: ...


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
        model: The refined model; its metadata carries ``uncertainty`` (and ``refinement``).
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
            lines.append(f"outliers ({len(self.outliers)} poses in records {self.outlier_records}):")
            lines += ["  " + o.describe() for o in self.outliers]
        if self.identifiability.warnings:
            lines += ["warning: " + w for w in self.identifiability.warnings]
        return "\n".join(lines)


# ---- residuals and their Jacobian -----------------------------------------------------------------


def _so3_log_and_jr_inv(E: Array) -> tuple[Array, Array]:
    """Rotation vectors ``phi = log(E)`` (N, 3) and the inverse right Jacobians (N, 3, 3)."""
    phi = Rotation.from_matrix(E).as_rotvec()
    th = np.linalg.norm(phi, axis=1)
    K = np.zeros((len(phi), 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -phi[:, 2], phi[:, 1], -phi[:, 0]
    K[:, 1, 0], K[:, 2, 0], K[:, 2, 1] = phi[:, 2], -phi[:, 1], phi[:, 0]
    small = th < 1e-4
    ths = np.where(small, 1.0, th)
    # J_r^-1(phi) = I + K/2 + (1/th^2 - (1 + cos th) / (2 th sin th)) K^2; series below 1e-4.
    coef = np.where(small, 1.0 / 12.0, 1.0 / ths**2 - (1.0 + np.cos(ths)) / (2.0 * ths * np.sin(ths)))
    return phi, np.eye(3) + 0.5 * K + coef[:, None, None] * (K @ K)


class _Problem:
    """Weighted residuals and Jacobian for a set of (record, frame) poses."""

    def __init__(
        self,
        chart: Parametrization,
        q: Array,
        poses: dict[str, Array],
        use: dict[str, NDArray[np.bool_]],
        sigma_t: float,
        sigma_r: float,
    ) -> None:
        self.chart = chart
        self.q = q
        self.frames = [f for f in chart.frames if use[f].any()]
        self.rows = {f: np.flatnonzero(use[f]) for f in self.frames}
        self.p_meas = {f: poses[f][self.rows[f], :3, 3] for f in self.frames}
        self.R_meas = {f: poses[f][self.rows[f], :3, :3] for f in self.frames}
        self.w_t = 1.0 / sigma_t
        self.w_r = np.sqrt(3.0) / sigma_r  # per-axis std of Fig. 10's rotation noise
        self.n_poses = sum(len(r) for r in self.rows.values())
        self.loss = "linear"
        self.scale = 1.0

    def robustified(self, loss: str, scale: float) -> _Problem:
        """This problem with a robust loss on each pose's squared weighted residual."""
        if loss not in ROBUST_LOSSES:
            raise ValueError(f"robust loss must be one of {sorted(ROBUST_LOSSES)}, got {loss!r}")
        other = _Problem.__new__(_Problem)
        other.__dict__.update(self.__dict__)
        other.loss, other.scale = loss, scale
        return other

    def _predict(self, x: Array) -> dict[str, Array]:
        model = self.chart.model_from_vector(x)
        return model.fk(self.q, self.frames)

    def residual_blocks(self, x: Array) -> dict[str, tuple[Array, Array]]:
        """Unweighted ``(p_meas - p_pred, log(R_meas R_pred^T))`` per frame, each (n_f, 3)."""
        T = self._predict(x)
        out = {}
        for f in self.frames:
            Tp = T[f][self.rows[f]]
            E = self.R_meas[f] @ np.swapaxes(Tp[:, :3, :3], 1, 2)
            out[f] = (self.p_meas[f] - Tp[:, :3, 3], Rotation.from_matrix(E).as_rotvec())
        return out

    def _weighted(self, x: Array) -> Array:
        blocks = self.residual_blocks(x)
        return np.concatenate(
            [np.hstack([dp * self.w_t, dr * self.w_r]).ravel() for dp, dr in blocks.values()]
        )

    def residuals(self, x: Array) -> Array:
        try:
            r = self._weighted(x)
        except DegenerateDataError:  # a trial step left the chart: make the solver reject it
            return np.full(6 * self.n_poses, 1e6)
        if self.loss == "linear":
            return r
        g, _ = _robust_gain(self.loss, (r.reshape(-1, 6) ** 2).sum(1) / self.scale**2)
        return (r.reshape(-1, 6) * g[:, None]).ravel()

    def jacobian(self, x: Array) -> Array:
        T, D = self.chart.pose_jacobian(x, self.q)
        out = []
        for f in self.frames:
            Tp = T[f][self.rows[f]]
            Df = D[f][self.rows[f]]  # (n_f, 6, P)
            E = self.R_meas[f] @ np.swapaxes(Tp[:, :3, :3], 1, 2)
            _, Jr_inv = _so3_log_and_jr_inv(E)
            # dR_pred = [w] R_pred  =>  E -> E exp(-[w])  =>  d log E = -J_r^-1(log E) w
            Jt = -Df[:, :3, :] * self.w_t
            Jr = -np.einsum("nij,njp->nip", Jr_inv, Df[:, 3:, :]) * self.w_r
            out.append(np.concatenate([Jt, Jr], axis=1).reshape(-1, self.chart.n_params))
        J = np.concatenate(out, axis=0)
        if self.loss == "linear":
            return J
        # Block loss rho(s), s = |r_b|^2 / c^2, as residual g(s) r_b with g^2 = rho(s) / s, so that
        # sum |g r_b|^2 = c^2 sum rho: d(g r) = g dr + r g'(s) 2 r^T dr / c^2.
        r = self._weighted(x).reshape(-1, 6)
        Jb = J.reshape(-1, 6, self.chart.n_params)
        g, dg = _robust_gain(self.loss, (r**2).sum(1) / self.scale**2)
        rJ = np.einsum("bi,bip->bp", r, Jb)
        Jb = g[:, None, None] * Jb + (2.0 * dg / self.scale**2)[:, None, None] * r[:, :, None] * rJ[:, None, :]
        return Jb.reshape(-1, self.chart.n_params)

    def pose_p_values(self, x: Array) -> dict[str, Array]:
        """Per used pose, the probability that a good measurement is this far off, per frame.

        Fig. 10's noise makes ``|dp|^2 / sigma_t^2`` chi-square(3) and ``|angle| / sigma_r``
        half-normal (the angle is N(0, sigma_r), its axis uniform), so each part has its own
        exact test; the pose's p-value is twice the smaller one (Bonferroni).
        """
        out = {}
        for f, (dp, dr) in self.residual_blocks(x).items():
            # chi2(3).sf(x) = Q(3/2, x/2); P(|N(0,1)| > z) = erfc(z / sqrt(2)) (scipy.stats is slow to import)
            p_t = gammaincc(1.5, 0.5 * (dp**2).sum(1) * self.w_t**2)
            p_r = erfc(np.linalg.norm(dr, axis=1) * self.w_r / np.sqrt(6.0))
            out[f] = np.minimum(1.0, 2.0 * np.minimum(p_t, p_r))
        return out


def _robust_gain(loss: str, z: Array) -> tuple[Array, Array]:
    """``g(z) = sqrt(rho(z) / z)`` and ``dg/dz`` for a block loss ``rho`` (``rho(z) ~ z`` near 0)."""
    zs = np.maximum(z, 0.0)
    if loss == "soft_l1":  # rho = 2 (sqrt(1 + z) - 1)
        u = np.sqrt(1.0 + zs)
        g2 = 2.0 / (u + 1.0)
        dg2 = -1.0 / ((u + 1.0) ** 2 * u)
    elif loss == "cauchy":  # rho = log(1 + z)
        small = zs < 1e-8
        zz = np.where(small, 1.0, zs)
        g2 = np.where(small, 1.0 - zs / 2.0, np.log1p(zz) / zz)
        dg2 = np.where(small, -0.5, (zz / (1.0 + zz) - np.log1p(zz)) / zz**2)
    else:  # huber: rho = z below 1, 2 sqrt(z) - 1 above
        big = zs > 1.0
        zz = np.where(big, zs, 1.0)
        g2 = np.where(big, (2.0 * np.sqrt(zz) - 1.0) / zz, 1.0)
        dg2 = np.where(big, (1.0 - np.sqrt(zz)) / zz**2, 0.0)
    g = np.sqrt(g2)
    return g, dg2 / (2.0 * g)


def _max_tilt(chart: Parametrization, x: Array) -> float:
    """Largest local axis turn ``|(db_x, db_y)|`` of any block of ``x``."""
    tilts = [np.hypot(x[b.start], x[b.start + 1]) for b in chart.blocks]
    return float(max(tilts)) if tilts else 0.0


def _solve(problem: _Problem, x0: Array, max_nfev: int | None) -> Any:
    # MINPACK's Levenberg-Marquardt: no BLAS-threaded SVD per step (trf's SVD of the 660 x 32
    # Jacobian costs 10-40x more on a loaded machine), and robust losses are folded into the
    # residuals (_robust_gain), so one solver serves both modes.
    return least_squares(
        problem.residuals,
        x0,
        jac=problem.jacobian,
        method="lm",
        x_scale="jac",
        xtol=SOLVER_TOL,
        ftol=SOLVER_TOL,
        gtol=SOLVER_TOL,
        max_nfev=max_nfev,
    )


# ---- public API ----------------------------------------------------------------------------------


def refine(
    model: CPCModel,
    measurements: Measurements,
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
        robust_loss: scipy loss for robust mode (``"soft_l1"``, ``"huber"``, ``"cauchy"``).
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
        raise DegenerateDataError(f"noise sigmas must be positive, got sigma_t={sigma_t}, sigma_r={sigma_r}")
    s = model.structure
    q = s.check_q(measurements.q)
    q = np.atleast_2d(q)
    if frames is None:
        frames = [f for f in s.frame_names if f in measurements.poses and measurements.has_pose(f).any()]
    frames = list(frames)
    if not frames:
        raise DegenerateDataError("no measured poses to refine against")
    seen = {f: np.asarray(measurements.has_pose(f), dtype=bool) for f in frames}
    chart = Parametrization(model, frames)
    poses = {f: np.asarray(measurements.poses[f], dtype=float) for f in frames}

    def problem_for(use: dict[str, NDArray[np.bool_]]) -> _Problem:
        return _Problem(chart, q, poses, use, sigma_t, sigma_r)

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
        all_poses = problem_for(seen)
        rejected: set[tuple[str, int]] = set()
        for it in range(5):  # reject, refit plainly, re-test everything; stop when stable
            pv = all_poses.pose_p_values(x)
            now = {(f, int(all_poses.rows[f][i])) for f in pv for i in np.flatnonzero(pv[f] < outlier_alpha)}
            if now == rejected and it > 0:
                break
            rejected = now
            use = {f: seen[f].copy() for f in frames}
            for f, k in rejected:
                use[f][k] = False
            if not any(u.any() for u in use.values()):
                raise DegenerateDataError("robust mode rejected every pose: are sigma_t/sigma_r far too small?")
            sol = _solve(problem_for(use), x, max_nfev)
            x, nfev = sol.x, nfev + sol.nfev
        blocks = all_poses.residual_blocks(x)
        pv = all_poses.pose_p_values(x)
        labels = getattr(measurements, "labels", None) or [f"record {i}" for i in range(len(q))]
        for f, k in sorted(rejected, key=lambda t: (t[1], t[0])):
            i = int(np.searchsorted(all_poses.rows[f], k))
            dp, dr = blocks[f]
            outliers.append(
                Outlier(k, str(labels[k]), f, float(np.linalg.norm(dp[i])), float(np.linalg.norm(dr[i])), float(pv[f][i]))
            )

    refined = chart.model_from_vector(x)
    # Everything below is about the refined model in its own chart (x = 0 there).
    final_chart = Parametrization(refined, frames)
    final = _Problem(final_chart, q, poses, use, sigma_t, sigma_r)
    x0 = np.zeros(final_chart.n_params)
    r = final.residuals(x0)
    J = final.jacobian(x0)
    reasons = data_reasons(final_chart, q, use)
    ident = analyze_jacobian(J, final_chart.names, reasons=reasons, warn=warn)
    cov = covariance_from_jacobian(J, final_chart, residuals=r, sigma_t=sigma_t, sigma_r=sigma_r, scale=covariance_scale)
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
    refined = with_uncertainty(refined, cov)
    # Model files keep only known sections: the refinement's report travels inside "uncertainty".
    refined.metadata["uncertainty"].update(
        {
            "refinement": {
                "method": "weighted least squares (scipy least_squares, Levenberg-Marquardt)" + (", robust" if robust else ""),
                "parameters": final_chart.n_params,
                "gauge": final_chart.gauge_description(),
                "poses_used": final.n_poses,
                "seconds": seconds,
            },
            "identifiability": ident.to_json(),
            "outliers": [o.__dict__ for o in outliers],
        }
    )
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


def noise_from_metadata(metadata: dict[str, Any]) -> tuple[float, float, bool]:
    """``(sigma_t, sigma_r, known)`` from a measurement set's ``noise`` section.

    The simulator writes ``{"model": "fig10", "sigma_t_m": ..., "sigma_r_rad": ...}``; then the
    sigmas are known. Otherwise (real data, stereo pixel noise) the paper's 0.5 mm / 0.5 deg set
    the relative weights and ``known`` is False (use the a-posteriori covariance scale).
    """
    noise = metadata.get("noise") if isinstance(metadata, dict) else None
    if isinstance(noise, dict):
        st, sr = noise.get("sigma_t_m"), noise.get("sigma_r_rad")
        if isinstance(st, (int, float)) and isinstance(sr, (int, float)) and st > 0 and sr > 0:
            return float(st), float(sr), True
    return DEFAULT_SIGMA_T, DEFAULT_SIGMA_R, False


def _carry_frames(refined: CPCModel, start: CPCModel, fitted: list[str]) -> CPCModel:
    """Unfitted frames (cameras) keep their pose relative to a fitted frame on the same link."""
    s = refined.structure
    moved = {}
    for f in s.frames:
        if f.name in fitted:
            continue
        anchor = next((g for g in fitted if s.frame(g).parent == f.parent), None)
        if anchor is None:
            continue
        T_link_anchor_old = start.frames[anchor].matrix()
        T_link_anchor_new = refined.frames[anchor].matrix()
        T = T_link_anchor_new @ np.linalg.solve(T_link_anchor_old, start.frames[f.name].matrix())
        moved[f.name] = CPCParams.from_matrix(T)
    return refined.with_params(frames=moved) if moved else refined


def align_base(model: CPCModel, ms: Any, frames: list[str]) -> CPCModel:
    """``model`` with ``T_world_base`` re-fitted so its frame origins best match the measured ones.

    A nominal model usually does not know where the robot stands in the measuring system's
    world; the chart of :class:`Parametrization` keeps ``T_world_base`` fixed (gauge), so a start
    must be placed first. Kabsch/Arun fit of all measured origins (sec. 3.3's registration).
    """
    T_pred = model.fk(ms.q, frames)
    a, b = [], []
    for f in frames:
        ok = ms.has_pose(f)
        a.append(T_pred[f][ok, :3, 3])
        b.append(ms.poses[f][ok, :3, 3])
    A, B = np.concatenate(a), np.concatenate(b)
    ca, cb = A.mean(0), B.mean(0)
    U, _, Vt = np.linalg.svd((A - ca).T @ (B - cb))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0])
    R = Vt.T @ D @ U.T
    G = np.eye(4)
    G[:3, :3], G[:3, 3] = R, cb - R @ ca
    return model.with_params(world_to_base=CPCParams.from_matrix(G @ model.T_world_base()))


def identify_refined(ms: Any, nominal: CPCModel | None = None, *, robust: bool = False) -> CPCModel:
    """``cpc2urdf identify --method refined``: closed form, then :func:`refine` on every record.

    Starts from the closed form (one-joint-at-a-time data); if the records do not follow that
    protocol and a nominal model is given, starts from the nominal model instead (arbitrary
    configurations). Noise sigmas come from the measurement file's ``noise`` section when it
    states them (then the covariance trusts them), else 0.5 mm / 0.5 deg with the a-posteriori
    covariance scale. Unmeasured frames (cameras) keep their pose relative to the plate on their
    link. The model carries ``provenance`` (with the start's), ``uncertainty`` and ``notes``.

    Raises:
        DegenerateDataError: Neither the closed form nor a nominal model can start it.
    """
    from cpc2urdf.identification.kinematics.methods import closed_form

    notes: list[str] = []
    try:
        start = closed_form(ms, nominal)
        start_method = "closed-form"
    except DegenerateDataError as e:
        if nominal is None:
            raise DegenerateDataError(
                f"refined identification needs a start: the closed form failed ({e}) and the robot "
                "has no nominal geometry"
            ) from e
        fitted = [f for f in nominal.structure.frame_names if f in ms.poses and ms.has_pose(f).any()]
        start, start_method = align_base(nominal, ms, fitted), "nominal"
        notes.append(
            f"closed form not applicable ({e}); refinement started from the nominal model placed "
            "in world by a rigid fit of the measured plate origins"
        )
    sigma_t, sigma_r, known = noise_from_metadata(getattr(ms, "metadata", {}))
    fitted = [f for f in start.structure.frame_names if f in ms.poses and ms.has_pose(f).any()]
    res = refine(start, ms, sigma_t, sigma_r, robust=robust, frames=fitted,
                 covariance_scale="known" if known else "a_posteriori", warn=False)
    model = _carry_frames(res.model, start, fitted)
    meta = dict(model.metadata)
    start_prov = dict(start.metadata.get("provenance", {})) if start_method == "closed-form" else {}
    meta["provenance"] = {
        **start_prov,
        "method": "refined-robust" if robust else "refined",
        "reference": "weighted least squares of every record (eq. (23) with the Fig. 10 noise "
        "weights), started from " + start_method,
        "start": start_method,
        "sigma_t_m": sigma_t,
        "sigma_r_rad": sigma_r,
        "sigma_source": "measurement file noise section" if known else "default (paper's 0.5 mm / 0.5 deg)",
        "identified_parameters": res.parametrization.counts(),
        "refinement_time_s": res.seconds,
        "outlier_records": res.outlier_records,
    }
    notes += list(start.metadata.get("notes", [])) if start_method == "closed-form" else []
    notes += [f"outlier: {o.describe()}" for o in res.outliers]
    notes += [f"identifiability: {w}" for w in res.identifiability.warnings]
    if res.covariance.variance_factor > 25.0:
        notes.append(
            f"fit residuals are {np.sqrt(res.covariance.variance_factor):.0f}x the stated noise: wrong "
            "sigmas, gross outliers (try --method refined-robust) or a start too far from the robot"
        )
    if not known:
        notes.append(
            f"noise sigmas not given: covariance scaled by the variance factor "
            f"{res.covariance.variance_factor:.3g}"
        )
    if notes:
        meta["notes"] = notes
    return model.with_params(metadata=meta)


__all__ = [
    "DEFAULT_SIGMA_R",
    "align_base",
    "identify_refined",
    "noise_from_metadata",
    "DEFAULT_SIGMA_T",
    "OUTLIER_ALPHA",
    "Measurements",
    "Outlier",
    "RefinementResult",
    "refine",
]
