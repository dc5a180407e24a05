"""Tests of hindrax_common.base.thrust_curve ([Hindrax-Drag] eq. 1 / Table 2, docs/devices.md 5.2-5.3).

Expected values are computed here directly from the printed coefficients (plain Horner evaluation),
from numpy.roots as an independent inverse, or taken from the reference tables.
"""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hindrax_common.base.thrust_curve import (
                                               HINDRAX_DRAG_NEGATIVE_COEFFS,
                                               HINDRAX_DRAG_POSITIVE_COEFFS_AS_PRINTED,
                                               ThrustCurve,
                                               ThrustCurveError,
                                               hindrax_default_curve,
                                               point_reflection,
                                               voltage_thrust_scale,
                                               )

# [Hindrax-Drag] Table 2, typed in again here (not imported) so that a typo in the module is caught.
C4, C3, C2, C1 = -4.61e-7, 0.001794, -2.2726, 927.1827
P4, P3, P2, P1 = -3.52e-7, 1.82e-4, -0.3106, 174.3542


def f_neg(p):
    """[Hindrax-Drag] eq. 1 with the Table 2 negative row."""
    p = np.asarray(p, dtype=float)
    return ((C4 * p + C3) * p + C2) * p + C1


def df_neg(p, h=1e-3):
    """Central-difference derivative of f_neg (N/us)."""
    return (f_neg(p + h) - f_neg(p - h)) / (2 * h)


def f_pos_reflected(p):
    """Project default positive curve: point reflection about (1500 us, 0 N), docs/architecture.md §4."""
    return -f_neg(3000.0 - np.asarray(p, dtype=float))


# ---------------------------------------------------------------- facts about [Hindrax-Drag]'s coefficients
def test_seed_negative_row_values_at_ends():
    # docs/architecture.md §4: about -15.6 N at 1100 us and -1.1 N at 1500 us (computed: -15.53 N, -1.09 N).
    assert f_neg(1100.0) == pytest.approx(-15.5283, abs=1e-4)
    assert f_neg(1500.0) == pytest.approx(-1.0923, abs=1e-4)
    assert HINDRAX_DRAG_NEGATIVE_COEFFS == (C4, C3, C2, C1)
    curve = hindrax_default_curve()
    assert curve.max_reverse_n == pytest.approx(float(f_neg(1100.0)), abs=1e-9)
    assert curve.max_forward_n == pytest.approx(-float(f_neg(1100.0)), abs=1e-9)


def test_seed_negative_row_is_not_monotone_up_to_neutral():
    grid = np.arange(1100.0, 1500.01, 0.25)
    slope = df_neg(grid)
    # increasing (slope > 0) from 1100 to about 1495.8 us, decreasing after it
    assert np.all(slope[grid <= 1495.5] > 0.0)
    assert np.all(slope[grid >= 1496.0] < 0.0)
    assert slope[0] == pytest.approx(7.7e-4, rel=0.01)  # nearly flat at full reverse
    # so the deadband-free branch ends at the extremum, between 1495.5 and 1496.0 us
    curve = hindrax_default_curve(deadband_us=0.0)
    low, high = curve.reverse_branch_us
    assert low == 1100.0 and 1495.5 < high < 1496.0
    assert curve.smallest_reverse_n == pytest.approx(float(f_neg(high)), abs=1e-9)
    assert curve.smallest_reverse_n == pytest.approx(-1.0873, abs=1e-4)
    assert curve.forward_branch_us[0] == pytest.approx(3000.0 - high, abs=1e-9)


def test_seed_positive_row_as_printed_is_inconsistent_and_rejected():
    def f_printed(p):
        return ((P4 * p + P3) * p + P2) * p + P1

    assert f_printed(1500.0) == pytest.approx(-1070.05, abs=0.01)
    assert f_printed(1900.0) < -2000.0
    assert HINDRAX_DRAG_POSITIVE_COEFFS_AS_PRINTED == (P4, P3, P2, P1)
    with pytest.raises(ThrustCurveError, match="positive"):
        ThrustCurve(HINDRAX_DRAG_NEGATIVE_COEFFS, HINDRAX_DRAG_POSITIVE_COEFFS_AS_PRINTED)


def test_point_reflection_matches_definition_and_is_an_involution():
    g = point_reflection((C4, C3, C2, C1), neutral_us=1500.0)
    grid = np.linspace(1100.0, 1900.0, 81)
    np.testing.assert_allclose(np.polyval(g, grid), f_pos_reflected(grid), atol=1e-8)
    assert np.polyval(g, 1900.0) == pytest.approx(15.5283, abs=1e-4)
    np.testing.assert_allclose(point_reflection(g, 1500.0), (C4, C3, C2, C1), rtol=1e-9, atol=1e-9)
    # about another centre: g(P) = -f(2 n - P)
    g2 = point_reflection((C4, C3, C2, C1), neutral_us=1520.0)
    np.testing.assert_allclose(np.polyval(g2, grid), -f_neg(3040.0 - grid), atol=1e-8)


def test_point_reflection_rejects_bad_input():
    for bad in [(1.0, 2.0, 3.0), (1.0, 2.0, math.nan, 4.0), "abcd"]:
        with pytest.raises(ThrustCurveError):
            point_reflection(bad)
    with pytest.raises(ThrustCurveError):
        point_reflection((C4, C3, C2, C1), neutral_us=math.inf)


# ---------------------------------------------------------------- forward model
def test_forward_zero_in_deadband_and_cubic_outside():
    curve = hindrax_default_curve()  # deadband 25 us, docs/devices.md §5.2
    inside = np.arange(1475.5, 1525.0, 0.5)
    np.testing.assert_array_equal(curve.thrust_n(inside), 0.0)
    below = np.arange(1100.0, 1475.01, 0.5)
    above = np.arange(1525.0, 1900.01, 0.5)
    np.testing.assert_allclose(curve.thrust_n(below), f_neg(below), atol=1e-9)
    np.testing.assert_allclose(curve.thrust_n(above), f_pos_reflected(above), atol=1e-9)
    # edges of the deadband belong to the cubic: the ESC deadband is 1475-1525 exclusive
    assert curve.thrust_n(1475.0) == pytest.approx(float(f_neg(1475.0)), abs=1e-9)
    assert curve.thrust_n(1475.0) == pytest.approx(-1.2017, abs=1e-4)


def test_forward_neutral_is_zero_without_deadband_and_cubic_next_to_it():
    curve = hindrax_default_curve(deadband_us=0.0)
    assert curve.thrust_n(1500.0) == 0.0
    # next to neutral [Hindrax-Drag]'s cubic does not go to zero: about -1.09 N
    assert curve.thrust_n(1499.0) == pytest.approx(float(f_neg(1499.0)), abs=1e-9)
    assert curve.thrust_n(1501.0) == pytest.approx(float(f_pos_reflected(1501.0)), abs=1e-9)


def test_forward_clamps_pulse_range_and_keeps_shapes():
    curve = hindrax_default_curve()
    assert curve.thrust_n(900.0) == curve.thrust_n(1100.0)
    assert curve.thrust_n(2500.0) == curve.thrust_n(1900.0)
    assert isinstance(curve.thrust_n(1700.0), float)
    out = curve.thrust_n(np.full((2, 3), 1700.0))
    assert out.shape == (2, 3)
    np.testing.assert_allclose(out, f_pos_reflected(1700.0))


def test_forward_clips_wrong_sign_of_a_curve_crossing_zero():
    # A straight line through zero at 1460 us on the reverse side (a T200-like zero band, docs/devices.md 5.3):
    # between 1460 and the deadband edge 1475 the cubic is positive; a reversing thruster gives 0 N there.
    line = (0.0, 0.0, 0.04, -0.04 * 1460.0)
    curve = ThrustCurve(line, point_reflection(line))
    assert curve.reverse_branch_us == pytest.approx((1100.0, 1460.0))
    assert curve.smallest_reverse_n == 0.0
    assert curve.thrust_n(1470.0) == 0.0
    assert curve.thrust_n(1400.0) == pytest.approx(0.04 * (1400.0 - 1460.0))
    assert curve.pulse_width_us(-2.4) == pytest.approx(1400.0, abs=0.005)


# ---------------------------------------------------------------- inverse
@pytest.mark.parametrize("deadband_us", [25.0, 0.0, 40.0])
def test_inverse_recovers_pulse_width_on_dense_grid(deadband_us):
    curve = hindrax_default_curve(deadband_us=deadband_us)
    for low, high in (curve.reverse_branch_us, curve.forward_branch_us):
        grid = np.linspace(low, high, 4001)
        thrust = curve.thrust_n(grid)
        back = curve.pulse_width_us(thrust)
        assert np.max(np.abs(back - grid)) < 0.5
        # away from the nearly flat full-throttle ends the inverse is exact to the table cell
        mid = (np.abs(grid - 1100.0) > 5.0) & (np.abs(grid - 1900.0) > 5.0)
        assert np.max(np.abs(back[mid] - grid[mid])) <= 0.0051


def test_inverse_agrees_with_numpy_roots():
    curve = hindrax_default_curve()
    rng = np.random.default_rng(3)
    forces = np.concatenate([rng.uniform(-15.5, -1.21, 40), rng.uniform(1.21, 15.5, 40)])
    pulses = curve.pulse_width_us(forces)
    for force, pulse in zip(forces, pulses):
        if force < 0:
            roots = np.roots([C4, C3, C2, C1 - force])
            lo, hi = 1100.0, 1475.0
        else:
            g = point_reflection((C4, C3, C2, C1))
            roots = np.roots([g[0], g[1], g[2], g[3] - force])
            lo, hi = 1525.0, 1900.0
        real = [r.real for r in roots if abs(r.imag) < 1e-9 and lo <= r.real <= hi]
        assert len(real) == 1
        assert pulse == pytest.approx(real[0], abs=0.01)


def test_inverse_saturates_beyond_curve_ends():
    curve = hindrax_default_curve()
    np.testing.assert_array_equal(curve.pulse_width_us([-100.0, -15.6, 15.6, 1e300]), [1100.0, 1100.0, 1900.0, 1900.0])
    assert curve.pulse_width_us(0.0) == 1500.0
    assert isinstance(curve.pulse_width_us(3.0), float)


def test_inverse_small_forces_nearest_and_neutral_policies():
    smallest = float(-f_neg(1475.0))  # 1.2017 N at the deadband edge
    nearest = hindrax_default_curve(small_force="nearest")
    assert nearest.smallest_forward_n == pytest.approx(smallest, abs=1e-9)
    forces = np.array([-0.99 * smallest, -0.51 * smallest, -0.49 * smallest, 0.3, 0.49 * smallest, 0.51 * smallest])
    np.testing.assert_array_equal(nearest.pulse_width_us(forces), [1475.0, 1475.0, 1500.0, 1500.0, 1500.0, 1525.0])
    neutral = hindrax_default_curve(small_force="neutral")
    np.testing.assert_array_equal(neutral.pulse_width_us(forces), 1500.0)
    # just beyond the smallest force the inverse is on the branch again
    assert neutral.pulse_width_us(-1.01 * smallest) < 1475.0


def test_voltage_scale_multiplies_forward_and_divides_inverse():
    curve = hindrax_default_curve()
    grid = np.linspace(1100.0, 1900.0, 33)
    np.testing.assert_allclose(curve.thrust_n(grid, voltage_scale=0.8), 0.8 * curve.thrust_n(grid))
    forces = np.array([-12.0, -5.0, 4.0, 11.0])
    np.testing.assert_allclose(curve.pulse_width_us(forces, voltage_scale=0.8), curve.pulse_width_us(forces / 0.8))
    assert curve.force_limits_n(0.5) == pytest.approx((0.5 * f_neg(1100.0), -0.5 * f_neg(1100.0)))
    # 12 N is beyond the scaled forward limit 0.5 * 15.53 N: saturates
    assert curve.pulse_width_us(12.0, voltage_scale=0.5) == 1900.0


def test_voltage_thrust_scale_matches_t200_table():
    # docs/devices.md §5.3: full-throttle forward thrust 2.93 kgf at 10 V, 6.72 at 20 V, 3.71 at 12 V, 5.25 at 16 V
    assert voltage_thrust_scale(20.0, nominal_voltage_v=10.0) == pytest.approx(6.72 / 2.93, rel=0.01)
    assert voltage_thrust_scale(16.0, nominal_voltage_v=12.0) == pytest.approx(5.245 / 3.714, rel=0.01)
    assert voltage_thrust_scale(14.8) == 1.0  # nominal Hindrax battery, [Hindrax-Drag] section 2.1
    for bad in (0.0, -1.0, math.nan, math.inf):
        with pytest.raises(ThrustCurveError):
            voltage_thrust_scale(bad)


# ---------------------------------------------------------------- bad input
@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf, [1500.0, math.nan], "x", None])
def test_non_finite_or_garbage_input_raises(bad):
    curve = hindrax_default_curve()
    with pytest.raises(ThrustCurveError):
        curve.thrust_n(bad)
    with pytest.raises(ThrustCurveError):
        curve.pulse_width_us(bad)


@pytest.mark.parametrize("scale", [0.0, -1.0, math.nan, math.inf, "a"])
def test_bad_voltage_scale_raises(scale):
    curve = hindrax_default_curve()
    with pytest.raises(ThrustCurveError):
        curve.thrust_n(1600.0, voltage_scale=scale)
    with pytest.raises(ThrustCurveError):
        curve.pulse_width_us(3.0, voltage_scale=scale)


@pytest.mark.parametrize("kwargs", [
    {"deadband_us": -1.0},
    {"deadband_us": 400.0},
    {"pulse_width_min_us": 1600.0},
    {"pulse_width_max_us": 1400.0},
    {"pulse_width_neutral_us": math.nan},
    {"small_force": "round"},
    {"negative": (1.0, 2.0)},
    {"negative": (0.0, 0.0, 0.0, 5.0)},           # positive thrust on the reverse side
    {"negative": (0.0, 0.0, -0.04, 44.0)},        # decreasing at 1100 us: end is not the largest magnitude
])
def test_invalid_construction_raises(kwargs):
    args = {"negative": (C4, C3, C2, C1), "positive": point_reflection((C4, C3, C2, C1))}
    args.update(kwargs)
    with pytest.raises(ThrustCurveError):
        ThrustCurve(**args)
    assert issubclass(ThrustCurveError, ValueError)


# ---------------------------------------------------------------- properties
@settings(max_examples=200, deadline=None)
@given(st.floats(allow_nan=False, allow_infinity=False), st.floats(0.2, 2.0))
def test_inverse_then_forward_is_nearest_producible_force(force, voltage_scale):
    curve = hindrax_default_curve()
    pulse = curve.pulse_width_us(force, voltage_scale=voltage_scale)
    assert 1100.0 <= pulse <= 1900.0
    actual = curve.thrust_n(pulse, voltage_scale=voltage_scale)
    assert actual * force >= 0.0  # never the wrong direction
    lo, hi = curve.force_limits_n(voltage_scale)
    target = min(max(force, lo), hi)
    smallest = voltage_scale * curve.smallest_forward_n  # symmetric default curve
    if abs(target) >= smallest:
        # on the branch: slope <= 0.055 N/us ([Hindrax-Drag] curve), table cell 0.005 us
        assert actual == pytest.approx(target, abs=voltage_scale * 0.055 * 0.005 + 1e-9)
    else:
        assert abs(actual - target) <= 0.5 * smallest + 1e-9
