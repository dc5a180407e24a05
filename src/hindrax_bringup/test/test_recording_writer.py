"""BagWriter: rosbag2 layout, independent readers (rosbags, mcap_ros2), chunking, compression, splitting,
durability of finished chunks. Pure (no ROS runtime; rclpy.serialization only builds the CDR bytes)."""
from __future__ import annotations

import math
import threading
from pathlib import Path

import numpy as np
import pytest
import yaml
from geometry_msgs.msg import WrenchStamped
from mcap.reader import make_reader
from rclpy.serialization import serialize_message
from sensor_msgs.msg import Imu
from hindrax_common.cdr import msgdefs
from hindrax_bringup.recording.metadata import read_metadata
from hindrax_bringup.recording.qos import default_profile, profiles_from_yaml
from hindrax_bringup.recording.reader import BagReader
from hindrax_bringup.recording.recover import iter_file_records
from hindrax_bringup.recording.writer import BagWriter, WriterOptions
from hindrax_bringup.recording.writer_thread import ThreadedBagWriter
from hindrax_common.testing import wait_until
from hindrax_msgs.msg import Dvl, RawDeviceData

T0 = 1_700_000_000_000_000_000
TOPICS = {"/imu": "sensor_msgs/msg/Imu", "/wrench": "geometry_msgs/msg/WrenchStamped",
          "/dvl": "hindrax_msgs/msg/Dvl", "/raw": "hindrax_msgs/msg/RawDeviceData"}


def make(topic: str, i: int):
    """A message whose fields encode (topic, i), so decoded copies can be checked field by field."""
    if topic == "/imu":
        m = Imu()
        m.header.frame_id = "imu_link"
        m.linear_acceleration.x = 0.5 * i
        m.angular_velocity.z = -0.25 * i
        m.orientation_covariance[0] = -1.0
    elif topic == "/wrench":
        m = WrenchStamped()
        m.header.frame_id = "base_link"
        m.wrench.force.x, m.wrench.torque.z = float(i), -float(i)
    elif topic == "/dvl":
        m = Dvl()
        m.header.frame_id = "base_link"
        m.velocity_m_s.x = 0.01 * i
        m.altitude_m = 1.0 + i
        m.beam_lock = [True, False, True, i % 2 == 0]
        m.bottom_lock = True
    else:
        m = RawDeviceData(device_name="ms5837" if i % 2 else "dvl75", transport=RawDeviceData.TRANSPORT_I2C,
                          i2c_address=0x76, i2c_register=-1 if i % 3 else 0x48)
        m.data = bytes([(i + k) % 256 for k in range(i % 7 + 1)])
    m.header.stamp.sec, m.header.stamp.nanosec = divmod(T0 + i * 1_000_000, 1_000_000_000)
    return m


def write_sample(bag: Path, n: int = 200, options: WriterOptions | None = None) -> list[tuple[str, int, int]]:
    """n messages round-robin over TOPICS at 1 ms spacing; returns (topic, i, log_time_ns)."""
    written = []
    with BagWriter(bag, options or WriterOptions(chunk_size_bytes=2048)) as w:
        for topic, type_name in TOPICS.items():
            w.add_topic(topic, type_name, [default_profile("best_effort" if topic == "/imu" else "reliable")])
        for i in range(n):
            topic = list(TOPICS)[i % len(TOPICS)]
            t = T0 + i * 1_000_000
            w.write(topic, t, serialize_message(make(topic, i)), t - 500)
            written.append((topic, i, t))
    return written


def decode_with_mcap_ros2(path: Path) -> list:
    """(channel, message, decoded) of every message, decoded by mcap_ros2 from the file's own schemas."""
    from mcap_ros2.decoder import DecoderFactory

    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        return [(c, m, d) for _s, c, m, d in reader.iter_decoded_messages()]


def check_fields(topic: str, i: int, msg) -> None:
    """Compare a decoded message (rosbags or mcap_ros2 object) with make(topic, i)."""
    ref = make(topic, i)
    assert msg.header.frame_id == ref.header.frame_id
    assert msg.header.stamp.sec == ref.header.stamp.sec and msg.header.stamp.nanosec == ref.header.stamp.nanosec
    if topic == "/imu":
        assert msg.linear_acceleration.x == ref.linear_acceleration.x
        assert msg.angular_velocity.z == ref.angular_velocity.z
        assert list(msg.orientation_covariance) == list(ref.orientation_covariance)
    elif topic == "/wrench":
        assert (msg.wrench.force.x, msg.wrench.torque.z) == (ref.wrench.force.x, ref.wrench.torque.z)
    elif topic == "/dvl":
        assert msg.velocity_m_s.x == ref.velocity_m_s.x and msg.altitude_m == ref.altitude_m
        assert [bool(b) for b in msg.beam_lock] == [bool(b) for b in ref.beam_lock]
        assert math.isnan(msg.altitude_m) is False and msg.bottom_lock
    else:
        assert msg.device_name == ref.device_name and msg.i2c_register == ref.i2c_register
        assert bytes(msg.data) == bytes(ref.data)


def test_bag_directory_and_metadata_yaml_follow_rosbag2_jazzy(tmp_path):
    bag = tmp_path / "run1"
    written = write_sample(bag, n=100)
    assert sorted(p.name for p in bag.iterdir()) == ["metadata.yaml", "run1_0.mcap"]
    info = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert info["version"] == 9 and info["storage_identifier"] == "mcap" and info["ros_distro"] == "jazzy"
    assert info["relative_file_paths"] == ["run1_0.mcap"]
    assert info["message_count"] == 100
    assert info["starting_time"]["nanoseconds_since_epoch"] == written[0][2]
    assert info["duration"]["nanoseconds"] == written[-1][2] - written[0][2]
    assert info["files"] == [{"path": "run1_0.mcap", "starting_time": {"nanoseconds_since_epoch": written[0][2]},
                              "duration": {"nanoseconds": written[-1][2] - written[0][2]}, "message_count": 100}]
    topics = {t["topic_metadata"]["name"]: t for t in info["topics_with_message_count"]}
    assert set(topics) == set(TOPICS)
    for name, t in topics.items():
        tm = t["topic_metadata"]
        assert tm["type"] == TOPICS[name] and tm["serialization_format"] == "cdr"
        assert t["message_count"] == 25
        assert tm["type_description_hash"] == msgdefs.type_description_hash(TOPICS[name])
        assert isinstance(tm["offered_qos_profiles"], list)  # a list from version 9 on, not a string
        assert tm["offered_qos_profiles"][0]["reliability"] == ("best_effort" if name == "/imu" else "reliable")


def test_mcap_file_has_ros2_profile_schemas_channels_and_rosbag2_metadata_record(tmp_path):
    bag = tmp_path / "b"
    write_sample(bag, n=40)
    with open(bag / "b_0.mcap", "rb") as f:
        reader = make_reader(f)
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
        schemas = {s.name: s for s in summary.schemas.values()}
        assert set(schemas) == set(TOPICS.values())
        for name, s in schemas.items():
            assert s.encoding == "ros2msg"
            assert s.data.decode() == msgdefs.message_definition(name)
        for ch in summary.channels.values():
            assert ch.message_encoding == "cdr"
            assert summary.schemas[ch.schema_id].name == TOPICS[ch.topic]
            assert ch.metadata["topic_type_hash"] == msgdefs.type_description_hash(TOPICS[ch.topic])
            (prof,) = profiles_from_yaml(ch.metadata["offered_qos_profiles"])
            assert prof["reliability"] == ("best_effort" if ch.topic == "/imu" else "reliable")
        (meta,) = [m for m in reader.iter_metadata() if m.name == "rosbag2"]
        serialized = yaml.safe_load(meta.metadata["serialized_metadata"])
        on_disk = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
        assert serialized == on_disk
        assert summary.statistics.chunk_count > 1  # 2 kB chunks


def test_rosbags_anyreader_decodes_every_message_including_custom_types(tmp_path):
    from rosbags.highlevel import AnyReader

    bag = tmp_path / "b"
    written = write_sample(bag, n=120)
    got = []
    with AnyReader([bag]) as reader:
        assert {c.topic: c.msgtype for c in reader.connections} == TOPICS
        for conn, t, raw in reader.messages():
            got.append((conn.topic, t, reader.deserialize(raw, conn.msgtype)))
    assert [(topic, t) for topic, t, _ in got] == [(topic, t) for topic, _, t in written]
    for (topic, i, _), (_, _, msg) in zip(written, got):
        check_fields(topic, i, msg)


def test_mcap_ros2_reader_decodes_every_message_from_the_stored_schemas(tmp_path):
    bag = tmp_path / "b"
    written = write_sample(bag, n=120)
    got = decode_with_mcap_ros2(bag / "b_0.mcap")
    assert len(got) == len(written)
    for (topic, i, t), (channel, message, ros_msg) in zip(written, got):
        assert channel.topic == topic and message.log_time == t and message.publish_time == t - 500
        check_fields(topic, i, ros_msg)
    # our reader decodes the same way (used by bag info and analyses)
    assert [m.topic for m, _ in BagReader(bag).decoded()] == [w[0] for w in written]


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_chunks_use_the_configured_compression(tmp_path, compression):
    bag = tmp_path / compression
    write_sample(bag, n=60, options=WriterOptions(compression=compression, chunk_size_bytes=1024))
    with open(bag / f"{compression}_0.mcap", "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary.statistics.chunk_count >= 2
    assert {c.compression for c in summary.chunk_indexes} == {"" if compression == "none" else compression}
    assert sum(1 for _ in BagReader(bag).messages()) == 60


def test_split_by_size_keeps_files_under_the_limit_and_loses_nothing(tmp_path):
    from rosbags.highlevel import AnyReader

    bag = tmp_path / "s"
    limit = 60_000  # per-file overhead of these 4 topics (schemas twice, metadata record) is about 20 kB
    written = write_sample(bag, n=1500, options=WriterOptions(chunk_size_bytes=4096, split_size_bytes=limit))
    meta = read_metadata(bag)
    files = [bag / p for p in meta.relative_file_paths]
    assert len(files) >= 3
    assert [f.name for f in files] == [f"s_{k}.mcap" for k in range(len(files))]
    assert all(f.stat().st_size <= limit for f in files)
    assert sum(f.message_count for f in meta.files) == 1500
    with AnyReader([bag]) as reader:
        times = [t for _, t, _ in reader.messages()]
    assert times == [w[2] for w in written]


def test_a_split_size_below_the_per_file_overhead_is_reported_not_obeyed_message_by_message(tmp_path):
    bag = tmp_path / "tiny"
    with BagWriter(bag, WriterOptions(chunk_size_bytes=4096, split_size_bytes=5000)) as w:
        for topic, type_name in TOPICS.items():
            w.add_topic(topic, type_name)
        for i in range(400):
            topic = list(TOPICS)[i % 4]
            w.write(topic, T0 + i, serialize_message(make(topic, i)))
        assert any("too small" in x for x in w.warnings)
    meta = read_metadata(bag)
    assert sum(f.message_count for f in meta.files) == 400
    # each file carries at least as many message bytes as its ~20 kB overhead: 400 messages of ~250 bytes
    # (100 kB) make a handful of files, not hundreds
    assert 2 <= len(meta.files) <= 8


def test_split_by_duration_starts_a_new_file_every_interval_of_log_time(tmp_path):
    bag = tmp_path / "d"
    # 600 messages 1 ms apart = 0.599 s of log time; 0.2 s per file -> files start at 0, 0.2, 0.4 s
    write_sample(bag, n=600, options=WriterOptions(split_duration_s=0.2))
    meta = read_metadata(bag)
    assert [f.message_count for f in meta.files] == [200, 200, 200]
    assert all(f.duration_ns == 199_000_000 for f in meta.files)
    assert [f.starting_time_ns - T0 for f in meta.files] == [0, 200_000_000, 400_000_000]
    # every file repeats every topic's schema and channel (readable alone)
    for f in meta.files:
        with open(bag / f.path, "rb") as fh:
            assert {c.topic for c in make_reader(fh).get_summary().channels.values()} == set(TOPICS)


def test_finished_chunks_are_on_disk_before_close_and_flush_interval_bounds_the_open_chunk(tmp_path):
    now = [0.0]
    bag = tmp_path / "c"
    w = BagWriter(bag, WriterOptions(chunk_size_bytes=4096, flush_interval_s=1.0), monotonic=lambda: now[0])
    w.add_topic("/imu", "sensor_msgs/msg/Imu")
    data = serialize_message(make("/imu", 1))
    per_chunk = 4096 // len(data) + 1  # messages in one full chunk (closed when it exceeds 4096 bytes)
    for i in range(10 * per_chunk + 3):
        w.write("/imu", T0 + i, data)
    on_disk = sum(1 for _ in iter_file_records(w.current_file) if type(_).__name__ == "Message")
    assert w.message_count - per_chunk <= on_disk < w.message_count  # open chunk not yet written
    assert w.chunks_written >= 9
    now[0] = 0.99
    assert not w.flush_if_due()
    now[0] = 1.01  # the oldest unflushed message is now older than flush_interval_s
    assert w.flush_if_due()
    on_disk = sum(1 for _ in iter_file_records(w.current_file) if type(_).__name__ == "Message")
    assert on_disk == w.message_count
    w.close()


def test_bad_use_raises_clear_errors(tmp_path):
    bag = tmp_path / "e"
    w = BagWriter(bag)
    with pytest.raises(KeyError):
        w.write("/not_added", T0, b"\x00\x01\x00\x00")
    w.close()
    with pytest.raises(RuntimeError, match="closed"):
        w.write("/x", T0, b"")
    with pytest.raises(FileExistsError, match="already holds a bag"):
        BagWriter(bag)
    with pytest.raises(ValueError, match="compression"):
        WriterOptions(compression="gzip")


def test_a_type_without_installed_definition_is_recorded_with_the_given_definition(tmp_path):
    bag = tmp_path / "custom"
    definition = "float64 depth_m\nstring label\n"
    with BagWriter(bag) as w:
        w.add_topic("/foo", "nonexistent_msgs/msg/Foo", definition=definition, type_hash="")
        # CDR of {depth_m: 2.5, label: "ab"}: encapsulation header, float64, uint32 length, "ab\0"
        payload = b"\x00\x01\x00\x00" + np.float64(2.5).tobytes() + (3).to_bytes(4, "little") + b"ab\x00"
        w.write("/foo", T0, payload)
        w.add_topic("/bar", "nonexistent_msgs/msg/Bar")  # no definition anywhere: empty schema, warning
        assert any("nonexistent_msgs/msg/Bar" in x for x in w.warnings)
    (_, _, foo), = [d for d in decode_with_mcap_ros2(bag / "custom_0.mcap") if d[0].topic == "/foo"]
    assert foo.depth_m == 2.5 and foo.label == "ab"


def test_threaded_writer_accepts_writes_from_several_threads(tmp_path):
    bag = tmp_path / "t"
    tw = ThreadedBagWriter(bag, WriterOptions(chunk_size_bytes=4096))
    tw.add_topic("/imu", "sensor_msgs/msg/Imu")
    tw.add_topic("/raw", "hindrax_msgs/msg/RawDeviceData")
    imu, raw = serialize_message(make("/imu", 3)), serialize_message(make("/raw", 4))

    def producer(topic, data, base):
        for i in range(500):
            assert tw.write(topic, T0 + base + 2 * i, data)

    threads = [threading.Thread(target=producer, args=a) for a in (("/imu", imu, 0), ("/raw", raw, 1))]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    meta = tw.close()
    assert tw.dropped == 0 and tw.error is None
    assert {t.name: t.message_count for t in meta.topics} == {"/imu": 500, "/raw": 500}
    assert sum(1 for _ in BagReader(bag).messages()) == 1000


def test_threaded_writer_drops_beyond_its_queue_and_close_drains_at_once(tmp_path):
    # the writer thread drains the queue every drain_period_s; with a period far longer than the test, nothing is
    # taken before close(): the queue bound counts the drops, and close() wakes the thread and writes the rest
    bag = tmp_path / "q"
    tw = ThreadedBagWriter(bag, WriterOptions(chunk_size_bytes=4096), max_queue=20, drain_period_s=3600.0)
    tw.add_topic("/imu", "sensor_msgs/msg/Imu")  # one queue slot
    data = serialize_message(make("/imu", 3))
    accepted = [tw.write("/imu", T0 + i, data) for i in range(30)]
    assert accepted == [True] * 19 + [False] * 11 and tw.dropped == 11 and tw.pending == 20
    meta = tw.close(timeout_s=20.0)  # TimeoutError if close waited for the hour-long drain period
    assert {t.name: t.message_count for t in meta.topics} == {"/imu": 19}
    assert [m.log_time_ns for m in BagReader(bag).messages()] == [T0 + i for i in range(19)]


def test_threaded_writer_writes_without_close_within_its_drain_period(tmp_path):
    bag = tmp_path / "d"
    tw = ThreadedBagWriter(bag, WriterOptions(chunk_size_bytes=4096), drain_period_s=0.05)
    tw.add_topic("/imu", "sensor_msgs/msg/Imu")
    data = serialize_message(make("/imu", 3))
    for i in range(10):
        tw.write("/imu", T0 + i, data)
    wait_until(lambda: tw.topic_counts().get("/imu") == 10, 10, None, "10 messages written by the writer thread")
    assert tw.pending == 0
    tw.close()
