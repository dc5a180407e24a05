"""ESC output node: thruster pulse widths and the lights channel through a PCA9685 on I2C.

Safety behaviour (design.md §8, hardware.md §5.2):

- From start-up every thruster channel is held at neutral (``thrusters.pulse_width_neutral_us``, 1500 us)
  and the lights at ``lights.pulse_width_off_us``: the ESC arms only after seeing neutral for a few seconds.
- Thrust is accepted only after ``esc.arming_time_s`` at neutral **and** an explicit arm request on the
  ``esc/set_armed`` service (hindrax_msgs/SetArmed). Disarm is always accepted.
- Watchdog: if no command arrives on ``thrusters/command_pulse_width`` for ``esc.watchdog_timeout_s``, every
  channel is written neutral at the next output tick, i.e. within one output period
  (1 / ``esc.output_rate_hz``). The same on disarm, on any exception in the output path, and on
  shutdown (:meth:`EscNode.close`, called for SIGINT/SIGTERM by :func:`run_node`).
- Commands are clamped to [``pulse_width_min_us``, ``pulse_width_max_us``]; per-channel reversal (mirror
  about neutral) and trim are applied after the clamp, and the result is clamped again; an optional slew
  limit ``esc.slew_rate_us_per_s`` bounds the change per tick.

Subscribes ``thrusters/command_pulse_width`` (hindrax_msgs/ThrusterPwm, thruster order) and
``lights/brightness`` (std_msgs/Float64, 0-1, mapped linearly from ``pulse_width_off_us`` to
``pulse_width_full_us``). Publishes ``thrusters/pulse_width`` (hindrax_msgs/ThrusterPwm: the widths actually
written, decoded back from the register counts, and the armed state), ``raw/pca9685``
(hindrax_msgs/RawDeviceData of every I2C transaction) and ``/diagnostics``.

The bus is injected: ``smbus2.SMBus(esc.i2c_bus)`` on the Pi, an
:class:`~hindrax_drivers.transport.emulated_i2c.EmulatedI2CBus` holding a
:class:`~hindrax_drivers.pca9685.emulator.Pca9685Emulator` in tests and simulation.
Time: ROS time (``use_sim_time`` supported) for the watchdog and arming timer.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus
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
        """(n,) neutral widths; also resets the slew-limiter state (neutral is always immediate)."""
        self.current = np.full(len(self.channels), self.neutral_us)
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

    def __init__(self, bus: Any = None, **kwargs: Any):
        super().__init__("esc", **kwargs)
        cfg = load_node_config(self, ("thrusters", "esc", "lights"))
        self.cfg = cfg
        t = cfg.thrusters
        esc = cfg.section("esc")
        self.period_s = 1.0 / esc["output_rate_hz"]
        self.watchdog_s = esc["watchdog_timeout_s"]
        self.arming_time_s = esc["arming_time_s"]
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
        self.armed = False
        self.command: np.ndarray | None = None
        self.command_time = None
        self.written = self.output.neutral()
        self.start_time = self.get_clock().now()

        self.pub_written = self.create_publisher(ThrusterPwm, "thrusters/pulse_width", 10)
        self.create_subscription(ThrusterPwm, "thrusters/command_pulse_width", self.on_command, 10)
        self.create_subscription(Float64, "lights/brightness", self.on_lights, 10)
        self.create_service(SetArmed, "esc/set_armed", self.on_set_armed)
        self.diagnostics = DiagnosticsPublisher(self, [self.diag], extra=self._diag_extra)
        self._configure_chip()
        self.timer = self.create_timer(self.period_s, self.tick)

    # -- device
    def _configure_chip(self) -> None:
        """MODE2, frequency (sleep, PRE_SCALE, wake, restart), then neutral on every used channel."""
        try:
            self.device.write_sequence(p.startup_sequence(self.prescale))
            self._write(self.output.neutral(), self.lights_off_us)
            self.diag.set_state("holding neutral", DiagnosticStatus.OK, "holding neutral, disarmed")
        except I2CError as exc:
            self.diag.count("i2c_error")
            self.diag.set_state("i2c error", DiagnosticStatus.ERROR, str(exc))
            self.get_logger().error(f"PCA9685 start-up failed: {exc}")

    def _write(self, widths_us: np.ndarray, lights_us: float) -> None:
        """Write the thruster channels (and the lights channel), grouped in auto-increment block writes."""
        per_channel = {int(ch): float(w) for ch, w in zip(self.output.channels, widths_us)}
        per_channel[self.lights_channel] = float(lights_us)
        chans = sorted(per_channel)
        run: list[int] = []
        for ch in chans + [None]:
            if ch is not None and (not run or (ch == run[-1] + 1 and len(run) < 8)):
                run.append(ch)
                continue
            data = b"".join(p.channel_bytes_for_pulse(per_channel[c], self.prescale, self.oscillator_hz)
                            for c in run)
            self.device.write_block(p.led_register(run[0]), data)
            run = [ch] if ch is not None else []
        self.written = np.array([self._decoded(w) for w in widths_us])
        self.lights_us = lights_us

    def _decoded(self, width_us: float) -> float:
        counts = p.pulse_width_to_counts(width_us, self.prescale, self.oscillator_hz)
        return p.counts_to_pulse_width_us(counts, self.prescale, self.oscillator_hz)

    # -- inputs
    def on_command(self, msg: ThrusterPwm) -> None:
        self.command = np.array(msg.pulse_width_us, dtype=float)
        self.command_time = self.get_clock().now()

    def on_lights(self, msg: Float64) -> None:
        b = msg.data
        if not math.isfinite(b):
            self.get_logger().warn(f"lights brightness {b} rejected (expected 0-1)")
            return
        b = min(max(b, 0.0), 1.0)
        self.lights_us = self.lights_off_us + b * (self.lights_full_us - self.lights_off_us)

    def arming_remaining_s(self) -> float:
        """Seconds still needed at neutral before arming is accepted (0 when ready)."""
        held = (self.get_clock().now() - self.start_time).nanoseconds * 1e-9
        return max(0.0, self.arming_time_s - held)

    def on_set_armed(self, request: SetArmed.Request, response: SetArmed.Response) -> SetArmed.Response:
        if not request.arm:
            self.armed = False
            self.command = None
            self._safe_neutral("disarmed")
            response.success, response.armed, response.message = True, False, "disarmed"
            return response
        remaining = self.arming_remaining_s()
        if remaining > 0.0:
            response.success, response.armed = False, self.armed
            response.message = f"ESC arming: {remaining:.1f} s more at neutral needed (esc.arming_time_s)"
            return response
        if self.diag.state == "i2c error":
            response.success, response.armed, response.message = False, False, "PCA9685 not reachable"
            return response
        self.armed = True
        self.command = None  # thrust only from commands that arrive after arming
        response.success, response.armed, response.message = True, True, "armed"
        return response

    # -- output tick
    def tick(self) -> None:
        now = self.get_clock().now()
        try:
            fresh = (self.command is not None and self.command_time is not None
                     and (now - self.command_time).nanoseconds * 1e-9 <= self.watchdog_s)
            if self.armed and self.command is not None and not fresh:
                self.watchdog_trips += 1
                self.command = None
                self.get_logger().warn(f"watchdog: no command for {self.watchdog_s:g} s, outputs neutral")
            if self.armed and fresh:
                widths = self.output.target(self.command, self.period_s)
                state = "armed, commanding"
            else:
                widths = self.output.neutral()
                state = "armed, neutral" if self.armed else "disarmed, neutral"
            self._write(widths, self.lights_us)
            self.diag.set_state(state, DiagnosticStatus.OK)
        except Exception as exc:  # noqa: BLE001 - any fault in the output path must end at neutral
            self.diag.count("output_exception")
            self.get_logger().error(f"output fault, writing neutral: {exc}", throttle_duration_sec=1.0)
            self.command = None
            self._safe_neutral(f"fault: {exc}")
        self._publish_written(now)

    def _safe_neutral(self, reason: str) -> None:
        try:
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

    def _diag_extra(self):
        return [("armed", self.armed), ("watchdog_trips", self.watchdog_trips),
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
