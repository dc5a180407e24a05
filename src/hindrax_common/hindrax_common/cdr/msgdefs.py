r"""Message definitions for MCAP schemas, exactly as rosbag2 (Jazzy) writes them.

An MCAP channel of the ``ros2`` profile points at a schema named ``pkg/msg/Type`` with encoding
``ros2msg`` whose data is the *full* definition (docs/architecture.md §11.6; rosbag2
``rosbag2_cpp/message_definitions/local_message_definition_source.cpp``, Jazzy):

- the type's own ``.msg`` text, verbatim (comments included);
- then, for every dependency in sorted order (``std::set``), depth first, each dependency only once
  for the whole definition: ``"\n"``, a line of 80 ``=``, a line ``MSG: pkg/Type``, then that
  dependency's text (and its own dependencies, recursively).

Dependencies are the first word of each line (``[a-zA-Z0-9_/]+``, optional ``[...]`` array suffix,
then whitespace) that is not a primitive type; a bare ``Type`` means ``<same package>/Type``.

Files come from ``share/<pkg>/msg/`` of every prefix of ``AMENT_PREFIX_PATH`` (colcon / apt on the Pi),
then of the running interpreter's prefix (the pip-wheel venv installs ``share/`` there, docs/architecture.md §11.1).
The RIHS01 type hash comes from ``share/<pkg>/msg/<Type>.json`` (written by
rosidl_generator_type_description), as rosbag2 stores it in ``topic_type_hash``/``type_description_hash``.

Pure: file reads only, no ROS runtime. Errors: :class:`DefinitionNotFoundError` (a ``LookupError``)."""
from __future__ import annotations

import functools
import json
import os
import re
import sys
from pathlib import Path

DELIMITER = "=" * 80
"""The separator line rosbag2 puts before each dependency of a ros2msg full definition."""

PRIMITIVE_TYPES = frozenset({
    "bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16", "int32", "uint32",
    "int64", "uint64", "string", "wstring",
})

# rosbag2: PACKAGE_TYPENAME_REGEX and MSG_FIELD_TYPE_REGEX (local_message_definition_source.cpp)
_TYPE_NAME = re.compile(r"^([a-zA-Z0-9_]+)/(?:msg/|srv/)?([a-zA-Z0-9_]+)$")
_FIELD_TYPE = re.compile(r"(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+")


class DefinitionNotFoundError(LookupError):
    """No ``.msg`` file (or type-description ``.json``) for a type in any share directory searched."""


def split_type_name(type_name: str) -> tuple[str, str]:
    """``"pkg/msg/Type"`` or ``"pkg/Type"`` -> ``("pkg", "Type")``. Raises ValueError on anything else."""
    m = _TYPE_NAME.match(type_name)
    if not m:
        raise ValueError(f"message type name {type_name!r} not understood (expected pkg/msg/Type)")
    return m.group(1), m.group(2)


def normalize_type_name(type_name: str) -> str:
    """``"pkg/Type"`` or ``"pkg/msg/Type"`` -> ``"pkg/msg/Type"`` (the form rosbag2 stores)."""
    pkg, name = split_type_name(type_name)
    return f"{pkg}/msg/{name}"


def share_directories() -> list[Path]:
    """``share`` directories searched, in order: AMENT_PREFIX_PATH entries, then ``sys.prefix``."""
    dirs: list[Path] = []
    for prefix in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep):
        if prefix:
            dirs.append(Path(prefix) / "share")
    for prefix in (sys.prefix, sys.base_prefix):
        d = Path(prefix) / "share"
        if d not in dirs:
            dirs.append(d)
    return dirs


def _interface_file(pkg: str, name: str, ext: str, search: tuple[Path, ...]) -> Path:
    for share in search:
        p = share / pkg / "msg" / f"{name}{ext}"
        if p.is_file():
            return p
    raise DefinitionNotFoundError(
        f"no {pkg}/msg/{name}{ext} in " + ", ".join(str(s) for s in search)
        + " (is the interface package installed?)")


@functools.lru_cache(maxsize=512)
def _msg_text(pkg: str, name: str, search: tuple[Path, ...]) -> str:
    return _interface_file(pkg, name, ".msg", search).read_text()


def msg_dependencies(text: str, package: str) -> list[str]:
    """Sorted non-primitive field types of one ``.msg`` text, as ``pkg/Type`` (rosbag2's rule)."""
    deps: set[str] = set()
    for m in _FIELD_TYPE.finditer(text):
        t = m.group(1)
        if t in PRIMITIVE_TYPES:
            continue
        deps.add(t if "/" in t else f"{package}/{t}")
    return sorted(deps)


def message_definition(type_name: str) -> str:
    """Full ``ros2msg`` definition of ``type_name`` (``pkg/msg/Type``) as rosbag2 Jazzy writes it,
    from the :func:`share_directories`. Raises :class:`DefinitionNotFoundError` when the type or one
    of its dependencies has no ``.msg`` file, and ValueError for a malformed type name."""
    pkg, name = split_type_name(type_name)
    dirs = tuple(share_directories())
    seen: set[str] = set()

    def append(pkg_: str, name_: str, depth: int) -> str:
        if depth <= 0:
            raise RecursionError(f"definition of {type_name} nests too deeply")
        text = _msg_text(pkg_, name_, dirs)
        out = text
        for dep in msg_dependencies(text, pkg_):
            if dep in seen:
                continue
            seen.add(dep)
            dpkg, dname = split_type_name(dep)
            out += "\n" + DELIMITER + "\nMSG: " + dep + "\n" + append(dpkg, dname, depth - 1)
        return out

    return append(pkg, name, 50)


def type_description_hash(type_name: str) -> str:
    """RIHS01 type hash of ``type_name`` from ``share/<pkg>/msg/<Type>.json`` (e.g. ``"RIHS01_6f61..."``).

    Raises :class:`DefinitionNotFoundError` when the JSON file is missing or has no hash for the type."""
    pkg, name = split_type_name(type_name)
    dirs = tuple(share_directories())
    path = _interface_file(pkg, name, ".json", dirs)
    full = f"{pkg}/msg/{name}"
    try:
        doc = json.loads(path.read_text())
        for entry in doc.get("type_hashes", []):
            if entry.get("type_name") == full:
                return str(entry["hash_string"])
    except (ValueError, KeyError, AttributeError) as exc:
        raise DefinitionNotFoundError(f"{path}: unreadable type description ({exc})") from exc
    raise DefinitionNotFoundError(f"{path}: no type hash for {full}")


def _layout(full_text: str) -> list[str]:
    """The field and constant lines of a full definition: comments, blank lines and spacing dropped."""
    out = []
    for line in full_text.split("\n"):
        line = line.split("#", 1)[0].strip()
        if line:
            out.append(" ".join(line.split()))
    return out


def matches_installed(type_name: str, definition: str, type_hash: str | None = None) -> bool:
    """True when a recorded type has the wire layout of the installed one, so the installed Python class
    (and rclpy's C deserializer) can decode its messages.

    type_name: ``pkg/msg/Type``; definition: the full ``ros2msg`` definition stored in the bag's schema;
    type_hash: the channel's ``topic_type_hash`` (RIHS01) when the bag has one. The hashes are compared when
    both exist (they cover the fields, not the comments); otherwise the definitions are compared without their
    comments. False when the installed type or its definition cannot be found: a bag recorded before a message
    changed (a field added, as ``ThrusterPwm.output_state``) must be decoded from its own stored definition."""
    try:
        if type_hash:
            return type_hash == type_description_hash(type_name)
        return _layout(definition) == _layout(message_definition(type_name))
    except (DefinitionNotFoundError, ValueError):
        return False
