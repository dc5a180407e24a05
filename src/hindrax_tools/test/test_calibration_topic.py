"""The calibration steps' results on ``identification/calibration``:
the identification node publishes them when a step ends (diagnostic_msgs/DiagnosticArray, transient local), the
recorder stores them, and ``hindrax ident bag`` applies them (sections ``calibration`` and ``joint``, and
``inclining`` / ``free_decay``) as ``hindrax run`` does from the node's record (docs/identification.md §6).
"""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
import yaml

from hindrax_common.config import default_config_path, load_config
from hindrax_tools import cli
from hindrax_onboard.identification.model import calibration_topic
from hindrax_onboard.identification.model.dof_model import parameter_names

# step results in the steps' layout (identification/steps: Ballast, LinePull, Inclining, TiltDecay): the holding
# forces and their parts from forward and reverse thrust
CAL = {"vertical": {"value": 0.9, "std": 0.01, "known_force_n": 8.5603, "holding_force_n": [0.81, -8.70],
                    "holding_force_std_n": [0.05, 0.06], "method": "ballast", "direction": "+z", "group": "vertical",
                    "forward_force_n": [0.84, 0.0], "reverse_force_n": [-0.03, -8.70]},
       "surge": {"value": 0.88, "std": 0.02, "known_force_n": 4.905, "holding_force_n": [0.1, -5.47],
                 "holding_force_std_n": [0.04, 0.05], "method": "line_pull", "direction": "+x", "group": "horizontal",
                 "forward_force_n": [0.05, -2.73], "reverse_force_n": [0.05, -2.74]},
       "sway": {"value": 0.92, "std": 0.04, "known_force_n": 4.905, "holding_force_n": [0.0, -5.33],
                "holding_force_std_n": [0.03, 0.07], "method": "line_pull", "direction": "+y", "group": "horizontal",
                "forward_force_n": [0.0, -2.66], "reverse_force_n": [0.0, -2.67]}}
#: the same results as a node before issue 26 published them: single scales, no forward/reverse parts
OLD_CAL = {k: {kk: vv for kk, vv in v.items() if kk not in ("direction", "group", "forward_force_n",
                                                                "reverse_force_n")} for k, v in CAL.items()}
INCL = {"roll": {"value": 4.489, "std": 0.132, "known_moment_n_m": 0.642, "thruster_moment_n_m": [0.01, 0.03],
                 "tilt_rad": [0.001, 0.144], "tilt_std_rad": [0.002, 0.003], "method": "inclining"}}
DECAYS = {"pitch": (1012.34, 1032.34)}
T0 = 1000.0  # ROS time of the synthetic campaign's start, s


def _stamped(msg, t):
    msg.header.stamp.sec = int(t)
    msg.header.stamp.nanosec = int(round((t - int(t)) * 1e9))
    return msg


def test_results_survive_the_message_exactly_with_named_keys():
    from builtin_interfaces.msg import Time

    arr = calibration_topic.calibration_array(calibration_topic.statuses(CAL, INCL, DECAYS), Time(sec=5))
    names = [s.name for s in arr.status]
    assert names == ["thrust_scale/vertical", "thrust_scale/surge", "thrust_scale/sway", "inclining/roll",
                     "tilt_decay/pitch"]
    kv = {v.key: v.value for v in arr.status[0].values}
    assert kv["scale"] == "0.9" and kv["scale_std"] == "0.01" and kv["known_force_n"] == "8.5603"
    assert kv["group"] == "vertical" and kv["direction"] == "+z" and kv["step"] == "ballast"
    assert kv["holding_force_with_n"] == "-8.7" and kv["holding_force_without_std_n"] == "0.05"
    assert kv["forward_force_without_n"] == "0.84" and kv["reverse_force_with_n"] == "-8.7"
    kv = {v.key: v.value for v in arr.status[2].values}
    assert kv["group"] == "horizontal" and kv["direction"] == "+y" and kv["axis"] == "sway"
    kv = {v.key: v.value for v in arr.status[3].values}
    assert kv["stiffness_n_m_per_rad"] == "4.489" and kv["thruster_moment_with_n_m"] == "0.03"
    assert kv["tilt_with_rad"] == "0.144" and kv["tilt_without_std_rad"] == "0.002"
    cal, incl, decays = calibration_topic.results_from_array(arr)
    assert cal == CAL and incl == INCL and decays == DECAYS
    # a later message's result of the same name replaces the earlier one; other statuses are ignored
    newer = calibration_topic.calibration_array(
        calibration_topic.statuses({"vertical": dict(CAL["vertical"], value=0.95)}), Time(sec=6))
    newer.status.append(type(newer.status[0])(name="recorder", hardware_id="hindrax recorder"))
    cal, _, _ = calibration_topic.merge_results([arr, newer])
    assert cal["vertical"]["value"] == 0.95 and cal["surge"] == CAL["surge"]
    bad = calibration_topic.calibration_array(calibration_topic.statuses({"vertical": CAL["vertical"]}), Time())
    bad.status[0].values = [v for v in bad.status[0].values if v.key != "scale_std"]
    with pytest.raises(ValueError, match="thrust_scale/vertical.*scale_std"):
        calibration_topic.results_from_array(bad)
    # an older node's message (no forward/reverse parts) still reads: its scales measure each group's mean
    old = calibration_topic.calibration_array(calibration_topic.statuses(OLD_CAL), Time(sec=5))
    for st in old.status:
        st.values = [v for v in st.values if not v.key.startswith(("forward_", "reverse_"))]
    cal, _, _ = calibration_topic.results_from_array(old)
    assert all("forward_force_n" not in e for e in cal.values())
    assert {k: e["value"] for k, e in cal.items()} == {k: e["value"] for k, e in CAL.items()}


def _write_campaign_bag(path, cfg, calibration_msg, cut_s=None):
    """A bag with what ``hindrax ident bag`` needs: 10 s of a heave run at fixed widths (status, ESC widths,
    pressure, DVL, IMU) and, optionally, the node's calibration message (type from its own class). The campaign ends
    with a DONE status, unless the bag is cut ``cut_s`` after its start (heave, the first of 3 levels, running)."""
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import FluidPressure, Imu

    from hindrax_bringup.recording.writer import BagWriter, WriterOptions
    from hindrax_msgs.msg import Dvl, ManeuverStatus, ThrusterPwm

    n = len(cfg.thrusters.thrusters)
    with BagWriter(path, WriterOptions(fsync=False)) as w:
        for topic, type_name in (("/identification/status", "hindrax_msgs/msg/ManeuverStatus"),
                                 ("/thrusters/pulse_width", "hindrax_msgs/msg/ThrusterPwm"),
                                 ("/pressure/fluid_pressure", "sensor_msgs/msg/FluidPressure"),
                                 ("/dvl/data", "hindrax_msgs/msg/Dvl"), ("/imu/data_raw", "sensor_msgs/msg/Imu"),
                                 ("/identification/calibration", "diagnostic_msgs/msg/DiagnosticArray")):
            w.add_topic(topic, type_name)
        if calibration_msg is not None:  # transient local: the recorder gets it when it subscribes, first
            assert isinstance(calibration_msg, DiagnosticArray)
            w.write("/identification/calibration", int(T0 * 1e9), serialize_message(calibration_msg))
        for k in range(501):
            t = T0 + 0.02 * k
            t_ns = int(round(t * 1e9))
            if cut_s is not None and t > T0 + cut_s:
                break
            running = T0 + 2.0 <= t < T0 + 6.0
            st = ManeuverStatus(phase=ManeuverStatus.PHASE_RUNNING if running else ManeuverStatus.PHASE_POSITIONING,
                                dof="heave" if running else "", level_command=10.0 if running else 0.0,
                                level_count=1 if cut_s is None else 3)
            if k == 500:
                st = ManeuverStatus(phase=ManeuverStatus.PHASE_DONE, dof="", level_count=1)
            w.write("/identification/status", t_ns, serialize_message(_stamped(st, t)))
            pw = ThrusterPwm(pulse_width_us=[1600.0 if running else 1500.0] * n, armed=True)
            w.write("/thrusters/pulse_width", t_ns, serialize_message(_stamped(pw, t)))
            if k % 5 == 0:
                w.write("/pressure/fluid_pressure", t_ns,
                        serialize_message(_stamped(FluidPressure(fluid_pressure=101325.0 + 9810.0), t)))
                d = Dvl(velocity_valid=True, delta_time_s=0.1)
                d.header.frame_id = "base_link"
                w.write("/dvl/data", t_ns, serialize_message(_stamped(d, t)))
                w.write("/imu/data_raw", t_ns, serialize_message(_stamped(Imu(), t)))


def _ident(dof, values, stds, cfg):
    """A DofIdentification stand-in (what identify_all_with_errors returns; test_joint_estimation's layout)."""
    from hindrax_onboard.identification.model.dof_model import rigid_inertia

    names = parameter_names(dof)
    vals = dict(zip(names, values))
    vals["added_mass"] = vals["inertia"] - rigid_inertia(cfg, dof)
    std = dict(zip(names, stds))
    std["added_mass"] = std["inertia"]
    return SimpleNamespace(dof=dof, names=names, values=vals, std=std, ci95={k: (0.0, 0.0) for k in vals},
                           signals={"covariance": np.diag(np.square(stds))}, steady=None, pool_time_s=60.0,
                           units={k: "" for k in vals}, method="output-error", equation_error={}, online={},
                           steady_note="", truth={}, rls_time_s=None, steady_time_s=None)


@pytest.mark.parametrize("with_calibration", [True, False])
def test_ident_bag_applies_the_calibration_in_the_bag(tmp_path, monkeypatch, capsys, with_calibration):
    """The fit (replaced here: the dynamics are not the subject) sees the thrust-model force times the bag's scales;
    identification.yaml gets ``calibration`` (the scales and known forces used) and ``joint`` (the scales' posterior
    from their prior N(1, sigma_s^2) and the steps, docs/identification.md §6.2); ``inclining`` from the inclining
    step. Without the message: no such sections and the force unscaled."""
    from builtin_interfaces.msg import Time

    from hindrax_fit.assessment import report
    from hindrax_fit.assessment import pipeline
    from hindrax_fit.fit.calibration import thrust_scales

    cfg = load_config(default_config_path())
    # a free decay of an earlier goal (the node's message is cumulative) has no data in this bag: left out
    msg = calibration_topic.calibration_array(calibration_topic.statuses(CAL, INCL, {"roll": (T0 - 90.0, T0 - 70.0)}),
                                              Time(sec=int(T0)))
    bag = tmp_path / "bag"
    _write_campaign_bag(bag, cfg, msg if with_calibration else None)
    seen = []

    def fake_identify(record, cfg_, *_opts):
        seen.append(record)
        return {"heave": _ident("heave", [37.7, 93.5, 56.6, 5.3, 11.8, 0.78], [0.5, 3, 3, 3, 3, 0.05], cfg_)}, {}

    # the bindings identify_bag and write_outputs use (the pipeline's own, report's own): the other tests of this
    # module see the real ones
    monkeypatch.setattr(pipeline, "identify_all_with_errors", fake_identify)
    monkeypatch.setattr(report, "write_report", lambda out, *a, **k: out.mkdir(parents=True, exist_ok=True))
    assert cli.main(["ident", "bag", str(bag), "--out", str(tmp_path / "out")]) == 0, capsys.readouterr().err
    out = capsys.readouterr().out
    assert out.startswith(f"ident bag: reading and fitting {bag}\n"), out  # the fit's progress (Ticker), first
    doc = yaml.safe_load((tmp_path / "out" / "identification.yaml").read_text())
    (rec,) = seen
    z = rec.wrench_cmd_frd[:, 2]
    assert np.max(np.abs(z)) > 1.0  # the heave run's thrust
    from hindrax_fit.bag_input.from_bag import record_from_bag
    raw = record_from_bag(bag, cfg).wrench_cmd_frd[:, 2]
    if not with_calibration:
        assert np.array_equal(z, raw)
        assert "calibration" not in doc and "inclining" not in doc
        assert doc.get("joint", {}).get("scales", {}) == {}
        return
    assert "calibration from the bag" in out
    # issue 74.8: the joint scale (what control model divides by) printed beside the step's, each named
    joint_line = next(x for x in out.splitlines() if x.startswith("thrust scales estimated jointly"))
    vf = doc["joint"]["scales"]["vertical_forward"]
    assert f"vertical_forward {vf['value']:.4f} +- {vf['std']:.4f} (heave)" in joint_line, joint_line
    # the heave run pushes down with every vertical thruster (1600 us): forward thrust, the vertical forward scale
    # of the bag's calibration (the sinker's and the hovers' holds, thrust_scales: test_thrust_calibration.py)
    sc = thrust_scales(CAL, cfg)
    assert abs(sc["vertical_forward"]["value"] - sc["vertical_reverse"]["value"]) > 0.01
    assert np.allclose(z, sc["vertical_forward"]["value"] * raw, rtol=1e-9)
    steps = doc["calibration"]["steps"]
    assert steps["vertical"]["value"] == 0.9 and steps["vertical"]["known_force_n"] == 8.5603
    assert steps["vertical"]["holding_force_n"] == [0.81, -8.70] and steps["vertical"]["method"] == "ballast"
    assert steps["sway"]["known_force_n"] == 4.905 and steps["surge"]["forward_force_n"] == [0.05, -2.73]
    assert doc["calibration"]["thrust_scales"]["vertical_forward"]["value"] == pytest.approx(
        sc["vertical_forward"]["value"], rel=1e-12)
    joint = doc["joint"]["scales"]["vertical_forward"]
    assert [m["step"] for m in joint["measurements"]] == ["ballast vertical"] and joint["dofs"] == ["heave"]
    # the empirical priors (identification.prior_std_rel) pull the joint posterior only a little
    assert abs(joint["value"] - sc["vertical_forward"]["value"]) < 0.5 * sc["vertical_forward"]["std"]
    assert rec.decays == {} and "free_decay" not in doc
    assert doc["inclining"]["roll"]["value"] == 4.489 and doc["inclining"]["roll"]["tilt_rad"] == [0.001, 0.144]


@pytest.mark.ros
def test_ident_bag_prints_and_writes_the_data_advice_of_suspect_parameters(tmp_path, capsys):
    """Issue 27 item 3: the campaign bag above (a heave run with no measured motion: every heave parameter
    suspect) through the real ``ident bag`` fit: each suspect parameter's advice (manoeuvre, speed range,
    seconds more) is in identification.yaml and printed as a ``to fix <dof> <parameter>:`` line."""
    cfg = load_config(default_config_path())
    bag = tmp_path / "bag"
    _write_campaign_bag(bag, cfg, None)
    assert cli.main(["ident", "bag", str(bag), "--out", str(tmp_path / "out")]) == 0
    printed = capsys.readouterr().out
    doc = yaml.safe_load((tmp_path / "out" / "identification.yaml").read_text())
    advised = {n: p["advice"] for n, p in doc["dofs"]["heave"].items() if isinstance(p, dict) and p.get("advice")}
    assert "inertia" in advised and "quadratic_damping_positive" in advised
    for name, a in advised.items():
        assert doc["dofs"]["heave"][name]["verdict"] == "suspect"
        assert a["seconds_more"] > 0 and len(a["speed_range"]) == 3 and a["runs"] >= 1
        assert f"  to fix heave {name}: " in printed and f"({a['manoeuvre']}), speeds " in printed
        assert f"{a['runs']} {a['run_kind']} of about" in printed


def test_node_publishes_the_step_result_when_the_ballast_step_ends_and_the_recorder_stores_it(
        ballast_goal_on_the_graph):
    """Ballast step on the graph (virtual pool; steps shortened; conftest.py ``ballast_goal_on_the_graph``) with the
    recorder on: no calibration message while the step runs; when it ends the node publishes the scale it measured
    (its record's numbers, exactly); a subscriber that arrives afterwards still gets it (transient local), and the
    bag holds it."""
    from hindrax_bringup.recording.reader import BagReader

    run = ballast_goal_on_the_graph
    assert run.calibration_before_end == []  # nothing before the step's result exists
    assert run.result.success, run.result.message
    cal = run.calibration
    assert set(cal) == {"vertical"} and cal["vertical"]["value"] == pytest.approx(1.0, abs=0.1)
    assert len(run.published) == 1 and calibration_topic.results_from_array(run.published[0]) == (cal, {}, {})
    # a late subscriber (a recorder started after the result) still receives it
    late = run.late
    kv = {v.key: v.value for v in late[0].status[0].values}
    assert late[0].status[0].name == "thrust_scale/vertical" and kv["group"] == "vertical"
    assert float(kv["scale"]) == cal["vertical"]["value"] and float(kv["known_force_n"]) > 8.0
    reader = BagReader(run.bag)
    topic = next(tp for tp in reader.topics if tp.lstrip("/") == "identification/calibration")
    msgs = [obj for _m, obj in reader.decoded([topic])]
    assert msgs and calibration_topic.merge_results(msgs) == (cal, {}, {})
    assert not math.isnan(cal["vertical"]["std"])


def test_tilt_decay_command_uses_the_campaigns_verdict_rule(tmp_path, capsys, monkeypatch):
    """``hindrax ident tilt-decay --identification`` decides through verdicts.free_decay_reason (via
    apply_reference_verdicts), not a copy of it: replacing the rule changes the command's verdict both ways."""
    import json

    from scipy.integrate import solve_ivp

    from hindrax_fit.assessment import results, verdicts

    c, inertia, b1, b2 = 4.5, 0.96, 0.05, 1.3
    sol = solve_ivp(lambda _t, x: [x[1], -(b1 * x[1] + b2 * abs(x[1]) * x[1] + c * x[0]) / inertia], (0.0, 25.0),
                    [0.3, 0.0], t_eval=np.arange(0.0, 25.0, 0.01), rtol=1e-9, atol=1e-12)
    f = tmp_path / "roll.csv"
    f.write_text("time_s,rate\n" + "".join(f"{t:.4f},{p:.8f}\n" for t, p in zip(sol.t, sol.y[1])))
    doc_path = tmp_path / "identification.yaml"
    monkeypatch.setattr(results, "read_identification", lambda path: yaml.safe_load(open(path).read()))
    args = ["ident", "tilt-decay", str(f), "--stiffness", str(c), "--identification", str(doc_path), "--dof", "roll"]

    def verdict(value, std):
        doc_path.write_text(yaml.safe_dump({"dofs": {"roll": {"inertia": {"value": value, "std": std}}}}))
        assert cli.main(args) == 0
        return json.loads(capsys.readouterr().out)["self_propelled"]

    sp = verdict(1.2 * inertia, 0.01)  # 20 % high with a tight interval
    assert sp["verdict"] == "suspect" and "beyond 1.96 combined std" in sp["reason"], sp
    assert sp["rule"] == "suspect when |free decay - self-propelled| > 1.96 combined std"
    assert sp["z"] > 1.96 and sp["inertia_kg_m2"] == 1.2 * inertia
    assert verdict(inertia, 0.02)["verdict"] == "agrees"
    monkeypatch.setattr(verdicts, "free_decay_reason", lambda *a, **k: None)
    assert verdict(1.2 * inertia, 0.01)["verdict"] == "agrees"
    monkeypatch.setattr(verdicts, "free_decay_reason", lambda *a, **k: "stand-in rule")
    sp = verdict(inertia, 0.02)
    assert sp["verdict"] == "suspect" and sp["reason"] == "stand-in rule"


@pytest.mark.ros
def test_ident_bag_writes_each_result_into_a_new_folder_beside_the_bag(tmp_path, capsys):
    """Issue 45.3: without --out, each ``ident bag`` writes a new ``<bag>_ident_<time>`` folder beside the bag, never
    into the parent all bags share, and never over an earlier result; --out must be new or empty."""
    cfg = load_config(default_config_path())
    runs = tmp_path / "runs"
    bag = runs / "hindrax_2026_11_25-10_00_00"
    _write_campaign_bag(bag, cfg, None)
    assert cli.main(["ident", "bag", str(bag)]) == 0
    assert cli.main(["ident", "bag", str(bag)]) == 0
    capsys.readouterr()
    results = sorted(p for p in runs.iterdir() if p != bag)
    assert len(results) == 2 and all(p.name.startswith(f"{bag.name}_ident_") for p in results)
    assert all((p / "identification.yaml").is_file() and (p / "report" / "index.html").is_file() for p in results)
    assert not (runs / "identification.yaml").exists() and not (runs / "report").exists()
    assert cli.main(["ident", "bag", str(bag), "--out", str(results[0])]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not empty" in err[0]


@pytest.mark.ros
def test_ident_bag_names_a_truncated_bag_with_what_it_lacks(tmp_path, capsys):
    """Issue 45.4: a bag cut while the campaign ran (heave, level 1 of 3) is identified and named TRUNCATED, with
    the DOF, the levels missing and the campaign time it holds, in the output and in identification.yaml; a whole
    campaign is not."""
    cfg = load_config(default_config_path())
    whole, cut = tmp_path / "whole", tmp_path / "cut"
    _write_campaign_bag(whole, cfg, None)
    _write_campaign_bag(cut, cfg, None, cut_s=5.0)
    assert cli.main(["ident", "bag", str(whole), "--out", str(tmp_path / "w")]) == 0
    assert "TRUNCATED" not in capsys.readouterr().out
    assert "truncated" not in yaml.safe_load((tmp_path / "w" / "identification.yaml").read_text())["provenance"]
    assert cli.main(["ident", "bag", str(cut), "--out", str(tmp_path / "c")]) == 0
    line = next(ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("TRUNCATED"))
    assert "still running when the bag ends, 5.0 s after it started (heave, level 1 of 3)" in line
    assert "levels missing: heave 1 of 3 levels" in line
    recorded = yaml.safe_load((tmp_path / "c" / "identification.yaml").read_text())["provenance"]["truncated"]
    assert any("heave 1 of 3 levels" in x for x in recorded)


@pytest.mark.ros
def test_ident_fit_on_a_campaign_bag_without_config_says_how_to_read_it_as_one(tmp_path, capsys):
    """Issue 45.4: ``ident fit`` on a campaign bag that it cannot read as one (no --config) fails naming the fix."""
    cfg = load_config(default_config_path())
    bag = tmp_path / "bag"
    _write_campaign_bag(bag, cfg, None)
    assert cli.main(["ident", "fit", str(bag), "--out", str(tmp_path / "out")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("ident fit: ")
    assert f"{bag} is a campaign bag: give --config VEHICLE.yaml to read it as the campaign" in err[0]
