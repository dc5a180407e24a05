"""A bag recorded before a message type changed is read by one rule (BagReader.installed_messages): records of the
installed layout through rclpy's deserializer, older ones from the bag's stored definition, copied into the
installed class with the new fields at their defaults. The replay's recorded_parsed uses that rule."""
from __future__ import annotations

from pathlib import Path

from mcap_ros2.writer import Writer
from hindrax_common.cdr import msgdefs
from hindrax_bringup.recording.msgtypes import from_decoded
from hindrax_bringup.recording.reader import BagReader
from hindrax_test_support.replay_devices import recorded_parsed
from hindrax_msgs.msg import ThrusterPwm
from tf2_msgs.msg import TFMessage

PWM = "hindrax_msgs/msg/ThrusterPwm"
WIDTHS = [1500.0, 1560.0, 1440.0, 1500.0, 1610.0, 1500.0, 1390.0, 1500.0]


def _write(path: Path, definition: str, messages: list[dict]) -> Path:
    with open(path, "wb") as fh:
        writer = Writer(fh)
        schema = writer.register_msgdef(PWM, definition)
        for i, msg in enumerate(messages):
            writer.write_message("/thrusters/pulse_width", schema, msg, log_time=(i + 1) * 20_000_000,
                                 publish_time=(i + 1) * 20_000_000)
        writer.finish()
    return path


def _pwm(i: int, **extra) -> dict:
    return {"header": {"stamp": {"sec": 1, "nanosec": i * 20_000_000}, "frame_id": "base_link"},
            "pulse_width_us": WIDTHS, "armed": bool(i % 2), **extra}


def test_a_bag_from_before_output_state_reads_into_the_installed_class(tmp_path):
    now = msgdefs.message_definition(PWM)
    before = "\n".join(line for line in now.split("\n") if not line.startswith("uint8 "))
    assert not msgdefs.matches_installed(PWM, before)
    bag = _write(tmp_path / "old.mcap", before, [_pwm(i) for i in range(3)])
    msgs = recorded_parsed(bag)["/thrusters/pulse_width"]
    assert len(msgs) == 3 and all(isinstance(m, ThrusterPwm) for m in msgs)
    assert [list(m.pulse_width_us) for m in msgs] == [WIDTHS] * 3
    assert [m.armed for m in msgs] == [False, True, False]
    assert [m.header.stamp.nanosec for m in msgs] == [0, 20_000_000, 40_000_000]
    assert {m.output_state for m in msgs} == {ThrusterPwm.OUTPUT_UNKNOWN}  # not recorded then: unknown


def test_a_bag_of_the_installed_layout_keeps_every_field(tmp_path):
    bag = _write(tmp_path / "new.mcap", msgdefs.message_definition(PWM),
                 [_pwm(i, output_state=ThrusterPwm.OUTPUT_NEUTRAL) for i in range(2)])
    reader = BagReader(bag)
    assert reader.installed_class("/thrusters/pulse_width") is ThrusterPwm
    msgs = [m for _raw, m in reader.installed_messages(["/thrusters/pulse_width"])]
    assert [m.output_state for m in msgs] == [ThrusterPwm.OUTPUT_NEUTRAL] * 2
    assert [list(m.pulse_width_us) for m in msgs] == [WIDTHS] * 2


def test_from_decoded_converts_nested_sequences_of_messages():
    class Obj:
        def __init__(self, **kw):
            self.__dict__.update(kw)

    stamp = Obj(sec=3, nanosec=7)
    tr = Obj(header=Obj(stamp=stamp, frame_id="base_link"), child_frame_id="dvl_link",
             transform=Obj(translation=Obj(x=0.1, y=0.0, z=-0.2), rotation=Obj(x=0.0, y=0.0, z=0.0, w=1.0)))
    msg = from_decoded(TFMessage, Obj(transforms=[tr, tr]))
    assert isinstance(msg, TFMessage) and len(msg.transforms) == 2
    assert msg.transforms[1].child_frame_id == "dvl_link" and msg.transforms[0].transform.translation.z == -0.2
    assert msg.transforms[0].header.stamp.sec == 3
