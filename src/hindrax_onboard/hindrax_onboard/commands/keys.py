"""``hindrax keys [--vehicle NAME | --config FILE] [--force]``: create the vehicle's operator key.

Run on the vehicle: writes a new random 32-byte key to ``<keys dir>/<name>.key`` (``$HINDRAX_KEYS_DIR``, default
``~/.config/hindrax/keys``; mode 0600) for the vehicle named, else the vehicle file's ``vehicle.name``, and prints
where it is and where the topside copy goes: the same path on the operator's PC, mode 0600. The gateway checks every
operator request against it (docs/architecture.md §8.2, :mod:`hindrax_bringup.gateway.operator_signing`); the
``hindrax`` command signs with it. An existing key is kept unless ``--force`` (a new key must be copied to the topside
again). Exit 1 with one line when the key exists or the vehicle file is invalid."""
from __future__ import annotations

import argparse

from .common import CommandError, add_config_argument, load_vehicle

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the command's options to ``parser``."""
    add_config_argument(parser)
    parser.add_argument("--vehicle", default=None, metavar="NAME", help="the vehicle's name (default: the vehicle "
                        "file's vehicle.name)")
    parser.add_argument("--force", action="store_true", help="replace an existing key")


def run(args: argparse.Namespace) -> int:
    """Run the command with the parsed ``args``; returns the process exit code."""
    from hindrax_bringup.gateway.operator_signing import OperatorKeyError, create_key, key_path

    name = args.vehicle or load_vehicle(args.config).vehicle.name
    try:
        path = create_key(key_path(name), force=args.force)
    except OperatorKeyError as exc:
        raise CommandError(f"hindrax keys: {exc}") from None
    print(f"{name}: operator key written to {path} (mode 0600)")
    print(f"copy it to the operator's PC at the same place, mode 0600 (e.g. scp -p {path} topside:{path}); "
          "then restart the gateway")
    return 0
