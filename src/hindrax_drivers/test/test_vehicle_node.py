"""VehicleNode: no parameter or type-description services, no default QoS event handlers; the
event callbacks a node gives are kept."""
from __future__ import annotations

from rclpy.event_handler import EventHandler, SubscriptionEventCallbacks
from std_msgs.msg import String

from hindrax_drivers.testing import ros_context
from hindrax_drivers.vehicle_node import VehicleNode


def test_a_vehicle_node_has_no_services_nor_default_event_handlers_but_keeps_given_ones():
    with ros_context() as ctx:
        plain = VehicleNode("plain", context=ctx)
        with_services = VehicleNode("with_services", context=ctx, start_parameter_services=True)
        try:
            assert list(plain.services) == []
            # a node that asks for its parameter services gets them (not the type-description one)
            assert {s.srv_name.rsplit("/", 1)[-1] for s in with_services.services} == {
                "describe_parameters", "get_parameter_types", "get_parameters", "list_parameters",
                "set_parameters", "set_parameters_atomically"}
            # rclpy's own /parameter_events publisher carries no event handler either
            assert not any(isinstance(w, EventHandler) for w in plain.waitables)
            plain.create_publisher(String, "out", 10)
            plain.create_subscription(String, "in", lambda _m: None, 10)
            assert not any(isinstance(w, EventHandler) for w in plain.waitables)
            seen = []
            given = SubscriptionEventCallbacks(liveliness=seen.append)
            plain.create_subscription(String, "beat", lambda _m: None, 10, event_callbacks=given)
            handlers = [w for w in plain.waitables if isinstance(w, EventHandler)]
            assert seen.append in [h.callback for h in handlers]
            # parameters still work in-process
            assert plain.get_parameter("start_type_description_service").value is False
        finally:
            plain.destroy_node()
            with_services.destroy_node()
