"""Manoeuvre planning and holding control for the self-propelled tests (seed 003 §4; design.md §5).

Pure numpy, no ROS. Everything here uses the vehicle configuration and SENSOR samples only (never the
simulator's truth):

* :func:`dof_authority` - the largest feasible wrench along one body axis, from the thrust allocator
  (same curves and thrust allocation matrix as the allocation node, seed 003 eqs. 1 and 9).
* :func:`level_ladder` - the ladder of constant thrust/moment levels, fractions
  ``identification.level_fraction_min .. level_fraction_max`` of the authority (seed 003 §4: constant
  known forces/torques, one DOF at a time).
* :class:`PoolBox` - where the body origin may go: the pool (``pool.*``) shrunk by ``pool.margin_m`` plus
  half the vehicle's extent at walls and floor, ``limits.max_depth_m`` / ``limits.min_altitude_m`` below
  and half the vehicle height plus :data:`SURFACE_CLEARANCE_M` at the free surface (the margin key is
  documented for walls and floor only). Run lengths are planned from the distance left in the box.
* :class:`SensorState` - conditions the raw samples: depth of the body origin from the MS5837 pressure
  (lever arm corrected with the DVL attitude), roll/pitch/heading from the DVL attitude, body rates from
  the ICM-20948 gyro (mounting rotation and FLU->FRD applied, bias removed after a still period), body
  velocity from the DVL (lever arm ``w x r`` removed with the gyro), altitude from the Ping1D, and a
  dead-reckoned horizontal position (DVL velocity rotated by the DVL heading, from the known start).
* :class:`HoldController` - PD/PI holds for depth, roll, pitch, heading and surge/sway velocity, gains from
  the a-priori (configured) rigid + added inertia: ``k_p = I w_n^2``, ``k_d = 2 zeta w_n I``.

Frames: body FRD, world NED (design.md §3); conversions through :mod:`hindrax_drivers.frames`.
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

__all__ = [
    "DOF_INDEX", "TRANSLATIONAL", "ROTATIONAL", "SURFACE_CLEARANCE_M", "dof_authority", "level_ladder",
    "prior_inertia", "PoolBox", "SensorState", "HoldController", "wrap_angle",
]

#: DOF name -> index in nu / tau (SNAME order).
DOF_INDEX = {d: i for i, d in enumerate(DOFS)}
TRANSLATIONAL = ("surge", "sway", "heave")
ROTATIONAL = ("roll", "pitch", "yaw")
#: Clearance between the hull top and the free surface, m (the hull must not emerge: buoyancy would change).
SURFACE_CLEARANCE_M = 0.1


def wrap_angle(a: float) -> float:
    """Angle wrapped to (-pi, pi], rad."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


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
    """Constant levels (N or N m), evenly spaced fractions of ``authority`` (seed 003 §4).

    Fractions from ``identification.level_fraction_min`` to ``level_fraction_max``;
    ``levels`` defaults to ``identification.levels_per_dof``. Raises ``ValueError`` for levels < 1.
    """
    n = int(cfg.flat["identification.levels_per_dof"] if levels is None else levels)
    if n < 1:
        raise ValueError(f"levels must be >= 1, got {levels}")
    lo = float(cfg.flat["identification.level_fraction_min"])
    hi = float(cfg.flat["identification.level_fraction_max"])
    fr = [hi] if n == 1 else list(np.linspace(lo, hi, n))
    return [float(f * authority) for f in fr]


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
        f = cfg.flat
        m = float(f["pool.margin_m"])
        hl, hw, hh = 0.5 * f["vehicle.length_m"], 0.5 * f["vehicle.width_m"], 0.5 * f["vehicle.height_m"]
        half_xy = max(hl, hw)  # the heading changes in yaw tests: keep the larger half extent everywhere
        z_floor = f["pool.depth_m"] - m - hh
        z_floor = min(z_floor, float(f["limits.max_depth_m"]) - 0.05,
                      f["pool.depth_m"] - float(f["limits.min_altitude_m"]) - hh - 0.05)
        box = cls(m + half_xy, f["pool.length_m"] - m - half_xy, m + half_xy, f["pool.width_m"] - m - half_xy,
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


@dataclass
class SensorState:
    """Latest conditioned sensor values and a raw log of every sample (module docstring).

    Attributes (NaN until a first sample): ``depth_m`` (body origin, m, NED z), ``rpy_rad`` (3,),
    ``rates_frd_rad_s`` (3,), ``velocity_frd_m_s`` (3,) (DVL, lever arm removed; NaN without lock),
    ``altitude_m`` (Ping1D, NaN when invalid), ``position_ned_m`` (3,) dead-reckoned x, y and depth.
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
        f = self.cfg.flat
        roll, pitch, yaw = f["sensors.icm20948.mounting_rpy_rad"]
        r_mount = Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_matrix()  # sensor -> base_link (FLU)
        self._frd_from_sensor = frames.R_FLU_FRD @ r_mount
        self._p0 = float(f["environment.surface_pressure_pa"])
        self._rho_g = float(self.cfg.water_density_kg_m3 * self.cfg.gravity_m_s2)
        self._r_pressure = np.asarray(f["sensors.ms5837.position_frd_m"], dtype=float)
        self._r_dvl = np.asarray(f["sensors.dvl75.position_frd_m"], dtype=float)
        self.position_ned_m = np.asarray(f["pool.start_position_ned_m"], dtype=float).copy()
        self._last_dr_t: float | None = None
        self._bias_sum = np.zeros(3)
        self._bias_n = 0
        self._acc_sum = np.zeros(3)
        self._acc_n = 0
        self.accel_bias_frd_m_s2 = np.zeros(3)
        self.acceleration_frd_m_s2 = np.full(3, np.nan)
        self._g = float(self.cfg.gravity_m_s2)
        self.collecting_gyro_bias = False
        self.log = {k: [] for k in ("depth", "attitude", "gyro", "dvl", "altitude", "accel")}

    def _rotation(self) -> np.ndarray:
        rpy = np.nan_to_num(self.rpy_rad)
        return Rotation.from_euler("ZYX", [rpy[2], rpy[1], rpy[0]]).as_matrix()

    def on_sample(self, device: str, s) -> None:
        """Condition and store one simulator/driver sample (device names of :mod:`hindrax_ident.sim.sensors`)."""
        if device == "ms5837":
            depth_port = (s.pressure_pa - self._p0) / self._rho_g
            self.depth_m = float(depth_port - self._rotation()[2] @ self._r_pressure)
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
            v = np.asarray(s.velocity_frd_m_s, dtype=float)
            if s.locked and np.all(np.isfinite(v)):
                w = np.nan_to_num(self.rates_frd_rad_s)
                v = v - np.cross(w, self._r_dvl)
            else:
                v = np.full(3, np.nan)
            self._dead_reckon(s.stamp_s, v)
            self.velocity_frd_m_s = v
            self.log["dvl"].append((s.stamp_s, tuple(v)))
        elif device == "icm20948_accel":
            f_frd = self._frd_from_sensor @ np.asarray(s.specific_force_m_s2, dtype=float)
            g_body = self._rotation().T @ np.array([0.0, 0.0, self._g])
            raw = f_frd + g_body  # a = f + R^T g (sim/sensors.py: f = a - g)
            if self.collecting_gyro_bias:
                self._acc_sum += raw
                self._acc_n += 1
            w = np.nan_to_num(self.rates_frd_rad_s)
            v = np.nan_to_num(self.velocity_frd_m_s)
            self.acceleration_frd_m_s2 = raw - self.accel_bias_frd_m_s2 - np.cross(w, v)  # nu_dot = a - w x v
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


class HoldController:
    """Holds for depth, roll, pitch, heading and body velocities from sensor values (module docstring).

    ``wrench(state, free)`` returns the FRD wrench (6,) holding every DOF not in ``free``: depth (Z) to
    ``depth_setpoint_m`` (PI + D on the filtered depth rate, net-buoyancy feed-forward), roll/pitch to 0,
    heading to ``heading_setpoint_rad``, surge/sway body velocity to ``velocity_setpoint_m_s``. Each hold
    is limited to ``hold_fraction`` of the axis authority.
    """

    def __init__(self, cfg: VehicleConfig, authority: Sequence[float], natural_frequency_rad_s: float = 2.0,
                 hold_fraction: float = 0.6) -> None:
        self.cfg = cfg
        self.authority = np.asarray(authority, dtype=float)
        self.inertia = np.array([prior_inertia(cfg, d) for d in DOFS])
        self.wn = float(natural_frequency_rad_s)
        self.hold_fraction = float(hold_fraction)
        self.net_buoyancy_n = float(cfg.buoyancy_n - cfg.weight_n)  # FRD force holding depth (down)
        self.depth_setpoint_m = math.nan
        self.heading_setpoint_rad = 0.0
        self.velocity_setpoint_m_s = np.zeros(2)
        self.attitude_setpoint_rad = np.zeros(2)
        self._depth_integral = 0.0
        self.depth_rate_m_s = 0.0

    def reset_integral(self) -> None:
        """Clear the depth integrator."""
        self._depth_integral = 0.0

    def wrench(self, st: SensorState, free: Sequence[str] = (), dt_s: float = 0.02,
               velocity_gain: float = 1.5) -> np.ndarray:
        """FRD wrench (6,) of the holds (N, N m) for the DOFs not in ``free``."""
        w = np.zeros(6)
        wn, zeta = self.wn, 1.0
        lim = self.hold_fraction * self.authority
        rates = np.nan_to_num(st.rates_frd_rad_s)
        rpy = np.nan_to_num(st.rpy_rad)
        for k, dof in enumerate(("surge", "sway")):
            if dof not in free:
                v = st.velocity_frd_m_s[k]
                if np.isfinite(v):
                    w[k] = -velocity_gain * wn * self.inertia[k] * (v - self.velocity_setpoint_m_s[k])
        if "heave" not in free and math.isfinite(self.depth_setpoint_m) and math.isfinite(st.depth_m):
            m = self.inertia[2]
            err = self.depth_setpoint_m - st.depth_m
            self._depth_integral = float(np.clip(self._depth_integral + err * dt_s, -0.5, 0.5))
            w[2] = (self.net_buoyancy_n + m * wn * wn * err - 2.0 * zeta * wn * m * self.depth_rate_m_s
                    + 0.5 * m * wn ** 3 * self._depth_integral)
        for k, dof in ((3, "roll"), (4, "pitch")):
            if dof not in free:
                i = self.inertia[k]
                w[k] = i * (2 * wn) ** 2 * (self.attitude_setpoint_rad[k - 3] - rpy[k - 3]) \
                    - 2.0 * zeta * (2 * wn) * i * rates[k - 3]
        if "yaw" not in free:
            i = self.inertia[5]
            w[5] = i * wn * wn * wrap_angle(self.heading_setpoint_rad - rpy[2]) - 2.0 * zeta * wn * i * rates[2]
        for k in range(6):
            w[k] = float(np.clip(w[k], -lim[k], lim[k]))
        return w
