"""ICM-20948 IMU node (TDK InvenSense ICM-20948 + AK09916 magnetometer on I2C; docs/devices.md §4): the I2C polls and
the messages. The start-up steps, each poll's reads, the data-ready, chip-reset and magnetometer decisions, the gyro
bias, the noise figures and the publishing rates are :mod:`hindrax_drivers.icm20948.core` (see its docstring).

The start-up runs from ROS timers (datasheet waits as one-shot timers, not sleeps); a failure is an ERROR with the
reason and is retried (:class:`~hindrax_common.node_support.i2c_node.I2cSensorNode`); a silent magnetometer is a WARN,
and no ``imu/mag``. Polls run at the achieved 1125 / (1 + div) Hz (100 Hz set -> 102.27 Hz); an I2C failure drops that
poll, failures lasting :data:`REINIT_AFTER_S` restart the start-up; 2 s of bit-identical samples raise the ERROR
``stuck``. Publishes (reliable, depth 10; stamped after the poll's reads; frame ``imu_link``, base_link's orientation at
the sensor by ``sensors.icm20948.mounting_rpy_rad``): ``imu/data_raw`` sensor_msgs/Imu (REP-145, no orientation, less
the gyro bias), ``imu/mag`` sensor_msgs/MagneticField (tesla, (hx, -hy, -hz), docs/devices.md §4.7; covariance 0 =
unknown), ``imu/temperature`` (degC), ``raw/icm20948`` (a poll's I2C transactions) and ``/diagnostics`` (ERRORs
``stuck``, ``chip_reset``, ``magnetometer``, ``data_ready``). The bus: ``smbus2.SMBus(sensors.icm20948.i2c_bus)`` on
the Pi, an :class:`~hindrax_drivers.icm20948.emulator.Icm20948Emulator` on an emulated bus in tests and simulation.
Alone: ``python -m hindrax_drivers.icm20948.node --ros-args --params-file ros_ws/config/hindrax.yaml``."""
from __future__ import annotations

from typing import Any

from diagnostic_msgs.msg import DiagnosticStatus
from sensor_msgs.msg import Imu, MagneticField, Temperature
from std_msgs.msg import Header

from hindrax_common.node_support.i2c_node import I2cSensorNode
from hindrax_common.cdr.lean_cdr import imu_cdr
from hindrax_common.node_support.node_common import declare_frame_ids, load_node_config, run_node
from hindrax_common.transport.i2c import I2CDevice, I2CError
from . import protocol as p
from .core import (BankedRegisters, DataReadyGate, FrozenBlockWatch, GyroBias, GyroBiasResult, ImuSettings,
                   MagnetometerWatch, MagNackFilter, PollFailures, StartupSequence, diagnostic_values, read_asleep,
                   read_chip_reset, read_poll)

__all__ = ["Icm20948Node", "main"]

#: I2C failures lasting this long (ROS time) restart the start-up sequence, s.
REINIT_AFTER_S = 1.0
FRAME_ID = "imu_link"  #: frame of every message (module docstring: base_link's orientation, at the sensor)


class Icm20948Node(I2cSensorNode):
    """ICM-20948 + AK09916 driver node (module docstring). bus: an ``smbus2.SMBus``-like object (default: opened from
    ``sensors.icm20948.i2c_bus``); kwargs go to ``rclpy.node.Node``. Raises ConfigError on an invalid configuration."""

    label = "ICM-20948"

    def __init__(self, bus: Any = None, **kwargs: Any):
        super().__init__("icm20948", **kwargs)
        self.frames = declare_frame_ids(self, {"frame_id": FRAME_ID})
        s = load_node_config(self, ("sensors.icm20948",)).sensors.icm20948
        self.sample_rate_hz = float(s.sample_rate_hz)
        self.settings = st = ImuSettings.from_section(s)
        self.config, self.odr_hz, self.rotation = st.config, st.odr_hz, st.rotation
        self.mag_mode_name, self.mag_mode = str(s.magnetometer_mode), st.mag_mode
        self.bias = GyroBias(s.estimate_gyro_bias, s.gyro_bias_duration_s, st.gyro_var, st.accel_var)
        for warning in st.warnings:
            self.get_logger().warn(warning)
        self.device = self.mag_device = self.regs = None  # made at the first start-up (open_device)
        self.startup: StartupSequence | None = None  # the start-up, or the magnetometer's re-initialisation
        self.setup_device("icm20948", s.i2c_bus, s.i2c_address, bus, self.odr_hz)
        self.require_data_ready = bool(s.require_data_ready)
        self.data_ready = DataReadyGate(int(s.not_ready_error_polls))
        self.frozen = FrozenBlockWatch(int(s.frozen_check_samples))
        self.mag_nack = MagNackFilter()
        self.mag = MagnetometerWatch(st.mag_every, s.mag_stale_timeout_s, s.mag_retry_interval_s,
                                     lambda: self._startup_sequence(magnetometer_only=True))
        self.who_am_i: int | None = None
        self.mag_available = self.running = False
        self.poll_failures = PollFailures(REINIT_AFTER_S)
        self.samples = self.mag_samples = 0
        self._temperature_count = 0  # IMU samples published since the start-up
        self.pub_imu = self.sensor_publisher(Imu, "imu/data_raw")
        self.pub_mag = self.sensor_publisher(MagneticField, "imu/mag")
        self.pub_temperature = self.sensor_publisher(Temperature, "imu/temperature")
        self.periodic = self.create_timer(1.0 / self.odr_hz, self._poll, autostart=False)

    def _start(self) -> None:
        """Open the bus if needed and run the start-up steps (docs/devices.md §4.3)."""
        self.running = False
        self.poll_failures.ok()
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
        self.startup = self._startup_sequence()
        self._run_steps()

    def _startup_sequence(self, magnetometer_only: bool = False) -> StartupSequence:
        return StartupSequence(self.regs, self.mag_device, self.config, self.mag_mode_name, self.mag_mode,
                               self._on_magnetometer, magnetometer_only=magnetometer_only)

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
            return self.diag.clear("magnetometer")
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
        self.get_logger().info(f"ICM-20948 ready at {self.settings.describe()}, magnetometer {self.mag_mode_name}: "
                               f"{'ok' if self.mag_available else 'unavailable'}")
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
        self.poll_failures.ok()
        if self.diag.state == "i2c error":
            self.diag.set_state("running", DiagnosticStatus.OK, "running")
        self._process(r.block, r.mag_block, stamp, r.ready)
        self.raw.flush()

    def _data_ready_gate(self, ready: bool | None) -> bool:
        """:class:`~hindrax_drivers.icm20948.core.DataReadyGate` with its counter and ERROR: True to publish."""
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
        self.get_logger().warn(f"ICM-20948 poll failed: {exc}", throttle_duration_sec=5.0)
        if self.poll_failures.failed(self._now_s()) == "restart":
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
        # REP-145, no orientation estimate; serialised by rosbags (hindrax_common.cdr.lean_cdr), published as bytes
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
        """After a published sample (:meth:`~hindrax_drivers.icm20948.core.MagnetometerWatch.after_sample`): the
        accel/gyro polls go on during a re-initialisation (no device reset)."""
        event = self.mag.after_sample(now_s, self.mag_available)
        if event == "lost":
            self.mag_available = False
            self.alarm("magnetometer", self.mag.text, "mag_lost")
        elif event == "retry":
            self.diag.count("mag_retries")
            self.get_logger().warn(f"AK09916 still missing: re-initialising it (every {self.mag.retry_interval_s:g} "
                                   "s)", throttle_duration_sec=30.0)
        elif event == "recovered":
            self.mag_nack.reset()
            self.get_logger().info("AK09916 answers again: publishing imu/mag")

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
        """Applied when still (:class:`~hindrax_drivers.icm20948.core.GyroBias`), else the WARN ``gyro_bias``."""
        self.diag.clear("gyro_bias") if result.still else self.diag.warn("gyro_bias", result.message)
        (self.get_logger().info if result.still else self.get_logger().warn)(result.message)
        self.diag.set_state("running", DiagnosticStatus.OK, "running")

    def _reset_detected(self, zero_block: bool) -> bool:
        """The chip state read back; on the state of a reset chip restart the start-up (True)."""
        try:
            problems = read_chip_reset(self.regs, self.mag_mode_name == "i2c_master" and self.mag_available)
        except I2CError as exc:
            self._poll_failed(exc)
            return True  # unknown: the suspect sample is dropped
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
            asleep = read_asleep(self.regs)
        except I2CError:
            self.regs.invalidate()
            return
        if asleep:
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
