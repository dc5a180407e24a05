"""The device table (hindrax_common.base.devices) is the one list of devices: every path that builds devices (the
composed processes, ``hindrax health``, the pool-day emulators, the drive replay, the simulator's virtual hardware,
bringup) has exactly the table's devices, and a device added to the table alone appears in bringup, the replay and the
simulator."""
from __future__ import annotations

import inspect
from pathlib import Path
from types import SimpleNamespace

import pytest
from rclpy.node import Node

from hindrax_common.base import devices
from hindrax_bringup.layout.composition import GROUPS, NODE_CLASSES
from hindrax_common.config import default_config_path, load_config
from hindrax_bringup.layout.emulated_devices import I2C_DEVICES, SERIAL_DEVICES, EmulatedDevices
from hindrax_bringup.layout.health import STATUS_OF_NODE
from hindrax_test_support import replay_devices
from hindrax_common.testing import ros_context
from hindrax_sim.graph.bringup import build_graph
from hindrax_sim.hardware import VirtualHardware
from hindrax_sim.simulator import Simulator
from hindrax_sim.truth import truth_from_mapping
from hindrax_msgs.msg import RawDeviceData

BAG = Path(__file__).resolve().parents[2] / "hindrax_bringup" / "test" / "data" / "sim_drivers_3s"
NAMES = {"dvl75", "ping1d", "ms5837", "icm20948", "pca9685"}
SERIAL = {d.name for d in devices.DEVICES if d.transport == devices.SERIAL}
I2C = {d.name for d in devices.DEVICES if d.transport == devices.I2C}


def _addresses(config) -> set[int]:
    return {devices.settings(config, d).i2c_address for d in devices.DEVICES if d.transport == devices.I2C}


def test_the_table_holds_the_five_devices_and_every_path_exactly_them():
    assert {d.name for d in devices.DEVICES} == NAMES and SERIAL == {"dvl75", "ping1d"}
    cfg = load_config(default_config_path())
    nodes = {d.node for d in devices.DEVICES}
    assert nodes <= set(NODE_CLASSES)
    assert set(GROUPS["sensors_node"]) - {"static_tf"} == {d.node for d in devices.DEVICES if not d.output}
    assert {d.node for d in devices.DEVICES if d.output} <= set(GROUPS["actuation_node"])
    assert {n: s for n, s in STATUS_OF_NODE.items() if n in nodes} == {
        "dvl75": "hindrax/dvl75", "ping1d": "hindrax/ping1d", "ms5837": "hindrax/ms5837",
        "icm20948": "hindrax/icm20948", "esc": "hindrax/esc_pca9685"}  # what each node reports on /diagnostics
    assert set(SERIAL_DEVICES) == SERIAL and set(I2C_DEVICES) - {"output_guard"} == {"ms5837", "icm20948", "esc"}
    pool = EmulatedDevices(cfg, serve_i2c=False)
    try:
        assert set(pool.ports) == SERIAL and set(pool.bus.devices) == _addresses(cfg)
    finally:
        pool.close()
    assert set(replay_devices.PARSED_TOPICS.values()) == NAMES - {"pca9685"}
    hw = replay_devices.ReplayHardware(BAG)  # the committed bag has raw data of every device
    try:
        assert set(hw.serial) | set(hw.i2c_device_of.values()) == NAMES
    finally:
        hw.close()
    sim = Simulator(cfg, seed=1)
    vh = VirtualHardware(sim, sim.config, serve_serial=True)
    try:
        assert set(vh.emulators) == NAMES and set(vh.ports) == SERIAL
        assert _addresses(cfg) <= set(vh.i2c_bus.devices)
    finally:
        vh.close()


class FakeNode(Node):
    """A driver of the fake device: a node that keeps the bus it was given."""

    def __init__(self, bus=None, **kwargs):
        super().__init__("fake_sensor", **kwargs)
        self.bus = bus


class FakeEmulator:
    """An I2C device answering zeros, built by the table's factory with the truth it was given."""

    def __init__(self, truth):
        self.truth = truth

    def i2c_write(self, data: bytes) -> None:
        pass

    def i2c_read(self, n: int) -> bytes:
        return bytes(n)


FAKE = devices.Device("fake", "fake_sensor", devices.I2C, FakeNode,
                      lambda config, truth, clock, seed: FakeEmulator(truth), "test.fake",
                      {"/fake/value": "std_msgs/msg/Float32"})
FAKE_ADDRESS = 0x50


@pytest.fixture
def fake_device(monkeypatch):
    """The table with the fake device added (its configuration section, at :data:`FAKE_ADDRESS`, is the test's)."""
    settings = devices.settings
    monkeypatch.setattr(devices, "DEVICES", devices.DEVICES + (FAKE,))
    monkeypatch.setattr(devices, "settings", lambda config, d: SimpleNamespace(i2c_address=FAKE_ADDRESS)
                        if d is FAKE else settings(config, d))
    raw = replay_devices.iter_raw_device_data

    def recorded(bag, name):  # the bag holds one read of the fake device
        if name != "fake":
            return raw(bag, name)
        return [(0, RawDeviceData(device_name="fake", transport=RawDeviceData.TRANSPORT_I2C, i2c_address=FAKE_ADDRESS,
                                  i2c_register=0, direction=RawDeviceData.DIRECTION_DEVICE_TO_HOST, data=b"\x01"))]

    monkeypatch.setattr(replay_devices, "iter_raw_device_data", recorded)


@pytest.mark.ros
def test_a_device_added_to_the_table_alone_appears_in_bringup_replay_and_the_simulator(fake_device):
    cfg = load_config(default_config_path())
    sim = Simulator(cfg, seed=1)
    vh = VirtualHardware(sim, sim.config, serve_serial=False)
    assert isinstance(vh.emulators["fake"], FakeEmulator) and vh.i2c_bus.devices[FAKE_ADDRESS] is vh.emulators["fake"]
    with ros_context() as ctx:
        graph = build_graph(default_config_path(), sim=True, identification=False, context=ctx)
        try:
            fake = graph.nodes["fake_sensor"]
            assert isinstance(fake, FakeNode) and fake.bus is graph.hardware.i2c_bus
            assert isinstance(graph.hardware.i2c_bus.devices[FAKE_ADDRESS], FakeEmulator)
            assert {d.node for d in devices.DEVICES} <= set(graph.nodes)
        finally:
            graph.shutdown()
        replay = replay_devices.DriverReplay(BAG, default_config_path(), ctx)
        try:
            assert replay.hardware.i2c_device_of[FAKE_ADDRESS] == "fake"
            assert isinstance(replay.nodes["fake_sensor"], FakeNode)
            assert replay.nodes["fake_sensor"].bus is replay.hardware.i2c_bus
            assert {d.node for d in devices.DEVICES} <= set(replay.nodes)
        finally:
            replay.close()


def test_each_device_names_the_truth_keywords_its_emulator_takes_and_the_simulator_passes_them():
    """A truth-only setting is a field of its device: the table names every keyword-only argument of each emulator
    factory, and the simulator hands each the truth's value (a bottom-lock floor other than the emulator's default)."""
    for d in devices.DEVICES:
        params = inspect.signature(devices.load(d.emulator)).parameters.values()
        assert set(d.truth_keywords) == {p.name for p in params if p.kind is p.KEYWORD_ONLY}, d.name
    cfg = load_config(default_config_path())
    sim = Simulator(truth_from_mapping(cfg, {"simulation": {"sensors": {"dvl75": {"min_altitude_m": 0.55}}}}).config,
                    seed=1)
    vh = VirtualHardware(sim, sim.config, serve_serial=False)
    try:
        assert vh.emulators["dvl75"].min_altitude_m == 0.55
    finally:
        vh.close()
