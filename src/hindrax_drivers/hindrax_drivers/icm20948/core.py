"""ICM-20948 driver core: pure, no rclpy, no clock, no sleep (docs/devices.md §4), run by the node (:mod:`.node`) from
its timers through injected I2C ports, tested step by step against the register-exact emulator.

- Settings (:class:`ImuSettings`): register fields, noise variances, AK09916 mode and publishing
  rates from ``sensors.icm20948.*`` (§4.4, §4.6). :class:`BankedRegisters`: REG_BANK_SEL with the
  bank cached (§4.1), unknown after a failed transfer or a DEVICE_RESET.
- :class:`StartupSequence` (§4.3): steps each giving the datasheet's wait. A wrong WHO_AM_I or an I2C failure ends the
  attempt (the node retries); a silent magnetometer is reported through ``on_magnetometer``, never a start-up failure;
  ``magnetometer_only=True`` brings a lost AK09916 back without resetting the chip.
- :class:`GyroBias`: the mean over the first ``gyro_bias_duration_s``, subtracted only when every
  axis's gyro and accelerometer std shows a still vehicle, else a WARN says why.
- :func:`read_poll`: one burst per poll. With ``require_data_ready`` a poll without
  INT_STATUS_1.RAW_DATA_0_RDY publishes nothing (:class:`DataReadyGate`: counted ``not_ready``,
  ``not_ready_error_polls`` in a row raise the ERROR ``data_ready``).
- Chip reset (power glitch: data registers 0 and frozen, PWR_MGMT_1 0x41, USER_CTRL 0): an all-zero
  block or ``frozen_check_samples`` identical blocks (:class:`FrozenBlockWatch`) make the node read
  the state back (:func:`read_chip_reset`); a reset is counted ``chip_resets``, an ERROR, its
  samples unpublished, the start-up run again. An all-zero block is never published.
- Magnetometer: an ``i2c_master`` block read under SLV0_NACK is old (:class:`MagNackFilter`, counted ``mag_nack``).
  :class:`MagnetometerWatch`: none for ``mag_stale_timeout_s`` raises the ERROR ``magnetometer`` and re-initialises the
  magnetometer alone, one step per poll, retried every ``mag_retry_interval_s`` (``mag_retries``)."""
from __future__ import annotations

import collections
import math
from dataclasses import dataclass
from typing import Any, Callable, Protocol

import numpy as np

from hindrax_common.transport.i2c import I2CError, RegisterWrite
from . import protocol as p
from .mounting import mounting_rotation

__all__ = ["ACCEL_NOISE_BANDWIDTH_HZ", "ACCEL_NOISE_DENSITY_G_PER_SQRT_HZ", "BankedRegisters", "DataReadyGate",
           "FrozenBlockWatch", "ImuSettings", "PollResult", "read_poll", "MagNackFilter", "MagnetometerWatch",
           "chip_reset_problems", "diagnostic_values", "GYRO_NOISE_BANDWIDTH_HZ",
           "GYRO_NOISE_DENSITY_DPS_PER_SQRT_HZ", "GyroBias", "GyroBiasResult", "MAG_ATTEMPTS",
           "STILL_STD_FACTOR", "StartupSequence", "StepResult", "imu_config_from_settings", "imu_noise_variances",
           "mag_mode_for_rate", "CHIP_STATE_LENGTH", "PollFailures", "read_asleep", "read_chip_reset"]

#: Attempts to reach the AK09916 through the I2C master (SparkFun retries too, docs/devices.md §4.3 step 7).
MAG_ATTEMPTS = 3
#: Accelerometer noise spectral density, g/sqrt(Hz): DS-000189 rev 1.3 Table 2 (p. 12), 230 ug/sqrt(Hz).
ACCEL_NOISE_DENSITY_G_PER_SQRT_HZ = 230e-6
#: Gyroscope rate noise spectral density, deg/s/sqrt(Hz): DS-000189 rev 1.3 Table 1 (p. 11), 0.015.
#: Not in docs/devices.md and that page was not re-read for this project: UNVERIFIED here.
GYRO_NOISE_DENSITY_DPS_PER_SQRT_HZ = 0.015
#: DLPF noise bandwidths in Hz per DLPFCFG 0..7 (FCHOICE = 1), docs/devices.md §4.4 table (from [I2]).
GYRO_NOISE_BANDWIDTH_HZ = (229.8, 187.6, 154.3, 73.3, 35.9, 17.8, 8.9, 376.5)
ACCEL_NOISE_BANDWIDTH_HZ = (265.0, 265.0, 136.0, 68.8, 34.4, 17.0, 8.3, 499.0)
#: The vehicle is "still" when every axis's std is below this many times the expected noise std.
STILL_STD_FACTOR = 5.0
#: rate of ``imu/temperature``, Hz (diagnostics and bag: the die temperature drifts over minutes)
TEMPERATURE_PUBLISH_HZ = 1.0
#: highest rate of ``imu/mag``, Hz (heading on the topside; AK09916 continuous mode 2 is 20 Hz, docs/devices.md §4.5)
MAG_PUBLISH_HZ = 20.0


class I2CPort(Protocol):
    """What the core needs of one device on the bus (:class:`~hindrax_common.transport.i2c.I2CDevice`)."""

    address: int

    def write_byte_data(self, register: int, value: int) -> None: ...  # noqa: D102

    def read_block(self, register: int, length: int) -> bytes: ...  # noqa: D102


# ---------------------------------------------------------------------------------------- settings
@dataclass(frozen=True)
class ImuSettings:
    """What the node derives from ``sensors.icm20948.*`` once (:meth:`from_section`): the register fields
    (``config``), the achieved output rate ``odr_hz`` (Hz), the AK09916 mode, the mounting ``rotation`` (3x3,
    sensor -> base_link FLU), per-axis noise variances and the rotated covariances (3x3; accel m^2/s^4, gyro
    rad^2/s^2), the temperature variance (degC^2), the decimations of ``imu/temperature`` and ``imu/mag`` (every
    k-th sample) and the start-up ``warnings`` (an unreachable rate, a gyro that ignores its divider)."""

    config: p.ImuConfig
    odr_hz: float
    mag_mode: int
    rotation: np.ndarray
    accel_var: float
    gyro_var: float
    accel_cov: np.ndarray
    gyro_cov: np.ndarray
    temperature_var: float
    temperature_every: int
    mag_every: int
    warnings: tuple[str, ...]

    def describe(self) -> str:
        """Rate and ranges in one line (the start-up's log)."""
        c = self.config
        return (f"{self.odr_hz:.2f} Hz (FS {p.ACCEL_RANGE_G[c.accel_fs_sel]:g} g, {p.GYRO_RANGE_DPS[c.gyro_fs_sel]:g} "
                f"dps, DLPFCFG {c.gyro_dlpfcfg})")

    @classmethod
    def from_section(cls, s: Any) -> "ImuSettings":
        """s: the validated ``sensors.icm20948`` section."""
        rate = float(s.sample_rate_hz)
        config = imu_config_from_settings(s.accel_full_scale_g, s.gyro_full_scale_dps, s.dlpf_config, rate)
        odr, rot = config.accel_odr_hz, mounting_rotation(s.mounting_rpy_rad)
        mag_mode = mag_mode_for_rate(odr)
        a_var, g_var = imu_noise_variances(config)
        warnings = []
        if abs(odr - rate) > 0.05 * rate:
            warnings.append(f"sensors.icm20948.sample_rate_hz = {rate:g} Hz is not reachable: the chip runs at "
                            f"1125 / (1 + div) Hz, here {odr:.2f} Hz")
        if not 0 < int(s.dlpf_config) < 7:
            warnings.append(f"dlpf_config {int(s.dlpf_config)}: the gyro ignores its sample-rate divider "
                            f"(docs/devices.md §4.4) and runs at 1125 Hz; polled at {odr:.2f} Hz")
        temperature_every = max(1, round(odr / TEMPERATURE_PUBLISH_HZ))
        mag_every = max(1, round(min(p.AK_CONTINUOUS_MODE_RATE_HZ[mag_mode], odr) / MAG_PUBLISH_HZ))
        return cls(config, odr, mag_mode, rot, a_var, g_var, (rot * a_var) @ rot.T, (rot * g_var) @ rot.T,
                   (1.0 / p.TEMP_SENSITIVITY_LSB_PER_C) ** 2, temperature_every, mag_every, tuple(warnings))


def imu_config_from_settings(accel_full_scale_g: float, gyro_full_scale_dps: float, dlpf_config: int,
                             sample_rate_hz: float) -> p.ImuConfig:
    """Register fields from the ``sensors.icm20948.*`` settings (docs/devices.md §4.4).

    Full scale: the FS_SEL whose range equals the setting (2/4/8/16 g, 250/500/1000/2000 dps). DLPF: the
    same DLPFCFG for accel and gyro (FCHOICE = 1). Divider for both: ``round(1125 / rate) - 1`` in 0..255.

    Raises ``Icm20948Error``: a full scale that is not a device range, DLPFCFG outside 0..7, or a non-positive rate."""
    try:
        accel_fs = p.ACCEL_RANGE_G.index(float(accel_full_scale_g))
        gyro_fs = p.GYRO_RANGE_DPS.index(float(gyro_full_scale_dps))
    except ValueError:
        raise p.Icm20948Error(f"full scale {accel_full_scale_g} g / {gyro_full_scale_dps} dps is not a device "
                              f"range ({p.ACCEL_RANGE_G} g, {p.GYRO_RANGE_DPS} dps)") from None
    if not (math.isfinite(sample_rate_hz) and sample_rate_hz > 0.0):
        raise p.Icm20948Error(f"sample_rate_hz must be > 0, got {sample_rate_hz}")
    div = min(255, max(0, round(p.BASE_ODR_HZ / sample_rate_hz) - 1))
    return p.ImuConfig(accel_fs_sel=accel_fs, gyro_fs_sel=gyro_fs, accel_dlpfcfg=int(dlpf_config),
                       gyro_dlpfcfg=int(dlpf_config), accel_smplrt_div=div, gyro_smplrt_div=div)


def imu_noise_variances(config: p.ImuConfig) -> tuple[float, float]:
    """Per-axis white-noise variances (accel m^2/s^4, gyro rad^2/s^2) for ``config``.

    variance = density^2 * noise_bandwidth(DLPFCFG) + LSB^2 / 12, with the datasheet densities
    (:data:`ACCEL_NOISE_DENSITY_G_PER_SQRT_HZ`, :data:`GYRO_NOISE_DENSITY_DPS_PER_SQRT_HZ`), the noise bandwidths of
    docs/devices.md §4.4 and the LSB of the full scale. With the DLPF bypassed the widest bandwidth (DLPFCFG 7) is used.
    """
    a_cfg = 7 if config.accel_dlpfcfg is None else config.accel_dlpfcfg
    g_cfg = 7 if config.gyro_dlpfcfg is None else config.gyro_dlpfcfg
    a_density = ACCEL_NOISE_DENSITY_G_PER_SQRT_HZ * p.GRAVITY_M_S2
    g_density = math.radians(GYRO_NOISE_DENSITY_DPS_PER_SQRT_HZ)
    a_lsb = p.GRAVITY_M_S2 / config.accel_lsb_per_g
    g_lsb = math.radians(1.0 / config.gyro_lsb_per_dps)
    accel_var = a_density ** 2 * ACCEL_NOISE_BANDWIDTH_HZ[a_cfg] + a_lsb ** 2 / 12.0
    gyro_var = g_density ** 2 * GYRO_NOISE_BANDWIDTH_HZ[g_cfg] + g_lsb ** 2 / 12.0
    return accel_var, gyro_var


def mag_mode_for_rate(rate_hz: float) -> int:
    """AK09916 continuous mode: the slowest of 10/20/50/100 Hz not below ``rate_hz`` (100 Hz at most)."""
    for mode, mode_rate in sorted(p.AK_CONTINUOUS_MODE_RATE_HZ.items(), key=lambda kv: kv[1]):
        if mode_rate >= rate_hz - 1e-9:
            return mode
    return p.AK_MODE_CONTINUOUS_100HZ


# ---------------------------------------------------------------------------------------- register access
class BankedRegisters:
    """Register access to one ICM-20948 through REG_BANK_SEL, the selected bank cached (docs/devices.md §4.1).

    Args:
        device: the chip on the bus (``write_byte_data``, ``read_block``; raises ``I2CError``).

    :attr:`bank` is None while unknown: before the first selection, after a failed selection, after
    :meth:`invalidate` (a failed transfer elsewhere) and after a DEVICE_RESET (reset-to-bank-0 is only assumed)."""

    def __init__(self, device: I2CPort):
        self.device = device
        self.bank: int | None = None

    def invalidate(self) -> None:
        """Forget the selected bank: the next access selects it again."""
        self.bank = None

    def select_bank(self, bank: int) -> None:
        """Write REG_BANK_SEL unless ``bank`` is the one known to be selected."""
        if self.bank != bank:
            self.bank = None  # unknown until the write succeeds
            self.device.write_byte_data(p.REG_BANK_SEL_ADDRESS, p.bank_select_value(bank))
            self.bank = bank

    @staticmethod
    def _bank_of(register: p.Register) -> int:
        if register.bank is None:
            raise ValueError(f"{register.name} is not an ICM-20948 register (no user bank)")
        return register.bank

    def write(self, register: p.Register, value: int) -> None:
        """Write one byte to ``register`` in its bank (ValueError for a register without a bank)."""
        self.select_bank(self._bank_of(register))
        self.device.write_byte_data(register.address, value)
        if register == p.PWR_MGMT_1 and value & p.PWR_MGMT_1_DEVICE_RESET:
            self.bank = None

    def read(self, register: p.Register, length: int = 1) -> bytes:
        """Read ``length`` bytes from ``register`` in its bank (burst, auto-increment)."""
        self.select_bank(self._bank_of(register))
        return self.device.read_block(register.address, length)


# ---------------------------------------------------------------------------------------- start-up
@dataclass(frozen=True)
class StepResult:
    """What the sequence asks of its caller after :meth:`StartupSequence.advance` or :meth:`~StartupSequence.step`.

    Attributes:
        wait_s: wait before the next call, s (the datasheet wait after the last step run; 0 = at once).
        done: every step has run (the magnetometer state is :attr:`StartupSequence.mag_available`).
        failure: the start-up attempt failed (one line: the reason); the caller retries it from the beginning.
        i2c_failure: the failure was a failed I2C transfer (the caller counts it)."""

    wait_s: float = 0.0
    done: bool = False
    failure: str | None = None
    i2c_failure: bool = False


class StartupSequence:
    """The start-up of the ICM-20948 and its AK09916 as steps (docs/devices.md §4.3; see the module docstring).

    Args:
        regs: the chip's registers (:class:`BankedRegisters`).
        mag_device: the AK09916 at 0x0C on the host bus (used in ``bypass`` mode only).
        config: register fields (:func:`imu_config_from_settings`).
        mag_mode_name: ``i2c_master`` or ``bypass`` (``sensors.icm20948.magnetometer_mode``).
        mag_mode: AK09916 continuous mode (:func:`mag_mode_for_rate`).
        on_magnetometer: called ``(available, reason)`` when the magnetometer is found (True, "") or given up (False,
            one line why).
        magnetometer_only: run the magnetometer steps alone (no identity check, no reset)."""

    def __init__(self, regs: BankedRegisters, mag_device: I2CPort, config: p.ImuConfig, mag_mode_name: str,
                 mag_mode: int, on_magnetometer: Callable[[bool, str], Any], *, magnetometer_only: bool = False):
        self.regs = regs
        self.mag_device = mag_device
        self.config = config
        self.mag_mode_name = mag_mode_name
        self.mag_mode = mag_mode
        self.on_magnetometer = on_magnetometer
        self.who_am_i: int | None = None
        self.mag_available = False
        self.mag_failed = False
        self.mag_attempt = 0
        steps: list[Callable[[], float]] = []
        if not magnetometer_only:
            steps.append(self._check_who_am_i)
            steps += [self._write_step(w) for w in p.reset_wake_sequence() + p.configure_sequence(config)]
        steps += self._mag_steps()
        self._steps: collections.deque[Callable[[], float]] = collections.deque(steps)

    @property
    def finished(self) -> bool:
        """No step left."""
        return not self._steps

    def advance(self) -> StepResult:
        """Run steps until one asks for a wait, a step fails, or none is left.

        An I2C failure or a wrong identity ends the attempt (``failure``); a magnetometer that does not answer does
        not (``on_magnetometer(False, reason)``)."""
        while self._steps:
            step = self._steps.popleft()
            try:
                wait_s = step()
            except I2CError as exc:
                self.regs.invalidate()
                self._steps.clear()
                return StepResult(failure=f"start-up I2C failure: {exc}", i2c_failure=True)
            except p.Icm20948Error as exc:
                self._steps.clear()
                return StepResult(failure=str(exc))
            if wait_s > 0.0:
                return StepResult(wait_s=wait_s)
        return StepResult(done=True)

    def step(self) -> StepResult:
        """Run one step (the magnetometer re-initialisation between two polls). A failure gives the magnetometer
        up for this attempt (``on_magnetometer(False, reason)``) and ends the sequence."""
        if not self._steps:
            return StepResult(done=True)
        step = self._steps.popleft()
        try:
            wait_s = step()
        except (I2CError, p.Icm20948Error) as exc:
            self.regs.invalidate()
            self._steps.clear()
            self._mag_unavailable(f"re-initialisation failed: {exc}")
            return StepResult(done=True)
        return StepResult(wait_s=wait_s, done=not self._steps)

    # -- chip
    def _check_who_am_i(self) -> float:
        self.regs.invalidate()
        value = self.regs.read(p.WHO_AM_I)[0]
        self.who_am_i = value
        if value != p.WHO_AM_I_VALUE:
            raise p.Icm20948Error(f"WHO_AM_I = 0x{value:02x}, expected 0x{p.WHO_AM_I_VALUE:02x}: not an ICM-20948 "
                                  f"at 0x{self.regs.device.address:02x}")
        return 0.0

    def _write_step(self, write: p.BankedWrite) -> Callable[[], float]:
        def step() -> float:
            self.regs.write(write.register, write.value)
            return write.delay_after_s
        return step

    # -- magnetometer
    def _mag_steps(self) -> list[Callable[[], float]]:
        if self.mag_mode_name == "bypass":
            return [self._write_step(w) for w in p.mag_bypass_sequence()] + [self._bypass_mag_init]
        steps = [self._write_step(w) for w in p.mag_master_sequence(self.config, self.mag_mode)]
        return steps + [self._slv4_who_am_i_request, self._slv4_who_am_i_check]

    def _mag_unavailable(self, reason: str) -> None:
        self.mag_available = False
        self.on_magnetometer(False, reason)

    def _mag_found(self) -> None:
        self.mag_available = True
        self.on_magnetometer(True, "")

    def _bypass_mag_init(self) -> float:
        """Bypass: check WIA1/WIA2 at 0x0C, then queue soft reset and continuous mode (docs/devices.md §4.5-4.6a)."""
        try:
            wia = self.mag_device.read_block(p.AK_WIA1.address, 2)
        except I2CError as exc:
            self._mag_unavailable(f"no answer at 0x0c: {exc}")
            return 0.0
        if tuple(wia) != (p.AK09916_WIA1_VALUE, p.AK09916_WIA2_VALUE):
            self._mag_unavailable(f"WIA1/WIA2 = {wia.hex()}, expected 4809")
            return 0.0
        steps = [self._mag_write_step(w) for w in p.ak09916_direct_init_writes(self.mag_mode)]
        self._steps.extendleft(reversed(steps + [self._mag_ready]))
        return 0.0

    def _mag_write_step(self, write: RegisterWrite) -> Callable[[], float]:
        """A direct AK09916 write (bypass); a failure marks the magnetometer unavailable, not the IMU."""
        def step() -> float:
            if self.mag_failed:
                return 0.0
            try:
                self.mag_device.write_byte_data(write.register, write.value)
            except I2CError as exc:
                self.mag_failed = True
                self._mag_unavailable(f"write of 0x{write.register:02x} failed: {exc}")
                return 0.0
            return write.delay_after_s
        return step

    def _mag_ready(self) -> float:
        if not self.mag_failed:
            self._mag_found()
        return 0.0

    def _slv4_who_am_i_request(self) -> float:
        """I2C master: one SLV4 read of AK09916 WIA2; the answer comes after a master cycle."""
        self.mag_attempt += 1
        self.regs.write(p.I2C_SLV4_ADDR, p.I2C_SLV_ADDR_RNW | p.AK09916_ADDRESS)
        self.regs.write(p.I2C_SLV4_REG, p.AK_WIA2.address)
        self.regs.write(p.I2C_SLV4_CTRL, p.I2C_SLV_CTRL_EN)
        return max(3.0 / self.config.gyro_odr_hz, p.AK_RESET_WAIT_S)

    def _slv4_who_am_i_check(self) -> float:
        status = self.regs.read(p.I2C_MST_STATUS)[0]
        value = self.regs.read(p.I2C_SLV4_DI)[0]
        ok = bool(status & p.I2C_MST_STATUS_SLV4_DONE) and not status & p.I2C_MST_STATUS_SLV4_NACK \
            and value == p.AK09916_WIA2_VALUE
        if ok:
            self._mag_found()
        elif self.mag_attempt < MAG_ATTEMPTS:
            # I2C_MST_RST, then the whole magnetometer sequence again (SparkFun, docs/devices.md §4.3 step 7)
            retry = [self._write_step(p.BankedWrite(p.USER_CTRL, p.USER_CTRL_I2C_MST_EN | p.USER_CTRL_I2C_MST_RST,
                                                    0.01, "I2C_MST_RST"))]
            retry += [self._write_step(w) for w in p.mag_master_sequence(self.config, self.mag_mode)]
            retry += [self._slv4_who_am_i_request, self._slv4_who_am_i_check]
            self._steps.extendleft(reversed(retry))
        else:
            self._mag_unavailable(f"SLV4 read of WIA2: status 0x{status:02x}, value 0x{value:02x} after "
                                  f"{self.mag_attempt} attempts")
        return 0.0


# ---------------------------------------------------------------------------------------- calibration
@dataclass(frozen=True)
class GyroBiasResult:
    """Outcome of a start-up gyro-bias estimate.

    Attributes:
        bias_rad_s: (3,) mean gyro rate in sensor axes, rad/s (applied only when ``still``).
        gyro_std_rad_s, accel_std_m_s2: (3,) per-axis standard deviations during the window.
        samples: number of samples averaged.
        still: every std below its threshold.
        message: one line for the diagnostics."""

    bias_rad_s: np.ndarray
    gyro_std_rad_s: np.ndarray
    accel_std_m_s2: np.ndarray
    samples: int
    still: bool
    message: str


class GyroBias:
    """The start-up gyro-bias calibration (``sensors.icm20948.estimate_gyro_bias``).

    Args:
        enabled: estimate at all. duration_s: window from the first sample, s (> 0, else
            ValueError). gyro_var, accel_var: per-axis noise variances (rad^2/s^2, m^2/s^4); still:
            every axis's std at most :data:`STILL_STD_FACTOR` times theirs.

    :meth:`start` after each start-up begins the window once (True while it runs); :meth:`add` feeds
    it and returns a :class:`GyroBiasResult` once (at least two samples and ``duration_s``);
    ``bias_rad_s`` (3,) is what the node subtracts: zero until a still window gave one."""

    def __init__(self, enabled: bool, duration_s: float, gyro_var: float, accel_var: float) -> None:
        if not duration_s > 0.0:
            raise ValueError(f"duration_s must be > 0, got {duration_s}")
        self.enabled, self.duration_s = bool(enabled), float(duration_s)
        self.gyro_threshold = STILL_STD_FACTOR * math.sqrt(gyro_var)
        self.accel_threshold = STILL_STD_FACTOR * math.sqrt(accel_var)
        self.bias_rad_s = np.zeros(3)
        self.estimating = False
        self.result: GyroBiasResult | None = None
        self._t0: float | None = None
        self._gyro: list[np.ndarray] = []
        self._accel: list[np.ndarray] = []

    def start(self) -> bool:
        """Begin the window unless disabled or done; True while estimating."""
        if self.enabled and self.result is None:
            self.estimating, self._t0, self._gyro, self._accel = True, None, [], []
        return self.estimating

    def add(self, t_s: float, gyro_rad_s: np.ndarray, accel_m_s2: np.ndarray) -> GyroBiasResult | None:
        """One sample (s, rad/s (3,), m/s^2 (3,)); the result once, at the window's end."""
        if not self.estimating:
            return None
        self._t0 = t_s if self._t0 is None else self._t0
        self._gyro.append(np.asarray(gyro_rad_s, dtype=float))
        self._accel.append(np.asarray(accel_m_s2, dtype=float))
        if t_s - self._t0 < self.duration_s or len(self._gyro) < 2:
            return None
        g, a = np.array(self._gyro), np.array(self._accel)
        g_std, a_std = g.std(axis=0, ddof=1), a.std(axis=0, ddof=1)
        still = bool(np.all(g_std <= self.gyro_threshold) and np.all(a_std <= self.accel_threshold))
        bias = g.mean(axis=0)
        if still:
            message = (f"gyro bias {np.array2string(bias, precision=5)} rad/s from {len(g)} samples "
                       f"(std max {g_std.max():.2e} rad/s)")
            self.bias_rad_s = bias
        else:
            message = (f"vehicle not still during the gyro-bias estimate (gyro std max "
                       f"{g_std.max():.2e} rad/s, limit {self.gyro_threshold:.2e}; accel std max "
                       f"{a_std.max():.2e} m/s^2, limit {self.accel_threshold:.2e}): "
                       "no bias applied; the rates keep the gyro's own offset (the identification's fit removes "
                       "what is left against the attitude and heading); start the vehicle resting to measure it "
                       "(on the virtual pool it drifts at start: expected)")
        self.estimating = False
        self.result = GyroBiasResult(bias, g_std, a_std, len(g), still, message)
        return self.result

    @property
    def status(self) -> str | None:
        """The diagnostics' ``gyro_bias_status``: the result's message, ``estimating``, or None."""
        if self.result is not None:
            return self.result.message
        return "estimating" if self.estimating else None


# ---------------------------------------------------------------------------------------- per-poll decisions
class FrozenBlockWatch:
    """Says when a sensor block calls for a chip-state read-back (docs/devices.md §4.3: a reset chip's data registers
    read 0 and stop updating).

    Args:
        frozen_check_samples: bit-identical blocks in a row that trigger the check (``sensors.icm20948.
            frozen_check_samples``; a live sensor's noise changes the low bits of every new sample, and one repeat
            is a poll that came before the next sample)."""

    def __init__(self, frozen_check_samples: int):
        self.frozen_check_samples = int(frozen_check_samples)
        self.repeats = 0
        self._last: bytes | None = None

    def update(self, block: bytes) -> str | None:
        """Feed one sensor block: ``"zero"`` (all zero), ``"frozen"`` (the ``frozen_check_samples``-th repeat) or
        None (nothing to check)."""
        block = bytes(block)
        self.repeats = self.repeats + 1 if block == self._last else 0
        self._last = block
        if not any(block):
            return "zero"
        return "frozen" if self.repeats == self.frozen_check_samples else None

    def reset(self) -> None:
        """Forget the blocks seen (after a re-initialisation)."""
        self.repeats = 0
        self._last = None


#: Bytes read back by the chip-state check: USER_CTRL (0x03), reserved 0x04, LP_CONFIG 0x05, PWR_MGMT_1 0x06.
CHIP_STATE_LENGTH = 4


def read_chip_reset(regs: BankedRegisters, master_expected: bool) -> list[str]:
    """Read USER_CTRL..PWR_MGMT_1 back (one 4-byte read, bank 0) and say what shows a chip that reset
    (:func:`chip_reset_problems`; empty: none). Raises I2CError."""
    return chip_reset_problems(regs.read(p.USER_CTRL, CHIP_STATE_LENGTH), master_expected)


def read_asleep(regs: BankedRegisters) -> bool:
    """PWR_MGMT_1.SLEEP read back: a frozen chip found asleep was reset by a power glitch. Raises I2CError."""
    return bool(regs.read(p.PWR_MGMT_1)[0] & p.PWR_MGMT_1_SLEEP)


class PollFailures:
    """Failed polls in a row (ROS time, s): :meth:`failed` says ``restart`` once they have lasted ``reinit_after_s``
    (the start-up runs again), else ``warn``; :meth:`ok` after a poll that read its burst."""

    def __init__(self, reinit_after_s: float) -> None:
        self.reinit_after_s = float(reinit_after_s)
        self.since_s: float | None = None

    def ok(self) -> None:
        """A poll read its burst."""
        self.since_s = None

    def failed(self, now_s: float) -> str:
        """One more failed poll at ``now_s``."""
        self.since_s = now_s if self.since_s is None else self.since_s
        return "restart" if now_s - self.since_s >= self.reinit_after_s else "warn"


def chip_reset_problems(state: bytes, master_expected: bool) -> list[str]:
    """What in the read-back USER_CTRL..PWR_MGMT_1 (4 bytes from 0x03, bank 0) shows a chip that reset: asleep
    (PWR_MGMT_1.SLEEP), or the I2C master off while ``master_expected`` (docs/devices.md §4.3). Empty: no reset."""
    user_ctrl, pwr = state[0], state[-1]
    problems = []
    if pwr & p.PWR_MGMT_1_SLEEP:
        problems.append(f"PWR_MGMT_1 = 0x{pwr:02x} (asleep)")
    if master_expected and not user_ctrl & p.USER_CTRL_I2C_MST_EN:
        problems.append(f"USER_CTRL = 0x{user_ctrl:02x} (I2C master off)")
    return problems


@dataclass(frozen=True)
class DataReadyVerdict:
    """publish: the sample may go out; raise_error / clear_error: the ERROR ``data_ready`` starts / ends now;
    polls: consecutive polls without RAW_DATA_0_RDY."""

    publish: bool
    raise_error: bool
    clear_error: bool
    polls: int

    @property
    def text(self) -> str:
        """The ERROR ``data_ready``'s message."""
        return (f"data_ready: INT_STATUS_1.RAW_DATA_0_RDY not set for {self.polls} consecutive polls: no new "
                "accel/gyro sample, nothing published")


class DataReadyGate:
    """INT_STATUS_1.RAW_DATA_0_RDY per poll (DS-000189, bank 0 0x1A bit 0, clears on read): a poll without it holds
    the sample of an earlier poll and is not published; ``error_polls`` in a row raise the ERROR, the next ready
    sample clears it. An unknown flag (its read failed) publishes, as without the gate."""

    def __init__(self, error_polls: int):
        self.error_polls = int(error_polls)
        self.polls = 0

    def update(self, ready: bool | None) -> DataReadyVerdict:
        """Feed the flag of one poll (True, False, or None when unknown)."""
        if ready is False:
            self.polls += 1
            return DataReadyVerdict(False, self.polls == self.error_polls, False, self.polls)
        cleared = self.polls >= self.error_polls
        self.polls = 0
        return DataReadyVerdict(True, False, cleared, 0)


class MagNackFilter:
    """The AK09916 block read through the I2C master, dropped while it is the one EXT_SLV_SENS_DATA held when
    I2C_MST_STATUS.SLV0_NACK was last set (the magnetometer did not answer; a poll between two master cycles
    re-reads the same block, so one NACK covers every poll that sees its data) until the block changes."""

    def __init__(self) -> None:
        self.frozen: bytes | None = None

    def update(self, block: bytes, nack: bool) -> bytes | None:
        """The block to use, or None (stale after a NACK)."""
        block = bytes(block)
        if nack:
            self.frozen = block
        if self.frozen is not None:
            if block == self.frozen:
                return None
            self.frozen = None  # the AK09916 answered again: a new sample
        return block

    def reset(self) -> None:
        """Forget the NACKed block (after a re-initialisation)."""
        self.frozen = None


class MagnetometerWatch:
    """Which AK09916 samples are published and when the magnetometer is re-initialised (module docstring; times in s
    of ROS time). every: publish every k-th valid sample (k = round(AK09916 rate / MAG_PUBLISH_HZ), counted from each
    start-up); stale_timeout_s: no fresh sample this long is a lost magnetometer; retry_interval_s: between
    re-initialisations while it stays lost. A re-initialisation is a magnetometer-only :class:`StartupSequence`
    (``make_reinit()``), run one step per poll by :meth:`after_sample`."""

    def __init__(self, every: int, stale_timeout_s: float, retry_interval_s: float,
                 make_reinit: Callable[[], StartupSequence]) -> None:
        self.every, self.stale_timeout_s = int(every), float(stale_timeout_s)
        self.retry_interval_s = float(retry_interval_s)
        self.make_reinit = make_reinit
        self.reinit: StartupSequence | None = None  # the running re-initialisation
        self.fresh_s: float | None = None  # the last fresh sample (None: not watched)
        self.lost = False
        self.retry_due_s: float | None = None
        self.step_due_s = 0.0
        self.count = 0  # valid samples since the start-up
        self.text = ""  # the ERROR ``magnetometer``'s text when lost

    def started(self, now_s: float, available: bool) -> None:
        """A whole start-up finished, with the magnetometer ``available`` or not."""
        self.count, self.reinit = 0, None
        self.fresh_s = now_s if available else None
        self.lost = self.lost and not available
        self.retry_due_s = now_s + self.retry_interval_s if self.lost else None

    def sample(self, now_s: float, data_ready: bool, overflow: bool) -> bool:
        """One AK09916 block (ST1.DRDY, ST2.HOFL): True when it is published."""
        if not data_ready:
            return False
        self.fresh_s = now_s
        if overflow:
            return False
        self.count += 1
        return (self.count - 1) % self.every == 0

    def begin(self, now_s: float) -> None:
        """A magnetometer-only re-initialisation starts (its first step now)."""
        self.reinit, self.step_due_s = self.make_reinit(), now_s

    def after_sample(self, now_s: float, available: bool) -> str:
        """After each published sample: ``lost`` (no fresh sample for the timeout while ``available``: ``text`` says
        why; the re-initialisation begins), ``retry`` (a re-initialisation of a lost magnetometer begins),
        ``recovered`` (a re-initialisation ended and the AK09916 answers), or ''. Runs one due step."""
        if available and self.fresh_s is not None and now_s - self.fresh_s > self.stale_timeout_s:
            self.text = (f"magnetometer: no new AK09916 sample for {now_s - self.fresh_s:.2f} s (SLV0 NACK or no "
                         "DRDY): imu/mag not published, re-initialising")
            self.lost, self.fresh_s = True, None
            self.begin(now_s)
            return "lost"
        event = ""
        if self.retry_due_s is not None and now_s >= self.retry_due_s:
            self.retry_due_s, event = None, "retry"
            self.begin(now_s)
        if self.reinit is None or now_s < self.step_due_s:
            return event
        if not self.reinit.finished:
            self.step_due_s = now_s + self.reinit.step().wait_s
            return event
        self.reinit = None
        if not available:
            self.retry_due_s = now_s + self.retry_interval_s
            return event
        self.lost, self.fresh_s = False, now_s
        return "recovered"


def diagnostic_values(config: p.ImuConfig, who_am_i: int | None, sample_rate_hz: float, mag_mode: str,
                      mag_available: bool, mag_messages: int, startup_attempts: int, gyro_bias_rad_s: Any,
                      bias_status: str | None) -> list[tuple[str, Any]]:
    """The device-specific KeyValues of the IMU's ``/diagnostics`` entry (bias_status None: no calibration)."""
    out = [("who_am_i", f"0x{who_am_i:02x}" if who_am_i is not None else "unknown"),
           ("sample_rate_configured_hz", f"{sample_rate_hz:g}"), ("output_data_rate_hz", f"{config.accel_odr_hz:.3f}"),
           ("accel_full_scale_g", f"{p.ACCEL_RANGE_G[config.accel_fs_sel]:g}"),
           ("gyro_full_scale_dps", f"{p.GYRO_RANGE_DPS[config.gyro_fs_sel]:g}"), ("dlpf_config", config.gyro_dlpfcfg),
           ("magnetometer_mode", mag_mode), ("magnetometer_available", mag_available),
           ("magnetometer_messages", mag_messages), ("startup_attempts", startup_attempts),
           ("gyro_bias_rad_s", " ".join(f"{v:.6f}" for v in gyro_bias_rad_s))]
    return out + ([("gyro_bias_status", bias_status)] if bias_status is not None else [])


@dataclass(frozen=True)
class PollResult:
    """One poll's reads (:func:`read_poll`). ready: INT_STATUS_1.RAW_DATA_0_RDY (None: not read);
    block: the 14-byte accel/gyro/temperature block (None when the burst failed: ``error``);
    mag_block: the AK09916's ST1..ST2 (None: no magnetometer, its read failed, or stale after a
    NACK); counters: diagnostics counters to add (``mag_nack``, ``mag_i2c_failure``)."""

    ready: bool | None
    block: bytes | None
    mag_block: bytes | None
    counters: tuple[str, ...]
    error: I2CError | None = None


def read_poll(regs: BankedRegisters, mag_device: I2CPort, mag_mode: str, mag_available: bool,
              require_data_ready: bool, nack_filter: MagNackFilter) -> PollResult:
    """The reads of one poll, in bank 0 (module docstring of the node): one burst ending with the sensor block from
    ACCEL_XOUT_H (plus the AK09916 block in ``i2c_master`` mode), starting early enough to take the status registers the
    poll needs in the same transfer: I2C_MST_STATUS (0x17, SLV0_NACK through ``nack_filter``) in ``i2c_master`` mode,
    else INT_STATUS_1 (0x1A, RAW_DATA_0_RDY) when ``require_data_ready``, else ACCEL_XOUT_H itself. One bus transaction
    (one system call, one wake-up) per poll instead of three; the status registers between them (INT_STATUS,
    INT_STATUS_2/3) are read and cleared too, which no step uses. In ``bypass`` mode the AK09916 block is a second read,
    at 0x0C:0x10. Only the burst's failure is an error (the poll is dropped)."""
    counters: list[str] = []
    master = mag_mode == "i2c_master" and mag_available
    first = p.I2C_MST_STATUS if master else p.INT_STATUS_1 if require_data_ready else p.ACCEL_XOUT_H
    skip = p.ACCEL_XOUT_H.address - first.address
    try:
        length = skip + p.SENSOR_BLOCK_LENGTH + (p.AK09916_BLOCK_LENGTH if master else 0)
        data = bytes(regs.read(first, length))
    except I2CError as exc:
        return PollResult(None, None, None, (), exc)
    ready = bool(data[p.INT_STATUS_1.address - first.address] & p.INT_STATUS_1_RAW_DATA_0_RDY) \
        if require_data_ready else None
    block = data[skip:skip + p.SENSOR_BLOCK_LENGTH]
    mag_block = None
    if master:
        nack = bool(data[0] & p.I2C_MST_STATUS_SLV0_NACK)
        if nack:
            counters.append("mag_nack")
        # None: the sample before the NACK
        mag_block = nack_filter.update(data[skip + p.SENSOR_BLOCK_LENGTH:], nack)
    elif mag_mode == "bypass" and mag_available:
        try:
            mag_block = mag_device.read_block(p.AK_ST1.address, p.AK09916_BLOCK_LENGTH)
        except I2CError:
            counters.append("mag_i2c_failure")
    return PollResult(ready, block, mag_block, tuple(counters))
