"""TE MS5837-30BA / MS5837-02BA pressure sensor: pure protocol layer (no I/O, no clocks).

Commands, PROM parsing and CRC-4, first- and second-order compensation, variant detection, unit conversion and depth,
all from docs/devices.md §3 (TE datasheets [M1][M2][M3], Blue Robotics and TE libraries [M4][M5][M6]).

Why our own code instead of Blue Robotics' ``ms5837-python``: that library is not in the local package index, needs I/O
in the same class, and uses float division, which does not reproduce the datasheet's integer examples (docs/devices.md
§0 item 5, §3.7). Here every step uses the datasheet's integer arithmetic with **floor** semantics (Python ``//``, equal
to an arithmetic right shift), which reproduces both worked examples exactly.

Vendor-document issue handled here: the 30BA datasheet example prints OFF = 2381326464, a digit
typo for 2381323464 (docs/devices.md §3.7); we implement the formula, and the tests check the corrected
value together with the printed P = 39998."""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field
from fractions import Fraction
from typing import Sequence

__all__ = ["Ms5837Error", "Variant", "ADDRESS", "CMD_RESET", "CMD_ADC_READ", "CMD_PROM_READ_BASE",
           "CMD_CONVERT_D1_BASE", "CMD_CONVERT_D2_BASE", "OSR_VALUES", "CONVERSION_TIME_S", "RESET_TIME_S", "ADC_MAX",
           "PRODUCT_CODE_30BA26", "EXAMPLE_COEFFICIENTS_30BA", "EXAMPLE_COEFFICIENTS_02BA", "EXAMPLE_WORD0_30BA",
           "EXAMPLE_WORD0_02BA", "EXAMPLE_D1_30BA", "EXAMPLE_D2_30BA", "EXAMPLE_D1_02BA", "EXAMPLE_D2_02BA",
           "GRAVITY_M_S2", "FRESH_WATER_DENSITY_KG_M3", "SALT_WATER_DENSITY_KG_M3", "STANDARD_SURFACE_PRESSURE_PA",
           "TEMPERATURE_MIN_C", "TEMPERATURE_MAX_C", "Command", "parse_variant", "prom_sanity_issue",
           "convert_d1_command", "convert_d2_command", "prom_read_command", "decode_command", "conversion_time_s",
           "parse_adc", "encode_adc", "parse_prom_word", "encode_prom_word", "crc4", "prom_with_crc", "Calibration",
           "detect_variant", "Compensation", "Reading", "first_order", "second_order", "compensate",
           "pressure_pa_from_counts", "pressure_counts_per_pa", "depth_m", "unrounded_temp"]


class Ms5837Error(ValueError):
    """Bad MS5837 input: wrong length, out-of-range value, CRC mismatch, unknown variant/OSR."""


class Variant(enum.Enum):
    """Sensor variant; selects the compensation constants (docs/devices.md §3.4-3.5)."""

    MS5837_30BA = "30BA"
    MS5837_02BA = "02BA"


# ---------------------------------------------------------------------------- bus and commands
#: I2C address, both variants, not configurable (docs/devices.md §3.1).
ADDRESS = 0x76
CMD_RESET = 0x1E
CMD_ADC_READ = 0x00
CMD_PROM_READ_BASE = 0xA0
CMD_CONVERT_D1_BASE = 0x40
CMD_CONVERT_D2_BASE = 0x50
#: Oversampling ratios; command offset = 2 * index (docs/devices.md §3.1).
OSR_VALUES = (256, 512, 1024, 2048, 4096, 8192)
#: Conversion time per OSR in seconds. The datasheet table was not retrieved (docs/devices.md §3.1,
#: §6 item 5); these are TE's own Arduino-library waits [M6] (1/2/3/5/9/17 ms), used both as the
#: emulator's conversion time and as the minimum wait for drivers.
CONVERSION_TIME_S = {256: 0.001, 512: 0.002, 1024: 0.003, 2048: 0.005, 4096: 0.009, 8192: 0.017}
#: Wait after the reset command (both Blue Robotics libraries wait ~10 ms, docs/devices.md §3.1).
RESET_TIME_S = 0.010
#: Largest 24-bit ADC value (docs/devices.md §3.4).
ADC_MAX = (1 << 24) - 1

#: 30BA product code (PROM word 0 bits 11:5, docs/devices.md §3.2), unreliable (§3.9).
PRODUCT_CODE_30BA26 = 0b0011010

#: Datasheet typical coefficients C1..C6 and example ADC values (docs/devices.md §3.7).
EXAMPLE_COEFFICIENTS_30BA = (34982, 36352, 20328, 22354, 26646, 26146)
EXAMPLE_D1_30BA = 4958179
EXAMPLE_D2_30BA = 6815414
EXAMPLE_COEFFICIENTS_02BA = (46372, 43981, 29059, 27842, 31553, 28165)
EXAMPLE_D1_02BA = 6465444
EXAMPLE_D2_02BA = 8077636
#: PROM word 0 without CRC for the examples (docs/devices.md §3.3 test vectors).
EXAMPLE_WORD0_30BA = PRODUCT_CODE_30BA26 << 5  # 0x0340
EXAMPLE_WORD0_02BA = 0x0000

#: Depth constants (docs/devices.md §3.6).
GRAVITY_M_S2 = 9.80665
FRESH_WATER_DENSITY_KG_M3 = 997.0
SALT_WATER_DENSITY_KG_M3 = 1029.0
STANDARD_SURFACE_PRESSURE_PA = 101300.0
#: Specified operating temperature range (docs/devices.md §3.4).
TEMPERATURE_MIN_C = -40.0
TEMPERATURE_MAX_C = 85.0


@dataclass(frozen=True)
class Command:
    """Decoded command byte.

    ``kind`` is one of ``"reset"``, ``"adc_read"``, ``"prom_read"`` (``index`` = word 0..7),
    ``"convert_d1"`` / ``"convert_d2"`` (``osr`` = oversampling ratio)."""

    kind: str
    index: int | None = None
    osr: int | None = None


def _osr_index(osr: int) -> int:
    try:
        return OSR_VALUES.index(int(osr))
    except (ValueError, TypeError):
        raise Ms5837Error(f"OSR must be one of {OSR_VALUES}, got {osr!r}") from None


def convert_d1_command(osr: int) -> int:
    """Command byte starting a pressure (D1) conversion: 0x40 + 2*index(osr) (docs/devices.md §3.1).

    Raises Ms5837Error for an OSR not in :data:`OSR_VALUES`."""
    return CMD_CONVERT_D1_BASE + 2 * _osr_index(osr)


def convert_d2_command(osr: int) -> int:
    """Command byte starting a temperature (D2) conversion: 0x50 + 2*index(osr) (docs/devices.md §3.1)."""
    return CMD_CONVERT_D2_BASE + 2 * _osr_index(osr)


def prom_read_command(index: int) -> int:
    """Command byte reading PROM word ``index`` (0..7): 0xA0 + 2*index (docs/devices.md §3.1)."""
    if not isinstance(index, int) or not 0 <= index <= 7:
        raise Ms5837Error(f"PROM index must be 0..7, got {index!r}")
    return CMD_PROM_READ_BASE + 2 * index


def decode_command(byte: int) -> Command:
    """Decode a command byte (device side; used by the emulator). Source: docs/devices.md §3.1.

    Raises ``Ms5837Error``: the byte is not an MS5837 command."""
    if not isinstance(byte, int) or not 0 <= byte <= 0xFF:
        raise Ms5837Error(f"command must be a byte, got {byte!r}")
    if byte == CMD_RESET:
        return Command("reset")
    if byte == CMD_ADC_READ:
        return Command("adc_read")
    for base, kind in ((CMD_CONVERT_D1_BASE, "convert_d1"), (CMD_CONVERT_D2_BASE, "convert_d2")):
        offset = byte - base
        if 0 <= offset < 2 * len(OSR_VALUES) and offset % 2 == 0:
            return Command(kind, osr=OSR_VALUES[offset // 2])
    offset = byte - CMD_PROM_READ_BASE
    if 0 <= offset <= 14 and offset % 2 == 0:
        return Command("prom_read", index=offset // 2)
    raise Ms5837Error(f"0x{byte:02x} is not an MS5837 command")


def conversion_time_s(osr: int) -> float:
    """Conversion time for ``osr`` in seconds (see :data:`CONVERSION_TIME_S`; docs/devices.md §3.1 [M6])."""
    return CONVERSION_TIME_S[OSR_VALUES[_osr_index(osr)]]


def _as_bytes(data: bytes | Sequence[int], n: int, what: str) -> bytes:
    try:
        raw = bytes(data)
    except (TypeError, ValueError):
        raise Ms5837Error(f"{what}: expected {n} bytes, got {data!r}") from None
    if len(raw) != n:
        raise Ms5837Error(f"{what}: expected {n} bytes, got {len(raw)}")
    return raw


def parse_adc(data: bytes | Sequence[int]) -> int:
    """24-bit ADC result from the 3 bytes read after command 0x00, MSB first (docs/devices.md §3.1).

    A value of 0 means "no completed conversion" (read too early, twice, or corrupted) and raises.

    Raises ``Ms5837Error``: not 3 bytes, or value 0."""
    raw = _as_bytes(data, 3, "ADC read")
    value = int.from_bytes(raw, "big")
    if value == 0:
        raise Ms5837Error("ADC read returned 0: no completed conversion (read too early, read twice, "
                          "or conversion corrupted)")
    return value


def encode_adc(value: int) -> bytes:
    """3 bytes MSB first for a 24-bit ADC value (device side). Raises Ms5837Error if out of range."""
    if not isinstance(value, int) or not 0 <= value <= ADC_MAX:
        raise Ms5837Error(f"ADC value must be 0..{ADC_MAX}, got {value!r}")
    return value.to_bytes(3, "big")


def parse_prom_word(data: bytes | Sequence[int]) -> int:
    """16-bit PROM word from the 2 bytes read after 0xA0+2k, MSB first (docs/devices.md §3.1).

    Note that ``SMBus.read_word_data`` returns the bytes little-endian; use a 2-byte block read."""
    return int.from_bytes(_as_bytes(data, 2, "PROM read"), "big")


def encode_prom_word(word: int) -> bytes:
    """2 bytes MSB first for a PROM word (device side)."""
    if not isinstance(word, int) or not 0 <= word <= 0xFFFF:
        raise Ms5837Error(f"PROM word must be 0..65535, got {word!r}")
    return word.to_bytes(2, "big")


def _prom_words(words: Sequence[int]) -> list[int]:
    try:
        out = [int(w) for w in words]
    except (TypeError, ValueError):
        raise Ms5837Error(f"PROM must be a sequence of ints, got {words!r}") from None
    if len(out) not in (7, 8):
        raise Ms5837Error(f"PROM must have 7 or 8 words, got {len(out)}")
    if any(not 0 <= w <= 0xFFFF for w in out):
        raise Ms5837Error(f"PROM words must be 0..65535, got {out}")
    return out


def crc4(words: Sequence[int]) -> int:
    """CRC-4 of the MS5837 PROM (7-word variant, docs/devices.md §3.3 [M4][M5][M6]).

    Args:
        words: PROM words 0..6 (word 7, if given, is ignored and taken as 0); word 0's CRC nibble
            (bits 15:12) is ignored.

    Returns The 4-bit CRC (0..15), to compare with ``words[0] >> 12``.

    Raises ``Ms5837Error``: wrong number of words or a word outside 0..65535."""
    n = _prom_words(words)[:7] + [0]
    n[0] &= 0x0FFF
    rem = 0
    for cnt in range(16):
        byte = (n[cnt >> 1] >> 8) if cnt % 2 == 0 else (n[cnt >> 1] & 0xFF)
        rem ^= byte
        for _ in range(8):
            rem = ((rem << 1) ^ 0x3000) if rem & 0x8000 else (rem << 1)
            rem &= 0xFFFF
    return (rem >> 12) & 0xF


def prom_with_crc(word0: int, coefficients: Sequence[int]) -> tuple[int, ...]:
    """Build an 8-word PROM image with a valid CRC nibble (device side; docs/devices.md §3.2-3.3).

    Args:
        word0: product/version and factory bits (bits 11:0; bits 15:12 are replaced by the CRC).
        coefficients: C1..C6 (6 ints, 0..65535); word 7 (not covered by the CRC) is 0."""
    coeffs = [int(c) for c in coefficients]
    if len(coeffs) != 6:
        raise Ms5837Error(f"need 6 coefficients C1..C6, got {len(coeffs)}")
    words = _prom_words([word0 & 0x0FFF, *coeffs, 0])
    words[0] = (crc4(words) << 12) | words[0]
    return tuple(words)


class _Coefficient:
    """``Calibration.c<k>``: PROM word k, the coefficient Ck (docs/devices.md §3.2)."""

    def __init__(self, k: int, doc: str) -> None:
        self.k, self.__doc__ = k, f"{doc} (word {k})."

    def __get__(self, cal: "Calibration | None", owner: type) -> int:
        if cal is None:
            return self  # type: ignore[return-value]  # the class attribute (documentation)
        return cal.words[self.k]


@dataclass(frozen=True)
class Calibration:
    """Parsed PROM (docs/devices.md §3.2).

    Attributes:
        words: the 8 PROM words (word 7 may be 0).
    Properties: ``c1``..``c6`` (C1 SENS_T1, C2 OFF_T1, C3 TCS, C4 TCO, C5 T_REF, C6 TEMPSENS),
    ``crc`` (stored nibble), ``product_code`` (bits 11:5 of word 0; bits 4:0 are factory settings)."""

    words: tuple[int, ...]

    @classmethod
    def from_words(cls, words: Sequence[int], check_crc: bool = True) -> "Calibration":
        """Validate and wrap 7 or 8 PROM words.

        Raises ``Ms5837Error``: wrong count/range, or CRC mismatch when ``check_crc``."""
        w = _prom_words(words)
        if len(w) == 7:
            w.append(0)
        if check_crc:
            computed = crc4(w)
            stored = w[0] >> 12
            if computed != stored:
                raise Ms5837Error(f"PROM CRC mismatch: stored 0x{stored:x}, computed 0x{computed:x}")
        return cls(tuple(w))

    @classmethod
    def from_coefficients(cls, coefficients: Sequence[int], word0: int = 0) -> "Calibration":
        """Calibration from C1..C6 with a valid CRC computed over ``word0`` (for tests/emulation)."""
        return cls(prom_with_crc(word0, coefficients))

    c1 = _Coefficient(1, "C1 = SENS_T1, pressure sensitivity")
    c2 = _Coefficient(2, "C2 = OFF_T1, pressure offset")
    c3 = _Coefficient(3, "C3 = TCS, temperature coefficient of sensitivity")
    c4 = _Coefficient(4, "C4 = TCO, temperature coefficient of offset")
    c5 = _Coefficient(5, "C5 = T_REF, reference temperature")
    c6 = _Coefficient(6, "C6 = TEMPSENS, temperature coefficient of the temperature")

    @property
    def crc(self) -> int:
        """Stored CRC-4 nibble (word 0 bits 15:12)."""
        return self.words[0] >> 12

    @property
    def product_code(self) -> int:
        """Product/version code (word 0 bits 11:5; unreliable, §3.9)."""
        return (self.words[0] >> 5) & 0x7F


def prom_sanity_issue(calibration: Calibration) -> str:
    """Why ``calibration`` cannot be a factory-programmed PROM, or "" when it can.

    A blank (all-zero) PROM has CRC-4 0 and passes the check of docs/devices.md §3.3; an unanswered read on a bus held
    high gives 0xFFFF words. Every coefficient C1..C6 of a real part is a non-zero 16-bit value (the datasheet examples:
    34982 ... 26146, docs/devices.md §3.7), so a coefficient of 0x0000 or 0xFFFF rejects the PROM."""
    bad = [f"C{k}" for k, c in enumerate(calibration.words[1:7], start=1) if c in (0, 0xFFFF)]
    if bad:
        return (f"PROM coefficient(s) {', '.join(bad)} read 0x0000 or 0xFFFF (blank or unread PROM; an all-zero "
                "PROM passes CRC-4)")
    return ""


def parse_variant(value: Variant | str | None) -> Variant | None:
    """Variant from configuration: ``Variant``, ``"30BA"``/``"02BA"`` (case-insensitive, optional
    ``"MS5837-"`` prefix), or None/``"auto"`` meaning "detect" (returns None).

    Raises ``Ms5837Error``: any other value."""
    if value is None or isinstance(value, Variant):
        return value
    name = str(value).strip().upper().replace("MS5837-", "").replace("MS5837_", "")
    if name == "AUTO":
        return None
    for variant in Variant:
        if variant.value == name:
            return variant
    raise Ms5837Error(f"unknown MS5837 variant {value!r}; use '30BA', '02BA' or 'auto'")


def detect_variant(calibration: Calibration, configured: Variant | str | None = None) -> Variant:
    """Sensor variant: the configured one if given, else Blue Robotics' C1 heuristic.

    Heuristic (docs/devices.md §3.9 [M5][M9]): C1 < 26000 or C1 > 49000 -> unrecognised;
    C1 > 37000 -> 02BA; otherwise 30BA. The product-code bits are not used (unreliable [M8]).

    Args:
        calibration: parsed PROM.
        configured: ``Variant``, ``"30BA"``/``"02BA"`` (case-insensitive, optional "MS5837-"
            prefix), or None/``"auto"`` for the heuristic.

    Raises ``Ms5837Error``: unknown configured name, or C1 outside the recognised range."""
    variant = parse_variant(configured)
    if variant is not None:
        return variant
    c1 = calibration.c1
    if c1 < 26000 or c1 > 49000:
        raise Ms5837Error(f"cannot detect MS5837 variant: C1 = {c1} outside 26000..49000; configure it")
    return Variant.MS5837_02BA if c1 > 37000 else Variant.MS5837_30BA


@dataclass(frozen=True)
class Compensation:
    """Integer intermediate and output values of one compensation (datasheet names).

    ``dt`` (dT), ``temp`` (TEMP, 0.01 degC), ``off`` (OFF), ``sens`` (SENS), ``p`` (P: 0.1 mbar for
    30BA, 0.01 mbar for 02BA). For second order, ``temp``/``off``/``sens``/``p`` are TEMP2/OFF2/
    SENS2/P2 and ``ti``/``offi``/``sensi`` hold the corrections (all 0 for first order)."""

    dt: int
    temp: int
    off: int
    sens: int
    p: int
    ti: int = 0
    offi: int = 0
    sensi: int = 0


def _check_adc(name: str, value: int) -> int:
    if not isinstance(value, int) or isinstance(value, bool) or not 0 <= value <= ADC_MAX:
        raise Ms5837Error(f"{name} must be a 24-bit int 0..{ADC_MAX}, got {value!r}")
    return value


_SHIFTS = {
    # variant: (OFF C2 shift, OFF C4*dT divisor shift, SENS C1 shift, SENS C3*dT shift, P shift)
    Variant.MS5837_30BA: (16, 7, 15, 8, 13),
    Variant.MS5837_02BA: (17, 6, 16, 7, 15),
}


def _pressure(d1: int, sens: int, off: int, p_shift: int) -> int:
    return (d1 * sens // (1 << 21) - off) // (1 << p_shift)


def first_order(d1: int, d2: int, calibration: Calibration, variant: Variant) -> Compensation:
    """First-order compensation with floor arithmetic (docs/devices.md §3.4, §3.7).

    dT = D2 - C5*2^8; TEMP = 2000 + dT*C6/2^23; OFF/SENS/P per variant table.

    Raises ``Ms5837Error``: D1/D2 not 24-bit ints."""
    _check_adc("D1", d1)
    _check_adc("D2", d2)
    c = calibration
    off_shift, off_dt_shift, sens_shift, sens_dt_shift, p_shift = _SHIFTS[Variant(variant)]
    dt = d2 - c.c5 * 256
    temp = 2000 + dt * c.c6 // (1 << 23)
    off = c.c2 * (1 << off_shift) + c.c4 * dt // (1 << off_dt_shift)
    sens = c.c1 * (1 << sens_shift) + c.c3 * dt // (1 << sens_dt_shift)
    p = _pressure(d1, sens, off, p_shift)
    return Compensation(dt=dt, temp=temp, off=off, sens=sens, p=p)


#: (Ti, OFFi, SENSi) per (variant, TEMP < 2000), each (k, s): k x^2 / 2^s, x = dT for Ti, TEMP - 2000 for the others
#: (docs/devices.md §3.5; the 30BA below -1500 adds to OFFi and SENSi, :func:`_second_order_terms`)
_SECOND_ORDER = {(Variant.MS5837_30BA, True): ((3, 33), (3, 1), (5, 3)),
                 (Variant.MS5837_30BA, False): ((2, 37), (1, 4), (0, 0)),
                 (Variant.MS5837_02BA, True): ((11, 35), (31, 3), (63, 5)),
                 (Variant.MS5837_02BA, False): ((0, 0), (0, 0), (0, 0))}


def _second_order_terms(dt: int, temp: int, variant: Variant) -> tuple[int, int, int]:
    """(Ti, OFFi, SENSi) per docs/devices.md §3.5, floor division as the datasheet's integers."""
    (kt, st), (ko, so), (ks, ss) = _SECOND_ORDER[variant, temp < 2000]
    t2 = (temp - 2000) ** 2
    ti, offi, sensi = kt * dt * dt // (1 << st), ko * t2 // (1 << so), ks * t2 // (1 << ss)
    if variant is Variant.MS5837_30BA and temp < -1500:
        offi += 7 * (temp + 1500) ** 2
        sensi += 4 * (temp + 1500) ** 2
    return ti, offi, sensi


def unrounded_temp(d2: int, calibration: Calibration, variant: Variant, apply_second_order: bool = True) -> Fraction:
    """TEMP (TEMP2 with second order) of ``d2`` without the floors of docs/devices.md §3.4-3.5, 0.01 degC, exact.
    Unlike the rounded TEMP2, which falls back a count where Ti steps up between two steps of TEMP, strictly increasing
    in D2 for C6 >= 4096 (§3.7: 26146, 28165): one D2 per temperature for the emulator's inversion (§3.8)."""
    dt = d2 - calibration.c5 * 256
    temp = 2000 + Fraction(dt * calibration.c6, 1 << 23)
    k, s = _SECOND_ORDER[Variant(variant), temp < 2000][0] if apply_second_order else (0, 0)
    return temp - Fraction(k * dt * dt, 1 << s)


def second_order(d1: int, first: Compensation, variant: Variant) -> Compensation:
    """Apply the second-order correction to a first-order result (docs/devices.md §3.5).

    OFF2 = OFF - OFFi, SENS2 = SENS - SENSi, TEMP2 = TEMP - Ti, P recomputed with the same
    divisors. Raises Ms5837Error if D1 is not 24-bit."""
    _check_adc("D1", d1)
    variant = Variant(variant)
    ti, offi, sensi = _second_order_terms(first.dt, first.temp, variant)
    off2 = first.off - offi
    sens2 = first.sens - sensi
    p2 = _pressure(d1, sens2, off2, _SHIFTS[variant][4])
    return Compensation(dt=first.dt, temp=first.temp - ti, off=off2, sens=sens2, p=p2, ti=ti, offi=offi, sensi=sensi)


def pressure_counts_per_pa(variant: Variant) -> float:
    """Output counts of P per pascal: 30BA P is in 0.1 mbar (10 Pa), 02BA in 0.01 mbar (1 Pa) (§3.4, §3.6)."""
    return 0.1 if Variant(variant) is Variant.MS5837_30BA else 1.0


def pressure_pa_from_counts(p: int, variant: Variant) -> float:
    """Pressure in Pa from the integer P (docs/devices.md §3.4, §3.6)."""
    return float(p) / pressure_counts_per_pa(variant)


@dataclass(frozen=True)
class Reading:
    """One compensated measurement.

    Attributes:
        pressure_pa: absolute pressure, Pa.
        temperature_c: temperature, degC (TEMP/100).
        compensation: integer values it was computed from (second order if applied).
        temperature_in_range: TEMP within the specified -40..85 degC (docs/devices.md §3.4)."""

    pressure_pa: float
    temperature_c: float
    compensation: Compensation = field(repr=False)
    temperature_in_range: bool = True


def compensate(d1: int, d2: int, calibration: Calibration, variant: Variant,
               apply_second_order: bool = True) -> Reading:
    """Pressure (Pa) and temperature (degC) from raw D1/D2 (docs/devices.md §3.4-3.7).

    Never raises for 24-bit D1/D2 and any calibration (Python integers do not overflow); a result
    outside the specified temperature range is flagged, not rejected.

    Raises ``Ms5837Error``: D1/D2 not 24-bit ints, or an unknown variant."""
    try:
        variant = Variant(variant)
    except ValueError:
        raise Ms5837Error(f"unknown variant {variant!r}") from None
    result = first_order(d1, d2, calibration, variant)
    if apply_second_order:
        result = second_order(d1, result, variant)
    temperature_c = result.temp / 100.0
    return Reading(
        pressure_pa=pressure_pa_from_counts(result.p, variant),
        temperature_c=temperature_c,
        compensation=result,
        temperature_in_range=TEMPERATURE_MIN_C <= temperature_c <= TEMPERATURE_MAX_C,
    )


def _check_density_gravity(fluid_density_kg_m3: float, gravity_m_s2: float) -> None:
    if not (math.isfinite(fluid_density_kg_m3) and fluid_density_kg_m3 > 0.0):
        raise Ms5837Error(f"fluid_density_kg_m3 must be finite and > 0, got {fluid_density_kg_m3}")
    if not (math.isfinite(gravity_m_s2) and gravity_m_s2 > 0.0):
        raise Ms5837Error(f"gravity_m_s2 must be finite and > 0, got {gravity_m_s2}")


def depth_m(pressure_pa: float, fluid_density_kg_m3: float = FRESH_WATER_DENSITY_KG_M3,
            surface_pressure_pa: float = STANDARD_SURFACE_PRESSURE_PA, gravity_m_s2: float = GRAVITY_M_S2) -> float:
    """Depth below the surface: (P - P_surface) / (rho * g), in m (positive down; docs/devices.md §3.6).

    Defaults: fresh water 997 kg/m^3, P_surface 101300 Pa, g = 9.80665 m/s^2. Measure the surface
    pressure at the start of a dive and pass it for best accuracy (§3.6).

    Raises ``Ms5837Error``: non-positive or non-finite density/gravity."""
    _check_density_gravity(fluid_density_kg_m3, gravity_m_s2)
    return (pressure_pa - surface_pressure_pa) / (fluid_density_kg_m3 * gravity_m_s2)
