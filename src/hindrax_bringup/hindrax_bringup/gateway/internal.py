"""The gateway's internal side: its process on the vehicle's loopback graph (docs/architecture.md §8.2).

Started by the topside process (:mod:`hindrax_bringup.gateway.node`) with the vehicle's loopback transport
(:mod:`hindrax_common.process.dds_transport`: every UDP socket on 127.0.0.1) and one end of a Unix socket pair
(``--link-fd N``, :mod:`.link`). It reads the gateway's settings from its parameters (the vehicle file), sends them and
the request bounds (:class:`.bounds.RequestBounds`) to the topside process, then serves it: calls the internal services,
publishes the internal topics and sends the campaign goals of the interface (:data:`.interface.INTERFACE`) and nothing
else (a name outside the interface is refused), and sends the telemetry topics back as serialized bytes. Its node is
``/<vehicle.name>/gateway`` on the internal graph; the gateway's status goes to ``/diagnostics``. It ends when the
channel ends (the topside process is gone), and the topside process ends when it does.

Parameters (read here, for both processes): the vehicle file (``vehicle.name``: the namespace; the sections the
bounds need), ``topside_domain_id`` (int, 0-101), ``topside_discovery_range`` (``LOCALHOST``, ``SUBNET``,
``SYSTEM_DEFAULT``, ``OFF``), ``call_timeout_s`` (0.1-30 s, default 4). A bad value ends the start with one line
naming key, value and allowed range (exit status 1).

A campaign goal whose send-goal response is lost (Fast DDS drops a response to a client its server has not matched
yet: :mod:`hindrax_common.node_support.action_goal`) is known accepted by its first feedback, which the server sends
only for a goal it executes: the goal's handle is made then and its result fetched as for an answered goal. A cancel
that comes before the acceptance is kept and sent once the goal is known accepted."""
from __future__ import annotations

import argparse
import importlib
import os
import signal
import socket
import threading
import uuid
from dataclasses import asdict, dataclass
from typing import Any, Sequence

import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.action import ActionClient
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message
from unique_identifier_msgs.msg import UUID

from hindrax_common.config import ConfigError, ConfigIssue
from hindrax_common.node_support.action_goal import accepted_goal_handle
from hindrax_common.node_support.node_common import load_node_config
from hindrax_common.process.ros_process import RosProcess
from .bounds import RequestBounds
from .interface import GATEWAY_NODE, relays
from .link import Channel

__all__ = ["BOUNDS_SECTIONS", "DISCOVERY_RANGES", "GatewaySettings", "InternalSide", "interface_type", "main",
           "read_settings"]

#: allowed values of ``topside_discovery_range`` (Jazzy's ``ROS_AUTOMATIC_DISCOVERY_RANGE``)
DISCOVERY_RANGES = ("LOCALHOST", "SUBNET", "SYSTEM_DEFAULT", "OFF")
#: default longest wait for an internal service's answer, s: patience, not a safety bound (the call goes on inside
#: and the e-stop has its own thread); 2 s gave "no answer" for controller/enable under a loaded suite; below the 5 s
#: of ``hindrax arm`` and ``ident status``, so the operator gets the gateway's reason rather than the command's silence
DEFAULT_CALL_TIMEOUT_S = 4.0
#: the vehicle file's sections the gateway reads: its name, and what the request bounds need
BOUNDS_SECTIONS = ("vehicle", "identification", "supervisor", "limits", "pool", "hydrodynamics", "thrusters", "esc")
#: the relay of these topics takes best-effort publishers too (odometry is often published best effort)
BEST_EFFORT_TOPICS = frozenset({"odom"})


@dataclass(frozen=True)
class GatewaySettings:
    """The gateway's settings: ``vehicle_name`` (namespace), ``topside_domain_id``, ``topside_discovery_range``,
    ``call_timeout_s`` (s)."""

    vehicle_name: str
    topside_domain_id: int
    topside_discovery_range: str
    call_timeout_s: float


def read_settings(node: Any) -> tuple[GatewaySettings, Any]:
    """Declare and read the gateway's parameters on ``node`` (module docstring): (settings, the vehicle file's
    :data:`BOUNDS_SECTIONS`). Raises :class:`~hindrax_common.config.ConfigError` naming key, value and range."""
    cfg = load_node_config(node, BOUNDS_SECTIONS)
    domain = node.declare_parameter("topside_domain_id", 0).value
    scope = node.declare_parameter("topside_discovery_range", "LOCALHOST").value
    timeout = node.declare_parameter("call_timeout_s", DEFAULT_CALL_TIMEOUT_S).value
    if isinstance(domain, bool) or not isinstance(domain, int) or not 0 <= domain <= 101:
        raise ConfigError([ConfigIssue("topside_domain_id", domain, "integer in [0, 101]")])
    if scope not in DISCOVERY_RANGES:
        raise ConfigError([ConfigIssue("topside_discovery_range", scope, "one of " + ", ".join(DISCOVERY_RANGES))])
    if isinstance(timeout, bool) or not isinstance(timeout, (int, float)) or not 0.1 <= timeout <= 30.0:
        raise ConfigError([ConfigIssue("call_timeout_s", timeout, "number in [0.1, 30]")])
    return GatewaySettings(cfg.vehicle.name, int(domain), str(scope), float(timeout)), cfg


def interface_type(name: str) -> Any:
    """The Python class of a ROS interface type ``pkg/kind/Name`` (kind ``msg``, ``srv`` or ``action``)."""
    package, kind, cls = name.split("/")
    return getattr(importlib.import_module(f"{package}.{kind}"), cls)


class InternalSide:
    """The interface's internal ends on ``node`` (module docstring), driven by frames from ``channel``
    (:class:`.link.Channel`); :meth:`serve` reads them until the channel ends."""

    def __init__(self, node: Any, channel: Any) -> None:
        self.node, self.channel = node, channel
        self.clients: dict[str, tuple[Any, Any]] = {}
        for relay in relays("service"):
            cls = interface_type(relay.inner_type)
            self.clients.setdefault(relay.internal, (node.create_client(cls, relay.internal), cls))
        reliable = QoSProfile(depth=10)
        best_effort = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)
        for relay in relays("topic_out"):
            if relay.internal:
                node.create_subscription(interface_type(relay.type), relay.internal, self._forward(relay.topside),
                                         best_effort if relay.topside in BEST_EFFORT_TOPICS else reliable, raw=True)
        self.publishers = {r.internal: node.create_publisher(interface_type(r.inner_type), r.internal, reliable)
                           for r in relays("topic_in")}
        (action,) = relays("action")
        self.action_type = interface_type(action.inner_type)
        self.action = ActionClient(node, self.action_type, action.internal)
        self.goals: dict[int, Any] = {}
        self.cancelled: set[int] = set()  # goals the topside cancelled before they were known accepted
        self.diagnostics = node.create_publisher(DiagnosticArray, "/diagnostics", 10)

    def _forward(self, topside: str) -> Any:
        return lambda data: self.channel.send({"k": "topic", "name": topside}, data)

    def serve(self) -> None:
        """Handle frames until the channel ends."""
        while (frame := self.channel.recv()) is not None:
            head, payload = frame
            try:
                getattr(self, "_on_" + str(head.get("k")), self._on_unknown)(head, payload)
            except Exception as exc:  # noqa: BLE001 - a malformed frame answers failure, the side goes on serving
                if "id" in head:
                    self.channel.send({"k": "answer", "id": head["id"], "ok": False, "why": f"gateway: {exc}"})

    def _on_unknown(self, head: dict, _payload: bytes) -> None:
        self.node.get_logger().warn(f"gateway link: unknown frame {head.get('k')!r} ignored")

    def _on_call(self, head: dict, payload: bytes) -> None:
        reply = {"k": "answer", "id": head["id"]}
        if head.get("name") not in self.clients:
            self.channel.send(dict(reply, ok=False, why="not in the gateway's interface"))
            return
        client, cls = self.clients[head["name"]]
        if not client.service_is_ready():
            self.channel.send(dict(reply, ok=False, why="not available on the vehicle (its node is not running)"))
            return
        future = client.call_async(deserialize_message(payload, cls.Request))
        future.add_done_callback(lambda f: self.channel.send(dict(reply, ok=True), serialize_message(f.result())))

    def _on_publish(self, head: dict, payload: bytes) -> None:
        if head.get("name") in self.publishers:
            self.publishers[head["name"]].publish(payload)

    def _on_status(self, _head: dict, payload: bytes) -> None:
        msg = DiagnosticArray(status=[deserialize_message(payload, DiagnosticStatus)])
        msg.header.stamp = self.node.get_clock().now().to_msg()
        self.diagnostics.publish(msg)

    def _on_goal(self, head: dict, payload: bytes) -> None:
        goal_id = head["id"]
        if not self.action.server_is_ready():
            self.channel.send({"k": "accepted", "id": goal_id, "ok": False,
                               "why": "the identification node is not running on the vehicle"})
            return
        goal = deserialize_message(payload, self.action_type.Goal)
        goal_uuid = UUID(uuid=list(uuid.uuid4().bytes))
        known = []  # the goal's handle once it is known accepted (its response, or its first feedback)

        def running(handle: Any) -> None:  # the first sign of acceptance only: the response or a feedback
            known.append(handle)
            self.goals[goal_id] = handle
            self.channel.send({"k": "accepted", "id": goal_id, "ok": True, "why": ""})
            handle.get_result_async().add_done_callback(lambda f: (self.goals.pop(goal_id, None), self.channel.send(
                {"k": "result", "id": goal_id, "status": int(f.result().status)},
                serialize_message(f.result().result))))
            if goal_id in self.cancelled:
                handle.cancel_goal_async()

        def on_feedback(fb: Any) -> None:
            if not known:  # executing, its response lost: accepted, as the lost response said
                now = self.node.get_clock().now().to_msg()
                running(accepted_goal_handle(self.action, goal_uuid, goal, now))
            self.channel.send({"k": "feedback", "id": goal_id}, serialize_message(fb.feedback))

        def on_sent(future: Any) -> None:
            handle = future.result()
            if known:
                return
            if handle.accepted:
                running(handle)
            else:
                self.channel.send({"k": "accepted", "id": goal_id, "ok": False,
                                   "why": "refused by the identification node (see identification/status)"})
        self.action.send_goal_async(goal, feedback_callback=on_feedback, goal_uuid=goal_uuid).add_done_callback(
            on_sent)

    def _on_cancel(self, head: dict, _payload: bytes) -> None:
        handle = self.goals.get(head["id"])
        if handle is not None:
            handle.cancel_goal_async()
        else:
            self.cancelled.add(head["id"])  # sent once the goal is known accepted (module docstring)


def main(args: Sequence[str] | None = None) -> int:
    """Process entry point (module docstring): ``--link-fd N`` then the ROS arguments. Exit status 0 when the
    channel or a signal ends it, 1 on a bad setting (one line)."""
    parser = argparse.ArgumentParser(prog="gateway internal side")
    parser.add_argument("--link-fd", type=int, required=True)
    known, ros_args = parser.parse_known_args(args)
    channel = Channel(socket.socket(fileno=known.link_fd))
    with RosProcess(["gateway_internal", *ros_args], errors={ConfigError: "invalid configuration"},
                    executor="single", interrupt=False) as proc:
        boot = Node("gateway", automatically_declare_parameters_from_overrides=False)
        try:
            settings, cfg = read_settings(boot)
        finally:
            boot.destroy_node()
        # no parameter services: nothing may set its use_sim_time at run time (issue 71.5)
        node = proc.own(Node(GATEWAY_NODE, namespace="/" + settings.vehicle_name, start_parameter_services=False))
        proc.executor.add_node(node)
        side = InternalSide(node, channel)
        channel.send({"k": "settings", "settings": asdict(settings), "bounds": asdict(RequestBounds.from_config(cfg))})

        def serve() -> None:
            side.serve()
            os.kill(os.getpid(), signal.SIGTERM)  # the topside process is gone: end this one too

        threading.Thread(target=serve, daemon=True, name="gateway-link").start()
        node.get_logger().info(f"vehicle {settings.vehicle_name!r}: internal side on domain "
                               f"{os.environ.get('ROS_DOMAIN_ID', '0')} (loopback)")
        proc.spin()
    channel.close()
    rclpy.try_shutdown()
    return proc.status


if __name__ == "__main__":
    raise SystemExit(main())
