"""The ESC's decisions without ROS or a bus (pca9685/core.py): one row per rule of the core's docstring.

Expected values are written from the rules and the hardware facts (Basic ESC 1100-1900 us, neutral 1500 us,
deadband +-25 us; PCA9685 at prescale 30 and 25 MHz: one count = 31 / 25 MHz = 1.24 us), not computed by the core.
"""
from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from hindrax_drivers.pca9685.core import (COMMAND_NODE, CONFIGURE, GUARD_CONFIRM_S, NEUTRAL, OUTPUT_COMMANDING,
                                          OUTPUT_NEUTRAL, OUTPUT_UNKNOWN, READBACK, RETRY_MAX_S, RETRY_MIN_S, WRITE,
                                          EscCore, EscOutput, SteadyWatchdog, command_fault, command_source_fault,
                                          heartbeat_verdict)

COUNT_US = 1.24


class Clock:
    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t


def make(arming_time_s=1.0, calibrated=True, n=2):
    clock = Clock()
    out = EscOutput(range(n), [False] * n, [0.0] * n, 1100, 1500, 1900)
    core = EscCore(out, arming_time_s=arming_time_s, watchdog_timeout_s=0.2, oscillator_calibrated=calibrated,
                   clock=clock, period_s=0.02)
    return core, clock


def ready(core, clock, wait_s=1.0):
    """Chip confirmed, both peers trusted, the arming time passed."""
    core.chip_confirmed()
    core.set_peers("", "")
    clock.t += wait_s


def test_output_states_are_the_message_constants():
    """The constants as hindrax_msgs/msg/ThrusterPwm.msg defines them (read from the definition, so this core's
    tests need no ROS: they also run under other Pythons, test/test_pure_cores_other_pythons.py)."""
    definition = (Path(__file__).resolve().parents[2] / "hindrax_msgs" / "msg" / "ThrusterPwm.msg").read_text()
    constants = dict(re.findall(r"^uint8 (OUTPUT_\w+)=(\d+)$", definition, re.MULTILINE))
    assert constants == {"OUTPUT_UNKNOWN": str(OUTPUT_UNKNOWN), "OUTPUT_NEUTRAL": str(OUTPUT_NEUTRAL),
                         "OUTPUT_COMMANDING": str(OUTPUT_COMMANDING)}


# rule -> (command widths, its armed flag, expected fault substring or "" for accepted)
COMMAND_ROWS = [
    ("in range", [1700.0, 1300.0], True, ""),
    ("range ends are the ESC's full reverse / forward", [1100.0, 1900.0], True, ""),
    ("default-constructed message: 0.0 us", [0.0, 0.0], True, "outside the ESC's range 1100-1900"),
    ("3000 us", [3000.0, 1500.0], True, "3000 us (thruster 0) outside"),
    ("just below full reverse", [1500.0, 1099.9], True, "(thruster 1) outside"),
    ("NaN", [math.nan, 1500.0], True, "non-finite"),
    ("infinity", [1500.0, math.inf], True, "non-finite"),
    ("wrong count", [1500.0], True, "1 pulse widths, expected 2"),
    ("armed=false", [1700.0, 1700.0], False, "armed=false"),
]


@pytest.mark.parametrize("rule, widths, armed, fault", COMMAND_ROWS, ids=[r[0] for r in COMMAND_ROWS])
def test_command_fault(rule, widths, armed, fault):
    got = command_fault(widths, armed, 2, 1100.0, 1900.0)
    assert (fault in got and got) if fault else got == ""


def test_heartbeat_verdict_rows():
    assert heartbeat_verdict("supervisor", "supervisor/heartbeat", 0.1, 0.2, True, "ok") == ""
    assert heartbeat_verdict("supervisor", "s", 0.1, 0.2, False, "depth 3 m").endswith("not OK: depth 3 m")
    assert heartbeat_verdict("supervisor", "s", 0.3, 0.2, True, "ok").startswith("no supervisor heartbeat for 0.30")
    assert heartbeat_verdict("guard", "g", math.inf, 0.2, True, "ok").startswith("no guard heartbeat (g")


# arming: rule -> (setup, expected refusal substring, "" = accepted)
def _uncalibrated(core, clock):
    core.oscillator_calibrated = False
    ready(core, clock)


def _not_confirmed(core, clock):
    core.set_peers("", "")
    clock.t += 5.0


def _supervisor_untrusted(core, clock):
    ready(core, clock)
    core.set_peers("no supervisor heartbeat for 0.30 s", "")


def _guard_untrusted(core, clock):
    ready(core, clock)
    core.set_peers("", "output guard holds the outputs off: /OE high")


def _too_soon(core, clock):
    ready(core, clock, wait_s=0.4)  # arming time 1.0 s


def _guard_error_restarts_time(core, clock):
    ready(core, clock, wait_s=0.9)
    core.set_peers("", "output guard holds the outputs off")
    core.set_peers("", "")
    clock.t += 0.5  # 0.5 s since the guard's OK again, not 1.4 s


def _ready(core, clock):
    ready(core, clock)


def _foreign_commander(core, clock):
    ready(core, clock)
    core.set_command_source(command_source_fault(["thrust_allocation", "rogue_script"]))


def _chip_lost_after_ready(core, clock):
    ready(core, clock)
    core.chip_lost("PCA9685 read-back failed")


ARM_ROWS = [
    ("oscillator not calibrated", _uncalibrated, "oscillator_calibrated is false"),
    ("neutral not confirmed on the chip", _not_confirmed, "not confirmed at neutral"),
    ("supervisor not trusted", _supervisor_untrusted, "no supervisor heartbeat"),
    ("guard not trusted", _guard_untrusted, "output guard holds the outputs off"),
    ("arming time not over", _too_soon, "0.6 s more at neutral"),
    ("a guard ERROR restarts the arming time", _guard_error_restarts_time, "0.5 s more at neutral"),
    ("chip lost", _chip_lost_after_ready, "not confirmed at neutral"),
    ("a command publisher other than the allocation", _foreign_commander, "published by 'rogue_script'"),
    ("everything ready", _ready, ""),
]


@pytest.mark.parametrize("rule, setup, refusal", ARM_ROWS, ids=[r[0] for r in ARM_ROWS])
def test_arming(rule, setup, refusal):
    core, clock = make()
    setup(core, clock)
    got = core.request_arm()
    if refusal:
        assert refusal in got and not core.armed
    else:
        assert got == "" and core.armed and core.output_state == OUTPUT_NEUTRAL


def test_arm_waits_for_the_guard_confirmation_even_with_no_arming_time():
    core, clock = make(arming_time_s=0.0)
    ready(core, clock, wait_s=0.0)
    assert "the output guard's OK confirmed for 0.15 s" in core.request_arm()
    clock.t += GUARD_CONFIRM_S
    assert core.request_arm() == ""


def armed_commanding(n=2):
    core, clock = make(n=n)
    ready(core, clock)
    assert core.request_arm() == ""
    assert core.on_command(10.0, [1700.0] * n, True) == ""
    d = core.decide(10.0, 0.02)
    assert d.output_state == OUTPUT_COMMANDING and d.widths_us.tolist() == [1700.0] * n
    return core, clock


def test_commands_before_arming_give_neutral():
    core, clock = make()
    ready(core, clock)
    core.on_command(10.0, [1700.0, 1700.0], True)
    d = core.decide(10.0, 0.02)
    assert d.output_state == OUTPUT_NEUTRAL and d.widths_us.tolist() == [1500.0, 1500.0]


def test_arming_drops_a_command_from_before_it():
    core, clock = make()
    ready(core, clock)
    core.on_command(10.0, [1700.0, 1700.0], True)
    core.request_arm()
    assert core.decide(10.0, 0.02).widths_us.tolist() == [1500.0, 1500.0]


@pytest.mark.parametrize("rule, widths, armed", [(r[0], r[1], r[2]) for r in COMMAND_ROWS if r[3]],
                         ids=[r[0] for r in COMMAND_ROWS if r[3]])
def test_a_faulty_command_while_commanding_gives_neutral_and_the_reason(rule, widths, armed):
    core, _clock = armed_commanding()
    fault = core.on_command(10.01, widths, armed)
    d = core.decide(10.01, 0.02)
    assert fault and d.output_state == OUTPUT_NEUTRAL and d.widths_us.tolist() == [1500.0, 1500.0]
    assert d.reason == f"command rejected: {fault}" and core.armed and core.rejected_commands == 1
    core.on_command(10.02, [1600.0, 1600.0], True)  # the next valid command drives again
    assert core.decide(10.02, 0.02).widths_us.tolist() == [1600.0, 1600.0] and core.reason == ""


def test_peer_loss_while_armed_disarms_with_the_reason():
    core, _clock = armed_commanding()
    assert core.set_peers("supervisor tripped: depth", "") == "supervisor tripped: depth"
    d = core.decide(10.0, 0.02)
    assert not core.armed and d.widths_us.tolist() == [1500.0, 1500.0] and core.heartbeat_disarms == 1
    assert d.reason == "supervisor tripped: depth"


def test_watchdog_on_ros_time():
    core, _clock = armed_commanding()
    assert core.decide(10.2, 0.02).output_state == OUTPUT_COMMANDING  # 0.2 s: not older than the timeout
    d = core.decide(10.21, 0.02)
    assert d.output_state == OUTPUT_NEUTRAL and core.watchdog_trips == 1 and core.armed
    assert d.reason.startswith("watchdog")


def test_the_core_decides_the_steady_watchdog_trip():
    """ROS time stopped (``decide`` at the command's own ROS time never trips): the core's steady-clock check trips
    after 0.2 s (the timeout, default watchdog_timeout_s) of 20 ms ticks without a command, drops the command and
    says why; a command restarts it, and disarmed it never trips."""
    core, clock = armed_commanding()
    for _ in range(10):  # 0.2 s: not beyond the timeout
        clock.t += 0.02
        assert core.steady_check(clock.t) == "" and core.decide(10.0, 0.02).output_state == OUTPUT_COMMANDING
    clock.t += 0.02
    assert core.steady_check(clock.t) == "steady-clock watchdog: no command for 0.2 s"
    d = core.decide(10.0, 0.02)
    assert d.output_state == OUTPUT_NEUTRAL and d.reason == "steady-clock watchdog: no command for 0.2 s"
    assert core.watchdog_trips == core.steady_watchdog_trips == 1 and core.command is None and core.armed
    assert core.on_command(10.0, [1700.0, 1700.0], True) == "" and core.last_command_s == clock.t
    clock.t += 0.02
    assert core.steady_check(clock.t) == "" and core.decide(10.0, 0.02).output_state == OUTPUT_COMMANDING
    core.disarm("disarmed")
    clock.t += 5.0
    assert core.steady_check(clock.t) == "" and core.steady_watchdog_trips == 1


def test_the_core_hands_out_no_settable_state():
    """What the core decides (armed, output state, the held command, the watchdogs) changes only through its methods:
    no caller can arm it or give it a command by assignment."""
    core, _clock = make()
    for name, value in (("armed", True), ("output_state", OUTPUT_COMMANDING), ("command", np.full(2, 1700.0)),
                        ("watchdog_s", 1e9), ("steady_watchdog_s", 1e9), ("steady_watchdog_trips", 0)):
        with pytest.raises(AttributeError):
            setattr(core, name, value)
    assert not core.armed and core.output_state == OUTPUT_UNKNOWN and core.command is None


def test_chip_lost_is_unknown_and_disarmed():
    core, _clock = armed_commanding()
    assert core.chip_lost("write failed")
    assert core.output_state == OUTPUT_UNKNOWN and not core.armed and core.command is None
    assert not core.chip_lost("write failed")  # the same outage: not new


def test_chip_mismatch_disarms():
    core, _clock = armed_commanding()
    core.chip_mismatch("MODE1 0x11")
    assert not core.armed and core.decide(10.0, 0.02).widths_us.tolist() == [1500.0, 1500.0]


def test_retry_backs_off_when_nothing_but_neutral_was_written():
    core, clock = make()
    core.chip_attempt()
    core.chip_lost("no I2C bus")
    assert not core.stale_width_possible
    delays = []
    for _ in range(6):
        clock.t += 0.01
        assert not core.retry_due()
        clock.t += core.retry_s
        assert core.retry_due()
        delays.append(core.retry_s)
        core.chip_attempt()
        core.chip_lost("no I2C bus")
    assert delays == [2 * RETRY_MIN_S, 4 * RETRY_MIN_S, 8 * RETRY_MIN_S, RETRY_MAX_S, RETRY_MAX_S, RETRY_MAX_S]


def test_retry_at_every_tick_while_an_old_width_may_be_on_the_wire():
    """Issue 44 finding 8: with /OE not wired, a bus that fails after a 1700 us write leaves 1700 us running; the
    back-off (up to 4 s) kept it there 138-1288 ms after the bus returned. Retried at every tick instead."""
    core, clock = armed_commanding()
    core.wrote(np.array([1700.0, 1700.0]))
    core.chip_attempt()
    core.chip_lost("write failed")
    assert core.stale_width_possible and "1700, 1700 us" in core.reason and "may still be on the wire" in core.reason
    for _ in range(10):
        clock.t += 0.02  # one tick
        assert core.retry_due()
        core.chip_attempt()
        core.chip_lost("write failed")
    core.wrote(np.array([1500.0, 1500.0]))  # the returning bus took neutral
    core.chip_confirmed()
    assert not core.stale_width_possible and not core.retry_due() and core.output_state == OUTPUT_NEUTRAL


# deadband rounding (issue 44 item 9): one count = 1.24 us; deadband 1475-1525 us about each channel's neutral
GRID_ROWS = [
    ("forward edge 1525: 1229.8 counts, up to 1230", [1525.0], [False], [0.0], 1230 * COUNT_US),
    ("reversed 1525 -> 1475: 1189.5 counts, down to 1189 (half-up gave 1190 = 1475.6, inside)",
     [1525.0], [True], [0.0], 1189 * COUNT_US),
    ("reversed with +3 us trim: 1478 -> 1191.9 counts, down to 1191", [1525.0], [True], [3.0], 1191 * COUNT_US),
    ("inside the deadband: nearest count (1510 -> 1217.7 -> 1218)", [1510.0], [False], [0.0], 1218 * COUNT_US),
    ("full forward 1900: 1532.3 counts, not up to 1533 (1900.9 us, beyond the ESC's maximum)", [1900.0], [False],
     [0.0], 1532 * COUNT_US),
]


@pytest.mark.parametrize("rule, cmd, rev, trim, expected", GRID_ROWS, ids=[r[0] for r in GRID_ROWS])
def test_count_grid_rounds_away_from_neutral_outside_the_deadband(rule, cmd, rev, trim, expected):
    out = EscOutput(range(1), rev, trim, 1100, 1500, 1900, count_us=COUNT_US, deadband_us=25.0)
    assert out.on_grid(out.target(np.array(cmd), 0.02))[0] == pytest.approx(expected, abs=1e-9)


def test_no_thrust_command_lands_in_the_deadband_after_the_chips_rounding_exhaustive():
    """Issue 44 item 9: 320 of 3200 reversed-thruster cases landed 0.1-0.3 us inside the deadband after the PCA9685's
    12-bit rounding (thrust lost). Exhaustive over: the part's oscillator 23-27 MHz in 0.5 MHz steps (calibrated,
    datasheet range), at 200 Hz; every command width outside the deadband (1100-1475 us and 1525-1900 us) on the
    allocation's grid for that oscillator (one count) and on a 0.5 us grid (``hindrax thruster-test`` widths);
    a normal and a reversed thruster; trims -5, 0 and +5 us. Put on the wire as the chip does (counts = the written
    width / count duration rounded half-up, datasheet §7.3.5, as the register encoder), each stays at least 25 us
    from its channel's neutral (1500 us + trim) and inside 1100-1900 us. (Without the rounding away from neutral:
    388 of these 114240 cases land inside.)"""
    from hindrax_drivers.pca9685 import protocol as pca

    cases = inside = 0
    for osc_hz in np.arange(23.0e6, 27.0e6 + 1.0, 0.5e6):
        prescale = pca.esc_prescale(200.0, osc_hz)
        count_us = (prescale + 1) / osc_hz * 1e6  # datasheet §7.3.5
        on_grid = np.arange(math.ceil(1100 / count_us), math.floor(1900 / count_us) + 1) * count_us
        fine = np.arange(1100.0, 1900.0 + 1e-9, 0.5)
        w = np.concatenate([on_grid, fine])
        w = w[((w >= 1100) & (w <= 1475.0 + 1e-9)) | ((w >= 1525.0 - 1e-9) & (w <= 1900))]
        for rev in (False, True):
            for trim in (-5.0, 0.0, 5.0):
                n = w.size  # one channel per width: the whole sweep in one call
                out = EscOutput(range(n), [rev] * n, [trim] * n, 1100, 1500, 1900, count_us=count_us,
                                deadband_us=25.0)
                written = out.on_grid(out.target(w, 0.02))
                decoded = np.floor(written / count_us + 0.5) * count_us
                cases += n
                bad = (np.abs(decoded - (1500.0 + trim)) < 25.0 - 1e-9) | (decoded < 1100 - 1e-9) | \
                    (decoded > 1900 + 1e-9)
                inside += int(bad.sum())
    assert cases == 114240 and inside == 0


SOURCE_ROWS = [
    ("the allocation alone", ["thrust_allocation"], ""),
    ("nobody (no command comes)", [], ""),
    ("another node beside it", ["thrust_allocation", "thruster_test"], "published by 'thruster_test'"),
    ("another node alone", ["probe"], "published by 'probe'"),
    ("two allocations", ["thrust_allocation", "thrust_allocation"], "2 live publishers named 'thrust_allocation'"),
]


@pytest.mark.parametrize("rule, names, fault", SOURCE_ROWS, ids=[r[0] for r in SOURCE_ROWS])
def test_command_source_fault(rule, names, fault):
    assert COMMAND_NODE == "thrust_allocation"
    got = command_source_fault(names)
    assert (fault in got and got) if fault else got == ""


def test_a_dead_allocation_still_in_the_graph_is_not_a_second_one():
    """A respawned allocation beside its killed predecessor's graph entry (about 20 s): one live publisher."""
    assert command_source_fault(["thrust_allocation", "thrust_allocation"], alive=1) == ""
    assert "2 live publishers" in command_source_fault(["thrust_allocation", "thrust_allocation"], alive=2)
    assert "'rogue'" in command_source_fault(["thrust_allocation", "rogue"], alive=1)  # a stranger by its name


def test_a_foreign_commander_while_armed_disarms_and_its_commands_are_refused():
    """Issue 43 finding 3: a plain rclpy script publishing thrusters/command_pulse_width put 1900 us on the wire."""
    core, _clock = armed_commanding()
    fault = command_source_fault(["thrust_allocation", "rogue"])
    assert core.set_command_source(fault) == fault
    assert not core.armed and core.decide(10.0, 0.02).widths_us.tolist() == [1500.0, 1500.0]
    assert core.on_command(10.01, [1900.0, 1900.0], True) == fault
    assert fault in core.request_arm()
    core.set_command_source("")  # gone
    assert core.request_arm() == ""


def test_a_publisher_not_named_yet_holds_neutral_without_a_disarm_until_named_or_the_bound():
    """Under load, discovery shows a new command publisher as _NODE_NAME_UNKNOWN_ for a while: that alone must not
    disarm (it did), but its commands cannot be trusted meanwhile (it may be a foreign one): held at neutral. Once
    named, the allocation's commands flow again; a stranger once named, one unnamed past the bound, or a second live
    publisher beside the allocation is a fault that disarms."""
    from hindrax_drivers.pca9685.core import NAME_RESOLVE_BOUND_S, UNNAMED_NODE, command_source_unnamed

    names = [COMMAND_NODE, UNNAMED_NODE]
    assert UNNAMED_NODE == "_NODE_NAME_UNKNOWN_"
    assert command_source_fault(names, alive=1, unnamed_for_s=0.5) == ""
    assert command_source_fault([UNNAMED_NODE], alive=1, unnamed_for_s=NAME_RESOLVE_BOUND_S - 0.1) == ""
    assert "still unnamed after 2.5 s" in command_source_fault(names, alive=1, unnamed_for_s=2.5)
    assert "2 live publishers" in command_source_fault(names, alive=2, unnamed_for_s=0.0)
    assert "'rogue'" in command_source_fault([COMMAND_NODE, UNNAMED_NODE, "rogue"], alive=1)
    unnamed = command_source_unnamed(names)
    assert "not named yet" in unnamed and command_source_unnamed([COMMAND_NODE]) == ""

    core, _clock = armed_commanding()
    assert core.set_command_source("", unnamed) == ""
    assert core.armed and core.decide(10.0, 0.02).widths_us.tolist() == [1500.0, 1500.0]
    assert core.on_command(10.01, [1900.0, 1900.0], True) == unnamed
    assert core.decide(10.02, 0.02).widths_us.tolist() == [1500.0, 1500.0]
    core.set_command_source("", "")  # named: the allocation
    assert core.on_command(10.03, [1700.0, 1700.0], True) == ""
    assert core.armed and core.decide(10.04, 0.02).widths_us.tolist() == [1700.0, 1700.0]
    fault = command_source_fault(names, alive=1, unnamed_for_s=2.5)
    assert core.set_command_source(fault, command_source_unnamed(names)) == fault
    assert not core.armed and core.command_unnamed == ""


# (rule, job kind, result fields, chip confirmed before, expected event, output state after, substring of the reason)
CHIP_RESULT_ROWS = [
    ("configure read back: neutral confirmed", CONFIGURE, {}, False, "confirmed", OUTPUT_NEUTRAL, "holding neutral"),
    ("no bus at start-up: unknown, retried", CONFIGURE, {"error": "no I2C bus: ENOENT", "no_bus": True}, False,
     "lost", OUTPUT_UNKNOWN, "retrying"),
    ("configure not read back", CONFIGURE, {"mismatch": "MODE1 0x11"}, True, "lost", OUTPUT_UNKNOWN,
     "not confirmed: MODE1 0x11"),
    ("read-back failed", READBACK, {"error": "NACK"}, True, "lost", OUTPUT_UNKNOWN, "read-back failed"),
    ("read-back mismatch: re-initialise", READBACK, {"mismatch": "PRE_SCALE 121"}, True, "reinit", OUTPUT_NEUTRAL,
     "re-initialised at neutral"),
    ("thrust write failed: neutral next", WRITE, {"error": "NACK"}, True, "write_failed", OUTPUT_NEUTRAL, ""),
    ("neutral write failed: unknown", NEUTRAL, {"error": "NACK"}, True, "lost", OUTPUT_UNKNOWN,
     "cannot write neutral"),
    ("thrust written", WRITE, {"wrote": True}, True, "done", OUTPUT_COMMANDING, ""),
    ("a write posted before the chip was lost changes no state", WRITE, {"wrote": True}, False, "done",
     OUTPUT_UNKNOWN, ""),
]


@pytest.mark.parametrize("rule, kind, fields, confirmed, event, state, why", CHIP_RESULT_ROWS,
                         ids=[r[0] for r in CHIP_RESULT_ROWS])
def test_what_a_chip_result_means(rule, kind, fields, confirmed, event, state, why):
    core, clock = make()
    if confirmed:
        ready(core, clock)
    out = core.chip_result(kind, written_us=np.array([1700.0, 1700.0]), output_state=OUTPUT_COMMANDING, **fields)
    assert out.event == event and core.output_state == state
    assert why in out.message or why in core.reason
    assert not core.armed


def test_a_failed_thrust_write_drops_the_command_and_a_mismatch_disarms():
    core, clock = make()
    ready(core, clock)
    assert core.request_arm() == ""
    core.on_command(0.0, [1700.0, 1700.0], True)
    assert core.chip_result(WRITE, error="NACK").event == "write_failed" and core.command is None and core.armed
    assert core.chip_result(READBACK, mismatch="MODE1 0x11").event == "reinit" and not core.armed


def test_the_steady_watchdog_counts_executor_alive_time_only():
    """A 2 s gap between two checks counts two periods (0.04 s); regular 20 ms checks without a command trip after
    the timeout (0.2 s); a command restarts it; inactive (disarmed or no command) it never trips."""
    dog = SteadyWatchdog(0.02, 0.2, t_s=100.0)
    t = 102.0
    assert not dog.check(t, True) and dog.age_s == pytest.approx(0.04)
    for _ in range(7):
        t += 0.02
        assert not dog.check(t, True)
    t += 0.02
    assert not dog.check(t, True)  # 0.2 s: not beyond the timeout
    t += 0.02
    assert dog.check(t, True) and dog.trips == 1
    dog.command(t)
    assert dog.age_s == 0.0 and not dog.check(t + 0.02, True)
    assert not dog.check(t + 10.0, False) and dog.age_s == 0.0


def test_a_thrust_write_that_lands_after_the_chip_was_lost_keeps_the_retry_at_every_tick():
    """A bus call that came back after the stuck bound (the chip already counted as lost) may have put thrust on the
    wire: the chip is retried at once, not after the back-off, so that neutral follows within one tick."""
    core, clock = make()
    ready(core, clock)
    core.chip_attempt()
    core.chip_lost("PCA9685 bus call not returned after 0.16 s")
    clock.t += 0.01  # well inside the back-off
    assert core.chip_result(WRITE, wrote=True, written_us=np.array([1700.0, 1700.0]),
                            output_state=OUTPUT_COMMANDING).event == "done"
    assert core.output_state == OUTPUT_UNKNOWN and core.stale_width_possible and core.retry_due()
    core.chip_result(NEUTRAL, wrote=True, written_us=np.array([1500.0, 1500.0]))
    assert not core.stale_width_possible and not core.retry_due()
