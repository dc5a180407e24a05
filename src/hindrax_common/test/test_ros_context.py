"""ros_context leaves nothing in the graph: a node that a failure's traceback still holds is destroyed on exit."""
from __future__ import annotations

import rclpy
from rclpy.executors import SingleThreadedExecutor
from std_msgs.msg import Empty

from hindrax_common.process.conditions import destroy_nodes_of
from hindrax_common.testing import ros_context, wait_until

TOPIC = "ros_context_test/held"


def publishers_named(node, name: str) -> int:
    return sum(1 for i in node.get_publishers_info_by_topic(f"/{TOPIC}") if i.node_name == name)


def test_a_node_still_referenced_after_the_context_leaves_no_publisher_behind():
    """Without the destroy on exit the held node keeps its participant: the observer sees its publisher for as long
    as the reference lives (the way a failed test's frames held a stand-in 'thrust_allocation' and made the ESC of
    every later test in the worker refuse a second commander)."""
    held = []
    try:
        with ros_context() as ctx:
            node = rclpy.create_node("held_publisher", context=ctx)
            node.create_publisher(Empty, TOPIC, 10)
            executor = SingleThreadedExecutor(context=ctx)
            executor.add_node(node)
            executor.spin_once(timeout_sec=0.0)
            raise RuntimeError("a failing test")
    except RuntimeError as e:
        held.append(e)  # what pytest does: the traceback keeps the frame, its node and its executor
    with ros_context() as ctx2:
        observer = rclpy.create_node("observer", context=ctx2)
        other = rclpy.create_node("control_publisher", context=ctx2)
        other.create_publisher(Empty, TOPIC, 10)
        # the observer has discovered its own context's publisher, so discovery of the topic has run
        wait_until(lambda: publishers_named(observer, "control_publisher") == 1, 10, message="own publisher seen")
        assert publishers_named(observer, "held_publisher") == 0
    assert held[0].__traceback__ is not None  # the frames are still referenced; only the DDS entities are gone


def test_destroy_nodes_of_counts_the_nodes_of_that_context_only():
    with ros_context() as a, ros_context() as b:
        nodes_a = [rclpy.create_node(f"a{i}", context=a) for i in range(2)]
        node_b = rclpy.create_node("b0", context=b)
        assert destroy_nodes_of(a) == 2
        assert node_b.get_node_names()  # b's node still works
        assert len(nodes_a) == 2
