"""Broadband excitation: the signals of identification/online/excitation.py, the pool-box shaping, and
the executive running one multisine run per DOF instead of the ladder on the in-process campaign."""
from __future__ import annotations

import math

import numpy as np
import pytest

from hindrax_common.config import default_config_path, load_config
from hindrax_onboard.identification.online.excitation import (BoxShaping, Chirp, Multisine, Prbs, design_band,
                                                            design_signal, steady_speed)

pytestmark = pytest.mark.filterwarnings("error::RuntimeWarning")


def test_multisine_has_power_at_the_designed_lines_only():
    ms = Multisine.design(10.0, 0.05, 1.0, period_s=20.0)
    assert ms.harmonics == tuple(range(1, 21))  # 1/20 .. 20/20 Hz
    fs, periods = 50.0, 3
    t = np.arange(int(periods * 20.0 * fs)) / fs
    x = ms.value(t)
    assert np.max(np.abs(x)) == pytest.approx(10.0, rel=0.01)  # the peak is the amplitude
    spec = np.abs(np.fft.rfft(x)) ** 2
    f = np.fft.rfftfreq(t.size, 1.0 / fs)
    lines = np.isin(np.rint(f * 20.0).astype(int), np.arange(1, 21)) & (np.abs(f * 20.0 - np.rint(f * 20.0)) < 1e-9)
    assert lines.sum() == 20
    assert spec[~lines].sum() < 1e-20 * spec.sum()  # whole periods: no leakage, nothing off the lines (DC too)
    assert np.ptp(spec[lines]) < 1e-6 * spec[lines].max()  # flat amplitude spectrum
    # Schroeder phases keep the crest factor low: well under the sqrt(2 N) = 6.3 of equal (zero) phases
    crest = np.max(np.abs(x)) / np.sqrt(np.mean(x ** 2))
    assert crest < 2.0


def test_prbs_is_plus_minus_a_with_the_m_sequence_period():
    a, n, clock = 3.0, 6, 0.25
    p = Prbs(a, n, clock)
    period = (2 ** n - 1) * clock  # 63 clocks
    assert p.period_s == pytest.approx(period)
    t = (np.arange(2 * 63) + 0.5) * clock
    x = p.value(t)
    assert set(np.unique(x)) == {-a, a}
    np.testing.assert_array_equal(x[:63], x[63:])  # periodic with 63 clocks
    one = x[:63] / a
    assert (one > 0).sum() == 32 and (one < 0).sum() == 31  # m-sequence balance: 2^(n-1) ones
    # two-valued circular autocorrelation of an m-sequence: 63 at lag 0, -1 at every other lag
    acf = np.array([np.dot(one, np.roll(one, k)) for k in range(63)])
    assert acf[0] == 63 and np.all(acf[1:] == -1)
    # the design picks the longest sequence whose period fits the run
    assert Prbs.design(a, 0.4, 60.0).nbits == 7  # 127 x 0.4 = 50.8 s <= 60 s < 255 x 0.4


def test_chirp_sweeps_from_f_min_to_f_max():
    c = Chirp(2.0, 0.1, 1.0, 50.0)
    t = np.arange(0, 50.0, 0.001)
    x = c.value(t)
    assert np.max(np.abs(x)) <= 2.0 + 1e-12 and abs(x[0]) < 1e-9
    zc = t[2:][np.diff(np.signbit(x[1:])) != 0]  # zero crossings after t = 0: two per period
    # logarithmic sweep: f(t) = f0 (f1 / f0)^(t / T); a half period between crossings at its middle time
    for a, b in ((zc[0], zc[1]), (zc[-2], zc[-1])):
        mid = 0.5 * (a + b)
        assert 0.5 / (b - a) == pytest.approx(0.1 * 10.0 ** (mid / 50.0), rel=0.05)
    assert 0.5 / (zc[-1] - zc[-2]) > 0.9


def test_band_from_the_time_constant():
    m, kq, a = 27.3, 66.48, 20.0
    v = math.sqrt(a / kq)  # k_l = 0: k_q v^2 = A
    assert steady_speed(a, 0.0, kq) == pytest.approx(v)
    assert steady_speed(a, 4.0, 0.0) == pytest.approx(5.0)
    b = design_band(m, 0.0, kq, a)
    tau = m / (2.0 * kq * v)
    assert b.time_constant_s == pytest.approx(tau)
    fc = 1.0 / (2.0 * math.pi * tau)
    assert (b.f_min_hz, b.f_max_hz) == (pytest.approx(fc / 8.0), pytest.approx(3.0 * fc))
    # the thruster lag caps the top of the band
    assert design_band(m, 0.0, kq, a, thruster_time_constant_s=0.5).f_max_hz == pytest.approx(1.0 / math.pi)
    with pytest.raises(ValueError):
        design_signal("sweep", a, b, 60.0)


def _simulate(kind: str, shaped: bool, disturbance_n: float = 0.0, seconds: float = 300.0):
    """Surge-like one-DOF plant M v' = F - k_q |v| v - k_l v + d (numbers of the vehicle file), the force from the
    excitation through the box shaping (or raw); returns the positions (m)."""
    m, kl, kq, lim, half = 27.3, 1.25, 66.48, 35.6, 1.0
    amp = 0.6 * lim
    band = design_band(m, kl, kq, amp, 0.1)
    sig = design_signal(kind, amp, band, seconds)
    box = BoxShaping(half, m, lim, math.pi * band.f_min_hz, 0.02)
    x = v = 0.0
    xs = []
    for i in range(int(seconds / 0.02)):
        u = float(sig.value(i * 0.02))
        f = box.force(u, x, v) if shaped else u
        for _ in range(4):
            acc = (f + disturbance_n - kq * abs(v) * v - kl * v) / m
            v += acc * 0.005
            x += v * 0.005
        xs.append(x)
    return np.array(xs)


@pytest.mark.parametrize("kind", ["multisine", "prbs", "chirp"])
def test_box_shaping_keeps_a_double_integrator_with_drag_inside_the_box(kind):
    # a 2 m wide box (half range 1 m) and a 3 N push towards one wall (a tether or current)
    raw = _simulate(kind, shaped=False, disturbance_n=3.0)
    assert np.max(np.abs(raw)) > 1.0  # unshaped, the same input leaves the box
    x = _simulate(kind, shaped=True, disturbance_n=3.0)
    assert np.max(np.abs(x)) < 1.0
    assert np.ptp(x) > 0.5  # and it still moves: the excitation is not cancelled


def test_ladder_is_the_default_and_the_excitation_comes_from_the_config():
    from hindrax_onboard.identification.online.executive import Executive

    cfg = load_config(default_config_path())
    assert cfg.identification.excitation == "ladder"
    assert Executive(cfg, ["surge"], tick_s=0.02).excitation == "ladder"
    cfg2 = load_config(default_config_path(), {"identification.excitation": "prbs",
                                               "identification.excitation_duration_s": 30.0})
    ex = Executive(cfg2, ["surge"], tick_s=0.02)
    assert (ex.excitation, ex.excitation_duration_s) == ("prbs", 30.0)
    with pytest.raises(ValueError, match="excitation"):
        Executive(cfg, ["surge"], tick_s=0.02, excitation="sweep")


def test_multisine_campaign_recovers_surge_inertia_and_quadratic_damping():
    from hindrax_sim.campaign import Campaign
    from hindrax_fit.fit.campaign_fit import identify_dof

    cfg = load_config(default_config_path())
    rec = Campaign(cfg, dofs=["surge"], seed=3, excitation="multisine", excitation_duration_s=40.0).run()
    assert not rec.aborted, rec.abort_reason
    assert np.all(np.isfinite(rec.run_id)) and set(np.unique(rec.run_id[rec.active == 0])) <= {-1, 0}  # one run
    assert not np.any(np.diff(rec.level[np.isfinite(rec.level)]) == 0.0)  # a varying force, not constant levels
    r = identify_dof(rec, "surge", cfg)
    assert r.method == "output-error"
    assert r.pool_time_s < 60.0  # 40 s run plus the settling
    m_true = cfg.vehicle.mass_kg + float(cfg.added_mass_matrix[0, 0])  # rigid + added mass of the vehicle file
    kq_true = float(cfg.dof_hydrodynamics("surge").quadratic_damping_positive)
    assert r.values["inertia"] == pytest.approx(m_true, rel=0.15)
    assert r.values["quadratic_damping"] == pytest.approx(kq_true, rel=0.15)
    # the dead-reckoned track stayed inside the pool box (truth position of the simulator)
    box = Campaign(cfg, dofs=["surge"]).executive.box
    pos = rec.truth_position_ned_m
    assert np.all((pos[:, 0] > box.x_min) & (pos[:, 0] < box.x_max))


def test_run_options_reach_the_campaign_and_the_graph_override():
    import argparse

    from hindrax_tools.commands import run as run_cmd
    from hindrax_onboard.commands.common import CommandError

    parser = argparse.ArgumentParser(prog="hindrax run")
    run_cmd.add_arguments(parser)
    args = parser.parse_args(["--dofs", "surge", "--excitation", "prbs", "--excitation-duration", "30"])
    assert (args.excitation, args.excitation_duration) == ("prbs", 30.0)
    assert parser.parse_args([]).excitation is None  # default: the vehicle file's identification.excitation
    with pytest.raises(SystemExit):
        parser.parse_args(["--excitation", "sweep"])
    bad = parser.parse_args(["--dofs", "surge", "--excitation-duration", "2"])
    with pytest.raises(CommandError, match="excitation-duration"):
        run_cmd._check_args(bad)


def test_excitation_table_scales_errors_to_100_s_of_pool_time():
    from hindrax_tools.commands.scenarios import format_excitation_table

    def row(param, err, std_fit, truth, covered):
        return {"dof": "surge", "parameter": param, "rel_error": err, "std": 99.0, "std_fit": std_fit,
                "truth": truth, "covered": covered, "pool_time_s": 400.0}

    results = [{"scenario": "none [prbs]", "excitation": "prbs", "seed": 1,
                "cases": [row("inertia", 0.02, 0.5, 25.0, True), row("quadratic_damping", -0.04, 2.0, 50.0, False),
                          row("linear_damping", 0.5, 1.0, 1.0, True)]}]
    lines = format_excitation_table(results).splitlines()
    assert len(lines) == 3  # header, rule, one row (linear damping is not compared)
    # 400 s of pool time: x sqrt(4) = 2 at 100 s; 1-sigma 0.5 / 25 = 2 %, 2 / 50 = 4 %
    assert lines[2] == ("| none | prbs | surge | 1 | 400 | 2.0 % | 4.0 % | 1/2 | 4.0 % | 8.0 % | 4.0 % / 8.0 % |")
