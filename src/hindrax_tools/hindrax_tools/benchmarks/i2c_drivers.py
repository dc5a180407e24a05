"""I2C sensor drivers benchmark: CPU per published message and register-read-to-topic latency.

For each driver (MS5837 pressure node, ICM-20948 IMU node) one process runs the node over its
device emulator on an :class:`~hindrax_common.transport.emulated_i2c.EmulatedI2CBus`, plus a probe node
subscribing to the main topic, all in one EventsExecutor (the executor of every node process,
``hindrax_common.process.ros_process``), with the shipped configuration
(MS5837: 10 Hz, OSR 4096; ICM-20948: 100 Hz configured = 102.27 Hz, I2C-master magnetometer).

* Latency: from the emulator's ``i2c_read`` of the data (ICM-20948: the 23-byte burst; MS5837: the ADC read
  of D2, the last read of a cycle) to the probe's callback for the message made from it, wall clock
  (``time.time_ns``, the same clock as the ROS stamps). For the MS5837 the age of the stamp (the D1 read,
  see the node docstring) at receipt is reported too; it includes the D2 conversion time.
* CPU per message: process CPU time (node + probe + raw-traffic publication + DDS) over the run, minus the CPU spent
  inside the emulator's ``i2c_read``/``i2c_write`` (reported separately: the MS5837 emulator inverts the compensation by
  bisection at every conversion start, which costs more than the driver), divided by the messages published on the main
  topic; and the load in % of one core. The ``_marginal`` rows also subtract the CPU an idle process with one DDS
  participant uses over the same time (measured first), which dominates the per-message figure of a 10 Hz driver."""
from __future__ import annotations

import bisect
import time
from typing import Any, Callable

import numpy as np
import rclpy
from hindrax_drivers.icm20948.emulator import Icm20948Emulator
from hindrax_drivers.icm20948.node import Icm20948Node
from hindrax_drivers.ms5837.emulator import Ms5837Emulator
from hindrax_drivers.ms5837.node import Ms5837Node
from hindrax_common.testing import config_parameters, ros_context, wait_until
from hindrax_common.transport.emulated_i2c import EmulatedI2CBus
from sensor_msgs.msg import FluidPressure, Imu

from . import run_alone, spin_for, spinning


def _run(node_factory, emulator, address: int, msg_type, topic: str, duration_s: float):
    """Spin node + probe for ``duration_s``; return (cpu_s, wall_s, published, receipts [(t_ns, stamp_ns)])."""
    bus = EmulatedI2CBus({address: emulator})
    receipts: list[tuple[int, int]] = []
    with ros_context() as ctx:
        node = node_factory(bus, ctx)
        probe = rclpy.create_node("bench_probe", context=ctx)
        probe.create_subscription(
            msg_type, topic,
            lambda m: receipts.append((time.time_ns(), m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec)),
            50)
        # spin() blocks until there is work, as a node process's spin does
        with spinning(ctx, node, probe, events=True) as (_ex, spin):
            wait_until(lambda: len(receipts) >= 3, 15, spin, f"first {topic} messages")
            receipts.clear()
            published0 = node.diag.total_published
            cpu, wall = spin_for(duration_s, spin)
            published = node.diag.total_published - published0
    return cpu, wall, published, receipts


def _idle_load(duration_s: float) -> float:
    """CPU load (fraction of a core) of this process with an idle context and probe node: the DDS background."""
    with ros_context() as ctx:
        probe = rclpy.create_node("bench_idle", context=ctx)
        with spinning(ctx, probe, events=True) as (_ex, spin):
            cpu, wall = spin_for(duration_s, spin)
            return cpu / wall


def _timed(cls: type, timed_read: Callable[[int], bool]) -> type:
    """Emulator class ``cls`` that also keeps ``reads_ns``, the wall time of each read of n bytes with
    ``timed_read(n)``, and ``cpu_s``, the CPU time its reads and writes took (not the driver's)."""
    class Timed(cls):  # type: ignore[misc, valid-type]
        def i2c_read(self, n: int) -> bytes:
            c0 = time.process_time()
            out = super().i2c_read(n)
            if timed_read(n):
                self.reads_ns.append(time.time_ns())
            self.cpu_s += time.process_time() - c0
            return out

        def i2c_write(self, data: bytes) -> None:  # MS5837 conversion start: inverts compensation
            c0 = time.process_time()
            super().i2c_write(data)
            self.cpu_s += time.process_time() - c0
    Timed.reads_ns, Timed.cpu_s = [], 0.0
    return Timed


def _cpu_rows(prefix: str, emu: Any, cpu: float, wall: float, published: int, idle: float,
              per: str, unit: str, emulator_note: str = "") -> list[dict]:
    """The CPU rows of a driver: per message and load (node + probe + DDS, the emulator's CPU
    excluded), the same minus the idle DDS background, and the emulator's own per message."""
    own, n = cpu - emu.cpu_s, max(published, 1)
    return [
        {"name": f"{prefix}_cpu_per_message", "value": own / n * 1e3, "unit": "ms",
         "note": f"per {per}; node + probe + DDS, emulator excluded"},
        {"name": f"{prefix}_cpu_load", "value": own / wall * 100.0, "unit": "% of a core",
         "note": f"{published / wall:.3g} {unit}; emulator excluded"},
        {"name": f"{prefix}_cpu_per_message_marginal", "value": (own - idle * wall) / n * 1e3,
         "unit": "ms", "note": f"minus the idle DDS background ({idle * 100:.2f} % of a core)"},
        {"name": f"{prefix}_emulator_cpu_per_message", "value": emu.cpu_s / n * 1e3, "unit": "ms",
         **({"note": emulator_note} if emulator_note else {})},
    ]


def _icm20948(duration_s: float, idle: float) -> list[dict]:
    def truth(t):
        s = np.sin(3.0 * t)
        return (np.array([0.1, -0.2, 9.8]) + 0.3 * s, np.array([0.01, 0.02, -0.03]) * s,
                np.array([2e-5, -5e-6, 4e-5]), 25.0 + s)

    params = config_parameters({"sensors.icm20948.estimate_gyro_bias": False})
    emu = _timed(Icm20948Emulator, lambda n: n >= 14)(truth, address=0x69)
    reads_ns = emu.reads_ns
    cpu, wall, published, receipts = _run(
        lambda bus, ctx: Icm20948Node(bus=bus, context=ctx, parameter_overrides=params), emu, 0x69, Imu,
        "imu/data_raw", duration_s)
    latencies = []
    for t_rx, stamp in receipts:
        i = bisect.bisect_right(reads_ns, stamp) - 1  # the burst read just before the stamp
        if i >= 0:
            latencies.append((t_rx - reads_ns[i]) * 1e-6)
    p50, p99 = np.percentile(latencies, [50, 99])  # ms
    return [
        {"name": "icm20948_read_to_topic_p50", "value": p50, "unit": "ms", "target": "< 10 ms (one 100 Hz period)"},
        {"name": "icm20948_read_to_topic_p99", "value": p99, "unit": "ms"},
        *_cpu_rows("icm20948", emu, cpu, wall, published, idle,
                   "Imu (+ Temperature, MagneticField, raw) cycle", "Imu/s"),
    ]


def _ms5837(duration_s: float, idle: float) -> list[dict]:
    params = config_parameters({})
    emu = _timed(Ms5837Emulator, lambda n: n == 3)(
        lambda t: (110000.0 + 500.0 * np.sin(t), 18.0 + np.sin(0.5 * t)), variant="30BA")
    adc_reads_ns = emu.reads_ns
    cpu, wall, published, receipts = _run(
        lambda bus, ctx: Ms5837Node(bus=bus, context=ctx, parameter_overrides=params), emu, 0x76, FluidPressure,
        "pressure/fluid_pressure", duration_s)
    latencies, ages = [], []
    for t_rx, stamp in receipts:
        # the D2 read is the last ADC read before the receipt (the stamp: mid D1 conversion)
        i = bisect.bisect_right(adc_reads_ns, t_rx) - 1
        if i >= 1 and adc_reads_ns[i - 1] > stamp:  # D1's read lies between the stamp and D2's read
            latencies.append((t_rx - adc_reads_ns[i]) * 1e-6)
        ages.append((t_rx - stamp) * 1e-6)
    (p50, p99), (a50, a99) = np.percentile(latencies, [50, 99]), np.percentile(ages, [50, 99])  # ms
    return [
        {"name": "ms5837_read_to_topic_p50", "value": p50, "unit": "ms", "target": "< 5 ms"},
        {"name": "ms5837_read_to_topic_p99", "value": p99, "unit": "ms"},
        {"name": "ms5837_stamp_age_p50", "value": a50, "unit": "ms",
         "note": "stamp (middle of the D1 conversion) to receipt: includes the D2 conversion (9.5 ms at OSR 4096)"},
        {"name": "ms5837_stamp_age_p99", "value": a99, "unit": "ms"},
        *_cpu_rows("ms5837", emu, cpu, wall, published, idle,
                   "cycle (FluidPressure + Temperature + depth + raw)", "cycles/s",
                   "two compensation inversions per conversion (bisection)"),
    ]


def run(quick: bool = False) -> list[dict]:
    """Rows for ``make bench`` (see the module docstring). ``quick``: 3 s per driver instead of 10/15 s."""
    idle = _idle_load(2.0 if quick else 5.0)
    return _icm20948(3.0 if quick else 10.0, idle) + _ms5837(3.0 if quick else 15.0, idle)


if __name__ == "__main__":
    raise SystemExit(run_alone(run))
