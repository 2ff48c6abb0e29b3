"""The pointing residual of the solved cameras and its Jacobian (compiled).

Per solved camera ``r = u - e_z`` with ``u`` the unit target direction in the camera frame,
``p_cam = R^T (p - o)``; ``|r| = 2 sin(err / 2)``. With the camera's world twist ``(v, w)``:
``d p_cam = R^T ((p - o) x w - v)`` and ``d u = (I - u u^T) d p_cam / |p_cam|``. ``d u`` lies in the
plane orthogonal to ``u``, so the Jacobian is kept in a basis ``t1, t2`` of that plane
(:func:`_tangent`): two rows per camera, ``J_t = T^T d p_cam / |p_cam|``, with the residual's own
part there, ``r_t = T^T r``. Every product the step takes is the same as with three rows
(``J^T J = J_t^T J_t``, ``J^T r = J_t^T r_t``), and ``J_x J_x^T`` of a redundant head is
``2S x 2S`` instead of ``3S x 3S``.
"""

from __future__ import annotations

import math

import numpy as np

from cpc2urdf.validation.gaze.kernels._jit import hot_kernel, kernel
from cpc2urdf.validation.gaze.kernels.constants import MIN_TARGET_DISTANCE
from cpc2urdf.validation.gaze.kernels.kinematics import _fk_scalars, camera_jacobian

# ``want_jac`` as numpy bools, not Python's: numba types a Python bool argument as a literal and
# compiles the helpers once per value (their call sites are inlined, so the branch goes either way)
WITH_JACOBIAN, RESIDUAL_ONLY = np.bool_(True), np.bool_(False)


@hot_kernel
def _tangent(ux, uy, uz):  # type: ignore[no-untyped-def]
    """Two unit vectors ``t1, t2`` (6 scalars) that complete the unit direction ``u`` to an
    orthonormal basis: the rotation taking ``e_z`` to ``u`` (``-e_z`` when ``u_z < -1/2``: the
    first is singular at ``u = -e_z``) applied to ``e_x`` and ``e_y``, ``R = I + [k] + [k]^2 / (1 +
    a . u)``, ``k = a x u``. Continuous in ``u`` on either side, so a warm-started decomposition of
    ``J_x J_x^T`` stays warm from step to step. ``u = 0`` (a target on the camera centre): ``e_x,
    e_y``. The side is read from ``u_z - 1`` as the residual holds it, so that
    :func:`_tangent_residual` (which has only the residual) takes the same side at every double."""
    if uz - 1.0 >= -1.5:
        c = 1.0 / (1.0 + uz)
        return 1.0 - ux * ux * c, -ux * uy * c, -ux, -ux * uy * c, 1.0 - uy * uy * c, -uy
    c = 1.0 / (1.0 - uz)
    return 1.0 - ux * ux * c, -ux * uy * c, ux, -ux * uy * c, 1.0 - uy * uy * c, uy


@hot_kernel
def _tangent_residual(r, s):  # type: ignore[no-untyped-def]
    """``r_t = T^T r_s`` (2 scalars) of solved camera ``s`` from its residual ``r_s = u - e_z``
    (``r[3 s:3 s + 3]``): the part of ``r`` the Jacobian's rows see. In the bases of
    :func:`_tangent` it is ``(u_x, u_y)``, and ``(-u_x, -u_y)`` on the side ``u_z < -1/2``."""
    if r[3 * s + 2] >= -1.5:  # the side _tangent takes (from the same double)
        return r[3 * s], r[3 * s + 1]
    return -r[3 * s], -r[3 * s + 1]


@hot_kernel
def _gradient_entry(J, r, v):  # type: ignore[no-untyped-def]
    """``(J^T r)_v``, unknown ``v``'s entry of the pointing error's gradient ``J_t^T r_t``."""
    gv = 0.0
    for c in range(J.shape[0] // 2):
        rt1, rt2 = _tangent_residual(r, c)
        gv += J[2 * c, v] * rt1 + J[2 * c + 1, v] * rt2
    return gv


@hot_kernel
def _residual_hot(ch, u, b, p, r, J, want_jac, ws):  # type: ignore[no-untyped-def]
    """Pointing residual ``r`` (3 S,) of the solved cameras at ``u`` for target ``p`` (world), its
    Jacobian ``J`` (2 S, m) by ``u`` in each camera's tangent basis when ``want_jac``, and each
    solved camera's view of the target in ``ws.Pc`` (S, 5 + m): ``p_cam``, ``|p_cam|``, and with the
    Jacobian (columns 4 on, left as they are by a trial's evaluation) ``|p_cam|`` again and its
    gradient by ``u``. Returns ``|r|^2``."""
    _fk_scalars(ch, u, b, ws.JR, ws.Jp, ws.Ja, ws.CR, ws.Co)
    return residual_at_fk(ch, p, r, J, want_jac, ws)


@kernel
def residual(ch, u, b, p, r, J, want_jac, JR, Jp, Ja, CR, Co, Jc, Pc):  # type: ignore[no-untyped-def]
    """:func:`_residual_hot` for Python and the cold callers, on the kinematics buffers given
    one by one (a workspace's first seven)."""
    _fk_scalars(ch, u, b, JR, Jp, Ja, CR, Co)
    return _residual_from(ch, p, r, J, want_jac, Jp, Ja, CR, Co, Jc, Pc)


@hot_kernel
def residual_at_fk(ch, p, r, J, want_jac, ws):  # type: ignore[no-untyped-def]
    """:func:`_residual_hot` on the kinematics already in the workspace (the last FK): an accepted
    trial step's configuration is not evaluated twice."""
    return _residual_from(ch, p, r, J, want_jac, ws.Jp, ws.Ja, ws.CR, ws.Co, ws.Jc, ws.Pc)


@hot_kernel
def _residual_from(ch, p, r, J, want_jac, Jp, Ja, CR, Co, Jc, Pc):  # type: ignore[no-untyped-def]
    """The residual, Jacobian and views of :func:`_residual_hot` from the FK's buffers."""
    A, solve_cams = ch.A, ch.solve_cameras
    S = solve_cams.shape[0]
    K = A.shape[0]
    m = A.shape[1]
    rr = 0.0
    for s in range(S):
        c = solve_cams[s]
        dx, dy, dz = p[0] - Co[c, 0], p[1] - Co[c, 1], p[2] - Co[c, 2]
        x = CR[c, 0, 0] * dx + CR[c, 1, 0] * dy + CR[c, 2, 0] * dz
        y = CR[c, 0, 1] * dx + CR[c, 1, 1] * dy + CR[c, 2, 1] * dz
        z = CR[c, 0, 2] * dx + CR[c, 1, 2] * dy + CR[c, 2, 2] * dz
        nrm = math.sqrt(x * x + y * y + z * z)
        Pc[s, 0], Pc[s, 1], Pc[s, 2], Pc[s, 3] = x, y, z, nrm
        if nrm >= MIN_TARGET_DISTANCE:
            inv = 1.0 / nrm
            ux, uy, uz = x * inv, y * inv, z * inv
        else:  # on the camera centre: no direction (missed by pi), no gradient from this eye
            inv, ux, uy, uz = 0.0, 0.0, 0.0, 0.0
        r[3 * s], r[3 * s + 1], r[3 * s + 2] = ux, uy, uz - 1.0
        rr += ux * ux + uy * uy + (uz - 1.0) * (uz - 1.0)
        if not want_jac:
            continue
        camera_jacobian(ch, c, Jp, Ja, CR, Co, Jc)
        t1x, t1y, t1z, t2x, t2y, t2z = _tangent(ux, uy, uz)
        for v in range(m):
            J[2 * s, v] = 0.0
            J[2 * s + 1, v] = 0.0
            Pc[s, 5 + v] = 0.0
        Pc[s, 4] = nrm
        for k in range(K):
            # d(p - o) x w - v in world, then R^T: d p_cam; its tangent part T^T d p_cam / |p_cam|
            # is T^T d r (d r = (I - u u^T) d p_cam / |p_cam| and I - u u^T = T T^T)
            wx, wy, wz = Jc[3, k], Jc[4, k], Jc[5, k]
            ex = dy * wz - dz * wy - Jc[0, k]
            ey = dz * wx - dx * wz - Jc[1, k]
            ez = dx * wy - dy * wx - Jc[2, k]
            gx = CR[c, 0, 0] * ex + CR[c, 1, 0] * ey + CR[c, 2, 0] * ez
            gy = CR[c, 0, 1] * ex + CR[c, 1, 1] * ey + CR[c, 2, 1] * ez
            gz = CR[c, 0, 2] * ex + CR[c, 1, 2] * ey + CR[c, 2, 2] * ez
            d = ux * gx + uy * gy + uz * gz  # d |p_cam|
            h1 = (t1x * gx + t1y * gy + t1z * gz) * inv
            h2 = (t2x * gx + t2y * gy + t2z * gz) * inv
            for v in range(m):
                a = A[k, v]
                if a != 0.0:
                    J[2 * s, v] += h1 * a
                    J[2 * s + 1, v] += h2 * a
                    Pc[s, 5 + v] += d * a
    return rr
