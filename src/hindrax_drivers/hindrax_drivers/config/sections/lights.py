"""``lights.*``: the lights' PCA9685 channel and pulse widths ([Hindrax-Drag] §2.1: PWM also drives the lights).

The section's schema (:data:`SCHEMA`), its optional keys (:data:`OPTIONAL`) and the checks that name one of its keys
(:func:`cross_checks`); :mod:`hindrax_drivers.config.sections` joins the sections.
"""
from __future__ import annotations

from typing import Any, Mapping

from ..spec import ConfigIssue, Spec, integer, real

SCHEMA: dict[str, Spec] = {
    "lights.esc_channel": integer("PCA9685 channel of the lights", 0, 15),
    "lights.pulse_width_off_us": real("pulse width for lights off, us", 500.0, 2500.0),
    "lights.pulse_width_full_us": real("pulse width for full brightness, us", 500.0, 2500.0),
}

#: Optional keys (prefixes): absent is fine; present must validate. Every other key of :data:`SCHEMA` is required.
OPTIONAL: tuple[str, ...] = ()


def cross_checks(c: Mapping[str, Any]) -> list[ConfigIssue]:
    """``lights.esc_channel`` not a thruster's channel."""
    light = c.get("lights.esc_channel")
    for n in c.get("thrusters.names", ()):
        if light is not None and c.get(f"thrusters.{n}.esc_channel") == light:
            return [ConfigIssue("lights.esc_channel", light, f"a channel not used by a thruster (thrusters.{n})")]
    return []
