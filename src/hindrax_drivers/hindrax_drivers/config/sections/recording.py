"""``recording.*``: the MCAP recorder (docs/architecture.md §7).

The section's schema (:data:`SCHEMA`), its optional keys (:data:`OPTIONAL`) and the checks that name one of its keys
(:func:`cross_checks`); :mod:`hindrax_drivers.config.sections` joins the sections.
"""
from __future__ import annotations

from typing import Any, Mapping

from ..spec import STRS, ConfigIssue, Spec, integer, real, text

SCHEMA: dict[str, Spec] = {
    "recording.output_root": text("directory new bags are created in"),
    "recording.compression": text("chunk compression", ("zstd", "lz4", "none")),
    "recording.chunk_size_bytes": integer("MCAP chunk size, bytes", 1024, 64 * 1024 * 1024),
    "recording.split_size_bytes": integer("start a new file beyond this size, bytes (0 = never)", 0, 2**40),
    "recording.split_duration_s": real("start a new file after this duration, s (0 = never)", 0.0, 86400.0),
    "recording.flush_interval_s": real("close and fsync the open chunk once its oldest message is this old, s "
                                       "(bounds the data lost on power loss; 0 = only when the chunk is full)",
                                       0.0, 3600.0),
    "recording.min_free_disk_mb": real("stop recording cleanly (bag finished) when the free space of the bag's "
                                       "filesystem falls below this, MB (1e6 bytes; 0 = no check)", 0.0, 1e7),
}
SCHEMA["recording.topics"] = Spec(STRS, "topics recorded by default (empty list not allowed by ROS: omit the key "
                                         "to record all topics)")

#: Optional keys (prefixes): absent is fine; present must validate. Every other key of :data:`SCHEMA` is required.
OPTIONAL: tuple[str, ...] = ("recording.topics",)


def cross_checks(c: Mapping[str, Any]) -> list[ConfigIssue]:
    """None: every ``recording.*`` key is checked by its own range."""
    return []
