"""The gateway: the vehicle's only door to the topside domain, as two processes (docs/architecture.md §8.2).

* This process (``gateway_node``) is the topside side: the only participant on ``topside_domain_id`` with
  ``topside_discovery_range`` (SUBNET on the vehicle, LOCALHOST in tests) and Fast DDS's default transports (it must
  reach the tether; the topside profile's 0.5 s announcement period, ``fastdds_topside.xml``). It has no
  participant on the vehicle's internal domain.
* Its child, :mod:`hindrax_bringup.gateway.internal`, is the internal side: the vehicle's loopback transport (every
  UDP socket on 127.0.0.1, :mod:`hindrax_common.process.dds_transport`), like every other vehicle process.

Why two processes: a Fast DDS profile (``FASTRTPS_DEFAULT_PROFILES_FILE``) applies to every participant of a
process and is read once, and rmw_fastrtps picks no profile per context; under ``LOCALHOST`` it binds its own UDP
transport to 0.0.0.0. One process could not have a loopback-bound internal participant and a topside one that
reaches the tether. The two are joined by a Unix socket pair (:mod:`.link`) that carries only the interface's
elements (:data:`.interface.INTERFACE`), as serialized messages; each ends when the other does.

Every request is checked here before it goes inside: an operator element's signature
(:class:`~hindrax_bringup.gateway.operator_signing.Verifier`, the key ``<keys dir>/<vehicle>.key``; none on the
vehicle = every operator request refused, the e-stop still works), a goal's and a setpoint's bounds
(:class:`.bounds.RequestBounds`), ``arm`` while another gateway answers to this vehicle's name or another server
answers one of its services (refused: :func:`.interface.extra_servers_problem`), and an
``arm`` that an e-stop overtook: one that arrived before an e-stop (while the operator's requests were busy) but is
answered after it is refused, and the vehicle disarmed again. A refusal is one line, counted in the gateway's status
(``/<name>/gateway/status`` on the topside, ``/diagnostics`` inside; ERROR while another gateway has this name or
another server answers one of its services).

Threads: three topside nodes, each with its own executor and thread: ``/<name>/gateway`` (``estop``,
telemetry, setpoints, status), ``/<name>/gateway_operator`` (the operator's services), ``/<name>/gateway_campaign``
(the ``run_identification`` action): a slow arm or a running campaign never delays an e-stop. The campaign's executor
has :data:`CAMPAIGN_THREADS` threads: one relays the running campaign, another answers its cancel and rejects a new
goal at once ("a campaign is already running"; a goal left unanswered would wait in DDS and could start a second
campaign after the first). One thread reads the channel. A relay whose internal server is absent or silent
(``call_timeout_s``) answers ``success: false`` with the reason; the action relay aborts its goal the same way, and
a cancel of the topside goal cancels the internal one.

Parameters: read by the internal side (:mod:`.internal`). Run alone: ``python -m hindrax_bringup.gateway.node
--ros-args --params-file ros_ws/config/hindrax.yaml -p topside_domain_id:=7``."""
from __future__ import annotations

import contextlib
import itertools
import math
import os
import queue
import signal
import socket
import subprocess
import sys
import threading
import time
from concurrent.futures import Future
from typing import Any, Callable, Sequence

import rclpy
from action_msgs.msg import GoalStatus
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile
from rclpy.serialization import deserialize_message, serialize_message

from hindrax_common.process.dds_transport import (PROFILE_ENV, RANGE_ENV, TOPSIDE_PROFILE_FILE, loopback_transport,
    profile_path)
from .operator_signing import OperatorKeyError, Verifier, key_path, load_key, replay_path
from hindrax_common.process.ros_process import RosProcess
from .sros2_policy import topside_enclaves
from .bounds import RequestBounds
from .interface import GATEWAY_NODE, STATUS_TOPIC, duplicate_problem, extra_servers_problem, participants, relays
from .internal import GatewaySettings, interface_type
from .link import Channel

__all__ = ["Gateway", "main"]

#: how often a relayed campaign checks for a cancel of the topside goal, s
CANCEL_POLL_S = 0.1
#: threads of the campaign node's executor: the running campaign's relay, and its cancel or a new goal's rejection
CAMPAIGN_THREADS = 2
#: the gateway's status (and its check for another gateway with its name) period, s
STATUS_PERIOD_S = 1.0
#: an operator request starting less than this after the previous one ended may have waited behind it: an e-stop
#: since the start of that busy spell overtook it, s
QUEUE_GAP_S = 0.5


class Gateway:
    """The topside side (module docstring): three nodes of ``context`` under ``/<settings.vehicle_name>``, relaying
    through ``channel`` (:class:`.link.Channel`) to the internal side. :meth:`start` spins them and reads the
    channel in threads of their own; :meth:`close` stops them (the context is left to the caller)."""

    def __init__(self, channel: Channel, context: Any, settings: GatewaySettings, bounds: RequestBounds,
                 verifier: Verifier) -> None:
        self.settings, self.channel, self.bounds, self.verifier = settings, channel, bounds, verifier
        ns = "/" + settings.vehicle_name
        make = lambda name: Node(name, namespace=ns, context=context,  # noqa: E731
                                 use_global_arguments=False, start_parameter_services=False, enable_rosout=False)
        self.front = make(GATEWAY_NODE)
        self.operator = make(GATEWAY_NODE + "_operator")
        self.campaign = make(GATEWAY_NODE + "_campaign")
        self.nodes = (self.front, self.operator, self.campaign)
        self.relayed = {"services": 0, "failed": 0, "messages": 0, "out_of_bounds": 0, "overtaken_by_estop": 0,
                        "refused_duplicate_name": 0}
        """Counts: service calls relayed, of those failed (absent or silent server), topic messages relayed, and the
        requests refused for bounds, an e-stop that overtook them, another gateway with this name."""
        self.duplicate = ""
        """One line while another gateway answers to this vehicle's name (:func:`.interface.duplicate_problem`)."""
        self.extra = ""
        """One line while another server answers an operator service (:func:`.interface.extra_servers_problem`)."""
        self.last_refusal = ""
        self._ids = itertools.count(1)
        self._pending: dict[int, Future] = {}
        self._goals: dict[int, queue.Queue] = {}
        self._last_estop_s = -math.inf
        self._operator_idle_s = -math.inf
        self._busy_since_s = -math.inf
        for relay in relays("service"):
            node = self.front if relay.who == "anyone" else self.operator
            node.create_service(interface_type(relay.type), relay.topside, self._service_callback(relay))
        reliable = QoSProfile(depth=10)
        self._out = {r.topside: self.front.create_publisher(interface_type(r.type), r.topside, reliable)
                     for r in relays("topic_out")}
        for relay in relays("topic_in"):
            self.front.create_subscription(interface_type(relay.type), relay.topside, self._topic_in(relay), reliable)
        (action,) = relays("action")
        self._action_type = interface_type(action.type)
        self._campaign_running = threading.Lock()  # held while a campaign is relayed
        self._closing = threading.Event()
        self._action_server = ActionServer(self.campaign, self._action_type, action.topside, self._run_goal,
                                           callback_group=ReentrantCallbackGroup(), goal_callback=self._on_goal,
                                           cancel_callback=lambda _goal: CancelResponse.ACCEPT)
        self.front.create_timer(STATUS_PERIOD_S, self.publish_status)
        self.executors = []
        for node in self.nodes:
            executor = (MultiThreadedExecutor(CAMPAIGN_THREADS, context=context) if node is self.campaign else
                        SingleThreadedExecutor(context=context))
            executor.add_node(node)
            self.executors.append(executor)
        self._threads: list[threading.Thread] = []

    # ------------------------------------------------------------------------------------------- checks
    def _refuse(self, why: str, count: str | None = None) -> str:
        if count:
            self.relayed[count] += 1
        self.last_refusal = why
        self.front.get_logger().warn(why + (f" ({self.verifier.problem})" if self.verifier.problem else ""))
        return why

    def _operator_check(self, relay: Any, request: Any) -> str:
        """Why an operator's request is refused before it goes inside ("" = relay it)."""
        why = self.verifier.check_message(relay.topside, request)
        if why:
            return self._refuse(why)
        if relay.topside == "arm" and (self.duplicate or self.extra):
            return self._refuse(f"arm: refused: {self.duplicate or self.extra}", "refused_duplicate_name")
        return ""

    def publish_status(self) -> None:
        """Look for another gateway with this vehicle's name; publish the gateway's status (topside and inside)."""
        name = self.settings.vehicle_name
        infos = self.front.get_publishers_info_by_topic(f"/{name}/{STATUS_TOPIC}")
        self.duplicate = duplicate_problem(name, participants(i.endpoint_gid for i in infos))
        self.extra = extra_servers_problem(name, self.front.count_services)
        problem = self.duplicate or self.extra
        if problem:
            self.front.get_logger().error(problem, throttle_duration_sec=10.0)
        no_key = self.verifier.key is None
        level = DiagnosticStatus.ERROR if problem else DiagnosticStatus.WARN if no_key else DiagnosticStatus.OK
        message = problem or ("no operator key on the vehicle: operator requests refused" if no_key else "ok")
        values = {**{f"requests.{k}": v for k, v in self.verifier.counts.items()}, **self.relayed,
                  "last_refusal": self.last_refusal}
        status = DiagnosticStatus(level=level, name=f"{name}/gateway", message=message,
                                  values=[KeyValue(key=k, value=str(v)) for k, v in values.items()])
        self._out[STATUS_TOPIC].publish(status)
        self.channel.send({"k": "status"}, serialize_message(status))

    # ------------------------------------------------------------------------------------------- relays
    def _topic_in(self, relay: Any) -> Callable[[Any], None]:
        def forward(msg: Any) -> None:
            why = self.verifier.check_message(relay.topside, msg)
            if why:
                self._refuse(why)
                return
            why = self.bounds.setpoint_problem(msg)
            if why:
                self._refuse(why, "out_of_bounds")
                return
            self.relayed["messages"] += 1
            self.channel.send({"k": "publish", "name": relay.internal}, serialize_message(msg))
        return forward

    def _service_callback(self, relay: Any) -> Callable[[Any, Any], Any]:
        inner = interface_type(relay.inner_type)
        operator = relay.who == "operator"
        arm = relay.topside == "arm"

        def to_internal(request: Any) -> Any:
            if relay.internal == "/esc/set_armed":
                return inner.Request(arm=arm)
            out = inner.Request()
            for key in out.get_fields_and_field_types():
                setattr(out, key, getattr(request, key))
            return out

        def callback(request: Any, response: Any) -> Any:
            started = time.monotonic()
            if relay.topside == "estop":
                self._last_estop_s = started
            if operator:
                if started - self._operator_idle_s > QUEUE_GAP_S:
                    self._busy_since_s = started
            try:
                why = self._operator_check(relay, request) if operator else ""
                if not why and arm and self._last_estop_s >= self._busy_since_s:
                    why = self._refuse("arm: refused: an e-stop arrived while it waited; hindrax reset, then hindrax "
                                       "arm again", "overtaken_by_estop")
                if why:
                    response.success, response.message = False, why
                    return response
                self.relayed["services"] += 1
                answer, why = self.call(relay.internal, to_internal(request), inner)
                if answer is None:
                    self.relayed["failed"] += 1
                    response.success, response.message = False, f"{relay.internal}: {why}"
                    return response
                if arm and answer.success and self._last_estop_s >= self._busy_since_s:
                    self.call(relay.internal, inner.Request(arm=False), inner)
                    response.success = False
                    response.message = self._refuse("arm: refused: an e-stop arrived before the arm completed; "
                                                    "disarmed again", "overtaken_by_estop")
                    return response
                for key in response.get_fields_and_field_types():
                    if hasattr(answer, key):
                        setattr(response, key, getattr(answer, key))
                if relay.internal == "/esc/set_armed":
                    response.message = answer.message or ("armed" if answer.armed else "disarmed")
                return response
            finally:
                if operator:
                    self._operator_idle_s = time.monotonic()
        return callback

    def call(self, name: str, request: Any, cls: Any) -> tuple[Any, str]:
        """Call internal service ``name`` (type ``cls``) through the internal side and wait for its answer:
        (response, "") or (None, one-line reason)."""
        call_id = next(self._ids)
        pending = self._pending[call_id] = Future()
        try:
            if not self.channel.send({"k": "call", "id": call_id, "name": name}, serialize_message(request)):
                return None, "the gateway's internal side is gone"
            head, payload = pending.result(timeout=self.settings.call_timeout_s)
        except TimeoutError:
            return None, f"no answer within {self.settings.call_timeout_s:g} s"
        finally:
            self._pending.pop(call_id, None)
        if not head.get("ok"):
            return None, str(head.get("why", "failed"))
        return deserialize_message(payload, cls.Response), ""

    def _on_goal(self, _goal: Any) -> GoalResponse:
        """A new topside goal: rejected at once while a campaign is relayed (module docstring, "Threads")."""
        if self._campaign_running.locked():
            self._refuse("run_identification: refused: a campaign is already running")
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    def _run_goal(self, goal_handle: Any) -> Any:
        """The topside ``run_identification`` goal, checked, sent to the identification node; its feedback relayed,
        a cancel passed on; ends as the internal goal ended. Aborted when another one is relayed (two goals that
        passed :meth:`_on_goal` together)."""
        result_type = self._action_type.Result

        def failed(why: str) -> Any:
            goal_handle.abort()
            return result_type(success=False, message=why if why.startswith("run_identification") else
                               f"run_identification: {why}")

        if not self._campaign_running.acquire(blocking=False):
            return failed(self._refuse("run_identification: refused: a campaign is already running"))
        try:
            return self._relay_goal(goal_handle, failed)
        finally:
            self._campaign_running.release()

    def _relay_goal(self, goal_handle: Any, failed: Callable[[str], Any]) -> Any:
        """:meth:`_run_goal`'s body, while it holds the campaign."""
        result_type = self._action_type.Result
        why = self.verifier.check_message("run_identification", goal_handle.request)
        if why:
            return failed(self._refuse(why))
        why = self.bounds.goal_problem(goal_handle.request)
        if why:
            return failed(self._refuse(why, "out_of_bounds"))
        goal_id = next(self._ids)
        replies: queue.Queue = queue.Queue()
        self._goals[goal_id] = replies
        answer_by = time.monotonic() + self.settings.call_timeout_s
        accepted = cancelling = False
        try:
            self.channel.send({"k": "goal", "id": goal_id}, serialize_message(goal_handle.request))
            while True:  # one loop over the frame kinds: a goal's feedback can overtake its acceptance
                try:
                    head, payload = replies.get(timeout=CANCEL_POLL_S)
                except queue.Empty:
                    if not accepted and time.monotonic() > answer_by:
                        # fail closed: a goal accepted after this is cancelled, not left running unseen
                        self.channel.send({"k": "cancel", "id": goal_id})
                        return failed("no answer from the identification node within "
                                      f"{self.settings.call_timeout_s:g} s")
                    if accepted and goal_handle.is_cancel_requested and not cancelling:
                        self.channel.send({"k": "cancel", "id": goal_id})
                        cancelling = True
                    if self._closing.is_set() or not self.campaign.context.ok():
                        return failed("the gateway is shutting down")
                    continue
                kind = head.get("k")
                if kind == "feedback":  # sent only for an executing goal: accepted
                    accepted = True
                    goal_handle.publish_feedback(deserialize_message(payload, self._action_type.Feedback))
                elif kind == "accepted":
                    if not head.get("ok"):
                        return failed(str(head.get("why", "refused")))
                    accepted = True
                elif kind == "result":
                    break
                else:
                    return failed("the gateway's internal side is gone")
        finally:
            self._goals.pop(goal_id, None)
        status = head.get("status")
        if status == GoalStatus.STATUS_SUCCEEDED:
            goal_handle.succeed()
        elif status == GoalStatus.STATUS_CANCELED and goal_handle.is_cancel_requested:
            goal_handle.canceled()
        else:
            goal_handle.abort()
        return deserialize_message(payload, result_type)

    def _read_channel(self) -> None:
        """The channel's reader thread: answers, telemetry, the campaign's replies; at its end the process ends."""
        while (frame := self.channel.recv()) is not None:
            head, payload = frame
            kind = head.get("k")
            pending = self._pending.get(head.get("id")) if kind == "answer" else None
            if pending is not None:
                if not pending.done():  # a second answer to one call is dropped, not raised here
                    pending.set_result((head, payload))
            elif kind == "topic" and head.get("name") in self._out:
                self.relayed["messages"] += 1
                self._out[head["name"]].publish(payload)
            elif kind in ("accepted", "feedback", "result") and head.get("id") in self._goals:
                self._goals[head["id"]].put((head, payload))
        for replies in list(self._goals.values()):
            replies.put(({"k": "gone"}, b""))
        if self.executors:
            self.front.get_logger().error("the gateway's internal side ended: ending the gateway")
            os.kill(os.getpid(), signal.SIGTERM)

    # ------------------------------------------------------------------------------------------- life
    def start(self) -> None:
        """Spin each topside node in a thread of its own; read the channel in another."""
        for executor in self.executors:
            thread = threading.Thread(target=self._spin, args=(executor,), daemon=True, name="gateway-topside")
            thread.start()
            self._threads.append(thread)
        threading.Thread(target=self._read_channel, daemon=True, name="gateway-link").start()

    @staticmethod
    def _spin(executor: Any) -> None:
        with contextlib.suppress(ExternalShutdownException):
            executor.spin()

    def close(self) -> None:
        """Stop the topside executors, join their threads, destroy the topside nodes (idempotent)."""
        executors, self.executors = self.executors, []
        self._closing.set()  # a relayed campaign ends its wait: the campaign's executor can stop
        for executor in executors:
            executor.shutdown(timeout_sec=1.0)
        for thread in self._threads:
            thread.join(timeout=2.0)
        self._threads = []
        if executors:
            self._action_server.destroy()
            for node in self.nodes:
                node.destroy_node()


def start_internal_side(argv: Sequence[str]) -> tuple[subprocess.Popen, Channel]:
    """Start the internal side (:mod:`.internal`) with the vehicle's loopback transport and the same ROS arguments;
    returns it and this end of the channel."""
    env = {k: v for k, v in os.environ.items() if k != "ROS_STATIC_PEERS"}
    env[RANGE_ENV] = "LOCALHOST"
    loopback_transport(env)
    ours, theirs = socket.socketpair()
    child = subprocess.Popen([sys.executable, "-m", "hindrax_bringup.gateway.internal", "--link-fd",
                              str(theirs.fileno()), *argv], pass_fds=(theirs.fileno(),), env=env)
    theirs.close()
    return child, Channel(ours)


def main(args: Sequence[str] | None = None) -> int:
    """Process entry point (module docstring). Exit status 0 on SIGINT/SIGTERM, 1 on a bad setting (one line, from
    the internal side) or when the internal side cannot start."""
    argv = list(sys.argv[1:] if args is None else args)
    internal_domain = os.environ.get("ROS_DOMAIN_ID", "0")
    child, channel = start_internal_side(argv)
    try:
        first = channel.recv()
        if first is None or first[0].get("k") != "settings":
            child.wait(timeout=30)
            return 1
        settings = GatewaySettings(**first[0]["settings"])
        bounds = RequestBounds(**first[0]["bounds"])
        try:
            verifier = Verifier(load_key(key_path(settings.vehicle_name)), settings.vehicle_name,
                                state=replay_path(settings.vehicle_name))
            if verifier.problem:
                print(f"gateway: {verifier.problem}", file=sys.stderr, flush=True)
        except OperatorKeyError as exc:
            print(f"gateway: {exc}: every operator request will be refused (the e-stop works)", file=sys.stderr,
                  flush=True)
            verifier = Verifier(None, settings.vehicle_name)
        # this process's participants are the topside's only: its range, peers and default transports, with the
        # topside profile's announcement period
        os.environ[PROFILE_ENV] = str(profile_path(TOPSIDE_PROFILE_FILE))
        os.environ[RANGE_ENV] = settings.topside_discovery_range
        os.environ["ROS_DOMAIN_ID"] = str(settings.topside_domain_id)
        with RosProcess(["gateway_node", "--ros-args", "--enclave", topside_enclaves(settings.vehicle_name)["gateway"]],
                        executor="single", interrupt=False) as proc:
            gateway = Gateway(channel, rclpy.get_default_context(), settings, bounds, verifier)
            proc.at_exit(gateway.close)
            gateway.start()
            gateway.front.get_logger().info(
                f"vehicle {settings.vehicle_name!r}: internal domain {internal_domain} (loopback, process "
                f"{child.pid}), topside domain {settings.topside_domain_id} ({settings.topside_discovery_range})")
            proc.spin()
        return proc.status
    finally:
        channel.close()
        try:
            child.wait(timeout=5)
        except subprocess.TimeoutExpired:
            child.kill()
            child.wait()


if __name__ == "__main__":
    raise SystemExit(main())
