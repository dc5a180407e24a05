"""ESC output decisions, pure (no ROS, no bus): when thrust may reach the wire, what is written, and why not.

:class:`EscCore` is the state machine of the ESC node (:mod:`.node`, docs/architecture.md §8). Its inputs are
explicit method calls; time comes from an injected steady clock (``clock``, seconds, ``time.monotonic`` on the
vehicle) and, for the command watchdog, from the ROS time passed with each command and tick. Its outputs are
:attr:`EscCore.armed`, :attr:`EscCore.output_state`, :attr:`EscCore.reason` and, from :meth:`EscCore.decide`,
the pulse widths to write now. The node owns the bus and the messages and does what the core decides.

Rules (one test row each in ``test/test_esc_core.py``):

* **Chip** (:meth:`EscCore.chip_result`: what a chip job's result means): thrust needs neutral confirmed on the
  chip by read-back (:meth:`EscCore.chip_confirmed`). A chip
  that cannot be written or read back (:meth:`EscCore.chip_lost`) makes the output state UNKNOWN (never
  "neutral"), disarms and drops the command; a read-back mismatch (:meth:`EscCore.chip_mismatch`) disarms.
* **Retry** (:meth:`EscCore.retry_due`): an unreachable chip is retried with a back-off (:data:`RETRY_MIN_S`
  doubling to :data:`RETRY_MAX_S`), except while the last width written may still be on the wire (the bus failed
  after a non-neutral write, and with /OE not wired nothing else stops it): then at every tick, so that a returning
  bus gets neutral within one tick period. The node's first write to a returning chip is neutral.
* **Arming** (:meth:`EscCore.arm_refusal`): refused while the oscillator is not calibrated, neutral is not
  confirmed, the supervisor's or the guard's heartbeat is not trusted (:meth:`EscCore.set_peers`), or neutral has
  not been on the wire, with the guard letting it through, for ``max(arming_time_s, guard_confirm_s)``. A guard
  verdict that is not trusted restarts that time. Disarm is always accepted.
* **Peers**: a heartbeat verdict that is not trusted while armed disarms at once (reason kept).
* **Commands** (:func:`command_fault`): a command with the wrong number of widths, a non-finite width, a width
  outside the ESC's physical range [``min_us``, ``max_us``] (a default-constructed message's 0.0, 3000 us) or
  whose own ``armed`` flag is false is a fault: neutral on every channel and the reason, never a clamp into
  thrust. The fault holds until the next valid command.
* **Command source** (:func:`command_source_fault`, :meth:`EscCore.set_command_source`): commands come only from the
  ``thrust_allocation`` node, alone on the topic. Any other publisher (``hindrax thruster-test`` goes through the
  allocation; a script, a replayed bag) refuses arming, disarms while armed and holds neutral until it is gone.
  A publisher not named yet by discovery holds neutral and refuses arming without a disarm, until it is named or
  :data:`NAME_RESOLVE_BOUND_S` makes it a fault.
* **Chip results**: a failed configure, read-back or neutral write is a lost chip; a failed thrust write drops the
  command (the node writes neutral); a read-back mismatch asks for a re-initialisation; a result of a job posted
  before the chip was lost changes nothing but what is known to be on the wire.
* **Watchdog**: armed, a command older than ``watchdog_timeout_s`` (ROS time) gives neutral; so does no command
  for ``steady_watchdog_s`` of steady time (:meth:`EscCore.steady_check`: a stopped ROS clock).
* **Output**: armed with a fresh valid command -> the command's widths through :class:`EscOutput` (reversal,
  trim, slew limit, PCA9685 counts rounded away from neutral outside the deadband); otherwise neutral."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from hindrax_common.process.dds_transport import UNNAMED_NODE

__all__ = ["OUTPUT_UNKNOWN", "OUTPUT_NEUTRAL", "OUTPUT_COMMANDING", "RETRY_MIN_S", "RETRY_MAX_S", "GUARD_CONFIRM_S",
           "COMMAND_NODE", "CONFIGURE", "WRITE", "NEUTRAL", "READBACK", "EscOutput", "EscCore", "EscDecision",
           "ChipOutcome", "SteadyWatchdog", "command_fault", "command_source_fault", "command_source_unnamed",
           "heartbeat_verdict", "UNNAMED_NODE", "NAME_RESOLVE_BOUND_S"]

#: output states, the values of hindrax_msgs/ThrusterPwm ``output_state`` (checked equal in the tests)
OUTPUT_UNKNOWN, OUTPUT_NEUTRAL, OUTPUT_COMMANDING = 0, 1, 2
STATE_NAMES = {OUTPUT_UNKNOWN: "unknown", OUTPUT_NEUTRAL: "neutral", OUTPUT_COMMANDING: "commanding"}
#: first retry of an unreachable bus or chip, s (doubled after every failure up to :data:`RETRY_MAX_S`)
RETRY_MIN_S = 0.25
RETRY_MAX_S = 4.0
#: the shortest time at neutral, with the output guard letting it through, before an arm is accepted, whatever
#: ``esc.arming_time_s`` says, s: two guard ticks (20 Hz) and their delivery. A guard ERROR published just before
#: the ESC's own recovery (an I2C outage: the ESC reconfigures the chip within 15 ms of reporting UNKNOWN) arrives
#: within it, so an arm is never accepted on the guard's stale OK and undone at once (measured in the safety bench
#: with arming_time_s 0: 1 in about 115 cycles of ESC hung, arm, I2C outage, arm)
GUARD_CONFIRM_S = 0.15
#: the one node that may publish ``thrusters/command_pulse_width`` (docs/architecture.md §8.2)
COMMAND_NODE = "thrust_allocation"
#: how long a command publisher may stay unnamed before it is a command source fault, s: discovery names an
#: endpoint within one participant-announcement round (0.1 s quiet); the rounds stretch on a loaded machine
NAME_RESOLVE_BOUND_S = 2.0
#: chip jobs (:mod:`.worker`): (re)configure and read back; write the widths if they changed; write them whatever is
#: believed on the chip (a neutral for safety); read the registers back
CONFIGURE, WRITE, NEUTRAL, READBACK = "configure", "write", "neutral", "readback"


@dataclass(frozen=True)
class ChipOutcome:
    """What a chip job's result means (:meth:`EscCore.chip_result`): ``event`` is ``"confirmed"`` (neutral read
    back), ``"lost"`` (UNKNOWN; ``new``: a new outage), ``"reinit"`` (read-back mismatch: re-initialise the chip),
    ``"write_failed"`` (write neutral now) or ``"done"``; ``message`` says why; ``count``: the diagnostics counter
    to increment ('' none)."""

    event: str
    message: str = ""
    count: str = ""
    new: bool = False


class SteadyWatchdog:
    """The steady-clock command watchdog for a ROS clock that stops (``use_sim_time`` with a dead ``/clock``,
    where the ROS-time watchdog stands still): trips after ``timeout_s`` of steady time without a command while
    active. Only executor-alive time counts: a gap between two checks counts at most ``2 * period_s``, so a stalled
    process does not trip it when it resumes. Times in s (``time.monotonic`` on the vehicle)."""

    def __init__(self, period_s: float, timeout_s: float, t_s: float) -> None:
        self.period_s, self.timeout_s = float(period_s), float(timeout_s)
        self.last_check_s = self.last_command_s = float(t_s)
        self.age_s = 0.0
        self.trips = 0

    def command(self, t_s: float) -> None:
        """A command arrived at ``t_s``."""
        self.age_s, self.last_command_s = 0.0, float(t_s)

    def check(self, t_s: float, active: bool) -> bool:
        """A check at ``t_s``; ``active``: armed with a command held. True when it trips (counted)."""
        gap, self.last_check_s = t_s - self.last_check_s, t_s
        if not active:
            self.age_s = 0.0
            return False
        self.age_s += min(max(gap, 0.0), t_s - self.last_command_s, 2.0 * self.period_s)
        if self.age_s > self.timeout_s:
            self.trips += 1
            return True
        return False


def command_source_fault(node_names: Sequence[str], topic: str = "thrusters/command_pulse_width",
                         alive: int | None = None, unnamed_for_s: float = 0.0) -> str:
    """Why the command topic cannot be trusted ('' when it can): ``node_names`` of every publisher the graph shows
    on it (``get_publishers_info_by_topic``) and ``alive``, how many of them are live (the subscription's DDS
    liveliness count; None: count the names). Only :data:`COMMAND_NODE` may be there, and only one live; none is
    no fault (no command comes). The live count, not the names, decides "one": a killed process stays in the graph
    for about 20 s (Fast DDS participant lease), its writer is not alive after the 1 s liveliness lease, so a
    respawned allocation is not refused as a second one.

    A publisher seen before its participant's node names arrived is named :data:`UNNAMED_NODE` (discovery not
    finished): not a fault by itself (:func:`command_source_unnamed` holds the commands meanwhile) until it has
    been there ``unnamed_for_s`` > :data:`NAME_RESOLVE_BOUND_S`; it still counts in ``alive``."""
    strangers = sorted({n for n in node_names if n not in (COMMAND_NODE, UNNAMED_NODE)})
    if strangers:
        return (f"{topic} published by {', '.join(map(repr, strangers))}: only {COMMAND_NODE!r} may command the "
                "thrusters")
    if UNNAMED_NODE in node_names and unnamed_for_s > NAME_RESOLVE_BOUND_S:
        return (f"{topic} has a publisher still unnamed after {unnamed_for_s:.1f} s (discovery bound "
                f"{NAME_RESOLVE_BOUND_S:g} s): only {COMMAND_NODE!r} may command the thrusters")
    count = len(node_names) if alive is None else int(alive)
    if count > 1:
        return f"{count} live publishers named {COMMAND_NODE!r} on {topic}: only one may command the thrusters"
    return ""


def command_source_unnamed(node_names: Sequence[str], topic: str = "thrusters/command_pulse_width") -> str:
    """Why the commands are held at neutral without a disarm ('' when they are not): a publisher on ``topic`` whose
    node name discovery has not delivered yet (:data:`UNNAMED_NODE`). It may be a foreign one: its commands (and
    the allocation's, which cannot be told apart) are refused until it is named or the bound makes it a fault
    (:func:`command_source_fault`)."""
    if UNNAMED_NODE in node_names:
        return f"{topic} has a publisher not named yet (discovery): commands held at neutral"
    return ""


def command_fault(widths_us: Sequence[float], armed: bool, n: int, min_us: float, max_us: float) -> str:
    """Why a ThrusterPwm command must not reach the wire ('' when it may).

    ``widths_us`` (thruster order, us), the message's own ``armed`` flag, the expected count ``n`` and the ESC's
    physical range [``min_us``, ``max_us``] (``thrusters.pulse_width_min_us``/``max_us``: full reverse / full
    forward of the Basic ESC, docs/devices.md §5.2). A width outside it is a fault, not a clamp: 0.0 is a
    default-constructed message, 3000 us a unit or scaling error, and neither means "full thrust"."""
    if not armed:
        return "command says armed=false (its sender does not mean thrust)"
    try:
        w = np.asarray(widths_us, dtype=float)
    except (TypeError, ValueError):
        return "command widths are not numbers"
    if w.shape != (n,):
        return f"command has {w.size} pulse widths, expected {n}"
    if not np.all(np.isfinite(w)):
        return f"command has a non-finite pulse width: {w.tolist()}"
    bad = (w < min_us) | (w > max_us)
    if np.any(bad):
        i = int(np.argmax(bad))
        return (f"command width {w[i]:g} us (thruster {i}) outside the ESC's range {min_us:g}-{max_us:g} us "
                "(thrusters.pulse_width_min_us/max_us)")
    return ""


def heartbeat_verdict(name: str, topic: str, age_s: float, timeout_s: float, ok: bool, message: str) -> str:
    """Whether a peer's heartbeat (supervisor, output guard) is trusted now: '' or the reason it is not.

    ``age_s``: since the last beat (``math.inf`` never heard); ``ok``: its level was OK; ``message``: its text."""
    if not age_s <= timeout_s:
        return (f"no {name} heartbeat" + (f" for {age_s:.2f} s" if math.isfinite(age_s) else "") +
                f" ({topic}, timeout {timeout_s:g} s): {name} not running or hung")
    if not ok:
        return f"{name} not OK: {message}"
    return ""


class EscOutput:
    """Command -> per-channel pulse widths (pure): reversal, trim, limits, slew, the PCA9685's count grid.

    channels (n,): PCA9685 channel of each thruster; reversed (n,) bool (mirror about neutral); trim_us (n,)
    (moves the channel's neutral, the ESC's own stop point); limits and neutral in us; slew_rate_us_per_s (0 =
    off). ``count_us`` (> 0: one PCA9685 count at the actual prescale and oscillator, datasheet §7.3.5) and
    ``deadband_us`` (the ESC's half-width around its neutral, docs/devices.md §5.2): a command outside the deadband
    is put on the count grid rounded *away* from the channel's neutral, so that the chip's 12-bit rounding never
    moves a thrust command back inside the deadband (a reversed thruster's mirrored 1525 us landed at 1474.8 +
    trim before). ``count_us`` 0 leaves the widths off the grid (the chip rounds half-up).

    ``outputs_off``: the oscillator is not measured (``esc.oscillator_calibrated`` false), so no width is known to
    be neutral on the wire: "neutral" is then no pulse at all, 0 us (the channel's full-OFF bit), which the Basic
    ESC treats as stop (docs/devices.md §5.2).

    ``target(command, dt_s)`` returns the (n,) widths to write now. Raises :class:`ValueError` for a command of
    the wrong length or with a non-finite value. Without a slew limit the widths of a command are computed once
    (the same command object again returns them as they are); a new object, or :meth:`neutral`, computes anew."""

    def __init__(self, channels, reversed_, trim_us, min_us: float, neutral_us: float, max_us: float,
                 slew_rate_us_per_s: float = 0.0, count_us: float = 0.0, deadband_us: float = 0.0,
                 outputs_off: bool = False):
        self.channels = np.asarray(channels, dtype=int)
        self.reversed = np.asarray(reversed_, dtype=bool)
        self.trim_us = np.asarray(trim_us, dtype=float)
        self.min_us, self.neutral_us, self.max_us = float(min_us), float(neutral_us), float(max_us)
        self.slew = float(slew_rate_us_per_s)
        self.count_us = float(count_us)
        self.deadband_us = float(deadband_us)
        self.current = np.full(len(self.channels), self.neutral_us)
        self._computed_for: object = None  # the command object :attr:`current` was computed for (no slew limit)
        # computed once (read-only): the output path asks for it twice per 20 ms period
        self._channel_neutral = np.zeros(len(self.channels)) if outputs_off else np.clip(
            np.full(len(self.channels), self.neutral_us) + self.trim_us, self.min_us, self.max_us)
        self._channel_neutral.flags.writeable = False
        self._grid_bounds = (math.ceil(self.min_us / self.count_us - 1e-9),
                             math.floor(self.max_us / self.count_us + 1e-9)) if self.count_us > 0.0 else (0, 0)

    @classmethod
    def from_config(cls, thrusters, slew_rate_us_per_s: float, count_us: float,
                    outputs_off: bool = False) -> "EscOutput":
        """From the ``thrusters`` configuration section (channels, reversal, trims, widths, deadband)."""
        t = thrusters
        return cls([th.esc_channel for th in t.thrusters], [th.reversed for th in t.thrusters],
                   [th.trim_us for th in t.thrusters], t.pulse_width_min_us, t.pulse_width_neutral_us,
                   t.pulse_width_max_us, slew_rate_us_per_s, count_us=count_us, deadband_us=t.deadband_us,
                   outputs_off=outputs_off)

    def channel_neutral(self) -> np.ndarray:
        """(n,) ``neutral_us + trim_us`` clamped to the limits, us (read-only); zeros with ``outputs_off``."""
        return self._channel_neutral

    def neutral(self) -> np.ndarray:
        """(n,) neutral widths (:meth:`channel_neutral`; the widths :meth:`target` gives for a neutral command).
        Also resets the slew-limiter state (neutral is immediate)."""
        self.current = self.channel_neutral().copy()
        self._computed_for = None
        return self.current.copy()

    def on_grid(self, widths_us: np.ndarray) -> np.ndarray:
        """Widths put on the count grid: outside the deadband (at or beyond ``deadband_us`` from the channel's
        neutral) rounded away from neutral, else to the nearest count (half-up, as the chip's encoder); never beyond
        [``min_us``, ``max_us``]."""
        if self.count_us <= 0.0:
            return widths_us
        mid = self.channel_neutral()
        x = widths_us / self.count_us
        outside = np.abs(widths_us - mid) >= self.deadband_us - 1e-9
        counts = np.where(outside, np.where(widths_us > mid, np.ceil(x - 1e-9), np.floor(x + 1e-9)), np.floor(x + 0.5))
        # never beyond the ESC's range: the nearest count inside it there
        lo, hi = self._grid_bounds
        return np.clip(counts, lo, hi) * self.count_us

    def target(self, command, dt_s: float) -> np.ndarray:
        """Pulse widths to write for a fresh, armed ``command`` (thruster order, us)."""
        if command is self._computed_for:
            return self.current.copy()
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
        self._computed_for = command if self.slew <= 0.0 else None
        return out.copy()


@dataclass(frozen=True)
class EscDecision:
    """What to put on the wire now: ``widths_us`` (n,), the ``output_state`` it gives (NEUTRAL or COMMANDING),
    the ``state`` text for diagnostics and, for neutral, why (``reason``; '' when nothing is wrong)."""

    widths_us: np.ndarray
    output_state: int
    state: str
    reason: str = ""


class EscCore:
    """The ESC's state machine (module docstring). ``output``: the :class:`EscOutput`; ``clock``: steady time, s;
    ``period_s``: the node's tick period, s; ``steady_watchdog_s``: the steady-clock watchdog's timeout, s (default
    ``watchdog_timeout_s``). Its state is read-only outside: only its methods change it.

    Times: ``clock()`` for the chip, the arming time, the retries and the steady-clock watchdog; ROS time
    ``ros_t_s`` (passed in) for the command watchdog, so that a simulation's held time holds the watchdog too."""

    def __init__(self, output: EscOutput, *, arming_time_s: float, watchdog_timeout_s: float,
                 oscillator_calibrated: bool, clock: Callable[[], float], period_s: float,
                 steady_watchdog_s: float | None = None, guard_confirm_s: float = GUARD_CONFIRM_S) -> None:
        self.output = output
        self.arming_time_s = float(arming_time_s)
        self._watchdog_s = float(watchdog_timeout_s)
        self._steady = SteadyWatchdog(period_s, watchdog_timeout_s if steady_watchdog_s is None else steady_watchdog_s,
                                      clock())
        self.oscillator_calibrated = bool(oscillator_calibrated)
        self.clock = clock
        self.guard_confirm_s = float(guard_confirm_s)
        self._armed = False
        self._output_state = OUTPUT_UNKNOWN
        #: why the output is neutral or unknown now ('' when nothing is wrong)
        self.reason = "PCA9685 not configured yet"
        self._command: np.ndarray | None = None
        self.command_t_s: float | None = None  # ROS time of the command's arrival, s
        self.neutral_confirmed_at: float | None = None
        self.neutral_on_wire_since: float | None = None
        self.command_source = ""  # '' or why the command topic is not trusted (command_source_fault)
        self.command_unnamed = ""  # '' or why commands are held without a disarm (command_source_unnamed)
        self.supervisor_refusal = "no supervisor heartbeat yet"
        self.guard_refusal = "no output-guard heartbeat yet"
        #: the last widths written may still be on the wire although the chip cannot be reached
        self.stale_width_possible = False
        self.retry_s = RETRY_MIN_S
        self.last_attempt: float | None = None
        self.watchdog_trips = 0
        self.watchdog_trip_t_s: float | None = None  # ROS time of the last ROS-time watchdog trip (decide), s
        self.heartbeat_disarms = 0
        self.rejected_commands = 0
        self.last_written: np.ndarray = output.neutral()

    # the decided state, read-only outside (the node, its diagnostics, the tests and the benches read it)
    armed = property(lambda self: self._armed)
    output_state = property(lambda self: self._output_state)
    #: the held command's widths, us (None: none held)
    command = property(lambda self: self._command)
    watchdog_s = property(lambda self: self._watchdog_s)
    steady_watchdog_s = property(lambda self: self._steady.timeout_s)
    steady_watchdog_trips = property(lambda self: self._steady.trips)
    #: ``clock()`` of the last command taken (the benches' reference for the steady-clock watchdog)
    last_command_s = property(lambda self: self._steady.last_command_s)

    # ------------------------------------------------------------------ chip
    def chip_attempt(self) -> None:
        """The node is about to (re)configure the chip: neutral is no longer confirmed until it reads back."""
        self.last_attempt = self.clock()
        self.neutral_confirmed_at = None
        self.neutral_on_wire_since = None

    def chip_confirmed(self) -> None:
        """Neutral read back from the chip: output NEUTRAL, disarmed; the arming time may start."""
        self.neutral_confirmed_at = self.clock()
        self.retry_s = RETRY_MIN_S
        self.stale_width_possible = False
        self._output_state = OUTPUT_NEUTRAL
        self.last_written = self.output.channel_neutral().copy()
        self.reason = "holding neutral, disarmed"

    def chip_lost(self, reason: str) -> bool:
        """The chip cannot be written or read back: UNKNOWN, disarmed, no command, retry scheduled. Returns True
        when this is a new outage (for the node's log and counters)."""
        new = self._output_state != OUTPUT_UNKNOWN or self._armed
        if not np.allclose(self.last_written, self.output.channel_neutral()):
            self.stale_width_possible = True
        self._output_state = OUTPUT_UNKNOWN
        self._armed = False
        self._command = None
        self.neutral_confirmed_at = None
        self.neutral_on_wire_since = None
        self.retry_s = min(RETRY_MAX_S, self.retry_s * 2.0) if self.last_attempt is not None else RETRY_MIN_S
        self.reason = reason + (f"; the last widths written ({self._stale_text()}) may still be on the wire"
                                if self.stale_width_possible else "")
        return new

    def _stale_text(self) -> str:
        return ", ".join(f"{w:.0f}" for w in self.last_written) + " us"

    def chip_mismatch(self, reason: str) -> None:
        """A read-back found the chip changed (brown-out reset): disarmed; the node re-initialises it."""
        self._armed = False
        self._command = None
        self.reason = reason

    def wrote(self, widths_us: np.ndarray) -> None:
        """The node wrote these widths (decoded from the counts) to the chip. What is on the wire is known again;
        a write that lands while the chip counts as lost (a bus call that came back after the stuck bound) leaves a
        width that nothing confirmed: unless it is neutral, the chip is retried at every tick (module docstring)."""
        self.last_written = np.asarray(widths_us, dtype=float).copy()
        self.stale_width_possible = self._output_state == OUTPUT_UNKNOWN and \
            not np.allclose(self.last_written, self.output.channel_neutral())

    def retry_due(self) -> bool:
        """Whether the node should try the chip now (module docstring, Retry)."""
        if self.neutral_confirmed_at is not None:
            return False
        if self.stale_width_possible or self.last_attempt is None:
            return True
        return self.clock() - self.last_attempt >= self.retry_s

    def chip_result(self, kind: str, *, error: str = "", no_bus: bool = False, mismatch: str = "", wrote: bool = False,
                    written_us: np.ndarray | None = None, output_state: int = OUTPUT_NEUTRAL) -> ChipOutcome:
        """A chip job done (module docstring, Chip results): ``kind`` (:data:`CONFIGURE`, :data:`WRITE`,
        :data:`NEUTRAL`, :data:`READBACK`), its ``error`` ('' or why the bus failed; ``no_bus``: it could not be
        opened), a read-back ``mismatch`` ('' or what differed), ``wrote`` and ``written_us`` (n,) what is on the chip
        now, and the ``output_state`` the job's widths give."""
        if wrote and not error and written_us is not None:
            self.wrote(written_us)
        if kind == CONFIGURE:
            if not (error or mismatch):
                self.chip_confirmed()
                return ChipOutcome("confirmed", self.reason)
            why = (f"{error}; retrying" if no_bus else f"PCA9685 start-up failed: {error}" if error else
                   f"PCA9685 start-up not confirmed: {mismatch}")
            return self._lost(why, "no_bus" if no_bus else "i2c_error" if error else "readback_mismatch")
        if self.neutral_confirmed_at is None:
            return ChipOutcome("done")  # posted before the chip was lost: only a configure brings it back
        if kind == READBACK and error:
            return self._lost(f"PCA9685 read-back failed: {error}", "i2c_error")
        if kind == READBACK and mismatch:
            message = f"PCA9685 read-back mismatch: {mismatch}; re-initialised at neutral" + \
                (", disarmed (re-arm after esc.arming_time_s)" if self._armed else "")
            self.chip_mismatch(message)
            return ChipOutcome("reinit", message, "chip_reinit")
        if kind == WRITE and error:
            self._command = None
            return ChipOutcome("write_failed", f"fault: {error}", "output_exception")
        if error:
            return self._lost(f"cannot write neutral: {error}", "i2c_error")
        if kind != READBACK:
            self._output_state = output_state
        return ChipOutcome("done")

    def _lost(self, reason: str, count: str) -> ChipOutcome:
        new = self.chip_lost(reason)
        return ChipOutcome("lost", self.reason, count, new)

    # ------------------------------------------------------------------ peers and arming
    def set_peers(self, supervisor_refusal: str, guard_refusal: str) -> str:
        """The heartbeat verdicts ('' = trusted, else why not; :func:`heartbeat_verdict`). Returns the reason of
        a disarm they cause ('' when none). A guard that is not trusted restarts the arming time."""
        self.supervisor_refusal, self.guard_refusal = supervisor_refusal, guard_refusal
        refusal = self.peer_refusal()
        if guard_refusal or self.neutral_confirmed_at is None:
            self.neutral_on_wire_since = None
        elif self.neutral_on_wire_since is None:
            self.neutral_on_wire_since = self.clock()
        if refusal and self._armed:
            self.heartbeat_disarms += 1
            self.disarm(refusal)
            return refusal
        return ""

    def set_command_source(self, fault: str, unnamed: str = "") -> str:
        """The command topic's publishers checked (:func:`command_source_fault`): a fault drops the command and
        disarms while armed. ``unnamed`` (:func:`command_source_unnamed`, only without a fault): a publisher not
        named yet; the command is dropped and commands are refused (neutral) until it is named, without a disarm.
        Returns the reason of a disarm it causes ('' when none)."""
        self.command_source = fault
        self.command_unnamed = "" if fault else unnamed
        if fault or unnamed:
            self._command = None
        if fault and self._armed:
            self.disarm(fault)
            return fault
        return ""

    def peer_refusal(self) -> str:
        """Why the supervisor or the output guard forbid thrust now ('' when both are trusted)."""
        if self.supervisor_refusal:
            return self.supervisor_refusal
        if self.guard_refusal:
            return self.guard_refusal
        return ""

    def arming_remaining_s(self) -> float:
        """Seconds still needed at neutral, with the guard letting it through, before an arm (0 when ready)."""
        needed_s = max(self.arming_time_s, self.guard_confirm_s)
        if self.neutral_on_wire_since is None:
            return needed_s
        return max(0.0, needed_s - (self.clock() - self.neutral_on_wire_since))

    def arm_refusal(self, bus_error: str = "") -> str:
        """Why an arm request would be refused now ('' when it would be accepted)."""
        if not self.oscillator_calibrated:
            return ("esc.oscillator_calibrated is false: neutral on the wire depends on this PCA9685's oscillator "
                    "(nominal 25 MHz, parts measure 23-27 MHz). Measure the neutral pulse with a scope and run "
                    "`hindrax esc calibrate --measured-us X --write`")
        if self.neutral_confirmed_at is None:
            return ("PCA9685 not confirmed at neutral (not reachable or its registers did not read back)" +
                    (f": {bus_error}" if bus_error else ""))
        refusal = self.peer_refusal() or self.command_source or self.command_unnamed
        if refusal:
            return refusal
        remaining = self.arming_remaining_s()
        if remaining > 0.0:
            why = "esc.arming_time_s" if self.arming_time_s >= self.guard_confirm_s else \
                f"the output guard's OK confirmed for {self.guard_confirm_s:g} s"
            return f"ESC arming: {remaining:.1f} s more at neutral needed ({why})"
        return ""

    def request_arm(self, bus_error: str = "") -> str:
        """An arm request: '' when accepted (armed, neutral until a command arrives after it), else the refusal."""
        refusal = self.arm_refusal(bus_error)
        if refusal:
            return refusal
        self._armed = True
        self._output_state = OUTPUT_NEUTRAL
        self._command = None  # thrust only from commands that arrive after arming
        self.reason = ""
        return ""

    def disarm(self, reason: str) -> None:
        """Disarm (always accepted): no thrust until a new arm request."""
        self._armed = False
        self._command = None
        self.reason = reason

    # ------------------------------------------------------------------ commands and output
    def on_command(self, ros_t_s: float, widths_us: Sequence[float], armed: bool) -> str:
        """A ThrusterPwm command arrived at ROS time ``ros_t_s``. Returns the fault ('' when it is valid); a fault
        drops the held command, so the next :meth:`decide` gives neutral with the reason. Any command restarts the
        steady-clock watchdog."""
        self._steady.command(self.clock())
        fault = self.command_source or self.command_unnamed or \
            command_fault(widths_us, armed, len(self.output.channels), self.output.min_us, self.output.max_us)
        if fault:
            self.rejected_commands += 1
            self._command = None
            self.command_t_s = ros_t_s
            self.reason = f"command rejected: {fault}"
            return fault
        self._command = np.array(widths_us, dtype=float)
        self.command_t_s = ros_t_s
        if self.reason.startswith("command rejected") or self.reason.startswith("watchdog"):
            self.reason = ""
        return ""

    def steady_check(self, t_s: float) -> str:
        """The steady-clock watchdog at steady time ``t_s`` (every safety tick; it covers a ROS clock that stopped,
        where :meth:`decide` stands still): armed with a command held and none for ``steady_watchdog_s`` of
        executor-alive time (:class:`SteadyWatchdog`) drops the command. Returns the trip's reason ('' none)."""
        if not self._steady.check(t_s, self._armed and self._command is not None):
            return ""
        self.watchdog_trips += 1
        self.output_fault(f"steady-clock watchdog: no command for {self._steady.timeout_s:g} s")
        return self.reason

    def output_fault(self, reason: str) -> None:
        """Drop the command (neutral until the next one) with ``reason``: a steady-clock watchdog trip, or a fault in
        the node's output path (which writes neutral)."""
        self._command = None
        self.reason = reason

    def decide(self, ros_t_s: float, dt_s: float) -> EscDecision:
        """The widths to write now (``dt_s``: since the previous commanded write, for the slew limit). Applies the
        ROS-time watchdog. Raises :class:`ValueError` from :class:`EscOutput` (the node writes neutral)."""
        if self._armed and self._command is not None and self.command_t_s is not None \
                and ros_t_s - self.command_t_s > self._watchdog_s:
            self.watchdog_trips += 1
            self.watchdog_trip_t_s = ros_t_s
            self._command = None
            self.reason = f"watchdog: no command for {self._watchdog_s:g} s"
        if self._armed and self._command is not None:
            widths = self.output.on_grid(self.output.target(self._command, dt_s))
            return EscDecision(widths, OUTPUT_COMMANDING, "armed, commanding")
        return EscDecision(self.output.neutral(), OUTPUT_NEUTRAL,
                           "armed, neutral" if self._armed else "disarmed, neutral", self.reason)
