"""What the gateway lets through (hindrax_bringup.gateway.bounds): campaign goals a pool day can run and setpoints
inside the vehicle file's envelope; everything else refused with one line naming the bound."""
from __future__ import annotations

import math
from types import SimpleNamespace

import pytest

from hindrax_common.config import default_config_path, load_config
from hindrax_bringup.gateway.bounds import RequestBounds, top_speeds_m_s

CFG = load_config(default_config_path())
BOUNDS = RequestBounds.from_config(CFG)


def goal(**fields):
    base = dict(dofs=[], levels_per_dof=0, level_fractions=[], calibrate=[], calibration_only=False)
    return SimpleNamespace(**{**base, **fields})


def setpoint(**fields):
    base = dict(vertical_mode=1, depth_m=1.0, altitude_m=0.0, hold_heading=False, heading_rad=0.0,
                hold_velocity=False, surge_m_s=0.0, sway_m_s=0.0)
    return SimpleNamespace(**{**base, **fields})


@pytest.mark.parametrize("fields", [dict(), dict(dofs=["surge"], levels_per_dof=5), dict(calibrate=["ballast"]),
                                    dict(dofs=["heave", "yaw"], level_fractions=[0.3, 0.6, 0.9])])
def test_pool_day_goals_pass(fields):
    assert BOUNDS.goal_problem(goal(**fields)) == ""


@pytest.mark.parametrize("fields, words", [
    (dict(dofs=["surge"], levels_per_dof=2**32 - 1), "supervisor.max_run_time_s = 1800 s"),
    (dict(levels_per_dof=11), "6 DOFs x 11 levels x 30 s = 1980 s"),
    (dict(dofs=["surge", "surge"]), "each of surge, sway, heave, roll, pitch, yaw at most once"),
    (dict(dofs=["warp"]), "dofs = ['warp']"),
    (dict(dofs=["surge"] * 7), "dofs has 7 entries: allowed at most 6"),
    (dict(level_fractions=[0.5, math.nan]), "level_fractions: allowed each finite in (0, 1]"),
    (dict(level_fractions=[0.5] * 100_000), "supervisor.max_run_time_s"),
    (dict(calibrate=["ballast"] * 9), "calibrate has 9 entries"),
])
def test_goals_beyond_the_pool_day_are_refused_in_one_line(fields, words):
    why = BOUNDS.goal_problem(goal(**fields))
    assert why.startswith("run_identification: ") and words in why and "\n" not in why, why


def test_setpoints_inside_the_envelope_pass():
    top = top_speeds_m_s(CFG)["surge"]
    for sp in (setpoint(depth_m=0.0), setpoint(depth_m=1.3), setpoint(vertical_mode=2, altitude_m=0.9),
               setpoint(vertical_mode=0, hold_velocity=True, surge_m_s=0.9 * top, sway_m_s=-0.1)):
        assert BOUNDS.setpoint_problem(sp) == "", sp


@pytest.mark.parametrize("fields, words", [
    (dict(depth_m=1e30), "depth_m = 1e+30: allowed [0, 1.3] m"),
    (dict(depth_m=1.45), "allowed [0, 1.3] m (limits.max_depth_m and pool.depth_m - pool.margin_m)"),
    (dict(depth_m=-0.5), "allowed [0, 1.3] m"),
    (dict(depth_m=math.inf), "depth_m = inf: allowed a finite number"),
    (dict(vertical_mode=2, altitude_m=0.1), "altitude_m = 0.1: allowed [0.3, 1.8] m"),
    (dict(vertical_mode=7), "vertical_mode = 7"),
    (dict(hold_velocity=True, surge_m_s=50.0), "surge_m_s = 50: allowed |surge_m_s| <="),
    (dict(hold_velocity=True, sway_m_s=-50.0), "sway_m_s = -50: allowed |sway_m_s| <="),
])
def test_setpoints_outside_the_envelope_are_refused_in_one_line(fields, words):
    why = BOUNDS.setpoint_problem(setpoint(**fields))
    assert why.startswith("controller/setpoint: ") and words in why and "\n" not in why, why


def test_the_top_speed_is_where_the_damping_equals_the_capacity():
    from hindrax_bringup.allocation.core import AllocationCore

    low, high = AllocationCore(CFG).wrench_capacity_frd()
    for i, dof in enumerate(("surge", "sway")):
        v = top_speeds_m_s(CFG)[dof]
        h = CFG.dof_hydrodynamics(dof)
        assert h.damping(v) == pytest.approx(min(-low[i], high[i]), rel=1e-9)
        assert 0.2 < v < 3.0  # a small ROV: tenths of a metre to a few metres per second
