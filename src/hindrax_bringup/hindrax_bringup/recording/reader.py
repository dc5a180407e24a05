"""Reading bags: raw CDR messages in log-time order, decoded messages.

A *bag* is a rosbag2 directory (metadata.yaml + ``*.mcap``) or a single ``.mcap`` file. Files are read
in the order of ``relative_file_paths`` (split files are consecutive in time); a directory without a
usable metadata.yaml falls back to its ``*.mcap`` files sorted by their ``_<n>`` index.

- :class:`BagReader` ``.messages(topics, start_ns, end_ns)`` yields :class:`RawMessage` (CDR bytes
  unchanged) in ascending log time, using the MCAP chunk indexes;
- ``.decoded(...)`` decodes with ``mcap_ros2`` from the bag's own ``ros2msg`` schemas, so custom types
  decode without their Python package.

A file without a summary (recorder killed, not yet recovered) is read sequentially up to its last
complete record (:func:`hindrax_bringup.recording.recover.iter_file_records`) and flagged in
:attr:`BagReader.truncated_files`; run ``hindrax bag recover BAG`` to repair it.

Errors: ``FileNotFoundError`` (no bag at the path), :class:`BagError` (not a readable bag)."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, Iterator

from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Channel, Message, Schema

from hindrax_common.cdr import msgdefs
from . import recover as _recover
from .metadata import MetadataError, read_metadata
from .msgtypes import TypeNotInstalledError, message_class


class BagError(ValueError):
    """The path exists but is not a readable rosbag2/MCAP bag."""


@dataclass(frozen=True)
class RawMessage:
    """One recorded message: topic, ``pkg/msg/Type``, log/publish time (ns since epoch), CDR bytes."""

    topic: str
    type: str
    log_time_ns: int
    publish_time_ns: int
    data: bytes


@dataclass
class ChannelInfo:
    """A topic as found in the MCAP files: type, full definition, channel metadata, message encoding."""

    topic: str
    type: str
    schema_encoding: str
    definition: str
    metadata: dict[str, str]
    message_count: int = 0
    message_encoding: str = "cdr"


def bag_files(path: str | Path) -> list[Path]:
    """MCAP files of a bag (directory or single file), in recording order. Raises FileNotFoundError/BagError."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such bag (directory or .mcap file)")
    if path.is_file():
        return [path]
    try:
        meta = read_metadata(path)
        files = [path / Path(p).name for p in meta.relative_file_paths]
        present = [f for f in files if f.is_file()]
    except MetadataError:
        present = []
    # metadata.yaml may be stale after a crash (written before the last split): add unlisted files
    listed = {f.name for f in present}
    extra = [f for f in sorted(path.glob("*.mcap"), key=_recover.file_index) if f.name not in listed]
    files = present + extra
    if not files:
        raise BagError(f"{path}: no .mcap files")
    return files


class BagReader:
    """Read-only access to a bag's topics and messages (see module docstring)."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.files = bag_files(self.path)
        self.truncated_files: list[Path] = []
        self.channels: dict[str, ChannelInfo] = {}
        self._summaries: dict[Path, Any] = {}
        self.start_ns: int | None = None
        """First message log time of the bag (ns since epoch), None for an empty bag."""
        self.end_ns: int | None = None
        """Last message log time of the bag (ns since epoch), None for an empty bag."""
        for f in self.files:
            self._scan(f)

    def _span(self, t0: int, t1: int) -> None:
        self.start_ns = t0 if self.start_ns is None else min(self.start_ns, t0)
        self.end_ns = t1 if self.end_ns is None else max(self.end_ns, t1)

    def _scan(self, f: Path) -> None:
        try:
            with open(f, "rb") as fh:
                summary = make_reader(fh).get_summary()
        except (McapError, OSError, ValueError, EOFError) as exc:
            if not f.is_file():
                raise BagError(f"{f}: cannot read ({exc})") from exc
            summary = None
        if summary is None or summary.statistics is None:
            self.truncated_files.append(f)
            messages = 0
            try:
                for ch, schema, msg in _stream_records(f):
                    self._add_channel(ch, schema, int(msg is not None))
                    if msg is not None:
                        messages += 1
                        self._span(msg.log_time, msg.log_time)
            except _recover.RecoverError as exc:  # not MCAP at all (empty file, wrong magic)
                raise BagError(str(exc)) from exc
            if not messages:
                raise BagError(f"{f}: truncated MCAP without a summary and without one complete message "
                               "(nothing to read)")
            self._summaries[f] = None
            return
        self._summaries[f] = summary
        if summary.statistics.message_count:
            self._span(summary.statistics.message_start_time, summary.statistics.message_end_time)
        for cid, ch in summary.channels.items():
            self._add_channel(ch, summary.schemas.get(ch.schema_id),
                              summary.statistics.channel_message_counts.get(cid, 0))

    def _add_channel(self, ch: Channel, schema: Schema | None, count: int) -> None:
        info = self.channels.get(ch.topic)
        if info is None:
            info = ChannelInfo(ch.topic, schema.name if schema else "", schema.encoding if schema else "",
                               schema.data.decode(errors="replace") if schema else "", dict(ch.metadata),
                               message_encoding=ch.message_encoding)
            self.channels[ch.topic] = info
        info.message_count += count

    def summary(self, f: Path) -> Any:
        """The MCAP summary (``mcap.records`` Summary) of file ``f`` of :attr:`files`; None for a file without
        one (truncated: see :attr:`truncated_files`)."""
        return self._summaries.get(f)

    @property
    def topics(self) -> dict[str, str]:
        """Topic name -> ``pkg/msg/Type``."""
        return {t: c.type for t, c in self.channels.items()}

    def installed_class(self, topic: str) -> Any | None:
        """The installed Python class of ``topic``'s type when it has the wire layout the bag recorded
        (:func:`.msgdefs.matches_installed`), so rclpy's C deserializer can decode the records; None when the type
        is not installed or has changed since (e.g. a bag from before ``ThrusterPwm.output_state``): decode
        those with :meth:`decoded`, from the bag's own definition. KeyError for a topic not in the bag."""
        ch = self.channels[topic]
        try:
            cls = message_class(ch.type)
        except (TypeNotInstalledError, ValueError):
            return None
        same = msgdefs.matches_installed(ch.type, ch.definition, ch.metadata.get("topic_type_hash"))
        return cls if same else None

    def installed_messages(self, topics: Iterable[str], lean: bool = False) -> Iterator[tuple[RawMessage, Any]]:
        """(raw message, instance of the installed class) pairs of ``topics`` in log-time order.

        Records whose type has the installed layout (:meth:`installed_class`) go through rclpy's C
        deserializer (``lean``: :func:`hindrax_common.cdr.lean_cdr.cdr_decoder`, read-only objects of
        the same fields, twice as fast);
        records of a type that changed since the bag was written are decoded from the bag's stored definition
        (:meth:`decoded`) and copied into the installed class field by field (:func:`.msgtypes.from_decoded`:
        a field the bag lacks keeps the installed default). One rule for every reader of old bags.
        Raises :class:`.msgtypes.TypeNotInstalledError` for a type that is not installed, KeyError for a topic
        not in the bag, :class:`BagError` for a stored definition that does not parse."""
        from rclpy.serialization import deserialize_message

        from hindrax_common.cdr.lean_cdr import cdr_decoder
        from .msgtypes import from_decoded

        wanted = list(topics)
        classes = {t: self.installed_class(t) for t in wanted}
        changed = {t: message_class(self.channels[t].type) for t, c in classes.items() if c is None}
        decode = {t: cdr_decoder(c) if lean else (lambda data, c=c: deserialize_message(data, c))
                  for t, c in classes.items() if c is not None}
        for raw, obj in (self.decoded(wanted) if changed else ((raw, None) for raw in self.messages(wanted))):
            dec = decode.get(raw.topic)
            yield raw, dec(raw.data) if dec is not None else from_decoded(changed[raw.topic], obj)

    def messages(self, topics: Iterable[str] | None = None, start_ns: int | None = None,
                 end_ns: int | None = None) -> Iterator[RawMessage]:
        """Raw messages of ``topics`` (all when None) with start_ns <= log time < end_ns, in log-time order."""
        wanted = set(topics) if topics is not None else None
        for f in self.files:
            yield from self.file_messages(f, wanted, start_ns, end_ns)

    def file_messages(self, f: Path, topics: Iterable[str] | None = None, start_ns: int | None = None,
                      end_ns: int | None = None) -> Iterator[RawMessage]:
        """:meth:`messages` of one file ``f`` of :attr:`files` (log-time order within the file)."""
        wanted = set(topics) if topics is not None else None
        summary = self._summaries.get(f)
        if summary is None:
            yield from _sorted_stream_messages(f, wanted, start_ns, end_ns)
            return
        with open(f, "rb") as fh:
            for schema, channel, msg in make_reader(fh).iter_messages(
                    topics=None if wanted is None else sorted(wanted), log_time_order=True,
                    starting_at=None if start_ns is None else int(start_ns),
                    ending_before=None if end_ns is None else int(end_ns)):
                yield RawMessage(channel.topic, schema.name if schema else "", msg.log_time, msg.publish_time, msg.data)

    def decoded(self, topics: Iterable[str] | None = None) -> Iterator[tuple[RawMessage, Any]]:
        """(raw message, decoded object) pairs, decoded by mcap_ros2 from the stored schemas
        (``mcap_ros2.decoder.DecoderFactory``, the decoder an ``mcap`` reader uses).

        Raises :class:`BagError` naming the topic when its schema is missing or cannot be parsed."""
        from mcap_ros2.decoder import DecoderFactory

        factory = DecoderFactory()
        decoders: dict[str, Any] = {}
        for m in self.messages(topics):
            dec = decoders.get(m.topic)
            if dec is None:
                ch = self.channels[m.topic]
                if ch.schema_encoding != "ros2msg" or not ch.definition:
                    raise BagError(f"{m.topic}: no ros2msg definition stored for {ch.type!r}; cannot decode")
                # one schema id per topic: the factory caches its decoders by schema id
                schema = Schema(id=len(decoders) + 1, name=ch.type, encoding=ch.schema_encoding,
                                data=ch.definition.encode())
                try:
                    dec = factory.decoder_for(ch.message_encoding, schema)
                except Exception as exc:  # noqa: BLE001 - any parser failure is a bad schema
                    raise BagError(f"{m.topic}: stored definition of {ch.type} does not parse ({exc})") from exc
                if dec is None:
                    raise BagError(f"{m.topic}: mcap_ros2 has no decoder for {ch.message_encoding!r} messages")
                decoders[m.topic] = dec
            yield m, dec(m.data)


def _stream_records(f: Path) -> Iterator[tuple[Channel, Schema | None, Message | None]]:
    """A file without summary, tolerant of truncation: (channel, its schema, None) at each channel
    record and (channel, schema, message) at each message of a channel seen before it."""
    schemas: dict[int, Schema] = {}
    chans: dict[int, Channel] = {}
    for rec in _recover.iter_file_records(f):
        if isinstance(rec, Schema):
            schemas[rec.id] = rec
        elif isinstance(rec, Channel):
            chans[rec.id] = rec
            yield rec, schemas.get(rec.schema_id), None
        elif isinstance(rec, Message) and rec.channel_id in chans:
            ch = chans[rec.channel_id]
            yield ch, schemas.get(ch.schema_id), rec


def _sorted_stream_messages(f: Path, wanted: set[str] | None, start_ns: int | None,
                            end_ns: int | None) -> Iterator[RawMessage]:
    """Messages of a file without summary, tolerant of truncation, in log-time order (stable)."""
    found = [RawMessage(ch.topic, schema.name if schema else "", m.log_time, m.publish_time, m.data)
             for ch, schema, m in _stream_records(f)
             if m is not None and (wanted is None or ch.topic in wanted)
             and (start_ns is None or m.log_time >= start_ns)
             and (end_ns is None or m.log_time < end_ns)]
    yield from sorted(found, key=lambda r: r.log_time_ns)
