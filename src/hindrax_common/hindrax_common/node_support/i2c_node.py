"""The base of the I2C sensor nodes (MS5837, ICM-20948): bus, raw tap, diagnostics with the ERROR ``stuck``, the
one-shot timer of the waits, and the start-up's failure path (ERROR with the reason, the bus closed, the start-up
retried every :data:`RETRY_PERIOD_S`). A subclass calls :meth:`I2cSensorNode.setup_device` after its configuration,
implements ``_start`` (beginning with :meth:`~I2cSensorNode.open_device`) and ``_diag_extra``, and keeps its
periodic timer in ``periodic``."""
from __future__ import annotations

from typing import Any

from diagnostic_msgs.msg import DiagnosticStatus

from .node_common import (DEFAULT_QOS_DEPTH, DeviceDiagnostics, DiagnosticsPublisher, OneShot, RawDataPublisher,
                          StuckAlarm)
from ..transport.i2c import BusHandle, I2CDevice
from .vehicle_node import VehicleNode

__all__ = ["I2cSensorNode", "RETRY_PERIOD_S", "STUCK_AFTER_S"]

#: Wait between start-up attempts after a failure (wrong identity, bad PROM, bus error, bus not openable), s.
RETRY_PERIOD_S = 1.0
#: Bit-identical raw readings for this long (at least 3 readings) raise the ERROR ``stuck``, s.
STUCK_AFTER_S = 2.0


class I2cSensorNode(VehicleNode):
    """rclpy Node of one I2C sensor (module docstring). ``label`` names the part in the log ("MS5837")."""

    label = "I2C device"

    def setup_device(self, device_name: str, i2c_bus: int, address: int, bus: Any, rate_hz: float) -> None:
        """Bus (``bus`` injected, else ``smbus2.SMBus(i2c_bus)`` opened at start-up), ``raw/<device_name>``,
        diagnostics ``hindrax/<device_name>``, the ERROR ``stuck`` after :data:`STUCK_AFTER_S` of identical readings
        at ``rate_hz``; the first start-up from the executor, not the constructor."""
        self.i2c_bus_number, self.address = int(i2c_bus), int(address)
        self._bus = BusHandle(self.i2c_bus_number, bus)  # reopened after a failed start-up when owned
        self.raw = RawDataPublisher(self, device_name)
        self.diag = DeviceDiagnostics(f"hindrax/{device_name}", f"i2c-{self.i2c_bus_number}@0x{self.address:02x}",
                                      self._now_s)
        self.stuck = StuckAlarm(max(3, round(STUCK_AFTER_S * rate_hz)), self.diag)
        self.diagnostics = DiagnosticsPublisher(self, [self.diag], extra=self._diag_extra)
        self.startup_attempts = 0
        self.periodic = None  # the subclass's cycle or poll timer
        self._after = OneShot(self)
        self._after.schedule(0.0, self._start)

    @property
    def is_stuck(self) -> bool:
        """The ERROR ``stuck`` is raised."""
        return self.stuck.stuck

    def sensor_publisher(self, msg_type: Any, topic: str) -> Any:
        """A reliable publisher (depth 10; no QoS event handlers, :class:`VehicleNode`)."""
        return self.create_publisher(msg_type, topic, DEFAULT_QOS_DEPTH)

    def alarm(self, key: str, text: str, counter: str = "") -> None:
        """Raise the ERROR ``key`` with ``text`` (counted ``counter`` if given), logged and published at once."""
        self.diag.error(key, text)
        if counter:
            self.diag.count(counter)
        self.get_logger().error(f"{self.label} {text}")
        self.diagnostics.publish()

    def stuck_reading(self, value: Any, text: str) -> bool:
        """Feed one raw reading to the ERROR ``stuck`` (``text``: what is identical); True while stuck."""
        if self.stuck.update(value, text) and self.stuck.raised:
            self.get_logger().error(f"{self.label} stuck: {text} for {self.stuck.limit} readings: not published")
            self.diagnostics.publish()
        return self.stuck.stuck

    def _now_s(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def open_device(self, name: str) -> Any:
        """Begin a start-up attempt (counted, the periodic timer stopped): the bus (the same, or opened afresh after a
        failed attempt) and ``self.device`` on it (no backoff: no sleep in a callback; its counters kept across
        reopened buses), or None after :meth:`_fail` when the bus cannot be opened."""
        self.startup_attempts += 1
        if self.periodic is not None:
            self.periodic.cancel()
        try:
            bus = self._bus.get()
        except (OSError, ImportError) as exc:
            return self._fail(str(exc))
        if getattr(self, "device", None) is None:
            self.device = I2CDevice(bus, self.address, name, backoff_s=0.0, raw_tap=self.raw.i2c_tap)
        self.device.bus = bus
        return self.device

    def _fail(self, reason: str) -> None:
        """Start-up failed: ERROR state with the reason, the bus closed, another attempt after RETRY_PERIOD_S."""
        self.diag.set_state("error", DiagnosticStatus.ERROR, f"{reason}; retrying every {RETRY_PERIOD_S:g} s")
        self.get_logger().error(f"{self.label} start-up failed: {reason}", throttle_duration_sec=10.0)
        self._bus.reset()
        self._after.schedule(RETRY_PERIOD_S, self._start)

    def close(self) -> None:
        """Stop the timers and close the bus if this node opened it (run_node calls this on shutdown)."""
        if self.periodic is not None:
            self.periodic.cancel()
        self._after.cancel()
        self._bus.close()
