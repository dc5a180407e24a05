"""Helpers for tests and benchmarks: waiting on conditions, isolated rclpy contexts (both from
:mod:`hindrax_drivers.conditions`, which production code uses), child processes, configuration parameters.

Tests wait on conditions with a deadline, never on fixed sleeps (README, "Tests"). Every helper here
keeps ROS 2 traffic on loopback (ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST) and in the ROS_DOMAIN_ID the
test session reserved (conftest.py).
"""
from __future__ import annotations

import os
import sys

from .conditions import ConditionTimeout, ros_context, wait_until  # production helpers, re-exported for tests

__all__ = ["ConditionTimeout", "SafetyHeartbeats", "child_env", "config_parameters", "python_executable", "ros_context",
           "wait_until"]


def child_env(**extra: str) -> dict[str, str]:
    """Environment for a child Python process of this venv: loopback discovery, same domain, extras."""
    env = dict(os.environ)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env.setdefault("PYTHONUNBUFFERED", "1")
    env.update(extra)
    return env


def python_executable() -> str:
    """The interpreter to start child processes with (this venv's python)."""
    return sys.executable


def config_parameters(overrides: dict | None = None, path: str | None = None) -> list:
    """The vehicle configuration (default file, with dotted-key ``overrides``) as rclpy Parameters, for
    ``Node(..., parameter_overrides=config_parameters({...}))``; validated like a params file."""
    from rclpy.parameter import Parameter

    from .config import default_config_path, load_config

    cfg = load_config(path or default_config_path(), overrides)
    return [Parameter(k, value=v) for k, v in cfg.to_ros_parameters().items()]


class SafetyHeartbeats:
    """Stand-in for the supervisor's and the output guard's heartbeats (docs/architecture.md §8), for tests and
    benchmarks that arm an ESC node without running those two nodes.

    Publishes OK ``supervisor/heartbeat`` and ``guard/heartbeat`` at 20 Hz from a timer on ``node`` (steady clock).
    Set :attr:`supervisor` / :attr:`guard` to ``None`` (silent), ``""`` (OK) or a reason (ERROR) to emulate a dead,
    healthy or tripped peer.
    """

    def __init__(self, node, supervisor: str | None = "", guard: str | None = "", rate_hz: float = 20.0) -> None:
        from diagnostic_msgs.msg import DiagnosticStatus
        from rclpy.clock import Clock, ClockType

        from .liveness import HEARTBEAT_NAMES

        self._status = DiagnosticStatus
        self.supervisor, self.guard = supervisor, guard
        self._pubs = {k: node.create_publisher(DiagnosticStatus, topic, 10) for k, topic in HEARTBEAT_NAMES.items()}
        node.create_timer(1.0 / rate_hz, self.publish, clock=Clock(clock_type=ClockType.STEADY_TIME))

    def publish(self) -> None:
        """Publish both heartbeats now (as configured)."""
        for name, state in (("supervisor", self.supervisor), ("guard", self.guard)):
            if state is None:
                continue
            level = self._status.OK if state == "" else self._status.ERROR
            self._pubs[name].publish(self._status(level=level, name=name, message=state or "ok"))
