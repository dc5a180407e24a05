"""A sloped pool floor (truth ``disturbances.floor.gradient``): altitudes, Ping1D and DVL beam ranges, contact, and the
DVL beam ranges through the emulator and driver message into the campaign's sensor samples.

Expected values are plain geometry written out here (a ray from a point along a direction to the plane
z = D + g_n (x - L/2) + g_e (y - W/2)), not the simulator's own ray caster."""
import math
from types import SimpleNamespace

import numpy as np
import pytest

from hindrax_common.config import default_config_path, load_config
from hindrax_drivers.dvl75.protocol import BEAM_TILT_RAD
from hindrax_onboard.vehicle.state import SensorState
from hindrax_onboard.vehicle.signals import samples_from_dvl
from hindrax_sim.simulator import Simulator
from hindrax_sim.truth import TruthError, load_truth, truth_from_mapping, with_floor_gradient

GRAD = (-0.08, 0.03)


@pytest.fixture(scope="module")
def cfg():
    return load_config(default_config_path())


def plane_depth(cfg, x, y, g=GRAD):
    f = cfg.flat
    return f["pool.depth_m"] + g[0] * (x - 0.5 * f["pool.length_m"]) + g[1] * (y - 0.5 * f["pool.width_m"])


def test_floor_gradient_moves_the_floor_and_the_dvl_altitude(cfg):
    sim = Simulator(cfg, truth=with_floor_gradient(load_truth(cfg), GRAD))
    pool = sim.pool
    # 2 m north of the centre the floor is 0.16 m shallower, 1 m east 0.03 m deeper
    assert pool.floor_depth_m(7.0, 4.0) == pytest.approx(1.8 - 0.16 + 0.03)
    assert pool.altitude_m([7.0, 4.0, 1.0]) == pytest.approx(1.8 - 0.16 + 0.03 - 1.0)
    # default truth: flat
    flat = Simulator(cfg).pool
    assert flat.floor_depth_m(7.0, 4.0) == pytest.approx(1.8)


def test_ping_and_dvl_beams_see_the_slope(cfg):
    """A level vehicle: the Ping1D range along body z, and each beam tilted 22.5 deg, hit the sloped plane where the
    hand-solved ray meets it."""
    quiet = {"ping1d": {"noise_std_m": 0.0, "dropout_probability": 0.0},
             "dvl75": {"noise_std_m_s": 0.0, "scale_error_fraction": 0.0, "dropout_probability": 0.0}}
    truth = truth_from_mapping(cfg, {"simulation": {"sensors": quiet}})
    sim = Simulator(cfg, truth=with_floor_gradient(truth, GRAD))
    x0, y0, z0 = 3.0, 2.5, 1.0
    sim.reset(position_ned_m=[x0, y0, z0], rpy_rad=[0.0, 0.0, 0.0])
    samples = {}
    sim.add_sensor_listener(lambda dev, s: samples.setdefault(dev, s))
    sim.advance(0.2, [1500.0] * 8)
    ping = np.asarray(cfg.sensors.ping1d.position_frd_m)
    px, py, pz = x0 + ping[0], y0 + ping[1], z0 + ping[2]
    assert samples["ping1d"].distance_m == pytest.approx(plane_depth(cfg, px, py) - pz, abs=2e-3)  # body moved < 2 mm
    dvl = np.asarray(cfg.sensors.dvl75.position_frd_m)
    s, c = math.sin(BEAM_TILT_RAD), math.cos(BEAM_TILT_RAD)
    p = sim.position_ned_m + dvl
    h = plane_depth(cfg, p[0], p[1]) - p[2]
    expected = []
    for d in ((0.0, -s, c), (-s, 0.0, c), (0.0, s, c), (s, 0.0, c)):  # port, stern, starboard, bow
        expected.append(h / (d[2] - GRAD[0] * d[0] - GRAD[1] * d[1]))
    got = samples["dvl75"].beam_range_m
    for g, e in zip(got, expected):
        assert g == pytest.approx(e, rel=0.05)  # 1 % range noise in the default truth
    # the bow beam looks up-slope (north, shallower): shorter than the stern beam
    assert got[3] < got[1]


def test_vehicle_rests_on_the_sloped_floor(cfg):
    """A sinking vehicle (net buoyancy negative) comes to rest on the floor under its hull centre."""
    truth = truth_from_mapping(cfg, {"vehicle": {"mass_kg": 15.4, "net_buoyancy_n": -0.98}})
    sim = Simulator(cfg, truth=with_floor_gradient(truth, GRAD), sensors=False)
    sim.reset(position_ned_m=[7.0, 3.0, 1.0])
    sim.advance(20.0, [1500.0] * 8)
    f = cfg.flat
    cb = cfg.vehicle.centre_of_buoyancy_frd_m
    bottom = sim.position_ned_m[2] + cb[2] + 0.5 * f["vehicle.height_m"]
    floor = plane_depth(cfg, sim.position_ned_m[0] + cb[0], sim.position_ned_m[1] + cb[1])
    assert bottom == pytest.approx(floor, abs=0.01)
    assert "floor" in sim.contact.faces


def test_floor_gradient_out_of_range_is_one_line(cfg):
    with pytest.raises(TruthError, match="floor.gradient"):
        truth_from_mapping(cfg, {"disturbances": {"floor": {"gradient": [0.9, 0.0]}}})


def test_dvl_emulator_reports_the_simulated_beam_ranges(dvl_reports):
    """Through the emulator on a pty and the driver's parser: $DVEXT carries the sloped floor's beam ranges."""
    from hindrax_drivers.dvl75 import protocol as dvl
    from hindrax_sim.hardware import VirtualHardware

    vehicle = load_config(default_config_path())
    sim = Simulator(vehicle, seed=3, truth=with_floor_gradient(load_truth(vehicle), (-0.15, 0.0)))
    vh = VirtualHardware(sim, sim.config)
    try:
        sim.reset(position_ned_m=[5.0, 3.0, 1.0])
        records = dvl_reports(sim, vh, lambda rs: any(isinstance(r, dvl.DvlExtended) and r.locked for r in rs),
                              "$DVEXT report with lock")
        ext = [r for r in records if isinstance(r, dvl.DvlExtended) and r.locked][-1]
        port_b, stern, starboard, bow = ext.beam_range_m
        p = sim.position_ned_m + np.asarray(vehicle.sensors.dvl75.position_frd_m)
        h = plane_depth(vehicle, p[0], p[1], (-0.15, 0.0)) - p[2]
        s, c = math.sin(BEAM_TILT_RAD), math.cos(BEAM_TILT_RAD)
        assert bow == pytest.approx(h / (c + 0.15 * s), rel=0.05)  # up-slope
        assert stern == pytest.approx(h / (c - 0.15 * s), rel=0.05)  # down-slope
        assert port_b == pytest.approx(h / c, rel=0.05)
    finally:
        vh.close()


def test_beam_ranges_reach_the_sensor_state_from_a_driver_message():
    """hindrax_msgs/Dvl beam_range_m / beam_lock -> the dvl75 sample -> SensorState (NaN for an unlocked beam)."""
    cfg = load_config(default_config_path())
    msg = SimpleNamespace(
        header=SimpleNamespace(stamp=SimpleNamespace(sec=10, nanosec=0)), delta_time_s=0.1,
        orientation=SimpleNamespace(x=0.0, y=0.0, z=0.0, w=1.0), velocity_m_s=SimpleNamespace(x=0.1, y=0.0, z=0.0),
        velocity_valid=True, beam_range_m=[0.61, 0.60, -1.0, 0.55], beam_lock=[True, True, False, True])
    st = SensorState(cfg)
    for dev, s in samples_from_dvl(msg):
        st.on_sample(dev, s)
    assert st.dvl_beam_stamp_s == pytest.approx(10.0)
    assert st.dvl_beam_range_m[0] == pytest.approx(0.61)
    assert math.isnan(st.dvl_beam_range_m[2])
    assert st.dvl_beam_range_m[3] == pytest.approx(0.55)


PROFILE = ((3.5, 1.8), (4.4, 1.5), (10.0, 1.5 - 5.6 / 12.0))  # the deep end, 1:3, then 1:12 (control evaluate)


def test_floor_profile_depths_rays_and_contact(cfg):
    """A floor that changes slope (Pool.set_floor_profile): depth by hand-interpolation, a vertical ray and a ray
    tilted forward that lands on the 1:3 ramp (solved by hand below), a ray from under the floor, bad profiles, and
    a sinking vehicle resting on the ramp."""
    sim = Simulator(cfg, sensors=False)
    pool = sim.pool
    pool.set_floor_profile(PROFILE)
    assert pool.floor_depth_m(1.0, 2.0) == pytest.approx(1.8)  # before the first point: constant
    assert pool.floor_depth_m(3.95, 2.0) == pytest.approx(1.8 - 0.45 / 3.0)  # middle of the ramp
    assert pool.floor_depth_m(7.2, 2.0) == pytest.approx(1.5 - 2.8 / 12.0)
    assert pool.floor_depth_m(11.0, 2.0) == pytest.approx(1.5 - 5.6 / 12.0)
    assert pool.ray_distance_m([3.0, 3.0, 1.0], [0.0, 0.0, 1.0]) == pytest.approx(0.8)
    s, c = math.sin(math.radians(22.5)), math.cos(math.radians(22.5))
    # from (3.4, 1.0) the ray x = 3.4 + t s, z = 1 + t c meets z = 1.8 - (x - 3.5) / 3 at
    # t = (0.8 + 0.1 / 3) / (c + s / 3), on the ramp (the flat floor's 0.8 / c would land at x = 3.73)
    t = (0.8 + 0.1 / 3.0) / (c + s / 3.0)
    assert 3.5 < 3.4 + t * s < 4.4
    assert pool.ray_distance_m([3.4, 3.0, 1.0], [s, 0.0, c]) == pytest.approx(t, rel=1e-9)
    # looking back (south) the same ray meets the flat deep end: 0.8 / c
    assert pool.ray_distance_m([3.0, 3.0, 1.0], [-s, 0.0, c]) == pytest.approx(0.8 / c, rel=1e-9)
    assert pool.ray_distance_m([4.0, 3.0, 1.7], [0.0, 0.0, 1.0]) == math.inf  # under the ramp
    for bad in ([(1.0, 1.8)], [(2.0, 1.8), (1.0, 1.5)], [(1.0, 1.8), (2.0, -0.1)], [(1.0, 1.8), (1.5, 0.5)],
                [(1.0, math.nan), (2.0, 1.5)]):
        with pytest.raises(ValueError, match="floor profile"):
            pool.set_floor_profile(bad)
    pool.set_floor_profile(())
    assert pool.floor_depth_m(7.2, 2.0) == pytest.approx(1.8)  # flat again

    truth = truth_from_mapping(cfg, {"vehicle": {"mass_kg": 15.4, "net_buoyancy_n": -0.98}})
    sink = Simulator(cfg, truth=truth, sensors=False)
    sink.pool.set_floor_profile(PROFILE)
    sink.reset(position_ned_m=[7.0, 3.0, 0.9])
    sink.advance(8.0, [1500.0] * 8)
    cb = cfg.vehicle.centre_of_buoyancy_frd_m
    bottom = sink.position_ned_m[2] + cb[2] + 0.5 * cfg.flat["vehicle.height_m"]
    assert bottom == pytest.approx(sink.pool.floor_depth_m(sink.position_ned_m[0] + cb[0], 3.0), abs=0.01)
    assert "floor" in sink.contact.faces
