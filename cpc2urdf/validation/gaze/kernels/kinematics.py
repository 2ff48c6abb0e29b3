"""Forward kinematics of a head chain and its cameras' world Jacobians (compiled).

Everything works on the flat arrays of :class:`~cpc2urdf.validation.gaze.chain.HeadChain`,
gathered in a :class:`Chain` (:func:`pack`). Unknowns ``u`` (shape (m,)); chain readings
``q = A u + b``.

Kinematics (as Pinocchio): ``T_world_j = T_world_parent * placement_j * M_j(q_j)`` with ``M_j`` a
rotation by ``q_j`` about ``axis_j`` (Rodrigues) or a translation ``q_j axis_j``;
``T_world_cam = T_world_parent * placement_cam``. The world axis of joint ``j`` is
``a_j = R_world_j axis_j``; a revolute joint moves a camera centre ``o`` by ``a_j x (o - p_j)`` and
turns it by ``a_j``, a prismatic one moves it by ``a_j``.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np

from cpc2urdf.transforms import Array
from cpc2urdf.validation.gaze.chain import HeadChain
from cpc2urdf.validation.gaze.kernels._jit import hot_kernel, kernel
from cpc2urdf.validation.gaze.kernels.constants import MIN_TARGET_DISTANCE

#: The head as the kernels take it. Per chain joint (K): ``parent`` index (-1: the world),
#: ``jtype`` (0 revolute, 1 prismatic), ``axis`` (K, 3), placement ``R`` (K, 3, 3) and ``t``
#: (K, 3); readings ``q = A u + b`` (``A`` (K, m), ``b`` (K,)); per camera (C): ``cam_parent``,
#: ``cam_R``, ``cam_t``; ``anc`` (C, K): whether joint k moves camera c; ``solve_cameras`` (S,): the
#: solved axes; the policy's zero-version row ``version_row`` (m,; zeros: none) and ``tasks``
#: (4,): its weight, ``c . home``, the minimum viewing distance [m] and the null cut near fixation.
Chain = namedtuple(
    "Chain",
    "parent jtype axis R t A b cam_parent cam_R cam_t anc solve_cameras version_row tasks",
)
TASK_WEIGHT, TASK_VERSION_REF, TASK_MIN_DISTANCE, TASK_NEAR_NULL = (
    0,
    1,
    2,
    3,
)  # indices into Chain.tasks


def pack(
    chain: HeadChain,
    version_row: Array | None = None,
    version_weight: float = 0.0,
    min_distance: float = 0.0,
) -> Chain:
    """The chain's arrays as the :class:`Chain` the kernels take, with the policy's secondary tasks:
    the zero-version task's row ``c`` over the unknowns (None: none) and its weight, the minimum
    viewing distance [m] the policy phase keeps each solved camera from the target (0: none), and the
    null cut near a fixating posture (0 here: ``null_rel`` there too; ``CompiledGaze`` sets
    :data:`~.constants.BINOCULAR_NULL` on two eyes with a structural null direction)."""
    c = np.zeros(chain.m) if version_row is None else np.ascontiguousarray(version_row, dtype=float)
    home = 0.5 * (chain.lower + chain.upper)
    weight = float(version_weight) if version_row is not None else 0.0
    tasks = np.array([weight, float(c @ home), float(min_distance), 0.0])
    return Chain(
        chain.parent,
        chain.jtype,
        chain.axis,
        chain.R,
        chain.t,
        chain.A,
        chain.b,
        chain.cam_parent,
        chain.cam_R,
        chain.cam_t,
        np.ascontiguousarray(chain.anc, dtype=np.int64),
        chain.solve_cameras,
        c,
        tasks,
    )


@hot_kernel
def _fk_scalars(ch, u, b, JR, Jp, Ja, CR, Co):  # type: ignore[no-untyped-def]
    """:func:`fk`'s arithmetic, inlined into the residual (the solve's hot path)."""
    parent, jtype, axis, R, t, A = ch.parent, ch.jtype, ch.axis, ch.R, ch.t, ch.A
    K = parent.shape[0]
    m = u.shape[0]
    for k in range(K):
        q = b[k]
        for v in range(m):
            q += A[k, v] * u[v]
        pk = parent[k]
        if pk >= 0:
            p00, p01, p02 = JR[pk, 0, 0], JR[pk, 0, 1], JR[pk, 0, 2]
            p10, p11, p12 = JR[pk, 1, 0], JR[pk, 1, 1], JR[pk, 1, 2]
            p20, p21, p22 = JR[pk, 2, 0], JR[pk, 2, 1], JR[pk, 2, 2]
            ox, oy, oz = Jp[pk, 0], Jp[pk, 1], Jp[pk, 2]
        else:
            p00, p01, p02, p10, p11, p12, p20, p21, p22 = (
                1.0,
                0.0,
                0.0,
                0.0,
                1.0,
                0.0,
                0.0,
                0.0,
                1.0,
            )
            ox, oy, oz = 0.0, 0.0, 0.0
        tx, ty, tz = t[k, 0], t[k, 1], t[k, 2]
        px = ox + p00 * tx + p01 * ty + p02 * tz
        py = oy + p10 * tx + p11 * ty + p12 * tz
        pz = oz + p20 * tx + p21 * ty + p22 * tz
        # M0 = Rparent * R[k]
        q00 = p00 * R[k, 0, 0] + p01 * R[k, 1, 0] + p02 * R[k, 2, 0]
        q01 = p00 * R[k, 0, 1] + p01 * R[k, 1, 1] + p02 * R[k, 2, 1]
        q02 = p00 * R[k, 0, 2] + p01 * R[k, 1, 2] + p02 * R[k, 2, 2]
        q10 = p10 * R[k, 0, 0] + p11 * R[k, 1, 0] + p12 * R[k, 2, 0]
        q11 = p10 * R[k, 0, 1] + p11 * R[k, 1, 1] + p12 * R[k, 2, 1]
        q12 = p10 * R[k, 0, 2] + p11 * R[k, 1, 2] + p12 * R[k, 2, 2]
        q20 = p20 * R[k, 0, 0] + p21 * R[k, 1, 0] + p22 * R[k, 2, 0]
        q21 = p20 * R[k, 0, 1] + p21 * R[k, 1, 1] + p22 * R[k, 2, 1]
        q22 = p20 * R[k, 0, 2] + p21 * R[k, 1, 2] + p22 * R[k, 2, 2]
        ax, ay, az = axis[k, 0], axis[k, 1], axis[k, 2]
        wx = q00 * ax + q01 * ay + q02 * az
        wy = q10 * ax + q11 * ay + q12 * az
        wz = q20 * ax + q21 * ay + q22 * az
        Ja[k, 0], Ja[k, 1], Ja[k, 2] = wx, wy, wz
        if jtype[k] == 0:
            c, s = math.cos(q), math.sin(q)
            C1 = 1.0 - c
            r00 = c + ax * ax * C1
            r01 = ax * ay * C1 - az * s
            r02 = ax * az * C1 + ay * s
            r10 = ay * ax * C1 + az * s
            r11 = c + ay * ay * C1
            r12 = ay * az * C1 - ax * s
            r20 = az * ax * C1 - ay * s
            r21 = az * ay * C1 + ax * s
            r22 = c + az * az * C1
            JR[k, 0, 0] = q00 * r00 + q01 * r10 + q02 * r20
            JR[k, 0, 1] = q00 * r01 + q01 * r11 + q02 * r21
            JR[k, 0, 2] = q00 * r02 + q01 * r12 + q02 * r22
            JR[k, 1, 0] = q10 * r00 + q11 * r10 + q12 * r20
            JR[k, 1, 1] = q10 * r01 + q11 * r11 + q12 * r21
            JR[k, 1, 2] = q10 * r02 + q11 * r12 + q12 * r22
            JR[k, 2, 0] = q20 * r00 + q21 * r10 + q22 * r20
            JR[k, 2, 1] = q20 * r01 + q21 * r11 + q22 * r21
            JR[k, 2, 2] = q20 * r02 + q21 * r12 + q22 * r22
        else:
            JR[k, 0, 0], JR[k, 0, 1], JR[k, 0, 2] = q00, q01, q02
            JR[k, 1, 0], JR[k, 1, 1], JR[k, 1, 2] = q10, q11, q12
            JR[k, 2, 0], JR[k, 2, 1], JR[k, 2, 2] = q20, q21, q22
            px += q * wx
            py += q * wy
            pz += q * wz
        Jp[k, 0], Jp[k, 1], Jp[k, 2] = px, py, pz
    _cameras_at(ch, JR, Jp, CR, Co)


@hot_kernel
def _cameras_at(ch, JR, Jp, CR, Co):  # type: ignore[no-untyped-def]
    """Every camera's world rotation ``CR`` and centre ``Co`` from its parent joint's pose."""
    cam_parent, cam_R, cam_t = ch.cam_parent, ch.cam_R, ch.cam_t
    for c in range(cam_parent.shape[0]):
        pk = cam_parent[c]
        for i in range(3):
            for j in range(3):
                s = 0.0
                for l in range(3):
                    s += (JR[pk, i, l] if pk >= 0 else (1.0 if i == l else 0.0)) * cam_R[c, l, j]
                CR[c, i, j] = s
            s = 0.0
            for l in range(3):
                s += (JR[pk, i, l] if pk >= 0 else (1.0 if i == l else 0.0)) * cam_t[c, l]
            Co[c, i] = s + (Jp[pk, i] if pk >= 0 else 0.0)


@kernel
def fk(ch, u, b, JR, Jp, Ja, CR, Co):  # type: ignore[no-untyped-def]
    """World rotation ``JR`` (K, 3, 3), origin ``Jp`` (K, 3) and axis ``Ja`` (K, 3) of every chain
    joint, and rotation ``CR`` (C, 3, 3) and centre ``Co`` (C, 3) of every camera, at unknowns ``u``
    (chain readings ``A u + b``; ``b`` given per solve). Written out in scalars (3x3 products
    unrolled, no temporaries): the trigonometry is most of its cost."""
    _fk_scalars(ch, u, b, JR, Jp, Ja, CR, Co)


@hot_kernel
def camera_jacobian(ch, c, Jp, Ja, CR, Co, Jc):  # type: ignore[no-untyped-def]
    """World Jacobian ``Jc`` (6, K) of camera ``c`` by the chain readings: rows (v, w)."""
    jtype, anc = ch.jtype, ch.anc
    K = jtype.shape[0]
    for k in range(K):
        if not anc[c, k]:
            for i in range(6):
                Jc[i, k] = 0.0
            continue
        ax, ay, az = Ja[k, 0], Ja[k, 1], Ja[k, 2]
        if jtype[k] == 0:
            dx, dy, dz = Co[c, 0] - Jp[k, 0], Co[c, 1] - Jp[k, 1], Co[c, 2] - Jp[k, 2]
            Jc[0, k] = ay * dz - az * dy
            Jc[1, k] = az * dx - ax * dz
            Jc[2, k] = ax * dy - ay * dx
            Jc[3, k], Jc[4, k], Jc[5, k] = ax, ay, az
        else:
            Jc[0, k], Jc[1, k], Jc[2, k] = ax, ay, az
            Jc[3, k], Jc[4, k], Jc[5, k] = 0.0, 0.0, 0.0


@kernel
def pointing_error(x, y, z):  # type: ignore[no-untyped-def]
    """Angle [rad] between the optical axis and a target at ``(x, y, z)`` in the camera frame
    (scaled first: no overflow for any finite coordinates); pi on the centre."""
    big = max(abs(x), abs(y), abs(z))
    if big == 0.0 or not big < np.inf:
        return math.pi if big == 0.0 else math.atan2(math.hypot(x, y), z)
    if big < MIN_TARGET_DISTANCE:
        return math.pi
    x, y, z = x / big, y / big, z / big
    return math.atan2(math.sqrt(x * x + y * y), z)
