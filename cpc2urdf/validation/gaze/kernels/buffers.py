"""The solve's scratch arrays: views carved from one float and one int buffer (compiled).

A solve allocates nothing: every array it writes is a field of a :class:`Workspace`, carved from two
buffers (:func:`scratch`) that ``CompiledGaze`` keeps one pair of per thread. The buffers also keep,
from target to target, :func:`~.starts.best_starts`' cache of the reference posture.
"""

from __future__ import annotations

import functools
import math
from collections import namedtuple
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cpc2urdf.validation.gaze.chain import HeadChain
from cpc2urdf.validation.gaze.kernels._jit import view_kernel
from cpc2urdf.validation.gaze.kernels.constants import HISTORY

#: The workspace of one solve, for a head of K joints, C cameras, S solved axes, m unknowns, G table
#: entries and n_top starts per target (``M = 2 S`` Jacobian rows).
#:
#: - FK and residual: ``JR`` (K, 3, 3), ``Jp``, ``Ja`` (K, 3), ``CR`` (C, 3, 3), ``Co`` (C, 3),
#:   ``Jc`` (6, K), ``Pc`` (S, 5 + m) (each solved camera's view of the target), ``r`` (3 S,),
#:   ``J`` (M, m), and a trial's ``r2``, ``J2``;
#: - the step: ``g`` (m,), ``H``, ``V`` (m, m), ``lam``, ``idx``, ``free``, ``dx``, ``trial`` (m,),
#:   ``Hb``, ``Vp`` (m, m); the iteration's flags ``eig`` (3,) (see constants ``EIG_*``), last step
#:   ``s_prev``, probe target ``u_near``, acceleration history ``acc`` (4 HISTORY + 2, m);
#: - the starts: ``u``, ``score`` (G + 1,), ``top_g`` (n_top,);
#: - one target: the aim point ``ps``, readings offset ``b`` (K,), ``u_ref``, ``u_start``, ``starts``
#:   (n_top, m), the answer ``u_out``, ``e_out`` (S,), the kept answers ``u1``, ``e1``,
#:   ``best_start``, ``u2``, ``e2``, equal weights ``ones``, the rows step's scratch ``null_z``,
#:   ``null_c``;
#: - best_starts' cache: ``ref_key`` (m + K,), ``ref_axis`` (6,), ``ref_cost`` (G,); and
#:   ``vw_plain`` (4,), the tasks of the chain without its zero-version task.
Workspace = namedtuple(
    "Workspace",
    "JR Jp Ja CR Co Jc Pc r J r2 J2 g H V lam idx free dx trial Hb Vp eig s_prev u_near acc u score top_g ps b"
    " u_ref u_start starts u_out e_out u1 e1 best_start u2 e2 ones null_z null_c ref_key ref_axis ref_cost"
    " vw_plain",
)


@view_kernel
def _sizes(I):  # type: ignore[no-untyped-def]
    """``(K, C, S, m, G, n_top)`` of a workspace for the packed head whose ints are ``I``
    (:func:`~.flat.pack_flat`)."""
    return I[0], I[1], I[2], I[3], I[4], I[6] + 1


@view_kernel
def _carve_workspace(f, ints, sizes):  # type: ignore[no-untyped-def]
    """The :class:`Workspace` as views of the float buffer ``f`` and the int buffer ``ints`` for
    ``sizes`` (:func:`_sizes`); nothing written or allocated (~0.5 us a call)."""
    K, C, S, m, G, n_top = sizes
    M = 2 * S
    o = 0
    JR = f[o : o + 9 * K]
    o += 9 * K
    Jp = f[o : o + 3 * K]
    o += 3 * K
    Ja = f[o : o + 3 * K]
    o += 3 * K
    CR = f[o : o + 9 * C]
    o += 9 * C
    Co = f[o : o + 3 * C]
    o += 3 * C
    Jc = f[o : o + 6 * K]
    o += 6 * K
    Pc = f[o : o + (5 + m) * S]
    o += (5 + m) * S
    r = f[o : o + 3 * S]
    o += 3 * S
    J = f[o : o + M * m]
    o += M * m
    r2 = f[o : o + 3 * S]
    o += 3 * S
    J2 = f[o : o + M * m]
    o += M * m
    g = f[o : o + m]
    o += m
    H = f[o : o + m * m]
    o += m * m
    V = f[o : o + m * m]
    o += m * m
    lam = f[o : o + m]
    o += m
    dx = f[o : o + m]
    o += m
    trial = f[o : o + m]
    o += m
    Hb = f[o : o + m * m]
    o += m * m
    Vp = f[o : o + m * m]
    o += m * m
    eig = f[o : o + 3]
    o += 3
    s_prev = f[o : o + m]
    o += m
    u_near = f[o : o + m]
    o += m
    acc = f[o : o + (4 * HISTORY + 2) * m]
    o += (4 * HISTORY + 2) * m
    u = f[o : o + m]
    o += m
    score = f[o : o + G + 1]
    o += G + 1
    ps = f[o : o + 3]
    o += 3
    b = f[o : o + K]
    o += K
    u_ref = f[o : o + m]
    o += m
    u_start = f[o : o + m]
    o += m
    starts = f[o : o + n_top * m]
    o += n_top * m
    u_out = f[o : o + m]
    o += m
    e_out = f[o : o + S]
    o += S
    u1 = f[o : o + m]
    o += m
    e1 = f[o : o + S]
    o += S
    best_start = f[o : o + m]
    o += m
    u2 = f[o : o + m]
    o += m
    e2 = f[o : o + S]
    o += S
    ones = f[o : o + m]
    o += m
    null_z = f[o : o + m]
    o += m
    null_c = f[o : o + m]
    o += m
    ref_key = f[o : o + m + K]
    o += m + K
    ref_axis = f[o : o + 6]
    o += 6
    ref_cost = f[o : o + G]
    o += G
    vw_plain = f[o : o + 4]
    o += 4
    return Workspace(
        JR.reshape((K, 3, 3)),
        Jp.reshape((K, 3)),
        Ja.reshape((K, 3)),
        CR.reshape((C, 3, 3)),
        Co.reshape((C, 3)),
        Jc.reshape((6, K)),
        Pc.reshape((S, 5 + m)),
        r,
        J.reshape((M, m)),
        r2,
        J2.reshape((M, m)),
        g,
        H.reshape((m, m)),
        V.reshape((m, m)),
        lam,
        ints[0:m],
        ints[m + n_top : m + n_top + m],
        dx,
        trial,
        Hb.reshape((m, m)),
        Vp.reshape((m, m)),
        eig,
        s_prev,
        u_near,
        acc.reshape((4 * HISTORY + 2, m)),
        u,
        score,
        ints[m : m + n_top],
        ps,
        b,
        u_ref,
        u_start,
        starts.reshape((n_top, m)),
        u_out,
        e_out,
        u1,
        e1,
        best_start,
        u2,
        e2,
        ones,
        null_z,
        null_c,
        ref_key,
        ref_axis,
        ref_cost,
        vw_plain,
    )


# The float buffer's fields in their order, with their shapes, for the Python side (nothing to
# compile): the same layout as :func:`_carve_workspace` (tests/test_first_use.py checks it).
_FLOATS = (
    ("JR", "K 3 3"),
    ("Jp", "K 3"),
    ("Ja", "K 3"),
    ("CR", "C 3 3"),
    ("Co", "C 3"),
    ("Jc", "6 K"),
    ("Pc", "S 5+m"),
    ("r", "3S"),
    ("J", "M m"),
    ("r2", "3S"),
    ("J2", "M m"),
    ("g", "m"),
    ("H", "m m"),
    ("V", "m m"),
    ("lam", "m"),
    ("dx", "m"),
    ("trial", "m"),
    ("Hb", "m m"),
    ("Vp", "m m"),
    ("eig", "3"),
    ("s_prev", "m"),
    ("u_near", "m"),
    ("acc", "A m"),
    ("u", "m"),
    ("score", "G+1"),
    ("ps", "3"),
    ("b", "K"),
    ("u_ref", "m"),
    ("u_start", "m"),
    ("starts", "T m"),
    ("u_out", "m"),
    ("e_out", "S"),
    ("u1", "m"),
    ("e1", "S"),
    ("best_start", "m"),
    ("u2", "m"),
    ("e2", "S"),
    ("ones", "m"),
    ("null_z", "m"),
    ("null_c", "m"),
    ("ref_key", "m+K"),
    ("ref_axis", "6"),
    ("ref_cost", "G"),
    ("vw_plain", "4"),
)
_INTS = (("idx", "m"), ("top_g", "T"), ("free", "m"))  # the int buffer's fields in their order


def _shapes(
    fields: tuple[tuple[str, str], ...], sizes: tuple[int, ...]
) -> list[tuple[str, tuple[int, ...]]]:
    """Each field's shape for ``sizes`` ``(K, C, S, m, G, n_top)``."""
    K, C, S, m, G, n_top = sizes
    dims = {
        "K": K,
        "C": C,
        "S": S,
        "m": m,
        "M": 2 * S,
        "3S": 3 * S,
        "5+m": 5 + m,
        "G+1": G + 1,
        "G": G,
        "T": n_top,
        "m+K": m + K,
        "A": 4 * HISTORY + 2,
    }
    return [
        (name, tuple(dims[d] if d in dims else int(d) for d in shape.split()))
        for name, shape in fields
    ]


def _carve_in_python(
    f: NDArray[np.float64], ints: NDArray[np.int64], sizes: tuple[int, ...]
) -> Workspace:
    """:func:`_carve_workspace` with numpy views."""
    views = {}
    for buf, fields in ((f, _FLOATS), (ints, _INTS)):
        o = 0
        for name, shape in _shapes(fields, sizes):
            n = int(np.prod(shape))
            views[name] = buf[o : o + n].reshape(shape)
            o += n
    return Workspace(**views)


def start(ws: Workspace) -> None:
    """The values a workspace starts with: no reference posture cached, no warm eigenvectors, equal
    weights."""
    ws.ref_key[:] = np.nan
    ws.eig[:] = 0.0
    ws.ones[:] = 1.0


@functools.cache
def _started(sizes: tuple[int, ...]) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """The two buffers of a started workspace of ``sizes``, carved once: a template to copy."""
    n_float = sum(math.prod(shape) for _, shape in _shapes(_FLOATS, sizes))
    n_int = sum(math.prod(shape) for _, shape in _shapes(_INTS, sizes))
    f, ints = np.zeros(n_float), np.zeros(n_int, dtype=np.int64)
    start(_carve_in_python(f, ints, sizes))
    return f, ints


def _buffers_in_python(sizes: tuple[int, ...]) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """The two buffers (float, int) of a started workspace of ``sizes`` (:func:`start`)."""
    f, ints = _started(sizes)
    return f.copy(), ints.copy()


def sizes_of(I: NDArray[Any]) -> tuple[int, int, int, int, int, int]:
    """``(K, C, S, m, G, n_top)`` of a workspace for the packed head whose ints are ``I``."""
    return int(I[0]), int(I[1]), int(I[2]), int(I[3]), int(I[4]), int(I[6]) + 1


def scratch(I: NDArray[Any]) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """The two buffers (float, int) of a workspace for the packed head whose ints are ``I``
    (:func:`~.flat.pack_flat`): what :func:`~.flat.solve_flat` carves its workspace from."""
    return _buffers_in_python(sizes_of(I))


def workspace(chain: HeadChain) -> Workspace:
    """A :class:`Workspace` for :func:`~.kinematics.fk` and :func:`~.pointing.residual` on ``chain``."""
    sizes = (len(chain.parent), len(chain.cam_parent), len(chain.solve_cameras), chain.m, 0, 0)
    return _carve_in_python(*_buffers_in_python(sizes), sizes)


__all__ = ["Workspace", "scratch", "workspace"]
