"""Heave's depth residuals are judged by their independence from the input, not by their lag-1 autocorrelation.

A measured position's output-error residual is the double integral of every force the model does not have: on a
synthetic heave record whose vehicle also feels an unrecorded force of 1 N (Ornstein-Uhlenbeck, 1 s correlation
time; the README's pool day on the wall clock leaves such a misfit, lag-1 autocorrelation 0.86) the right model's
consecutive depth residuals are correlated far above the whiteness threshold, yet their cross-correlation with the
input stays inside its 99 % bound (:func:`~hindrax_fit.fit.fit_core.input_correlation`,
[Ljung1999] §16.6) and the verdict trusts it.
On the same data a model without quadratic damping, and the right model with a 30 % wrong inertia, leave residuals
that follow the force: the verdict flags them.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from hindrax_fit.assessment import verdicts
from hindrax_fit.fit import fit_core

pytestmark = pytest.mark.filterwarnings("error::RuntimeWarning")

#: heave truth: inertia kg, quadratic damping down / up kg/m, linear damping down / up kg/s, bias N (the vehicle file's)
TRUTH = (37.7, 93.52, 56.57, 5.26, 11.84, 0.785)
H = 0.02  # tick, s
DEPTH_EVERY = 5  # a depth sample every 5 ticks (10 Hz, the MS5837's rate)


def _record(seed: int = 3, seconds: float = 240.0, disturbance_std_n: float = 1.0) -> fit_core.DofRecord:
    """A heave ladder (holds of 2-5 s at +-15..50 N and 0) on a vehicle that also feels ``disturbance_std_n`` of
    unrecorded Ornstein-Uhlenbeck force (1 s correlation time); depth at 10 Hz with 2 mm white noise (20 Pa)."""
    rng = np.random.default_rng(seed)
    n = int(round(seconds / H))
    f = np.empty(n)
    i = 0
    while i < n:
        d = int(rng.uniform(2.0, 5.0) / H)
        f[i:i + d] = rng.choice([-1.0, 1.0]) * rng.uniform(15.0, 50.0) if rng.random() > 0.3 else 0.0
        i += d
    a_ou = np.exp(-H / 1.0)
    dist = np.zeros(n)
    for j in range(1, n):
        dist[j] = a_ou * dist[j - 1] + disturbance_std_n * np.sqrt(1 - a_ou ** 2) * rng.standard_normal()
    m_, kqp, kqn, klp, kln, b = TRUTH

    def acc(w, force):
        kq, kl = (kqp, klp) if w > 0 else (kqn, kln)
        return (force - kq * abs(w) * w - kl * w - b) / m_

    v, x, a = np.zeros(n), np.zeros(n), np.zeros(n)
    w, z, dt = 0.0, 1.0, H / 10
    x[0] = z
    for j in range(n - 1):
        force = f[j] + dist[j]
        a[j] = acc(w, force)
        for _ in range(10):
            k1 = acc(w, force)
            k2 = acc(w + 0.5 * dt * k1, force)
            k3 = acc(w + 0.5 * dt * k2, force)
            k4 = acc(w + dt * k3, force)
            z += dt * w + dt * dt / 6 * (k1 + k2 + k3)
            w += dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        v[j + 1], x[j + 1] = w, z
    a[-1] = a[-2]
    pos = np.arange(0, n, DEPTH_EVERY, dtype=float)
    depth = x[::DEPTH_EVERY] + 0.002 * rng.standard_normal(pos.size)
    ch = fit_core.Chunk(f, v, x, a, pos, depth, group=0, force_start=0.0)
    return fit_core.DofRecord("heave", H, "position", [ch], "thrust_model", 0.0, terms=fit_core.Terms("both", True),
                              all_segments=True)


def _reasons(res: fit_core.DofResult) -> list[str]:
    """The DOF-wide reasons of the one verdict path (:func:`verdicts.assess`) for a fit core result."""
    ev = verdicts.FitEvidence(res.dof, list(res.names), res.theta, res.covariance.cov, res.covariance.t_dof, {},
                              *verdicts.core_signals(res), residual_rho=res.covariance.residual_rho,
                              input_corr=res.covariance.input_corr, expected_bias=None)
    return verdicts.assess(ev, (0.0, 0.0))["reasons"]


@pytest.fixture(scope="module")
def record() -> fit_core.DofRecord:
    return _record()


@pytest.fixture(scope="module")
def right_fit(record) -> fit_core.DofResult:
    """The right model's fit of :func:`record`, once for the tests that read it (the fit is the costly part)."""
    return fit_core.identify_dof(record)


def test_the_right_model_under_a_coloured_disturbance_is_trusted(right_fit):
    res = right_fit
    cov = res.covariance
    # what the lag-1 whiteness check saw: far above its threshold although the model is the truth's
    assert cov.residual_rho > 3 * verdicts.WHITENESS_MAX, cov.residual_rho
    assert cov.input_corr["z"] < verdicts.INDEPENDENCE_Z, cov.input_corr
    assert _reasons(res) == []
    # and the estimate is the truth's within its intervals
    for (lo, hi), true in zip(res.ci95, TRUTH):
        assert lo <= true <= hi, (res.names, res.ci95, TRUTH)


def test_a_model_without_quadratic_damping_is_flagged(record):
    res = fit_core.identify_dof(dataclasses.replace(record, terms=fit_core.Terms("linear", True)))
    assert res.covariance.input_corr["z"] > verdicts.INDEPENDENCE_Z, res.covariance.input_corr
    assert any("residuals follow the" in r for r in _reasons(res)), _reasons(res)


@pytest.mark.parametrize("factor", [0.7, 1.3])
def test_a_wrong_added_mass_is_flagged(right_fit, factor):
    """The right terms with the inertia held 30 % off (the other parameters and initial velocities refitted)."""
    res = right_fit
    layout = list(res.chosen.layout)
    theta = res.theta.copy()
    theta[0] *= factor
    name, kind, _lo, _hi = layout[0]
    layout[0] = (name, kind, theta[0] * (1 - 1e-6), theta[0] * (1 + 1e-6))
    fit = fit_core.fit_terms(res.chosen.train, "heave", layout, theta)
    xc = fit_core.input_correlation(fit.residuals, res.chosen.train)
    assert xc["z"] > verdicts.INDEPENDENCE_Z, xc
