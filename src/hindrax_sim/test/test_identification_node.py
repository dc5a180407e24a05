"""Identification node: ROS message adapters (frames, reversal) and the run_identification action on the
virtual pool (goal validation, refusal while disarmed, feedback, HydroEstimate >= 1 Hz, cancel -> neutral)."""

import time
from types import SimpleNamespace

import numpy as np
import pytest
import rclpy
from action_msgs.msg import GoalStatus
from geometry_msgs.msg import WrenchStamped
from rclpy.action import ActionClient
from sensor_msgs.msg import Imu, Range

from hindrax_common.base import frames
from hindrax_bringup.allocation.core import AllocationCore
from hindrax_common.config import default_config_path, load_config
from hindrax_common.testing import ros_context, wait_until
from hindrax_sim.graph.bringup import build_graph
from hindrax_onboard.identification.online.executive import ordered_samples
from hindrax_onboard.vehicle.signals import (sample_from_range, samples_from_dvl, samples_from_imu,
                                             thrust_of_written_widths)
from hindrax_msgs.action import RunIdentification
from hindrax_msgs.msg import Dvl, HydroEstimate, ManeuverStatus, ThrusterPwm
from hindrax_msgs.srv import SetArmed


def test_dvl_message_becomes_frd_velocity_and_ned_attitude():
    m = Dvl()
    m.header.stamp.sec, m.header.stamp.nanosec = 12, 500_000_000
    m.velocity_m_s.x, m.velocity_m_s.y, m.velocity_m_s.z = 0.4, 0.1, -0.05  # forward, left, down (FLU)
    m.velocity_valid = True
    rpy = [0.1, -0.2, 1.0]  # roll, pitch, yaw of body FRD in NED
    q = frames.quaternion_marine_to_ros(frames.quaternion_from_euler_ned(rpy))
    m.orientation.x, m.orientation.y, m.orientation.z, m.orientation.w = (float(v) for v in q)
    (att_dev, att), (vel_dev, vel) = samples_from_dvl(m)
    assert (att_dev, vel_dev) == ("dvl75_attitude", "dvl75")
    assert att.stamp_s == pytest.approx(12.5) and vel.stamp_s == pytest.approx(12.5)
    assert [att.roll_rad, att.pitch_rad, att.yaw_rad] == pytest.approx(rpy, abs=1e-9)
    assert vel.locked and vel.velocity_frd_m_s == pytest.approx([0.4, -0.1, 0.05])  # FRD: right and down +
    # with the $DVPDL interval known, the attitude (from the ping's $DVEXT) is dated at the end of the interval
    m.delta_time_s = 0.1
    (_, att), (_, vel) = samples_from_dvl(m)
    assert att.stamp_s == pytest.approx(12.55) and vel.stamp_s == pytest.approx(12.5)
    m.velocity_valid = False
    m.orientation.x = m.orientation.y = m.orientation.z = m.orientation.w = 0.0  # DVL gave no attitude
    (dev, s), = samples_from_dvl(m)
    assert dev == "dvl75" and not s.locked and np.all(np.isnan(s.velocity_frd_m_s))


def test_imu_and_range_messages():
    imu = Imu()
    imu.angular_velocity.z = 0.3          # turning left (FLU)
    imu.linear_acceleration.z = 9.81      # at rest: specific force up
    (g_dev, g), (a_dev, a) = samples_from_imu(imu)
    assert (g_dev, a_dev) == ("icm20948_gyro", "icm20948_accel")
    assert g.angular_rate_rad_s == pytest.approx([0, 0, 0.3]) and a.specific_force_m_s2 == pytest.approx([0, 0, 9.81])
    r = Range(range=0.9, min_range=0.3, max_range=50.0)
    assert sample_from_range(r)[1].valid and sample_from_range(r)[1].distance_m == pytest.approx(0.9)
    assert not sample_from_range(Range(range=float("nan"), min_range=0.3, max_range=50.0))[1].valid
    assert not sample_from_range(Range(range=0.1, min_range=0.3, max_range=50.0))[1].valid


def test_samples_are_ordered_late_ones_moved_and_impossible_ones_left_out():
    s = lambda t: SimpleNamespace(stamp_s=t)  # noqa: E731
    samples = [("imu", s(10.02)), ("dvl", s(9.95)), ("ping", s(1.8e9)), ("ms5837", s(10.01)), ("imu", s(3.0))]
    out = ordered_samples(samples, not_before_s=10.0, not_after_s=10.02 + 1.0, drop_before_s=10.0 - 2.0)
    assert [d for d, _ in out] == ["dvl", "ms5837", "imu"]  # by stamp; 1.8e9 (future) and 3.0 (stale) left out
    assert [x.stamp_s for _, x in out] == [10.0, 10.01, 10.02]  # the late DVL report moved to the previous tick
    assert samples[1][1].stamp_s == 9.95  # a copy: the caller's sample keeps its stamp
    assert [d for d, _ in ordered_samples(samples)] == ["imu", "dvl", "ms5837", "imu", "ping"]  # no bounds: all


def test_force_from_written_widths_undoes_the_esc_reversal_and_trim():
    cfg = load_config(default_config_path())
    core = AllocationCore(cfg)
    curve = core.allocator.curves[0]
    n = len(cfg.thrusters.thrusters)
    rev = [t.reversed for t in cfg.thrusters.thrusters]
    trim = np.array([t.trim_us for t in cfg.thrusters.thrusters])
    logical = np.full(n, 1650.0)  # forward thrust on every thruster
    wire = np.where(rev, 3000.0 - logical, logical) + trim  # what EscOutput writes (pca9685/node.py)
    f = thrust_of_written_widths(cfg, curve, wire)
    assert np.all(f > 0) and f == pytest.approx(np.full(n, float(curve.thrust_n(1650.0))))
    assert thrust_of_written_widths(cfg, curve, np.full(n, 1500.0) + trim * 0) == pytest.approx(np.zeros(n), abs=0.2)
    with pytest.raises(ValueError, match="expected"):
        thrust_of_written_widths(cfg, curve, [1500.0])


@pytest.mark.ros
def test_action_validates_refuses_disarmed_reports_and_cancels_to_neutral():
    with ros_context() as ctx:
        graph = build_graph(default_config_path(), sim=True, context=ctx, seed=3,
                            overrides={"esc.arming_time_s": 1.0, "simulation.real_time_factor": 0.0})
        probe = rclpy.create_node("probe", context=ctx)
        graph.executor.add_node(probe)
        got = {"est": [], "status": [], "wrench": [], "pwm": [], "fb": []}
        probe.create_subscription(HydroEstimate, "identification/estimates", got["est"].append, 50)
        probe.create_subscription(ManeuverStatus, "identification/status", got["status"].append, 100)
        probe.create_subscription(WrenchStamped, "wrench", got["wrench"].append, 100)
        probe.create_subscription(ThrusterPwm, "thrusters/pulse_width", got["pwm"].append, 100)
        arm = probe.create_client(SetArmed, "esc/set_armed")
        action = ActionClient(probe, RunIdentification, "run_identification")
        spin = lambda: graph.spin_once(0.005)  # noqa: E731
        sim = graph.nodes["simulator"].simulator
        try:
            wait_until(action.server_is_ready, 30, spin, "action server")
            # unknown DOF and out-of-range fractions: rejected
            for goal in (RunIdentification.Goal(dofs=["swirl"]),
                         RunIdentification.Goal(dofs=["surge"], level_fractions=[1.5])):
                f = action.send_goal_async(goal)
                wait_until(f.done, 10, spin, "goal answer")
                assert not f.result().accepted
            # disarmed: the goal fails at once, nothing is commanded
            f = action.send_goal_async(RunIdentification.Goal(dofs=["surge"]))
            wait_until(f.done, 10, spin, "goal answer")
            r = f.result().get_result_async()
            wait_until(r.done, 10, spin, "result")
            assert not r.result().result.success and "armed" in r.result().result.message
            assert not any(abs(w.wrench.force.x) > 0 for w in got["wrench"])

            wait_until(lambda: graph.nodes["esc"].arming_remaining_s() == 0.0, 30, spin, "arming time")
            a = arm.call_async(SetArmed.Request(arm=True))
            wait_until(a.done, 10, spin, "arm")
            assert a.result().success
            wait_until(lambda: got["pwm"] and got["pwm"][-1].armed, 10, spin, "armed")
            f = action.send_goal_async(RunIdentification.Goal(dofs=["surge"], level_fractions=[0.6]),
                                       feedback_callback=lambda fb: got["fb"].append(fb.feedback))
            wait_until(f.done, 10, spin, "goal answer")
            handle = f.result()
            assert handle.accepted
            running = lambda: any(s.phase == ManeuverStatus.PHASE_RUNNING for s in got["status"])  # noqa: E731
            wait_until(running, 300, spin, "surge run under way")  # wall time: slow under load
            second = action.send_goal_async(RunIdentification.Goal(dofs=["heave"]))
            wait_until(second.done, 10, spin, "second goal answer")
            assert not second.result().accepted  # a campaign runs: refused, and the first goes on (below)
            t_run = sim.t_s
            wait_until(lambda: sim.t_s > t_run + 2.0, 30, spin, "two seconds of the run")
            # a publisher on another clock (a second graph on the system clock in this domain): its samples are
            # left out and counted, the campaign goes on (it stopped with "time went backwards" before)
            foreign = probe.create_publisher(Imu, "imu/data_raw", 10)
            node = graph.nodes["identification"]
            for stamp_s in (time.time(), max(0.0, sim.t_s - 100.0)):
                m = Imu()
                m.header.frame_id = "imu_link"
                m.header.stamp.sec, m.header.stamp.nanosec = int(stamp_s), int((stamp_s % 1.0) * 1e9)
                m.linear_acceleration.z = 9.81
                foreign.publish(m)
            wait_until(lambda: node.samples_dropped >= 4, 30, spin, "foreign IMU samples left out")  # gyro + accel
            t_foreign = sim.t_s
            wait_until(lambda: sim.t_s > t_foreign + 0.5, 30, spin, "the run going on")
            # the running campaign's goal reads ACCEPTED: the node executes it only at its end (node docstring)
            assert handle.status == GoalStatus.STATUS_ACCEPTED
            fb = [x for x in got["fb"] if x.level_command != 0.0]
            assert fb and fb[-1].dof == "surge" and fb[-1].level_count == 1 and 0.0 < fb[-1].progress < 1.0
            # the level is 0.6 of the surge authority, pushed forward or backward along the body x axis
            forces = [w.wrench.force.x for w in got["wrench"][-20:]]
            assert max(abs(x) for x in forces) > 0.5 * abs(fb[-1].level_command)
            est = [e for e in got["est"] if e.dof == "surge"]
            assert est and est[-1].parameter_names[:2] == ["inertia", "quadratic_damping"]
            stamps = [e.header.stamp.sec + 1e-9 * e.header.stamp.nanosec for e in got["est"]]
            assert len(stamps) >= 2 and max(np.diff(stamps)) <= 1.0 + 0.05  # at least 1 Hz
            cancel = handle.cancel_goal_async()
            wait_until(cancel.done, 10, spin, "cancel answer")
            res = handle.get_result_async()
            wait_until(res.done, 30, spin, "result after cancel")
            assert not res.result().result.success and "cancel" in res.result().result.message
            assert res.result().status == GoalStatus.STATUS_CANCELED
            assert got["wrench"][-1].wrench.force.x == 0.0 and got["wrench"][-1].wrench.force.z == 0.0
            n_wrench = len(got["wrench"])
            t_end = sim.t_s
            wait_until(lambda: sim.t_s > t_end + 1.0, 30, spin, "a second after the cancel")
            assert len(got["wrench"]) == n_wrench  # no more commands after the neutral one
            assert got["pwm"][-1].pulse_width_us == pytest.approx([1500.0] * 8, abs=1.3)  # neutral thrust
            assert got["status"][-1].phase in (ManeuverStatus.PHASE_ABORTED, ManeuverStatus.PHASE_IDLE)
        finally:
            graph.shutdown()
            probe.destroy_node()


def _stand_in_handle(k: int) -> SimpleNamespace:
    """A goal handle stand-in (goal id ``[k] * 16``, a surge goal) recording its terminal states and results."""
    from unique_identifier_msgs.msg import UUID

    h = SimpleNamespace(request=RunIdentification.Goal(dofs=["surge"]), is_cancel_requested=False,
                        goal_id=UUID(uuid=[k] * 16), states=[], results=[], publish_feedback=lambda _fb: None)
    h.abort, h.succeed = (lambda: h.states.append("aborted")), (lambda: h.states.append("succeeded"))
    h.canceled = lambda: h.states.append("canceled")
    h.execute = lambda cb: h.results.append(cb(h))
    return h


def test_a_goal_waits_for_the_armed_flag_within_its_grace_and_fails_without_commanding_after_it():
    """An operator who arms and starts at once: the goal is accepted while the ESC's armed flag is on its way and
    goes on once it arrives; without it (ARMED_REPORTS disarmed reports since the acceptance) the goal ends after
    ARMED_GRACE_S with the "not armed" result, having commanded nothing. The node's own callbacks are driven directly
    (no graph), with a stand-in goal handle."""
    from hindrax_onboard.identification.online.core import ARMED_GRACE_S, ARMED_REPORTS, NOT_ARMED
    from hindrax_onboard.identification.online.node import IdentificationNode

    cfg = load_config(default_config_path())
    with ros_context() as ctx:
        node = IdentificationNode(config=cfg, context=ctx)
        wrenches, status = [], []
        node._publish_wrench = lambda w, now: wrenches.append(w)
        node._publish_status = lambda phase, st, message: status.append((phase, message))
        try:
            handle = _stand_in_handle
            armed = ThrusterPwm(pulse_width_us=[1500.0] * 8, armed=True)
            late = handle(1)
            node._on_accepted(late)
            node._on_tick()
            assert node.core.run is not None and status[-1][1] == "waiting for the ESC output to report armed"
            node._on_pwm(armed)  # the flag arrives within the grace: the goal goes on (to the sensors' wait)
            node._on_tick()
            assert node.core.run is not None and not late.results and status[-1][1] == "waiting for the sensors"
            node.core.run.ended = True  # leave this goal
            node.core.run = None

            node._on_pwm(ThrusterPwm(pulse_width_us=[1500.0] * 8, armed=False))
            never = handle(2)
            t0 = node._now_s()  # before the acceptance, which starts the grace
            node._on_accepted(never)
            for _ in range(ARMED_REPORTS):  # the ESC's reports since the acceptance say disarmed
                node._on_pwm(ThrusterPwm(pulse_width_us=[1500.0] * 8, armed=False))
            wait_until(lambda: node._on_tick() or never.results, 10 * ARMED_GRACE_S, None, "the goal's end")
            assert node._now_s() - t0 >= ARMED_GRACE_S
            assert never.states == ["aborted"] and never.results[0].message == NOT_ARMED
            assert not never.results[0].success and not wrenches and node.core.run is None
            assert status[-1] == (ManeuverStatus.PHASE_ABORTED, NOT_ARMED)
        finally:
            node.destroy_node()


def test_node_parameters_are_described_read_only_and_checked():
    from rclpy.parameter import Parameter

    from hindrax_common.config import ConfigError
    from hindrax_onboard.identification.online.node import IdentificationNode

    cfg = load_config(default_config_path())
    with ros_context() as ctx:
        node = IdentificationNode(config=cfg, context=ctx)
        try:
            d = node.describe_parameters(["stop_timeout_s"])[0]
            assert d.read_only and "neutral" in d.description
            assert not node.set_parameters([Parameter("stop_timeout_s", value=5.0)])[0].successful
            assert node.stop_timeout_s == 2.0
        finally:
            node.destroy_node()
        with pytest.raises(ConfigError, match="sensor_timeout_s = -1"):
            IdentificationNode(config=cfg, context=ctx, node_name="bad",
                               parameter_overrides=[Parameter("sensor_timeout_s", value=-1.0)])


def test_main_runs_alone_exits_0_on_sigint_and_1_on_a_bad_parameter():
    """``python -m hindrax_onboard.identification.online.node`` (run_node): ready, SIGINT -> status 0; an invalid node
    parameter -> status 1 with one line naming key, value and allowed range."""
    import subprocess

    from hindrax_common.testing import child_env, child_process, interrupt, python_executable

    cmd = [python_executable(), "-m", "hindrax_onboard.identification.online.node", "--ros-args", "--params-file",
           str(default_config_path())]
    bad = subprocess.run(cmd + ["-p", "sensor_timeout_s:=-1.0"], env=child_env(), capture_output=True, text=True,
                         timeout=60)
    assert bad.returncode == 1, bad.stderr
    assert bad.stderr.splitlines()[-1] == ("invalid configuration: parameters of identification: "
                                           "sensor_timeout_s = -1.0: allowed a number > 0")
    with child_process(cmd, env=child_env(), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True) as proc:
        lines = []
        for line in proc.stdout:  # the node logs once when ready
            lines.append(line)
            if "identification executive ready" in line:
                break
        assert lines and "ready" in lines[-1], "".join(lines)
        assert "ticks at 25 Hz, wrench at 25 Hz" in lines[-1]  # the vehicle file's estimate and command rates
        assert interrupt(proc, 30) == 0, proc.stdout.read()



def _node_and_probe(cfg, ctx):
    """An identification node and a bare probe node of ``ctx``, both on one single-threaded executor."""
    from rclpy.executors import SingleThreadedExecutor

    from hindrax_onboard.identification.online.node import IdentificationNode

    node = IdentificationNode(config=cfg, context=ctx)
    probe = rclpy.create_node("probe", context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    ex.add_node(probe)
    return node, probe, ex

def test_on_the_system_clock_the_inputs_are_callbacks_as_with_sim_time():
    """On the system clock (the vehicle) the node's five inputs are subscription callbacks of the node itself, as with
    use_sim_time (issue 47 item 1: one input path): each message reaches its handler once (armed flag, widths, sensor
    samples)."""


    cfg = load_config(default_config_path())
    with ros_context() as ctx:
        node, probe, ex = _node_and_probe(cfg, ctx)
        try:
            inputs = {"/dvl/data", "/pressure/fluid_pressure", "/imu/data_raw", "/ping/altitude",
                      "/thrusters/pulse_width"}
            assert not inputs & {s.topic_name for s in node.subscriptions}  # idle: none
            node._set_active(True)  # what an accepted goal does
            assert inputs <= {s.topic_name for s in node.subscriptions}
            assert "identification_intake" not in probe.get_node_names()
            pwm = probe.create_publisher(ThrusterPwm, "thrusters/pulse_width", 10)
            imu = probe.create_publisher(Imu, "imu/data_raw", 10)
            spin = lambda: ex.spin_once(timeout_sec=0.01)  # noqa: E731
            wait_until(lambda: pwm.get_subscription_count() == 1 and imu.get_subscription_count() == 1, 10, spin,
                       "subscriptions matched")
            pwm.publish(ThrusterPwm(pulse_width_us=[1600.0] * 8, armed=True))
            m = Imu()
            m.header.stamp = probe.get_clock().now().to_msg()
            imu.publish(m)
            wait_until(lambda: node.core.armed and any(d.startswith("icm20948") for d in node.core.seen), 10, spin,
                       "the armed flag and the IMU sample taken")
            assert node.core.written.tolist() == [1600.0] * 8 and node.core.pwm_count == 1
        finally:
            ex.shutdown()
            probe.destroy_node()
            node.destroy_node()


@pytest.mark.ros
def test_an_idle_node_takes_no_sensor_message_and_ticks_at_the_idle_period_before_and_after_a_goal():
    """Idle work: without a goal the node has none of the five input subscriptions and only its idle timer runs
    (IDLE_STATUS_PERIOD_S); an accepted goal opens them and the control tick, its end closes them again. The armed
    flag is known while idle from the ESC's latched ``esc/output_state``."""
    from diagnostic_msgs.msg import DiagnosticStatus, KeyValue

    from hindrax_common.node_support.esc_state import ESC_STATE_TOPIC, esc_state_qos
    from hindrax_onboard.identification.online.core import (ARMED_GRACE_S, ARMED_REPORTS, IDLE_STATUS_PERIOD_S,
                                                            NOT_ARMED)

    cfg = load_config(default_config_path())
    inputs = {"/dvl/data", "/pressure/fluid_pressure", "/imu/data_raw", "/ping/altitude", "/thrusters/pulse_width"}
    with ros_context() as ctx:
        node, probe, ex = _node_and_probe(cfg, ctx)

        def state() -> tuple[set, float]:
            """(input topics subscribed, period of the one timer that runs in s)."""
            running = [t for t in (node._timer, node._idle_timer) if not t.is_canceled()]
            assert len(running) == 1, f"{len(running)} tick timers running"
            return inputs & {s.topic_name for s in node.subscriptions}, running[0].timer_period_ns * 1e-9

        try:
            assert state() == (set(), pytest.approx(IDLE_STATUS_PERIOD_S))
            goal = _stand_in_handle(1)
            node._on_accepted(goal)
            assert state() == (inputs, pytest.approx(1.0 / cfg.identification.estimate_rate_hz))
            for _ in range(ARMED_REPORTS):  # the ESC's reports since the acceptance say disarmed
                node._on_pwm(ThrusterPwm(pulse_width_us=[1500.0] * 8, armed=False))
            wait_until(lambda: node._on_tick() or goal.results, 10 * ARMED_GRACE_S, None, "the goal's end")
            assert goal.results[0].message == NOT_ARMED
            assert state() == (set(), pytest.approx(IDLE_STATUS_PERIOD_S))
            esc = probe.create_publisher(DiagnosticStatus, ESC_STATE_TOPIC, esc_state_qos())
            esc.publish(DiagnosticStatus(values=[KeyValue(key="output_state", value="1"),
                                                 KeyValue(key="armed", value="true")]))
            wait_until(lambda: node.core.armed, 10, lambda: ex.spin_once(timeout_sec=0.01), "the latched armed flag")
        finally:
            ex.shutdown()
            probe.destroy_node()
            node.destroy_node()


def test_a_starved_control_tick_stops_the_goal_naming_the_starvation():
    """Injected delay: the node's control tick held off 1.2 s (beyond twice thrusters.wrench_timeout_s, 0.5 s) while
    a goal moves the vehicle. The node measures the gap on the steady clock and stops the goal naming the starvation
    as its reason, on supervisor/abort and its aborted status, then a zero wrench (the core's rule: core.starved). The
    node's callbacks are driven directly, the campaign a stand-in (test_identification_core.StandInExecutive)."""
    import importlib.util
    from pathlib import Path

    from hindrax_onboard.identification.online.core import NEEDED_SENSORS
    spec = importlib.util.spec_from_file_location(
        "core_cases", Path(__file__).parents[2] / "hindrax_onboard" / "test" / "test_identification_core.py")
    cases = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(cases)
    from hindrax_onboard.identification.online.node import IdentificationNode

    cfg = load_config(default_config_path())
    with ros_context() as ctx:
        node = IdentificationNode(config=cfg, context=ctx)
        node.core._executive = cases.StandInExecutive
        wrenches, status, aborts = [], [], []
        node._publish_wrench = lambda w, now: wrenches.append(np.asarray(w))
        node._publish_status = lambda phase, st, message: status.append((phase, message))
        node.pub_abort.publish = lambda m: aborts.append(m.data)
        try:
            node._on_accepted(_stand_in_handle(3))
            node._on_pwm(ThrusterPwm(pulse_width_us=[1500.0] * 8, armed=True))
            node.core.add_samples([(d, SimpleNamespace(stamp_s=node._now_s())) for d in NEEDED_SENSORS])
            node._on_tick()
            node._on_tick()
            assert node.core.run.executive.started and not aborts and np.any(wrenches[-1])
            time.sleep(1.2)  # the injected delay: the process held off its tick (what this test is about)
            node._on_tick()
            assert len(aborts) == 1 and aborts[0].startswith("identification starved for 1.2"), aborts
            assert "beyond 1 s: twice thrusters.wrench_timeout_s" in aborts[0]
            assert status[-1] == (ManeuverStatus.PHASE_ABORTED, aborts[0]) and not np.any(wrenches[-1])
        finally:
            node.destroy_node()
