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
  (:data:`ENTRY_POINT_PACKAGES`) may; what production needs of them lives in ``hindrax_drivers.conditions``;
- layers (:data:`LAYERS`), one strict order: drivers < estimation < vehicle < control < identification < simulator
  < the graph builders < the runs on the composed graph and the tools room (:data:`TOOLS`: the
  command line, its
  commands and the benchmarks); no module imports a module of a higher layer, without exceptions,
  and nothing outside
  the tools room imports it;
- the identification package keeps its rooms (:data:`ROOMS`): fit < bag input < assessment < online (the fit core
  defines the per-DOF record the bag reader returns; the assessment runs the pipeline and writes its outputs); the
  online campaign does not import the identification.yaml writer; only the bag input room reads bags
  (:data:`BAG_READER`) and, outside the identification package, only the pipeline's faces are used
  (:data:`PIPELINE_FACES`);
- the vehicle's shared physics is defined once (:data:`DEFINED_ONCE`): the angle wrap, the thrust lag, the thrust
  curve and the rigid-body mass matrix, each in its one module, and no other module writes their formulas out.

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
    "hindrax_sim.graph.bringup",
    "hindrax_drivers.recording.replay_devices",
    "hindrax_tools.commands.bag.play",
    "hindrax_tools.commands.bag.record",
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


def test_graph_covers_both_packages(graph):
    """Sanity: the graph holds the known modules and edges (a broken parser would pass the rules vacuously)."""
    assert "hindrax_fit.bag_input.from_bag" in graph
    assert "hindrax_drivers.recording.writer" in graph
    # function-local import
    assert "hindrax_sim.graph.bringup" in graph["hindrax_tools.commands.bringup"]
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


# ------------------------------------------------------------------------------------------------ layers
#: (module prefix, layer), the longest matching prefix wins; a module matching none is in the top layer (commands,
#: benchmarks, the command line, the runs on the composed graph). docs/architecture.md §2. The controller the vehicle
#: runs sits below identification (which holds with it); the simulator above both (it runs their campaigns and
#: closed-loop evaluations); the graph builders above every node they compose.
LAYERS = (
    ("hindrax_drivers", 0),
    ("hindrax_onboard.estimation", 1),
    ("hindrax_onboard.vehicle", 2),
    ("hindrax_onboard.control", 3),
    ("hindrax_onboard.identification", 4),
    ("hindrax_sim", 5),
    ("hindrax_sim.graph.ordered_executor", 6),  # the graph builders' executor
    ("hindrax_sim.graph.bringup", 6),
    ("hindrax_onboard.composition", 6),
)
TOP_LAYER = 7


def layer_of(module: str) -> int:
    """Layer of ``module`` (:data:`LAYERS`; the package ``hindrax_ident`` itself is below everything)."""
    if module == "hindrax_ident":
        return 0
    best = [(len(p), lay) for p, lay in LAYERS if module == p or module.startswith(p + ".")]
    return max(best)[1] if best else TOP_LAYER


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
             "hindrax_sim.model": {"hindrax_onboard.vehicle.x", "hindrax_drivers.frames"},
             "hindrax_drivers.frames": set()}
    assert upward_imports(graph) == {("hindrax_onboard.vehicle.x", "hindrax_sim.model")}
    assert layer_of("hindrax_tools.commands.run") == TOP_LAYER
    assert layer_of("hindrax_drivers.frames") == 0
    assert [layer_of(f"hindrax_ident.{m}") for m in ("vehicle.state", "control.node", "identification.online.node",
                                                     "sim.campaign", "bringup", "graph_campaign")] == [2, 3, 4, 5, 6, 7]


#: The tools room: what engineers run beside the vehicle (``hindrax``, ``make bench``), never what
#it runs.
TOOLS = "hindrax_tools"


def imports_of_tools(graph: dict[str, set[str]]) -> list[str]:
    """``"importer -> tools module"`` for every import of the tools room from outside it."""
    def inside(m: str) -> bool:
        return m == TOOLS or m.startswith(TOOLS + ".")

    return sorted(f"{src} -> {dst}" for src, deps in graph.items() for dst in deps
                  if inside(dst) and not inside(src))


def test_nothing_outside_the_tools_room_imports_it(graph):
    assert f"{TOOLS}.commands.run" in graph and f"{TOOLS}.benchmarks.stack" in graph  # not vacuous
    seen = imports_of_tools({"hindrax_sim.x": {f"{TOOLS}.cli"},
                             f"{TOOLS}.cli": {f"{TOOLS}.bench"}})
    assert seen == [f"hindrax_sim.x -> {TOOLS}.cli"]
    assert imports_of_tools(graph) == []


def test_no_import_from_a_lower_layer_to_a_higher_one(graph):
    # the order is not vacuous: identification holds with the controller's law, the simulator runs the campaign
    assert "hindrax_onboard.control.maneuvers" in graph["hindrax_onboard.identification.online.steps.context"]
    assert "hindrax_onboard.identification.online.executive" in graph["hindrax_sim.campaign"]
    up = sorted(f"{a} -> {b}" for a, b in upward_imports(graph))
    assert not up, "imports from a lower layer to a higher one (drivers < estimation < vehicle < control < " \
                   "identification < sim < bringup < commands):\n" + "\n".join(up)
    assert all(layer_of(m) <= layer_of("hindrax_onboard.vehicle")
               for m in graph.get("hindrax_onboard.vehicle.rigid_body", set()) if m in graph)


# ------------------------------------------------------------------------------------------------ identification rooms
IDENT = "hindrax_onboard.identification"
#: The rooms of the identification package, lowest first: a module imports its own room and the rooms below it. The
#: fit core defines the per-DOF record (``fit_core.DofRecord``, ``Chunk``) that the bag reader returns; the
#: assessment (verdicts, identification.yaml, report, the pipeline) reads, fits and writes.
ROOMS = {"fit": 0, "bag_input": 1, "assessment": 2, "online": 3}
#: Imports a room may not make although the target is below it: the online campaign never writes
#: identification.yaml (its estimator's priors come from the fit's posterior module, not from the writer).
ROOM_FORBIDDEN = {("online", f"{IDENT}.assessment.results")}


def room_of(module: str) -> tuple[str, int] | None:
    """(room, level) of an identification module; the package itself and modules outside it None. A flat module
    outside the rooms is ("?", -1)."""
    if not module.startswith(IDENT + "."):
        return None
    room = module[len(IDENT) + 1:].split(".")[0]
    return (room, ROOMS[room]) if room in ROOMS else ("?", -1)


def room_violations(graph: dict[str, set[str]]) -> list[str]:
    """``"importer -> imported (why)"`` for each import against the rooms' order and for each module outside any
    room."""
    out = [f"{m} (in no room: move it into one of {sorted(ROOMS)})" for m in graph if room_of(m) == ("?", -1)]
    for src, deps in graph.items():
        rs = room_of(src)
        for dst in deps:
            rd = room_of(dst)
            if rs is None or rd is None:
                continue
            if rd[1] > rs[1]:
                out.append(f"{src} -> {dst} (room {rd[0]} is above {rs[0]})")
            elif (rs[0], dst) in ROOM_FORBIDDEN:
                out.append(f"{src} -> {dst} (forbidden for room {rs[0]})")
    return sorted(out)


def test_the_room_checker_sees_a_wrong_import():
    graph = {f"{IDENT}.fit.fit_core": {f"{IDENT}.online.executive"},
             f"{IDENT}.fit.calibration": {f"{IDENT}.assessment.verdicts"},
             f"{IDENT}.online.estimators": {f"{IDENT}.assessment.results", f"{IDENT}.fit.posterior"},
             f"{IDENT}.assessment.verdicts": {f"{IDENT}.fit.fit_core", f"{IDENT}.bag_input.from_bag"},
             f"{IDENT}.flat": set()}
    assert room_violations(graph) == [
        f"{IDENT}.fit.calibration -> {IDENT}.assessment.verdicts (room assessment is above fit)",
        f"{IDENT}.fit.fit_core -> {IDENT}.online.executive (room online is above fit)",
        f"{IDENT}.flat (in no room: move it into one of ['assessment', 'bag_input', 'fit', 'online'])",
        f"{IDENT}.online.estimators -> {IDENT}.assessment.results (forbidden for room online)"]


def test_identification_keeps_its_rooms(graph):
    """fit < bag input < assessment < online; online does not write identification.yaml."""
    rooms = {room_of(m)[0] for m in graph if room_of(m)}
    assert set(ROOMS) <= rooms  # the rule is not vacuous
    assert f"{IDENT}.fit.posterior" in graph[f"{IDENT}.online.estimators"]
    assert f"{IDENT}.fit.fit_core" in graph[f"{IDENT}.bag_input.any_topics"]
    assert room_violations(graph) == []


#: The bag reader: within the identification package, only the bag input room imports it.
BAG_READER = "hindrax_drivers.recording.reader"
#: What modules outside the identification package may import of it: the pipeline (read, fit, write), the campaign's
#: own pieces (its record, its calibration topic, the record's fit and references), the yaml's reader and schema, and
#: the rooms below the assessment's writers. The adapters (``bag_input.from_bag``, ``bag_input.any_topics``), the
#: fits of bags (``fit.fit_any``) and the writers' internals stay behind these faces.
PIPELINE_FACES = frozenset({
    f"{IDENT}.assessment.pipeline", f"{IDENT}.assessment.results", f"{IDENT}.assessment.report",
    f"{IDENT}.assessment.verdicts", f"{IDENT}.assessment.predict", f"{IDENT}.bag_input.reader",
    f"{IDENT}.bag_input.campaign_record", f"{IDENT}.bag_input.calibration_topic",
})
#: Rooms whose every module is a face (the fit's maths and the online campaign are used by the controller, the
#: simulator and the benchmarks directly); the fits of bags in ``fit.fit_any`` are not (:data:`PIPELINE_ONLY`).
OPEN_ROOMS = ("fit", "online")
PIPELINE_ONLY = frozenset({f"{IDENT}.fit.fit_any"})


def pipeline_violations(graph: dict[str, set[str]]) -> list[str]:
    """``"importer -> imported (why)"`` for a bag read outside the bag input room and for an import of the pipeline's
    insides from outside the identification package (:data:`PIPELINE_FACES`)."""
    out = []
    for src, deps in graph.items():
        rs = room_of(src)
        if rs is not None and rs[0] != "bag_input" and BAG_READER in deps:
            out.append(f"{src} -> {BAG_READER} (only the bag input room reads bags)")
        if rs is not None:
            continue
        for dst in deps:
            rd = room_of(dst)
            if rd is None or dst in PIPELINE_FACES or dst == f"{IDENT}.{rd[0]}" or (
                    rd[0] in OPEN_ROOMS and dst not in PIPELINE_ONLY):
                continue
            out.append(f"{src} -> {dst} (outside identification: use the pipeline, "
                       f"{IDENT}.assessment.pipeline, or the bag reader, {IDENT}.bag_input.reader)")
    return sorted(out)


def test_the_pipeline_checker_sees_a_reader_or_an_adapter_used_elsewhere():
    graph = {f"{IDENT}.fit.fit_any": {BAG_READER},
             "hindrax_tools.commands.ident_fit": {
                 f"{IDENT}.bag_input.any_topics", f"{IDENT}.fit.fit_any",
                 f"{IDENT}.assessment.pipeline", f"{IDENT}.fit.fit_core"},
             f"{IDENT}.bag_input.from_bag": {BAG_READER}}
    assert pipeline_violations(graph) == [
        f"{IDENT}.fit.fit_any -> {BAG_READER} (only the bag input room reads bags)",
        f"hindrax_tools.commands.ident_fit -> {IDENT}.bag_input.any_topics "
        "(outside identification: use the "
        f"pipeline, {IDENT}.assessment.pipeline, or the bag reader, {IDENT}.bag_input.reader)",
        f"hindrax_tools.commands.ident_fit -> {IDENT}.fit.fit_any "
        "(outside identification: use the "
        f"pipeline, {IDENT}.assessment.pipeline, or the bag reader, {IDENT}.bag_input.reader)"]


def test_one_pipeline_reads_bags_and_writes_identification(graph):
    """Only the bag input room reads bags; commands, the simulator and the graph runs go through the pipeline."""
    assert BAG_READER in graph[f"{IDENT}.bag_input.any_topics"]  # the rule is not vacuous
    assert f"{IDENT}.assessment.pipeline" in graph["hindrax_tools.commands.ident_fit"]
    assert all(m in graph for m in PIPELINE_FACES | PIPELINE_ONLY)
    assert pipeline_violations(graph) == []


# ------------------------------------------------------------------------------------------------ defined once
#: name -> the one module (path under src/) that defines it.
DEFINED_ONCE = {
    "wrap_angle": "hindrax_drivers/hindrax_drivers/frames.py",
    "ThrustLag": "hindrax_onboard/hindrax_onboard/vehicle/thrust_lag.py",
    "ThrustCurve": "hindrax_drivers/hindrax_drivers/allocation/thrust_curve.py",
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
    "a thrust curve": (r"\bThrustCurve\(", ("allocation/thrust_curve.py", "allocation/from_config.py",
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
CONFIG_MODULES = ("hindrax_drivers.config", "hindrax_drivers.config.sections", "hindrax_drivers.config.loader",
                  "hindrax_drivers.config.typed_sections", "hindrax_drivers.config.node_parameters")
#: Device drivers and safety nodes' packages: the configuration imports none of them, not even through another
#: module; the hardware limits it checks live in ``hindrax_drivers.hardware_limits``, below the driver too.
DRIVER_PACKAGES = tuple(f"hindrax_drivers.{p}" for p in (
    "pca9685", "dvl75", "icm20948", "ms5837", "ping1d", "transport", "guard", "supervisor", "gateway"))


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
    graph = {"hindrax_drivers.config": {"hindrax_drivers.hardware_limits", "hindrax_drivers.frames"},
             "hindrax_drivers.frames": {"hindrax_drivers.pca9685.protocol"}}
    assert driver_imports_of_config(graph) == ["hindrax_drivers.config -> hindrax_drivers.pca9685.protocol"]


def test_the_configuration_imports_no_driver(graph):
    assert all(m in graph for m in CONFIG_MODULES)
    assert "hindrax_drivers.hardware_limits" in graph["hindrax_drivers.config.sections.esc"]
    assert "hindrax_drivers.hardware_limits" in graph["hindrax_drivers.pca9685.protocol"]
    assert driver_imports_of_config(graph) == []
