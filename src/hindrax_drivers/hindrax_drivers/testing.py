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

__all__ = ["ConditionTimeout", "child_env", "config_parameters", "python_executable", "ros_context", "wait_until"]


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
