"""Never worse than persistence: a DOF whose velocity is mostly a random walk the force does not
explain gets the verdict "no model beats holding the velocity" and no trusted parameter.

The construction is independent of the code: for a random walk (integrated white noise) the conditional mean of a
later velocity given the initial one IS the initial velocity, so no model of the force can predict it better than
holding it, except by the force-driven part; that part is made 1 % of the velocity's variance here, below the
5 % margin the tool documents (``fit_core.PERSISTENCE_MARGIN``)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from hindrax_tools.commands.ident_fit import format_table

from hindrax_fit.fit import fit_core
from hindrax_fit.assessment.results import assessment, build_document
from hindrax_fit.fit.fit_any import DofFit, FitResult


def _noise_record(syn, seed: int = 3) -> fit_core.DofRecord:
    rng = np.random.default_rng(seed)
    h, n = 0.05, 1600  # 80 s chunks on a 20 Hz grid
    chunks = []
    for c in range(4):
        force = syn.steps(rng, n, -20.0, 20.0)  # a piloted-like force: held steps of 1-4 s, +-20 N
        resp = syn.first_order(force, 40.0, 20.0, h)  # the force's own response (M 40 kg, damping 20 kg/s)
        walk = np.cumsum(rng.normal(0.0, 1.0, n)) * 0.04  # random walk, m/s
        walk -= walk[0]
        v_true = walk + resp * (0.1 * np.std(walk) / np.std(resp))  # response std = 10 % of the walk's
        # 10 Hz measurements with 5 mm/s white noise
        chunks.append(syn.measured_chunk(rng, v_true, force, h, 0.005, group=0, t0=c * (n + 100) * h))
    return fit_core.DofRecord("surge", h, "velocity", chunks, "wrench")


@pytest.fixture(scope="module")
def noise_fit(synthetic_runs):
    return fit_core.identify_dof(_noise_record(synthetic_runs))


def test_a_dof_that_is_mostly_noise_gets_no_model_and_no_trusted_parameter(noise_fit):
    res = noise_fit
    p = res.persistence
    # the scores come from the same held-out samples: the trivial predictors are finite and the model does not
    # beat holding the velocity by the margin
    assert p is not None and math.isfinite(p["nrmse_hold"]) and math.isfinite(p["nrmse_zero"])
    assert not p["beats"] and p["nrmse"] > (1 - fit_core.PERSISTENCE_MARGIN) * p["nrmse_hold"]
    fit = DofFit("surge", "fitted", {"excited": True}, res, {"cross_validation": dict(res.cv)})
    a = assessment(fit, None)
    assert a["verdict"] == "no model beats holding the velocity"
    assert a["parameters"] and all(e["verdict"] != "trusted" for e in a["parameters"].values())
    doc = build_document(FitResult({"surge": fit}, {}, "test"), None, ["noise"])
    e = doc["dofs"]["surge"]
    assert e["verdict"] == "no model beats holding the velocity"
    assert not [n for n, v in e.items() if isinstance(v, dict) and v.get("verdict") == "trusted"]
    rows = {r["terms"]: r for r in e["model_selection"]}
    assert rows["hold the velocity (persistence)"]["cv_nrmse"] == p["nrmse_hold"]
    assert "zero" in rows


def test_persistence_rule_follows_its_definition():
    assert fit_core.persistence({"nrmse": 0.90, "nrmse_hold": 1.0}, 0.05)["beats"]
    assert not fit_core.persistence({"nrmse": 0.96, "nrmse_hold": 1.0}, 0.05)["beats"]
    assert not fit_core.persistence({"nrmse": float("nan"), "nrmse_hold": 1.0}, 0.05)["beats"]


def test_printed_table_has_no_nan_and_the_cv_row_its_noise_floor(noise_fit):
    fit = DofFit("surge", "fitted", {"excited": True}, noise_fit, {"cross_validation": dict(noise_fit.cv)})
    # the measurements carry 5 mm/s of white noise: the floor is that over the held-out velocity's std
    floor = noise_fit.cv["nrmse_floor"]
    assert math.isfinite(floor) and 0.0 < floor < 0.1
    table = format_table(FitResult({"surge": fit}, {}, "test"))
    assert "nan" not in table and f"{floor:11.3f}" in table
    assert "verdict: no model beats holding the velocity" in table
    # a score that cannot be computed (a measured position has no noise floor) prints as "-", not "nan"
    fit.validation["holdout"] = {**noise_fit.cv, "nrmse_floor": float("nan")}
    assert "nan" not in format_table(FitResult({"surge": fit}, {}, "test"))


def test_a_delay_beyond_the_searched_range_is_reported_at_its_edge(synthetic_runs):
    """A surge record whose force acts 0.6 s late, searched up to 0.3 s: the estimate sits at the bound and says
    so; searched up to 1 s it is found inside the range."""
    syn = synthetic_runs
    rng = np.random.default_rng(5)
    h, n, M, D, lag_ticks = 0.05, 1600, 30.0, 25.0, 12
    chunks = []
    for c in range(3):
        force = syn.steps(rng, n, -20.0, 20.0)
        late = np.concatenate([np.full(lag_ticks, force[0]), force[:-lag_ticks]])
        chunks.append(syn.measured_chunk(rng, syn.first_order(late, M, D, h), force, h, 0.003, group=c))
    rec = fit_core.DofRecord("surge", h, "velocity", chunks, "wrench")
    short = fit_core.estimate_timing(rec, fit_core.CoreOptions(max_delay_s=0.3))
    assert short.bound_s == pytest.approx(0.3) and short.at_edge and "edge of its range" in short.edge_note
    full = fit_core.estimate_timing(rec, fit_core.CoreOptions(max_delay_s=1.0))
    assert not full.at_edge and abs(full.delay_s - lag_ticks * h) < 0.1
