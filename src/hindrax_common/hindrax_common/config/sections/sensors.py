"""``sensors.*``: the DVL-75, the Ping1D altimeter, the MS5837 pressure sensor and the ICM-20948 IMU
([Hindrax-Drag] Table 1; docs/devices.md), with their plausibility gates and declared noise."""
from __future__ import annotations

import math
from typing import Any, Mapping

from ..spec import ConfigIssue, Spec, flag, integer, real, section, text, vector

_KEYS: dict[str, Spec] = {
    "dvl75.port": text("serial device path or pyserial URL of the DVL-75"),
    "dvl75.baud_rate": integer("baud rate (docs/devices.md §1.1)", choices=(9600, 19200, 38400, 57600, 115200,
                                                                        230400, 460800, 921600)),
    "dvl75.position_frd_m": vector("DVL position relative to the CG, FRD, m", 3, -5.0, 5.0),
    "dvl75.sensor_orientation_rpy_rad": vector(
            "SET-SENSOR-ORIENTATION roll, pitch, heading of the sensor in the vehicle, rad (docs/devices.md §1.4)",
            3, -math.pi, math.pi),
    "dvl75.speed_of_sound_m_s": real("speed of sound sent to the DVL, m/s (docs/devices.md §1.4)", 1100.0, 1950.0),
    "dvl75.velocity_std_m_s": real("1-sigma velocity error used for the covariance, m/s", 0.0, 1.0),
    "dvl75.max_speed_m_s": real("plausibility gate: a faster $DVPDL velocity is published invalid, m/s "
                                "(DVL-75 envelope <= 8 kn = 4.1 m/s, docs/devices.md §1.1)", 0.1, 10.0),
    "dvl75.max_angular_rate_rad_s": real("plausibility gate: a $DVPDL whose attitude change over dtu gives a "
                                         "faster angular rate is published invalid (it feeds the lever-arm "
                                         "correction), rad/s", 0.1, 50.0),
    "dvl75.min_interval_s": real("plausibility gate: a shorter $DVPDL dtu is published invalid, s "
                                 "(ping rate 5-20 Hz, docs/devices.md §1.1)", 0.001, 1.0),
    "dvl75.max_interval_s": real("plausibility gate: a longer $DVPDL dtu is published invalid, s", 0.05, 10.0),
    "ping1d.port": text("serial device path or pyserial URL of the Ping altimeter"),
    "ping1d.baud_rate": integer("baud rate (docs/devices.md §2.1)", choices=(9600, 115200)),
    "ping1d.position_frd_m": vector("sonar position relative to the CG, FRD, m", 3, -5.0, 5.0),
    "ping1d.speed_of_sound_m_s": real("speed of sound, m/s (fresh water about 1481)", 1000.0, 2000.0),
    "ping1d.ping_interval_s": real("interval between pings, s", 0.01, 10.0),
    "ping1d.mode_auto": flag("let the sonar choose range and gain"),
    "ping1d.field_of_view_rad": real("beam width for sensor_msgs/Range, rad", 0.01, math.pi),
    "ping1d.min_range_m": real("minimum range for sensor_msgs/Range, m", 0.0, 100.0),
    "ping1d.max_range_m": real("maximum range for sensor_msgs/Range, m", 0.1, 300.0),
    "ms5837.i2c_bus": integer("Linux I2C bus number", 0, 31),
    "ms5837.i2c_address": integer("MS5837 7-bit address (fixed 0x76)", choices=(0x76,)),
    "ms5837.variant": text("sensor variant (auto = C1 heuristic, docs/devices.md §3.9)", ("30BA", "02BA", "auto")),
    "ms5837.oversampling": integer("oversampling ratio (docs/devices.md §3.1)",
                                   choices=(256, 512, 1024, 2048, 4096, 8192)),
    "ms5837.rate_hz": real("pressure publication rate, Hz", 0.1, 50.0),
    "ms5837.position_frd_m": vector("pressure port position relative to the CG, FRD, m", 3, -5.0, 5.0),
    "ms5837.min_pressure_pa": real("plausibility gate: a lower compensated pressure is not published, Pa", 0.0, 2e5),
    "ms5837.max_pressure_pa": real("plausibility gate: a higher compensated pressure is not published, Pa "
                                   "(30BA full scale 30 bar)", 1e4, 3.1e6),
    "ms5837.min_depth_m": real("plausibility gate: a shallower depth (negative = above the surface, e.g. on "
                               "deck) is not published, m", -20.0, 0.0),
    "ms5837.max_depth_m": real("plausibility gate: a deeper depth is not published, m", 0.5, 300.0),
    "ms5837.max_depth_rate_m_s": real("plausibility gate: a depth changing faster than this since the last "
                                      "published one is held back until the next sample confirms it, m/s",
                                      0.1, 20.0),
    "ms5837.zero_depth_margin_pa": real("pressure/zero_depth is refused when the mean pressure is further than "
                                        "this from the atmospheric reference environment.surface_pressure_pa "
                                        "(the vehicle is not at the surface), Pa", 100.0, 50000.0),
    "ms5837.prom_reject_blank_words": flag("PROM sanity gate: reject a PROM whose coefficient C1..C6 reads "
                                           "0x0000 or 0xFFFF (blank or unread PROM; an all-zero PROM passes "
                                           "CRC-4, docs/devices.md §3.2-3.3)"),
    "icm20948.i2c_bus": integer("Linux I2C bus number", 0, 31),
    "icm20948.i2c_address": integer("ICM-20948 7-bit address (AD0 low 0x68, high 0x69)", choices=(0x68, 0x69)),
    "icm20948.accel_full_scale_g": integer("accelerometer full scale, g", choices=(2, 4, 8, 16)),
    "icm20948.gyro_full_scale_dps": integer("gyroscope full scale, deg/s", choices=(250, 500, 1000, 2000)),
    "icm20948.dlpf_config": integer("ACCEL/GYRO_DLPFCFG register code (docs/devices.md §4.4)", 0, 7),
    "icm20948.sample_rate_hz": real("output data rate and publication rate, Hz", 1.0, 1125.0),
    "icm20948.magnetometer_mode": text("how the AK09916 is reached (docs/devices.md §4.6)", ("i2c_master", "bypass")),
    "icm20948.estimate_gyro_bias": flag("estimate gyro bias at start-up while the vehicle is still"),
    "icm20948.gyro_bias_duration_s": real("duration of the start-up gyro-bias estimate, s", 0.1, 60.0),
    "icm20948.mounting_rpy_rad": vector("rotation of the sensor frame in base_link (FLU), rad", 3, -math.pi, math.pi),
    "icm20948.position_frd_m": vector("IMU chip position relative to the CG, FRD, m (the imu_link origin)",
                                      3, -5.0, 5.0),
    "icm20948.frozen_check_samples": integer("data-ready gate: after this many bit-identical samples in a row "
                                             "the chip's PWR_MGMT_1/USER_CTRL are read back (reset check)", 1, 100),
    "icm20948.require_data_ready": flag("data-ready gate: read INT_STATUS_1.RAW_DATA_0_RDY (bank 0, 0x1A) "
                                        "in each poll's burst and publish no sample without it"),
    "icm20948.not_ready_error_polls": integer("data-ready gate: this many consecutive polls without "
                                              "RAW_DATA_0_RDY raise the ERROR data_ready", 1, 10000),
    "icm20948.mag_retry_interval_s": real("lost AK09916: period of the magnetometer re-initialisation "
                                          "attempts until it answers again, s", 0.1, 600.0),
    "icm20948.mag_stale_timeout_s": real("data-ready gate: no new magnetometer sample (ST1.DRDY, SLV0 "
                                         "answered) for this long -> ERROR and re-initialisation, s", 0.05, 10.0),
}
# Declared (datasheet / bench) noise of the sensors: what the vehicle's estimators assume. The virtual pool's own
# noise lives in the truth file (ros_ws/config/truth/*.yaml, ``simulation.sensors.*``), never read by a node.
_KEYS["dvl75.noise_std_m_s"] = real("declared DVL velocity white noise 1-sigma per axis, m/s", 0.0, 1.0)
_KEYS["dvl75.scale_error_fraction"] = real("declared DVL 1-sigma multiplicative velocity error per report", 0.0, 0.5)
_KEYS["dvl75.attitude_noise_std_rad"] = real("declared DVL attitude white noise 1-sigma, rad", 0.0, 1.0)
_KEYS["ms5837.noise_std_pa"] = real("declared pressure white noise 1-sigma, Pa", 0.0, 1e4)
_KEYS["icm20948.accel_noise_std_m_s2"] = real("declared accelerometer white noise 1-sigma, m/s^2", 0.0, 10.0)
_KEYS["icm20948.gyro_noise_std_rad_s"] = real("declared gyro white noise 1-sigma, rad/s", 0.0, 1.0)
SCHEMA, OPTIONAL = section("sensors", _KEYS,
                           optional=("dvl75.noise_std_m_s", "dvl75.scale_error_fraction",
                                     "dvl75.attitude_noise_std_rad", "ms5837.noise_std_pa",
                                     "icm20948.accel_noise_std_m_s2", "icm20948.gyro_noise_std_rad_s"))


def cross_checks(c: Mapping[str, Any]) -> list[ConfigIssue]:
    """Each lower bound of a sensor's range or plausibility gate at most its upper bound."""
    return [ConfigIssue(a, c[a], f"at most {b} ({c[b]:g})")
            for a, b in (("sensors.ping1d.min_range_m", "sensors.ping1d.max_range_m"),
                         ("sensors.dvl75.min_interval_s", "sensors.dvl75.max_interval_s"),
                         ("sensors.ms5837.min_pressure_pa", "sensors.ms5837.max_pressure_pa"))
            if a in c and b in c and c[a] > c[b]]
