"""``environment.*``: water and gravity."""
from __future__ import annotations

from ..spec import real, section

SCHEMA, OPTIONAL = section("environment", {
    "water_density_kg_m3": real("water density, kg/m^3 (the Hindrax papers use 1000)", 900.0, 1100.0),
    "gravity_m_s2": real("gravitational acceleration, m/s^2", 9.7, 9.9),
    "kinematic_viscosity_m2_s": real("kinematic viscosity of water, m^2/s ([Hindrax-AM] §4)", 1e-7, 1e-5),
    "surface_pressure_pa": real("atmospheric pressure at the surface, Pa", 50000.0, 120000.0),
})
