"""What on a ROS graph speaks for a vehicle: the topics that command or vouch for it, and the processes that are it.

The project's tools must never speak for a vehicle they were not started as (docs/architecture.md, "Authority"): a
replayed ``supervisor/heartbeat`` would answer for a dead supervisor, a replayed ``wrench`` would drive the thrusters, a
second ``bringup --sim`` on the vehicle's domain would mix its ESC and supervisor into the vehicle's safety graph.

- :func:`vehicle_topic_reason` / :func:`split_vehicle_topics` (pure): the safety and actuation topics (heartbeats,
  ``thrusters/*``, ``esc/*``, ``supervisor/*``, ``guard/*``, ``output_guard/*``, ``wrench``, ``setpoint``, action and
  service topics) in any namespace; ``hindrax bag play`` withholds them unless asked with ``--safety-topics``.
- :func:`foreign_vehicle_processes` (pure): the ESCs and supervisors a graph shows beyond the
  caller's own, each as one phrase naming the node.
- :func:`graph_view`, :func:`own_view`, :class:`ForeignVehicleWatch` (over a discovery window, then every
  :data:`CHECK_PERIOD_S`; raises :class:`ForeignVehicleError`) and :func:`refuse_before_start` (from a bare look-out
  node before a tool creates anything: its heartbeat publishers, even for a second, would disarm the vehicle's ESC).
- :func:`refuse_live_peer`: the same look-out for a vehicle's own ESC or supervisor process at its start: another
  one's heartbeat arriving is a second vehicle on the domain (issue 74.2)."""
from __future__ import annotations

import re
import threading
import time
from collections import Counter
from dataclasses import dataclass, field
from typing import Any, Callable, Iterable, Mapping

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter

from hindrax_msgs.msg import Heartbeat

from ..process.dds_transport import DISCOVERY_BOUND_S, UNNAMED_NODE, wait_discovered
from .liveness import HEARTBEAT_LEASE_S, HEARTBEAT_NAMES, heartbeat_qos

__all__ = ["CHECK_PERIOD_S", "DISCOVERY_WINDOW_S", "HEARTBEAT_TOPICS", "ROLE_NODES", "ForeignVehicleError",
           "ForeignVehicleWatch", "GraphView", "foreign_vehicle_processes", "graph_view", "own_view",
           "refuse_before_start", "refuse_live_peer", "split_vehicle_topics", "vehicle_topic_reason"]

#: (pattern matched with ``re.search`` against the full topic name, why the topic speaks for the vehicle); the first
#: match gives the reason
_VEHICLE_TOPIC_RULES: tuple[tuple[re.Pattern, str], ...] = tuple((re.compile(p), why) for p, why in (
    (r"(^|/)heartbeat$", "a heartbeat: a replayed one answers for a process that may be dead"),
    (r"(^|/)(thrusters|esc)(/|$)", "the thruster output"),
    (r"(^|/)(supervisor|guard|output_guard)(/|$)", "the safety supervisor's or the output guard's"),
    (r"(^|/)controller/setpoint$", "a controller setpoint"),
    (r"(?<!/sim)/wrench$|^wrench$", "the wrench the thrust allocation drives the thrusters from"),
    (r"/_action/", "an action's goals, feedback or status"),
    (r"^/?r[qr]/", "a service request or reply"),
))

#: node name (any namespace) -> the role it plays in the vehicle's safety graph
ROLE_NODES = {"esc": "ESC", "supervisor": "supervisor"}
#: heartbeat topic (relative name, any namespace) -> role of its one legitimate publisher
HEARTBEAT_TOPICS = {"esc/heartbeat": "ESC", "supervisor/heartbeat": "supervisor"}
#: how long a new participant watches the graph before it trusts that no other ESC or supervisor is there, s: three
#: announcement periods of the vehicle's profile (:data:`~hindrax_common.process.dds_transport.DISCOVERY_BOUND_S`)
DISCOVERY_WINDOW_S = DISCOVERY_BOUND_S
#: how often a running tool looks again after the discovery window (:meth:`ForeignVehicleWatch.check_every`), s:
#: discovery on a loaded machine can outlast the window, and a second vehicle graph may start later
CHECK_PERIOD_S = 1.0


def vehicle_topic_reason(topic: str) -> str | None:
    """Why ``topic`` (full or relative name) speaks for the vehicle, or None for a topic a bag may replay freely
    (sensor data, status, /tf_static, /clock, /diagnostics, the simulator's ``sim/*``)."""
    name = topic if topic.startswith("/") else "/" + topic
    for pattern, why in _VEHICLE_TOPIC_RULES:
        if pattern.search(name):
            return why
    return None


def split_vehicle_topics(topics: Iterable[str]) -> tuple[list[str], dict[str, str]]:
    """(topics that may be replayed, {withheld topic: reason}) in the order given."""
    free: list[str] = []
    withheld: dict[str, str] = {}
    for t in topics:
        why = vehicle_topic_reason(t)
        if why is None:
            free.append(t)
        else:
            withheld[t] = why
    return free, withheld


@dataclass(frozen=True)
class GraphView:
    """What a participant sees: ``nodes`` (fully qualified names, duplicates kept: two processes may carry the same
    name) and ``heartbeat_publishers`` ({full heartbeat topic: fully qualified names of its publishers' nodes})."""

    nodes: tuple[str, ...] = ()
    heartbeat_publishers: Mapping[str, tuple[str, ...]] = field(default_factory=dict)


def _fq(name: str, namespace: str) -> str:
    return f"{namespace.rstrip('/')}/{name}" if namespace not in ("", "/") else f"/{name}"


def _role_of_node(fq_name: str) -> str | None:
    return ROLE_NODES.get(fq_name.rsplit("/", 1)[-1])


def _role_of_topic(topic: str) -> str | None:
    for rel, role in HEARTBEAT_TOPICS.items():
        if topic == "/" + rel or topic.endswith("/" + rel):
            return role
    return None


def foreign_vehicle_processes(seen: GraphView, own: GraphView = GraphView()) -> list[str]:
    """The ESCs and supervisors ``seen`` shows beyond ``own`` (the caller's own nodes and heartbeat publishers), one
    phrase each, e.g. ``"supervisor /supervisor"`` or ``"ESC heartbeat publisher /forger on /esc/heartbeat"``.

    A node counts by its name (``esc``, ``supervisor``, in any namespace); a node of another name counts when it
    publishes an ESC or supervisor heartbeat topic. Names are counted as a multiset, so a second process with the
    caller's own node name is found. Empty: nothing foreign."""
    extra_nodes = Counter(n for n in seen.nodes if _role_of_node(n)) - Counter(n for n in own.nodes if _role_of_node(n))
    found = [f"{_role_of_node(n)} {n}" for n in sorted(extra_nodes.elements())]
    named = set(extra_nodes)
    for topic in sorted(seen.heartbeat_publishers):
        role = _role_of_topic(topic)
        if role is None:
            continue
        extra = Counter(seen.heartbeat_publishers[topic]) - Counter(own.heartbeat_publishers.get(topic, ()))
        for n in sorted(extra.elements()):
            if n not in named:
                found.append(f"{role} heartbeat publisher {n} on {topic}")
                named.add(n)
    return found


def own_view(nodes: Iterable[Any]) -> GraphView:
    """The :class:`GraphView` of the caller's own rclpy ``nodes``: their names and the heartbeat topics they
    publish, to subtract from what the graph shows."""
    nodes = list(nodes)
    names = tuple(n.get_fully_qualified_name() for n in nodes)
    pubs: dict[str, list[str]] = {}
    for n in nodes:
        for p in n.publishers:
            if _role_of_topic(p.topic_name) is not None:
                pubs.setdefault(p.topic_name, []).append(n.get_fully_qualified_name())
    return GraphView(names, {t: tuple(v) for t, v in pubs.items()})


def graph_view(node: Any) -> GraphView:
    """The graph as ``node`` (an rclpy node) sees it now: node names and the publishers of every ESC or supervisor
    heartbeat topic in any namespace."""
    nodes = tuple(_fq(n, ns) for n, ns in node.get_node_names_and_namespaces())
    pubs: dict[str, tuple[str, ...]] = {}
    for topic, _types in node.get_topic_names_and_types():
        if _role_of_topic(topic) is not None:
            # an endpoint seen before its participant's node names arrives as _NODE_NAME_UNKNOWN_: left out until
            # it can be named (one discovery round later)
            pubs[topic] = tuple(_fq(i.node_name, i.node_namespace) for i in node.get_publishers_info_by_topic(topic)
                                if i.node_name != UNNAMED_NODE)
    return GraphView(nodes, pubs)


class ForeignVehicleError(RuntimeError):
    """Another vehicle's ESC or supervisor is on the domain (message is one line naming it)."""


class ForeignVehicleWatch:
    """Watches ``node``'s graph for ESCs and supervisors that are not the caller's: through the discovery window
    (:meth:`settled`), then every ``period_s`` while the tool runs (:meth:`check_every` for a spun node,
    :meth:`poll` for a loop of its own).

    node: an rclpy node on the domain to check. own: callable returning the caller's own :class:`GraphView` (its
    nodes and heartbeat publishers; default nothing). what: the refusing tool, for the message (``hindrax run``).
    consequence: what the tool refuses to do. window_s: :data:`DISCOVERY_WINDOW_S`. period_s:
    :data:`CHECK_PERIOD_S`. clock: monotonic seconds."""

    def __init__(self, node: Any, what: str, consequence: str, own: Callable[[], GraphView] = GraphView,
                 window_s: float = DISCOVERY_WINDOW_S, period_s: float = CHECK_PERIOD_S,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.node = node
        self.what = what
        self.consequence = consequence
        self.own = own
        self.window_s = float(window_s)
        self.period_s = float(period_s)
        self.clock = clock
        self.t0 = clock()
        self._next_poll = self.t0

    def found(self) -> list[str]:
        """The foreign ESCs and supervisors seen now (:func:`foreign_vehicle_processes`)."""
        return foreign_vehicle_processes(graph_view(self.node), self.own())

    def check(self) -> None:
        """Raise :class:`ForeignVehicleError` when a foreign ESC or supervisor is visible now."""
        found = Counter(self.found())  # one phrase per process: two processes named /esc give it twice
        if found:
            domain = self.node.context.get_domain_id()
            named = ", ".join(p if n == 1 else f"{p} ({n} processes)" for p, n in found.items())
            raise ForeignVehicleError(f"{self.what}: ROS domain {domain} already has {named}; {self.consequence}")

    def settled(self) -> bool:
        """:meth:`check`, then True once the discovery window has passed since construction (nothing foreign seen
        through it). Poll it, e.g. as a ``wait_until`` predicate."""
        self.check()
        return self.clock() - self.t0 >= self.window_s

    def check_every(self) -> Any:
        """Keep checking after the window for as long as ``node`` is spun: a timer of ``period_s`` (the node's clock)
        running :meth:`check`, so a foreign ESC or supervisor discovered later raises :class:`ForeignVehicleError` out
        of the executor's spin, the same one line. Returns the rclpy timer (it goes with the node)."""
        return self.node.create_timer(self.period_s, self.check)

    def poll(self) -> None:
        """:meth:`check` when ``period_s`` has passed (``clock``) since the last poll's check: cheap enough to call
        from a loop of the tool's own at every turn (``hindrax bag play`` between messages)."""
        now = self.clock()
        if now >= self._next_poll:
            self._next_poll = now + self.period_s
            self.check()


def refuse_before_start(context: Any, consequence: str, what: str = "refused",
                        window_s: float = DISCOVERY_WINDOW_S) -> None:
    """Watch the domain of ``context`` (an initialised rclpy Context, None: the default one) through the discovery
    window from a bare look-out node (no publisher, no service, no rosout), then destroy it; raise
    :class:`ForeignVehicleError` (:meth:`ForeignVehicleWatch.check`'s line) as soon as an ESC or supervisor is seen.
    Call it before the tool creates any node or publisher of its own: the look-out is one more participant, which
    the vehicle ignores, where a tool's heartbeat publishers would disarm it. The caller's own watch afterwards
    (``window_s=0``) keeps checking while it runs."""
    lookout = rclpy.create_node("vehicle_graph_check", context=context, enable_rosout=False,
                                start_parameter_services=False,
                                parameter_overrides=[Parameter("start_type_description_service", value=False)])
    try:
        watch = ForeignVehicleWatch(lookout, what, consequence, window_s=window_s)
        pause = threading.Event()

        def ready() -> bool:
            settled = watch.settled()  # a named ESC or supervisor: its line
            if settled:  # names lag behind endpoints: an unnamed heartbeat publisher refuses too
                _refuse_heartbeat_endpoint(lookout, watch)
            return settled
        # past the window, wait on while discovery is still bringing nodes or topics in (a loaded machine), up to a cap
        wait_discovered(lambda: (len(lookout.get_node_names_and_namespaces()),
                                 len(lookout.get_topic_names_and_types())),
                        ready, lambda: pause.wait(0.05), bound_s=window_s)
    finally:
        lookout.destroy_node()


def _refuse_heartbeat_endpoint(lookout: Any, watch: ForeignVehicleWatch) -> None:
    """Raise :class:`ForeignVehicleError` when any publisher of a safety heartbeat is on the domain, its node named
    or not yet: the look-out has none of its own, and rmw knows an endpoint before its node's name arrives."""
    for name, _types in lookout.get_topic_names_and_types():
        role = _role_of_topic(name)
        if role is not None and lookout.count_publishers(name) > 0:
            domain = lookout.context.get_domain_id()
            raise ForeignVehicleError(f"{watch.what}: ROS domain {domain} already has a publisher of {name} "
                                      f"({role}); {watch.consequence}")


def refuse_live_peer(kind: str, consequence: str, window_s: float = DISCOVERY_WINDOW_S) -> None:
    """At the start of a vehicle's ESC or supervisor process (``kind`` ``"esc"`` or ``"supervisor"``, a key of
    :data:`~hindrax_common.node_support.liveness.HEARTBEAT_NAMES`), before its node exists: watch the default
    context's domain from a bare look-out node with one subscription to that heartbeat, through the discovery window
    and while discovery still changes (:func:`~hindrax_common.process.dds_transport.wait_discovered`), and for one
    heartbeat lease
    (:data:`~hindrax_common.node_support.liveness.HEARTBEAT_LEASE_S`) after a publisher of it appears. Raises
    :class:`ForeignVehicleError` ``"<kind>: ROS domain N already has a live <kind> (<its node>, heartbeat on
    <topic>); <consequence>"`` when a beat arrives: another vehicle's live one. A publisher whose beats do not arrive
    (a killed predecessor, on the graph until its participant's lease ends) does not refuse: a respawn starts."""
    topic = "/" + HEARTBEAT_NAMES[kind]
    lookout = rclpy.create_node(f"{kind}_start_check", enable_rosout=False, start_parameter_services=False,
                                use_global_arguments=False,
                                parameter_overrides=[Parameter("start_type_description_service", value=False)])
    executor = SingleThreadedExecutor(context=lookout.context)
    executor.add_node(lookout)
    beats: list = []
    lookout.create_subscription(Heartbeat, topic, beats.append, heartbeat_qos())
    first_seen: list[float] = []
    try:
        def ready(last: bool = False) -> bool:
            if lookout.count_publishers(topic) and not first_seen:
                first_seen.append(time.monotonic())
            waited = bool(first_seen) and time.monotonic() - first_seen[0] >= HEARTBEAT_LEASE_S
            if beats:  # its node's name follows its endpoint: named when it came within the lease, else "unnamed"
                named = sorted({i.node_name for i in lookout.get_publishers_info_by_topic(topic)} - {UNNAMED_NODE})
                if named or waited or last:
                    raise ForeignVehicleError(f"{kind}: ROS domain {lookout.context.get_domain_id()} already has a "
                                              f"live {kind} ({', '.join(named) or 'unnamed'}, heartbeat on {topic}); "
                                              f"{consequence}")
            return not first_seen or waited
        wait_discovered(lambda: (len(lookout.get_node_names_and_namespaces()), lookout.count_publishers(topic)),
                        ready, lambda: executor.spin_once(timeout_sec=0.05), bound_s=window_s)
        ready(last=True)  # a beat in the last spin
    finally:
        executor.shutdown()
        lookout.destroy_node()
