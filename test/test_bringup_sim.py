"""The whole stack on the virtual pool, in one process: simulator -> emulators -> real drivers, and
wrench -> allocation -> ESC node -> PCA9685 registers -> thrust -> vehicle motion."""

import random
import time

import numpy as np
import pytest
import rclpy
from rclpy.parameter import Parameter
from geometry_msgs.msg import WrenchStamped
from sensor_msgs.msg import FluidPressure, Imu, Range

from hindrax_common.config import default_config_path
from hindrax_common.testing import ros_context, wait_until
from hindrax_sim.graph.bringup import build_graph
from hindrax_msgs.msg import Dvl, ThrusterPwm
from hindrax_msgs.srv import SetArmed

pytestmark = pytest.mark.ros


def test_drivers_read_the_simulated_vehicle_and_thrust_moves_it():
    """Drivers read the simulated vehicle; a wrench, armed, moves it (real-time factor 1: the graph on the wall clock).

    The widths are checked by waiting, while pushing, for a report armed and above neutral, not by reading the last
    report: on the wall clock a starved process (a loaded machine) can leave the ESC without a command for longer
    than its watchdog (``esc.watchdog_timeout_s``, 0.5 s, steady and ROS time) or the allocation without a wrench for
    ``thrusters.wrench_timeout_s``; both then write neutral, still armed, by design, until the next wrench. One such
    report came last once in two fresh-clone runs (neutral 1500.4 us, armed, after the vehicle had moved); beside
    two to four busy loops the gap between two pushes reached 0.26 s of simulated time, against 0.03 s quiet."""
    with ros_context() as ctx:
        graph = build_graph(default_config_path(), sim=True, context=ctx, seed=5,
                            overrides={"esc.arming_time_s": 1.0, "simulation.real_time_factor": 1.0,
                                       "pool.start_position_ned_m": [3.0, 3.0, 0.9]})
        probe = rclpy.create_node("probe", context=ctx)
        graph.executor.add_node(probe)
        got = {"dvl": [], "pressure": [], "imu": [], "ping": [], "pwm": []}
        probe.create_subscription(Dvl, "dvl/data", got["dvl"].append, 10)
        probe.create_subscription(FluidPressure, "pressure/fluid_pressure", got["pressure"].append, 10)
        probe.create_subscription(Imu, "imu/data_raw", got["imu"].append, 10)
        probe.create_subscription(Range, "ping/altitude", got["ping"].append, 10)
        probe.create_subscription(ThrusterPwm, "thrusters/pulse_width", got["pwm"].append, 10)
        wrench = probe.create_publisher(WrenchStamped, "wrench", 10)
        arm = probe.create_client(SetArmed, "esc/set_armed")
        sim = graph.nodes["simulator"].simulator
        surge_history = []  # (t_s, u): ground truth to compare each DVL report with at its own stamp
        graph.nodes["simulator"].add_step_listener(lambda s: surge_history.append((s.t_s, s.nu[0])))
        spin = lambda: graph.spin_once(0.005)  # noqa: E731
        try:
            wait_until(lambda: all(got[k] for k in ("dvl", "pressure", "imu", "ping")), 60, spin,
                       "all four drivers publishing from the emulators")
            truth = sim.truth()
            # pressure driver vs simulated depth of the pressure port (fresh water), within a few cm
            depth = (got["pressure"][-1].fluid_pressure - 101325.0) / (1000.0 * 9.81)
            assert depth == pytest.approx(truth.position_ned_m[2] - 0.10, abs=0.1)
            # IMU at rest-ish: specific force about +g upwards in base_link (FLU)
            assert got["imu"][-1].linear_acceleration.z == pytest.approx(9.81, abs=0.5)
            assert got["imu"][-1].orientation_covariance[0] == -1.0
            # altimeter: pool 1.8 m deep, sonar 0.18 m below the origin
            assert got["ping"][-1].range == pytest.approx(1.8 - truth.position_ned_m[2] - 0.18, abs=0.1)

            wait_until(lambda: graph.nodes["esc"].arming_remaining_s() == 0.0, 60, spin, "arming time")
            fut = arm.call_async(SetArmed.Request(arm=True))
            wait_until(fut.done, 10, spin, "arm answer")
            assert fut.result().success
            x0 = sim.truth().position_ned_m[0]

            def push():
                m = WrenchStamped()
                m.header.frame_id = "base_link"
                # stamped on the graph's simulated time (the probe runs on system time): the allocation rejects a
                # wrench stamped beyond thrusters.wrench_future_margin_s in its future
                m.header.stamp = graph.nodes["thrust_allocation"].get_clock().now().to_msg()
                m.wrench.force.x = 12.0  # forward, base_link
                wrench.publish(m)
                spin()

            wait_until(lambda: sim.nu[0] > 0.15, 60, push, "vehicle surging under commanded thrust")
            # the DVL's reports (stamped with the device's time of validity) follow the true surge velocity; the
            # serial stream may lag the simulation (more so on a loaded machine), so each report is compared with the
            # truth at its own stamp, and the wait is for 3 reports stamped while the vehicle moved
            def moving() -> list:
                t_hist, u_hist = np.array(surge_history).T
                return [m for m in got["dvl"] if m.velocity_valid
                        and np.interp(m.header.stamp.sec + m.header.stamp.nanosec * 1e-9, t_hist, u_hist) > 0.1]

            wait_until(lambda: len(moving()) >= 3, 60, push, "3 DVL reports stamped while surging")
            assert sim.truth().position_ned_m[0] > x0
            wait_until(lambda: got["pwm"][-1].armed and max(got["pwm"][-1].pulse_width_us) > 1550, 10, push,
                       "thrusters/pulse_width armed and above neutral while pushed")
            t_hist, u_hist = np.array(surge_history).T
            for m in moving():
                u_true = np.interp(m.header.stamp.sec + m.header.stamp.nanosec * 1e-9, t_hist, u_hist)
                assert m.velocity_m_s.x == pytest.approx(u_true, abs=0.1)
        finally:
            graph.shutdown()
            probe.destroy_node()
        # shutdown wrote neutral on every thruster channel
        assert np.allclose(graph.hardware.pulse_widths_us(), 1500.0, atol=1.3)


def test_hindrax_bringup_sim_command_starts_and_stops_cleanly():
    import subprocess
    import sys
    from pathlib import Path

    from hindrax_test_support.helpers import fresh_domain

    from hindrax_common.testing import child_env, child_process, interrupt

    hindrax = str(Path(sys.executable).with_name("hindrax"))
    # a domain of its own: the ESCs of this worker's earlier tests may still be in its domain's discovery caches,
    # and bringup refuses a domain with another ESC
    with fresh_domain() as fresh, child_process([hindrax, "bringup", "--sim", "--rtf", "1"],
                                             env=child_env(ROS_DOMAIN_ID=str(fresh)), stdout=subprocess.PIPE,
                                             stderr=subprocess.STDOUT, text=True) as proc:
        lines = []
        while not (lines and lines[-1].startswith("bringup:")):
            line = proc.stdout.readline()
            assert line, "bringup exited early: " + "".join(lines)
            lines.append(line)
        assert lines[-1].startswith("bringup: 12 nodes (simulator, dvl75, ping1d, ms5837, icm20948, esc, "
                                    "thrust_allocation, supervisor, output_guard, static_tf, gateway, "
                                    "identification), virtual pool"), lines[-1]
        assert interrupt(proc, 30) == 0


def _late_kernel(transport, rng: random.Random):
    """``transport.pump`` as on a loaded machine: a third of the time the bytes not handled yet are still in the
    kernel's pty buffer, and a wait shorter than 1 s without a byte gets none of them (returns False)."""
    real = transport.pump

    def pump(n_bytes: int, wait_s: float) -> bool:
        if wait_s < 1.0 and transport.status().bytes_handled < n_bytes and rng.random() < 1 / 3:
            return False
        return real(n_bytes, wait_s)
    return pump


def _stepped_run(seed: int, duration_s: float, disturbed: bool = False) -> dict:
    """Messages of a stepped graph (drive_clocks=True), as ``hindrax run`` builds it, over ``duration_s``
    simulated seconds with a constant surge wrench from 0.5 s; topic -> list of (simulated time received, ns,
    message repr). ``disturbed``: as on a loaded machine, a pty hands a third of the serial bytes over a second
    late (:func:`_late_kernel`) and the process stalls for up to 0.3 s before one callback in 50 (the steady-clock
    timers then run at other simulated instants)."""
    topics = {"dvl/data": Dvl, "pressure/fluid_pressure": FluidPressure, "imu/data_raw": Imu,
              "ping/altitude": Range, "thrusters/pulse_width": ThrusterPwm}
    got: dict = {t: [] for t in topics}
    with ros_context() as ctx:
        graph = build_graph(default_config_path(), sim=True, context=ctx, seed=seed, drive_clocks=True,
                            identification=False, overrides={"esc.arming_time_s": 0.3,
                                                             "simulation.real_time_factor": 0.0})
        assert graph.stepped
        probe = rclpy.create_node("probe", context=ctx, parameter_overrides=[Parameter("use_sim_time", value=True)])
        graph.nodes["simulator"].drive_clock(probe.get_clock())  # the probe's timer runs on simulated time too
        graph.executor.add_node(probe)
        for topic, cls in topics.items():
            probe.create_subscription(cls, topic, (lambda t: lambda m: got[t].append(
                (probe.get_clock().now().nanoseconds, repr(m))))(topic), 100)
        wrench = probe.create_publisher(WrenchStamped, "wrench", 10)
        arm = probe.create_client(SetArmed, "esc/set_armed")
        sim = graph.nodes["simulator"].simulator
        spin = lambda: graph.spin_once(0.005)  # noqa: E731
        if disturbed:
            rng = random.Random(7)
            for link in graph.hardware.serial_lock_steps.values():
                link.transport.pump = _late_kernel(link.transport, rng)
            run_callbacks = graph.spin_until_idle

            def stalled(max_callbacks: int = 100_000) -> int:  # one callback at a time, a stall before some
                for n in range(max_callbacks):
                    if rng.random() < 0.02:
                        time.sleep(rng.uniform(0.0, 0.3))
                    if not run_callbacks(1):
                        return n
                return max_callbacks

            graph.spin_until_idle = stalled
        try:
            graph.start_and_arm(arm, 60, spin_timeout_s=0.005)
            m = WrenchStamped()
            m.header.frame_id = "base_link"
            m.wrench.force.x = 20.0
            probe.create_timer(0.02, lambda: wrench.publish(m))  # on simulated time, like a controller
            wait_until(lambda: sim.t_s >= duration_s, 60, spin, f"{duration_s} s simulated")
        finally:
            graph.shutdown()
            probe.destroy_node()
    return got


def test_stepped_graph_gives_the_same_messages_when_serial_bytes_come_late_and_the_process_stalls():
    """Issue 72.4: on a loaded machine the lock-step graph receives every message at the same simulated instant,
    with the same content, as on a quiet one: serial bytes a pty hands over a second late and stalls of the process
    between callbacks (its steady-clock timers then run at other simulated instants) change nothing. Before, the
    tick gave up on bytes 0.5 s late: the DVL's and the Ping1D's messages went out a tick later, and the serial gate,
    holding at the next boundary, ran the other nodes' callbacks once more at the same instant, so messages published
    there (the ESC's widths) arrived a tick earlier than on a quiet machine."""
    a, b = _stepped_run(11, 2.0), _stepped_run(11, 2.0, disturbed=True)
    for topic in a:
        assert len(a[topic]) > 5, topic
        n = min(len(a[topic]), len(b[topic]))
        assert a[topic][:n] == b[topic][:n], topic
        assert abs(len(a[topic]) - len(b[topic])) <= 1, topic  # the last tick may be cut by the end condition


def test_stepped_graph_gives_the_same_messages_for_the_same_seed():
    """``hindrax run``'s graph (stepped simulator, serial devices in lock-step, nodes visited in a fixed order,
    time frozen during start-up and operator calls) is reproducible: two runs with one seed publish the same
    messages, value for value and stamp for stamp, whatever the machine's load. A third with another seed
    differs (the comparison is not vacuous)."""
    a, b, c = _stepped_run(11, 2.0), _stepped_run(11, 2.0), _stepped_run(12, 2.0)
    for topic in a:
        assert len(a[topic]) > 5, topic
        n = min(len(a[topic]), len(b[topic]))
        assert a[topic][:n] == b[topic][:n], topic
        assert abs(len(a[topic]) - len(b[topic])) <= 1, topic  # the last tick may be cut by the end condition
    assert a["dvl/data"][:10] != c["dvl/data"][:10]
