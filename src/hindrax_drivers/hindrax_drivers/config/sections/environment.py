"""``environment.*``: water and gravity.

The section's schema (:data:`SCHEMA`), its optional keys (:data:`OPTIONAL`) and the checks that name one of its keys
(:func:`cross_checks`); :mod:`hindrax_drivers.config.sections` joins the sections.
"""
from __future__ import annotations

from typing import Any, Mapping

from ..spec import ConfigIssue, Spec, real

SCHEMA: dict[str, Spec] = {
    "environment.water_density_kg_m3": real("water density, kg/m^3 (seeds use 1000)", 900.0, 1100.0),
    "environment.gravity_m_s2": real("gravitational acceleration, m/s^2", 9.7, 9.9),
    "environment.kinematic_viscosity_m2_s": real("kinematic viscosity of water, m^2/s ([Hindrax-AM] §4)", 1e-7, 1e-5),
    "environment.surface_pressure_pa": real("atmospheric pressure at the surface, Pa", 50000.0, 120000.0),
}

#: Optional keys (prefixes): absent is fine; present must validate. Every other key of :data:`SCHEMA` is required.
OPTIONAL: tuple[str, ...] = ()


def cross_checks(c: Mapping[str, Any]) -> list[ConfigIssue]:
    """None: every ``environment.*`` key is checked by its own range."""
    return []
