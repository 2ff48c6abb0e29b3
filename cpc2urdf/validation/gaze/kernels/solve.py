"""One target's solve from its starts: policy phase, polish, further starts, the status (compiled).

The policy phase runs from the start that best faces the target (:func:`~.starts.best_starts`),
then pointing alone (the polish) to the rounding floor. A further start of the table is tried only
if the answer is neither fixated nor decided by geometry (behind, too close), and it is probed for
:data:`~.constants.PROBE_ITERATIONS` first: it goes on only if it already does better than the best
answer so far, so an unreachable target costs a few iterations per start, not a full solve each.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np

from cpc2urdf.validation.gaze.kernels._jit import hot_kernel, inline_kernel
from cpc2urdf.validation.gaze.kernels.constants import (
    AT_BOUND,
    EIG_PROBE,
    EXACT_RESIDUAL,
    MIN_TARGET_DISTANCE,
    POLISH_ITERATIONS,
    PROBE_ITERATIONS,
    S_BEHIND,
    S_DISPARITY,
    S_FIXATED,
    S_LIMITS,
    S_NO_SOLUTION,
    S_TOO_CLOSE,
    SAME_BASIN,
    SECONDARY_GAIN,
)
from cpc2urdf.validation.gaze.kernels.iterate import _distance, _iterate
from cpc2urdf.validation.gaze.kernels.kinematics import fk, pointing_error
from cpc2urdf.validation.gaze.kernels.pointing import RESIDUAL_ONLY, residual
from cpc2urdf.validation.gaze.kernels.starts import further_start

#: A head's solve settings: the pointing ``tol`` [rad] under which an axis is on its target, the
#: iteration cap ``max_it``, whether it is a ``disparity_head`` (two eyes that cannot fixate exactly)
#: and its ``baseline`` [m] (nearer, a target is too close).
Settings = namedtuple("Settings", "tol max_it disparity_head baseline")

# the phases of one start (:func:`_run_start`)
PHASE_POLICY, PHASE_PROBE, PHASE_REST, PHASE_POLISH = 0, 1, 2, 3


@inline_kernel
def solve_one(pb, p, settings, starts, table_from, table_u, u_out, err_out, ws, rr_to_beat):  # type: ignore[no-untyped-def]
    """One target ``p`` of the :class:`~.step.Problem` ``pb`` (aimed at ``pb.p``, judged on ``p``)
    from the best start of ``starts`` (rows, best first). Rows from ``table_from`` on are the
    table's starts: the first is given (:func:`~.starts.best_starts`), the others picked when
    reached (:func:`~.starts.further_start`). Given a finite ``rr_to_beat`` (|r|^2 of the answer
    already in ``u_out``), every start is probed and kept only if it does better. Returns
    ``(iterations, status)``; ``u_out`` the unknowns, ``err_out`` (S,) the pointing errors [rad]."""
    m = u_out.shape[0]
    u = ws.u
    best_rr = rr_to_beat
    total = 0
    n_rows = starts.shape[0]
    for k in range(n_rows):
        if k > table_from:
            further_start(
                k - table_from,
                n_rows - table_from,
                pb.u_ref,
                pb.sw,
                table_u,
                ws.score,
                ws.top_g,
                starts[k],
            )
        for v in range(m):
            u[v] = starts[k, v]
        it, rr, answered = _run_start(
            pb, u, u_out, k == 0 and best_rr == np.inf, best_rr, settings.max_it, ws
        )
        total += it
        if not answered:
            continue
        if rr < best_rr:
            best_rr = rr
            for v in range(m):
                u_out[v] = u[v]
        if best_rr <= EXACT_RESIDUAL * 1e8:
            break
        if settings.disparity_head:  # the near-null posture: no other start
            break
        if _decided_by_geometry(pb, u_out, settings.baseline, ws):
            break
    return total, _judge(pb, p, settings, u_out, err_out, ws)


@inline_kernel
def _run_start(pb, u, u_out, first, best_rr, max_it, ws):  # type: ignore[no-untyped-def]
    """The phases from the start in ``u``: the policy phase (``first``: in full; a further start:
    probed, then on only if it does better than ``best_rr``), then the polish (pointing alone, the
    same near-null space). Returns ``(iterations, |r|^2, answered)``; not answered: a probe that
    joined the best answer ``u_out`` or fell behind it."""
    probe_it, polish_it = np.int64(PROBE_ITERATIONS), np.int64(POLISH_ITERATIONS)
    phase = PHASE_POLICY if first else PHASE_PROBE
    total = 0
    rr = -1.0
    while True:
        gain = 0.0 if phase == PHASE_POLISH else SECONDARY_GAIN
        if phase == PHASE_POLICY:
            cap = max_it
        elif phase == PHASE_PROBE:
            cap = probe_it
            for v in range(u.shape[0]):
                ws.u_near[v] = u_out[v]
            ws.eig[EIG_PROBE] = 1.0  # the iteration stops once it joins u_near
        elif phase == PHASE_REST:
            cap = max_it - probe_it
        else:
            cap = polish_it
        it, rr = _iterate(pb, u, gain, cap, -1.0 if phase <= PHASE_PROBE else rr, ws)
        ws.eig[EIG_PROBE] = 0.0
        total += it
        if phase == PHASE_POLISH:
            return total, rr, True
        if phase == PHASE_PROBE:
            if _distance(u, u_out) < SAME_BASIN:  # on its way to the best answer: nothing new
                return total, rr, False
            if it == probe_it:
                if rr >= best_rr:
                    return total, rr, False
                phase = PHASE_REST
                continue
        phase = PHASE_POLISH


@hot_kernel
def _decided_by_geometry(pb, u, baseline, ws):  # type: ignore[no-untyped-def]
    """Whether the answer ``u`` leaves the target behind a solved camera or nearer than the
    baseline: no other start would fixate it."""
    residual(
        pb.ch,
        u,
        pb.b,
        pb.p,
        ws.r,
        ws.J,
        RESIDUAL_ONLY,
        ws.JR,
        ws.Jp,
        ws.Ja,
        ws.CR,
        ws.Co,
        ws.Jc,
        ws.Pc,
    )
    Pc = ws.Pc
    for s in range(Pc.shape[0]):
        if Pc[s, 2] <= 0.0 or Pc[s, 3] < baseline:
            return True
    return False


@hot_kernel
def _judge(pb, p, settings, u_out, err_out, ws):  # type: ignore[no-untyped-def]
    """The status of the answer ``u_out`` on the target ``p`` itself, its solved cameras' pointing
    errors into ``err_out``; the cameras at ``u_out`` left in ``ws.CR``, ``ws.Co``."""
    ch, lower, upper = pb.ch, pb.lower, pb.upper
    CR, Co = ws.CR, ws.Co
    fk(ch, u_out, pb.b, ws.JR, ws.Jp, ws.Ja, CR, Co)
    fixated = True
    behind = False
    close = False
    for s in range(err_out.shape[0]):
        c = ch.solve_cameras[s]
        dx, dy, dz = p[0] - Co[c, 0], p[1] - Co[c, 1], p[2] - Co[c, 2]
        big = max(abs(dx), abs(dy), abs(dz))
        if big > 1e150:  # scaled by a power of two: no overflow in the rotation
            f = math.ldexp(1.0, -math.frexp(big)[1])
            dx, dy, dz = dx * f, dy * f, dz * f
        else:
            f = 1.0
        x = CR[c, 0, 0] * dx + CR[c, 1, 0] * dy + CR[c, 2, 0] * dz
        y = CR[c, 0, 1] * dx + CR[c, 1, 1] * dy + CR[c, 2, 1] * dz
        z = CR[c, 0, 2] * dx + CR[c, 1, 2] * dy + CR[c, 2, 2] * dz
        e = pointing_error(x, y, z)
        err_out[s] = e
        dist = math.sqrt(x * x + y * y + z * z) / f
        if e > settings.tol:
            fixated = False
        if f == 1.0 and dist < MIN_TARGET_DISTANCE:
            close = True
        elif z <= 0.0:
            behind = True
        elif dist < settings.baseline:
            close = True
    if fixated:
        return S_FIXATED
    if close:
        return S_TOO_CLOSE
    if behind:
        return S_BEHIND
    for v in range(u_out.shape[0]):
        if lower[v] < upper[v] and (
            u_out[v] <= lower[v] + AT_BOUND or u_out[v] >= upper[v] - AT_BOUND
        ):
            return S_LIMITS
    if settings.disparity_head:
        return S_DISPARITY
    return S_NO_SOLUTION
