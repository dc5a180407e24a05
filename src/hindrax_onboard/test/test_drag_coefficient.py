"""Tests of hindrax_onboard.estimation.drag_coefficient ([Hindrax-Drag] Table 4, docs/identification.md)."""

import numpy as np
import pytest

from hindrax_onboard.estimation.drag_coefficient import (
    KINEMATIC_VISCOSITY_WATER_M2_S,
    characteristic_length_from_volume,
    drag_coefficient,
    reynolds_number,
    reynolds_range,
)
from hindrax_onboard.estimation.least_squares import EstimationError


def test_characteristic_lengths_of_hindrax_am():
    """[Hindrax-AM] section 4: V^(1/3) = 0.0824 m (model, 0.00056 m^3), 0.2483 m (0.0153 m^3)."""
    assert characteristic_length_from_volume(0.00056) == pytest.approx(0.0824, abs=5e-5)
    assert characteristic_length_from_volume(0.0153) == pytest.approx(0.2483, abs=5e-5)


def test_reynolds_number():
    assert KINEMATIC_VISCOSITY_WATER_M2_S == 1.01e-6
    # 0.5 m/s over 0.2483 m: 0.5 * 0.2483 / 1.01e-6 = 1.229e5
    assert reynolds_number(0.5, 0.2483) == pytest.approx(1.2292e5, rel=1e-4)
    assert reynolds_number(-0.5, 0.2483) == reynolds_number(0.5, 0.2483)
    np.testing.assert_allclose(reynolds_number(np.array([0.1, 0.2]), 1.0, 1e-6), [1e5, 2e5])
    lo, hi = reynolds_range([0.0, 0.2, -0.45, 0.3], 0.2483, min_speed=0.01)
    assert lo == pytest.approx(0.2 * 0.2483 / 1.01e-6)
    assert hi == pytest.approx(0.45 * 0.2483 / 1.01e-6)


def test_drag_coefficient_definition():
    """C_D = 2 k_q / (rho A_p): k_q = 66.48 kg/m on A_p = 0.188 m^2 (0.47 x 0.40 m front
    bounding box) -> 2 * 66.48 / (1000 * 0.188) = 0.7072 (Table 4 prints 2.28 without areas)."""
    cd, sd = drag_coefficient(66.48, 0.188, 1000.0, quadratic_damping_std=10.20)
    assert cd == pytest.approx(0.70723, rel=1e-4)
    assert sd == pytest.approx(2 * 10.20 / 188.0, rel=1e-9)
    # the quadratic drag law it inverts: F = 0.5 rho C_D A v|v| = k_q v|v|
    v = 0.4
    assert 0.5 * 1000.0 * cd * 0.188 * v * v == pytest.approx(66.48 * v * v)


@pytest.mark.parametrize("call", [
    lambda: characteristic_length_from_volume(0.0),
    lambda: reynolds_number(1.0, -1.0),
    lambda: reynolds_number(1.0, 1.0, 0.0),
    lambda: reynolds_range([0.0, 0.0], 1.0, min_speed=0.01),
    lambda: drag_coefficient(66.0, 0.0),
    lambda: drag_coefficient(66.0, 0.1, quadratic_damping_std=-1.0),
])
def test_errors(call):
    with pytest.raises(EstimationError):
        call()
