"""Tests of hindrax_onboard.estimation.thruster_fit ([Hindrax-Drag] eq. 1, section 2.2.1, Table 2)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hindrax_onboard.estimation.least_squares import EstimationError
from hindrax_onboard.estimation.thruster_fit import (
    fit_cubic,
    fit_thruster_curve,
    point_reflection,
)

# [Hindrax-Drag] Table 2 as printed: (c4, c3, c2, c1) of tau = c4 P^3 + c3 P^2 + c2 P + c1
TABLE2_NEGATIVE = (-4.61e-7, 0.001794, -2.2726, 927.1827)
TABLE2_POSITIVE = (-3.52e-7, 1.82e-4, -0.3106, 174.3542)
# half a unit of the last printed digit of each coefficient
TABLE2_NEGATIVE_HALF_ULP = (0.005e-7, 0.0000005, 0.00005, 0.00005)
TABLE2_POSITIVE_HALF_ULP = (0.005e-7, 0.005e-4, 0.00005, 0.00005)


def rounding_bound(half_ulps, p_us):
    """Max |change of tau(P)| when each coefficient moves by half a printed unit."""
    return sum(h * abs(p_us) ** k for h, k in zip(half_ulps, (3, 2, 1, 0)))


def test_table2_negative_row_is_consistent():
    """docs/architecture.md §4: -15.6 N at 1100 us and about -1.1 N at 1500 us (the coefficients
    are printed to 3-5 significant digits; c4's rounding alone moves tau by 0.67 N at 1100 us)."""
    at_1100 = np.polyval(TABLE2_NEGATIVE, 1100.0)
    at_1500 = np.polyval(TABLE2_NEGATIVE, 1500.0)
    assert abs(at_1100 - (-15.6)) <= rounding_bound(TABLE2_NEGATIVE_HALF_ULP, 1100.0) + 0.05
    assert abs(at_1500 - (-1.1)) <= 0.05
    # hand arithmetic: -613.591 + 2170.740 - 2499.860 + 927.183 = -15.528 N
    assert at_1100 == pytest.approx(-15.528, abs=1e-3)


def test_table2_positive_row_as_printed_is_inconsistent():
    """docs/architecture.md §4: the printed positive row gives about -1070 N at 1500 us, far outside
    what coefficient rounding can explain (bound ~ 1.7 N); hence the point reflection."""
    at_1500 = np.polyval(TABLE2_POSITIVE, 1500.0)
    # hand arithmetic: -1188.000 + 409.500 - 465.900 + 174.354 = -1070.046 N
    assert at_1500 == pytest.approx(-1070.05, abs=0.01)
    assert abs(at_1500) > 100 * rounding_bound(TABLE2_POSITIVE_HALF_ULP, 1500.0)


def test_point_reflection_of_table2_negative_row():
    pos = point_reflection(*TABLE2_NEGATIVE)
    assert np.polyval(pos, 1900.0) == pytest.approx(15.528, abs=1e-3)
    assert np.polyval(pos, 1500.0) == pytest.approx(1.0923, abs=1e-3)
    # a point reflection keeps the cubic coefficient
    assert pos[0] == pytest.approx(TABLE2_NEGATIVE[0], rel=1e-12)


@settings(max_examples=60, deadline=None)
@given(c=st.tuples(*[st.floats(-10.0, 10.0) for _ in range(4)]),
       d=st.floats(-400.0, 400.0), neutral=st.floats(1400.0, 1600.0))
def test_point_reflection_identity(c, d, neutral):
    """f_pos(N + d) = -f_neg(N - d) for any cubic (scaled coefficients keep values O(1))."""
    scale = (1e-6, 1e-4, 1e-2, 1.0)
    neg = tuple(ci * s for ci, s in zip(c, scale))
    pos = point_reflection(*neg, neutral_us=neutral)
    lhs = np.polyval(pos, neutral + d)
    rhs = -np.polyval(neg, neutral - d)
    assert lhs == pytest.approx(rhs, rel=1e-9, abs=1e-6)


def synthetic_bollard(rng, noise_n=0.3, with_neutral=False):
    """Negative rotation = Table 2 negative row; positive = its reflection (docs/architecture.md §4)."""
    neg = TABLE2_NEGATIVE
    pos = point_reflection(*neg)
    P = np.concatenate([np.repeat(np.arange(1100.0, 1500.0, 25.0), 2),
                        np.repeat(np.arange(1525.0, 1901.0, 25.0), 2)])
    tau = np.where(P < 1500, np.polyval(neg, P), np.polyval(pos, P))
    if with_neutral:
        P = np.append(P, [1500.0] * 3)
        tau = np.append(tau, [0.0] * 3)
    return P, tau + rng.normal(0, noise_n, P.size), neg, pos


def test_fit_recovers_known_cubics_within_three_sigma():
    rng = np.random.default_rng(0)
    P, tau, neg, pos = synthetic_bollard(rng)
    fit = fit_thruster_curve(P, tau, include_neutral=False)
    for side, true in (("negative", neg), ("positive", pos)):
        cf = getattr(fit, side)
        for name, value in zip(("c4", "c3", "c2", "c1"), true):
            assert abs(getattr(cf, name) - value) < 3 * getattr(cf, name + "_std"), (side, name)
        assert cf.n == 32
        assert cf.residual_std_n == pytest.approx(0.3, rel=0.35)
        # the fitted thrust is far better determined than the raw coefficients
        grid = np.linspace(cf.pulse_width_min_us, cf.pulse_width_max_us, 9)
        truth = np.polyval(true, grid)
        assert np.all(np.abs(cf.predict(grid) - truth) < 4 * cf.predict_std(grid))
        assert np.all(cf.predict_std(grid) < 0.3)
    d = fit.to_dict()
    assert set(d) == {"negative", "positive", "neutral_us"}
    assert set(d["negative"]) >= {"c4", "c3", "c2", "c1", "c4_std", "c3_std", "c2_std",
                                  "c1_std", "n", "residual_std_n"}


def test_raw_covariance_is_the_exact_transform_of_the_centred_one():
    """Var(tau(P)) from the raw covariance with rows [P^3, P^2, P, 1] equals the centred one;
    raw coefficients evaluated directly equal the centred prediction."""
    rng = np.random.default_rng(1)
    P, tau, _, _ = synthetic_bollard(rng)
    cf = fit_cubic(P[P < 1500], tau[P < 1500])
    grid = np.array([1100.0, 1250.0, 1400.0, 1490.0])
    raw_rows = np.column_stack([grid**3, grid**2, grid, np.ones_like(grid)])
    raw_var = np.einsum("ij,jk,ik->i", raw_rows, cf.covariance, raw_rows)
    np.testing.assert_allclose(np.sqrt(raw_var), cf.predict_std(grid), rtol=1e-5)
    np.testing.assert_allclose(np.polyval(cf.coefficients, grid), cf.predict(grid),
                               atol=1e-6)
    np.testing.assert_allclose(np.sqrt(np.diag(cf.covariance)),
                               [cf.c4_std, cf.c3_std, cf.c2_std, cf.c1_std])


def test_neutral_and_deadband_handling():
    rng = np.random.default_rng(2)
    P, tau, _, _ = synthetic_bollard(rng, with_neutral=True)
    with_n = fit_thruster_curve(P, tau, include_neutral=True)
    without = fit_thruster_curve(P, tau, include_neutral=False)
    assert with_n.negative.n == without.negative.n + 3
    assert with_n.positive.n == without.positive.n + 3
    dead = fit_thruster_curve(P, tau, include_neutral=False, deadband_us=30.0)
    assert dead.negative.n == without.negative.n - 2     # 1475 us x2
    assert dead.positive.n == without.positive.n - 2     # 1525 us x2
    assert with_n.predict(1500.0) == 0.0
    assert with_n.predict(np.array([1100.0, 1900.0])) == pytest.approx([-15.5, 15.5], abs=0.6)


def test_errors():
    with pytest.raises(EstimationError, match="negative direction"):
        fit_thruster_curve([1100.0, 1200.0, 1600.0, 1700.0, 1800.0, 1900.0, 1650.0],
                           [-15.0, -10.0, 3.0, 6.0, 10.0, 15.0, 4.0])
    with pytest.raises(EstimationError, match="distinct"):
        fit_cubic([1100.0, 1100.0, 1200.0, 1200.0, 1300.0], [1.0, 1.0, 2.0, 2.0, 3.0])
    with pytest.raises(EstimationError):
        fit_cubic([1100.0, 1200.0, 1300.0], [1.0, 2.0])
    with pytest.raises(EstimationError):
        fit_cubic([1100.0, 1200.0, 1300.0, 1400.0, np.nan], [1.0, 2.0, 3.0, 4.0, 5.0])


@pytest.mark.parametrize("value", [-4e-07, 1500.0, -1.25e-05, 3.0e-9, 0.0, -2.0, 123456789012.0])
def test_written_curve_coefficients_load_back_as_floats(value):
    """`thruster-fit --write` floats (commands.common.yaml_float, used by every vehicle-file edit): YAML 1.1 reads
    '-4e-07' as a string and '1500' as an int."""
    import yaml

    from hindrax_onboard.commands.common import yaml_float

    loaded = yaml.safe_load("[" + ", ".join(yaml_float(v) for v in (value, value)) + "]")
    assert all(isinstance(x, float) for x in loaded)
    assert loaded[0] == pytest.approx(value, rel=1e-9, abs=0.0)
