"""Lean CDR (hindrax_common.cdr.lean_cdr): what rosbags encodes, rclpy's own typesupport decodes to the same message,
and what rclpy serialises, rosbags decodes to the same fields. rclpy's deserialiser is the reference here, not code
of this project."""
import math

import numpy as np
import pytest
from geometry_msgs.msg import WrenchStamped
from rclpy.serialization import deserialize_message, serialize_message

from hindrax_common.cdr.lean_cdr import cdr_decoder, cdr_encoder, lean_class, thruster_pwm_cdr, wrench_stamped_cdr
from hindrax_msgs.msg import ThrusterPwm


def test_a_wrench_encoded_by_rosbags_is_the_message_rclpy_would_publish():
    w = [1.5, -2.25, 3e-3, -4.0, 5.5, -6.125]
    data = wrench_stamped_cdr(1_732_500_000_123_456_789, "base_link", np.array(w))
    ref = WrenchStamped()
    ref.header.stamp.sec, ref.header.stamp.nanosec, ref.header.frame_id = 1_732_500_000, 123_456_789, "base_link"
    ref.wrench.force.x, ref.wrench.force.y, ref.wrench.force.z = w[:3]
    ref.wrench.torque.x, ref.wrench.torque.y, ref.wrench.torque.z = w[3:]
    assert deserialize_message(data, WrenchStamped) == ref
    # the same length and bytes but for the string's padding (rosbags zeroes it; Fast CDR leaves what was there)
    assert len(data) == len(serialize_message(ref))


def test_thruster_widths_encoded_by_rosbags_decode_in_rclpy_nan_included():
    widths = [1500.0, 1525.2, math.nan, 1899.96, 1100.0, 1500.0, 1474.8, 1650.0]
    data = thruster_pwm_cdr(2_000_000_001, "base_link", widths, True, ThrusterPwm.OUTPUT_COMMANDING)
    got = deserialize_message(data, ThrusterPwm)
    assert (got.header.stamp.sec, got.header.stamp.nanosec, got.header.frame_id) == (2, 1, "base_link")
    assert got.armed is True and got.output_state == ThrusterPwm.OUTPUT_COMMANDING
    assert len(got.pulse_width_us) == 8 and math.isnan(got.pulse_width_us[2])
    assert [x for i, x in enumerate(got.pulse_width_us) if i != 2] == [x for i, x in enumerate(widths) if i != 2]


def test_rclpy_bytes_decode_in_rosbags_to_the_same_fields_and_back():
    ref = ThrusterPwm(pulse_width_us=[1510.0, 1490.0], armed=False, output_state=ThrusterPwm.OUTPUT_NEUTRAL)
    ref.header.frame_id = "base_link"
    lean = cdr_decoder(ThrusterPwm)(serialize_message(ref))
    assert list(lean.pulse_width_us) == [1510.0, 1490.0] and lean.armed is False and lean.output_state == 1
    assert deserialize_message(cdr_encoder(ThrusterPwm)(lean), ThrusterPwm) == ref
    assert lean_class(ThrusterPwm) is type(lean)


def test_bytes_that_are_not_the_type_raise_and_a_non_message_is_refused():
    with pytest.raises(Exception):  # noqa: B017 - rosbags raises several types; the node catches them all
        cdr_decoder(WrenchStamped)(b"\x00\x01\x00\x00\x05")
    with pytest.raises(ValueError, match="not a ROS message class"):
        cdr_encoder(int)


def test_an_imu_sample_encoded_by_rosbags_is_the_message_rclpy_would_publish():
    from sensor_msgs.msg import Imu

    from hindrax_common.cdr.lean_cdr import imu_cdr

    acc, gyr = np.array([0.1, -0.2, 9.81]), np.array([1e-3, -2e-3, 0.5])
    acc_cov, gyr_cov = np.diag([1e-4, 2e-4, 3e-4]), np.diag([4e-6, 5e-6, 6e-6])
    ref = Imu()
    ref.header.stamp.sec, ref.header.stamp.nanosec, ref.header.frame_id = 7, 500, "imu_link"
    ref.orientation_covariance[0] = -1.0
    ref.linear_acceleration.x, ref.linear_acceleration.y, ref.linear_acceleration.z = acc
    ref.angular_velocity.x, ref.angular_velocity.y, ref.angular_velocity.z = gyr
    ref.linear_acceleration_covariance, ref.angular_velocity_covariance = acc_cov.ravel(), gyr_cov.ravel()
    assert deserialize_message(imu_cdr(7_000_000_500, "imu_link", acc, gyr, acc_cov, gyr_cov), Imu) == ref


def test_the_esc_state_encoded_by_rosbags_is_the_status_rclpy_would_publish():
    from diagnostic_msgs.msg import DiagnosticStatus, KeyValue

    from hindrax_common.cdr.lean_cdr import diagnostic_status_cdr

    ref = DiagnosticStatus(level=DiagnosticStatus.ERROR, name="hindrax/esc", message="unknown", hardware_id="esc",
                           values=[KeyValue(key="output_state", value="0"), KeyValue(key="armed", value="false")])
    data = diagnostic_status_cdr(DiagnosticStatus.ERROR, "hindrax/esc", "unknown", "esc",
                                 [("output_state", "0"), ("armed", "false")])
    assert deserialize_message(data, DiagnosticStatus) == ref
    empty = DiagnosticStatus(level=DiagnosticStatus.OK, name="hindrax/supervisor", message="", hardware_id="")
    assert deserialize_message(diagnostic_status_cdr(0, "hindrax/supervisor", "", ""), DiagnosticStatus) == empty
    assert deserialize_message(diagnostic_status_cdr(DiagnosticStatus.OK, "hindrax/supervisor", "", ""),
                               DiagnosticStatus) == empty  # rclpy's constant (b"\x00") as well as an int


#: heartbeats as rclpy builds them: every field at its extremes, an empty, an ASCII and a UTF-8 message
HEARTBEATS = [
    dict(boot_id=1, seq=1, steady_ns=0, level=0, message=""),
    dict(boot_id=2**64 - 1, seq=2**64 - 1, steady_ns=2**63, guard_boot_id=2**64 - 1, guard_seq=2**64 - 1, level=2,
         output_state=2, armed=True, message="output state unknown: I2C write failed"),
    dict(boot_id=0x0123456789ABCDEF, seq=7, steady_ns=123_456_789, guard_boot_id=42, guard_seq=41, level=0,
         output_state=1, armed=False, message="Tiefe über 2 m, 40 °"),
]


@pytest.mark.parametrize("fields", HEARTBEATS, ids=["smallest", "largest", "utf-8"])
def test_a_heartbeat_packed_at_fixed_offsets_is_the_message_rclpy_would_publish(fields):
    """The heartbeats are packed and read with struct (lean_cdr.heartbeat_cdr, read_heartbeat), not by a generated
    serialiser: both must agree with rclpy's own, both ways."""
    from hindrax_msgs.msg import Heartbeat

    from hindrax_common.cdr.lean_cdr import heartbeat_cdr, read_heartbeat

    ref = Heartbeat(**fields)
    assert deserialize_message(heartbeat_cdr(**fields), Heartbeat) == ref
    beat = read_heartbeat(serialize_message(ref))
    assert beat is not None and beat._asdict() == {k: getattr(ref, k) for k in beat._fields}


def test_bytes_that_are_not_a_heartbeat_read_as_none():
    """What a raw heartbeat subscription may be handed that is not one: never a crash, never a beat (fail closed:
    the receiver rejects it and does not count the peer as heard)."""
    from hindrax_msgs.msg import Heartbeat

    from hindrax_common.cdr.lean_cdr import read_heartbeat

    good = serialize_message(Heartbeat(boot_id=1, seq=1, message="ok"))
    assert read_heartbeat(good) is not None
    bad = {"empty": b"", "header only": good[:4], "cut in the fields": good[:30], "cut in the string": good[:-2],
           "big-endian encapsulation": b"\x00\x00" + good[2:], "no NUL": good[:-1] + b"x",
           "not UTF-8": good[:-3] + b"\xff\xfe\x00", "string length 0": good[:48] + b"\x00" * 4}
    for name, data in bad.items():
        assert read_heartbeat(data) is None, name


def test_a_heartbeat_says_ok_only_at_level_ok():
    """A beat taken as bytes (lean_cdr.Beat) or as an rclpy Heartbeat reads the same; a level other than OK, or a
    level that is not an integer, is never OK."""
    from types import SimpleNamespace

    from hindrax_msgs.msg import Heartbeat

    from hindrax_common.cdr.lean_cdr import heartbeat_cdr, read_heartbeat
    from hindrax_common.node_support.liveness import heartbeat_ok

    for level, ok in ((Heartbeat.OK, True), (1, False), (Heartbeat.ERROR, False), (3, False), (255, False)):
        data = heartbeat_cdr(1, 1, 0, level, "x")
        assert heartbeat_ok(deserialize_message(data, Heartbeat)) is ok  # rclpy
        assert heartbeat_ok(read_heartbeat(data)) is ok  # struct
    for odd in (None, False, "0", b"", b"\x00", 0.0):
        assert heartbeat_ok(SimpleNamespace(level=odd)) is False


def test_prepare_generates_the_code_when_asked_not_at_the_first_message(monkeypatch):
    """rosbags generates a type's code at its first message (80 ms of CPU here for the first ThrusterPwm); a node
    asks for it while it starts (lean_cdr.prepare), so that no tick of its executor pays it."""
    from hindrax_common.cdr import lean_cdr

    store = lean_cdr._typestore()
    asked = []
    real = store.get_msgdef
    monkeypatch.setattr(store, "get_msgdef", lambda name: (asked.append(name), real(name))[1])
    lean_cdr.prepare(ThrusterPwm, "geometry_msgs/msg/WrenchStamped")
    assert asked == ["hindrax_msgs/msg/ThrusterPwm", "geometry_msgs/msg/WrenchStamped"]
    with pytest.raises(ValueError, match="not a ROS message class"):
        lean_cdr.prepare(42)
