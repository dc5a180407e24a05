"""No single failure leaves a thruster running (docs/architecture.md §8).

Each test reproduces one finding against the register-exact PCA9685 emulator (what is on the wire), with the
supervisor's and the guard's heartbeats from a stand-in or the real nodes. Every one of them failed on the code
before the independent stop paths (no heartbeat, no guard, no output state, ROS-time read-back).
"""
from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rosgraph_msgs.msg import Clock

from hindrax_bringup.guard.core import OUTPUT_COMMANDING, OUTPUT_NEUTRAL, OUTPUT_UNKNOWN, GuardCore
from hindrax_bringup.guard.node import OutputGuardNode
from hindrax_common.cdr.lean_cdr import Beat
from hindrax_common.node_support.liveness import AliveAge, ClockStepMonitor
from hindrax_drivers.pca9685.emulator import Pca9685Emulator
from hindrax_drivers.pca9685.node import EscNode
from hindrax_common.testing import (AllocationStandIn, SafetyHeartbeats, child_env, child_process, config_parameters,
                                     interrupt, ros_context, wait_until)
from hindrax_common.transport.emulated_i2c import EmulatedI2CBus
from hindrax_common.transport.gpio import EmulatedGpioLine, WatchdogFeedLine, WatchedOutputEnable
from hindrax_common.transport.shared_emulation import EmulationServer, SharedGpioLine
from hindrax_msgs.msg import ThrusterPwm
from hindrax_msgs.srv import SetArmed

TICK_US = 1.3  # one PCA9685 count at 200 Hz (docs/devices.md §5.1)
OVER = {"esc.arming_time_s": 0.0, "esc.oscillator_calibrated": True, "esc.watchdog_timeout_s": 2.0}


def wire(emu):
    return np.array([emu.pulse_width_us(c) for c in range(8)])


class Rig:
    """ESC node on an emulated PCA9685 (with an emulated /OE line), a probe with heartbeat stand-ins, and
    optionally the real output guard on the same bus and line."""

    def __init__(self, ctx, guard=False, wired=True, sim_time=False, overrides=None, guard_bus=lambda bus: bus,
                 guard_opens_line=False, watchdog_s=None):
        self.line = EmulatedGpioLine(pull_high=True) if wired else None
        # watchdog_s: the hardware watchdog on /OE fitted (docs/watchdog.md), with that timeout
        self.feed = WatchdogFeedLine(watchdog_s) if watchdog_s else None
        self.emu = Pca9685Emulator(output_enable_line=self.line if self.feed is None else
                                   WatchedOutputEnable(self.line, self.feed))
        self.bus = EmulatedI2CBus({0x40: self.emu})
        params = config_parameters({**OVER, **(overrides or {})})
        if sim_time:
            params = params + [Parameter("use_sim_time", value=True)]
        self.esc = EscNode(bus=self.bus, context=ctx, parameter_overrides=params)
        self.probe = rclpy.create_node("probe", context=ctx)
        self.beats = SafetyHeartbeats(self.probe, supervisor="", guard=None if guard else "")
        # guard_opens_line: the guard requests its configured /OE line itself (open_output_enable, patched by the test)
        gpio = {"esc.output_enable_gpio.chip": "/dev/gpiochip0", "esc.output_enable_gpio.line": 17}
        feed = {"esc.output_enable_feed_rate_hz": 10.0, "esc.output_enable_feed_timeout_s": watchdog_s or 0.33}
        self.guard = OutputGuardNode(
            line=None if guard_opens_line else self.line, bus=None if wired else guard_bus(self.bus), feed=self.feed,
            context=ctx, parameter_overrides=config_parameters({**OVER, **(gpio if guard_opens_line else {}),
                                                                **(feed if self.feed else {})})) if guard else None
        self.ex = SingleThreadedExecutor(context=ctx)
        for n in (self.esc, self.probe, self.guard):
            if n is not None:
                self.ex.add_node(n)
        self.states: list[ThrusterPwm] = []
        self.probe.create_subscription(ThrusterPwm, "thrusters/pulse_width", self.states.append, 50)
        self.allocation = AllocationStandIn(ctx)  # the one commander the ESC accepts
        self.cmd = self.allocation.pub
        self.clock = self.probe.create_publisher(Clock, "/clock", 10)
        self.arm_client = self.probe.create_client(SetArmed, "esc/set_armed")
        self.ns = 200_000_000_000
        self.sim_time = sim_time
        if self.line is not None and not guard:
            self.line.set_high(False)  # /OE held low (no guard in this rig)
        self.wait(lambda: self.arm_client.service_is_ready() and self.cmd.get_subscription_count() > 0,
                  "ESC ready")

    def spin(self):
        if self.sim_time:
            self.ns += 2_000_000
            c = Clock()
            c.clock.sec, c.clock.nanosec = divmod(self.ns, 1_000_000_000)
            self.clock.publish(c)
        self.ex.spin_once(timeout_sec=0.005)

    def wait(self, predicate, message, timeout=10.0, poll=None):
        return wait_until(predicate, timeout, poll or self.spin, message)

    def set_armed(self, value):
        fut = self.arm_client.call_async(SetArmed.Request(arm=value))
        self.wait(fut.done, "SetArmed answer")
        return fut.result()

    def command(self, width=1700.0):
        self.cmd.publish(ThrusterPwm(pulse_width_us=[width] * 8, armed=True))

    def commanding(self):
        self.command()
        self.spin()

    def arm_at_1700(self):
        """Arm and command 1700 us until it is on the wire. This process runs the guard and the heartbeats; the
        suite's load can starve it past the guard's 0.2 s (a fresh clone of 1a1d83e: "ESC output state silent for
        0.22 s", arming refused). The guard is right to silence the outputs then, so an attempt that the guard
        silenced (a refusal for a silent heartbeat, or an assertion before 1700 us reached the wire) waits for its
        release and arms again; any other refusal, or a disarm without the guard, fails."""
        def attempt():
            self.wait(lambda: not self.esc.heartbeat_refusal() and self.esc.arming_remaining_s() == 0.0
                      and (self.guard is None or not self.guard.core.asserted), "ready to arm")
            silenced = self.guard.assertions if self.guard is not None else 0
            res = self.set_armed(True)
            assert res.success or " silent for " in res.message, res.message
            if res.success:
                self.wait(lambda: wire(self.emu)[0] > 1690 or not self.esc.armed, "1700 us on the wire",
                          poll=self.commanding)
            on_wire = self.esc.armed and wire(self.emu)[0] > 1690
            assert on_wire or not res.success and " silent for " in res.message \
                or self.guard is not None and self.guard.assertions > silenced, "disarmed, the guard silent"
            return on_wire
        self.wait(attempt, "armed, 1700 us on the wire", timeout=30.0)

    def close(self):
        self.ex.shutdown()
        for n in (self.guard, self.probe, self.esc, self.allocation.node):
            if n is not None:
                n.destroy_node()


@pytest.fixture
def rig():
    rigs = []
    with ros_context() as ctx:
        def make(**kwargs):
            r = Rig(ctx, **kwargs)
            rigs.append(r)
            return r
        yield make
        for r in rigs:
            r.close()


# ------------------------------------------------------------------ finding 1: the supervisor's heartbeat
def test_f1_arming_is_refused_without_a_supervisor_or_while_it_is_tripped(rig):
    r = rig()
    r.beats.supervisor = None  # no supervisor running
    # the chip confirmed at neutral first (its worker thread answers when the machine lets it): that refusal comes
    # before the supervisor's, and is not what this test is about
    r.wait(lambda: r.esc.neutral_confirmed_time is not None, "PCA9685 confirmed at neutral")
    r.wait(lambda: not r.esc.peers.supervisor_age.fresh(r.esc.peers.timeout_s), "heartbeat stale")
    res = r.set_armed(True)
    assert not res.success and "no supervisor heartbeat" in res.message
    r.beats.supervisor = "depth 3.00 m beyond supervisor.max_depth_m 1.65"  # running, tripped
    r.wait(lambda: r.esc.peers.supervisor_age.fresh(0.1) and not r.esc.peers.supervisor_ok, "tripped heartbeat")
    res = r.set_armed(True)
    assert not res.success and "supervisor tripped: depth 3.00 m" in res.message
    r.beats.supervisor = ""
    r.wait(lambda: r.esc.peers.supervisor_ok and r.esc.arming_remaining_s() == 0.0, "OK heartbeat, time at neutral")
    assert r.set_armed(True).success


@pytest.mark.parametrize("failure", ["killed_or_hung", "tripped"])
def test_f1_losing_the_supervisor_while_armed_disarms_to_neutral(rig, failure):
    """Killed (SIGKILL) and hung (SIGSTOP) look the same from the ESC: the heartbeats stop."""
    r = rig()
    r.arm_at_1700()
    r.beats.supervisor = None if failure == "killed_or_hung" else "imu/data_raw at 0.0 Hz"
    r.wait(lambda: np.allclose(wire(r.emu), 1500.0, atol=TICK_US), "neutral on the wire", poll=r.commanding)
    assert not r.esc.armed and r.esc.heartbeat_disarms >= 1
    # still commanding 1700 us: nothing reaches the wire until a new arm request
    for _ in range(20):
        r.commanding()
    assert np.allclose(wire(r.emu), 1500.0, atol=TICK_US)


# ------------------------------------------------------------------ finding 2: a stop path outside the ESC
def test_f2_esc_process_gone_while_armed_the_guard_drives_oe_high(rig):
    r = rig(guard=True)
    r.wait(lambda: not r.guard.core.asserted and not r.line.is_high(), "guard released /OE at neutral")
    r.arm_at_1700()
    r.ex.remove_node(r.esc)  # the ESC process dies or hangs: its registers keep 1700 us
    assert r.emu.channel_registers(0).off_count > 0
    r.wait(lambda: r.line.is_high(), "/OE asserted")
    assert np.all(wire(r.emu) == 0.0)  # no pulses at all: the Basic ESC stops
    assert "ESC output state silent" in r.guard.core.reason
    # the ESC comes back (SIGCONT): it sees the guard's ERROR heartbeat, disarms, and only then /OE is released
    r.ex.add_node(r.esc)
    r.wait(lambda: not r.line.is_high(), "released after the ESC disarmed", poll=r.commanding)
    assert not r.esc.armed and np.allclose(wire(r.emu), 1500.0, atol=TICK_US)


def test_f2_a_starved_guard_takes_the_waiting_beats_before_it_judges_a_dead_esc_still_stops(rig):
    """The busy-neighbours bench at nice -5 disarmed once: a guard starved past its 0.2 s timeout
    ran its tick before the callbacks of the ESC beats that had arrived meanwhile, and took a live
    ESC for a dead one. Starved here by leaving the executor (the ESC beating on); its tick must
    take those beats first. A dead ESC must still stop the
    outputs: the beats waiting then are aged from their send stamps, older than the timeout."""
    # the ESC does not disarm on the quiet guard
    r = rig(guard=True, overrides={"esc.heartbeat_timeout_s": 1.0})
    r.wait(lambda: not r.guard.core.asserted and not r.line.is_high(),
           "guard released /OE at neutral")
    r.arm_at_1700()

    def spin_for(seconds):
        start = time.monotonic()
        r.wait(lambda: time.monotonic() - start > seconds, f"{seconds} s passed", poll=r.commanding)

    def starve_guard(esc_dies=False):
        r.ex.remove_node(r.guard)
        # callbacks of the guard the executor had already found ready still run after remove_node (rclpy takes them
        # one per spin_once): let them run out before the stall, or the guard hears a beat inside it (under load)
        spin_for(0.05)
        r.guard.tick()  # its last tick before the stall (a beat heard since: its age is above 0)
        spin_for(0.3)  # the ESC's beats wait on the guard's subscription
        if esc_dies:
            r.ex.remove_node(r.esc)
            spin_for(0.3)
        r.ex.add_node(r.guard)
        r.guard.tick()  # its timer before the beats' callbacks

    starve_guard()
    assert (not r.guard.core.asserted and not r.line.is_high()
            and r.guard.watches["esc"].taken_late > 0)
    assert r.esc.armed and wire(r.emu)[0] > 1690
    taken = r.guard.watches["esc"].taken_late
    # the ESC dies while the guard is starved: its beats wait, the newest 0.3 s old
    starve_guard(esc_dies=True)
    assert r.guard.watches["esc"].taken_late > taken
    assert (r.guard.core.asserted and r.line.is_high()
            and "ESC output state silent" in r.guard.core.reason)


def test_f2_supervisor_breach_asserts_oe_too(rig):
    r = rig(guard=True)
    r.wait(lambda: not r.guard.core.asserted, "guard released")
    r.arm_at_1700()
    r.beats.supervisor = "depth 3.00 m beyond supervisor.max_depth_m 1.65"
    r.wait(lambda: r.line.is_high(), "/OE asserted on the breach", poll=r.commanding)
    assert r.guard.core.reason.startswith("supervisor tripped")


def test_f2_without_oe_the_guard_puts_the_chip_to_sleep_over_the_bus(rig):
    r = rig(guard=True, wired=False)
    r.wait(lambda: not r.guard.core.asserted, "guard released")
    r.arm_at_1700()
    r.ex.remove_node(r.esc)
    r.wait(lambda: r.emu.sleeping, "chip asleep")
    assert np.all(wire(r.emu) == 0.0)


@pytest.mark.parametrize("forger_name", ["forger", "supervisor"])
def test_f2_a_second_supervisor_heartbeat_publisher_asserts_oe(rig, forger_name):
    """Issue 43 item 2: a second live publisher on supervisor/heartbeat (another name, or the supervisor's own) is a
    forged or replayed heartbeat: /OE is asserted, and released only after the forger is gone and the ESC disarmed."""
    from hindrax_common.node_support.liveness import HeartbeatPublisher

    r = rig(guard=True)
    r.wait(lambda: not r.guard.core.asserted and not r.line.is_high(), "guard released /OE at neutral")
    r.arm_at_1700()
    with ros_context() as other:  # a participant of its own, as another process's would be
        forger = rclpy.create_node(forger_name, context=other)
        beats = HeartbeatPublisher(forger, "supervisor")
        # both stop paths act on it: the guard's identity check and the ESC's (a loaded machine may also make the
        # guard's first reason "ESC output state silent"; the forger must not be gone before the ESC has seen it)
        r.wait(lambda: r.line.is_high() and not r.esc.armed and "supervisor/heartbeat" in r.guard.core.identity_fault,
               "/OE asserted and the ESC disarmed", poll=lambda: (beats.publish(True, "ok"),
                                                                  r.commanding()))
        assert np.all(wire(r.emu) == 0.0)
        forger.destroy_node()
    r.wait(lambda: not r.line.is_high(), "released once the forger is gone and the ESC disarmed",
           poll=r.commanding, timeout=20.0)
    assert not r.esc.armed and np.allclose(wire(r.emu), 1500.0, atol=TICK_US)


def test_f2_guard_start_holds_oe_until_a_live_esc_confirms_neutral():
    core = GuardCore(timeout_s=0.2)
    assert core.decide(math.inf, 0.0, 1)[0]  # no ESC heard yet
    core.on_supervisor(True, "")
    core.on_esc(OUTPUT_COMMANDING, True, 1)
    assert core.decide(0.0, 0.0, 2)[0]  # latched: an armed ESC never releases it
    core.on_esc(OUTPUT_UNKNOWN, False, 2)
    assert core.decide(0.0, 0.0, 3)[0] and "unknown" in core.reason
    core.on_esc(OUTPUT_NEUTRAL, False, 0)  # at neutral, but it acknowledges no beat of this guard (its restart)
    assert core.decide(0.0, 0.0, 4)[0] and "waiting for the ESC" in core.reason
    core.on_esc(OUTPUT_NEUTRAL, False, 4)
    assert core.decide(0.0, 0.0, 5) == (False, True)
    assert core.decide(0.0, 0.25, 6)[0] and "no supervisor heartbeat" in core.reason


def test_f2_the_guard_releases_only_on_an_esc_beat_acknowledging_an_error_beat_after_the_cause():
    """Seen under load: the guard asserted /OE on a forged supervisor beat and released it 37 ms later on the ESC's
    newest beat, sent before the arm (disarmed, neutral), while the ESC was armed with 1700 us on the chip. Then the
    rule was "an ESC beat received after the cause", which a pre-arm beat delivered late still met. A release now
    needs an ESC beat that acknowledges a guard beat published since the last cause (the ESC handled that ERROR
    beat, so it disarmed and cannot have armed again), whenever it arrives."""
    core = GuardCore(timeout_s=0.2)
    core.on_supervisor(True, "")
    core.on_esc(OUTPUT_NEUTRAL, False, 1)
    assert core.decide(0.0, 0.0, 2) == (False, True)  # beat 2 says OK: the ESC may arm on it
    core.on_identity("supervisor/heartbeat published by node '_NODE_NAME_UNKNOWN_'")  # (the ESC arms meanwhile)
    assert core.decide(0.05, 0.0, 3) == (True, True)  # beat 3: ERROR
    core.on_identity("")  # the forger gone
    core.on_esc(OUTPUT_NEUTRAL, False, 2)  # a beat from before the arm, delivered late: received after the cause
    assert core.decide(0.0, 0.0, 4)[0] and "waiting for the ESC" in core.reason
    core.on_esc(OUTPUT_COMMANDING, False, 3)  # it handled beat 3 and disarmed; neutral not yet confirmed on the chip
    assert core.decide(0.0, 0.0, 5)[0]
    core.on_esc(OUTPUT_NEUTRAL, False, 5)  # disarmed at neutral, after an ERROR beat since the cause
    assert core.decide(0.0, 0.0, 6) == (False, True)


def test_f2_the_esc_beat_acknowledges_the_guard_beat_it_handled_and_the_guard_releases_on_it(rig):
    """The node side of the release rule: the ESC's beat echoes this guard's boot and the newest guard beat it
    handled; the guard releases at start-up and after a supervisor trip only once that echo reaches the ERROR beat
    of the last cause, and an echo of another guard boot acknowledges nothing."""
    r = rig(guard=True)
    r.wait(lambda: not r.guard.core.asserted, "guard released at start-up")
    assert r.esc.peers.guard_ack[0] == r.guard.heartbeat.boot_id
    assert r.guard.core.esc_ack_seq >= r.guard.core.cause_seq >= 1
    r.arm_at_1700()
    r.beats.supervisor = "depth limit"  # a breach: the guard asserts, the ESC disarms
    r.wait(lambda: r.guard.core.asserted, "guard asserted on the trip", poll=r.commanding)
    r.beats.supervisor = ""
    r.wait(lambda: not r.guard.core.asserted, "guard released after the trip")
    assert not r.esc.armed and r.guard.core.esc_ack_seq >= r.guard.core.cause_seq > 1
    other = Beat(boot_id=1, seq=1, steady_ns=0, guard_boot_id=r.guard.heartbeat.boot_id ^ 1, guard_seq=1000000,
                 level=0, output_state=OUTPUT_NEUTRAL, armed=False, message="")
    r.guard.on_esc(other)
    assert r.guard.core.esc_ack_seq == 0


def test_44_7_guard_without_its_line_says_error_retries_and_the_esc_refuses_to_arm(rig, monkeypatch):
    """Issue 44 item 7: the GPIO request fails at start-up (line busy): the guard's heartbeat is ERROR (it said OK
    before, and the ESC armed), the ESC refuses to arm on it; the guard retries and, once the line is granted, lets
    the ESC arm."""
    import hindrax_bringup.guard.node as guard_module

    granted = {"ok": False, "attempts": 0}

    def open_line(chip, line):
        granted["attempts"] += 1
        if not granted["ok"]:
            raise OSError(16, "Device or resource busy")
        r.line.set_high(True)
        return r.line

    monkeypatch.setattr(guard_module, "open_output_enable", open_line)
    r = rig(guard=True, guard_opens_line=True)
    r.wait(lambda: granted["attempts"] >= 3 and r.esc.heartbeat_refusal(), "retried, ESC sees the guard's ERROR")
    assert r.guard.core.asserted and "cannot request /OE /dev/gpiochip0:17" in r.guard.core.reason
    assert r.guard.diag.status().level == DiagnosticStatus.ERROR
    res = r.set_armed(True)
    assert not res.success and "output guard" in res.message and "Device or resource busy" in res.message
    granted["ok"] = True
    r.wait(lambda: not r.guard.core.asserted and not r.line.is_high(), "line granted, guard released")
    assert r.guard.core.drive_fault == ""
    r.arm_at_1700()


class _FlakyBus:
    """The guard's view of the I2C bus, failing on demand (the ESC keeps its own, working)."""

    def __init__(self, bus):
        self.bus, self.fail = bus, False

    def __getattr__(self, name):
        attr = getattr(self.bus, name)
        if not callable(attr):
            return attr

        def call(*args, **kwargs):
            if self.fail:
                raise OSError(121, "Remote I/O error")
            return attr(*args, **kwargs)
        return call


def test_44_7_a_failed_silencing_stays_error_until_a_retry_reaches_the_chip(rig):
    """Issue 44 item 7, without /OE: the guard's sleep-register write fails; its heartbeat stays ERROR after the
    cause (a supervisor trip) is gone, so the ESC cannot arm, until a retry reaches the chip (it returned to OK at
    once before, and never retried)."""
    r = rig(guard=True, wired=False, guard_bus=_FlakyBus)
    flaky = r.guard._bus
    r.wait(lambda: not r.guard.core.asserted, "guard released")
    r.arm_at_1700()
    flaky.fail = True
    r.beats.supervisor = "depth 3.00 m beyond supervisor.max_depth_m 1.65"
    r.wait(lambda: r.guard.core.drive_fault and not r.esc.armed, "silencing failed, ESC disarmed",
           poll=r.commanding)
    failures = r.guard.silence_failures
    r.beats.supervisor = ""
    r.wait(lambda: r.guard.silence_failures >= failures + 2, "retried", poll=r.commanding)
    assert r.guard.core.asserted and r.guard.core.reason.startswith("guard cannot act: cannot silence the outputs")
    res = r.set_armed(True)
    assert not res.success and "guard cannot act" in res.message
    flaky.fail = False
    r.wait(lambda: not r.guard.core.asserted, "a retry reached the chip, guard released", timeout=20.0)
    assert r.guard.core.drive_fault == ""


def test_44_2_frozen_guard_and_esc_the_hardware_watchdog_stops_the_outputs(rig):
    """Issue 44 item 2: the guard feeds the hardware watchdog only while the outputs are released; with the ESC and
    the guard frozen (their lines stay as they were, as for a SIGSTOPped process or a frozen Pi) the edges stop and
    the watchdog disables the outputs although /OE itself stays low. Before, a frozen launch kept thrust on."""
    import time

    r = rig(guard=True, watchdog_s=0.33)
    assert r.emu.output_enable_line.is_high()  # never fed yet: outputs off from power-up
    r.wait(lambda: not r.guard.core.asserted and r.feed.rises >= 2, "guard released and feeding")
    r.arm_at_1700()
    rises = r.feed.rises
    r.wait(lambda: r.feed.rises >= rises + 3, "fed while armed", poll=r.commanding)
    r.ex.remove_node(r.guard)  # the launch freezes: nothing runs any more
    r.ex.remove_node(r.esc)
    frozen_at = time.monotonic()
    wait_until(lambda: np.all(wire(r.emu) == 0.0), 10, None, "no pulses")
    assert not r.line.is_high(), "the guard's /OE line is still low: the watchdog stopped the outputs"
    assert r.feed.expires_at() - frozen_at <= r.feed.timeout_s  # within the circuit's timeout of the freeze
    # the launch resumes: the ESC disarms on the guard's view, feeding starts again only once released
    r.ex.add_node(r.esc)
    r.ex.add_node(r.guard)
    r.wait(lambda: not r.esc.armed, "disarmed after the freeze", poll=r.commanding, timeout=20.0)
    assert r.guard.assertions >= 1  # the guard saw that the watchdog had cut the outputs, and latched


def _thrust_seen(r, seen):
    """Command 1700 us, spin once, and record any thrust on the wire (a width off neutral, pulses on)."""
    r.commanding()
    w = wire(r.emu)
    seen.append(bool(np.any((w > 0.0) & (np.abs(w - 1500.0) > TICK_US))))


def test_a_launch_frozen_before_the_guard_heard_the_arm_latches_all_the_same(rig):
    """The launch freezes just after an arm, before an ESC beat saying "armed" has reached the guard (beats are
    40 ms apart): the guard's last beat says disarmed. The stall must latch all the same. Before, a stall with the
    ESC last heard disarmed was exempted: the guard fed the watchdog again after the resume and thrust came back
    with the ESC still armed (CI's test_frozen_launch; 51 of 300 freezes on a loaded 2-core machine)."""
    r = rig(guard=True, watchdog_s=0.33)
    r.wait(lambda: not r.guard.core.asserted and r.feed.rises >= 2, "guard released and feeding")
    heard, held = r.guard.core.on_esc, [True]
    r.guard.core.on_esc = lambda state, armed, ack: None if held[0] else heard(state, armed, ack)  # the beats are late
    r.arm_at_1700()
    assert not r.guard.core.esc_armed  # the guard's newest beat predates the arm
    # both peers' last beats reached the guard after its last tick: after the resume their ages read 0.2 s, the
    # timeout, so neither looks silent (an age grows by at most the timeout per tick gap)
    r.guard.esc_age.heard()
    r.guard.supervisor_age.heard()
    r.ex.remove_node(r.guard)  # the launch freezes
    r.ex.remove_node(r.esc)
    wait_until(lambda: np.all(wire(r.emu) == 0.0), 10, None, "the hardware watchdog cut the outputs")
    r.guard.tick()  # the guard's first decision after the resume, before any new ESC beat
    assert r.guard.core.asserted and "hardware watchdog cut the outputs" in r.guard.core.reason, r.guard.core.reason
    held[0] = False
    r.ex.add_node(r.esc)
    r.ex.add_node(r.guard)
    seen: list[bool] = []
    r.wait(lambda: not r.esc.armed, "disarmed after the freeze", poll=lambda: _thrust_seen(r, seen), timeout=20.0)
    assert not any(seen), "thrust came back after the freeze"


def test_a_stall_between_the_feed_check_and_its_edge_latches_before_thrust_returns(rig):
    """The guard (and with it the launch: one executor here) stalls after deciding to feed and before the rising
    edge, long enough for the hardware watchdog to run out; the late edge retriggers it. The guard must assert /OE
    in that same callback. Before, the edge counted as a normal feed taken after the stall: thrust came back with
    the ESC armed and nothing latched."""
    r = rig(guard=True, watchdog_s=0.33)
    r.wait(lambda: not r.guard.core.asserted and r.feed.rises >= 2, "guard released and feeding")
    r.arm_at_1700()
    check, stalled = r.guard.feeding, []

    def feeding(*args):
        ok = check(*args)
        if ok and not r.guard._feed_high and not stalled:  # the next edge rises: stall here, once
            stalled.append(True)
            wait_until(r.feed.expired, 5, None, "the hardware watchdog ran out during the stall")
        return ok
    r.guard.feeding = feeding
    r.wait(lambda: stalled, "the guard stalled once", poll=r.commanding)
    assert not r.feed.expired()  # the late edge went out and retriggered the watchdog ...
    assert r.line.is_high() and np.all(wire(r.emu) == 0.0)  # ... and the guard's /OE holds the outputs off
    assert r.guard.core.asserted and "hardware watchdog cut the outputs" in r.guard.core.reason, r.guard.core.reason
    seen: list[bool] = []
    r.wait(lambda: not r.esc.armed, "disarmed after the stall", poll=lambda: _thrust_seen(r, seen))
    assert not any(seen), "thrust came back after the stall"


def test_44_2_the_guard_does_not_feed_while_asserted(rig):
    import time

    r = rig(guard=True, watchdog_s=0.33)
    # issue 44.9: tick gaps count in full up to the timeout (test_watchdog.py, the starved guard)
    assert r.guard.esc_age.max_step_s == r.guard.supervisor_age.max_step_s == r.guard.timeout_s
    r.wait(lambda: not r.guard.core.asserted and r.feed.rises >= 2, "guard released and feeding")
    r.arm_at_1700()
    r.beats.supervisor = "depth 3.00 m beyond supervisor.max_depth_m 1.65"
    r.wait(lambda: r.guard.core.asserted, "guard asserted on the breach", poll=r.commanding)
    rises = r.feed.rises
    r.wait(lambda: r.feed.expired(), "watchdog ran out while asserted", poll=r.commanding)
    assert r.feed.rises <= rises + 1 and not r.guard.feeding()
    # cleared and disarmed: released and fed again, and the long pause before is not taken for a stall of its own
    r.beats.supervisor = ""
    r.wait(lambda: not r.guard.core.asserted, "released")
    r.guard._last_rise = time.monotonic() - 1.0  # its last edge went out before the assertion, long ago
    r.guard.tick()  # a tick before the first feed edge after the release
    assert not r.guard.core.asserted, r.guard.core.reason
    r.wait(lambda: r.feed.rises >= rises + 3, "fed again")
    # fed on: no assertion but a real stall. This process runs the guard, and a loaded machine can starve it past
    # the watchdog's 0.33 s (a fresh clone's suite: feed gaps of 0.52 s): the guard is right to latch those. Every
    # stall it reports must show on the feed line itself, a gap between edges (or since the last) of the timeout.
    rises_at, stalls = [r.feed.last_rise], []
    set_high, ran_out = r.feed.set_high, r.guard.watchdog_ran_out

    def feed_line(high):
        before = r.feed.rises
        set_high(high)
        if r.feed.rises > before:
            rises_at.append(r.feed.last_rise)

    def stall_seen():
        why = ran_out()
        if why:
            stalls.append((time.monotonic(), list(rises_at)))
        return why

    r.feed.set_high, r.guard.watchdog_ran_out = feed_line, stall_seen
    assertions = r.guard.assertions
    r.wait(lambda: len(rises_at) >= 7 and not r.guard.core.asserted, "fed for 0.5 s")
    assert r.guard.assertions - assertions == len(stalls), r.guard.core.reason  # no other cause
    for t, edges in stalls:
        gaps = np.diff([*edges[-2:], t])
        assert gaps.max() >= 0.9 * r.feed.timeout_s, (t, edges[-2:])  # the line was quiet that long: a real stall


_HOLDER = """
import sys, time
from hindrax_common.transport.shared_emulation import SharedGpioLine
line = SharedGpioLine(sys.argv[1], "oe", initial_high=False)  # outputs enabled
print("driving", flush=True)
time.sleep(60)
"""


def test_f2_a_dead_guard_process_leaves_oe_high_through_the_pull_up(tmp_path):
    """The kernel frees a dead process's line request; with the /OE pull-up the outputs go off."""
    line = EmulatedGpioLine(pull_high=True)
    server = EmulationServer(str(tmp_path / "emu.sock"), lines={"oe": line})
    proc = subprocess.Popen([sys.executable, "-c", _HOLDER, server.path], env=child_env(), stdout=subprocess.PIPE,
                            text=True)
    try:
        assert proc.stdout.readline().strip() == "driving"
        assert not line.is_high() and line.driven
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(10)
        wait_until(lambda: line.is_high() and not line.driven, 5, message="line released to its pull-up")
    finally:
        if proc.poll() is None:
            proc.kill()
        server.close()
    # a client that releases explicitly (clean shutdown) does the same
    server = EmulationServer(str(tmp_path / "emu2.sock"), lines={"oe": line})
    client = SharedGpioLine(server.path, "oe", initial_high=False)
    assert not line.is_high()
    client.release()
    wait_until(lambda: line.is_high(), 5, message="released")
    server.close()


# ------------------------------------------------------------------ finding 3: I2C outage while armed
def test_f3_i2c_outage_reports_unknown_and_thrust_needs_a_new_arm_request(rig):
    r = rig(overrides={"esc.readback_interval_s": 0.1})
    r.arm_at_1700()
    r.bus.disconnected = True  # the PCA9685 stops acknowledging; 1700 us stays on the wire
    r.wait(lambda: r.states and r.states[-1].output_state == ThrusterPwm.OUTPUT_UNKNOWN, "state unknown",
           poll=r.commanding)
    last = r.states[-1]
    assert not last.armed and all(math.isnan(w) for w in last.pulse_width_us)  # never "neutral", never 1700
    assert wire(r.emu)[0] > 1690  # what is really on the wire (no /OE in this rig is held by a guard)
    res = r.set_armed(False)
    assert not res.success and "NOT confirmed" in res.message
    assert not r.set_armed(True).success
    r.bus.disconnected = False  # after 2 s in the finding; here as soon as the node has retried
    r.wait(lambda: r.states[-1].output_state == ThrusterPwm.OUTPUT_NEUTRAL, "chip re-initialised",
           poll=r.commanding)
    assert np.allclose(wire(r.emu), 1500.0, atol=TICK_US)
    for _ in range(30):  # the controller keeps commanding 1600 us: nothing without a new arm request
        r.command(1600.0)
        r.spin()
    assert np.allclose(wire(r.emu), 1500.0, atol=TICK_US) and not r.esc.armed
    assert r.esc.link.unknown_entries >= 1


def test_esc_starts_without_its_bus_and_picks_it_up(monkeypatch):
    """Issue 24 item 2: no /dev/i2c-N at start-up; the node runs, reports, retries, and uses the bus once it
    appears, never armed by itself."""
    import hindrax_drivers.pca9685.node as esc_module

    emu = Pca9685Emulator()
    state = {"present": False, "opens": 0}

    def fake_open(bus_number):
        state["opens"] += 1
        if not state["present"]:
            raise OSError(2, f"cannot open I2C bus {bus_number} (/dev/i2c-{bus_number}): No such file or directory")
        return EmulatedI2CBus({0x40: emu})

    monkeypatch.setattr(esc_module, "open_smbus", fake_open)
    monkeypatch.delenv("HINDRAX_EMULATION_SOCKET", raising=False)
    with ros_context() as ctx:
        node = EscNode(context=ctx, parameter_overrides=config_parameters(OVER))
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(node)
        spin = lambda: ex.spin_once(timeout_sec=0.01)  # noqa: E731
        wait_until(lambda: state["opens"] >= 3, 10, spin, "retries with backoff")
        assert node.output_state == ThrusterPwm.OUTPUT_UNKNOWN
        status = node.diag.status()
        assert status.level == DiagnosticStatus.ERROR and "no I2C bus" in status.message
        assert "/dev/i2c-1" in node.arm_refusal()
        state["present"] = True
        wait_until(lambda: node.output_state == ThrusterPwm.OUTPUT_NEUTRAL, 10, spin, "bus picked up")
        assert np.allclose(wire(emu), 1500.0, atol=TICK_US) and not node.armed
        ex.shutdown()
        node.destroy_node()


# ------------------------------------------------------------------ finding 7: /clock steps back
def test_f7_clock_step_back_brown_out_detected_on_the_steady_clock(rig):
    r = rig(sim_time=True, overrides={"esc.readback_interval_s": 0.5})
    r.arm_at_1700()
    reinits = r.esc.link.chip_reinits
    r.ns -= 100_000_000_000  # /clock steps back 100 s
    r.commanding()
    r.emu.reset()  # brown-out: asleep, every output off
    # before: the read-back waited for ROS time to catch up (4 s in the finding, 100 s here)
    r.wait(lambda: r.esc.link.chip_reinits > reinits, "brown-out detected", timeout=3.0, poll=r.commanding)
    assert not r.esc.armed and r.esc.clock_monitor.steps_back >= 1
    assert r.esc.diag.counts().get("clock_step", 0) >= 1
    r.wait(lambda: r.states[-1].output_state == ThrusterPwm.OUTPUT_NEUTRAL and not r.states[-1].armed,
           "reported neutral, disarmed", poll=r.commanding)


def test_f7_clock_step_monitor_and_alive_age():
    t = {"ros": 1000.0, "steady": 0.0}
    mon = ClockStepMonitor(lambda: t["ros"], clock=lambda: t["steady"])
    t["ros"] += 0.02
    t["steady"] += 0.02
    assert mon.check() == 0.0
    t["ros"] -= 100.0
    assert mon.check() == pytest.approx(-100.0) and mon.steps_back == 1
    t["steady"] += 5.0
    mon.check()
    assert mon.stalled_for_s() == pytest.approx(5.0)
    age = AliveAge(0.04, clock=lambda: t["steady"])
    age.heard()
    t["steady"] += 3.0  # this process stalled: counts two periods at most
    assert age.tick() == pytest.approx(0.04)
    for _ in range(10):
        t["steady"] += 0.02
        age.tick()
    assert age.age_s == pytest.approx(0.24) and not age.fresh(0.2)


def test_esc_process_without_its_bus_keeps_running_and_reports():
    """Issue 24 item 2, as the vehicle starts it: ``python -m hindrax_drivers.pca9685.node`` with no /dev/i2c-N
    stays up, says why on /diagnostics, reports the output state unknown, refuses to arm, exits 0 on SIGINT."""
    from diagnostic_msgs.msg import DiagnosticArray

    from hindrax_common.config import default_config_path

    assert not os.path.exists("/dev/i2c-31")
    env = child_env()
    env.pop("HINDRAX_EMULATION_SOCKET", None)
    with child_process([sys.executable, "-m", "hindrax_drivers.pca9685.node", "--ros-args", "--params-file",
                        str(default_config_path()), "-p", "esc.i2c_bus:=31", "-p",
                        "esc.oscillator_calibrated:=true"], env=env,
                       stdout=subprocess.PIPE, stderr=subprocess.STDOUT) as proc:
        with ros_context() as ctx:
            probe = rclpy.create_node("probe", context=ctx)
            ex = SingleThreadedExecutor(context=ctx)
            ex.add_node(probe)
            diags, states = [], []
            probe.create_subscription(DiagnosticArray, "/diagnostics", diags.append, 10)
            probe.create_subscription(ThrusterPwm, "thrusters/pulse_width", states.append, 10)
            arm = probe.create_client(SetArmed, "esc/set_armed")
            spin = lambda: ex.spin_once(timeout_sec=0.05)  # noqa: E731
            wait_until(lambda: any("no I2C bus" in s.message and "/dev/i2c-31" in s.message
                                   and s.level == DiagnosticStatus.ERROR for a in diags for s in a.status)
                       and states, 20, spin, "bus error in diagnostics and the output state")
            assert states[-1].output_state == ThrusterPwm.OUTPUT_UNKNOWN and not states[-1].armed
            wait_until(arm.service_is_ready, 10, spin, "esc/set_armed")
            fut = arm.call_async(SetArmed.Request(arm=True))
            wait_until(fut.done, 10, spin, "arm answer")
            assert not fut.result().success and "/dev/i2c-31" in fut.result().message
            assert proc.poll() is None
            ex.shutdown()
            probe.destroy_node()
        assert interrupt(proc, 10) == 0


def test_a_hung_esc_bus_turns_its_heartbeat_to_error_and_the_guard_asserts_oe(rig):
    """The ESC's chip I/O runs on its own thread: a bus call that does not return (a hung adapter, an emulation
    server that stopped answering) leaves the heartbeat running, and within BUS_CALL_TIMEOUT_S (0.15 s) it says
    ERROR, output state unknown; the guard then drives /OE high (for that, not for a silent ESC). When the bus
    answers again the chip is reconfigured at neutral and the ESC stays disarmed."""
    import threading
    import time

    from hindrax_drivers.pca9685.worker import BUS_CALL_TIMEOUT_S

    r = rig(guard=True)
    r.wait(lambda: not r.guard.core.asserted and not r.line.is_high(), "guard released /OE at neutral")
    r.arm_at_1700()
    release = threading.Event()
    write = r.bus.write_i2c_block_data

    def hung(address, register, data):
        release.wait(30)
        return write(address, register, data)

    r.bus.write_i2c_block_data = hung
    t_hang = time.monotonic()
    r.command(1750.0)  # its write hangs
    r.wait(lambda: r.esc.output_state == OUTPUT_UNKNOWN, "ESC output state unknown")
    assert time.monotonic() - t_hang >= BUS_CALL_TIMEOUT_S and not r.esc.armed
    assert "not returned" in r.esc.core.reason
    r.wait(lambda: r.line.is_high(), "/OE asserted")
    assert r.guard.core.reason.startswith("ESC output state unknown"), r.guard.core.reason
    r.bus.write_i2c_block_data = write
    release.set()
    r.wait(lambda: r.esc.output_state == OUTPUT_NEUTRAL, "neutral confirmed once the bus answers")
    r.wait(lambda: not r.line.is_high(), "/OE released at neutral, disarmed")
    assert np.allclose(wire(r.emu), 1500.0, atol=TICK_US) and not r.esc.armed
