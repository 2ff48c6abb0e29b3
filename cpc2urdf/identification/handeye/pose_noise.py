"""The noise of hand-eye poses, as a pose file states it, and what it means for the residuals.

A ``cpc2urdf/handeye-poses@1`` file may state the noise of its two pose streams (in the file's
units; standard deviations per axis)::

    "noise": {"T_base_hand":     {"position": 0.05, "angle": 0.01},
              "T_camera_target": {"position": 0.3,  "angle": 0.05}}

Model: every pose ``T = (R, p)`` of a stream is the true pose with ``p' = p + dp`` and
``R' = Exp(dr) R``, ``dp ~ N(0, position^2 I)``, ``dr ~ N(0, angle^2 I)`` (a rotation about the
pose's own origin), independent between poses and streams.

:func:`residual_covariance` propagates it to first order to the residual of pose k of
``A_k X = Z B_k`` (``A_k = T_base_hand[k]``, ``B_k = inv(T_camera_target[k])``): the camera position
predicted by the hand minus the one predicted by the target, and the rotation vector of
``R(Z B_k) R(A_k X)^T``, both in the base frame. Rotation noise of the hand moves the predicted
camera position by its lever arm ``R_A t_X``; rotation noise of the target pose moves it by the
camera-target distance ``|t_C|``, which is why solvePnP's small angle errors dominate the position
residuals of stage 2.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.stats import chi2

from cpc2urdf.files.jsonio import finite_float
from cpc2urdf.files.units import Units
from cpc2urdf.transforms import Array, skew

NOISE_STREAMS = ("T_base_hand", "T_camera_target")
_NOISE_KEYS = ("position", "angle")


@dataclass(frozen=True)
class PoseNoise:
    """Stated noise of the hand and camera pose streams (standard deviation per axis, SI).

    Attributes:
        hand_position: Of each ``T_base_hand`` translation component [m].
        hand_angle: Of each ``T_base_hand`` rotation about an axis [rad].
        camera_position: Of each ``T_camera_target`` translation component [m].
        camera_angle: Of each ``T_camera_target`` rotation about an axis [rad].
        camera_angle_per_metre: Camera angle noise that grows with the camera-target distance
            ``d`` [rad/m]: the angle noise of pose k is ``sqrt(camera_angle^2 + (this * d_k)^2)``
            (solvePnP's: the target subtends less of the image further away). Only estimated
            noise has it (the file states ``camera_angle``).
    """

    hand_position: float
    hand_angle: float
    camera_position: float
    camera_angle: float
    camera_angle_per_metre: float = 0.0

    def __post_init__(self) -> None:
        values = (
            self.hand_position,
            self.hand_angle,
            self.camera_position,
            self.camera_angle,
            self.camera_angle_per_metre,
        )
        if not all(np.isfinite(v) and v >= 0.0 for v in values):
            raise ValueError(f"noise standard deviations must be finite and >= 0, got {values}")
        angle = self.hand_angle + self.camera_angle + self.camera_angle_per_metre
        if self.hand_position + self.camera_position <= 0.0 or angle <= 0.0:
            raise ValueError(
                "noise: the position and the angle noise must each be > 0 in at least one stream "
                "(noise-free poses cannot be tested against a statement)"
            )

    @classmethod
    def from_json(cls, obj: Any, units: Units, where: str = "noise") -> PoseNoise:
        """Parse the ``noise`` section (values in ``units``: length for position, angle for angle).

        Raises:
            ValueError: Naming ``where`` and the field: not an object, unknown or missing keys,
                a value that is not a finite number >= 0.
        """
        if not isinstance(obj, Mapping):
            raise ValueError(f"{where} must be an object with {list(NOISE_STREAMS)}, got {obj!r}")
        if set(obj) != set(NOISE_STREAMS):
            raise ValueError(
                f"{where} must have exactly the keys {list(NOISE_STREAMS)}, got {sorted(obj)}"
            )
        values: dict[str, float] = {}
        for stream in NOISE_STREAMS:
            s = obj[stream]
            if not isinstance(s, Mapping) or set(s) != set(_NOISE_KEYS):
                raise ValueError(
                    f"{where}.{stream} must be {{'position': std, 'angle': std}}, got {s!r}"
                )
            for key in _NOISE_KEYS:
                v = finite_float(s[key], f"{where}.{stream}.{key}")
                if v < 0.0:
                    raise ValueError(
                        f"{where}.{stream}.{key} must be >= 0 (a standard deviation), got {v}"
                    )
                values[f"{stream}.{key}"] = v * (units.length if key == "position" else units.angle)
        try:
            return cls(
                values["T_base_hand.position"],
                values["T_base_hand.angle"],
                values["T_camera_target.position"],
                values["T_camera_target.angle"],
            )
        except ValueError as e:
            raise ValueError(f"{where}: {str(e).removeprefix('noise: ')}") from e

    def to_json(self, units: Units | None = None) -> dict[str, Any]:
        """The ``noise`` section in ``units`` (default SI)."""
        u = units or Units()
        return {
            "T_base_hand": {
                "position": self.hand_position / u.length,
                "angle": self.hand_angle / u.angle,
            },
            "T_camera_target": {
                "position": self.camera_position / u.length,
                "angle": self.camera_angle / u.angle,
            },
        }


def _noise_jacobian(T_base_hand: Array, T_camera_target: Array, X: Array, Z: Array) -> Array:
    """``d[e_t; e_r] / d[da, dalpha, dc, dgamma]`` per pose: shape (N, 6, 12)."""
    n = len(T_base_hand)
    u = T_base_hand[:, :3, :3] @ X[:3, 3]
    t_C = T_camera_target[:, :3, 3]
    M = Z[:3, :3][None] @ np.swapaxes(T_camera_target[:, :3, :3], -1, -2)
    eye = np.broadcast_to(np.eye(3), (n, 3, 3))
    J = np.zeros((n, 6, 12))
    J[:, :3, 0:3] = eye
    J[:, :3, 3:6] = -skew(u)
    J[:, :3, 6:9] = M
    J[:, :3, 9:12] = M @ skew(t_C)
    J[:, 3:, 3:6] = -eye
    J[:, 3:, 9:12] = -M
    return J


def _covariance_terms(T_base_hand: Array, T_camera_target: Array, X: Array, Z: Array) -> Array:
    """The residual covariance per unit variance of each noise source: shape (4, N, 6, 6) for
    hand position, hand angle, camera position, camera angle."""
    J = _noise_jacobian(T_base_hand, T_camera_target, X, Z)
    return np.stack(
        [
            np.einsum("nij,nkj->nik", J[..., 3 * i : 3 * i + 3], J[..., 3 * i : 3 * i + 3])
            for i in range(4)
        ]
    )


def residual_covariance(
    noise: PoseNoise, T_base_hand: Array, T_camera_target: Array, X: Array, Z: Array
) -> Array:
    """First-order covariance of each pose's residual ``[e_t; e_r]`` under ``noise``.

    With ``u = R_A t_X`` (hand-to-camera lever arm, base frame) and ``M = R_Z R_C^T`` (camera frame
    to base), the hand noise ``(da, dalpha)`` and camera noise ``(dc, dgamma)`` enter as::

        e_t = da - [u]_x dalpha + M dc + M [t_C]_x dgamma      (camera position, base frame)
        e_r = -dalpha - M dgamma                               (rotation vector, base frame)

    Args:
        noise: The stated noise.
        T_base_hand, T_camera_target: Poses, shape (N, 4, 4) [m].
        X, Z: The solution ``T_hand_camera``, ``T_base_target``, shape (4, 4) [m].

    Returns:
        Shape (N, 6, 6): rows/columns position [m] then rotation [rad].
    """
    v = (
        np.array([noise.hand_position, noise.hand_angle, noise.camera_position, noise.camera_angle])
        ** 2
    )
    terms = _covariance_terms(T_base_hand, T_camera_target, X, Z)
    S = np.einsum("i,injk->njk", v, terms)
    if noise.camera_angle_per_metre > 0.0:
        d2 = np.sum(T_camera_target[:, :3, 3] ** 2, axis=-1)
        S = S + noise.camera_angle_per_metre**2 * d2[:, None, None] * terms[3]
    # rounding can leave a zero-noise direction a hair below zero: keep S positive definite
    floor = 1e-12 * np.trace(S, axis1=1, axis2=2) + 1e-30
    return S + floor[:, None, None] * np.eye(6)


# Floors of an estimated noise (noise-free data has none): residuals below are rounding.
MIN_POSITION_NOISE = 1e-9  # [m]
MIN_ANGLE_NOISE = 1e-9  # [rad]
# Residuals this far out (chi-square, 6 dof) are left out of the noise estimate (gross outliers).
_TRIM_QUANTILE = 1e-3


def estimate_noise(
    T_base_hand: Array, T_camera_target: Array, X: Array, Z: Array, e: Array, dof: int
) -> PoseNoise:
    """Maximum-likelihood noise from the residuals of a fit, robust to a few gross outliers.

    Four variances are estimated (the two position noises enter the residuals identically, so
    only their sum is determined): position noise (given to the camera stream), hand angle noise
    (lever arm ``|R_A t_X|``), camera angle noise (lever arm ``|t_C|``, the camera-target distance)
    and camera angle noise proportional to that distance (solvePnP: a target further away subtends
    fewer pixels, so the camera's position error in the target frame grows as ``|t_C|^2``). The
    Gaussian likelihood ``sum_k log det S_k + e_k^T S_k^-1 e_k`` is minimised over the variances by
    Fisher scoring; then again on the best-fitting three quarters of the poses, scaled to the median
    of all, and once more on every pose within the 99.9 % chi-square quantile of that (so gross
    outliers neither inflate the estimate nor hide themselves); finally the variances are scaled by
    ``6 N / dof`` for the degrees of freedom the fit used.

    Args:
        T_base_hand, T_camera_target: Poses, shape (N, 4, 4) [m].
        X, Z: The fit, shape (4, 4) [m].
        e: Its residuals ``[e_t, e_r]``, shape (N, 6) [m, rad].
        dof: Residual degrees of freedom of the fit (``6 N - 12``).
    """
    terms = _covariance_terms(T_base_hand, T_camera_target, X, Z)
    d2 = np.sum(T_camera_target[:, :3, 3] ** 2, axis=-1)[:, None, None]
    # position, hand angle, camera angle, camera angle growing with the distance (solvePnP)
    K = np.stack(
        [terms[2], terms[1], terms[3], d2 * terms[3]]
    )  # terms[0] == terms[2] (both isotropic)
    floor = np.array(
        [MIN_POSITION_NOISE**2, MIN_ANGLE_NOISE**2, MIN_ANGLE_NOISE**2, MIN_ANGLE_NOISE**2]
    )

    def nll(v: Array, Kk: Array, ek: Array) -> float:
        S = np.einsum("i,injk->njk", v, Kk)
        sign, logdet = np.linalg.slogdet(S)
        if not np.all(sign > 0) or not np.all(np.isfinite(logdet)):
            return math.inf  # not a covariance: never a step's answer
        return float(
            np.sum(logdet) + np.einsum("nj,nj->", ek, np.linalg.solve(S, ek[..., None])[..., 0])
        )

    def fit(keep: NDArray[np.intp], v: Array) -> Array:
        # Fisher scoring for variance components, with step halving (the likelihood never rises).
        Kk, ek = K[:, keep], e[keep]
        v = np.maximum(v, floor)
        f = nll(v, Kk, ek)
        for _ in range(50):
            S = np.einsum("i,injk->njk", v, Kk)
            if not np.all(np.isfinite(S)) or np.any(np.linalg.det(S) <= 0.0):
                break  # a variance left the finite, positive range: keep the last good one
            Si = np.linalg.inv(S)
            SK = np.einsum("njk,inkl->injl", Si, Kk)  # S^-1 K_i
            a = np.einsum("njk,nk->nj", Si, ek)
            g = 0.5 * (np.einsum("nj,injk,nk->i", a, Kk, a) - np.einsum("injj->i", SK))
            F = 0.5 * np.einsum("injk,mnkj->im", SK, SK)
            step = np.linalg.lstsq(F, g, rcond=None)[0]
            for _ in range(12):
                v_new = np.maximum(v + step, floor)
                f_new = nll(v_new, Kk, ek)
                if f_new <= f + 1e-12 * abs(f):
                    break
                step = 0.5 * step
            else:
                break
            done = np.all(np.abs(v_new - v) <= 1e-4 * v) or f - f_new <= 1e-6
            v, f = v_new, f_new
            if done:
                break
        return v

    def scores(v: Array) -> Array:  # e_k^T S_k^-1 e_k
        return np.einsum("nj,njk,nk->n", e, np.linalg.inv(np.einsum("i,injk->njk", v, K)), e)

    ms_t = float(np.mean(e[:, :3] ** 2)) + MIN_POSITION_NOISE**2
    ms_r = float(np.mean(e[:, 3:] ** 2)) + MIN_ANGLE_NOISE**2
    n = len(e)
    v = fit(np.arange(n), np.array([ms_t, ms_r / 3, ms_r / 3, ms_r / 3]))
    # Robust to gross outliers (which would inflate the estimate and hide themselves): refit on the
    # best-fitting three quarters, scale that to the median of all poses, then refit on every pose
    # within the chi-square quantile.
    best = np.argsort(scores(v))[: max(math.ceil(0.75 * n), min(n, 4))]
    v = fit(np.sort(best), v)
    v = v * float(np.median(scores(v))) / (float(chi2.median(6)) * max(dof, 1) / (6.0 * n))
    keep = np.flatnonzero(scores(v) <= chi2.isf(_TRIM_QUANTILE, 6))
    if len(keep) >= min(n, 4):
        v = fit(keep, v)
    v = v * 6.0 * len(e) / max(dof, 1)
    return PoseNoise(
        0.0, float(np.sqrt(v[1])), float(np.sqrt(v[0])), float(np.sqrt(v[2])), float(np.sqrt(v[3]))
    )


__all__ = [
    "MIN_ANGLE_NOISE",
    "MIN_POSITION_NOISE",
    "NOISE_STREAMS",
    "PoseNoise",
    "estimate_noise",
    "residual_covariance",
]
