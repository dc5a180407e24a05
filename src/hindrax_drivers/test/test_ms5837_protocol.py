"""MS5837-30BA / -02BA protocol and emulator tests. Expected values are from docs/devices.md §3
(datasheet worked examples, CRC-4 vectors, command table) or restate its formulas."""

from __future__ import annotations

import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from hindrax_drivers.ms5837 import protocol as ms
from hindrax_drivers.ms5837.emulator import Ms5837Emulator, invert_to_raw
from hindrax_common.transport.emulated_i2c import EmulatedI2CBus, ManualClock

CAL_30BA = ms.Calibration.from_coefficients(ms.EXAMPLE_COEFFICIENTS_30BA, ms.EXAMPLE_WORD0_30BA)
CAL_02BA = ms.Calibration.from_coefficients(ms.EXAMPLE_COEFFICIENTS_02BA, ms.EXAMPLE_WORD0_02BA)
V30 = ms.Variant.MS5837_30BA
V02 = ms.Variant.MS5837_02BA


# ----------------------------------------------------------------------------- commands (§3.1)
def test_command_bytes():
    assert ms.CMD_RESET == 0x1E and ms.CMD_ADC_READ == 0x00 and ms.ADDRESS == 0x76
    assert [ms.convert_d1_command(o) for o in ms.OSR_VALUES] == [0x40, 0x42, 0x44, 0x46, 0x48, 0x4A]
    assert [ms.convert_d2_command(o) for o in ms.OSR_VALUES] == [0x50, 0x52, 0x54, 0x56, 0x58, 0x5A]
    assert [ms.prom_read_command(k) for k in range(8)] == [0xA0, 0xA2, 0xA4, 0xA6, 0xA8, 0xAA, 0xAC, 0xAE]
    assert ms.OSR_VALUES == (256, 512, 1024, 2048, 4096, 8192)
    # TE library waits 1/2/3/5/9/17 ms (§3.1 [M6]).
    assert [ms.conversion_time_s(o) for o in ms.OSR_VALUES] == [0.001, 0.002, 0.003, 0.005, 0.009, 0.017]
    with pytest.raises(ms.Ms5837Error):
        ms.convert_d1_command(300)
    with pytest.raises(ms.Ms5837Error):
        ms.prom_read_command(8)


def test_decode_command():
    assert ms.decode_command(0x1E).kind == "reset"
    assert ms.decode_command(0x00).kind == "adc_read"
    assert ms.decode_command(0x4A) == ms.Command("convert_d1", osr=8192)
    assert ms.decode_command(0x50) == ms.Command("convert_d2", osr=256)
    assert ms.decode_command(0xAC) == ms.Command("prom_read", index=6)
    for bad in (0x41, 0x4C, 0xA1, 0xB0, 0xFF):
        with pytest.raises(ms.Ms5837Error):
            ms.decode_command(bad)


@given(st.integers(min_value=-1000, max_value=1000))
def test_decode_command_rejects_garbage_with_declared_error(byte):
    try:
        ms.decode_command(byte)
    except ms.Ms5837Error:
        pass


def test_adc_and_prom_byte_order():
    assert ms.parse_adc(b"\x4b\xa7\xe3") == 4958179 == ms.EXAMPLE_D1_30BA
    assert ms.encode_adc(ms.EXAMPLE_D2_30BA) == bytes([0x67, 0xFE, 0xB6])
    assert ms.parse_prom_word(b"\x93\x40") == 0x9340
    with pytest.raises(ms.Ms5837Error, match="no completed conversion"):
        ms.parse_adc(b"\x00\x00\x00")
    for bad in (b"", b"\x01\x02", b"\x01\x02\x03\x04", None, "abc"):
        with pytest.raises(ms.Ms5837Error):
            ms.parse_adc(bad)
    with pytest.raises(ms.Ms5837Error):
        ms.parse_prom_word(b"\x01")


@given(st.binary(max_size=6))
def test_parsers_raise_only_declared_error(data):
    for parser in (ms.parse_adc, ms.parse_prom_word):
        try:
            value = parser(data)
        except ms.Ms5837Error:
            continue
        assert 0 <= value < 2 ** (8 * len(data))


# ----------------------------------------------------------------------------- CRC (§3.3)
def test_crc4_vectors_from_devices_doc():
    assert ms.crc4([0x0340, *ms.EXAMPLE_COEFFICIENTS_30BA]) == 0x9
    assert CAL_30BA.words[0] == 0x9340
    assert ms.crc4([0x0000, *ms.EXAMPLE_COEFFICIENTS_02BA, 0]) == 0x8
    assert CAL_02BA.words[0] == 0x8000
    # The CRC ignores the stored nibble and word 7.
    assert ms.crc4([0xF340, *ms.EXAMPLE_COEFFICIENTS_30BA, 0xBEEF]) == 0x9


def test_calibration_checks_crc_and_decodes_fields():
    cal = ms.Calibration.from_words([0x9340, *ms.EXAMPLE_COEFFICIENTS_30BA])
    assert (cal.c1, cal.c2, cal.c3, cal.c4, cal.c5, cal.c6) == ms.EXAMPLE_COEFFICIENTS_30BA
    assert cal.crc == 0x9 and cal.product_code == ms.PRODUCT_CODE_30BA26 == 0b0011010
    with pytest.raises(ms.Ms5837Error, match="CRC"):
        ms.Calibration.from_words([0x8340, *ms.EXAMPLE_COEFFICIENTS_30BA])
    assert ms.Calibration.from_words([0x8340, *ms.EXAMPLE_COEFFICIENTS_30BA], check_crc=False).c1 == 34982
    for bad in ([1, 2, 3], [0x10000] * 7, None, ["x"] * 7):
        with pytest.raises(ms.Ms5837Error):
            ms.Calibration.from_words(bad)


# ----------------------------------------------------------------------------- worked examples (§3.7)
def test_30ba_datasheet_example_with_documented_off_typo():
    r = ms.first_order(ms.EXAMPLE_D1_30BA, ms.EXAMPLE_D2_30BA, CAL_30BA, V30)
    assert r.dt == -5962
    assert r.temp == 1981          # C truncation would give 1982
    assert r.sens == 1145816755    # C truncation would give 1145816756
    # The datasheet prints OFF = 2381326464, a digit typo (docs/devices.md §3.7); the formula gives:
    assert r.off == 2381323464 and r.off != 2381326464
    assert r.p == 39998            # 3999.8 mbar, as printed
    second = ms.second_order(ms.EXAMPLE_D1_30BA, r, V30)
    assert (second.ti, second.offi, second.sensi) == (0, 541, 225)
    assert (second.temp, second.p) == (1981, 39998)
    reading = ms.compensate(ms.EXAMPLE_D1_30BA, ms.EXAMPLE_D2_30BA, CAL_30BA, V30)
    assert reading.pressure_pa == 399_980.0            # 3999.8 mbar
    assert reading.temperature_c == pytest.approx(19.81)
    assert reading.temperature_in_range


def test_02ba_datasheet_example():
    r = ms.first_order(ms.EXAMPLE_D1_02BA, ms.EXAMPLE_D2_02BA, CAL_02BA, V02)
    assert (r.dt, r.temp, r.sens, r.off, r.p) == (68, 2000, 3039050829, 5764707214, 110002)
    reading = ms.compensate(ms.EXAMPLE_D1_02BA, ms.EXAMPLE_D2_02BA, CAL_02BA, V02)
    assert (reading.compensation.ti, reading.compensation.offi, reading.compensation.sensi) == (0, 0, 0)
    assert reading.pressure_pa == 110_002.0            # 1100.02 mbar
    assert reading.temperature_c == pytest.approx(20.00)


def _d2_for_temp(cal, temp_target):
    """D2 giving first-order TEMP close to temp_target (inverse of TEMP = 2000 + dT*C6/2^23)."""
    return cal.c5 * 256 + round((temp_target - 2000) * 2 ** 23 / cal.c6)


@pytest.mark.parametrize("variant, cal, temp_target", [
    (V30, CAL_30BA, 3500), (V30, CAL_30BA, 500), (V30, CAL_30BA, -2500),
    (V02, CAL_02BA, 500), (V02, CAL_02BA, -2000), (V02, CAL_02BA, 4000),
])
def test_second_order_branches(variant, cal, temp_target):
    d1, d2 = 5_000_000, _d2_for_temp(cal, temp_target)
    first = ms.first_order(d1, d2, cal, variant)
    dt, temp = first.dt, first.temp
    assert abs(temp - temp_target) <= 1
    # Formulas of docs/devices.md §3.5, written out independently.
    if variant is V30 and temp < 2000:
        ti, offi, sensi = 3 * dt ** 2 // 2 ** 33, 3 * (temp - 2000) ** 2 // 2, 5 * (temp - 2000) ** 2 // 2 ** 3
        if temp < -1500:
            offi += 7 * (temp + 1500) ** 2
            sensi += 4 * (temp + 1500) ** 2
    elif variant is V30:
        ti, offi, sensi = 2 * dt ** 2 // 2 ** 37, (temp - 2000) ** 2 // 2 ** 4, 0
    elif temp < 2000:
        ti, offi, sensi = 11 * dt ** 2 // 2 ** 35, 31 * (temp - 2000) ** 2 // 2 ** 3, 63 * (temp - 2000) ** 2 // 2 ** 5
    else:
        ti = offi = sensi = 0
    second = ms.second_order(d1, first, variant)
    assert (second.ti, second.offi, second.sensi) == (ti, offi, sensi)
    assert second.temp == temp - ti
    p_shift = 13 if variant is V30 else 15
    assert second.p == (d1 * (first.sens - sensi) // 2 ** 21 - (first.off - offi)) // 2 ** p_shift
    if temp_target != 4000:  # all branches except 02BA high have non-zero corrections here
        assert offi > 0


def test_variant_detection():
    assert ms.detect_variant(CAL_30BA) is V30      # C1 = 34982
    assert ms.detect_variant(CAL_02BA) is V02      # C1 = 46372
    assert ms.detect_variant(CAL_02BA, "30BA") is V30
    assert ms.detect_variant(CAL_30BA, "ms5837-02ba") is V02
    assert ms.detect_variant(CAL_30BA, "auto") is V30
    for c1, expected in ((26000, V30), (37000, V30), (37001, V02), (49000, V02)):
        cal = ms.Calibration.from_coefficients((c1, 1, 1, 1, 1, 1))
        assert ms.detect_variant(cal) is expected
    for c1 in (25999, 49001):
        with pytest.raises(ms.Ms5837Error, match="configure"):
            ms.detect_variant(ms.Calibration.from_coefficients((c1, 1, 1, 1, 1, 1)))
    with pytest.raises(ms.Ms5837Error):
        ms.detect_variant(CAL_30BA, "05BA")


def test_depth():
    # 10 m of fresh water (997 kg/m^3) above the Blue Robotics surface pressure 101300 Pa.
    p = 101_300.0 + 997.0 * 9.80665 * 10.0
    assert ms.depth_m(p) == pytest.approx(10.0)
    assert ms.depth_m(101_300.0 + 1029.0 * 9.80665 * 3.0, ms.SALT_WATER_DENSITY_KG_M3) == pytest.approx(3.0)
    assert ms.depth_m(100_000.0, surface_pressure_pa=100_000.0) == 0.0
    with pytest.raises(ms.Ms5837Error):
        ms.depth_m(p, fluid_density_kg_m3=0.0)
    with pytest.raises(ms.Ms5837Error):
        ms.depth_m(p, fluid_density_kg_m3=float("nan"))


def test_compensate_rejects_out_of_range_adc():
    for d1, d2 in ((-1, 0), (0, 2 ** 24), (1.5, 0)):
        with pytest.raises(ms.Ms5837Error):
            ms.compensate(d1, d2, CAL_30BA, V30)


coefficient = st.integers(min_value=0, max_value=0xFFFF)
adc = st.integers(min_value=0, max_value=2 ** 24 - 1)


@settings(max_examples=300, deadline=None)
@given(st.tuples(*[coefficient] * 6), st.integers(0, 0x0FFF), adc, adc, st.sampled_from(list(ms.Variant)),
       st.booleans())
def test_compensation_never_raises_for_valid_inputs(coeffs, word0, d1, d2, variant, second):
    cal = ms.Calibration.from_words(ms.prom_with_crc(word0, coeffs))
    reading = ms.compensate(d1, d2, cal, variant, second)
    assert isinstance(reading.pressure_pa, float) and isinstance(reading.temperature_c, float)


def temperature_bound_c(second_order: bool) -> float:
    """Round-trip temperature error bound, degC: half of TEMP's 0.01 degC step plus one D2 step (C6/2^23 of 0.01 degC,
    ~0.004 with margin). With the second-order model TEMP2 = TEMP - Ti (docs/devices.md §3.5) both integers can
    change at the same D2, so TEMP2 may skip a value: up to one whole step away, 0.01 degC."""
    return (0.010 if second_order else 0.005) + 0.004


@settings(max_examples=60, deadline=None)
@given(st.floats(80_000.0, 3_000_000.0), st.floats(-20.0, 60.0), st.booleans())
def test_inversion_round_trip_30ba(pressure_pa, temperature_c, second):
    d1, d2 = invert_to_raw(pressure_pa, temperature_c, CAL_30BA, V30, second)
    reading = ms.compensate(d1, d2, CAL_30BA, V30, second)
    # Half an output LSB (0.1 mbar = 10 Pa -> 5 Pa) plus one ADC step (SENS/2^34 * 10 Pa ~ 0.7 Pa).
    assert abs(reading.pressure_pa - pressure_pa) <= 5.0 + 0.7
    assert abs(reading.temperature_c - temperature_c) <= temperature_bound_c(second)


@settings(max_examples=60, deadline=None)
@given(st.floats(30_000.0, 120_000.0), st.floats(-20.0, 60.0), st.booleans())
def test_inversion_round_trip_02ba(pressure_pa, temperature_c, second):
    d1, d2 = invert_to_raw(pressure_pa, temperature_c, CAL_02BA, V02, second)
    reading = ms.compensate(d1, d2, CAL_02BA, V02, second)
    # Half of 0.01 mbar (0.5 Pa) plus one ADC step (SENS/2^36 Pa ~ 0.05 Pa).
    assert abs(reading.pressure_pa - pressure_pa) <= 0.5 + 0.06
    assert abs(reading.temperature_c - temperature_c) <= temperature_bound_c(second)


def test_inversion_temperature_where_the_second_order_step_skips_a_value():
    """The case a CI run found (02BA, 30 kPa, -17.939453125 degC, second order): TEMP and Ti change at the same D2,
    TEMP2 skips a 0.01 degC value, and the nearest reachable reading is 0.0095 degC away: within the second-order
    bound, beyond the first-order one."""
    d1, d2 = invert_to_raw(30_000.0, -17.939453125, CAL_02BA, V02, True)
    error = abs(ms.compensate(d1, d2, CAL_02BA, V02, True).temperature_c - -17.939453125)
    assert temperature_bound_c(False) < error <= temperature_bound_c(True)


@settings(max_examples=80, deadline=None)
@given(st.floats(80_000.0, 3_000_000.0), st.floats(-20.0, 60.0), st.booleans(),
       st.tuples(st.integers(0, ms.ADC_MAX), st.integers(0, ms.ADC_MAX)))
@example(80_000.0, 58.953125, True, (0, 81))
def test_inversion_from_a_hint_gives_the_same_counts(pressure_pa, temperature_c, second, hint):
    """The emulator starts each inversion at the previous one's counts: any hint, near or far, gives the counts of
    the full bisection. The example (a CI run under 3.12): TEMP2 is 5895 at D2 8078096-8078415 and again at
    8078575-8078736, so a search on the rounded TEMP2 found one or the other by where it started."""
    assert invert_to_raw(pressure_pa, temperature_c, CAL_30BA, V30, second, hint) == \
        invert_to_raw(pressure_pa, temperature_c, CAL_30BA, V30, second)


def test_inversion_saturates_outside_the_adc_range():
    d1, _ = invert_to_raw(1e9, 20.0, CAL_30BA, V30)
    assert d1 == ms.ADC_MAX
    with pytest.raises(ms.Ms5837Error):
        invert_to_raw(float("nan"), 20.0, CAL_30BA, V30)


# ----------------------------------------------------------------------------- emulator (§3.1, §3.8)
class Harness:
    def __init__(self, variant="30BA", truth=None):
        self.clock = ManualClock(10.0)
        self.truth_value = (150_000.0, 12.0)
        self.emu = Ms5837Emulator(truth or (lambda t: self.truth_value), self.clock, variant=variant)
        self.bus = EmulatedI2CBus({0x76: self.emu})

    def adc(self) -> int:
        return int.from_bytes(bytes(self.bus.read_i2c_block_data(0x76, 0x00, 3)), "big")

    def convert(self, command: int, wait_s: float) -> int:
        self.bus.write_byte(0x76, command)
        self.clock.advance(wait_s)
        return self.adc()


def test_emulator_prom_has_valid_crc_and_configured_coefficients():
    h = Harness("02BA")
    words = [int.from_bytes(bytes(h.bus.read_i2c_block_data(0x76, 0xA0 + 2 * k, 2)), "big") for k in range(8)]
    assert words[:7] == [0x8000, *ms.EXAMPLE_COEFFICIENTS_02BA]
    # SMBus read_word_data is little-endian: the driver must swap (docs/devices.md §3.1).
    assert h.bus.read_word_data(0x76, 0xA0) == 0x0080
    h.emu.corrupt_prom_crc = True
    words[0] = int.from_bytes(bytes(h.bus.read_i2c_block_data(0x76, 0xA0, 2)), "big")
    with pytest.raises(ms.Ms5837Error, match="CRC"):
        ms.Calibration.from_words(words)


def test_emulator_adc_read_semantics():
    h = Harness()
    d2_cmd = ms.convert_d2_command(4096)
    assert h.adc() == 0                                      # no conversion done
    assert h.convert(d2_cmd, 0.009) == h.emu.raw_for_truth(h.clock())[1]
    assert h.adc() == 0                                      # read twice
    assert h.convert(d2_cmd, 0.008) == 0                     # too early: 0 ...
    h.clock.advance(0.01)
    assert h.adc() == 0                                      # ... and that conversion is corrupted
    h.bus.write_byte(0x76, d2_cmd)
    h.clock.advance(0.004)
    h.bus.write_byte(0x76, ms.convert_d1_command(256))       # new conversion during one
    h.clock.advance(0.02)
    assert h.adc() == 0
    assert h.convert(ms.convert_d1_command(256), 0.001) == h.emu.raw_for_truth(h.clock())[0]
    h.bus.write_byte(0x76, d2_cmd)
    h.bus.write_byte(0x76, ms.CMD_RESET)                     # reset aborts the conversion
    h.clock.advance(0.02)
    assert h.adc() == 0


def test_emulator_follows_truth_and_stuck_fault():
    h = Harness()
    d1_cmd = ms.convert_d1_command(8192)
    first = h.convert(d1_cmd, 0.017)
    h.truth_value = (250_000.0, 12.0)
    second = h.convert(d1_cmd, 0.017)
    assert second > first
    h.emu.stuck = True
    h.truth_value = (350_000.0, 12.0)
    assert h.convert(d1_cmd, 0.017) == second


def test_emulator_requires_explicit_variant():
    with pytest.raises(ms.Ms5837Error):
        Ms5837Emulator(lambda t: (1e5, 20.0), variant="auto")


@settings(max_examples=300, deadline=None)
@given(st.lists(st.one_of(st.integers(0, 0xFFFF), st.sampled_from([0, 0xFFFF])), min_size=8, max_size=8),
       st.integers(1, 0xFFFFFF), st.integers(1, 0xFFFFFF), st.sampled_from(list(ms.Variant)))
def test_any_prom_and_adc_give_a_declared_error_a_rejection_or_finite_values(words, d1, d2, variant):
    """PROM words as read -> CRC-4 (Ms5837Error only) -> sanity (a coefficient 0x0000/0xFFFF is always named)
    -> compensation of any 24-bit D1/D2: finite pressure and temperature."""
    import math

    try:
        ms.Calibration.from_words(words, check_crc=True)
    except ms.Ms5837Error:
        pass
    cal = ms.Calibration.from_words(words, check_crc=False)
    issue = ms.prom_sanity_issue(cal)
    assert bool(issue) == any(c in (0, 0xFFFF) for c in words[1:7])
    reading = ms.compensate(d1, d2, cal, variant)
    assert math.isfinite(reading.pressure_pa) and math.isfinite(reading.temperature_c)


def test_all_zero_prom_passes_crc4_but_not_the_sanity_check():
    """Issue 19 fault 9: the blank PROM's CRC-4 is 0, equal to its stored nibble."""
    cal = ms.Calibration.from_words([0] * 8, check_crc=True)
    assert "C1" in ms.prom_sanity_issue(cal) and "C6" in ms.prom_sanity_issue(cal)
    assert ms.prom_sanity_issue(ms.Calibration.from_coefficients((34982, 36352, 20328, 22354, 26646, 26146))) == ""
