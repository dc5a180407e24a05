"""Identification goal decisions, pure (no ROS): which goal is accepted, what each control tick does, when it ends.

:class:`IdentificationCore` is the state machine of the identification node (:mod:`.node`, its module docstring
describes the interface). Its inputs are explicit calls: sensor samples (:meth:`~IdentificationCore.add_samples`,
the samples of :mod:`...vehicle.signals`), the ESC's written widths and armed flag
(:meth:`~IdentificationCore.on_pwm`), an accepted goal (:meth:`~IdentificationCore.accept`), the operator's
"continue" and, at every control tick, the ROS time (s) and whether a cancel was requested
(:meth:`~IdentificationCore.tick`). Its outputs are the ordered :class:`Event` list of each call: the statuses,
wrench (body FRD), feedback, estimates, calibration results, supervisor abort, log lines and the goal's end, which
the node turns into messages in that order. The campaign itself is the :class:`~.executive.Executive`.

Rules (one test row each in ``test/test_identification_core.py``):

* **Goals** (:func:`goal_problem`): an unknown DOF or calibration step, a level fraction outside (0, 1] or
  ``calibration_only`` without a step is refused; so is any goal while one runs.
* **Armed** (:data:`ARMED_GRACE_S`, :data:`ARMED_REPORTS`): an accepted goal waits for the ESC output's armed flag;
  past the grace, with that many ``thrusters/pulse_width`` reports since the goal's acceptance, all disarmed (or no
  report within ``sensor_timeout_s``), it ends with :data:`NOT_ARMED`, having commanded nothing and without a neutral
  hold. The ESC's reports decide, not the timer alone: a starved process ticks before it reads the reports waiting.
* **Sensors**: armed, the goal starts once every sensor of :data:`NEEDED_SENSORS` has published; none for
  ``sensor_timeout_s`` after acceptance, or a cancel before the start, stops it.
* **Samples**: those stamped more than :data:`FUTURE_STAMP_TOLERANCE_S` after the tick or
  :data:`STALE_STAMP_TOLERANCE_S` before the previous one are left out and counted (``samples_dropped``).
* **Stop** (done, abort, cancel, error): the final status, ``supervisor/abort`` with the reason unless it is one
  of :data:`NOT_SUPERVISOR_ABORTS`, then a zero wrench every tick until the ESC reports, after the stop, neutral
  widths or disarmed, or ``stop_timeout_s`` has passed; then the goal ends.
* **Disarm cause** (:meth:`~IdentificationCore.on_disarm_cause`, the supervisor's ``disarm_cause``,
  :mod:`hindrax_bringup.supervisor.disarm_cause`): a new cause while a goal runs is a stop of the thrust (a killed
  ESC reports nothing, only the output guard says so) and aborts it as :data:`DISARMED`; the end of a goal aborted
  as :data:`DISARMED` waits for the cause (within ``stop_timeout_s``) and its result and final status name it.
* **Status** (:data:`STATUS_PERIOD_S`): the running status goes out at once when the phase, DOF, level or
  message changes, else at most every period; ``idle`` every :data:`IDLE_STATUS_PERIOD_S` without a goal (a
  tick early by up to half a control tick counts: the node then ticks at that period).
* **Feedback**: at every change of DOF, level, prompt or step message and at least once per second, with the
  phase and the step's message; estimates every ``publish_period_s``.
* **Undo** (:attr:`~IdentificationCore.pending_undo`): the loads a stopped goal's calibration asked for and did not
  see removed are named in its result and confirmed first by the next goal (:class:`~.steps.Confirm`).
* **Starvation** (:meth:`~IdentificationCore.starved`, docs/architecture.md §10.1): a control tick that comes more than
  :data:`STARVED_WARN_TICKS` periods after the previous one (the steady clock's gap, measured by the node) is said in a
  warning naming it ("identification starved for 0.31 s"); one later than twice ``thrusters.wrench_timeout_s`` (the
  allocation has held neutral for as long as a wrench may be old: the manoeuvre is not what the executive commanded)
  stops the goal with that reason, which trips the supervisor (its ``disarm_cause`` then names the starvation).
* **Step gate** (:meth:`~IdentificationCore.clock_may_advance`): a simulator in the same process may not step
  past the next control tick while a goal runs."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

import numpy as np

from hindrax_common.config import DOFS, VehicleConfig
from hindrax_common.node_support.liveness import STARVED_WARN_TICKS, starvation, starved_stop_s

from ..model import calibration_topic
from ..model.campaign_record import CampaignRecord
from ...vehicle.signals import thrust_of_written_widths
from .executive import (CALIBRATION_STEPS, Executive, ExecutiveStatus, TickInput, calibration_forces, inclining_load,
                        ordered_samples)
from .steps import undo_line

__all__ = ["IdentificationCore", "GoalRun", "Event", "goal_problem", "NEEDED_SENSORS",
           "NOT_SUPERVISOR_ABORTS", "STATUS_PERIOD_S", "IDLE_STATUS_PERIOD_S", "ARMED_GRACE_S", "ARMED_REPORTS",
           "NOT_ARMED", "FUTURE_STAMP_TOLERANCE_S", "STALE_STAMP_TOLERANCE_S", "DISARMED", "STARVED_WARN_TICKS"]

#: sensors that must have published before a goal starts moving the vehicle
NEEDED_SENSORS = frozenset({"ms5837", "dvl75", "dvl75_attitude", "icm20948_gyro", "ping1d"})
#: the executive's abort reason when the thrust stopped under it
DISARMED = "ESC output disarmed"
#: abort reasons not sent to the safety supervisor (the executive's words): an operator's cancel,
#: and a disarmed ESC output (the thrusters are already stopped, possibly by the supervisor itself)
NOT_SUPERVISOR_ABORTS = frozenset({"cancelled", DISARMED})
#: period of ``identification/status`` while a goal runs and nothing changes, s (2 Hz: the progress on a topside
#: display; every change of phase, DOF, level or message goes out at once, so a bag's zero-order hold of the status
#: loses nothing)
STATUS_PERIOD_S = 0.5
#: period of the ``idle`` status without a goal, s; also the node's tick period then
IDLE_STATUS_PERIOD_S = 1.0
#: how long an accepted goal waits for the ESC to report armed (latched ``esc/output_state``, and
#: ``thrusters/pulse_width``: published on every write and at least every 0.1 s, ``hindrax_drivers.pca9685.node``)
#: before it fails, s (ROS time)
ARMED_GRACE_S = 0.5
#: how many ``thrusters/pulse_width`` reports (at least one every 0.1 s) since the goal's acceptance must say disarmed
#: before the goal ends as not armed: the ESC has answered since, so its disarmed state is not a report still queued
ARMED_REPORTS = 3
#: the result message of a goal whose ESC output did not report armed
NOT_ARMED = "ESC output not armed: call esc/set_armed first"
#: a sensor sample stamped further than this after the node's clock is impossible and left out (s): the drivers stamp
#: with their receive time or a device time converted to the ROS clock, both at or before the tick that takes them
FUTURE_STAMP_TOLERANCE_S = 1.0
#: a sample stamped further than this before the previous tick is stale and left out (s): sensor latencies through the
#: graph (a conversion start, a report's time of validity) are tens to hundreds of milliseconds
STALE_STAMP_TOLERANCE_S = 2.0


def goal_problem(dofs: Sequence[str], calibrate: Sequence[str], calibration_only: bool,
                 level_fractions: Sequence[float]) -> str:
    """Why a ``run_identification`` goal is refused (one line), "" when it is acceptable: DOFs from
    :data:`~hindrax_common.config.DOFS`, steps from :data:`~.executive.CALIBRATION_STEPS`, fractions of the DOF's
    authority in (0, 1], ``calibration_only`` only with a step."""
    bad = [d for d in dofs if d not in DOFS]
    if bad:
        return f"unknown DOF(s) {bad}; choose from {', '.join(DOFS)}"
    bad = [c for c in calibrate if c not in CALIBRATION_STEPS]
    if bad:
        return f"unknown calibration step(s) {bad}; choose from {', '.join(CALIBRATION_STEPS)}"
    if calibration_only and not calibrate:
        return "calibration_only without a calibration step"
    fr = list(level_fractions)
    if any(not (math.isfinite(x) and 0.0 < x <= 1.0) for x in fr):
        return f"level_fractions must be in (0, 1], got {fr}"
    return ""


@dataclass(frozen=True)
class Event:
    """One thing the node does, in order; ``kind`` and its ``data`` are below.

    ``status`` (phase name: idle, positioning, running, returning, done, aborted; ExecutiveStatus or None; message),
    ``wrench`` (body FRD wrench (6,), N and N m), ``feedback`` (ExecutiveStatus, operator prompt: the action feedback),
    ``estimates`` (the executive whose online estimates to publish), ``calibration`` (every step result since start,
    list of :func:`~..model.calibration_topic.statuses` items), ``abort`` (the reason for ``supervisor/abort``), ``log``
    (level info / warn / error, text), ``warn_throttled`` (text), ``end`` (the :class:`GoalRun` that ended: deliver its
    result)."""

    kind: str
    data: tuple = ()


@dataclass
class GoalRun:
    """One accepted goal: its handle (opaque here), executive and end state."""

    handle: Any
    executive: Any
    accepted_s: float
    written_us: np.ndarray
    stop_since_s: float | None = None
    ended: bool = False
    pwm_count_at_stop: int = 0
    pwm_count_at_accept: int = 0
    error: str = ""
    record: CampaignRecord | None = None
    last_feedback: tuple = field(default_factory=lambda: (None, -1))
    last_feedback_s: float = -math.inf
    calibration_results: int = 0  # step results of this goal already published on identification/calibration
    cause_at_start: str = ""  # the supervisor's disarm cause when the campaign started (an older stop's)
    cause: str = ""  # a DISARMED abort's reason with its cause, once known (the result message)


class IdentificationCore:
    """The identification node's goal and tick logic (module docstring).

    config: the vehicle configuration; tick_s: control tick period (s); publish_period_s: period of the online
    estimates (s); dvl_lock_timeout_s, sensor_timeout_s, stop_timeout_s: the node parameters (s, > 0);
    executive: factory ``(config, dofs, levels, **kwargs) -> Executive`` (tests pass a stand-in)."""

    def __init__(self, config: VehicleConfig, *, tick_s: float, publish_period_s: float, dvl_lock_timeout_s: float,
                 sensor_timeout_s: float, stop_timeout_s: float, executive: Callable[..., Any] = Executive) -> None:
        self.config = config
        self.tick_s = float(tick_s)
        self.publish_period_s = float(publish_period_s)
        self.dvl_lock_timeout_s = float(dvl_lock_timeout_s)
        self.sensor_timeout_s = float(sensor_timeout_s)
        self.stop_timeout_s = float(stop_timeout_s)
        self._executive = executive
        self.n_thrusters = len(config.thrusters.thrusters)
        self.neutral_us = float(config.thrusters.pulse_width_neutral_us)
        self.samples: list = []
        self.seen: set[str] = set()
        self.written: np.ndarray | None = None
        self.pwm_count = 0
        self.armed = False
        #: the supervisor's ``disarm_cause`` ('' while none): why the thrust last stopped, and the next step
        self.disarm_cause = ""
        #: loads an aborted goal left on the vehicle, (remove code, instruction): the next goal confirms them first
        self.pending_undo: list[tuple[str, str]] = []
        #: sensor samples left out since start (:data:`FUTURE_STAMP_TOLERANCE_S`, :data:`STALE_STAMP_TOLERANCE_S`)
        self.samples_dropped = 0
        self.run: GoalRun | None = None
        self.last_tick_s: float | None = None  # ROS time of the last control tick of a goal (step gate)
        self._last_publish_t = -math.inf
        self._last_idle_status_t = -math.inf
        self._last_status: tuple[float, tuple] = (-math.inf, ())  # (ROS time, key) of the last running status
        self.last_record: CampaignRecord | None = None
        self.last_result = ""
        #: step results published on identification/calibration: name -> (name, message, [(key, value)])
        self.calibration_results: dict[str, tuple] = {}

    # ------------------------------------------------------------------ inputs
    def add_samples(self, samples: list) -> None:
        """Sensor samples ``[(device, sample)]``: the devices count as seen; kept for the next tick while a goal
        runs."""
        for dev, _s in samples:
            self.seen.add(dev)
        if self.run is not None:
            self.samples.extend(samples)

    def on_pwm(self, widths_us: Sequence[float], armed: bool) -> None:
        """A ``thrusters/pulse_width`` report: the wire widths (us; kept when all finite and one per thruster) and
        the armed flag."""
        w = np.asarray(widths_us, dtype=float)
        if w.size == self.n_thrusters and np.all(np.isfinite(w)):
            self.written = w
        self.armed = bool(armed)
        self.pwm_count += 1

    def on_disarm_cause(self, line: str) -> None:
        """The ``disarm_cause`` of a ``supervisor/status`` ('' when it has none): ``<process>: <cause>; next:
        <step>``."""
        self.disarm_cause = str(line)

    def _new_cause(self, run: GoalRun) -> bool:
        """Whether the supervisor names a stop of the thrust newer than the campaign's start."""
        return bool(self.disarm_cause) and self.disarm_cause != run.cause_at_start

    def _disarm_message(self, run: GoalRun) -> str:
        """The result of a goal aborted as :data:`DISARMED`: with the supervisor's cause and next step."""
        return (f"{DISARMED} by {self.disarm_cause}" if self._new_cause(run) else
                f"{DISARMED} (the supervisor named no cause); next: hindrax health, then hindrax arm")

    def forget_inputs(self) -> None:
        """The node opens its sensor inputs for a goal: the sensors seen and widths written before count no more
        (the goal waits for fresh samples); the armed flag stays (the ESC's latched state keeps it current)."""
        self.seen.clear()
        self.written = None

    # ------------------------------------------------------------------ goals
    @property
    def busy(self) -> bool:
        """True while a goal runs (a new one is refused)."""
        return self.run is not None

    def accept(self, handle: Any, goal: Any, t: float) -> str:
        """Set up an accepted goal (fields of hindrax_msgs/RunIdentification.Goal) at ROS time ``t`` (s); the ticks
        run it. Returns the log line."""
        dofs = [] if goal.calibration_only else (list(goal.dofs) or list(DOFS))
        calibrate = list(goal.calibrate)
        w_ballast, f_line = calibration_forces(self.config) if calibrate else (0.0, 0.0)
        incl = inclining_load(self.config) if "inclining" in calibrate else (0.0, 0.0)
        executive = self._executive(self.config, dofs, int(goal.levels_per_dof) or None, tick_s=self.tick_s,
                                    fractions=list(goal.level_fractions) or None,
                                    dvl_lock_timeout_s=self.dvl_lock_timeout_s, calibrate=calibrate,
                                    ballast_weight_in_water_n=w_ballast, line_pull_n=f_line,
                                    inclining_load_n_m=incl, confirm=list(self.pending_undo))
        self.samples = []
        self.run = GoalRun(handle, executive, t, np.full(self.n_thrusters, self.neutral_us),
                           pwm_count_at_accept=self.pwm_count)
        return (f"run_identification: {', '.join(dofs) or 'no ladders'}"
                + (f"; calibration {', '.join(calibrate)}" if calibrate else ""))

    def finish(self, run: GoalRun) -> tuple[bool, str]:
        """(success, result message) of an ended goal; kept as :attr:`last_record` / :attr:`last_result`."""
        self.last_record = run.record
        ok = run.record is not None and not run.record.aborted and not run.error
        message = run.error or ("" if run.record is None else run.cause or run.record.abort_reason) \
            or "campaign complete"
        if self.pending_undo:
            message += "; " + undo_line(self.pending_undo)
        if run.record is not None and run.record.calibration:  # the thrust scales measured, for the operator
            message += "; thrust scale " + ", ".join(f"{k} {v['value']:.4f} +- {v['std']:.4f}"
                                                     for k, v in run.record.calibration.items())
        self.last_result = message
        return ok, message

    def operator_continue(self) -> tuple[bool, str]:
        """``identification/continue``: (success, message); resumes the calibration step that waits."""
        run = self.run
        ex = None if run is None else run.executive
        if ex is None or run.ended or run.stop_since_s is not None:
            return False, "no identification goal is running"
        if not ex.awaiting:
            return False, "nothing awaits the operator (no calibration step waits)"
        what = ex.awaiting
        return bool(ex.operator_continue()), f"continuing: {what}"

    def close(self) -> GoalRun | None:
        """The node shuts down: the running goal (to end with a zero wrench, "node shutting down"), or None."""
        run = self.run
        if run is None or run.ended:
            return None
        run.error = run.error or "node shutting down"
        if run.record is None and run.executive.started:
            run.record = run.executive.record()
        return run

    def end(self, run: GoalRun) -> Event:
        """Mark ``run`` ended (no goal runs any more) and return its ``end`` event."""
        run.ended = True
        if self.run is run:
            self.run = None
            self.last_tick_s = None
        return Event("end", (run,))

    # ------------------------------------------------------------------ control tick
    def starved(self, t: float, gap_s: float) -> list[Event]:
        """Call before :meth:`tick` at ROS time ``t`` (s) with ``gap_s``, the steady-clock time since the previous
        control tick of the goal (s): a warning for a starved tick, the goal's stop beyond
        :func:`~hindrax_common.node_support.liveness.starved_stop_s` (module docstring, "Starvation"). No goal moving
        the vehicle: nothing."""
        run = self.run
        said = starvation("identification", gap_s, self.tick_s)
        if run is None or run.ended or run.stop_since_s is not None or not run.executive.started or not said:
            return []
        limit_s = starved_stop_s(self.config.thrusters.wrench_timeout_s)
        if gap_s <= limit_s:
            return [Event("warn_throttled", (said,))]
        out: list[Event] = []
        self._stop(run, t, f"{said[:-1]}, beyond {limit_s:g} s: twice thrusters.wrench_timeout_s)", out)
        return out

    def tick(self, t: float, cancel: bool) -> list[Event]:
        """One control tick at ROS time ``t`` (s); ``cancel``: the goal's cancel was requested. Returns the events."""
        out: list[Event] = []
        run = self.run
        if run is None:
            if t - self._last_idle_status_t >= IDLE_STATUS_PERIOD_S - 0.5 * self.tick_s:
                self._last_idle_status_t = t
                out.append(Event("status", ("idle", None, "idle")))
            return out
        if run.ended:
            return out
        if run.stop_since_s is not None:
            self._hold_neutral(run, t, out)
            return out
        ex = run.executive
        if not ex.started:
            if not self.armed and not cancel:  # nothing commanded yet: the goal ends without a neutral hold
                waited_s, heard = t - run.accepted_s, self.pwm_count - run.pwm_count_at_accept
                if (waited_s > ARMED_GRACE_S and heard >= ARMED_REPORTS) or waited_s > self.sensor_timeout_s:
                    run.error = NOT_ARMED
                    out.append(Event("status", ("aborted", None, NOT_ARMED)))
                    out.append(self.end(run))
                else:
                    self._status_throttled(t, "positioning", None, "waiting for the ESC output to report armed", out)
                return out
            if cancel or t - run.accepted_s > self.sensor_timeout_s:
                self._stop(run, t, "cancelled" if cancel
                           else f"sensors not publishing: {sorted(NEEDED_SENSORS - self.seen)}", out)
                return out
            if not NEEDED_SENSORS <= self.seen:
                self._status_throttled(t, "positioning", None, "waiting for the sensors", out)
                return out
            self.samples = []
            run.cause_at_start = self.disarm_cause
            w = ex.start(t)
        else:
            samples, self.samples = self.samples, []
            previous = ex.t_s
            valid = ordered_samples(samples, previous, t + FUTURE_STAMP_TOLERANCE_S, previous - STALE_STAMP_TOLERANCE_S)
            if len(valid) < len(samples):
                self.samples_dropped += len(samples) - len(valid)
                out.append(Event("warn_throttled", (
                    f"{self.samples_dropped} sensor samples left out, stamped more than {FUTURE_STAMP_TOLERANCE_S} s "
                    f"after or {STALE_STAMP_TOLERANCE_S} s before this node's clock ({t:.3f} s): a publisher on "
                    "another clock?",)))
            armed = self.armed and not self._new_cause(run)  # a newer stop: disarmed
            w = ex.step(TickInput(t, max(0.0, t - previous), valid, armed, cancel))
            if self.written is not None:
                run.written_us = self.written
        self.last_tick_s = t
        self._calibration(run, out)
        if w is None:
            self._stop(run, t, "", out)
            return out
        ex.command(thrust_of_written_widths(self.config, ex.curve, run.written_us))
        if ex.new_command:  # a held command is not sent again (executive module docstring, "Command rate")
            out.append(Event("wrench", (np.asarray(w, dtype=float),)))
        self._progress(run, t, out)
        return out

    def _calibration(self, run: GoalRun, out: list[Event]) -> None:
        """The ``calibration`` event when the executive has a step result it had not at the last tick: all results
        since start, the new ones replacing older ones of the same name."""
        ex = run.executive
        n = len(ex.calibration) + len(ex.inclining) + len(ex.decays)
        if n == run.calibration_results:
            return
        run.calibration_results = n
        for item in calibration_topic.statuses(ex.calibration, ex.inclining, ex.decays):
            self.calibration_results[item[0]] = item
        out.append(Event("calibration", (list(self.calibration_results.values()),)))
        out.append(Event("log", ("info", "identification/calibration: " + "; ".join(
            m for _n, m, _kv in self.calibration_results.values()))))

    def _stop(self, run: GoalRun, t: float, error: str, out: list[Event]) -> None:
        """End of the goal: record, final status, zero wrench; the goal ends once the thrusters are neutral."""
        run.error = error
        run.stop_since_s = t
        run.pwm_count_at_stop = self.pwm_count
        self.pending_undo = list(run.executive.undo)
        reason = error
        if run.executive.started:
            run.record = run.executive.record()
            st = run.executive.status()
            out.append(Event("status", ("aborted" if (error or st.phase == "aborted") else "done", st,
                                        error or st.message)))
            reason = error or (run.record.abort_reason if run.record.aborted else "")
        else:
            out.append(Event("status", ("aborted", None, error)))
        if reason and reason not in NOT_SUPERVISOR_ABORTS:
            out.append(Event("log", ("error", f"run_identification aborted: {reason}; tripping the safety supervisor")))
            out.append(Event("abort", (reason,)))
        out.append(Event("wrench", (np.zeros(6),)))
        self._hold_neutral(run, t, out)

    def _hold_neutral(self, run: GoalRun, t: float, out: list[Event]) -> None:
        """Zero wrench at every tick until the ESC reported, after the stop, neutral widths (or disarmed), or
        ``stop_timeout_s``; then the goal ends."""
        self.last_tick_s = t
        neutral = False
        if self.pwm_count > run.pwm_count_at_stop:
            if not self.armed:
                neutral = True
            elif self.written is not None:
                f = thrust_of_written_widths(self.config, run.executive.curve, self.written)
                neutral = bool(np.all(np.abs(f) < 1e-9))
        timed_out = t - run.stop_since_s >= self.stop_timeout_s - 1e-9
        disarmed = run.record is not None and run.record.abort_reason == DISARMED and not run.error
        if neutral and disarmed and not timed_out and not self._new_cause(run):
            neutral = False  # the supervisor has not named the cause yet: wait for it (module docstring)
        if neutral or timed_out:
            if not neutral and not disarmed:
                out.append(Event("log", ("warn", f"run_identification: thrusters not reported neutral within "
                                                 f"{self.stop_timeout_s:g} s of the stop")))
            if disarmed:
                run.cause = self._disarm_message(run)
                undo = f"; {undo_line(self.pending_undo)}" if self.pending_undo else ""
                out.append(Event("status", ("aborted", run.executive.status(), run.cause + undo)))
            out.append(self.end(run))
            return
        if t > run.stop_since_s:
            out.append(Event("wrench", (np.zeros(6),)))

    def clock_may_advance(self, t_s: float) -> bool:
        """Step gate for a simulator in the same process: False while a goal's control ticks run (manoeuvre and the
        neutral hold at its end) and the tick due at simulated time ``t_s`` (s) has not run yet."""
        if self.run is None or self.last_tick_s is None:
            return True
        return t_s + 1e-6 < self.last_tick_s + self.tick_s

    def _progress(self, run: GoalRun, t: float, out: list[Event]) -> None:
        ex = run.executive
        st = ex.status()
        prompt = f"[{ex.awaiting}] {ex.prompt}" if ex.awaiting else ""  # feedback and status
        self._status_throttled(t, st.phase, st, prompt or st.message, out)
        key = (st.dof, st.level_index, math.copysign(1.0, st.level_command) if st.level_command else 0.0, prompt,
               st.message)
        if key != run.last_feedback or t - run.last_feedback_s >= 1.0:
            if prompt and prompt != run.last_feedback[-1]:
                out.append(Event("log", ("info", f"operator: {prompt}")))
            run.last_feedback, run.last_feedback_s = key, t
            out.append(Event("feedback", (st, prompt)))
        if t - self._last_publish_t >= self.publish_period_s - 1e-9:
            self._last_publish_t = t
            out.append(Event("estimates", (ex,)))

    def _status_throttled(self, t: float, phase: str, st: ExecutiveStatus | None, message: str,
                          out: list[Event]) -> None:
        """The running status at ROS time ``t`` (s): at once when phase, DOF, level or message changed, else at
        most every :data:`STATUS_PERIOD_S` (the status is a step signal: a bag's zero-order hold of it,
        :mod:`hindrax_fit.bag_input.from_bag`, sees every change at its time)."""
        key = (phase, message) if st is None else (phase, message, st.dof, st.level_index, st.level_command)
        last_t, last_key = self._last_status
        if key == last_key and t - last_t < STATUS_PERIOD_S - 1e-9:
            return
        self._last_status = (t, key)
        out.append(Event("status", (phase, st, message)))
