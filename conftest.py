"""Test-session set-up shared by every test directory.

- Discovery and data stay on loopback, over the vehicle's transport: UDPv4 bound to 127.0.0.1, no shared memory
  (:mod:`hindrax_drivers.dds_transport`; docs/architecture.md §11.4).
- Each pytest-xdist worker (and a plain run) reserves its own ROS domain ID through
  ``domain_coordinator`` (a port lock, so concurrent test runs on one machine never share a domain) and
  exports it as ROS_DOMAIN_ID before any test imports rclpy; subprocesses inherit it.
"""
from __future__ import annotations

import os

import pytest

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
from hindrax_drivers.dds_transport import loopback_transport  # noqa: E402 - after the range is set

loopback_transport()
os.environ.setdefault("MPLBACKEND", "Agg")

_domain_ctx = None


def pytest_configure(config: pytest.Config) -> None:
    global _domain_ctx
    if hasattr(config, "workerinput") or os.environ.get("PYTEST_XDIST_WORKER") is None:
        # In a worker (or a run without xdist): reserve a domain for this process.
        from domain_coordinator import domain_id

        worker = os.environ.get("PYTEST_XDIST_WORKER", "gw0")
        start = int(worker[2:]) * 10 if worker.startswith("gw") and worker[2:].isdigit() else 0

        class _Selector:
            def __init__(self) -> None:
                self.value = start + (os.getpid() % 7)

            def __call__(self) -> int:
                self.value += 1
                return (self.value % 100) + 1

        _domain_ctx = domain_id(_Selector())
        os.environ["ROS_DOMAIN_ID"] = str(_domain_ctx.__enter__())


def pytest_unconfigure(config: pytest.Config) -> None:
    global _domain_ctx
    if _domain_ctx is not None:
        try:
            _domain_ctx.__exit__(None, None, None)
        except Exception:  # noqa: BLE001 - releasing the port lock must not fail the run
            pass
        _domain_ctx = None
