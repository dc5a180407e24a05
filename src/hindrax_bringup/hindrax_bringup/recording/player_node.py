"""Player node: publishes a bag with its original timing (rate factor, start offset, topic subset, loop,
optional /clock) (docs/architecture.md §7).

Thin rclpy node over :mod:`~hindrax_bringup.recording.reader` (raw CDR messages in log-time order) and
:func:`~hindrax_bringup.recording.playback.play` (timing). Messages are published as the recorded bytes
(``Publisher.publish(bytes)``), unchanged.

- Publishers are created for every selected topic first; :meth:`BagPlayerNode.wait_for_subscribers` then
  waits (up to ``wait_for_subscribers_timeout_s``) until each has at least one subscriber, so the first
  messages are not lost to discovery (docs/architecture.md §11). Topics still without subscribers after the timeout
  are reported and played anyway.
- QoS per topic: the recorded publishers' profile when they agreed, else reliable/volatile
  (:func:`~hindrax_bringup.recording.qos.playback_profile`), keep-last ``qos_depth``.
- A topic whose message type is not installed cannot be published (rclpy needs the type support even for
  raw bytes): it is skipped with a one-line warning naming the type. Its messages remain decodable from
  the bag's own schema (``hindrax bag info``, :meth:`BagReader.decoded`).
- ``clock:=true`` publishes rosgraph_msgs/Clock on /clock at ``clock_rate_hz`` (wall) with the bag time;
  nodes under test then run with ``use_sim_time:=true``.
- The safety and actuation topics (heartbeats, ``thrusters/*``, ``esc/*``, ``supervisor/*``, ``guard/*``, ``wrench``,
  setpoints, action and service topics: :func:`~hindrax_common.node_support.vehicle_graph.vehicle_topic_reason`) are
  withheld unless ``safety_topics:=true``: a bag must never answer for the vehicle's supervisor or drive its thrusters.
  Naming one in ``topics`` without it is an error. With it, the player watches the graph
  (:class:`~hindrax_common.node_support.vehicle_graph.ForeignVehicleWatch`) for the discovery window before it creates
  its first publisher (a refused play leaves nothing on a vehicle's graph) and all through the play, and stops with a
  :class:`PlayerError` naming the ESC or supervisor it sees.

Parameters: ``bag`` (string, required), ``rate`` (1.0), ``start_offset_s`` (0.0), ``topics`` (string[],
empty = all), ``loop`` (false), ``clock`` (false), ``clock_rate_hz`` (100.0),
``wait_for_subscribers_timeout_s`` (5.0), ``qos_depth`` (100), ``safety_topics`` (false).

Run alone: ``python -m hindrax_bringup.recording.player_node --ros-args -p bag:=runs/BAG -p rate:=2.0``.
Errors: :class:`PlayerError` (one line) for a missing bag, unknown topics, nothing publishable, a withheld topic
requested without ``safety_topics``, or (with it) an ESC or supervisor on the graph."""
from __future__ import annotations

import sys
import threading
import time
from typing import Any

from rcl_interfaces.msg import ParameterDescriptor
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock

from hindrax_common.node_support.node_common import time_from_ns
from hindrax_common.process.ros_process import RosProcess
from hindrax_common.node_support.vehicle_graph import (DISCOVERY_WINDOW_S, ForeignVehicleError, ForeignVehicleWatch,
    GraphView, split_vehicle_topics)
from .msgtypes import TypeNotInstalledError, message_class
from .playback import PlayStats, play
from .qos import playback_profile, profiles_from_yaml
from .reader import BagError, BagReader


class PlayerError(ValueError):
    """The bag cannot be played as requested (message is one line)."""


#: Descriptions of the player's parameters (``ros2 param describe``); all read at start-up (read-only).
_PARAMETER_DOCS = {
    "bag": "bag directory (or .mcap file) to play",
    "rate": "playback rate factor (1 = recorded timing)",
    "start_offset_s": "start this many seconds into the bag, s",
    "topics": "topics to play (empty: all)",
    "loop": "play the bag again when it ends",
    "clock": "publish /clock from the bag's time",
    "clock_rate_hz": "rate /clock is published at, Hz",
    "wait_for_subscribers_timeout_s": "how long to wait for a subscriber on every topic before playing, s",
    "qos_depth": "publisher queue depth",
    "safety_topics": "also publish the safety and actuation topics (heartbeats, thrusters, esc, supervisor, guard, "
                     "wrench, setpoints); refused while an ESC or supervisor is on the graph",
}

#: how often the player looks at the graph for an ESC or supervisor while it publishes safety topics, s
GRAPH_CHECK_PERIOD_S = 0.2


#: what the player refuses beside a live ESC or supervisor (with ``safety_topics``)
REFUSAL = "a bag's safety and actuation topics are never published onto a live vehicle's graph"


class BagPlayerNode(Node):
    """Publishes a bag; see the module docstring. Raises :class:`PlayerError` at construction. ``window_s``: the
    discovery window watched before the first publisher (with ``safety_topics``; 0 when the caller watched it
    already, :func:`~hindrax_common.node_support.vehicle_graph.refuse_before_start`)."""

    def __init__(self, node_name: str = "player", window_s: float = DISCOVERY_WINDOW_S, **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        bag = str(self._param("bag", ""))
        self.rate = float(self._param("rate", 1.0))
        self.start_offset_s = float(self._param("start_offset_s", 0.0))
        requested = [t if t.startswith("/") else "/" + t for t in (self._param("topics", []) or []) if t]
        self.loop = bool(self._param("loop", False))
        self.publish_clock = bool(self._param("clock", False))
        self.clock_rate_hz = float(self._param("clock_rate_hz", 100.0))
        self.wait_timeout_s = float(self._param("wait_for_subscribers_timeout_s", 5.0))
        depth = int(self._param("qos_depth", 100))
        self.safety_topics = bool(self._param("safety_topics", False))
        if not bag:
            raise PlayerError("no bag given (parameter bag:=PATH)")
        if not self.rate > 0:
            raise PlayerError(f"rate {self.rate}: must be > 0")
        if self.start_offset_s < 0:
            raise PlayerError(f"start offset {self.start_offset_s} s: must be >= 0")
        if self.publish_clock and not self.clock_rate_hz > 0:
            raise PlayerError(f"clock rate {self.clock_rate_hz} Hz: must be > 0")
        try:
            self.reader = BagReader(bag)
        except (FileNotFoundError, BagError) as exc:
            raise PlayerError(str(exc)) from exc
        if self.reader.truncated_files:
            self.get_logger().warning(
                f"{bag}: truncated file(s) {[f.name for f in self.reader.truncated_files]}; playing what is "
                f"readable (run `hindrax bag recover {bag}`)")
        unknown = [t for t in requested if t not in self.reader.channels]
        if unknown:
            raise PlayerError(f"topic(s) {' '.join(unknown)} not in {bag}; it has: "
                              + " ".join(sorted(self.reader.channels)))
        selected = requested or sorted(self.reader.channels)
        self.skipped: dict[str, str] = {}
        self.withheld: dict[str, str] = {}
        if not self.safety_topics:
            selected, self.withheld = split_vehicle_topics(selected)
            asked = [t for t in requested if t in self.withheld]
            if asked:
                raise PlayerError(f"{' '.join(asked)}: {self.withheld[asked[0]]}; a bag does not speak for the "
                                  "vehicle unless asked with --safety-topics (safety_topics:=true)")
            if self.withheld:
                self.get_logger().info(f"not publishing {len(self.withheld)} safety and actuation topic(s) "
                                       f"({' '.join(self.withheld)}); --safety-topics to publish them")
        if self.reader.start_ns is None:
            raise PlayerError(f"{bag}: the bag holds no messages")
        self.bag_start_ns = self.reader.start_ns
        self.origin_ns = self.bag_start_ns + int(round(self.start_offset_s * 1e9))
        if self.origin_ns > self.reader.end_ns:
            raise PlayerError(f"start offset {self.start_offset_s:g} s is beyond the end of {bag} "
                              f"({(self.reader.end_ns - self.bag_start_ns) / 1e9:.3f} s long)")
        self.pubs: dict[str, Any] = {}
        self._stop = threading.Event()
        self.watch: ForeignVehicleWatch | None = None
        if self.safety_topics:
            # the discovery window before the first publisher: a refused play must leave nothing on a vehicle's
            # graph (a second heartbeat publisher, even for the window, disarms its ESC)
            me = self.get_fully_qualified_name()
            self.watch = ForeignVehicleWatch(self, "refused", REFUSAL, window_s=window_s,
                                             own=lambda: GraphView((me,), {t: (me,) for t in self.pubs}),
                                             period_s=GRAPH_CHECK_PERIOD_S)
            while not self._stop.is_set() and not self._graph_settled():
                self._wait(0.05)
        for topic in selected:
            ch = self.reader.channels[topic]
            try:
                cls = message_class(ch.type)
            except (TypeNotInstalledError, ValueError) as exc:
                reason = f"{topic} not published: {exc}; decode it from the bag's stored schema instead"
                self.skipped[topic] = reason
                self.get_logger().warning(reason)
                continue
            try:
                prof = playback_profile(profiles_from_yaml(ch.metadata.get("offered_qos_profiles", "")))
            except ValueError:
                prof = playback_profile([])
            qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                             reliability=ReliabilityPolicy.get_from_short_key(prof["reliability"]),
                             durability=DurabilityPolicy.get_from_short_key(prof["durability"]))
            self.pubs[topic] = self.create_publisher(cls, topic, qos)
        if not self.pubs:
            raise PlayerError("nothing to publish: " + "; ".join(
                list(self.skipped.values()) + ([f"the bag's {len(self.withheld)} safety and actuation topic(s) are "
                                                "withheld (--safety-topics)"] if self.withheld else [])))
        self.clock_pub = self.create_publisher(Clock, "/clock", 10) if self.publish_clock else None

    def _check_graph(self, force: bool = False) -> None:
        """With ``safety_topics``: raise :class:`PlayerError` when an ESC or supervisor is on the graph (looked at
        every :data:`GRAPH_CHECK_PERIOD_S` at most, unless ``force``)."""
        if self.watch is None:
            return
        try:
            if force:
                self.watch.check()
            else:
                self.watch.poll()
        except ForeignVehicleError as exc:
            self._stop.set()
            raise PlayerError(str(exc)) from exc

    def _graph_settled(self) -> bool:
        """True once the discovery window has passed with no ESC or supervisor seen (raises :class:`PlayerError`
        when one is); True at once without ``safety_topics``."""
        self._check_graph(force=True)
        return self.watch is None or self.watch.settled()

    def _param(self, name: str, default: Any) -> Any:
        """Declare (once) and read a parameter. A list is declared as a string array without a value: rclpy
        types an empty list as a byte array and would then refuse a ``topics`` override of strings."""
        if not self.has_parameter(name):
            desc = ParameterDescriptor(description=_PARAMETER_DOCS.get(name, name), read_only=True)
            if isinstance(default, list):
                self.declare_parameter(name, Parameter.Type.STRING_ARRAY, desc)
            else:
                self.declare_parameter(name, default, desc)
        return self.get_parameter_or(name, Parameter(name, value=default)).value

    def wait_for_subscribers(self, timeout_s: float | None = None) -> list[str]:
        """Wait until every publisher has a subscriber or the timeout passes; returns topics without any."""
        timeout_s = self.wait_timeout_s if timeout_s is None else timeout_s
        waiting = lambda: [t for t, p in self.pubs.items() if p.get_subscription_count() == 0]  # noqa: E731
        deadline = time.monotonic() + max(0.0, timeout_s)
        missing = waiting()
        while missing and time.monotonic() < deadline and not self._stop.is_set():
            self._wait(0.02)
            missing = waiting()
        # safety topics: no message before the graph had the discovery window to show an ESC or supervisor
        while not self._stop.is_set() and not self._graph_settled():
            self._wait(0.05)
        if missing:
            self.get_logger().warning(f"no subscriber after {timeout_s:g} s on: {' '.join(missing)}; playing anyway")
        return missing

    def _wait(self, seconds: float) -> None:
        """Wait on the stop event in slices of <= 0.1 s; a shut-down context (SIGINT/SIGTERM) stops play."""
        self._stop.wait(min(seconds, 0.1))
        if not self.context.ok():
            self._stop.set()
        self._check_graph()

    def stop(self) -> None:
        """Ask :meth:`play` to return (thread-safe)."""
        self._stop.set()

    def play(self) -> PlayStats:
        """Publish the selected topics from the start offset with the recorded timing (blocking)."""
        topics = sorted(self.pubs)

        def messages():
            return self.reader.messages(topics, start_ns=self.origin_ns)

        def publish(m) -> None:
            self._check_graph()
            self.pubs[m.topic].publish(m.data)

        def publish_clock(t_ns: int) -> None:
            self.clock_pub.publish(Clock(clock=time_from_ns(t_ns)))

        self.get_logger().info(
            f"playing {len(topics)} topic(s) from {self.reader.path} at rate {self.rate:g}"
            f"{f', from +{self.start_offset_s:g} s' if self.start_offset_s else ''}{', looping' if self.loop else ''}"
            f"{', publishing /clock' if self.clock_pub else ''}")
        stats = play(messages, publish, self.origin_ns, rate=self.rate, loop=self.loop,
                     publish_clock=publish_clock if self.clock_pub is not None else None,
                     clock_period_s=1.0 / self.clock_rate_hz, stop=self._stop, wait=self._wait)
        self.wait_for_acknowledgements()
        self.get_logger().info(f"published {stats.published} messages in {stats.passes} pass(es)")
        return stats

    def wait_for_acknowledgements(self, timeout_s: float = 2.0) -> bool:
        """Wait (bounded) until reliable subscribers acknowledged everything, so exiting loses nothing."""
        ok = True
        deadline = time.monotonic() + timeout_s
        for pub in self.pubs.values():
            left = max(0.0, deadline - time.monotonic())
            ok = pub.wait_for_all_acked(Duration(nanoseconds=int(left * 1e9))) and ok
        return ok


def main(args: list[str] | None = None) -> int:
    """Entry point: ``python -m hindrax_bringup.recording.player_node --ros-args -p bag:=PATH ...``.

    Exit 0 when played (or stopped by SIGINT/SIGTERM), 1 with one line on stderr for a :class:`PlayerError`."""
    with RosProcess(args, errors={PlayerError: "player"}) as proc:
        node = proc.own(BagPlayerNode())
        node.wait_for_subscribers()
        node.play()
    return proc.status


if __name__ == "__main__":
    sys.exit(main())

