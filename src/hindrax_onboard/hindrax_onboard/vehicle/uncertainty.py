"""What the vehicle file declares about its measurements: each DOF's measured signal and filter tuning from the
sensors' declared noise (:func:`measurement_settings`), and the relative thrust uncertainty (:func:`declared_rel`).

Pure, no ROS. The controller's depth filter, the identification's online filters, its offline fit and its verdicts
read them here, so they agree on the same noise."""
from __future__ import annotations

import math

from hindrax_common.config import DOFS, VehicleConfig, or_default

__all__ = ["ACCEL_JERK_PSD", "measurement_settings", "DEFAULT_THRUST_UNCERTAINTY_REL", "declared_rel"]

#: White-jerk PSD (m^2/s^5) of the accelerometer-aided filter (fusion.py) for surge, sway and heave.
ACCEL_JERK_PSD = 20.0
#: 1-sigma relative thrust uncertainty [negative, positive] when the vehicle file declares none.
DEFAULT_THRUST_UNCERTAINTY_REL = (0.05, 0.10)


def measurement_settings(cfg: VehicleConfig, dof: str) -> dict:
    """Which conditioned signal measures a DOF and the filter tuning.

    Returns {"log": SensorState log key, "column": index, "measured": 'position'|'velocity',
    "std": measurement std, "jerk_psd": q, "accel": True when the accelerometer aids the filter (surge, sway,
    heave; then also "accel_std" and "accel_jerk_psd", :mod:`.fusion`)}. The noise std comes from
    the noise the vehicle file declares (``sensors.dvl75.noise_std_m_s``, ``scale_error_fraction``,
    ``attitude_noise_std_rad``, ``sensors.ms5837.noise_std_pa``, ``sensors.icm20948.*_noise_std_*``; else
    ``sensors.dvl75.velocity_std_m_s`` / typical values), never the simulator's truth; q = std^2 w^k puts the filter
    bandwidth near w = 12 rad/s (translation) or 20 rad/s (rotation) (filters.py: bandwidth ~ (q / std^2)^(1/4) for
    velocity and ^(1/6) for position measurements)."""
    dvl, imu = cfg.sensors.dvl75, cfg.sensors.icm20948
    k = DOFS.index(dof)
    acc = max(float(or_default(imu.accel_noise_std_m_s2, 0.05)), 1e-3)
    att = float(or_default(dvl.attitude_noise_std_rad, 0.005))
    accel = {"accel": True, "accel_std": math.hypot(acc, cfg.environment.gravity_m_s2 * att),
             "accel_jerk_psd": ACCEL_JERK_PSD}
    if dof in ("surge", "sway"):
        std = max(float(or_default(dvl.noise_std_m_s, dvl.velocity_std_m_s)), 1e-3)
        std = math.hypot(std, 0.5 * float(or_default(dvl.scale_error_fraction, 0.0)))
        return {"log": "dvl", "column": k, "measured": "velocity", "std": std, "jerk_psd": std ** 2 * 12.0 ** 4,
                **accel}
    if dof == "heave":
        pa = float(or_default(cfg.sensors.ms5837.noise_std_pa, 20.0))
        std = max(pa / (cfg.environment.water_density_kg_m3 * cfg.environment.gravity_m_s2), 5e-4)
        return {"log": "depth", "column": 0, "measured": "position", "std": std, "jerk_psd": std ** 2 * 12.0 ** 6,
                **accel}
    std = max(float(or_default(imu.gyro_noise_std_rad_s, 0.003)), 5e-4)
    return {"log": "gyro", "column": k - 3, "measured": "velocity", "std": std, "jerk_psd": std ** 2 * 20.0 ** 4,
            "accel": False}


def declared_rel(cfg: VehicleConfig | None) -> tuple[float, float]:
    """1-sigma relative thrust uncertainty [negative, positive]: the vehicle file's bollard-pull fit
    (``thrusters.thrust_fit_uncertainty_rel``), else its declared
    ``thrusters.thrust_uncertainty_rel``, else (also without a vehicle file: a commanded wrench is
    realised by thrust curves nobody measured here) :data:`DEFAULT_THRUST_UNCERTAINTY_REL`."""
    if cfg is None:
        return DEFAULT_THRUST_UNCERTAINTY_REL
    # the bollard-pull fit's own uncertainty (hindrax ident thruster-fit --write) replaces the declared one
    v = cfg.thrusters.thrust_fit_uncertainty_rel
    if v is not None:
        return float(v[0]), float(v[1])
    v = cfg.thrusters.thrust_uncertainty_rel
    return tuple(float(x) for x in v) if v is not None else DEFAULT_THRUST_UNCERTAINTY_REL  # type: ignore
