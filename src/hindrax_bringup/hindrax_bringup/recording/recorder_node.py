"""Recorder node: records topics (parsed and raw device data) to rosbag2-compatible MCAP bags.

Thin rclpy node over :class:`hindrax_bringup.recording.writer_thread.ThreadedBagWriter` (docs/architecture.md §7).

Behaviour
- Topics: the parameters ``topics`` (names), ``topic_regex`` (``re.search``) and ``all_topics``
  select topics (:class:`~hindrax_bringup.recording.selection.TopicSelection`); with none of them the
  configuration key ``recording.topics`` is used, and without it every topic. The graph is polled every
  ``discovery_period_s`` so topics that appear after the start are recorded too. A topic is subscribed
  to once it has a publisher (its QoS is then known).
- QoS: each subscription is best effort unless the topic is transient local, where it matches the topic's publishers as
  rosbag2 does (:func:`~hindrax_bringup.recording.qos.recorder_policies`: the writers then run no reliability protocol
  for the recorder), keep-last depth ``queue_depth``; the publishers' profiles are stored in the bag
  (``offered_qos_profiles``). A sample sent before the recorder's reader has matched its writer is not recorded.
- Data: one subscription callback per message on the node's executor, whatever the clock (the
  vehicle, the virtual pool and the tests take the same path). The subscriptions are raw: the
  callback gets the CDR bytes and they are written unchanged, never converted into a Python message
  and back (:mod:`hindrax_common.cdr.lean_cdr`). Log time =
  the node's clock in the callback (sim time with ``use_sim_time``, so a stepped simulation's bag
  depends on its seed only); publish time = the log time (not the DDS source timestamp, which is
  wall-clock time; the MCAP specification asks for the log time where the publish time is not
  available). Writing happens in one writer thread (the mcap writer is not thread-safe),
  which drains what the callbacks queued every ``drain_period_s``.
- Start/stop: services ``recorder/start`` (hindrax_msgs/srv/StartRecording) and ``recorder/stop``
  (hindrax_msgs/srv/StopRecording), or ``autostart:=true``; stopping (also on SIGINT/SIGTERM) finishes
  the bag (summary, metadata.yaml). A SIGKILL or power loss loses at most the open chunk
  (:mod:`~hindrax_bringup.recording.writer`); ``hindrax bag recover`` repairs the bag.
- Loss in transit: the callback also gets the message info
  (:class:`~hindrax_common.process.ros_process.WithMessageInfo`); gaps in each topic's publication sequence
  numbers count the samples lost between its writer and this reader
  (:class:`~hindrax_bringup.recording.sequence_gaps.SequenceGaps`; a best-effort reader's loss is
  otherwise silent). The info has no publisher gid here, so the count is keyed by topic and a gap
  counts only while the topic has one publisher (``get_publisher_count``, asked on a gap only).
- Status: ``/diagnostics`` (diagnostic_msgs/DiagnosticArray) every ``status_period_s``: state, bag, messages written,
  dropped (the writer's queue) and lost (in transit; WARN when either is above 0), one key per topic
  (``topic:/name`` -> count) and one per topic that lost samples (``lost:/name`` -> samples lost).
- Disk floor: every ``disk_check_period_s`` (and before a start) the free space of the filesystem the bag
  goes to is compared with ``recording.min_free_disk_mb``; below it the recorder stops cleanly (the bag is
  finished: summary, metadata.yaml), refuses new starts, and reports the reason at level ERROR on
  ``/diagnostics`` until space is freed. 0 turns the check off.

Parameters (besides the vehicle configuration, ``recording.*`` keys of hindrax.yaml):
``topics`` (string[]), ``topic_regex`` (string), ``all_topics`` (bool), ``exclude_regex`` (string: never these),
``output_dir`` (string; empty = a new
timestamped directory under ``recording.output_root`` at every start, never an existing one: :mod:`.bag_dir`),
``autostart`` (bool, false), ``discovery_period_s`` (1.0), ``status_period_s`` (1.0), ``queue_depth`` (1000),
``disk_check_period_s`` (1.0), ``drain_period_s`` (:data:`DRAIN_PERIOD_S`, 0.1; the writer thread's drain period:
what a crash loses grows by at most this much).

Run alone: ``python -m hindrax_bringup.recording.recorder_node --ros-args --params-file
ros_ws/config/hindrax.yaml -p autostart:=true``."""
from __future__ import annotations

import functools
import os
import sys
from pathlib import Path
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from hindrax_msgs.srv import StartRecording, StopRecording

from hindrax_common.config import ConfigError
from hindrax_common.node_support.node_common import load_node_config
from hindrax_common.process.ros_process import RosProcess, WithMessageInfo
from hindrax_common.node_support.vehicle_node import VehicleNode
from .bag_dir import new_bag_dir
from .metadata import BagMetadata
from hindrax_common.cdr.msgdefs import normalize_type_name
from .msgtypes import TypeNotInstalledError, message_class
from .qos import profile_from_rclpy, recorder_policies
from .selection import TopicSelection
from .sequence_gaps import SequenceGaps
from .writer import WriterOptions
from .writer_thread import ThreadedBagWriter

#: default ``drain_period_s``, s: the writer thread drains what the callbacks queued 10 times a second
#: (docs/architecture.md §10.1)
DRAIN_PERIOD_S = 0.1


class RecorderNode(VehicleNode):
    """Records selected topics to MCAP bags; see the module docstring for parameters and interfaces.

    Raises :class:`hindrax_common.config.ConfigError` when the vehicle configuration is invalid and
    ValueError for an invalid topic regex given at start-up."""

    def __init__(self, node_name: str = "recorder", *, statvfs: Any = None, **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        #: os.statvfs, or a stand-in with the same result fields (tests)
        self._statvfs = statvfs or os.statvfs
        self._disk_full: str = ""
        self._cfg = load_node_config(self, ("recording",))
        self._topics_param = list(self._param("topics", []) or [])
        self._regex_param = str(self._param("topic_regex", ""))
        self._all_param = bool(self._param("all_topics", False))
        self._exclude_param = str(self._param("exclude_regex", ""))
        self._output_dir_param = str(self._param("output_dir", ""))
        self._discovery_period_s = float(self._param("discovery_period_s", 1.0))
        self._status_period_s = float(self._param("status_period_s", 1.0))
        self._queue_depth = int(self._param("queue_depth", 1000))
        autostart = bool(self._param("autostart", False))
        self._options = WriterOptions.from_section(self._cfg.recording)
        self._output_root = Path(self._cfg.recording.output_root)
        self._min_free_bytes = float(self._cfg.recording.min_free_disk_mb) * 1e6
        self._disk_check_period_s = float(self._param("disk_check_period_s", 1.0))
        self._drain_period_s = float(self._param("drain_period_s", DRAIN_PERIOD_S))

        self._writer: ThreadedBagWriter | None = None
        self._gaps = SequenceGaps()
        self._selection: TopicSelection | None = None
        self._subs: dict[str, Any] = {}
        self._skipped: set[str] = set()
        self._last_metadata: BagMetadata | None = None
        self._last_bag: Path | None = None

        self._diag_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.create_service(StartRecording, "recorder/start", self._on_start)
        self.create_service(StopRecording, "recorder/stop", self._on_stop)
        self.create_timer(self._discovery_period_s, self.discover_now)
        self.create_timer(self._status_period_s, self._publish_status)
        if self._min_free_bytes > 0.0:
            self.create_timer(self._disk_check_period_s, self.check_disk)
        if autostart:
            self.start_recording()

    _PARAM_DOCS = {
        "topics": "topics to record (names); with topic_regex and all_topics empty: recording.topics, else all",
        "topic_regex": "record topics matching this regular expression (re.search)",
        "all_topics": "record every topic",
        "exclude_regex": "never record topics matching this regular expression (re.search; with the three above)",
        "output_dir": "bag directory (empty: a new timestamped directory under recording.output_root per start)",
        "discovery_period_s": "period of the graph poll that subscribes to new topics, s",
        "status_period_s": "period of the /diagnostics status, s",
        "queue_depth": "subscription queue depth (keep last)",
        "autostart": "start recording at start-up",
        "disk_check_period_s": "period of the free-disk check against recording.min_free_disk_mb, s",
        "drain_period_s": "period at which the writer thread writes what the callbacks queued, s",
    }

    def _param(self, name: str, default: Any) -> Any:
        if not self.has_parameter(name):
            self.declare_parameter(name, default, ParameterDescriptor(
                description=self._PARAM_DOCS.get(name, ""), read_only=True, dynamic_typing=True))
        return self.get_parameter(name).value

    # -- disk floor -------------------------------------------------------------------------------
    def free_disk_bytes(self, path: Path) -> float:
        """Free bytes available to this user on the filesystem holding ``path`` (its nearest existing parent)."""
        p = Path(path).absolute()
        while not p.exists() and p != p.parent:
            p = p.parent
        st = self._statvfs(str(p))
        return float(st.f_bavail) * float(st.f_frsize)

    def _below_floor(self, path: Path) -> str:
        """The reason (one line) when the free space at ``path`` is below the floor, else ""."""
        if self._min_free_bytes <= 0.0:
            return ""
        free = self.free_disk_bytes(path)
        if free >= self._min_free_bytes:
            return ""
        return (f"free disk space {free / 1e6:.1f} MB at {path} is below recording.min_free_disk_mb = "
                f"{self._min_free_bytes / 1e6:g}")

    def check_disk(self) -> None:
        """Stop recording cleanly (bag finished) when the free space falls below ``recording.min_free_disk_mb``."""
        target = self.bag_path if self._writer is not None else (self._output_dir_param or self._output_root)
        reason = self._below_floor(Path(target))
        self._disk_full = reason
        if reason and self._writer is not None:
            self._log(f"{reason}: stopping the recording", warning=True)
            self.stop_recording()

    # -- recording control ------------------------------------------------------------------------
    @property
    def recording(self) -> bool:
        return self._writer is not None

    @property
    def bag_path(self) -> Path | None:
        """Directory of the bag being written (or last written)."""
        return self._writer.bag_dir if self._writer is not None else self._last_bag

    def default_selection(self) -> TopicSelection:
        """Selection from the node parameters, else ``recording.topics``, else all topics."""
        if self._topics_param or self._regex_param or self._all_param:
            return TopicSelection(tuple(self._topics_param), self._regex_param, self._all_param, self._exclude_param)
        configured = self._cfg.recording.topics
        if configured:
            return TopicSelection(tuple(configured))
        return TopicSelection(all_topics=True)

    def start_recording(self, output_dir: str = "", selection: TopicSelection | None = None) -> Path:
        """Open a new bag and subscribe to the selected topics. Returns the bag directory.

        Raises RuntimeError when already recording, FileExistsError when a named directory holds a bag,
        OSError when it cannot be created."""
        if self._writer is not None:
            raise RuntimeError(f"already recording to {self._writer.bag_dir}")
        named = output_dir or self._output_dir_param  # else a new directory under the root (bag_dir)
        reason = self._below_floor(Path(named) if named else self._output_root)
        if reason:
            self._disk_full = reason
            raise OSError(f"not recording: {reason}")
        out = Path(named) if named else new_bag_dir(self._output_root)
        self._selection = selection or self.default_selection()
        self._writer = ThreadedBagWriter(out, self._options, drain_period_s=self._drain_period_s)
        self._gaps = SequenceGaps(self._publisher_count)
        self._skipped.clear()
        self.get_logger().info(f"recording {self._selection.describe()} to {out}")
        self.discover_now()
        return out

    def stop_recording(self) -> BagMetadata | None:
        """Unsubscribe, finish the bag and return its metadata (None when not recording)."""
        writer = self._writer
        if writer is None:
            return None
        self._writer = None
        for sub in self._subs.values():
            self.destroy_subscription(sub)
        self._subs.clear()
        meta = writer.close()
        for w in writer.warnings:
            self._log(w, warning=True)
        self._last_metadata = meta
        self._last_bag = writer.bag_dir
        self._log(f"bag {writer.bag_dir} closed: {meta.message_count} messages in {len(meta.files)} file(s), "
                  f"{writer.dropped} dropped, {self._gaps.lost} lost in transit")
        return meta

    def _publisher_count(self, topic: str) -> int:
        """Publishers of ``topic`` matched with the recorder's subscription (0 when not subscribed)."""
        sub = self._subs.get(topic)
        return sub.get_publisher_count() if sub is not None else 0

    def _log(self, text: str, warning: bool = False) -> None:
        """Log through ROS while the context is up; after SIGINT/SIGTERM (context shut down) to stderr."""
        if self.context.ok():  # one call site per severity: rclpy refuses two severities from one line
            if warning:
                self.get_logger().warning(text)
            else:
                self.get_logger().info(text)
        else:
            print(f"[{self.get_name()}] {text}", file=sys.stderr)

    # -- graph discovery --------------------------------------------------------------------------
    def subscribed_to(self, topics) -> bool:
        """True while recording and every topic of ``topics`` (iterable of names) that the selection records has
        a subscription matched with at least one publisher: from then on none of their messages is missed."""
        if self._writer is None or self._selection is None:
            return False
        for topic in topics:
            if topic in self._skipped or not self._selection.matches(topic):
                continue
            sub = self._subs.get(topic)
            if sub is None or sub.get_publisher_count() == 0:
                return False
        return True

    def discover_now(self) -> None:
        """Subscribe to newly published topics now (also the discovery timer's callback, on ROS
        time, which may be frozen)."""
        if self._writer is None or self._selection is None:
            return
        for topic, types in self.get_topic_names_and_types():
            if topic in self._subs or topic in self._skipped or not self._selection.matches(topic):
                continue
            if not types:
                continue
            infos = self.get_publishers_info_by_topic(topic)
            if not infos:
                continue  # no publisher yet: its QoS is unknown; try again at the next poll
            type_name = normalize_type_name(types[0])
            if len(types) > 1:
                self.get_logger().warning(f"{topic}: several types {types}; recording {type_name}")
            try:
                cls = message_class(type_name)
            except (TypeNotInstalledError, ValueError) as exc:
                self.get_logger().warning(f"{topic}: not recorded: {exc}")
                self._skipped.add(topic)
                continue
            profiles = [profile_from_rclpy(i.qos_profile) for i in infos if normalize_type_name(i.topic_type)
                        == type_name]
            reliability, durability = recorder_policies(profiles)
            qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=self._queue_depth,
                             reliability=ReliabilityPolicy.get_from_short_key(reliability),
                             durability=DurabilityPolicy.get_from_short_key(durability))
            self._writer.add_topic(topic, type_name, profiles)
            on_message = WithMessageInfo(functools.partial(self._on_message, topic))
            self._subs[topic] = self.create_subscription(cls, topic, on_message, qos, raw=True)
            self.get_logger().info(f"recording {topic} [{type_name}] ({reliability}, {durability})")

    def _on_message(self, topic: str, data: bytes, info: dict) -> None:
        """One received message (CDR bytes) of ``topic`` and its rmw message info: queued for the
        writer thread, log time = publish time = the node's clock now; its publication sequence
        number counted (module docstring)."""
        writer = self._writer
        if writer is None:
            return
        writer.write(topic, self.get_clock().now().nanoseconds, data)
        self._gaps.observe(topic, info.get("publication_sequence_number"))

    # -- services and status ----------------------------------------------------------------------
    def _on_start(self, request: StartRecording.Request, response: StartRecording.Response):
        try:
            sel = None
            if list(request.topics) or request.topic_regex:
                sel = TopicSelection(tuple(request.topics), request.topic_regex)
            path = self.start_recording(request.output_dir, sel)
        except (RuntimeError, ValueError, OSError) as exc:
            response.success, response.message = False, str(exc)
            response.bag_path = str(self.bag_path or "")
            return response
        response.success = True
        response.bag_path = str(path)
        response.message = f"recording {self._selection.describe() if self._selection else ''}"
        return response

    def _on_stop(self, request: StopRecording.Request, response: StopRecording.Response):
        response.success, response.message = False, "not recording"
        if self._writer is not None:
            try:
                meta = self.stop_recording()
                response.message_count = int(meta.message_count if meta else 0)
                response.success = True
                response.message = f"{response.message_count} messages written"
            except Exception as exc:  # noqa: BLE001 - reported to the caller, the node goes on
                response.message = f"bag could not be finished: {exc}"
        response.bag_path = str(self._last_bag or "")
        return response

    def status(self) -> DiagnosticStatus:
        """The recorder's diagnostic status (also published on /diagnostics)."""
        st = DiagnosticStatus(name=f"{self.get_name()}: recording", hardware_id="")
        w = self._writer
        values = [KeyValue(key="state", value="recording" if w else "idle"),
                  KeyValue(key="bag", value=str(self.bag_path or ""))]
        if w is None and self._disk_full:
            st.level = DiagnosticStatus.ERROR
            st.message = f"stopped: {self._disk_full}"
        elif w is None:
            st.level = DiagnosticStatus.OK
            st.message = "idle"
        else:
            lost = self._gaps.lost_by_writer()
            st.level = (DiagnosticStatus.ERROR if w.error else
                        DiagnosticStatus.WARN if w.dropped or lost else DiagnosticStatus.OK)
            st.message = f"writer failed: {w.error}" if w.error else f"recording to {w.bag_dir}"
            values += [KeyValue(key="messages_written", value=str(w.written)),
                       KeyValue(key="messages_dropped", value=str(w.dropped)),
                       KeyValue(key="messages_lost", value=str(sum(lost.values()))),
                       KeyValue(key="messages_queued", value=str(w.pending)),
                       KeyValue(key="file", value=str(w.current_file.name))]
            values += [KeyValue(key=f"topic:{t}", value=str(n)) for t, n in sorted(w.topic_counts().items())]
            values += [KeyValue(key=f"lost:{t}", value=str(n)) for t, n in sorted(lost.items())]
        st.values = values
        return st

    def _publish_status(self) -> None:
        arr = DiagnosticArray()
        arr.header.stamp = self.get_clock().now().to_msg()
        arr.status = [self.status()]
        self._diag_pub.publish(arr)

    def shutdown(self) -> None:
        """Finish any bag in progress (called on exit, also after SIGINT/SIGTERM; as :meth:`close`,
        the clean-up of a composed process, :func:`~hindrax_common.node_support.node_common.run_nodes`)."""
        try:
            self.stop_recording()
        except Exception as exc:  # noqa: BLE001 - exiting: report, never hide the bag path
            print(f"recorder: bag {self.bag_path} not finished cleanly: {exc}; run `hindrax bag recover "
                  f"{self.bag_path}`", file=sys.stderr)

    close = shutdown


def main(args: list[str] | None = None) -> int:
    """Entry point: ``python -m hindrax_bringup.recording.recorder_node --ros-args ...``.

    Exit 0 (also after SIGINT/SIGTERM, the bag finished), 1 with one line on stderr when the node cannot start.
    The process spins the EventsExecutor (:mod:`hindrax_common.process.ros_process`)."""
    with RosProcess(args) as proc:
        try:
            node = RecorderNode()
        except (ConfigError, ValueError) as exc:
            print(f"recorder: {str(exc).splitlines()[0]}", file=sys.stderr)
            return 1
        proc.executor.add_node(proc.own(node))  # on exit: close() finishes the bag
        proc.spin()
    return proc.status


if __name__ == "__main__":
    sys.exit(main())
