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
