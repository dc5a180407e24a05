"""Manoeuvre planning and holding control for the self-propelled tests ([Hindrax-Drag] §4; docs/architecture.md §5).

Pure numpy, no ROS. Everything here uses the vehicle configuration and SENSOR samples only (never the
simulator's truth):

* :func:`dof_authority` - the largest feasible wrench along one body axis, from the thrust allocator
  (same curves and thrust allocation matrix as the allocation node, [Hindrax-Drag] eqs. 1 and 9).
* :func:`level_ladder` - the ladder of constant thrust/moment levels, fractions
  ``identification.level_fraction_min .. level_fraction_max`` of the authority ([Hindrax-Drag] §4: constant
  known forces/torques, one DOF at a time).
* :class:`PoolBox` - where the body origin may go: the pool (``pool.*``) shrunk by ``pool.margin_m`` plus
  half the vehicle's extent at walls and floor, ``limits.max_depth_m`` / ``limits.min_altitude_m`` below
  and half the vehicle height plus :data:`SURFACE_CLEARANCE_M` at the free surface (the margin key is
  documented for walls and floor only). Run lengths are planned from the distance left in the box.
* :class:`SensorState` - conditions the raw samples: depth of the body origin from the MS5837 pressure
  (lever arm corrected with the DVL attitude), roll/pitch/heading from the DVL attitude, body rates from
  the ICM-20948 gyro (mounting rotation and FLU->FRD applied, bias removed after a still period), body
  velocity from the DVL (lever arm ``w x r`` removed with the gyro rate at the sample's time, unless the
  sample is already at the body origin, as the DVL driver's ``dvl/data`` is), altitude from the Ping1D, and a
  dead-reckoned horizontal position (DVL velocity rotated by the DVL heading, from the known start).
* :class:`HoldController` - holds for depth (or altitude), roll, pitch, heading and surge/sway velocity: the
  model-based law of :mod:`hindrax_ident.control.law` with the vehicle file's model (or an identified one); the
  former PD/PI law is :class:`hindrax_ident.control.legacy.LegacyPDHold`.

Frames: body FRD, world NED (docs/architecture.md §3); conversions through :mod:`hindrax_drivers.frames`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
from scipy.spatial.transform import Rotation

from hindrax_drivers import frames
from hindrax_drivers.allocation.core import AllocationCore
from hindrax_drivers.config import DOFS, VehicleConfig
from hindrax_drivers.dvl75.protocol import beam_directions_frd
from hindrax_drivers.frames import wrap_angle

from ..control.law import ControlInput, ControlSettings, Controller
from ..control.model import ControlModel, inertia_vector, model_from_config
from .fusion import AccelAidedFilter

__all__ = [
    "DOF_INDEX", "TRANSLATIONAL", "ROTATIONAL", "SURFACE_CLEARANCE_M", "dof_authority", "level_ladder",
    "prior_inertia", "PoolBox", "SensorState", "DepthEstimator", "HoldController", "euler_rates",
]

#: DOF name -> index in nu / tau (SNAME order).
DOF_INDEX = {d: i for i, d in enumerate(DOFS)}
TRANSLATIONAL = ("surge", "sway", "heave")
ROTATIONAL = ("roll", "pitch", "yaw")
#: Clearance between the hull top and the free surface, m (the hull must not emerge: buoyancy would change).
SURFACE_CLEARANCE_M = 0.1


def dof_authority(core: AllocationCore, dof: str) -> tuple[float, float]:
    """(positive, negative) authority along one body axis, N or N m (both > 0).

    The allocator is asked for a very large pure wrench along the FRD axis; with uniform scaling it
    returns the largest feasible multiple, whose achieved component (thrust curves at the quantised pulse
    widths, times the thrust allocation matrix) is the authority. Raises ``KeyError`` for an unknown DOF.
    """
    i = DOF_INDEX[dof]
    out = []
    for sign in (1.0, -1.0):
        w = np.zeros(6)
        w[i] = sign * 1e4
        res = core.allocator.allocate(w)
        out.append(abs(float(res.achieved_wrench[i])))
    return out[0], out[1]


def level_ladder(cfg: VehicleConfig, authority: float, levels: int | None = None) -> list[float]:
    """Constant levels (N or N m), evenly spaced fractions of ``authority`` ([Hindrax-Drag] §4).

    Fractions from ``identification.level_fraction_min`` to ``level_fraction_max``;
    ``levels`` defaults to ``identification.levels_per_dof``. Raises ``ValueError`` for levels < 1.
    """
    n = int(cfg.identification.levels_per_dof if levels is None else levels)
    if n < 1:
        raise ValueError(f"levels must be >= 1, got {levels}")
    lo = float(cfg.identification.level_fraction_min)
    hi = float(cfg.identification.level_fraction_max)
    fr = [hi] if n == 1 else list(np.linspace(lo, hi, n))
    return [float(f * authority) for f in fr]


def tilt_test_angle_rad(cfg: VehicleConfig, dof: str) -> float:
    """``identification.roll_test_angle_rad`` or ``pitch_test_angle_rad``: where the roll or pitch test turns back,
    rad ([Hindrax-Drag] §4.2). Raises KeyError for another DOF."""
    ident = cfg.identification
    return {"roll": ident.roll_test_angle_rad, "pitch": ident.pitch_test_angle_rad}[dof]


def prior_inertia(cfg: VehicleConfig, dof: str) -> float:
    """A-priori rigid + added inertia of a DOF from the configuration (kg or kg m^2), for controller gains."""
    i = DOF_INDEX[dof]
    rigid = cfg.mass_kg if i < 3 else float(cfg.inertia_matrix_kg_m2[i - 3, i - 3])
    return float(rigid + cfg.added_mass_matrix[i, i])


@dataclass(frozen=True)
class PoolBox:
    """Allowed region of the body origin (NED, m): x in [x_min, x_max], y in [y_min, y_max], z in [z_min, z_max].

    :meth:`from_config` builds it from ``pool.*``, ``limits.*`` and the vehicle size (module docstring).
    """

    x_min: float
    x_max: float
    y_min: float
    y_max: float
    z_min: float
    z_max: float

    @classmethod
    def from_config(cls, cfg: VehicleConfig) -> "PoolBox":
        """Box of the configuration. Raises ``ValueError`` when the margins leave no room."""
        pool, v, limits = cfg.pool, cfg.vehicle, cfg.limits
        m = float(pool.margin_m)
        hl, hw, hh = 0.5 * v.length_m, 0.5 * v.width_m, 0.5 * v.height_m
        half_xy = max(hl, hw)  # the heading changes in yaw tests: keep the larger half extent everywhere
        z_floor = pool.depth_m - m - hh
        z_floor = min(z_floor, float(limits.max_depth_m) - 0.05,
                      pool.depth_m - float(limits.min_altitude_m) - hh - 0.05)
        box = cls(m + half_xy, pool.length_m - m - half_xy, m + half_xy, pool.width_m - m - half_xy,
                  hh + SURFACE_CLEARANCE_M, z_floor)
        if box.x_min >= box.x_max or box.y_min >= box.y_max or box.z_min >= box.z_max:
            raise ValueError(f"the pool with its margins leaves no room for the vehicle: {box}")
        return box

    @property
    def centre(self) -> np.ndarray:
        """(3,) centre of the box, NED, m."""
        return np.array([0.5 * (self.x_min + self.x_max), 0.5 * (self.y_min + self.y_max),
                         0.5 * (self.z_min + self.z_max)])

    def contains(self, p_ned_m: Sequence[float], tolerance_m: float = 0.0) -> bool:
        """True when the point (3,) NED is inside the box grown by ``tolerance_m``."""
        x, y, z = (float(v) for v in p_ned_m)
        t = tolerance_m
        return (self.x_min - t <= x <= self.x_max + t and self.y_min - t <= y <= self.y_max + t
                and self.z_min - t <= z <= self.z_max + t)

    def room_m(self, p_ned_m: Sequence[float], direction_ned: Sequence[float]) -> float:
        """Distance (m) from ``p_ned_m`` along the unit ``direction_ned`` (3,) to the box boundary (0 if outside)."""
        p = np.asarray(p_ned_m, dtype=float)
        d = np.asarray(direction_ned, dtype=float)
        lo = np.array([self.x_min, self.y_min, self.z_min])
        hi = np.array([self.x_max, self.y_max, self.z_max])
        best = math.inf
        for k in range(3):
            if d[k] > 1e-9:
                best = min(best, (hi[k] - p[k]) / d[k])
            elif d[k] < -1e-9:
                best = min(best, (lo[k] - p[k]) / d[k])
        return max(0.0, best)


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


def _finite_or_zero(x: float) -> float:
    return x if math.isfinite(x) else 0.0


def _cross3(a, b) -> np.ndarray:
    """a x b of two 3-vectors with NaN components taken as 0 (``np.cross`` of ``np.nan_to_num``, at a tenth of the
    time: SensorState calls it for every IMU and DVL sample)."""
    a1, a2, a3 = (_finite_or_zero(float(x)) for x in a)
    b1, b2, b3 = (_finite_or_zero(float(x)) for x in b)
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
    ``log``: device -> list of (stamp_s, value tuple) with the conditioned values (what the estimators use).
    """

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
        r_mount = Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_matrix()  # sensor -> base_link (FLU)
        self._frd_from_sensor = frames.R_FLU_FRD @ r_mount
        self._p0 = float(self.cfg.environment.surface_pressure_pa)
        self._rho_g = float(self.cfg.water_density_kg_m3 * self.cfg.gravity_m_s2)
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
        self._g = float(self.cfg.gravity_m_s2)
        self.collecting_gyro_bias = False
        self.log = {k: [] for k in ("depth", "attitude", "gyro", "dvl", "altitude", "accel")}
        self.dvl_beam_range_m = np.full(4, np.nan)
        self.dvl_beam_stamp_s = math.nan

    def _rotation(self, rpy=None) -> np.ndarray:
        """Body -> NED at ``rpy`` (default the latest attitude); a NaN angle counts as 0."""
        roll, pitch, yaw = (_finite_or_zero(float(a)) for a in (self.rpy_rad if rpy is None else rpy))
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
        """Condition and store one simulator/driver sample (device names of :mod:`hindrax_ident.sim.sensors`)."""
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
    """Depth and depth rate of the body origin for the depth hold: the MS5837 depth (10 Hz, arriving tens of
    ms after its conversion) fused with the 100 Hz vertical acceleration (:class:`~.fusion.AccelAidedFilter`,
    position measured, NED z).

    Why: the hold's rate feedback from the 10 Hz depth alone lagged by about its own filter bandwidth (6 rad/s),
    close to the loop's crossover (about 4 rad/s at ``natural_frequency_rad_s`` 2); with the latencies of the
    ROS graph (depth used 30-40 ms after its conversion, wrench on the thrusters 30-40 ms after it was
    computed) the depth hold went into a limit cycle of +-25-35 N at 0.7 Hz, and the 0.1-0.2 m/s heave it
    caused coupled into the roll and pitch runs (Munk moment, Fossen eq. 6.55). The acceleration gives the
    rate without that lag.

    ``on_sample(device, stamp_s, state)`` takes every conditioned sample (``ms5837``: ``state.depth_m``;
    ``icm20948_accel``: ``state.acceleration_ned_m_s2[2]``); a sample older than the filter's time is fused at
    the filter's time (samples come in stamp order per control tick; a late depth is not dropped).
    ``predict_to(t_s)`` returns (depth m, depth rate m/s), NaN before the first depth sample.
    depth_std_m, accel_std_m_s2, jerk_psd: the filter's noise settings (the campaign passes those of
    :func:`~.estimators.measurement_settings` for heave). Raises
    :class:`~hindrax_ident.estimation.least_squares.EstimationError` for a setting that is not > 0.
    """

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


class HoldController:
    """Holds for depth (or altitude), roll, pitch, heading and body velocities from sensor values: the model-based law
    of :mod:`hindrax_ident.control.law` (reference model, feedforward of the model's inertia, damping, net buoyancy and
    restoring, PID at a bandwidth lowered by the model's uncertainty, anti-windup; docs/control.md).

    cfg: the vehicle file. authority (6,) or (6, 2): largest wrench per axis (N, N m) from the thrust allocation
    (:func:`dof_authority`). natural_frequency_rad_s: target bandwidth w of the position holds; the velocity holds use
    ``velocity_gain`` w. hold_fraction: share of each axis' authority the holds may use. model: the
    :class:`~hindrax_ident.control.model.ControlModel` (default: the vehicle file's, the campaign's model before any
    identification exists). reference_accel: DOF -> acceleration limit of the reference models (default: from the
    model, :class:`~hindrax_ident.control.law.Controller`). settings: a
    :class:`~hindrax_ident.control.law.ControlSettings` replacing the bandwidths and hold fraction above (the
    controller node's ``control.*``).

    ``wrench(state, free)`` returns the FRD wrench (6,) holding every DOF not in ``free``: depth (Z) to
    ``depth_setpoint_m`` on ``depth_estimate_m`` and ``depth_rate_m_s`` (which the caller sets from a
    :class:`DepthEstimator`; the latest ``state.depth_m`` while ``depth_estimate_m`` is NaN), or, when
    ``altitude_setpoint_m`` is finite, the Ping1D altitude; roll/pitch to ``attitude_setpoint_rad``; heading to
    ``heading_setpoint_rad``; surge/sway body velocity to ``velocity_setpoint_m_s``. A DOF in ``free`` gets 0 and, held
    again, starts from its measured state. ``net_buoyancy_n`` and ``inertia`` are the model's.
    ``note_allocation(requested_frd, achieved_frd)`` passes the allocation's result for the anti-windup.
    """

    def __init__(self, cfg: VehicleConfig, authority, natural_frequency_rad_s: float = 2.0,
                 hold_fraction: float = 0.6, model: ControlModel | None = None, velocity_gain: float = 1.5,
                 reference_accel=None, settings: ControlSettings | None = None) -> None:
        self.cfg = cfg
        self.authority = np.asarray(authority, dtype=float)
        self.model = model if model is not None else model_from_config(cfg)
        self.inertia = inertia_vector(self.model)
        self.wn = float(natural_frequency_rad_s)
        self.hold_fraction = float(hold_fraction)
        self.velocity_gain = float(velocity_gain)
        self.net_buoyancy_n = float(self.model.axis("heave").bias)  # FRD force holding depth (down)
        self.depth_setpoint_m = math.nan
        self.altitude_setpoint_m = math.nan
        self.heading_setpoint_rad = 0.0
        self.velocity_setpoint_m_s = np.zeros(2)
        self.attitude_setpoint_rad = np.zeros(2)
        self.depth_rate_m_s = 0.0
        self.depth_estimate_m = math.nan
        self.reference_accel = reference_accel
        self.settings = settings
        self.core = self._build(self.velocity_gain)

    def _build(self, velocity_gain: float) -> Controller:
        wn = self.wn
        settings = self.settings or ControlSettings(
            depth_bandwidth_rad_s=wn, heading_bandwidth_rad_s=wn, attitude_bandwidth_rad_s=wn,
            velocity_bandwidth_rad_s=velocity_gain * wn, hold_fraction=self.hold_fraction)
        dvl = self.cfg.sensors.dvl75
        roll, pitch, yaw = dvl.sensor_orientation_rpy_rad
        beams = Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_matrix() @ np.asarray(beam_directions_frd()).T
        return Controller(self.model, self.authority, settings,
                          ping_position_frd_m=self.cfg.sensors.ping1d.position_frd_m,
                          dvl_position_frd_m=dvl.position_frd_m, dvl_beams_frd=beams.T,
                          reference_accel=self.reference_accel)

    def reset_integral(self) -> None:
        """Clear the depth integrator."""
        self.core.axes["heave"].reset_integral()

    def note_allocation(self, requested_frd, achieved_frd) -> None:
        """Anti-windup from the thrust allocation's result.

        As :meth:`~hindrax_ident.control.law.Controller.note_allocation`.
        """
        self.core.note_allocation(requested_frd, achieved_frd)

    def control_input(self, st: SensorState, t_s: float | None = None) -> ControlInput:
        """The :class:`~hindrax_ident.control.law.ControlInput` of a :class:`SensorState` and the depth estimate."""
        depth = self.depth_estimate_m if math.isfinite(self.depth_estimate_m) else st.depth_m
        alt = st.log["altitude"][-1] if st.log.get("altitude") else (math.nan, (math.nan,))
        t = t_s if t_s is not None else max((log[-1][0] for log in st.log.values() if log), default=0.0)
        return ControlInput(t_s=float(t), depth_m=float(depth), depth_rate_m_s=float(self.depth_rate_m_s),
                            rpy_rad=st.rpy_now(), rates_frd_rad_s=np.asarray(st.rates_frd_rad_s, dtype=float),
                            velocity_frd_m_s=np.asarray(st.velocity_frd_m_s, dtype=float),
                            altitude_m=float(alt[1][0]), altitude_stamp_s=float(alt[0]),
                            dvl_beam_range_m=st.dvl_beam_range_m, dvl_beam_stamp_s=st.dvl_beam_stamp_s)

    def wrench(self, st: SensorState, free: Sequence[str] = (), dt_s: float = 0.02,
               velocity_gain: float | None = None, t_s: float | None = None) -> np.ndarray:
        """FRD wrench (6,) of the holds (N, N m) for the DOFs not in ``free``, one tick of ``dt_s`` ending at ``t_s``
        (default: the newest sample's time). ``velocity_gain`` (given): the velocity holds' bandwidth over the
        position holds' from now on."""
        if velocity_gain is not None and velocity_gain != self.velocity_gain and self.settings is None:
            self.velocity_gain = float(velocity_gain)
            self.core = self._build(self.velocity_gain)
        c = self.core
        c.depth_m = float(self.depth_setpoint_m)
        c.altitude_m = float(self.altitude_setpoint_m)
        c.heading_rad = float(self.heading_setpoint_rad)
        c.velocity_frd_m_s = np.asarray(self.velocity_setpoint_m_s, dtype=float)
        c.attitude_rad = np.asarray(self.attitude_setpoint_rad, dtype=float)
        return c.wrench(self.control_input(st, t_s), float(dt_s), free)
