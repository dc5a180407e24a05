"""``hindrax allocate X Y Z K M N [--config FILE]``: run the thrust-allocation node's core on one wrench.

The wrench is in base_link (FLU): forces X Y Z in N, moments K M N in N m, about the CG. Prints one JSON
object: ``force_n`` (per thruster, N), ``pulse_width_us`` (per thruster, us), ``achieved_wrench``
(base_link, N and N m), ``scale`` and ``saturated`` (per-thruster flags). Computed by
:class:`hindrax_drivers.allocation.core.AllocationCore`, exactly what the node runs. Exit 1 on an
invalid wrench or configuration.
"""
from __future__ import annotations

import argparse
import json
import sys

from hindrax_drivers.allocation.allocator import InvalidWrenchError
from hindrax_drivers.allocation.core import AllocationCore
from hindrax_drivers.config import ConfigError, default_config_path, load_config


def add_arguments(parser: argparse.ArgumentParser) -> None:
    for name, unit in zip("XYZKMN", ["N"] * 3 + ["N m"] * 3):
        parser.add_argument(name, type=float, help=f"{name} in base_link (FLU), {unit}")
    parser.add_argument("--config", default=None, help="vehicle configuration (default ros_ws/config/hindrax.yaml)")


def run(args: argparse.Namespace) -> int:
    try:
        cfg = load_config(args.config or default_config_path())
    except ConfigError as exc:
        print(f"invalid configuration: {exc}", file=sys.stderr)
        return 1
    try:
        result = AllocationCore(cfg).allocate([args.X, args.Y, args.Z, args.K, args.M, args.N])
    except InvalidWrenchError as exc:
        print(f"rejected: {exc}", file=sys.stderr)
        return 1
    print(json.dumps(result.to_json_dict()))
    return 0
