"""What every ``hindrax`` command shares: the ``--config`` option, loading the vehicle file, the error exit.

A command raises :class:`CommandError` for a problem it found (bad input, invalid configuration): the
``hindrax`` entry point (:func:`hindrax_onboard.cli.main`) prints its one-line message on stderr and
exits 1. Only the standard library is imported here at module level, so defining a command's arguments
stays cheap (``hindrax --help`` imports no command module at all, :mod:`hindrax_onboard.cli`)."""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any, Mapping

__all__ = ["CommandError", "add_config_argument", "choices", "load_vehicle", "update_vehicle_file", "yaml_float"]


class CommandError(Exception):
    """A command found a problem: its message (one line) goes to stderr and the exit status is 1."""


def add_config_argument(parser: argparse.ArgumentParser, default: Any = None) -> None:
    """``--config FILE``: the vehicle configuration (None or empty: the default file, :func:`load_vehicle`)."""
    parser.add_argument("--config", default=default, metavar="FILE",
                        help="vehicle configuration (default ros_ws/config/hindrax.yaml)")


def choices(option: str, text: str | None, allowed, what: str, empty_ok: bool = True) -> list[str]:
    """The comma-separated words of ``text`` (None or blank: none). Raises :class:`CommandError` ``"<option>: unknown
    <what>(s) [...]; choose from ..."`` for a word not in ``allowed``, or for none when not ``empty_ok``."""
    words = [w.strip() for w in str(text or "").split(",") if w.strip()]
    bad = [w for w in words if w not in allowed]
    if bad or not (words or empty_ok):
        raise CommandError(f"{option}: unknown {what}(s) {bad}; choose from {', '.join(allowed)}")
    return words


def load_vehicle(path: str | None = None) -> Any:
    """The validated :class:`~hindrax_common.config.VehicleConfig` of ``path`` (default: the repository's
    ``ros_ws/config/hindrax.yaml``).

    Raises :class:`CommandError` ``"invalid configuration: <key, value, allowed range>"`` when the file does
    not load or validate (:class:`~hindrax_common.config.ConfigError`)."""
    from hindrax_common.config import ConfigError, default_config_path, load_config

    try:
        return load_config(path or default_config_path())
    except ConfigError as exc:
        raise CommandError(f"invalid configuration: {exc}") from exc


def _round_trip_yaml() -> Any:
    """A ruamel.yaml round-trip loader/dumper that reproduces the shipped vehicle file byte for byte.

    Lines are never wrapped (flow collections stay on their line), ``null`` is written as ``null``, and a float
    set by a command as :func:`yaml_float` writes it. Floats read from the file keep their text."""
    from ruamel.yaml import YAML
    from ruamel.yaml.representer import RoundTripRepresenter

    class _Representer(RoundTripRepresenter):  # own class: ruamel's representer table is class-wide
        pass

    _Representer.add_representer(type(None), lambda r, _: r.represent_scalar("tag:yaml.org,2002:null", "null"))
    _Representer.add_representer(float, lambda r, v: r.represent_scalar("tag:yaml.org,2002:float", yaml_float(v)))
    yaml = YAML(typ="rt")
    yaml.Representer = _Representer
    yaml.preserve_quotes = True
    yaml.width = 1 << 16
    yaml.indent(mapping=2, sequence=4, offset=2)
    return yaml


def yaml_float(value: float) -> str:
    """``value`` with 10 significant digits in a form YAML 1.1 (PyYAML) reads back as a float.

    YAML 1.1's float pattern needs a decimal point: ``-4e-07`` or ``1500`` would load as a string or an int,
    so the mantissa always carries one (``-4.0e-07``, ``1500.0``)."""
    text = f"{float(value):.10g}"
    mantissa, sep, exponent = text.partition("e")
    if "." not in mantissa and mantissa.lstrip("-").isdigit():
        mantissa += ".0"
    return mantissa + sep + exponent


def update_vehicle_file(path: str | Path, values: Mapping[str, Any],
                        new_keys: Mapping[str, tuple[str, str]] | None = None) -> None:
    """Set dotted keys of the vehicle file ``path`` in place with a round-trip YAML library (ruamel.yaml),
    keeping every comment, the key order and every other value; then validate the file and restore the
    original text if it no longer validates.

    values: {dotted key below ``ros__parameters`` (e.g. ``"esc.oscillator_hz"``): its new value (bool, int, float, str
    or a list of them; a list is written in flow style, ``[1.0, 2.0]``)}. new_keys: {dotted key of ``values`` that may
    be absent: (sibling key it is inserted after, end-of-line comment)}; any other key must already be in the file.
    Raises ValueError when a key (or its section) is missing (the file is not written),
    :class:`~hindrax_common.config.ConfigError` when the result does not validate (the file is restored)."""
    from ruamel.yaml.comments import CommentedMap, CommentedSeq

    from hindrax_common.config import ConfigError, load_config

    p = Path(path)
    original = p.read_text()
    yaml = _round_trip_yaml()
    doc = yaml.load(original)
    node = next(iter(doc.values()), None) if isinstance(doc, CommentedMap) and len(doc) == 1 else None
    params = node.get("ros__parameters") if isinstance(node, CommentedMap) else None
    if not isinstance(params, CommentedMap):
        raise ValueError(f"{path}: not a params file {{'/**': {{'ros__parameters': {{...}}}}}}")
    new_keys = new_keys or {}
    for dotted, value in values.items():
        *sections, key = dotted.split(".")
        parent = params
        for name in sections:
            parent = parent.get(name) if isinstance(parent, CommentedMap) else None
        if not isinstance(parent, CommentedMap):
            raise ValueError(f"{path}: no section '{'.'.join(sections)}' for '{dotted}'")
        if isinstance(value, (list, tuple)):
            value = CommentedSeq(value)
            value.fa.set_flow_style()
        if key in parent:
            parent[key] = value
        elif dotted in new_keys:
            after, comment = new_keys[dotted]
            if after not in parent:
                raise ValueError(f"{path}: no '{after}' to add '{dotted}' after")
            parent.insert(list(parent).index(after) + 1, key, value, comment=comment)
        else:
            raise ValueError(f"{path}: no key '{dotted}' to update")
    with p.open("w") as stream:
        yaml.dump(doc, stream)
    try:
        load_config(p)
    except ConfigError:
        p.write_text(original)
        raise
