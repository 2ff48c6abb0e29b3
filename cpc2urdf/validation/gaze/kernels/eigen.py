"""Eigen-decomposition of the step's small symmetric matrices by cyclic Jacobi rotations (compiled).

Small ``f`` (the unknowns of a head, or two rows a camera): cheaper than a LAPACK call and
allocation-free. ``f = 4`` (``J_x J_x^T`` on every binocular head) and ``f = 2`` (one camera's) run
in scalars (:func:`_jacobi4`, :func:`_jacobi2`), the same rotations as :func:`_jacobi_any` bit for
bit (up to the sign of a zero, which a solve's ``H``, sums from ``0.0``, never holds).
"""

from __future__ import annotations

import math

import numpy as np

from cpc2urdf.validation.gaze.kernels._jit import hot_kernel, inline_kernel, internal_kernel


@internal_kernel
def jacobi_eigh(H, f, lam, V):  # type: ignore[no-untyped-def]
    """Eigen-decomposition of the symmetric ``H[:f, :f]`` (destroyed): ``lam[:f]`` ascending,
    eigenvectors in the columns of ``V[:f, :f]``. A sweep visits the pairs in round-robin order:
    each round's pairs are disjoint, so the processor overlaps their divisions and square roots; the
    order is a relabelling of the row order's pairs and converges like it, quadratically."""
    if f == 4:
        _jacobi4(H, lam, V)
    elif f == 2:
        _jacobi2(H, lam, V)
    else:
        _jacobi_any(H, f, lam, V)


@inline_kernel
def _jacobi_any(H, f, lam, V):  # type: ignore[no-untyped-def]
    """:func:`jacobi_eigh` for any ``f`` (arrays and loops)."""
    for i in range(f):
        for j in range(f):
            V[i, j] = 1.0 if i == j else 0.0
    n = f + (f & 1)  # players of the round-robin (a dummy one when f is odd)
    for _ in range(50):
        off = 0.0
        diag = 0.0
        for i in range(f):
            diag += H[i, i] * H[i, i]
            for j in range(i + 1, f):
                off += H[i, j] * H[i, j]
        if (
            off <= 1e-24 * diag or off == 0.0
        ):  # off-diagonal at 1e-12 of the diagonal (a Newton step needs no more)
            break
        tiny = (
            1e-24 * diag / (f * f)
        )  # elements this small cannot keep the test above from passing: not rotated
        # the circle method: player n - 1 fixed, the others turning; round r pairs (r, n - 1)
        # and ((r + i) mod (n - 1), (r - i) mod (n - 1)), i = 1 .. n/2 - 1
        for r in range(n - 1):
            if n == f:  # (no dummy player)
                _rotate_pair(H, V, f, r, n - 1, tiny)
            for i in range(1, n // 2):
                a = (r + i) % (n - 1)
                c = (r - i + n - 1) % (n - 1)
                _rotate_pair(H, V, f, min(a, c), max(a, c), tiny)
    for i in range(f):
        lam[i] = H[i, i]
    _sort_eigen(lam, V, f)


@hot_kernel
def _jacobi_angle(hpp, hqq, hpq, tiny):  # type: ignore[no-untyped-def]
    """The rotation that zeroes ``hpq`` between the diagonal entries ``hpp``, ``hqq`` as
    ``(cos, sin, tan, keep)``: ``tan`` of the smaller angle (Numerical Recipes' ``theta`` form, no
    overflow); ``keep`` 0. Where ``hpq^2 <= tiny``, none: ``(1, 0, 0, 1)``."""
    if hpq * hpq <= tiny:
        return 1.0, 0.0, 0.0, 1.0
    theta = (hqq - hpp) / (2.0 * hpq)
    tt = (1.0 if theta >= 0 else -1.0) / (abs(theta) + math.sqrt(theta * theta + 1.0))
    t2 = tt * tt
    if t2 < 1.1102230246251565e-16:  # 1 + t^2 rounds to 1: cos is exactly 1 (as computed below)
        return 1.0, tt, tt, 0.0
    cs = 1.0 / math.sqrt(t2 + 1.0)
    return cs, tt * cs, tt, 0.0


@hot_kernel
def _rotate_pair(H, V, f, a, c, tiny):  # type: ignore[no-untyped-def]
    """One rotation of :func:`jacobi_eigh` (``a < c``; :func:`_jacobi_angle`). It touches rows and
    columns ``a`` and ``c`` only: the pivot's two diagonal entries in closed form, the others in
    pairs (a third of the updates of rotating all of H's rows and columns)."""
    cs, sn, tt, keep = _jacobi_angle(H[a, a], H[c, c], H[a, c], tiny)
    if keep == 1.0:
        return
    hac = H[a, c]
    H[a, a] -= tt * hac
    H[c, c] += tt * hac
    H[a, c] = 0.0
    H[c, a] = 0.0
    for k in range(f):
        if k != a and k != c:
            hka, hkc = H[k, a], H[k, c]
            H[k, a] = cs * hka - sn * hkc
            H[k, c] = sn * hka + cs * hkc
            H[a, k] = H[k, a]
            H[c, k] = H[k, c]
    for k in range(f):
        vka, vkc = V[k, a], V[k, c]
        V[k, a] = cs * vka - sn * vkc
        V[k, c] = sn * vka + cs * vkc


@inline_kernel
def _jacobi4(H, lam, V):  # type: ignore[no-untyped-def]
    """:func:`jacobi_eigh` of a 4 x 4 ``H`` (the step's ``J_x J_x^T`` on every binocular head) in
    scalars: the same rotations in the same order as :func:`_jacobi_any`, bit for bit, without
    its indexing, short inner loops and branches. Written out by a generator (the round-robin
    order below); tests/test_gaze_heads.py checks it against :func:`_jacobi_any`."""
    h00, h01, h02, h03 = H[0, 0], H[0, 1], H[0, 2], H[0, 3]
    h11, h12, h13 = H[1, 1], H[1, 2], H[1, 3]
    h22, h23 = H[2, 2], H[2, 3]
    h33 = H[3, 3]
    v00, v01, v02, v03 = 1.0, 0.0, 0.0, 0.0
    v10, v11, v12, v13 = 0.0, 1.0, 0.0, 0.0
    v20, v21, v22, v23 = 0.0, 0.0, 1.0, 0.0
    v30, v31, v32, v33 = 0.0, 0.0, 0.0, 1.0
    for _ in range(50):
        off = h01 * h01 + h02 * h02 + h03 * h03 + h12 * h12 + h13 * h13 + h23 * h23
        diag = h00 * h00 + h11 * h11 + h22 * h22 + h33 * h33
        if off <= 1e-24 * diag or off == 0.0:
            break
        tiny = 1e-24 * diag / 16.0
        cs, sn, tt, keep = _jacobi_angle(h00, h33, h03, tiny)  # pair (0, 3)
        h00, h33, h03 = h00 - tt * h03, h33 + tt * h03, keep * h03
        h01, h13 = cs * h01 - sn * h13, sn * h01 + cs * h13
        h02, h23 = cs * h02 - sn * h23, sn * h02 + cs * h23
        v00, v03 = cs * v00 - sn * v03, sn * v00 + cs * v03
        v10, v13 = cs * v10 - sn * v13, sn * v10 + cs * v13
        v20, v23 = cs * v20 - sn * v23, sn * v20 + cs * v23
        v30, v33 = cs * v30 - sn * v33, sn * v30 + cs * v33
        cs, sn, tt, keep = _jacobi_angle(h11, h22, h12, tiny)  # pair (1, 2)
        h11, h22, h12 = h11 - tt * h12, h22 + tt * h12, keep * h12
        h01, h02 = cs * h01 - sn * h02, sn * h01 + cs * h02
        h13, h23 = cs * h13 - sn * h23, sn * h13 + cs * h23
        v01, v02 = cs * v01 - sn * v02, sn * v01 + cs * v02
        v11, v12 = cs * v11 - sn * v12, sn * v11 + cs * v12
        v21, v22 = cs * v21 - sn * v22, sn * v21 + cs * v22
        v31, v32 = cs * v31 - sn * v32, sn * v31 + cs * v32
        cs, sn, tt, keep = _jacobi_angle(h11, h33, h13, tiny)  # pair (1, 3)
        h11, h33, h13 = h11 - tt * h13, h33 + tt * h13, keep * h13
        h01, h03 = cs * h01 - sn * h03, sn * h01 + cs * h03
        h12, h23 = cs * h12 - sn * h23, sn * h12 + cs * h23
        v01, v03 = cs * v01 - sn * v03, sn * v01 + cs * v03
        v11, v13 = cs * v11 - sn * v13, sn * v11 + cs * v13
        v21, v23 = cs * v21 - sn * v23, sn * v21 + cs * v23
        v31, v33 = cs * v31 - sn * v33, sn * v31 + cs * v33
        cs, sn, tt, keep = _jacobi_angle(h00, h22, h02, tiny)  # pair (0, 2)
        h00, h22, h02 = h00 - tt * h02, h22 + tt * h02, keep * h02
        h01, h12 = cs * h01 - sn * h12, sn * h01 + cs * h12
        h03, h23 = cs * h03 - sn * h23, sn * h03 + cs * h23
        v00, v02 = cs * v00 - sn * v02, sn * v00 + cs * v02
        v10, v12 = cs * v10 - sn * v12, sn * v10 + cs * v12
        v20, v22 = cs * v20 - sn * v22, sn * v20 + cs * v22
        v30, v32 = cs * v30 - sn * v32, sn * v30 + cs * v32
        cs, sn, tt, keep = _jacobi_angle(h22, h33, h23, tiny)  # pair (2, 3)
        h22, h33, h23 = h22 - tt * h23, h33 + tt * h23, keep * h23
        h02, h03 = cs * h02 - sn * h03, sn * h02 + cs * h03
        h12, h13 = cs * h12 - sn * h13, sn * h12 + cs * h13
        v02, v03 = cs * v02 - sn * v03, sn * v02 + cs * v03
        v12, v13 = cs * v12 - sn * v13, sn * v12 + cs * v13
        v22, v23 = cs * v22 - sn * v23, sn * v22 + cs * v23
        v32, v33 = cs * v32 - sn * v33, sn * v32 + cs * v33
        cs, sn, tt, keep = _jacobi_angle(h00, h11, h01, tiny)  # pair (0, 1)
        h00, h11, h01 = h00 - tt * h01, h11 + tt * h01, keep * h01
        h02, h12 = cs * h02 - sn * h12, sn * h02 + cs * h12
        h03, h13 = cs * h03 - sn * h13, sn * h03 + cs * h13
        v00, v01 = cs * v00 - sn * v01, sn * v00 + cs * v01
        v10, v11 = cs * v10 - sn * v11, sn * v10 + cs * v11
        v20, v21 = cs * v20 - sn * v21, sn * v20 + cs * v21
        v30, v31 = cs * v30 - sn * v31, sn * v30 + cs * v31
    lam[0], lam[1], lam[2], lam[3] = h00, h11, h22, h33
    V[0, 0], V[0, 1], V[0, 2], V[0, 3] = v00, v01, v02, v03
    V[1, 0], V[1, 1], V[1, 2], V[1, 3] = v10, v11, v12, v13
    V[2, 0], V[2, 1], V[2, 2], V[2, 3] = v20, v21, v22, v23
    V[3, 0], V[3, 1], V[3, 2], V[3, 3] = v30, v31, v32, v33
    _sort_eigen(lam, V, np.int64(4))  # not the literal: one compiled _sort_eigen


@inline_kernel
def _jacobi2(H, lam, V):  # type: ignore[no-untyped-def]
    """:func:`_jacobi4` for a 2 x 2 ``H`` (one camera's ``J_x J_x^T``). Its one rotation zeroes the
    only off-diagonal entry, so the general loops' second sweep always stops at its test: one
    test, at most one rotation (where the test fails, ``h01^2`` is above the skip threshold)."""
    h00, h01, h11 = H[0, 0], H[0, 1], H[1, 1]
    v00, v01, v10, v11 = 1.0, 0.0, 0.0, 1.0
    off = h01 * h01
    diag = h00 * h00 + h11 * h11
    if not (off <= 1e-24 * diag or off == 0.0):
        cs, sn, tt, keep = _jacobi_angle(h00, h11, h01, 1e-24 * diag / 4.0)  # pair (0, 1)
        h00, h11 = h00 - tt * h01, h11 + tt * h01
        v00, v01 = cs * v00 - sn * v01, sn * v00 + cs * v01
        v10, v11 = cs * v10 - sn * v11, sn * v10 + cs * v11
    lam[0], lam[1] = h00, h11
    V[0, 0], V[0, 1] = v00, v01
    V[1, 0], V[1, 1] = v10, v11
    _sort_eigen(lam, V, np.int64(2))


@hot_kernel
def _sort_eigen(lam, V, f):  # type: ignore[no-untyped-def]
    """``lam[:f]`` ascending by insertion sort, the columns of ``V[:f, :f]`` with them."""
    for i in range(1, f):
        j = i
        while j > 0 and lam[j - 1] > lam[j]:
            lam[j - 1], lam[j] = lam[j], lam[j - 1]
            for k in range(f):
                V[k, j - 1], V[k, j] = V[k, j], V[k, j - 1]
            j -= 1


@hot_kernel
def _product(A, B, out, n):  # type: ignore[no-untyped-def]
    """``out[:n, :n] = A[:n, :n] B[:n, :n]``."""
    for a in range(n):
        for c in range(n):
            s = 0.0
            for k in range(n):
                s += A[a, k] * B[k, c]
            out[a, c] = s


@inline_kernel
def _eigh_warm(H, n, lam, V, Vp, Hb, warm, keep):  # type: ignore[no-untyped-def]
    """:func:`jacobi_eigh` of ``H[:n, :n]``, warm-started from the eigenvectors in ``Vp`` when
    ``warm`` (the last step's, every unknown free): in that basis ``H`` is nearly diagonal, so the
    sweeps are few, and the eigenvectors are then ``Vp`` times those found. ``keep``: ``Vp``
    takes the result (for the next step's warm start)."""
    if warm:
        _product(H, Vp, Hb, n)
        for a in range(n):  # H = Vp^T (H Vp), symmetric
            for c in range(a, n):
                s = 0.0
                for k in range(n):
                    s += Vp[k, a] * Hb[k, c]
                H[a, c] = s
                H[c, a] = s
    jacobi_eigh(H, n, lam, V)
    if warm:
        _product(Vp, V, Hb, n)
        for a in range(n):
            for c in range(n):
                V[a, c] = Hb[a, c]
    if keep:
        for a in range(n):
            for c in range(n):
                Vp[a, c] = V[a, c]
