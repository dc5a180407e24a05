"""Automatic detection of steady-velocity windows in a self-propelled test record.

[Hindrax-Drag] (sections 4-5) fits F = k_q |v| v + k_l v + b to "the data collected in all tests with
constant velocity" of each DOF: a ladder of constant thrust levels, each held until the velocity
is steady. This module finds those windows in a record of (time, velocity, applied force) so the
steady-state LS of :func:`hindrax_onboard.estimation.least_squares.fit_drag` can be run on them
(docs/identification.md §3 C9: steady-window detection and averaging).

Algorithm (all thresholds are arguments; defaults in brackets):

1. Constant-command segments: a new segment starts whenever the force differs from the
   segment's first value by more than ``force_tolerance`` [0.05 N or N m]. The force is the
   commanded/allocated force, so it is piecewise constant in a ladder manoeuvre.
2. Inside each segment, every sub-window of duration ``min_duration_s`` [2.0 s] starting at a
   sample is tested: least-squares slope of the velocity |slope| <= ``max_slope`` [0.02 m/s^2
   or rad/s^2] and velocity standard deviation <= ``max_std`` [0.02 m/s or rad/s]. Window
   sums are computed with cumulative sums (O(n), non-uniform sampling supported).
3. Samples covered by at least one passing sub-window form the steady region; each maximal
   contiguous run of them lasting at least ``min_duration_s`` (after step 4) is reported, with
   its mean, standard deviation and slope of velocity and force.
4. Edge trimming: leading and trailing samples of a region farther than :data:`EDGE_FACTOR` (2) times ``max_std`` from
   the region mean are dropped (a 2 s window whose first samples are still in the tail of the transient can pass the std
   test, since its std dilutes the tail); the duration test is repeated after trimming. So every sample at a window's
   edges is within ``EDGE_FACTOR * max_std`` of the window mean.

Thresholds are absolute in the DOF's units: pick ``max_std`` above the velocity sensor noise (DVL ~ 0.01 m/s,
filtered gyro ~ 0.005 rad/s) and ``max_slope`` well below the transient accelerations (force / inertia).
[Hindrax-Drag]'s heave runs never became steady for lack of depth (section 5); expect no windows there and use the
transient fit (the fit core, :mod:`..identification.fit.fit_core`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import List, Tuple

import numpy as np

from .least_squares import EstimationError, as_float_array, check_same_length, check_time_vector

__all__ = ["SteadyWindow", "detect_steady_windows", "constant_force_segments"]

#: edge trimming, in units of ``max_std`` (step 4 of the module algorithm)
EDGE_FACTOR = 2.0


@dataclass(frozen=True)
class SteadyWindow:
    """One steady-velocity window: samples ``start`` (inclusive) to ``stop`` (exclusive).

    Attributes:
        start, stop: sample indices into the record (slice ``start:stop``).
        t_start_s, t_stop_s: times of the first and last sample in the window (s).
        velocity_mean, velocity_std: mean and std of the velocity (m/s or rad/s).
        velocity_slope: LS slope of the velocity over the window (m/s^2 or rad/s^2).
        force_mean, force_std: mean and std of the force (N or N m).
        n: number of samples."""

    start: int
    stop: int
    t_start_s: float
    t_stop_s: float
    velocity_mean: float
    velocity_std: float
    velocity_slope: float
    force_mean: float
    force_std: float
    n: int


def constant_force_segments(force, force_tolerance: float = 0.05) -> List[Tuple[int, int]]:
    """Split a force record into constant-command segments (step 1 of the module algorithm).

    Args:
        force: (n,) finite force/moment samples (N or N m).
        force_tolerance: a segment ends when |force - first value of the segment| exceeds it.

    Returns:
        List of (start, stop) index pairs covering the record.

    Raises:
        EstimationError: bad input or negative tolerance."""
    f = as_float_array(force, "force", 1)
    if not force_tolerance >= 0:
        raise EstimationError(f"force_tolerance must be >= 0, got {force_tolerance}")
    segments = []
    start = 0
    n = f.size
    while start < n:
        dev = np.abs(f[start:] - f[start]) > force_tolerance
        stop = start + (int(np.argmax(dev)) if np.any(dev) else n - start)
        segments.append((start, stop))
        start = stop
    return segments


def _window_stats(t: np.ndarray, v: np.ndarray, i: np.ndarray, j: np.ndarray):
    """Slope and std of v over windows [i, j) using cumulative sums (t centred per call)."""
    tc = t - t[0]
    # running sums from 0 of t, t^2, v, v^2 and t v
    c1, c2, cv, cv2, ctv = (np.concatenate([[0.0], np.cumsum(x)]) for x in (tc, tc * tc, v, v * v, tc * v))
    m = (j - i).astype(float)
    st, stt = c1[j] - c1[i], c2[j] - c2[i]
    sv, svv, stv = cv[j] - cv[i], cv2[j] - cv2[i], ctv[j] - ctv[i]
    den = m * stt - st * st
    with np.errstate(invalid="ignore", divide="ignore"):
        slope = np.where(den > 0, (m * stv - st * sv) / den, np.inf)
        var = np.clip(svv / m - (sv / m) ** 2, 0.0, None)
    return slope, np.sqrt(var)


def _slope(t: np.ndarray, v: np.ndarray) -> float:
    if t.size < 2:
        return float("nan")
    return float(np.polyfit(t - t[0], v, 1)[0])


def _trim_edges(v: np.ndarray, s: int, e: int, tol: float) -> Tuple[int, int]:
    """Drop leading/trailing samples of v[s:e] farther than tol from the run mean."""
    dev = np.abs(v[s:e] - np.mean(v[s:e])) <= tol
    if not np.any(dev):
        return s, s
    first = int(np.argmax(dev))
    last = int(dev.size - np.argmax(dev[::-1]))
    return s + first, s + last


def detect_steady_windows(t_s, velocity, force, min_duration_s: float = 2.0,
                          max_slope: float = 0.02, max_std: float = 0.02,
                          force_tolerance: float = 0.05) -> List[SteadyWindow]:
    """Find steady-velocity windows under constant force (module docstring for the algorithm).

    Args:
        t_s: (n,) strictly increasing times in s.
        velocity: (n,) velocity (m/s or rad/s), e.g. from smooth_kinematics.
        force: (n,) applied (commanded/allocated) force in N or moment in N m.
        min_duration_s: minimum window duration in s (> 0).
        max_slope: maximum |LS slope| of the velocity inside a window (m/s^2 or rad/s^2).
        max_std: maximum velocity standard deviation inside a window (m/s or rad/s).
        force_tolerance: constant-command tolerance (N or N m).

    Returns:
        List of :class:`SteadyWindow` in time order (empty when nothing is steady).

    Raises:
        EstimationError: bad shapes, NaN, non-increasing time, non-positive thresholds."""
    t = check_time_vector(t_s, "t_s")
    v = as_float_array(velocity, "velocity", 1)
    f = as_float_array(force, "force", 1)
    check_same_length(t_s=t, velocity=v, force=f)
    for name, val in (("min_duration_s", min_duration_s), ("max_slope", max_slope), ("max_std", max_std)):
        if not (np.isfinite(val) and val > 0):
            raise EstimationError(f"{name} must be > 0, got {val}")
    windows: List[SteadyWindow] = []
    for a, b in constant_force_segments(f, force_tolerance):
        ts, vs = t[a:b], v[a:b]
        if ts.size < 3 or ts[-1] - ts[0] < min_duration_s:
            continue
        i = np.arange(ts.size)
        # window [i, j) spans at least min_duration_s: last sample time >= t_i + min_duration
        j = np.searchsorted(ts, ts + min_duration_s, side="left") + 1
        ok_len = j <= ts.size
        i, j = i[ok_len], j[ok_len]
        slope, std = _window_stats(ts, vs, i, j)
        passing = (np.abs(slope) <= max_slope) & (std <= max_std)
        if not np.any(passing):
            continue
        # mark covered samples with a difference array
        cover = np.zeros(ts.size + 1, dtype=int)
        np.add.at(cover, i[passing], 1)
        np.add.at(cover, j[passing], -1)
        steady = np.cumsum(cover[:-1]) > 0
        edges = np.flatnonzero(np.diff(np.concatenate([[0], steady.astype(int), [0]])))
        for s, e in zip(edges[::2], edges[1::2]):
            s, e = _trim_edges(vs, int(s), int(e), EDGE_FACTOR * max_std)
            if e - s < 2 or ts[e - 1] - ts[s] < min_duration_s:
                continue
            sl = slice(a + s, a + e)
            windows.append(SteadyWindow(
                start=a + int(s), stop=a + int(e), t_start_s=float(t[a + s]),
                t_stop_s=float(t[a + e - 1]), velocity_mean=float(np.mean(v[sl])),
                velocity_std=float(np.std(v[sl])), velocity_slope=_slope(t[sl], v[sl]),
                force_mean=float(np.mean(f[sl])), force_std=float(np.std(f[sl])),
                n=int(e - s)))
    return windows

