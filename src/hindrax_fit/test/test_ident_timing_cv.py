"""Input delay and thrust lag by output-error cross-validation, and a model that never loses to the 1-DOF model it
contains (docs/identification.md §7 step 1 and 4).

The data are built here, real-like and NOT from the model the fit assumes: a yaw channel measured by a gyro at 50 Hz
with white noise of 0.15 rad/s (a third of the rate's standard deviation), the commanded moment acting 0.25 s late
through a SECOND-order thrust spin-up (40 ms and 12 ms), a slowly wandering disturbance moment (Ornstein-Uhlenbeck,
5 s) and a bias of its own in every run; integrated at a tenth of the tick. On such a channel the equation-error
delay (the shift of the force minimising the residual of ``M a + k_q |v| v + k_l v + b = tau`` on the smoothed
rate and its derivative, computed here from its definition) is pulled late by the differentiated noise."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal
from scipy.integrate import solve_ivp

from hindrax_fit.fit import fit_core

H = 0.05
DELAY_S, LAG1_S, LAG2_S = 0.25, 0.04, 0.012
M, KL, KQ = 1.2, 0.8, 2.5  # N m s^2/rad, N m s/rad, N m s^2/rad^2
NOISE = 0.15  # rad/s


def _yaw_record(seed: int, runs: int = 4, run_s: float = 180.0) -> fit_core.DofRecord:
    rng = np.random.default_rng(seed)
    sub = 10
    dt = H / sub
    chunks = []
    for r in range(runs):
        n = int(run_s / H)
        tau = np.empty(n)  # a pilot: levels held 0.5-3 s, a quarter of them at rest, +-2 N m
        i = 0
        while i < n:
            k = int(rng.integers(10, 60))
            tau[i:i + k] = rng.uniform(-2.0, 2.0) if rng.random() > 0.25 else 0.0
            i += k
        bias = rng.normal(0.0, 0.15)
        late = np.concatenate([np.zeros(int(round(DELAY_S / dt))), np.repeat(tau, sub)])[:n * sub]
        a1, a2 = math.exp(-dt / LAG1_S), math.exp(-dt / LAG2_S)
        y1 = y2 = v = dist = 0.0
        rate = np.empty(n * sub)
        kick = rng.normal(0.0, 0.05 * math.sqrt(dt), n * sub)
        for j in range(n * sub):
            y1 = a1 * y1 + (1 - a1) * late[j]
            y2 = a2 * y2 + (1 - a2) * y1
            dist += -dist * dt / 5.0 + kick[j]
            v += dt * (y2 - bias + dist - KL * v - KQ * abs(v) * v) / M
            rate[j] = v
        t = np.arange(0.0, n * H - H, 0.02) + 0.007  # gyro at 50 Hz, not on the ticks
        z = rate[np.minimum((t / dt).astype(int), n * sub - 1)] + rng.normal(0.0, NOISE, t.size)
        zi = np.interp(np.arange(n) * H, t, z)
        chunks.append(fit_core.Chunk(tau, signal.savgol_filter(zi, 11, 2), np.zeros(n),
                                     signal.savgol_filter(zi, 11, 2, deriv=1, delta=H), t / H, z, group=r,
                                     t0=r * (run_s + 10.0)))
    return fit_core.DofRecord("yaw", H, "velocity", chunks, "wrench", run_count=runs)


def _equation_error_delay(rec: fit_core.DofRecord, max_ticks: int = 20) -> float:
    res = []
    for s in range(max_ticks + 1):
        rows, rhs = [], []
        for ch in rec.chunks:
            f = np.concatenate([np.zeros(s), ch.force[:ch.force.size - s]])
            rows.append(np.column_stack([ch.a, np.abs(ch.v) * ch.v, ch.v, np.ones_like(ch.v)])[s:])
            rhs.append(f[s:])
        X, y = np.concatenate(rows), np.concatenate(rhs)
        th, *_ = np.linalg.lstsq(X, y, rcond=None)
        res.append(float(np.mean((y - X @ th) ** 2)))
    return H * int(np.argmin(res))


@pytest.fixture(scope="module")
def yaw_fit():
    rec = _yaw_record(1)
    results, errors = fit_core.identify_dofs({"yaw": rec})
    assert not errors
    return rec, results["yaw"]


def test_the_equation_error_delay_goes_wrong_and_the_cross_validated_one_does_not(yaw_fit):
    rec, res = yaw_fit
    assert _equation_error_delay(rec) - DELAY_S > 0.05  # the case this test is about
    assert res.timing.source.startswith("estimated") and abs(res.timing.delay_s - DELAY_S) <= 0.05, res.timing
    assert not res.timing.at_edge
    # each grid point was scored: the lags searched include none and longer than the truth's
    lags = {lag for _d, lag, _s in res.timing.curve}
    assert 0.0 in lags and max(lags) >= 0.15


def test_the_chosen_model_never_predicts_held_out_runs_worse_than_the_nested_1dof_model(yaw_fit):
    _rec, res = yaw_fit
    hold = _yaw_record(2, runs=2)
    hold.runs_known = False  # new runs: the mean bias applies

    def held_out_nrmse(c):
        sd = fit_core.build_segments(hold, c.terms, res.timing, 10.0, None, excited_only=False)
        return fit_core.validation_measures(sd, fit_core.predict_validation(sd, c.layout, c.fit.theta))["nrmse"]

    nested = [c for c in res.candidates if c.terms == fit_core.Terms("both")]
    assert len(nested) == 1
    assert held_out_nrmse(res.chosen) <= held_out_nrmse(nested[0]) + 0.005
    assert res.chosen.mse <= nested[0].mse  # and in cross-validation, by construction


def test_a_richer_model_with_a_worse_cross_validation_gives_way_to_the_nested_one(yaw_fit):
    _rec, res = yaw_fit
    nested = next(c for c in res.candidates if c.terms == fit_core.Terms("both"))
    richer = next(c for c in res.candidates if c.terms != nested.terms)
    worse = fit_core.Candidate(richer.terms, richer.layout, richer.fit, richer.train, richer.val,
                               richer.fold_theta, richer.fold_sse + nested.fold_sse, richer.fold_n, richer.cv, [])
    assert fit_core.not_below_nested(worse, res.candidates) is nested
    better = fit_core.Candidate(richer.terms, richer.layout, richer.fit, richer.train, richer.val,
                                richer.fold_theta, 0.5 * nested.fold_sse, nested.fold_n, richer.cv, [])
    assert fit_core.not_below_nested(better, res.candidates) is better


def test_where_the_truth_is_in_the_model_class_the_search_and_the_fit_find_it():
    """Noise-free yaw runs of the 1-DOF model itself (solve_ivp, the lagged moment a state), delay and lag on the
    coarse grid: the warm-started timing search lands on them and the output-error fit on the parameters."""
    delay, lag, bias = 0.2, 0.05, 0.1
    rng = np.random.default_rng(3)
    chunks = []
    for r in range(3):
        n = int(60.0 / H)
        tau = np.repeat(rng.uniform(-2.0, 2.0, n // 30 + 1), 30)[:n]  # levels held 1.5 s, at rest before
        tau[:30] = 0.0
        late = np.concatenate([np.zeros(int(round(delay / H))), tau])

        def rhs(t, y):
            c = late[min(int(t / H + 1e-9), n - 1)]
            return [(c - y[0]) / lag, (y[0] - bias - KL * y[1] - KQ * abs(y[1]) * y[1]) / M]

        t = np.arange(n) * H
        sol = solve_ivp(rhs, (0.0, t[-1]), [0.0, 0.0], t_eval=t, rtol=1e-9, atol=1e-11, max_step=H / 4)
        v = sol.y[1]
        a = np.array([rhs(ti, yi)[1] for ti, yi in zip(t, sol.y.T)])
        chunks.append(fit_core.Chunk(tau, v, np.zeros(n), a, np.arange(0.0, n, 2.0), v[::2], group=r, t0=70.0 * r,
                                     force_start=0.0))
    rec = fit_core.DofRecord("yaw", H, "velocity", chunks, "wrench", run_count=3)
    res = fit_core.identify_dof(rec, fit_core.CoreOptions(select=False, max_delay_s=0.6))
    assert (res.timing.delay_s, res.timing.lag_s) == (delay, lag), res.timing
    assert res.theta == pytest.approx([M, KQ, KL, bias], rel=0.01)
