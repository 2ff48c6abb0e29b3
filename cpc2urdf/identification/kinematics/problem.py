"""The maximum-likelihood identification problem: weighted residuals of eq. (23) and their Jacobian.

The paper's eq. (23), with the noise model's weights, over every record (any configurations, not
only the one-joint-at-a-time protocol) and every measured frame:

    r_t = (p_meas - p_pred) / sigma_t                   (3 per measured pose) [-]
    r_r = log(R_meas R_pred^T) / (sigma_r / sqrt(3))    (3 per measured pose) [-]

``p``/``R`` are a frame's origin and rotation in world; ``log`` is the SO(3) logarithm (a rotation
vector in world, matching Fig. 10's noise, which pre-multiplies the rotation). ``sigma_t`` is the
standard deviation of each translation entry [m]; ``sigma_r`` that of the noise rotation's
*angle* [rad] (Fig. 10), whose rotation vector has per-axis standard deviation ``sigma_r /
sqrt(3)``: dividing by that makes every residual unit-variance, so the weighted least-squares
estimate is the maximum-likelihood one for Gaussian noise of that covariance and its covariance
is the Cramér-Rao bound (see :mod:`uncertainty`).

Parameters: the minimal chart of :mod:`parametrization` (32 for the IIS-head), centred on a
model. Jacobian: analytic (spatial twists of the chart, chain rule through the SO(3) logarithm),
checked against finite differences in ``tests/test_refine.py``. :mod:`refine` minimises it;
:func:`uncertainty.cramer_rao_covariance` evaluates its Jacobian at a true robot.
"""

from __future__ import annotations

import copy

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation
from scipy.special import erfc, gammaincc

from cpc2urdf.errors import DegenerateDataError
from cpc2urdf.identification.kinematics.parametrization import Parametrization
from cpc2urdf.transforms import Array

# Defaults of the noise model when the caller has none: the paper's choice (sec. 6).
DEFAULT_SIGMA_T = 0.5e-3  # [m]
DEFAULT_SIGMA_R = np.radians(0.5)  # [rad]
# Robust losses on each pose's squared weighted residual norm (see IdentificationProblem.robustified).
ROBUST_LOSSES = ("soft_l1", "cauchy", "huber")


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
    coef = np.where(
        small, 1.0 / 12.0, 1.0 / ths**2 - (1.0 + np.cos(ths)) / (2.0 * ths * np.sin(ths))
    )
    return phi, np.eye(3) + 0.5 * K + coef[:, None, None] * (K @ K)


class IdentificationProblem:
    """Weighted residuals (eq. (23)) and their Jacobian for a set of (record, frame) poses.

    Args:
        chart: Parameter chart (:class:`Parametrization`) centred on a model; ``x`` below are its
            coordinates, shape (P,) [m]/[rad] (``x = 0`` is the centre model).
        q: Joint readings [rad]/[m], shape (N, n) in ``structure.joint_names`` order.
        poses: Frame name -> measured ``T_world_<frame>``, shape (N, 4, 4) (at least the chart's
            frames).
        use: Frame name -> which records' poses take part, shape (N,) booleans.
        sigma_t: Standard deviation of each measured translation entry [m].
        sigma_r: Standard deviation of the measured rotation error's angle [rad] (Fig. 10).

    Attributes:
        frames: The chart's frames with at least one used pose, in chart order.
        rows: Frame -> indices of its used records, shape (n_f,).
        n_poses: Used poses over all frames; there are ``6 * n_poses`` residuals.
        loss: ``"linear"`` (plain weighted least squares) or a robust loss of
            :data:`ROBUST_LOSSES` (see :meth:`robustified`).
        scale: Robust loss scale on the per-pose weighted residual norm [-].
    """

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

    def robustified(self, loss: str, scale: float) -> IdentificationProblem:
        """This problem with a robust loss on each pose's squared weighted residual.

        Args:
            loss: One of :data:`ROBUST_LOSSES`.
            scale: Weighted residual norm of a pose [-] where the loss turns from quadratic to
                robust.
        """
        if loss not in ROBUST_LOSSES:
            raise ValueError(f"robust loss must be one of {sorted(ROBUST_LOSSES)}, got {loss!r}")
        other = copy.copy(self)
        other.loss, other.scale = loss, scale
        return other

    def _predict(self, x: Array) -> dict[str, Array]:
        model = self.chart.model_from_vector(x)
        return model.fk(self.q, self.frames)

    def residual_blocks(self, x: Array) -> dict[str, tuple[Array, Array]]:
        """Unweighted ``(p_meas - p_pred, log(R_meas R_pred^T))`` per frame, each (n_f, 3) [m], [rad]."""
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
        """Weighted residuals at chart coordinates ``x`` (P,), shape (6 * n_poses,) [-].

        Per pose: 3 translation then 3 rotation entries, frames in :attr:`frames` order. With a
        robust loss, each pose's block is scaled so that the sum of squares is the loss.
        """
        try:
            r = self._weighted(x)
        except DegenerateDataError:  # a trial step left the chart: make the solver reject it
            return np.full(6 * self.n_poses, 1e6)
        if self.loss == "linear":
            return r
        g, _ = _robust_gain(self.loss, (r.reshape(-1, 6) ** 2).sum(1) / self.scale**2)
        return (r.reshape(-1, 6) * g[:, None]).ravel()

    def jacobian(self, x: Array) -> Array:
        """Jacobian of :meth:`residuals` at ``x``, shape (6 * n_poses, P) [1/m] or [1/rad]."""
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
        Jb = (
            g[:, None, None] * Jb
            + (2.0 * dg / self.scale**2)[:, None, None] * r[:, :, None] * rJ[:, None, :]
        )
        return Jb.reshape(-1, self.chart.n_params)

    def pose_p_values(self, x: Array) -> dict[str, Array]:
        """Per used pose, the probability that a good measurement is this far off, per frame.

        Fig. 10's noise makes ``|dp|^2 / sigma_t^2`` chi-square(3) and ``|angle| / sigma_r``
        half-normal (the angle is N(0, sigma_r), its axis uniform), so each part has its own
        exact test; the pose's p-value is twice the smaller one (Bonferroni).

        Returns:
            Frame -> p-values, shape (n_f,), in :attr:`rows` order.
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


__all__ = ["DEFAULT_SIGMA_R", "DEFAULT_SIGMA_T", "ROBUST_LOSSES", "IdentificationProblem"]
