"""Manoeuvres and campaign safety ([Hindrax-Drag] §4; docs/architecture.md §5): authority from the allocator, ladders,
the pool box, abort on limits with neutral thrust."""
from __future__ import annotations

import math

import numpy as np
import pytest

from hindrax_bringup.allocation.core import AllocationCore
from hindrax_common.config import default_config_path, load_config
from hindrax_sim.campaign import Campaign
from hindrax_fit.fit.campaign_fit import identify_dof
from hindrax_onboard.control.maneuvers import PoolBox, dof_authority, level_ladder

pytestmark = pytest.mark.filterwarnings("error::RuntimeWarning")


@pytest.fixture(scope="module")
def cfg():
    return load_config(default_config_path())


def test_surge_authority_is_four_horizontal_thrusters_at_full_thrust(cfg):
    # T1/T2 push forward and T3/T4 pull in reverse, each along a direction 55 deg off the x axis
    # ([Hindrax-Drag] §4, Fig. 5): X_max = sum |F_i| cos(55 deg), F_i the curve's largest forward/reverse thrust.
    core = AllocationCore(cfg)
    curve = core.allocator.curves[0]
    expected = 2 * (curve.max_forward_n + abs(curve.max_reverse_n)) * math.cos(math.radians(55.0))
    pos, neg = dof_authority(core, "surge")
    assert pos == pytest.approx(expected, rel=0.01)
    assert neg == pytest.approx(expected, rel=0.01)
    # heave: four vertical thrusters in parallel
    pos, neg = dof_authority(core, "heave")
    assert pos == pytest.approx(4 * curve.max_forward_n, rel=0.01)
    assert neg == pytest.approx(4 * abs(curve.max_reverse_n), rel=0.01)


def test_level_ladder_spans_configured_fractions(cfg):
    ladder = level_ladder(cfg, 40.0, 5)
    assert ladder[0] == pytest.approx(40.0 * cfg.identification.level_fraction_min)
    assert ladder[-1] == pytest.approx(40.0 * cfg.identification.level_fraction_max)
    assert np.all(np.diff(ladder) > 0)
    with pytest.raises(ValueError):
        level_ladder(cfg, 40.0, 0)


def test_pool_box_has_margins(cfg):
    box = PoolBox.from_config(cfg)
    m = cfg.pool.margin_m
    assert box.x_min == pytest.approx(m + 0.5 * cfg.vehicle.length_m)
    assert box.x_max == pytest.approx(cfg.pool.length_m - m - 0.5 * cfg.vehicle.length_m)
    assert box.z_max <= cfg.limits.max_depth_m
    assert box.room_m(box.centre, [1.0, 0.0, 0.0]) == pytest.approx(box.x_max - box.centre[0])
    assert box.room_m([box.x_max + 1.0, box.centre[1], box.centre[2]], [1.0, 0.0, 0.0]) == 0.0


def test_translation_and_yaw_runs_stay_inside_the_pool_box(cfg):
    rec = Campaign(cfg, dofs=("sway", "surge", "yaw"), levels=2, seed=3).run()
    assert not rec.aborted, rec.abort_reason
    box = PoolBox.from_config(cfg)
    p = rec.truth_position_ned_m
    m = cfg.pool.margin_m
    half = 0.5 * max(cfg.vehicle.length_m, cfg.vehicle.width_m)
    # the true body origin never entered the margin (dead reckoning error allowance 0.15 m)
    assert p[:, 0].min() >= m + half - 0.15 and p[:, 0].max() <= cfg.pool.length_m - m - half + 0.15
    assert p[:, 1].min() >= m + half - 0.15 and p[:, 1].max() <= cfg.pool.width_m - m - half + 0.15
    dive = rec.t_s > rec.windows["sway"][0]
    assert p[dive, 2].max() <= box.z_max + 0.05 and p[dive, 2].min() >= box.z_min - 0.05
    # both directions were run in surge and sway, and the runs used a good part of the box
    for dof, k in (("surge", 0), ("sway", 1)):
        sl = rec.dof_slice(dof)
        levels = rec.level[sl]
        assert np.nanmax(levels) > 0 > np.nanmin(levels)
    sl = rec.dof_slice("surge")
    assert np.ptp(p[sl, 0]) > 0.6 * (box.x_max - box.x_min)
    # yaw runs turned about a full turn each way
    sl = rec.dof_slice("yaw")
    assert np.ptp(np.unwrap(rec.truth_euler_rad[sl, 2])) > 1.5 * math.pi
    # neutral at the end
    assert np.all(rec.final_pulse_width_us == cfg.thrusters.pulse_width_neutral_us)
    # yaw identification target (issue: 10 %): inertia Iz + added (0.7217 + 0.55) and [Hindrax-Drag] Table 3 k_q
    yaw = identify_dof(rec, "yaw", cfg)
    assert yaw.values["inertia"] == pytest.approx(cfg.inertia_matrix_kg_m2[2, 2] + 0.55, rel=0.10)
    assert yaw.values["quadratic_damping"] == pytest.approx(0.55, rel=0.10)


def test_abort_on_roll_limit_leaves_neutral_thrust():
    # the roll test goes to identification.roll_test_angle_rad (30 deg); a 0.25 rad roll limit must abort it
    cfg = load_config(default_config_path(), overrides={"limits.max_roll_rad": 0.25})
    c = Campaign(cfg, dofs=("roll",), levels=2, seed=1)
    rec = c.run()
    assert rec.aborted
    assert "roll" in rec.abort_reason
    neutral = cfg.thrusters.pulse_width_neutral_us
    assert np.all(c.sim.thrusters.pulse_width_us == neutral)
    assert np.all(c.sim.thrusters.commanded_force_n == 0.0)
    # the thrust decays to zero afterwards (first-order lag): nothing keeps pushing the vehicle
    c.sim.advance(1.0)
    assert np.all(np.abs(c.sim.thrust_n) < 1e-3)
    # the abort happened near the limit (the true roll did not run away)
    assert np.max(np.abs(rec.truth_euler_rad[:, 0])) < 0.25 + 0.15


def test_roll_and_pitch_rotate_to_the_test_angle_return_and_are_identified(cfg):
    rec = Campaign(cfg, dofs=("roll", "pitch"), levels=2, seed=2).run()
    assert not rec.aborted, rec.abort_reason
    for dof, k in (("roll", 0), ("pitch", 1)):
        sl = rec.dof_slice(dof)
        ang = np.abs(rec.truth_euler_rad[sl, k])
        target = cfg.flat[f"identification.{dof}_test_angle_rad"]
        assert ang.max() > 0.7 * target  # it did rotate towards the configured angle ...
        assert ang.max() < target + 0.1  # ... and returned without overshooting much
        assert ang[-1] < 0.05  # back to level at the end
        # identification target (issue: 10 %): inertia I + added inertia, [Hindrax-Drag] Table 3 k_q, and the
        # restoring moment z_g W - z_b B (CB 3 cm above the CG)
        r = identify_dof(rec, dof, cfg)
        i = {"roll": 0, "pitch": 1}[dof]
        h = cfg.dof_hydrodynamics(dof)
        assert r.values["inertia"] == pytest.approx(cfg.inertia_matrix_kg_m2[i, i] + h.added_mass, rel=0.10)
        assert r.values["quadratic_damping"] == pytest.approx(h.quadratic_damping_positive, rel=0.10)
        assert r.values["restoring"] == pytest.approx(0.03 * cfg.buoyancy_n, rel=0.10)
