"""``calibration.*``: the known forces of the campaign's reference steps (docs/identification.md §6), the times
of their holds, and the forces' derived view (:class:`CalibrationConfig`)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

from ..spec import ConfigIssue, real, section

SCHEMA, OPTIONAL = section("calibration", {
    "ballast_mass_kg": real("mass of the ballast hung on the vehicle in the ballast step, kg", 0.01, 50.0),
    "ballast_volume_m3": real("displaced volume of that ballast, m^3 (weight in water (m - rho V) g must be "
                              "> 0)", 0.0, 0.05),
    "line_pull_force_n": real("horizontal force of the line over the pool-edge pulley in the line_pull "
                              "step (e.g. a hanging mass times g), N", 0.1, 200.0),
    "inclining_mass_kg": real("test mass of the inclining step, kg", 0.01, 20.0),
    "inclining_volume_m3": real("displaced volume of that test mass, m^3 (it must sink)", 0.0, 0.02),
    "inclining_arm_m": real("horizontal arm of the test mass from the centre line (roll: to starboard, "
                            "pitch: forward), m", 0.01, 2.0),
    "float_mass_kg": real("mass of the sealed float tied to the vehicle in the float step (optional), kg", 0.0, 50.0),
    "float_volume_m3": real("displaced volume of that float, m^3 (net buoyancy (rho V - m) g must be > 0)", 1e-6, 0.1),
    "net_buoyancy_std_n": real("1-sigma of the vehicle's net buoyancy (rho V - m) g as weighed, N (the hover holds of "
                               "the thrust calibration measure the forward thrust against it; optional)", 1e-4, 10.0),
    "hold_settle_s": real("settling time before each averaging hold of the reference steps, s (optional; "
                          "default 15)", 1.0, 600.0),
    "hold_window_s": real("averaging time of each hold of the reference steps, s (optional; default 30)", 1.0, 600.0),
}, optional=("float_", "net_buoyancy_std_n", "hold_"))


def cross_checks(c: Mapping[str, Any]) -> list[ConfigIssue]:
    """The ballast and the inclining test mass sink, the float floats (with the configured water density)."""
    issues: list[ConfigIssue] = []
    rho = float(c.get("environment.water_density_kg_m3", 1000.0))
    bodies = (("ballast", "below", "the ballast must sink"),
              ("float", "above", "the float must float"),
              ("inclining", "below", "the test mass must sink"))
    for body, side, why in bodies:
        mass, volume = f"calibration.{body}_mass_kg", f"calibration.{body}_volume_m3"
        if mass in c and volume in c:
            limit = c[mass] / rho
            ok = c[volume] > limit if side == "above" else c[volume] < limit
            if not ok:
                issues.append(ConfigIssue(volume, c[volume], f"{side} {mass} / water density = {limit:.4g} ({why})"))
    return issues


@dataclass(frozen=True)
class CalibrationConfig:
    """The known forces of the campaign's reference steps (``calibration.*``; docs/identification.md §6.1).

    Weights in water and buoyancies are (m - rho V) g and (rho V - m) g with the configured water density and g.
    ``float_net_buoyancy_n`` is None without the optional ``calibration.float_*`` keys; ``net_buoyancy_std_n``
    defaults to 0.05 N (the vehicle weighed in water with a spring scale; ASSUMPTION when not configured)."""

    ballast_weight_in_water_n: float
    line_pull_force_n: float
    inclining_weight_in_water_n: float
    inclining_arm_m: float
    float_net_buoyancy_n: float | None
    net_buoyancy_std_n: float
