"""Why the thrust stopped, in one line with the next step (supervisor/disarm_cause.py): one row per rule."""
from __future__ import annotations

import pytest

from hindrax_bringup.supervisor.disarm_cause import DisarmCauses, next_step

GUARD_SILENT = "ESC output state silent for 0.20 s (esc/heartbeat): ESC process dead or hung"


def armed() -> DisarmCauses:
    c = DisarmCauses()
    c.on_armed(True)
    return c


def test_the_first_cause_while_armed_is_kept_until_the_next_arming():
    c = armed()
    assert c.line == ""
    c.on_trip("depth 1.62 m beyond supervisor.max_depth_m 1.6")
    c.on_guard(False, "supervisor tripped: depth 1.62 m beyond supervisor.max_depth_m 1.6")
    c.on_armed(False, "supervisor not OK: depth 1.62 m")
    assert c.line == ("supervisor: depth 1.62 m beyond supervisor.max_depth_m 1.6; next: bring the vehicle back "
                      "inside the envelope (or fix what the cause names), then hindrax reset, hindrax arm")
    c.on_armed(True)
    assert c.line == ""


def test_the_guard_names_a_killed_esc_whose_armed_state_stays_latched():
    c = armed()
    c.on_guard(True, "outputs enabled")
    assert c.line == ""
    c.on_guard(False, GUARD_SILENT)
    assert c.line == (f"output guard: {GUARD_SILENT}; next: check the ESC process (hindrax health; the launch "
                      "respawns it), then hindrax arm")


def test_a_guard_error_while_disarmed_is_no_cause_and_an_esc_disarm_names_its_own_reason():
    c = DisarmCauses()
    c.on_guard(False, "start-up: no ESC output state confirmed yet")
    assert c.line == ""
    c.on_armed(True)
    c.on_armed(False, "watchdog: no command for 0.5 s")
    assert c.line.startswith("ESC: watchdog: no command for 0.5 s; next: the ESC got no thrust command in time")


@pytest.mark.parametrize("process, cause, words", [
    ("output guard", "no supervisor heartbeat for 0.25 s (supervisor/heartbeat): supervisor dead or hung",
     "check the supervisor process"),
    ("output guard", "ESC output state unknown: the PCA9685 cannot be written or read back (I2C fault)",
     "check the PCA9685"),
    ("supervisor", "operator e-stop (supervisor/estop)", "hindrax reset, then hindrax arm"),
    ("output guard", "heartbeat not trusted: supervisor/heartbeat publisher not identified yet (discovery has not "
     "named its node): trusted once the graph names it 'supervisor'", "wait a few seconds"),
    ("ESC", "disarmed", "hindrax arm when ready"),
    ("ESC", "something new", "hindrax health, then hindrax arm"),
])
def test_each_cause_has_its_next_step(process, cause, words):
    assert words in next_step(process, cause)


STARVED = ("identification starved for 1.80 s (tick due every 0.04 s; the CPU is short: docs/architecture.md "
           "§10.1, beyond 1 s: twice thrusters.wrench_timeout_s)")


def test_a_starvation_reported_after_the_stop_it_caused_joins_that_cause_once():
    """Starved, the campaign's wrench went stale, the vehicle sank and the supervisor tripped on the DVL before the
    identification ran again; its abort naming the starvation then comes second, and the line says both, the step
    the starvation's."""
    c = armed()
    c.on_trip("no valid DVL velocity for 2.0 s, beyond supervisor.max_invalid_dvl_s 2")
    c.on_starved("thruster test aborted")                 # not a starvation: no change
    c.on_starved(STARVED)
    c.on_starved(STARVED.replace("1.80", "2.40"))         # once
    assert c.line == (f"supervisor: no valid DVL velocity for 2.0 s, beyond supervisor.max_invalid_dvl_s 2 (after: "
                      f"{STARVED}); next: a process was starved of CPU (docs/architecture.md §10.1): stop what else "
                      "loads the vehicle's computer, then hindrax reset, hindrax arm")


def test_a_starvation_before_any_stop_is_the_cause_itself():
    c = armed()
    c.on_starved(STARVED)
    assert c.line == ""                                    # the supervisor's trip on the abort names it
    c.on_trip(f"abort requested: {STARVED}")
    assert c.line.startswith(f"supervisor: abort requested: {STARVED}; next: a process was starved of CPU")
