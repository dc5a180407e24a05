"""The vehicle's five devices, emulated, for a launch layout of driver processes on a machine without the hardware
(the pool-day test, docs/deployment.md §9).

Each driver process of the launch layout opens its device as on the vehicle: the DVL-75 and Ping1D drivers a serial
port (here a pseudo-terminal behind a stable symlink, :class:`~hindrax_common.transport.pty_device.PtyDevice`, so
the real pyserial path runs), the MS5837, ICM-20948 and PCA9685 drivers ``/dev/i2c-N`` (here one
:class:`~hindrax_common.transport.emulated_i2c.EmulatedI2CBus` holding the register-exact emulators, served over a
Unix socket by :class:`~hindrax_common.transport.socket_i2c.I2CSocketServer`; a driver process reaches it through
the environment variable in :meth:`EmulatedDevices.env`). What a pool day does to the devices is a method here:
:meth:`unplug` / :meth:`replug` a USB-serial adapter (the port's symlink disappears and comes back on a new pty, as
udev's ``/dev/hindrax-dvl``), :meth:`stop_i2c` / :meth:`start_i2c` the bus (absent at start, or gone mid-run).

The truth is a vehicle holding station in the pool, moving a little so that no driver's stuck-value detection
trips on bit-identical readings: depth 1.0 m +/- 2 cm, altitude 1.5 m +/- 2 cm (DVL and Ping agree), surge
velocity +/- 1 cm/s, level attitude, gravity and the Earth's field on the IMU, with periods of a few seconds.
It is not a simulation (no thrust, no dynamics): the virtual pool is ``hindrax bringup --sim``."""
from __future__ import annotations

import abc
import math
import os
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

from hindrax_common.base.devices import DEVICES, I2C, SERIAL, load, settings
from hindrax_common.config import VehicleConfig
from hindrax_drivers.dvl75.emulator import DvlTruth
from hindrax_drivers.ping1d.emulator import Ping1dTruth
from hindrax_common.process.scheduling import HARDWARE_STAND_IN_PRIORITY
from hindrax_common.transport.emulated_i2c import EmulatedI2CBus
from hindrax_common.transport.pty_device import PtyDevice
from hindrax_common.transport.socket_i2c import SOCKET_ENV, I2CSocketServer

__all__ = ["EmulatedDevices", "DriverEndpoints", "SERIAL_DEVICES", "I2C_DEVICES"]

#: launch-file node name -> configuration section of its serial port
SERIAL_DEVICES = {d.node: d.section for d in DEVICES if d.transport == SERIAL}
#: launch-file node names of the drivers on the I2C bus (the output guard silences the PCA9685 over it)
I2C_DEVICES = tuple(d.node for d in DEVICES if d.transport == I2C) + ("output_guard",)

_DEPTH_M, _ALTITUDE_M, _WOBBLE_M = 1.0, 1.5, 0.02
_SURFACE_PA, _RHO_KG_M3, _G_M_S2 = 101325.0, 1000.0, 9.80665
_EARTH_FIELD_T = (2.0e-5, 0.0, 4.0e-5)


class DriverEndpoints(abc.ABC):
    """Where the driver processes of a launch layout find emulated devices: :attr:`ports` (launch node name -> serial
    port path) and :attr:`socket_path` (the emulated I2C bus's socket). A context manager that calls :meth:`close`.
    Shared by :class:`EmulatedDevices` and the live pool's client (:class:`hindrax_sim.live_pool.LivePool`)."""

    ports: dict[str, str]
    socket_path: str

    def ros_arguments(self, name: str) -> list[str]:
        """Extra ``--ros-args`` for the driver process of launch node ``name``: its serial port as
        the ``sensors.<device>.port`` parameter; [] for a node without one."""
        if name in SERIAL_DEVICES and name in self.ports:
            return ["-p", f"{SERIAL_DEVICES[name]}.port:={self.ports[name]}"]
        return []

    def env(self, name: str) -> dict[str, str]:
        """Extra environment for the driver process of launch node ``name``: the emulated I2C bus's socket
        (:data:`~hindrax_common.transport.socket_i2c.SOCKET_ENV`) for a node on the bus, else {}."""
        return {SOCKET_ENV: self.socket_path} if name in I2C_DEVICES else {}

    @abc.abstractmethod
    def close(self) -> None:
        """Stop serving the devices."""

    def __enter__(self) -> Any:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


def _wobble(t_s: float, period_s: float, amplitude: float) -> float:
    return amplitude * math.sin(2.0 * math.pi * t_s / period_s)


class EmulatedDevices(DriverEndpoints):
    """The five emulated devices (module docstring), serving as soon as constructed unless ``serve_i2c`` is False.

    Each device of :data:`~.devices.DEVICES` comes from its table's factory on the truth ``_<name>_truth``:
    :attr:`emulators` by device name; the serial ones behind :attr:`serial` (node -> pty), the I2C ones on :attr:`bus`.

    config: the vehicle configuration (I2C addresses, PCA9685 oscillator). directory: where the I2C socket goes
    (default: a new temporary directory). Use as a context manager or call :meth:`close`. The threads that serve the
    devices run ``SCHED_FIFO`` :data:`~hindrax_common.process.scheduling.HARDWARE_STAND_IN_PRIORITY`, above the
    vehicle's processes, and the rest of the process keeps its scheduling (refused without ``CAP_SYS_NICE``: they keep
    it too)."""

    def __init__(self, config: VehicleConfig, directory: str | os.PathLike | None = None,
                 serve_i2c: bool = True, poll_period_s: float = 0.05) -> None:
        self.directory = Path(directory or tempfile.mkdtemp(prefix="hindrax-devices-"))
        self.directory.mkdir(parents=True, exist_ok=True)
        self.socket_path = str(self.directory / "i2c.sock")
        self.emulators = {d.name: load(d.emulator)(config, getattr(self, f"_{d.name}_truth", None), time.monotonic)
                          for d in DEVICES}
        self.serial = {d.node: PtyDevice(self.emulators[d.name], poll_period_s=poll_period_s, link_name=d.name,
                                         realtime_priority=HARDWARE_STAND_IN_PRIORITY)
                       for d in DEVICES if d.transport == SERIAL}
        self.bus = EmulatedI2CBus({int(settings(config, d).i2c_address): self.emulators[d.name]
                                   for d in DEVICES if d.transport == I2C})
        self._server: I2CSocketServer | None = None
        self._lock = threading.Lock()
        if serve_i2c:
            self.start_i2c()

    # -- what the driver processes need (with DriverEndpoints' ros_arguments, env) -------------
    @property
    def ports(self) -> dict[str, str]:
        """Node name -> serial port path (stable across :meth:`unplug` / :meth:`replug`)."""
        return {name: dev.path for name, dev in self.serial.items()}

    # -- a pool day ---------------------------------------------------------------------------------
    def unplug(self, name: str) -> None:
        """The USB-serial adapter of ``name`` (``dvl75`` or ``ping1d``) is pulled out."""
        self.serial[name].disconnect()

    def replug(self, name: str) -> None:
        """... and plugged in again (a new tty behind the same path)."""
        self.serial[name].reconnect()

    def start_i2c(self) -> None:
        """The I2C bus is there (idempotent)."""
        with self._lock:
            if self._server is None:
                if os.path.exists(self.socket_path):
                    os.unlink(self.socket_path)
                self._server = I2CSocketServer(self.bus, self.socket_path, realtime_priority=HARDWARE_STAND_IN_PRIORITY)

    def stop_i2c(self) -> None:
        """The I2C bus is gone: opening fails, open connections fail with ENODEV (idempotent)."""
        with self._lock:
            server, self._server = self._server, None
        if server is not None:
            server.close()

    def close(self) -> None:
        """Stop serving everything and remove the pseudo-terminals."""
        self.stop_i2c()
        for dev in self.serial.values():
            dev.close()

    # -- truth: a vehicle holding station, at the emulators' clock t_s (time.monotonic), s -----------------------
    def _dvl75_truth(self, t_s: float) -> DvlTruth:
        return DvlTruth(velocity_frd_m_s=(_wobble(t_s, 7.0, 0.01), 0.0, 0.0),
                        altitude_m=self._ping1d_truth(t_s).altitude_m)

    def _ping1d_truth(self, t_s: float) -> Ping1dTruth:
        return Ping1dTruth(altitude_m=_ALTITUDE_M + _wobble(t_s, 5.0, _WOBBLE_M))

    def _ms5837_truth(self, t_s: float) -> tuple[float, float]:
        depth_m = _DEPTH_M + _wobble(t_s, 4.0, _WOBBLE_M)
        return (_SURFACE_PA + _RHO_KG_M3 * _G_M_S2 * depth_m, 20.0)

    def _icm20948_truth(self, t_s: float):
        w = _wobble(t_s, 3.0, 0.05)
        return ((w, 0.0, _G_M_S2), (0.0, 0.0, 0.01 * w), _EARTH_FIELD_T, 20.0)
