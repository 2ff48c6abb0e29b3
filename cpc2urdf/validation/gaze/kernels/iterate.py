"""The gaze iteration: bounded, damped Gauss-Newton with the policy in the null space (compiled).

Each iteration takes the step of :mod:`.step` over an active set (joints at a bound whose step
points outward are held), caps it at :data:`~.constants.MAX_STEP`, shortens a step that turns back
along the last one (a secant along it), and backtracks until ``|r|^2`` does not rise by more than
the policy's null-space move may raise it (:func:`_line_search`).

Near the answer (``|r|^2 <= ACCELERATE_BELOW``) the policy phase of a head that fixates exactly,
with no zero-version task, takes Anderson-accelerated steps (:func:`_accelerate`): its plain step
ignores how the null space turns as the joints move, so it converges linearly; a multisecant step
over the last ``HISTORY`` pairs of (unknowns, plain step) removes most of that, with the plain step
as the fallback and the stopping test.
"""

from __future__ import annotations

import numpy as np

from cpc2urdf.validation.gaze.kernels._jit import hot_kernel, inline_kernel, internal_kernel
from cpc2urdf.validation.gaze.kernels.constants import (
    ACCELERATE_BELOW,
    ACCELERATE_NULL_REL,
    AT_BOUND,
    BACKTRACKS,
    EIG_EXACT,
    EIG_PROBE,
    EIG_WARM,
    EXACT_RESIDUAL,
    HISTORY,
    MAX_STEP,
    NEAR_FIXATION,
    OVERSHOOT,
    POLICY_STEP_TOL,
    POLISHED,
    SAME_BASIN,
    STALLED,
    STEP_TOL,
    VERSION_POLISH,
    VERSION_SETTLED,
)
from cpc2urdf.validation.gaze.kernels.kinematics import (
    TASK_MIN_DISTANCE,
    TASK_NEAR_NULL,
    TASK_VERSION_REF,
    TASK_WEIGHT,
)
from cpc2urdf.validation.gaze.kernels.pointing import (
    RESIDUAL_ONLY,
    WITH_JACOBIAN,
    _residual_hot,
    residual_at_fk,
)
from cpc2urdf.validation.gaze.kernels.step import (
    DN,
    _capped,
    _decompose,
    _hold_off,
    _policy_allowance,
    _step_from_columns,
    _step_from_rows,
    _version,
)

D_PLAIN = (
    4 * HISTORY
)  # the row of the workspace's ``acc`` holding the plain step of an accelerated one


@internal_kernel
def _iterate(pb, u, gain, max_it, rr_at_u, ws):  # type: ignore[no-untyped-def]
    """Task-priority Gauss-Newton on the :class:`~.step.Problem` ``pb`` from ``u`` (updated in
    place) for at most ``max_it`` iterations; ``gain`` is the policy's (0: pointing alone, the
    polish). Returns ``(iterations, |r|^2)``, with the residual and its Jacobian at the returned
    ``u`` left in the workspace ``ws``. Given ``rr_at_u >= 0`` (the previous phase's return), they
    are taken from there, not re-evaluated; -1.0: evaluated at ``u``. The flags of ``ws.eig``
    (:data:`~.constants.EIG_WARM` ...) carry the warm eigenvectors from call to call."""
    ch, sw, eig, dx, dn = pb.ch, pb.sw, ws.eig, ws.dx, ws.acc[DN]
    m = u.shape[0]
    have_v = eig[EIG_WARM] > 0.0
    exact_v = eig[EIG_EXACT] > 0.0 and rr_at_u >= 0.0
    eig[EIG_EXACT] = 0.0
    vw_w = ch.tasks[TASK_WEIGHT]
    # Anderson acceleration: heads that fixate exactly, policy = distance from u_ref (the version
    # task's and a disparity head's near-null moves are left as they are)
    accelerate = gain > 0.0 and vw_w == 0.0 and pb.null_rel <= ACCELERATE_NULL_REL and m <= 62
    near_rel = max(ch.tasks[TASK_NEAR_NULL], pb.null_rel)  # the null cut near a fixating posture
    moved_before = (
        False  # s_prev holds the last accepted step of this call (before its scale sigma_prev)
    )
    sigma_prev = 1.0
    nh = 0  # pairs (x, F) in the acceleration's history
    h_free = 0  # the free unknowns of the pairs in the history, as bits
    rr_old = 0.0  # |r|^2 before the last accepted step
    rr = (
        rr_at_u
        if rr_at_u >= 0.0
        else _residual_hot(ch, u, pb.b, pb.p, ws.r, ws.J, WITH_JACOBIAN, ws)
    )
    it = 0
    while it < max_it:
        if gain == 0.0 and rr <= POLISHED:  # polished: no further step (and its eigen-solve) needed
            ver = _version(ch.version_row, ch.tasks[TASK_VERSION_REF], u)
            if vw_w == 0.0 or abs(ver) <= VERSION_SETTLED or abs(ver) > VERSION_POLISH:
                break
        it += 1
        null_rel = near_rel if rr <= NEAR_FIXATION else pb.null_rel  # this iteration's null cut
        f, vmove, held_off, exact_v, have_v = _active_set_step(
            pb, u, gain, null_rel, rr, accelerate, exact_v, have_v, ws
        )
        accel, nh, h_free = _accelerate(u, sw, rr, vmove, held_off, accelerate, nh, h_free, ws)
        big, scale = _capped(dx, sw, m)
        if (
            accelerate
            and not accel
            and scale < 1.0
            and vmove > 0.0
            and moved_before
            and rr > rr_old
        ):
            big, scale = _cap_walk_alone(dx, dn, sw, big, scale)
        plain = big * scale
        if accel:  # converged is judged on the plain step (an accelerated one can stagnate)
            plain = 0.0
            for v in range(m):
                plain = max(plain, abs(ws.acc[D_PLAIN, v] / sw[v]))
        if plain < (STEP_TOL if gain == 0.0 else POLICY_STEP_TOL):
            if f == m:  # not moved: the decomposition holds at u for the next phase
                eig[EIG_EXACT] = 1.0
            break
        if moved_before and not accel:
            scale = _shorten_overshoot(dx, sw, ws.s_prev, scale, sigma_prev)
        accepted, limited, scale, accel, nh = _line_search(
            pb, u, gain, rr, vmove, scale, accel, nh, ws
        )
        if not accepted:
            break
        moved = _take_step(u, sw, ws)
        sigma_prev = scale
        # the secant rule compares a plain step with the last plain one: not after an accelerated
        # step or a step cut at a bound
        moved_before = not accel and not limited
        rr_old = rr
        rr = residual_at_fk(ch, pb.p, ws.r, ws.J, WITH_JACOBIAN, ws)  # the FK of the trial
        if eig[EIG_PROBE] > 0.0 and _distance(u, ws.u_near) < SAME_BASIN:
            break
        if moved < (STEP_TOL if gain == 0.0 else POLICY_STEP_TOL) and not accel and not limited:
            break
        if gain == 0.0 and vmove == 0.0 and rr > rr_old * (1.0 - STALLED):
            break  # a residual that cannot be removed (a bound, disparity): polished to the floor
    eig[EIG_WARM] = 1.0 if have_v else 0.0
    return it, rr


@inline_kernel
def _active_set_step(pb, u, gain, null_rel, rr, accelerate, exact_v, have_v, ws):  # type: ignore[no-untyped-def]
    """The step into ``ws.dx`` (its null move into the ``acc`` row ``DN`` if ``accelerate``), the
    unknowns at a bound that it pushes outward held (``ws.free``). Returns ``(f, vmove, held_off,
    exact_v, have_v)``: the free unknowns' count, the null move's squared length, whether the
    minimum viewing distance held the step, and whether ``ws.V`` holds this ``u``'s decomposition
    (``exact_v``, used once) or a warm start (``have_v``)."""
    free, idx, dx, dn = ws.free, ws.idx, ws.dx, ws.acc[DN]
    lower, upper, sw = pb.lower, pb.upper, pb.sw
    m = u.shape[0]
    M = ws.J.shape[0]  # two rows a solved camera (its tangent basis)
    have_g = False  # ws.g = J_x^T r at this u: the column form's, made once when first needed
    for v in range(m):
        free[v] = 1
    for _ in range(m + 1):
        # np.int64, not 0: numba's inference first sees the literal 0 and compiles callees for it too
        f = np.int64(0)
        for v in range(m):
            if free[v]:
                idx[f] = v
                f += 1
        for v in range(m):
            dx[v] = 0.0
        if accelerate:  # the null move on its own (the split cap)
            for v in range(m):
                dn[v] = 0.0
        vmove = 0.0
        # more free unknowns than residual rows: the decomposition is of J_x J_x^T (M x M)
        rows = f > M
        # near fixation the structural null direction is among the eigenvalues only with at
        # least as many free unknowns as rows
        cut_rel = null_rel if f >= M else pb.null_rel
        if f > 0 and f == m and exact_v:
            exact_v = False  # V, lam already hold this decomposition at this u
        elif f > 0:
            _decompose(pb, f, M, rows, f == m and have_v, ws)
            if f == m:
                have_v = True
        if rows:
            vmove = _step_from_rows(pb, u, M, f, cut_rel, rr, gain, accelerate, ws)
        elif f > 0:
            vmove = _step_from_columns(pb, u, f, cut_rel, rr, gain, accelerate, have_g, ws)
            have_g = True
        held_off = False
        if pb.ch.tasks[TASK_MIN_DISTANCE] > 0.0 and gain > 0.0 and f > 0:
            held_off = _hold_off(pb, rows, M, f, cut_rel, accelerate, ws)
        changed = False
        for v in range(m):
            if free[v]:
                du = dx[v] / sw[v]
                if (u[v] <= lower[v] + AT_BOUND and du < 0.0) or (
                    u[v] >= upper[v] - AT_BOUND and du > 0.0
                ):
                    free[v] = 0
                    changed = True
        if not changed:
            break
    return f, vmove, held_off, exact_v, have_v


@inline_kernel
def _accelerate(u, sw, rr, vmove, held_off, accelerate, nh, h_free, ws):  # type: ignore[no-untyped-def]
    """Anderson acceleration of the policy phase near the answer: ``ws.dx`` becomes a multisecant
    quasi-Newton step on the step map ``F(x) = dx`` over the last ``HISTORY`` pairs ``(x_i, F_i)``
    (``gamma = argmin |F - dF gamma|``, step ``F - (dX + dF) gamma``), the plain step kept in the
    ``acc`` row ``D_PLAIN``. The history holds for one active set (``ws.free`` and ``held_off``) and
    is dropped when the step map grew since its last pair. Returns ``(accel, nh, h_free)``."""
    free, dx, acc = ws.free, ws.dx, ws.acc
    m = u.shape[0]
    hx, hf = acc[0:HISTORY], acc[HISTORY : 2 * HISTORY]
    dXh, dFh, d_plain = acc[2 * HISTORY : 3 * HISTORY], acc[3 * HISTORY : 4 * HISTORY], acc[D_PLAIN]
    accel = False
    if accelerate:
        bits = 0
        for v in range(m):
            if free[v]:
                bits |= 1 << v
        if held_off:
            bits |= 1 << m
        if bits != h_free:
            nh = 0
            h_free = bits
    if nh > 0:  # safeguard: the step map grew since the history's last pair
        f_now = 0.0
        f_last = 0.0
        for v in range(m):
            f_now += dx[v] * dx[v]
            f_last += hf[0, v] * hf[0, v]
        if f_now >= f_last:
            nh = 0
    if not (accelerate and rr <= ACCELERATE_BELOW and vmove > 0.0):
        return accel, 0, h_free
    for j in range(nh):  # dX_j = x - x_j, dF_j = F - F_j
        for v in range(m):
            dXh[j, v] = sw[v] * u[v] - hx[j, v]
            dFh[j, v] = dx[v] - hf[j, v]
    for j in range(HISTORY - 1, 0, -1):  # push (x, F) into the history (newest first)
        for v in range(m):
            hx[j, v] = hx[j - 1, v]
            hf[j, v] = hf[j - 1, v]
    for v in range(m):
        hx[0, v] = sw[v] * u[v]
        hf[0, v] = dx[v]
    k = nh
    nh = min(nh + 1, HISTORY)
    if k == 0:
        return accel, nh, h_free
    # normal equations of the small least squares (k <= 2), solved by Cramer
    g11 = 0.0
    g12 = 0.0
    g22 = 0.0
    c1 = 0.0
    c2 = 0.0
    for v in range(m):
        g11 += dFh[0, v] * dFh[0, v]
        c1 += dFh[0, v] * dx[v]
        if k > 1:
            g12 += dFh[0, v] * dFh[1, v]
            g22 += dFh[1, v] * dFh[1, v]
            c2 += dFh[1, v] * dx[v]
    ga1 = 0.0
    ga2 = 0.0
    det = g11 * g22 - g12 * g12
    if k > 1 and det > 1e-10 * g11 * g22:
        ga1 = (c1 * g22 - c2 * g12) / det
        ga2 = (g11 * c2 - g12 * c1) / det
    elif g11 > 0.0:
        ga1 = c1 / g11
    if g11 > 0.0:
        for v in range(m):
            d_plain[v] = dx[v]
            dx[v] -= ga1 * (dXh[0, v] + dFh[0, v])
            if k > 1:
                dx[v] -= ga2 * (dXh[1, v] + dFh[1, v])
        accel = True
    return accel, nh, h_free


@inline_kernel
def _cap_walk_alone(dx, dn, sw, big, scale):  # type: ignore[no-untyped-def]
    """A long policy walk that raised the pointing error over its last step is capped on its own,
    not the pointing step with it (scaled together, the walk circles where its drift off the
    fixating postures balances a fraction of its correction). Returns the new ``(big, scale)``."""
    m = dx.shape[0]
    big_r = 0.0
    big_n = 0.0
    for v in range(m):
        big_r = max(big_r, abs((dx[v] - dn[v]) / sw[v]))
        big_n = max(big_n, abs(dn[v] / sw[v]))
    if big_r < MAX_STEP:
        tn = (MAX_STEP - big_r) / big_n
        for v in range(m):
            dx[v] += (tn - 1.0) * dn[v]
        return _capped(dx, sw, m)
    return big, scale


@inline_kernel
def _shorten_overshoot(dx, sw, s_prev, scale, sigma_prev):  # type: ignore[no-untyped-def]
    """A Gauss-Newton step that turns back along the last one ``s_prev`` (taken at scale
    ``sigma_prev``) overshoots: along it the steps are ``rho = s . s' / |s'|^2`` of each other, and
    where they fall linearly (a secant) the minimum is at ``sigma / (1 - rho)`` of this step."""
    dd = 0.0
    pp = 0.0
    for v in range(dx.shape[0]):
        dd += dx[v] / sw[v] * s_prev[v]
        pp += s_prev[v] * s_prev[v]
    rho = dd / pp if pp > 0.0 else 0.0
    if rho < -OVERSHOOT:
        return min(scale, sigma_prev / (1.0 - max(rho, -10.0)))
    return scale


@inline_kernel
def _line_search(pb, u, gain, rr, vmove, scale, accel, nh, ws):  # type: ignore[no-untyped-def]
    """Backtracking along ``ws.dx`` from ``scale``: the first trial (into ``ws.trial``, clipped to
    the bounds) whose ``|r|^2`` rises by no more than the policy's allowance is accepted. A refused
    accelerated step falls back to the plain one; a refused plain policy step near fixation is cut
    at the first bound it reaches (:func:`_first_bound`), since halving on would leave that unknown
    short of its bound and the walk would creep. Returns ``(accepted, limited, scale, accel, nh)``
    (``limited``: the step was cut at a bound)."""
    ch, sw, lower, upper = pb.ch, pb.sw, pb.lower, pb.upper
    trial, dx, d_plain = ws.trial, ws.dx, ws.acc[D_PLAIN]
    m = u.shape[0]
    allowance = 0.0  # the policy's null-space move may raise |r|^2 to second order
    if gain > 0.0:
        allowance = _policy_allowance(dx, sw, scale, gain, m)
    elif vmove > 0.0:  # the polish's zero-version move (scaled unknowns)
        allowance = min(vmove, 1.0) * 1e-2
    allow = allowance * scale * scale
    tries = (
        BACKTRACKS + 1 if accel else BACKTRACKS
    )  # the fallback to the plain step is not a halving
    cut_tried = gain == 0.0  # the policy phase's cut at the first bound, tried once
    cut_now = False  # this trial is the step cut at its first bound (not a halving)
    sb = -1.0  # the step's scale at the first bound it reaches (-1: not yet found)
    vb = -1  # the unknown there
    k = 0
    while k < tries:
        for v in range(m):
            trial[v] = min(
                max(u[v] + (sb if cut_now else scale) * dx[v] / sw[v], lower[v]), upper[v]
            )
        if cut_now:
            trial[vb] = lower[vb] if dx[vb] / sw[vb] < 0.0 else upper[vb]
        rr_new = _residual_hot(ch, trial, pb.b, pb.p, ws.r2, ws.J2, RESIDUAL_ONLY, ws)
        if cut_now:
            cut_now = False
            if rr_new <= rr + allowance * sb * sb or rr_new <= EXACT_RESIDUAL:
                return True, True, sb, accel, nh
        elif rr_new <= rr + allow or rr_new <= EXACT_RESIDUAL:
            return True, False, scale, accel, nh
        elif (
            accel
        ):  # the accelerated step failed: the plain one (its own allowance), a fresh history
            accel = False
            nh = 0
            for v in range(m):
                dx[v] = d_plain[v]
            scale = _capped(dx, sw, m)[1]
            allowance = _policy_allowance(dx, sw, scale, gain, m)
            allow = allowance * scale * scale
            k += 1
            continue
        elif not cut_tried:
            if sb < 0.0:
                sb, vb = _first_bound(u, dx, sw, lower, upper, scale)
                if vb < 0:
                    cut_tried = True  # no bound on the way: halving alone
            # cut where halving would first fall short of that bound, or at the last halving; only
            # near a fixating posture, where the step's null move is the walk
            if vb >= 0 and ((rr <= ACCELERATE_BELOW and 0.5 * scale < sb) or k == tries - 1):
                cut_tried = True
                cut_now = True
                continue
        allow *= 0.25
        scale *= 0.5
        k += 1
    return False, False, scale, accel, nh


@hot_kernel
def _first_bound(u, dx, sw, lower, upper, scale):  # type: ignore[no-untyped-def]
    """The scale at which the step ``scale dx`` first reaches a bound (ratio test) and the unknown
    there: ``(scale, -1)`` when it reaches none."""
    sb = scale
    vb = -1
    for v in range(u.shape[0]):
        du = dx[v] / sw[v]
        if du < 0.0 and u[v] + sb * du < lower[v]:
            sb = max((lower[v] - u[v]) / du, 0.0)
            vb = v
        elif du > 0.0 and u[v] + sb * du > upper[v]:
            sb = max((upper[v] - u[v]) / du, 0.0)
            vb = v
    return sb, vb


@inline_kernel
def _take_step(u, sw, ws):  # type: ignore[no-untyped-def]
    """``u`` takes the accepted trial; ``ws.s_prev`` the step (unscaled). Returns the largest move."""
    dx, trial, s_prev = ws.dx, ws.trial, ws.s_prev
    moved = 0.0
    for v in range(u.shape[0]):
        s_prev[v] = dx[v] / sw[v]
        moved = max(moved, abs(trial[v] - u[v]))
        u[v] = trial[v]
    return moved


@hot_kernel
def _distance(u, w):  # type: ignore[no-untyped-def]
    """The largest difference of one unknown between ``u`` and ``w``."""
    near = 0.0
    for v in range(u.shape[0]):
        near = max(near, abs(u[v] - w[v]))
    return near
