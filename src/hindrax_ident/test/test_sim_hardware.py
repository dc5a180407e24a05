"""Virtual hardware: emulators fed by the simulator, through the real transports."""
import numpy as np
import pytest
import serial

from hindrax_drivers.config import default_config_path, load_config
from hindrax_drivers.dvl75 import protocol as dvl
from hindrax_drivers.pca9685 import protocol as pca
from hindrax_drivers.testing import wait_until
from hindrax_drivers.transport.i2c import I2CDevice
from hindrax_ident.sim.hardware import VirtualHardware
from hindrax_ident.sim.simulator import Simulator


@pytest.fixture
def hw():
    cfg = load_config(default_config_path())
    sim = Simulator(cfg, seed=3)
    vh = VirtualHardware(sim, cfg)
    yield sim, vh, cfg
    vh.close()


def test_pca9685_registers_drive_the_simulated_thrusters(hw):
    sim, vh, cfg = hw
    assert np.all(vh.pulse_widths_us() == 0.0)  # power-up: full OFF, no pulses, no thrust
    dev = I2CDevice(vh.i2c_bus, cfg.get("esc.i2c_address"), "pca9685")
    prescale = pca.esc_prescale(cfg.get("esc.pwm_frequency_hz"), cfg.get("esc.oscillator_hz"))
    dev.write_sequence(pca.startup_sequence(prescale))
    widths = [1700.0, 1700.0, 1500.0, 1500.0, 1500.0, 1500.0, 1500.0, 1500.0]  # T1+T2: pure surge
    for ch, w in enumerate(widths):
        dev.write_block(pca.led_register(ch), pca.channel_bytes_for_pulse(w, prescale, cfg.get("esc.oscillator_hz")))
    wire = vh.pulse_widths_us()
    assert np.allclose(wire, widths, atol=1.3)
    sim.reset(position_ned_m=[5.0, 3.0, 0.9])
    sim.advance(1.0, wire)
    assert sim.nu[0] > 0.05  # surging forward
    assert abs(sim.nu[5]) < 0.02  # T1+T2 with the symmetric layout: no yaw


def test_dvl_emulator_on_a_pty_reports_the_simulated_velocity(hw):
    sim, vh, cfg = hw
    sim.reset(position_ned_m=[5.0, 3.0, 0.9], nu=[0.3, 0.0, 0.0, 0.0, 0.0, 0.0])
    port = serial.serial_for_url(vh.dvl_port, baudrate=115200, timeout=0.05)
    try:
        port.write(b"SEND-DVPDL ON\n")
        framer = dvl.DvlLineFramer()
        records = []

        def poll():
            sim.advance(0.02)
            for line in framer.feed(port.read(4096)):
                try:
                    records.append(dvl.parse_line(line))
                except dvl.DvlParseError:
                    pass

        wait_until(lambda: any(isinstance(r, dvl.DvlPositionDelta) for r in records), 20, poll, "$DVPDL report")
        deltas = [r for r in records if isinstance(r, dvl.DvlPositionDelta)]
        v = deltas[-1].velocity_frd_m_s()
        assert v is not None and abs(v[0] - sim.nu[0]) < 0.1  # 5 % scale noise + 0.01 m/s, plus decay
    finally:
        port.close()
