"""The fit of bags of any topics: the fit core over the records of the any-topics reader, validated.

The reading is :func:`..bag_input.reader.read_any_topics`; everything after it is the fit core shared with the campaign
(:mod:`.fit_core`, docs/identification.md §7). Several bags are fitted jointly (their segments pooled; clusters never
span two bags). The verdicts and identification.yaml are :mod:`..assessment.results`'
(:func:`..assessment.results.build_document`). Validation: the core's cross-validation and ``holdout`` bags, both
measured by :func:`.fit_core.validation_measures` (``nrmse``, ``nrmse_hold``, ``nrmse_zero``)."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hindrax_common.config import DOFS

from hindrax_onboard.estimation.least_squares import EstimationError
from . import fit_core

__all__ = ["DofFit", "FitResult", "fit_records"]


@dataclass
class DofFit:
    """One DOF: status "fitted" | "not excited" | "failed"; excitation numbers; the core's result
    (:class:`.fit_core.DofResult`: names, theta, std, ci95, chosen terms, candidates, timing, intervals); validation
    {cross_validation, holdout}; plot arrays of the validation data for the report; reason when not fitted."""

    dof: str
    status: str
    excitation: dict
    core: fit_core.DofResult | None = None
    validation: dict = field(default_factory=dict)
    plot: dict = field(default_factory=dict)
    reason: str = ""

    @property
    def folds(self) -> list:
        if self.core is None:
            return []
        return [t for t in self.core.fold_theta if np.all(np.isfinite(t))]


@dataclass
class FitResult:
    """Per-DOF fits, the preprocessing notes and the validation design."""

    dofs: dict
    preprocessing: dict
    design: str


def fit_records(bags, opts: fit_core.CoreOptions, design: str) -> FitResult:
    """Fit the records of the any-topics reader (``bags``: :class:`..bag_input.reader.BagRecords`) with the fit core
    (module docstring), the core's options ``opts``; ``design`` describes the validation. A DOF the reader could not
    record keeps its status; a DOF the core cannot fit is "failed" with the core's message."""
    out = {d: DofFit(d, st, bags.excitation[d], reason=why) for d, (st, why) in bags.statuses.items()}
    todo = [d for d in bags.dofs if d not in out]
    pre_notes = dict(bags.notes)
    results, errors = fit_core.identify_dofs(bags.records, opts)
    inertia = fit_core.inertia_vector(results)
    pre_notes["timing"] = {d: {"delay_s": round(r.timing.delay_s, 4), "lag_s": round(r.timing.lag_s, 4),
                               "source": r.timing.source,
                               **({"searched_up_to_s": round(r.timing.bound_s, 4), "bound": r.timing.bound_why,
                                   "at_edge": r.timing.at_edge} if r.timing.bound_s is not None else {})}
                           for d, r in results.items()}
    pre_notes["delay_method"] = ("per DOF: a commanded wrench's delay (force shift) "
                                 f"(0 up to the smallest of {opts.max_delay_s:g} s, a tenth of the segment and a "
                                 "quarter period of the excitation bandwidth: fit_core.resolvable_delay) "
                                 "and first-order lag with the smallest cross-validated output error of the 1-DOF "
                                 "model over a grid of both (fit_core.estimate_timing); a thrust-model force keeps "
                                 "thrusters.time_constant_s and esc.output_latency_s")
    pre_notes["coupling"] = ("Coriolis and centripetal force of the diagonal inertias (Fossen 2011) from the "
                             "interpolated velocities, with the fitted inertias (" + ", ".join(
                                 f"{d} {inertia[DOFS.index(d)]:.4g}" for d in results) + "): a candidate term, "
                             "chosen by cross-validation")
    hrecs = bags.holdout_records
    for dof in todo:
        e = bags.excitation[dof]
        if dof in errors:
            out[dof] = DofFit(dof, "failed", e, reason=errors[dof])
            continue
        r = results[dof]
        fit = DofFit(dof, "fitted", e, r)
        fit.validation["cross_validation"] = dict(r.cv)
        cand = r.chosen
        if cand.cv.get("samples", 0):
            fit.plot = {"data": "cross-validation", "measured": cand.val.v_s, "segments": cand.val,
                        "predicted": fit_core.predict_validation(cand.val, cand.layout, r.theta)}
        if dof in hrecs and hrecs[dof].chunks:
            try:  # every segment of validation_s with measurements, moving or not
                sd = fit_core.build_segments(hrecs[dof], r.terms, r.timing, opts.validation_s,
                                             inertia, excited_only=False)
                vp = fit_core.predict_validation(sd, cand.layout, r.theta)
                fit.validation["holdout"] = fit_core.validation_measures(sd, vp)
                fit.plot = {"data": "holdout", "measured": sd.v_s, "predicted": vp, "segments": sd}
            except EstimationError as exc:
                fit.validation["holdout_note"] = str(exc)
        out[dof] = fit
    out = {d: out[d] for d in bags.dofs}
    return FitResult(out, pre_notes, design)


