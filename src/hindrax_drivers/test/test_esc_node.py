"""ESC node at the register "wire": the PCA9685 emulator decodes what each channel actually outputs."""
import math
import threading

import numpy as np
import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from std_msgs.msg import Float64

from hindrax_drivers.pca9685.emulator import Pca9685Emulator
from hindrax_drivers.pca9685.node import EscNode, EscOutput
from hindrax_drivers.testing import config_parameters, ros_context, wait_until
from hindrax_drivers.transport.emulated_i2c import EmulatedI2CBus
from hindrax_msgs.msg import ThrusterPwm
from hindrax_msgs.srv import SetArmed

pytestmark = pytest.mark.ros
TICK_US = 1.24  # one PCA9685 count at 200 Hz (prescale 30) and 25 MHz, docs/devices.md §5.1
PERIOD_S = 1 / 50.0  # esc.output_rate_hz


def wire(emu, channels=range(8)):
    return np.array([emu.pulse_width_us(c) for c in channels])


@pytest.fixture
def esc():
    with ros_context() as ctx:
        emu = Pca9685Emulator()
        bus = EmulatedI2CBus({0x40: emu})
        params = config_parameters({"esc.arming_time_s": 0.3, "esc.watchdog_timeout_s": 0.2,
                                    "thrusters.t2.reversed": True, "thrusters.t3.trim_us": 10.0})
        node = EscNode(bus=bus, context=ctx, parameter_overrides=params)
        probe = rclpy.create_node("probe", context=ctx)
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(node)
        ex.add_node(probe)
        pub = probe.create_publisher(ThrusterPwm, "thrusters/command_pulse_width", 10)
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

        wait_until(lambda: pub.get_subscription_count() > 0 and arm.service_is_ready(), 10, spin, "ESC node ready")
        yield dict(node=node, emu=emu, bus=bus, spin=spin, set_armed=set_armed, command=command, written=written,
                   lights=lights)
        ex.shutdown()
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
    assert np.allclose(wire(emu), 1500.0, atol=TICK_US)  # before any command
    assert emu.pulse_width_us(8) == pytest.approx(1100.0, abs=TICK_US)  # lights off
    esc["command"]([1700.0] * 8)
    wait_until(lambda: len(esc["written"]) >= 3, 5, esc["spin"], "output ticks")
    assert np.allclose(wire(emu), 1500.0, atol=TICK_US)
    assert not esc["written"][-1].armed


def test_arming_needs_time_at_neutral_then_commands_reach_the_wire(esc):
    emu, node = esc["emu"], esc["node"]
    if node.arming_remaining_s() > 0.05:
        res = esc["set_armed"](True)
        assert not res.success and "at neutral" in res.message
    wait_until(lambda: node.arming_remaining_s() == 0.0, 5, esc["spin"], "arming time")
    assert esc["set_armed"](True).success
    cmd = np.array([1700.0, 1700.0, 1300.0, 2500.0, 900.0, 1500.0, 1600.0, 1400.0])
    # expected: clamp to 1100-1900, t2 reversed about 1500, t3 trimmed +10 us
    expected = np.array([1700.0, 1300.0, 1310.0, 1900.0, 1100.0, 1500.0, 1600.0, 1400.0])
    stream(esc, cmd, lambda: np.allclose(wire(emu), expected, atol=TICK_US))
    # the node reports what it wrote, decoded from the register counts
    wait_until(lambda: esc["written"][-1].armed and np.allclose(esc["written"][-1].pulse_width_us, wire(emu),
                                                                 atol=1e-6), 5, esc["spin"], "written report")


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
        params = config_parameters({"esc.arming_time_s": 0.0, "esc.watchdog_timeout_s": 0.2})
        node = EscNode(bus=EmulatedI2CBus({0x40: emu}), context=ctx,
                       parameter_overrides=params + [Parameter("use_sim_time", value=True)])
        probe = rclpy.create_node("probe", context=ctx)
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(node)
        ex.add_node(probe)
        clock_pub = probe.create_publisher(Clock, "/clock", 10)
        pub = probe.create_publisher(ThrusterPwm, "thrusters/command_pulse_width", 10)
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
                   and arm.service_is_ready(), 10, advance, "ESC node ready")
        fut = arm.call_async(SetArmed.Request(arm=True))
        wait_until(fut.done, 5, advance, "armed")
        assert fut.result().success

        def command_and_advance():
            m = ThrusterPwm(pulse_width_us=[1650.0] * 8, armed=True)
            pub.publish(m)
            advance()
        wait_until(lambda: wire(emu)[0] > 1600, 10, command_and_advance, "commanded output")
        wait_until(lambda: np.allclose(wire(emu), 1500.0, atol=TICK_US), 10, advance, "watchdog neutral")
        # the node stamps each command on arrival with its (simulated) clock; the last one started the watchdog
        elapsed_s = (node.get_clock().now() - node.command_time).nanoseconds * 1e-9
        assert 0.2 <= elapsed_s <= 0.2 + PERIOD_S + 0.005  # timeout + at most one output period (+1 clock step)
        assert node.watchdog_trips == 1
        ex.shutdown()
        probe.destroy_node()
        node.destroy_node()


def test_disarm_and_fault_and_shutdown_go_neutral(esc):
    arm(esc)
    emu, node = esc["emu"], esc["node"]
    assert esc["set_armed"](False).success
    assert np.allclose(wire(emu), 1500.0, atol=TICK_US)  # at once, in the service call
    arm(esc)
    stream(esc, [math.nan] * 8, lambda: node.diag.counts().get("output_exception", 0) > 0)
    assert np.allclose(wire(emu), 1500.0, atol=TICK_US)  # a NaN command is a fault: neutral
    stream(esc, [1650.0] * 8, lambda: wire(emu)[0] > 1600)
    node.close()
    assert np.allclose(wire(emu), 1500.0, atol=TICK_US)


def test_lights_channel(esc):
    msg = Float64(data=0.5)
    esc["lights"].publish(msg)
    wait_until(lambda: abs(esc["emu"].pulse_width_us(8) - 1500.0) < TICK_US, 5, esc["spin"], "lights at half")


def test_i2c_errors_are_retried_and_reported(esc):
    esc["bus"].set_fault_rate(0.3)
    n = len(esc["written"])
    wait_until(lambda: len(esc["written"]) > n + 10, 5, esc["spin"], "ticks under bus faults")
    assert esc["node"].device.stats.retries > 0
    assert np.allclose(wire(esc["emu"]), 1500.0, atol=TICK_US)


def test_sigterm_path_writes_neutral():
    """run_node (the process entry point) closes the node on external shutdown: neutral on the wire."""
    from hindrax_drivers.node_common import run_node

    emu = Pca9685Emulator()
    bus = EmulatedI2CBus({0x40: emu})
    holder = {}

    def factory():
        node = EscNode(bus=bus, parameter_overrides=config_parameters({"esc.arming_time_s": 0.0}))
        node.armed = True
        node.command = np.full(8, 1700.0)
        node.command_time = node.get_clock().now()
        node.watchdog_s = 1e9
        holder["node"] = node
        return node

    t = threading.Thread(target=lambda: holder.setdefault("rc", run_node(factory, [])))
    t.start()
    wait_until(lambda: "node" in holder and emu.pulse_width_us(0) > 1650, 10, message="commanding 1700 us")
    rclpy.shutdown()  # what the SIGINT/SIGTERM handler does
    t.join(10)
    assert not t.is_alive() and holder["rc"] == 0
    assert np.allclose(wire(emu), 1500.0, atol=TICK_US)


def test_output_logic_slew_and_errors():
    out = EscOutput(range(2), [False, True], [0.0, 0.0], 1100, 1500, 1900, slew_rate_us_per_s=1000.0)
    assert out.target([1900, 1900], 0.1).tolist() == [1600.0, 1400.0]  # 100 us per 0.1 s
    with pytest.raises(ValueError):
        out.target([1500], 0.1)
    with pytest.raises(ValueError):
        out.target([1500, math.inf], 0.1)
