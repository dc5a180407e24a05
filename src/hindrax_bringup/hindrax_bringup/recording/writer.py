"""Bag writer: rosbag2-compatible MCAP files (docs/architecture.md §7, docs/architecture.md §11.6).

:class:`BagWriter` is the pure core of the recorder (no ROS runtime, no threads). It takes CDR bytes as
received and writes a bag *directory*::

    <bag>/metadata.yaml          rosbag2_bagfile_information version 9 (see :mod:`.metadata`)
    <bag>/<bag>_0.mcap           profile ros2; schemas pkg/msg/Type (ros2msg, full definition);
    <bag>/<bag>_1.mcap ...       channels (cdr, offered_qos_profiles, topic_type_hash); messages
                                 in chunks (zstd/lz4/none); a "rosbag2" metadata record at close

Crash safety (power loss or SIGKILL loses at most the chunk being filled):

- every chunk is written to the file as soon as it closes, then the file is flushed and ``os.fsync``'d;
- a chunk is also closed early when its oldest message has waited ``flush_interval_s`` (wall time), so the
  loss is bounded by ``min(chunk_size_bytes of data, flush_interval_s of data)``;
- metadata.yaml is rewritten (atomically, fsync'd) when a file is opened or split, so a crashed bag still
  lists its files; :mod:`.recover` rebuilds the summaries and the counts.

Splitting: a new file ``<bag>_<n+1>.mcap`` starts before a message that would take the current file past
``split_size_bytes`` (estimated from the bytes on disk, the *uncompressed* size of the open chunk and an
upper bound of what closing adds: indexes, summary, metadata record; so a finished file stays under the
limit unless one chunk alone exceeds it) or whose log time is ``split_duration_s`` or more after the
file's first message. Every file repeats all schemas and channels, as rosbag2 does.

Not thread-safe (neither is ``mcap.writer.Writer``): use it from one thread only; the recorder node uses
:class:`hindrax_bringup.recording.writer_thread.ThreadedBagWriter`.

Errors: ``FileExistsError`` (bag directory already holds a bag), ``KeyError`` (write to an unknown topic),
``ValueError`` (bad options), ``RuntimeError`` (write after close), ``OSError`` from the file system."""
from __future__ import annotations

import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping

from mcap.writer import CompressionType, Writer

from hindrax_common.config.typed_sections import RecordingSection
from hindrax_common.cdr import msgdefs
from .metadata import BagMetadata, FileInfo, TopicInfo, write_metadata
from .qos import profiles_to_yaml

PROFILE = "ros2"
SCHEMA_ENCODING = "ros2msg"
MESSAGE_ENCODING = "cdr"
LIBRARY = "hindrax-recorder"
_MESSAGE_RECORD_OVERHEAD_BYTES = 1 + 8 + 2 + 4 + 8 + 8  # opcode, length, channel, sequence, 2 times

_COMPRESSION = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}


@dataclass(frozen=True)
class WriterOptions:
    """How bags are written (configuration keys ``recording.*``, hindrax.yaml).

    compression: chunk compression, "zstd" (default), "lz4" or "none".
    chunk_size_bytes: uncompressed size at which a chunk is closed and written, bytes.
    split_size_bytes: start a new file before this size would be exceeded, bytes (0 = never).
    split_duration_s: start a new file after this much log time, s (0 = never).
    flush_interval_s: close and fsync the open chunk once its oldest message is this old, s (0 = only
        when the chunk is full).
    fsync: call os.fsync after each chunk (disable only for benchmarks of the format itself)."""

    compression: str = "zstd"
    chunk_size_bytes: int = 1024 * 1024
    split_size_bytes: int = 0
    split_duration_s: float = 0.0
    flush_interval_s: float = 1.0
    fsync: bool = True

    def __post_init__(self) -> None:
        if self.compression not in _COMPRESSION:
            raise ValueError(f"compression {self.compression!r}: one of {', '.join(_COMPRESSION)}")
        if self.chunk_size_bytes < 1:
            raise ValueError(f"chunk_size_bytes {self.chunk_size_bytes}: must be >= 1")
        if self.split_size_bytes < 0 or self.split_duration_s < 0 or self.flush_interval_s < 0:
            raise ValueError("split_size_bytes, split_duration_s and flush_interval_s must be >= 0")

    @classmethod
    def from_section(cls, recording: RecordingSection) -> "WriterOptions":
        """From the validated ``recording.*`` section (``VehicleConfig.recording``)."""
        keys = ("compression", "chunk_size_bytes", "split_size_bytes", "split_duration_s", "flush_interval_s")
        return cls(**{k: getattr(recording, k) for k in keys})


@dataclass
class _Topic:
    info: TopicInfo
    definition: str


@dataclass
class _File:
    path: Path
    stream: Any
    writer: Writer
    schema_ids: dict[str, int] = field(default_factory=dict)
    channel_ids: dict[str, int] = field(default_factory=dict)
    sequence: dict[str, int] = field(default_factory=dict)
    message_count: int = 0
    start_ns: int = 0
    end_ns: int = 0
    last_pos: int = 0
    chunks: int = 0
    message_bytes: int = 0
    record_bytes: int = 0  # schema + channel records, repeated in the summary at close


class BagWriter:
    """Write a rosbag2-compatible MCAP bag directory from serialized (CDR) messages.

    bag_dir: directory to create (its name is the bag name; an existing empty directory is accepted).
    options: :class:`WriterOptions`. monotonic: wall clock for the flush interval (injectable for tests).

    Usage: ``add_topic`` for each topic (before or between writes), ``write`` messages in receive order,
    ``close`` (also on exceptions: use it as a context manager). Times are ns since the epoch in the
    clock the caller records with (ROS time; sim time when ``use_sim_time``)."""

    def __init__(self, bag_dir: str | Path, options: WriterOptions | None = None,
                 monotonic: Callable[[], float] = time.monotonic) -> None:
        self.bag_dir = Path(bag_dir)
        self.options = options or WriterOptions()
        self._monotonic = monotonic
        if (self.bag_dir / "metadata.yaml").exists() or any(self.bag_dir.glob("*.mcap")):
            raise FileExistsError(f"{self.bag_dir}: already holds a bag; choose a new output directory")
        self.bag_dir.mkdir(parents=True, exist_ok=True)
        self.name = self.bag_dir.name
        self._topics: dict[str, _Topic] = {}
        self._files: list[FileInfo] = []
        self._file: _File | None = None
        self._closed = False
        self._pending_bytes = 0
        self._oldest_unflushed: float | None = None
        self.message_count = 0
        self.chunks_written = 0
        self.warnings: list[str] = []
        self._warned_split = False
        self._open_file()

    # -- public API -------------------------------------------------------------------------------
    def __enter__(self) -> "BagWriter":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    @property
    def current_file(self) -> Path:
        """Path of the file being written (the last one after close). Safe to read from another thread."""
        return self._current_path

    @property
    def topics(self) -> dict[str, TopicInfo]:
        """Registered topics (name -> TopicInfo with running message counts)."""
        return {name: t.info for name, t in self._topics.items()}

    def add_topic(self, name: str, type_name: str, offered_qos_profiles: Iterable[Mapping[str, Any]] = (),
                  definition: str | None = None, type_hash: str | None = None) -> TopicInfo:
        """Register a topic: schema (full ros2msg definition) and channel with rosbag2 metadata.

        name: topic name ("/imu"). type_name: "pkg/msg/Type" ("pkg/Type" accepted). offered_qos_profiles:
        the publishers' profiles (:mod:`.qos` dicts). definition/type_hash: given explicitly for types whose
        interface files are not installed; otherwise looked up (:mod:`.msgdefs`). A missing definition
        is recorded as an empty schema with a warning (readers then cannot decode that topic).
        Registering an existing topic again is a no-op returning the existing info."""
        self._check_open()
        if name in self._topics:
            return self._topics[name].info
        type_name = msgdefs.normalize_type_name(type_name)
        if definition is None:
            try:
                definition = msgdefs.message_definition(type_name)
            except (msgdefs.DefinitionNotFoundError, RecursionError) as exc:
                definition = ""
                self.warnings.append(f"{name}: no message definition for {type_name} ({exc})")
        if type_hash is None:
            try:
                type_hash = msgdefs.type_description_hash(type_name)
            except msgdefs.DefinitionNotFoundError:
                type_hash = ""
        info = TopicInfo(name, type_name, [dict(p) for p in offered_qos_profiles], type_hash, 0)
        topic = _Topic(info, definition)
        self._topics[name] = topic
        assert self._file is not None
        self._register(self._file, topic)
        return info

    def write(self, topic: str, log_time_ns: int, data: bytes, publish_time_ns: int | None = None) -> None:
        """Append one serialized message (CDR bytes, unchanged) to ``topic`` at ``log_time_ns``.

        May close a chunk (then flush + fsync) or start a new file (split). Raises KeyError for a topic
        not registered with :meth:`add_topic`."""
        self._check_open()
        t = self._topics[topic]
        f = self._file
        assert f is not None
        size = len(data) + len(topic) + _MESSAGE_RECORD_OVERHEAD_BYTES
        if f.message_count and self._should_split(f, log_time_ns, size):
            self._close_file()
            self._open_file()
            f = self._file
            assert f is not None
        seq = f.sequence.get(topic, 0) + 1
        f.sequence[topic] = seq
        f.writer.add_message(channel_id=f.channel_ids[topic], log_time=int(log_time_ns), data=data,
                             publish_time=int(log_time_ns if publish_time_ns is None else publish_time_ns),
                             sequence=seq & 0xFFFFFFFF)
        if f.message_count == 0:
            f.start_ns = f.end_ns = int(log_time_ns)
        else:
            f.start_ns = min(f.start_ns, int(log_time_ns))
            f.end_ns = max(f.end_ns, int(log_time_ns))
        f.message_count += 1
        f.message_bytes += size
        t.info.message_count += 1
        self.message_count += 1
        self._pending_bytes += size
        if self._oldest_unflushed is None:
            self._oldest_unflushed = self._monotonic()
        pos = f.stream.tell()
        if pos != f.last_pos:  # the writer closed a chunk and wrote it: make it durable now
            self._sync(f)
            self._chunk_done(f)

    def seconds_until_flush(self) -> float | None:
        """Wall seconds until the open chunk must be flushed; None when nothing is pending or never."""
        if self._oldest_unflushed is None or self.options.flush_interval_s <= 0:
            return None
        return max(0.0, self._oldest_unflushed + self.options.flush_interval_s - self._monotonic())

    def flush_if_due(self) -> bool:
        """Flush the open chunk if its oldest message waited ``flush_interval_s``; True if flushed."""
        wait = self.seconds_until_flush()
        if wait is not None and wait <= 0.0:
            self.flush()
            return True
        return False

    def flush(self) -> None:
        """Close the open chunk (if it holds messages), write it, flush and fsync the file."""
        self._check_open()
        f = self._file
        assert f is not None
        if self._oldest_unflushed is None:
            return
        f.writer.flush()  # closes the open chunk, writes it out and flushes the stream (mcap >= 1.6)
        self._sync(f)
        self._chunk_done(f)

    def metadata(self) -> BagMetadata:
        """Snapshot of the bag metadata (files so far, including the open one, and topic counts)."""
        files = list(self._files)
        if self._file is not None:
            files.append(self._file_info(self._file))
        topics = [TopicInfo(t.info.name, t.info.type, [dict(p) for p in t.info.offered_qos_profiles],
                            t.info.type_description_hash, t.info.message_count) for t in self._topics.values()]
        return BagMetadata(files=files, topics=topics)

    def close(self) -> BagMetadata:
        """Finish the current file (rosbag2 metadata record, summary), write metadata.yaml; idempotent."""
        if self._closed:
            return self._final
        self._close_file()
        self._closed = True
        self._final = BagMetadata(files=list(self._files), topics=[t.info for t in self._topics.values()])
        write_metadata(self.bag_dir, self._final, fsync=self.options.fsync)
        return self._final

    # -- internals --------------------------------------------------------------------------------
    def _check_open(self) -> None:
        if self._closed:
            raise RuntimeError(f"{self.bag_dir}: bag already closed")

    def _chunk_done(self, f: _File) -> None:
        self._pending_bytes = 0
        self._oldest_unflushed = None
        self.chunks_written += 1
        f.chunks += 1

    def _should_split(self, f: _File, log_time_ns: int, size: int) -> bool:
        o = self.options
        if o.split_duration_s > 0 and log_time_ns - f.start_ns >= int(o.split_duration_s * 1e9):
            return True
        if o.split_size_bytes > 0:
            overhead = self._close_overhead(f)
            if f.stream.tell() + self._pending_bytes + size + overhead > o.split_size_bytes:
                # A limit smaller than the per-file overhead (schemas, summary, metadata) cannot be met:
                # splitting after every message would only multiply that overhead. Require at least as many
                # message bytes as overhead bytes per file (half the file useful), and say so once.
                if f.message_bytes >= overhead:
                    return True
                if not self._warned_split:
                    self._warned_split = True
                    self.warnings.append(
                        f"split_size_bytes {o.split_size_bytes} is too small for this bag's per-file overhead "
                        f"(about {overhead} bytes of schemas, indexes and metadata); files will exceed it")
        return False

    def _close_overhead(self, f: _File) -> int:
        """Upper estimate of the bytes still to come when the file is closed after this chunk.

        Summary (schemas and channels repeated, one chunk index per chunk, statistics, offsets, footer),
        the open chunk's message indexes (16 bytes per message) and the rosbag2 metadata record (about
        1 kB per topic with its QoS YAML, 150 bytes per file listed)."""
        n_topics = max(1, len(self._topics))
        chunk_index = 80 + 10 * n_topics
        return (f.record_bytes + (f.chunks + 1) * chunk_index + 16 * (self._pending_bytes // 32 + 1)
                + 15 * n_topics + 1200 * n_topics + 160 * (len(self._files) + 1) + 600)

    def _file_info(self, f: _File) -> FileInfo:
        return FileInfo(f.path.name, f.start_ns if f.message_count else 0,
                        (f.end_ns - f.start_ns) if f.message_count else 0, f.message_count)

    def _open_file(self) -> None:
        path = self.bag_dir / f"{self.name}_{len(self._files)}.mcap"
        stream = open(path, "wb")  # noqa: SIM115 - closed in _close_file
        writer = Writer(stream, chunk_size=self.options.chunk_size_bytes,
                        compression=_COMPRESSION[self.options.compression])
        writer.start(profile=PROFILE, library=LIBRARY)
        f = _File(path=path, stream=stream, writer=writer)
        self._current_path = path
        for topic in self._topics.values():
            self._register(f, topic)
        f.last_pos = stream.tell()
        self._file = f
        self._pending_bytes = 0
        self._oldest_unflushed = None
        write_metadata(self.bag_dir, self.metadata(), fsync=self.options.fsync)

    def _register(self, f: _File, topic: _Topic) -> None:
        info = topic.info
        if info.type not in f.schema_ids:
            data = topic.definition.encode()
            f.schema_ids[info.type] = f.writer.register_schema(name=info.type, encoding=SCHEMA_ENCODING, data=data)
            f.record_bytes += 9 + 2 + 12 + len(info.type) + len(SCHEMA_ENCODING) + len(data)
        metadata = {"offered_qos_profiles": profiles_to_yaml(info.offered_qos_profiles),
                    "topic_type_hash": info.type_description_hash}
        f.channel_ids[info.name] = f.writer.register_channel(
            topic=info.name, message_encoding=MESSAGE_ENCODING, schema_id=f.schema_ids[info.type],
            metadata=metadata)
        f.record_bytes += 9 + 4 + 16 + len(info.name) + len(MESSAGE_ENCODING) + sum(
            8 + len(k) + len(v) for k, v in metadata.items())

    def _sync(self, f: _File) -> None:
        f.stream.flush()
        if self.options.fsync:
            os.fsync(f.stream.fileno())
        f.last_pos = f.stream.tell()

    def _close_file(self) -> None:
        f = self._file
        if f is None:
            return
        self._file = None
        info = self._file_info(f)
        self._files.append(info)
        meta = BagMetadata(files=list(self._files), topics=[t.info for t in self._topics.values()])
        f.writer.add_metadata("rosbag2", {"serialized_metadata": meta.serialized()})
        f.writer.finish()
        self._sync(f)
        f.stream.close()
