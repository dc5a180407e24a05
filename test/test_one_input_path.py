"""One input path for every node (issue 47 item 1): the path the vehicle takes is the path the tests take.

Every node takes its topic inputs as subscription callbacks on its own executor, whatever the clock. This test reads
every module of the project's Python packages with :mod:`ast` (nothing is imported) and fails when a
second input path comes back:

- a message taken outside an executor: a call of ``take_message`` (the subscription handle's call that a polled
  intake needs; rclpy's executors make it for every callback), but in the functions of :data:`TAKERS`, each listed
  with why it is not a second path;
- a subscription chosen by the clock: ``create_subscription`` (or any ``subscribe``) inside a branch on
  ``use_sim_time``, or the ``use_sim_time`` parameter read anywhere but the modules of :data:`CLOCK_READERS`, each
  listed with what it chooses by the clock (timers, never inputs);
- the polled-input helpers themselves (a module ``polled_input`` or a class ``PolledInputs`` /
  ``PolledSubscriptions``).

Run alone: ``.venv/bin/python -m pytest -n0 test/test_one_input_path.py -q``.
"""
from __future__ import annotations

import ast
import functools
from pathlib import Path

import pytest

#: one xdist worker parses the packages once for every check here (:func:`_modules` is cached per process)
pytestmark = pytest.mark.xdist_group("one_input_path")

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = tuple(ROOT / "src" / p / p for p in ("hindrax_common", "hindrax_drivers", "hindrax_bringup",
                                                "hindrax_onboard", "hindrax_fit", "hindrax_sim", "hindrax_tools"))

#: Modules that read the ``use_sim_time`` parameter, with what they choose by it (never how an input arrives).
CLOCK_READERS = {
    "hindrax_drivers/pca9685/node.py": "its timers: the output tick on ROS time with use_sim_time (the stepped "
                                       "graph's order), one steady-clock timer for both ticks on the system clock",
}
#: Names of the polled-input helpers that a node used to take its inputs at its own tick.
POLLED_NAMES = frozenset({"polled_input", "PolledInputs", "PolledSubscriptions", "PolledInputsMixin"})
#: Calls that subscribe a node to a topic.
SUBSCRIBE_CALLS = frozenset({"create_subscription", "subscribe", "subscribe_input"})


@functools.cache
def _modules() -> dict[str, ast.Module]:
    """{path relative to the package's parent: parsed module} of every module of :data:`PACKAGES`, parsed once per
    process: the checks only read the trees."""
    out = {}
    for root in PACKAGES:
        for path in sorted(root.rglob("*.py")):
            out[str(path.relative_to(root.parent))] = ast.parse(path.read_text(), filename=str(path))
    return out


@functools.cache
def _nodes() -> dict[str, tuple[ast.AST, ...]]:
    """{path: every node of its tree (``ast.walk`` order)} of :func:`_modules`, walked once per process."""
    return {path: tuple(ast.walk(tree)) for path, tree in _modules().items()}


def _call_name(node: ast.AST) -> str:
    """The called name of a Call (``x.take_message(...)`` -> ``take_message``), else ""."""
    if not isinstance(node, ast.Call):
        return ""
    return node.func.attr if isinstance(node.func, ast.Attribute) else getattr(node.func, "id", "")


def _is_use_sim_time_read(n: ast.AST) -> bool:
    """True when ``n`` is a call with the string ``"use_sim_time"`` as its first argument
    (``get_parameter("use_sim_time")``, ``has_parameter(...)``): reading the parameter, not setting it."""
    return (isinstance(n, ast.Call) and _call_name(n) in ("get_parameter", "has_parameter", "get_parameter_or")
            and bool(n.args) and isinstance(n.args[0], ast.Constant) and n.args[0].value == "use_sim_time")


def _reads_use_sim_time(node: ast.AST) -> bool:
    """True when ``node`` contains a read of the ``use_sim_time`` parameter (:func:`_is_use_sim_time_read`)."""
    return any(map(_is_use_sim_time_read, ast.walk(node)))


def _defines_an_executor(tree: ast.Module) -> bool:
    """True when the module defines a class deriving from an executor of rclpy (a name ending in ``Executor``
    imported from an ``rclpy`` module, e.g. ``rclpy.executors.SingleThreadedExecutor``): an executor takes a
    ready subscription's message as rclpy's own do."""
    rclpy_executors = {a.asname or a.name for n in tree.body if isinstance(n, ast.ImportFrom)
                       and (n.module or "").split(".")[0] == "rclpy" for a in n.names if a.name.endswith("Executor")}
    return any(isinstance(b, ast.Name) and b.id in rclpy_executors
               for c in tree.body if isinstance(c, ast.ClassDef) for b in c.bases)


#: (module, function) that take a message outside an executor, each with why it is not a second input path.
TAKERS = {
    ("hindrax_common/node_support/liveness.py", "fresh"): "before a stale verdict only, the beats already waiting on "
    "the same subscription, through the same identity check and handler (a starved receiver's tick can run before the "
    "callbacks of beats that arrived meanwhile), aged from their send stamps (docs/architecture.md §8)",
}


def test_no_node_takes_a_message_outside_its_executor():
    found = [f"{path}:{n.lineno}" for path, tree in _modules().items() if not _defines_an_executor(tree)
             for f in ast.walk(tree) if isinstance(f, ast.FunctionDef) and (path, f.name) not in TAKERS
             for n in ast.walk(f) if _call_name(n) == "take_message"]
    found += [f"{path}:{n.lineno}" for path, tree in _modules().items() if not _defines_an_executor(tree)
              for n in tree.body if not isinstance(n, (ast.FunctionDef, ast.ClassDef))
              for m in ast.walk(n) if _call_name(m) == "take_message"]
    assert not found, f"messages taken outside an executor (a polled intake, a second input path): {found}"


def test_no_subscription_depends_on_the_clock():
    readers, branched = set(), []
    for path, nodes in _nodes().items():
        for n in nodes:
            if isinstance(n, (ast.If, ast.IfExp)) and _reads_use_sim_time(n.test):
                branches = n.body + n.orelse if isinstance(n, ast.If) else [n.body, n.orelse]
                branched += [f"{path}:{c.lineno}" for b in branches for c in ast.walk(b)
                             if _call_name(c) in SUBSCRIBE_CALLS]
        if any(map(_is_use_sim_time_read, nodes)):
            readers.add(path)
    assert not branched, f"subscriptions chosen by use_sim_time (one input path in both clock modes): {branched}"
    assert readers == set(CLOCK_READERS), (
        f"modules reading use_sim_time: {sorted(readers)}; a new one must choose timers only, never inputs, and be "
        f"listed in CLOCK_READERS with what it chooses; a module no longer reading it leaves the list")


def _names(node: ast.AST) -> list[str]:
    """The names an import statement brings in (its module too) or a class statement defines, else []."""
    if isinstance(node, ast.Import):
        return [a.name for a in node.names]
    if isinstance(node, ast.ImportFrom):
        return [node.module or ""] + [a.name for a in node.names]
    return [node.name] if isinstance(node, ast.ClassDef) else []


def test_the_polled_input_helpers_are_gone():
    modules = _modules()
    assert not [p for p in modules if Path(p).stem in POLLED_NAMES]
    used = sorted({f"{path}: {name}" for path, nodes in _nodes().items() for n in nodes for name in _names(n)
                   if name.rsplit(".", 1)[-1] in POLLED_NAMES})
    assert not used, f"polled-input helpers imported or defined again: {used}"


def test_the_checks_see_what_they_look_for():
    """The checks above find what they forbid (else a green run would mean nothing): the ESC's clock read is found,
    and a polled subscription written the old way is caught by each rule."""
    assert set(CLOCK_READERS) <= set(_modules())
    old = ast.parse("from hindrax_common.polled_input import PolledInputs\n"
                    "if node.get_parameter('use_sim_time').value:\n"
                    "    node.create_subscription(Imu, 'imu/data_raw', cb, 10)\n"
                    "else:\n"
                    "    taken = sub.handle.take_message(Imu, False)\n")
    assert _reads_use_sim_time(old.body[1].test)
    assert [_call_name(c) for c in ast.walk(old) if _call_name(c) in SUBSCRIBE_CALLS | {"take_message"}] == \
        ["create_subscription", "take_message"]
    assert {n.rsplit(".", 1)[-1] for n in _names(old.body[0])} == {"polled_input", "PolledInputs"}
    # an executor is recognised by its rclpy base class, not by its path; a look-alike base is not one
    executor = "from rclpy.executors import SingleThreadedExecutor as S\nclass E(S):\n    pass\n"
    assert _defines_an_executor(ast.parse(executor))
    assert not _defines_an_executor(ast.parse("from mylib import S\nclass E(S):\n    pass\n"))
    assert not _defines_an_executor(ast.parse("from rclpy.node import Node\nclass E(Node):\n    pass\n"))
    assert _defines_an_executor(_modules()["hindrax_sim/graph/ordered_executor.py"])
