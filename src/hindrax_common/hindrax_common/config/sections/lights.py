"""``lights.*``: the lights' PCA9685 channel and pulse widths ([Hindrax-Drag] §2.1: PWM also drives the lights)."""
from __future__ import annotations

from typing import Any, Mapping

from ..spec import ConfigIssue, integer, real, section

SCHEMA, OPTIONAL = section("lights", {
    "esc_channel": integer("PCA9685 channel of the lights (15 carries the reference pulse for `hindrax esc calibrate`)",
                           0, 14),
    "pulse_width_off_us": real("pulse width for lights off, us", 500.0, 2500.0),
    "pulse_width_full_us": real("pulse width for full brightness, us", 500.0, 2500.0),
})


def cross_checks(c: Mapping[str, Any]) -> list[ConfigIssue]:
    """``lights.esc_channel`` not a thruster's channel."""
    light = c.get("lights.esc_channel")
    for n in c.get("thrusters.names", ()):
        if light is not None and c.get(f"thrusters.{n}.esc_channel") == light:
            return [ConfigIssue("lights.esc_channel", light, f"a channel not used by a thruster (thrusters.{n})")]
    return []
