"""hindrax_onboard's composed processes: the identification node and the controller in one process, with or without the
recorder.

``ident_control_node`` (``pool_test.launch.xml``): both nodes keep their names (``identification``, ``controller``),
read the same vehicle file and are spun by one executor (:func:`hindrax_bringup.layout.composition.run_group`; the node
list is :data:`hindrax_bringup.layout.composition.IDENT_GROUPS`, this module maps it to classes). ``ident_record_node``
(recording on, the default): the same two and the recorder (the other nodes ignore keys they do not declare).

Why composed: docs/architecture.md §10.1. None of them has a safety role (§8): a failure of one ends all, and the
allocation's wrench timeout brings the thrusters to neutral as for any lost wrench source. The recorder's bag writer
keeps its own thread, and its keep-last depth (``queue_depth``, 1000) holds what arrives while an identification
callback runs."""
from __future__ import annotations

from typing import Sequence

from hindrax_bringup.layout.composition import IDENT_GROUPS, NODE_CLASSES as DRIVER_CLASSES, run_group

__all__ = ["NODE_CLASSES", "ident_control_main", "ident_record_main"]

#: node -> "module:class" of the nodes this package composes
NODE_CLASSES: dict[str, str] = {
    "identification": "hindrax_onboard.identification.online.node:IdentificationNode",
    "controller": "hindrax_onboard.control.node:ControllerNode",
    "recorder": DRIVER_CLASSES["recorder"],
}


def ident_control_main(args: Sequence[str] | None = None) -> int:
    """Console script ``ident_control_node``: the identification node and the controller in one process (module
    docstring). Returns the exit status (1 on an invalid configuration, one line on stderr)."""
    return run_group(IDENT_GROUPS["ident_control_node"], args, NODE_CLASSES)


def ident_record_main(args: Sequence[str] | None = None) -> int:
    """Console script ``ident_record_node``: the identification node, the controller and the recorder in one process
    (module docstring). Returns the exit status (1 on an invalid configuration, one line on stderr)."""
    return run_group(IDENT_GROUPS["ident_record_node"], args, NODE_CLASSES)
