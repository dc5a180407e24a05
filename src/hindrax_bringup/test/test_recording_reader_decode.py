"""BagReader.decoded: messages decoded from the bag's own ros2msg schemas through mcap_ros2's public
DecoderFactory; a schema that does not parse or an encoding without decoder is a one-line BagError."""
from __future__ import annotations

import struct

import pytest
from mcap.writer import Writer

from hindrax_bringup.recording.reader import BagError, BagReader


def cdr_string(text: str) -> bytes:
    """std_msgs/msg/String in CDR (little-endian encapsulation header, uint32 length incl. NUL, bytes, NUL)."""
    raw = text.encode() + b"\0"
    return b"\x00\x01\x00\x00" + struct.pack("<I", len(raw)) + raw


def write_mcap(path, channels) -> None:
    """channels: [(topic, type, definition, message encoding, [payload, ...])]."""
    with open(path, "wb") as fh:
        w = Writer(fh)
        w.start()
        t = 1
        for topic, type_name, definition, encoding, payloads in channels:
            sid = w.register_schema(name=type_name, encoding="ros2msg", data=definition.encode())
            cid = w.register_channel(topic=topic, message_encoding=encoding, schema_id=sid)
            for p in payloads:
                w.add_message(channel_id=cid, log_time=t, publish_time=t, data=p)
                t += 1
        w.finish()


def test_decodes_two_topics_of_the_same_type(tmp_path):
    bag = tmp_path / "ok.mcap"
    write_mcap(bag, [("/a", "std_msgs/msg/String", "string data", "cdr", [cdr_string("one"), cdr_string("two")]),
                     ("/b", "std_msgs/msg/String", "string data", "cdr", [cdr_string("three")])])
    got = [(m.topic, d.data) for m, d in BagReader(bag).decoded()]
    assert got == [("/a", "one"), ("/a", "two"), ("/b", "three")]


def test_unparsable_definition_names_the_topic(tmp_path):
    bag = tmp_path / "bad.mcap"
    write_mcap(bag, [("/bad", "pkg/msg/Bad", "this is not ( a definition", "cdr", [b"\x00\x01\x00\x00"])])
    with pytest.raises(BagError, match=r"^/bad: stored definition of pkg/msg/Bad does not parse"):
        list(BagReader(bag).decoded())


def test_message_encoding_without_decoder(tmp_path):
    bag = tmp_path / "json.mcap"
    write_mcap(bag, [("/j", "std_msgs/msg/String", "string data", "json", [b'{"data": "x"}'])])
    with pytest.raises(BagError, match=r"^/j: mcap_ros2 has no decoder for 'json' messages"):
        list(BagReader(bag).decoded())


def _same_fields(lean, ref, where: str) -> None:
    """Every field of ``ref`` (mcap_ros2's object) has the same value in ``lean`` (rosbags' object),
    recursively."""
    import numpy as np

    for name in ref.__slots__:
        a, b = getattr(lean, name), getattr(ref, name)
        if hasattr(b, "__slots__"):
            _same_fields(a, b, f"{where}.{name}")
        elif isinstance(b, list) and b and hasattr(b[0], "__slots__"):
            assert len(a) == len(b), f"{where}.{name}"
            for i, (x, y) in enumerate(zip(a, b)):
                _same_fields(x, y, f"{where}.{name}[{i}]")
        elif isinstance(b, (list, bytes)):
            assert np.array_equal(np.asarray(a), np.asarray(list(b)),
                                  equal_nan=True), f"{where}.{name}"
        else:
            assert a == b or (a != a and b != b), f"{where}.{name}: {a!r} != {b!r}"


def test_lean_installed_messages_read_what_the_bags_definitions_say():
    """installed_messages(lean=True), the campaign reader's fast path (rosbags' decoder of the
    installed definitions), gives field by field the values mcap_ros2 decodes from the bag's own
    definitions, for every topic of a bag
    recorded through the driver graph, in the same order."""
    from pathlib import Path

    bag = BagReader(Path(__file__).parent / "data" / "sim_drivers_3s")
    topics = [t for t, c in bag.channels.items() if c.message_count]
    lean, ref = list(bag.installed_messages(topics, lean=True)), list(bag.decoded(topics))
    assert [m for m, _ in lean] == [m for m, _ in ref]
    assert {m.topic for m, _ in lean} >= {"/imu/data_raw", "/dvl/data", "/thrusters/pulse_width",
                                           "/pressure/fluid_pressure", "/ping/altitude",
                                           "/identification/status"}
    for (m, a), (_, b) in zip(lean, ref):
        assert not hasattr(a, "get_fields_and_field_types"), "an rclpy object: not the lean decoder"
        _same_fields(a, b, m.topic)
