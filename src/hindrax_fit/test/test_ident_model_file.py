"""The model file is a contract: whatever ``hindrax ident fit`` writes
(:func:`~hindrax_fit.assessment.results.build_document`, validated on write), ``hindrax ident predict`` reads
(:func:`~hindrax_fit.assessment.predict.load_model`, validated on read) and predicts with exactly as the fit's
in-memory model does.

The records are built here from their definition (conftest ``synthetic_runs``): a first-order DOF driven by its own
force, other DOFs' velocities (cross terms), other DOFs' forces and a bias per run; the fit core chooses nothing (its
terms are given), so every term set is written."""
from __future__ import annotations

import dataclasses
import types

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hindrax_common.config import DOFS
from hindrax_fit.assessment.predict import ModelError, load_model
from hindrax_fit.assessment.results import (IdentificationFileError, build_document,
                                                             write_identification)
from hindrax_fit.fit import fit_core
from hindrax_fit.fit.fit_any import fit_records

H = 0.05


def _fit(syn, seed: int, dof: str, terms: fit_core.Terms, cross: tuple, forces: tuple, runs: int, ticks: int,
         quiet_last: bool = False):
    """(fit result of ``fit_records``, the record) of ``max(runs, 1)`` runs of ``ticks`` ticks each; ``quiet_last``:
    the last run's forces and velocities a twentieth (its velocity std below the 0.03 m/s a held-out fold needs)."""
    rng = np.random.default_rng(seed)
    chunks = []
    for g in range(max(runs, 1)):
        k = 0.05 if quiet_last and g == max(runs, 1) - 1 else 1.0
        own = syn.steps(rng, ticks, -20.0 * k, 20.0 * k)
        cv = np.column_stack([syn.steps(rng, ticks, -0.3 * k, 0.3 * k) for _ in cross]) if cross else None
        cf = np.column_stack([syn.steps(rng, ticks, -20.0 * k, 20.0 * k) for _ in forces]) if forces else None
        force = own + (0.2 * cf.sum(axis=1) if forces else 0.0) - (3.0 * cv.sum(axis=1) if cross else 0.0)
        v = syn.first_order(force, 30.0, 25.0, H, offset=k * (float(g) - 0.5))
        chunks.append(syn.measured_chunk(rng, v, own, H, 0.005, group=g, t0=100.0 * g, cross=cv, cross_force=cf,
                                         restoring=np.zeros(ticks) if dof in ("roll", "pitch") else None,
                                         shortfall=np.zeros(ticks) if terms.saturation else None))
    rec = fit_core.DofRecord(dof, H, "velocity", chunks, "thrust_model", 0.1, cross_names=cross,
                             force_names=forces, run_count=runs, terms=terms)
    bags = types.SimpleNamespace(statuses={}, excitation={dof: {}}, dofs=[dof], notes={}, records={dof: rec},
                                 holdout_records={})
    res = fit_records(bags, fit_core.CoreOptions(folds=3), "synthetic")
    assert res.dofs[dof].status == "fitted", res.dofs[dof].reason
    return res, rec


def _written_and_read(res, path):
    """identification.yaml written as ``hindrax ident fit`` writes it and read as ``hindrax ident predict`` reads it:
    (the document, {dof: DofModel}, inertia)."""
    doc = build_document(res, None, [f"run{k}" for k in range(3)])
    write_identification(path, doc)
    read = yaml.safe_load(path.read_text())
    return read, *load_model(read)


def _predictions(rec, terms, timing, cross, forces, runs, layout, theta, inertia):
    """Open-loop predictions of a model on ``rec`` as ``hindrax ident predict`` makes them (a bag that is not a
    fitted run: the mean bias; every 10 s segment)."""
    r = dataclasses.replace(rec, cross_names=cross, force_names=forces, run_count=runs, runs_known=False, terms=None)
    sd = fit_core.build_segments(r, terms, timing, fit_core.VALIDATION_S, inertia, excited_only=False)
    return fit_core.predict_validation(sd, layout, theta)


def _assert_same_model(res, rec, models, inertia):
    for dof, fit in res.dofs.items():
        c, m = fit.core, models[dof]
        assert m.terms == c.terms and m.layout == c.chosen.layout
        assert m.cross_names == rec.cross_names[:len(m.cross_names)] and (m.cross_names == rec.cross_names
                                                                            or not c.terms.cross)
        assert m.force_names == (rec.force_names if c.terms.cross_force else ())
        assert np.array_equal(m.theta, c.theta)  # YAML floats round-trip exactly
        assert (m.timing.delay_s, m.timing.lag_s) == (c.timing.delay_s, c.timing.lag_s)
        mem = _predictions(rec, c.terms, c.timing, rec.cross_names, rec.force_names, rec.run_count, c.chosen.layout,
                           c.theta, fit_core.inertia_vector(res_cores(res)))
        got = _predictions(rec, m.terms, m.timing, m.cross_names, m.force_names, m.run_count, m.layout, m.theta,
                           inertia)
        assert np.all(np.isfinite(mem)) and np.array_equal(got, mem)


def res_cores(res) -> dict:
    return {d: f.core for d, f in res.dofs.items()}


def test_cross_terms_with_a_fold_note_go_from_fit_to_predict(synthetic_runs, tmp_path):
    """The reported combination: a DOF with cross terms and a cross-validation note (here: the last of three runs
    barely moves, so its fold is "not excited") - the old reader took ``cross_validation_notes`` for a cross term."""
    terms = fit_core.Terms(cross=True, cross_force=True, run_bias=True)
    res, rec = _fit(synthetic_runs, 3, "sway", terms, ("surge", "yaw"), ("heave",), 3, 500, quiet_last=True)
    assert any("not excited" in n for n in res.dofs["sway"].core.fold_notes)  # the combination that broke it
    doc, models, inertia = _written_and_read(res, tmp_path / "identification.yaml")
    assert "cross_validation_notes" in doc["dofs"]["sway"]
    assert doc["dofs"]["sway"]["cross_dofs"] == ["surge", "yaw"] and doc["dofs"]["sway"]["force_dofs"] == ["heave"]
    _assert_same_model(res, rec, models, inertia)
    # an older file, without the explicit lists, still reads as the same model
    old = {**doc, "dofs": {"sway": {k: v for k, v in doc["dofs"]["sway"].items()
                                    if k not in ("cross_dofs", "force_dofs", "bias_runs", "parameters")}}}
    old_models, _ = load_model(old)
    assert old_models["sway"].layout == models["sway"].layout
    assert np.array_equal(old_models["sway"].theta, models["sway"].theta)
    # validated on write and on read: lists that disagree with the terms are refused, naming the key
    bad = {**doc, "dofs": {"sway": {**doc["dofs"]["sway"], "cross_dofs": ["surge"]}}}
    with pytest.raises(IdentificationFileError, match=r"dofs\.sway\.parameters"):
        write_identification(tmp_path / "bad.yaml", bad)
    with pytest.raises(ModelError, match=r"dofs\.sway\.parameters"):
        load_model(bad)


@st.composite
def _models(draw):
    dof = draw(st.sampled_from(DOFS))
    others = [d for d in DOFS if d != dof]
    terms = fit_core.Terms(draw(st.sampled_from(["both", "linear", "quadratic"])), draw(st.booleans()),
                           draw(st.booleans()), draw(st.booleans()), draw(st.booleans()), draw(st.booleans()),
                           draw(st.booleans()), draw(st.booleans()))
    cross = tuple(draw(st.lists(st.sampled_from(others), max_size=2, unique=True)))
    forces = tuple(draw(st.lists(st.sampled_from(others), max_size=2, unique=True)))
    runs = draw(st.integers(0, 3))
    notes = draw(st.lists(st.text(min_size=1, max_size=20), max_size=2))
    return dof, terms, cross, forces, runs, notes, draw(st.sampled_from([250, 500])), draw(st.integers(0, 99))


@settings(max_examples=12, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(_models())
def test_whatever_fit_writes_predict_reads_and_predicts_exactly(synthetic_runs, tmp_path, model):
    dof, terms, cross, forces, runs, notes, ticks, seed = model
    res, rec = _fit(synthetic_runs, seed, dof, terms, cross, forces, runs, ticks)
    res.dofs[dof].core.fold_notes.extend(notes)  # what a fold can say (any text) is written beside the model
    _doc, models, inertia = _written_and_read(res, tmp_path / "identification.yaml")
    _assert_same_model(res, rec, models, inertia)
