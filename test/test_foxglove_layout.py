"""The Foxglove layout of the pool campaign names only topics the stack publishes and fields their messages have.

Topics and types come from the stack's own source (every ``create_publisher(Type, "topic", ...)`` of the
node packages and the module the type is imported from), fields from the message definitions (rosidl
introspection of the installed interfaces, ``get_fields_and_field_types``).
"""
from __future__ import annotations

import importlib
import json
import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
LAYOUT = REPO / "src" / "hindrax_onboard" / "foxglove" / "pool_test.json"


def published_topics() -> dict[str, type]:
    """'/topic' -> message class, from the create_publisher calls of the node packages (tests and benchmarks out)."""
    out: dict[str, type] = {}
    for f in REPO.glob("src/hindrax_*/hindrax_*/**/*.py"):
        if "benchmarks" in f.parts:
            continue
        text = f.read_text()
        imported: dict[str, tuple[str, str]] = {}  # local name -> (package, message name)
        for pkg, names in (re.findall(r"from (\w+)\.msg import \(([^)]*)\)", text)
                           + re.findall(r"from (\w+)\.msg import ([^\n(]+)", text)):
            for item in names.split(","):
                words = item.split()
                if words:
                    imported[words[-1]] = (pkg, words[0])
        for type_name, topic in re.findall(r'(?:create|sensor)_publisher\(\s*(\w+)\s*,\s*"([^"]+)"', text):
            if type_name not in imported:
                continue
            pkg, real = imported[type_name]
            cls = getattr(importlib.import_module(f"{pkg}.msg"), real)
            out[topic if topic.startswith("/") else "/" + topic] = cls
    return out


def _field_type(cls: type, name: str) -> str:
    fields = cls.get_fields_and_field_types()
    assert name in fields, f"{cls.__module__}.{cls.__name__} has no field {name!r} (fields: {sorted(fields)})"
    return fields[name]


def _class_of(type_str: str):
    """Message class of a rosidl field type such as 'geometry_msgs/Vector3' or 'sequence<pkg/T>'; None if basic."""
    base = re.sub(r"^sequence<(.+?)(, \d+)?>$", r"\1", type_str)
    base = re.sub(r"\[\d+\]$", "", base)
    if "/" not in base:
        return None
    pkg, name = base.split("/")
    return getattr(importlib.import_module(f"{pkg}.msg"), name)


def resolve(path: str, topics: dict[str, type]) -> str:
    """Check one Foxglove message path (``/topic{field=="x"}.a.b[0]``); returns the leaf field type."""
    m = re.match(r"^(/[A-Za-z0-9_/]+?)((?:\{[^}]*\})*)((?:\.[A-Za-z0-9_\[\]]+)*)$", path)
    assert m, f"unparsed path {path}"
    topic, filters, fields = m.groups()
    assert topic in topics, f"{path}: topic {topic} is published by no node of the stack"
    cls = topics[topic]
    for flt in re.findall(r"\{(\w+)==", filters):
        _field_type(cls, flt)
    leaf = f"{cls.__module__}/{cls.__name__}"
    for part in [p for p in fields.split(".") if p]:
        name = re.sub(r"\[\d+\]$", "", part)
        assert cls is not None, f"{path}: {name} below a basic type"
        leaf = _field_type(cls, name)
        if part != name:
            assert leaf.startswith("sequence<") or re.search(r"\[\d+\]$", leaf), f"{path}: {name} is not an array"
            leaf = re.sub(r"^sequence<(.+?)(, \d+)?>$", r"\1", re.sub(r"\[\d+\]$", "", leaf))  # element type
        cls = _class_of(leaf)
    return leaf


def _paths(config: dict) -> list[str]:
    out = []
    for panel_id, cfg in config.items():
        kind = panel_id.split("!")[0]
        if kind in ("Plot", "StateTransitions"):
            out += [p["value"] for p in cfg["paths"]]
        elif kind == "RawMessages":
            out.append(cfg["topicPath"])
        elif kind == "DiagnosticSummary":
            out.append(cfg["topicToRender"])
    return out


def _panels(tree) -> set[str]:
    if isinstance(tree, str):
        return {tree}
    return _panels(tree["first"]) | _panels(tree["second"])


def test_every_plotted_topic_and_field_exists_in_the_stack():
    doc = json.loads(LAYOUT.read_text())
    topics = published_topics()
    paths = _paths(doc["configById"])
    assert len(paths) >= 20
    leaves = {p: resolve(p, topics) for p in paths}
    # plotted and state-transition values are single numbers or booleans, not messages or arrays
    for panel_id, cfg in doc["configById"].items():
        if panel_id.split("!")[0] in ("Plot", "StateTransitions"):
            for p in (x["value"] for x in cfg["paths"]):
                assert re.fullmatch(r"double|float|u?int\d+|boolean|octet", leaves[p]), (p, leaves[p])
    # the campaign's views are all there
    joined = " ".join(paths)
    for needed in ("/dvl/data.velocity_m_s", "/identification/status.level_command", "/pressure/depth",
                   "/ping/altitude", "/thrusters/pulse_width.pulse_width_us", "/identification/estimates",
                   ".std[", "/identification/status.phase", "/diagnostics"):
        assert needed in joined, needed
    # every panel configured is placed in the layout and vice versa
    assert _panels(doc["layout"]) == set(doc["configById"])


def test_the_checker_rejects_a_missing_topic_or_field():
    topics = published_topics()
    for bad in ("/dvl/nothing.velocity_m_s.x", "/dvl/data.velocity.x", "/thrusters/pulse_width.armed[0]"):
        try:
            resolve(bad, topics)
        except AssertionError:
            continue
        raise AssertionError(f"{bad} accepted")
