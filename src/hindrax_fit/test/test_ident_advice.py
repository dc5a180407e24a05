"""Numbers people can use: advice in pool units (runs of a named kind, a speed range,
minutes), never above a pool day nor nothing; a parameter at a bound says so instead of an interval; a parameter
no amount of the data's own manoeuvre can fix names the kind of run that would."""
from __future__ import annotations

import math

import numpy as np

from hindrax_fit.assessment.verdicts import FitEvidence, assess, data_advice, format_advice

POOL_DAY_S = 8 * 3600.0


def _signals(seed: int = 1):
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 300.0, 0.05)
    v = 0.4 * np.sin(2 * np.pi * t / 20.0) + rng.normal(0, 0.01, t.size)
    a = np.gradient(v, 0.05)
    f = 30.0 * v + 20.0 * a
    return v, a, f


def test_advice_is_whole_runs_within_a_pool_day_and_never_nothing():
    v, a, f = _signals()
    names = ["inertia", "quadratic_damping", "linear_damping", "bias", "restoring", "reverse_thrust_gain",
             "cross_sway", "quadratic_damping_negative"]
    for name in names:
        for rel in (1e-3, 0.1, 0.3, 1.0, 10.0, 1e3, 1e9):  # 95 % half-width relative to the value
            for at_bound in (False, True):
                adv = data_advice("heave" if name.endswith("negative") else "surge", name, 2.0, 2.0 * rel, v, a, f,
                                  0.05, at_bound)
                line = format_advice(name, adv)
                assert 0 < adv["seconds_more"] <= POOL_DAY_S, (name, rel, adv)
                assert adv["runs"] >= 1 and adv["minutes"] >= 1 and adv["minutes"] * 60 <= POOL_DAY_S
                assert adv["runs"] * adv["run_s"] == adv["seconds_more"]
                lo, hi, unit = adv["speed_range"]
                assert hi > lo >= 0 and unit == "m/s"
                assert " 0 s" not in line and "nan" not in line and f"{adv['runs']} {adv['run_kind']}" in line
                assert "min of pool time" in line


def test_a_parameter_no_amount_of_its_manoeuvre_fixes_names_another_kind_of_run():
    v, a, f = _signals()
    # a half-width 1000 x the value: (1000 / 0.25)^2 times the data's seconds is years of the same runs
    adv = data_advice("surge", "quadratic_damping", 2.0, 2000.0, v, a, f, 0.05)
    assert adv["feasible"] is False
    assert "faster than the data's top speed" in adv["manoeuvre"]
    lo, hi, _unit = adv["speed_range"]
    top = float(np.percentile(np.abs(v), 98))
    assert math.isclose(lo, round(top, 3), abs_tol=2e-3) and hi > lo  # beyond the speeds in the data
    assert "cannot fix it within a pool day" in format_advice("quadratic_damping", adv)
    # a reverse gain with no reverse command in the data: reverse-command runs
    adv = data_advice("surge", "reverse_thrust_gain", 1.0, 5.0, v, a, np.abs(f), 0.05)
    assert adv["feasible"] is False and adv["run_kind"] == "reverse-command runs"


def test_a_parameter_at_a_bound_says_so_and_gets_no_width_verdict():
    v, a, f = _signals()
    names = ["inertia", "linear_damping", "bias", "reverse_thrust_gain"]
    ev = FitEvidence(dof="surge", names=names, theta=np.array([20.0, 30.0, 0.0, 2.0]),
                     cov=np.diag([0.04, 0.09, 0.0001, 1.02e3 ** 2]), t_dof=10,
                     units={"inertia": "kg", "linear_damping": "kg/s", "bias": "N", "reverse_thrust_gain": "1"},
                     velocity=v, acceleration=a, force=f, h=0.05,
                     lower_bounds=[1e-6, 0.0, -np.inf, 0.2], upper_bounds=[np.inf, np.inf, np.inf, 2.0])
    out = assess(ev, (0.05, 0.10))
    g = out["parameters"]["reverse_thrust_gain"]
    assert g["at_bound"] == 2.0 and g["verdict"] == "suspect"
    assert any("upper bound 2" in r and "no interval" in r for r in g["reasons"])
    assert not any("%" in r for r in g["reasons"])  # no "+-109858 %" width of a bound value
    assert "at_bound" not in out["parameters"]["inertia"] and "at_bound" not in out["parameters"]["linear_damping"]


def test_a_bias_near_zero_is_judged_against_the_damping_force_not_its_value():
    v, a, f = _signals()
    # a bias of 0.001 N with a +-0.5 N interval against a 2 N damping force: a few more slow runs, not "never"
    adv = data_advice("surge", "bias", 0.001, 0.5, v, a, f, 0.05, scale=2.0)
    assert adv["feasible"] is True and adv["run_kind"] == "holds and slow runs both ways"
    assert adv["seconds_more"] < POOL_DAY_S / 4


def test_parameters_suspect_for_a_dof_wide_reason_alone_are_told_which_runs_fix_them():
    """Issue 74.3: a pool day ended with seven heave parameters suspect for DOF-wide reasons (narrow intervals)
    and no advice; each now names runs of a kind and the pool time."""
    v, a, f = _signals()
    names = ["inertia", "linear_damping", "bias"]
    ev = FitEvidence(dof="surge", names=names, theta=np.array([20.0, 30.0, 0.0]),
                     cov=np.diag([0.04, 0.09, 0.0001]), t_dof=10, units={"inertia": "kg", "linear_damping": "kg/s",
                                                                          "bias": "N"},
                     velocity=v, acceleration=a, force=f, h=0.05, residual_rho=0.9)
    out = assess(ev, (0.05, 0.10))
    assert out["verdict"] == "suspect" and any("residuals not white" in r for r in out["reasons"])
    for name in names:
        p = out["parameters"][name]
        assert p["verdict"] == "suspect" and p["advice"]["runs"] >= 1, p
        assert "min of pool time" in format_advice(name, p["advice"])
