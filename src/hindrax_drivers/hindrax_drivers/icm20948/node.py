"""ICM-20948 IMU node (TDK InvenSense ICM-20948 + AK09916 magnetometer on I2C; docs/devices.md §4): the I2C polls and
the messages; the start-up steps, calibration and per-poll decisions are :mod:`hindrax_drivers.icm20948.core`.

Start-up (docs/devices.md §4.3): the steps of :class:`~hindrax_drivers.icm20948.core.StartupSequence`, run from ROS
timers (the datasheet waits are one-shot timers, not sleeps). A wrong identity or an I2C failure is an ERROR with the
reason and the start-up is retried (:class:`~hindrax_drivers.i2c_node.I2cSensorNode`); a magnetometer that does not
answer is a WARN and the IMU publishes without ``imu/mag``. The chip runs at 1125 / (1 + div) Hz (100 Hz configured
-> 102.27 Hz): the node polls at that achieved rate and reports both.

Polling: one burst from ACCEL_XOUT_H of 14 bytes (accel, gyro, temperature), 23 in I2C-master mode (plus ST1..ST2 of
the AK09916, so ST2 is read last and the data registers unlock, docs/devices.md §4.5) followed by a 1-byte read of
I2C_MST_STATUS (SLV0_NACK); in bypass mode a second 9-byte burst at 0x0C:0x10. With
``sensors.icm20948.require_data_ready`` each poll first reads INT_STATUS_1 (19 bytes before ACCEL_XOUT_H: a separate
read). The register bank stays 0 between polls. An I2C failure after the transport's immediate retries drops that
poll (counted); failures lasting :data:`REINIT_AFTER_S` restart the start-up. The data-ready gate, chip-reset and
magnetometer checks are the core's (its module docstring); bit-identical samples for :data:`STUCK_AFTER_S` with the
chip state intact raise the ERROR ``stuck`` and nothing is published until the data change.

Publishes (reliable, depth 10), frame ``imu_link``, stamped with the ROS time right after the burst read returned (at
most one output period after the sample):

- ``imu/data_raw`` sensor_msgs/Imu (REP-145): no orientation (``orientation_covariance[0] = -1``), specific force
  (m/s^2, +g up at rest) and angular velocity (rad/s, less the gyro bias when estimated); diagonal covariances from
  the datasheet noise densities and the DLPF's noise bandwidth (:func:`~.core.imu_noise_variances`).
- ``imu/mag`` sensor_msgs/MagneticField, tesla, in the accel/gyro axes (m_x = hx, m_y = -hy, m_z = -hz,
  docs/devices.md §4.7); covariance 0 = unknown (DS-000189 Table 3 gives no noise figure); at most
  :data:`MAG_PUBLISH_HZ` (:class:`~.core.MagnetometerWatch`).
- ``imu/temperature`` sensor_msgs/Temperature, degC (raw / 333.87 + 21), at :data:`TEMPERATURE_PUBLISH_HZ`: every
  round(rate / 1 Hz)-th published sample, the first after each start-up included.
- ``raw/icm20948`` (every I2C transaction, a poll's in one message) and ``/diagnostics`` (state, rate, I2C counters,
  identity, configuration, magnetometer, gyro bias, ERRORs ``stuck``, ``chip_reset``, ``magnetometer``, ``data_ready``).

Mounting: ``sensors.icm20948.mounting_rpy_rad`` (extrinsic x-y-z, FLU) rotates every vector and covariance by
R = Rz(yaw) Ry(pitch) Rx(roll), so ``imu_link`` has base_link's orientation at the sensor (no TF from this node).
Gyro bias (``estimate_gyro_bias``): the first ``gyro_bias_duration_s`` of data are averaged (published uncorrected
meanwhile); the mean is subtracted only if the vehicle was still (:class:`~.core.GyroBiasEstimator`), else a WARN.

The bus: ``smbus2.SMBus(sensors.icm20948.i2c_bus)`` on the Pi, an
:class:`~hindrax_drivers.icm20948.emulator.Icm20948Emulator` on an
:class:`~hindrax_drivers.transport.emulated_i2c.EmulatedI2CBus` in tests and simulation. Alone:
``python -m hindrax_drivers.icm20948.node --ros-args --params-file ros_ws/config/hindrax.yaml``.
"""
from __future__ import annotations

from typing import Any

from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.event_handler import PublisherEventCallbacks
from sensor_msgs.msg import Imu, MagneticField, Temperature
from std_msgs.msg import Header

from ..i2c_node import I2cSensorNode
from ..lean_cdr import imu_cdr
from ..node_common import DEFAULT_QOS_DEPTH, declare_frame_ids, load_node_config, run_node
from ..transport.i2c import I2CDevice, I2CError
from . import protocol as p
from .core import (BankedRegisters, DataReadyGate, FrozenBlockWatch, GyroBias, GyroBiasResult, ImuSettings,
                   MagnetometerWatch, MagNackFilter, StartupSequence, chip_reset_problems, diagnostic_values,
                   read_poll)

__all__ = ["Icm20948Node", "main"]

#: rate of ``imu/temperature``, Hz (diagnostics and bag: the die temperature drifts over minutes)
TEMPERATURE_PUBLISH_HZ = 1.0
#: highest rate of ``imu/mag``, Hz (heading on the topside; AK09916 continuous mode 2 is 20 Hz, docs/devices.md §4.5)
MAG_PUBLISH_HZ = 20.0
#: I2C failures lasting this long (ROS time) restart the start-up sequence, s.
REINIT_AFTER_S = 1.0
#: Identical samples for this long mean a stuck sensor, s.
STUCK_AFTER_S = 2.0
#: Bytes read back by the chip-state check: USER_CTRL (0x03), reserved 0x04, LP_CONFIG 0x05, PWR_MGMT_1 0x06.
CHIP_STATE_LENGTH = 4
#: Frame of every message (see the module docstring: base_link orientation, at the sensor).
FRAME_ID = "imu_link"


class Icm20948Node(I2cSensorNode):
    """ICM-20948 + AK09916 driver node (module docstring). bus: an ``smbus2.SMBus``-like object (default
    ``smbus2.SMBus(sensors.icm20948.i2c_bus)``); kwargs go to :class:`rclpy.node.Node` (``context``,
    ``parameter_overrides``...). Raises ConfigError for an invalid configuration (one line: key, value, range)."""

    label = "ICM-20948"

    def __init__(self, bus: Any = None, **kwargs: Any):
        super().__init__("icm20948", **kwargs)
        self.frames = declare_frame_ids(self, {"frame_id": FRAME_ID})
        s = load_node_config(self, ("sensors.icm20948",)).sensors.icm20948
        self.sample_rate_hz = float(s.sample_rate_hz)
        self.settings = st = ImuSettings.from_section(s, TEMPERATURE_PUBLISH_HZ, MAG_PUBLISH_HZ)
        self.config, self.odr_hz, self.rotation = st.config, st.odr_hz, st.rotation
        self.mag_mode_name, self.mag_mode = str(s.magnetometer_mode), st.mag_mode
        self.bias = GyroBias(s.estimate_gyro_bias, s.gyro_bias_duration_s, st.gyro_var, st.accel_var)
        for warning in st.warnings:
            self.get_logger().warn(warning)
        self.device: I2CDevice | None = None  # made at the first start-up (open_device), with mag_device
        self.mag_device: I2CDevice | None = None
        self.regs: BankedRegisters | None = None
        self.startup: StartupSequence | None = None  # the start-up, or the magnetometer's re-initialisation
        self.setup_device("icm20948", s.i2c_bus, s.i2c_address, bus, max(3, round(STUCK_AFTER_S * self.odr_hz)))
        self.require_data_ready = bool(s.require_data_ready)
        self.data_ready = DataReadyGate(int(s.not_ready_error_polls))
        self.frozen = FrozenBlockWatch(int(s.frozen_check_samples))
        self.mag_nack = MagNackFilter()
        self.mag = MagnetometerWatch(st.mag_every, s.mag_stale_timeout_s, s.mag_retry_interval_s)
        self.chip_state_checks = 0
        self.who_am_i: int | None = None
        self.mag_available = False
        self.running = False
        self._fail_since_s: float | None = None
        self.samples = self.mag_samples = 0
        self._temperature_count = 0  # IMU samples published since the start-up

        # no QoS event handlers (rclpy's default incompatible-QoS warning handler of each publisher is visited in
        # Python on every executor spin, at the 100 Hz poll)
        ev = PublisherEventCallbacks(use_default_callbacks=False)
        self.pub_imu = self.create_publisher(Imu, "imu/data_raw", DEFAULT_QOS_DEPTH, event_callbacks=ev)
        self.pub_mag = self.create_publisher(MagneticField, "imu/mag", DEFAULT_QOS_DEPTH, event_callbacks=ev)
        self.pub_temperature = self.create_publisher(Temperature, "imu/temperature", DEFAULT_QOS_DEPTH,
                                                     event_callbacks=ev)
        self.periodic = self.create_timer(1.0 / self.odr_hz, self._poll, autostart=False)

    def _start(self) -> None:
        """Open the bus if needed and run the start-up steps (docs/devices.md §4.3)."""
        self.running = False
        self._fail_since_s = None
        if self.open_device("icm20948") is None:
            return
        if self.regs is None:
            self.mag_device = I2CDevice(self.device.bus, p.AK09916_ADDRESS, "ak09916", backoff_s=0.0,
                                        raw_tap=self.raw.i2c_tap)
            self.regs = BankedRegisters(self.device)
        self.mag_device.bus = self.device.bus  # the devices keep their counters across reopened buses
        self.regs.invalidate()
        self.mag_available = False
        self._temperature_count = 0
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
            self._after.schedule(result.wait_s, self._run_steps)
        else:
            self._started()

    def _fail(self, reason: str) -> None:
        self.startup = None
        super()._fail(reason)

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
        self.mag.started(self._now_s(), self.mag_available)
        if self.bias.start():
            self.diag.set_state("estimating gyro bias", DiagnosticStatus.OK,
                                f"estimating gyro bias for {self.bias.duration_s:g} s (keep the vehicle still)")
        else:
            self.diag.set_state("running", DiagnosticStatus.OK, "running")
        self.get_logger().info(
            f"ICM-20948 ready at {self.odr_hz:.2f} Hz (FS {p.ACCEL_RANGE_G[self.config.accel_fs_sel]:g} g, "
            f"{p.GYRO_RANGE_DPS[self.config.gyro_fs_sel]:g} dps, DLPFCFG {self.config.gyro_dlpfcfg}), magnetometer "
            f"{self.mag_mode_name}: {'ok' if self.mag_available else 'unavailable'}")
        self.periodic.reset()

    def _poll(self) -> None:
        self.raw.begin_batch()  # raw/icm20948: the poll's transactions in one message
        r = read_poll(self.regs, self.mag_device, self.mag_mode_name, self.mag_available, self.require_data_ready,
                      self.mag_nack)
        stamp = self.get_clock().now()
        for counter in r.counters:
            self.diag.count(counter)
        if r.error is not None:
            self.raw.flush()
            self._poll_failed(r.error)
            return
        self._fail_since_s = None
        if self.diag.state == "i2c error":
            self.diag.set_state("running", DiagnosticStatus.OK, "running")
        self._process(r.block, r.mag_block, stamp, r.ready)
        self.raw.flush()

    def _data_ready_gate(self, ready: bool | None) -> bool:
        """Count a poll without RAW_DATA_0_RDY (``not_ready``); ERROR ``data_ready`` after
        ``not_ready_error_polls`` in a row, cleared by the next ready sample. Returns True when the sample may be
        published (ready, or unknown)."""
        verdict = self.data_ready.update(ready)
        if ready is False:
            self.diag.count("not_ready")
        if verdict.raise_error:
            self.alarm("data_ready", verdict.text)
        if verdict.clear_error:
            self.diag.clear("data_ready")
        return verdict.publish

    def _poll_failed(self, exc: Exception) -> None:
        self.regs.invalidate()
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
        if self.stuck_reading(block, "identical accel/gyro/temperature"):
            if self.stuck.raised:
                self._check_asleep()
            return
        if not self._data_ready_gate(ready):
            return  # the registers still hold the sample of an earlier poll (RAW_DATA_0_RDY not set)
        if sample.accel_saturated or sample.gyro_saturated:
            self.diag.count("saturated_samples")
        if self.bias.add(stamp.nanoseconds * 1e-9, sample.gyro_rad_s, sample.accel_m_s2) is not None:
            self._bias_done(self.bias.result)
        stamp_msg = stamp.to_msg()

        # REP-145, no orientation estimate; serialised by rosbags and published as bytes (51 Hz without rclpy's
        # object conversion: 0.30-0.31 -> 0.23-0.25 ms per publish here, hindrax_drivers.lean_cdr)
        acc = self.rotation @ sample.accel_m_s2
        gyr = self.rotation @ (sample.gyro_rad_s - self.bias.bias_rad_s)
        self.pub_imu.publish(imu_cdr(stamp.nanoseconds, self.frames["frame_id"], acc, gyr, self.settings.accel_cov,
                                     self.settings.gyro_cov))
        if self._temperature_count % self.settings.temperature_every == 0:
            self.pub_temperature.publish(Temperature(header=Header(stamp=stamp_msg, frame_id=self.frames["frame_id"]),
                                                     temperature=float(sample.temperature_c),
                                                     variance=self.settings.temperature_var))
        self._temperature_count += 1

        now_s = self._now_s()
        if mag_block is not None:
            self._publish_mag(p.parse_ak09916_block(mag_block), stamp_msg, now_s)
        self.diag.published()
        self._watch_magnetometer(now_s)

    def _watch_magnetometer(self, now_s: float) -> None:
        """After a published sample: a lost magnetometer, a re-initialisation due, one step of it
        (:class:`~hindrax_drivers.icm20948.core.MagnetometerWatch`)."""
        text = self.mag.stale(now_s) if self.mag_available else ""
        if text:
            self.alarm("magnetometer", text, "mag_lost")
            self.mag_available = False
            self._begin_mag_retry(now_s)
            return
        if self.mag.retry_due(now_s):
            self.diag.count("mag_retries")
            self.get_logger().warn(f"AK09916 still missing: re-initialising it (every {self.mag.retry_interval_s:g} "
                                   "s)", throttle_duration_sec=30.0)
            self._begin_mag_retry(now_s)
        if not self.mag.step_due(now_s):
            return
        if not self.startup.finished:
            self.mag.step_due_s = now_s + self.startup.step().wait_s
            return
        self.mag.finished(now_s, self.mag_available)
        if self.mag_available:
            self.mag_nack.reset()
            self.get_logger().info("AK09916 answers again: publishing imu/mag")

    def _begin_mag_retry(self, now_s: float) -> None:
        """Re-initialise only the magnetometer, one step per poll (the accel/gyro polls go on: at most one missed
        sample, where the whole start-up with its device reset cost 340-350 ms of samples every retry)."""
        self.startup = StartupSequence(self.regs, self.mag_device, self.config, self.mag_mode_name, self.mag_mode,
                                       self._on_magnetometer, magnetometer_only=True)
        self.mag.begin(now_s)

    def _publish_mag(self, mag: p.MagSample, stamp_msg, now_s: float) -> None:
        if mag.data_overrun:
            self.diag.count("mag_overrun")
        if mag.data_ready and mag.overflow:
            self.diag.count("mag_overflow")
        if not self.mag.sample(now_s, mag.data_ready, mag.overflow):
            return
        msg = MagneticField(header=Header(stamp=stamp_msg, frame_id=self.frames["frame_id"]))
        msg.magnetic_field.x, msg.magnetic_field.y, msg.magnetic_field.z = (
            float(v) for v in self.rotation @ mag.magnetic_field_t)
        self.pub_mag.publish(msg)  # magnetic_field_covariance stays 0: unknown (sensor_msgs/MagneticField)
        self.mag_samples += 1

    def _bias_done(self, result: GyroBiasResult) -> None:
        if result.still:
            self.diag.clear("gyro_bias")
            self.get_logger().info(result.message)
        else:
            self.diag.warn("gyro_bias", result.message)
            self.get_logger().warn(result.message)
        self.diag.set_state("running", DiagnosticStatus.OK, "running")

    def _reset_detected(self, zero_block: bool) -> bool:
        """Read USER_CTRL..PWR_MGMT_1 back; on the state of a reset chip restart the start-up (True)."""
        self.chip_state_checks += 1
        try:
            state = self.regs.read(p.USER_CTRL, CHIP_STATE_LENGTH)
        except I2CError as exc:
            self._poll_failed(exc)
            return True  # unknown: the suspect sample is dropped
        problems = chip_reset_problems(state, self.mag_mode_name == "i2c_master" and self.mag_available)
        if not problems:
            return False
        seen = "all-zero data" if zero_block else f"{self.frozen.repeats + 1} identical samples"
        self.alarm("chip_reset", f"chip reset detected ({', '.join(problems)}; {seen}): re-initialising", "chip_resets")
        self._restart()
        return True

    def _restart(self) -> None:
        """A chip that reset: the data watches forgotten, the start-up again."""
        self.frozen.reset()
        self.stuck.reset()
        self._start()

    def _check_asleep(self) -> None:
        """A frozen chip may have been reset by a power glitch (asleep after reset): start again if so."""
        try:
            pwr = self.regs.read(p.PWR_MGMT_1)[0]
        except I2CError:
            self.regs.invalidate()
            return
        if pwr & p.PWR_MGMT_1_SLEEP:
            self.get_logger().error("ICM-20948 found asleep (reset by a power glitch?): restarting the start-up")
            self.diag.count("unexpected_sleep")
            self._restart()

    def _diag_extra(self):
        stats = self.device.stats.diagnostics() if self.device is not None else []
        return diagnostic_values(self.config, self.who_am_i, self.sample_rate_hz, self.mag_mode_name,
                                 self.mag_available, self.mag_samples, self.startup_attempts, self.bias.bias_rad_s,
                                 self.bias.status) + stats


def main(args=None) -> int:
    """``python -m hindrax_drivers.icm20948.node --ros-args --params-file ros_ws/config/hindrax.yaml`` (Pi)."""
    return run_node(Icm20948Node, args)


if __name__ == "__main__":
    raise SystemExit(main())
