"""Known-force thrust calibration per thruster group and rotation direction, and the joint
estimation ([Hindrax-Drag] §6; the method, and which direction each manoeuvre turns:
docs/identification.md §6.1-§6.2).

The thrust model has one scale per thruster group and rotation direction (``vertical_forward``,
``vertical_reverse``, ``horizontal_forward``, ``horizontal_reverse``; forward = positive thrust
along the thruster's configured direction, the curve_positive branch; [Hindrax-Drag] eq. 1,
Table 2): the true force of thruster j is s_{g(j), d} F_j, d the sign of its commanded force F_j.
:func:`scale_model` collects the calibration steps' holds as linear Gaussian measurements of the
scales, :func:`thrust_scales` is their posterior, :func:`apply_thrust_calibration` rebuilds a
record's wrenches with the point scales, :func:`attach_thrust_sensitivities` measures how each fit
moves with each scale and :func:`joint_estimate` estimates the scales with every DOF's parameters
([Tarantola2005] Ch. 3).

ASSUMPTION when only one group was measured: the other group's thrusters get the same two scales (``common_*``; a
common cause such as the battery voltage, docs/devices.md §5.3). The RLS comparison values in ``record.online``
stay in curve units."""
from __future__ import annotations

import dataclasses
import math
from typing import Any, Mapping

import numpy as np
from scipy import optimize

from hindrax_bringup.allocation.core import AllocationCore
from hindrax_common.config import DOFS

from hindrax_onboard.estimation.free_decay import fit_quadratic_free_decay
from hindrax_onboard.vehicle.thrust_lag import ThrustLag
from hindrax_onboard.vehicle.uncertainty import DEFAULT_THRUST_UNCERTAINTY_REL, declared_rel
from hindrax_onboard.identification.model.calibration_topic import KNOWN_FORCE_AXES
from hindrax_onboard.identification.model.dof_model import rigid_inertia, thrust_weights
from hindrax_onboard.identification.model.posterior import (DEFAULT_PRIOR_STD_REL, prior_posterior, prior_std_rel_of,
                                                            theta_priors)

__all__ = ["apply_thrust_calibration", "calibration_section", "thrust_scales", "decay_inertia",
           "DEFAULT_PRIOR_STD_REL", "scale_prior_stds", "scale_model", "ScaleModel", "joint_estimate",
           "KNOWN_FORCE_AXES", "GROUPS", "DIRECTIONS", "thruster_groups", "attach_thrust_sensitivities",
           "identify_calibrated", "lagged_parts"]

GROUPS = ("vertical", "horizontal")
DIRECTIONS = ("forward", "reverse")
#: The step that produces each calibration key (an older result may not name it).
_METHOD = {"vertical": "ballast", "vertical_negative": "float", "surge": "line_pull", "surge_negative": "line_pull",
           "sway": "line_pull", "sway_negative": "line_pull"}
#: The thruster group that moves each DOF in a pure single-DOF manoeuvre (:func:`_fallback_weights`).
_DOF_GROUP = {"surge": "horizontal", "sway": "horizontal", "yaw": "horizontal",
              "heave": "vertical", "roll": "vertical", "pitch": "vertical"}
_COLUMNS = {"horizontal": [0, 1, 5], "vertical": [2, 3, 4]}
#: Name of the vertical group's hover constant (the net buoyancy the vertical thrusters hold) in the scale model.
NET_BUOYANCY = "net_buoyancy_n"


def thruster_groups(cfg) -> list[str]:
    """Group of each thruster (allocation order): ``vertical`` when its configured direction is mostly along
    body z (|d_z| >= 0.5), else ``horizontal``."""
    return ["vertical" if abs(float(t.direction_frd[2])) >= 0.5 else "horizontal" for t in cfg.thrusters.thrusters]


def scale_prior_stds(cfg) -> dict[str, float]:
    """1-sigma of the prior N(1, u^2) of each direction's scale: {"forward": u_positive, "reverse": u_negative}
    from the bollard-pull fit's ``thrusters.thrust_fit_uncertainty_rel`` [negative, positive] when the vehicle file
    has it, else the declared ``thrusters.thrust_uncertainty_rel`` (the same choice as the intervals,
    :func:`~...vehicle.uncertainty.declared_rel`)."""
    neg, pos = declared_rel(cfg)
    return {"forward": float(pos), "reverse": float(neg)}


@dataclasses.dataclass
class ScaleModel:
    """The calibration steps as linear Gaussian measurements of the thrust scales (docs/identification.md §6.2).

    names: scale parameters (``<group>_<direction>`` or ``common_<direction>``); nuisance: the constants R (the
    vertical group's ``net_buoyancy_n``, a free one per horizontal step); rows: (coefficients (n_names,), nuisance
    index or -1, right-hand side, std, step key) of ``sum_k c_k s_k - R = rhs``; prior: (n_names, 2) mean and std of
    each scale; nuisance_prior: {nuisance index: (mean, std)} (the weighed net buoyancy)."""

    names: list
    nuisance: list
    rows: list
    prior: np.ndarray
    nuisance_prior: dict

    def parameter(self, group: str, direction: str) -> str:
        """The scale parameter of ``group`` turning in ``direction``."""
        name = f"{group}_{direction}"
        return name if name in self.names else f"common_{direction}"

    def steps_of(self, name: str) -> list[str]:
        """Calibration keys whose measurements involve scale ``name``."""
        k = self.names.index(name)
        return list(dict.fromkeys(key for c, _, _, _, key in self.rows if c[k] != 0.0))

    def solve(self) -> tuple[np.ndarray, np.ndarray]:
        """Posterior mean and covariance of [scales, nuisances] (linear Gaussian: weighted least squares with the
        priors as rows)."""
        ns, nr = len(self.names), len(self.nuisance)
        # the priors as rows of the same form: s_k = mean, and -R = -mean for a nuisance
        eye = np.eye(ns)
        rows = (list(self.rows) + [(eye[k], -1, m, sd, "") for k, (m, sd) in enumerate(self.prior)]
                + [(np.zeros(ns), ri, -m, sd, "") for ri, (m, sd) in self.nuisance_prior.items()])
        a, b = np.zeros((len(rows), ns + nr)), np.zeros(len(rows))
        for i, (c, ri, rhs, sd, _) in enumerate(rows):
            a[i, :ns] = c
            if ri >= 0:
                a[i, ns + ri] = -1.0
            a[i], b[i] = a[i] / sd, rhs / sd
        cov = np.linalg.inv(a.T @ a)
        return cov @ a.T @ b, cov


def _entry(calibration: Mapping[str, Any], key: str) -> Mapping | None:
    v = calibration.get(key) if calibration else None
    if not isinstance(v, Mapping) or "value" not in v:
        return None
    s, sd = float(v["value"]), float(v["std"])
    if not (math.isfinite(s) and s > 0 and math.isfinite(sd) and sd >= 0):
        raise ValueError(f"calibration.{key}: scale must be > 0 with std >= 0, got {s} +- {sd}")
    return v


def scale_model(calibration: Mapping[str, Any] | None, cfg=None) -> ScaleModel | None:
    """The :class:`ScaleModel` of the calibration steps' results (``record.calibration``: keys of
    :data:`KNOWN_FORCE_AXES`), None without any. A result with its holds' forward and reverse parts
    (``forward_force_n``, ``reverse_force_n``) gives one row per hold (docs/identification.md §6.2); an older result
    with only its single scale (``value``, ``std``) measures the mean of the group's two directions. Priors from ``cfg``
    (:func:`scale_prior_stds`; the weighed net buoyancy (rho V - m) g +- ``calibration.net_buoyancy_std_n``); without
    ``cfg`` the default thrust uncertainty and a free net buoyancy. Raises ``ValueError`` on a non-positive scale or a
    zero std."""
    cal = calibration or {}
    entries = {k: e for k in KNOWN_FORCE_AXES if (e := _entry(cal, k)) is not None}
    if not entries:
        return None
    measured = [g for g in GROUPS if any(KNOWN_FORCE_AXES[k][0] == g for k in entries)]
    names = ([f"{g}_{d}" for g in GROUPS for d in DIRECTIONS] if len(measured) == 2
             else [f"common_{d}" for d in DIRECTIONS])
    u = scale_prior_stds(cfg) if cfg is not None else {"forward": DEFAULT_THRUST_UNCERTAINTY_REL[1],
                                                       "reverse": DEFAULT_THRUST_UNCERTAINTY_REL[0]}
    prior = np.array([[1.0, u[n.rsplit("_", 1)[1]]] for n in names])
    model = ScaleModel(names, [], [], prior, {})
    for key, e in entries.items():
        group, _axis, sense = KNOWN_FORCE_AXES[key]
        kf, kr = names.index(model.parameter(group, "forward")), names.index(model.parameter(group, "reverse"))
        if "forward_force_n" in e and "reverse_force_n" in e:
            known = sense * float(e["known_force_n"])
            nuis = NET_BUOYANCY if group == "vertical" else f"{key}_bias_n"
            if nuis not in model.nuisance:
                model.nuisance.append(nuis)
                if nuis == NET_BUOYANCY and cfg is not None:
                    model.nuisance_prior[len(model.nuisance) - 1] = (
                        float(cfg.buoyancy_n - cfg.weight_n), float(cfg.known_forces.net_buoyancy_std_n))
            ri = model.nuisance.index(nuis)
            for h, ext in enumerate((0.0, known)):
                sd = float(e["holding_force_std_n"][h])
                if not (math.isfinite(sd) and sd > 0):
                    raise ValueError(f"calibration.{key}: a holding force std must be > 0, got {sd}")
                c = np.zeros(len(names))
                c[kf], c[kr] = float(e["forward_force_n"][h]), float(e["reverse_force_n"][h])
                model.rows.append((c, ri, -ext, sd, key))
        else:
            sd = float(e["std"])
            if not sd > 0:
                raise ValueError(f"calibration.{key}: a scale std must be > 0 for the joint estimate, got {sd}")
            c = np.zeros(len(names))
            c[kf] = c[kr] = 0.5
            model.rows.append((c, -1, float(e["value"]), sd, key))
    return model


def thrust_scales(calibration: Mapping[str, Any] | None, cfg=None) -> dict[str, dict]:
    """{scale: {value, std, source}} of the calibration alone (:func:`scale_model`, its posterior), plus
    ``<group>_mean`` entries (the mean of the group's two directions, what a symmetric manoeuvre uses) and
    ``net_buoyancy_n`` when the vertical group was measured per hold; {} without a calibration. Raises
    ``ValueError`` on a bad scale."""
    model = scale_model(calibration, cfg)
    if model is None:
        return {}
    x, cov = model.solve()
    ns = len(model.names)
    out: dict = {}
    for k, n in enumerate(model.names):
        steps = model.steps_of(n)
        src = ("steps " + ", ".join(steps) if steps else "prior only (not measured)")
        if n.startswith("common_"):
            src += "; ASSUMPTION: the same for both thruster groups (only one measured)"
        out[n] = {"value": float(x[k]), "std": float(math.sqrt(cov[k, k])), "source": src}
    for g in dict.fromkeys(n.rsplit("_", 1)[0] for n in model.names):
        a = np.zeros(ns + len(model.nuisance))
        a[model.names.index(f"{g}_forward")] = a[model.names.index(f"{g}_reverse")] = 0.5
        out[f"{g}_mean"] = {"value": float(a @ x), "std": float(math.sqrt(a @ cov @ a)),
                            "source": "mean of the two directions"}
    if NET_BUOYANCY in model.nuisance:
        i = ns + model.nuisance.index(NET_BUOYANCY)
        out[NET_BUOYANCY] = {"value": float(x[i]), "std": float(math.sqrt(cov[i, i])),
                             "source": "hover holds (weighed net buoyancy as prior)"
                             if model.nuisance_prior else "hover holds"}
    return out


def _thruster_scales(model: ScaleModel, x: np.ndarray, cfg) -> tuple[np.ndarray, np.ndarray]:
    """(forward, reverse) scale of each thruster (m,) from the scale vector ``x``."""
    groups = thruster_groups(cfg)
    fwd = np.array([x[model.names.index(model.parameter(g, "forward"))] for g in groups])
    rev = np.array([x[model.names.index(model.parameter(g, "reverse"))] for g in groups])
    return fwd, rev


def lagged_parts(record: Any) -> tuple[np.ndarray, np.ndarray]:
    """The commanded thruster forces of ``record`` (``thrust_cmd_n``, (n, m) N) split into their positive and
    negative parts, each through the first-order thrust lag ``record.time_constant_s`` over the tick intervals
    (zero before the first tick, as the executive and :mod:`..bag_input.from_bag` lag them): (forward, reverse), (n, m)
    each, the value at each tick."""
    f = np.asarray(record.thrust_cmd_n, dtype=float)
    t = np.asarray(record.t_s, dtype=float)
    parts = np.stack([np.maximum(f, 0.0), np.minimum(f, 0.0)])  # (2, n, m)
    out = np.zeros_like(parts)
    lag = ThrustLag(float(record.time_constant_s))
    for i in range(1, f.shape[0]):
        out[:, i] = lag.advance(out[:, i - 1], parts[:, i - 1], float(t[i] - t[i - 1]))
    return out[0], out[1]


def _has_thrust(record: Any) -> bool:
    f = getattr(record, "thrust_cmd_n", None)
    return f is not None and np.ndim(f) == 2 and np.shape(f)[0] == np.size(record.t_s) and np.shape(f)[1] > 0


def _rebuild(record: Any, cfg, fwd: np.ndarray, rev: np.ndarray) -> Any:
    """``record`` with its wrenches rebuilt from ``thrust_cmd_n`` with per-thruster forward / reverse scales (m,)."""
    b = np.asarray(AllocationCore(cfg).matrix_frd, dtype=float)
    f = np.asarray(record.thrust_cmd_n, dtype=float)
    lp, ln = lagged_parts(record)
    wc = (np.where(f >= 0.0, fwd, rev) * f) @ b.T
    w = (fwd * lp + rev * ln) @ b.T
    return dataclasses.replace(record, wrench_frd=w, wrench_cmd_frd=wc)


def apply_thrust_calibration(record: Any, calibration: Mapping[str, Any] | None = None, cfg=None) -> Any:
    """A copy of ``record`` (:class:`~..bag_input.campaign_record.CampaignRecord`) whose wrenches (n, 6) are rebuilt
    with the calibration's point scales (:func:`thrust_scales`; ``calibration`` default ``record.calibration``): from
    the commanded thruster forces ``thrust_cmd_n`` times the scale of each thruster's group and direction, lagged as the
    executive does (:func:`lagged_parts`), times the thrust allocation matrix of ``cfg``. A record without
    ``thrust_cmd_n`` (or without ``cfg``) gets each group's wrench columns (vertical: Z, K, M; horizontal: X, Y, N)
    times the mean of its two directions. The record itself without a calibration. Raises ``ValueError`` on a
    non-positive scale."""
    cal = record.calibration if calibration is None else calibration
    model = scale_model(cal, cfg)
    if model is None:
        return record
    x, _ = model.solve()
    if cfg is not None and _has_thrust(record):
        return _rebuild(record, cfg, *_thruster_scales(model, x, cfg))
    factor = np.ones(6)
    for group, cols in _COLUMNS.items():
        p = (model.parameter(group, "forward"), model.parameter(group, "reverse"))
        factor[cols] = 0.5 * (x[model.names.index(p[0])] + x[model.names.index(p[1])])
    return dataclasses.replace(record, wrench_frd=np.asarray(record.wrench_frd) * factor,
                               wrench_cmd_frd=np.asarray(record.wrench_cmd_frd) * factor)


def _fallback_weights(dof: str, names) -> dict[str, np.ndarray]:
    """First-order guess of each parameter's weights on its group's two directions when the fit's
    sensitivity was not measured (:func:`attach_thrust_sensitivities` not run): the declared thrust
    uncertainty's weights (:func:`~.dof_model.thrust_weights`)."""
    w = thrust_weights(dof, names)  # (p, 2): [positive, negative]
    g = _DOF_GROUP[dof]
    return {f"{g}_forward": w[:, 0].copy(), f"{g}_reverse": w[:, 1].copy()}


def _affecting(record: Any, cfg, model: ScaleModel, dofs) -> dict[str, list[str]]:
    """Per DOF, the scale parameters whose thrusters put force on the DOF's axis during its window (model order)."""
    f = np.asarray(record.thrust_cmd_n, dtype=float)
    b = np.asarray(AllocationCore(cfg).matrix_frd, dtype=float)
    groups = thruster_groups(cfg)
    out = {}
    for dof in dofs:
        sl = record.dof_slice(dof)
        k = DOFS.index(dof)
        used = set()
        for j, g in enumerate(groups):
            col = f[sl, j] * b[k, j]
            if np.any((f[sl, j] > 0) & (col != 0)):
                used.add(model.parameter(g, "forward"))
            if np.any((f[sl, j] < 0) & (col != 0)):
                used.add(model.parameter(g, "reverse"))
        out[dof] = [n for n in model.names if n in used]
    return out


def attach_thrust_sensitivities(record: Any, identifications: Mapping[str, Any], cfg, identify,
                                calibration: Mapping[str, Any] | None = None, step: float = 0.02) -> None:
    """Measure how each DOF's fit moves with each thrust scale: ``signals["thrust_sensitivity"]`` =
    {scale: (p,) d theta / d s} (the interface to :func:`joint_estimate`), in place.

    ``identifications`` were fitted by ``identify(record', cfg)`` on ``record'`` = ``record``
    rebuilt with the calibration's point scales s_c (:func:`apply_thrust_calibration`). For each DOF
    and each scale whose thrusters push on its axis during its window (from ``thrust_cmd_n``), the
    fit is repeated with that scale raised by ``step`` (relative):
    d theta / d s_n = (theta' - theta) / (step s_n); the last scale follows from the model's
    homogeneity, sum_n s_n d theta / d s_n = theta (docs/identification.md §6.2). Nothing is done
    without a calibration or without ``thrust_cmd_n``."""
    cal = record.calibration if calibration is None else calibration
    model = scale_model(cal, cfg)
    if model is None or not _has_thrust(record) or not identifications:
        return
    x, _ = model.solve()
    s_c = x[:len(model.names)]
    affecting = _affecting(record, cfg, model, list(identifications))
    sens = {d: {} for d in identifications}
    for j, name in enumerate(model.names):
        dofs = [d for d, a in affecting.items() if name in a[:-1]]
        if not dofs:
            continue
        xp = x.copy()
        xp[j] *= 1.0 + step
        rec = _rebuild(record, cfg, *_thruster_scales(model, xp, cfg))
        rec = dataclasses.replace(rec, windows={d: w for d, w in record.windows.items() if d in dofs})
        refit, _errors = identify(rec, cfg)
        for d in dofs:
            r, r2 = identifications[d], refit.get(d)
            if r2 is None:
                continue
            sens[d][name] = np.array([(r2.values[n] - r.values[n]) / (step * s_c[j]) for n in r.names])
    for d, r in identifications.items():
        a = affecting.get(d, [])
        if not a or any(n not in sens[d] for n in a[:-1]):
            continue  # a refit failed: no measured sensitivity (joint_estimate falls back)
        theta = np.array([r.values[n] for n in r.names])
        last = a[-1]
        rest = sum(s_c[model.names.index(n)] * sens[d][n] for n in a[:-1]) if len(a) > 1 else 0.0
        sens[d][last] = (theta - rest) / s_c[model.names.index(last)]
        r.signals["thrust_sensitivity"] = {n: [float(v) for v in sens[d][n]] for n in a}


def identify_calibrated(record: Any, cfg, identify) -> tuple[dict, dict]:
    """({dof: DofIdentification}, {dof: error}) of ``record`` with its calibration applied
    (:func:`apply_thrust_calibration`) and each DOF's sensitivity to the thrust scales measured
    (:func:`attach_thrust_sensitivities`), ready for :func:`joint_estimate`. identify: called as
    identify(record, cfg) (:func:`~.campaign_fit.identify_all_with_errors`; passed in, as
    campaign_fit depends on this module through results)."""
    idents, errors = identify(apply_thrust_calibration(record, cfg=cfg), cfg)
    attach_thrust_sensitivities(record, idents, cfg, identify)
    return idents, errors


def calibration_section(calibration: Mapping[str, Any] | None, cfg=None) -> dict:
    """The ``calibration`` section of identification.yaml: ``thrust_scales`` (the calibration's own posterior per
    group and direction, the group means and the hover's net buoyancy, :func:`thrust_scales`) and ``steps`` (each
    raw step result: scale, known force, holding forces and their forward/reverse parts)."""
    sc = thrust_scales(calibration, cfg)
    if not sc:
        return {}

    def plain(d):
        return {k: ([float(x) for x in v] if isinstance(v, (list, tuple)) else
                    (float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else v)) for k, v in d.items()}

    return {"thrust_scales": {k: plain(v) for k, v in sc.items()},
            "steps": {k: plain(dict(calibration[k])) for k in KNOWN_FORCE_AXES if k in calibration}}


def decay_inertia(record: Any, dof: str, stiffness_n_m_per_rad: float, stiffness_std: float = 0.0,
                  rigid_inertia_kg_m2: float | None = None) -> dict:
    """Rigid + added inertia of ``dof`` (roll | pitch) from the campaign's free decay.

    The de-biased gyro rate of the recorded window ``record.decays[dof]`` (from its largest excursion on) is
    fitted with I x'' + b1 x' + b2 |x'| x' + C x = 0 (:func:`~hindrax_onboard.estimation.free_decay.
    fit_quadratic_free_decay`, output = velocity), C the restoring stiffness of an inclining test (``hindrax ident
    inclining``). The thrusters only tilted the vehicle, so the result does not depend on the thrust curve.
    Returns {total_inertia_kg_m2, total_inertia_kg_m2_std (fit and C's std combined), total_inertia_kg_m2_std_fit,
    added_inertia_kg_m2 (None without the rigid inertia), linear_damping_kg_m2_s, quadratic_damping_kg_m2 (with
    _std), stiffness_n_m_per_rad, window_s}. Raises ``KeyError`` when the DOF has no recorded decay and
    :class:`~hindrax_onboard.estimation.least_squares.EstimationError` when the fit fails."""
    t0, t1 = record.decays[dof]
    k = {"roll": 0, "pitch": 1}[dof]
    rows = [(s, r[k]) for s, r in record.sensors["gyro"] if t0 <= s <= t1 and math.isfinite(r[k])]
    t = np.array([a for a, _ in rows])
    y = np.array([b for _, b in rows])
    i0 = int(np.argmax(np.abs(y - np.median(y)))) if y.size else 0
    fit = fit_quadratic_free_decay(t[i0:], y[i0:], stiffness_n_m_per_rad, rigid_inertia=rigid_inertia_kg_m2,
                                   output="velocity")
    std = math.hypot(fit.total_inertia_std, fit.total_inertia * float(stiffness_std) / float(stiffness_n_m_per_rad))
    return {"total_inertia_kg_m2": fit.total_inertia, "total_inertia_kg_m2_std": std,
            "total_inertia_kg_m2_std_fit": fit.total_inertia_std,
            "added_inertia_kg_m2": None if math.isnan(fit.added_inertia) else fit.added_inertia,
            "linear_damping_kg_m2_s": fit.linear_damping, "linear_damping_kg_m2_s_std": fit.linear_damping_std,
            "quadratic_damping_kg_m2": fit.quadratic_damping,
            "quadratic_damping_kg_m2_std": fit.quadratic_damping_std,
            "stiffness_n_m_per_rad": float(stiffness_n_m_per_rad), "stiffness_std": float(stiffness_std),
            "window_s": [float(t0), float(t1)]}


# Joint estimation: thrust scales and empirical priors as unknowns (docs/identification.md §6.2-3)

def _sensitivity_matrix(r, model: ScaleModel, s_c: np.ndarray) -> np.ndarray:
    """(p, n_scales) d theta / d s of a DOF's parameters at the point scales s_c: the measured
    ``signals["thrust_sensitivity"]`` (:func:`attach_thrust_sensitivities`), else theta w / sigma(s_c) from the
    first-order weights w of :func:`_fallback_weights` (merged onto ``common_*`` when one scale serves both groups)."""
    names = list(r.names)
    theta = np.array([r.values[n] for n in names], dtype=float)
    g = np.zeros((len(names), len(model.names)))
    meas = r.signals.get("thrust_sensitivity")
    if meas:
        for nm, v in meas.items():
            g[:, model.names.index(nm)] += np.asarray(v, dtype=float)
        return g
    w = np.zeros_like(g)
    for nm, v in _fallback_weights(r.dof, names).items():
        gr, d = nm.rsplit("_", 1)
        w[:, model.names.index(model.parameter(gr, d))] += np.asarray(v, dtype=float)
    return theta[:, None] * w / (w @ s_c)[:, None]


def joint_estimate(identifications: Mapping[str, Any], cfg, calibration: Mapping[str, Any] | None = None,
                   prior_std_rel: float | None = None) -> dict:
    """Bayesian (regularised) least squares of the thrust scales, the empirical priors and the manoeuvres' fits
    together (docs/identification.md §6.2-§6.3; [Tarantola2005] Ch. 3), written into the identifications.

    ``identifications``: {dof: :class:`~.dof_model.DofIdentification`} fitted on the record rebuilt
    with the calibration's point scales s_c (:func:`apply_thrust_calibration`; the record as
    recorded without one), each with its sensitivity ``signals["thrust_sensitivity"]``
    = G = d theta / d s (:func:`attach_thrust_sensitivities`; else the first-order guess of
    :func:`_sensitivity_matrix`) and its fit covariance ``signals["covariance"]``.
    theta(s) = theta_0 + G (s - s_c); the joint problem over [theta_0 of every DOF, the scales,
    the nuisance constants of :func:`scale_model`] is the S(x) of docs/identification.md §6.2, its
    covariance (J^T J)^-1 at the optimum and theta's by the delta method. Without a calibration
    the scales stay 1 and the problem separates into :func:`~.posterior.prior_posterior` per DOF;
    the thrust-curve uncertainty is then added by :func:`~..assessment.verdicts.assess_dof`.

    ``prior_std_rel``: default ``identification.prior_std_rel`` (or :data:`~.posterior.DEFAULT_PRIOR_STD_REL`); 0
    leaves the priors out. Idempotent (a DOF with ``signals["joint"]`` is left alone). Returns the ``joint`` section of
    identification.yaml: {scales: {name: {value, std, prior: [1, u], measurements: [{step, value, std}], dofs}},
    group_means: {group: {value, std}}, net_buoyancy_n (with a per-hold vertical calibration), prior_std_rel,
    method}. Raises ``ValueError`` on a bad calibration scale or ``prior_std_rel`` < 0."""
    prior_std_rel = prior_std_rel_of(cfg, prior_std_rel)
    model = scale_model(calibration, cfg)
    ns = len(model.names) if model else 0
    z_c = model.solve()[0] if model else np.zeros(0)   # the point scales (and constants) the record was rebuilt with
    s_c = z_c[:ns]
    todo = [d for d, r in identifications.items() if "joint" not in r.signals and "assessment" not in r.signals]
    blocks = []  # (dof, names, theta_fit, Linv, priors, slice, G (p, ns) or None, fit covariance)
    k = 0
    for dof in todo:
        r = identifications[dof]
        names = list(r.names)
        y = np.array([r.values[n] for n in names], dtype=float)
        cov_y = r.signals.get("covariance")
        if cov_y is None or np.shape(cov_y) != (len(names), len(names)):
            cov_y = np.diag([r.std[n] ** 2 for n in names])
        cov = np.asarray(cov_y, dtype=float)
        cov = 0.5 * (cov + cov.T) + np.eye(len(names)) * 1e-18 * max(1.0, float(np.max(np.abs(np.diag(cov)))))
        linv = np.linalg.inv(np.linalg.cholesky(cov))
        g = _sensitivity_matrix(r, model, s_c) if model else None
        blocks.append((dof, names, y, linv, theta_priors(dof, names, cfg, prior_std_rel),
                       slice(k, k + len(names)), g, cov_y))
        k += len(names)
    if not blocks:
        return {}
    n_th = k
    rows = model.rows if model else []
    nuis_prior = model.nuisance_prior if model else {}
    prior = model.prior if model else np.zeros((0, 2))

    def theta_of(x, sl, g):
        return x[sl] if g is None else x[sl] + g @ (x[n_th:n_th + ns] - s_c)

    def residuals(x):
        s, rr = x[n_th:n_th + ns], x[n_th + ns:]
        out = []
        for _, names, y, linv, pri, sl, g, _c in blocks:
            out.append(linv @ (x[sl] - y))
            th = theta_of(x, sl, g)
            for i, n in enumerate(names):
                if n in pri:
                    out.append(np.array([(th[i] - pri[n][0]) / pri[n][1]]))
        out.append((s - prior[:, 0]) / prior[:, 1])
        out.append(np.array([(c @ s - (rr[ri] if ri >= 0 else 0.0) - rhs) / sd for c, ri, rhs, sd, _ in rows]))
        out.append(np.array([(rr[ri] - m) / sd for ri, (m, sd) in nuis_prior.items()]))
        return np.concatenate(out)

    x0 = np.concatenate([b[2] for b in blocks] + [z_c])
    if model is None:  # no scales: the problem separates into the per-DOF update of posterior.prior_posterior
        x = x0.copy()
        cx = np.zeros((n_th, n_th))
        for _dof, names, y, _, pri, sl, _g, cov_y in blocks:
            x[sl], cx[sl, sl] = prior_posterior(names, y, cov_y, pri)
    else:
        sol = optimize.least_squares(residuals, x0, method="lm", xtol=1e-14, ftol=1e-14)
        J = sol.jac
        cx = np.linalg.inv(J.T @ J)
        x = sol.x
    s = x[n_th:n_th + ns]
    for dof, names, y, _, pri, sl, g, _c in blocks:
        r = identifications[dof]
        p = len(names)
        idx = list(range(sl.start, sl.stop)) + list(range(n_th, n_th + ns))
        T = np.zeros((p, p + ns))
        T[:, :p] = np.eye(p)
        if g is not None:
            T[:, p:] = g
        cov = T @ cx[np.ix_(idx, idx)] @ T.T
        theta = theta_of(x, sl, g)
        cov_y = r.signals.get("covariance")
        fit_sd = (np.sqrt(np.clip(np.diag(cov_y), 0.0, None)) if cov_y is not None and np.shape(cov_y) == (p, p)
                  else np.array([r.std[n] for n in names]))
        used = [] if g is None else [model.names[j] for j in range(ns) if np.any(g[:, j] != 0.0)]
        r.signals["joint"] = {
            "fit_values": {n: float(v) for n, v in zip(names, y)},
            "fit_std": {n: float(v) for n, v in zip(names, fit_sd)},
            "priors": {n: [m, sd] for n, (m, sd) in pri.items()},
            "scale_parameter": ", ".join(used) if used else None,
            "thrust_sensitivity": None if g is None else {model.names[j]: [float(v) for v in g[:, j]]
                                                          for j in range(ns) if model.names[j] in used},
            "sensitivity_source": None if g is None else ("measured (refits)" if r.signals.get("thrust_sensitivity")
                                                          else "first-order weights (not measured)"),
            "thrust_in_covariance": g is not None}
        r.signals["covariance"] = cov
        for n, v, sd in zip(names, theta, np.sqrt(np.clip(np.diag(cov), 0.0, None))):
            r.values[n] = float(v)
            r.std[n] = float(sd)
        r.values["added_mass"] = r.values["inertia"] - rigid_inertia(cfg, dof)
        r.std["added_mass"] = r.std["inertia"]
    sec = {"prior_std_rel": float(prior_std_rel),
           "method": ("Bayesian least squares ([Tarantola2005] Ch. 3; docs/identification.md §6.2): each DOF's "
                      "output-error fit as a Gaussian measurement of its parameters at the calibration's point "
                      "scales, theta(s) = theta_0 + G (s - s_c) with G the fit's measured sensitivity to each scale; "
                      "one scale per thruster group and rotation direction with prior N(1, u^2) and the calibration "
                      "holds as measurements; the empirical priors on theta; covariance (J^T J)^-1 at the optimum"),
           "scales": {}}
    if model is None:
        return sec
    cal = calibration or {}
    cs = cx[n_th:n_th + ns, n_th:n_th + ns]
    for j, name in enumerate(model.names):
        meas = [{"step": f"{cal[key].get('method', _METHOD[key])} {key}", "value": float(cal[key]["value"]),
                 "std": float(cal[key]["std"])} for key in model.steps_of(name)]
        sec["scales"][name] = {"value": float(s[j]), "std": float(math.sqrt(cs[j, j])),
                               "prior": [float(model.prior[j, 0]), float(model.prior[j, 1])],
                               "measurements": meas,
                               "dofs": [b[0] for b in blocks if b[6] is not None and np.any(b[6][:, j] != 0.0)]}
    sec["group_means"] = {}
    for grp in dict.fromkeys(n.rsplit("_", 1)[0] for n in model.names):
        a = np.zeros(ns)
        a[model.names.index(f"{grp}_forward")] = a[model.names.index(f"{grp}_reverse")] = 0.5
        sec["group_means"][grp] = {"value": float(a @ s), "std": float(math.sqrt(a @ cs @ a))}
    if NET_BUOYANCY in model.nuisance:
        i = n_th + ns + model.nuisance.index(NET_BUOYANCY)
        pr = model.nuisance_prior.get(model.nuisance.index(NET_BUOYANCY))
        sec[NET_BUOYANCY] = {"value": float(x[i]), "std": float(math.sqrt(cx[i, i])),
                             "prior": None if pr is None else [float(pr[0]), float(pr[1])]}
    return sec
