"""Virtual pool box: free surface (Archimedes), floor and wall contacts, contact reports."""
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from hindrax_common.config import default_config_path, load_config
from hindrax_sim.pool import FACES, FreeSurface, Pool
from hindrax_sim.simulator import Simulator


@pytest.fixture(scope="module")
def cfg():
    return load_config(default_config_path())


def hull_corners_ned(sim):
    """The 8 corners of the hull box (vehicle envelope centred on the CB) in the pool frame."""
    f = sim.config.flat
    half = 0.5 * np.array([f["vehicle.length_m"], f["vehicle.width_m"], f["vehicle.height_m"]])
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    body = sim.config.vehicle.centre_of_buoyancy_frd_m + signs * half
    return sim.position_ned_m + body @ sim.rotation.T


def test_free_surface_fraction_geometry():
    fs = FreeSurface((0.3, 0.2, 0.1), (0.0, 0.0, -0.05))
    # level: hull centre at depth z - 0.05, vertical half extent 0.1
    assert fs(0.5, 0.0, 0.0, 1.0) == 1.0
    assert fs(0.05, 0.0, 0.0, 1.0) == pytest.approx(0.5)  # centre exactly at the surface: half submerged
    assert fs(0.10, 0.0, 0.0, 1.0) == pytest.approx(0.75)
    assert fs(-0.2, 0.0, 0.0, 1.0) == 0.0
    # pitched 90 deg nose down: the body x axis is vertical, half extent 0.3, the CB offset is horizontal
    r = Rotation.from_euler("y", -math.pi / 2).as_matrix()
    assert fs.vertical_half_extent_m(*r[2]) == pytest.approx(0.3)
    assert fs(0.15, *r[2]) == pytest.approx(0.75)


def test_unpowered_vehicle_rises_and_floats_at_the_archimedes_waterline(cfg):
    """Released at 1 m depth with the thrusters stopped, the positively buoyant vehicle (B - W = 0.785 N,
    [Hindrax-Drag] §5) rises, breaks the surface and stays there with the submerged fraction W / B (Archimedes);
    with the hull centred on the CB that puts the CB at depth h (2 W / B - 1), h = height / 2."""
    sim = Simulator(cfg, sensors=False)
    start = [5.0, 3.0, 1.0]
    sim.reset(position_ned_m=start)
    w, b = cfg.weight_n, cfg.buoyancy_n
    h = 0.5 * cfg.vehicle.height_m
    z_eq = h * (2.0 * w / b - 1.0) - cfg.vehicle.centre_of_buoyancy_frd_m[2]
    depths = []
    for _ in range(int(round(60.0 / sim.step_s))):
        sim.step([1500.0] * 8)
        depths.append(sim.position_ned_m[2])
        assert sim.position_ned_m[2] > -h  # never leaves the water
    depths = np.array(depths)
    n20 = int(round(20.0 / sim.step_s))
    assert np.all(np.diff(depths[: n20 // 2]) < 0.0)  # first it rises
    assert np.all(np.abs(depths[-n20:] - z_eq) < 0.005)  # the last 20 s within 5 mm of the waterline
    assert sim.buoyancy_fraction == pytest.approx(w / b, abs=1e-3)
    assert abs(sim.nu[2]) < 1e-3
    assert np.allclose(sim.position_ned_m[:2], start[:2], atol=1e-9)  # straight up
    assert sim.contact.faces == ("surface",) and sim.contact.since_s["surface"] > 10.0


def test_wall_contact_clamps_reports_and_clears(cfg):
    sim = Simulator(cfg, sensors=False)
    length = cfg.pool.length_m
    sim.reset(position_ned_m=[length - 1.5, 3.0, 1.0], rpy_rad=[0, 0, 0])
    sim.advance(12.0, external_wrench_frd=[15.0, 0, 0.785, 0, 0, 0])  # push north; Z cancels B - W
    contact = sim.contact
    assert "north_wall" in contact.faces
    started = contact.since_s["north_wall"]
    assert 1.0 < started < 12.0
    # the hull front touches the wall: x + half length * cos(pitch) ... within the box, not beyond
    assert np.max(hull_corners_ned(sim)[:, 0]) == pytest.approx(length, abs=1e-6)
    assert abs(sim.nu[0]) < 1e-3  # the velocity into the wall is removed
    sim.advance(1.0)
    assert sim.contact.since_s["north_wall"] == started  # a continuing contact keeps its start time
    sim.advance(3.0, external_wrench_frd=[-15.0, 0, 0.785, 0, 0, 0])
    assert "north_wall" not in sim.contact.faces
    assert sim.nu[0] < -0.1


def test_floor_contact(cfg):
    sim = Simulator(cfg, sensors=False)
    depth = cfg.pool.depth_m
    sim.reset(position_ned_m=[5.0, 3.0, 1.2])
    sim.advance(8.0, external_wrench_frd=[0, 0, 20.0, 0, 0, 0])
    assert sim.contact.faces == ("floor",)
    assert np.max(hull_corners_ned(sim)[:, 2]) == pytest.approx(depth, abs=1e-6)
    assert abs(sim.nu[2]) < 1e-6


def test_vehicle_cannot_leave_the_box(cfg):
    """Random strong thrust for 60 s: every hull corner stays inside the pool box (and below the surface
    level minus the hull size)."""
    sim = Simulator(cfg, sensors=False)
    sim.reset(position_ned_m=[5.0, 3.0, 0.9])
    rng = np.random.default_rng(2)
    f = cfg.flat
    seen = set()
    for k in range(int(60.0 / sim.step_s)):
        pw = rng.uniform(1100, 1900, 8) if k % 200 == 0 else None
        sim.step(pw)
        if k % 10 == 0:
            c = hull_corners_ned(sim)
            assert np.all(c[:, 0] >= -1e-9) and np.all(c[:, 0] <= f["pool.length_m"] + 1e-9)
            assert np.all(c[:, 1] >= -1e-9) and np.all(c[:, 1] <= f["pool.width_m"] + 1e-9)
            assert np.all(c[:, 2] <= f["pool.depth_m"] + 1e-9) and np.max(c[:, 2]) >= -1e-9
            seen |= set(sim.contact.faces)
    assert seen & {"north_wall", "south_wall", "east_wall", "west_wall", "floor"}  # contacts did happen
    assert set(FACES) >= seen


def test_geometry_queries(cfg):
    pool = Pool.from_config(cfg)
    assert pool.altitude_m([1, 1, 0.5]) == pytest.approx(1.3)
    assert pool.wall_distance_m([0.3, 3.0, 1.0]) == pytest.approx(0.3)
    assert pool.wall_distance_m([5.0, 5.9, 1.0]) == pytest.approx(0.1)
    # straight down from 0.5 m: 1.3 m; tilted 30 deg: slant 1.3 / cos 30
    assert pool.ray_distance_m([5, 3, 0.5], [0, 0, 1]) == pytest.approx(1.3)
    d = [math.sin(math.radians(30)), 0, math.cos(math.radians(30))]
    assert pool.ray_distance_m([5, 3, 0.5], d) == pytest.approx(1.3 / math.cos(math.radians(30)))
    # a shallow ray towards the north wall hits the wall first
    d = [math.cos(0.1), 0, math.sin(0.1)]
    assert pool.ray_distance_m([9.0, 3, 0.5], d) == pytest.approx(1.0 / math.cos(0.1))
    assert pool.ray_distance_m([5, 3, 0.5], [0, 0, -1]) == math.inf  # up through the surface
    with pytest.raises(ValueError):
        Pool(0.5, 6.0, 1.8, FreeSurface((0.3, 0.2, 0.2), (0, 0, 0)))
