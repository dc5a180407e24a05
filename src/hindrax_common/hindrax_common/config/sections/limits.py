"""``limits.*``: the identification's own abort limits (docs/architecture.md §8)."""
from __future__ import annotations

import math
from typing import Any, Mapping

from ..spec import ConfigIssue, real, section

SCHEMA, OPTIONAL = section("limits", {
    "max_depth_m": real("abort below this depth, m", 0.0, 100.0),
    "min_altitude_m": real("abort closer than this to the floor, m", 0.0, 10.0),
    "max_roll_rad": real("abort beyond this roll, rad", 0.0, math.pi),
    "max_pitch_rad": real("abort beyond this pitch, rad", 0.0, math.pi / 2),
})


def cross_checks(c: Mapping[str, Any]) -> list[ConfigIssue]:
    """``limits.max_depth_m`` at most the pool's depth."""
    if "pool.depth_m" in c and "limits.max_depth_m" in c and c["limits.max_depth_m"] > c["pool.depth_m"]:
        return [ConfigIssue("limits.max_depth_m", c["limits.max_depth_m"],
                            f"at most pool.depth_m ({c['pool.depth_m']:g})")]
    return []
