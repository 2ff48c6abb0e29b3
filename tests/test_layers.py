"""The package's layers point one way, and no modules import each other in a cycle.

Layers, lowest first (docs/architecture.md):

    core            cpc2urdf/*.py (model, transforms, errors, ...), cpc2urdf.files, cpc2urdf.urdf
                    and cpc2urdf.robots
    identification  kinematics, vision  <  handeye, selfcal  <  simulation  <  planning
    validation      crosscheck, accuracy, gaze, view (what uses the calibrated URDF)
    api             cpc2urdf.api and the package's __init__ (re-exports the api)
    studies         cpc2urdf.studies (experiments, benchmarks)
    cli             cpc2urdf.cli, cpc2urdf.__main__

A module may import its own subpackage and anything in a lower layer; inside the identification
layer, only the listed direction. Imports inside functions count: hiding an upward edge in a
function body is exactly what this test is for.
"""

from __future__ import annotations

import ast
from collections.abc import Iterable
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "cpc2urdf"

# (subpackage or module, rank, unit): the longest matching name wins; any other module of the
# package is core. Modules of one unit may import each other; otherwise the imported module's rank
# must be strictly lower.
RULES: list[tuple[str, tuple[int, int], str]] = [
    ("cpc2urdf.identification.kinematics", (1, 0), "kinematics"),
    ("cpc2urdf.identification.vision", (1, 0), "vision"),
    ("cpc2urdf.identification.handeye", (1, 1), "handeye"),
    ("cpc2urdf.identification.selfcal", (1, 1), "selfcal"),
    ("cpc2urdf.identification.simulation", (1, 2), "simulation"),
    ("cpc2urdf.identification.planning", (1, 3), "planning"),
    ("cpc2urdf.identification", (1, 0), "identification"),
    ("cpc2urdf.validation", (2, 0), "validation"),
    ("cpc2urdf.api", (3, 0), "api"),
    ("cpc2urdf.studies", (4, 0), "studies"),
    ("cpc2urdf.cli", (5, 0), "cli"),
    ("cpc2urdf.__main__", (5, 0), "cli"),
]
CORE = ((0, 0), "core")
API = ((3, 0), "api")  # the package's own __init__: it re-exports cpc2urdf.api


def layer_of(module: str) -> tuple[tuple[int, int], str]:
    if module == "cpc2urdf":
        return API
    for name, rank, unit in sorted(RULES, key=lambda r: -len(r[0])):
        if module == name or module.startswith(name + "."):
            return rank, unit
    return CORE


def module_name(path: Path) -> str:
    rel = path.relative_to(PACKAGE.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def known_modules() -> set[str]:
    return {module_name(p) for p in PACKAGE.rglob("*.py")}


def imports_of(module: str, source: str, is_package: bool, modules: set[str]) -> set[str]:
    """Our modules that ``source`` imports anywhere (top level or inside functions)."""
    out: set[str] = set()
    package = module if is_package else module.rpartition(".")[0]
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")
                anchor = anchor[: len(anchor) - (node.level - 1)]
                base = ".".join([*anchor, base] if base else anchor)
            # `from pkg import sub` imports the submodule when one exists, else a name of pkg.
            names = [
                f"{base}.{a.name}" if f"{base}.{a.name}" in modules else base for a in node.names
            ]
        else:
            continue
        for name in names:
            while name and name not in modules:
                name = name.rpartition(".")[0]
            if name.startswith("cpc2urdf") and name != module:
                out.add(name)
    return out


def import_graph(extra: Iterable[tuple[str, str, bool]] = ()) -> dict[str, set[str]]:
    """Module -> our modules it imports; ``extra`` adds (module, source, is_package) to scan."""
    modules = known_modules() | {m for m, _, _ in extra}
    graph: dict[str, set[str]] = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        m = module_name(path)
        graph[m] = imports_of(m, path.read_text(), path.name == "__init__.py", modules)
    for m, src, is_pkg in extra:
        graph[m] = imports_of(m, src, is_pkg, modules)
    return graph


def upward_edges(graph: dict[str, set[str]]) -> list[str]:
    bad = []
    for src, targets in graph.items():
        (rank_s, unit_s) = layer_of(src)
        for dst in targets:
            (rank_d, unit_d) = layer_of(dst)
            # The package __init__ is the api layer, but importing a core name from it (the error
            # base, the model classes it re-exports from core) is not allowed below the api either.
            if unit_s == unit_d and dst != "cpc2urdf":
                continue
            if not rank_d < rank_s:
                bad.append(f"{src} ({unit_s}) imports {dst} ({unit_d})")
    return sorted(bad)


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_every_module_has_a_layer() -> None:
    assert all(layer_of(m) for m in known_modules())


def test_layers_point_one_way() -> None:
    assert upward_edges(import_graph()) == []


def test_no_import_cycles() -> None:
    assert cycles(import_graph()) == []


@pytest.mark.parametrize(
    ("module", "source", "expected"),
    [
        # an upward import hidden inside a function of a core module
        (
            "cpc2urdf.model",
            "def f():\n    from cpc2urdf.validation.crosscheck import cross_check\n",
            "cpc2urdf.model (core) imports cpc2urdf.validation.crosscheck (validation)",
        ),
        # vision must not reach into hand-eye (the renderer once imported stage 2 for its target)
        (
            "cpc2urdf.identification.vision.render",
            "def f():\n    from cpc2urdf.identification.handeye import stage2\n",
            "cpc2urdf.identification.vision.render (vision) imports cpc2urdf.identification.handeye.stage2 (handeye)",
        ),
        # a study used by the library
        (
            "cpc2urdf.identification.kinematics.refine",
            "import cpc2urdf.studies.crb\n",
            "cpc2urdf.identification.kinematics.refine (kinematics) imports cpc2urdf.studies.crb (studies)",
        ),
        # the package's api names from below the api
        (
            "cpc2urdf.urdf.document",
            "from cpc2urdf import identify\n",
            "cpc2urdf.urdf.document (core) imports cpc2urdf (api)",
        ),
        # a relative import is resolved too
        (
            "cpc2urdf.identification.kinematics.protocol",
            "from ..simulation import design\n",
            "cpc2urdf.identification.kinematics.protocol (kinematics) imports cpc2urdf.identification.simulation",
        ),
    ],
)
def test_planted_upward_import_is_caught(module: str, source: str, expected: str) -> None:
    graph = import_graph([(module, source, False)])
    assert any(v.startswith(expected) for v in upward_edges(graph)), upward_edges(graph)


def test_planted_cycle_is_caught() -> None:
    graph = import_graph(
        [
            (
                "cpc2urdf.identification.kinematics.refine",
                "def f():\n    from cpc2urdf.identification.kinematics.methods import identify\n",
                False,
            ),
        ]
    )
    graph["cpc2urdf.identification.kinematics.methods"] = {
        "cpc2urdf.identification.kinematics.refine"
    }
    assert [
        "cpc2urdf.identification.kinematics.methods",
        "cpc2urdf.identification.kinematics.refine",
    ] in cycles(graph)
