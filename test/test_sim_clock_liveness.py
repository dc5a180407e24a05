"""A liveness judgement follows the clock of the graph it protects (docs/architecture.md §8, heartbeats).

The vehicle's three safety processes (ESC, supervisor, output guard:
:mod:`hindrax_tools.benchmarks.safety`'s
emulated layout, each a process of its own) run on simulated time (``use_sim_time``), with this process publishing
``/clock``. A simulation that runs slower than real time (a starved simulator on a loaded machine) while the ESC's
process is stopped (SIGSTOP) for 1.5 s of wall time: on the graph's clock its heartbeat was never late, so the
guard keeps the outputs enabled and the vehicle stays armed. Before, the ESC's DDS liveliness lease (1 s, wall
clock) ran out at the guard ("no live publisher on esc/heartbeat") and its steady-clock age passed the 0.2 s timeout,
and the guard asserted /OE. Then, on a simulation at real time, a SIGKILLed ESC is still caught by its heartbeat's
age, and the outputs stop.
"""
from __future__ import annotations

import os
import signal
import time

import pytest
from rosgraph_msgs.msg import Clock

from hindrax_common.node_support.liveness import heartbeat_qos
from hindrax_common.testing import wait_until
from hindrax_tools.benchmarks.participant_churn import hardware_priority
from hindrax_tools.benchmarks.safety import _Layout, running_layout
from hindrax_msgs.msg import Heartbeat

pytestmark = pytest.mark.vehicle_launch

#: simulated seconds per wall second while the ESC is stopped: 1.5 s stopped (and up to 3.5 s more before its next
#: beat reaches the guard on a loaded machine) stay below the 0.2 s timeout on the graph's clock
SLOW_RATE = 0.04
#: how long the ESC's process is stopped, wall s (longer than the 1 s liveliness lease and the 0.2 s timeout)
STOP_S = 1.5
#: generous bound for what a loaded 2-core machine takes (resume, discovery of a kill), s
BOUND_S = 30.0


class SimClockLayout(_Layout):
    """The layout with every process on ``use_sim_time`` and a ``/clock`` from this process at 100 Hz of wall time,
    advancing :attr:`rate` simulated seconds per wall second. Records the guard's heartbeats (monotonic time,
    level, message)."""

    def __init__(self, *args, **kwargs) -> None:
        self.rate = SLOW_RATE
        self._sim_ns = 1_000_000_000_000
        self._wall = time.monotonic()
        self.guard_beats: list[tuple[float, int, str]] = []
        super().__init__(*args, **kwargs)
        self._clock = self.probe.create_publisher(Clock, "/clock", 10)
        self.probe.create_timer(0.01, self._tick_clock)
        self.probe.create_subscription(Heartbeat, "guard/heartbeat", self._on_guard, heartbeat_qos())

    def _tick_clock(self) -> None:
        now = time.monotonic()
        self._sim_ns += int(self.rate * (now - self._wall) * 1e9)
        self._wall = now
        msg = Clock()
        msg.clock.sec, msg.clock.nanosec = divmod(self._sim_ns, 1_000_000_000)
        self._clock.publish(msg)

    def _on_guard(self, msg) -> None:
        self.guard_beats.append((time.monotonic(), msg.level, msg.message))

    def start(self, name: str, extra: tuple = ()) -> None:
        super().start(name, ("-p", "use_sim_time:=true", *extra))


def test_a_stalled_esc_on_a_slow_simulation_stays_armed_and_a_killed_one_still_stops_the_outputs():
    with running_layout("hindrax-simclock-", int(os.environ["ROS_DOMAIN_ID"]), SimClockLayout) as lay:
        hw = lay.hw
        lay.armed_at_1700()
        # the emulated hardware real-time from here, as the benches run it: the vehicle's /OE line and watchdog
        # are never starved by a CPU load, and this process's starved line held the guard's feed 0.35 s at load 10-15
        with hardware_priority():
            _stalled_then_killed(lay, hw)


def _stalled_then_killed(lay, hw) -> None:
    """Armed: the ESC stopped 1.5 s on a slow simulation (nothing happens), then killed on a real-time one (the
    outputs stop, the guard says why)."""
    # the commands go on through the stop: a SIGSTOP inside one of the ESC's bus calls stalls the worker's
    # checker too, which defers its stuck-bus verdict (pca9685/worker.py, ChipWorker.stuck_s)
    stopped_at = time.monotonic()
    lay.signal("esc", signal.SIGSTOP)
    try:
        wait_until(lambda: time.monotonic() - stopped_at >= STOP_S, STOP_S + 5.0, None, "ESC stopped 1.5 s")
    finally:
        lay.signal("esc", signal.SIGCONT)
    resumed_at = time.monotonic()
    # the ESC publishes again, and the guard has judged it for a second of wall time after that
    wait_until(lambda: lay.last_state is not None and lay.last_state[0] > resumed_at, BOUND_S, None,
               "ESC publishing again")
    judged = time.monotonic()
    wait_until(lambda: sum(t > judged for t, _, _ in lay.guard_beats) >= 20, BOUND_S, None,
               "20 guard heartbeats after the ESC resumed")
    bad = [(round(t - stopped_at, 2), m) for t, level, m in lay.guard_beats if t > stopped_at and level != 0]
    assert not bad, f"the guard silenced the outputs although nothing was late on the graph's clock: {bad[:3]}"
    assert hw.oe_at is None and hw.thrust() and hw.emu.pulse_width_us(0) > 1690.0
    assert lay.last_msg.armed and not lay.disarmed_after_arm, "the ESC disarmed"

    # a simulation at real time: a killed ESC is late on the graph's clock too, and the guard stops the outputs
    lay.rate = 1.0
    killed_at = time.monotonic()
    lay.kill("esc")
    wait_until(lambda: hw.line.is_high(), BOUND_S, None, "/OE asserted after the ESC was killed")
    assert not hw.thrust()

    def reasons() -> list[str]:  # the guard's beat saying why goes out just before its /OE write
        return [m for t, level, m in lay.guard_beats if t > killed_at and level != 0]
    wait_until(reasons, BOUND_S, None, "the guard's ERROR heartbeat")
    assert reasons()[0].startswith("ESC output state silent"), reasons()[:3]
