"""The gaze kernels as plain Python until their compiled code is in numba's cache.

A kernel's Python function gives the same answer, bit for bit, as its compiled code: about 2 ms a
target instead of about 10 us, and nothing to compile. The first use after an install would
otherwise compile the solve for about 35 s on a 2-core machine. So:

- a command that solves a few targets (``cpc2urdf gaze``, ``check --gaze-report``) runs the Python
  functions when the cache does not hold the compiled solve (:func:`run_interpreted`);
- a solver built in Python (:func:`cpc2urdf.gaze_solver`) starts a process that compiles the solve
  into the cache and solves with the Python functions meanwhile; its first solve after that
  process ends loads the compiled code (:func:`compile_in_background`, :func:`compiled_now`).

Switching swaps module attributes: every kernel is looked up by name in its module at each call,
so replacing the dispatchers of this package's modules by their Python functions (and back) changes
what every call runs.
"""

from __future__ import annotations

import os
import subprocess
import sys
import threading
from typing import Any

from numba.core.dispatcher import Dispatcher

# the kernels package: the gaze modules call kernels through it
_PACKAGE = __name__.rsplit(".", 1)[0]
_lock = threading.Lock()
_swapped: list[tuple[Any, str, Dispatcher]] = []  # (module, name, dispatcher) replaced by Python
_worker: subprocess.Popen[bytes] | None = None
WARM = "cpc2urdf.validation.gaze.warm"  # the module the background process runs
NOTICE = (
    "gaze: first use: solving with the Python kernels (~2 ms a target) while the compiled ones "
    "(~10 us) are built in the background and cached"
)


def compiled() -> bool:
    """True when numba's cache holds the compiled solve (any run after the first)."""
    from cpc2urdf.validation.gaze.kernels import flat

    return os.path.exists(flat._solve_rows._cache._cache_file._index_path)  # numba's layout: tested


def run_interpreted() -> None:
    """Every kernel runs as its Python function from now on (until :func:`compiled_now` or
    :func:`run_compiled`). The package's ``__init__`` has loaded every kernel module, and the gaze
    modules reach kernels only as attributes of this package (``kernels.solve_flat``)."""
    with _lock:
        if _swapped:
            return
        for name, module in list(sys.modules.items()):
            if module is None or not (name == _PACKAGE or name.startswith(_PACKAGE + ".")):
                continue
            for key, value in list(vars(module).items()):
                if isinstance(value, Dispatcher):
                    _swapped.append((module, key, value))
                    setattr(module, key, value.py_func)


def compile_in_background() -> None:
    """Start a process that compiles the solve into numba's cache; solve in Python meanwhile.

    Nothing to do when the cache holds the compiled solve. ``CPC2URDF_GAZE_FIRST_USE`` in the
    environment chooses otherwise: ``compile`` compiles in this process on the first solve (the
    tests do), ``python`` solves in Python and compiles nothing."""
    global _worker
    mode = os.environ.get("CPC2URDF_GAZE_FIRST_USE", "background")
    if _worker is not None or _swapped or mode == "compile" or compiled():
        return
    if mode != "python":
        env = {**os.environ, "CPC2URDF_GAZE_FIRST_USE": "compile", "CPC2URDF_PROGRESS": "0"}
        _worker = subprocess.Popen(
            [sys.executable, "-m", WARM],
            stdin=subprocess.DEVNULL,
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        if os.environ.get("CPC2URDF_PROGRESS", "1") != "0":
            print(NOTICE, file=sys.stderr)
    run_interpreted()


def compiled_now() -> bool:
    """Back to the compiled kernels once the background compile has ended (True when compiled)."""
    global _worker
    if not _swapped:
        return True
    if _worker is None or _worker.poll() is None:  # still compiling, or Python by choice
        return False
    run_compiled()
    return True


def run_compiled() -> None:
    """Back to the compiled kernels now (they compile on their next call if the cache lacks them)."""
    global _worker
    with _lock:
        for module, key, dispatcher in _swapped:
            setattr(module, key, dispatcher)
        _swapped.clear()
    _worker = None
