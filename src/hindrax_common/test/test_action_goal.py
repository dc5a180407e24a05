"""GoalSender: a goal whose request, response or result response is lost still runs once and returns its result.

The losses are made on the client's side: the first call of the ActionClient (or goal handle) method returns a
future that never completes (the real request is sent or not), as when the response is dropped by the RMW.
"""
from __future__ import annotations

import pytest
import rclpy
from action_msgs.msg import GoalStatus
from rclpy.action import ActionClient, ActionServer, CancelResponse, GoalResponse
from rclpy.action.client import ClientGoalHandle
from rclpy.executors import SingleThreadedExecutor
from rclpy.task import Future
from rclpy.time import Time

from hindrax_common.node_support.action_goal import GoalNotAnswered, GoalSender, send_goal_response_type
from hindrax_common.testing import ros_context, wait_until
from hindrax_msgs.action import RunIdentification


class _Server:
    """A run_identification server that accepts goals naming a DOF, counts accepted goals, ends them on demand."""

    def __init__(self, node) -> None:
        self.accepted = 0
        self.server = ActionServer(node, RunIdentification, "run_identification", self._execute,
                                   goal_callback=self._goal)

    def _goal(self, goal) -> GoalResponse:
        return GoalResponse.ACCEPT if goal.dofs else GoalResponse.REJECT

    def _execute(self, handle):
        self.accepted += 1
        handle.succeed()
        return RunIdentification.Result(success=True, message=f"done {handle.request.dofs[0]}")


@pytest.fixture
def graph():
    with ros_context() as ctx:
        server_node = rclpy.create_node("fake_identification", context=ctx)
        client_node = rclpy.create_node("goal_client", context=ctx)
        ex = SingleThreadedExecutor(context=ctx)
        for n in (server_node, client_node):
            ex.add_node(n)
        server = _Server(server_node)
        client = ActionClient(client_node, RunIdentification, "run_identification")
        spin = lambda: ex.spin_once(timeout_sec=0.01)  # noqa: E731
        wait_until(client.server_is_ready, 20, spin, "action server discovered")
        try:
            yield client_node, client, server, spin
        finally:
            client.destroy()
            server.server.destroy()
            ex.shutdown()
            server_node.destroy_node()
            client_node.destroy_node()


def _lose_first(obj, name: str, send: bool) -> list:
    """Make the first call of ``obj.name`` return a never-completing future (after sending if ``send``)."""
    real = getattr(obj, name)
    calls = []

    def wrapper(*args, **kwargs):
        calls.append(1)
        if len(calls) == 1:
            if send:
                real(*args, **kwargs)
            return Future()
        return real(*args, **kwargs)

    setattr(obj, name, wrapper)
    return calls


def _run(sender, spin, dofs=("surge",)):
    handle = sender.send(RunIdentification.Goal(dofs=list(dofs)), spin, timeout_s=20)
    if not handle.accepted:
        return handle, None
    return handle, wait_until(lambda: sender.poll_result(handle), 20, spin, "result")


def test_lost_goal_response_is_recovered_from_the_status_topic_and_the_goal_runs_once(graph):
    node, client, server, spin = graph
    calls = _lose_first(client, "send_goal_async", send=True)
    sender = GoalSender(node, client, "run_identification", resend_every_s=0.5)
    before = node.get_clock().now()
    handle, result = _run(sender, spin)
    assert handle.accepted
    # the recovered handle is rclpy's own, stamped with the acceptance time the server published
    assert isinstance(handle, ClientGoalHandle)
    assert Time.from_msg(handle.stamp) >= before
    assert result.result.success and result.result.message == "done surge"
    assert server.accepted == 1  # a resend (if any) carried the same UUID and was refused as a duplicate
    assert len(calls) >= 1


def test_lost_goal_request_is_sent_again_with_the_same_uuid(graph):
    node, client, server, spin = graph
    calls = _lose_first(client, "send_goal_async", send=False)
    # 1.5 s: the resent request's answer must come within one period on a loaded machine,
    # else a third is sent
    sender = GoalSender(node, client, "run_identification", resend_every_s=1.5)
    handle, result = _run(sender, spin, ("heave",))
    assert handle.accepted and result.result.message == "done heave"
    assert len(calls) == 2 and sender.resends == 1 and server.accepted == 1


def test_lost_result_response_is_requested_again_after_the_goal_ended(graph, monkeypatch):
    node, client, server, spin = graph
    real = ClientGoalHandle.get_result_async
    calls = []

    def lossy(self):
        calls.append(1)
        if len(calls) == 1:
            real(self)
            return Future()
        return real(self)

    monkeypatch.setattr(ClientGoalHandle, "get_result_async", lossy)
    sender = GoalSender(node, client, "run_identification", resend_every_s=0.3)
    handle, result = _run(sender, spin, ("yaw",))
    assert result.result.message == "done yaw" and len(calls) >= 2


def test_a_rejected_goal_is_reported_as_rejected(graph):
    node, client, server, spin = graph
    # 5 s: a rejection slower than the resend period is taken as lost and sent again
    # (CI once took > 0.3 s)
    sender = GoalSender(node, client, "run_identification", resend_every_s=5.0)
    handle, result = _run(sender, spin, ())
    assert not handle.accepted and result is None and server.accepted == 0 and sender.resends == 0


def test_no_server_raises_goal_not_answered():
    with ros_context() as ctx:
        node = rclpy.create_node("lonely_client", context=ctx)
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(node)
        client = ActionClient(node, RunIdentification, "run_identification_nobody")
        sender = GoalSender(node, client, "run_identification_nobody", resend_every_s=0.2)
        try:
            with pytest.raises(GoalNotAnswered, match="no answer to the goal within 1 s"):
                sender.send(RunIdentification.Goal(dofs=["surge"]), lambda: ex.spin_once(timeout_sec=0.01), 1.0)
            assert sender.resends >= 3
        finally:
            sender.destroy()
            client.destroy()
            ex.shutdown()
            node.destroy_node()


def test_lost_cancel_request_is_sent_again_until_the_goal_is_cancelling():
    with ros_context() as ctx:
        server_node = rclpy.create_node("slow_identification", context=ctx)
        client_node = rclpy.create_node("cancel_client", context=ctx)
        ex = SingleThreadedExecutor(context=ctx)
        for n in (server_node, client_node):
            ex.add_node(n)
        cancels: list = []
        cancel_seen = Future()

        def on_cancel(_request) -> CancelResponse:
            cancels.append(1)
            if not cancel_seen.done():
                cancel_seen.set_result(True)
            return CancelResponse.ACCEPT

        async def run_until_cancelled(handle):
            await cancel_seen  # the goal runs until a cancel request reaches the server
            handle.canceled()
            return RunIdentification.Result(success=False, message="cancelled")

        server = ActionServer(server_node, RunIdentification, "run_identification", run_until_cancelled,
                              cancel_callback=on_cancel)
        client = ActionClient(client_node, RunIdentification, "run_identification")
        spin = lambda: ex.spin_once(timeout_sec=0.01)  # noqa: E731
        try:
            wait_until(client.server_is_ready, 20, spin, "action server discovered")
            # 1.5 s: the status showing the resent cancel must come within one period,
            # else a third is sent
            sender = GoalSender(client_node, client, "run_identification", resend_every_s=1.5)
            handle = sender.send(RunIdentification.Goal(dofs=["sway"]), spin, 20)
            assert handle.accepted
            calls = _lose_first(handle, "cancel_goal_async", send=False)
            result = wait_until(lambda: (sender.cancel(handle), sender.poll_result(handle))[1], 20, spin, "end")
            assert result.status == GoalStatus.STATUS_CANCELED and result.result.message == "cancelled"
            assert len(calls) == 2 and len(cancels) == 1
        finally:
            client.destroy()
            server.destroy()
            ex.shutdown()
            server_node.destroy_node()
            client_node.destroy_node()


def test_send_goal_response_type_is_the_actions_own_and_other_messages_are_refused():
    assert send_goal_response_type(RunIdentification.Goal()) is RunIdentification.Impl.SendGoalService.Response
    with pytest.raises(TypeError, match="not the Goal message"):
        send_goal_response_type(RunIdentification.Result())
    with pytest.raises(TypeError, match="not the Goal message"):
        send_goal_response_type(GoalStatus())
