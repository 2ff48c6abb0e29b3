"""The gaze kernels' first use: what compiles, once, and says so.

The solve compiles as one entry over one iteration (``kernels/_jit.py``); these tests keep that
shape (no kernel compiled twice for another signature), the workspace's two layouts (numba's and
Python's) equal, the cache keyed on the whole package, and the line on stderr while compiling.
``cpc2urdf bench first-use`` measures the first runs themselves (slow: minutes).
"""

from __future__ import annotations

import ast
import io
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from cpc2urdf.validation.gaze import kernels
from cpc2urdf.validation.gaze.kernels import _cache, _progress, buffers

KERNEL_DIR = Path(kernels.__file__).parent
COMPILED_APART = (
    "kernel",
    "kernel_without_refcounts",
    "internal_kernel",
    "hot_kernel",
    "view_kernel",
)


@pytest.mark.parametrize(
    "sizes", [(8, 2, 2, 6, 256, 4), (5, 1, 1, 4, 256, 4), (12, 3, 1, 9, 7, 1), (3, 2, 2, 2, 0, 0)]
)
def test_python_carves_the_workspace_as_the_kernels_do(sizes):
    """``workspace()`` and ``scratch()`` carve in Python (nothing to compile); the solve carves the
    same buffers in numba: every field the same view."""
    f, ints = buffers._buffers_in_python(sizes)
    ours = buffers._carve_in_python(f, ints, sizes)
    theirs = kernels._carve_workspace_counted(f, ints, sizes)
    for name, a, b in zip(kernels.Workspace._fields, ours, theirs, strict=True):
        assert a.shape == b.shape and a.dtype == b.dtype, name
        if a.size:
            assert a.__array_interface__["data"][0] == b.__array_interface__["data"][0], name
    assert np.isnan(ours.ref_key).all() and not ours.eig.any() and (ours.ones == 1.0).all()


def _calls_with_another_signature() -> list[str]:
    """Calls, inside the kernels' modules, of a kernel compiled apart (not inlined by numba) that
    would make numba compile another copy of it: an omitted argument (typed as its default), an
    integer constant or literal (typed as a literal), or a Python bool literal."""
    functions: dict[str, ast.FunctionDef] = {}
    apart: set[str] = set()
    trees = []
    for path in sorted(KERNEL_DIR.glob("*.py")):
        tree = ast.parse(path.read_text())
        trees.append(tree)
        for node in tree.body:
            if isinstance(node, ast.FunctionDef):
                functions[node.name] = node
                if any(
                    isinstance(d, ast.Name) and d.id in COMPILED_APART for d in node.decorator_list
                ):
                    apart.add(node.name)
    found = []
    for tree in trees:
        for fn in (n for n in tree.body if isinstance(n, ast.FunctionDef) and n.name in functions):
            if not fn.decorator_list:
                continue  # Python calls a kernel with its ints typed int64, never a literal
            for call in ast.walk(fn):
                if not (
                    isinstance(call, ast.Call)
                    and isinstance(call.func, ast.Name)
                    and call.func.id in apart
                ):
                    continue
                where = f"{fn.name} -> {call.func.id} (line {call.lineno})"
                n_params = len(functions[call.func.id].args.args)
                if len(call.args) != n_params or call.keywords:
                    found.append(f"{where}: {len(call.args)} of {n_params} arguments")
                for a in call.args:
                    if isinstance(a, ast.Constant) and type(a.value) in (int, bool):
                        found.append(f"{where}: the literal {a.value!r}")
    return found


def test_every_kernel_compiled_apart_gets_one_signature():
    """numba compiles a kernel once per argument signature, and types an omitted argument as its
    default and a Python int or bool literal as a literal: each a copy of the callee, compiled
    again (``_residual_hot`` once with ``True`` and once with ``False`` cost 2 s)."""
    assert _calls_with_another_signature() == []


def test_the_cache_is_keyed_on_every_module_of_the_package():
    """A kernel's machine code holds the code of the kernels it calls, in other files of the
    package: its cache entry is keyed, and named, on all of them."""
    stamp = _cache._package_stamp()
    assert isinstance(stamp, bytes) and len(stamp) == 32
    from numba.core import caching

    names = [c.__name__ for c in caching.CacheImpl._locator_classes]
    assert names[0].startswith("GazeKernels")  # before numba's own locators
    from cpc2urdf.validation.gaze.kernels import flat

    ours = [c for c in caching.CacheImpl._locator_classes if c.__name__.startswith("GazeKernels")]
    found = [c.from_function(flat._solve_rows.py_func, str(KERNEL_DIR / "flat.py")) for c in ours]
    found = [x for x in found if x is not None]
    assert found and all(x.get_source_stamp() == stamp for x in found)
    assert all(stamp.hex()[:12] in x.get_disambiguator() for x in found)
    assert all(
        c.from_function(len, __file__) is None for c in ours
    )  # another file: numba's own locators


def test_a_line_says_the_kernels_compile(monkeypatch):
    """A compile of this package's kernels that lasts longer than a moment prints a line on
    stderr, and its end another; a short one (a cache load is not a compile at all) prints none."""
    monkeypatch.setenv("CPC2URDF_PROGRESS", "1")
    monkeypatch.setattr(_progress, "DELAY", 0.01)
    err = io.StringIO()
    monkeypatch.setattr(sys, "stderr", err)
    notice = _progress._CompileNotice()
    ours = SimpleNamespace(data={"dispatcher": kernels.fk})
    other = SimpleNamespace(data={"dispatcher": SimpleNamespace(py_func=len)})
    notice.on_start(other)
    notice.on_end(other)
    assert err.getvalue() == ""
    notice.on_start(ours)
    notice.on_start(other)  # nested compiles inside ours
    import time

    time.sleep(0.1)
    notice.on_end(other)
    notice.on_end(ours)
    lines = err.getvalue().strip().splitlines()
    assert lines[0].startswith(_progress.LABEL) and "done in" in lines[-1]


@pytest.mark.slow
def test_first_use_script_times_a_command():
    """``cpc2urdf bench first-use --commands check`` runs (the cheapest command)."""
    done = subprocess.run(
        [sys.executable, "-m", "cpc2urdf.studies.first_use", "--commands", "check"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert "check" in done.stdout and "first" in done.stdout


# ---- the first use: the kernels as Python until the compiled ones are cached (kernels.interpreted) ----


@pytest.mark.parametrize("head", ["iis_head"])
def test_python_kernels_answer_as_the_compiled_ones_bit_for_bit(head):
    """The kernels' Python functions give the compiled answers exactly: one target, a batch,
    another policy; every kernel is a Python function meanwhile, and compiled again after."""
    from cpc2urdf.validation.gaze import solver_for
    from cpc2urdf.validation.gaze.kernels import interpreted

    solver = solver_for(head)
    targets = np.array(
        [[-0.6, -0.6, 0.7], [-0.5, -0.55, 0.8], [0.3, 2.0, -1.0], [-0.6, -0.6, 0.7001]]
    )
    compiled = [solver.solve(t).q for t in targets]
    compiled_many = solver.solve_many(targets).q
    compiled_mm = solver.solve(targets[1], solver.home, "min-motion").q
    assert interpreted.compiled()  # the solve above is in numba's cache now
    interpreted.run_interpreted()
    try:
        assert not hasattr(kernels.flat._solve_rows, "py_func")  # a plain function now
        assert interpreted.compiled_now() is False  # Python by choice: no compile running
        for t, q in zip(targets, compiled, strict=True):
            assert np.array_equal(solver.solve(t).q, q)
        assert np.array_equal(solver.solve_many(targets).q, compiled_many)
        assert np.array_equal(solver.solve(targets[1], solver.home, "min-motion").q, compiled_mm)
    finally:
        interpreted.run_compiled()
    assert hasattr(kernels.flat._solve_rows, "py_func")


def test_first_cli_gaze_solves_in_python_and_compiles_nothing(tmp_path):
    """A fresh install (an empty numba cache) with ``CPC2URDF_GAZE_FIRST_USE=python``: ``cpc2urdf
    gaze`` answers as the compiled solver does and writes nothing to the cache. (By default it also
    starts the background compile: ``cpc2urdf bench first-use`` times that.)"""
    import os

    from cpc2urdf.validation.gaze import solver_for

    env = {
        **os.environ,
        "NUMBA_CACHE_DIR": str(tmp_path / "cache"),
        "CPC2URDF_GAZE_FIRST_USE": "python",
    }
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "cpc2urdf",
            "gaze",
            "iis_head",
            "--target",
            "-0.6",
            "-0.6",
            "0.7",
            "--json",
        ],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
        check=True,
    )
    import json

    q = list(json.loads(out.stdout)["joints"].values())  # repr of floats: exact
    assert np.array_equal(np.array(q), solver_for("iis_head").solve(np.array([-0.6, -0.6, 0.7])).q)
    assert not any((tmp_path / "cache").rglob("*.nbi"))  # nothing compiled
