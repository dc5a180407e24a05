"""Import structure of the two Python packages (issue 14, "Pure cores, thin nodes, one direction").

Every module of ``hindrax_drivers`` and ``hindrax_ident`` is parsed with :mod:`ast` (nothing is imported), and
the intra-project import graph is built from every ``import`` / ``from ... import`` statement anywhere in the
module, function-local imports included (a lazy import is still a dependency). ``from pkg import name`` is an
edge to ``pkg.name`` when that is a module, else to ``pkg``; importing ``a.b.c`` also imports the packages
``a`` and ``a.b`` (their ``__init__``), so those are edges too, except to the importing module's own ancestor
packages (Python initialises them before the module runs).

Rules checked:

- no import cycle (strongly connected component of more than one module, or a module importing itself);
- a node module (``*/node.py`` or ``*_node.py``: it defines an rclpy node) is imported only by other node
  modules and by the entry points that start nodes (:data:`ENTRY_POINTS`); pure functions that offline tools
  need live in pure modules that the nodes import too.
- production code does not import the test helpers (:data:`TESTING`): only the benchmarks
  (:data:`ENTRY_POINT_PACKAGES`) may; what production needs of them lives in ``hindrax_drivers.conditions``.

Run alone: ``.venv/bin/python -m pytest -n0 -p no:randomly test/test_import_structure.py -q``.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = {"hindrax_drivers": ROOT / "src" / "hindrax_drivers" / "hindrax_drivers",
            "hindrax_ident": ROOT / "src" / "hindrax_ident" / "hindrax_ident"}

#: Modules allowed to import node modules: the graph builders (the whole stack in one process; the driver nodes
#: on replayed device data) and the entry points that start nodes (``hindrax bag play|record``).
ENTRY_POINTS = frozenset({
    "hindrax_ident.bringup",
    "hindrax_drivers.recording.replay_devices",
    "hindrax_ident.commands.bag.play",
    "hindrax_ident.commands.bag.record",
})
#: Packages whose every module is an entry point: the ``make bench`` benchmarks start the nodes they measure.
ENTRY_POINT_PACKAGES = ("hindrax_ident.benchmarks",)


def is_entry_point(name: str) -> bool:
    """True for the modules of :data:`ENTRY_POINTS` and :data:`ENTRY_POINT_PACKAGES`."""
    return name in ENTRY_POINTS or any(name == p or name.startswith(p + ".") for p in ENTRY_POINT_PACKAGES)


def _modules(packages: dict[str, Path]) -> dict[str, Path]:
    """{dotted module name: path} of every module of ``packages`` ({top-level name: directory})."""
    out: dict[str, Path] = {}
    for pkg, root in packages.items():
        for path in sorted(root.rglob("*.py")):
            parts = list(path.relative_to(root).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join([pkg, *parts])] = path
    return out


def is_node_module(name: str) -> bool:
    """True for ``*.node`` and ``*_node`` modules (they define rclpy nodes)."""
    last = name.rsplit(".", 1)[-1]
    return last == "node" or last.endswith("_node")


def _resolve(module: str, is_package: bool, level: int, target: str | None) -> str:
    """Absolute dotted name of a (possibly relative) import target seen from ``module``."""
    if level == 0:
        return target or ""
    base = module.split(".")
    if not is_package:
        base = base[:-1]
    base = base[: len(base) - (level - 1)]
    return ".".join(base + ([target] if target else []))


def import_graph(packages: dict[str, Path] = PACKAGES) -> dict[str, set[str]]:
    """{module: set of project modules it imports}, function-local imports included."""
    modules = _modules(packages)
    graph: dict[str, set[str]] = {m: set() for m in modules}

    def add(src: str, name: str) -> None:
        parts = name.split(".")
        for i in range(1, len(parts) + 1):
            dep = ".".join(parts[:i])
            # The module's own ancestor packages are initialised before it runs: not a dependency. A module
            # importing itself is kept (reported as a cycle).
            if dep in modules and (i == len(parts) or not (src == dep or src.startswith(dep + "."))):
                graph[src].add(dep)

    for mod, path in modules.items():
        is_pkg = path.name == "__init__.py"
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                for alias in node.names:
                    add(mod, alias.name)
            elif isinstance(node, ast.ImportFrom):
                base = _resolve(mod, is_pkg, node.level, node.module)
                add(mod, base)
                for alias in node.names:
                    sub = f"{base}.{alias.name}"
                    if sub in modules:
                        add(mod, sub)
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with a cycle (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    counter = [0]

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1 or v in graph[v]:
                found.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def node_imports(graph: dict[str, set[str]]) -> list[str]:
    """``"importer -> node module"`` for every import of a node module from a non-node, non-entry module."""
    return sorted(f"{src} -> {dst}" for src, deps in graph.items() for dst in deps
                  if is_node_module(dst) and not is_node_module(src) and not is_entry_point(src))


# ------------------------------------------------------------------------------------------------ the checker
def test_graph_sees_function_local_and_relative_imports(tmp_path):
    """The checker itself: relative, function-local and ``from pkg import submodule`` imports are edges,
    and a two-module circle and an offline import of a node module are reported."""
    pkg = tmp_path / "pkg"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "sub" / "__init__.py").write_text("")
    (pkg / "sub" / "node.py").write_text("from . import pure\n")
    (pkg / "sub" / "pure.py").write_text("def f():\n    from ..tool import g\n")
    (pkg / "tool.py").write_text("from .sub import pure\ndef g():\n    from pkg.sub.node import x\n")
    graph = import_graph({"pkg": pkg})
    assert graph["pkg.sub.node"] == {"pkg.sub", "pkg.sub.pure"}
    assert graph["pkg.sub.pure"] == {"pkg.tool"}
    assert graph["pkg.tool"] == {"pkg.sub", "pkg.sub.pure", "pkg.sub.node"}
    assert cycles(graph) == [["pkg.sub.node", "pkg.sub.pure", "pkg.tool"]]  # tool -> node -> pure -> tool
    assert node_imports(graph) == ["pkg.tool -> pkg.sub.node"]


# ------------------------------------------------------------------------------------------------ the packages
@pytest.fixture(scope="module")
def graph() -> dict[str, set[str]]:
    return import_graph()


def test_graph_covers_both_packages(graph):
    """Sanity: the graph holds the known modules and edges (a broken parser would pass the rules vacuously)."""
    assert "hindrax_ident.identification.from_bag" in graph
    assert "hindrax_drivers.recording.writer" in graph
    assert "hindrax_ident.bringup" in graph["hindrax_ident.commands.bringup"]  # function-local import
    assert "hindrax_drivers.recording.recover" in graph["hindrax_drivers.recording.reader"]  # from . import x
    assert len(graph) > 80


def test_no_import_cycles(graph):
    assert cycles(graph) == []


def test_node_modules_imported_only_by_nodes_and_entry_points(graph):
    assert node_imports(graph) == []


#: The helpers for tests and benchmarks (waits, contexts, child environments, configuration parameters).
TESTING = "hindrax_drivers.testing"


def production_imports_of_testing(graph: dict[str, set[str]]) -> list[str]:
    """``"importer -> hindrax_drivers.testing"`` for every production module importing the test helpers."""
    return sorted(f"{src} -> {TESTING}" for src, deps in graph.items()
                  if TESTING in deps and src != TESTING and not any(
                      src == p or src.startswith(p + ".") for p in ENTRY_POINT_PACKAGES))


def test_production_code_does_not_import_the_test_helpers(graph):
    assert TESTING in graph and "hindrax_drivers.conditions" in graph[TESTING]  # the rule is not vacuous
    assert production_imports_of_testing(graph) == []


def test_entry_points_exist(graph):
    """Every allowed entry point is a real module (a renamed module must not leave a stale allowance)."""
    assert sorted(ENTRY_POINTS - set(graph)) == []
    assert all(p in graph for p in ENTRY_POINT_PACKAGES)
