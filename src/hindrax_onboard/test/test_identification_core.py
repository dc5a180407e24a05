"""The identification node's goal and tick logic without ROS (identification/online/core.py): one row per rule of
the module docstring, on a stand-in executive whose start, steps, status and record each test sets."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from hindrax_bringup.allocation.core import AllocationCore
from hindrax_common.config import default_config_path, load_config
from hindrax_onboard.identification.online.core import (ARMED_GRACE_S, ARMED_REPORTS, DISARMED, NEEDED_SENSORS,
                                                      NOT_ARMED, STARVED_WARN_TICKS, STATUS_PERIOD_S,
                                                      IdentificationCore, goal_problem)
from hindrax_onboard.identification.online.executive import ExecutiveStatus

CFG = load_config(default_config_path())
CURVE = AllocationCore(CFG).allocator.curves[0]
N = len(CFG.thrusters.thrusters)
NEUTRAL = float(CFG.thrusters.pulse_width_neutral_us)
TICK = 0.02


class StandInExecutive:
    """What the core uses of :class:`~hindrax_onboard.identification.online.executive.Executive`: ``wrenches`` are
    returned by start/step in turn (None = the campaign is over), ``phase`` and ``message`` make the status."""

    def __init__(self, cfg, dofs, levels, **kwargs):
        self.dofs, self.levels, self.kwargs = dofs, levels, kwargs
        self.started, self.t_s, self.curve = False, 0.0, CURVE
        self.wrenches = [np.array([5.0, 0, 0, 0, 0, 0])] * 1000
        self.phase, self.message, self.dof, self.level_index = "running", "surge level 1/3", "surge", 0
        self.awaiting, self.prompt, self.continued = "", "", 0
        self.calibration, self.inclining, self.decays, self.online = {}, {}, {}, {}
        self.aborted, self.abort_reason, self.inputs, self.commands = False, "", [], []
        self.new_command = True                                  # Executive: this tick's wrench is a new command
        self.undo = []                                           # Executive: loads asked for and not removed

    def start(self, t):
        self.started, self.t_s = True, t
        return self.wrenches.pop(0)

    def step(self, tick):
        self.inputs.append(tick)
        self.t_s = tick.t_s
        return self.wrenches.pop(0)

    def command(self, thrust_n):
        self.commands.append(np.asarray(thrust_n))

    def status(self):
        return ExecutiveStatus(self.phase, self.dof, self.level_index, 3, 5.0 if self.phase == "running" else 0.0,
                               0.25, self.message)

    def record(self):
        return SimpleNamespace(aborted=self.aborted, abort_reason=self.abort_reason, calibration=self.calibration)

    def operator_continue(self):
        self.continued += 1
        self.awaiting = ""
        return True


def goal(**kw):
    base = dict(dofs=["surge"], calibrate=[], calibration_only=False, level_fractions=[], levels_per_dof=0)
    return SimpleNamespace(**{**base, **kw})


def core(**kw) -> IdentificationCore:
    args = dict(tick_s=TICK, publish_period_s=1.0, dvl_lock_timeout_s=3.0, sensor_timeout_s=30.0,
                stop_timeout_s=2.0, executive=StandInExecutive)
    return IdentificationCore(CFG, **{**args, **kw})


def kinds(events):
    return [e.kind for e in events]


def statuses(events):
    return [(e.data[0], e.data[2]) for e in events if e.kind == "status"]


def ready(c: IdentificationCore, armed: bool = True):
    """Armed ESC at neutral and every needed sensor seen."""
    c.on_pwm([NEUTRAL] * N, armed)
    c.add_samples([(d, SimpleNamespace(stamp_s=0.0)) for d in NEEDED_SENSORS])


@pytest.mark.parametrize("fields, problem", [
    (dict(dofs=["surge", "heave"]), ""),
    (dict(dofs=[]), ""),                                            # empty = all six
    (dict(dofs=["swirl"]), "unknown DOF(s) ['swirl']"),
    (dict(calibrate=["ballast", "float"]), ""),
    (dict(calibrate=["weigh"]), "unknown calibration step(s) ['weigh']"),
    (dict(calibration_only=True), "calibration_only without a calibration step"),
    (dict(calibration_only=True, calibrate=["line_pull"]), ""),
    (dict(level_fractions=[0.2, 1.0]), ""),
    (dict(level_fractions=[1.5]), "level_fractions must be in (0, 1], got [1.5]"),
    (dict(level_fractions=[0.0]), "level_fractions must be in (0, 1], got [0.0]"),
    (dict(level_fractions=[float("nan")]), "level_fractions must be in (0, 1]"),
])
def test_goal_problems(fields, problem):
    g = goal(**fields)
    found = goal_problem(g.dofs, g.calibrate, g.calibration_only, g.level_fractions)
    assert found.startswith(problem) and bool(found) == bool(problem)


def test_a_goal_is_set_up_from_its_fields_and_refused_while_one_runs():
    c = core()
    assert not c.busy
    line = c.accept("h", goal(dofs=[], calibrate=["ballast"], levels_per_dof=4, level_fractions=[0.5]), 1.0)
    ex = c.run.executive
    assert c.busy and ex.dofs == ["surge", "sway", "heave", "roll", "pitch", "yaw"] and ex.levels == 4
    assert ex.kwargs["fractions"] == [0.5] and ex.kwargs["calibrate"] == ["ballast"] and ex.kwargs["tick_s"] == TICK
    assert ex.kwargs["ballast_weight_in_water_n"] > 0 and line.endswith("; calibration ballast")
    assert c.run.written_us.tolist() == [NEUTRAL] * N
    c2 = core()
    c2.accept("h", goal(calibration_only=True, calibrate=["line_pull"]), 0.0)
    assert c2.run.executive.dofs == [] and c2.run.executive.kwargs["line_pull_n"] > 0
    assert c2.run.executive.kwargs["inclining_load_n_m"] == (0.0, 0.0)  # only with an inclining step


@pytest.mark.parametrize("armed_at, reports, ends, message", [
    (None, ARMED_REPORTS, True, NOT_ARMED),        # reported disarmed: ends after the grace, nothing commanded
    (None, ARMED_REPORTS - 1, False, "waiting for the ESC output to report armed"),  # too few reports read yet
    (None, 0, False, "waiting for the ESC output to report armed"),  # a starved tick before the reports it waits on
    (0.5 * ARMED_GRACE_S, 1, False, "waiting for the sensors"),  # armed within the grace: goes on
])
def test_the_goal_waits_for_the_armed_flag_within_its_grace(armed_at, reports, ends, message):
    c = core()
    c.accept("h", goal(), 10.0)
    out = c.tick(10.0, False)
    assert statuses(out) == [("positioning", "waiting for the ESC output to report armed")]
    for _ in range(reports):
        c.on_pwm([NEUTRAL] * N, armed_at is not None)
    out = c.tick(10.0 + ARMED_GRACE_S + TICK, False)
    assert ("wrench" not in kinds(out)) and (kinds(out)[-1:] == ["end"]) == ends
    assert statuses(out)[-1] == ("aborted" if ends else "positioning", message)
    if ends:
        assert c.run is None and c.finish(out[-1].data[0]) == (False, NOT_ARMED)


def test_a_silent_esc_output_ends_the_goal_as_not_armed_after_the_sensor_timeout():
    c = core()
    c.accept("h", goal(), 10.0)
    assert kinds(c.tick(10.0 + c.sensor_timeout_s - TICK, False))[-1:] != ["end"]  # no report yet: still waiting
    out = c.tick(10.0 + c.sensor_timeout_s + TICK, False)
    assert kinds(out)[-1:] == ["end"] and "wrench" not in kinds(out)
    assert c.finish(out[-1].data[0]) == (False, NOT_ARMED)


@pytest.mark.parametrize("cancel, t, reason, to_supervisor", [
    (True, 1.0, "cancelled", False),
    (False, 30.5, "sensors not publishing: ['dvl75', 'dvl75_attitude', 'icm20948_gyro', 'ms5837', 'ping1d']", True),
])
def test_before_the_start_a_cancel_or_silent_sensors_stop_the_goal(cancel, t, reason, to_supervisor):
    c = core()
    c.on_pwm([NEUTRAL] * N, True)
    c.accept("h", goal(), 0.0)
    out = c.tick(t, cancel)
    assert statuses(out) == [("aborted", reason)]
    assert ("abort", (reason,)) in [(e.kind, e.data) for e in out] if to_supervisor else "abort" not in kinds(out)
    assert np.all(out[kinds(out).index("wrench")].data[0] == 0.0)
    # no new ESC report since the stop: the zero wrench is held until stop_timeout_s, then the goal ends
    assert kinds(c.tick(t + TICK, False)) == ["wrench"]
    out = c.tick(t + 2.0, False)
    assert kinds(out) == ["log", "end"] and out[0].data[0] == "warn" and c.run is None


def test_the_goal_starts_once_every_sensor_has_published_and_commands_the_written_thrust():
    c = core()
    c.on_pwm([NEUTRAL] * N, True)
    c.accept("h", goal(), 0.0)
    assert statuses(c.tick(0.02, False)) == [("positioning", "waiting for the sensors")]
    assert c.tick(0.04, False) == []                             # same status within STATUS_PERIOD_S
    assert statuses(c.tick(0.04 + STATUS_PERIOD_S, False)) == [("positioning", "waiting for the sensors")]
    ready(c)
    out = c.tick(1.0, False)
    ex = c.run.executive
    assert ex.started and kinds(out) == ["wrench", "status", "feedback", "estimates"]
    assert out[0].data[0].tolist() == [5.0, 0, 0, 0, 0, 0] and statuses(out) == [("running", "surge level 1/3")]
    assert out[2].data[0].dof == "surge" and out[2].data[0].level_count == 3
    assert np.allclose(ex.commands[-1], 0.0)                    # neutral widths: no thrust
    c.on_pwm([NEUTRAL + 100.0] * N, True)                       # the ESC wrote thrust: the next tick's force
    c.tick(1.02, False)
    assert ex.commands[-1].shape == (N,) and np.any(np.abs(ex.commands[-1]) > 1.0)
    assert ex.inputs[-1].armed and ex.inputs[-1].elapsed_s == pytest.approx(0.02)


def test_a_held_command_is_not_sent_again_but_the_tick_still_records_the_written_thrust():
    """Executive.new_command false (a tick between two commands, executive module docstring "Command rate"): no
    wrench event, the written thrust is still recorded and the tick still goes to the executive."""
    c = core()
    ready(c)
    c.accept("h", goal(), 0.0)
    assert "wrench" in kinds(c.tick(1.0, False))
    ex = c.run.executive
    ex.new_command = False
    assert "wrench" not in kinds(c.tick(1.02, False))
    assert len(ex.commands) == 2 and len(ex.inputs) == 1
    ex.new_command = True
    out = c.tick(1.04, False)
    assert kinds(out)[0] == "wrench" and len(ex.commands) == 3


def test_samples_stamped_in_the_future_or_long_before_are_left_out_and_counted():
    c = core()
    ready(c)
    c.accept("h", goal(), 0.0)
    c.tick(5.0, False)
    c.add_samples([("ms5837", SimpleNamespace(stamp_s=t)) for t in (5.01, 6.5, 2.5, 4.99)])
    out = c.tick(5.02, False)
    assert c.samples_dropped == 2 and kinds(out)[0] == "warn_throttled"
    # in stamp order; the late one (4.99, before the previous tick at 5.0) is dated at that tick (ordered_samples)
    assert [s.stamp_s for _d, s in c.run.executive.inputs[-1].samples] == [5.0, 5.01]


@pytest.mark.parametrize("phase, abort_reason, status, to_supervisor", [
    ("done", "", ("done", "surge done"), False),
    ("aborted", "depth 1.9 m beyond the limit", ("aborted", "surge done"), True),
    ("aborted", "cancelled", ("aborted", "surge done"), False),
])
def test_the_end_of_a_campaign_reports_and_trips_the_supervisor_only_for_limits(phase, abort_reason, status,
                                                                               to_supervisor):
    c = core()
    ready(c)
    c.accept("h", goal(), 0.0)
    ex = c.run.executive
    ex.wrenches = [np.ones(6), None]
    c.tick(1.0, False)
    ex.phase, ex.message, ex.aborted, ex.abort_reason = phase, "surge done", phase == "aborted", abort_reason
    out = c.tick(1.02, False)
    assert statuses(out) == [status] and np.all(out[kinds(out).index("wrench")].data[0] == 0.0)
    assert (("abort", (abort_reason,)) in [(e.kind, e.data) for e in out]) == to_supervisor
    c.on_pwm([NEUTRAL] * N, True)                                # the ESC reports neutral widths: the goal ends
    out = c.tick(1.04, False)
    assert kinds(out) == ["end"] and c.run is None
    ok, message = c.finish(out[0].data[0])
    assert ok == (phase == "done") and message == (abort_reason or "campaign complete")
    assert c.last_result == message


GUARD_CAUSE = ("output guard: ESC output state silent for 0.21 s (esc/heartbeat): ESC process dead or hung; next: "
               "check the ESC process (hindrax health; the launch respawns it), then hindrax arm")


@pytest.mark.parametrize("cause_after_ticks", [0, 3, None])
def test_a_disarmed_end_waits_for_the_supervisors_cause_and_names_it(cause_after_ticks):
    """The ESC output disarmed under the campaign: the goal ends once the supervisor named the cause (or after
    stop_timeout_s without one), and the result and the last status carry it in one line with the next step."""
    c = core()
    c.on_disarm_cause("supervisor: an older stop; next: hindrax arm")  # before this arming: not this goal's
    ready(c)
    c.accept("h", goal(), 0.0)
    ex = c.run.executive
    c.tick(1.0, False)
    assert ex.inputs == [] and c.run.cause_at_start.startswith("supervisor: an older")
    c.on_disarm_cause("")                                        # the supervisor cleared it at the arming
    ex.wrenches = [None]
    ex.phase, ex.aborted, ex.abort_reason = "aborted", True, DISARMED
    c.on_pwm([NEUTRAL] * N, False)
    out = c.tick(1.02, False)                                    # the executive stopped on the disarm
    assert "abort" not in kinds(out)
    t, ticks = 1.02, 0
    while c.run is not None and t < 1.02 + 2.0:
        if ticks == cause_after_ticks:
            c.on_disarm_cause(GUARD_CAUSE)
        c.on_pwm([NEUTRAL] * N, False)
        t, ticks = t + TICK, ticks + 1
        out = c.tick(t, False)
    assert kinds(out)[-2:] == ["status", "end"]
    ok, message = c.finish(out[-1].data[0])
    expected = f"{DISARMED} by {GUARD_CAUSE}" if cause_after_ticks is not None else \
        f"{DISARMED} (the supervisor named no cause); next: hindrax health, then hindrax arm"
    assert not ok and message == expected and statuses(out)[-1] == ("aborted", expected)
    assert ticks == (cause_after_ticks + 1 if cause_after_ticks is not None else round(2.0 / TICK))


def test_a_new_disarm_cause_while_armed_stops_the_campaign():
    """A killed ESC reports nothing: its last pulse_width said armed; the supervisor's new cause (the output
    guard's) is the executive's disarm."""
    c = core()
    ready(c)
    c.accept("h", goal(), 0.0)
    c.tick(1.0, False)
    c.tick(1.02, False)
    ex = c.run.executive
    assert ex.inputs[-1].armed
    c.on_disarm_cause(GUARD_CAUSE)
    c.tick(1.04, False)
    assert not ex.inputs[-1].armed and c.armed


@pytest.mark.parametrize("report, ends", [
    (([NEUTRAL] * N, True), True),                  # neutral widths
    (([NEUTRAL + 200.0] * N, False), True),         # disarmed
    (([NEUTRAL + 200.0] * N, True), False),         # still thrusting: hold the zero wrench
])
def test_the_neutral_hold_ends_on_a_report_after_the_stop(report, ends):
    c = core()
    ready(c)
    c.accept("h", goal(), 0.0)
    c.run.executive.wrenches = [np.ones(6), None]
    c.tick(1.0, False)
    c.tick(1.02, False)                                          # stop
    c.on_pwm(*report)
    out = c.tick(1.04, False)
    assert kinds(out) == (["end"] if ends else ["wrench"])


def test_status_changes_go_out_at_once_and_repeats_at_most_every_period():
    c = core()
    ready(c)
    c.accept("h", goal(), 0.0)
    c.tick(1.0, False)
    assert statuses(c.tick(1.02, False)) == []                   # unchanged
    c.run.executive.message = "surge level 2/3"
    assert statuses(c.tick(1.04, False)) == [("running", "surge level 2/3")]
    assert statuses(c.tick(1.04 + STATUS_PERIOD_S, False)) == [("running", "surge level 2/3")]
    idle = core()
    assert statuses(idle.tick(0.0, False)) == [("idle", "idle")]
    assert idle.tick(0.5, False) == [] and statuses(idle.tick(1.0, False)) == [("idle", "idle")]


def test_feedback_on_every_change_and_at_least_every_second_with_the_prompt():
    c = core()
    ready(c)
    c.accept("h", goal(calibrate=["ballast"]), 0.0)
    c.tick(1.0, False)
    assert "feedback" not in kinds(c.tick(1.5, False))
    assert "feedback" in kinds(c.tick(2.0, False))               # one second after the last
    ex = c.run.executive
    ex.awaiting, ex.prompt = "attach_ballast", "calibration: attach the ballast, then call continue"
    out = c.tick(2.02, False)
    prompt = next(e.data[1] for e in out if e.kind == "feedback")
    assert prompt == "[attach_ballast] calibration: attach the ballast, then call continue"
    assert ("log", ("info", f"operator: {prompt}")) in [(e.kind, e.data) for e in out]
    assert statuses(out) == [("running", prompt)]             # the prompt replaces the step's message


@pytest.mark.parametrize("state, answer", [
    ("no goal", (False, "no identification goal is running")),
    ("nothing awaited", (False, "nothing awaits the operator (no calibration step waits)")),
    ("awaiting", (True, "continuing: attach_ballast")),
    ("stopping", (False, "no identification goal is running")),
])
def test_operator_continue(state, answer):
    c = core()
    ready(c)
    if state != "no goal":
        c.accept("h", goal(calibrate=["ballast"]), 0.0)
        c.tick(1.0, False)
        c.run.executive.awaiting = "attach_ballast" if state in ("awaiting", "stopping") else ""
        if state == "stopping":
            c.run.stop_since_s = 1.0
    assert c.operator_continue() == answer
    if state == "awaiting":
        assert c.run.executive.continued == 1


def test_calibration_results_are_published_when_a_step_ends_all_since_start():
    c = core()
    ready(c)
    c.accept("h", goal(calibrate=["ballast"]), 0.0)
    c.tick(1.0, False)
    ex = c.run.executive
    ex.calibration = {"vertical": {"value": 1.02, "std": 0.01, "known_force_n": 8.56, "holding_force_n": (0.0, 8.7),
                                   "holding_force_std_n": (0.1, 0.1), "method": "ballast"}}
    out = c.tick(1.02, False)
    sent = next(e.data[0] for e in out if e.kind == "calibration")
    assert [item[0] for item in sent] == ["thrust_scale/vertical"] and c.calibration_results
    assert "calibration" not in kinds(c.tick(1.04, False))        # nothing new


def test_the_step_gate_holds_the_simulator_at_the_next_tick_while_a_goal_runs():
    c = core()
    assert c.clock_may_advance(5.0)
    ready(c)
    c.accept("h", goal(), 0.0)
    assert c.clock_may_advance(5.0)                               # no tick of the goal yet
    c.tick(1.0, False)
    assert c.clock_may_advance(1.0 + TICK / 2) and not c.clock_may_advance(1.0 + TICK)


def test_close_ends_a_running_goal_with_its_record():
    c = core()
    assert c.close() is None
    ready(c)
    c.accept("h", goal(), 0.0)
    c.tick(1.0, False)
    run = c.close()
    assert run is c.run and run.error == "node shutting down" and run.record is not None
    assert c.end(run).kind == "end" and c.run is None and c.finish(run) == (False, "node shutting down")


def test_a_starved_tick_is_named_and_beyond_the_wrench_timeout_stops_the_goal_with_that_reason():
    """The node's steady-clock gap between two control ticks: within STARVED_WARN_TICKS periods nothing; beyond, a
    warning naming it, also just past thrusters.wrench_timeout_s (one stale wrench is survived); beyond twice it the
    goal stops with the starvation as its reason: aborted status, supervisor/abort, zero wrench; no goal or before
    the start: nothing."""
    c = core()
    assert c.starved(0.5, 5.0) == []                             # no goal
    ready(c)
    c.accept("h", goal(), 0.0)
    assert c.starved(0.9, 5.0) == []                             # accepted, not started: nothing commanded yet
    c.tick(1.0, False)
    assert c.starved(1.02, STARVED_WARN_TICKS * TICK) == []
    timeout = CFG.thrusters.wrench_timeout_s
    for gap in (0.3, 2 * timeout):
        warned = c.starved(1.04, gap)
        assert kinds(warned) == ["warn_throttled"] and \
            warned[0].data[0].startswith(f"identification starved for {gap:.2f} s")
    out = c.starved(3.0, 2 * timeout + 0.3)
    reason = out[[e.kind for e in out].index("abort")].data[0]
    assert reason.startswith(f"identification starved for {2 * timeout + 0.3:.2f} s") and \
        f"beyond {2 * timeout:g} s: twice thrusters.wrench_timeout_s" in reason
    assert statuses(out)[0] == ("aborted", reason) and kinds(out)[-1] == "wrench" and \
        not np.any(out[-1].data[0])
    assert c.starved(3.1, 9.0) == []                             # stopping already: once
    assert c.finish(c.run)[1] == reason
