"""`hindrax decode dvl75|ping1d FILE` as users run it: real captures of docs/devices.md, emulator captures with
faults, and files that hold nothing decodable."""
import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

from hindrax_drivers.dvl75.emulator import Dvl75Emulator, DvlTruth
from hindrax_drivers.dvl75.protocol import startup_commands
from hindrax_drivers.ping1d.emulator import Ping1dEmulator, Ping1dTruth
from hindrax_drivers.ping1d.protocol import ContinuousStart, Ping1dId, request_frame

HINDRAX = str(Path(sys.executable).with_name("hindrax"))

# Real captured sentences with verified checksums (docs/devices.md §1.2 [D21]).
REAL_DVPDL_1 = b"$DVPDL,160401000,100000,0.000000,-0.000000,-0.000000,0.000,-0.000,-0.000,0*55"
REAL_DVPDL_2 = b"$DVPDL,1398604000,50000,0.000000,-0.000000,-0.000000,-0.003,0.017,0.002,100*79"
REAL_DVEXT = (b"$DVEXT,F,X,3330,-1.8,2.4,259.5,-1175,0.000,0.00,-0.000,0.000,0.000000000,0.000000000,0.100,"
              b"0.091711,0.019853,0.017436,-0.995435,25,25,25,25,F,F,F,F,0.0000,0.0000,0.0000,0.0000,-1.000,"
              b"-1.000,-1.000,-1.000,*54")
# Byte-exact Ping1D vectors (docs/devices.md §2.5)
PING_VECTORS = bytes.fromhex(
    "42 52 04 00 05 00 00 00 01 02 03 00 a3 00"        # protocol_version reply v1.2.3
    "42 52 05 00 bb 04 01 00 d2 04 00 00 57 86 02"     # distance_simple 1234 mm, 87 %, src 1
    "42 52 02 00 01 00 01 00 ea 03 85 01"              # ack(1002)
    "42 52 04 00 ea 03 00 00 40 95 16 00 70 02"        # set_speed_of_sound 1480000 mm/s
    "42 52 02 00 06 00 00 00 bb 04 5b 01")             # general_request(1211)


def decode(device, path):
    res = subprocess.run([HINDRAX, "decode", device, str(path)], capture_output=True, text=True, timeout=60)
    records = [json.loads(line) for line in res.stdout.splitlines()]
    return res.returncode, records, res.stderr


def test_dvl_real_captures_decode_to_the_documented_values(tmp_path):
    bad = REAL_DVPDL_2[:-2] + b"7A"  # the real sentence with a wrong checksum (0x79 is right)
    cap = tmp_path / "dvl.txt"
    cap.write_bytes(b"\r\n".join([REAL_DVPDL_1, REAL_DVPDL_2, bad, REAL_DVEXT]))  # no final line end
    rc, recs, err = decode("dvl75", cap)
    assert rc == 0
    assert [r["type"] for r in recs] == ["DvlPositionDelta", "DvlPositionDelta", "DvlExtended"]
    assert [r["line"] for r in recs] == [1, 2, 4]
    p1, p2, ext = recs
    assert p1["time_since_boot_s"] == pytest.approx(160.401) and p1["delta_time_s"] == pytest.approx(0.1)
    assert p1["confidence_pct"] == 0
    assert p2["time_since_boot_s"] == pytest.approx(1398.604) and p2["delta_time_s"] == pytest.approx(0.05)
    assert (p2["delta_x_m"], p2["delta_y_m"], p2["delta_z_m"]) == pytest.approx((-0.003, 0.017, 0.002))
    assert p2["confidence_pct"] == 100
    assert ext["locked"] is False and ext["gps_status"] == "X" and ext["imu_calibration"] == [3, 3, 3, 0]
    assert ext["roll_rad"] == pytest.approx(math.radians(-1.8)) and ext["pitch_rad"] == pytest.approx(math.radians(2.4))
    assert ext["heading_rad"] == pytest.approx(math.radians(259.5)) and ext["data_skips"] == -1175
    assert ext["orientation_wxyz"] == pytest.approx([0.091711, 0.019853, 0.017436, -0.995435])
    assert ext["beam_range_m"] == [-1.0] * 4 and ext["beam_gain_db"] == [25.0] * 4
    assert "dvl75 line 3: bad_checksum" in err
    assert "1 line(s) did not parse (bad_checksum 1)" in err.splitlines()[-1]


def test_dvl_emulator_capture_with_faults(tmp_path):
    truth = DvlTruth(velocity_frd_m_s=(0.25, 0.0, -0.1), altitude_m=2.0)
    emu = Dvl75Emulator(truth, rate_hz=10.0)
    for cmd in startup_commands(request_configuration=False):
        emu.feed_host_bytes(cmd)
    data = bytearray(emu.poll(0.0))
    for k in range(1, 21):
        if k == 5:
            emu.faults.inject_garbage(n_bytes=30)
        if k == 8:
            emu.faults.corrupt_checksum(2)
        if k == 12:
            emu.faults.truncate(1)
        data += emu.poll(0.1 * k)
    cap = tmp_path / "emu.txt"
    cap.write_bytes(bytes(data))
    rc, recs, err = decode("dvl75", cap)
    assert rc == 0
    sent = emu.sent_counts["DVPDL"] + emu.sent_counts["DVEXT"] + emu.sent_counts["DVTXT"]
    assert len(recs) == sent - 3  # two corrupted, one truncated
    pdl = [r for r in recs if r["type"] == "DvlPositionDelta"]
    for r in pdl[1:]:  # mean velocity = delta / dtu, 1 mm quantisation (docs/devices.md §1.3.1)
        assert r["delta_x_m"] / r["delta_time_s"] == pytest.approx(0.25, abs=0.0051)
        assert r["delta_z_m"] / r["delta_time_s"] == pytest.approx(-0.1, abs=0.0051)
    summary = err.splitlines()[-1]
    assert "3 line(s) did not parse (bad_checksum 2, truncated 1)" in summary
    garbage = int(summary.split(";")[-1].split()[0])
    assert garbage >= 30
    assert sum("bad_checksum" in line for line in err.splitlines()[:-1]) == 2


def test_ping_vectors_and_emulator_capture_with_faults(tmp_path):
    cap = tmp_path / "vectors.bin"
    cap.write_bytes(PING_VECTORS)
    rc, recs, err = decode("ping1d", cap)
    assert rc == 0
    assert [r["type"] for r in recs] == ["ProtocolVersion", "DistanceSimple", "Ack", "SetSpeedOfSound",
                                         "GeneralRequest"]
    assert (recs[0]["version_major"], recs[0]["version_minor"], recs[0]["version_patch"]) == (1, 2, 3)
    assert recs[1]["distance_m"] == pytest.approx(1.234) and recs[1]["confidence_pct"] == 87
    assert recs[1]["src_device_id"] == 1 and recs[1]["offset"] == 14
    assert recs[2]["acked_id"] == 1002 and recs[3]["speed_of_sound_m_s"] == pytest.approx(1480.0)
    assert recs[4]["requested_id"] == 1211

    emu = Ping1dEmulator(Ping1dTruth(altitude_m=6.5, confidence_pct=77))
    emu.feed_host_bytes(ContinuousStart(int(Ping1dId.PROFILE)).encode() + request_frame(Ping1dId.DISTANCE_SIMPLE))
    data = bytearray()
    for k in range(12):
        if k == 4:
            emu.faults.inject_garbage(data=b"\xfe" * 25)
        if k == 6:
            emu.faults.corrupt_checksum(1)
        if k == 8:
            emu.faults.truncate(1)
        data += emu.poll(0.1 * k)
    data += b"BR\x10\x00\x14"  # capture ends inside a frame header
    cap = tmp_path / "ping.bin"
    cap.write_bytes(bytes(data))
    rc, recs, err = decode("ping1d", cap)
    assert rc == 0
    profiles = [r for r in recs if r["type"] == "Profile"]
    # 12 pings at 0.1 s; the first precedes continuous_start (handled after the pings of that poll); 2 faulted
    assert len(profiles) == 11 - 2 and all(r["distance_m"] == pytest.approx(6.5) for r in profiles)
    assert all(len(r["profile_data"]) == 200 for r in profiles)
    summary = err.splitlines()[-1]
    assert "3 frame(s) did not parse (bad_checksum 1, truncated 2)" in summary and "25 garbage byte(s)" in summary
    assert any(line.startswith("ping1d offset ") and "truncated" in line for line in err.splitlines())


def test_nothing_decodable_exits_1(tmp_path):
    cap = tmp_path / "noise.bin"
    cap.write_bytes(bytes(range(0x80, 0x100)) * 4)
    for device in ("dvl75", "ping1d"):
        rc, recs, err = decode(device, cap)
        assert rc == 1 and recs == []
        assert "decode: 0 record(s)" in err and "512 garbage byte(s)" in err
    rc, recs, err = decode("dvl75", tmp_path / "missing.txt")
    assert rc == 1 and err.strip().startswith("decode: cannot read") and len(err.strip().splitlines()) == 1
