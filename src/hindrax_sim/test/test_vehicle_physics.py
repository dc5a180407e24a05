"""The vehicle physics shared below control, identification and the simulator (hindrax_onboard.vehicle).

Expected values are written out by hand: exp(-0.2) = 0.818730753, exp(-0.1) = 0.904837418; M_RB of a 10 kg body with
its CG 0.1 m below the origin (r_g = (0, 0, 0.1) m, FRD) and I_cg = diag(1, 2, 3) kg m^2: the off-diagonal block
m S(r_g) = [[0, -1, 0], [1, 0, 0], [0, 0, 0]] kg m and I_o = I_cg + m (|r_g|^2 I - r_g r_g^T) = diag(1.1, 2.1, 3).
"""
from __future__ import annotations

import numpy as np
import pytest

from hindrax_bringup.allocation.from_config import thrust_curve_from_config
from hindrax_common.config import default_config_path, load_config
from hindrax_common.base.frames import wrap_angle
from hindrax_sim.thrusters import Thrusters
from hindrax_onboard.vehicle.rigid_body import rigid_body_mass_matrix
from hindrax_onboard.vehicle.thrust_lag import ThrustLag


@pytest.mark.parametrize("time_constant_s,dt_s,decay", [(0.1, 0.02, 0.818730753), (0.1, 0.01, 0.904837418),
                                                         (0.0, 0.02, 0.0), (0.25, 0.0, 1.0)])
def test_thrust_lag_decay(time_constant_s, dt_s, decay):
    assert ThrustLag(time_constant_s).decay(dt_s) == pytest.approx(decay, abs=1e-9)


@pytest.mark.parametrize("bad", [-0.1, float("nan"), float("inf")])
def test_thrust_lag_refuses_an_impossible_time_constant(bad):
    with pytest.raises(ValueError, match="time constant"):
        ThrustLag(bad)


def test_thrust_lag_over_ticks_is_the_held_command_step_by_step():
    lag = ThrustLag(0.1)
    commands = np.array([10.0, 10.0, -4.0, 0.0])
    start, middle, end = lag.over_ticks(commands, 0.02, force_start=2.0)
    # by hand: F(j+1) = c_j + (F_j - c_j) exp(-0.2), F_0 = 2
    f, expected_start = 2.0, []
    for c in commands:
        expected_start.append(f)
        f = c + (f - c) * 0.818730753
    assert start == pytest.approx(expected_start, abs=1e-8)
    assert end[:-1] == pytest.approx(expected_start[1:], abs=1e-8)
    assert middle[0] == pytest.approx(10.0 - 8.0 * 0.904837418, abs=1e-8)
    assert list(ThrustLag(0.0).over_ticks(commands, 0.02)[0]) == list(commands)  # no lag: the commands


def test_rigid_body_mass_matrix_moves_the_inertia_to_the_origin():
    m = rigid_body_mass_matrix(10.0, [0.0, 0.0, 0.1], np.diag([1.0, 2.0, 3.0]))
    assert m[:3, :3] == pytest.approx(10.0 * np.eye(3))
    assert m[3:, :3] == pytest.approx(np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]]))
    assert m[:3, 3:] == pytest.approx(-m[3:, :3])
    assert m[3:, 3:] == pytest.approx(np.diag([1.1, 2.1, 3.0]))


@pytest.mark.parametrize("angle,wrapped", [(0.0, 0.0), (3.5, 3.5 - 2 * np.pi), (-3.5, 2 * np.pi - 3.5),
                                           (np.pi, -np.pi), (-np.pi, -np.pi), (7 * np.pi / 2, -np.pi / 2)])
def test_wrap_angle_to_minus_pi_pi(angle, wrapped):
    assert wrap_angle(angle) == pytest.approx(wrapped, abs=1e-12)


def test_the_simulator_uses_the_allocations_thrust_curve():
    cfg = load_config(default_config_path())
    sim_curve = Thrusters(cfg).curve
    curve = thrust_curve_from_config(cfg)
    pw = np.linspace(1100.0, 1900.0, 81)
    assert np.array_equal(sim_curve.thrust_n(pw), curve.thrust_n(pw))
    assert type(sim_curve) is type(curve)
