"""Helpers for tests and benchmarks: waiting on conditions, isolated rclpy contexts (both from
:mod:`hindrax_common.process.conditions`, which production code uses), child processes, configuration parameters.

Tests wait on conditions with a deadline, never on fixed sleeps (README, "Tests"). Every helper here keeps ROS 2 traffic
on loopback (ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST) and in the ROS_DOMAIN_ID the test session reserved (conftest.py).
"""
from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
from typing import Iterator

import rclpy
from rclpy.clock import Clock, ClockType
from rclpy.parameter import Parameter

from hindrax_msgs.msg import ThrusterPwm

from .process.dds_transport import loopback_transport
from .process.conditions import ConditionTimeout, ros_context, wait_until  # production helpers, re-exported for tests
from .config import default_config_path, load_config
from .node_support.liveness import HEARTBEAT_NODES, HeartbeatPublisher, heartbeat_qos

__all__ = ["AllocationStandIn", "ConditionTimeout", "GraphSettled", "SafetyHeartbeats", "child_env", "child_process",
           "interrupt", "config_parameters", "python_executable", "ros_context", "wait_until"]


def child_env(**extra: str) -> dict[str, str]:
    """Environment for a child Python process of this venv: loopback discovery over the vehicle's loopback UDP
    transport (:func:`~hindrax_common.process.dds_transport.loopback_transport`), same domain, extras."""
    env = dict(os.environ)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    loopback_transport(env)
    env.setdefault("PYTHONUNBUFFERED", "1")
    env.update(extra)
    return env


def own_domain_env(**extra: str) -> dict[str, str]:
    """:func:`child_env` without ROS_DOMAIN_ID, for ``hindrax run``, which then reserves a domain no other process
    holds (``domain_coordinator``), as it does for a user. A vehicle graph started on the worker's own domain would
    meet the ESCs and supervisors of the worker's earlier tests still in the discovery caches, and be refused."""
    env = child_env(**extra)
    env.pop("ROS_DOMAIN_ID", None)
    return env


@contextlib.contextmanager
def child_process(args, **popen_kwargs) -> Iterator[subprocess.Popen]:
    """A child process (:class:`subprocess.Popen` of ``args`` with ``popen_kwargs``) that never outlives the block:
    if it still runs on exit (a failed assertion, a timeout), it is killed (SIGKILL) and reaped, so that no node of
    it stays in the test domain's graph."""
    proc = subprocess.Popen(args, **popen_kwargs)
    try:
        yield proc
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def interrupt(proc: subprocess.Popen, timeout_s: float) -> int:
    """Send ``proc`` SIGINT (a Ctrl-C) and return its exit status; raises :class:`subprocess.TimeoutExpired` when it
    has not ended within ``timeout_s`` seconds."""
    proc.send_signal(signal.SIGINT)
    return proc.wait(timeout=timeout_s)


def python_executable() -> str:
    """The interpreter to start child processes with (this venv's python)."""
    return sys.executable


def config_parameters(overrides: dict | None = None, path: str | None = None) -> list:
    """The vehicle configuration (default file, with dotted-key ``overrides``) as rclpy Parameters, for
    ``Node(..., parameter_overrides=config_parameters({...}))``; validated like a params file."""
    cfg = load_config(path or default_config_path(), overrides)
    return [Parameter(k, value=v) for k, v in cfg.to_ros_parameters().items()]


class SafetyHeartbeats:
    """Stand-in for the supervisor's and the output guard's heartbeats (docs/architecture.md §8), for tests and
    benchmarks that arm an ESC node without running those two nodes.

    Publishes OK ``supervisor/heartbeat`` and ``guard/heartbeat`` at 20 Hz from a timer on ``node`` (steady clock),
    each from a node of its own with the real publisher's name (``supervisor``, ``output_guard``:
    :data:`~hindrax_common.node_support.liveness.HEARTBEAT_NODES`, created in ``node``'s context the first time that
    heartbeat is published) and with ``boot_id``/``seq``
    (:class:`~hindrax_common.node_support.liveness.HeartbeatPublisher`), as the receivers' identity check requires. Set
    :attr:`supervisor` / :attr:`guard` to ``None`` (silent), ``""`` (OK) or a reason (ERROR) to emulate a dead, healthy
    or tripped peer. The peer nodes are destroyed with ``node`` (:meth:`destroy`, run by ``node.destroy_node()``): left
    alive, they would hold their context's participant and count as a second live publisher for the next test in the
    same process."""

    def __init__(self, node, supervisor: str | None = "", guard: str | None = "", rate_hz: float = 20.0) -> None:
        self._node = node
        self.supervisor, self.guard = supervisor, guard
        self.publishers: dict[str, HeartbeatPublisher] = {}
        self.nodes: list = []
        node.create_timer(1.0 / rate_hz, self.publish, clock=Clock(clock_type=ClockType.STEADY_TIME))
        destroy_owner = node.destroy_node

        def destroy_node() -> None:
            self.destroy()
            destroy_owner()
        node.destroy_node = destroy_node

    def destroy(self) -> None:
        """Destroy the peer nodes (silent from now on)."""
        self.supervisor = self.guard = None
        for peer in self.nodes:
            peer.destroy_node()
        self.nodes.clear()
        self.publishers.clear()

    def _publisher(self, kind: str) -> HeartbeatPublisher:
        if kind not in self.publishers:
            peer = rclpy.create_node(HEARTBEAT_NODES[kind], namespace=self._node.get_namespace(),
                                     context=self._node.context, start_parameter_services=False)
            self.nodes.append(peer)
            self.publishers[kind] = HeartbeatPublisher(peer, kind)
        return self.publishers[kind]

    def publish(self) -> None:
        """Publish both heartbeats now (as configured)."""
        for name, state in (("supervisor", self.supervisor), ("guard", self.guard)):
            if state is None:
                continue
            self._publisher(name).publish(state == "", state or "ok")


class AllocationStandIn:
    """Stand-in for the thrust allocation as the ESC's commander, for tests and benchmarks that drive an ESC node
    with pulse widths directly: a node named ``thrust_allocation`` (the only publisher the ESC accepts on
    ``thrusters/command_pulse_width``, :func:`hindrax_drivers.pca9685.core.command_source_fault`) in ``context``
    with :attr:`pub` on that topic; :meth:`destroy` when done. The node needs no executor."""

    def __init__(self, context=None) -> None:
        self.node = rclpy.create_node("thrust_allocation", context=context)
        self.pub = self.node.create_publisher(ThrusterPwm, "thrusters/command_pulse_width", heartbeat_qos())

    def destroy(self) -> None:
        """Destroy the stand-in's node."""
        self.node.destroy_node()


class GraphSettled:
    """Predicate for :func:`wait_until`: True once the ROS graph ``node`` sees (its node names) has not changed for
    ``quiet_s`` seconds (monotonic clock) and holds at least ``min_nodes`` nodes besides ``node``.

    Why: with ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` rmw_fastrtps gives every participant Fast DDS's
    shared-memory transport, and the first message a process sends to a new participant's port runs Fast DDS's port
    health check, which can sleep 333 ms (a third of the 1 s ``healthy_check_timeout_ms``) while the sending
    participant's send lock is held: every publish of that process waits (docs/architecture.md §10.1, "The publish
    stalls"), and such stalls come within seconds of the newest participant's creation. So anything
    that arms the ESC in a freshly started layout waits for this first."""

    def __init__(self, node, quiet_s: float = 5.0, min_nodes: int = 1) -> None:
        self.node, self.quiet_s, self.min_nodes = node, float(quiet_s), int(min_nodes)
        self._names: frozenset | None = None
        self._since = 0.0

    def __call__(self) -> bool:
        names = frozenset(self.node.get_node_names_and_namespaces())
        now = time.monotonic()
        if names != self._names:
            self._names, self._since = names, now
        return len(names) - 1 >= self.min_nodes and now - self._since >= self.quiet_s
