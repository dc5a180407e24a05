"""Known-force thrust calibration and joint estimation (issue 17 items 1-3, 5; [Hindrax-Drag] §6).

A self-propelled test only sees force / inertia and force / damping: if every thruster gives s times its curve,
inertia, damping and bias all come out s times too (docs/identification.md). The ballast step of the executive
(:meth:`~.executive.Executive._ballast`) measures s against a known weight; here it enters the identification:

* :func:`apply_thrust_calibration` returns the record with its thrust-model wrenches (``wrench_frd``,
  ``wrench_cmd_frd``) multiplied by the calibrated point scale, so that the fits come out near physical units.
* :func:`joint_estimate` then estimates the scales as parameters together with every DOF's parameters: prior
  N(1, sigma_s^2) from ``thrusters.thrust_uncertainty_rel``, each calibration step a measurement, the empirical
  priors ([NTNU-Thesis] App. A, weight ``identification.prior_std_rel``) on the physical parameters, and
  each DOF's fit in curve units phi = theta / s (the model is linear in 1/s: an exact reparametrisation) as a
  Gaussian measurement; Bayesian least squares ([Tarantola2005] Ch. 3; docs/identification.md §6.2-§6.3). The
  reported intervals carry the calibration's own uncertainty; :func:`~.verdicts.assess_dof` then adds no second
  thrust term. (:func:`calibration_relative_std` is the former, first-order shortcut: the scale's relative std.)

Scales: ``vertical`` (ballast: heave, roll, pitch columns Z, K, M, the vertical thrusters) and ``horizontal``
(line pull in surge and sway, their inverse-variance mean: X, Y, N, the horizontal thrusters). ASSUMPTION when only
one of the two was measured: the other thrusters get the same scale (a common cause such as the battery voltage,
docs/devices.md §5.3); the section says so. The RLS comparison values in ``record.online`` stay in curve units.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any, Mapping

import numpy as np

__all__ = ["apply_thrust_calibration", "calibration_relative_std", "calibration_section", "thrust_scales",
           "DOF_GROUP", "decay_inertia", "DEFAULT_PRIOR_STD_REL", "scale_prior_std", "scale_measurements",
           "joint_estimate"]

#: Which thrusters (scale) act in each DOF, and the wrench columns of each group.
DOF_GROUP = {"surge": "horizontal", "sway": "horizontal", "yaw": "horizontal",
             "heave": "vertical", "roll": "vertical", "pitch": "vertical"}
_COLUMNS = {"horizontal": [0, 1, 5], "vertical": [2, 3, 4]}
#: Calibration keys of the known-force steps -> (thruster group, FRD axis index, sense of the known force).
KNOWN_FORCE_AXES = {"vertical": ("vertical", 2, 1), "vertical_negative": ("vertical", 2, -1),
                    "surge": ("horizontal", 0, 1), "surge_negative": ("horizontal", 0, -1),
                    "sway": ("horizontal", 1, 1), "sway_negative": ("horizontal", 1, -1)}


def _entry(calibration: Mapping[str, Any], key: str) -> tuple[float, float] | None:
    v = calibration.get(key) if calibration else None
    if not isinstance(v, Mapping) or "value" not in v:
        return None
    s, sd = float(v["value"]), float(v["std"])
    if not (math.isfinite(s) and s > 0 and math.isfinite(sd) and sd >= 0):
        raise ValueError(f"calibration.{key}: scale must be > 0 with std >= 0, got {s} +- {sd}")
    return s, sd


def thrust_scales(calibration: Mapping[str, Any] | None) -> dict[str, dict]:
    """{"vertical"|"horizontal": {value, std, source}} from the raw step results (``vertical`` from the ballast;
    ``surge``/``sway`` line pulls -> ``horizontal``, inverse-variance mean); a group without its own measurement
    takes the other's (source says "assumed"). {} without any calibration. Raises ``ValueError`` on a bad scale."""
    cal = calibration or {}
    out: dict[str, dict] = {}
    v = _entry(cal, "vertical")
    if v is not None:
        out["vertical"] = {"value": v[0], "std": v[1], "source": "ballast"}
    hs = [(k, e) for k in ("surge", "sway") if (e := _entry(cal, k)) is not None]
    if hs:
        w = np.array([1.0 / max(e[1], 1e-12) ** 2 for _, e in hs])
        val = float(np.sum(w * [e[0] for _, e in hs]) / np.sum(w))
        out["horizontal"] = {"value": val, "std": float(1.0 / math.sqrt(np.sum(w))),
                             "source": "line pull (" + ", ".join(k for k, _ in hs) + ")"}
    if len(out) == 1:
        have, other = next(iter(out)), ("horizontal" if "vertical" in out else "vertical")
        out[other] = dict(out[have], source=f"assumed equal to the {have} scale (not measured)")
    return out


def apply_thrust_calibration(record: Any, calibration: Mapping[str, Any] | None = None) -> Any:
    """A copy of ``record`` (:class:`~.executive.CampaignRecord`) with both wrench arrays (n, 6) scaled per
    thruster group (:func:`thrust_scales`; ``calibration`` default ``record.calibration``); the record itself
    without a calibration. Raises ``ValueError`` on a non-positive scale."""
    cal = record.calibration if calibration is None else calibration
    sc = thrust_scales(cal)
    if not sc:
        return record
    factor = np.ones(6)
    for group, cols in _COLUMNS.items():
        factor[cols] = sc[group]["value"]
    return dataclasses.replace(record, wrench_frd=np.asarray(record.wrench_frd) * factor,
                               wrench_cmd_frd=np.asarray(record.wrench_cmd_frd) * factor)


def calibration_relative_std(calibration: Mapping[str, Any] | None, dof: str = "heave") -> list[float] | None:
    """[negative, positive] relative 1-sigma thrust uncertainty of ``dof``'s thrusters after calibration, or None."""
    sc = thrust_scales(calibration)
    if not sc:
        return None
    g = sc[DOF_GROUP[dof]]
    rel = g["std"] / g["value"]
    return [rel, rel]


def calibration_section(calibration: Mapping[str, Any] | None) -> dict:
    """The ``calibration`` section of identification.yaml: ``vertical_thrust_scale`` / ``horizontal_thrust_scale``
    ({value, std, source} plus, for a measured one, the step's known force and holding forces) and each raw step
    (``surge``/``sway`` line pulls)."""
    sc = thrust_scales(calibration)
    if not sc:
        return {}

    def plain(d):
        return {k: ([float(x) for x in v] if isinstance(v, (list, tuple)) else
                    (float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else v)) for k, v in d.items()}

    out = {}
    for group in ("vertical", "horizontal"):
        e = dict(sc[group])
        if group == "vertical" and "vertical" in calibration:
            e = {**dict(calibration["vertical"]), **e}
        out[f"{group}_thrust_scale"] = plain(e)
    for axis in ("surge", "sway"):
        if axis in calibration:
            out[f"line_pull_{axis}"] = plain(dict(calibration[axis]))
    return out


def decay_inertia(record: Any, dof: str, stiffness_n_m_per_rad: float, stiffness_std: float = 0.0,
                  rigid_inertia_kg_m2: float | None = None) -> dict:
    """Rigid + added inertia of ``dof`` (roll | pitch) from the campaign's free decay (issue 17 item 3).

    The de-biased gyro rate of the recorded window ``record.decays[dof]`` (from its largest excursion on) is
    fitted with I x'' + b1 x' + b2 |x'| x' + C x = 0 (:func:`~hindrax_ident.estimation.free_decay.
    fit_quadratic_free_decay`, output = velocity), C the restoring stiffness of an inclining test (``hindrax ident
    inclining``). The thrusters only tilted the vehicle, so the result does not depend on the thrust curve.
    Returns {total_inertia_kg_m2, total_inertia_kg_m2_std (fit and C's std combined), total_inertia_kg_m2_std_fit,
    added_inertia_kg_m2 (None without the rigid inertia), linear_damping_kg_m2_s, quadratic_damping_kg_m2 (with
    _std), stiffness_n_m_per_rad, window_s}. Raises ``KeyError`` when the DOF has no recorded decay and
    :class:`~hindrax_ident.estimation.least_squares.EstimationError` when the fit fails.
    """
    from ..estimation.free_decay import fit_quadratic_free_decay

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


# ---------------------------------------------------------------------------------------------------------------
# Joint estimation: thrust scales and empirical priors as parameters (issue 17 items 2 and 5; docs/identification.md
# §6.2-§6.3)
# ---------------------------------------------------------------------------------------------------------------

#: Default 1-sigma of an empirical prior as a fraction of the prior's value (``identification.prior_std_rel``).
DEFAULT_PRIOR_STD_REL = 0.5


def scale_prior_std(cfg) -> float:
    """1-sigma of the prior on a thruster group's scale s (prior mean 1): the RMS of the relative thrust
    uncertainty of the two directions, [negative, positive] (a group scale weighs both directions alike): the
    bollard-pull fit's ``thrusters.thrust_fit_uncertainty_rel`` when the vehicle file has it, else the declared
    ``thrusters.thrust_uncertainty_rel`` (the same choice as the intervals, :func:`~.verdicts._declared_rel`)."""
    from .verdicts import _declared_rel

    neg, pos = _declared_rel(cfg, None)
    return math.sqrt(0.5 * (neg * neg + pos * pos))


def scale_measurements(calibration: Mapping[str, Any] | None) -> dict[str, list[tuple[str, float, float]]]:
    """The calibration steps as measurements of the scale parameters: {parameter: [(step, value, std), ...]}.

    Parameters: ``vertical`` (ballast) and ``horizontal`` (each line pull, surge and sway, is one measurement of
    it) when both groups were measured; when only one group was, a single ``common`` scale for all thrusters
    (the ASSUMPTION of :func:`thrust_scales`). {} without a calibration. Raises ``ValueError`` on a bad scale."""
    cal = calibration or {}
    groups: dict[str, list] = {}
    v = _entry(cal, "vertical")
    if v is not None:
        groups["vertical"] = [("ballast", v[0], v[1])]
    hs = [("line pull " + k, *e) for k in ("surge", "sway") if (e := _entry(cal, k)) is not None]
    if hs:
        groups["horizontal"] = hs
    if len(groups) == 1:
        return {"common": next(iter(groups.values()))}
    return groups


def _scale_parameter(groups: Mapping[str, Any], dof: str) -> str | None:
    if not groups:
        return None
    return "common" if "common" in groups else DOF_GROUP[dof]


def _rigid_inertia(cfg, dof: str) -> float:
    """Rigid-body mass or moment of inertia of ``dof`` about the body origin, diag of M_RB (as
    :func:`~.estimators.rigid_inertia`; not imported from there: estimators -> results -> calibration)."""
    from hindrax_drivers.config import DOFS

    from ..sim.model import rigid_body_mass_matrix

    m = rigid_body_mass_matrix(cfg.mass_kg, cfg.centre_of_gravity_frd_m, cfg.inertia_matrix_kg_m2)
    return float(m[DOFS.index(dof), DOFS.index(dof)])


def _prior_entry(cfg, dof: str) -> dict:
    """{added_mass, linear_damping, quadratic_damping} of ``dof`` from the configured geometry
    (:func:`~hindrax_ident.estimation.priors.priors_from_config`, as :func:`~.results.prior_entries`); {} when the
    configuration lacks the geometry."""
    from hindrax_drivers.config import DOFS

    from ..estimation.least_squares import EstimationError
    from ..estimation.priors import priors_from_config

    try:
        p = priors_from_config(cfg)
    except (KeyError, TypeError, EstimationError):
        return {}
    i = DOFS.index(dof)
    return {k: (None if p[k][i] is None else float(p[k][i])) for k in ("added_mass", "linear_damping",
                                                                        "quadratic_damping")}


def _theta_priors(dof: str, names: list, cfg, prior_std_rel: float) -> dict[str, tuple[float, float]]:
    """{parameter: (mean, std)} of the empirical priors ([NTNU-Thesis] App. A.1/A.2 via
    :func:`_prior_entry`) on the physical parameters: inertia = rigid + prior added mass with std
    ``prior_std_rel`` x the added mass (the rigid part is known), quadratic and linear damping (heave: the same
    prior for both directions) with std ``prior_std_rel`` x the value. Bias and restoring have none."""
    if not prior_std_rel > 0:
        return {}
    p = _prior_entry(cfg, dof)
    if not p:
        return {}
    out = {}
    for n in names:
        key = ("added_mass" if n == "inertia" else "quadratic_damping" if n.startswith("quadratic")
               else "linear_damping" if n.startswith("linear") else None)
        val = p.get(key) if key else None
        if val is None or not (math.isfinite(val) and val > 0):
            continue
        mean = val + (_rigid_inertia(cfg, dof) if n == "inertia" else 0.0)
        out[n] = (float(mean), float(prior_std_rel) * float(val))
    return out


def joint_estimate(identifications: Mapping[str, Any], cfg, calibration: Mapping[str, Any] | None = None,
                   prior_std_rel: float | None = None) -> dict:
    """Bayesian (regularised) least squares of the thrust scales, the empirical priors and the ladders' fits
    together (docs/identification.md §6.2-§6.3; [Tarantola2005] Ch. 3), written into the identifications.

    ``identifications``: {dof: :class:`~.estimators.DofIdentification`} fitted on the record whose thrust-model
    force was multiplied by the calibration's point scale (:func:`apply_thrust_calibration` with ``calibration``;
    none without one). The model tau = M nu_dot + D(nu) nu + b (+ k_r s(eta)) with the true force s x the curve's
    depends on the parameters only through phi = theta / s, so each DOF's fit is, to first order, a Gaussian
    measurement of phi (value and the fit covariance ``signals["covariance"]``, without the thrust-curve
    uncertainty). The joint problem over x = [phi of every DOF, s of every scale parameter] minimises

        sum_dof ||L^-1 (phi - phi_fit)||^2 + sum_i ((s phi_i - mu_i) / sigma_i)^2
        + sum_g ((s_g - 1) / sigma_s)^2 + sum_steps ((s_g - s_step) / sd_step)^2

    (L L^T the fit covariance; mu_i, sigma_i the empirical priors of :func:`_theta_priors`; sigma_s
    :func:`scale_prior_std`; the steps of :func:`scale_measurements`) and its covariance is (J^T J)^-1 at the
    optimum (Gauss-Newton, the Laplace approximation). The reported theta = s phi with the covariance carried by the
    Jacobian [s I, phi]: the intervals contain the calibration's own uncertainty and the prior's pull. Without a
    calibration s is fixed at 1 (only the priors act) and the thrust-curve uncertainty is added later by
    :func:`~.verdicts.assess_dof`, per direction, as before.

    ``prior_std_rel``: default ``identification.prior_std_rel`` (or :data:`DEFAULT_PRIOR_STD_REL`); 0 leaves the
    priors out. Idempotent (a DOF with ``signals["joint"]`` is left alone). Returns the ``joint`` section of
    identification.yaml: {scales: {parameter: {value, std, prior: [1, sigma_s], measurements: [...], dofs}},
    prior_std_rel, method}. Raises ``ValueError`` on a bad calibration scale or ``prior_std_rel`` < 0.
    """
    from scipy import optimize

    if prior_std_rel is None:
        prior_std_rel = float(cfg.flat.get("identification.prior_std_rel", DEFAULT_PRIOR_STD_REL))
    if not (math.isfinite(prior_std_rel) and prior_std_rel >= 0):
        raise ValueError(f"prior_std_rel must be >= 0, got {prior_std_rel}")
    groups = scale_measurements(calibration)
    applied = thrust_scales(calibration)
    todo = [d for d, r in identifications.items() if "joint" not in r.signals and "assessment" not in r.signals]
    g_names = list(groups)  # every measured scale (one no DOF uses still shows its posterior)
    blocks = []  # (dof, names, phi_fit, Linv, priors, slice, scale index or None)
    k = 0
    for dof in todo:
        r = identifications[dof]
        names = list(r.names)
        s_app = applied[DOF_GROUP[dof]]["value"] if applied else 1.0
        y = np.array([r.values[n] for n in names], dtype=float)
        cov = r.signals.get("covariance")
        if cov is None or np.shape(cov) != (len(names), len(names)):
            cov = np.diag([r.std[n] ** 2 for n in names])
        cov = np.asarray(cov, dtype=float) / s_app ** 2
        cov = 0.5 * (cov + cov.T) + np.eye(len(names)) * 1e-18 * max(1.0, float(np.max(np.abs(np.diag(cov)))))
        linv = np.linalg.inv(np.linalg.cholesky(cov))
        gp = _scale_parameter(groups, dof)
        blocks.append((dof, names, y / s_app, linv, _theta_priors(dof, names, cfg, prior_std_rel),
                       slice(k, k + len(names)), None if gp is None else g_names.index(gp)))
        k += len(names)
    n_phi = k
    sig_s = scale_prior_std(cfg)
    meas = [(g_names.index(g), v, sd) for g in g_names for _, v, sd in groups[g]]
    for _, v, sd in meas:
        if not sd > 0:
            raise ValueError(f"calibration: a scale std must be > 0 for the joint estimate, got {sd}")

    def scales(x):
        return x[n_phi:]

    def residuals(x):
        s = scales(x)
        out = []
        for _, names, phi_fit, linv, pri, sl, gi in blocks:
            phi = x[sl]
            out.append(linv @ (phi - phi_fit))
            sg = 1.0 if gi is None else s[gi]
            for i, n in enumerate(names):
                if n in pri:
                    out.append(np.array([(sg * phi[i] - pri[n][0]) / pri[n][1]]))
        out.append((s - 1.0) / sig_s)
        out.append(np.array([(s[gi] - v) / sd for gi, v, sd in meas]))
        return np.concatenate(out)

    if not blocks:
        return {}
    s0 = []  # start: each scale at the inverse-variance mean of its measurements
    for gi in range(len(g_names)):
        w = np.array([1.0 / sd ** 2 for g2, _, sd in meas if g2 == gi])
        s0.append(float(np.sum(w * [v for g2, v, _ in meas if g2 == gi]) / np.sum(w)))
    x0 = np.concatenate([b[2] for b in blocks] + [np.array(s0)])
    sol = optimize.least_squares(residuals, x0, method="lm", xtol=1e-14, ftol=1e-14)
    J = sol.jac
    cx = np.linalg.inv(J.T @ J)
    x = sol.x
    s = scales(x)
    for dof, names, phi_fit, _, pri, sl, gi in blocks:
        r = identifications[dof]
        phi = x[sl]
        sg = 1.0 if gi is None else float(s[gi])
        idx = list(range(sl.start, sl.stop)) + ([] if gi is None else [n_phi + gi])
        T = np.zeros((len(names), len(idx)))
        T[:, :len(names)] = sg * np.eye(len(names))
        if gi is not None:
            T[:, -1] = phi
        cov = T @ cx[np.ix_(idx, idx)] @ T.T
        theta = sg * phi
        s_app = applied[DOF_GROUP[dof]]["value"] if applied else 1.0
        cov_y = r.signals.get("covariance")
        fit_sd = (np.sqrt(np.clip(np.diag(cov_y), 0.0, None)) if cov_y is not None and np.shape(cov_y) ==
                  (len(names), len(names)) else np.array([r.std[n] for n in names]))
        r.signals["joint"] = {
            "fit_values": {n: float(v * s_app) for n, v in zip(names, phi_fit)},
            "fit_std": {n: float(v) for n, v in zip(names, fit_sd)},
            "priors": {n: [m, sd] for n, (m, sd) in pri.items()},
            "scale_parameter": None if gi is None else g_names[gi],
            "thrust_in_covariance": gi is not None}
        r.signals["covariance"] = cov
        for n, v, sd in zip(names, theta, np.sqrt(np.clip(np.diag(cov), 0.0, None))):
            r.values[n] = float(v)
            r.std[n] = float(sd)
        r.values["added_mass"] = r.values["inertia"] - _rigid_inertia(cfg, dof)
        r.std["added_mass"] = r.std["inertia"]
    sec = {"prior_std_rel": float(prior_std_rel),
           "method": ("Bayesian least squares ([Tarantola2005] Ch. 3; docs/identification.md §6.2): each DOF's "
                      "output-error fit in curve units phi = theta / s as a Gaussian measurement, the thrust scales s "
                      "with prior N(1, sigma_s^2) and the calibration steps as measurements, the empirical priors "
                      "on theta = s phi; covariance (J^T J)^-1 at the optimum"),
           "scales": {}}
    for gi, g in enumerate(g_names):
        sec["scales"][g] = {"value": float(s[gi]), "std": float(math.sqrt(cx[n_phi + gi, n_phi + gi])),
                            "prior": [1.0, float(sig_s)],
                            "measurements": [{"step": st, "value": float(v), "std": float(sd)}
                                             for st, v, sd in groups[g]],
                            "dofs": [b[0] for b in blocks if b[6] == gi]}
    return sec
