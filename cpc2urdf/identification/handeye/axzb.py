"""Simultaneous robot-world and hand-eye calibration ``A X = Z B`` (Li, Wang & Wu 2010).

Conventions as in :mod:`cpc2urdf.identification.handeye.axxb`: ``A_k = T_base_hand[k]``,
``B_k = inv(T_camera_target[k]) = T_target_camera[k]``, unknowns ``X = T_hand_camera`` and
``Z = T_base_target``, so ``A_k X = Z B_k = T_base_camera[k]``.

Solvers:

- ``kronecker``: Li et al. eq. (19), one linear least-squares problem for ``vec(R_X)``,
  ``vec(R_Z)``, ``t_X``, ``t_Z``; rotations then projected onto SO(3) by SVD (polar). Eqs. (15),
  (17)-(19) as printed carry typos; what is implemented, with row-major ``vec``
  (``vec(M A N) = (M kron N^T) vec(A)``, Li's Definition 1 lists ``a11, a12, ...``):
  ``R_A R_X = R_Z R_B`` (eq. (15) prints ``R_B R_Z``), so
  ``(R_A kron I) x - (I kron R_B^T) z = 0`` (17), and ``R_A t_X + t_A = R_Z t_B + t_Z`` (16) as
  ``(I kron t_B^T) z - R_A t_X + t_Z = t_A`` (eq. (18) prints ``vec(R_X)`` where eq. (19) rightly
  has ``z``). Same as OpenCV's ``CALIB_ROBOT_WORLD_HAND_EYE_LI``.
- ``dual_quaternion``: Li et al. eqs. (9)-(14): ``a x = z b`` and ``a' x + a x' = z b' + z' b``,
  i.e. ``[L(a), 0, -R(b), 0; L(a'), L(a), -R(b'), -R(b)] [x; x'; z; z'] = 0`` (eq. (12) prints
  ``+b~``; the signs must be minus as in eq. (11)). Its null space is two-dimensional (the solution
  and its ``eps`` multiple ``(0, x, 0, z)``); eq. (14b) must read ``= 0`` (unit dual quaternion:
  ``x . x' = 0``), as (14d) does. The quaternion signs of A and B must agree across poses, which
  the paper does not discuss; see :func:`align_quaternion_signs`.
- ``zhuang``: the two-stage quaternion method of Zhuang, Roth & Sudhakar (1994) as Li et al.
  describe it: rotations first from ``a x = z b``, eliminating ``x_0`` with the scalar equation
  (which divides by ``a_0``: the rotation angle of every A must stay away from 180 deg), solved
  here as a homogeneous least-squares problem (so Z's rotation may be anything); translations
  afterwards by least squares from ``R_A t_X - t_Z = R_Z t_B - t_A``.
- ``refined``: Kronecker start, then a joint nonlinear least-squares refinement of X and Z
  (:func:`refine`).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from cpc2urdf.errors import DegenerateDataError
from cpc2urdf.identification.handeye.axxb import null_space_combination
from cpc2urdf.transforms import (
    Array,
    dual_quat_from_transform,
    homogeneous,
    inverse,
    project_to_rotation,
    quat_left_matrix,
    quat_right_matrix,
    quat_wxyz_from_matrix,
    transform_from_dual_quat,
)

# Zhuang's elimination divides by a_0 = cos(theta_A / 2): refuse A rotations closer than this to
# 180 deg, warn within NEAR_180_WARN.
NEAR_180_REFUSE = math.radians(1.0)
NEAR_180_WARN = math.radians(10.0)
# Weight of rotation residuals in the joint refinement [m/rad]: 1 mrad counts as 0.1 mm, about
# the ratio of Li et al.'s noise levels (1 mm : 0.5 deg).
ROTATION_SCALE = 0.1
# align_quaternion_signs: a maximum spanning tree over all poses up to this many (O(N^3)), hubs beyond.
SIGN_HUBS = 32


def rotation_rows(RA: Array, RB: Array) -> Array:
    """Li et al. eq. (17) per pose, ``[R_A kron I, -I kron R_B^T]`` acting on ``[vec R_X; vec R_Z]``
    (row-major vec): ``R_A R_X - R_Z R_B`` as 9 rows; shape (N, 9, 18)."""
    n, I3 = len(RA), np.eye(3)
    M = np.empty((n, 9, 18))
    M[:, :, :9] = np.einsum("kac,bd->kabcd", RA, I3).reshape(n, 9, 9)
    M[:, :, 9:] = -np.einsum("ac,kdb->kabcd", I3, RB).reshape(n, 9, 9)
    return M


def solve_kronecker(A: Array, B: Array, length_unit: float = 1.0) -> tuple[Array, Array]:
    """Li et al. eq. (19): returns ``(X, Z)``; A, B absolute, shape (N, 4, 4) [m].

    The least squares mixes 9 dimensionless rotation rows with 3 translation rows per pose, so
    its noisy solution depends on the length unit: ``length_unit`` [m] is the unit the
    translations are expressed in while solving (1.0: metres, as OpenCV; 1e-3: millimetres,
    which weights the translation rows 1000 times more). Noise-free data is solved exactly
    either way.
    """
    if length_unit != 1.0:
        S = np.diag([1.0 / length_unit] * 3 + [1.0])
        Si = np.diag([length_unit] * 3 + [1.0])
        Xs, Zs = solve_kronecker(S @ A @ Si, S @ B @ Si)
        return Si @ Xs @ S, Si @ Zs @ S
    n = len(A)
    I3 = np.eye(3)
    RA, tA, RB, tB = A[:, :3, :3], A[:, :3, 3], B[:, :3, :3], B[:, :3, 3]
    M = np.zeros((n, 12, 24))  # 12 rows per pose, built for all poses at once
    M[:, :9, :18] = rotation_rows(RA, RB)
    M[:, 9:, 9:18] = np.einsum("ac,kd->kacd", I3, tB).reshape(n, 3, 9)  # eq. (18): I kron tB^T
    M[:, 9:, 18:21] = -RA
    M[:, 9:, 21:24] = I3
    rhs = np.zeros((n, 12))
    rhs[:, 9:] = tA
    w = np.linalg.lstsq(M.reshape(12 * n, 24), rhs.reshape(-1), rcond=None)[0]
    R_X = project_to_rotation(w[0:9].reshape(3, 3))
    R_Z = project_to_rotation(w[9:18].reshape(3, 3))
    return homogeneous(R_X, w[18:21]), homogeneous(R_Z, w[21:24])


def align_quaternion_signs(qa: Array, qb: Array, hubs: int = SIGN_HUBS) -> tuple[Array, Array]:
    """Choose signs so that ``a_i x = z b_i`` holds with one sign for all poses.

    Scalar parts of ``a_i a_j^*`` and ``b_i b_j^*`` are equal (conjugate rotations), i.e.
    ``a_i . a_j = b_i . b_j``; a pose is aligned against an aligned pose j with a large
    ``|a_i . a_j|`` (avoids pairs 180 deg apart, where the sign is lost in the noise). Up to
    ``hubs`` poses: each against the already aligned pose with the largest ``|a_i . a_j|`` (a
    maximum spanning tree). Beyond, in O(N hubs) time and O(N) memory: ``hubs`` poses spread over
    the rotations (farthest-point: each next one the pose least similar to those chosen) are
    aligned that way among themselves, then every other pose against the hub of largest
    ``|a_i . a_j|`` (with 32 hubs that is above ~0.7 whatever the rotations). Shapes (N, 4) each.
    """
    qa, qb = qa.copy(), qb.copy()
    n = len(qa)
    if n > hubs:
        chosen = [0]
        near = np.abs(qa @ qa[0])  # |a_i . a_hub| of the most similar hub so far
        for _ in range(hubs - 1):
            chosen.append(int(np.argmin(near)))
            near = np.maximum(near, np.abs(qa @ qa[chosen[-1]]))
        H = np.array(chosen)
        qa[H], qb[H] = align_quaternion_signs(qa[H], qb[H], hubs)
        dots = qa @ qa[H].T  # (N, hubs)
        best = H[np.argmax(np.abs(dots), axis=1)]
        flip_a = np.einsum("ki,ki->k", qa, qa[best]) < 0
        flip_b = np.einsum("ki,ki->k", qb, qb[best]) < 0
        return np.where(flip_a[:, None], -qa, qa), np.where(flip_b[:, None], -qb, qb)
    done = [0]
    todo = list(range(1, n))
    while todo:
        dots = np.abs(qa[todo] @ qa[done].T)
        t, d = np.unravel_index(np.argmax(dots), dots.shape)
        i, j = todo.pop(int(t)), done[int(d)]
        if qa[i] @ qa[j] < 0:
            qa[i] = -qa[i]
        if qb[i] @ qb[j] < 0:
            qb[i] = -qb[i]
        done.append(i)
    return qa, qb


def solve_dual_quaternion(A: Array, B: Array) -> tuple[Array, Array]:
    """Li et al. eqs. (9)-(14): returns ``(X, Z)``; A, B absolute, shape (N, 4, 4)."""
    a, ad = dual_quat_from_transform(A)
    b, bd = dual_quat_from_transform(B)
    qa, qb = align_quaternion_signs(a, b)
    sa = np.where(np.einsum("ki,ki->k", qa, a) > 0, 1.0, -1.0)[:, None]
    sb = np.where(np.einsum("ki,ki->k", qb, b) > 0, 1.0, -1.0)[:, None]
    La = quat_left_matrix(sa * a)
    Lad = quat_left_matrix(sa * ad)
    Rb = quat_right_matrix(sb * b)
    Rbd = quat_right_matrix(sb * bd)
    S = np.zeros((len(A), 8, 16))  # eq. (12) with the signs of eq. (11), all poses at once
    S[:, :4, 0:4] = La
    S[:, :4, 8:12] = -Rb
    S[:, 4:, 0:4] = Lad
    S[:, 4:, 4:8] = La
    S[:, 4:, 8:12] = -Rbd
    S[:, 4:, 12:16] = -Rb
    _, _, Vt = np.linalg.svd(S.reshape(-1, 16), full_matrices=False)
    v1, v2 = Vt[-1], Vt[-2]  # eq. (13): the two right singular vectors of (near) zero
    lam = null_space_combination(
        [(v1[0:4], v2[0:4], v1[4:8], v2[4:8]), (v1[8:12], v2[8:12], v1[12:16], v2[12:16])]
    )  # eqs. (14a)-(14d)
    v = lam[0] * v1 + lam[1] * v2
    return transform_from_dual_quat(v[0:4], v[4:8]), transform_from_dual_quat(v[8:12], v[12:16])


def zhuang_a0_check(A: Array) -> list[str]:
    """Refuse or warn about hand rotations near 180 deg (Zhuang's method divides by ``a_0``)."""
    ang = 2.0 * np.arccos(np.clip(quat_wxyz_from_matrix(A[:, :3, :3])[:, 0], -1.0, 1.0))
    bad = np.flatnonzero(ang > math.pi - NEAR_180_REFUSE)
    if bad.size:
        raise DegenerateDataError(
            f"quaternion method (zhuang): hand poses {bad.tolist()} rotate by "
            f"{math.degrees(float(ang[bad[0]])):.2f} deg, within {math.degrees(NEAR_180_REFUSE):g} deg of "
            "180 deg, where its elimination divides by cos(theta/2) ~ 0; use kronecker or dual_quaternion"
        )
    weak = np.flatnonzero(ang > math.pi - NEAR_180_WARN)
    if weak.size:
        return [
            f"quaternion method (zhuang): hand poses {weak.tolist()} rotate within "
            f"{math.degrees(NEAR_180_WARN):g} deg of 180 deg; their equations are amplified by 1/cos(theta/2)"
        ]
    return []


def solve_zhuang(A: Array, B: Array) -> tuple[Array, Array]:
    """Zhuang et al.'s two-stage quaternion method: returns ``(X, Z)``; shape (N, 4, 4) each."""
    qa, qb = align_quaternion_signs(
        quat_wxyz_from_matrix(A[:, :3, :3]), quat_wxyz_from_matrix(B[:, :3, :3])
    )
    G, r0s, a0s = [], [], []
    for a, b in zip(qa, qb, strict=True):
        M = np.hstack(
            [quat_left_matrix(a), -quat_right_matrix(b)]
        )  # a x - z b = 0, unknowns [x0..3, z0..3]
        others = M[:, 1:]  # [x1..3, z0..3]
        # scalar row: a0 x0 + others[0] u = 0  ->  x0 = -others[0] u / a0, into the vector rows
        G.append(others[1:] - np.outer(M[1:, 0], others[0]) / a[0])
        r0s.append(others[0])
        a0s.append(a[0])
    _, _, Vt = np.linalg.svd(np.concatenate(G), full_matrices=False)
    u = Vt[-1]
    a0 = np.array(a0s)
    x0 = -float(a0 @ (np.array(r0s) @ u)) / float(a0 @ a0)  # least squares over the poses
    x = np.concatenate([[x0], u[:3]])
    z = u[3:]
    to_R = lambda q: Rotation.from_quat([q[1], q[2], q[3], q[0]]).as_matrix()  # noqa: E731
    R_X, R_Z = to_R(x / np.linalg.norm(x)), to_R(z / np.linalg.norm(z))
    # stage 2: R_A t_X - t_Z = R_Z t_B - t_A
    n = len(A)
    M = np.zeros((3 * n, 6))
    rhs = np.zeros(3 * n)
    for k in range(n):
        M[3 * k : 3 * k + 3, :3] = A[k, :3, :3]
        M[3 * k : 3 * k + 3, 3:] = -np.eye(3)
        rhs[3 * k : 3 * k + 3] = R_Z @ B[k, :3, 3] - A[k, :3, 3]
    t = np.linalg.lstsq(M, rhs, rcond=None)[0]
    return homogeneous(R_X, t[:3]), homogeneous(R_Z, t[3:])


def refine(
    A: Array, B: Array, X0: Array, Z0: Array, rotation_scale: float = ROTATION_SCALE
) -> tuple[Array, Array]:
    """Joint nonlinear least squares over X and Z from a start ``(X0, Z0)``.

    Minimises, over all poses, ``|p(A_k X) - p(Z B_k)|^2 + (s |log((A_k X)^-1 Z B_k)|)^2`` with
    ``s = rotation_scale`` [m/rad] (scipy ``least_squares``, Levenberg-Marquardt). X and Z are
    updated as ``X0 exp(dx)``, so rotations stay rotations.
    """

    def unpack(p: Array) -> tuple[Array, Array]:
        dX = homogeneous(Rotation.from_rotvec(p[0:3]).as_matrix(), p[3:6])
        dZ = homogeneous(Rotation.from_rotvec(p[6:9]).as_matrix(), p[9:12])
        return X0 @ dX, Z0 @ dZ

    def fun(p: Array) -> Array:
        X, Z = unpack(p)
        AX = A @ X
        ZB = Z @ B
        D = inverse(AX) @ ZB
        rot = Rotation.from_matrix(D[:, :3, :3]).as_rotvec() * rotation_scale
        return np.concatenate([(AX[:, :3, 3] - ZB[:, :3, 3]).ravel(), rot.ravel()])

    sol = least_squares(fun, np.zeros(12), method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)
    return unpack(sol.x)


def solve_refined(A: Array, B: Array) -> tuple[Array, Array]:
    """Kronecker start (:func:`solve_kronecker`), then :func:`refine`: returns ``(X, Z)``; A, B
    absolute, shape (N, 4, 4)."""
    X0, Z0 = solve_kronecker(A, B)
    return refine(A, B, X0, Z0)


__all__ = [
    "NEAR_180_REFUSE",
    "NEAR_180_WARN",
    "ROTATION_SCALE",
    "SIGN_HUBS",
    "align_quaternion_signs",
    "refine",
    "rotation_rows",
    "solve_dual_quaternion",
    "solve_kronecker",
    "solve_refined",
    "solve_zhuang",
    "zhuang_a0_check",
]
