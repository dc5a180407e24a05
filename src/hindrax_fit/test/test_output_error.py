"""The output-error pieces (identification/fit/dof_model.py, identification/fit/fit_core.py) against
hand-computed values and analytic solutions: the one-DOF model, the lagged thrust inside a tick, the
core's Runge-Kutta step, the segment bookkeeping of the fit core, and its whole fit on records
integrated by an independent solver (scipy's solve_ivp), with RuntimeWarnings turned into errors."""
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from hindrax_onboard.estimation.least_squares import EstimationError
from hindrax_fit.fit import fit_core
from hindrax_onboard.identification.model.dof_model import model_terms
from hindrax_onboard.vehicle.thrust_lag import ThrustLag

pytestmark = pytest.mark.filterwarnings("error::RuntimeWarning")


# ---------------------------------------------------------------------------------------------------- the model
class DofModel:
    """The one-DOF model of dof_model: nu_dot = (tau - model_terms . theta[1:]) / M."""

    def __init__(self, dof, theta):
        self.dof, self.theta = dof, np.asarray(theta, dtype=float)

    def acceleration(self, velocity, force, restoring=None):
        return (force - model_terms(self.dof, velocity, restoring) @ self.theta[1:]) / self.theta[0]


def test_model_acceleration_by_hand():
    surge = DofModel("surge", np.array([20.0, 50.0, 2.0, 0.5]))  # M, k_q, k_l, b
    # (10 - (50 * 0.3^2 + 2 * 0.3 + 0.5)) / 20
    assert surge.acceleration(0.3, 10.0) == pytest.approx(0.22, abs=1e-12)
    assert surge.acceleration(-0.3, 10.0) == pytest.approx((10.0 - (-4.5 - 0.6 + 0.5)) / 20.0, abs=1e-12)
    heave = DofModel("heave", np.array([30.0, 60.0, 40.0, 5.0, 10.0, 0.8]))  # M, kq+, kq-, kl+, kl-, b
    assert heave.acceleration(0.2, 5.0) == pytest.approx((5.0 - (60 * 0.04 + 5 * 0.2 + 0.8)) / 30.0, abs=1e-12)
    assert heave.acceleration(-0.2, 5.0) == pytest.approx((5.0 - (-40 * 0.04 - 10 * 0.2 + 0.8)) / 30.0, abs=1e-12)
    roll = DofModel("roll", np.array([0.5, 0.4, 0.1, 0.01, 4.5]))  # M, k_q, k_l, b, k_r
    s = math.cos(0.1) * math.sin(0.2)
    assert roll.acceleration(1.0, 2.0, s) == pytest.approx((2.0 - (0.4 + 0.1 + 0.01 + 4.5 * s)) / 0.5, abs=1e-12)
    assert roll.acceleration(1.0, 2.0) == pytest.approx((2.0 - 0.51) / 0.5, abs=1e-12)  # no restoring given: 0
    assert model_terms("yaw", np.zeros((4, 3))).shape == (4, 3, 3)
    assert model_terms("pitch", np.zeros(7)).shape == (7, 4)


def _within_tick(lag, force_start, command, tick_s):
    """The thrust at the start, middle and end of one tick (ThrustLag.over_ticks of one command)."""
    return tuple(float(x[0]) for x in lag.over_ticks(np.array([command]), tick_s, force_start))


def test_lagged_thrust_inside_a_tick():
    lag = ThrustLag(time_constant_s=0.1)
    f = _within_tick(lag, 2.0, 10.0, 0.02)  # from 2 N towards a 10 N command
    assert f == pytest.approx((2.0, 10.0 - 8.0 * math.exp(-0.1), 10.0 - 8.0 * math.exp(-0.2)), abs=1e-12)
    # no lag: the command acts over the whole tick
    assert _within_tick(ThrustLag(0.0), 2.0, 10.0, 0.02) == pytest.approx((10.0, 10.0, 10.0))


# ---------------------------------------------------------------------------------------------------- the integrator
def _simulate(theta, v0, forces, h, n):
    """(v, x) after n ticks of h of the fit core's simulation (:func:`fit_core.simulate`: RK4 for v,
    Runge-Kutta-Nystrom for x) of surge with ``theta`` [M, k_q, k_l, b] from v0, x = 0, under the
    force ``forces`` (start, middle, end of every tick)."""
    L = n + 1
    u = np.broadcast_to(np.asarray(forces, dtype=float)[:, None, None], (3, 1, L)).copy()
    empty_i, empty_f, zeros = np.zeros(0, int), np.zeros(0), np.zeros((1, L))
    sd = fit_core.SegmentData(h, L, u, np.zeros((3, 1, L, 0)), np.array([v0]), np.zeros(1),
                              empty_i, empty_i, empty_f, empty_f, np.zeros(1, int),
                              np.zeros((1, 2)), np.ones(1, bool), zeros, zeros, zeros)
    layout = fit_core.parameter_layout("surge", fit_core.Terms("both"))
    V, X = fit_core.simulate(sd, layout, np.asarray(theta, dtype=float), position=True)
    return float(V[0, 0, -1]), float(X[0, 0, -1])


def test_rk4_step_against_linear_damping_and_its_fourth_order():
    m, k, f, v0 = 20.0, 8.0, 10.0, -0.2  # M v' = F - k v: v = F/k + (v0 - F/k) exp(-k t / M)
    t = 2.0
    vt = f / k + (v0 - f / k) * math.exp(-k * t / m)
    xt = f / k * t + (v0 - f / k) * m / k * (1.0 - math.exp(-k * t / m))
    v, x = _simulate([m, 0.0, k, 0.0], v0, (f, f, f), 0.02, 100)
    assert v == pytest.approx(vt, abs=1e-10) and x == pytest.approx(xt, abs=1e-10)
    # fourth order: errors fall about 16 times when the step halves (large steps, so they are above round-off)
    e1 = abs(_simulate([m, 0.0, k, 0.0], v0, (f, f, f), 1.0, 2)[0] - vt)
    e2 = abs(_simulate([m, 0.0, k, 0.0], v0, (f, f, f), 0.5, 4)[0] - vt)
    assert 12.0 < e1 / e2 < 20.0


def test_rk4_step_against_quadratic_damping():
    m, kq, f = 27.3, 66.5, 20.0  # from rest: v = vt tanh(kq vt t / M), x = M / kq ln cosh(kq vt t / M)
    vt = math.sqrt(f / kq)
    t = 3.0
    v, x = _simulate([m, kq, 0.0, 0.0], 0.0, (f, f, f), 0.02, 150)
    assert v == pytest.approx(vt * math.tanh(kq * vt * t / m), abs=1e-9)
    assert x == pytest.approx(m / kq * math.log(math.cosh(kq * vt * t / m)), abs=1e-8)


def test_rk4_step_with_the_lagged_thrust_integrates_the_impulse():
    lag = ThrustLag(0.1)
    # M = 1, no damping: v(h) = v0 + integral of f
    v, _x = _simulate([1.0, 0.0, 0.0, 0.0], 0.3, _within_tick(lag, 2.0, 10.0, 0.02), 0.02, 1)
    impulse = 10.0 * 0.02 + (2.0 - 10.0) * 0.1 * (1.0 - math.exp(-0.2))
    assert v == pytest.approx(0.3 + impulse, abs=1e-7)


# ---------------------------------------------------------------------------------------------------- segments
def test_segments_keep_whole_parts_with_an_initial_state_and_three_measurements():
    n = 25
    pos = np.array([0.0, 3.0, 5.0, 7.5, 12.0, 14.0, 16.0, 22.0])  # tick 0 is an initial state only
    z = np.arange(pos.size, dtype=float)
    v = np.arange(float(n))
    ch = fit_core.Chunk(np.ones(n), v, -v, np.zeros(n), pos, z)
    rec = fit_core.DofRecord("surge", 1.0, "velocity", [ch], "thrust_model")
    sd = fit_core.build_segments(rec, fit_core.Terms(), fit_core.Timing(), 10.0, excited_only=False)
    # 0-9 and 10-19; 20-24 is half a segment (kept: at least half) but has one measurement (dropped)
    assert sd.m == 2 and sd.v0.tolist() == [0.0, 10.0] and sd.x0.tolist() == [0.0, -10.0]
    assert sd.s_seg.tolist() == [0, 0, 0, 1, 1, 1] and sd.s_z.tolist() == [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]
    assert (sd.s_j + sd.s_a).tolist() == [3.0, 5.0, 7.5, 2.0, 4.0, 6.0]
    # a segment without an initial velocity is dropped
    v_bad = v.copy()
    v_bad[10] = np.nan
    ch2 = fit_core.Chunk(np.ones(n), v_bad, -v, np.zeros(n), pos, z)
    sd2 = fit_core.build_segments(fit_core.DofRecord("surge", 1.0, "velocity", [ch2]), fit_core.Terms(),
                                  fit_core.Timing(), 10.0, excited_only=False)
    assert sd2.m == 1
    with pytest.raises(EstimationError, match="no segment"):
        fit_core.build_segments(fit_core.DofRecord("surge", 1.0, "velocity", [fit_core.Chunk(
            np.ones(15), v[:15], -v[:15], np.zeros(15), pos[:2], z[:2])]), fit_core.Terms(), fit_core.Timing(), 10.0)


# ---------------------------------------------------------------------------------------------------- the fit
def _record(dof, theta, tau, levels, hold_s=2.0, h=0.02, v0=0.0):
    """Ticks, lagged and commanded force, true velocity and position from solve_ivp with the exact lagged force."""
    n = int(round(len(levels) * hold_s / h)) + 1
    t = np.arange(n) * h
    fc = np.array([levels[min(int(ti / hold_s + 1e-9), len(levels) - 1)] for ti in t])
    f = np.zeros(n)
    for i in range(1, n):  # lagged force at each tick (exact first-order lag of the held command)
        f[i] = fc[i - 1] + (f[i - 1] - fc[i - 1]) * math.exp(-h / tau)
    model = DofModel(dof, np.asarray(theta, dtype=float))

    def rhs(s, y):
        i = min(int(s / h + 1e-9), n - 1)
        force = fc[i] + (f[i] - fc[i]) * math.exp(-(s - t[i]) / tau)
        return [y[1], float(model.acceleration(y[1], force))]

    sol = solve_ivp(rhs, (0.0, t[-1]), [0.0, v0], t_eval=t, rtol=1e-10, atol=1e-12, max_step=h / 4)
    return t, f, fc, sol.y[1], sol.y[0]


def _core_fit(dof, t, fc, v, x, z_pos, z, measured, segment_s, theta0, v_start=None):
    h = float(t[1] - t[0])
    ch = fit_core.Chunk(fc, v if v_start is None else v_start, x, np.zeros_like(v), z_pos, z, force_start=0.0)
    rec = fit_core.DofRecord(dof, h, measured, [ch], "thrust_model", 0.1)
    terms = fit_core.Terms("both", dof == "heave")
    sd = fit_core.build_segments(rec, terms, fit_core.Timing(0.0, 0.1), segment_s, excited_only=False)
    layout = fit_core.parameter_layout(dof, terms)
    return sd, layout, fit_core.fit_terms(sd, dof, layout, np.asarray(theta0, dtype=float), robust=False)


def test_output_error_fit_recovers_surge_from_measured_velocity():
    theta = [27.3, 66.5, 1.25, 0.4]
    t, f, fc, v, x = _record("surge", theta, 0.1, [20.0, -20.0, 35.0, -35.0, 10.0, -10.0] * 2)
    idx = np.arange(0, t.size, 5)  # a 10 Hz velocity sensor on the 50 Hz tick grid
    sd, layout, res = _core_fit("surge", t, fc, v, np.zeros_like(v), idx.astype(float), v[idx], "velocity", 3.0,
                                np.array(theta) * np.array([1.3, 0.7, 2.0, -1.0]))
    assert res.theta == pytest.approx(theta, rel=1e-4, abs=1e-4)
    cov = fit_core.cluster_covariance(res, sd)
    assert np.all(np.isfinite(cov.cov)) and np.all(np.diag(cov.cov) >= 0.0)
    V = fit_core.predict_validation(sd, layout, res.theta)
    starts = np.rint(sd.span[:, 0] / 0.02).astype(int)
    err = max(float(np.max(np.abs(V[i] - v[s0:s0 + sd.L]))) for i, s0 in enumerate(starts) if s0 + sd.L <= v.size)
    assert err < 1e-5


def test_output_error_fit_recovers_heave_from_measured_depth_with_free_offsets_and_initial_velocities():
    theta = [30.0, 60.0, 40.0, 5.0, 10.0, 0.8]
    t, f, fc, v, x = _record("heave", theta, 0.1, [25.0, -25.0, 40.0, -40.0, 15.0, -15.0] * 2, hold_s=3.0)
    idx = np.arange(0, t.size, 5)
    # depth with an unknown offset, a biased initial velocity: both free in the fit
    sd, _layout, res = _core_fit("heave", t, fc, v, x - 1.0, idx.astype(float), x[idx] + 0.3, "position", 6.0,
                                 np.array(theta) * 1.2, v_start=v + 0.02)
    assert res.theta == pytest.approx(theta, rel=1e-3, abs=1e-3)
    assert res.v0 is not None and res.v0.size == sd.m
