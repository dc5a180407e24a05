"""The vehicle's devices in one table: what bringup, composition, the drive replay, the emulated pool-day devices
and the simulator's virtual hardware loop over.

Adding a device is one :class:`Device` entry here plus its own folder (protocol, emulator, node). Node classes and
emulator factories are "module:attribute" strings (".dvl75.node": in hindrax_drivers) or callables (a test's fake
device), imported only when used, so reading the table loads no ROS messages."""
from __future__ import annotations

import functools
import importlib
from dataclasses import dataclass, field
from typing import Any

__all__ = ["Device", "DEVICES", "SERIAL", "I2C", "load", "settings", "build_node"]

SERIAL, I2C = "serial", "i2c"


@dataclass(frozen=True)
class Device:
    """One device of the vehicle.

    name: device name (``raw/<name>`` topic, emulator key, pty link name in the simulator). node: its driver node's
    name. transport: :data:`SERIAL` (a port at ``<section>.port``) or :data:`I2C` (at ``<section>.i2c_address``, the
    node takes the bus as ``bus=``). node_class / emulator: "module:attribute" or a callable; the emulator factory is
    called as ``emulator(config, truth, clock, seed)`` (truth: a callable of time, s, or None for an output). section:
    dotted configuration section. topics: parsed topic (absolute) -> message type, the topics a replay compares. output:
    an actuator (its reads echo the driver's writes; not part of the sensors group). status: its ``/diagnostics`` status
    name, "" for ``hindrax/<node>``. truth_keywords: the emulator factory's keyword-only arguments that only the
    simulated part knows (the simulator passes each from its truth's section of this device, by name)."""

    name: str
    node: str
    transport: str
    node_class: Any
    emulator: Any
    section: str
    topics: dict[str, str] = field(default_factory=dict)
    output: bool = False
    status: str = ""
    truth_keywords: tuple[str, ...] = ()


#: every device, in construction order (bringup builds the drivers in this order; the ESC, an output, last)
DEVICES: tuple[Device, ...] = (
    Device("dvl75", "dvl75", SERIAL, ".dvl75.node:Dvl75Node", ".dvl75.emulator:from_config", "sensors.dvl75",
           {"/dvl/data": "hindrax_msgs/msg/Dvl", "/dvl/twist": "geometry_msgs/msg/TwistWithCovarianceStamped",
            "/dvl/altitude": "sensor_msgs/msg/Range"},
           truth_keywords=("rate_hz", "min_altitude_m", "max_altitude_m")),
    Device("ping1d", "ping1d", SERIAL, ".ping1d.node:Ping1dNode", ".ping1d.emulator:from_config", "sensors.ping1d",
           {"/ping/altitude": "sensor_msgs/msg/Range", "/ping/confidence": "std_msgs/msg/Float32"}),
    Device("ms5837", "ms5837", I2C, ".ms5837.node:Ms5837Node", ".ms5837.emulator:from_config", "sensors.ms5837",
           {"/pressure/fluid_pressure": "sensor_msgs/msg/FluidPressure",
            "/pressure/temperature": "sensor_msgs/msg/Temperature",
            "/pressure/depth": "geometry_msgs/msg/PoseWithCovarianceStamped"}),
    Device("icm20948", "icm20948", I2C, ".icm20948.node:Icm20948Node", ".icm20948.emulator:from_config",
           "sensors.icm20948", {"/imu/data_raw": "sensor_msgs/msg/Imu", "/imu/mag": "sensor_msgs/msg/MagneticField",
                                "/imu/temperature": "sensor_msgs/msg/Temperature"}),
    Device("pca9685", "esc", I2C, ".pca9685.node:EscNode", ".pca9685.emulator:from_config", "esc", output=True,
           status="hindrax/esc_pca9685"),
)


def load(ref: Any) -> Any:
    """``ref`` itself if callable, else the attribute a "module:attribute" string names (imported; a module name
    with a leading dot is in hindrax_drivers, the devices' package)."""
    if callable(ref):
        return ref
    module, _, attr = ref.partition(":")
    return getattr(importlib.import_module(module, "hindrax_drivers"), attr)


def settings(config: Any, device: Device) -> Any:
    """The configuration section of ``device`` in ``config`` (a VehicleConfig)."""
    return functools.reduce(getattr, device.section.split("."), config)


def build_node(device: Device, bus: Any = None, **kwargs: Any) -> Any:
    """The driver node of ``device``: its class called with ``kwargs``, and ``bus`` (None: the node opens its
    configured bus) for an I2C device."""
    cls = load(device.node_class)
    return cls(bus=bus, **kwargs) if device.transport == I2C else cls(**kwargs)

