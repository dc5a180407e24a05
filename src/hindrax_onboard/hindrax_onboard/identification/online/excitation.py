"""Broadband force inputs for one DOF (multisine, PRBS, chirp) and the pool-box shaping that keeps them inside.

Pure numpy / scipy, no ROS. The campaign executive (:mod:`.executive`, ``identification.excitation``) can replace
the ladder of constant levels of a DOF by one run of one of these signals; the DOF is then identified from the
recorded force and motion by the output-error fit (:mod:`hindrax_fit.fit.fit_core`, through
:func:`~hindrax_fit.fit.campaign_fit.identify_dof`), which works on any force history. Signals are forces (N) for surge,
sway, heave and moments (N m) for roll, pitch, yaw, body FRD, on the axis of the DOF under test; time ``t`` (s) from
the start of the run.

* :class:`Multisine` - a sum of cosines on the lines k / P (P the period) from ``f_min`` to ``f_max`` with equal
  amplitudes and Schroeder's phases phi_k = -pi k (k - 1) / N (Schroeder 1970, "Synthesis of low-peak-factor
  signals and binary sequences with low autocorrelation", IEEE Trans. Inf. Theory 16(1) 85-89, eq. 11; Pintelon
  and Schoukens 2012, *System Identification: A Frequency Domain Approach*, 2nd ed., §5.2.4), scaled so that
  its peak over one period is the amplitude. Periodic, so a run of whole periods has power on the designed
  lines only (no leakage) and a bounded displacement.
* :class:`Prbs` - a maximum-length binary sequence (m-sequence, ``scipy.signal.max_len_seq``) of ``nbits`` bits held for
  a clock period ``clock_s`` each: +-A, period (2^nbits - 1) clock_s, spectrum flat to about 0.44 / clock_s (Godfrey
  1993, *Perturbation Signals for System Identification*, ch. 1; Pintelon and Schoukens 2012 §5.2.6).
* :class:`Chirp` - a logarithmic swept sine from ``f_min`` to ``f_max`` over the run (``scipy.signal.chirp``).
* :func:`design_band` - the band from the DOF's time constant: with the vehicle file's inertia M, linear and
  quadratic damping k_l, k_q, the speed reached under the amplitude A is v_A (k_q v^2 + k_l v = A) and the
  linearised time constant there tau = M / (k_l + 2 k_q v_A). The band is f_c / 8 .. 3 f_c with f_c =
  1 / (2 pi tau) (the lowest lines nearly steady: damping; the highest well into the inertia-dominated range),
  capped at 1 / (2 pi tau_thr) of the thruster lag, above which the thrust no longer follows the command.
* :class:`BoxShaping` - "stay in the pool box" (module section below).

Pool-box shaping (:meth:`BoxShaping.force`), with e the displacement from the box centre along the DOF's axis
(m, or rad for a rotation), v its rate and L the room from the centre to the box boundary along that axis:

1. a slow PD on the displacement, f_pd = -M w_b^2 e - 2 zeta M w_b v with w_b = 2 pi f_min / 2 (half the lowest
   designed line, so it removes drift without cancelling the band), zeta = 0.7;
2. the excitation is scaled down near a wall when it pushes outwards: g = clip((L - |e|) / (0.3 L), 0, 1) when
   u e > 0, else 1 (a linear taper over the outer 30 % of the room), and a wall spring pushes back in that outer
   band, -sign(e) ``brake_fraction`` x authority x ((|e| - 0.7 L) / (0.3 L))^2, which reaches the braking force at
   the boundary, so an unmodelled steady push (tether, current, buoyancy error) smaller than that is held inside;
3. a braking guard: when moving outwards and the stopping distance at the braking authority, v^2 / (2 a_b)
   with a_b = ``brake_fraction`` x authority / M (the drag, which helps, is left out), plus one tick of travel
   reaches the room left, the whole command is a full brake -sign(v) ``brake_fraction`` x authority.

The total is clipped to the authority. Because the fit uses the recorded force, the shaping does not bias the
identification; it only removes some low-frequency power."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

__all__ = ["EXCITATIONS", "BROADBAND", "DEFAULT_AMPLITUDE_FRACTION", "Multisine", "Prbs", "Chirp", "Band",
           "design_band", "steady_speed", "BoxShaping", "design_signal"]

#: Values of ``identification.excitation``: the constant-thrust ladder (default) or one broadband run per DOF.
EXCITATIONS = ("ladder", "multisine", "prbs", "chirp")
#: The broadband ones (everything except the ladder).
BROADBAND = EXCITATIONS[1:]
#: Peak of the excitation as a fraction of the DOF's smaller authority (the box shaping and the holds of the other
#: DOFs use the rest; the ladder's largest level is ``identification.level_fraction_max`` = 0.85).
DEFAULT_AMPLITUDE_FRACTION = 0.6


@dataclass(frozen=True)
class Multisine:
    """Schroeder-phased multisine (module docstring): ``amplitude`` (N or N m, the peak), ``period_s`` (s),
    ``harmonics`` (N,) the integer line numbers k (frequencies k / period_s, Hz). Raises ``ValueError`` for an
    empty line set, a non-positive period or amplitude."""

    amplitude: float
    period_s: float
    harmonics: tuple
    _scale: float = field(init=False, repr=False, default=1.0)

    def __post_init__(self) -> None:
        if not (self.period_s > 0 and self.amplitude > 0):
            raise ValueError(f"multisine: period_s {self.period_s} and amplitude {self.amplitude} must be > 0")
        if len(self.harmonics) == 0 or min(self.harmonics) < 1:
            raise ValueError(f"multisine: harmonics must be integers >= 1, got {list(self.harmonics)}")
        t = np.linspace(0.0, self.period_s, 64 * max(self.harmonics) + 1)
        peak = float(np.max(np.abs(self._raw(t))))
        object.__setattr__(self, "_scale", self.amplitude / peak)

    @classmethod
    def design(cls, amplitude: float, f_min_hz: float, f_max_hz: float, period_s: float | None = None) -> "Multisine":
        """Lines k / P for k from ceil(f_min P) (>= 1) to floor(f_max P); the period P defaults to 1 / f_min (the
        lowest line is then f_min). Raises ``ValueError`` when no line falls in the band."""
        p = 1.0 / f_min_hz if period_s is None else float(period_s)
        k0 = max(1, math.ceil(f_min_hz * p - 1e-9))
        k1 = math.floor(f_max_hz * p + 1e-9)
        if k1 < k0:
            raise ValueError(f"multisine: no line k / {p:g} s between {f_min_hz:g} and {f_max_hz:g} Hz")
        return cls(float(amplitude), p, tuple(range(k0, k1 + 1)))

    def _raw(self, t) -> np.ndarray:
        """Unscaled sum of the lines: frequencies k / period_s, Schroeder phases
        -pi k (k - 1) / N over the lines in order (Schroeder 1970 eq. 11)."""
        n = len(self.harmonics)
        k = np.arange(1, n + 1, dtype=float)
        freqs = np.asarray(self.harmonics, dtype=float) / self.period_s
        phases = -math.pi * k * (k - 1.0) / n
        arg = 2.0 * math.pi * np.multiply.outer(np.asarray(t, dtype=float), freqs) + phases
        return np.cos(arg).sum(axis=-1)

    def value(self, t):
        """Force (N or N m) at ``t`` (s, scalar or array)."""
        return self._scale * self._raw(t)


@dataclass(frozen=True)
class Prbs:
    """Maximum-length PRBS (module docstring): +-``amplitude`` (N or N m), ``nbits`` (shift-register length,
    period 2^nbits - 1 clocks), ``clock_s`` (s per bit). Raises ``ValueError`` for nbits outside 2..20 or a
    non-positive clock or amplitude."""

    amplitude: float
    nbits: int
    clock_s: float
    _bits: np.ndarray = field(init=False, repr=False, default=None)

    def __post_init__(self) -> None:
        from scipy import signal  # here, not at the top: node processes import this module (pyproject.toml, PLC0415)

        if not (2 <= int(self.nbits) <= 20):
            raise ValueError(f"prbs: nbits must be in 2..20, got {self.nbits}")
        if not (self.clock_s > 0 and self.amplitude > 0):
            raise ValueError(f"prbs: clock_s {self.clock_s} and amplitude {self.amplitude} must be > 0")
        seq, _ = signal.max_len_seq(int(self.nbits))
        object.__setattr__(self, "_bits", np.asarray(seq, dtype=float))

    @classmethod
    def design(cls, amplitude: float, clock_s: float, duration_s: float, max_bits: int = 10) -> "Prbs":
        """The longest m-sequence (3..``max_bits`` bits) whose period fits in ``duration_s`` (at least 3 bits)."""
        n = 3
        while n < max_bits and (2 ** (n + 1) - 1) * clock_s <= duration_s:
            n += 1
        return cls(float(amplitude), n, float(clock_s))

    @property
    def period_s(self) -> float:
        """(2^nbits - 1) clock_s, s."""
        return (2 ** int(self.nbits) - 1) * self.clock_s

    def value(self, t):
        """Force (N or N m) at ``t`` (s, scalar or array): +-amplitude, the bit of clock floor(t / clock_s)."""
        i = np.floor(np.asarray(t, dtype=float) / self.clock_s + 1e-9).astype(int) % self._bits.size
        return self.amplitude * (2.0 * self._bits[i] - 1.0)


@dataclass(frozen=True)
class Chirp:
    """Logarithmic swept sine (``scipy.signal.chirp``, method "logarithmic") of ``amplitude`` (N or N m) from
    ``f_min_hz`` at t = 0 to ``f_max_hz`` at ``duration_s``, then held at f_max."""

    amplitude: float
    f_min_hz: float
    f_max_hz: float
    duration_s: float

    def value(self, t):
        """Force (N or N m) at ``t`` (s, scalar or array)."""
        from scipy import signal  # here, not at the top: node processes import this module (pyproject.toml, PLC0415)

        t = np.minimum(np.asarray(t, dtype=float), self.duration_s)
        return self.amplitude * signal.chirp(t, self.f_min_hz, self.duration_s, self.f_max_hz,
                                             method="logarithmic", phi=-90.0)


def steady_speed(amplitude: float, linear_damping: float, quadratic_damping: float) -> float:
    """The speed v >= 0 (m/s or rad/s) where k_q v^2 + k_l v = A (the steady state of the one-DOF model under a
    constant force A > 0). Raises ``ValueError`` when both damping coefficients are <= 0."""
    a, kl, kq = float(amplitude), float(linear_damping), float(quadratic_damping)
    if kq > 0:
        return (-kl + math.sqrt(kl * kl + 4.0 * kq * a)) / (2.0 * kq)
    if kl > 0:
        return a / kl
    raise ValueError(f"steady speed: no damping (k_l {kl}, k_q {kq})")


@dataclass(frozen=True)
class Band:
    """Designed band: ``f_min_hz``, ``f_max_hz`` (Hz); ``time_constant_s`` tau (s) and ``speed`` v_A (m/s or
    rad/s) it came from (:func:`design_band`)."""

    f_min_hz: float
    f_max_hz: float
    time_constant_s: float
    speed: float


def design_band(inertia: float, linear_damping: float, quadratic_damping: float, amplitude: float,
                thruster_time_constant_s: float = 0.0) -> Band:
    """Band from the DOF's time constant (module docstring): inertia M (kg or kg m^2), damping k_l (kg/s),
    k_q (kg/m) and the excitation amplitude A (N or N m) of the vehicle file; the thruster lag (s) caps f_max.
    Raises ``ValueError`` for a non-positive inertia or amplitude."""
    if not (inertia > 0 and amplitude > 0):
        raise ValueError(f"design_band: inertia {inertia} and amplitude {amplitude} must be > 0")
    v = steady_speed(amplitude, linear_damping, quadratic_damping)
    tau = inertia / (max(linear_damping, 0.0) + 2.0 * max(quadratic_damping, 0.0) * v)
    fc = 1.0 / (2.0 * math.pi * tau)
    f_max = 3.0 * fc
    if thruster_time_constant_s > 0:
        f_max = min(f_max, 1.0 / (2.0 * math.pi * thruster_time_constant_s))
    return Band(fc / 8.0, max(f_max, fc / 4.0), tau, v)


def design_signal(kind: str, amplitude: float, band: Band, duration_s: float):
    """The signal of ``kind`` (:data:`BROADBAND`) for one run of ``duration_s`` (s): a :class:`Multisine` of
    period 1 / f_min (lines f_min .. f_max), a :class:`Prbs` clocked at the time constant (the longest m-sequence
    fitting the run), or a :class:`Chirp` over the band. Raises ``ValueError`` for another kind."""
    if kind == "multisine":
        return Multisine.design(amplitude, band.f_min_hz, band.f_max_hz)
    if kind == "prbs":
        return Prbs.design(amplitude, band.time_constant_s, duration_s)
    if kind == "chirp":
        return Chirp(float(amplitude), band.f_min_hz, band.f_max_hz, float(duration_s))
    raise ValueError(f"excitation {kind!r}: choose from {', '.join(BROADBAND)}")


@dataclass(frozen=True)
class BoxShaping:
    """Keeps a run inside the pool box along one axis (module docstring, "Pool-box shaping").

    half_range: room L from the centre to the boundary (m or rad, > 0). inertia: M (kg or kg m^2, > 0, the
    vehicle file's). authority: largest force of the axis (N or N m, > 0). bandwidth_rad_s: w_b of the PD.
    tick_s: control period (s), the travel of one tick is added to the stopping distance. zeta, taper_fraction,
    brake_fraction: as documented."""

    half_range: float
    inertia: float
    authority: float
    bandwidth_rad_s: float
    tick_s: float = 0.02
    zeta: float = 0.7
    taper_fraction: float = 0.3
    brake_fraction: float = 0.8

    def force(self, u: float, e: float, v: float) -> float:
        """Total force (N or N m) for the excitation ``u``, displacement ``e`` from the centre and its rate ``v``."""
        m, wb, lim = self.inertia, self.bandwidth_rad_s, self.authority
        room = self.half_range - abs(e)
        if v * e >= 0.0 and v != 0.0:  # moving outwards (or from the centre)
            a_b = self.brake_fraction * lim / m
            if v * v / (2.0 * a_b) + abs(v) * self.tick_s >= room:
                return -math.copysign(self.brake_fraction * lim, v)
        band = self.taper_fraction * self.half_range
        g = 1.0
        if u * e > 0.0:
            g = min(1.0, max(0.0, room / band))
        depth = min(1.0, max(0.0, 1.0 - room / band))  # 0 inside the taper's start, 1 at the boundary
        f_wall = -math.copysign(self.brake_fraction * lim * depth * depth, e)
        f = g * u + f_wall - m * wb * wb * e - 2.0 * self.zeta * m * wb * v
        return float(min(lim, max(-lim, f)))
