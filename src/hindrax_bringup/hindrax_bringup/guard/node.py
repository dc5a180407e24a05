"""Output guard node: silences the PCA9685 outputs from outside the ESC process (docs/architecture.md §8).

The decision is :class:`~hindrax_bringup.guard.core.GuardCore` (ESC output state silent or unknown, supervisor
heartbeat silent or tripped, either heartbeat not its sender's -> silence, latched until the ESC reports disarmed at
neutral). Each heartbeat comes through a :class:`~.liveness.HeartbeatWatch` (its identity check:
at every tick the topic's live count and its publishers' node names, asked of the graph when DDS reports a change,
at every beat its ``boot_id`` and ``seq``; a rejected beat does not count as the peer being heard). How it silences:

* ``esc.output_enable_gpio`` set (chip and line): the PCA9685 /OE line through libgpiod
  (:class:`~hindrax_common.transport.gpio.GpiodLine`), driven HIGH (outputs off, no pulses: the Basic ESC
  stops) when asserted and LOW when released. The line is requested high at start-up. The wiring has a pull-up on
  /OE, so when this process dies and the kernel frees the line (the Pi's pinctrl returns it to an input with
  ``dtparam=strict_gpiod``) the outputs go off by themselves. A kernel that keeps a freed output's level, or one
  whose behaviour the guard cannot read (:meth:`~hindrax_common.transport.gpio.GpiodLine.release_problem`), is a
  cause that never clears: the outputs stay off and the ESC refuses to arm. After a kill, the unit's
  ``ExecStopPost=`` (:mod:`.outputs_off`) silences the chip and /OE from outside.
* not wired: over the shared I2C bus, the chip's ALL_LED_OFF_H full-OFF bit then MODE1 SLEEP (datasheet §7.3.1,
  §7.3.4), once on assertion and again whenever the ESC reports commanding while asserted. Needs a working bus: an
  I2C outage on an unwired vehicle leaves the last widths on the wire (``hindrax config check`` warns).

The hardware watchdog (``esc.output_enable_feed_gpio``, docs/watchdog.md): a retriggerable monostable ORed into
/OE holds the outputs off unless it sees rising edges. The guard toggles that line on a steady-clock timer at twice
``esc.output_enable_feed_rate_hz``, and only while the outputs are released (the ESC heartbeat fresh, nothing
tripped, the guard able to act) and its own decision tick ran within the last half watchdog timeout: a frozen
launch, a frozen Pi or a starved guard stops the edges, and the outputs go off ``esc.output_enable_feed_timeout_s``
later without any software alive. A feed line that cannot be requested or driven is a drive fault (ERROR
heartbeat). When no edge went out for longer than the timeout while the ESC was armed (this process was frozen or
starved), the guard asserts and latches: thrust comes back only through a new arm request.

Subscribes ``esc/heartbeat`` (hindrax_msgs/Heartbeat from the ESC's steady-clock tick: its output state, armed flag and
the guard beat it acknowledges; ``thrusters/pulse_width`` follows ROS time, which a simulation may hold) and
``supervisor/heartbeat`` (hindrax_msgs/Heartbeat). Under systemd (``$NOTIFY_SOCKET``) it alone sends the unit's READY=1
and WATCHDOG=1, at each tick while both heartbeats are fresh (:mod:`~hindrax_common.process.sd_notify`): a frozen ESC,
supervisor or guard stops the pings, and systemd stops the unit after ``WatchdogSec``. Publishes ``guard/heartbeat``
(hindrax_msgs/Heartbeat at every tick, before the tick's /OE write: level OK = outputs enabled, ERROR = silenced with
the reason; the ESC refuses to arm and disarms without a fresh OK) and ``/diagnostics`` (``hindrax/output_guard``).

Timing: one steady-clock timer at ``GUARD_RATE_HZ``; ages in executor-alive steady time
(:class:`~hindrax_common.node_support.liveness.AliveAge`: a gap between two ticks counts in full up to the timeout, so
a starved guard ages a dead peer at wall speed; on simulated time a peer is late only when also late on the graph's
clock), timeout: the read-only node parameter ``heartbeat_timeout_s`` (default ``esc.guard_heartbeat_timeout_s``).
The two heartbeats are callbacks in both clock modes (the path the vehicle takes is the path the tests take). A
small process of its own (EventsExecutor, two heartbeat inputs, one 20 Hz timer) so that a fault in the supervisor's
sensor code cannot take the second stop path with it."""
from __future__ import annotations

import math
import time
from typing import Any

from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.clock import Clock, ClockType

from hindrax_common.config import output_enable_gpio
from hindrax_common.config.sections.esc import GUARD_HEARTBEAT_TIMEOUT
from hindrax_common.cdr.lean_cdr import Beat
from hindrax_common.node_support.liveness import (AliveAge, HeartbeatPublisher, HeartbeatWatch, TickGaps, heartbeat_ok,
                                     simulated_now_s)
from hindrax_common.node_support.node_common import DeviceDiagnostics, DiagnosticsPublisher, load_node_config, run_node
from hindrax_common.config.node_parameters import declare_node_parameter
from hindrax_drivers.pca9685 import protocol as p
from hindrax_common.transport.gpio import GpiodLine
from hindrax_common.transport.i2c import I2CDevice, I2CError, open_smbus
from hindrax_common.process.sd_notify import SafetyNotifier
from hindrax_common.transport.shared_emulation import open_shared_bus, open_shared_line
from hindrax_common.node_support.vehicle_node import VehicleNode
from .core import OUTPUT_COMMANDING, OUTPUT_NEUTRAL, OUTPUT_UNKNOWN, GuardCore
from .outputs_off import open_output_enable, silence_chip

__all__ = ["OutputGuardNode", "GUARD_RATE_HZ", "open_output_enable", "open_watchdog_feed", "main"]

#: the guard's tick (decision, /OE, heartbeat), Hz
GUARD_RATE_HZ = 20.0
#: while asserted without /OE, the sleep registers are written again at most this often when the ESC commands, s
REWRITE_INTERVAL_S = 0.2
#: after a failure to drive /OE or to reach the chip, the line request or the chip is tried again this often, s
DRIVE_RETRY_S = 0.5


def open_watchdog_feed(chip: str, line: int) -> Any:
    """The hardware watchdog's feed line, requested LOW (no edge): the emulation server's ``oe_feed`` line when
    ``HINDRAX_EMULATION_SOCKET`` is set, else libgpiod. Raises OSError/ImportError."""
    shared = open_shared_line("oe_feed", False)
    if shared is not None:
        return shared
    return GpiodLine(chip, line, initial_high=False, consumer="hindrax-watchdog-feed")


class OutputGuardNode(VehicleNode):
    """The output guard (module docstring). ``line``: an injected /OE line (``set_high``/``release``); ``bus``: an
    injected SMBus-like bus for the register fallback; ``feed``: an injected watchdog feed line (with
    ``esc.output_enable_feed_rate_hz`` configured). Without them, they are opened from the configuration."""

    def __init__(self, line: Any = None, bus: Any = None, feed: Any = None, **kwargs: Any):
        super().__init__("output_guard", **kwargs)
        cfg = load_node_config(self, ("esc",))
        esc = cfg.esc
        #: the heartbeats' timeout, s: parameter ``heartbeat_timeout_s`` (config.sections.esc.GUARD_HEARTBEAT_TIMEOUT)
        self.timeout_s = float(declare_node_parameter(self, "heartbeat_timeout_s", GUARD_HEARTBEAT_TIMEOUT,
                                                      esc.guard_heartbeat_timeout_s))
        self.core = GuardCore(self.timeout_s)
        period = 1.0 / GUARD_RATE_HZ
        #: a gap between two ticks counts in full up to the timeout, so that a starved guard still ages a dead peer
        #: at wall speed (a longer gap is this process's own stall; the watchdog feed covers it)
        #: on simulated time, also on the graph's clock (liveness.AliveAge: late only when late in the simulation)
        self.esc_age = AliveAge(self.timeout_s, graph_now_s=lambda: simulated_now_s(self))
        self.supervisor_age = AliveAge(self.timeout_s, graph_now_s=lambda: simulated_now_s(self))
        self.gpio = output_enable_gpio(cfg)
        self.line = line
        self._bus, self._bus_number, self._address = bus, int(esc.i2c_bus), int(esc.i2c_address)
        self.device: I2CDevice | None = None
        self.assertions = 0
        self.silence_failures = 0
        self._last_rewrite = -1e9
        self._last_drive_attempt = -1e9
        #: the hardware watchdog's feed (module docstring): (chip, line) or None, the line, its level, edges
        self.feed_gpio = output_enable_gpio(cfg, "esc.output_enable_feed_gpio")
        self.feed = feed
        self.feed_rate_hz = esc.output_enable_feed_rate_hz
        self._feed_high = False
        self.feed_edges = 0
        self._last_decision = -1e9
        self._last_rise: float | None = None  # time.monotonic() of the last rising edge sent
        self._released_at = -1e9  # time.monotonic() of the last release of the outputs (feeding starts again)
        self.feed_timeout_s = esc.output_enable_feed_timeout_s
        #: READY=1 / WATCHDOG=1 for the systemd unit (sd_notify.py): at each tick while both heartbeats are fresh
        self.notifier = SafetyNotifier()
        if (self.feed_gpio is not None or feed is not None) and not self.feed_rate_hz:
            raise ValueError("the watchdog feed needs esc.output_enable_feed_rate_hz")
        where = (f"/OE {self.gpio[0]}:{self.gpio[1]}" if self.gpio else "/OE (injected line)" if line is not None
                 else f"registers i2c-{self._bus_number}@0x{self._address:02x}")
        self.diag = DeviceDiagnostics("hindrax/output_guard", where, lambda: time.monotonic())
        if self.gpio is None and line is None:
            self.diag.warn("no_hardware_cutoff", "esc.output_enable_gpio not wired: outputs silenced over the I2C "
                                                 "bus (does not work through an I2C outage)")
        if not self.feeds:
            self.diag.warn("no_hardware_watchdog", "esc.output_enable_feed_gpio not wired: a frozen launch or Pi "
                                                   "keeps the last widths until systemd restarts the unit")
        self._open_line()
        if line is not None:
            self._check_release()
        self.heartbeat = HeartbeatPublisher(self, "guard")
        #: the peers' heartbeats through their identity checks (module docstring)
        #: "armed" for their boot_id rule: the ESC reported armed and the outputs are let through; once /OE is
        #: asserted a peer's new start (a restart after a crash) is accepted, since release still needs the ESC to
        #: report disarmed at neutral
        self.watches = {kind: HeartbeatWatch(self, kind, handler, self._armed_through)
                        for kind, handler in (("esc", self.on_esc), ("supervisor", self.on_supervisor))}
        self.tick_gaps = TickGaps()  # how late the tick (and its heartbeat) ran, on /diagnostics
        self.diagnostics = DiagnosticsPublisher(self, [self.diag], extra=self._diag_extra)
        self.create_timer(period, self.tick, clock=Clock(clock_type=ClockType.STEADY_TIME))
        if self.feeds:
            self._open_feed()
            self.create_timer(0.5 / float(self.feed_rate_hz), self.feed_tick,
                              clock=Clock(clock_type=ClockType.STEADY_TIME))
        if self.wired:
            self._apply(True, force=True)  # /OE high from the start; the registers are the ESC's own start-up's job

    @property
    def wired(self) -> bool:
        """True when the guard drives an /OE line (else it writes the chip's registers)."""
        return self.gpio is not None or self.line is not None

    @property
    def feeds(self) -> bool:
        """True when a hardware watchdog is fitted (the guard toggles its feed line)."""
        return self.feed_gpio is not None or self.feed is not None

    # -- the hardware watchdog's feed
    def _open_feed(self) -> None:
        if self.feed is not None or self.feed_gpio is None:
            return
        try:
            self.feed = open_watchdog_feed(*self.feed_gpio)
        except (OSError, ImportError) as exc:
            self._drive_failed(f"cannot request the watchdog feed {self.feed_gpio[0]}:{self.feed_gpio[1]}: {exc}")

    def feeding(self, now_s: float | None = None) -> bool:
        """Whether the watchdog gets edges at ``now_s`` (``time.monotonic()``, s; default now): outputs released by
        the last decision, which is recent (half the watchdog's timeout: a starved or frozen guard stops feeding,
        and the outputs stop at most 1.5 x ``esc.output_enable_feed_timeout_s`` after its last decision)."""
        now_s = time.monotonic() if now_s is None else now_s
        fresh = now_s - self._last_decision <= 0.5 * float(self.feed_timeout_s or 0.0)
        return fresh and not self.core.asserted and not self.core.drive_fault

    def _feed_quiet_s(self, now_s: float) -> float:
        """Seconds since the last rising edge sent or the last release, whichever is later (0 before any edge)."""
        return 0.0 if self._last_rise is None else now_s - max(self._last_rise, self._released_at)

    def watchdog_ran_out(self) -> str:
        """'' or why the watchdog has (probably) disabled the outputs although this guard released them: no rising
        edge sent for longer than its timeout (this process was frozen or starved). The outputs then stay off until
        the ESC has reported disarmed at neutral in a beat acknowledging a guard ERROR beat sent after the stall
        (:mod:`.core`): thrust comes back only through a new arm request. This holds whatever the last ESC beat
        said: that beat may predate an arm (beats are 40 ms apart), and a stall with the ESC in fact
        disarmed costs one assertion, released by its first beat acknowledging it."""
        if not self.feeds or self.core.asserted:
            return ""
        quiet = self._feed_quiet_s(time.monotonic())
        if quiet <= float(self.feed_timeout_s):
            return ""
        return (f"no watchdog feed edge for {quiet:.2f} s (esc.output_enable_feed_timeout_s "
                f"{float(self.feed_timeout_s):g}): the guard stalled, the hardware watchdog cut the outputs")

    def feed_tick(self) -> None:
        """Toggle the feed line (twice ``esc.output_enable_feed_rate_hz``) while :meth:`feeding`; else hold it.

        The time is read before the check and the edge, so a stall anywhere after the check counts as a quiet feed.
        A rising edge that went out later than the watchdog's timeout after the previous one (this process stalled
        between its check and the edge, when the watchdog may already have cut the outputs and the edge let them
        through again) runs the decision at once (:meth:`tick`, which latches the stall) before it counts."""
        asked = time.monotonic()  # before the check and the edge: quiet times are upper bounds
        if not self.feeding(asked):
            return
        if self.feed is None:
            if time.monotonic() - self._last_drive_attempt < DRIVE_RETRY_S:
                return
            self._last_drive_attempt = time.monotonic()
            self._open_feed()
            if self.feed is None:
                return
        try:
            self.feed.set_high(not self._feed_high)
            self._feed_high = not self._feed_high
            if self._feed_high:
                self.feed_edges += 1
                if self._feed_quiet_s(time.monotonic()) > float(self.feed_timeout_s):
                    self.tick()  # stalled between the check and the edge: latch before the edge counts as a feed
                self._last_rise = asked
        except OSError as exc:
            self._drive_failed(f"cannot feed the watchdog: {exc}")

    # -- outputs
    def _open_line(self) -> None:
        """Request the /OE line (configured and not injected); a failure is a drive fault (:meth:`_drive_failed`)."""
        if self.line is not None or self.gpio is None:
            return
        self._last_drive_attempt = time.monotonic()
        try:
            self.line = open_output_enable(*self.gpio)
        except (OSError, ImportError) as exc:
            self._drive_failed(f"cannot request /OE {self.gpio[0]}:{self.gpio[1]}: {exc}")
            return
        self._check_release()

    def _check_release(self) -> None:
        """How the line behaves once freed (module docstring): a cause of its own unless it returns to the pull-up.
        A line without ``release_problem`` (a test's stand-in) is taken as returning."""
        try:
            fault = self.line.release_problem() if hasattr(self.line, "release_problem") else ""
        except OSError as exc:
            fault = f"cannot tell how a freed /OE line behaves: {exc}"
        if fault and fault != self.core.release_fault:
            self.get_logger().error(f"/OE: {fault}: outputs stay off")
            self.diag.set_state("cannot trust /OE", DiagnosticStatus.ERROR, fault)
        self.core.on_release(fault)

    def _device(self) -> I2CDevice:
        if self.device is None:
            if self._bus is None:
                self._bus = open_shared_bus() or open_smbus(self._bus_number)
            self.device = I2CDevice(self._bus, self._address, "pca9685-guard", retries=1)
        return self.device

    def _silence_registers(self) -> None:
        """Every output full OFF, then SLEEP (:func:`.outputs_off.silence_chip`)."""
        silence_chip(self._device())

    def _drive_failed(self, reason: str) -> None:
        """The guard could not drive /OE or silence the chip: a cause of its own (ERROR heartbeat: the ESC refuses
        to arm and disarms) until a later attempt succeeds."""
        self.silence_failures += 1
        self.diag.count("silence_failed")
        self.diag.set_state("cannot silence", DiagnosticStatus.ERROR, reason)
        self.get_logger().error(reason, throttle_duration_sec=2.0)
        self.core.on_drive(reason)

    def _drive_ok(self) -> None:
        if self.core.drive_fault:
            self.get_logger().info("the outputs can be silenced again")
            if not self.core.release_fault:
                self.diag.set_state("ok", DiagnosticStatus.OK)
        self.core.on_drive("")

    def _apply(self, asserted: bool, force: bool = False) -> None:
        """Drive /OE (or write the registers) for ``asserted``; failures become a drive fault of the core, never
        raised. After a failure the line request (wired) or the chip (a read of MODE1, unwired) is tried again every
        :data:`DRIVE_RETRY_S`, and only a success clears it."""
        now = time.monotonic()
        retry_due = now - self._last_drive_attempt >= DRIVE_RETRY_S
        try:
            if self.wired:
                if self.line is None:
                    if not retry_due:
                        return
                    self._open_line()
                    if self.line is None:
                        return
                self.line.set_high(asserted)
                self._drive_ok()
            elif asserted and (force or self.core.drive_fault or self.core.esc_state == OUTPUT_COMMANDING):
                if force or now - self._last_rewrite > REWRITE_INTERVAL_S:
                    self._last_rewrite = self._last_drive_attempt = now
                    self._silence_registers()
                    self._drive_ok()
            elif self.core.drive_fault and retry_due:
                self._last_drive_attempt = now
                self._device().read_byte_data(p.MODE1)  # the chip answers: the next silencing can reach it
                self._drive_ok()
        except (OSError, I2CError, ImportError) as exc:
            self._last_drive_attempt = now
            self._drive_failed(f"cannot silence the outputs: {exc}")

    # -- inputs
    def _armed_through(self) -> bool:
        return self.core.esc_armed and not self.core.asserted

    def on_esc(self, msg: Beat) -> None:
        """An accepted ``esc/heartbeat``: the ESC's output state and armed flag, and the newest beat of this guard the
        ESC has handled (core module docstring; an echo of another boot acknowledges nothing)."""
        self.esc_age.heard()
        ack = msg.guard_seq if msg.guard_boot_id == self.heartbeat.boot_id else 0
        state = msg.output_state if msg.output_state in (OUTPUT_NEUTRAL, OUTPUT_COMMANDING) else OUTPUT_UNKNOWN
        self.core.on_esc(state, bool(msg.armed), ack)

    def on_supervisor(self, msg: Beat) -> None:
        """An accepted ``supervisor/heartbeat``: OK or the breach."""
        self.supervisor_age.heard()
        self.core.on_supervisor(heartbeat_ok(msg), msg.message)

    # -- tick
    def check_identity(self) -> str:
        """Feed the heartbeats' publishers to their identity checks and the first fault to the core; returns it."""
        faults = [w.check() for w in self.watches.values()]
        fault = next((f for f in faults if f), "")
        self.core.on_identity(fault)
        return fault

    def tick(self) -> None:
        self.tick_gaps.tick()
        self._last_decision = time.monotonic()
        for kind, age in (("esc", self.esc_age), ("supervisor", self.supervisor_age)):
            age.tick()
            # a stale one's waiting beats taken first (starved)
            self.watches[kind].fresh(age, self.timeout_s)
        self.check_identity()
        self.core.on_stall(self.watchdog_ran_out())
        beat_seq = self.heartbeat.seq + 1  # the beat below carries this decision
        asserted, changed = self.core.decide(self.esc_age.age_s, self.supervisor_age.age_s, beat_seq)
        # the beat before the write: a slow /OE or register write (an emulated line's socket round trip under load:
        # up to 135 ms measured) does not hold it; the write follows in the same tick
        if changed and asserted:
            self.assertions += 1
            self.diag.count("asserted")
            self.get_logger().warn(f"outputs silenced: {self.core.reason}")
        elif changed:
            self._released_at = time.monotonic()
            self.get_logger().info("outputs enabled: the ESC reports disarmed at neutral, after an ERROR beat")
        self.heartbeat.publish(not asserted, self.core.reason if asserted else "outputs enabled")
        self.diag.published()
        # without /OE, the registers are written only once the ESC was heard (a guard starting before the ESC has
        # nothing to silence: the ESC's own start-up writes neutral before anything runs)
        self._apply(asserted, force=changed and (self.wired or math.isfinite(self.esc_age.age_s)))
        if self.core.drive_fault and not asserted:  # the write failed: a cause, said in a beat of its own at once
            asserted, _ = self.core.decide(self.esc_age.age_s, self.supervisor_age.age_s, self.heartbeat.seq + 1)
            if asserted:
                self.heartbeat.publish(False, self.core.reason)
        # systemd's watchdog hears from this process alone, and only while all three safety processes run
        self.notifier.update({"esc": self.esc_age.age_s, "supervisor": self.supervisor_age.age_s}, self.timeout_s)

    def _diag_extra(self):
        return [("asserted", self.core.asserted), ("reason", self.core.reason), ("assertions", self.assertions),
                ("silence_failures", self.silence_failures), ("drive_fault", self.core.drive_fault or "none"),
                ("output_enable_gpio", f"{self.gpio[0]}:{self.gpio[1]}" if self.gpio else "not wired"),
                ("watchdog_feed", ("feeding" if self.feeding() else "held") if self.feeds else "not fitted"),
                ("watchdog_feed_edges", self.feed_edges),
                ("systemd_watchdog", (self.notifier.reason or "pinging") if self.notifier.enabled else "no unit"),
                ("esc_age_s", f"{self.esc_age.age_s:.2f}"), ("supervisor_age_s", f"{self.supervisor_age.age_s:.2f}"),
                ("heartbeat_identity", self.core.identity_fault or "ok"),
                ("heartbeats_rejected", sum(w.identity.rejected for w in self.watches.values())),
                ("heartbeats_taken_late", sum(w.taken_late for w in self.watches.values())), *self.tick_gaps.report()]

    def close(self) -> None:
        """Shutdown: with /OE, drive it high and release the line (the pull-up keeps it off). Without /OE, nothing:
        the ESC, which loses this heartbeat, disarms and writes neutral itself (sleeping the chip under a running
        ESC would only fight its read-back)."""
        self._last_decision = -1e9  # no more edges on the watchdog feed
        if self.feed is not None:
            release = getattr(self.feed, "release", None)
            if release is not None:
                release()
        if not self.wired:
            return
        self._apply(True, force=True)
        if self.line is not None:
            release = getattr(self.line, "release", None)
            if release is not None:
                release()


def main(args=None) -> int:
    """``python -m hindrax_bringup.guard.node --ros-args --params-file ros_ws/config/hindrax.yaml``."""
    return run_node(OutputGuardNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
