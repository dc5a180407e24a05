"""Serial drivers benchmark (DVL-75, Ping1D): CPU per published report and bytes-to-topic latency.

For each driver one process runs its device emulator behind a pseudo-terminal
(:class:`~hindrax_common.transport.pty_device.PtyDevice`), the driver node reading it through the real
pyserial path (:class:`~hindrax_common.transport.serial_transport.SerialTransport`), and a probe node
subscribed to the output topics, in one SingleThreadedExecutor:

    emulator.poll -> pty write -> pyserial read (reader thread) -> decode -> publish -> probe callback

* Latency: from the emulator's write of the bytes (``time.monotonic_ns`` right after ``poll`` returns;
  :class:`PtyDevice` writes them at once) to the probe's callback for the message made from them. The side channel
  identifying each message is the emulator truth: the k-th DVL cycle reports confidence ``1 + k % 100`` % and altitude
  ``2.00 + (k % 100) * 0.01`` m, the k-th ping a distance of ``1.000 + (k % 1000) * 0.001`` m, all exact on the wire, so
  a received message maps to the write that carried it.
* CPU per report: (a) the transport reader thread's own CPU time (``pthread_getcpuclockid``): decode, conversion and
  publication of every output topic of that report (DVL: dvl/data + dvl/twist + dvl/altitude + raw/dvl75; Ping:
  ping/altitude + ping/confidence + raw/ping1d); (b) process CPU time minus the emulator thread's, i.e.
  node + probe + executor + DDS. Both divided by the reports published. Rates: DVL 20 Hz (its maximum, docs/devices.md
  §1.1); Ping 40 Hz (25 ms interval: a 236-byte profile per ping is about the most a 115200-baud link carries)."""
from __future__ import annotations

import time

import numpy as np
import rclpy
from sensor_msgs.msg import Range

from hindrax_common.config import default_config_path, load_config
from hindrax_drivers.dvl75.emulator import Dvl75Emulator, DvlTruth
from hindrax_drivers.dvl75.node import Dvl75Node
from hindrax_drivers.ping1d.emulator import Ping1dEmulator, Ping1dSettings, Ping1dTruth
from hindrax_drivers.ping1d.node import Ping1dNode
from hindrax_common.testing import config_parameters, ros_context, wait_until
from hindrax_common.transport.pty_device import PtyDevice
from hindrax_msgs.msg import Dvl

from . import run_alone, spin_for, spinning
from .machine import thread_cpu_s

DVL_RATE_HZ = 20.0
PING_INTERVAL_S = 0.025


class _TimedEmulator:
    """The emulator ``make(sample)`` whose k-th truth sample is ``truth(k)``, keyed ``k % modulus``; :attr:`written`
    maps a key to the ``time.monotonic_ns()`` at which ``poll`` returned its bytes."""

    def __init__(self, make, truth, modulus: int) -> None:
        self.written: dict[int, int] = {}
        self._pending: list[int] = []  # keys of the truth samples taken during the current poll
        self._k = 0

        def sample(_t: float):
            k, self._k = self._k, self._k + 1
            self._pending.append(k % modulus)
            return truth(k)
        self.emulator = make(sample)
        self.feed_host_bytes = self.emulator.feed_host_bytes

    def poll(self, t_s: float) -> bytes:
        out = self.emulator.poll(t_s)
        now = time.monotonic_ns()
        for key in self._pending:
            self.written[key] = now
        self._pending.clear()
        return out


def _measure(node_factory, emulator, subscriptions, duration_s: float, name: str, rate: str) -> list[dict]:
    """Run node + probe for ``duration_s`` after a warm-up; the rows of :func:`_rows`."""
    latencies: dict[str, list[int]] = {topic: [] for topic, _, _ in subscriptions}
    dev = PtyDevice(emulator)
    try:
        with ros_context() as ctx:
            node = node_factory(dev.path, ctx)
            probe = rclpy.create_node(f"bench_probe_{name}", context=ctx)
            for topic, msg_type, written_at in subscriptions:
                def cb(msg, topic=topic, written_at=written_at):
                    t_write = written_at(msg)
                    if t_write is not None:
                        latencies[topic].append(time.monotonic_ns() - t_write)
                probe.create_subscription(msg_type, topic, cb, 100)
            with spinning(ctx, node, probe) as (_ex, spin):  # spin blocks until work, like spin()
                first = subscriptions[0][0]
                wait_until(lambda: len(latencies[first]) >= 20, 20, spin, f"{name}: first messages")
                for v in latencies.values():
                    v.clear()
                published0 = node.diag.total_published
                threads0 = thread_cpu_s()
                cpu, wall = spin_for(duration_s, spin)
                threads = {k: v - threads0.get(k, 0.0) for k, v in thread_cpu_s().items()}
                reader = sum(v for k, v in threads.items() if k.startswith("SerialTransport("))
                emu = sum(v for k, v in threads.items() if k.startswith("PtyDevice"))
                reports = node.diag.total_published - published0
    finally:
        dev.close()
    return _rows(name, rate, reader, cpu - emu - reader, wall, reports, latencies)


def _rows(device: str, rate: str, reader_s: float, other_s: float, wall_s: float, reports: int,
          latencies: dict[str, list[int]]) -> list[dict]:
    """Reports, CPU per report and load, and per topic the latency from the device's bytes."""
    n = max(reports, 1)
    rows = [
        {"name": f"{device} reports published", "value": reports, "unit": "msgs", "note": f"{rate} for {wall_s:.1f} s"},
        {"name": f"{device} reader-thread CPU per report", "value": reader_s / n * 1e3, "unit": "ms",
         "target": "< 2", "note": "decode + convert + publish all topics of one report"},
        {"name": f"{device} node+probe+DDS CPU per report", "value": (reader_s + other_s) / n * 1e3, "unit": "ms",
         "note": "process CPU minus the emulator thread"},
        {"name": f"{device} node+probe+DDS load", "value": (reader_s + other_s) / wall_s * 100.0, "unit": "% core"},
    ]
    for label, values in latencies.items():
        if not values:
            continue
        p50, p99 = np.percentile(np.array(values, dtype=float) * 1e-6, [50, 99])
        rows.append({"name": f"{device} latency p50 bytes->{label}", "value": p50, "unit": "ms",
                     "note": f"{len(values)} samples"})
        rows.append({"name": f"{device} latency p99 bytes->{label}", "value": p99, "unit": "ms", "target": "< 10"})
    return rows


def _bench_dvl(duration_s: float) -> list[dict]:
    emu = _TimedEmulator(
        lambda truth: Dvl75Emulator(truth, rate_hz=DVL_RATE_HZ),
        lambda k: DvlTruth(velocity_frd_m_s=(0.2 + 0.01 * (k % 7), 0.0, 0.0),
                           altitude_m=2.0 + (k % 100) * 0.01, confidence_pct=1 + k % 100), 100)
    written = emu.written

    def data_key(msg):
        return written.get(int(round(msg.confidence_percent)) - 1) if msg.velocity_valid else None

    def altitude_key(msg):
        return written.get(int(round((msg.range - 2.0) / 0.01)) % 100) if msg.range < 1e9 else None

    def factory(port, ctx):
        return Dvl75Node(context=ctx, parameter_overrides=config_parameters(
            {"sensors.dvl75.port": port, "sensors.dvl75.position_frd_m": [0.0, 0.0, 0.0]}))

    subscriptions = [("dvl/data", Dvl, data_key), ("dvl/altitude", Range, altitude_key)]
    return _measure(factory, emu, subscriptions, duration_s, "dvl75", f"{DVL_RATE_HZ:g} Hz")


def _bench_ping(duration_s: float) -> list[dict]:
    c = float(load_config(default_config_path()).sensors.ping1d.speed_of_sound_m_s)
    settings = Ping1dSettings(speed_of_sound_m_s=c, ping_interval_s=PING_INTERVAL_S)
    emu = _TimedEmulator(
        lambda truth: Ping1dEmulator(truth, settings=settings, true_speed_of_sound_m_s=c),
        lambda k: Ping1dTruth(altitude_m=1.0 + (k % 1000) * 0.001, confidence_pct=90), 1000)
    written = emu.written

    def range_key(msg):
        return written.get(int(round((msg.range - 1.0) / 0.001)) % 1000) if msg.range < 1e9 else None

    def factory(port, ctx):
        return Ping1dNode(context=ctx, parameter_overrides=config_parameters(
            {"sensors.ping1d.port": port, "sensors.ping1d.ping_interval_s": PING_INTERVAL_S}))

    return _measure(factory, emu, [("ping/altitude", Range, range_key)], duration_s, "ping1d",
                    f"{1 / PING_INTERVAL_S:g} Hz")


def run(quick: bool = False) -> list[dict]:
    """Benchmark rows (see the module docstring). ``quick``: 3 s per driver instead of 10 s."""
    rows = _bench_dvl(3.0 if quick else 10.0)
    rows += _bench_ping(3.0 if quick else 10.0)
    return rows


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(run_alone(run))
