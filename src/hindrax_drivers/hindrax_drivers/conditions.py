"""Waiting on a condition with a wall-clock deadline, and an isolated rclpy context: for production code that
drives a graph step by step (``hindrax run``'s campaign, :meth:`hindrax_ident.bringup.Graph.start_and_arm`) as well
as for the tests and benchmarks (:mod:`hindrax_drivers.testing` re-exports these).

A wait polls a condition (e.g. one executor spin per check), never sleeps a fixed time the caller relies on.
rclpy is imported when a context is created, not when this module is.
"""
from __future__ import annotations

import contextlib
import threading
import time
from typing import Any, Callable, Iterator

import rclpy
from rclpy.context import Context

from .dds_transport import loopback_transport

__all__ = ["ConditionTimeout", "ros_context", "wait_until"]


class ConditionTimeout(AssertionError):
    """A waited-for condition did not become true before its deadline."""


def wait_until(predicate: Callable[[], Any], timeout_s: float = 10.0, poll: Callable[[], None] | None = None,
               message: str = "condition") -> Any:
    """Call ``poll`` (e.g. one executor spin) until ``predicate()`` is truthy; return its value.

    poll: called between checks; default waits 5 ms on a threading.Event (a bounded poll interval, not a
    fixed delay the caller relies on). Raises :class:`ConditionTimeout` after ``timeout_s`` seconds (wall clock,
    ``time.monotonic``).
    """
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
    kept on loopback over the vehicle's loopback UDP transport (:func:`~hindrax_drivers.dds_transport.
    loopback_transport`) unless the environment already asks for another discovery range."""
    loopback_transport()
    ctx = Context()
    kwargs = {}
    if domain_id is not None:
        kwargs["domain_id"] = domain_id
    rclpy.init(context=ctx, **kwargs)
    try:
        yield ctx
    finally:
        with contextlib.suppress(Exception):
            rclpy.shutdown(context=ctx)
