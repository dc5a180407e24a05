"""MS5837 pressure-sensor node (TE MS5837-30BA / -02BA on I2C, address 0x76; docs/devices.md §3).

Start-up (docs/devices.md §3.1-3.3, §3.9):

1. Reset command 0x1E, then wait :data:`~hindrax_drivers.ms5837.protocol.RESET_TIME_S` (10 ms).
2. Read the 8 PROM words (0xA0 + 2k, 2 bytes MSB first) and check the CRC-4 and, when
   ``sensors.ms5837.prom_reject_blank_words`` is true, the PROM sanity
   (:func:`~hindrax_drivers.ms5837.protocol.prom_sanity_issue`: no coefficient 0x0000/0xFFFF; an all-zero
   PROM passes CRC-4). A bad CRC or PROM (or an I2C
   failure, or a C1 outside the heuristic's range with ``variant: auto``) stops start-up: the device
   state goes to ERROR with the reason in ``/diagnostics`` and the log, and the whole start-up is
   retried every :data:`RETRY_PERIOD_S` seconds. The node never crashes on it.
3. Variant: ``sensors.ms5837.variant`` (``30BA`` / ``02BA``), or ``auto`` for Blue Robotics' C1
   heuristic (docs/devices.md §3.9), reported in the diagnostics.

Measurement cycle, every 1 / ``sensors.ms5837.rate_hz`` seconds, as a state machine driven by ROS timers
so that the executor is never blocked (no sleep in any callback):
``convert D1 (OSR)`` -> one-shot timer (conversion time of the OSR + :data:`CONVERSION_MARGIN_S`) ->
``ADC read (D1)`` -> ``convert D2 (OSR)`` -> one-shot timer -> ``ADC read (D2)`` -> compensate -> publish.
Conversion times are TE's library waits (docs/devices.md §3.1,
:data:`~hindrax_drivers.ms5837.protocol.CONVERSION_TIME_S`; the datasheet table is UNVERIFIED). Compensation is the
datasheet's first- and second-order integer arithmetic with floor semantics
(:func:`hindrax_drivers.ms5837.protocol.compensate`, docs/devices.md §3.4-3.7). An ADC read of 0 (no completed
conversion, docs/devices.md §3.1), a saturated ADC read (0xFFFFFF: a bus held high or a broken bridge; no reading in the
sensor's range comes near it) or an I2C failure after the transport's retries abandons that cycle only (counted in the
diagnostics: ``adc_zero``, ``adc_saturated``,
``i2c_failure``); the next cycle starts afresh. After :data:`FAILED_CYCLES_FOR_ERROR` consecutive failed
cycles the state turns to ERROR and the whole start-up (reset command, PROM read) runs again: a part
that lost power during an I2C outage needs the reset to reload its PROM (datasheet "Reset sequence"). The
transport retries at once (``backoff_s = 0``), so even a failing bus never sleeps inside a callback. A cycle that
is still running when the next one is due is skipped (``cycle_overrun``): with OSR 8192 two conversions
take 34 ms, so rates above ~28 Hz are not reachable and a warning is logged at start-up.

Publishes (reliable, depth 10):

- ``pressure/fluid_pressure`` sensor_msgs/FluidPressure: absolute pressure, Pa; ``variance`` =
  resolution^2 + LSB^2/12 (:func:`pressure_variance_pa2`), frame ``pressure_link`` (the pressure port,
  at ``sensors.ms5837.position_frd_m`` from the CG).
- ``pressure/temperature`` sensor_msgs/Temperature: degC, variance = (0.01 degC)^2 (output resolution).
- ``pressure/depth`` geometry_msgs/PoseWithCovarianceStamped (chosen over std_msgs/Float64 because it
  carries a stamp, a frame and a variance, which a depth filter needs; docs/architecture.md §3): frame ``odom``
  (REP-105, ENU, z up), ``position.z = -depth_m`` of the pressure port, where depth_m =
  (P - surface_pressure_pa) / (water_density_kg_m3 * gravity_m_s2) (docs/devices.md §3.6) with the
  ``environment.*`` values of the configuration; ``covariance[14]`` (z, z) = variance_P / (rho g)^2.
  x, y and the orientation are not measured: their diagonal variances are :data:`UNKNOWN_VARIANCE`
  (1e6), off-diagonals 0, orientation the identity. Correcting the port depth to base_link needs the
  attitude and the lever arm ``sensors.ms5837.position_frd_m``; that is the state estimator's job.
- ``raw/ms5837`` hindrax_msgs/RawDeviceData: every I2C transaction (command bytes and ADC/PROM reads); the
  four of a measurement cycle in one message (:class:`~hindrax_drivers.node_common.RawDataPublisher` batch).
- ``/diagnostics``: state, rate, last message age, I2C transactions/errors/retries/failures, ADC zero
  reads, saturated reads, cycle overruns, restarts, variant, OSR, surface pressure, the ERRORs ``stuck`` and
  ``implausible``.

Service ``pressure/zero_depth`` (std_srvs/Trigger): sets the surface pressure to the mean of the
pressures of the last :data:`ZERO_DEPTH_WINDOW_S` seconds (run it with the vehicle at the surface);
the value is also written to the node's ``environment.surface_pressure_pa`` parameter (not to the file). Setting that
parameter (``ros2 param set``) is refused in the same ESC states as the service, with the same reason.
Refused (``success`` false, the reason in ``message``, surface pressure unchanged) while the ESC reports armed
(``esc/output_state``, latched, :mod:`hindrax_drivers.esc_state`: the last state received says armed, an output
state that became unknown while armed counts as armed, and a dead ESC's last state stays), before any ESC state has
arrived (nothing says the thrusters are off: fail closed), and when that mean is further than
``sensors.ms5837.zero_depth_margin_pa`` from the atmospheric reference, the ``environment.surface_pressure_pa`` the
node started with: a zero taken at 1.5 m would move every depth, and the
depth limits with it, 1.5 m down.

Time stamps: the device has no clock, so every message is stamped with the time of validity of its
pressure: the ROS time (``use_sim_time`` supported) at which the D1 conversion was commanded plus half the
OSR's conversion time (4.5 ms at OSR 4096), the middle of the interval over which the ADC integrates the
pressure (docs/devices.md §3.1). The read time is later by at least the full conversion wait plus the timer's
latency; for a depth rate of 0.3 m/s in a heave test, 10 ms of stamp error is 3 mm of depth, which biases the
identified heave inertia and damping.

Plausibility (ERROR ``implausible`` in the diagnostics, held :data:`IMPLAUSIBLE_HOLD_S` after the last
rejection; nothing is published for that cycle, counted ``implausible_pressure``): a compensated pressure
outside [``sensors.ms5837.min_pressure_pa``, ``max_pressure_pa``] of the vehicle file; then, after the conversion
to depth, :class:`DepthGate`: a depth outside [``sensors.ms5837.min_depth_m``, ``max_depth_m``], or one that moved
faster than ``max_depth_rate_m_s`` from the last published depth and is not confirmed by the next sample (counted
``implausible_depth``). Garbage ADC words (a bus returning noise, not errors) pass the pressure window in about
4.5 % of random pairs; the rate gate needs two consecutive garbage depths to agree, which they almost never do.

A stuck sensor (bit-identical D1 and D2 for :data:`STUCK_AFTER_S` seconds, :class:`StuckDetector`)
raises the ERROR ``stuck`` in the diagnostics and a log error, and its readings are not published until
they change.

The bus is injected: ``smbus2.SMBus(sensors.ms5837.i2c_bus)`` on the Pi (opened at start-up; if it cannot
be opened, or a start-up attempt fails, the node reports it, closes the bus and opens it again at the next
attempt: :class:`~hindrax_drivers.transport.i2c.BusHandle`), an
:class:`~hindrax_drivers.transport.emulated_i2c.EmulatedI2CBus` holding an
:class:`~hindrax_drivers.ms5837.emulator.Ms5837Emulator` in tests and simulation.

Run alone: ``python -m hindrax_drivers.ms5837.node --ros-args --params-file ros_ws/config/hindrax.yaml``.
"""
from __future__ import annotations

import collections
import math
from typing import Any, Callable

from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import PoseWithCovarianceStamped
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import FluidPressure, Temperature
from std_srvs.srv import Trigger

from ..esc_state import ArmedWatch
from ..node_common import (DEFAULT_QOS_DEPTH, DeviceDiagnostics, DiagnosticsPublisher, RawDataPublisher,
                           StuckDetector, declare_frame_ids, load_node_config, run_node)
from ..transport.i2c import BusHandle, I2CDevice, I2CError
from . import protocol as p

__all__ = ["Ms5837Node", "pressure_variance_pa2", "PRESSURE_RESOLUTION_PA", "main"]

#: Wait between start-up attempts after a failure (bad CRC, bus error, bus not openable), s.
RETRY_PERIOD_S = 1.0
#: Added to the conversion time before the ADC read, s (timer jitter is always late, never early).
CONVERSION_MARGIN_S = 0.0005
#: Identical raw readings for this long mean a stuck sensor, s.
STUCK_AFTER_S = 2.0
#: Consecutive failed cycles after which the device state turns to ERROR and the start-up (reset, PROM) reruns.
FAILED_CYCLES_FOR_ERROR = 3
#: The ERROR ``implausible`` stays raised this long after the last rejected reading (ROS time), s.
IMPLAUSIBLE_HOLD_S = 2.0
#: Window of readings averaged by the zero_depth service, s.
ZERO_DEPTH_WINDOW_S = 1.0
#: Variance used for the pose components a depth sensor does not measure (x, y, orientation).
UNKNOWN_VARIANCE = 1.0e6
#: Frame of the pressure and temperature messages (the pressure port).
SENSOR_FRAME_ID = "pressure_link"
#: Frame of the depth pose (REP-105 odom, ENU, z up, 0 at the water surface).
DEPTH_FRAME_ID = "odom"
#: Pressure resolution per variant, Pa: docs/devices.md §3.4 table ("0.25 mbar resolution" 30BA,
#: "0.01 mbar" 02BA). The per-OSR RMS table of the datasheet was not retrieved, so one figure is used
#: for every OSR (it is the figure for the highest OSR; lower OSRs are noisier).
PRESSURE_RESOLUTION_PA = {p.Variant.MS5837_30BA: 25.0, p.Variant.MS5837_02BA: 1.0}
#: Temperature output resolution, degC (TEMP in 0.01 degC, docs/devices.md §3.4).
TEMPERATURE_RESOLUTION_C = 0.01


class DepthGate:
    """Range and rate-of-change gate on the depth after conversion (pure; see the module docstring).

    ``check(t_s, depth_m)`` returns '' to publish, else the reason; ``invalid()`` tells it that a cycle gave no
    reading (rejected earlier, or failed). A depth within ``max_rate_m_s * dt + noise_m`` of the last accepted
    one, accepted at most ``max_age_s`` ago, is accepted; any other in-range depth is held as a candidate and
    accepted when the very next cycle agrees with it (a real jump, e.g. after an outage, costs one sample). Noise
    passes only when two consecutive garbage readings agree. Defaults from the vehicle's physics: Hindrax heaves well
    under 1 m/s.
    """

    def __init__(self, min_depth_m: float, max_depth_m: float, max_rate_m_s: float, noise_m: float = 0.05,
                 max_age_s: float = 0.5) -> None:
        self.min_depth_m, self.max_depth_m = float(min_depth_m), float(max_depth_m)
        self.max_age_s = float(max_age_s)
        self.max_rate_m_s, self.noise_m = float(max_rate_m_s), float(noise_m)
        self._last: tuple[float, float] | None = None
        self._candidate: tuple[float, float] | None = None

    def _agrees(self, ref: tuple[float, float], t_s: float, depth_m: float) -> bool:
        return abs(depth_m - ref[1]) <= self.max_rate_m_s * max(t_s - ref[0], 0.0) + self.noise_m

    def invalid(self) -> None:
        """A cycle without a reading: the next depth cannot confirm a candidate across it."""
        self._candidate = None

    def check(self, t_s: float, depth_m: float) -> str:
        if not math.isfinite(depth_m) or not self.min_depth_m <= depth_m <= self.max_depth_m:
            self._candidate = None
            return (f"depth {depth_m:.2f} m outside sensors.ms5837.min_depth_m..max_depth_m "
                    f"{self.min_depth_m:g}..{self.max_depth_m:g} m")
        if self._last is not None and t_s - self._last[0] <= self.max_age_s and self._agrees(self._last, t_s, depth_m):
            self._last, self._candidate = (t_s, depth_m), None
            return ""
        if self._candidate is not None and self._agrees(self._candidate, t_s, depth_m):
            self._last, self._candidate = (t_s, depth_m), None
            return ""
        if self._last is None:  # the first depth (range-checked) is the baseline
            self._last = (t_s, depth_m)
            return ""
        self._candidate = (t_s, depth_m)
        return (f"depth {depth_m:.2f} m changed faster than sensors.ms5837.max_depth_rate_m_s {self.max_rate_m_s:g} "
                f"since {self._last[1]:.2f} m (held until the next sample confirms it)")


def pressure_variance_pa2(variant: p.Variant) -> float:
    """Variance of one pressure reading, Pa^2: resolution^2 (taken as 1 sigma) + output LSB^2 / 12.

    Output LSB: 10 Pa (30BA, 0.1 mbar) or 1 Pa (02BA, 0.01 mbar) (docs/devices.md §3.4, §3.6).
    """
    lsb_pa = 1.0 / p.pressure_counts_per_pa(variant)
    return PRESSURE_RESOLUTION_PA[p.Variant(variant)] ** 2 + lsb_pa ** 2 / 12.0


class Ms5837Node(Node):
    """MS5837 driver node (see the module docstring).

    Args:
        bus: object with the ``smbus2.SMBus`` interface; default ``smbus2.SMBus(sensors.ms5837.i2c_bus)``.
        **kwargs: passed to :class:`rclpy.node.Node` (``context``, ``parameter_overrides``...).

    Raises:
        ConfigError: invalid configuration (one line naming key, value and range).
    """

    def __init__(self, bus: Any = None, **kwargs: Any):
        super().__init__("ms5837", **kwargs)
        self.frames = declare_frame_ids(self, {"frame_id": SENSOR_FRAME_ID, "depth_frame_id": DEPTH_FRAME_ID})
        #: the ESC's armed flag (latched: the current state arrives on matching): zero_depth and a change of the
        #: surface pressure, the one key applied while running (hindrax zero_depth, ros2 param set), need it disarmed
        self.armed = ArmedWatch(lambda: self.diag.count("esc_state_malformed"))
        cfg = load_node_config(self, ("sensors.ms5837", "environment"), dynamic=("environment.surface_pressure_pa",),
                               on_change=self._on_vehicle_parameters, locked=self.armed.refusal)
        s = cfg.sensors.ms5837
        self.i2c_bus_number = int(s.i2c_bus)
        self.address = int(s.i2c_address)
        self.osr = int(s.oversampling)
        self.rate_hz = float(s.rate_hz)
        self.configured_variant = p.parse_variant(s.variant)
        self.water_density_kg_m3 = float(cfg.environment.water_density_kg_m3)
        self.gravity_m_s2 = float(cfg.environment.gravity_m_s2)
        self.surface_pressure_pa = float(cfg.environment.surface_pressure_pa)
        #: zero_depth's atmospheric reference (Pa) and margin (Pa): the start-up surface pressure, fixed
        self.atmospheric_reference_pa = self.surface_pressure_pa
        self.zero_depth_margin_pa = float(s.zero_depth_margin_pa)
        self.conversion_wait_s = p.conversion_time_s(self.osr) + CONVERSION_MARGIN_S
        self.min_pressure_pa = float(s.min_pressure_pa)
        self.max_pressure_pa = float(s.max_pressure_pa)
        # a baseline is "recent" for 5 cycles at sensors.ms5837.rate_hz
        self.depth_gate = DepthGate(s.min_depth_m, s.max_depth_m, s.max_depth_rate_m_s,
                                    max_age_s=5.0 / float(s.rate_hz))
        self.prom_reject_blank_words = bool(s.prom_reject_blank_words)
        self._last_implausible_s: float | None = None
        self.d1_command = p.convert_d1_command(self.osr)
        self.d2_command = p.convert_d2_command(self.osr)

        self._bus = BusHandle(self.i2c_bus_number, bus)  # reopened after a failed start-up when owned
        self.raw = RawDataPublisher(self, "ms5837")
        self.device: I2CDevice | None = None
        self.calibration: p.Calibration | None = None
        self.variant: p.Variant | None = None
        self.diag = DeviceDiagnostics("hindrax/ms5837", f"i2c-{self.i2c_bus_number}@0x{self.address:02x}",
                                      self._now_s)
        self.stuck = StuckDetector(max(3, round(STUCK_AFTER_S * self.rate_hz)))
        self.is_stuck = False
        self.startup_attempts = 0
        self.cycles = 0
        self._failed_cycles = 0
        self._phase = "idle"  # idle | d1 | d2
        self._d1 = 0
        self._d1_stamp = None  # time of validity of the pressure of the running cycle
        self._recent: collections.deque[tuple[float, float]] = collections.deque()
        self.last_reading: p.Reading | None = None

        qos = DEFAULT_QOS_DEPTH
        self.pub_pressure = self.create_publisher(FluidPressure, "pressure/fluid_pressure", qos)
        self.pub_temperature = self.create_publisher(Temperature, "pressure/temperature", qos)
        self.pub_depth = self.create_publisher(PoseWithCovarianceStamped, "pressure/depth", qos)
        self.create_service(Trigger, "pressure/zero_depth", self.on_zero_depth)
        self.armed.subscribe(self)
        self.diagnostics = DiagnosticsPublisher(self, [self.diag], extra=self._diag_extra)

        # One-shot timer (re-armed with the wanted delay) and the periodic cycle timer, both on ROS time.
        self._step_timer = self.create_timer(1.0, self._on_step_timer, autostart=False)
        self._step: Callable[[], None] | None = None
        self._cycle_timer = self.create_timer(1.0 / self.rate_hz, self._start_cycle, autostart=False)

        cycle_s = 2.0 * self.conversion_wait_s
        if cycle_s >= 1.0 / self.rate_hz:
            self.get_logger().warn(
                f"sensors.ms5837.rate_hz = {self.rate_hz:g} Hz is not reachable with OSR {self.osr}: two "
                f"conversions take {cycle_s * 1e3:.1f} ms; cycles will be skipped")
        self._schedule(0.0, self._start)  # first bus access from the executor, not the constructor

    # ------------------------------------------------------------------ helpers
    def _now_s(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def _schedule(self, delay_s: float, step: Callable[[], None]) -> None:
        """Run ``step`` once after ``delay_s`` of ROS time (the executor stays free meanwhile)."""
        self._step = step
        self._step_timer.timer_period_ns = max(1, int(delay_s * 1e9))
        self._step_timer.reset()

    def _on_step_timer(self) -> None:
        self._step_timer.cancel()
        step, self._step = self._step, None
        if step is not None:
            step()

    # ------------------------------------------------------------------ start-up
    def _start(self) -> None:
        """Open the bus if needed, send the reset command, read the PROM after RESET_TIME_S."""
        self.startup_attempts += 1
        self._cycle_timer.cancel()
        self._phase = "idle"
        try:
            bus = self._bus.get()  # the same bus, or opened afresh after a failed attempt (BusHandle)
        except (OSError, ImportError) as exc:
            self._fail(str(exc))
            return
        if self.device is None:
            self.device = I2CDevice(bus, self.address, "ms5837", backoff_s=0.0, raw_tap=self.raw.i2c_tap)
        self.device.bus = bus  # the device keeps its counters across reopened buses
        self.diag.set_state("starting", DiagnosticStatus.WARN, "reset and PROM read")
        try:
            self.device.write_byte(p.CMD_RESET)
        except I2CError as exc:
            self.diag.count("i2c_failure")
            self._fail(f"reset command failed: {exc}")
            return
        self._schedule(p.RESET_TIME_S, self._read_prom)

    def _read_prom(self) -> None:
        """Read the 8 PROM words, check the CRC-4, pick the variant; start the cycle timer."""
        assert self.device is not None
        try:
            words = [p.parse_prom_word(self.device.read_block(p.prom_read_command(k), 2)) for k in range(8)]
            calibration = p.Calibration.from_words(words, check_crc=True)
            issue = p.prom_sanity_issue(calibration) if self.prom_reject_blank_words else ""
            if issue:
                raise p.Ms5837Error(issue)
            variant = p.detect_variant(calibration, self.configured_variant)
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
        self._cycle_timer.reset()

    def _fail(self, reason: str) -> None:
        """Start-up failed: ERROR state with the reason, retry after RETRY_PERIOD_S."""
        self.diag.set_state("error", DiagnosticStatus.ERROR, f"{reason}; retrying every {RETRY_PERIOD_S:g} s")
        self.get_logger().error(f"MS5837 start-up failed: {reason}", throttle_duration_sec=10.0)
        self._bus.reset()  # the next attempt opens /dev/i2c-N again: a bus that went and came back is picked up
        self._schedule(RETRY_PERIOD_S, self._start)

    # ------------------------------------------------------------------ measurement cycle
    def _start_cycle(self) -> None:
        """Periodic: issue the D1 (pressure) conversion."""
        if self._phase != "idle":
            self.diag.count("cycle_overrun")
            return
        commanded = self.get_clock().now()
        self.raw.begin_batch()  # raw/ms5837: the cycle's four transactions in one message
        try:
            self.device.write_byte(self.d1_command)
        except I2CError as exc:
            self._cycle_failed("i2c_failure", exc)
            return
        self._d1_stamp = commanded + Duration(nanoseconds=int(0.5e9 * p.conversion_time_s(self.osr)))
        self._phase = "d1"
        self._schedule(self.conversion_wait_s, self._read_d1)

    def _read_adc(self) -> int | None:
        """ADC read (0x00 + 3 bytes); None (cycle abandoned, counted) on an I2C failure, a 0 or a saturated
        (0xFFFFFF) result."""
        try:
            value = p.parse_adc(self.device.read_block(p.CMD_ADC_READ, 3))
        except I2CError as exc:
            self._cycle_failed("i2c_failure", exc)
            return None
        except p.Ms5837Error as exc:
            self._cycle_failed("adc_zero", exc)
            return None
        if value >= p.ADC_MAX:
            self._cycle_failed("adc_saturated", p.Ms5837Error("ADC read 0xFFFFFF (saturated): reading rejected"))
            return None
        return value

    def _read_d1(self) -> None:
        d1 = self._read_adc()
        if d1 is None:
            return
        self._d1 = d1
        try:
            self.device.write_byte(self.d2_command)
        except I2CError as exc:
            self._cycle_failed("i2c_failure", exc)
            return
        self._phase = "d2"
        self._schedule(self.conversion_wait_s, self._read_d2)

    def _read_d2(self) -> None:
        d2 = self._read_adc()
        if d2 is None:
            return
        self._phase = "idle"
        reading = p.compensate(self._d1, d2, self.calibration, self.variant, apply_second_order=True)
        self.cycles += 1
        self._failed_cycles = 0
        if self.diag.state != "running":
            self.diag.set_state("running", DiagnosticStatus.OK, f"MS5837-{self.variant.value} running")
        if self._check_stuck(self._d1, d2):
            return  # a stuck sensor's reading is not published (ERROR "stuck")
        now_s = self._now_s()
        if not self.min_pressure_pa <= reading.pressure_pa <= self.max_pressure_pa:
            self.depth_gate.invalid()
            self.diag.count("implausible_pressure")
            text = (f"implausible pressure {reading.pressure_pa:.0f} Pa outside {self.min_pressure_pa:g}.."
                    f"{self.max_pressure_pa:g} Pa (D1 = {self._d1}, D2 = {d2}): not published")
            self.diag.error("implausible", text)
            self.get_logger().error(f"MS5837: {text}", throttle_duration_sec=5.0)
            if self._last_implausible_s is None:
                self.diagnostics.publish()
            self._last_implausible_s = now_s
            return
        depth_reason = self.depth_gate.check(now_s, self.depth_m(reading.pressure_pa))
        if depth_reason:
            self.diag.count("implausible_depth")
            if not depth_reason.startswith("first"):
                self.diag.error("implausible", f"{depth_reason} (D1 = {self._d1}, D2 = {d2}): not published")
                self.get_logger().error(f"MS5837: {depth_reason}", throttle_duration_sec=5.0)
                self._last_implausible_s = now_s
            return
        if self._last_implausible_s is not None and now_s - self._last_implausible_s > IMPLAUSIBLE_HOLD_S:
            self._last_implausible_s = None
            self.diag.clear("implausible")
        if reading.temperature_in_range:
            self.diag.clear("temperature_range")
        else:
            self.diag.warn("temperature_range", f"temperature {reading.temperature_c:.2f} degC outside "
                                                f"{p.TEMPERATURE_MIN_C:g}..{p.TEMPERATURE_MAX_C:g} degC")
        self._publish(reading, self._d1_stamp)
        self.raw.flush()

    def _cycle_failed(self, kind: str, exc: Exception) -> None:
        self.depth_gate.invalid()
        self._phase = "idle"
        self.raw.flush()
        self.diag.count(kind)
        self._failed_cycles += 1
        self.get_logger().warn(f"MS5837 cycle abandoned ({kind}): {exc}", throttle_duration_sec=5.0)
        if self._failed_cycles >= FAILED_CYCLES_FOR_ERROR:
            self.diag.set_state("i2c error", DiagnosticStatus.ERROR,
                                f"{self._failed_cycles} consecutive failed cycles: {exc}; reset and PROM read again")
            self.get_logger().error(f"MS5837: {self._failed_cycles} consecutive failed cycles ({exc}): "
                                    "re-running the start-up (reset, PROM)", throttle_duration_sec=5.0)
            self._failed_cycles = 0
            self.diag.count("restarts")
            self._start()

    def _check_stuck(self, d1: int, d2: int) -> bool:
        """Feed one raw pair; raise/clear the ERROR ``stuck``. Returns True while stuck."""
        stuck = self.stuck.update((d1, d2))
        if stuck and not self.is_stuck:
            self.get_logger().error(f"MS5837 stuck: identical D1/D2 for {self.stuck.limit} readings: not published")
            self.diag.error("stuck", f"stuck: identical D1/D2 ({d1}, {d2}) for >= {self.stuck.limit} readings")
            self.diag.count("stuck_events")
            self.diagnostics.publish()
        elif not stuck and self.is_stuck:
            self.diag.clear("stuck")
        self.is_stuck = stuck
        return stuck

    # ------------------------------------------------------------------ output
    def depth_m(self, pressure_pa: float) -> float:
        """Depth of the pressure port below the surface, m (docs/devices.md §3.6, configured rho, g, P_surface)."""
        return p.depth_m(pressure_pa, self.water_density_kg_m3, self.surface_pressure_pa, self.gravity_m_s2)

    def _publish(self, reading: p.Reading, stamp) -> None:
        stamp_msg = stamp.to_msg()
        t_s = stamp.nanoseconds * 1e-9
        self.last_reading = reading
        self._recent.append((t_s, reading.pressure_pa))
        while self._recent and self._recent[0][0] < t_s - ZERO_DEPTH_WINDOW_S:
            self._recent.popleft()

        fp = FluidPressure()
        fp.header.stamp, fp.header.frame_id = stamp_msg, self.frames["frame_id"]
        fp.fluid_pressure = reading.pressure_pa
        fp.variance = self.pressure_variance_pa2
        self.pub_pressure.publish(fp)

        tm = Temperature()
        tm.header.stamp, tm.header.frame_id = stamp_msg, self.frames["frame_id"]
        tm.temperature = reading.temperature_c
        tm.variance = TEMPERATURE_RESOLUTION_C ** 2
        self.pub_temperature.publish(tm)

        depth = PoseWithCovarianceStamped()
        depth.header.stamp, depth.header.frame_id = stamp_msg, self.frames["depth_frame_id"]
        depth.pose.pose.position.z = -self.depth_m(reading.pressure_pa)
        cov = [0.0] * 36
        for i in (0, 7, 21, 28, 35):
            cov[i] = UNKNOWN_VARIANCE
        cov[14] = self.pressure_variance_pa2 / (self.water_density_kg_m3 * self.gravity_m_s2) ** 2
        depth.pose.covariance = cov
        self.pub_depth.publish(depth)
        self.diag.published()

    def _on_vehicle_parameters(self, cfg) -> None:
        """Apply a validated change of ``environment.surface_pressure_pa`` (this node's one writable key)."""
        self.surface_pressure_pa = float(cfg.environment.surface_pressure_pa)

    def on_zero_depth(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        """Set the surface pressure to the mean pressure of the last ZERO_DEPTH_WINDOW_S seconds; refused while the
        ESC is armed or has not reported its state yet, or with that mean further than ``zero_depth_margin_pa`` from
        the atmospheric reference."""
        response.success = False
        if not self._recent:
            response.message = "no pressure reading yet; surface pressure unchanged"
            return response
        mean_pa = sum(v for _, v in self._recent) / len(self._recent)
        off_pa = mean_pa - self.atmospheric_reference_pa
        refusal = self.armed.refusal()
        if refusal:
            response.message = f"{refusal}; surface pressure unchanged"
        elif abs(off_pa) > self.zero_depth_margin_pa:
            response.message = (f"refused: mean pressure {mean_pa:.1f} Pa is {off_pa:+.1f} Pa "
                                 f"({off_pa / (self.water_density_kg_m3 * self.gravity_m_s2):+.2f} m of water) from "
                                 f"the atmospheric reference {self.atmospheric_reference_pa:.1f} Pa, beyond "
                                 f"sensors.ms5837.zero_depth_margin_pa {self.zero_depth_margin_pa:g}: not at the "
                                 "surface; surface pressure unchanged")
        if response.message:
            self.diag.count("zero_depth_refused")
            self.get_logger().warn(f"pressure/zero_depth {response.message}")
            return response
        old = self.surface_pressure_pa
        self.surface_pressure_pa = mean_pa
        try:
            self.set_parameters([Parameter("environment.surface_pressure_pa", value=self.surface_pressure_pa)])
        except Exception as exc:  # noqa: BLE001 - the parameter mirror is informative only
            self.get_logger().warn(f"could not update environment.surface_pressure_pa parameter: {exc}")
        response.success = True
        response.message = (f"surface pressure set to {self.surface_pressure_pa:.1f} Pa (was {old:.1f} Pa), "
                            f"mean of {len(self._recent)} readings")
        self.get_logger().info(response.message)
        return response

    def _diag_extra(self):
        out = [("variant", self.variant.value if self.variant else "unknown"),
               ("variant_configured", self.configured_variant.value if self.configured_variant else "auto"),
               ("oversampling", self.osr), ("conversion_wait_s", f"{self.conversion_wait_s:.4f}"),
               ("surface_pressure_pa", f"{self.surface_pressure_pa:.1f}"), ("cycles", self.cycles),
               ("startup_attempts", self.startup_attempts)]
        if self.calibration is not None:
            out.append(("prom_c1_c6", " ".join(str(c) for c in self.calibration.words[1:7])))
        if self.device is not None:
            out += self.device.stats.diagnostics()
        return out

    def close(self) -> None:
        """Stop the timers and close the bus if this node opened it (run_node calls this on shutdown)."""
        self._cycle_timer.cancel()
        self._step_timer.cancel()
        self._bus.close()


def main(args=None) -> int:
    """``python -m hindrax_drivers.ms5837.node --ros-args --params-file ros_ws/config/hindrax.yaml`` (Pi)."""
    return run_node(Ms5837Node, args)


if __name__ == "__main__":
    raise SystemExit(main())
