"""The live pool process (hindrax_sim/live_pool.py) as a driver process meets it: the PCA9685 over the I2C
socket moves the simulated vehicle, the DVL-75 port speaks its protocol, the operator's hands push, and simulated
time follows the wall clock. The whole launch against it: test/test_pool_day.py."""
from __future__ import annotations

import os
import time

import pytest
import serial

from hindrax_common.config import default_config_path, load_config
from hindrax_common.process.conditions import wait_until
from hindrax_bringup.layout.emulated_devices import I2C_DEVICES, SERIAL_DEVICES
from hindrax_common.process.scheduling import HARDWARE_STAND_IN_PRIORITY
from hindrax_common.testing import child_env
from hindrax_test_support.helpers import may_set_fifo
from hindrax_common.transport.socket_i2c import SOCKET_ENV, SocketI2CBus
from hindrax_sim.live_pool import LivePool

pytestmark = pytest.mark.vehicle_launch

# PCA9685 registers (NXP PCA9685 datasheet rev. 4, §7.3): MODE1, LED0_ON_L, PRE_SCALE
MODE1, LED0_ON_L, PRE_SCALE = 0x00, 0x06, 0xFE


def _pulse_registers(width_us: float, frequency_hz: float = 200.0) -> list[int]:
    """LEDn_ON_L..OFF_H for a pulse of ``width_us`` starting at count 0 (datasheet §7.3.3: 4096 counts a period)."""
    off = round(width_us * 1e-6 * frequency_hz * 4096)
    return [0, 0, off & 0xFF, off >> 8]


def test_live_pool_moves_with_the_pulse_widths_and_the_operator(tmp_path):
    config = default_config_path()
    cfg = load_config(config)
    address = int(cfg.esc.i2c_address)
    channels = [t.esc_channel for t in cfg.thrusters.thrusters]
    vertical = [t.esc_channel for t in cfg.thrusters.thrusters if abs(t.direction_frd[2]) > 0.5]
    with LivePool(config, tmp_path / "pool", env=child_env()) as pool:
        # what a driver process is given: its port, or the bus socket
        assert pool.ros_arguments("dvl75") == ["-p", f"{SERIAL_DEVICES['dvl75']}.port:={pool.ports['dvl75']}"]
        assert all(pool.env(n) == {SOCKET_ENV: pool.socket_path} for n in I2C_DEVICES)
        assert pool.env("dvl75") == {} and pool.ros_arguments("esc") == []
        # the vehicle's hardware answers whatever the load: every thread SCHED_FIFO 20 (or refused, and said so),
        # the serving threads too, started after the call: they inherited it
        policies = {(os.sched_getscheduler(int(t)), os.sched_getparam(int(t)).sched_priority)
                    for t in os.listdir(f"/proc/{pool.pid}/task")}
        if may_set_fifo(HARDWARE_STAND_IN_PRIORITY):
            assert policies == {(os.SCHED_FIFO, HARDWARE_STAND_IN_PRIORITY)}, policies
            assert f"live pool: SCHED_FIFO priority {HARDWARE_STAND_IN_PRIORITY} (" in pool.log(), pool.log()
        else:
            assert f"SCHED_FIFO priority {HARDWARE_STAND_IN_PRIORITY} refused" in pool.log(), pool.log()
        # simulated time follows the wall clock
        t0_sim, t0_wall = pool.truth()["t_s"], time.monotonic()
        wait_until(lambda: time.monotonic() - t0_wall > 1.0, 5.0)
        advanced = pool.truth()["t_s"] - t0_sim
        assert 0.5 < advanced < 3.0, advanced
        # the altimeter's true range: from the Ping1D's mount straight down to the floor while the vehicle is about
        # level (the floor's slope over the mount's 0.1 m forward offset and the tilt change it by millimetres)
        t = pool.truth()
        below = t["floor_depth_m"] - t["position_ned_m"][2] - float(cfg.sensors.ping1d.position_frd_m[2])
        assert max(abs(a) for a in t["euler_rad"][:2]) < 0.05 and abs(t["altimeter_range_m"] - below) < 0.02, t
        # the DVL-75 speaks on its port: $DVPDL/$DVEXT sentences (Cerulean DVL-75 manual, serial output)
        with serial.Serial(pool.ports["dvl75"], 115200, timeout=0.2) as port:
            got = bytearray()
            wait_until(lambda: got.extend(port.read(256)) or b"$DV" in got, 10.0, message="DVL-75 sentences")
        # the bus: the PCA9685 is there; 200 Hz, awake, 1900 us on the vertical thrusters -> the vehicle rises
        bus = SocketI2CBus(pool.socket_path)
        try:
            prescale = round(float(cfg.esc.oscillator_hz) / (4096 * 200.0)) - 1  # datasheet eq. 1
            bus.write_byte_data(address, MODE1, 0x10)  # sleep to set the prescaler
            bus.write_byte_data(address, PRE_SCALE, prescale)
            bus.write_byte_data(address, MODE1, 0x20)  # awake, auto-increment
            for ch in channels:
                width = 1500.0 if ch not in vertical else 1900.0
                bus.write_i2c_block_data(address, LED0_ON_L + 4 * ch, _pulse_registers(width))
            wait_until(lambda: max(pool.truth()["pulse_widths_us"]) > 1850.0, 5.0, message="widths on the chip")
            z0 = pool.truth()["position_ned_m"][2]
            wait_until(lambda: abs(pool.truth()["position_ned_m"][2] - z0) > 0.05, 10.0, message="thrust moves it")
            for ch in channels:
                bus.write_i2c_block_data(address, LED0_ON_L + 4 * ch, _pulse_registers(1500.0))
        finally:
            bus.close()
        # the operator's hands: the ballast sinks it (8.56 N in water), an unknown code is refused
        assert pool.act("attach_ballast") and not pool.act("attach_an_anvil")
        wait_until(lambda: pool.truth()["nu"][2] > 0.05, 20.0, message="the ballast sinks the vehicle (w > 0, FRD)")
        assert pool.act("remove_ballast")
    assert "Traceback" not in pool.log(), pool.log()
