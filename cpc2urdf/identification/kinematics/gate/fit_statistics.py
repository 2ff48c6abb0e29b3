"""How far are a fit's residuals from the data's own noise statement? Exact tests, both tails.

At the maximum-likelihood fit (:func:`refine.refine`, weighted least squares of eq. (23)) of data
with Fig. 10 noise (N(0, sigma_t) per translation entry; rotation error of angle N(0, sigma_r)
about a uniformly random axis):

- translation: ``chi2_t = sum |dp|^2 / sigma_t^2`` is chi-square with ``dof_t = 3 n - h_t``
  degrees of freedom, ``h_t`` the trace of the hat matrix ``J (J^T J)^-1 J^T`` over the
  translation rows (the share of the fit's parameters spent on translations);
- rotation: ``chi2_r = sum angle^2 / sigma_r^2`` is chi-square with ``dof_r = n - h_r / 3``: each
  pose contributes ``angle^2 / sigma_r^2 = chi-square(1)`` (not chi-square(3): the angle is
  Gaussian, the axis random), and the fit spends ``h_r / 3`` of them. For per-axis Gaussian
  rotation noise this test is conservative (the statistic is less spread than assumed);
- each pose: ``|dp|^2 / sigma_t^2`` is chi-square(3) and ``angle / sigma_r`` half-normal; the
  pose's p-value is twice the smaller (as :meth:`problem.IdentificationProblem.pose_p_values`).

:class:`FitStatistics` holds the fit and these numbers; :func:`fit_statistics` computes them for a
model (refined from it first, so any method's model can be tested). Tails use
``scipy.special.gammainc`` (regularised incomplete gamma = chi-square CDF).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import solve_triangular
from scipy.special import erfc, gammainc, gammaincc

from cpc2urdf.files.measurements import MeasurementSet
from cpc2urdf.identification.kinematics.identifiability import (
    IdentifiabilityReport,
    triangular_factor,
)
from cpc2urdf.identification.kinematics.parametrization import Parametrization
from cpc2urdf.identification.kinematics.problem import IdentificationProblem
from cpc2urdf.model import CPCModel
from cpc2urdf.transforms import Array


@dataclass(frozen=True)
class FitStatistics:
    """The maximum-likelihood fit of a measurement set and its residual statistics.

    Attributes:
        model: The fitted model (refined; ``metadata.uncertainty`` set).
        frames: The fitted frames.
        sigma_t: Translation noise of the weights [m].
        sigma_r: Rotation-angle noise of the weights [rad].
        n_poses: Poses used.
        rank: Numerical rank of the weighted Jacobian at the fit (parameters determined).
        n_params: Parameters of the chart.
        chi2_t: ``sum |dp|^2 / sigma_t^2`` [-].
        dof_t: Its degrees of freedom ``3 n - h_t`` [-].
        chi2_r: ``sum angle^2 / sigma_r^2`` [-].
        dof_r: Its degrees of freedom ``n - h_r / 3`` [-].
        records: Frame -> record indices of the used poses, shape (n_f,).
        translation: Frame -> ``|dp|`` [m] of the used poses, shape (n_f,).
        rotation: Frame -> rotation error angle [rad] of the used poses, shape (n_f,).
        identifiability: Rank analysis at the fit.
        converged: The solver reported convergence.
    """

    model: CPCModel
    frames: tuple[str, ...]
    sigma_t: float
    sigma_r: float
    n_poses: int
    rank: int
    n_params: int
    chi2_t: float
    dof_t: float
    chi2_r: float
    dof_r: float
    records: dict[str, NDArray[np.intp]] = field(default_factory=dict)
    translation: dict[str, Array] = field(default_factory=dict)
    rotation: dict[str, Array] = field(default_factory=dict)
    identifiability: IdentifiabilityReport | None = None
    converged: bool = True

    @property
    def ratio_t(self) -> float:
        """RMS translation residual over the one ``sigma_t`` predicts (1 if the noise is right)."""
        return float(np.sqrt(self.chi2_t / max(self.dof_t, 1e-12)))

    @property
    def ratio_r(self) -> float:
        """RMS rotation residual over the one ``sigma_r`` predicts (1 if the noise is right)."""
        return float(np.sqrt(self.chi2_r / max(self.dof_r, 1e-12)))

    def variance_factor(self, length_factor: float = 1.0) -> float:
        """Weighted cost per degree of freedom, translations divided by ``length_factor`` [-].

        ``length_factor`` compares fits of data whose lengths were rescaled (a unit fix):
        residuals of data x1000 are x1000 for the same fit quality.
        """
        dof = self.dof_t + 3.0 * self.dof_r
        return float((self.chi2_t / length_factor**2 + 3.0 * self.chi2_r) / max(dof, 1e-12))

    def tails(self) -> dict[str, float]:
        """One-sided p-values: ``translation_low/high``, ``rotation_low/high``."""
        return {
            "translation_low": float(gammainc(self.dof_t / 2.0, self.chi2_t / 2.0)),
            "translation_high": float(gammaincc(self.dof_t / 2.0, self.chi2_t / 2.0)),
            "rotation_low": float(gammainc(self.dof_r / 2.0, self.chi2_r / 2.0)),
            "rotation_high": float(gammaincc(self.dof_r / 2.0, self.chi2_r / 2.0)),
        }

    def pose_p_values(self) -> dict[str, Array]:
        """Per used pose, the probability that a good one is this far off, shape (n_f,) per frame."""
        out = {}
        for f in self.translation:
            p_t = gammaincc(1.5, 0.5 * (self.translation[f] / self.sigma_t) ** 2)
            p_r = erfc(self.rotation[f] / self.sigma_r / np.sqrt(2.0))
            out[f] = np.minimum(1.0, 2.0 * np.minimum(p_t, p_r))
        return out

    def rms(self) -> tuple[float, float]:
        """RMS position [m] and rotation [rad] residual over the used poses."""
        t = np.concatenate(list(self.translation.values()))
        r = np.concatenate(list(self.rotation.values()))
        return float(np.sqrt(np.mean(t**2))), float(np.sqrt(np.mean(r**2)))

    def to_json(self) -> dict[str, float | int]:
        """The numbers for a model file's provenance (SI units)."""
        t, r = self.rms()
        return {
            "poses": self.n_poses,
            "parameters": self.rank,
            "sigma_t_m": self.sigma_t,
            "sigma_r_rad": self.sigma_r,
            "chi2_translation": self.chi2_t,
            "dof_translation": self.dof_t,
            "chi2_rotation": self.chi2_r,
            "dof_rotation": self.dof_r,
            "rms_translation_m": t,
            "rms_rotation_rad": r,
        }


def without_poses(ms: MeasurementSet, drop: Iterable[tuple[str, int]]) -> MeasurementSet:
    """``ms`` with the poses ``(frame, record)`` in ``drop`` marked unmeasured (NaN)."""
    poses = {f: T.copy() for f, T in ms.poses.items()}
    for f, k in drop:
        poses[f][k] = np.nan
    out = MeasurementSet(
        ms.structure, ms.q, poses, ms.source, ms.robot, list(ms.labels), metadata=dict(ms.metadata)
    )
    out.spec = ms.spec
    return out


def hat_traces(J: Array) -> tuple[float, float]:
    """Traces of the hat matrix of a full-rank weighted Jacobian (6 rows per pose: 3 translation,
    3 rotation) over its translation and its rotation rows."""
    R = triangular_factor(J)
    Q = solve_triangular(R, J.T, trans="T").T  # J R^-1: orthonormal columns spanning J
    lev = np.einsum("ij,ij->i", Q, Q).reshape(-1, 6)
    return float(lev[:, :3].sum()), float(lev[:, 3:].sum())


def fit_statistics(
    model: CPCModel,
    ms: MeasurementSet,
    sigma_t: float,
    sigma_r: float,
    *,
    frames: Iterable[str] | None = None,
    drop: Iterable[tuple[str, int]] = (),
    max_nfev: int | None = 200,
) -> FitStatistics:
    """Refine ``model`` on ``ms`` (minus the poses ``drop``) and test its residuals.

    Args:
        model: Start of the refinement (any method's estimate; already the optimum for
            ``refined``, when it costs a few evaluations).
        ms: The measurements.
        sigma_t: Stated (or assumed) translation noise per entry [m].
        sigma_r: Stated (or assumed) rotation noise angle [rad].
        frames: Frames to fit (default: every measured frame of the model).
        drop: ``(frame, record)`` poses left out (outliers already named).
        max_nfev: Solver evaluations per stage.

    Returns:
        The statistics; ``rank < n_params`` means the data leave parameters free (then the
        degrees of freedom count the determined ones only).
    """
    from cpc2urdf.identification.kinematics.refine import refine

    data = without_poses(ms, drop) if drop else ms
    if frames is None:
        frames = [
            f for f in model.structure.frame_names if f in data.poses and data.has_pose(f).any()
        ]
    frames = list(frames)
    res = refine(model, data, sigma_t, sigma_r, frames=frames, warn=False, max_nfev=max_nfev)
    use = {f: data.has_pose(f) for f in frames}
    records = {f: np.flatnonzero(use[f]) for f in frames if use[f].any()}
    dt = {f: res.residuals[f][r, 0] for f, r in records.items()}
    dr = {f: res.residuals[f][r, 1] for f, r in records.items()}
    n = sum(len(r) for r in records.values())
    rank = res.identifiability.rank
    P = res.parametrization.n_params
    if rank == P:
        chart = Parametrization(res.model, frames)
        prob = IdentificationProblem(chart, data.q, data.poses, use, sigma_t, sigma_r)
        h_t, h_r = hat_traces(prob.jacobian(np.zeros(chart.n_params)))
    else:  # free directions: split the determined ones by the translation rows' share
        h_t = h_r = rank / 2.0
    return FitStatistics(
        model=res.model,
        frames=tuple(frames),
        sigma_t=float(sigma_t),
        sigma_r=float(sigma_r),
        n_poses=n,
        rank=rank,
        n_params=P,
        chi2_t=float(sum(np.sum((v / sigma_t) ** 2) for v in dt.values())),
        dof_t=3.0 * n - h_t,
        chi2_r=float(sum(np.sum((v / sigma_r) ** 2) for v in dr.values())),
        dof_r=n - h_r / 3.0,
        records=records,
        translation=dt,
        rotation=dr,
        identifiability=res.identifiability,
        converged=res.success,
    )


__all__ = ["FitStatistics", "fit_statistics", "hat_traces", "without_poses"]
