"""MS5837 pressure-sensor node (TE MS5837-30BA / -02BA on I2C at 0x76; docs/devices.md §3): the I2C cycle and the
messages; what a reading means (PROM and ADC checks, stamps, depth, variances, plausibility, zero depth) is
:mod:`hindrax_drivers.ms5837.core`, the start-up's retry and the ERROR ``stuck`` :mod:`~.i2c_node`.

Start-up: reset command 0x1E, 10 ms, the 8 PROM words. Cycle, every 1 / ``sensors.ms5837.rate_hz`` s from ROS timers
(no sleep in any callback): convert D1, wait the OSR's conversion time + :data:`CONVERSION_MARGIN_S`, ADC read; the
same for D2; compensate (second order); publish. A rejected ADC word or an I2C failure abandons that cycle only
(counted); :data:`FAILED_CYCLES_FOR_ERROR` in a row are an ERROR and rerun the start-up (a part that lost power needs
the reset to reload its PROM). A cycle still running when the next is due is skipped (``cycle_overrun``).

Publishes (reliable, depth 10): ``pressure/fluid_pressure`` (Pa, frame ``pressure_link``, the port at
``sensors.ms5837.position_frd_m``), ``pressure/temperature`` (degC), ``pressure/depth``
geometry_msgs/PoseWithCovarianceStamped (frame ``odom``, ``position.z = -depth_m`` of the port; docs/architecture.md
§3), ``raw/ms5837`` (a cycle's I2C transactions in one message), ``/diagnostics``. Service ``pressure/zero_depth``
(std_srvs/Trigger): the surface pressure becomes the mean of the last second, also in the node's
``environment.surface_pressure_pa`` parameter; it and a change of that parameter are refused while the ESC reports armed
or has not reported (:class:`hindrax_common.node_support.esc_state.ArmedWatch`), with the same reason; a change of the
parameter also passes zero_depth's checks: at the surface, and within ``sensors.ms5837.zero_depth_margin_pa`` of the
mean reading (:meth:`~hindrax_drivers.ms5837.core.ZeroDepth.check_value`). Run alone:
``python -m hindrax_drivers.ms5837.node --ros-args --params-file ros_ws/config/hindrax.yaml``."""
from __future__ import annotations

from typing import Any

from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import PoseWithCovarianceStamped
from rclpy.duration import Duration
from rclpy.parameter import Parameter
from sensor_msgs.msg import FluidPressure, Temperature
from std_msgs.msg import Header
from std_srvs.srv import Trigger

from hindrax_common.node_support.esc_state import ArmedWatch
from hindrax_common.node_support.i2c_node import I2cSensorNode
from hindrax_common.node_support.node_common import declare_frame_ids, load_node_config, run_node
from hindrax_common.transport.i2c import I2CDevice, I2CError
from . import protocol as p
from .core import (TEMPERATURE_RESOLUTION_C, DepthGate, Plausibility, ZeroDepth, adc_problem, check_prom,
                   depth_covariance, diagnostic_values, pressure_variance_pa2, stamp_offset_s, temperature_warning)

__all__ = ["Ms5837Node", "main"]

#: Added to the conversion time before the ADC read, s (timer jitter is always late, never early).
CONVERSION_MARGIN_S = 0.0005
#: Consecutive failed cycles after which the device state turns to ERROR and the start-up (reset, PROM) reruns.
FAILED_CYCLES_FOR_ERROR = 3
#: Frame of the pressure and temperature messages (the pressure port).
SENSOR_FRAME_ID = "pressure_link"
#: Frame of the depth pose (REP-105 odom, ENU, z up, 0 at the water surface).
DEPTH_FRAME_ID = "odom"


class Ms5837Node(I2cSensorNode):
    """MS5837 driver node (module docstring). bus: an ``smbus2.SMBus``-like object (default
    ``smbus2.SMBus(sensors.ms5837.i2c_bus)``); kwargs go to :class:`rclpy.node.Node` (``context``,
    ``parameter_overrides``...). Raises ConfigError for an invalid configuration (one line: key, value, range)."""

    label = "MS5837"

    def __init__(self, bus: Any = None, **kwargs: Any):
        super().__init__("ms5837", **kwargs)
        self.frames = declare_frame_ids(self, {"frame_id": SENSOR_FRAME_ID, "depth_frame_id": DEPTH_FRAME_ID})
        #: the ESC's armed flag (latched: the current state arrives on matching): zero_depth and a change of the
        #: surface pressure, the one key applied while running (hindrax zero_depth, ros2 param set), need it disarmed
        self.armed = ArmedWatch(lambda: self.diag.count("esc_state_malformed"))
        cfg = load_node_config(self, ("sensors.ms5837", "environment"), dynamic=("environment.surface_pressure_pa",),
                               on_change=self._on_vehicle_parameters, locked=self.armed.refusal)
        s = cfg.sensors.ms5837
        self.osr = int(s.oversampling)
        self.rate_hz = float(s.rate_hz)
        self.configured_variant = p.parse_variant(s.variant)
        self.water_density_kg_m3 = float(cfg.environment.water_density_kg_m3)
        self.gravity_m_s2 = float(cfg.environment.gravity_m_s2)
        self.surface_pressure_pa = float(cfg.environment.surface_pressure_pa)
        #: zero_depth's window and checks; its atmospheric reference is the start-up surface pressure, fixed
        self.zero = ZeroDepth(self.surface_pressure_pa, s.zero_depth_margin_pa,
                              self.water_density_kg_m3 * self.gravity_m_s2)
        self.conversion_wait_s = p.conversion_time_s(self.osr) + CONVERSION_MARGIN_S
        # a depth baseline is "recent" for 5 cycles at sensors.ms5837.rate_hz
        self.plausibility = Plausibility(s.min_pressure_pa, s.max_pressure_pa, DepthGate(
            s.min_depth_m, s.max_depth_m, s.max_depth_rate_m_s, max_age_s=5.0 / float(s.rate_hz)))
        self.prom_reject_blank_words = bool(s.prom_reject_blank_words)

        self.device: I2CDevice | None = None  # made at the first start-up (open_device)
        self.calibration: p.Calibration | None = None
        self.variant: p.Variant | None = None
        self.setup_device("ms5837", s.i2c_bus, s.i2c_address, bus, self.rate_hz)
        self.cycles = 0
        self._failed_cycles = 0
        self._phase = "idle"  # idle | d1 | d2
        self._d1: int | None = None
        self._d1_stamp = None  # time of validity of the pressure of the running cycle

        self.pub_pressure = self.sensor_publisher(FluidPressure, "pressure/fluid_pressure")
        self.pub_temperature = self.sensor_publisher(Temperature, "pressure/temperature")
        self.pub_depth = self.sensor_publisher(PoseWithCovarianceStamped, "pressure/depth")
        self.create_service(Trigger, "pressure/zero_depth", self.on_zero_depth)
        self.armed.subscribe(self)
        self.periodic = self.create_timer(1.0 / self.rate_hz, self._start_cycle, autostart=False)  # ROS time

        if 2.0 * self.conversion_wait_s >= 1.0 / self.rate_hz:
            self.get_logger().warn(f"sensors.ms5837.rate_hz = {self.rate_hz:g} Hz is not reachable with OSR "
                                   f"{self.osr}: two conversions take {2e3 * self.conversion_wait_s:.1f} ms; cycles "
                                   "will be skipped")

    def _start(self) -> None:
        """Open the bus if needed, send the reset command, read the PROM after RESET_TIME_S."""
        self._phase = "idle"
        if self.open_device("ms5837") is None:
            return
        self.diag.set_state("starting", DiagnosticStatus.WARN, "reset and PROM read")
        try:
            self.device.write_byte(p.CMD_RESET)
        except I2CError as exc:
            self.diag.count("i2c_failure")
            self._fail(f"reset command failed: {exc}")
            return
        self._after.schedule(p.RESET_TIME_S, self._read_prom)

    def _read_prom(self) -> None:
        """Read the 8 PROM words, check the CRC-4, pick the variant; start the cycle timer."""
        try:
            words = [p.parse_prom_word(self.device.read_block(p.prom_read_command(k), 2)) for k in range(8)]
            calibration, variant = check_prom(words, self.prom_reject_blank_words, self.configured_variant)
        except I2CError as exc:
            self.diag.count("i2c_failure")
            self._fail(f"PROM read failed: {exc}")
            return
        except p.Ms5837Error as exc:
            self.diag.count("prom_error")
            self._fail(f"PROM rejected: {exc}")
            return
        self.calibration, self.variant = calibration, variant
        self.pressure_variance_pa2 = pressure_variance_pa2(variant)
        self.diag.set_state("running", DiagnosticStatus.OK, f"MS5837-{variant.value} running")
        self.get_logger().info(f"MS5837-{variant.value} ready (C1..C6 = {list(calibration.words[1:7])}, "
                               f"OSR {self.osr}, {self.rate_hz:g} Hz)")
        self.periodic.reset()

    def _start_cycle(self) -> None:
        """Periodic: issue the D1 (pressure) conversion."""
        if self._phase != "idle":
            self.diag.count("cycle_overrun")
            return
        commanded = self.get_clock().now()
        self.raw.begin_batch()  # raw/ms5837: the cycle's four transactions in one message
        try:
            self.device.write_byte(p.convert_d1_command(self.osr))
        except I2CError as exc:
            self._cycle_failed("i2c_failure", exc)
            return
        self._d1_stamp = commanded + Duration(nanoseconds=int(1e9 * stamp_offset_s(self.osr)))
        self._phase = "d1"
        self._after.schedule(self.conversion_wait_s, self._read_d1)

    def _read_adc(self) -> int | None:
        """ADC read (0x00 + 3 bytes); None (cycle abandoned, counted) on an I2C failure, a 0 or a saturated
        (0xFFFFFF) result."""
        try:
            data = self.device.read_block(p.CMD_ADC_READ, 3)
        except I2CError as exc:
            self._cycle_failed("i2c_failure", exc)
            return None
        kind, text = adc_problem(data)
        if kind:
            self._cycle_failed(kind, text)
            return None
        return p.parse_adc(data)

    def _read_d1(self) -> None:
        self._d1 = self._read_adc()
        if self._d1 is None:
            return
        try:
            self.device.write_byte(p.convert_d2_command(self.osr))
        except I2CError as exc:
            self._cycle_failed("i2c_failure", exc)
            return
        self._phase = "d2"
        self._after.schedule(self.conversion_wait_s, self._read_d2)

    def _read_d2(self) -> None:
        d2 = self._read_adc()
        if d2 is None:
            return
        self._phase = "idle"
        reading = p.compensate(self._d1, d2, self.calibration, self.variant, apply_second_order=True)
        self.cycles, self._failed_cycles = self.cycles + 1, 0
        if self.diag.state != "running":
            self.diag.set_state("running", DiagnosticStatus.OK, f"MS5837-{self.variant.value} running")
        if self.stuck_reading((self._d1, d2), f"identical D1/D2 ({self._d1}, {d2})"):
            return
        depth_m = self.depth_m(reading.pressure_pa)
        verdict = self.plausibility.check(self._now_s(), reading.pressure_pa, depth_m, f"D1 = {self._d1}, D2 = {d2}")
        if not verdict.publish:
            self.diag.count(verdict.counter)
            self.diag.error("implausible", verdict.error)
            self.get_logger().error(f"MS5837: {verdict.error}", throttle_duration_sec=5.0)
            if verdict.first:
                self.diagnostics.publish()
            return
        if verdict.clear:
            self.diag.clear("implausible")
        warning = temperature_warning(reading)
        self.diag.warn("temperature_range", warning) if warning else self.diag.clear("temperature_range")
        self._publish(reading, depth_m, self._d1_stamp)
        self.raw.flush()

    def _cycle_failed(self, kind: str, exc: Exception | str) -> None:
        self.plausibility.invalid()
        self._phase = "idle"
        self.raw.flush()
        self.diag.count(kind)
        self._failed_cycles += 1
        self.get_logger().warn(f"MS5837 cycle abandoned ({kind}): {exc}", throttle_duration_sec=5.0)
        if self._failed_cycles >= FAILED_CYCLES_FOR_ERROR:
            text = f"{self._failed_cycles} consecutive failed cycles: {exc}; reset and PROM read again"
            self.diag.set_state("i2c error", DiagnosticStatus.ERROR, text)
            self.get_logger().error(f"MS5837: {text}", throttle_duration_sec=5.0)
            self._failed_cycles = 0
            self.diag.count("restarts")
            self._start()

    def depth_m(self, pressure_pa: float) -> float:
        """Depth of the pressure port below the surface, m (docs/devices.md §3.6, configured rho, g, P_surface)."""
        return p.depth_m(pressure_pa, self.water_density_kg_m3, self.surface_pressure_pa, self.gravity_m_s2)

    def _publish(self, reading: p.Reading, depth_m: float, stamp) -> None:
        stamp_msg = stamp.to_msg()
        port, odom = (Header(stamp=stamp_msg, frame_id=self.frames[k]) for k in ("frame_id", "depth_frame_id"))
        self.zero.add(stamp.nanoseconds * 1e-9, reading.pressure_pa)
        self.pub_pressure.publish(FluidPressure(header=port, fluid_pressure=reading.pressure_pa,
                                                variance=self.pressure_variance_pa2))
        self.pub_temperature.publish(Temperature(header=port, temperature=reading.temperature_c,
                                                 variance=TEMPERATURE_RESOLUTION_C ** 2))
        depth = PoseWithCovarianceStamped(header=odom)
        depth.pose.pose.position.z = -depth_m
        depth.pose.covariance = depth_covariance(self.pressure_variance_pa2, self.zero.rho_g)
        self.pub_depth.publish(depth)
        self.diag.published()

    def _on_vehicle_parameters(self, cfg) -> None:
        """Apply a validated change of ``environment.surface_pressure_pa`` (this node's one writable key), checked as
        ``pressure/zero_depth`` is (:meth:`~hindrax_drivers.ms5837.core.ZeroDepth.check_value`); raises ValueError
        with the reason when refused."""
        value = float(cfg.environment.surface_pressure_pa)
        why = "" if value == self.surface_pressure_pa else self.zero.check_value(value, self.armed.refusal())
        if why:
            raise ValueError(why)
        self.surface_pressure_pa = value

    def on_zero_depth(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        """Set the surface pressure to the mean pressure of the last second, unless
        :meth:`~hindrax_drivers.ms5837.core.ZeroDepth.decide` refuses (with the ESC's arm lock)."""
        mean_pa, response.message = self.zero.decide(self.armed.refusal())
        response.success = mean_pa is not None
        if mean_pa is None:
            if self.zero.recent:
                self.diag.count("zero_depth_refused")
                self.get_logger().warn(f"pressure/zero_depth {response.message}")
            return response
        old, self.surface_pressure_pa = self.surface_pressure_pa, mean_pa
        try:
            self.set_parameters([Parameter("environment.surface_pressure_pa", value=self.surface_pressure_pa)])
        except Exception as exc:  # noqa: BLE001 - the parameter mirror is informative only
            self.get_logger().warn(f"could not update environment.surface_pressure_pa parameter: {exc}")
        response.message = (f"surface pressure set to {self.surface_pressure_pa:.1f} Pa (was {old:.1f} Pa), "
                            f"mean of {len(self.zero.recent)} readings")
        self.get_logger().info(response.message)
        return response

    def _diag_extra(self):
        return diagnostic_values(self.variant, self.configured_variant, self.osr, self.conversion_wait_s,
                                 self.surface_pressure_pa, self.cycles, self.startup_attempts, self.calibration) + (
            self.device.stats.diagnostics() if self.device is not None else [])


def main(args=None) -> int:
    """``python -m hindrax_drivers.ms5837.node --ros-args --params-file ros_ws/config/hindrax.yaml`` (Pi)."""
    return run_node(Ms5837Node, args)


if __name__ == "__main__":
    raise SystemExit(main())
