"""Homogeneous transforms and the CPC rotation of eq. (4).

Conventions used across the package:

- ``T_a_b`` is the pose of frame ``b`` in frame ``a``: a (4, 4) matrix mapping b-coordinates to
  a-coordinates, as Pinocchio's ``aMb``. ``T_world_plate = T_world_base @ T_base_plate``.
- Points and directions carry their frame: ``p_world``, ``axis_base``.
- SI units: metres and radians.

Functions that take an angle also accept an array of angles of shape (N,) and then return a
stack of shape (N, 4, 4): forward kinematics is vectorised over configurations this way.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]


def rot_z(theta: ArrayLike) -> Array:
    """``Rot(z, theta)`` of eq. (2).

    Args:
        theta: Angle [rad], scalar or shape (N,).

    Returns:
        Shape (4, 4), or (N, 4, 4) for an array of angles.
    """
    t = np.asarray(theta, dtype=float)
    c, s = np.cos(t), np.sin(t)
    T = np.zeros(t.shape + (4, 4))
    T[..., 0, 0] = c
    T[..., 0, 1] = -s
    T[..., 1, 0] = s
    T[..., 1, 1] = c
    T[..., 2, 2] = 1.0
    T[..., 3, 3] = 1.0
    return T


def rot_x(alpha: ArrayLike) -> Array:
    """``Rot(x, alpha)``, shape (4, 4) or (N, 4, 4); ``alpha`` in [rad]."""
    t = np.asarray(alpha, dtype=float)
    c, s = np.cos(t), np.sin(t)
    T = np.zeros(t.shape + (4, 4))
    T[..., 0, 0] = 1.0
    T[..., 1, 1] = c
    T[..., 1, 2] = -s
    T[..., 2, 1] = s
    T[..., 2, 2] = c
    T[..., 3, 3] = 1.0
    return T


def trans(xyz: ArrayLike) -> Array:
    """``Trans(l)`` of eq. (2).

    Args:
        xyz: Translation [m], shape (3,) or (N, 3).

    Returns:
        Shape (4, 4) or (N, 4, 4).
    """
    v = np.asarray(xyz, dtype=float)
    T = np.zeros(v.shape[:-1] + (4, 4))
    T[..., 0, 0] = T[..., 1, 1] = T[..., 2, 2] = T[..., 3, 3] = 1.0
    T[..., :3, 3] = v
    return T


def trans_z(d: ArrayLike) -> Array:
    """``Trans(0, 0, d)`` of eq. (6); ``d`` [m] scalar or shape (N,)."""
    t = np.asarray(d, dtype=float)
    T = np.zeros(t.shape + (4, 4))
    T[..., 0, 0] = T[..., 1, 1] = T[..., 2, 2] = T[..., 3, 3] = 1.0
    T[..., 2, 3] = t
    return T


def homogeneous(R: ArrayLike, p: ArrayLike) -> Array:
    """Stack a rotation (3, 3) and a translation (3,) [m] into a (4, 4) transform."""
    T = np.eye(4)
    T[:3, :3] = np.asarray(R, dtype=float)
    T[:3, 3] = np.asarray(p, dtype=float)
    return T


def inverse(T: ArrayLike) -> Array:
    """Inverse of a rigid transform, shape (..., 4, 4), without a general matrix inverse."""
    T = np.asarray(T, dtype=float)
    R = T[..., :3, :3]
    Rt = np.swapaxes(R, -1, -2)
    out = np.zeros_like(T)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", Rt, T[..., :3, 3])
    out[..., 3, 3] = 1.0
    return out


# Below this value of 1 + b_z, eq. (4) loses precision (it divides by 1 + b_z); we switch to the
# equivalent axis-angle form. Exactly b = -z is the CPC singularity: the axis k of eq. (4) is then
# undefined and we fix it to x, so the transform is still exact (the parametrisation is merely
# not continuous there).
_BZ_SWITCH = 1e-6


def cpc_rotation(b: ArrayLike) -> Array:
    """The CPC rotation ``R_i`` of eq. (4): maps z onto the unit vector ``b``.

    ``R(b) = Rot(k, phi)`` with ``k = z x b / |z x b|`` and ``phi = acos(b_z)``. Eq. (4) is used
    as printed for ``b_z > -1 + 1e-6``; closer to ``b = -z`` the equivalent Rodrigues form is
    used (eq. (4) divides by ``1 + b_z``).

    Args:
        b: Unit axis ``[b_x, b_y, b_z]``, shape (3,).

    Returns:
        Rotation matrix, shape (3, 3).
    """
    bx, by, bz = (float(v) for v in np.asarray(b, dtype=float))
    if 1.0 + bz > _BZ_SWITCH:
        c = 1.0 + bz
        return np.array(
            [
                [1.0 - bx * bx / c, -bx * by / c, bx],
                [-bx * by / c, 1.0 - by * by / c, by],
                [-bx, -by, bz],
            ]
        )
    s = math.hypot(bx, by)
    kx, ky = (-by / s, bx / s) if s > 1e-15 else (1.0, 0.0)  # k = z x b / |z x b|
    phi = math.atan2(s, bz)
    K = np.array([[0.0, 0.0, ky], [0.0, 0.0, -kx], [-ky, kx, 0.0]])
    return np.eye(3) + math.sin(phi) * K + (1.0 - math.cos(phi)) * (K @ K)


def rotation_z(angle: float) -> Array:
    """3x3 rotation about z by ``angle`` [rad] (eq. (24))."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def matrix_from_rpy(rpy: ArrayLike) -> Array:
    """URDF convention: ``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)``; ``rpy`` [rad], shape (3,)."""
    r, p, y = (float(v) for v in np.asarray(rpy, dtype=float))
    cr, sr, cp, sp, cy, sy = (
        math.cos(r),
        math.sin(r),
        math.cos(p),
        math.sin(p),
        math.cos(y),
        math.sin(y),
    )
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def rpy_from_matrix(R: ArrayLike) -> Array:
    """Inverse of :func:`matrix_from_rpy`, exact to rounding even near pitch = ±90°.

    Pitch and yaw are read off the first column; roll is then solved from
    ``Ry(p)^T Rz(y)^T R``, so any rounding in yaw (ill-conditioned at gimbal lock) is absorbed by
    roll and the reconstructed matrix still matches to ~1e-16.

    Returns:
        ``[roll, pitch, yaw]`` [rad].
    """
    R = np.asarray(R, dtype=float)
    pitch = math.atan2(-R[2, 0], math.hypot(R[0, 0], R[1, 0]))
    yaw = math.atan2(R[1, 0], R[0, 0]) if math.hypot(R[0, 0], R[1, 0]) > 1e-300 else 0.0
    cy, sy, cp, sp = math.cos(yaw), math.sin(yaw), math.cos(pitch), math.sin(pitch)
    Rz_t = np.array([[cy, sy, 0.0], [-sy, cy, 0.0], [0.0, 0.0, 1.0]])
    Ry_t = np.array([[cp, 0.0, -sp], [0.0, 1.0, 0.0], [sp, 0.0, cp]])
    Rx = Ry_t @ Rz_t @ R
    roll = math.atan2(Rx[2, 1], Rx[1, 1])
    return np.array([roll, pitch, yaw])


def rotation_error(R_a: ArrayLike, R_b: ArrayLike) -> Array:
    """Angle [rad] of ``R_a^T R_b``, shape (...,), robust for tiny and large angles."""
    R_a = np.asarray(R_a, dtype=float)
    R_b = np.asarray(R_b, dtype=float)
    D = np.swapaxes(R_a, -1, -2) @ R_b
    # atan2(|skew|, trace part) keeps full precision near 0 and near pi.
    w = np.stack(
        [D[..., 2, 1] - D[..., 1, 2], D[..., 0, 2] - D[..., 2, 0], D[..., 1, 0] - D[..., 0, 1]],
        axis=-1,
    )
    s = 0.5 * np.linalg.norm(w, axis=-1)
    c = 0.5 * (np.trace(D, axis1=-2, axis2=-1) - 1.0)
    return np.arctan2(s, c)


def rotvec_from_matrix(R: Array) -> Array:
    """Rotation vectors of rotation matrices (N, 3, 3) -> (N, 3) [rad].

    ``theta = atan2(|v|, (tr R - 1) / 2)`` with ``v = vee(R - R^T) / 2 = sin(theta) n``: exact and
    fast (the gate's fits evaluate it thousands of times); within 1e-3 rad of 180 deg, where ``v``
    loses the axis, scipy's quaternion route.
    """
    v = 0.5 * np.stack(
        [R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0], R[:, 1, 0] - R[:, 0, 1]], axis=-1
    )
    s = np.linalg.norm(v, axis=-1)
    c = 0.5 * (np.trace(R, axis1=-2, axis2=-1) - 1.0)
    theta = np.arctan2(s, c)
    out = v * np.where(s > 1e-300, theta / np.where(s > 1e-300, s, 1.0), 1.0)[:, None]
    near_pi = theta > np.pi - 1e-3
    if np.any(near_pi):
        from scipy.spatial.transform import Rotation

        out[near_pi] = Rotation.from_matrix(R[near_pi]).as_rotvec()
    return out


def matrix_from_rotvec(r: Array) -> Array:
    """Rodrigues' formula for one rotation vector (3,) [rad] -> (3, 3)."""
    theta = float(np.linalg.norm(r))
    K = skew(r)
    if theta < 1e-8:
        return np.eye(3) + K + 0.5 * K @ K
    return np.eye(3) + math.sin(theta) / theta * K + (1.0 - math.cos(theta)) / theta**2 * K @ K


def project_to_rotation(M: ArrayLike) -> Array:
    """Nearest rotation matrix to ``M`` in the Frobenius norm (polar decomposition via SVD)."""
    U, _, Vt = np.linalg.svd(np.asarray(M, dtype=float))
    D = np.eye(3)
    D[2, 2] = np.sign(np.linalg.det(U @ Vt)) or 1.0
    return U @ D @ Vt


def rotation_defect(R: ArrayLike) -> float:
    """Largest entry of ``|R^T R - I|`` plus ``|det R - 1|``: 0 for an exact rotation."""
    R = np.asarray(R, dtype=float)
    return float(np.max(np.abs(R.T @ R - np.eye(3))) + abs(np.linalg.det(R) - 1.0))


# ---- quaternions and dual quaternions -------------------------------------------------------------
# Scalar-first unit quaternions ``[w, x, y, z]`` (Hamilton product), as in Li et al. 2010 and
# Daniilidis 1999; scipy's ``Rotation.as_quat`` is scalar-last.


def skew(v: ArrayLike) -> Array:
    """The cross-product matrix ``[v]_x`` of a 3-vector: ``skew(v) @ u == cross(v, u)``; vectors
    (..., 3) -> (..., 3, 3)."""
    v = np.asarray(v, dtype=float)
    S = np.zeros((*v.shape[:-1], 3, 3))
    S[..., 0, 1], S[..., 0, 2], S[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    S[..., 1, 0], S[..., 2, 0], S[..., 2, 1] = v[..., 2], -v[..., 1], v[..., 0]
    return S


def quat_wxyz_from_matrix(R: ArrayLike) -> Array:
    """Unit quaternions ``[w, x, y, z]`` of rotations (..., 3, 3) with ``w >= 0``, shape (..., 4)."""
    from scipy.spatial.transform import Rotation

    q = Rotation.from_matrix(R).as_quat()  # x, y, z, w
    q = np.concatenate([q[..., 3:], q[..., :3]], axis=-1)
    return np.where(q[..., :1] < 0, -q, q)


def _quat_matrix(q: ArrayLike, sign: float) -> Array:
    q = np.asarray(q, dtype=float)
    w, v = q[..., 0], q[..., 1:]
    M = np.empty((*q.shape[:-1], 4, 4))
    M[..., 0, 0], M[..., 0, 1:], M[..., 1:, 0] = w, -v, v
    M[..., 1:, 1:] = w[..., None, None] * np.eye(3) + sign * skew(v)
    return M


def quat_left_matrix(q: ArrayLike) -> Array:
    """Matrix of ``p -> q p`` for a quaternion ``q = [w, x, y, z]`` (Li et al.'s ``a~``);
    quaternions (..., 4) -> (..., 4, 4)."""
    return _quat_matrix(q, 1.0)


def quat_right_matrix(q: ArrayLike) -> Array:
    """Matrix of ``p -> p q`` for a quaternion ``q = [w, x, y, z]`` (Li et al.'s ``b~``);
    quaternions (..., 4) -> (..., 4, 4)."""
    return _quat_matrix(q, -1.0)


def quat_multiply(p: ArrayLike, q: ArrayLike) -> Array:
    """Hamilton product ``p q`` of quaternions ``[w, x, y, z]``, shape (4,)."""
    return quat_left_matrix(p) @ np.asarray(q, dtype=float)


def dual_quat_from_transform(T: ArrayLike) -> tuple[Array, Array]:
    """Unit dual quaternion ``q + eps q'`` of a rigid transform: ``q' = 1/2 (0, t) q``.

    Returns:
        ``(q, q')``, each ``[w, x, y, z]``, with ``w >= 0``; transforms (..., 4, 4) -> (..., 4)
        each; ``t`` in [m].
    """
    T = np.asarray(T, dtype=float)
    q = quat_wxyz_from_matrix(T[..., :3, :3])
    t = np.concatenate([np.zeros((*T.shape[:-2], 1)), T[..., :3, 3]], axis=-1)
    return q, 0.5 * np.einsum("...ij,...j->...i", quat_left_matrix(t), q)


def transform_from_dual_quat(q: ArrayLike, qd: ArrayLike) -> Array:
    """Inverse of :func:`dual_quat_from_transform` (``t = 2 q' q*``); ``q`` normalised first.

    The dual part is made orthogonal to the real part (a unit dual quaternion has
    ``q . q' = 0``) before the translation is read off. Returns shape (4, 4).
    """
    from scipy.spatial.transform import Rotation

    q = np.asarray(q, dtype=float)
    qd = np.asarray(qd, dtype=float)
    n = float(np.linalg.norm(q))
    q, qd = q / n, qd / n
    qd = qd - (q @ qd) * q  # unit dual quaternion: q . q' = 0
    R = Rotation.from_quat([q[1], q[2], q[3], q[0]]).as_matrix()
    t = 2.0 * quat_multiply(qd, np.array([q[0], -q[1], -q[2], -q[3]]))[1:]
    return homogeneous(R, t)


__all__ = [
    "Array",
    "cpc_rotation",
    "dual_quat_from_transform",
    "homogeneous",
    "inverse",
    "matrix_from_rotvec",
    "matrix_from_rpy",
    "project_to_rotation",
    "quat_left_matrix",
    "quat_multiply",
    "quat_right_matrix",
    "quat_wxyz_from_matrix",
    "rot_x",
    "rot_z",
    "rotation_defect",
    "rotation_error",
    "rotation_z",
    "rotvec_from_matrix",
    "rpy_from_matrix",
    "skew",
    "trans",
    "trans_z",
    "transform_from_dual_quat",
]
