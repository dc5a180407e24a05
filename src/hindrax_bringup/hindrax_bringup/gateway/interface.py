"""What the vehicle offers on the topside graph, and how a command finds the vehicle it means.

This is the whole topside interface (docs/architecture.md §8.2): the gateway (:mod:`hindrax_bringup.gateway.node`)
relays these and nothing else between the vehicle's internal graph (loopback) and the topside domain, under the
namespace ``/<vehicle.name>/``. Heartbeats, ``thrusters/*``, ``esc/*``, ``pressure/zero_depth`` and ``supervisor/abort``
have no entry: they do not exist on the topside. ``who`` is the access the SROS2 permissions policy grants on the Pi:
``anyone`` (every topside participant), ``operator`` (the operator enclave only), ``read`` (telemetry, subscribe only).

Pure: no rclpy import (the CLI, the policy generator and the tests read it)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Iterable

__all__ = ["GATEWAY_NODE", "INTERFACE", "STATUS_TOPIC", "Relay", "VehicleChoiceError", "choose_vehicle",
           "duplicate_problem", "extra_servers_problem", "participants", "relays", "vehicles_seen"]

#: the node name the gateway has on both graphs, in the namespace ``/<vehicle.name>``; tools find vehicles by it
GATEWAY_NODE = "gateway"


@dataclass(frozen=True)
class Relay:
    """One element of the topside interface.

    topside: name relative to ``/<vehicle.name>/``; internal: absolute name on the vehicle's internal graph (""
    for the gateway's own status); kind: ``service``, ``action``, ``topic_in`` (topside -> vehicle) or
    ``topic_out`` (vehicle -> topside); type: the ROS interface type on the topside (``pkg/srv/Name``,
    ``pkg/action/Name``, ``pkg/msg/Name``); who: ``anyone``, ``operator`` or ``read`` (module docstring);
    internal_type: the type on the internal graph when it differs (an operator's signed request, e.g.
    ``hindrax_msgs/srv/SignedTrigger`` on the topside, ``std_srvs/srv/Trigger`` inside)."""

    topside: str
    internal: str
    kind: str
    type: str
    who: str
    internal_type: str = ""

    @property
    def inner_type(self) -> str:
        """The type on the internal graph."""
        return self.internal_type or self.type


_TRIGGER = "std_srvs/srv/Trigger"
#: an operator's Trigger: signed on the topside (hindrax_bringup.gateway.operator_signing), plain inside
_SIGNED = "hindrax_msgs/srv/SignedTrigger"

#: the topside interface, in full (module docstring). ``arm``/``disarm`` call ``esc/set_armed`` (hindrax_msgs/SetArmed).
#: Every ``operator`` element carries a signature (hindrax_msgs/Signature) the gateway checks; the e-stop has none.
INTERFACE: tuple[Relay, ...] = (
    Relay("estop", "/supervisor/estop", "service", _TRIGGER, "anyone"),
    Relay("arm", "/esc/set_armed", "service", _SIGNED, "operator", "hindrax_msgs/srv/SetArmed"),
    Relay("disarm", "/esc/set_armed", "service", _SIGNED, "operator", "hindrax_msgs/srv/SetArmed"),
    Relay("reset", "/supervisor/reset", "service", _SIGNED, "operator", _TRIGGER),
    Relay("recorder/start", "/recorder/start", "service", "hindrax_msgs/srv/StartRecording", "operator"),
    Relay("recorder/stop", "/recorder/stop", "service", "hindrax_msgs/srv/StopRecording", "operator"),
    Relay("identification/continue", "/identification/continue", "service", _SIGNED, "operator", _TRIGGER),
    Relay("controller/hold", "/controller/hold", "service", _SIGNED, "operator", _TRIGGER),
    Relay("controller/enable", "/controller/enable", "service", "hindrax_msgs/srv/SignedSetBool", "operator",
          "std_srvs/srv/SetBool"),
    Relay("run_identification", "/run_identification", "action", "hindrax_msgs/action/RunIdentification", "operator"),
    Relay("controller/setpoint", "/controller/setpoint", "topic_in", "hindrax_msgs/msg/ControlSetpoint", "operator"),
    Relay("supervisor/status", "/supervisor/status", "topic_out", "diagnostic_msgs/msg/DiagnosticStatus", "read"),
    Relay("identification/status", "/identification/status", "topic_out", "hindrax_msgs/msg/ManeuverStatus", "read"),
    Relay("controller/status", "/controller/status", "topic_out", "hindrax_msgs/msg/ControllerStatus", "read"),
    Relay("odom", "/odom", "topic_out", "nav_msgs/msg/Odometry", "read"),
    Relay("gateway/status", "", "topic_out", "diagnostic_msgs/msg/DiagnosticStatus", "read"),
)


#: the gateway's own status under ``/<vehicle.name>/``: published by gateways only, so its publishers are the gateways
#: answering to that name (:func:`participants`)
STATUS_TOPIC = "gateway/status"


def relays(kind: str) -> tuple[Relay, ...]:
    """The entries of :data:`INTERFACE` of one ``kind``."""
    return tuple(r for r in INTERFACE if r.kind == kind)


class VehicleChoiceError(ValueError):
    """No vehicle, several, or not the one named: one line saying what was seen."""


def vehicles_seen(nodes: Iterable[tuple[str, str]]) -> list[str]:
    """Vehicle names from a graph's ``(node name, namespace)`` pairs (rclpy ``get_node_names_and_namespaces``):
    the namespaces of the nodes named :data:`GATEWAY_NODE`, sorted, without duplicates."""
    return sorted({ns.strip("/") for name, ns in nodes if name == GATEWAY_NODE and ns.strip("/")})


def choose_vehicle(seen: Iterable[str], wanted: str | None, domain: str = "this domain") -> str:
    """The vehicle a command that moves one talks to: ``wanted`` if it is among ``seen``, else the only one seen.

    Raises :class:`VehicleChoiceError` (one line naming the domain and what was seen) when ``wanted`` is not seen,
    when nothing is seen, or when several are seen and none is named."""
    seen = sorted(set(seen))
    if wanted is not None:
        if wanted in seen:
            return wanted
        others = f" (seen: {', '.join(seen)})" if seen else ""
        raise VehicleChoiceError(f"vehicle {wanted!r} not seen on {domain}{others}: is its gateway running?")
    if not seen:
        raise VehicleChoiceError(f"no vehicle on {domain}: no gateway node seen (check ROS_DOMAIN_ID and "
                                 "ROS_AUTOMATIC_DISCOVERY_RANGE, docs/deployment.md §6)")
    if len(seen) > 1:
        raise VehicleChoiceError(f"several vehicles on {domain} ({', '.join(seen)}): name one with --vehicle")
    return seen[0]


def participants(gids: Iterable[bytes]) -> list[str]:
    """The DDS participants (GUID prefix, 12 bytes, as dotted hex) of endpoints given by their gids (rclpy
    ``TopicEndpointInfo.endpoint_gid``), sorted, without duplicates."""
    return sorted({".".join(f"{b:02x}" for b in bytes(g)[:12]) for g in gids})


def duplicate_problem(vehicle: str, gateways: Iterable[str]) -> str:
    """One line when more than one gateway (participants, :func:`participants` of the publishers of
    ``/<vehicle>/`` :data:`STATUS_TOPIC`) answers to ``vehicle``, naming them; "" for one or none."""
    found = sorted(set(gateways))
    if len(found) < 2:
        return ""
    return (f"vehicle {vehicle!r} is answered by {len(found)} gateways (participants {', '.join(found)}): two vehicles "
            "share the name; give one another vehicle.name")


def extra_servers_problem(vehicle: str, count_services: Callable[[str], int]) -> str:
    """One line naming the services of ``/<vehicle>/`` (the service relays and the campaign's ``send_goal``) that
    more than one server answers on the topside, with the count; "" when each has at most one. ``count_services``:
    rclpy ``Node.count_services``. A DDS request reaches every server of its name: another server reads every request
    (harmless to a signed one, issue 71) and may answer it before the gateway."""
    names = [f"/{vehicle}/{r.topside}" for r in relays("service")]
    names += [f"/{vehicle}/{r.topside}/_action/send_goal" for r in relays("action")]
    extra = [f"{n} ({k} servers)" for n in names if (k := count_services(n)) > 1]
    if not extra:
        return ""
    return (f"another server answers {', '.join(extra)} on the topside: someone reads the operator's requests and may "
            "answer them; arming refused until it is gone")
