"""The online estimator of one DOF: Kalman filter on its sensor + RLS with forgetting, the campaign's live indicator.

RLS with forgetting (``identification.forgetting_factor``) on the regressor row of the per-DOF model
(:mod:`..model.dof_model`), with calibrated covariance and the persistence-of-excitation measure of
:class:`~hindrax_onboard.estimation.rls.RecursiveLeastSquares`; directional forgetting, the excitation gate,
physical-sign bounds, the change detector and the start at the empirical priors as :func:`online_rls` sets them
from ``identification.rls_*``. The causal filter lags the fast transients and the forgetting window
(1 / (1 - lambda) = 500 ticks, 20 s at the 25 Hz tick) is short, so the online values are a live indicator (a few
per cent in surge/sway/heave/yaw; the roll/pitch linear/quadratic split is poorly conditioned online), not the
reported estimate (that is the fit core's, :mod:`hindrax_fit.fit.fit_core`)."""
from __future__ import annotations

import math
from typing import Optional

import numpy as np

from hindrax_common.config import DOFS, VehicleConfig

from ...estimation.filters import KinematicKalmanFilter
from ...estimation.rls import RecursiveLeastSquares
from ...vehicle.fusion import AccelAidedFilter
from ...vehicle.state import finite_or_zeros
from ...vehicle.uncertainty import measurement_settings
from ..model.dof_model import (parameter_names, regressor_matrix, restoring_regressor,
                             rigid_inertia, rls_published_std, truth_parameters)
from ..model.posterior import prior_entries

__all__ = ["OnlineDofEstimator", "online_rls", "rls_setting", "rls_prior"]

#: Online RLS defaults when the vehicle file omits ``identification.rls_*`` (docs/identification.md §1.D).
RLS_DEFAULTS = {"directional_forgetting": True, "min_excitation": 0.001, "change_threshold": 6.0,
                "change_window_s": 10.0, "prior_std_rel": 1.0}
#: Reference force noise (N; N m for roll, pitch, yaw) that scales the prior std into the RLS's
#: P0 = diag(std^2) / sigma_ref^2 (P is the inverse information without sigma^2): about half the
#: online residual std of a campaign without disturbances: the prior is never stronger than stated.
RLS_PRIOR_NOISE_STD = {"surge": 1.0, "sway": 1.0, "heave": 1.0, "roll": 0.1, "pitch": 0.1, "yaw": 0.1}
#: Prior 1-sigma of the bias (N; N m), centred on the expected bias (0; heave: the net buoyancy).
RLS_PRIOR_BIAS_STD = {"surge": 1.0, "sway": 1.0, "heave": 1.0, "roll": 0.1, "pitch": 0.1, "yaw": 0.1}


def rls_setting(cfg: VehicleConfig, name: str):
    """``identification.rls_<name>`` from the vehicle file, else :data:`RLS_DEFAULTS`."""
    v = getattr(cfg.identification, f"rls_{name}")
    return RLS_DEFAULTS[name] if v is None else v


def rls_prior(cfg: VehicleConfig, dof: str, prior_std_rel: float) -> tuple[np.ndarray, np.ndarray] | None:
    """Start value and 1-sigma (p,) of the online RLS of ``dof`` from the empirical priors, or None.

    inertia = rigid + prior added mass, std ``prior_std_rel`` x the added mass (the rigid part is known); quadratic and
    linear damping (heave: the same prior for both directions) std ``prior_std_rel`` x the value ([NTNU-Thesis] App.
    A.1/A.2 via :func:`~..model.posterior.prior_entries`; a solid prism of the configured box); bias: the expected one
    (0; heave (rho V - m) g) with :data:`RLS_PRIOR_BIAS_STD`; restoring: the configured z_g W - z_b B with
    ``prior_std_rel`` x its value. None when ``prior_std_rel`` is 0 or the geometry gives no prior."""
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
        initial_theta=theta0, directional=bool(rls_setting(cfg, "directional_forgetting")),
        min_excitation=float(rls_setting(cfg, "min_excitation")),
        lower_bounds=[math.nan if n == "bias" else 0.0 for n in names],
        change_threshold=thr if thr > 1.0 else None,
        change_samples=max(1, int(round(float(rls_setting(cfg, "change_window_s")) * rate))))


class OnlineDofEstimator:
    """Online estimator of one DOF: KinematicKalmanFilter on its sensor + RLS with forgetting.

    ``on_sample(device, stamp_s, state)`` feeds the filter from the conditioned :class:`~..vehicle.state.SensorState`;
    ``update(t_s, force, state)`` predicts the filter to ``t_s`` and adds one regressor row (``force``: thrust-model
    force/moment on the axis, N or N m). ``history`` holds (t, theta, std, excitation_normalised) every
    ``history_every`` updates; ``converged_at_s`` is the first time :meth:`_converged` holds."""

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
            rpy = finite_or_zeros(state.rpy_rad)
            if state.log["attitude"]:  # the 10 Hz attitude carried forward with the gyro rate to t_s
                age_s = max(0.0, t_s - state.log["attitude"][-1][0])
                rpy = rpy + finite_or_zeros(state.rates_frd_rad_s) * age_s
            rr = restoring_regressor(self.dof, rpy[0], rpy[1])
        phi = regressor_matrix(self.dof, np.array([a]), np.array([v]), None if rr is None else np.array([rr]))[0]
        if not (np.all(np.isfinite(phi)) and math.isfinite(force)):
            return
        self.rls.update(phi, force)
        self._n += 1
        if self._n % self.history_every == 0:
            std = self.rls.std
            row = (t_s, self.rls.theta.copy(), std.copy(), self.rls.excitation_normalised)
            for column, value in zip(self.history.values(), row):  # t, theta, std, excitation
                column.append(value)
            if self.converged_at_s is None and self._converged(std):
                self.converged_at_s = t_s

    def _converged(self, std: np.ndarray) -> bool:
        """Inertia, quadratic damping and restoring: std <= ``converged_relative_std`` |value|;
        bias: std <= 0.1 N (0.02 N m); after 500 samples. Linear damping is left out (small and
        weakly excited at the speeds of [Hindrax-Drag] Table 3)."""
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
        """The std to publish: :func:`~..model.dof_model.rls_published_std` of :meth:`converged_std`
        (NaN: not published)."""
        return rls_published_std(self.dof, self.names, self.rls.theta, self.converged_std(), self.cfg)

    def converged_std(self) -> np.ndarray:
        """The RLS std where converged (inertia, damping, restoring: std <= converged_relative_std |value|; bias:
        std <= 0.1 N / 0.02 N m; linear damping: std <= 0.5 |value| + its bias tolerance), NaN = not converged."""
        tol_abs = [(0.02 if self.dof in ("roll", "pitch", "yaw") else 0.1) if n in ("bias",) or n.startswith("linear")
                   else 0.0 for n in self.names]
        rel = np.array([0.5 if n.startswith("linear") else 0.0 if n == "bias" else self.rel_tol for n in self.names])
        return self.rls.published_std(rel, np.asarray(tol_abs), min_samples=500)

    def result(self) -> dict:
        """Final {name: (value, std)} plus n_samples, excitation, converged_at_s."""
        th, sd = self.rls.theta, self.converged_std()
        return {"parameters": {n: (float(v), float(s)) for n, v, s in zip(self.names, th, sd)},
                "n_samples": self.rls.n_samples, "excitation_normalised": self.rls.excitation_normalised,
                "converged_at_s": self.converged_at_s}
