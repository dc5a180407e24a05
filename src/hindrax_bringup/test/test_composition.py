"""Composed processes (hindrax_bringup.layout.composition): each group's nodes exist and keep their own names in one
process (the installed group executable), a group ends cleanly on SIGINT, and a bad node list is refused."""
from __future__ import annotations

import subprocess
from pathlib import Path

import pytest
import rclpy

from hindrax_bringup.layout.composition import GROUPS, NODE_CLASSES, main, node_factories
from hindrax_common.config import default_config_path
from hindrax_common.testing import child_env, child_process, interrupt, python_executable, ros_context, wait_until


def test_every_group_names_known_nodes_once_and_unknown_nodes_are_refused(capsys):
    assert set(GROUPS) == {"sensors_node", "actuation_node"}
    seen = [n for nodes in GROUPS.values() for n in nodes]
    assert len(seen) == len(set(seen)) and set(seen) <= set(NODE_CLASSES)
    for nodes in GROUPS.values():
        assert all(isinstance(f, type) for f in node_factories(nodes))
    # the ESC is built last in its group, so it is closed first on exit (neutral before anything else goes)
    assert GROUPS["actuation_node"][-1] == "esc"
    with pytest.raises(ValueError, match="unknown node 'gps'"):
        node_factories(["esc", "gps"])
    assert main(["composition", "esc,gps"]) == 2
    assert "unknown node 'gps'" in capsys.readouterr().err


@pytest.mark.ros
def test_sensors_group_runs_its_five_nodes_under_their_own_names_and_exits_0_on_sigint():
    # the installed console script; no serial ports, no /dev/i2c-1 here: every driver keeps running and reports it
    # (as alone)
    script = Path(python_executable()).with_name("sensors_node")
    with child_process([str(script), "--ros-args", "--params-file", str(default_config_path())],
                       env=child_env(), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True) as proc:
        with ros_context() as ctx:
            probe = rclpy.create_node("composition_probe", context=ctx)
            wait_until(lambda: proc.poll() is None and set(GROUPS["sensors_node"]) <= set(probe.get_node_names()),
                       30, None, "the five nodes in the graph")

            def topics(node: str) -> set[str]:
                return {t for t, _ in probe.get_publisher_names_and_types_by_node(node, "/")}

            # a node is discovered before its publishers: wait for each node's own topic under its own name
            own = {"dvl75": "/dvl/data", "ping1d": "/ping/altitude", "ms5837": "/pressure/fluid_pressure",
                   "icm20948": "/imu/data_raw", "static_tf": "/tf_static"}
            wait_until(lambda: all(topic in topics(node) for node, topic in own.items()), 30, None,
                       "each node's publishers under its own name")
            for node, topic in own.items():
                assert not [other for other in own if other != node and topic in topics(other)], topic
            probe.destroy_node()
        assert interrupt(proc, 30) == 0, proc.stdout.read()


@pytest.mark.ros
def test_actuation_the_esc_takes_the_allocations_commands_by_its_subscription():
    """actuation_node composes the allocation and the ESC: the allocation's command reaches the chip through the
    ESC's subscription callback, as in separate processes; the ESC has no polled intake node and no in-process
    hand-off. Another publisher on the command topic (not the allocation) disarms the ESC: its 1600 us never reach
    the wire."""
    import numpy as np
    from geometry_msgs.msg import WrenchStamped
    from rclpy.executors import SingleThreadedExecutor

    from hindrax_bringup.allocation.node import ThrustAllocationNode
    from hindrax_drivers.pca9685.emulator import Pca9685Emulator
    from hindrax_drivers.pca9685.node import EscNode
    from hindrax_common.testing import SafetyHeartbeats, config_parameters
    from hindrax_common.transport.emulated_i2c import EmulatedI2CBus
    from hindrax_msgs.msg import ThrusterPwm
    from hindrax_msgs.srv import SetArmed

    with ros_context() as ctx:
        params = config_parameters({"esc.arming_time_s": 0.0, "esc.oscillator_calibrated": True})
        emu = Pca9685Emulator()
        alloc = ThrustAllocationNode(context=ctx, parameter_overrides=params)
        esc = EscNode(bus=EmulatedI2CBus({0x40: emu}), context=ctx, parameter_overrides=params)
        topics = {s.topic_name for s in esc.subscriptions}
        assert {"/thrusters/command_pulse_width", "/supervisor/heartbeat", "/guard/heartbeat"} <= topics
        assert not hasattr(esc, "in_process_sink") and not hasattr(alloc, "command_sinks")
        probe = rclpy.create_node("handoff_probe", context=ctx)
        SafetyHeartbeats(probe)
        ex = SingleThreadedExecutor(context=ctx)
        for n in (alloc, esc, probe):
            ex.add_node(n)
        assert "esc_intake" not in probe.get_node_names()
        wrench = probe.create_publisher(WrenchStamped, "wrench", 10)
        copies: list = []
        probe.create_subscription(ThrusterPwm, "thrusters/command_pulse_width", copies.append, 10)
        arm = probe.create_client(SetArmed, "esc/set_armed")
        spin = lambda: ex.spin_once(timeout_sec=0.01)  # noqa: E731
        wait_until(lambda: wrench.get_subscription_count() and alloc.pub_pwm.get_subscription_count() >= 2
                   and arm.service_is_ready() and not esc.heartbeat_refusal() and esc.arming_remaining_s() == 0.0,
                   10, spin, "graph")
        fut = arm.call_async(SetArmed.Request(arm=True))
        wait_until(fut.done, 5, spin, "armed")
        assert fut.result().success, fut.result().message
        try:
            m = WrenchStamped()
            m.header.frame_id = "base_link"
            m.header.stamp = probe.get_clock().now().to_msg()
            m.wrench.force.x = 20.0
            wrench.publish(m)
            wait_until(lambda: copies, 10, spin, "the allocation's command on the topic")
            target = copies[-1].pulse_width_us[0]
            assert abs(target - 1500.0) > 50.0
            wait_until(lambda: abs(emu.pulse_width_us(0) - target) < 1.3, 10, spin, "the command on the chip")
            other = probe.create_publisher(ThrusterPwm, "thrusters/command_pulse_width", 10)

            def other_command():
                other.publish(ThrusterPwm(pulse_width_us=[1600.0] * 8, armed=True))
                spin()
            wait_until(lambda: not esc.armed, 10, other_command, "disarmed by the other publisher")
            other_command()
            esc.settle()  # the disarm's neutral, written by the ESC's chip thread
            assert np.allclose([emu.pulse_width_us(c) for c in range(8)], 1500.0, atol=1.3)
        finally:
            ex.shutdown()
            for n in (probe, esc, alloc):
                n.destroy_node()
