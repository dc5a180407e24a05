"""Write src/hindrax_common/hindrax_common/config/typed_sections.py: one frozen dataclass per configuration section.

The classes mirror ``config.SCHEMA`` exactly (field name = the key's last segment, nested dataclasses where the
key nests, Python type from ``Spec.kind``, ``X | None`` for optional keys). The ``thrusters`` section is the
hand-written ``ThrustersConfig``/``ThrusterConfig`` of config/sections/thrusters.py (its keys are per thruster name).

Usage: ``python scripts/gen_config_sections.py`` (rewrites the file) or ``--check`` (exit 1 if it is stale);
test_config_sections.py runs the check, so an edit of SCHEMA without regenerating fails the tests.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "src" / "hindrax_common" / "hindrax_common" / "config" / "typed_sections.py"
sys.path.insert(0, str(ROOT / "src" / "hindrax_common"))

from hindrax_common import config as c  # noqa: E402

#: sections whose typed object is hand-written in their section module (not generated)
HAND_WRITTEN = ("thrusters",)
TYPES = {"float": "float", "int": "int", "str": "str", "bool": "bool", "float[]": "tuple[float, ...]",
         "str[]": "tuple[str, ...]"}

HEADER = '''"""Typed configuration sections: frozen dataclasses of the vehicle file (GENERATED).

Do not edit: written by ``scripts/gen_config_sections.py`` from ``hindrax_common.config.SCHEMA``; the tests check that
this file is current. Field names are the keys' last segments, nested dataclasses follow the nesting of the keys
(sibling sections with the same keys share one class, ``HydrodynamicsSurgeSwaySection``: a section's dotted path is
given when it is built), optional keys are ``X | None`` (None when absent) and lists are tuples. Build them through
:class:`hindrax_common.config.VehicleConfig` (``cfg.esc.output_latency_s``), never by hand. A required key that a node
did not declare among its parameters is absent from its configuration: reading it raises KeyError naming the key. Each
field's unit and meaning: its key's ``Spec.doc`` in SCHEMA."""
from dataclasses import dataclass, fields
from typing import Any, ClassVar, dataclass_transform

ABSENT: Any = type("Absent", (), {"__repr__": lambda self: "<absent>"})()
"""Marks a required key this configuration does not hold (a node's selection of keys) in :meth:`Section.build`."""


@dataclass_transform(frozen_default=True, eq_default=False)
class Section:
    """Base of the generated sections, each a frozen dataclass compared by identity: ``PREFIX`` is the dotted path (the
    ``prefix`` class keyword of a subclass, ``class X(Section, prefix="esc")``); reading an absent key raises KeyError.

    An absent required key is simply not set on the instance, so reading a present field is a plain attribute
    read (no per-access check on the control loops' paths) and only a missing one reaches :meth:`__getattr__`."""

    PREFIX: ClassVar[str] = ""

    def __init_subclass__(cls, prefix: str | None = None, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if prefix is not None:
            cls.PREFIX = prefix
        dataclass(frozen=True, eq=False, repr=False)(cls)

    @classmethod
    def build(cls, values: dict[str, Any], prefix: str | None = None) -> Any:
        """An instance holding ``values`` (field name -> value; ABSENT values left unset); ``prefix`` overrides
        ``PREFIX`` in the KeyError messages (e.g. ``thrusters.t3``). Bypasses ``__init__``: the values are
        validated already."""
        obj = object.__new__(cls)
        for name, value in values.items():
            if value is not ABSENT:
                object.__setattr__(obj, name, value)
        if prefix is not None:
            object.__setattr__(obj, "PREFIX", prefix)
        return obj

    def __getattr__(self, name: str) -> Any:
        """Called only for an attribute the instance lacks: KeyError naming the dotted key of an absent field."""
        if name in {f.name for f in fields(self)}:  # type: ignore[arg-type]  # every subclass is a dataclass
            raise KeyError(f"{self.PREFIX}.{name}")
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    def __repr__(self) -> str:
        """``ClassName(field=value, ...)`` with absent keys shown as <absent>."""
        names = [f.name for f in fields(self)]  # type: ignore[arg-type]  # every subclass is a dataclass
        items = ", ".join(f"{k}={self.__dict__.get(k, ABSENT)!r}" for k in names)
        return f"{type(self).__name__}({items})"
'''


def _camel(path: str) -> str:
    return "".join(p[:1].upper() + p[1:] for p in path.replace("_", ".").split(".")) + "Section"


def _tree() -> dict:
    tree: dict = {}
    for key, spec in c.SCHEMA.items():
        parts = key.split(".")
        if parts[0] in HAND_WRITTEN:
            continue
        node = tree
        for p in parts[:-1]:
            node = node.setdefault(p, {})
        node[parts[-1]] = (key, spec)
    return tree


def _type(key: str, spec) -> str:
    return TYPES[spec.kind] + (" | None" if c.is_optional(key) else "")


def _class_names(path: str, node: dict) -> dict[str, str]:
    """Class name of each nested section of ``node``: sibling sections with the same keys (and no
    nested sections) share one class, named after all of them (``HydrodynamicsSurgeSwaySection``).
    """
    groups: dict = {}
    for name, sub in node.items():
        if isinstance(sub, dict):
            leaves = all(not isinstance(v, dict) for v in sub.values())
            shape = tuple((n, _type(*v)) for n, v in sub.items()) if leaves and path else name
            groups.setdefault(shape, []).append(name)
    return {name: _camel(".".join([path, *members]) if path else members[0])
            for members in groups.values() for name in members}


def _classes(path: str, node: dict, out: list[str], cls: str = "") -> None:
    names = _class_names(path, node)
    emitted: set[str] = set()
    for name, sub in node.items():
        if isinstance(sub, dict) and names[name] not in emitted:
            emitted.add(names[name])
            _classes(f"{path}.{name}" if path else name, sub, out, names[name])
    if not path:
        return
    lines = ["", "", f'class {cls}(Section, prefix="{path}"):']
    for name, sub in node.items():
        lines.append(f"    {name}: {names[name] if isinstance(sub, dict) else _type(*sub)}")
    out.append("\n".join(lines) + "\n")


def render() -> str:
    """The source of typed_sections.py for the current SCHEMA."""
    out: list[str] = [HEADER]
    _classes("", _tree(), out)
    return "".join(out)


def main() -> int:
    """Rewrite typed_sections.py, or with --check report whether it is current (exit status 1 if not)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="exit 1 if typed_sections.py is not current")
    args = ap.parse_args()
    text = render()
    if args.check:
        current = OUT.read_text() if OUT.is_file() else ""
        if current != text:
            print(f"{OUT} is stale: run python scripts/gen_config_sections.py")
            return 1
        return 0
    OUT.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
