"""``hindrax ident bag`` and ``hindrax ident fit`` on the same campaign bag give the
same values and intervals (docs/identification.md §7).

The bag is written here: a surge ladder (8 runs of 6 s at +-10, +-20, +-30, +-15 N, each followed by 6 s of coasting
while the status says "returning") with the campaign's topics, stamped as the drivers stamp them:
``identification/status`` and ``thrusters/pulse_width`` at 50 Hz (the allocation's widths for the level, on the wire
as the ESC node writes them), ``dvl/data`` at 10 Hz (the body velocity FLU with 1 cm/s white noise, level attitude),
``pressure/fluid_pressure`` at 10 Hz (a constant depth), ``imu/data_raw`` declared without messages (no
accelerometer aid). The motion is the 1-DOF surge model of the vehicle file (inertia = mass + added mass, linear
and quadratic damping) driven by the thrust model of the written widths (allocation matrix, first-order lag
``thrusters.time_constant_s``, after ``esc.output_latency_s``), integrated at 1 ms.

Both commands must read it as the campaign (its DOF windows from the status) and go through the one fit core: every
``value`` and ``ci95`` of identification.yaml equal, and the fit near the vehicle file's surge parameters (so the
equality is not that of two empty fits). RuntimeWarning is an error.

The offline fits overlapped with the campaign (``hindrax run``; :class:`~hindrax_fit.
assessment.pipeline.OverlappedFits`) give the serial ``identify_bag``'s: a DOF's
fit on the bag still being written, once ready, is the whole bag's; the worker's result is the
serial one.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
import yaml

from hindrax_bringup.allocation.core import AllocationCore
from hindrax_common.config import default_config_path, load_config
from hindrax_bringup.recording.reader import BagReader
from hindrax_fit.assessment.pipeline import OverlappedFits, _ready, identify_bag
from hindrax_fit.bag_input import from_bag
from hindrax_fit.fit.campaign_fit import fit_dofs
from hindrax_tools import cli
from hindrax_onboard.identification.model.dof_model import truth_parameters
from hindrax_onboard.vehicle.signals import thrust_of_written_widths

pytestmark = pytest.mark.filterwarnings("error::RuntimeWarning")

T0 = 2000.0  # ROS time of the bag's first message, s
LEVELS_N = (10.0, -10.0, 20.0, -20.0, 30.0, -30.0, 15.0, -15.0)
RUN_S, COAST_S, IDLE_S = 6.0, 6.0, 1.0


def _stamped(msg, t):
    msg.header.stamp.sec = int(t)
    msg.header.stamp.nanosec = int(round((t - int(t)) * 1e9))
    return msg


def _schedule(t_rel: float):
    """(phase, level N or None) at ``t_rel`` s after T0."""
    if t_rel < IDLE_S:
        return 0, None  # PHASE_IDLE
    k, r = divmod(t_rel - IDLE_S, RUN_S + COAST_S)
    if k >= len(LEVELS_N):
        return 4, None  # PHASE_DONE
    return (2, LEVELS_N[int(k)]) if r < RUN_S else (3, None)  # RUNNING / RETURNING


def write_surge_campaign_bag(path, cfg, seed: int = 5, walk_m_s: float = 0.0, truth: dict | None = None) -> dict:
    """The campaign bag of the module docstring at ``path``; returns the surge truth of the vehicle file.
    ``walk_m_s``: a random walk (m/s per sqrt(s)) the DVL measures on top of the force's response, the vehicle
    pushed about by what the force does not explain (drawn from its own generator: 0 keeps the bag as it was);
    ``truth``: surge parameters of the simulated vehicle that differ from the vehicle file's."""
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import FluidPressure

    from hindrax_bringup.recording.writer import BagWriter, WriterOptions
    from hindrax_msgs.msg import Dvl, ManeuverStatus, ThrusterPwm

    rng = np.random.default_rng(seed)
    core = AllocationCore(cfg)
    curve, matrix = core.allocator.curves[0], np.asarray(core.matrix_frd, dtype=float)
    ths = cfg.thrusters.thrusters
    neutral = float(cfg.thrusters.pulse_width_neutral_us)
    rev = np.array([t.reversed for t in ths], dtype=bool)
    trim = np.array([t.trim_us for t in ths], dtype=float)
    truth = {**truth_parameters(cfg, "surge"), **(truth or {})}
    m, kq, kl = truth["inertia"], truth["quadratic_damping"], truth["linear_damping"]
    tau, lat = float(cfg.thrusters.time_constant_s), float(cfg.esc.output_latency_s)

    def wire(level):
        logical = core.allocate([level, 0, 0, 0, 0, 0]).pulse_width_us if level else np.full(len(ths), neutral)
        return np.where(rev, 2 * neutral - logical, logical) + trim

    total = IDLE_S + len(LEVELS_N) * (RUN_S + COAST_S) + 1.0
    dt = 0.001
    n = int(round(total / dt))
    widths, force = {}, {}
    v, f_lag = 0.0, 0.0
    walk = np.cumsum(np.random.default_rng(seed + 1).normal(0.0, walk_m_s * math.sqrt(dt), n + 1))
    with BagWriter(path, WriterOptions(fsync=False)) as w:
        for topic, type_name in (("/identification/status", "hindrax_msgs/msg/ManeuverStatus"),
                                 ("/thrusters/pulse_width", "hindrax_msgs/msg/ThrusterPwm"),
                                 ("/pressure/fluid_pressure", "sensor_msgs/msg/FluidPressure"),
                                 ("/dvl/data", "hindrax_msgs/msg/Dvl"), ("/imu/data_raw", "sensor_msgs/msg/Imu")):
            w.add_topic(topic, type_name)
        for i in range(n + 1):
            t_rel = i * dt
            t = T0 + t_rel
            t_ns = int(round(t * 1e9))
            if i % 20 == 0:  # 50 Hz: status and the widths the ESC wrote
                phase, level = _schedule(t_rel)
                st = ManeuverStatus(phase=phase, dof="surge" if phase in (2, 3) else "",
                                    level_command=level or 0.0, level_count=len(LEVELS_N))
                w.write("/identification/status", t_ns, serialize_message(_stamped(st, t)))
                pw = wire(level)
                widths[i] = pw
                w.write("/thrusters/pulse_width", t_ns,
                        serialize_message(_stamped(ThrusterPwm(pulse_width_us=list(pw), armed=True), t)))
            if i % 100 == 0:  # 10 Hz: DVL (velocity FLU) and pressure
                d = Dvl(velocity_valid=True, delta_time_s=0.1)
                d.header.frame_id = "base_link"
                d.velocity_m_s.x = v + walk[i] + 0.01 * float(rng.standard_normal())
                d.orientation.w = 1.0
                w.write("/dvl/data", t_ns, serialize_message(_stamped(d, t)))
                w.write("/pressure/fluid_pressure", t_ns,
                        serialize_message(_stamped(FluidPressure(fluid_pressure=101325.0 + 9810.0), t)))
            # the force of the last widths written at least the ESC latency ago, through the thrust lag
            k = 20 * int(math.floor(max(t_rel - lat, 0.0) / (20 * dt) + 1e-9))
            if k not in force:
                force[k] = float(matrix[0] @ thrust_of_written_widths(cfg, curve, widths.get(k, widths[0])))
            f_cmd = force[k]
            f_lag = f_cmd + (f_lag - f_cmd) * math.exp(-dt / tau)
            v += dt * (f_lag - kq * abs(v) * v - kl * v) / m
    return truth


def test_ident_bag_and_ident_fit_give_the_same_values_and_intervals(tmp_path, capsys):
    cfg = load_config(default_config_path())
    bag = tmp_path / "campaign"
    truth = write_surge_campaign_bag(bag, cfg)
    assert cli.main(["ident", "bag", str(bag), "--out", str(tmp_path / "bag_out")]) == 0, capsys.readouterr().err
    capsys.readouterr()
    assert cli.main(["ident", "fit", str(bag), "--config", str(default_config_path()),
                     "--out", str(tmp_path / "fit_out")]) == 0, capsys.readouterr().err
    printed = capsys.readouterr().out
    assert "the campaign's topics" in printed and "linear + quadratic damping" in printed
    a = yaml.safe_load((tmp_path / "bag_out" / "identification.yaml").read_text())
    b = yaml.safe_load((tmp_path / "fit_out" / "identification.yaml").read_text())
    assert set(a["dofs"]) == set(b["dofs"]) == {"surge"}
    for name, e in a["dofs"]["surge"].items():
        if not (isinstance(e, dict) and "value" in e):
            continue
        f = b["dofs"]["surge"][name]
        assert f["value"] == pytest.approx(e["value"], rel=1e-12, abs=1e-15), name
        assert f["ci95"] == pytest.approx(e["ci95"], rel=1e-12, abs=1e-15), name
        assert f["std"] == pytest.approx(e["std"], rel=1e-12, abs=1e-15), name
    # a real fit: inertia and quadratic damping near the vehicle file's, inside their intervals, and a model that
    # beats holding the velocity on the same held-out samples (issue 46.1)
    s = a["dofs"]["surge"]
    assert s["persistence"]["beats"] and s["verdict"] != "no model beats holding the velocity"
    assert s["persistence"]["nrmse"] < 0.5 * s["persistence"]["nrmse_hold"]
    for name in ("inertia", "quadratic_damping"):
        assert s[name]["value"] == pytest.approx(truth[name], rel=0.05), name
        assert s[name]["ci95"][0] <= truth[name] <= s[name]["ci95"][1], name


def test_one_verdict_path_for_both_document_builders(tmp_path):
    """Issue 27 item 1, the verdicts: the same fit core result written by ``hindrax ident bag``'s builder
    (:func:`~hindrax_fit.assessment.results.build_results`: empirical priors by the joint estimate,
    thrust-curve covariance and checks by :func:`~hindrax_fit.assessment.verdicts.assess_dof`) and by
    ``hindrax ident fit``'s (:func:`~hindrax_fit.assessment.results.
    build_document`) gives the same values,
    std (with the thrust curve), std_fit, priors, intervals and verdicts; the campaign builder may add DOF-wide
    reasons only from its steady windows (evidence the generic reader does not have) and the residual whiteness.
    Fails when either builder changes its priors, thrust term, intervals or per-parameter checks alone. (The
    whiteness check is the designed campaign's only.)"""
    from hindrax_fit.assessment.results import build_document
    from hindrax_fit.fit import fit_any
    from hindrax_fit.assessment.results import build_results
    from hindrax_onboard.vehicle.uncertainty import declared_rel

    cfg = load_config(default_config_path())
    bag = tmp_path / "campaign"
    truth = write_surge_campaign_bag(bag, cfg)
    _record, idents, errors = identify_bag(bag, cfg)
    assert set(idents) == {"surge"}, errors
    core = idents["surge"].signals["core"]
    res = fit_any.FitResult({"surge": fit_any.DofFit("surge", "fitted", {}, core, {"cross_validation": dict(core.cv)})},
                            {}, "test")
    b = build_document(res, cfg, [bag])["dofs"]["surge"]
    a = build_results(idents, cfg)["dofs"]["surge"]
    rel = declared_rel(cfg)
    steady_only = {x for x in a["reasons"]
                   if x.startswith(("steady-state", "positive/negative", "residuals not white"))}
    compared = 0
    for name, e in a.items():
        if not (isinstance(e, dict) and "value" in e) or b[name].get("model_term") == "excluded":
            continue
        f = b[name]
        for key in ("value", "std", "std_fit"):
            assert f[key] == pytest.approx(e[key], rel=1e-9, abs=1e-12), (name, key)
        assert f["ci95"] == pytest.approx(e["ci95"], rel=1e-9, abs=1e-12), name
        assert f.get("prior") == (e.get("prior") if name != "added_mass" else None) or name == "added_mass", name
        assert set(e["reasons"]) - set(f["reasons"]) <= steady_only, name
        assert set(f["reasons"]) <= set(e["reasons"]), name
        # the thrust-curve term is in both, and the priors pulled both alike (against numbers neither produced)
        thrust_var = (e["value"] ** 2 * (0.25 * rel[0] ** 2 + 0.25 * rel[1] ** 2)) if name != "added_mass" else None
        if thrust_var is not None:
            assert f["std"] ** 2 == pytest.approx(f["std_fit"] ** 2 + thrust_var, rel=1e-9), name
        compared += 1
    assert compared >= 5  # inertia, added mass, both damping terms, bias
    assert "prior" in b["inertia"] and b["inertia"]["fit_value"] == pytest.approx(float(core.theta[0]))
    assert abs(b["inertia"]["value"] - truth["inertia"]) < 0.05 * truth["inertia"]


def test_ident_bag_says_when_no_model_beats_holding_the_velocity(tmp_path, capsys):
    """Issue 46.1 for ``hindrax ident bag``: the same surge campaign, but the DVL measures a random walk of 1 m/s
    per sqrt(s) on top of the force's response. For a random walk the best prediction of a later velocity from the
    initial one IS the initial one, and over a 10 s segment the walk moves ~3 m/s while the ladder's levels move the
    vehicle ~0.5 m/s: no model of the force beats holding the velocity by the 5 % margin. The command prints the
    verdict, identification.yaml carries it with both scores, and no parameter is trusted."""
    cfg = load_config(default_config_path())
    bag = tmp_path / "campaign"
    write_surge_campaign_bag(bag, cfg, walk_m_s=1.0)
    assert cli.main(["ident", "bag", str(bag), "--out", str(tmp_path / "out")]) == 0, capsys.readouterr().err
    printed = capsys.readouterr().out
    assert "surge  verdict: no model beats holding the velocity (cross-validated nrmse" in printed
    s = yaml.safe_load((tmp_path / "out" / "identification.yaml").read_text())["dofs"]["surge"]
    assert s["verdict"] == "no model beats holding the velocity"
    p = s["persistence"]
    assert not p["beats"] and p["nrmse"] > (1 - p["margin"]) * p["nrmse_hold"] and math.isfinite(p["nrmse_zero"])
    params = {n: e for n, e in s.items() if isinstance(e, dict) and "value" in e}
    assert params and all(e["verdict"] == "suspect" for e in params.values())
    assert all(any("no model beats holding the velocity" in r for r in e["reasons"]) for e in params.values())
    rows = {r["terms"]: r for r in s["model_selection"]}
    assert rows["hold the velocity (persistence)"]["cv_nrmse"] == pytest.approx(p["nrmse_hold"])
    assert [r for r in s["model_selection"] if r["chosen"]]


def test_a_parameter_at_its_bound_says_so_instead_of_an_interval(tmp_path, capsys):
    """Issue 46, "no interval reported for a parameter at a bound without saying so", for ``hindrax ident bag``: a
    vehicle whose low-speed drag is below the quadratic law (linear damping -3 kg/s in the simulation; the fit keeps
    it >= 0) puts linear_damping on its bound 0 (the empirical priors off, ``identification.prior_std_rel: 0``: they
    would pull it just off the bound). identification.yaml marks it (``at_bound``), the printed row gives that
    reason, and the report's interval cell says there is none."""
    from hindrax_onboard.commands.common import update_vehicle_file

    cfg = load_config(default_config_path())
    bag = tmp_path / "campaign"
    write_surge_campaign_bag(bag, cfg, truth={"linear_damping": -3.0})
    vehicle = tmp_path / "vehicle.yaml"
    vehicle.write_text(default_config_path().read_text())
    update_vehicle_file(vehicle, {"identification.prior_std_rel": 0.0})
    out = tmp_path / "out"
    assert cli.main(["ident", "bag", str(bag), "--out", str(out), "--config", str(vehicle)]) == 0, \
        capsys.readouterr().err
    printed = capsys.readouterr().out
    s = yaml.safe_load((out / "identification.yaml").read_text())["dofs"]["surge"]
    assert s["linear_damping"]["at_bound"] == 0.0 and s["linear_damping"]["verdict"] == "suspect"
    assert "at_bound" not in s["quadratic_damping"]
    row = next(x for x in printed.splitlines() if x.startswith("surge  linear_damping"))
    assert "at its lower bound 0" in row and "no interval" in row and "nan" not in printed
    assert "none: at its bound 0" in (out / "report" / "index.html").read_text()


@pytest.fixture(scope="module")
def surge_bag(tmp_path_factory):
    cfg = load_config(default_config_path())
    bag = tmp_path_factory.mktemp("overlap") / "campaign"
    write_surge_campaign_bag(bag, cfg)
    return cfg, bag


def _same_fit(a, b) -> None:
    assert list(a.names) == list(b.names)
    np.testing.assert_array_equal(a.theta, b.theta)
    np.testing.assert_array_equal(a.covariance.cov, b.covariance.cov)


def test_a_ready_dof_fitted_on_a_prefix_of_the_bag_is_the_whole_bags_fit(surge_bag):
    cfg, bag = surge_bag
    reader = BagReader(bag)
    wanted = [tp for tp in reader.topics if tp.lstrip("/") in from_bag.TOPICS]
    msgs = [(m.topic.lstrip("/"), obj) for m, obj in reader.installed_messages(wanted, lean=True)]
    full = from_bag.record_from_messages(msgs, cfg)
    end = full.windows["surge"][1]

    def upto(t_s: float):
        return from_bag.record_from_messages([(tp, m) for tp, m in msgs
                                              if from_bag._stamp(m) <= t_s], cfg)

    # the bag as written to the window's end is not ready; to a sensor sample past the margin, it
    # is (the bag ends 1 s after the window: a margin of 0.5 s here)
    assert not _ready(upto(end), "surge", 0.5)
    prefix = upto(end + 0.55)
    assert _ready(prefix, "surge", 0.5) and prefix.t_s.size < full.t_s.size
    _same_fit(fit_dofs(prefix, cfg)[0]["surge"][0], fit_dofs(full, cfg)[0]["surge"][0])


def test_overlapped_fits_give_the_serial_identification(surge_bag):
    cfg, bag = surge_bag
    overlap = OverlappedFits(bag, cfg)
    overlap.done(["surge"])
    fitted = overlap.result()
    assert list(fitted) == ["surge"]  # fitted by the worker before the end
    record, idents, errors = identify_bag(bag, cfg, fitted=fitted)
    serial_record, serial, _errors = identify_bag(bag, cfg)
    assert not errors and set(idents) == set(serial) == {"surge"}
    _same_fit(idents["surge"].signals["core"], serial["surge"].signals["core"])
    assert idents["surge"].values == serial["surge"].values
    assert idents["surge"].std == serial["surge"].std
    np.testing.assert_array_equal(record.t_s, serial_record.t_s)


def test_a_bag_not_readable_yet_leaves_its_dofs_to_the_serial_fit(tmp_path):
    overlap = OverlappedFits(tmp_path / "no_bag", load_config(default_config_path()))
    overlap.done(["surge"])
    assert overlap.result() == {} and overlap.error == ""


def test_a_lost_worker_says_why_and_gives_no_fits(tmp_path):
    overlap = OverlappedFits(tmp_path / "no_bag", load_config(default_config_path()))
    overlap._proc.kill()
    overlap._proc.join(10)
    assert overlap.result() is None and "worker lost" in overlap.error
