"""ESC output node: thruster pulse widths and the lights channel through a PCA9685 on I2C. Thin: the decisions are
:class:`.core.EscCore`'s, the registers :class:`.chip.EscChip`'s, the bus :class:`.worker.ChipWorker`'s (its own
thread), the peers' heartbeats :class:`.peers.EscPeers`'.

The executor thread (callbacks, the safety tick, ``esc/heartbeat``) never waits on the bus: it posts what the chip
should hold and takes what the chip confirmed at its next command or tick (at most one output period later). A bus
call that has not returned within :data:`.worker.BUS_CALL_TIMEOUT_S` makes the output state UNKNOWN (heartbeat
ERROR: the output guard stops the outputs, docs/watchdog.md). A disarm's neutral is never dropped nor overtaken by a
later thrust write.

- Chip: start-up and every recovery through :meth:`.chip.EscChip.configure` (neutral first), confirmed by
  read-back (:meth:`.core.EscCore.chip_confirmed`); a failed write or read-back is :meth:`.core.EscCore.chip_lost`
  (``OUTPUT_UNKNOWN``, widths NaN on ``thrusters/pulse_width``, never "neutral"); a read-back mismatch every
  ``esc.readback_interval_s`` (brown-out) re-initialises the chip and disarms. No bus at start-up: the node keeps
  running, reports ERROR "no I2C bus" and picks the bus up when it appears.
- Inputs, all by callbacks in both clock modes: ``thrusters/command_pulse_width`` (hindrax_msgs/ThrusterPwm,
  thruster order; written on arrival while armed, the newest one when the bus is behind; only from
  ``thrust_allocation``, checked in the graph), ``supervisor/heartbeat`` and ``guard/heartbeat``
  (:mod:`.peers`), ``lights/brightness`` (std_msgs/Float64, 0-1 mapped linearly from ``lights.pulse_width_off_us``
  to ``pulse_width_full_us``), the ``esc/set_armed`` service (hindrax_msgs/SetArmed).
- Ticks: on the system clock one steady-clock timer (``esc.output_rate_hz``) runs the safety tick
  (:meth:`EscNode.steady_check`: heartbeats, a stuck bus, chip retries and read-back, the steady-clock watchdog for a
  stopped ROS clock, ROS-time steps) and then the output tick (:meth:`EscNode.tick`: the ROS-time command watchdog);
  with ``use_sim_time`` the output tick is a ROS-time timer of its own.
- Outputs: ``thrusters/pulse_width`` (the widths on the chip, decoded from the register counts, armed flag, output
  state; on every confirmed write and at a tick without one), ``esc/heartbeat`` (diagnostic_msgs/DiagnosticStatus
  every second steady tick, 25 Hz at 50 Hz: values ``output_state``, ``armed``, ``reason`` and the ``boot_id``/
  ``seq`` of :class:`~hindrax_drivers.liveness.HeartbeatPublisher`; ERROR while unknown; the output guard's sign of
  life), ``raw/pca9685`` (every I2C transaction) and ``/diagnostics``. Neutral is written on disarm, on any
  exception in the output path and on shutdown (:meth:`EscNode.close`, SIGINT/SIGTERM via :func:`run_node`).
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
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.time import Time
from std_msgs.msg import Float64

from hindrax_msgs.msg import ThrusterPwm
from hindrax_msgs.srv import SetArmed

from ..config import Spec
from ..lean_cdr import thruster_pwm_cdr
from ..liveness import ClockStepMonitor, HeartbeatPublisher, heartbeat_qos
from ..node_common import DeviceDiagnostics, DiagnosticsPublisher, RawDataPublisher, load_node_config, run_node
from ..config.node_parameters import declare_node_parameter
from ..transport.i2c import open_smbus
from ..transport.shared_emulation import open_shared_bus
from . import protocol as p
from .chip import EscChip
from .core import GUARD_CONFIRM_S, RETRY_MAX_S, RETRY_MIN_S, STATE_NAMES, EscCore, EscOutput, command_source_fault
from .peers import EscPeers
from .worker import CONFIGURE, NEUTRAL, READBACK, WRITE, ChipJob, ChipResult, ChipWorker

__all__ = ["EscNode", "EscOutput", "GUARD_CONFIRM_S", "RETRY_MIN_S", "RETRY_MAX_S", "main"]

COMMAND_TOPIC = "thrusters/command_pulse_width"
_UNKNOWN, _NEUTRAL, _COMMANDING = ThrusterPwm.OUTPUT_UNKNOWN, ThrusterPwm.OUTPUT_NEUTRAL, ThrusterPwm.OUTPUT_COMMANDING
#: node parameter ``heartbeat_timeout_s`` (read-only; declared by config.node_parameters.declare_node_parameter)
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
    """PCA9685 ESC output node (see the module docstring). ``bus``: SMBus-like object (default: opened by the
    worker, smbus2); ``chip_thread``: False runs the chip jobs in the executor thread (a lock-step simulation)."""

    def __init__(self, bus: Any = None, chip_thread: bool = True, **kwargs: Any):
        super().__init__("esc", **kwargs)
        cfg = self.cfg = load_node_config(self, ("thrusters", "esc", "lights"))
        t, esc, lights = cfg.thrusters, cfg.esc, cfg.lights
        self.period_s = 1.0 / esc.output_rate_hz
        #: steady-clock (time.monotonic) watchdog, s: parameter ``steady_watchdog_timeout_s`` (:data:`STEADY_WATCHDOG`)
        self.steady_watchdog_s = float(declare_node_parameter(self, "steady_watchdog_timeout_s", STEADY_WATCHDOG,
                                                              esc.watchdog_timeout_s))
        self.readback_interval_s = esc.readback_interval_s
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
        self.i2c_bus_number = int(esc.i2c_bus)
        self.raw = RawDataPublisher(self, "pca9685")
        chip = EscChip(int(esc.i2c_address), self.prescale, self.oscillator_hz, self.output.channels,
                       lights.esc_channel, self.raw)
        self._closing = False
        #: the bus's thread (:mod:`.worker`); its results are taken at each command and tick (the rclpy
        #: EventsExecutor of the node processes has no guard conditions to be woken by)
        self.chip_io = ChipWorker(chip, self._open_bus, self.raw.i2c_tap, threaded=chip_thread)
        if bus is not None:
            self.chip_io.use_bus(bus)
        #: (n,) thruster widths on the chip as confirmed by the worker (decoded from the counts written), us
        self.written = np.full(len(self.output.channels), np.nan)
        self.bus_error = ""
        now_s = lambda: self.get_clock().now().nanoseconds * 1e-9  # noqa: E731
        self.diag = DeviceDiagnostics("hindrax/esc_pca9685", f"i2c-{esc.i2c_bus}@0x{esc.i2c_address:02x}", now_s)
        self.unknown_entries = 0
        self.last_unknown_monotonic: float | None = None
        self.clock_monitor = ClockStepMonitor(now_s)
        self.steady_watchdog_trips = self.chip_reinits = self.bus_stalls = 0
        self.last_chip_reinit_monotonic: float | None = None  # time.monotonic() of the last detection
        self._last_target_time = None
        self._last_readback = -math.inf
        self._published_since_tick = False
        self._steady_last = self._steady_command = time.monotonic()
        self._steady_age_s = 0.0

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
        #: supervisor and guard heartbeats; timeout: parameter ``heartbeat_timeout_s`` (:data:`HEARTBEAT_TIMEOUT`)
        beat_timeout_s = declare_node_parameter(self, "heartbeat_timeout_s", HEARTBEAT_TIMEOUT, esc.heartbeat_timeout_s)
        self.peers = EscPeers(self, self.period_s, beat_timeout_s, lambda: self.armed, self._feed_peers)
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

    # -- the core's and the peers' state, as the node's (read by the tests, the benches and the diagnostics)
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
    device = property(lambda self: self.chip_io.chip.device)
    heartbeat_timeout_s = property(lambda self: self.peers.timeout_s)
    supervisor_age = property(lambda self: self.peers.supervisor_age)
    supervisor_ok = property(lambda self: self.peers.supervisor_ok)
    on_supervisor_heartbeat = property(lambda self: self.peers.on_supervisor_heartbeat)
    on_guard_heartbeat = property(lambda self: self.peers.on_guard_heartbeat)

    @property
    def command_time(self) -> Time | None:
        """ROS time of the last command's arrival (None before the first)."""
        t = self.core.command_t_s
        return None if t is None else Time(nanoseconds=round(t * 1e9), clock_type=self.get_clock().clock_type)

    @command_time.setter
    def command_time(self, value: Time) -> None:
        self.core.command_t_s = value.nanoseconds * 1e-9

    # -- the chip, through the worker
    def _post(self, kind: str, widths_us: np.ndarray | None = None, output_state: int = _NEUTRAL,
              reason: str = "") -> None:
        self.chip_io.post(ChipJob(kind, widths_us, self.lights_us, output_state, reason))
        if not self.chip_io.threaded:
            self._take_results()  # the job ran in this thread

    def _configure_chip(self) -> None:
        """Put the chip in a known state with neutral on every used channel, confirmed by read-back
        (:meth:`.chip.EscChip.configure`: neutral first); the arming time may start when that result comes."""
        self.core.chip_attempt()
        self.lights_us = self.lights_off_us
        self._post(CONFIGURE, self.output.neutral())

    def _open_bus(self) -> Any:
        """``/dev/i2c-<esc.i2c_bus>`` (or the shared emulated bus): the worker's, when the chip has no device."""
        return open_shared_bus() or open_smbus(self.i2c_bus_number)

    def _take_results(self) -> None:
        """What the worker confirmed (at each command and tick; at once without a chip thread)."""
        if self._closing:
            return  # shutdown: the context may be gone; close() waits for the neutral itself
        for result in self.chip_io.results():
            self._apply(result)

    def _apply(self, r: ChipResult) -> None:
        job, now = r.job, self.get_clock().now()
        if r.wrote and not r.error:
            self.core.wrote(r.written_us)
        self.written = r.written_us
        if job.kind == CONFIGURE:
            self.bus_error = r.error if r.no_bus else ""
            if r.error or r.mismatch:
                self.diag.count("no_bus" if r.no_bus else "i2c_error" if r.error else "readback_mismatch")
                self._set_unknown(f"{r.error}; retrying" if r.no_bus else f"PCA9685 start-up failed: {r.error}"
                                  if r.error else f"PCA9685 start-up not confirmed: {r.mismatch}")
            else:
                self.core.chip_confirmed()
                self._last_readback = self.core.neutral_confirmed_at
                self.diag.set_state("holding neutral", DiagnosticStatus.OK, "holding neutral, disarmed")
        elif self.core.neutral_confirmed_at is None:
            return  # a job posted before the chip was lost: only a configure brings it back
        elif job.kind == READBACK:
            if r.error:
                self.diag.count("i2c_error")
                self._set_unknown(f"PCA9685 read-back failed: {r.error}")
            elif r.mismatch:
                self._chip_mismatch(r.mismatch)
        elif r.error and job.kind == WRITE:
            self.diag.count("output_exception")
            self.get_logger().error(f"output fault, writing neutral: {r.error}", throttle_duration_sec=1.0)
            self.command = None
            self._safe_neutral(f"fault: {r.error}")
        elif r.error:
            self.diag.count("i2c_error")
            self._set_unknown(f"cannot write neutral: {r.error}")
        else:
            self.output_state = job.output_state
        if r.wrote or r.error or job.kind == CONFIGURE:
            self._publish_written(now)

    def _chip_mismatch(self, mismatch: str) -> None:
        """A read-back found the chip changed (brown-out reset, sleep, lost registers): re-initialise it, disarm,
        and restart the arming timer (the ESCs must see neutral again), reporting it in diagnostics."""
        self.chip_reinits += 1
        self.last_chip_reinit_monotonic = time.monotonic()
        self.diag.count("chip_reinit")
        message = f"PCA9685 read-back mismatch: {mismatch}; re-initialised at neutral" + \
            (", disarmed (re-arm after esc.arming_time_s)" if self.armed else "")
        self.core.chip_mismatch(message)
        self.diag.warn("chip_reset", message)
        self.get_logger().error(message)
        self._configure_chip()

    def _set_unknown(self, reason: str) -> None:
        """The chip cannot be written or read back: the output state is unknown. Disarm (thrust needs a new arm
        request once the chip is back), report ERROR, retry with backoff."""
        if self.core.chip_lost(reason):
            self.unknown_entries += 1
            self.last_unknown_monotonic = time.monotonic()
            self.get_logger().error(f"output state unknown: {self.core.reason}")
        self.diag.set_state("i2c error", DiagnosticStatus.ERROR, f"{self.core.reason} (output state unknown)")

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
        self._steady_age_s = 0.0
        self._steady_command = time.monotonic()
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
        """Who publishes the peers' heartbeats and the commands (the graph; every second safety tick and before an
        arm request): the heartbeats' identity checks, then the command topic's publishers: only the allocation may
        (:func:`.core.command_source_fault`); a fault disarms and holds neutral while it lasts."""
        self.peers.check_identities()
        names = [info.node_name for info in self.get_publishers_info_by_topic(COMMAND_TOPIC)]
        fault = command_source_fault(names, COMMAND_TOPIC, self.command_publishers_alive)
        if fault and fault != self.core.command_source:
            self.diag.count("command_source_fault")
            self.get_logger().error(f"command topic not trusted: {fault}")
        if self.core.set_command_source(fault):
            self._after_disarm(fault)

    def _on_command_liveliness(self, info: Any) -> None:
        self.command_publishers_alive = int(info.alive_count)

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
        refusal = self.core.request_arm(self.bus_error)
        if refusal:
            response.success, response.armed, response.message = False, self.armed, refusal
            return response
        self.diag.clear("chip_reset")
        self.diag.set_state("armed, neutral", DiagnosticStatus.OK)
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
            self._post(WRITE, decision.widths_us, decision.output_state)
        except Exception as exc:  # noqa: BLE001 - any fault in the output path must end at neutral
            self.diag.count("output_exception")
            self.get_logger().error(f"output fault, writing neutral: {exc}", throttle_duration_sec=1.0)
            self.command = None
            self._safe_neutral(f"fault: {exc}")
            self._publish_written(now)

    def _safe_neutral(self, reason: str) -> None:
        """Post neutral, written whatever is believed on the chip; never dropped nor overtaken (:mod:`.worker`)."""
        self._last_target_time = None
        if self.neutral_confirmed_time is not None:
            self.diag.set_state("neutral", DiagnosticStatus.WARN if reason.startswith("fault") else
                                DiagnosticStatus.OK, reason)
        self._post(NEUTRAL, self.output.neutral(), _NEUTRAL, reason)

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
        self.steady_check()
        self.tick()

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
        self._take_results()
        stuck_s = self.chip_io.stuck_s()
        if stuck_s and self.output_state != _UNKNOWN:  # the heartbeat below says ERROR: the guard stops the outputs
            self.bus_stalls += 1
            self.diag.count("bus_stalled")
            self._set_unknown(f"PCA9685 bus call not returned after {stuck_s:.2f} s (limit "
                              f"{self.chip_io.call_timeout_s:g} s)")
            self._publish_written(self.get_clock().now())
        self.peers.tick()
        if self._heartbeat_tick % 2 == 0:  # 25 Hz, in the ticks without a beat: three graph queries (~26 us each)
            self._check_graph()
        self._feed_peers()
        self._heartbeat_tick += 1
        if self._heartbeat_tick % 2 == 0:
            self._publish_heartbeat()
        if stuck_s:
            pass  # nothing more can reach the chip until the call returns
        elif self.core.retry_due() and not self.chip_io.pending(CONFIGURE):
            self._configure_chip()
        elif self.neutral_confirmed_time is not None and t - self._last_readback >= self.readback_interval_s:
            self._last_readback = t
            self._post(READBACK)
        self.core.set_peers(*self._peer_verdicts())  # the arming time starts in the tick that confirmed neutral

    def _publish_heartbeat(self) -> None:
        unknown = self.output_state == _UNKNOWN
        self.heartbeat.publish(
            DiagnosticStatus.ERROR if unknown else DiagnosticStatus.OK, STATE_NAMES[self.output_state],
            [("output_state", str(int(self.output_state))),
             ("armed", "true" if self.armed and not unknown else "false"), ("reason", self.core.reason)])

    def diag_message(self) -> str:
        """The current /diagnostics message (why the state is what it is)."""
        return getattr(self.diag, "_message", "") or self.diag.state

    def _publish_written(self, now) -> None:
        unknown = self.output_state == _UNKNOWN
        widths = [math.nan] * len(self.written) if unknown else self.written
        # serialised by rosbags and published as bytes: 50 Hz without rclpy's object conversion (lean_cdr.py)
        self.pub_written.publish(thruster_pwm_cdr(now.nanoseconds, "base_link", widths,
                                                  self.armed and not unknown, self.output_state))
        self.diag.published(now.nanoseconds * 1e-9)
        self._published_since_tick = True

    def _diag_extra(self):
        return [("armed", self.armed), ("watchdog_trips", self.watchdog_trips),
                ("steady_watchdog_trips", self.steady_watchdog_trips), ("chip_reinits", self.chip_reinits),
                ("bus_stalls", self.bus_stalls), ("neutral_confirmed", self.neutral_confirmed_time is not None),
                ("oscillator_calibrated", self.oscillator_calibrated),
                ("arming_remaining_s", f"{self.arming_remaining_s():.1f}"), ("prescale", self.prescale),
                ("output_state", STATE_NAMES[self.output_state]), *self.peers.diagnostics(),
                ("heartbeat_disarms", self.heartbeat_disarms), ("rejected_commands", self.core.rejected_commands),
                ("reason", self.core.reason), ("command_source", self.core.command_source or "thrust_allocation"),
                ("clock_steps_back", self.clock_monitor.steps_back),
                *(self.device.stats.diagnostics() if self.device is not None else [("i2c_bus", "not open")])]

    def close(self) -> None:
        """Shutdown path: disarm and write neutral (SIGINT/SIGTERM via run_node, or destroy by the owner); waits up
        to 1 s for the worker to write it."""
        self._closing = True
        self.core.disarm("shutdown")
        self._safe_neutral("shutdown")
        self.chip_io.wait_idle(1.0)

    def destroy_node(self) -> None:
        self.chip_io.stop()
        super().destroy_node()


def main(args=None) -> int:
    """``python -m hindrax_drivers.pca9685.node --ros-args --params-file ros_ws/config/hindrax.yaml`` (Pi)."""
    return run_node(EscNode, args, systemd_notify=True)  # READY=1, WATCHDOG=1 (sd_notify.py)


if __name__ == "__main__":
    raise SystemExit(main())
