"""Safety supervisor: the pure checks, and the node disarming the ESC output on every kind of breach.

The graph test runs the ESC node (on an emulated PCA9685) and the supervisor on a /clock the test drives, with a
probe publishing the sensor topics; for each breach it reads the emulated chip back: every thruster channel must
be at neutral within one output period (1 / esc.output_rate_hz of simulated time) of the breach.
"""
import math

import numpy as np
import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import PoseWithCovarianceStamped
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.qos import ReliabilityPolicy
from sensor_msgs.msg import Imu, Range
from std_msgs.msg import String
from std_srvs.srv import Trigger

from hindrax_common.base import frames
from hindrax_common.config import default_config_path, load_config
from hindrax_bringup.supervisor.core import SupervisorCore, SupervisorLimits, tilt_from_specific_force
from hindrax_bringup.supervisor.node import SupervisorNode
from hindrax_common.testing import config_parameters, ros_context, wait_until
from hindrax_msgs.msg import Dvl, ThrusterPwm
from hindrax_msgs.srv import SetArmed
from hindrax_test_support.safety_graph import SafetyGraph

TICK_US = 1.24
PERIOD_S = 1 / 50.0  # esc.output_rate_hz


def limits(**kw):
    base = dict(min_rate_hz={"dvl": 1.0, "altimeter": 1.0, "pressure": 2.0, "imu": 20.0}, rate_window_s=2.0,
                max_depth_m=1.6, min_altitude_m=0.2, max_roll_rad=1.0, max_pitch_rad=1.1,
                cage_min_ne=(0.1, 0.1), cage_max_ne=(9.9, 5.9), max_run_time_s=100.0,
                start_position_ne=(2.0, 3.0), start_heading_rad=0.0)
    base.update(kw)
    return SupervisorLimits(**base)


# ------------------------------------------------------------------ core
def test_limits_from_the_shipped_configuration():
    lim = SupervisorLimits.from_config(load_config(default_config_path()))
    assert lim.cage_min_ne == (0.1, 0.1) and lim.cage_max_ne == (9.9, 5.9)  # 10 x 6 m pool, 0.1 m margin
    assert lim.start_position_ne == (2.0, 3.0) and lim.max_depth_m == 1.65
    assert lim.clock_stall_timeout_s == 3.0  # its default: supervisor.rate_window_s
    assert SupervisorLimits.from_config(load_config(default_config_path()), 30.0).clock_stall_timeout_s == 30.0


def test_supervisor_limits_must_be_wider_than_the_identification_limits():
    from hindrax_common.config import ConfigError

    for key, value, words in (("supervisor.max_depth_m", 1.4, "at least limits.max_depth_m (1.5)"),
                              ("supervisor.min_altitude_m", 0.4, "at most limits.min_altitude_m (0.3)"),
                              ("supervisor.max_pitch_rad", 0.8, "at least limits.max_pitch_rad (0.9)"),
                              ("supervisor.cage_margin_m", 3.0, "below half the pool's smaller side (3)")):
        with pytest.raises(ConfigError) as err:
            load_config(default_config_path(), {key: value})
        assert err.value.lines() == [f"{key} = {value}: allowed {words}" + (
            ": the identification aborts first" if "limits." in words else "")]


def test_nothing_trips_while_disarmed_and_each_limit_trips_once_armed():
    c = SupervisorCore(limits())
    assert c.on_depth(0.0, 5.0) == "" and c.on_altitude(0.0, 0.0) == "" and c.on_attitude(2.0, 0.0, 0.0) == ""
    assert c.tripped == ""
    for feed, expect in ((lambda c: c.on_depth(1.0, 1.61), "depth 1.61 m"),
                         (lambda c: c.on_altitude(1.0, 0.19), "altitude 0.19 m"),
                         (lambda c: c.on_attitude(-1.01, 0.0, 0.0), "roll -1.01"),
                         (lambda c: c.on_attitude(0.0, 1.2, 0.0), "pitch 1.20"),
                         (lambda c: c.trip("operator e-stop"), "operator e-stop")):
        c = SupervisorCore(limits())
        c.set_armed(0.0, True)
        assert c.on_depth(0.5, 1.59) == "" and c.on_altitude(0.5, 0.21) == ""
        reason = feed(c)
        assert expect in reason and c.tripped == reason
        assert feed(c) == ""  # latched: reported once
        c.reset()
        assert c.tripped == ""


def test_ros_time_standing_still_beyond_the_timeout_trips_only_while_armed():
    """clock_stall_timeout_s 2 s: ROS time still for 2 s of steady time (or less) does not trip, 2.01 s does; while
    disarmed no stall trips (the other checks are off then too)."""
    c = SupervisorCore(limits(clock_stall_timeout_s=2.0))
    assert c.stall_check(1e6) == "" and c.tripped == ""
    c.set_armed(0.0, True)
    assert c.stall_check(1.99) == "" and c.stall_check(2.0) == "" and c.tripped == ""
    reason = c.stall_check(2.01)
    assert reason == "ROS time stalled for 2.0 s while armed: the supervisor's ROS-time checks are blind"
    assert c.tripped == reason and c.stall_check(3.0) == ""  # latched: reported once


def test_a_disarm_is_asked_at_a_breach_and_repeated_every_0_2_s_while_the_esc_stays_armed():
    c = SupervisorCore(limits())
    c.set_armed(0.0, True)
    assert not c.disarm_due(5.0)  # armed, not tripped: nothing to ask
    c.trip("operator e-stop")
    assert c.disarm_due(5.0, breach=True)
    assert not c.disarm_due(5.19) and c.disarm_due(5.2)  # DISARM_RETRY_S 0.2 s of steady time after the last ask
    assert not c.disarm_due(5.3) and c.disarm_due(5.45)
    c.set_armed(6.0, False)
    assert not c.disarm_due(7.0)  # disarmed: done
    c.set_armed(7.0, True)  # re-armed while tripped: at once
    assert c.disarm_due(7.0)
    c.shift_time(-100.0)  # ROS time stepped back: the steady-time repeats go on
    assert c.disarm_due(7.2)


def test_dead_reckoning_and_cage():
    """Heading 90 deg (east), 0.5 m/s surge for 5 s from (2, 3): 2.5 m east -> (2, 5.5), inside; 1 s more ->
    east 6.0, beyond the 5.9 m cage edge (hand arithmetic)."""
    c = SupervisorCore(limits())
    c.set_armed(0.0, True)
    c.on_attitude(0.0, 0.0, math.pi / 2)
    v = np.array([0.5, 0.0, 0.0])
    t = 0.0
    reasons = []
    for _ in range(51):
        reasons.append(c.on_dvl(t, v))
        t += 0.1
    np.testing.assert_allclose(c.position_ne, [2.0, 5.5], atol=1e-9)
    assert not any(reasons)
    for _ in range(10):
        reasons.append(c.on_dvl(t, v))
        t += 0.1
    assert any("outside the cage" in r for r in reasons)
    # invalid velocities and long gaps are not integrated
    c2 = SupervisorCore(limits())
    c2.on_dvl(0.0, v)
    c2.on_dvl(0.1, None)
    c2.on_dvl(5.0, v)
    c2.on_dvl(7.0, v)  # 2 s gap
    np.testing.assert_allclose(c2.position_ne, [2.0, 3.0])


def test_rates_and_run_time():
    c = SupervisorCore(limits())
    c.set_armed(0.0, True)
    reason = ""
    for k in range(600):  # 10 ms steps; IMU 100 Hz, the others 10 Hz; the pressure sensor stops after t = 2.9 s
        t = k / 100.0
        c.on_message("imu", t)
        if k % 10 == 0:
            c.on_dvl(t, np.zeros(3))  # a valid velocity (an invalid one no longer counts toward the rate)
            c.on_altitude(t, 1.0)
            if k <= 290:
                c.on_depth(t, 0.5)
        reason = c.check(t)
        if reason:
            break
    assert "pressure/depth" in reason and "below supervisor.min_rate.pressure_hz 2" in reason
    # below 2 Hz over the 2 s window = fewer than 4 messages in it: only 2.7, 2.8 and 2.9 s remain once
    # t - 2 s > 2.6 s, first at t = 4.61 s (hand arithmetic)
    assert t == pytest.approx(4.61)
    c2 = SupervisorCore(limits(min_rate_hz={"dvl": 0.0, "altimeter": 0.0, "pressure": 0.0, "imu": 0.0}))
    c2.set_armed(10.0, True)
    assert c2.check(109.0) == "" and "max_run_time_s 100" in c2.check(110.5)


def test_one_hour_old_identical_samples_are_not_alive_and_trip():
    """At the normal rates (IMU 100 Hz, the others 10 Hz), every sample stamped 3600 s old: none counts, the rate check
    trips once armed for one window (2 s) and names why; fresh but bit-identical samples trip too, once identical for
    max_identical_s (1 s) and then below the rate over the 2 s window."""
    for lag_s, words in ((3600.0, "samples not alive: stamped 3600.0 s old, beyond supervisor.max_sample_age_s 1"),
                         (0.0, "beyond supervisor.max_identical_s 1 (frozen)")):
        c = SupervisorCore(limits(max_sample_age_s=1.0, max_identical_s=1.0, reaction_time_s=3.0))
        c.set_armed(0.0, True)
        reason = ""
        for k in range(500):
            t = k / 100.0
            c.on_imu(t, t - lag_s, b"same bytes", np.array([0.0, 0.0, -9.81]))
            if k % 10 == 0:
                c.on_dvl(t, np.zeros(3), t - lag_s, (0.0, 0.0, 0.0), (0.0,) * 7)
                c.on_altitude(t, 1.0, t - lag_s)
                c.on_depth(t, 0.5, t - lag_s)
            reason = c.check(t)
            if reason:
                break
        assert words in reason, reason
        assert 2.0 <= t <= 4.0 and c.not_alive["pressure"] > 0
    # the same streams with a sensor's noise and fresh stamps never trip
    c = SupervisorCore(limits(max_sample_age_s=1.0, max_identical_s=1.0, reaction_time_s=3.0))
    c.set_armed(0.0, True)
    rng = np.random.default_rng(1)
    for k in range(500):
        t = k / 100.0
        c.on_imu(t, t, rng.bytes(8), np.array([0.0, 0.0, -9.81]) + rng.normal(0, 0.01, 3))
        if k % 10 == 0:
            v = rng.normal(0.0, 1e-3, 3)
            assert c.on_dvl(t, v, t, (0.0, 0.0, 0.0), tuple(v)) == ""
            c.on_altitude(t, 1.0 + rng.normal(0, 1e-3), t)
            c.on_depth(t, 0.5 + rng.normal(0, 1e-3), t)
        assert c.check(t) == "", t


def test_dvl_without_dvext_uses_the_imu_tilt_or_trips():
    """$DVPDL without $DVEXT: the report has no attitude (not level). At 60 deg of roll (IMU at rest: specific force
    FRD (0, -g sin 60, -g cos 60)) the roll limit (1 rad) trips on the IMU's tilt; without the IMU's tilt either,
    the supervisor trips once reaction_time_s (3 s) has passed armed without attitude."""
    g, roll = 9.81, math.radians(60.0)
    assert tilt_from_specific_force(np.array([0.0, -g * math.sin(roll), -g * math.cos(roll)])) == pytest.approx(
        (roll, 0.0))
    pitch = math.radians(20.0)
    assert tilt_from_specific_force(np.array([g * math.sin(pitch), 0.0, -g * math.cos(pitch)])) == pytest.approx(
        (0.0, pitch))
    assert tilt_from_specific_force(np.zeros(3)) is None  # a zero (default) message is no tilt

    c = SupervisorCore(limits(max_sample_age_s=1.0, reaction_time_s=3.0))
    c.set_armed(10.0, True)
    c.on_dvl(10.0, np.zeros(3), 10.0, (0.0, 0.0, 0.0))  # a last DVL attitude, level
    f = np.array([0.0, -g * math.sin(roll), -g * math.cos(roll)])
    assert c.on_imu(10.5, 10.5, b"a", f) == ""  # the DVL's attitude is fresh: it rules
    assert c.on_dvl(10.6, np.zeros(3), 10.6, None) == ""  # no $DVEXT from here on
    reason = c.on_imu(11.2, 11.2, b"b", f)  # the DVL's attitude is 1.2 s old: the IMU's tilt is used
    assert "roll 1.05 rad beyond supervisor.max_roll_rad 1 (IMU accelerometer (no fresh DVL attitude))" in reason

    c = SupervisorCore(limits(max_sample_age_s=1.0, reaction_time_s=3.0, rate_window_s=10.0))  # rates not yet
    c.set_armed(10.0, True)
    t_trip, reason = 0.0, ""
    for k in range(100):
        t_trip = 10.0 + 0.05 * k
        assert c.on_dvl(t_trip, np.full(3, 1e-3 * k), t_trip, None) == ""
        reason = c.check(t_trip)
        if reason:
            break
    assert "no attitude for 3.1 s (no fresh DVL attitude: $DVEXT missing" in reason and t_trip == pytest.approx(13.05)


# ------------------------------------------------------------------ graph: every breach -> neutral on the chip
@pytest.fixture
def graph(request):
    """The ESC and the supervisor (:class:`~hindrax_test_support.safety_graph.SafetyGraph`) with the e-stop client,
    ``supervisor/abort`` and :attr:`step` publishing the sensors from :attr:`state`. Parametrized indirectly, the
    parameter is the supervisor's ``clock_stall_timeout_s`` (s; default the graph's 30 s)."""
    over = {"esc.arming_time_s": 0.0, "esc.oscillator_calibrated": True, "esc.watchdog_timeout_s": 5.0,
            "supervisor.rate_window_s": 1.0, "supervisor.max_run_time_s": 30.0}
    with ros_context() as ctx:
        g = SafetyGraph(ctx, over, getattr(request, "param", 30.0))
        g.pubs["abort"] = g.probe.create_publisher(String, "supervisor/abort", 10)
        g.estop = g.probe.create_client(Trigger, "supervisor/estop")
        g.state = dict(depth=0.5, alt=1.0, roll=0.0, v=(0.0, 0.0), quiet=set())
        rng = np.random.default_rng(7)

        def noise(std, n=None):
            """A sensor's noise; none (bit-identical samples) with the state's ``frozen``."""
            return 0.0 * rng.normal(0.0, std, n) if g.state.get("frozen") else rng.normal(0.0, std, n)

        def step(dt_s=0.01):
            """Publish the sensors for this instant (stamped now, with a little noise as real sensors have: the
            supervisor takes stale or bit-identical streams as dead), then advance /clock by dt_s and let every node
            run."""
            st, pubs = g.state, g.pubs
            stamp = g.stamp(st.get("stamp_lag_ns", 0))
            if (g.ns // 1_000_000) % 100 == 0:
                if "dvl" not in st["quiet"]:
                    m = Dvl(velocity_valid=True)
                    m.header.stamp = stamp
                    m.velocity_m_s.x, m.velocity_m_s.y = np.asarray(st["v"]) + noise(1e-4, 2)
                    q = frames.quaternion_marine_to_ros(frames.quaternion_from_euler_ned([st["roll"], 0.0, 0.0]))
                    if "dvext" in st["quiet"]:
                        q = np.zeros(4)  # what the driver publishes without a $DVEXT: no attitude
                    m.orientation.x, m.orientation.y, m.orientation.z, m.orientation.w = (float(x) for x in q)
                    pubs["dvl"].publish(m)
                if "alt" not in st["quiet"]:
                    r = Range(range=float(st["alt"] + noise(1e-3)))
                    r.header.stamp = stamp
                    pubs["alt"].publish(r)
                if "depth" not in st["quiet"]:
                    d = PoseWithCovarianceStamped()
                    d.header.stamp = stamp
                    d.pose.pose.position.z = -float(st["depth"] + noise(1e-3))
                    pubs["depth"].publish(d)
            if "imu" not in st["quiet"]:
                imu = Imu()
                imu.header.stamp = stamp
                # specific force of the vehicle at rest at the state's roll, FLU (FRD (0, -g sin, -g cos) mirrored)
                f = frames.frd_to_flu([0.0, -9.81 * math.sin(st.get("imu_roll", st["roll"])),
                                       -9.81 * math.cos(st.get("imu_roll", st["roll"]))]) + noise(0.01, 3)
                imu.linear_acceleration.x, imu.linear_acceleration.y, imu.linear_acceleration.z = (float(x) for x in f)
                pubs["imu"].publish(imu)
            g.advance(dt_s)

        g.step = step
        g.wait_ready(step, g.estop.service_is_ready)
        yield g
        g.close()


def sim_s(g):
    return g.ns * 1e-9


def arm_and_thrust(g):
    """Reset the supervisor, arm, and command 1700 us until it is on the wire and the supervisor sees armed."""
    g.call(g.reset, Trigger.Request())
    g.state.clear()
    g.state.update(depth=0.5, alt=1.0, roll=0.0, v=(0.0, 0.0), quiet=set())
    g.sup.core.position_ne = np.array(g.sup.core.limits.start_position_ne)
    g.arm_with_thrust(g.step)


def until_neutral(g, keep_commanding=True, max_steps=400):
    """Step (commanding 1700 us like a controller that did not notice) until the chip is at neutral; returns the
    simulated time at which neutral was read back. Before each look at the wire the ESC's chip thread finishes
    what it was posted: it runs on wall time while /clock is held, and on a loaded machine (a fresh clone's suite,
    2 workers on 2 cores) a starved thread let 28 slices of 1 ms pass before its neutral write landed."""
    for _ in range(max_steps):
        assert g.esc.link.worker.wait_idle(5.0), "the ESC's chip thread hangs"
        if np.allclose(g.wire(), 1500.0, atol=TICK_US):
            return sim_s(g)
        if keep_commanding:
            g.pubs["cmd"].publish(ThrusterPwm(pulse_width_us=[1700.0] * 8, armed=True))
        g.step(0.001)
    raise AssertionError(f"not neutral: {g.wire()}")


@pytest.mark.ros
@pytest.mark.parametrize("breach", ["depth", "altitude", "attitude", "cage", "sensor_rate", "run_time", "estop",
                                    "abort", "stale_frozen", "no_dvext_roll"])
def test_supervisor_disarms_on_each_breach_neutral_within_one_period(graph, breach):
    g = graph
    arm_and_thrust(g)
    st = g.state
    breach_at = None
    if breach == "estop":
        breach_at = sim_s(g)
        res = g.call(g.estop, Trigger.Request())
        assert res.success
    elif breach == "abort":
        breach_at = sim_s(g)
        g.pubs["abort"].publish(String(data="limits.max_depth_m"))
    elif breach == "run_time":
        g.sup.core.armed_since_s -= 29.9  # 0.1 s of simulated time before supervisor.max_run_time_s
    else:
        st.update({"depth": dict(depth=1.7), "altitude": dict(alt=0.1), "attitude": dict(roll=1.2),
                   "cage": dict(v=(0.0, 0.0)), "sensor_rate": dict(quiet={"depth"}),
                   # identical samples stamped one hour old, at the normal rates
                   "stale_frozen": dict(stamp_lag_ns=3600 * 10**9, frozen=True),
                   # $DVPDL without $DVEXT (no attitude) while the IMU says 60 deg of roll
                   "no_dvext_roll": dict(quiet={"dvext"}, imu_roll=math.radians(60.0))}[breach])
        if breach == "cage":
            g.sup.core.position_ne = np.array([9.95, 3.0])  # beyond the 9.9 m north cage edge
            st["v"] = (0.01, 0.0)
    # step in 1 ms slices while commanding thrust, until the supervisor trips
    for _ in range(3000):
        if g.sup.core.tripped:
            break
        g.pubs["cmd"].publish(ThrusterPwm(pulse_width_us=[1700.0] * 8, armed=True))
        g.step(0.001)
    assert g.sup.core.tripped, breach
    trip_s = g.sup.last_breach_time_s
    neutral_s = until_neutral(g)
    assert neutral_s - trip_s <= PERIOD_S + 1e-9, (breach, neutral_s - trip_s)
    if breach_at is not None:
        assert neutral_s - breach_at <= PERIOD_S + 1e-9
    assert not g.esc.armed
    wait_until(lambda: g.statuses and g.statuses[-1].level == DiagnosticStatus.ERROR, 5, g.step, "status")
    expected_words = {"depth": "depth 1.70 m", "altitude": "altitude 0.10 m", "attitude": "roll 1.20",
                      "cage": "outside the cage", "sensor_rate": "pressure/depth", "run_time": "max_run_time_s",
                      "estop": "e-stop", "abort": "limits.max_depth_m",
                      "stale_frozen": "samples not alive: stamped 3600", "no_dvext_roll": "roll 1.05 rad beyond "
                      "supervisor.max_roll_rad 1 (IMU accelerometer (no fresh DVL attitude))"}[breach]
    assert expected_words in g.statuses[-1].message
    # latched: re-arming is undone by the supervisor until it is reset
    g.esc.on_set_armed(SetArmed.Request(arm=True), SetArmed.Response())
    wait_until(lambda: not g.esc.armed, 5, g.step, "disarmed again while tripped")


@pytest.mark.ros
@pytest.mark.parametrize("graph", [0.5], indirect=True)
def test_ros_time_standing_still_while_armed_trips_the_node_and_neutral_reaches_the_chip(graph):
    """The node's wiring of the stall check: armed with thrust, /clock stops; the supervisor's steady-clock check
    trips on "ROS time stalled" (clock_stall_timeout_s 0.5 s, never before 0.5 s of steady time) and the chip goes
    to neutral once time moves again."""
    import time

    g = graph
    arm_and_thrust(g)
    # taken before ROS time last moves: the node sees that move after it, never before (a fresh
    # clone's suite failed the bound by 0.2 ms when this was taken after arm_and_thrust's last step,
    # which the node had seen already)
    held_at = time.monotonic()
    g.step(0.001)
    wait_until(lambda: g.sup.core.tripped, 10, g.spin_once, "a stall trip")
    assert time.monotonic() - held_at >= 0.5
    assert g.sup.core.tripped.startswith("ROS time stalled for ") and "while armed" in g.sup.core.tripped
    until_neutral(g)
    assert not g.esc.armed


# ------------------------------------------------------------------ system clock: the same callbacks as with sim time
def test_supervisor_takes_imu_samples_by_callback_on_the_system_clock():
    """On the system clock (the vehicle) imu/data_raw is a callback subscription of the supervisor node itself, as
    with use_sim_time (issue 47 item 1: one input path): every sample is counted once, at its arrival; the rate
    check then sees the IMU stop."""
    import time

    with ros_context() as ctx:
        over = {"supervisor.rate_window_s": 1.0, "supervisor.check_rate_hz": 20.0}
        sup = SupervisorNode(context=ctx, parameter_overrides=config_parameters(over))
        probe = rclpy.create_node("probe", context=ctx)
        pub = probe.create_publisher(Imu, "imu/data_raw", 10)
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(sup)
        ex.add_node(probe)
        try:
            assert "/imu/data_raw" in {s.topic_name for s in sup.subscriptions}
            assert "supervisor_intake" not in probe.get_node_names()
            # the sensor readers are best effort (no acknowledgements); they match the drivers' reliable writers
            sensors = ("/imu/data_raw", "/dvl/data", "/ping/altitude", "/pressure/depth")
            assert {s.topic_name: s.qos_profile.reliability for s in sup.subscriptions if s.topic_name in sensors} \
                == dict.fromkeys(sensors, ReliabilityPolicy.BEST_EFFORT)
            assert pub.qos_profile.reliability == ReliabilityPolicy.RELIABLE
            spin = lambda: ex.spin_once(timeout_sec=0.01)  # noqa: E731
            wait_until(lambda: pub.get_subscription_count() == 1, 10, spin, "subscription matched")
            t0 = time.time_ns() * 1e-9
            for k in range(30):
                imu = Imu()
                imu.header.stamp = sup.get_clock().now().to_msg()
                imu.linear_acceleration.z = 9.81 + 1e-3 * k  # a sensor's noise: no two samples alike
                pub.publish(imu)
            for _ in range(5):
                pub.publish(Imu())  # stamp 0: never set, not alive
            stamps = sup.core._stamps["imu"]
            wait_until(lambda: sup.core.not_alive["imu"] == 5, 10, spin, "35 samples taken by callbacks")
            assert len(stamps) == 30 and "stamp 0" in sup.core.not_alive_reason["imu"]
            assert all(t0 <= t <= time.time_ns() * 1e-9 for t in stamps)  # arrival times
            assert sup.core.rate_hz("imu", sup._now_s()) == pytest.approx(30.0 / 1.0)
            # the IMU stops: once the window has passed the rate is 0 (an armed supervisor trips on it)
            wait_until(lambda: sup.core.rate_hz("imu", sup._now_s()) == 0.0, 10, spin, "rate back to 0")
        finally:
            ex.shutdown()
            probe.destroy_node()
            sup.destroy_node()


def test_supervisor_takes_the_latched_esc_state_and_disarms_a_tripped_arming():
    """``esc/output_state`` is latched (esc_state.py): a state the ESC published before the supervisor started
    reaches the core at once, dated at its arrival; unknown after armed stays armed (it may still be thrusting); an
    ESC that reports armed while the supervisor is tripped gets an ``esc/set_armed(false)`` request."""
    import time

    from diagnostic_msgs.msg import DiagnosticStatus, KeyValue

    from hindrax_common.node_support.esc_state import ESC_STATE_TOPIC, esc_state_qos

    def state(output_state, armed):
        return DiagnosticStatus(values=[KeyValue(key="output_state", value=str(output_state)),
                                        KeyValue(key="armed", value="true" if armed else "false")])

    with ros_context() as ctx:
        probe = rclpy.create_node("probe", context=ctx)
        pub = probe.create_publisher(DiagnosticStatus, ESC_STATE_TOPIC, esc_state_qos())
        t0 = time.time_ns() * 1e-9
        pub.publish(state(ThrusterPwm.OUTPUT_NEUTRAL, True))  # before the supervisor exists
        sup = SupervisorNode(context=ctx, parameter_overrides=config_parameters({"supervisor.check_rate_hz": 20.0}))
        requests: list = []

        def on_set_armed(req, resp):
            requests.append(req.arm)
            resp.success = True
            return resp

        probe.create_service(SetArmed, "esc/set_armed", on_set_armed)
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(sup)
        ex.add_node(probe)
        try:
            topics = {s.topic_name for s in sup.subscriptions}
            assert "/esc/output_state" in topics and "/thrusters/pulse_width" not in topics
            spin = lambda: ex.spin_once(timeout_sec=0.01)  # noqa: E731
            wait_until(lambda: sup.core.armed, 10, spin, "latched armed state taken")
            assert t0 <= sup.core.armed_since_s <= time.time_ns() * 1e-9  # its arrival time
            assert requests == []
            sub = next(s for s in sup.subscriptions if s.topic_name == "/esc/output_state")
            taken, on_esc = [], sub.callback
            sub.callback = lambda m: (on_esc(m), taken.append(m))  # noqa: E731 - the supervisor's, then noted
            pub.publish(state(ThrusterPwm.OUTPUT_UNKNOWN, False))
            wait_until(lambda: taken, 10, spin, "unknown delivered")
            assert sup.core.armed  # unknown after armed: still armed
            sup.core.trip("test breach")
            wait_until(lambda: requests == [False], 10, spin, "disarm requested")
            pub.publish(state(ThrusterPwm.OUTPUT_NEUTRAL, False))
            wait_until(lambda: not sup.core.armed, 10, spin, "disarmed at neutral")
        finally:
            ex.shutdown()
            probe.destroy_node()
            sup.destroy_node()


def test_a_backward_clock_step_between_a_sample_and_the_check_gives_no_dvl_trip():
    """ROS time steps back 100 s while armed, and a valid DVL report arrives before the next check: the report is
    stored in the new time base, the check re-bases nothing twice, no "no valid DVL velocity for 100 s" trip (was:
    the report's time shifted by the step once more, 3 runs in 4 tripped)."""
    from rclpy.time import Time

    with ros_context() as ctx:
        quiet = ("altimeter", "pressure", "imu")
        over = {**{f"supervisor.min_rate.{s}_hz": 0.0 for s in quiet},
                **{f"supervisor.rate_check_disabled.{s}": "clock-step test: DVL only" for s in quiet}}
        # the test sets ROS time by hand: a starved step must not read as a stalled clock (tested by itself above)
        sup = SupervisorNode(context=ctx, parameter_overrides=config_parameters(over)
                             + [Parameter("use_sim_time", value=True), Parameter("clock_stall_timeout_s", value=30.0)])
        clock = sup.get_clock()
        try:
            def at(t_s: float) -> None:
                clock.set_ros_time_override(Time(nanoseconds=int(t_s * 1e9), clock_type=clock.clock_type))

            def dvl(t_s: float, k: int) -> Dvl:
                m = Dvl(velocity_valid=True)
                m.header.stamp = Time(nanoseconds=int(t_s * 1e9)).to_msg()
                m.velocity_m_s.x = 1e-3 * (k % 7)  # a sensor's noise
                m.orientation.w = 1.0
                return m

            t, k = 1000.0, 0
            at(t)
            sup.on_check()
            sup.core.set_armed(t, True)
            for _ in range(60):  # 3 s armed (beyond max_invalid_dvl_s, 2 s), DVL at 10 Hz, checks at 20 Hz
                t, k = t + 0.05, k + 1
                at(t)
                if k % 2 == 0:
                    sup.on_dvl(dvl(t, k))
                sup.on_check()
            t -= 100.0  # the step back, then a report before the check
            at(t)
            sup.on_dvl(dvl(t, k))
            for _ in range(20):
                sup.on_check()
                t, k = t + 0.05, k + 1
                at(t)
                if k % 2 == 0:
                    sup.on_dvl(dvl(t, k))
            assert sup.core.tripped == "" and sup.clock_monitor.steps_back == 1
            assert sup.core.last_valid_dvl_t == pytest.approx(t, abs=0.11)
        finally:
            sup.destroy_node()


def test_identical_samples_far_apart_are_not_a_frozen_stream():
    """Two identical depths 4 s apart (beyond max_identical_s, 3 s) say nothing about a stream in between: the second
    is alive and its breach trips (the safety bench publishes one such depth per repeat); 10 Hz repeats of it for
    3 s are frozen."""
    c = SupervisorCore(limits(max_sample_age_s=1.0, max_identical_s=3.0, reaction_time_s=3.0))
    c.set_armed(10.0, True)
    assert "depth 1.75 m" in c.on_depth(10.0, 1.75, 10.0)
    c.reset()
    assert "depth 1.75 m" in c.on_depth(14.0, 1.75, 14.0)
    c.reset()
    for k in range(1, 40):  # 14.1 ... 17.9 s: identical beyond 17.0 s, i.e. the last 9 (10 with rounding)
        c.on_depth(14.0 + 0.1 * k, 1.75, 14.0 + 0.1 * k)
    assert 9 <= c.not_alive["pressure"] <= 10 and "frozen" in c.not_alive_reason["pressure"]
