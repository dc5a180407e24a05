"""Fit what you score (docs/identification.md §7): training segments, validation segments and ``hindrax ident predict
--segment-s`` start each segment from the same initial state, the smoothed measurement at its first tick; a measured
position, whose training fits each segment's initial velocity instead, has both rules scored under the validation's
and reported; a fit on the moving segments only is reported beside the fit on every segment.

The records are synthetic: a first-order response to held force steps (conftest ``synthetic_runs``), with still
stretches where the DOF does not move."""
from __future__ import annotations

import numpy as np
import pytest

from hindrax_fit.fit import fit_core

H = 0.05


def _velocity_record(synthetic_runs, seed: int = 3) -> fit_core.DofRecord:
    """Surge: 150 s of force steps with a still stretch (no force, no motion) of 40 s in the middle."""
    rng = np.random.default_rng(seed)
    n = int(150 / H)
    force = synthetic_runs.steps(rng, n, -30.0, 30.0)
    force[int(55 / H):int(95 / H)] = 0.0
    v = synthetic_runs.first_order(force, 27.0, 12.0, H)
    ch = synthetic_runs.measured_chunk(rng, v, force, H, 0.01, group=0, t0=0.0, force_start=0.0)
    return fit_core.DofRecord("surge", H, "velocity", [ch], "thrust_model", 0.0)


def test_predict_and_cross_validation_start_each_segment_from_the_same_smoothed_measurement(synthetic_runs):
    rec = _velocity_record(synthetic_runs)
    ch = rec.chunks[0]
    terms, timing = fit_core.Terms("linear"), fit_core.Timing(0.0, 0.0)
    train = fit_core.build_segments(rec, terms, timing, fit_core.SEGMENT_S, excited_only=True)
    val = fit_core.build_segments(rec, terms, timing, fit_core.VALIDATION_S, excited_only=False)
    # ident predict --segment-s 10: boundaries every 10 s from the first instant with force and velocity
    pred = fit_core.build_segments(rec, terms, timing, 10.0, excited_only=False, min_fraction=0.0, anchor_s=0.0)
    # --segment-s 7.3 from an anchor between two ticks of a boundary: still the smoothed value at each start tick
    odd = fit_core.build_segments(rec, terms, timing, 7.3, excited_only=False, min_fraction=0.0, anchor_s=2.0)
    for sd in (train, val, pred, odd):
        start = np.rint((sd.span[:, 0] - ch.t0) / H).astype(int)
        assert np.array_equal(sd.v0, ch.v[start])  # the smoothed measurement at the segment's first tick
    # the segments predict scores with --segment-s 10 are the validation's: same starts, same initial states
    assert np.array_equal(pred.span[:, 0], val.span[:, 0]) and np.array_equal(pred.v0, val.v0)
    assert train.m < val.m  # the still stretch is left out of the training only


def test_moving_only_and_all_segment_fits_are_both_reported(synthetic_runs):
    from hindrax_fit.assessment.results import build_document
    from hindrax_fit.fit.fit_any import DofFit, FitResult

    rec = _velocity_record(synthetic_runs)
    res = fit_core.identify_dof(rec, fit_core.CoreOptions(select=False, terms=fit_core.Terms("linear")))
    seg = res.training["segments"]
    moving, every = seg["moving_only"], seg["all_segments"]
    assert seg["used"] == "moving_only" and every["segments"] > moving["segments"]
    # the verdict's parameters are the moving segments' fit; the other fit is there with its own score
    assert [moving["parameters"][n] for n in res.names] == pytest.approx(list(res.theta), rel=1e-12)
    assert moving["cv_nrmse"] == pytest.approx(res.cv["nrmse"], rel=1e-12)
    assert np.isfinite(every["cv_nrmse"]) and set(every["parameters"]) == set(res.names)
    assert every["parameters"]["inertia"] == pytest.approx(27.0, rel=0.1)
    doc = build_document(FitResult({"surge": DofFit("surge", "fitted", {}, res, {})}, {}, "test"), None, ["bag"])
    assert doc["dofs"]["surge"]["training"]["segments"] == seg
    assert doc["dofs"]["surge"]["training"]["initial_state"]["used"] == "smoothed measurement"


def test_a_measured_position_reports_both_initial_state_rules_and_keeps_the_fitted_one(synthetic_runs):
    rng = np.random.default_rng(7)
    n = int(120 / H)
    force = synthetic_runs.steps(rng, n, -20.0, 20.0)
    v = synthetic_runs.first_order(force, 30.0, 15.0, H)
    x = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * H)])
    idx = np.arange(0, n, 4)
    z = x[idx] + rng.normal(0.0, 0.002, idx.size)
    v_smooth = v + 0.01 * np.sin(np.arange(n) * H)  # a smoothed velocity with a slow error
    ch = fit_core.Chunk(force, v_smooth, x, np.gradient(v_smooth, H), idx.astype(float), z, group=0,
                        force_start=0.0)
    rec = fit_core.DofRecord("heave", H, "position", [ch], "thrust_model", 0.0)
    res = fit_core.identify_dof(rec, fit_core.CoreOptions(select=False, terms=fit_core.Terms("linear")))
    part = res.training["initial_state"]
    scores = part["cv_nrmse"]
    # both rules scored under the validation's rule (the smoothed measurement at each segment's start), the
    # verdict's fit the one with a free initial velocity per segment
    assert set(scores) == {"fitted per segment", "smoothed measurement"}
    assert all(np.isfinite(list(scores.values()))) and scores["fitted per segment"] != scores["smoothed measurement"]
    assert part["used"] == "fitted per segment" and res.chosen.free_v0 and res.chosen.fit.v0 is not None
    assert scores["fitted per segment"] == pytest.approx(res.cv["nrmse"], rel=1e-12)
    seg = res.training["segments"]  # fitted on its moving segments: the fit on every segment beside it
    assert seg["used"] == "moving_only" and seg["all_segments"] is not None
