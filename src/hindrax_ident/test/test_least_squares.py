"""Tests of hindrax_ident.estimation.least_squares ([Hindrax-Drag] eqs. 2-8)."""

import numpy as np
import pytest
from scipy import stats

from hindrax_ident.estimation.least_squares import (
    DragFit,
    DynamicFit,
    EstimationError,
    confidence_interval,
    fit_drag,
    fit_dynamic,
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
    d = r.to_dict()
    assert d["parameters"]["b"]["value"] == pytest.approx(theta[1])
    assert d["n"] == 50


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
    assert np.all(fit.predict_std(vq) > 0)
    d = fit.to_dict()
    assert set(d) >= {"quadratic_damping", "quadratic_damping_std", "linear_damping",
                      "linear_damping_std", "bias", "bias_std", "n"}


def test_fit_drag_optional_terms():
    rng = np.random.default_rng(2)
    v, f = surge_data(rng)
    fit = fit_drag(v, f, include_linear=False, include_bias=False)
    assert fit.ls.p == 1
    assert fit.linear_damping is None and fit.bias is None and fit.bias_std is None
    assert fit.quadratic_damping == pytest.approx(SURGE[0], rel=0.1)


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
        low, high = confidence_interval(fit.ls.theta, fit.ls.std, fit.ls.dof, 0.95)
        covered += np.sum((low <= SURGE) & (SURGE <= high))
    est, stds = np.array(est), np.array(stds)
    spread = est.std(axis=0, ddof=1)
    np.testing.assert_allclose(stds.mean(axis=0), spread, rtol=0.20)
    coverage = covered / (3 * trials)
    band = 3 * np.sqrt(0.95 * 0.05 / trials)
    assert abs(coverage - 0.95) < band


def test_confidence_interval_student_t():
    lo, hi = confidence_interval(10.0, 2.0, dof=5, level=0.95)
    t = stats.t.ppf(0.975, 5)   # 2.5706 (tabulated)
    assert t == pytest.approx(2.5706, abs=1e-4)
    assert (lo, hi) == pytest.approx((10 - 2 * t, 10 + 2 * t))
    lo, hi = confidence_interval(np.array([1.0, 2.0]), np.array([0.1, 0.2]), dof=1000)
    np.testing.assert_allclose(hi - lo, 2 * 1.9623 * np.array([0.1, 0.2]), rtol=1e-3)


@pytest.mark.parametrize("kwargs", [dict(dof=0), dict(dof=2.5), dict(level=1.0),
                                    dict(level=0.0), dict(std=-1.0)])
def test_confidence_interval_errors(kwargs):
    args = dict(value=1.0, std=1.0, dof=3, level=0.95)
    args.update(kwargs)
    with pytest.raises(EstimationError):
        confidence_interval(**args)


def _one_dof_record(rng, n=3000, dt=0.02, separate=False, restoring=False):
    """Velocity/acceleration of a multi-sine manoeuvre and the force of the 1-DOF model."""
    t = np.arange(n) * dt
    v = 0.3 * np.sin(0.4 * t) + 0.15 * np.sin(1.1 * t + 1.0) + 0.05
    a = 0.12 * np.cos(0.4 * t) + 0.165 * np.cos(1.1 * t + 1.0)
    m, kl, b = 35.0, 6.0, 0.78
    q = np.abs(v) * v
    if separate:
        f = m * a + np.where(v > 0, 93.5 * q, 56.6 * q) + kl * v + b
    else:
        f = m * a + 70.0 * q + kl * v + b
    angle = 0.4 * np.sin(0.7 * t)
    if restoring:
        f = f + 4.5 * np.sin(angle)          # W*BG = 4.5 N m (docs/identification.md §5)
    return a, v, f + rng.normal(0, 0.3, n), np.sin(angle)


def test_fit_dynamic_recovers_inertia_and_damping():
    rng = np.random.default_rng(4)
    a, v, f, _ = _one_dof_record(rng)
    fit = fit_dynamic(a, v, f)
    assert isinstance(fit, DynamicFit)
    for name, true in (("inertia", 35.0), ("quadratic_damping", 70.0),
                       ("linear_damping", 6.0), ("bias", 0.78)):
        est, std = getattr(fit, name), getattr(fit, name + "_std")
        assert abs(est - true) < 4 * std, name
    assert fit.quadratic_damping_positive is None and fit.restoring is None


def test_fit_dynamic_separate_quadratic_and_restoring():
    """Heave: different quadratic damping up/down ([Hindrax-Drag] Table 3 positive 93.52, negative
    56.57 N/(m/s)^2) and a restoring column sin(angle) whose coefficient is W*BG."""
    rng = np.random.default_rng(5)
    a, v, f, r = _one_dof_record(rng, separate=True, restoring=True)
    fit = fit_dynamic(a, v, f, separate_quadratic=True, restoring=r)
    assert fit.quadratic_damping is None
    assert abs(fit.quadratic_damping_positive - 93.5) < 4 * fit.quadratic_damping_positive_std
    assert abs(fit.quadratic_damping_negative - 56.6) < 4 * fit.quadratic_damping_negative_std
    assert abs(fit.restoring - 4.5) < 4 * fit.restoring_std
    assert abs(fit.inertia - 35.0) < 4 * fit.inertia_std
    assert fit.ls.names == ("inertia", "quadratic_damping_positive",
                            "quadratic_damping_negative", "linear_damping", "bias", "restoring")


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
    lambda: fit_dynamic(np.zeros(20), np.linspace(0.1, 1, 20), np.ones(20)),  # no accel
    lambda: fit_dynamic(np.sin(np.arange(20.0)), np.linspace(0.1, 1, 20), np.ones(20),
                        separate_quadratic=True),                         # no v < 0
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
