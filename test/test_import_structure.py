"""Import structure of the project's Python packages (issue 14, "Pure cores, thin nodes, one direction"; issue 75,
packages by where the code runs).

Every module of ``hindrax_common``, ``hindrax_drivers``, ``hindrax_bringup``, ``hindrax_onboard``, ``hindrax_fit``,
``hindrax_sim`` and ``hindrax_tools`` is parsed with :mod:`ast` (nothing is imported), and the intra-project import
graph is built from every ``import`` / ``from ... import`` statement anywhere in the module, function-local imports
included (a lazy import is still a dependency). ``from pkg import name`` is an edge to ``pkg.name`` when that is a
module, else to ``pkg``; importing ``a.b.c`` also imports the packages ``a`` and ``a.b`` (their ``__init__``), so
those are edges too, except to the importing module's own ancestor packages (Python initialises them before the
module runs).

Rules checked:

- no import cycle (strongly connected component of more than one module, or a module importing itself);
- a node module (``*/node.py`` or ``*_node.py``: it defines an rclpy node) is imported only by other node
  modules and by the entry points that start nodes (:data:`ENTRY_POINTS`); pure functions that offline tools
  need live in pure modules that the nodes import too.
- production code does not import the test helpers (:data:`TESTING`): only the benchmarks
  (:data:`ENTRY_POINT_PACKAGES`) may; what production needs of them lives in ``hindrax_common.process.conditions``;
- the packages in one order, msgs <- common <- drivers <- bringup <- onboard <- fit <- sim <- tools
  (:data:`PACKAGE_ORDER`): no module imports a higher package, each package.xml's ``exec_depend`` names exactly the
  project packages its modules import, and the vehicle's build (msgs, common, drivers, bringup, onboard:
  :data:`VEHICLE_PACKAGES`) runs no topside code;
- rooms in layers (:data:`LAYERS`), one strict order across the packages: the driver level's seven (common: pure
  helpers < configuration < transports < node support; drivers: devices; bringup: allocation, safety, gateway and
  recording < launch layouts) < estimation < vehicle < control < the shared per-DOF model < online identification
  < the composed processes < fit < bag input < assessment < the virtual pool < the graph in one process < tools; no
  module imports a module of a higher layer, without exceptions, and no module is loose at a package's root but its
  public surface (:data:`ROOT_MODULES`); every room of the driver level has a layer of its own;
- only the bag input room reads bags (:data:`BAG_READER`) and, outside the fit package, only the pipeline's faces
  are used (:data:`PIPELINE_FACES`);
- each process of the vehicle's launch files can import at most :data:`VEHICLE_PROCESS_MAX_LINES` lines of project
  code outside the driver-level packages (:data:`DRIVER_LEVEL`) and messages; no package over
  :data:`PACKAGE_MAX_LINES` source lines;
- the vehicle's shared physics is defined once (:data:`DEFINED_ONCE`): the angle wrap, the thrust lag, the thrust
  curve and the rigid-body mass matrix, each in its one module, and no other module writes their formulas out.

Run alone: ``.venv/bin/python -m pytest -n0 -p no:randomly test/test_import_structure.py -q``.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest
from hindrax_test_support.packages import setup_kwargs

ROOT = Path(__file__).resolve().parents[1]
#: The Python packages, lowest first (hindrax_msgs, the generated interfaces, is below them all).
PACKAGE_ORDER = ("hindrax_common", "hindrax_drivers", "hindrax_bringup", "hindrax_onboard", "hindrax_fit",
                 "hindrax_sim", "hindrax_tools")
PACKAGES = {p: ROOT / "src" / p / p for p in PACKAGE_ORDER}
#: What the vehicle's build installs (make ros-install, the image); the other packages are topside.
VEHICLE_PACKAGES = ("hindrax_msgs", "hindrax_common", "hindrax_drivers", "hindrax_bringup", "hindrax_onboard")
#: The driver level: what every vehicle process stands on, the devices, and the vehicle graph over them (the three
#: packages hindrax_drivers was split into, issue 75).
DRIVER_LEVEL = ("hindrax_common", "hindrax_drivers", "hindrax_bringup")

#: Modules allowed to import node modules: the graph builder (the whole stack in one process) and the entry points
#: that start nodes (``hindrax bag play|record``).
ENTRY_POINTS = frozenset({
    "hindrax_sim.graph.bringup",
    "hindrax_onboard.commands.bag.play",
    "hindrax_onboard.commands.bag.record",
})
#: Packages whose every module is an entry point: the ``make bench`` benchmarks start the nodes they measure.
ENTRY_POINT_PACKAGES = ("hindrax_tools.benchmarks",)


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
                if base != mod:  # ``from . import sub`` in a package's __init__ imports its submodules, not itself
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


def test_graph_covers_every_package(graph):
    """Sanity: the graph holds the known modules and edges (a broken parser would pass the rules vacuously)."""
    assert "hindrax_fit.bag_input.from_bag" in graph
    assert "hindrax_bringup.recording.writer" in graph
    # function-local import
    assert "hindrax_sim.graph.bringup" in graph["hindrax_tools.commands.bringup"]
    assert "hindrax_bringup.recording.recover" in graph["hindrax_bringup.recording.reader"]  # from . import x
    assert {m.split(".")[0] for m in graph} == set(PACKAGE_ORDER) and len(graph) > 80


def test_no_import_cycles(graph):
    assert cycles(graph) == []


def test_node_modules_imported_only_by_nodes_and_entry_points(graph):
    assert node_imports(graph) == []


#: The helpers for tests and benchmarks (waits, contexts, child environments, configuration parameters).
TESTING = "hindrax_common.testing"


def production_imports_of_testing(graph: dict[str, set[str]]) -> list[str]:
    """``"importer -> hindrax_common.testing"`` for every production module importing the test helpers."""
    return sorted(f"{src} -> {TESTING}" for src, deps in graph.items()
                  if TESTING in deps and src != TESTING and not any(
                      src == p or src.startswith(p + ".") for p in ENTRY_POINT_PACKAGES))


def test_production_code_does_not_import_the_test_helpers(graph):
    assert TESTING in graph and "hindrax_common.process.conditions" in graph[TESTING]  # the rule is not vacuous
    assert production_imports_of_testing(graph) == []


def test_entry_points_exist(graph):
    """Every allowed entry point is a real module (a renamed module must not leave a stale allowance)."""
    assert sorted(ENTRY_POINTS - set(graph)) == []
    assert all(p in graph for p in ENTRY_POINT_PACKAGES)


# ------------------------------------------------------------------------------------------------ packages
def package_of(module: str) -> str:
    return module.split(".", 1)[0]


def upward_package_imports(graph: dict[str, set[str]]) -> list[str]:
    """``"importer -> imported"`` for every import of a higher package (:data:`PACKAGE_ORDER`)."""
    rank = {p: i for i, p in enumerate(PACKAGE_ORDER)}
    return sorted(f"{a} -> {b}" for a, deps in graph.items() for b in deps
                  if rank[package_of(b)] > rank[package_of(a)])


def test_the_package_checker_sees_an_upward_import():
    graph = {"hindrax_onboard.control.law": {"hindrax_fit.fit.fit_core", "hindrax_common.base.frames"},
             "hindrax_fit.fit.fit_core": {"hindrax_onboard.vehicle.state"}}
    assert upward_package_imports(graph) == ["hindrax_onboard.control.law -> hindrax_fit.fit.fit_core"]


def test_no_package_imports_a_higher_one_and_package_xml_says_which_it_imports(graph):
    """msgs <- common <- drivers <- bringup <- onboard <- fit <- sim <- tools: no import back up, and each
    package.xml's exec_depend names exactly the project packages its modules import (colcon's build order is the
    import order)."""
    import xml.etree.ElementTree as ET

    assert "hindrax_onboard.identification.model.dof_model" in graph["hindrax_fit.fit.campaign_fit"]  # not vacuous
    assert upward_package_imports(graph) == []
    for pkg in PACKAGE_ORDER:
        root = ET.parse(ROOT / "src" / pkg / "package.xml").getroot()
        declared = {e.text.strip() for e in root.iter("exec_depend")} & {"hindrax_msgs", *PACKAGE_ORDER}
        imported = {package_of(d) for m, deps in graph.items() if package_of(m) == pkg for d in deps} - {pkg}
        imported |= {"hindrax_msgs"} & {package_of(n.module or "") if isinstance(n, ast.ImportFrom) else
                                        package_of(n.names[0].name) for path in _modules({pkg: PACKAGES[pkg]}).values()
                                        for n in ast.walk(ast.parse(path.read_text(encoding="utf-8")))
                                        if isinstance(n, (ast.Import, ast.ImportFrom))}
        assert declared == imported, f"{pkg}/package.xml exec_depend {sorted(declared)}, imports {sorted(imported)}"


def test_the_vehicle_build_holds_no_topside_module():
    """make ros-install and the image build msgs, the driver level and onboard: none of their console scripts or
    launch files runs a topside package's code."""
    import re

    for pkg in VEHICLE_PACKAGES[1:]:
        scripts = setup_kwargs(pkg)["entry_points"]["console_scripts"]
        assert scripts or pkg == "hindrax_common", pkg
        assert all(package_of(s.split("=")[1].strip()) in VEHICLE_PACKAGES for s in scripts), scripts
        for launch in (ROOT / "src" / pkg / "launch").glob("*.launch.xml"):
            used = set(re.findall(r'pkg="(hindrax_\w+)"', launch.read_text()))
            assert used <= set(VEHICLE_PACKAGES), f"{launch.name}: {sorted(used)}"
    make = (ROOT / "Makefile").read_text()
    assert "--packages-up-to hindrax_onboard" in make
    # one `hindrax` script, the vehicle's, which the image's /usr/local/bin/hindrax runs; the topside adds commands
    assert "hindrax = hindrax_onboard.cli:main" in setup_kwargs("hindrax_onboard")["entry_points"]["console_scripts"]
    assert "console_scripts" not in setup_kwargs("hindrax_tools")["entry_points"]
    assert "/ws/install/lib/hindrax_onboard/hindrax" in (ROOT / "docker" / "hindrax-exec.sh").read_text()


# ------------------------------------------------------------------------------------------------ layers
#: (module prefix, layer), the longest matching prefix wins; every module falls under one (a package's root prefix
#: is its lowest room, which holds only its public surface). docs/architecture.md §2. The controller the vehicle runs
#: sits below identification (which holds with it); the per-DOF model that the online campaign and the topside fit
#: share below both; the simulator above the fit (it runs the campaign and fits it); the graph in one process above
#: every node it composes; the tools on top.
LAYERS = (
    ("hindrax_common", 0),  # its public surface: the package alone
    ("hindrax_common.base", 0),  # frames, PWM limits, thrust curve, device clocks, the device table: pure
    ("hindrax_common.process", 0),  # the process's life, scheduling, systemd, DDS transport, waits
    ("hindrax_common.cdr", 0),  # CDR without rclpy objects, message definitions
    ("hindrax_common.config", 1),
    ("hindrax_common.transport", 2),
    ("hindrax_common.node_support", 3),  # base node, diagnostics, heartbeats, I2C and serial node bases
    ("hindrax_common.testing", 3),  # the helpers of tests and benchmarks (their public surface)
    ("hindrax_drivers", 4),
    ("hindrax_drivers.dvl75", 4),  # the devices: protocol, emulator, node
    ("hindrax_drivers.ping1d", 4),
    ("hindrax_drivers.ms5837", 4),
    ("hindrax_drivers.icm20948", 4),
    ("hindrax_drivers.pca9685", 4),
    ("hindrax_drivers.tf", 4),
    ("hindrax_bringup", 5),
    ("hindrax_bringup.allocation", 5),  # over the ESC's protocol
    ("hindrax_bringup.guard", 5),
    ("hindrax_bringup.supervisor", 5),
    ("hindrax_bringup.gateway", 5),  # over the allocation's bounds
    ("hindrax_bringup.recording", 5),  # replays the devices' emulators
    ("hindrax_bringup.layout", 6),  # launch layouts: composed processes, launch files, emulated devices, health
    ("hindrax_onboard", 7),
    ("hindrax_onboard.estimation", 7),
    ("hindrax_onboard.vehicle", 8),
    ("hindrax_onboard.control", 9),
    ("hindrax_onboard.identification", 10),
    ("hindrax_onboard.identification.model", 10),
    ("hindrax_onboard.identification.online", 11),
    ("hindrax_onboard.composition", 12),  # the composed processes of the pool test launch
    ("hindrax_onboard.commands", 12),  # the vehicle's `hindrax` commands (over the drivers only)
    ("hindrax_onboard.cli", 12),  # the `hindrax` command line; other packages add commands by entry point
    ("hindrax_fit", 13),
    ("hindrax_fit.fit", 13),
    ("hindrax_fit.bag_input", 14),  # the fit core defines the per-DOF record (Chunk) the bag reader returns
    ("hindrax_fit.assessment", 15),  # verdicts, identification.yaml, reports: reads, fits and writes
    ("hindrax_sim", 16),  # the virtual pool: its modules are the package's root room
    ("hindrax_sim.graph", 17),  # the graph in one process, its executor, the runs on it
    ("hindrax_tools", 18),  # the command line, its commands, the benchmarks, progress and results doc
)
#: Modules that may sit at a package's root beside its public surface (``__init__``): the helpers for tests and
#: benchmarks (hindrax_common), the sim's root room, the tools' command line and its helpers, the composed processes.
ROOT_MODULES = {"hindrax_common": {"testing"}, "hindrax_drivers": set(), "hindrax_bringup": set(),
                "hindrax_onboard": {"composition", "cli"}, "hindrax_fit": set(),
                "hindrax_tools": {
    "cli", "bench", "progress_run", "results_doc", "output_dirs"}}


def layer_of(module: str) -> int:
    """Layer of ``module`` (:data:`LAYERS`); ValueError for a module outside every package."""
    best = [(len(p), lay) for p, lay in LAYERS if module == p or module.startswith(p + ".")]
    if not best:
        raise ValueError(f"{module}: in no layer of LAYERS")
    return max(best)[1]


def upward_imports(graph: dict[str, set[str]]) -> set[tuple[str, str]]:
    """(importer, imported) for every import of a higher layer's module (packages' ``__init__`` edges dropped when
    the module itself is also imported)."""
    out = set()
    for src, deps in graph.items():
        for dst in deps:
            if layer_of(dst) > layer_of(src) and not any(d.startswith(dst + ".") for d in deps):
                out.add((src, dst))
    return out


def test_the_layer_checker_sees_an_upward_import():
    graph = {"hindrax_onboard.vehicle.x": {"hindrax_sim", "hindrax_sim.model"},
             "hindrax_sim.model": {"hindrax_onboard.vehicle.x", "hindrax_common.base.frames"},
             "hindrax_common.base.frames": set()}
    assert upward_imports(graph) == {("hindrax_onboard.vehicle.x", "hindrax_sim.model")}
    assert [layer_of(m) for m in (
        "hindrax_common.base.frames", "hindrax_onboard.vehicle.state", "hindrax_onboard.control.node",
        "hindrax_onboard.identification.model.dof_model", "hindrax_onboard.identification.online.node",
        "hindrax_onboard.composition", "hindrax_fit.fit.fit_core", "hindrax_fit.bag_input.reader",
        "hindrax_fit.assessment.report", "hindrax_sim.campaign", "hindrax_sim.graph.bringup",
        "hindrax_tools.commands.run")] == [0, 8, 9, 10, 11, 12, 13, 14, 15, 16, 17, 18]
    assert [layer_of(m) for m in (
        "hindrax_common.base.frames", "hindrax_common.config.loader", "hindrax_common.transport.i2c",
        "hindrax_common.node_support.liveness", "hindrax_common.testing", "hindrax_drivers.pca9685.core",
        "hindrax_bringup.allocation.node", "hindrax_bringup.layout.composition")] == [0, 1, 2, 3, 3, 4, 5, 6]
    with pytest.raises(ValueError):
        layer_of("hindrax_other.x")


def test_no_import_from_a_lower_layer_to_a_higher_one(graph):
    # the order is not vacuous: identification holds with the controller's law, the simulator runs the campaign
    assert "hindrax_onboard.control.maneuvers" in graph["hindrax_onboard.identification.online.steps.context"]
    assert "hindrax_onboard.identification.online.executive" in graph["hindrax_sim.campaign"]
    up = sorted(f"{a} -> {b}" for a, b in upward_imports(graph))
    assert not up, "imports from a lower layer to a higher one (LAYERS):\n" + "\n".join(up)
    assert all(layer_of(m) <= layer_of("hindrax_onboard.vehicle")
               for m in graph.get("hindrax_onboard.vehicle.rigid_body", set()) if m in graph)


def loose_modules(graph: dict[str, set[str]]) -> list[str]:
    """Modules at the root of the driver level, onboard, fit or tools that are neither the package nor in
    :data:`ROOT_MODULES`."""
    return sorted(m for m in graph if m.count(".") == 1 and package_of(m) in ROOT_MODULES
                  and m.split(".")[1] not in ROOT_MODULES[package_of(m)]
                  and not any(k.startswith(m + ".") for k in graph))  # a subpackage is a room


def test_every_module_is_in_a_room(graph):
    """No loose module at a package's root but its public surface (:data:`ROOT_MODULES`); each room a layer."""
    assert loose_modules({"hindrax_fit.flat": set(), "hindrax_fit.fit": set(), "hindrax_fit.fit.x": set()}) == [
        "hindrax_fit.flat"]
    assert loose_modules(graph) == []
    assert {m for m in graph if m.count(".") == 1 and package_of(m) in ROOT_MODULES} >= {
        f"{p}.{m}" for p, ms in ROOT_MODULES.items() for m in ms}  # no stale allowance
    # every room of the driver level has its own layer (none falls to its package's)
    rooms = {".".join(m.split(".")[:2]) for m in graph if package_of(m) in DRIVER_LEVEL and m.count(".") >= 1}
    named = {p for p, _ in LAYERS if package_of(p) in DRIVER_LEVEL and "." in p}
    assert rooms == named, f"driver-level rooms without a layer: {sorted(rooms - named)}, stale: {named - rooms}"


# ------------------------------------------------------------------------------------------------ the fit's faces
FIT = "hindrax_fit"
#: The bag reader: within the identification rooms (the fit package and onboard's identification), only the bag
#: input room imports it.
BAG_READER = "hindrax_bringup.recording.reader"
#: What modules outside the fit package may import of it: the pipeline (read, fit, write), the yaml's reader and
#: schema, the verdicts, reports and predictions, the bag reader. The adapters (``bag_input.from_bag``,
#: ``bag_input.any_topics``), the fits of bags (``fit.fit_any``) and the writers' internals stay behind these faces.
PIPELINE_FACES = frozenset({
    f"{FIT}.assessment.pipeline", f"{FIT}.assessment.results", f"{FIT}.assessment.report",
    f"{FIT}.assessment.verdicts", f"{FIT}.assessment.predict", f"{FIT}.bag_input.reader",
})
#: Rooms whose every module is a face (the fit's maths are used by the simulator and the benchmarks directly); the
#: fits of bags in ``fit.fit_any`` are not (:data:`PIPELINE_ONLY`).
OPEN_ROOMS = ("fit",)
PIPELINE_ONLY = frozenset({f"{FIT}.fit.fit_any"})
IDENTIFICATION_ROOMS = (f"{FIT}.", "hindrax_onboard.identification.")


def pipeline_violations(graph: dict[str, set[str]]) -> list[str]:
    """``"importer -> imported (why)"`` for a bag read outside the bag input room and for an import of the pipeline's
    insides from outside the fit package (:data:`PIPELINE_FACES`)."""
    out = []
    for src, deps in graph.items():
        if src.startswith(IDENTIFICATION_ROOMS) and not src.startswith(f"{FIT}.bag_input.") and BAG_READER in deps:
            out.append(f"{src} -> {BAG_READER} (only the bag input room reads bags)")
        if package_of(src) == FIT:
            continue
        for dst in deps:
            if package_of(dst) != FIT or dst in PIPELINE_FACES or dst.count(".") < 2 or (
                    dst.split(".")[1] in OPEN_ROOMS and dst not in PIPELINE_ONLY):
                continue
            out.append(f"{src} -> {dst} (outside the fit package: use the pipeline, "
                       f"{FIT}.assessment.pipeline, or the bag reader, {FIT}.bag_input.reader)")
    return sorted(out)


def test_the_pipeline_checker_sees_a_reader_or_an_adapter_used_elsewhere():
    graph = {f"{FIT}.fit.fit_any": {BAG_READER},
             "hindrax_tools.commands.ident_fit": {
                 f"{FIT}.bag_input.any_topics", f"{FIT}.fit.fit_any",
                 f"{FIT}.assessment.pipeline", f"{FIT}.fit.fit_core"},
             "hindrax_onboard.identification.online.node": {BAG_READER},
             f"{FIT}.bag_input.from_bag": {BAG_READER}}
    assert pipeline_violations(graph) == [
        f"{FIT}.fit.fit_any -> {BAG_READER} (only the bag input room reads bags)",
        f"hindrax_onboard.identification.online.node -> {BAG_READER} (only the bag input room reads bags)",
        f"hindrax_tools.commands.ident_fit -> {FIT}.bag_input.any_topics (outside the fit package: use the "
        f"pipeline, {FIT}.assessment.pipeline, or the bag reader, {FIT}.bag_input.reader)",
        f"hindrax_tools.commands.ident_fit -> {FIT}.fit.fit_any (outside the fit package: use the "
        f"pipeline, {FIT}.assessment.pipeline, or the bag reader, {FIT}.bag_input.reader)"]


def test_one_pipeline_reads_bags_and_writes_identification(graph):
    """Only the bag input room reads bags; commands, the simulator and the graph runs go through the pipeline."""
    assert BAG_READER in graph[f"{FIT}.bag_input.any_topics"]  # the rule is not vacuous
    assert f"{FIT}.assessment.pipeline" in graph["hindrax_tools.commands.ident_fit"]
    assert all(m in graph for m in PIPELINE_FACES | PIPELINE_ONLY)
    assert pipeline_violations(graph) == []


# ------------------------------------------------------------------------------------------------ what runs where
#: The launch files the vehicle runs (the pool test includes the vehicle's).
VEHICLE_LAUNCHES = (ROOT / "src" / "hindrax_bringup" / "launch" / "vehicle.launch.xml",
                    ROOT / "src" / "hindrax_onboard" / "launch" / "pool_test.launch.xml")
#: Lines (``wc -l``) of project code outside the driver level (:data:`DRIVER_LEVEL`) and hindrax_msgs that one process
#: of the vehicle's launch files may import (issue 75: the identification process could import 11.3k, the topside fit
#: among them).
VEHICLE_PROCESS_MAX_LINES = 8_500
#: Source lines (tests excluded) of one package at most (issue 75).
PACKAGE_MAX_LINES = 15_000


def class_path_edges(modules: dict[str, Path]) -> dict[str, set[str]]:
    """{module: modules it names as ``"package.module:Class"`` strings} (the composed processes import their nodes'
    classes by name at run time, :mod:`hindrax_bringup.layout.composition`)."""
    import re

    out: dict[str, set[str]] = {}
    for mod, path in modules.items():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Constant) and isinstance(node.value, str):
                m = re.fullmatch(r"(hindrax_\w+(?:\.\w+)*):\w+", node.value)
                if m and m.group(1) in modules:
                    out.setdefault(mod, set()).add(m.group(1))
    return out


def process_closure(graph: dict[str, set[str]], start: str) -> set[str]:
    """Every project module that the process whose entry module is ``start`` can import: the transitive closure of
    the import graph, plus the classes named by ``module:Class`` strings (:func:`class_path_edges`)."""
    seen, todo = {start}, [start]
    while todo:
        for dep in graph.get(todo.pop(), ()):
            if dep not in seen:
                seen.add(dep)
                todo.append(dep)
    return seen


def vehicle_processes() -> dict[str, str]:
    """{"package/executable": entry module} of every ``<node>`` of :data:`VEHICLE_LAUNCHES` that is this
    workspace's (external ones, foxglove_bridge, left out), whatever its launch condition."""
    import xml.etree.ElementTree as ET

    scripts: dict[str, str] = {}
    out = {}
    for launch in VEHICLE_LAUNCHES:
        for node in ET.parse(launch).getroot().iter("node"):
            pkg, exe = node.get("pkg"), node.get("exec")
            if pkg not in PACKAGES:
                continue
            if pkg not in {k.split("/")[0] for k in scripts}:
                for s in setup_kwargs(pkg)["entry_points"]["console_scripts"]:
                    name, target = (x.strip() for x in s.split("="))
                    scripts[f"{pkg}/{name}"] = target.split(":")[0]
            out[f"{pkg}/{exe}"] = scripts[f"{pkg}/{exe}"]
    return out


def test_each_vehicle_process_imports_at_most_its_share_of_project_code(graph):
    """Each process of the vehicle's launch files can import at most :data:`VEHICLE_PROCESS_MAX_LINES` lines of
    project code outside the driver level and messages; online identification imports no fit core and no report."""
    modules = _modules(PACKAGES)
    named = class_path_edges(modules)
    full = {m: deps | named.get(m, set()) for m, deps in graph.items()}
    processes = vehicle_processes()
    assert {"hindrax_bringup/sensors_node", "hindrax_onboard/ident_record_node",
            "hindrax_onboard/controller_node"} <= set(processes)  # not vacuous
    sizes = {}
    for proc, entry in processes.items():
        closure = process_closure(full, entry)
        sizes[proc] = sum(len(modules[m].read_text(encoding="utf-8").splitlines()) for m in closure
                          if package_of(m) not in (*DRIVER_LEVEL, "hindrax_msgs"))
        if proc == "hindrax_onboard/ident_record_node":  # the classes named by string are followed
            assert {"hindrax_onboard.identification.online.node", "hindrax_onboard.control.node",
                    "hindrax_bringup.recording.recorder_node"} <= closure
            assert not {"hindrax_fit.fit.fit_core", "hindrax_fit.assessment.report"} & closure
    print("project lines each vehicle process can import:", sizes)
    assert sizes["hindrax_onboard/ident_record_node"] > 1000  # the count is not vacuous
    over = {p: n for p, n in sizes.items() if n > VEHICLE_PROCESS_MAX_LINES}
    assert not over, f"vehicle processes over {VEHICLE_PROCESS_MAX_LINES} lines of project code: {over}"


def package_lines(pkg: str) -> int:
    """Source lines of ``src/<pkg>`` (``wc -l`` of its ``.py`` files, tests excluded; the issue 75 measure)."""
    return sum(len(p.read_text(encoding="utf-8").splitlines()) for p in (ROOT / "src" / pkg).rglob("*.py")
               if "test" not in p.relative_to(ROOT / "src" / pkg).parts)


def test_no_package_is_over_its_size():
    sizes = {pkg: package_lines(pkg) for pkg in PACKAGE_ORDER}
    print("source lines per package:", sizes)
    assert all(n > 1000 for n in sizes.values())  # the count is not vacuous
    over = {p: n for p, n in sizes.items() if n > PACKAGE_MAX_LINES}
    assert not over, f"packages over {PACKAGE_MAX_LINES} source lines: {over}"


# ------------------------------------------------------------------------------------------------ defined once
#: name -> the one module (path under src/) that defines it.
DEFINED_ONCE = {
    "wrap_angle": "hindrax_common/hindrax_common/base/frames.py",
    "ThrustLag": "hindrax_onboard/hindrax_onboard/vehicle/thrust_lag.py",
    "ThrustCurve": "hindrax_common/hindrax_common/base/thrust_curve.py",
    "rigid_body_mass_matrix": "hindrax_onboard/hindrax_onboard/vehicle/rigid_body.py",
    "skew": "hindrax_onboard/hindrax_onboard/vehicle/rigid_body.py",
}
#: Other names the same things had; none may be defined anywhere.
FORMER_NAMES = ("wrap", "_wrap", "_wrap_angle", "angle_wrap", "LaggedThrust", "_lagged", "lag_factor", "_skew")
#: The formulas written out: the wrap ``(a + pi) % (2 pi) - pi``, ``atan2(sin a, cos a)`` or ``remainder(a, 2 pi)``
#: (a heading in [0, 2 pi) is another convention), a lag factor ``exp(-t / time_constant | lag | tau)``, and a
#: ThrustCurve built outside the allocation's modules.
FORMULAS = {
    "the angle wrap": (r"pi\s*\)\s*%\s*\(\s*2(\.0)?\s*\*\s*(math|np)\.pi|atan2\(\s*(math|np)\.sin\(|"
                       r"remainder\([^\n]*,\s*2(\.0)?\s*\*\s*(math|np)\.pi", ("frames.py",)),
    "the thrust lag": (r"exp\(\s*-[^\n]*?/\s*(self\.)?(time_constant|lag|tau)", ("vehicle/thrust_lag.py",)),
    # the thrusters' section builds one only to validate the configured coefficients (its one-line refusal)
    "a thrust curve": (r"\bThrustCurve\(", ("base/thrust_curve.py", "allocation/from_config.py",
                                            "config/sections/thrusters.py")),
}


def _sources() -> dict[Path, str]:
    src = ROOT / "src"
    return {p: p.read_text(encoding="utf-8") for p in sorted(src.rglob("*.py"))
            if "test" not in p.relative_to(src).parts}


def test_the_vehicle_physics_is_defined_once():
    import re

    defined: dict[str, list[str]] = {}
    for path, text in _sources().items():
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
                defined.setdefault(node.name, []).append(path.relative_to(ROOT / "src").as_posix())
    for name, where in DEFINED_ONCE.items():
        assert defined.get(name) == [where], f"{name} must be defined once, in {where}: found {defined.get(name)}"
    assert not {n: defined[n] for n in FORMER_NAMES if n in defined}, "a second angle wrap, lag or skew"
    offenders = []
    for what, (pattern, allowed) in FORMULAS.items():
        for path, text in _sources().items():
            rel = path.relative_to(ROOT / "src").as_posix()
            if re.search(pattern, text) and not rel.endswith(allowed):
                offenders.append(f"{rel}: {what}")
    assert not offenders, "formulas written out again instead of imported:\n" + "\n".join(offenders)


def test_the_defined_once_scan_sees_a_second_definition(tmp_path):
    import re

    pattern = FORMULAS["the angle wrap"][0]
    assert re.search(pattern, "return (a + math.pi) % (2.0 * math.pi) - math.pi")
    assert re.search(pattern, "math.atan2(math.sin(angle), math.cos(angle))")
    assert re.search(pattern, "e_psi = math.remainder(psi_ref - eul[2], 2 * math.pi)")
    assert not re.search(pattern, "heading_rad=truth.yaw_rad % (2.0 * math.pi),")
    assert re.search(FORMULAS["the thrust lag"][0], "k = math.exp(-grid_s / tau) if tau > 0 else 0.0")
    assert re.search(FORMULAS["the thrust lag"][0], "k = math.exp(-float(dt) / self.time_constant_s)")
    assert re.search(FORMULAS["the thrust lag"][0], "e = math.exp(-0.5 * h / lag_s)")
    assert re.search(FORMULAS["a thrust curve"][0], "self.curve = ThrustCurve(t.curve_negative, ...)")


# ------------------------------------------------------------------------------------------------ configuration
#: The configuration's modules (the package: schema per section, validation, loading, typed sections; the nodes'
#: parameter declarations).
CONFIG_MODULES = ("hindrax_common.config", "hindrax_common.config.sections", "hindrax_common.config.loader",
                  "hindrax_common.config.typed_sections", "hindrax_common.config.node_parameters")
#: Device drivers and safety nodes' packages: the configuration imports none of them, not even through another
#: module; the hardware limits it checks live in ``hindrax_common.base.hardware_limits``, below the driver too.
DRIVER_PACKAGES = ("hindrax_drivers", "hindrax_common.transport", *(f"hindrax_bringup.{p}" for p in (
    "guard", "supervisor", "gateway")))


def driver_imports_of_config(graph: dict[str, set[str]]) -> list[str]:
    """``"config module -> driver module"`` for every driver module reachable from a configuration module."""
    out = []
    for start in CONFIG_MODULES:
        seen, todo = set(), [start]
        while todo:
            for dep in graph.get(todo.pop(), ()):
                if dep not in seen:
                    seen.add(dep)
                    todo.append(dep)
        out += [f"{start} -> {m}" for m in sorted(seen)
                if any(m == p or m.startswith(p + ".") for p in DRIVER_PACKAGES)]
    return out


def test_the_config_rule_sees_a_driver_import():
    graph = {"hindrax_common.config": {"hindrax_common.base.hardware_limits", "hindrax_common.base.frames"},
             "hindrax_common.base.frames": {"hindrax_drivers.pca9685.protocol"}}
    assert driver_imports_of_config(graph) == ["hindrax_common.config -> hindrax_drivers.pca9685.protocol"]


def test_the_configuration_imports_no_driver(graph):
    assert all(m in graph for m in CONFIG_MODULES)
    assert "hindrax_common.base.hardware_limits" in graph["hindrax_common.config.sections.esc"]
    assert "hindrax_common.base.hardware_limits" in graph["hindrax_drivers.pca9685.protocol"]
    assert driver_imports_of_config(graph) == []
