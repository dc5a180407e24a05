"""``hindrax bag play BAG``: publish a bag with its recorded timing (options: ``--help``).

The safety and actuation topics (heartbeats, ``thrusters/*``, ``esc/*``, ``supervisor/*``, ``guard/*``, ``wrench``,
setpoints, action topics) are withheld unless ``--safety-topics``, so that a bag never answers for a vehicle's
supervisor or drives its thrusters; that option is refused while an ESC or supervisor is on the graph. Give BAG first
(``--topics`` takes every following word). Exit 0 when played, 1 with one line on stderr when the bag cannot be played
or is refused. Implementation: :class:`hindrax_bringup.recording.player_node.BagPlayerNode`."""
from __future__ import annotations

import argparse


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the command's options and arguments to ``parser``."""
    parser.add_argument("bag", help="bag directory or .mcap file")
    parser.add_argument("--rate", type=float, default=1.0, help="playback rate factor (default 1)")
    parser.add_argument("--start-offset", type=float, default=0.0, metavar="S",
                        help="start S seconds after the beginning of the bag")
    parser.add_argument("--topics", nargs="+", default=[], metavar="TOPIC", help="play only these topics")
    parser.add_argument("--loop", action="store_true", help="repeat until Ctrl-C")
    parser.add_argument("--clock", nargs="?", type=float, const=100.0, default=0.0, metavar="HZ",
                        help="publish /clock at HZ (default 100 Hz when given without a value)")
    parser.add_argument("--wait-subscribers", type=float, default=5.0, metavar="S",
                        help="wait up to S s for subscribers before starting (default 5)")
    parser.add_argument("--safety-topics", action="store_true",
                        help="also publish the bag's safety and actuation topics (heartbeats, thrusters, esc, "
                             "supervisor, guard, wrench, setpoints); refused while an ESC or supervisor is on the "
                             "graph. For a bench graph without a vehicle only")


def run(args: argparse.Namespace) -> int:
    """Run the command with the parsed ``args``; returns the process exit code."""
    from rclpy.parameter import Parameter

    from hindrax_bringup.recording.player_node import REFUSAL, BagPlayerNode, PlayerError
    from hindrax_common.process.ros_process import RosProcess
    from hindrax_common.node_support.vehicle_graph import ForeignVehicleError, refuse_before_start

    overrides = [Parameter("bag", value=str(args.bag)), Parameter("rate", value=float(args.rate)),
                 Parameter("start_offset_s", value=float(args.start_offset)), Parameter("loop", value=bool(args.loop)),
                 Parameter("clock", value=bool(args.clock > 0)),
                 Parameter("clock_rate_hz", value=float(args.clock) if args.clock > 0 else 100.0),
                 Parameter("wait_for_subscribers_timeout_s", value=float(args.wait_subscribers)),
                 Parameter("safety_topics", value=bool(args.safety_topics))]
    if args.topics:
        overrides.append(Parameter("topics", value=list(args.topics)))
    with RosProcess([], errors={PlayerError: "hindrax bag play", ForeignVehicleError: "hindrax bag play"}) as proc:
        if args.safety_topics:  # the domain watched before the player's node exists: a refusal leaves nothing
            refuse_before_start(None, REFUSAL)
        node = proc.own(BagPlayerNode(parameter_overrides=overrides, window_s=0.0))  # (the window was just watched)
        node.wait_for_subscribers()
        stats = node.play()
        print(f"{args.bag}: published {stats.published} messages in {stats.passes} pass(es)")
    return proc.status
