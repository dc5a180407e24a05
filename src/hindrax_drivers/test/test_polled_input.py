"""Polled subscriptions (hindrax_drivers.polled_input): messages are taken in order with their DDS times, no
executor dispatches them, and the intake node keeps its own name under the process's ``__node`` remap."""
from __future__ import annotations

import time

import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from std_msgs.msg import String

from hindrax_drivers.polled_input import PolledSubscriptions
from hindrax_drivers.testing import wait_until

pytestmark = pytest.mark.ros


def test_take_returns_queued_messages_in_order_with_their_times_and_nothing_dispatches_them():
    from rclpy.context import Context

    ctx = Context()
    rclpy.init(args=["--ros-args", "-r", "__node:=renamed"], context=ctx)  # domain: conftest's ROS_DOMAIN_ID
    try:
        owner = rclpy.create_node("owner", context=ctx)
        assert owner.get_name() == "renamed"  # the process-wide remap applies to ordinary nodes
        intake = PolledSubscriptions(owner)
        assert intake.node.get_name() == "renamed_intake"  # not renamed to "renamed" as well
        talker = rclpy.create_node("talker", context=ctx, use_global_arguments=False)
        pub = talker.create_publisher(String, "/polled/x", 10)
        sub = intake.subscribe(String, "/polled/x", 50)
        raw = intake.subscribe(String, "/polled/x", 50, raw=True)
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(owner)  # spinning the owner must not take the intake's messages (its callback raises)
        ex.add_node(talker)
        spin = lambda: ex.spin_once(timeout_sec=0.01)  # noqa: E731
        wait_until(lambda: pub.get_subscription_count() == 2, 10, spin, "intake matched")
        t0 = time.time_ns()
        for i in range(5):
            pub.publish(String(data=f"m{i}"))
        got: list = []
        wait_until(lambda: got.extend(PolledSubscriptions.take(sub)) or len(got) == 5, 10, spin, "5 messages taken")
        assert [m.data for m, _ in got] == [f"m{i}" for i in range(5)]
        for _, info in got:  # DDS times on the system clock, source before reception
            assert t0 <= info["source_timestamp"] <= info["received_timestamp"] <= time.time_ns()
        raw_got = list(PolledSubscriptions.take(raw))
        assert len(raw_got) == 5 and all(isinstance(d, bytes) for d, _ in raw_got)
        assert list(PolledSubscriptions.take(sub)) == []  # taken once
        intake.destroy(raw)
        intake.close()
        ex.shutdown()
        owner.destroy_node()
        talker.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)


def test_a_lean_input_hands_over_the_fields_of_the_message_decoded_from_its_cdr():
    """``lean``: the handler gets rosbags' decoding of the CDR bytes, whose fields are those rclpy's own deserialiser
    reads from the same bytes (the reference), not an rclpy message."""
    import numpy as np
    from rclpy.serialization import deserialize_message, serialize_message
    from sensor_msgs.msg import Imu

    from hindrax_drivers.polled_input import PolledInputs
    from hindrax_drivers.testing import ros_context
    from hindrax_msgs.msg import Dvl, ThrusterPwm

    imu = Imu()
    imu.header.stamp.sec, imu.header.stamp.nanosec, imu.header.frame_id = 12, 345, "imu_link"
    imu.orientation.x, imu.angular_velocity.y, imu.linear_acceleration.z = 0.5, -0.25, 9.81
    imu.linear_acceleration_covariance[4] = 0.02
    dvl = Dvl(velocity_valid=True, beam_range_m=[1.0, 2.0, 3.0, 4.5], beam_lock=[True, False, True, True])
    dvl.velocity_m_s.x, dvl.delta_time_s = 0.31, 0.1
    pwm = ThrusterPwm(pulse_width_us=[1500.0 + i for i in range(8)], armed=True, output_state=2)
    with ros_context() as ctx:
        owner = rclpy.create_node("lean_owner", context=ctx)
        talker = rclpy.create_node("lean_talker", context=ctx)
        inputs = PolledInputs(owner)
        got: dict = {}
        pubs = []
        for msg in (imu, dvl, pwm):
            topic = f"/lean/{type(msg).__name__}"
            inputs.add(type(msg), topic, lambda m, k=type(msg): got.setdefault(k, m), 10, lean=True)
            pubs.append((talker.create_publisher(type(msg), topic, 10), msg))
        wait_until(lambda: all(p.get_subscription_count() == 1 for p, _ in pubs), 10, lambda: time.sleep(0.01),
                   "lean inputs matched")
        for p, msg in pubs:
            p.publish(msg)
        wait_until(lambda: inputs.take_all() >= 0 and len(got) == 3, 10, lambda: time.sleep(0.01), "taken")
        inputs.close()
        owner.destroy_node()
        talker.destroy_node()
    for msg in (imu, dvl, pwm):
        lean = got[type(msg)]
        assert not isinstance(lean, type(msg))
        ref = deserialize_message(serialize_message(msg), type(msg))
        for field in msg.get_fields_and_field_types():
            want, have = getattr(ref, field), getattr(lean, field)
            if hasattr(want, "get_fields_and_field_types"):
                for sub in want.get_fields_and_field_types():
                    w, h = getattr(want, sub), getattr(have, sub)
                    if hasattr(w, "get_fields_and_field_types"):  # header.stamp
                        assert (w.sec, w.nanosec) == (h.sec, h.nanosec)
                    else:
                        assert w == h, (field, sub)
            else:
                assert np.array_equal(np.asarray(want), np.asarray(have)), field


def test_the_mixin_opens_takes_after_its_hooks_and_closes_with_the_node():
    """PolledInputsMixin: on the system clock the inputs are polled (kept in the attribute named), each take runs the
    before-take hooks first, and destroy_node closes the intake node and sets the attribute to None; with
    use_sim_time there are no polled inputs, the hooks still run and a take hands over nothing."""
    from rclpy.node import Node
    from rclpy.parameter import Parameter

    from hindrax_drivers.polled_input import PolledInputs, PolledInputsMixin, subscribe_input
    from hindrax_drivers.testing import ros_context

    class Taker(PolledInputsMixin, Node):
        def __init__(self, name: str, log: list, **kwargs) -> None:
            super().__init__(name, **kwargs)
            self.intake = self.open_inputs("intake", before_take=(lambda: log.append("hook"),))
            subscribe_input(self, self.intake, String, "/polled/mixin", lambda m: log.append(m.data), 10)

    with ros_context() as ctx:
        log: list = []
        node = Taker("taker", log, context=ctx)
        talker = rclpy.create_node("talker", context=ctx)
        try:
            topics = lambda n: {sub.topic_name for sub in n.subscriptions}  # noqa: E731
            assert isinstance(node.intake, PolledInputs) and "/polled/mixin" not in topics(node)  # on the intake
            pub = talker.create_publisher(String, "/polled/mixin", 10)
            wait_until(lambda: pub.get_subscription_count() == 1, 10, message="intake matched")
            pub.publish(String(data="m0"))
            wait_until(lambda: node.take_inputs() == 1, 10, message="m0 taken")
            assert log[-2:] == ["hook", "m0"] and set(log[:-1]) == {"hook"}
            inputs = node.intake
            node.destroy_node()
            assert node.intake is None and inputs.handlers == {}  # closed
            wait_until(lambda: pub.get_subscription_count() == 0, 10, message="the intake node's subscription gone")
        finally:
            talker.destroy_node()
        sim_log: list = []
        sim = Taker("sim_taker", sim_log, context=ctx, parameter_overrides=[Parameter("use_sim_time", value=True)])
        assert sim.intake is None and "/polled/mixin" in topics(sim)  # a callback subscription on the node itself
        assert sim.take_inputs() == 0 and sim_log == ["hook"]
        sim.destroy_node()
