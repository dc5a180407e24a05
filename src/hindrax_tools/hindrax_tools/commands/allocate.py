"""``hindrax allocate X Y Z K M N [--config FILE]``: run the thrust-allocation node's core on one wrench.

The wrench is in base_link (FLU): forces X Y Z in N, moments K M N in N m, about the CG. Prints one JSON object:
``force_n`` (per thruster, N), ``pulse_width_us`` (per thruster, us), ``achieved_wrench`` (base_link, N and N m),
``scale`` and ``saturated`` (per-thruster flags). Computed by :class:`hindrax_bringup.allocation.core.AllocationCore`,
exactly what the node runs. Exit 1 on an invalid wrench or configuration.

``achieved_wrench`` is what the thrusters give at the printed widths, so it shows every component nobody asked
for: a thruster runs at 0 N or at least its smallest thrust outside the ESC deadband, and the allocator chooses
which thrusters run (docs/architecture.md §9)."""
from __future__ import annotations

import argparse
import json

from hindrax_onboard.commands.common import CommandError, add_config_argument, load_vehicle


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the command's options and arguments to ``parser``."""
    for name, unit in zip("XYZKMN", ["N"] * 3 + ["N m"] * 3):
        parser.add_argument(name, type=float, help=f"{name} in base_link (FLU), {unit}")
    add_config_argument(parser)
    parser.epilog = ("achieved_wrench is what the thrusters give at the printed pulse widths (thrust curves, ESC "
                     "deadband, PCA9685 step): a thruster runs at 0 N or at least its smallest thrust outside the "
                     "deadband, and the allocator chooses which thrusters run (docs/architecture.md §9).")


def run(args: argparse.Namespace) -> int:
    """Run the command with the parsed ``args``; returns the process exit code."""
    from hindrax_bringup.allocation.allocator import InvalidWrenchError
    from hindrax_bringup.allocation.core import AllocationCore

    cfg = load_vehicle(args.config)
    try:
        result = AllocationCore(cfg).allocate([args.X, args.Y, args.Z, args.K, args.M, args.N])
    except InvalidWrenchError as exc:
        raise CommandError(f"rejected: {exc}") from exc
    print(json.dumps(result.to_json_dict()))
    return 0
