"""The honesty options of the online RLS: directional forgetting, excitation gate, physical
signs, change detection with covariance reset, and a standard deviation published only when converged."""
from __future__ import annotations

import math

import numpy as np

from hindrax_onboard.estimation.rls import RecursiveLeastSquares


def _feed(rls, rng, theta, n, cols=(0, 1), noise=0.05):
    for _ in range(n):
        phi = np.zeros(len(theta))
        for c in cols:
            phi[c] = rng.normal()
        rls.update(phi, float(phi @ theta) + rng.normal(0.0, noise))


def test_directional_forgetting_keeps_unexcited_directions():
    """Exciting only parameter 0 for a long time: exponential forgetting winds P[1, 1] up to its bound,
    directional forgetting leaves it where the excited phase put it."""
    rng = np.random.default_rng(1)
    theta = np.array([2.0, -1.0])
    runs = {}
    for directional in (False, True):
        r = RecursiveLeastSquares(2, forgetting=0.99, initial_covariance=100.0, directional=directional)
        _feed(r, rng, theta, 500)
        p11_before = r.P[1, 1]
        _feed(r, rng, theta, 3000, cols=(0,))
        runs[directional] = (p11_before, r.P[1, 1], r.theta)
    assert runs[False][1] > 100 * runs[False][0]  # wound up
    assert runs[True][1] < 2.0 * runs[True][0]  # kept
    assert np.allclose(runs[True][2], theta, atol=0.05)


def test_excitation_gate_freezes_the_estimate():
    """Before the excitation first reaches the threshold every sample updates (nothing is lost, nothing published);
    afterwards, rows that cannot separate the parameters (collinear: a long hold) leave theta and P untouched once
    they have pulled the forgetting-weighted excitation below the threshold."""
    r = RecursiveLeastSquares(2, forgetting=0.99, min_excitation=0.05)
    gateless = RecursiveLeastSquares(2, forgetting=0.99)
    rng = np.random.default_rng(2)
    for _ in range(400):
        phi = rng.normal(size=2)
        y = float(phi @ [1.0, 2.0]) + rng.normal(0.0, 0.01)
        r.update(phi, y)
        gateless.update(phi, y)
    assert r.gate_open and r.gated_samples == 0
    assert np.array_equal(r.theta, gateless.theta)  # the start is not gated
    assert np.all(np.isnan(RecursiveLeastSquares(2, min_excitation=0.05).published_std()))
    frozen = None
    for _ in range(1000):  # collinear rows that say theta_0 + theta_1 = 6 (a different truth)
        r.update([1.0, 1.0], 6.0)
        gateless.update([1.0, 1.0], 6.0)
        if r.gated_samples == 1:
            frozen = (r.theta, r.P)
    assert r.excitation_normalised < 0.05 and frozen is not None
    assert r.gated_samples > 600  # the first ~300 rows pull the excitation down (memory 100 samples)
    assert np.array_equal(r.theta, frozen[0]) and np.array_equal(r.P, frozen[1])
    assert np.all(np.isnan(r.published_std(rel_tol=1.0)))  # below the gate: not converged
    assert abs(gateless.theta.sum() - 6.0) < 0.01  # without the gate the hold drags the estimate


def test_lower_bounds_keep_physical_signs():
    rng = np.random.default_rng(3)
    r = RecursiveLeastSquares(2, forgetting=1.0, lower_bounds=[0.0, math.nan])
    for _ in range(300):  # true first parameter slightly negative: projected onto 0
        phi = rng.normal(size=2)
        r.update(phi, float(phi @ [-0.5, 1.0]) + rng.normal(0.0, 0.01))
        assert r.theta[0] >= 0.0
    assert r.theta[0] == 0.0


def test_change_is_detected_and_the_estimate_follows():
    rng = np.random.default_rng(4)
    r = RecursiveLeastSquares(2, forgetting=0.999, change_threshold=4.0, change_samples=30)
    _feed(r, rng, np.array([1.0, 1.0]), 3000)
    assert r.changes_detected == 0  # no false alarm on 3000 samples of a correct model
    _feed(r, rng, np.array([1.5, 0.5]), 400)
    assert r.changes_detected >= 1 and r.covariance_resets >= 1
    assert np.allclose(r.theta, [1.5, 0.5], atol=0.05)
    plain = RecursiveLeastSquares(2, forgetting=0.999)
    rng = np.random.default_rng(4)
    _feed(plain, rng, np.array([1.0, 1.0]), 3000)
    _feed(plain, rng, np.array([1.5, 0.5]), 400)
    assert abs(plain.theta[0] - 1.5) > 0.1  # without the reset the old data still pull (memory 1000 samples)


def test_std_published_only_when_converged():
    r = RecursiveLeastSquares(2, forgetting=1.0)
    r.update([1.0, 0.0], 1.0)
    assert np.all(np.isnan(r.published_std()))
    rng = np.random.default_rng(5)
    _feed(r, rng, np.array([2.0, 0.001]), 2000, noise=0.05)
    pub = r.published_std(rel_tol=0.05)
    assert math.isfinite(pub[0]) and pub[0] == r.std[0]
    assert math.isnan(pub[1])  # std of a tiny parameter is not 5 % of it
    assert math.isfinite(r.published_std(rel_tol=0.05, abs_tol=[0.0, 0.01])[1])


def test_bounded_estimate_is_the_constrained_least_squares_solution():
    """Strongly correlated columns (like v and |v| v) with the least-squares solution outside the bounds: the
    bounded estimate equals scipy's bounded least squares on the same rows at every checkpoint (a Euclidean clip
    fed back into the recursion, as first written, made campaigns diverge to 1e14-1e27)."""
    from scipy.optimize import lsq_linear

    rng = np.random.default_rng(7)
    n = 3000
    v = rng.uniform(0.05, 0.5, n)
    X = np.column_stack([rng.normal(size=n), np.abs(v) * v, v, np.ones(n)])
    truth = np.array([2.0, -0.3, 1.0, 0.2])  # the "quadratic damping" is negative: bounded at 0
    y = X @ truth + rng.normal(0.0, 0.05, n)
    lb = np.array([0.0, 0.0, 0.0, -np.inf])
    r = RecursiveLeastSquares(4, forgetting=1.0, initial_covariance=1e8, lower_bounds=[0.0, 0.0, 0.0, math.nan])
    for k in range(n):
        r.update(X[k], y[k])
        if k + 1 in (200, 1000, n):
            ref = lsq_linear(X[:k + 1], y[:k + 1], bounds=(lb, np.full(4, np.inf)), tol=1e-12).x
            assert np.allclose(r.theta, ref, atol=2e-3), (k, r.theta, ref)
    assert r.theta[1] == 0.0 and r.at_bound().tolist() == [False, True, False, False]
    assert math.isnan(r.published_std(rel_tol=1.0, abs_tol=10.0)[1])  # held on its bound: no interval
    unconstrained = np.linalg.lstsq(X, y, rcond=None)[0]
    assert np.allclose(r.theta_unconstrained, unconstrained, atol=1e-3)
