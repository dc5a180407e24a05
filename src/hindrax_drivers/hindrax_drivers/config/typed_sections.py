"""Typed configuration sections: one frozen dataclass per section of the vehicle file (GENERATED).

Do not edit: written by ``scripts/gen_config_sections.py`` from ``hindrax_drivers.config.SCHEMA``; the tests
check that this file is current. Field names are the keys' last segments, nested dataclasses follow the nesting
of the keys, optional keys are ``X | None`` (None when absent) and lists are tuples. Build them through
:class:`hindrax_drivers.config.VehicleConfig` (``cfg.esc.output_latency_s``), never by hand. A required key that
a node did not declare among its parameters is absent from its configuration: reading it raises KeyError naming
the key.
"""
from dataclasses import dataclass, fields
from typing import Any, ClassVar

ABSENT: Any = type("Absent", (), {"__repr__": lambda self: "<absent>"})()
"""Marks a required key this configuration does not hold (a node's selection of keys) in :meth:`Section.build`."""


class Section:
    """Base of the generated sections: ``PREFIX`` is the dotted path; reading an absent key raises KeyError.

    An absent required key is simply not set on the instance, so reading a present field is a plain attribute
    read (no per-access check on the control loops' paths) and only a missing one reaches :meth:`__getattr__`.
    """

    PREFIX: ClassVar[str] = ""

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


@dataclass(frozen=True, eq=False, repr=False)
class VehicleSection(Section):
    """``vehicle.*`` (docs: hindrax_drivers.config.SCHEMA)."""

    PREFIX: ClassVar[str] = "vehicle"

    name: str
    """the vehicle's name: its namespace on the topside graph (docs/architecture.md §8.2), unique among the vehicles
    on one topside domain"""
    mass_kg: float
    """total mass in air, kg ([Hindrax-Drag] §2.1)"""
    displaced_volume_m3: float
    """displaced volume, m^3 ([Hindrax-Drag] §2.1)"""
    length_m: float
    """overall length (x), m ([Hindrax-Drag] §2.1)"""
    width_m: float
    """overall width (y), m ([Hindrax-Drag] §2.1)"""
    height_m: float
    """overall height (z), m ([Hindrax-Drag] §2.1)"""
    net_buoyancy_n: float
    """stated net buoyancy (buoyancy - weight), N; checked against (rho V - m) g"""
    inertia_kg_m2: tuple[float, ...]
    """principal moments of inertia [Ixx, Iyy, Izz] about the CG, kg m^2"""
    products_of_inertia_kg_m2: tuple[float, ...]
    """products of inertia [Ixy, Ixz, Iyz], kg m^2"""
    centre_of_gravity_frd_m: tuple[float, ...]
    """CG relative to the body origin, FRD, m"""
    centre_of_buoyancy_frd_m: tuple[float, ...]
    """CB relative to the body origin, FRD, m"""


@dataclass(frozen=True, eq=False, repr=False)
class EnvironmentSection(Section):
    """``environment.*`` (docs: hindrax_drivers.config.SCHEMA)."""

    PREFIX: ClassVar[str] = "environment"

    water_density_kg_m3: float
    """water density, kg/m^3 (the Hindrax papers use 1000)"""
    gravity_m_s2: float
    """gravitational acceleration, m/s^2"""
    kinematic_viscosity_m2_s: float
    """kinematic viscosity of water, m^2/s ([Hindrax-AM] §4)"""
    surface_pressure_pa: float
    """atmospheric pressure at the surface, Pa"""


@dataclass(frozen=True, eq=False, repr=False)
class HydrodynamicsSurgeSection(Section):
    """``hydrodynamics.surge.*`` (docs: hindrax_drivers.config.SCHEMA)."""

    PREFIX: ClassVar[str] = "hydrodynamics.surge"

    added_mass_kg: float
    """surge added mass, kg"""
    linear_damping_kg_s: float
    """surge linear damping, kg/s"""
    quadratic_damping_kg_m: float
    """surge quadratic damping, kg/m"""


@dataclass(frozen=True, eq=False, repr=False)
class HydrodynamicsSwaySection(Section):
    """``hydrodynamics.sway.*`` (docs: hindrax_drivers.config.SCHEMA)."""

    PREFIX: ClassVar[str] = "hydrodynamics.sway"

    added_mass_kg: float
    """sway added mass, kg"""
    linear_damping_kg_s: float
    """sway linear damping, kg/s"""
    quadratic_damping_kg_m: float
    """sway quadratic damping, kg/m"""


@dataclass(frozen=True, eq=False, repr=False)
class HydrodynamicsHeaveSection(Section):
    """``hydrodynamics.heave.*`` (docs: hindrax_drivers.config.SCHEMA)."""

    PREFIX: ClassVar[str] = "hydrodynamics.heave"

    added_mass_kg: float
    """heave added mass, kg"""
    linear_damping_positive_kg_s: float
    """heave linear damping for positive w (positive = down), kg/s"""
    quadratic_damping_positive_kg_m: float
    """heave quadratic damping for positive w (positive = down), kg/m"""
    linear_damping_negative_kg_s: float
    """heave linear damping for negative w (positive = down), kg/s"""
    quadratic_damping_negative_kg_m: float
    """heave quadratic damping for negative w (positive = down), kg/m"""


@dataclass(frozen=True, eq=False, repr=False)
class HydrodynamicsRollSection(Section):
    """``hydrodynamics.roll.*`` (docs: hindrax_drivers.config.SCHEMA)."""

    PREFIX: ClassVar[str] = "hydrodynamics.roll"

    added_mass_kg_m2: float
    """roll added moment of inertia, kg m^2"""
    linear_damping_kg_m2_s: float
    """roll linear damping, N m/(rad/s) = kg m^2/s"""
    quadratic_damping_kg_m2: float
    """roll quadratic damping, N m/(rad/s)^2 = kg m^2"""


@dataclass(frozen=True, eq=False, repr=False)
class HydrodynamicsPitchSection(Section):
    """``hydrodynamics.pitch.*`` (docs: hindrax_drivers.config.SCHEMA)."""

    PREFIX: ClassVar[str] = "hydrodynamics.pitch"

    added_mass_kg_m2: float
    """pitch added moment of inertia, kg m^2"""
    linear_damping_kg_m2_s: float
    """pitch linear damping, N m/(rad/s) = kg m^2/s"""
    quadratic_damping_kg_m2: float
    """pitch quadratic damping, N m/(rad/s)^2 = kg m^2"""


@dataclass(frozen=True, eq=False, repr=False)
class HydrodynamicsYawSection(Section):
    """``hydrodynamics.yaw.*`` (docs: hindrax_drivers.config.SCHEMA)."""

    PREFIX: ClassVar[str] = "hydrodynamics.yaw"

    added_mass_kg_m2: float
    """yaw added moment of inertia, kg m^2"""
    linear_damping_kg_m2_s: float
    """yaw linear damping, N m/(rad/s) = kg m^2/s"""
    quadratic_damping_kg_m2: float
    """yaw quadratic damping, N m/(rad/s)^2 = kg m^2"""


@dataclass(frozen=True, eq=False, repr=False)
class HydrodynamicsSection(Section):
    """``hydrodynamics.*`` (docs: hindrax_drivers.config.SCHEMA)."""

    PREFIX: ClassVar[str] = "hydrodynamics"

    added_mass_coupling: tuple[float, ...]
    """off-diagonal added-mass terms added to diag(added_mass), row-major 6x6 (kg, kg m, kg m^2); diagonal entries
    must be 0"""
    surge: HydrodynamicsSurgeSection
    sway: HydrodynamicsSwaySection
    heave: HydrodynamicsHeaveSection
    roll: HydrodynamicsRollSection
    pitch: HydrodynamicsPitchSection
    yaw: HydrodynamicsYawSection


@dataclass(frozen=True, eq=False, repr=False)
class EscOutputEnableGpioSection(Section):
    """``esc.output_enable_gpio.*`` (docs: hindrax_drivers.config.SCHEMA)."""

    PREFIX: ClassVar[str] = "esc.output_enable_gpio"

    chip: str | None
    """gpiochip of the PCA9685 /OE line, e.g. /dev/gpiochip0 (absent or null: /OE not wired, the guard writes the
    chip's all-off and sleep registers instead)"""
    line: int | None
    """line offset of the PCA9685 /OE on esc.output_enable_gpio.chip (BCM GPIO number on a Pi 4)"""


@dataclass(frozen=True, eq=False, repr=False)
class EscOutputEnableFeedGpioSection(Section):
    """``esc.output_enable_feed_gpio.*`` (docs: hindrax_drivers.config.SCHEMA)."""

    PREFIX: ClassVar[str] = "esc.output_enable_feed_gpio"

    chip: str | None
    """gpiochip of the hardware watchdog's feed line (docs/watchdog.md: a retriggerable monostable that holds /OE
    high unless it sees rising edges); absent or null: no hardware watchdog"""
    line: int | None
    """line offset of the watchdog feed on esc.output_enable_feed_gpio.chip (BCM GPIO number on a Pi 4)"""


@dataclass(frozen=True, eq=False, repr=False)
class EscSection(Section):
    """``esc.*`` (docs: hindrax_drivers.config.SCHEMA)."""

    PREFIX: ClassVar[str] = "esc"

    i2c_bus: int
    """Linux I2C bus number (/dev/i2c-N)"""
    i2c_address: int
    """PCA9685 7-bit address"""
    pwm_frequency_hz: float
    """PWM frequency, Hz (Basic ESC max 400 Hz)"""
    oscillator_hz: float
    """calibrated PCA9685 internal oscillator frequency, Hz (25 MHz nominal, NXP PCA9685 data sheet §7.3.5; parts
    measure 23-27 MHz, docs/devices.md §5.1)"""
    arming_time_s: float
    """time at neutral before arming is accepted, s (docs/devices.md §5.2: BR holds 7 s)"""
    watchdog_timeout_s: float
    """no command for this long -> all neutral, s"""
    output_rate_hz: float
    """rate the outputs are refreshed and the watchdog checked, Hz"""
    slew_rate_us_per_s: float
    """max pulse-width change rate, us/s (0 = off)"""
    output_latency_s: float
    """delay from the ESC node's stamp of a written width (thrusters/pulse_width) to the thrust starting to change,
    s: the identification's force timing"""
    oscillator_calibrated: bool
    """esc.oscillator_hz was measured on this board (`hindrax esc calibrate`); arming is refused while false"""
    readback_interval_s: float
    """MODE1, PRE_SCALE and the channel registers are read back this often; a mismatch (chip reset) re-initialises
    the chip and disarms, s"""
    bus_call_timeout_s: float
    """a PCA9685 bus call (write or read-back) not returned after this long makes the output state unknown: ESC
    heartbeat ERROR, the guard asserts /OE (a block write takes 0.9 ms at 400 kHz; must be below
    esc.guard_heartbeat_timeout_s), s"""
    heartbeat_timeout_s: float
    """the ESC refuses to arm, and disarms, when supervisor/heartbeat or guard/heartbeat is older than this (steady
    clock; docs/architecture.md §8), s"""
    guard_heartbeat_timeout_s: float
    """the output guard asserts /OE (or silences the chip over I2C) when esc/heartbeat or supervisor/heartbeat is
    older than this (steady clock; docs/architecture.md §8), s"""
    output_enable_gpio: EscOutputEnableGpioSection
    output_enable_feed_gpio: EscOutputEnableFeedGpioSection
    output_enable_feed_rate_hz: float | None
    """rising edges per second the output guard puts on the watchdog feed while the ESC heartbeat is fresh and
    nothing is tripped, Hz"""
    output_enable_feed_timeout_s: float | None
    """the hardware watchdog's timeout: its monostable's pulse width t_W = R_EXT * C_EXT (docs/watchdog.md); the
    outputs stop this long after the last rising edge, s"""


@dataclass(frozen=True, eq=False, repr=False)
class LightsSection(Section):
    """``lights.*`` (docs: hindrax_drivers.config.SCHEMA)."""

    PREFIX: ClassVar[str] = "lights"

    esc_channel: int
    """PCA9685 channel of the lights (15 carries the reference pulse for `hindrax esc calibrate`)"""
    pulse_width_off_us: float
    """pulse width for lights off, us"""
    pulse_width_full_us: float
    """pulse width for full brightness, us"""


@dataclass(frozen=True, eq=False, repr=False)
class SensorsDvl75Section(Section):
    """``sensors.dvl75.*`` (docs: hindrax_drivers.config.SCHEMA)."""

    PREFIX: ClassVar[str] = "sensors.dvl75"

    port: str
    """serial device path or pyserial URL of the DVL-75"""
    baud_rate: int
    """baud rate (docs/devices.md §1.1)"""
    position_frd_m: tuple[float, ...]
    """DVL position relative to the CG, FRD, m"""
    sensor_orientation_rpy_rad: tuple[float, ...]
    """SET-SENSOR-ORIENTATION roll, pitch, heading of the sensor in the vehicle, rad (docs/devices.md §1.4)"""
    speed_of_sound_m_s: float
    """speed of sound sent to the DVL, m/s (docs/devices.md §1.4)"""
    velocity_std_m_s: float
    """1-sigma velocity error used for the covariance, m/s"""
    max_speed_m_s: float
    """plausibility gate: a faster $DVPDL velocity is published invalid, m/s (DVL-75 envelope <= 8 kn = 4.1 m/s,
    docs/devices.md §1.1)"""
    max_angular_rate_rad_s: float
    """plausibility gate: a $DVPDL whose attitude change over dtu gives a faster angular rate is published invalid
    (it feeds the lever-arm correction), rad/s"""
    min_interval_s: float
    """plausibility gate: a shorter $DVPDL dtu is published invalid, s (ping rate 5-20 Hz, docs/devices.md §1.1)"""
    max_interval_s: float
    """plausibility gate: a longer $DVPDL dtu is published invalid, s"""
    noise_std_m_s: float | None
    """declared DVL velocity white noise 1-sigma per axis, m/s"""
    scale_error_fraction: float | None
    """declared DVL 1-sigma multiplicative velocity error per report"""
    attitude_noise_std_rad: float | None
    """declared DVL attitude white noise 1-sigma, rad"""


@dataclass(frozen=True, eq=False, repr=False)
class SensorsPing1dSection(Section):
    """``sensors.ping1d.*`` (docs: hindrax_drivers.config.SCHEMA)."""

    PREFIX: ClassVar[str] = "sensors.ping1d"

    port: str
    """serial device path or pyserial URL of the Ping altimeter"""
    baud_rate: int
    """baud rate (docs/devices.md §2.1)"""
    position_frd_m: tuple[float, ...]
    """sonar position relative to the CG, FRD, m"""
    speed_of_sound_m_s: float
    """speed of sound, m/s (fresh water about 1481)"""
    ping_interval_s: float
    """interval between pings, s"""
    mode_auto: bool
    """let the sonar choose range and gain"""
    field_of_view_rad: float
    """beam width for sensor_msgs/Range, rad"""
    min_range_m: float
    """minimum range for sensor_msgs/Range, m"""
    max_range_m: float
    """maximum range for sensor_msgs/Range, m"""


@dataclass(frozen=True, eq=False, repr=False)
class SensorsMs5837Section(Section):
    """``sensors.ms5837.*`` (docs: hindrax_drivers.config.SCHEMA)."""

    PREFIX: ClassVar[str] = "sensors.ms5837"

    i2c_bus: int
    """Linux I2C bus number"""
    i2c_address: int
    """MS5837 7-bit address (fixed 0x76)"""
    variant: str
    """sensor variant (auto = C1 heuristic, docs/devices.md §3.9)"""
    oversampling: int
    """oversampling ratio (docs/devices.md §3.1)"""
    rate_hz: float
    """pressure publication rate, Hz"""
    position_frd_m: tuple[float, ...]
    """pressure port position relative to the CG, FRD, m"""
    min_pressure_pa: float
    """plausibility gate: a lower compensated pressure is not published, Pa"""
    max_pressure_pa: float
    """plausibility gate: a higher compensated pressure is not published, Pa (30BA full scale 30 bar)"""
    min_depth_m: float
    """plausibility gate: a shallower depth (negative = above the surface, e.g. on deck) is not published, m"""
    max_depth_m: float
    """plausibility gate: a deeper depth is not published, m"""
    max_depth_rate_m_s: float
    """plausibility gate: a depth changing faster than this since the last published one is held back until the next
    sample confirms it, m/s"""
    zero_depth_margin_pa: float
    """pressure/zero_depth is refused when the mean pressure is further than this from the atmospheric reference
    environment.surface_pressure_pa (the vehicle is not at the surface), Pa"""
    prom_reject_blank_words: bool
    """PROM sanity gate: reject a PROM whose coefficient C1..C6 reads 0x0000 or 0xFFFF (blank or unread PROM; an
    all-zero PROM passes CRC-4, docs/devices.md §3.2-3.3)"""
    noise_std_pa: float | None
    """declared pressure white noise 1-sigma, Pa"""


@dataclass(frozen=True, eq=False, repr=False)
class SensorsIcm20948Section(Section):
    """``sensors.icm20948.*`` (docs: hindrax_drivers.config.SCHEMA)."""

    PREFIX: ClassVar[str] = "sensors.icm20948"

    i2c_bus: int
    """Linux I2C bus number"""
    i2c_address: int
    """ICM-20948 7-bit address (AD0 low 0x68, high 0x69)"""
    accel_full_scale_g: int
    """accelerometer full scale, g"""
    gyro_full_scale_dps: int
    """gyroscope full scale, deg/s"""
    dlpf_config: int
    """ACCEL/GYRO_DLPFCFG register code (docs/devices.md §4.4)"""
    sample_rate_hz: float
    """output data rate and publication rate, Hz"""
    magnetometer_mode: str
    """how the AK09916 is reached (docs/devices.md §4.6)"""
    estimate_gyro_bias: bool
    """estimate gyro bias at start-up while the vehicle is still"""
    gyro_bias_duration_s: float
    """duration of the start-up gyro-bias estimate, s"""
    mounting_rpy_rad: tuple[float, ...]
    """rotation of the sensor frame in base_link (FLU), rad"""
    position_frd_m: tuple[float, ...]
    """IMU chip position relative to the CG, FRD, m (the imu_link origin)"""
    frozen_check_samples: int
    """data-ready gate: after this many bit-identical samples in a row the chip's PWR_MGMT_1/USER_CTRL are read back
    (reset check)"""
    require_data_ready: bool
    """data-ready gate: read INT_STATUS_1.RAW_DATA_0_RDY (bank 0, 0x1A) before each poll and publish no sample
    without it"""
    not_ready_error_polls: int
    """data-ready gate: this many consecutive polls without RAW_DATA_0_RDY raise the ERROR data_ready"""
    mag_retry_interval_s: float
    """lost AK09916: period of the magnetometer re-initialisation attempts until it answers again, s"""
    mag_stale_timeout_s: float
    """data-ready gate: no new magnetometer sample (ST1.DRDY, SLV0 answered) for this long -> ERROR and re-
    initialisation, s"""
    accel_noise_std_m_s2: float | None
    """declared accelerometer white noise 1-sigma, m/s^2"""
    gyro_noise_std_rad_s: float | None
    """declared gyro white noise 1-sigma, rad/s"""


@dataclass(frozen=True, eq=False, repr=False)
class SensorsSection(Section):
    """``sensors.*`` (docs: hindrax_drivers.config.SCHEMA)."""

    PREFIX: ClassVar[str] = "sensors"

    dvl75: SensorsDvl75Section
    ping1d: SensorsPing1dSection
    ms5837: SensorsMs5837Section
    icm20948: SensorsIcm20948Section


@dataclass(frozen=True, eq=False, repr=False)
class PoolSection(Section):
    """``pool.*`` (docs: hindrax_drivers.config.SCHEMA)."""

    PREFIX: ClassVar[str] = "pool"

    length_m: float
    """pool length (north, x), m"""
    width_m: float
    """pool width (east, y), m"""
    depth_m: float
    """water depth, m"""
    margin_m: float
    """keep-out margin from walls and floor for manoeuvres, m"""
    start_position_ned_m: tuple[float, ...]
    """vehicle start position (north, east, down) from the pool corner, m"""
    start_heading_rad: float
    """vehicle start heading, rad (NED yaw)"""


@dataclass(frozen=True, eq=False, repr=False)
class LimitsSection(Section):
    """``limits.*`` (docs: hindrax_drivers.config.SCHEMA)."""

    PREFIX: ClassVar[str] = "limits"

    max_depth_m: float
    """abort below this depth, m"""
    min_altitude_m: float
    """abort closer than this to the floor, m"""
    max_roll_rad: float
    """abort beyond this roll, rad"""
    max_pitch_rad: float
    """abort beyond this pitch, rad"""


@dataclass(frozen=True, eq=False, repr=False)
class IdentificationSection(Section):
    """``identification.*`` (docs: hindrax_drivers.config.SCHEMA)."""

    PREFIX: ClassVar[str] = "identification"

    levels_per_dof: int
    """thrust levels in each DOF's ladder"""
    level_fraction_min: float
    """smallest level as a fraction of the DOF's authority"""
    level_fraction_max: float
    """largest level as a fraction of the DOF's authority"""
    forgetting_factor: float
    """RLS forgetting factor lambda"""
    estimate_rate_hz: float
    """RLS update rate, Hz"""
    command_rate_hz: float | None
    """manoeuvre wrench command rate, Hz: the control law steps at estimate_rate_hz and its wrench is sent and held
    at this rate (a whole fraction of estimate_rate_hz; default estimate_rate_hz)"""
    publish_rate_hz: float
    """HydroEstimate publication rate, Hz"""
    altitude_setpoint_m: float
    """altitude held during manoeuvres, m ([Hindrax-Drag] §4: 0.8-1.0 m)"""
    roll_test_angle_rad: float
    """roll test turns back at this angle, rad ([Hindrax-Drag] §4.2: 30 deg)"""
    pitch_test_angle_rad: float
    """pitch test turns back at this angle, rad ([Hindrax-Drag] §4.2: 40 deg)"""
    max_level_duration_s: float
    """longest time one level is held, s"""
    converged_relative_std: float
    """converged when every std/|value| is below this"""
    prior_std_rel: float | None
    """1-sigma of the empirical priors in the batch fit, as a fraction of the prior value (0 = no prior;
    docs/identification.md §6.3)"""
    rls_directional_forgetting: bool | None
    """online RLS: forget only along the regressor (Bittanti et al. 1990), default true (docs/identification.md
    §1.D)"""
    rls_min_excitation: float | None
    """online RLS: hold the estimate while the normalised excitation is below this once reached (0 = no gate),
    default 0.001"""
    rls_change_threshold: float | None
    """online RLS: reset the covariance when the mean normalised a-priori error over rls_change_window_s exceeds
    this (0 = no detector), default 6"""
    rls_change_window_s: float | None
    """online RLS: window of the change detector, s, default 10"""
    rls_prior_std_rel: float | None
    """online RLS: 1-sigma of its starting values (empirical priors) as a fraction of the prior value (0 = diffuse
    start at zero), default 1"""
    excitation: str | None
    """force input per DOF: the constant-thrust ladder, or one broadband run shaped to stay in the pool box
    (hindrax_ident identification/online/excitation.py)"""
    excitation_duration_s: float | None
    """length of the broadband run per DOF (excitation not ladder), s"""


@dataclass(frozen=True, eq=False, repr=False)
class SimulationSensorsDvl75Section(Section):
    """``simulation.sensors.dvl75.*`` (docs: hindrax_drivers.config.SCHEMA)."""

    PREFIX: ClassVar[str] = "simulation.sensors.dvl75"

    noise_std_m_s: float | None
    """dvl75 white-noise 1-sigma, m_s"""
    bias_m_s: float | None
    """dvl75 constant bias, m_s"""
    rate_hz: float | None
    """dvl75 output rate, Hz"""
    dropout_probability: float | None
    """dvl75 probability a sample is lost"""
    scale_error_fraction: float | None
    """1-sigma multiplicative velocity error per report ([Hindrax-Drag] Table 1: mean error about 5 %)"""
    min_altitude_m: float | None
    """DVL loses lock below this altitude, m"""
    max_altitude_m: float | None
    """DVL loses lock above this altitude, m"""
    wall_lock_loss_distance_m: float | None
    """DVL loses lock closer than this to a wall, m (0 = never)"""


@dataclass(frozen=True, eq=False, repr=False)
class SimulationSensorsPing1dSection(Section):
    """``simulation.sensors.ping1d.*`` (docs: hindrax_drivers.config.SCHEMA)."""

    PREFIX: ClassVar[str] = "simulation.sensors.ping1d"

    noise_std_m: float | None
    """ping1d white-noise 1-sigma, m"""
    bias_m: float | None
    """ping1d constant bias, m"""
    rate_hz: float | None
    """ping1d output rate, Hz"""
    dropout_probability: float | None
    """ping1d probability a sample is lost"""


@dataclass(frozen=True, eq=False, repr=False)
class SimulationSensorsMs5837Section(Section):
    """``simulation.sensors.ms5837.*`` (docs: hindrax_drivers.config.SCHEMA)."""

    PREFIX: ClassVar[str] = "simulation.sensors.ms5837"

    noise_std_pa: float | None
    """ms5837 white-noise 1-sigma, pa"""
    bias_pa: float | None
    """ms5837 constant bias, pa"""
    rate_hz: float | None
    """ms5837 output rate, Hz"""
    dropout_probability: float | None
    """ms5837 probability a sample is lost"""


@dataclass(frozen=True, eq=False, repr=False)
class SimulationSensorsIcm20948AccelSection(Section):
    """``simulation.sensors.icm20948_accel.*`` (docs: hindrax_drivers.config.SCHEMA)."""

    PREFIX: ClassVar[str] = "simulation.sensors.icm20948_accel"

    noise_std_m_s2: float | None
    """icm20948_accel white-noise 1-sigma, m_s2"""
    bias_m_s2: float | None
    """icm20948_accel constant bias, m_s2"""
    rate_hz: float | None
    """icm20948_accel output rate, Hz"""
    dropout_probability: float | None
    """icm20948_accel probability a sample is lost"""


@dataclass(frozen=True, eq=False, repr=False)
class SimulationSensorsIcm20948GyroSection(Section):
    """``simulation.sensors.icm20948_gyro.*`` (docs: hindrax_drivers.config.SCHEMA)."""

    PREFIX: ClassVar[str] = "simulation.sensors.icm20948_gyro"

    noise_std_rad_s: float | None
    """icm20948_gyro white-noise 1-sigma, rad_s"""
    bias_rad_s: float | None
    """icm20948_gyro constant bias, rad_s"""
    rate_hz: float | None
    """icm20948_gyro output rate, Hz"""
    dropout_probability: float | None
    """icm20948_gyro probability a sample is lost"""


@dataclass(frozen=True, eq=False, repr=False)
class SimulationSensorsIcm20948MagSection(Section):
    """``simulation.sensors.icm20948_mag.*`` (docs: hindrax_drivers.config.SCHEMA)."""

    PREFIX: ClassVar[str] = "simulation.sensors.icm20948_mag"

    noise_std_t: float | None
    """icm20948_mag white-noise 1-sigma, t"""
    bias_t: float | None
    """icm20948_mag constant bias, t"""
    rate_hz: float | None
    """icm20948_mag output rate, Hz"""
    dropout_probability: float | None
    """icm20948_mag probability a sample is lost"""
    earth_field_ned_t: tuple[float, ...] | None
    """earth magnetic field [north, east, down] seen by the simulated magnetometer, T"""


@dataclass(frozen=True, eq=False, repr=False)
class SimulationSensorsDvl75AttitudeSection(Section):
    """``simulation.sensors.dvl75_attitude.*`` (docs: hindrax_drivers.config.SCHEMA)."""

    PREFIX: ClassVar[str] = "simulation.sensors.dvl75_attitude"

    noise_std_rad: float | None
    """dvl75_attitude white-noise 1-sigma, rad"""
    bias_rad: float | None
    """dvl75_attitude constant bias, rad"""
    rate_hz: float | None
    """dvl75_attitude output rate, Hz"""
    dropout_probability: float | None
    """dvl75_attitude probability a sample is lost"""


@dataclass(frozen=True, eq=False, repr=False)
class SimulationSensorsSection(Section):
    """``simulation.sensors.*`` (docs: hindrax_drivers.config.SCHEMA)."""

    PREFIX: ClassVar[str] = "simulation.sensors"

    dvl75: SimulationSensorsDvl75Section
    ping1d: SimulationSensorsPing1dSection
    ms5837: SimulationSensorsMs5837Section
    icm20948_accel: SimulationSensorsIcm20948AccelSection
    icm20948_gyro: SimulationSensorsIcm20948GyroSection
    icm20948_mag: SimulationSensorsIcm20948MagSection
    dvl75_attitude: SimulationSensorsDvl75AttitudeSection


@dataclass(frozen=True, eq=False, repr=False)
class SimulationSection(Section):
    """``simulation.*`` (docs: hindrax_drivers.config.SCHEMA)."""

    PREFIX: ClassVar[str] = "simulation"

    step_s: float
    """fixed integration step, s"""
    real_time_factor: float
    """simulated seconds per wall second (0 = as fast as possible)"""
    seed: int
    """random seed of the sensor noise"""
    clock_rate_hz: float
    """rate /clock is published, in simulated time, Hz"""
    sensors: SimulationSensorsSection


@dataclass(frozen=True, eq=False, repr=False)
class RecordingSection(Section):
    """``recording.*`` (docs: hindrax_drivers.config.SCHEMA)."""

    PREFIX: ClassVar[str] = "recording"

    output_root: str
    """directory new bags are created in"""
    compression: str
    """chunk compression"""
    chunk_size_bytes: int
    """MCAP chunk size, bytes"""
    split_size_bytes: int
    """start a new file beyond this size, bytes (0 = never)"""
    split_duration_s: float
    """start a new file after this duration, s (0 = never)"""
    flush_interval_s: float
    """close and fsync the open chunk once its oldest message is this old, s (bounds the data lost on power loss; 0
    = only when the chunk is full)"""
    min_free_disk_mb: float
    """stop recording cleanly (bag finished) when the free space of the bag's filesystem falls below this, MB (1e6
    bytes; 0 = no check)"""
    topics: tuple[str, ...] | None
    """topics recorded by default (empty list not allowed by ROS: omit the key to record all topics)"""


@dataclass(frozen=True, eq=False, repr=False)
class SupervisorMinRateSection(Section):
    """``supervisor.min_rate.*`` (docs: hindrax_drivers.config.SCHEMA)."""

    PREFIX: ClassVar[str] = "supervisor.min_rate"

    dvl_hz: float
    """minimum dvl/data rate while armed, Hz (0 = not watched)"""
    altimeter_hz: float
    """minimum ping/altitude rate while armed, Hz (0 = not watched)"""
    pressure_hz: float
    """minimum pressure/depth rate while armed, Hz (0 = not watched)"""
    imu_hz: float
    """minimum imu/data_raw rate while armed, Hz (0 = not watched)"""


@dataclass(frozen=True, eq=False, repr=False)
class SupervisorRateCheckDisabledSection(Section):
    """``supervisor.rate_check_disabled.*`` (docs: hindrax_drivers.config.SCHEMA)."""

    PREFIX: ClassVar[str] = "supervisor.rate_check_disabled"

    dvl: str | None
    """why supervisor.min_rate.dvl_hz is 0 (required with 0, refused otherwise)"""
    altimeter: str | None
    """why supervisor.min_rate.altimeter_hz is 0 (required with 0)"""
    pressure: str | None
    """why supervisor.min_rate.pressure_hz is 0 (required with 0)"""
    imu: str | None
    """why supervisor.min_rate.imu_hz is 0 (required with 0)"""


@dataclass(frozen=True, eq=False, repr=False)
class SupervisorSection(Section):
    """``supervisor.*`` (docs: hindrax_drivers.config.SCHEMA)."""

    PREFIX: ClassVar[str] = "supervisor"

    check_rate_hz: float
    """rate of the supervisor's rate and run-time checks, Hz"""
    rate_window_s: float
    """window the sensor rates are measured over (at most supervisor.reaction_time_s), s"""
    max_sample_age_s: float
    """a sensor sample whose header stamp is further than this from the supervisor's time on arrival (older, or
    ahead) is not alive: not counted, not used, s"""
    max_identical_s: float
    """a sensor stream bit-identical (header stamp aside) for longer than this is frozen: its samples are not alive
    (sensor noise changes every reading within a few samples), s"""
    reaction_time_s: float
    """longest time a failed sensor (silent, stale or frozen) may go unnoticed while armed; bounds
    supervisor.rate_window_s, max_invalid_dvl_s, max_sample_age_s and max_identical_s, s"""
    min_rate: SupervisorMinRateSection
    max_invalid_dvl_s: float
    """armed with no valid DVL velocity for this long -> trip (the cage's dead reckoning is frozen meanwhile), s"""
    rate_check_disabled: SupervisorRateCheckDisabledSection
    max_depth_m: float
    """disarm below this depth (pressure port), m"""
    min_altitude_m: float
    """disarm closer than this to the floor (altimeter), m"""
    max_roll_rad: float
    """disarm beyond this roll (DVL attitude), rad"""
    max_pitch_rad: float
    """disarm beyond this pitch (DVL attitude), rad"""
    cage_margin_m: float
    """disarm when the DVL dead-reckoned position comes closer than this to a pool wall (pool.* box), m"""
    max_run_time_s: float
    """disarm after this long armed, s"""


@dataclass(frozen=True, eq=False, repr=False)
class CalibrationSection(Section):
    """``calibration.*`` (docs: hindrax_drivers.config.SCHEMA)."""

    PREFIX: ClassVar[str] = "calibration"

    ballast_mass_kg: float
    """mass of the ballast hung on the vehicle in the ballast step, kg"""
    ballast_volume_m3: float
    """displaced volume of that ballast, m^3 (weight in water (m - rho V) g must be > 0)"""
    line_pull_force_n: float
    """horizontal force of the line over the pool-edge pulley in the line_pull step (e.g. a hanging mass times g),
    N"""
    inclining_mass_kg: float
    """test mass of the inclining step, kg"""
    inclining_volume_m3: float
    """displaced volume of that test mass, m^3 (it must sink)"""
    inclining_arm_m: float
    """horizontal arm of the test mass from the centre line (roll: to starboard, pitch: forward), m"""
    float_mass_kg: float | None
    """mass of the sealed float tied to the vehicle in the float step (optional), kg"""
    float_volume_m3: float | None
    """displaced volume of that float, m^3 (net buoyancy (rho V - m) g must be > 0)"""
    net_buoyancy_std_n: float | None
    """1-sigma of the vehicle's net buoyancy (rho V - m) g as weighed, N (the hover holds of the thrust calibration
    measure the forward thrust against it; optional)"""


@dataclass(frozen=True, eq=False, repr=False)
class ControlSection(Section):
    """``control.*`` (docs: hindrax_drivers.config.SCHEMA)."""

    PREFIX: ClassVar[str] = "control"

    rate_hz: float | None
    """rate of the controller node's wrench, Hz (default 50)"""
    depth_bandwidth_rad_s: float | None
    """target bandwidth of the depth and altitude hold, rad/s (default 2)"""
    heading_bandwidth_rad_s: float | None
    """target bandwidth of the heading hold, rad/s (default 2)"""
    attitude_bandwidth_rad_s: float | None
    """target bandwidth of the roll and pitch holds, rad/s (default 2)"""
    velocity_bandwidth_rad_s: float | None
    """target bandwidth of the surge and sway velocity holds, rad/s (default 3)"""
    damping_ratio: float | None
    """damping ratio of the reference models and the PID, default 1"""
    hold_fraction: float | None
    """share of each axis' authority the holds may use, default 0.6"""
    max_depth_rate_m_s: float | None
    """largest depth rate the reference model asks for, m/s (default 0.3)"""
    max_yaw_rate_rad_s: float | None
    """largest yaw rate the reference model asks for, rad/s (default 0.6)"""
    sensor_timeout_s: float | None
    """the controller stops when depth or attitude is older than this, s (default 0.5)"""
