"""ESC output node: thruster pulse widths and the lights channel through a PCA9685 on I2C (thin, over
:class:`.core.EscCore`, the decisions, and :class:`.chip.EscChip`, the registers).

The decisions (arm, refuse to arm, disarm, neutral, output state, the reason; the rules and their sources) are the
core's (:mod:`.core`, docs/architecture.md §8). This node does the ROS I/O and feeds the core:

- Chip: start-up and every recovery through :meth:`.chip.EscChip.configure` (neutral first), confirmed by
  read-back (:meth:`.core.EscCore.chip_confirmed`); a failed write or read-back is :meth:`.core.EscCore.chip_lost`
  (``OUTPUT_UNKNOWN``, widths NaN on ``thrusters/pulse_width``, never "neutral"); a read-back mismatch every
  ``esc.readback_interval_s`` (brown-out) re-initialises the chip and disarms. No bus at start-up: the node keeps
  running, reports ERROR "no I2C bus" and picks the bus up when it appears.
- Inputs, all by callbacks in both clock modes: ``thrusters/command_pulse_width`` (hindrax_msgs/ThrusterPwm,
  thruster order; an armed command is written when it arrives, unless it comes sooner after the last chip write than
  that write lasted: then by the next output tick (coalesced: a backlog of commands behind a slow bus costs one
  write, not one each, and cannot delay the tick and its heartbeat); only from ``thrust_allocation``, checked in the
  graph), ``supervisor/heartbeat`` and ``guard/heartbeat`` (through :class:`~hindrax_drivers.liveness.
  HeartbeatWatch`: a forged or replayed beat, a second publisher or another node name is a fault; aged on the
  steady clock in executor-alive time, :class:`~hindrax_drivers.liveness.AliveAge`; verdicts to
  :meth:`.core.EscCore.set_peers`), ``lights/brightness`` (std_msgs/Float64, 0-1 mapped linearly from
  ``lights.pulse_width_off_us`` to ``pulse_width_full_us``), the ``esc/set_armed`` service (hindrax_msgs/SetArmed).
- Ticks: on the system clock one steady-clock timer (``esc.output_rate_hz``) runs the safety tick
  (:meth:`EscNode.steady_check`: heartbeats, chip retries and read-back, the steady-clock watchdog for a stopped ROS
  clock, ROS-time steps) and then the output tick (:meth:`EscNode.tick`: the ROS-time command watchdog); with
  ``use_sim_time`` the output tick is a ROS-time timer of its own.
- Outputs: ``thrusters/pulse_width`` (the widths on the chip, decoded from the register counts, armed flag, output
  state; on every write and at a tick without one), ``esc/heartbeat`` (diagnostic_msgs/DiagnosticStatus every
  second steady tick, 25 Hz at 50 Hz: values ``output_state``, ``armed``, ``reason`` and the ``boot_id``/``seq``
  of :class:`~hindrax_drivers.liveness.HeartbeatPublisher`; ERROR while unknown; the output guard's sign of life),
  ``raw/pca9685`` (every I2C transaction) and ``/diagnostics``. Neutral is written on disarm, on any exception in
  the output path and on shutdown (:meth:`EscNode.close`, SIGINT/SIGTERM via
  :func:`run_node`).
- Node parameters outside the vehicle file (read-only, :data:`HEARTBEAT_TIMEOUT`, :data:`STEADY_WATCHDOG`):
  ``heartbeat_timeout_s`` (default ``esc.heartbeat_timeout_s``), ``steady_watchdog_timeout_s`` (default
  ``esc.watchdog_timeout_s``).

The bus is injected: ``smbus2.SMBus(esc.i2c_bus)`` on the Pi, an
:class:`~hindrax_drivers.transport.emulated_i2c.EmulatedI2CBus` holding a
:class:`~hindrax_drivers.pca9685.emulator.Pca9685Emulator` in tests and simulation.
"""
from __future__ import annotations

import math
import time
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.time import Time
from std_msgs.msg import Float64

from hindrax_msgs.msg import ThrusterPwm
from hindrax_msgs.srv import SetArmed

from ..lean_cdr import thruster_pwm_cdr
from rclpy.event_handler import SubscriptionEventCallbacks

from ..liveness import (HEARTBEAT_NAMES, AliveAge, ClockStepMonitor, HeartbeatPublisher, HeartbeatWatch, heartbeat_ok,
                        heartbeat_qos)
from ..config import Spec
from ..node_common import DeviceDiagnostics, DiagnosticsPublisher, RawDataPublisher, load_node_config, run_node
from ..node_parameters import declare_node_parameter
from ..transport.i2c import I2CDevice, I2CError, open_smbus
from ..transport.shared_emulation import open_shared_bus
from . import protocol as p
from .chip import EscChip
from .core import (GUARD_CONFIRM_S, RETRY_MAX_S, RETRY_MIN_S, STATE_NAMES, EscCore, EscOutput, command_source_fault,
                   heartbeat_verdict)

__all__ = ["EscNode", "EscOutput", "GUARD_CONFIRM_S", "RETRY_MIN_S", "RETRY_MAX_S", "main"]

COMMAND_TOPIC = "thrusters/command_pulse_width"
#: node parameter ``heartbeat_timeout_s`` (read-only; :func:`~hindrax_drivers.node_parameters.declare_node_parameter`)
HEARTBEAT_TIMEOUT = Spec("float", "the ESC refuses to arm, and disarms, when supervisor/heartbeat or guard/heartbeat "
                         "is older than this (steady clock), s; default esc.heartbeat_timeout_s, widened only where "
                         "the three safety nodes share one executor thread (hindrax bringup: none can stall alone)",
                         0.05, 10.0)
#: node parameter ``steady_watchdog_timeout_s``: the steady-clock watchdog counts wall time (time.monotonic) during
#: which the executor runs but no command arrives; it covers a ROS clock that stops (use_sim_time with a dead
#: /clock), where the ROS-time watchdog and output tick stand still
STEADY_WATCHDOG = Spec("float", "no command for this long of steady-clock time (the executor running) -> all neutral, "
                       "s; default esc.watchdog_timeout_s, widened only by an in-process simulator that holds "
                       "simulated time on purpose (hindrax bringup's stepped graph)", 0.02, 60.0)


class EscNode(Node):
    """PCA9685 ESC output node (see the module docstring). ``bus``: SMBus-like object (default smbus2)."""

    def __init__(self, bus: Any = None, **kwargs: Any):
        super().__init__("esc", **kwargs)
        cfg = load_node_config(self, ("thrusters", "esc", "lights"))
        self.cfg = cfg
        t = cfg.thrusters
        esc = cfg.esc
        self.period_s = 1.0 / esc.output_rate_hz
        #: steady-clock (time.monotonic) watchdog, s: parameter ``steady_watchdog_timeout_s`` (:data:`STEADY_WATCHDOG`)
        self.steady_watchdog_s = float(declare_node_parameter(self, "steady_watchdog_timeout_s", STEADY_WATCHDOG,
                                                              esc.watchdog_timeout_s))
        self.readback_interval_s = esc.readback_interval_s
        lights = cfg.lights
        self.lights_channel = lights.esc_channel
        self.lights_off_us, self.lights_full_us = lights.pulse_width_off_us, lights.pulse_width_full_us
        self.lights_us = self.lights_off_us
        self.oscillator_hz = esc.oscillator_hz
        self.prescale = p.esc_prescale(esc.pwm_frequency_hz, self.oscillator_hz)
        self.output = EscOutput([th.esc_channel for th in t.thrusters], [th.reversed for th in t.thrusters],
                                [th.trim_us for th in t.thrusters], t.pulse_width_min_us, t.pulse_width_neutral_us,
                                t.pulse_width_max_us, esc.slew_rate_us_per_s,
                                count_us=p.count_duration_us(self.prescale, self.oscillator_hz),
                                deadband_us=t.deadband_us)
        #: the decisions (arm, refuse, disarm, neutral, output state, reason): :mod:`.core`
        self.core = EscCore(self.output, arming_time_s=esc.arming_time_s, watchdog_timeout_s=esc.watchdog_timeout_s,
                            oscillator_calibrated=esc.oscillator_calibrated, clock=lambda: time.monotonic())

        self.i2c_bus_number, self.i2c_address = int(esc.i2c_bus), int(esc.i2c_address)
        self.raw = RawDataPublisher(self, "pca9685")
        #: the registers (:mod:`.chip`); its device is None until the bus is open
        self.chip = EscChip(self.i2c_address, self.prescale, self.oscillator_hz, self.output.channels,
                            self.lights_channel, self.raw)
        self.bus_error = ""
        if bus is not None:
            self.device = I2CDevice(bus, self.i2c_address, "pca9685", raw_tap=self.raw.i2c_tap)
        now_s = lambda: self.get_clock().now().nanoseconds * 1e-9  # noqa: E731
        self.diag = DeviceDiagnostics("hindrax/esc_pca9685", f"i2c-{esc.i2c_bus}@0x{esc.i2c_address:02x}",
                                      now_s)
        #: supervisor and guard heartbeat timeout, s: parameter ``heartbeat_timeout_s`` (:data:`HEARTBEAT_TIMEOUT`)
        self.heartbeat_timeout_s = float(declare_node_parameter(self, "heartbeat_timeout_s", HEARTBEAT_TIMEOUT,
                                                                esc.heartbeat_timeout_s))
        self.supervisor_age = AliveAge(2.0 * self.period_s)
        self.guard_age = AliveAge(2.0 * self.period_s)
        self.supervisor_ok, self.supervisor_message = False, ""
        self.guard_ok, self.guard_message = False, ""
        self.unknown_entries = 0
        self.last_unknown_monotonic: float | None = None
        self.clock_monitor = ClockStepMonitor(now_s)
        self.steady_watchdog_trips = 0
        self.chip_reinits = 0
        self.last_chip_reinit_monotonic: float | None = None  # time.monotonic() of the last detection
        self._last_target_time = None
        self._last_readback = None
        self._published_since_tick = False
        #: time.monotonic() at the end of the last chip write and how long that write took, s: a command arriving
        #: sooner after a write than the write lasted is left to the output tick (:meth:`on_command`)
        self._last_write_end, self._last_write_s = -math.inf, 0.0
        self._steady_last = time.monotonic()
        self._last_tick_monotonic = -math.inf  # time.monotonic() of the last _steady_and_output_tick
        self._steady_command = self._steady_last
        self._steady_age_s = 0.0
        self.start_time = self.get_clock().now()

        self.pub_written = self.create_publisher(ThrusterPwm, "thrusters/pulse_width", 10)
        # every input is a callback, in both clock modes (the path the vehicle takes is the path the tests take)
        #: with the heartbeats' liveliness contract (1 s lease): the allocation publishes with the same QoS; a
        #: publisher without a finite lease (a script, a bag player) is not matched, and is refused by its name
        self.command_publishers_alive = 0
        self.create_subscription(ThrusterPwm, COMMAND_TOPIC, self.on_command, heartbeat_qos(),
                                 event_callbacks=SubscriptionEventCallbacks(liveliness=self._on_command_liveliness))
        self.create_subscription(Float64, "lights/brightness", self.on_lights, 10)
        self.create_service(SetArmed, "esc/set_armed", self.on_set_armed)
        self.heartbeat = HeartbeatPublisher(self, "esc", "hindrax/esc", "esc")
        self._heartbeat_tick = 0
        #: the peers' heartbeats through their identity checks (:class:`~hindrax_drivers.liveness.HeartbeatWatch`:
        #: one live publisher with the expected node name, boot_id and seq); only accepted beats reach the handlers
        self.watches = {"supervisor": HeartbeatWatch(self, "supervisor", self.on_supervisor_heartbeat,
                                                     lambda: self.armed),
                        "guard": HeartbeatWatch(self, "guard", self.on_guard_heartbeat, lambda: self.armed)}
        self.diagnostics = DiagnosticsPublisher(self, [self.diag], extra=self._diag_extra)
        self._configure_chip()
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        if self.get_parameter("use_sim_time").value:
            # use_sim_time: the output tick follows simulated time (the stepped graph's order); the safety tick
            # keeps running on the steady clock when /clock stops
            self.output_timer = self.create_timer(self.period_s, self.tick)
            self.steady_timer = self.create_timer(self.period_s, self.steady_check, clock=steady)
        else:
            # system clock: ROS time is wall time, so one steady-clock timer runs the safety tick and then the
            # output tick (one executor wake-up per period instead of two, docs/architecture.md §10.1)
            self.output_timer = None
            self.steady_timer = self.create_timer(self.period_s, self._steady_and_output_tick, clock=steady)

    # -- the core's state, as the node's (read by the tests, the benches and the diagnostics)
    armed = property(lambda self: self.core.armed, lambda self, v: setattr(self.core, "armed", bool(v)))
    output_state = property(lambda self: self.core.output_state,
                            lambda self, v: setattr(self.core, "output_state", int(v)))
    command = property(lambda self: self.core.command, lambda self, v: setattr(self.core, "command", v))
    arming_time_s = property(lambda self: self.core.arming_time_s)
    watchdog_s = property(lambda self: self.core.watchdog_s, lambda self, v: setattr(self.core, "watchdog_s", v))
    oscillator_calibrated = property(lambda self: self.core.oscillator_calibrated)
    watchdog_trips = property(lambda self: self.core.watchdog_trips)
    heartbeat_disarms = property(lambda self: self.core.heartbeat_disarms)
    #: time.monotonic() at which neutral was read back from the chip (None: not confirmed)
    neutral_confirmed_time = property(lambda self: self.core.neutral_confirmed_at)
    #: time.monotonic() since which neutral is confirmed on the chip AND the guard lets it through, or None
    neutral_on_wire_since = property(lambda self: self.core.neutral_on_wire_since)

    device = property(lambda self: self.chip.device, lambda self, v: setattr(self.chip, "device", v))
    #: (n,) thruster widths on the chip as decoded from the counts written, us
    written = property(lambda self: self.chip.written)

    @property
    def command_time(self) -> Time | None:
        """ROS time of the last command's arrival (None before the first)."""
        t = self.core.command_t_s
        return None if t is None else Time(nanoseconds=round(t * 1e9), clock_type=self.get_clock().clock_type)

    @command_time.setter
    def command_time(self, value: Time) -> None:
        self.core.command_t_s = value.nanoseconds * 1e-9

    # -- device
    def _configure_chip(self) -> bool:
        """Put the chip in a known state with neutral on every used channel and confirm it by reading it back
        (:meth:`.chip.EscChip.configure`: neutral first); the arming time may start then. Returns True on success."""
        self.core.chip_attempt()
        if self.device is None and not self._open_bus():
            return False
        try:
            mismatch = self.chip.configure(self.output.neutral(), self.lights_off_us)
            self.core.wrote(self.chip.written)
            self.lights_us = self.lights_off_us
        except I2CError as exc:
            self.diag.count("i2c_error")
            self._set_unknown(f"PCA9685 start-up failed: {exc}")
            return False
        if mismatch:
            self.diag.count("readback_mismatch")
            self._set_unknown(f"PCA9685 start-up not confirmed: {mismatch}")
            return False
        self.core.chip_confirmed()
        self._last_readback = self.core.neutral_confirmed_at
        self.diag.set_state("holding neutral", DiagnosticStatus.OK, "holding neutral, disarmed")
        return True

    def _open_bus(self) -> bool:
        """Open ``/dev/i2c-<esc.i2c_bus>`` (or the shared emulated bus); False with an ERROR when it fails."""
        try:
            bus = open_shared_bus() or open_smbus(self.i2c_bus_number)
        except (OSError, ImportError) as exc:
            self.bus_error = str(exc)
            self.diag.count("no_bus")
            self._set_unknown(f"no I2C bus: {exc}; retrying")
            return False
        self.bus_error = ""
        self.device = I2CDevice(bus, self.i2c_address, "pca9685", raw_tap=self.raw.i2c_tap)
        return True

    def _set_unknown(self, reason: str) -> None:
        """The chip cannot be written or read back: the output state is unknown. Disarm (thrust needs a new arm
        request once the chip is back), forget what we believe is on the chip, report ERROR, retry with backoff."""
        if self.core.chip_lost(reason):
            self.unknown_entries += 1
            self.last_unknown_monotonic = time.monotonic()
            self.get_logger().error(f"output state unknown: {self.core.reason}")
        self.chip.forget()
        self.diag.set_state("i2c error", DiagnosticStatus.ERROR, f"{self.core.reason} (output state unknown)")

    def _write(self, widths_us: np.ndarray, lights_us: float) -> bool:
        """Write the widths (:meth:`.chip.EscChip.write`, skipping what is on the chip already) and tell the core.
        Returns True when it wrote; raises :class:`I2CError`."""
        start = time.monotonic()
        wrote = self.chip.write(widths_us, lights_us)
        if wrote:
            self._last_write_end = time.monotonic()
            self._last_write_s = self._last_write_end - start
            self.core.wrote(self.chip.written)
            self.lights_us = lights_us
        return wrote

    # -- inputs
    def on_command(self, msg: ThrusterPwm) -> None:
        """Hand the command to the core and, armed, write it at once (event-driven output; the tick is the
        watchdog), unless the bus is behind (:meth:`_bus_behind`): the output tick then writes the latest command.
        A faulty command (:func:`~.core.command_fault`) gives neutral at once, with its reason."""
        now = self.get_clock().now()
        fault = self.core.on_command(now.nanoseconds * 1e-9, msg.pulse_width_us, bool(msg.armed))
        self._steady_age_s = 0.0
        self._steady_command = time.monotonic()
        if fault:
            self.diag.count("command_rejected")
            self.get_logger().error(f"command rejected, neutral: {fault}", throttle_duration_sec=1.0)
        if self.armed and self.neutral_confirmed_time is not None and (fault or not self._bus_behind()):
            self._output(now)
        # else coalesced: the next output tick writes the latest command, so a backlog costs one write

    def _bus_behind(self) -> bool:
        """True when a command now would queue behind a slow bus: the last chip write lasted a tenth of an output
        period or more (2 ms at 50 Hz; a PCA9685 block write takes 0.9 ms at 400 kHz, 3.4 ms at 100 kHz) and ended
        less than its own duration ago (commands that waited in the executor while it ran). Writing each of them
        would keep this thread on the bus and delay the tick and its heartbeat past the output guard's timeout."""
        last = self._last_write_s
        return last >= 0.1 * self.period_s and time.monotonic() - self._last_write_end < min(last, self.period_s)

    def on_lights(self, msg: Float64) -> None:
        b = msg.data
        if not math.isfinite(b):
            self.get_logger().warn(f"lights brightness {b} rejected (expected 0-1)")
            return
        b = min(max(b, 0.0), 1.0)
        self.lights_us = self.lights_off_us + b * (self.lights_full_us - self.lights_off_us)

    def arming_remaining_s(self) -> float:
        """Seconds still needed at neutral before arming is accepted (0 when ready; :meth:`.core.EscCore.
        arming_remaining_s`)."""
        return self.core.arming_remaining_s()

    def _peer_verdicts(self) -> tuple[str, str]:
        """The supervisor's and the guard's heartbeat verdicts ('' = trusted, else why not)."""
        t = self.heartbeat_timeout_s
        sup = heartbeat_verdict("supervisor", HEARTBEAT_NAMES["supervisor"], self.supervisor_age.age_s, t,
                                self.supervisor_ok, self.supervisor_message)
        if sup and self.supervisor_age.fresh(t):
            sup = f"supervisor tripped: {self.supervisor_message} (clear it with supervisor/reset)"
        guard = heartbeat_verdict("output guard", HEARTBEAT_NAMES["guard"], self.guard_age.age_s, t,
                                  self.guard_ok, self.guard_message)
        if guard and self.guard_age.fresh(t):
            guard = f"output guard holds the outputs off: {self.guard_message}"
        # a silent peer first (its identity fault is then "no live publisher"); then the identity checks, before
        # the level: a forged or replayed OK must not count as the peer's
        sup_id, guard_id = (self.watches[k].identity.fault for k in ("supervisor", "guard"))
        return (sup if not self.supervisor_age.fresh(t) else
                f"supervisor heartbeat not trusted: {sup_id}" if sup_id else sup,
                guard if not self.guard_age.fresh(t) else
                f"output-guard heartbeat not trusted: {guard_id}" if guard_id else guard)

    def heartbeat_refusal(self) -> str:
        """Why the supervisor or the output guard forbid thrust now ('' when both are fresh and OK)."""
        sup, guard = self._peer_verdicts()
        return sup or guard

    def _check_graph(self) -> None:
        """Who publishes the peers' heartbeats and the commands (the graph; every second safety tick and before an
        arm request): the heartbeats' identity checks, then the command topic's publishers."""
        for watch in self.watches.values():
            watch.check()
        self._check_command_source()

    def _on_command_liveliness(self, info: Any) -> None:
        self.command_publishers_alive = int(info.alive_count)

    def _check_command_source(self) -> None:
        """Who publishes ``thrusters/command_pulse_width`` (the graph, and the live count): only the allocation may
        (:func:`.core.command_source_fault`); a fault disarms and holds neutral while it lasts."""
        names = [info.node_name for info in self.get_publishers_info_by_topic(COMMAND_TOPIC)]
        fault = command_source_fault(names, COMMAND_TOPIC, self.command_publishers_alive)
        if fault and fault != self.core.command_source:
            self.diag.count("command_source_fault")
            self.get_logger().error(f"command topic not trusted: {fault}")
        if self.core.set_command_source(fault):
            self._after_disarm(fault)

    def _feed_peers(self) -> str:
        """Hand the heartbeat verdicts to the core; log and publish a disarm they cause. Returns its reason."""
        refusal = self.core.set_peers(*self._peer_verdicts())
        if refusal:
            self.get_logger().error(f"disarming: {refusal}")
            self._after_disarm(refusal)
        return refusal

    def arm_refusal(self) -> str:
        """Why an arm request would be refused now ('' when it would be accepted)."""
        self.core.set_peers(*self._peer_verdicts())
        return self.core.arm_refusal(self.bus_error)

    def _take_inputs(self) -> None:
        """Advance the heartbeat ages to now (the safety tick and an arm request; the beats arrive by callbacks)."""
        self.supervisor_age.tick()
        self.guard_age.tick()

    def on_set_armed(self, request: SetArmed.Request, response: SetArmed.Response) -> SetArmed.Response:
        if not request.arm:
            self.disarm("disarmed")
            if self.output_state == ThrusterPwm.OUTPUT_UNKNOWN:
                response.success, response.armed = False, False
                response.message = ("disarmed (no thrust accepted), but neutral is NOT confirmed on the chip: "
                                    f"{self.diag_message()}; the output guard must silence the outputs")
            else:
                response.success, response.armed, response.message = True, False, "disarmed"
            return response
        self._take_inputs()
        self._check_graph()
        self.core.set_peers(*self._peer_verdicts())
        refusal = self.core.request_arm(self.bus_error)
        if refusal:
            response.success, response.armed, response.message = False, self.armed, refusal
            return response
        self.diag.clear("chip_reset")
        self.diag.set_state("armed, neutral", DiagnosticStatus.OK)
        response.success, response.armed, response.message = True, True, "armed"
        return response

    def disarm(self, reason: str) -> None:
        """Disarm and write neutral now (the disarm service, the supervisor, shutdown)."""
        self.core.disarm(reason)
        self._after_disarm(reason)

    def _after_disarm(self, reason: str) -> None:
        self._safe_neutral(reason)
        self._publish_written(self.get_clock().now())

    # -- output
    def _output(self, now) -> None:
        """Write what the core decides for now (neutral unless armed with a fresh, valid command)."""
        try:
            trips = self.core.watchdog_trips
            dt_s = self.period_s if self._last_target_time is None else \
                min(self.period_s, max(0.0, (now - self._last_target_time).nanoseconds * 1e-9))
            decision = self.core.decide(now.nanoseconds * 1e-9, dt_s)
            if self.core.watchdog_trips != trips:
                self.get_logger().warn(f"watchdog: no command for {self.watchdog_s:g} s, outputs neutral")
            self._last_target_time = now if decision.output_state == ThrusterPwm.OUTPUT_COMMANDING else None
            wrote = self._write(decision.widths_us, self.lights_us)
            self.output_state = decision.output_state
            if self.diag.state not in ("i2c error",) or wrote:
                # a malformed command is a WARN; one that says armed=false (a rejected wrench) is only neutral
                level = DiagnosticStatus.WARN if decision.reason.startswith("command rejected") and \
                    "armed=false" not in decision.reason else DiagnosticStatus.OK
                self.diag.set_state(decision.state, level, decision.reason)
            if wrote:
                self._publish_written(now)
        except Exception as exc:  # noqa: BLE001 - any fault in the output path must end at neutral
            self.diag.count("output_exception")
            self.get_logger().error(f"output fault, writing neutral: {exc}", throttle_duration_sec=1.0)
            self.command = None
            self._safe_neutral(f"fault: {exc}")
            self._publish_written(now)

    def tick(self) -> None:
        """Output tick (ROS time, ``esc.output_rate_hz``): the ROS-time watchdog and the output (the chip's
        (re)configuration and read-back run on the steady clock, :meth:`steady_check`)."""
        now = self.get_clock().now()
        if self.neutral_confirmed_time is not None:
            self._output(now)
        if not self._published_since_tick:
            self._publish_written(now)
        self._published_since_tick = False

    def _steady_and_output_tick(self) -> None:
        """The one timer of the system clock (steady clock, ``esc.output_rate_hz``): :meth:`steady_check`, then
        :meth:`tick`, which reads ROS time (= wall time there) for its watchdog and stamps."""
        self._last_tick_monotonic = time.monotonic()
        self.steady_check()
        self.tick()

    def _check_chip(self) -> None:
        """Read the chip back; on a mismatch (brown-out reset, sleep, lost registers) re-initialise it, disarm,
        and restart the arming timer (the ESCs must see neutral again), reporting it in diagnostics."""
        self.raw.begin_batch()  # raw/pca9685: the reads join the 0.1 s batches of the writes
        try:
            mismatch = self.chip.readback_mismatch()
        except I2CError as exc:
            self.diag.count("i2c_error")
            self._set_unknown(f"PCA9685 read-back failed: {exc}")
            self._publish_written(self.get_clock().now())
            return
        finally:
            self.raw.flush()
        if not mismatch:
            return
        self.chip_reinits += 1
        self.last_chip_reinit_monotonic = time.monotonic()
        self.diag.count("chip_reinit")
        was_armed = self.armed
        message = f"PCA9685 read-back mismatch: {mismatch}; re-initialised at neutral" + \
            (", disarmed (re-arm after esc.arming_time_s)" if was_armed else "")
        self.core.chip_mismatch(message)
        self.diag.warn("chip_reset", message)
        self.get_logger().error(message)
        self._configure_chip()
        self._publish_written(self.get_clock().now())

    def steady_check(self) -> None:
        """Steady-clock watchdog (``time.monotonic``, independent of ROS time; see
        parameter ``steady_watchdog_timeout_s``). Only executor-alive time counts (a gap between two checks counts at
        most two output periods), so a stalled process does not trip it when it resumes."""
        t = time.monotonic()
        self._safety_tick(t)
        gap, self._steady_last = t - self._steady_last, t
        if not (self.armed and self.command is not None):
            self._steady_age_s = 0.0
            return
        self._steady_age_s += min(max(gap, 0.0), t - self._steady_command, 2.0 * self.period_s)
        if self._steady_age_s > self.steady_watchdog_s:
            self.steady_watchdog_trips += 1
            self.core.watchdog_trip(f"steady-clock watchdog: no command for {self.steady_watchdog_s:g} s")
            self.get_logger().warn(f"steady-clock watchdog: no command for {self.steady_watchdog_s:g} s of wall "
                                   f"time (ROS time stalled?), outputs neutral")
            self._safe_neutral("steady-clock watchdog")
            self._publish_written(self.get_clock().now())

    def _safety_tick(self, t: float) -> None:
        """Steady-clock part of every output period: heartbeats (disarm on loss), the chip's (re)configuration with
        backoff, the read-back every ``esc.readback_interval_s``, the arming clock, ROS-time steps."""
        step = self.clock_monitor.check()
        if step:
            self.diag.count("clock_step")
            self.diag.warn("clock_step", f"ROS time stepped back {-step:.3f} s (/clock restarted?); protective "
                                         "timing is on the steady clock")
            self.get_logger().warn(f"ROS time stepped back {-step:.3f} s")
            self.diagnostics.publish()  # at once: its timer runs on the ROS time that just jumped
        self._take_inputs()
        if self._heartbeat_tick % 2 == 0:  # 25 Hz, in the ticks without a beat: three graph queries (~26 us each)
            self._check_graph()
        self._feed_peers()
        self._heartbeat_tick += 1
        if self._heartbeat_tick % 2 == 0:  # before the chip's transactions: their bus time does not delay the beat
            self._publish_heartbeat()
        if self.core.retry_due():
            if self._configure_chip():
                self._publish_written(self.get_clock().now())
        elif self.neutral_confirmed_time is not None and t - self._last_readback >= self.readback_interval_s:
            self._last_readback = t
            self._check_chip()
        self.core.set_peers(*self._peer_verdicts())  # the arming time starts in the tick that confirmed neutral

    def _publish_heartbeat(self) -> None:
        unknown = self.output_state == ThrusterPwm.OUTPUT_UNKNOWN
        self.heartbeat.publish(
            DiagnosticStatus.ERROR if unknown else DiagnosticStatus.OK, STATE_NAMES[self.output_state],
            [("output_state", str(int(self.output_state))),
             ("armed", "true" if self.armed and not unknown else "false"), ("reason", self.core.reason)])

    def on_supervisor_heartbeat(self, msg: DiagnosticStatus) -> None:
        """``supervisor/heartbeat``: level OK = within the envelope; otherwise the breach is latched. A trip
        disarms when it is handled (at once as a callback; at the next safety tick on the system clock, where
        the supervisor's own ``esc/set_armed`` request has disarmed already)."""
        self.supervisor_age.heard()
        self.supervisor_ok, self.supervisor_message = heartbeat_ok(msg), msg.message
        if not self.supervisor_ok and self.armed:
            self._feed_peers()

    def on_guard_heartbeat(self, msg: DiagnosticStatus) -> None:
        """``guard/heartbeat``: level OK = the guard lets the outputs through (/OE low)."""
        self.guard_age.heard()
        self.guard_ok, self.guard_message = heartbeat_ok(msg), msg.message
        if not self.guard_ok:
            self._feed_peers()  # restarts the time at neutral even if a later beat of the same take says OK

    def diag_message(self) -> str:
        """The current /diagnostics message (why the state is what it is)."""
        return getattr(self.diag, "_message", "") or self.diag.state

    def _safe_neutral(self, reason: str) -> None:
        try:
            self.chip.forget()  # always write: neutral must reach the chip even if we believe it is there
            self._last_target_time = None
            self._write(self.output.neutral(), self.lights_us)
            if self.neutral_confirmed_time is not None:
                self.output_state = ThrusterPwm.OUTPUT_NEUTRAL
            self.diag.set_state("neutral", DiagnosticStatus.WARN if reason.startswith("fault") else DiagnosticStatus.OK,
                                reason)
        except Exception as exc:  # noqa: BLE001 - bus down: report, keep running, retry with backoff
            self.diag.count("i2c_error")
            self._set_unknown(f"cannot write neutral: {exc}")

    def _publish_written(self, now) -> None:
        unknown = self.output_state == ThrusterPwm.OUTPUT_UNKNOWN
        widths = [math.nan] * len(self.written) if unknown else self.written
        # serialised by rosbags and published as bytes: 50 Hz without rclpy's object conversion (lean_cdr.py)
        self.pub_written.publish(thruster_pwm_cdr(now.nanoseconds, "base_link", widths,
                                                  self.armed and not unknown, self.output_state))
        self.diag.published(now.nanoseconds * 1e-9)
        self._published_since_tick = True

    def _diag_extra(self):
        return [("armed", self.armed), ("watchdog_trips", self.watchdog_trips),
                ("steady_watchdog_trips", self.steady_watchdog_trips), ("chip_reinits", self.chip_reinits),
                ("neutral_confirmed", self.neutral_confirmed_time is not None),
                ("oscillator_calibrated", self.oscillator_calibrated),
                ("arming_remaining_s", f"{self.arming_remaining_s():.1f}"), ("prescale", self.prescale),
                ("output_state", STATE_NAMES[self.output_state]),
                ("supervisor_heartbeat_age_s", f"{self.supervisor_age.age_s:.2f}"),
                ("guard_heartbeat_age_s", f"{self.guard_age.age_s:.2f}"), ("heartbeat_disarms", self.heartbeat_disarms),
                ("heartbeats_rejected", sum(w.identity.rejected for w in self.watches.values())),
                ("rejected_commands", self.core.rejected_commands), ("reason", self.core.reason),
                ("command_source", self.core.command_source or "thrust_allocation"),
                ("clock_steps_back", self.clock_monitor.steps_back),
                *(self.device.stats.diagnostics() if self.device is not None else [("i2c_bus", "not open")])]

    def close(self) -> None:
        """Shutdown path: disarm and write neutral (SIGINT/SIGTERM via run_node, or destroy by the owner)."""
        self.core.disarm("shutdown")
        self._safe_neutral("shutdown")


def main(args=None) -> int:
    """``python -m hindrax_drivers.pca9685.node --ros-args --params-file ros_ws/config/hindrax.yaml`` (Pi)."""
    return run_node(EscNode, args, systemd_notify=True)  # READY=1, WATCHDOG=1 (sd_notify.py)


if __name__ == "__main__":
    raise SystemExit(main())
