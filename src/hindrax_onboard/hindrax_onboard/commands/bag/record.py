"""``hindrax bag record``: record topics to a rosbag2-compatible MCAP bag until Ctrl-C or --duration.

Selection: ``--topics T [T ...]``, ``--regex R`` and/or ``--all``; none of them records the configured
``recording.topics`` (hindrax.yaml), else every topic. Topics appearing later are added. Chunking, compression and
splitting come from the ``recording.*`` keys of the configuration file (``--config``). Ctrl-C / SIGTERM / the end of
``--duration`` finish the bag; prints the bag path and message count. Exit 0, 1 on a configuration or output-directory
error (one line on stderr). Implementation: :class:`hindrax_bringup.recording.recorder_node.RecorderNode`."""
from __future__ import annotations

import argparse
import sys
import time

from ..common import CommandError, add_config_argument


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the command's options and arguments to ``parser``."""
    parser.add_argument("--topics", nargs="+", default=[], metavar="TOPIC", help="topics to record")
    parser.add_argument("--regex", default="", help="record topics matching this regular expression")
    parser.add_argument("--all", action="store_true", dest="all_topics", help="record every (non-hidden) topic")
    parser.add_argument("--out", default="", metavar="DIR",
                        help="bag directory to create (default: timestamped under recording.output_root)")
    parser.add_argument("--duration", type=float, default=0.0, metavar="S",
                        help="stop after S seconds (default: until Ctrl-C)")
    add_config_argument(parser, default="")


def run(args: argparse.Namespace) -> int:
    """Run the command with the parsed ``args``; returns the process exit code."""
    import rclpy
    from rclpy.parameter import Parameter

    from hindrax_common.config import ConfigError
    from hindrax_bringup.recording.recorder_node import RecorderNode
    from hindrax_common.process.ros_process import RosProcess

    if args.duration < 0:
        raise CommandError("hindrax bag record: --duration must be >= 0")
    overrides = [Parameter("autostart", value=True), Parameter("all_topics", value=bool(args.all_topics)),
                 Parameter("topic_regex", value=args.regex), Parameter("output_dir", value=args.out)]
    if args.topics:
        overrides.append(Parameter("topics", value=list(args.topics)))
    if args.config:
        overrides.append(Parameter("config_file", value=args.config))
    with RosProcess([]) as proc:
        try:
            node = RecorderNode(parameter_overrides=overrides)
        except (ConfigError, ValueError, OSError, RuntimeError) as exc:
            raise CommandError(f"hindrax bag record: {str(exc).splitlines()[0]}") from exc

        def finish() -> None:
            """Close the bag (also after SIGINT/SIGTERM); a failure points at ``hindrax bag recover``."""
            try:
                meta = node.stop_recording()
            except Exception as exc:  # noqa: BLE001 - report and point at recovery
                print(f"hindrax bag record: bag {node.bag_path} not finished: {exc}; run `hindrax bag recover "
                      f"{node.bag_path}`", file=sys.stderr)
                proc.status = 1
            else:
                if meta is not None:
                    print(f"{node.bag_path}: {meta.message_count} messages on {len(meta.topics)} topics")
            proc.executor.remove_node(node)
            node.destroy_node()

        proc.at_exit(finish)
        proc.executor.add_node(node)
        deadline = time.monotonic() + args.duration if args.duration > 0 else None
        while rclpy.ok() and (deadline is None or time.monotonic() < deadline):
            proc.executor.spin_once(timeout_sec=0.1)
    return proc.status
