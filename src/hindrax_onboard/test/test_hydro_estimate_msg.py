"""identification/estimates carries the RLS std only where it is worth publishing."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
from builtin_interfaces.msg import Time

from hindrax_onboard.identification.online.node import hydro_estimate


def _estimator(raw_std, published):
    names = ["inertia", "quadratic_damping", "linear_damping", "bias"]
    rls = SimpleNamespace(theta=np.array([27.0, 66.0, 1.2, 0.01]), std=np.asarray(raw_std, float),
                          covariance=np.diag(np.square(raw_std)), n_samples=900, excitation_normalised=0.3)
    return SimpleNamespace(rls=rls, names=names, converged_at_s=None,
                           published_std=lambda: np.asarray(published, float))


def test_std_is_the_published_one_and_minus_one_where_not_converged_or_not_trusted():
    est = _estimator(raw_std=[0.5, 2.0, 0.3, 0.02], published=[np.nan, 3.5, np.nan, np.nan])
    msg = hydro_estimate("surge", est, Time(sec=3))
    # the raw RLS std of the inertia (0.5) is not published: the suite showed it does not cover the truth
    assert list(msg.std) == [-1.0, 3.5, -1.0, -1.0]
    # the covariance stays the raw RLS one (a consumer that wants it can still have it)
    assert msg.covariance[0] == 0.25 and msg.covariance[5] == 4.0
    assert msg.converged is False and msg.sample_count == 900


def test_nothing_converged_publishes_no_std():
    est = _estimator(raw_std=[0.5, 2.0, 0.3, 0.02], published=[np.nan] * 4)
    assert list(hydro_estimate("sway", est, Time()).std) == [-1.0] * 4
