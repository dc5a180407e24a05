"""ICM-20948 start-up core (hindrax_drivers.icm20948.core) against the register-exact emulator, without ROS.

The expected values are the datasheet's and the settings', written out here: DEVICE_RESET then 10 ms, wake then
20 ms (docs/devices.md §4.3); +-4 g -> ACCEL_FS_SEL 1, +-500 dps -> GYRO_FS_SEL 1, 50 Hz -> divider
round(1125 / 50) - 1 = 21, DLPFCFG 4 (docs/devices.md §4.4); the slowest AK09916 continuous mode not below
1125 / 22 = 51.1 Hz is mode 4, 100 Hz, CNTL2 = 0x08 (docs/devices.md §4.5); WHO_AM_I 0xEA, AK09916 WIA 0x48 0x09.
"""
from __future__ import annotations

import numpy as np
import pytest

from hindrax_drivers.icm20948 import protocol as p
from hindrax_drivers.icm20948.core import (MAG_ATTEMPTS, BankedRegisters, DataReadyGate, FrozenBlockWatch,
                                           MagNackFilter, StartupSequence, chip_reset_problems,
                                           imu_config_from_settings, mag_mode_for_rate)
from hindrax_drivers.icm20948.emulator import Icm20948Emulator
from hindrax_drivers.transport.emulated_i2c import EmulatedI2CBus, ManualClock
from hindrax_drivers.transport.i2c import I2CDevice

ADDRESS = 0x69
CONFIG = imu_config_from_settings(4.0, 500.0, 4, 50.0)
EXPECTED_CONFIG = p.ImuConfig(accel_fs_sel=1, gyro_fs_sel=1, accel_dlpfcfg=4, gyro_dlpfcfg=4, accel_smplrt_div=21,
                              gyro_smplrt_div=21)
EXPECTED_MAG_MODE = 0x08  # AK09916 CNTL2 continuous mode 4 (100 Hz)


def truth(t):
    return np.array([0.1, -0.2, 9.8]), np.array([0.01, 0.02, -0.03]), np.array([20e-6, -5e-6, 40e-6]), 25.0


class OtherChip(Icm20948Emulator):
    """An MPU-9250 answering at the address (WHO_AM_I 0x71)."""

    def _read_register(self, register):
        if self._bank == 0 and register == p.WHO_AM_I.address:
            return 0x71
        return super()._read_register(register)


class Rig:
    def __init__(self, mode="i2c_master", chip=Icm20948Emulator, present=True, aux=True, aux_on_bus=True):
        self.clock = ManualClock(100.0)
        self.emu = chip(truth, clock=self.clock, address=ADDRESS)
        self.emu.aux_connected = aux
        self.bus = EmulatedI2CBus()
        if present:
            self.bus.add_device(ADDRESS, self.emu)
            if mode == "bypass" and aux_on_bus:
                self.bus.add_device(p.AK09916_ADDRESS, self.emu.aux_port)
        self.mode = mode
        self.regs = BankedRegisters(I2CDevice(self.bus, ADDRESS, "icm20948", backoff_s=0.0))
        self.mag = I2CDevice(self.bus, p.AK09916_ADDRESS, "ak09916", backoff_s=0.0)
        self.events: list[tuple[bool, str]] = []

    def sequence(self, **kwargs):
        return StartupSequence(self.regs, self.mag, CONFIG, self.mode, mag_mode_for_rate(CONFIG.accel_odr_hz),
                               lambda ok, why: self.events.append((ok, why)), **kwargs)

    def run(self, **kwargs):
        """Advance a sequence to its end, letting the emulator's time pass by each requested wait."""
        seq = self.sequence(**kwargs)
        waits = []
        for _ in range(200):
            result = seq.advance()
            if result.failure is not None or result.done:
                return seq, result, waits
            waits.append(result.wait_s)
            self.clock.advance(result.wait_s)
        raise AssertionError("the start-up never ended")


def test_settings_give_the_datasheet_register_fields():
    assert CONFIG == EXPECTED_CONFIG
    assert mag_mode_for_rate(CONFIG.accel_odr_hz) == EXPECTED_MAG_MODE
    assert mag_mode_for_rate(10.0) == 0x02 and mag_mode_for_rate(20.0) == 0x04 and mag_mode_for_rate(50.0) == 0x06


#: name, Rig arguments, failure text (None: the start-up completes), magnetometer available, reason text
CASES = [
    ("i2c_master", {}, None, True, ""),
    ("i2c_master, AK09916 silent", {"aux": False}, None, False, f"after {MAG_ATTEMPTS} attempts"),
    ("bypass", {"mode": "bypass"}, None, True, ""),
    ("bypass, AK09916 absent", {"mode": "bypass", "aux_on_bus": False}, None, False, "no answer at 0x0c"),
    ("another chip", {"chip": OtherChip}, "WHO_AM_I = 0x71, expected 0xea: not an ICM-20948 at 0x69", None, ""),
    ("no chip", {"present": False}, "start-up I2C failure", None, ""),
]


@pytest.mark.parametrize("name,kwargs,failure,mag,reason", CASES, ids=[c[0] for c in CASES])
def test_startup_table(name, kwargs, failure, mag, reason):
    rig = Rig(**kwargs)
    seq, result, waits = rig.run()
    if failure is not None:
        assert result.failure is not None and failure in result.failure
        assert result.i2c_failure == ("I2C" in failure)
        assert rig.emu.sleeping  # never woken: nothing was configured
        return
    assert result.done and result.failure is None
    assert waits[:2] == [0.010, 0.020]  # DEVICE_RESET, wake
    assert seq.who_am_i == 0xEA
    assert not rig.emu.sleeping and rig.emu.config == EXPECTED_CONFIG
    assert seq.mag_available is mag
    assert rig.events[-1][0] is mag and reason in rig.events[-1][1]
    if kwargs.get("mode") == "bypass":
        assert rig.emu.bypass_active and not rig.emu.master_enabled
        if mag:
            assert rig.emu.magnetometer.mode == EXPECTED_MAG_MODE
    else:
        assert rig.emu.master_enabled
        assert seq.mag_attempt == (1 if mag else MAG_ATTEMPTS)


def test_magnetometer_only_brings_a_returned_ak09916_back_without_resetting_the_chip():
    rig = Rig(aux=False)
    seq, result, _ = rig.run()
    assert result.done and not seq.mag_available
    rig.emu.aux_connected = True
    # a bank-0 register the start-up never writes and a DEVICE_RESET would clear: proof that no reset ran
    rig.regs.write(p.INT_ENABLE_1, 0x01)
    retry = rig.sequence(magnetometer_only=True)
    steps = 0
    while not retry.finished:
        rig.clock.advance(retry.step().wait_s)
        steps += 1
    assert retry.mag_available and rig.events[-1] == (True, "")
    assert steps >= 3 and retry.who_am_i is None  # no identity check: the chip is not started again
    assert rig.emu.register_value(p.INT_ENABLE_1) == 0x01 and rig.emu.config == EXPECTED_CONFIG


def test_a_failed_step_of_the_magnetometer_retry_gives_it_up_without_a_start_up_failure():
    rig = Rig(aux=False)
    rig.run()
    retry = rig.sequence(magnetometer_only=True)
    rig.bus.remove_device(ADDRESS)  # the whole bus goes quiet mid-retry
    result = retry.step()
    assert result.done and retry.finished and result.failure is None
    assert rig.events[-1][0] is False and "re-initialisation failed" in rig.events[-1][1]
    assert rig.regs.bank is None  # the failed transfer left the bank unknown


class RecordingDevice:
    address = ADDRESS

    def __init__(self):
        self.writes: list[tuple[int, int]] = []

    def write_byte_data(self, register, value):
        self.writes.append((register, value))

    def read_block(self, register, length):
        return bytes(length)


def test_banked_registers_select_a_bank_only_when_it_changes_or_is_unknown():
    dev = RecordingDevice()
    regs = BankedRegisters(dev)
    regs.read(p.WHO_AM_I)            # bank 0: selected
    regs.read(p.WHO_AM_I)            # still bank 0: no selection
    regs.write(p.GYRO_CONFIG_1, 1)   # bank 2
    regs.invalidate()
    regs.write(p.GYRO_CONFIG_1, 1)   # unknown: selected again
    regs.write(p.PWR_MGMT_1, p.PWR_MGMT_1_DEVICE_RESET)  # bank 0, and the reset makes the bank unknown
    regs.read(p.WHO_AM_I)
    bank_writes = [v for r, v in dev.writes if r == 0x7F]
    assert bank_writes == [0x00, 0x20, 0x20, 0x00, 0x00]  # REG_BANK_SEL bits 5:4 (docs/devices.md §4.1)


# ---------------------------------------------------------------------------------------------- per-poll decisions
A, B = bytes(range(1, 15)), bytes(range(2, 16))  # two different non-zero 14-byte sensor blocks
ZERO = bytes(14)


@pytest.mark.parametrize("blocks,expected", [
    ([A, B, A, B], [None, None, None, None]),          # a live sensor
    ([A, A, A, A], [None, None, None, "frozen"]),      # the third repeat with frozen_check_samples 3
    ([A, A, B, B, B, B], [None, None, None, None, None, "frozen"]),
    ([A, ZERO, ZERO], [None, "zero", "zero"]),         # the reset value of every data register
    ([A, A, A, A, A], [None, None, None, "frozen", None]),  # once per run of repeats
])
def test_frozen_block_watch(blocks, expected):
    watch = FrozenBlockWatch(3)
    assert [watch.update(b) for b in blocks] == expected


@pytest.mark.parametrize("state,master,problems", [
    (bytes([0x20, 0, 0x40, 0x01]), True, []),                                        # I2C master on, awake
    (bytes([0x00, 0, 0x40, 0x41]), True, ["PWR_MGMT_1 = 0x41 (asleep)", "USER_CTRL = 0x00 (I2C master off)"]),
    (bytes([0x00, 0, 0x40, 0x41]), False, ["PWR_MGMT_1 = 0x41 (asleep)"]),           # bypass: master off is right
    (bytes([0x00, 0, 0x40, 0x01]), True, ["USER_CTRL = 0x00 (I2C master off)"]),
])
def test_chip_reset_problems_from_the_read_back(state, master, problems):
    """PWR_MGMT_1 0x41 = the reset value (SLEEP, CLKSEL 1); USER_CTRL bit 5 = I2C_MST_EN (docs/devices.md §4.3)."""
    assert chip_reset_problems(state, master) == problems


@pytest.mark.parametrize("flags,publish,raised_at,cleared_at", [
    ([True, None, True], [True, True, True], [], []),
    ([False, False, True], [False, False, True], [], []),                     # below the 3 polls: no ERROR
    ([False, False, False, False, True], [False] * 4 + [True], [2], [4]),    # ERROR at the 3rd, cleared by a sample
    ([False, False, False, None], [False] * 3 + [True], [2], [3]),           # an unknown flag publishes and clears
])
def test_data_ready_gate(flags, publish, raised_at, cleared_at):
    gate = DataReadyGate(3)
    verdicts = [gate.update(f) for f in flags]
    assert [v.publish for v in verdicts] == publish
    assert [i for i, v in enumerate(verdicts) if v.raise_error] == raised_at
    assert [i for i, v in enumerate(verdicts) if v.clear_error] == cleared_at


def test_mag_nack_filter_drops_the_block_held_since_the_nack_until_it_changes():
    old, new = bytes([1] * 9), bytes([2] * 9)
    f = MagNackFilter()
    assert f.update(old, nack=False) == old
    assert f.update(old, nack=True) is None        # NACK: the block is the sample of before
    assert f.update(old, nack=False) is None       # the same block re-read between two master cycles
    assert f.update(new, nack=False) == new        # the AK09916 answered again
    assert f.update(new, nack=False) == new
