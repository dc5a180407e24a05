"""What every ``hindrax`` command shares: the ``--config`` option, loading the vehicle file, the error exit.

A command raises :class:`CommandError` for a problem it found (bad input, invalid configuration): the
``hindrax`` entry point (:func:`hindrax_ident.cli.main`) prints its one-line message on stderr and exits 1.
Only the standard library is imported here at module level, so defining a command's arguments stays cheap
(``hindrax --help`` imports no command module at all, :mod:`hindrax_ident.cli`).
"""
from __future__ import annotations

import argparse
import re
from pathlib import Path
from typing import Any, Mapping

__all__ = ["CommandError", "CONFIG_HELP", "add_config_argument", "load_vehicle", "update_vehicle_file"]

CONFIG_HELP = "vehicle configuration (default ros_ws/config/hindrax.yaml)"


class CommandError(Exception):
    """A command found a problem: its message (one line) goes to stderr and the exit status is 1."""


def add_config_argument(parser: argparse.ArgumentParser, default: Any = None) -> None:
    """``--config FILE``: the vehicle configuration (None or empty: the default file, :func:`load_vehicle`)."""
    parser.add_argument("--config", default=default, metavar="FILE", help=CONFIG_HELP)


def load_vehicle(path: str | None = None) -> Any:
    """The validated :class:`~hindrax_drivers.config.VehicleConfig` of ``path`` (default: the repository's
    ``ros_ws/config/hindrax.yaml``).

    Raises :class:`CommandError` ``"invalid configuration: <key, value, allowed range>"`` when the file does
    not load or validate (:class:`~hindrax_drivers.config.ConfigError`).
    """
    from hindrax_drivers.config import ConfigError, default_config_path, load_config

    try:
        return load_config(path or default_config_path())
    except ConfigError as exc:
        raise CommandError(f"invalid configuration: {exc}") from exc


def update_vehicle_file(path: str | Path, values: Mapping[str, str]) -> None:
    """Set ``key: value`` in the vehicle file ``path`` in place, keeping every other line and each line's comment;
    then validate the file and restore the original text if it no longer validates.

    values: {key as written on its line (e.g. ``"oscillator_hz"``): the value's YAML text, a scalar or a one-line
    flow list such as ``"[1.0, 2.0]"``}; each key must stand on exactly one line of the file.
    Raises ValueError when a key is missing or stands on several lines (the file is not written),
    :class:`~hindrax_drivers.config.ConfigError` when the result does not validate (the file is restored).
    """
    from hindrax_drivers.config import ConfigError, load_config

    p = Path(path)
    original = p.read_text()
    text = original
    for key, value in values.items():
        pattern = re.compile(rf"^(\s*{re.escape(key)}:\s*)(\[[^\]\n]*\]|[^\s#]+)(.*)$", re.MULTILINE)
        found = len(pattern.findall(text))
        if found != 1:
            raise ValueError(f"{path}: expected exactly one '{key}:' line to update, found {found}")
        text = pattern.sub(lambda m, v=value: m.group(1) + v + m.group(3), text, count=1)
    p.write_text(text)
    try:
        load_config(p)
    except ConfigError:
        p.write_text(original)
        raise
