"""Honest intervals and a verdict for every identified parameter, added after the fit (the fit is not touched).

:func:`apply_verdicts` takes the :class:`~..fit.dof_model.DofIdentification` of each DOF and the vehicle configuration
and

1. **adds the force model's uncertainty** to the fit covariance. Every parameter of the self-propelled model
   ``tau = M nu_dot + D(nu) nu + b`` scales with the thrust: thrust s times the curve's gives parameters s times
   the identified ones ([Hindrax-Drag] eq. 1 curve and eq. 9 allocation feed tau). With independent
   relative thrust errors s_neg, s_pos of the two rotation directions (1-sigma ``thrusters.thrust_uncertainty_rel``
   = [negative, positive], default [0.05, 0.10], see ros_ws/config/hindrax.yaml for why), parameter i moves by
   ``theta_i (a_i ds_pos + b_i ds_neg)`` and ``cov += sum_k sigma_k^2 (theta o w_k)(theta o w_k)^T``. The weights:
   surge, sway, yaw, roll and pitch use two thrusters in each direction of rotation for either sign of the
   command (55-degree layout, [Hindrax-Drag] Fig. 5), so a = b = 1/2; heave moves down on positive and up on negative
   thrust: ``*_positive`` (and the bias holding the net buoyancy, a downward force) a = 1, ``*_negative`` b = 1,
   inertia a = b = 1/2. When a thrust-curve fit covariance is known it replaces the declared value: the vehicle
   file's ``thrusters.thrust_fit_uncertainty_rel`` (written by ``hindrax ident thruster-fit --write``: the
   thrust-weighted relative std of the fitted curve over the pulse widths of the bollard-pull data,
   :meth:`~hindrax_onboard.estimation.thruster_fit.CubicFit.relative_std`);
2. **uses degrees of freedom that match the independent information**: the output-error residuals are correlated
   inside a segment and between neighbouring segments, so the fit core's covariance is cluster-robust
   (docs/identification.md §7, step 5) and the 95 % interval uses the Student t quantile with its (clusters - 1)
   degrees of freedom ([Cameron-Miller2015] §VI), not (samples - parameters);
3. **gives each parameter ``verdict: trusted | suspect`` and the reasons**, from the checks a pool engineer makes:

   * ``bias``: the constant force differs significantly from the one expected (0; heave: the configured net
     buoyancy): something the model does not have is pushing (current, tether, thrust offset). DOF-wide when the
     difference is more than :data:`BIAS_MIN_REL` of the damping force at the typical speed, else the bias alone (a
     small bias outside its interval is a miss whatever its size).
   * ``methods``: the steady-state fit ([Hindrax-Drag] eqs. 2-8) disagrees with the reported quadratic damping by more
     than :data:`METHODS_MAX` and beyond 3 combined standard deviations: the model does not explain the transients and
     the steady states with the same numbers (lag, latency, coupling). DOF-wide. (The equation-error fit is not used:
     its inertia is biased low by the noise of the differentiated velocity even when nothing is wrong.)
   * ``direction``: the steady-window misfits (relative to the model force) of the two directions of motion differ
     by more than :data:`DIRECTION_MAX` and beyond their scatter (z > 4) (heave: up/down; others: forward/backward),
     a level-to-level inconsistency. DOF-wide.
   * ``whiteness``: the lag-1 autocorrelation of the output-error residuals between consecutive samples is above
     :data:`WHITENESS_MAX` (the model leaves a slow, systematic misfit: a thrust lag or latency the vehicle file does
     not have, a late DVL). DOF-wide. A measured position (heave's depth) is judged by the independence of its residuals
     from the input instead (:data:`INDEPENDENCE_Z`, :func:`~..fit.fit_core.input_correlation`): its residual is the
     double integral of every force the model does not have, so a few tenths of a newton of disturbance make consecutive
     depth samples correlated (0.86 on the README's pool day, whose intervals all hold the truth) whatever the model;
     for an output-error model the residuals' colour is the disturbance's, and the dynamics are judged by whether the
     residuals follow the input ([Ljung1999] §16.6).
   * ``thrust`` (across DOFs, :func:`apply_verdicts`): heave's bias is the force that holds the vehicle at depth,
     the net buoyancy (rho V - m) g known from the vehicle's mass and volume. When the identified heave bias
     differs from it significantly, the thrust curves are wrong, and every DOF identified with them is suspect
     (a thrust error in one direction cannot be seen in surge, sway or yaw, which use both directions at once).
   * ``width``: the 95 % half-width is too wide to design a controller from: above :data:`WIDTH_MAX`
     of the value (inertia, quadratic damping, restoring, reverse gain), or for linear damping and
     bias of the damping force at the typical speed of the test (the 75th percentile of |velocity|).
   * ``spread`` (scenario suite only, :func:`spread_reasons`): over repeated campaigns the estimates scatter more
     than their own intervals say.
   * ``free decay`` (roll and pitch inertia, :func:`apply_reference_verdicts`): the rigid + added inertia from a free
     decay (campaign ``tilt_decay`` step or ``hindrax ident free-decay``; restoring stiffness from an inclining
     test, independent of the thrust curve) differs from the self-propelled inertia by more than
     :data:`REFERENCE_Z_MAX` combined standard deviations (docs/identification.md §6.4).

All quantities SI, the parameters and units of :func:`~..fit.dof_model.parameter_names`."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np
from scipy import stats

from hindrax_common.config import ROTATIONAL_DOFS, VehicleConfig

from hindrax_onboard.vehicle.uncertainty import declared_rel
from hindrax_onboard.identification.model.dof_model import core_index, thrust_covariance, thrust_weights
from ..fit.fit_core import NO_MODEL_VERDICT, PERSISTENCE_MARGIN, SEGMENT_S, persistence

__all__ = ["REFERENCE_Z_MAX", "free_decay_reason", "apply_reference_verdicts",
           "WHITENESS_MAX", "INDEPENDENCE_Z", "WIDTH_MAX", "thrust_weights", "thrust_covariance",
           "FitEvidence", "core_signals", "core_evidence", "model_selection",
           "no_model_line", "NRMSE_MAX", "BIAS_MIN_REL", "assess", "with_added_mass", "assess_dof",
           "apply_verdicts", "thrust_curve_check", "spread_reasons", "data_advice", "format_advice", "ADVICE_TARGET",
           "POOL_DAY_S", "RUN_KINDS"]

#: Residual lag-1 autocorrelation above which the fit is not trusted.
WHITENESS_MAX = 0.2
#: Largest z of a measured position's residual-input cross-correlation a trusted fit may leave
#: (:func:`~..fit.fit_core.input_correlation`): the 99 % bound of each lag, as Ljung's residual test draws it.
INDEPENDENCE_Z = 2.58
#: Relative difference of the steady-state and transient quadratic damping flagged (with |z| > 3).
METHODS_MAX = 0.05
#: Difference of the mean relative steady-window misfit between the two directions of motion flagged (with z > 4).
DIRECTION_MAX = 0.05
#: Relative 95 % half-width above which a parameter is too uncertain for controller design.
WIDTH_MAX = 0.3


@dataclass
class FitEvidence:
    """What the verdicts of one DOF's fit are made from (:func:`assess`), whichever reader made the record.

    dof; names (p,) the fit's parameters (:func:`~..fit.dof_model.parameter_names`, or the fit core's chosen terms);
    theta (p,) their values (after the empirical priors, :mod:`..fit.posterior`); cov (p, p) their covariance without
    the thrust-curve term (the fit core's cluster-robust covariance after the priors; with ``thrust_in_covariance`` the
    calibrated joint estimate's, which already holds the thrust scales); t_dof: the interval's degrees of freedom (the
    fit core's clusters - 1); units {name: unit}; velocity, acceleration, force (n,): the smoothed velocity,
    acceleration and input force at the fitted ticks, ``h`` s apart (typical speed, :func:`data_advice`); lower_bounds,
    upper_bounds (p,) the optimiser's bounds (0: a physical bound; +-inf or None: none) or None; fold_theta (K, p) the
    cross-validation folds' estimates or None; cv_nrmse: the chosen model's cross-validated prediction nrmse or None;
    residual_rho: lag-1 autocorrelation of consecutive output-error residuals or None; input_corr: the residuals'
    correlation with the input (:func:`~..fit.fit_core.input_correlation`, a measured position) or None; steady {name:
    (value, std)} of the steady-state method ([Hindrax-Drag] eqs. 2-8) or None; windows [(mean velocity, mean force)] of
    the steady windows; expected_bias: the constant force expected (0; heave the configured net buoyancy, N) or None
    when unknown (heave without a vehicle file); fit_std {name: std} of the fit alone when ``thrust_in_covariance``;
    cv_nrmse_hold: holding the velocity's nrmse on the same cross-validation samples as ``cv_nrmse`` or None (no
    comparison); persistence_margin: the relative margin the model must beat it by
    (:func:`~..fit.fit_core.persistence`)."""

    dof: str
    names: list
    theta: np.ndarray
    cov: np.ndarray
    t_dof: int
    units: Mapping[str, str]
    velocity: np.ndarray
    acceleration: np.ndarray
    force: np.ndarray
    h: float
    lower_bounds: Sequence[float] | None = None
    upper_bounds: Sequence[float] | None = None
    fold_theta: np.ndarray | None = None
    cv_nrmse: float | None = None
    residual_rho: float | None = None
    input_corr: Mapping[str, Any] | None = None
    steady: Mapping[str, tuple] | None = None
    windows: Sequence[tuple] = ()
    expected_bias: float | None = 0.0
    thrust_in_covariance: bool = False
    fit_std: Mapping[str, float] | None = None
    cv_nrmse_hold: float | None = None
    persistence_margin: float = PERSISTENCE_MARGIN


#: Smallest bias difference flagged, as a fraction of the damping force at the typical speed: a force the data
#: detect (the piloted test bags: 0.03 N in sway, z = 2.8) but far below what moves the vehicle is not a reason.
BIAS_MIN_REL = 0.05
#: Cross-validated prediction nrmse at or above which the DOF's model is suspect (it misses a force).
NRMSE_MAX = 0.5
#: Parameters whose 95 % half-width is judged against their own value (:data:`WIDTH_MAX`).
_RELATIVE = ("inertia", "added_mass", "restoring", "reverse_thrust_gain")


def assess(ev: FitEvidence, rel: Sequence[float]) -> dict:
    """Honest covariance, intervals and verdicts of one DOF's fit (module docstring).

    The one verdict path of ``hindrax ident bag`` (:func:`assess_dof`) and ``hindrax ident fit``
    (:func:`.results.assessment`). ``rel`` = [negative, positive] 1-sigma relative thrust uncertainty
    (:func:`declared_rel`), added as :func:`thrust_covariance` unless ``ev.thrust_in_covariance``. The checks of the
    module docstring run when their evidence is there (the campaign reader gives the steady windows), and also:
    cross-validated nrmse at or above :data:`NRMSE_MAX` (DOF-wide); with ``cv_nrmse_hold`` the model must beat holding
    the velocity (:func:`~..fit.fit_core.persistence`), else the DOF's verdict is
    :data:`~..fit.fit_core.NO_MODEL_VERDICT`; per parameter, on a bound or fold estimates spread by more than 3 fit std.
    A suspect parameter (a reason of its own or of the DOF) gets ``advice`` (:func:`data_advice`).

    Returns {"parameters": {name: {value, std, std_fit, ci95, t_dof, verdict, reasons[, advice]}}, "verdict"
    (trusted | suspect | :data:`~..fit.fit_core.NO_MODEL_VERDICT`), "reasons" (DOF-wide), "checks": {name: number}}."""
    names = list(ev.names)
    theta = np.asarray(ev.theta, dtype=float)
    cov_fit = np.asarray(ev.cov, dtype=float)
    if ev.thrust_in_covariance:
        rel = (0.0, 0.0)
        cov = cov_fit
        fs = ev.fit_std or {}
        std_fit = np.array([fs.get(n, math.sqrt(max(cov[i, i], 0.0))) for i, n in enumerate(names)])
    else:
        rel = (float(rel[0]), float(rel[1]))
        cov = cov_fit + thrust_covariance(ev.dof, names, theta, rel)
        std_fit = np.sqrt(np.clip(np.diag(cov_fit), 0.0, None))
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    t_dof = max(1, int(ev.t_dof))
    tq = float(stats.t.ppf(0.975, t_dof))
    values = dict(zip(names, (float(v) for v in theta)))
    out: dict = {}
    for n, v, s, sf in zip(names, theta, std, std_fit):
        out[n] = {"value": float(v), "std": float(s), "std_fit": float(sf), "ci95": (v - tq * s, v + tq * s),
                  "t_dof": t_dof, "reasons": []}
    dof_reasons: list[str] = []
    checks: dict = {"t_quantile": tq, "thrust_uncertainty_rel": list(rel)}
    v = np.asarray(ev.velocity, dtype=float)
    v = v[np.isfinite(v)]
    v_typ = float(np.percentile(np.abs(v), 75)) if v.size else 0.0
    total = float(np.mean(np.abs(_drag(ev.dof, values, np.array([v_typ, -v_typ]), bias=False)))) if v_typ else 0.0
    # --- bias: significant, and not negligible against the damping force at the typical speed
    if "bias" in out and ev.expected_bias is not None:
        b, sb = out["bias"]["value"], out["bias"]["std"]
        z = (b - ev.expected_bias) / sb if sb > 0 else 0.0
        checks["bias_z"] = z
        checks["bias_off"] = bool(abs(z) > tq and abs(b - ev.expected_bias) > BIAS_MIN_REL * total)
        unit = ev.units.get("bias", "")
        if checks["bias_off"]:
            dof_reasons.append(f"bias {b:+.3g} {unit} differs from the expected {ev.expected_bias:+.3g} {unit} "
                               f"(z = {z:+.1f}): an unmodelled force (current, tether, thrust offset)")
        elif abs(z) > tq:  # too small to doubt the DOF, but its interval misses the expected force: not trusted
            out["bias"]["reasons"].append(f"bias {b:+.3g} {unit} outside its interval around the expected "
                                          f"{ev.expected_bias:+.3g} {unit} (z = {z:+.1f}): a small unmodelled force "
                                          "(current, tether, thrust offset) the interval does not hold")
    # --- methods: steady-state against the reported fit
    for n in (x for x in names if x.startswith("quadratic")):
        st = (ev.steady or {}).get(n)
        if st is not None and st[1] is not None and math.isfinite(st[1]):
            vs, ss = st
            zz = (vs - out[n]["value"]) / math.hypot(ss, out[n]["std_fit"]) if (ss or out[n]["std_fit"]) else 0.0
            checks[f"steady_z_{n}"] = zz
            if abs(zz) > 3.0 and abs(vs - out[n]["value"]) > METHODS_MAX * abs(out[n]["value"]):
                dof_reasons.append(f"steady-state {n} {vs:.4g} disagrees with the transient fit "
                                   f"{out[n]['value']:.4g} (z = {zz:+.1f})")
    # --- direction consistency of the steady windows
    if len(ev.windows) >= 4:
        wv = np.array([w[0] for w in ev.windows], dtype=float)
        wf = np.array([w[1] for w in ev.windows], dtype=float)
        pred = _drag(ev.dof, values, wv)
        scale = np.maximum(np.abs(pred), 0.1 * float(np.max(np.abs(pred))) + 1e-9)
        res = (wf - pred) / scale  # relative misfit of each steady window
        pos, neg = res[wv > 0], res[wv < 0]
        if pos.size >= 2 and neg.size >= 2:
            se = max(math.sqrt(np.var(pos, ddof=1) / pos.size + np.var(neg, ddof=1) / neg.size), 0.01)
            diff = float(np.mean(pos)) - float(np.mean(neg))
            zz = diff / se
            checks["direction_z"] = zz
            if abs(zz) > 4.0 and abs(diff) > DIRECTION_MAX:
                which = "down/up" if ev.dof == "heave" else "positive/negative"
                dof_reasons.append(f"{which} steady windows disagree with the model by {100 * np.mean(pos):+.0f} % / "
                                   f"{100 * np.mean(neg):+.0f} % of the force (z = {zz:+.1f})")
    # --- whiteness
    rho = ev.residual_rho
    if rho is not None and math.isfinite(rho):
        checks["residual_lag1"] = float(rho)
    xc = ev.input_corr
    if xc is not None:  # a measured position: the independence of the residuals and the input decides
        checks.update(input_xcorr=float(xc["r"]), input_xcorr_z=float(xc["z"]), input_xcorr_lag_s=float(xc["lag_s"]))
        if xc["z"] > INDEPENDENCE_Z:
            dof_reasons.append(f"residuals follow the {xc['input']} (cross-correlation {xc['r']:.2f} at lag "
                               f"{xc['lag_s']:.1f} s, z = {xc['z']:.1f} > {INDEPENDENCE_Z}): the model misses part of "
                               "the response to the force (inertia, damping law, lag, direction)")
    elif rho is not None and math.isfinite(rho) and rho > WHITENESS_MAX:
        dof_reasons.append(f"residuals not white (lag-1 autocorrelation {rho:.2f} > {WHITENESS_MAX})")
    # --- prediction
    if ev.cv_nrmse is not None and math.isfinite(ev.cv_nrmse):
        checks["cv_nrmse"] = float(ev.cv_nrmse)
        if ev.cv_nrmse >= NRMSE_MAX:
            dof_reasons.append(f"cross-validated prediction nrmse {ev.cv_nrmse:.3f} >= {NRMSE_MAX}: the model misses "
                               "a force (current, tether, thrust not as commanded) or the data are mostly noise")
    # --- never worse than persistence: a model that does not beat holding the velocity is not trusted at all
    no_model = False
    if ev.cv_nrmse is not None and ev.cv_nrmse_hold is not None:
        per = persistence({"nrmse": ev.cv_nrmse, "nrmse_hold": ev.cv_nrmse_hold}, ev.persistence_margin)
        checks["cv_nrmse_hold"] = per["nrmse_hold"]
        if math.isfinite(per["nrmse_hold"]) and not per["beats"]:
            no_model = True
            dof_reasons.append(f"{NO_MODEL_VERDICT}: cross-validated nrmse {per['nrmse']:.3f} against "
                               f"{per['nrmse_hold']:.3f} for holding the velocity on the same samples (needs "
                               f"{100 * per['margin']:.0f} % less): the parameters explain nothing the last "
                               "measurement does not")
    # --- width, physical bound, fold spread
    folds = np.asarray(ev.fold_theta, dtype=float) if ev.fold_theta is not None and len(ev.fold_theta) else None
    scale = max(1.0, float(np.max(np.abs(theta)))) if theta.size else 1.0
    at_bound = {}
    for i, n in enumerate(names):
        e = out[n]
        half = 0.5 * (e["ci95"][1] - e["ci95"][0])
        lb = None if ev.lower_bounds is None else ev.lower_bounds[i]
        ub = None if ev.upper_bounds is None else ev.upper_bounds[i]
        where = None
        if lb is not None and np.isfinite(lb) and (theta[i] <= 1e-9 * scale if lb == 0.0 else
                                                   theta[i] <= lb + 1e-3 * max(abs(lb), 1e-9)):
            where = ("lower", float(lb))
        elif ub is not None and np.isfinite(ub) and theta[i] >= ub - 1e-3 * max(abs(ub), 1e-9):
            where = ("upper", float(ub))
        at_bound[n] = where is not None
        if at_bound[n]:
            e["at_bound"] = where[1]
            e["reasons"].append(f"{n} at its {where[0]} bound {where[1]:g}"
                                + (" (physical; the data do not show it)" if where[1] == 0.0 else "")
                                + ": no interval (the data push it to the bound)")
        elif n in _RELATIVE or n.startswith("quadratic"):
            if theta[i] != 0 and half / abs(theta[i]) > WIDTH_MAX:
                e["reasons"].append(f"95 % interval +-{100 * half / abs(theta[i]):.0f} % of the value, too wide for "
                                    "controller design")
        elif (n.startswith("linear") or n == "bias") and total > 0:
            contrib = half * (v_typ if n.startswith("linear") else 1.0)
            if contrib / total > WIDTH_MAX:
                e["reasons"].append(f"95 % interval +-{contrib:.3g} at {v_typ:.2f} (typical speed) is "
                                    f"{100 * contrib / total:.0f} % of the damping force there")
        if folds is not None and folds.shape[0] >= 3:
            good = np.all(np.isfinite(folds), axis=1)
            if good.sum() >= 3:
                spread = float(np.std(folds[good, i], ddof=1))
                if std_fit[i] > 0 and spread > 3 * std_fit[i]:
                    e["reasons"].append(f"fold estimates spread {spread:.3g} > 3 x std {std_fit[i]:.3g}")
    for n, e in out.items():
        # what data would fix it: a parameter suspect for a DOF-wide reason alone gets it too (issue 74.3: a pool
        # day's seven suspect heave parameters named no run); its narrow interval gets a repetition (data_advice)
        if (e["reasons"] or dof_reasons) and ev.h > 0:
            half = 0.5 * (e["ci95"][1] - e["ci95"][0])
            ref = (total / v_typ if n.startswith("linear") and v_typ > 0 else total if n == "bias" else None)
            e["advice"] = data_advice(ev.dof, n, e["value"], half, ev.velocity, ev.acceleration, ev.force, ev.h,
                                      at_bound[n], ref if ref else None)
        e["reasons"] = dof_reasons + e["reasons"]
        e["verdict"] = "suspect" if e["reasons"] else "trusted"
    verdict = NO_MODEL_VERDICT if no_model else "suspect" if any(e["reasons"] for e in out.values()) else "trusted"
    return {"parameters": out, "verdict": verdict, "reasons": dof_reasons, "checks": checks}


def with_added_mass(a: dict, added_mass: float) -> dict:
    """An :func:`assess` result with ``added_mass`` = inertia - the rigid-body inertia (known): the inertia's std,
    interval shifted, verdict, reasons and advice (changed in place; returned)."""
    e = a["parameters"]["inertia"]
    shift = added_mass - e["value"]
    am = {k: v for k, v in e.items() if k != "advice"}
    am.update(value=float(added_mass), ci95=(e["ci95"][0] + shift, e["ci95"][1] + shift), reasons=list(e["reasons"]))
    if "advice" in e:
        am["advice"] = dict(e["advice"])
    a["parameters"]["added_mass"] = am
    return a


def core_signals(core: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """(velocity, acceleration, force (n,), tick h s) of a fit core result's training segments
    (:class:`~..fit.fit_core.DofResult` ``train``: the smoothed velocity and acceleration and the input force at the
    fitted ticks), the evidence of the typical speed and of :func:`data_advice` for both readers."""
    sd = core.train
    return (np.asarray(sd.v_s, dtype=float).ravel(), np.asarray(sd.a_s, dtype=float).ravel(),
            np.asarray(sd.force, dtype=float).ravel(), float(sd.h))


def core_evidence(core: Any, names: Sequence[str] | None = None) -> dict:
    """The :class:`FitEvidence` fields a fit core result (:class:`~..fit.fit_core.DofResult`) gives, for
    :func:`assess_dof` and :func:`~.results.assessment`: the optimiser's bounds and fold estimates of ``names`` (default
    the core's own; heave's ``*_positive``/``*_negative`` map onto the one pair, absent ones get no bound and no fold
    estimates), the cross-validated nrmse, holding the velocity's and the margin (:func:`~..fit.fit_core.persistence`),
    and :func:`core_signals`. Returns {lower_bounds, upper_bounds, fold_theta, cv_nrmse, cv_nrmse_hold,
    persistence_margin, velocity, acceleration, force, h}."""
    core_names = list(core.names)
    idx = core_index(core_names if names is None else list(names), core_names)
    lows = [lo for _n, _k, lo, _hi in core.chosen.layout]
    highs = [hi for _n, _k, _lo, hi in core.chosen.layout]
    ft = np.asarray(core.fold_theta, dtype=float) if core.fold_theta is not None else np.zeros((0, 0))
    fold = ft[:, idx] if ft.ndim == 2 and ft.shape[0] and all(j is not None for j in idx) else None
    per = core.persistence or {}
    vel, acc, force, h = core_signals(core)
    return {"lower_bounds": [lows[j] if j is not None else None for j in idx],
            "upper_bounds": [highs[j] if j is not None else None for j in idx], "fold_theta": fold,
            "cv_nrmse": core.cv.get("nrmse") if core.cv else None, "cv_nrmse_hold": per.get("nrmse_hold"),
            "persistence_margin": per.get("margin", PERSISTENCE_MARGIN), "velocity": vel, "acceleration": acc,
            "force": force, "h": h}


def model_selection(core: Any) -> list[dict]:
    """identification.yaml ``model_selection`` of a fit core result, for both document builders: every candidate's
    terms, parameter count and cross-validated nrmse (``chosen`` marks the model kept), then holding the velocity
    (persistence) and the zero model scored on the chosen model's held-out samples
    (:func:`~..fit.fit_core.persistence`)."""
    rows = [{"terms": k.terms.label, "parameters": k.n_params, "cv_nrmse": k.cv.get("nrmse"),
             "cv_nrmse_hold": k.cv.get("nrmse_hold"), "chosen": k is core.chosen} for k in core.candidates]
    if core.persistence is not None:
        rows += [{"terms": "hold the velocity (persistence)", "parameters": 0,
                  "cv_nrmse": core.persistence["nrmse_hold"], "chosen": False},
                 {"terms": "zero", "parameters": 0, "cv_nrmse": core.persistence["nrmse_zero"], "chosen": False}]
    return rows


def no_model_line(dof: str, per: Mapping[str, float]) -> str:
    """The printed verdict of a DOF whose model does not beat holding the velocity (``per``: the ``persistence``
    entry, :func:`~..fit.fit_core.persistence`), the same line for ``hindrax ident fit`` and ``hindrax ident bag``."""
    return (f"{dof:6} verdict: {NO_MODEL_VERDICT} (cross-validated nrmse {per['nrmse']:.3f}, holding the velocity "
            f"{per['nrmse_hold']:.3f}, needs {100 * per['margin']:.0f} % less): no parameter trusted")


def assess_dof(r: Any, cfg: VehicleConfig) -> dict:
    """:func:`assess` of a :class:`~..fit.dof_model.DofIdentification` (the campaign reader's, ``ident bag``); ``r`` is
    not modified. The fit core's bounds, fold estimates, cross-validated nrmse and holding the velocity's come from
    ``r.signals["core"]`` when present (:func:`core_evidence`, as for ``hindrax ident fit``; so a DOF no model beats
    persistence in gets :data:`~..fit.fit_core.NO_MODEL_VERDICT` here too); ``added_mass`` from the inertia
    (:func:`with_added_mass`)."""
    names = list(r.names)
    theta = np.array([r.values[n] for n in names])
    cov_fit = r.signals.get("covariance")
    if cov_fit is None or np.shape(cov_fit) != (len(names), len(names)):
        cov_fit = np.diag([r.std[n] ** 2 for n in names])
    joint = r.signals.get("joint") or {}
    sig = r.signals
    nseg = max(1, int(r.pool_time_s // SEGMENT_S))  # independent segments of the output-error fit
    t = np.asarray(sig.get("t") if sig.get("t") is not None else [], dtype=float)
    have = all(sig.get(k) is not None for k in ("velocity", "acceleration", "force")) and t.size > 1
    core = sig.get("core")
    ev = FitEvidence(
        dof=r.dof, names=names, theta=theta, cov=np.asarray(cov_fit, dtype=float),
        t_dof=int(sig["t_dof"]) if sig.get("t_dof") else max(1, nseg - 1), units=r.units,
        velocity=np.asarray(sig.get("velocity") if have else [], dtype=float),
        acceleration=np.asarray(sig.get("acceleration") if have else [], dtype=float),
        force=np.asarray(sig.get("force") if have else [], dtype=float),
        h=float(np.median(np.diff(t))) if have else 0.0,
        residual_rho=sig.get("residual_autocorrelation"), input_corr=sig.get("input_correlation"), steady=r.steady,
        windows=sig.get("windows") or [],
        expected_bias=float(cfg.buoyancy_n - cfg.weight_n) if r.dof == "heave" else 0.0,
        thrust_in_covariance=bool(joint.get("thrust_in_covariance")),
        fit_std=joint.get("fit_std"))
    if core is not None:  # bounds, folds, cross-validation, persistence and signals as hindrax ident fit takes them
        for key, value in core_evidence(core, names).items():
            setattr(ev, key, value)
    elif not have and sig.get("velocity") is not None:  # the typical speed without the advice's signals
        ev.velocity = np.asarray(sig["velocity"], dtype=float)
    a = assess(ev, declared_rel(cfg))
    a["checks"]["segments"] = nseg
    return with_added_mass(a, float(r.values["added_mass"]))


def _drag(dof: str, values: Mapping[str, float], v: np.ndarray, bias: bool = True) -> np.ndarray:
    """Damping (+ bias) force of the identified model at velocities ``v`` (restoring left out)."""
    v = np.asarray(v, dtype=float)

    def get(name):  # a term the model leaves out is 0; heave's one pair serves both directions
        return float(values.get(name, values.get(name.rsplit("_", 1)[0], 0.0)))

    if dof == "heave":
        kq = np.where(v > 0, get("quadratic_damping_positive"), get("quadratic_damping_negative"))
        kl = np.where(v > 0, get("linear_damping_positive"), get("linear_damping_negative"))
    else:
        kq, kl = get("quadratic_damping"), get("linear_damping")
    return kq * np.abs(v) * v + kl * v + (float(values.get("bias", 0.0)) if bias else 0.0)


def apply_verdicts(identifications: Mapping[str, Any], cfg: VehicleConfig) -> dict:
    """:func:`assess_dof` for every DOF, written into each identification (idempotent): ``std`` and ``ci95``
    become the honest ones, the fit-only std moves to ``signals["std_fit"]``, ``signals["assessment"]`` holds
    the verdicts. Returns {dof: assessment}."""
    out = {}
    fresh = []
    for dof, r in identifications.items():
        if "assessment" in r.signals:
            out[dof] = r.signals["assessment"]
            continue
        a = assess_dof(r, cfg)
        r.signals["std_fit"] = dict(r.std)
        for n, e in a["parameters"].items():
            r.std[n] = e["std"]
            r.ci95[n] = tuple(e["ci95"])
        r.signals["assessment"] = a
        out[dof] = a
        fresh.append(dof)
    thrust_curve_check(out, fresh)
    return out


def thrust_curve_check(assessments: Mapping[str, dict], dofs: Sequence[str]) -> None:
    """The ``thrust`` check across DOFs (module docstring), in place: when heave's bias differs from the configured
    net buoyancy (its ``bias_off`` check of :func:`assess`), every parameter of ``dofs`` other than heave is suspect."""
    heave = assessments.get("heave")
    if heave is None or not dofs or not heave["checks"].get("bias_off"):
        return
    z = heave["checks"].get("bias_z", 0.0)
    reason = (f"heave bias differs from the configured net buoyancy (z = {z:+.1f}): the thrust curves do not "
              "match the vehicle, every thrust-derived parameter is suspect")
    for dof in dofs:
        if dof == "heave" or dof not in assessments:
            continue
        a = assessments[dof]
        a["reasons"].append(reason)
        for e in a["parameters"].values():
            e["reasons"].append(reason)
            e["verdict"] = "suspect"
        if a["verdict"] != NO_MODEL_VERDICT:
            a["verdict"] = "suspect"


def spread_reasons(values: Sequence[float], stds: Sequence[float], factor: float = 2.0) -> list[str]:
    """Run-to-run check over repeated campaigns: the sample std of ``values`` above ``factor`` times the median
    reported std (needs 3 or more runs)."""
    x = np.asarray(values, dtype=float)
    s = np.asarray(stds, dtype=float)
    if x.size < 3:
        return []
    spread = float(np.std(x, ddof=1))
    med = float(np.median(s))
    if med > 0 and spread > factor * med:
        return [f"run-to-run spread {spread:.3g} is {spread / med:.1f} x the reported std"]
    return []


#: |difference| / combined std beyond which an independent reference contradicts the self-propelled value (the
#: two-sided 95 % normal quantile: the two intervals do not overlap at that level).
REFERENCE_Z_MAX = 1.96


def free_decay_reason(dof: str, self_propelled: tuple[float, float], free_decay: tuple[float, float]) -> str | None:
    """The reason text when the free-decay inertia (value, std; kg m^2) contradicts the self-propelled one
    (value, std): |I_sp - I_fd| > :data:`REFERENCE_Z_MAX` sqrt(std_sp^2 + std_fd^2); None when they
    agree. Raises
    ``ValueError`` for a negative std."""
    (v, sd), (vf, sf) = self_propelled, free_decay
    if sd < 0 or sf < 0:
        raise ValueError(f"{dof}: std must be >= 0, got {sd} and {sf}")
    comb = math.hypot(sd, sf)
    z = (v - vf) / comb if comb > 0 else (0.0 if v == vf else math.copysign(math.inf, v - vf))
    if abs(z) <= REFERENCE_Z_MAX:
        return None
    return (f"{dof} inertia {v:.4g} kg m^2 (self-propelled) differs from the free decay's {vf:.4g} +- {sf:.2g} kg m^2 "
            f"(z = {z:+.1f}, beyond {REFERENCE_Z_MAX:g} combined std): the thrust curve (or the model) is off in {dof}")


def apply_reference_verdicts(document: dict) -> dict:
    """Independent references against the self-propelled result in an identification.yaml ``document`` (changed
    in place; returned): for every roll/pitch of ``document["free_decay"]`` (``total_inertia_kg_m2`` and
    ``total_inertia_kg_m2_std``) also identified self-propelled (``dofs.<dof>.inertia`` value and honest std), a
    disagreement (:func:`free_decay_reason`) makes ``inertia`` and ``added_mass`` ``verdict: suspect`` with the
    reason, and the DOF suspect; the free-decay entry gets ``self_propelled: {inertia_kg_m2, inertia_kg_m2_std, z,
    verdict: suspect | agrees}``. Idempotent."""
    for dof, fd in (document.get("free_decay") or {}).items():
        entry = (document.get("dofs") or {}).get(dof)
        if entry is None or "inertia" not in entry or "total_inertia_kg_m2" not in fd:
            continue
        v, sd = float(entry["inertia"]["value"]), float(entry["inertia"]["std"])
        vf, sf = float(fd["total_inertia_kg_m2"]), float(fd["total_inertia_kg_m2_std"])
        comb = math.hypot(sd, sf)
        reason = free_decay_reason(dof, (v, sd), (vf, sf))
        fd["self_propelled"] = {"inertia_kg_m2": v, "inertia_kg_m2_std": sd,
                                "z": abs(v - vf) / comb if comb > 0 else 0.0,
                                "verdict": "agrees" if reason is None else "suspect"}
        if reason is None:
            continue
        for name in ("inertia", "added_mass"):
            par = entry.get(name)
            if isinstance(par, dict):
                par.setdefault("reasons", [])
                if reason not in par["reasons"]:
                    par["reasons"].append(reason)
                par["verdict"] = "suspect"
        entry["verdict"] = "suspect"
    return document


# ------------------------------------------------------------------------------------------------ data advice
#: Relative 95 % half-width the advice aims at (below :data:`WIDTH_MAX`, with a margin).
ADVICE_TARGET = 0.25
#: Shortest extra recording the advice asks for, s (a few runs).
ADVICE_MIN_S = 30.0
#: A pool day, s: no advice asks for more (a pool engineer books the pool by the day).
POOL_DAY_S = 8 * 3600.0
#: Runs of a kind the advice names when more of the data's own manoeuvre cannot fix a parameter within a pool day
ALTERNATIVE_RUNS = 10
#: The named kinds of run: key -> (plural name, seconds of one run including its start and stop)
RUN_KINDS = {
    "start-stop": ("start-and-stop runs", 15.0),
    "steady": ("steady runs", 20.0),
    "slow": ("slow steady runs", 30.0),
    "hold": ("holds and slow runs both ways", 30.0),
    "tilt": ("tilt-and-release runs", 15.0),
    "reverse": ("reverse-command runs", 20.0),
    "coupled": ("combined runs", 20.0),
    "ladder": ("speed-ladder runs", 60.0),
    "full": ("full-command runs", 20.0),
}


def format_advice(parameter: str, advice: dict) -> str:
    """One printed line of :func:`data_advice` for ``parameter`` (``hindrax ident fit`` and ``ident bag`` alike):
    runs of a named kind, their speed range and the pool time in minutes."""
    lo, hi, unit = advice["speed_range"]
    head = "" if advice.get("feasible", True) else "more of the same runs cannot fix it within a pool day: "
    runs, kind = advice["runs"], advice["run_kind"]
    return (f"  to fix {parameter}: {head}{runs} {kind} of about {advice['run_s']:.0f} s ({advice['manoeuvre']}), "
            f"speeds {lo:g}-{hi:g} {unit}: about {advice['minutes']} min of pool time")


def data_advice(dof: str, name: str, value: float, half_width: float, velocity, acceleration, force,
                h: float, at_bound: bool = False, scale: float | None = None) -> dict:
    """What data would make the 95 % half-width of one parameter ``ADVICE_TARGET`` of its value, in the units a
    pool engineer plans in: runs of a named kind (:data:`RUN_KINDS`), a speed range, minutes.

    velocity, acceleration, force (n,): the smoothed velocity, acceleration and input force at the ticks (``h`` s) of
    the fitted segments. The variance of an estimate falls as 1 / (seconds of the manoeuvre that informs it), so
    ``seconds_more = T (w / w_target)^2 - T`` with T the seconds of that manoeuvre in the data (at least
    :data:`ADVICE_MIN_S`); the manoeuvre per parameter (docs/identification.md §4, R1, R2, R15) is the branch's ``used``
    mask below. The time is rounded up to whole runs, at least one, never above :data:`POOL_DAY_S`: when more of the
    same would take longer (or the data hold none of it while the interval is wide), the advice names the kind of run
    that would fix it (``feasible`` False, the branch's ``alt``), :data:`ALTERNATIVE_RUNS` runs of it. A parameter at a
    bound gets as much again of its manoeuvre; one whose interval is already narrow (another reason) gets a repetition,
    which tells a real effect from chance. ``scale``: the magnitude the half-width is judged against when not the value
    (a bias and a linear damping: the damping force at the typical speed, :func:`assess`). Returns {dof, manoeuvre,
    run_kind, runs, run_s, minutes, speed_range (low, high, unit), seconds_in_data, seconds_more, feasible, why}."""
    v = np.asarray(velocity, dtype=float)
    a = np.asarray(acceleration, dtype=float)
    f = np.asarray(force, dtype=float)
    ok = np.isfinite(v) & np.isfinite(a) & np.isfinite(f)
    v, a, f = v[ok], a[ok], f[ok]
    unit = "rad/s" if dof in ROTATIONAL_DOFS else "m/s"
    sign = 1.0 if name.endswith("_positive") else -1.0 if name.endswith("_negative") else 0.0
    vv = v if sign == 0.0 else np.where(sign * v > 0, np.abs(v), 0.0)
    vmax = float(np.percentile(np.abs(vv), 98)) if vv.size else 0.0
    top = vmax if vmax >= 1e-3 else 0.5  # nothing moved: the usual top speed of a small ROV, 0.5 m/s or rad/s
    direction = "" if sign == 0.0 else (" down (w > 0)" if sign > 0 else " up (w < 0)")
    if name in ("inertia", "added_mass"):
        thr = float(np.percentile(np.abs(a), 70)) if a.size else 0.0
        used = np.abs(a) >= thr if a.size else np.zeros(0, bool)
        man = f"{dof}: accelerate from rest to the top speed, hold, brake, both directions"
        kind, lo, hi = "start-stop", 0.0, top
        alt = ("start-stop", f"{dof}: full-thrust steps from rest and full-thrust braking (the acceleration, not "
                             "the time, informs the inertia)", 0.0, top)
    elif name.startswith("quadratic"):
        used = np.abs(vv) >= 0.5 * vmax if vmax > 0 else np.zeros(v.size, bool)
        man = f"{dof}{direction}: steady runs of 5 s or more in the top half of the speeds"
        kind, lo, hi = "steady", 0.5 * top, top
        alt = ("steady", f"{dof}{direction}: steady runs faster than the data's top speed (the curvature over a "
                         "wider speed range tells quadratic from linear damping)", top, 1.5 * top)
    elif name.startswith("linear"):
        used = (np.abs(vv) > 0.05 * vmax) & (np.abs(vv) <= vmax / 3.0) if vmax > 0 else np.zeros(v.size, bool)
        man = f"{dof}{direction}: slow steady runs (low speeds, where linear damping dominates)"
        kind, lo, hi = "slow", 0.05 * top, top / 3.0
        alt = ("ladder", f"{dof}{direction}: a ladder of 5-7 steady speeds from slow to the top, both directions "
                         "(linear and quadratic damping from one curve)", 0.05 * top, top)
    elif name == "bias":
        used = np.abs(v) <= 0.3 * vmax if vmax > 0 else np.ones(v.size, bool)
        man = f"{dof}: slow runs in both directions and holds (the same speed both ways tells bias from damping)"
        kind, lo, hi = "hold", 0.0, 0.3 * top
        alt = ("hold", f"{dof}: holds at zero command, 30 s each, at the start and end of every set of runs (the "
                       "force that moves a vehicle at rest)", 0.0, 0.1 * top)
    elif name == "restoring":
        used = np.abs(a) > 0
        man = f"{dof}: tilts of 10-30 degrees and releases (roll/pitch excursions)"
        kind, lo, hi = "tilt", 0.0, top
        alt = ("tilt", f"{dof}: larger tilts (20-30 degrees) held, then released (free decay)", 0.0, top)
    elif name == "reverse_thrust_gain":
        used = f < 0
        man = f"{dof}: runs with reverse (negative) commands as long as the forward ones"
        kind, lo, hi = "reverse", 0.0, top
        alt = ("reverse", f"{dof}: reverse-command steps of the same sizes as the forward ones", 0.0, top)
    elif name == "saturation_gain":
        used = np.abs(f) >= float(np.percentile(np.abs(f), 90)) if f.size else np.zeros(0, bool)
        man = f"{dof}: commands held beyond the thrusters' limits (the allocation saturates), both directions"
        kind, lo, hi = "full", 0.5 * top, top
        alt = ("full", f"{dof}: full commands from rest to the top speed and back, both directions (the force at "
                       "the thrusters' limits against the command)", 0.5 * top, top)
    else:
        used = np.abs(v) > 0.05 * vmax if vmax > 0 else np.ones(v.size, bool)
        man = f"{dof}: runs that move {dof} together with the coupled DOF"
        kind, lo, hi = "coupled", 0.0, top
        alt = ("coupled", f"{dof} alone, the coupled DOF alone, then both together (tells the coupling from "
                          f"{dof}'s own dynamics)", 0.0, top)
    t_in = float(np.count_nonzero(used)) * h
    feasible = True
    ref = abs(value) if scale is None or not (math.isfinite(scale) and scale > 0) else float(scale)
    if at_bound:
        more = max(ADVICE_MIN_S, t_in)
        why = (f"at its bound: the data cannot tell it from the bound, so it has no interval; {t_in:.0f} s of that "
               "manoeuvre in the data, as much again to see it move off the bound")
    elif ref > 0.0 and math.isfinite(half_width) and half_width > ADVICE_TARGET * ref:
        ratio = half_width / (ADVICE_TARGET * ref)
        need = max(t_in, ADVICE_MIN_S) * (ratio ** 2 - 1.0)
        what = "the value" if scale is None else "its reference force"
        why = (f"95 % half-width {100 * half_width / ref:.0f} % of {what}; {t_in:.0f} s of that manoeuvre "
               f"in the data, the variance falls as 1 / seconds")
        if t_in <= 0.0 or need > POOL_DAY_S:
            feasible = False
            why += (f": more of it would take {need / 3600.0:.0f} h, beyond a pool day" if t_in > 0 else
                    ": the data hold none of it")
        more = max(ADVICE_MIN_S, need)
    elif ref == 0.0 or not math.isfinite(half_width):
        feasible = t_in > 0.0
        more = max(ADVICE_MIN_S, t_in)
        why = f"no usable interval; {t_in:.0f} s of that manoeuvre in the data"
    else:
        more = max(ADVICE_MIN_S, t_in)
        why = (f"95 % half-width {100 * half_width / ref:.0f} % of the reference (narrow enough); the reason is "
               f"another check: repeating the manoeuvre ({t_in:.0f} s in the data) tells a real effect from chance")
    if not feasible:
        kind, man, lo, hi = alt
        more = ALTERNATIVE_RUNS * RUN_KINDS[kind][1]
        why += f"; it needs a different kind of run: {RUN_KINDS[kind][0]}"
    run_name, run_s = RUN_KINDS[kind]
    runs = int(min(max(1, math.ceil(more / run_s)), POOL_DAY_S // run_s))
    more = runs * run_s
    return {"dof": dof, "manoeuvre": man, "run_kind": run_name, "runs": runs, "run_s": run_s,
            "minutes": int(max(1, math.ceil(more / 60.0))), "speed_range": [round(lo, 3), round(hi, 3), unit],
            "seconds_in_data": round(t_in, 1), "seconds_more": round(float(more), 0), "feasible": feasible,
            "why": why}
