"""Tests of the Ping1D protocol codec and its I/O-free emulator.

Expected bytes are the byte-exact vectors of docs/devices.md §2.5; payload layouts
and sizes come from the table in §2.4; emulator behaviour from the §2.6 checklist.
"""

import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hindrax_drivers.ping1d.emulator import Ping1dEmulator, Ping1dSettings, Ping1dTruth
from hindrax_drivers.ping1d.protocol import (
    PAYLOAD_TYPES,
    Ack,
    ContinuousStart,
    ContinuousStop,
    DeviceInformation,
    Distance,
    DistanceSimple,
    FirmwareVersion,
    GainSetting,
    GeneralInfo,
    GeneralRequest,
    ModeAuto,
    Nack,
    Ping1dFramer,
    Ping1dId,
    Ping1dMessage,
    Ping1dParseError,
    PingEnable,
    PingInterval,
    ProcessorTemperature,
    Profile,
    ProtocolVersion,
    Range,
    SetGainSetting,
    SetModeAuto,
    SetPingEnable,
    SetPingInterval,
    SetRange,
    SetSpeedOfSound,
    SpeedOfSound,
    checksum,
    decode_frame,
    decode_message,
    encode_frame,
    request_frame,
)


def h(text: str) -> bytes:
    return bytes.fromhex(text)


# docs/devices.md §2.5 (verified with the checksum rule)
REQ_PROTOCOL_VERSION = h("42 52 02 00 06 00 00 00 05 00 a1 00")
REPLY_PROTOCOL_VERSION_123 = h("42 52 04 00 05 00 00 00 01 02 03 00 a3 00")
GENERAL_REQUEST_1211 = h("42 52 02 00 06 00 00 00 bb 04 5b 01")
LEGACY_REQUEST_1211 = h("42 52 00 00 bb 04 00 00 53 01")
DISTANCE_SIMPLE_1234MM_87PCT_SRC1 = h("42 52 05 00 bb 04 01 00 d2 04 00 00 57 86 02")
SET_SPEED_OF_SOUND_1480000 = h("42 52 04 00 ea 03 00 00 40 95 16 00 70 02")
SET_PING_INTERVAL_100MS = h("42 52 02 00 ec 03 00 00 64 00 e9 01")
ACK_1002 = h("42 52 02 00 01 00 01 00 ea 03 85 01")
CONTINUOUS_START_1300 = h("42 52 02 00 78 05 00 00 14 05 2c 01")
ALL_VECTORS = [REQ_PROTOCOL_VERSION, REPLY_PROTOCOL_VERSION_123, GENERAL_REQUEST_1211,
               LEGACY_REQUEST_1211, DISTANCE_SIMPLE_1234MM_87PCT_SRC1, SET_SPEED_OF_SOUND_1480000,
               SET_PING_INTERVAL_100MS, ACK_1002, CONTINUOUS_START_1300]


# ------------------------------------------------------------------------------------------------
# Byte-exact vectors (§2.5)
# ------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("frame", ALL_VECTORS)
def test_vector_checksum_is_sum_of_preceding_bytes(frame):
    assert checksum(frame[:-2]) == struct.unpack("<H", frame[-2:])[0]
    assert decode_frame(frame).encode() == frame


def test_encode_vectors():
    assert request_frame(Ping1dId.PROTOCOL_VERSION) == REQ_PROTOCOL_VERSION
    assert ProtocolVersion(1, 2, 3).encode() == REPLY_PROTOCOL_VERSION_123
    assert request_frame(1211) == GENERAL_REQUEST_1211
    assert GeneralRequest(1211).encode() == GENERAL_REQUEST_1211
    assert encode_frame(1211) == LEGACY_REQUEST_1211
    assert DistanceSimple(distance_m=1.234, confidence_pct=87).encode(src_device_id=1) \
        == DISTANCE_SIMPLE_1234MM_87PCT_SRC1
    assert SetSpeedOfSound(speed_of_sound_m_s=1480.0).encode() == SET_SPEED_OF_SOUND_1480000
    assert SetPingInterval(ping_interval_s=0.1).encode() == SET_PING_INTERVAL_100MS
    assert Ack(1002).encode(src_device_id=1) == ACK_1002
    assert ContinuousStart(1300).encode() == CONTINUOUS_START_1300


def test_decode_vectors():
    assert decode_message(REPLY_PROTOCOL_VERSION_123) == ProtocolVersion(1, 2, 3, 0)
    d = decode_message(DISTANCE_SIMPLE_1234MM_87PCT_SRC1)
    assert d == DistanceSimple(1.234, 87)
    assert decode_frame(DISTANCE_SIMPLE_1234MM_87PCT_SRC1).src_device_id == 1
    assert decode_message(SET_SPEED_OF_SOUND_1480000).speed_of_sound_m_s == 1480.0
    assert decode_message(SET_PING_INTERVAL_100MS).ping_interval_s == pytest.approx(0.1)
    assert decode_message(ACK_1002) == Ack(1002)
    assert decode_message(CONTINUOUS_START_1300) == ContinuousStart(1300)
    legacy = decode_frame(LEGACY_REQUEST_1211)
    assert legacy.message_id == 1211 and legacy.payload == b""


# ------------------------------------------------------------------------------------------------
# Payload layouts (§2.4)
# ------------------------------------------------------------------------------------------------


def test_payload_sizes_match_table():
    sizes = {1: 2, 4: 6, 5: 4, 6: 2, 1000: 1, 1001: 8, 1002: 4, 1003: 1, 1004: 2, 1005: 1, 1006: 1,
             1100: 0, 1200: 6, 1201: 1, 1202: 2, 1203: 4, 1204: 8, 1205: 1, 1206: 2, 1207: 4,
             1208: 2, 1210: 10, 1211: 5, 1212: 24, 1213: 2, 1214: 2, 1215: 1, 1400: 2, 1401: 2}
    for mid, size in sizes.items():
        cls = PAYLOAD_TYPES[mid]
        assert struct.calcsize("<" + "".join(c for c, _ in cls.LAYOUT)) == size, cls.__name__


def test_distance_field_offsets():
    """1212 layout @0 u32 mm, @4 u16 %, @6 u16 µs, @8 u32, @12 u32 mm, @16 u32 mm, @20 u32."""
    payload = Distance(2.5, 90, 120e-6, 77, 0.5, 10.0, 3).pack()
    assert len(payload) == 24
    assert struct.unpack_from("<I", payload, 0)[0] == 2500
    assert struct.unpack_from("<H", payload, 4)[0] == 90
    assert struct.unpack_from("<H", payload, 6)[0] == 120
    assert struct.unpack_from("<I", payload, 8)[0] == 77
    assert struct.unpack_from("<I", payload, 12)[0] == 500
    assert struct.unpack_from("<I", payload, 16)[0] == 10000
    assert struct.unpack_from("<I", payload, 20)[0] == 3


def test_profile_layout_and_length_check():
    p = Profile(2.5, 90, 120e-6, 77, 0.5, 10.0, 3, bytes(range(200)))
    payload = p.pack()
    assert payload[:24] == Distance(2.5, 90, 120e-6, 77, 0.5, 10.0, 3).pack()
    assert struct.unpack_from("<H", payload, 24)[0] == 200 and payload[26:] == bytes(range(200))
    assert Profile.unpack(payload) == p
    with pytest.raises(Ping1dParseError, match="profile_data_length"):
        Profile.unpack(payload[:-1])


def test_gain_setting_get_is_u32_but_set_is_u8():
    assert len(GainSetting(5).pack()) == 4 and len(SetGainSetting(5).pack()) == 1


def test_nack_text_without_nul_and_with_nul():
    assert decode_message(encode_frame(2, struct.pack("<H", 1002) + b"bad value")) == Nack(1002, "bad value")
    assert decode_message(encode_frame(2, struct.pack("<H", 7) + b"x\x00")) == Nack(7, "x")


def test_general_info_units():
    gi = decode_message(encode_frame(1210, struct.pack("<HHHHBB", 3, 29, 5012, 100, 4, 1)))
    assert gi == GeneralInfo(3, 29, 5.012, 0.1, 4, True)


def test_processor_temperature_is_u16_centidegrees():
    """The brping 0.2.x S500 overlay makes 1213 a u32 (§2.7); Ping1D uses u16 cC (§2.4)."""
    msg = decode_message(encode_frame(1213, struct.pack("<H", 3456)))
    assert msg == ProcessorTemperature(34.56)
    with pytest.raises(Ping1dParseError):
        decode_message(encode_frame(1213, struct.pack("<I", 3456)))


@pytest.mark.parametrize("bad", [
    lambda: SetSpeedOfSound(-1.0).pack(),
    lambda: SetSpeedOfSound(float("nan")).pack(),
    lambda: SetPingInterval(70.0).pack(),  # 70000 ms does not fit u16
    lambda: SetGainSetting(2.5).pack(),
    lambda: encode_frame(70000, b""),
    lambda: encode_frame(5, b"", src_device_id=256),
    lambda: Nack(1, "é").pack(),
])
def test_encode_rejects_values_that_do_not_fit(bad):
    with pytest.raises(ValueError):
        bad()


@pytest.mark.parametrize("frame,match", [
    (b"BR\x00\x00", "too short"),
    (b"XR\x00\x00\x05\x00\x00\x00\x00\x00", "BR"),
    (REQ_PROTOCOL_VERSION[:-1] + b"\x01", "checksum"),
    (REQ_PROTOCOL_VERSION + b"\x00", "inconsistent"),
])
def test_decode_frame_errors(frame, match):
    with pytest.raises(Ping1dParseError, match=match):
        decode_frame(frame)


def test_decode_message_errors():
    with pytest.raises(Ping1dParseError, match="unknown message id"):
        decode_message(encode_frame(4242, b""))
    with pytest.raises(Ping1dParseError, match="expected 5"):
        decode_message(LEGACY_REQUEST_1211)  # an empty 1211 is a request, not a reply
    with pytest.raises(Ping1dParseError, match="0 or 1"):
        decode_message(encode_frame(1205, b"\x02"))


_ROUND_TRIP = [
    Ack(1002), Nack(1002, "value out of range"), DeviceInformation(1, 2, 3, 29, 1),
    ProtocolVersion(1, 2, 3), GeneralRequest(1212), SetRange(0.5, 12.0), SetSpeedOfSound(1512.345),
    SetModeAuto(False), SetPingInterval(0.066), SetGainSetting(6), SetPingEnable(True),
    FirmwareVersion(1, 1, 3, 29), SpeedOfSound(1484.0), Range(0.0, 30.0), ModeAuto(True),
    PingInterval(0.2), GainSetting(4), PingEnable(False), ContinuousStop(1300),
    Distance(12.345, 100, 0.000233, 4294967295, 1.0, 99.999, 6),
]


@pytest.mark.parametrize("msg", _ROUND_TRIP, ids=lambda m: type(m).__name__)
def test_round_trip(msg):
    frame = msg.encode(src_device_id=1, dst_device_id=0)
    assert decode_message(frame) == msg


@settings(max_examples=200, deadline=None)
@given(distance_mm=st.integers(0, 2**32 - 1), confidence=st.integers(0, 255))
def test_distance_simple_round_trip_exact_mm(distance_mm, confidence):
    msg = DistanceSimple(distance_mm / 1000, confidence)
    back = decode_message(msg.encode())
    assert round(back.distance_m * 1000) == distance_mm and back.confidence_pct == confidence


# ------------------------------------------------------------------------------------------------
# Streaming framer
# ------------------------------------------------------------------------------------------------


def test_framer_resynchronises_after_garbage_and_counts():
    f = Ping1dFramer()
    stream = b"UUU\x00\xffjunk" + GENERAL_REQUEST_1211 + b"B" + ACK_1002
    out = f.feed(stream)
    assert [m.encode() for m in out] == [GENERAL_REQUEST_1211, ACK_1002]
    assert f.discarded_bytes == 9 + 1 and f.bad_checksums == 0 and f.frames_ok == 2  # 9 junk + lone B


def test_framer_bad_checksum_and_truncated_frames_are_counted_and_recovered():
    f = Ping1dFramer()
    bad = ACK_1002[:-1] + bytes([ACK_1002[-1] ^ 0xFF])
    truncated = DISTANCE_SIMPLE_1234MM_87PCT_SRC1[:9]
    out = f.feed(bad + truncated + CONTINUOUS_START_1300 + SET_PING_INTERVAL_100MS)
    assert [m.encode() for m in out] == [CONTINUOUS_START_1300, SET_PING_INTERVAL_100MS]
    assert f.bad_checksums == 2  # the corrupted ack and the truncated frame
    assert f.discarded_bytes == len(bad) + len(truncated)


def test_framer_oversize_header_is_a_false_start():
    f = Ping1dFramer(max_payload_bytes=64)
    out = f.feed(b"BR\xff\xff" + ACK_1002)
    assert [m.encode() for m in out] == [ACK_1002]
    assert f.oversize_headers == 1 and f.discarded_bytes == 4


def test_framer_byte_by_byte():
    f = Ping1dFramer()
    out = []
    for b in DISTANCE_SIMPLE_1234MM_87PCT_SRC1 * 3:
        out += f.feed(bytes([b]))
    assert len(out) == 3 and all(m.message_id == 1211 and m.src_device_id == 1 for m in out)


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=400), st.lists(st.integers(min_value=1, max_value=40), max_size=20))
def test_framer_arbitrary_bytes_never_raise_and_are_chunking_invariant(data, cuts):
    ref_f = Ping1dFramer(max_payload_bytes=128)
    ref = ref_f.feed(data)
    f = Ping1dFramer(max_payload_bytes=128)
    got, pos = [], 0
    for c in cuts:
        got += f.feed(data[pos:pos + c])
        pos += c
    got += f.feed(data[pos:])
    assert got == ref
    assert (f.discarded_bytes, f.bad_checksums) == (ref_f.discarded_bytes, ref_f.bad_checksums)
    for m in ref:  # every returned frame is valid
        assert decode_frame(m.encode()) == m


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=60).filter(lambda b: b"B" not in b), st.sampled_from(ALL_VECTORS),
       st.binary(max_size=60).filter(lambda b: b"B" not in b))
def test_framer_finds_valid_frame_inside_garbage(before, frame, after):
    f = Ping1dFramer()
    out = f.feed(before + frame + after)
    assert [m.encode() for m in out] == [frame]
    assert f.discarded_bytes == len(before) + len(after)


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=80))
def test_decode_arbitrary_bytes_raises_only_parse_error(data):
    try:
        decode_message(data)
    except Ping1dParseError:
        pass


@settings(max_examples=300, deadline=None)
@given(st.sampled_from(sorted(PAYLOAD_TYPES)), st.binary(max_size=40))
def test_unpack_arbitrary_payload_raises_only_parse_error(mid, payload):
    try:
        decode_message(Ping1dMessage(mid, payload))
    except Ping1dParseError:
        pass


# ------------------------------------------------------------------------------------------------
# Emulator (I/O-free)
# ------------------------------------------------------------------------------------------------


def _exchange(emu, data: bytes, t_s: float, framer=None):
    emu.feed_host_bytes(data)
    return [decode_message(m) for m in (framer or Ping1dFramer()).feed(emu.poll(t_s))]


def test_emulator_answers_both_request_forms_byte_exact():
    emu = Ping1dEmulator(Ping1dTruth(altitude_m=1.234, confidence_pct=87))
    emu.poll(0.0)
    emu.feed_host_bytes(b"U" + GENERAL_REQUEST_1211)  # leading auto-baud U (§2.1)
    assert emu.poll(0.01) == DISTANCE_SIMPLE_1234MM_87PCT_SRC1  # §2.5 reply vector
    emu.feed_host_bytes(LEGACY_REQUEST_1211)
    assert emu.poll(0.02) == DISTANCE_SIMPLE_1234MM_87PCT_SRC1
    assert emu.framer.discarded_bytes == 1  # the U


def test_emulator_protocol_version_reply_vector():
    emu = Ping1dEmulator(Ping1dTruth(), settings=Ping1dSettings(device_id=0), protocol_version=(1, 2, 3))
    emu.feed_host_bytes(REQ_PROTOCOL_VERSION)
    assert emu.poll(0.0) == REPLY_PROTOCOL_VERSION_123


def test_emulator_set_speed_of_sound_acks_and_scales_distance():
    emu = Ping1dEmulator(Ping1dTruth(altitude_m=3.0), true_speed_of_sound_m_s=1500.0)
    emu.poll(0.0)
    emu.feed_host_bytes(SET_SPEED_OF_SOUND_1480000)
    assert emu.poll(0.01) == ACK_1002  # §2.5 ack vector
    assert emu.settings.speed_of_sound_m_s == 1480.0
    replies = _exchange(emu, request_frame(1212), 0.2)
    # distance = true range x configured c / true c (§2.6), 1 mm resolution
    assert replies[0].distance_m == pytest.approx(round(3.0 * 1480 / 1500, 3), abs=1e-9)
    assert replies[0].confidence_pct == 100
    assert _exchange(emu, encode_frame(1203), 0.21) == [SpeedOfSound(1480.0)]


def test_emulator_continuous_profile_stream_at_ping_interval():
    emu = Ping1dEmulator(Ping1dTruth(altitude_m=4.0))
    framer = Ping1dFramer()
    emu.poll(0.0)
    emu.feed_host_bytes(SET_PING_INTERVAL_100MS + CONTINUOUS_START_1300)
    msgs = []
    for k in range(1, 101):
        msgs += [decode_message(m) for m in framer.feed(emu.poll(0.01 * k))]
    profiles = [m for m in msgs if isinstance(m, Profile)]
    assert Ack(1004) in msgs and Ack(1400) in msgs
    assert len(profiles) == 10  # pings at 0.1 .. 1.0 s
    assert [p.ping_number for p in profiles] == list(range(profiles[0].ping_number,
                                                           profiles[0].ping_number + 10))
    p = profiles[-1]
    assert p.distance_m == pytest.approx(4.0) and len(p.profile_data) == 200
    # strongest sample at the echo: sample centres span scan_start .. scan_start + scan_length
    peak = max(range(200), key=lambda i: p.profile_data[i])
    assert p.scan_start_m + (peak + 0.5) * p.scan_length_m / 200 == pytest.approx(4.0, abs=p.scan_length_m / 200)
    emu.feed_host_bytes(ContinuousStop(1300).encode())
    emu.poll(1.01)
    assert not any(isinstance(decode_message(m), Profile) for m in framer.feed(emu.poll(1.5)))


def test_emulator_nacks_and_validation():
    emu = Ping1dEmulator(Ping1dTruth())
    replies = _exchange(emu, encode_frame(4242, b"") + SetGainSetting(7).encode()
                        + SetRange(0.0, 0.5).encode() + request_frame(9999)
                        + encode_frame(1002, b"\x01") + ContinuousStart(1215).encode(), 0.0)
    assert [type(r) for r in replies] == [Nack] * 6
    assert [r.nacked_id for r in replies] == [4242, 1005, 1001, 9999, 1002, 1400]
    assert emu.settings.gain_setting == 6 and emu.settings.scan_length_m == 30.0


def test_emulator_manual_mode_range_window_and_settings():
    emu = Ping1dEmulator(Ping1dTruth(altitude_m=8.0, confidence_pct=70))
    emu.poll(0.0)
    replies = _exchange(emu, SetModeAuto(False).encode() + SetRange(0.0, 5.0).encode(), 0.01)
    assert replies == [Ack(1003), Ack(1001)]
    d = _exchange(emu, request_frame(1212), 0.5)[0]
    assert (d.distance_m, d.confidence_pct) == (0.0, 0)  # echo outside the 0-5 m window
    assert (d.scan_start_m, d.scan_length_m) == (0.0, 5.0)
    _exchange(emu, SetRange(5.0, 5.0).encode(), 0.51)
    d = _exchange(emu, request_frame(1212), 1.0)[0]
    assert (d.distance_m, d.confidence_pct) == (8.0, 70)
    gi = _exchange(emu, request_frame(1210), 1.01)[0]
    assert gi.mode_auto is False and gi.ping_interval_s == pytest.approx(0.1)


def test_emulator_ping_enable_stops_pinging():
    emu = Ping1dEmulator(Ping1dTruth())
    emu.poll(0.0)
    n0 = _exchange(emu, request_frame(1212), 0.35)[0].ping_number
    _exchange(emu, SetPingEnable(False).encode(), 0.36)
    n1 = _exchange(emu, request_frame(1212), 1.0)[0].ping_number
    n2 = _exchange(emu, request_frame(1212), 2.0)[0].ping_number
    assert n0 == 4 and n1 == n0 and n2 == n1  # pings at 0, .1, .2, .3; none while disabled
    assert _exchange(emu, request_frame(1215), 2.01) == [PingEnable(False)]


def test_emulator_destination_filter():
    emu = Ping1dEmulator(Ping1dTruth())
    emu.poll(0.0)
    assert _exchange(emu, request_frame(1211, src_device_id=0, dst_device_id=5), 0.01) == []
    assert len(_exchange(emu, request_frame(1211, src_device_id=0, dst_device_id=255), 0.02)) == 1
    reply = Ping1dFramer().feed((emu.feed_host_bytes(request_frame(1211, src_device_id=7,
                                                                   dst_device_id=1)), emu.poll(0.03))[1])
    assert reply[0].dst_device_id == 7 and reply[0].src_device_id == 1


def test_emulator_faults():
    truth = {"v": Ping1dTruth(altitude_m=2.0)}
    emu = Ping1dEmulator(lambda t: truth["v"])
    framer = Ping1dFramer()
    emu.poll(0.0)
    # bad checksum from the host: frame dropped, no reply
    bad = GENERAL_REQUEST_1211[:-1] + b"\x00"
    assert _exchange(emu, bad, 0.01) == [] and emu.framer.bad_checksums == 1
    # garbage
    emu.faults.inject_garbage(b"\x00\x01\x02\x03")
    assert len(_exchange(emu, request_frame(1211), 0.02, framer)) == 1 and framer.discarded_bytes == 4
    # corrupted checksum and truncated replies are counted by the host framer, not fatal
    emu.faults.corrupt_checksum(1)
    assert _exchange(emu, request_frame(1211), 0.03, framer) == [] and framer.bad_checksums == 1
    emu.faults.truncate(1)
    out = _exchange(emu, request_frame(1211) + request_frame(1212), 0.04, framer)
    assert [type(m) for m in out] == [Distance]
    # stuck values
    emu.faults.set_stuck(True)
    truth["v"] = Ping1dTruth(altitude_m=9.0)
    assert _exchange(emu, request_frame(1211), 0.5, framer)[0].distance_m == 2.0
    emu.faults.set_stuck(False)
    assert _exchange(emu, request_frame(1211), 0.8, framer)[0].distance_m == 9.0
    # zero confidence
    emu.set_zero_confidence(True)
    assert _exchange(emu, request_frame(1211), 1.0, framer)[0].confidence_pct == 0
    emu.set_zero_confidence(False)
    # disconnect: deaf and silent
    emu.faults.set_disconnected(True)
    emu.feed_host_bytes(request_frame(1211))
    assert emu.poll(1.1) == b""
    emu.faults.set_disconnected(False)
    assert len(_exchange(emu, request_frame(1211), 1.2, framer)) == 1


@settings(max_examples=300, deadline=None)
@given(st.sampled_from([1, 2, 3, 5, 1200, 1203, 1210, 1211, 1212, 1300, 1400, 65535]), st.binary(max_size=300),
       st.binary(max_size=40))
def test_stream_decoder_never_raises_on_checksum_valid_frames_with_arbitrary_payloads(mid, payload, noise):
    """The node's decoding path (Ping1dStreamDecoder) on frames whose checksum is right around any payload:
    every frame is either decoded or counted as an error, nothing raises."""
    from hindrax_drivers.ping1d.protocol import encode_frame
    from hindrax_drivers.ping1d.stream import Ping1dStreamDecoder

    decoder = Ping1dStreamDecoder()
    decoder.feed(noise + encode_frame(mid, payload) + noise)
