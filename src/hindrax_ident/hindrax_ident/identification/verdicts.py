"""Honest intervals and a verdict for every identified parameter, added after the fit (the fit is not touched).

:func:`apply_verdicts` takes the :class:`~.estimators.DofIdentification` of each DOF and the vehicle configuration
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
   :meth:`~hindrax_ident.estimation.thruster_fit.CubicFit.relative_std`), or a calibration's scale std
   (``thruster_fit_rel``), which takes precedence;
2. **uses degrees of freedom that match the independent information**: the output-error residuals are correlated
   inside a segment and between neighbouring segments, so the fit core's covariance is cluster-robust
   (docs/identification.md §7, step 5) and the 95 % interval uses the Student t quantile with its (clusters - 1)
   degrees of freedom ([Cameron-Miller2015] §VI), not (samples - parameters);
3. **gives each parameter ``verdict: trusted | suspect`` and the reasons**, from the checks a pool engineer makes:

   * ``bias``: the constant force differs significantly from the one expected (0; heave: the configured net
     buoyancy): something the model does not have is pushing (current, tether, thrust offset). DOF-wide.
   * ``methods``: the steady-state fit ([Hindrax-Drag] eqs. 2-8) disagrees with the reported
     quadratic damping by more than :data:`METHODS_MAX` and beyond 3 combined standard deviations: the model does not
     explain the transients and the steady states with the same numbers (lag, latency, coupling). DOF-wide. (The
     equation-error fit is not used: its inertia is biased low by the noise of the differentiated velocity even when
     nothing is wrong.)
   * ``direction``: the steady-window misfits (relative to the model force) of the two directions of motion differ
     by more than :data:`DIRECTION_MAX` and beyond their scatter (z > 4) (heave: up/down; others: forward/backward),
     a level-to-level inconsistency. DOF-wide.
   * ``whiteness``: the lag-1 autocorrelation of the output-error residuals between consecutive samples is above
     :data:`WHITENESS_MAX` (the model leaves a slow, systematic misfit: a thrust lag or latency the vehicle file
     does not have, a late DVL). In the scenario suite's no-disturbance runs it stayed at or below 0.06. DOF-wide.
   * ``thrust`` (across DOFs, :func:`apply_verdicts`): heave's bias is the force that holds the vehicle at depth,
     the net buoyancy (rho V - m) g known from the vehicle's mass and volume. When the identified heave bias
     differs from it significantly, the thrust curves are wrong, and every DOF identified with them is suspect
     (a thrust error in one direction cannot be seen in surge, sway or yaw, which use both directions at once).
   * ``width``: the 95 % half-width is too wide to design a controller from: above :data:`WIDTH_MAX` of the value
     (inertia, quadratic damping), or for linear damping and bias of the total damping force at the typical
     speed of the test (the 75th percentile of |velocity|).
   * ``spread`` (scenario suite only, :func:`spread_reasons`): over repeated campaigns the estimates scatter more
     than their own intervals say.
   * ``free decay`` (roll and pitch inertia, :func:`apply_reference_verdicts`): the rigid + added inertia from a free
     decay (campaign ``tilt_decay`` step or ``hindrax ident free-decay``; restoring stiffness from an inclining
     test, independent of the thrust curve) differs from the self-propelled inertia by more than
     :data:`REFERENCE_Z_MAX` combined standard deviations (issue 17 item 3; docs/identification.md §6.4).

All quantities SI, the parameters and units of :func:`~.estimators.parameter_names`.
"""
from __future__ import annotations

import math
from typing import Any, Mapping, Sequence

import numpy as np
from scipy import stats

from hindrax_drivers.config import VehicleConfig

from .fit_core import SEGMENT_S

__all__ = ["REFERENCE_Z_MAX", "free_decay_reason", "apply_reference_verdicts", "RLS_STD_DOFS", "rls_published_std",
           "DEFAULT_THRUST_UNCERTAINTY_REL", "WHITENESS_MAX", "WIDTH_MAX", "thrust_weights", "thrust_covariance",
           "segment_count", "assess_dof", "apply_verdicts", "spread_reasons", "data_advice", "format_advice",
           "fit_parameter_verdicts",
           "ADVICE_TARGET"]

#: 1-sigma relative thrust uncertainty [negative, positive] when the vehicle file declares none.
DEFAULT_THRUST_UNCERTAINTY_REL = (0.05, 0.10)
#: Residual lag-1 autocorrelation above which the fit is not trusted.
WHITENESS_MAX = 0.2
#: Relative difference of the steady-state and transient quadratic damping flagged (with |z| > 3).
METHODS_MAX = 0.05
#: Difference of the mean relative steady-window misfit between the two directions of motion flagged (with z > 4).
DIRECTION_MAX = 0.05
#: Relative 95 % half-width above which a parameter is too uncertain for controller design.
WIDTH_MAX = 0.3


def thrust_weights(dof: str, names: Sequence[str]) -> np.ndarray:
    """(p, 2) weights [a_pos, b_neg] of each parameter on the positive / negative thrust scale (module docstring)."""
    w = np.full((len(names), 2), 0.5)
    if dof == "heave":
        for i, n in enumerate(names):
            if n.endswith("_positive") or n == "bias":
                w[i] = (1.0, 0.0)
            elif n.endswith("_negative"):
                w[i] = (0.0, 1.0)
    return w


def thrust_covariance(dof: str, names: Sequence[str], theta, rel: Sequence[float]) -> np.ndarray:
    """(p, p) covariance of the parameters from the thrust-scale uncertainty ``rel`` = [neg, pos] (1-sigma)."""
    theta = np.asarray(theta, dtype=float)
    w = thrust_weights(dof, names)
    cov = np.zeros((theta.size, theta.size))
    for k, sigma in ((0, float(rel[1])), (1, float(rel[0]))):
        g = theta * w[:, k]
        cov += sigma ** 2 * np.outer(g, g)
    return cov


def segment_count(dof: str, pool_time_s: float) -> int:
    """Independent segments of the output-error fit (pool time / :data:`~.fit_core.SEGMENT_S`, every DOF)."""
    return max(1, int(pool_time_s // SEGMENT_S))


def _declared_rel(cfg: VehicleConfig, thruster_fit_rel: Sequence[float] | None) -> tuple[float, float]:
    if thruster_fit_rel is not None:
        return float(thruster_fit_rel[0]), float(thruster_fit_rel[1])
    # the bollard-pull fit's own uncertainty (hindrax ident thruster-fit --write) replaces the declared one
    v = cfg.thrusters.thrust_fit_uncertainty_rel
    if v is not None:
        return float(v[0]), float(v[1])
    v = cfg.thrusters.thrust_uncertainty_rel
    return tuple(float(x) for x in v) if v is not None else DEFAULT_THRUST_UNCERTAINTY_REL  # type: ignore


def _expected_bias(cfg: VehicleConfig, dof: str) -> float:
    return float(cfg.buoyancy_n - cfg.weight_n) if dof == "heave" else 0.0


def assess_dof(r: Any, cfg: VehicleConfig, thruster_fit_rel: Sequence[float] | None = None) -> dict:
    """Honest covariance, intervals and verdicts of one DOF (module docstring); ``r`` is not modified.

    Returns {"parameters": {name: {value, std, std_fit, ci95, t_dof, verdict, reasons}}, "verdict",
    "reasons" (DOF-wide), "checks": {name: number}}.
    """
    names = list(r.names)
    theta = np.array([r.values[n] for n in names])
    cov_fit = r.signals.get("covariance")
    if cov_fit is None or np.shape(cov_fit) != (len(names), len(names)):
        cov_fit = np.diag([r.std[n] ** 2 for n in names])
    joint = r.signals.get("joint") or {}
    if joint.get("thrust_in_covariance"):
        # the joint estimate (calibration.joint_estimate) already carries the calibrated scale's uncertainty
        rel = (0.0, 0.0)
        cov = np.asarray(cov_fit, dtype=float)
        fit_std = joint.get("fit_std", {})
        cov_fit = np.diag([fit_std.get(n, math.sqrt(max(cov[i, i], 0.0))) ** 2 for i, n in enumerate(names)])
    else:
        rel = _declared_rel(cfg, thruster_fit_rel)
        cov = np.asarray(cov_fit, dtype=float) + thrust_covariance(r.dof, names, theta, rel)
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    nseg = segment_count(r.dof, r.pool_time_s)
    # the fit core's interval (docs/identification.md §7): t on clusters - 1 degrees of freedom
    t_dof = int(r.signals["t_dof"]) if r.signals.get("t_dof") else max(1, nseg - 1)
    tq = float(stats.t.ppf(0.975, t_dof))
    out: dict = {}
    for n, v, s, sf in zip(names, theta, std, np.sqrt(np.clip(np.diag(cov_fit), 0.0, None))):
        out[n] = {"value": float(v), "std": float(s), "std_fit": float(sf), "ci95": (v - tq * s, v + tq * s),
                  "t_dof": t_dof, "reasons": []}
    rigid = r.values["inertia"] - r.values["added_mass"]
    s_in = out["inertia"]["std"]
    out["added_mass"] = {"value": float(r.values["added_mass"]), "std": s_in, "std_fit": out["inertia"]["std_fit"],
                         "ci95": (r.values["added_mass"] - tq * s_in, r.values["added_mass"] + tq * s_in),
                         "t_dof": t_dof, "reasons": []}
    _ = rigid
    dof_reasons: list[str] = []
    checks: dict = {"segments": nseg, "t_quantile": tq, "thrust_uncertainty_rel": list(rel)}
    # --- bias
    b, sb = out["bias"]["value"], out["bias"]["std"]
    expected = _expected_bias(cfg, r.dof)
    z = (b - expected) / sb if sb > 0 else 0.0
    checks["bias_z"] = z
    if abs(z) > tq:
        unit = r.units.get("bias", "")
        dof_reasons.append(f"bias {b:+.3g} {unit} differs from the expected {expected:+.3g} {unit} (z = {z:+.1f}): "
                           "an unmodelled force (current, tether, thrust offset)")
    # --- methods: steady-state and equation-error against the reported fit
    quad = [n for n in names if n.startswith("quadratic")]
    if r.steady:
        for n in quad:
            if n in r.steady and r.steady[n][1] is not None and math.isfinite(r.steady[n][1] or math.nan):
                vs, ss = r.steady[n]
                zz = (vs - out[n]["value"]) / math.hypot(ss, out[n]["std_fit"]) if (ss or out[n]["std_fit"]) else 0.0
                checks[f"steady_z_{n}"] = zz
                if abs(zz) > 3.0 and abs(vs - out[n]["value"]) > METHODS_MAX * abs(out[n]["value"]):
                    dof_reasons.append(f"steady-state {n} {vs:.4g} disagrees with the transient fit "
                                       f"{out[n]['value']:.4g} (z = {zz:+.1f})")
    # --- direction consistency of the steady windows
    wins = r.signals.get("windows") or []
    if len(wins) >= 4:
        wv = np.array([w[0] for w in wins], dtype=float)
        wf = np.array([w[1] for w in wins], dtype=float)
        pred = _drag(r.dof, r.values, wv)
        scale = np.maximum(np.abs(pred), 0.1 * float(np.max(np.abs(pred))) + 1e-9)
        res = (wf - pred) / scale  # relative misfit of each steady window
        pos, neg = res[wv > 0], res[wv < 0]
        if pos.size >= 2 and neg.size >= 2:
            se = max(math.sqrt(np.var(pos, ddof=1) / pos.size + np.var(neg, ddof=1) / neg.size), 0.01)
            diff = float(np.mean(pos)) - float(np.mean(neg))
            zz = diff / se
            checks["direction_z"] = zz
            if abs(zz) > 4.0 and abs(diff) > DIRECTION_MAX:
                which = "down/up" if r.dof == "heave" else "positive/negative"
                dof_reasons.append(f"{which} steady windows disagree with the model by {100 * np.mean(pos):+.0f} % / "
                                   f"{100 * np.mean(neg):+.0f} % of the force (z = {zz:+.1f})")
    # --- whiteness
    rho = r.signals.get("residual_autocorrelation")
    if rho is not None and math.isfinite(rho):
        checks["residual_lag1"] = float(rho)
        if rho > WHITENESS_MAX:
            dof_reasons.append(f"residuals not white (lag-1 autocorrelation {rho:.2f} > {WHITENESS_MAX})")
    # --- width
    v = np.asarray(r.signals.get("velocity", []), dtype=float)
    v = v[np.isfinite(v)]
    v_typ = float(np.percentile(np.abs(v), 75)) if v.size else 0.0
    total = float(np.mean(np.abs(_drag(r.dof, r.values, np.array([v_typ, -v_typ]), bias=False)))) if v_typ else 0.0
    for n, e in out.items():
        half = 0.5 * (e["ci95"][1] - e["ci95"][0])
        if n in ("inertia", "added_mass") or n.startswith("quadratic") or n == "restoring":
            base = abs(e["value"])
            if n == "added_mass":
                base = abs(out["inertia"]["value"])
            if base > 0 and half / base > WIDTH_MAX:
                e["reasons"].append(f"95 % interval +-{100 * half / base:.0f} % of the value, too wide for controller "
                                    "design")
        elif total > 0:
            contrib = half * (v_typ if n.startswith("linear") else 1.0)
            if contrib / total > WIDTH_MAX:
                e["reasons"].append(f"95 % interval +-{contrib:.3g} at {v_typ:.2f} (typical speed) is "
                                    f"{100 * contrib / total:.0f} % of the damping force there")
    sig = r.signals
    have = all(sig.get(k) is not None for k in ("velocity", "acceleration", "force", "t"))
    h = float(np.median(np.diff(np.asarray(sig["t"], dtype=float)))) if have and len(sig["t"]) > 1 else 0.0
    for n, e in out.items():
        if e["reasons"] and have and h > 0:  # what data would fix it (the same advice as hindrax ident fit)
            half = 0.5 * (e["ci95"][1] - e["ci95"][0])
            e["advice"] = data_advice(r.dof, n, e["value"], half, sig["velocity"], sig["acceleration"], sig["force"],
                                      h)
        e["reasons"] = dof_reasons + e["reasons"]
        e["verdict"] = "suspect" if e["reasons"] else "trusted"
    return {"parameters": out, "verdict": "suspect" if any(e["reasons"] for e in out.values()) else "trusted",
            "reasons": dof_reasons, "checks": checks}


def _drag(dof: str, values: Mapping[str, float], v: np.ndarray, bias: bool = True) -> np.ndarray:
    """Damping (+ bias) force of the identified model at velocities ``v`` (restoring left out)."""
    v = np.asarray(v, dtype=float)
    if dof == "heave":
        kq = np.where(v > 0, values["quadratic_damping_positive"], values["quadratic_damping_negative"])
        kl = np.where(v > 0, values["linear_damping_positive"], values["linear_damping_negative"])
    else:
        kq, kl = values["quadratic_damping"], values["linear_damping"]
    return kq * np.abs(v) * v + kl * v + (values["bias"] if bias else 0.0)


def apply_verdicts(identifications: Mapping[str, Any], cfg: VehicleConfig,
                   thruster_fit_rel: Sequence[float] | None = None) -> dict:
    """:func:`assess_dof` for every DOF, written into each identification (idempotent): ``std`` and ``ci95``
    become the honest ones, the fit-only std moves to ``signals["std_fit"]``, ``signals["assessment"]`` holds
    the verdicts. Returns {dof: assessment}."""
    out = {}
    fresh = []
    for dof, r in identifications.items():
        if "assessment" in r.signals:
            out[dof] = r.signals["assessment"]
            continue
        a = assess_dof(r, cfg, thruster_fit_rel)
        r.signals["std_fit"] = dict(r.std)
        for n, e in a["parameters"].items():
            r.std[n] = e["std"]
            r.ci95[n] = tuple(e["ci95"])
        r.signals["assessment"] = a
        out[dof] = a
        fresh.append(dof)
    heave = out.get("heave")
    if heave is not None and fresh:
        z, tq = heave["checks"].get("bias_z", 0.0), heave["checks"].get("t_quantile", math.inf)
        if abs(z) > tq:
            reason = (f"heave bias differs from the configured net buoyancy (z = {z:+.1f}): the thrust curves do not "
                      "match the vehicle, every thrust-derived parameter is suspect")
            for dof in fresh:
                if dof == "heave":
                    continue
                a = out[dof]
                a["reasons"].append(reason)
                for e in a["parameters"].values():
                    e["reasons"].append(reason)
                    e["verdict"] = "suspect"
                a["verdict"] = "suspect"
    return out


#: DOFs whose online RLS damping std the scenario suite measured (issue 16 item 5). Elsewhere it is not published.
RLS_STD_DOFS = ("surge", "sway", "heave", "yaw")


def rls_published_std(dof: str, names: Sequence[str], theta, converged_std, cfg: VehicleConfig) -> np.ndarray:
    """The online RLS standard deviations worth publishing (p,), NaN = "not converged / not trusted".

    ``converged_std`` (p,): the RLS std where the estimator has converged, NaN elsewhere. Only the damping
    parameters of :data:`RLS_STD_DOFS` keep a number, widened by the thrust-curve uncertainty
    (:func:`thrust_covariance`): in the scenario suite (no disturbance, seed 1) the RLS inertia read 2-5 % low
    (z = -4 to -7) and the bias was off by up to 1.6 N (z = -32), the lag of the causal filter behind the
    acceleration, so their std would not cover the truth; roll and pitch are not in the suite.
    """
    std = np.asarray(converged_std, dtype=float).copy()
    theta = np.asarray(theta, dtype=float)
    keep = np.array([dof in RLS_STD_DOFS and (n.startswith("quadratic") or n.startswith("linear")) for n in names],
                    dtype=bool)
    thrust = np.diag(thrust_covariance(dof, names, theta, _declared_rel(cfg, None)))
    out = np.sqrt(std ** 2 + thrust)
    return np.where(keep & np.isfinite(std), out, np.nan)


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


def free_decay_reason(dof: str, self_propelled: tuple[float, float], free_decay: tuple[float, float],
                      z_max: float = REFERENCE_Z_MAX) -> str | None:
    """The reason text when the free-decay inertia (value, std; kg m^2) contradicts the self-propelled one
    (value, std): |I_sp - I_fd| > ``z_max`` sqrt(std_sp^2 + std_fd^2); None when they agree. Raises ``ValueError``
    for a negative std."""
    (v, sd), (vf, sf) = self_propelled, free_decay
    if sd < 0 or sf < 0:
        raise ValueError(f"{dof}: std must be >= 0, got {sd} and {sf}")
    comb = math.hypot(sd, sf)
    z = (v - vf) / comb if comb > 0 else (0.0 if v == vf else math.copysign(math.inf, v - vf))
    if abs(z) <= z_max:
        return None
    return (f"{dof} inertia {v:.4g} kg m^2 (self-propelled) differs from the free decay's {vf:.4g} +- {sf:.2g} kg m^2 "
            f"(z = {z:+.1f}, beyond {z_max:g} combined std): the thrust curve (or the model) is off in {dof}")


def apply_reference_verdicts(document: dict, z_max: float = REFERENCE_Z_MAX) -> dict:
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
        reason = free_decay_reason(dof, (v, sd), (vf, sf), z_max)
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


def _speed_unit(dof: str) -> str:
    return "rad/s" if dof in ("roll", "pitch", "yaw") else "m/s"


def format_advice(parameter: str, advice: dict) -> str:
    """One printed line of :func:`data_advice` for ``parameter`` (``hindrax ident fit`` and ``ident bag`` alike)."""
    lo, hi, unit = advice["speed_range"]
    return f"  to fix {parameter}: {advice['manoeuvre']}, speeds {lo:g}-{hi:g} {unit}, about " \
           f"{advice['seconds_more']:.0f} s more"


def data_advice(dof: str, name: str, value: float, half_width: float, velocity, acceleration, force,
                h: float, at_bound: bool = False) -> dict:
    """What data would make the 95 % half-width of one parameter ``ADVICE_TARGET`` of its value.

    velocity, acceleration, force (n,): the smoothed velocity, acceleration and input force at the ticks (``h`` s) of
    the segments that were fitted. The variance of an estimate falls as 1 / (seconds of the manoeuvre that informs
    it) (least-squares information adds over independent data), so ``seconds_more = T (w / w_target)^2 - T`` with
    T the seconds of that manoeuvre already in the data (at least :data:`ADVICE_MIN_S`); the manoeuvre per
    parameter (docs/identification.md §4, R1, R2, R15): inertia from accelerating and braking (the 30 % of the
    ticks with the largest |acceleration|), quadratic damping from steady runs in the top half of the speeds
    reached, linear damping from slow runs (below a third of the top speed), the bias from slow runs in both
    directions, restoring from tilts, a reverse thrust gain from reverse commands; heave ``_positive`` is down
    (w > 0), ``_negative`` up. Returns {dof, manoeuvre, speed_range (low, high, unit), seconds_in_data,
    seconds_more, why}."""
    v = np.asarray(velocity, dtype=float)
    a = np.asarray(acceleration, dtype=float)
    f = np.asarray(force, dtype=float)
    ok = np.isfinite(v) & np.isfinite(a) & np.isfinite(f)
    v, a, f = v[ok], a[ok], f[ok]
    unit = _speed_unit(dof)
    sign = 1.0 if name.endswith("_positive") else -1.0 if name.endswith("_negative") else 0.0
    vv = v if sign == 0.0 else np.where(sign * v > 0, np.abs(v), 0.0)
    vmax = float(np.percentile(np.abs(vv), 98)) if vv.size else 0.0
    direction = "" if sign == 0.0 else (" down (w > 0)" if sign > 0 else " up (w < 0)")
    if dof in ("roll", "pitch", "yaw") and sign == 0.0:
        direction = ""
    if name in ("inertia", "added_mass"):
        thr = float(np.percentile(np.abs(a), 70)) if a.size else 0.0
        used = np.abs(a) >= thr if a.size else np.zeros(0, bool)
        man = f"{dof}: start-and-stop runs (accelerate from rest to the top speed, hold, brake), both directions"
        lo, hi = 0.0, vmax
    elif name.startswith("quadratic"):
        used = np.abs(vv) >= 0.5 * vmax if vmax > 0 else np.zeros(v.size, bool)
        hi = max(vmax, 1e-3)
        man = (f"{dof}{direction}: steady runs of 5 s or more in the top half of the speeds "
               "(and faster if the pool allows)")
        lo = 0.5 * hi
    elif name.startswith("linear"):
        used = (np.abs(vv) > 0.05 * vmax) & (np.abs(vv) <= vmax / 3.0) if vmax > 0 else np.zeros(v.size, bool)
        lo, hi = 0.05 * vmax, vmax / 3.0
        man = f"{dof}{direction}: slow steady runs (low speeds, where linear damping dominates)"
    elif name == "bias":
        used = np.abs(v) <= 0.3 * vmax if vmax > 0 else np.ones(v.size, bool)
        lo, hi = 0.0, 0.3 * vmax
        man = f"{dof}: slow runs in both directions and holds (the same speed both ways tells bias from damping)"
    elif name == "restoring":
        used = np.abs(a) > 0
        lo, hi = 0.0, vmax
        man = f"{dof}: tilts of 10-30 degrees and releases (roll/pitch excursions)"
    elif name == "reverse_thrust_gain":
        used = f < 0
        lo, hi = 0.0, vmax
        man = f"{dof}: runs with reverse (negative) commands as long as the forward ones"
    else:
        used = np.abs(v) > 0.05 * vmax if vmax > 0 else np.ones(v.size, bool)
        lo, hi = 0.0, vmax
        man = f"{dof}: runs that move {dof} together with the coupled DOF"
    t_in = float(np.count_nonzero(used)) * h
    if at_bound or not (value != 0.0 and math.isfinite(half_width)):
        more = max(ADVICE_MIN_S, t_in)
        why = (f"held at its physical bound 0: the data cannot tell it from zero; {t_in:.0f} s of that manoeuvre "
               "in the data")
    else:
        ratio = half_width / (ADVICE_TARGET * abs(value))
        more = max(ADVICE_MIN_S, max(t_in, ADVICE_MIN_S) * (ratio ** 2 - 1.0)) if ratio > 1 else 0.0
        why = (f"95 % half-width {100 * half_width / abs(value):.0f} % of the value; {t_in:.0f} s of that manoeuvre "
               f"in the data, the variance falls as 1 / seconds: about {more:.0f} s more for "
               f"+-{100 * ADVICE_TARGET:.0f} %")
    return {"dof": dof, "manoeuvre": man, "speed_range": [round(lo, 3), round(hi, 3), unit],
            "seconds_in_data": round(t_in, 1), "seconds_more": round(float(more), 0), "why": why}


def fit_parameter_verdicts(dof: str, names: Sequence[str], theta, ci95, lower_bounds, fold_theta, std, cv: dict,
                           signals: Mapping[str, Any], h: float, nrmse_max: float = 0.5) -> dict:
    """Verdicts of an output-error fit from the fit core (:mod:`.fit_core`) with the data each suspect parameter
    needs (:func:`data_advice`). Per parameter: suspect when its 95 % interval is wider than :data:`WIDTH_MAX` of the
    value (inertia, quadratic damping, restoring, reverse gain), when it sits on its physical bound (damping 0: not
    shown by the data), or when the fold estimates spread by more than 3 std. DOF-wide: the cross-validated
    prediction nrmse at or above ``nrmse_max``. Returns {"parameters": {name: {verdict, reasons, advice}},
    "reasons": [...], "verdict"}."""
    theta = np.asarray(theta, dtype=float)
    out: dict = {}
    dof_reasons: list[str] = []
    cvn = cv.get("nrmse") if cv else None
    if cvn is not None and math.isfinite(cvn) and cvn >= nrmse_max:
        dof_reasons.append(f"cross-validated prediction nrmse {cvn:.3f} >= {nrmse_max}: the model misses a force "
                           "(current, tether, thrust not as commanded) or the data are mostly noise")
    folds = np.asarray(fold_theta, dtype=float) if fold_theta is not None and len(fold_theta) else None
    for i, n in enumerate(names):
        reasons = []
        lo, hi = ci95[i]
        half = 0.5 * (hi - lo)
        at_bound = np.isfinite(lower_bounds[i]) and lower_bounds[i] == 0.0 and theta[i] <= 1e-9 * max(
            1.0, float(np.max(np.abs(theta))))
        if at_bound:
            reasons.append(f"{n} at its physical bound 0 (the data do not show it)")
        elif n in ("inertia",) or n.startswith("quadratic") or n in ("restoring", "reverse_thrust_gain"):
            if theta[i] != 0 and half / abs(theta[i]) > WIDTH_MAX:
                reasons.append(f"95 % interval +-{100 * half / abs(theta[i]):.0f} % of the value, too wide for "
                               "controller design")
        if folds is not None and folds.shape[0] >= 3:
            good = np.all(np.isfinite(folds), axis=1)
            if good.sum() >= 3:
                spread = float(np.std(folds[good, i], ddof=1))
                if std[i] > 0 and spread > 3 * std[i]:
                    reasons.append(f"fold estimates spread {spread:.3g} > 3 x std {std[i]:.3g}")
        e = {"verdict": "suspect" if (reasons or dof_reasons) else "trusted", "reasons": dof_reasons + reasons}
        if reasons:
            e["advice"] = data_advice(dof, n, float(theta[i]), half, signals["velocity"], signals["acceleration"],
                                      signals["force"], h, at_bound)
        out[n] = e
    verdict = "suspect" if dof_reasons or any(e["verdict"] == "suspect" for e in out.values()) else "trusted"
    return {"parameters": out, "reasons": dof_reasons, "verdict": verdict}
