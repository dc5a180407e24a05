"""The per-DOF model: parameters, units, regressors, the offline result, the thrust covariance, the RLS std shown.

Model per DOF (docs/architecture.md §5; [Hindrax-Drag] eq. 2 extended with the inertia term; Fossen/SNAME positive
coefficients), body FRD, tau the thrust-model force (N) or moment (N m) on the axis:

    tau = M nu_dot + k_q |nu| nu + k_l nu + b (+ k_r s(eta))

* M: inertia, rigid + added (kg or kg m^2); added mass = M - rigid (rigid from the configuration).
* heave: separate quadratic AND linear damping for w > 0 (down, "positive heave", [Hindrax-Drag] §4.1) and w < 0
  (the simulator and configuration carry both pairs; [Hindrax-Drag] Table 3 reports both). The configured
  truth has different linear terms per direction (5.26 / 11.84 kg/s), so a single linear column would bias
  the quadratic terms. b is the force holding depth, (rho V - m) g = +0.785 N FRD ([Hindrax-Drag] §5).
* roll: s = cos(theta) sin(phi); pitch: s = sin(theta); k_r = z_g W - z_b B (Fossen g(eta),
  docs/identification.md §1.A, [NTNU-Thesis] eq. 2.23; "W*BG" when W = B), 4.50 N m for Hindrax.

The reported offline estimate is the fit core's (:mod:`hindrax_fit.fit.fit_core`) on the campaign reader's
records (:mod:`hindrax_fit.fit.campaign_fit`); :class:`DofIdentification` holds it beside the comparisons: the
online RLS on :func:`regressor_matrix` (:class:`~..online.estimators.OnlineDofEstimator`, a live
indicator), the equation-error batch LS ([Hindrax-Drag] eqs. 6-8; its inertia biased low by the
smoothing of the fast thrust transients) and the steady-state method (:func:`steady_state_fit`,
[Hindrax-Drag] eqs. 2-8; heave usually has too few steady windows, [Hindrax-Drag] §5)."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Optional, Sequence

import numpy as np

from hindrax_common.config import DOFS, VehicleConfig

from ...estimation.least_squares import EstimationError, fit_drag
from ...estimation.steady_windows import detect_steady_windows
from ...vehicle.rigid_body import rigid_body_mass_matrix
from ...vehicle.uncertainty import declared_rel

__all__ = ["core_index", "model_terms", "parameter_names", "parameter_units", "regressor_matrix",
           "rigid_inertia", "truth_parameters", "DofIdentification", "steady_state_fit",
           "thrust_weights", "thrust_covariance", "RLS_STD_DOFS", "rls_published_std"]

def core_index(names: Sequence[str], core_names: Sequence[str]) -> list:
    """Index in ``core_names`` (the fit core's) of each of ``names`` (heave's ``*_positive`` and
    ``*_negative`` fall back on the one pair of both directions), None when absent."""
    out = []
    for n in names:
        base = n.rsplit("_", 1)[0] if n.endswith(("_positive", "_negative")) else n
        out.append(core_names.index(n) if n in core_names else core_names.index(base) if base in core_names else None)
    return out


def parameter_names(dof: str) -> list[str]:
    """Parameter names of a DOF's regression, in regressor-column order (module docstring)."""
    if dof == "heave":
        return ["inertia", "quadratic_damping_positive", "quadratic_damping_negative",
                "linear_damping_positive", "linear_damping_negative", "bias"]
    names = ["inertia", "quadratic_damping", "linear_damping", "bias"]
    if dof in ("roll", "pitch"):
        names.append("restoring")
    return names


def parameter_units(dof: str) -> dict[str, str]:
    """Unit of every reported parameter (SI, as the configuration keys)."""
    rot = dof in ("roll", "pitch", "yaw")
    u = {"inertia": "kg m^2" if rot else "kg", "added_mass": "kg m^2" if rot else "kg",
         "bias": "N m" if rot else "N", "restoring": "N m"}
    for n in parameter_names(dof):
        if n.startswith("quadratic"):
            u[n] = "kg m^2" if rot else "kg/m"
        elif n.startswith("linear"):
            u[n] = "kg m^2/s" if rot else "kg/s"
    return u


def restoring_regressor(dof: str, roll_rad, pitch_rad) -> np.ndarray:
    """Restoring column s(eta): roll cos(theta) sin(phi), pitch sin(theta).

    Source: docs/identification.md §1.A, [NTNU-Thesis] eq. 2.23."""
    if dof == "roll":
        return np.cos(pitch_rad) * np.sin(roll_rad)
    return np.sin(pitch_rad)


def model_terms(dof: str, velocity, restoring=None) -> np.ndarray:
    """The model's columns after the inertia column, shape (..., p - 1), for velocity (...)
    and, roll and pitch, the restoring regressor s(eta) (...; zeros when None):
    ``[|nu| nu, nu, 1 (, s)]``; heave
    ``[|w| w (w > 0), |w| w (w <= 0), w (w > 0), w (w <= 0), 1]``."""
    v = np.asarray(velocity, dtype=float)
    q = np.abs(v) * v
    one = np.ones_like(v)
    if dof == "heave":
        pos = v > 0
        cols = [np.where(pos, q, 0.0), np.where(pos, 0.0, q), np.where(pos, v, 0.0), np.where(pos, 0.0, v), one]
    else:
        cols = [q, v, one]
        if dof in ("roll", "pitch"):
            cols.append(np.zeros_like(v) if restoring is None else np.asarray(restoring, dtype=float))
    return np.stack(cols, axis=-1)


def regressor_matrix(dof: str, acceleration, velocity, restoring=None) -> np.ndarray:
    """Regressor (n, p): [nu_dot, |nu| nu (per sign for heave), nu (per sign for heave), 1, (s(eta))]."""
    a = np.asarray(acceleration, dtype=float)
    return np.concatenate([a[..., None], model_terms(dof, velocity, restoring)], axis=-1)


def rigid_inertia(cfg: VehicleConfig, dof: str) -> float:
    """Rigid-body mass or moment of inertia about the body origin (kg, kg m^2): diag of M_RB (Fossen eq. 2.7)."""
    m = rigid_body_mass_matrix(cfg.vehicle.mass_kg, cfg.vehicle.centre_of_gravity_frd_m, cfg.inertia_matrix_kg_m2)
    return float(m[DOFS.index(dof), DOFS.index(dof)])


def truth_parameters(cfg: VehicleConfig, dof: str) -> dict[str, float]:
    """Configured ("true") values of every parameter of :func:`parameter_names` plus added_mass.

    inertia = rigid + added mass (configuration hydrodynamics); bias: heave (rho V - m) g, FRD force holding
    depth (+0.785 N for Hindrax), 0 otherwise; restoring: z_g W - z_b B (module docstring)."""
    h = cfg.dof_hydrodynamics(dof)
    added = float(cfg.added_mass_matrix[DOFS.index(dof), DOFS.index(dof)])
    out = {"inertia": rigid_inertia(cfg, dof) + added, "added_mass": added}
    if dof == "heave":  # its damping parameters are named as the fields of DofHydrodynamics
        out.update({n: getattr(h, n) for n in parameter_names(dof)[1:5]}, bias=float(cfg.buoyancy_n - cfg.weight_n))
    else:
        out.update(quadratic_damping=h.quadratic_damping_positive, linear_damping=h.linear_damping_positive, bias=0.0)
    if dof in ("roll", "pitch"):
        out["restoring"] = float(cfg.vehicle.centre_of_gravity_frd_m[2] * cfg.weight_n
                                 - cfg.vehicle.centre_of_buoyancy_frd_m[2] * cfg.buoyancy_n)
    return {k: float(v) for k, v in out.items()}


@dataclass
class DofIdentification:
    """Offline identification of one DOF.

    values/std/ci95 (dict name -> float / float / (low, high)): the reported (output-error) estimate of every
    parameter of :func:`parameter_names` plus ``added_mass``; method: "output-error" (fit core).
    equation_error / online / steady: the other methods' {name: (value, std)}
    (steady: None when too few windows, with ``steady_note``). truth: configured values (simulation only).
    pool_time_s: duration of the DOF's manoeuvres; rls_time_s: pool time until the RLS converged (None:
    never); steady_time_s: pool time until the end of the last steady window used. signals: arrays for the
    report (t, velocity, acceleration, force, fitted velocity, steady window means)."""

    dof: str
    names: list
    values: dict
    std: dict
    ci95: dict
    method: str
    residual_dof: int
    equation_error: dict
    online: dict
    steady: Optional[dict]
    steady_note: str
    truth: dict
    units: dict
    pool_time_s: float
    rls_time_s: Optional[float]
    steady_time_s: Optional[float]
    signals: dict = field(default_factory=dict)

    def relative_error(self, name: str, source: str = "final") -> float:
        """(estimate - truth) / |truth| of one parameter (NaN when unknown or truth 0)."""
        est = {"final": self.values, "equation_error": {k: v[0] for k, v in self.equation_error.items()},
               "online": {k: v[0] for k, v in self.online.items()},
               "steady": {k: v[0] for k, v in (self.steady or {}).items()}}[source].get(name)
        tr = self.truth.get(name)
        if est is None or tr is None or tr == 0.0:
            return math.nan
        return (est - tr) / abs(tr)


#: The parameters of :func:`~...estimation.least_squares.fit_drag` (each with its ``_std``)
_DRAG = ("quadratic_damping", "linear_damping", "bias")


def steady_state_fit(dof: str, t, velocity, force, run_id, restoring=None, restoring_coefficient: float = 0.0,
                     min_duration_s: float = 2.0, max_std: float = 0.02, max_slope: float = 0.02):
    """The steady-state method: steady windows per run, fit_drag on window means ([Hindrax-Drag] eqs. 2-8).

    t, velocity (smoothed), force (thrust model), run_id (-1 outside runs) (n,); restoring (n,) and its
    coefficient are subtracted from the force for roll/pitch. Returns (params {name: (value, std)},
    windows list, note, end time of the last window). Heave: one fit per direction (names with
    _positive/_negative). params is None when there are too few windows (note says why)."""
    t = np.asarray(t, dtype=float)
    v = np.asarray(velocity, dtype=float)
    f = np.asarray(force, dtype=float)
    if restoring is not None:
        f = f - restoring_coefficient * np.asarray(restoring, dtype=float)
    ok = np.isfinite(v) & np.isfinite(f)
    t, v, f, run = t[ok], v[ok], f[ok], np.asarray(run_id)[ok]
    wins = [w for w in detect_steady_windows(t, v, run.astype(float), min_duration_s=min_duration_s,
                                             max_slope=max_slope, max_std=max_std, force_tolerance=0.5)
            if run[w.start] >= 0]
    vm = np.array([w.velocity_mean for w in wins])
    fm = np.array([float(np.mean(f[w.start:w.stop])) for w in wins])
    t_end = max((w.t_stop_s for w in wins), default=None)
    out: dict = {}
    try:
        if dof == "heave":
            for sign, suffix in ((1, "positive"), (-1, "negative")):
                sel = np.sign(vm) == sign
                if sel.sum() < 4:
                    return None, wins, f"{int(sel.sum())} steady windows in {suffix} heave (need 4)", t_end
                fit = fit_drag(vm[sel], fm[sel])
                out.update({f"{k}_{suffix}": (getattr(fit, k), getattr(fit, f"{k}_std")) for k in _DRAG})
        else:
            if len(wins) < 4:
                return None, wins, f"{len(wins)} steady windows (need 4)", t_end
            fit = fit_drag(vm, fm)
            out = {k: (getattr(fit, k), getattr(fit, f"{k}_std")) for k in _DRAG}
    except EstimationError as exc:
        return None, wins, f"steady-state fit failed: {exc}", t_end
    return out, wins, f"{len(wins)} steady windows", t_end


def thrust_weights(dof: str, names: Sequence[str]) -> np.ndarray:
    """(p, 2) weights [a_pos, b_neg] of each parameter on the positive / negative thrust scale: a parameter scales with
    the thrust of the directions it is fitted from (heave ``*_positive`` and the bias forward, ``*_negative`` reverse,
    the others both halves; with a reverse gain the gain takes the reverse scale; a saturation gain none)."""
    w = np.full((len(names), 2), 0.5)
    if "reverse_thrust_gain" in names:
        # the force of negative commands is the gain times the curve's: the gain takes the reverse scale (a = -1,
        # b = 1), every other parameter only the forward one
        for i, n in enumerate(names):
            w[i] = (-1.0, 1.0) if n == "reverse_thrust_gain" else (1.0, 0.0)
    elif dof == "heave":
        for i, n in enumerate(names):
            if n.endswith("_positive") or n == "bias":
                w[i] = (1.0, 0.0)
            elif n.endswith("_negative"):
                w[i] = (0.0, 1.0)
    w[[i for i, n in enumerate(names) if n == "saturation_gain"]] = 0.0  # a ratio of two thrusts: no scale
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


#: DOFs whose online RLS damping std the scenario suite measured. Elsewhere it is not published.
RLS_STD_DOFS = ("surge", "sway", "heave", "yaw")


def rls_published_std(dof: str, names: Sequence[str], theta, converged_std, cfg: VehicleConfig) -> np.ndarray:
    """The online RLS standard deviations worth publishing (p,), NaN = "not converged / not trusted".

    ``converged_std`` (p,): the RLS std where the estimator has converged, NaN elsewhere. Only the damping parameters of
    :data:`RLS_STD_DOFS` keep a number, widened by the thrust-curve uncertainty (:func:`thrust_covariance`): the RLS
    inertia and bias carry the lag of the causal filter behind the acceleration, so their std would not cover the truth;
    roll and pitch are not in the scenario suite."""
    std = np.asarray(converged_std, dtype=float)
    keep = np.array([dof in RLS_STD_DOFS and (n.startswith("quadratic") or n.startswith("linear")) for n in names],
                    dtype=bool)
    thrust = np.diag(thrust_covariance(dof, names, theta, declared_rel(cfg)))
    out = np.sqrt(std ** 2 + thrust)
    return np.where(keep & np.isfinite(std), out, np.nan)
