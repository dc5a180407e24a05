"""Output-error fit of the one-DOF model: the model, the integrator and the segment bookkeeping, each on its own.

Model (docs/identification.md; [Hindrax-Drag] eq. 2 with the inertia term; Fossen/SNAME positive
coefficients), body FRD, for the DOF under test with velocity nu (m/s or rad/s) and thrust-model force tau
(N or N m)::

    M nu_dot + k_q |nu| nu + k_l nu + b (+ k_r s(eta)) = tau

``theta = [M, k_q, k_l, b (, k_r)]`` in :func:`model_terms` column order; heave has ``k_q`` and ``k_l`` per sign
of w (down positive): ``[M, k_q+, k_q-, k_l+, k_l-, b]``. Roll and pitch add the restoring moment ``k_r s(eta)``,
``s`` = cos(theta) sin(phi) (roll) or sin(theta) (pitch) ([NTNU-Thesis] eq. 2.23).

* :class:`DofModel` - the acceleration nu_dot of that model for given parameters.
* :class:`LaggedThrust` - the force inside one control tick: the thrust reaches the commanded value through the
  first-order lag ``thrusters.time_constant_s`` (exact for a command held over the tick).
* :func:`rk4_step` - one classical Runge-Kutta step of the velocity, and the matching Runge-Kutta-Nystrom
  step of the position (x' = v, v' = a(v, t)), force and restoring regressor given at the start, middle and
  end of the step.
* :class:`Segments` - the record cut into equal segments, each integrated from its own initial state (from
  the smoother; free for a measured position), the measured samples on the tick grid that the residuals use.
* :class:`OutputErrorFit` - the least-squares fit of theta (``scipy.optimize.least_squares``) and its
  covariance: sigma^2 (J^T J)^-1 ([Hindrax-Drag] eq. 8 analogue), inflated for the lag-1
  autocorrelation of consecutive residual samples within segments (AR(1) effective sample size), and at
  least the cluster-robust covariance with one cluster per segment (Liang and Zeger 1986).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy import optimize

from ..estimation.least_squares import EstimationError

__all__ = ["model_terms", "DofModel", "LaggedThrust", "rk4_step", "Segments", "OutputErrorFit", "OutputErrorResult",
           "at_least_cluster_robust"]


def model_terms(dof: str, velocity, restoring=None) -> np.ndarray:
    """The model's columns after the inertia column, shape (..., p - 1), for velocity (...) and, roll and pitch,
    the restoring regressor s(eta) (...; zeros when None): ``[|nu| nu, nu, 1 (, s)]``; heave
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


@dataclass(frozen=True)
class DofModel:
    """The one-DOF model of the module docstring with parameters ``theta`` ((p,), ``theta[0]`` = M > 0)."""

    dof: str
    theta: np.ndarray

    def acceleration(self, velocity, force, restoring=None) -> np.ndarray:
        """nu_dot = (tau - [k_q |nu| nu + k_l nu + b (+ k_r s)]) / M, elementwise over ``velocity`` (...) with
        ``force`` and ``restoring`` broadcast against it."""
        return (force - model_terms(self.dof, velocity, restoring) @ self.theta[1:]) / self.theta[0]


@dataclass(frozen=True)
class LaggedThrust:
    """Force inside one tick of ``tick_s`` when the thrust follows a first-order lag of ``time_constant_s`` (0: no
    lag) towards the commanded value: f(s) = f_cmd + (f_start - f_cmd) exp(-s / tau), 0 <= s <= tick_s."""

    time_constant_s: float
    tick_s: float

    def decay(self, s: float) -> float:
        """exp(-s / tau) (0.0 without a lag)."""
        return math.exp(-s / self.time_constant_s) if self.time_constant_s > 0 else 0.0

    def start_middle_end(self, f_start, f_cmd) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The force at s = 0, tick_s / 2 and tick_s (arrays broadcast as ``f_start``, ``f_cmd``)."""
        return tuple(f_cmd + (f_start - f_cmd) * self.decay(s) for s in (0.0, 0.5 * self.tick_s, self.tick_s))


def rk4_step(acceleration: Callable, v, x, h: float, forces: tuple, restorings: tuple = (None, None, None)):
    """One step of ``h`` (s) of x' = v, v' = acceleration(v, f, r): classical Runge-Kutta for v, Runge-Kutta-Nystrom
    for x (x + h v + h^2 / 6 (k1 + k2 + k3)); ``forces`` and ``restorings`` at the start, middle and end of the
    step. Returns (v, x) at the end; fourth order in h for smooth inputs."""
    f0, fh, f1 = forces
    r0, rh, r1 = restorings
    k1 = acceleration(v, f0, r0)
    k2 = acceleration(v + 0.5 * h * k1, fh, rh)
    k3 = acceleration(v + 0.5 * h * k2, fh, rh)
    k4 = acceleration(v + h * k3, f1, r1)
    x = x + h * v + h * h / 6.0 * (k1 + k2 + k3)
    v = v + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
    return v, x


@dataclass
class Segments:
    """The usable equal segments of a tick record (:meth:`split`).

    index: (m, n) tick indices, one row per segment; mask: (m, n) True where a measurement is at the tick (never
    the first tick of a segment, the initial state); v0, x0: (m,) initial velocity and position of each segment.
    """

    index: np.ndarray
    mask: np.ndarray
    v0: np.ndarray
    x0: np.ndarray

    @classmethod
    def split(cls, ticks_per_segment: int, z_tick: np.ndarray, v_start: np.ndarray, x_start: np.ndarray
              ) -> "Segments":
        """Cut ``len(z_tick)`` ticks into whole segments of ``ticks_per_segment`` (the rest is left out) and keep
        those with a finite initial state (``v_start``, ``x_start`` (n,) at their first tick) and at least 3
        measurements (``z_tick`` (n,), NaN where none). Raises :class:`EstimationError` with fewer than 2 segments
        before or after that selection."""
        seg = int(ticks_per_segment)
        nseg = len(z_tick) // seg
        if nseg < 2:
            raise EstimationError("record too short for the output-error refinement")
        idx = np.arange(nseg * seg).reshape(nseg, seg)
        mask = np.isfinite(z_tick[idx])
        mask[:, 0] = False
        ok = np.isfinite(v_start[idx[:, 0]]) & np.isfinite(x_start[idx[:, 0]]) & (mask.sum(axis=1) >= 3)
        if ok.sum() < 2:
            raise EstimationError("too few usable segments for the output-error refinement")
        idx, mask = idx[ok], mask[ok]
        return cls(idx, mask, v_start[idx[:, 0]], x_start[idx[:, 0]])

    def take(self, a: np.ndarray | None) -> np.ndarray | None:
        """``a`` (n,) arranged as the segments (m, n_seg); None stays None."""
        return None if a is None else a[self.index]

    @property
    def sample_segment(self) -> np.ndarray:
        """Segment number of every measured sample, in the (row-major) order of the residual vector."""
        return np.broadcast_to(np.arange(self.mask.shape[0])[:, None], self.mask.shape)[self.mask]


@dataclass
class OutputErrorResult:
    """theta (p,); covariance (p, p); residual_dof: samples - parameters (- one offset per segment for a measured
    position); velocity_fit (n,) the simulated velocity on the record's ticks (NaN outside the used segments);
    rho: lag-1 autocorrelation of consecutive residual samples within segments."""

    theta: np.ndarray
    covariance: np.ndarray
    residual_dof: int
    velocity_fit: np.ndarray
    rho: float


class OutputErrorFit:
    """Output-error fit of one DOF (module docstring) on a tick record.

    dof: the DOF. t (n,): tick times, s (uniform: the step is their median spacing). force, force_cmd (n,): the
    lagged thrust-model force at each tick and the force commanded over it (N or N m); lag: the
    :class:`LaggedThrust` between them. restoring (n,) or None: s(eta) (roll, pitch). z_tick (n,): the measurement
    at the ticks that have one, else NaN. measured: ``"velocity"`` (residual V - z, initial velocity from
    ``v_start``) or ``"position"`` (residual X - z less its mean per segment, so the offset is free, and the initial
    velocity of each segment a free parameter too). x_start, v_start (n,): smoothed position and velocity, the
    initial states. segment_s: segment length, s (at least 10 ticks).
    Raises :class:`EstimationError` when too few segments are usable (:meth:`Segments.split`).
    """

    def __init__(self, dof: str, t: np.ndarray, force: np.ndarray, force_cmd: np.ndarray, lag_time_constant_s: float,
                 restoring: np.ndarray | None, z_tick: np.ndarray, measured: str, x_start: np.ndarray,
                 v_start: np.ndarray, segment_s: float) -> None:
        self.dof = dof
        self.n_ticks = len(t)
        self.h = float(np.median(np.diff(t)))
        self.lag = LaggedThrust(float(lag_time_constant_s), self.h)
        self.measured = measured
        self.segments = Segments.split(max(10, int(round(segment_s / self.h))), z_tick, v_start, x_start)
        sg = self.segments
        self.F, self.Fc, self.R, self.Z = sg.take(force), sg.take(force_cmd), sg.take(restoring), sg.take(z_tick)
        self.free_v0 = measured == "position"

    def simulate(self, theta: np.ndarray, v0: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(V, X) (m, n_seg): velocity and position of every segment from its initial state (``v0`` (m,) replaces the
        smoothed initial velocities) under the model with ``theta``."""
        model = DofModel(self.dof, theta)
        sg = self.segments
        v = sg.v0.copy() if v0 is None else v0.copy()
        x = sg.x0.copy()
        V = np.empty(self.F.shape)
        X = np.empty(self.F.shape)
        V[:, 0], X[:, 0] = v, x
        for i in range(self.F.shape[1] - 1):
            forces = self.lag.start_middle_end(self.F[:, i], self.Fc[:, i])
            restorings = (None, None, None)
            if self.R is not None:
                r0, r1 = self.R[:, i], self.R[:, i + 1]
                restorings = (r0, 0.5 * (r0 + r1), r1)
            v, x = rk4_step(model.acceleration, v, x, self.h, forces, restorings)
            V[:, i + 1], X[:, i + 1] = v, x
        return V, X

    def _split(self, params: np.ndarray, p_model: int) -> tuple[np.ndarray, np.ndarray | None]:
        return params[:p_model], (params[p_model:] if self.free_v0 else None)

    def residuals(self, params: np.ndarray, p_model: int) -> np.ndarray:
        """Residual of every measured sample (row-major); ``params`` = theta, then the free initial velocities."""
        theta, v0 = self._split(params, p_model)
        V, X = self.simulate(theta, v0)
        mask = self.segments.mask
        if self.measured == "velocity":
            r = np.where(mask, V - np.nan_to_num(self.Z), 0.0)
        else:
            r = np.where(mask, X - np.nan_to_num(self.Z), 0.0)
            off = r.sum(axis=1) / mask.sum(axis=1)
            r = np.where(mask, r - off[:, None], 0.0)
        return r[mask]

    def fit(self, theta0: np.ndarray) -> OutputErrorResult:
        """Least squares from ``theta0`` ((p,), e.g. the equation-error estimate; inertia kept >= 1e-3)."""
        p_model = theta0.size
        th0 = theta0.copy()
        th0[0] = max(th0[0], 1e-2)
        if self.free_v0:  # initial velocity of every segment free (a wrong v0 would bias the integrated depth)
            th0 = np.concatenate([th0, self.segments.v0])
        lower = np.full(th0.size, -np.inf)
        lower[0] = 1e-3
        sol = optimize.least_squares(self.residuals, th0, bounds=(lower, np.inf), x_scale="jac", method="trf",
                                     args=(p_model,))
        r = sol.fun
        n, p = r.size, th0.size
        mask = self.segments.mask
        n_extra = mask.shape[0] if self.measured == "position" else 0
        dof_res = n - p - n_extra
        sigma2 = float(r @ r) / max(dof_res, 1)
        J = sol.jac
        cov = (sigma2 * np.linalg.pinv(J.T @ J))[:p_model, :p_model]
        # AR(1) inflation from consecutive residuals inside segments: consecutive *samples* (a 10 Hz sensor on the
        # 100 Hz tick grid has no two samples on adjacent ticks, so pairs of adjacent ticks would find none)
        seg_of = self.segments.sample_segment
        same = seg_of[1:] == seg_of[:-1]
        num = float(np.sum((r[1:] * r[:-1])[same]))
        den = float(r @ r)
        rho = max(0.0, min(0.95, num / den)) if den > 0 else 0.0
        cov *= (1.0 + rho) / (1.0 - rho)
        cov = at_least_cluster_robust(cov, J, r, seg_of, p_model)
        theta, v0 = self._split(sol.x, p_model)
        V, _ = self.simulate(theta, v0)
        v_fit = np.full(self.n_ticks, np.nan)
        v_fit[self.segments.index.ravel()] = V.ravel()
        return OutputErrorResult(sol.x[:p_model], cov, dof_res, v_fit, rho)


def at_least_cluster_robust(cov: np.ndarray, J: np.ndarray, r: np.ndarray, cluster: np.ndarray,
                            p_model: int) -> np.ndarray:
    """``cov`` (p_model, p_model) widened, parameter by parameter, to at least the cluster-robust (sandwich)
    covariance with one cluster per segment: ``G / (G - 1) (J^T J)^-1 (sum_g J_g^T r_g r_g^T J_g) (J^T J)^-1``
    (Liang and Zeger 1986). It holds whatever the correlation of the residuals inside a segment, e.g. the slowly
    varying misfit a 1-DOF model leaves when the vehicle's other DOFs move, which the residual variance and
    the lag-1 correction miss. Scaling is ``D cov D`` with ``D = diag(max(1, sandwich_ii / cov_ii))^(1/2)``, so the
    result stays a covariance. Fewer than 3 clusters: ``cov`` unchanged."""
    groups = np.unique(cluster)
    if groups.size < 3:
        return cov
    JtJ_inv = np.linalg.pinv(J.T @ J)
    scores = np.array([J[cluster == g].T @ r[cluster == g] for g in groups])  # (G, p)
    sandwich = (JtJ_inv @ (scores.T @ scores) @ JtJ_inv)[:p_model, :p_model] * groups.size / (groups.size - 1)
    var = np.diag(cov)
    ratio = np.where(var > 0, np.diag(sandwich) / np.where(var > 0, var, 1.0), 1.0)
    d = np.sqrt(np.maximum(1.0, ratio))
    return cov * np.outer(d, d)
