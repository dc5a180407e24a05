"""Helpers for tests and benchmarks: waiting on conditions, isolated rclpy contexts, child processes.

Tests wait on conditions with a deadline, never on fixed sleeps (README, "Tests"). Every helper here
keeps ROS 2 traffic on loopback (ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST) and in the ROS_DOMAIN_ID the
test session reserved (conftest.py).
"""
from __future__ import annotations

import contextlib
import os
import sys
import time
from typing import Any, Callable, Iterator


class ConditionTimeout(AssertionError):
    """A waited-for condition did not become true before its deadline."""


def wait_until(predicate: Callable[[], Any], timeout_s: float = 10.0, poll: Callable[[], None] | None = None,
               message: str = "condition") -> Any:
    """Call ``poll`` (e.g. one executor spin) until ``predicate()`` is truthy; return its value.

    poll: called between checks; default waits 5 ms on a threading.Event (a bounded poll interval, not a
    fixed delay the test relies on). Raises :class:`ConditionTimeout` after ``timeout_s`` seconds.
    """
    import threading

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
    """An initialised, isolated rclpy Context (shut down on exit). Domain from ROS_DOMAIN_ID by default."""
    import rclpy
    from rclpy.context import Context

    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
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
