"""Mock hardware from a bag (docs/architecture.md §6-7): record a simulated run of every driver (raw and parsed topics),
serve its raw device data again through ptys and the emulated I2C bus to fresh driver nodes, and check that
the drivers re-publish the same parsed messages (same values, same count)."""
import pytest

from hindrax_common.config import default_config_path
from hindrax_test_support.record_bag import record_simulated_run
from hindrax_bringup.recording.reader import BagReader
from hindrax_test_support.replay_devices import (PARSED_TOPICS, DriverReplay, ReplayHardware, compare_parsed,
                                                 i2c_transactions, iter_raw_device_data, recorded_parsed)
from hindrax_common.testing import ros_context

pytestmark = pytest.mark.ros

# The ICM-20948 gyro-bias estimate averages the samples received within gyro_bias_duration_s of *receive*
# (ROS) time; how many polls fall in that window depends on how the executor interleaved the poll timer with
# the /clock steps, which a replay cannot reproduce. With it on, every later gyro value differs by the two
# runs' bias estimates; it is switched off in both runs so that every field is compared exactly.
OVERRIDES = {"sensors.icm20948.estimate_gyro_bias": False}
# The committed bag was recorded (python test/support/hindrax_test_support/record_bag.py) with the vehicle file's
# driver settings and the same switch; a replay runs the drivers with the recording's configuration (DriverReplay's
# overrides).
COMMITTED_BAG_OVERRIDES = OVERRIDES


def test_raw_device_data_replayed_through_fresh_drivers_reproduces_the_parsed_topics(tmp_path):
    bag = tmp_path / "sim_run"
    with ros_context() as ctx:
        published = record_simulated_run(bag, 3.0, context=ctx, overrides=OVERRIDES)
        recorded = recorded_parsed(bag)
        # the recording holds every parsed message the drivers published, and raw data of all five devices
        for topic in PARSED_TOPICS:
            assert len(recorded[topic]) == published[topic] > 0, topic
        assert {"/raw/dvl75", "/raw/ping1d", "/raw/ms5837", "/raw/icm20948", "/raw/pca9685"} <= set(
            BagReader(bag).topics)
        # 3 s at 10 Hz (DVL, Ping), MS5837 at its configured rate after start-up, IMU 51 Hz after start-up
        assert 25 <= len(recorded["/dvl/data"]) <= 31 and 25 <= len(recorded["/ping/altitude"]) <= 31
        assert len(recorded["/imu/data_raw"]) > 100

        # the recording's configuration: its emulated PCA9685 runs at the configured oscillator, which bringup counts
        # as measured (pulses out); the shipped vehicle file says "not measured" (outputs off) until calibrated
        replay = DriverReplay(bag, default_config_path(), ctx,
                              overrides={**OVERRIDES, "esc.oscillator_calibrated": True})
        try:
            replay.run(timeout_s=30.0)
            # read before close(), which stops the ptys and empties hw.ptys
            dropped = {name: pty.bytes_dropped for name, pty in replay.hardware.ptys.items()}
        finally:
            replay.close()
    hw = replay.hardware
    # everything recorded was consumed: every serial byte read, every I2C read served, no serial byte dropped
    assert [n for n, d in hw.serial.items() if not d.done] == []
    assert set(dropped) == {"dvl75", "ping1d"} and all(n == 0 for n in dropped.values()), dropped
    assert hw.i2c_reads_left() == {}  # else: the device whose recorded reads the fresh driver did not make
    # the fresh MS5837 and ICM-20948 drivers wrote exactly the recorded register writes, in order
    for address, dev in hw.i2c.items():
        if hw.i2c_device_of[address] in ("ms5837", "icm20948"):
            assert dev.write_mismatches == [] and dev.writes_left == 0, hw.i2c_device_of[address]
    # same values, same count on every parsed topic (stamps: see replay_devices.compare_parsed)
    assert compare_parsed(recorded, replay.received) == []
    # the ESC output (not parsed from device data): the same neutral, disarmed widths
    assert replay.received["/thrusters/pulse_width"]
    assert {tuple(m.pulse_width_us) for m in replay.received["/thrusters/pulse_width"]} == {
        tuple(m.pulse_width_us) for m in recorded["/thrusters/pulse_width"]}


def test_committed_simulator_bag_replays_through_fresh_drivers():
    """The small bag committed under src/hindrax_bringup/test/data (recorded from the simulator by
    ``python test/support/hindrax_test_support/record_bag.py``) drives fresh drivers to the same parsed
    messages: the regression guard for any change in a driver's parsing."""
    from pathlib import Path

    bag = Path(__file__).resolve().parents[1] / "src" / "hindrax_bringup" / "test" / "data" / "sim_drivers_3s"
    recorded = recorded_parsed(bag)
    assert all(len(recorded[t]) > 0 for t in PARSED_TOPICS)
    with ros_context() as ctx:
        replay = DriverReplay(bag, default_config_path(), ctx, overrides=COMMITTED_BAG_OVERRIDES)
        try:
            replay.run(timeout_s=30.0)
        finally:
            replay.close()
    # a stale bag (a driver that now reads otherwise) names the device whose recorded reads were not consumed
    assert replay.hardware.i2c_reads_left() == {}, "rerecord: python test/support/hindrax_test_support/record_bag.py"
    assert [n for n, d in replay.hardware.serial.items() if not d.done] == []
    assert compare_parsed(recorded, replay.received) == []


def test_the_replay_names_the_i2c_device_whose_recorded_reads_are_left():
    """What a stale bag reports: each I2C device with recorded reads not made, by name and count; a device whose
    every recorded read was made leaves the list."""
    from pathlib import Path

    bag = Path(__file__).resolve().parents[1] / "src" / "hindrax_bringup" / "test" / "data" / "sim_drivers_3s"
    hw = ReplayHardware(bag, devices=("ms5837", "icm20948"))
    try:
        left = hw.i2c_reads_left()
        assert set(left) == {"ms5837", "icm20948"} and all(n > 0 for n in left.values()) and not hw.i2c_done()
        for address, tr in i2c_transactions(iter_raw_device_data(bag, "ms5837")).items():
            for register, reads in tr.reads.items():
                for data in reads:  # the driver's reads, in the recorded order, register pointer first
                    if register >= 0:
                        hw.i2c[address].i2c_write(bytes([register]))
                    assert hw.i2c[address].i2c_read(len(data)) == data
        assert hw.i2c_reads_left() == {"icm20948": left["icm20948"]}
    finally:
        hw.close()
