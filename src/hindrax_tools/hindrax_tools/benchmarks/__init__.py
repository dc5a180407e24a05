"""The ``make bench`` benchmarks: one module per concern, each with a ``run(quick)`` function.

A module that ends in :func:`run_alone` runs alone: ``python -m
hindrax_tools.benchmarks.<module> [--quick]`` prints its rows as JSON."""
from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import rclpy
from hindrax_common.process.dds_transport import loopback_transport
from hindrax_common.testing import ros_context, wait_until
from rclpy.executors import SingleThreadedExecutor
from rclpy.experimental.events_executor import EventsExecutor


@contextmanager
def spinning(ctx, *nodes, events: bool = False, timeout_s: float = 0.1) -> Iterator[tuple[Any, Callable[[], None]]]:
    """``nodes`` (of rclpy context ``ctx``) in one executor, a SingleThreadedExecutor or with ``events`` rclpy's
    EventsExecutor (a node process's); yields (executor, spin): ``spin()`` is one ``spin_once`` of at most
    ``timeout_s``. Shuts the executor down and destroys the nodes on the way out."""
    ex = (EventsExecutor if events else SingleThreadedExecutor)(context=ctx)
    for node in nodes:
        ex.add_node(node)
    try:
        yield ex, lambda: ex.spin_once(timeout_sec=timeout_s)
    finally:
        ex.shutdown()
        for node in nodes:
            node.destroy_node()


@contextmanager
def probe_spinning(domain: int | None, name: str = "bench_probe",
                   timeout_s: float = 0.05) -> Iterator[tuple[Any, Any, Callable[[], None]]]:
    """A node ``name`` in an rclpy context of its own on ROS domain ``domain`` (None: this
    process's), spun as by :func:`spinning`; yields (node, executor, spin)."""
    with ros_context(domain_id=domain) as ctx:
        node = rclpy.create_node(name, context=ctx)
        with spinning(ctx, node, timeout_s=timeout_s) as (ex, spin):
            yield node, ex, spin


def spin_for(duration_s: float, spin: Callable[[], None] | None = None) -> tuple[float, float]:
    """Call ``spin`` (None: wait) for ``duration_s`` of wall time (a measurement window, a warm-up);
    returns (this process's CPU seconds, wall seconds) over it."""
    cpu0, start = time.process_time(), time.monotonic()
    wait_until(lambda: time.monotonic() >= start + duration_s, duration_s + 60, spin, "time window")
    return time.process_time() - cpu0, time.monotonic() - start


def call(client: Any, request: Any, spin: Callable[[], None] | None = None, timeout_s: float = 10.0) -> Any:
    """The answer to ``request`` from the service of rclpy ``client``, waited for up to ``timeout_s`` (``spin``: one
    executor spin between checks; None: another thread spins). Raises ConditionTimeout."""
    fut = client.call_async(request)
    wait_until(fut.done, timeout_s, spin, f"{client.srv_name} answer")
    return fut.result()


def start_logged(log: Path, argv: Sequence[str], mode: str = "w", **popen_kwargs: Any) -> subprocess.Popen:
    """``argv`` started (:class:`subprocess.Popen` with ``popen_kwargs``), its output and errors
    written to the file ``log`` (opened with ``mode``: ``"a"`` keeps an earlier run's lines)."""
    with open(log, mode) as out:
        return subprocess.Popen(argv, stdout=out, stderr=subprocess.STDOUT, **popen_kwargs)


def stop_processes(procs: Sequence[subprocess.Popen], wait_s: float = 15.0) -> None:
    """SIGCONT and SIGINT to every process still running, in order, then wait for each: ``wait_s``, then SIGKILL.
    One left alive keeps its nodes on the domain, and the next graph there refuses to start beside "another vehicle"."""
    for p in procs:
        if p.poll() is None:
            p.send_signal(signal.SIGCONT)  # a frozen process handles SIGINT only once it runs again
            p.send_signal(signal.SIGINT)
    for p in procs:
        try:
            p.wait(wait_s)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait(5)


def run_alone(run: Callable[[bool], list[dict]], argv: Sequence[str] | None = None) -> int:
    """Run one benchmark module alone (``python -m hindrax_tools.benchmarks.<name> [--quick]``) on the vehicle's
    loopback transport: print the rows of ``run(quick)`` as JSON; returns the exit status 0."""
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    loopback_transport()
    parser = argparse.ArgumentParser(description="one benchmark module's rows, as JSON")
    parser.add_argument("--quick", action="store_true", help="the reduced variant (bench --quick)")
    print(json.dumps(run(parser.parse_args(argv).quick), indent=2))
    return 0
