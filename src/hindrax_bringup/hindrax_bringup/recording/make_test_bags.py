"""Write the small synthetic test bags under ``src/hindrax_bringup/test/data/``.

Usage: ``python -m hindrax_bringup.recording.make_test_bags [--out DIR]`` (default: the repository's
``src/hindrax_bringup/test/data``). Existing bags of the same names are replaced.

The synthetic streams (:data:`STREAMS`, :func:`synthetic_messages`, :func:`write_bag`: a vehicle at 1 m depth
surging sinusoidally at the stack's nominal rates) give the recorder benchmark and the writer tests a known,
fixed load. The bag recorded from the virtual pool through the real drivers (``sim_drivers_3s``) needs the
simulator, which lives in hindrax_sim (dependencies flow hindrax_msgs <- hindrax_bringup <- ... <- hindrax_sim):
it is written by ``test/support/hindrax_test_support/record_bag.py``."""
from __future__ import annotations

import argparse
import math
import shutil
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np
from geometry_msgs.msg import WrenchStamped
from rclpy.serialization import serialize_message
from sensor_msgs.msg import FluidPressure, Imu, MagneticField, Range

from hindrax_msgs.msg import Dvl, RawDeviceData, ThrusterPwm

from hindrax_drivers.dvl75.protocol import format_sentence
from .qos import default_profile
from .writer import BagWriter, WriterOptions

START_NS = 1_700_000_000_000_000_000
"""Log-time origin of the test bags (2023-11-14 22:13:20 UTC), ns."""
LATENCY_NS = 1_000_000
"""Log time minus header stamp of every message, ns."""
SEED = 20240611

WATER_DENSITY_KG_M3 = 1000.0
GRAVITY_M_S2 = 9.81
SURFACE_PRESSURE_PA = 101325.0
DEPTH_M = 1.0
SURGE_AMPLITUDE_M_S = 0.2
SURGE_FREQUENCY_HZ = 0.25


@dataclass(frozen=True)
class StreamSpec:
    """One synthetic topic: name, type, rate (Hz), reliability, message factory f(t_s, rng) -> msg."""

    topic: str
    type: str
    rate_hz: float
    reliability: str
    make: Callable[[float, np.random.Generator], Any]


def _stamp(msg: Any, t_s: float, frame_id: str) -> Any:
    ns = START_NS + int(round(t_s * 1e9))
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(ns, 1_000_000_000)
    msg.header.frame_id = frame_id
    return msg


def surge_velocity_m_s(t_s: float) -> float:
    """Synthetic surge velocity u(t) = A sin(2 pi f t), m/s (base_link x)."""
    return SURGE_AMPLITUDE_M_S * math.sin(2 * math.pi * SURGE_FREQUENCY_HZ * t_s)


def surge_acceleration_m_s2(t_s: float) -> float:
    """du/dt of :func:`surge_velocity_m_s`, m/s^2."""
    w = 2 * math.pi * SURGE_FREQUENCY_HZ
    return SURGE_AMPLITUDE_M_S * w * math.cos(w * t_s)


def _imu(t: float, rng: np.random.Generator) -> Any:
    m = _stamp(Imu(), t, "imu_link")
    m.orientation.w = 1.0
    m.orientation_covariance[0] = -1.0
    m.angular_velocity.z = float(rng.normal(0.0, 0.003))
    m.linear_acceleration.x = surge_acceleration_m_s2(t) + float(rng.normal(0.0, 0.05))
    m.linear_acceleration.z = GRAVITY_M_S2 + float(rng.normal(0.0, 0.05))
    m.angular_velocity_covariance[0] = m.angular_velocity_covariance[4] = m.angular_velocity_covariance[8] = 9e-6
    m.linear_acceleration_covariance[0] = m.linear_acceleration_covariance[4] = 0.0025
    m.linear_acceleration_covariance[8] = 0.0025
    return m


def _mag(t: float, rng: np.random.Generator) -> Any:
    m = _stamp(MagneticField(), t, "imu_link")
    m.magnetic_field.x = 2.0e-5 + float(rng.normal(0.0, 1e-6))
    m.magnetic_field.z = -4.0e-5 + float(rng.normal(0.0, 1e-6))
    return m


def _dvl(t: float, rng: np.random.Generator) -> Any:
    m = _stamp(Dvl(), t, "base_link")
    m.velocity_m_s.x = surge_velocity_m_s(t) + float(rng.normal(0.0, 0.01))
    m.velocity_covariance[0] = m.velocity_covariance[4] = m.velocity_covariance[8] = 1e-4
    m.velocity_valid = True
    m.altitude_m = 0.8
    m.bottom_lock = True
    m.confidence_percent = 95.0
    m.beam_range_m = [0.8 / math.cos(math.radians(22.5))] * 4
    m.beam_velocity_m_s = [0.0] * 4
    m.beam_lock = [True] * 4
    m.orientation.w = 1.0
    m.orientation_covariance[0] = -1.0
    m.delta_position_m.x = surge_velocity_m_s(t) * 0.1
    m.delta_time_s = 0.1
    return m


def _range(frame: str, altitude_m: float) -> Callable[[float, np.random.Generator], Any]:
    def make(t: float, rng: np.random.Generator) -> Any:
        m = _stamp(Range(), t, frame)
        m.radiation_type = Range.ULTRASOUND
        m.field_of_view = math.radians(30.0)
        m.min_range = 0.3
        m.max_range = 50.0
        m.range = float(altitude_m + rng.normal(0.0, 0.005))
        m.variance = 2.5e-5
        return m
    return make


def _pressure(t: float, rng: np.random.Generator) -> Any:
    m = _stamp(FluidPressure(), t, "pressure_link")
    m.fluid_pressure = SURFACE_PRESSURE_PA + WATER_DENSITY_KG_M3 * GRAVITY_M_S2 * DEPTH_M + float(rng.normal(0, 20))
    m.variance = 400.0
    return m


def _pwm(t: float, rng: np.random.Generator) -> Any:
    m = _stamp(ThrusterPwm(), t, "base_link")
    surge = 60.0 * math.sin(2 * math.pi * SURGE_FREQUENCY_HZ * t)
    m.pulse_width_us = [1500.0 + surge, 1500.0 + surge, 1500.0, 1500.0, 1500.0, 1500.0, 1500.0, 1500.0]
    m.armed = True
    return m


def _wrench(t: float, rng: np.random.Generator) -> Any:
    m = _stamp(WrenchStamped(), t, "base_link")
    m.wrench.force.x = 10.0 * math.sin(2 * math.pi * SURGE_FREQUENCY_HZ * t)
    return m


def _raw(t: float, device: str, transport: int, address: int, register: int, data: bytes) -> Any:
    m = _stamp(RawDeviceData(), t, "")
    m.device_name = device
    m.transport = transport
    m.direction = RawDeviceData.DIRECTION_DEVICE_TO_HOST
    m.i2c_address = address
    m.i2c_register = register
    m.data = data
    return m


def _raw_dvl(t: float, rng: np.random.Generator) -> Any:
    body = (f"DVEXT,{int(round(t * 1000))},{surge_velocity_m_s(t):.3f},0.000,0.000,0.800,95,1,"
            "0.866,0.866,0.866,0.866,0.0,0.0,0.0")
    return _raw(t, "dvl75", RawDeviceData.TRANSPORT_SERIAL, 0, -1, format_sentence(body))


def _raw_ms5837(t: float, rng: np.random.Generator) -> Any:
    data = int(rng.integers(4_000_000, 4_100_000)).to_bytes(3, "big")
    return _raw(t, "ms5837", RawDeviceData.TRANSPORT_I2C, 0x76, 0x00, data)  # ADC read


def _raw_icm(t: float, rng: np.random.Generator) -> Any:
    data = bytes(int(v) & 0xFF for v in rng.integers(0, 256, 12))
    return _raw(t, "icm20948", RawDeviceData.TRANSPORT_I2C, 0x68, 0x2D, data)  # accel + gyro burst


STREAMS: tuple[StreamSpec, ...] = (
    StreamSpec("/imu/data", "sensor_msgs/msg/Imu", 100.0, "best_effort", _imu),
    StreamSpec("/imu/mag", "sensor_msgs/msg/MagneticField", 100.0, "best_effort", _mag),
    StreamSpec("/dvl/data", "hindrax_msgs/msg/Dvl", 10.0, "reliable", _dvl),
    StreamSpec("/dvl/range", "sensor_msgs/msg/Range", 10.0, "reliable", _range("dvl_link", 0.8)),
    StreamSpec("/ping1d/range", "sensor_msgs/msg/Range", 10.0, "reliable", _range("ping1d_link", 0.8)),
    StreamSpec("/depth/pressure", "sensor_msgs/msg/FluidPressure", 10.0, "reliable", _pressure),
    StreamSpec("/thrusters/pwm", "hindrax_msgs/msg/ThrusterPwm", 50.0, "reliable", _pwm),
    StreamSpec("/thrusters/wrench", "geometry_msgs/msg/WrenchStamped", 50.0, "reliable", _wrench),
    StreamSpec("/raw/dvl75", "hindrax_msgs/msg/RawDeviceData", 10.0, "reliable", _raw_dvl),
    StreamSpec("/raw/ms5837", "hindrax_msgs/msg/RawDeviceData", 20.0, "reliable", _raw_ms5837),
    StreamSpec("/raw/icm20948", "hindrax_msgs/msg/RawDeviceData", 100.0, "reliable", _raw_icm),
)
"""The synthetic topics (see module docstring)."""

#: bag name -> (duration s, WriterOptions)
BAGS: dict[str, tuple[float, WriterOptions]] = {
    "sensors_4s": (4.0, WriterOptions(chunk_size_bytes=64 * 1024, fsync=False)),
    "split_3s": (3.0, WriterOptions(chunk_size_bytes=32 * 1024, split_duration_s=1.0, fsync=False)),
}


def messages_per_stream(duration_s: float, rate_hz: float) -> int:
    """Samples at t = k / rate for k = 0, 1, ... with t < duration: ceil(duration * rate)."""
    return int(math.ceil(duration_s * rate_hz - 1e-9))


def synthetic_messages(duration_s: float, streams: tuple[StreamSpec, ...] = STREAMS):
    """(log_time_ns, topic, message) of every stream over ``duration_s``, in log-time order."""
    rng = np.random.default_rng(SEED)
    events = []
    for i, s in enumerate(streams):
        for k in range(messages_per_stream(duration_s, s.rate_hz)):
            t_ns = int(round(k * 1e9 / s.rate_hz))
            events.append((t_ns, i, s))
    events.sort(key=lambda e: (e[0], e[1]))
    for t_ns, _, s in events:
        msg = s.make(t_ns / 1e9, rng)
        yield START_NS + t_ns + LATENCY_NS, s.topic, msg


def write_bag(bag_dir: Path, duration_s: float, options: WriterOptions) -> int:
    """Write one bag of :data:`STREAMS`; returns its message count. Replaces an existing directory."""
    if bag_dir.exists():
        shutil.rmtree(bag_dir)
    n = 0
    with BagWriter(bag_dir, options) as w:
        for s in STREAMS:
            w.add_topic(s.topic, s.type, [default_profile(s.reliability)])
        for log_ns, topic, msg in synthetic_messages(duration_s):
            w.write(topic, log_ns, serialize_message(msg), log_ns - LATENCY_NS)
            n += 1
    return n



__all__ = ["STREAMS", "synthetic_messages", "messages_per_stream", "write_bag", "BAGS", "default_output_dir",
           "write_bags", "main"]

def default_output_dir() -> Path:
    """``src/hindrax_bringup/test/data`` of the source checkout this module lives in."""
    return Path(__file__).resolve().parents[2] / "test" / "data"


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point (``argv`` without the program name); returns the exit code."""
    parser = argparse.ArgumentParser(prog="make_test_bags", description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=str(default_output_dir()), help="directory to write the bags into")
    args = parser.parse_args(argv)
    write_bags(Path(args.out), BAGS, write_bag)
    return 0


def write_bags(out: Path, bags: dict[str, tuple[float, Any]], write: Callable[[Path, float, Any], int]) -> None:
    """Write every bag of ``bags`` (name -> (duration s, argument of ``write``)) into ``out`` with ``write``
    (returns the message count) and print one line per bag: its path, messages and size."""
    out.mkdir(parents=True, exist_ok=True)
    for name, (duration_s, arg) in bags.items():
        n = write(out / name, duration_s, arg)
        size = sum(p.stat().st_size for p in (out / name).iterdir())
        print(f"{out / name}: {n} messages, {size / 1024:.1f} KiB")


if __name__ == "__main__":
    sys.exit(main())
