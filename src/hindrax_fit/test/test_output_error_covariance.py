"""The fit core's covariance is at least the cluster-robust (sandwich) covariance with segments as clusters
(fit_core.cluster_covariance, docs/identification.md §7): with residuals correlated inside segments, as a 1-DOF
model leaves them when the other DOFs move, the residual-variance covariance is too narrow and its 95 % intervals
miss the truth far more often than 5 %; the widened one keeps close to 95 %."""
import numpy as np
import pytest
from scipy import stats

from hindrax_fit.fit import fit_core

pytestmark = pytest.mark.filterwarnings("error::RuntimeWarning")


def _at_least_cluster_robust(naive, J, r, cluster, _p):
    """fit_core.cluster_covariance on a linear fit, one segment per cluster (independent groups: no merging).
    ``naive`` is recomputed there (sigma^2 (J^T J)^-1 with the residuals' lag-1 inflation)."""
    m = int(cluster.max()) + 1
    sd = fit_core.SegmentData(1.0, 2, np.zeros((3, m, 2)), np.zeros((3, m, 2, 0)), np.zeros(m), np.zeros(m), cluster,
                              np.zeros(r.size, int), np.zeros(r.size), np.zeros(r.size), np.arange(m),
                              np.zeros((m, 2)), np.ones(m, bool), np.zeros((m, 2)), np.zeros((m, 2)),
                              np.zeros((m, 2)))
    fit = fit_core.FitOutcome([("a", "bias", -np.inf, np.inf)] * J.shape[1], np.zeros(J.shape[1]), None, r,
                              np.ones(r.size), J, 1.0)
    return fit_core.cluster_covariance(fit, sd, min_clusters=3).cov


def _fit(rng, n_groups=40, per_group=50, group_std=0.5, noise_std=0.2):
    """Straight-line fit y = a + b x with a random offset per group; returns (theta, naive cov, wide cov)."""
    x = rng.uniform(-1.0, 1.0, size=(n_groups, per_group)) + rng.normal(0.0, 1.0, size=(n_groups, 1))
    y = 2.0 + 3.0 * x + rng.normal(0.0, group_std, size=(n_groups, 1)) + rng.normal(0.0, noise_std, x.shape)
    J = np.column_stack([np.ones(x.size), x.ravel()])
    theta, *_ = np.linalg.lstsq(J, y.ravel(), rcond=None)
    r = y.ravel() - J @ theta
    naive = (r @ r) / (x.size - 2) * np.linalg.inv(J.T @ J)
    cluster = np.repeat(np.arange(n_groups), per_group)
    return theta, naive, _at_least_cluster_robust(naive, J, r, cluster, 2)


def test_sandwich_widening_restores_the_coverage_of_correlated_residuals():
    rng = np.random.default_rng(7)
    truth = np.array([2.0, 3.0])
    z = stats.norm.ppf(0.975)
    hits_naive = np.zeros(2)
    hits_wide = np.zeros(2)
    n = 300
    for _ in range(n):
        theta, naive, wide = _fit(rng)
        assert np.all(np.diag(wide) >= np.diag(naive) - 1e-15)  # never narrower
        assert np.all(np.linalg.eigvalsh(wide) > 0)  # still a covariance
        hits_naive += np.abs(theta - truth) <= z * np.sqrt(np.diag(naive))
        hits_wide += np.abs(theta - truth) <= z * np.sqrt(np.diag(wide))
    assert np.all(hits_naive / n < 0.6)  # the group offsets make the naive intervals far too narrow
    assert np.all(np.abs(hits_wide / n - 0.95) < 0.04)


def test_independent_residuals_keep_their_covariance():
    rng = np.random.default_rng(3)
    ratios = []
    for _ in range(50):
        _theta, naive, wide = _fit(rng, group_std=0.0)
        ratios.append(np.diag(wide) / np.diag(naive))
    # only the sampling noise of the sandwich can widen it, by a few per cent on average
    assert np.mean(ratios) < 1.1


def test_too_few_clusters_leave_the_model_based_covariance():
    J = np.column_stack([np.ones(6), np.arange(6.0)])
    r = np.array([1.0, -1.0, 2.0, -2.0, 0.5, -0.5])
    sd = fit_core.SegmentData(1.0, 2, np.zeros((3, 2, 2)), np.zeros((3, 2, 2, 0)), np.zeros(2), np.zeros(2),
                              np.array([0, 0, 0, 1, 1, 1]), np.zeros(6, int), np.zeros(6), np.zeros(6), np.arange(2),
                              np.zeros((2, 2)), np.ones(2, bool), np.zeros((2, 2)), np.zeros((2, 2)), np.zeros((2, 2)))
    fit = fit_core.FitOutcome([("a", "bias", -np.inf, np.inf)] * 2, np.zeros(2), None, r,
                              np.ones(6), J, 1.0)
    cov = fit_core.cluster_covariance(fit, sd, min_clusters=3)
    assert cov.clusters == 2 and np.array_equal(cov.cov, cov.model)
