"""ESC node at the register "wire": the PCA9685 emulator decodes what each channel actually outputs."""
import contextlib
import itertools
import math
import threading
import time

import numpy as np
import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from diagnostic_msgs.msg import DiagnosticStatus
from std_msgs.msg import Float64

from hindrax_drivers.pca9685.emulator import Pca9685Emulator
from hindrax_drivers.pca9685.node import EscNode, EscOutput
from hindrax_common.testing import AllocationStandIn, SafetyHeartbeats, config_parameters, ros_context, wait_until
from hindrax_common.transport.emulated_i2c import EmulatedI2CBus
from hindrax_msgs.msg import Heartbeat, ThrusterPwm
from hindrax_msgs.srv import SetArmed

pytestmark = pytest.mark.ros
TICK_US = 1.24  # one PCA9685 count at 200 Hz (prescale 30) and 25 MHz, docs/devices.md §5.1
PERIOD_S = 1 / 50.0  # esc.output_rate_hz
#: these tests are not about the safety heartbeats (test_safety_paths.py is): the stand-in's heartbeats, published in
#: this same busy process, get a wide timeout so that a loaded machine cannot disarm the ESC mid-test
HEARTBEAT_TIMEOUT_S = 2.0
#: neutral of the fixture's channels: 1500 us plus each thruster's trim (t3: +10 us)
NEUTRAL = np.array([1500.0, 1500.0, 1510.0, 1500.0, 1500.0, 1500.0, 1500.0, 1500.0])


def wide_heartbeat_timeout(seconds=HEARTBEAT_TIMEOUT_S):
    """The ESC's node parameter ``heartbeat_timeout_s`` as a parameter override."""
    from rclpy.parameter import Parameter

    return [Parameter("heartbeat_timeout_s", value=seconds)]


def wire(emu, channels=range(8)):
    return np.array([emu.pulse_width_us(c) for c in channels])


@pytest.fixture
def esc():
    with ros_context() as ctx:
        emu = Pca9685Emulator()
        bus = EmulatedI2CBus({0x40: emu})
        params = config_parameters({"esc.arming_time_s": 0.3, "esc.watchdog_timeout_s": 0.2,
                                    "esc.oscillator_calibrated": True,
                                    "thrusters.t2.reversed": True, "thrusters.t3.trim_us": 10.0})
        node = EscNode(bus=bus, context=ctx, parameter_overrides=params + wide_heartbeat_timeout())
        probe = rclpy.create_node("probe", context=ctx)
        _beats = SafetyHeartbeats(probe)  # supervisor and output guard healthy
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(node)
        ex.add_node(probe)
        allocation = AllocationStandIn(ctx)
        pub = allocation.pub
        lights = probe.create_publisher(Float64, "lights/brightness", 10)
        written = []
        probe.create_subscription(ThrusterPwm, "thrusters/pulse_width", written.append, 10)
        arm = probe.create_client(SetArmed, "esc/set_armed")
        spin = lambda: ex.spin_once(timeout_sec=0.01)  # noqa: E731

        def set_armed(value):
            fut = arm.call_async(SetArmed.Request(arm=value))
            wait_until(fut.done, 5, spin, "SetArmed answer")
            return fut.result()

        def command(widths):
            m = ThrusterPwm(pulse_width_us=[float(w) for w in widths], armed=True)
            m.header.stamp = probe.get_clock().now().to_msg()
            pub.publish(m)

        wait_until(lambda: pub.get_subscription_count() > 0 and arm.service_is_ready() and not node.heartbeat_refusal(),
                   10, spin, "ESC node ready")
        yield dict(node=node, emu=emu, bus=bus, spin=spin, set_armed=set_armed, command=command, written=written,
                   lights=lights, probe=probe)
        ex.shutdown()
        allocation.destroy()
        probe.destroy_node()
        node.destroy_node()


def stream(e, widths, until, timeout=5.0):
    """Keep commanding ``widths`` until ``until()`` holds (a controller streaming commands)."""
    def poll():
        e["command"](widths)
        e["spin"]()
    return wait_until(until, timeout, poll, "commanded output")


def test_neutral_from_start_and_commands_ignored_until_armed(esc):
    emu = esc["emu"]
    assert np.allclose(wire(emu), NEUTRAL, atol=TICK_US)  # before any command
    assert emu.pulse_width_us(8) == pytest.approx(1100.0, abs=TICK_US)  # lights off
    esc["command"]([1700.0] * 8)
    wait_until(lambda: len(esc["written"]) >= 3, 5, esc["spin"], "output ticks")
    assert np.allclose(wire(emu), NEUTRAL, atol=TICK_US)
    assert not esc["written"][-1].armed


def test_arming_needs_time_at_neutral_then_commands_reach_the_wire(esc):
    emu, node = esc["emu"], esc["node"]
    if node.arming_remaining_s() > 0.05:
        res = esc["set_armed"](True)
        assert not res.success and "at neutral" in res.message
    wait_until(lambda: node.arming_remaining_s() == 0.0, 5, esc["spin"], "arming time")
    assert esc["set_armed"](True).success
    cmd = np.array([1700.0, 1700.0, 1300.0, 1900.0, 1100.0, 1500.0, 1600.0, 1400.0])
    # expected: t2 reversed about 1500, t3 trimmed +10 us
    expected = np.array([1700.0, 1300.0, 1310.0, 1900.0, 1100.0, 1500.0, 1600.0, 1400.0])
    stream(esc, cmd, lambda: np.allclose(wire(emu), expected, atol=TICK_US))
    # the node reports what it wrote, decoded from the register counts
    wait_until(lambda: esc["written"][-1].armed and np.allclose(esc["written"][-1].pulse_width_us, wire(emu),
                                                                 atol=1e-6), 5, esc["spin"], "written report")


def test_output_state_is_latched_for_late_subscribers_and_follows_arming(esc):
    """esc/output_state (esc_state.py): a subscriber that joins after the ESC started gets the current state at once
    (transient local), then one message per change of armed or output state and one a second without a change,
    not one per output tick."""
    from hindrax_common.node_support.esc_state import ESC_STATE_TOPIC, esc_state_qos, read_esc_state

    node, probe, spin = esc["node"], esc["probe"], esc["spin"]
    wait_until(lambda: node.output_state == ThrusterPwm.OUTPUT_NEUTRAL, 5, spin, "neutral confirmed")
    got = []
    probe.create_subscription(DiagnosticStatus, ESC_STATE_TOPIC, lambda m: got.append((time.monotonic(), m)),
                              esc_state_qos())
    wait_until(lambda: got, 10, spin, "the latched state")
    assert read_esc_state(got[0][1]) == (ThrusterPwm.OUTPUT_NEUTRAL, False) and got[0][1].message == "neutral"
    arm(esc)  # armed, then commanding
    wait_until(lambda: (ThrusterPwm.OUTPUT_COMMANDING, True) in [read_esc_state(m) for _, m in got], 5, spin,
               "armed, commanding")
    esc["set_armed"](False)
    wait_until(lambda: read_esc_state(got[-1][1]) == (ThrusterPwm.OUTPUT_NEUTRAL, False), 5, spin, "disarmed state")
    n, t0 = len(got), time.monotonic()
    wait_until(lambda: time.monotonic() > t0 + 2.5, 10, spin, "2.5 s without a change")
    # 1 Hz repeats: 2 or 3 in 2.5 s (the 50 Hz output ticks would have given about 125; a loaded machine, one more
    # or one less)
    assert 1 <= len(got) - n <= 4, [round(t - t0, 2) for t, _ in got[n:]]
    assert all(read_esc_state(m) == (ThrusterPwm.OUTPUT_NEUTRAL, False) for _, m in got[n:])


def arm(esc):
    wait_until(lambda: esc["node"].arming_remaining_s() == 0.0, 5, esc["spin"], "arming time")
    assert esc["set_armed"](True).success
    stream(esc, [1650.0] * 8, lambda: wire(esc["emu"])[0] > 1600)


def test_watchdog_returns_to_neutral_within_one_period():
    """Deterministic in simulated time: the test drives /clock, so executor load cannot blur the bound."""
    from rclpy.parameter import Parameter
    from rosgraph_msgs.msg import Clock

    with ros_context() as ctx:
        emu = Pca9685Emulator()
        params = config_parameters({"esc.arming_time_s": 0.0, "esc.watchdog_timeout_s": 0.2,
                                    "esc.oscillator_calibrated": True})
        # the ROS-time watchdog is under test; the wall-clock one (test_fault3_...) must not pre-empt it when this
        # loop's simulated 5 ms steps take longer than 5 ms of wall time on a loaded machine
        node = EscNode(bus=EmulatedI2CBus({0x40: emu}), context=ctx,
                       parameter_overrides=params + wide_heartbeat_timeout() + [
                           Parameter("use_sim_time", value=True), Parameter("steady_watchdog_timeout_s", value=5.0)])
        probe = rclpy.create_node("probe", context=ctx)
        _beats = SafetyHeartbeats(probe)  # supervisor and output guard healthy
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(node)
        ex.add_node(probe)
        clock_pub = probe.create_publisher(Clock, "/clock", 10)
        allocation = AllocationStandIn(ctx)
        pub = allocation.pub
        arm = probe.create_client(SetArmed, "esc/set_armed")
        now = {"ns": 1_000_000_000}

        def advance(dt_s=0.005):
            now["ns"] += int(dt_s * 1e9)
            m = Clock()
            m.clock.sec, m.clock.nanosec = divmod(now["ns"], 1_000_000_000)
            clock_pub.publish(m)
            ex.spin_once(timeout_sec=0.01)
            ex.spin_once(timeout_sec=0.0)

        wait_until(lambda: clock_pub.get_subscription_count() > 0 and pub.get_subscription_count() > 0
                   and arm.service_is_ready() and not node.heartbeat_refusal()
                   and node.arming_remaining_s() == 0.0, 10, advance, "ESC node ready")
        fut = arm.call_async(SetArmed.Request(arm=True))
        wait_until(fut.done, 5, advance, "armed")
        assert fut.result().success

        def command_and_advance():
            m = ThrusterPwm(pulse_width_us=[1650.0] * 8, armed=True)
            pub.publish(m)
            advance()
        wait_until(lambda: wire(emu)[0] > 1600, 10, command_and_advance, "commanded output")
        wait_until(lambda: np.allclose(wire(emu), 1500.0, atol=TICK_US), 10, advance, "watchdog neutral")
        # the node stamps each command on arrival with its (simulated) clock; the last one started the watchdog, and the
        # output tick that found it too old stamped the trip. The write itself is the bus worker's and reaches the
        # emulator some wall-clock time later, while this loop goes on advancing /clock: the simulated time at which
        # the wire is seen neutral measures this loop's load, not the watchdog.
        elapsed_s = node.core.watchdog_trip_t_s - node.core.command_t_s
        assert 0.2 <= elapsed_s <= 0.2 + PERIOD_S + 0.005  # timeout + at most one output period (+1 clock step)
        assert node.watchdog_trips == 1
        ex.shutdown()
        allocation.destroy()
        probe.destroy_node()
        node.destroy_node()


def test_disarm_and_fault_and_shutdown_go_neutral(esc):
    arm(esc)
    emu, node = esc["emu"], esc["node"]
    assert esc["set_armed"](False).success
    node.settle()  # the neutral the service posted, before anything else reaches the chip
    assert np.allclose(wire(emu), NEUTRAL, atol=TICK_US)
    arm(esc)
    stream(esc, [math.nan] * 8, lambda: node.diag.counts().get("command_rejected", 0) > 0)
    node.settle()
    assert np.allclose(wire(emu), NEUTRAL, atol=TICK_US)  # a NaN command is a fault: neutral
    stream(esc, [1650.0] * 8, lambda: wire(emu)[0] > 1600)
    node.close()
    assert np.allclose(wire(emu), NEUTRAL, atol=TICK_US)
    node.settle()  # a node that keeps running after close() (an in-process bench) still takes the chip's results
    assert node.output_state == ThrusterPwm.OUTPUT_NEUTRAL and not node.armed


@pytest.mark.parametrize("widths, armed, why", [
    ([0.0] * 8, True, "outside the ESC's range"),  # a default-constructed ThrusterPwm: not full reverse
    ([3000.0] * 8, True, "outside the ESC's range"),  # not full forward
    ([1700.0] * 7 + [math.inf], True, "non-finite"),
    ([1700.0] * 8, False, "armed=false"),  # its sender does not mean thrust
])
def test_a_faulty_command_gives_neutral_and_a_reason_never_a_clamp(esc, widths, armed, why):
    """Issue 44 finding 3: 0.0 us gave 1100 us (full reverse) on every channel, 3000 us gave 1900 us, a command with
    armed false gave 1700 us. Each is a fault: neutral on every channel, the reason on /diagnostics and the
    heartbeat, counted; the next valid command drives again."""
    arm(esc)
    node, emu = esc["node"], esc["emu"]
    stream(esc, [1700.0] * 8, lambda: wire(emu)[0] > 1690)
    msg = ThrusterPwm(pulse_width_us=[float(w) for w in widths], armed=armed)
    node.on_command(msg)
    node.settle()
    assert np.allclose(wire(emu), NEUTRAL, atol=TICK_US)
    assert node.armed and node.diag.counts()["command_rejected"] == 1
    assert why in node.core.reason and why in node.diag.status().message
    assert node.diag.status().level == (DiagnosticStatus.OK if not armed else DiagnosticStatus.WARN)
    node.tick()  # the output tick keeps neutral: the faulty command is not held
    node.settle()
    assert np.allclose(wire(emu), NEUTRAL, atol=TICK_US)
    stream(esc, [1650.0] * 8, lambda: wire(emu)[0] > 1640)


def test_only_the_allocation_may_command_a_second_publisher_disarms_and_is_refused(esc):
    """Issue 43 finding 3: a plain rclpy script publishing thrusters/command_pulse_width put 1900 us on the wire for
    3.6 s. The ESC takes commands only while the graph shows one publisher on the topic, the node
    ``thrust_allocation``: another one (here a node named ``probe``) disarms it at its next tick, its commands never
    reach the wire, arming is refused naming it, and once it is gone the ESC can be armed again."""
    node, emu, probe = esc["node"], esc["emu"], esc["probe"]
    arm(esc)
    stream(esc, [1700.0] * 8, lambda: wire(emu)[0] > 1690)
    rogue = probe.create_publisher(ThrusterPwm, "thrusters/command_pulse_width", 10)

    def rogue_command():
        rogue.publish(ThrusterPwm(pulse_width_us=[1900.0] * 8, armed=True))
        esc["spin"]()
    wait_until(lambda: not node.armed, 10, rogue_command, "disarmed on the second publisher")
    node.settle()
    for _ in range(20):
        rogue_command()
        assert np.allclose(wire(emu), NEUTRAL, atol=TICK_US)
    res = esc["set_armed"](True)
    assert not res.success and "published by 'probe'" in res.message
    assert node.diag.counts()["command_source_fault"] >= 1
    probe.destroy_publisher(rogue)
    wait_until(lambda: not node.core.command_source, 10, esc["spin"], "the second publisher gone")
    arm(esc)


def test_a_command_publisher_not_named_yet_holds_neutral_but_does_not_disarm(esc, monkeypatch):
    """Under load, discovery shows a new publisher as _NODE_NAME_UNKNOWN_ for a while: it disarmed the vehicle.
    Now its commands are held at neutral (it may be a foreign one) while the ESC stays armed; once named the
    allocation commands again; once named as a stranger it disarms. (The graph is stood in: discovery's timing
    cannot be forced.)"""
    from hindrax_common.node_support import liveness as graph_module

    node, emu = esc["node"], esc["emu"]
    arm(esc)
    stream(esc, [1700.0] * 8, lambda: wire(emu)[0] > 1690)
    graph = graph_module.publisher_node_names
    shown = {"extra": "_NODE_NAME_UNKNOWN_"}

    def publishers(of, topic):
        real = graph(of, topic)
        if topic != "thrusters/command_pulse_width" or not shown["extra"]:
            return real
        return real + [shown["extra"]]
    monkeypatch.setattr(graph_module, "publisher_node_names", publishers)
    stream(esc, [1700.0] * 8, lambda: np.allclose(wire(emu), NEUTRAL, atol=TICK_US))
    assert node.armed and node.core.command_unnamed and not node.core.command_source
    assert node.diag.counts()["command_source_unnamed"] == 1
    shown["extra"] = ""  # named: it was the allocation's own endpoint
    stream(esc, [1700.0] * 8, lambda: wire(emu)[0] > 1690)
    assert node.armed and node.diag.counts().get("command_source_fault", 0) == 0
    shown["extra"] = "rogue"
    wait_until(lambda: not node.armed, 10, lambda: (esc["command"]([1700.0] * 8), esc["spin"]()),
               "disarmed on a named stranger")
    node.settle()
    assert np.allclose(wire(emu), NEUTRAL, atol=TICK_US) and "'rogue'" in node.core.command_source


def test_a_forged_supervisor_heartbeat_disarms_and_refuses_arming(esc):
    """Issue 43 finding 2 at the ESC: a 10-line script publishing level-0 supervisor/heartbeat was taken as the
    supervisor's. The ESC takes the heartbeats through their identity check (one live publisher, node
    ``supervisor``, boot_id and seq): a forger beside the real one disarms it and arming is refused with the reason;
    once the forger is gone the ESC arms again."""
    from hindrax_common.node_support.liveness import HeartbeatPublisher

    node, emu, probe = esc["node"], esc["emu"], esc["probe"]
    arm(esc)
    stream(esc, [1700.0] * 8, lambda: wire(emu)[0] > 1690)
    forger = rclpy.create_node("forger", context=probe.context)
    beat = HeartbeatPublisher(forger, "supervisor")

    def forge():
        beat.publish(True, "ok")
        esc["command"]([1700.0] * 8)
        esc["spin"]()
    wait_until(lambda: not node.armed, 10, forge, "disarmed on the forged heartbeat")
    node.settle()
    assert np.allclose(wire(emu), NEUTRAL, atol=TICK_US)
    res = esc["set_armed"](True)
    assert not res.success and "supervisor heartbeat not trusted" in res.message and "'forger'" in res.message
    forger.destroy_node()
    wait_until(lambda: node.heartbeat_refusal() == "", 10, esc["spin"], "the forger gone")
    arm(esc)


def test_a_late_safety_tick_beats_at_once(esc):
    """A beat on every second safety tick only made a stalled ESC's beat gap its tick gap plus up to
    two periods (a 110 ms tick gap, a 165 ms beat gap in the busy-neighbours bench at nice -5; the
    guard's timeout is 200 ms): a tick two periods after the last beat sends one whatever its
    parity, and the beats stay at every second tick."""
    node = esc["node"]
    node._heartbeat_tick = 0  # the next tick is one without a beat by its parity
    node._beat_s = time.monotonic() - 2.0 * node.period_s
    seq = node.heartbeat.seq
    for expected in (seq + 1, seq + 2, seq + 2):
        node.steady_check()
        assert node.heartbeat.seq == expected


def test_lights_channel(esc):
    msg = Float64(data=0.5)
    esc["lights"].publish(msg)
    wait_until(lambda: abs(esc["emu"].pulse_width_us(8) - 1500.0) < TICK_US, 5, esc["spin"], "lights at half")


def test_i2c_errors_are_retried_and_reported(esc):
    arm(esc)
    esc["bus"].set_fault_rate(0.3)
    widths = itertools.cycle([1640.0, 1660.0])  # a new command each time: each one is written at once
    emu = esc["emu"]

    def poll():
        esc["command"]([next(widths)] * 8)
        esc["spin"]()
    # the wire carries the commands (not neutral) while the bus fails 30 % of the transactions
    wait_until(lambda: esc["node"].device.stats.retries > 3 and min(abs(wire(emu)[0] - 1640.0),
                                                                   abs(wire(emu)[0] - 1660.0)) < TICK_US,
               10, poll, "commands written under bus faults")
    esc["bus"].set_fault_rate(0.0)
    assert esc["set_armed"](False).success
    esc["node"].settle()
    assert np.allclose(wire(emu), NEUTRAL, atol=TICK_US)


def test_sigterm_path_writes_neutral():
    """run_node (the process entry point) closes the node on external shutdown: neutral on the wire."""
    from hindrax_common.node_support.node_common import run_node

    emu = Pca9685Emulator()
    bus = EmulatedI2CBus({0x40: emu})
    holder = {}

    def factory():
        node = EscNode(bus=bus, parameter_overrides=config_parameters({"esc.arming_time_s": 0.0,
                                                                       "esc.oscillator_calibrated": True}))
        node._peer_verdicts = lambda: ("", "")  # this test is about the shutdown path only

        def drive():  # in the executor, through the node's inputs: arm once allowed, then 1700 us every 20 ms
            if node.armed:
                node.on_command(ThrusterPwm(pulse_width_us=[1700.0] * 8, armed=True))
            elif not node.arm_refusal():
                node.on_set_armed(SetArmed.Request(arm=True), SetArmed.Response())

        node.create_timer(0.02, drive)
        holder["node"] = node
        return node

    raised = []  # an exception in any thread (the chip worker's raw publish once failed after the shutdown)
    hook, threading.excepthook = threading.excepthook, raised.append
    try:
        t = threading.Thread(target=lambda: holder.setdefault("rc", run_node(factory, [])))
        t.start()
        wait_until(lambda: "node" in holder and emu.pulse_width_us(0) > 1650, 10, message="commanding 1700 us")
        rclpy.shutdown()  # what the SIGINT/SIGTERM handler does
        t.join(10)
    finally:
        threading.excepthook = hook
    assert not t.is_alive() and holder["rc"] == 0
    assert np.allclose(wire(emu), 1500.0, atol=TICK_US)
    assert not holder["node"].chip_io._thread.is_alive()  # joined before the node was destroyed
    assert not raised, [(a.thread.name, a.exc_value) for a in raised]


def test_output_logic_slew_and_errors():
    out = EscOutput(range(2), [False, True], [0.0, 0.0], 1100, 1500, 1900, slew_rate_us_per_s=1000.0)
    assert out.target([1900, 1900], 0.1).tolist() == [1600.0, 1400.0]  # 100 us per 0.1 s
    with pytest.raises(ValueError):
        out.target([1500], 0.1)
    with pytest.raises(ValueError):
        out.target([1500, math.inf], 0.1)



def test_output_logic_computes_a_command_once_and_never_caches_a_slew_step():
    """Without slew limit a tick between two commands reuses the command's widths; neutral in between, a new command
    or a slew limit compute them anew (each assertion fails if the widths came from the wrong cache)."""
    out = EscOutput(range(2), [False, True], [0.0, 10.0], 1100, 1500, 1900)
    cmd = np.array([1600.0, 1600.0])
    assert out.target(cmd, 0.02).tolist() == [1600.0, 1410.0]  # t2 mirrored about 1500, then its +10 us trim
    assert out.target(cmd, 0.02).tolist() == [1600.0, 1410.0]
    assert out.neutral().tolist() == [1500.0, 1510.0]
    assert out.target(cmd, 0.02).tolist() == [1600.0, 1410.0]  # after neutral: computed again, not neutral
    assert out.target(np.array([1700.0, 1500.0]), 0.02).tolist() == [1700.0, 1510.0]
    slewed = EscOutput(range(1), [False], [0.0], 1100, 1500, 1900, slew_rate_us_per_s=1000.0)
    cmd = np.array([1900.0])
    assert slewed.target(cmd, 0.1).tolist() == [1600.0]
    assert slewed.target(cmd, 0.1).tolist() == [1700.0]  # the same command keeps approaching its target


def block_writes(bus) -> list[int]:
    """The start register of every block write on ``bus`` from now on (the list fills as the node writes; the
    writes still reach the emulated chip)."""
    registers: list[int] = []
    write = bus.write_i2c_block_data

    def counted(address, register, data):
        registers.append(register)
        return write(address, register, data)

    bus.write_i2c_block_data = counted
    return registers


def test_a_thrust_command_writes_only_the_blocks_that_changed(esc):
    """The lights channel (8) is a block of its own: a thrust command that leaves it alone is one block write, not
    two; a change of the lights writes its block; a neutral for safety writes every block whatever is believed to be
    on the chip."""
    arm(esc)
    node, emu = esc["node"], esc["emu"]
    registers = block_writes(esc["bus"])
    node.on_command(ThrusterPwm(pulse_width_us=[1720.0] * 8, armed=True))
    node.settle()
    node.on_command(ThrusterPwm(pulse_width_us=[1580.0] * 8, armed=True))
    node.settle()
    assert registers == [0x06, 0x06]  # LED0_ON_L: the thrusters' block only
    assert wire(emu)[0] == pytest.approx(1580.0, abs=TICK_US)
    assert emu.pulse_width_us(8) == pytest.approx(node.lights_off_us, abs=TICK_US)
    registers.clear()
    node.on_lights(Float64(data=0.5))
    node.on_command(ThrusterPwm(pulse_width_us=[1580.0] * 8, armed=True))
    node.settle()
    assert registers == [0x06 + 4 * 8]  # LED8: the lights' block only
    assert emu.pulse_width_us(8) == pytest.approx(1500.0, abs=TICK_US)
    registers.clear()
    node._safe_neutral("test")
    node.settle()
    assert registers == [0x06, 0x06 + 4 * 8]
    assert np.allclose(wire(emu), NEUTRAL, atol=TICK_US)

# ------------------------------------------------------------------ issue 19, faults 1-5 (each failed before the fix)
class _SampledBus:
    """Delegates to an EmulatedI2CBus and records, after every SMBus call, what each channel puts on the wire."""

    def __init__(self, bus, emu, channels=range(9)):
        self._bus, self._emu, self._channels = bus, emu, list(channels)
        self.samples: list[np.ndarray] = []

    def __getattr__(self, name):
        attr = getattr(self._bus, name)
        if not callable(attr):
            return attr

        def call(*args, **kwargs):
            try:
                return attr(*args, **kwargs)
            finally:
                self.samples.append(wire(self._emu, self._channels))
        return call


def _direct_beats(node):
    """For tests that feed heartbeats by calling the handlers: no publisher in the graph to check (the identity and
    command-source checks are test_only_the_allocation_... and test_a_forged_...'s)."""
    node._check_graph = lambda: None


def _healthy(node):
    """Feed the node one OK supervisor and guard heartbeat (tests that call the node's methods directly)."""
    _direct_beats(node)
    for feed in (node.peers.on_supervisor_heartbeat, node.peers.on_guard_heartbeat):
        feed(Heartbeat(level=Heartbeat.OK, message="ok"))
    node.steady_check()


def _node(emu_or_bus, overrides, sim_time=False, ctx=None, heartbeat_timeout_s=HEARTBEAT_TIMEOUT_S):
    from rclpy.parameter import Parameter

    bus = emu_or_bus if not isinstance(emu_or_bus, Pca9685Emulator) else EmulatedI2CBus({0x40: emu_or_bus})
    params = config_parameters({"esc.oscillator_calibrated": True, **overrides})
    if sim_time:
        params.append(Parameter("use_sim_time", value=True))
    node = EscNode(bus=bus, context=ctx, parameter_overrides=params + wide_heartbeat_timeout(heartbeat_timeout_s))
    node.settle()  # the start-up configuration, run by the chip thread
    return node


def test_fault1_chip_reset_while_armed_is_detected_reinitialised_and_disarms(esc):
    """A brown-out reset of the PCA9685 (all registers to their reset values: asleep, outputs off) while armed at
    1700 us: the read-back finds MODE1 wrong, re-initialises the chip at neutral, disarms and says so."""
    emu, node = esc["emu"], esc["node"]
    node.link.readback_interval_s = 0.2
    arm(esc)
    stream(esc, [1700.0] * 8, lambda: wire(emu)[0] > 1690)
    emu.reset()  # brown-out: MODE1 = 0x11 (SLEEP), every channel full OFF
    assert np.allclose(wire(emu), 0.0)
    # a controller keeps streaming 1700 us: the node must not keep reporting "armed, commanding" at 1700
    stream(esc, [1700.0] * 8, lambda: node.link.chip_reinits >= 1 and not node.armed)
    wait_until(lambda: np.allclose(wire(emu), NEUTRAL, atol=TICK_US), 5, esc["spin"], "neutral after re-init")
    assert emu.mode1 == 0x21 and emu.prescale == 30  # awake, auto-increment, 200 Hz again
    status = node.diag.status()
    assert "read-back mismatch" in status.message and "MODE1 0x11" in status.message
    assert status.level == DiagnosticStatus.WARN
    assert node.diag.counts()["chip_reinit"] == 1
    wait_until(lambda: esc["written"] and not esc["written"][-1].armed, 5, esc["spin"], "disarmed reported")
    # re-arming needs the arming time at neutral again, counted from the re-initialisation
    assert 0.0 < node.arming_remaining_s() <= node.arming_time_s


def test_i2c_outage_without_oe_the_returning_bus_gets_neutral_first_within_one_tick(esc):
    """Issue 44 finding 8 (/OE not wired): the bus fails while armed at 1700 us and the chip keeps outputting
    1700 us. The ESC says so (UNKNOWN, the widths that may still be on the wire); when the bus returns, the first
    width that reaches the wire is neutral and it comes at the next tick, however long the outage was (before: the
    retry back-off, up to 4 s, left 1700 us on the wire 138-1288 ms after the bus returned)."""
    node, emu, bus = esc["node"], esc["emu"], esc["bus"]
    arm(esc)
    stream(esc, [1700.0] * 8, lambda: wire(emu)[0] > 1690)
    bus.disconnected = True
    stream(esc, [1700.0] * 8, lambda: node.output_state == ThrusterPwm.OUTPUT_UNKNOWN)
    t_lost = node.get_clock().now()
    # 1.5 s of outage: a doubling back-off would be at 1-2 s by now
    wait_until(lambda: (node.get_clock().now() - t_lost).nanoseconds > 1.5e9, 5, esc["spin"], "1.5 s outage")
    assert wire(emu)[0] > 1690 and not node.armed  # what the chip really outputs, and the ESC's state
    assert "1700" in node.core.reason and "may still be on the wire" in node.core.reason
    assert "may still be on the wire" in node.diag.status().message
    samples = []
    write = bus.write_i2c_block_data

    def sampled(address, register, data):
        write(address, register, data)
        samples.append(wire(emu))

    bus.write_i2c_block_data = sampled
    # the bus returns between two ticks: a (re)configuration the last tick posted has failed by then (under load the
    # worker can still be inside its attempts, and the tick posts no second one while it is pending)
    node.settle()
    bus.disconnected = False
    node.steady_check()  # the next tick
    node.settle()
    assert samples and np.allclose(samples[0], NEUTRAL, atol=TICK_US)  # the first write: neutral
    assert all(np.all((s == 0.0) | (np.abs(s - NEUTRAL) <= TICK_US)) for s in samples)
    assert np.allclose(wire(emu), NEUTRAL, atol=TICK_US) and node.output_state == ThrusterPwm.OUTPUT_NEUTRAL
    assert not node.armed and "may still be on the wire" not in node.diag.status().message


def test_fault2_arming_time_counts_from_neutral_confirmed_on_the_chip():
    """Bus down at start, back later: the arming time starts when neutral is read back from the chip."""
    with ros_context() as ctx:
        emu = Pca9685Emulator()
        bus = EmulatedI2CBus({0x40: emu})
        bus.disconnected = True
        node = _node(bus, {"esc.arming_time_s": 0.3, "esc.readback_interval_s": 0.1}, ctx=ctx)
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(node)
        probe = rclpy.create_node("probe", context=ctx)
        SafetyHeartbeats(probe)
        ex.add_node(probe)
        spin = lambda: ex.spin_once(timeout_sec=0.01)  # noqa: E731
        created = node.get_clock().now()
        wait_until(lambda: (node.get_clock().now() - created).nanoseconds > 0.6e9, 5, spin, "0.6 s with the bus down")
        res = node.on_set_armed(SetArmed.Request(arm=True), SetArmed.Response())
        assert not res.success and "not confirmed at neutral" in res.message
        bus.disconnected = False
        wait_until(lambda: node.neutral_confirmed_time is not None, 5, spin, "chip configured after the bus returned")
        assert np.allclose(wire(emu), 1500.0, atol=TICK_US)
        res = node.on_set_armed(SetArmed.Request(arm=True), SetArmed.Response())
        assert not res.success and "more at neutral" in res.message  # 0.6 s since creation do not count
        wait_until(lambda: node.arming_remaining_s() == 0.0, 5, spin, "arming time")
        assert node.on_set_armed(SetArmed.Request(arm=True), SetArmed.Response()).success
        ex.shutdown()
        node.destroy_node()


def test_fault3_dead_clock_steady_watchdog_returns_to_neutral():
    """use_sim_time with a /clock that stops: ROS time stands still, so the ROS-time watchdog cannot trip; the
    steady-clock watchdog brings every channel to neutral."""
    import time

    from rosgraph_msgs.msg import Clock as ClockMsg

    with ros_context() as ctx:
        emu = Pca9685Emulator()
        node = _node(emu, {"esc.arming_time_s": 0.0, "esc.watchdog_timeout_s": 0.2}, sim_time=True, ctx=ctx)
        probe = rclpy.create_node("probe", context=ctx)
        _beats = SafetyHeartbeats(probe)  # supervisor and output guard healthy
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(node)
        ex.add_node(probe)
        clock_pub = probe.create_publisher(ClockMsg, "/clock", 10)
        allocation = AllocationStandIn(ctx)
        pub = allocation.pub
        now = {"ns": 1_000_000_000}

        def advance():
            now["ns"] += 5_000_000
            m = ClockMsg()
            m.clock.sec, m.clock.nanosec = divmod(now["ns"], 1_000_000_000)
            clock_pub.publish(m)
            ex.spin_once(timeout_sec=0.01)

        wait_until(lambda: clock_pub.get_subscription_count() > 0 and pub.get_subscription_count() > 0, 10, advance)
        wait_until(lambda: node.arming_remaining_s() == 0.0 and node.get_clock().now().nanoseconds > 0
                   and not node.heartbeat_refusal(), 10, advance)
        assert node.on_set_armed(SetArmed.Request(arm=True), SetArmed.Response()).success

        def command_and_advance():
            pub.publish(ThrusterPwm(pulse_width_us=[1650.0] * 8, armed=True))
            advance()
        wait_until(lambda: wire(emu)[0] > 1600, 10, command_and_advance, "commanded output")
        t_last = time.monotonic()  # /clock and the commands stop here
        wait_until(lambda: np.allclose(wire(emu), 1500.0, atol=TICK_US), 10, lambda: ex.spin_once(timeout_sec=0.01),
                   "neutral with the clock dead")
        wall_s = time.monotonic() - t_last
        # ROS time stood still: by it the last command is younger than the timeout (the ROS watchdog cannot trip)
        assert node.get_clock().now().nanoseconds * 1e-9 - node.core.command_t_s < 0.2
        assert node.steady_watchdog_trips == 1
        assert wall_s >= 0.2  # not before the timeout
        ex.shutdown()
        allocation.destroy()
        probe.destroy_node()
        node.destroy_node()


def test_fault4_restart_never_resumes_the_previous_process_outputs():
    """A previous process died armed at 1700 us: the new node's start-up puts only nothing (no pulses) or neutral
    on the wire, sampled after every I2C transaction (before the fix RESTART resumed 1700 us first)."""
    from hindrax_drivers.pca9685 import protocol as pca
    from hindrax_common.transport.i2c import I2CDevice

    emu = Pca9685Emulator()
    bus = EmulatedI2CBus({0x40: emu})
    old = I2CDevice(bus, 0x40, "previous process")
    old.write_sequence(pca.startup_sequence(30))
    for ch in range(8):
        old.write_block(pca.led_register(ch), pca.channel_bytes_for_pulse(1700.0, 30))
    assert np.allclose(wire(emu, range(8)), 1700.0, atol=TICK_US)
    sampled = _SampledBus(bus, emu, range(8))
    with ros_context() as ctx:
        node = _node(sampled, {}, ctx=ctx)
        assert node.neutral_confirmed_time is not None
        node.destroy_node()
    assert len(sampled.samples) >= 6
    # the old outputs run until the first transactions reach the chip; from the first change on, only "no
    # pulses" or neutral, and the change comes within the first two transactions (MODE2, all outputs off)
    first = next(i for i, s in enumerate(sampled.samples) if not np.allclose(s, 1700.0, atol=TICK_US))
    assert first <= 1
    for s in sampled.samples[first:]:
        assert np.all((s == 0.0) | (np.abs(s - 1500.0) <= TICK_US)), s
    assert np.allclose(sampled.samples[-1], 1500.0, atol=TICK_US)


def test_fault5_uncalibrated_oscillator_refuses_arming_and_neutral_applies_trim():
    with ros_context() as ctx:
        node = EscNode(bus=EmulatedI2CBus({0x40: Pca9685Emulator()}), context=ctx,
                       parameter_overrides=config_parameters({"esc.arming_time_s": 0.0}))  # the shipped default
        res = node.on_set_armed(SetArmed.Request(arm=True), SetArmed.Response())
        assert not res.success and "oscillator_calibrated" in res.message and "hindrax esc calibrate" in res.message
        node.destroy_node()
    # trim moves neutral too (the ESC's own stop point): 1500 + 10 and 1500 - 7 us, independent arithmetic
    out = EscOutput(range(3), [False, True, False], [10.0, -7.0, 0.0], 1100, 1500, 1900)
    assert out.neutral().tolist() == [1510.0, 1493.0, 1500.0]
    assert out.target([1500.0, 1500.0, 1500.0], 0.02).tolist() == out.neutral().tolist()


def test_fault9_an_unmeasured_oscillator_keeps_the_thruster_outputs_off():
    """The shipped file (oscillator not measured) on a 23 MHz part: every thruster channel is full OFF (no pulses)
    instead of a "neutral" computed at the nominal 25 MHz (1500 * 25 / 23 = 1630.4 us on the wire, inside the ESC's
    forward range); channel 15 carries that same reference pulse for the scope; arming is refused."""
    from hindrax_drivers.pca9685 import protocol as p

    with ros_context() as ctx:
        emu = Pca9685Emulator(oscillator_hz=23.0e6)
        node = EscNode(bus=EmulatedI2CBus({0x40: emu}), context=ctx, parameter_overrides=config_parameters({}))
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(node)
        wait_until(lambda: node.core.neutral_confirmed_at is not None, 10, lambda: ex.spin_once(timeout_sec=0.01),
                   "chip configured and read back")
        assert wire(emu).tolist() == [0.0] * 8
        assert all(emu.channel_registers(c).full_off for c in range(8))
        assert abs(emu.pulse_width_us(p.REFERENCE_CHANNEL) - 1500.0 * 25.0 / 23.0) < 1.5
        res = node.on_set_armed(SetArmed.Request(arm=True), SetArmed.Response())
        assert not res.success and "oscillator_calibrated" in res.message
        ex.shutdown()
        node.destroy_node()


def test_fault5_oscillator_calibration_from_one_scope_reading():
    """A 24.06 MHz part with the nominal 25 MHz configured: neutral on the wire is 1500 * 25 / 24.06 = 1558.6 us
    (outside the 1475-1525 us deadband). One reading of it calibrates the oscillator; then neutral is 1500 us."""
    from hindrax_drivers.pca9685 import protocol as pca

    with ros_context() as ctx:
        emu = Pca9685Emulator(oscillator_hz=24.06e6)
        node = _node(emu, {}, ctx=ctx)
        scope_us = emu.pulse_width_us(0)
        assert scope_us == pytest.approx(1500.0 * 25.0 / 24.06, abs=1.3)  # one count at 24.06 MHz, 1.29 us
        f = pca.oscillator_from_measurement(scope_us, 1500.0, node.prescale, 25e6)
        node.destroy_node()
        assert f == pytest.approx(24.06e6, rel=1e-9)  # the emulator decodes exactly: no scope noise here
        emu2 = Pca9685Emulator(oscillator_hz=24.06e6)
        node2 = _node(emu2, {"esc.oscillator_hz": f}, ctx=ctx)
        assert np.allclose(wire(emu2, range(8)), 1500.0, atol=pca.count_duration_us(node2.prescale, f) / 2 + 1e-9)
        node2.destroy_node()


def test_event_driven_output_writes_the_command_on_arrival(esc):
    """Issue 15 item 3: a command goes to the chip thread in its own callback, not at the next output tick."""
    arm(esc)
    node, emu = esc["node"], esc["emu"]
    msg = ThrusterPwm(pulse_width_us=[1720.0] * 8, armed=True)
    node.on_command(msg)  # as the subscription does, outside any tick
    assert node.settle()
    assert wire(emu)[0] == pytest.approx(1720.0, abs=TICK_US)


def test_commands_behind_a_busy_bus_never_wait_and_the_newest_one_is_written(esc):
    """The executor thread never waits on the bus: while a chip write hangs, the command callbacks return, the newer
    commands replace each other in the worker's queue, and once the bus answers only the newest one is written
    (one block write for the whole backlog)."""
    arm(esc)
    node, emu, bus = esc["node"], esc["emu"], esc["bus"]
    writes, release = [], threading.Event()
    write = bus.write_i2c_block_data

    def held(address, register, data):
        writes.append(register)
        release.wait(10)  # the bus hangs until the test lets it go
        return write(address, register, data)

    bus.write_i2c_block_data = held
    node.on_command(ThrusterPwm(pulse_width_us=[1600.0] * 8, armed=True))
    wait_until(lambda: writes, 5, message="the first write on the bus")
    for width in (1650.0, 1700.0):
        node.on_command(ThrusterPwm(pulse_width_us=[width] * 8, armed=True))  # returns: the bus is not waited on
    assert writes == [0x06] and not release.is_set()
    release.set()
    assert node.settle()
    assert writes == [0x06, 0x06] and wire(emu)[0] == pytest.approx(1700.0, abs=TICK_US)


def test_steady_watchdog_counts_only_executor_alive_time(monkeypatch):
    """A stalled process (one 2 s gap between two checks, e.g. a long callback) does not trip the steady-clock
    watchdog by itself (a gap counts at most two output periods); regular checks without a command do."""
    import hindrax_drivers.pca9685.node as esc_node

    fake = {"t": 100.0}
    monkeypatch.setattr(esc_node.time, "monotonic", lambda: fake["t"])
    with ros_context() as ctx:
        node = _node(Pca9685Emulator(), {"esc.arming_time_s": 0.0, "esc.watchdog_timeout_s": 0.2}, ctx=ctx)
        _healthy(node)
        fake["t"] += esc_node.GUARD_CONFIRM_S  # at neutral with the guard's OK for the shortest arming time
        _healthy(node)
        assert node.on_set_armed(SetArmed.Request(arm=True), SetArmed.Response()).success
        node.on_command(ThrusterPwm(pulse_width_us=[1650.0] * 8, armed=True))
        fake["t"] += 2.0  # stall
        node.steady_check()
        assert node.steady_watchdog_trips == 0 and node.command is not None
        # the stall counted 2 periods (0.04 s); 7 regular checks of 20 ms: 0.18 s in all, below 0.2 s
        for _ in range(7):
            fake["t"] += PERIOD_S
            node.steady_check()
        assert node.steady_watchdog_trips == 0
        for _ in range(2):  # 0.22 s
            fake["t"] += PERIOD_S
            node.steady_check()
        assert node.steady_watchdog_trips == 1 and node.command is None
        assert node.core.reason == "steady-clock watchdog: no command for 0.2 s"  # the core's decision
        for name in ("armed", "output_state", "command", "watchdog_s", "steady_watchdog_s"):
            with pytest.raises(AttributeError):  # the node only wires ROS: the core's state is not settable here
                setattr(node, name, 1)
        node.destroy_node()


def _steady_timers(node):
    from rclpy.clock import ClockType

    period_ns = round(PERIOD_S * 1e9)
    timers = [t for t in node.timers if t.timer_period_ns == period_ns]
    return [t.clock.clock_type == ClockType.STEADY_TIME for t in timers]


@contextlib.contextmanager
def _esc_beside_heartbeats(ctx, node):
    """``node`` and a probe publishing healthy supervisor and guard heartbeats on one executor; yields
    (probe, beats, executor, spin-once); destroys both nodes on the way out."""
    probe = rclpy.create_node("probe", context=ctx)
    beats = SafetyHeartbeats(probe)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    ex.add_node(probe)
    try:
        yield probe, beats, ex, lambda: ex.spin_once(timeout_sec=0.005)
    finally:
        ex.shutdown()
        probe.destroy_node()
        node.destroy_node()


def test_heartbeats_are_callbacks_in_both_clock_modes_and_age_from_their_arrival():
    """Issue 47 item 1: the ESC takes its inputs by callbacks whatever the clock (no polled intake node): on the system
    clock one steady-clock timer runs the safety and output ticks, with use_sim_time the output tick is a ROS-time
    timer; a heartbeat counts from its arrival, so a supervisor silenced for more than esc.heartbeat_timeout_s
    (0.2 s here) is refused no earlier than 0.2 s minus one beat period after its last beat."""
    import time

    beat_topics = {"/supervisor/heartbeat", "/guard/heartbeat", "/thrusters/command_pulse_width"}
    with ros_context() as ctx:
        sim = _node(Pca9685Emulator(), {}, sim_time=True, ctx=ctx)
        assert sorted(_steady_timers(sim)) == [False, True]
        assert beat_topics <= {s.topic_name for s in sim.subscriptions}
        sim.destroy_node()

        node = _node(Pca9685Emulator(), {"esc.arming_time_s": 0.0}, ctx=ctx, heartbeat_timeout_s=0.2)
        assert _steady_timers(node) == [True]
        assert beat_topics <= {s.topic_name for s in node.subscriptions}
        with _esc_beside_heartbeats(ctx, node) as (probe, beats, ex, spin):
            assert "esc_intake" not in probe.get_node_names()
            wait_until(lambda: node.heartbeat_refusal() == "", 10, spin, "both heartbeats by callbacks")
            beats.supervisor = None
            t0 = time.monotonic()
            wait_until(lambda: "no supervisor heartbeat" in node.heartbeat_refusal(), 5, spin, "supervisor stale")
            assert time.monotonic() - t0 >= 0.15

def test_the_read_back_goes_to_raw_pca9685_in_the_batches_of_the_writes():
    """The read-back (MODE1, PRE_SCALE, the thruster block and the lights channel every esc.readback_interval_s,
    0.25 s) is recorded on raw/pca9685 in the 0.1 s batches, not one message per read: 4 reads x 4 read-backs a
    second were 16 messages a second on their own, and each is a publish and a delivery to the recorder
    (docs/architecture.md §10.1). Every read is still recorded, in wire order."""
    import time

    from hindrax_msgs.msg import RawDeviceData

    from hindrax_common.node_support.node_common import raw_transactions

    with ros_context() as ctx:
        node = _node(Pca9685Emulator(), {"esc.arming_time_s": 0.0, "esc.readback_interval_s": 0.25}, ctx=ctx)
        with _esc_beside_heartbeats(ctx, node) as (probe, beats, ex, spin):
            got = []
            probe.create_subscription(RawDeviceData, "raw/pca9685", got.append, 100)
            wait_until(lambda: node.neutral_confirmed_time is not None and len(got) > 0, 10, spin, "ESC up")
            t_end = time.monotonic() + 2.0
            got.clear()
            n0 = node.device.stats.transactions
            wait_until(lambda: time.monotonic() > t_end, 3, spin, "2 s idle")  # a window, counted below
            reads = node.device.stats.transactions - n0
            node.raw.flush_pending()
            wait_until(lambda: sum(len(raw_transactions(m)) for m in got) >= reads, 5, spin, "every read recorded")
            records = [t for m in got for t in raw_transactions(m)]
            assert reads >= 24  # 2 s of read-backs: 8 x (MODE1, PRE_SCALE, channels 0-7, channel 8)
            assert {reg for _d, _a, reg, _data in records} >= {0x00, 0xFE}
            assert len(got) <= 11, f"{len(got)} messages for {reads} reads in 2 s"


def test_an_arm_waits_for_the_guard_to_confirm_even_with_no_arming_time():
    """With ``esc.arming_time_s`` 0 an arm is still refused until neutral has been on the wire with the guard's OK
    for GUARD_CONFIRM_S (0.15 s), and a guard ERROR taken in the same round as a later OK restarts that time. Found
    by the safety bench: after an I2C outage the ESC reconfigured the chip within 15 ms of reporting UNKNOWN, was
    armed on the guard's last OK, then took the guard's ERROR for that UNKNOWN and disarmed itself."""
    import time

    from hindrax_drivers.pca9685.node import GUARD_CONFIRM_S

    assert GUARD_CONFIRM_S == pytest.approx(0.15)
    with ros_context() as ctx:
        node = _node(Pca9685Emulator(), {"esc.arming_time_s": 0.0}, ctx=ctx, heartbeat_timeout_s=2.0)
        _direct_beats(node)
        ok = Heartbeat(level=Heartbeat.OK, message="ok")
        err = Heartbeat(level=Heartbeat.ERROR, message="ESC output state unknown")
        node.peers.on_supervisor_heartbeat(ok)
        node.peers.on_guard_heartbeat(ok)
        assert node.neutral_confirmed_time is not None
        node._safety_tick(time.monotonic())  # neutral on the wire with the guard's OK from now
        assert node.neutral_on_wire_since is not None
        assert GUARD_CONFIRM_S - 0.05 < node.arming_remaining_s() <= GUARD_CONFIRM_S
        res = node.on_set_armed(SetArmed.Request(arm=True), SetArmed.Response())
        assert not res.success and "at neutral" in res.message and not node.armed
        # the guard's ERROR and its next OK taken in one round: the time at neutral starts again
        node.peers.on_guard_heartbeat(err)
        node.peers.on_guard_heartbeat(ok)
        assert node.neutral_on_wire_since is None
        node._safety_tick(time.monotonic())
        t0 = time.monotonic()
        wait_until(lambda: node.arming_remaining_s() == 0.0, 2, None, "guard confirmation time")
        assert time.monotonic() - t0 >= GUARD_CONFIRM_S - 0.02
        node.peers.on_supervisor_heartbeat(ok)
        node.peers.on_guard_heartbeat(ok)
        res = node.on_set_armed(SetArmed.Request(arm=True), SetArmed.Response())
        assert res.success and node.armed
        node.destroy_node()




def test_a_slow_bus_does_not_slow_the_heartbeat(esc):
    """Every block write takes 150 ms (a socket round trip on a loaded machine is 7-10 ms): with commands streaming,
    esc/heartbeat keeps its 25 Hz (at least 30 % of it arrives here, on a loaded machine; with the chip written on
    the executor thread a tick lasted a write, 150 ms: at most 3.3 beats a second, 13 %), the ESC stays armed with a
    known output state, and the newest command reaches the wire. (A call slower than the stuck bound is a fault:
    test_safety_paths' hung bus; here the bound is widened so that the load of the machine cannot reach it.)"""
    from hindrax_msgs.msg import Heartbeat as Status

    arm(esc)
    node, emu, bus, probe = esc["node"], esc["emu"], esc["bus"], esc["probe"]
    beats = []
    probe.create_subscription(Status, "esc/heartbeat", lambda m: beats.append(time.monotonic()), 50)
    write = bus.write_i2c_block_data

    def slow(address, register, data):
        time.sleep(0.15)
        return write(address, register, data)

    node.chip_io.call_timeout_s = 2.0
    # not about who publishes: a loaded machine's discovery ("_NODE_NAME_UNKNOWN_" for a while) must not disarm it
    node._check_graph = lambda: None
    bus.write_i2c_block_data = slow
    widths = itertools.cycle([1640.0, 1660.0, 1680.0])
    t_end = time.monotonic() + 2.0
    wait_until(lambda: beats, 5, esc["spin"], "first heartbeat")
    beats.clear()
    t0 = time.monotonic()
    wait_until(lambda: time.monotonic() > t_end, 10, lambda: (esc["command"]([next(widths)] * 8), esc["spin"]()),
               "2 s of commands")
    window_s = time.monotonic() - t0
    assert len(beats) >= 0.3 * 25.0 * window_s, f"{len(beats)} heartbeats in {window_s:.2f} s"
    assert node.armed and node.output_state == ThrusterPwm.OUTPUT_COMMANDING and node.link.bus_stalls == 0
    # the stream goes on, ending in 1700 us: one command alone would meet the 0.2 s watchdog while the worker is
    # still in the previous command's 150 ms block writes, and give neutral (as it should)
    wait_until(lambda: abs(wire(emu)[0] - 1700.0) < TICK_US, 5, lambda: (esc["command"]([1700.0] * 8), esc["spin"]()),
               "the newest command on the wire")


def test_pulse_width_goes_out_on_every_write_and_repeats_only_after_a_quiet_period(monkeypatch):
    """``thrusters/pulse_width``: every confirmed write goes out at once; the output tick repeats the last widths only
    when none went out for REPEAT_AFTER_PERIODS output periods (ROS time). With commands at 25 Hz (the
    identification's) and the tick at 50 Hz, that is one message per write, each width once; armed at rest, every
    second tick; disarmed at neutral, a keep-alive every DISARMED_REPEAT_S (it had been every second tick: 25 Hz of
    nothing new while the vehicle waits); the arm and the disarm go out within a tick; a step back of ROS time
    repeats at once. Before, every tick without a write repeated: 50 Hz in both."""
    import rclpy.time
    from rclpy.serialization import deserialize_message

    import hindrax_drivers.pca9685.node as esc_node

    fake = {"t": 100.0}
    monkeypatch.setattr(esc_node.time, "monotonic", lambda: fake["t"])
    with ros_context() as ctx:
        node = _node(Pca9685Emulator(), {"esc.arming_time_s": 0.0}, sim_time=True, ctx=ctx)
        clock = node.get_clock()
        sent = []
        node.pub_written = type("Pub", (), {"publish": lambda self, data: sent.append(data)})()
        ros = {"ns": 5_000_000_000}

        def tick(n=1):  # n output periods: the safety tick (takes the chip's results) and the output tick
            for _ in range(n):
                ros["ns"] += round(PERIOD_S * 1e9)
                fake["t"] += PERIOD_S
                clock.set_ros_time_override(rclpy.time.Time(nanoseconds=ros["ns"], clock_type=clock.clock_type))
                node.settle()
                node.steady_check()
                node.tick()

        _healthy(node)
        fake["t"] += esc_node.GUARD_CONFIRM_S
        _healthy(node)
        tick(4)
        sent.clear()
        rest_ticks = round(4 * esc_node.DISARMED_REPEAT_S / PERIOD_S)
        tick(rest_ticks)  # disarmed at neutral: the keep-alive only
        assert len(sent) == 4, f"{len(sent)} messages in {rest_ticks} ticks disarmed at rest"
        assert not deserialize_message(sent[-1], ThrusterPwm).armed
        assert node.on_set_armed(SetArmed.Request(arm=True), SetArmed.Response()).success
        sent.clear()
        tick(2)
        assert sent and deserialize_message(sent[-1], ThrusterPwm).armed  # the arm goes out at the tick rate
        sent.clear()
        tick(20)  # armed at rest: a repeat every second tick
        assert len(sent) == 10
        sent.clear()
        widths = [1550.0 + 10.0 * k for k in range(10)]
        for w in widths:  # 25 Hz commands, each a new width
            node.on_command(ThrusterPwm(pulse_width_us=[w] * 8, armed=True))
            tick(2)
        got = [deserialize_message(m, ThrusterPwm).pulse_width_us[0] for m in sent]
        assert len(sent) == len(widths), got  # one message per write: no repeat between two writes
        assert got == [pytest.approx(w, abs=TICK_US) for w in widths]
        sent.clear()
        ros["ns"] -= 1_000_000_000  # ROS time steps back (a restarted /clock): the next tick repeats at once
        tick()
        assert len(sent) == 1
        sent.clear()
        assert node.on_set_armed(SetArmed.Request(arm=False), SetArmed.Response()).success
        assert sent and not deserialize_message(sent[-1], ThrusterPwm).armed  # the disarm goes out at once
        sent.clear()
        tick(rest_ticks)
        assert len(sent) <= 4, f"{len(sent)} messages in {rest_ticks} ticks disarmed at rest after a disarm"
        node.destroy_node()


def test_an_oscillator_marked_calibrated_without_a_measurement_of_this_board_warns_on_diagnostics(monkeypatch):
    """Issue 71.8: `hindrax health` reads the ESC's /diagnostics: WARN with the operator's check (on a real chip;
    the emulated one here is taken as real)."""
    import hindrax_drivers.pca9685.node as esc_node
    from hindrax_common.config.sections.esc import board_id

    monkeypatch.setattr(esc_node, "real_chip", lambda _bus: True)
    with ros_context() as ctx:
        for record, warned in ((None, True), ("0badc0de 2026-01-01 1559 us", True), (f"{board_id()} x", False)):
            extra = {} if record is None else {"esc.oscillator_measured_on": record}
            node = EscNode(bus=EmulatedI2CBus({0x40: Pca9685Emulator()}), context=ctx,
                           parameter_overrides=config_parameters({"esc.oscillator_calibrated": True, **extra}))
            try:
                warning = node.diag._warnings.get("oscillator_not_measured_here", "")
                assert bool(warning) is warned and (not warned or "1500 us" in warning), (record, warning)
            finally:
                node.destroy_node()
