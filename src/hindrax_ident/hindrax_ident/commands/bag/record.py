"""``hindrax bag record``: record topics to a rosbag2-compatible MCAP bag until Ctrl-C or --duration.

Selection: ``--topics T [T ...]``, ``--regex R`` and/or ``--all``; none of them records the configured
``recording.topics`` (hindrax.yaml), else every topic. Topics appearing later are added. Chunking,
compression and splitting come from the ``recording.*`` keys of the configuration file (``--config``).
Ctrl-C / SIGTERM / the end of ``--duration`` finish the bag; prints the bag path and message count.
Exit 0, 1 on a configuration or output-directory error (one line on stderr).
Implementation: :class:`hindrax_drivers.recording.recorder_node.RecorderNode`.
"""
from __future__ import annotations

import argparse
import sys
import time


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--topics", nargs="+", default=[], metavar="TOPIC", help="topics to record")
    parser.add_argument("--regex", default="", help="record topics matching this regular expression")
    parser.add_argument("--all", action="store_true", dest="all_topics", help="record every (non-hidden) topic")
    parser.add_argument("--out", default="", metavar="DIR",
                        help="bag directory to create (default: timestamped under recording.output_root)")
    parser.add_argument("--duration", type=float, default=0.0, metavar="S",
                        help="stop after S seconds (default: until Ctrl-C)")
    parser.add_argument("--config", default="", metavar="FILE",
                        help="vehicle configuration (default: ros_ws/config/hindrax.yaml)")


def run(args: argparse.Namespace) -> int:
    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from rclpy.parameter import Parameter

    from hindrax_drivers.config import ConfigError
    from hindrax_drivers.recording.recorder_node import RecorderNode

    if args.duration < 0:
        print("hindrax bag record: --duration must be >= 0", file=sys.stderr)
        return 1
    overrides = [Parameter("autostart", value=True), Parameter("all_topics", value=bool(args.all_topics)),
                 Parameter("topic_regex", value=args.regex), Parameter("output_dir", value=args.out)]
    if args.topics:
        overrides.append(Parameter("topics", value=list(args.topics)))
    if args.config:
        overrides.append(Parameter("config_file", value=args.config))
    rclpy.init(args=[])
    node = None
    executor = SingleThreadedExecutor()
    status = 0
    try:
        try:
            node = RecorderNode(parameter_overrides=overrides)
        except (ConfigError, ValueError, OSError, RuntimeError) as exc:
            print(f"hindrax bag record: {str(exc).splitlines()[0]}", file=sys.stderr)
            return 1
        executor.add_node(node)
        deadline = time.monotonic() + args.duration if args.duration > 0 else None
        while rclpy.ok() and (deadline is None or time.monotonic() < deadline):
            executor.spin_once(timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            try:
                meta = node.stop_recording()
            except Exception as exc:  # noqa: BLE001 - report and point at recovery
                print(f"hindrax bag record: bag {node.bag_path} not finished: {exc}; run `hindrax bag recover "
                      f"{node.bag_path}`", file=sys.stderr)
                status = 1
            else:
                if meta is not None:
                    print(f"{node.bag_path}: {meta.message_count} messages on {len(meta.topics)} topics")
            executor.remove_node(node)
            node.destroy_node()
        executor.shutdown()
        rclpy.try_shutdown()
    return status
