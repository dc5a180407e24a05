"""DVL-75 driver node through the real pyserial path: emulator on a pty -> SerialTransport -> node -> topics.

Expected values come from the emulator truth and the wire quantisation of docs/devices.md §1.3 ($DVPDL: 1 mm
position deltas over dtu, 1 us times; $DVEXT: cm altitude, 0.1 deg attitude, 1e-6 quaternion), from the
frame definitions of docs/devices.md §1.5 / REP-103, and from rigid-body kinematics for the lever arm.
Every wait is on a condition with a deadline.
"""
import dataclasses
import math
import random
import subprocess
import time

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import TwistWithCovarianceStamped
from rclpy.parameter import Parameter
from sensor_msgs.msg import Range

from hindrax_common.config import default_config_path
from hindrax_common.base.device_clock import DeviceClockSync
from hindrax_drivers.dvl75.emulator import Dvl75Emulator, DvlTruth
from hindrax_drivers.dvl75.node import Dvl75Node
from hindrax_drivers.dvl75.protocol import DvlPositionDelta, format_dvpdl, format_sentence, parse_line
from hindrax_drivers.dvl75.report import DvlReportBuilder
from hindrax_drivers.dvl75.stream import DvlStreamDecoder
from hindrax_common.base.frames import quaternion_from_euler_ned, quaternion_marine_to_ros
from hindrax_common.testing import (child_env, config_parameters, python_executable,
                                     wait_until)
from hindrax_common.transport.pty_device import PtyDevice
from hindrax_msgs.msg import Dvl, RawDeviceData

pytestmark = pytest.mark.ros

RATE_HZ = 20.0
DT_S = 1.0 / RATE_HZ
VEL_TOL = 0.0005 / DT_S + 1e-6  # +-0.5 mm position quantisation over one dtu (docs/devices.md §1.3.1)
REAL_DVEXT = (b"$DVEXT,F,X,3330,-1.8,2.4,259.5,-1175,0.000,0.00,-0.000,0.000,0.000000000,0.000000000,0.100,"
              b"0.091711,0.019853,0.017436,-0.995435,25,25,25,25,F,F,F,F,0.0000,0.0000,0.0000,0.0000,-1.000,"
              b"-1.000,-1.000,-1.000,*54")  # real capture, docs/devices.md §1.2


def stamp_s(header) -> float:
    return header.stamp.sec + header.stamp.nanosec * 1e-9


class Rig:
    """Emulator on a pty, the node under test, and the probe's subscriptions to every output topic (the ``rig``
    fixture, conftest.py, adds the probe and the executor)."""

    def __init__(self, ctx, truth, overrides=None, extra_params=(), clock=time.time, rate_hz=RATE_HZ,
                 start_disconnected=False):
        self.emu = Dvl75Emulator(truth, rate_hz=rate_hz)
        self.first_poll_s = []

        def emulator_clock():
            t = clock()
            if not self.first_poll_s:
                self.first_poll_s.append(t)  # the emulator boots (tu = 0) at its first poll
            return t

        self.dev = PtyDevice(self.emu, clock=emulator_clock)
        if start_disconnected:
            self.dev.disconnect()  # the device is plugged in later: nothing is lost to discovery
        params = config_parameters({"sensors.dvl75.port": self.dev.path, **(overrides or {})})
        self.start(ctx, Dvl75Node(context=ctx, parameter_overrides=params + self.quiet_stuck_detector(extra_params)),
                   "hindrax/dvl75")
        self.data, self.twist, self.altitude = [], [], []
        self.probe.create_subscription(Dvl, "dvl/data", self._stamped(self.data), 50)
        self.probe.create_subscription(TwistWithCovarianceStamped, "dvl/twist", self._stamped(self.twist), 50)
        self.probe.create_subscription(Range, "dvl/altitude", self._stamped(self.altitude), 50)
        self.raw = self.collect(RawDeviceData, "raw/dvl75", 200)

    def _stamped(self, sink):
        return lambda m: sink.append((m, time.time()))

    def valid(self):
        return [m for m, _ in self.data if m.velocity_valid]

    def diag_values(self, status=None):
        st = status or self.diag[-1]
        return {kv.key: kv.value for kv in st.values}

    def close(self):
        super().close()
        self.dev.close()


STEADY = DvlTruth(velocity_frd_m_s=(0.3, -0.2, 0.05), altitude_m=4.0, roll_rad=0.1, pitch_rad=-0.05, yaw_rad=1.0)


# --------------------------------------------------------------------------------------------- node, through the pty


def test_startup_commands_and_published_values_match_truth(rig):
    overrides = {"sensors.dvl75.sensor_orientation_rpy_rad": [math.radians(a) for a in (1.0, -2.0, 45.0)],
                 "sensors.dvl75.speed_of_sound_m_s": 1500.0}
    r = rig(STEADY, overrides=overrides, start_disconnected=True)
    r.wait(lambda: r.node.raw.publisher.get_subscription_count() and r.node.pub_data.get_subscription_count()
           and r.diag and r.diag[-1].level == DiagnosticStatus.ERROR, message="probe matched")
    assert r.diag_values()["state"] == "disconnected" and r.diag_values()["open_failures"] != "0"
    r.dev.reconnect()
    r.wait(lambda: len(r.valid()) >= 5 and len(r.twist) >= 5 and len(r.altitude) >= 5
           and "CONFIGURATION" in r.emu.commands_received, message="DVL data and the whole start-up sequence")
    # start-up commands seen by the device (docs/devices.md §0 item 1, §1.4; orientation sent in degrees)
    cmds = r.emu.commands_received
    for expected in ("SEND-DVPDL ON", "SEND-DVEXT ON", "SET-SENSOR-ORIENTATION 1,-2,45", "SET-SPEED-OF-SOUND 1500"):
        assert expected in cmds, cmds
    assert r.emu.flash.send_dvpdl and r.emu.flash.speed_of_sound_m_s == 1500.0
    assert np.allclose(r.emu.flash.sensor_orientation_rad, np.radians([1.0, -2.0, 45.0]))

    m = r.valid()[-1]
    assert m.header.frame_id == "base_link"
    # FRD (0.3, -0.2, 0.05) -> base_link FLU (0.3, 0.2, -0.05) (REP-103)
    assert [m.velocity_m_s.x, m.velocity_m_s.y, m.velocity_m_s.z] == pytest.approx([0.3, 0.2, -0.05], abs=VEL_TOL)
    assert [m.delta_position_m.x, m.delta_position_m.y, m.delta_position_m.z] == pytest.approx(
        [0.3 * DT_S, 0.2 * DT_S, -0.05 * DT_S], abs=0.0005 + 1e-9)
    assert m.delta_time_s == pytest.approx(DT_S, abs=1e-9)
    assert m.confidence_percent == 100.0 and m.bottom_lock
    assert list(m.velocity_covariance) == pytest.approx([0.02 ** 2, 0, 0, 0, 0.02 ** 2, 0, 0, 0, 0.02 ** 2])
    # vertical altitude over a flat bottom: along-axis (cm) projected with the 0.1 deg attitude
    assert m.altitude_m == pytest.approx(4.0, abs=0.006)
    # orientation: FLU body in ENU (docs/devices.md §1.5), the REP-103 form of the NED/FRD truth
    q_expected = quaternion_marine_to_ros(quaternion_from_euler_ned([0.1, -0.05, 1.0]))
    q = np.array([m.orientation.x, m.orientation.y, m.orientation.z, m.orientation.w])
    assert min(np.abs(q - q_expected).max(), np.abs(q + q_expected).max()) < 2e-5
    assert m.orientation_covariance[0] == -1.0
    assert all(m.beam_lock) and all(rng > 4.0 for rng in m.beam_range_m)  # slant > vertical

    tw, _ = r.twist[-1]
    assert tw.header.frame_id == "base_link"
    assert [tw.twist.twist.linear.x, tw.twist.twist.linear.y, tw.twist.twist.linear.z] == pytest.approx(
        [0.3, 0.2, -0.05], abs=VEL_TOL)
    cov = np.array(tw.twist.covariance).reshape(6, 6)
    assert np.allclose(cov[:3, :3], np.eye(3) * 0.02 ** 2)
    assert np.allclose(np.diag(cov)[3:], -1.0) and np.count_nonzero(cov - np.diag(np.diag(cov))) == 0

    rng, _ = r.altitude[-1]
    assert rng.header.frame_id == "dvl_link" and rng.radiation_type == Range.ULTRASOUND
    assert rng.range == pytest.approx(4.0 / (math.cos(0.1) * math.cos(0.05)), abs=0.0051)
    assert (rng.min_range, rng.max_range) == pytest.approx((0.3, 40.0))

    # raw traffic in both directions
    def joined(direction):
        return b"".join(bytes(x.data) for x in r.raw if x.direction == direction)

    r.wait(lambda: b"$DVPDL," in joined(RawDeviceData.DIRECTION_DEVICE_TO_HOST), message="raw rx")
    tx = joined(RawDeviceData.DIRECTION_HOST_TO_DEVICE)
    assert tx.startswith(b"SEND-DVPDL ON\r\nSEND-DVEXT ON\r\n") and b"SET-SPEED-OF-SOUND 1500\r\n" in tx
    assert all(x.device_name == "dvl75" and x.transport == RawDeviceData.TRANSPORT_SERIAL for x in r.raw)


def test_stamps_are_the_dvl_time_of_validity_mapped_to_ros_time(rig):
    """Emulator clock = ROS (system) time, boot at its first poll: $DVPDL tu = k * dtu exactly,
    so the time of validity of the mean velocity is boot + tu - dtu/2. Every (tu, receive time)
    pair the node takes in is recorded; its stamp is that time of validity plus the smallest
    latency seen so far (r - tu - boot, min filter over 10 s of DVL time). A receive-time stamp
    would sit >= dtu/2 later. No bound on the latency itself: a starved machine delays the
    reader, not the mapping."""
    r = rig(STEADY, start_disconnected=True)
    samples = []  # (tu ns, node receive ns) in arrival order, from the first sentence on
    update = r.node.clock_sync.update
    r.node.clock_sync.update = lambda device_ns, receive_ns: (
        samples.append((int(device_ns), int(receive_ns))), update(device_ns, receive_ns))[1]
    r.dev.reconnect()
    r.wait(lambda: len(r.valid()) >= 20, message="DVL data")
    boot_ns = round(r.first_poll_s[0] * 1e9)
    window_ns, dtu_ns = 10 * 10**9, round(DT_S * 1e9)
    expected = {}  # stamp the min filter gives -> (time of validity, receive time) of that sentence
    for i, (tu, received_ns) in enumerate(list(samples)):
        # whole ms; sent when due or later
        assert tu % 1_000_000 == 0 and received_ns - (boot_ns + tu) >= -1_000_000
        offset = min(rcv - d for d, rcv in samples[:i + 1] if d >= tu - window_ns)
        expected[tu - dtu_ns // 2 + offset] = (boot_ns + tu - dtu_ns // 2, received_ns)
    for m in r.valid()[-15:]:
        s = m.header.stamp.sec * 10**9 + m.header.stamp.nanosec
        assert s in expected, s
        validity_ns, received_ns = expected[s]
        assert s - validity_ns >= -1_000_000  # not before the time of validity (tu in whole ms)
        # not the receive time (equal when this sentence set the minimum)
        assert s <= received_ns - dtu_ns // 2


def test_beam_velocity_signs_follow_the_motion(rig):
    """Dvl.beam_velocity_m_s is + away from the transducer: moving forward, the bow beam (D) closes on the
    bottom (negative) and the stern beam (B) opens (positive); port/starboard see no along-beam motion."""
    r = rig(DvlTruth(velocity_frd_m_s=(0.4, 0.0, 0.0), altitude_m=3.0))
    r.wait(lambda: len(r.valid()) >= 3, message="DVL data")
    a, b, c, d = r.valid()[-1].beam_velocity_m_s
    assert d < -0.1 and b > 0.1 and abs(a) < 1e-3 and abs(c) < 1e-3
    assert d == pytest.approx(-b, abs=2e-4)


def test_unlocked_or_zero_confidence_dvl_publishes_no_velocity(rig):
    r = rig(STEADY)
    r.wait(lambda: len(r.valid()) >= 3, message="locked data")
    with r.dev.lock:
        r.emu.set_unlocked(True)
    r.wait(lambda: len(r.data) and not r.data[-1][0].velocity_valid, message="first unlocked report")
    first_invalid = len(r.data) - 1
    r.wait(lambda: len(r.data) >= first_invalid + 6 and len(r.altitude) >= 3
           and math.isinf(r.altitude[-1][0].range), message="unlocked reports")
    t_unlock = stamp_s(r.data[first_invalid][0].header)
    for k, (m, _) in enumerate(r.data[first_invalid:]):
        assert not m.velocity_valid and m.confidence_percent == 0.0
        v = [m.velocity_m_s.x, m.velocity_m_s.y, m.velocity_m_s.z]
        d = [m.delta_position_m.x, m.delta_position_m.y, m.delta_position_m.z]
        assert all(math.isnan(x) for x in v + d) and m.velocity_covariance[0] == -1.0
        if k:  # lock, altitude and beams come from the latest $DVEXT: one ping cycle later
            assert not m.bottom_lock and not any(m.beam_lock)
            assert all(math.isnan(x) for x in [m.altitude_m] + list(m.beam_range_m))
    assert all(stamp_s(tw.header) < t_unlock for tw, _ in r.twist)  # no twist from an unlocked report
    assert math.isinf(r.altitude[-1][0].range) and r.altitude[-1][0].range > 0  # REP-117 "no detection"

    # locked but confidence 0: still no velocity
    with r.dev.lock:
        r.emu.set_unlocked(False)
        r.emu.set_zero_confidence(True)
    r.wait(lambda: r.data[-1][0].bottom_lock and r.data[-1][0].confidence_percent == 0.0, message="c=0")
    n_twist, n_data = len(r.twist), len(r.data)
    r.wait(lambda: len(r.data) >= n_data + 5, message="more c=0 reports")
    assert not any(m.velocity_valid for m, _ in r.data[n_data:])
    assert all(stamp_s(tw.header) < stamp_s(r.data[n_data][0].header) for tw, _ in r.twist)
    # and back
    with r.dev.lock:
        r.emu.set_zero_confidence(False)
    r.wait(lambda: len(r.twist) > n_twist and r.data[-1][0].velocity_valid, message="valid again")


def _diag_until(r, predicate, timeout_s=5.0, message="diagnostics"):
    return r.wait(lambda: r.diag and predicate(r.diag_values()), timeout_s, message)


def test_garbage_bad_checksums_truncated_lines_and_unknown_sentences_are_counted_not_fatal(rig):
    r = rig(STEADY)
    # wait until the start-up sequence (ending with CONFIGURATION, answered in free text) is over
    r.wait(lambda: r.node.commands.sequences_completed >= 1 and len(r.valid()) >= 3, message="steady")
    r.wait(lambda: r.node.decoder.records.get("DvlText", 0) >= 18 and len(r.valid()) >= 6, message="config dump")
    with r.dev.lock:
        r.emu.faults.inject_garbage(n_bytes=40)  # 0x80-0xFF line noise
        r.emu.faults.truncate(2)
        r.emu.faults.corrupt_checksum(3)
        r.emu.faults.inject_garbage(data=format_sentence("DVNVM,SPEED-OF-SOUND=1481"))  # unknown sentence
    _diag_until(r, lambda v: v.get("errors.bad_checksum") == "3" and v.get("errors.truncated") == "2"
                and v.get("errors.unknown_sentence") == "1", message="error counters")
    v = r.diag_values()
    assert int(v["errors.garbage_bytes"]) >= 40 and "errors.malformed" not in v
    # a storm of arbitrary bytes (any value, including '$', '*', CR, LF) does not stop the node either
    rng = random.Random(7)
    with r.dev.lock:
        r.emu.faults.inject_garbage(data=bytes(rng.randrange(256) for _ in range(3000)))
    n = len(r.valid())
    r.wait(lambda: len(r.valid()) >= n + 10, message="data after the faults")
    m = r.valid()[-1]
    assert [m.velocity_m_s.x, m.velocity_m_s.y, m.velocity_m_s.z] == pytest.approx([0.3, 0.2, -0.05], abs=VEL_TOL)
    assert "internal_error" not in r.node.diag.counts()
    assert r.node.transport.status().callback_errors == 0


def test_device_disappears_and_comes_back_node_reconnects_at_the_next_attempt_and_resends_startup(rig):
    r = rig(STEADY)
    r.wait(lambda: len(r.valid()) >= 3, message="data")
    assert r.emu.commands_received.count("SEND-DVPDL ON") == 1
    r.dev.disconnect()
    with r.dev.lock:
        r.emu.flash.send_dvpdl = False  # a DVL at factory settings comes back: the node must re-enable it
    _diag_until(r, lambda v: v["state"] == "reconnecting", message="reconnecting in diagnostics")
    assert r.diag[-1].level == DiagnosticStatus.ERROR
    failures = r.node.transport.status().open_failures
    r.dev.reconnect()
    # reconnected at the first open attempt after the device came back (at most one was under way), i.e.
    # within one backoff period (1 s); counted in attempts because a loaded CI can miss a wall-clock deadline
    _diag_until(r, lambda v: v["state"] == "connected" and v["reconnects"] == "1", timeout_s=30.0,
                message="reconnected")
    assert r.node.transport.status().open_failures <= failures + 1
    assert "reconnected" in r.diag[-1].message
    n = len(r.valid())
    r.wait(lambda: r.emu.commands_received.count("SEND-DVPDL ON") == 2 and len(r.valid()) >= n + 3,
           message="start-up resent and data flowing")


def test_dvpdl_switched_off_behind_the_drivers_back_is_switched_on_again(rig):
    """$DVEXT flowing without $DVPDL (e.g. a DVL reset to factory defaults, docs/devices.md §0 item 1): the node
    keeps publishing dvl/data from $DVEXT with no velocity, warns, and resends its start-up commands."""
    r = rig(STEADY)
    r.wait(lambda: len(r.valid()) >= 3 and r.node.commands.sequences_completed >= 1, message="data")
    with r.dev.lock:
        r.emu.flash.send_dvpdl = False
    r.wait(lambda: r.data and r.data[-1][0].bottom_lock and math.isnan(r.data[-1][0].delta_time_s),
           message="reports from $DVEXT alone")
    assert not r.data[-1][0].velocity_valid and r.data[-1][0].altitude_m == pytest.approx(4.0, abs=0.006)
    r.wait(lambda: r.emu.commands_received.count("SEND-DVPDL ON") >= 2, 8.0, "start-up resent")
    n = len(r.valid())
    r.wait(lambda: len(r.valid()) >= n + 3, message="velocity again")
    assert r.node.diag.counts().get("startup_resends", 0) >= 1


def _moving_truth(t):
    return DvlTruth(velocity_frd_m_s=(0.3 + 0.1 * math.sin(2 * t), 0.05 * math.cos(3 * t), 0.0),
                    altitude_m=3.0 + 0.2 * math.sin(t), roll_rad=0.0, pitch_rad=0.0, yaw_rad=0.5 * math.sin(t))


def test_stuck_sensor_is_an_error_and_its_velocity_and_altitude_are_withdrawn(rig):
    r = rig(_moving_truth, extra_params=[Parameter("stuck_limit_samples", value=10)])
    r.wait(lambda: len(r.valid()) >= 15, message="data")
    assert not r.node.stuck
    with r.dev.lock:
        r.emu.faults.set_stuck(True)
    r.wait(lambda: "dvext" in r.node._stuck_now and "dvpdl" in r.node._stuck_now, 5.0, "stuck detected")
    detected_ns = r.node.now_ns()  # at or after the detection of both sentences
    n_data, n_alt = len(r.data), len(r.altitude)
    r.wait(lambda: len(r.data) >= n_data + 5 and r.diag and "stuck" in r.diag[-1].message, 5.0,
           "stuck reports and the stuck error in diagnostics")
    assert r.diag[-1].level == DiagnosticStatus.ERROR
    assert r.node.stuck  # still frozen: from the first withdrawn report on, none has a velocity
    first = next(i for i in range(n_data, len(r.data)) if not r.data[i][0].velocity_valid)
    assert first < len(r.data) - 3  # (reports published before the detection may arrive after n_data)
    assert not any(m.velocity_valid for m, _ in r.data[first:])
    assert all(math.isnan(m.velocity_m_s.x) and m.velocity_covariance[0] == -1.0 for m, _ in r.data[first:])
    assert all(stamp_s(tw.header) < stamp_s(r.data[first][0].header) for tw, _ in r.twist)  # no twist since
    assert not [a for a, _ in r.altitude if stamp_s(a.header) * 1e9 > detected_ns + 1e3]  # no altitude since
    with r.dev.lock:
        r.emu.faults.set_stuck(False)
    r.wait(lambda: not r.node.stuck, message="stuck cleared")
    n = len(r.valid())
    r.wait(lambda: len(r.valid()) >= n + 3 and len(r.altitude) > n_alt + 2, message="valid data again")
    r.wait(lambda: r.diag[-1].level == DiagnosticStatus.OK, 5.0, "error cleared")


def test_implausible_but_checksum_valid_dvpdl_is_published_not_valid_with_an_error(rig):
    """$DVPDL with 999.999 m over 0.1 s (9999.99 m/s) and with a 1 us interval (1e306 m/s from a 1e300 m
    field): both pass the XOR checksum and the parser; the gates sensors.dvl75.max_speed_m_s (4.1 m/s) and
    min_interval_s (25 ms) of the vehicle file publish them with velocity_valid false and raise ERROR."""
    r = rig(STEADY)
    r.wait(lambda: len(r.valid()) >= 3 and r.node.commands.sequences_completed >= 1, message="data")
    tu = time.time() - r.first_poll_s[0]  # the emulator's clock: after every $DVPDL sent so far
    bad = [format_dvpdl(_pdl(time_since_boot_s=tu, delta_time_s=0.1, delta_x_m=999.999)),
           format_dvpdl(_pdl(time_since_boot_s=tu + 1e-6, delta_time_s=1e-6, delta_x_m=1e300))]
    assert all(parse_line(line.strip()).confidence_pct == 100 for line in bad)  # checksum and fields parse
    with r.dev.lock:
        r.emu.faults.inject_garbage(data=b"".join(bad))
    r.wait(lambda: r.node.diag.counts().get("implausible_velocity", 0) >= 2, message="both rejected")
    r.wait(lambda: any(st.level == DiagnosticStatus.ERROR and "implausible" in st.message for st in r.diag),
           5.0, "ERROR in diagnostics")
    def rejected_reports():
        return [m for m, _ in r.data if m.confidence_percent == 100.0
                and any(abs(m.delta_time_s - dt) < 1e-6 * dt for dt in (0.1, 1e-6))]

    rejected = r.wait(lambda: len(rejected_reports()) == 2 and rejected_reports(), 5.0, "both reports received")
    assert all(not m.velocity_valid and math.isnan(m.velocity_m_s.x) and m.velocity_covariance[0] == -1.0
               for m in rejected)
    assert all(abs(tw.twist.twist.linear.x) < 1.0 for tw, _ in r.twist)  # no twist from them
    n = len(r.valid())
    r.wait(lambda: len(r.valid()) >= n + 3, message="plausible data again")
    r.wait(lambda: r.diag[-1].level == DiagnosticStatus.OK, 8.0, "error cleared 2 s after the last rejection")


def test_use_sim_time_stamps_follow_the_clock_topic(rig):
    sim = {"t": 1000.0}
    r = rig(STEADY, clock=lambda: sim["t"], extra_params=[Parameter("use_sim_time", value=True)])
    tick = r.wall_clock_ticker(sim)
    wait_until(lambda: len(r.valid()) >= 5 and stamp_s(r.valid()[-1].header) > 1000.0, 10, tick, "sim data")
    wait_until(lambda: len(r.altitude) >= 3 and stamp_s(r.altitude[-1][0].header) > 1000.0, 10, tick, "range")
    for stamp in (stamp_s(r.valid()[-1].header), stamp_s(r.altitude[-1][0].header)):
        assert 1000.0 < stamp <= sim["t"] + 1e-6  # simulated time, not the wall clock (~1.7e9 s)


# --------------------------------------------------------------------------------------------- the process entry point


def test_main_runs_with_the_params_file_and_stops_cleanly_on_sigint(node_process):
    emu = Dvl75Emulator(STEADY, rate_hz=RATE_HZ)
    dev = PtyDevice(emu)
    cmd = [python_executable(), "-m", "hindrax_drivers.dvl75.node", "--ros-args", "--params-file",
           str(default_config_path()), "-p", f"sensors.dvl75.port:={dev.path}",
           "-p", "stuck_limit_samples:=100000"]  # constant truth: identical reports, however slow the start
    try:
        node_process(cmd, Dvl, "dvl/data", lambda got: sum(m.velocity_valid for m in got) >= 3,
                     "data from the node process")
        assert "SEND-DVPDL ON" in emu.commands_received
    finally:
        dev.close()


def test_main_refuses_an_invalid_configuration_with_one_line():
    cmd = [python_executable(), "-m", "hindrax_drivers.dvl75.node", "--ros-args", "--params-file",
           str(default_config_path()), "-p", "sensors.dvl75.speed_of_sound_m_s:=5000.0"]
    res = subprocess.run(cmd, env=child_env(), capture_output=True, text=True, timeout=60)
    assert res.returncode == 1
    assert "sensors.dvl75.speed_of_sound_m_s" in res.stderr and "5000" in res.stderr


# --------------------------------------------------------------------------------------------- pure cores


def _pdl(**kw):
    base = dict(time_since_boot_s=10.0, delta_time_s=0.1, delta_roll_rad=0.0, delta_pitch_rad=0.0,
                delta_yaw_rad=0.0, delta_x_m=0.0, delta_y_m=0.0, delta_z_m=0.0, confidence_pct=100)
    base.update(kw)
    return DvlPositionDelta(**base)


def _ext(**kw):
    return dataclasses.replace(parse_line(REAL_DVEXT), **kw)


def test_lever_arm_rolling_in_place_gives_zero_base_link_velocity():
    """DVL 0.5 m below the CG, vehicle rolling at p = 0.1 rad/s about the CG: the transducer moves at
    omega x r = (0, -0.05, 0) m/s FRD (to port) but base_link does not move (v_CG = v_DVL - omega x r)."""
    b = DvlReportBuilder(position_frd_m=(0.0, 0.0, 0.5))
    rep = b.from_position_delta(_pdl(delta_roll_rad=0.01, delta_y_m=-0.005), receive_ns=0)
    assert rep.velocity_valid and rep.velocity_flu_m_s == pytest.approx((0.0, 0.0, 0.0), abs=1e-12)
    # yawing at r = 0.2 rad/s with the DVL 0.3 m ahead of the CG, vehicle surging at 0.5 m/s:
    # DVL sees (0.5, 0.06, 0) FRD; base_link gets (0.5, 0, 0) FRD = (0.5, 0, 0) FLU
    b = DvlReportBuilder(position_frd_m=(0.3, 0.0, 0.0))
    rep = b.from_position_delta(_pdl(delta_yaw_rad=0.02, delta_x_m=0.05, delta_y_m=0.006), receive_ns=0)
    assert rep.velocity_flu_m_s == pytest.approx((0.5, 0.0, 0.0), abs=1e-12)
    assert rep.delta_position_flu_m == pytest.approx((0.05, 0.0, 0.0), abs=1e-12)
    # the midpoint of the interval is the time of validity
    assert rep.device_time_ns == 10_000_000_000 - 50_000_000


def test_validity_gating_uses_confidence_dtu_and_a_fresh_dvext_lock():
    b = DvlReportBuilder()
    assert b.from_position_delta(_pdl(delta_x_m=0.03), 0).velocity_valid  # no DVEXT yet: confidence decides
    assert not b.from_position_delta(_pdl(delta_x_m=0.03, confidence_pct=0), 0).velocity_valid
    assert not b.from_position_delta(_pdl(delta_x_m=0.03, delta_time_s=0.0), 0).velocity_valid
    b.update_extended(_ext(locked=False), receive_ns=1_000_000_000)
    rep = b.from_position_delta(_pdl(delta_x_m=0.03), receive_ns=1_050_000_000)
    assert not rep.velocity_valid and math.isnan(rep.velocity_flu_m_s[0])  # DVEXT says searching
    assert rep.twist_covariance[0] == -1.0 and rep.velocity_covariance[0] == -1.0
    rep = b.from_position_delta(_pdl(delta_x_m=0.03), receive_ns=2_500_000_000)  # that DVEXT is 1.5 s old
    assert rep.velocity_valid and rep.velocity_flu_m_s[0] == pytest.approx(0.3)


def test_plausibility_gates_speed_and_interval():
    b = DvlReportBuilder(max_speed_m_s=4.1, min_interval_s=0.025, max_interval_s=1.0)
    ok = b.from_position_delta(_pdl(delta_x_m=0.4, delta_y_m=0.1), 0)  # 4.12 m/s over 0.1 s
    assert not ok.velocity_valid and "speed" in ok.rejection
    ok = b.from_position_delta(_pdl(delta_x_m=0.4), 0)  # 4.0 m/s: inside the envelope
    assert ok.velocity_valid and ok.rejection == "" and ok.velocity_flu_m_s[0] == pytest.approx(4.0)
    for pdl, word in ((_pdl(delta_x_m=999.999), "speed"), (_pdl(delta_time_s=1e-6, delta_x_m=1e300), "dtu"),
                      (_pdl(delta_time_s=0.024, delta_x_m=0.001), "dtu"), (_pdl(delta_time_s=1.001), "dtu"),
                      (_pdl(delta_x_m=math.inf), "finite"), (_pdl(delta_x_m=math.nan), "finite"),
                      (_pdl(delta_z_m=1e300), "speed")):  # 1e300 ** 2 overflowed (found by the property test)
        rep = b.from_position_delta(pdl, 0)
        assert not rep.velocity_valid and word in rep.rejection, (pdl, rep.rejection)
        assert all(math.isnan(v) for v in rep.velocity_flu_m_s) and rep.twist_covariance[0] == -1.0
    # without gates only finiteness is checked; zero confidence is never a candidate (no rejection reason)
    assert DvlReportBuilder().from_position_delta(_pdl(delta_x_m=999.999), 0).velocity_valid
    assert DvlReportBuilder().from_position_delta(_pdl(delta_x_m=math.inf), 0).rejection
    assert b.from_position_delta(_pdl(delta_x_m=999.999, confidence_pct=0), 0).rejection == ""


def test_dvext_fields_altitude_projection_beams_and_quaternion():
    b = DvlReportBuilder()
    ext = _ext(locked=True, altitude_m=5.0, roll_rad=0.2, pitch_rad=0.1,
               beam_locked=(True, False, True, True), beam_velocity_m_s=(0.1, 0.2, -0.3, 0.4),
               beam_range_m=(5.5, -1.0, 5.4, 5.3))
    b.update_extended(ext, 0)
    rep = b.from_position_delta(_pdl(), 0)
    assert rep.altitude_m == pytest.approx(5.0 * math.cos(0.2) * math.cos(0.1))
    assert rep.beam_lock == (True, False, True, True)
    assert rep.beam_velocity_m_s[0] == -0.1 and rep.beam_velocity_m_s[2] == 0.3  # + away from the transducer
    assert math.isnan(rep.beam_velocity_m_s[1]) and math.isnan(rep.beam_range_m[1])
    # the real capture's quaternion (w, x, y, z) = (0.091711, 0.019853, 0.017436, -0.995435) reordered, unit norm
    q = np.array(rep.orientation_xyzw)
    assert np.linalg.norm(q) == pytest.approx(1.0)
    assert q == pytest.approx(np.array([0.019853, 0.017436, -0.995435, 0.091711]) / np.linalg.norm(
        [0.019853, 0.017436, -0.995435, 0.091711]))
    assert math.isnan(b.from_extended(_ext(locked=False)).altitude_m)


def test_dvpdl_without_dvext_has_no_attitude_not_a_level_one():
    """$DVPDL alone (SEND-DVEXT off, or $DVEXT older than max_extended_age_s): the report carries the all-zero
    quaternion ("no attitude", hindrax_msgs/Dvl) and unknown covariance, never the identity (level) that the
    supervisor would take for 0 roll and 0 pitch."""
    b = DvlReportBuilder(max_extended_age_s=1.0)
    rep = b.from_position_delta(_pdl(), 0)
    assert rep.velocity_valid and rep.orientation_xyzw == (0.0, 0.0, 0.0, 0.0)
    assert rep.orientation_covariance[0] == -1.0
    b.update_extended(_ext(locked=True), 0)
    assert np.linalg.norm(b.from_position_delta(_pdl(), 500_000_000).orientation_xyzw) == pytest.approx(1.0)
    assert b.from_position_delta(_pdl(), 1_500_000_000).orientation_xyzw == (0.0, 0.0, 0.0, 0.0)  # $DVEXT stale


def test_device_clock_sync_minimum_latency_reboot_and_time_jump():
    s = DeviceClockSync(window_s=10.0, jump_s=1.0, resync_samples=3)
    offset = 1_000_000_000_000
    for k, latency_ms in enumerate([5, 2, 7, 3]):
        s.update(k * 50_000_000, k * 50_000_000 + offset + latency_ms * 1_000_000)
    assert s.offset_ns == offset + 2_000_000  # the smallest latency seen
    assert s.to_ros_ns(500_000_000) == 500_000_000 + offset + 2_000_000
    s.update(10_000_000, 5 * 50_000_000 + offset + 1_000_000)  # device clock went back: reboot
    assert s.resets == 1 and s.offset_ns == 5 * 50_000_000 + offset + 1_000_000 - 10_000_000
    base = s.offset_ns
    for k in range(3):  # ROS time jumped 100 s forward
        s.update(20_000_000 + k * 50_000_000, 20_000_000 + k * 50_000_000 + base + 100_000_000_000)
    assert s.resets == 2 and s.offset_ns == base + 100_000_000_000
    # slow drift (100 ppm) is followed through the sliding window
    s = DeviceClockSync(window_s=2.0)
    for k in range(400):
        d = k * 50_000_000
        s.update(d, d + offset + d // 10_000)
    d_last = 399 * 50_000_000
    assert abs(s.offset_ns - (offset + d_last // 10_000)) <= 200_000  # within the 2 s window's drift


def test_stream_decoder_counts_are_exact_and_independent_of_chunking():
    good = [format_dvpdl(_pdl(time_since_boot_s=1.0 + 0.1 * k, delta_x_m=0.01 * k)) for k in range(5)]
    bad = bytearray(good[1])
    bad[-4] ^= 0x01  # one bit flipped in the checksum digits
    stream = (b"\x80\x81\x82" + good[0] + bytes(bad) + good[2][:20] + good[3] + b"$DVPDL,1,2\r\n"
              + format_sentence("DVNVM,A=1") + b"IMU:1,2,3\r\n" + REAL_DVEXT + b"\r\n" + good[4])
    for chunk in (len(stream), 1, 5, 64):
        d = DvlStreamDecoder()
        recs = []
        for i in range(0, len(stream), chunk):
            recs += d.feed(stream[i:i + chunk])
        assert d.counts["bad_checksum"] == 1 and d.counts["truncated"] == 2 and d.counts["unknown_sentence"] == 2
        assert d.counts["garbage_bytes"] == 3 + 20 and d.counts["malformed"] == 0
        assert [type(x).__name__ for x in recs].count("DvlPositionDelta") == 3
        assert [type(x).__name__ for x in recs].count("DvlExtended") == 1


def test_frame_ids_are_parameters_with_rep103_defaults(rig):
    """``frame_id`` (the beam's Range) and ``base_frame_id`` (velocity) set by parameter reach every header."""
    frames = [Parameter("frame_id", value="dvl_down"), Parameter("base_frame_id", value="hull")]
    r = rig(STEADY, extra_params=frames)
    r.wait(lambda: len(r.valid()) >= 2 and len(r.twist) >= 2 and len(r.altitude) >= 2, message="DVL data")
    assert {m.header.frame_id for m in r.valid()} == {"hull"}
    assert {m.header.frame_id for m, _ in r.twist} == {"hull"}
    assert {m.header.frame_id for m, _ in r.altitude} == {"dvl_down"}
