"""TE MS5837-30BA / -02BA device emulator (command-exact, I2C address 0x76).

For :class:`~hindrax_common.transport.emulated_i2c.EmulatedI2CBus`; the device side of docs/devices.md §3.1 and §3.8:

* commands: reset (0x1E), PROM read (0xA0 + 2k, MSB first), D1/D2 conversions with OSR, ADC read
  (0x00, 3 bytes MSB first);
* an ADC read with no conversion done, read twice, or before the conversion time returns 0; a read
  during a conversion zeroes it, and so does a conversion started while one runs;
* PROM with a valid CRC-4 (§3.3), coefficients configurable (default: datasheet example);
* raw values from a truth source ``t_s -> (pressure_pa, temperature_c)`` at the start of each
  conversion, through the inverse compensation (§3.8, :func:`invert_to_raw`);
* faults: stuck outputs, corrupted or blank PROM, forced ADC counts (``raw_override``), a power
  cycle (:meth:`Ms5837Emulator.power_cycle`: ADC reads 0 until the next reset); NACKs are injected by the bus.

Modelling choices: reset is instantaneous; conversion time per OSR is
:data:`~hindrax_drivers.ms5837.protocol.CONVERSION_TIME_S` (§3.1); unknown commands are ignored;
reads not preceded by PROM/ADC commands return zeros."""

from __future__ import annotations

import threading
import time
from fractions import Fraction
from typing import Any, Callable, Sequence

from . import protocol as p

__all__ = ["from_config", "Ms5837Emulator", "invert_to_raw", "TruthSource"]

#: Truth source: time in s -> (absolute pressure in Pa, temperature in degC).
TruthSource = Callable[[float], "tuple[float, float]"]


def _closest_monotonic(f: Callable[[int], int], target: float | Fraction, lo: int, hi: int, hint: int | None = None,
                       key: Callable[[int], Any] | None = None) -> int:
    """Integer x in [lo, hi] near where the non-decreasing ``key`` (default ``f``) crosses target: of the two
    integers around the crossing, the one whose f(x) is closer (a tie: the upper). ``hint``: a guess (e.g. the previous
    answer): the bracket is found by doubling steps out from it, then bisected; as ``key`` is monotonic the pair
    around its crossing is unique, so the answer is the one without a hint, in a few evaluations when the target
    moved little."""
    key, a, b, step = key or f, lo, hi, 1
    if hint is not None and lo < hint < hi:
        a = b = hint
        up = key(hint) < target
        while (b < hi and key(b) < target) if up else (a > lo and key(a) >= target):
            a, b, step = (b, min(b + step, hi), 2 * step) if up else (max(a - step, lo), a, 2 * step)
    if key(b) < target:
        return hi
    if key(a) >= target:
        return lo
    # invariant: key(a) < target <= key(b)
    while b - a > 1:
        mid = (a + b) // 2
        if key(mid) < target:
            a = mid
        else:
            b = mid
    return a if abs(f(a) - target) < abs(f(b) - target) else b


def invert_to_raw(pressure_pa: float, temperature_c: float, calibration: p.Calibration, variant: p.Variant,
                  apply_second_order: bool = True, hint: tuple[int, int] | None = None) -> tuple[int, int]:
    """Raw (D1, D2) whose compensation is closest to the given pressure and temperature.

    Implements docs/devices.md §3.8: D2 is chosen so that TEMP is closest to ``temperature_c * 100``; then D1 so
    that P (P2) is closest to the pressure in output counts. Instead of the closed-form estimate plus +-1 adjustment
    we bisect on the exact integer forward model (:func:`~hindrax_drivers.ms5837.protocol.compensate`), which gives
    the same answer and also covers the second-order branches. TEMP2 is not monotonic in D2 (it falls back a count
    where Ti steps up), so several D2 can give the closest TEMP2: with second order D2 is the count next to where the
    unrounded TEMP2 (:func:`~hindrax_drivers.ms5837.protocol.unrounded_temp`, strictly increasing) crosses the
    request, the one of the two whose TEMP2 is closer: what a part at that temperature reads, one D2 whatever the
    hint. Both are clamped to 24 bits, so targets outside the representable range saturate.

    Args:
        pressure_pa: absolute pressure, Pa.
        temperature_c: temperature, degC.
        calibration: PROM contents.
        variant: sensor variant.
        apply_second_order: invert the second-order model (as a driver using it will see).
        hint: (D1, D2) of a previous inversion, where the search starts (same answer, fewer evaluations).

    Returns:
        (D1, D2), each 0..2^24-1. The round trip error is within half an output LSB
        (30BA: 5 Pa, 02BA: 0.5 Pa; 0.005 degC) plus the ADC step, inside the representable range; with the second-order
        model within one TEMP2 step (0.01 degC) plus the D2 step.

    Raises ``Ms5837Error``: non-finite inputs."""
    if not all(map(lambda v: v == v and abs(v) != float("inf"), (pressure_pa, temperature_c))):
        raise p.Ms5837Error(f"truth values must be finite, got {pressure_pa}, {temperature_c}")
    variant = p.Variant(variant)
    reference_d1 = p.ADC_MAX // 2

    def temp_of(d2: int) -> int:
        return p.compensate(reference_d1, d2, calibration, variant, apply_second_order).compensation.temp

    d2 = _closest_monotonic(temp_of, Fraction(temperature_c) * 100, 0, p.ADC_MAX, hint and hint[1],
                            (lambda d: p.unrounded_temp(d, calibration, variant)) if apply_second_order else None)
    target_p = pressure_pa * p.pressure_counts_per_pa(variant)

    def p_of(d1: int) -> int:
        return p.compensate(d1, d2, calibration, variant, apply_second_order).compensation.p

    if p_of(p.ADC_MAX) >= p_of(0):
        d1 = _closest_monotonic(p_of, target_p, 0, p.ADC_MAX, hint and hint[0])
    else:  # non-physical calibration (SENS <= 0): pick the closer end
        d1 = min((0, p.ADC_MAX), key=lambda x: abs(p_of(x) - target_p))
    return d1, d2


class Ms5837Emulator:
    """Command-exact MS5837 device emulator (see module docstring).

    Args:
        truth: ``t_s -> (pressure_pa, temperature_c)``, evaluated at conversion start.
        clock: monotonic clock in seconds (inject the simulator's or a test's clock).
        variant: ``Variant`` (or "30BA"/"02BA") used for the inversion.
        coefficients: C1..C6; default: the datasheet example of the variant (docs/devices.md §3.7).
        word0: PROM word 0 bits 11:0 (product code and factory bits); default: 30BA26 product
            code for 30BA, 0 for 02BA (docs/devices.md §3.3 vectors).
        apply_second_order: invert with the second-order model.
        conversion_time_s: optional override {osr: seconds}.

    Fault injection attributes (thread-safe to set at any time):
        ``stuck``: conversions return the previous D1/D2 instead of the truth.
        ``corrupt_prom_crc``: PROM word 0 is read with a wrong CRC nibble.
        ``blank_prom``: every PROM word reads 0 (whose CRC-4 is 0: it passes the CRC check).
        ``raw_override``: (D1, D2) counts every conversion returns instead of the truth's, or None.

    Counter: ``zero_reads`` (ADC reads that returned 0)."""

    address = p.ADDRESS

    def __init__(self, truth: TruthSource, clock: Callable[[], float] = time.monotonic,
                 variant: p.Variant | str = p.Variant.MS5837_30BA, coefficients: Sequence[int] | None = None,
                 word0: int | None = None, apply_second_order: bool = True,
                 conversion_time_s: dict[int, float] | None = None) -> None:
        self._lock = threading.RLock()
        self.truth = truth
        self.clock = clock
        parsed = p.parse_variant(variant)
        if parsed is None:
            raise p.Ms5837Error("the emulator needs an explicit variant ('30BA' or '02BA')")
        self.variant = parsed
        if coefficients is None:
            coefficients = (p.EXAMPLE_COEFFICIENTS_30BA if self.variant is p.Variant.MS5837_30BA
                            else p.EXAMPLE_COEFFICIENTS_02BA)
        if word0 is None:
            word0 = p.EXAMPLE_WORD0_30BA if self.variant is p.Variant.MS5837_30BA else p.EXAMPLE_WORD0_02BA
        self.calibration = p.Calibration.from_coefficients(coefficients, word0)
        self.apply_second_order = apply_second_order
        self.conversion_time_s = dict(p.CONVERSION_TIME_S if conversion_time_s is None else conversion_time_s)
        self.stuck = False
        self.corrupt_prom_crc = False
        self.blank_prom = False
        self.raw_override: tuple[int, int] | None = None
        self.needs_reset = False
        self.resets = 0
        self.zero_reads = 0
        self._last_raw = {"convert_d1": 0, "convert_d2": 0}
        self._raw_hint: tuple[int, int] | None = None  # the last inversion, where the next one starts
        self._reset_state()

    # ------------------------------------------------------------------ state
    def _reset_state(self) -> None:
        self._conversion: dict | None = None  # {"kind", "value", "done_t", "corrupt"}
        self._result: int | None = None       # completed, not yet read
        self._output = b""                    # bytes for the next read transaction

    def _settle(self, now: float) -> None:
        """Move a finished conversion into the result register."""
        conv = self._conversion
        if conv is not None and now >= conv["done_t"]:
            self._result = 0 if conv["corrupt"] else conv["value"]
            self._conversion = None

    @property
    def prom_words(self) -> tuple[int, ...]:
        """PROM as read over the bus (with the CRC fault applied if enabled)."""
        words = list(self.calibration.words)
        if self.blank_prom:
            return (0,) * 8
        if self.corrupt_prom_crc:
            words[0] = (((words[0] >> 12) + 1) & 0xF) << 12 | (words[0] & 0x0FFF)
        return tuple(words)

    def power_cycle(self) -> None:
        """Fault: the part lost power (e.g. during an I2C outage): conversions give 0 until a reset command."""
        with self._lock:
            self._reset_state()
            self.needs_reset = True

    def raw_for_truth(self, t_s: float) -> tuple[int, int]:
        """(D1, D2) the device produces for the truth at ``t_s`` (no faults applied)."""
        pressure_pa, temperature_c = self.truth(t_s)
        self._raw_hint = invert_to_raw(float(pressure_pa), float(temperature_c), self.calibration, self.variant,
                                       self.apply_second_order, self._raw_hint)
        return self._raw_hint

    # ------------------------------------------------------------------ I2CDeviceEmulator
    def i2c_write(self, data: bytes) -> None:
        """One write transaction: a command byte (docs/devices.md §3.1). Extra bytes are ignored."""
        with self._lock:
            now = float(self.clock())
            self._settle(now)
            if not data:
                return
            try:
                cmd = p.decode_command(data[0])
            except p.Ms5837Error:
                self._output = b""
                return
            if cmd.kind == "reset":
                self._reset_state()
                self.needs_reset = False
                self.resets += 1
            elif cmd.kind == "prom_read":
                self._output = p.encode_prom_word(self.prom_words[cmd.index])
            elif cmd.kind == "adc_read":
                if self._conversion is not None:  # read during conversion: 0, and corrupt it
                    self._conversion["corrupt"] = True
                    value = 0
                else:
                    value = self._result or 0
                    self._result = None  # read twice -> 0
                if value == 0:
                    self.zero_reads += 1
                self._output = p.encode_adc(value)
            else:  # convert_d1 / convert_d2
                corrupt = self._conversion is not None  # new conversion during one: bad result
                if self.needs_reset:
                    value = 0
                elif self.raw_override is not None:
                    value = self.raw_override[0 if cmd.kind == "convert_d1" else 1]
                elif self.stuck:
                    value = self._last_raw[cmd.kind]
                else:
                    d1, d2 = self.raw_for_truth(now)
                    value = d1 if cmd.kind == "convert_d1" else d2
                    self._last_raw = {"convert_d1": d1, "convert_d2": d2}
                self._result = None
                self._conversion = {"kind": cmd.kind, "value": value, "corrupt": corrupt,
                                    "done_t": now + self.conversion_time_s[cmd.osr]}
                self._output = b""

    def i2c_read(self, n: int) -> bytes:
        """One read transaction: the pending PROM word / ADC bytes, then zeros."""
        with self._lock:
            self._settle(float(self.clock()))
            out = (self._output + bytes(max(0, n - len(self._output))))[:n]
            self._output = self._output[n:]
            return out


def from_config(config, truth: TruthSource, clock: Callable[[], float], seed: int = 0) -> Ms5837Emulator:
    """The configured MS5837 variant ("auto": 30BA) on ``truth`` and ``clock`` (s) (devices.py factory)."""
    variant = config.sensors.ms5837.variant
    return Ms5837Emulator(truth, clock, variant="30BA" if variant == "auto" else variant)
