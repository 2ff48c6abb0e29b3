"""One call per solve from Python: the head and its workspace as flat arrays (compiled).

numba's dispatcher types every argument of a call, and a chain's and a workspace's arrays cost
~5 us a call, more than the solve's arithmetic. The entry (:func:`solve_flat`,
:func:`solve_flat_many`) takes the head as one float and one int array (:func:`pack_flat`), views
them (:func:`_unpack`, same layout) and writes the whole answer (readings, errors, misses,
fixation point, vergence, limits) into one output row (:func:`out_size`). Both go through one
compiled kernel, :func:`_solve_rows`: the solve is compiled once.
"""

from __future__ import annotations

import math
from collections import namedtuple
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cpc2urdf.transforms import Array
from cpc2urdf.validation.gaze.kernels._jit import (
    hot_kernel,
    inline_kernel,
    kernel_without_refcounts,
    view_kernel,
)
from cpc2urdf.validation.gaze.kernels.buffers import _carve_workspace, _sizes, scratch
from cpc2urdf.validation.gaze.kernels.constants import (
    AT_BOUND,
    FAR_TARGET,
    MODE_FALLBACK,
    MODE_Q_CURRENT,
    MODE_WARM_START,
    S_FIXATED,
    S_LIMITS,
    S_NO_SOLUTION,
    S_NOT_FINITE,
    STATIONARY,
)
from cpc2urdf.validation.gaze.kernels.kinematics import (
    TASK_MIN_DISTANCE,
    TASK_NEAR_NULL,
    TASK_WEIGHT,
    Chain,
    fk,
)
from cpc2urdf.validation.gaze.kernels.pointing import WITH_JACOBIAN, _gradient_entry, residual
from cpc2urdf.validation.gaze.kernels.solve import Settings, solve_one
from cpc2urdf.validation.gaze.kernels.starts import best_starts
from cpc2urdf.validation.gaze.kernels.step import Problem

I_HEADER = 9  # K, C, S, m, G, n, starts per target, iteration cap, disparity head (0/1)
F_SCALARS = 7  # null_rel, tolerance, baseline, has a zero-version task (0/1), the head's centre (3)

#: The packed head's views (:func:`_unpack`): the :class:`~.kinematics.Chain` ``ch``; the unknowns'
#: ``lower``, ``upper``, scale ``sw`` and ``home``; the start table ``table_u`` (m, G), ``table_o``
#: and ``table_z`` (3, G); the robot map ``q = robot_A u + robot_b`` with the readings' limits
#: ``robot_lo``, ``robot_hi`` and ``pinv`` of ``robot_A``; the ``scalars`` (:data:`F_SCALARS`); per
#: chain joint its robot index ``joint_index`` and whether it is ``held`` at its reading; per robot
#: joint whether the head leaves it ``still``.
Head = namedtuple(
    "Head",
    "ch lower upper sw home table_u table_o table_z robot_A robot_b robot_lo robot_hi pinv scalars joint_index"
    " held still",
)


def pack_flat(
    ch: Chain,
    lower: Array,
    upper: Array,
    sw: Array,
    table: tuple[Array, Array, Array],
    robot: tuple[Array, Array, Array, Array, NDArray[np.floating[Any]]],
    joint_index: NDArray[np.integer[Any]],
    held: NDArray[np.bool_],
    still: NDArray[np.bool_],
    n_starts: int,
    max_it: int,
    null_rel: float,
    tol: float,
    baseline: float,
    disparity_head: bool,
    centre: Array,
) -> tuple[Array, Array]:
    """The head as ``(F, I)`` for :func:`solve_flat`: the chain's tuple ``ch`` (:func:`pack`),
    the unknowns' bounds and scale ``sw``, the start ``table`` (unknowns (m, G), centres and
    axes (3, G)), the ``robot`` map (``robot_A``, ``robot_b``, readings' lower and upper
    limits, ``pinv`` of ``robot_A``), per chain joint its robot index and whether it is held at
    its reading, per robot joint whether the head leaves it still, and the solve's constants
    (``centre``: the point far targets are pulled in towards, world [m], shape (3,))."""
    ch = Chain(*ch)  # (a plain tuple in the same order too)
    parent, cam_parent, solve_cams, vw = ch.parent, ch.cam_parent, ch.solve_cameras, ch.tasks
    axis, R, t, A, b, cam_R, cam_t, c, anc, jtype = (
        ch.axis,
        ch.R,
        ch.t,
        ch.A,
        ch.b,
        ch.cam_R,
        ch.cam_t,
        ch.version_row,
        ch.anc,
        ch.jtype,
    )
    table_u, table_o, table_z = table
    robot_A, robot_b, robot_lo, robot_hi, pinv = robot
    K, C, S, m, G, n = (
        len(parent),
        len(cam_parent),
        len(solve_cams),
        len(lower),
        table_u.shape[1],
        len(robot_b),
    )
    floats = [
        axis,
        R,
        t,
        A,
        b,
        cam_R,
        cam_t,
        c,
        vw,
        lower,
        upper,
        sw,
        0.5 * (lower + upper),
        table_u,
        table_o,
        table_z,
        robot_A,
        robot_b,
        robot_lo,
        robot_hi,
        pinv,
        np.array([null_rel, tol, baseline, 1.0 if vw[0] > 0.0 else 0.0]),
        np.asarray(centre, dtype=float),
    ]
    ints = [
        np.array([K, C, S, m, G, n, n_starts, max_it, int(bool(disparity_head))]),
        parent,
        jtype,
        cam_parent,
        anc,
        solve_cams,
        joint_index,
        held,
        still,
    ]
    F = np.concatenate([np.asarray(x, dtype=float).ravel() for x in floats])
    I = np.concatenate([np.asarray(x).astype(np.int64).ravel() for x in ints])
    return np.ascontiguousarray(F), np.ascontiguousarray(I)


@view_kernel
def _unpack(F, I):  # type: ignore[no-untyped-def]
    """The :class:`Head` as views of :func:`pack_flat`'s arrays."""
    K, C, S, m, G, n = I[0], I[1], I[2], I[3], I[4], I[5]
    o = I_HEADER
    parent = I[o : o + K]
    o += K
    jtype = I[o : o + K]
    o += K
    cam_parent = I[o : o + C]
    o += C
    anc = I[o : o + C * K].reshape((C, K))
    o += C * K
    solve_cams = I[o : o + S]
    o += S
    joint_index = I[o : o + K]
    o += K
    held = I[o : o + K]
    o += K
    still = I[o : o + n]
    f = 0
    axis = F[f : f + 3 * K].reshape((K, 3))
    f += 3 * K
    R = F[f : f + 9 * K].reshape((K, 3, 3))
    f += 9 * K
    t = F[f : f + 3 * K].reshape((K, 3))
    f += 3 * K
    A = F[f : f + K * m].reshape((K, m))
    f += K * m
    b = F[f : f + K]
    f += K
    cam_R = F[f : f + 9 * C].reshape((C, 3, 3))
    f += 9 * C
    cam_t = F[f : f + 3 * C].reshape((C, 3))
    f += 3 * C
    c = F[f : f + m]
    f += m
    vw = F[f : f + 4]
    f += 4
    lower = F[f : f + m]
    f += m
    upper = F[f : f + m]
    f += m
    sw = F[f : f + m]
    f += m
    home = F[f : f + m]
    f += m
    table_u = F[f : f + G * m].reshape((m, G))
    f += G * m
    table_o = F[f : f + 3 * G].reshape((3, G))
    f += 3 * G
    table_z = F[f : f + 3 * G].reshape((3, G))
    f += 3 * G
    robot_A = F[f : f + n * m].reshape((n, m))
    f += n * m
    robot_b = F[f : f + n]
    f += n
    robot_lo = F[f : f + n]
    f += n
    robot_hi = F[f : f + n]
    f += n
    pinv = F[f : f + m * n].reshape((m, n))
    f += m * n
    scalars = F[f : f + F_SCALARS]
    ch = Chain(parent, jtype, axis, R, t, A, b, cam_parent, cam_R, cam_t, anc, solve_cams, c, vw)
    return Head(
        ch,
        lower,
        upper,
        sw,
        home,
        table_u,
        table_o,
        table_z,
        robot_A,
        robot_b,
        robot_lo,
        robot_hi,
        pinv,
        scalars,
        joint_index,
        held,
        still,
    )


def out_size(n: int, S: int) -> int:
    """Length of :func:`solve_flat`'s output for ``n`` robot joints and ``S`` solved axes."""
    return 2 + n + 2 * S + 4 + n + 3


@kernel_without_refcounts
def _solve_rows(F, I, T, qin, mode, OUT, f, ints):  # type: ignore[no-untyped-def]
    """:func:`_solve_target` for every row of ``T`` (N, 3), answers in the rows of ``OUT``, on the
    workspace carved from the buffers ``f`` and ``ints`` (:func:`~.buffers.scratch`): the one
    compiled entry of every solve."""
    head = _unpack(F, I)
    ws = _carve_workspace(f, ints, _sizes(I))
    plain = _without_version(head.ch, ws.vw_plain)
    for i in range(T.shape[0]):
        _solve_target(head, plain, I, ws, T[i], qin, mode, OUT[i])


def solve_flat(
    F: Array, I: Array, p: Array, qin: Array, mode: int, out: Array, f: Array, ints: Array
) -> None:
    """One target ``p`` (3,) (see :func:`_solve_target`): the entry of ``GazeSolver.solve``. The
    workspace is carved from the buffers ``f`` and ``ints`` (:func:`~.buffers.scratch`), which
    keep, from call to call, the reference posture's scores (:func:`~.starts.best_starts`); no other
    call may use them at the same time (the kernel runs without the GIL)."""
    _solve_rows(F, I, p.reshape((1, 3)), qin, mode, out[None], f, ints)


def solve_flat_many(F: Array, I: Array, T: Array, qin: Array, mode: int, OUT: Array) -> None:
    """:func:`_solve_target` for every row of ``T`` (N, 3), answers in the rows of ``OUT``, on a
    fresh workspace: ``solve_many``'s answers are ``solve``'s, target by target. Serial, without
    the GIL: ``solve_many`` runs one call per core on its share of the rows from Python threads."""
    f, ints = scratch(I)
    _solve_rows(F, I, np.ascontiguousarray(T, dtype=float), qin, mode, OUT, f, ints)


@inline_kernel
def _solve_target(head, plain, I, ws, p, qin, mode, out):  # type: ignore[no-untyped-def]
    """One target, the whole answer in one call. ``head``: the packed head (:func:`_unpack`);
    ``plain``: its chain without the zero-version task (:func:`_without_version`); ``ws``: its
    workspace (nothing of one solve is read by the next but :func:`~.starts.best_starts`' cache of
    the reference posture, keyed by it); ``p`` (3,): the target (world) [m]; ``qin`` (2 n,):
    ``q_current`` then ``q_start``; ``mode``: the flags ``MODE_*`` of :mod:`.constants`.

    A target with a coordinate that is not finite: status :data:`~.constants.S_NOT_FINITE`, nothing
    else written (``GazeSolver.solve`` passes a float array to this call as it is).

    With :data:`~.constants.MODE_FALLBACK`, a first answer at a limit or with no solution is tried
    again without the zero-version task, which can hold a joint at a bound where fixation needs it
    inside (pan at 0 with tilt at its limit): from the first answer, and if that ends at a limit,
    with equal weights from the best start (the weighted home can pull the eyes into a corner of
    the bounds). Only where the task held pointing back, not where pointing alone has no descent
    direction inside the bounds (an unreachable target's answer). The better answer is kept."""
    if not (math.isfinite(p[0]) and math.isfinite(p[1]) and math.isfinite(p[2])):
        out[0] = S_NOT_FINITE
        return
    ch, lower, upper, sw, scalars = head.ch, head.lower, head.upper, head.sw, head.scalars
    settings = Settings(scalars[1], I[7], I[8] != 0, scalars[2])
    ps, b, u_ref, u_start, starts, u_out, e_out = (
        ws.ps,
        ws.b,
        ws.u_ref,
        ws.u_start,
        ws.starts,
        ws.u_out,
        ws.e_out,
    )
    eig = ws.eig  # the state the iteration keeps in the workspace: nothing from another target
    eig[0] = 0.0
    eig[1] = 0.0
    eig[2] = 0.0
    _aim_point(p, scalars[4:7], ps)
    warm = _readings(head, I[5], qin, mode, ws)
    row = 1 if warm else 0  # the table's first start (after the warm start)
    if warm:
        for v in range(u_start.shape[0]):
            starts[0, v] = min(max(u_start[v], lower[v]), upper[v])
    best_starts(ch, ps, b, u_ref, sw, head.table_u, head.table_o, head.table_z, starts[row], ws)
    n_first = starts.shape[0] - 1 + row
    it, st, it2, st2 = 0, S_NO_SOLUTION, 0, S_NO_SOLUTION
    fell_back = False
    for attempt in range(3):
        chain, weights, rows, table_from = ch, sw, starts[:n_first], row  # round one
        if attempt == 1:  # without the zero-version task, from the first answer
            if not (
                (mode & MODE_FALLBACK) != 0
                and scalars[3] > 0.0
                and (st == S_LIMITS or st == S_NO_SOLUTION)
                and not _pointing_stationary(plain, u_out, b, ps, lower, upper, ws)
            ):
                break
            fell_back = True
            _copy(u_out, ws.u1)
            _copy(e_out, ws.e1)
            _copy(starts[row], ws.best_start)
            _copy(ws.u1, starts[0])
            chain, rows, table_from = plain, starts[:1], 0
        elif attempt == 2:  # and with equal weights from the best start
            if st2 != S_LIMITS:
                break
            _copy(u_out, ws.u2)
            _copy(e_out, ws.e2)
            _copy(ws.best_start, starts[0])
            chain, weights, rows, table_from = plain, ws.ones, starts[:1], 0
        it_a, st_a = solve_one(
            Problem(chain, ps, b, u_ref, lower, upper, weights, scalars[0]),
            p,
            settings,
            rows,
            table_from,
            head.table_u,
            u_out,
            e_out,
            ws,
            np.inf,
        )
        if attempt == 0:
            it, st = it_a, st_a
        elif attempt == 1:
            it2, st2 = it_a, st_a
        else:
            it2 += it_a
            if st_a == S_FIXATED or _largest(e_out) < _largest(ws.e2):
                st2 = st_a
            else:
                _keep(ch, ws.u2, ws.e2, b, ws)
    if fell_back:
        if st2 != S_FIXATED and _largest(e_out) >= _largest(ws.e1):
            _keep(ch, ws.u1, ws.e1, b, ws)
        else:
            st = st2
        it += it2
    _report(head, I[5], ws, p, qin, mode, st, it, out)


@hot_kernel
def _readings(head, n, qin, mode, ws):  # type: ignore[no-untyped-def]
    """The readings offset ``ws.b`` and reference ``ws.u_ref`` of one target (the chain's and the
    home, or from ``q_current`` with :data:`~.constants.MODE_Q_CURRENT`: the held joints read there),
    and the warm start ``ws.u_start`` from ``q_start`` (:data:`~.constants.MODE_WARM_START`).
    Returns whether there is a warm start."""
    b, u_ref = ws.b, ws.u_ref
    _copy(head.ch.b, b)
    _copy(head.home, u_ref)
    if (mode & MODE_Q_CURRENT) != 0:
        _u_of_q(qin[0:n], head.robot_b, head.pinv, head.lower, head.upper, u_ref)
        for k in range(b.shape[0]):
            if head.held[k] != 0:
                b[k] = qin[head.joint_index[k]]
    warm = (mode & MODE_WARM_START) != 0
    if warm:
        _u_of_q(qin[n : 2 * n], head.robot_b, head.pinv, head.lower, head.upper, ws.u_start)
    return warm


@hot_kernel
def _keep(ch, u, e, b, ws):  # type: ignore[no-untyped-def]
    """The answer ``u`` with errors ``e`` back into ``ws.u_out``, ``ws.e_out``, the cameras there."""
    _copy(u, ws.u_out)
    _copy(e, ws.e_out)
    fk(ch, ws.u_out, b, ws.JR, ws.Jp, ws.Ja, ws.CR, ws.Co)


@hot_kernel
def _report(head, n, ws, p, qin, mode, st, it, out):  # type: ignore[no-untyped-def]
    """``out`` (:func:`out_size`) from the answer ``ws.u_out`` and the cameras there (``ws.CR``,
    ``ws.Co``): status, iterations, readings (n), pointing errors (S), miss distances (S), fixation
    point (3; NaN when the two axes are parallel or S = 1), vergence, per robot joint 1.0 at a limit
    (n), the target (3)."""
    robot_A, robot_b, u_out, e_out = head.robot_A, head.robot_b, ws.u_out, ws.e_out
    CR, Co, solve_cams = ws.CR, ws.Co, head.ch.solve_cameras
    S, m = e_out.shape[0], u_out.shape[0]
    has_qc = (mode & MODE_Q_CURRENT) != 0
    out[0] = st
    out[1] = it
    q = out[2 : 2 + n]
    for i in range(n):
        s = robot_b[i]
        for v in range(m):
            s += robot_A[i, v] * u_out[v]
        q[i] = qin[i] if (has_qc and head.still[i] != 0) else s
    o = 2 + n
    for s_ in range(S):
        cam = solve_cams[s_]
        out[o + s_] = e_out[s_]
        dx, dy, dz = p[0] - Co[cam, 0], p[1] - Co[cam, 1], p[2] - Co[cam, 2]
        big = max(abs(dx), abs(dy), abs(dz))
        f = math.ldexp(1.0, -math.frexp(big)[1]) if big > 1e150 else 1.0
        dx, dy, dz = dx * f, dy * f, dz * f
        x = CR[cam, 0, 0] * dx + CR[cam, 1, 0] * dy + CR[cam, 2, 0] * dz
        y = CR[cam, 0, 1] * dx + CR[cam, 1, 1] * dy + CR[cam, 2, 1] * dz
        z = CR[cam, 0, 2] * dx + CR[cam, 1, 2] * dy + CR[cam, 2, 2] * dz
        # the lateral offset in front of the camera, the distance behind it
        out[o + S + s_] = (
            math.sqrt(x * x + y * y) if z >= 0 else math.sqrt(x * x + y * y + z * z)
        ) / f
    o += 2 * S
    _fixation_point(CR, Co, solve_cams, out[o : o + 4])
    o += 4
    for i in range(n):
        out[o + i] = (
            1.0
            if (q[i] <= head.robot_lo[i] + AT_BOUND or q[i] >= head.robot_hi[i] - AT_BOUND)
            else 0.0
        )
    o += n
    out[o], out[o + 1], out[o + 2] = p[0], p[1], p[2]


@hot_kernel
def _fixation_point(CR, Co, solve_cams, out):  # type: ignore[no-untyped-def]
    """``out`` (4,): the midpoint of the closest points of two solved axes and their vergence (NaN,
    NaN, NaN, 0 with one axis; the point NaN when the axes are parallel)."""
    out[0], out[1], out[2], out[3] = np.nan, np.nan, np.nan, 0.0
    if solve_cams.shape[0] != 2:
        return
    c0, c1 = solve_cams[0], solve_cams[1]
    d0x, d0y, d0z = CR[c0, 0, 2], CR[c0, 1, 2], CR[c0, 2, 2]
    d1x, d1y, d1z = CR[c1, 0, 2], CR[c1, 1, 2], CR[c1, 2, 2]
    wx, wy, wz = Co[c0, 0] - Co[c1, 0], Co[c0, 1] - Co[c1, 1], Co[c0, 2] - Co[c1, 2]
    aa = d0x * d0x + d0y * d0y + d0z * d0z
    bb = d0x * d1x + d0y * d1y + d0z * d1z
    cc = d1x * d1x + d1y * d1y + d1z * d1z
    den = aa * cc - bb * bb
    if den >= 1e-14:
        dd = d0x * wx + d0y * wy + d0z * wz
        ee = d1x * wx + d1y * wy + d1z * wz
        s0 = (bb * ee - cc * dd) / den
        t0 = (aa * ee - bb * dd) / den
        out[0] = 0.5 * (Co[c0, 0] + s0 * d0x + Co[c1, 0] + t0 * d1x)
        out[1] = 0.5 * (Co[c0, 1] + s0 * d0y + Co[c1, 1] + t0 * d1y)
        out[2] = 0.5 * (Co[c0, 2] + s0 * d0z + Co[c1, 2] + t0 * d1z)
    out[3] = math.acos(max(-1.0, min(1.0, bb)))


@hot_kernel
def _u_of_q(q, robot_b, pinv, lower, upper, u):  # type: ignore[no-untyped-def]
    """Unknowns ``u`` closest to robot readings ``q`` in least squares, clipped to the bounds."""
    m, n = pinv.shape
    for v in range(m):
        s = 0.0
        for i in range(n):
            s += pinv[v, i] * (q[i] - robot_b[i])
        u[v] = min(max(s, lower[v]), upper[v])


@hot_kernel
def _aim_point(p, centre, ps):  # type: ignore[no-untyped-def]
    """Writes into ``ps`` (3,) the point the iteration aims at for target ``p``: ``p`` itself, or for
    a target with a coordinate beyond :data:`~.constants.FAR_TARGET` the point on the ray from
    ``centre`` through ``p`` at that distance (the same direction to ~1e-15 rad from any camera;
    beyond it the start table and the policies would square coordinates out of the float range)."""
    big = max(abs(p[0]), abs(p[1]), abs(p[2]))
    if big <= FAR_TARGET:
        ps[0], ps[1], ps[2] = p[0], p[1], p[2]
        return
    dx, dy, dz = p[0] - centre[0], p[1] - centre[1], p[2] - centre[2]
    big = max(abs(dx), abs(dy), abs(dz))  # components scaled into [-1, 1]: no overflow in the norm
    dx, dy, dz = dx / big, dy / big, dz / big
    k = FAR_TARGET / math.sqrt(dx * dx + dy * dy + dz * dz)
    ps[0], ps[1], ps[2] = centre[0] + k * dx, centre[1] + k * dy, centre[2] + k * dz


@hot_kernel
def _copy(src, dst):  # type: ignore[no-untyped-def]
    """``dst[:] = src`` (1-D, same length), as a loop: no view or temporary."""
    for i in range(src.shape[0]):
        dst[i] = src[i]


@hot_kernel
def _largest(a):  # type: ignore[no-untyped-def]
    """``a.max()`` of a non-empty 1-D array, as a loop."""
    big = a[0]
    for i in range(1, a.shape[0]):
        big = max(big, a[i])
    return big


@view_kernel
def _without_version(ch, vw):  # type: ignore[no-untyped-def]
    """The chain ``ch`` without its zero-version task (weight 0; the minimum viewing distance and the
    null cut kept), its task scalars written into ``vw`` (4,): nothing allocated."""
    vw[TASK_WEIGHT] = 0.0
    vw[1] = 0.0
    vw[TASK_MIN_DISTANCE] = ch.tasks[TASK_MIN_DISTANCE]
    vw[TASK_NEAR_NULL] = ch.tasks[TASK_NEAR_NULL]
    return Chain(
        ch.parent,
        ch.jtype,
        ch.axis,
        ch.R,
        ch.t,
        ch.A,
        ch.b,
        ch.cam_parent,
        ch.cam_R,
        ch.cam_t,
        ch.anc,
        ch.solve_cameras,
        ch.version_row,
        vw,
    )


@hot_kernel
def _pointing_stationary(ch, u, b, p, lower, upper, ws):  # type: ignore[no-untyped-def]
    """Whether pointing alone (chain ``ch``) has no descent direction at ``u`` inside the bounds:
    the gradient ``J^T r`` without its components that push an unknown out through the bound it is
    at is at most :data:`~.constants.STATIONARY` ``|J| |r|`` (a KKT point of the pointing error).
    Leaves the FK at ``u`` in the workspace."""
    r, J = ws.r, ws.J
    rr = residual(ch, u, b, p, r, J, WITH_JACOBIAN, ws.JR, ws.Jp, ws.Ja, ws.CR, ws.Co, ws.Jc, ws.Pc)
    M, m = J.shape
    g2 = 0.0
    j2 = 0.0
    for v in range(m):
        gv = _gradient_entry(J, r, v)
        for i in range(M):
            j2 += J[i, v] * J[i, v]
        if (u[v] <= lower[v] + AT_BOUND and gv > 0.0) or (u[v] >= upper[v] - AT_BOUND and gv < 0.0):
            continue  # descent (-g) pushes u[v] out through its bound
        g2 += gv * gv
    return g2 <= STATIONARY * STATIONARY * j2 * rr
