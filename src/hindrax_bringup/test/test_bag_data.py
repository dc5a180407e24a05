"""The committed test bags (test/data): readable by independent readers, equal to what the generator writes,
small, and usable by device emulators through iter_raw_device_data."""
from __future__ import annotations

import math
from pathlib import Path

import pytest
from rclpy.serialization import deserialize_message, serialize_message

from hindrax_bringup.recording.make_test_bags import (BAGS, LATENCY_NS, START_NS, STREAMS, messages_per_stream,
                                                      synthetic_messages, write_bag)
from hindrax_bringup.recording.msgtypes import message_class
from hindrax_bringup.recording.reader import BagReader
from hindrax_test_support.replay_devices import iter_raw_device_data

DATA = Path(__file__).parent / "data"


def test_test_data_is_small_and_documented():
    total = sum(p.stat().st_size for p in DATA.rglob("*") if p.is_file())
    assert total < 5 * 1024 * 1024
    readme = (DATA / "README.md").read_text()
    assert "python -m hindrax_bringup.recording.make_test_bags" in readme
    assert set(BAGS) <= {p.name for p in DATA.iterdir() if p.is_dir()}


def decoded(bag: Path) -> list[tuple[str, int, object]]:
    """(topic, log time, rclpy message) sorted by log time then topic. Messages are compared decoded: CDR
    alignment padding bytes are not initialised by the serializer, so equal messages may differ in bytes."""
    reader = BagReader(bag)
    classes = {t: message_class(c.type) for t, c in reader.channels.items()}
    out = [(m.topic, m.log_time_ns, deserialize_message(m.data, classes[m.topic])) for m in reader.messages()]
    return sorted(out, key=lambda x: (x[1], x[0]))


@pytest.mark.parametrize("name", sorted(BAGS))
def test_committed_bags_hold_exactly_what_the_generator_produces(name):
    duration_s, _ = BAGS[name]
    # through CDR and back, as float32 fields (Range) are stored in single precision
    expected = sorted(((topic, t, deserialize_message(serialize_message(msg), type(msg)))
                       for t, topic, msg in synthetic_messages(duration_s)), key=lambda x: (x[1], x[0]))
    assert decoded(DATA / name) == expected


def test_regenerating_gives_the_same_messages(tmp_path):
    duration_s, options = BAGS["split_3s"]
    write_bag(tmp_path / "split_3s", duration_s, options)
    assert decoded(tmp_path / "split_3s") == decoded(DATA / "split_3s")
    assert [p.name for p in BagReader(tmp_path / "split_3s").files] == [f"split_3s_{k}.mcap" for k in range(3)]


@pytest.mark.parametrize("name", sorted(BAGS))
def test_rosbags_and_mcap_ros2_decode_every_message(name):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    from rosbags.highlevel import AnyReader

    duration_s, _ = BAGS[name]
    n_expected = sum(messages_per_stream(duration_s, s.rate_hz) for s in STREAMS)
    with AnyReader([DATA / name]) as reader:
        decoded = [(c.topic, reader.deserialize(raw, c.msgtype)) for c, _, raw in reader.messages()]
    assert len(decoded) == n_expected
    with AnyReader([DATA / name]) as reader:
        by_type = {c.topic: c.msgtype for c in reader.connections}
    assert by_type["/dvl/data"] == "hindrax_msgs/msg/Dvl" and by_type["/raw/dvl75"] == "hindrax_msgs/msg/RawDeviceData"
    # physical content survives: pressure at 1 m depth = p0 + rho g h (noise 20 Pa)
    pressures = [m.fluid_pressure for t, m in decoded if t == "/depth/pressure"]
    assert all(abs(p - (101325.0 + 1000.0 * 9.81 * 1.0)) < 200 for p in pressures)
    n = 0
    for f in BagReader(DATA / name).files:
        with open(f, "rb") as fh:
            for _schema, channel, message, ros_msg in make_reader(
                    fh, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
                n += 1
                if channel.topic == "/thrusters/wrench":
                    assert ros_msg.header.frame_id == "base_link"
                    t = (message.log_time - LATENCY_NS - START_NS) / 1e9
                    assert ros_msg.wrench.force.x == pytest.approx(10.0 * math.sin(2 * math.pi * 0.25 * t))
    assert n == n_expected


def test_iter_raw_device_data_gives_one_device_in_time_order():
    from hindrax_msgs.msg import RawDeviceData

    rates = {s.topic.split("/")[-1]: s.rate_hz for s in STREAMS if s.type.endswith("RawDeviceData")}
    for device, rate in rates.items():
        items = list(iter_raw_device_data(DATA / "sensors_4s", device))
        assert len(items) == messages_per_stream(4.0, rate)
        times = [t for t, _ in items]
        assert times == sorted(times)
        assert all(isinstance(m, RawDeviceData) and m.device_name == device for _, m in items)
        # t_ns is the header stamp: sample k at START_NS + k / rate
        assert times == [START_NS + int(round(k * 1e9 / rate)) for k in range(len(items))]
    dvl = [bytes(m.data) for _, m in iter_raw_device_data(DATA / "split_3s", "dvl75")]
    assert len(dvl) == 30 and all(d.startswith(b"$DVEXT,") and d.endswith(b"\r\n") for d in dvl)
    assert list(iter_raw_device_data(DATA / "sensors_4s", "no_such_device")) == []
