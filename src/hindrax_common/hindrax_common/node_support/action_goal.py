"""Sending an action goal and fetching its result when a request or response can be lost.

Why this module exists: rclpy's :class:`rclpy.action.ActionClient` sends a goal request once and waits on its
response for ever. On Fast DDS (the Jazzy default RMW) a service response is dropped without an error when the
server has not yet matched the client's reply reader (rmw_fastrtps ``__rmw_send_response``: the client is taken
as gone, the call returns OK), which happens shortly after discovery on a loaded machine: ``server_is_ready()``
is true on the client's side, the server accepts the goal and starts the campaign, and the client never learns
so. No maintained library covers this; the ROS 2 answer is to observe the action's status topic, which the server
publishes (transient local) on every goal state change (ROS 2 design, "Actions": ``_action/status``).

:class:`GoalSender` does that:

- the goal is sent with a client-chosen UUID; while neither a response nor the UUID on the status topic has
  arrived, the same request (same UUID) is sent again every ``resend_every_s``. A server that got an earlier copy
  rejects the duplicate UUID (rclpy ``ActionServer._execute_goal_request``) and the status topic tells that the
  goal runs, so a goal is never started twice;
- a goal seen on the status topic without a response is accepted: rclpy's
  :class:`~rclpy.action.client.ClientGoalHandle` is made for it from the action's own ``SendGoal`` response
  type, accepted, stamped with the acceptance time the server published (``GoalInfo.stamp``), exactly what the
  ActionClient makes when the response arrives, so its result and cancel calls work as usual;
- :meth:`GoalSender.cancel` sends the cancel request again until the status topic shows the goal cancelling;
- :meth:`GoalSender.poll_result` requests the result again when the status topic says the goal ended and no
  result came within ``resend_every_s`` (``get_result`` is idempotent).

Times are wall-clock seconds (``time.monotonic``); spinning is the caller's (one executor spin per call of
``spin``), as in :func:`hindrax_common.process.conditions.wait_until`."""
from __future__ import annotations

import sys
import time
import uuid as uuidlib
from typing import Any, Callable

from action_msgs.msg import GoalStatus, GoalStatusArray
from rclpy.action.client import ClientGoalHandle
from rclpy.qos import qos_profile_action_status_default
from unique_identifier_msgs.msg import UUID

__all__ = ["GoalNotAnswered", "GoalSender", "accepted_goal_handle", "send_goal_response_type"]

#: Goal states after which the server publishes no more (action_msgs/GoalStatus, ROS 2 design "Actions").
_ENDED = frozenset({GoalStatus.STATUS_SUCCEEDED, GoalStatus.STATUS_CANCELED, GoalStatus.STATUS_ABORTED})
#: States in which a cancel request needs no resend: the server took it, or the goal is over.
_CANCEL_TAKEN = _ENDED | {GoalStatus.STATUS_CANCELING}


def send_goal_response_type(goal: Any) -> type:
    """The ``SendGoal`` response message class of the action whose ``Goal`` message ``goal`` is.

    rosidl generates the action ``pkg/action/Name`` as the class ``Name`` next to ``Name_Goal`` in one module;
    the response class is ``Name.Impl.SendGoalService.Response`` (what rclpy's ActionClient and ActionServer
    use). Raises ``TypeError`` if ``goal`` is not a generated action goal message."""
    goal_type = type(goal)
    action_name = goal_type.__name__.removesuffix("_Goal")
    action = getattr(sys.modules.get(goal_type.__module__), action_name, None)
    impl = getattr(action, "Impl", None)
    if action_name == goal_type.__name__ or impl is None or getattr(action, "Goal", None) is not goal_type:
        raise TypeError(f"{goal_type.__qualname__} is not the Goal message of a generated ROS 2 action")
    return impl.SendGoalService.Response


def accepted_goal_handle(client: Any, goal_id: Any, goal: Any, stamp: Any) -> ClientGoalHandle:
    """The :class:`~rclpy.action.client.ClientGoalHandle` that ``client`` (an ActionClient)
    would have made from a lost ``SendGoal`` response accepting ``goal`` (its ``Goal`` message)
    under ``goal_id`` (a ``unique_identifier_msgs/UUID``) at ``stamp``
    (``builtin_interfaces/Time``): accepted, so its result and cancel calls work as usual.
    Raises ``TypeError`` as :func:`send_goal_response_type`."""
    response = send_goal_response_type(goal)(accepted=True, stamp=stamp)
    return ClientGoalHandle(client, goal_id, response)


class GoalNotAnswered(RuntimeError):
    """No response and no status for a goal within the caller's timeout."""


class GoalSender:
    """Goals of one :class:`rclpy.action.ActionClient` sent and followed through the action's status topic.

    node: the client's node (a subscription to ``<action_name>/_action/status`` is created on it);
    client: the ActionClient; action_name: the name the client was created with (resolved the same way);
    resend_every_s: how long to wait for a response or a status before sending the request again."""

    def __init__(self, node: Any, client: Any, action_name: str, resend_every_s: float = 2.0) -> None:
        self._node, self._client = node, client
        self.resend_every_s = float(resend_every_s)
        self._status: dict[bytes, int] = {}
        self._accepted_stamp: dict[bytes, Any] = {}  # GoalInfo.stamp: when the server accepted the goal
        self._ended_at: dict[bytes, float] = {}
        self._result_requested_at: dict[bytes, float] = {}
        self._results: dict[bytes, Any] = {}
        self._cancel_requested_at: dict[bytes, float] = {}
        self.resends = 0  # goal requests sent again (for the caller's log)
        self._sub = node.create_subscription(GoalStatusArray, f"{action_name}/_action/status", self._on_status,
                                             qos_profile_action_status_default)

    def _on_status(self, msg: Any) -> None:
        now = time.monotonic()
        for s in msg.status_list:
            key = bytes(s.goal_info.goal_id.uuid)
            self._status[key] = int(s.status)
            self._accepted_stamp.setdefault(key, s.goal_info.stamp)
            if int(s.status) in _ENDED:
                self._ended_at.setdefault(key, now)

    def status(self, handle_or_uuid: Any) -> int | None:
        """Last status code seen on the status topic for a goal (``action_msgs.msg.GoalStatus.STATUS_*``), or None."""
        key = bytes(getattr(handle_or_uuid, "goal_id", handle_or_uuid).uuid)
        return self._status.get(key)

    def send(self, goal: Any, spin: Callable[[], None], timeout_s: float,
             feedback_callback: Callable[[Any], None] | None = None) -> Any:
        """Send ``goal`` and return its ClientGoalHandle once the server answered or the status topic shows it.

        Returns a handle whose ``accepted`` is False when the server rejected the goal. Raises
        :class:`GoalNotAnswered` when neither came within ``timeout_s`` seconds (the request is sent
        ``1 + timeout_s / resend_every_s`` times at most)."""
        send_goal_response_type(goal)  # a TypeError before anything is sent
        goal_id = UUID(uuid=list(uuidlib.uuid4().bytes))
        key = bytes(goal_id.uuid)
        futures = [self._client.send_goal_async(goal, feedback_callback=feedback_callback, goal_uuid=goal_id)]
        t0 = last = time.monotonic()
        while True:
            accepted = [f.result() for f in futures if f.done() and f.result().accepted]
            if accepted:
                return accepted[0]
            if key in self._status:  # running (or already ended) on the server: our goal, response lost
                # the SendGoal response the server sent and we lost: accepted, at the stamp it published
                return accepted_goal_handle(self._client, goal_id, goal, self._accepted_stamp[key])
            now = time.monotonic()
            rejected = [f.result() for f in futures if f.done()]
            if rejected and (len(futures) == 1 or now - last > self.resend_every_s):
                return rejected[0]  # a real rejection: no status for the UUID after a resend either
            if now - t0 > timeout_s:
                raise GoalNotAnswered(f"no answer to the goal within {timeout_s:g} s ({len(futures)} request(s) sent)")
            if not rejected and now - last > self.resend_every_s:
                futures.append(self._client.send_goal_async(goal, feedback_callback=feedback_callback,
                                                            goal_uuid=goal_id))
                self.resends += 1
                last = now
            spin()

    def poll_result(self, handle: Any) -> Any | None:
        """The goal's result response (``.status``, ``.result``) once it arrived, else None.

        Call once per spin. Requests the result on the first call, and again when the status topic has shown the
        goal ended for more than ``resend_every_s`` without a result arriving."""
        key = bytes(handle.goal_id.uuid)
        if key in self._results and self._results[key].done():
            return self._results[key].result()
        now = time.monotonic()
        asked = self._result_requested_at.get(key)
        ended = self._ended_at.get(key)
        if asked is None or (ended is not None and now - max(asked, ended) > self.resend_every_s):
            self._results[key] = handle.get_result_async()
            self._result_requested_at[key] = now
        return None

    def cancel(self, handle: Any) -> bool:
        """Request the goal's cancellation; call once per spin while waiting for its end. The request is sent
        again every ``resend_every_s`` until the status topic shows the goal cancelling or ended; returns True
        from then on."""
        key = bytes(handle.goal_id.uuid)
        if self._status.get(key) in _CANCEL_TAKEN:
            return True
        now = time.monotonic()
        if now - self._cancel_requested_at.get(key, -float("inf")) > self.resend_every_s:
            handle.cancel_goal_async()
            self._cancel_requested_at[key] = now
        return False

    def destroy(self) -> None:
        """Remove the status subscription from the node."""
        self._node.destroy_subscription(self._sub)
