"""Heartbeats of the safety nodes: their identity, their ages, and ROS-time step detection (docs/architecture.md §8).

The pieces every safety node (ESC, output guard, supervisor) shares:

* :class:`HeartbeatPublisher`: a node's heartbeat (``hindrax_msgs/Heartbeat``) with ``boot_id`` (random, non-zero, new
  at every node start) and ``seq`` (1, 2, 3 ... per beat), which make it hard to take for another process's.
* :class:`HeartbeatIdentity`: the pure check a receiver runs on the topic's publishers and every
  beat (a forger, a replayed bag); a beat it rejects does not count as the peer being alive.
* :class:`HeartbeatWatch`: the receiver's subscription, taking the beats as bytes
  (:func:`hindrax_common.cdr.lean_cdr.read_heartbeat`). Heartbeats use :func:`heartbeat_qos`: AUTOMATIC
  liveliness with a :data:`HEARTBEAT_LEASE_S` lease, so the liveliness event counts the *live*
  publishers (a SIGKILLed process's endpoints stay in the graph until its participant lease runs
  out, 20 s with Fast DDS's default). A writer offering a longer lease does not match at all.
* :class:`PublisherNames`: the node names of a topic's publishers, asked of the graph only when DDS says something
  changed (matched, liveliness, incompatible-QoS and incompatible-type events), for :data:`SETTLE_S` after such an
  event, while a publisher is still unnamed, and every :data:`BACKSTOP_S`.

On simulated time (``use_sim_time``, :func:`simulated_now_s`) the DDS lease, on the wall clock, cannot silence a peer (a
process starved on a loaded machine would lose it although nothing was late on the graph's clock): "no live publisher"
then needs no publisher in the graph at all (:meth:`HeartbeatIdentity.on_publishers`, ``simulated``), the other identity
checks stay, and a dead or frozen peer is caught by its :class:`AliveAge`. The QoS is the same in both modes.

* :class:`AliveAge`: a peer's age on ``time.monotonic`` from its beat, over the time this process's executor ran (a gap
  between two :meth:`AliveAge.tick` calls counts at most ``max_step_s``), so this process's own stall does not make
  every peer look dead. On simulated time the age is also counted on the graph's clock and the smaller count holds: a
  slow or held simulation ages no peer, and the beats, paced by steady timers, are not made late by a fast one.
* :class:`ClockStepMonitor`: reports a backward step of ROS time against the steady clock
  (``/clock`` restarted, a bag looped) and a stall (ROS time frozen while the steady clock runs), so
  a node can re-base its ROS-time checks and say so on ``/diagnostics``."""
from __future__ import annotations

import math
import secrets
import time
from dataclasses import dataclass
from typing import Any, Callable, Sequence

from rclpy.duration import Duration
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.expand_topic_name import expand_topic_name
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.qos import LivelinessPolicy, QoSProfile
from rclpy.validate_full_topic_name import validate_full_topic_name

from hindrax_msgs.msg import Heartbeat

from ..cdr.lean_cdr import heartbeat_cdr, read_heartbeat
from ..process.dds_transport import UNNAMED_NODE

__all__ = ["AliveAge", "BACKSTOP_S", "ClockStepMonitor", "HEARTBEAT_LEASE_S", "HEARTBEAT_NAMES", "HEARTBEAT_NODES",
           "HeartbeatIdentity", "HeartbeatPublisher", "HeartbeatWatch", "PublisherNames", "SETTLE_S", "TickGaps",
           "heartbeat_ok", "heartbeat_qos", "new_boot_id", "publisher_node_names", "simulated_now_s"]

#: heartbeat topics (hindrax_msgs/Heartbeat: level OK = healthy, ERROR = tripped/asserted + reason)
HEARTBEAT_NAMES = {"supervisor": "supervisor/heartbeat", "guard": "guard/heartbeat", "esc": "esc/heartbeat"}
#: the one node allowed to publish each heartbeat (internal graph names, docs/architecture.md §8)
HEARTBEAT_NODES = {"supervisor": "supervisor", "guard": "output_guard", "esc": "esc"}
#: DDS liveliness lease of the heartbeat writers and readers, s (module docstring): how long a dead publisher still
#: counts as live; the heartbeat ages (``esc.heartbeat_timeout_s``, ``esc.guard_heartbeat_timeout_s``: 0.2 s) stop
#: the outputs long before
HEARTBEAT_LEASE_S = 1.0
#: :class:`PublisherNames` asks the graph at every check for this long after a DDS event, s: an endpoint and its node
#: name reach the graph by discovery traffic of their own, not in step with the DDS match that raised the event
SETTLE_S = 0.5
#: and at least this often without an event, s (a change no event reports: rmw_fastrtps raises no incompatible-type
#: event here, so a publisher of another type, whose beats never arrive, is named within this)
BACKSTOP_S = 1.0


def heartbeat_qos() -> Any:
    """The heartbeats' QoS (publishers and subscriptions): reliable, keep last 10, volatile, AUTOMATIC liveliness
    with a :data:`HEARTBEAT_LEASE_S` lease (module docstring)."""
    return QoSProfile(depth=10, liveliness=LivelinessPolicy.AUTOMATIC,
                      liveliness_lease_duration=Duration(seconds=HEARTBEAT_LEASE_S))


def simulated_now_s(node: Any) -> float | None:
    """``node``'s ROS time, s, when its clock runs on simulated time (``use_sim_time``: set by ``/clock`` or by a
    simulator driving it), else None (the system clock: the vehicle)."""
    clock = node.get_clock()
    return clock.now().nanoseconds * 1e-9 if getattr(clock, "ros_time_is_active", False) else None


def publisher_node_names(node: Any, topic: str) -> list[str]:
    """Node names of the publishers of ``topic`` that ``node``'s graph shows: what ``[i.node_name for i in
    node.get_publishers_info_by_topic(topic)]`` gives (the same rcl query, the topic expanded, validated and
    remapped as rclpy does, once per node and topic), without the ``TopicEndpointInfo`` and ``QoSProfile`` objects
    rclpy builds per endpoint, which the safety ticks never read: 19 us instead of 51 us a call with two publishers
    here (:class:`PublisherNames` says when it is asked). Raises as ``get_publishers_info_by_topic`` for an
    invalid topic name. Uses rclpy's own binding (``rclpy.impl.implementation_singleton``), as its ``Node`` does."""
    resolved = node.__dict__.setdefault("_hindrax_resolved_topics", {})
    fq = resolved.get(topic)
    if fq is None:
        fq = expand_topic_name(topic, node.get_name(), node.get_namespace())
        validate_full_topic_name(fq)
        with node.handle:
            fq = resolved[topic] = _rclpy.rclpy_remap_topic_name(node.handle, fq)
    with node.handle:
        return [info["node_name"] for info in _rclpy.rclpy_get_publishers_info_by_topic(node.handle, fq, False)]


def new_boot_id() -> int:
    """A heartbeat's per-start value: 64 random bits from :mod:`secrets`, never 0 (0 means "none")."""
    return secrets.randbits(64) or 1


class HeartbeatPublisher:
    """One node's heartbeat (``hindrax_msgs/Heartbeat`` on ``HEARTBEAT_NAMES[kind]``) carrying ``boot_id`` and ``seq``
    (module docstring), published as CDR bytes (:func:`hindrax_common.cdr.lean_cdr.heartbeat_cdr`: no rclpy object per
    beat).

    ``node``: the publishing rclpy node (it must be named ``HEARTBEAT_NODES[kind]`` for receivers to accept it); the
    QoS is :func:`heartbeat_qos`; keyword arguments go to ``create_publisher``.
    :attr:`boot_id` is new for every instance (a node re-created in the same process is a new start)."""

    def __init__(self, node: Any, kind: str, **publisher_kwargs: Any) -> None:
        self.topic = HEARTBEAT_NAMES[kind]
        self.boot_id = new_boot_id()
        self.seq = 0
        self.publisher = node.create_publisher(Heartbeat, self.topic, heartbeat_qos(), **publisher_kwargs)

    def publish(self, ok: bool, message: str, output_state: int = 0, armed: bool = False, guard_ack: tuple[int, int]
                = (0, 0)) -> None:
        """Publish one beat: ``ok`` (level OK, else ERROR), ``message`` (one line); the ESC's fields
        ``output_state``, ``armed`` and ``guard_ack`` (the guard beat it handled last: boot_id, seq)."""
        self.seq += 1
        self.publisher.publish(heartbeat_cdr(self.boot_id, self.seq, time.monotonic_ns(),
                                             Heartbeat.OK if ok else Heartbeat.ERROR, message, int(output_state),
                                             bool(armed), *guard_ack))


@dataclass
class HeartbeatIdentity:
    """Is a peer's heartbeat really the peer's? Pure (no ROS, no clock): the receiver feeds it the publishers it sees
    on the topic (:meth:`on_publishers`, node names from ``get_publishers_info_by_topic``) and every beat
    (:meth:`on_beat`, with its own armed state). :attr:`fault` is '' or the reason, naming the topic.

    Faults: a number of live publishers other than one (a forger or a bag player beside the peer; none), a publisher
    with another node name, a publisher not named yet (:data:`UNNAMED_NODE`, seen before its participant's node names
    arrived: no evidence of a forger, but not trusted until discovery names it), a beat that is not a Heartbeat or has
    ``boot_id`` or ``seq`` 0, a ``seq`` not greater than the last accepted one of the same ``boot_id`` (a replay or a
    repeat), a ``boot_id`` change while armed (a forger or a replay of another boot taking over a dead peer's topic).
    The publisher faults hold while the graph shows them; a beat fault holds until a beat is accepted while not armed
    (while armed, it stays until the receiver has disarmed). A new ``boot_id`` while not armed is a restart of the
    peer: its sequence starts again."""

    topic: str
    node_name: str
    boot_id: int | None = None
    seq: int | None = None
    publisher_fault: str = ""
    beat_fault: str = ""
    rejected: int = 0

    @property
    def fault(self) -> str:
        """'' when the peer's heartbeat can be trusted, else why not (publisher faults first)."""
        return self.publisher_fault or self.beat_fault

    def on_publishers(self, node_names: Sequence[str], alive: int | None = None, simulated: bool = False) -> str:
        """The node names of every publisher the graph shows on :attr:`topic`, and how many of them are live (the
        subscription's liveliness ``alive_count``; None: count the names). ``simulated``: the receiver's graph runs
        on simulated time, where the wall-clock lease behind ``alive`` cannot make the topic silent (module
        docstring): "no live publisher" then needs no publisher among ``node_names``; ``alive`` still decides
        "more than one" (a dead duplicate stops counting after its lease in both modes). Returns :attr:`fault`."""
        names = sorted(node_names)
        count = len(names) if alive is None else int(alive)
        strangers = sorted({n for n in names if n not in (self.node_name, UNNAMED_NODE)})
        if strangers:
            self.publisher_fault = (f"{self.topic} published by node {', '.join(map(repr, strangers))}, only "
                                    f"{self.node_name!r} may publish it: a forged or replayed heartbeat")
        elif count > 1:
            self.publisher_fault = (f"{count} live publishers on {self.topic}, only one {self.node_name!r} may "
                                    "publish it: a forged or replayed heartbeat")
        elif UNNAMED_NODE in names:
            self.publisher_fault = (f"{self.topic} publisher not identified yet (discovery has not named its node): "
                                    f"trusted once the graph names it {self.node_name!r}")
        elif count < 1 and not (simulated and names):
            self.publisher_fault = f"no live publisher on {self.topic}"
        else:
            self.publisher_fault = ""
        return self.fault

    def on_beat(self, beat: Any, armed: bool) -> bool:
        """One beat (a :class:`~hindrax_common.cdr.lean_cdr.Beat` or an rclpy ``Heartbeat``; None: bytes that are not
        one); ``armed``: the receiver's (or the vehicle's) armed state. True when the beat is accepted (the peer
        counts as heard), False when it is rejected (:attr:`beat_fault` says why, :attr:`rejected` counts it)."""
        boot_id, seq = (0, 0) if beat is None else (beat.boot_id, beat.seq)
        fault = ""
        if not boot_id or not seq:
            fault = f"{self.topic} beat without boot_id/seq: not from a {self.node_name} of this stack"
        elif self.boot_id is not None and boot_id != self.boot_id:
            if armed:
                fault = (f"{self.topic} boot_id changed from {self.boot_id:016x} to {boot_id:016x} while armed: "
                         f"{self.node_name} restarted or another process publishes it")
        elif self.seq is not None and seq <= self.seq:
            fault = (f"{self.topic} seq {seq} after {self.seq}: " +
                     ("repeated" if seq == self.seq else "went back") + " (a replayed or duplicated heartbeat)")
        if fault:
            self.beat_fault = fault
            self.rejected += 1
            return False
        self.boot_id, self.seq = boot_id, seq
        if not armed:
            self.beat_fault = ""
        return True


def heartbeat_ok(msg: Any) -> bool:
    """Whether a heartbeat (a :class:`~hindrax_common.cdr.lean_cdr.Beat` or an rclpy ``Heartbeat``) says OK (level
    0); any other level or type is not OK."""
    level = msg.level
    return isinstance(level, int) and not isinstance(level, bool) and level == Heartbeat.OK


class PublisherNames:
    """The node names of ``topic``'s publishers as ``node``'s graph shows them (:func:`publisher_node_names`), asked
    only when they may have changed (module docstring): :meth:`changed` is the subscription's event callback (any
    of its DDS events), :meth:`names` answers at a tick. ``clock``: steady time, s."""

    def __init__(self, node: Any, topic: str, clock: Callable[[], float] = time.monotonic) -> None:
        self.node, self.topic, self._clock = node, topic, clock
        self._names: list[str] = []
        self._asked_s = self._event_s = -math.inf
        #: graph queries made (the benches count them)
        self.queries = 0

    def changed(self, _info: Any = None) -> None:
        """A DDS event on the topic's subscription (matched, liveliness, incompatible QoS or type)."""
        self._event_s = self._clock()

    def names(self) -> list[str]:
        """The publishers' node names, from the graph when due, else as last asked."""
        now = self._clock()
        if (now - self._event_s <= SETTLE_S or now - self._asked_s >= BACKSTOP_S or UNNAMED_NODE in self._names):
            self._names = publisher_node_names(self.node, self.topic)
            self._asked_s = now
            self.queries += 1
        return self._names

    def event_callbacks(self, **others: Callable[[Any], None]) -> SubscriptionEventCallbacks:
        """Subscription event callbacks that call :meth:`changed` on every graph-related event; ``others`` (e.g.
        ``liveliness=f``) are called too."""
        def both(name: str) -> Callable[[Any], None]:
            extra = others.get(name)
            if extra is None:
                return self.changed
            return lambda info: (extra(info), self.changed(info))
        return SubscriptionEventCallbacks(**{k: both(k) for k in
                                             ("matched", "liveliness", "incompatible_qos", "incompatible_type")})


class HeartbeatWatch:
    """A receiver's subscription to a peer's heartbeat through its :class:`HeartbeatIdentity` (module docstring).

    ``node``: the receiving rclpy node; ``kind``: a key of :data:`HEARTBEAT_NAMES`; ``handler(beat)``: called with
    every accepted beat (a :class:`~hindrax_common.cdr.lean_cdr.Beat`) only; ``armed()``: the receiver's armed state
    for the check. Call :meth:`check` at the receiver's tick (the graph asked only when due, :class:`PublisherNames`):
    it returns :attr:`identity`'s fault ('' when trusted), judged for the receiver's clock at that moment (module
    docstring: on simulated time the lease does not silence a peer). Rejected beats are counted in :attr:`identity`."""

    def __init__(self, node: Any, kind: str, handler: Callable[[Any], None], armed: Callable[[], bool]) -> None:
        self.node, self.handler, self.armed = node, handler, armed
        self.identity = HeartbeatIdentity(HEARTBEAT_NAMES[kind], HEARTBEAT_NODES[kind])
        #: live publishers (the subscription's liveliness ``alive_count``; 0 until the first event)
        self.alive = 0
        #: beats taken at a stale judgement rather than by the executor (:meth:`fresh`)
        self.taken_late = 0
        self.publishers = PublisherNames(node, self.identity.topic)
        self.subscription = node.create_subscription(
            Heartbeat, self.identity.topic, self._on_beat, heartbeat_qos(), raw=True,
            event_callbacks=self.publishers.event_callbacks(liveliness=self._on_liveliness))

    def _on_liveliness(self, info: Any) -> None:
        self.alive = int(info.alive_count)

    def _on_beat(self, data: bytes) -> Any:
        beat = read_heartbeat(data)
        if self.identity.on_beat(beat, bool(self.armed())):
            self.handler(beat)
            return beat
        return None

    def check(self) -> str:
        """Feed the publishers the graph shows and the live count to the identity check; returns its fault."""
        return self.identity.on_publishers(self.publishers.names(), self.alive, simulated_now_s(self.node) is not None)

    def fresh(self, age: AliveAge, timeout_s: float) -> bool:
        """Whether ``age`` (just ticked) is within ``timeout_s``; if not, the waiting beats (a starved process's timer
        ran first) are taken through the same check and handler, the newest aged from its send stamp (``steady_ns``,
        this host's ``time.monotonic``): a dead peer is not made younger. :attr:`taken_late` counts them."""
        if not age.fresh(timeout_s):
            newest = None
            while (taken := self.subscription.handle.take_message(Heartbeat, True)) is not None:
                self.taken_late += 1
                newest = self._on_beat(taken[0]) or newest
            if newest is not None:
                age.heard(time.monotonic() - newest.steady_ns * 1e-9)
        return age.fresh(timeout_s)


class AliveAge:
    """Age of the last message from a peer, s, in executor-alive steady time and, on simulated time, on the graph's
    clock too (module docstring).

    ``max_step_s``: the most one tick-to-tick gap may add (two tick periods is the usual choice).
    ``graph_now_s()``: the receiver's simulated time, s, or None on the system clock (:func:`simulated_now_s`);
    when it gives a time at both the beat and the tick, :attr:`age_s` is the smaller of the steady age and the
    simulated time since the beat (a backward step of simulated time restarts that count from the step).
    ``age_s`` is ``math.inf`` until the peer is first heard."""

    def __init__(self, max_step_s: float, clock: Callable[[], float] = time.monotonic,
                 graph_now_s: Callable[[], float | None] = lambda: None) -> None:
        self.max_step_s = float(max_step_s)
        self._clock = clock
        self._graph_now_s = graph_now_s
        self._last_tick = clock()
        #: the steady (executor-alive) age, s
        self.steady_age_s = math.inf
        #: simulated time of the last beat, s (None: on the system clock, or not heard since it became simulated)
        self._heard_graph_s: float | None = None
        self.age_s = math.inf

    def heard(self, ago_s: float = 0.0) -> None:
        """The peer spoke ``ago_s`` s ago (0: now); the next tick counts from now, not the last."""
        ago = max(0.0, float(ago_s))
        graph = self._graph_now_s()
        self._heard_graph_s = None if graph is None else graph - ago
        self.steady_age_s = self.age_s = ago
        self._last_tick = self._clock()

    def tick(self) -> float:
        """Advance by the (capped) time since the previous tick; returns the age, s."""
        t = self._clock()
        gap, self._last_tick = t - self._last_tick, t
        if math.isfinite(self.steady_age_s):
            self.steady_age_s += min(max(gap, 0.0), self.max_step_s)
        self.age_s = self.steady_age_s
        graph = self._graph_now_s() if self._heard_graph_s is not None else None
        if graph is not None:
            if graph < self._heard_graph_s:  # simulated time stepped back: count from the step
                self._heard_graph_s = graph
            self.age_s = min(self.steady_age_s, graph - self._heard_graph_s)
        return self.age_s

    def fresh(self, timeout_s: float) -> bool:
        """Heard within ``timeout_s``."""
        return self.age_s <= timeout_s


#: a tick this many periods after the previous one is a starved tick, said in a warning (docs/architecture.md §10.1)
STARVED_WARN_TICKS = 5


def starvation(who: str, gap_s: float, tick_s: float) -> str:
    """``"<who> starved for 0.31 s (tick due every 0.04 s; the CPU is short: docs/architecture.md §10.1)"`` when
    ``gap_s`` (s, steady clock, since the previous tick; :meth:`TickGaps.tick`) is beyond :data:`STARVED_WARN_TICKS`
    periods ``tick_s`` (s), else ''. The campaign and the controller stop their thrust on one beyond
    :func:`starved_stop_s`."""
    if gap_s <= STARVED_WARN_TICKS * tick_s:
        return ""
    return (f"{who} starved for {gap_s:.2f} s (tick due every {tick_s:g} s; the CPU is short: "
            "docs/architecture.md §10.1)")


def starved_stop_s(wrench_timeout_s: float) -> float:
    """The tick gap (s) beyond which the campaign and the controller stop their thrust: twice
    ``thrusters.wrench_timeout_s``, the allocation has then held neutral for as long as a wrench may be old. One
    gap just past the timeout (one stale wrench, neutral for tens of ms) is survived: on a loaded development
    machine six of them came in one pool day."""
    return 2.0 * float(wrench_timeout_s)


class TickGaps:
    """The longest gap between two calls of a node's steady tick since the last :meth:`report`, and where the CPU went
    during it: the calling (executor) thread's CPU time, high when a long callback held the tick, and the whole
    process's, which also counts its other threads (the ESC's chip worker, DDS). Both low: the process was not
    running (not scheduled, or blocked). Clocks in s: ``clock`` steady, ``thread_clock`` and ``process_clock`` CPU."""

    def __init__(self, clock: Callable[[], float] = time.monotonic,
                 thread_clock: Callable[[], float] = time.thread_time,
                 process_clock: Callable[[], float] = time.process_time) -> None:
        self._clocks = (clock, thread_clock, process_clock)
        self._last = tuple(c() for c in self._clocks)
        self.worst = (0.0, 0.0, 0.0)

    def tick(self) -> float:
        """Call at every tick, from the ticking thread; returns the steady-clock gap since the previous one, s."""
        now = tuple(c() for c in self._clocks)
        gap = tuple(b - a for a, b in zip(self._last, now))
        self._last = now
        if gap[0] > self.worst[0]:
            self.worst = gap
        return gap[0]

    def report(self) -> list[tuple[str, str]]:
        """``/diagnostics`` pairs of the worst gap since the last report (ms): ``tick_gap_max_ms``,
        ``tick_gap_thread_cpu_ms``, ``tick_gap_process_cpu_ms``; then starts again."""
        out = [(k, f"{v * 1e3:.1f}") for k, v in zip(("tick_gap_max_ms", "tick_gap_thread_cpu_ms",
                                                        "tick_gap_process_cpu_ms"), self.worst)]
        self.worst = (0.0, 0.0, 0.0)
        return out


class ClockStepMonitor:
    """Detects a backward step of ROS time against the steady clock (and a stalled ROS clock).

    ``ros_now_s``: the node's ROS time in seconds; ``tolerance_s``: a backward move smaller than this is jitter.
    :meth:`check` returns the step in seconds (negative) when ROS time went back, else 0.0; :attr:`steps_back`
    counts them. :meth:`stalled_for_s`: how long ROS time has not moved while the steady clock ran."""

    def __init__(self, ros_now_s: Callable[[], float], tolerance_s: float = 0.05,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self._ros = ros_now_s
        self._clock = clock
        self.tolerance_s = float(tolerance_s)
        self._last_ros = ros_now_s()
        self._moved_at = clock()
        self.steps_back = 0

    def check(self) -> float:
        """Call at every steady tick. Returns the backward step (s, < 0) or 0.0."""
        ros = self._ros()
        delta = ros - self._last_ros
        self._last_ros = ros
        if delta != 0.0:
            self._moved_at = self._clock()
        if delta < -self.tolerance_s:
            self.steps_back += 1
            return delta
        return 0.0

    def stalled_for_s(self) -> float:
        """Steady time since ROS time last moved, s."""
        return self._clock() - self._moved_at
