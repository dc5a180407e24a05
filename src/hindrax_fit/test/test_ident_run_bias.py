"""Per-run bias: a constant force that differs between runs (tether lay, trim), estimated and reported per run; a
candidate that cross-validation on whole held-out runs (new runs: the mean bias) does not choose for itself.

Built here from its definition: three runs of one first-order surge model, each with its own constant force
(+2, -1.5, +0.5 N), integrated exactly for held forces; one bias for all runs cannot predict all three."""
from __future__ import annotations

import numpy as np

from hindrax_fit.fit import fit_core
from hindrax_fit.assessment.results import build_document
from hindrax_fit.fit.fit_any import DofFit, FitResult

BIASES = (2.0, -1.5, 0.5)


def _record(syn) -> fit_core.DofRecord:
    rng = np.random.default_rng(21)
    h, n, M, D = 0.05, 2000, 30.0, 25.0
    chunks = []
    for run, b in enumerate(BIASES):
        own = syn.steps(rng, n, -15.0, 15.0)
        v = syn.first_order(own, M, D, h, offset=b)  # M v' = F - b_run - D v (the bias opposes the force)
        chunks.append(syn.measured_chunk(rng, v, own, h, 0.005, group=run, t0=0.0))
    return fit_core.DofRecord("surge", h, "velocity", chunks, "thrust_model", 0.0, run_count=len(BIASES))


def test_a_bias_that_differs_between_runs_is_estimated_and_reported_per_run(synthetic_runs):
    rec = _record(synthetic_runs)
    res = fit_core.identify_dof(rec, fit_core.CoreOptions(select=False, terms=fit_core.Terms("linear",
                                                                                             run_bias=True)))
    assert res.terms.run_bias, res.terms.label
    # cross-validation holds out whole runs and predicts each with the mean bias, as a new run is predicted: the
    # per-run bias cannot lower that score, and selection does not choose it for it
    sel = fit_core.identify_dof(rec)
    assert not sel.terms.run_bias
    fit = DofFit("surge", "fitted", {"excited": True}, res, {"cross_validation": dict(res.cv)})
    doc = build_document(FitResult({"surge": fit}, {}, "test"), None, ["run0", "run1", "run2"])
    per_run = doc["dofs"]["surge"]["bias_per_run"]
    assert [r["run"] for r in per_run] == ["run0", "run1", "run2"]
    for r, want in zip(per_run, BIASES):
        assert abs(r["bias"] - want) < 0.15, per_run
        assert r["std"] > 0 and r["unit"] == "N"
