"""TDK InvenSense ICM-20948 (with AK09916 magnetometer): pure protocol layer (no I/O, no clocks).

The registers the driver uses (the full map: docs/devices.md §4.1), identity values, the reset/wake and configuration
sequences as data (lists of register writes), full-scale / DLPF / sample-rate register values from SI settings,
conversion of raw burst reads to SI (accel m/s^2, gyro rad/s, temperature degC, magnetic field T rotated into the
accel/gyro frame), the AK09916 status flags, and the device-side quantisation used by the emulator. Everything is from
docs/devices.md §4 (datasheet DS-000189 [I1], SparkFun [I2], Pimoroni [I3], PX4 [I4]).

Why our own code: the available Python packages (Pimoroni ``icm20948``) do I/O inside the
conversion code, hard-code one configuration and write a questionable I2C_MST_CTRL value
(docs/devices.md §4.6); the drivers need a pure, testable layer shared with the emulator.

Facts used that docs/devices.md marks as unverified or that go beyond it are flagged in the docstrings: gyro base rate
1125 Hz (§4.4 discrepancy), gyro ODR with the DLPF bypassed (9 kHz, datasheet spec table, not in docs/devices.md),
INT_STATUS_1 / I2C_MST_STATUS bit positions (datasheet register descriptions), temperature room offset 0 (§4.4)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import NamedTuple, Sequence

import numpy as np

from hindrax_common.transport.i2c import RegisterWrite

__all__ = ["Icm20948Error", "Register", "BankedWrite", "ImuConfig", "ImuSample", "MagSample",
           "reset_wake_sequence", "configure_sequence", "slave_read_writes", "slave_write_writes",
           "mag_master_sequence", "mag_bypass_sequence", "ak09916_direct_init_writes", "parse_sensor_block",
           "parse_ak09916_block", "accel_to_raw", "gyro_to_raw", "temperature_to_raw", "mag_to_raw",
           "bank_select_value", "gyro_odr_hz", "accel_odr_hz"]


class Icm20948Error(ValueError):
    """Bad ICM-20948/AK09916 input: wrong length, unsupported setting, bad identity."""


class Register(NamedTuple):
    """A banked register: ``bank`` (0..3; ``None`` for AK09916 registers) and 7-bit ``address``."""

    bank: int | None
    address: int
    name: str


# ------------------------------------------------------------------------------ identity
ADDRESS_AD0_LOW = 0x68
ADDRESS_AD0_HIGH = 0x69
WHO_AM_I_VALUE = 0xEA
AK09916_ADDRESS = 0x0C
AK09916_WIA1_VALUE = 0x48
AK09916_WIA2_VALUE = 0x09

# ------------------------------------------------------------------------------ bank 0
WHO_AM_I = Register(0, 0x00, "WHO_AM_I")
USER_CTRL = Register(0, 0x03, "USER_CTRL")
LP_CONFIG = Register(0, 0x05, "LP_CONFIG")
PWR_MGMT_1 = Register(0, 0x06, "PWR_MGMT_1")
PWR_MGMT_2 = Register(0, 0x07, "PWR_MGMT_2")
INT_PIN_CFG = Register(0, 0x0F, "INT_PIN_CFG")
INT_ENABLE_1 = Register(0, 0x11, "INT_ENABLE_1")
I2C_MST_STATUS = Register(0, 0x17, "I2C_MST_STATUS")
INT_STATUS_1 = Register(0, 0x1A, "INT_STATUS_1")
ACCEL_XOUT_H = Register(0, 0x2D, "ACCEL_XOUT_H")
GYRO_XOUT_H = Register(0, 0x33, "GYRO_XOUT_H")
TEMP_OUT_H = Register(0, 0x39, "TEMP_OUT_H")
EXT_SLV_SENS_DATA_00 = Register(0, 0x3B, "EXT_SLV_SENS_DATA_00")
#: REG_BANK_SEL is at 0x7F in every bank, bank in bits 5:4 (docs/devices.md §4.1).
REG_BANK_SEL_ADDRESS = 0x7F
EXT_SLV_SENS_DATA_LENGTH = 24

# ------------------------------------------------------------------------------ bank 2
GYRO_SMPLRT_DIV = Register(2, 0x00, "GYRO_SMPLRT_DIV")
GYRO_CONFIG_1 = Register(2, 0x01, "GYRO_CONFIG_1")
ACCEL_SMPLRT_DIV_1 = Register(2, 0x10, "ACCEL_SMPLRT_DIV_1")
ACCEL_SMPLRT_DIV_2 = Register(2, 0x11, "ACCEL_SMPLRT_DIV_2")
ACCEL_CONFIG = Register(2, 0x14, "ACCEL_CONFIG")

# ------------------------------------------------------------------------------ bank 3
I2C_MST_CTRL = Register(3, 0x01, "I2C_MST_CTRL")
I2C_SLV4_ADDR = Register(3, 0x13, "I2C_SLV4_ADDR")
I2C_SLV4_REG = Register(3, 0x14, "I2C_SLV4_REG")
I2C_SLV4_CTRL = Register(3, 0x15, "I2C_SLV4_CTRL")
I2C_SLV4_DO = Register(3, 0x16, "I2C_SLV4_DO")
I2C_SLV4_DI = Register(3, 0x17, "I2C_SLV4_DI")


def slave_registers(slave: int) -> tuple[Register, Register, Register, Register]:
    """(I2C_SLVn_ADDR, _REG, _CTRL, _DO) for slave n = 0..3 (bank 3, 0x03 + 4n; docs/devices.md §4.2)."""
    if not isinstance(slave, int) or not 0 <= slave <= 3:
        raise Icm20948Error(f"I2C master slave index must be 0..3, got {slave!r}")
    base = 0x03 + 4 * slave
    return (Register(3, base, f"I2C_SLV{slave}_ADDR"), Register(3, base + 1, f"I2C_SLV{slave}_REG"),
            Register(3, base + 2, f"I2C_SLV{slave}_CTRL"), Register(3, base + 3, f"I2C_SLV{slave}_DO"))


# ------------------------------------------------------------------------------ bits (MSB = 7)
USER_CTRL_I2C_MST_EN = 0x20
USER_CTRL_I2C_IF_DIS = 0x10
USER_CTRL_DMP_RST = 0x08
USER_CTRL_SRAM_RST = 0x04
USER_CTRL_I2C_MST_RST = 0x02
PWR_MGMT_1_DEVICE_RESET = 0x80
PWR_MGMT_1_SLEEP = 0x40
PWR_MGMT_1_TEMP_DIS = 0x08
CLKSEL_AUTO = 0x01
INT_PIN_CFG_BYPASS_EN = 0x02
#: INT_STATUS_1 bit 0 RAW_DATA_0_RDY_INT (datasheet register description; not in docs/devices.md).
INT_STATUS_1_RAW_DATA_0_RDY = 0x01
#: I2C_MST_STATUS bits (docs/devices.md gives bit 7 PASS_THROUGH; the others follow the datasheet
#: register description: 6 SLV4_DONE, 5 LOST_ARB, 4 SLV4_NACK, 3..0 SLV3..SLV0_NACK).
I2C_MST_STATUS_SLV4_DONE = 0x40
I2C_MST_STATUS_SLV4_NACK = 0x10
I2C_MST_STATUS_SLV0_NACK = 0x01
I2C_SLV_ADDR_RNW = 0x80
I2C_SLV_CTRL_EN = 0x80
I2C_SLV_CTRL_BYTE_SW = 0x40
I2C_SLV_CTRL_REG_DIS = 0x20
I2C_SLV_CTRL_GRP = 0x10
I2C_SLV_CTRL_LENG_MASK = 0x0F
I2C_MST_CTRL_P_NSR = 0x10
#: P_NSR | CLK = 7 (345.6 kHz), the recommended value used by SparkFun (docs/devices.md §4.6).
I2C_MST_CTRL_RECOMMENDED = I2C_MST_CTRL_P_NSR | 0x07

#: Reset values that differ from 0 (docs/devices.md §4.2, §4.8). GYRO_CONFIG_1 = 0x01 is UNVERIFIED.
RESET_VALUES: dict[Register, int] = {
    WHO_AM_I: WHO_AM_I_VALUE,
    LP_CONFIG: 0x40,
    PWR_MGMT_1: 0x41,
    ACCEL_CONFIG: 0x01,
    GYRO_CONFIG_1: 0x01,
}

# ------------------------------------------------------------------------------ scales
#: Accel sensitivity per ACCEL_FS_SEL 0..3 (+-2/4/8/16 g) in LSB/g [I1 p12] (docs/devices.md §4.4).
ACCEL_LSB_PER_G = (16384.0, 8192.0, 4096.0, 2048.0)
ACCEL_RANGE_G = (2.0, 4.0, 8.0, 16.0)
#: Gyro sensitivity per GYRO_FS_SEL 0..3 (+-250/500/1000/2000 dps) in LSB/(deg/s) [I2][I3].
GYRO_LSB_PER_DPS = (131.0, 65.5, 32.8, 16.4)
GYRO_RANGE_DPS = (250.0, 500.0, 1000.0, 2000.0)
#: Temperature: degC = (TEMP_OUT - offset)/333.87 + 21, offset taken as 0 (docs/devices.md §4.4, PX4).
TEMP_SENSITIVITY_LSB_PER_C = 333.87
TEMP_OFFSET_C = 21.0
#: AK09916: 0.15 uT/LSB, valid range +-32752 counts (docs/devices.md §4.5).
AK09916_TESLA_PER_LSB = 0.15e-6
AK09916_MAX_COUNTS = 32752
#: Standard gravity used for the g <-> m/s^2 conversion.
GRAVITY_M_S2 = 9.80665

#: Base output data rate of accel and gyro with FCHOICE = 1: 1125 Hz (docs/devices.md §4.4; the
#: datasheet's "1.1 kHz" for the gyro is the documented discrepancy, resolved as 1125 Hz).
BASE_ODR_HZ = 1125.0
#: Accel ODR with the DLPF bypassed (FCHOICE = 0) [I1 p12].
ACCEL_BYPASS_ODR_HZ = 4500.0
#: Gyro ODR with the DLPF bypassed: 9 kHz, from the datasheet spec table (NOT in docs/devices.md;
#: only affects how often the emulator's data registers change).
GYRO_BYPASS_ODR_HZ = 9000.0

SENSOR_BLOCK_LENGTH = 14
AK09916_BLOCK_LENGTH = 9

# ------------------------------------------------------------------------------ AK09916
AK_WIA1 = Register(None, 0x00, "WIA1")
AK_WIA2 = Register(None, 0x01, "WIA2")
AK_ST1 = Register(None, 0x10, "ST1")
AK_HXL = Register(None, 0x11, "HXL")
AK_TMPS = Register(None, 0x17, "TMPS")
AK_ST2 = Register(None, 0x18, "ST2")
AK_CNTL2 = Register(None, 0x31, "CNTL2")
AK_CNTL3 = Register(None, 0x32, "CNTL3")
AK_ST1_DRDY = 0x01
AK_ST1_DOR = 0x02
AK_ST2_HOFL = 0x08
AK_CNTL3_SRST = 0x01
AK_MODE_POWER_DOWN = 0x00
AK_MODE_SINGLE = 0x01
AK_MODE_CONTINUOUS_10HZ = 0x02
AK_MODE_CONTINUOUS_20HZ = 0x04
AK_MODE_CONTINUOUS_50HZ = 0x06
AK_MODE_CONTINUOUS_100HZ = 0x08
AK_MODE_SELF_TEST = 0x10
#: Continuous-mode rates (docs/devices.md §4.5 CNTL2 table).
AK_CONTINUOUS_MODE_RATE_HZ = {AK_MODE_CONTINUOUS_10HZ: 10.0, AK_MODE_CONTINUOUS_20HZ: 20.0,
                              AK_MODE_CONTINUOUS_50HZ: 50.0, AK_MODE_CONTINUOUS_100HZ: 100.0}
#: Wait after an AK09916 soft reset before the next command. Not given in docs/devices.md (SparkFun
#: polls CNTL3 until it reads 0); 1 ms is our assumption, enough for the emulator (instant reset).
AK_RESET_WAIT_S = 0.001


def bank_select_value(bank: int) -> int:
    """REG_BANK_SEL value for ``bank`` 0..3: ``bank << 4`` (docs/devices.md §4.1)."""
    if not isinstance(bank, int) or not 0 <= bank <= 3:
        raise Icm20948Error(f"bank must be 0..3, got {bank!r}")
    return bank << 4


# ------------------------------------------------------------------------------ configuration
def accel_odr_hz(smplrt_div: int, fchoice: int) -> float:
    """Accel output data rate: 1125/(1 + div) with FCHOICE = 1, 4500 Hz bypassed (docs/devices.md §4.4)."""
    if not fchoice:
        return ACCEL_BYPASS_ODR_HZ
    return BASE_ODR_HZ / (1 + (int(smplrt_div) & 0xFFF))


def gyro_odr_hz(smplrt_div: int, fchoice: int, dlpfcfg: int) -> float:
    """Gyro output data rate (docs/devices.md §4.4).

    1125/(1 + div) when FCHOICE = 1 and 0 < DLPFCFG < 7 (the divider only takes effect then); 1125 Hz for FCHOICE = 1
    with DLPFCFG 0 or 7; 9 kHz with the DLPF bypassed (flagged, see :data:`GYRO_BYPASS_ODR_HZ`)."""
    if not fchoice:
        return GYRO_BYPASS_ODR_HZ
    if 0 < int(dlpfcfg) < 7:
        return BASE_ODR_HZ / (1 + (int(smplrt_div) & 0xFF))
    return BASE_ODR_HZ


@dataclass(frozen=True)
class ImuConfig:
    """Accel/gyro configuration as register fields (docs/devices.md §4.2, §4.4).

    Attributes:
        accel_fs_sel, gyro_fs_sel: full-scale selectors 0..3.
        accel_dlpfcfg, gyro_dlpfcfg: DLPF config 0..7, or None for DLPF bypassed (FCHOICE = 0).
        accel_smplrt_div: 12-bit accel divider 0..4095. gyro_smplrt_div: 8-bit divider 0..255."""

    accel_fs_sel: int = 0
    gyro_fs_sel: int = 0
    accel_dlpfcfg: int | None = 3
    gyro_dlpfcfg: int | None = 3
    accel_smplrt_div: int = 4
    gyro_smplrt_div: int = 4

    def __post_init__(self) -> None:
        for name, value, hi in (("accel_fs_sel", self.accel_fs_sel, 3), ("gyro_fs_sel", self.gyro_fs_sel, 3),
                                ("accel_smplrt_div", self.accel_smplrt_div, 4095),
                                ("gyro_smplrt_div", self.gyro_smplrt_div, 255)):
            if not isinstance(value, int) or not 0 <= value <= hi:
                raise Icm20948Error(f"{name} must be an int 0..{hi}, got {value!r}")
        for name, dlpfcfg in (("accel_dlpfcfg", self.accel_dlpfcfg), ("gyro_dlpfcfg", self.gyro_dlpfcfg)):
            if dlpfcfg is not None and (not isinstance(dlpfcfg, int) or not 0 <= dlpfcfg <= 7):
                raise Icm20948Error(f"{name} must be None or an int 0..7, got {dlpfcfg!r}")

    @property
    def gyro_config_1_value(self) -> int:
        """GYRO_CONFIG_1: DLPFCFG bits 5:3, FS_SEL bits 2:1, FCHOICE bit 0."""
        return _config_value(self.gyro_dlpfcfg, self.gyro_fs_sel)

    @property
    def accel_config_value(self) -> int:
        """ACCEL_CONFIG: DLPFCFG bits 5:3, FS_SEL bits 2:1, FCHOICE bit 0."""
        return _config_value(self.accel_dlpfcfg, self.accel_fs_sel)

    @property
    def accel_lsb_per_g(self) -> float:
        """Accel sensitivity, LSB/g."""
        return ACCEL_LSB_PER_G[self.accel_fs_sel]

    @property
    def gyro_lsb_per_dps(self) -> float:
        """Gyro sensitivity, LSB/(deg/s)."""
        return GYRO_LSB_PER_DPS[self.gyro_fs_sel]

    @property
    def accel_odr_hz(self) -> float:
        """Accel output data rate, Hz (:func:`accel_odr_hz`)."""
        return accel_odr_hz(self.accel_smplrt_div, self.accel_dlpfcfg is not None)

    @property
    def gyro_odr_hz(self) -> float:
        """Gyro output data rate, Hz (:func:`gyro_odr_hz`)."""
        return gyro_odr_hz(self.gyro_smplrt_div, self.gyro_dlpfcfg is not None,
                           self.gyro_dlpfcfg if self.gyro_dlpfcfg is not None else 0)

    @classmethod
    def from_registers(cls, gyro_smplrt_div: int, gyro_config_1: int, accel_smplrt_div_1: int,
                       accel_smplrt_div_2: int, accel_config: int) -> "ImuConfig":
        """Decode the bank-2 register values (device side, used by the emulator)."""
        def fields(value: int) -> tuple[int, int | None]:
            fs = (value >> 1) & 0x3
            dlpf = (value >> 3) & 0x7 if value & 0x1 else None
            return fs, dlpf

        gfs, gdlpf = fields(gyro_config_1)
        afs, adlpf = fields(accel_config)
        return cls(accel_fs_sel=afs, gyro_fs_sel=gfs, accel_dlpfcfg=adlpf, gyro_dlpfcfg=gdlpf,
                   accel_smplrt_div=((accel_smplrt_div_1 & 0x0F) << 8) | (accel_smplrt_div_2 & 0xFF),
                   gyro_smplrt_div=gyro_smplrt_div & 0xFF)


def _config_value(dlpfcfg: int | None, fs_sel: int) -> int:
    if dlpfcfg is None:
        return fs_sel << 1
    return (dlpfcfg << 3) | (fs_sel << 1) | 0x1


# ------------------------------------------------------------------------------ sequences
@dataclass(frozen=True)
class BankedWrite:
    """A register write in a given bank, with the delay to wait afterwards (seconds)."""

    register: Register
    value: int
    delay_after_s: float = 0.0
    note: str = ""


def reset_wake_sequence(reset_wait_s: float = 0.010, wake_wait_s: float = 0.020) -> list[BankedWrite]:
    """Reset and wake (docs/devices.md §4.3 steps 2-4).

    PWR_MGMT_1 = 0x80 (DEVICE_RESET), wait ~10 ms; PWR_MGMT_1 = 0x01 (SLEEP = 0, CLKSEL auto),
    wait 20 ms (accel start-up from sleep [I1 p12]); PWR_MGMT_2 = 0x00 (all axes on). Check
    WHO_AM_I == 0xEA before (step 1) with a read of bank 0 register 0x00."""
    return [
        BankedWrite(PWR_MGMT_1, PWR_MGMT_1_DEVICE_RESET, reset_wait_s, "DEVICE_RESET"),
        BankedWrite(PWR_MGMT_1, CLKSEL_AUTO, wake_wait_s, "wake, CLKSEL auto"),
        BankedWrite(PWR_MGMT_2, 0x00, 0.0, "enable accel and gyro"),
    ]


def configure_sequence(config: ImuConfig) -> list[BankedWrite]:
    """Bank-2 writes for divider, DLPF and full scale (docs/devices.md §4.3 step 5, §4.2 bank 2)."""
    return [
        BankedWrite(GYRO_SMPLRT_DIV, config.gyro_smplrt_div),
        BankedWrite(GYRO_CONFIG_1, config.gyro_config_1_value),
        BankedWrite(ACCEL_SMPLRT_DIV_1, (config.accel_smplrt_div >> 8) & 0x0F),
        BankedWrite(ACCEL_SMPLRT_DIV_2, config.accel_smplrt_div & 0xFF),
        BankedWrite(ACCEL_CONFIG, config.accel_config_value),
    ]


def slave_read_writes(slave: int, address: int, register: int, length: int) -> list[BankedWrite]:
    """Configure I2C master slave ``slave`` to read ``length`` bytes each cycle (docs/devices.md §4.6b).

    The slave is disabled first, so no master cycle can run with a half-updated configuration;
    the bytes land in EXT_SLV_SENS_DATA in slave order."""
    if not 1 <= length <= 15:
        raise Icm20948Error(f"slave read length must be 1..15, got {length}")
    a, r, c, _ = slave_registers(slave)
    return [BankedWrite(c, 0x00), BankedWrite(a, I2C_SLV_ADDR_RNW | (address & 0x7F)),
            BankedWrite(r, register & 0xFF), BankedWrite(c, I2C_SLV_CTRL_EN | length)]


def slave_write_writes(slave: int, address: int, register: int, value: int, wait_s: float = 0.0) -> list[BankedWrite]:
    """Make the I2C master write ``value`` to ``register`` of ``address`` (docs/devices.md §4.6b step 4).

    SLVn_ADDR = address (RNW = 0), SLVn_REG, SLVn_DO, then SLVn_CTRL = 0x81 (EN, length 1). The master repeats the write
    every cycle until the slave is reconfigured; wait ``wait_s`` (at least one master cycle) after enabling."""
    a, r, c, d = slave_registers(slave)
    return [BankedWrite(c, 0x00), BankedWrite(a, address & 0x7F), BankedWrite(r, register & 0xFF),
            BankedWrite(d, value & 0xFF), BankedWrite(c, I2C_SLV_CTRL_EN | 1, wait_s)]


def mag_master_sequence(config: ImuConfig, mode: int = AK_MODE_CONTINUOUS_100HZ) -> list[BankedWrite]:
    """Reach the AK09916 through the ICM I2C master (docs/devices.md §4.6 (b)).

    BYPASS_EN = 0; I2C_MST_CTRL = 0x17; USER_CTRL = I2C_MST_EN; via SLV0: CNTL3 = SRST, then CNTL2 = ``mode``; finally
    SLV0 reads 9 bytes from ST1 (0x10) every cycle into EXT_SLV_SENS_DATA_00..08. Each SLV0 write waits three master
    cycles (the master runs at the gyro ODR, an assumption: the I2C_MST_ODR_CONFIG formula is unverified, §6).

    Raises ``Icm20948Error``: ``mode`` not an AK09916 CNTL2 mode."""
    if mode not in (AK_MODE_POWER_DOWN, AK_MODE_SINGLE, AK_MODE_SELF_TEST, *AK_CONTINUOUS_MODE_RATE_HZ):
        raise Icm20948Error(f"0x{mode:02x} is not an AK09916 CNTL2 mode")
    cycle_wait_s = max(3.0 / config.gyro_odr_hz, AK_RESET_WAIT_S)
    return [
        BankedWrite(INT_PIN_CFG, 0x00, note="BYPASS_EN = 0"),
        BankedWrite(I2C_MST_CTRL, I2C_MST_CTRL_RECOMMENDED, note="P_NSR, 345.6 kHz"),
        BankedWrite(USER_CTRL, USER_CTRL_I2C_MST_EN, note="I2C master on"),
        *slave_write_writes(0, AK09916_ADDRESS, AK_CNTL3.address, AK_CNTL3_SRST, cycle_wait_s),
        *slave_write_writes(0, AK09916_ADDRESS, AK_CNTL2.address, mode, cycle_wait_s),
        *slave_read_writes(0, AK09916_ADDRESS, AK_ST1.address, AK09916_BLOCK_LENGTH),
    ]


def mag_bypass_sequence() -> list[BankedWrite]:
    """Expose the AK09916 at 0x0C on the host bus (docs/devices.md §4.6 (a)): I2C_MST_EN = 0, BYPASS_EN = 1."""
    return [BankedWrite(USER_CTRL, 0x00, note="I2C master off"),
            BankedWrite(INT_PIN_CFG, INT_PIN_CFG_BYPASS_EN, note="BYPASS_EN")]


def ak09916_direct_init_writes(mode: int = AK_MODE_CONTINUOUS_100HZ) -> list[RegisterWrite]:
    """AK09916 writes for bypass mode, to address 0x0C: CNTL3 = SRST, then CNTL2 = ``mode`` (§4.6)."""
    if mode not in (AK_MODE_POWER_DOWN, AK_MODE_SINGLE, AK_MODE_SELF_TEST, *AK_CONTINUOUS_MODE_RATE_HZ):
        raise Icm20948Error(f"0x{mode:02x} is not an AK09916 CNTL2 mode")
    return [RegisterWrite(AK_CNTL3.address, AK_CNTL3_SRST, AK_RESET_WAIT_S, "AK09916 soft reset"),
            RegisterWrite(AK_CNTL2.address, mode, 0.0, "AK09916 mode")]


# ------------------------------------------------------------------------------ conversions
def _as_bytes(data: bytes | Sequence[int], n: int, what: str) -> bytes:
    try:
        raw = bytes(data)
    except (TypeError, ValueError):
        raise Icm20948Error(f"{what}: expected {n} bytes, got {data!r}") from None
    if len(raw) != n:
        raise Icm20948Error(f"{what}: expected {n} bytes, got {len(raw)}")
    return raw


@dataclass(frozen=True)
class ImuSample:
    """One accel/gyro/temperature sample in the SENSOR (accel/gyro) frame.

    Attributes:
        accel_m_s2: specific force, shape (3,), m/s^2 (+g on Z when flat, docs/devices.md §4.4).
        gyro_rad_s: angular rate, shape (3,), rad/s.
        temperature_c: die temperature, degC.
        accel_raw, gyro_raw: int16 counts (x, y, z); temp_raw: int16.
        accel_saturated, gyro_saturated: some axis at an int16 limit (reading clipped)."""

    accel_m_s2: np.ndarray = field(repr=False)
    gyro_rad_s: np.ndarray = field(repr=False)
    temperature_c: float
    accel_raw: tuple[int, int, int]
    gyro_raw: tuple[int, int, int]
    temp_raw: int
    accel_saturated: bool
    gyro_saturated: bool


def _saturated(raw: Sequence[int]) -> bool:
    return any(v in (-32768, 32767) for v in raw)


def parse_sensor_block(data: bytes | Sequence[int], config: ImuConfig) -> ImuSample:
    """Convert the 14-byte burst from ACCEL_XOUT_H (0x2D, bank 0) to SI (docs/devices.md §4.2, §4.4).

    Layout: accel X/Y/Z, gyro X/Y/Z, temperature, each int16 big-endian. accel = raw/LSB_per_g * g;
    gyro = raw/LSB_per_dps in rad/s; temperature = raw/333.87 + 21 degC.

    Raises ``Icm20948Error``: not 14 bytes."""
    raw = np.frombuffer(_as_bytes(data, SENSOR_BLOCK_LENGTH, "ICM-20948 sensor block"), dtype=">i2")
    accel_raw = (int(raw[0]), int(raw[1]), int(raw[2]))
    gyro_raw = (int(raw[3]), int(raw[4]), int(raw[5]))
    temp_raw = int(raw[6])
    return ImuSample(
        accel_m_s2=raw[0:3].astype(float) / config.accel_lsb_per_g * GRAVITY_M_S2,
        gyro_rad_s=np.radians(raw[3:6].astype(float) / config.gyro_lsb_per_dps),
        temperature_c=temp_raw / TEMP_SENSITIVITY_LSB_PER_C + TEMP_OFFSET_C,
        accel_raw=accel_raw, gyro_raw=gyro_raw, temp_raw=temp_raw,
        accel_saturated=_saturated(accel_raw), gyro_saturated=_saturated(gyro_raw),
    )


@dataclass(frozen=True)
class MagSample:
    """One AK09916 reading, rotated into the accel/gyro frame (docs/devices.md §4.7).

    Attributes:
        magnetic_field_t: shape (3,), tesla, accel frame: (hx, -hy, -hz) * 0.15 uT.
        raw: (hx, hy, hz) int16 counts in the AK09916's own axes.
        data_ready: ST1.DRDY, a new measurement since the last read.
        data_overrun: ST1.DOR, at least one measurement was skipped.
        overflow: ST2.HOFL, magnetic sensor overflow: the values are not valid."""

    magnetic_field_t: np.ndarray = field(repr=False)
    raw: tuple[int, int, int]
    data_ready: bool
    data_overrun: bool
    overflow: bool

    @property
    def valid(self) -> bool:
        """False when the sensor overflowed (HOFL)."""
        return not self.overflow


def parse_ak09916_block(data: bytes | Sequence[int]) -> MagSample:
    """Convert the 9 bytes ST1, HXL..HZH, TMPS, ST2 (from 0x10) to a :class:`MagSample`.

    Works for both paths: the bypass burst read of 9 bytes from 0x0C:0x10, and
    EXT_SLV_SENS_DATA_00..08 filled by SLV0 (docs/devices.md §4.5-4.7). Data are int16
    little-endian; 0.15 uT/LSB; axes flipped to the accel frame (m_x = hx, m_y = -hy, m_z = -hz).

    Raises ``Icm20948Error``: not 9 bytes."""
    raw_bytes = _as_bytes(data, AK09916_BLOCK_LENGTH, "AK09916 block")
    st1, st2 = raw_bytes[0], raw_bytes[8]
    h = np.frombuffer(raw_bytes[1:7], dtype="<i2").astype(float)
    field_t = np.array([h[0], -h[1], -h[2]]) * AK09916_TESLA_PER_LSB
    return MagSample(magnetic_field_t=field_t, raw=(int(h[0]), int(h[1]), int(h[2])),
                     data_ready=bool(st1 & AK_ST1_DRDY), data_overrun=bool(st1 & AK_ST1_DOR),
                     overflow=bool(st2 & AK_ST2_HOFL))


def _vector3(value: Sequence[float] | np.ndarray, what: str) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise Icm20948Error(f"{what} must be 3 finite numbers, got {value!r}")
    return arr


def _to_int16(scaled: np.ndarray) -> tuple[int, ...]:
    return tuple(int(v) for v in np.clip(np.rint(scaled), -32768, 32767))


def accel_to_raw(specific_force_m_s2: Sequence[float], fs_sel: int) -> tuple[int, int, int]:
    """Device side: round(a/g * LSB_per_g), clamped to int16 (docs/devices.md §4.8 item 3)."""
    f = _vector3(specific_force_m_s2, "specific_force_m_s2")
    return _to_int16(f / GRAVITY_M_S2 * ACCEL_LSB_PER_G[fs_sel])  # type: ignore[return-value]


def gyro_to_raw(angular_rate_rad_s: Sequence[float], fs_sel: int) -> tuple[int, int, int]:
    """Device side: round(w_dps * LSB_per_dps), clamped to int16 (docs/devices.md §4.8 item 3)."""
    w = _vector3(angular_rate_rad_s, "angular_rate_rad_s")
    return _to_int16(np.degrees(w) * GYRO_LSB_PER_DPS[fs_sel])  # type: ignore[return-value]


def temperature_to_raw(temperature_c: float) -> int:
    """Device side: round((T - 21) * 333.87), clamped to int16 (docs/devices.md §4.8 item 3)."""
    if not math.isfinite(temperature_c):
        raise Icm20948Error(f"temperature_c must be finite, got {temperature_c}")
    return _to_int16(np.array([(temperature_c - TEMP_OFFSET_C) * TEMP_SENSITIVITY_LSB_PER_C]))[0]


def mag_to_raw(magnetic_field_t: Sequence[float]) -> tuple[tuple[int, int, int], bool]:
    """Device side: accel-frame field (T) -> AK09916 counts (hx, hy, hz) and overflow flag.

    hx = Bx, hy = -By, hz = -Bz (docs/devices.md §4.7); counts = round(B_uT / 0.15) clamped to
    +-32752; overflow (HOFL) when any axis had to be clamped (docs/devices.md §4.8 item 4).
    """
    b = _vector3(magnetic_field_t, "magnetic_field_t")
    counts = np.rint(np.array([b[0], -b[1], -b[2]]) / AK09916_TESLA_PER_LSB)
    overflow = bool(np.any(np.abs(counts) > AK09916_MAX_COUNTS))
    clipped = np.clip(counts, -AK09916_MAX_COUNTS, AK09916_MAX_COUNTS)
    return tuple(int(v) for v in clipped), overflow  # type: ignore[return-value]
