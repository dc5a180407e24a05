"""Values that are invalid, implausible after a transformation, or
configured unsafely are never taken as valid (docs/architecture.md §8). Each test failed on 3f4c425."""
from __future__ import annotations

import math

import numpy as np
import pytest

from hindrax_bringup.allocation.node import wrench_header_problem
from hindrax_common.config import ConfigError, default_config_path, load_config
from hindrax_drivers.dvl75.protocol import DvlPositionDelta
from hindrax_drivers.dvl75.report import DvlReportBuilder
from hindrax_drivers.ms5837 import protocol as ms
from hindrax_drivers.ms5837.core import DepthGate
from hindrax_drivers.ping1d.node import rep117_range
from hindrax_bringup.supervisor.core import SupervisorCore, SupervisorLimits

SHIPPED = load_config(default_config_path())


def limits(**kw):
    base = dict(min_rate_hz={"dvl": 1.0, "altimeter": 1.0, "pressure": 2.0, "imu": 20.0}, rate_window_s=3.0,
                max_depth_m=1.65, min_altitude_m=0.3, max_roll_rad=1.0, max_pitch_rad=1.1,
                cage_min_ne=(0.1, 0.1), cage_max_ne=(9.9, 5.9), max_run_time_s=1800.0, max_invalid_dvl_s=2.0,
                start_position_ne=(2.0, 3.0), start_heading_rad=0.0)
    base.update(kw)
    return SupervisorLimits(**base)


# ------------------------------------------------------------------ finding 4: the supervisor on invalid data
def test_f4_invalid_dvl_freezes_dead_reckoning_and_trips():
    """58 s of velocity_valid=false at 10 Hz gave no trip on 3f4c425 while the position froze."""
    c = SupervisorCore(limits())
    c.set_armed(0.0, True)
    reason = ""
    for k in range(1, 600):  # 10 Hz DVL, invalid from t = 0.5 s; the other sensors healthy
        t = k / 10.0
        c.on_message("imu", t)
        c.on_altitude(t, 1.0)
        c.on_depth(t, 0.5)
        c.on_dvl(t, np.array([0.5, 0.0, 0.0]) if t < 0.5 else None)
        reason = c.check(t)
        if reason:
            break
    assert "no valid DVL velocity" in reason and "max_invalid_dvl_s 2" in reason
    assert t == pytest.approx(2.5, abs=0.11)  # 2 s after the last valid velocity at 0.4 s
    assert c.position_ne[0] == pytest.approx(2.0 + 0.5 * 0.3, abs=1e-9)  # 0.1..0.4 s integrated, then frozen


@pytest.mark.parametrize("depth", [math.nan, math.inf, -math.inf])
def test_f4_non_finite_depth_trips_at_once(depth):
    c = SupervisorCore(limits())
    c.set_armed(0.0, True)
    assert "not finite" in c.on_depth(0.1, depth)


def test_f4_altitude_no_detection_does_not_keep_the_altimeter_alive_and_blind_zone_trips():
    c = SupervisorCore(limits())
    c.set_armed(0.0, True)
    reason = ""
    for k in range(1, 100):
        t = k / 10.0
        c.on_message("imu", t)
        c.on_depth(t, 0.5)
        c.on_dvl(t, np.zeros(3))
        assert c.on_altitude(t, math.inf) == ""  # REP-117 no detection: not a reading, not a breach by itself
        reason = c.check(t)
        if reason:
            break
    assert "ping/altitude" in reason and "min_rate.altimeter_hz" in reason
    c2 = SupervisorCore(limits())
    c2.set_armed(0.0, True)
    assert "-inf" in c2.on_altitude(0.1, -math.inf)


def test_f4_clock_step_back_rebases_every_supervised_time():
    """After /clock steps back 100 s the IMU's loss still trips within the rate window (was: after 102 s)."""
    c = SupervisorCore(limits(min_rate_hz={"dvl": 0.0, "altimeter": 0.0, "pressure": 0.0, "imu": 20.0}))
    c.set_armed(500.0, True)
    for k in range(400):
        c.on_message("imu", 500.0 + k / 100.0)
    c.shift_time(-100.0)  # what the node does when it detects the step
    t, reason = 404.0, ""
    while not reason and t < 420.0:
        t += 0.05
        reason = c.check(t)
    assert "imu/data_raw" in reason and t < 404.0 + 3.0 + 0.1


# ------------------------------------------------------------------ finding 5: DVL gates after the lever arm
def _pdl(pitch_delta, dx=0.01, dt=0.1):
    return DvlPositionDelta(10.0, dt, 0.0, pitch_delta, 0.0, dx, 0.0, 0.0, 100.0)


def test_f5_wild_attitude_delta_is_rejected_not_a_180_m_s_velocity():
    b = DvlReportBuilder(position_frd_m=(0.0, 0.0, 0.18), max_speed_m_s=4.1, min_interval_s=0.025,
                         max_interval_s=1.0, max_angular_rate_rad_s=3.0)
    r = b.from_position_delta(_pdl(100.0), 0)
    assert not r.velocity_valid and "angular rate" in r.rejection
    # the speed gate sees the corrected velocity too: 10 rad/s passes a 20 rad/s rate gate, but
    # 0.01 - 1.0 * 0.18 m in 0.1 s is 1.7 m/s; at 3 rad over 0.1 s it is 5.4 m/s > 4.1
    b2 = DvlReportBuilder(position_frd_m=(0.0, 0.0, 0.18), max_speed_m_s=4.1, max_angular_rate_rad_s=50.0)
    assert b2.from_position_delta(_pdl(0.1), 0).velocity_valid
    r2 = b2.from_position_delta(_pdl(3.0), 0)
    assert not r2.velocity_valid and "lever-arm corrected" in r2.rejection


# ------------------------------------------------------------------ finding 6: MS5837 garbage
def test_f6_garbage_adc_words_almost_never_pass_the_depth_gates():
    s = SHIPPED.sensors.ms5837
    cal = ms.Calibration.from_coefficients(ms.EXAMPLE_COEFFICIENTS_30BA, ms.EXAMPLE_WORD0_30BA)
    rng = np.random.default_rng(23)
    gate = DepthGate(s.min_depth_m, s.max_depth_m, s.max_depth_rate_m_s, max_age_s=5.0 / s.rate_hz)
    assert gate.check(0.0, 1.0) == ""  # a real depth before the bus starts returning noise
    n, in_window, published = 20000, 0, []
    for k in range(n):
        d1, d2 = (int(x) for x in rng.integers(0, 1 << 24, 2))
        pa = ms.compensate(d1, d2, cal, ms.Variant.MS5837_30BA).pressure_pa
        if not s.min_pressure_pa <= pa <= s.max_pressure_pa:
            gate.invalid()  # as the node does for a reading outside the pressure window
            continue
        in_window += 1
        depth = ms.depth_m(pa)
        if gate.check(0.1 * (k + 1), depth) == "":
            published.append(depth)
    assert in_window / n > 0.03  # the pressure window alone lets 4.5 % through (the finding)
    assert len(published) / n < 0.002, published[:10]
    assert all(-2.0 <= d <= 31.0 for d in published)


def test_f6_depth_gate_holds_a_jump_until_confirmed():
    g = DepthGate(-2.0, 31.0, 2.0)
    assert g.check(0.0, 1.0) == ""
    assert g.check(0.1, 1.15) == ""  # 1.5 m/s
    assert "faster" in g.check(0.2, 5.0)
    assert g.check(0.3, 5.1) == ""  # confirmed by the next cycle: a real step (e.g. after an outage)
    assert "faster" in g.check(0.4, 9.0)
    g.invalid()
    assert "faster" in g.check(0.6, 9.1)  # not confirmed across a cycle without a reading
    assert "outside" in g.check(0.7, -5.2)


# ------------------------------------------------------------------ finding 8: config and Ping
@pytest.mark.parametrize("overrides, key", [
    ({"thrusters.t1.trim_us": 60.0}, "thrusters.t1.trim_us"),
    ({"esc.pwm_frequency_hz": 30.0}, "esc.pwm_frequency_hz"),
    ({"supervisor.max_depth_m": 100.0}, "supervisor.max_depth_m"),
    ({"supervisor.min_rate.imu_hz": 0.0}, "supervisor.min_rate.imu_hz"),
    ({"supervisor.min_altitude_m": 0.15, "limits.min_altitude_m": 0.3}, "supervisor.min_altitude_m"),
])
def test_f8_unsafe_configuration_is_refused_in_one_line(overrides, key):
    with pytest.raises(ConfigError) as err:
        load_config(default_config_path(), overrides)
    lines = [ln for ln in err.value.lines() if ln.startswith(key)]
    assert len(lines) == 1 and "\n" not in lines[0], err.value.lines()


def test_f8_a_disabled_rate_check_needs_a_reason():
    cfg = load_config(default_config_path(), {"supervisor.min_rate.dvl_hz": 0.0,
                                              "supervisor.rate_check_disabled.dvl": "no DVL fitted for this dive"})
    assert cfg.supervisor.min_rate.dvl_hz == 0.0
    with pytest.raises(ConfigError, match="rate_check_disabled.dvl"):
        load_config(default_config_path(), {"supervisor.rate_check_disabled.dvl": "on, yet disabled?"})


def test_f8_ping_out_of_range_is_published_per_rep117():
    assert rep117_range(0.15, 100, 0.3, 50.0) == -math.inf  # inside the blind zone
    assert rep117_range(60.0, 100, 0.3, 50.0) == math.inf
    assert rep117_range(2.0, 0, 0.3, 50.0) == math.inf
    assert rep117_range(2.0, 90, 0.3, 50.0) == 2.0


# ------------------------------------------------------------------ finding 10: allocation input checks
@pytest.mark.parametrize("frame, stamp_ns, fragment", [
    ("", 10**18, "frame_id is empty"),
    ("base_link", 0, "stamp is 0"),
    ("base_link", 10**18 + 3600 * 10**9, "in the future"),
    ("base_link", 10**18 - 10**9, "stale"),
])
def test_f10_wrench_header_checks(frame, stamp_ns, fragment):
    assert fragment in wrench_header_problem(frame, stamp_ns, 10**18, 0.5, 0.1)
    assert wrench_header_problem("base_link", 10**18 - 10**7, 10**18, 0.5, 0.1) == ""
