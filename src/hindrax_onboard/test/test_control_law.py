"""The control law (docs/control.md §2): reference model, gains, feedforward, anti-windup, floor estimate.

The plants here are written out in the test (a 1-DOF heave with its own inertia, damping, buoyancy and thrust scale,
integrated at 1 ms), and the expected responses are the textbook ones (critically damped second order), not the
controller's own reference model."""
import math

import numpy as np
import pytest

from hindrax_common.config import default_config_path, load_config
from hindrax_onboard.control.law import (MIN_BANDWIDTH_FACTOR, UNCERTAINTY_Z, ControlInput, ControlSettings, Controller,
                                       FloorEstimator, ReferenceModel, design_gains)
from hindrax_onboard.control.model import AxisModel, ControlModel, model_from_config

TICK = 0.02


@pytest.fixture(scope="module")
def cfg():
    return load_config(default_config_path())


def test_reference_model_is_the_critically_damped_response():
    w, r = 2.0, 0.3
    ref = ReferenceModel(w)
    ref.reset(0.0)
    for k in range(1, 301):
        x, v, _ = ref.step(r, TICK)
        t = k * TICK
        assert x == pytest.approx(r * (1.0 - (1.0 + w * t) * math.exp(-w * t)), abs=1e-3)
        assert v == pytest.approx(r * w * w * t * math.exp(-w * t), abs=2e-3)


def test_reference_model_limits_acceleration_and_rate_and_brakes_harder():
    ref = ReferenceModel(2.0, max_rate=0.1, max_accel=0.2)
    ref.reset(0.0)
    xs, vs, acc = [], [], []
    for _ in range(1000):
        x, v, a = ref.step(1.0, TICK)
        xs.append(x), vs.append(v), acc.append(a)
    assert max(vs) <= 0.1 + 1e-12
    speeding = [a for a, v in zip(acc, vs) if a * v > 0]
    assert max(abs(a) for a in speeding) <= 0.2 + 1e-9
    assert xs[-1] == pytest.approx(1.0, abs=1e-3)
    # a hold engaged on a moving vehicle brakes with twice the speed-up limit
    ref = ReferenceModel(2.0, max_accel=0.2)
    ref.reset(0.0, 1.0)
    _, v, a = ref.step(0.0, 0.005)
    assert a == pytest.approx(-0.4)


def _axis(dof, inertia, rel_std=0.0, kl=0.0, kq=0.0, bias=0.0):
    return AxisModel(dof, inertia, rel_std, kl, kl, kq, kq, bias, 0.0, {"inertia": "test"})


def test_gains_are_lowered_by_the_inertia_uncertainty():
    g = design_gains(_axis("heave", 40.0, 0.10), 2.0)
    factor = 1.0 - 1.96 * 0.10
    assert g.w == pytest.approx(2.0 * factor)
    assert g.kp == pytest.approx((2.0 * factor) ** 2)
    assert g.kd == pytest.approx(2.0 * 2.0 * factor)
    assert g.ki == pytest.approx(0.1 * (2.0 * factor) ** 3)  # K_i = (w / 10) K_p
    assert design_gains(_axis("heave", 40.0, 0.0), 2.0).w == pytest.approx(2.0)
    assert design_gains(_axis("heave", 40.0, 0.5), 2.0).w == pytest.approx(2.0 * MIN_BANDWIDTH_FACTOR)
    v = design_gains(_axis("surge", 27.0, 0.0), 3.0, velocity=True)
    assert (v.kp, v.kd, v.ki) == pytest.approx((3.0, 0.0, 0.9))
    assert UNCERTAINTY_Z == 1.96
    with pytest.raises(ValueError):
        design_gains(_axis("heave", 40.0), 0.0)


class HeavePlant:
    """M z'' = s F - D(z') - (B - W): depth z (down), F the body force the controller asks for (level vehicle)."""

    def __init__(self, mass, kl, kq, net_buoyancy, scale=1.0, lag_s=0.0, z0=1.0):
        self.m, self.kl, self.kq, self.b, self.s, self.lag = mass, kl, kq, net_buoyancy, scale, lag_s
        self.z, self.w, self.f = z0, 0.0, 0.0

    def run(self, force, duration):
        h = 0.001
        for _ in range(int(round(duration / h))):
            if self.lag > 0:
                self.f += (force - self.f) * h / self.lag
            else:
                self.f = force
            acc = (self.s * self.f - self.kl * self.w - self.kq * abs(self.w) * self.w - self.b) / self.m
            self.w += acc * h
            self.z += self.w * h


def _model(heave: AxisModel) -> ControlModel:
    cfg = load_config(default_config_path())
    base = model_from_config(cfg)
    return ControlModel({**base.axes, "heave": heave}, "test")


def _run_step(plant, ctrl, step=0.3, duration=12.0):
    """Depth step with the controller on the plant; returns (t, z, reference x_d) per tick after the step."""
    ctrl.depth_m = plant.z
    for _ in range(int(2.0 / TICK)):  # settle
        f = ctrl.wrench(ControlInput(0.0, depth_m=plant.z, depth_rate_m_s=plant.w, rpy_rad=np.zeros(3),
                                     rates_frd_rad_s=np.zeros(3), velocity_frd_m_s=np.full(3, np.nan)), TICK)[2]
        plant.run(f, TICK)
    z0 = ctrl.depth_m
    ctrl.depth_m = z0 + step
    out = []
    for k in range(int(duration / TICK)):
        f = ctrl.wrench(ControlInput(k * TICK, depth_m=plant.z, depth_rate_m_s=plant.w, rpy_rad=np.zeros(3),
                                     rates_frd_rad_s=np.zeros(3), velocity_frd_m_s=np.full(3, np.nan)), TICK)[2]
        plant.run(f, TICK)
        out.append(((k + 1) * TICK, plant.z - z0))
    return np.array(out)


AUTH = [36.0, 50.0, 62.0, 10.0, 12.0, 4.8]
NO_ACCEL_LIMIT = {d: math.inf for d in ("surge", "sway", "heave", "roll", "pitch", "yaw")}


def test_a_right_model_gives_the_specified_response():
    """Plant = model (thrust scale 1, no lag): the depth follows the critically damped response at the target
    bandwidth, written out here, within 5 mm (the sampled controller: one 20 ms tick at the peak rate of 0.22 m/s is
    4.4 mm)."""
    heave = _axis("heave", 48.0, 0.0, 9.0, 120.0, 0.9)
    plant = HeavePlant(48.0, 9.0, 120.0, 0.9)  # positively buoyant: the net buoyancy pushes up (-z)
    ctrl = Controller(_model(heave), AUTH, ControlSettings(hold_fraction=1.0), reference_accel=NO_ACCEL_LIMIT)
    res = _run_step(plant, ctrl)
    w = 2.0
    spec = 0.3 * (1.0 - (1.0 + w * res[:, 0]) * np.exp(-w * res[:, 0]))
    assert np.max(np.abs(res[:, 1] - spec)) < 0.005
    assert np.sqrt(np.mean((res[:, 1] - spec) ** 2)) < 0.002
    assert res[-1, 1] == pytest.approx(0.3, abs=1e-3)


def test_the_identified_model_tracks_better_than_a_wrong_one():
    """A heavier, more damped vehicle with 15 % weaker thrust: the model in commanded-thrust units (M/s, D/s, b/s:
    what a self-propelled identification measures) tracks the specified response at least 3 x better than the
    vehicle file's model, with less overshoot."""
    s, m_true, kl, kq, b = 0.85, 48.0, 9.0, 120.0, 0.785
    right = _axis("heave", m_true / s, 0.05, kl / s, kq / s, b / s)
    wrong = _axis("heave", 37.7, 0.079, 5.26, 93.52, 0.785)
    errs, over = {}, {}
    for name, ax in (("right", right), ("wrong", wrong)):
        plant = HeavePlant(m_true, kl, kq, b, scale=s, lag_s=0.1)
        ctrl = Controller(_model(ax), AUTH, ControlSettings(), reference_accel={"heave": 0.4})
        res = _run_step(plant, ctrl)
        ref = ReferenceModel(2.0, 1.0, 0.3, max_accel=0.4)  # the same specified response for both
        ref.reset(0.0)
        spec = np.array([ref.step(0.3, TICK)[0] for _ in range(len(res))])
        errs[name] = float(np.sqrt(np.mean((res[:, 1] - spec) ** 2)))
        over[name] = float(np.max(res[:, 1]) - 0.3)
    assert errs["right"] < errs["wrong"] / 3.0
    assert over["right"] < over["wrong"]


def test_integrator_does_not_wind_up_when_saturated_or_the_allocation_falls_short():
    """A vehicle stuck at 0 m while the depth setpoint is 1 m: once the output is clipped at the limit the integral
    stops growing; and an integral that would grow stops while the allocation reports the axis short."""
    heave = _axis("heave", 40.0, 0.0, 5.0, 90.0, 0.0)
    ctrl = Controller(_model(heave), AUTH, ControlSettings(hold_fraction=0.1))  # 6.2 N
    ctrl.depth_m = 1.0
    inp = ControlInput(0.0, depth_m=0.0, depth_rate_m_s=0.0, rpy_rad=np.zeros(3), rates_frd_rad_s=np.zeros(3))
    ax = ctrl.axes["heave"]
    forces = [ctrl.wrench(inp, TICK)[2] for _ in range(200)]
    assert max(forces) == pytest.approx(6.2)
    k = forces.index(max(forces))
    held = ax.integral
    for _ in range(200):
        assert ctrl.wrench(inp, TICK)[2] == pytest.approx(6.2)
    assert ax.integral == pytest.approx(held)  # no integration towards the error while clipped
    assert k < 150
    # not clipped by the law, but the allocation reports the heave short downwards (+z): no integration
    ctrl2 = Controller(_model(heave), AUTH, ControlSettings())
    ctrl2.depth_m = 0.01
    ctrl2.note_allocation([0.0, 0.0, 10.0, 0.0, 0.0, 0.0], [0.0, 0.0, 4.0, 0.0, 0.0, 0.0])
    for _ in range(50):
        ctrl2.wrench(inp, TICK)
    assert ctrl2.axes["heave"].integral == pytest.approx(0.0)
    ctrl2.note_allocation(np.zeros(6), np.zeros(6))
    ctrl2.wrench(inp, TICK)
    assert ctrl2.axes["heave"].integral > 0.0


def test_free_dof_gets_nothing_and_restarts_from_the_measured_state():
    heave = _axis("heave", 40.0, 0.0, 5.0, 90.0, 0.8)
    ctrl = Controller(_model(heave), AUTH, ControlSettings())
    ctrl.depth_m, ctrl.heading_rad = 1.0, 0.0
    inp = ControlInput(0.0, depth_m=1.2, depth_rate_m_s=0.3, rpy_rad=np.zeros(3), rates_frd_rad_s=np.zeros(3))
    assert ctrl.wrench(inp, TICK, free=("heave",))[2] == 0.0
    ctrl.wrench(inp, TICK)
    ref = ctrl.axes["heave"].ref
    assert ref.x == pytest.approx(1.2 + 0.3 * TICK, abs=2e-3) and ref.v < 0.3  # from the measured state, braking
    assert math.isnan(Controller(_model(heave), AUTH).wrench(inp, TICK)[2]) is False


def test_floor_estimator_finds_the_slope_from_one_dvl_report():
    """Four beams (22.5 deg) and the Ping1D from a level vehicle over the plane z = 1.8 - 0.08 x + 0.03 y: the
    filter's gradient and the floor depth under the vehicle, from points computed here."""
    g = np.array([-0.08, 0.03])
    x0, z_dvl = np.array([3.0, 2.0]), 1.0

    def plane(p):
        return 1.8 + g @ (p - np.array([5.0, 3.0]))

    est = FloorEstimator()
    s, c = math.sin(math.radians(22.5)), math.cos(math.radians(22.5))
    for k in range(3):  # three reports, still
        for d in ((0, -s, c), (-s, 0, c), (0, s, c), (s, 0, c)):
            d = np.array(d, dtype=float)
            # range t along d from (x0, z_dvl): z_dvl + t d_z = plane(x0 + t d_xy)
            t = (plane(x0) - z_dvl) / (d[2] - g @ d[:2])
            est.update_point(0.1 * k, t * d[:2], z_dvl + t * d[2], 0.01, (0.0, 0.0))
    z, gn, ge = est.floor_at(0.2, (0.0, 0.0))
    assert z == pytest.approx(plane(x0), abs=0.01)
    assert (gn, ge) == pytest.approx(tuple(g), abs=0.01)
    # moving north at 0.3 m/s for 0.5 s without ranges: the floor under the vehicle rises by 0.3 * 0.5 * 0.08
    z2, _, _ = est.floor_at(0.7, (0.3, 0.0))
    assert z2 - z == pytest.approx(-0.08 * 0.15, abs=0.003)
    # without any range for FLOOR_TIMEOUT_S the floor is held
    assert est.floor_at(5.0, (0.3, 0.0))[0] == pytest.approx(z, abs=1e-9)


def _ramp_floor(x):
    """Floor depth (m) under north position x: flat 1.8 m, up at 1:3 from x = 2 to 2.9 m, flat 1.5 m beyond."""
    return 1.8 - min(max(x - 2.0, 0.0), 0.9) / 3.0


def _ray_to_floor(x0, z0, d):
    """Range along the unit (north, east, down) direction d from (x0, z0) to _ramp_floor, by bisection."""
    lo, hi = 0.0, 5.0
    for _ in range(60):
        t = 0.5 * (lo + hi)
        lo, hi = (t, hi) if z0 + t * d[2] < _ramp_floor(x0 + t * d[0]) else (lo, t)
    return 0.5 * (lo + hi)


def _altitude_over_the_ramp(gradient_feedforward: bool, monkeypatch, ping_x_m: float = 0.0) -> np.ndarray:
    """Altitude hold at 0.5 m over _ramp_floor, surging north at 0.4 m/s (kinematic), heave plant = model; four
    22.5-degree beams from the body origin and the Ping1D ``ping_x_m`` ahead of it, at 10 Hz; returns the altitude
    error (m, under the Ping1D) per tick."""
    from hindrax_drivers.dvl75.protocol import beam_directions_frd

    heave = _axis("heave", 48.0, 0.0, 9.0, 120.0, 0.785)
    plant = HeavePlant(48.0, 9.0, 120.0, 0.785, z0=1.3)
    beams = np.array(beam_directions_frd())
    ctrl = Controller(_model(heave), AUTH, ControlSettings(), dvl_beams_frd=beams,
                      ping_position_frd_m=(ping_x_m, 0.0, 0.0))
    if not gradient_feedforward:
        monkeypatch.setattr(ctrl, "_floor_gradient_rate", lambda t, g: np.zeros(2))
    ctrl.altitude_m, ctrl.velocity_frd_m_s = 0.5, np.array([0.4, 0.0])
    err, alt, ranges, stamp = [], math.nan, np.full(4, np.nan), -1.0
    for k in range(int(9.0 / TICK)):
        t, x = k * TICK, 0.4 * k * TICK
        if k % 5 == 0:  # 10 Hz ranges
            alt, stamp = _ramp_floor(x + ping_x_m) - plant.z, t
            ranges = np.array([_ray_to_floor(x, plant.z, b) for b in beams])
        f = ctrl.wrench(ControlInput(t, depth_m=plant.z, depth_rate_m_s=plant.w, rpy_rad=np.zeros(3),
                                     rates_frd_rad_s=np.zeros(3), velocity_frd_m_s=np.array([0.4, 0.0, 0.0]),
                                     altitude_m=alt, altitude_stamp_s=stamp, dvl_beam_range_m=ranges,
                                     dvl_beam_stamp_s=stamp), TICK)[2]
        plant.run(f, TICK)
        err.append(_ramp_floor(x + ping_x_m + 0.4 * TICK) - plant.z - 0.5)
    return np.array(err)


def test_a_slope_change_is_fed_forward_as_the_floors_acceleration(monkeypatch):
    """Over a floor whose slope changes (flat, 1:3, flat) at 0.4 m/s the floor's vertical acceleration g' . v is fed
    forward (x_d'' = g . a_ref + g' . v_ref - a_d''): the altitude error is less than 0.6 of the error with that term
    removed; and the floor filter's slope walks with the distance travelled (FLOOR_GRADIENT_WALK_PER_SQRT_M), so it
    learns the new slope within the ramp: RMS error below 1 cm (2.8 cm with the time-only walk of 0.02/sqrt(s)), and
    the vehicle ends at the setpoint. Ideal plant and ranges: no noise, no lag."""
    with_ff = _altitude_over_the_ramp(True, monkeypatch)
    without = _altitude_over_the_ramp(False, monkeypatch)
    rms = [float(np.sqrt(np.mean(e[100:] ** 2))) for e in (with_ff, without)]
    assert rms[0] < 0.6 * rms[1], rms
    assert rms[0] < 0.01, rms
    assert abs(with_ff[-1]) < 0.005


def test_beams_far_from_the_altimeters_footprint_count_less_where_the_slope_changes(monkeypatch):
    """The vehicle's geometry (docs/devices.md; ros_ws/config/hindrax.yaml): the Ping1D 0.10 m ahead of the DVL, so at
    0.5 m the bow beam lands 0.11 m ahead of the altimeter's footprint and the stern beam 0.31 m behind it. A plane
    through them is wrong by the slope change times that distance (law.FLOOR_SLOPE_CHANGE_STD): with that error in
    each beam's variance the stern beam, still on the flat, holds the new slope back less, and the altitude error over
    flat - 1:3 - flat is at most 0.9 of the error without it. Ideal plant and ranges: no noise, no lag."""
    from hindrax_onboard.control import law

    with_term = _altitude_over_the_ramp(True, monkeypatch, ping_x_m=0.10)
    monkeypatch.setattr(law, "FLOOR_SLOPE_CHANGE_STD", 0.0)
    without = _altitude_over_the_ramp(True, monkeypatch, ping_x_m=0.10)
    rms = [float(np.sqrt(np.mean(e[100:] ** 2))) for e in (with_term, without)]
    assert rms[0] < 0.9 * rms[1], rms
