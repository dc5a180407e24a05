"""``hindrax bag info``: what a bag holds (topics, types, counts, rates, duration, size).

Counts and times come from the MCAP summaries (statistics records), not from metadata.yaml, so the figures are right
even when metadata.yaml is stale; a file without summary is counted by reading it sequentially and reported as
truncated. Rates are ``(count - 1) / (last - first log time)`` per topic (Hz), i.e. the mean message rate over the
topic's own span; a topic with fewer than 2 messages has rate 0.

Pure (no ROS runtime). Errors: as :class:`hindrax_bringup.recording.reader.BagReader`."""
from __future__ import annotations

import datetime as _dt
from dataclasses import dataclass, field
from pathlib import Path

from mcap.reader import make_reader

from .reader import BagReader


@dataclass
class TopicSummary:
    """One topic: type, message count, first/last log time (ns since epoch), mean rate (Hz), QoS text."""

    name: str
    type: str
    message_count: int
    first_ns: int
    last_ns: int
    rate_hz: float
    reliability: str = ""


@dataclass
class BagInfo:
    """Summary of a bag (see module docstring); times in ns since the epoch, sizes in bytes."""

    path: Path
    files: list[Path]
    size_bytes: int
    message_count: int
    start_ns: int
    end_ns: int
    topics: list[TopicSummary] = field(default_factory=list)
    truncated_files: list[Path] = field(default_factory=list)
    compression: str = ""

    @property
    def duration_s(self) -> float:
        return (self.end_ns - self.start_ns) / 1e9 if self.message_count else 0.0


def bag_info(path: str | Path) -> BagInfo:
    """Read the summary of a bag directory or ``.mcap`` file (see module docstring)."""
    reader = BagReader(path)
    first: dict[str, int] = {}
    last: dict[str, int] = {}
    compression = ""
    for f in reader.files:
        summary = reader.summary(f)
        if summary is not None:
            if summary.chunk_indexes and not compression:
                compression = summary.chunk_indexes[0].compression or "none"
        else:
            for m in reader.file_messages(f):
                first[m.topic] = min(first.get(m.topic, m.log_time_ns), m.log_time_ns)
                last[m.topic] = max(last.get(m.topic, m.log_time_ns), m.log_time_ns)
    _exact_times(reader, first, last)
    topics = []
    for name, ch in sorted(reader.channels.items()):
        n = ch.message_count
        t0, t1 = first.get(name, 0), last.get(name, 0)
        rate = (n - 1) / ((t1 - t0) / 1e9) if n >= 2 and t1 > t0 else 0.0
        qos = ch.metadata.get("offered_qos_profiles", "")
        rel = "best_effort" if "best_effort" in qos else "reliable" if "reliable" in qos else ""
        topics.append(TopicSummary(name, ch.type, n, t0, t1, rate, rel))
    total = sum(t.message_count for t in topics)
    starts = [t.first_ns for t in topics if t.message_count]
    ends = [t.last_ns for t in topics if t.message_count]
    return BagInfo(Path(path), list(reader.files), sum(f.stat().st_size for f in reader.files), total,
                   min(starts) if starts else 0, max(ends) if ends else 0, topics, list(reader.truncated_files),
                   compression)


def _exact_times(reader: BagReader, first: dict[str, int], last: dict[str, int]) -> None:
    """First/last log time per topic of the summarised files (reads the first and last chunk of
    each), merged into ``first`` and ``last``."""
    for f in reader.files:
        summary = reader.summary(f)
        if summary is None:
            continue
        with open(f, "rb") as fh:
            r = make_reader(fh)
            for topic in {c.topic for c in summary.channels.values()}:
                for _s, _c, m in r.iter_messages(topics=[topic], log_time_order=True):
                    first[topic] = min(first.get(topic, m.log_time), m.log_time)
                    break
                for _s, _c, m in r.iter_messages(topics=[topic], log_time_order=True, reverse=True):
                    last[topic] = max(last.get(topic, m.log_time), m.log_time)
                    break


def format_bag_info(info: BagInfo) -> str:
    """Human-readable multi-line text (the output of ``hindrax bag info``)."""
    def stamp(ns: int) -> str:
        return _dt.datetime.fromtimestamp(ns / 1e9, tz=_dt.timezone.utc).strftime("%Y-%m-%d %H:%M:%S.%f UTC")

    lines = [
        f"Bag:          {info.path}",
        f"Files:        {', '.join(f.name for f in info.files)}",
        f"Size:         {_size(info.size_bytes)}",
        f"Storage:      mcap (chunk compression {info.compression or 'none'})",
        f"Duration:     {info.duration_s:.3f} s",
        f"Start:        {stamp(info.start_ns) if info.message_count else '-'}",
        f"End:          {stamp(info.end_ns) if info.message_count else '-'}",
        f"Messages:     {info.message_count}",
        f"Topics:       {len(info.topics)}",
    ]
    if info.truncated_files:
        lines.append("WARNING:      truncated (no summary): " + ", ".join(f.name for f in info.truncated_files)
                     + "; run `hindrax bag recover " + str(info.path) + "`")
    width = max((len(t.name) for t in info.topics), default=5)
    twidth = max((len(t.type) for t in info.topics), default=4)
    lines.append(f"  {'topic':<{width}}  {'type':<{twidth}}  {'count':>8}  {'rate_hz':>9}  qos")
    for t in info.topics:
        lines.append(f"  {t.name:<{width}}  {t.type:<{twidth}}  {t.message_count:>8}  {t.rate_hz:>9.2f}  "
                     f"{t.reliability}")
    return "\n".join(lines)


def _size(n: int) -> str:
    for unit in ("B", "KiB", "MiB", "GiB"):
        if n < 1024 or unit == "GiB":
            return f"{n:.1f} {unit}" if unit != "B" else f"{n} B"
        n /= 1024
