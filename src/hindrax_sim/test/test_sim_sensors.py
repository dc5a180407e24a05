"""Sensor truth and noise models of the virtual pool, checked against physics and the configured statistics."""
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from hindrax_common.config import default_config_path, load_config
from hindrax_sim import sensors as sn
from hindrax_sim.model import rotation_matrix_from_quaternion
from hindrax_sim.pool import Pool
from hindrax_sim.simulator import Simulator
from hindrax_sim.truth import load_truth

G = 9.81


@pytest.fixture(scope="module")
def cfg():
    """The simulator's configuration: the vehicle file with the default truth (sim/truth.py: sensor noise)."""
    return load_truth(load_config(default_config_path())).config


@pytest.fixture(scope="module")
def quiet_cfg(cfg):
    """Every noise, bias and dropout off (truth equals measurement)."""
    over = {}
    for key in cfg.flat:
        leaf = key.split(".")[-1]
        if key.startswith("simulation.sensors.") and (leaf.startswith(("noise_std_", "bias_")) or
                                                      leaf in ("dropout_probability", "scale_error_fraction")):
            over[key] = 0.0
    return cfg.with_overrides(over)


def truth(position=(5.0, 3.0, 1.0), rpy=(0.0, 0.0, 0.0), nu=None, nu_dot=None, t=1.0):
    q = Rotation.from_euler("ZYX", [rpy[2], rpy[1], rpy[0]]).as_quat()
    r = rotation_matrix_from_quaternion(q)
    return sn.VehicleTruth(t, np.array(position, float), q, r, np.array(rpy, float),
                           np.zeros(6) if nu is None else np.array(nu, float),
                           np.zeros(6) if nu_dot is None else np.array(nu_dot, float), np.zeros(6), 1.0)


# ----------------------------------------------------------------------------------- IMU
def test_specific_force_at_rest_reads_minus_gravity(quiet_cfg):
    """f = a - g: at rest the accelerometer reads g upwards: [0, 0, -g] in FRD, [0, 0, +g] in FLU."""
    accel = sn.AccelModel(quiet_cfg, seed=1)
    s = accel.measure(truth())
    assert np.allclose(s.specific_force_m_s2, [0, 0, G])  # sensor frame = base_link FLU (mounting 0)
    # rolled 30 deg to starboard: gravity has a body +y (starboard) component -> f_y = -g sin(phi) in FRD
    phi = math.radians(30)
    f_frd = sn.specific_force_frd(np.zeros(6), np.zeros(6), truth(rpy=(phi, 0, 0)).rotation, G)
    assert np.allclose(f_frd, [0, -G * math.sin(phi), -G * math.cos(phi)])
    theta = math.radians(20)  # nose up: gravity points backwards in the body, f_x = +g sin(theta)
    f_frd = sn.specific_force_frd(np.zeros(6), np.zeros(6), truth(rpy=(0, theta, 0)).rotation, G)
    assert np.allclose(f_frd, [G * math.sin(theta), 0, -G * math.cos(theta)])


def test_specific_force_centripetal_and_coriolis():
    """Yawing at r with a lever arm l forward: centripetal -r^2 l along x; surging at u while yawing: the
    path curves, a_y = u r (w x v)."""
    r_rate, lever = 1.5, 0.2
    f = sn.specific_force_frd([0, 0, 0, 0, 0, r_rate], np.zeros(6), np.eye(3), G, (lever, 0, 0))
    assert np.allclose(f, [-r_rate ** 2 * lever, 0, -G])
    f = sn.specific_force_frd([0.5, 0, 0, 0, 0, 0.4], np.zeros(6), np.eye(3), G)
    assert np.allclose(f, [0, 0.5 * 0.4, -G])
    f = sn.specific_force_frd(np.zeros(6), [1.0, 0, 0, 0, 0, 0], np.eye(3), G)
    assert np.allclose(f, [1.0, 0, -G])


def test_gyro_and_magnetometer_frames(quiet_cfg):
    gyro, mag = sn.GyroModel(quiet_cfg, 1), sn.MagModel(quiet_cfg, 1)
    s = gyro.measure(truth(nu=[0, 0, 0, 0.1, 0.2, 0.3]))
    assert np.allclose(s.angular_rate_rad_s, [0.1, -0.2, -0.3])  # FRD -> FLU sensor axes
    b_n, b_e, b_d = quiet_cfg.simulation.sensors.icm20948_mag.earth_field_ned_t
    s = mag.measure(truth(rpy=(0, 0, 0)))
    assert np.allclose(s.magnetic_field_t, [b_n, -b_e, -b_d])
    # heading east (yaw +90 deg): forward sees the east component, starboard (south) sees -north
    s = mag.measure(truth(rpy=(0, 0, math.pi / 2)))
    assert np.allclose(s.magnetic_field_t, [b_e, b_n, -b_d])
    # the heading recovered from a level magnetometer is the yaw minus the declination
    for yaw in (0.3, -2.0, 2.9):
        fx, fy, _ = mag.measure(truth(rpy=(0, 0, yaw))).magnetic_field_t
        heading = math.atan2(fy, fx)  # FLU sensor: y left -> -(starboard)
        assert heading == pytest.approx(math.atan2(math.sin(yaw - math.atan2(b_e, b_n)),
                                                   math.cos(yaw - math.atan2(b_e, b_n))), abs=1e-9)


def test_imu_mounting_rotation(quiet_cfg):
    """A sensor yawed +90 deg in base_link (FLU) sees the base_link x axis as its -y axis."""
    c = quiet_cfg.with_overrides({"sensors.icm20948.mounting_rpy_rad": [0.0, 0.0, math.pi / 2]})
    s = sn.GyroModel(c, 1).measure(truth(nu=[0, 0, 0, 0.4, 0, 0]))
    assert np.allclose(s.angular_rate_rad_s, [0, -0.4, 0], atol=1e-12)


# ----------------------------------------------------------------------------------- pressure & altitude
def test_pressure_at_port_depth(quiet_cfg):
    model = sn.PressureModel(quiet_cfg, 1)
    port = quiet_cfg.sensors.ms5837.position_frd_m
    s = model.measure(truth(position=(5, 3, 1.0)))
    depth = 1.0 + port[2]
    assert s.true_depth_m == pytest.approx(depth)
    assert s.pressure_pa == pytest.approx(101325.0 + 1000.0 * G * depth)
    # pitched 20 deg nose up: the rear port (x = -0.2 m) goes deeper by 0.2 sin(20 deg)
    th = math.radians(20)
    s = model.measure(truth(position=(5, 3, 1.0), rpy=(0, th, 0)))
    assert s.true_depth_m == pytest.approx(1.0 - port[0] * math.sin(th) + port[2] * math.cos(th))
    s = model.measure(truth(position=(5, 3, 0.05)))  # port above the surface: atmospheric pressure
    assert s.pressure_pa == pytest.approx(101325.0) and s.true_depth_m == 0.0


def test_sonar_slant_range(quiet_cfg):
    pool = Pool.from_config(quiet_cfg)
    model = sn.AltitudeModel(quiet_cfg, pool, 1)
    son = np.array(quiet_cfg.sensors.ping1d.position_frd_m)
    depth = quiet_cfg.pool.depth_m
    s = model.measure(truth(position=(5, 3, 1.0)))
    assert s.valid and s.distance_m == pytest.approx(depth - 1.0 - son[2])
    phi = math.radians(20)
    t = truth(position=(5, 3, 1.0), rpy=(phi, 0, 0))
    z_sonar = 1.0 + t.rotation[2] @ son
    s = model.measure(t)
    assert s.distance_m == pytest.approx((depth - z_sonar) / math.cos(phi))
    s = model.measure(truth(position=(5, 3, 1.5)))  # 0.12 m from the floor: below the minimum range
    assert not s.valid and math.isnan(s.distance_m)


# ----------------------------------------------------------------------------------- DVL
def test_dvl_velocity_at_its_position_and_lock_rules(quiet_cfg):
    pool = Pool.from_config(quiet_cfg)
    model = sn.DvlVelocityModel(quiet_cfg, pool, 1)
    r = np.array(quiet_cfg.sensors.dvl75.position_frd_m)
    nu = [0.3, -0.1, 0.05, 0.2, -0.1, 0.5]
    s = model.measure(truth(nu=nu))
    assert s.locked
    assert np.allclose(s.velocity_frd_m_s, np.array(nu[:3]) + np.cross(nu[3:], r))
    assert s.altitude_m == pytest.approx(quiet_cfg.pool.depth_m - 1.0 - r[2])
    s = model.measure(truth(position=(5, 3, 1.5)))  # 0.12 m above the floor: below min_altitude_m
    assert not s.locked and math.isnan(s.velocity_frd_m_s[0])
    s = model.measure(truth(position=(0.1, 3, 1.0)))  # 0.1 m from the south wall
    assert not s.locked
    s = model.measure(truth(position=(5, 3, -0.5)))  # out of the water
    assert not s.locked


def test_dvl_noise_statistics(cfg):
    """Multiplicative 5 % (1-sigma per report, [Hindrax-Drag] Table 1) and additive noise: at a steady 0.5 m/s surge
    the reports have mean 0.5 + bias and std sqrt((0.05 * 0.5)^2 + sigma_n^2)."""
    pool = Pool.from_config(cfg)
    model = sn.DvlVelocityModel(cfg, pool, 3)
    t = truth(nu=[0.5, 0, 0, 0, 0, 0])
    u = np.array([model.measure(t).velocity_frd_m_s[0] for _ in range(4000)])
    sc, sd, bias = (cfg.get(f"simulation.sensors.dvl75.{k}") for k in ("scale_error_fraction", "noise_std_m_s",
                                                                        "bias_m_s"))
    expected_std = math.hypot(sc * 0.5, sd)
    assert u.std() == pytest.approx(expected_std, rel=0.08)
    assert u.mean() == pytest.approx(0.5 + bias, abs=4 * expected_std / math.sqrt(len(u)))
    v = np.array([model.measure(t).velocity_frd_m_s[1] for _ in range(2000)])
    assert v.std() == pytest.approx(sd, rel=0.1)  # no scale error on a zero velocity


# ----------------------------------------------------------------------------------- rates, dropouts, seeds
def test_rates_and_dropout(cfg):
    c = cfg.with_overrides({"simulation.sensors.ping1d.dropout_probability": 0.3})
    sim = Simulator(c)
    sim.reset(position_ned_m=[5, 3, 1.0])
    counts: dict[str, int] = {}
    sim.add_sensor_listener(lambda name, s: counts.__setitem__(name, counts.get(name, 0) + 1))
    sim.advance(20.0, [1500] * 8, external_wrench_frd=[0, 0, 0.785, 0, 0, 0])
    for dev in ("icm20948_accel", "icm20948_gyro", "icm20948_mag", "ms5837", "dvl75", "dvl75_attitude"):
        rate = c.get(f"simulation.sensors.{dev}.rate_hz")
        expected = rate * 20.0 * (1 - c.get(f"simulation.sensors.{dev}.dropout_probability"))
        assert counts[dev] == pytest.approx(expected, rel=0.05, abs=2), dev
    n_ping = 20.0 * c.simulation.sensors.ping1d.rate_hz
    assert counts["ping1d"] == pytest.approx(0.7 * n_ping, abs=4 * math.sqrt(n_ping * 0.21))
    assert sim.sensors.latest["ms5837"].stamp_s == pytest.approx(20.0, abs=0.11)


def test_device_streams_do_not_depend_on_other_devices(cfg):
    def gyro_values(devices):
        sim = Simulator(cfg, seed=4, sensors=devices)
        sim.reset(position_ned_m=[5, 3, 1.0])
        out = []
        sim.add_sensor_listener(lambda n, s: out.append(s.angular_rate_rad_s) if n == "icm20948_gyro" else None)
        sim.advance(1.0)
        return out

    assert gyro_values(["icm20948_gyro"]) == gyro_values(None)
    with pytest.raises(ValueError):
        Simulator(cfg, sensors=["sonar9000"])


def test_stop_grid_leaves_only_on_demand_samples(cfg):
    """The live pool stops the rate grid: steps sample nothing, ``latest`` holds, :meth:`measure` still answers."""
    sim = Simulator(cfg)
    sim.advance(0.2)
    before = dict(sim.sensors.latest)
    assert set(before) == set(sim.sensors.models)
    sim.sensors.stop_grid()
    assert all(sim.step() == [] for _ in range(100))  # 0.5 s: every device (>= 10 Hz) would have sampled
    assert sim.sensors.latest == before
    assert sim.measure("ms5837") is not None
    sim.sensors.reset(sim.t_s)
    assert any(sim.step() for _ in range(100))
