"""The vocabulary of the configuration schema: :class:`Spec` (one key's type, range and meaning), the one-line
errors (:class:`ConfigIssue`, :class:`ConfigError`) and the check of one value against its Spec.

Why our own validator: the errors must name ROS parameter keys in the one-line form users see from
``hindrax config check``, and the same checks must run on a YAML file and on the parameters of a running rclpy node; no
maintained schema library covers ROS parameter overrides. generate_parameter_library generates a C++ and Python
parameter module per node at colcon build time (a CMake step), while this stack installs pip wheels and runs from an
editable venv without a colcon build, and the library is not on PyPI. Its schema is per node; ours is per section of one
vehicle file shared by every node, validated as a whole with cross-key checks that need Python. A Spec holds the fields
of one of its entries (``kind`` -> ``type``, ``doc`` -> ``description``, ``lo``/``hi`` -> ``bounds<>``,
``choices`` -> ``one_of<>``, ``length`` -> ``fixed_size<>``), should the stack move."""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np

__all__ = ["Spec", "ConfigIssue", "ConfigError", "check_value", "real", "integer", "text", "flag", "vector",
           "section", "FLOAT", "INT", "STR", "BOOL", "FLOATS", "STRS", "THRUSTER", "DOFS", "TRANSLATIONAL_DOFS",
           "ROTATIONAL_DOFS", "ROS_NAME_TOKEN"]

DOFS: tuple[str, ...] = ("surge", "sway", "heave", "roll", "pitch", "yaw")
"""The six degrees of freedom in SNAME order (nu = [u v w p q r], tau = [X Y Z K M N])."""

TRANSLATIONAL_DOFS = DOFS[:3]
ROTATIONAL_DOFS = DOFS[3:]

#: The path segment of per-thruster keys in the schema (``thrusters.<thruster>.esc_channel``); a file uses the
#: names of ``thrusters.names`` there.
THRUSTER = "<thruster>"

FLOAT = "float"
INT = "int"
STR = "str"
BOOL = "bool"
FLOATS = "float[]"
STRS = "str[]"

#: A ROS 2 name token (rcl's namespace rules: a letter, then letters, digits and single underscores), 1-63 chars.
ROS_NAME_TOKEN = (r"[A-Za-z](?!.*__)[A-Za-z0-9_]{0,62}",
                  "a ROS name token: a letter, then letters, digits or single underscores, at most 63 characters")


@dataclass(frozen=True)
class Spec:
    """Declaration of one configuration key.

    kind: one of "float", "int", "str", "bool", "float[]", "str[]".
    lo/hi: inclusive numeric bounds (for lists: of every element). length: required list length.
    choices: allowed values (str or int). doc: one-line meaning (with unit and source)."""

    kind: str
    doc: str
    lo: float | None = None
    hi: float | None = None
    length: int | None = None
    choices: tuple | None = None
    unit_vector: bool = False
    #: for "str": a regular expression the whole value must match, and its meaning as printed in error lines
    pattern: tuple[str, str] | None = None

    def allowed(self) -> str:
        """Human-readable allowed range, as printed in error lines."""
        if self.choices is not None:
            return "one of " + ", ".join(str(c) for c in self.choices)
        if self.pattern is not None:
            return self.pattern[1]
        base = {FLOAT: "number", INT: "integer", STR: "string", BOOL: "true/false",
                FLOATS: "list of numbers", STRS: "list of strings"}[self.kind]
        if self.length is not None:
            base += f" of length {self.length}"
        if self.lo is not None or self.hi is not None:
            lo = "-inf" if self.lo is None else f"{self.lo:g}"
            hi = "+inf" if self.hi is None else f"{self.hi:g}"
            base += f" in [{lo}, {hi}]"
        if self.unit_vector:
            base += ", unit length"
        return base


def real(doc: str, lo: float | None = None, hi: float | None = None) -> Spec:
    """A number (float) in [lo, hi]."""
    return Spec(FLOAT, doc, lo, hi)


def integer(doc: str, lo: int | None = None, hi: int | None = None, choices: tuple | None = None) -> Spec:
    """An integer in [lo, hi] or among ``choices``."""
    return Spec(INT, doc, lo, hi, choices=choices)


def text(doc: str, choices: tuple | None = None) -> Spec:
    """A string, optionally among ``choices``."""
    return Spec(STR, doc, choices=choices)


def flag(doc: str) -> Spec:
    """true/false."""
    return Spec(BOOL, doc)


def vector(doc: str, length: int, lo: float | None = None, hi: float | None = None, unit: bool = False) -> Spec:
    """A list of ``length`` numbers, each in [lo, hi]; ``unit``: of unit length."""
    return Spec(FLOATS, doc, lo, hi, length=length, unit_vector=unit)


def section(name: str, keys: Mapping[str, Spec],
            optional: Sequence[str] = ()) -> tuple[dict[str, Spec], tuple[str, ...]]:
    """One section of the vehicle file from its own keys, as a section module declares it
    (:mod:`hindrax_common.config.sections`).

    name: the section (``"lights"``). keys: key below ``name.`` -> :class:`Spec`, in the file's order (``<thruster>``,
    :data:`THRUSTER`, for the per-thruster segment). optional: prefixes below ``name.`` of the keys a file may leave
    out (``""``: the whole section). Returns (``SCHEMA``: dotted key -> Spec, ``OPTIONAL``: dotted prefixes)."""
    return {f"{name}.{k}": v for k, v in keys.items()}, tuple(f"{name}.{p}" for p in optional)


@dataclass(frozen=True)
class ConfigIssue:
    """One validation error: the key, the offending value and the allowed range."""

    key: str
    value: Any
    allowed: str

    def line(self) -> str:
        """One line: ``key = value: allowed ...`` (``unknown key`` / ``missing`` where that is the problem)."""
        if self.allowed.startswith("no such key"):
            return f"{self.key} = {_show(self.value)}: unknown key{self.allowed[len('no such key'):]}"
        if self.value == "<missing>":
            return f"{self.key} is missing: allowed {self.allowed}"
        return f"{self.key} = {_show(self.value)}: allowed {self.allowed}"


class ConfigError(ValueError):
    """Raised when a configuration does not validate. ``issues`` lists every problem found.

    ``str(error)`` is the first issue as one line (what a node prints when it refuses to start)."""

    def __init__(self, issues: Sequence[ConfigIssue], source: str = ""):
        self.issues = list(issues)
        self.source = source
        prefix = f"{source}: " if source else ""
        first = self.issues[0].line() if self.issues else "invalid configuration"
        more = f" (and {len(self.issues) - 1} more)" if len(self.issues) > 1 else ""
        super().__init__(f"{prefix}{first}{more}")

    def lines(self) -> list[str]:
        """Every issue as one line each."""
        return [i.line() for i in self.issues]


def _show(value: Any) -> str:
    if isinstance(value, str):
        return repr(value)
    if isinstance(value, (list, tuple, np.ndarray)):
        return "[" + ", ".join(_show(v) for v in value) + "]"
    return str(value)


def check_value(key: str, spec: Spec, value: Any) -> tuple[Any, ConfigIssue | None]:
    """Coerce and check one value of ``key`` against ``spec``. Returns (coerced value, None) or (value, the issue:
    key, value, ``spec.allowed()``)."""
    bad = ConfigIssue(key, value, spec.allowed())

    def number(x: Any) -> float | None:
        if isinstance(x, bool) or not isinstance(x, (int, float, np.integer, np.floating)):
            return None
        x = float(x)
        return x if math.isfinite(x) else None

    def in_range(x: float) -> bool:
        return (spec.lo is None or x >= spec.lo) and (spec.hi is None or x <= spec.hi)

    if spec.kind == FLOAT:
        x = number(value)
        return (x, None) if x is not None and in_range(x) else (value, bad)
    if spec.kind == INT:
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
            return value, bad
        x = int(value)
        ok = (spec.choices is None or x in spec.choices) and in_range(x)
        return (x, None) if ok else (value, bad)
    if spec.kind == STR:
        ok = (isinstance(value, str) and (spec.choices is None or value in spec.choices)
              and (spec.pattern is None or re.fullmatch(spec.pattern[0], value) is not None))
        return value, None if ok else bad
    if spec.kind == BOOL:
        return value, None if isinstance(value, bool) else bad
    if spec.kind == FLOATS:
        if not isinstance(value, (list, tuple, np.ndarray)):
            return value, bad
        maybe = [number(v) for v in value]
        xs = [x for x in maybe if x is not None]
        if len(xs) < len(maybe):
            return value, bad
        if spec.length is not None and len(xs) != spec.length:
            return value, bad
        if not all(in_range(x) for x in xs):
            return value, bad
        if spec.unit_vector and abs(math.sqrt(sum(x * x for x in xs)) - 1.0) > 1e-3:
            return value, bad
        return xs, None
    if spec.kind == STRS:
        if not isinstance(value, (list, tuple)) or not value or not all(isinstance(v, str) for v in value):
            return value, bad
        if spec.choices is not None and any(v not in spec.choices for v in value):
            return value, bad
        return list(value), None
    raise AssertionError(f"unknown spec kind {spec.kind}")  # pragma: no cover - schema bug
