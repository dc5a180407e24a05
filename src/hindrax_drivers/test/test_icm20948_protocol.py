"""ICM-20948 / AK09916 protocol and emulator tests. Expected register addresses, bit positions,
scale factors and sequences are those of docs/devices.md §4."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from hindrax_drivers.icm20948 import protocol as icm
from hindrax_drivers.icm20948.core import BankedRegisters
from hindrax_drivers.icm20948.emulator import Ak09916Emulator, Icm20948Emulator
from hindrax_common.transport.emulated_i2c import EmulatedI2CBus, ManualClock
from hindrax_common.transport.i2c import I2CDevice

G = 9.80665


# ----------------------------------------------------------------------------- register map (§4.1-4.2)
def test_register_map_matches_devices_doc():
    assert (icm.ADDRESS_AD0_LOW, icm.ADDRESS_AD0_HIGH, icm.WHO_AM_I_VALUE) == (0x68, 0x69, 0xEA)
    expected = {
        "WHO_AM_I": (0, 0x00), "USER_CTRL": (0, 0x03), "LP_CONFIG": (0, 0x05), "PWR_MGMT_1": (0, 0x06),
        "PWR_MGMT_2": (0, 0x07), "INT_PIN_CFG": (0, 0x0F), "INT_ENABLE_1": (0, 0x11),
        "I2C_MST_STATUS": (0, 0x17), "INT_STATUS_1": (0, 0x1A),
        "ACCEL_XOUT_H": (0, 0x2D), "GYRO_XOUT_H": (0, 0x33), "TEMP_OUT_H": (0, 0x39),
        "EXT_SLV_SENS_DATA_00": (0, 0x3B),
        "GYRO_SMPLRT_DIV": (2, 0x00), "GYRO_CONFIG_1": (2, 0x01),
        "ACCEL_SMPLRT_DIV_1": (2, 0x10), "ACCEL_SMPLRT_DIV_2": (2, 0x11), "ACCEL_CONFIG": (2, 0x14),
        "I2C_MST_CTRL": (3, 0x01), "I2C_SLV4_ADDR": (3, 0x13), "I2C_SLV4_REG": (3, 0x14),
        "I2C_SLV4_CTRL": (3, 0x15), "I2C_SLV4_DO": (3, 0x16), "I2C_SLV4_DI": (3, 0x17),
    }
    for name, (bank, address) in expected.items():
        reg = getattr(icm, name)
        assert (reg.bank, reg.address) == (bank, address), name
    assert icm.REG_BANK_SEL_ADDRESS == 0x7F
    assert [icm.bank_select_value(b) for b in range(4)] == [0x00, 0x10, 0x20, 0x30]
    assert [tuple(r.address for r in icm.slave_registers(n)) for n in range(4)] == [
        (0x03, 0x04, 0x05, 0x06), (0x07, 0x08, 0x09, 0x0A), (0x0B, 0x0C, 0x0D, 0x0E), (0x0F, 0x10, 0x11, 0x12)]
    assert (icm.USER_CTRL_I2C_MST_EN, icm.USER_CTRL_I2C_IF_DIS, icm.PWR_MGMT_1_SLEEP,
            icm.PWR_MGMT_1_DEVICE_RESET, icm.INT_PIN_CFG_BYPASS_EN) == (0x20, 0x10, 0x40, 0x80, 0x02)
    with pytest.raises(icm.Icm20948Error):
        icm.bank_select_value(4)
    with pytest.raises(icm.Icm20948Error):
        icm.slave_registers(4)


def test_ak09916_registers():
    assert (icm.AK09916_ADDRESS, icm.AK09916_WIA1_VALUE, icm.AK09916_WIA2_VALUE) == (0x0C, 0x48, 0x09)
    assert [r.address for r in (icm.AK_ST1, icm.AK_HXL, icm.AK_TMPS, icm.AK_ST2, icm.AK_CNTL2, icm.AK_CNTL3)] \
        == [0x10, 0x11, 0x17, 0x18, 0x31, 0x32]


# ----------------------------------------------------------------------------- configuration (§4.4)
def test_config_register_values():
    cfg = icm.ImuConfig(accel_fs_sel=1, gyro_fs_sel=1, accel_dlpfcfg=3, gyro_dlpfcfg=5,
                        accel_smplrt_div=0x123, gyro_smplrt_div=10)
    # DLPFCFG bits 5:3, FS_SEL bits 2:1, FCHOICE bit 0.
    assert cfg.accel_config_value == 0b00_011_01_1 == 0x1B
    assert cfg.gyro_config_1_value == 0b00_101_01_1 == 0x2B
    assert icm.ImuConfig(accel_dlpfcfg=None, accel_fs_sel=3).accel_config_value == 0b110
    assert cfg.gyro_odr_hz == pytest.approx(102.27, abs=0.01)   # div 10 (docs/devices.md §4.4)
    assert cfg.accel_lsb_per_g == 8192 and cfg.gyro_lsb_per_dps == 65.5
    decoded = icm.ImuConfig.from_registers(10, 0x2B, 0x01, 0x23, 0x1B)
    assert decoded == cfg
    with pytest.raises(icm.Icm20948Error):
        icm.ImuConfig(accel_fs_sel=4)
    with pytest.raises(icm.Icm20948Error):
        icm.ImuConfig(gyro_smplrt_div=256)


def test_output_data_rates():
    assert icm.accel_odr_hz(0, 1) == 1125.0
    assert icm.accel_odr_hz(4, 1) == 225.0
    assert icm.accel_odr_hz(4, 0) == 4500.0           # DLPF bypassed
    assert icm.gyro_odr_hz(4, 1, 3) == 225.0
    assert icm.gyro_odr_hz(4, 1, 0) == 1125.0         # divider ignored for DLPFCFG 0 and 7
    assert icm.gyro_odr_hz(4, 1, 7) == 1125.0


# ----------------------------------------------------------------------------- conversions (§4.4, §4.5, §4.7)
def test_parse_sensor_block():
    raw = bytes([0x40, 0x00, 0xE0, 0x00, 0x00, 0x00,      # accel 16384, -8192, 0
                 0x00, 0x83, 0xFF, 0x7D, 0x7F, 0xFF,      # gyro 131, -131, 32767
                 0x0D, 0x0B])                             # temp 3339
    s = icm.parse_sensor_block(raw, icm.ImuConfig())
    np.testing.assert_allclose(s.accel_m_s2, [G, -G / 2, 0.0])
    np.testing.assert_allclose(s.gyro_rad_s, [math.radians(1), -math.radians(1), math.radians(32767 / 131)])
    assert s.temperature_c == pytest.approx(3339 / 333.87 + 21)
    assert s.accel_raw == (16384, -8192, 0) and s.temp_raw == 3339
    assert s.gyro_saturated and not s.accel_saturated
    s16 = icm.parse_sensor_block(raw, icm.ImuConfig(accel_fs_sel=3, gyro_fs_sel=3))
    np.testing.assert_allclose(s16.accel_m_s2[0], 8 * G)
    np.testing.assert_allclose(s16.gyro_rad_s[0], math.radians(131 / 16.4))
    with pytest.raises(icm.Icm20948Error):
        icm.parse_sensor_block(raw[:13], icm.ImuConfig())


def test_parse_ak09916_block_flips_axes_to_accel_frame():
    block = bytes([0x01, 0x64, 0x00, 0x38, 0xFF, 0x2C, 0x01, 0x00, 0x00])   # hx 100, hy -200, hz 300
    m = icm.parse_ak09916_block(block)
    assert m.raw == (100, -200, 300)
    np.testing.assert_allclose(m.magnetic_field_t, [15e-6, 30e-6, -45e-6])
    assert m.data_ready and not m.data_overrun and m.valid
    m2 = icm.parse_ak09916_block(bytes([0x02]) + block[1:8] + bytes([0x08]))
    assert not m2.data_ready and m2.data_overrun and m2.overflow and not m2.valid
    with pytest.raises(icm.Icm20948Error):
        icm.parse_ak09916_block(block[:8])


@given(st.binary(max_size=30))
def test_parsers_raise_only_declared_error(data):
    for parse in (lambda d: icm.parse_sensor_block(d, icm.ImuConfig()), icm.parse_ak09916_block):
        try:
            parse(data)
        except icm.Icm20948Error:
            pass


def test_device_side_quantisation():
    assert icm.accel_to_raw([0.0, 0.0, G], 0) == (0, 0, 16384)
    assert icm.accel_to_raw([3 * G, -3 * G, 0.0], 0) == (32767, -32768, 0)      # clamped
    assert icm.gyro_to_raw([math.radians(250), 0.0, 0.0], 0) == (32750, 0, 0)
    assert icm.temperature_to_raw(21.0) == 0
    assert icm.temperature_to_raw(31.0) == round(10 * 333.87)
    assert icm.mag_to_raw([15e-6, 30e-6, -45e-6]) == ((100, -200, 300), False)
    assert icm.mag_to_raw([5000e-6, 0.0, 0.0]) == ((32752, 0, 0), True)       # HOFL
    assert icm.mag_to_raw([4912e-6, 0.0, 0.0])[1] is False
    with pytest.raises(icm.Icm20948Error):
        icm.accel_to_raw([0.0, float("nan"), 0.0], 0)


@settings(max_examples=100, deadline=None)
@given(st.lists(st.floats(-15 * G, 15 * G), min_size=3, max_size=3),
       st.lists(st.floats(-30.0, 30.0), min_size=3, max_size=3),
       st.floats(-40.0, 85.0), st.integers(0, 3))
@example([0.0, 0.0, 0.0], [0.0, 0.0, 17.4375], 0.0, 2)   # 999.1 dps: nominal range, past int16 (clamps)
def test_quantisation_round_trip(accel, gyro, temperature, fs):
    cfg = icm.ImuConfig(accel_fs_sel=3, gyro_fs_sel=fs)
    # the 14 bytes at 0x2D..0x3A, int16 big-endian (docs/devices.md §4.2)
    block = np.asarray([*icm.accel_to_raw(accel, 3), *icm.gyro_to_raw(gyro, fs),
                        icm.temperature_to_raw(temperature)], dtype=">i2").tobytes()
    s = icm.parse_sensor_block(block, cfg)
    np.testing.assert_allclose(s.accel_m_s2, accel, atol=0.5 * G / 2048 + 1e-9)
    gyro_lsb = math.radians(1 / icm.GYRO_LSB_PER_DPS[fs])
    # In range = representable in int16 (32767 counts is 998.99 dps at fs=2, below the nominal 1000 dps);
    # beyond it the device clamps (docs/devices.md §4.8 item 3), checked in test_device_side_quantisation.
    in_range = np.abs(np.degrees(gyro)) * icm.GYRO_LSB_PER_DPS[fs] < 32767.5
    np.testing.assert_allclose(s.gyro_rad_s[in_range], np.asarray(gyro)[in_range], atol=0.5 * gyro_lsb + 1e-9)
    assert abs(s.temperature_c - temperature) <= 0.5 / 333.87 + 1e-9


# ----------------------------------------------------------------------------- emulator (§4.8)
def truth(t):
    return [0.5, -0.25, G], [0.1, 0.2, -0.3], [20e-6, 5e-6, -40e-6], 25.0


def make(clock=None):
    clock = clock or ManualClock(2.0)
    emu = Icm20948Emulator(truth, clock)
    bus = EmulatedI2CBus({0x68: emu, 0x0C: emu.aux_port})
    return clock, emu, bus


def test_emulator_banks_and_reset_values():
    clock, emu, bus = make()
    assert bus.read_byte_data(0x68, 0x00) == 0xEA
    assert bus.read_byte_data(0x68, 0x06) == 0x41       # PWR_MGMT_1: asleep, CLKSEL 1
    assert bus.read_byte_data(0x68, 0x05) == 0x40       # LP_CONFIG
    bus.write_byte_data(0x68, 0x7F, 0x20)
    assert bus.read_byte_data(0x68, 0x7F) == 0x20 and emu.bank == 2
    assert bus.read_byte_data(0x68, 0x14) == 0x01       # ACCEL_CONFIG
    assert bus.read_byte_data(0x68, 0x01) == 0x01       # GYRO_CONFIG_1 [UNVERIFIED]
    assert bus.read_byte_data(0x68, 0x00) == 0x00       # bank 2 0x00 is GYRO_SMPLRT_DIV, not WHO_AM_I
    bus.write_byte_data(0x68, 0x00, 9)
    bus.write_byte_data(0x68, 0x7F, 0x00)
    bus.write_byte_data(0x68, 0x00, 0x12)               # WHO_AM_I is read-only
    assert bus.read_byte_data(0x68, 0x00) == 0xEA
    bus.write_byte_data(0x68, 0x06, 0x01)
    bus.write_byte_data(0x68, 0x7F, 0x20)
    bus.write_byte_data(0x68, 0x06, 0x80)               # bank 2 0x06 is not PWR_MGMT_1: no reset
    assert emu.register_value(icm.GYRO_SMPLRT_DIV) == 9
    bus.write_byte_data(0x68, 0x7F, 0x00)
    bus.write_byte_data(0x68, 0x06, 0x80)               # DEVICE_RESET
    assert emu.bank == 0 and bus.read_byte_data(0x68, 0x06) == 0x41
    assert emu.register_value(icm.GYRO_SMPLRT_DIV) == 0


def test_emulator_data_follow_config_and_sleep():
    clock, emu, bus = make()
    assert bytes(bus.read_i2c_block_data(0x68, 0x2D, 14)) == bytes(14)   # asleep after reset
    bus.write_byte_data(0x68, 0x06, 0x01)
    clock.advance(0.01)
    s = icm.parse_sensor_block(bytes(bus.read_i2c_block_data(0x68, 0x2D, 14)), icm.ImuConfig(0, 0))
    assert s.accel_raw == (round(0.5 / G * 16384), round(-0.25 / G * 16384), 16384)
    assert s.gyro_raw == tuple(round(math.degrees(w) * 131) for w in (0.1, 0.2, -0.3))
    assert s.temp_raw == round(4 * 333.87)
    assert bus.read_byte_data(0x68, 0x1A) == 0x01       # RAW_DATA_0_RDY ...
    assert bus.read_byte_data(0x68, 0x1A) == 0x00       # ... clears on read
    bus.write_byte_data(0x68, 0x7F, 0x20)
    bus.write_byte_data(0x68, 0x14, (1 << 3) | (3 << 1) | 1)   # +-16 g
    bus.write_byte_data(0x68, 0x7F, 0x00)
    clock.advance(0.01)
    assert icm.parse_sensor_block(bytes(bus.read_i2c_block_data(0x68, 0x2D, 14)),
                                  icm.ImuConfig(3, 0)).accel_raw[2] == 2048
    bus.write_byte_data(0x68, 0x06, 0x41)               # sleep: data freeze
    emu.truth = lambda t: ([0, 0, -G], [0, 0, 0], [0, 0, 0], 0.0)
    clock.advance(0.1)
    assert icm.parse_sensor_block(bytes(bus.read_i2c_block_data(0x68, 0x2D, 14)),
                                  icm.ImuConfig(3, 0)).accel_raw[2] == 2048
    bus.write_byte_data(0x68, 0x06, 0x01)
    emu.stuck = True
    clock.advance(0.1)
    assert icm.parse_sensor_block(bytes(bus.read_i2c_block_data(0x68, 0x2D, 14)),
                                  icm.ImuConfig(3, 0)).accel_raw[2] == 2048
    emu.stuck = False
    clock.advance(0.1)
    assert icm.parse_sensor_block(bytes(bus.read_i2c_block_data(0x68, 0x2D, 14)),
                                  icm.ImuConfig(3, 0)).accel_raw[2] == -2048


def test_emulator_rejects_bad_address():
    with pytest.raises(ValueError):
        Icm20948Emulator(truth, address=0x70)


def test_ak09916_register_file_auto_increment_and_modes():
    clock = ManualClock(0.0)
    ak = Ak09916Emulator(lambda t: truth(t)[2], clock)
    bus = EmulatedI2CBus({0x0C: ak})
    # 00 -> 01 -> 02 -> 03 -> 10 (ST1) -> 11 ...
    assert bytes(bus.read_i2c_block_data(0x0C, 0x00, 6)) == bytes([0x48, 0x09, 0, 0, 0, 0])
    bus.write_byte_data(0x0C, 0x31, 0x08)               # continuous 100 Hz
    assert ak.mode == 0x08 and bus.read_byte_data(0x0C, 0x31) == 0x08
    clock.advance(0.0101)
    block = bytes(bus.read_i2c_block_data(0x0C, 0x10, 9))
    m = icm.parse_ak09916_block(block)
    assert m.data_ready and not m.data_overrun
    np.testing.assert_allclose(m.magnetic_field_t, truth(0)[2], atol=0.075e-6)
    # ST2 -> wraps to 0x00 (WIA1).
    assert bus.read_byte(0x0C) == 0x48
    clock.advance(0.035)                                # three measurements, none read: DOR
    st1 = bus.read_byte_data(0x0C, 0x10)
    assert st1 == 0x03
    # Read a data register without ST2: the lock keeps the data and the next one is skipped.
    bus.read_i2c_block_data(0x0C, 0x11, 2)
    assert bus.read_byte_data(0x0C, 0x10) == 0x00       # data read cleared DRDY/DOR
    clock.advance(0.01)
    assert bus.read_byte_data(0x0C, 0x10) == 0x02       # skipped during lock: DOR, no DRDY
    bus.read_byte_data(0x0C, 0x18)                      # ST2 ends the lock
    clock.advance(0.01)
    assert bus.read_byte_data(0x0C, 0x10) & 0x01
    # CNTL3 soft reset: power-down, CNTL3 reads back 0.
    bus.write_byte_data(0x0C, 0x32, 0x01)
    assert ak.mode == 0 and bus.read_byte_data(0x0C, 0x32) == 0
    # CNTL2..CNTL3 wrap to 0x30.
    assert bytes(bus.read_i2c_block_data(0x0C, 0x31, 3)) == bytes([0, 0, 0])
    # Single measurement: DRDY after the measurement time, then power-down.
    bus.write_byte_data(0x0C, 0x31, 0x01)
    assert bus.read_byte_data(0x0C, 0x10) == 0x00
    clock.advance(0.011)
    assert bus.read_byte_data(0x0C, 0x10) == 0x01 and ak.mode == 0


def test_ak09916_overflow_sets_hofl():
    clock = ManualClock(0.0)
    ak = Ak09916Emulator(lambda t: [6000e-6, 0.0, 0.0], clock)
    bus = EmulatedI2CBus({0x0C: ak})
    bus.write_byte_data(0x0C, 0x31, 0x02)
    clock.advance(0.1)
    m = icm.parse_ak09916_block(bytes(bus.read_i2c_block_data(0x0C, 0x10, 9)))
    assert m.overflow and m.raw[0] == 32752


def master_setup(bus, clock, emu):
    bus.write_byte_data(0x68, 0x06, 0x01)
    regs = BankedRegisters(I2CDevice(bus, 0x68, "icm20948", backoff_s=0.0))  # the driver's register access
    for w in icm.mag_master_sequence(icm.ImuConfig()):
        regs.write(w.register, w.value)
        clock.advance(w.delay_after_s)
    bus.write_byte_data(0x68, 0x7F, 0x00)


def test_i2c_master_slv0_read_and_byte_swap():
    clock, emu, bus = make()
    master_setup(bus, clock, emu)
    assert emu.magnetometer.mode == 0x08
    clock.advance(0.02)
    m = icm.parse_ak09916_block(bytes(bus.read_i2c_block_data(0x68, 0x3B, 9)))
    np.testing.assert_allclose(m.magnetic_field_t, truth(0)[2], atol=0.075e-6)
    # BYTE_SW with GRP = 0 starting at odd register 0x11: pairs start at even addresses (0x12, 0x13)...
    bus.write_byte_data(0x68, 0x7F, 0x30)
    bus.write_i2c_block_data(0x68, 0x03, [0x8C, 0x11, 0x80 | 0x40 | 6])
    bus.write_byte_data(0x68, 0x7F, 0x00)
    clock.advance(0.02)
    swapped = bytes(bus.read_i2c_block_data(0x68, 0x3B, 6))
    hx, hy, hz = m.raw
    plain = np.asarray([hx, hy, hz], dtype="<i2").tobytes()
    assert swapped == plain[0:1] + plain[2:3] + plain[1:2] + plain[4:5] + plain[3:4] + plain[5:6]


def test_i2c_master_slv4_and_nack():
    clock, emu, bus = make()
    bus.write_byte_data(0x68, 0x06, 0x01)
    bus.write_byte_data(0x68, 0x03, 0x20)               # I2C_MST_EN
    bus.write_byte_data(0x68, 0x7F, 0x30)
    bus.write_i2c_block_data(0x68, 0x13, [0x8C, 0x01, 0x80])   # SLV4 read WIA2
    assert bus.read_byte_data(0x68, 0x17) == 0x09       # SLV4_DI
    assert bus.read_byte_data(0x68, 0x15) & 0x80 == 0   # EN self-clears
    bus.write_byte_data(0x68, 0x7F, 0x00)
    assert bus.read_byte_data(0x68, 0x17) == icm.I2C_MST_STATUS_SLV4_DONE
    assert bus.read_byte_data(0x68, 0x17) == 0          # clears on read
    emu.aux_connected = False
    bus.write_byte_data(0x68, 0x7F, 0x30)
    bus.write_i2c_block_data(0x68, 0x03, [0x8C, 0x10, 0x89])
    bus.write_byte_data(0x68, 0x7F, 0x00)
    clock.advance(0.02)
    assert bus.read_byte_data(0x68, 0x17) & 0x01        # SLV0_NACK


@settings(max_examples=300, deadline=None)
@given(st.binary(min_size=14, max_size=14), st.binary(min_size=9, max_size=9),
       st.lists(st.integers(0, 255), min_size=5, max_size=5))
def test_any_registers_decode_to_finite_values_or_the_declared_error(block, mag_block, regs):
    try:
        config = icm.ImuConfig.from_registers(*regs)
    except icm.Icm20948Error:
        return
    sample = icm.parse_sensor_block(block, config)
    mag = icm.parse_ak09916_block(mag_block)
    values = np.concatenate([sample.accel_m_s2, sample.gyro_rad_s, [sample.temperature_c], mag.magnetic_field_t])
    assert np.all(np.isfinite(values))
    assert mag.data_ready == bool(mag_block[0] & 0x01) and mag.overflow == bool(mag_block[8] & 0x08)
