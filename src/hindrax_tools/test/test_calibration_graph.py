"""Calibration steps on the ROS graph: the run_identification goal's ``calibrate`` field, the
operator prompt in the action feedback and in ``identification/status``, the ``identification/continue`` service
(std_srvs/Trigger), the virtual operator of ``hindrax run`` (:class:`~hindrax_sim.graph.graph_campaign.
VirtualOperator`) and the ``calibration.*`` keys of the vehicle file.

The graph tests shorten the ballast step's settling and averaging times with the vehicle file's keys
(``calibration.hold_settle_s``, ``hold_window_s``) so that a calibration-only goal takes about a
minute of simulated time.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
import yaml
from hindrax_test_support.vehicle_files import SHORT_HOLDS, vehicle_file

from hindrax_common.config import ConfigError, default_config_path, load_config
from hindrax_tools import cli
from hindrax_onboard.identification.online import executive
from hindrax_sim.graph.graph_campaign import VirtualOperator, parse_prompt

# the shipped keys: 1 kg of steel (7850 kg/m^3), in water of 1000 kg/m^3 with g = 9.81 m/s^2
W_BALLAST = (1.0 - 1000.0 / 7850.0) * 9.81


@pytest.mark.parametrize("key, value, allowed", [
    ("ballast_mass_kg", -1.0, "calibration.ballast_mass_kg = -1.0: allowed number in [0.01, 50]"),
    ("line_pull_force_n", 0.0, "calibration.line_pull_force_n = 0.0: allowed number in [0.1, 200]"),
    ("ballast_volume_m3", 0.002, "calibration.ballast_volume_m3 = 0.002: allowed below calibration.ballast_mass_kg"),
    ("inclining_arm_m", 5.0, "calibration.inclining_arm_m = 5.0: allowed number in [0.01, 2]"),
    ("inclining_volume_m3", 0.001, "calibration.inclining_volume_m3 = 0.001: allowed below "
                                   "calibration.inclining_mass_kg"),
])
def test_calibration_keys_are_validated_with_one_line_naming_key_value_and_range(tmp_path, key, value, allowed):
    p = vehicle_file(tmp_path / "v.yaml", {f"calibration.{key}": value})
    with pytest.raises(ConfigError) as exc:
        load_config(p)
    lines = exc.value.lines()
    assert len(lines) == 1 and allowed in lines[0], lines


def test_shipped_calibration_keys_and_cli_defaults(tmp_path, capsys):
    cfg = load_config(default_config_path())
    w, f = executive.calibration_forces(cfg)
    assert w == pytest.approx(W_BALLAST, rel=1e-6) and f == 4.905
    # a command-line value replaces the key and is validated like the file (one line naming the key)
    assert cli.main(["ident", "campaign", "--calibrate", "ballast", "--dofs", "heave", "--ballast-volume-m3", "0.01",
                     "--out", str(tmp_path / "x")]) == 1
    err = capsys.readouterr().err
    assert "calibration.ballast_volume_m3 = 0.01: allowed below" in err and len(err.strip().splitlines()) == 1


def test_prompt_codes_and_virtual_operator_forces():
    assert parse_prompt("[attach_ballast] calibration: attach the ballast") == "attach_ballast"
    assert parse_prompt("") == "" and parse_prompt("dive to the altitude setpoint") == ""

    class Sim:  # yawed 90 deg: body +x points east; pitched by 0.1 rad does not tilt the line
        t_s = 0.0
        rotation = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
        wrenches: list = []

        def set_external_wrench(self, w):
            self.wrenches.append(list(w))

    sim = Sim()
    sent = []
    op = VirtualOperator(sim, 8.0, 5.0, lambda: sent.append(1))
    op.on_prompt("[attach_ballast] calibration: attach the ballast, then call continue")
    op.on_prompt("[attach_ballast] calibration: attach the ballast, then call continue")  # repeated feedback
    assert len(sent) == 1 and op.pool.ballast_on
    op.on_step()
    assert sim.wrenches[-1] == pytest.approx([0, 0, 8.0, 0, 0, 0])  # weight: NED down = body down here
    op.on_prompt("")
    op.on_prompt("[remove_ballast] calibration: remove the ballast")
    op.on_prompt("[apply_line_pull_surge] pull the line")
    assert not op.pool.ballast_on
    assert op.pool.line_ned == pytest.approx([0.0, 5.0, 0.0])  # east, along body +x
    op.on_step()
    assert sim.wrenches[-1] == pytest.approx([5.0, 0, 0, 0, 0, 0])
    op.on_prompt("[release_line_surge] release the line")
    op.on_step()
    assert sim.wrenches[-1] == pytest.approx([0.0] * 6) and len(sent) == 4
    n = len(sim.wrenches)
    op.on_step()
    assert len(sim.wrenches) == n  # nothing held: no further writes
    # the float (net buoyancy up) and a line along the negative body axis (issue 26: --calibrate thrust)
    op2 = VirtualOperator(sim, 8.0, 5.0, lambda: sent.append(1), float_buoyancy_n=9.3)
    op2.on_prompt("[attach_float] calibration: tie the float")
    op2.on_step()
    assert op2.pool.float_on and sim.wrenches[-1] == pytest.approx([0, 0, -9.3, 0, 0, 0])
    op2.on_prompt("[remove_float] calibration: remove the float")
    op2.on_prompt("[apply_line_pull_sway_negative] pull the line along -y")
    assert not op2.pool.float_on
    assert op2.pool.line_ned == pytest.approx([5.0, 0.0, 0.0])  # body -y is north here
    op2.on_step()
    assert sim.wrenches[-1] == pytest.approx([0, -5.0, 0, 0, 0, 0])


@pytest.mark.ros
@pytest.mark.timeout(1500)
def test_goal_with_ballast_prompts_continue_proceeds_and_nothing_awaited_is_refused(ballast_goal_on_the_graph):
    """The calibration-only ballast goal on the graph, the operator played step by step (conftest.py
    ``ballast_goal_on_the_graph``): continue is refused with no goal and when nothing awaits; bad goals are
    rejected; the prompt reaches the feedback and the status and the step waits for the operator; the measured scale
    is the result."""
    run = ballast_goal_on_the_graph
    ok, message = run.continue_before_goal
    assert not ok and "no identification goal" in message
    # an unknown step and calibration_only without a step are rejected
    assert run.bad_goals_accepted == [False, False]
    assert run.armed and run.accepted
    assert run.prompts[0].startswith("[attach_ballast] calibration: attach the ballast (8.56 N in water)")
    assert run.prompt_in_status
    assert run.awaiting_after_2_s == "attach_ballast"  # still waits, two seconds after the prompt
    assert run.continue_attach == (True, "continuing: attach_ballast")
    ok, message = run.continue_again  # the step holds now: nothing awaited
    assert not ok and "nothing awaits" in message
    assert any(p.startswith("[remove_ballast]") for p in run.prompts[1:])
    assert run.continue_remove[0]
    result = run.result
    assert result.success, result.message
    cal = run.calibration["vertical"]
    # default truth: the thrusters give their curves, so the known weight is held by scale 1
    assert cal["value"] == pytest.approx(1.0, abs=0.1) and 0.0 < cal["std"] < 0.1, cal
    assert cal["known_force_n"] == pytest.approx(W_BALLAST)
    assert "thrust scale vertical" in result.message
    assert not math.isnan(cal["holding_force_n"][0])
    ok, message = run.continue_after
    assert not ok and "no identification goal" in message


@pytest.mark.ros
def test_hindrax_run_calibrate_ballast_through_the_graph_plays_the_operator(tmp_path, capsys):
    """`hindrax run --calibrate ballast` through the whole graph (recorder, bag): the virtual operator answers both
    prompts from the feedback (known weight in the simulator, identification/continue); the measured scale reaches
    identification.yaml. Without the weight applied the step would abort (holding force did not rise)."""
    vehicle = vehicle_file(tmp_path / "v.yaml", SHORT_HOLDS)
    out = tmp_path / "run"
    rc = cli.main(["run", "--config", str(vehicle), "--calibrate", "ballast", "--dofs", "heave",
                   "--levels", "1", "--seed", "2", "--out", str(out)])
    text = capsys.readouterr().out
    assert rc == 0, text[-3000:]
    assert "virtual operator: attach_ballast done" in text and "virtual operator: remove_ballast done" in text
    assert "continue refused" not in text
    doc = yaml.safe_load((out / "identification.yaml").read_text())
    v = doc["calibration"]["steps"]["vertical"]
    assert v["method"] == "ballast" and v["known_force_n"] == pytest.approx(W_BALLAST)
    assert v["value"] == pytest.approx(1.0, abs=0.1) and 0.0 < v["std"] < 0.05, v  # default truth: curves exact
    # the sinker is held by reverse thrust: the node recorded which direction held it
    assert abs(v["reverse_force_n"][1]) > 5.0 and abs(v["forward_force_n"][1]) < 0.5, v
    s = doc["calibration"]["thrust_scales"]["common_reverse"]
    assert abs(s["value"] - 1.0) < 3.0 * s["std"] + 0.01, s
    assert doc["dofs"]["heave"]["inertia"]["value"] > 0


def test_inclining_step_gives_the_restoring_stiffness_of_roll_and_pitch():
    """In-process (the campaign hangs the test mass on the simulator): 0.5 kg of steel 0.15 m to starboard, then
    forward, with that DOF free and the rest held. Truth: z_g W - z_b B of the vehicle file (= the default truth,
    4.503 N m/rad). Measured with the default 15 s / 30 s holds: seed 2 roll 4.489 +- 0.132, pitch 4.606 +- 0.129;
    seed 3 roll 4.464 +- 0.136, pitch 4.554 +- 0.139 (within 2.3 %, |z| < 0.8). Without the thrusters' realised
    moment on the free DOF (thruster_moment_n_m, about 0.02 N m against the mass's 0.64 N m) pitch read 6 % high
    (2.8 std)."""
    from hindrax_sim.campaign import Campaign
    from hindrax_onboard.identification.online.executive import inclining_load

    cfg = load_config(default_config_path()).with_overrides({"calibration.hold_settle_s": 10.0,
                                                             "calibration.hold_window_s": 21.0})
    f = cfg.flat
    w_b = float(f["vehicle.displaced_volume_m3"]) * float(f["environment.water_density_kg_m3"]) * 9.81
    c_true = float(f["vehicle.centre_of_gravity_frd_m"][2]) * cfg.weight_n \
        - float(f["vehicle.centre_of_buoyancy_frd_m"][2]) * w_b
    w, d = inclining_load(cfg)
    assert w == pytest.approx((0.5 - 500.0 / 7850.0) * 9.81) and d == 0.15
    rec = Campaign(cfg, dofs=[], seed=2, calibrate=["inclining"], inclining_load_n_m=(w, d)).run()
    assert not rec.aborted, rec.abort_reason
    for dof, sign in (("roll", 1.0), ("pitch", -1.0)):
        e = rec.inclining[dof]
        assert e["method"] == "inclining" and e["known_moment_n_m"] == pytest.approx(sign * w * d)
        assert sign * (e["tilt_rad"][1] - e["tilt_rad"][0]) > 0.1  # the mass tilted the vehicle its way
        assert e["value"] == pytest.approx(c_true, rel=0.04), (dof, e, c_true)
        assert 0.0 < e["std"] < 0.05 * e["value"] and abs(e["value"] - c_true) < 2.5 * e["std"], (dof, e)
    with pytest.raises(ValueError, match="inclining_load_n_m"):
        executive.Executive(cfg, [], tick_s=0.02, calibrate=["inclining"])


@pytest.mark.ros
def test_ident_continue_without_a_stack_and_start_refuses_bad_calibrate(capsys):
    assert cli.main(["ident", "continue", "--timeout", "1", "--discovery-timeout", "1"]) == 1
    assert "no vehicle on ROS domain" in capsys.readouterr().err
    assert cli.main(["ident", "start", "--calibrate", "tow"]) == 1
    assert "unknown step(s) ['tow']" in capsys.readouterr().err
    assert cli.main(["ident", "start", "--calibration-only"]) == 1
    assert "--calibration-only needs --calibrate" in capsys.readouterr().err
