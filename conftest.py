"""Test-session set-up shared by every test directory.

- Discovery and data stay on loopback, over the vehicle's transport: UDPv4 bound to 127.0.0.1, no shared memory
  (:mod:`hindrax_drivers.dds_transport`; docs/architecture.md §11.4).
- Each pytest-xdist worker (and a plain run) reserves its own ROS domain ID through
  ``domain_coordinator`` (a port lock, so concurrent test runs on one machine never share a domain) and
  exports it as ROS_DOMAIN_ID before any test imports rclpy; subprocesses inherit it.
- A test that leaves SIGINT or SIGTERM ignored in its worker fails (:func:`_stop_signals_not_left_ignored`): every
  child the worker starts later would inherit the ignored signal, and ``kill`` or Ctrl-C could not end it.
"""
from __future__ import annotations

import os
import signal

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


@pytest.fixture(autouse=True)
def _stop_signals_not_left_ignored():
    """Fail a test that leaves SIGINT or SIGTERM ignored (``SIG_IGN``, which ``exec`` passes on to children) where it
    was not before, and put the handler found back. A process that got a stop signal ignores further ones until it
    exits (:mod:`hindrax_drivers.ros_process`), so a test running such a process in its worker's main thread must
    restore the handlers. Found by a fresh clone of e0567a0: a ``RosProcess`` test left both ignored, and a later
    test's bash could not end its own background loop with ``kill``."""
    sigs = (signal.SIGINT, signal.SIGTERM)
    before = {sig: signal.getsignal(sig) for sig in sigs}
    yield
    left = [sig for sig in sigs if signal.getsignal(sig) == signal.SIG_IGN != before[sig]]
    for sig in left:
        signal.signal(sig, before[sig])
    assert not left, f"the test left {', '.join(signal.Signals(s).name for s in left)} ignored in its worker"
