"""The controller node in the virtual pool graph (docs/control.md §3): refuses before arming, holds the current state,
follows depth and altitude setpoints (checked on the simulator's truth), and yields ``wrench`` to a pilot and to a
running identification goal; its estimate goes out as ``odom`` and ``odom -> base_link`` on ``/tf`` (REP-105); a bad
model file stops its start-up with one line (never the vehicle file's model in its place)."""
from __future__ import annotations

import math

import numpy as np
import pytest
import rclpy
from geometry_msgs.msg import WrenchStamped
from nav_msgs.msg import Odometry
from std_srvs.srv import SetBool, Trigger
from tf2_msgs.msg import TFMessage

from hindrax_common.config import default_config_path, load_config
from hindrax_common.testing import ros_context, wait_until
from hindrax_msgs.msg import ControllerStatus, ControlSetpoint, ManeuverStatus
from hindrax_msgs.srv import SetArmed


def _call(client, request, spin):
    f = client.call_async(request)
    wait_until(f.done, 20, spin, f"{client.srv_name} answer")
    return f.result()


@pytest.mark.ros
def test_controller_holds_depth_and_altitude_and_yields_wrench(tmp_path):
    with ros_context() as ctx:
        from hindrax_sim.graph.bringup import build_graph

        graph = build_graph(default_config_path(), sim=True, context=ctx, seed=5, controller=True, drive_clocks=True,
                            overrides={"esc.arming_time_s": 1.0, "simulation.real_time_factor": 0.0})
        probe = rclpy.create_node("pool_operator", context=ctx)
        graph.executor.add_node(probe)
        sim = graph.nodes["simulator"].simulator
        ctrl = graph.nodes["controller"]
        status: list[ControllerStatus] = []
        wrenches: list[WrenchStamped] = []
        probe.create_subscription(ControllerStatus, "controller/status", status.append, 100)
        probe.create_subscription(WrenchStamped, "wrench", wrenches.append, 100)
        odoms: list[Odometry] = []
        tfs: list[TFMessage] = []
        probe.create_subscription(Odometry, "odom", odoms.append, 100)
        probe.create_subscription(TFMessage, "/tf", tfs.append, 100)
        arm = probe.create_client(SetArmed, "esc/set_armed")
        hold = probe.create_client(Trigger, "controller/hold")
        enable = probe.create_client(SetBool, "controller/enable")
        setpoint = probe.create_publisher(ControlSetpoint, "controller/setpoint", 10)
        pilot = probe.create_publisher(WrenchStamped, "wrench", 10)
        ident = probe.create_publisher(ManeuverStatus, "identification/status", 10)
        spin = lambda: graph.spin_once(0.005)  # noqa: E731
        try:
            assert ctrl.model.source == "vehicle file"
            wait_until(lambda: hold.service_is_ready() and enable.service_is_ready(), 30, spin, "controller services")
            r = _call(hold, Trigger.Request(), spin)
            assert not r.success and "not armed" in r.message
            assert graph.start_and_arm(arm, 60).success
            wait_until(lambda: ctrl._armed, 30, spin, "ESC reporting armed")
            r = _call(hold, Trigger.Request(), spin)
            assert r.success, r.message
            wait_until(lambda: any(s.enabled for s in status), 10, spin, "enabled status")
            # depth 0.6 m, heading north
            sp = ControlSetpoint(vertical_mode=ControlSetpoint.VERTICAL_DEPTH, depth_m=0.6, hold_heading=True,
                                 heading_rad=0.0, hold_velocity=True)
            setpoint.publish(sp)
            t0 = sim.t_s
            wait_until(lambda: sim.t_s > t0 + 10.0, 120, spin, "10 s of holding")
            assert sim.position_ned_m[2] == pytest.approx(0.6, abs=0.03)
            assert abs(math.remainder(sim.euler_rad[2], 2 * math.pi)) < math.radians(3.0)
            # the estimate for ROS tools: odom (ENU, z up) -> base_link, holding 0.6 m deep, heading north (ENU +y)
            wait_until(lambda: odoms and tfs, 10, spin, "odom and /tf")
            o = odoms[-1]
            assert (o.header.frame_id, o.child_frame_id) == ("odom", "base_link")
            assert o.pose.pose.position.z == pytest.approx(-0.6, abs=0.05)
            q = o.pose.pose.orientation
            assert math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y ** 2 + q.z ** 2)) == \
                pytest.approx(math.pi / 2, abs=math.radians(5.0))
            t = next(x for m in tfs for x in m.transforms if x.child_frame_id == "base_link")
            assert t.header.frame_id == "odom"
            # altitude 1.0 m (Ping1D range): the pool is 1.8 m deep, the altimeter 0.18 m below base_link
            sp = ControlSetpoint(vertical_mode=ControlSetpoint.VERTICAL_ALTITUDE, altitude_m=1.0, hold_heading=True,
                                 heading_rad=0.0, hold_velocity=True)
            setpoint.publish(sp)
            t0 = sim.t_s
            wait_until(lambda: sim.t_s > t0 + 10.0, 120, spin, "10 s of altitude hold")
            ping_z = float(load_config(default_config_path()).sensors.ping1d.position_frd_m[2])
            assert 1.8 - (sim.position_ned_m[2] + ping_z) == pytest.approx(1.0, abs=0.03)
            assert status[-1].enabled and status[-1].vertical_mode == ControlSetpoint.VERTICAL_ALTITUDE
            # a pilot publishes: the controller yields and stops publishing
            w = WrenchStamped()
            w.header.frame_id = "base_link"
            w.header.stamp = probe.get_clock().now().to_msg()
            pilot.publish(w)
            wait_until(lambda: not ctrl.enabled, 10, spin, "yield to the pilot")
            assert "another source" in ctrl.message
            ours = lambda: [m for m in wrenches if m.header.stamp != w.header.stamp]  # noqa: E731
            t0 = sim.t_s
            wait_until(lambda: sim.t_s > t0 + 0.2, 30, spin, "messages in flight")
            n = len(ours())
            t0 = sim.t_s
            wait_until(lambda: sim.t_s > t0 + 1.0, 30, spin, "a second without the controller")
            assert len(ours()) == n  # nothing from the controller
            # enabled again on request; then an identification goal runs: it yields, and refuses to enable
            assert _call(enable, SetBool.Request(data=True), spin).success
            assert _tick_period_s(ctrl) == pytest.approx(ctrl.tick_s)  # enabled: control.rate_hz
            wait_until(lambda: len(ours()) > n + 5, 10, spin, "wrench again")
            streams = ("imu/data_raw", "dvl/data", "pressure/fluid_pressure", "ping/altitude", "allocation/status",
                       "wrench")
            subscribers = {t: probe.count_subscribers(t) for t in streams}
            ident.publish(ManeuverStatus(phase=ManeuverStatus.PHASE_RUNNING, dof="surge"))
            wait_until(lambda: not ctrl.enabled, 10, spin, "yield to the identification")
            assert "identification" in ctrl.message
            # while the goal runs the controller takes none of the streams (the graph sees one subscriber less each)
            wait_until(lambda: all(probe.count_subscribers(t) == subscribers[t] - 1 for t in streams), 10, spin,
                       "the controller's streams dropped")
            r = _call(enable, SetBool.Request(data=True), spin)
            assert not r.success and "identification goal is running" in r.message
            ident.publish(ManeuverStatus(phase=ManeuverStatus.PHASE_DONE))
            wait_until(lambda: not ctrl._ident_running, 10, spin, "identification done")
            # disabled: the sensors back, the pilot's wrench and the allocation's status only once enabled
            sensors = streams[:4]
            wait_until(lambda: all(probe.count_subscribers(t) == subscribers[t] for t in sensors), 10, spin,
                       "the controller's sensor streams back")
            assert all(probe.count_subscribers(t) == subscribers[t] - 1 for t in streams[4:])
            wait_until(lambda: {"ms5837", "dvl75_attitude", "icm20948_gyro"} <= set(ctrl._last_sample_s), 10, spin,
                       "fresh sensor data after the goal")
            assert _call(enable, SetBool.Request(data=True), spin).success
            wait_until(lambda: all(probe.count_subscribers(t) == subscribers[t] for t in streams), 10, spin,
                       "every stream of an enabled controller")
            assert _call(enable, SetBool.Request(data=False), spin).success
            assert not ctrl.enabled
            def last_is_zero():
                x = wrenches[-1].wrench
                return np.allclose([x.force.x, x.force.y, x.force.z, x.torque.x, x.torque.y, x.torque.z], 0.0)

            wait_until(last_is_zero, 10, spin, "a zero wrench after the disable on request")
            assert any("Kp" in line for line in status[-1].gain_report)
        finally:
            graph.shutdown()
            probe.destroy_node()


@pytest.mark.ros
def _tick_period_s(node) -> float:
    """The period of the one tick timer of a ControllerNode that runs (the others are cancelled), s."""
    running = [t for t in (node._tick_timer, node._idle_timer, node._goal_timer) if not t.is_canceled()]
    assert len(running) == 1, f"{len(running)} tick timers running"
    return running[0].timer_period_ns * 1e-9


def test_main_runs_alone_exits_0_on_sigint_and_1_on_a_bad_parameter(tmp_path):
    """``python -m hindrax_onboard.control.node`` (what ``ros2 run hindrax_onboard controller_node`` runs): ready with
    the vehicle file's model, SIGINT -> 0; a bad ``control.*`` value, or a model file of another vehicle (never a
    silent fallback, issue 45.4) -> 1 with one line naming key, value and allowed range."""
    import subprocess

    import yaml

    from hindrax_common.testing import child_env, child_process, interrupt, python_executable

    other = tmp_path / "identification.yaml"
    other.write_text(yaml.safe_dump({"schema_version": 1, "provenance": {"configuration_sha256": "0" * 64},
                                     "dofs": {"heave": {"inertia": {"value": 50.0, "std": 1.0, "unit": "kg"}}}}))
    cmd = [python_executable(), "-m", "hindrax_onboard.control.node", "--ros-args", "--params-file",
           str(default_config_path())]
    bad = subprocess.run(cmd + ["-p", "control.hold_fraction:=1.5"], env=child_env(), capture_output=True, text=True,
                         timeout=60)
    assert bad.returncode == 1, bad.stderr
    assert bad.stderr.splitlines()[-1] == ("invalid configuration: parameters of controller (from "
                                           f"{default_config_path()}): control.hold_fraction = 1.5: allowed number in "
                                           "[0.05, 1]")
    refused = subprocess.run(cmd + ["-p", f"model_file:={other}"], env=child_env(), capture_output=True, text=True,
                             timeout=60)
    assert refused.returncode == 1, refused.stderr
    last = refused.stderr.splitlines()[-1]
    assert last.startswith("invalid configuration: ") and "model_file = " in last and str(other) in last
    assert "another vehicle" in last
    with child_process(cmd, env=child_env(), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True) as proc:
        lines = []
        for line in proc.stdout:  # the node logs once when ready
            lines.append(line)
            if "controller ready" in line:
                break
        text = "".join(lines)
        assert "controller ready (disabled): model vehicle file" in text, text
        assert interrupt(proc, 30) == 0, proc.stdout.read()


@pytest.mark.ros
def test_on_the_system_clock_the_inputs_are_callbacks_and_streams_drop_while_a_goal_runs():
    """On the system clock (the vehicle) the controller's topic inputs are subscription callbacks of the node itself,
    as with use_sim_time (issue 47 item 1: one input path): the armed flag and sensor samples arrive at once (counted at
    their arrival), and a running identification goal drops the sensor streams, an idle one opens them again."""
    import time

    from rclpy.executors import SingleThreadedExecutor
    from sensor_msgs.msg import Imu

    from hindrax_onboard.control.node import ControllerNode
    from diagnostic_msgs.msg import DiagnosticStatus, KeyValue

    from hindrax_common.node_support.esc_state import ESC_STATE_TOPIC, esc_state_qos

    with ros_context() as ctx:
        node = ControllerNode(config=load_config(default_config_path()), context=ctx, model_file="")
        probe = rclpy.create_node("probe", context=ctx)
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(node)
        ex.add_node(probe)
        try:
            # disabled: the sensors; /allocation/status and /wrench (a pilot) only while enabled
            streams = {"/dvl/data", "/pressure/fluid_pressure", "/imu/data_raw", "/ping/altitude"}
            inputs = streams | {"/identification/status", "/esc/output_state"}
            topics = lambda: {s.topic_name for s in node.subscriptions} - {"/controller/setpoint"}  # noqa: E731
            assert topics() == inputs and "controller_intake" not in probe.get_node_names()
            esc = probe.create_publisher(DiagnosticStatus, ESC_STATE_TOPIC, esc_state_qos())
            imu = probe.create_publisher(Imu, "imu/data_raw", 10)
            status = probe.create_publisher(ManeuverStatus, "identification/status", 10)
            spin = lambda: ex.spin_once(timeout_sec=0.01)  # noqa: E731
            wait_until(lambda: all(p.get_subscription_count() == 1 for p in (esc, imu, status)), 10, spin,
                       "subscriptions matched")
            t0 = time.time_ns() * 1e-9
            esc.publish(DiagnosticStatus(values=[KeyValue(key="output_state", value="1"),
                                                 KeyValue(key="armed", value="true")]))
            m = Imu()
            m.header.stamp = probe.get_clock().now().to_msg()
            imu.publish(m)
            wait_until(lambda: node._armed and "icm20948_gyro" in node._last_sample_s, 10, spin, "taken")
            assert t0 <= node._last_sample_s["icm20948_gyro"] <= time.time_ns() * 1e-9
            status.publish(ManeuverStatus(phase=ManeuverStatus.PHASE_RUNNING))
            wait_until(lambda: not streams & topics(), 10, spin, "streams dropped while the goal runs")
            # the latched armed flag stays subscribed (about 1 message/s)
            assert node._ident_running and topics() == {"/identification/status", "/esc/output_state"}
            assert node._armed_seen and node._armed
            status.publish(ManeuverStatus(phase=ManeuverStatus.PHASE_IDLE))
            wait_until(lambda: topics() == inputs, 10, spin, "streams open again")
            assert "no data yet" in str(node._refusal())  # the hold waits for fresh samples after the goal
            esc.publish(DiagnosticStatus())  # malformed: read as disarmed, counted
            wait_until(lambda: node.esc_state_malformed == 1, 10, spin, "malformed state counted")
            assert "not armed" in str(node._refusal())
        finally:
            ex.shutdown()
            probe.destroy_node()
            node.destroy_node()


def test_disabled_the_controller_conditions_one_imu_message_in_idle_imu_every():
    """The IMU arrives as CDR bytes: disabled, one message in IDLE_IMU_EVERY is decoded and conditioned (the odometry's
    10 Hz), the first one included; enabled, every one. A conditioned sample is the rclpy message's."""
    import numpy as np
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import Imu

    from hindrax_onboard.control.node import IDLE_IMU_EVERY, ControllerNode
    from hindrax_onboard.vehicle.signals import samples_from_imu

    with ros_context() as ctx:
        node = ControllerNode(config=load_config(default_config_path()), context=ctx, model_file="")
        try:
            m = Imu()
            m.header.stamp.sec, m.header.stamp.nanosec = 5, 250_000_000
            m.angular_velocity.x, m.angular_velocity.z = 0.1, -0.25
            m.linear_acceleration.z = 9.81
            data = serialize_message(m)
            gyro = lambda: [s for d, s in node._pending if d == "icm20948_gyro"]  # noqa: E731
            for _ in range(2 * IDLE_IMU_EVERY):
                node._on_imu(data)
            assert len(gyro()) == 2 and len(node._pending) == 4  # the 1st and the (IDLE_IMU_EVERY + 1)-th
            want = dict(samples_from_imu(m, node._mount_t))
            assert gyro()[0].stamp_s == 5.25
            assert np.allclose(gyro()[0].angular_rate_rad_s, want["icm20948_gyro"].angular_rate_rad_s)
            node._pending = []
            node.enabled = True
            for _ in range(3):
                node._on_imu(data)
            assert len(gyro()) == 3
        finally:
            node.destroy_node()


@pytest.mark.ros
def test_on_the_system_clock_the_tick_slows_while_a_goal_runs_and_resumes_after():
    """Under the vehicle's executor (rclpy's EventsExecutor, system clock) the disabled controller ticks every
    ODOM_PERIOD_S (10 Hz, not ``control.rate_hz``: idle work), at 1 / GOAL_TICK_S (5 Hz) while an identification goal
    runs, and at 10 Hz again once it ends (``control.rate_hz`` while enabled:
    ``test_controller_holds_depth_and_altitude_and_yields_wrench``).

    The rate is read where the node decides it, the period of the one tick timer that runs (load-independent); the
    ticks counted in wall time are bounded from above only (a loaded machine delivers fewer, never more) and must
    keep coming in each phase."""
    import time

    from rclpy.experimental.events_executor import EventsExecutor

    from hindrax_onboard.control.node import GOAL_TICK_S, ODOM_PERIOD_S, ControllerNode

    cfg = load_config(default_config_path())
    with ros_context() as ctx:
        node = ControllerNode(config=cfg, context=ctx, model_file="")
        ticks = {"n": 0}
        odometry = node._publish_odometry

        def counted(t: float) -> None:
            ticks["n"] += 1
            odometry(t)

        node._publish_odometry = counted  # the last thing every tick does
        probe = rclpy.create_node("probe", context=ctx)
        status = probe.create_publisher(ManeuverStatus, "identification/status", 10)
        ex = EventsExecutor(context=ctx)
        ex.add_node(node)
        ex.add_node(probe)
        spin = lambda: ex.spin_once(timeout_sec=0.01)  # noqa: E731

        def ticks_in(seconds: float) -> int:
            n0, t0 = ticks["n"], time.monotonic()
            wait_until(lambda: time.monotonic() - t0 >= seconds, seconds + 5, spin, f"{seconds} s of ticks")
            return ticks["n"] - n0

        tick_period_s = lambda: _tick_period_s(node)  # noqa: E731
        def ticking() -> None:
            n0 = ticks["n"]
            wait_until(lambda: ticks["n"] >= n0 + 3, 30, spin, "three ticks")

        try:
            wait_until(lambda: status.get_subscription_count() == 1 and ticks["n"] >= 3, 10, spin, "matched")
            rate = 1.0 / ODOM_PERIOD_S
            assert rate < cfg.control.rate_hz and tick_period_s() == pytest.approx(ODOM_PERIOD_S)
            assert ticks_in(1.0) <= 1.1 * rate
            status.publish(ManeuverStatus(phase=ManeuverStatus.PHASE_RUNNING))
            wait_until(lambda: node._ident_running, 5, spin, "the goal seen")
            assert tick_period_s() == pytest.approx(GOAL_TICK_S)
            ticking()
            slow = ticks_in(2.0)
            assert slow <= 2.0 * 2.0 / GOAL_TICK_S, slow  # 10 Hz would give 20
            status.publish(ManeuverStatus(phase=ManeuverStatus.PHASE_IDLE))
            wait_until(lambda: not node._ident_running, 5, spin, "the goal's end seen")
            assert tick_period_s() == pytest.approx(ODOM_PERIOD_S)
            ticking()
            assert ticks_in(1.0) <= 1.1 * rate
        finally:
            ex.shutdown()
            probe.destroy_node()
            node.destroy_node()


def test_a_starved_tick_stops_the_hold_naming_the_starvation():
    """Injected delay: the controller's tick held off 1.2 s (beyond twice thrusters.wrench_timeout_s, 0.5 s) while
    enabled. It disables itself saying "controller starved for 1.2 s" and sends one zero wrench, instead of
    leaving the allocation to drop its last wrench as stale. The node's tick is driven directly."""
    import time

    from hindrax_onboard.control.node import ControllerNode

    cfg = load_config(default_config_path())
    with ros_context() as ctx:
        node = ControllerNode(config=cfg, context=ctx, model_file="")
        sent: list = []
        node._publish_wrench = lambda w: sent.append(np.asarray(w))
        try:
            node._on_tick()
            time.sleep(1.2)  # the injected delay: the process held off its tick (what this test is about)
            node.enabled = True
            node._on_tick()
            assert not node.enabled and node.message.startswith("stopped: controller starved for 1.2"), node.message
            assert f"beyond {2 * cfg.thrusters.wrench_timeout_s:g} s: twice thrusters.wrench_timeout_s" in node.message
            assert len(sent) == 1 and not np.any(sent[0])
        finally:
            node.destroy_node()
