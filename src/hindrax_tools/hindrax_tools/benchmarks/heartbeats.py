"""Heartbeat benchmark: what one safety heartbeat costs, as ``hindrax_msgs/Heartbeat`` against the
``diagnostic_msgs/DiagnosticStatus`` with key-value pairs it replaced, measured side by side in one process.

The three safety processes send 65 beats a second between them (ESC 25 Hz, supervisor and guard 20 Hz each) and
each beat is read by two receivers (docs/architecture.md §8), so a beat's cost is paid about 130 times a second.

* ``heartbeat_codec_cpu_us_{status,heartbeat}`` and ``heartbeat_codec_cpu_ratio``: thread CPU time to build one ESC
  beat as the bytes a node publishes and to read it back as a receiver does, median of 5 blocks. Before: rosbags'
  encoder of a DiagnosticStatus with the ESC's seven key-value pairs (``boot_id``, ``seq``, ``output_state``,
  ``armed``, ``reason``, ``guard_boot_id``, ``guard_seq``), rclpy's deserialiser and the pairs parsed into numbers.
  After: :func:`hindrax_common.cdr.lean_cdr.heartbeat_cdr` and :func:`~hindrax_common.cdr.lean_cdr.read_heartbeat`.
* ``heartbeat_cycle_cpu_us_{status,heartbeat}`` and ``heartbeat_cycle_cpu_ratio``: process CPU time (every thread:
  DDS included) per beat built, published, delivered to a subscription in a second participant through rclpy's
  EventsExecutor and read, median of 5 alternating blocks of beats. Before: the DiagnosticStatus subscription of
  rclpy objects; after: the raw subscription the receivers use (:class:`~.liveness.HeartbeatWatch`).
* ``heartbeat_graph_queries_per_s``: graph queries of one :class:`~.liveness.HeartbeatWatch` checked
  at 25 Hz with its peer publishing (before: one query per check, 25 a second; the ESC and the guard check four
  watches and the command topic, 115 queries a second), and ``heartbeat_graph_query_cpu_us`` what one costs."""
from __future__ import annotations

import statistics
import time

import rclpy
from diagnostic_msgs.msg import DiagnosticStatus
from domain_coordinator import domain_id
from rclpy.serialization import deserialize_message

from hindrax_common.cdr.lean_cdr import diagnostic_status_cdr, heartbeat_cdr, read_heartbeat
from hindrax_common.node_support.liveness import (SETTLE_S, HeartbeatPublisher, HeartbeatWatch, heartbeat_qos,
                                                   publisher_node_names)
from hindrax_common.testing import ros_context, wait_until
from hindrax_msgs.msg import Heartbeat

from . import run_alone, spinning

BLOCKS = 5
BOOT, GUARD_BOOT = 0x0123456789ABCDEF, 0x0FEDCBA987654321
REASON = "armed, commanding"


def _status_bytes(seq: int) -> bytes:
    return diagnostic_status_cdr(0, "hindrax/esc", "commanding", "esc", [
        ("boot_id", f"{BOOT:016x}"), ("seq", str(seq)), ("output_state", "2"), ("armed", "true"),
        ("reason", REASON), ("guard_boot_id", f"{GUARD_BOOT:016x}"), ("guard_seq", str(seq))])


def _read_status(msg) -> tuple:
    values = {kv.key: kv.value for kv in msg.values}
    return (values["boot_id"], int(values["seq"]), int(values["output_state"]), values["armed"] == "true",
            values["guard_boot_id"], int(values["guard_seq"]), msg.level, msg.message)


def _heartbeat_bytes(seq: int) -> bytes:
    return heartbeat_cdr(BOOT, seq, time.monotonic_ns(), 0, REASON, 2, True, GUARD_BOOT, seq)


def codec_rows(n: int) -> list[dict]:
    """Build + read, no DDS (module docstring)."""
    kinds = {"status": lambda i: _read_status(deserialize_message(_status_bytes(i), DiagnosticStatus)),
             "heartbeat": lambda i: tuple(read_heartbeat(_heartbeat_bytes(i)))}
    per = {k: [] for k in kinds}
    for _ in range(BLOCKS):
        for kind, one in kinds.items():
            t0 = time.thread_time_ns()
            for i in range(1, n + 1):
                one(i)
            per[kind].append((time.thread_time_ns() - t0) / n / 1e3)
    return _cpu_rows("codec", per, n, "one ESC beat built as bytes and read back ({k}), median of {blocks} blocks")


def cycle_rows(n: int) -> list[dict]:
    """Build, publish, deliver through the EventsExecutor, read (module docstring)."""
    per = {"status": [], "heartbeat": []}
    with domain_id() as dom, ros_context(domain_id=dom) as tx_ctx, ros_context(domain_id=dom) as rx_ctx:
        tx = rclpy.create_node("beat_sender", context=tx_ctx)
        rx = rclpy.create_node("beat_receiver", context=rx_ctx)
        got = {"n": 0}

        def count(read):
            def callback(msg) -> None:
                read(msg)
                got["n"] += 1
            return callback
        pubs = {"status": tx.create_publisher(DiagnosticStatus, "status_beat", heartbeat_qos()),
                "heartbeat": tx.create_publisher(Heartbeat, "heartbeat_beat", heartbeat_qos())}
        rx.create_subscription(DiagnosticStatus, "status_beat", count(_read_status), heartbeat_qos())
        rx.create_subscription(Heartbeat, "heartbeat_beat", count(read_heartbeat), heartbeat_qos(), raw=True)
        build = {"status": _status_bytes, "heartbeat": _heartbeat_bytes}
        with spinning(rx_ctx, rx, events=True, timeout_s=0.05) as (ex, spin):
            wait_until(lambda: all(p.get_subscription_count() for p in pubs.values()), 30, spin, "matched")
            for _ in range(BLOCKS):
                for kind, pub in pubs.items():
                    got["n"] = 0
                    t0 = time.process_time()
                    for i in range(1, n + 1):
                        pub.publish(build[kind](i))
                        while got["n"] < i:
                            ex.spin_once(timeout_sec=1.0)
                    per[kind].append((time.process_time() - t0) / n * 1e6)
        tx.destroy_node()
    return _cpu_rows("cycle", per, n,
                     "process CPU per beat built, published, delivered to a second participant through the "
                     "EventsExecutor and read ({k}), median of {blocks} alternating blocks")


def _cpu_rows(what: str, per: dict[str, list[float]], n: int, note: str) -> list[dict]:
    """Rows ``heartbeat_<what>_cpu_us_<kind>`` (the median of the blocks ``per[kind]``, us per beat; ``note`` with
    ``{k}`` the kind, ``{blocks}`` their number) and ``heartbeat_<what>_cpu_ratio``."""
    med = {k: statistics.median(v) for k, v in per.items()}
    name = f"heartbeat_{what}_cpu"
    return [*({"name": f"{name}_us_{k}", "value": med[k], "unit": "us", "n": n * BLOCKS,
               "note": note.format(k=k, blocks=BLOCKS)} for k in med),
            {"name": f"{name}_ratio", "value": med["heartbeat"] / med["status"], "unit": "x",
             "note": "Heartbeat / DiagnosticStatus, same process and run"}]


def graph_rows(seconds: float) -> list[dict]:
    """Graph queries of one watch checked at 25 Hz, and one query's CPU (module docstring)."""
    with domain_id() as dom, ros_context(domain_id=dom) as ctx:
        peer = rclpy.create_node("supervisor", context=ctx)
        rx = rclpy.create_node("esc", context=ctx)
        beat = HeartbeatPublisher(peer, "supervisor")
        watch = HeartbeatWatch(rx, "supervisor", lambda _b: None, lambda: False)
        with spinning(ctx, rx, events=True, timeout_s=0.04) as (_ex, spin):
            wait_until(lambda: not watch.check() and watch.identity.seq, 30,
                       lambda: (beat.publish(True, "ok"), spin()), "the peer trusted")

            def ticks(duration_s: float) -> tuple[int, float]:  # a 25 Hz tick: beat, deliver, check
                t0, checks = time.monotonic(), 0
                while time.monotonic() - t0 < duration_s:
                    beat.publish(True, "ok")
                    spin()
                    watch.check()
                    checks += 1
                    time.sleep(max(0.0, t0 + checks * 0.04 - time.monotonic()))
                return checks, time.monotonic() - t0
            ticks(SETTLE_S + 0.1)  # past the discovery events' settle window
            start = watch.publishers.queries
            checks, elapsed = ticks(seconds)
            queries = watch.publishers.queries - start
            t1 = time.thread_time_ns()
            for _ in range(200):
                publisher_node_names(rx, "supervisor/heartbeat")
            query_us = (time.thread_time_ns() - t1) / 200 / 1e3
        peer.destroy_node()
    return [{"name": "heartbeat_graph_queries_per_s", "value": queries / elapsed, "unit": "1/s",
             "note": f"one watch checked {checks / elapsed:.0f} times a second with its peer beating, no graph "
                     f"change, after discovery settled ({queries} queries in {elapsed:.1f} s; before: one per "
                     "check)"},
            {"name": "heartbeat_graph_query_cpu_us", "value": query_us, "unit": "us", "n": 200,
             "note": "thread CPU of one publisher_node_names call, one publisher"}]


def run(quick: bool = False) -> list[dict]:
    """The rows of the module docstring."""
    return [*codec_rows(500 if quick else 5000), *cycle_rows(200 if quick else 1000),
            *graph_rows(2.0 if quick else 6.0)]


if __name__ == "__main__":
    raise SystemExit(run_alone(run))
