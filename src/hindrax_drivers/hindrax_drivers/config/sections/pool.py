"""``pool.*``: the pool box and the vehicle's start pose ([Hindrax-Drag] §4).

The section's schema (:data:`SCHEMA`), its optional keys (:data:`OPTIONAL`) and the checks that name one of its keys
(:func:`cross_checks`); :mod:`hindrax_drivers.config.sections` joins the sections.
"""
from __future__ import annotations

import math
from typing import Any, Mapping

from ..spec import ConfigIssue, Spec, real, vector

SCHEMA: dict[str, Spec] = {
    "pool.length_m": real("pool length (north, x), m", 1.0, 200.0),
    "pool.width_m": real("pool width (east, y), m", 1.0, 200.0),
    "pool.depth_m": real("water depth, m", 0.3, 100.0),
    "pool.margin_m": real("keep-out margin from walls and floor for manoeuvres, m", 0.0, 10.0),
    "pool.start_position_ned_m": vector("vehicle start position (north, east, down) from the pool corner, m", 3,
                                        -1.0, 200.0),
    "pool.start_heading_rad": real("vehicle start heading, rad (NED yaw)", -math.pi, math.pi),
}

#: Optional keys (prefixes): absent is fine; present must validate. Every other key of :data:`SCHEMA` is required.
OPTIONAL: tuple[str, ...] = ()


def cross_checks(c: Mapping[str, Any]) -> list[ConfigIssue]:
    """None: every ``pool.*`` key is checked by its own range."""
    return []
