"""An I2C bus that is absent, appears, goes and comes back: the MS5837 and ICM-20948 drivers keep running, report
it on /diagnostics and pick the bus up again without a restart (transport/i2c.py BusHandle); the emulated bus a
launch layout's driver processes share (transport/socket_i2c.py) fails the way a real adapter does."""
from __future__ import annotations

import errno

import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.executors import SingleThreadedExecutor
from sensor_msgs.msg import FluidPressure, Imu

from hindrax_common.config import default_config_path, load_config
from hindrax_bringup.layout.emulated_devices import EmulatedDevices
from hindrax_drivers.icm20948.node import Icm20948Node
from hindrax_drivers.ms5837.node import Ms5837Node
from hindrax_common.testing import config_parameters, ros_context, wait_until
from hindrax_common.transport.emulated_i2c import EmulatedI2CBus
from hindrax_common.transport.i2c import BusHandle, open_smbus
from hindrax_common.transport.socket_i2c import SOCKET_ENV, I2CSocketServer, SocketI2CBus


class _Register:
    """One register at any pointer: a write [pointer, value] stores value, [pointer] alone only points."""

    def __init__(self):
        self.value = 0x5A

    def i2c_write(self, data):
        if len(data) > 1:
            self.value = data[-1]

    def i2c_read(self, n):
        return bytes([self.value]) * n


def test_socket_bus_fails_like_an_adapter_and_bus_handle_reopens_it(tmp_path, monkeypatch):
    path = str(tmp_path / "i2c.sock")
    monkeypatch.setenv(SOCKET_ENV, path)
    with pytest.raises(OSError) as absent:  # nobody serves: as a missing /dev/i2c-1
        open_smbus(1)
    assert absent.value.errno in (errno.ENOENT, errno.ECONNREFUSED)
    handle = BusHandle(1)
    with pytest.raises(OSError):
        handle.get()
    server = I2CSocketServer(EmulatedI2CBus({0x40: _Register()}), path)
    bus = handle.get()
    assert isinstance(bus, SocketI2CBus) and bus.read_byte_data(0x40, 0) == 0x5A
    with pytest.raises(OSError) as nack:
        bus.read_byte_data(0x41, 0)
    assert nack.value.errno == errno.EREMOTEIO  # nobody at 0x41, as smbus2 reports it
    server.close()  # the adapter goes away mid-run
    with pytest.raises(OSError) as gone:
        bus.write_byte_data(0x40, 0, 1)
    assert gone.value.errno == errno.ENODEV
    with pytest.raises(OSError):  # stays gone on this connection, even when the adapter is back
        server = I2CSocketServer(EmulatedI2CBus({0x40: _Register()}), path)
        bus.read_byte_data(0x40, 0)
    assert handle.reset() and handle.get().read_byte_data(0x40, 0) == 0x5A and handle.opens == 2
    server.close()
    injected = BusHandle(1, bus=EmulatedI2CBus({}))
    assert not injected.reset() and injected.get() is injected.get()  # a given bus is never closed or replaced


@pytest.mark.ros
def test_i2c_drivers_keep_running_without_their_bus_and_pick_it_up_when_it_returns(tmp_path, monkeypatch):
    cfg = load_config(default_config_path())
    with EmulatedDevices(cfg, tmp_path, serve_i2c=False) as dev, ros_context() as ctx:
        monkeypatch.setenv(SOCKET_ENV, dev.socket_path)  # what open_smbus in the nodes reads
        params = config_parameters({"sensors.ms5837.rate_hz": 20.0})
        nodes = [Ms5837Node(context=ctx, parameter_overrides=params),
                 Icm20948Node(context=ctx, parameter_overrides=params)]
        probe = rclpy.create_node("probe", context=ctx)
        ex = SingleThreadedExecutor(context=ctx)
        for n in nodes + [probe]:
            ex.add_node(n)
        pressure, imu, levels = [], [], {"hindrax/ms5837": [], "hindrax/icm20948": []}
        probe.create_subscription(FluidPressure, "pressure/fluid_pressure", pressure.append, 50)
        probe.create_subscription(Imu, "imu/data_raw", imu.append, 200)

        def on_diag(msg):
            for st in msg.status:
                if st.name in levels:
                    levels[st.name].append(st.level[0] if isinstance(st.level, bytes) else st.level)
        probe.create_subscription(DiagnosticArray, "/diagnostics", on_diag, 50)
        spin = lambda: ex.spin_once(timeout_sec=0.02)  # noqa: E731

        def reports_error(times: int, since: dict) -> bool:
            return all(sum(1 for lv in levels[k][since[k]:] if lv >= 2) >= times for k in levels)

        try:
            # 1. no bus: both report ERROR, again and again (retrying), and publish nothing
            wait_until(lambda: reports_error(2, {k: 0 for k in levels}), 30, spin, "ERROR without the bus")
            assert not pressure and not imu
            # 2. the bus appears: picked up by the running nodes
            dev.start_i2c()
            wait_until(lambda: len(pressure) >= 5 and len(imu) >= 20, 30, spin, "data once the bus is there")
            # 3. the bus goes mid-run: ERROR again
            dev.stop_i2c()
            mark = {k: len(v) for k, v in levels.items()}
            wait_until(lambda: reports_error(1, mark), 30, spin, "ERROR after the bus went")
            n_pressure, n_imu = len(pressure), len(imu)
            # 4. ... and comes back: data again, same processes, the bus opened afresh
            dev.start_i2c()
            wait_until(lambda: len(pressure) >= n_pressure + 5 and len(imu) >= n_imu + 20, 30, spin,
                       "data once the bus is back")
            assert all(n._bus.opens >= 2 for n in nodes)
        finally:
            ex.shutdown()
            for n in nodes + [probe]:
                n.destroy_node()
