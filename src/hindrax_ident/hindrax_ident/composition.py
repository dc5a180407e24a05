"""hindrax_ident's composed processes: the identification node and the controller in one process, with or without
the recorder.

Console script ``ident_control_node`` (``pool_test.launch.xml``): both nodes keep their own names (``identification``,
``controller``) and read the same vehicle file; one executor spins them
(:func:`hindrax_drivers.composition.run_group`, the EventsExecutor like every node process). The group's node list
is :data:`hindrax_drivers.composition.IDENT_GROUPS` (the launch-file readers, ``hindrax health`` and the SROS2
policy, take the node names from there); this module maps them to their classes.

Why one process (docs/architecture.md §10.1): the two largest processes of the launch layout load mostly the same
Python modules (numpy, the vehicle model, the control law, the sensor conditioning) once (``launch_pss_*``).
Neither has a safety role (the supervisor, the output guard and the ESC's process stay alone, §8): a failure of
one ends both, and the allocation's wrench timeout brings the thrusters to neutral as for any lost wrench source.
While an identification goal runs the controller is disabled and ticks every 0.2 s, so the pair costs about what
the identification node costs alone.

Console script ``ident_record_node`` (``pool_test.launch.xml`` with recording on, its default): the same two nodes and
the recorder (``hindrax_drivers.recording.recorder_node``, its parameters given to the process: the other nodes
ignore keys they do not declare). Every sensor message both subscribe to then reaches one participant once instead
of two, and the layout has one process, participant and executor less (docs/architecture.md §10.1,
``launch_*_cpu_participant_idle``). The recorder has no safety role either; its bag writer keeps its own thread, and
its subscriptions' keep-last depth (``queue_depth``, 1000) holds what arrives while an identification callback runs.
"""
from __future__ import annotations

import sys
from typing import Sequence

from hindrax_drivers.composition import IDENT_GROUPS, NODE_CLASSES as DRIVER_CLASSES, run_group

__all__ = ["GROUPS", "NODE_CLASSES", "ident_control_main", "ident_record_main"]

#: node -> "module:class" of the nodes this package composes
NODE_CLASSES: dict[str, str] = {
    "identification": "hindrax_ident.identification.online.node:IdentificationNode",
    "controller": "hindrax_ident.control.node:ControllerNode",
    "recorder": DRIVER_CLASSES["recorder"],
}
#: console script -> its nodes, in construction order
GROUPS = IDENT_GROUPS


def ident_control_main(args: Sequence[str] | None = None) -> int:
    """Console script ``ident_control_node``: the identification node and the controller in one process (module
    docstring). Returns the exit status (1 on an invalid configuration, one line on stderr)."""
    return run_group(GROUPS["ident_control_node"], args, NODE_CLASSES)


def ident_record_main(args: Sequence[str] | None = None) -> int:
    """Console script ``ident_record_node``: the identification node, the controller and the recorder in one process
    (module docstring). Returns the exit status (1 on an invalid configuration, one line on stderr)."""
    return run_group(GROUPS["ident_record_node"], args, NODE_CLASSES)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(ident_control_main())
