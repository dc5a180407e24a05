"""Recorder node in its own process: services, QoS matching, late topics, selection, bag content.

The recorder (python -m hindrax_bringup.recording.recorder_node) is started idle; this test drives it through
recorder/start and recorder/stop, publishes from its own process and checks the finished bag with rosbags.
"""
from __future__ import annotations

import subprocess
import time

import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, QoSProfile, qos_profile_sensor_data
from sensor_msgs.msg import Imu
from std_msgs.msg import String

from hindrax_common.process.conditions import ConditionTimeout
from hindrax_bringup.recording.metadata import read_metadata
from hindrax_common.testing import child_env, python_executable, ros_context, wait_until
from hindrax_msgs.msg import RawDeviceData
from hindrax_msgs.srv import StartRecording, StopRecording

pytestmark = pytest.mark.ros


@pytest.fixture
def recorder():
    proc = subprocess.Popen(
        [python_executable(), "-m", "hindrax_bringup.recording.recorder_node", "--ros-args",
         "-p", "discovery_period_s:=0.2", "-p", "status_period_s:=0.2"],
        env=child_env(), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        with ros_context() as ctx:
            node = rclpy.create_node("recorder_test", context=ctx)
            ex = SingleThreadedExecutor(context=ctx)
            ex.add_node(node)
            counts: dict[str, int] = {}

            def on_diag(msg: DiagnosticArray) -> None:
                for st in msg.status:
                    if st.name.startswith("recorder"):
                        counts.clear()
                        counts.update({kv.key[6:]: int(kv.value) for kv in st.values if kv.key.startswith("topic:")})

            node.create_subscription(DiagnosticArray, "/diagnostics", on_diag, 10)
            start = node.create_client(StartRecording, "recorder/start")
            stop = node.create_client(StopRecording, "recorder/stop")
            spin = lambda: ex.spin_once(timeout_sec=0.02)  # noqa: E731

            def call(client, request):
                fut = client.call_async(request)
                wait_until(fut.done, 30, spin, "service answer")
                return fut.result()

            wait_until(lambda: (start.service_is_ready() and stop.service_is_ready()) or proc.poll() is not None,
                       20, spin, "recorder services")
            assert proc.poll() is None, proc.stderr.read().decode()
            # Handshake: service_is_ready() can turn true before the server has matched this client's response
            # reader, and a response sent then is lost (DDS discovery race). A stop with nothing recording has no
            # side effect, so repeat it until one is answered; after that the response paths are matched.
            answered = []

            def handshake():
                fut = stop.call_async(StopRecording.Request())
                try:
                    wait_until(fut.done, 3, spin, "handshake")
                    answered.append(fut.result())
                except AssertionError:
                    pass
            wait_until(lambda: answered, 40, handshake, "recorder answering its services")
            assert not answered[0].success  # nothing was being recorded
            yield dict(node=node, spin=spin, call=call, start=start, stop=stop, counts=counts, proc=proc)
            ex.shutdown()
            node.destroy_node()
    finally:
        proc.terminate()
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(10)


def test_services_qos_matching_late_topics_and_selection(recorder, tmp_path):
    from rosbags.highlevel import AnyReader

    r = recorder
    node, spin, call, counts = r["node"], r["spin"], r["call"], r["counts"]
    imu = node.create_publisher(Imu, "/n/imu", qos_profile_sensor_data)  # best effort
    latched = node.create_publisher(String, "/n/latched",
                                    QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL))
    raw = node.create_publisher(RawDeviceData, "/n/raw", 100)
    other = node.create_publisher(String, "/other/x", 10)
    latched.publish(String(data="published before the recording started"))

    bag1 = tmp_path / "bag1"
    t_start_ns = time.time_ns()
    res = call(r["start"], StartRecording.Request(output_dir=str(bag1),
                                                  topics=["/n/imu", "/n/latched", "/n/raw", "/n/late"]))
    assert res.success and res.bag_path == str(bag1), res.message
    again = call(r["start"], StartRecording.Request(output_dir=str(tmp_path / "other")))
    assert not again.success and "already recording" in again.message

    wait_until(lambda: imu.get_subscription_count() and raw.get_subscription_count()
               and latched.get_subscription_count(), 15, spin, "recorder subscribed")
    # Best effort (the recorder's readers of volatile topics, recorder_policies): a sample sent before the recorder's
    # reader has matched this writer is lost, and the writer's subscription count above is only its own side of the
    # match (Fast-DDS issues 2641, 3009). So a warm-up sample goes first on each topic, again every 2 s until the
    # recorder counts it, and the samples counted follow a reader known to be there.
    def warm_up(pub, msg, topic: str) -> int:
        def counted() -> bool:
            pub.publish(msg)
            try:
                wait_until(lambda: counts.get(topic, 0) > 0, 2, spin, f"the warm-up sample of {topic} counted")
            except ConditionTimeout:
                return False
            return True
        wait_until(counted, 30, None, f"the recorder receiving {topic}")
        return counts[topic]

    def imu_sample(x: float) -> Imu:
        m = Imu()
        m.linear_acceleration.x = x
        return m

    warm = warm_up(imu, imu_sample(-1.0), "/n/imu")
    warm_raw = warm_up(raw, RawDeviceData(device_name="warm-up"), "/n/raw")
    for i in range(50):
        imu.publish(imu_sample(float(i)))
        raw.publish(RawDeviceData(device_name="ms5837", data=bytes([i, 255 - i])))
        other.publish(String(data="not selected"))
    late = node.create_publisher(String, "/n/late", 10)  # appears after the start: found by the graph poll
    wait_until(lambda: late.get_subscription_count() > 0, 15, spin, "late topic subscribed")
    warm_late = warm_up(late, String(data="warm-up"), "/n/late")
    for i in range(10):
        late.publish(String(data=f"late {i}"))
    expected = {"/n/imu": warm + 50, "/n/raw": warm_raw + 50, "/n/latched": 1, "/n/late": warm_late + 10}
    wait_until(lambda: all(counts.get(t) == n for t, n in expected.items()), 15, spin,
               f"recorder counts {expected}")
    res = call(r["stop"], StopRecording.Request())
    t_stop_ns = time.time_ns()
    total = sum(expected.values())
    assert res.success and res.message_count == total and res.bag_path == str(bag1)

    meta = read_metadata(bag1)
    assert {t.name: t.message_count for t in meta.topics} == expected  # /other/x not selected
    qos = {t.name: t.offered_qos_profiles[0] for t in meta.topics}
    assert qos["/n/imu"]["reliability"] == "best_effort"  # the publisher's own QoS, as the graph reported it
    assert qos["/n/latched"]["durability"] == "transient_local"
    assert qos["/n/raw"]["reliability"] == "reliable"
    with AnyReader([bag1]) as reader:
        by_topic: dict[str, list] = {}
        for c, _, data in reader.messages():
            by_topic.setdefault(c.topic, []).append(reader.deserialize(data, c.msgtype))
    assert [m.linear_acceleration.x for m in by_topic["/n/imu"]] == [-1.0] * warm + [float(i) for i in range(50)]
    assert [bytes(m.data) for m in by_topic["/n/raw"]] == [b""] * warm_raw + [bytes([i, 255 - i])
                                                                              for i in range(50)]
    assert by_topic["/n/latched"][0].data == "published before the recording started"
    # log time = publish time = the node's clock (the system clock here) in the callback, within the recording's
    # span (recorder_node docstring)
    from mcap.reader import make_reader

    with open(next(bag1.glob("*.mcap")), "rb") as f:
        times = {(c.topic, m.log_time, m.publish_time) for _, c, m in make_reader(f).iter_messages()}
    assert len(times) == total and all(pub == log for _, log, pub in times)
    assert all(t_start_ns <= log <= t_stop_ns for _, log, _ in times)

    # a second recording selected by regular expression; stopping twice is reported, not fatal
    bag2 = tmp_path / "bag2"
    res = call(r["start"], StartRecording.Request(output_dir=str(bag2), topic_regex="^/other/"))
    assert res.success, res.message
    wait_until(lambda: "/other/x" in counts, 15, spin, "regex topic subscribed")
    warm_other = warm_up(other, String(data="warm-up"), "/other/x")
    for _ in range(5):
        other.publish(String(data="now selected"))
    wait_until(lambda: counts.get("/other/x") == warm_other + 5, 15, spin, "5 messages on /other/x")
    assert call(r["stop"], StopRecording.Request()).message_count == warm_other + 5
    assert not call(r["stop"], StopRecording.Request()).success
    assert [t.name for t in read_metadata(bag2).topics] == ["/other/x"]
    bad = call(r["start"], StartRecording.Request(output_dir=str(tmp_path / "bag3"), topic_regex="("))
    assert not bad.success and "regular expression" in bad.message
