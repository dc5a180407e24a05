"""Which topics a recording takes: an explicit list, a regular expression, or everything.

Pure. :class:`TopicSelection` is what the recorder node evaluates against the ROS graph on every poll,
so topics that appear after the recording started are picked up (docs/architecture.md §7)."""
from __future__ import annotations

import re
from dataclasses import dataclass, field


def _normalize(topic: str) -> str:
    topic = topic.strip()
    return topic if topic.startswith("/") else "/" + topic


def is_hidden(topic: str) -> bool:
    """True for hidden topics (a name segment starting with ``_``), which ``--all`` leaves out."""
    return any(seg.startswith("_") for seg in topic.split("/") if seg)


@dataclass(frozen=True)
class TopicSelection:
    """Topics to record.

    topics: explicit names (a leading "/" is added when missing). regex: Python regular expression matched with
    ``re.search`` against full topic names (in addition to ``topics``). all_topics: every non-hidden topic.
    exclude_regex: topics never recorded. Empty topics + empty regex + all_topics False selects nothing.

    Raises ValueError (one line) for an invalid regular expression."""

    topics: tuple[str, ...] = ()
    regex: str = ""
    all_topics: bool = False
    exclude_regex: str = ""
    _compiled: tuple = field(default=(), compare=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "topics", tuple(_normalize(t) for t in self.topics if t.strip()))
        compiled = []
        for label, pattern in (("topic regex", self.regex), ("exclude regex", self.exclude_regex)):
            try:
                compiled.append(re.compile(pattern) if pattern else None)
            except re.error as exc:
                raise ValueError(f"{label} {pattern!r} is not a valid regular expression: {exc}") from exc
        object.__setattr__(self, "_compiled", tuple(compiled))

    @property
    def empty(self) -> bool:
        return not (self.topics or self.regex or self.all_topics)

    def matches(self, topic: str) -> bool:
        """True when ``topic`` is to be recorded."""
        inc, exc = self._compiled
        if exc is not None and exc.search(topic):
            return False
        if topic in self.topics:
            return True
        if inc is not None and inc.search(topic):
            return True
        return self.all_topics and not is_hidden(topic)

    def describe(self) -> str:
        parts = []
        if self.all_topics:
            parts.append("all topics")
        if self.topics:
            parts.append("topics " + " ".join(self.topics))
        if self.regex:
            parts.append(f"regex {self.regex!r}")
        return ", ".join(parts) or "nothing"
