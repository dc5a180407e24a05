"""Tests of the DVL-75 protocol layer and its I/O-free emulator.

Expected values come from docs/devices.md (§0, §1.2-§1.6: real captures [D21],
vendor examples, factory defaults) and from independent geometry (rotation of a body velocity, the
Cerulean Euler->quaternion formula of §1.5), never from the code under test.
"""

import math
from dataclasses import replace

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hindrax_drivers.dvl75.emulator import Dvl75Emulator, DvlFlash, DvlTruth
from hindrax_drivers.dvl75.protocol import (
    DvlExtended,
    DvlGprmc,
    DvlLineFramer,
    DvlParseError,
    DvlPositionDelta,
    DvlText,
    DvlUnknown,
    cmd_set_sensor_orientation,
    cmd_set_speed_of_sound,
    cmd_send,
    format_dvext,
    format_dvpdl,
    format_gprmc,
    format_sentence,
    nmea_checksum,
    parse_command,
    parse_line,
    split_sentence,
    startup_commands,
)

# Real captures, docs/devices.md §1.2 [D21].
PDL_1 = b"$DVPDL,160401000,100000,0.000000,-0.000000,-0.000000,0.000,-0.000,-0.000,0*55"
PDL_2 = b"$DVPDL,1398604000,50000,0.000000,-0.000000,-0.000000,-0.003,0.017,0.002,100*79"
EXT_1 = (b"$DVEXT,F,X,3330,-1.8,2.4,259.5,-1175,0.000,0.00,-0.000,0.000,0.000000000,0.000000000,"
         b"0.100,0.091711,0.019853,0.017436,-0.995435,25,25,25,25,F,F,F,F,0.0000,0.0000,0.0000,"
         b"0.0000,-1.000,-1.000,-1.000,-1.000,*54")
# Vendor doc example with a wrong checksum (docs/devices.md §0 item 2: printed *22, computed 6E).
DOC_PDL_BODY = b"DVPDL,101234000,50000,0.001263,-0.019663,-0.745226,-0.000,0.001,-0.005,100"
# Vendor doc $GPRMC example, checksum correct (docs/devices.md §1.3.3).
DOC_RMC = b"$GPRMC,192921.000,A,4458.1690,N,09331.0392,W,0.01,36.57,280720,,,D*43"


def _with_checksum(body: bytes) -> bytes:
    return b"$" + body + b"*%02X" % nmea_checksum(body)


# ------------------------------------------------------------------------------------------------
# Checksum and vendor-document errors
# ------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("line,expected", [(PDL_1, 0x55), (PDL_2, 0x79), (EXT_1, 0x54)])
def test_checksum_of_real_captures(line, expected):
    body = line[1:line.index(b"*")]
    assert nmea_checksum(body) == expected


def test_vendor_doc_dvpdl_example_has_wrong_checksum_and_is_rejected():
    assert nmea_checksum(DOC_PDL_BODY) == 0x6E
    with pytest.raises(DvlParseError, match="checksum"):
        parse_line(b"$" + DOC_PDL_BODY + b"*22")
    rec = parse_line(b"$" + DOC_PDL_BODY + b"*6E")
    assert isinstance(rec, DvlPositionDelta)
    assert rec.delta_yaw_rad == pytest.approx(-0.745226)


def test_lowercase_hex_checksum_is_accepted():
    assert isinstance(parse_line(b"$" + DOC_PDL_BODY + b"*6e"), DvlPositionDelta)


def test_format_sentence_uppercase_hex_and_crlf():
    assert format_sentence("DVPDL,1398604000,50000,0.000000,-0.000000,-0.000000,-0.003,0.017,0.002,100") \
        == PDL_2 + b"\r\n"
    with pytest.raises(ValueError):
        format_sentence("BAD*BODY")


# ------------------------------------------------------------------------------------------------
# $DVPDL
# ------------------------------------------------------------------------------------------------


def test_parse_dvpdl_capture_zero_confidence():
    rec = parse_line(PDL_1 + b"\r\n")
    assert isinstance(rec, DvlPositionDelta)
    assert rec.time_since_boot_s == pytest.approx(160.401)
    assert rec.delta_time_s == pytest.approx(0.1)  # 100000 µs = 10 Hz
    assert rec.confidence_pct == 0
    assert (rec.delta_x_m, rec.delta_y_m, rec.delta_z_m) == (0.0, 0.0, 0.0)
    assert rec.velocity_frd_m_s() is None  # c = 0: fields after dtu are garbage [D4b]


def test_parse_dvpdl_capture_full_confidence_and_velocity():
    rec = parse_line(PDL_2)
    assert rec.time_since_boot_s == pytest.approx(1398.604)
    assert rec.delta_time_s == pytest.approx(0.05)  # 20 Hz
    assert (rec.delta_x_m, rec.delta_y_m, rec.delta_z_m) == pytest.approx((-0.003, 0.017, 0.002))
    assert rec.confidence_pct == 100
    # velocity = pd / (dtu * 1e-6) ([D22], docs/devices.md §1.3.1)
    assert rec.velocity_frd_m_s() == pytest.approx((-0.06, 0.34, 0.04))


@pytest.mark.parametrize("bad", [
    b"DVPDL,1,2,0,0,0,0,0,0",  # 8 data fields
    b"DVPDL,1,2,0,0,0,0,0,0,100,5",  # 10 data fields
    b"DVPDL,-1,2,0,0,0,0,0,0,100",  # negative time
    b"DVPDL,1,2,0,0,0,0,0,0,101",  # confidence > 100
    b"DVPDL,1,2,0,0,0,0,0,nan,100",  # not a decimal number
    b"DVPDL,1,2,0,0,0,0,0,1_0,100",  # python-only literal
    b"DVPDL,1.5,2,0,0,0,0,0,0,100",  # tu must be an integer
])
def test_dvpdl_malformed_is_rejected(bad):
    with pytest.raises(DvlParseError):
        parse_line(_with_checksum(bad))


def test_dvpdl_without_checksum_is_rejected():
    with pytest.raises(DvlParseError, match="without checksum"):
        parse_line(PDL_2[:PDL_2.index(b"*")])


# ------------------------------------------------------------------------------------------------
# $DVEXT
# ------------------------------------------------------------------------------------------------


def test_parse_dvext_capture_every_field():
    rec = parse_line(EXT_1 + b"\r\n")
    assert isinstance(rec, DvlExtended)
    assert rec.locked is False
    assert rec.gps_status == "X"
    assert rec.imu_calibration == (3, 3, 3, 0) and rec.imu_calibration_raw == "3330"
    assert rec.roll_rad == pytest.approx(math.radians(-1.8))
    assert rec.pitch_rad == pytest.approx(math.radians(2.4))
    assert rec.heading_rad == pytest.approx(math.radians(259.5))
    assert rec.data_skips == -1175  # signed (docs/devices.md §1.3.2 field 7)
    assert rec.velocity_up_m_s == 0.0 and rec.altitude_m == 0.0
    assert rec.velocity_north_m_s == 0.0 and math.copysign(1, rec.velocity_north_m_s) == -1
    assert rec.velocity_east_m_s == 0.0
    assert rec.latitude_deg == 0.0 and rec.longitude_deg == 0.0
    assert rec.ekf_elapsed_time_s == pytest.approx(0.1)
    assert rec.orientation_wxyz == pytest.approx((0.091711, 0.019853, 0.017436, -0.995435))
    assert rec.beam_gain_db == (25, 25, 25, 25)
    assert rec.beam_locked == (False,) * 4
    assert rec.beam_velocity_m_s == (0.0,) * 4
    assert rec.beam_range_m == (-1.0,) * 4  # -1.000 when unlocked [D21]


def test_dvext_capture_quaternion_agrees_with_compass_heading():
    """§1.5 [DERIVED]: the quaternion is ENU/FLU, so yaw_enu = 90 deg - compass heading."""
    rec = parse_line(EXT_1)
    w, x, y, z = rec.orientation_wxyz
    yaw_enu = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    expected = math.radians(90.0 - 259.5)
    assert abs(math.remainder(yaw_enu - expected, 2 * math.pi)) < math.radians(3.0)
    assert math.sqrt(w * w + x * x + y * y + z * z) == pytest.approx(1.0, abs=1e-5)


def test_dvext_trailing_empty_field_variants():
    body = EXT_1[1:EXT_1.index(b"*")]
    assert body.endswith(b",")
    assert isinstance(parse_line(_with_checksum(body[:-1])), DvlExtended)  # no trailing comma: ok
    with pytest.raises(DvlParseError, match="field 35"):
        parse_line(_with_checksum(body + b"7"))
    with pytest.raises(DvlParseError):
        parse_line(_with_checksum(body + b","))  # 36 data fields
    with pytest.raises(DvlParseError):
        parse_line(_with_checksum(body.replace(b"F,X,", b"Q,X,", 1)))  # lock must be T/F


def test_capture_round_trip_is_byte_exact():
    """The formatter reproduces the DVL's own number formats (captures, docs/devices.md §1.2)."""
    for line in (PDL_1, PDL_2, EXT_1):
        rec = parse_line(line)
        out = format_dvpdl(rec) if isinstance(rec, DvlPositionDelta) else format_dvext(rec)
        assert out == line + b"\r\n"


# ------------------------------------------------------------------------------------------------
# $GPRMC, text and unknown lines
# ------------------------------------------------------------------------------------------------


def test_parse_gprmc_vendor_example():
    rec = parse_line(DOC_RMC)
    assert isinstance(rec, DvlGprmc)
    assert rec.valid
    assert rec.time_of_day_s == pytest.approx(19 * 3600 + 29 * 60 + 21)
    assert rec.latitude_deg == pytest.approx(44 + 58.1690 / 60)
    assert rec.longitude_deg == pytest.approx(-(93 + 31.0392 / 60))
    assert rec.speed_m_s == pytest.approx(0.01 * 1852 / 3600)
    assert rec.track_rad == pytest.approx(math.radians(36.57))
    assert rec.date_ddmmyy == "280720"


def test_format_gprmc_dvl_style_round_trip():
    line = format_gprmc(3723.25, True, -12.0465, -77.0428, 1.0, math.radians(350.0))
    assert b",010120,,*" in line  # date always 010120, magnetic variation empty (§1.3.3)
    assert line.startswith(b"$GPRMC,010203.25,A,1202.7900,S,07702.5680,W,1.94,350.00,")
    rec = parse_line(line)
    assert rec.latitude_deg == pytest.approx(-12.0465, abs=1e-6)
    assert rec.longitude_deg == pytest.approx(-77.0428, abs=1e-6)
    invalid = parse_line(format_gprmc(0.0, False, None, None, 0.0, 0.0))
    assert not invalid.valid and invalid.latitude_deg is None


def test_text_and_unknown_lines_are_records_not_errors():
    txt = parse_line(b"$DVTXT,Boot complete, all good\r\n")
    assert isinstance(txt, DvlText) and txt.text == "Boot complete, all good" and txt.checksum_ok is None
    assert parse_line(_with_checksum(b"DVTXT,ok")).checksum_ok is True
    bare = parse_line(b"local IP address 192.168.2.3:50000")
    assert isinstance(bare, DvlText) and bare.sentence_id == ""
    nvm = parse_line(_with_checksum(b"DVNVM,key=value,other=1"))
    assert isinstance(nvm, DvlUnknown) and nvm.sentence_id == "DVNVM" and nvm.fields == ("key=value", "other=1")
    imu = parse_line(b"IMU:1,0,0,0,0.1,0.2,0.3,1,2,3,0.05")
    assert isinstance(imu, DvlUnknown) and imu.sentence_id == "IMU" and len(imu.fields) == 11
    gps = parse_line(b"GPS:$GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,*47")
    assert isinstance(gps, DvlUnknown) and gps.sentence_id == "GPS"


def test_non_utf8_bytes_raise_only_parse_error():
    with pytest.raises(DvlParseError):
        parse_line(_with_checksum(b"DVPDL,1,2,0,0,0,0,0,\xff\xfe,100"))
    with pytest.raises(DvlParseError):
        parse_line(b"\xff\xfe\x00garbage")
    txt = parse_line(b"$DVTXT,caf\xff")
    assert isinstance(txt, DvlText) and txt.text.startswith("caf")
    with pytest.raises(DvlParseError):
        parse_line(b"")
    with pytest.raises(DvlParseError):
        parse_line(b"$\x01\x02,1")


# ------------------------------------------------------------------------------------------------
# Line framer
# ------------------------------------------------------------------------------------------------


def test_framer_splits_on_lf_and_strips_cr_across_chunks():
    stream = PDL_1 + b"\r\n" + PDL_2 + b"\r\n" + EXT_1 + b"\r\n"
    f = DvlLineFramer()
    lines = []
    for i in range(0, len(stream), 7):
        lines += f.feed(stream[i:i + 7])
    assert lines == [PDL_1, PDL_2, EXT_1]
    assert f.discarded_bytes == 0


def test_framer_counts_garbage_and_resynchronises():
    f = DvlLineFramer()
    garbage = bytes(range(0x80, 0x8A))  # 10 bytes of line noise
    truncated = PDL_2[:20]  # a sentence cut short, no terminator
    lines = f.feed(garbage + PDL_1 + b"\r\n" + truncated + EXT_1 + b"\r\n" + b"\x00\x01\x02\r\n")
    assert lines == [PDL_1, EXT_1]
    assert f.discarded_bytes == 10 + 20 + 3


def test_framer_keeps_gps_retweet_and_dvtxt_dollars():
    f = DvlLineFramer()
    lines = f.feed(b"GPS:$GPGGA,1*00\n$DVTXT,costs $5\n")
    assert lines == [b"GPS:$GPGGA,1*00", b"$DVTXT,costs $5"]
    assert f.discarded_bytes == 0


def test_framer_discards_overlong_line_whole():
    f = DvlLineFramer(max_line_bytes=64)
    assert f.feed(b"$" + b"A" * 100) == []
    assert f.feed(b"B" * 10 + b"\r\n" + PDL_2[:60] + b"\n") == [PDL_2[:60]]
    assert f.discarded_bytes == 101 + 10 + 1  # the CR belongs to the discarded line


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=600), st.lists(st.integers(min_value=1, max_value=50), max_size=30))
def test_framer_arbitrary_bytes_never_raise_and_are_chunking_invariant(data, cuts):
    whole = DvlLineFramer(max_line_bytes=128)
    ref = whole.feed(data)
    chunked = DvlLineFramer(max_line_bytes=128)
    got, pos = [], 0
    for c in cuts:
        got += chunked.feed(data[pos:pos + c])
        pos += c
    got += chunked.feed(data[pos:])
    assert got == ref
    assert chunked.discarded_bytes == whole.discarded_bytes
    for line in ref:
        assert b"\n" not in line and not line.endswith(b"\r") and 0 < len(line) <= 128
    assert sum(map(len, ref)) + whole.discarded_bytes <= len(data)


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=300))
def test_parse_line_arbitrary_bytes_raise_only_parse_error(data):
    try:
        rec = parse_line(data)
    except DvlParseError:
        return
    assert isinstance(rec, (DvlPositionDelta, DvlExtended, DvlGprmc, DvlText, DvlUnknown))


_FIELD = st.one_of(st.text(alphabet="0123456789-.+eETFAVX", max_size=8), st.text(max_size=6))


@settings(max_examples=300, deadline=None)
@given(st.sampled_from(["DVPDL", "DVEXT", "GPRMC", "DVTXT", "DVNVM"]),
       st.lists(_FIELD, min_size=0, max_size=40))
def test_checksummed_random_fields_raise_only_parse_error(sentence_id, fields):
    body = ",".join([sentence_id] + fields).encode("utf-8", errors="replace")
    try:
        parse_line(_with_checksum(body))
        split_sentence(_with_checksum(body))
    except DvlParseError:
        pass


@settings(max_examples=100, deadline=None)
@given(tu=st.integers(0, 2**40), dtu=st.integers(0, 10**7),
       ang=st.tuples(*[st.floats(-3.2, 3.2)] * 3), pos=st.tuples(*[st.floats(-100, 100)] * 3),
       c=st.integers(0, 100))
def test_dvpdl_format_parse_round_trip(tu, dtu, ang, pos, c):
    rec = DvlPositionDelta(tu / 1e6, dtu / 1e6, *ang, *pos, c)
    back = parse_line(format_dvpdl(rec))
    assert round(back.time_since_boot_s * 1e6) == tu and round(back.delta_time_s * 1e6) == dtu
    for a, b in zip(ang, (back.delta_roll_rad, back.delta_pitch_rad, back.delta_yaw_rad)):
        assert abs(a - b) <= 0.5e-6 + 1e-12  # %.6f quantisation
    for a, b in zip(pos, (back.delta_x_m, back.delta_y_m, back.delta_z_m)):
        assert abs(a - b) <= 0.5e-3 + 1e-12  # %.3f quantisation
    assert back.confidence_pct == c


# ------------------------------------------------------------------------------------------------
# Commands
# ------------------------------------------------------------------------------------------------


def test_startup_commands_enable_dvpdl_first_and_are_plain_lines():
    cmds = startup_commands(sensor_orientation_rad=(0.0, math.pi / 2, 0.0), speed_of_sound_m_s=1500)
    assert cmds[0] == b"SEND-DVPDL ON\r\n"  # factory OFF (docs/devices.md §0 item 1)
    # BlueOS forward-looking mount sends 0,90,0 (docs/devices.md §1.4)
    assert b"SET-SENSOR-ORIENTATION 0,90,0\r\n" in cmds
    assert b"SET-SPEED-OF-SOUND 1500\r\n" in cmds and b"RESUME\r\n" in cmds
    assert cmds[-1] == b"CONFIGURATION\r\n"
    for c in cmds:
        assert c.endswith(b"\r\n") and b"*" not in c  # commands carry no checksum (§1.4)
        parse_command(c)


def test_command_builder_ranges_match_devices_doc():
    assert cmd_set_speed_of_sound(1100) == b"SET-SPEED-OF-SOUND 1100\r\n"
    assert cmd_set_speed_of_sound(1950) == b"SET-SPEED-OF-SOUND 1950\r\n"
    for bad in (1099.9, 1950.1):
        with pytest.raises(ValueError):
            cmd_set_speed_of_sound(bad)
    with pytest.raises(ValueError):
        cmd_set_sensor_orientation(0.0, 0.0, math.radians(181))
    assert cmd_send("dvext", False) == b"SEND-DVEXT OFF\r\n"
    with pytest.raises(ValueError):
        cmd_send("DVXYZ", True)


def test_parse_command_forms():
    assert parse_command(b"?\r\n").keyword == "CONFIGURATION"
    cmd = parse_command(b"send-dvpdl on\r\n")
    assert (cmd.keyword, cmd.argument) == ("SEND-DVPDL", "on")
    assert parse_command(DOC_RMC).keyword == "$GPRMC"
    with pytest.raises(DvlParseError):
        parse_command(b"\r\n")
    with pytest.raises(DvlParseError):
        parse_command(b"SEND\x00")


# ------------------------------------------------------------------------------------------------
# Emulator (I/O-free)
# ------------------------------------------------------------------------------------------------


def _records(emu, t0, t1, step=0.01, framer=None):
    framer = framer or DvlLineFramer()
    out = []
    n = int(round((t1 - t0) / step))
    for k in range(n + 1):
        for line in framer.feed(emu.poll(t0 + k * step)):
            out.append(parse_line(line))
    return out


def _of(records, cls):
    return [r for r in records if isinstance(r, cls)]


def test_emulator_factory_defaults_dvpdl_off():
    emu = Dvl75Emulator(DvlTruth(), rate_hz=10)
    recs = _records(emu, 0.0, 1.0)
    assert len(_of(recs, DvlExtended)) == 10  # DVEXT ON, 10 Hz
    assert _of(recs, DvlPositionDelta) == []  # DVPDL OFF by factory default (§0 item 1)
    assert _of(recs, DvlText)  # free-form ON: boot banner
    f = emu.flash
    assert (f.send_dvpdl, f.send_dvext, f.send_freeform, f.send_gprmc, f.send_dvkfa, f.send_dvkfb,
            f.retweet_gps, f.retweet_imu) == (False, True, True, False, False, False, False, False)
    assert f.speed_of_sound_m_s == 1484.0 and f.declination_rad == 0.0
    assert f.sensor_orientation_rad == (0.0, 0.0, 0.0)
    assert f.host_address == "255.255.255.255:27000" and f.fallback_address == "192.168.2.3"


def test_emulator_dvpdl_after_enable_matches_truth_and_rate():
    truth = DvlTruth(velocity_frd_m_s=(0.4, -0.25, 0.05), altitude_m=2.0)
    emu = Dvl75Emulator(truth, rate_hz=20)
    emu.poll(0.0)
    emu.feed_host_bytes(b"SEND-DVPDL ON\r\n")
    pdl = _of(_records(emu, 0.0, 1.0), DvlPositionDelta)
    assert len(pdl) == 20
    for r in pdl:
        assert round(r.delta_time_s * 1e6) == 50000  # dtu = real interval at 20 Hz
        assert round(r.time_since_boot_s * 1e6) % 1000 == 0
        assert r.confidence_pct == 100
        v = r.velocity_frd_m_s()
        for got, want in zip(v, truth.velocity_frd_m_s):
            assert abs(got - want) <= 0.5e-3 / 0.05 + 1e-9  # 1 mm quantisation over 50 ms
    tus = [round(r.time_since_boot_s * 1e6) for r in pdl]
    assert all(b - a == 50000 for a, b in zip(tus, tus[1:]))


def test_emulator_dvext_geometry_and_conventions():
    """Heading east (yaw = 90 deg), surge 1 m/s: ground velocity is due east; level attitude gives
    altitude along the axis = altitude; beam ranges = altitude / cos(tilt)."""
    tilt = math.radians(22.5)
    emu = Dvl75Emulator(DvlTruth(velocity_frd_m_s=(1.0, 0.0, 0.0), altitude_m=4.0,
                                 yaw_rad=math.radians(90.0)), beam_tilt_rad=tilt)
    ext = _of(_records(emu, 0.0, 0.2), DvlExtended)[-1]
    assert ext.locked and ext.beam_locked == (True,) * 4 and ext.data_skips == 0
    assert ext.velocity_east_m_s == pytest.approx(1.0, abs=1e-3)
    assert ext.velocity_north_m_s == pytest.approx(0.0, abs=1e-3)
    assert ext.velocity_up_m_s == pytest.approx(0.0, abs=1e-3)
    assert ext.heading_rad == pytest.approx(math.radians(90.0), abs=1e-3)
    assert ext.altitude_m == pytest.approx(4.0, abs=0.005)
    for r in ext.beam_range_m:
        assert r == pytest.approx(4.0 / math.cos(tilt), abs=5e-4)
    a_port, b_stern, c_stbd, d_bow = ext.beam_velocity_m_s
    assert d_bow == pytest.approx(math.sin(tilt), abs=1e-4)  # approaching the bottom ahead: +
    assert b_stern == pytest.approx(-math.sin(tilt), abs=1e-4)
    assert a_port == pytest.approx(0.0, abs=1e-4) and c_stbd == pytest.approx(0.0, abs=1e-4)


def test_emulator_attitude_and_quaternion_follow_cerulean_conventions():
    roll, pitch, yaw = math.radians(5.0), math.radians(8.0), math.radians(259.5)
    emu = Dvl75Emulator(DvlTruth(roll_rad=roll, pitch_rad=pitch, yaw_rad=yaw, altitude_m=3.0))
    ext = _of(_records(emu, 0.0, 0.2), DvlExtended)[-1]
    assert ext.roll_rad == pytest.approx(roll, abs=math.radians(0.05))
    # DVL Euler pitch is right-handed about +Y port: bow-up (FRD +pitch) prints negative (§1.5).
    assert ext.pitch_rad == pytest.approx(-pitch, abs=math.radians(0.05))
    assert ext.heading_rad == pytest.approx(yaw, abs=math.radians(0.05))
    # Cerulean's Euler->quaternion formula (§1.5) with ENU yaw = 90 deg - heading and FLU pitch.
    y, p, r = (math.pi / 2 - yaw) / 2, -pitch / 2, roll / 2
    cy, sy, cp, sp, cr, sr = math.cos(y), math.sin(y), math.cos(p), math.sin(p), math.cos(r), math.sin(r)
    q = (cy * cr * cp + sy * sr * sp, cy * sr * cp - sy * cr * sp, cy * cr * sp + sy * sr * cp,
         sy * cr * cp - cy * sr * sp)
    sign = 1.0 if sum(a * b for a, b in zip(q, ext.orientation_wxyz)) > 0 else -1.0
    assert [sign * c for c in ext.orientation_wxyz] == pytest.approx(q, abs=2e-6)
    assert ext.altitude_m == pytest.approx(3.0 / (math.cos(roll) * math.cos(pitch)), abs=0.005)


@pytest.mark.parametrize("truth", [DvlTruth(bottom_lock=False), DvlTruth(altitude_m=0.2),
                                   DvlTruth(altitude_m=45.0), DvlTruth(altitude_m=None),
                                   DvlTruth(roll_rad=math.radians(25.0))])
def test_emulator_unlocked_reports(truth):
    """Outside the lock envelope (docs/devices.md §1.1: 0.3-40 m, <= 20 deg) or without lock: c=0 with
    zero deltas, lock F, ranges -1 (§1.6 item 3), data skips counting up."""
    emu = Dvl75Emulator(replace(truth, velocity_frd_m_s=(0.3, 0.1, 0.0)), flash=DvlFlash(send_dvpdl=True))
    recs = _records(emu, 0.0, 0.5)
    for r in _of(recs, DvlPositionDelta):
        assert r.confidence_pct == 0 and (r.delta_x_m, r.delta_y_m, r.delta_z_m) == (0.0, 0.0, 0.0)
        assert r.delta_time_s == pytest.approx(0.1)
    exts = _of(recs, DvlExtended)
    for e in exts:
        assert not e.locked and e.beam_locked == (False,) * 4 and e.beam_range_m == (-1.0,) * 4
        assert e.velocity_north_m_s == 0.0
    assert [e.data_skips for e in exts] == list(range(1, len(exts) + 1))


def test_emulator_commands_speed_of_sound_pause_reboot_config():
    truth = DvlTruth(velocity_frd_m_s=(1.0, 0.0, 0.0))
    emu = Dvl75Emulator(truth, true_speed_of_sound_m_s=1484.0, flash=DvlFlash(send_dvpdl=True))
    emu.poll(0.0)
    emu.feed_host_bytes(b"SET-SPEED-OF-SOUND 1500\r\n?\r\n")
    recs = _records(emu, 0.0, 0.5)
    texts = [t.text for t in _of(recs, DvlText)]
    assert "SET-SPEED-OF-SOUND 1500.0" in texts and "SEND-DVPDL ON" in texts
    v = _of(recs, DvlPositionDelta)[-1].velocity_frd_m_s()
    assert v[0] == pytest.approx(1500.0 / 1484.0, abs=0.01)  # Doppler scales with configured c
    emu.feed_host_bytes(b"PAUSE\n")
    assert _of(_records(emu, 0.5, 1.0), DvlPositionDelta) == []
    emu.feed_host_bytes(b"RESUME\n")
    assert len(_of(_records(emu, 1.0, 1.5), DvlPositionDelta)) == 5
    emu.feed_host_bytes(b"REBOOT\r\n")
    after = _records(emu, 1.5, 1.75)
    assert any("Boot" in t.text for t in _of(after, DvlText))
    first = _of(after, DvlPositionDelta)[0]
    assert first.time_since_boot_s == pytest.approx(0.1)  # tu restarts at boot
    assert emu.flash.speed_of_sound_m_s == 1500.0  # sticky across REBOOT
    emu.feed_host_bytes(b"SET-SPEED-OF-SOUND 3000\r\nFLY-TO-MOON\r\n")
    errs = [t.text for t in _of(_records(emu, 1.75, 1.8), DvlText)]
    assert any("SET-SPEED-OF-SOUND" in e for e in errs) and any("Unknown command" in e for e in errs)
    assert emu.flash.speed_of_sound_m_s == 1500.0


def test_emulator_freeform_off_silences_text():
    emu = Dvl75Emulator(DvlTruth(), flash=DvlFlash(send_freeform=False))
    emu.feed_host_bytes(b"?\r\n")
    assert _of(_records(emu, 0.0, 0.3), DvlText) == []


def test_emulator_set_position_fix_freshness_and_gprmc():
    emu = Dvl75Emulator(DvlTruth(), flash=DvlFlash(send_gprmc=True))
    emu.poll(0.0)
    emu.feed_host_bytes(b"SET-POSITION 44 58.13256 N, 93 31.03476 W\r\n")
    recs = _records(emu, 0.0, 2.0)
    ext = _of(recs, DvlExtended)
    assert ext[0].gps_status == "A" and ext[-1].gps_status == "X"  # fresh for 1.5 s
    assert ext[0].latitude_deg == pytest.approx(44 + 58.13256 / 60, abs=1e-6)
    assert ext[0].longitude_deg == pytest.approx(-(93 + 31.03476 / 60), abs=1e-6)
    rmc = _of(recs, DvlGprmc)
    assert rmc and rmc[0].valid and rmc[0].date_ddmmyy == "010120"
    assert rmc[0].latitude_deg == pytest.approx(44 + 58.13256 / 60, abs=1e-5)


def test_emulator_faults():
    truth = {"v": DvlTruth(velocity_frd_m_s=(0.5, 0.0, 0.0))}
    emu = Dvl75Emulator(lambda t: truth["v"], flash=DvlFlash(send_dvpdl=True))
    framer = DvlLineFramer()
    _records(emu, 0.0, 0.3, framer=framer)
    # garbage: counted exactly by the framer (alphabet 0x80-0xFF has no '$' or LF)
    emu.faults.inject_garbage(n_bytes=25)
    before = framer.discarded_bytes
    _records(emu, 0.31, 0.5, framer=framer)
    assert framer.discarded_bytes - before == 25
    # bad checksum -> parse error
    emu.faults.corrupt_checksum(1)
    errors = []
    for line in framer.feed(emu.poll(0.6)):
        try:
            parse_line(line)
        except DvlParseError as exc:
            errors.append(str(exc))
    assert len(errors) == 1 and "checksum" in errors[0]
    # truncated line merges with the next one; the framer resynchronises on '$'
    emu.faults.truncate(1)
    before = framer.discarded_bytes
    lines = framer.feed(emu.poll(0.7))
    assert len(lines) == 1 and framer.discarded_bytes > before
    assert isinstance(parse_line(lines[0]), DvlPositionDelta)  # the $DVEXT (sent first) was truncated
    # dropped lines: the cycle's $DVEXT (sent first) and $DVPDL missing
    emu.faults.drop(2)
    assert len(_of([parse_line(x) for x in framer.feed(emu.poll(0.8))], DvlPositionDelta)) == 0
    # stuck: truth changes, output does not
    emu.faults.set_stuck(True)
    truth["v"] = DvlTruth(velocity_frd_m_s=(-1.0, 0.0, 0.0))
    stuck = _of(_records(emu, 0.81, 1.2, framer=framer), DvlPositionDelta)
    assert all(r.delta_x_m == pytest.approx(0.05) for r in stuck)
    emu.faults.set_stuck(False)
    moving = _of(_records(emu, 1.21, 1.6, framer=framer), DvlPositionDelta)
    assert moving[-1].delta_x_m == pytest.approx(-0.1)
    # zero-confidence and unlocked reports
    emu.set_zero_confidence(True)
    assert all(r.confidence_pct == 0 for r in _of(_records(emu, 1.61, 1.9, framer=framer), DvlPositionDelta))
    emu.set_zero_confidence(False)
    emu.set_unlocked(True)
    assert all(not e.locked for e in _of(_records(emu, 1.91, 2.2, framer=framer), DvlExtended))
    emu.set_unlocked(False)
    # disconnect: silent and deaf
    emu.faults.set_disconnected(True)
    emu.feed_host_bytes(b"SEND-DVEXT OFF\r\n")
    assert emu.poll(3.0) == b""
    emu.faults.set_disconnected(False)
    assert emu.flash.send_dvext is True
    assert _of(_records(emu, 3.01, 3.2, framer=framer), DvlExtended)


def test_emulator_rate_limits():
    with pytest.raises(ValueError):
        Dvl75Emulator(DvlTruth(), rate_hz=25)
    with pytest.raises(ValueError):
        Dvl75Emulator(DvlTruth(), rate_hz=4)


_NUMBER = st.one_of(st.floats(allow_nan=False, allow_infinity=False, width=32).map(lambda v: f"{v:.6g}"),
                    st.integers(-10**9, 10**9).map(str), st.sampled_from(["1e999", "-1e999", "999.999", "1e300"]))


@settings(max_examples=300, deadline=None)
@given(st.integers(0, 10**9), st.integers(0, 10**7), st.lists(_NUMBER, min_size=6, max_size=6), st.integers(1, 100))
def test_checksum_valid_dvpdl_never_yields_a_valid_velocity_outside_the_gates(tu, dtu, numbers, confidence):
    """Property behind issue 19 fault 8: whatever a checksum-valid $DVPDL carries, the report builder with the
    gates of the vehicle file (4.1 m/s, dtu 25 ms..1 s) publishes a valid velocity only when it is finite and
    within the envelope (|v| of the transducer <= 4.1 m/s; the lever arm here is 0)."""
    from hindrax_drivers.dvl75.report import DvlReportBuilder
    from hindrax_drivers.dvl75.stream import DvlStreamDecoder

    line = format_sentence(",".join(["DVPDL", str(tu), str(dtu), *numbers, str(confidence)]))
    builder = DvlReportBuilder(max_speed_m_s=4.1, min_interval_s=0.025, max_interval_s=1.0)
    for record in DvlStreamDecoder().feed(line):
        rep = builder.from_position_delta(record, 0)
        if rep.velocity_valid:
            speed = math.sqrt(sum(v * v for v in rep.velocity_flu_m_s))
            assert math.isfinite(speed) and speed <= 4.1 * (1 + 1e-12) and 0.025 <= rep.delta_time_s <= 1.0
        else:
            assert all(math.isnan(v) for v in rep.velocity_flu_m_s)
