"""``hindrax bringup [--config FILE] [--sim] [--record [--record-dir DIR]] [--rtf X] [--seed N]``.

Starts the whole node graph in this process (:mod:`hindrax_ident.bringup`): on the vehicle against the
configured serial ports and I2C bus; with ``--sim`` against the virtual pool and the device emulators.
Runs until Ctrl-C / SIGTERM, then commands neutral thrust and closes any bag.
"""
from __future__ import annotations

import argparse

from .common import add_config_argument


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_config_argument(parser)
    parser.add_argument("--sim", action="store_true", help="virtual pool and emulated devices instead of hardware")
    parser.add_argument("--record", action="store_true", help="record every topic to an MCAP bag")
    parser.add_argument("--record-dir", default="", help="bag directory (default: under recording.output_root)")
    parser.add_argument("--rtf", type=float, default=None, help="simulation real-time factor (0 = fastest)")
    parser.add_argument("--seed", type=int, default=None, help="simulation noise seed")


def run(args: argparse.Namespace) -> int:
    from hindrax_drivers.config import default_config_path

    from hindrax_ident.bringup import run as run_graph

    return run_graph(args.config or default_config_path(), sim=args.sim, record=args.record,
                     record_dir=args.record_dir, seed=args.seed, real_time_factor=args.rtf)
