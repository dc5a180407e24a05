"""Tests of hindrax_onboard.estimation.least_squares ([Hindrax-Drag] eqs. 2-8)."""

import numpy as np
import pytest
from scipy import stats

from hindrax_onboard.estimation.least_squares import (
    DragFit,
    EstimationError,
    fit_drag,
    fit_linear_model,
)

# [Hindrax-Drag] Table 3 surge: k_q = 66.48, k_l = 1.25, b = -0.02 (N, m/s)
SURGE = (66.48, 1.25, -0.02)


def surge_data(rng, n=80, noise_n=0.5):
    v = rng.uniform(-0.5, 0.5, n)
    f = SURGE[0] * np.abs(v) * v + SURGE[1] * v + SURGE[2] + rng.normal(0, noise_n, n)
    return v, f


def test_fit_linear_model_matches_normal_equations():
    """theta (eq. 6), sigma^2 (eq. 8) and covariance (eq. 7) against direct formulas."""
    rng = np.random.default_rng(0)
    X = np.column_stack([rng.normal(size=50), rng.uniform(size=50), np.ones(50)])
    y = X @ [2.0, -1.0, 0.5] + rng.normal(0, 0.1, 50)
    r = fit_linear_model(X, y, names=("a", "b", "c"))
    xtx_inv = np.linalg.inv(X.T @ X)
    theta = xtx_inv @ X.T @ y
    res = y - X @ theta
    s2 = res @ res / (50 - 3)
    np.testing.assert_allclose(r.theta, theta, rtol=1e-10)
    assert r.sigma2 == pytest.approx(s2, rel=1e-10)
    np.testing.assert_allclose(r.covariance, s2 * xtx_inv, rtol=1e-8)
    np.testing.assert_allclose(r.std, np.sqrt(np.diag(s2 * xtx_inv)), rtol=1e-8)
    np.testing.assert_allclose(r.residuals, res, atol=1e-12)
    assert (r.n, r.p, r.dof) == (50, 3, 47)
    assert r.theta[r.index("b")] == pytest.approx(theta[1])


def test_noise_free_fit_is_exact():
    v = np.linspace(-0.6, 0.6, 25)
    f = SURGE[0] * np.abs(v) * v + SURGE[1] * v + SURGE[2]
    fit = fit_drag(v, f)
    assert isinstance(fit, DragFit)
    assert fit.quadratic_damping == pytest.approx(SURGE[0], rel=1e-10)
    assert fit.linear_damping == pytest.approx(SURGE[1], rel=1e-8)
    assert fit.bias == pytest.approx(SURGE[2], abs=1e-10)
    assert fit.ls.sigma2 == pytest.approx(0.0, abs=1e-20)


def test_abs_v_times_v_keeps_the_sign():
    """[Hindrax-Drag] eq. 2: with |v|v a symmetric drag law is one model for both signs; an x^2
    regressor (eq. 3 as printed) cannot represent it."""
    v = np.linspace(-0.5, 0.5, 41)
    f = 70.0 * np.abs(v) * v + 3.0 * v
    fit = fit_drag(v, f)
    assert fit.quadratic_damping == pytest.approx(70.0, rel=1e-9)
    printed = fit_linear_model(np.column_stack([v**2, v, np.ones_like(v)]), f)
    assert printed.residual_std > 1.0   # x^2 misfits an odd function badly


def test_fit_drag_recovers_parameters_and_predicts():
    rng = np.random.default_rng(1)
    v, f = surge_data(rng, n=400)
    fit = fit_drag(v, f)
    for est, std, true in ((fit.quadratic_damping, fit.quadratic_damping_std, SURGE[0]),
                           (fit.linear_damping, fit.linear_damping_std, SURGE[1]),
                           (fit.bias, fit.bias_std, SURGE[2])):
        assert abs(est - true) < 4 * std
    assert fit.quadratic_damping_std < 2.0
    vq = np.array([-0.4, 0.0, 0.4])
    np.testing.assert_allclose(fit.predict(vq), fit.quadratic_damping * np.abs(vq) * vq
                               + fit.linear_damping * vq + fit.bias)


def test_std_matches_monte_carlo_and_ci_coverage():
    """eq. 7 std vs the spread over 1000 seeded repetitions (within 20 %), and 95 % Student-t
    interval coverage. The three coverage events of one trial are correlated, so the band is
    the binomial 3-sigma band of 1000 (not 3000) independent trials."""
    rng = np.random.default_rng(3)
    v = rng.uniform(-0.5, 0.5, 30)           # fixed design, new noise each trial
    trials = 1000
    est, stds, covered = [], [], 0
    for _ in range(trials):
        f = SURGE[0] * np.abs(v) * v + SURGE[1] * v + SURGE[2] + rng.normal(0, 0.8, v.size)
        fit = fit_drag(v, f)
        est.append(fit.ls.theta)
        stds.append(fit.ls.std)
        half = stats.t.ppf(0.975, fit.ls.dof) * fit.ls.std
        low, high = fit.ls.theta - half, fit.ls.theta + half
        covered += np.sum((low <= SURGE) & (SURGE <= high))
    est, stds = np.array(est), np.array(stds)
    spread = est.std(axis=0, ddof=1)
    np.testing.assert_allclose(stds.mean(axis=0), spread, rtol=0.20)
    coverage = covered / (3 * trials)
    band = 3 * np.sqrt(0.95 * 0.05 / trials)
    assert abs(coverage - 0.95) < band


def test_buoyancy_bias_in_heave():
    """[Hindrax-Drag] section 5: in heave b equals the net buoyancy f_b = (W - rho V) g,
    15.22 kg vs 1000 * 0.0153 = 15.30 kg -> |f_b| = 0.0800 * 9.80665 = 0.7845 N."""
    f_b = (15.30 - 15.22) * 9.80665
    assert f_b == pytest.approx(0.7845, abs=1e-4)
    rng = np.random.default_rng(6)
    v = np.concatenate([rng.uniform(0.05, 0.5, 60), rng.uniform(-0.5, -0.05, 60)])
    f = 75.0 * np.abs(v) * v + 8.0 * v + f_b + rng.normal(0, 0.3, v.size)
    fit = fit_drag(v, f)
    assert abs(fit.bias - f_b) < 4 * fit.bias_std
    assert fit.bias_std < 0.1


@pytest.mark.parametrize("call", [
    lambda: fit_linear_model(np.ones((3, 3)), np.ones(3)),                 # n <= p
    lambda: fit_linear_model(np.column_stack([np.arange(5.0), 2 * np.arange(5.0)]),
                             np.arange(5.0)),                              # collinear
    lambda: fit_linear_model(np.column_stack([np.zeros(5), np.ones(5)]), np.ones(5)),
    lambda: fit_linear_model(np.ones((5, 2)), np.ones(4)),                 # shape mismatch
    lambda: fit_linear_model(np.ones(5), np.ones(5)),                      # 1-D X
    lambda: fit_linear_model([[1.0, np.nan], [1.0, 2.0], [1.0, 3.0]], [1.0, 2.0, 3.0]),
    lambda: fit_linear_model([["a", "b"]] * 3, [1, 2, 3]),                 # not numeric
    lambda: fit_linear_model(np.eye(4)[:, :2], np.ones(4), names=("only_one",)),
    lambda: fit_drag(np.full(10, 0.3), np.full(10, 6.0)),                  # one velocity
    lambda: fit_drag([0.1, 0.2], [1.0, 2.0]),                              # n <= p
    lambda: fit_drag([0.1, 0.2, 0.3, 0.4], [1.0, 2.0, 3.0]),               # lengths
])
def test_error_paths_raise_value_error(call):
    with pytest.raises(EstimationError) as info:
        call()
    assert isinstance(info.value, ValueError)
    assert str(info.value)


def test_rank_deficiency_message_names_the_problem():
    with pytest.raises(EstimationError, match="rank deficient"):
        fit_drag(np.full(10, 0.3), np.full(10, 6.0))
    with pytest.raises(EstimationError, match="n=3, p=3"):
        fit_linear_model(np.eye(3), np.ones(3))


def test_badly_scaled_columns_are_not_rank_deficient():
    """Column equilibration: thruster-like regressors P^3 ~ 1e9 and 1 fit fine."""
    P = np.linspace(1100.0, 1480.0, 30)
    X = np.column_stack([P**3, P**2, P, np.ones_like(P)])
    y = X @ [-4.61e-7, 0.001794, -2.2726, 927.1827]
    r = fit_linear_model(X, y + np.random.default_rng(7).normal(0, 0.05, P.size))
    np.testing.assert_allclose(X @ r.theta, y, atol=0.1)
