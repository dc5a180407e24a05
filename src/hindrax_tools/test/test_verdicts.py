"""Honest intervals and verdicts (identification/assessment/verdicts.py) and the scenario suite command."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy import stats

from hindrax_common.config import default_config_path, load_config
from hindrax_onboard.identification.model.dof_model import (DofIdentification, parameter_names, parameter_units,
                                                        truth_parameters)
from hindrax_fit.assessment.verdicts import (apply_verdicts, assess_dof,
                                                              spread_reasons, thrust_covariance)

pytestmark = pytest.mark.filterwarnings("error::RuntimeWarning")


@pytest.fixture(scope="module")
def cfg():
    return load_config(default_config_path())


def _ident(cfg, dof, rel_std=0.01, bias=None, pool_time_s=90.0, rho=0.05, velocity=None):
    truth = truth_parameters(cfg, dof)
    names = parameter_names(dof)
    values = {n: truth[n] for n in names}
    if bias is not None:
        values["bias"] = bias
    values["added_mass"] = truth["added_mass"]
    std = {n: rel_std * abs(v) + 1e-3 for n, v in values.items()}
    cov = np.diag([std[n] ** 2 for n in names])
    v = np.linspace(-0.4, 0.4, 201) if velocity is None else velocity
    return DofIdentification(dof=dof, names=names, values=values, std=std, ci95={}, method="output-error",
                             residual_dof=5000, equation_error={}, online={}, steady=None, steady_note="",
                             truth=truth, units=parameter_units(dof), pool_time_s=pool_time_s, rls_time_s=None,
                             steady_time_s=None, signals={"covariance": cov, "residual_autocorrelation": rho,
                                                          "velocity": v, "windows": []})


def test_thrust_covariance_by_hand():
    theta = np.array([30.0, 60.0, 2.0, 0.5])
    cov = thrust_covariance("surge", ["inertia", "quadratic_damping", "linear_damping", "bias"], theta, [0.05, 0.10])
    # both directions weigh 1/2: var_i = theta_i^2 (0.25 * 0.10^2 + 0.25 * 0.05^2), fully correlated
    s2 = 0.25 * 0.01 + 0.25 * 0.0025
    assert cov == pytest.approx(s2 * np.outer(theta, theta))
    heave = thrust_covariance("heave", ["inertia", "quadratic_damping_positive", "quadratic_damping_negative"],
                              np.array([40.0, 90.0, 60.0]), [0.05, 0.10])
    assert heave[1, 1] == pytest.approx((0.10 * 90.0) ** 2)
    assert heave[2, 2] == pytest.approx((0.05 * 60.0) ** 2)
    assert heave[1, 2] == pytest.approx(0.0)
    assert heave[0, 0] == pytest.approx(40.0 ** 2 * (0.25 * 0.01 + 0.25 * 0.0025))


def test_interval_uses_thrust_uncertainty_and_segment_dof(cfg):
    r = _ident(cfg, "surge", pool_time_s=90.0)
    a = assess_dof(r, cfg)
    nseg = 9  # 90 s in 10 s segments of the fit core (fit_core.SEGMENT_S)
    assert a["checks"]["segments"] == nseg
    p = a["parameters"]["inertia"]
    assert p["t_dof"] == nseg - 1  # cluster-robust: segments - 1
    rel = cfg.flat["thrusters.thrust_uncertainty_rel"]
    expected_std = math.sqrt(r.std["inertia"] ** 2 + r.values["inertia"] ** 2 * (0.25 * rel[0] ** 2 +
                                                                                0.25 * rel[1] ** 2))
    assert p["std"] == pytest.approx(expected_std)
    tq = stats.t.ppf(0.975, nseg - 1)
    assert p["ci95"][1] - p["value"] == pytest.approx(tq * expected_std)
    assert a["verdict"] == "trusted" and p["reasons"] == []


def test_bias_where_none_is_expected_makes_the_dof_suspect(cfg):
    r = _ident(cfg, "surge", bias=2.0)
    a = assess_dof(r, cfg)
    assert a["verdict"] == "suspect"
    assert any("bias" in x for x in a["reasons"])
    assert all(p["verdict"] == "suspect" for p in a["parameters"].values())
    # heave: the configured net buoyancy is expected, not zero
    h = assess_dof(_ident(cfg, "heave"), cfg)
    assert not any("bias" in x for x in h["reasons"])


def test_a_small_bias_outside_its_interval_is_suspect_alone(cfg):
    """0.05 N of surge bias, far below the damping force at the typical speed, yet 20 std from the expected 0: the
    bias is not trusted (its interval misses the expected force); the other parameters keep their verdicts."""
    r = _ident(cfg, "surge", bias=0.05)
    r.std["bias"] = 0.0025
    cov = r.signals["covariance"]
    cov[r.names.index("bias"), r.names.index("bias")] = 0.0025 ** 2
    a = assess_dof(r, cfg)
    b = a["parameters"]["bias"]
    assert b["verdict"] == "suspect" and any("outside its interval" in x for x in b["reasons"])
    assert not (b["ci95"][0] <= 0.0 <= b["ci95"][1])
    assert a["parameters"]["inertia"]["verdict"] == "trusted" and not a["reasons"]
    # within its interval: trusted
    r.values["bias"] = 0.001
    assert assess_dof(r, cfg)["parameters"]["bias"]["verdict"] == "trusted"


def test_heave_bias_off_the_net_buoyancy_makes_every_dof_suspect(cfg):
    """The net buoyancy is known from mass and volume: a heave bias far from it says the thrust curves are wrong."""
    good = {"surge": _ident(cfg, "surge"), "heave": _ident(cfg, "heave")}
    assert apply_verdicts(good, cfg)["surge"]["verdict"] == "trusted"
    bad = {"surge": _ident(cfg, "surge"), "heave": _ident(cfg, "heave", bias=-0.7)}
    out = apply_verdicts(bad, cfg)
    assert out["heave"]["verdict"] == "suspect"
    assert out["surge"]["verdict"] == "suspect"
    assert any("thrust curves" in x for x in out["surge"]["parameters"]["inertia"]["reasons"])


def test_coloured_residuals_and_wide_intervals_are_suspect(cfg):
    a = assess_dof(_ident(cfg, "sway", rho=0.3), cfg)
    assert any("not white" in x for x in a["reasons"])
    wide = assess_dof(_ident(cfg, "yaw", rel_std=0.3), cfg)
    assert wide["parameters"]["inertia"]["verdict"] == "suspect"
    assert any("too wide" in x for x in wide["parameters"]["inertia"]["reasons"])


def test_direction_inconsistency_of_steady_windows(cfg):
    r = _ident(cfg, "surge")
    kq, kl = r.values["quadratic_damping"], r.values["linear_damping"]
    v = np.array([0.1, 0.2, 0.3, 0.4, -0.1, -0.2, -0.3, -0.4])
    f = kq * np.abs(v) * v + kl * v
    f[v > 0] *= 1.15  # forward runs need 15 % more force than the model: not one model for both directions
    r.signals["windows"] = list(zip(v, f))
    a = assess_dof(r, cfg)
    assert any("steady windows disagree" in x for x in a["reasons"])


def test_apply_verdicts_writes_honest_intervals_once(cfg):
    r = _ident(cfg, "surge")
    fit_std = r.std["inertia"]
    apply_verdicts({"surge": r}, cfg)
    once = r.std["inertia"]
    apply_verdicts({"surge": r}, cfg)
    assert r.std["inertia"] == once > fit_std
    assert r.signals["std_fit"]["inertia"] == fit_std
    assert r.ci95["inertia"][0] < r.values["inertia"] < r.ci95["inertia"][1]


def test_spread_check():
    assert spread_reasons([1.0, 1.1, 0.9], [0.01, 0.01, 0.01])
    assert not spread_reasons([1.0, 1.01, 0.99], [0.01, 0.01, 0.01])
    assert not spread_reasons([1.0, 2.0], [0.01, 0.01])  # too few runs


def test_scenarios_command_writes_table_and_json(tmp_path):
    from hindrax_tools.cli import main
    out = tmp_path / "suite"
    assert main(["ident", "scenarios", "--scenarios", "thrust_0.90", "--seeds", "1", "--dofs", "surge",
                 "--levels", "2", "--out", str(out)]) == 0
    doc = json.loads((out / "scenarios.json").read_text())
    rows = {(r["scenario"], c["parameter"]): c for r in doc["runs"] for c in r["cases"]}
    inertia = rows[("thrust_0.90", "inertia")]
    assert inertia["truth"] == pytest.approx(15.22 + 12.08)
    assert inertia["rel_error"] == pytest.approx((inertia["value"] - inertia["truth"]) / inertia["truth"])
    assert inertia["rel_error"] > 0.05  # 10 % less thrust than the vehicle file believes: inertia reads high
    assert inertia["covered"] == (abs(inertia["value"] - inertia["truth"]) <=
                                  stats.t.ppf(0.975, inertia["t_dof"]) * inertia["std"] + 1e-12)
    assert inertia["verdict"] in ("trusted", "suspect")
    assert set(doc["summary"]) == {"thrust_0.90"}
    assert "| thrust_0.90 |" in (out / "scenarios.md").read_text()
    assert main(["ident", "scenarios", "--scenarios", "nosuch"]) == 1
