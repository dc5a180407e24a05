"""``pool.*``: the pool box and the vehicle's start pose ([Hindrax-Drag] §4)."""
from __future__ import annotations

import math

from ..spec import real, section, vector

SCHEMA, OPTIONAL = section("pool", {
    "length_m": real("pool length (north, x), m", 1.0, 200.0),
    "width_m": real("pool width (east, y), m", 1.0, 200.0),
    "depth_m": real("water depth, m", 0.3, 100.0),
    "margin_m": real("keep-out margin from walls and floor for manoeuvres, m", 0.0, 10.0),
    "start_position_ned_m": vector("vehicle start position (north, east, down) from the pool corner, m", 3,
                                   -1.0, 200.0),
    "start_heading_rad": real("vehicle start heading, rad (NED yaw)", -math.pi, math.pi),
})
