"""ESC output node: thruster pulse widths and the lights channel through a PCA9685 on I2C.

Safety behaviour (docs/architecture.md §8, docs/devices.md §5.2):

- From start-up every thruster channel is held at neutral (``thrusters.pulse_width_neutral_us`` plus the
  channel's ``trim_us``) and the lights at ``lights.pulse_width_off_us``: the ESC arms only after seeing neutral
  for a few seconds. Start-up never lets old channel values run: every output is switched full OFF, the chip is
  put to sleep, PRE_SCALE and neutral are written, and only then is it woken and restarted
  (:func:`~.protocol.safe_startup_sequence`); the result is read back before anything else happens.
- Thrust is accepted only after an explicit arm request on the ``esc/set_armed`` service (hindrax_msgs/SetArmed),
  with ``esc.oscillator_calibrated`` true (neutral on the wire depends on the part's oscillator, 23-27 MHz; see
  ``hindrax esc calibrate``) and ``esc.arming_time_s`` after neutral was confirmed on the chip by read-back (not
  after node creation: a bus that was down at start delays it). Disarm is always accepted.
- Event-driven output: an armed command is written to the chip in its own subscription callback. The output
  tick (``esc.output_rate_hz``, ROS time) is the watchdog: if no command arrives on
  ``thrusters/command_pulse_width`` for ``esc.watchdog_timeout_s``, every channel is written neutral at the next
  tick, i.e. within one output period. A second, steady-clock watchdog (``time.monotonic``) does the same when
  ROS time stops (``use_sim_time`` with a dead ``/clock``, where the ROS timers stand still). Neutral is also
  written on disarm, on any exception in the output path, and on shutdown (:meth:`EscNode.close`, called for
  SIGINT/SIGTERM by :func:`run_node`).
- Read-back: every ``esc.readback_interval_s`` the tick reads MODE1, PRE_SCALE and the written channel registers;
  a mismatch (a brown-out reset leaves the chip asleep with every output off) re-initialises the chip at neutral,
  disarms (the ESCs must see neutral for the arming time again) and raises a ``/diagnostics`` warning
  (``errors.chip_reinit``, message "read-back mismatch ...").
- Commands are clamped to [``pulse_width_min_us``, ``pulse_width_max_us``]; per-channel reversal (mirror
  about neutral) and trim are applied after the clamp, and the result is clamped again; an optional slew
  limit ``esc.slew_rate_us_per_s`` bounds the change per step.

Subscribes ``thrusters/command_pulse_width`` (hindrax_msgs/ThrusterPwm, thruster order) and
``lights/brightness`` (std_msgs/Float64, 0-1, mapped linearly from ``pulse_width_off_us`` to
``pulse_width_full_us``). Publishes ``thrusters/pulse_width`` (hindrax_msgs/ThrusterPwm: the widths actually
written, decoded back from the register counts, and the armed state; on every write, and at a tick when nothing
was written since the previous one), ``raw/pca9685``
(hindrax_msgs/RawDeviceData of every I2C transaction) and ``/diagnostics``.

The bus is injected: ``smbus2.SMBus(esc.i2c_bus)`` on the Pi, an
:class:`~hindrax_drivers.transport.emulated_i2c.EmulatedI2CBus` holding a
:class:`~hindrax_drivers.pca9685.emulator.Pca9685Emulator` in tests and simulation.
Time: ROS time (``use_sim_time`` supported) for the output tick, watchdog, read-back and arming timer;
the steady clock only for the second watchdog.
"""
from __future__ import annotations

import math
import time
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from std_msgs.msg import Float64

from hindrax_msgs.msg import ThrusterPwm
from hindrax_msgs.srv import SetArmed

from ..node_common import DeviceDiagnostics, DiagnosticsPublisher, RawDataPublisher, load_node_config, run_node
from ..transport.i2c import I2CDevice, I2CError, open_smbus
from . import protocol as p


class EscOutput:
    """Pure output logic of the ESC node (no ROS): command -> per-channel pulse widths.

    channels (n,): PCA9685 channel of each thruster; reversed (n,) bool; trim_us (n,);
    limits and neutral in us; slew_rate_us_per_s (0 = off). ``target(command, armed, fresh, dt_s)``
    returns the (n,) pulse widths to write now. Raises :class:`ValueError` for a command of the wrong
    length or with a non-finite value (the node then writes neutral).
    """

    def __init__(self, channels, reversed_, trim_us, min_us: float, neutral_us: float, max_us: float,
                 slew_rate_us_per_s: float = 0.0):
        self.channels = np.asarray(channels, dtype=int)
        self.reversed = np.asarray(reversed_, dtype=bool)
        self.trim_us = np.asarray(trim_us, dtype=float)
        self.min_us, self.neutral_us, self.max_us = float(min_us), float(neutral_us), float(max_us)
        self.slew = float(slew_rate_us_per_s)
        self.current = np.full(len(self.channels), self.neutral_us)

    def neutral(self) -> np.ndarray:
        """(n,) neutral widths: ``neutral_us + trim_us`` per channel, clamped to the limits (the same widths
        :meth:`target` gives for a neutral command). Also resets the slew-limiter state (neutral is immediate)."""
        self.current = np.clip(np.full(len(self.channels), self.neutral_us) + self.trim_us, self.min_us, self.max_us)
        return self.current.copy()

    def target(self, command, dt_s: float) -> np.ndarray:
        """Pulse widths to write for a fresh, armed ``command`` (thruster order, us)."""
        cmd = np.asarray(command, dtype=float)
        if cmd.shape != self.current.shape:
            raise ValueError(f"command has {cmd.size} pulse widths, expected {self.current.size}")
        if not np.all(np.isfinite(cmd)):
            raise ValueError(f"command contains a non-finite pulse width: {cmd.tolist()}")
        out = np.clip(cmd, self.min_us, self.max_us)
        out = np.where(self.reversed, 2.0 * self.neutral_us - out, out) + self.trim_us
        out = np.clip(out, self.min_us, self.max_us)
        if self.slew > 0.0 and dt_s > 0.0:
            step = self.slew * dt_s
            out = np.clip(out, self.current - step, self.current + step)
        self.current = out
        return out.copy()


class EscNode(Node):
    """PCA9685 ESC output node (see the module docstring). ``bus``: SMBus-like object (default smbus2)."""

    #: MODE1 as read back from a configured chip: awake, auto-increment, All-Call, no RESTART pending.
    EXPECTED_MODE1 = p.MODE1_AI | p.MODE1_ALLCALL

    def __init__(self, bus: Any = None, **kwargs: Any):
        super().__init__("esc", **kwargs)
        cfg = load_node_config(self, ("thrusters", "esc", "lights"))
        self.cfg = cfg
        t = cfg.thrusters
        esc = cfg.section("esc")
        self.period_s = 1.0 / esc["output_rate_hz"]
        self.watchdog_s = esc["watchdog_timeout_s"]
        #: steady-clock (time.monotonic) watchdog: see :meth:`set_steady_watchdog_timeout`
        self.steady_watchdog_s = esc["watchdog_timeout_s"]
        self.arming_time_s = esc["arming_time_s"]
        self.readback_interval_s = esc["readback_interval_s"]
        self.oscillator_calibrated = bool(esc["oscillator_calibrated"])
        self.output = EscOutput([th.esc_channel for th in t.thrusters], [th.reversed for th in t.thrusters],
                                [th.trim_us for th in t.thrusters], t.pulse_width_min_us, t.pulse_width_neutral_us,
                                t.pulse_width_max_us, esc["slew_rate_us_per_s"])
        lights = cfg.section("lights")
        self.lights_channel = lights["esc_channel"]
        self.lights_off_us, self.lights_full_us = lights["pulse_width_off_us"], lights["pulse_width_full_us"]
        self.lights_us = self.lights_off_us
        self.oscillator_hz = esc["oscillator_hz"]
        self.prescale = p.esc_prescale(esc["pwm_frequency_hz"], self.oscillator_hz)

        if bus is None:
            bus = open_smbus(esc["i2c_bus"])
        self.raw = RawDataPublisher(self, "pca9685")
        self.device = I2CDevice(bus, esc["i2c_address"], "pca9685", raw_tap=self.raw.i2c_tap)
        now_s = lambda: self.get_clock().now().nanoseconds * 1e-9  # noqa: E731
        self.diag = DeviceDiagnostics("hindrax/esc_pca9685", f"i2c-{esc['i2c_bus']}@0x{esc['i2c_address']:02x}",
                                      now_s)
        self.watchdog_trips = 0
        self.steady_watchdog_trips = 0
        self.chip_reinits = 0
        self.last_chip_reinit_monotonic: float | None = None  # time.monotonic() of the last detection
        self.armed = False
        self.command: np.ndarray | None = None
        self.command_time = None
        self.written = self.output.neutral()
        self._expected: dict[int, bytes] = {}  # channel -> the 4 LEDn bytes last written
        self._written_key: tuple | None = None  # (widths, lights) last written, to skip identical writes
        self._last_target_time = None
        #: ROS time at which neutral was read back from the chip (the arming timer starts here), or None
        self.neutral_confirmed_time = None
        self._last_readback = None
        self._last_configure_attempt = None
        self._published_since_tick = False
        self._steady_last = time.monotonic()
        self._steady_command = self._steady_last
        self._steady_age_s = 0.0
        self.start_time = self.get_clock().now()

        self.pub_written = self.create_publisher(ThrusterPwm, "thrusters/pulse_width", 10)
        self.create_subscription(ThrusterPwm, "thrusters/command_pulse_width", self.on_command, 10)
        self.create_subscription(Float64, "lights/brightness", self.on_lights, 10)
        self.create_service(SetArmed, "esc/set_armed", self.on_set_armed)
        self.diagnostics = DiagnosticsPublisher(self, [self.diag], extra=self._diag_extra)
        self._configure_chip()
        self.timer = self.create_timer(self.period_s, self.tick)
        self.steady_timer = self.create_timer(self.period_s, self.steady_check,
                                              clock=Clock(clock_type=ClockType.STEADY_TIME))

    def set_steady_watchdog_timeout(self, seconds: float) -> None:
        """Steady-clock watchdog timeout, s (default ``esc.watchdog_timeout_s``).

        The steady watchdog counts wall time (``time.monotonic``) during which the executor runs but no command
        arrives; it covers a ROS clock that stops (``use_sim_time`` with a dead ``/clock``), where the ROS-time
        watchdog and output tick stand still. An in-process simulator that holds simulated time on purpose (the
        stepped graph of :func:`hindrax_ident.bringup.build_graph`) widens it so that a hold never trips it.
        """
        if not seconds > 0.0:
            raise ValueError(f"steady watchdog timeout must be > 0 s, got {seconds}")
        self.steady_watchdog_s = float(seconds)

    # -- device
    def _configure_chip(self) -> bool:
        """Put the chip in a known state with neutral on every used channel, then confirm it by reading it back.

        Order (fault-safe): MODE2; every output full OFF (ALL_LED_OFF_H bit 4) so that nothing a previous process
        left in the channel registers can run again; sleep; PRE_SCALE; neutral (and lights off) written into the
        channel registers while asleep; wake; RESTART (:func:`~.protocol.safe_startup_sequence`, datasheet
        §7.3.1.1: RESTART resumes the channel registers, which now hold neutral). The arming timer starts when
        the read-back matches (:meth:`arming_remaining_s`). Returns True on success.
        """
        self._last_configure_attempt = self.get_clock().now()
        self.neutral_confirmed_time = None
        before, after = p.safe_startup_sequence(self.prescale)
        try:
            self.device.write_sequence(before)
            self._written_key = None
            self._write(self.output.neutral(), self.lights_off_us)
            self.device.write_sequence(after)
            mismatch = self._readback_mismatch()
        except I2CError as exc:
            self.diag.count("i2c_error")
            self.diag.set_state("i2c error", DiagnosticStatus.ERROR, f"PCA9685 start-up failed: {exc}")
            self.get_logger().error(f"PCA9685 start-up failed: {exc}", throttle_duration_sec=5.0)
            return False
        if mismatch:
            self.diag.count("readback_mismatch")
            self.diag.set_state("i2c error", DiagnosticStatus.ERROR, f"PCA9685 start-up not confirmed: {mismatch}")
            return False
        now = self.get_clock().now()
        self.neutral_confirmed_time = now
        self._last_readback = now
        self.diag.set_state("holding neutral", DiagnosticStatus.OK, "holding neutral, disarmed")
        return True

    def _readback_mismatch(self) -> str:
        """Read MODE1, PRE_SCALE and every written channel back; '' when they match what was written, else why.

        Raises :class:`I2CError` when the chip does not answer."""
        mode1 = self.device.read_byte_data(p.MODE1)
        if mode1 != self.EXPECTED_MODE1:
            return f"MODE1 0x{mode1:02x}, expected 0x{self.EXPECTED_MODE1:02x} (chip reset or asleep)"
        prescale = self.device.read_byte_data(p.PRE_SCALE)
        if prescale != self.prescale:
            return f"PRE_SCALE {prescale}, expected {self.prescale}"
        for run in self._channel_runs(sorted(self._expected)):
            data = self.device.read_block(p.led_register(run[0]), 4 * len(run))
            for i, ch in enumerate(run):
                want = self._expected[ch]
                got = bytes(data[4 * i:4 * i + 4])
                # reserved H bits 7:5 read 0 (datasheet §7.3.3); compare what the chip keeps
                if bytes(b & m for b, m in zip(got, (0xFF, 0x1F, 0xFF, 0x1F))) != \
                        bytes(b & m for b, m in zip(want, (0xFF, 0x1F, 0xFF, 0x1F))):
                    return f"channel {ch} registers {got.hex()}, expected {want.hex()}"
        return ""

    @staticmethod
    def _channel_runs(channels: list[int]) -> list[list[int]]:
        """Consecutive channels in runs of at most 8 (32-byte SMBus blocks)."""
        runs: list[list[int]] = []
        for ch in channels:
            if runs and ch == runs[-1][-1] + 1 and len(runs[-1]) < 8:
                runs[-1].append(ch)
            else:
                runs.append([ch])
        return runs

    def _write(self, widths_us: np.ndarray, lights_us: float) -> bool:
        """Write the thruster channels (and the lights channel), grouped in auto-increment block writes.

        Skips the bus when the same widths are already on the chip (the read-back confirms them once per
        ``esc.readback_interval_s``). Returns True when it wrote."""
        key = (tuple(float(w) for w in widths_us), float(lights_us))
        if key == self._written_key:
            return False
        per_channel = {int(ch): float(w) for ch, w in zip(self.output.channels, widths_us)}
        per_channel[self.lights_channel] = float(lights_us)
        self.raw.begin_batch()  # raw/pca9685: the block writes of one update in one message
        decoded: dict[int, float] = {}
        for run in self._channel_runs(sorted(per_channel)):
            block, widths = p.channel_block_for_pulses([per_channel[c] for c in run], self.prescale,
                                                       self.oscillator_hz)
            self._written_key = None  # unknown until the whole write succeeded
            self.device.write_block(p.led_register(run[0]), block)
            self._expected.update((c, block[4 * i:4 * i + 4]) for i, c in enumerate(run))
            decoded.update(zip(run, widths))
        self.raw.flush()  # (after a failed write the records are published with the next update's)
        self.written = np.array([decoded[int(ch)] for ch in self.output.channels])
        self.lights_us = lights_us
        self._written_key = key
        return True

    # -- inputs
    def on_command(self, msg: ThrusterPwm) -> None:
        """Store the command and, armed, write it at once (event-driven output; the tick is the watchdog)."""
        self.command = np.array(msg.pulse_width_us, dtype=float)
        now = self.get_clock().now()
        self.command_time = now
        self._steady_age_s = 0.0
        self._steady_command = time.monotonic()
        if self.armed and self.neutral_confirmed_time is not None:
            self._output(now)

    def on_lights(self, msg: Float64) -> None:
        b = msg.data
        if not math.isfinite(b):
            self.get_logger().warn(f"lights brightness {b} rejected (expected 0-1)")
            return
        b = min(max(b, 0.0), 1.0)
        self.lights_us = self.lights_off_us + b * (self.lights_full_us - self.lights_off_us)

    def arming_remaining_s(self) -> float:
        """Seconds still needed at neutral before arming is accepted (0 when ready).

        The time counts from the moment neutral was read back from the chip (not from node creation): while the
        chip has not been configured and confirmed, the whole ``esc.arming_time_s`` remains."""
        if self.neutral_confirmed_time is None:
            return self.arming_time_s
        held = (self.get_clock().now() - self.neutral_confirmed_time).nanoseconds * 1e-9
        return max(0.0, self.arming_time_s - held)

    def arm_refusal(self) -> str:
        """Why an arm request would be refused now ('' when it would be accepted)."""
        if not self.oscillator_calibrated:
            return ("esc.oscillator_calibrated is false: neutral on the wire depends on this PCA9685's oscillator "
                    "(nominal 25 MHz, parts measure 23-27 MHz). Measure the neutral pulse with a scope and run "
                    "`hindrax esc calibrate --measured-us X --write`")
        if self.neutral_confirmed_time is None:
            return "PCA9685 not confirmed at neutral (not reachable or its registers did not read back)"
        remaining = self.arming_remaining_s()
        if remaining > 0.0:
            return f"ESC arming: {remaining:.1f} s more at neutral needed (esc.arming_time_s)"
        return ""

    def on_set_armed(self, request: SetArmed.Request, response: SetArmed.Response) -> SetArmed.Response:
        if not request.arm:
            self.disarm("disarmed")
            response.success, response.armed, response.message = True, False, "disarmed"
            return response
        refusal = self.arm_refusal()
        if refusal:
            response.success, response.armed, response.message = False, self.armed, refusal
            return response
        self.armed = True
        self.command = None  # thrust only from commands that arrive after arming
        self.diag.clear("chip_reset")
        self.diag.set_state("armed, neutral", DiagnosticStatus.OK)
        response.success, response.armed, response.message = True, True, "armed"
        return response

    def disarm(self, reason: str) -> None:
        """Disarm and write neutral now (the disarm service, the supervisor, shutdown)."""
        self.armed = False
        self.command = None
        self._safe_neutral(reason)
        self._publish_written(self.get_clock().now())

    # -- output
    def _output(self, now) -> None:
        """Compute and write the widths for the current state (neutral unless armed with a fresh command)."""
        try:
            fresh = (self.command is not None and self.command_time is not None
                     and (now - self.command_time).nanoseconds * 1e-9 <= self.watchdog_s)
            if self.armed and self.command is not None and not fresh:
                self.watchdog_trips += 1
                self.command = None
                self.get_logger().warn(f"watchdog: no command for {self.watchdog_s:g} s, outputs neutral")
            if self.armed and fresh:
                dt_s = self.period_s if self._last_target_time is None else \
                    min(self.period_s, max(0.0, (now - self._last_target_time).nanoseconds * 1e-9))
                widths = self.output.target(self.command, dt_s)
                self._last_target_time = now
                state = "armed, commanding"
            else:
                widths = self.output.neutral()
                self._last_target_time = None
                state = "armed, neutral" if self.armed else "disarmed, neutral"
            wrote = self._write(widths, self.lights_us)
            if self.diag.state not in ("i2c error",) or wrote:
                self.diag.set_state(state, DiagnosticStatus.OK)
            if wrote:
                self._publish_written(now)
        except Exception as exc:  # noqa: BLE001 - any fault in the output path must end at neutral
            self.diag.count("output_exception")
            self.get_logger().error(f"output fault, writing neutral: {exc}", throttle_duration_sec=1.0)
            self.command = None
            self._safe_neutral(f"fault: {exc}")
            self._publish_written(now)

    def tick(self) -> None:
        """Output tick (ROS time, ``esc.output_rate_hz``): the ROS-time watchdog, (re)configuration of a chip
        that was not reachable, the register read-back every ``esc.readback_interval_s``, and the output."""
        now = self.get_clock().now()
        if self.neutral_confirmed_time is None:
            since = (now - self._last_configure_attempt).nanoseconds * 1e-9 if self._last_configure_attempt else 1e9
            if since >= self.readback_interval_s:
                self._configure_chip()
        elif (now - self._last_readback).nanoseconds * 1e-9 >= self.readback_interval_s:
            self._last_readback = now
            self._check_chip()
        if self.neutral_confirmed_time is not None:
            self._output(now)
        if not self._published_since_tick:
            self._publish_written(now)
        self._published_since_tick = False

    def _check_chip(self) -> None:
        """Read the chip back; on a mismatch (brown-out reset, sleep, lost registers) re-initialise it, disarm,
        and restart the arming timer (the ESCs must see neutral again), reporting it in diagnostics."""
        try:
            mismatch = self._readback_mismatch()
        except I2CError as exc:
            self.diag.count("i2c_error")
            self.diag.set_state("i2c error", DiagnosticStatus.ERROR, f"PCA9685 read-back failed: {exc}")
            return
        if not mismatch:
            return
        self.chip_reinits += 1
        self.last_chip_reinit_monotonic = time.monotonic()
        self.diag.count("chip_reinit")
        was_armed = self.armed
        self.armed = False
        self.command = None
        message = f"PCA9685 read-back mismatch: {mismatch}; re-initialised at neutral" + \
            (", disarmed (re-arm after esc.arming_time_s)" if was_armed else "")
        self.diag.warn("chip_reset", message)
        self.get_logger().error(message)
        self._configure_chip()
        self._publish_written(self.get_clock().now())

    def steady_check(self) -> None:
        """Steady-clock watchdog (``time.monotonic``, independent of ROS time; see
        :meth:`set_steady_watchdog_timeout`). Only executor-alive time counts (a gap between two checks counts at
        most two output periods), so a stalled process does not trip it when it resumes."""
        t = time.monotonic()
        gap, self._steady_last = t - self._steady_last, t
        if not (self.armed and self.command is not None):
            self._steady_age_s = 0.0
            return
        self._steady_age_s += min(max(gap, 0.0), t - self._steady_command, 2.0 * self.period_s)
        if self._steady_age_s > self.steady_watchdog_s:
            self.steady_watchdog_trips += 1
            self.watchdog_trips += 1
            self.command = None
            self.get_logger().warn(f"steady-clock watchdog: no command for {self.steady_watchdog_s:g} s of wall "
                                   f"time (ROS time stalled?), outputs neutral")
            self._safe_neutral("steady-clock watchdog")
            self._publish_written(self.get_clock().now())

    def _safe_neutral(self, reason: str) -> None:
        try:
            self._written_key = None  # always write: neutral must reach the chip even if we believe it is there
            self._last_target_time = None
            self._write(self.output.neutral(), self.lights_us)
            self.diag.set_state("neutral", DiagnosticStatus.WARN if reason.startswith("fault") else DiagnosticStatus.OK,
                                reason)
        except Exception as exc:  # noqa: BLE001 - bus down: report, keep running, retry next tick
            self.diag.count("i2c_error")
            self.diag.set_state("i2c error", DiagnosticStatus.ERROR, f"cannot write neutral: {exc}")

    def _publish_written(self, now) -> None:
        msg = ThrusterPwm(pulse_width_us=[float(x) for x in self.written], armed=self.armed)
        msg.header.stamp = now.to_msg()
        msg.header.frame_id = "base_link"
        self.pub_written.publish(msg)
        self.diag.published()
        self._published_since_tick = True

    def _diag_extra(self):
        return [("armed", self.armed), ("watchdog_trips", self.watchdog_trips),
                ("steady_watchdog_trips", self.steady_watchdog_trips), ("chip_reinits", self.chip_reinits),
                ("neutral_confirmed", self.neutral_confirmed_time is not None),
                ("oscillator_calibrated", self.oscillator_calibrated),
                ("arming_remaining_s", f"{self.arming_remaining_s():.1f}"), ("prescale", self.prescale),
                *self.device.stats.diagnostics()]

    def close(self) -> None:
        """Shutdown path: disarm and write neutral (SIGINT/SIGTERM via run_node, or destroy by the owner)."""
        self.armed = False
        self.command = None
        self._safe_neutral("shutdown")


def main(args=None) -> int:
    """``python -m hindrax_drivers.pca9685.node --ros-args --params-file ros_ws/config/hindrax.yaml`` (Pi)."""
    return run_node(EscNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
