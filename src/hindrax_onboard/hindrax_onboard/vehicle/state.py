"""The vehicle's state from its sensors: conditioning of the raw samples and the depth estimate (pure numpy, no ROS).

* :class:`SensorState` - conditions the raw samples: depth of the body origin (MS5837, lever arm
  corrected), attitude (DVL), body rates (ICM-20948 gyro, mounting applied, bias removed after a
  still period), body velocity (DVL, lever arm removed with the gyro rate at the sample's time),
  altitude (Ping1D) and a horizontal position dead-reckoned from the known start.
* :class:`DepthEstimator` - depth and depth rate of the body origin, the MS5837 depth fused with the vertical
  acceleration (:class:`~.fusion.AccelAidedFilter`).
* :func:`euler_rates`, :func:`rotation_ned_from_body` - the attitude kinematics ([Fossen2021] eqs. 2.18, 2.29).

Used alike by the identification (online executive and bag analysis) and the controller. Everything here uses the
vehicle configuration and SENSOR samples only, never the simulator's truth. Frames: body FRD, world NED
(docs/architecture.md §3); conversions through :mod:`hindrax_common.base.frames`."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from hindrax_common.base import frames
from hindrax_common.config import VehicleConfig
from hindrax_common.base.frames import wrap_angle

from .fusion import AccelAidedFilter

__all__ = ["SensorState", "DepthEstimator", "all_finite", "euler_rates", "finite_or_zero",
           "finite_or_zeros", "rotation_ned_from_body"]


def euler_rates(rpy_rad, rates_frd_rad_s) -> np.ndarray:
    """Euler-angle rates (..., 3) rad/s of roll, pitch, yaw (zyx convention) from body rates p, q, r (..., 3)
    rad/s at attitudes ``rpy_rad`` (..., 3) (broadcast): d Theta / dt = T(Theta) omega (Fossen 2021 eq. 2.29;
    singular at pitch +-90 deg, where T's tan/sec grow without bound)."""
    rpy = np.asarray(rpy_rad, dtype=float)
    w = np.asarray(rates_frd_rad_s, dtype=float)
    phi, theta = rpy[..., 0], rpy[..., 1]
    p, q, r = w[..., 0], w[..., 1], w[..., 2]
    sp, cp, ct, tt = np.sin(phi), np.cos(phi), np.cos(theta), np.tan(theta)
    return np.stack([p + sp * tt * q + cp * tt * r, cp * q - sp * r, (sp * q + cp * r) / ct], axis=-1)


def rotation_ned_from_body(roll_rad: float, pitch_rad: float, yaw_rad: float) -> np.ndarray:
    """Rotation matrix (3, 3) body (FRD) -> NED of the zyx Euler angles (rad), R = Rz(yaw) Ry(pitch) Rx(roll)
    ([Fossen2021] eq. 2.18), written out: ``scipy.spatial.transform.Rotation.from_euler("ZYX", ...)`` gives the same
    matrix for about 5 times the time, and the identification node builds one for every IMU sample."""
    sr, cr = math.sin(roll_rad), math.cos(roll_rad)
    sp, cp = math.sin(pitch_rad), math.cos(pitch_rad)
    sy, cy = math.sin(yaw_rad), math.cos(yaw_rad)
    return np.array([[cy * cp, -sy * cr + cy * sp * sr, sy * sr + cy * cr * sp],
                     [sy * cp, cy * cr + sr * sp * sy, -cy * sr + sp * sy * cr],
                     [-sp, cp * sr, cp * cr]])


def finite_or_zero(x: float) -> float:
    """``x`` as a float, 0.0 when it is NaN or infinite (an unknown angle, rate or velocity
    taken as 0)."""
    x = float(x)
    return x if math.isfinite(x) else 0.0


def finite_or_zeros(values) -> np.ndarray:
    """``values`` as a float array of the same shape, its NaN and infinite entries 0.0.
    ``np.nan_to_num`` does the same for NaN (and maps an infinity to the largest float) at 3-4
    times the cost on a 3-vector (17 against 5 us here, 30 us for a scalar): the control tick
    calls this several times per tick."""
    a = np.asarray(values, dtype=float)
    return np.where(np.isfinite(a), a, 0.0)


def all_finite(values) -> bool:
    """True when every entry of a short sequence (an attitude, a rate vector) is finite:
    ``np.all(np.isfinite(.))`` at a third of its cost on a 3-vector."""
    return all(map(math.isfinite, values))


def _cross3(a, b) -> np.ndarray:
    """a x b of two 3-vectors with NaN components taken as 0 (``np.cross`` of ``np.nan_to_num``, at a tenth of the
    time: SensorState calls it for every IMU and DVL sample)."""
    a1, a2, a3 = (finite_or_zero(x) for x in a)
    b1, b2, b3 = (finite_or_zero(x) for x in b)
    return np.array([a2 * b3 - a3 * b2, a3 * b1 - a1 * b3, a1 * b2 - a2 * b1])


def _interpolate_log(log: list, t_s: float, fallback, wrap: Sequence[int] = ()) -> np.ndarray:
    """Value (k,) of a SensorState log (list of (stamp, tuple), stamps non-decreasing) at ``t_s``: linear
    between the samples around ``t_s``, the nearest sample outside the logged span, ``fallback`` when empty.
    Components listed in ``wrap`` are angles interpolated along the shorter arc. Searches from the newest
    sample backwards (callers ask for recent times)."""
    if not log:
        return np.asarray(fallback, dtype=float).copy()
    i = len(log) - 1
    while i >= 0 and log[i][0] > t_s:
        i -= 1
    if i < 0:
        return np.asarray(log[0][1], dtype=float)
    t0, v0 = log[i]
    v0 = np.asarray(v0, dtype=float)
    if i == len(log) - 1 or t0 == t_s:
        return v0.copy()
    t1, v1 = log[i + 1]
    d = np.asarray(v1, dtype=float) - v0
    for k in wrap:
        d[k] = wrap_angle(float(d[k]))
    out = v0 + d * ((t_s - t0) / (t1 - t0))
    for k in wrap:
        out[k] = wrap_angle(float(out[k]))
    return out


@dataclass
class SensorState:
    """Latest conditioned sensor values and a raw log of every sample (module docstring).

    Attributes (NaN until a first sample): ``depth_m`` (body origin, m, NED z), ``rpy_rad`` (3,),
    ``rates_frd_rad_s`` (3,), ``velocity_frd_m_s`` (3,) (DVL, lever arm removed; NaN without lock; a ``dvl75``
    sample with ``at_body_origin`` true is taken as it is, as the DVL driver has removed the lever arm),
    ``altitude_m`` (Ping1D, NaN when invalid), ``dvl_beam_range_m`` (4,) the latest DVL beam ranges A-D (NaN
    without lock) at ``dvl_beam_stamp_s``, ``position_ned_m`` (3,) dead-reckoned x, y and depth,
    ``acceleration_frd_m_s2`` (3,) nu_dot of the body origin and ``acceleration_ned_m_s2`` (3,) its acceleration in
    NED (accelerometer: specific force + gravity, bias removed; NaN before the first sample).
    ``log``: device -> list of (stamp_s, value tuple) with the conditioned values (what the estimators use)."""

    cfg: VehicleConfig
    depth_m: float = math.nan
    rpy_rad: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    rates_frd_rad_s: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    velocity_frd_m_s: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    altitude_m: float = math.nan
    position_ned_m: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    gyro_bias_frd_rad_s: np.ndarray = field(default_factory=lambda: np.zeros(3))
    log: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        sensors = self.cfg.sensors
        roll, pitch, yaw = sensors.icm20948.mounting_rpy_rad
        r_mount = rotation_ned_from_body(roll, pitch, yaw)  # sensor -> base_link (FLU): the same zyx Euler matrix
        self._frd_from_sensor = frames.R_FLU_FRD @ r_mount
        self._p0 = float(self.cfg.environment.surface_pressure_pa)
        self._rho_g = float(self.cfg.environment.water_density_kg_m3 * self.cfg.environment.gravity_m_s2)
        self._r_pressure = np.asarray(sensors.ms5837.position_frd_m, dtype=float)
        self._r_dvl = np.asarray(sensors.dvl75.position_frd_m, dtype=float)
        self.position_ned_m = np.asarray(self.cfg.pool.start_position_ned_m, dtype=float).copy()
        self._last_dr_t: float | None = None
        self._bias_sum = np.zeros(3)
        self._bias_n = 0
        self._acc_sum = np.zeros(3)
        self._acc_n = 0
        self.accel_bias_frd_m_s2 = np.zeros(3)
        self.acceleration_frd_m_s2 = np.full(3, np.nan)
        self.acceleration_ned_m_s2 = np.full(3, np.nan)
        self._g = float(self.cfg.environment.gravity_m_s2)
        self.collecting_gyro_bias = False
        self.log = {k: [] for k in ("depth", "attitude", "gyro", "dvl", "altitude", "accel")}
        self.dvl_beam_range_m = np.full(4, np.nan)
        self.dvl_beam_stamp_s = math.nan

    def _rotation(self, rpy=None) -> np.ndarray:
        """Body -> NED at ``rpy`` (default the latest attitude); a NaN angle counts as 0."""
        roll, pitch, yaw = (finite_or_zero(a) for a in (self.rpy_rad if rpy is None else rpy))
        return rotation_ned_from_body(roll, pitch, yaw)

    def rates_at(self, t_s: float) -> np.ndarray:
        """Body rates (3,) rad/s FRD at time ``t_s``, linear between the two gyro samples around it (the nearest
        one outside the logged span; the latest rates when the log is empty).

        The DVL and pressure samples reach the node tens of ms after their time of validity (the DVL stamp is
        the middle of its ping interval, the MS5837 stamp its conversion; docs/devices.md §1, §3), by which time
        newer gyro samples have arrived; lever-arm corrections use the rate at the sample's own time."""
        return _interpolate_log(self.log["gyro"], t_s, self.rates_frd_rad_s)

    def rpy_now(self) -> np.ndarray:
        """Roll, pitch, yaw (3,) rad at the newest sample time of the attitude and the gyro: the 10 Hz attitude
        carried forward with the 100 Hz gyro (:meth:`rpy_at`). The holds use it: the attitude alone is up to
        100 ms old, plus its delivery latency. NaN before the first attitude sample."""
        t = max(self.log["attitude"][-1][0] if self.log["attitude"] else -math.inf,
                self.log["gyro"][-1][0] if self.log["gyro"] else -math.inf)
        return self.rpy_at(t)

    def rpy_at(self, t_s: float) -> np.ndarray:
        """Roll, pitch, yaw (3,) rad at ``t_s``: linear between the two attitude samples around it, or from
        the newest one before it carried forward with the gyro rates through the Euler-angle kinematics
        (Fossen eq. 2.29, d Theta / dt = T(Theta) omega). NaN before the first attitude sample."""
        log = self.log["attitude"]
        if not log:
            return np.full(3, np.nan)
        t_last, last = log[-1]
        if t_s <= t_last:
            return _interpolate_log(log, t_s, np.asarray(last, dtype=float), wrap=(2,))
        rpy = np.asarray(last, dtype=float)
        rates = self.rates_at(0.5 * (t_last + t_s))
        if not np.all(np.isfinite(rates)):
            return rpy.copy()
        return rpy + (t_s - t_last) * euler_rates(rpy, rates)

    def on_sample(self, device: str, s) -> None:
        """Condition and store one simulator/driver sample (device names of :mod:`hindrax_sim.sensors`)."""
        if device == "ms5837":
            depth_port = (s.pressure_pa - self._p0) / self._rho_g
            self.depth_m = float(depth_port - self._rotation(self.rpy_at(s.stamp_s))[2] @ self._r_pressure)
            self.position_ned_m[2] = self.depth_m
            self.log["depth"].append((s.stamp_s, (self.depth_m,)))
        elif device == "dvl75_attitude":
            self.rpy_rad = np.array([s.roll_rad, s.pitch_rad, s.yaw_rad])
            self.log["attitude"].append((s.stamp_s, tuple(self.rpy_rad)))
        elif device == "icm20948_gyro":
            raw = self._frd_from_sensor @ np.asarray(s.angular_rate_rad_s, dtype=float)
            if self.collecting_gyro_bias:
                self._bias_sum += raw
                self._bias_n += 1
            self.rates_frd_rad_s = raw - self.gyro_bias_frd_rad_s
            self.log["gyro"].append((s.stamp_s, tuple(self.rates_frd_rad_s)))
        elif device == "dvl75":
            beams = getattr(s, "beam_range_m", None)
            if beams is not None:
                self.dvl_beam_range_m = np.asarray(beams, dtype=float)
                self.dvl_beam_stamp_s = float(s.stamp_s)
            v = np.asarray(s.velocity_frd_m_s, dtype=float)
            if s.locked and np.all(np.isfinite(v)):
                if not getattr(s, "at_body_origin", False):
                    v = v - _cross3(self.rates_at(s.stamp_s), self._r_dvl)
            else:
                v = np.full(3, np.nan)
            self._dead_reckon(s.stamp_s, v)
            self.velocity_frd_m_s = v
            self.log["dvl"].append((s.stamp_s, tuple(v)))
        elif device == "icm20948_accel":
            f_frd = self._frd_from_sensor @ np.asarray(s.specific_force_m_s2, dtype=float)
            rot = self._rotation()
            g_body = rot[2] * self._g  # R^T [0, 0, g]
            raw = f_frd + g_body  # a = f + R^T g (sim/sensors.py: f = a - g)
            if self.collecting_gyro_bias:
                self._acc_sum += raw
                self._acc_n += 1
            w_cross_v = _cross3(self.rates_frd_rad_s, self.velocity_frd_m_s)  # NaN (no rate, no DVL lock) as 0
            self.acceleration_frd_m_s2 = raw - self.accel_bias_frd_m_s2 - w_cross_v  # nu_dot = a - w x v
            self.acceleration_ned_m_s2 = rot @ (raw - self.accel_bias_frd_m_s2)  # d^2 p / dt^2 in NED
            self.log["accel"].append((s.stamp_s, tuple(self.acceleration_frd_m_s2)))
        elif device == "ping1d":
            self.altitude_m = float(s.distance_m) if s.valid else math.nan
            self.log["altitude"].append((s.stamp_s, (self.altitude_m,)))

    def _dead_reckon(self, t: float, v_frd: np.ndarray) -> None:
        if self._last_dr_t is not None:
            dt = t - self._last_dr_t
            use = v_frd if np.all(np.isfinite(v_frd)) else self.velocity_frd_m_s
            if np.all(np.isfinite(use)):
                self.position_ned_m[:2] += dt * (self._rotation() @ use)[:2]
        self._last_dr_t = t

    def start_gyro_bias(self) -> None:
        """Start averaging the raw gyro and accelerometer (vehicle held still) to estimate their biases."""
        self.collecting_gyro_bias = True
        self._bias_sum[:] = 0.0
        self._bias_n = 0
        self._acc_sum[:] = 0.0
        self._acc_n = 0

    def finish_gyro_bias(self) -> None:
        """Stop averaging; the mean raw rate (and the mean raw acceleration, zero when still) become the
        biases removed from later samples."""
        self.collecting_gyro_bias = False
        if self._bias_n > 0:
            self.gyro_bias_frd_rad_s = self._bias_sum / self._bias_n
        if self._acc_n > 0:
            self.accel_bias_frd_m_s2 = self._acc_sum / self._acc_n


class DepthEstimator:
    """Depth and depth rate of the body origin for the depth hold: the MS5837 depth (10 Hz, arriving tens of ms after
    its conversion) fused with the 100 Hz vertical acceleration (:class:`~.fusion.AccelAidedFilter`, position
    measured, NED z).

    Why: a rate from the 10 Hz depth alone lags by about its own filter bandwidth, close to the hold's crossover;
    with the ROS graph's latencies that drives the depth hold into a limit cycle whose heave couples into the roll
    and pitch runs (Munk moment, Fossen eq. 6.55). The acceleration gives the rate without that lag.

    ``on_sample(device, stamp_s, state)`` takes every conditioned sample (``ms5837``: ``state.depth_m``;
    ``icm20948_accel``: ``state.acceleration_ned_m_s2[2]``); a sample older than the filter's time is fused at
    the filter's time (samples come in stamp order per control tick; a late depth is not dropped).
    ``predict_to(t_s)`` returns (depth m, depth rate m/s), NaN before the first depth sample.
    depth_std_m, accel_std_m_s2, jerk_psd: the filter's noise settings (the campaign passes those of
    :func:`~.uncertainty.measurement_settings` for heave). Raises
    :class:`~hindrax_onboard.estimation.least_squares.EstimationError` for a setting that is not > 0."""

    def __init__(self, depth_std_m: float = 0.005, accel_std_m_s2: float = 0.07, jerk_psd: float = 20.0) -> None:
        self.kf = AccelAidedFilter("position", depth_std_m, accel_std_m_s2, jerk_psd)

    def on_sample(self, device: str, stamp_s: float, state: SensorState) -> None:
        """Fuse one sample (class docstring)."""
        t = float(stamp_s) if self.kf.t_s is None else max(float(stamp_s), self.kf.t_s)
        if device == "ms5837" and math.isfinite(state.depth_m):
            self.kf.step(t, state.depth_m, None)
        elif device == "icm20948_accel" and self.kf.initialised:
            a = float(state.acceleration_ned_m_s2[2])
            if math.isfinite(a):
                self.kf.step(t, None, a)

    def predict_to(self, t_s: float) -> tuple[float, float]:
        """(depth m, depth rate m/s) predicted to ``t_s`` (never before the last fused sample)."""
        if not self.kf.initialised:
            return math.nan, math.nan
        x, v, _ = self.kf.predict_to(max(float(t_s), self.kf.t_s))
        return x, v
