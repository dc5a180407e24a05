"""Batch least squares with parameter standard deviations ([Hindrax-Drag], eqs. 2-8).

This module is the offline estimation core of the identification package:

* :func:`fit_linear_model` is the ordinary least-squares estimator of [Hindrax-Drag] eq. 6, theta = (X^T X)^-1 X^T Y,
  with the parameter covariance sigma^2 (X^T X)^-1 (eq. 7) and the unbiased residual variance sigma^2 = S / (n - p) of
  eq. 8 (Beck and Arnold 1977; also docs/identification.md §1.D "Ordinary LS covariance").
* :func:`fit_drag` fits [Hindrax-Drag] eq. 2, F = k_q |v| v + k_l v + b, to steady-state samples.
  [Hindrax-Drag] eq. 3 prints the regressor column as x^2; we use |v| v, as eq. 2 and its text state ("the absolute
  value symbol is to conserve the velocity sign"), so that one model covers both signs of the velocity.

Why not ``numpy.linalg.lstsq`` alone: it returns theta but neither the covariance of eq. 7 nor a rank diagnosis we can
turn into a clear error; we use an SVD of the regressor with its columns scaled to unit norm (numerically equivalent to
lstsq; regressors of very different magnitudes, such as P^3 and 1 of a thruster curve, then trigger no false rank
deficiency) and build the covariance from the same SVD, mapped back exactly to the original columns.

The module also hosts :class:`EstimationError` and the small input-validation helpers shared
by the other estimation modules (one place, no copy-paste).

Conventions: SI units; forces in N (moments in N m), velocities in m/s (rad/s), accelerations in m/s^2 (rad/s^2).
Damping and inertia are reported as positive numbers (Fossen/SNAME, docs/architecture.md §3)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional, Sequence

import numpy as np

__all__ = ["EstimationError", "LsResult", "DragFit", "fit_linear_model", "fit_drag"]


class EstimationError(ValueError):
    """Bad input to an estimation routine (shape, NaN, too few samples, rank deficiency).

    Subclass of ``ValueError`` so callers can catch either. Raised by every module of
    ``hindrax_onboard.estimation`` for bad data; the message names the offending argument."""


# Shared validation helpers (used by rls, filters, steady_windows, free_decay, ...)
def positive(value: float, name: str) -> float:
    """``value`` as a float; EstimationError naming ``name`` unless it is finite and > 0."""
    value = float(value)
    if not (np.isfinite(value) and value > 0):
        raise EstimationError(f"{name} must be a finite number > 0, got {value}")
    return value


def as_float_array(value, name: str, ndim: int, allow_nan: bool = False) -> np.ndarray:
    """``value`` as a float ndarray of ``ndim`` dimensions (1 or 2); EstimationError naming ``name``
    when it is not numeric, has another number of dimensions, or holds non-finite values (NaN is
    accepted with ``allow_nan``, inf never)."""
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise EstimationError(f"{name}: not a numeric array ({exc})") from None
    if arr.ndim != ndim:
        raise EstimationError(f"{name}: expected a {ndim}-D array, got shape {arr.shape}")
    if allow_nan:
        if np.any(np.isinf(arr)):
            raise EstimationError(f"{name}: contains infinite values")
    elif not np.all(np.isfinite(arr)):
        raise EstimationError(f"{name}: contains NaN or infinite values")
    return arr


def check_same_length(**arrays: np.ndarray) -> int:
    """Return the common length of 1-D/2-D arrays (first axis) or raise EstimationError."""
    lengths = {name: len(a) for name, a in arrays.items()}
    if len(set(lengths.values())) != 1:
        raise EstimationError(f"arrays must have the same length, got {lengths}")
    return next(iter(lengths.values()))


def check_time_vector(t, name: str = "t_s", min_samples: int = 2) -> np.ndarray:
    """``t`` checked as a time vector: 1-D, finite, strictly increasing, at least ``min_samples``
    long; EstimationError naming ``name`` otherwise."""
    t = as_float_array(t, name, 1)
    if t.size < min_samples:
        raise EstimationError(f"{name}: need at least {min_samples} samples, got {t.size}")
    if np.any(np.diff(t) <= 0.0):
        raise EstimationError(f"{name}: time stamps must be strictly increasing")
    return t


# Results
@dataclass(frozen=True, eq=False)
class LsResult:
    """Result of an ordinary least-squares fit ([Hindrax-Drag] eqs. 6-8).

    Attributes:
        theta: (p,) estimated parameters, eq. 6.
        std: (p,) standard deviations sqrt(diag(covariance)), eq. 7.
        covariance: (p, p) parameter covariance sigma2 (X^T X)^-1, eq. 7.
        sigma2: residual variance S / (n - p), eq. 8 (units of y squared).
        residuals: (n,) y - X theta.
        n: number of samples.
        p: number of parameters.
        names: optional parameter names (length p), used by :meth:`index`."""

    theta: np.ndarray
    std: np.ndarray
    covariance: np.ndarray
    sigma2: float
    residuals: np.ndarray
    n: int
    p: int
    names: Optional[tuple] = field(default=None)

    @property
    def dof(self) -> int:
        """Residual degrees of freedom n - p."""
        return self.n - self.p

    @property
    def residual_std(self) -> float:
        """sqrt(sigma2): standard deviation of the residuals (units of y)."""
        return float(np.sqrt(self.sigma2))

    def index(self, name: str) -> int:
        """Index of the parameter called ``name``; KeyError if unknown or unnamed."""
        if self.names is None or name not in self.names:
            raise KeyError(f"no parameter named {name!r} (names: {self.names})")
        return self.names.index(name)


class _Param:
    """A fit's attribute ``<name>``: the fitted value of parameter ``<name>``; ``<name>_std``: its
    standard deviation (from the fit's :class:`LsResult`)."""

    def __init__(self, doc: str) -> None:
        self.__doc__ = doc

    def __set_name__(self, owner: type, name: str) -> None:
        self.std = name.endswith("_std")
        self.name = name[:-4] if self.std else name

    def __get__(self, fit: "DragFit | None", owner: type) -> float:
        if fit is None:
            return self  # type: ignore[return-value]  # the class attribute (documentation)
        ls = fit.ls
        return float((ls.std if self.std else ls.theta)[ls.index(self.name)])


@dataclass(frozen=True, eq=False)
class DragFit:
    """Steady-state drag fit of [Hindrax-Drag] eq. 2: F = k_q |v| v + k_l v + b.

    Parameter names in ``ls.names``: ``quadratic_damping`` (N/(m/s)^2 or N m/(rad/s)^2),
    ``linear_damping`` (N/(m/s) or N m/(rad/s)), ``bias`` (N or N m)."""

    ls: LsResult

    quadratic_damping = _Param("Quadratic damping k_q of [Hindrax-Drag] eq. 2.")
    quadratic_damping_std = _Param("Standard deviation of k_q ([Hindrax-Drag] eq. 7).")
    linear_damping = _Param("Linear damping k_l of [Hindrax-Drag] eq. 2 (Table 3 second column).")
    linear_damping_std = _Param("Standard deviation of k_l.")
    bias = _Param("Constant force/moment b of [Hindrax-Drag] eq. 2 (Table 3 third column; net buoyancy in heave).")
    bias_std = _Param("Standard deviation of b.")

    def predict(self, velocity) -> np.ndarray:
        """Model force F(v) (same units as the fitted force) at ``velocity`` (array-like)."""
        return _drag_regressors(np.asarray(velocity, dtype=float)) @ self.ls.theta


# Core estimator
def fit_linear_model(X, y, names: Optional[Sequence[str]] = None) -> LsResult:
    """Ordinary least squares with parameter covariance ([Hindrax-Drag] eqs. 4-8).

    theta = (X^T X)^-1 X^T y (eq. 6), sigma2 = |y - X theta|^2 / (n - p) (eq. 8),
    covariance = sigma2 (X^T X)^-1 and std = sqrt(diag(covariance)) (eq. 7); numerics in the
    module docstring.

    Args:
        X: (n, p) regressor matrix (finite).
        y: (n,) observations (finite), e.g. forces in N.
        names: optional p parameter names carried into the result.

    Returns:
        :class:`LsResult`.

    Raises:
        EstimationError (a ValueError): wrong shapes, NaN/inf, n <= p (eq. 8 needs n - p > 0),
            an all-zero column, or a rank-deficient X (the message gives the rank)."""
    X = as_float_array(X, "X", 2)
    y = as_float_array(y, "y", 1)
    n, p = X.shape
    if y.shape[0] != n:
        raise EstimationError(f"X has {n} rows but y has {y.shape[0]} samples")
    if p == 0:
        raise EstimationError("X has no columns")
    if n <= p:
        raise EstimationError(f"need more samples than parameters for eq. 8 (n - p > 0): n={n}, p={p}")
    if names is not None:
        names = tuple(str(s) for s in names)
        if len(names) != p:
            raise EstimationError(f"names has {len(names)} entries for {p} parameters")
    scale = np.linalg.norm(X, axis=0)
    if np.any(scale == 0.0):
        zero = [i if names is None else names[i] for i in np.flatnonzero(scale == 0.0)]
        raise EstimationError(f"regressor column(s) {zero} are identically zero (rank deficient)")
    Xs = X / scale
    U, s, Vt = np.linalg.svd(Xs, full_matrices=False)
    tol = max(n, p) * np.finfo(float).eps * s[0]  # as numpy.linalg.matrix_rank
    rank = int(np.sum(s > tol))
    if rank < p:
        raise EstimationError(
            f"regressor matrix is rank deficient (rank {rank} < {p} parameters): "
            "the data do not excite every term; add excitation or remove a regressor")
    theta_s = Vt.T @ ((U.T @ y) / s)
    theta = theta_s / scale
    residuals = y - X @ theta
    dof = n - p
    sigma2 = float(residuals @ residuals) / dof
    inv_xtx_s = (Vt.T / s**2) @ Vt  # (Xs^T Xs)^-1
    covariance = sigma2 * inv_xtx_s / np.outer(scale, scale)
    covariance = 0.5 * (covariance + covariance.T)
    std = np.sqrt(np.clip(np.diag(covariance), 0.0, None))
    return LsResult(theta=theta, std=std, covariance=covariance, sigma2=sigma2,
                    residuals=residuals, n=n, p=p, names=names)


# Hydrodynamic models
def _drag_regressors(v: np.ndarray) -> np.ndarray:
    """The regressors (n, 3) [|v| v, v, 1] of [Hindrax-Drag] eq. 2 at the velocities ``v`` (n,)."""
    return np.column_stack([np.abs(v) * v, v, np.ones_like(v)])


def fit_drag(velocity, force) -> DragFit:
    """Fit [Hindrax-Drag] eq. 2, F = k_q |v| v + k_l v + b, by least squares (eqs. 3-8).

    The regressor row is [|v| v, v, 1], not eq. 3's x^2 (module docstring).

    Args:
        velocity: (n,) steady velocity samples in m/s (rad/s for roll/pitch/yaw), body frame.
        force: (n,) applied thrust in N (moment in N m) balancing the drag at that velocity.

    Returns:
        :class:`DragFit` (values and standard deviations of k_q, k_l, b).

    Raises:
        EstimationError: shape mismatch, NaN, n <= p, or rank deficiency (e.g. one velocity)."""
    v = as_float_array(velocity, "velocity", 1)
    f = as_float_array(force, "force", 1)
    check_same_length(velocity=v, force=f)
    names = ["quadratic_damping", "linear_damping", "bias"]
    return DragFit(ls=fit_linear_model(_drag_regressors(v), f, names))

