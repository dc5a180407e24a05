"""Per-DOF model and estimators: the online RLS, the regressors and the comparison methods of the campaign.

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

Signals: velocity and acceleration come from filters, never raw differences (docs/architecture.md §5): surge/sway
from the DVL velocity, heave from the pressure depth, each aided by the 100 Hz accelerometer
(:mod:`.fusion`); roll/pitch/yaw from the gyro rate (:func:`measurement_settings`). Online:
:class:`~hindrax_ident.estimation.filters.KinematicKalmanFilter` (or the accelerometer-aided filter); offline the
campaign reader :mod:`.campaign_fit` (RTS smoothers, gyro bias against the DVL attitude, restoring regressor).

Methods:

1. Online (:class:`OnlineDofEstimator`): RLS with forgetting (``identification.forgetting_factor``) on the
   regressor row, with calibrated covariance and the persistence-of-excitation measure of
   :class:`~hindrax_ident.estimation.rls.RecursiveLeastSquares`; directional forgetting, the excitation gate,
   physical-sign bounds, the change detector and the start at the empirical priors as :func:`online_rls` sets
   them from ``identification.rls_*``. The causal filter lags the fast transients
   and the forgetting window (1 / (1 - lambda) = 20 s at 50 Hz) is short, so the online values are a live
   indicator (a few per cent in surge/sway/heave/yaw; the roll/pitch linear/quadratic split is poorly
   conditioned online), not the reported estimate.
2. The reported offline estimate is the fit core's (:mod:`.fit_core`, docs/identification.md §7) on the campaign
   reader's records (:mod:`.campaign_fit`), the same core and options as ``hindrax ident fit``;
   :class:`DofIdentification` holds it with the comparisons below.
3. Comparison: equation-error batch LS on the smoothed signals ([Hindrax-Drag] eqs. 6-8,
   :func:`~hindrax_ident.estimation.least_squares.fit_linear_model` on :func:`regressor_matrix`); its inertia is
   biased low by the smoothing of the fast thrust transients (the thruster lag is 0.1 s), so it is reported, not
   used.
4. Comparison: the steady-state method of [Hindrax-Drag] (:func:`steady_state_fit`): steady windows detected
   automatically (:func:`~hindrax_ident.estimation.steady_windows.detect_steady_windows`) on the smoothed velocity
   per run, then :func:`~hindrax_ident.estimation.least_squares.fit_drag` on the window means ([Hindrax-Drag]
   eqs. 2-8). Roll/pitch windows are corrected by the output-error restoring term; heave fits each direction
   separately and usually has too few windows (no steady state in the depth available, [Hindrax-Drag] §5).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from hindrax_drivers.config import DOFS, VehicleConfig, or_default

from ..estimation.filters import KinematicKalmanFilter
from ..estimation.least_squares import EstimationError, fit_drag
from ..estimation.rls import RecursiveLeastSquares
from ..estimation.steady_windows import detect_steady_windows
from ..vehicle.fusion import AccelAidedFilter
from ..vehicle.rigid_body import rigid_body_mass_matrix
from .output_error import model_terms
from .results import prior_entries
from .verdicts import rls_published_std

__all__ = [
    "parameter_names", "parameter_units", "regressor_matrix", "rigid_inertia", "truth_parameters",
    "measurement_settings", "OnlineDofEstimator", "DofIdentification", "steady_state_fit",
]

#: White-jerk PSD (m^2/s^5) of the accelerometer-aided filter (fusion.py) for surge, sway and heave.
ACCEL_JERK_PSD = 20.0


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

    Source: docs/identification.md §1.A, [NTNU-Thesis] eq. 2.23.
    """
    if dof == "roll":
        return np.cos(pitch_rad) * np.sin(roll_rad)
    return np.sin(pitch_rad)


#: the model's columns after the inertia column (:func:`.output_error.model_terms`)
_rest_terms = model_terms


def regressor_matrix(dof: str, acceleration, velocity, restoring=None) -> np.ndarray:
    """Regressor (n, p): [nu_dot, |nu| nu (per sign for heave), nu (per sign for heave), 1, (s(eta))]."""
    a = np.asarray(acceleration, dtype=float)
    return np.concatenate([a[..., None], _rest_terms(dof, velocity, restoring)], axis=-1)


def rigid_inertia(cfg: VehicleConfig, dof: str) -> float:
    """Rigid-body mass or moment of inertia about the body origin (kg, kg m^2): diag of M_RB (Fossen eq. 2.7)."""
    m = rigid_body_mass_matrix(cfg.vehicle.mass_kg, cfg.vehicle.centre_of_gravity_frd_m, cfg.inertia_matrix_kg_m2)
    return float(m[DOFS.index(dof), DOFS.index(dof)])


def truth_parameters(cfg: VehicleConfig, dof: str) -> dict[str, float]:
    """Configured ("true") values of every parameter of :func:`parameter_names` plus added_mass.

    inertia = rigid + added mass (configuration hydrodynamics); bias: heave (rho V - m) g, FRD force holding
    depth (+0.785 N for Hindrax), 0 otherwise; restoring: z_g W - z_b B (module docstring).
    """
    h = cfg.hydrodynamics(dof)
    rigid = rigid_inertia(cfg, dof)
    out = {"inertia": rigid + float(cfg.added_mass_matrix[DOFS.index(dof), DOFS.index(dof)]),
           "added_mass": float(cfg.added_mass_matrix[DOFS.index(dof), DOFS.index(dof)])}
    if dof == "heave":
        out.update(quadratic_damping_positive=h.quadratic_damping_positive,
                   quadratic_damping_negative=h.quadratic_damping_negative,
                   linear_damping_positive=h.linear_damping_positive,
                   linear_damping_negative=h.linear_damping_negative,
                   bias=float(cfg.buoyancy_n - cfg.weight_n))
    else:
        out.update(quadratic_damping=h.quadratic_damping_positive, linear_damping=h.linear_damping_positive,
                   bias=0.0)
    if dof in ("roll", "pitch"):
        out["restoring"] = float(cfg.vehicle.centre_of_gravity_frd_m[2] * cfg.weight_n
                                 - cfg.vehicle.centre_of_buoyancy_frd_m[2] * cfg.buoyancy_n)
    return {k: float(v) for k, v in out.items()}


def measurement_settings(cfg: VehicleConfig, dof: str) -> dict:
    """Which conditioned signal measures a DOF and the filter tuning.

    Returns {"log": SensorState log key, "column": index, "measured": 'position'|'velocity',
    "std": measurement std, "jerk_psd": q, "accel": True when the accelerometer aids the filter (surge, sway,
    heave; then also "accel_std" and "accel_jerk_psd", :mod:`.fusion`)}. The noise std comes from
    the noise the vehicle file declares (``sensors.dvl75.noise_std_m_s``, ``scale_error_fraction``,
    ``attitude_noise_std_rad``, ``sensors.ms5837.noise_std_pa``, ``sensors.icm20948.*_noise_std_*``; else
    ``sensors.dvl75.velocity_std_m_s`` / typical values), never the simulator's truth; q = std^2 w^k puts the filter
    bandwidth near w = 12 rad/s (translation) or 20 rad/s (rotation) (filters.py: bandwidth ~ (q / std^2)^(1/4) for
    velocity and ^(1/6) for position measurements).
    """
    dvl, imu = cfg.sensors.dvl75, cfg.sensors.icm20948
    k = DOFS.index(dof)
    acc = max(float(or_default(imu.accel_noise_std_m_s2, 0.05)), 1e-3)
    att = float(or_default(dvl.attitude_noise_std_rad, 0.005))
    accel = {"accel": True, "accel_std": math.hypot(acc, cfg.environment.gravity_m_s2 * att),
             "accel_jerk_psd": ACCEL_JERK_PSD}
    if dof in ("surge", "sway"):
        std = max(float(or_default(dvl.noise_std_m_s, dvl.velocity_std_m_s)), 1e-3)
        std = math.hypot(std, 0.5 * float(or_default(dvl.scale_error_fraction, 0.0)))
        return {"log": "dvl", "column": k, "measured": "velocity", "std": std, "jerk_psd": std ** 2 * 12.0 ** 4,
                **accel}
    if dof == "heave":
        pa = float(or_default(cfg.sensors.ms5837.noise_std_pa, 20.0))
        std = max(pa / (cfg.environment.water_density_kg_m3 * cfg.environment.gravity_m_s2), 5e-4)
        return {"log": "depth", "column": 0, "measured": "position", "std": std, "jerk_psd": std ** 2 * 12.0 ** 6,
                **accel}
    std = max(float(or_default(imu.gyro_noise_std_rad_s, 0.003)), 5e-4)
    return {"log": "gyro", "column": k - 3, "measured": "velocity", "std": std, "jerk_psd": std ** 2 * 20.0 ** 4,
            "accel": False}


# ============================================================================ online
#: Online RLS defaults when the vehicle file omits ``identification.rls_*`` (docs/identification.md §1.D).
RLS_DEFAULTS = {"directional_forgetting": True, "min_excitation": 0.001, "change_threshold": 6.0,
                "change_window_s": 10.0, "prior_std_rel": 1.0}
#: Reference force noise (N; N m for roll, pitch, yaw) that scales the prior std into the RLS's P0 = diag(std^2) /
#: sigma_ref^2 (P is the inverse information without sigma^2). The online residual std measured in a no-disturbance
#: campaign (seed 1, 3 levels) was 1.9-2.7 N and 0.15-0.29 N m; taking about half of it makes the prior weaker than
#: its stated std, never stronger.
RLS_PRIOR_NOISE_STD = {"surge": 1.0, "sway": 1.0, "heave": 1.0, "roll": 0.1, "pitch": 0.1, "yaw": 0.1}
#: Prior 1-sigma of the bias (N; N m), centred on the expected bias (0; heave: the net buoyancy).
RLS_PRIOR_BIAS_STD = {"surge": 1.0, "sway": 1.0, "heave": 1.0, "roll": 0.1, "pitch": 0.1, "yaw": 0.1}


def rls_setting(cfg: VehicleConfig, name: str):
    """``identification.rls_<name>`` from the vehicle file, else :data:`RLS_DEFAULTS`."""
    v = getattr(cfg.identification, f"rls_{name}")
    return RLS_DEFAULTS[name] if v is None else v


def rls_prior(cfg: VehicleConfig, dof: str, prior_std_rel: float) -> tuple[np.ndarray, np.ndarray] | None:
    """Start value and 1-sigma (p,) of the online RLS of ``dof`` from the empirical priors, or None.

    inertia = rigid + prior added mass, std ``prior_std_rel`` x the added mass (the rigid part is known);
    quadratic and linear damping (heave: the same prior for both directions) std ``prior_std_rel`` x the value
    ([NTNU-Thesis] App. A.1/A.2 via :func:`~.results.prior_entries`; a solid prism of the configured
    box); bias: the expected one (0; heave (rho V - m) g) with :data:`RLS_PRIOR_BIAS_STD`; restoring: the
    configured z_g W - z_b B with ``prior_std_rel`` x its value. None when ``prior_std_rel`` is 0 or the geometry
    gives no prior."""
    if not prior_std_rel > 0:
        return None
    p = prior_entries(cfg).get(dof)
    if not p:
        return None
    truth = truth_parameters(cfg, dof)  # configured bias and restoring only (what the vehicle file states)
    mean, std = [], []
    for n in parameter_names(dof):
        key = "added_mass" if n == "inertia" else "quadratic_damping" if n.startswith("quadratic") \
            else "linear_damping" if n.startswith("linear") else None
        if key is not None:
            v = p.get(key)
            if v is None or not (math.isfinite(v) and v > 0):
                return None
            mean.append(v + (rigid_inertia(cfg, dof) if n == "inertia" else 0.0))
            std.append(prior_std_rel * v)
        elif n == "bias":
            mean.append(truth["bias"])
            std.append(RLS_PRIOR_BIAS_STD[dof])
        else:  # restoring
            mean.append(truth["restoring"])
            std.append(max(prior_std_rel * abs(truth["restoring"]), RLS_PRIOR_BIAS_STD[dof]))
    return np.array(mean, dtype=float), np.array(std, dtype=float)


def online_rls(cfg: VehicleConfig, dof: str) -> RecursiveLeastSquares:
    """The online RLS of one DOF with the vehicle file's settings (docs/identification.md §1.D).

    Forgetting ``identification.forgetting_factor``, directional (``rls_directional_forgetting``), the excitation
    gate (``rls_min_excitation``), lower bounds 0 on inertia, damping and restoring (physical signs; the bias is
    free), the change detector (``rls_change_threshold`` over ``rls_change_window_s`` at
    ``identification.estimate_rate_hz``) and the start at the empirical priors (:func:`rls_prior`) with
    P0 = diag(std^2) / :data:`RLS_PRIOR_NOISE_STD`^2; without priors a diffuse start (theta = 0, P0 = 1e4 I)."""
    names = parameter_names(dof)
    rate = float(cfg.identification.estimate_rate_hz)
    thr = float(rls_setting(cfg, "change_threshold"))
    prior = rls_prior(cfg, dof, float(rls_setting(cfg, "prior_std_rel")))
    if prior is None:
        theta0, p0 = None, 1e4
    else:
        theta0, p0 = prior[0], np.diag((prior[1] / RLS_PRIOR_NOISE_STD[dof]) ** 2)
    return RecursiveLeastSquares(
        len(names), forgetting=float(cfg.identification.forgetting_factor), initial_covariance=p0,
        initial_theta=theta0, names=names, directional=bool(rls_setting(cfg, "directional_forgetting")),
        min_excitation=float(rls_setting(cfg, "min_excitation")),
        lower_bounds=[math.nan if n == "bias" else 0.0 for n in names],
        change_threshold=thr if thr > 1.0 else None,
        change_samples=max(1, int(round(float(rls_setting(cfg, "change_window_s")) * rate))))


class OnlineDofEstimator:
    """Online estimator of one DOF: KinematicKalmanFilter on its sensor + RLS with forgetting.

    ``on_sample(device, stamp_s, state)`` feeds the filter from the conditioned
    :class:`~..vehicle.state.SensorState`; ``update(t_s, force, state)`` predicts the filter to ``t_s`` and adds
    one regressor row (``force``: thrust-model force/moment on the axis, N or N m). ``history`` holds
    (t, theta, std, excitation_normalised) every ``history_every`` updates; ``converged_at_s`` is the
    first time the inertia, quadratic damping and restoring have std <= ``identification.converged_relative_std``
    |value| and the bias std <= 0.1 N (0.02 N m) (:meth:`_converged`).
    """

    _DEVICE = {"dvl": "dvl75", "depth": "ms5837", "gyro": "icm20948_gyro"}

    def __init__(self, cfg: VehicleConfig, dof: str, history_every: int = 5) -> None:
        self.dof = dof
        self.cfg = cfg
        self.settings = measurement_settings(cfg, dof)
        s = self.settings
        if s["accel"]:
            self.kf = AccelAidedFilter(s["measured"], s["std"], s["accel_std"], s["accel_jerk_psd"])
        else:
            self.kf = KinematicKalmanFilter(s["measured"], jerk_psd=s["jerk_psd"], measurement_std=s["std"])
        self.names = parameter_names(dof)
        self.rls = online_rls(cfg, dof)
        self.rel_tol = float(cfg.identification.converged_relative_std)
        self.history_every = int(history_every)
        self.history: dict[str, list] = {"t": [], "theta": [], "std": [], "excitation": []}
        self.converged_at_s: Optional[float] = None
        self._n = 0
        self._device = self._DEVICE[s["log"]]

    def on_sample(self, device: str, stamp_s: float, state) -> None:
        """Feed the filter when ``device`` is this DOF's sensor (or the accelerometer, when aided)."""
        s = self.settings
        if self.kf.initialised and self.kf.t_s is not None and stamp_s < self.kf.t_s:
            return
        if device == "icm20948_accel" and s["accel"]:
            if state.log["accel"]:
                self.kf.step(stamp_s, None, state.log["accel"][-1][1][DOFS.index(self.dof)])
            return
        if device != self._device:
            return
        log = state.log[s["log"]]
        if not log:
            return
        z = log[-1][1][s["column"]]
        self.kf.step(stamp_s, z if math.isfinite(z) else None)

    def update(self, t_s: float, force: float, state) -> None:
        """One RLS row at ``t_s`` with the filtered velocity/acceleration and ``force``."""
        if not self.kf.initialised:
            return
        _, v, a = self.kf.predict_to(t_s)
        if not (math.isfinite(v) and math.isfinite(a)):
            return
        rr = None
        if self.dof in ("roll", "pitch"):
            rpy = np.nan_to_num(state.rpy_rad)
            if state.log["attitude"]:  # the 10 Hz attitude carried forward with the gyro rate to t_s
                rpy = rpy + np.nan_to_num(state.rates_frd_rad_s) * max(0.0, t_s - state.log["attitude"][-1][0])
            rr = restoring_regressor(self.dof, rpy[0], rpy[1])
        phi = regressor_matrix(self.dof, np.array([a]), np.array([v]), None if rr is None else np.array([rr]))[0]
        if not (np.all(np.isfinite(phi)) and math.isfinite(force)):
            return
        self.rls.update(phi, force)
        self._n += 1
        if self._n % self.history_every == 0:
            std = self.rls.std
            self.history["t"].append(t_s)
            self.history["theta"].append(self.rls.theta.copy())
            self.history["std"].append(std.copy())
            self.history["excitation"].append(self.rls.excitation_normalised)
            if self.converged_at_s is None and self._converged(std):
                self.converged_at_s = t_s

    def _converged(self, std: np.ndarray) -> bool:
        """Inertia, quadratic damping and restoring: std <= rel_tol |value|; bias: std <= 0.1 N (0.02 N m).
        Linear damping is left out (small and weakly excited at the speeds of [Hindrax-Drag] Table 3)."""
        if self.rls.n_samples < 500 or not np.all(np.isfinite(std)):
            return False
        th = self.rls.theta
        for i, name in enumerate(self.names):
            if name.startswith("linear"):
                continue
            tol = (0.02 if self.dof in ("roll", "pitch", "yaw") else 0.1) if name == "bias" \
                else self.rel_tol * abs(th[i])
            if std[i] > tol:
                return False
        return True

    def published_std(self) -> np.ndarray:
        """The std to publish (:func:`~.verdicts.rls_published_std` of :meth:`converged_std`): damping parameters
        of the DOFs the scenario suite measured, widened by the thrust uncertainty; NaN = not converged / not
        trusted."""
        return rls_published_std(self.dof, self.names, self.rls.theta, self.converged_std(), self.cfg)

    def converged_std(self) -> np.ndarray:
        """The RLS std where converged (inertia, damping, restoring: std <= converged_relative_std |value|; bias:
        std <= 0.1 N / 0.02 N m; linear damping: std <= 0.5 |value| + its bias tolerance), NaN = not converged."""
        tol_abs = [(0.02 if self.dof in ("roll", "pitch", "yaw") else 0.1) if n in ("bias",) or n.startswith("linear")
                   else 0.0 for n in self.names]
        rel = np.array([0.5 if n.startswith("linear") else 0.0 if n == "bias" else self.rel_tol for n in self.names])
        std = self.rls.std
        ok = np.isfinite(std) & (std <= rel * np.abs(self.rls.theta) + np.asarray(tol_abs))
        ok &= ~self.rls.at_bound()  # held on a physical-sign bound: its std is not an interval around the truth
        if self.rls.n_samples < 500 or self.rls.excitation_normalised < self.rls.min_excitation:
            ok[:] = False
        return np.where(ok, std, np.nan)

    def result(self) -> dict:
        """Final {name: (value, std)} plus n_samples, excitation, converged_at_s."""
        th, sd = self.rls.theta, self.converged_std()
        return {"parameters": {n: (float(v), float(s)) for n, v, s in zip(self.names, th, sd)},
                "n_samples": self.rls.n_samples, "excitation_normalised": self.rls.excitation_normalised,
                "converged_at_s": self.converged_at_s}


# ============================================================================ offline
@dataclass
class DofIdentification:
    """Offline identification of one DOF.

    values/std/ci95 (dict name -> float / float / (low, high)): the reported (output-error) estimate of every
    parameter of :func:`parameter_names` plus ``added_mass``; method: "output-error" (or "equation-error"
    when the refinement failed). equation_error / online / steady: the other methods' {name: (value, std)}
    (steady: None when too few windows, with ``steady_note``). truth: configured values (simulation only).
    pool_time_s: duration of the DOF's manoeuvres; rls_time_s: pool time until the RLS converged (None:
    never); steady_time_s: pool time until the end of the last steady window used. signals: arrays for the
    report (t, velocity, acceleration, force, fitted velocity, steady window means).
    """

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


def steady_state_fit(dof: str, t, velocity, force, run_id, restoring=None, restoring_coefficient: float = 0.0,
                     min_duration_s: float = 2.0, max_std: float = 0.02, max_slope: float = 0.02):
    """The steady-state method: steady windows per run, fit_drag on window means ([Hindrax-Drag] eqs. 2-8).

    t, velocity (smoothed), force (thrust model), run_id (-1 outside runs) (n,); restoring (n,) and its
    coefficient are subtracted from the force for roll/pitch. Returns (params {name: (value, std)},
    windows list, note, end time of the last window). Heave: one fit per direction (names with
    _positive/_negative). params is None when there are too few windows (note says why).
    """
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
                out[f"quadratic_damping_{suffix}"] = (fit.quadratic_damping, fit.quadratic_damping_std)
                out[f"linear_damping_{suffix}"] = (fit.linear_damping, fit.linear_damping_std)
                out[f"bias_{suffix}"] = (fit.bias, fit.bias_std)
        else:
            if len(wins) < 4:
                return None, wins, f"{len(wins)} steady windows (need 4)", t_end
            fit = fit_drag(vm, fm)
            out = {"quadratic_damping": (fit.quadratic_damping, fit.quadratic_damping_std),
                   "linear_damping": (fit.linear_damping, fit.linear_damping_std),
                   "bias": (fit.bias, fit.bias_std)}
    except EstimationError as exc:
        return None, wins, f"steady-state fit failed: {exc}", t_end
    return out, wins, f"{len(wins)} steady windows", t_end
