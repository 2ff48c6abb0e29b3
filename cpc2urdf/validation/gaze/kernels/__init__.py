"""The compiled core of the gaze solver (numba, cached across runs).

Modules, from the bottom up:

- :mod:`.constants`: tuning constants (one reason each), status codes, mode flags;
- :mod:`.kinematics`: the head as a :class:`~.kinematics.Chain` (:func:`pack`), forward kinematics, camera Jacobians;
- :mod:`.pointing`: the pointing residual and its Jacobian in each camera's tangent basis;
- :mod:`.eigen`: Jacobi eigen-decomposition of the step's small symmetric matrices;
- :mod:`.step`: one task-priority step (pointing, then the policy in the near-null space);
- :mod:`.iterate`: the iteration (active set, Anderson acceleration, line search);
- :mod:`.starts`: the table entries that best face a target;
- :mod:`.solve`: one target from its starts, and its status;
- :mod:`.flat`: the one compiled entry, over a head packed into two flat arrays;
- :mod:`.buffers`: the solve's scratch arrays, carved from two buffers.

What compiles: the first solve compiles :func:`~.flat._solve_rows` and the kernels below it once;
:func:`fk`, :func:`residual` and the workspace kernels are small. See ``_jit.py`` for why the solve
is one entry.
"""

from __future__ import annotations

from cpc2urdf.validation.gaze.kernels import _cache, _progress

_cache.install()  # before any kernel is defined: each is keyed on the whole package's source
_progress.install()  # a line on stderr while the kernels compile

import numpy as np  # noqa: E402
from numba import njit  # noqa: E402

from cpc2urdf.validation.gaze.kernels import buffers as _workspace_module  # noqa: E402
from cpc2urdf.validation.gaze.kernels import eigen as _eigen  # noqa: E402
from cpc2urdf.validation.gaze.kernels import flat as _flat  # noqa: E402
from cpc2urdf.validation.gaze.kernels import iterate as _iterate_module  # noqa: E402
from cpc2urdf.validation.gaze.kernels import pointing as _pointing  # noqa: E402
from cpc2urdf.validation.gaze.kernels import starts as _starts  # noqa: E402
from cpc2urdf.validation.gaze.kernels._jit import kernel, kernel_without_refcounts  # noqa: E402
from cpc2urdf.validation.gaze.kernels.buffers import Workspace, scratch, workspace  # noqa: E402
from cpc2urdf.validation.gaze.kernels.constants import *  # noqa: E402,F403
from cpc2urdf.validation.gaze.kernels.constants import (  # noqa: E402
    BACKTRACKS,
    BINOCULAR_NULL,
    DAMPING,
    DISTANCE_REACH,
    EXACT_RESIDUAL,
    FAR_TARGET,
    MAX_STEP,
    MIN_TARGET_DISTANCE,
    NEAR_FIXATION,
    POLICY_STEP_TOL,
    POLISH_ITERATIONS,
    POLISHED,
    PROBE_ITERATIONS,
    S_BEHIND,
    S_DISPARITY,
    S_FIXATED,
    S_LIMITS,
    S_NO_SOLUTION,
    S_NOT_FINITE,
    S_TOO_CLOSE,
    SECONDARY_GAIN,
    STATIONARY,
    STEP_TOL,
    STRUCTURAL_NULL,
)
from cpc2urdf.validation.gaze.kernels.flat import out_size, pack_flat, solve_flat, solve_flat_many  # noqa: E402
from cpc2urdf.validation.gaze.kernels.kinematics import fk, pack, pointing_error  # noqa: E402
from cpc2urdf.validation.gaze.kernels.pointing import residual  # noqa: E402
from cpc2urdf.validation.gaze.kernels.step import Problem  # noqa: E402

# Python-callable kernels over internal ones, for tests that call them one by one (compiled on their
# first call only; functions of their own, so that numba caches them apart from the internal ones)


@kernel
def _tangent(ux, uy, uz):  # type: ignore[no-untyped-def]
    return _pointing._tangent(ux, uy, uz)


@kernel
def _tangent_residual(r, s):  # type: ignore[no-untyped-def]
    return _pointing._tangent_residual(r, s)


@kernel
def jacobi_eigh(H, f, lam, V):  # type: ignore[no-untyped-def]
    _eigen.jacobi_eigh(H, f, lam, V)


@kernel
def _jacobi_any(H, f, lam, V):  # type: ignore[no-untyped-def]
    _eigen._jacobi_any(H, f, lam, V)


_sizes = _workspace_module.sizes_of
_carve_workspace = _workspace_module._carve_in_python
_carve_workspace_counted = njit(error_model="numpy")(_workspace_module._carve_workspace.py_func)


@njit(error_model="numpy")
def _new_workspace(n_float, n_int, sizes):  # type: ignore[no-untyped-def]
    return _carve_workspace_counted(np.empty(n_float), np.empty(n_int, dtype=np.int64), sizes)


def _workspace(K, C, S, m, G, n_top):  # type: ignore[no-untyped-def]
    """A :class:`Workspace` carved by numba from two buffers it allocates (the arrays' base is numba's
    MemInfo), started as :func:`~.buffers.scratch` starts one."""
    sizes = (int(K), int(C), int(S), int(m), int(G), int(n_top))
    f, ints = _workspace_module._started(sizes)
    ws = _new_workspace(f.size, ints.size, sizes)
    _workspace_module.start(ws)
    return ws


# the kernels that return views, as copies of their own with reference counting (not cached: the
# solve's copies, without it, are cached under the same name)
_unpack = njit(error_model="numpy")(_flat._unpack.py_func)


@kernel_without_refcounts
def best_starts(ch, p, b, u_ref, sw, table_u, table_o, table_z, out, ws):  # type: ignore[no-untyped-def]
    """:func:`~.starts.best_starts`."""
    _starts.best_starts(ch, p, b, u_ref, sw, table_u, table_o, table_z, out, ws)


@kernel_without_refcounts
def further_start(j, n_table, u_ref, sw, table_u, score, top_g, out):  # type: ignore[no-untyped-def]
    """:func:`~.starts.further_start`."""
    _starts.further_start(j, n_table, u_ref, sw, table_u, score, top_g, out)


@kernel_without_refcounts
def _iterate_problem(pb, u, gain, max_it, rr_at_u, ws):  # type: ignore[no-untyped-def]
    return _iterate_module._iterate(pb, u, gain, max_it, rr_at_u, ws)


def _iterate(ch, p, b, u, u_ref, lower, upper, sw, gain, null_rel, max_it, ws, rr_at_u):  # type: ignore[no-untyped-def]
    """The iteration (:func:`~.iterate._iterate`) with its problem given argument by argument."""
    return _iterate_problem(
        Problem(ch, p, b, u_ref, lower, upper, sw, float(null_rel)),
        u,
        float(gain),
        max_it,
        float(rr_at_u),
        ws,
    )


__all__ = [
    "BACKTRACKS",
    "BINOCULAR_NULL",
    "DAMPING",
    "DISTANCE_REACH",
    "EXACT_RESIDUAL",
    "FAR_TARGET",
    "MAX_STEP",
    "MIN_TARGET_DISTANCE",
    "NEAR_FIXATION",
    "POLICY_STEP_TOL",
    "POLISHED",
    "POLISH_ITERATIONS",
    "PROBE_ITERATIONS",
    "SECONDARY_GAIN",
    "STATIONARY",
    "STEP_TOL",
    "STRUCTURAL_NULL",
    "S_BEHIND",
    "S_DISPARITY",
    "S_FIXATED",
    "S_LIMITS",
    "S_NOT_FINITE",
    "S_NO_SOLUTION",
    "S_TOO_CLOSE",
    "Problem",
    "Workspace",
    "best_starts",
    "fk",
    "further_start",
    "out_size",
    "pack",
    "pack_flat",
    "pointing_error",
    "residual",
    "scratch",
    "solve_flat",
    "solve_flat_many",
    "workspace",
]
