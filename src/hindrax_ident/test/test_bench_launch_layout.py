"""The launch-layout benchmark's stand-in for /dev/i2c-1: a driver process's SocketI2CBus talks to an
EmulatedI2CBus in the pool process through I2CSocketServer, with the smbus2 semantics the drivers rely on
(block writes reach the register-exact emulator, reads come back as lists, an absent device is OSError 121)."""
import errno
import threading

import pytest

from hindrax_drivers.pca9685 import protocol as p
from hindrax_drivers.pca9685.emulator import Pca9685Emulator
from hindrax_drivers.transport.emulated_i2c import EmulatedI2CBus
from hindrax_drivers.transport.i2c import I2CDevice
from hindrax_ident.benchmarks.launch_layout import I2CSocketServer, SocketI2CBus


def test_socket_bus_serves_the_emulated_bus(tmp_path):
    emulator = Pca9685Emulator()
    server = I2CSocketServer(EmulatedI2CBus({0x40: emulator}), str(tmp_path / "i2c.sock"), threading.Lock())
    bus = SocketI2CBus(str(tmp_path / "i2c.sock"))
    device = I2CDevice(bus, 0x40, "pca9685", retries=0)
    prescale = p.esc_prescale(50.0, p.INTERNAL_OSCILLATOR_HZ)
    device.write_sequence(p.startup_sequence(prescale))
    device.write_block(p.led_register(0), p.channel_bytes_for_pulse(1700.0, prescale, p.INTERNAL_OSCILLATOR_HZ))
    # the emulator decodes the pulse width from the registers the driver wrote through the socket
    assert emulator.pulse_width_us(0) == pytest.approx(1700.0, abs=5.0)  # one count at 50 Hz: 20 ms / 4096
    # and a burst read returns what the registers hold
    assert device.read_block(p.led_register(0), 4) == p.channel_bytes_for_pulse(1700.0, prescale,
                                                                                p.INTERNAL_OSCILLATOR_HZ)
    with pytest.raises(OSError) as exc:
        bus.read_byte_data(0x41, 0x00)  # nobody at 0x41: a NACK, as smbus2 reports it
    assert exc.value.errno == errno.EREMOTEIO
    bus.close()
    server.close()
    assert not (tmp_path / "i2c.sock").exists()
