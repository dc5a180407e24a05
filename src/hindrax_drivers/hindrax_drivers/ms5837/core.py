"""The MS5837 driver's decisions, without ROS (the node, :mod:`hindrax_drivers.ms5837.node`, runs the I2C cycle).

- Readings: the PROM (:func:`check_prom`: CRC-4; with ``sensors.ms5837.prom_reject_blank_words`` no coefficient
  0x0000/0xFFFF, which an all-zero PROM would pass; the variant configured or by Blue Robotics' C1 heuristic,
  docs/devices.md §3.9) and each ADC word (:func:`adc_problem`: 0 is no completed conversion, §3.1; 0xFFFFFF a bus
  held high or a broken bridge).
- Time of validity (:func:`stamp_offset_s`): the D1 command's ROS time plus half the OSR's conversion time (4.5 ms at
  OSR 4096), the middle of the ADC's integration; at 0.3 m/s of heave 10 ms of stamp error is 3 mm of depth.
- Depth = (P - surface_pressure_pa) / (water_density_kg_m3 * gravity_m_s2) of the port (§3.6), variance
  variance_P / (rho g)^2 (:func:`depth_covariance`); pressure variance resolution^2 + LSB^2/12.
- Plausibility (:class:`Plausibility`; ERROR ``implausible``, held :data:`IMPLAUSIBLE_HOLD_S` after the last
  rejection; nothing published for that cycle): a pressure outside [``min_pressure_pa``, ``max_pressure_pa``]
  (counted ``implausible_pressure``), then :class:`DepthGate`: a depth outside [``min_depth_m``, ``max_depth_m``] or
  one faster than ``max_depth_rate_m_s`` not confirmed by the next sample (``implausible_depth``). Garbage ADC words
  pass the pressure window in about 4.5 % of random pairs; the rate gate needs two consecutive ones to agree.
- Zero depth (:class:`ZeroDepth`): the surface pressure becomes the mean of the last :data:`ZERO_DEPTH_WINDOW_S`;
  refused while the ESC may be thrusting (:class:`hindrax_common.node_support.esc_state.ArmedWatch`'s reason) and when
  that mean is further than ``zero_depth_margin_pa`` from the pressure the node started with (a zero taken at 1.5 m
  would move every depth, and the depth limits with it, 1.5 m down)."""
from __future__ import annotations

import collections
import math
from dataclasses import dataclass
from typing import Any

from . import protocol as p

__all__ = ["DepthGate", "Plausibility", "Verdict", "ZeroDepth", "adc_problem", "check_prom", "depth_covariance",
           "diagnostic_values", "pressure_variance_pa2", "stamp_offset_s", "temperature_warning",
           "PRESSURE_RESOLUTION_PA", "UNKNOWN_VARIANCE"]

#: The ERROR ``implausible`` stays raised this long after the last rejected reading (ROS time), s.
IMPLAUSIBLE_HOLD_S = 2.0
#: Window of readings averaged by the zero_depth service, s.
ZERO_DEPTH_WINDOW_S = 1.0
#: Variance used for the pose components a depth sensor does not measure (x, y, orientation).
UNKNOWN_VARIANCE = 1.0e6
#: Pressure resolution per variant, Pa: docs/devices.md §3.4 table ("0.25 mbar resolution" 30BA,
#: "0.01 mbar" 02BA). The per-OSR RMS table of the datasheet was not retrieved, so one figure is used
#: for every OSR (it is the figure for the highest OSR; lower OSRs are noisier).
PRESSURE_RESOLUTION_PA = {p.Variant.MS5837_30BA: 25.0, p.Variant.MS5837_02BA: 1.0}
#: Temperature output resolution, degC (TEMP in 0.01 degC, docs/devices.md §3.4).
TEMPERATURE_RESOLUTION_C = 0.01


def pressure_variance_pa2(variant: p.Variant) -> float:
    """Variance of one pressure reading, Pa^2: resolution^2 (taken as 1 sigma) + output LSB^2 / 12.

    Output LSB: 10 Pa (30BA, 0.1 mbar) or 1 Pa (02BA, 0.01 mbar) (docs/devices.md §3.4, §3.6)."""
    lsb_pa = 1.0 / p.pressure_counts_per_pa(variant)
    return PRESSURE_RESOLUTION_PA[p.Variant(variant)] ** 2 + lsb_pa ** 2 / 12.0


def check_prom(words: list[int], reject_blank_words: bool,
               configured: p.Variant | None) -> tuple[p.Calibration, p.Variant]:
    """The calibration and variant of 8 PROM words (module docstring). configured: the variant set, None for
    ``auto``. Raises :class:`~hindrax_drivers.ms5837.protocol.Ms5837Error` with the reason."""
    calibration = p.Calibration.from_words(words, check_crc=True)
    issue = p.prom_sanity_issue(calibration) if reject_blank_words else ""
    if issue:
        raise p.Ms5837Error(issue)
    return calibration, p.detect_variant(calibration, configured)


def adc_problem(data: bytes) -> tuple[str, str]:
    """('', '') for a usable 3-byte ADC read, else (counter, reason): ``adc_zero`` or ``adc_saturated``."""
    try:
        value = p.parse_adc(data)
    except p.Ms5837Error as exc:
        return "adc_zero", str(exc)
    if value >= p.ADC_MAX:
        return "adc_saturated", "ADC read 0xFFFFFF (saturated): reading rejected"
    return "", ""


def stamp_offset_s(osr: int) -> float:
    """From the D1 command to the reading's time of validity, s: half the OSR's conversion time."""
    return 0.5 * p.conversion_time_s(osr)


def temperature_warning(reading: p.Reading) -> str:
    """The WARN ``temperature_range`` text of a reading outside the datasheet's range ('' inside)."""
    if reading.temperature_in_range:
        return ""
    return (f"temperature {reading.temperature_c:.2f} degC outside {p.TEMPERATURE_MIN_C:g}..{p.TEMPERATURE_MAX_C:g} "
            "degC")


def diagnostic_values(variant: p.Variant | None, configured: p.Variant | None, osr: int, conversion_wait_s: float,
                      surface_pressure_pa: float, cycles: int, startup_attempts: int,
                      calibration: p.Calibration | None) -> list[tuple[str, Any]]:
    """The device-specific KeyValues of the driver's ``/diagnostics`` entry."""
    out = [("variant", variant.value if variant else "unknown"),
           ("variant_configured", configured.value if configured else "auto"), ("oversampling", osr),
           ("conversion_wait_s", f"{conversion_wait_s:.4f}"), ("surface_pressure_pa", f"{surface_pressure_pa:.1f}"),
           ("cycles", cycles), ("startup_attempts", startup_attempts)]
    if calibration is not None:
        out.append(("prom_c1_c6", " ".join(str(c) for c in calibration.words[1:7])))
    return out


def depth_covariance(pressure_variance_pa2: float, rho_g: float) -> list[float]:
    """Row-major 6x6 covariance of the depth pose (x y z roll pitch yaw): z = variance_P / (rho g)^2 (m^2), the
    unmeasured diagonal :data:`UNKNOWN_VARIANCE`, off-diagonals 0. rho_g: water density times gravity, Pa/m."""
    cov = [0.0] * 36
    for i in (0, 7, 21, 28, 35):
        cov[i] = UNKNOWN_VARIANCE
    cov[14] = pressure_variance_pa2 / rho_g ** 2
    return cov


class DepthGate:
    """Range and rate-of-change gate on the depth after conversion (pure; see the module docstring).

    ``check(t_s, depth_m)`` returns '' to publish, else the reason; ``invalid()`` tells it that a cycle gave no reading
    (rejected earlier, or failed). A depth within ``max_rate_m_s * dt + noise_m`` of the last accepted one, accepted at
    most ``max_age_s`` ago, is accepted; any other in-range depth is held as a candidate and accepted when the very next
    cycle agrees with it (a real jump, e.g. after an outage, costs one sample). Noise passes only when two consecutive
    garbage readings agree. Defaults from the vehicle's physics: Hindrax heaves well under 1 m/s."""

    def __init__(self, min_depth_m: float, max_depth_m: float, max_rate_m_s: float, noise_m: float = 0.05,
                 max_age_s: float = 0.5) -> None:
        self.min_depth_m, self.max_depth_m = float(min_depth_m), float(max_depth_m)
        self.max_age_s = float(max_age_s)
        self.max_rate_m_s, self.noise_m = float(max_rate_m_s), float(noise_m)
        self._last: tuple[float, float] | None = None
        self._candidate: tuple[float, float] | None = None

    def _agrees(self, ref: tuple[float, float], t_s: float, depth_m: float) -> bool:
        return abs(depth_m - ref[1]) <= self.max_rate_m_s * max(t_s - ref[0], 0.0) + self.noise_m

    def invalid(self) -> None:
        """A cycle without a reading: the next depth cannot confirm a candidate across it."""
        self._candidate = None

    def check(self, t_s: float, depth_m: float) -> str:
        """'' when the depth (m) at ``t_s`` (s) is published, else the reason (one line)."""
        if not math.isfinite(depth_m) or not self.min_depth_m <= depth_m <= self.max_depth_m:
            self._candidate = None
            return (f"depth {depth_m:.2f} m outside sensors.ms5837.min_depth_m..max_depth_m "
                    f"{self.min_depth_m:g}..{self.max_depth_m:g} m")
        if self._last is not None and t_s - self._last[0] <= self.max_age_s and self._agrees(self._last, t_s, depth_m):
            self._last, self._candidate = (t_s, depth_m), None
            return ""
        if self._candidate is not None and self._agrees(self._candidate, t_s, depth_m):
            self._last, self._candidate = (t_s, depth_m), None
            return ""
        if self._last is None:  # the first depth (range-checked) is the baseline
            self._last = (t_s, depth_m)
            return ""
        self._candidate = (t_s, depth_m)
        return (f"depth {depth_m:.2f} m changed faster than sensors.ms5837.max_depth_rate_m_s {self.max_rate_m_s:g} "
                f"since {self._last[1]:.2f} m (held until the next sample confirms it)")


@dataclass(frozen=True)
class Verdict:
    """What :meth:`Plausibility.check` decided: ``publish`` the reading; else ``counter`` to count and ``error`` the
    text of the ERROR ``implausible``; ``first`` is True for the first rejection of a run (diagnostics at once);
    ``clear`` is True when the held ERROR ends now."""

    publish: bool
    counter: str = ""
    error: str = ""
    first: bool = False
    clear: bool = False


class Plausibility:
    """The pressure window, then the :class:`DepthGate`, with the ERROR's hold (module docstring). Times in s of ROS
    time; pressures in Pa; depths in m."""

    def __init__(self, min_pressure_pa: float, max_pressure_pa: float, gate: DepthGate,
                 hold_s: float = IMPLAUSIBLE_HOLD_S) -> None:
        self.min_pressure_pa, self.max_pressure_pa = float(min_pressure_pa), float(max_pressure_pa)
        self.gate, self.hold_s = gate, float(hold_s)
        self.last_rejected_s: float | None = None

    def invalid(self) -> None:
        """A cycle that gave no reading (failed)."""
        self.gate.invalid()

    def check(self, now_s: float, pressure_pa: float, depth_m: float, raw: str = "") -> Verdict:
        """Judge one reading; ``raw`` (e.g. "D1 = .., D2 = ..") is added to the ERROR's text."""
        if not self.min_pressure_pa <= pressure_pa <= self.max_pressure_pa:
            self.gate.invalid()
            first, self.last_rejected_s = self.last_rejected_s is None, now_s
            return Verdict(False, "implausible_pressure", f"implausible pressure {pressure_pa:.0f} Pa outside "
                           f"{self.min_pressure_pa:g}..{self.max_pressure_pa:g} Pa ({raw}): not published", first)
        reason = self.gate.check(now_s, depth_m)
        if reason:
            self.last_rejected_s = now_s
            return Verdict(False, "implausible_depth", f"{reason} ({raw}): not published")
        if self.last_rejected_s is not None and now_s - self.last_rejected_s > self.hold_s:
            self.last_rejected_s = None
            return Verdict(True, clear=True)
        return Verdict(True)


class ZeroDepth:
    """The readings of the last ``window_s`` (s) and the ``pressure/zero_depth`` decision (module docstring).

    reference_pa: the atmospheric reference; margin_pa: how far from it the mean may be; rho_g: Pa per m of water."""

    def __init__(self, reference_pa: float, margin_pa: float, rho_g: float,
                 window_s: float = ZERO_DEPTH_WINDOW_S) -> None:
        self.reference_pa, self.margin_pa, self.rho_g = float(reference_pa), float(margin_pa), float(rho_g)
        self.window_s = float(window_s)
        self.recent: collections.deque[tuple[float, float]] = collections.deque()

    def add(self, t_s: float, pressure_pa: float) -> None:
        """One published pressure (Pa) at ``t_s`` (s); older than the window drops out."""
        self.recent.append((t_s, pressure_pa))
        while self.recent and self.recent[0][0] < t_s - self.window_s:
            self.recent.popleft()

    def decide(self, refusal: str) -> tuple[float | None, str]:
        """(new surface pressure in Pa, '') when the zero is taken, else (None, the reason). refusal: the arm lock's
        reason ('' = the ESC reported disarmed)."""
        if not self.recent:
            return None, "no pressure reading yet; surface pressure unchanged"
        mean_pa = sum(v for _, v in self.recent) / len(self.recent)
        off_pa = mean_pa - self.reference_pa
        if refusal:
            return None, f"{refusal}; surface pressure unchanged"
        if abs(off_pa) > self.margin_pa:
            return None, (f"refused: mean pressure {mean_pa:.1f} Pa is {off_pa:+.1f} Pa ({off_pa / self.rho_g:+.2f} m "
                          f"of water) from the atmospheric reference {self.reference_pa:.1f} Pa, beyond "
                          f"sensors.ms5837.zero_depth_margin_pa {self.margin_pa:g}: not at the surface; surface "
                          "pressure unchanged")
        return mean_pa, ""

    def check_value(self, value_pa: float, refusal: str) -> str:
        """'' when ``environment.surface_pressure_pa`` may be set to ``value_pa`` (Pa) at run time, else the reason:
        :meth:`decide`'s checks (disarmed, at the surface), and ``value_pa`` within the margin of the mean reading,
        so the published depth moves by at most the margin (issue 71.7: 3.00 m published as 1.50 m)."""
        mean_pa, why = self.decide(refusal)
        if mean_pa is None:
            return why
        if abs(value_pa - mean_pa) > self.margin_pa:
            return (f"environment.surface_pressure_pa = {value_pa:g}: {value_pa - mean_pa:+.1f} Pa "
                    f"({(value_pa - mean_pa) / self.rho_g:+.2f} m of water) from the mean reading {mean_pa:.1f} Pa, "
                    f"allowed within sensors.ms5837.zero_depth_margin_pa {self.margin_pa:g}; surface pressure "
                    "unchanged")
        return ""
