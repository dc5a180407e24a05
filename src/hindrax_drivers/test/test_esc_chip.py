"""The ESC's PCA9685 at the register level (pca9685/chip.py) on the register-exact emulator, without ROS."""
from __future__ import annotations

import numpy as np
import pytest

from hindrax_drivers.pca9685.chip import EscChip, channel_runs
from hindrax_drivers.pca9685.emulator import Pca9685Emulator
from hindrax_common.transport.emulated_i2c import EmulatedI2CBus
from hindrax_common.transport.i2c import I2CDevice, I2CError

COUNT_US = 1.24  # prescale 30 at 25 MHz (datasheet §7.3.5)


class _Raw:
    def begin_batch(self):
        pass

    def flush(self):
        pass


def _chip(emu=None):
    emu = emu or Pca9685Emulator()
    bus = EmulatedI2CBus({0x40: emu})
    chip = EscChip(0x40, 30, 25e6, range(8), 8, _Raw(), I2CDevice(bus, 0x40, "pca9685"))
    return chip, emu, bus


def test_channel_runs_are_consecutive_and_at_most_eight_long():
    assert channel_runs([0, 1, 2, 3, 4, 5, 6, 7, 8, 10]) == [[0, 1, 2, 3, 4, 5, 6, 7], [8], [10]]


def test_configure_puts_neutral_on_the_wire_and_reads_it_back():
    chip, emu, _ = _chip()
    assert chip.configure(np.full(8, 1500.0), 1100.0) == ""
    assert emu.mode1 == 0x21 and emu.prescale == 30  # awake, auto-increment, All-Call; 200 Hz
    assert all(abs(emu.pulse_width_us(c) - 1500.0) <= COUNT_US for c in range(8))
    assert abs(emu.pulse_width_us(8) - 1100.0) <= COUNT_US
    emu.reset()  # brown-out: asleep, every output off
    assert "MODE1 0x11" in chip.readback_mismatch()


def test_identical_writes_skip_the_bus_until_forgotten():
    chip, emu, bus = _chip()
    chip.configure(np.full(8, 1500.0), 1100.0)
    assert chip.write(np.full(8, 1600.0), 1100.0)
    assert not chip.write(np.full(8, 1600.0), 1100.0)  # already on the chip
    chip.forget()
    assert chip.write(np.full(8, 1600.0), 1100.0)
    assert chip.written == pytest.approx(np.full(8, 1290 * COUNT_US))  # 1600 / 1.24 = 1290.3 -> 1290 counts
    bus.disconnected = True
    with pytest.raises(I2CError):
        chip.write(np.full(8, 1700.0), 1100.0)
