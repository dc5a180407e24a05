"""Recovering bags whose recorder died (SIGKILL, power loss): rebuild summaries and metadata.yaml.

A killed recorder leaves ``<bag>_<n>.mcap`` without its summary/footer, possibly ending in a partial record (or, after a
power loss on some file systems, in zero-filled blocks), and a metadata.yaml with stale counts. Because the writer
fsyncs every finished chunk (:mod:`.writer`), everything but the chunk being filled is on disk.

:func:`iter_file_records` reads a file sequentially with the mcap library's stream reader, one complete record at a
time: it stops at the first record that runs past the end of the file, has an invalid opcode (0x00: zero fill) or is a
Footer/DataEnd; chunks are decompressed with CRC validation and a corrupt chunk is skipped. :func:`recover_file`
rewrites such a file as a complete MCAP (same schemas, channels with their metadata, messages, metadata records; new
chunk indexes, statistics, summary) via a temporary file and an atomic rename; :func:`recover_bag` does it for every
file of a bag and rebuilds metadata.yaml from the files themselves (topics, types, QoS, hashes, counts, times).

Errors: ``FileNotFoundError``; :class:`RecoverError` (a ``ValueError``) when a file is not MCAP at all."""
from __future__ import annotations

import io
import os
import re
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, Message, Metadata, Schema
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap.writer import CompressionType, Writer

from .metadata import BagMetadata, FileInfo, MetadataError, TopicInfo, read_metadata, write_metadata
from .qos import profiles_from_yaml

MAGIC = bytes([137, 77, 67, 65, 80, 48, 13, 10])
_VALID_OPCODES = {int(o) for o in Opcode}
_END_OPCODES = (Opcode.FOOTER, Opcode.DATA_END)
_COMPRESSION = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "": CompressionType.NONE}


class RecoverError(ValueError):
    """The file cannot be recovered (not an MCAP file)."""


@dataclass
class FileRecovery:
    """Result of recovering one file: counts and what was lost."""

    path: Path
    was_complete: bool
    message_count: int = 0
    chunks: int = 0
    corrupt_chunks: int = 0
    truncated_bytes: int = 0
    topics: dict[str, int] = field(default_factory=dict)

    def summary_line(self) -> str:
        if self.was_complete:
            return f"{self.path.name}: complete ({self.message_count} messages), left unchanged"
        return (f"{self.path.name}: recovered {self.message_count} messages in {self.chunks} chunks; "
                f"{self.truncated_bytes} trailing bytes discarded, {self.corrupt_chunks} corrupt chunks skipped")


def is_complete(path: str | Path) -> bool:
    """True when the file ends with a footer and magic and has a summary with statistics."""
    path = Path(path)
    try:
        with open(path, "rb") as f:
            f.seek(0, io.SEEK_END)
            if f.tell() < 2 * len(MAGIC):
                return False
            f.seek(-len(MAGIC), io.SEEK_END)
            if f.read(len(MAGIC)) != MAGIC:
                return False
            f.seek(0)
            summary = make_reader(f).get_summary()
            return summary is not None and summary.statistics is not None
    except (McapError, OSError, ValueError, struct.error, EOFError, StopIteration, UnicodeDecodeError):
        return False


def _raw_records(f, size: int) -> Iterator[tuple[int, int, bytes]]:
    """(opcode, end offset, header + body) of each complete record of the data section of open file ``f`` (``size``
    bytes), stopping at the first invalid opcode (zero fill), Footer/DataEnd or truncated record."""
    pos = len(MAGIC)
    while pos + 9 <= size:
        f.seek(pos)
        hdr = f.read(9)
        opcode, length = struct.unpack("<BQ", hdr)
        if opcode not in _VALID_OPCODES or opcode in _END_OPCODES or pos + 9 + length > size:
            return
        pos += 9 + length
        yield opcode, pos, hdr + f.read(length)


def _parse(raw: bytes) -> object:
    """The mcap record of one raw record (header + body). Raises McapError, struct.error, ..."""
    return next(iter(StreamReader(io.BytesIO(raw), skip_magic=True, emit_chunks=True).records))


_SUMMARY_OPCODES = (Opcode.MESSAGE_INDEX, Opcode.CHUNK_INDEX, Opcode.STATISTICS,
                    Opcode.SUMMARY_OFFSET, Opcode.ATTACHMENT_INDEX, Opcode.METADATA_INDEX)


def iter_file_records(path: str | Path, stats: FileRecovery | None = None) -> Iterator[object]:
    """Complete records of the data section of an MCAP file, tolerant of truncation (see module doc).

    Chunks are expanded into their Schema/Channel/Message records. Summary records are not yielded.
    ``stats`` (optional) receives chunk counts and the number of trailing bytes not read."""
    path = Path(path)
    size = path.stat().st_size
    with open(path, "rb") as f:
        if f.read(len(MAGIC)) != MAGIC:
            raise RecoverError(f"{path}: not an MCAP file (bad magic)")
        pos = len(MAGIC)
        for opcode, pos, raw in _raw_records(f, size):
            if opcode in _SUMMARY_OPCODES:
                continue
            try:
                rec = _parse(raw)
            except (McapError, struct.error, UnicodeDecodeError, StopIteration, ValueError):
                if stats is not None and opcode == Opcode.CHUNK:
                    stats.corrupt_chunks += 1
                continue
            if isinstance(rec, Chunk):
                try:
                    inner = breakup_chunk(rec, validate_crc=True)
                except Exception:  # noqa: BLE001 - zstd/lz4/CRC errors: the chunk is corrupt
                    if stats is not None:
                        stats.corrupt_chunks += 1
                    continue
                if stats is not None:
                    stats.chunks += 1
                yield from inner
            else:
                yield rec
        if stats is not None:
            stats.truncated_bytes = max(0, size - pos) if not _ends_complete(f, size, pos) else 0


def _ends_complete(f, size: int, pos: int) -> bool:
    if pos + 9 > size:
        return False
    f.seek(pos)
    opcode = f.read(1)
    return bool(opcode) and opcode[0] in _END_OPCODES


def _chunk_compression(path: Path) -> str:
    """Compression of the first chunk of a file ("zstd" when no chunk is readable)."""
    with open(path, "rb") as f:
        for opcode, _, raw in _raw_records(f, path.stat().st_size):
            if opcode == Opcode.CHUNK:
                try:
                    return _parse(raw).compression  # type: ignore[attr-defined]  # a Chunk
                except (McapError, struct.error, StopIteration, ValueError):
                    return "zstd"
    return "zstd"


def recover_file(path: str | Path, keep_original: bool = False) -> FileRecovery:
    """Rewrite a truncated MCAP file as a complete one in place (atomic rename).

    keep_original: keep the damaged file as ``<name>.truncated``; a complete file is left as it is.
    Returns a :class:`FileRecovery`. Raises FileNotFoundError, :class:`RecoverError`."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    if is_complete(path):
        res = FileRecovery(path, was_complete=True)
        with open(path, "rb") as f:
            summary = make_reader(f).get_summary()
        stats = summary.statistics
        res.message_count = stats.message_count
        res.chunks = stats.chunk_count
        for cid, n in stats.channel_message_counts.items():
            res.topics[summary.channels[cid].topic] = n
        return res
    res = FileRecovery(path, was_complete=False)
    compression = _COMPRESSION.get(_chunk_compression(path), CompressionType.ZSTD)
    tmp = path.with_name(path.name + ".recovering")
    schemas: dict[int, int] = {}
    channels: dict[int, int] = {}
    channel_topic: dict[int, str] = {}
    topic_infos: dict[str, TopicInfo] = {}
    t_first: int | None = None
    t_last = 0
    has_rosbag2_metadata = False
    with open(tmp, "wb") as out:
        w = Writer(out, chunk_size=1024 * 1024, compression=compression)
        w.start(profile="ros2", library="hindrax-recover")
        src_schemas: dict[int, Schema] = {}
        for rec in iter_file_records(path, res):
            if isinstance(rec, Schema):
                src_schemas[rec.id] = rec
                if rec.id not in schemas:
                    schemas[rec.id] = w.register_schema(rec.name, rec.encoding, rec.data)
            elif isinstance(rec, Channel):
                if rec.id not in channels:
                    sid = schemas.get(rec.schema_id, 0)
                    channels[rec.id] = w.register_channel(rec.topic, rec.message_encoding, sid, dict(rec.metadata))
                    channel_topic[rec.id] = rec.topic
                    if rec.topic not in topic_infos:
                        schema = src_schemas.get(rec.schema_id)
                        topic_infos[rec.topic] = _topic_info(rec, schema.name if schema else "")
            elif isinstance(rec, Message):
                cid = channels.get(rec.channel_id)
                if cid is None:
                    continue  # channel record lost: the message cannot be attributed
                w.add_message(cid, rec.log_time, rec.data, rec.publish_time, rec.sequence)
                res.message_count += 1
                t = channel_topic[rec.channel_id]
                res.topics[t] = res.topics.get(t, 0) + 1
                topic_infos[t].message_count += 1
                t_first = rec.log_time if t_first is None else min(t_first, rec.log_time)
                t_last = max(t_last, rec.log_time)
            elif isinstance(rec, Metadata):
                if rec.name == "rosbag2":
                    has_rosbag2_metadata = True
                w.add_metadata(rec.name, dict(rec.metadata))
        if not has_rosbag2_metadata:
            file_info = FileInfo(path.name, t_first or 0, (t_last - t_first) if t_first is not None else 0,
                                 res.message_count)
            meta = BagMetadata(files=[file_info], topics=list(topic_infos.values()))
            w.add_metadata("rosbag2", {"serialized_metadata": meta.serialized()})
        w.finish()
        out.flush()
        os.fsync(out.fileno())
    if keep_original:
        os.replace(path, path.with_name(path.name + ".truncated"))
    os.replace(tmp, path)
    return res


def _topic_info(ch: Channel, type_name: str) -> TopicInfo:
    try:
        qos = profiles_from_yaml(ch.metadata.get("offered_qos_profiles", ""))
    except Exception:  # noqa: BLE001 - unreadable QoS is recorded as none
        qos = []
    return TopicInfo(ch.topic, type_name, qos, ch.metadata.get("topic_type_hash", ""), 0, ch.message_encoding or "cdr")


def metadata_from_files(files: list[Path]) -> BagMetadata:
    """Bag metadata computed from complete MCAP files alone (topics, QoS, hashes, counts, times)."""
    topics: dict[str, TopicInfo] = {}
    infos: list[FileInfo] = []
    for p in files:
        with open(p, "rb") as f:
            summary = make_reader(f).get_summary()
        if summary is None or summary.statistics is None:
            raise RecoverError(f"{p}: no summary; recover the file first")
        st = summary.statistics
        n = st.message_count
        infos.append(FileInfo(p.name, st.message_start_time if n else 0,
                              (st.message_end_time - st.message_start_time) if n else 0, n))
        for cid, ch in sorted(summary.channels.items()):
            schema = summary.schemas.get(ch.schema_id)
            t = topics.get(ch.topic)
            if t is None:
                t = topics[ch.topic] = _topic_info(ch, schema.name if schema else "")
            t.message_count += st.channel_message_counts.get(cid, 0)
    return BagMetadata(files=infos, topics=list(topics.values()))


def file_index(p: Path) -> tuple[int, str]:
    """Sort key of a bag's split file ``<bag>_<n>.mcap``: (n, name); n = -1 without ``_<n>``."""
    m = re.search(r"_(\d+)\.mcap$", p.name)
    return (int(m.group(1)) if m else -1, p.name)


def recover_bag(bag_path: str | Path, keep_original: bool = False) -> tuple[BagMetadata, list[FileRecovery]]:
    """Recover every ``*.mcap`` of a bag directory (or one file) and rewrite metadata.yaml.

    Files are taken from the directory itself (metadata.yaml may be stale or missing), in ``_<n>``
    order. Returns (new metadata, per-file results). Raises FileNotFoundError, :class:`RecoverError`."""
    bag_path = Path(bag_path)
    if not bag_path.exists():
        raise FileNotFoundError(f"{bag_path}: no such bag")
    if bag_path.is_file():
        res = recover_file(bag_path, keep_original=keep_original)
        return metadata_from_files([bag_path]), [res]
    files = sorted(bag_path.glob("*.mcap"), key=file_index)
    if not files:
        raise RecoverError(f"{bag_path}: no .mcap files")
    results = [recover_file(f, keep_original=keep_original) for f in files]
    meta = metadata_from_files(files)
    try:  # keep what the old metadata knew that the files cannot tell (custom data, distro)
        old = read_metadata(bag_path)
        meta.custom_data = old.custom_data
        meta.ros_distro = old.ros_distro or meta.ros_distro
    except MetadataError:
        pass
    write_metadata(bag_path, meta)
    return meta, results
