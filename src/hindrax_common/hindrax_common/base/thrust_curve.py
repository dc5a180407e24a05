"""Thruster thrust curve: pulse width (us) <-> bollard-pull thrust (N), pure numpy.

Model ([Hindrax-Drag], section 2.2.1, eq. 1 and Table 2): the thrust of one thruster is a cubic in
the ESC pulse width P (us), ``tau = c4 P^3 + c3 P^2 + c2 P + c1``, one cubic for negative rotation
(1100-1500 us) and one for positive (1500-1900 us); 1500 us stops the motor. Coefficient tuples are
ordered ``(c4, c3, c2, c1)``, highest power first (``numpy.polyval`` order).

[Hindrax-Drag]'s Table 2 negative row gives -15.53 N at 1100 us and is monotone only up to 1495.8 us; its positive row
as printed is negative and decreasing on the forward side, which ``ThrustCurve`` rejects (``test/test_thrust_curve.py``
asserts both). Until a bollard-pull fit replaces it, the default positive curve is the point reflection of the negative
one about (1500 us, 0 N) (docs/architecture.md §4, :func:`point_reflection`).

ESC conventions (docs/devices.md §5.2, Blue Robotics Basic ESC): 1100 us full reverse, 1500 us stop, 1900 us full
forward, deadband 1500 +- 25 us (UNVERIFIED there). The forward model returns 0 N inside the deadband.

Inverse: on each side only the monotone branch from the range end towards neutral is used, ending at the cubic's first
extremum, its first zero or the deadband edge, whichever comes first (1100-1475 us and 1525-1900 us for the default
curve, +-1.20 N to +-15.53 N). A smaller force maps to whichever of 0 N and the branch's inner end is nearer
(``small_force="nearest"``, default) or to neutral (``"neutral"``); a larger one saturates at the end.
:meth:`ThrustCurve.thrust_n` gives the force actually produced. Each branch is tabulated once on a grid of at most
0.005 us and inverted with ``numpy.interp`` (vectorised, exact to the grid step; ``numpy.roots`` and ``brentq`` are one
Python call per thruster), about 2.4 MB per distinct curve; the tests check it against ``numpy.roots``.

Battery voltage (docs/devices.md §5.3: full-throttle thrust roughly as V^1.2): both directions take
``voltage_scale``, which multiplies the forward model and divides the requested force;
:func:`voltage_thrust_scale` gives it from a battery voltage."""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

__all__ = ["ThrustCurveError", "HINDRAX_DRAG_NEGATIVE_COEFFS", "HINDRAX_DRAG_POSITIVE_COEFFS_AS_PRINTED",
           "HINDRAX_NOMINAL_VOLTAGE_V", "BASIC_ESC_DEADBAND_US", "point_reflection", "voltage_thrust_scale",
           "check_positive", "ThrustCurve", "hindrax_default_curve", "forward_thrust"]

#: [Hindrax-Drag] Table 2, negative direction, ``(c4, c3, c2, c1)`` of eq. 1 (N, P in us).
HINDRAX_DRAG_NEGATIVE_COEFFS: tuple[float, float, float, float] = (-4.61e-7, 0.001794, -2.2726, 927.1827)
#: [Hindrax-Drag] Table 2, positive direction exactly as printed. Inconsistent (about -1070 N at 1500 us);
#: kept only to document and test that it is rejected.
HINDRAX_DRAG_POSITIVE_COEFFS_AS_PRINTED: tuple[float, float, float, float] = (-3.52e-7, 1.82e-4, -0.3106, 174.3542)
#: Hindrax battery nominal voltage, [Hindrax-Drag] section 2.1 (14.8 V, 19.2 Ah).
HINDRAX_NOMINAL_VOLTAGE_V = 14.8
#: Blue Robotics Basic ESC deadband half-width, docs/devices.md §5.2 (1500 +- 25 us; UNVERIFIED there).
BASIC_ESC_DEADBAND_US = 25.0

_TABLE_STEP_US = 0.005  # upper bound of the inverse's error (one table cell)
_SMALL_FORCE_POLICIES = ("nearest", "neutral")


class ThrustCurveError(ValueError):
    """Invalid thrust-curve parameters or non-finite input to a thrust-curve function."""


def _coeffs(values: Sequence[float], name: str) -> np.ndarray:
    try:
        arr = np.asarray(values, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ThrustCurveError(f"{name}: expected 4 numbers (c4, c3, c2, c1), got {values!r}") from exc
    if arr.shape != (4,) or not np.all(np.isfinite(arr)):
        raise ThrustCurveError(f"{name}: expected 4 finite numbers (c4, c3, c2, c1), got {values!r}")
    return arr


def point_reflection(coeffs: Sequence[float], neutral_us: float = 1500.0) -> tuple[float, float, float, float]:
    """Coefficients of the cubic point-reflected about (``neutral_us``, 0 N).

    Returns ``g`` with ``g(P) = -f(2 * neutral_us - P)`` for the cubic ``f`` given by ``coeffs``
    ``(c4, c3, c2, c1)`` (N as a function of P in us), in the same order. With the [Hindrax-Drag] Table 2
    negative row this is the project's default positive-rotation curve (docs/architecture.md §4): it gives
    +15.53 N at 1900 us. Applying it twice returns the original coefficients.

    Raises :class:`ThrustCurveError` for anything but 4 finite numbers or a non-finite ``neutral_us``."""
    f = np.poly1d(_coeffs(coeffs, "coeffs"))
    if not math.isfinite(neutral_us):
        raise ThrustCurveError(f"neutral_us must be finite, got {neutral_us!r}")
    g = -f(np.poly1d([-1.0, 2.0 * float(neutral_us)]))  # composition f(2n - P), negated
    c = np.zeros(4)
    c[4 - len(g.coeffs):] = g.coeffs
    return (float(c[0]), float(c[1]), float(c[2]), float(c[3]))


def voltage_thrust_scale(battery_voltage_v: float, nominal_voltage_v: float = HINDRAX_NOMINAL_VOLTAGE_V,
                         exponent: float = 1.2) -> float:
    """Thrust factor ``(battery_voltage_v / nominal_voltage_v) ** exponent`` for ``voltage_scale``.

    Source: docs/devices.md §5.3 (Blue Robotics T200 data, DERIVED there): full-throttle thrust scales roughly with
    V^1.2 (10 V -> 20 V gives x2.29, 12 V -> 16 V gives x1.41). The nominal voltage is the Hindrax battery, 14.8 V
    ([Hindrax-Drag] section 2.1), at which the curves are taken to be valid. Raises :class:`ThrustCurveError` unless
    both voltages are finite and positive and the exponent is finite."""
    for name, value in (("battery_voltage_v", battery_voltage_v), ("nominal_voltage_v", nominal_voltage_v)):
        if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0.0):
            raise ThrustCurveError(f"{name} must be a finite positive number, got {value!r}")
    if not math.isfinite(exponent):
        raise ThrustCurveError(f"exponent must be finite, got {exponent!r}")
    return float((battery_voltage_v / nominal_voltage_v) ** exponent)


def check_positive(value: float, name: str, allow_zero: bool = False) -> float:
    """``value`` as a float. Raises :class:`ThrustCurveError` (a ValueError) naming it when it is
    not a finite number > 0 (>= 0 with ``allow_zero``)."""
    kind = "a finite number >= 0" if allow_zero else "a finite positive number"
    try:
        out = float(value)
    except (TypeError, ValueError) as exc:
        raise ThrustCurveError(f"{name} must be {kind}, got {value!r}") from exc
    if not (math.isfinite(out) and (out >= 0.0 if allow_zero else out > 0.0)):
        raise ThrustCurveError(f"{name} must be {kind}, got {value!r}")
    return out


def _finite_array(values, name: str) -> np.ndarray:
    try:
        arr = np.asarray(values, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ThrustCurveError(f"{name}: expected numbers, got {values!r}") from exc
    if not np.all(np.isfinite(arr)):
        raise ThrustCurveError(f"{name}: all values must be finite, got {values!r}")
    return arr


def _cubic(coeffs: np.ndarray, p):
    """[Hindrax-Drag] eq. 1 by Horner's rule: c4 P^3 + c3 P^2 + c2 P + c1 (N), coeffs ordered (c4, c3, c2, c1)."""
    return ((coeffs[0] * p + coeffs[1]) * p + coeffs[2]) * p + coeffs[3]


def forward_thrust(pulse_width_us, negative, positive, pulse_width_min_us, pulse_width_max_us, negative_edge_us,
                   positive_edge_us, max_reverse_n, max_forward_n):
    """Forward thrust model (N) of :meth:`ThrustCurve.thrust_n` at ``voltage_scale = 1``, vectorised.

    Every parameter broadcasts against ``pulse_width_us``: ``negative`` and ``positive`` are ``(c4, c3, c2, c1)`` of
    [Hindrax-Drag] eq. 1 with shape (4,) or (4, n) (one column per thruster), the others scalars or (n,). Pulse widths
    are clamped to ``[pulse_width_min_us, pulse_width_max_us]``; the negative cubic (clipped to <= 0) applies at
    ``P <= negative_edge_us``, the positive one (clipped to >= 0) at ``P >= positive_edge_us``, 0 N between (deadband,
    docs/devices.md §5.2); the result is clipped to ``[max_reverse_n, max_forward_n]``. Inputs are not validated: use
    :meth:`ThrustCurve.thrust_n` unless the values come from :attr:`ThrustCurve.forward_parameters`."""
    p = np.minimum(np.maximum(pulse_width_us, pulse_width_min_us), pulse_width_max_us)
    thrust = np.where(p <= negative_edge_us, np.minimum(_cubic(negative, p), 0.0),
                      np.where(p >= positive_edge_us, np.maximum(_cubic(positive, p), 0.0), 0.0))
    # never beyond the end values (also removes last-bit differences of vectorised evaluation)
    return np.minimum(np.maximum(thrust, max_reverse_n), max_forward_n)


def _out(arr: np.ndarray):
    return float(arr) if arr.ndim == 0 else arr


class ThrustCurve:
    """Two-branch cubic thrust curve of one thruster ([Hindrax-Drag] eq. 1), with its inverse.

    Parameters
    ----------
    negative, positive:
        ``(c4, c3, c2, c1)`` of eq. 1 for negative rotation (``pulse_width_min_us`` to neutral) and
        positive rotation (neutral to ``pulse_width_max_us``); thrust in N, pulse width in us.
    pulse_width_min_us, pulse_width_neutral_us, pulse_width_max_us:
        ESC range and stop value ([Hindrax-Drag] section 2.2.1; docs/devices.md §5.2): 1100, 1500, 1900 us.
    deadband_us:
        Half-width of the ESC deadband around neutral; thrust is 0 N for
        ``|P - neutral| < deadband_us`` and at neutral itself. Default 25 us (docs/devices.md §5.2).
    small_force:
        ``"nearest"`` (default) or ``"neutral"``: what the inverse does with a force smaller in magnitude
        than the branch's smallest producible force (see the module docstring).

    Each side must, at its range end, be monotone increasing with the right sign (negative at
    ``pulse_width_min_us``, positive at ``pulse_width_max_us``); the usable branch then runs from the
    end towards neutral up to the first extremum, zero crossing or deadband edge. Violations (for
    example [Hindrax-Drag]'s printed positive row) raise :class:`ThrustCurveError`.

    Attributes (all read-only, at ``voltage_scale = 1``): ``max_forward_n`` (> 0, thrust at
    ``pulse_width_max_us``), ``max_reverse_n`` (< 0, thrust at ``pulse_width_min_us``),
    ``smallest_forward_n`` (>= 0) and ``smallest_reverse_n`` (<= 0), the branch forces nearest zero,
    ``forward_branch_us`` and ``reverse_branch_us``, the ``(low, high)`` pulse widths of the branches."""

    def __init__(self, negative: Sequence[float], positive: Sequence[float], pulse_width_min_us: float = 1100.0,
                 pulse_width_neutral_us: float = 1500.0, pulse_width_max_us: float = 1900.0,
                 deadband_us: float = BASIC_ESC_DEADBAND_US, small_force: str = "nearest") -> None:
        self._neg = _coeffs(negative, "negative")
        self._pos = _coeffs(positive, "positive")
        limits = _finite_array([pulse_width_min_us, pulse_width_neutral_us, pulse_width_max_us, deadband_us],
                               "pulse widths / deadband")
        pmin, pneu, pmax, dead = (float(v) for v in limits)
        if dead < 0.0:
            raise ThrustCurveError(f"deadband_us must be >= 0, got {dead}")
        if not (pmin < pneu - dead and pneu + dead < pmax):
            raise ThrustCurveError(
                "need pulse_width_min_us < neutral - deadband_us and neutral + deadband_us < pulse_width_max_us, "
                f"got min={pmin}, neutral={pneu}, max={pmax}, deadband={dead}")
        if small_force not in _SMALL_FORCE_POLICIES:
            raise ThrustCurveError(f"small_force must be one of {_SMALL_FORCE_POLICIES}, got {small_force!r}")
        self._pmin, self._pneu, self._pmax, self._dead = pmin, pneu, pmax, dead
        self._small_force = small_force
        self._neg_branch = self._branch(self._neg, end=pmin, inner=pneu - dead, side="negative")
        self._pos_branch = self._branch(self._pos, end=pmax, inner=pneu + dead, side="positive")
        self._neg_table = self._table(self._neg, *self._neg_branch)
        self._pos_table = self._table(self._pos, *self._pos_branch)
        self._max_forward_n = float(_cubic(self._pos, pmax))
        self._max_reverse_n = float(_cubic(self._neg, pmin))
        # forward-model switch points: the cubic applies at and beyond the deadband edges, never at neutral
        self._neg_edge_us = pneu - dead if dead > 0.0 else float(np.nextafter(pneu, -np.inf))
        self._pos_edge_us = pneu + dead if dead > 0.0 else float(np.nextafter(pneu, np.inf))
        self._saturation_bound_n = 2.0 * max(self._max_forward_n, -self._max_reverse_n)

    # ----------------------------------------------------------------- construction helpers
    @staticmethod
    def _branch(coeffs: np.ndarray, end: float, inner: float, side: str) -> tuple[float, float]:
        """(low, high) pulse widths of the monotone branch that starts at ``end`` towards ``inner``."""
        f = np.poly1d(coeffs)
        df = f.deriv()
        f_end, slope_end = float(_cubic(coeffs, end)), float(df(end))
        want_sign = -1.0 if side == "negative" else 1.0
        if not f_end * want_sign > 0.0:
            raise ThrustCurveError(
                f"{side} curve gives {f_end:.6g} N at its range end {end:g} us; expected a "
                f"{'negative' if side == 'negative' else 'positive'} thrust")
        if not slope_end > 0.0:
            raise ThrustCurveError(
                f"{side} curve is not increasing at its range end {end:g} us (slope {slope_end:.3g} N/us), "
                "so its end is not its largest thrust magnitude")
        lo, hi = sorted((end, inner))
        candidates = [inner]
        for poly in (df, f):  # first extremum or zero crossing between end and inner
            for root in np.roots(poly.coeffs) if poly.order > 0 else []:
                if abs(root.imag) < 1e-9 and lo < root.real < hi:
                    candidates.append(float(root.real))
        stop = min(candidates, key=lambda p: abs(p - end))
        if abs(stop - end) < 10.0 * _TABLE_STEP_US:
            raise ThrustCurveError(f"{side} curve has no usable monotone branch next to {end:g} us")
        return (end, stop) if side == "negative" else (stop, end)

    @staticmethod
    def _table(coeffs: np.ndarray, low_us: float, high_us: float) -> tuple[np.ndarray, np.ndarray]:
        n = int(math.ceil((high_us - low_us) / _TABLE_STEP_US)) + 1
        p = np.linspace(low_us, high_us, n)
        thrust = _cubic(coeffs, p)
        if not np.all(np.diff(thrust) > 0.0):
            raise ThrustCurveError("thrust curve branch is not strictly increasing to table precision")
        return thrust, p

    # ----------------------------------------------------------------- properties
    @property
    def negative_coeffs(self) -> tuple[float, ...]:
        """``(c4, c3, c2, c1)`` of the negative-rotation cubic (N, us)."""
        return tuple(float(c) for c in self._neg)

    @property
    def positive_coeffs(self) -> tuple[float, ...]:
        """``(c4, c3, c2, c1)`` of the positive-rotation cubic (N, us)."""
        return tuple(float(c) for c in self._pos)

    @property
    def pulse_width_min_us(self) -> float:
        """Full reverse pulse width (us)."""
        return self._pmin

    @property
    def pulse_width_neutral_us(self) -> float:
        """Stop pulse width (us)."""
        return self._pneu

    @property
    def pulse_width_max_us(self) -> float:
        """Full forward pulse width (us)."""
        return self._pmax

    @property
    def deadband_us(self) -> float:
        """Deadband half-width around neutral (us)."""
        return self._dead

    @property
    def reverse_branch_us(self) -> tuple[float, float]:
        """``(pulse_width_min_us, inner end)`` of the monotone negative branch (us)."""
        return self._neg_branch

    @property
    def forward_branch_us(self) -> tuple[float, float]:
        """``(inner end, pulse_width_max_us)`` of the monotone positive branch (us)."""
        return self._pos_branch

    @property
    def max_forward_n(self) -> float:
        """Largest forward thrust (N, > 0): the positive cubic at ``pulse_width_max_us``."""
        return self._max_forward_n

    @property
    def max_reverse_n(self) -> float:
        """Largest reverse thrust (N, < 0): the negative cubic at ``pulse_width_min_us``."""
        return self._max_reverse_n

    @property
    def smallest_forward_n(self) -> float:
        """Smallest producible forward thrust (N, >= 0), at the inner end of the forward branch."""
        return max(float(self._pos_table[0][0]), 0.0)

    @property
    def smallest_reverse_n(self) -> float:
        """Smallest-magnitude producible reverse thrust (N, <= 0), at the inner end of the reverse branch."""
        return min(float(self._neg_table[0][-1]), 0.0)

    @property
    def forward_parameters(self) -> tuple:
        """Arguments of :func:`forward_thrust` after the pulse widths, for this curve:
        ``(negative (4,), positive (4,), pulse_width_min_us, pulse_width_max_us, negative_edge_us,
        positive_edge_us, max_reverse_n, max_forward_n)``."""
        return (self._neg, self._pos, self._pmin, self._pmax, self._neg_edge_us, self._pos_edge_us,
                self._max_reverse_n, self._max_forward_n)

    def force_limits_n(self, voltage_scale: float = 1.0) -> tuple[float, float]:
        """``(max_reverse_n, max_forward_n)`` multiplied by ``voltage_scale`` (N).

        Raises :class:`ThrustCurveError` for a non-finite or non-positive ``voltage_scale``."""
        s = check_positive(voltage_scale, "voltage_scale")
        return (s * self.max_reverse_n, s * self.max_forward_n)

    # ----------------------------------------------------------------- forward model
    def thrust_n(self, pulse_width_us, voltage_scale: float = 1.0):
        """Thrust (N) at pulse width(s) ``pulse_width_us`` (us); scalar in, float out; array in, array out.

        Pulse widths are first clamped to ``[pulse_width_min_us, pulse_width_max_us]`` (the ESC output is
        clamped there, docs/architecture.md §8). Result: 0 N at neutral and for ``|P - neutral| <
        deadband_us``; otherwise the negative cubic (below neutral) or positive cubic (above), clipped to
        the side's sign (a thruster in reverse rotation does not push forward) and to
        ``[max_reverse_n, max_forward_n]``, times ``voltage_scale``.
        Source: [Hindrax-Drag] eq. 1, docs/devices.md §5.2. Raises :class:`ThrustCurveError` for non-finite
        input or a bad ``voltage_scale``."""
        s = check_positive(voltage_scale, "voltage_scale")
        p = _finite_array(pulse_width_us, "pulse_width_us")
        return _out(s * forward_thrust(p, *self.forward_parameters))

    # ----------------------------------------------------------------- inverse
    def pulse_width_us(self, force_n, voltage_scale: float = 1.0):
        """Pulse width(s) (us) that produce thrust ``force_n`` (N); scalar in, float out; array in, array out.

        The requested force is divided by ``voltage_scale``, then inverted on the monotone branch of its sign (exact to
        0.005 us). 0 N gives neutral. Forces beyond ``max_forward_n`` / ``max_reverse_n`` saturate at
        ``pulse_width_max_us`` / ``pulse_width_min_us``. Forces smaller in magnitude than the branch's smallest thrust
        go to neutral or to the branch's inner end according to ``small_force`` (module docstring). Source: inverse of
        [Hindrax-Drag] eq. 1. Raises :class:`ThrustCurveError` for non-finite input or a bad ``voltage_scale``."""
        s = check_positive(voltage_scale, "voltage_scale")
        return _out(self._pulse_width_unchecked(_finite_array(force_n, "force_n"), s))

    def _pulse_width_unchecked(self, force: np.ndarray, s: float) -> np.ndarray:
        """:meth:`pulse_width_us` without input validation (finite array, valid scale), for the allocator."""
        # Clip first (beyond 2x the limits everything saturates anyway) so that the division cannot overflow.
        bound = s * self._saturation_bound_n
        t = np.minimum(np.maximum(force, -bound), bound) / s
        negative = t < 0.0
        # both branches for every element (n is small), each saturating at its table ends
        p = np.where(negative, np.interp(t, *self._neg_table),
                     np.where(t > 0.0, np.interp(t, *self._pos_table), self._pneu))
        inner_n = np.where(negative, -self._neg_table[0][-1], self._pos_table[0][0])  # |smallest force|
        inner_p = np.where(negative, self._neg_table[1][-1], self._pos_table[1][0])
        magnitude = np.abs(t)
        small = magnitude < inner_n
        if self._small_force == "nearest":
            replacement = np.where(magnitude >= 0.5 * inner_n, inner_p, self._pneu)
        else:
            replacement = np.asarray(self._pneu)
        return np.where(small, replacement, p)

    def _key(self) -> tuple:
        return (self.negative_coeffs, self.positive_coeffs, self._pmin, self._pneu, self._pmax, self._dead,
                self._small_force)

    def __eq__(self, other) -> bool:
        """Curves are equal when all their constructor parameters are equal."""
        return isinstance(other, ThrustCurve) and self._key() == other._key()

    def __hash__(self) -> int:
        return hash(self._key())

    def __repr__(self) -> str:
        return (f"ThrustCurve(negative={self.negative_coeffs}, positive={self.positive_coeffs}, "
                f"pulse_width_min_us={self._pmin}, pulse_width_neutral_us={self._pneu}, "
                f"pulse_width_max_us={self._pmax}, deadband_us={self._dead}, small_force={self._small_force!r})")


def hindrax_default_curve(deadband_us: float = BASIC_ESC_DEADBAND_US, small_force: str = "nearest") -> ThrustCurve:
    """The project's default thruster curve: [Hindrax-Drag] Table 2 negative row, and its point reflection
    about (1500 us, 0 N) as positive row (docs/architecture.md §4), ESC range 1100/1500/1900 us.

    Raises :class:`ThrustCurveError` for a bad ``deadband_us`` or ``small_force``."""
    return ThrustCurve(HINDRAX_DRAG_NEGATIVE_COEFFS, point_reflection(HINDRAX_DRAG_NEGATIVE_COEFFS, 1500.0),
                       deadband_us=deadband_us, small_force=small_force)
