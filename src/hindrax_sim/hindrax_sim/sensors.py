"""Sensor truth and noise models: what each Hindrax device would measure in the virtual pool. Pure numpy.

Each model samples the simulated vehicle at its own rate and returns a plain frozen dataclass holding the
*measured* value (truth + bias + noise, with dropouts and lock rules). Device emulators (DVL-75,
Ping1D, MS5837, ICM-20948) consume these as their truth source.

Configuration (all optional keys under ``simulation.sensors.<device>``; absent = no noise, no bias, no
dropout, the device's configured or default rate):
``noise_std_<unit>`` (white noise 1-sigma), ``bias_<unit>`` (constant bias, every axis), ``rate_hz``,
``dropout_probability`` (probability a sample is lost: no report at all). Devices and their models:

* ``dvl75`` (:class:`DvlVelocitySample`, [Hindrax-Drag] Table 1, docs/devices.md §1): velocity over the bottom of the
  DVL's position ``sensors.dvl75.position_frd_m``, ``v + w x r``, in the vehicle FRD axes (the DVL applies
  its configured mounting orientation itself and reports in the vehicle frame, docs/devices.md §1.4). Measured
  ``(1 + e) v_true + bias + n`` with one scale error ``e ~ N(0, scale_error_fraction)`` per report
  ([Hindrax-Drag] Table 1: mean error about 5 %) and ``n ~ N(0, noise_std_m_s)`` per axis. No bottom lock when
  the DVL is out of the water, its vertical altitude above the floor is outside
  ``[min_altitude_m, max_altitude_m]``, or it is within ``wall_lock_loss_distance_m`` of a wall; unlocked
  reports carry NaN velocities (the real DVL keeps reporting "searching"). Each locked report also carries the
  range along each of the four beams (:func:`hindrax_drivers.dvl75.protocol.beam_directions_frd`, turned by
  ``sensors.dvl75.sensor_orientation_rpy_rad``) to the first wall or floor it hits (:meth:`.pool.Pool.ray_distance_m`:
  a sloped floor shows in them), with :data:`DVL_BEAM_RANGE_NOISE_FRACTION` relative noise.
* ``dvl75_attitude`` (:class:`DvlAttitudeSample`): roll, pitch, yaw (Fossen ZYX, NED; yaw = heading from
  north) of the DVL's own IMU, plus bias and noise (rad), yaw wrapped to (-pi, pi].
* ``icm20948_accel`` / ``icm20948_gyro`` / ``icm20948_mag`` ([Hindrax-Drag] Table 1, docs/devices.md §4): specific
  force ``f = a - g`` at the body origin (:func:`specific_force_frd` takes a lever arm r):
  ``a = v_dot + w x v + w_dot x r + w x (w x r)``, ``g = R^T [0, 0, g]``, so a vehicle at rest reads
  ``-g`` along body z (up); angular rate ``w``; the earth magnetic field ``R^T B_ned``. All three in the
  ICM's sensor frame, given by ``sensors.icm20948.mounting_rpy_rad`` (rotation of the sensor frame in
  base_link FLU, ROS fixed-axis roll-pitch-yaw): ``x_sensor = R_mount^T R_FLU_FRD x_frd``.
  ``B_ned`` is ``simulation.sensors.icm20948_mag.earth_field_ned_t`` or :data:`DEFAULT_EARTH_FIELD_NED_T`.
* ``ms5837`` (:class:`PressureSample`, docs/devices.md §3): absolute pressure at the port position
  ``sensors.ms5837.position_frd_m``: ``p0 + rho g max(depth, 0)`` with ``environment.surface_pressure_pa``,
  ``environment.water_density_kg_m3`` and ``environment.gravity_m_s2``; temperature = the water temperature.
* ``ping1d`` (:class:`AltitudeSample`, docs/devices.md §2): distance from the sonar position
  ``sensors.ping1d.position_frd_m`` along the vehicle's down axis to the floor (or a wall, whichever the
  beam hits first), so the slant range ``h / (cos roll cos pitch)`` when tilted over a flat floor. Invalid
  when the sonar is out of the water or the distance is outside ``sensors.ping1d.min_range_m .. max_range_m``.

Sampling: a model is due at ``k / rate_hz`` (k = 0, 1, ...); the simulator calls it at the first step at or
after that time and stamps the sample with the step time (jitter below one integration step).
Determinism: one ``numpy.random.Generator`` per device, seeded from ``(seed, device index)``
(:data:`DEVICE_INDEX`), so a device's noise does not depend on which other devices are enabled."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, Mapping, Sequence

import numpy as np
from scipy.spatial.transform import Rotation

from hindrax_common.base import frames
from hindrax_common.config import VehicleConfig, or_default
from hindrax_drivers.dvl75.protocol import beam_directions_frd
from hindrax_common.base.frames import wrap_angle

from .pool import Pool

__all__ = ["DEFAULT_EARTH_FIELD_NED_T", "DEFAULT_WATER_TEMPERATURE_C", "DEVICE_INDEX",
           "VehicleTruth", "DvlVelocitySample", "DvlAttitudeSample", "AccelSample", "GyroSample",
           "MagSample", "PressureSample", "AltitudeSample", "NoiseSpec", "SensorModel",
           "SensorSuite", "specific_force_frd", "point_velocity_frd", "pressure_at_depth_pa"]

#: Earth magnetic field in NED, tesla, used when ``simulation.sensors.icm20948_mag.earth_field_ned_t`` is absent.
#: ASSUMPTION, approximate for the Peruvian coast (Paracas, 13.8 S 76.3 W), close to the magnetic dip equator
#: (the Huancayo observatory, 12 S, lies on it): horizontal about 24 uT, declination about -3 deg, a small
#: upward (negative down) component (inclination about -5 deg). Not from a geomagnetic model; only the
#: magnitude and the direction matter to the simulation.
DEFAULT_EARTH_FIELD_NED_T: tuple[float, float, float] = (24.0e-6, -1.3e-6, -2.0e-6)
#: Water (and sensor) temperature, deg C. ASSUMPTION consistent with the configured fresh-water speed of sound
#: of 1481 m/s (about 20 deg C).
DEFAULT_WATER_TEMPERATURE_C = 20.0
#: ASSUMPTION: 1-sigma relative noise of a DVL beam range (no datasheet figure in docs/devices.md; about the Ping1D's
#: 5 mm at 0.5 m).
DVL_BEAM_RANGE_NOISE_FRACTION = 0.01
#: Fixed index of each device in the seed sequence (so streams do not depend on which devices are enabled).
DEVICE_INDEX: dict[str, int] = {"dvl75": 1, "dvl75_attitude": 2, "ping1d": 3, "ms5837": 4, "icm20948_accel": 5,
                                "icm20948_gyro": 6, "icm20948_mag": 7}


# --------------------------------------------------------------------------------------------- truth & samples
@dataclass(frozen=True)
class VehicleTruth:
    """Snapshot of the simulated vehicle at ``t_s`` (s, simulated time).

    position_ned_m (3,): body origin CO in the pool frame (NED, origin at a pool corner on the surface).
    quaternion_xyzw (4,): body FRD in NED. rotation (3, 3): R, body FRD -> NED. euler_rad (3,): Fossen ZYX
    [roll, pitch, yaw]. nu (6,): [u v w (m/s) p q r (rad/s)], FRD. nu_dot (6,): its time derivative.
    wrench_frd (6,): thruster wrench about CO [X Y Z K M N] (N, N m). buoyancy_fraction: submerged fraction."""

    t_s: float
    position_ned_m: np.ndarray
    quaternion_xyzw: np.ndarray
    rotation: np.ndarray
    euler_rad: np.ndarray
    nu: np.ndarray
    nu_dot: np.ndarray
    wrench_frd: np.ndarray
    buoyancy_fraction: float


@dataclass(frozen=True)
class DvlVelocitySample:
    """DVL-75 velocity report. velocity_frd_m_s: measured (NaN when not locked); locked: bottom lock; altitude_m: true
    vertical distance DVL -> floor (NaN out of the water); beam_range_m: range along each beam A-D (port, stern,
    starboard, bow) to the floor with the DVL's range noise (NaN for a beam without lock)."""

    stamp_s: float
    velocity_frd_m_s: tuple[float, float, float]
    locked: bool
    altitude_m: float
    beam_range_m: tuple[float, float, float, float] = (math.nan, math.nan, math.nan, math.nan)


@dataclass(frozen=True)
class DvlAttitudeSample:
    """DVL-75 attitude report: measured roll, pitch, yaw (rad, Fossen ZYX in NED)."""

    stamp_s: float
    roll_rad: float
    pitch_rad: float
    yaw_rad: float


@dataclass(frozen=True)
class AccelSample:
    """ICM-20948 accelerometer: measured specific force (m/s^2) in the sensor frame; temperature."""

    stamp_s: float
    specific_force_m_s2: tuple[float, float, float]
    temperature_c: float


@dataclass(frozen=True)
class GyroSample:
    """ICM-20948 gyroscope: measured angular rate (rad/s) in the sensor frame."""

    stamp_s: float
    angular_rate_rad_s: tuple[float, float, float]


@dataclass(frozen=True)
class MagSample:
    """AK09916 magnetometer (in the ICM sensor frame): measured magnetic field (T)."""

    stamp_s: float
    magnetic_field_t: tuple[float, float, float]


@dataclass(frozen=True)
class PressureSample:
    """MS5837: absolute pressure (Pa) measured and true, water temperature (deg C), true port depth (m, >= 0)."""

    stamp_s: float
    pressure_pa: float
    temperature_c: float
    true_pressure_pa: float
    true_depth_m: float


@dataclass(frozen=True)
class AltitudeSample:
    """Ping1D: distance (m) along the vehicle's down axis to the floor (measured; NaN when invalid), valid flag."""

    stamp_s: float
    distance_m: float
    valid: bool


# --------------------------------------------------------------------------------------------- physics
def _cross(a, b) -> np.ndarray:
    """a x b for 3-vectors (numpy's cross costs about 10x more for a single pair)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def point_velocity_frd(nu, r_frd_m) -> np.ndarray:
    """Velocity (3,) in m/s, FRD, of the body point ``r_frd_m`` (3,) (relative to CO): v + w x r."""
    nu = np.asarray(nu, dtype=float)
    return nu[:3] + _cross(nu[3:], r_frd_m)


def specific_force_frd(nu, nu_dot, rotation, gravity_m_s2: float, r_frd_m=(0.0, 0.0, 0.0)) -> np.ndarray:
    """Specific force f = a - g (3,) in m/s^2, FRD, at the body point ``r_frd_m`` (relative to CO).

    a = v_dot + w x v + w_dot x r + w x (w x r) (inertial acceleration of the point in body axes, nu and
    nu_dot (6,) in FRD); g = R^T [0, 0, gravity] with R (3, 3) body -> NED. At rest f = [0, 0, -g] (level)."""
    nu, nu_dot = np.asarray(nu, dtype=float), np.asarray(nu_dot, dtype=float)
    w, w_dot = nu[3:], nu_dot[3:]
    r = np.asarray(r_frd_m, dtype=float)
    a = nu_dot[:3] + _cross(w, nu[:3]) + _cross(w_dot, r) + _cross(w, _cross(w, r))
    return a - gravity_m_s2 * np.asarray(rotation, dtype=float)[2]


def pressure_at_depth_pa(depth_m: float, density_kg_m3: float, gravity_m_s2: float,
                         surface_pressure_pa: float) -> float:
    """Hydrostatic absolute pressure p0 + rho g max(depth, 0) (Pa)."""
    return surface_pressure_pa + density_kg_m3 * gravity_m_s2 * max(float(depth_m), 0.0)


# --------------------------------------------------------------------------------------------- models
@dataclass(frozen=True)
class NoiseSpec:
    """Noise settings of one device: white-noise 1-sigma, constant bias, rate (Hz), dropout probability."""

    noise_std: float = 0.0
    bias: float = 0.0
    rate_hz: float = 10.0
    dropout_probability: float = 0.0

    @classmethod
    def of(cls, section: Any, unit: str, default_rate_hz: float) -> "NoiseSpec":
        """From a ``simulation.sensors.<device>`` section (module docstring); absent keys: 0, 0,
        ``default_rate_hz``, 0."""
        return cls(float(or_default(getattr(section, f"noise_std_{unit}"), 0.0)),
                   float(or_default(getattr(section, f"bias_{unit}"), 0.0)),
                   float(or_default(section.rate_hz, default_rate_hz)),
                   float(or_default(section.dropout_probability, 0.0)))


class SensorModel:
    """Base of the device models: rate bookkeeping, a private Generator, noise and dropout helpers.

    name: device key (one of :data:`DEVICE_INDEX`). spec: :class:`NoiseSpec`. seed: simulation seed.
    Subclasses implement ``measure(truth) -> sample``; :meth:`sample` adds the rate and dropout logic."""

    def __init__(self, name: str, spec: NoiseSpec, seed: int) -> None:
        if spec.rate_hz <= 0.0:
            raise ValueError(f"{name}: rate_hz must be positive, got {spec.rate_hz}")
        self.spec = spec
        self.period_s = 1.0 / spec.rate_hz
        self.rng = np.random.default_rng(np.random.SeedSequence([int(seed), DEVICE_INDEX.get(name, 99)]))
        # truth disturbances (SensorSuite.apply_disturbances): bias random walk per sqrt(s) and drift per s, drawn
        # from a stream of their own so that the white noise is the same with and without them
        self.walk_std = 0.0
        self.drift_per_s = 0.0
        self._walk = np.zeros(3)
        self._walk_t: float | None = None
        self.walk_rng = np.random.default_rng(np.random.SeedSequence([int(seed), DEVICE_INDEX.get(name, 99), 1000]))
        self.reset()

    def reset(self, t_s: float = 0.0) -> None:
        """Restart the sampling grid at ``t_s`` (the noise streams continue)."""
        self._k = 0
        self._t0 = t_s
        self.next_due_s = t_s

    def sample(self, t_s: float, truth: VehicleTruth) -> Any | None:
        """If due at ``t_s``: advance the grid and return a sample (None when dropped). Else None."""
        if t_s + 1e-9 < self.next_due_s:
            return None
        self._k = max(self._k + 1, int(math.floor((t_s - self._t0) / self.period_s + 1e-9)) + 1)
        self.next_due_s = self._t0 + self._k * self.period_s
        if self.spec.dropout_probability > 0.0 and self.rng.random() < self.spec.dropout_probability:
            return None
        return self.measure(truth)

    def extra_bias(self, t_s: float) -> np.ndarray:
        """Bias (3,) of the truth disturbances at ``t_s``: random walk (``walk_std`` per sqrt(s), advanced from
        the previous call) plus ``drift_per_s`` t. Zeros when neither is set."""
        if self.walk_std > 0.0:
            if self._walk_t is not None and t_s > self._walk_t:
                self._walk = self._walk + self.walk_rng.normal(0.0, self.walk_std * math.sqrt(t_s - self._walk_t), 3)
            self._walk_t = t_s if self._walk_t is None else max(self._walk_t, t_s)
        return self._walk + self.drift_per_s * t_s

    @property
    def disturbed(self) -> bool:
        """True when a bias walk or drift applies."""
        return self.walk_std > 0.0 or self.drift_per_s != 0.0

    def _noisy3(self, true3) -> tuple[float, float, float]:
        n = self.rng.normal(0.0, self.spec.noise_std, 3) if self.spec.noise_std > 0.0 else (0.0, 0.0, 0.0)
        b = self.spec.bias
        return (float(true3[0] + b + n[0]), float(true3[1] + b + n[1]), float(true3[2] + b + n[2]))

    def _noisy1(self, true1: float) -> float:
        n = self.rng.normal(0.0, self.spec.noise_std) if self.spec.noise_std > 0.0 else 0.0
        return float(true1 + self.spec.bias + n)

    def measure(self, truth: VehicleTruth) -> Any:  # pragma: no cover - abstract
        raise NotImplementedError


class DvlVelocityModel(SensorModel):
    """DVL-75 bottom-track velocity with scale error, noise, lock rules (module docstring)."""

    def __init__(self, config: VehicleConfig, pool: Pool | None, seed: int) -> None:
        s = config.simulation.sensors.dvl75
        super().__init__("dvl75", NoiseSpec.of(s, "m_s", 10.0), seed)
        self.scale_error_fraction = float(or_default(s.scale_error_fraction, 0.0))
        self.min_altitude_m = float(or_default(s.min_altitude_m, 0.0))
        self.max_altitude_m = float(or_default(s.max_altitude_m, math.inf))
        self.wall_lock_loss_distance_m = float(or_default(s.wall_lock_loss_distance_m, 0.0))
        self.position_frd_m = np.asarray(config.sensors.dvl75.position_frd_m, dtype=float)
        self.pool = pool
        # truth disturbances (SensorSuite.apply_disturbances; sim/truth.py): off
        self.matrix: np.ndarray | None = None  # scale factor x misalignment applied to the true velocity
        self.latency_s = 0.0
        self.delayed_state: Callable[[float], list] | None = None
        self.multipath_distance_m = 0.0
        self.multipath_probability = 0.0
        self.floor_noise_gain = 0.0
        self.floor_reference_m = 0.5
        # beams: directions in the body frame (sensor orientation), range noise from a stream of its own (the velocity
        # noise is the same with and without the beams)
        roll, pitch, yaw = config.sensors.dvl75.sensor_orientation_rpy_rad
        r_sensor = Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_matrix()
        self.beam_dirs_frd = (r_sensor @ np.asarray(beam_directions_frd(), dtype=float).T).T
        self.beam_rng = np.random.default_rng(np.random.SeedSequence([int(seed), DEVICE_INDEX["dvl75"], 2000]))
        self.beam_range_noise_fraction = DVL_BEAM_RANGE_NOISE_FRACTION  # 0: noise-free beams (diagnostic)

    def beam_ranges(self, point_ned_m, rotation) -> tuple[float, float, float, float]:
        """Range (m) along each beam from ``point_ned_m`` to the first wall or floor it hits, with
        ``beam_range_noise_fraction`` (default :data:`DVL_BEAM_RANGE_NOISE_FRACTION`) of relative noise; NaN
        beyond the altitude envelope or without a pool."""
        if self.pool is None:
            return (math.nan,) * 4  # type: ignore[return-value]
        out = []
        for d in self.beam_dirs_frd:
            r = self.pool.ray_distance_m(point_ned_m, rotation @ d)
            ok = math.isfinite(r) and self.min_altitude_m <= r
            out.append(float(r * (1.0 + self.beam_range_noise_fraction * self.beam_rng.standard_normal()))
                       if ok else math.nan)
        return tuple(out)  # type: ignore[return-value]

    def locked(self, point_ned_m) -> tuple[bool, float]:
        """(bottom lock, vertical altitude m) for the DVL at ``point_ned_m`` (NED); altitude NaN out of the
        water or without a pool."""
        if point_ned_m[2] <= 0.0:
            return False, math.nan
        if self.pool is None:  # unbounded water: no floor to measure, treated as locked
            return True, math.nan
        altitude = self.pool.altitude_m(point_ned_m)
        near_wall = self.wall_lock_loss_distance_m > 0.0 and \
            self.pool.wall_distance_m(point_ned_m) < self.wall_lock_loss_distance_m
        return self.min_altitude_m <= altitude <= self.max_altitude_m and not near_wall, altitude

    def measure(self, truth: VehicleTruth) -> DvlVelocitySample | None:
        point = truth.position_ned_m + truth.rotation @ self.position_frd_m
        locked, altitude = self.locked(point)
        if not locked:
            return DvlVelocitySample(truth.t_s, (math.nan, math.nan, math.nan), False, altitude)
        beams = self.beam_ranges(point, truth.rotation)
        if self.multipath_probability > 0.0 and self.pool is not None:
            d = self.pool.wall_distance_m(point)
            if d < self.multipath_distance_m and \
                    self.walk_rng.random() < self.multipath_probability * (1.0 - d / self.multipath_distance_m):
                return None  # side-lobe return from the wall: the report is lost
        v_meas = point_velocity_frd(truth.nu, self.position_frd_m)
        if self.latency_s > 0.0 and self.delayed_state is not None:
            st = self.delayed_state(self.latency_s)
            v_meas = point_velocity_frd(np.asarray(st[7:13]), self.position_frd_m)
        if self.matrix is not None:
            v_meas = self.matrix @ v_meas
        scale = 1.0 + (self.rng.normal(0.0, self.scale_error_fraction) if self.scale_error_fraction > 0.0 else 0.0)
        out = self._noisy3(scale * v_meas)
        if self.floor_noise_gain > 0.0 and math.isfinite(altitude) and self.spec.noise_std > 0.0:
            g = 1.0 + self.floor_noise_gain * (self.floor_reference_m / max(altitude, 0.05)) ** 2
            extra = self.walk_rng.normal(0.0, self.spec.noise_std * math.sqrt(g * g - 1.0), 3)
            out = (out[0] + float(extra[0]), out[1] + float(extra[1]), out[2] + float(extra[2]))
        return DvlVelocitySample(truth.t_s, out, True, altitude, beams)


class DvlAttitudeModel(SensorModel):
    """DVL-75 attitude (roll, pitch, yaw) with bias and noise."""

    def __init__(self, config: VehicleConfig, seed: int) -> None:
        spec = NoiseSpec.of(config.simulation.sensors.dvl75_attitude, "rad", 10.0)
        super().__init__("dvl75_attitude", spec, seed)

    def measure(self, truth: VehicleTruth) -> DvlAttitudeSample:
        m = self._noisy3(truth.euler_rad)
        return DvlAttitudeSample(truth.t_s, m[0], m[1], wrap_angle(m[2]))


class _ImuBase(SensorModel):
    def __init__(self, name: str, unit: str, config: VehicleConfig, seed: int) -> None:
        section = getattr(config.simulation.sensors, name)
        rate_hz = float(config.sensors.icm20948.sample_rate_hz)
        super().__init__(name, NoiseSpec.of(section, unit, rate_hz), seed)
        roll, pitch, yaw = config.sensors.icm20948.mounting_rpy_rad
        r_mount = Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_matrix()  # sensor -> base_link (FLU)
        self.sensor_from_frd = r_mount.T @ frames.R_FLU_FRD

    def _to_sensor(self, v_frd) -> np.ndarray:
        return self.sensor_from_frd @ v_frd


class AccelModel(_ImuBase):
    """ICM-20948 accelerometer: specific force at the IMU position, sensor frame (module docstring)."""

    def __init__(self, config: VehicleConfig, seed: int) -> None:
        super().__init__("icm20948_accel", "m_s2", config, seed)
        self.gravity_m_s2 = float(config.environment.gravity_m_s2)

    def measure(self, truth: VehicleTruth) -> AccelSample:
        f = self._to_sensor(specific_force_frd(truth.nu, truth.nu_dot, truth.rotation, self.gravity_m_s2))
        m = f + self.extra_bias(truth.t_s) if self.disturbed else f
        return AccelSample(truth.t_s, self._noisy3(m), DEFAULT_WATER_TEMPERATURE_C)


class GyroModel(_ImuBase):
    """ICM-20948 gyroscope: body angular rate in the sensor frame."""

    def __init__(self, config: VehicleConfig, seed: int) -> None:
        super().__init__("icm20948_gyro", "rad_s", config, seed)

    def measure(self, truth: VehicleTruth) -> GyroSample:
        w = self._to_sensor(truth.nu[3:])
        m = w + self.extra_bias(truth.t_s) if self.disturbed else w
        return GyroSample(truth.t_s, self._noisy3(m))


class MagModel(_ImuBase):
    """AK09916 magnetometer: the earth field R^T B_ned in the ICM sensor frame."""

    def __init__(self, config: VehicleConfig, seed: int) -> None:
        super().__init__("icm20948_mag", "t", config, seed)
        field = or_default(config.simulation.sensors.icm20948_mag.earth_field_ned_t, DEFAULT_EARTH_FIELD_NED_T)
        self.earth_field_ned_t = np.asarray(field, dtype=float)

    def measure(self, truth: VehicleTruth) -> MagSample:
        field_sensor = self._to_sensor(truth.rotation.T @ self.earth_field_ned_t)
        return MagSample(truth.t_s, self._noisy3(field_sensor))


class PressureModel(SensorModel):
    """MS5837 absolute pressure at the port position (module docstring)."""

    def __init__(self, config: VehicleConfig, seed: int) -> None:
        super().__init__("ms5837", NoiseSpec.of(config.simulation.sensors.ms5837, "pa",
                                                float(config.sensors.ms5837.rate_hz)), seed)
        self.position_frd_m = np.asarray(config.sensors.ms5837.position_frd_m, dtype=float)
        self.density_kg_m3 = float(config.environment.water_density_kg_m3)
        self.gravity_m_s2 = float(config.environment.gravity_m_s2)
        self.surface_pressure_pa = float(config.environment.surface_pressure_pa)

    def measure(self, truth: VehicleTruth) -> PressureSample:
        depth = float(truth.position_ned_m[2] + truth.rotation[2] @ self.position_frd_m)
        p = pressure_at_depth_pa(depth, self.density_kg_m3, self.gravity_m_s2, self.surface_pressure_pa)
        m = p + float(self.extra_bias(truth.t_s)[0]) if self.disturbed else p
        temperature_c = DEFAULT_WATER_TEMPERATURE_C
        return PressureSample(truth.t_s, self._noisy1(m), temperature_c, p, max(depth, 0.0))


class AltitudeModel(SensorModel):
    """Ping1D slant range along the vehicle's down axis (module docstring)."""

    def __init__(self, config: VehicleConfig, pool: Pool | None, seed: int) -> None:
        ping = config.sensors.ping1d
        spec = NoiseSpec.of(config.simulation.sensors.ping1d, "m", 1 / ping.ping_interval_s)
        super().__init__("ping1d", spec, seed)
        self.position_frd_m = np.asarray(ping.position_frd_m, dtype=float)
        self.min_range_m = float(ping.min_range_m)
        self.max_range_m = float(ping.max_range_m)
        self.pool = pool

    def measure(self, truth: VehicleTruth) -> AltitudeSample:
        point = truth.position_ned_m + truth.rotation @ self.position_frd_m
        if self.pool is None:
            return AltitudeSample(truth.t_s, math.nan, False)
        true_d = self.pool.ray_distance_m(point, truth.rotation[:, 2])
        valid = point[2] > 0.0 and math.isfinite(true_d) and self.min_range_m <= true_d <= self.max_range_m
        measured = self._noisy1(true_d) if valid else math.nan
        return AltitudeSample(truth.t_s, measured, bool(valid))


# --------------------------------------------------------------------------------------------- the suite
class SensorSuite:
    """All device models of a configuration, sampled by the simulator (module docstring).

    config: the vehicle configuration. pool: the pool (None: no floor, walls or surface for the DVL and sonar). seed:
    noise seed (default ``simulation.seed``). devices: names to enable (default all of :data:`DEVICE_INDEX`).

    ``latest``: device name -> its newest sample. ``next_due_s``: the earliest time any device is due.
    Raises ``ValueError`` for an unknown device name."""

    def __init__(self, config: VehicleConfig, pool: Pool | None, seed: int | None = None,
                 devices: Sequence[str] | None = None) -> None:
        seed = int(config.simulation.seed if seed is None else seed)
        names = list(DEVICE_INDEX) if devices is None else list(devices)
        unknown = [n for n in names if n not in DEVICE_INDEX]
        if unknown:
            raise ValueError(f"unknown sensor device(s) {unknown}; known: {', '.join(DEVICE_INDEX)}")
        factories: Mapping[str, Callable[[], SensorModel]] = {
            "dvl75": lambda: DvlVelocityModel(config, pool, seed),
            "dvl75_attitude": lambda: DvlAttitudeModel(config, seed),
            "ping1d": lambda: AltitudeModel(config, pool, seed),
            "ms5837": lambda: PressureModel(config, seed),
            "icm20948_accel": lambda: AccelModel(config, seed),
            "icm20948_gyro": lambda: GyroModel(config, seed),
            "icm20948_mag": lambda: MagModel(config, seed),
        }
        self.models: dict[str, SensorModel] = {n: factories[n]() for n in names}
        self.latest: dict[str, Any] = {}
        self.next_due_s = 0.0

    def apply_disturbances(self, dist, delayed_state: Callable[[float], list] | None = None) -> None:
        """Set the sensor disturbances of a truth file (:class:`~.truth.Disturbances`, :mod:`.truth`): DVL scale
        factor, misalignment, latency (``delayed_state(delay_s)`` returns the state that long ago), wall multipath
        dropouts and floor noise; IMU bias random walks; pressure drift and random walk."""
        dvl = self.models.get("dvl75")
        if isinstance(dvl, DvlVelocityModel):
            roll, pitch, yaw = dist.dvl.misalignment_rpy_rad
            mis = Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_matrix()
            scale = float(dist.dvl.scale_factor)
            dvl.matrix = None if (scale == 1.0 and not any((roll, pitch, yaw))) else scale * mis
            dvl.latency_s = float(dist.dvl.latency_s)
            dvl.delayed_state = delayed_state
            dvl.multipath_distance_m = float(dist.dvl.multipath_distance_m)
            dvl.multipath_probability = float(dist.dvl.multipath_dropout_probability) \
                if dvl.multipath_distance_m > 0.0 else 0.0
            dvl.floor_noise_gain = float(dist.floor.dvl_noise_gain)
            dvl.floor_reference_m = float(dist.floor.reference_altitude_m)
        for name, walk in (("icm20948_gyro", dist.imu.gyro_bias_walk_rad_s_sqrt_s),
                           ("icm20948_accel", dist.imu.accel_bias_walk_m_s2_sqrt_s),
                           ("ms5837", dist.pressure.random_walk_pa_sqrt_s)):
            if name in self.models:
                self.models[name].walk_std = float(walk)
        if "ms5837" in self.models:
            self.models["ms5837"].drift_per_s = float(dist.pressure.drift_pa_per_s)

    def reset(self, t_s: float = 0.0) -> None:
        """Restart every device's sampling grid at ``t_s`` and forget the latest samples."""
        for m in self.models.values():
            m.reset(t_s)
        self.latest.clear()
        self.next_due_s = t_s

    def measure(self, name: str, truth: VehicleTruth, dropout: bool = False) -> Any | None:
        """One sample of device ``name`` on ``truth``, off its rate grid (noise and bias; with ``dropout`` the
        device's ``dropout_probability`` applies and a dropped sample is None), for the device
        emulators, which sample when the real device would (:mod:`.hardware`). The grid (``latest``,
        :meth:`update`) is unchanged. Raises ``KeyError`` for a disabled device."""
        model = self.models[name]
        if dropout and model.spec.dropout_probability > 0.0 and model.rng.random() < model.spec.dropout_probability:
            return None
        return model.measure(truth)

    def stop_grid(self) -> None:
        """Sample on the rate grid no more (``latest`` keeps its samples, :meth:`reset` restarts the grid), for a
        simulator whose devices all sample on demand (:meth:`measure`): the live pool's emulators."""
        self.next_due_s = math.inf

    def update(self, t_s: float, truth: Callable[[], VehicleTruth]) -> list[tuple[str, Any]]:
        """Sample every device due at ``t_s``; ``truth`` is called (at most once) only if one is due.

        Returns the new ``(device name, sample)`` pairs (dropped samples are absent)."""
        if t_s + 1e-9 < self.next_due_s:
            return []
        snapshot = truth()
        out = []
        for name, model in self.models.items():
            s = model.sample(t_s, snapshot)
            if s is not None:
                self.latest[name] = s
                out.append((name, s))
        self.next_due_s = min(m.next_due_s for m in self.models.values()) if self.models else math.inf
        return out
