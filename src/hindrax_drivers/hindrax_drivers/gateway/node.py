"""The gateway process: the vehicle's only participant on the topside domain (docs/architecture.md §8.2).

One process, two rclpy Contexts:

* the *internal* context: the vehicle's own domain (``ROS_DOMAIN_ID``), discovery on loopback only
  (``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``, forced here whatever the environment says). Its node
  ``/<vehicle.name>/gateway`` holds the clients, publishers and subscriptions that reach the vehicle's nodes;
* the *topside* context: ``topside_domain_id`` with ``topside_discovery_range`` (SUBNET on the vehicle, LOCALHOST
  in tests). rcl reads the discovery range (and ``ROS_STATIC_PEERS``) from the environment at each context's
  init, so the environment is set for that init and restored after it. Under ``/<vehicle.name>/`` it serves the
  relays of :data:`hindrax_drivers.gateway.interface.INTERFACE` and nothing else.

A Fast DDS profile named by ``FASTRTPS_DEFAULT_PROFILES_FILE`` applies to every participant of a process, and the
vehicle's profile binds UDP to 127.0.0.1: the gateway drops that variable before the first init, or its topside
participant could not reach the tether.

Threads: the internal context is spun by the main thread; the topside has three nodes, each with its own
SingleThreadedExecutor and thread, because a relay waits for the internal answer (at most ``call_timeout_s``) and a
campaign for its whole run: ``/<name>/gateway`` (``estop``, telemetry, setpoints), ``/<name>/gateway_operator``
(the operator's services) and ``/<name>/gateway_campaign`` (the ``run_identification`` action). A slow arm or a
running campaign therefore never delays an e-stop. Messages are relayed as serialized bytes (``raw=True``), never
decoded.

A relay whose internal server is absent or silent answers ``success: false`` with the reason (one line); the
action relay aborts its goal the same way, and a cancel of the topside goal cancels the internal one.

Parameters: the vehicle file's ``vehicle.*`` keys (``vehicle.name``: the namespace), ``topside_domain_id`` (int,
0-101), ``topside_discovery_range`` (``LOCALHOST``, ``SUBNET``, ``SYSTEM_DEFAULT``, ``OFF``), ``call_timeout_s``
(0.1-30 s, default 2). A bad value stops the start with one line naming key, value and allowed range.

Run alone: ``python -m hindrax_drivers.gateway.node --ros-args --params-file ros_ws/config/hindrax.yaml -p
topside_domain_id:=7``.
"""
from __future__ import annotations

import importlib
import os
import threading
from dataclasses import dataclass
from typing import Any, Callable, Sequence

import rclpy
from action_msgs.msg import GoalStatus
from rclpy.action import ActionClient, ActionServer, CancelResponse
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions

from ..config import ConfigError, ConfigIssue
from ..node_common import load_node_config
from ..ros_process import RosProcess
from ..sros2_policy import topside_enclaves
from .interface import GATEWAY_NODE, relays

__all__ = ["DISCOVERY_RANGES", "GatewaySettings", "Gateway", "main", "read_settings"]

#: allowed values of ``topside_discovery_range`` (Jazzy's ``ROS_AUTOMATIC_DISCOVERY_RANGE``)
DISCOVERY_RANGES = ("LOCALHOST", "SUBNET", "SYSTEM_DEFAULT", "OFF")
#: default longest wait for an internal service's answer, s
DEFAULT_CALL_TIMEOUT_S = 2.0
#: the relay of these topics takes best-effort publishers too (odometry is often published best effort)
BEST_EFFORT_TOPICS = frozenset({"odom"})
#: how often a relayed campaign checks for a cancel of the topside goal, s
CANCEL_POLL_S = 0.1


@dataclass(frozen=True)
class GatewaySettings:
    """The gateway's settings: ``vehicle_name`` (namespace), ``topside_domain_id``, ``topside_discovery_range``,
    ``call_timeout_s`` (s)."""

    vehicle_name: str
    topside_domain_id: int
    topside_discovery_range: str
    call_timeout_s: float


def read_settings(node: Any) -> GatewaySettings:
    """Declare and read the gateway's parameters on ``node`` (module docstring). Raises
    :class:`~hindrax_drivers.config.ConfigError` naming key, value and allowed range."""
    cfg = load_node_config(node, ("vehicle",))
    domain = node.declare_parameter("topside_domain_id", 0).value
    scope = node.declare_parameter("topside_discovery_range", "LOCALHOST").value
    timeout = node.declare_parameter("call_timeout_s", DEFAULT_CALL_TIMEOUT_S).value
    if isinstance(domain, bool) or not isinstance(domain, int) or not 0 <= domain <= 101:
        raise ConfigError([ConfigIssue("topside_domain_id", domain, "integer in [0, 101]")])
    if scope not in DISCOVERY_RANGES:
        raise ConfigError([ConfigIssue("topside_discovery_range", scope, "one of " + ", ".join(DISCOVERY_RANGES))])
    if isinstance(timeout, bool) or not isinstance(timeout, (int, float)) or not 0.1 <= timeout <= 30.0:
        raise ConfigError([ConfigIssue("call_timeout_s", timeout, "number in [0.1, 30]")])
    return GatewaySettings(cfg.vehicle.name, int(domain), str(scope), float(timeout))


def interface_type(name: str) -> Any:
    """The Python class of a ROS interface type ``pkg/kind/Name`` (kind ``msg``, ``srv`` or ``action``)."""
    package, kind, cls = name.split("/")
    return getattr(importlib.import_module(f"{package}.{kind}"), cls)


def wait_for(future: Any, timeout_s: float) -> bool:
    """Wait up to ``timeout_s`` (wall clock) for an rclpy Future completed by another thread's executor; True if
    done."""
    done = threading.Event()
    future.add_done_callback(lambda _f: done.set())
    return done.wait(timeout_s) or future.done()


def init_topside_context(domain_id: int, discovery_range: str, static_peers: str | None,
                         enclave: str | None = None) -> Any:
    """An initialised rclpy Context on the topside domain. rcl reads ``ROS_AUTOMATIC_DISCOVERY_RANGE`` and
    ``ROS_STATIC_PEERS`` at init: they are set for this init only, and the environment restored after. ``enclave``:
    the SROS2 enclave of this context (``/<vehicle.name>/gateway``, :mod:`hindrax_drivers.sros2_policy`; used when
    ``ROS_SECURITY_ENABLE`` is true, on the Pi)."""
    saved = {k: os.environ.get(k) for k in ("ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_STATIC_PEERS")}
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = discovery_range
    if static_peers:
        os.environ["ROS_STATIC_PEERS"] = static_peers
    context = rclpy.Context()
    try:
        rclpy.init(args=["--ros-args", "--enclave", enclave] if enclave else [], context=context,
                   domain_id=domain_id, signal_handler_options=SignalHandlerOptions.NO)
    finally:
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value
    return context


class Gateway:
    """The relays between ``internal`` (a node of the internal context, spun by the caller) and three topside nodes
    of ``topside_context`` under ``/<settings.vehicle_name>`` (module docstring). :meth:`start` spins the topside
    in threads of its own; :meth:`close` stops and destroys them (the context is left to the caller)."""

    def __init__(self, internal: Any, topside_context: Any, settings: GatewaySettings) -> None:
        self.settings = settings
        self.internal = internal
        ns = "/" + settings.vehicle_name
        # no rosout: these nodes never log, and the front node's logger name (<vehicle>.gateway) is the internal
        # node's, whose rosout publisher rcl keys by that name in the process (a second one was refused with a
        # warning at every start, and destroying either node would have unregistered the other's)
        make = lambda name: Node(name, namespace=ns, context=topside_context,  # noqa: E731
                                 use_global_arguments=False, start_parameter_services=False, enable_rosout=False)
        self.front = make(GATEWAY_NODE)
        self.operator = make(GATEWAY_NODE + "_operator")
        self.campaign = make(GATEWAY_NODE + "_campaign")
        self.nodes = (self.front, self.operator, self.campaign)
        self.relayed = {"services": 0, "failed": 0, "messages": 0}
        """Counts: service calls relayed, of those failed (absent or silent server), topic messages relayed."""
        self._clients: dict[str, Any] = {}
        for relay in relays("service"):
            node = self.front if relay.who == "anyone" else self.operator
            internal_type = interface_type("hindrax_msgs/srv/SetArmed") if relay.internal == "/esc/set_armed" \
                else interface_type(relay.type)
            if relay.internal not in self._clients:
                self._clients[relay.internal] = internal.create_client(internal_type, relay.internal)
            node.create_service(interface_type(relay.type), relay.topside, self._service_callback(relay))
        reliable = QoSProfile(depth=10)
        best_effort = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)
        for relay in relays("topic_out"):
            cls = interface_type(relay.type)
            pub = self.front.create_publisher(cls, relay.topside, reliable)
            internal.create_subscription(cls, relay.internal, self._forward(pub), best_effort
                                         if relay.topside in BEST_EFFORT_TOPICS else reliable, raw=True)
        for relay in relays("topic_in"):
            cls = interface_type(relay.type)
            pub = internal.create_publisher(cls, relay.internal, reliable)
            self.front.create_subscription(cls, relay.topside, self._forward(pub), reliable, raw=True)
        (action,) = relays("action")
        self._action_type = interface_type(action.type)
        self._action_client = ActionClient(internal, self._action_type, action.internal)
        self._action_server = ActionServer(self.campaign, self._action_type, action.topside, self._run_goal,
                                           cancel_callback=lambda _goal: CancelResponse.ACCEPT)
        self.executors = []
        for node in self.nodes:
            executor = SingleThreadedExecutor(context=topside_context)
            executor.add_node(node)
            self.executors.append(executor)
        self._threads: list[threading.Thread] = []

    # ------------------------------------------------------------------------------------------- relays
    def _forward(self, publisher: Any) -> Callable[[bytes], None]:
        def forward(data: bytes) -> None:
            self.relayed["messages"] += 1
            publisher.publish(data)
        return forward

    def _service_callback(self, relay: Any) -> Callable[[Any, Any], Any]:
        client = self._clients[relay.internal]
        if relay.internal == "/esc/set_armed":
            set_armed = interface_type("hindrax_msgs/srv/SetArmed")
            arm = relay.topside == "arm"

            def to_internal(_request: Any) -> Any:
                return set_armed.Request(arm=arm)

            def to_topside(answer: Any, response: Any) -> Any:
                response.success = bool(answer.success)
                response.message = answer.message or ("armed" if answer.armed else "disarmed")
                return response
        else:
            def to_internal(request: Any) -> Any:
                return request

            def to_topside(answer: Any, _response: Any) -> Any:
                return answer

        def callback(request: Any, response: Any) -> Any:
            self.relayed["services"] += 1
            answer, why = self.call(client, to_internal(request))
            if answer is None:
                self.relayed["failed"] += 1
                response.success = False
                response.message = f"{relay.internal}: {why}"
                return response
            return to_topside(answer, response)
        return callback

    def call(self, client: Any, request: Any) -> tuple[Any, str]:
        """Call an internal service and wait for its answer: (response, "") or (None, one-line reason)."""
        if not client.service_is_ready():
            return None, "not available on the vehicle (its node is not running)"
        future = client.call_async(request)
        if not wait_for(future, self.settings.call_timeout_s):
            client.remove_pending_request(future)
            return None, f"no answer within {self.settings.call_timeout_s:g} s"
        return future.result(), ""

    def _run_goal(self, goal_handle: Any) -> Any:
        """The topside ``run_identification`` goal: sent to the identification node, its feedback relayed, a cancel
        passed on; ends as the internal goal ended."""
        result_type = self._action_type.Result

        def failed(why: str) -> Any:
            goal_handle.abort()
            return result_type(success=False, message=f"run_identification: {why}")

        if not self._action_client.server_is_ready():
            return failed("the identification node is not running on the vehicle")
        sent = self._action_client.send_goal_async(
            goal_handle.request, feedback_callback=lambda fb: goal_handle.publish_feedback(fb.feedback))
        if not wait_for(sent, self.settings.call_timeout_s):
            return failed(f"no answer from the identification node within {self.settings.call_timeout_s:g} s")
        inner = sent.result()
        if not inner.accepted:
            return failed("refused by the identification node (see identification/status)")
        result = inner.get_result_async()
        cancelling = False
        while not wait_for(result, CANCEL_POLL_S):
            if goal_handle.is_cancel_requested and not cancelling:
                inner.cancel_goal_async()
                cancelling = True
            if not self.campaign.context.ok():
                return failed("the gateway is shutting down")
        answer = result.result()
        if answer.status == GoalStatus.STATUS_SUCCEEDED:
            goal_handle.succeed()
        elif answer.status == GoalStatus.STATUS_CANCELED and goal_handle.is_cancel_requested:
            goal_handle.canceled()
        else:
            goal_handle.abort()
        return answer.result

    # ------------------------------------------------------------------------------------------- life
    def start(self) -> None:
        """Spin each topside node in a thread of its own."""
        for executor in self.executors:
            thread = threading.Thread(target=self._spin, args=(executor,), daemon=True, name="gateway-topside")
            thread.start()
            self._threads.append(thread)

    @staticmethod
    def _spin(executor: Any) -> None:
        try:
            executor.spin()
        except ExternalShutdownException:
            pass

    def close(self) -> None:
        """Stop the topside executors, join their threads, destroy the topside nodes (idempotent)."""
        for executor in self.executors:
            executor.shutdown(timeout_sec=1.0)
        for thread in self._threads:
            thread.join(timeout=2.0)
        self._threads = []
        self._action_server.destroy()
        for node in self.nodes:
            node.destroy_node()
        self.executors = []


def main(args: Sequence[str] | None = None) -> int:
    """Process entry point (module docstring). Exit status 0 on SIGINT/SIGTERM, 1 on a bad setting (one line)."""
    os.environ.pop("FASTRTPS_DEFAULT_PROFILES_FILE", None)  # module docstring: the topside must not be loopback-bound
    static_peers = os.environ.pop("ROS_STATIC_PEERS", None)  # the topside's, not the internal graph's
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"  # the internal context: loopback whatever was set
    with RosProcess(args, errors={ConfigError: "invalid configuration"}, executor="single",
                    interrupt=False) as proc:
        boot = Node("gateway", automatically_declare_parameters_from_overrides=False)
        try:
            settings = read_settings(boot)
        finally:
            boot.destroy_node()
        internal = proc.own(Node("gateway", namespace="/" + settings.vehicle_name, use_global_arguments=False))
        proc.executor.add_node(internal)
        topside = init_topside_context(settings.topside_domain_id, settings.topside_discovery_range, static_peers,
                                       enclave=topside_enclaves(settings.vehicle_name)["gateway"])
        proc.at_exit(lambda: rclpy.try_shutdown(context=topside))
        gateway = Gateway(internal, topside, settings)
        proc.at_exit(gateway.close)
        gateway.start()
        internal.get_logger().info(
            f"vehicle {settings.vehicle_name!r}: internal domain {os.environ.get('ROS_DOMAIN_ID', '0')} (loopback), "
            f"topside domain {settings.topside_domain_id} ({settings.topside_discovery_range})")
        proc.spin()
    return proc.status


if __name__ == "__main__":
    raise SystemExit(main())
