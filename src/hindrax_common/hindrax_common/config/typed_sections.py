"""Typed configuration sections: frozen dataclasses of the vehicle file (GENERATED).

Do not edit: written by ``scripts/gen_config_sections.py`` from ``hindrax_common.config.SCHEMA``; the tests check that
this file is current. Field names are the keys' last segments, nested dataclasses follow the nesting of the keys
(sibling sections with the same keys share one class, ``HydrodynamicsSurgeSwaySection``: a section's dotted path is
given when it is built), optional keys are ``X | None`` (None when absent) and lists are tuples. Build them through
:class:`hindrax_common.config.VehicleConfig` (``cfg.esc.output_latency_s``), never by hand. A required key that a node
did not declare among its parameters is absent from its configuration: reading it raises KeyError naming the key. Each
field's unit and meaning: its key's ``Spec.doc`` in SCHEMA."""
from dataclasses import dataclass, fields
from typing import Any, ClassVar, dataclass_transform

ABSENT: Any = type("Absent", (), {"__repr__": lambda self: "<absent>"})()
"""Marks a required key this configuration does not hold (a node's selection of keys) in :meth:`Section.build`."""


@dataclass_transform(frozen_default=True, eq_default=False)
class Section:
    """Base of the generated sections, each a frozen dataclass compared by identity: ``PREFIX`` is the dotted path (the
    ``prefix`` class keyword of a subclass, ``class X(Section, prefix="esc")``); reading an absent key raises KeyError.

    An absent required key is simply not set on the instance, so reading a present field is a plain attribute
    read (no per-access check on the control loops' paths) and only a missing one reaches :meth:`__getattr__`."""

    PREFIX: ClassVar[str] = ""

    def __init_subclass__(cls, prefix: str | None = None, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if prefix is not None:
            cls.PREFIX = prefix
        dataclass(frozen=True, eq=False, repr=False)(cls)

    @classmethod
    def build(cls, values: dict[str, Any], prefix: str | None = None) -> Any:
        """An instance holding ``values`` (field name -> value; ABSENT values left unset); ``prefix`` overrides
        ``PREFIX`` in the KeyError messages (e.g. ``thrusters.t3``). Bypasses ``__init__``: the values are
        validated already."""
        obj = object.__new__(cls)
        for name, value in values.items():
            if value is not ABSENT:
                object.__setattr__(obj, name, value)
        if prefix is not None:
            object.__setattr__(obj, "PREFIX", prefix)
        return obj

    def __getattr__(self, name: str) -> Any:
        """Called only for an attribute the instance lacks: KeyError naming the dotted key of an absent field."""
        if name in {f.name for f in fields(self)}:  # type: ignore[arg-type]  # every subclass is a dataclass
            raise KeyError(f"{self.PREFIX}.{name}")
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    def __repr__(self) -> str:
        """``ClassName(field=value, ...)`` with absent keys shown as <absent>."""
        names = [f.name for f in fields(self)]  # type: ignore[arg-type]  # every subclass is a dataclass
        items = ", ".join(f"{k}={self.__dict__.get(k, ABSENT)!r}" for k in names)
        return f"{type(self).__name__}({items})"


class VehicleSection(Section, prefix="vehicle"):
    name: str
    mass_kg: float
    displaced_volume_m3: float
    length_m: float
    width_m: float
    height_m: float
    net_buoyancy_n: float
    inertia_kg_m2: tuple[float, ...]
    products_of_inertia_kg_m2: tuple[float, ...]
    centre_of_gravity_frd_m: tuple[float, ...]
    centre_of_buoyancy_frd_m: tuple[float, ...]


class EnvironmentSection(Section, prefix="environment"):
    water_density_kg_m3: float
    gravity_m_s2: float
    kinematic_viscosity_m2_s: float
    surface_pressure_pa: float


class HydrodynamicsSurgeSwaySection(Section, prefix="hydrodynamics.surge"):
    added_mass_kg: float
    linear_damping_kg_s: float
    quadratic_damping_kg_m: float


class HydrodynamicsHeaveSection(Section, prefix="hydrodynamics.heave"):
    added_mass_kg: float
    linear_damping_positive_kg_s: float
    quadratic_damping_positive_kg_m: float
    linear_damping_negative_kg_s: float
    quadratic_damping_negative_kg_m: float


class HydrodynamicsRollPitchYawSection(Section, prefix="hydrodynamics.roll"):
    added_mass_kg_m2: float
    linear_damping_kg_m2_s: float
    quadratic_damping_kg_m2: float


class HydrodynamicsSection(Section, prefix="hydrodynamics"):
    added_mass_coupling: tuple[float, ...]
    surge: HydrodynamicsSurgeSwaySection
    sway: HydrodynamicsSurgeSwaySection
    heave: HydrodynamicsHeaveSection
    roll: HydrodynamicsRollPitchYawSection
    pitch: HydrodynamicsRollPitchYawSection
    yaw: HydrodynamicsRollPitchYawSection


class EscOutputEnableGpioOutputEnableFeedGpioSection(Section, prefix="esc.output_enable_gpio"):
    chip: str | None
    line: int | None


class EscSection(Section, prefix="esc"):
    i2c_bus: int
    i2c_address: int
    pwm_frequency_hz: float
    oscillator_hz: float
    arming_time_s: float
    watchdog_timeout_s: float
    output_rate_hz: float
    slew_rate_us_per_s: float
    output_latency_s: float
    oscillator_calibrated: bool
    oscillator_measured_on: str | None
    readback_interval_s: float
    bus_call_timeout_s: float
    heartbeat_timeout_s: float
    guard_heartbeat_timeout_s: float
    output_enable_gpio: EscOutputEnableGpioOutputEnableFeedGpioSection
    output_enable_feed_gpio: EscOutputEnableGpioOutputEnableFeedGpioSection
    output_enable_feed_rate_hz: float | None
    output_enable_feed_timeout_s: float | None


class LightsSection(Section, prefix="lights"):
    esc_channel: int
    pulse_width_off_us: float
    pulse_width_full_us: float


class SensorsDvl75Section(Section, prefix="sensors.dvl75"):
    port: str
    baud_rate: int
    position_frd_m: tuple[float, ...]
    sensor_orientation_rpy_rad: tuple[float, ...]
    speed_of_sound_m_s: float
    velocity_std_m_s: float
    max_speed_m_s: float
    max_angular_rate_rad_s: float
    min_interval_s: float
    max_interval_s: float
    noise_std_m_s: float | None
    scale_error_fraction: float | None
    attitude_noise_std_rad: float | None


class SensorsPing1dSection(Section, prefix="sensors.ping1d"):
    port: str
    baud_rate: int
    position_frd_m: tuple[float, ...]
    speed_of_sound_m_s: float
    ping_interval_s: float
    mode_auto: bool
    field_of_view_rad: float
    min_range_m: float
    max_range_m: float


class SensorsMs5837Section(Section, prefix="sensors.ms5837"):
    i2c_bus: int
    i2c_address: int
    variant: str
    oversampling: int
    rate_hz: float
    position_frd_m: tuple[float, ...]
    min_pressure_pa: float
    max_pressure_pa: float
    min_depth_m: float
    max_depth_m: float
    max_depth_rate_m_s: float
    zero_depth_margin_pa: float
    prom_reject_blank_words: bool
    noise_std_pa: float | None


class SensorsIcm20948Section(Section, prefix="sensors.icm20948"):
    i2c_bus: int
    i2c_address: int
    accel_full_scale_g: int
    gyro_full_scale_dps: int
    dlpf_config: int
    sample_rate_hz: float
    magnetometer_mode: str
    estimate_gyro_bias: bool
    gyro_bias_duration_s: float
    mounting_rpy_rad: tuple[float, ...]
    position_frd_m: tuple[float, ...]
    frozen_check_samples: int
    require_data_ready: bool
    not_ready_error_polls: int
    mag_retry_interval_s: float
    mag_stale_timeout_s: float
    accel_noise_std_m_s2: float | None
    gyro_noise_std_rad_s: float | None


class SensorsSection(Section, prefix="sensors"):
    dvl75: SensorsDvl75Section
    ping1d: SensorsPing1dSection
    ms5837: SensorsMs5837Section
    icm20948: SensorsIcm20948Section


class PoolSection(Section, prefix="pool"):
    length_m: float
    width_m: float
    depth_m: float
    margin_m: float
    start_position_ned_m: tuple[float, ...]
    start_heading_rad: float


class LimitsSection(Section, prefix="limits"):
    max_depth_m: float
    min_altitude_m: float
    max_roll_rad: float
    max_pitch_rad: float


class IdentificationSection(Section, prefix="identification"):
    levels_per_dof: int
    level_fraction_min: float
    level_fraction_max: float
    forgetting_factor: float
    estimate_rate_hz: float
    command_rate_hz: float | None
    publish_rate_hz: float
    altitude_setpoint_m: float
    roll_test_angle_rad: float
    pitch_test_angle_rad: float
    max_level_duration_s: float
    heave_repeats: int | None
    converged_relative_std: float
    prior_std_rel: float | None
    rls_directional_forgetting: bool | None
    rls_min_excitation: float | None
    rls_change_threshold: float | None
    rls_change_window_s: float | None
    rls_prior_std_rel: float | None
    excitation: str | None
    excitation_duration_s: float | None


class SimulationSensorsDvl75Section(Section, prefix="simulation.sensors.dvl75"):
    noise_std_m_s: float | None
    bias_m_s: float | None
    rate_hz: float | None
    dropout_probability: float | None
    scale_error_fraction: float | None
    min_altitude_m: float | None
    max_altitude_m: float | None
    wall_lock_loss_distance_m: float | None


class SimulationSensorsPing1dSection(Section, prefix="simulation.sensors.ping1d"):
    noise_std_m: float | None
    bias_m: float | None
    rate_hz: float | None
    dropout_probability: float | None


class SimulationSensorsMs5837Section(Section, prefix="simulation.sensors.ms5837"):
    noise_std_pa: float | None
    bias_pa: float | None
    rate_hz: float | None
    dropout_probability: float | None


class SimulationSensorsIcm20948AccelSection(Section, prefix="simulation.sensors.icm20948_accel"):
    noise_std_m_s2: float | None
    bias_m_s2: float | None
    rate_hz: float | None
    dropout_probability: float | None


class SimulationSensorsIcm20948GyroSection(Section, prefix="simulation.sensors.icm20948_gyro"):
    noise_std_rad_s: float | None
    bias_rad_s: float | None
    rate_hz: float | None
    dropout_probability: float | None


class SimulationSensorsIcm20948MagSection(Section, prefix="simulation.sensors.icm20948_mag"):
    noise_std_t: float | None
    bias_t: float | None
    rate_hz: float | None
    dropout_probability: float | None
    earth_field_ned_t: tuple[float, ...] | None


class SimulationSensorsDvl75AttitudeSection(Section, prefix="simulation.sensors.dvl75_attitude"):
    noise_std_rad: float | None
    bias_rad: float | None
    rate_hz: float | None
    dropout_probability: float | None


class SimulationSensorsSection(Section, prefix="simulation.sensors"):
    dvl75: SimulationSensorsDvl75Section
    ping1d: SimulationSensorsPing1dSection
    ms5837: SimulationSensorsMs5837Section
    icm20948_accel: SimulationSensorsIcm20948AccelSection
    icm20948_gyro: SimulationSensorsIcm20948GyroSection
    icm20948_mag: SimulationSensorsIcm20948MagSection
    dvl75_attitude: SimulationSensorsDvl75AttitudeSection


class SimulationSection(Section, prefix="simulation"):
    step_s: float
    real_time_factor: float
    seed: int
    clock_rate_hz: float
    sensors: SimulationSensorsSection


class RecordingSection(Section, prefix="recording"):
    output_root: str
    compression: str
    chunk_size_bytes: int
    split_size_bytes: int
    split_duration_s: float
    flush_interval_s: float
    min_free_disk_mb: float
    topics: tuple[str, ...] | None


class SupervisorMinRateSection(Section, prefix="supervisor.min_rate"):
    dvl_hz: float
    altimeter_hz: float
    pressure_hz: float
    imu_hz: float


class SupervisorRateCheckDisabledSection(Section, prefix="supervisor.rate_check_disabled"):
    dvl: str | None
    altimeter: str | None
    pressure: str | None
    imu: str | None


class SupervisorSection(Section, prefix="supervisor"):
    check_rate_hz: float
    rate_window_s: float
    max_sample_age_s: float
    max_identical_s: float
    reaction_time_s: float
    min_rate: SupervisorMinRateSection
    max_invalid_dvl_s: float
    rate_check_disabled: SupervisorRateCheckDisabledSection
    max_depth_m: float
    min_altitude_m: float
    max_roll_rad: float
    max_pitch_rad: float
    cage_margin_m: float
    max_run_time_s: float


class CalibrationSection(Section, prefix="calibration"):
    ballast_mass_kg: float
    ballast_volume_m3: float
    line_pull_force_n: float
    inclining_mass_kg: float
    inclining_volume_m3: float
    inclining_arm_m: float
    float_mass_kg: float | None
    float_volume_m3: float | None
    net_buoyancy_std_n: float | None
    hold_settle_s: float | None
    hold_window_s: float | None


class ControlSection(Section, prefix="control"):
    rate_hz: float | None
    depth_bandwidth_rad_s: float | None
    heading_bandwidth_rad_s: float | None
    attitude_bandwidth_rad_s: float | None
    velocity_bandwidth_rad_s: float | None
    damping_ratio: float | None
    hold_fraction: float | None
    max_depth_rate_m_s: float | None
    max_yaw_rate_rad_s: float | None
    sensor_timeout_s: float | None
