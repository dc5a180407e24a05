"""Tests of the emulated I2C bus, the I2CDevice helper, and driver-style round trips through the
MS5837 and ICM-20948 emulators (docs/architecture.md §2; docs/devices.md §3, §4)."""

from __future__ import annotations

import errno
import math
import threading

import numpy as np
import pytest
from smbus2 import i2c_msg

from hindrax_drivers.icm20948 import protocol as icm
from hindrax_drivers.icm20948.core import BankedRegisters, imu_config_from_settings
from hindrax_drivers.icm20948.emulator import Icm20948Emulator
from hindrax_drivers.ms5837 import protocol as ms
from hindrax_drivers.ms5837.emulator import Ms5837Emulator
from hindrax_common.transport.emulated_i2c import (EmulatedI2CBus, ManualClock,
                                                    RegisterPointerEmulator)
from hindrax_common.transport.i2c import I2CDevice, I2CError, RegisterWrite


class RecordingDevice:
    """Logs every transaction; reads return a counter pattern."""

    def __init__(self) -> None:
        self.log: list[tuple[str, object]] = []
        self.general_calls: list[bytes] = []

    def i2c_write(self, data: bytes) -> None:
        self.log.append(("w", bytes(data)))

    def i2c_read(self, n: int) -> bytes:
        self.log.append(("r", n))
        return bytes((0xA0 + i) & 0xFF for i in range(n))


class Memory(RegisterPointerEmulator):
    """Plain 256-byte register file with auto-increment."""

    def __init__(self) -> None:
        super().__init__()
        self.regs = bytearray(256)

    def _read_register(self, register: int) -> int:
        return self.regs[register]

    def _write_register(self, register: int, value: int) -> None:
        self.regs[register] = value


class FlakyDevice(Memory):
    """Fails the first ``failures`` transactions with errno 121 (NACK)."""

    def __init__(self, failures: int) -> None:
        super().__init__()
        self.failures = failures

    def _begin_transaction(self) -> None:
        if self.failures > 0:
            self.failures -= 1
            raise OSError(errno.EREMOTEIO, "Remote I/O error")


# ----------------------------------------------------------------------------- bus semantics
def test_smbus_calls_decompose_into_i2c_transactions():
    dev = RecordingDevice()
    bus = EmulatedI2CBus({0x20: dev})
    bus.write_byte(0x20, 0x1E)
    assert bus.read_byte(0x20) == 0xA0
    bus.write_byte_data(0x20, 0x06, 0x55)
    assert bus.read_byte_data(0x20, 0x07) == 0xA0
    bus.write_word_data(0x20, 0x08, 0x1234)
    # SMBus words are little-endian: first byte read is the low byte.
    assert bus.read_word_data(0x20, 0xA0) == 0xA1A0
    bus.write_i2c_block_data(0x20, 0x10, [1, 2, 3])
    assert bus.read_i2c_block_data(0x20, 0x00, 3) == [0xA0, 0xA1, 0xA2]
    bus.write_quick(0x20)
    assert dev.log == [
        ("w", b"\x1e"), ("r", 1),
        ("w", b"\x06\x55"),
        ("w", b"\x07"), ("r", 1),
        ("w", b"\x08\x34\x12"),
        ("w", b"\xa0"), ("r", 2),
        ("w", b"\x10\x01\x02\x03"),
        ("w", b"\x00"), ("r", 3),
        ("w", b""),
    ]


def test_i2c_rdwr_fills_read_messages_in_place():
    mem = Memory()
    mem.regs[0x40:0x48] = bytes(range(10, 18))
    bus = EmulatedI2CBus({0x33: mem})
    write = i2c_msg.write(0x33, [0x40])
    read = i2c_msg.read(0x33, 8)
    bus.i2c_rdwr(write, read)
    assert bytes(read) == bytes(range(10, 18))
    bus.i2c_rdwr(i2c_msg.write(0x33, [0x01, 0xAA, 0xBB]))
    assert mem.regs[0x01:0x03] == b"\xaa\xbb"


def test_unknown_address_is_remote_io_error_121():
    bus = EmulatedI2CBus({0x20: Memory()})
    with pytest.raises(OSError) as info:
        bus.read_byte_data(0x21, 0x00)
    assert info.value.errno == 121 == errno.EREMOTEIO


def test_argument_checks_match_smbus2():
    bus = EmulatedI2CBus({0x20: Memory()})
    with pytest.raises(ValueError):
        bus.read_i2c_block_data(0x20, 0, 33)
    with pytest.raises(ValueError):
        bus.write_i2c_block_data(0x20, 0, bytes(33))
    with pytest.raises(ValueError):
        bus.write_byte_data(0x20, 0, 256)
    with pytest.raises(ValueError):
        bus.read_byte(0x80)


def test_close_and_context_manager():
    with EmulatedI2CBus({0x20: Memory()}) as bus:
        bus.write_byte_data(0x20, 1, 2)
    with pytest.raises(OSError) as info:
        bus.read_byte_data(0x20, 1)
    assert info.value.errno == errno.EBADF
    bus.open(1)
    assert bus.read_byte_data(0x20, 1) == 2


def test_fault_injection_rate_is_seeded_and_reproducible():
    def pattern(seed: int) -> list[bool]:
        bus = EmulatedI2CBus({0x20: Memory()}, fault_rate=0.3, seed=seed)
        out = []
        for _ in range(1000):
            try:
                bus.read_byte_data(0x20, 0)
                out.append(True)
            except OSError as exc:
                assert exc.errno == 121
                out.append(False)
        assert bus.injected_faults == out.count(False)
        return out

    first = pattern(7)
    assert first == pattern(7)
    failures = first.count(False)
    # Binomial(1000, 0.3): mean 300, sd 14.5; +-5 sd.
    assert 227 < failures < 373
    with pytest.raises(ValueError):
        EmulatedI2CBus(fault_rate=1.5)


def test_disconnect_switches():
    bus = EmulatedI2CBus({0x20: Memory(), 0x21: Memory()})
    bus.disconnected = True
    for address in (0x20, 0x21):
        with pytest.raises(OSError) as info:
            bus.read_byte_data(address, 0)
        assert info.value.errno == 121
    bus.disconnected = False
    bus.set_device_connected(0x21, False)
    assert bus.read_byte_data(0x20, 0) == 0
    with pytest.raises(OSError):
        bus.read_byte_data(0x21, 0)
    bus.set_device_connected(0x21, True)
    assert bus.read_byte_data(0x21, 0) == 0


def test_general_call_reaches_devices_that_handle_it():
    dev = RecordingDevice()
    dev.i2c_general_call = dev.general_calls.append  # type: ignore[attr-defined]
    bus = EmulatedI2CBus({0x40: dev})
    bus.write_byte(0x00, 0x06)
    assert dev.general_calls == [b"\x06"]
    with pytest.raises(OSError):
        EmulatedI2CBus({0x20: Memory()}).write_byte(0x00, 0x06)


def test_bus_calls_from_threads_do_not_interleave_within_a_call():
    dev = RecordingDevice()
    bus = EmulatedI2CBus({0x20: dev})

    def worker(register: int) -> None:
        for _ in range(200):
            bus.read_i2c_block_data(0x20, register, 2)

    threads = [threading.Thread(target=worker, args=(r,)) for r in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=20.0)
        assert not t.is_alive()
    assert len(dev.log) == 4 * 200 * 2
    for i in range(0, len(dev.log), 2):
        assert dev.log[i][0] == "w" and dev.log[i + 1] == ("r", 2)


# ----------------------------------------------------------------------------- I2CDevice
def test_retries_with_backoff_then_success():
    clock = ManualClock()
    bus = EmulatedI2CBus({0x20: FlakyDevice(failures=2)})
    dev = I2CDevice(bus, 0x20, "flaky", retries=3, backoff_s=0.001, sleep=clock.sleep, clock=clock)
    dev.write_byte_data(0x05, 0x77)
    assert dev.read_byte_data(0x05) == 0x77
    assert dev.stats.errors == 2 and dev.stats.retries == 2
    assert dev.stats.transactions == 2 and dev.stats.failures == 0
    assert clock.sleeps == [0.001, 0.002]
    assert "Remote I/O error" in dev.stats.last_error


def test_retries_exhausted_raise_i2c_error_with_errno():
    clock = ManualClock()
    bus = EmulatedI2CBus({0x20: FlakyDevice(failures=100)})
    dev = I2CDevice(bus, 0x20, "dead", retries=3, backoff_s=0.001, sleep=clock.sleep, clock=clock)
    with pytest.raises(I2CError) as info:
        dev.read_block(0x10, 4)
    err = info.value
    assert isinstance(err, OSError) and err.errno == 121
    assert err.attempts == 4 and err.address == 0x20 and err.device_name == "dead"
    assert "dead@0x20" in str(err)
    assert dev.stats.errors == 4 and dev.stats.retries == 3 and dev.stats.failures == 1
    assert clock.sleeps == [0.001, 0.002, 0.004]


def test_unknown_address_fails_through_i2c_device():
    dev = I2CDevice(EmulatedI2CBus(), 0x76, "ms5837", retries=1, backoff_s=0.0)
    with pytest.raises(I2CError) as info:
        dev.write_byte(0x1E)
    assert info.value.errno == 121


def test_value_errors_are_not_retried():
    bus = EmulatedI2CBus({0x20: Memory()})
    dev = I2CDevice(bus, 0x20, "m", sleep=lambda s: None)
    with pytest.raises(ValueError):
        dev.write_byte_data(0x01, 300)
    assert dev.stats.errors == 0 and bus.calls == 0


def test_raw_tap_sees_every_successful_transaction():
    clock = ManualClock(100.0)
    taps: list[tuple] = []
    mem = Memory()
    mem.regs[0x10:0x14] = b"\x01\x02\x03\x04"
    bus = EmulatedI2CBus({0x20: mem})
    dev = I2CDevice(bus, 0x20, "m", raw_tap=lambda *a: taps.append(a), sleep=clock.sleep, clock=clock)
    dev.write_byte(0x10)
    clock.advance(0.5)
    dev.write_byte_data(0x30, 0x99)
    assert dev.read_byte_data(0x30) == 0x99
    dev.write_block(0x40, b"\x05\x06")
    assert dev.read_block(0x10, 4) == b"\x01\x02\x03\x04"
    assert taps == [
        ("write", 0x20, 0x10, b"", 100.0),
        ("write", 0x20, 0x30, b"\x99", 100.5),
        ("read", 0x20, 0x30, b"\x99", 100.5),
        ("write", 0x20, 0x40, b"\x05\x06", 100.5),
        ("read", 0x20, 0x10, b"\x01\x02\x03\x04", 100.5),
    ]
    bus.disconnected = True
    with pytest.raises(I2CError):
        dev.read_byte_data(0x30)
    assert len(taps) == 5


def test_long_transfers_use_i2c_rdwr():
    mem = Memory()
    mem.regs[0:64] = bytes(range(64))
    bus = EmulatedI2CBus({0x20: mem})
    dev = I2CDevice(bus, 0x20, "m", sleep=lambda s: None)
    assert dev.read_block(0x00, 48) == bytes(range(48))
    dev.write_block(0x80, bytes(range(40)))
    assert mem.regs[0x80:0x80 + 40] == bytes(range(40))


def test_write_sequence_applies_delays():
    clock = ManualClock()
    mem = Memory()
    dev = I2CDevice(EmulatedI2CBus({0x20: mem}), 0x20, "m", sleep=clock.sleep, clock=clock)
    dev.write_sequence([RegisterWrite(0x01, 0x11, 0.01), RegisterWrite(0x02, 0x22)])
    assert mem.regs[1:3] == b"\x11\x22"
    assert clock.sleeps == [0.01]
    with pytest.raises(ValueError):
        RegisterWrite(0x100, 0)


# ----------------------------------------------------------------------------- round trips
def read_ms5837(dev: I2CDevice, clock: ManualClock, variant_config: str | None,
                osr: int = 8192) -> ms.Reading:
    """Minimal MS5837 driver built only from the protocol module and I2CDevice (docs/devices.md §3)."""
    dev.write_byte(ms.CMD_RESET)
    clock.sleep(ms.RESET_TIME_S)
    words = [ms.parse_prom_word(dev.read_block(ms.prom_read_command(k), 2)) for k in range(7)]
    calibration = ms.Calibration.from_words(words)
    variant = ms.detect_variant(calibration, variant_config)
    dev.write_byte(ms.convert_d2_command(osr))
    clock.sleep(ms.conversion_time_s(osr))
    d2 = ms.parse_adc(dev.read_block(ms.CMD_ADC_READ, 3))
    dev.write_byte(ms.convert_d1_command(osr))
    clock.sleep(ms.conversion_time_s(osr))
    d1 = ms.parse_adc(dev.read_block(ms.CMD_ADC_READ, 3))
    return ms.compensate(d1, d2, calibration, variant)


@pytest.mark.parametrize("variant, pressure_pa, temperature_c, tol_pa", [
    # 12.5 m; 0.1 mbar LSB -> 5 Pa + ADC step
    ("30BA", 101_300.0 + 997.0 * 9.80665 * 12.5, 14.37, 6.0),
    ("30BA", 101_325.0, -3.2, 6.0),
    ("02BA", 104_321.7, 22.81, 0.6),                       # 0.01 mbar LSB -> 0.5 Pa + ADC step
])
@pytest.mark.parametrize("configured", [True, False])
def test_ms5837_driver_round_trip(variant, pressure_pa, temperature_c, tol_pa, configured):
    clock = ManualClock(5.0)
    emulator = Ms5837Emulator(lambda t: (pressure_pa, temperature_c), clock, variant=variant)
    bus = EmulatedI2CBus({ms.ADDRESS: emulator})
    dev = I2CDevice(bus, ms.ADDRESS, "ms5837", sleep=clock.sleep, clock=clock)
    reading = read_ms5837(dev, clock, variant if configured else None)
    assert abs(reading.pressure_pa - pressure_pa) <= tol_pa
    assert abs(reading.temperature_c - temperature_c) <= 0.01
    assert emulator.zero_reads == 0


def test_ms5837_round_trip_survives_bus_faults_between_transactions():
    clock = ManualClock()
    emulator = Ms5837Emulator(lambda t: (200_000.0, 10.0), clock, variant="30BA")
    bus = EmulatedI2CBus({ms.ADDRESS: emulator}, fault_rate=0.2, seed=3)
    dev = I2CDevice(bus, ms.ADDRESS, "ms5837", retries=10, sleep=clock.sleep, clock=clock)
    reading = read_ms5837(dev, clock, "30BA")
    assert abs(reading.pressure_pa - 200_000.0) <= 6.0
    assert dev.stats.retries == bus.injected_faults > 0


def icm_truth(t: float):
    """Sensor-frame truth: tilted and rotating, with Earth-like field and 31.4 degC."""
    f = np.array([1.234, -0.567, 9.61])
    w = np.array([0.1, -0.25, 0.05 + 0.0 * t])
    b = np.array([21.5e-6, -4.2e-6, -43.7e-6])
    return f, w, b, 31.4


def icm_setup(path: str):
    clock = ManualClock(1.0)
    emulator = Icm20948Emulator(icm_truth, clock)
    devices = {icm.ADDRESS_AD0_LOW: emulator, icm.AK09916_ADDRESS: emulator.aux_port}
    bus = EmulatedI2CBus(devices)
    dev = I2CDevice(bus, icm.ADDRESS_AD0_LOW, "icm20948", sleep=clock.sleep, clock=clock)
    config = imu_config_from_settings(8.0, 500.0, 3, 225.0)  # +-8 g, +-500 dps, DLPFCFG 3
    dev.write_byte_data(icm.REG_BANK_SEL_ADDRESS, icm.bank_select_value(0))
    assert dev.read_byte_data(icm.WHO_AM_I.address) == icm.WHO_AM_I_VALUE
    writes = [*icm.reset_wake_sequence(), *icm.configure_sequence(config)]
    if path == "master":
        writes += icm.mag_master_sequence(config)
    else:
        writes += icm.mag_bypass_sequence()
    regs = BankedRegisters(dev)  # the driver's register access, as its start-up runs the writes
    for w in writes:
        regs.write(w.register, w.value)
        clock.sleep(w.delay_after_s)
    dev.write_byte_data(icm.REG_BANK_SEL_ADDRESS, icm.bank_select_value(0))
    return clock, emulator, bus, dev, config


@pytest.mark.parametrize("path", ["master", "bypass"])
def test_icm20948_driver_round_trip(path):
    clock, emulator, bus, dev, config = icm_setup(path)
    assert config.accel_fs_sel == 2 and config.gyro_fs_sel == 1
    if path == "bypass":
        mag_dev = I2CDevice(bus, icm.AK09916_ADDRESS, "ak09916", sleep=clock.sleep, clock=clock)
        assert mag_dev.read_block(icm.AK_WIA1.address, 2) == bytes([0x48, 0x09])
        mag_dev.write_sequence(icm.ak09916_direct_init_writes(icm.AK_MODE_CONTINUOUS_100HZ))
        clock.sleep(0.011)
        mag = icm.parse_ak09916_block(mag_dev.read_block(icm.AK_ST1.address, icm.AK09916_BLOCK_LENGTH))
        block = dev.read_block(icm.ACCEL_XOUT_H.address, icm.SENSOR_BLOCK_LENGTH)
    else:
        clock.sleep(0.011)  # one 100 Hz magnetometer period, then the next master cycle
        block = dev.read_block(icm.ACCEL_XOUT_H.address, icm.SENSOR_BLOCK_LENGTH + icm.AK09916_BLOCK_LENGTH)
        mag = icm.parse_ak09916_block(block[icm.SENSOR_BLOCK_LENGTH:])
        block = block[:icm.SENSOR_BLOCK_LENGTH]
    sample = icm.parse_sensor_block(block, config)
    f, w, b, temp = icm_truth(clock())
    accel_lsb = icm.GRAVITY_M_S2 / config.accel_lsb_per_g
    gyro_lsb = math.radians(1.0 / config.gyro_lsb_per_dps)
    np.testing.assert_allclose(sample.accel_m_s2, f, atol=0.5 * accel_lsb + 1e-12)
    np.testing.assert_allclose(sample.gyro_rad_s, w, atol=0.5 * gyro_lsb + 1e-12)
    assert abs(sample.temperature_c - temp) <= 0.5 / icm.TEMP_SENSITIVITY_LSB_PER_C + 1e-12
    assert mag.data_ready and not mag.overflow and not mag.data_overrun
    np.testing.assert_allclose(mag.magnetic_field_t, b, atol=0.5 * 0.15e-6 + 1e-15)


def test_icm20948_bypass_port_nacks_unless_bypass_enabled():
    clock, emulator, bus, dev, config = icm_setup("master")
    with pytest.raises(OSError) as info:
        bus.read_byte_data(icm.AK09916_ADDRESS, 0x00)
    assert info.value.errno == 121
