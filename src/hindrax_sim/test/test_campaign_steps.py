"""The campaign's steps as objects: each step run on its own on the in-process simulator, after the
dive that every plan starts with, through the same sequencer as the whole campaign
(:class:`~hindrax_onboard.identification.online.executive.Executive` with an explicit step list); the plan the sequencer
makes
from its arguments; the virtual pool's operator.

The known-force steps run against the "thrust_asymmetric" truth (forward thrust x0.95, reverse x0.85: the vehicle
file does not know it), so the expected holding forces follow from the truth alone: at rest the true thrust balances
the net buoyancy B = (rho V - m) g (0.7848 N down) plus the known force. Holds are shortened (5 s settling, 12 s
averaging: four 3 s blocks) to keep each test short.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from hindrax_common.config import ConfigError, default_config_path, load_config
from hindrax_fit.fit.calibration import thrust_scales
from hindrax_sim.campaign import Campaign, PoolOperator
from hindrax_onboard.identification.online.executive import THRUST_STEPS, Executive, TickInput, expand_calibration
from hindrax_onboard.control.maneuvers import PoolBox
from hindrax_onboard.identification.online.steps import (Ballast, BroadbandRun, Dive, Float, Inclining, LinePull,
                                                       RotationLadder, Step, TiltDecay, TranslationLadder)
from hindrax_sim.simulator import Simulator
from hindrax_sim.truth import truth_dir

ASYMMETRIC = truth_dir() / "scenarios" / "thrust_asymmetric.yaml"
FWD, REV = 0.95, 0.85                        # the truth file's disturbances.thrust positive / negative
SETTLE_S, WINDOW_S = 5.0, 12.0


@pytest.fixture(scope="module")
def cfg():
    return load_config(default_config_path())


def _run(cfg, steps, seed=2, truth=None):
    sim = Simulator(cfg, seed=seed, truth=None if truth is None else str(truth))
    camp = Campaign(cfg, dofs=[], seed=seed, sim=sim, steps=steps)
    return camp, camp.run()


# ---------------------------------------------------------------------------------------------------------- plan
def test_the_plan_runs_the_reference_steps_in_a_fixed_order_and_thrust_expands(cfg, tmp_path):
    assert expand_calibration(["thrust", "ballast", "inclining"]) == [*THRUST_STEPS, "inclining"]
    with pytest.raises(ValueError, match="unknown calibration step"):
        expand_calibration(["tow"])
    ex = Executive(cfg, ["surge", "heave", "yaw"], tick_s=0.02, calibrate=["line_pull", "thrust", "inclining"],
                   ballast_weight_in_water_n=8.56, line_pull_n=4.905, inclining_load_n_m=(4.28, 0.15))
    assert [s.name for s in ex.steps] == [
        "dive", "inclining roll", "inclining pitch", "ballast", "float", "line pull +x", "line pull +y",
        "line pull -x", "line pull -y", "surge ladder", "heave ladder", "yaw ladder"]
    assert ex.steps[4].force_n == pytest.approx((1000.0 * 0.001 - 0.05) * 9.81)   # the shipped float: 1 l, 50 g
    assert isinstance(ex.steps[9], TranslationLadder) and isinstance(ex.steps[11], RotationLadder)
    assert ex.steps[9].levels == pytest.approx(ex.ladder("surge"))
    # the holds: 15 s settling and 30 s averaging, unless the vehicle file's calibration.hold_* keys say otherwise
    assert {(s.settle_s, s.window_s) for s in ex.steps[1:9]} == {(15.0, 30.0)}
    short = cfg.with_overrides({"calibration.hold_settle_s": 6.0, "calibration.hold_window_s": 12.0})
    assert [(s.settle_s, s.window_s) for s in Executive(short, ["heave"], tick_s=0.02, calibrate=["ballast"],
                                                        ballast_weight_in_water_n=8.56).steps[1:2]] == [(6.0, 12.0)]
    with pytest.raises(ConfigError, match=r"calibration.hold_window_s = 0.5: allowed number in \[1, 600\]"):
        cfg.with_overrides({"calibration.hold_window_s": 0.5})
    bb = Executive(cfg, ["sway"], tick_s=0.02, excitation="prbs", excitation_duration_s=40.0)
    assert isinstance(bb.steps[1], BroadbandRun) and bb.steps[1].duration_s == 40.0
    # a known force the step needs must be given (the float's comes from the vehicle file)
    with pytest.raises(ValueError, match="line_pull_n"):
        Executive(cfg, ["heave"], tick_s=0.02, calibrate=["line_pull_negative"])
    no_float = _without(tmp_path, "calibration", ("float_mass_kg", "float_volume_m3"))
    with pytest.raises(ValueError, match="float_buoyancy_n"):
        Executive(no_float, ["heave"], tick_s=0.02, calibrate=["float"])


def _without(tmp_path, section: str, keys):
    """The shipped vehicle file without the optional keys ``keys`` of ``section``."""
    import yaml

    from hindrax_common.config import ros_parameters_from_yaml

    params = ros_parameters_from_yaml(yaml.safe_load(default_config_path().read_text()))
    for k in keys:
        params[section].pop(k)
    p = tmp_path / "v.yaml"
    p.write_text(yaml.safe_dump({"/**": {"ros__parameters": params}}))
    return load_config(p)


def test_the_pool_operator_applies_what_each_code_asks():
    op = PoolOperator(ballast_weight_n=8.0, line_pull_n=5.0, float_buoyancy_n=9.0)
    yaw90 = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])   # body +x points east (NED +y)
    assert not op.active and op.external_wrench_frd(yaw90) == pytest.approx(np.zeros(6))
    assert op.act("attach_float", yaw90) and op.external_wrench_frd(yaw90) == pytest.approx([0, 0, -9.0, 0, 0, 0])
    op.act("remove_float", yaw90)
    op.act("apply_line_pull_surge_negative", yaw90)        # along body -x = west, fixed in the pool frame
    assert op.line_ned == pytest.approx([0.0, -5.0, 0.0])
    assert op.external_wrench_frd(np.eye(3)) == pytest.approx([0.0, -5.0, 0, 0, 0, 0])   # the vehicle turned back
    op.act("release_line_surge_negative", yaw90)
    op.act("apply_line_pull_sway", yaw90)                  # body +y = south
    assert op.line_ned == pytest.approx([-5.0, 0.0, 0.0])
    assert not op.act("tow_the_vehicle", yaw90)
    steps = [Ballast(8.5), Float(9.3), LinePull("sway", 4.9, -1), Inclining("roll", 4.2, 0.15)]
    op2 = PoolOperator.for_steps(steps)
    assert (op2.ballast_weight_n, op2.float_buoyancy_n, op2.line_pull_n, op2.inclining_load_n_m) == \
        (8.5, 9.3, 4.9, (4.2, 0.15))


# ---------------------------------------------------------------------------------------------------------- dive
def test_dive_reaches_the_altitude_setpoint_and_averages_the_gyro_bias(cfg):
    camp, rec = _run(cfg, [Dive()], seed=3)
    assert not rec.aborted, rec.abort_reason
    ex = camp.executive
    alt_sp = cfg.identification.altitude_setpoint_m
    box = PoolBox.from_config(cfg)
    # pool floor (FRD depth) minus the setpoint, inside the box: the depth held and where the vehicle is
    expected = min(max(cfg.pool.depth_m - 0.5 * cfg.vehicle.height_m - alt_sp, box.z_min), box.z_max)
    assert ex.depth_hold_m == pytest.approx(expected, abs=0.05)
    assert rec.truth_position_ned_m[-1, 2] == pytest.approx(ex.depth_hold_m, abs=0.05)
    # The average of the gyro over the 2 s window is its bias plus the body's mean rate: the holds leave roll and
    # pitch wandering by up to 1.5 mrad/s over 2 s (10 seeds, at 25 and 50 Hz ticks), so the truth's mean rate over
    # the window (its Euler angles' change; small angles) is added. truth/default.yaml: 0.002 rad/s on each sensor
    # axis, mapped to FRD by the IMU's mounting. The remainder is the gyro's white noise averaged over the window's
    # samples (0.003 rad/s at the truth's 100 Hz: 0.21 mrad/s, 1 sigma): 3 sigma allowed. Yaw is not checked (the
    # heading hold may still be settling).
    gyro = camp.sim.sensors.models["icm20948_gyro"]
    bias_frd = gyro.sensor_from_frd.T @ np.full(3, gyro.spec.bias)
    assert np.abs(bias_frd) == pytest.approx([0.002] * 3)
    window = int(round(2.0 / ex.tick_s))
    euler = rec.truth_euler_rad[-window - 1:]
    mean_rate = (euler[-1, :2] - euler[0, :2]) / 2.0
    sigma = gyro.spec.noise_std / math.sqrt(2.0 * gyro.spec.rate_hz)
    assert ex.state.gyro_bias_frd_rad_s[:2] == pytest.approx(bias_frd[:2] + mean_rate, abs=3.0 * sigma)
    assert rec.windows == {} and np.all(rec.active == -1)


# ---------------------------------------------------------------------------------------------------------- ladders
def test_translation_ladder_runs_both_directions_inside_the_box_and_records_its_window(cfg):
    steps = [Dive(), TranslationLadder("surge", [15.0], max_level_s=8.0)]
    _, rec = _run(cfg, steps, seed=3)
    assert not rec.aborted, rec.abort_reason
    assert rec.levels["surge"] == [15.0] and set(rec.windows) == {"surge"}
    runs = sorted(set(rec.run_id[rec.run_id >= 0]))
    assert len(runs) == 2
    signs = [np.sign(rec.level[rec.run_id == r][0]) for r in runs]
    assert sorted(signs) == [-1.0, 1.0]                    # one run each way along the body axis
    for r, sgn in zip(runs, signs):
        sel = rec.run_id == r
        assert np.all(rec.level[sel] == sgn * 15.0) and np.all(rec.active[sel] == 0)
        # the DOF under test gets the level on top of the holds: the mean surge force about the level
        assert np.mean(rec.wrench_cmd_frd[sel, 0]) == pytest.approx(sgn * 15.0, rel=0.25)
    box = PoolBox.from_config(cfg)
    p = rec.truth_position_ned_m
    assert np.all(p[:, 0] >= box.x_min - 0.1) and np.all(p[:, 0] <= box.x_max + 0.1)


def test_heave_ladder_runs_the_vehicle_files_down_up_pairs_per_level(cfg, tmp_path):
    # identification.heave_repeats: down/up pairs at each heave level (3 when the key is absent)
    absent = _without(tmp_path, "identification", ("heave_repeats",))
    assert Executive(absent, ["heave"], tick_s=0.04).steps[-1].heave_repeats == 3
    with pytest.raises(ConfigError, match=r"heave_repeats = 0: allowed integer in \[1, 10\]"):
        cfg.with_overrides({"identification.heave_repeats": 0})
    two = Executive(cfg.with_overrides({"identification.heave_repeats": 2}), ["heave"], levels=1,
                    tick_s=0.04)
    ladder = two.steps[-1]
    assert isinstance(ladder, TranslationLadder) and ladder.heave_repeats == 2
    _, rec = _run(cfg, [Dive(), ladder], seed=3)
    assert not rec.aborted, rec.abort_reason
    runs = sorted(set(rec.run_id[rec.run_id >= 0]))
    signs = [float(np.sign(rec.level[rec.run_id == r][0])) for r in runs]
    assert signs == [1.0, -1.0, 1.0, -1.0]                 # down (+z, NED), up, down, up


def test_rotation_ladder_turns_yaw_once_per_run(cfg):
    steps = [Dive(), RotationLadder("yaw", [1.5], max_level_s=40.0)]
    _, rec = _run(cfg, steps, seed=3)
    assert not rec.aborted, rec.abort_reason
    yaw = np.unwrap(rec.truth_euler_rad[:, 2])
    for r in sorted(set(rec.run_id[rec.run_id >= 0])):
        idx = np.flatnonzero(rec.run_id == r)
        sgn = np.sign(rec.level[idx[0]])
        # the run stops when the predicted stopping angle reaches 2 pi; the vehicle coasts to about there (1 s
        # later; the next run, the other way, starts once it is still)
        t_end = idx[-1] + int(round(1.0 / rec.tick_s))
        turned = sgn * (yaw[min(t_end, yaw.size - 1)] - yaw[idx[0]])
        assert turned == pytest.approx(2.0 * math.pi, abs=0.3), (r, turned)
    assert len(set(np.sign(rec.level[rec.run_id >= 0]))) == 2


def test_broadband_run_is_one_run_shaped_into_the_box(cfg):
    step = BroadbandRun("heave", "multisine", 20.0, 0.6)
    _, rec = _run(cfg, [Dive(), step], seed=3)
    assert not rec.aborted, rec.abort_reason
    assert len(set(rec.run_id[rec.run_id >= 0])) == 1 and set(rec.windows) == {"heave"}
    sel = rec.run_id >= 0
    assert (rec.t_s[sel][-1] - rec.t_s[sel][0]) == pytest.approx(20.0, abs=0.05)
    assert rec.levels["heave"] == [pytest.approx(0.6 * min(rec.authority["heave"]))]
    box = PoolBox.from_config(cfg)
    z = rec.truth_position_ned_m[sel, 2]
    assert np.all(z >= box.z_min - 0.1) and np.all(z <= box.z_max + 0.1)
    assert np.ptp(z) > 0.1                                  # it did move


# ---------------------------------------------------------------------------------------------------------- thrust
@pytest.fixture(scope="module")
def vertical(cfg):
    """Dive, the known sinker, then the known float, against the asymmetric truth."""
    c = cfg.known_forces
    _, rec = _run(cfg, [Dive(), Ballast(c.ballast_weight_in_water_n, SETTLE_S, WINDOW_S),
                        Float(c.float_net_buoyancy_n, SETTLE_S, WINDOW_S)], seed=2, truth=ASYMMETRIC)
    assert not rec.aborted, rec.abort_reason
    return rec


def _net_buoyancy(cfg):
    return (1000.0 * 0.0153 - 15.22) * 9.81                # ros_ws/config/hindrax.yaml: rho V - m, times g


def _close(value, expected, std, floor):
    return abs(value - expected) <= 3.0 * std + floor


def test_the_sinker_is_held_by_reverse_thrust(cfg, vertical):
    e = vertical.calibration["vertical"]
    b, w = _net_buoyancy(cfg), (1.0 - 1000.0 / 7850.0) * 9.81
    assert e["method"] == "ballast" and e["direction"] == "+z" and e["group"] == "vertical"
    assert e["known_force_n"] == pytest.approx(w)
    # without: the hover, B (the vehicle is buoyant; 0.2 N per thruster is inside the ESC deadband, so the deadband
    # allocation may run some thrusters forward and others in reverse): the true forces balance B; with: B - w, by
    # reverse thrust only
    x1, x2 = e["holding_force_n"]
    p1, n1 = e["forward_force_n"][0], e["reverse_force_n"][0]
    assert FWD * p1 + REV * n1 == pytest.approx(b, abs=0.15), (p1, n1)
    assert e["reverse_force_n"][1] == pytest.approx((b - w) / REV, rel=0.03)
    assert abs(e["forward_force_n"][1]) < 0.05
    for h in range(2):
        assert e["forward_force_n"][h] + e["reverse_force_n"][h] == pytest.approx(e["holding_force_n"][h], abs=1e-9)
    # one scale for both directions, w / (X1 - X2): a mix, mostly the reverse scale
    assert e["value"] == pytest.approx(w / (x1 - (b - w) / REV), rel=0.03)


def test_the_float_is_held_by_forward_thrust(cfg, vertical):
    e = vertical.calibration["vertical_negative"]
    b, f = _net_buoyancy(cfg), cfg.known_forces.float_net_buoyancy_n
    assert e["method"] == "float" and e["direction"] == "-z" and e["known_force_n"] == pytest.approx(f)
    assert e["forward_force_n"][1] == pytest.approx((b + f) / FWD, rel=0.03)
    assert abs(e["reverse_force_n"][1]) < 0.05
    assert e["value"] == pytest.approx(FWD, rel=0.04)


def test_sinker_float_and_hovers_give_both_vertical_scales(cfg, vertical):
    sc = thrust_scales(vertical.calibration, cfg)
    assert set(sc) >= {"common_forward", "common_reverse", "net_buoyancy_n"}   # only the vertical group measured
    for name, truth in (("common_forward", FWD), ("common_reverse", REV)):
        assert _close(sc[name]["value"], truth, sc[name]["std"], 0.005), (name, sc[name])
        assert sc[name]["std"] < 0.03
    assert _close(sc["net_buoyancy_n"]["value"], _net_buoyancy(cfg), sc["net_buoyancy_n"]["std"], 0.01)


def test_a_line_pull_sees_two_thrusters_each_way(cfg):
    """The 55-degree layout: a horizontal force is held by two thrusters turning forward and two in reverse with
    equal thrust, in either sense, so a pull measures the mean of the two horizontal scales (0.90 here). The pull
    along -x (line_pull_negative); +x and +y: test_thrust_calibration.py."""
    f = cfg.known_forces.line_pull_force_n
    _, rec = _run(cfg, [Dive(), LinePull("surge", f, -1, 4.0, 9.0)], seed=2, truth=ASYMMETRIC)
    assert not rec.aborted, rec.abort_reason
    for key, sense in (("surge_negative", -1.0),):
        e = rec.calibration[key]
        assert e["method"] == "line_pull" and e["direction"] == ("+x" if sense > 0 else "-x")
        p, n = e["forward_force_n"][1], e["reverse_force_n"][1]
        assert p + n == pytest.approx(-sense * f / (0.5 * (FWD + REV)), rel=0.04)
        assert p == pytest.approx(n, rel=0.05)              # half the holding force from each direction
        assert _close(e["value"], 0.5 * (FWD + REV), e["std"], 0.01), e
    sc = thrust_scales(rec.calibration, cfg)
    mean = sc["common_mean"]
    assert _close(mean["value"], 0.5 * (FWD + REV), mean["std"], 0.005) and mean["std"] < 0.02
    # the difference of the two directions stays with its prior: each scale alone is uncertain
    assert sc["common_forward"]["std"] > 3.0 * mean["std"]


def test_attitude_steps_validate_their_arguments():
    with pytest.raises(ValueError, match="roll or pitch"):
        Inclining("yaw", 4.0, 0.15)
    with pytest.raises(ValueError, match="roll or pitch"):
        TiltDecay("heave")
    with pytest.raises(ValueError, match="must be > 0"):
        Ballast(-1.0)
    with pytest.raises(ValueError, match="surge or sway"):
        LinePull("heave", 4.9)


class _Waits(Step):
    """A step that waits for the operator, then gives a surge force of 1 N."""
    name = "waits"

    def run(self, ctx):
        yield from ctx.wait_operator("attach_ballast", "calibration: attach the ballast")
        for _ in range(10):
            yield np.array([1.0, 0.0, 0.0, 0.0, 0.0, 0.0])


def test_a_second_continue_before_the_next_tick_finds_nothing_awaited(cfg):
    """StepContext.operator_continue: the first continue clears the prompt at once; a double press before the step's
    next tick is refused (it once answered "continuing" twice, the graph test's presses 9 ms apart), and the step
    resumes at that tick."""
    ex = Executive(cfg, [], tick_s=0.04, steps=[_Waits()], command_rate_hz=25.0)
    w = ex.start(0.0)
    assert ex.awaiting == "attach_ballast" and ex.prompt.endswith("then call continue") and w[0] == 0.0
    assert ex.operator_continue() is True
    assert ex.awaiting == "" and ex.prompt == ""
    assert ex.operator_continue() is False  # the double press
    assert ex.step(TickInput(0.04, 0.04, (), True, False))[0] == 1.0


# ------------------------------------------------------------------------------------------------ command rate
class _Ramp(Step):
    """A step whose law gives a new wrench every tick: surge force = the tick's index."""
    name = "ramp"

    def run(self, ctx):
        for k in range(1000):
            yield np.array([float(k), 0.0, 0.0, 0.0, 0.0, 0.0])


@pytest.mark.parametrize("rate_hz, ticks", [(25.0, 2), (50.0, 1), (10.0, 5), (None, 2)])
def test_a_command_is_the_laws_output_of_its_tick_held_for_whole_ticks(cfg, rate_hz, ticks):
    """Executive "Command rate": the law steps every tick (its output is the tick's index here); every ``ticks``-th
    tick's output is the command, held unchanged and flagged not new in between. None: the vehicle file's
    identification.command_rate_hz (25 Hz: 2 ticks at this test's 50 Hz tick)."""
    ex = Executive(cfg, [], tick_s=0.02, steps=[_Ramp()], command_rate_hz=rate_hz)
    assert ex.command_ticks == ticks
    got = [(ex.start(0.0)[0], ex.new_command)]
    for k in range(1, 21):
        got.append((ex.step(TickInput(0.02 * k, 0.02, (), True, False))[0], ex.new_command))
    assert got == [(float(k - k % ticks), k % ticks == 0) for k in range(21)]
