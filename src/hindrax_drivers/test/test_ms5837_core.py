"""The MS5837 driver's pure core: plausibility verdicts, zero depth, ADC and PROM checks, variances (no ROS).
Expected figures are hand arithmetic from the datasheet's units (docs/devices.md §3)."""
from __future__ import annotations

import pytest

from hindrax_drivers.ms5837 import protocol as p
from hindrax_drivers.ms5837.core import (UNKNOWN_VARIANCE, DepthGate, Plausibility, ZeroDepth, adc_problem,
                                         check_prom, depth_covariance, diagnostic_values, pressure_variance_pa2,
                                         stamp_offset_s, temperature_warning)

RHO_G = 1000.0 * 9.81  # Pa per m of fresh water
GOOD_WORDS = [0x9340, *p.EXAMPLE_COEFFICIENTS_30BA]  # word 0 with CRC nibble 9 (test_ms5837_protocol)


@pytest.mark.parametrize("data,expected", [
    (b"\x00\x00\x00", "adc_zero"),  # no completed conversion
    (b"\xff\xff\xff", "adc_saturated"),  # a bus held high
    (b"\x4e\x20\x00", ""),  # 5120000 counts: a reading
    (b"\xff\xff\xfe", ""),  # one count below saturation
])
def test_adc_words(data, expected):
    kind, text = adc_problem(data)
    assert kind == expected and bool(text) == bool(expected)


@pytest.mark.parametrize("words,blank,configured,expected", [
    (GOOD_WORDS, True, None, p.Variant.MS5837_30BA),  # C1 34982: the 30BA by the heuristic
    (GOOD_WORDS, True, p.Variant.MS5837_02BA, p.Variant.MS5837_02BA),  # configured wins
    ([0x8340, *p.EXAMPLE_COEFFICIENTS_30BA], True, None, "CRC"),
    ([0] * 8, True, p.Variant.MS5837_30BA, "C1"),  # blank PROM: CRC-4 0 passes, the sanity check does not
    ([0] * 8, False, p.Variant.MS5837_30BA, p.Variant.MS5837_30BA),  # sanity check off: taken as it stands
])
def test_prom_check(words, blank, configured, expected):
    if isinstance(expected, str):
        with pytest.raises(p.Ms5837Error, match=expected):
            check_prom(words, blank, configured)
    else:
        assert check_prom(words, blank, configured)[1] is expected


def test_variances_stamp_and_covariance():
    assert pressure_variance_pa2(p.Variant.MS5837_30BA) == pytest.approx(25.0 ** 2 + 10.0 ** 2 / 12)  # 633.33 Pa^2
    assert pressure_variance_pa2(p.Variant.MS5837_02BA) == pytest.approx(1.0 + 1.0 / 12)
    assert stamp_offset_s(4096) == pytest.approx(0.0045) and stamp_offset_s(8192) == pytest.approx(0.0085)
    cov = depth_covariance(981.0 ** 2, 981.0)  # 1 m^2 of depth variance
    assert cov[14] == pytest.approx(1.0) and [cov[i] for i in (0, 7, 21, 28, 35)] == [UNKNOWN_VARIANCE] * 5
    assert sum(cov) == pytest.approx(1.0 + 5 * UNKNOWN_VARIANCE)


def test_temperature_warning_and_diagnostics():
    hot = p.Reading(pressure_pa=101325.0, temperature_c=90.0, compensation=None, temperature_in_range=False)
    assert "90.00 degC outside -40..85 degC" in temperature_warning(hot)
    assert temperature_warning(p.Reading(101325.0, 20.0, None, True)) == ""
    cal = p.Calibration.from_words(GOOD_WORDS)
    values = dict(diagnostic_values(p.Variant.MS5837_30BA, None, 4096, 0.0095, 101325.0, 7, 2, cal))
    assert values == {"variant": "30BA", "variant_configured": "auto", "oversampling": 4096,
                      "conversion_wait_s": "0.0095", "surface_pressure_pa": "101325.0", "cycles": 7,
                      "startup_attempts": 2, "prom_c1_c6": "34982 36352 20328 22354 26646 26146"}


# (t s, pressure Pa, depth m) -> (publish, counter, first, clear); window 80-130 kPa, depth -0.5..3 m, 1 m/s
PLAUSIBILITY = [
    ("in range, first depth is the baseline", [(0.0, 110000.0, 0.88)], [(True, "", False, False)]),
    ("pressure below the window, then above: first only once",
     [(0.0, 70000.0, -3.2), (0.1, 140000.0, 3.9)],
     [(False, "implausible_pressure", True, False), (False, "implausible_pressure", False, False)]),
    ("depth beyond max_depth_m", [(0.0, 129000.0, 3.2)], [(False, "implausible_depth", False, False)]),
    ("a 1 m jump in 0.1 s held, confirmed by the next sample",
     [(0.0, 110000.0, 0.9), (0.1, 120000.0, 1.9), (0.2, 120000.0, 1.9)],
     [(True, "", False, False), (False, "implausible_depth", False, False), (True, "", False, False)]),
    ("a jump not confirmed (garbage) stays rejected",
     [(0.0, 110000.0, 0.9), (0.1, 120000.0, 1.9), (0.2, 125000.0, 2.5)],
     [(True, "", False, False), (False, "implausible_depth", False, False),
      (False, "implausible_depth", False, False)]),
    ("the ERROR is held 2 s after the last rejection, then cleared once",
     [(0.0, 70000.0, 0.0), (1.0, 110000.0, 0.9), (2.5, 110000.0, 0.9), (2.6, 110000.0, 0.9)],
     [(False, "implausible_pressure", True, False), (True, "", False, False), (True, "", False, True),
      (True, "", False, False)]),
]


@pytest.mark.parametrize("name,readings,expected", PLAUSIBILITY, ids=[row[0] for row in PLAUSIBILITY])
def test_plausibility_table(name, readings, expected):
    check = Plausibility(80000.0, 130000.0, DepthGate(-0.5, 3.0, 1.0, max_age_s=5.0))
    got = []
    for t_s, pa, depth_m in readings:
        v = check.check(t_s, pa, depth_m, "D1 = 1, D2 = 2")
        got.append((v.publish, v.counter, v.first, v.clear))
        assert v.publish or ("D1 = 1, D2 = 2" in v.error and "not published" in v.error)
    assert got == expected


def test_a_failed_cycle_breaks_the_confirmation():
    check = Plausibility(80000.0, 130000.0, DepthGate(-0.5, 3.0, 1.0, max_age_s=5.0))
    check.check(0.0, 110000.0, 0.9)
    assert not check.check(0.1, 120000.0, 1.9).publish
    check.invalid()  # a cycle without a reading between the jump and its confirmation
    assert not check.check(0.2, 120000.0, 1.9).publish


# (refusal, window readings Pa) -> (new surface Pa or None, message part); reference 101325 Pa, margin 5000 Pa
ZERO = [
    ("", [], None, "no pressure reading yet"),
    ("refused while the ESC is armed (esc/output_state)", [101725.0], None, "armed"),
    ("", [101325.0 + 14715.0], None, "+14715.0 Pa (+1.50 m of water)"),  # 1.5 m down: 1.5 * 9810
    ("", [101325.0 + 5001.0], None, "zero_depth_margin_pa 5000"),
    ("", [101700.0, 101750.0, 101800.0], 101750.0, ""),  # 4 cm of weather: the mean is taken
]


@pytest.mark.parametrize("refusal,readings,surface,message", ZERO)
def test_zero_depth_table(refusal, readings, surface, message):
    zero = ZeroDepth(101325.0, 5000.0, RHO_G)
    for i, pa in enumerate(readings):
        zero.add(0.1 * i, pa)
    got, text = zero.decide(refusal)
    assert got == (pytest.approx(surface) if surface is not None else None)
    assert message in text and (surface is None) == bool(text)
    assert surface is not None or "surface pressure unchanged" in text


def test_zero_depth_window_keeps_the_last_second():
    zero = ZeroDepth(101325.0, 5000.0, RHO_G)
    zero.add(0.0, 90000.0)  # older than 1 s when the last arrives: dropped
    for t_s in (0.5, 1.0, 1.5):
        zero.add(t_s, 101400.0)
    assert len(zero.recent) == 3 and zero.decide("") == (pytest.approx(101400.0), "")
