"""Added mass from free-decay (spring-supported free vibration) tests: [Hindrax-AM] eqs. 1-12.

[Hindrax-AM] supports a 1:3 model of Hindrax on springs (equivalent stiffness k_eq), releases it
from an initial displacement A and records its acceleration at 330 Hz for 10 s. The model is
the 1-DOF damped oscillator m x'' + c x' + k_eq x = 0 with m = m_b + m_ad (eq. 1). From the
displacement (double integral of the acceleration) it measures the damped frequency omega_d and
the log decrement delta; the closed-form relations below (eqs. 2-11, each function names its
equation; docs/identification.md §2.2) give the added mass, damping, C_M, KC and Re.

Signal processing (our choices; [Hindrax-AM] only says "double integration" in MATLAB):

* Release: the first sample whose |a - median(a)| exceeds :data:`RELEASE_THRESHOLD` (0.5) times the largest deviation
  (at release the acceleration jumps to its largest value, -omega_n^2 A). The record is analysed from there on.
* Displacement (:func:`displacement_from_acceleration`): the accelerometer bias is the
  (trapezoid-weighted) mean of the acceleration over the analysed record (exact when it starts
  and ends at rest, because the velocity change is then zero); velocity = cumulative
  trapezoid (v = 0 at release, from rest); displacement = cumulative trapezoid of the
  velocity minus its mean (equilibrium reference). Optionally a zero-phase Butterworth
  high-pass (order 2, ``highpass_hz``) is applied to the velocity (odd padding: v is odd about
  the release) and to the displacement (even padding) to suppress the random-walk drift of
  integrated noise; :func:`analyse_free_decay` uses :data:`HIGHPASS_FRACTION` (0.1) times the
  damped frequency. The high-pass removes the genuine
  low-frequency content of a decaying oscillation too (its integral is c A / k_eq), so it biases
  the displacement by about 2 sigma omega_c A / omega_n^2 near the release; this is why the peak
  amplitudes below are measured peak-to-trough.
* Peaks: extrema of the displacement found with ``scipy.signal.find_peaks`` (release sample
  included as the first peak; its sign is opposite to the acceleration at release; minimum
  spacing 0.6 of the half period estimated from the acceleration spectrum); each
  amplitude is measured as the peak-to-following-trough height H_k, which is insensitive to any
  slowly varying offset. For a linear oscillator H_k / H_{k+n} = x_k / x_{k+n} = exp(n delta)
  exactly, so delta = (1/n) ln(H_0 / H_n) is eq. 3 averaged over n periods, and the peak
  amplitudes are x_k = H_k / (1 + exp(-delta / 2)). Peaks are used while H_k exceeds both
  :data:`MIN_PEAK_FRACTION` (0.05) H_0 and 6 times the std of the linearly detrended displacement
  over the last 20 % of the record (noise floor).
* omega_d from the spacing of the interior extrema (peaks and troughs, release excluded, times
  refined by parabolic interpolation): least-squares slope of t_k against k is T_d / 2.
* Cross-check: a damped sinusoid plus bias, a = exp(-s t) (C1 cos w t + C2 sin w t) + b, is fitted
  to the acceleration by ``scipy.optimize.curve_fit`` (``omega_d_fit_rad_s``, ``zeta_fit``)."""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field, fields
from typing import Any, Optional, Tuple

import numpy as np

from .drag_coefficient import characteristic_length_from_volume, reynolds_number
from .least_squares import EstimationError, as_float_array, check_same_length, check_time_vector, positive

__all__ = ["FreeDecayResult", "analyse_free_decay", "displacement_from_acceleration", "find_release_index",
           "log_decrement", "damping_ratio_from_log_decrement", "natural_frequency", "added_mass_exact",
           "added_mass_simplified", "added_mass_error_percent", "damping_coefficient", "inertia_coefficient",
           "keulegan_carpenter", "DECAY_OUTPUTS", "QuadraticDecayFit", "fit_quadratic_free_decay",
           "quadratic_free_decay_keys", "IncliningResult", "restoring_from_inclining"]

#: the release: |a - median(a)| above this fraction of its largest value (module docstring)
RELEASE_THRESHOLD = 0.5
#: the displacement's high-pass cut-off as a fraction of the damped frequency (module docstring)
HIGHPASS_FRACTION = 0.1
#: peaks smaller than this fraction of the first are not used (module docstring)
MIN_PEAK_FRACTION = 0.05


# Closed-form relations ([Hindrax-AM] eqs. 2-12)
def _zeta(z: float) -> float:
    z = float(z)
    if not (np.isfinite(z) and 0.0 <= z < 1.0):
        raise EstimationError(f"zeta must be in [0, 1) (under-damped), got {z}")
    return z


def log_decrement(peak_amplitudes) -> float:
    """delta = (1/n) ln(x_0 / x_n) over n periods ([Hindrax-AM] eq. 3, averaged over n peaks).

    Args:
        peak_amplitudes: (n + 1,) successive same-sign peak amplitudes (> 0), one period apart.

    Raises:
        EstimationError: fewer than 2 peaks or non-positive amplitudes."""
    x = as_float_array(peak_amplitudes, "peak_amplitudes", 1)
    if x.size < 2:
        raise EstimationError("need at least 2 peaks for a log decrement")
    if np.any(x <= 0):
        raise EstimationError("peak amplitudes must be > 0")
    return float(np.log(x[0] / x[-1]) / (x.size - 1))


def damping_ratio_from_log_decrement(delta: float) -> float:
    """zeta = delta / sqrt(4 pi^2 + delta^2) ([Hindrax-AM] eq. 3 inverted)."""
    delta = float(delta)
    if not (np.isfinite(delta) and delta >= 0):
        raise EstimationError(f"log decrement must be >= 0, got {delta}")
    return delta / np.sqrt(4.0 * np.pi**2 + delta**2)


def natural_frequency(omega_d_rad_s: float, zeta: float) -> float:
    """omega_n = omega_d / sqrt(1 - zeta^2) in rad/s ([Hindrax-AM] eq. 2)."""
    return positive(omega_d_rad_s, "omega_d_rad_s") / np.sqrt(1.0 - _zeta(zeta) ** 2)


def added_mass_exact(stiffness_n_per_m: float, omega_d_rad_s: float, zeta: float, mass_kg: float) -> float:
    """m_ad = k_eq (1 - zeta^2) / omega_d^2 - m_b in kg ([Hindrax-AM] eq. 5, based on omega_d)."""
    k = positive(stiffness_n_per_m, "stiffness_n_per_m")
    wd = positive(omega_d_rad_s, "omega_d_rad_s")
    return k * (1.0 - _zeta(zeta) ** 2) / wd**2 - positive(mass_kg, "mass_kg")


def added_mass_simplified(stiffness_n_per_m: float, omega_rad_s: float, mass_kg: float) -> float:
    """m_ad = k_eq / omega^2 - m_b in kg ([Hindrax-AM] eq. 7, damping omitted).

    ``omega_rad_s`` is the measured oscillation frequency taken as omega_n (damping neglected);
    [Hindrax-AM] Tables 3-5 (sixth column) evaluate it with the measured omega_d."""
    k = positive(stiffness_n_per_m, "stiffness_n_per_m")
    w = positive(omega_rad_s, "omega_rad_s")
    return k / w**2 - positive(mass_kg, "mass_kg")


def added_mass_error_percent(added_mass_simplified_kg: float, added_mass_exact_kg: float) -> float:
    """(m_ad,eq7 - m_ad,eq5) / m_ad,eq5 * 100 ([Hindrax-AM] eq. 11)."""
    exact = float(added_mass_exact_kg)
    if exact == 0.0 or not np.isfinite(exact):
        raise EstimationError("exact added mass must be finite and non-zero")
    return (float(added_mass_simplified_kg) - exact) / exact * 100.0


def damping_coefficient(zeta: float, stiffness_n_per_m: float, total_mass_kg: float) -> float:
    """c = 2 zeta sqrt(k_eq m) in N s/m ([Hindrax-AM] prints N.m.s), m = m_b + m_ad (eq. 6)."""
    return 2.0 * _zeta(zeta) * np.sqrt(positive(stiffness_n_per_m, "stiffness_n_per_m")
                                       * positive(total_mass_kg, "total_mass_kg"))


def inertia_coefficient(added_mass_kg: float, volume_m3: float, fluid_density_kg_m3: float = 1000.0) -> float:
    """C_M = m_ad / (rho V), dimensionless ([Hindrax-AM] eq. 8)."""
    return float(added_mass_kg) / (positive(fluid_density_kg_m3, "fluid_density_kg_m3")
                                   * positive(volume_m3, "volume_m3"))


def keulegan_carpenter(amplitude_m: float, characteristic_length_m: float) -> float:
    """KC = 2 pi A / D ([Hindrax-AM] eq. 9; D = V^(1/3) for the ROV model)."""
    return 2.0 * np.pi * abs(float(amplitude_m)) / positive(characteristic_length_m, "characteristic_length_m")


# Signal processing
def _sample_rate(t: np.ndarray) -> float:
    return 1.0 / float(np.median(np.diff(t)))


def _highpass(x: np.ndarray, fs_hz: float, cutoff_hz: float, padtype: str) -> np.ndarray:
    from scipy import signal  # here, not at the top: node processes import this module (pyproject.toml, PLC0415)

    sos = signal.butter(2, cutoff_hz, btype="highpass", fs=fs_hz, output="sos")
    padlen = int(min(x.size - 1, np.ceil(3.0 * fs_hz / cutoff_hz)))
    return signal.sosfiltfilt(sos, x, padtype=padtype, padlen=padlen)


def displacement_from_acceleration(t_s, acceleration_m_s2, highpass_hz: Optional[float] = None,
                                   remove_bias: bool = True) -> Tuple[np.ndarray, np.ndarray]:
    """Displacement and velocity by double integration with drift removal (module docstring).

    Args:
        t_s: (n,) strictly increasing times in s (should start at the release, from rest).
        acceleration_m_s2: (n,) measured acceleration along the oscillation axis in m/s^2.
        highpass_hz: high-pass cut-off in Hz (None: no filter). Must be below fs/2. The
            filter assumes roughly uniform sampling (it uses the median sample rate).
        remove_bias: subtract the mean acceleration first.

    Returns:
        (displacement_m, velocity_m_s), each (n,).

    Raises:
        EstimationError: bad shapes, NaN, non-increasing time, fewer than 8 samples, bad cut-off."""
    from scipy import integrate  # here, not at the top: node processes import this module (pyproject.toml, PLC0415)

    t = check_time_vector(t_s, "t_s", min_samples=8)
    a = as_float_array(acceleration_m_s2, "acceleration_m_s2", 1)
    check_same_length(t_s=t, acceleration_m_s2=a)
    fs = _sample_rate(t)
    if highpass_hz is not None and not (0.0 < float(highpass_hz) < 0.5 * fs):
        raise EstimationError(f"highpass_hz must be in (0, {0.5 * fs}), got {highpass_hz}")
    if remove_bias:
        # trapezoid-weighted mean, so that the integrated velocity change is exactly zero
        a = a - integrate.trapezoid(a, t) / (t[-1] - t[0])
    v = integrate.cumulative_trapezoid(a, t, initial=0.0)
    if highpass_hz is not None:
        v = _highpass(v, fs, float(highpass_hz), "odd")
    x = integrate.cumulative_trapezoid(v, t, initial=0.0)
    x = x - np.mean(x)
    if highpass_hz is not None:
        x = _highpass(x, fs, float(highpass_hz), "even")
    return x, v


def find_release_index(acceleration_m_s2, release_threshold: float = 0.5) -> int:
    """Index of the release: first |a - median(a)| > release_threshold * max |a - median(a)|.

    Raises:
        EstimationError: threshold outside (0, 1] or a constant signal."""
    a = as_float_array(acceleration_m_s2, "acceleration_m_s2", 1)
    if not (0.0 < release_threshold <= 1.0):
        raise EstimationError(f"release_threshold must be in (0, 1], got {release_threshold}")
    dev = np.abs(a - np.median(a))
    if dev.size == 0 or dev.max() == 0.0:
        raise EstimationError("acceleration is constant: no release found")
    return int(np.argmax(dev > release_threshold * dev.max()))


def _dominant_frequency_hz(t: np.ndarray, a: np.ndarray) -> float:
    fs = _sample_rate(t)
    x = a - np.mean(a)
    nfft = int(2 ** np.ceil(np.log2(8 * x.size)))
    spec = np.abs(np.fft.rfft(x * np.hanning(x.size), nfft))
    freqs = np.fft.rfftfreq(nfft, 1.0 / fs)
    spec[freqs < 2.0 / (t[-1] - t[0])] = 0.0   # ignore (near) DC
    return float(freqs[int(np.argmax(spec))])


def _parabolic_time(t: np.ndarray, y: np.ndarray, i: int) -> float:
    """Vertex time of the parabola through samples i-1, i, i+1 (falls back to t[i] at edges)."""
    if i <= 0 or i >= y.size - 1:
        return float(t[i])
    y0, y1, y2 = y[i - 1], y[i], y[i + 1]
    den = y0 - 2.0 * y1 + y2
    if den == 0.0:
        return float(t[i])
    off = 0.5 * (y0 - y2) / den
    off = float(np.clip(off, -1.0, 1.0))
    dt = 0.5 * (t[i + 1] - t[i - 1])
    return float(t[i] + off * dt)


def _alternating_extrema(sx: np.ndarray, distance: int):
    """Alternating (peak, trough, peak, ...) indices of sx starting with a peak at index 0."""
    from scipy import signal  # here, not at the top: node processes import this module (pyproject.toml, PLC0415)

    padded = np.concatenate([[-np.inf], sx])
    peaks = signal.find_peaks(padded, distance=distance)[0] - 1
    troughs = signal.find_peaks(-sx, distance=distance)[0]
    ext = sorted([(int(i), 1) for i in peaks] + [(int(i), -1) for i in troughs])
    seq: list = []
    for idx, kind in ext:
        if seq and kind == seq[-1][1]:  # two of a kind in a row: keep the more extreme one
            if kind * sx[idx] > kind * sx[seq[-1][0]]:
                seq[-1] = (idx, kind)
        elif seq or kind == 1:  # the sequence starts with a peak
            seq.append((idx, kind))
    return seq


@dataclass(frozen=True, eq=False)
class FreeDecayResult:
    """Result of :func:`analyse_free_decay` ([Hindrax-AM] eqs. 1-12).

    Scalar attributes (units in the names): ``omega_d_rad_s`` (extremum spacing),
    ``zeta`` (eq. 3 from ``log_decrement``), ``log_decrement``, ``omega_n_rad_s`` (eq. 2),
    ``added_mass_kg`` (eq. 5), ``added_mass_simplified_kg`` (eq. 7),
    ``added_mass_error_percent`` (eq. 11), ``damping_n_s_per_m`` (eq. 6), ``c_m`` (eq. 8),
    ``kc`` (eq. 9, A = ``first_peak_displacement_m``, D = V^(1/3)), ``reynolds``
    (U_m V^(1/3) / nu), ``first_peak_displacement_m``, ``max_velocity_m_s``, ``n_periods``,
    ``omega_d_fit_rad_s``/``zeta_fit`` and their ``_std`` (acceleration-fit cross-check, NaN if
    the fit failed), the inputs ``stiffness_n_per_m``, ``mass_kg``, ``volume_m3``,
    ``fluid_density_kg_m3``, and ``release_index`` (into the input arrays).

    Array attributes for plots, all over the analysed record (from the release):
    ``t_s``, ``acceleration_m_s2``, ``displacement_m``, ``velocity_m_s``, ``envelope_m``
    (x_0 exp(-zeta omega_n (t - t_0)), the decay envelope through the first peak, positive;
    the displacement keeps its sign, its first peak has the sign of the release), ``peaks``
    (indices into these arrays of the peaks used), ``peak_times_s`` and ``peak_amplitudes_m``."""

    omega_d_rad_s: float
    zeta: float
    log_decrement: float
    omega_n_rad_s: float
    added_mass_kg: float
    added_mass_simplified_kg: float
    added_mass_error_percent: float
    damping_n_s_per_m: float
    c_m: float
    kc: float
    reynolds: float
    first_peak_displacement_m: float
    max_velocity_m_s: float
    n_periods: int
    omega_d_fit_rad_s: float
    omega_d_fit_std_rad_s: float
    zeta_fit: float
    zeta_fit_std: float
    stiffness_n_per_m: float
    mass_kg: float
    volume_m3: float
    fluid_density_kg_m3: float
    release_index: int
    peaks: np.ndarray = field(repr=False)
    peak_times_s: np.ndarray = field(repr=False)
    peak_amplitudes_m: np.ndarray = field(repr=False)
    t_s: np.ndarray = field(repr=False)
    acceleration_m_s2: np.ndarray = field(repr=False)
    displacement_m: np.ndarray = field(repr=False)
    velocity_m_s: np.ndarray = field(repr=False)
    envelope_m: np.ndarray = field(repr=False)

    def to_dict(self) -> dict:
        """JSON-friendly dict: every scalar attribute (same keys), ``peaks`` (list of indices),
        ``peak_times_s`` and ``peak_amplitudes_m`` (lists)."""
        out: dict[str, Any] = {}
        for f in fields(self):
            if f.repr:  # the scalars (the arrays are repr=False)
                v = getattr(self, f.name)
                out[f.name] = int(v) if f.type == "int" else float(v)
        out["peaks"] = [int(i) for i in self.peaks]
        out["peak_times_s"] = [float(x) for x in self.peak_times_s]
        out["peak_amplitudes_m"] = [float(x) for x in self.peak_amplitudes_m]
        return out


def _fit_damped_sinusoid(t: np.ndarray, a: np.ndarray, omega0: float, sigma0: float):
    """curve_fit of exp(-s t)(C1 cos w t + C2 sin w t) + b; returns (w, w_std, zeta, zeta_std)."""
    from scipy import optimize  # here, not at the top: node processes import this module (pyproject.toml, PLC0415)

    tt = t - t[0]
    b0 = float(np.mean(a))

    def model(tv, s, w, c1, c2, b):
        e = np.exp(-s * tv)
        return e * (c1 * np.cos(w * tv) + c2 * np.sin(w * tv)) + b

    p0 = [sigma0, omega0, a[0] - b0, 0.0, b0]
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", optimize.OptimizeWarning)
            popt, pcov = optimize.curve_fit(model, tt, a, p0=p0, maxfev=4000)
    except (RuntimeError, ValueError):
        return (np.nan,) * 4
    s, w = popt[0], abs(popt[1])
    if not (np.all(np.isfinite(pcov)) and s > 0):
        return (np.nan,) * 4
    wn2 = s * s + w * w
    zeta = s / np.sqrt(wn2)
    # gradient of zeta = s / sqrt(s^2 + w^2) w.r.t. (s, w)
    g = np.array([w * w, -s * w]) / wn2**1.5
    zeta_std = float(np.sqrt(max(0.0, g @ pcov[:2, :2] @ g)))
    return float(w), float(np.sqrt(max(0.0, pcov[1, 1]))), float(zeta), zeta_std


def analyse_free_decay(t_s, acceleration_m_s2, stiffness_n_per_m: float, mass_kg: float,
                       volume_m3: float, fluid_density_kg_m3: float = 1000.0) -> FreeDecayResult:
    """Full [Hindrax-AM] analysis of one free-decay record (module docstring for the method).

    Args:
        t_s: (n,) strictly increasing sample times in s ([Hindrax-AM]: 330 Hz for 10 s).
        acceleration_m_s2: (n,) acceleration along the tested axis in m/s^2 (any constant
            bias, e.g. gravity on a tilted sensor, is removed).
        stiffness_n_per_m: equivalent spring stiffness k_eq ([Hindrax-AM]: 1127.7 or 659.9 N/m).
        mass_kg: body (model) mass m_b ([Hindrax-AM]: 0.39 kg).
        volume_m3: displaced volume V of the body ([Hindrax-AM] model: 0.00056 m^3).
        fluid_density_kg_m3: rho (default 1000); Re uses nu = 1.01e-6 m^2/s ([Hindrax-AM] §4).

    Returns:
        :class:`FreeDecayResult`.

    Raises:
        EstimationError: bad input, no oscillation, fewer than one full period above the noise,
            or an over-damped/unphysical result (zeta >= 1)."""
    from scipy import signal  # here, not at the top: node processes import this module (pyproject.toml, PLC0415)

    t = check_time_vector(t_s, "t_s", min_samples=16)
    a_all = as_float_array(acceleration_m_s2, "acceleration_m_s2", 1)
    check_same_length(t_s=t, acceleration_m_s2=a_all)
    k = positive(stiffness_n_per_m, "stiffness_n_per_m")
    mb = positive(mass_kg, "mass_kg")
    vol = positive(volume_m3, "volume_m3")
    rho = positive(fluid_density_kg_m3, "fluid_density_kg_m3")

    i_rel = find_release_index(a_all, RELEASE_THRESHOLD)
    t = t[i_rel:]
    a = a_all[i_rel:]
    if t.size < 16:
        raise EstimationError("record too short after the release")
    f_est = _dominant_frequency_hz(t, a)
    if not f_est > 0:
        raise EstimationError("no oscillation found in the acceleration")
    fs = _sample_rate(t)
    x, v = displacement_from_acceleration(t, a, highpass_hz=HIGHPASS_FRACTION * f_est)
    # the release is a displacement extremum of sign opposite to the acceleration there
    sign = -1.0 if a[0] - np.mean(a) > 0 else 1.0
    sx = sign * x

    distance = max(1, int(0.6 * fs / f_est / 2.0))  # extrema are half a period apart
    seq = _alternating_extrema(sx, distance)
    tail = sx[int(0.8 * sx.size):]
    noise_floor = 6.0 * float(np.std(signal.detrend(tail))) if tail.size > 2 else 0.0
    peaks_idx: list[int] = []
    heights: list[float] = []
    for j in range(0, len(seq) - 1, 2):
        ip, it = seq[j][0], seq[j + 1][0]
        h = sx[ip] - sx[it]
        if heights and (h < MIN_PEAK_FRACTION * heights[0] or h < noise_floor):
            break
        if not heights and h <= 0:
            break
        peaks_idx.append(ip)
        heights.append(h)
    if len(heights) < 2:
        raise EstimationError("fewer than two peaks above the noise floor: cannot measure a period")
    heights_arr = np.asarray(heights)
    n_periods = len(heights) - 1
    delta = log_decrement(heights_arr)
    zeta = damping_ratio_from_log_decrement(delta)

    # omega_d from interior extrema (peaks and troughs), release excluded
    last = 2 * n_periods  # index in seq of the last used peak
    times = np.array([_parabolic_time(t, sx * seq[j][1], seq[j][0]) for j in range(1, min(len(seq), last + 2))])
    # two peaks above the noise give at least three interior extrema
    half_period = float(np.polyfit(np.arange(times.size), times, 1)[0])
    omega_d = np.pi / half_period

    amp = heights_arr / (1.0 + np.exp(-0.5 * delta))
    x0 = float(amp[0])
    wn = natural_frequency(omega_d, zeta)
    m5 = added_mass_exact(k, omega_d, zeta, mb)
    m7 = added_mass_simplified(k, omega_d, mb)
    c = damping_coefficient(zeta, k, mb + m5)
    L = characteristic_length_from_volume(vol)
    i_end = min(t.size, peaks_idx[-1] + 1)
    u_max = float(np.max(np.abs(v[:i_end])))
    sigma = zeta * wn
    envelope = x0 * np.exp(-sigma * (t - t[0]))

    fit_end = min(t.size, peaks_idx[-1] + int(round(0.5 * fs * 2 * np.pi / omega_d)) + 1)
    w_fit, w_fit_std, z_fit, z_fit_std = _fit_damped_sinusoid(t[:fit_end], a[:fit_end], omega_d, sigma)
    peaks_arr = np.asarray(peaks_idx, dtype=int)
    return FreeDecayResult(
        omega_d_rad_s=float(omega_d), zeta=float(zeta), log_decrement=float(delta),
        omega_n_rad_s=float(wn), added_mass_kg=float(m5), added_mass_simplified_kg=float(m7),
        added_mass_error_percent=float(added_mass_error_percent(m7, m5)),
        damping_n_s_per_m=float(c), c_m=inertia_coefficient(m5, vol, rho),
        kc=keulegan_carpenter(x0, L),
        reynolds=float(reynolds_number(u_max, L)),
        first_peak_displacement_m=x0, max_velocity_m_s=u_max, n_periods=int(n_periods),
        omega_d_fit_rad_s=w_fit, omega_d_fit_std_rad_s=w_fit_std, zeta_fit=z_fit,
        zeta_fit_std=z_fit_std, stiffness_n_per_m=k, mass_kg=mb, volume_m3=vol,
        fluid_density_kg_m3=rho, release_index=int(i_rel), peaks=peaks_arr,
        peak_times_s=t[peaks_arr], peak_amplitudes_m=amp, t_s=t, acceleration_m_s2=a,
        displacement_m=x, velocity_m_s=v, envelope_m=envelope)


# Quadratic damping: output-error fit of the nonlinear free-decay ODE ([SmallROV] eqs. 12-16)
#: Signals the ODE fit can compare with the record (``output``): what the sensor measured.
DECAY_OUTPUTS = ("acceleration", "velocity", "displacement")


@dataclass(frozen=True, eq=False)
class QuadraticDecayFit:
    """Result of :func:`fit_quadratic_free_decay`.

    The model is the 1-DOF free decay with linear and quadratic damping of [SmallROV] eq. 12 with the restoring term
    of [Hindrax-AM] eq. 1 (a spring of stiffness k, or a hydrostatic restoring moment C for roll/pitch):

        M x'' + b1 x' + b2 |x'| x' + k x = 0,   M = m_b + m_ad   (rigid + added inertia)

    Attributes (SI; for a rotational DOF read kg as kg m^2, m as rad, N as N m):
    ``total_inertia`` (M, kg) and ``total_inertia_std``; ``added_inertia`` (M - m_b, kg; NaN when
    no rigid inertia was given) and ``added_inertia_std`` (= ``total_inertia_std``: m_b is taken as
    exact); ``linear_damping`` (b1, N s/m) and ``linear_damping_std``; ``quadratic_damping`` (b2,
    N s^2/m^2) and ``quadratic_damping_std``; ``initial_displacement`` and ``initial_velocity`` (state
    at the first analysed sample, m and m/s); ``bias`` (constant sensor offset in the unit of the
    output); ``rms_residual`` (unit of the output); ``n_samples``; ``stiffness`` (k, N/m, given);
    ``output`` (one of :data:`DECAY_OUTPUTS`); ``t0_s`` (time of the first analysed sample);
    ``covariance`` ((6, 6), order M, b1, b2, x0, v0, bias: s^2 (J^T J)^-1 with the residual variance
    s^2, i.e. white residuals assumed - the std are optimistic when the residuals are coloured);
    ``fitted`` ((n,) the model output at the record's times)."""

    total_inertia: float
    total_inertia_std: float
    added_inertia: float
    added_inertia_std: float
    linear_damping: float
    linear_damping_std: float
    quadratic_damping: float
    quadratic_damping_std: float
    initial_displacement: float
    initial_velocity: float
    bias: float
    rms_residual: float
    n_samples: int
    stiffness: float
    output: str
    t0_s: float
    covariance: np.ndarray = field(repr=False)
    fitted: np.ndarray = field(repr=False)


def _decay_rhs(M: float, b1: float, b2: float, k: float):
    """Right-hand side of the state + sensitivity system (see :func:`_simulate_decay`).

    Plain Python floats on purpose: the system is tiny and numpy's per-call overhead would
    dominate the integration time."""
    inv_m = 1.0 / M

    def rhs(_t, z):
        x, v = z[0], z[1]
        av = abs(v)
        f = -(k * x + b1 * v + b2 * av * v) * inv_m
        dfdx = -k * inv_m
        dfdv = -(b1 + 2.0 * b2 * av) * inv_m
        # d f / d(M, b1, b2) directly; x0 and v0 enter through the initial sensitivities only
        d0, d1, d2 = -f * inv_m, -v * inv_m, -av * v * inv_m
        return [v, f,
                z[3], dfdx * z[2] + dfdv * z[3] + d0,
                z[5], dfdx * z[4] + dfdv * z[5] + d1,
                z[7], dfdx * z[6] + dfdv * z[7] + d2,
                z[9], dfdx * z[8] + dfdv * z[9],
                z[11], dfdx * z[10] + dfdv * z[11]]
    return rhs


def _simulate_decay(tt: np.ndarray, theta: np.ndarray, k: float, output: str):
    """Integrate the ODE and its forward sensitivities (scipy ``solve_ivp``, DOP853, rtol 1e-7: model error
    about 1e-7 of the amplitude, far below any sensor noise).

    theta = (M, b1, b2, x0, v0, bias); tt: (n,) times from 0. Returns (y, J): the model output
    (n,) and its Jacobian (n, 6) with respect to theta."""
    from scipy import integrate  # here, not at the top: node processes import this module (pyproject.toml, PLC0415)

    M, b1, b2, x0, v0, bias = (float(p) for p in theta)
    z0 = np.zeros(12)
    z0[0], z0[1] = x0, v0
    z0[2 + 2 * 3] = 1.0       # d x / d x0 at t = 0
    z0[2 + 2 * 4 + 1] = 1.0   # d v / d v0 at t = 0
    sol = integrate.solve_ivp(_decay_rhs(M, b1, b2, k), (0.0, float(tt[-1])), z0, method="DOP853",
                              t_eval=tt, rtol=1e-7, atol=1e-10 * max(abs(x0), abs(v0), 1e-6))
    if not sol.success or sol.y.shape[1] != tt.size:
        raise EstimationError(f"free-decay ODE integration failed: {sol.message}")
    x, v = sol.y[0], sol.y[1]
    s = sol.y[2:].reshape(5, 2, -1)            # (param, x|v, time)
    n = tt.size
    J = np.zeros((n, 6))
    if output in ("displacement", "velocity"):
        j = 0 if output == "displacement" else 1   # state x or v
        y = sol.y[j] + bias
        J[:, :5] = s[:, j, :].T
    else:
        f = -(k * x + b1 * v + b2 * np.abs(v) * v) / M
        y = f + bias
        dfdx = -k / M
        dfdv = -(b1 + 2.0 * b2 * np.abs(v)) / M
        direct = np.stack([-f / M, -v / M, -np.abs(v) * v / M, np.zeros(n), np.zeros(n)])
        J[:, :5] = (dfdx * s[:, 0, :] + dfdv * s[:, 1, :] + direct).T
    J[:, 5] = 1.0
    return y, J


def fit_quadratic_free_decay(t_s, y, stiffness: float, rigid_inertia: Optional[float] = None,
                             output: str = "acceleration", initial_total_inertia: Optional[float] = None,
                             initial_linear_damping: Optional[float] = None) -> QuadraticDecayFit:
    """Fit M x'' + b1 x' + b2 |x'| x' + k x = 0 to a whole free-decay record (output error).

    The amplitude-dependent decrement of quadratic damping ([SmallROV] eqs. 12-16: the
    pendulum's K_L x' + K_Q |x'| x') is what separates b1 from b2: a log decrement
    ([Hindrax-AM] eq. 3) assumes a constant decrement and reports one equivalent linear
    damping that depends on the amplitude. [SmallROV] eq. 17 estimates the coefficients by
    linear least squares on differentiated angles; here the ODE is integrated instead
    (``scipy.integrate.solve_ivp`` with forward sensitivities) and the simulated output is fitted to
    the measured one with ``scipy.optimize.least_squares`` (trust-region reflective, b1, b2 >= 0,
    M > 0), so no signal is differentiated or integrated. The stiffness k is known (spring:
    [Hindrax-AM] k_eq; roll/pitch: the inclining test's restoring moment per radian), so
    M follows from the period and the result is independent of any thrust curve.

    Args:
        t_s: (n,) strictly increasing times in s, starting at (or just after) the release.
        y: (n,) measured output: acceleration (m/s^2; any constant bias is fitted), velocity (m/s)
            or displacement (m) per ``output``; for a rotational DOF rad/s^2, rad/s or rad.
        stiffness: k in N/m (or C in N m/rad), > 0.
        rigid_inertia: m_b in kg (or kg m^2) to report ``added_inertia`` = M - m_b (optional).
        output: one of :data:`DECAY_OUTPUTS`.
        initial_total_inertia: starting M (default: k / omega^2 from the record's spectrum peak).
        initial_linear_damping: starting equivalent linear damping in N s/m (default: 0.1 of
            critical); split half linear, half quadratic at the record's mean speed.

    Returns:
        :class:`QuadraticDecayFit`.

    Raises:
        EstimationError: bad input (shapes, NaN, time, k <= 0, unknown output), fewer than 32
            samples, no oscillation, or a failed integration/fit."""
    from scipy import optimize  # here, not at the top: node processes import this module (pyproject.toml, PLC0415)

    if output not in DECAY_OUTPUTS:
        raise EstimationError(f"output must be one of {', '.join(DECAY_OUTPUTS)}, got {output!r}")
    t = check_time_vector(t_s, "t_s", min_samples=32)
    yy = as_float_array(y, "y", 1)
    check_same_length(t_s=t, y=yy)
    k = positive(stiffness, "stiffness")
    tt = t - t[0]

    f_hz = _dominant_frequency_hz(t, yy)
    if not f_hz > 0:
        raise EstimationError("no oscillation found in the record")
    w = 2.0 * np.pi * f_hz
    M0 = float(initial_total_inertia) if initial_total_inertia else k / w**2
    c0 = float(initial_linear_damping) if initial_linear_damping else 0.1 * 2.0 * np.sqrt(k * M0)
    # starting state and amplitude from the first sample(s), per output
    yc = yy - np.mean(yy[int(0.8 * yy.size):])
    if output == "acceleration":
        x0, v0 = -yc[0] / w**2, 0.0
    elif output == "velocity":
        x0, v0 = float(np.max(np.abs(yc[: max(2, int(t.size * 0.5 / (f_hz * tt[-1])))])) / w), float(yc[0])
        x0 = x0 if yc[min(yc.size - 1, 3)] < 0 else -x0
    else:
        x0, v0 = float(yc[0]), 0.0
    amp = max(abs(x0), 1e-12)
    u_mean = 0.5 * w * amp
    theta0 = np.array([M0, 0.5 * c0, 0.5 * c0 / max(u_mean, 1e-12), x0, v0, float(np.mean(yy[int(0.8 * yy.size):]))])

    cache: dict = {}

    def model(theta):
        key = theta.tobytes()
        if key not in cache:
            cache.clear()
            cache[key] = _simulate_decay(tt, theta, k, output)
        return cache[key]

    lower = np.array([1e-9 * M0, 0.0, 0.0, -np.inf, -np.inf, -np.inf])
    best, last_exc = None, None
    for scale_b2 in (1.0, 0.05):   # a second starting split only if the first fit fails
        if best is not None and best.success:
            break
        th0 = theta0.copy()
        th0[2] *= scale_b2
        try:
            res = optimize.least_squares(lambda th: model(th)[0] - yy, th0, jac=lambda th: model(th)[1],
                                         bounds=(lower, np.full(6, np.inf)), x_scale="jac", method="trf", max_nfev=100)
        except (ValueError, EstimationError) as exc:
            last_exc = exc
            continue
        if best is None or res.cost < best.cost:
            best = res
    if best is None:
        raise EstimationError(f"free-decay ODE fit failed: {last_exc}")
    theta = best.x
    yfit, J = model(theta)
    r = yfit - yy
    dof = max(1, yy.size - 6)
    s2 = float(r @ r) / dof
    try:
        cov = s2 * np.linalg.inv(J.T @ J)
    except np.linalg.LinAlgError:
        cov = np.full((6, 6), np.nan)
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    M = float(theta[0])
    mb = None if rigid_inertia is None else positive(rigid_inertia, "rigid_inertia")
    return QuadraticDecayFit(
        total_inertia=M, total_inertia_std=float(std[0]),
        added_inertia=float("nan") if mb is None else M - mb, added_inertia_std=float(std[0]),
        linear_damping=float(theta[1]), linear_damping_std=float(std[1]),
        quadratic_damping=float(theta[2]), quadratic_damping_std=float(std[2]),
        initial_displacement=float(theta[3]), initial_velocity=float(theta[4]), bias=float(theta[5]),
        rms_residual=float(np.sqrt(np.mean(r * r))), n_samples=int(yy.size), stiffness=k,
        output=output, t0_s=float(t[0]), covariance=cov, fitted=yfit)


def quadratic_free_decay_keys(res: "FreeDecayResult", t_s, acceleration_m_s2) -> dict:
    """The keys ``hindrax ident free-decay --model quadratic`` adds to the linear analysis' JSON.

    Fits :func:`fit_quadratic_free_decay` to the acceleration from the release found by the linear analysis ``res``
    (its ``release_index``), started from its added mass (eq. 5) and damping (eq. 6). Returns
    ``linear_damping_n_s_per_m``, ``quadratic_damping_n_s2_per_m2``, the ODE fit's ``added_mass_ode_kg`` (rigid mass
    ``res.mass_kg`` subtracted), each with its ``_std``, and ``ode_rms_residual_m_s2``."""
    t = np.asarray(t_s, dtype=float)[res.release_index:]
    a = np.asarray(acceleration_m_s2, dtype=float)[res.release_index:]
    fit = fit_quadratic_free_decay(t, a, res.stiffness_n_per_m, rigid_inertia=res.mass_kg, output="acceleration",
                                   initial_total_inertia=res.mass_kg + res.added_mass_kg,
                                   initial_linear_damping=res.damping_n_s_per_m)
    out = {}
    for key, name in (("linear_damping_n_s_per_m", "linear_damping"),
                      ("quadratic_damping_n_s2_per_m2", "quadratic_damping"),
                      ("added_mass_ode_kg", "added_inertia")):
        out[key], out[f"{key}_std"] = getattr(fit, name), getattr(fit, f"{name}_std")
    out["ode_rms_residual_m_s2"] = fit.rms_residual
    return out


# Inclining test: hydrostatic restoring stiffness in roll/pitch from a known moment
@dataclass(frozen=True)
class IncliningResult:
    """Result of :func:`restoring_from_inclining`.

    ``restoring_n_m_per_rad`` (C, N m/rad) and its ``_std`` (NaN with only two points); ``offset_n_m`` (the moment
    that holds the vehicle's own static list, from the intercept); ``bg_m`` (C / (m g), when the vehicle mass was
    given, else NaN) and ``bg_m_std``; ``weight_in_water_n`` (of the test mass); ``n_points``; ``residual_rms_n_m``."""

    restoring_n_m_per_rad: float
    restoring_n_m_per_rad_std: float
    offset_n_m: float
    bg_m: float
    bg_m_std: float
    weight_in_water_n: float
    n_points: int
    residual_rms_n_m: float

    def to_dict(self) -> dict:
        return {k: (int(v) if k == "n_points" else float(v)) for k, v in self.__dict__.items()}


def restoring_from_inclining(arm_m, tilt_rad, test_mass_kg: float, test_volume_m3: float = 0.0,
                             fluid_density_kg_m3: float = 1000.0, gravity_m_s2: float = 9.81,
                             vehicle_mass_kg: Optional[float] = None) -> IncliningResult:
    """Restoring stiffness C from an inclining test: a known mass moved across the vehicle, tilt measured.

    With the test mass's weight in water w = (m - rho V) g at horizontal arm d (body frame, from the CG, in the
    plane of the tilt) the static equilibrium is w d cos(phi) = C sin(phi) + M0, i.e. w d = C tan(phi) + M0 / cos(phi)
    ~= C tan(phi) + M0 for small tilts (M0: the moment of the vehicle's own list). C (and M0) by linear least
    squares over the points, std from the residual variance. C = W BG for a vehicle whose weight equals its
    buoyancy ([NTNU-Thesis] Sec. 3.1.2), so BG = C / (m g) when the vehicle mass is given. This is
    the classical inclining experiment; the stiffness it gives is what turns a roll/pitch free-decay period into
    rigid + added inertia (:func:`fit_quadratic_free_decay` with ``stiffness`` = C), free of any thrust curve.
    Assumes the test mass hangs at the CG's height (a mass above/below it shifts the CG too).

    Args:
        arm_m: (n,) signed horizontal arms, m (n >= 2, at least two different arms; include 0 and both signs).
        tilt_rad: (n,) measured tilt (IMU roll or pitch, averaged over each hold), rad, same sign convention
            as the moment w d.
        test_mass_kg, test_volume_m3: the known mass and its displaced volume.
        vehicle_mass_kg: optional, for BG.

    Raises:
        EstimationError: bad shapes, fewer than 2 points, all arms equal, non-positive weight in water."""
    d = as_float_array(arm_m, "arm_m", 1)
    phi = as_float_array(tilt_rad, "tilt_rad", 1)
    check_same_length(arm_m=d, tilt_rad=phi)
    if d.size < 2 or np.ptp(d) <= 0:
        raise EstimationError("need at least two different arms")
    if np.any(np.abs(phi) >= 0.5 * np.pi):
        raise EstimationError("tilts must be within +-90 deg (radians expected)")
    rho = positive(fluid_density_kg_m3, "fluid_density_kg_m3")
    w = (positive(test_mass_kg, "test_mass_kg") - float(test_volume_m3) * rho) * gravity_m_s2
    if not w > 0:
        raise EstimationError(f"test mass must be heavier than the water it displaces, weight in water {w} N")
    y = w * d
    X = np.column_stack([np.tan(phi), np.ones_like(phi)])
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    r = y - X @ coef
    n = y.size
    if n > 2:
        s2 = float(r @ r) / (n - 2)
        cov = s2 * np.linalg.inv(X.T @ X)
        c_std = float(np.sqrt(cov[0, 0]))
    else:
        c_std = float("nan")
    c = float(coef[0])
    if not c > 0:
        raise EstimationError(f"restoring stiffness came out {c:.4g} N m/rad (<= 0): check the signs of arm and tilt")
    if vehicle_mass_kg is not None:
        wv = positive(vehicle_mass_kg, "vehicle_mass_kg") * gravity_m_s2
        bg, bg_std = c / wv, c_std / wv
    else:
        bg, bg_std = float("nan"), float("nan")
    return IncliningResult(restoring_n_m_per_rad=c, restoring_n_m_per_rad_std=c_std, offset_n_m=float(coef[1]),
                           bg_m=bg, bg_m_std=bg_std, weight_in_water_n=float(w), n_points=int(n),
                           residual_rms_n_m=float(np.sqrt(np.mean(r * r))))
