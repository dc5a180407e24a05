"""Recursive least squares with exponential forgetting, calibrated covariance and an
excitation measure (online identification per DOF, docs/architecture.md §5).

Update (docs/identification.md §1.D, forgetting factor lambda in (0, 1]):

    e     = y - phi^T theta                      (a-priori error, returned by ``update``)
    K     = P phi / (lambda + phi^T P phi)
    theta = theta + K e
    P     = (P - K phi^T P) / lambda

P is the inverse of the forgetting-weighted information matrix
W_k = lambda^k P0^-1 + sum_j lambda^(k-j) phi_j phi_j^T, so theta is the weighted LS estimate
with weights w_j = lambda^(k-j).

Noise variance and calibrated covariance (our estimator; the papers contain no recursive LS):

* Weighted residual sum of squares, exact recursion for weighted LS:
  S_k = lambda S_{k-1} + lambda e_k^2 / (lambda + phi_k^T P_{k-1} phi_k).
* Its expectation is sigma^2 (sum_j w_j - tr(P Q)) with Q_k = lambda^2 Q_{k-1} + phi phi^T
  (the information matrix with squared weights), so
  sigma2_hat = S_k / (N_eff - tr(P Q)), N_eff = sum_j lambda^(k-j).
  With lambda = 1 this is [Hindrax-Drag] eq. 8, S / (n - p).
* The covariance of a weighted LS estimate is sigma^2 P Q P (sandwich form). The prior is
  treated as a pseudo-measurement, Q_0 = P0^-1, so that the covariance starts at
  sigma^2 P0 and, for lambda = 1, P Q P = P exactly: the covariance is sigma2_hat * P, the
  batch covariance of [Hindrax-Drag] eq. 7 (plus the negligible diffuse prior).
  :meth:`RecursiveLeastSquares.reset_covariance` restarts Q = P^-1 in the same way.
  For lambda < 1 the plain sigma2_hat * P (i.e. std = sqrt(diag(P) sigma2_hat)) overstates
  the variance (by the factor 1 + lambda, about 2, for a constant regressor in steady state);
  the sandwich is exact for constant parameters and white noise, which is what "calibrated" means
  here (checked by Monte Carlo in test_rls.py). It does not include the lag error of tracking
  parameters that actually change.

Persistence of excitation: R_k = lambda R_{k-1} + phi phi^T normalised by the effective
window N_eff; :attr:`RecursiveLeastSquares.excitation` is its smallest eigenvalue (units of
phi^2: near zero when some direction of parameter space is not excited, e.g. a constant
regressor), and :attr:`RecursiveLeastSquares.excitation_normalised` is the smallest eigenvalue of
D^-1/2 R D^-1/2 (D = diag R), dimensionless in [0, 1], independent of regressor units.

Anti wind-up: with lambda < 1 and poor excitation P grows as lambda^-k in the unexcited
directions. When ``max_covariance`` is set (default: the initial covariance), the eigenvalues of
P are clipped to it after each update (the eigen-decomposition is only computed when trace(P)
exceeds the bound, which is cheap to test). :meth:`RecursiveLeastSquares.reset_covariance`
restarts P explicitly.

Honesty options (all off by default in this class; the identification executive switches them on,
:func:`hindrax_onboard.identification.online.estimators.online_rls`; why each is needed:
docs/identification.md §1.D):

* ``directional=True``: directional forgetting (Bittanti, Bolzern and Campi 1990, "Recursive least
  squares identification algorithms with incomplete excitation", IEEE TAC 35(12); Kulhavy 1987):
  ``P^-1 <- P^-1 + eps phi phi^T`` with ``eps = mu - (1 - mu) / (phi^T P phi)`` (mu = the forgetting
  factor), i.e. ``P <- P - P phi phi^T P / (1 / eps + phi^T P phi)``; covariance sigma2_hat * P.
* ``min_excitation``: once :attr:`excitation_normalised` (which always accumulates) has reached this
  value, theta and P are updated only while it stays at or above it; before that every sample
  updates (nothing is published then, :meth:`converged_mask`).
* ``lower_bounds`` (p,): :attr:`theta` is the unconstrained estimate projected onto theta >= lb
  (NaN = unbounded) in the P^-1 metric, min (t - theta_u)^T P^-1 (t - theta_u), the exact
  constrained minimiser of the forgetting-weighted cost (Goodwin and Sin 1984, "Adaptive Filtering
  Prediction and Control", ch. 3), by an active set (p <= 6). The recursion keeps the
  unconstrained estimate; :meth:`at_bound` says which parameters sit on their bound.
* ``change_threshold``: when the mean of the normalised a-priori error ``e^2 / (sigma2_hat (1 + phi^T P phi))``
  (chi-square with 1 degree of freedom for a correct model) over ``change_samples`` consecutive samples exceeds it, the
  covariance is reset (:meth:`reset_covariance`) and the residual statistics restart (:attr:`changes_detected`).
* :meth:`published_std`: the std where the estimate has converged (std <= rel_tol |theta| + abs_tol,
  enough samples, excitation above ``min_excitation``), NaN ("not converged") elsewhere.

Everything is a few small dense numpy operations per sample (p = 4..6), fast enough for 50-100 Hz per DOF."""

from __future__ import annotations

from collections import deque
from typing import Optional

import numpy as np

from .least_squares import EstimationError, as_float_array

__all__ = ["RecursiveLeastSquares"]


class RecursiveLeastSquares:
    """Recursive least squares with exponential forgetting (docs/identification.md §1.D).

    Model: y_k = phi_k^T theta + e_k with white e_k of variance sigma^2. Typical use, one
    instance per DOF with regressor [nu_dot, |nu| nu, nu, 1] -> tau (docs/architecture.md §5).

    Args:
        n_params: number of parameters p (>= 1).
        forgetting: lambda in (0, 1]; 1 = no forgetting (converges to batch LS); the
            effective memory is about 1 / (1 - lambda) samples.
        initial_covariance: P0 = initial_covariance * I (scalar > 0) or a (p, p) SPD matrix.
        initial_theta: optional (p,) start value (default zeros).
        max_covariance: upper bound on the eigenvalues of P (anti wind-up); ``None`` (default)
            means the largest eigenvalue of P0; pass ``float('inf')`` to disable bounding.
        directional: directional forgetting instead of exponential (module docstring).
        min_excitation: update only while excitation_normalised >= this (0 = always).
        lower_bounds: optional (p,) lower bounds on theta (NaN = none), e.g. 0 for damping.
        change_threshold: mean normalised a-priori error over ``change_samples`` samples above which a change is
            declared and the covariance reset (None = off).
        change_samples: window of the change detector (samples).

    Raises:
        EstimationError: invalid sizes or values."""

    def __init__(self, n_params: int, forgetting: float = 0.995, initial_covariance=1e3, initial_theta=None,
                 max_covariance: Optional[float] = None, directional: bool = False,
                 min_excitation: float = 0.0, lower_bounds=None,
                 change_threshold: Optional[float] = None, change_samples: int = 50):
        if int(n_params) != n_params or n_params < 1:
            raise EstimationError(f"n_params must be a positive integer, got {n_params}")
        self._p = int(n_params)
        lam = float(forgetting)
        if not (0.0 < lam <= 1.0):
            raise EstimationError(f"forgetting must be in (0, 1], got {forgetting}")
        self._lambda = lam
        P0 = np.asarray(initial_covariance, dtype=float)
        if P0.ndim == 0:
            if not (np.isfinite(P0) and P0 > 0):
                raise EstimationError(f"initial_covariance must be > 0, got {initial_covariance}")
            P0 = float(P0) * np.eye(self._p)
        elif P0.shape != (self._p, self._p) or not np.all(np.isfinite(P0)):
            raise EstimationError(f"initial_covariance must be a scalar or ({self._p}, {self._p})")
        else:
            P0 = 0.5 * (P0 + P0.T)
            if np.linalg.eigvalsh(P0)[0] <= 0:
                raise EstimationError("initial_covariance must be positive definite")
        self._P0 = P0.copy()
        if max_covariance is None:
            max_covariance = float(np.linalg.eigvalsh(P0)[-1])
        if not max_covariance > 0:
            raise EstimationError(f"max_covariance must be > 0, got {max_covariance}")
        self._max_cov = float(max_covariance)
        if initial_theta is None:
            theta0 = np.zeros(self._p)
        else:
            theta0 = as_float_array(initial_theta, "initial_theta", 1)
            if theta0.size != self._p:
                raise EstimationError(f"initial_theta must have {self._p} entries")
        self._theta0 = theta0.copy()
        self.directional = bool(directional)
        self.min_excitation = float(min_excitation)
        if not (0.0 <= self.min_excitation <= 1.0):
            raise EstimationError(f"min_excitation must be in [0, 1], got {min_excitation}")
        if lower_bounds is None:
            self._lb = None
        else:
            lb = np.asarray(lower_bounds, dtype=float)
            if lb.shape != (self._p,):
                raise EstimationError(f"lower_bounds must have {self._p} entries")
            self._lb = np.where(np.isnan(lb), -np.inf, lb)
        if change_threshold is not None and not change_threshold > 1.0:
            raise EstimationError(f"change_threshold must be > 1 (chi-square mean), got {change_threshold}")
        self.change_threshold = change_threshold
        self.change_samples = max(1, int(change_samples))
        self.reset()

    # ------------------------------------------------------------------ state management
    def reset(self) -> None:
        """Forget everything: theta = initial_theta, P = P0, statistics cleared."""
        p = self._p
        self._theta = self._theta0.copy()
        self._P = self._P0.copy()
        self._Q = np.linalg.inv(self._P0)  # prior pseudo-data + sum lambda^(2(k-j)) phi phi^T
        self._R = np.zeros((p, p))      # sum lambda^(k-j) phi phi^T (excitation)
        self._S = 0.0                   # weighted residual sum of squares
        self._w = 0.0                   # effective window sum lambda^(k-j) of the samples that updated theta
        self._wr = 0.0                  # the same over every sample (normalises the excitation)
        self._n = 0
        self._covariance_resets = 0
        self._changes = 0
        self._nis: deque[float] = deque(maxlen=self.change_samples)
        self._gated = 0
        self._gate_open = False
        self._theta_c: Optional[np.ndarray] = None   # cached constrained estimate (None = recompute)

    def reset_covariance(self) -> None:
        """Restart P at P0 keeping theta and statistics (after a parameter change: adaptation
        re-opens; the reported covariance restarts at sigma2_hat * P, theta taken as a prior)."""
        self._P = self._P0.copy()
        self._Q = np.linalg.inv(self._P)
        self._covariance_resets += 1
        self._theta_c = None

    # ------------------------------------------------------------------ update
    def update(self, phi, y: float) -> float:
        """Process one sample; return the a-priori error y - phi^T theta_{k-1}.

        Args:
            phi: (p,) regressor vector (finite).
            y: observation (finite), e.g. force in N.

        Raises:
            EstimationError: wrong size or non-finite input (the state is left unchanged)."""
        phi = np.asarray(phi, dtype=float)
        if phi.shape != (self._p,):
            raise EstimationError(f"phi must have shape ({self._p},), got {phi.shape}")
        y = float(y)
        if not (np.all(np.isfinite(phi)) and np.isfinite(y)):
            raise EstimationError("phi and y must be finite")
        lam = self._lambda
        P = self._P
        Pphi = P @ phi
        r = float(phi @ Pphi)
        err = y - phi @ self._theta
        outer = np.outer(phi, phi)
        self._R = lam * self._R + outer
        self._wr = lam * self._wr + 1.0
        self._n += 1
        if self.min_excitation > 0.0:
            informative = self.excitation_normalised >= self.min_excitation
            self._gate_open = self._gate_open or informative
            if self._gate_open and not informative:
                self._gated += 1  # not informative enough: theta and P stay (the excitation keeps accumulating)
                return float(err)
        self._theta_c = None
        self._w = lam * self._w + 1.0
        if self.directional:
            denom = 1.0 + r
            K = Pphi / denom
            self._theta = self._theta + K * err
            eps = lam - (1.0 - lam) / r if r > 1e-12 else 1.0
            if eps > 0.0:
                P = P - np.outer(Pphi, Pphi) / (1.0 / eps + r)
            P = 0.5 * (P + P.T)
            self._S = lam * self._S + err * err / denom
        else:
            denom = lam + r
            K = Pphi / denom
            self._theta = self._theta + K * err
            P = (P - np.outer(K, Pphi)) / lam
            P = 0.5 * (P + P.T)
            self._S = lam * self._S + lam * err * err / denom
        if np.trace(P) > self._max_cov:
            ev, V = np.linalg.eigh(P)
            if ev[-1] > self._max_cov:
                P = (V * np.clip(ev, 0.0, self._max_cov)) @ V.T
        self._P = P
        self._Q = (lam * lam) * self._Q + outer
        if self.change_threshold is not None:
            s2 = self.sigma2
            if np.isfinite(s2) and s2 > 0.0:
                self._nis.append(err * err / (s2 * (1.0 + r)))  # the oldest falls out (maxlen)
                if len(self._nis) == self.change_samples and \
                        sum(self._nis) / self.change_samples > self.change_threshold:
                    self._changes += 1
                    self._nis.clear()
                    self.reset_covariance()
                    self._S = 0.0
                    self._w = 0.0
                    self._Q = np.linalg.inv(self._P)
        return float(err)

    def predict(self, phi) -> float:
        """Model output phi^T theta for a (p,) regressor (the constrained :attr:`theta`)."""
        return float(np.asarray(phi, dtype=float) @ self.theta)

    def _constrained(self) -> np.ndarray:
        """theta_u projected onto theta >= lb in the P^-1 metric (module docstring), by an active set: fix the
        violated parameters at their bounds, move the free ones by the conditional mean
        t_F = theta_F + P_FA P_AA^-1 (lb_A - theta_A), repeat until no free parameter violates its bound, then
        release a fixed parameter whose Lagrange multiplier has the wrong sign."""
        th = self._theta
        if self._lb is None or np.all(th >= self._lb):
            return th.copy()
        P = self._P
        active = th < self._lb
        t = th.copy()
        for _ in range(4 * self._p):
            A = np.flatnonzero(active)
            F = np.flatnonzero(~active)
            t = th.copy()
            t[A] = self._lb[A]
            if A.size:
                d = np.linalg.solve(P[np.ix_(A, A)], self._lb[A] - th[A])
                if F.size:
                    t[F] = th[F] + P[np.ix_(F, A)] @ d
                # multiplier of each active bound: the cost decreases when released if d < 0 (it pulls down)
                release = A[d < -1e-15]
            else:
                release = np.array([], dtype=int)
            viol = F[t[F] < self._lb[F] - 1e-12] if F.size else np.array([], dtype=int)
            if viol.size:
                active[viol] = True
            elif release.size:
                active[release[0]] = False
            else:
                break
        return np.maximum(t, self._lb)

    def at_bound(self) -> np.ndarray:
        """(p,) bool: parameters held on their lower bound by the constraint (False without bounds)."""
        if self._lb is None:
            return np.zeros(self._p, dtype=bool)
        return np.isfinite(self._lb) & (self.theta <= self._lb)

    # ------------------------------------------------------------------ estimates
    @property
    def theta(self) -> np.ndarray:
        """(p,) current estimate (copy), constrained to the lower bounds when given (module docstring)."""
        if self._lb is None:
            return self._theta.copy()
        if self._theta_c is None:
            self._theta_c = self._constrained()
        return self._theta_c.copy()

    @property
    def theta_unconstrained(self) -> np.ndarray:
        """(p,) the recursion's unconstrained estimate (equal to :attr:`theta` without bounds)."""
        return self._theta.copy()

    @property
    def gate_open(self) -> bool:
        """True once the excitation has reached ``min_excitation`` (always True without a gate)."""
        return self.min_excitation <= 0.0 or self._gate_open

    @property
    def P(self) -> np.ndarray:
        """(p, p) raw RLS matrix P (inverse weighted information, not scaled by sigma^2)."""
        return self._P.copy()

    @property
    def n_samples(self) -> int:
        """Number of samples processed since the last :meth:`reset`."""
        return self._n

    @property
    def effective_window(self) -> float:
        """N_eff = sum lambda^(k-j) (-> 1 / (1 - lambda) for long runs; = n when lambda = 1)."""
        return self._w

    @property
    def dof(self) -> float:
        """Effective residual degrees of freedom N_eff - tr(P Q) (= n - p for lambda = 1)."""
        if self.directional:
            return self._w - self._p
        return self._w - float(np.sum(self._P * self._Q))  # tr(P Q), both symmetric

    @property
    def sigma2(self) -> float:
        """Noise variance estimate S / (N_eff - tr(P Q)) (NaN until dof > 0.5)."""
        dof = self.dof
        if dof <= 0.5:
            return float("nan")
        return self._S / dof

    @property
    def covariance(self) -> np.ndarray:
        """(p, p) calibrated parameter covariance sigma2_hat * P Q P (module docstring).

        NaN-filled until enough samples for a noise estimate (dof > 0.5)."""
        s2 = self.sigma2
        if not np.isfinite(s2):
            return np.full((self._p, self._p), np.nan)
        if self.directional:  # P^-1 is the retained information (module docstring)
            return s2 * self._P.copy()
        C = s2 * (self._P @ self._Q @ self._P)
        return 0.5 * (C + C.T)

    @property
    def std(self) -> np.ndarray:
        """(p,) standard deviations sqrt(diag(covariance)) (NaN before a noise estimate)."""
        return np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))

    @property
    def excitation(self) -> float:
        """Smallest eigenvalue of R / N_eff (units of phi^2); 0 before any sample.

        R = sum lambda^(k-j) phi phi^T: near zero when a parameter direction is not excited."""
        if self._wr == 0.0:
            return 0.0
        return float(np.linalg.eigvalsh(self._R / self._wr)[0])

    @property
    def excitation_normalised(self) -> float:
        """Smallest eigenvalue of D^-1/2 R D^-1/2 (D = diag R), dimensionless in [0, 1].

        0 when a regressor is identically zero or regressors are collinear (e.g. constant
        phi); approaches 1 for orthogonal, equally weighted regressors."""
        d = np.diag(self._R)
        if self._wr == 0.0 or np.any(d <= 0.0):
            return 0.0
        s = 1.0 / np.sqrt(d)
        return float(max(0.0, np.linalg.eigvalsh(self._R * np.outer(s, s))[0]))

    @property
    def changes_detected(self) -> int:
        """Number of parameter changes the detector declared (each reset the covariance)."""
        return self._changes

    @property
    def gated_samples(self) -> int:
        """Samples skipped by the excitation gate."""
        return self._gated

    def converged_mask(self, rel_tol: float = 0.05, abs_tol=0.0, min_samples: Optional[int] = None) -> np.ndarray:
        """(p,) bool: std <= rel_tol |theta| + abs_tol per parameter (abs_tol scalar or (p,)), with at least
        ``min_samples`` samples (default 10 p) and the excitation at or above ``min_excitation``."""
        if min_samples is None:
            min_samples = 10 * self._p
        std = self.std
        if self._n < min_samples or self.excitation_normalised < self.min_excitation:
            return np.zeros(self._p, dtype=bool)
        ok = np.isfinite(std) & (std <= rel_tol * np.abs(self.theta) + np.asarray(abs_tol, dtype=float))
        return ok & ~self.at_bound()  # a parameter held on its bound has no interval of its own

    def published_std(self, rel_tol: float = 0.05, abs_tol=0.0, min_samples: Optional[int] = None) -> np.ndarray:
        """(p,) the std where :meth:`converged_mask` holds, NaN ("not converged") elsewhere."""
        return np.where(self.converged_mask(rel_tol, abs_tol, min_samples), self.std, np.nan)

    @property
    def covariance_resets(self) -> int:
        """Number of :meth:`reset_covariance` calls."""
        return self._covariance_resets
