"""Tests of hindrax_onboard.estimation.rls (recursive LS with forgetting, docs/identification.md §1.D)."""

import numpy as np
import pytest

from hindrax_onboard.estimation.least_squares import EstimationError, fit_linear_model
from hindrax_onboard.estimation.rls import RecursiveLeastSquares

THETA = np.array([35.0, 70.0, 6.0, 0.78])   # inertia, k_q, k_l, bias (docs/architecture.md §5)


def update_batch(rls, Phi, y):
    """One :meth:`RecursiveLeastSquares.update` per row."""
    for phi, yi in zip(Phi, y):
        rls.update(phi, yi)


def regressors(n, dt=0.02, phase=0.0):
    """Rich multi-sine manoeuvre: rows [v_dot, |v| v, v, 1]."""
    t = np.arange(n) * dt + phase
    v = 0.3 * np.sin(0.5 * t) + 0.15 * np.sin(1.3 * t) + 0.05
    a = 0.15 * np.cos(0.5 * t) + 0.195 * np.cos(1.3 * t)
    return np.column_stack([a, np.abs(v) * v, v, np.ones(n)])


def test_lambda_one_equals_batch_least_squares():
    """With lambda = 1 and a diffuse prior RLS is the batch LS of [Hindrax-Drag] eqs. 6-8."""
    rng = np.random.default_rng(0)
    Phi = regressors(1500)
    y = Phi @ THETA + rng.normal(0, 0.4, Phi.shape[0])
    rls = RecursiveLeastSquares(4, forgetting=1.0, initial_covariance=1e8)
    update_batch(rls, Phi, y)
    batch = fit_linear_model(Phi, y)
    np.testing.assert_allclose(rls.theta, batch.theta, rtol=1e-4, atol=1e-5)
    np.testing.assert_allclose(rls.std, batch.std, rtol=1e-3)
    assert rls.sigma2 == pytest.approx(batch.sigma2, rel=1e-3)
    assert rls.dof == pytest.approx(1500 - 4, abs=1e-3)
    assert rls.n_samples == 1500
    assert rls.effective_window == pytest.approx(1500)


def test_update_returns_a_priori_error():
    rls = RecursiveLeastSquares(2, forgetting=1.0)
    rls.update([1.0, 0.0], 3.0)
    theta_before = rls.theta
    phi, y = np.array([0.5, 2.0]), 4.0
    err = rls.update(phi, y)
    assert err == pytest.approx(y - phi @ theta_before)


def test_tracks_a_parameter_step_with_forgetting():
    """Inertia 35 -> 45 kg at mid-record (e.g. a payload added): lambda = 0.99 (memory about
    100 samples = 2 s) re-converges, lambda = 1 stays near the average of the two values."""
    rng = np.random.default_rng(1)
    n = 4000
    Phi = regressors(n)
    theta_t = np.tile(THETA, (n, 1))
    theta_t[n // 2:, 0] = 45.0
    y = np.einsum("ij,ij->i", Phi, theta_t) + rng.normal(0, 0.2, n)
    fast = RecursiveLeastSquares(4, forgetting=0.99)
    slow = RecursiveLeastSquares(4, forgetting=1.0)
    update_batch(fast, Phi, y)
    update_batch(slow, Phi, y)
    assert fast.theta[0] == pytest.approx(45.0, abs=1.5)
    assert 37.0 < slow.theta[0] < 43.0


def test_persistence_of_excitation_measure():
    const = RecursiveLeastSquares(4, forgetting=0.995)
    for _ in range(500):
        const.update([0.0, 0.09, 0.3, 1.0], 25.0)     # steady velocity, no acceleration
    rich = RecursiveLeastSquares(4, forgetting=0.995)
    update_batch(rich, regressors(2000), regressors(2000) @ THETA)
    assert const.excitation < 1e-9
    assert const.excitation_normalised < 1e-9
    assert rich.excitation > 1e-4
    assert rich.excitation_normalised > 1e-2
    fresh = RecursiveLeastSquares(3)
    assert fresh.excitation == 0.0 and fresh.excitation_normalised == 0.0


def test_noise_variance_estimate_and_calibrated_std_with_forgetting():
    """Monte Carlo over 150 seeded runs: sigma2 ~ true variance; reported std matches the
    spread of the estimates within 20 % for lambda = 0.995 (sandwich covariance)."""
    rng = np.random.default_rng(2)
    Phi = regressors(1200)
    errs, stds, s2 = [], [], []
    for _ in range(150):
        y = Phi @ THETA + rng.normal(0, 0.5, Phi.shape[0])
        rls = RecursiveLeastSquares(4, forgetting=0.995, initial_covariance=1e4)
        update_batch(rls, Phi, y)
        errs.append(rls.theta - THETA)
        stds.append(rls.std)
        s2.append(rls.sigma2)
    spread = np.std(errs, axis=0, ddof=1)
    np.testing.assert_allclose(np.mean(stds, axis=0), spread, rtol=0.20)
    assert np.mean(s2) == pytest.approx(0.25, rel=0.05)
    # the naive sqrt(diag(P) sigma2) would be about sqrt(1 + lambda) = 1.41 times too large
    naive = np.sqrt(np.diag(rls.P) * rls.sigma2)
    assert np.all(naive > 1.2 * rls.std)


def test_covariance_bounding_prevents_wind_up():
    """Constant regressor with lambda = 0.95: P grows as 0.95^-k in unexcited directions
    (after 500 samples ~ 1e11 x P0) unless bounded by max_covariance."""
    bounded = RecursiveLeastSquares(3, forgetting=0.95, initial_covariance=10.0)
    unbounded = RecursiveLeastSquares(3, forgetting=0.95, initial_covariance=10.0,
                                      max_covariance=float("inf"))
    for _ in range(500):
        bounded.update([1.0, 0.5, 0.0], 2.0)
        unbounded.update([1.0, 0.5, 0.0], 2.0)
    assert np.linalg.eigvalsh(bounded.P)[-1] <= 10.0 * (1 + 1e-9)
    assert np.linalg.eigvalsh(unbounded.P)[-1] > 1e9
    assert np.all(np.isfinite(bounded.theta))
    assert bounded.predict([1.0, 0.5, 0.0]) == pytest.approx(2.0, abs=1e-6)


def test_reset_and_reset_covariance():
    rng = np.random.default_rng(4)
    Phi = regressors(600)
    y = Phi @ THETA + rng.normal(0, 0.3, Phi.shape[0])
    rls = RecursiveLeastSquares(4, forgetting=0.99, initial_covariance=100.0)
    update_batch(rls, Phi[:300], y[:300])
    theta, std_before = rls.theta, rls.std
    rls.reset_covariance()
    np.testing.assert_array_equal(rls.theta, theta)
    np.testing.assert_array_equal(rls.P, 100.0 * np.eye(4))
    assert rls.covariance_resets == 1
    # the current estimate is now a prior of covariance sigma2_hat * P0: std jumps up ...
    np.testing.assert_allclose(rls.std, np.sqrt(100.0 * rls.sigma2), rtol=1e-9)
    assert np.all(rls.std > std_before)
    # ... and comes down again with new data
    update_batch(rls, Phi[300:], y[300:])
    assert np.all(rls.std < np.sqrt(100.0 * rls.sigma2))
    rls.reset()
    np.testing.assert_array_equal(rls.theta, np.zeros(4))
    assert rls.n_samples == 0
    assert np.all(np.isnan(rls.std))


def test_converged_flag():
    rng = np.random.default_rng(3)
    Phi = regressors(3000)
    y = Phi @ THETA + rng.normal(0, 0.3, Phi.shape[0])
    rls = RecursiveLeastSquares(4, forgetting=1.0)
    assert not rls.converged_mask(0.05).all()
    update_batch(rls, Phi[:20], y[:20])
    assert not rls.converged_mask(0.05).all()           # fewer than 10 p samples
    update_batch(rls, Phi[20:], y[20:])
    assert not rls.converged_mask(0.001).all()          # too strict
    assert rls.converged_mask(0.05).all()


def test_six_parameter_model_shapes():
    """A (p,) update keeps (p, p) state only; no per-sample history is stored."""
    rls = RecursiveLeastSquares(6)
    for _ in range(50):
        rls.update(np.arange(6.0) + 1, 1.0)
    assert rls.P.shape == (6, 6) and rls.theta.shape == (6,)


@pytest.mark.parametrize("call", [
    lambda: RecursiveLeastSquares(0),
    lambda: RecursiveLeastSquares(2.5),
    lambda: RecursiveLeastSquares(3, forgetting=0.0),
    lambda: RecursiveLeastSquares(3, forgetting=1.01),
    lambda: RecursiveLeastSquares(3, initial_covariance=-1.0),
    lambda: RecursiveLeastSquares(2, initial_covariance=np.array([[1.0, 2.0], [2.0, 1.0]])),
    lambda: RecursiveLeastSquares(2, initial_covariance=np.eye(3)),
    lambda: RecursiveLeastSquares(2, initial_theta=[1.0]),
    lambda: RecursiveLeastSquares(2, max_covariance=0.0),
    lambda: RecursiveLeastSquares(2).update([1.0, 2.0, 3.0], 1.0),
    lambda: RecursiveLeastSquares(2).update([1.0, np.nan], 1.0),
    lambda: RecursiveLeastSquares(2).update([1.0, 1.0], np.inf),
])
def test_errors(call):
    with pytest.raises(EstimationError):
        call()


def test_bad_sample_leaves_state_unchanged():
    rls = RecursiveLeastSquares(2, forgetting=1.0)
    rls.update([1.0, 1.0], 2.0)
    theta, P, n = rls.theta, rls.P, rls.n_samples
    with pytest.raises(EstimationError):
        rls.update([np.nan, 1.0], 2.0)
    np.testing.assert_array_equal(rls.theta, theta)
    np.testing.assert_array_equal(rls.P, P)
    assert rls.n_samples == n
