"""The output-error pieces (identification/output_error.py) against hand-computed values and analytic solutions:
the one-DOF model, the lagged thrust inside a tick, the Runge-Kutta step, the segment bookkeeping, and the whole
fit on records integrated by an independent solver (scipy's solve_ivp)."""
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from hindrax_ident.estimation.least_squares import EstimationError
from hindrax_ident.identification.output_error import (DofModel, LaggedThrust, OutputErrorFit, Segments, model_terms,
                                                       rk4_step)


# ---------------------------------------------------------------------------------------------------- the model
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


def test_lagged_thrust_inside_a_tick():
    lag = LaggedThrust(time_constant_s=0.1, tick_s=0.02)
    f = lag.start_middle_end(2.0, 10.0)  # from 2 N towards a 10 N command
    assert f == pytest.approx((2.0, 10.0 - 8.0 * math.exp(-0.1), 10.0 - 8.0 * math.exp(-0.2)), abs=1e-12)
    # no lag: the command acts over the whole tick
    assert LaggedThrust(0.0, 0.02).start_middle_end(2.0, 10.0) == pytest.approx((10.0, 10.0, 10.0))


# ---------------------------------------------------------------------------------------------------- the integrator
def _integrate(model, v0, force, h, n):
    v, x = np.array([v0]), np.array([0.0])
    for _ in range(n):
        v, x = rk4_step(model.acceleration, v, x, h, (force, force, force))
    return float(v[0]), float(x[0])


def test_rk4_step_against_linear_damping_and_its_fourth_order():
    m, k, f, v0 = 20.0, 8.0, 10.0, -0.2  # M v' = F - k v: v = F/k + (v0 - F/k) exp(-k t / M)
    model = DofModel("surge", np.array([m, 0.0, k, 0.0]))
    t = 2.0
    vt = f / k + (v0 - f / k) * math.exp(-k * t / m)
    xt = f / k * t + (v0 - f / k) * m / k * (1.0 - math.exp(-k * t / m))
    v, x = _integrate(model, v0, f, 0.02, 100)
    assert v == pytest.approx(vt, abs=1e-10) and x == pytest.approx(xt, abs=1e-10)
    # fourth order: errors fall about 16 times when the step halves (large steps, so they are above round-off)
    e1 = abs(_integrate(model, v0, f, 1.0, 2)[0] - vt)
    e2 = abs(_integrate(model, v0, f, 0.5, 4)[0] - vt)
    assert 12.0 < e1 / e2 < 20.0


def test_rk4_step_against_quadratic_damping():
    m, kq, f = 27.3, 66.5, 20.0  # from rest: v = vt tanh(kq vt t / M), x = M / kq ln cosh(kq vt t / M)
    model = DofModel("surge", np.array([m, kq, 0.0, 0.0]))
    vt = math.sqrt(f / kq)
    t = 3.0
    v, x = _integrate(model, 0.0, f, 0.02, 150)
    assert v == pytest.approx(vt * math.tanh(kq * vt * t / m), abs=1e-9)
    assert x == pytest.approx(m / kq * math.log(math.cosh(kq * vt * t / m)), abs=1e-8)


def test_rk4_step_with_the_lagged_thrust_integrates_the_impulse():
    lag = LaggedThrust(0.1, 0.02)
    free = DofModel("surge", np.array([1.0, 0.0, 0.0, 0.0]))  # M = 1, no damping: v(h) = v0 + integral of f
    v, x = rk4_step(free.acceleration, np.array([0.3]), np.array([0.0]), 0.02, lag.start_middle_end(2.0, 10.0))
    impulse = 10.0 * 0.02 + (2.0 - 10.0) * 0.1 * (1.0 - math.exp(-0.2))
    assert float(v[0]) == pytest.approx(0.3 + impulse, abs=1e-7)


# ---------------------------------------------------------------------------------------------------- segments
def test_segments_split_keeps_whole_segments_with_an_initial_state_and_three_samples():
    z = np.full(25, np.nan)
    z[[0, 3, 5, 7, 12, 14, 16, 22]] = 1.0  # tick 0 is an initial state, 20-24 is no whole segment
    v = np.arange(25.0)
    x = -np.arange(25.0)
    sg = Segments.split(10, z, v, x)
    assert sg.index.tolist() == [list(range(10)), list(range(10, 20))]
    assert np.flatnonzero(sg.mask[0]).tolist() == [3, 5, 7] and np.flatnonzero(sg.mask[1]).tolist() == [2, 4, 6]
    assert sg.v0.tolist() == [0.0, 10.0] and sg.x0.tolist() == [0.0, -10.0]
    assert sg.sample_segment.tolist() == [0, 0, 0, 1, 1, 1]
    assert sg.take(v)[1, 3] == 13.0 and sg.take(None) is None
    # a segment without an initial velocity, or with only two samples, is dropped: one left is too few
    v_bad = v.copy()
    v_bad[10] = np.nan
    with pytest.raises(EstimationError, match="too few usable segments"):
        Segments.split(10, z, v_bad, x)
    z_two = z.copy()
    z_two[16] = np.nan
    with pytest.raises(EstimationError, match="too few usable segments"):
        Segments.split(10, z_two, v, x)
    with pytest.raises(EstimationError, match="too short"):
        Segments.split(10, z[:15], v[:15], x[:15])


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


def test_output_error_fit_recovers_surge_from_measured_velocity():
    theta = [27.3, 66.5, 1.25, 0.4]
    t, f, fc, v, x = _record("surge", theta, 0.1, [20.0, -20.0, 35.0, -35.0, 10.0, -10.0] * 2)
    z = np.full(t.size, np.nan)
    z[::5] = v[::5]  # a 10 Hz velocity sensor on the 50 Hz tick grid
    fit = OutputErrorFit("surge", t, f, fc, 0.1, None, z, "velocity", x, v, 3.0)
    res = fit.fit(np.array(theta) * np.array([1.3, 0.7, 2.0, -1.0]))
    assert res.theta == pytest.approx(theta, rel=1e-4, abs=1e-4)
    assert np.all(np.isfinite(res.covariance)) and np.all(np.diag(res.covariance) >= 0.0)
    used = np.isfinite(res.velocity_fit)
    assert used.sum() > 0.9 * t.size and np.max(np.abs(res.velocity_fit[used] - v[used])) < 1e-5


def test_output_error_fit_recovers_heave_from_measured_depth_with_free_offsets_and_initial_velocities():
    theta = [30.0, 60.0, 40.0, 5.0, 10.0, 0.8]
    t, f, fc, v, x = _record("heave", theta, 0.1, [25.0, -25.0, 40.0, -40.0, 15.0, -15.0] * 2, hold_s=3.0)
    z = np.full(t.size, np.nan)
    z[::5] = x[::5] + 0.3  # depth with an unknown offset
    v_start = v + 0.02  # a biased initial velocity: free in the fit
    fit = OutputErrorFit("heave", t, f, fc, 0.1, None, z, "position", x - 1.0, v_start, 6.0)
    res = fit.fit(np.array(theta) * 1.2)
    assert res.theta == pytest.approx(theta, rel=1e-3, abs=1e-3)
    assert res.residual_dof == int(fit.segments.mask.sum()) - len(theta) - 2 * fit.segments.mask.shape[0]
