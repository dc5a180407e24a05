"""The thrust scales per thruster group and rotation direction
and the empirical priors estimated jointly with the fits (:func:`hindrax_fit.fit.calibration.
joint_estimate`), checked against closed forms.

With the fit of phi = theta / sigma(s) (sigma the shares-weighted scale of a parameter) and Gaussian priors, the
joint least squares separates when no empirical prior acts: the scales' posterior is that of their priors and the
calibration holds alone (linear Gaussian), and theta = sigma phi has the delta-method covariance
sigma^2 C_phi + phi phi^T var(sigma) (+ a second-order product term). A parameter with a prior and a diagonal fit
covariance is the precision-weighted mean of fit and prior.
"""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from hindrax_common.config import default_config_path, load_config
from hindrax_fit.fit.calibration import joint_estimate, scale_prior_stds
from hindrax_onboard.identification.model.dof_model import parameter_names, rigid_inertia
from hindrax_fit.assessment.results import build_results
from hindrax_onboard.identification.model.posterior import prior_entries
from hindrax_fit.assessment.verdicts import apply_verdicts

pytestmark = pytest.mark.filterwarnings("error::RuntimeWarning")


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
    """An older single-scale ballast result only (the mean of the two directions, one vertical measurement: the same
    two scales for every thruster); surge uses both directions equally (the 55-degree layout), so it depends on
    their mean m only, whose prior is N(1, (u_f^2 + u_r^2) / 4)."""
    cal = {"vertical": {"value": 0.90, "std": 0.009}}
    y = np.array([27.3, 66.5, 1.25, 0.02])                   # surge fit on the force rebuilt with the point scales
    sd = np.array([0.3, 2.0, 3.0, 0.05])
    r = _ident("surge", y, sd)
    sec = joint_estimate({"surge": r}, cfg, cal, prior_std_rel=0.0)
    u = scale_prior_stds(cfg)
    assert (u["forward"], u["reverse"]) == (0.10, 0.05)      # ros_ws/config/hindrax.yaml [negative, positive]
    vm = (u["forward"] ** 2 + u["reverse"] ** 2) / 4.0
    m = (1.0 / vm + 0.90 / 0.009 ** 2) / (1.0 / vm + 1.0 / 0.009 ** 2)
    var_m = 1.0 / (1.0 / vm + 1.0 / 0.009 ** 2)
    assert sec["group_means"]["common"]["value"] == pytest.approx(m, rel=1e-9)
    assert sec["group_means"]["common"]["std"] == pytest.approx(math.sqrt(var_m), rel=1e-6)
    # the fit was made at the calibration's own posterior, which nothing else moves: theta stays, its variance grows
    for i, n in enumerate(parameter_names("surge")):
        assert r.values[n] == pytest.approx(y[i], rel=1e-9)
        expected = math.sqrt(sd[i] ** 2 + (y[i] / m) ** 2 * var_m)
        assert r.std[n] == pytest.approx(expected, rel=1e-3), n
    assert r.values["added_mass"] == pytest.approx(r.values["inertia"] - rigid_inertia(cfg, "surge"))
    # the verdicts do not add the thrust-curve uncertainty a second time
    a = apply_verdicts({"surge": r}, cfg)["surge"]
    assert a["parameters"]["inertia"]["std"] == pytest.approx(r.std["inertia"], rel=1e-9)
    assert a["parameters"]["inertia"]["std_fit"] == pytest.approx(0.3)
    assert a["checks"]["thrust_uncertainty_rel"] == [0.0, 0.0]


def _hold_rows(cfg, a=0.95, b=0.85):
    """Sinker and float results of a pool whose vertical thrusters give a (forward) and b (reverse) times their
    curves, holding-force std 0.02 N."""
    bn, w, f = cfg.buoyancy_n - cfg.weight_n, 8.56, 9.32
    e = {"std": 0.01, "holding_force_std_n": [0.02, 0.02]}
    return {"vertical": {**e, "value": 0.86, "known_force_n": w, "method": "ballast",
                         "forward_force_n": [bn / a, 0.0], "reverse_force_n": [0.0, (bn - w) / b]},
            "vertical_negative": {**e, "value": 0.95, "known_force_n": f, "method": "float",
                                  "forward_force_n": [bn / a, (bn + f) / a], "reverse_force_n": [0.0, 0.0]}}


def _vertical_posterior(cfg, cal):
    """Posterior mean and covariance of [a, b, B] (vertical forward and reverse scales, net buoyancy) from the four
    vertical holds, the priors N(1, 0.10^2), N(1, 0.05^2) and the weighed B +- 0.05 N: normal equations written out
    here, independently of calibration.ScaleModel."""
    bn = cfg.buoyancy_n - cfg.weight_n
    rows = []   # [a, b, B] coefficients, rhs, std: a P + b N - B = -E
    for e, sense in ((cal["vertical"], 1.0), (cal["vertical_negative"], -1.0)):
        for k, ext in enumerate((0.0, sense * e["known_force_n"])):
            rows.append(([e["forward_force_n"][k], e["reverse_force_n"][k], -1.0], -ext, 0.02))
    rows += [([1, 0, 0], 1.0, 0.10), ([0, 1, 0], 1.0, 0.05), ([0, 0, 1], bn, 0.05)]
    A = np.array([np.array(c) / sd for c, _, sd in rows])
    z = np.array([r / sd for _, r, sd in rows])
    cov = np.linalg.inv(A.T @ A)
    return cov @ A.T @ z, cov


def test_each_heave_parameter_carries_the_direction_it_depends_on(cfg):
    """Heave down is forward thrust, up reverse: ``*_positive`` and the bias (the hover) depend on the forward scale,
    ``*_negative`` on the reverse one, the inertia on both. The scales' posterior recomputed here independently
    (normal equations of the four holds, the weighed net buoyancy and the priors; unknowns a, b, B)."""
    cal = _hold_rows(cfg)
    h = _ident("heave", [37.7, 93.5, 56.6, 5.3, 11.8, 0.78], [0.5, 3, 3, 3, 3, 0.05])
    sec = joint_estimate({"heave": h}, cfg, cal, prior_std_rel=0.0)
    post, cov = _vertical_posterior(cfg, cal)
    assert sec["scales"]["common_forward"]["value"] == pytest.approx(post[0], rel=1e-6)
    assert sec["scales"]["common_reverse"]["value"] == pytest.approx(post[1], rel=1e-6)
    assert sec["scales"]["common_reverse"]["std"] == pytest.approx(math.sqrt(cov[1, 1]), rel=1e-4)
    assert sec["net_buoyancy_n"]["value"] == pytest.approx(post[2], rel=1e-6)
    assert post[0] == pytest.approx(0.95, abs=0.01) and post[1] == pytest.approx(0.85, abs=0.01)
    y = dict(zip(parameter_names("heave"), [37.7, 93.5, 56.6, 5.3, 11.8, 0.78]))
    sd = dict(zip(parameter_names("heave"), [0.5, 3, 3, 3, 3, 0.05]))
    sig_i = 0.5 * (post[0] + post[1])
    var_i = 0.25 * (cov[0, 0] + cov[1, 1] + 2.0 * cov[0, 1])
    for n, s_, var in (("quadratic_damping_positive", post[0], cov[0, 0]), ("bias", post[0], cov[0, 0]),
                       ("quadratic_damping_negative", post[1], cov[1, 1]), ("inertia", sig_i, var_i)):
        assert h.values[n] == pytest.approx(y[n], rel=1e-6), n
        assert h.std[n] == pytest.approx(math.sqrt(sd[n] ** 2 + (y[n] / s_) ** 2 * var), rel=1e-3), n
    assert h.signals["joint"]["scale_parameter"] == "common_forward, common_reverse"


def test_line_pulls_fix_the_horizontal_mean_and_surge_depends_on_nothing_else(cfg):
    """Both groups measured; the line pulls held half by forward and half by reverse thrust (the 55-degree layout):
    the horizontal mean is measured, the difference keeps its prior, and surge (half each way) sees the mean only."""
    pull = {"std": 0.01, "holding_force_std_n": [0.02, 0.02], "value": 0.9, "known_force_n": 4.905,
            "method": "line_pull", "forward_force_n": [0.0, -2.725], "reverse_force_n": [0.0, -2.725]}
    cal = {**_hold_rows(cfg), "surge": pull, "sway": dict(pull)}
    r = _ident("surge", [27.3, 66.5, 1.25, 0.02], [0.3, 2.0, 3.0, 0.05])
    sec = joint_estimate({"surge": r}, cfg, cal, prior_std_rel=0.0)
    mean = sec["group_means"]["horizontal"]
    assert mean["value"] == pytest.approx(4.905 / 5.45, rel=1e-3)      # held by s_mean * 5.45 N of curve force
    for d in ("forward", "reverse"):
        assert sec["scales"][f"horizontal_{d}"]["std"] > 5.0 * mean["std"]
        assert sec["scales"][f"horizontal_{d}"]["dofs"] == ["surge"]
    assert sec["scales"]["vertical_forward"]["dofs"] == []
    assert r.std["inertia"] == pytest.approx(math.hypot(0.3, 27.3 / mean["value"] * mean["std"]), rel=1e-3)


def test_sensitivities_are_measured_by_refits_and_carried_into_the_intervals(cfg):
    """attach_thrust_sensitivities with a stand-in fit that is linear in the force (theta = A F of the DOF's axis):
    the refit with one scale raised and the homogeneity of the rest must give exactly A times each direction's part
    of the curve force, computed here independently (sign split, first-order lag as an IIR filter, allocation
    matrix); surge only sees the horizontal scales, heave only the vertical ones. joint_estimate then carries
    G Cov(s) G^T into each parameter's variance."""
    from scipy import signal

    from hindrax_bringup.allocation.matrix import thrust_allocation_matrix
    from hindrax_fit.fit.calibration import attach_thrust_sensitivities
    from hindrax_onboard.identification.model.campaign_record import CampaignRecord

    rng = np.random.default_rng(3)
    n, dt, tau = 600, 0.02, float(cfg.thrusters.time_constant_s)
    f = np.repeat(rng.uniform(-10.0, 10.0, size=(n // 30, 8)), 30, axis=0)
    t = np.arange(n) * dt
    pull = {"std": 0.01, "holding_force_std_n": [0.02, 0.02], "value": 0.9, "known_force_n": 4.905,
            "method": "line_pull", "forward_force_n": [0.0, -3.6], "reverse_force_n": [0.0, -1.7]}
    cal = {**_hold_rows(cfg), "surge": pull, "sway": dict(pull, forward_force_n=[0.0, -1.0],
                                                           reverse_force_n=[0.0, -4.5])}
    rec = CampaignRecord(t_s=t, wrench_frd=np.zeros((n, 6)), wrench_cmd_frd=np.zeros((n, 6)),
                         active=np.zeros(n, int), level=np.zeros(n), run_id=np.zeros(n, int),
                         truth_position_ned_m=np.zeros((n, 3)), truth_euler_rad=np.zeros((n, 3)), sensors={},
                         windows={"surge": (t[0], t[299]), "heave": (t[300], t[-1])}, online={}, levels={},
                         authority={}, aborted=False, abort_reason="", wall_time_s=0.0, tick_s=dt, time_constant_s=tau,
                         seed=0, calibration=cal, thrust_cmd_n=f)
    a = {d: np.random.default_rng(9).normal(size=(len(parameter_names(d)), 300)) / 300.0 for d in ("surge", "heave")}

    def linear_fit(record, _cfg):
        out = {}
        for d, k in (("surge", 0), ("heave", 2)):
            if d in record.windows:
                sl = record.dof_slice(d)
                theta = a[d] @ record.wrench_frd[sl, k][:300]
                out[d] = _ident(d, theta, np.full(theta.size, 0.01))
        return out, {}

    from hindrax_fit.fit.calibration import apply_thrust_calibration
    ids, _ = linear_fit(apply_thrust_calibration(rec, cfg=cfg), cfg)
    attach_thrust_sensitivities(rec, ids, cfg, linear_fit)
    tc = cfg.thrusters
    b = thrust_allocation_matrix(tc.positions_frd_m, tc.directions_frd)
    vertical = np.abs(tc.directions_frd[:, 2]) > 0.5
    k_ = math.exp(-dt / tau)
    for d, k, g in (("surge", 0, "horizontal"), ("heave", 2, "vertical")):
        sens = ids[d].signals["thrust_sensitivity"]
        assert set(sens) == {f"{g}_forward", f"{g}_reverse"}, sens.keys()
        sl = rec.dof_slice(d)
        for direction, part in (("forward", np.maximum(f, 0.0)), ("reverse", np.minimum(f, 0.0))):
            mask = vertical if g == "vertical" else ~vertical
            lagged = signal.lfilter([0.0, 1.0 - k_], [1.0, -k_], part * mask, axis=0)
            expected = a[d] @ (lagged @ b.T)[sl, k][:300]
            np.testing.assert_allclose(sens[f"{g}_{direction}"], expected, rtol=1e-5, atol=1e-9)
    # the joint estimate: no empirical prior, so theta stays and its variance grows by G Cov(s) G^T
    theta = np.array([ids["heave"].values[n_] for n_ in ids["heave"].names])
    g_mat = np.array([ids["heave"].signals["thrust_sensitivity"][f"vertical_{x}"] for x in ("forward", "reverse")]).T
    sec = joint_estimate(ids, cfg, cal, prior_std_rel=0.0)
    _, cov = _vertical_posterior(cfg, cal)
    assert sec["scales"]["vertical_forward"]["dofs"] == ["heave"]
    for i, n_ in enumerate(ids["heave"].names):
        assert ids["heave"].values[n_] == pytest.approx(theta[i], rel=1e-6, abs=1e-9)
        expected = 0.01 ** 2 + g_mat[i] @ cov[:2, :2] @ g_mat[i]
        assert ids["heave"].std[n_] ** 2 == pytest.approx(expected, rel=1e-4), n_
    assert ids["heave"].signals["joint"]["sensitivity_source"] == "measured (refits)"


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
    assert doc["joint"]["prior_std_rel"] == 0.5
    assert doc["joint"]["scales"]["common_forward"]["measurements"][0]["step"] == "ballast vertical"
    assert doc["calibration"]["steps"]["vertical"]["known_force_n"] == 8.56
    with pytest.raises(ValueError, match="prior_std_rel"):
        joint_estimate({"surge": _ident("surge", [1, 1, 1, 0], [1, 1, 1, 1])}, cfg, None, prior_std_rel=-1.0)


def test_free_decay_disagreement_makes_the_inertia_suspect():
    from hindrax_fit.assessment.verdicts import apply_reference_verdicts, free_decay_reason

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
    from hindrax_fit.assessment.report import references_html
    from hindrax_fit.assessment.verdicts import apply_reference_verdicts

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
    assert "Thrust scales estimated jointly" in page and "line_pull surge 0.8998" in page
    assert "ballast vertical 0.9012" in page
    h = doc["joint"]["scales"]["horizontal_forward"]["value"]
    assert f"{100 * (1 / h - 1):+.1f} %" in page and "curve off" in page
    # free decay beside the self-propelled value, z = 0.0988 / hypot(0.02, 0.0301) = 2.73: suspect
    assert "<td>0.9712</td>" in page and "<td>1.07</td>" in page and "<td>2.73</td>" in page
    assert "<td>suspect</td>" in page
    # the priors with the stated weight
    assert "Empirical priors" in page and "1-sigma 0.5 x its value" in page
    assert page.startswith("<h2>References (independent of the thrust curve)</h2>")
