"""Simulator node: /clock, ground truth in ROS frames, pulse-width input (topic or injected source)."""
import math
import signal
import subprocess

import numpy as np
import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import WrenchStamped
from nav_msgs.msg import Odometry
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rosgraph_msgs.msg import Clock

from hindrax_common.base import frames
from hindrax_common.config import default_config_path, load_config
from hindrax_common.testing import child_env, child_process, python_executable, ros_context, wait_until
from hindrax_sim.node import SimulatorNode, time_msg
from hindrax_msgs.msg import ThrusterPwm

pytestmark = pytest.mark.ros

SURGE_PW = [1700.0, 1700.0, 1500.0, 1500.0, 1500.0, 1500.0, 1500.0, 1500.0]


@pytest.fixture(scope="module")
def cfg():
    return load_config(default_config_path(), overrides={"simulation.real_time_factor": 0.0})


def stamp_s(t) -> float:
    return t.sec + 1e-9 * t.nanosec


class Probe:
    """A node under test: use_sim_time, subscribes to the simulator's outputs."""

    def __init__(self, ctx):
        self.node = rclpy.create_node("probe", context=ctx,
                                      parameter_overrides=[Parameter("use_sim_time", value=True)])
        self.clock, self.odom, self.wrench, self.contact = [], [], [], []
        self.node.create_subscription(Clock, "/clock", lambda m: self.clock.append(stamp_s(m.clock)), 10)
        self.node.create_subscription(Odometry, "sim/odometry", self.odom.append, 50)
        self.node.create_subscription(WrenchStamped, "sim/wrench", self.wrench.append, 50)
        self.node.create_subscription(DiagnosticArray, "sim/contact", self.contact.append, 10)
        self.pub = self.node.create_publisher(ThrusterPwm, "thrusters/pulse_width", 10)

    def send(self, widths, armed=True):
        msg = ThrusterPwm(pulse_width_us=[float(w) for w in widths], armed=armed)
        msg.header.frame_id = "base_link"
        self.pub.publish(msg)


def make(ctx, cfg, **kwargs):
    sim_node = SimulatorNode(config=cfg, context=ctx, **kwargs)
    probe = Probe(ctx)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(sim_node)
    ex.add_node(probe.node)
    history = {}
    sim_node.add_step_listener(lambda s: history.__setitem__(round(s.t_s, 6), (s.position_ned_m, s.quaternion_xyzw,
                                                                               s.nu, s.contact.faces)))
    return sim_node, probe, ex, history


def spin_until(ex, predicate, timeout_s=20.0, message="condition"):
    return wait_until(predicate, timeout_s, poll=lambda: ex.spin_once(timeout_sec=0.01), message=message)


def close(ex, *nodes):
    ex.shutdown()
    for n in nodes:
        n.destroy_node()


def test_clock_and_ground_truth_follow_the_model(cfg):
    with ros_context() as ctx:
        sim_node, probe, ex, history = make(ctx, cfg)
        try:
            spin_until(ex, lambda: sim_node.count_subscribers("/clock") >= 1 and probe.clock, message="first /clock")
            spin_until(ex, lambda: sim_node.count_publishers("thrusters/pulse_width") >= 1, message="pwm publisher")
            probe.send(SURGE_PW)
            spin_until(ex, lambda: probe.clock and probe.clock[-1] >= 6.0, message="6 s of simulated time")
            # /clock advances monotonically in steps of the clock period, and the probe's ROS time follows it
            clk = np.array(probe.clock)
            assert np.all(np.diff(clk) > 0)
            assert np.allclose(np.diff(clk), 1.0 / cfg.simulation.clock_rate_hz, atol=1e-6)
            assert probe.node.get_clock().now().nanoseconds * 1e-9 == pytest.approx(clk[-1], abs=0.02)
            # odometry: pose in odom ENU, twist in base_link FLU, both converted with the frames module
            assert len(probe.odom) > 100
            for msg in probe.odom[-40:]:
                pos, quat, nu, _faces = history[round(stamp_s(msg.header.stamp), 6)]
                assert msg.header.frame_id == "odom" and msg.child_frame_id == "base_link"
                p = msg.pose.pose.position
                assert np.allclose([p.x, p.y, p.z], frames.ned_to_enu(pos), atol=1e-9)
                o = msg.pose.pose.orientation
                q_ros = frames.quaternion_marine_to_ros(quat)
                assert abs(abs(np.dot([o.x, o.y, o.z, o.w], q_ros)) - 1.0) < 1e-9
                lin, ang = msg.twist.twist.linear, msg.twist.twist.angular
                assert np.allclose([lin.x, lin.y, lin.z, ang.x, ang.y, ang.z], frames.twist_frd_to_flu(nu), atol=1e-9)
            # the commanded surge moved the vehicle forward = north = ENU +y (start heading 0)
            last = probe.odom[-1]
            start = cfg.pool.start_position_ned_m
            assert last.pose.pose.position.y - start[0] > 0.5
            assert last.twist.twist.linear.x > 0.2
            # true wrench in base_link FLU: surge 2 F cos 55 deg, no sway force, no yaw moment ([Hindrax-Drag] §4.1)
            w = probe.wrench[-1]
            c4, c3, c2, c1 = cfg.thrusters.curve_positive
            f_one = c4 * 1700.0 ** 3 + c3 * 1700.0 ** 2 + c2 * 1700.0 + c1
            assert w.header.frame_id == "base_link"
            assert w.wrench.force.x == pytest.approx(2 * f_one * math.cos(math.radians(55)), rel=1e-4)
            assert abs(w.wrench.force.y) < 1e-9 and abs(w.wrench.torque.z) < 1e-9
            # contact report: one status per face, WARN exactly for the faces the model reports in contact
            assert len(probe.contact) >= 6  # once per simulated second at least
            for msg in probe.contact:
                t = round(stamp_s(msg.header.stamp), 6)
                if t == 0.0:
                    continue
                assert len(msg.status) == 6
                warn = {s.name.rsplit("/", 1)[1] for s in msg.status if s.level == DiagnosticStatus.WARN}
                assert warn == set(history[t][3])
            # the vehicle released at the surface (start depth 0) sinks to its waterline: surface contact
            assert "surface" in history[round(stamp_s(probe.contact[-1].header.stamp), 6)][3]
        finally:
            close(ex, sim_node, probe.node)


def test_armed_false_bad_messages_and_deterministic_truth(cfg):
    with ros_context() as ctx:
        sim_node, probe, ex, _ = make(ctx, cfg)
        try:
            spin_until(ex, lambda: sim_node.count_publishers("thrusters/pulse_width") >= 1, message="pwm publisher")
            probe.send(SURGE_PW, armed=False)
            probe.send([1700.0] * 3)  # wrong length: ignored with a warning
            probe.send([float("nan")] * 8)  # non-finite: ignored
            spin_until(ex, lambda: probe.clock and probe.clock[-1] >= 2.0)
            assert np.allclose(sim_node.simulator.thrust_n, 0.0)
            assert probe.wrench[-1].wrench.force.x == 0.0
            assert sim_node.pulse_widths_us.tolist() == SURGE_PW  # the valid (disarmed) message was kept
        finally:
            close(ex, sim_node, probe.node)


def test_injected_pulse_width_source(cfg):
    calls = []

    def source():
        calls.append(1)
        return SURGE_PW

    with ros_context() as ctx:
        # the simulator node itself may be started with use_sim_time (a shared params file): it steps on the
        # steady clock, so it still runs
        sim_node, probe, ex, _ = make(ctx, cfg, pulse_width_source=source,
                                      parameter_overrides=[Parameter("use_sim_time", value=True)])
        try:
            assert sim_node.count_subscribers("thrusters/pulse_width") == 0  # the topic is not used
            spin_until(ex, lambda: probe.odom and stamp_s(probe.odom[-1].header.stamp) >= 3.0)
            assert probe.odom[-1].twist.twist.linear.x > 0.2
            assert len(calls) >= int(3.0 / cfg.simulation.step_s)  # polled before every step
        finally:
            close(ex, sim_node, probe.node)


def test_real_time_factor_limits_simulated_time(cfg):
    """With real_time_factor 1 the simulated time never runs ahead of the wall time."""
    import time

    rt = cfg.with_overrides({"simulation.real_time_factor": 1.0})
    with ros_context() as ctx:
        t0 = time.monotonic()  # before the node exists: its wall-clock anchor is set at construction
        sim_node, probe, ex, _ = make(ctx, rt)
        try:
            spin_until(ex, lambda: probe.clock and probe.clock[-1] >= 0.3)
            assert sim_node.simulator.t_s <= (time.monotonic() - t0) + 0.05
        finally:
            close(ex, sim_node, probe.node)


def test_step_gate_holds_simulated_time_until_it_opens(cfg):
    """Lock-step: a closed gate stops the clock at a /clock boundary; opening it lets time run on."""
    state = {"open_after_s": 0.5, "asked": []}

    def gate(t_s):
        state["asked"].append(t_s)
        return t_s < state["open_after_s"] - 1e-9

    with ros_context() as ctx:
        sim_node, probe, ex, _ = make(ctx, cfg)
        sim_node.add_step_gate(gate)
        try:
            spin_until(ex, lambda: state["asked"] and state["asked"][-1] >= 0.5 and len(state["asked"]) > 60)
            for _ in range(50):  # the executor keeps spinning; the simulation must not move
                ex.spin_once(timeout_sec=0.001)
            assert sim_node.simulator.t_s == pytest.approx(0.5, abs=1e-9)
            state["open_after_s"] = math.inf
            spin_until(ex, lambda: sim_node.simulator.t_s >= 1.0)
        finally:
            close(ex, sim_node, probe.node)


def test_a_stepped_simulation_holds_a_closed_gate_whatever_the_wall_time(cfg, monkeypatch):
    """Issue 72.4: stepped by its caller (``hindrax run``'s lock-step graph), a gate that refuses for longer than
    GATE_TIMEOUT_S of wall time (here the steady clock jumps a minute per reading) still holds simulated time: the
    step it allows never depends on how busy the machine is. Before, it stepped on after 10 s of wall time. On the
    node's own timer the override stays (a stalled node cannot freeze an interactive simulation)."""
    import itertools

    from hindrax_sim import node as sim_node_module

    with ros_context() as ctx:
        sim_node, probe, ex, _ = make(ctx, cfg)
        ex.remove_node(sim_node)  # stepped by this test, as Graph.spin_once does
        sim_node.add_step_gate(lambda t_s: False)
        clock = itertools.count(0.0, 60.0)
        monkeypatch.setattr(sim_node_module.time, "monotonic", lambda: float(next(clock)))
        try:
            assert not any(sim_node.advance_clock_period() for _ in range(50))
            assert sim_node.simulator.t_s == 0.0
            assert sim_node.advance_clock_period(override_gates=True) or \
                sim_node.advance_clock_period(override_gates=True)
            assert sim_node.simulator.t_s == pytest.approx(sim_node.clock_period_s)
        finally:
            close(ex, sim_node, probe.node)


def test_time_msg_rounding():
    assert time_msg(1.5).sec == 1 and time_msg(1.5).nanosec == 500_000_000
    m = time_msg(2.9999999999)
    assert (m.sec, m.nanosec) == (3, 0)


def test_node_runs_alone_from_the_params_file():
    """``python -m hindrax_sim.node --ros-args --params-file hindrax.yaml``: /clock advances; SIGINT
    ends it cleanly; an invalid parameter stops it with one line naming the key."""
    params = str(default_config_path())
    cmd = [python_executable(), "-m", "hindrax_sim.node", "--ros-args", "--params-file", params,
           "-p", "simulation.real_time_factor:=0.0"]
    with child_process(cmd, env=child_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) as proc:
        with ros_context() as ctx:
            node = rclpy.create_node("alone_probe", context=ctx)
            seen = []
            node.create_subscription(Clock, "/clock", lambda m: seen.append(stamp_s(m.clock)), 10)
            ex = SingleThreadedExecutor(context=ctx)
            ex.add_node(node)
            try:
                spin_until(ex, lambda: len(seen) > 5 and seen[-1] > seen[0], timeout_s=30.0, message="/clock")
            finally:
                close(ex, node)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=20)
        assert proc.returncode == 0, err
        assert "Traceback" not in err

    bad = subprocess.run(cmd + ["-p", "simulation.step_s:=5.0"], env=child_env(), capture_output=True, text=True,
                         timeout=30)
    assert bad.returncode == 1
    assert "simulation.step_s = 5.0" in bad.stderr and "Traceback" not in bad.stderr

