"""``hindrax bringup [--config FILE] [--sim] [--record [--record-dir DIR]] [--rtf X] [--seed N] [--controller
[--model YAML]]``.

Starts the whole node graph in this process (:mod:`hindrax_sim.graph.bringup`): with ``--sim`` against the virtual pool
and the device emulators (the virtual pool's and the tests' graph). ``--controller`` adds the controller node
(depth/altitude, heading and velocity holds from ``--model``, disabled until ``controller/hold``; docs/control.md §3).
Runs until Ctrl-C / SIGTERM, then commands neutral thrust and closes any bag.

The vehicle does not run this: it runs the launch layout, one process per node, respawned
(``ros2 launch hindrax_bringup vehicle.launch.xml``, started by the Docker image and the systemd unit;
docs/deployment.md). Without ``--sim`` the graph still opens the configured ports and I2C bus (a bench check of
the hardware on one process), after printing :data:`VEHICLE_NOTICE` on stderr."""
from __future__ import annotations

import argparse
import sys

from hindrax_onboard.commands.common import add_config_argument

#: printed on stderr by ``hindrax bringup`` without ``--sim``
VEHICLE_NOTICE = ("bringup: this is the single-process graph of the virtual pool and the tests; the vehicle runs the "
                  "launch layout (ros2 launch hindrax_bringup vehicle.launch.xml: one process per node, respawned; "
                  "docs/deployment.md). Starting it on the hardware for a bench check only.")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the command's options and arguments to ``parser``."""
    add_config_argument(parser)
    parser.add_argument("--sim", action="store_true", help="virtual pool and emulated devices instead of hardware")
    parser.add_argument("--record", action="store_true", help="record every topic to an MCAP bag")
    parser.add_argument("--record-dir", default="", help="bag directory (default: under recording.output_root)")
    parser.add_argument("--rtf", type=float, default=None, help="simulation real-time factor (0 = fastest)")
    parser.add_argument("--seed", type=int, default=None, help="simulation noise seed")
    parser.add_argument("--controller", action="store_true",
                        help="add the controller node (disabled until the service controller/hold; docs/control.md)")
    parser.add_argument("--model", default="", metavar="YAML",
                        help="identification.yaml for the controller's model (default: the vehicle file's)")


def run(args: argparse.Namespace) -> int:
    """Run the command with the parsed ``args``; returns the process exit code."""
    from hindrax_common.config import default_config_path

    from hindrax_sim.graph.bringup import run as run_graph

    if not args.sim:
        print(VEHICLE_NOTICE, file=sys.stderr, flush=True)
    return run_graph(args.config or default_config_path(), sim=args.sim, record=args.record, record_dir=args.record_dir,
                     seed=args.seed, real_time_factor=args.rtf, controller=args.controller, model_file=args.model)
