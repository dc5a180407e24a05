"""Batched output-error fits of the 1-DOF model over a grid of input timings (the timing search of :mod:`.fit_core`).

The model is the one-page gray-box model ``M v' = u(t) - k_q |v| v - k_l v - b`` with ``u`` the commanded force
through a pure delay and a first-order lag (each grid point its own input). For every grid point g and every
cross-validation fold k one fit on the fold's training segments (segment-wise simulation error, each segment
simulated open loop from its initial state, classical RK4 with the force at the start, middle and end of each tick,
compared with each measurement at its own time), then the fold's held-out segments predicted: the cross-validated
simulation error of each timing. All G x K fits run at once as arrays (one simulation per iteration for all of
them), a projected Levenberg-Marquardt on forward-difference Jacobians (M > 0, k_q, k_l >= 0), so that a grid of
timings costs a few simulations of the whole data set rather than G x K fits one by one.

Shapes: U (3, G, m, L) the input force at the start, middle and end of each of L ticks of m segments for G grid
points; v0 (m,) initial velocities; samples (s_seg, s_j, s_a, s_z) (n,) each measurement's segment, tick, fraction
of the tick and value; masks (K, m) the segments each fold fits (or predicts); theta (G, K, p) [M, k_q, k_l, b]
(roll, pitch: and the restoring stiffness). Pure numpy; SI units (N or N m, m/s or rad/s)."""
from __future__ import annotations

import numpy as np

__all__ = ["rk4_step", "simulate_batch", "fit_batch", "held_out_sse"]

#: Levenberg-Marquardt iterations of one batch at most (each one simulation of every problem and its perturbations).
#: From the equation-error start 12 left the fits of a noisy, idle-heavy record short of their optimum: the
#: cross-validated curve jagged by more than its slope near the truth and the delay 0.15 s off (src/hindrax_fit/test/
#: test_cv_like_holdout.py); ``WARM_ITERATIONS`` from a converged fit at a neighbouring timing
ITERATIONS, WARM_ITERATIONS = 40, 15


def rk4_step(stage, u0, um, u1, v, h: float, k: tuple, w: np.ndarray) -> np.ndarray:
    """One classical RK4 step of v' = f(u, v), in place: ``stage(u, vv, out)`` writes f into
    ``out``; ``u0``, ``um``, ``u1`` the inputs at the start, middle and end of the tick. The stages
    go into the buffers ``k`` (k1..k4, shaped as ``v``), the increment h/6 (k1 + 2 (k2 + k3) + k4)
    into ``w``, which is returned; ``v`` is left as it is."""
    k1, k2, k3, k4 = k
    hh = 0.5 * h
    stage(u0, v, k1)
    np.multiply(hh, k1, out=w)
    w += v
    stage(um, w, k2)
    np.multiply(hh, k2, out=w)
    w += v
    stage(um, w, k3)
    np.multiply(h, k3, out=w)
    w += v
    stage(u1, w, k4)
    np.add(k2, k3, out=w)
    w *= 2.0
    w += k1
    w += k4
    w *= h / 6.0
    return w


def simulate_batch(U: np.ndarray, v0: np.ndarray, theta: np.ndarray, h: float,
                   cols: np.ndarray | None = None) -> np.ndarray:
    """Velocities (G, B, m, L) of the 1-DOF model for parameter sets ``theta`` (G, B, 4 + c) driven by U (3, G, m, L)
    from ``v0`` (m,) (module docstring); ``cols`` (3, m, L, c): regressors whose parameters theta[..., 4:] add to the
    force (the restoring moment -s(eta) of roll and pitch). States bounded (a diverging trial stays finite)."""
    G, B = theta.shape[:2]
    m, L = U.shape[2], U.shape[3]
    inv_m = (1.0 / theta[..., 0])[..., None]
    kq, kl, b = (theta[..., i][..., None] for i in (1, 2, 3))
    Ut = np.ascontiguousarray(np.moveaxis(U, -1, 1))[:, :, :, None, :]  # (3, L, G, 1, m)
    if cols is not None and cols.shape[-1]:
        Ut = Ut + np.moveaxis(np.einsum("smlc,gbc->sgbml", cols, theta[..., 4:]), -1, 1)
    v = np.broadcast_to(v0, (G, B, m)).copy()
    V = np.empty((L, G, B, m))
    V[0] = v
    bound = 1e3 * (float(np.max(np.abs(v0))) + 1.0)
    u0, um, u1, w, *k = (np.empty((G, B, m)) for _ in range(8))

    def stage(u, vv, out):  # (u - (kq |vv| + kl) vv) / M, in place
        np.abs(vv, out=out)
        out *= kq
        out += kl
        out *= vv
        np.subtract(u, out, out=out)
        out *= inv_m

    with np.errstate(all="ignore"):
        for i in range(L - 1):
            np.subtract(Ut[0, i], b, out=u0)
            np.subtract(Ut[1, i], b, out=um)
            np.subtract(Ut[2, i], b, out=u1)
            v += rk4_step(stage, u0, um, u1, v, h, k, w)
            np.minimum(np.maximum(v, -bound, out=v), bound, out=v)
            V[i + 1] = v
    return np.moveaxis(V, 0, -1)


def tick_weights(samples: tuple, m: int, L: int) -> tuple:
    """The measurements as quadratic forms on the ticks: each measurement z at tick j + a compares with
    (1 - a) V_j + a V_(j+1), so sum (that - z)^2 over a segment = V.(D0 V) + 2 V_j D1_j V_(j+1) - 2 q.V + c, with
    D0, D1, q (m, L) and c (m,). Returns (D0, D1, q, c): the simulation error at L ticks instead of every
    measurement."""
    s_seg, s_j, s_a, s_z = samples
    D0, D1, q = np.zeros((m, L)), np.zeros((m, L)), np.zeros((m, L))
    np.add.at(D0, (s_seg, s_j), (1.0 - s_a) ** 2)
    np.add.at(D0, (s_seg, s_j + 1), s_a ** 2)
    np.add.at(D1, (s_seg, s_j), (1.0 - s_a) * s_a)
    np.add.at(q, (s_seg, s_j), (1.0 - s_a) * s_z)
    np.add.at(q, (s_seg, s_j + 1), s_a * s_z)
    return D0, D1, q, np.bincount(s_seg, weights=s_z * s_z, minlength=m)


def _apply(tw, V):
    """(Q V - q) for V (..., m, L) with Q the tridiagonal form of :func:`tick_weights`."""
    D0, D1, q, _c = tw
    out = D0 * V
    out -= q
    d1 = D1[:, :-1]
    t = d1 * V[..., 1:]
    out[..., :-1] += t
    out[..., 1:] += np.multiply(d1, V[..., :-1], out=t)
    return out


def _cost(tw, V, w):
    """Weighted simulation error (G, B) of V (G, B, m, L) with segment weights w (B, m)."""
    per = np.sum(V * (_apply(tw, V) - tw[2]), axis=-1) + tw[3]  # (G, B, m)
    return np.sum(per * w, axis=-1)


def fit_batch(U: np.ndarray, v0: np.ndarray, samples: tuple, masks: np.ndarray, theta0: np.ndarray, h: float,
              cols: np.ndarray | None = None, iterations: int = ITERATIONS) -> np.ndarray:
    """Least-squares simulation-error fits (G, K, p) of every grid point's input U[:, g] on every fold's training
    segments ``masks`` (K, m) from ``theta0`` (G, p) or (G, K, p), p = 4 + the columns of ``cols`` (bounded below by
    0, as the restoring stiffness), in at most ``iterations`` steps (module docstring)."""
    G, K = U.shape[1], masks.shape[0]
    m, L = U.shape[2], U.shape[3]
    p = theta0.shape[-1]
    tw = tick_weights(samples, m, L)
    w = masks.astype(float)  # (K, m) the fold's training segments
    lower = np.concatenate([[1e-6, 0.0, 0.0, -np.inf], np.zeros(p - 4)])
    vmax = float(np.max(np.abs(samples[3]))) if samples[3].size else 1.0

    def resolvable(t):  # inertia at least the damping over the tick: RK4 stays stable (time constant >= h / 2)
        t[..., 0] = np.maximum(t[..., 0], 0.5 * h * (t[..., 2] + 2.0 * t[..., 1] * vmax))
        return t

    th0 = np.maximum(theta0, lower)
    th = resolvable((th0 if th0.ndim == 3 else np.repeat(th0[:, None, :], K, axis=1)).copy())
    V = simulate_batch(U, v0, th, h, cols)
    cost = _cost(tw, V, w)
    lam = np.full((G, K), 1e-3)
    eye = np.eye(p)
    wk = np.repeat(w, L, axis=1)[None, :, None, :]  # (1, K, 1, m L)
    for _ in range(iterations):
        d = 1e-6 * np.maximum(np.abs(th), 1e-3 * np.maximum(np.abs(th[..., :1]), 1e-6))
        P = th[:, :, None, :] + d[:, :, None, :] * eye  # (G, K, p, p) one parameter stepped per set
        VP = simulate_batch(U, v0, P.reshape(G, K * p, p), h, cols).reshape(G, K, p, m, L)
        dV = ((VP - V[:, :, None]) / d[..., None, None]).reshape(G, K, p, m * L)
        QdV = _apply(tw, dV.reshape(G, K, p, m, L)) + tw[2]  # Q dV (the q of _apply cancelled)
        A = dV @ (QdV.reshape(G, K, p, m * L) * wk).swapaxes(-1, -2)
        g = np.einsum("gkpn,gkn->gkp", dV * wk, _apply(tw, V).reshape(G, K, m * L))
        dg = np.maximum(np.einsum("gkpp->gkp", A), 1e-30)
        step = -np.linalg.solve(A + lam[..., None, None] * dg[..., :, None] * eye, g[..., None])[..., 0]
        trial = np.maximum(th + step, lower)
        trial[..., 0] = np.maximum(trial[..., 0], 0.1 * th[..., 0])
        trial = resolvable(trial)
        Vt = simulate_batch(U, v0, trial, h, cols)
        ct = _cost(tw, Vt, w)
        ok = np.isfinite(ct) & (ct < cost)
        done = (ok & (cost - ct < 1e-6 * cost)) | (~ok & (lam >= 1e3))
        th = np.where(ok[..., None], trial, th)
        V = np.where(ok[..., None, None], Vt, V)
        cost = np.where(ok, ct, cost)
        lam = np.where(ok, np.maximum(lam / 3.0, 1e-9), lam * 10.0)
        if np.all(done):
            break
    return th


def held_out_sse(U: np.ndarray, v0: np.ndarray, samples: tuple, masks: np.ndarray, theta: np.ndarray,
                 h: float, cols: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Squared simulation error (G, K) of each fold's fit ``theta`` (G, K, p) on its held-out segments ``masks``
    (K, m) of the validation input U (3, G, m, L) (and ``cols``), and the number of measurements (K,)."""
    tw = tick_weights(samples, U.shape[2], U.shape[3])
    w = masks.astype(float)
    sse = _cost(tw, simulate_batch(U, v0, theta, h, cols), w)
    return sse, w @ np.bincount(samples[0], minlength=U.shape[2]).astype(float)
