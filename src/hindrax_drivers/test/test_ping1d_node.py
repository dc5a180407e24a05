"""Ping1D altimeter node through the real pyserial path: emulator on a pty -> SerialTransport -> node -> topics.

Expected bytes are the verified vectors of docs/devices.md §2.5; expected ranges are the emulator truth within
the 1 mm wire resolution of docs/devices.md §2.4 (and float32 of sensor_msgs/Range). Every wait is on a
condition with a deadline.
"""
import math
import random
import time

import pytest
from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.parameter import Parameter
from sensor_msgs.msg import Range
from std_msgs.msg import Float32

from hindrax_common.config import default_config_path
from hindrax_drivers.ping1d.emulator import Ping1dEmulator, Ping1dTruth
from hindrax_drivers.ping1d.node import Ping1dNode
from hindrax_drivers.ping1d.protocol import Ping1dId, encode_frame
from hindrax_drivers.ping1d.stream import Ping1dStreamDecoder
from hindrax_drivers.ping1d.protocol import Profile
from hindrax_common.testing import (config_parameters, python_executable,
                                     wait_until)
from hindrax_common.transport.pty_device import PtyDevice
from hindrax_msgs.msg import RawDeviceData

pytestmark = pytest.mark.ros

SPEED_OF_SOUND_M_S = 1480.0  # the value of the docs/devices.md §2.5 set_speed_of_sound vector
# docs/devices.md §2.5 (verified vectors)
SET_SPEED_OF_SOUND_1480000 = bytes.fromhex("42 52 04 00 ea 03 00 00 40 95 16 00 70 02")
SET_PING_INTERVAL_100 = bytes.fromhex("42 52 02 00 ec 03 00 00 64 00 e9 01")
CONTINUOUS_START_1300 = bytes.fromhex("42 52 02 00 78 05 00 00 14 05 2c 01")
NOISE = bytes(range(0x80, 0xA8))  # 40 bytes that cannot form a 'BR' header


class Rig:
    """Ping emulator on a pty, the node under test, and the probe's subscriptions to its outputs (the ``rig`` fixture,
    conftest.py, adds the probe and the executor)."""

    def __init__(self, ctx, truth, overrides=None, extra_params=(), clock=time.monotonic, start_disconnected=False,
                 true_speed_of_sound_m_s=SPEED_OF_SOUND_M_S):
        self.emu = Ping1dEmulator(truth, true_speed_of_sound_m_s=true_speed_of_sound_m_s)
        self.dev = PtyDevice(self.emu, clock=clock)
        if start_disconnected:
            self.dev.disconnect()
        params = config_parameters({"sensors.ping1d.port": self.dev.path,
                                    "sensors.ping1d.speed_of_sound_m_s": SPEED_OF_SOUND_M_S, **(overrides or {})})
        self.start(ctx, Ping1dNode(context=ctx, parameter_overrides=params + self.quiet_stuck_detector(extra_params)),
                   "hindrax/ping1d")
        self.ranges = self.collect(Range, "ping/altitude", 100)
        self.confidence = self.collect(Float32, "ping/confidence", 100)
        self.raw = self.collect(RawDeviceData, "raw/ping1d", 500)

    def values(self):
        return {kv.key: kv.value for kv in self.diag[-1].values} if self.diag else {}

    def close(self):
        super().close()
        self.dev.close()


def test_startup_frames_settings_and_published_range_match_truth(rig):
    r = rig(Ping1dTruth(altitude_m=3.217, confidence_pct=87), start_disconnected=True)
    r.wait(lambda: r.node.raw.publisher.get_subscription_count() and r.node.pub_range.get_subscription_count()
           and r.values().get("state") == "disconnected", message="probe matched, device absent")
    r.dev.reconnect()
    r.wait(lambda: len(r.ranges) >= 5 and r.node.settings_verified is not None, message="ranges and settings")
    # start-up frames, byte-exact against docs/devices.md §2.5 (auto-baud 'U' first, §2.1)
    r.wait(lambda: r.emu.received.get(Ping1dId.GENERAL_REQUEST, 0) >= 3, message="verification requests")
    tx = b"".join(bytes(m.data) for m in r.raw if m.direction == RawDeviceData.DIRECTION_HOST_TO_DEVICE)
    assert tx.startswith(b"U" + SET_SPEED_OF_SOUND_1480000 + SET_PING_INTERVAL_100)
    assert CONTINUOUS_START_1300 in tx
    s = r.emu.settings
    assert s.speed_of_sound_m_s == SPEED_OF_SOUND_M_S and s.ping_interval_s == 0.1 and s.mode_auto
    assert s.ping_enabled and r.emu.streaming == {Ping1dId.PROFILE: 0}
    assert r.node.settings_verified is True and r.node.firmware_version == "3.29"

    rng = r.ranges[-1]
    assert rng.header.frame_id == "ping_link" and rng.radiation_type == Range.ULTRASOUND
    assert rng.range == pytest.approx(3.217, abs=0.0005)
    assert rng.field_of_view == pytest.approx(0.5236, rel=1e-6)  # sensors.ping1d.* of hindrax.yaml
    assert (rng.min_range, rng.max_range) == pytest.approx((0.3, 50.0))
    assert r.confidence[-1].data == 87.0
    assert r.values()["state"] == "connected"


def test_configured_interval_and_manual_mode_reach_the_device(rig):
    r = rig(Ping1dTruth(altitude_m=2.0), overrides={"sensors.ping1d.ping_interval_s": 0.05,
                                                     "sensors.ping1d.mode_auto": False})
    r.wait(lambda: r.node.settings_verified is not None and len(r.ranges) >= 3, message="settings")
    assert r.emu.settings.ping_interval_s == 0.05 and not r.emu.settings.mode_auto
    assert r.node.settings_verified is True


def test_zero_confidence_and_no_echo_give_infinite_range(rig):
    truth = {"value": Ping1dTruth(altitude_m=5.0, confidence_pct=90)}
    r = rig(lambda t: truth["value"])
    r.wait(lambda: len(r.ranges) >= 2 and math.isfinite(r.ranges[-1].range), message="echo")
    with r.dev.lock:
        r.emu.set_zero_confidence(True)
    r.wait(lambda: len(r.confidence) and r.confidence[-1].data == 0.0, message="confidence 0")
    n = len(r.ranges)
    r.wait(lambda: len(r.ranges) >= n + 2, message="more pings")
    assert all(math.isinf(m.range) and m.range > 0 for m in r.ranges[n:])  # REP-117: no detection
    with r.dev.lock:
        r.emu.set_zero_confidence(False)
        truth["value"] = Ping1dTruth(altitude_m=None)  # nothing in range
    n = len(r.ranges)
    r.wait(lambda: len(r.ranges) >= n + 3, message="pings without echo")
    assert math.isinf(r.ranges[-1].range) and r.confidence[-1].data == 0.0


def test_garbage_bad_checksums_truncated_frames_and_unknown_ids_are_counted_not_fatal(rig):
    r = rig(Ping1dTruth(altitude_m=4.321, confidence_pct=80))
    r.wait(lambda: r.node.settings_verified is not None and len(r.ranges) >= 3, message="steady")
    r.wait(lambda: r.node.acks >= 5 and len(r.ranges) >= 6, message="start-up replies over")
    with r.dev.lock:
        r.emu.faults.inject_garbage(data=NOISE)
        r.emu.faults.truncate(2)
        r.emu.faults.corrupt_checksum(2)
    r.wait(lambda: r.values().get("errors.truncated") == "2" and r.values().get("errors.bad_checksum") == "2",
           message="counters")
    with r.dev.lock:
        r.emu.faults.inject_garbage(data=encode_frame(4242, b"\x01\x02", 1, 0))  # valid frame, unknown id
    r.wait(lambda: r.values().get("errors.unknown_message") == "1", message="unknown id counted")
    v = r.values()
    assert int(v["errors.garbage_bytes"]) == len(NOISE) and "errors.malformed" not in v
    # arbitrary bytes of every value do not stop the node either
    rng = random.Random(3)
    with r.dev.lock:
        r.emu.faults.inject_garbage(data=bytes(rng.randrange(256) for _ in range(3000)))
    n = len(r.ranges)
    r.wait(lambda: len(r.ranges) >= n + 5, message="ranges after the faults")
    assert r.ranges[-1].range == pytest.approx(4.321, abs=0.0005)
    assert "internal_error" not in r.node.diag.counts()


def test_device_disappears_and_comes_back_node_reconnects_within_2_s_and_restarts_streaming(rig):
    r = rig(Ping1dTruth(altitude_m=2.5))
    r.wait(lambda: len(r.ranges) >= 3, message="ranges")
    assert r.emu.received[Ping1dId.SET_SPEED_OF_SOUND] == 1
    r.dev.disconnect()
    with r.dev.lock:  # a device that was power-cycled: streaming off, speed of sound back to its default
        r.emu.streaming.clear()
        r.emu.settings.speed_of_sound_m_s = 1500.0
    r.wait(lambda: r.values().get("state") == "reconnecting", 5.0, "reconnecting in diagnostics")
    assert r.diag[-1].level == DiagnosticStatus.ERROR
    r.dev.reconnect()
    r.wait(lambda: r.values().get("state") == "connected" and r.values().get("reconnects") == "1", 2.0,
           "reconnected within 2 s")
    n = len(r.ranges)
    r.wait(lambda: len(r.ranges) >= n + 3, message="ranges again")
    assert r.emu.received[Ping1dId.SET_SPEED_OF_SOUND] == 2
    assert r.emu.settings.speed_of_sound_m_s == SPEED_OF_SOUND_M_S


def test_silent_device_warns_no_data_and_gets_its_startup_frames_again(rig):
    r = rig(Ping1dTruth(altitude_m=2.5))
    r.wait(lambda: len(r.ranges) >= 3 and r.node.commands.sequences_completed >= 1, message="ranges")
    with r.dev.lock:
        r.emu.faults.set_disconnected(True)  # port still open, device mute and deaf
        r.emu.streaming.clear()  # and it forgot the stream (a reset)
    r.wait(lambda: r.diag and r.diag[-1].level == DiagnosticStatus.WARN and "no data" in r.diag[-1].message
           and int(r.values().get("errors.startup_resends", "0")) >= 1, 6.0, "no-data warning and restart")
    with r.dev.lock:
        r.emu.faults.set_disconnected(False)
    n = len(r.ranges)
    r.wait(lambda: len(r.ranges) >= n + 3 and r.diag[-1].level == DiagnosticStatus.OK, 6.0, "streaming again")
    assert r.emu.streaming == {Ping1dId.PROFILE: 0}


def test_stuck_sensor_is_an_error_and_is_not_published(rig):
    r = rig(lambda t: Ping1dTruth(altitude_m=3.0 + 0.3 * math.sin(2.0 * t), confidence_pct=95),
            extra_params=[Parameter("stuck_limit_samples", value=8)])
    r.wait(lambda: len(r.ranges) >= 12, message="ranges")
    assert not r.node.stuck
    with r.dev.lock:
        r.emu.faults.set_stuck(True)
    r.wait(lambda: r.node.stuck, 5.0, "stuck detected")
    detected_ns, pings = r.node.now_ns(), r.node._last_distance_ns  # at or after the detection
    r.wait(lambda: r.diag and "stuck" in r.diag[-1].message, 5.0, "stuck error in diagnostics")
    assert r.diag[-1].level == DiagnosticStatus.ERROR
    r.wait(lambda: r.node.stuck and r.node._last_distance_ns > pings + 5e8, 5.0, "0.5 s of stuck pings")
    assert not [m for m in r.ranges if m.header.stamp.sec * 10**9 + m.header.stamp.nanosec > detected_ns]
    n = len(r.ranges)
    with r.dev.lock:
        r.emu.faults.set_stuck(False)
    r.wait(lambda: not r.node.stuck, message="cleared")
    r.wait(lambda: len(r.ranges) >= n + 3, message="published again")


def test_use_sim_time_stamps_follow_the_clock_topic(rig):
    sim = {"t": 500.0}
    r = rig(Ping1dTruth(altitude_m=1.5), clock=lambda: sim["t"], extra_params=[Parameter("use_sim_time", value=True)])
    tick = r.wall_clock_ticker(sim)

    def stamp():
        return r.ranges[-1].header.stamp.sec + r.ranges[-1].header.stamp.nanosec * 1e-9

    wait_until(lambda: len(r.ranges) >= 3 and stamp() > 500.0, 10, tick, "ranges in sim time")
    assert 500.0 < stamp() <= sim["t"]


def test_main_runs_with_the_params_file_and_stops_cleanly_on_sigint(node_process):
    dev = PtyDevice(Ping1dEmulator(Ping1dTruth(altitude_m=2.0), true_speed_of_sound_m_s=1481.0))
    cmd = [python_executable(), "-m", "hindrax_drivers.ping1d.node", "--ros-args", "--params-file",
           str(default_config_path()), "-p", f"sensors.ping1d.port:={dev.path}"]
    try:
        got = node_process(cmd, Range, "ping/altitude", lambda got: len(got) >= 3, "ranges from the node process")
        assert got[-1].range == pytest.approx(2.0, abs=0.0005)
    finally:
        dev.close()


def test_stream_decoder_tells_truncated_from_corrupted_frames_for_any_chunking():
    frames = [Profile(2.0, 90, 1e-4, k, 0.0, 3.0, 2, bytes(200)).encode(1, 0) for k in range(5)]
    half = [f[: len(f) // 2] for f in frames]
    bad = [f[:-1] + bytes([f[-1] ^ 0xFF]) for f in frames]
    stream = b"U\x80" + half[0] + half[1] + bad[2] + frames[3] + bad[4] + b"\x81" * 3 + frames[0] + half[2]
    for chunk in (len(stream), 1, 7, 100):
        d = Ping1dStreamDecoder()
        out = []
        for i in range(0, len(stream), chunk):
            out += d.feed(stream[i:i + chunk])
        d.finish()
        assert [o.payload.ping_number for o in out] == [3, 0]
        assert d.counts == {"garbage_bytes": 2 + 3, "truncated": 3, "bad_checksum": 2, "unknown_message": 0,
                            "malformed": 0}


def test_frame_id_is_a_parameter(rig):
    """``frame_id`` (default ``ping_link``, the frame the static TF node publishes) reaches the Range header."""
    r = rig(Ping1dTruth(altitude_m=2.0, confidence_pct=90), extra_params=[Parameter("frame_id", value="sonar")])
    r.wait(lambda: len(r.ranges) >= 2, message="ranges")
    assert {m.header.frame_id for m in r.ranges} == {"sonar"}
