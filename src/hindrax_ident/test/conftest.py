"""Fixtures of the hindrax_ident tests.

``synthetic_runs``: the pieces the identification tests build their data from, each from its definition and none
from the code under test: a pilot's held force steps, the exact response of a first-order model to a force held
over each tick, and a record chunk (:class:`~hindrax_ident.identification.fit.fit_core.Chunk`) of that velocity measured
at half the tick rate with white noise and smoothed (Savitzky-Golay) as the readers smooth it.
"""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest


def _steps(rng: np.random.Generator, n: int, lo: float, hi: float) -> np.ndarray:
    """(n,) a force held for 20-80 ticks at a time, each level uniform in [lo, hi] (N)."""
    out = np.empty(n)
    i = 0
    while i < n:
        k = int(rng.integers(20, 80))
        out[i:i + k] = rng.uniform(lo, hi)
        i += k
    return out


def _first_order(force: np.ndarray, inertia: float, damping: float, h: float, offset: float = 0.0) -> np.ndarray:
    """(n,) velocity of ``inertia v' = force - offset - damping v`` from rest, exact for a force held over each
    tick of ``h`` s."""
    e = math.exp(-damping / inertia * h)
    v = np.zeros(force.size)
    for j in range(1, force.size):
        v[j] = v[j - 1] * e + (1.0 - e) * (force[j - 1] - offset) / damping
    return v


def _measured_chunk(rng: np.random.Generator, v: np.ndarray, force: np.ndarray, h: float, noise: float, **chunk):
    """A fit-core chunk of ``force`` whose velocity ``v`` (n,) is measured every second tick with white noise of
    ``noise`` (m/s); smoothed velocity and acceleration by an 11-tick quadratic Savitzky-Golay filter of the
    measurements interpolated onto the ticks. ``chunk``: further :class:`~.fit_core.Chunk` fields (group, t0, ...)."""
    from scipy import signal

    from hindrax_ident.identification.fit import fit_core

    n = v.size
    meas = np.arange(0, n, 2)
    z = v[meas] + rng.normal(0.0, noise, meas.size)
    zi = np.interp(np.arange(n), meas, z)
    return fit_core.Chunk(force, signal.savgol_filter(zi, 11, 2), np.zeros(n),
                          signal.savgol_filter(zi, 11, 2, deriv=1, delta=h), meas.astype(float), z, **chunk)


@pytest.fixture(scope="session")
def synthetic_runs() -> SimpleNamespace:
    """``steps(rng, n, lo, hi)``, ``first_order(force, inertia, damping, h, offset=0)`` and
    ``measured_chunk(rng, v, force, h, noise, **chunk_fields)`` (module docstring)."""
    return SimpleNamespace(steps=_steps, first_order=_first_order, measured_chunk=_measured_chunk)
