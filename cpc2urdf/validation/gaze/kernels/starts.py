"""The starts of one target's solve: the table entries that best face it (compiled)."""

from __future__ import annotations

import math

import numpy as np

from cpc2urdf.validation.gaze.kernels._jit import hot_kernel, internal_kernel
from cpc2urdf.validation.gaze.kernels.constants import (
    DISTINCT_START,
    START_DISTANCE,
    START_DISTANCE_REDUNDANT,
)
from cpc2urdf.validation.gaze.kernels.kinematics import fk

DISTINCT, ANY = (
    np.bool_(True),
    np.bool_(False),
)  # _best_other's choice (numpy bools: one compiled copy)


@internal_kernel
def best_starts(ch, p, b, u_ref, sw, table_u, table_o, table_z, out, ws):  # type: ignore[no-untyped-def]
    """The start that best faces target ``p`` (into ``out`` (m,)) among ``u_ref`` and the table
    entries (unknowns ``table_u`` (m, G), cyclopean centre ``table_o`` and axis ``table_z`` (3,
    G), world; one column per entry), by the cosine of the angle between their axis and the
    target direction, less a small cost of their distance (scaled) from ``u_ref``
    (:data:`START_DISTANCE`; :data:`START_DISTANCE_REDUNDANT` on a one-camera head with spare
    joints). The scores stay in the workspace for :func:`further_start`. They are computed
    column-wise (loops the compiler vectorises), then the best picked. ``u_ref``'s centre and
    axis and each entry's distance cost stay in the workspace too (``ws.ref_key``, ``ref_axis``, ``ref_cost``), keyed by
    ``u_ref`` and ``b``: a batch's targets share them. A workspace serves one packed head (its
    table, ``sw`` and chain), so the key needs nothing else."""
    JR, Jp, Ja, CR, Co = ws.JR, ws.Jp, ws.Ja, ws.CR, ws.Co
    m, G = table_u.shape
    solve_cams = ch.solve_cameras
    S = solve_cams.shape[0]
    key, axis, cost = ws.ref_key, ws.ref_axis, ws.ref_cost
    K = b.shape[0]
    same = True  # the same u_ref and b as the last target's (a batch's every target, from one q_current)?
    for v in range(m):
        if key[v] != u_ref[v]:  # (a NaN key, as made: never)
            same = False
    for k in range(K):
        if key[m + k] != b[k]:
            same = False
    if (
        not same
    ):  # u_ref's cyclopean centre and axis, and each entry's cost of its distance from u_ref
        for v in range(m):
            key[v] = u_ref[v]
        for k in range(K):
            key[m + k] = b[k]
        fk(ch, u_ref, b, JR, Jp, Ja, CR, Co)
        for i in range(6):
            axis[i] = 0.0
        for s in range(S):
            c = solve_cams[s]
            axis[0] += Co[c, 0] / S
            axis[1] += Co[c, 1] / S
            axis[2] += Co[c, 2] / S
            axis[3] += CR[c, 0, 2]
            axis[4] += CR[c, 1, 2]
            axis[5] += CR[c, 2, 2]
        w0 = START_DISTANCE_REDUNDANT if S == 1 and m > 3 else START_DISTANCE
        for g in range(G):
            cost[g] = 0.0
        for v in range(m):
            w = w0 * sw[v] * sw[v]
            r = u_ref[v]
            for g in range(G):
                d = table_u[v, g] - r
                cost[g] += w * d * d
    ox, oy, oz, zx, zy, zz = axis[0], axis[1], axis[2], axis[3], axis[4], axis[5]
    # the table's axes are unit vectors and targets are within FAR_TARGET (1e15 m): |p - o|^2
    # cannot overflow, so no scaling in the loop (the start at u_ref is g = G, scored last)
    px, py, pz = p[0], p[1], p[2]
    score = ws.score
    for g in range(G):
        dx, dy, dz = px - table_o[0, g], py - table_o[1, g], pz - table_o[2, g]
        nd2 = max(dx * dx + dy * dy + dz * dz, 1e-300)
        score[g] = (dx * table_z[0, g] + dy * table_z[1, g] + dz * table_z[2, g]) / math.sqrt(
            nd2
        ) - cost[g]
    nzr = math.sqrt(zx * zx + zy * zy + zz * zz) + 1e-300
    dx, dy, dz = px - ox, py - oy, pz - oz
    nd2 = dx * dx + dy * dy + dz * dz
    score[G] = (dx * zx + dy * zy + dz * zz) / nzr / math.sqrt(nd2) if nd2 > 0.0 else 0.0
    top_g = ws.top_g
    best = -np.inf
    top_g[0] = G
    for g in range(G + 1):
        if score[g] > best:
            best = score[g]
            top_g[0] = g
    _entry(top_g[0], u_ref, table_u, out)


@hot_kernel
def _entry(g, u_ref, table_u, out):  # type: ignore[no-untyped-def]
    """Start ``g`` of :func:`best_starts`' scores into ``out``: a table column, or ``u_ref`` (g = G)."""
    G = table_u.shape[1]
    for v in range(out.shape[0]):
        out[v] = u_ref[v] if g == G else table_u[v, g]


@internal_kernel
def further_start(j, n_table, u_ref, sw, table_u, score, top_g, out):  # type: ignore[no-untyped-def]
    """The table's ``j``-th start (j >= 1) of ``n_table`` for the target :func:`best_starts`
    scored last (its ``score`` and picks ``top_g``, the workspace's, into which this one goes;
    the start into ``out`` (m,)): the best-scored not chosen before. The last one also
    differs from each table start before it by :data:`DISTINCT_START` in some scaled unknown,
    when any entry does (a warm start before them is not counted): the best-facing entries are
    often one cluster, all in one basin."""
    G = table_u.shape[1]
    g = -1
    if j == n_table - 1:
        g = _best_other(score, top_g, j, DISTINCT, u_ref, sw, table_u)
    if g < 0:
        g = _best_other(score, top_g, j, ANY, u_ref, sw, table_u)
    top_g[j] = G if g < 0 else g  # (a table of one entry: u_ref again)
    _entry(top_g[j], u_ref, table_u, out)


@hot_kernel
def _best_other(score, top_g, j, distinct, u_ref, sw, table_u):  # type: ignore[no-untyped-def]
    """The best-scored start (column of ``score``, G + 1) not among ``top_g[:j]``, and, when
    ``distinct``, at least :data:`DISTINCT_START` from each of them in some scaled unknown;
    -1 if none."""
    m, G = table_u.shape
    best = -np.inf
    pick = -1
    for g in range(G + 1):
        if not score[g] > best:  # (and never a NaN score)
            continue
        ok = True
        for i in range(j):
            h = top_g[i]
            if h == g:
                ok = False
                break
            if distinct:
                far = 0.0
                for v in range(m):
                    a = u_ref[v] if g == G else table_u[v, g]
                    c = u_ref[v] if h == G else table_u[v, h]
                    far = max(far, abs(a - c) * sw[v])
                if far < DISTINCT_START:
                    ok = False
                    break
        if ok:
            best = score[g]
            pick = g
    return pick
