"""The base of every vehicle node: an rclpy ``Node`` without the entities nothing uses.

rclpy gives every publisher and subscription two QoS event handlers (incompatible QoS, incompatible type) that only log,
and every node six parameter services and a type-description service. Each is one more entity in every wait of the
node's executor, visited in Python at every spin: in the one-process graph of the virtual pool (13 nodes) they were two
thirds of the wait set (213 of 325). :class:`VehicleNode`'s publishers and subscriptions get no default event handler;
event callbacks a node passes itself (e.g. the heartbeat subscriptions' liveliness and matched events,
:mod:`hindrax_common.node_support.liveness`) are kept as given. Its parameter services stay (``ros2 param`` reads and
sets the nodes' parameters) unless the node is built with ``start_parameter_services=False``, which then also leaves out
the type-description service: the one-process graph of ``hindrax run`` does so (nothing outside its process talks to
it).

rclpy's own parameters (``use_sim_time``; ``start_type_description_service`` is read-only already) are made
read-only once the node is built: ``use_sim_time`` is set at start only (the simulation's launch and
``hindrax run``); set at run time on the guard or the ESC it froze their timers while armed (issue 71.5). Every
parameter a vehicle node can change at run time, and why each is safe: docs/threat_model.md."""
from __future__ import annotations

import copy
from typing import Any

from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.parameter import Parameter

__all__ = ["VehicleNode"]

#: event callbacks of a publisher / subscription that passes none: no handler at all
NO_PUB_EVENTS = PublisherEventCallbacks(use_default_callbacks=False)
NO_SUB_EVENTS = SubscriptionEventCallbacks(use_default_callbacks=False)
#: rclpy's parameter that starts a node's ``~/get_type_description`` service
_TYPE_SERVICE = "start_type_description_service"


class VehicleNode(Node):
    """``rclpy.node.Node`` (same arguments) without default QoS event handlers, rclpy's built-in parameters read-only;
    with ``start_parameter_services=False`` without the type-description service either (module docstring)."""

    def __init__(self, node_name: str, **kwargs: Any) -> None:
        overrides = list(kwargs.get("parameter_overrides") or [])
        if kwargs.get("start_parameter_services") is False and not any(p.name == _TYPE_SERVICE for p in overrides):
            kwargs["parameter_overrides"] = overrides + [Parameter(_TYPE_SERVICE, value=False)]
        super().__init__(node_name, **kwargs)
        for name in list(self._parameters):  # rclpy's built-ins, the only ones declared so far
            descriptor = copy.copy(self.describe_parameter(name))  # rclpy hands out its own object
            if descriptor.read_only:
                continue
            descriptor.read_only = True
            descriptor.description = "rclpy built-in: set at start only (read-only, docs/threat_model.md)"
            self.set_descriptor(name, descriptor)

    def create_publisher(self, *args: Any, event_callbacks: PublisherEventCallbacks | None = None,
                         **kwargs: Any) -> Any:
        """``Node.create_publisher``; without ``event_callbacks``, no QoS event handler."""
        return super().create_publisher(*args, event_callbacks=event_callbacks or NO_PUB_EVENTS, **kwargs)

    def create_subscription(self, *args: Any,
                            event_callbacks: SubscriptionEventCallbacks | None = None,
                            **kwargs: Any) -> Any:
        """``Node.create_subscription``; without ``event_callbacks``, no QoS event handler."""
        return super().create_subscription(*args, event_callbacks=event_callbacks or NO_SUB_EVENTS, **kwargs)
