"""Issue 17 items 2 and 5 (batch part): the thrust scales and the empirical priors estimated jointly with the fits
(:func:`hindrax_ident.identification.calibration.joint_estimate`), checked against closed forms.

With one scale s, the fit of phi = theta / s and Gaussian priors, the joint least squares separates: the scale's
posterior is the precision-weighted mean of its prior N(1, sigma_s^2) and the calibration steps, and theta = s phi
has the delta-method covariance s^2 C_phi + phi phi^T var(s) (+ the product term var(s) C_phi, second order). A
parameter with a prior and a diagonal fit covariance is the precision-weighted mean of fit and prior.
"""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from hindrax_drivers.config import default_config_path, load_config
from hindrax_ident.identification.calibration import joint_estimate, scale_prior_std
from hindrax_ident.identification.estimators import parameter_names, rigid_inertia
from hindrax_ident.identification.results import build_results, prior_entries
from hindrax_ident.identification.verdicts import apply_verdicts


def _ident(dof, values, stds):
    names = parameter_names(dof)
    vals = dict(zip(names, values))
    vals["added_mass"] = vals["inertia"] - 15.22
    std = dict(zip(names, stds))
    std["added_mass"] = std["inertia"]
    return SimpleNamespace(dof=dof, names=names, values=vals, std=std, ci95={n: (0.0, 0.0) for n in vals},
                           signals={"covariance": np.diag(np.square(stds))}, steady=None, pool_time_s=60.0,
                           units={n: "" for n in vals}, method="output-error", equation_error={}, online={},
                           steady_note="", truth={}, rls_time_s=None, steady_time_s=None)


@pytest.fixture(scope="module")
def cfg():
    return load_config(default_config_path())


def test_calibrated_scale_is_the_precision_weighted_mean_and_theta_carries_its_variance(cfg):
    cal = {"vertical": {"value": 0.90, "std": 0.009}}       # ballast only: one common scale for all thrusters
    y = np.array([27.3, 66.5, 1.25, 0.02])                   # surge fit on the force scaled by 0.90
    sd = np.array([0.3, 2.0, 3.0, 0.05])
    r = _ident("surge", y, sd)
    sec = joint_estimate({"surge": r}, cfg, cal, prior_std_rel=0.0)
    sp = scale_prior_std(cfg)
    assert sp == pytest.approx(math.sqrt((0.05 ** 2 + 0.10 ** 2) / 2))   # ros_ws/config/hindrax.yaml [0.05, 0.10]
    w1, w2 = 1 / sp ** 2, 1 / 0.009 ** 2
    s_post = (w1 * 1.0 + w2 * 0.90) / (w1 + w2)
    var_s = 1 / (w1 + w2)
    assert sec["scales"]["common"]["value"] == pytest.approx(s_post, rel=1e-9)
    assert sec["scales"]["common"]["std"] == pytest.approx(math.sqrt(var_s), rel=1e-6)
    phi = y / 0.90
    for i, n in enumerate(parameter_names("surge")):
        assert r.values[n] == pytest.approx(s_post * phi[i], rel=1e-9)
        expected = math.sqrt(s_post ** 2 * (sd[i] / 0.90) ** 2 + phi[i] ** 2 * var_s)
        assert r.std[n] == pytest.approx(expected, rel=1e-3), n
    assert r.values["added_mass"] == pytest.approx(r.values["inertia"] - rigid_inertia(cfg, "surge"))
    # the verdicts do not add the thrust-curve uncertainty a second time
    a = apply_verdicts({"surge": r}, cfg)["surge"]
    assert a["parameters"]["inertia"]["std"] == pytest.approx(r.std["inertia"], rel=1e-9)
    assert a["parameters"]["inertia"]["std_fit"] == pytest.approx(0.3)
    assert a["checks"]["thrust_uncertainty_rel"] == [0.0, 0.0]


def test_two_groups_use_their_own_steps(cfg):
    cal = {"vertical": {"value": 0.92, "std": 0.01}, "surge": {"value": 0.80, "std": 0.01},
           "sway": {"value": 0.84, "std": 0.02}}
    rs = {"surge": _ident("surge", [27.3, 66.5, 1.25, 0.0], [0.3, 2.0, 3.0, 0.05]),
          "heave": _ident("heave", [37.7, 93.5, 56.6, 5.3, 11.8, 0.78], [0.5, 3, 3, 3, 3, 0.05])}
    sec = joint_estimate(rs, cfg, cal, prior_std_rel=0.0)
    sp = scale_prior_std(cfg)
    h = (1 / sp ** 2 + 0.80 / 0.01 ** 2 + 0.84 / 0.02 ** 2) / (1 / sp ** 2 + 1 / 0.01 ** 2 + 1 / 0.02 ** 2)
    v = (1 / sp ** 2 + 0.92 / 0.01 ** 2) / (1 / sp ** 2 + 1 / 0.01 ** 2)
    assert sec["scales"]["horizontal"]["value"] == pytest.approx(h, rel=1e-9)
    assert sec["scales"]["vertical"]["value"] == pytest.approx(v, rel=1e-9)
    assert sec["scales"]["horizontal"]["dofs"] == ["surge"] and sec["scales"]["vertical"]["dofs"] == ["heave"]
    # applied scale of the surge fit: the line pulls' inverse-variance mean (calibration.thrust_scales)
    h_app = (0.80 / 0.01 ** 2 + 0.84 / 0.02 ** 2) / (1 / 0.01 ** 2 + 1 / 0.02 ** 2)
    assert rs["surge"].values["inertia"] == pytest.approx(27.3 / h_app * h, rel=1e-9)
    assert rs["heave"].values["bias"] == pytest.approx(0.78 / 0.92 * v, rel=1e-9)


def test_empirical_prior_weights_the_fit_with_the_stated_std(cfg):
    y = np.array([27.3, 66.5, 1.25, 0.02])
    sd = np.array([0.3, 2.0, 3.0, 0.05])
    r = _ident("surge", y, sd)
    joint_estimate({"surge": r}, cfg, None, prior_std_rel=0.5)
    p = prior_entries(cfg)["surge"]
    for i, (n, mu) in enumerate((("inertia", rigid_inertia(cfg, "surge") + p["added_mass"]),
                                 ("quadratic_damping", p["quadratic_damping"]),
                                 ("linear_damping", p["linear_damping"]))):
        sp = 0.5 * (p["added_mass"] if n == "inertia" else mu)
        expected = (y[i] / sd[i] ** 2 + mu / sp ** 2) / (1 / sd[i] ** 2 + 1 / sp ** 2)
        assert r.values[n] == pytest.approx(expected, rel=1e-6), n
        assert r.std[n] == pytest.approx((1 / sd[i] ** 2 + 1 / sp ** 2) ** -0.5, rel=1e-6), n
    assert r.values["bias"] == pytest.approx(0.02, rel=1e-9)                 # no prior on the bias
    assert not r.signals["joint"]["thrust_in_covariance"]
    # without a calibration the verdicts still add the declared thrust-curve uncertainty
    joint_std = r.std["inertia"]
    a = apply_verdicts({"surge": r}, cfg)["surge"]
    assert a["parameters"]["inertia"]["std"] > 1.03 * joint_std


def test_identification_yaml_shows_the_prior_beside_the_value_and_the_joint_section(cfg):
    rs = {"surge": _ident("surge", [27.3, 66.5, 1.25, 0.02], [0.3, 2.0, 3.0, 0.05])}
    rs["surge"].signals.update(velocity=np.linspace(-0.5, 0.5, 50))
    doc = build_results(rs, cfg, calibration={"vertical": {"value": 0.9, "std": 0.009, "known_force_n": 8.56}})
    e = doc["dofs"]["surge"]
    p = prior_entries(cfg)["surge"]
    assert e["quadratic_damping"]["prior"] == pytest.approx([p["quadratic_damping"], 0.5 * p["quadratic_damping"]])
    assert e["inertia"]["prior"][0] == pytest.approx(rigid_inertia(cfg, "surge") + p["added_mass"])
    assert e["added_mass"]["prior"] == pytest.approx([p["added_mass"], 0.5 * p["added_mass"]])
    assert "prior" not in e["bias"]
    assert doc["joint"]["prior_std_rel"] == 0.5 and doc["joint"]["scales"]["common"]["measurements"][0]["step"] == \
        "ballast"
    assert doc["calibration"]["vertical_thrust_scale"]["known_force_n"] == 8.56
    with pytest.raises(ValueError, match="prior_std_rel"):
        joint_estimate({"surge": _ident("surge", [1, 1, 1, 0], [1, 1, 1, 1])}, cfg, None, prior_std_rel=-1.0)


def test_free_decay_disagreement_makes_the_inertia_suspect():
    from hindrax_ident.identification.verdicts import apply_reference_verdicts, free_decay_reason

    # 1.07 +- 0.02 against 0.97 +- 0.03: |0.10| / 0.0361 = 2.77 > 1.96 -> suspect
    assert "z = +2.8" in free_decay_reason("roll", (1.07, 0.02), (0.97, 0.03))
    assert free_decay_reason("roll", (1.02, 0.02), (0.97, 0.03)) is None     # 1.39 combined std: agrees
    doc = {"dofs": {
        "roll": {"inertia": {"value": 1.07, "std": 0.02, "verdict": "trusted", "reasons": []},
                 "added_mass": {"value": 0.59, "std": 0.02, "verdict": "trusted", "reasons": []},
                 "quadratic_damping": {"value": 1.3, "std": 0.1, "verdict": "trusted", "reasons": []},
                 "verdict": "trusted", "reasons": []},
        "pitch": {"inertia": {"value": 1.30, "std": 0.03, "verdict": "trusted", "reasons": []},
                  "verdict": "trusted", "reasons": []}},
        "free_decay": {"roll": {"total_inertia_kg_m2": 0.97, "total_inertia_kg_m2_std": 0.03},
                       "pitch": {"total_inertia_kg_m2": 1.26, "total_inertia_kg_m2_std": 0.04}}}
    apply_reference_verdicts(doc)
    apply_reference_verdicts(doc)                                              # idempotent
    roll = doc["dofs"]["roll"]
    assert roll["inertia"]["verdict"] == "suspect" and roll["added_mass"]["verdict"] == "suspect"
    assert len(roll["inertia"]["reasons"]) == 1 and "free decay" in roll["inertia"]["reasons"][0]
    assert roll["quadratic_damping"]["verdict"] == "trusted" and roll["verdict"] == "suspect"
    assert doc["free_decay"]["roll"]["self_propelled"]["verdict"] == "suspect"
    assert doc["free_decay"]["roll"]["self_propelled"]["z"] == pytest.approx(0.10 / math.hypot(0.02, 0.03))
    # pitch: 0.04 / 0.05 = 0.8 combined std
    assert doc["dofs"]["pitch"]["inertia"]["verdict"] == "trusted" and doc["dofs"]["pitch"]["verdict"] == "trusted"
    assert doc["free_decay"]["pitch"]["self_propelled"]["verdict"] == "agrees"


def test_report_references_section_shows_scales_free_decay_priors_and_disagreements(cfg):
    from hindrax_ident.identification.report import references_html
    from hindrax_ident.identification.verdicts import apply_reference_verdicts

    rs = {"surge": _ident("surge", [27.3, 66.5, 1.25, 0.02], [0.3, 2.0, 3.0, 0.05])}
    rs["surge"].signals.update(velocity=np.linspace(-0.5, 0.5, 50))
    cal = {"vertical": {"value": 0.9012, "std": 0.0044, "known_force_n": 8.56, "method": "ballast"},
           "surge": {"value": 0.8998, "std": 0.003, "known_force_n": 4.905, "method": "line_pull"}}
    doc = build_results(rs, cfg, calibration=cal)
    doc["dofs"]["roll"] = {"inertia": {"value": 1.07, "std": 0.02, "verdict": "trusted", "reasons": []},
                           "verdict": "trusted", "reasons": []}
    doc["free_decay"] = {"roll": {"total_inertia_kg_m2": 0.9712, "total_inertia_kg_m2_std": 0.0301,
                                  "added_inertia_kg_m2": 0.4881, "stiffness_n_m_per_rad": 4.503,
                                  "stiffness_source": "--restoring-n-m-per-rad (inclining test)"}}
    apply_reference_verdicts(doc)
    page = references_html(doc)
    # joint scales: the two groups with their steps, and the uncalibrated error 1/s - 1 (about +11 %)
    assert "Thrust scales estimated jointly" in page and "line pull surge 0.8998" in page and "ballast 0.9012" in page
    h = doc["joint"]["scales"]["horizontal"]["value"]
    assert f"{100 * (1 / h - 1):+.1f} %" in page and "curve off" in page
    # free decay beside the self-propelled value, z = 0.0988 / hypot(0.02, 0.0301) = 2.73: suspect
    assert "<td>0.9712</td>" in page and "<td>1.07</td>" in page and "<td>2.73</td>" in page
    assert "<td>suspect</td>" in page
    # the priors with the stated weight
    assert "Empirical priors" in page and "1-sigma 0.5 x its value" in page
    assert page.startswith("<h2>References (independent of the thrust curve)</h2>")
