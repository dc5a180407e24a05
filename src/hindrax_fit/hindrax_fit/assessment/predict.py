"""Open-loop predictions of an identified model on bags, written so that anyone can score them (``hindrax ident
predict``).

The model is an identification.yaml of ``hindrax ident fit`` (:func:`.results.build_document`): per DOF its chosen
``terms``, the parameters' ``value``, the ``timing`` (input delay and first-order thrust lag) and, for the Coriolis
term, the other fitted DOFs' inertias. The bags are read as ``hindrax ident fit`` reads them
(:func:`..bag_input.any_topics.preprocess_bag`, :func:`..bag_input.any_topics.dof_records`: force held on the 0.05 s
grid, velocity samples at their own times, body FRD) and every DOF of the model is simulated open loop from the recorded
force (:func:`..fit.fit_core.simulate`), re-initialised at the start of each segment from the measured velocity there
(the Savitzky-Golay-smoothed measurement, 0.5 s window, the same initial state as the tool's validation).

Segments:

* ``segment_s`` given: boundaries every ``segment_s`` seconds from the first instant where force and velocity both exist
  (the bag's first continuous chunk), whatever the DOF does; a gap in the data ends a segment and the next starts where
  the data resume; pieces shorter than 10 grid steps (0.5 s) or with fewer than 3 measurements are not predicted;
* ``segment_s`` None: the tool's own rule, the one of its holdout validation (:func:`..fit.fit_any.fit_records`):
  segments of :data:`..fit.fit_core.VALIDATION_S` from each continuous chunk's start, a last part kept when at least
  half a segment long.

Scores (:func:`score`, the definition an independent script reproduces): over the rows whose ``segment`` is >= 0
and whose measurement lies strictly after its segment's start, ``nrmse = sqrt(mean((predicted - measured)^2)) /
std(measured)`` (population std over the same rows); ``nrmse_hold`` with the segment's initial velocity as the
prediction, ``nrmse_zero`` with 0.

CSV per bag and DOF (:func:`write_csv`): a first line ``# ...`` stating the DOF, the velocity, its unit, the body
frame (FRD about base_link) and the time origin; then ``t_s,segment,measured,predicted``; one row per velocity
measurement of the DOF in the continuous data; ``segment`` -1 and ``predicted`` empty where nothing is predicted."""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from hindrax_common.config import DOFS, VehicleConfig

from ..fit import fit_core
from ..bag_input.any_topics import FitInputError, FitOptions, TopicChoice, dof_records, preprocess_bag
from .results import IdentificationFileError, model_spec, validate

__all__ = ["ModelError", "DofModel", "load_model", "Prediction", "predict_bag", "score", "write_csv", "VELOCITY_NAMES"]

#: SNAME velocity name and unit per DOF (body FRD)
VELOCITY_NAMES = {"surge": ("u", "m/s"), "sway": ("v", "m/s"), "heave": ("w", "m/s"), "roll": ("p", "rad/s"),
                  "pitch": ("q", "rad/s"), "yaw": ("r", "rad/s")}


class ModelError(ValueError):
    """The model file cannot be used (one line: the key, what was found, what is needed)."""


@dataclass
class DofModel:
    """One DOF of an identification.yaml: its terms, parameter layout and values (in layout order), timing, the
    other DOFs of its cross terms (velocities), its verdict, the other DOFs whose forces it takes, and the number of
    fitted runs of a per-run bias (0: none; a predicted bag gets the mean bias)."""

    dof: str
    terms: fit_core.Terms
    layout: list
    theta: np.ndarray
    timing: fit_core.Timing
    cross_names: tuple
    verdict: str
    force_names: tuple = ()
    run_count: int = 0


def load_model(doc: dict) -> tuple[dict, np.ndarray]:
    """({dof: :class:`DofModel`}, inertia (6,) of the fitted DOFs, NaN elsewhere) of an identification.yaml
    document, validated (:func:`.results.validate`) and each DOF's model read from its explicit lists
    (:func:`.results.model_spec`). Raises :class:`ModelError` (one line naming the key) for a document that fails
    the schema, has no ``dofs`` or a DOF without ``terms`` (written by an older ``hindrax ident fit``: fit again)."""
    dofs = doc.get("dofs") if isinstance(doc, dict) else None
    if not isinstance(dofs, dict) or not dofs:
        raise ModelError("dofs: missing or empty (an identification.yaml of hindrax ident fit is needed)")
    inertia = np.full(6, np.nan)
    out = {}
    try:
        validate(doc)
        for dof, e in dofs.items():
            if "terms" not in e:
                raise ModelError(f"dofs.{dof}.terms: missing (written by an older hindrax ident fit: fit again)")
            terms, cross, forces, runs, layout, theta = model_spec(dof, e)
            tm = e.get("timing") or {}
            timing = fit_core.Timing(float(tm.get("delay_s", 0.0)), float(tm.get("lag_s", 0.0)), "model file")
            out[dof] = DofModel(dof, terms, layout, theta, timing, cross, str(e.get("verdict", "")), forces, runs)
            inertia[DOFS.index(dof)] = theta[0]
    except IdentificationFileError as exc:
        raise ModelError(str(exc)) from exc
    return out, inertia


@dataclass
class Prediction:
    """One bag and DOF: every measurement (t_s (k,), measured (k,)), its segment (-1: none) and prediction (NaN:
    none), the segments' initial velocities (m,) and start times (m,), and the scores (:func:`score`)."""

    dof: str
    t_s: np.ndarray
    measured: np.ndarray
    segment: np.ndarray
    predicted: np.ndarray
    v0: np.ndarray
    start_s: np.ndarray
    scores: dict


def score(segment: np.ndarray, measured: np.ndarray, predicted: np.ndarray, v0: np.ndarray) -> dict:
    """{nrmse, nrmse_hold, nrmse_zero, samples, segments} over the rows with ``segment`` >= 0 and a finite
    prediction (module docstring); NaN scores with fewer than 2 rows."""
    seg = np.asarray(segment)
    ok = (seg >= 0) & np.isfinite(predicted) & np.isfinite(measured)
    z, p = np.asarray(measured, dtype=float)[ok], np.asarray(predicted, dtype=float)[ok]
    if z.size < 2:
        return {"nrmse": math.nan, "nrmse_hold": math.nan, "nrmse_zero": math.nan, "samples": int(z.size),
                "segments": 0}
    sd = float(np.std(z)) or 1.0
    hold = np.asarray(v0, dtype=float)[seg[ok]]

    def rms(e):
        return float(np.sqrt(np.mean(e ** 2)))

    return {"nrmse": rms(p - z) / sd, "nrmse_hold": rms(hold - z) / sd, "nrmse_zero": rms(z) / sd,
            "samples": int(z.size), "segments": int(np.unique(seg[ok]).size)}


def predict_bag(path: str | Path, models: dict, inertia: np.ndarray, choice: TopicChoice = TopicChoice(),
                cfg: VehicleConfig | None = None, segment_s: float | None = None,
                opts: FitOptions = FitOptions()) -> dict:
    """{dof: :class:`Prediction`} of every DOF of ``models`` (:func:`load_model`) on the bag ``path`` (module
    docstring). Raises :class:`..bag_input.any_topics.FitInputError` (topics, frames, a ThrusterPwm force without
    ``cfg``) or ``BagError``."""
    pre = preprocess_bag(path, choice, cfg, opts)
    if not pre.stretches:
        raise FitInputError(f"{path}: no continuous stretch of force and velocity")
    anchor = float(pre.stretches[0].t[0])
    out = {}
    for dof, m in models.items():
        recs = dof_records([pre], [dof], opts, [dof, *m.cross_names], m.force_names)
        rec = recs[dof]
        rec.run_count, rec.runs_known = m.run_count, False  # a bag to predict is not a fitted run: the mean bias
        # every measurement of the DOF in the continuous data, in record time
        t_all = np.concatenate([c.t0 + c.sample_pos * rec.h for c in rec.chunks]) if rec.chunks else np.zeros(0)
        z_all = np.concatenate([c.sample_z for c in rec.chunks]) if rec.chunks else np.zeros(0)
        order = np.argsort(t_all, kind="stable")
        t_all, z_all = t_all[order], z_all[order]
        seg_all = np.full(t_all.size, -1)
        pred_all = np.full(t_all.size, np.nan)
        v0 = start = np.zeros(0)
        if rec.chunks:
            seconds = fit_core.VALIDATION_S if segment_s is None else float(segment_s)
            try:
                sd = fit_core.build_segments(rec, m.terms, m.timing, seconds, inertia, excited_only=False,
                                             min_fraction=0.5 if segment_s is None else 0.0,
                                             anchor_s=None if segment_s is None else anchor)
            except fit_core.EstimationError:
                sd = None
            if sd is not None:
                V = fit_core.predict_validation(sd, m.layout, m.theta)
                p = fit_core.at_samples(sd, V)
                t_seg = sd.span[sd.s_seg, 0] + (sd.s_j + sd.s_a) * sd.h
                # the segment rows are measurements of t_all: match them by time
                idx = np.searchsorted(t_all, t_seg - 1e-6)
                idx = np.clip(idx, 0, max(t_all.size - 1, 0))
                hit = np.abs(t_all[idx] - t_seg) < 1e-6
                seg_all[idx[hit]] = sd.s_seg[hit]
                pred_all[idx[hit]] = p[hit]
                v0, start = sd.v0, sd.span[:, 0]
        out[dof] = Prediction(dof, t_all, z_all, seg_all, pred_all, v0, start, score(seg_all, z_all, pred_all, v0))
    return out


def write_csv(path: str | Path, pred: Prediction, bag: str, rule: str) -> Path:
    """Write one :class:`Prediction` as CSV (module docstring); returns the path."""
    path = Path(path)
    name, unit = VELOCITY_NAMES[pred.dof]
    lines = [f"# {pred.dof} velocity {name} in {unit}, body frame FRD (x forward, y right, z down) about base_link; "
             f"t_s in s from the first force message of {bag}; segments: {rule}; segment -1 and an empty predicted: "
             "not predicted", "t_s,segment,measured,predicted"]
    for t, s, z, p in zip(pred.t_s, pred.segment, pred.measured, pred.predicted):
        lines.append(f"{t:.4f},{int(s)},{z:.6g}," + (f"{p:.6g}" if math.isfinite(p) else ""))
    path.write_text("\n".join(lines) + "\n")
    return path


def rule_text(segment_s: float | None) -> str:
    """The segment rule in words (CSV header, printed table)."""
    if segment_s is None:
        return (f"the tool's rule: {fit_core.VALIDATION_S:g} s from each continuous stretch's start, a last part of "
                "at least half a segment kept")
    return f"every {segment_s:g} s from the first instant with force and velocity, a gap ends a segment"


def dofs_of(models: dict) -> Sequence[str]:
    """The model's DOFs in the standard order."""
    return [d for d in DOFS if d in models]
