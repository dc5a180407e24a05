"""ICM-20948 IMU node (TDK InvenSense ICM-20948 + AK09916 magnetometer on I2C; docs/devices.md §4).

Start-up (docs/devices.md §4.3): the steps of :class:`~hindrax_drivers.icm20948.core.StartupSequence` (identity
check, reset and wake, bank-2 configuration, magnetometer), run from ROS timers so the executor is never blocked
(the datasheet waits are one-shot timers, not sleeps). A wrong identity or an I2C failure stops the attempt with the
reason in ``/diagnostics`` (ERROR) and the log, and the whole start-up is retried every :data:`RETRY_PERIOD_S`
seconds; a magnetometer that does not answer is a WARN and the IMU keeps publishing without ``imu/mag``. The chip can
only run at 1125 / (1 + div) Hz (100 Hz configured -> 102.27 Hz): the node polls at that achieved rate and reports
both in the diagnostics. Every magnetometer read is the 9-byte burst ST1..ST2, so ST2 is always read last and the
data registers unlock (docs/devices.md §0 point 7, §4.5).

Polling, at the achieved output data rate: one burst read from ACCEL_XOUT_H of 14 bytes (accel, gyro,
temperature), 23 bytes in I2C-master mode (plus EXT_SLV_SENS_DATA_00..08 = ST1..ST2 of the AK09916); in
bypass mode a second 9-byte burst at 0x0C:0x10; in I2C-master mode a 1-byte read of I2C_MST_STATUS (the
AK09916's NACK bit, see "Data-ready gates" below). The register bank stays 0 between polls. With
``sensors.icm20948.require_data_ready`` each poll first reads INT_STATUS_1 (bank 0, 0x1A, one byte: it lies
19 bytes before ACCEL_XOUT_H, too far to share the burst): a poll whose RAW_DATA_0_RDY is not set (the chip
and host clocks drift at the same nominal rate, so a poll may come before the next sample) publishes nothing
(see "Data-ready gates").

Publishes (reliable, depth 10), all with frame ``imu_link``:

- ``imu/data_raw`` sensor_msgs/Imu (REP-145): no orientation, ``orientation_covariance[0] = -1``;
  ``linear_acceleration`` (specific force, m/s^2, +g on the up axis at rest) and ``angular_velocity``
  (rad/s, gyro bias subtracted when estimated); covariances diagonal, from the datasheet noise densities
  times the noise bandwidth of the configured DLPF plus the quantisation (:func:`imu_noise_variances`).
- ``imu/mag`` sensor_msgs/MagneticField, tesla, rotated into the accel/gyro axes (m_x = hx, m_y = -hy,
  m_z = -hz, docs/devices.md §4.7), only for new data (ST1.DRDY) without overflow (ST2.HOFL); covariance all 0
  = unknown (the datasheet gives no magnetometer noise figure, DS-000189 Table 3). At most
  :data:`MAG_PUBLISH_HZ` (a heading display's rate): every k-th such sample, k = round(AK09916 sample rate /
  20 Hz), counted from each start-up (a replay of the same raw data publishes the same samples).
- ``imu/temperature`` sensor_msgs/Temperature, degC (raw / 333.87 + 21, room offset 0, docs/devices.md §4.4),
  variance = one LSB squared; at :data:`TEMPERATURE_PUBLISH_HZ`: every round(rate / 1 Hz)-th published IMU
  sample, the first one after each start-up included (a slow diagnostic value).
- ``raw/icm20948`` hindrax_msgs/RawDeviceData: every I2C transaction (ICM and, in bypass mode, AK09916);
  those of one poll in one message (:class:`~hindrax_drivers.node_common.RawDataPublisher` batch).
- ``/diagnostics``: state, rate, last message age, I2C transactions/errors/retries/failures, identity,
  configuration, magnetometer state, gyro bias, the ERRORs ``stuck``, ``chip_reset`` and ``magnetometer``,
  the counters ``chip_resets``, ``mag_nack``, ``mag_lost``, ``stuck_events``.

Mounting: ``sensors.icm20948.mounting_rpy_rad`` = roll, pitch, yaw (extrinsic x-y-z, FLU) of the sensor
axes in base_link. The node rotates every vector (and covariance) by R = Rz(yaw) Ry(pitch) Rx(roll), so
``imu_link`` has the orientation of base_link (FLU, REP-103) and sits at the sensor; no TF is published by
this node (there is no position key for the IMU in the configuration).

Gyro bias (``sensors.icm20948.estimate_gyro_bias``): during the first ``gyro_bias_duration_s`` of data
after start-up the node averages the gyro (publishing meanwhile without correction, state
"estimating gyro bias"); if every axis's gyro and accelerometer standard deviation is below
:data:`STILL_STD_FACTOR` times the expected noise (:class:`GyroBiasEstimator`) the vehicle was still and
the mean is subtracted from then on; otherwise no bias is applied and a WARN says why. The result is in
the diagnostics (``gyro_bias_rad_s``, ``gyro_bias_status``).

Time stamps: the device has no clock usable by the host, so every message is stamped with the ROS time
(``use_sim_time`` supported) right after the burst read returned (receive time). The sample is at most
one output period (about 10 ms at 100 Hz) older than its stamp.

Faults: an I2C failure after the transport's retries (immediate, ``backoff_s = 0``: no sleep in any
callback) drops that poll only (counted). Failures lasting
:data:`REINIT_AFTER_S` seconds restart the start-up.

Data-ready gates (``sensors.icm20948.require_data_ready``, ``not_ready_error_polls``, ``frozen_check_samples``,
``mag_stale_timeout_s``, ``mag_retry_interval_s``):

- INT_STATUS_1.RAW_DATA_0_RDY (clears on read; datasheet DS-000189 register description, bank 0 0x1A bit 0):
  not set -> the sample is not published (``imu/data_raw``, ``imu/temperature``, ``imu/mag``), counted
  ``not_ready``; ``not_ready_error_polls`` in a row raise the ERROR ``data_ready``, cleared by the next ready
  sample. The burst is still read and checked (reset and stuck detection below work on it). A failed status
  read (counted ``data_ready_read_failure``) leaves the flag unknown and the sample is published as without
  the gate: a replay of a bag recorded without these reads therefore publishes what it recorded.

- Chip reset (power glitch): the data registers of a chip that reset read their reset value 0 and stop
  updating, PWR_MGMT_1 reads 0x41 (asleep) and USER_CTRL 0 (I2C master off) (docs/devices.md §4.3). An
  all-zero sensor block, or ``frozen_check_samples`` bit-identical blocks in a row (a live sensor's noise
  changes the low bits of every new sample; one repeat is a poll that came before the next sample),
  makes the node read USER_CTRL..PWR_MGMT_1 back (one 4-byte read). A chip asleep, or with the I2C master
  off in ``i2c_master`` mode, is a reset: counted (``chip_resets``), ERROR, the suspect samples are not
  published, and the start-up runs again at once. The all-zero block itself is never published.
- Stuck: bit-identical samples for :data:`STUCK_AFTER_S` seconds with the chip state intact raise the ERROR
  ``stuck``; nothing is published until the data change.
- Magnetometer in ``i2c_master`` mode: after each poll the node reads I2C_MST_STATUS (clears on read);
  SLV0_NACK set means the AK09916 did not answer and EXT_SLV_SENS_DATA holds an old sample: ``imu/mag`` is
  not published (counted ``mag_nack``) until that block changes (a new sample; a poll between two master
  cycles re-reads the same block, so the NACK of one cycle covers every poll that sees its data). If the
  status read itself fails the sample is published (the NACK bit stays set until read, the next poll sees it). No fresh
  magnetometer sample (DRDY without NACK) for ``mag_stale_timeout_s`` raises the ERROR ``magnetometer`` and re-runs the
  start-up once (the AK09916 may have reset to power-down); if it is still missing the IMU publishes without
  ``imu/mag``, the ERROR stays, and the magnetometer's part of the start-up is retried every
  ``mag_retry_interval_s`` (counted ``mag_retries``; one step per poll, no device reset: ``imu/data_raw`` goes on)
  until the AK09916 answers again.

The bus is injected: ``smbus2.SMBus(sensors.icm20948.i2c_bus)`` on the Pi (closed after a failed start-up
attempt and opened again at the next: :class:`~hindrax_drivers.transport.i2c.BusHandle`), an
:class:`~hindrax_drivers.transport.emulated_i2c.EmulatedI2CBus` with an
:class:`~hindrax_drivers.icm20948.emulator.Icm20948Emulator` (and its ``aux_port`` at 0x0C for bypass)
in tests and simulation.

Run alone: ``python -m hindrax_drivers.icm20948.node --ros-args --params-file ros_ws/config/hindrax.yaml``.
"""
from __future__ import annotations

import math
from typing import Any, Callable

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.event_handler import PublisherEventCallbacks
from rclpy.node import Node
from sensor_msgs.msg import Imu, MagneticField, Temperature

from ..lean_cdr import imu_cdr
from ..node_common import (DEFAULT_QOS_DEPTH, DeviceDiagnostics, DiagnosticsPublisher, RawDataPublisher,
                           StuckDetector, declare_frame_ids, load_node_config, run_node)
from ..transport.i2c import BusHandle, I2CDevice, I2CError
from . import protocol as p
from .core import (STILL_STD_FACTOR, BankedRegisters, DataReadyGate, FrozenBlockWatch, GyroBiasEstimator,
                   GyroBiasResult, MagNackFilter, StartupSequence, chip_reset_problems, imu_config_from_settings,
                   imu_noise_variances, mag_mode_for_rate)
from .mounting import mounting_rotation

#: rate of ``imu/temperature``, Hz (diagnostics and bag: the die temperature drifts over minutes)
TEMPERATURE_PUBLISH_HZ = 1.0
#: highest rate of ``imu/mag``, Hz (heading on the topside; AK09916 continuous mode 2 is 20 Hz, docs/devices.md §4.5)
MAG_PUBLISH_HZ = 20.0

__all__ = ["Icm20948Node", "GyroBiasEstimator", "GyroBiasResult", "imu_config_from_settings",
           "imu_noise_variances", "mounting_rotation", "mag_mode_for_rate", "main"]

#: Wait between start-up attempts after a failure, s.
RETRY_PERIOD_S = 1.0
#: I2C failures lasting this long (ROS time) restart the start-up sequence, s.
REINIT_AFTER_S = 1.0
#: Identical samples for this long mean a stuck sensor, s.
STUCK_AFTER_S = 2.0
#: Bytes read back by the chip-state check: USER_CTRL (0x03), reserved 0x04, LP_CONFIG 0x05, PWR_MGMT_1 0x06.
CHIP_STATE_LENGTH = 4
#: Frame of every message (see the module docstring: base_link orientation, at the sensor).
FRAME_ID = "imu_link"


# ---------------------------------------------------------------------------------------- node
class Icm20948Node(Node):
    """ICM-20948 + AK09916 driver node (see the module docstring).

    Args:
        bus: object with the ``smbus2.SMBus`` interface; default ``smbus2.SMBus(sensors.icm20948.i2c_bus)``.
        **kwargs: passed to :class:`rclpy.node.Node` (``context``, ``parameter_overrides``...).

    Raises:
        ConfigError: invalid configuration (one line naming key, value and range).
    """

    def __init__(self, bus: Any = None, **kwargs: Any):
        super().__init__("icm20948", **kwargs)
        self.frames = declare_frame_ids(self, {"frame_id": FRAME_ID})
        cfg = load_node_config(self, ("sensors.icm20948",))
        s = cfg.sensors.icm20948
        self.i2c_bus_number = int(s.i2c_bus)
        self.address = int(s.i2c_address)
        self.sample_rate_hz = float(s.sample_rate_hz)
        self.config = imu_config_from_settings(s.accel_full_scale_g, s.gyro_full_scale_dps,
                                               s.dlpf_config, self.sample_rate_hz)
        self.odr_hz = self.config.accel_odr_hz
        self.mag_mode_name = str(s.magnetometer_mode)
        self.mag_mode = mag_mode_for_rate(self.odr_hz)
        self.estimate_gyro_bias = bool(s.estimate_gyro_bias)
        self.gyro_bias_duration_s = float(s.gyro_bias_duration_s)
        self.rotation = mounting_rotation(s.mounting_rpy_rad)
        self.accel_var, self.gyro_var = imu_noise_variances(self.config)
        self.accel_cov = (self.rotation * self.accel_var) @ self.rotation.T
        self.gyro_cov = (self.rotation * self.gyro_var) @ self.rotation.T
        self.temperature_var = (1.0 / p.TEMP_SENSITIVITY_LSB_PER_C) ** 2
        if abs(self.odr_hz - self.sample_rate_hz) > 0.05 * self.sample_rate_hz:
            self.get_logger().warn(f"sensors.icm20948.sample_rate_hz = {self.sample_rate_hz:g} Hz is not reachable: "
                                   f"the chip runs at 1125 / (1 + div) Hz, here {self.odr_hz:.2f} Hz")
        if not 0 < self.config.gyro_dlpfcfg < 7:
            self.get_logger().warn(f"dlpf_config {self.config.gyro_dlpfcfg}: the gyro ignores its sample-rate "
                                   "divider (docs/devices.md §4.4) and runs at 1125 Hz; polled at "
                                   f"{self.odr_hz:.2f} Hz")

        self._bus = BusHandle(self.i2c_bus_number, bus)  # reopened after a failed start-up when owned
        self.raw = RawDataPublisher(self, "icm20948")
        self.device: I2CDevice | None = None
        self.mag_device: I2CDevice | None = None
        self.regs: BankedRegisters | None = None
        self.startup: StartupSequence | None = None  # the start-up, or the magnetometer's re-initialisation
        self.diag = DeviceDiagnostics("hindrax/icm20948", f"i2c-{self.i2c_bus_number}@0x{self.address:02x}",
                                      self._now_s)
        self.stuck = StuckDetector(max(3, round(STUCK_AFTER_S * self.odr_hz)))
        self.frozen_check_samples = int(s.frozen_check_samples)
        self.mag_stale_timeout_s = float(s.mag_stale_timeout_s)
        self.require_data_ready = bool(s.require_data_ready)
        self.not_ready_error_polls = int(s.not_ready_error_polls)
        self.mag_retry_interval_s = float(s.mag_retry_interval_s)
        self.data_ready = DataReadyGate(self.not_ready_error_polls)
        self._mag_retry_due_s: float | None = None
        self._mag_retrying = False  # a magnetometer-only re-initialisation runs between polls
        self._mag_step_due_s = 0.0
        self.frozen = FrozenBlockWatch(self.frozen_check_samples)
        self._mag_fresh_s: float | None = None
        self.mag_nack = MagNackFilter()
        self._mag_lost = False
        self.chip_state_checks = 0
        self.is_stuck = False
        self.who_am_i: int | None = None
        self.mag_available = False
        self.startup_attempts = 0
        self.running = False
        self.gyro_bias_rad_s = np.zeros(3)
        self.bias_estimator: GyroBiasEstimator | None = None
        self.bias_result: GyroBiasResult | None = None
        self._fail_since_s: float | None = None
        self.samples = 0
        self.mag_samples = 0
        self.temperature_every = max(1, round(self.odr_hz / TEMPERATURE_PUBLISH_HZ))
        self.mag_every = max(1, round(min(p.AK_CONTINUOUS_MODE_RATE_HZ[self.mag_mode], self.odr_hz)
                                      / MAG_PUBLISH_HZ))
        self._temperature_count = 0  # IMU samples published since the start-up
        self._mag_count = 0  # valid magnetometer samples since the start-up

        qos = DEFAULT_QOS_DEPTH
        # no QoS event handlers (rclpy's default incompatible-QoS warning handler of each publisher is visited in
        # Python on every executor spin, at the 100 Hz poll)
        ev = PublisherEventCallbacks(use_default_callbacks=False)
        self.pub_imu = self.create_publisher(Imu, "imu/data_raw", qos, event_callbacks=ev)
        self.pub_mag = self.create_publisher(MagneticField, "imu/mag", qos, event_callbacks=ev)
        self.pub_temperature = self.create_publisher(Temperature, "imu/temperature", qos, event_callbacks=ev)
        self.diagnostics = DiagnosticsPublisher(self, [self.diag], extra=self._diag_extra)

        self._step_timer = self.create_timer(1.0, self._on_step_timer, autostart=False)
        self._step_fn: Callable[[], None] | None = None
        self._poll_timer = self.create_timer(1.0 / self.odr_hz, self._poll, autostart=False)
        self._schedule(0.0, self._start)  # first bus access from the executor, not the constructor

    # ------------------------------------------------------------------ timer helpers
    def _now_s(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def _schedule(self, delay_s: float, fn: Callable[[], None]) -> None:
        """Run ``fn`` once after ``delay_s`` of ROS time."""
        self._step_fn = fn
        self._step_timer.timer_period_ns = max(1, int(delay_s * 1e9))
        self._step_timer.reset()

    def _on_step_timer(self) -> None:
        self._step_timer.cancel()
        fn, self._step_fn = self._step_fn, None
        if fn is not None:
            fn()

    # ------------------------------------------------------------------ banked register access
    def _read(self, register: p.Register, length: int = 1) -> bytes:
        return self.regs.read(register, length)

    def _invalidate_bank(self) -> None:
        if self.regs is not None:
            self.regs.invalidate()

    # ------------------------------------------------------------------ start-up
    def _start(self) -> None:
        """Open the bus if needed and run the start-up steps (docs/devices.md §4.3)."""
        self.startup_attempts += 1
        self._mag_retrying = False
        self._poll_timer.cancel()
        self.running = False
        self._fail_since_s = None
        try:
            bus = self._bus.get()  # the same bus, or opened afresh after a failed attempt (BusHandle)
        except (OSError, ImportError) as exc:
            self._fail(str(exc))
            return
        if self.device is None:
            self.device = I2CDevice(bus, self.address, "icm20948", backoff_s=0.0, raw_tap=self.raw.i2c_tap)
            self.mag_device = I2CDevice(bus, p.AK09916_ADDRESS, "ak09916", backoff_s=0.0,
                                        raw_tap=self.raw.i2c_tap)
            self.regs = BankedRegisters(self.device)
        self.device.bus = self.mag_device.bus = bus  # the devices keep their counters across reopened buses
        self.regs.invalidate()
        self.mag_available = False
        self._temperature_count = self._mag_count = 0
        self.diag.set_state("starting", DiagnosticStatus.WARN, "identity check, reset and configuration")
        self.startup = StartupSequence(self.regs, self.mag_device, self.config, self.mag_mode_name, self.mag_mode,
                                       self._on_magnetometer)
        self._run_steps()

    def _run_steps(self) -> None:
        """Execute start-up steps until one asks for a wait (then continue from a one-shot timer)."""
        result = self.startup.advance()
        self.who_am_i = self.startup.who_am_i if self.startup.who_am_i is not None else self.who_am_i
        if result.failure is not None:
            if result.i2c_failure:
                self.diag.count("i2c_failure")
            self._fail(result.failure)
        elif result.wait_s > 0.0:
            self._schedule(result.wait_s, self._run_steps)
        else:
            self._started()

    def _fail(self, reason: str) -> None:
        self.startup = None
        self.diag.set_state("error", DiagnosticStatus.ERROR, f"{reason}; retrying every {RETRY_PERIOD_S:g} s")
        self.get_logger().error(f"ICM-20948 start-up failed: {reason}", throttle_duration_sec=10.0)
        self._bus.reset()  # the next attempt opens /dev/i2c-N again: a bus that went and came back is picked up
        self._schedule(RETRY_PERIOD_S, self._start)

    def _on_magnetometer(self, available: bool, reason: str) -> None:
        self.mag_available = available
        if available:
            self.diag.clear("magnetometer")
        else:
            self.diag.warn("magnetometer", f"magnetometer unavailable: {reason}")
            self.get_logger().warn(f"AK09916 unavailable, publishing without imu/mag: {reason}")

    def _started(self) -> None:
        """Configuration done: select bank 0 for the polls and start the poll timer."""
        try:
            self.regs.select_bank(0)
        except I2CError as exc:
            self.regs.invalidate()
            self._fail(f"start-up I2C failure: {exc}")
            return
        self.running = True
        self.diag.clear("chip_reset")
        self.mag_nack.reset()
        self._mag_fresh_s = self._now_s() if self.mag_available else None
        if self.mag_available:
            self._mag_lost = False
        self._mag_retry_due_s = (self._now_s() + self.mag_retry_interval_s
                                 if self._mag_lost and not self.mag_available else None)
        if self.estimate_gyro_bias and self.bias_result is None:
            self.bias_estimator = GyroBiasEstimator(self.gyro_bias_duration_s,
                                                    STILL_STD_FACTOR * math.sqrt(self.gyro_var),
                                                    STILL_STD_FACTOR * math.sqrt(self.accel_var))
            self.diag.set_state("estimating gyro bias", DiagnosticStatus.OK,
                                f"estimating gyro bias for {self.gyro_bias_duration_s:g} s (keep the vehicle still)")
        else:
            self.diag.set_state("running", DiagnosticStatus.OK, "running")
        self.get_logger().info(
            f"ICM-20948 ready at {self.odr_hz:.2f} Hz (FS {p.ACCEL_RANGE_G[self.config.accel_fs_sel]:g} g, "
            f"{p.GYRO_RANGE_DPS[self.config.gyro_fs_sel]:g} dps, DLPFCFG {self.config.gyro_dlpfcfg}), magnetometer "
            f"{self.mag_mode_name}: {'ok' if self.mag_available else 'unavailable'}")
        self._poll_timer.reset()

    # ------------------------------------------------------------------ polling
    def _poll(self) -> None:
        master = self.mag_mode_name == "i2c_master" and self.mag_available
        length = p.SENSOR_BLOCK_LENGTH + (p.AK09916_BLOCK_LENGTH if master else 0)
        self.raw.begin_batch()  # raw/icm20948: the poll's transactions in one message
        ready = self._read_data_ready() if self.require_data_ready else None
        try:
            data = self._read(p.ACCEL_XOUT_H, length)
        except I2CError as exc:
            self.raw.flush()
            self._poll_failed(exc)
            return
        stamp = self.get_clock().now()
        self._fail_since_s = None
        mag_block = data[p.SENSOR_BLOCK_LENGTH:] if master else None
        if master:
            try:
                nack = bool(self.device.read_block(p.I2C_MST_STATUS.address, 1)[0] & p.I2C_MST_STATUS_SLV0_NACK)
            except I2CError:
                nack = False
                self.diag.count("mag_status_failure")
            if nack:
                self.diag.count("mag_nack")
            mag_block = self.mag_nack.update(mag_block, nack)  # None: the sample of before the NACK
        if self.mag_mode_name == "bypass" and self.mag_available:
            try:
                mag_block = self.mag_device.read_block(p.AK_ST1.address, p.AK09916_BLOCK_LENGTH)
            except I2CError:
                self.diag.count("mag_i2c_failure")
        if self.diag.state == "i2c error":
            self.diag.set_state("running", DiagnosticStatus.OK, "running")
        self._process(data[:p.SENSOR_BLOCK_LENGTH], mag_block, stamp, ready)
        self.raw.flush()

    def _read_data_ready(self) -> bool | None:
        """INT_STATUS_1.RAW_DATA_0_RDY (bank 0, 0x1A; clears on read), read before the data burst: True when a
        new accel/gyro sample was written since the last read, None when the read failed (unknown: the sample
        is then published, as without the gate; counted ``data_ready_read_failure``). INT_STATUS_1 is 19 bytes
        before ACCEL_XOUT_H (0x2D), so it is a separate 1-byte read rather than part of the burst."""
        try:
            return bool(self._read(p.INT_STATUS_1)[0] & p.INT_STATUS_1_RAW_DATA_0_RDY)
        except I2CError:  # a failed read leaves the bank unchanged (no re-select: the replay has no such write)
            self.diag.count("data_ready_read_failure")
            return None

    def _data_ready_gate(self, ready: bool | None) -> bool:
        """Count a poll without RAW_DATA_0_RDY (``not_ready``); ERROR ``data_ready`` after
        ``not_ready_error_polls`` in a row, cleared by the next ready sample. Returns True when the sample may be
        published (ready, or unknown)."""
        verdict = self.data_ready.update(ready)
        if ready is False:
            self.diag.count("not_ready")
        if verdict.raise_error:
            text = (f"data_ready: INT_STATUS_1.RAW_DATA_0_RDY not set for {verdict.polls} consecutive "
                    "polls: no new accel/gyro sample, nothing published")
            self.diag.error("data_ready", text)
            self.get_logger().error(f"ICM-20948 {text}")
            self.diagnostics.publish()
        if verdict.clear_error:
            self.diag.clear("data_ready")
        return verdict.publish

    def _poll_failed(self, exc: Exception) -> None:
        self._invalidate_bank()
        self.diag.count("i2c_failure")
        now = self._now_s()
        if self._fail_since_s is None:
            self._fail_since_s = now
        self.get_logger().warn(f"ICM-20948 poll failed: {exc}", throttle_duration_sec=5.0)
        if now - self._fail_since_s >= REINIT_AFTER_S:
            self.diag.set_state("i2c error", DiagnosticStatus.ERROR, f"no data for {REINIT_AFTER_S:g} s: {exc}")
            self.get_logger().error("ICM-20948 unreachable, restarting the start-up sequence")
            self._start()
        elif self.diag.state == "running":
            self.diag.set_state("i2c error", DiagnosticStatus.WARN, f"poll failed: {exc}")

    def _process(self, block: bytes, mag_block: bytes | None, stamp, ready: bool | None = None) -> None:
        block = bytes(block)
        suspect = self.frozen.update(block)
        if suspect is not None and self._reset_detected(zero_block=suspect == "zero"):
            return
        if suspect == "zero":
            return  # the reset value of every data register: never a measurement
        sample = p.parse_sensor_block(block, self.config)
        self.samples += 1
        if self._check_stuck(block):
            return  # a stuck sensor is not published (ERROR "stuck")
        if not self._data_ready_gate(ready):
            return  # the registers still hold the sample of an earlier poll (RAW_DATA_0_RDY not set)
        if sample.accel_saturated or sample.gyro_saturated:
            self.diag.count("saturated_samples")
        if self.bias_estimator is not None:
            result = self.bias_estimator.add(stamp.nanoseconds * 1e-9, sample.gyro_rad_s, sample.accel_m_s2)
            if result is not None:
                self._bias_done(result)
        stamp_msg = stamp.to_msg()

        # REP-145, no orientation estimate; serialised by rosbags and published as bytes (51 Hz without rclpy's
        # object conversion: 0.30-0.31 -> 0.23-0.25 ms per publish here, hindrax_drivers.lean_cdr)
        acc = self.rotation @ sample.accel_m_s2
        gyr = self.rotation @ (sample.gyro_rad_s - self.gyro_bias_rad_s)
        self.pub_imu.publish(imu_cdr(stamp.nanoseconds, self.frames["frame_id"], acc, gyr, self.accel_cov,
                                     self.gyro_cov))

        if self._temperature_count % self.temperature_every == 0:
            tm = Temperature()
            tm.header.stamp, tm.header.frame_id = stamp_msg, self.frames["frame_id"]
            tm.temperature = float(sample.temperature_c)
            tm.variance = self.temperature_var
            self.pub_temperature.publish(tm)
        self._temperature_count += 1

        if mag_block is not None:
            self._publish_mag(p.parse_ak09916_block(mag_block), stamp_msg)
        self.diag.published()
        now_s = self._now_s()
        if self.mag_available and self._mag_stale(now_s):
            return
        if self._mag_retry_due_s is not None and now_s >= self._mag_retry_due_s:
            self._mag_retry_due_s = None
            self.diag.count("mag_retries")
            self.get_logger().warn(f"AK09916 still missing: re-initialising it (every {self.mag_retry_interval_s:g} s)",
                                   throttle_duration_sec=30.0)
            self._begin_mag_retry(now_s)
        self._mag_retry_step(now_s)

    def _begin_mag_retry(self, now_s: float) -> None:
        """Re-initialise only the magnetometer, one step per poll (the accel/gyro polls go on: at most one missed
        sample, where the whole start-up with its device reset cost 340-350 ms of samples every retry)."""
        self.startup = StartupSequence(self.regs, self.mag_device, self.config, self.mag_mode_name, self.mag_mode,
                                       self._on_magnetometer, magnetometer_only=True)
        self._mag_retrying = True
        self._mag_step_due_s = now_s

    def _mag_retry_step(self, now_s: float) -> None:
        """One step of the magnetometer re-initialisation when due (called after a published sample)."""
        if not self._mag_retrying or now_s < self._mag_step_due_s:
            return
        if self.startup.finished:
            self._mag_retrying = False
            if self.mag_available:
                self._mag_lost = False
                self.mag_nack.reset()
                self._mag_fresh_s = now_s
                self.get_logger().info("AK09916 answers again: publishing imu/mag")
            else:
                self._mag_retry_due_s = now_s + self.mag_retry_interval_s
            return
        self._mag_step_due_s = now_s + self.startup.step().wait_s

    def _mag_stale(self, now_s: float) -> bool:
        """True (and re-initialisation started) when no fresh magnetometer sample came for the timeout."""
        if self._mag_fresh_s is None or now_s - self._mag_fresh_s <= self.mag_stale_timeout_s:
            return False
        text = (f"magnetometer: no new AK09916 sample for {now_s - self._mag_fresh_s:.2f} s (SLV0 NACK or no "
                "DRDY): imu/mag not published, re-initialising")
        self.diag.error("magnetometer", text)
        self.diag.count("mag_lost")
        self.get_logger().error(f"ICM-20948 {text}")
        self._mag_lost = True
        self._mag_fresh_s = None
        self.diagnostics.publish()
        self.mag_available = False
        self._begin_mag_retry(now_s)
        return True

    def _publish_mag(self, mag: p.MagSample, stamp_msg) -> None:
        if mag.data_overrun:
            self.diag.count("mag_overrun")
        if not mag.data_ready:
            return
        self._mag_fresh_s = self._now_s()
        if mag.overflow:
            self.diag.count("mag_overflow")
            return
        due = self._mag_count % self.mag_every == 0
        self._mag_count += 1
        if not due:
            return
        field_t = self.rotation @ mag.magnetic_field_t
        msg = MagneticField()
        msg.header.stamp, msg.header.frame_id = stamp_msg, self.frames["frame_id"]
        msg.magnetic_field.x, msg.magnetic_field.y, msg.magnetic_field.z = (float(v) for v in field_t)
        # magnetic_field_covariance stays all 0: unknown (sensor_msgs/MagneticField definition)
        self.pub_mag.publish(msg)
        self.mag_samples += 1

    def _bias_done(self, result: GyroBiasResult) -> None:
        self.bias_result = result
        self.bias_estimator = None
        if result.still:
            self.gyro_bias_rad_s = result.bias_rad_s
            self.diag.clear("gyro_bias")
            self.get_logger().info(result.message)
        else:
            self.diag.warn("gyro_bias", result.message)
            self.get_logger().warn(result.message)
        self.diag.set_state("running", DiagnosticStatus.OK, "running")

    def _check_stuck(self, block: bytes) -> bool:
        """Feed one sensor block; raise/clear the ERROR ``stuck``. Returns True while stuck."""
        stuck = self.stuck.update(block)
        if stuck and not self.is_stuck:
            self.get_logger().error(f"ICM-20948 stuck: identical samples for {self.stuck.limit} polls: not published")
            self.diag.error("stuck", f"stuck: identical accel/gyro/temperature for >= {self.stuck.limit} samples")
            self.diag.count("stuck_events")
            self.is_stuck = True
            self.diagnostics.publish()
            self._check_asleep()
        elif not stuck and self.is_stuck:
            self.diag.clear("stuck")
            self.is_stuck = False
        return self.is_stuck

    def _reset_detected(self, zero_block: bool) -> bool:
        """Read USER_CTRL..PWR_MGMT_1 back; on the state of a reset chip restart the start-up (True)."""
        self.chip_state_checks += 1
        try:
            state = self._read(p.USER_CTRL, CHIP_STATE_LENGTH)
        except I2CError as exc:
            self._poll_failed(exc)
            return True  # unknown: the suspect sample is dropped
        problems = chip_reset_problems(state, self.mag_mode_name == "i2c_master" and self.mag_available)
        if not problems:
            return False
        seen = "all-zero data" if zero_block else f"{self.frozen.repeats + 1} identical samples"
        text = f"chip reset detected ({', '.join(problems)}; {seen}): re-initialising"
        self.get_logger().error(f"ICM-20948 {text}")
        self.diag.count("chip_resets")
        self.diag.error("chip_reset", text)
        self.diagnostics.publish()
        self.frozen.reset()
        self.stuck = StuckDetector(self.stuck.limit)
        self.is_stuck = False
        self.diag.clear("stuck")
        self._start()
        return True

    def _check_asleep(self) -> None:
        """A frozen chip may have been reset by a power glitch (asleep after reset): start again if so."""
        try:
            pwr = self._read(p.PWR_MGMT_1)[0]
        except I2CError:
            self._invalidate_bank()
            return
        if pwr & p.PWR_MGMT_1_SLEEP:
            self.get_logger().error("ICM-20948 found asleep (reset by a power glitch?): restarting the start-up")
            self.diag.count("unexpected_sleep")
            self.stuck = StuckDetector(self.stuck.limit)
            self.is_stuck = False
            self.diag.clear("stuck")
            self._start()

    # ------------------------------------------------------------------ diagnostics / shutdown
    def _diag_extra(self):
        c = self.config
        out = [("who_am_i", f"0x{self.who_am_i:02x}" if self.who_am_i is not None else "unknown"),
               ("sample_rate_configured_hz", f"{self.sample_rate_hz:g}"), ("output_data_rate_hz", f"{self.odr_hz:.3f}"),
               ("accel_full_scale_g", f"{p.ACCEL_RANGE_G[c.accel_fs_sel]:g}"),
               ("gyro_full_scale_dps", f"{p.GYRO_RANGE_DPS[c.gyro_fs_sel]:g}"), ("dlpf_config", c.gyro_dlpfcfg),
               ("magnetometer_mode", self.mag_mode_name), ("magnetometer_available", self.mag_available),
               ("magnetometer_messages", self.mag_samples), ("startup_attempts", self.startup_attempts),
               ("gyro_bias_rad_s", " ".join(f"{v:.6f}" for v in self.gyro_bias_rad_s))]
        if self.bias_result is not None:
            out.append(("gyro_bias_status", self.bias_result.message))
        elif self.bias_estimator is not None:
            out.append(("gyro_bias_status", "estimating"))
        if self.device is not None:
            out += self.device.stats.diagnostics()
        return out

    def close(self) -> None:
        """Stop the timers and close the bus if this node opened it (run_node calls this on shutdown)."""
        self._poll_timer.cancel()
        self._step_timer.cancel()
        self._bus.close()


def main(args=None) -> int:
    """``python -m hindrax_drivers.icm20948.node --ros-args --params-file ros_ws/config/hindrax.yaml`` (Pi)."""
    return run_node(Icm20948Node, args)


if __name__ == "__main__":
    raise SystemExit(main())
