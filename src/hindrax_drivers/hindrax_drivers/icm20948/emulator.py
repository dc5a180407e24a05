"""ICM-20948 and AK09916 device emulators (register-exact), for tests and simulation.

:class:`Icm20948Emulator` (0x68, or 0x69 with AD0 high) follows the checklist of docs/devices.md §4.8:

* four banks selected by REG_BANK_SEL (0x7F, bits 5:4), WHO_AM_I = 0xEA, reset values PWR_MGMT_1 =
  0x41 (asleep), LP_CONFIG = 0x40, ACCEL_CONFIG = 0x01, GYRO_CONFIG_1 = 0x01 [UNVERIFIED];
  DEVICE_RESET restores them and selects bank 0 [assumed in §4.1]; bursts auto-increment;
* data registers follow a truth source ``t_s -> (specific_force_m_s2 (3,), angular_rate_rad_s (3,),
  magnetic_field_t (3,), temperature_c)`` in the SENSOR frame, sampled at the configured output data rate and quantised
  with the full scale; frozen while SLEEP; INT_STATUS_1.RAW_DATA_0_RDY set on new data, cleared on read;
* the AK09916 (:class:`Ak09916Emulator`: DRDY/DOR/HOFL, ST2 read-lock, modes) is reached directly
  through :attr:`Icm20948Emulator.aux_port` when BYPASS_EN = 1 and I2C_MST_EN = 0 (else it NACKs),
  or through the I2C master: SLV0..SLV3 once per master cycle (gyro ODR tick, and at once on a
  rising I2C_MST_EN) into EXT_SLV_SENS_DATA, SLV4 one transaction at once (SLV4_DONE);
* faults: ``stuck``, ``aux_connected = False`` (SLVn_NACK, the last sample kept, bypass errno 121),
  :meth:`Icm20948Emulator.power_glitch` (both chips to power-on state), ``data_ready_stuck_low``;
  bus errors are injected by the bus.

Not modelled: FIFO, DMP, interrupt pins, low-power cycling, self-test, the start-up delay after
wake, filter dynamics (the DLPF only sets the output rate)."""

from __future__ import annotations

import functools
import math
import time
from typing import Callable, Sequence

import numpy as np

from hindrax_common.transport.emulated_i2c import RegisterPointerEmulator, remote_io_error
from . import protocol as p

__all__ = ["from_config", "Icm20948Emulator", "Ak09916Emulator", "ImuTruth"]

#: the accel/gyro configuration of the bank-2 register values (:meth:`~.protocol.ImuConfig.from_registers`; frozen,
#: so one decoded object serves every transaction until a register changes)
_decoded_config = functools.lru_cache(maxsize=16)(p.ImuConfig.from_registers)

_SINGLE_MEASUREMENT_TIME_S = 0.01  # CNTL2 = 0x01 to DRDY, s (not in docs/devices.md; assumed)

#: Truth source in the sensor frame: t_s -> (specific_force_m_s2 (3,), angular_rate_rad_s (3,),
#: magnetic_field_t (3,), temperature_c).
ImuTruth = Callable[[float], "tuple[Sequence[float], Sequence[float], Sequence[float], float]"]


class Ak09916Emulator(RegisterPointerEmulator):
    """AK09916 magnetometer register file (docs/devices.md §4.5, address 0x0C).

    Args:
        field_truth: ``t_s -> magnetic_field_t (3,)`` in the ICM accel/gyro frame; the emulator
            applies the axis flip of §4.7 (hx = Bx, hy = -By, hz = -Bz).
        clock: monotonic clock, s.

    Semantics: continuous modes measure every 1/rate s from the mode write; a measurement that finds unread data
    (DRDY = 1), or arrives while a read is in progress (a data register was read but ST2 not yet), sets DOR and, in the
    second case, is discarded. DRDY and DOR clear when a data register or ST2 is read; reading ST2 ends the read lock.
    Values beyond +-32752 counts are clamped with ST2.HOFL = 1. Writing the current mode again keeps its timing; the
    self-test mode is stored but produces no measurement. ``stuck = True`` freezes the data registers."""

    def __init__(self, field_truth: Callable[[float], Sequence[float]],
                 clock: Callable[[], float] = time.monotonic) -> None:
        super().__init__()
        self.field_truth = field_truth
        self.clock = clock
        self.stuck = False
        self.measurements = 0
        self._soft_reset()

    def _soft_reset(self) -> None:
        self._mode = p.AK_MODE_POWER_DOWN
        self._mode_start_t = 0.0
        self._last_k = 0
        self._single_done_t: float | None = None
        self._data = bytearray(8)  # HXL..HZH, TMPS, ST2
        self._drdy = False
        self._dor = False
        self._locked = False

    @property
    def mode(self) -> int:
        """Current CNTL2 mode."""
        return self._mode

    # ------------------------------------------------------------------ measurement model
    def _measure(self, t_s: float) -> None:
        if not self.stuck:
            raw, overflow = p.mag_to_raw(self.field_truth(t_s))
            self._data[0:6] = np.asarray(raw, dtype="<i2").tobytes()
            self._data[6] = 0
            self._data[7] = p.AK_ST2_HOFL if overflow else 0
        self.measurements += 1

    def _begin_transaction(self) -> None:
        self.advance(float(self.clock()))

    def advance(self, now: float) -> None:
        """Bring the measurement state up to time ``now`` (called at every transaction)."""
        with self._lock:
            if self._mode == p.AK_MODE_SINGLE and self._single_done_t is not None:
                if now >= self._single_done_t:
                    if self._locked:
                        self._dor = True
                    else:
                        self._dor = self._dor or self._drdy
                        self._measure(self._single_done_t)
                        self._drdy = True
                    self._mode = p.AK_MODE_POWER_DOWN
                    self._single_done_t = None
            rate_hz = p.AK_CONTINUOUS_MODE_RATE_HZ.get(self._mode)
            if rate_hz is None:
                return
            period_s = 1.0 / rate_hz
            k = math.floor((now - self._mode_start_t) / period_s + 1e-9)
            if k <= self._last_k:
                return
            missed = k - self._last_k
            self._last_k = k
            if self._locked:
                self._dor = True
                return
            self._dor = self._dor or self._drdy or missed > 1
            self._measure(self._mode_start_t + k * period_s)
            self._drdy = True

    # ------------------------------------------------------------------ register file
    def _next_pointer(self, register: int) -> int:
        """Auto-increment 00..03 -> 10..18 -> 00; 30..32 -> 30 (docs/devices.md §4.5)."""
        if register == 0x03:
            return 0x10
        if register == 0x18:
            return 0x00
        if register == 0x32:
            return 0x30
        return (register + 1) & 0xFF

    def _read_register(self, register: int) -> int:
        if register == p.AK_WIA1.address:
            return p.AK09916_WIA1_VALUE
        if register == p.AK_WIA2.address:
            return p.AK09916_WIA2_VALUE
        if register == p.AK_ST1.address:
            return (p.AK_ST1_DRDY if self._drdy else 0) | (p.AK_ST1_DOR if self._dor else 0)
        if 0x11 <= register <= 0x17:
            value = self._data[register - 0x11]
            self._drdy = self._dor = False
            if self._mode in p.AK_CONTINUOUS_MODE_RATE_HZ:
                self._locked = True
            return value
        if register == p.AK_ST2.address:
            self._drdy = self._dor = False
            self._locked = False
            return self._data[7]
        if register == p.AK_CNTL2.address:
            return self._mode
        return 0  # RSV, CNTL1, CNTL3 (SRST self-clears), TS, non-existent registers

    def _write_register(self, register: int, value: int) -> None:
        if register == p.AK_CNTL3.address and value & p.AK_CNTL3_SRST:
            self._soft_reset()
        elif register == p.AK_CNTL2.address:
            mode = value & 0x1F
            if mode == self._mode:
                return
            now = float(self.clock())
            self._mode = mode
            self._single_done_t = None
            if mode in p.AK_CONTINUOUS_MODE_RATE_HZ:
                self._mode_start_t = now
                self._last_k = 0
            elif mode == p.AK_MODE_SINGLE:
                self._single_done_t = now + _SINGLE_MEASUREMENT_TIME_S


class _AuxBusPort:
    """The AK09916 as seen at 0x0C on the host bus: present only in bypass mode (docs/devices.md §4.6a)."""

    def __init__(self, icm: "Icm20948Emulator") -> None:
        self._icm = icm

    def _check(self) -> None:
        if not self._icm.bypass_active or not self._icm.aux_connected:
            raise remote_io_error(p.AK09916_ADDRESS, "bypass not enabled")

    def i2c_write(self, data: bytes) -> None:
        """Forward a write to the AK09916, or NACK (errno 121) when not in bypass."""
        with self._icm._lock:
            self._check()
            self._icm.magnetometer.i2c_write(data)

    def i2c_read(self, n: int) -> bytes:
        """Forward a read to the AK09916, or NACK (errno 121) when not in bypass."""
        with self._icm._lock:
            self._check()
            return self._icm.magnetometer.i2c_read(n)


class Icm20948Emulator(RegisterPointerEmulator):
    """Register-exact ICM-20948 with an AK09916 on its auxiliary bus (see module docstring).

    Args:
        truth: :data:`ImuTruth` in the sensor frame.
        clock: monotonic clock, s.
        address: 0x68 (AD0 low) or 0x69 (AD0 high); informational (the bus maps addresses).

    Attributes:
        magnetometer: the AK09916 emulator, fed by ``truth``'s field.
        aux_port: device to attach at 0x0C on the host bus for the bypass path.
        aux_connected: fault switch for the AK09916 (False = it NACKs).
        data_ready_stuck_low: fault switch: INT_STATUS_1.RAW_DATA_0_RDY always reads 0 (the data registers
            still update).
        samples: number of accel/gyro samples generated."""

    def __init__(self, truth: ImuTruth, clock: Callable[[], float] = time.monotonic,
                 address: int = p.ADDRESS_AD0_LOW) -> None:
        super().__init__()
        if address not in (p.ADDRESS_AD0_LOW, p.ADDRESS_AD0_HIGH):
            raise ValueError(f"ICM-20948 address must be 0x68 or 0x69, got 0x{address:02x}")
        self.address = address
        self.truth = truth
        self.clock = clock
        self.magnetometer = Ak09916Emulator(lambda t: self._truth_at(t)[2], clock)
        self.aux_port = _AuxBusPort(self)
        self.aux_connected = True
        self.data_ready_stuck_low = False
        self._stuck = False
        self.samples = 0
        self._truth_cache: tuple[float, tuple] | None = None
        self._device_reset()

    # ------------------------------------------------------------------ state
    def _device_reset(self) -> None:
        self._banks = [bytearray(128) for _ in range(4)]
        for reg, value in p.RESET_VALUES.items():
            self._banks[reg.bank][reg.address] = value
        self._bank = 0
        self._last_accel_t: float | None = None
        self._last_gyro_t: float | None = None
        self._last_master_t: float | None = None

    def _get(self, reg: p.Register) -> int:
        return self._banks[reg.bank][reg.address]

    def _set(self, reg: p.Register, value: int) -> None:
        self._banks[reg.bank][reg.address] = value & 0xFF

    @property
    def bank(self) -> int:
        """Currently selected register bank."""
        return self._bank

    @property
    def sleeping(self) -> bool:
        """PWR_MGMT_1.SLEEP."""
        return bool(self._get(p.PWR_MGMT_1) & p.PWR_MGMT_1_SLEEP)

    @property
    def bypass_active(self) -> bool:
        """BYPASS_EN = 1 and I2C_MST_EN = 0: the AK09916 is on the host bus."""
        return bool(self._get(p.INT_PIN_CFG) & p.INT_PIN_CFG_BYPASS_EN) and not self.master_enabled

    @property
    def master_enabled(self) -> bool:
        """USER_CTRL.I2C_MST_EN."""
        return bool(self._get(p.USER_CTRL) & p.USER_CTRL_I2C_MST_EN)

    @property
    def config(self) -> p.ImuConfig:
        """Accel/gyro configuration decoded from the bank-2 registers."""
        return _decoded_config(self._get(p.GYRO_SMPLRT_DIV), self._get(p.GYRO_CONFIG_1),
                               self._get(p.ACCEL_SMPLRT_DIV_1), self._get(p.ACCEL_SMPLRT_DIV_2),
                               self._get(p.ACCEL_CONFIG))

    @property
    def stuck(self) -> bool:
        """Fault: data registers (accel, gyro, temperature, magnetometer) frozen."""
        return self._stuck

    @stuck.setter
    def stuck(self, value: bool) -> None:
        with self._lock:
            self._stuck = bool(value)
            self.magnetometer.stuck = bool(value)

    def power_glitch(self, magnetometer: bool = True) -> None:
        """Fault: a supply glitch resets the ICM-20948 (and, with ``magnetometer``, the AK09916) to the
        power-on state, as DEVICE_RESET does (docs/devices.md §4.3: PWR_MGMT_1 = 0x41, asleep)."""
        with self._lock:
            self._device_reset()
            if magnetometer:
                self.magnetometer._soft_reset()

    def register_value(self, register: p.Register) -> int:
        """Stored value of a banked register (for tests; no side effects)."""
        with self._lock:
            return self._get(register)

    # ------------------------------------------------------------------ truth -> registers
    def _truth_at(self, t_s: float) -> tuple:
        if self._truth_cache is None or self._truth_cache[0] != t_s:
            self._truth_cache = (t_s, tuple(self.truth(t_s)))
        return self._truth_cache[1]

    def _begin_transaction(self) -> None:
        self.advance(float(self.clock()))

    def advance(self, now: float) -> None:
        """Update data registers and run the I2C master up to time ``now`` (every transaction)."""
        with self._lock:
            if self.sleeping or self._stuck:
                return
            cfg = self.config
            pm1, pm2 = self._get(p.PWR_MGMT_1), self._get(p.PWR_MGMT_2)
            bank0 = self._banks[0]
            t_acc = math.floor(now * cfg.accel_odr_hz) / cfg.accel_odr_hz
            if t_acc != self._last_accel_t:
                self._last_accel_t = t_acc
                raw = p.accel_to_raw(self._truth_at(t_acc)[0], cfg.accel_fs_sel)
                self._store_axes(bank0, p.ACCEL_XOUT_H.address, raw, pm2 >> 3)
                bank0[p.INT_STATUS_1.address] |= p.INT_STATUS_1_RAW_DATA_0_RDY
                self.samples += 1
            t_gyr = math.floor(now * cfg.gyro_odr_hz) / cfg.gyro_odr_hz
            if t_gyr != self._last_gyro_t:
                self._last_gyro_t = t_gyr
                truth = self._truth_at(t_gyr)
                raw = p.gyro_to_raw(truth[1], cfg.gyro_fs_sel)
                self._store_axes(bank0, p.GYRO_XOUT_H.address, raw, pm2)
                if not pm1 & p.PWR_MGMT_1_TEMP_DIS:
                    temp = p.temperature_to_raw(float(truth[3]))
                    bank0[p.TEMP_OUT_H.address:p.TEMP_OUT_H.address + 2] = int(temp).to_bytes(2, "big", signed=True)
                bank0[p.INT_STATUS_1.address] |= p.INT_STATUS_1_RAW_DATA_0_RDY
            if self.master_enabled:
                t_master = math.floor(now * cfg.gyro_odr_hz) / cfg.gyro_odr_hz
                if t_master != self._last_master_t:
                    self._last_master_t = t_master
                    self._run_master_cycle()

    @staticmethod
    def _store_axes(bank0: bytearray, start: int, raw: Sequence[int], disable_bits: int) -> None:
        """Write 3 int16 big-endian values; axis i skipped when its DISABLE bit (x = bit 2) is set."""
        for i, value in enumerate(raw):
            if disable_bits & (0x4 >> i):
                continue
            bank0[start + 2 * i:start + 2 * i + 2] = int(value).to_bytes(2, "big", signed=True)

    # ------------------------------------------------------------------ I2C master
    def _aux_device(self, address: int) -> Ak09916Emulator | None:
        if address == p.AK09916_ADDRESS and self.aux_connected:
            return self.magnetometer
        return None

    @staticmethod
    def _byte_swap(data: bytes, first_register: int, grp: bool) -> bytes:
        """BYTE_SW: swap byte pairs; GRP = 0 pairs start at even, GRP = 1 at odd register addresses."""
        out = bytearray(data)
        i = 0
        while i + 1 < len(out):
            if (first_register + i) % 2 == (1 if grp else 0):
                out[i], out[i + 1] = out[i + 1], out[i]
                i += 2
            else:
                i += 1
        return bytes(out)

    def _transfer(self, addr: int, reg: int, ctrl: int, value: int, length: int) -> bytes:
        """One slave transaction (docs/devices.md §4.6b): with RNW set in ``addr``, ``reg`` (unless
        REG_DIS) then a read of ``length`` bytes; else a write of ``value`` (after ``reg`` unless
        REG_DIS), returning b"". OSError when no device answers at ``addr``."""
        device = self._aux_device(addr & 0x7F)
        if device is None:
            raise remote_io_error(addr & 0x7F)
        if not addr & p.I2C_SLV_ADDR_RNW:
            device.i2c_write(bytes([value] if ctrl & p.I2C_SLV_CTRL_REG_DIS else [reg, value]))
            return b""
        if not ctrl & p.I2C_SLV_CTRL_REG_DIS:
            device.i2c_write(bytes([reg]))
        return device.i2c_read(length) if length else b""

    def _run_slv4(self) -> None:
        ctrl = self._get(p.I2C_SLV4_CTRL)
        if not ctrl & p.I2C_SLV_CTRL_EN:
            return
        addr = self._get(p.I2C_SLV4_ADDR)
        status = p.I2C_MST_STATUS_SLV4_DONE
        try:
            data = self._transfer(addr, self._get(p.I2C_SLV4_REG), ctrl, self._get(p.I2C_SLV4_DO), 1)
            if addr & p.I2C_SLV_ADDR_RNW:
                self._set(p.I2C_SLV4_DI, data[0])
        except OSError:
            status |= p.I2C_MST_STATUS_SLV4_NACK
        self._set(p.I2C_SLV4_CTRL, ctrl & ~p.I2C_SLV_CTRL_EN)
        self._set(p.I2C_MST_STATUS, self._get(p.I2C_MST_STATUS) | status)

    def _run_master_cycle(self) -> None:
        """One I2C-master cycle: SLV4 (if pending), then SLV0..SLV3 in order (docs/devices.md §4.6b)."""
        self._run_slv4()
        offset = 0
        status = 0
        ext_start = p.EXT_SLV_SENS_DATA_00.address
        for n in range(4):
            addr_r, reg_r, ctrl_r, do_r = p.slave_registers(n)
            ctrl = self._get(ctrl_r)
            if not ctrl & p.I2C_SLV_CTRL_EN:
                continue
            addr, reg = self._get(addr_r), self._get(reg_r)
            length = ctrl & p.I2C_SLV_CTRL_LENG_MASK
            try:
                data = self._transfer(addr, reg, ctrl, self._get(do_r), length)
                if addr & p.I2C_SLV_ADDR_RNW:
                    if ctrl & p.I2C_SLV_CTRL_BYTE_SW:
                        data = self._byte_swap(data, reg, bool(ctrl & p.I2C_SLV_CTRL_GRP))
                    data = data[:max(0, p.EXT_SLV_SENS_DATA_LENGTH - offset)]
                    self._banks[0][ext_start + offset:ext_start + offset + len(data)] = data
            except OSError:
                status |= 1 << n
            if addr & p.I2C_SLV_ADDR_RNW:
                offset += length
        if status:
            self._set(p.I2C_MST_STATUS, self._get(p.I2C_MST_STATUS) | status)

    # ------------------------------------------------------------------ register file
    def _next_pointer(self, register: int) -> int:
        return (register + 1) & 0x7F

    def _read_register(self, register: int) -> int:
        if register > 0x7F:
            return 0
        if register == p.REG_BANK_SEL_ADDRESS:
            return p.bank_select_value(self._bank)
        value = self._banks[self._bank][register]
        if self._bank == 0 and register == p.INT_STATUS_1.address and self.data_ready_stuck_low:
            value &= ~p.INT_STATUS_1_RAW_DATA_0_RDY  # fault: the data keep updating, the flag never shows it
        if self._bank == 0 and register in (p.I2C_MST_STATUS.address, p.INT_STATUS_1.address):
            self._banks[0][register] = 0  # status registers clear on read
        return value

    def _write_register(self, register: int, value: int) -> None:
        if register > 0x7F:
            return
        if register == p.REG_BANK_SEL_ADDRESS:
            self._bank = (value >> 4) & 0x3
            return
        reg = p.Register(self._bank, register, "")
        if self._bank == 0:
            if register == p.WHO_AM_I.address or register in range(0x17, 0x1D) \
                    or register in range(p.ACCEL_XOUT_H.address, p.EXT_SLV_SENS_DATA_00.address
                                         + p.EXT_SLV_SENS_DATA_LENGTH):
                return  # read-only
            if register == p.PWR_MGMT_1.address:
                if value & p.PWR_MGMT_1_DEVICE_RESET:
                    self._device_reset()
                    return
                self._set(p.PWR_MGMT_1, value)
                return
            if register == p.USER_CTRL.address:
                was_enabled = self.master_enabled
                if value & p.USER_CTRL_I2C_MST_RST:
                    self._banks[0][p.EXT_SLV_SENS_DATA_00.address:
                                   p.EXT_SLV_SENS_DATA_00.address + p.EXT_SLV_SENS_DATA_LENGTH] = bytes(24)
                    self._set(p.I2C_MST_STATUS, 0)
                self._set(p.USER_CTRL, value & ~(p.USER_CTRL_I2C_MST_RST | p.USER_CTRL_SRAM_RST | p.USER_CTRL_DMP_RST))
                if self.master_enabled and not was_enabled and not self.sleeping and not self._stuck:
                    gyro_odr_hz = self.config.gyro_odr_hz
                    self._last_master_t = math.floor(float(self.clock()) * gyro_odr_hz) / gyro_odr_hz
                    self._run_master_cycle()
                return
        self._banks[self._bank][register] = value
        if reg[:2] == p.I2C_SLV4_CTRL[:2] and value & p.I2C_SLV_CTRL_EN and self.master_enabled \
                and not self.sleeping:
            self._run_slv4()


def from_config(config, truth: ImuTruth, clock: Callable[[], float], seed: int = 0) -> Icm20948Emulator:
    """The ICM-20948 at ``sensors.icm20948.i2c_address`` on ``truth`` and ``clock`` (s) (devices.py factory)."""
    return Icm20948Emulator(truth, clock, address=config.sensors.icm20948.i2c_address)
