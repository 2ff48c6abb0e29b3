"""One step of the gaze iteration: task priority, Levenberg-Marquardt (compiled).

The unknowns are scaled by the square root of the policy's weights (``x = sw u``), so the secondary
task is ``|x - x_ref|^2 / 2``. With ``J^T J = V diag(l) V^T`` over the free unknowns, the pointing
task moves along the eigen-directions with ``l > cut`` (``-v (v . J^T r) / (l + mu)``, ``mu =
DAMPING |r|^2``) and the policy along the others (``-gain v v^T (x - x_ref)``), the near-null space
of the pointing error; ``cut`` is ``null_rel`` of the largest eigenvalue (:func:`_null_cut`). With a
zero-version row ``c`` (the nominal binocular head's cyclopean policy) the null move is the Newton
step of ``|x - x_ref|^2 / 2 + w (c . (u - home))^2 / 2`` over the null directions (Sherman-Morrison,
``w`` large: the version is held at zero). With more free unknowns than residual rows (a camera on
an arm, iCub's torso, neck and eyes) the same step comes from ``J_x J_x^T`` (``M x M``, ``M = 2S``;
:func:`_step_from_rows`). With a minimum viewing distance the null move keeps the solved camera
nearest the target from coming nearer than it (:func:`_hold_off`).
"""

from __future__ import annotations

import math
from collections import namedtuple

from cpc2urdf.validation.gaze.kernels._jit import hot_kernel, inline_kernel
from cpc2urdf.validation.gaze.kernels.constants import (
    DAMPING,
    DISTANCE_REACH,
    HISTORY,
    MAX_STEP,
    MIN_TARGET_DISTANCE,
    VERSION_POLISH,
)
from cpc2urdf.validation.gaze.kernels.eigen import _eigh_warm
from cpc2urdf.validation.gaze.kernels.kinematics import (
    TASK_MIN_DISTANCE,
    TASK_VERSION_REF,
    TASK_WEIGHT,
)
from cpc2urdf.validation.gaze.kernels.pointing import _gradient_entry, _tangent_residual

#: What one iteration solves: the :class:`~.kinematics.Chain` ``ch``, the aim point ``p`` (world, (3,)), the
#: chain's readings offset ``b`` (K,), the policy's reference ``u_ref``, the bounds ``lower`` and
#: ``upper`` and scale ``sw`` of the unknowns (m,), and the null cut ``null_rel`` (relative).
Problem = namedtuple("Problem", "ch p b u_ref lower upper sw null_rel")

DN = 4 * HISTORY + 1  # the row of the workspace's ``acc`` holding the step's null (policy) move


@hot_kernel
def _capped(dx, sw, m):  # type: ignore[no-untyped-def]
    """The step ``dx`` (scaled unknowns) as ``(big, scale)``: its largest change of one unknown
    and the factor that caps that at :data:`MAX_STEP`."""
    big = 0.0
    for v in range(m):
        big = max(big, abs(dx[v] / sw[v]))
    return big, (1.0 if big <= MAX_STEP else MAX_STEP / big)


@hot_kernel
def _policy_allowance(dx, sw, scale, gain, m):  # type: ignore[no-untyped-def]
    """The rise of ``|r|^2`` a policy step ``scale dx`` may cause (its null-space move's second
    order): 1e-2 of its squared length (at most 1), times the gain."""
    allowance = 0.0
    for v in range(m):
        d = dx[v] / sw[v] * scale
        allowance += d * d
    return min(allowance, 1.0) * 1e-2 * min(1.0, gain)


@hot_kernel
def _version(vc, vw_ref, u):  # type: ignore[no-untyped-def]
    """The version ``c . (u - home)`` of the zero-version task (``vw_ref = c . home``)."""
    ver = -vw_ref
    for v in range(u.shape[0]):
        ver += vc[v] * u[v]
    return ver


@hot_kernel
def _zero_version_gain(aa, ab, ver, vr, vw_w, gain):  # type: ignore[no-untyped-def]
    """The null move's coefficient ``k`` along ``P c_x`` of the zero-version task, from ``aa =
    |P c_x|^2`` and ``ab = P c_x . z`` (sums over the null directions), the version ``ver`` and
    what the pointing step moves it by, ``vr``. Sherman-Morrison on ``(I + w a a^T) z = -(b + w a
    (ver + vr))``, without the ``w^2`` terms: the version after the whole step is zero. The polish
    (``gain == 0``) zeroes the version alone, and only where the policy phase left it near zero."""
    if gain > 0.0 or abs(ver) <= VERSION_POLISH:
        if gain == 0.0:
            ab = 0.0
        return vw_w * (ab - ver - vr) / (1.0 + vw_w * aa)
    return 0.0


@hot_kernel
def _null_cut(lam, n, null_rel):  # type: ignore[no-untyped-def]
    """The eigenvalue at or below which a direction of the step's decomposition (``n`` eigenvalues
    ``lam``, ascending) is in the pointing task's null space: ``null_rel`` of the largest."""
    return null_rel * max(lam[n - 1], 1e-300)


@inline_kernel
def _decompose(pb, f, M, rows, warm, ws):  # type: ignore[no-untyped-def]
    """The step's eigen-decomposition into ``ws.lam``, ``ws.V`` over the free unknowns
    ``ws.idx[:f]`` (``J_x = J / sw``): of ``J_x J_x^T`` (M x M) when ``rows``, else of ``J_x^T
    J_x`` (f x f); warm-started from ``ws.Vp`` when ``warm``, and kept there with every unknown
    free (``f == m``) for the next step."""
    J, H, idx, sw = ws.J, ws.H, ws.idx, pb.sw
    if rows:
        for i in range(M):
            for j in range(i, M):
                s = 0.0
                for a in range(f):
                    va = idx[a]
                    s += J[i, va] * J[j, va] / (sw[va] * sw[va])
                H[i, j] = s
                H[j, i] = s
        n = M
    else:
        for a in range(f):
            for c in range(a, f):
                s = 0.0
                for i in range(M):
                    s += J[i, idx[a]] * J[i, idx[c]]
                s /= sw[idx[a]] * sw[idx[c]]
                H[a, c] = s
                H[c, a] = s
        n = f
    _eigh_warm(H, n, ws.lam, ws.V, ws.Vp, ws.Hb, warm, f == sw.shape[0])


@hot_kernel
def _range_direction(ws, root, e, M, f, sw, v):  # type: ignore[no-untyped-def]
    """``v[:f]``: the range direction ``v_e = J_x^T w_e / sqrt(l_e)`` (``root = sqrt(l_e)``) of
    ``J_x^T J_x`` over the free unknowns ``ws.idx[:f]``, from the eigenvector ``w_e`` (column ``e``
    of ``ws.V``) of ``J_x J_x^T`` (``J_x = J / sw``)."""
    J, W, idx = ws.J, ws.V, ws.idx
    for a in range(f):
        va = idx[a]
        t = 0.0
        for i in range(M):
            t += J[i, va] * W[i, e]
        v[a] = t / (root * sw[va])


@inline_kernel
def _step_from_columns(pb, u, f, null_rel, rr, gain, accelerate, have_g, ws):  # type: ignore[no-untyped-def]
    """The step (added to ``ws.dx``, its null move also to the ``acc`` row ``DN`` if
    ``accelerate``) from the decomposition of ``J_x^T J_x`` over the free unknowns ``ws.idx[:f]``.
    ``have_g``: ``ws.g = J_x^T r`` is already made at this ``u``. Returns the null move's squared
    length (scaled)."""
    ch, sw, u_ref = pb.ch, pb.sw, pb.u_ref
    V, lam, idx, g, dx, dn = ws.V, ws.lam, ws.idx, ws.g, ws.dx, ws.acc[DN]
    vc, vw_w = ch.version_row, ch.tasks[TASK_WEIGHT]
    m = u.shape[0]
    if not have_g:  # g = J_x^T r
        for v in range(m):
            g[v] = _gradient_entry(ws.J, ws.r, v) / sw[v]
    cut = _null_cut(lam, f, null_rel)
    mu = DAMPING * rr
    # the pointing step along the strong directions (Gauss-Newton, damped), and the version it
    # moves by, vr = c_x . dx_range (the null move makes up for it)
    vr = 0.0
    for e in range(f):
        if lam[e] > cut:
            s = 0.0
            a_e = 0.0
            for a in range(f):
                va = idx[a]
                s += V[a, e] * g[va]
                a_e += V[a, e] * vc[va] / sw[va]
            s = -s / (lam[e] + mu)
            vr += a_e * s
            for a in range(f):
                dx[idx[a]] += V[a, e] * s
    # zero-version task over the null directions: a_e = v_e . c_x, c_x = c / sw
    kv = 0.0
    if vw_w > 0.0:
        aa = 0.0
        ab = 0.0
        for e in range(f):
            if lam[e] <= cut:
                a_e = 0.0
                b_e = 0.0
                for a in range(f):
                    va = idx[a]
                    a_e += V[a, e] * vc[va] / sw[va]
                    b_e += V[a, e] * sw[va] * (u[va] - u_ref[va])
                aa += a_e * a_e
                ab += a_e * b_e
        kv = _zero_version_gain(aa, ab, _version(vc, ch.tasks[TASK_VERSION_REF], u), vr, vw_w, gain)
    vmove = 0.0
    for e in range(f):
        if lam[e] <= cut:
            s = 0.0
            a_e = 0.0
            for a in range(f):
                va = idx[a]
                s += V[a, e] * sw[va] * (u[va] - u_ref[va])
                a_e += V[a, e] * vc[va] / sw[va]
            s = -gain * s + (gain if gain > 0.0 else 1.0) * a_e * kv
            vmove += s * s
            for a in range(f):
                dx[idx[a]] += V[a, e] * s
            if accelerate:
                for a in range(f):
                    dn[idx[a]] += V[a, e] * s
    return vmove


@inline_kernel
def _step_from_rows(pb, u, M, f, null_rel, rr, gain, accelerate, ws):  # type: ignore[no-untyped-def]
    """The step of :func:`_step_from_columns` when the free unknowns ``ws.idx[:f]`` outnumber the
    ``M`` residual rows, from ``J_x J_x^T = W diag(l) W^T``: the range directions of ``J_x^T J_x``
    are ``v_e = J_x^T w_e / sqrt(l_e)`` (:func:`_range_direction`), its null directions everything
    orthogonal to them, and each null-space sum of the column form is a projection by ``P = I -
    sum_e v_e v_e^T``. Returns the null move's squared length.

    The pointing step along ``v_e`` is ``-v_e (v_e . g) / (l_e + mu)`` with ``v_e . g`` taken as
    ``sqrt(l_e) (w_e . r_t)`` (``r_t``: :func:`_tangent_residual`), not from ``J_x^T w_e``: the
    Jacobi sweeps stop with off-diagonal terms ~1e-12 of ``l_max``, and that error would move a weak
    direction's step by ~1e-12 ``l_max |r| / sqrt(l_e)`` (iCub's 4th eigenvalue is just above the
    cut at its answers)."""
    ch, sw, u_ref = pb.ch, pb.sw, pb.u_ref
    r, W, lam, idx, dx, dn = ws.r, ws.V, ws.lam, ws.idx, ws.dx, ws.acc[DN]
    v, pz, pc = ws.Hb[0], ws.null_z, ws.null_c  # scratch (f,)
    vc, vw_w = ch.version_row, ch.tasks[TASK_WEIGHT]
    mu = DAMPING * rr
    cut = _null_cut(lam, M, null_rel)
    for a in range(f):  # the policy's offset z = sw (u - u_ref) and the version row c_x = c / sw
        va = idx[a]
        pz[a] = sw[va] * (u[va] - u_ref[va])
        pc[a] = vc[va] / sw[va]
    vr = 0.0
    for e in range(M):
        if lam[e] <= cut:
            continue
        root = math.sqrt(lam[e])
        _range_direction(ws, root, e, M, f, sw, v)
        a_e = 0.0
        bz = 0.0
        for a in range(f):
            a_e += v[a] * pc[a]
            bz += v[a] * pz[a]
        # the pointing step along v_e (Gauss-Newton, damped) and the version it moves by; z and
        # c_x lose their v_e component (Gram-Schmidt, one range direction at a time)
        s = 0.0
        for c in range(M // 2):  # w_e . r_t
            rt1, rt2 = _tangent_residual(r, c)
            s += W[2 * c, e] * rt1 + W[2 * c + 1, e] * rt2
        s = -root * s / (lam[e] + mu)
        vr += a_e * s
        for a in range(f):
            dx[idx[a]] += v[a] * s
            pz[a] -= bz * v[a]
            pc[a] -= a_e * v[a]
    # the zero-version task over the null space (as the column form, whose sums over the null
    # directions of a_e^2 and a_e b_e are |P c_x|^2 and P c_x . z)
    kv = 0.0
    if vw_w > 0.0:
        aa = 0.0
        ab = 0.0
        for a in range(f):
            aa += pc[a] * pc[a]
            ab += pc[a] * pz[a]
        kv = _zero_version_gain(aa, ab, _version(vc, ch.tasks[TASK_VERSION_REF], u), vr, vw_w, gain)
    # the null move: -gain P z + k P c_x (the column form's sum of v_e s_e over the null directions)
    k = (gain if gain > 0.0 else 1.0) * kv
    vmove = 0.0
    for a in range(f):
        s = -gain * pz[a] + k * pc[a]
        vmove += s * s
        dx[idx[a]] += s
        if accelerate:
            dn[idx[a]] += s
    return vmove


@hot_kernel
def _null_part(ws, rows, M, f, sw, null_rel, a, v, pa):  # type: ignore[no-untyped-def]
    """``pa[:f]``: the part of ``a`` (scaled unknowns, (m,)) in the null space the policy moves in,
    over the free unknowns ``ws.idx[:f]``, from the step's decomposition (``ws.V``, ``ws.lam``): in
    the column form the sum of ``v_e (v_e . a)`` over its null directions, in the rows form
    (``rows``) ``a`` less its range part (:func:`_range_direction`, each in turn in ``v``).
    Returns ``|pa|^2``."""
    V, lam, idx = ws.V, ws.lam, ws.idx
    if rows:
        cut = _null_cut(lam, M, null_rel)
        for i in range(f):
            pa[i] = a[idx[i]]
        for e in range(M):
            if lam[e] <= cut:
                continue
            _range_direction(ws, math.sqrt(lam[e]), e, M, f, sw, v)
            va = 0.0
            for i in range(f):
                va += v[i] * a[idx[i]]
            for i in range(f):
                pa[i] -= va * v[i]
    else:
        cut = _null_cut(lam, f, null_rel)
        for i in range(f):
            pa[i] = 0.0
        for e in range(f):
            if lam[e] <= cut:
                va = 0.0
                for i in range(f):
                    va += V[i, e] * a[idx[i]]
                for i in range(f):
                    pa[i] += V[i, e] * va
    aa = 0.0
    for i in range(f):
        aa += pa[i] * pa[i]
    return aa


@inline_kernel
def _hold_off(pb, rows, M, f, null_rel, accelerate, ws):  # type: ignore[no-untyped-def]
    """The minimum viewing distance ``d_min`` [m] of the policy phase, applied to the step ``ws.dx``
    (and to its null move if ``accelerate``). Returns whether it held the step.

    Without it a camera on an arm is walked onto its target: the pointing task's null space includes
    sliding the camera along its optical axis. ``a`` is the gradient of the distance of the solved
    camera nearest the target (``ws.Pc``) by the scaled unknowns, ``P a`` its part in the null space
    (:func:`_null_part`): moving along ``P a`` changes the distance and, to first order, not the
    pointing. The hold acts where the step, capped at :data:`MAX_STEP`, would take the camera nearer
    than ``d_min`` to first order, and the null move alone would too; the null move then gains ``k P
    a`` so that it ends at ``d_min``, and the whole step is capped as any other. The pointing step's
    own change of the distance is not held (far from fixation its first-order prediction is poor).
    With the zero-version task ``P a`` loses its part along ``P c_x`` (the task outranks the
    distance). Nothing where the null space cannot move the distance (``|P a|^2`` at most
    :data:`DISTANCE_REACH` ``|a|^2``). ``d`` and ``a`` are taken where ``J`` was (``Pc`` columns 4
    on): a refused trial leaves its own distance in columns 0-3."""
    ch, sw = pb.ch, pb.sw
    Pc, idx, dx, dn = ws.Pc, ws.idx, ws.dx, ws.acc[DN]
    m = dx.shape[0]
    v, pa, a, cx, pc = ws.null_z, ws.null_c, ws.Hb[0], ws.trial, ws.Hb[1 % m]  # scratch
    d_min, vw_w = ch.tasks[TASK_MIN_DISTANCE], ch.tasks[TASK_WEIGHT]
    S = Pc.shape[0]
    near = 0
    for s in range(1, S):
        if Pc[s, 4] < Pc[near, 4]:
            near = s
    d = Pc[near, 4]  # at the Jacobian's u (columns 0-3 may hold a refused trial's)
    if d < MIN_TARGET_DISTANCE:  # on the camera centre: no gradient
        return False
    ahead = 0.0
    for w in range(m):
        a[w] = Pc[near, 5 + w] / sw[w]
        ahead += a[w] * dx[w]
    if d + _capped(dx, sw, m)[1] * ahead >= d_min:
        return False
    aa = _null_part(ws, rows, M, f, sw, null_rel, a, v, pa)
    a2 = 0.0
    short = d_min - d  # what the null move leaves: P a . dx is a . (the null move)
    for i in range(f):
        a2 += a[idx[i]] * a[idx[i]]
        short -= pa[i] * dx[idx[i]]
    if short <= 0.0:
        return False
    if vw_w > 0.0:
        # the zero-version task outranks the distance: P a loses its part along P c_x (the
        # nominal IIS-head's null space is one direction, the version's: nothing is left)
        for w in range(m):
            cx[w] = ch.version_row[w] / sw[w]
        cc = _null_part(ws, rows, M, f, sw, null_rel, cx, v, pc)
        c2 = 0.0
        for i in range(f):
            c2 += cx[idx[i]] * cx[idx[i]]
        if cc > DISTANCE_REACH * c2:
            ac = 0.0
            for i in range(f):
                ac += pa[i] * pc[i]
            aa = 0.0
            for i in range(f):
                pa[i] -= ac / cc * pc[i]
                aa += pa[i] * pa[i]
    if aa <= DISTANCE_REACH * a2:
        return False
    k = short / aa  # P a . (k pa) = k |pa|^2: pa is P a less a part orthogonal to it
    for i in range(f):
        t = k * pa[i]
        dx[idx[i]] += t
        if accelerate:
            dn[idx[i]] += t
    return True
