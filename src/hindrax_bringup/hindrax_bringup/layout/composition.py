"""Composed processes: several node classes of this package in one process, spun by one executor.

rclpy has no ``rclcpp_components`` containers. A *group* is a console script that builds a fixed
list of node classes and spins them (:func:`hindrax_common.node_support.node_common.run_nodes`). Nodes keep
their own names and read the same vehicle file, so a group runs from a launch file like the nodes it
composes (``<node pkg="hindrax_bringup" exec="sensors_node">`` without ``name``, which would rename
every node of the process). Every node keeps its own executable too (``ms5837_node`` ...).

Why groups (docs/architecture.md §10): nodes in one process share one participant, one set of DDS
threads and one executor thread, and a message between them stays inside the process. The ESC output
and the safety supervisor run in no process with anything heavy (docs/architecture.md §8).

Groups (:data:`GROUPS`):

``sensors_node``
    the four sensor drivers and ``static_tf``: DVL-75 and Ping1D (each with its serial reader
    thread), MS5837 and ICM-20948 on the shared I2C bus (the kernel serialises the transfers). No
    safety role: one driver's failure takes the others with it for the 2 s of the respawn (a
    campaign needs all four sensors, so the supervisor stops it either way).
``actuation_node``
    thrust allocation and ESC output: the allocation's commands reach the ESC's subscription
    callback inside the process, as from any other publisher. The ESC node is built last and so
    closed first on exit: it writes neutral before anything else shuts down.
``ident_control_node`` (hindrax_onboard, :data:`IDENT_GROUPS`)
    the identification node and the controller, both non-safety (:mod:`hindrax_onboard.composition`
    builds them; this package names them only).
``ident_record_node`` (hindrax_onboard, :data:`IDENT_GROUPS`)
    the same two and the recorder: the pool test's layout with recording on.

``python -m hindrax_bringup.layout.composition NODE[,NODE...] [--ros-args ...]`` composes any nodes of
:data:`NODE_CLASSES` (for measurements; the launch files use the groups)."""
from __future__ import annotations

import sys
from typing import Any, Callable, Mapping, Sequence

from hindrax_common.base.devices import DEVICES, load

__all__ = ["GROUPS", "IDENT_GROUPS", "NODE_CLASSES", "node_factories", "node_names", "run_group"]

#: node -> "module:class" of every node class that composes (the class is imported only when used)
NODE_CLASSES: dict[str, str] = {
    **{d.node: "hindrax_drivers" + d.node_class for d in DEVICES},
    "thrust_allocation": "hindrax_bringup.allocation.node:ThrustAllocationNode",
    "static_tf": "hindrax_drivers.tf.node:StaticTfNode",
    "supervisor": "hindrax_bringup.supervisor.node:SupervisorNode",
    "recorder": "hindrax_bringup.recording.recorder_node:RecorderNode",
}

#: console script -> the nodes it composes, in construction order (module docstring)
GROUPS: dict[str, tuple[str, ...]] = {
    "sensors_node": tuple(d.node for d in DEVICES if not d.output) + ("static_tf",),
    "actuation_node": ("thrust_allocation", "esc"),
}

#: hindrax_onboard's composed processes: console script -> its nodes (the classes: hindrax_onboard.composition; this
#: package imports nothing of hindrax_onboard, it only names the nodes for the launch-file readers)
IDENT_GROUPS: dict[str, tuple[str, ...]] = {
    "ident_control_node": ("identification", "controller"),
    "ident_record_node": ("identification", "controller", "recorder"),
}


def node_names(package: str, executable: str, name: str | None = None) -> tuple[str, ...]:
    """The ROS node names a launch file's ``<node pkg exec name>`` process runs: a group's nodes (their own names),
    else ``name``, else the executable. Used where a process list from a launch file is compared with the nodes
    in the graph (``hindrax health``, the pool-day test)."""
    groups = {"hindrax_bringup": GROUPS, "hindrax_onboard": IDENT_GROUPS}.get(package, {})
    if executable in groups:
        return groups[executable]
    return (name or executable,)


def node_factories(names: Sequence[str], classes: Mapping[str, str] = NODE_CLASSES) -> list[Callable[[], Any]]:
    """The node classes of ``names`` (keys of ``classes``, node -> "module:class", default :data:`NODE_CLASSES`),
    imported. Raises ValueError naming an unknown node and the known ones."""
    out = []
    for name in names:
        if name not in classes:
            raise ValueError(f"unknown node {name!r}: choose from {', '.join(classes)}")
        out.append(load(classes[name]))
    return out


def run_group(names: Sequence[str], args: Sequence[str] | None = None,
              classes: Mapping[str, str] = NODE_CLASSES) -> int:
    """Run the nodes ``names`` (keys of ``classes``, :func:`node_factories`) in this process until SIGINT/SIGTERM
    (:func:`~hindrax_common.node_support.node_common.run_nodes`). Returns the exit status (1 on an invalid
    configuration, one line on stderr)."""
    return _run(node_factories(names, classes), args)


def _run(factories: Sequence[Callable[[], Any]], args: Sequence[str] | None) -> int:
    # imported here: node_names (launch_xml, ``hindrax health``) reads GROUPS without loading the ROS messages
    from hindrax_common.node_support.node_common import run_nodes

    return run_nodes(factories, args)


def sensors_main(args: Sequence[str] | None = None) -> int:
    """Console script ``sensors_node``: the four sensor drivers and the static transforms in one process (module
    docstring)."""
    return run_group(GROUPS["sensors_node"], args)


def actuation_main(args: Sequence[str] | None = None) -> int:
    """Console script ``actuation_node``: thrust allocation and ESC output in one process (module docstring)."""
    return run_group(GROUPS["actuation_node"], args)


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m hindrax_bringup.layout.composition NODE[,NODE...] [--ros-args ...]``; exit 2 on a bad node list."""
    argv = list(sys.argv if argv is None else argv)
    if len(argv) < 2 or argv[1].startswith("-"):
        print(f"usage: python -m hindrax_bringup.layout.composition NODE[,NODE...] [--ros-args ...]; nodes: "
              f"{', '.join(NODE_CLASSES)}", file=sys.stderr)
        return 2
    names = [n for n in argv[1].split(",") if n]
    try:
        factories = node_factories(names)
    except ValueError as exc:
        print(f"composition: {exc}", file=sys.stderr)
        return 2
    return _run(factories, [argv[0]] + argv[2:])


if __name__ == "__main__":
    sys.exit(main())
