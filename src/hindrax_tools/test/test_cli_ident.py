"""`hindrax ident free-decay`, `hindrax ident thruster-fit` and `hindrax run` with synthetic inputs.

Free decay: an analytic damped oscillator released from rest ([Hindrax-AM] eq. 1) with the [Hindrax-AM] Table 5
conditions (k_eq 659.9 N/m, m_b 0.39 kg, added mass 0.82 kg, zeta 0.15, A 20 mm, V 0.00056 m^3, 330 Hz, 10 s);
expected values from [Hindrax-AM] eqs. 5-9. Thruster fit: the configured cubic ([Hindrax-Drag] Table 2 negative row)
and its point reflection, plus 0.05 N noise.
"""
from __future__ import annotations

import copy
import json
import math
import os
import shutil

import numpy as np
import pytest

from hindrax_common.config import default_config_path, load_config
from hindrax_tools import cli
from hindrax_onboard.estimation.thruster_fit import point_reflection
from hindrax_fit.assessment.results import read_identification

K, MB, MAD, ZETA, A, V = 659.9, 0.39, 0.82, 0.15, 0.02, 0.00056


def _free_decay_csv(path):
    m = MB + MAD
    wn = math.sqrt(K / m)
    wd = wn * math.sqrt(1 - ZETA ** 2)
    t = np.arange(0, 10.0, 1 / 330.0)
    tau = np.clip(t - 0.5, 0.0, None)  # held at A until release at 0.5 s
    env = np.exp(-ZETA * wn * tau)
    x = A * env * (np.cos(wd * tau) + ZETA * wn / wd * np.sin(wd * tau))
    xd = -A * wn ** 2 / wd * env * np.sin(wd * tau)
    acc = np.where(t < 0.5, 0.0, -wn ** 2 * x - 2 * ZETA * wn * xd)
    with open(path, "w") as fh:
        fh.write("time_s,acceleration_m_s2\n")
        for ti, ai in zip(t, acc):
            fh.write(f"{ti:.6f},{ai:.9f}\n")
    return wd


def test_free_decay_prints_seed_000_quantities(tmp_path, capsys):
    f = tmp_path / "decay.csv"
    wd = _free_decay_csv(f)
    rc = cli.main(["ident", "free-decay", str(f), "--stiffness", str(K), "--mass", str(MB), "--volume", str(V)])
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    assert out["omega_d_rad_s"] == pytest.approx(wd, rel=0.01)
    assert out["zeta"] == pytest.approx(ZETA, rel=0.05)
    assert out["added_mass_kg"] == pytest.approx(MAD, rel=0.02)  # eq. 5
    assert out["added_mass_simplified_kg"] == pytest.approx(K / wd ** 2 - MB, rel=0.02)  # eq. 7
    assert out["damping_n_s_per_m"] == pytest.approx(2 * ZETA * math.sqrt(K * (MB + MAD)), rel=0.06)  # eq. 6
    assert out["c_m"] == pytest.approx(MAD / (1000.0 * V), rel=0.02)  # eq. 8
    assert out["kc"] == pytest.approx(2 * math.pi * A / V ** (1 / 3), rel=0.05)  # eq. 9


def test_free_decay_bad_input(tmp_path, capsys):
    rc = cli.main(["ident", "free-decay", str(tmp_path / "nope.csv"), "--stiffness", "1", "--mass", "1",
                   "--volume", "1"])
    assert rc == 1
    err = capsys.readouterr().err.strip()
    assert "cannot read" in err and len(err.splitlines()) == 1
    bad = tmp_path / "bad.csv"
    bad.write_text("t,a\n0,abc\n")
    assert cli.main(["ident", "free-decay", str(bad), "--stiffness", "1", "--mass", "1", "--volume", "1"]) == 1
    assert "not numbers" in capsys.readouterr().err


def _thrust_csv(path, cfg):
    neg = cfg.thrusters.curve_negative
    pos = point_reflection(*neg)
    rng = np.random.default_rng(4)
    # outside the ESC dead band only (the cubic branches end at +-1.09 N, not at 0 N, [Hindrax-Drag] Table 2)
    pw = np.concatenate([np.arange(1100, 1480, 10.0), np.arange(1530, 1901, 10.0)])
    thrust = np.where(pw < 1500, np.polyval(neg, pw), np.polyval(pos, pw))
    thrust = thrust + rng.normal(0, 0.05, pw.size)
    with open(path, "w") as fh:
        fh.write("pulse_width_us,thrust_n\n")
        for p, f in zip(pw, thrust):
            fh.write(f"{p},{f}\n")
    return neg, pos


def test_thruster_fit_prints_cubics_and_writes_config(tmp_path, capsys):
    cfg = load_config(default_config_path())
    csv = tmp_path / "bollard.csv"
    neg, pos = _thrust_csv(csv, cfg)
    conf = tmp_path / "hindrax.yaml"
    shutil.copy(default_config_path(), conf)
    rc = cli.main(["ident", "thruster-fit", str(csv), "--write", str(conf)])
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out) == {"negative", "positive", "thrust_fit_uncertainty_rel"}
    for side, truth, pws in (("negative", neg, [1100, 1250, 1400]), ("positive", pos, [1600, 1750, 1900])):
        c = out[side]
        for k in ("c4", "c3", "c2", "c1", "c4_std", "c3_std", "c2_std", "c1_std"):
            assert math.isfinite(c[k])
        fitted = np.polyval([c["c4"], c["c3"], c["c2"], c["c1"]], np.array(pws, dtype=float))
        assert np.allclose(fitted, np.polyval(truth, np.array(pws, dtype=float)), atol=0.1)
    text = conf.read_text()
    assert "# [Hindrax-Drag] Table 2 prints for the positive direction" in text  # comments kept
    cfg2 = load_config(conf)
    assert np.allclose(cfg2.thrusters.curve_negative, [out["negative"][k] for k in ("c4", "c3", "c2", "c1")],
                       rtol=1e-8)
    assert np.allclose(cfg2.thrusters.curve_positive, [out["positive"][k] for k in ("c4", "c3", "c2", "c1")],
                       rtol=1e-8)
    # everything else unchanged: the two curve lines replaced, one thrust_fit_uncertainty_rel line added
    lines = text.splitlines()
    added = [i for i, ln in enumerate(lines) if ln.strip().startswith("thrust_fit_uncertainty_rel:")]
    assert len(added) == 1 and lines[added[0] - 1].strip().startswith("curve_positive:")
    del lines[added[0]]
    changed = [a for a, b in zip(lines, open(default_config_path()).read().splitlines()) if a != b]
    assert len(changed) == 2
    assert cfg2.flat["thrusters.thrust_fit_uncertainty_rel"] == pytest.approx(out["thrust_fit_uncertainty_rel"])


def test_thruster_fit_bad_csv(tmp_path, capsys):
    f = tmp_path / "t.csv"
    f.write_text("pw,thrust\n1500\n")
    assert cli.main(["ident", "thruster-fit", str(f)]) == 1
    assert "need two columns" in capsys.readouterr().err


def test_run_writes_identification_report_and_summary(tmp_path, capsys):
    out = tmp_path / "out"
    rc = cli.main(["run", "--in-process", "--dofs", "surge", "--levels", "2", "--max-level-duration", "8",
                   "--seed", "3", "--out", str(out)])
    text = capsys.readouterr().out
    assert rc == 0
    assert "no ROS graph" in text
    doc = read_identification(out / "identification.yaml")
    assert set(doc["dofs"]) == {"surge"}
    assert doc["provenance"]["source"] == "simulation" and doc["provenance"]["seed"] == 3
    page = (out / "report" / "index.html").read_text()
    # issue 74.8: the page opened with the vehicle parameters as a raw Python dict; now folded YAML
    assert "{&#x27;" not in page and "<b>vehicle_parameters</b>: <details>" in page
    assert "vehicle.mass_kg: 15.22" in page
    assert (out / "report" / "surge_force_velocity.png").exists()
    # summary table: DOF, parameter, value, std, configured value, relative error
    line = next(x for x in text.splitlines() if x.startswith("surge") and " inertia " in x)
    assert "27.3" in line and "%" in line


@pytest.fixture(scope="module")
def _campaign_records() -> dict:
    """Records of :func:`one_simulated_campaign`'s campaigns by their settings, kept for the module."""
    return {}


@pytest.fixture
def one_simulated_campaign(monkeypatch, _campaign_records):
    """The output-folder tests run ``hindrax run --in-process`` with the same settings several times; what they check
    is where each run writes, so each campaign of the same settings (DOFs, levels, seed, level duration, calibration,
    excitation; the default truth: no ``--truth``) is simulated once and every run gets a copy of its record (the
    identification, report and folders still run each time)."""
    from hindrax_sim import campaign

    class Reused(campaign.Campaign):
        def __init__(self, cfg, dofs, levels=None, seed=None, max_level_duration_s=None, **kwargs):
            super().__init__(cfg, dofs, levels, seed, max_level_duration_s=max_level_duration_s, **kwargs)
            self.key = (tuple(dofs), levels, self.seed, max_level_duration_s, tuple(kwargs.get("calibrate") or ()),
                        kwargs.get("excitation"))

        def run(self):
            if self.key not in _campaign_records:
                _campaign_records[self.key] = super().run()
            return copy.deepcopy(_campaign_records[self.key])

    monkeypatch.setattr(campaign, "Campaign", Reused)


def test_run_default_directory_and_latest_link(tmp_path, capsys, monkeypatch, one_simulated_campaign):
    monkeypatch.chdir(tmp_path)
    rc = cli.main(["run", "--in-process", "--dofs", "yaw", "--levels", "1", "--max-level-duration", "4"])
    capsys.readouterr()
    assert rc == 0
    latest = tmp_path / "runs" / "latest"
    assert latest.is_symlink()
    assert (latest / "identification.yaml").exists()
    assert os.readlink(latest).startswith("sim-in-process_yaw_")  # named by its input and time


def test_two_runs_in_one_second_get_two_folders_and_latest_moves_on_completion(tmp_path, capsys, monkeypatch,
                                                                              one_simulated_campaign):
    """Issue 45.3: the second run of the same second picks a new name with one line; an aborted run leaves latest."""
    import datetime as dt

    from hindrax_tools import output_dirs

    monkeypatch.chdir(tmp_path)
    frozen = dt.datetime(2026, 11, 25, 12, 0, 0)
    real = output_dirs.new_result_dir
    monkeypatch.setattr(output_dirs, "new_result_dir", lambda root, name, now=None: real(root, name, frozen))
    argv = ["run", "--in-process", "--dofs", "yaw", "--levels", "1", "--max-level-duration", "4"]
    assert cli.main(argv) == 0
    first = capsys.readouterr().out
    assert cli.main(argv) == 0
    second = capsys.readouterr().out
    runs = tmp_path / "runs"
    names = sorted(p.name for p in runs.iterdir() if p.name != "latest")
    assert names == ["sim-in-process_yaw_2026_11_25-12_00_00", "sim-in-process_yaw_2026_11_25-12_00_00_1"]
    assert "exists" not in first
    notice = [ln for ln in second.splitlines() if "exists: writing to" in ln]
    assert len(notice) == 1 and notice[0].endswith("_1")
    assert os.readlink(runs / "latest") == names[1]
    assert all((runs / n / "identification.yaml").is_file() for n in names)  # the first result is intact
    # a run without a result (no DOF identified) does not move latest
    import hindrax_fit.fit.calibration as calibration

    monkeypatch.setattr(calibration, "identify_calibrated", lambda *a, **k: ({}, {"yaw": "no data"}))
    assert cli.main(argv) == 1
    capsys.readouterr()
    assert os.readlink(runs / "latest") == names[1]


def test_run_rejects_unknown_dof(capsys):
    assert cli.main(["run", "--dofs", "surge,spin"]) == 1
    assert "spin" in capsys.readouterr().err


def test_ident_campaign_is_registered(capsys):
    with pytest.raises(SystemExit) as exc:
        cli.main(["ident", "campaign", "--help"])
    assert exc.value.code == 0
    assert "no ROS graph" in capsys.readouterr().out


def test_run_refuses_an_output_directory_that_holds_a_run(tmp_path, capsys):
    (tmp_path / "bag").mkdir()
    (tmp_path / "bag" / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    assert cli.main(["run", "--dofs", "surge", "--out", str(tmp_path)]) == 1
    err = capsys.readouterr().err
    assert "not empty" in err and len(err.strip().splitlines()) == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bag"]  # nothing started, nothing written


def test_an_online_estimate_prints_names_units_and_95_percent_intervals():
    from hindrax_tools.commands.ident_live import format_estimate
    from hindrax_msgs.msg import HydroEstimate

    e = HydroEstimate(dof="heave", parameter_names=["inertia", "bias"], parameter_units=["kg", "N"],
                      values=[56.6, 1.0], std=[1.0, -1.0])
    # 56.6 -+ 1.96 * 1.0 = [54.64, 58.56]; std -1 (not converged): no interval
    assert format_estimate(e) == "heave: inertia 56.6 kg [54.64, 58.56], bias 1 N (no interval)"


def test_the_convergence_plot_draws_the_band_its_title_promises(tmp_path, monkeypatch):
    """Issue 74.8: the RLS plot promised a +-1.96 std band that was not seen; the band is drawn where the std is
    known and the title says for how many parameters (none: it says so)."""
    from types import SimpleNamespace

    from hindrax_fit.assessment import report

    figures: list = []
    monkeypatch.setattr(report, "_save", lambda fig, path, dpi=None: figures.append(fig))
    nan = float("nan")
    for std, title in (([[nan, nan], [0.1, nan], [0.1, nan]], "heave: RLS convergence (shaded: +-1.96 std, 1 of 2 "
                                                                "parameters)"),
                       ([[nan, nan]] * 3, "heave: RLS convergence (no std yet: no band)")):
        r = SimpleNamespace(dof="heave", names=["inertia", "bias"], values={"inertia": 1.0, "bias": 0.0}, truth={},
                            signals={"online_history": {"t": [0.0, 1.0, 2.0], "std": std,
                                                        "theta": [[1.0, 0.0], [1.1, 0.1], [1.0, 0.0]]}})
        assert report._rls_plot(r, tmp_path / "p.png")
        axes = figures[-1].axes
        assert axes[0].get_title() == title
        assert len(axes[0].collections) == (1 if "shaded" in title else 0)  # the fill_between band
        assert not axes[1].collections
