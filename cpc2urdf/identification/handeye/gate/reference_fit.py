"""The consistency gate's own solution of ``A X = Z B``: a quick fit and a weighted refinement.

The gate judges the *data*, not a solver, so it solves for itself, the same way whatever solver
the user chose:

- :func:`quick_fit`: Park-Martin on every pair of poses, then Z as the chordal mean (milliseconds;
  used to compare the data as given with each repaired version of it);
- :func:`weighted_fit`: Levenberg-Marquardt over X and Z of the whitened residuals (the stated
  noise, or one estimated from the residuals by
  :func:`~cpc2urdf.identification.handeye.pose_noise.estimate_noise`, propagated by
  :func:`~cpc2urdf.identification.handeye.pose_noise.residual_covariance`), with the Jacobian at the
  solution for the leverage of every pose (:func:`leverage_blocks`).

Residual of pose k (as :func:`~cpc2urdf.identification.handeye.axxb.residuals`, as vectors):
``e_t`` = camera position predicted by the hand, ``p(A_k X)``, minus the one predicted by the
target, ``p(Z B_k)`` [m]; ``e_r`` = rotation vector of ``R(Z B_k) R(A_k X)^T`` [rad]; both in the
base frame.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from cpc2urdf.identification.handeye.axxb import relative_motions, solve_park_martin, target_from_x
from cpc2urdf.identification.handeye.pose_noise import (
    PoseNoise,
    estimate_noise,
    residual_covariance,
)
from cpc2urdf.transforms import (
    Array,
    homogeneous,
    inverse,
    matrix_from_rotvec,
    rotvec_from_matrix,
)

# Residuals below these are rounding, not noise: floors of every level the gate compares.
NUMERIC_POSITION = 1e-9  # [m]
NUMERIC_ANGLE = 1e-9  # [rad]


def residual_vectors(
    T_base_hand: Array, T_camera_target: Array, X: Array, Z: Array
) -> tuple[Array, Array]:
    """``(e_t, e_r)`` of every pose, each shape (N, 3): position [m], rotation vector [rad]."""
    P = T_base_hand @ X
    Q = Z @ inverse(T_camera_target)
    e_t = P[:, :3, 3] - Q[:, :3, 3]
    e_r = rotvec_from_matrix(Q[:, :3, :3] @ np.swapaxes(P[:, :3, :3], -1, -2))
    return e_t, e_r


def quick_fit(T_base_hand: Array, T_camera_target: Array) -> tuple[Array, Array]:
    """``(X, Z)`` by Park-Martin (over :func:`~cpc2urdf.identification.handeye.axxb.motion_pairs`) and the chordal mean; shapes (4, 4)."""
    A, B = relative_motions(T_base_hand, T_camera_target)
    X = solve_park_martin(A, B)
    return X, target_from_x(T_base_hand, T_camera_target, X)


@dataclass(frozen=True)
class WeightedFit:
    """A weighted least-squares solution and what the gate's statistics need.

    Attributes:
        X, Z: ``T_hand_camera``, ``T_base_target``, shape (4, 4) [m].
        e_t, e_r: Raw residuals, shape (N, 3) each [m], [rad].
        w: Whitened residuals, shape (N, 6): unit variance per component under ``noise``.
        jac: Jacobian of ``w.ravel()`` with respect to the 12 parameters of X and Z, shape (6N, 12).
        noise: The noise the weights come from (stated, or estimated from these residuals).
        estimated: Whether ``noise`` was estimated.
    """

    X: Array
    Z: Array
    e_t: Array
    e_r: Array
    w: Array
    jac: Array
    noise: PoseNoise
    estimated: bool

    @property
    def chi2(self) -> float:
        """Sum of squared whitened residuals."""
        return float(np.sum(self.w**2))


def whitening(
    noise: PoseNoise, T_base_hand: Array, T_camera_target: Array, X: Array, Z: Array
) -> Array:
    """``L_k^-1`` with ``L_k L_k^T`` the residual covariance of pose k: shape (N, 6, 6)."""
    L = np.linalg.cholesky(residual_covariance(noise, T_base_hand, T_camera_target, X, Z))
    return np.linalg.inv(L)


def _update(T0: Array, p: Array) -> Array:
    return T0 @ homogeneous(matrix_from_rotvec(p[:3]), p[3:6])


def _weights(
    T_base_hand: Array, T_camera_target: Array, X: Array, Z: Array, noise: PoseNoise
) -> Callable[[Array, Array], Array]:
    """``(e_t, e_r) -> w`` (N, 6), with weights fixed at ``(X, Z)``."""
    W = whitening(noise, T_base_hand, T_camera_target, X, Z)
    return lambda e_t, e_r: np.einsum("nij,nj->ni", W, np.concatenate([e_t, e_r], axis=-1))


def _objective(
    T_base_hand: Array,
    T_camera_target: Array,
    X0: Array,
    Z0: Array,
    weigh: Callable[[Array, Array], Array],
) -> Callable[[Array], Array]:
    """Whitened residuals (6N,) as a function of ``p`` (12,): ``X = X0 exp(p[:6])``, ``Z = Z0 exp(p[6:])``."""

    def fun(p: Array) -> Array:
        e_t, e_r = residual_vectors(
            T_base_hand, T_camera_target, _update(X0, p[:6]), _update(Z0, p[6:])
        )
        return weigh(e_t, e_r).ravel()

    return fun


def jacobian(fun: Callable[[Array], Array], p: Array, step: float = 1e-7) -> Array:
    """Central-difference Jacobian of ``fun`` at ``p``: shape (len(fun(p)), len(p))."""
    cols = []
    for i in range(len(p)):
        dp = np.zeros_like(p)
        dp[i] = step
        cols.append((fun(p + dp) - fun(p - dp)) / (2.0 * step))
    return np.stack(cols, axis=-1)


def whitened(
    T_base_hand: Array, T_camera_target: Array, X: Array, Z: Array, noise: PoseNoise
) -> tuple[Array, Array]:
    """Whitened residuals (N, 6) at ``(X, Z)`` and their Jacobian (6N, 12) with respect to
    ``X exp(dx)``, ``Z exp(dz)`` (weights from ``noise`` at ``(X, Z)``)."""
    fun = _objective(
        T_base_hand, T_camera_target, X, Z, _weights(T_base_hand, T_camera_target, X, Z, noise)
    )
    p0 = np.zeros(12)
    return fun(p0).reshape(-1, 6), jacobian(fun, p0)


def weighted_fit(
    T_base_hand: Array,
    T_camera_target: Array,
    noise: PoseNoise | None,
    start: tuple[Array, Array] | None = None,
    robust: bool = False,
) -> WeightedFit:
    """The gate's reference solution: two passes of weighted LM (weights from the previous pass).

    Args:
        T_base_hand, T_camera_target: Poses, shape (N, 4, 4) [m].
        noise: Stated noise, or None: estimated before each pass from the residuals of the
            previous one (:func:`~cpc2urdf.identification.handeye.pose_noise.estimate_noise`).
        start: ``(X, Z)`` to start from; default :func:`quick_fit`.
        robust: Minimise a Cauchy loss of the whitened residuals (scale 3) instead of their squares,
            so that gross outliers do not drag the solution (and the noise estimate) with them.
    """
    X, Z = start if start is not None else quick_fit(T_base_hand, T_camera_target)
    dof = 6 * len(T_base_hand) - 12
    used = noise
    for _ in range(2):
        if noise is None:
            e_t, e_r = residual_vectors(T_base_hand, T_camera_target, X, Z)
            used = estimate_noise(
                T_base_hand, T_camera_target, X, Z, np.concatenate([e_t, e_r], axis=-1), dof
            )
        assert used is not None
        fun = _objective(
            T_base_hand, T_camera_target, X, Z, _weights(T_base_hand, T_camera_target, X, Z, used)
        )
        if robust:  # Cauchy loss on the whitened residuals: gross outliers barely pull the fit
            sol = least_squares(
                fun,
                np.zeros(12),
                method="trf",
                loss="cauchy",
                f_scale=3.0,
                xtol=1e-12,
                ftol=1e-12,
                gtol=1e-12,
            )
        else:
            sol = least_squares(fun, np.zeros(12), method="lm", xtol=1e-12, ftol=1e-12, gtol=1e-12)
        X, Z = _update(X, sol.x[:6]), _update(Z, sol.x[6:])
    assert used is not None
    e_t, e_r = residual_vectors(T_base_hand, T_camera_target, X, Z)
    w, J = whitened(T_base_hand, T_camera_target, X, Z, used)
    return WeightedFit(X, Z, e_t, e_r, w, J, used, noise is None)


def leverage_blocks(jac: Array, rows: int = 6) -> Array:
    """Diagonal blocks of the hat matrix ``J (J^T J)^+ J^T``, one per pose: shape (N, rows, rows)."""
    G = np.linalg.pinv(jac.T @ jac)
    Jk = jac.reshape(-1, rows, jac.shape[1])
    return np.einsum("nij,jk,nlk->nil", Jk, G, Jk)


__all__ = [
    "NUMERIC_ANGLE",
    "NUMERIC_POSITION",
    "WeightedFit",
    "jacobian",
    "leverage_blocks",
    "quick_fit",
    "residual_vectors",
    "weighted_fit",
    "whitened",
    "whitening",
]
