"""The recorder counts samples lost in transit (gaps in publication sequence numbers) and reports them.

A publisher and the recorder node in one context, spun by rclpy's EventsExecutor (the executor of the recorder's
process, which hands the callback the message info as one tuple: ``ros_process.WithMessageInfo``).
"""
from __future__ import annotations

import types

import pytest
from rclpy.experimental.events_executor import EventsExecutor
from rclpy.parameter import Parameter
from std_msgs.msg import String

from hindrax_common.process.conditions import ConditionTimeout
from hindrax_bringup.recording.reader import BagReader
from hindrax_bringup.recording.recorder_node import RecorderNode
from hindrax_common.testing import ros_context, wait_until

pytestmark = pytest.mark.ros

TOPIC = "/loss_test"
N = 200


def values(node: RecorderNode) -> dict[str, str]:
    return {kv.key: kv.value for kv in node.status().values}


@pytest.fixture()
def rig(tmp_path):
    with ros_context() as ctx:
        node = RecorderNode(context=ctx, parameter_overrides=[Parameter("topics", value=[TOPIC])])
        pub = node.create_publisher(String, TOPIC, 10)
        ex = EventsExecutor(context=ctx)
        ex.add_node(node)
        lines: list[str] = []
        sent = []

        def send(text: str) -> None:
            pub.publish(String(data=text))
            sent.append(text)
        node._log = lambda text, warning=False: lines.append(text)  # noqa: SLF001 - the close line
        try:
            yield types.SimpleNamespace(node=node, pub=pub, spin=lambda: ex.spin_once(timeout_sec=0.02),
                                        out=tmp_path / "bag", lines=lines, send=send, sent=sent)
        finally:
            node.shutdown()
            ex.shutdown()
            node.destroy_node()


def record_n(rig) -> int:
    """Start, receive a warm-up sample, publish N more; returns the count before the N. Best effort: a sample sent
    before the writer has matched the recorder's reader is never delivered, so a warm-up goes again every 2 s until
    one is recorded (the first received is the baseline), and the N follow a writer known to be matched."""
    node = rig.node
    node.start_recording(str(rig.out))
    wait_until(lambda: node.subscribed_to([TOPIC]), 10, rig.spin, "recorder subscribed")

    def counted() -> bool:
        rig.send("warm-up")
        try:
            wait_until(lambda: int(values(node).get(f"topic:{TOPIC}", "0")) > 0, 2, rig.spin, "warm-up recorded")
        except ConditionTimeout:
            return False
        return True
    wait_until(counted, 30, None, "the recorder receiving the warm-up")
    before = int(values(node)[f"topic:{TOPIC}"])
    for i in range(N):
        rig.send(f"m{i}")
    wait_until(lambda: int(values(node)[f"topic:{TOPIC}"]) == before + N, 20, rig.spin, "N samples recorded")
    return before


def test_all_received_reports_zero_lost(rig):
    before = record_n(rig)
    v = values(rig.node)
    assert v["messages_lost"] == "0" and f"lost:{TOPIC}" not in v
    assert rig.node.status().level == rig.node.status().OK
    rig.node.stop_recording()
    assert sum(1 for _ in BagReader(rig.out).messages()) == before + N
    assert rig.lines[-1].endswith(", 0 dropped, 0 lost in transit"), rig.lines[-1]


def test_a_gap_is_reported(rig):
    record_n(rig)
    node = rig.node
    sub = node._subs[TOPIC]  # noqa: SLF001 - its callback, fed a sequence number that skips 4
    last = len(rig.sent)  # the writer numbers its samples 1, 2, ...: the last one published
    info = {"publication_sequence_number": last + 5, "source_timestamp": 0, "received_timestamp": 0,
            "reception_sequence_number": None}
    sub.callback((b"", info))  # the EventsExecutor's form: one (msg, info) tuple
    v = values(node)
    assert v["messages_lost"] == "4" and v[f"lost:{TOPIC}"] == "4"
    assert node.status().level == node.status().WARN
    node.stop_recording()
    assert rig.lines[-1].endswith(", 0 dropped, 4 lost in transit"), rig.lines[-1]
