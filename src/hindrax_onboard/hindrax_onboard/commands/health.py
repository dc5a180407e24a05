"""``hindrax health [--launch PKG/FILE] [NAME:=VALUE ...] [--timeout S] [--strict] [--quiet]``: ready to dive?

Listens to the running vehicle for up to ``--timeout`` seconds (default 6: two periods of the 1 Hz statuses plus
discovery) and exits 0 when it is ready, 1 with what is missing or failing otherwise (one line each,
:mod:`hindrax_bringup.layout.health`). What must be there comes from the launch file the vehicle runs, read as ``ros2
launch`` reads it (:mod:`hindrax_bringup.layout.launch_xml`; default ``hindrax_bringup/vehicle.launch.xml``, with the
launch arguments given as ``NAME:=VALUE``, e.g. ``record:=true`` to require the recorder): every node in the graph,
each node's ``/diagnostics`` status OK, ``supervisor/status`` OK, and no second ESC or supervisor on the domain
(a second vehicle). It returns as soon as everything is seen OK.
When no node of the vehicle is seen at all, one line says so and names the ROS domain and discovery it looked on.

The operator's check before a dive, and the Docker image's HEALTHCHECK (``--quiet``: the verdict line only)."""
from __future__ import annotations

import argparse
import time

from .common import CommandError

__all__ = ["add_arguments", "run", "collect"]

DEFAULT_LAUNCH = "hindrax_bringup/vehicle.launch.xml"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the command's options and arguments to ``parser``."""
    parser.add_argument("--launch", default=DEFAULT_LAUNCH, metavar="PKG/FILE",
                        help=f"the launch file the vehicle runs, as PACKAGE/FILE (default {DEFAULT_LAUNCH}) or a path")
    parser.add_argument("launch_arguments", nargs="*", metavar="NAME:=VALUE",
                        help="its launch arguments, as given to ros2 launch (e.g. record:=true)")
    parser.add_argument("--timeout", type=float, default=6.0,
                        help="wall time to listen before the verdict, s (default 6; returns earlier when ready)")
    parser.add_argument("--strict", action="store_true", help="a WARN status is a problem too")
    parser.add_argument("--quiet", action="store_true", help="print the verdict line only")


def _launch_path(spec: str):
    from pathlib import Path

    from hindrax_bringup.layout.launch_xml import ament_share

    if Path(spec).is_file():
        return Path(spec)
    package, _, name = spec.partition("/")
    if not name:
        raise CommandError(f"--launch {spec}: expected PACKAGE/FILE.launch.xml or the path of a launch file")
    return ament_share(package) / "launch" / name


def collect(timeout_s: float, done=None):
    """Listen to the graph for up to ``timeout_s`` s (returning early once ``done(nodes, statuses, supervisor)``):
    returns (node names, {status name: Seen}, Seen of supervisor/status or None, the graph's
    :class:`~hindrax_common.node_support.vehicle_graph.GraphView` at the end: node names with duplicates, heartbeat
    publishers)."""
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
    from rclpy.executors import SingleThreadedExecutor

    from hindrax_common.process.conditions import ros_context
    from hindrax_bringup.layout.health import SUPERVISOR_STATUS_TOPIC, Seen
    from hindrax_common.node_support.vehicle_graph import graph_view

    def seen(st: DiagnosticStatus) -> Seen:
        level = st.level[0] if isinstance(st.level, (bytes, bytearray)) else int(st.level)
        return Seen(int(level), st.message)

    statuses: dict = {}
    supervisor: list = []
    with ros_context() as ctx:
        node = rclpy.create_node("hindrax_health", context=ctx)
        node.create_subscription(DiagnosticArray, "/diagnostics",
                                 lambda msg: statuses.update({s.name: seen(s) for s in msg.status}), 50)
        node.create_subscription(DiagnosticStatus, SUPERVISOR_STATUS_TOPIC,
                                 lambda msg: supervisor.append(seen(msg)), 10)
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(node)
        deadline = time.monotonic() + timeout_s
        names: set = set()
        try:
            while time.monotonic() < deadline:
                ex.spin_once(timeout_sec=0.1)
                names = {n for n, _ns in node.get_node_names_and_namespaces()} - {node.get_name()}
                if done is not None and done(names, statuses, supervisor[-1] if supervisor else None):
                    break
            view = graph_view(node)
        finally:
            ex.shutdown()
            node.destroy_node()
    return names, statuses, (supervisor[-1] if supervisor else None), view


def second_vehicle(expected_nodes, view) -> str:
    """The problem line when ``view`` (:func:`collect`) shows an ESC or supervisor beyond the one each of the
    launch's ``expected_nodes`` (node names, no namespace) accounts for, e.g. ``"a second vehicle on this domain:
    ESC /esc, supervisor /supervisor: ..."``
    (:func:`hindrax_common.node_support.vehicle_graph.foreign_vehicle_processes`);
    "" when there is none."""
    from hindrax_common.node_support.vehicle_graph import (HEARTBEAT_TOPICS, ROLE_NODES, GraphView,
                                                            foreign_vehicle_processes)

    own = GraphView(tuple("/" + n for n in expected_nodes if n in ROLE_NODES),
                    {"/" + t: ("/" + t.split("/")[0],) for t in HEARTBEAT_TOPICS if t.split("/")[0] in expected_nodes})
    found = foreign_vehicle_processes(view, own)
    return (f"a second vehicle on this domain: {', '.join(found)}: it commands the same thrusters and fills the "
            "same bags; stop it (one vehicle per domain)") if found else ""


def _where() -> str:
    """The domain and discovery this process looked on, for the one-line verdict of an empty graph."""
    import os

    from hindrax_common.process.dds_transport import PROFILE_ENV

    scope = os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "") or "SYSTEM_DEFAULT"
    if os.environ.get(PROFILE_ENV):
        scope = "this machine only, UDP on 127.0.0.1"
    return f"ROS_DOMAIN_ID={os.environ.get('ROS_DOMAIN_ID', '') or 0} ({scope})"


def run(args: argparse.Namespace) -> int:
    """Run the command with the parsed ``args``; returns the process exit code."""
    from hindrax_bringup.layout.health import assess, expectation
    from hindrax_bringup.layout.launch_xml import LaunchFileError, read_launch

    given = {}
    for item in args.launch_arguments:
        name, sep, value = item.partition(":=")
        if not sep or not name:
            raise CommandError(f"launch argument {item!r}: expected NAME:=VALUE")
        given[name] = value
    try:
        processes = read_launch(_launch_path(args.launch), given)
    except LaunchFileError as exc:
        raise CommandError(f"hindrax health: {exc}") from exc
    expect = expectation(n for p in processes for n in p.node_names)

    def ready(nodes, statuses, supervisor) -> bool:
        return assess(expect, nodes, statuses, supervisor, args.strict).ready

    nodes, statuses, supervisor, view = collect(args.timeout, ready)
    if not ({n.rsplit("/", 1)[-1] for n in nodes} & set(expect.nodes)) and not statuses and supervisor is None:
        print(f"NOT READY: no node of {args.launch} seen on {_where()} within {args.timeout:g} s: is the vehicle "
              "running, on this domain? (from the topside: docs/deployment.md §6)")
        return 1
    report = assess(expect, nodes, statuses, supervisor, args.strict)
    second = second_vehicle(expect.nodes, view)
    if second:
        report.problems.append(second)
        report.ready = False
    for line in ([report.summary()] if args.quiet else report.lines()):
        print(line)
    return 0 if report.ready else 1
