"""``recording.*``: the MCAP recorder (docs/architecture.md §7)."""
from __future__ import annotations

from ..spec import STRS, Spec, integer, real, section, text

_KEYS: dict[str, Spec] = {
    "output_root": text("directory new bags are created in"),
    "compression": text("chunk compression", ("zstd", "lz4", "none")),
    "chunk_size_bytes": integer("MCAP chunk size, bytes", 1024, 64 * 1024 * 1024),
    "split_size_bytes": integer("start a new file beyond this size, bytes (0 = never)", 0, 2**40),
    "split_duration_s": real("start a new file after this duration, s (0 = never)", 0.0, 86400.0),
    "flush_interval_s": real("close and fsync the open chunk once its oldest message is this old, s "
                             "(bounds the data lost on power loss; 0 = only when the chunk is full)",
                             0.0, 3600.0),
    "min_free_disk_mb": real("stop recording cleanly (bag finished) when the free space of the bag's "
                             "filesystem falls below this, MB (1e6 bytes; 0 = no check)", 0.0, 1e7),
}
_KEYS["topics"] = Spec(STRS, "topics recorded by default (empty list not allowed by ROS: omit the key "
                              "to record all topics)")
SCHEMA, OPTIONAL = section("recording", _KEYS, optional=("topics",))
