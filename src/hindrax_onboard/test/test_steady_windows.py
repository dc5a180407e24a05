"""Tests of hindrax_onboard.estimation.steady_windows on a simulated thrust ladder ([Hindrax-Drag] §4)."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from hindrax_onboard.estimation.least_squares import EstimationError, fit_drag
from hindrax_onboard.estimation.steady_windows import (
    SteadyWindow,
    constant_force_segments,
    detect_steady_windows,
)

# Surge, [Hindrax-Drag] Table 3: k_q = 66.48 N/(m/s)^2, k_l = 1.25 N/(m/s); inertia 15.22 + 12.08 kg
# (mass + [Hindrax-AM] Table 6 added mass).
KQ, KL, INERTIA = 66.48, 1.25, 27.3
LEVELS_N = [0.0, 3.0, 6.0, 10.0, 15.0, 20.0]
HOLD_S = 15.0
FS_HZ = 50.0


def steady_velocity(force_n):
    """Root of k_q v^2 + k_l v = F (v >= 0)."""
    return (-KL + np.sqrt(KL**2 + 4 * KQ * force_n)) / (2 * KQ)


def ladder(noise=0.004, seed=0, levels=LEVELS_N, hold_s=HOLD_S):
    t = np.arange(0.0, len(levels) * hold_s, 1.0 / FS_HZ)
    force = np.array(levels)[np.minimum((t // hold_s).astype(int), len(levels) - 1)]

    def rhs(tt, y):
        f = levels[min(int(tt // hold_s), len(levels) - 1)]
        v = y[0]
        return [(f - KQ * abs(v) * v - KL * v) / INERTIA]

    sol = solve_ivp(rhs, (0.0, t[-1]), [0.0], t_eval=t, max_step=0.02, rtol=1e-8, atol=1e-10)
    rng = np.random.default_rng(seed)
    return t, sol.y[0] + rng.normal(0, noise, t.size), force, sol.y[0]


def test_one_window_per_level_after_the_transient():
    t, v, f, v_true = ladder(noise=0.004)
    windows = detect_steady_windows(t, v, f, min_duration_s=2.0, max_slope=0.01, max_std=0.01)
    assert len(windows) == len(LEVELS_N)
    for k, (w, level) in enumerate(zip(windows, LEVELS_N)):
        assert isinstance(w, SteadyWindow)
        t0 = k * HOLD_S
        assert t0 <= w.t_start_s and w.t_stop_s < t0 + HOLD_S
        assert w.t_stop_s - w.t_start_s >= 2.0
        assert w.force_mean == pytest.approx(level) and w.force_std == 0.0
        assert w.velocity_mean == pytest.approx(steady_velocity(level), abs=0.005)
        assert w.velocity_std <= 0.01 and abs(w.velocity_slope) <= 0.01
        # edge guarantee: the true velocity at the window edges is within 2 max_std of the
        # window mean, up to the 4-sigma noise of the trimmed sample (0.02 + 0.016 m/s)
        for i in (w.start, w.stop - 1):
            assert abs(v_true[i] - w.velocity_mean) <= 0.02 + 4 * 0.004
        if level > 0:
            # first-order response, time constant m / (2 k_q v_ss + k_l) >= 0.37 s: the step
            # transient has not decayed below 0.036 m/s in the first 0.3 s
            assert w.t_start_s > t0 + 0.3
        assert w.n == w.stop - w.start


def test_steady_state_ls_on_the_windows_recovers_table3_surge():
    t, v, f, _ = ladder()
    windows = detect_steady_windows(t, v, f, max_slope=0.01, max_std=0.01)
    vm, fm = np.array([w.velocity_mean for w in windows]), np.array([w.force_mean for w in windows])
    fit = fit_drag(vm, fm)
    assert fit.quadratic_damping == pytest.approx(KQ, rel=0.05)
    assert abs(fit.linear_damping - KL) < 2.0
    idx = np.concatenate([np.arange(w.start, w.stop) for w in windows])
    vs, fs = v[idx], f[idx]
    assert vs.size == sum(w.n for w in windows)
    fit_all = fit_drag(vs, fs)
    assert fit_all.quadratic_damping == pytest.approx(KQ, rel=0.05)


def test_no_window_when_velocity_keeps_changing():
    t = np.arange(0.0, 20.0, 0.02)
    v = 0.05 * t                                  # 0.05 m/s^2 ramp > max_slope
    assert detect_steady_windows(t, v, np.full(t.size, 5.0), max_slope=0.02) == []


def test_no_window_when_holds_are_too_short_or_noise_too_large():
    t, v, f, _ = ladder(levels=[5.0, 10.0, 15.0, 20.0], hold_s=1.5)
    assert detect_steady_windows(t, v, f, min_duration_s=2.0) == []
    t, v, f, _ = ladder(noise=0.05)
    assert detect_steady_windows(t, v, f, max_std=0.02) == []


def test_force_tolerance_segments():
    f = np.array([1.0, 1.01, 0.99, 2.0, 2.0, 3.0])
    assert constant_force_segments(f, 0.05) == [(0, 3), (3, 5), (5, 6)]
    assert constant_force_segments(f, 0.0) == [(0, 1), (1, 2), (2, 3), (3, 5), (5, 6)]


@pytest.mark.parametrize("call", [
    lambda: detect_steady_windows([0.0, 1.0, 1.0], [0.0, 0.0, 0.0], [1.0, 1.0, 1.0]),
    lambda: detect_steady_windows([0.0, 1.0, 2.0], [0.0, np.nan, 0.0], [1.0, 1.0, 1.0]),
    lambda: detect_steady_windows([0.0, 1.0, 2.0], [0.0, 0.0], [1.0, 1.0, 1.0]),
    lambda: detect_steady_windows([0.0, 1.0, 2.0], [0.0] * 3, [1.0] * 3, min_duration_s=0),
    lambda: detect_steady_windows([0.0, 1.0, 2.0], [0.0] * 3, [1.0] * 3, max_std=-1),
    lambda: constant_force_segments([1.0, 2.0], force_tolerance=-0.1),
])
def test_errors(call):
    with pytest.raises(EstimationError):
        call()
