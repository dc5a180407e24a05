"""Kinematic Kalman filter and RTS smoother: velocity and acceleration from noisy sensors.

Identification needs v and v_dot per DOF (docs/architecture.md §5: "velocities and accelerations come from sensors
through filters, not from raw finite differences"). [Hindrax-Drag] derived heave velocity "by deriving the altitude
signal" and reported the resulting oscillations as the main perturbation of negative heave (section 5); a model-based
filter avoids that.

State model (both modes): x = [position, velocity, acceleration] of one DOF, constant
acceleration driven by continuous white jerk of power spectral density ``jerk_psd``:

    F(dt) = [[1, dt, dt^2/2], [0, 1, dt], [0, 0, 1]]
    Q(dt) = jerk_psd * [[dt^5/20, dt^4/8, dt^3/6], [dt^4/8, dt^3/3, dt^2/2], [dt^3/6, dt^2/2, dt]]

(``filterpy.common.Q_continuous_white_noise(3, dt, jerk_psd)`` written out: the online filters rebuild Q for every
IMU sample, and filterpy's ``scipy.linalg.block_diag`` costs about 13 times more). F and Q are rebuilt from every
sample interval, so non-uniform sampling is handled exactly. Measurements:

* ``measured='position'``: H = [1, 0, 0] (altitude/depth in m, roll/pitch/yaw angle in rad);
* ``measured='velocity'``: H = [0, 1, 0] (DVL velocity in m/s, gyro rate in rad/s); the
  position state is then the integral of the velocity from the first accepted sample (it
  starts at 0 with zero variance).

Missing samples (NaN or ``None``) skip the update and keep predicting.

Tuning: ``jerk_psd`` has units (measured unit)^2/s^5 (e.g. m^2/s^5); the filter bandwidth
grows roughly as (jerk_psd / measurement_std^2)^(1/6) for position and ^(1/4) for velocity
measurements. ``measurement_std`` is the sensor noise standard deviation in the measured unit.

The offline smoother uses filterpy's ``KalmanFilter``; the online filter steps with :class:`~.kalman.LinearKalman`
(why: that module's docstring). This module builds F, Q, H, R and handles time stamps and missing data."""

from __future__ import annotations

from typing import Optional, Tuple

import numpy as np

from .kalman import LinearKalman
from .least_squares import EstimationError, as_float_array, check_same_length, check_time_vector

__all__ = ["KinematicKalmanFilter", "smooth_kinematics", "transition_matrix", "process_noise"]

_MEASURED = ("position", "velocity")


def transition_matrix(dt_s: float) -> np.ndarray:
    """(3, 3) constant-acceleration transition matrix F(dt) for [pos, vel, acc] (module doc)."""
    dt = float(dt_s)
    return np.array([[1.0, dt, 0.5 * dt * dt], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])


def process_noise(dt_s: float, jerk_psd: float) -> np.ndarray:
    """(3, 3) discrete process noise Q(dt) for continuous white jerk of PSD ``jerk_psd`` (module docstring; equal to
    ``filterpy.common.Q_continuous_white_noise(3, dt, jerk_psd)``, [Bar-Shalom2001] §6.2.3); zeros for dt = 0."""
    dt = float(dt_s)
    if dt == 0.0:
        return np.zeros((3, 3))
    d2 = dt * dt
    d3 = d2 * dt
    d4 = d2 * d2
    return float(jerk_psd) * np.array([[d4 * dt / 20.0, d4 / 8.0, d3 / 6.0],
                                       [d4 / 8.0, d3 / 3.0, d2 / 2.0],
                                       [d3 / 6.0, d2 / 2.0, dt]])


def _check_settings(measured: str, jerk_psd: float, measurement_std: float) -> None:
    if measured not in _MEASURED:
        raise EstimationError(f"measured must be one of {_MEASURED}, got {measured!r}")
    if not (np.isfinite(jerk_psd) and jerk_psd > 0):
        raise EstimationError(f"jerk_psd must be > 0, got {jerk_psd}")
    if not (np.isfinite(measurement_std) and measurement_std > 0):
        raise EstimationError(f"measurement_std must be > 0, got {measurement_std}")


def _initial_state(measured: str, z0: float, measurement_std: float, initial_velocity_std: float,
                   initial_acceleration_std: float) -> Tuple[np.ndarray, np.ndarray]:
    if measured == "position":
        x0 = np.array([z0, 0.0, 0.0])
        P0 = np.diag([measurement_std**2, initial_velocity_std**2, initial_acceleration_std**2])
    else:
        x0 = np.array([0.0, z0, 0.0])
        P0 = np.diag([0.0, measurement_std**2, initial_acceleration_std**2])
    return x0, P0


def _measurement_matrix(measured: str) -> np.ndarray:
    return np.array([[1.0, 0.0, 0.0]]) if measured == "position" else np.array([[0.0, 1.0, 0.0]])


class KinematicKalmanFilter:
    """Online constant-acceleration Kalman filter for one DOF (module docstring for the model).

    Args:
        measured: ``'position'`` or ``'velocity'``.
        jerk_psd: white-jerk power spectral density, (measured unit)^2/s^5 for position
            ((unit/s)^2/s^3 for velocity measurements, same numbers), > 0.
        measurement_std: measurement noise standard deviation (m, rad, m/s or rad/s), > 0.
        initial_velocity_std: prior std of the velocity at the first sample (position mode).
        initial_acceleration_std: prior std of the acceleration at the first sample.

    Use :meth:`step` with each sample time (s) and measurement (NaN/None when missing). Before
    the first valid measurement every estimate is NaN.

    Raises:
        EstimationError: invalid settings; :meth:`step` raises on time going backwards."""

    def __init__(self, measured: str = "position", jerk_psd: float = 1.0,
                 measurement_std: float = 0.01, initial_velocity_std: float = 1.0,
                 initial_acceleration_std: float = 1.0):
        _check_settings(measured, jerk_psd, measurement_std)
        self.measured = measured
        self.jerk_psd = float(jerk_psd)
        self.measurement_std = float(measurement_std)
        self.initial_velocity_std = float(initial_velocity_std)
        self.initial_acceleration_std = float(initial_acceleration_std)
        self._kf = LinearKalman(3, _measurement_matrix(measured), np.array([[self.measurement_std**2]]))
        self.reset()

    def reset(self) -> None:
        """Return to the uninitialised state (estimates NaN until the next valid sample)."""
        self._t: Optional[float] = None
        self._initialised = False

    @property
    def initialised(self) -> bool:
        """True once a valid measurement has been accepted."""
        return self._initialised

    @property
    def t_s(self) -> Optional[float]:
        """Time (s) of the current estimate, None before the first sample."""
        return self._t

    def step(self, t_s: float, z) -> Tuple[float, float, float]:
        """Advance to time ``t_s`` and fuse measurement ``z`` (skipped when NaN/None).

        Args:
            t_s: sample time in s (non-decreasing; equal times fuse without predicting).
            z: measurement in the measured unit, or NaN/None when missing.

        Returns:
            (position, velocity, acceleration) estimates at ``t_s`` (NaN before the first valid measurement).

        Raises:
            EstimationError: non-finite ``t_s`` or time going backwards."""
        t = float(t_s)
        if not np.isfinite(t):
            raise EstimationError(f"t_s must be finite, got {t_s}")
        missing = z is None or not np.isfinite(float(z))
        if not self._initialised:
            if missing:
                return (np.nan, np.nan, np.nan)
            x0, P0 = _initial_state(self.measured, float(z), self.measurement_std,
                                    self.initial_velocity_std, self.initial_acceleration_std)
            self._kf.x = x0.reshape(3, 1)
            self._kf.P = P0
            self._t = t
            self._initialised = True
            return self.state_tuple()
        assert self._t is not None  # set with _initialised
        dt = t - self._t
        if dt < 0.0:
            raise EstimationError(f"time went backwards: {t} < {self._t}")
        if dt > 0.0:
            self._kf.predict(F=transition_matrix(dt), Q=process_noise(dt, self.jerk_psd))
            self._t = t
        if not missing:
            self._kf.update(np.array([[float(z)]]))
        return self.state_tuple()

    def predict_to(self, t_s: float) -> Tuple[float, float, float]:
        """Predict (without a measurement) to time ``t_s``; same as ``step(t_s, None)``."""
        return self.step(t_s, None)

    def state_tuple(self) -> Tuple[float, float, float]:
        """(position, velocity, acceleration) as floats (NaN before initialisation)."""
        if not self._initialised:
            return (np.nan, np.nan, np.nan)
        x = self._kf.x.ravel()
        return (float(x[0]), float(x[1]), float(x[2]))

    @property
    def covariance(self) -> np.ndarray:
        """(3, 3) state covariance (NaN before initialisation)."""
        if not self._initialised:
            return np.full((3, 3), np.nan)
        return np.array(self._kf.P, copy=True)


def smooth_kinematics(t_s, z, measured: str = "position", jerk_psd: float = 1.0, measurement_std: float = 0.01):
    """Offline position, velocity and acceleration from a whole record (Kalman + RTS smoother).

    Runs filterpy's ``KalmanFilter.batch_filter`` with per-interval F(dt), Q(dt) (non-uniform
    sampling) and then ``KalmanFilter.rts_smoother`` (Rauch-Tung-Striebel fixed-interval
    smoother) over the same F and Q. NaN samples are treated as missing (predict only).

    Args:
        t_s: (n,) strictly increasing sample times in s.
        z: (n,) measurements (position in m/rad or velocity in m/s, rad/s); NaN = missing.
        measured: ``'position'`` or ``'velocity'``.
        jerk_psd, measurement_std: as :class:`KinematicKalmanFilter` (its default initial stds).

    Returns:
        ``(pos, vel, acc)``, each (n,). Samples before the first valid measurement are NaN. In
        velocity mode ``pos`` is the integrated velocity, 0 at the first valid sample.

    Raises:
        EstimationError: bad shapes, non-increasing time, infinite values, no valid sample."""
    _check_settings(measured, jerk_psd, measurement_std)
    t = check_time_vector(t_s, "t_s", min_samples=2)
    zz = as_float_array(z, "z", 1, allow_nan=True)
    n = check_same_length(t_s=t, z=zz)
    valid = np.isfinite(zz)
    if not np.any(valid):
        raise EstimationError("z has no valid (finite) sample")
    i0 = int(np.argmax(valid))
    tt, zs_arr = t[i0:], zz[i0:]
    from filterpy.kalman import KalmanFilter  # here, not at the top: the node processes step LinearKalman only

    kf = KalmanFilter(dim_x=3, dim_z=1)
    kf.H = _measurement_matrix(measured)
    kf.R = np.array([[float(measurement_std)**2]])
    x0, P0 = _initial_state(measured, float(zs_arr[0]), float(measurement_std), 1.0, 1.0)
    kf.x = x0
    kf.P = P0
    dts = np.diff(tt, prepend=tt[0])
    Fs = [transition_matrix(dt) for dt in dts]
    Qs = [process_noise(dt, jerk_psd) for dt in dts]
    zs = [None if not np.isfinite(v) else np.array([v]) for v in zs_arr]
    # The first sample initialises the state; do not fuse it a second time.
    zs[0] = None
    means, covs, _, _ = kf.batch_filter(zs, Fs=Fs, Qs=Qs)
    xs, _, _, _ = kf.rts_smoother(means, covs, Fs=Fs, Qs=Qs)
    xs = xs.reshape(len(tt), 3)
    out = np.full((n, 3), np.nan)
    out[i0:] = xs
    return out[:, 0], out[:, 1], out[:, 2]
