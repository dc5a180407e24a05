"""GraphSettled (hindrax_common.testing): the stack benchmark arms the ESC only once the ROS graph is quiet."""
import time

import rclpy

from hindrax_common.testing import GraphSettled, ros_context, wait_until


class FakeGraph:
    """A node whose graph the test sets: get_node_names_and_namespaces() returns ``names`` plus itself."""

    def __init__(self) -> None:
        self.names = [("probe", "/")]

    def get_node_names_and_namespaces(self):
        return list(self.names)


def test_settled_only_after_the_node_set_is_unchanged_for_the_quiet_time():
    """A node joining restarts the quiet time; too few nodes never count as settled."""
    graph = FakeGraph()
    settled = GraphSettled(graph, quiet_s=0.2, min_nodes=1)
    graph.names.append(("esc", "/"))
    t0 = time.monotonic()
    assert not settled()
    wait_until(settled, 5)
    first = time.monotonic() - t0
    assert first >= 0.2
    graph.names.append(("controller", "/"))  # a late process
    assert not settled()
    t1 = time.monotonic()
    wait_until(settled, 5)
    assert time.monotonic() - t1 >= 0.2
    lonely = FakeGraph()
    alone = GraphSettled(lonely, quiet_s=0.0, min_nodes=1)
    assert not alone()  # only the probe itself
    lonely.names.append(("esc", "/"))
    assert alone()


def test_settled_sees_a_real_node_join_the_graph():
    """With rclpy: a second node in the same context appears in the probe's graph; the predicate waits for it to be
    there for the quiet time."""
    with ros_context() as ctx:
        probe = rclpy.create_node("graph_probe", context=ctx)
        other = rclpy.create_node("graph_other", context=ctx)
        try:
            settled = GraphSettled(probe, quiet_s=0.3, min_nodes=1)
            wait_until(settled, 20)
            assert ("graph_other", "/") in probe.get_node_names_and_namespaces()
        finally:
            other.destroy_node()
            probe.destroy_node()
