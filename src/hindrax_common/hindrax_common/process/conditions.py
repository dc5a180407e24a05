"""Waiting on a condition with a wall-clock deadline, and an isolated rclpy context: for production code that
drives a graph step by step (``hindrax run``'s campaign, :meth:`hindrax_sim.graph.bringup.Graph.start_and_arm`) as well
as for the tests and benchmarks (:mod:`hindrax_common.testing` re-exports these).

A wait polls a condition (e.g. one executor spin per check), never sleeps a fixed time the caller relies on."""
from __future__ import annotations

import contextlib
import gc
import threading
import time
from typing import Any, Callable, Iterator

import rclpy
from rclpy.context import Context
from rclpy.node import Node

from .dds_transport import loopback_transport

__all__ = ["ConditionTimeout", "destroy_nodes_of", "ros_context", "wait_until"]


class ConditionTimeout(AssertionError):
    """A waited-for condition did not become true before its deadline."""


def wait_until(predicate: Callable[[], Any], timeout_s: float = 10.0, poll: Callable[[], None] | None = None,
               message: str = "condition") -> Any:
    """Call ``poll`` (e.g. one executor spin) until ``predicate()`` is truthy; return its value.

    poll: called between checks; default waits 5 ms on a threading.Event (a bounded poll interval, not a fixed delay the
    caller relies on). Raises :class:`ConditionTimeout` after ``timeout_s`` seconds (wall clock, ``time.monotonic``)."""
    ev = threading.Event()
    deadline = time.monotonic() + timeout_s
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            raise ConditionTimeout(f"{message} not met within {timeout_s:g} s")
        if poll is not None:
            poll()
        else:
            ev.wait(0.005)


@contextlib.contextmanager
def ros_context(domain_id: int | None = None) -> Iterator[Any]:
    """An initialised, isolated rclpy Context (shut down on exit). Domain from ROS_DOMAIN_ID by default; discovery
    kept on loopback over the vehicle's loopback UDP transport (:func:`~hindrax_common.process.dds_transport.
    loopback_transport`) unless the environment already asks for another discovery range.

    On exit every node still alive in the context is destroyed before the shutdown (:func:`destroy_nodes_of`).
    Shutting a context down does not destroy its nodes, and a node that an exception's traceback still references
    (pytest keeps the last failure's frames) keeps its DDS participant and publishers in the graph: the next user of
    the domain would count its ``supervisor/heartbeat`` or ``thrust_allocation`` as a second, live publisher and be
    refused (docs/architecture.md §8)."""
    loopback_transport()
    ctx = Context()
    rclpy.init(context=ctx, domain_id=domain_id)
    try:
        yield ctx
    finally:
        destroy_nodes_of(ctx)
        with contextlib.suppress(Exception):
            rclpy.shutdown(context=ctx)


def destroy_nodes_of(ctx: Context) -> int:
    """Destroy every rclpy node that still refers to ``ctx``; return how many were found (destroyed or not).

    The nodes are found among the objects that refer to the context (:func:`gc.get_referrers`, a few ms); a node
    destroyed already is destroyed again harmlessly. Errors while destroying are suppressed: this runs on the way
    out of :func:`ros_context`, often after a failure."""
    nodes = [obj for obj in gc.get_referrers(ctx) if isinstance(obj, Node) and obj.context is ctx]
    for node in nodes:
        with contextlib.suppress(Exception):
            node.destroy_node()
    return len(nodes)
