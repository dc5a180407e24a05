"""The ESC's chip I/O worker (pca9685/worker.py) on the register-exact emulator, without ROS: the queue rules, the
stuck-call bound, the bus opened in the worker, and with the link and core: a disarm during a thrust write ends at
neutral, and NEUTRAL is reported only while neutral is on the chip."""
from __future__ import annotations

import threading

import numpy as np
import pytest

from hindrax_drivers.pca9685.chip import EscChip
from hindrax_drivers.pca9685.emulator import Pca9685Emulator
from hindrax_drivers.pca9685.worker import CONFIGURE, NEUTRAL, READBACK, WRITE, ChipJob, ChipWorker
from hindrax_common.testing import wait_until
from hindrax_common.transport.emulated_i2c import EmulatedI2CBus

COUNT_US = 1.24  # prescale 30 at 25 MHz (datasheet §7.3.5)
NEUTRAL_US = np.full(8, 1500.0)


class _Raw:
    def begin_batch(self):
        pass

    def flush(self):
        pass


class _HeldBus:
    """An EmulatedI2CBus whose block writes wait for :attr:`release` while :attr:`hold` is set (a bus that hangs)."""

    def __init__(self, emu):
        self.bus = EmulatedI2CBus({0x40: emu})
        self.hold, self.release, self.writes = False, threading.Event(), []

    def __getattr__(self, name):
        return getattr(self.bus, name)

    def write_i2c_block_data(self, address, register, data):
        self.writes.append(list(data))
        if self.hold:
            self.release.wait(10)
        return self.bus.write_i2c_block_data(address, register, data)


def _worker(threaded=True, call_timeout_s=0.15, open_bus=None):
    emu = Pca9685Emulator()
    bus = _HeldBus(emu)
    chip = EscChip(0x40, 30, 25e6, range(8), 8, _Raw())
    worker = ChipWorker(chip, open_bus or (lambda: bus), threaded=threaded, call_timeout_s=call_timeout_s)
    return worker, emu, bus


def _job(kind, width=1500.0):
    return ChipJob(kind, np.full(8, width), 1100.0)


def _wire(emu):
    return np.array([emu.pulse_width_us(c) for c in range(8)])


def test_the_bus_is_opened_by_the_worker_and_a_configure_confirms_neutral():
    worker, emu, _ = _worker()
    worker.post(_job(CONFIGURE))
    assert worker.wait_idle(5)
    [result] = worker.results()
    assert result.job.kind == CONFIGURE and not result.error and not result.mismatch
    assert np.allclose(result.written_us, NEUTRAL_US, atol=COUNT_US) and emu.mode1 == 0x21
    worker.stop()


def test_no_bus_is_a_result_not_an_exception():
    def absent():
        raise FileNotFoundError(2, "No such file or directory: '/dev/i2c-1'")
    worker, _, _ = _worker(open_bus=absent)
    worker.post(_job(CONFIGURE))
    assert worker.wait_idle(5)
    [result] = worker.results()
    assert result.no_bus and "no I2C bus" in result.error and worker.chip.device is None
    worker.stop()


def test_newest_thrust_wins_and_a_neutral_is_never_dropped_nor_overtaken():
    """While the bus hangs on a write: two thrust writes queue as one (the newest), a neutral drops the thrust
    before it, and a thrust posted after the neutral runs after it; the read-back and the configure are not queued
    twice."""
    worker, emu, bus = _worker()
    worker.post(_job(CONFIGURE))
    assert worker.wait_idle(5)
    worker.results()
    bus.hold, bus.writes[:] = True, []
    worker.post(_job(WRITE, 1600.0))
    wait_until(lambda: bus.writes, 5, message="the first write on the bus")
    worker.post(_job(WRITE, 1650.0))
    worker.post(_job(WRITE, 1700.0))  # replaces 1650
    worker.post(_job(READBACK))
    worker.post(_job(READBACK))  # already queued
    worker.post(_job(WRITE, 1750.0))
    worker.post(_job(NEUTRAL))  # drops 1750 (and 1700 before the read-back); keeps the read-back
    worker.post(_job(WRITE, 1800.0))  # after the neutral
    bus.release.set()
    assert worker.wait_idle(5)
    done = [(r.job.kind, r.job.widths_us[0]) for r in worker.results()]
    assert done == [(WRITE, 1600.0), (READBACK, 1500.0), (NEUTRAL, 1500.0), (WRITE, 1800.0)]
    assert _wire(emu)[0] == pytest.approx(1800.0, abs=COUNT_US)
    worker.post(_job(CONFIGURE))
    worker.post(_job(CONFIGURE))
    assert worker.wait_idle(5) and [r.job.kind for r in worker.results()] == [CONFIGURE]
    worker.stop()


def test_a_checker_that_was_not_scheduled_defers_the_stuck_verdict_once():
    """stuck_s() after its caller was away longer than the bound (a stalled process) puts the verdict off to the
    next check, once per call: a call still hanging at that next check is reported (with its whole age)."""
    now = [0.0]
    worker, _, _ = _worker(threaded=False, call_timeout_s=0.15)
    worker.clock = lambda: now[0]
    assert worker.stuck_s() == 0.0  # idle: nothing to judge
    worker._call_since = 0.0  # a call started at 0 (as _TimedBus marks it) and not returned
    now[0] = 0.04
    assert worker.stuck_s() == 0.0  # within the bound
    now[0] = 0.84  # this checker was away 0.8 s: not conclusive
    assert worker.stuck_s() == 0.0
    now[0] = 0.88  # the next tick: still hanging, reported
    assert worker.stuck_s() == pytest.approx(0.88)
    now[0] = 2.0  # away again, same call: no second deferral
    assert worker.stuck_s() == pytest.approx(2.0)
    # a call that returns during the stall is never called stuck
    worker._call_since = 3.0
    now[0] = 3.05
    assert worker.stuck_s() == 0.0
    now[0] = 3.9
    assert worker.stuck_s() == 0.0  # deferred
    worker._call_since = None  # the worker got its turn and the reply
    now[0] = 3.94
    assert worker.stuck_s() == 0.0
    # checks every 0.04 s on a hanging call: reported as soon as it passes the bound, no deferral
    worker._call_since = 5.0
    for k in range(1, 5):
        now[0] = 5.0 + 0.04 * k
        assert worker.stuck_s() == (pytest.approx(0.16) if k == 4 else 0.0)


def test_a_call_that_does_not_return_is_reported_stuck_after_the_bound_and_only_then():
    worker, _, bus = _worker(call_timeout_s=0.1)
    worker.post(_job(CONFIGURE))
    assert worker.wait_idle(5)
    bus.hold = True
    worker.post(_job(WRITE, 1600.0))
    wait_until(lambda: bus.writes and worker.pending(WRITE), 5, message="the write on the bus")
    t0 = worker.clock()
    wait_until(lambda: worker.stuck_s() > 0.0, 5, message="stuck")
    assert worker.clock() - t0 >= 0.1 - 0.02 and worker.stuck_s() > 0.1
    bus.release.set()
    assert worker.wait_idle(5) and worker.stuck_s() == 0.0
    worker.stop()


def test_without_a_thread_the_poster_runs_the_job():
    worker, emu, _ = _worker(threaded=False)
    worker.post(_job(CONFIGURE))
    worker.post(_job(WRITE, 1700.0))
    assert _wire(emu)[0] == pytest.approx(1700.0, abs=COUNT_US)  # done before post returned
    assert [r.job.kind for r in worker.results()] == [CONFIGURE, WRITE]
    assert worker._thread is None


def test_a_failed_write_is_an_error_result_and_the_chip_forgets():
    worker, _, bus = _worker()
    worker.post(_job(CONFIGURE))
    assert worker.wait_idle(5)
    worker.results()
    bus.bus.disconnected = True
    worker.post(_job(WRITE, 1600.0))
    assert worker.wait_idle(5)
    [result] = worker.results()
    assert result.error and not result.wrote and worker.chip._written_key is None
    worker.stop()


class _Diag:
    """The node's diagnostics as the link uses them (state and counters only)."""

    def __init__(self):
        self.counts = {}

    def set_state(self, *args):
        pass

    def count(self, key):
        self.counts[key] = self.counts.get(key, 0) + 1

    def warn(self, *args):
        pass


def _armed_link(call_timeout_s=0.15):
    """A ChipLink over an EscCore and a threaded worker on the held bus, configured at neutral and armed."""
    from hindrax_drivers.pca9685.core import OUTPUT_NEUTRAL, EscCore, EscOutput
    from hindrax_drivers.pca9685.link import ChipLink

    worker, emu, bus = _worker(call_timeout_s=call_timeout_s)
    core = EscCore(EscOutput(range(8), [False] * 8, [0.0] * 8, 1100, 1500, 1900), arming_time_s=0.0,
                   watchdog_timeout_s=1.0, oscillator_calibrated=True, clock=worker.clock, period_s=0.02,
                   guard_confirm_s=0.0)
    link = ChipLink(core, worker, _Diag(), lambda text: None, lambda: 1100.0, readback_interval_s=1e9)
    link.configure()
    assert worker.wait_idle(5)
    link.take()
    assert core.output_state == OUTPUT_NEUTRAL and core.neutral_confirmed_at is not None
    core.set_peers("", "")
    assert core.request_arm() == ""
    return link, core, worker, emu, bus


def _neutral_claims(link, core, emu, worker, until):
    """Take results until ``until()``; every time the core says NEUTRAL (what lets the output guard release /OE),
    the wire must hold neutral. Returns the output states seen."""
    from hindrax_drivers.pca9685.core import OUTPUT_NEUTRAL

    seen = []

    def step():
        link.take()
        seen.append(core.output_state)
        if core.output_state == OUTPUT_NEUTRAL:
            assert np.allclose(_wire(emu), NEUTRAL_US, atol=COUNT_US), f"NEUTRAL reported with {_wire(emu)} on chip"
        return until()
    wait_until(step, 10, message="the link settled")
    return seen


def test_a_disarm_during_a_thrust_write_in_flight_ends_at_neutral_and_says_neutral_only_then():
    """Fail closed across the worker: a thrust write is on the bus when the disarm's neutral is posted. The neutral
    runs after it, the chip ends at neutral, and the output state says NEUTRAL only once neutral is on the chip."""
    from hindrax_drivers.pca9685.core import OUTPUT_COMMANDING, OUTPUT_NEUTRAL

    link, core, worker, emu, bus = _armed_link()
    bus.hold, bus.writes[:] = True, []
    link.post(WRITE, np.full(8, 1700.0), OUTPUT_COMMANDING)
    wait_until(lambda: bus.writes, 5, message="the thrust write on the bus")
    core.disarm("test disarm")
    link.neutral("test disarm")
    link.post(WRITE, core.decide(0.0, 0.0).widths_us, OUTPUT_NEUTRAL)  # the next tick, disarmed: deduplicated
    assert core.output_state == OUTPUT_NEUTRAL  # from the arm: the chip held neutral then
    bus.release.set()
    _neutral_claims(link, core, emu, worker, lambda: not worker.pending() and core.output_state == OUTPUT_NEUTRAL
                    and np.allclose(link.written, NEUTRAL_US, atol=COUNT_US))
    assert np.allclose(_wire(emu), NEUTRAL_US, atol=COUNT_US) and not core.armed
    worker.stop()


def test_a_thrust_write_that_returns_after_the_stuck_bound_is_overwritten_by_neutral():
    """A thrust write hangs past the bound: the chip counts as lost (UNKNOWN, disarmed). When the call returns
    late, its thrust is on the chip: the link re-configures at neutral, and NEUTRAL is said only after that."""
    from hindrax_drivers.pca9685.core import OUTPUT_COMMANDING, OUTPUT_NEUTRAL, OUTPUT_UNKNOWN

    link, core, worker, emu, bus = _armed_link(call_timeout_s=0.1)
    bus.hold, bus.writes[:] = True, []
    link.post(WRITE, np.full(8, 1700.0), OUTPUT_COMMANDING)
    wait_until(lambda: (link.maintain(worker.clock()), core.output_state == OUTPUT_UNKNOWN)[1], 10,
               message="the stuck call makes the chip UNKNOWN")
    assert not core.armed
    bus.release.set()
    seen = _neutral_claims(link, core, emu, worker,
                           lambda: (link.maintain(worker.clock()), not worker.pending()
                                    and core.output_state == OUTPUT_NEUTRAL)[1])
    assert OUTPUT_UNKNOWN in seen and np.allclose(_wire(emu), NEUTRAL_US, atol=COUNT_US)
    assert link.bus_stalls == 1 and not core.stale_width_possible
    worker.stop()
