"""``control.*``: the depth/altitude, heading and velocity holds (hindrax_onboard control, docs/control.md §2-§3;
all optional)."""
from __future__ import annotations

from ..spec import real, section

SCHEMA, OPTIONAL = section("control", {
    "rate_hz": real("rate of the controller node's wrench, Hz (default 50)", 1.0, 200.0),
    "depth_bandwidth_rad_s": real("target bandwidth of the depth and altitude hold, rad/s (default 2)", 0.05, 20.0),
    "heading_bandwidth_rad_s": real("target bandwidth of the heading hold, rad/s (default 2)", 0.05, 20.0),
    "attitude_bandwidth_rad_s": real("target bandwidth of the roll and pitch holds, rad/s (default 2)", 0.05, 20.0),
    "velocity_bandwidth_rad_s": real("target bandwidth of the surge and sway velocity holds, rad/s (default 3)",
                                     0.05, 20.0),
    "damping_ratio": real("damping ratio of the reference models and the PID, default 1", 0.3, 2.0),
    "hold_fraction": real("share of each axis' authority the holds may use, default 0.6", 0.05, 1.0),
    "max_depth_rate_m_s": real("largest depth rate the reference model asks for, m/s (default 0.3)", 0.01, 2.0),
    "max_yaw_rate_rad_s": real("largest yaw rate the reference model asks for, rad/s (default 0.6)", 0.01, 5.0),
    "sensor_timeout_s": real("the controller stops when depth or attitude is older than this, s (default 0.5)",
                             0.05, 10.0),
}, optional=("",))
