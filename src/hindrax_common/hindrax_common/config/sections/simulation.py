"""``simulation.*``: the virtual pool's integration and sensor models (docs/architecture.md §6)."""
from __future__ import annotations

from typing import Any, Mapping

from ..spec import ConfigIssue, Spec, integer, real, section, vector

_KEYS: dict[str, Spec] = {
    "step_s": real("fixed integration step, s", 1e-4, 0.05),
    "real_time_factor": real("simulated seconds per wall second (0 = as fast as possible)", 0.0, 1000.0),
    "seed": integer("random seed of the sensor noise", 0, 2**31 - 1),
    "clock_rate_hz": real("rate /clock is published, in simulated time, Hz", 1.0, 1000.0),
}
# Sensor-model keys of the simulator: per device, the same set (noise, bias, rate, dropout).
for _dev, _unit, _hi in (("dvl75", "m_s", 1.0), ("ping1d", "m", 1.0), ("ms5837", "pa", 1e4),
                         ("icm20948_accel", "m_s2", 10.0), ("icm20948_gyro", "rad_s", 1.0),
                         ("icm20948_mag", "t", 1e-3), ("dvl75_attitude", "rad", 1.0)):
    _KEYS[f"sensors.{_dev}.noise_std_{_unit}"] = real(f"{_dev} white-noise 1-sigma, {_unit}", 0.0, _hi)
    _KEYS[f"sensors.{_dev}.bias_{_unit}"] = real(f"{_dev} constant bias, {_unit}", -_hi, _hi)
    _KEYS[f"sensors.{_dev}.rate_hz"] = real(f"{_dev} output rate, Hz", 0.1, 2000.0)
    _KEYS[f"sensors.{_dev}.dropout_probability"] = real(f"{_dev} probability a sample is lost", 0.0, 1.0)
_KEYS["sensors.dvl75.scale_error_fraction"] = real(
      "1-sigma multiplicative velocity error per report ([Hindrax-Drag] Table 1: mean error about 5 %)", 0.0, 0.5)
_KEYS["sensors.dvl75.min_altitude_m"] = real("DVL loses lock below this altitude, m", 0.0, 10.0)
_KEYS["sensors.dvl75.max_altitude_m"] = real("DVL loses lock above this altitude, m", 0.1, 200.0)
_KEYS["sensors.dvl75.wall_lock_loss_distance_m"] = real(
      "DVL loses lock closer than this to a wall, m (0 = never)", 0.0, 10.0)
_KEYS["sensors.icm20948_mag.earth_field_ned_t"] = vector(
        "earth magnetic field [north, east, down] seen by the simulated magnetometer, T", 3, -1e-4, 1e-4)
SCHEMA, OPTIONAL = section("simulation", _KEYS, optional=("sensors.",))


def cross_checks(c: Mapping[str, Any]) -> list[ConfigIssue]:
    """The simulated DVL's lock range: lower bound at most the upper."""
    a, b = "simulation.sensors.dvl75.min_altitude_m", "simulation.sensors.dvl75.max_altitude_m"
    return [ConfigIssue(a, c[a], f"at most {b} ({c[b]:g})")] if a in c and b in c and c[a] > c[b] else []
