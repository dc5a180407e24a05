"""VehicleNode: no default QoS event handlers (the event callbacks a node gives are kept); without
parameter services no type-description service either."""
from __future__ import annotations

from rclpy.event_handler import EventHandler, SubscriptionEventCallbacks
from std_msgs.msg import String

from hindrax_common.testing import ros_context
from hindrax_common.node_support.vehicle_node import VehicleNode

PARAMETER_SERVICES = {"describe_parameters", "get_parameter_types", "get_parameters",
                      "list_parameters", "set_parameters", "set_parameters_atomically"}


def test_a_vehicle_node_has_no_default_event_handlers_but_keeps_given_ones():
    with ros_context() as ctx:
        node = VehicleNode("plain", context=ctx)
        try:
            # rclpy's own /parameter_events publisher carries no event handler either
            assert not any(isinstance(w, EventHandler) for w in node.waitables)
            node.create_publisher(String, "out", 10)
            node.create_subscription(String, "in", lambda _m: None, 10)
            assert not any(isinstance(w, EventHandler) for w in node.waitables)
            seen: list = []
            given = SubscriptionEventCallbacks(liveliness=seen.append)
            node.create_subscription(String, "beat", lambda _m: None, 10, event_callbacks=given)
            handlers = [w for w in node.waitables if isinstance(w, EventHandler)]
            assert seen.append in [h.callback for h in handlers]
            # parameter services as rclpy's (ros2 param)
            assert {s.srv_name.rsplit("/", 1)[-1] for s in node.services} == PARAMETER_SERVICES | {
                "get_type_description"}
        finally:
            node.destroy_node()


def test_without_parameter_services_a_vehicle_node_serves_nothing():
    with ros_context() as ctx:
        node = VehicleNode("closed", context=ctx, start_parameter_services=False)
        try:
            assert list(node.services) == []
            # parameters still work in-process
            assert node.get_parameter("start_type_description_service").value is False
        finally:
            node.destroy_node()


def test_rclpy_built_in_parameters_are_set_at_start_only():
    """Issue 71.5: ``use_sim_time`` set at run time froze the guard's and the ESC's timers while armed."""
    from rclpy.parameter import Parameter

    with ros_context() as ctx:
        for start in (False, True):
            node = VehicleNode("plain", context=ctx, parameter_overrides=[Parameter("use_sim_time", value=start)])
            try:
                assert node.get_parameter("use_sim_time").value is start  # the launch's value holds
                (result,) = node.set_parameters([Parameter("use_sim_time", value=not start)])
                assert not result.successful and "read-only" in result.reason, result.reason
                assert node.get_parameter("use_sim_time").value is start
                assert all(node.describe_parameter(n).read_only for n in node._parameters)
            finally:
                node.destroy_node()
