"""Cross-channel inputs (issue 46.2): another DOF's commanded force as a candidate term chosen by cross-validation.

The data are built here from the definition of coupling through the allocation: sway receives its own command plus
30 % of the surge command (thrusters that do not deliver what the allocation assumes), a first-order sway model
integrated exactly for held forces; the tool has to find the term and its coefficient."""
from __future__ import annotations

import math

import numpy as np
from scipy import signal

from hindrax_ident.identification import fit_core


def _steps(rng, n, lo, hi):
    out = np.empty(n)
    i = 0
    while i < n:
        k = int(rng.integers(20, 80))
        out[i:i + k] = rng.uniform(lo, hi)
        i += k
    return out


def test_another_dofs_force_is_chosen_when_the_allocation_couples_it():
    rng = np.random.default_rng(11)
    h, n, M, D, c = 0.05, 1600, 30.0, 25.0, 0.3
    chunks = []
    for i in range(4):
        own, surge = _steps(rng, n, -15.0, 15.0), _steps(rng, n, -30.0, 30.0)
        e = math.exp(-D / M * h)
        v = np.zeros(n)
        for j in range(1, n):  # M v' = own + c surge - D v, force held over each tick
            v[j] = v[j - 1] * e + (1.0 - e) * (own[j - 1] + c * surge[j - 1]) / D
        meas = np.arange(0, n, 2)
        z = v[meas] + rng.normal(0.0, 0.005, meas.size)
        zi = np.interp(np.arange(n), meas, z)
        chunks.append(fit_core.Chunk(own, signal.savgol_filter(zi, 11, 2), np.zeros(n),
                                     signal.savgol_filter(zi, 11, 2, deriv=1, delta=h), meas.astype(float), z,
                                     group=i, t0=0.0, cross_force=surge[:, None].copy()))
    rec = fit_core.DofRecord("sway", h, "velocity", chunks, "thrust_model", 0.0, force_names=("surge",))
    res = fit_core.identify_dof(rec)
    assert res.terms.cross_force, res.terms.label
    got = dict(zip(res.names, res.theta))
    assert abs(got["force_from_surge"] - c) < 0.05 * c
    assert abs(got["inertia"] - M) < 0.1 * M
    without = [k for k in res.candidates if not k.terms.cross_force and k.terms.damping == res.terms.damping]
    assert without and all(k.mse > 2.0 * res.chosen.mse for k in without)  # the term is what predicts sway
