"""Cross-validation that scores what the held-out runs score (issue 72 point 2; docs/identification.md §7 steps 1
and 4).

The data are vehicle B's as its open-loop pool runs show them, built here and NOT from the model the fit assumes:
a yaw channel whose commanded moment is held in levels of 1-4 s with idle stretches of 3-12 s between them, acting
0.25 s late through a first-order spin-up of 40 ms, through a deadband, a thrust error per direction of up to 25 %
and a saturation; a tether moment wandering within each run (Ornstein-Uhlenbeck, 20 s); a gyro with a bias of its
own in every run and white noise, read at the times of a DVL reporting at about 5 Hz with a sixth of its reports
lost (the reader interpolates the gyro onto the DVL's times); integrated at a tenth of the tick."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal

from hindrax_fit.fit import fit_core

H = 0.05
DELAY_S, LAG_S = 0.25, 0.04
M, KL, KQ = 1.2, 0.8, 2.5  # N m s^2/rad, N m s/rad, N m s^2/rad^2


def _runs(seed: int, runs: int, run_s: float = 40.0, driven: tuple = ()) -> fit_core.DofRecord:
    """``runs`` runs of ``run_s`` s; with ``driven``, only those runs drive yaw (a campaign's runs of one DOF in a
    row), the others drift on the tether and the gyro's bias."""
    rng = np.random.default_rng(seed)
    sub = 10
    dt = H / sub
    chunks = []
    for r in range(runs):
        n = int(run_s / H)
        tau = np.zeros(n)
        i = 0
        while i < n and (not driven or r in driven):  # levels of 0.7-3.6 N m held 1-4 s, idle stretches of 3-12 s
            if rng.random() < 0.5:
                i += int(rng.uniform(3.0, 12.0) / H)
                continue
            k = int(rng.uniform(1.0, 4.0) / H)
            tau[i:i + k] = rng.uniform(0.7, 3.6) * rng.choice([-1.0, 1.0])
            i += k
        gain = 1.0 + rng.uniform(-0.25, 0.25, 2)  # per direction
        act = np.where(np.abs(tau) < 0.3, 0.0, tau)
        act = np.clip(np.where(act > 0, gain[0] * act, gain[1] * act), -2.5, 2.5)
        late = np.concatenate([np.zeros(int(round(DELAY_S / dt))), np.repeat(act, sub)])[:n * sub]
        a1 = math.exp(-dt / LAG_S)
        y = v = 0.0
        tether = rng.normal(0.0, 0.3)
        kick = rng.normal(0.0, 0.3 * math.sqrt(2.0 * dt / 20.0), n * sub)
        rate = np.empty(n * sub)
        for j in range(n * sub):
            y = a1 * y + (1.0 - a1) * late[j]
            tether += -tether * dt / 20.0 + kick[j]
            v += dt * (y + tether - KL * v - KQ * abs(v) * v) / M
            rate[j] = v
        t, tt = [], rng.uniform(0.0, 0.2)  # DVL report times: 5 Hz +-50 %, a sixth lost
        while tt < n * H - H:
            if rng.random() > 0.15:
                t.append(tt)
            tt += rng.uniform(0.1, 0.3)
        t = np.array(t)
        z = rate[np.minimum((t / dt).astype(int), n * sub - 1)] + rng.normal(0.0, 0.01) + rng.normal(0.0, 0.03, t.size)
        grid = np.arange(int(math.ceil(t[0] / H)), int(t[-1] / H) + 1) * H
        zi = np.interp(grid, t, z)
        k0 = int(round(grid[0] / H))
        sel = (t >= grid[0]) & (t <= grid[-1])
        chunks.append(fit_core.Chunk(tau[k0:k0 + grid.size].copy(), signal.savgol_filter(zi, 11, 2),
                                     np.zeros(grid.size), signal.savgol_filter(zi, 11, 2, deriv=1, delta=H),
                                     (t[sel] - grid[0]) / H, z[sel], group=r, t0=grid[0]))
    return fit_core.DofRecord("yaw", H, "velocity", chunks, "wrench", run_count=runs)


@pytest.fixture(scope="module")
def fitted():
    rec = _runs(1, runs=4)
    res = fit_core.identify_dof(rec, fit_core.CoreOptions(select=False, max_delay_s=0.6))
    hold = _runs(2, runs=4)
    hold.runs_known = False  # new runs: the mean bias
    sd = fit_core.build_segments(hold, res.terms, res.timing, fit_core.VALIDATION_S, excited_only=False)
    held_out = fit_core.validation_measures(sd, fit_core.predict_validation(sd, res.chosen.layout, res.theta))
    return res, held_out


def test_the_delay_is_found_within_one_grid_step(fitted):
    res, _ = fitted
    # delay + lag: what the low frequencies see of both (0.29 s); 12 cold Levenberg-Marquardt steps per grid point left
    # the fits short of their optimum and gave 0.20 + 0.275 s
    assert abs(res.timing.delay_s + res.timing.lag_s - DELAY_S - LAG_S) <= fit_core.DELAY_STEP_S, res.timing
    assert abs(res.timing.delay_s - DELAY_S) <= fit_core.DELAY_STEP_S, res.timing


def test_cross_validation_scores_what_the_held_out_runs_score(fitted):
    res, held_out = fitted
    assert res.cv["samples"] > 0.5 * held_out["samples"]  # every segment of the runs held out, moving or not
    assert abs(res.cv["nrmse"] - held_out["nrmse"]) <= 0.06, (res.cv["nrmse"], held_out["nrmse"])
    assert res.cv["nrmse"] < 0.5 * res.cv["nrmse_hold"]


def test_folds_hold_out_whole_runs_with_every_segment_and_the_mean_bias():
    """Three runs of 30 s, the second idle for its last 20 s: the folds are the runs, idle segments included, and a
    held-out run is predicted with the mean bias, as ``ident predict`` predicts a new run."""
    n = 600
    chunks = []
    for r in range(3):
        force = np.where(np.arange(n) % 80 < 40, 2.0, -2.0)
        if r == 1:
            force[200:] = 0.0
        v = 0.3 * np.sign(force)
        chunks.append(fit_core.Chunk(force, v, np.zeros(n), np.zeros(n), np.arange(0.0, n, 2.0), v[::2], group=r))
    rec = fit_core.DofRecord("yaw", H, "velocity", chunks, "wrench", run_count=3)
    terms = fit_core.Terms("linear", run_bias=True)
    sv = fit_core.build_segments(rec, terms, fit_core.Timing(), 10.0, excited_only=False)
    st = fit_core.build_segments(rec, terms, fit_core.Timing(), 10.0)
    assert not sv.excited.all()  # the idle part of run 2
    folds = fit_core.make_folds(st, sv, 4)
    assert [sorted(set(sv.group[h].tolist())) for h in folds.held] == [[0], [1], [2]]
    assert sum(h.size for h in folds.held) == sv.m  # every segment scored once, moving or not
    for h, t in zip(folds.held, folds.train):
        assert not set(st.group[t].tolist()) & set(sv.group[h].tolist())
    layout = fit_core.parameter_layout("yaw", terms, n_runs=3)
    full = fit_core.FitOutcome(layout, np.array([1.0, 0.5, 0.0, 0.4, -0.4]), None, np.zeros(1), np.ones(1),
                               np.zeros((1, 5)), 1.0)
    th, sse, nn, _sst, _notes = fit_core._cv(st, sv, folds, "yaw", layout, full, False)
    assert np.all(nn > 0)
    # the held-out run's prediction equals the one with its per-run columns zero (the mean bias)
    va = sv.subset(folds.held[0])
    va.cols[...] = 0.0
    mean_bias = fit_core.validation_measures(va, fit_core.predict_validation(va, layout, th[0]))
    assert sse[0] == pytest.approx(mean_bias["sse"], rel=1e-12)


def test_a_campaign_driving_the_dof_in_three_runs_of_eleven_cross_validates_as_its_held_out_runs():
    """Eleven runs of 60 s of which only the last three drive yaw, as a campaign's yaw runs come in a row; eleven
    more alike held out. Before whole-run folds dealt by drive (bd95da7, e702a40) the fit's CV said 0.868 with
    holding at 0.998, "barely beats holding", while the same model predicted the held-out runs at 0.529 (issue 72's
    vehicle B: CV 0.617, holding 0.616, held-out 0.480); now CV 0.582 against held-out 0.533."""
    rec = _runs(1, runs=11, run_s=60.0, driven=(8, 9, 10))
    res = fit_core.identify_dof(rec, fit_core.CoreOptions(select=False, max_delay_s=0.6))
    hold = _runs(2, runs=11, run_s=60.0, driven=(8, 9, 10))
    hold.runs_known = False
    sd = fit_core.build_segments(hold, res.terms, res.timing, fit_core.VALIDATION_S, excited_only=False)
    held_out = fit_core.validation_measures(sd, fit_core.predict_validation(sd, res.chosen.layout, res.theta))
    assert abs(res.cv["nrmse"] - held_out["nrmse"]) <= 0.1, (res.cv["nrmse"], held_out["nrmse"])
    assert res.cv["nrmse"] < 0.7 * res.cv["nrmse_hold"], (res.cv["nrmse"], res.cv["nrmse_hold"])
