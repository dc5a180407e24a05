"""What every ``hindrax`` command shares: the ``--config`` option, loading the vehicle file, the error exit.

A command raises :class:`CommandError` for a problem it found (bad input, invalid configuration): the
``hindrax`` entry point (:func:`hindrax_ident.cli.main`) prints its one-line message on stderr and exits 1.
Only the standard library is imported here at module level, so defining a command's arguments stays cheap
(``hindrax --help`` imports no command module at all, :mod:`hindrax_ident.cli`).
"""
from __future__ import annotations

import argparse
from typing import Any

__all__ = ["CommandError", "CONFIG_HELP", "add_config_argument", "load_vehicle"]

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
