"""The executive's online RLS: directional forgetting, the excitation gate,
physical-sign bounds and the change detector switched on from the vehicle file, and the start at the empirical
priors with the stated weight."""
from __future__ import annotations

import math

import numpy as np
import pytest

from hindrax_common.config import default_config_path, load_config
from hindrax_onboard.estimation.priors import priors_from_config
from hindrax_sim.campaign import Campaign
from hindrax_onboard.identification.model.dof_model import (parameter_names, rigid_inertia,
                                                        truth_parameters)
from hindrax_onboard.identification.online.estimators import online_rls


@pytest.fixture(scope="module")
def cfg():
    return load_config(default_config_path())


def test_settings_come_from_the_vehicle_file(cfg):
    r = online_rls(cfg, "sway")
    f = cfg.flat
    assert r.directional is bool(f["identification.rls_directional_forgetting"]) is True
    assert r.min_excitation == f["identification.rls_min_excitation"] > 0.0
    assert r.change_threshold == f["identification.rls_change_threshold"] > 1.0
    assert r.change_samples == round(f["identification.rls_change_window_s"] * f["identification.estimate_rate_hz"])
    off = load_config(default_config_path(), {"identification.rls_directional_forgetting": False,
                                               "identification.rls_min_excitation": 0.0,
                                               "identification.rls_change_threshold": 0.0,
                                               "identification.rls_prior_std_rel": 0.0})
    r0 = online_rls(off, "sway")
    assert not r0.directional and r0.min_excitation == 0.0 and r0.change_threshold is None
    assert np.all(r0.theta == 0.0) and np.allclose(r0.P, 1e4 * np.eye(4))


def test_the_start_is_the_empirical_prior_with_the_stated_weight(cfg):
    pri = priors_from_config(cfg)  # [NTNU-Thesis] App. A.1/A.2 from the geometry
    rel = cfg.identification.rls_prior_std_rel
    for k, dof in enumerate(("surge", "sway", "heave", "roll", "pitch", "yaw")):
        r = online_rls(cfg, dof)
        am, lin, quad = pri["added_mass"][k], pri["linear_damping"][k], pri["quadratic_damping"][k]
        th = dict(zip(parameter_names(dof), r.theta))
        assert th["inertia"] == pytest.approx(rigid_inertia(cfg, dof) + am)
        for n, v in th.items():
            if n.startswith("quadratic"):
                assert v == pytest.approx(quad)
            elif n.startswith("linear"):
                assert v == pytest.approx(lin)
        assert th["bias"] == pytest.approx(cfg.buoyancy_n - cfg.weight_n if dof == "heave" else 0.0)
        # P0 = (prior std / reference force noise)^2: the inertia's prior std is rel x the added-mass prior
        noise = 0.1 if dof in ("roll", "pitch", "yaw") else 1.0
        assert r.P[0, 0] == pytest.approx((rel * am / noise) ** 2)


def test_online_rls_starts_at_the_priors_and_converges_on_a_short_campaign(cfg):
    """Surge, 3 levels, in-process, the default settings (all on): the first estimates are the priors (the
    surge quadratic damping prior is 93 kg/m, the truth 66.5 kg/m), the last within a few per cent of the truth,
    no divergence, no change detected in a pool that does not change."""
    c = Campaign(cfg, dofs=["surge"], levels=3, seed=2)
    est = c.executive.online["surge"]
    first = {}
    orig = est.rls.update

    def spy(phi, y):
        e = orig(phi, y)
        if not first:
            first.update(zip(est.names, est.rls.theta))
        return e

    est.rls.update = spy
    c.run()
    truth = truth_parameters(cfg, "surge")
    prior_quad = priors_from_config(cfg)["quadratic_damping"][0]
    # starts at the prior, not 0 nor the truth (28 % away): the first update moves it 2.3 % at the 25 Hz tick
    assert first["quadratic_damping"] == pytest.approx(prior_quad, rel=0.05)
    assert abs(prior_quad - truth["quadratic_damping"]) > 0.3 * truth["quadratic_damping"]
    final = dict(zip(est.names, est.rls.theta))
    assert est.rls.n_samples > 1000 and est.rls.changes_detected == 0
    assert final["quadratic_damping"] == pytest.approx(truth["quadratic_damping"], rel=0.05)
    assert final["inertia"] == pytest.approx(truth["inertia"], rel=0.12)  # the causal filter lags: reads low
    assert np.all(np.isfinite(est.rls.theta)) and np.all(est.rls.theta[:3] >= 0.0)
    pub = est.published_std()
    assert math.isfinite(pub[1])  # converged quadratic damping: a std is published
    assert abs(final["quadratic_damping"] - truth["quadratic_damping"]) <= 1.96 * pub[1]
    assert math.isnan(pub[0]) and math.isnan(pub[3])  # inertia and bias: never published
