"""Cross-channel inputs: another DOF's commanded force as a candidate term chosen by cross-validation.

The data are built here from the definition of coupling through the allocation: sway receives its own command plus
30 % of the surge command (thrusters that do not deliver what the allocation assumes), a first-order sway model
integrated exactly for held forces; the tool has to find the term and its coefficient."""
from __future__ import annotations

import numpy as np

from hindrax_fit.fit import fit_core


def test_another_dofs_force_is_chosen_when_the_allocation_couples_it(synthetic_runs):
    syn = synthetic_runs
    rng = np.random.default_rng(11)
    h, n, M, D, c = 0.05, 1600, 30.0, 25.0, 0.3
    chunks = []
    for i in range(4):
        own, surge = syn.steps(rng, n, -15.0, 15.0), syn.steps(rng, n, -30.0, 30.0)
        v = syn.first_order(own + c * surge, M, D, h)  # M v' = own + c surge - D v
        chunks.append(syn.measured_chunk(rng, v, own, h, 0.005, group=i, t0=0.0, cross_force=surge[:, None].copy()))
    rec = fit_core.DofRecord("sway", h, "velocity", chunks, "thrust_model", 0.0, force_names=("surge",))
    res = fit_core.identify_dof(rec)
    assert res.terms.cross_force, res.terms.label
    got = dict(zip(res.names, res.theta))
    assert abs(got["force_from_surge"] - c) < 0.05 * c
    assert abs(got["inertia"] - M) < 0.1 * M
    without = [k for k in res.candidates if not k.terms.cross_force and k.terms.damping == res.terms.damping]
    assert without and all(k.mse > 2.0 * res.chosen.mse for k in without)  # the term is what predicts sway
