"""An independent reference integrator of free decays for the identification tests (their records are generated here,
not by the code under test)."""
from __future__ import annotations

import numpy as np


def rk4_decay(k, M, b1, b2, x0, duration_s, fs_hz, substeps=20):
    """Samples (t, x, v, a), each (n,), of M x'' + b1 x' + b2 |x'| x' + k x = 0 released from rest at ``x0``, sampled at
    ``fs_hz`` for ``duration_s``: classical fixed-step Runge-Kutta 4 with ``substeps`` steps per sample (independent of
    scipy, which the fits use)."""
    def f(x, v):
        return v, -(k * x + b1 * v + b2 * abs(v) * v) / M

    n = int(round(duration_s * fs_hz))
    h = 1.0 / fs_hz / substeps
    x, v = x0, 0.0
    xs, vs, acc = np.empty(n), np.empty(n), np.empty(n)
    for i in range(n):
        xs[i], vs[i], acc[i] = x, v, f(x, v)[1]
        for _ in range(substeps):
            k1 = f(x, v)
            k2 = f(x + 0.5 * h * k1[0], v + 0.5 * h * k1[1])
            k3 = f(x + 0.5 * h * k2[0], v + 0.5 * h * k2[1])
            k4 = f(x + h * k3[0], v + h * k3[1])
            x += h / 6.0 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
            v += h / 6.0 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
    return np.arange(n) / fs_hz, xs, vs, acc
