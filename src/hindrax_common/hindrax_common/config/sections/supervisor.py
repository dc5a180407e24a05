"""``supervisor.*``: the safety supervisor (:mod:`hindrax_bringup.supervisor`), the last line after the
identification's own limits."""
from __future__ import annotations

import math
from typing import Any, Mapping

from ..spec import ConfigIssue, real, section, text

SCHEMA, OPTIONAL = section("supervisor", {
    "check_rate_hz": real("rate of the supervisor's rate and run-time checks, Hz", 1.0, 200.0),
    "rate_window_s": real("window the sensor rates are measured over (at most "
                          "supervisor.reaction_time_s), s", 0.2, 60.0),
    "max_sample_age_s": real("a sensor sample whose header stamp is further than this from the supervisor's "
                             "time on arrival (older, or ahead) is not alive: not counted, not used, s",
                             0.05, 10.0),
    "max_identical_s": real("a sensor stream bit-identical (header stamp aside) for longer than this is "
                            "frozen: its samples are not alive (sensor noise changes every reading within "
                            "a few samples), s", 0.1, 10.0),
    "reaction_time_s": real("longest time a failed sensor (silent, stale or frozen) may go unnoticed while "
                            "armed; bounds supervisor.rate_window_s, max_invalid_dvl_s, max_sample_age_s and "
                            "max_identical_s, s",
                            0.1, 10.0),
    "min_rate.dvl_hz": real("minimum dvl/data rate while armed, Hz (0 = not watched)", 0.0, 1000.0),
    "min_rate.altimeter_hz": real("minimum ping/altitude rate while armed, Hz (0 = not watched)", 0.0, 1000.0),
    "min_rate.pressure_hz": real("minimum pressure/depth rate while armed, Hz (0 = not watched)", 0.0, 1000.0),
    "min_rate.imu_hz": real("minimum imu/data_raw rate while armed, Hz (0 = not watched)", 0.0, 2000.0),
    "max_invalid_dvl_s": real("armed with no valid DVL velocity for this long -> trip (the cage's dead "
                              "reckoning is frozen meanwhile), s", 0.1, 60.0),
    "rate_check_disabled.dvl": text("why supervisor.min_rate.dvl_hz is 0 (required with 0, refused otherwise)"),
    "rate_check_disabled.altimeter": text("why supervisor.min_rate.altimeter_hz is 0 (required with 0)"),
    "rate_check_disabled.pressure": text("why supervisor.min_rate.pressure_hz is 0 (required with 0)"),
    "rate_check_disabled.imu": text("why supervisor.min_rate.imu_hz is 0 (required with 0)"),
    "max_depth_m": real("disarm below this depth (pressure port), m", 0.0, 100.0),
    "min_altitude_m": real("disarm closer than this to the floor (altimeter), m", 0.0, 10.0),
    "max_roll_rad": real("disarm beyond this roll (DVL attitude), rad", 0.0, math.pi),
    "max_pitch_rad": real("disarm beyond this pitch (DVL attitude), rad", 0.0, math.pi / 2),
    "cage_margin_m": real("disarm when the DVL dead-reckoned position comes closer than this to a pool "
                          "wall (pool.* box), m", 0.0, 10.0),
    "max_run_time_s": real("disarm after this long armed, s", 1.0, 86400.0),
}, optional=("rate_check_disabled.",))
#: the supervisor's node parameter ``clock_stall_timeout_s`` (read-only, outside the vehicle file, validated like the
#: keys: config.node_parameters.declare_node_parameter), widened only by an in-process simulator that holds simulated
#: time on purpose (hindrax bringup with the virtual pool)
CLOCK_STALL_TIMEOUT = real("armed, ROS time standing still this long (steady clock) trips, s; default "
                           "supervisor.rate_window_s", 0.2, 120.0)


def cross_checks(c: Mapping[str, Any]) -> list[ConfigIssue]:
    """Checks of the supervisor's settings, one issue (one line) each.

    * Its limits at least as wide as the identification's ``limits.*`` (which abort first); ``cage_margin_m`` below
      half the pool's smaller side; ``min_altitude_m`` at least the Ping's blind zone; ``max_depth_m`` at most the
      pool's depth and the depth sensor's plausibility gate (a deeper limit never trips).
    * ``rate_window_s``, ``max_invalid_dvl_s``, ``max_sample_age_s`` and ``max_identical_s`` at most
      ``reaction_time_s``: a dead sensor is found at the latest one rate window after it stops.
    * A rate check is off (``min_rate.<sensor>_hz: 0``) only with a reason (``rate_check_disabled.<sensor>``)."""
    issues: list[ConfigIssue] = []
    # the supervisor is the last line: its limits at least as wide as the identification's (which abort first)
    for key, other, wider in (("supervisor.max_depth_m", "limits.max_depth_m", "at least"),
                              ("supervisor.min_altitude_m", "limits.min_altitude_m", "at most"),
                              ("supervisor.max_roll_rad", "limits.max_roll_rad", "at least"),
                              ("supervisor.max_pitch_rad", "limits.max_pitch_rad", "at least")):
        if key in c and other in c and (c[key] < c[other] if wider == "at least" else c[key] > c[other]):
            issues.append(ConfigIssue(key, c[key], f"{wider} {other} ({c[other]:g}): the identification aborts first"))
    if "supervisor.cage_margin_m" in c and "pool.width_m" in c and \
            2.0 * c["supervisor.cage_margin_m"] >= min(c["pool.length_m"], c["pool.width_m"]):
        half_side = min(c["pool.length_m"], c["pool.width_m"]) / 2
        issues.append(ConfigIssue("supervisor.cage_margin_m", c["supervisor.cage_margin_m"],
                                  f"below half the pool's smaller side ({half_side:g})"))
    reaction = c.get("supervisor.reaction_time_s")
    if reaction is not None:
        for key in ("supervisor.rate_window_s", "supervisor.max_invalid_dvl_s", "supervisor.max_sample_age_s",
                    "supervisor.max_identical_s"):
            if key in c and c[key] > reaction:
                issues.append(ConfigIssue(key, c[key], f"at most supervisor.reaction_time_s ({reaction:g} s): a "
                                                       "failed sensor would go unnoticed longer"))
    # a rate check is off only with a reason
    for sensor in ("dvl", "altimeter", "pressure", "imu"):
        key, why = f"supervisor.min_rate.{sensor}_hz", f"supervisor.rate_check_disabled.{sensor}"
        if key not in c:
            continue
        reason = str(c.get(why, "")).strip()
        if c[key] == 0.0 and not reason:
            issues.append(ConfigIssue(key, 0.0, f"above 0, or 0 with {why}: '<reason>' (a disabled check needs a "
                                      "reason)"))
        elif c[key] > 0.0 and why in c:
            issues.append(ConfigIssue(why, c[why], f"absent while {key} = {c[key]:g} (the check is on)"))
    # supervisor limits inside what the sensors can report
    if "supervisor.min_altitude_m" in c and "sensors.ping1d.min_range_m" in c and \
            c["supervisor.min_altitude_m"] < c["sensors.ping1d.min_range_m"]:
        issues.append(ConfigIssue("supervisor.min_altitude_m", c["supervisor.min_altitude_m"],
                                  f"at least sensors.ping1d.min_range_m ({c['sensors.ping1d.min_range_m']:g}): closer "
                                  "is the Ping's blind zone"))
    if "supervisor.max_depth_m" in c:
        for other, what in (("pool.depth_m", "the pool's depth"),
                            ("sensors.ms5837.max_depth_m", "the depth sensor's plausibility gate")):
            if other in c and c["supervisor.max_depth_m"] > c[other]:
                issues.append(ConfigIssue("supervisor.max_depth_m", c["supervisor.max_depth_m"],
                                          f"at most {other} ({c[other]:g}, {what}): a deeper limit never trips"))
                break  # one line per key
    return issues
