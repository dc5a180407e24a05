"""Sensor conditioning of the identification executive (vehicle.state.SensorState, DepthEstimator), the gyro-aided
attitude smoother and the gyro-bias estimate of the offline analysis (estimators, fusion)."""
from __future__ import annotations

import collections
import math
from types import SimpleNamespace

import numpy as np
import pytest

from hindrax_common.base import frames
from hindrax_common.config import default_config_path, load_config
from hindrax_sim.campaign import Campaign
from hindrax_fit.fit.campaign_fit import rate_bias_against_angle
from hindrax_onboard.vehicle.fusion import smooth_with_rate
from hindrax_onboard.vehicle.state import DepthEstimator, SensorState, euler_rates, rotation_ned_from_body


@pytest.fixture(scope="module")
def cfg():
    return load_config(default_config_path())


def _gyro(state: SensorState, t: float, rates_frd) -> None:
    """A gyro sample whose FRD rate is ``rates_frd`` (default mounting: sensor axes = base_link FLU)."""
    state.on_sample("icm20948_gyro", SimpleNamespace(stamp_s=t, angular_rate_rad_s=frames.frd_to_flu(rates_frd)))


def test_rotation_ned_from_body_is_the_zyx_euler_rotation():
    # scipy's intrinsic ZYX rotation is the independent reference; angles over the whole range, pitch near +-90 deg
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(7)
    angles = np.vstack([rng.uniform([-math.pi, -1.5, -math.pi], [math.pi, 1.5, math.pi], (50, 3)),
                        [[0.3, math.pi / 2 - 1e-6, -2.0], [0.0, 0.0, 0.0]]])
    for roll, pitch, yaw in angles:
        np.testing.assert_allclose(rotation_ned_from_body(roll, pitch, yaw),
                                   Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_matrix(), atol=1e-14)


def test_default_mounting_is_identity(cfg):
    # _gyro relies on it
    assert np.allclose(cfg.sensors.icm20948.mounting_rpy_rad, 0.0)


def test_dvl_lever_arm_uses_the_rate_at_the_samples_time_not_the_latest(cfg):
    st = SensorState(cfg)
    r_dvl = np.asarray(cfg.sensors.dvl75.position_frd_m, dtype=float)
    assert np.linalg.norm(r_dvl) > 0.05
    for i in range(11):  # pitch rate ramps 0 -> 1 rad/s over 0.1 s
        _gyro(st, 0.01 * i, [0.0, 0.1 * i, 0.0])
    v_transducer = np.array([0.2, 0.0, 0.05])
    # a DVL sample valid at t = 0.05 s arrives after the gyro sample of t = 0.1 s
    st.on_sample("dvl75", SimpleNamespace(stamp_s=0.05, velocity_frd_m_s=v_transducer, locked=True))
    expected = v_transducer - np.cross([0.0, 0.5, 0.0], r_dvl)
    assert np.allclose(st.velocity_frd_m_s, expected, atol=1e-12)
    latest = v_transducer - np.cross([0.0, 1.0, 0.0], r_dvl)
    assert not np.allclose(st.velocity_frd_m_s, latest, atol=1e-3)


def test_driver_dvl_velocity_is_already_at_the_body_origin(cfg):
    """dvl/data carries the base_link velocity (the driver removed the lever arm): not corrected twice."""
    from hindrax_msgs.msg import Dvl

    from hindrax_onboard.vehicle.signals import samples_from_dvl

    st = SensorState(cfg)
    _gyro(st, 0.0, [0.0, 1.5, 0.0])
    _gyro(st, 0.1, [0.0, 1.5, 0.0])
    msg = Dvl()
    msg.header.stamp.sec, msg.header.stamp.nanosec = 0, 50_000_000
    msg.velocity_m_s.x, msg.velocity_m_s.y, msg.velocity_m_s.z = 0.1, -0.02, -0.03  # FLU
    msg.velocity_valid = True
    msg.delta_time_s = 0.1
    for dev, s in samples_from_dvl(msg):
        st.on_sample(dev, s)
    assert np.allclose(st.velocity_frd_m_s, [0.1, 0.02, 0.03], atol=1e-12)


def test_euler_rates_match_the_derivative_of_the_rotation(cfg):
    from scipy.spatial.transform import Rotation

    rpy = np.array([0.3, -0.6, 1.2])
    w = np.array([0.4, -0.7, 0.25])  # body FRD rates
    dt = 1e-6
    r0 = Rotation.from_euler("ZYX", rpy[::-1])
    r1 = r0 * Rotation.from_rotvec(w * dt)  # body-fixed rotation increment
    numeric = (r1.as_euler("ZYX")[::-1] - rpy) / dt
    assert np.allclose(euler_rates(rpy, w), numeric, rtol=1e-4, atol=1e-5)


def test_attitude_is_interpolated_or_carried_forward_with_the_gyro(cfg):
    st = SensorState(cfg)
    assert np.all(np.isnan(st.rpy_at(0.0)))
    for t, roll in ((0.0, 0.0), (0.1, 0.1)):
        st.on_sample("dvl75_attitude", SimpleNamespace(stamp_s=t, roll_rad=roll, pitch_rad=0.0, yaw_rad=3.1))
    assert st.rpy_at(0.05) == pytest.approx([0.05, 0.0, 3.1])
    for i in range(11, 16):
        _gyro(st, 0.01 * i, [2.0, 0.0, 0.0])
    # 0.05 s after the newest attitude at 2 rad/s of roll (level pitch: roll rate = p)
    assert st.rpy_now() == pytest.approx([0.2, 0.0, 3.1], abs=1e-9)


def test_depth_from_pressure_uses_the_attitude_at_the_pressure_time(cfg):
    st = SensorState(cfg)
    r_p = np.asarray(cfg.sensors.ms5837.position_frd_m, dtype=float)
    assert abs(r_p[0]) > 0.05
    for t, pitch in ((0.0, 0.0), (0.1, 0.4)):
        st.on_sample("dvl75_attitude", SimpleNamespace(stamp_s=t, roll_rad=0.0, pitch_rad=pitch, yaw_rad=0.0))
    rho_g = cfg.environment.water_density_kg_m3 * cfg.environment.gravity_m_s2
    p0 = cfg.environment.surface_pressure_pa
    st.on_sample("ms5837", SimpleNamespace(stamp_s=0.05, pressure_pa=p0 + rho_g * 1.0))
    theta = 0.2  # pitch at 0.05 s; port depth = origin depth + (R r_p)_z = d - sin(theta) x_p + cos(theta) z_p
    expected = 1.0 - (-math.sin(theta) * r_p[0] + math.cos(theta) * r_p[2])
    assert st.depth_m == pytest.approx(expected, abs=1e-9)


def test_depth_estimator_rate_follows_a_fast_heave_oscillation(cfg):
    """10 Hz depth, late by 35 ms, plus 100 Hz vertical acceleration: rate error < 10 % of its amplitude at
    4 rad/s. From the depth alone (the accelerometer left out) the same filter lags by far more."""
    rng = np.random.default_rng(3)
    amp, omega = 0.03, 4.0

    def run(use_accel: bool) -> float:
        est = DepthEstimator(0.002, 0.07, 20.0)
        st = SimpleNamespace(depth_m=math.nan, acceleration_ned_m_s2=np.full(3, np.nan))
        errors = []
        for i in range(1, 1001):  # 10 s of 10 ms ticks
            t = 0.01 * i
            if use_accel:
                st.acceleration_ned_m_s2 = np.array([0.0, 0.0, -amp * omega ** 2 * math.sin(omega * t)
                                                     + rng.normal(0.0, 0.05)])
                est.on_sample("icm20948_accel", t, st)
            if i % 10 == 0:  # a depth sample converted 35 ms ago reaches the node now
                tc = t - 0.035
                st.depth_m = 0.7 + amp * math.sin(omega * tc) + rng.normal(0.0, 0.002)
                est.on_sample("ms5837", tc, st)
            _, rate = est.predict_to(t)
            if t > 2.0:
                errors.append(rate - amp * omega * math.cos(omega * t))
        return float(np.sqrt(np.mean(np.square(errors))))

    with_accel, depth_only = run(True), run(False)
    assert with_accel < 0.1 * amp * omega
    assert depth_only > 2.0 * with_accel


def test_depth_estimator_is_nan_before_the_first_depth(cfg):
    est = DepthEstimator(0.002, 0.07, 20.0)
    st = SimpleNamespace(depth_m=math.nan, acceleration_ned_m_s2=np.array([0.0, 0.0, 0.1]))
    est.on_sample("icm20948_accel", 0.0, st)
    assert all(math.isnan(x) for x in est.predict_to(0.1))


def test_rate_bias_against_angle_recovers_a_constant_gyro_bias():
    rng = np.random.default_rng(7)
    tg = np.arange(0.0, 30.0, 0.01)
    ta = np.arange(0.0, 30.0, 0.1)
    angle = 0.6 * np.sin(1.3 * ta) + rng.normal(0.0, 0.005, ta.size)
    rate = 0.6 * 1.3 * np.cos(1.3 * tg) + 0.003 + rng.normal(0.0, 0.003, tg.size)
    assert rate_bias_against_angle(ta, angle, tg, rate) == pytest.approx(0.003, abs=3e-4)
    assert rate_bias_against_angle(ta[:2], angle[:2], tg, rate) == 0.0


def test_gyro_aided_angle_is_far_less_noisy_than_the_attitude():
    """smooth_with_rate: 10 Hz angle (std 5 mrad) + 100 Hz rate (std 3 mrad/s) -> angle error well below 5 mrad."""
    rng = np.random.default_rng(11)
    t = np.round(np.arange(0.0, 20.0, 0.01), 6)
    truth = 0.7 * np.sin(1.7 * t) * np.sin(0.4 * t)
    truth_rate = np.gradient(truth, t)
    angle = np.full(t.size, np.nan)
    angle[::10] = truth[::10] + rng.normal(0.0, 0.005, t[::10].size)
    rate = truth_rate + rng.normal(0.0, 0.003, t.size)
    est, est_rate, _ = smooth_with_rate(t, angle, rate, 0.005, 0.003, 0.003 ** 2 * 20.0 ** 4)
    err = est[100:-100] - truth[100:-100]
    assert np.sqrt(np.mean(err ** 2)) < 0.3 * 0.005
    assert np.sqrt(np.mean((est_rate[100:-100] - truth_rate[100:-100]) ** 2)) < 0.003


def test_holds_stay_calm_with_80_ms_of_command_latency(cfg):
    """The holds tolerate the latency of the ROS graph (sensor delivery + allocation + ESC, about 70 ms): with
    every wrench applied 4 control ticks (80 ms) late, the depth stays within a few mm during the roll runs
    (before the accelerometer-aided depth rate and the attitude hold at the common natural frequency: 16 mm
    std, 0.085 m/s rms heave, and the roll runs took 36 s instead of 13 s; measured with this test's seed)."""
    c = Campaign(cfg, dofs=["roll"], levels=2, seed=5)
    queue = collections.deque([np.zeros(6)] * 4)
    tick = c.tick
    heave = []

    def late_tick(w):
        heave.append((c.sim.t_s, float(c.sim.nu[2])))
        queue.append(np.asarray(w, dtype=float))
        return tick(queue.popleft())

    c.tick = late_tick
    rec = c.run()
    t0, t1 = rec.windows["roll"]
    z = np.asarray(rec.truth_position_ned_m)[:, 2]
    m = (rec.t_s >= t0) & (rec.t_s <= t1)
    w = np.array([v for t, v in heave if t0 <= t <= t1])
    assert np.std(z[m]) < 0.008
    assert np.sqrt(np.mean(w ** 2)) < 0.03
    assert t1 - t0 < 20.0
