"""An independent gray-box 1-DOF baseline for the identification benchmarks: the yardstick ``hindrax ident fit``
must not lose to.

Model (one DOF, [Fossen2011] eq. 6.1 reduced to one axis, no coupling)::

    M v' = u(t) - k_l v - k_q |v| v - b,    T u' = tau(t - d) - u

with ``tau`` the commanded force (N or N m), ``d`` a pure delay (s) and ``T`` a first-order thrust lag (s). The
four parameters are fitted by simulation error (each segment simulated open loop from the measured velocity at its
start) with :func:`scipy.optimize.least_squares` and forward sensitivities; ``d`` and ``T`` are chosen on a grid by
leave-one-run-out cross-validation on the training runs only, each grid point a full fit.

It shares nothing with the estimator under test but the input record (:class:`~hindrax_fit.fit.
fit_core.DofRecord`: the commanded force on the tick grid, the smoothed velocity for the initial states, the
measurements at their own times) and the vehicle's first-order lag filter (:class:`~hindrax_onboard.vehicle.
thrust_lag.ThrustLag`): its own delay, its own simulation, its own least squares, its own timing search and score.
Score (:func:`nrmse`): RMS(predicted - measured) / std(measured) pooled over every measurement after the start of
its segment; segments of ``segment_s`` from each chunk's start, a last part of at least half a segment kept (the
rule of ``hindrax ident predict --segment-s``, docs/identification.md §4).

No maintained library fits a simulation-error gray-box model with a delay and lag grid (python-control and SIPPY
identify linear models only), hence this module."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import optimize

from hindrax_onboard.vehicle.thrust_lag import ThrustLag

#: Delay grid, s, and thrust-lag grid, s, of the cross-validation
DELAYS_S = tuple(round(0.05 * k, 2) for k in range(13))
LAGS_S = (0.0, 0.04, 0.1, 0.2, 0.4)


@dataclass
class _Segments:
    """Segments of one record stacked for a vectorised simulation: u (m, L) the delayed, lagged force over each tick;
    v0 (m,) the initial velocities; seg, pos, z (k,) each measurement's segment, fractional tick from its segment's
    start and value; group (m,) the run of each segment."""

    u: np.ndarray
    v0: np.ndarray
    seg: np.ndarray
    pos: np.ndarray
    z: np.ndarray
    group: np.ndarray


def _delayed_lagged(force: np.ndarray, h: float, delay_s: float, lag_s: float) -> np.ndarray:
    """The force delayed by ``delay_s`` (linear interpolation between ticks, the first value held before the start)
    then through the first-order lag ``lag_s`` (exact for a force held over each tick, settled at the start)."""
    n = force.size
    src = np.arange(n) - delay_s / h
    f = np.interp(src, np.arange(n), force, left=force[0])
    return ThrustLag(lag_s).over_ticks(f, h, float(f[0]))[0]


def segments(rec, delay_s: float, lag_s: float, segment_s: float = 10.0) -> _Segments:
    """Cut ``rec`` (a DofRecord with a measured velocity) into segments of ``segment_s`` for the delay and lag.
    Raises ValueError for a measured position (the baseline predicts velocities only) or no segment."""
    if rec.measured != "velocity":
        raise ValueError(f"gray-box baseline: measured {rec.measured!r}, only a measured velocity is supported")
    h = rec.h
    L = max(10, int(round(segment_s / h)))
    U, V0, SEG, POS, Z, G = [], [], [], [], [], []
    for ch in rec.chunks:
        n = ch.force.size
        u = _delayed_lagged(np.asarray(ch.force, float), h, delay_s, lag_s)
        for s in range(0, n, L):
            e = min(n, s + L)
            if e - s < L // 2:
                break
            sel = (ch.sample_pos > s) & (ch.sample_pos <= e - 1) & np.isfinite(ch.sample_z)
            if not sel.any() or not np.isfinite(ch.v[s]):
                continue
            uu = np.zeros(L)
            uu[:e - s] = u[s:e]
            uu[e - s:] = u[e - 1]
            k = len(U)
            U.append(uu)
            V0.append(ch.v[s])
            SEG.append(np.full(int(sel.sum()), k))
            POS.append(ch.sample_pos[sel] - s)
            Z.append(ch.sample_z[sel])
            G.append(ch.group)
    if not U:
        raise ValueError("gray-box baseline: no segment with measurements")
    return _Segments(np.array(U), np.array(V0, float), np.concatenate(SEG), np.concatenate(POS),
                     np.concatenate(Z), np.array(G))


def _simulate(theta: np.ndarray, sg: _Segments, h: float, sens: bool):
    """Velocities (m, L) of v' = a u - c1 v - c2 |v| v - c0 with theta = (a, c1, c2, c0) = (1/M, k_l/M, k_q/M, b/M)
    by Heun's method; with ``sens`` also dv/dtheta (4, m, L)."""
    a, c1, c2, c0 = theta
    m, L = sg.u.shape
    V = np.empty((m, L))
    S = np.zeros((4, m, L)) if sens else None
    v = sg.v0.copy()
    s = np.zeros((4, m))
    for j in range(L):
        V[:, j] = v
        if sens:
            S[:, :, j] = s
        if j == L - 1:
            break
        u = sg.u[:, j]

        def f(vv):
            return a * u - c1 * vv - c2 * np.abs(vv) * vv - c0

        k1 = f(v)
        vp = v + h * k1
        k2 = f(vp)
        if sens:
            def fs(vv, ss):
                dfdv = -c1 - 2.0 * c2 * np.abs(vv)
                direct = np.stack([u, -vv, -np.abs(vv) * vv, -np.ones_like(vv)])
                return dfdv * ss + direct

            l1 = fs(v, s)
            l2 = fs(vp, s + h * l1)
            s = s + 0.5 * h * (l1 + l2)
        v = v + 0.5 * h * (k1 + k2)
        v = np.clip(v, -50.0, 50.0)
    return V, S


def _at_samples(X: np.ndarray, sg: _Segments) -> np.ndarray:
    """Values of X (..., m, L) at the measurements' fractional ticks (linear interpolation)."""
    L = X.shape[-1]
    j0 = np.clip(np.floor(sg.pos).astype(int), 0, L - 2)
    w = sg.pos - j0
    return X[..., sg.seg, j0] * (1 - w) + X[..., sg.seg, j0 + 1] * w


def _initial_theta(sg: _Segments, h: float) -> np.ndarray:
    """Equation-error start: least squares of the finite-difference acceleration of the segments' first ticks."""
    z = sg.z
    # one-step velocities from consecutive samples of a segment
    order = np.lexsort((sg.pos, sg.seg))
    seg, pos, zz = sg.seg[order], sg.pos[order], z[order]
    same = (seg[1:] == seg[:-1]) & (pos[1:] - pos[:-1] > 0)
    dv = (zz[1:] - zz[:-1])[same] / ((pos[1:] - pos[:-1])[same] * h)
    vm = 0.5 * (zz[1:] + zz[:-1])[same]
    j = np.clip(pos[:-1][same].astype(int), 0, sg.u.shape[1] - 1)
    um = sg.u[seg[:-1][same], j]
    A = np.column_stack([um, -vm, -np.abs(vm) * vm, -np.ones_like(vm)])
    th, *_ = np.linalg.lstsq(A, dv, rcond=None)
    th[0] = max(th[0], 1e-4)
    th[1] = max(th[1], 0.0)
    th[2] = max(th[2], 0.0)
    return th


def fit(sg: _Segments, h: float, theta0: np.ndarray | None = None) -> np.ndarray:
    """theta (4,) = (1/M, k_l/M, k_q/M, b/M) minimising the simulation error of ``sg``; bounds a > 0, c1, c2 >= 0."""
    th0 = _initial_theta(sg, h) if theta0 is None else theta0

    def res(th):
        V, _ = _simulate(th, sg, h, False)
        return _at_samples(V, sg) - sg.z

    def jac(th):
        _, S = _simulate(th, sg, h, True)
        return _at_samples(S, sg).T

    lo = np.array([1e-6, 0.0, 0.0, -np.inf])
    th0 = np.clip(th0, lo + 1e-9, np.inf)
    out = optimize.least_squares(res, th0, jac=jac, bounds=(lo, np.full(4, np.inf)), method="trf",
                                 x_scale="jac", max_nfev=60)
    return out.x


def nrmse(theta: np.ndarray, sg: _Segments, h: float) -> tuple[float, float]:
    """(sum of squared errors, sum of squares about the mean) of ``theta``'s predictions on ``sg``."""
    V, _ = _simulate(theta, sg, h, False)
    e = _at_samples(V, sg) - sg.z
    return float(np.sum(e ** 2)), float(np.sum((sg.z - sg.z.mean()) ** 2))


def choose_timing(train, delays=DELAYS_S, lags=LAGS_S) -> tuple[float, float, float]:
    """(delay_s, lag_s, CV nrmse) minimising the leave-one-run-out simulation error on ``train`` (a DofRecord whose
    chunks' ``group`` are the runs; one run: the chunks split in halves instead)."""
    groups = sorted({ch.group for ch in train.chunks})
    best = (math.inf, 0.0, 0.0)
    for d in delays:
        for T in lags:
            sg = segments(train, d, T)
            if len(groups) >= 2:
                folds = [sg.group == g for g in groups]
            else:
                half = np.arange(sg.u.shape[0]) < sg.u.shape[0] // 2
                folds = [half, ~half]
            sse = sst = 0.0
            th = None
            for test in folds:
                if test.all() or not test.any():
                    continue
                th = fit(_subset(sg, ~test), train.h, th)
                a, b = nrmse(th, _subset(sg, test), train.h)
                sse, sst = sse + a, sst + b
            score = math.sqrt(sse / sst) if sst > 0 else math.inf
            if score < best[0]:
                best = (score, d, T)
    return best[1], best[2], best[0]


def _subset(sg: _Segments, keep: np.ndarray) -> _Segments:
    """The segments ``keep`` (m,) bool of ``sg``, renumbered."""
    new = -np.ones(keep.size, int)
    new[keep] = np.arange(int(keep.sum()))
    sel = keep[sg.seg]
    return _Segments(sg.u[keep], sg.v0[keep], new[sg.seg[sel]], sg.pos[sel], sg.z[sel], sg.group[keep])


def holdout_nrmse(train, holdout, segment_s: float = 10.0, delays=DELAYS_S, lags=LAGS_S) -> dict:
    """Fit the gray-box model on ``train`` (timing by CV on its runs) and predict ``holdout`` (DofRecords of one DOF,
    measured velocity): {"nrmse", "cv_nrmse", "delay_s", "lag_s", "mass", "linear_damping", "quadratic_damping",
    "bias"}; mass in kg (kg m^2), damping per :class:`~hindrax_fit.fit.fit_core.Terms`' units.
    ``delays``, ``lags``: the timing grid, s. Raises ValueError when either record cannot be cut into segments."""
    d, T, cv = choose_timing(train, delays, lags)
    th = fit(segments(train, d, T, segment_s), train.h)
    sse, sst = nrmse(th, segments(holdout, d, T, segment_s), holdout.h)
    M = 1.0 / th[0]
    return {"nrmse": math.sqrt(sse / sst) if sst > 0 else math.nan, "cv_nrmse": cv, "delay_s": d, "lag_s": T,
            "mass": M, "linear_damping": th[1] * M, "quadratic_damping": th[2] * M, "bias": th[3] * M}
