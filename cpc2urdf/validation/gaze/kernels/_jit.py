"""The ways the gaze kernels are compiled (numba, ``cache=True``, IEEE division, no GIL).

numba compiles every kernel a kernel calls into a library of its own and links a copy of its code
into the caller's, which LLVM optimises and emits again: each level of a chain of kernels compiles
the code below it once more. So the solve is one compiled entry (:func:`~.flat._solve_rows`, for one
target and for a batch) over one compiled iteration (:func:`~.iterate._iterate`), and what lies
between them is inlined by numba before typing (``inline_kernel``). numba's inlining copies the
callee's IR and types the grown caller again, which costs more the bigger the caller, so the
iteration stays a library of its own. Internal kernels carry no Python wrappers (a wrapper of a
kernel taking the workspace unboxes its 47 arrays).
"""

from __future__ import annotations

from typing import Any

from numba import njit

_BASE: dict[str, Any] = {"cache": True, "error_model": "numpy", "nogil": True}
_INTERNAL: dict[str, Any] = {**_BASE, "no_cpython_wrapper": True, "no_cfunc_wrapper": True}

# kernels called from Python: cached across runs; IEEE division (every division that matters is
# guarded); the GIL released (a batch is split over threads, one per core)
kernel = njit(**_BASE)
# the solve's entry, which allocates nothing and returns no array: without numba's reference
# counting (its atomic increments on every array of the workspace cost a quarter of a solve). A
# kernel compiled so must not call one that returns a new array: nothing would release it.
kernel_without_refcounts = njit(**_BASE, _nrt=False)  # type: ignore[call-overload]
# the solve's own libraries below the entry (the iteration, the eigen-decomposition, the starts)
internal_kernel = njit(**_INTERNAL, _nrt=False)  # type: ignore[call-overload]
# the parts of the solve called from one place: inlined by numba into their caller before typing
inline_kernel = njit(**_INTERNAL, inline="always")
# small helpers called from several places: a library each, inlined by LLVM (a call passing the
# chain's arrays would cost as much as their arithmetic)
hot_kernel = njit(**_INTERNAL, forceinline=True)
# the helpers that return views (of the workspace's buffers, of the packed head) inside the solve.
# Set, not inherited: numba compiles a kernel that does not set _nrt with its first caller's flag and
# reuses that copy for every caller, and a copy without reference counting that returns a view to a
# caller with it corrupts the heap. So these are only ever called from the solve.
view_kernel = njit(**_INTERNAL, forceinline=True, _nrt=False)  # type: ignore[call-overload]
