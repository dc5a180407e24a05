"""Thruster curve fit from bollard-pull data ([Hindrax-Drag] eq. 1, section 2.2.1, Table 2).

[Hindrax-Drag] models the bollard-pull thrust of one thruster as a cubic in the ESC pulse width P (us),
one cubic per rotation direction:

    tau = c4 P^3 + c3 P^2 + c2 P + c1          (eq. 1, coefficients by LS)

with 1100-1500 us the negative rotation, 1500 us stop and 1500-1900 us the positive rotation.

Direction split and the neutral point (our documented choice): samples with
P < neutral_us - neutral_tolerance_us go to the negative fit, P > neutral_us +
neutral_tolerance_us to the positive fit; samples at neutral (within the tolerance; zero
thrust) are added to BOTH fits when ``include_neutral`` is True (default), so each cubic is
anchored at the stop point. An ESC dead band can be excluded with ``deadband_us``: samples with
0 < |P - neutral| <= deadband_us are dropped.

Conditioning: raw powers of P (P^3 ~ 7e9 us^3) make X^T X extremely ill-conditioned. We fit the
cubic in the centred and scaled variable s = (P - neutral_us) / scale_us (scale 400 us) with
:func:`hindrax_onboard.estimation.least_squares.fit_linear_model`, then map the coefficients to the
[Hindrax-Drag]'s raw form exactly: tau = sum_k a_k s^k = sum_j c_j P^j with c = T a, where
T[j, k] = binom(k, j) (-neutral)^(k-j) / scale^k, and the covariance is propagated exactly,
Cov(c) = T Cov(a) T^T. The raw standard deviations are large and strongly correlated (as in
[Hindrax-Drag] Table 2, e.g. c1 = 927.18 +- 137.82): use :meth:`CubicFit.predict_std` for the
uncertainty of the thrust itself.

Relative thrust uncertainty for the identification intervals (our definition, [Hindrax-Drag] gives
none): a self-propelled identification sees the thrust only through a scale (every identified parameter scales
with it, docs/identification.md), so the curve's covariance is summarised per direction as the thrust-weighted RMS
relative standard deviation of the fitted mean thrust over the fitted pulse-width range,
``rel = sqrt(sum_P sd(P)^2 / sum_P f(P)^2)`` on a uniform grid of 101 widths (:meth:`CubicFit.relative_std`;
weighting by f^2 keeps the widths near neutral, where f -> 0, from dominating). ``hindrax ident thruster-fit
--write`` stores it as ``thrusters.thrust_fit_uncertainty_rel`` = [negative, positive], which then replaces the
declared ``thrusters.thrust_uncertainty_rel`` in the intervals
(:mod:`hindrax_fit.assessment.verdicts`). It is the fit's statistical uncertainty at the bollard-pull
test's battery voltage only; a voltage that sags during a session (thrust ~ V^1.2, docs/devices.md §5.3) is not in it.

:func:`point_reflection` builds f_pos(P) = -f_neg(2 neutral - P). The vehicle configuration uses it because
[Hindrax-Drag] Table 2's printed positive-direction row evaluates to about -1070 N at 1500 us (docs/architecture.md §4),
while the negative row is consistent (-15.6 N at 1100 us, about -1.1 N at 1500 us)."""

from __future__ import annotations

from dataclasses import dataclass
from math import comb
from typing import Tuple

import numpy as np
from numpy.polynomial import Polynomial

from .least_squares import EstimationError, LsResult, as_float_array, check_same_length, fit_linear_model

__all__ = ["CubicFit", "ThrusterCurveFit", "fit_cubic", "fit_thruster_curve", "point_reflection", "NEUTRAL_US"]

#: ESC stop pulse width ([Hindrax-Drag] section 2.2.1).
NEUTRAL_US = 1500.0
_SCALE_US = 400.0


def _raw_transform(centre: float, scale: float) -> np.ndarray:
    """T with c_raw (ascending powers of P) = T @ a (ascending powers of s = (P - centre)/scale)."""
    T = np.zeros((4, 4))
    for k in range(4):
        for j in range(k + 1):
            T[j, k] = comb(k, j) * (-centre) ** (k - j) / scale**k
    return T


@dataclass(frozen=True, eq=False)
class CubicFit:
    """One cubic tau(P) = c4 P^3 + c3 P^2 + c2 P + c1 with exact raw covariance.

    Attributes:
        c4, c3, c2, c1: raw coefficients (N/us^3, N/us^2, N/us, N), [Hindrax-Drag] naming.
        c4_std, c3_std, c2_std, c1_std: their standard deviations ([Hindrax-Drag] eq. 7, propagated).
        covariance: (4, 4) covariance of (c4, c3, c2, c1).
        n: number of samples used; residual_std_n: sqrt(sigma^2) of eq. 8 in N.
        centre_us, scale_us: the centring used internally; ls: the centred LS result
            (coefficients of s^3, s^2, s, 1).
        pulse_width_min_us, pulse_width_max_us: range of the data."""

    c4: float
    c3: float
    c2: float
    c1: float
    c4_std: float
    c3_std: float
    c2_std: float
    c1_std: float
    covariance: np.ndarray
    n: int
    residual_std_n: float
    centre_us: float
    scale_us: float
    pulse_width_min_us: float
    pulse_width_max_us: float
    ls: LsResult

    @property
    def coefficients(self) -> Tuple[float, float, float, float]:
        """(c4, c3, c2, c1)."""
        return (self.c4, self.c3, self.c2, self.c1)

    def _centred_rows(self, pulse_width_us) -> np.ndarray:
        P = np.atleast_1d(np.asarray(pulse_width_us, dtype=float))
        s = (P - self.centre_us) / self.scale_us
        return np.column_stack([s**3, s**2, s, np.ones_like(s)])

    def predict(self, pulse_width_us) -> float | np.ndarray:
        """Thrust in N at pulse widths in us (evaluated in the centred form)."""
        out = self._centred_rows(pulse_width_us) @ self.ls.theta
        return float(out[0]) if np.ndim(pulse_width_us) == 0 else out

    def predict_std(self, pulse_width_us) -> float | np.ndarray:
        """Standard deviation in N of the fitted mean thrust at pulse widths in us."""
        X = self._centred_rows(pulse_width_us)
        out = np.sqrt(np.einsum("ij,jk,ik->i", X, self.ls.covariance, X))
        return float(out[0]) if np.ndim(pulse_width_us) == 0 else out

    def relative_std(self) -> float:
        """Thrust-weighted RMS relative std of the fitted mean thrust over [pulse_width_min_us, pulse_width_max_us]
        (dimensionless, module docstring): sqrt(sum sd^2 / sum f^2) on 101 uniformly spaced widths.

        Raises:
            EstimationError: the fitted thrust is zero over the whole range."""
        P = np.linspace(self.pulse_width_min_us, self.pulse_width_max_us, 101)
        f2 = float(np.sum(np.asarray(self.predict(P)) ** 2))
        if not f2 > 0.0:
            raise EstimationError("the fitted thrust is zero over the data's range: no relative uncertainty")
        return float(np.sqrt(np.sum(np.asarray(self.predict_std(P)) ** 2) / f2))

    def to_dict(self) -> dict:
        """{c4..c1, c4_std..c1_std, n, residual_std_n, thrust_relative_std, pulse_width_min_us, pulse_width_max_us}."""
        keys = ("c4", "c3", "c2", "c1", "c4_std", "c3_std", "c2_std", "c1_std")
        return {**{k: float(getattr(self, k)) for k in keys}, "n": int(self.n),
                "residual_std_n": float(self.residual_std_n), "thrust_relative_std": self.relative_std(),
                "pulse_width_min_us": float(self.pulse_width_min_us),
                "pulse_width_max_us": float(self.pulse_width_max_us)}


@dataclass(frozen=True, eq=False)
class ThrusterCurveFit:
    """Both rotation directions: ``negative`` (P < neutral) and ``positive`` (P > neutral)."""

    negative: CubicFit
    positive: CubicFit
    neutral_us: float

    def predict(self, pulse_width_us) -> float | np.ndarray:
        """Thrust in N: negative cubic below neutral, positive above, 0 at neutral exactly."""
        P = np.asarray(pulse_width_us, dtype=float)
        flat = np.atleast_1d(P).ravel()
        out = np.zeros_like(flat)
        lo, hi = flat < self.neutral_us, flat > self.neutral_us
        if np.any(lo):
            out[lo] = self.negative.predict(flat[lo])
        if np.any(hi):
            out[hi] = self.positive.predict(flat[hi])
        return float(out[0]) if P.ndim == 0 else out.reshape(P.shape)

    def relative_std(self) -> Tuple[float, float]:
        """(negative, positive) :meth:`CubicFit.relative_std`, the value for
        ``thrusters.thrust_fit_uncertainty_rel``."""
        return (self.negative.relative_std(), self.positive.relative_std())

    def to_dict(self) -> dict:
        """``{"negative": {...}, "positive": {...}, "neutral_us": ...}`` (see CubicFit.to_dict)."""
        return {"negative": self.negative.to_dict(), "positive": self.positive.to_dict(),
                "neutral_us": float(self.neutral_us)}


def fit_cubic(pulse_width_us, thrust_n, centre_us: float = NEUTRAL_US) -> CubicFit:
    """LS fit of tau = c4 P^3 + c3 P^2 + c2 P + c1 ([Hindrax-Drag] eq. 1) with exact raw covariance.

    Args:
        pulse_width_us: (n,) pulse widths in us.
        thrust_n: (n,) measured bollard-pull thrust in N.
        centre_us: centring of P used internally, scaled by 400 us (module docstring).

    Raises:
        EstimationError: fewer than 5 samples (n > p = 4), fewer than 4 distinct pulse widths,
            NaN, shape mismatch."""
    P = as_float_array(pulse_width_us, "pulse_width_us", 1)
    F = as_float_array(thrust_n, "thrust_n", 1)
    check_same_length(pulse_width_us=P, thrust_n=F)
    if np.unique(P).size < 4:
        raise EstimationError("a cubic needs at least 4 distinct pulse widths")
    s = (P - centre_us) / _SCALE_US
    ls = fit_linear_model(np.column_stack([s**3, s**2, s, np.ones_like(s)]), F, names=("a3", "a2", "a1", "a0"))
    # ascending order for the transform
    a_asc = ls.theta[::-1]
    cov_asc = ls.covariance[::-1, ::-1]
    T = _raw_transform(centre_us, _SCALE_US)
    c_asc = T @ a_asc
    cov_c_asc = T @ cov_asc @ T.T
    c_desc = c_asc[::-1]                    # (c4, c3, c2, c1)
    cov_desc = cov_c_asc[::-1, ::-1]
    std = np.sqrt(np.clip(np.diag(cov_desc), 0.0, None))
    return CubicFit(c4=float(c_desc[0]), c3=float(c_desc[1]), c2=float(c_desc[2]), c1=float(c_desc[3]),
                    c4_std=float(std[0]), c3_std=float(std[1]), c2_std=float(std[2]), c1_std=float(std[3]),
                    covariance=cov_desc, n=ls.n, residual_std_n=ls.residual_std, centre_us=float(centre_us),
                    scale_us=_SCALE_US, pulse_width_min_us=float(P.min()), pulse_width_max_us=float(P.max()), ls=ls)


def fit_thruster_curve(pulse_width_us, thrust_n, neutral_us: float = NEUTRAL_US,
                       include_neutral: bool = True, neutral_tolerance_us: float = 0.5,
                       deadband_us: float = 0.0) -> ThrusterCurveFit:
    """Fit one cubic per rotation direction from bollard-pull data ([Hindrax-Drag] section 2.2.1).

    Args:
        pulse_width_us: (n,) pulse widths in us ([Hindrax-Drag]: 1100-1900 us).
        thrust_n: (n,) thrust in N (negative for the negative rotation).
        neutral_us: stop pulse width (1500 us).
        include_neutral: add the samples at neutral to both fits (module docstring).
        neutral_tolerance_us: |P - neutral| <= this counts as neutral.
        deadband_us: drop samples with neutral_tolerance_us < |P - neutral| <= deadband_us.

    Returns:
        :class:`ThrusterCurveFit`.

    Raises:
        EstimationError: bad input or too few samples on one side (see :func:`fit_cubic`)."""
    P = as_float_array(pulse_width_us, "pulse_width_us", 1)
    F = as_float_array(thrust_n, "thrust_n", 1)
    check_same_length(pulse_width_us=P, thrust_n=F)
    d = P - float(neutral_us)
    neutral = np.abs(d) <= neutral_tolerance_us
    keep = neutral | (np.abs(d) > deadband_us)
    neg = keep & (d < -neutral_tolerance_us)
    pos = keep & (d > neutral_tolerance_us)
    if include_neutral:
        neg = neg | neutral
        pos = pos | neutral
    fits = {}
    for name, mask in (("negative", neg), ("positive", pos)):
        try:
            fits[name] = fit_cubic(P[mask], F[mask], centre_us=float(neutral_us))
        except EstimationError as exc:
            raise EstimationError(f"{name} direction: {exc}") from None
    return ThrusterCurveFit(negative=fits["negative"], positive=fits["positive"], neutral_us=float(neutral_us))


def point_reflection(c4: float, c3: float, c2: float, c1: float,
                     neutral_us: float = NEUTRAL_US) -> Tuple[float, float, float, float]:
    """Coefficients of f_pos(P) = -f_neg(2 neutral - P) (point reflection about (neutral, 0)).

    Args:
        c4, c3, c2, c1: the negative-direction cubic ([Hindrax-Drag] Table 2 naming).
        neutral_us: centre of the reflection (1500 us).

    Returns:
        (c4', c3', c2', c1') of the reflected cubic, so that
        f_pos(neutral + d) = -f_neg(neutral - d). Exact polynomial composition (numpy.polynomial)."""
    f_neg = Polynomial([c1, c2, c3, c4])
    reflected = -f_neg(Polynomial([2.0 * float(neutral_us), -1.0]))
    coef = np.zeros(4)
    coef[:len(reflected.coef)] = reflected.coef
    return (float(coef[3]), float(coef[2]), float(coef[1]), float(coef[0]))
