"""Disturbances of the virtual pool (sim/truth.py, sim/disturbances.py, sim/sensors.py): each against its law."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from hindrax_common.config import default_config_path, load_config
from hindrax_sim import sensors as sn
from hindrax_sim.model import rotation_matrix_from_quaternion
from hindrax_sim.simulator import Simulator
from hindrax_sim.truth import truth_from_mapping


@pytest.fixture(scope="module")
def vehicle():
    return load_config(default_config_path())


def sim_with(vehicle, doc, **kw):
    return Simulator(vehicle, truth=truth_from_mapping(vehicle, doc), sensors=False, **kw)


FWD = [1700.0, 1700.0, 1300.0, 1300.0, 1500.0, 1500.0, 1500.0, 1500.0]  # T1, T2 forward, T3, T4 reverse: surge


def test_thrust_scale_per_thruster_and_direction(vehicle):
    ref = sim_with(vehicle, {})
    ref.step(FWD)
    f0 = ref.thrust_n
    assert f0[0] > 0 and f0[2] < 0
    s = sim_with(vehicle, {"disturbances": {"thrust": {"scale": 0.9, "negative": 0.75,
                                                       "per_thruster": [1.0, 0.8, 1, 1, 1, 1, 1, 1]}}})
    s.step(FWD)
    f = s.thrust_n
    assert f[0] == pytest.approx(0.9 * f0[0])
    assert f[1] == pytest.approx(0.9 * 0.8 * f0[1])
    assert f[2] == pytest.approx(0.9 * 0.75 * f0[2])


def test_battery_law(vehicle):
    s = sim_with(vehicle, {"disturbances": {"battery": {"voltage_start_v": 16.0, "voltage_end_v": 12.0,
                                                        "nominal_voltage_v": 14.0, "duration_s": 10.0,
                                                        "exponent": 1.2}}})
    assert s.disturbances.battery_factor(0.0) == pytest.approx((16 / 14) ** 1.2)
    assert s.disturbances.battery_factor(5.0) == pytest.approx(1.0)
    assert s.disturbances.battery_factor(20.0) == pytest.approx((12 / 14) ** 1.2)


def test_inflow_loss_with_advance_speed(vehicle):
    s = sim_with(vehicle, {"disturbances": {"inflow": {"loss_per_m_s": 0.5}}})
    s.reset(nu=[0.4, 0, 0, 0, 0, 0])
    base = np.array([10.0, 10.0, -10.0, -10.0, 0, 0, 0, 0])
    f = s.disturbances.thrust_factor(0.0, s.state.tolist(), base)
    # T1 points forward-starboard at 55 deg: water enters at u cos(55) along its thrust
    assert f[0] == pytest.approx(1.0 - 0.5 * 0.4 * math.cos(math.radians(55)), rel=1e-4)
    # T3 points aft-starboard and pushes backwards (negative thrust): thrust direction -d3 has +x: same inflow
    assert f[2] == pytest.approx(f[0], rel=1e-4)


def test_esc_latency_delays_the_thrust(vehicle):
    s = sim_with(vehicle, {"esc": {"output_latency_s": 0.03}, "thrusters": {"time_constant_s": 0.0}})
    s.step(FWD)
    assert np.all(s.thrust_n == 0.0)
    s.advance(0.02)
    assert np.all(s.thrust_n == 0.0)
    s.advance(0.015)
    assert s.thrust_n[0] > 0.0


def test_constant_current_carries_the_vehicle(vehicle):
    s = sim_with(vehicle, {"disturbances": {"current": {"velocity_ned_m_s": [0.05, 0.0, 0.0]}}}, pool=False)
    s.advance(120.0)
    r = rotation_matrix_from_quaternion(s.quaternion_xyzw)
    v_ned = r @ s.nu[:3]
    # drifts with the water (heading 0: body x north); the last mm/s go slowly (quadratic damping of a small
    # relative speed)
    assert v_ned[0] == pytest.approx(0.05, abs=0.004)


def test_drag_centre_offset_gives_a_pitch_moment(vehicle):
    s = sim_with(vehicle, {"disturbances": {"hydrodynamics": {"drag_centre_offset_frd_m": [0.0, 0.0, -0.03]}}},
                 pool=False)
    s.reset(nu=[0.5, 0, 0, 0, 0, 0])
    w = s.disturbances.wrench(0.0, s.state.tolist(), [0.0] * 6)
    drag = 1.25 * 0.5 + 66.48 * 0.25  # surge damping of the vehicle file at 0.5 m/s
    # r x F with r = (0, 0, -0.03), F = (-drag, 0, 0): M = rz Fx = 0.03 drag (nose up)
    assert w[4] == pytest.approx(0.03 * drag)
    assert w[:4] == pytest.approx([0.0] * 4) and w[5] == pytest.approx(0.0)


def test_coupled_damping_and_tether(vehicle):
    doc = {"disturbances": {"hydrodynamics": {"damping_coupling_linear": [0.0] * 2 + [2.0] + [0.0] * 33},
                            "tether": {"anchor_ned_m": [0.0, 0.0, 1.0], "attachment_frd_m": [0.0, 0.0, 0.0],
                                       "drag_n_s2_m3": 0.0, "tension_n": 0.5}}}
    s = sim_with(vehicle, doc, pool=False)
    s.reset(position_ned_m=[3.0, 0.0, 1.0], nu=[0, 0, 0.2, 0, 0, 0])
    w = s.disturbances.wrench(0.0, s.state.tolist(), [0.0] * 6)
    assert w[0] == pytest.approx(-2.0 * 0.2 - 0.5)  # -D_c[0, 2] w, and the tension towards the anchor (north of... -x)
    assert w[1] == pytest.approx(0.0, abs=1e-12)


def test_floor_adds_heave_added_mass(vehicle):
    s = sim_with(vehicle, {"disturbances": {"floor": {"heave_added_mass_fraction": 0.5,
                                                      "reference_altitude_m": 0.5}}})
    s.reset(position_ned_m=[5.0, 3.0, 1.8 - 0.2 - 0.5])  # hull bottom (CO + 0.2 m) 0.5 m above the floor
    w = s.disturbances.wrench(0.0, s.state.tolist(), [0, 0, 1.0, 0, 0, 0])
    assert w[2] == pytest.approx(-0.5 * 22.48 * 1.0, rel=1e-6)


@pytest.fixture(scope="module")
def quiet(vehicle):
    over = {}
    for dev, unit in (("dvl75", "m_s"), ("icm20948_gyro", "rad_s"), ("icm20948_accel", "m_s2"), ("ms5837", "pa")):
        over[f"simulation.sensors.{dev}.noise_std_{unit}"] = 0.0
        over[f"simulation.sensors.{dev}.bias_{unit}"] = 0.0
        over[f"simulation.sensors.{dev}.dropout_probability"] = 0.0
    over["simulation.sensors.dvl75.scale_error_fraction"] = 0.0
    return truth_from_mapping(vehicle, {}, fill_only=True).config.with_overrides(over)


def _truth(t=1.0, nu=(0.3, 0.1, 0.0, 0, 0, 0), pos=(5.0, 3.0, 0.9)):
    q = Rotation.from_euler("ZYX", [0, 0, 0]).as_quat()
    return sn.VehicleTruth(t, np.array(pos), q, rotation_matrix_from_quaternion(q), np.zeros(3), np.array(nu, float),
                           np.zeros(6), np.zeros(6), 1.0)


def test_dvl_scale_factor_and_misalignment(quiet):
    suite = sn.SensorSuite(quiet, None, 1, devices=["dvl75"])
    truth = truth_from_mapping(quiet, {"disturbances": {"dvl": {"scale_factor": 1.02,
                                                                "misalignment_rpy_rad": [0.0, 0.0, 0.1]}}})
    suite.apply_disturbances(truth.disturbances)
    v = np.array(suite.measure("dvl75", _truth()).velocity_frd_m_s)
    c, s_ = math.cos(0.1), math.sin(0.1)
    assert v == pytest.approx(1.02 * np.array([c * 0.3 - s_ * 0.1, s_ * 0.3 + c * 0.1, 0.0]))


def test_dvl_multipath_dropouts_near_walls(quiet, vehicle):
    from hindrax_sim.pool import Pool
    suite = sn.SensorSuite(quiet, Pool.from_config(quiet), 1, devices=["dvl75"])
    d = truth_from_mapping(quiet, {"disturbances": {"dvl": {"multipath_distance_m": 1.0,
                                                            "multipath_dropout_probability": 0.6}}}).disturbances
    suite.apply_disturbances(d)
    near = [suite.measure("dvl75", _truth(pos=(0.5, 3.0, 0.9))) for _ in range(2000)]
    far = [suite.measure("dvl75", _truth(pos=(5.0, 3.0, 0.9))) for _ in range(200)]
    # the DVL sits 0.0 m forward of CO: 0.5 m from the x = 0 wall -> p = 0.6 (1 - 0.5 / 1.0) = 0.3
    assert sum(x is None for x in near) / 2000 == pytest.approx(0.3, abs=0.04)
    assert all(x is not None for x in far)


def test_imu_bias_random_walk_and_pressure_drift(quiet):
    suite = sn.SensorSuite(quiet, None, 1, devices=["icm20948_gyro", "ms5837"])
    d = truth_from_mapping(quiet, {"disturbances": {"imu": {"gyro_bias_walk_rad_s_sqrt_s": 0.01},
                                                    "pressure": {"drift_pa_per_s": 2.0}}}).disturbances
    suite.apply_disturbances(d)
    rates = np.array([suite.measure("icm20948_gyro", _truth(t=float(k), nu=(0, 0, 0, 0, 0, 0))).angular_rate_rad_s
                      for k in range(1, 2002)])
    steps = np.diff(rates, axis=0)  # increments over 1 s: N(0, 0.01^2) per axis
    assert np.std(steps) == pytest.approx(0.01, rel=0.05)
    assert abs(np.mean(steps)) < 0.001
    p = suite.measure("ms5837", _truth(t=50.0))
    assert p.pressure_pa - p.true_pressure_pa == pytest.approx(100.0)
