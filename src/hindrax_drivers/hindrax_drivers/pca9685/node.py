"""ESC output node: thruster pulse widths and the lights channel through a PCA9685 on I2C. Thin: the decisions are
:class:`.core.EscCore`'s, the registers :class:`.chip.EscChip`'s, the bus :class:`.worker.ChipWorker`'s (a thread of
its own), the peers' heartbeats and the command source :class:`.peers.EscPeers`'.

The executor thread (callbacks, the safety tick, ``esc/heartbeat``) never waits on the bus: it posts what the chip
should hold and takes what the chip confirmed at its next command or tick. A bus call not returned within
``esc.bus_call_timeout_s`` (0.15 s) makes the output state UNKNOWN (heartbeat ERROR: the output guard stops the
outputs, docs/watchdog.md). A disarm's neutral is never dropped nor overtaken by a later thrust write.

- Oscillator not measured (``esc.oscillator_calibrated`` false): "neutral" is no pulse on every thruster channel
  (full OFF: a width computed from an unmeasured 23-27 MHz oscillator may be outside the ESC's deadband), arming is
  refused, and channel :data:`~.protocol.REFERENCE_CHANNEL` carries the configured neutral width for the scope
  (``hindrax esc calibrate``).
- Chip: start-up and every recovery by :meth:`.chip.EscChip.configure` (neutral first), confirmed by read-back; a
  failed write or read-back is ``OUTPUT_UNKNOWN`` (widths NaN on ``thrusters/pulse_width``, never "neutral"); a
  read-back mismatch every ``esc.readback_interval_s`` (brown-out) re-initialises the chip and disarms. No bus at
  start-up: the node keeps running, reports ERROR "no I2C bus" and picks the bus up when it appears.
- Inputs, by callbacks in both clock modes: ``thrusters/command_pulse_width`` (hindrax_msgs/ThrusterPwm, thruster
  order; posted on arrival while armed; only from ``thrust_allocation``), ``supervisor/heartbeat`` and
  ``guard/heartbeat`` (:mod:`.peers`), ``lights/brightness`` (std_msgs/Float64, 0-1 mapped linearly from
  ``lights.pulse_width_off_us`` to ``pulse_width_full_us``), the ``esc/set_armed`` service (hindrax_msgs/SetArmed).
- Ticks: on the system clock one steady-clock timer (``esc.output_rate_hz``) runs the safety tick
  (:meth:`EscNode.steady_check`: heartbeats, a stuck bus, chip retries and read-back, the steady-clock watchdog,
  ROS-time steps) and then the output tick (:meth:`EscNode.tick`: the ROS-time command watchdog); with
  ``use_sim_time`` the output tick is a ROS-time timer of its own.
- Outputs: ``thrusters/pulse_width`` (the widths on the chip decoded from the register counts, armed flag, output state;
  on every confirmed write or change of state, and repeated by the output tick when nothing went out for
  :data:`REPEAT_AFTER_PERIODS` periods: 25 Hz armed and under the identification's 25 Hz commands; disarmed at neutral
  every :data:`DISARMED_REPEAT_S`), ``esc/heartbeat`` (hindrax_msgs/Heartbeat every second steady tick, at once in one
  two periods late; ``output_state``, ``armed``, the reason as ``message``, ``boot_id``/``seq``, the newest guard beat
  handled ``guard_boot_id``/``guard_seq``; ERROR while unknown; the output guard's sign of life and release condition),
  ``esc/output_state`` (the same state, latched: on a change of armed or output state and every 1 s,
  :mod:`hindrax_common.node_support.esc_state`; for nodes that need only "armed"), ``raw/pca9685`` (every I2C
  transaction), ``/diagnostics``. Neutral is written on disarm, on an exception in the output path and on shutdown
  (:meth:`EscNode.close`; SIGINT/SIGTERM).
- Node parameters outside the vehicle file (read-only, declared in
  :mod:`hindrax_common.config.sections.esc`): ``heartbeat_timeout_s`` (default ``esc.heartbeat_timeout_s``),
  ``steady_watchdog_timeout_s`` (default ``esc.watchdog_timeout_s``).

The bus: ``smbus2.SMBus(esc.i2c_bus)`` on the Pi, or injected (an
:class:`~hindrax_common.transport.emulated_i2c.EmulatedI2CBus` holding a
:class:`~hindrax_drivers.pca9685.emulator.Pca9685Emulator` in tests and simulation)."""
from __future__ import annotations

import math
import os
import time
from typing import Any

from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.clock import Clock, ClockType
from std_msgs.msg import Float64

from hindrax_msgs.msg import ThrusterPwm
from hindrax_msgs.srv import SetArmed

from hindrax_common.config.sections.esc import STEADY_WATCHDOG_TIMEOUT, board_id, oscillator_problem
from hindrax_common.node_support.esc_state import ESC_STATE_TOPIC, EscStateLatch, esc_state_qos, esc_state_values
from hindrax_common.cdr.lean_cdr import diagnostic_status_cdr, prepare, thruster_pwm_cdr
from hindrax_common.node_support.liveness import ClockStepMonitor, HeartbeatPublisher, TickGaps, heartbeat_qos
from hindrax_common.node_support.node_common import (DeviceDiagnostics, DiagnosticsPublisher, RawDataPublisher,
    load_node_config, run_node)
from hindrax_common.config.node_parameters import declare_node_parameter
from hindrax_common.transport.i2c import open_smbus
from hindrax_common.transport.shared_emulation import SOCKET_ENV, open_shared_bus
from . import protocol as p
from hindrax_common.node_support.vehicle_node import VehicleNode
from .chip import EscChip
from .core import GUARD_CONFIRM_S, RETRY_MAX_S, RETRY_MIN_S, STATE_NAMES, WRITE, EscCore, EscOutput
from .peers import COMMAND_TOPIC, EscPeers
from .link import ChipLink
from .worker import ChipWorker

__all__ = ["EscNode", "EscOutput", "GUARD_CONFIRM_S", "RETRY_MIN_S", "RETRY_MAX_S", "REPEAT_AFTER_PERIODS",
           "DISARMED_REPEAT_S", "main"]

_UNKNOWN, _NEUTRAL, _COMMANDING = ThrusterPwm.OUTPUT_UNKNOWN, ThrusterPwm.OUTPUT_NEUTRAL, ThrusterPwm.OUTPUT_COMMANDING
#: the output tick repeats ``thrusters/pulse_width`` (the last widths, a new stamp) only when none went out for this
#: many output periods (ROS time; a step back repeats at once). Every confirmed write and change of state goes out at
#: once, so no width is lost: the readers hold the last one (identification, bag fit, simulator). With the
#: identification's commands at 25 Hz, one repeat between two writes at 50 Hz had carried nothing new.
REPEAT_AFTER_PERIODS = 1.5
#: disarmed at neutral the repeat is a keep-alive every this many s (ROS time): the state is on ``esc/heartbeat`` at
#: 25 Hz for the guard and on ``esc/output_state`` for the rest; no reader needs the widths faster at rest
DISARMED_REPEAT_S = 0.5


def real_chip(bus: Any) -> bool:
    """True when the node drives a real PCA9685: no bus injected and no shared emulation (tests, benchmarks)."""
    return bus is None and not os.environ.get(SOCKET_ENV)


class EscNode(VehicleNode):
    """PCA9685 ESC output node (see the module docstring). ``bus``: SMBus-like object (default: opened by the
    worker, smbus2); ``chip_thread``: False runs the chip jobs in the executor thread (a lock-step simulation)."""

    #: its process refuses to start beside another live ESC
    #: (:func:`hindrax_common.node_support.vehicle_graph.refuse_live_peer`)
    START_CHECK = "esc"

    def __init__(self, bus: Any = None, chip_thread: bool = True, **kwargs: Any):
        super().__init__("esc", **kwargs)
        cfg = self.cfg = load_node_config(self, ("thrusters", "esc", "lights"))
        t, esc, lights = cfg.thrusters, cfg.esc, cfg.lights
        self.period_s = 1.0 / esc.output_rate_hz
        steady_watchdog_s = float(declare_node_parameter(self, "steady_watchdog_timeout_s", STEADY_WATCHDOG_TIMEOUT,
                                                         esc.watchdog_timeout_s))
        self.lights_off_us, self.lights_full_us = lights.pulse_width_off_us, lights.pulse_width_full_us
        self.lights_us = self.lights_off_us
        self.oscillator_hz = esc.oscillator_hz
        self.prescale = p.esc_prescale(esc.pwm_frequency_hz, self.oscillator_hz)
        # an oscillator nobody measured gives no known neutral: the thruster outputs stay off (no pulses), and the
        # reference channel carries the configured neutral width for the scope (hindrax esc calibrate)
        self.output = EscOutput.from_config(t, esc.slew_rate_us_per_s, p.count_duration_us(self.prescale,
                                                                                             self.oscillator_hz),
                                            outputs_off=not esc.oscillator_calibrated)
        #: the decisions (arm, refuse, disarm, neutral, output state, reason): :mod:`.core`
        self.core = EscCore(self.output, arming_time_s=esc.arming_time_s, watchdog_timeout_s=esc.watchdog_timeout_s,
                            oscillator_calibrated=esc.oscillator_calibrated, clock=lambda: time.monotonic(),
                            period_s=self.period_s, steady_watchdog_s=steady_watchdog_s)
        self.i2c_bus_number = int(esc.i2c_bus)
        self.raw = RawDataPublisher(self, "pca9685")
        chip = EscChip(int(esc.i2c_address), self.prescale, self.oscillator_hz, self.output.channels,
                       lights.esc_channel, self.raw, reference=None if esc.oscillator_calibrated else (
                           p.REFERENCE_CHANNEL, t.pulse_width_neutral_us))
        #: the bus's thread; results taken at each command and tick (rclpy's EventsExecutor has no guard conditions)
        self.chip_io = ChipWorker(chip, self._open_bus, self.raw.i2c_tap, threaded=chip_thread,
                                  call_timeout_s=esc.bus_call_timeout_s)
        if bus is not None:
            self.chip_io.use_bus(bus)
        now_s = lambda: self.get_clock().now().nanoseconds * 1e-9  # noqa: E731
        self.diag = DeviceDiagnostics("hindrax/esc_pca9685", f"i2c-{esc.i2c_bus}@0x{esc.i2c_address:02x}", now_s)
        # issue 71.8: a real chip marked calibrated without a measurement of this board: WARN on /diagnostics, so
        # hindrax health shows it (an emulated chip's oscillator is the configured one by construction)
        if real_chip(bus) and (problem := oscillator_problem(cfg, board_id())):
            self.diag.warn("oscillator_not_measured_here", problem)
        self.link = ChipLink(self.core, self.chip_io, self.diag, self.get_logger().error, lambda: self.lights_us,
                             esc.readback_interval_s)
        self.clock_monitor = ClockStepMonitor(now_s)
        self._last_target_time = None

        prepare(ThrusterPwm, DiagnosticStatus)  # before the ticks: the first use would hold one (lean_cdr.prepare)
        self.pub_written = self.create_publisher(ThrusterPwm, "thrusters/pulse_width", 10)
        #: ``esc/output_state``, latched (reliable, transient local, keep last 1): on a change and once a second
        self.pub_state = self.create_publisher(DiagnosticStatus, ESC_STATE_TOPIC, esc_state_qos())
        self.state_latch = EscStateLatch()
        self.peers = EscPeers(self, self.period_s, esc.heartbeat_timeout_s, lambda: self.armed, self._feed_peers)
        # every input is a callback, in both clock modes; the commands with the heartbeats' liveliness contract (1 s
        # lease): a publisher without a finite lease (a script, a bag player) is not matched, and refused by its name
        self.create_subscription(ThrusterPwm, COMMAND_TOPIC, self.on_command, heartbeat_qos(),
                                 event_callbacks=self.peers.command_publishers.event_callbacks(
                                     liveliness=self.peers.on_liveliness))
        self.create_subscription(Float64, "lights/brightness", self.on_lights, 10)
        self.create_service(SetArmed, "esc/set_armed", self.on_set_armed)
        self.heartbeat = HeartbeatPublisher(self, "esc")
        self._heartbeat_tick, self._beat_s = 0, -math.inf  # ticks; last beat, monotonic s
        self.tick_gaps = TickGaps()  # how late the safety tick (and its heartbeat) ran, on /diagnostics
        self.diagnostics = DiagnosticsPublisher(self, [self.diag], extra=self._diag_extra)
        self.lights_us = self.lights_off_us
        self.link.configure()
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

    # -- the core's state, read-only (read by the tests, the benches and the diagnostics; only the core changes it)
    armed = property(lambda self: self.core.armed)
    output_state = property(lambda self: self.core.output_state)
    command = property(lambda self: self.core.command)
    arming_time_s = property(lambda self: self.core.arming_time_s)
    watchdog_s = property(lambda self: self.core.watchdog_s)
    #: steady-clock (time.monotonic) watchdog, s: parameter ``steady_watchdog_timeout_s``
    steady_watchdog_s = property(lambda self: self.core.steady_watchdog_s)
    oscillator_calibrated = property(lambda self: self.core.oscillator_calibrated)
    watchdog_trips = property(lambda self: self.core.watchdog_trips)
    heartbeat_disarms = property(lambda self: self.core.heartbeat_disarms)
    #: time.monotonic() at which neutral was read back from the chip (None: not confirmed)
    neutral_confirmed_time = property(lambda self: self.core.neutral_confirmed_at)
    #: time.monotonic() since which neutral is confirmed on the chip AND the guard lets it through, or None
    neutral_on_wire_since = property(lambda self: self.core.neutral_on_wire_since)
    device = property(lambda self: self.chip_io.chip.device)
    steady_watchdog_trips = property(lambda self: self.core.steady_watchdog_trips)
    #: time.monotonic() of the last command taken (the benches' reference for the steady watchdog)
    _steady_command = property(lambda self: self.core.last_command_s)

    # -- the chip, through the worker and the link
    def _open_bus(self) -> Any:
        """``/dev/i2c-<esc.i2c_bus>`` (or the shared emulated bus): the worker's, when the chip has no device."""
        return open_shared_bus() or open_smbus(self.i2c_bus_number)

    def _take_results(self) -> None:
        if self.link.take():
            self._publish_written(self.get_clock().now())

    def settle(self, timeout_s: float = 5.0) -> bool:
        """Wait until the worker has run every posted job and take the results (shutdown; tests that call the
        node's methods directly). False when ``timeout_s`` passed first."""
        done = self.chip_io.wait_idle(timeout_s)
        self._take_results()
        return done

    # -- inputs
    def on_command(self, msg: ThrusterPwm) -> None:
        """Hand the command to the core and, armed, post it at once (event-driven output; the tick is the watchdog;
        a command the worker has not taken yet is replaced). A faulty command (:func:`~.core.command_fault`) gives
        neutral at once, with its reason."""
        now = self.get_clock().now()
        self._take_results()
        fault = self.core.on_command(now.nanoseconds * 1e-9, msg.pulse_width_us, bool(msg.armed))
        if fault:
            self.diag.count("command_rejected")
            self.get_logger().error(f"command rejected, neutral: {fault}", throttle_duration_sec=1.0)
        if self.armed and self.neutral_confirmed_time is not None:
            self._output(now)

    def on_lights(self, msg: Float64) -> None:
        b = msg.data
        if not math.isfinite(b):
            self.get_logger().warn(f"lights brightness {b} rejected (expected 0-1)")
            return
        self.lights_us = self.lights_off_us + min(max(b, 0.0), 1.0) * (self.lights_full_us - self.lights_off_us)

    def arming_remaining_s(self) -> float:
        """Seconds still needed at neutral before arming is accepted (0 when ready; :meth:`.core.EscCore.
        arming_remaining_s`)."""
        return self.core.arming_remaining_s()

    def _peer_verdicts(self) -> tuple[str, str]:
        return self.peers.verdicts()

    def heartbeat_refusal(self) -> str:
        """Why the supervisor or the output guard forbid thrust now ('' when both are fresh and OK)."""
        sup, guard = self._peer_verdicts()
        return sup or guard

    def _check_graph(self) -> None:
        """Who publishes the heartbeats and the commands (every second safety tick and before an arm request,
        :meth:`.peers.EscPeers.check_graph`); a command source fault disarms and holds neutral while it lasts."""
        fault, unnamed = self.peers.check_graph()
        if fault and fault != self.core.command_source:
            self.diag.count("command_source_fault")
            self.get_logger().error(f"command topic not trusted: {fault}")
        if unnamed and not fault and not self.core.command_unnamed:
            self.diag.count("command_source_unnamed")
        if self.core.set_command_source(fault, unnamed):
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
        return self.core.arm_refusal(self.link.bus_error)

    def on_set_armed(self, request: SetArmed.Request, response: SetArmed.Response) -> SetArmed.Response:
        if not request.arm:
            self.disarm("disarmed")
            response.success, response.armed, response.message = True, False, "disarmed"
            if self.output_state == _UNKNOWN:
                response.success = False
                response.message = ("disarmed (no thrust accepted), but neutral is NOT confirmed on the chip: "
                                    f"{self.diag_message()}; the output guard must silence the outputs")
            return response
        self.peers.tick()
        self._check_graph()
        self.core.set_peers(*self._peer_verdicts())
        refusal = self.core.request_arm(self.link.bus_error)
        if refusal:
            response.success, response.armed, response.message = False, self.armed, refusal
            return response
        self.diag.clear("chip_reset")
        self.diag.set_state("armed, neutral", DiagnosticStatus.OK)
        self._publish_state()
        response.success, response.armed, response.message = True, True, "armed"
        return response

    def disarm(self, reason: str) -> None:
        """Disarm and post neutral now (the disarm service, the supervisor, shutdown)."""
        self.core.disarm(reason)
        self._after_disarm(reason)

    def _after_disarm(self, reason: str) -> None:
        self._safe_neutral(reason)
        self._publish_written(self.get_clock().now())

    # -- output
    def _output(self, now) -> None:
        """Post what the core decides for now (neutral unless armed with a fresh, valid command)."""
        try:
            trips = self.core.watchdog_trips
            dt_s = self.period_s if self._last_target_time is None else \
                min(self.period_s, max(0.0, (now - self._last_target_time).nanoseconds * 1e-9))
            decision = self.core.decide(now.nanoseconds * 1e-9, dt_s)
            if self.core.watchdog_trips != trips:
                self.get_logger().warn(f"watchdog: no command for {self.watchdog_s:g} s, outputs neutral")
            self._last_target_time = now if decision.output_state == _COMMANDING else None
            if self.output_state != _UNKNOWN:
                # a malformed command is a WARN; one that says armed=false (a rejected wrench) is only neutral
                level = DiagnosticStatus.WARN if decision.reason.startswith("command rejected") and \
                    "armed=false" not in decision.reason else DiagnosticStatus.OK
                self.diag.set_state(decision.state, level, decision.reason)
            if self.link.post(WRITE, decision.widths_us, decision.output_state):
                self._publish_written(now)
        except Exception as exc:  # noqa: BLE001 - any fault in the output path must end at neutral
            self.diag.count("output_exception")
            self.get_logger().error(f"output fault, writing neutral: {exc}", throttle_duration_sec=1.0)
            self.core.output_fault(f"fault: {exc}")
            self._safe_neutral(f"fault: {exc}")
            self._publish_written(now)

    def _safe_neutral(self, reason: str) -> None:
        """Post neutral, written whatever is believed on the chip; never dropped nor overtaken (:mod:`.worker`)."""
        self._last_target_time = None
        self.link.neutral(reason)

    def tick(self) -> None:
        """Output tick (ROS time, ``esc.output_rate_hz``): the ROS-time watchdog and the output (the chip's
        (re)configuration and read-back run on the steady clock, :meth:`steady_check`)."""
        now = self.get_clock().now()
        if self.neutral_confirmed_time is not None:
            self._output(now)
        last_s = self.diag.last_publish_s  # the last thrusters/pulse_width, ROS time (_publish_written)
        rest = not self.armed and self.output_state == _NEUTRAL
        repeat_s = DISARMED_REPEAT_S if rest else REPEAT_AFTER_PERIODS * self.period_s
        if last_s is None or not 0.0 <= now.nanoseconds * 1e-9 - last_s < repeat_s:
            self._publish_written(now)

    def _steady_and_output_tick(self) -> None:
        """The system clock's one timer: :meth:`steady_check`, then :meth:`tick` (ROS time = wall time there)."""
        self.steady_check()
        self.tick()

    def steady_check(self) -> None:
        """The safety tick, then the core's steady-clock watchdog (:meth:`.core.EscCore.steady_check`, parameter
        ``steady_watchdog_timeout_s``): a trip is logged and neutral posted."""
        self.tick_gaps.tick()
        t = time.monotonic()
        self._safety_tick(t)
        trip = self.core.steady_check(t)
        if trip:
            self.get_logger().warn(f"{trip} of wall time (ROS time stalled?), outputs neutral")
            self._after_disarm("steady-clock watchdog")

    def _safety_tick(self, t: float) -> None:
        """Steady-clock part of every output period: a stuck bus, heartbeats (disarm on loss), the chip's
        (re)configuration with backoff, the read-back every ``esc.readback_interval_s``, ROS-time steps."""
        step = self.clock_monitor.check()
        if step:
            self.diag.count("clock_step")
            self.diag.warn("clock_step", f"ROS time stepped back {-step:.3f} s (/clock restarted?); protective "
                                         "timing is on the steady clock")
            self.get_logger().warn(f"ROS time stepped back {-step:.3f} s")
            self.diagnostics.publish()  # at once: its timer runs on the ROS time that just jumped
        if self.link.maintain(t):  # results, a stuck bus call (UNKNOWN: the beat below says ERROR), retries
            self._publish_written(self.get_clock().now())
        self.peers.tick()
        if self._heartbeat_tick % 2 == 0:  # 25 Hz, in the ticks without a beat (the graph asked only when due)
            self._check_graph()
        self._feed_peers()
        self._heartbeat_tick += 1
        if self._heartbeat_tick % 2 == 0 or t - self._beat_s >= 2 * self.period_s:  # 25 Hz, or late
            self._beat_s = t
            self._publish_heartbeat()
        self.core.set_peers(*self._peer_verdicts())  # the arming time starts in the tick that confirmed neutral
        self._publish_state()  # once a second without a change, on the steady clock (ROS time may stand still)

    def _publish_heartbeat(self) -> None:
        unknown = self.output_state == _UNKNOWN
        self.heartbeat.publish(not unknown, self.core.reason, self.output_state, self.armed and not unknown,
                               self.peers.guard_ack)

    def _publish_state(self) -> None:
        """``esc/output_state`` when :class:`~hindrax_common.node_support.esc_state.EscStateLatch` says so: a change of
        (armed, output state), or a second without one."""
        unknown = self.output_state == _UNKNOWN
        armed = self.armed and not unknown
        if self.state_latch.due(time.monotonic(), armed, self.output_state):
            self.pub_state.publish(diagnostic_status_cdr(
                DiagnosticStatus.ERROR if unknown else DiagnosticStatus.OK, "hindrax/esc",
                STATE_NAMES[self.output_state], "esc", esc_state_values(armed, self.output_state, self.core.reason)))

    def diag_message(self) -> str:
        """The current /diagnostics message (why the state is what it is)."""
        return getattr(self.diag, "_message", "") or self.diag.state

    def _publish_written(self, now) -> None:
        unknown = self.output_state == _UNKNOWN
        widths = [math.nan] * len(self.link.written) if unknown else self.link.written
        # serialised by rosbags and published as bytes: 50 Hz without rclpy's object conversion (lean_cdr.py)
        self.pub_written.publish(thruster_pwm_cdr(now.nanoseconds, "base_link", widths,
                                                  self.armed and not unknown, self.output_state))
        self.diag.published(now.nanoseconds * 1e-9)
        self._publish_state()

    def _diag_extra(self):
        return [("armed", self.armed), ("watchdog_trips", self.watchdog_trips),
                ("steady_watchdog_trips", self.steady_watchdog_trips), ("chip_reinits", self.link.chip_reinits),
                ("bus_stalls", self.link.bus_stalls), ("neutral_confirmed", self.neutral_confirmed_time is not None),
                ("oscillator_calibrated", self.oscillator_calibrated),
                ("arming_remaining_s", f"{self.arming_remaining_s():.1f}"), ("prescale", self.prescale),
                ("output_state", STATE_NAMES[self.output_state]), *self.peers.diagnostics(),
                ("heartbeat_disarms", self.heartbeat_disarms), ("rejected_commands", self.core.rejected_commands),
                ("reason", self.core.reason), ("command_source", self.core.command_source or "thrust_allocation"),
                ("clock_steps_back", self.clock_monitor.steps_back), *self.tick_gaps.report(),
                *(self.device.stats.diagnostics() if self.device is not None else [("i2c_bus", "not open")])]

    def close(self) -> None:
        """Shutdown path: disarm and write neutral (SIGINT/SIGTERM via run_node, or destroy by the owner); waits up
        to 1 s for the worker to write it. Its results are taken at the next tick, if the node still runs (the
        ROS context may be gone: nothing is published here)."""
        self.link.closing = True
        try:
            self.core.disarm("shutdown")
            self._safe_neutral("shutdown")
            self.chip_io.wait_idle(1.0)
        finally:
            self.link.closing = False

    def destroy_node(self) -> None:
        """Join the chip worker (after its queued jobs, the shutdown's neutral; up to 1 s), then silence its raw tap
        (a call left hanging past the join publishes nothing on a destroyed node), then destroy the node."""
        self.chip_io.stop()
        self.raw.close()
        super().destroy_node()


def main(args=None) -> int:
    """``python -m hindrax_drivers.pca9685.node --ros-args --params-file ros_ws/config/hindrax.yaml`` (Pi)."""
    return run_node(EscNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
