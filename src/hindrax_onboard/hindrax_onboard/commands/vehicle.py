"""Which vehicle a command that moves one talks to: ``--vehicle NAME``, or the only one on the domain.

A vehicle shows itself by its gateway's node, ``/<vehicle.name>/gateway`` (docs/architecture.md §8.2), on the
topside domain and on the vehicle's internal graph alike. On the topside the vehicle's interface is the gateway's
relays under ``/<name>/`` (:data:`hindrax_bringup.gateway.interface.INTERFACE`); on the internal graph (a command
run on the vehicle itself) the nodes' own names, without a namespace. :func:`find_vehicle` tells the two apart by
the gateway's topside-only node ``/<name>/gateway_operator``, refuses a name two gateways answer to, and warns (stderr)
when another server answers one of the vehicle's services (an eavesdropper, issue 71).

On the topside an operator's request is signed (:mod:`hindrax_bringup.gateway.operator_signing`) with the vehicle's key,
``<keys dir>/<name>.key`` (``hindrax keys``), when this PC has it; without it the gateway refuses the request and
says where the key goes. The e-stop is never signed."""
from __future__ import annotations

import argparse
import os
import sys
import time
from dataclasses import dataclass
from typing import Any, Callable

from .common import CommandError

__all__ = ["VEHICLE_ENV", "Target", "add_vehicle_arguments", "find_vehicle", "with_ros", "wait_for", "call_service"]

#: the environment variable naming the vehicle a topside PC commands (docker/topside.env.example): ``--vehicle``'s
#: default
VEHICLE_ENV = "HINDRAX_VEHICLE"


@dataclass(frozen=True)
class Target:
    """The vehicle a command talks to: its ``name``, whether the command is on the ``topside`` domain (through
    the gateway) or on the vehicle's internal graph, and the ``signer`` of its operator requests (topside, with the
    key on this PC; else None)."""

    name: str
    topside: bool
    signer: Any = None

    def resolve(self, topside_name: str, internal_name: str) -> str:
        """The absolute name to use: ``/<name>/<topside_name>`` on the topside, ``internal_name`` on the vehicle."""
        return f"/{self.name}/{topside_name}" if self.topside else internal_name

    def service(self, topside_name: str, internal_name: str, internal_type: Any, **fields: Any) -> tuple[Any, str, Any]:
        """(service type, absolute name, request with ``fields``) of an operator service: on the topside the
        gateway's signed type (:data:`~hindrax_bringup.gateway.interface.INTERFACE`), the request signed; on the
        vehicle ``internal_type`` and ``internal_name``."""
        if not self.topside:
            return internal_type, internal_name, internal_type.Request(**fields)
        from hindrax_bringup.gateway.interface import INTERFACE
        from hindrax_bringup.gateway.internal import interface_type

        (relay,) = [r for r in INTERFACE if r.topside == topside_name]
        srv = interface_type(relay.type)
        return srv, self.resolve(topside_name, internal_name), self.sign(topside_name, srv.Request(**fields))

    def sign(self, topside_name: str, message: Any) -> Any:
        """``message`` (with a ``signature`` field) signed for relay ``topside_name`` when there is a signer;
        returned either way."""
        if self.topside and self.signer is not None:
            self.signer.sign_message(topside_name, message)
        return message


def add_vehicle_arguments(parser: argparse.ArgumentParser) -> None:
    """``--vehicle NAME`` and ``--discovery-timeout S`` (how long to look for the vehicle)."""
    parser.add_argument("--vehicle", default=os.environ.get(VEHICLE_ENV) or None, metavar="NAME",
                        help=f"the vehicle's name (vehicle.name of its vehicle file); default: ${VEHICLE_ENV} (the "
                             "topside's settings file, docker/topside.env.example), else the only vehicle on this ROS "
                             "domain (refused when there are none or several)")
    parser.add_argument("--discovery-timeout", type=float, default=10.0, metavar="S",
                        help="how long to look for the vehicle's gateway, s (default 10)")


def find_vehicle(node: Any, executor: Any, wanted: str | None, timeout_s: float) -> Target:
    """Spin ``executor`` until a gateway (``wanted``'s, if given) is seen and discovery has settled
    (:func:`hindrax_common.process.dds_transport.wait_discovered`: every gateway running has announced itself), at most
    ``timeout_s``; then choose (:func:`hindrax_bringup.gateway.interface.choose_vehicle`). Raises
    :class:`CommandError` (one line) for no vehicle, several, not the one named, or a name two gateways answer to."""
    from hindrax_common.process.dds_transport import wait_discovered
    from hindrax_bringup.gateway.interface import (GATEWAY_NODE, STATUS_TOPIC, VehicleChoiceError, choose_vehicle,
                                                   duplicate_problem, extra_servers_problem, participants,
                                                   vehicles_seen)
    from hindrax_bringup.gateway.operator_signing import OperatorKeyError, Signer, key_path, load_key

    nodes = node.get_node_names_and_namespaces()

    def view() -> frozenset:
        nonlocal nodes
        nodes = node.get_node_names_and_namespaces()
        return frozenset(nodes)

    def ready() -> bool:
        seen = vehicles_seen(nodes)
        return bool(seen) if wanted is None else wanted in seen

    wait_discovered(view, ready, lambda: executor.spin_once(timeout_sec=0.1), cap_s=timeout_s)
    seen = vehicles_seen(nodes)
    domain = f"ROS domain {os.environ.get('ROS_DOMAIN_ID', '0')}"
    try:
        name = choose_vehicle(seen, wanted, domain)
    except VehicleChoiceError as exc:
        raise CommandError(str(exc)) from None
    topside = (GATEWAY_NODE + "_operator", "/" + name) in nodes
    if not topside:
        return Target(name, False)
    gids = [i.endpoint_gid for i in node.get_publishers_info_by_topic(f"/{name}/{STATUS_TOPIC}")]
    duplicate = duplicate_problem(name, participants(gids))
    if duplicate:
        raise CommandError(f"refusing to command it: {duplicate}")
    extra = extra_servers_problem(name, node.count_services)
    if extra:
        print(f"warning: vehicle {name!r}: {extra}", file=sys.stderr, flush=True)
    path = key_path(name)
    if not path.exists():
        return Target(name, True)
    try:
        return Target(name, True, Signer(load_key(path), name))
    except OperatorKeyError as exc:
        raise CommandError(str(exc)) from None


def with_ros(body: Callable[[Any, Any], Any], node_name: str) -> Any:
    """Run ``body(node, executor)`` with a node ``node_name`` in a context of its own (SIGINT left to the caller);
    shut everything down after it. Returns what ``body`` returns."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

    context = rclpy.Context()
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node(node_name, context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    try:
        return body(node, executor)
    finally:
        executor.shutdown()
        node.destroy_node()
        context.try_shutdown()


_HEALTH = "check with hindrax health on the vehicle"


def wait_for(executor: Any, done: Callable[[], Any], timeout_s: float, what: str, hint: str = _HEALTH) -> None:
    """Spin ``executor`` until ``done()`` is true. Raises :class:`CommandError` ``"<what> within
    <timeout_s> s (<hint>)"`` when it is not within ``timeout_s`` (wall time)."""
    deadline = time.monotonic() + timeout_s
    while not done():
        if time.monotonic() > deadline:
            raise CommandError(f"{what} within {timeout_s:g} s ({hint})")
        executor.spin_once(timeout_sec=0.05)


def call_service(node: Any, executor: Any, spec: tuple[Any, str, Any], timeout_s: float,
                 hint: str = _HEALTH, answer_hint: str | None = None) -> Any:
    """The answer of one call ``spec`` = (service type, name, request) (:meth:`Target.service`) from
    ``node``, spun by ``executor``. Raises :class:`CommandError` naming the service when it is not
    there (``hint``) or does not answer (``answer_hint``, default ``hint``) within ``timeout_s``
    each (wall), and when more than one server answers ``name`` before or after the call: a DDS
    request reaches every server of its name and the client takes the first answer, which may be
    another server's, not the vehicle's (docs/threat_model.md §3); the request went out, but the
    answer is not reported as the vehicle's."""
    srv_type, name, request = spec
    client = node.create_client(srv_type, name)
    wait_for(executor, client.service_is_ready, timeout_s, f"no {name} service", hint)
    servers = node.count_services(name)
    future = client.call_async(request)
    wait_for(executor, future.done, timeout_s, f"{name} did not answer", answer_hint or hint)
    servers = max(servers, node.count_services(name))
    refuse_shared_answer(name, servers, "it", "answer", "request", hint)
    return future.result()


def refuse_shared_answer(name: str, servers: int, answered: str, answer: str, request: str,
                         hint: str) -> None:
    """Raises :class:`CommandError` when ``servers`` (more than one) answer ``name``: a DDS
    request or goal reaches every server of its name and the client takes the first answer,
    which may be another server's, not the vehicle's (docs/threat_model.md §3); the ``request``
    went out, so its outcome is unknown. ``answered`` names what they answer ("it", "its
    goals"), ``answer`` what was taken ("answer", "acceptance"); ``hint``: where to look next."""
    if servers > 1:
        raise CommandError(f"{name}: {servers} servers answer {answered}, so this {answer} may not "
                           f"be the vehicle's: the {request} was sent, its outcome is unknown "
                           f"({hint})")
