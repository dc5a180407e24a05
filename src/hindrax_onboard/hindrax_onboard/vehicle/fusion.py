"""Kinematic Kalman filter/RTS smoother aided by the accelerometer (surge, sway, heave).

Same state model as :mod:`hindrax_onboard.estimation.filters` (x = [position, velocity, acceleration] of one
DOF, constant acceleration driven by white jerk, F(dt) and Q(dt) from its :func:`transition_matrix` and
:func:`process_noise`), with TWO scalar measurements (dim_z = 2; a missing one gets a zero row of H, so it carries no
information), fused online by :class:`~hindrax_onboard.estimation.kalman.LinearKalman` (filterpy's equations without
its import cost, that module's docstring) and offline by filterpy's ``KalmanFilter`` (batch filter, RTS smoother):

* the primary sensor: DVL velocity (``measured='velocity'``, H = [0 1 0]) or depth from pressure
  (``measured='position'``, H = [1 0 0]);
* the linear acceleration from the ICM-20948 (H = [0 0 1]): specific force + gravity in body axes - w x v -
  bias (:class:`~hindrax_onboard.vehicle.state.SensorState`).

Why: the DVL and pressure sensor report at 10 Hz, too slowly to resolve the thrust transients (thruster lag
0.1 s, velocity time constants 0.3-0.6 s); smoothing them alone attenuates nu_dot and biases the
equation-error and RLS inertia low. The 100 Hz accelerometer measures nu_dot directly ([Hindrax-Drag] Table 1;
docs/identification.md §4 R8: "use an IMU to measure acceleration directly")."""
from __future__ import annotations

import math
from typing import Optional

import numpy as np

from ..estimation.filters import process_noise, transition_matrix
from ..estimation.kalman import LinearKalman
from ..estimation.least_squares import EstimationError

__all__ = ["AccelAidedFilter", "smooth_with_acceleration", "smooth_with_rate"]


def _h(measured: str, has_primary: bool, has_accel: bool, aid_index: int = 2) -> np.ndarray:
    h = np.zeros((2, 3))
    if has_primary:
        h[0, 0 if measured == "position" else 1] = 1.0
    if has_accel:
        h[1, aid_index] = 1.0
    return h


def _init(measured: str, z: float, a: Optional[float], std: float) -> tuple[np.ndarray, np.ndarray]:
    a0 = 0.0 if a is None else a
    if measured == "position":
        return np.array([z, 0.0, a0]), np.diag([std ** 2, 1.0, 1.0])
    return np.array([0.0, z, a0]), np.diag([1e-12, std ** 2, 1.0])


def _ok(x) -> bool:
    return x is not None and math.isfinite(float(x))


class AccelAidedFilter:
    """Online filter (module docstring). measured: 'position' | 'velocity'; std: primary noise std;
    accel_std: acceleration noise std (m/s^2); jerk_psd: white-jerk PSD. Estimates NaN until the first
    primary sample. Raises :class:`EstimationError` for bad settings or time going backwards."""

    def __init__(self, measured: str, std: float, accel_std: float, jerk_psd: float) -> None:
        if measured not in ("position", "velocity"):
            raise EstimationError(f"measured must be 'position' or 'velocity', got {measured!r}")
        for name, v in (("std", std), ("accel_std", accel_std), ("jerk_psd", jerk_psd)):
            if not (math.isfinite(v) and v > 0):
                raise EstimationError(f"{name} must be > 0, got {v}")
        self.measured, self.std, self.accel_std, self.jerk_psd = measured, float(std), float(accel_std), float(jerk_psd)
        self.kf = LinearKalman(3, R=np.diag([self.std ** 2, self.accel_std ** 2]))
        self.t_s: Optional[float] = None
        self.initialised = False

    def step(self, t_s: float, z=None, accel=None) -> tuple[float, float, float]:
        """Advance to ``t_s`` and fuse the primary ``z`` and/or ``accel`` (None/NaN = missing)."""
        t = float(t_s)
        if not self.initialised:
            if not _ok(z):
                return (math.nan, math.nan, math.nan)
            x0, p0 = _init(self.measured, float(z), float(accel) if _ok(accel) else None, self.std)
            self.kf.x, self.kf.P = x0.reshape(3, 1), p0
            self.t_s, self.initialised = t, True
            return self.state()
        dt = t - self.t_s
        if dt < 0:
            raise EstimationError(f"time went backwards: {t} < {self.t_s}")
        if dt > 0:
            self.kf.predict(F=transition_matrix(dt), Q=process_noise(dt, self.jerk_psd))
            self.t_s = t
        hp, ha = _ok(z), _ok(accel)
        if hp or ha:
            zz = np.array([[float(z) if hp else 0.0], [float(accel) if ha else 0.0]])  # column, like kf.x
            self.kf.update(zz, H=_h(self.measured, hp, ha))
        return self.state()

    def predict_to(self, t_s: float) -> tuple[float, float, float]:
        """Predict to ``t_s`` without a measurement."""
        return self.step(t_s) if self.initialised else (math.nan, math.nan, math.nan)

    def state(self) -> tuple[float, float, float]:
        """(position, velocity, acceleration)."""
        if not self.initialised:
            return (math.nan, math.nan, math.nan)
        x = self.kf.x.ravel()
        return float(x[0]), float(x[1]), float(x[2])


def smooth_with_acceleration(t_s, z, accel, measured: str, std: float, accel_std: float, jerk_psd: float):
    """Offline (pos, vel, acc) (n,) each: Kalman filter + RTS smoother over the grid ``t_s`` (n,) strictly
    increasing, with primary samples ``z`` (n,) and acceleration samples ``accel`` (n,) (NaN = missing).
    Samples before the first primary sample are NaN. Raises :class:`EstimationError` without primary data."""
    return _smooth_aided(t_s, z, accel, measured, std, accel_std, jerk_psd, 2)


def smooth_with_rate(t_s, angle, rate, angle_std: float, rate_std: float, jerk_psd: float):
    """Offline (angle, rate, rate derivative) (n,) each: the smoother of :func:`smooth_with_acceleration` with the
    angle as the primary (position) measurement and its rate as the second one (H = [0 1 0]) instead
    of an acceleration; ``t_s``, ``angle`` (rad), ``rate`` (rad/s) (n,), NaN = missing.

    For roll and pitch: the DVL-75 attitude (10 Hz, noise ``angle_std``) with the Euler-angle rate from the 100 Hz
    gyro (Fossen eq. 2.29; noise ``rate_std``): the attitude smoothed alone keeps enough noise in the restoring
    regressor s(eta) to bias the roll/pitch damping by 1-2 %. Raises :class:`EstimationError` without angle samples."""
    return _smooth_aided(t_s, angle, rate, "position", angle_std, rate_std, jerk_psd, 1)


def _smooth_aided(t_s, z, accel, measured: str, std: float, accel_std: float, jerk_psd: float, aid_index: int):
    t = np.asarray(t_s, dtype=float)
    z = np.asarray(z, dtype=float)
    a = np.asarray(accel, dtype=float)
    if not (t.shape == z.shape == a.shape) or t.ndim != 1:
        raise EstimationError("t_s, z and accel must be 1-D arrays of the same length")
    if np.any(np.diff(t) <= 0):
        raise EstimationError("t_s must be strictly increasing")
    valid = np.isfinite(z)
    if not np.any(valid):
        raise EstimationError("no primary measurement")
    i0 = int(np.argmax(valid))
    tt, zz, aa = t[i0:], z[i0:], a[i0:]
    from filterpy.kalman import KalmanFilter  # here, not at the top: the node processes step LinearKalman only

    kf = KalmanFilter(dim_x=3, dim_z=2)
    kf.R = np.diag([std ** 2, accel_std ** 2])
    x0, p0 = _init(measured, float(zz[0]), float(aa[0]) if (aid_index == 2 and np.isfinite(aa[0])) else None, std)
    kf.x, kf.P = x0, p0
    dts = np.diff(tt, prepend=tt[0])
    Fs = [transition_matrix(dt) for dt in dts]
    Qs = [process_noise(dt, jerk_psd) for dt in dts]
    zs, Hs = [], []
    for k in range(tt.size):
        hp = bool(np.isfinite(zz[k])) and k > 0
        ha = bool(np.isfinite(aa[k])) and k > 0
        zs.append(np.array([zz[k] if hp else 0.0, aa[k] if ha else 0.0]) if (hp or ha) else None)
        Hs.append(_h(measured, hp, ha, aid_index))
    means, covs, _, _ = kf.batch_filter(zs, Fs=Fs, Qs=Qs, Hs=Hs)
    xs, _, _, _ = kf.rts_smoother(means, covs, Fs=Fs, Qs=Qs)
    out = np.full((t.size, 3), np.nan)
    out[i0:] = xs.reshape(tt.size, 3)
    return out[:, 0], out[:, 1], out[:, 2]
