"""hindrax_msgs across processes: the installed interfaces carry data between two rclpy processes.

Nothing is built here: the test imports the hindrax_msgs installed into the venv by `make setup`.
"""
import math
import signal
import subprocess
from pathlib import Path

import pytest
import rclpy
from rclpy.action import ActionClient
from rclpy.executors import SingleThreadedExecutor

from hindrax_common.testing import child_env, python_executable, ros_context, wait_until
from hindrax_msgs.action import RunIdentification
from hindrax_msgs.msg import Dvl, RawDeviceData
from hindrax_msgs.srv import SetArmed

pytestmark = pytest.mark.ros
PEER = Path(__file__).parent / "peers" / "interface_peer.py"


@pytest.fixture
def peer():
    proc = subprocess.Popen([python_executable(), str(PEER)], env=child_env(), stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    yield proc
    proc.send_signal(signal.SIGINT)
    try:
        proc.wait(timeout=10)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


def test_message_service_and_action_round_trip(peer):
    with ros_context() as ctx:
        node = rclpy.create_node("interface_test", context=ctx)
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(node)
        spin = lambda: ex.spin_once(timeout_sec=0.05)  # noqa: E731
        received: list[Dvl] = []
        node.create_subscription(Dvl, "/peer/dvl", received.append, 10)
        wait_until(lambda: len(received) >= 3, 20.0, spin, "three Dvl messages from the peer process")
        m = received[-1]
        assert m.header.frame_id == "base_link"
        assert (m.velocity_m_s.x, m.velocity_m_s.y) == (0.25, -0.125)
        assert m.velocity_valid and m.bottom_lock
        assert m.confidence_percent == 87.5
        assert list(m.beam_lock) == [True, True, False, True]
        assert math.isnan(m.beam_velocity_m_s[2]) and m.beam_range_m[3] == pytest.approx(1.3)
        assert received[-1].velocity_m_s.z > received[0].velocity_m_s.z  # a live stream, not a latched copy

        client = node.create_client(SetArmed, "/peer/set_armed")
        assert client.wait_for_service(timeout_sec=10.0)
        # arming the peer is idempotent: repeat until answered (a response sent before the server matched this
        # client's response reader is lost: DDS discovery race right after wait_for_service)
        answers = []

        def call():
            fut = client.call_async(SetArmed.Request(arm=True))
            try:
                wait_until(fut.done, 3.0, spin, "SetArmed response")
                answers.append(fut.result())
            except AssertionError:
                pass
        wait_until(lambda: answers, 30.0, call, "SetArmed answered")
        assert answers[0].success and answers[0].armed
        assert answers[0].message == "peer armed"

        action = ActionClient(node, RunIdentification, "/peer/run_identification")
        assert action.wait_for_server(timeout_sec=10.0)
        feedback = []
        goal = RunIdentification.Goal(dofs=["surge", "heave"], levels_per_dof=4)
        send = action.send_goal_async(goal, feedback_callback=lambda f: feedback.append(f.feedback))
        wait_until(send.done, 10.0, spin, "goal acceptance")
        handle = send.result()
        assert handle.accepted
        # Feedback travels on its own topic, and rclpy's ActionClient drops the feedback of a goal whose result it
        # has already received: take both feedback messages before asking for the result.
        wait_until(lambda: len(feedback) >= 2, 10, spin, "both feedback messages")
        result_future = handle.get_result_async()
        wait_until(result_future.done, 10.0, spin, "action result")
        result = result_future.result().result
        assert result.success
        assert [e.dof for e in result.estimates] == ["surge", "heave"]
        assert list(result.estimates[1].values) == [27.3, 66.5]
        assert list(result.estimates[0].parameter_units) == ["kg", "kg/m"]
        assert result.estimates[0].sample_count == 1234
        assert [f.dof for f in feedback] == ["surge", "heave"]
        assert feedback[-1].progress == pytest.approx(1.0)
        action.destroy()
        ex.shutdown()
        node.destroy_node()


def test_constants_and_raw_device_data_fields():
    assert (Dvl.BEAM_A_PORT, Dvl.BEAM_B_STERN, Dvl.BEAM_C_STARBOARD, Dvl.BEAM_D_BOW) == (0, 1, 2, 3)
    raw = RawDeviceData(device_name="ms5837", transport=RawDeviceData.TRANSPORT_I2C,
                        direction=RawDeviceData.DIRECTION_DEVICE_TO_HOST, i2c_address=0x76, i2c_register=0x00,
                        data=[0x12, 0x34, 0x56])
    assert bytes(raw.data) == b"\x12\x34\x56"
    assert raw.i2c_register == 0
    from rclpy.serialization import deserialize_message, serialize_message

    back = deserialize_message(serialize_message(raw), RawDeviceData)
    assert back == raw  # CDR round trip: what the recorder stores is what replay gets back
