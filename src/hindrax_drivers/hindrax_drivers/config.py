"""Vehicle configuration: schema, validation, typed objects and ROS-parameter conversion.

One YAML file per vehicle (``ros_ws/config/hindrax.yaml``) in the ros-args params-file layout::

    /**:
      ros__parameters:
        vehicle:
          mass_kg: 15.22
        ...

Nested keys become dotted ROS parameter names (``vehicle.mass_kg``). Every key of the file is declared in
:data:`SCHEMA` below with its type, unit (in the key name), allowed range and a one-line meaning; the
loader rejects unknown keys, wrong types and out-of-range values, reporting each as one line naming the
key, the value and the allowed range (docs/architecture.md §4). Geometry is in the marine body frame FRD with the
origin at the centre of gravity (docs/architecture.md §3); hydrodynamic coefficients are stored as positive numbers
(Fossen/SNAME).

Thruster-specific keys use the thruster names of ``thrusters.names`` as a path segment
(``thrusters.t3.esc_channel``); the schema writes that segment as ``<thruster>``.

Why our own validator rather than a schema library: the errors must name ROS parameter keys in the exact
one-line form users see from ``hindrax config check``, and the same checks must run on a YAML file and on
the parameters of a running rclpy node. No maintained library covers ROS parameter overrides.

Typed access: :class:`VehicleConfig` builds one frozen dataclass per section (``cfg.esc.output_latency_s``,
``cfg.sensors.dvl75.position_frd_m``, ``cfg.supervisor.min_rate.imu_hz``), so a misspelt name is an AttributeError
that mypy and the import of a module's tests catch, not a KeyError on the vehicle. The section classes live in
``config_sections.py``, GENERATED from :data:`SCHEMA` by ``scripts/gen_config_sections.py`` (a test checks the
file is current and that every key has a field of its kind, and every field a key): writing them by hand next to
a 250-key schema would let the two drift, and generating them at import time would hide them from mypy. Field
names are the keys' last segments (ROS parameter names do not change), lists are tuples, optional keys are
``X | None``. Section objects are built lazily, once per configuration (it is immutable). A node's configuration
holds only the keys it declared (:mod:`node_parameters`): reading another required key raises KeyError naming it.
Names taken by older typed views: ``cfg.thrusters`` is :class:`ThrustersConfig` (per-thruster keys),
``cfg.hydrodynamics(dof)`` and ``cfg.calibration`` (derived forces) keep their meaning, and the raw sections are
``cfg.hydrodynamics_section`` and ``cfg.calibration_section``. ``cfg.flat`` (dotted key -> value) stays for the
ROS-parameter conversion, overrides and validation; modules outside this one do not index it by a literal key.

Errors: :class:`ConfigError` (a ``ValueError``) carrying a list of :class:`ConfigIssue`.
"""
from __future__ import annotations

import dataclasses
import difflib
import functools
import hashlib
import math
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar, Iterable, Mapping, Sequence, TypeVar

import numpy as np
import yaml
from ament_index_python.packages import get_package_prefix, get_package_share_directory

from .config_sections import (
    ABSENT,
    CalibrationSection,
    ControlSection,
    EnvironmentSection,
    EscSection,
    HydrodynamicsSection,
    IdentificationSection,
    LightsSection,
    LimitsSection,
    PoolSection,
    RecordingSection,
    Section,
    SensorsSection,
    SimulationSection,
    SupervisorSection,
    VehicleSection,
)
from .allocation.thrust_curve import ThrustCurve, ThrustCurveError
from .hardware_limits import (ESC_DEADBAND_US, ESC_NEUTRAL_US, PCA9685_OSCILLATOR_MAX_HZ,
                              PCA9685_OSCILLATOR_MIN_HZ, Pca9685Error, esc_prescale)

DOFS: tuple[str, ...] = ("surge", "sway", "heave", "roll", "pitch", "yaw")
"""The six degrees of freedom in SNAME order (nu = [u v w p q r], tau = [X Y Z K M N])."""

TRANSLATIONAL_DOFS = DOFS[:3]
ROTATIONAL_DOFS = DOFS[3:]

#: Sections a configuration file may contain (top level under ``ros__parameters``).
SECTIONS: tuple[str, ...] = (
    "vehicle", "environment", "hydrodynamics", "thrusters", "esc", "lights", "sensors", "pool", "limits",
    "identification", "simulation", "recording", "supervisor", "calibration", "control",
)

_FLOAT = "float"
_INT = "int"
_STR = "str"
_BOOL = "bool"
_FLOATS = "float[]"
_STRS = "str[]"


@dataclass(frozen=True)
class Spec:
    """Declaration of one configuration key.

    kind: one of "float", "int", "str", "bool", "float[]", "str[]".
    lo/hi: inclusive numeric bounds (for lists: of every element). length: required list length.
    choices: allowed values (str or int). doc: one-line meaning (with unit and source).
    """

    kind: str
    doc: str
    lo: float | None = None
    hi: float | None = None
    length: int | None = None
    choices: tuple | None = None
    unit_vector: bool = False
    #: for "str": a regular expression the whole value must match, and its meaning as printed in error lines
    pattern: tuple[str, str] | None = None

    def allowed(self) -> str:
        """Human-readable allowed range, as printed in error lines."""
        if self.choices is not None:
            return "one of " + ", ".join(str(c) for c in self.choices)
        if self.pattern is not None:
            return self.pattern[1]
        base = {_FLOAT: "number", _INT: "integer", _STR: "string", _BOOL: "true/false",
                _FLOATS: "list of numbers", _STRS: "list of strings"}[self.kind]
        if self.length is not None:
            base += f" of length {self.length}"
        if self.lo is not None or self.hi is not None:
            lo = "-inf" if self.lo is None else f"{self.lo:g}"
            hi = "+inf" if self.hi is None else f"{self.hi:g}"
            base += f" in [{lo}, {hi}]"
        if self.unit_vector:
            base += ", unit length"
        return base


def _f(doc: str, lo: float | None = None, hi: float | None = None) -> Spec:
    return Spec(_FLOAT, doc, lo, hi)


def _i(doc: str, lo: int | None = None, hi: int | None = None, choices: tuple | None = None) -> Spec:
    return Spec(_INT, doc, lo, hi, choices=choices)


def _s(doc: str, choices: tuple | None = None) -> Spec:
    return Spec(_STR, doc, choices=choices)


#: A ROS 2 name token (rcl's namespace rules: a letter, then letters, digits and single underscores), 1-63 chars.
ROS_NAME_TOKEN = (r"[A-Za-z](?!.*__)[A-Za-z0-9_]{0,62}",
                  "a ROS name token: a letter, then letters, digits or single underscores, at most 63 characters")


def _b(doc: str) -> Spec:
    return Spec(_BOOL, doc)


def _v(doc: str, length: int, lo: float | None = None, hi: float | None = None, unit: bool = False) -> Spec:
    return Spec(_FLOATS, doc, lo, hi, length=length, unit_vector=unit)


_T = "<thruster>"

SCHEMA: dict[str, Spec] = {
    # --- vehicle ([Hindrax-AM] §2, [Hindrax-Drag] §2.1) ---
    "vehicle.name": Spec(_STR, "the vehicle's name: its namespace on the topside graph (docs/architecture.md "
                               "§8.2), unique among the vehicles on one topside domain", pattern=ROS_NAME_TOKEN),
    "vehicle.mass_kg": _f("total mass in air, kg ([Hindrax-Drag] §2.1)", 0.1, 1000.0),
    "vehicle.displaced_volume_m3": _f("displaced volume, m^3 ([Hindrax-Drag] §2.1)", 1e-5, 10.0),
    "vehicle.length_m": _f("overall length (x), m ([Hindrax-Drag] §2.1)", 0.01, 10.0),
    "vehicle.width_m": _f("overall width (y), m ([Hindrax-Drag] §2.1)", 0.01, 10.0),
    "vehicle.height_m": _f("overall height (z), m ([Hindrax-Drag] §2.1)", 0.01, 10.0),
    "vehicle.net_buoyancy_n": _f("stated net buoyancy (buoyancy - weight), N; checked against (rho V - m) g",
                                 -100.0, 100.0),
    "vehicle.inertia_kg_m2": _v("principal moments of inertia [Ixx, Iyy, Izz] about the CG, kg m^2", 3, 1e-6, 1e4),
    "vehicle.products_of_inertia_kg_m2": _v("products of inertia [Ixy, Ixz, Iyz], kg m^2", 3, -1e4, 1e4),
    "vehicle.centre_of_gravity_frd_m": _v("CG relative to the body origin, FRD, m", 3, -5.0, 5.0),
    "vehicle.centre_of_buoyancy_frd_m": _v("CB relative to the body origin, FRD, m", 3, -5.0, 5.0),
    # --- environment ---
    "environment.water_density_kg_m3": _f("water density, kg/m^3 (seeds use 1000)", 900.0, 1100.0),
    "environment.gravity_m_s2": _f("gravitational acceleration, m/s^2", 9.7, 9.9),
    "environment.kinematic_viscosity_m2_s": _f("kinematic viscosity of water, m^2/s ([Hindrax-AM] §4)", 1e-7, 1e-5),
    "environment.surface_pressure_pa": _f("atmospheric pressure at the surface, Pa", 50000.0, 120000.0),
    # --- hydrodynamics (positive numbers; [Hindrax-AM] Table 6, [Hindrax-Drag] Table 3) ---
    "hydrodynamics.added_mass_coupling": _v(
        "off-diagonal added-mass terms added to diag(added_mass), row-major 6x6 (kg, kg m, kg m^2); "
        "diagonal entries must be 0", 36, -1e4, 1e4),
}
for _dof in TRANSLATIONAL_DOFS:
    SCHEMA[f"hydrodynamics.{_dof}.added_mass_kg"] = _f(f"{_dof} added mass, kg", 0.0, 1e4)
    if _dof == "heave":
        for _d in ("positive", "negative"):
            SCHEMA[f"hydrodynamics.heave.linear_damping_{_d}_kg_s"] = _f(
                f"heave linear damping for {_d} w (positive = down), kg/s", 0.0, 1e4)
            SCHEMA[f"hydrodynamics.heave.quadratic_damping_{_d}_kg_m"] = _f(
                f"heave quadratic damping for {_d} w (positive = down), kg/m", 0.0, 1e4)
    else:
        SCHEMA[f"hydrodynamics.{_dof}.linear_damping_kg_s"] = _f(f"{_dof} linear damping, kg/s", 0.0, 1e4)
        SCHEMA[f"hydrodynamics.{_dof}.quadratic_damping_kg_m"] = _f(f"{_dof} quadratic damping, kg/m", 0.0, 1e4)
for _dof in ROTATIONAL_DOFS:
    SCHEMA[f"hydrodynamics.{_dof}.added_mass_kg_m2"] = _f(f"{_dof} added moment of inertia, kg m^2", 0.0, 1e3)
    SCHEMA[f"hydrodynamics.{_dof}.linear_damping_kg_m2_s"] = _f(
        f"{_dof} linear damping, N m/(rad/s) = kg m^2/s", 0.0, 1e3)
    SCHEMA[f"hydrodynamics.{_dof}.quadratic_damping_kg_m2"] = _f(
        f"{_dof} quadratic damping, N m/(rad/s)^2 = kg m^2", 0.0, 1e3)

SCHEMA.update({
    # --- thrusters ([Hindrax-Drag] §2.2, eq. 1, Table 2, §4 eq. 9) ---
    "thrusters.names": Spec(_STRS, "thruster names in allocation order"),
    "thrusters.pulse_width_min_us": _f("lowest pulse width (full reverse), us ([Hindrax-Drag] §2.2.1)", 500.0, 2500.0),
    "thrusters.pulse_width_neutral_us": _f("neutral pulse width (stop), us ([Hindrax-Drag] §2.2.1)", 500.0, 2500.0),
    "thrusters.pulse_width_max_us": _f("highest pulse width (full forward), us ([Hindrax-Drag] §2.2.1)", 500.0, 2500.0),
    "thrusters.deadband_us": _f("half-width of the ESC deadband around neutral, us (docs/devices.md §5.2)", 0.0, 200.0),
    "thrusters.curve_negative": _v("cubic [c4, c3, c2, c1] for P below neutral, N ([Hindrax-Drag] eq. 1)", 4),
    "thrusters.curve_positive": _v("cubic [c4, c3, c2, c1] for P above neutral, N ([Hindrax-Drag] eq. 1)", 4),
    "thrusters.time_constant_s": _f("first-order thruster lag time constant, s", 0.0, 5.0),
    "thrusters.allocation_mode": _s("saturation handling", ("uniform", "priority")),
    "thrusters.priority_dofs": Spec(_STRS, "DOFs kept exact in priority mode", choices=DOFS),
    "thrusters.max_wrench_excess_ratio": _f("a wrench beyond this many times what the thrusters can produce on an "
                                            "axis is rejected (neutral), not scaled into full thrust", 1.0, 100.0),
    "thrusters.wrench_timeout_s": _f("wrench older than this is rejected as stale, s", 0.01, 10.0),
    "thrusters.wrench_future_margin_s": _f("wrench stamped further than this in the future is rejected (clock "
                                           "offset allowed between the controller and this node), s", 0.0, 5.0),
    f"thrusters.{_T}.position_frd_m": _v("thruster position relative to the CG, FRD, m", 3, -5.0, 5.0),
    f"thrusters.{_T}.direction_frd": _v("unit thrust direction for positive thrust, FRD", 3, -1.0, 1.0, unit=True),
    f"thrusters.{_T}.esc_channel": _i("PCA9685 output channel", 0, 15),
    f"thrusters.{_T}.reversed": _b("mirror the pulse width about neutral (propeller/wiring reversed)"),
    f"thrusters.{_T}.trim_us": _f("pulse-width trim added after allocation, us", -100.0, 100.0),
    f"thrusters.{_T}.allocation_weight": _f("weight of this thruster in the weighted pseudo-inverse", 1e-3, 1e3),
    # --- ESC output: PCA9685 (docs/devices.md §5.1-5.2) ---
    "esc.i2c_bus": _i("Linux I2C bus number (/dev/i2c-N)", 0, 31),
    "esc.i2c_address": _i("PCA9685 7-bit address", 0x40, 0x7F),
    "esc.pwm_frequency_hz": _f("PWM frequency, Hz (Basic ESC max 400 Hz)", 24.0, 400.0),
    "esc.oscillator_hz": _f("calibrated PCA9685 internal oscillator frequency, Hz (25 MHz nominal, NXP PCA9685 "
                            "data sheet §7.3.5; parts measure 23-27 MHz, docs/devices.md §5.1)",
                            PCA9685_OSCILLATOR_MIN_HZ, PCA9685_OSCILLATOR_MAX_HZ),
    "esc.arming_time_s": _f("time at neutral before arming is accepted, s (docs/devices.md §5.2: BR holds 7 s)",
                            0.0, 60.0),
    "esc.watchdog_timeout_s": _f("no command for this long -> all neutral, s", 0.02, 10.0),
    "esc.output_rate_hz": _f("rate the outputs are refreshed and the watchdog checked, Hz", 1.0, 400.0),
    "esc.slew_rate_us_per_s": _f("max pulse-width change rate, us/s (0 = off)", 0.0, 1e6),
    "esc.output_latency_s": _f("delay from the ESC node's stamp of a written width (thrusters/pulse_width) to the "
                               "thrust starting to change, s: the identification's force timing", 0.0, 0.5),
    "esc.oscillator_calibrated": _b("esc.oscillator_hz was measured on this board (`hindrax esc calibrate`); "
                                    "arming is refused while false"),
    "esc.readback_interval_s": _f("MODE1, PRE_SCALE and the channel registers are read back this often; a "
                                  "mismatch (chip reset) re-initialises the chip and disarms, s", 0.05, 10.0),
    "esc.heartbeat_timeout_s": _f("the ESC refuses to arm, and disarms, when supervisor/heartbeat or guard/heartbeat "
                                  "is older than this (steady clock; docs/architecture.md §8), s", 0.05, 1.0),
    "esc.guard_heartbeat_timeout_s": _f("the output guard asserts /OE (or silences the chip over I2C) when "
                                        "esc/heartbeat or supervisor/heartbeat is older than this (steady clock; "
                                        "docs/architecture.md §8), s", 0.05, 1.0),
    "esc.output_enable_gpio.chip": _s("gpiochip of the PCA9685 /OE line, e.g. /dev/gpiochip0 (absent or null: /OE "
                                      "not wired, the guard writes the chip's all-off and sleep registers instead)"),
    "esc.output_enable_gpio.line": _i("line offset of the PCA9685 /OE on esc.output_enable_gpio.chip (BCM GPIO number "
                                      "on a Pi 4)", 0, 1023),
    "esc.output_enable_feed_gpio.chip": _s("gpiochip of the hardware watchdog's feed line (docs/watchdog.md: a "
                                           "retriggerable monostable that holds /OE high unless it sees rising "
                                           "edges); absent or null: no hardware watchdog"),
    "esc.output_enable_feed_gpio.line": _i("line offset of the watchdog feed on esc.output_enable_feed_gpio.chip (BCM "
                                           "GPIO number on a Pi 4)", 0, 1023),
    "esc.output_enable_feed_rate_hz": _f("rising edges per second the output guard puts on the watchdog feed while "
                                         "the ESC heartbeat is fresh and nothing is tripped, Hz", 2.0, 50.0),
    "esc.output_enable_feed_timeout_s": _f("the hardware watchdog's timeout: its monostable's pulse width "
                                           "t_W = R_EXT * C_EXT (docs/watchdog.md); the outputs stop this long after "
                                           "the last rising edge, s", 0.05, 2.0),
    # --- lights ([Hindrax-Drag] §2.1: PWM also drives the lights) ---
    "lights.esc_channel": _i("PCA9685 channel of the lights", 0, 15),
    "lights.pulse_width_off_us": _f("pulse width for lights off, us", 500.0, 2500.0),
    "lights.pulse_width_full_us": _f("pulse width for full brightness, us", 500.0, 2500.0),
    # --- sensors ([Hindrax-Drag] Table 1; docs/devices.md) ---
    "sensors.dvl75.port": _s("serial device path or pyserial URL of the DVL-75"),
    "sensors.dvl75.baud_rate": _i("baud rate (docs/devices.md §1.1)", choices=(9600, 19200, 38400, 57600, 115200,
                                                                           230400, 460800, 921600)),
    "sensors.dvl75.position_frd_m": _v("DVL position relative to the CG, FRD, m", 3, -5.0, 5.0),
    "sensors.dvl75.sensor_orientation_rpy_rad": _v(
        "SET-SENSOR-ORIENTATION roll, pitch, heading of the sensor in the vehicle, rad (docs/devices.md §1.4)",
        3, -math.pi, math.pi),
    "sensors.dvl75.speed_of_sound_m_s": _f("speed of sound sent to the DVL, m/s (docs/devices.md §1.4)", 1100.0, 1950.0),
    "sensors.dvl75.velocity_std_m_s": _f("1-sigma velocity error used for the covariance, m/s", 0.0, 1.0),
    "sensors.dvl75.max_speed_m_s": _f("plausibility gate: a faster $DVPDL velocity is published invalid, m/s "
                                      "(DVL-75 envelope <= 8 kn = 4.1 m/s, docs/devices.md §1.1)", 0.1, 10.0),
    "sensors.dvl75.max_angular_rate_rad_s": _f("plausibility gate: a $DVPDL whose attitude change over dtu gives a "
                                               "faster angular rate is published invalid (it feeds the lever-arm "
                                               "correction), rad/s", 0.1, 50.0),
    "sensors.dvl75.min_interval_s": _f("plausibility gate: a shorter $DVPDL dtu is published invalid, s "
                                       "(ping rate 5-20 Hz, docs/devices.md §1.1)", 0.001, 1.0),
    "sensors.dvl75.max_interval_s": _f("plausibility gate: a longer $DVPDL dtu is published invalid, s", 0.05, 10.0),
    "sensors.ping1d.port": _s("serial device path or pyserial URL of the Ping altimeter"),
    "sensors.ping1d.baud_rate": _i("baud rate (docs/devices.md §2.1)", choices=(9600, 115200)),
    "sensors.ping1d.position_frd_m": _v("sonar position relative to the CG, FRD, m", 3, -5.0, 5.0),
    "sensors.ping1d.speed_of_sound_m_s": _f("speed of sound, m/s (fresh water about 1481)", 1000.0, 2000.0),
    "sensors.ping1d.ping_interval_s": _f("interval between pings, s", 0.01, 10.0),
    "sensors.ping1d.mode_auto": _b("let the sonar choose range and gain"),
    "sensors.ping1d.field_of_view_rad": _f("beam width for sensor_msgs/Range, rad", 0.01, math.pi),
    "sensors.ping1d.min_range_m": _f("minimum range for sensor_msgs/Range, m", 0.0, 100.0),
    "sensors.ping1d.max_range_m": _f("maximum range for sensor_msgs/Range, m", 0.1, 300.0),
    "sensors.ms5837.i2c_bus": _i("Linux I2C bus number", 0, 31),
    "sensors.ms5837.i2c_address": _i("MS5837 7-bit address (fixed 0x76)", choices=(0x76,)),
    "sensors.ms5837.variant": _s("sensor variant (auto = C1 heuristic, docs/devices.md §3.9)", ("30BA", "02BA", "auto")),
    "sensors.ms5837.oversampling": _i("oversampling ratio (docs/devices.md §3.1)",
                                      choices=(256, 512, 1024, 2048, 4096, 8192)),
    "sensors.ms5837.rate_hz": _f("pressure publication rate, Hz", 0.1, 50.0),
    "sensors.ms5837.position_frd_m": _v("pressure port position relative to the CG, FRD, m", 3, -5.0, 5.0),
    "sensors.ms5837.min_pressure_pa": _f("plausibility gate: a lower compensated pressure is not published, Pa",
                                         0.0, 2e5),
    "sensors.ms5837.max_pressure_pa": _f("plausibility gate: a higher compensated pressure is not published, Pa "
                                         "(30BA full scale 30 bar)", 1e4, 3.1e6),
    "sensors.ms5837.min_depth_m": _f("plausibility gate: a shallower depth (negative = above the surface, e.g. on "
                                     "deck) is not published, m", -20.0, 0.0),
    "sensors.ms5837.max_depth_m": _f("plausibility gate: a deeper depth is not published, m", 0.5, 300.0),
    "sensors.ms5837.max_depth_rate_m_s": _f("plausibility gate: a depth changing faster than this since the last "
                                            "published one is held back until the next sample confirms it, m/s",
                                            0.1, 20.0),
    "sensors.ms5837.zero_depth_margin_pa": _f("pressure/zero_depth is refused when the mean pressure is further than "
                                              "this from the atmospheric reference environment.surface_pressure_pa "
                                              "(the vehicle is not at the surface), Pa", 100.0, 50000.0),
    "sensors.ms5837.prom_reject_blank_words": _b("PROM sanity gate: reject a PROM whose coefficient C1..C6 reads "
                                                 "0x0000 or 0xFFFF (blank or unread PROM; an all-zero PROM passes "
                                                 "CRC-4, docs/devices.md §3.2-3.3)"),
    "sensors.icm20948.i2c_bus": _i("Linux I2C bus number", 0, 31),
    "sensors.icm20948.i2c_address": _i("ICM-20948 7-bit address (AD0 low 0x68, high 0x69)", choices=(0x68, 0x69)),
    "sensors.icm20948.accel_full_scale_g": _i("accelerometer full scale, g", choices=(2, 4, 8, 16)),
    "sensors.icm20948.gyro_full_scale_dps": _i("gyroscope full scale, deg/s", choices=(250, 500, 1000, 2000)),
    "sensors.icm20948.dlpf_config": _i("ACCEL/GYRO_DLPFCFG register code (docs/devices.md §4.4)", 0, 7),
    "sensors.icm20948.sample_rate_hz": _f("output data rate and publication rate, Hz", 1.0, 1125.0),
    "sensors.icm20948.magnetometer_mode": _s("how the AK09916 is reached (docs/devices.md §4.6)",
                                             ("i2c_master", "bypass")),
    "sensors.icm20948.estimate_gyro_bias": _b("estimate gyro bias at start-up while the vehicle is still"),
    "sensors.icm20948.gyro_bias_duration_s": _f("duration of the start-up gyro-bias estimate, s", 0.1, 60.0),
    "sensors.icm20948.mounting_rpy_rad": _v("rotation of the sensor frame in base_link (FLU), rad",
                                            3, -math.pi, math.pi),
    "sensors.icm20948.position_frd_m": _v("IMU chip position relative to the CG, FRD, m (the imu_link origin)",
                                          3, -5.0, 5.0),
    "sensors.icm20948.frozen_check_samples": _i("data-ready gate: after this many bit-identical samples in a row "
                                                "the chip's PWR_MGMT_1/USER_CTRL are read back (reset check)", 1, 100),
    "sensors.icm20948.require_data_ready": _b("data-ready gate: read INT_STATUS_1.RAW_DATA_0_RDY (bank 0, 0x1A) "
                                              "before each poll and publish no sample without it"),
    "sensors.icm20948.not_ready_error_polls": _i("data-ready gate: this many consecutive polls without "
                                                 "RAW_DATA_0_RDY raise the ERROR data_ready", 1, 10000),
    "sensors.icm20948.mag_retry_interval_s": _f("lost AK09916: period of the magnetometer re-initialisation "
                                                "attempts until it answers again, s", 0.1, 600.0),
    "sensors.icm20948.mag_stale_timeout_s": _f("data-ready gate: no new magnetometer sample (ST1.DRDY, SLV0 "
                                               "answered) for this long -> ERROR and re-initialisation, s", 0.05, 10.0),
    # --- pool ([Hindrax-Drag] §4) ---
    "pool.length_m": _f("pool length (north, x), m", 1.0, 200.0),
    "pool.width_m": _f("pool width (east, y), m", 1.0, 200.0),
    "pool.depth_m": _f("water depth, m", 0.3, 100.0),
    "pool.margin_m": _f("keep-out margin from walls and floor for manoeuvres, m", 0.0, 10.0),
    "pool.start_position_ned_m": _v("vehicle start position (north, east, down) from the pool corner, m", 3,
                                    -1.0, 200.0),
    "pool.start_heading_rad": _f("vehicle start heading, rad (NED yaw)", -math.pi, math.pi),
    # --- limits (docs/architecture.md §8) ---
    "limits.max_depth_m": _f("abort below this depth, m", 0.0, 100.0),
    "limits.min_altitude_m": _f("abort closer than this to the floor, m", 0.0, 10.0),
    "limits.max_roll_rad": _f("abort beyond this roll, rad", 0.0, math.pi),
    "limits.max_pitch_rad": _f("abort beyond this pitch, rad", 0.0, math.pi / 2),
    # --- safety supervisor (hindrax_drivers.supervisor): the last line after the identification's own limits ---
    "supervisor.check_rate_hz": _f("rate of the supervisor's rate and run-time checks, Hz", 1.0, 200.0),
    "supervisor.rate_window_s": _f("window the sensor rates are measured over (at most "
                                   "supervisor.reaction_time_s), s", 0.2, 60.0),
    "supervisor.max_sample_age_s": _f("a sensor sample whose header stamp is further than this from the supervisor's "
                                      "time on arrival (older, or ahead) is not alive: not counted, not used, s",
                                      0.05, 10.0),
    "supervisor.max_identical_s": _f("a sensor stream bit-identical (header stamp aside) for longer than this is "
                                     "frozen: its samples are not alive (sensor noise changes every reading within "
                                     "a few samples), s", 0.1, 10.0),
    "supervisor.reaction_time_s": _f("longest time a failed sensor (silent, stale or frozen) may go unnoticed while "
                                     "armed; bounds supervisor.rate_window_s, max_invalid_dvl_s, max_sample_age_s and "
                                     "max_identical_s, s",
                                     0.1, 10.0),
    "supervisor.min_rate.dvl_hz": _f("minimum dvl/data rate while armed, Hz (0 = not watched)", 0.0, 1000.0),
    "supervisor.min_rate.altimeter_hz": _f("minimum ping/altitude rate while armed, Hz (0 = not watched)",
                                           0.0, 1000.0),
    "supervisor.min_rate.pressure_hz": _f("minimum pressure/depth rate while armed, Hz (0 = not watched)",
                                          0.0, 1000.0),
    "supervisor.min_rate.imu_hz": _f("minimum imu/data_raw rate while armed, Hz (0 = not watched)", 0.0, 2000.0),
    "supervisor.max_invalid_dvl_s": _f("armed with no valid DVL velocity for this long -> trip (the cage's dead "
                                       "reckoning is frozen meanwhile), s", 0.1, 60.0),
    "supervisor.rate_check_disabled.dvl": _s("why supervisor.min_rate.dvl_hz is 0 (required with 0, refused otherwise)"),
    "supervisor.rate_check_disabled.altimeter": _s("why supervisor.min_rate.altimeter_hz is 0 (required with 0)"),
    "supervisor.rate_check_disabled.pressure": _s("why supervisor.min_rate.pressure_hz is 0 (required with 0)"),
    "supervisor.rate_check_disabled.imu": _s("why supervisor.min_rate.imu_hz is 0 (required with 0)"),
    "supervisor.max_depth_m": _f("disarm below this depth (pressure port), m", 0.0, 100.0),
    "supervisor.min_altitude_m": _f("disarm closer than this to the floor (altimeter), m", 0.0, 10.0),
    "supervisor.max_roll_rad": _f("disarm beyond this roll (DVL attitude), rad", 0.0, math.pi),
    "supervisor.max_pitch_rad": _f("disarm beyond this pitch (DVL attitude), rad", 0.0, math.pi / 2),
    "supervisor.cage_margin_m": _f("disarm when the DVL dead-reckoned position comes closer than this to a pool "
                                   "wall (pool.* box), m", 0.0, 10.0),
    "supervisor.max_run_time_s": _f("disarm after this long armed, s", 1.0, 86400.0),
    # --- identification (docs/architecture.md §5; [Hindrax-Drag] §4) ---
    "identification.levels_per_dof": _i("thrust levels in each DOF's ladder", 1, 50),
    "identification.level_fraction_min": _f("smallest level as a fraction of the DOF's authority", 0.01, 1.0),
    "identification.level_fraction_max": _f("largest level as a fraction of the DOF's authority", 0.01, 1.0),
    "identification.forgetting_factor": _f("RLS forgetting factor lambda", 0.9, 1.0),
    "identification.estimate_rate_hz": _f("RLS update rate, Hz", 1.0, 400.0),
    "identification.publish_rate_hz": _f("HydroEstimate publication rate, Hz", 0.1, 50.0),
    "identification.altitude_setpoint_m": _f("altitude held during manoeuvres, m ([Hindrax-Drag] §4: 0.8-1.0 m)",
                                             0.1, 50.0),
    "identification.roll_test_angle_rad": _f("roll test turns back at this angle, rad ([Hindrax-Drag] §4.2: 30 deg)",
                                             0.01, 1.5),
    "identification.pitch_test_angle_rad": _f("pitch test turns back at this angle, rad ([Hindrax-Drag] §4.2: 40 deg)",
                                              0.01, 1.5),
    "identification.max_level_duration_s": _f("longest time one level is held, s", 1.0, 600.0),
    "identification.converged_relative_std": _f("converged when every std/|value| is below this", 0.001, 1.0),
    "identification.prior_std_rel": _f("1-sigma of the empirical priors in the batch fit, as a fraction of the prior "
                                       "value (0 = no prior; docs/identification.md §6.3)", 0.0, 100.0),
    "identification.rls_directional_forgetting": _b("online RLS: forget only along the regressor (Bittanti et al. "
                                                    "1990), default true (docs/identification.md §1.D)"),
    "identification.rls_min_excitation": _f("online RLS: hold the estimate while the normalised excitation is below "
                                            "this once reached (0 = no gate), default 0.001", 0.0, 1.0),
    "identification.rls_change_threshold": _f("online RLS: reset the covariance when the mean normalised a-priori error "
                                              "over rls_change_window_s exceeds this (0 = no detector), default 6",
                                              0.0, 1e6),
    "identification.rls_change_window_s": _f("online RLS: window of the change detector, s, default 10", 0.1, 600.0),
    "identification.rls_prior_std_rel": _f("online RLS: 1-sigma of its starting values (empirical priors) as a "
                                           "fraction of the prior value (0 = diffuse start at zero), default 1",
                                           0.0, 100.0),
    "identification.excitation": _s("force input per DOF: the constant-thrust ladder, or one broadband run shaped to "
                                    "stay in the pool box (hindrax_ident identification/excitation.py)",
                                    ("ladder", "multisine", "prbs", "chirp")),
    "identification.excitation_duration_s": _f("length of the broadband run per DOF (excitation not ladder), s",
                                               5.0, 1800.0),
    # --- calibration: known forces of the campaign's reference steps (docs/identification.md §6) ---
    "calibration.ballast_mass_kg": _f("mass of the ballast hung on the vehicle in the ballast step, kg", 0.01, 50.0),
    "calibration.ballast_volume_m3": _f("displaced volume of that ballast, m^3 (weight in water (m - rho V) g must be "
                                        "> 0)", 0.0, 0.05),
    "calibration.line_pull_force_n": _f("horizontal force of the line over the pool-edge pulley in the line_pull "
                                        "step (e.g. a hanging mass times g), N", 0.1, 200.0),
    "calibration.inclining_mass_kg": _f("test mass of the inclining step, kg", 0.01, 20.0),
    "calibration.inclining_volume_m3": _f("displaced volume of that test mass, m^3 (it must sink)", 0.0, 0.02),
    "calibration.inclining_arm_m": _f("horizontal arm of the test mass from the centre line (roll: to starboard, "
                                      "pitch: forward), m", 0.01, 2.0),
    "calibration.float_mass_kg": _f("mass of the sealed float tied to the vehicle in the float step (optional), kg",
                                    0.0, 50.0),
    "calibration.float_volume_m3": _f("displaced volume of that float, m^3 (net buoyancy (rho V - m) g must be > 0)",
                                      1e-6, 0.1),
    "calibration.net_buoyancy_std_n": _f("1-sigma of the vehicle's net buoyancy (rho V - m) g as weighed, N (the "
                                         "hover holds of the thrust calibration measure the forward thrust against "
                                         "it; optional)", 1e-4, 10.0),
    # --- control: the depth/altitude, heading and velocity holds (hindrax_ident control, docs/control.md §2-§3) ---
    "control.rate_hz": _f("rate of the controller node's wrench, Hz (default 50)", 1.0, 200.0),
    "control.depth_bandwidth_rad_s": _f("target bandwidth of the depth and altitude hold, rad/s (default 2)", 0.05, 20.0),
    "control.heading_bandwidth_rad_s": _f("target bandwidth of the heading hold, rad/s (default 2)", 0.05, 20.0),
    "control.attitude_bandwidth_rad_s": _f("target bandwidth of the roll and pitch holds, rad/s (default 2)",
                                           0.05, 20.0),
    "control.velocity_bandwidth_rad_s": _f("target bandwidth of the surge and sway velocity holds, rad/s (default 3)",
                                           0.05, 20.0),
    "control.damping_ratio": _f("damping ratio of the reference models and the PID, default 1", 0.3, 2.0),
    "control.hold_fraction": _f("share of each axis' authority the holds may use, default 0.6", 0.05, 1.0),
    "control.max_depth_rate_m_s": _f("largest depth rate the reference model asks for, m/s (default 0.3)", 0.01, 2.0),
    "control.max_yaw_rate_rad_s": _f("largest yaw rate the reference model asks for, rad/s (default 0.6)", 0.01, 5.0),
    "control.sensor_timeout_s": _f("the controller stops when depth or attitude is older than this, s (default 0.5)",
                                   0.05, 10.0),
    # --- simulation (docs/architecture.md §6) ---
    "simulation.step_s": _f("fixed integration step, s", 1e-4, 0.05),
    "simulation.real_time_factor": _f("simulated seconds per wall second (0 = as fast as possible)", 0.0, 1000.0),
    "simulation.seed": _i("random seed of the sensor noise", 0, 2**31 - 1),
    "simulation.clock_rate_hz": _f("rate /clock is published, in simulated time, Hz", 1.0, 1000.0),
    # --- recording (docs/architecture.md §7) ---
    "recording.output_root": _s("directory new bags are created in"),
    "recording.compression": _s("chunk compression", ("zstd", "lz4", "none")),
    "recording.chunk_size_bytes": _i("MCAP chunk size, bytes", 1024, 64 * 1024 * 1024),
    "recording.split_size_bytes": _i("start a new file beyond this size, bytes (0 = never)", 0, 2**40),
    "recording.split_duration_s": _f("start a new file after this duration, s (0 = never)", 0.0, 86400.0),
    "recording.flush_interval_s": _f("close and fsync the open chunk once its oldest message is this old, s "
                                     "(bounds the data lost on power loss; 0 = only when the chunk is full)",
                                     0.0, 3600.0),
    "recording.min_free_disk_mb": _f("stop recording cleanly (bag finished) when the free space of the bag's "
                                     "filesystem falls below this, MB (1e6 bytes; 0 = no check)", 0.0, 1e7),
})

#: Optional keys: absent is fine; present must validate. Everything else in SCHEMA is required.
OPTIONAL_PREFIXES: tuple[str, ...] = ("simulation.sensors.", "recording.topics", "sensors.dvl75.noise_std_m_s",
                                      "sensors.dvl75.scale_error_fraction", "sensors.dvl75.attitude_noise_std_rad",
                                      "sensors.ms5837.noise_std_pa", "sensors.icm20948.accel_noise_std_m_s2",
                                      "sensors.icm20948.gyro_noise_std_rad_s", "thrusters.thrust_uncertainty_rel",
                                      "identification.excitation", "identification.prior_std_rel",
                                      "identification.rls_", "thrusters.thrust_fit_uncertainty_rel",
                                      "calibration.float_", "calibration.net_buoyancy_std_n",
                                      "esc.output_enable_gpio.", "esc.output_enable_feed", "supervisor.rate_check_disabled.",
                                      "control.")

# Sensor-model keys of the simulator: per device, the same set (noise, bias, rate, dropout).
for _dev, _unit, _hi in (("dvl75", "m_s", 1.0), ("ping1d", "m", 1.0), ("ms5837", "pa", 1e4),
                         ("icm20948_accel", "m_s2", 10.0), ("icm20948_gyro", "rad_s", 1.0),
                         ("icm20948_mag", "t", 1e-3), ("dvl75_attitude", "rad", 1.0)):
    SCHEMA[f"simulation.sensors.{_dev}.noise_std_{_unit}"] = _f(f"{_dev} white-noise 1-sigma, {_unit}", 0.0, _hi)
    SCHEMA[f"simulation.sensors.{_dev}.bias_{_unit}"] = _f(f"{_dev} constant bias, {_unit}", -_hi, _hi)
    SCHEMA[f"simulation.sensors.{_dev}.rate_hz"] = _f(f"{_dev} output rate, Hz", 0.1, 2000.0)
    SCHEMA[f"simulation.sensors.{_dev}.dropout_probability"] = _f(f"{_dev} probability a sample is lost", 0.0, 1.0)
SCHEMA["simulation.sensors.dvl75.scale_error_fraction"] = _f(
    "1-sigma multiplicative velocity error per report ([Hindrax-Drag] Table 1: mean error about 5 %)", 0.0, 0.5)
SCHEMA["simulation.sensors.dvl75.min_altitude_m"] = _f("DVL loses lock below this altitude, m", 0.0, 10.0)
SCHEMA["simulation.sensors.dvl75.max_altitude_m"] = _f("DVL loses lock above this altitude, m", 0.1, 200.0)
SCHEMA["simulation.sensors.dvl75.wall_lock_loss_distance_m"] = _f(
    "DVL loses lock closer than this to a wall, m (0 = never)", 0.0, 10.0)
SCHEMA["simulation.sensors.icm20948_mag.earth_field_ned_t"] = _v(
    "earth magnetic field [north, east, down] seen by the simulated magnetometer, T", 3, -1e-4, 1e-4)
# Declared (datasheet / bench) noise of the sensors: what the vehicle's estimators assume. The virtual pool's own
# noise lives in the truth file (ros_ws/config/truth/*.yaml, ``simulation.sensors.*``), never read by a node.
SCHEMA["sensors.dvl75.noise_std_m_s"] = _f("declared DVL velocity white noise 1-sigma per axis, m/s", 0.0, 1.0)
SCHEMA["sensors.dvl75.scale_error_fraction"] = _f("declared DVL 1-sigma multiplicative velocity error per report",
                                                  0.0, 0.5)
SCHEMA["sensors.dvl75.attitude_noise_std_rad"] = _f("declared DVL attitude white noise 1-sigma, rad", 0.0, 1.0)
SCHEMA["sensors.ms5837.noise_std_pa"] = _f("declared pressure white noise 1-sigma, Pa", 0.0, 1e4)
SCHEMA["sensors.icm20948.accel_noise_std_m_s2"] = _f("declared accelerometer white noise 1-sigma, m/s^2", 0.0, 10.0)
SCHEMA["sensors.icm20948.gyro_noise_std_rad_s"] = _f("declared gyro white noise 1-sigma, rad/s", 0.0, 1.0)
SCHEMA["thrusters.thrust_uncertainty_rel"] = _v(
    "declared 1-sigma relative uncertainty of the thrust curves [negative, positive direction] (battery state, "
    "curve fit), added to the identification intervals", 2, 0.0, 1.0)
SCHEMA["thrusters.thrust_fit_uncertainty_rel"] = _v(
    "1-sigma relative uncertainty of the thrust curves [negative, positive direction] from the bollard-pull fit "
    "(written by hindrax ident thruster-fit --write); replaces thrust_uncertainty_rel in the intervals", 2, 0.0, 1.0)
SCHEMA["recording.topics"] = Spec(_STRS, "topics recorded by default (empty list not allowed by ROS: omit the key "
                                         "to record all topics)")


# ---------------------------------------------------------------------------------------------------------
# Errors


@dataclass(frozen=True)
class ConfigIssue:
    """One validation error: the key, the offending value and the allowed range."""

    key: str
    value: Any
    allowed: str

    def line(self) -> str:
        """One line: ``key = value: allowed ...`` (``unknown key`` / ``missing`` where that is the problem)."""
        if self.allowed.startswith("no such key"):
            return f"{self.key} = {_show(self.value)}: unknown key{self.allowed[len('no such key'):]}"
        if self.value == "<missing>":
            return f"{self.key} is missing: allowed {self.allowed}"
        return f"{self.key} = {_show(self.value)}: allowed {self.allowed}"


class ConfigError(ValueError):
    """Raised when a configuration does not validate. ``issues`` lists every problem found.

    ``str(error)`` is the first issue as one line (what a node prints when it refuses to start).
    """

    def __init__(self, issues: Sequence[ConfigIssue], source: str = ""):
        self.issues = list(issues)
        self.source = source
        prefix = f"{source}: " if source else ""
        first = self.issues[0].line() if self.issues else "invalid configuration"
        more = f" (and {len(self.issues) - 1} more)" if len(self.issues) > 1 else ""
        super().__init__(f"{prefix}{first}{more}")

    def lines(self) -> list[str]:
        """Every issue as one line each."""
        return [i.line() for i in self.issues]


def _show(value: Any) -> str:
    if isinstance(value, str):
        return repr(value)
    if isinstance(value, (list, tuple, np.ndarray)):
        return "[" + ", ".join(_show(v) for v in value) + "]"
    return str(value)


# ---------------------------------------------------------------------------------------------------------
# Flattening and validation


def flatten(tree: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """Flatten nested mappings into dotted keys (``{"a": {"b": 1}} -> {"a.b": 1}``); lists are leaves."""
    out: dict[str, Any] = {}
    for k, v in tree.items():
        key = f"{prefix}{k}"
        if isinstance(v, Mapping):
            out.update(flatten(v, key + "."))
        else:
            out[key] = v
    return out


def _schema_key(key: str, thruster_names: Iterable[str]) -> str | None:
    """Map a concrete key to its SCHEMA entry (thruster name -> <thruster>), or None if unknown."""
    if key in SCHEMA:
        return key
    parts = key.split(".")
    if len(parts) == 3 and parts[0] == "thrusters" and parts[1] in set(thruster_names):
        generic = f"thrusters.{_T}.{parts[2]}"
        if generic in SCHEMA:
            return generic
    return None


#: keys whose YAML value may be null, meaning "absent" (their sub-keys are optional)
NULLABLE_KEYS: tuple[str, ...] = ("esc.output_enable_gpio", "esc.output_enable_feed_gpio")


def output_enable_gpio(cfg: Any, key: str = "esc.output_enable_gpio") -> tuple[str, int] | None:
    """``(chip, line)`` of the PCA9685 /OE line from ``esc.output_enable_gpio`` (or of another GPIO key, e.g.
    ``esc.output_enable_feed_gpio``), or None when it is not wired."""
    flat = cfg.flat if hasattr(cfg, "flat") else cfg
    chip = flat.get(f"{key}.chip")
    if not chip:
        return None
    return str(chip), int(flat[f"{key}.line"])


def _is_optional(key: str) -> bool:
    return any(key.startswith(p) for p in OPTIONAL_PREFIXES)


def _check_value(key: str, spec: Spec, value: Any) -> tuple[Any, ConfigIssue | None]:
    """Coerce and check one value. Returns (coerced value, issue or None)."""
    bad = ConfigIssue(key, value, spec.allowed())

    def number(x: Any) -> float | None:
        if isinstance(x, bool) or not isinstance(x, (int, float, np.integer, np.floating)):
            return None
        x = float(x)
        return x if math.isfinite(x) else None

    if spec.kind == _FLOAT:
        x = number(value)
        if x is None:
            return value, bad
        if (spec.lo is not None and x < spec.lo) or (spec.hi is not None and x > spec.hi):
            return value, bad
        return x, None
    if spec.kind == _INT:
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
            return value, bad
        x = int(value)
        if spec.choices is not None and x not in spec.choices:
            return value, bad
        if (spec.lo is not None and x < spec.lo) or (spec.hi is not None and x > spec.hi):
            return value, bad
        return x, None
    if spec.kind == _STR:
        if not isinstance(value, str):
            return value, bad
        if spec.choices is not None and value not in spec.choices:
            return value, bad
        if spec.pattern is not None and re.fullmatch(spec.pattern[0], value) is None:
            return value, bad
        return value, None
    if spec.kind == _BOOL:
        if not isinstance(value, bool):
            return value, bad
        return value, None
    if spec.kind == _FLOATS:
        if not isinstance(value, (list, tuple, np.ndarray)):
            return value, bad
        maybe = [number(v) for v in value]
        xs = [x for x in maybe if x is not None]
        if len(xs) < len(maybe):
            return value, bad
        if spec.length is not None and len(xs) != spec.length:
            return value, bad
        if any((spec.lo is not None and x < spec.lo) or (spec.hi is not None and x > spec.hi) for x in xs):
            return value, bad
        if spec.unit_vector and abs(math.sqrt(sum(x * x for x in xs)) - 1.0) > 1e-3:
            return value, bad
        return xs, None
    if spec.kind == _STRS:
        if not isinstance(value, (list, tuple)) or not value or not all(isinstance(v, str) for v in value):
            return value, bad
        if spec.choices is not None and any(v not in spec.choices for v in value):
            return value, bad
        return list(value), None
    raise AssertionError(f"unknown spec kind {spec.kind}")  # pragma: no cover - schema bug


def validate_flat(flat: Mapping[str, Any], sections: Iterable[str] = SECTIONS,
                  source: str = "") -> dict[str, Any]:
    """Validate a flat dotted-key mapping against :data:`SCHEMA`.

    Keys outside ``sections`` are an error (unknown section). Returns the coerced mapping.
    Raises :class:`ConfigError` listing every issue (unknown keys, wrong types, out-of-range values,
    missing required keys, cross-key inconsistencies).
    """
    issues: list[ConfigIssue] = []
    sections = tuple(sections)
    names_raw = flat.get("thrusters.names", [])
    names = [n for n in names_raw if isinstance(n, str)] if isinstance(names_raw, (list, tuple)) else []
    out: dict[str, Any] = {}
    for key, value in flat.items():
        if value is None and key in NULLABLE_KEYS:
            continue  # e.g. esc.output_enable_gpio: null (not wired)
        if key.split(".")[0] not in sections:
            issues.append(ConfigIssue(key, value, "no such key (sections: " + ", ".join(sections) + ")"))
            continue
        skey = _schema_key(key, names)
        if skey is None:
            issues.append(ConfigIssue(key, value, "no such key" + _suggest(key, names)))
            continue
        coerced, issue = _check_value(key, SCHEMA[skey], value)
        if issue:
            issues.append(issue)
        else:
            out[key] = coerced
    # required keys
    for skey, spec in SCHEMA.items():
        if skey.split(".")[0] not in sections or _is_optional(skey):
            continue
        concrete = [skey.replace(_T, n) for n in names] if _T in skey else [skey]
        for key in concrete:
            if key not in flat:
                issues.append(ConfigIssue(key, "<missing>", spec.allowed()))
    if not issues:
        issues.extend(_cross_checks(out))
    if issues:
        raise ConfigError(issues, source)
    return out


def _suggest(key: str, names: Sequence[str]) -> str:
    known = [k.replace(_T, names[0]) if (_T in k and names) else k for k in SCHEMA]
    close = difflib.get_close_matches(key, known, n=1, cutoff=0.8)
    return f" (did you mean {close[0]}?)" if close else ""


def _cross_checks(c: Mapping[str, Any]) -> list[ConfigIssue]:
    """Checks across keys. Only run when every key is individually valid."""
    issues: list[ConfigIssue] = []
    if "thrusters.names" in c:
        names = c["thrusters.names"]
        if len(set(names)) != len(names):
            issues.append(ConfigIssue("thrusters.names", names, "unique names"))
        for n in names:
            if not re.fullmatch(r"[a-z][a-z0-9_]*", n):
                issues.append(ConfigIssue("thrusters.names", names, "names matching [a-z][a-z0-9_]*"))
        if "thrusters.pulse_width_min_us" in c:
            lo, mid, hi = (c["thrusters.pulse_width_min_us"], c["thrusters.pulse_width_neutral_us"],
                           c["thrusters.pulse_width_max_us"])
            if not lo < mid < hi:
                issues.append(ConfigIssue("thrusters.pulse_width_neutral_us", mid,
                                          f"strictly between pulse_width_min_us ({lo:g}) and "
                                          f"pulse_width_max_us ({hi:g})"))
            db = c["thrusters.deadband_us"]
            if db >= min(mid - lo, hi - mid):
                issues.append(ConfigIssue("thrusters.deadband_us", db, f"below {min(mid - lo, hi - mid):g}"))
        channels: dict[Any, str] = {}
        for n in names:
            ch = c.get(f"thrusters.{n}.esc_channel")
            if ch in channels:
                issues.append(ConfigIssue(f"thrusters.{n}.esc_channel", ch,
                                          f"a channel not already used by thrusters.{channels[ch]}"))
            channels[ch] = n
        light = c.get("lights.esc_channel")
        if light in channels:
            issues.append(ConfigIssue("lights.esc_channel", light,
                                      f"a channel not used by a thruster (thrusters.{channels[light]})"))
    if "vehicle.mass_kg" in c and "environment.water_density_kg_m3" in c:
        m, vol = c["vehicle.mass_kg"], c["vehicle.displaced_volume_m3"]
        rho, g = c["environment.water_density_kg_m3"], c["environment.gravity_m_s2"]
        derived = (rho * vol - m) * g
        stated = c["vehicle.net_buoyancy_n"]
        tol = max(0.1, 0.1 * abs(derived))
        if abs(derived - stated) > tol:
            issues.append(ConfigIssue("vehicle.net_buoyancy_n", stated,
                                      f"within {tol:.2f} N of (rho V - m) g = {derived:.3f} N"))
    if "hydrodynamics.added_mass_coupling" in c:
        coup = np.asarray(c["hydrodynamics.added_mass_coupling"]).reshape(6, 6)
        if np.any(np.diag(coup) != 0.0):
            issues.append(ConfigIssue("hydrodynamics.added_mass_coupling", c["hydrodynamics.added_mass_coupling"],
                                      "a 6x6 row-major matrix with zero diagonal"))
        elif "hydrodynamics.surge.added_mass_kg" in c:
            ma = added_mass_matrix_from_flat(c)
            if np.min(np.linalg.eigvalsh(0.5 * (ma + ma.T))) <= 0.0:
                issues.append(ConfigIssue("hydrodynamics.added_mass_coupling",
                                          c["hydrodynamics.added_mass_coupling"],
                                          "couplings keeping the added-mass matrix positive definite"))
    for a, b in (("identification.level_fraction_min", "identification.level_fraction_max"),
                 ("sensors.ping1d.min_range_m", "sensors.ping1d.max_range_m"),
                 ("sensors.dvl75.min_interval_s", "sensors.dvl75.max_interval_s"),
                 ("sensors.ms5837.min_pressure_pa", "sensors.ms5837.max_pressure_pa"),
                 ("simulation.sensors.dvl75.min_altitude_m", "simulation.sensors.dvl75.max_altitude_m")):
        if a in c and b in c and c[a] > c[b]:
            issues.append(ConfigIssue(a, c[a], f"at most {b} ({c[b]:g})"))
    if "calibration.ballast_mass_kg" in c and "calibration.ballast_volume_m3" in c:
        rho = float(c.get("environment.water_density_kg_m3", 1000.0))
        v_max = c["calibration.ballast_mass_kg"] / rho
        if c["calibration.ballast_volume_m3"] >= v_max:
            issues.append(ConfigIssue("calibration.ballast_volume_m3", c["calibration.ballast_volume_m3"],
                                      f"below calibration.ballast_mass_kg / water density = {v_max:.4g} (the ballast "
                                      "must sink)"))
    if "calibration.float_mass_kg" in c and "calibration.float_volume_m3" in c:
        v_min = c["calibration.float_mass_kg"] / float(c.get("environment.water_density_kg_m3", 1000.0))
        if c["calibration.float_volume_m3"] <= v_min:
            issues.append(ConfigIssue("calibration.float_volume_m3", c["calibration.float_volume_m3"],
                                      f"above calibration.float_mass_kg / water density = {v_min:.4g} (the float "
                                      "must float)"))
    if "calibration.inclining_mass_kg" in c and "calibration.inclining_volume_m3" in c:
        v_max = c["calibration.inclining_mass_kg"] / float(c.get("environment.water_density_kg_m3", 1000.0))
        if c["calibration.inclining_volume_m3"] >= v_max:
            issues.append(ConfigIssue("calibration.inclining_volume_m3", c["calibration.inclining_volume_m3"],
                                      f"below calibration.inclining_mass_kg / water density = {v_max:.4g} (the test "
                                      "mass must sink)"))
    if "pool.depth_m" in c and "limits.max_depth_m" in c and c["limits.max_depth_m"] > c["pool.depth_m"]:
        issues.append(ConfigIssue("limits.max_depth_m", c["limits.max_depth_m"],
                                  f"at most pool.depth_m ({c['pool.depth_m']:g})"))
    # the supervisor is the last line: its limits at least as wide as the identification's (which abort first)
    for key, other, wider in (("supervisor.max_depth_m", "limits.max_depth_m", "at least"),
                              ("supervisor.min_altitude_m", "limits.min_altitude_m", "at most"),
                              ("supervisor.max_roll_rad", "limits.max_roll_rad", "at least"),
                              ("supervisor.max_pitch_rad", "limits.max_pitch_rad", "at least")):
        if key in c and other in c and (c[key] < c[other] if wider == "at least" else c[key] > c[other]):
            issues.append(ConfigIssue(key, c[key], f"{wider} {other} ({c[other]:g}): the identification aborts first"))
    if "supervisor.cage_margin_m" in c and "pool.width_m" in c and \
            2.0 * c["supervisor.cage_margin_m"] >= min(c["pool.length_m"], c["pool.width_m"]):
        issues.append(ConfigIssue("supervisor.cage_margin_m", c["supervisor.cage_margin_m"],
                                  f"below half the pool's smaller side ({min(c['pool.length_m'], c['pool.width_m']) / 2:g})"))
    issues.extend(_safety_cross_checks(c))
    return issues


def _safety_cross_checks(c: Mapping[str, Any]) -> list[ConfigIssue]:
    """Cross-checks of the safety settings (docs/architecture.md §8), one issue (one line) each."""
    issues: list[ConfigIssue] = _hardware_checks(c)
    # the PWM frequency the ESC node accepts: the ACTUAL rate after prescale rounding within the ESC's 50-400 Hz
    if "esc.pwm_frequency_hz" in c and "esc.oscillator_hz" in c:
        try:
            esc_prescale(c["esc.pwm_frequency_hz"], c["esc.oscillator_hz"])
        except Pca9685Error as exc:
            issues.append(ConfigIssue("esc.pwm_frequency_hz", c["esc.pwm_frequency_hz"],
                                      f"an actual rate within the ESC's 50-400 Hz ({exc})"))
    if "esc.output_enable_gpio.chip" in c and "esc.output_enable_gpio.line" not in c:
        issues.append(ConfigIssue("esc.output_enable_gpio.line", "<missing>", "a line offset with "
                                  "esc.output_enable_gpio.chip"))
    # the hardware watchdog on /OE (docs/watchdog.md): its feed needs a rate and the circuit's timeout, and at least
    # three rising edges per timeout, so that one late guard tick does not stop the outputs
    if c.get("esc.output_enable_feed_gpio.chip"):
        for key in ("esc.output_enable_feed_gpio.line", "esc.output_enable_feed_rate_hz",
                    "esc.output_enable_feed_timeout_s"):
            if key not in c:
                issues.append(ConfigIssue(key, "<missing>", "a value with esc.output_enable_feed_gpio.chip"))
        if "esc.output_enable_feed_rate_hz" in c and "esc.output_enable_feed_timeout_s" in c:
            low = 3.0 / c["esc.output_enable_feed_timeout_s"]
            if c["esc.output_enable_feed_rate_hz"] < low:
                issues.append(ConfigIssue("esc.output_enable_feed_rate_hz", c["esc.output_enable_feed_rate_hz"],
                                          f">= {low:g} Hz: three rising edges per esc.output_enable_feed_timeout_s"))
    # the ESC and the guard must hear several supervisor heartbeats (one per supervisor check) within their timeouts
    for key in ("esc.heartbeat_timeout_s", "esc.guard_heartbeat_timeout_s"):
        if key in c and "supervisor.check_rate_hz" in c:
            period = 1.0 / c["supervisor.check_rate_hz"]
            if c[key] < 2.0 * period:
                issues.append(ConfigIssue(key, c[key], f"at least two supervisor heartbeats (2 / "
                                                       f"supervisor.check_rate_hz = {2.0 * period:g} s)"))
    # a rate check is off only with a reason
    for sensor in ("dvl", "altimeter", "pressure", "imu"):
        key, why = f"supervisor.min_rate.{sensor}_hz", f"supervisor.rate_check_disabled.{sensor}"
        if key not in c:
            continue
        reason = str(c.get(why, "")).strip()
        if c[key] == 0.0 and not reason:
            issues.append(ConfigIssue(key, 0.0, f"above 0, or 0 with {why}: '<reason>' (a disabled check needs a "
                                      "reason)"))
        elif c[key] > 0.0 and why in c:
            issues.append(ConfigIssue(why, c[why], f"absent while {key} = {c[key]:g} (the check is on)"))
    # supervisor limits inside what the sensors can report
    if "supervisor.min_altitude_m" in c and "sensors.ping1d.min_range_m" in c and \
            c["supervisor.min_altitude_m"] < c["sensors.ping1d.min_range_m"]:
        issues.append(ConfigIssue("supervisor.min_altitude_m", c["supervisor.min_altitude_m"],
                                  f"at least sensors.ping1d.min_range_m ({c['sensors.ping1d.min_range_m']:g}): closer "
                                  "is the Ping's blind zone"))
    if "supervisor.max_depth_m" in c:
        for other, what in (("pool.depth_m", "the pool's depth"),
                            ("sensors.ms5837.max_depth_m", "the depth sensor's plausibility gate")):
            if other in c and c["supervisor.max_depth_m"] > c[other]:
                issues.append(ConfigIssue("supervisor.max_depth_m", c["supervisor.max_depth_m"],
                                          f"at most {other} ({c[other]:g}, {what}): a deeper limit never trips"))
                break  # one line per key
    return issues


def _hardware_checks(c: Mapping[str, Any]) -> list[ConfigIssue]:
    """Values checked against the hardware they drive, one issue (one line) each.

    * ``thrusters.pulse_width_neutral_us`` and every neutral + ``trim_us`` (what a disarmed ESC node holds on the
      wire) strictly inside the Basic ESC's own deadband, 1500 +- 25 us (docs/devices.md §5.2; ESC_NEUTRAL_US and
      ESC_DEADBAND_US of :mod:`hindrax_drivers.hardware_limits`): outside it a vehicle that was never armed
      thrusts (1560 us; deadband 120 with trim 100 gives 1600 us).
    * ``thrusters.curve_negative`` / ``curve_positive``: each side increasing with the right sign at its range end
      (negative thrust at ``pulse_width_min_us``, positive at ``pulse_width_max_us``) with a usable monotone branch
      toward the deadband, the condition :class:`~hindrax_drivers.allocation.thrust_curve.ThrustCurve` needs to
      start ([Hindrax-Drag] eq. 1); a negated curve is refused here rather than by the allocation at start-up.
    * ``supervisor.rate_window_s``, ``max_invalid_dvl_s``, ``max_sample_age_s`` and ``max_identical_s`` at most
      ``supervisor.reaction_time_s``: a dead sensor is found at the latest one rate window after it stops (60 s
      found a dead depth sensor after 48 s).

    The oscillator's range (23-27 MHz, :data:`PCA9685_OSCILLATOR_MIN_HZ`) is the key's own range in :data:`SCHEMA`.
    """
    issues: list[ConfigIssue] = []
    lo_us, hi_us = ESC_NEUTRAL_US - ESC_DEADBAND_US, ESC_NEUTRAL_US + ESC_DEADBAND_US
    esc_band = f"the ESC's deadband ({lo_us:g}, {hi_us:g}) us (Basic ESC, docs/devices.md §5.2)"
    mid = c.get("thrusters.pulse_width_neutral_us")
    if mid is not None:
        if not lo_us < mid < hi_us:
            issues.append(ConfigIssue("thrusters.pulse_width_neutral_us", mid,
                                      f"inside {esc_band}: a disarmed ESC output would thrust"))
        else:
            for n in c.get("thrusters.names", ()):
                trim = c.get(f"thrusters.{n}.trim_us")
                if trim is not None and not lo_us < mid + trim < hi_us:
                    issues.append(ConfigIssue(f"thrusters.{n}.trim_us", trim,
                                              f"neutral + trim ({mid + trim:g} us) inside {esc_band}: the "
                                              "disarmed hold would thrust"))
    curve_keys = ("thrusters.curve_negative", "thrusters.curve_positive", "thrusters.pulse_width_min_us",
                  "thrusters.pulse_width_neutral_us", "thrusters.pulse_width_max_us", "thrusters.deadband_us")
    if all(k in c for k in curve_keys):
        try:
            ThrustCurve(*(c[k] for k in curve_keys))
        except ThrustCurveError as exc:
            side = "positive" if str(exc).startswith("positive") else "negative"
            key = f"thrusters.curve_{side}"
            issues.append(ConfigIssue(key, c[key], f"a cubic increasing with the right sign toward its range end "
                                                   f"([Hindrax-Drag] eq. 1): {exc}"))
    reaction = c.get("supervisor.reaction_time_s")
    if reaction is not None:
        for key in ("supervisor.rate_window_s", "supervisor.max_invalid_dvl_s", "supervisor.max_sample_age_s",
                    "supervisor.max_identical_s"):
            if key in c and c[key] > reaction:
                issues.append(ConfigIssue(key, c[key], f"at most supervisor.reaction_time_s ({reaction:g} s): a "
                                                       "failed sensor would go unnoticed longer"))
    return issues


def added_mass_matrix_from_flat(c: Mapping[str, Any]) -> np.ndarray:
    """6x6 added-mass matrix M_A (positive definite, FRD, SNAME order) from validated flat keys."""
    diag = [c[f"hydrodynamics.{d}.added_mass_kg"] for d in TRANSLATIONAL_DOFS] + \
           [c[f"hydrodynamics.{d}.added_mass_kg_m2"] for d in ROTATIONAL_DOFS]
    return np.diag(diag) + np.asarray(c["hydrodynamics.added_mass_coupling"], dtype=float).reshape(6, 6)


# ---------------------------------------------------------------------------------------------------------
# Typed objects


@dataclass(frozen=True)
class DofHydrodynamics:
    """Hydrodynamic coefficients of one DOF (positive numbers, SI).

    added_mass: kg (translation) or kg m^2 (rotation). linear_damping: kg/s or kg m^2/s.
    quadratic_damping: kg/m or kg m^2. Heave has direction-dependent damping ([Hindrax-Drag] Table 3:
    positive heave = moving down, w > 0 in FRD); for the other DOFs the positive and negative values are equal.
    Damping force/moment opposing motion: D(v) = linear v + quadratic |v| v, with the coefficient
    chosen by the sign of v.
    """

    dof: str
    added_mass: float
    linear_damping_positive: float
    linear_damping_negative: float
    quadratic_damping_positive: float
    quadratic_damping_negative: float

    def damping(self, velocity: float) -> float:
        """Damping force (N) or moment (N m) opposing ``velocity`` (m/s or rad/s), signed like velocity."""
        if velocity >= 0.0:
            return self.linear_damping_positive * velocity + self.quadratic_damping_positive * velocity * velocity
        return self.linear_damping_negative * velocity - self.quadratic_damping_negative * velocity * velocity


@dataclass(frozen=True, repr=False)
class ThrusterConfig(Section):
    """One thruster: name, position relative to the CG (FRD, m), unit direction of positive thrust (FRD),
    PCA9685 channel, reversal, trim (us) and allocation weight."""

    name: str
    position_frd_m: np.ndarray
    direction_frd: np.ndarray
    esc_channel: int
    reversed: bool
    trim_us: float
    allocation_weight: float

    PREFIX: ClassVar[str] = "thrusters.<thruster>"  # per instance: thrusters.<name> (KeyError messages)


@dataclass(frozen=True, repr=False)
class ThrustersConfig(Section):
    """Thruster set: per-thruster geometry and the shared cubic thrust curves ([Hindrax-Drag] eq. 1, Table 2).

    curve_negative/curve_positive: [c4, c3, c2, c1] with thrust_N = c4 P^3 + c3 P^2 + c2 P + c1, P in us.
    """

    PREFIX: ClassVar[str] = "thrusters"

    thrusters: tuple[ThrusterConfig, ...]
    pulse_width_min_us: float
    pulse_width_neutral_us: float
    pulse_width_max_us: float
    deadband_us: float
    curve_negative: tuple[float, float, float, float]
    curve_positive: tuple[float, float, float, float]
    time_constant_s: float
    allocation_mode: str
    priority_dofs: tuple[str, ...]
    max_wrench_excess_ratio: float
    wrench_timeout_s: float
    wrench_future_margin_s: float
    thrust_uncertainty_rel: tuple[float, ...] | None
    thrust_fit_uncertainty_rel: tuple[float, ...] | None

    @property
    def names(self) -> list[str]:
        """Thruster names in allocation order."""
        return [t.name for t in self.thrusters]

    @property
    def positions_frd_m(self) -> np.ndarray:
        """(n, 3) positions relative to the CG, FRD, m."""
        return np.array([t.position_frd_m for t in self.thrusters])

    @property
    def directions_frd(self) -> np.ndarray:
        """(n, 3) unit directions of positive thrust, FRD."""
        return np.array([t.direction_frd for t in self.thrusters])


@dataclass(frozen=True)
class CalibrationConfig:
    """The known forces of the campaign's reference steps (``calibration.*``; docs/identification.md §6.1).

    Weights in water and buoyancies are (m - rho V) g and (rho V - m) g with the configured water density and g.
    ``float_net_buoyancy_n`` is None without the optional ``calibration.float_*`` keys; ``net_buoyancy_std_n``
    defaults to 0.05 N (the vehicle weighed in water with a spring scale; ASSUMPTION when not configured).
    """

    ballast_weight_in_water_n: float
    line_pull_force_n: float
    inclining_weight_in_water_n: float
    inclining_arm_m: float
    float_net_buoyancy_n: float | None
    net_buoyancy_std_n: float


_S = TypeVar("_S", bound=Section)
_V = TypeVar("_V")


def or_default(value: _V | None, default: _V) -> _V:
    """``value``, or ``default`` when it is None (an absent optional key of a typed section)."""
    return default if value is None else value


def build_section(cls: type[_S], flat: Mapping[str, Any]) -> _S:
    """The typed section ``cls`` (a generated :class:`config_sections.Section`) from validated flat keys.

    Lists become tuples; an absent optional key is None; an absent required key (a node's selection of keys) is
    held as ABSENT and raises KeyError naming the key when read.
    """
    kw: dict[str, Any] = {}
    for f in dataclasses.fields(cls):  # type: ignore[arg-type]  # the generated sections are dataclasses
        if isinstance(f.type, type) and issubclass(f.type, Section):
            kw[f.name] = build_section(f.type, flat)
            continue
        key = f"{cls.PREFIX}.{f.name}"
        if key in flat:
            v = flat[key]
            kw[f.name] = tuple(v) if isinstance(v, (list, tuple, np.ndarray)) else v
        else:
            kw[f.name] = None if _is_optional(key) else ABSENT
    built: _S = cls.build(kw)
    return built


@dataclass(frozen=True)
class VehicleConfig:
    """The validated vehicle configuration.

    Typed sections (built once, on first use): ``vehicle``, ``environment``, ``hydrodynamics_section``,
    ``thrusters`` (:class:`ThrustersConfig`), ``esc``, ``lights``, ``sensors``, ``pool``, ``limits``,
    ``supervisor``, ``identification``, ``calibration_section``, ``control``, ``simulation``, ``recording``
    (module docstring). Derived views: rigid-body and added-mass matrices, ``hydrodynamics(dof)``,
    ``calibration``. ``flat`` holds every validated key (dotted names, SI values) for the ROS-parameter
    conversion and overrides.
    """

    flat: Mapping[str, Any]
    source: str = ""
    sha256: str = ""

    # -- generic access by dotted key (tools that list or convert keys; modules read the typed sections) --
    def get(self, key: str) -> Any:
        """Value of a dotted key (KeyError if absent)."""
        return self.flat[key]

    def section(self, prefix: str) -> dict[str, Any]:
        """All keys under ``prefix.`` with the prefix removed, e.g. ``section("sensors.dvl75")``."""
        p = prefix.rstrip(".") + "."
        return {k[len(p):]: v for k, v in self.flat.items() if k.startswith(p)}

    # -- typed sections --
    @functools.cached_property
    def vehicle(self) -> VehicleSection:
        """``vehicle.*``: rigid-body data."""
        return build_section(VehicleSection, self.flat)

    @functools.cached_property
    def environment(self) -> EnvironmentSection:
        """``environment.*``: water and gravity."""
        return build_section(EnvironmentSection, self.flat)

    @functools.cached_property
    def hydrodynamics_section(self) -> HydrodynamicsSection:
        """``hydrodynamics.*`` as configured (see also :meth:`hydrodynamics` and :attr:`added_mass_matrix`)."""
        return build_section(HydrodynamicsSection, self.flat)

    @functools.cached_property
    def esc(self) -> EscSection:
        """``esc.*``: the PCA9685 ESC output."""
        return build_section(EscSection, self.flat)

    @functools.cached_property
    def lights(self) -> LightsSection:
        """``lights.*``."""
        return build_section(LightsSection, self.flat)

    @functools.cached_property
    def sensors(self) -> SensorsSection:
        """``sensors.*``: ``dvl75``, ``ping1d``, ``ms5837``, ``icm20948``."""
        return build_section(SensorsSection, self.flat)

    @functools.cached_property
    def pool(self) -> PoolSection:
        """``pool.*``: the pool box and start pose."""
        return build_section(PoolSection, self.flat)

    @functools.cached_property
    def limits(self) -> LimitsSection:
        """``limits.*``: the identification's own abort limits."""
        return build_section(LimitsSection, self.flat)

    @functools.cached_property
    def supervisor(self) -> SupervisorSection:
        """``supervisor.*``: the safety supervisor."""
        return build_section(SupervisorSection, self.flat)

    @functools.cached_property
    def identification(self) -> IdentificationSection:
        """``identification.*``."""
        return build_section(IdentificationSection, self.flat)

    @functools.cached_property
    def calibration_section(self) -> CalibrationSection:
        """``calibration.*`` as configured (masses, volumes; :attr:`calibration` gives the derived forces)."""
        return build_section(CalibrationSection, self.flat)

    @functools.cached_property
    def control(self) -> ControlSection:
        """``control.*``: the holds' settings (all optional: None when absent)."""
        return build_section(ControlSection, self.flat)

    @functools.cached_property
    def simulation(self) -> SimulationSection:
        """``simulation.*``: the virtual pool's integration and sensor models."""
        return build_section(SimulationSection, self.flat)

    @functools.cached_property
    def recording(self) -> RecordingSection:
        """``recording.*``: the MCAP recorder."""
        return build_section(RecordingSection, self.flat)

    # -- derived views --
    @property
    def mass_kg(self) -> float:
        """``vehicle.mass_kg``, kg."""
        return self.vehicle.mass_kg

    @property
    def displaced_volume_m3(self) -> float:
        """``vehicle.displaced_volume_m3``, m^3."""
        return self.vehicle.displaced_volume_m3

    @property
    def water_density_kg_m3(self) -> float:
        """``environment.water_density_kg_m3``, kg/m^3."""
        return self.environment.water_density_kg_m3

    @property
    def gravity_m_s2(self) -> float:
        """``environment.gravity_m_s2``, m/s^2."""
        return self.environment.gravity_m_s2

    @property
    def weight_n(self) -> float:
        """W = m g, N."""
        return self.mass_kg * self.gravity_m_s2

    @property
    def buoyancy_n(self) -> float:
        """B = rho g V, N."""
        return self.water_density_kg_m3 * self.gravity_m_s2 * self.displaced_volume_m3

    @property
    def inertia_matrix_kg_m2(self) -> np.ndarray:
        """3x3 inertia tensor about the CG, kg m^2 (products of inertia with the usual minus sign)."""
        ixx, iyy, izz = self.vehicle.inertia_kg_m2
        ixy, ixz, iyz = self.vehicle.products_of_inertia_kg_m2
        return np.array([[ixx, -ixy, -ixz], [-ixy, iyy, -iyz], [-ixz, -iyz, izz]])

    @property
    def centre_of_gravity_frd_m(self) -> np.ndarray:
        return np.asarray(self.vehicle.centre_of_gravity_frd_m, dtype=float)

    @property
    def centre_of_buoyancy_frd_m(self) -> np.ndarray:
        return np.asarray(self.vehicle.centre_of_buoyancy_frd_m, dtype=float)

    @property
    def added_mass_matrix(self) -> np.ndarray:
        """6x6 positive-definite added-mass matrix M_A, FRD, SNAME order (kg, kg m, kg m^2)."""
        return added_mass_matrix_from_flat(self.flat)

    @functools.cached_property
    def calibration(self) -> CalibrationConfig:
        """Typed ``calibration.*`` section (:class:`CalibrationConfig`)."""
        c = self.calibration_section
        rho, g = self.water_density_kg_m3, self.gravity_m_s2
        float_b = None
        if c.float_mass_kg is not None and c.float_volume_m3 is not None:
            float_b = (rho * c.float_volume_m3 - c.float_mass_kg) * g
        return CalibrationConfig(
            ballast_weight_in_water_n=(c.ballast_mass_kg - c.ballast_volume_m3 * rho) * g,
            line_pull_force_n=float(c.line_pull_force_n),
            inclining_weight_in_water_n=(c.inclining_mass_kg - c.inclining_volume_m3 * rho) * g,
            inclining_arm_m=float(c.inclining_arm_m),
            float_net_buoyancy_n=float_b,
            net_buoyancy_std_n=float(or_default(c.net_buoyancy_std_n, 0.05)))

    def hydrodynamics(self, dof: str) -> DofHydrodynamics:
        """Typed hydrodynamic coefficients of one DOF (see :class:`DofHydrodynamics`)."""
        if dof not in DOFS:
            raise KeyError(f"unknown DOF {dof!r}; one of {', '.join(DOFS)}")
        hs = self.hydrodynamics_section
        if dof == "heave":
            v = hs.heave
            return DofHydrodynamics(dof, v.added_mass_kg, v.linear_damping_positive_kg_s,
                                    v.linear_damping_negative_kg_s, v.quadratic_damping_positive_kg_m,
                                    v.quadratic_damping_negative_kg_m)
        if dof in ROTATIONAL_DOFS:
            r = {"roll": hs.roll, "pitch": hs.pitch, "yaw": hs.yaw}[dof]
            return DofHydrodynamics(dof, r.added_mass_kg_m2, r.linear_damping_kg_m2_s, r.linear_damping_kg_m2_s,
                                    r.quadratic_damping_kg_m2, r.quadratic_damping_kg_m2)
        t = {"surge": hs.surge, "sway": hs.sway}[dof]
        return DofHydrodynamics(dof, t.added_mass_kg, t.linear_damping_kg_s, t.linear_damping_kg_s,
                                t.quadratic_damping_kg_m, t.quadratic_damping_kg_m)

    @functools.cached_property
    def thrusters(self) -> ThrustersConfig:
        """Typed thruster set (positions/directions FRD relative to the CG); built once per configuration (the
        configuration is immutable; the control and identification loops read it at every tick). Needs
        ``thrusters.names``; other keys a node did not declare raise KeyError naming them when read."""
        f = self.flat

        def get(key: str, convert: Any = None) -> Any:
            if key not in f:
                return None if _is_optional(key) else ABSENT
            return f[key] if convert is None else convert(f[key])

        def unit(v: Any) -> np.ndarray:
            return np.asarray(v, dtype=float) / np.linalg.norm(v)

        def array(v: Any) -> np.ndarray:
            return np.asarray(v, dtype=float)

        ts = tuple(
            ThrusterConfig.build(dict(
                name=n,
                position_frd_m=get(f"thrusters.{n}.position_frd_m", array),
                direction_frd=get(f"thrusters.{n}.direction_frd", unit),
                esc_channel=get(f"thrusters.{n}.esc_channel"),
                reversed=get(f"thrusters.{n}.reversed"),
                trim_us=get(f"thrusters.{n}.trim_us"),
                allocation_weight=get(f"thrusters.{n}.allocation_weight"),
            ), prefix=f"thrusters.{n}")
            for n in f["thrusters.names"]
        )
        built: ThrustersConfig = ThrustersConfig.build(dict(
            thrusters=ts,
            pulse_width_min_us=get("thrusters.pulse_width_min_us"),
            pulse_width_neutral_us=get("thrusters.pulse_width_neutral_us"),
            pulse_width_max_us=get("thrusters.pulse_width_max_us"),
            deadband_us=get("thrusters.deadband_us"),
            curve_negative=get("thrusters.curve_negative", tuple),
            curve_positive=get("thrusters.curve_positive", tuple),
            time_constant_s=get("thrusters.time_constant_s"),
            allocation_mode=get("thrusters.allocation_mode"),
            priority_dofs=get("thrusters.priority_dofs", tuple),
            max_wrench_excess_ratio=get("thrusters.max_wrench_excess_ratio"),
            wrench_timeout_s=get("thrusters.wrench_timeout_s"),
            wrench_future_margin_s=get("thrusters.wrench_future_margin_s"),
            thrust_uncertainty_rel=get("thrusters.thrust_uncertainty_rel", _float_tuple),
            thrust_fit_uncertainty_rel=get("thrusters.thrust_fit_uncertainty_rel", _float_tuple),
        ))
        return built

    def summary(self) -> str:
        """A short multi-line human summary of the vehicle (used by ``hindrax config check``)."""
        t = self.thrusters
        lines = [
            f"vehicle {self.vehicle.name}: mass {self.mass_kg:g} kg, volume {self.displaced_volume_m3:g} m^3,"
            f" net buoyancy {(self.buoyancy_n - self.weight_n):.3f} N (rho {self.water_density_kg_m3:g} kg/m^3)",
            f"thrusters: {len(t.thrusters)} ({', '.join(t.names)}), pulse width "
            f"{t.pulse_width_min_us:g}-{t.pulse_width_max_us:g} us, neutral {t.pulse_width_neutral_us:g} us",
            "added mass (surge sway heave kg; roll pitch yaw kg m^2): "
            + " ".join(f"{v:g}" for v in np.diag(self.added_mass_matrix)),
            f"pool {self.pool.length_m:g} x {self.pool.width_m:g} x {self.pool.depth_m:g} m",
            f"sha256 {self.sha256[:12]}" if self.sha256 else "",
        ]
        return "\n".join(x for x in lines if x)

    def to_ros_parameters(self) -> dict[str, Any]:
        """Flat dotted ROS parameter names -> values (lists as lists), for ``--params-file`` or declare."""
        return {k: (list(v) if isinstance(v, (list, tuple, np.ndarray)) else v) for k, v in self.flat.items()}

    def with_overrides(self, overrides: Mapping[str, Any]) -> "VehicleConfig":
        """A new validated configuration with some dotted keys replaced (raises ConfigError)."""
        flat = dict(self.flat)
        flat.update(overrides)
        return VehicleConfig(validate_flat(flat, source=self.source), self.source, self.sha256)


def _float_tuple(value: Any) -> tuple[float, ...]:
    return tuple(float(v) for v in value)


def ros_parameters_from_yaml(doc: Any, source: str = "") -> dict[str, Any]:
    """Extract the ``ros__parameters`` mapping of a params-file document (first node key) as a nested dict.

    Accepts ``{"/**": {"ros__parameters": {...}}}`` or any single node name. Raises ConfigError otherwise.
    """
    if not isinstance(doc, Mapping) or not doc:
        raise ConfigError([ConfigIssue("<file>", type(doc).__name__,
                                       "a mapping {'/**': {'ros__parameters': {...}}}")], source)
    if len(doc) != 1:
        raise ConfigError([ConfigIssue("<file>", list(doc), "exactly one node key, e.g. '/**'")], source)
    (node_key, body), = doc.items()
    if not isinstance(body, Mapping) or "ros__parameters" not in body or set(body) != {"ros__parameters"}:
        raise ConfigError([ConfigIssue(str(node_key), list(body) if isinstance(body, Mapping) else body,
                                       "a mapping with the single key 'ros__parameters'")], source)
    params = body["ros__parameters"]
    if not isinstance(params, Mapping):
        raise ConfigError([ConfigIssue(f"{node_key}.ros__parameters", params, "a mapping")], source)
    return dict(params)


def load_config(path: str | Path, overrides: Mapping[str, Any] | None = None) -> VehicleConfig:
    """Load and validate a vehicle configuration file (ros-args params-file layout).

    path: YAML file. overrides: dotted keys replacing file values before validation.
    Returns a :class:`VehicleConfig`. Raises :class:`ConfigError` (with every issue) on an unreadable
    file, bad YAML, unknown/missing keys, wrong types or out-of-range values.
    """
    path = Path(path)
    src = str(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise ConfigError([ConfigIssue("<file>", src, f"a readable file ({exc.strerror})")], src) from exc
    except UnicodeDecodeError as exc:  # a binary file
        raise ConfigError([ConfigIssue("<file>", src, f"a UTF-8 text file (byte {exc.start}: {exc.reason})")],
                          src) from exc
    try:
        doc = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise ConfigError([ConfigIssue("<file>", src, f"valid YAML ({str(exc).splitlines()[0]})")], src) from exc
    except RecursionError as exc:  # nesting deeper than the parser's recursion limit
        raise ConfigError([ConfigIssue("<file>", src, "YAML nested less deeply (the parser ran out of recursion)")],
                          src) from exc
    flat = flatten(ros_parameters_from_yaml(doc, src))
    if overrides:
        flat.update(overrides)
    valid = validate_flat(flat, source=src)
    return VehicleConfig(valid, src, hashlib.sha256(text.encode()).hexdigest())


def config_from_parameters(params: Mapping[str, Any], source: str = "ros parameters") -> VehicleConfig:
    """Validate the vehicle keys among a node's parameters (dotted names -> values).

    Parameters outside the configuration sections (``use_sim_time``, node-specific ones) are ignored;
    inside the sections, unknown keys are errors. Raises :class:`ConfigError`.
    """
    flat = {k: v for k, v in params.items() if k.split(".")[0] in SECTIONS}
    digest = hashlib.sha256(repr(sorted(flat.items())).encode()).hexdigest()
    return VehicleConfig(validate_flat(flat, source=source), source, digest)


def default_config_path() -> Path:
    """Path of the vehicle file used when none is given (``--config``, ``config_file``, ``--params-file``).

    Order: in an installed workspace (this module imported from a colcon install space, e.g.
    ``ros_ws/install`` or ``/ws/install``), ``share/hindrax_drivers/config/hindrax.yaml`` of that install;
    otherwise (repository checkout, editable dev venv) the repository's ``ros_ws/config/hindrax.yaml``, found
    by walking up from this file, then the installed share directory. The canonical file is the
    repository's ``ros_ws/config/hindrax.yaml``; the package installs it through the symlink
    ``src/hindrax_drivers/config -> ../../ros_ws/config``. The environment variable ``HINDRAX_CONFIG``, when set,
    names the file instead (the Docker image sets it to the mounted vehicle file). Raises FileNotFoundError
    naming the places searched.
    """
    env = os.environ.get("HINDRAX_CONFIG")
    if env:
        if Path(env).is_file():
            return Path(env)
        raise FileNotFoundError(f"HINDRAX_CONFIG={env}: no such file")
    here = Path(__file__).resolve()
    source_tree = [p / "ros_ws" / "config" / "hindrax.yaml" for p in here.parents]
    installed: list[Path] = []
    in_install_space = False
    try:  # colcon install (the vehicle) or the ament index of the dev venv
        installed.append(Path(get_package_share_directory("hindrax_drivers")) / "config" / "hindrax.yaml")
        in_install_space = Path(get_package_prefix("hindrax_drivers")).resolve() in here.parents
    except Exception:  # noqa: BLE001 - no ament index entry (plain checkout) is fine
        pass
    candidates = installed + source_tree if in_install_space else source_tree + installed
    for c in candidates:
        if c.is_file():
            return c
    raise FileNotFoundError("hindrax.yaml not found; searched: " + ", ".join(str(c) for c in candidates[:4]))
