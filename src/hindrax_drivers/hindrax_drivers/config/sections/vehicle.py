"""``vehicle.*``: the vehicle's name and rigid-body data ([Hindrax-AM] §2, [Hindrax-Drag] §2.1).

The section's schema (:data:`SCHEMA`), its optional keys (:data:`OPTIONAL`) and the checks that name one of its keys
(:func:`cross_checks`); :mod:`hindrax_drivers.config.sections` joins the sections.
"""
from __future__ import annotations

from typing import Any, Mapping

from ..spec import ROS_NAME_TOKEN, STR, ConfigIssue, Spec, real, vector

SCHEMA: dict[str, Spec] = {
    "vehicle.name": Spec(STR, "the vehicle's name: its namespace on the topside graph (docs/architecture.md "
                               "§8.2), unique among the vehicles on one topside domain", pattern=ROS_NAME_TOKEN),
    "vehicle.mass_kg": real("total mass in air, kg ([Hindrax-Drag] §2.1)", 0.1, 1000.0),
    "vehicle.displaced_volume_m3": real("displaced volume, m^3 ([Hindrax-Drag] §2.1)", 1e-5, 10.0),
    "vehicle.length_m": real("overall length (x), m ([Hindrax-Drag] §2.1)", 0.01, 10.0),
    "vehicle.width_m": real("overall width (y), m ([Hindrax-Drag] §2.1)", 0.01, 10.0),
    "vehicle.height_m": real("overall height (z), m ([Hindrax-Drag] §2.1)", 0.01, 10.0),
    "vehicle.net_buoyancy_n": real("stated net buoyancy (buoyancy - weight), N; checked against (rho V - m) g",
                                   -100.0, 100.0),
    "vehicle.inertia_kg_m2": vector("principal moments of inertia [Ixx, Iyy, Izz] about the CG, kg m^2", 3, 1e-6, 1e4),
    "vehicle.products_of_inertia_kg_m2": vector("products of inertia [Ixy, Ixz, Iyz], kg m^2", 3, -1e4, 1e4),
    "vehicle.centre_of_gravity_frd_m": vector("CG relative to the body origin, FRD, m", 3, -5.0, 5.0),
    "vehicle.centre_of_buoyancy_frd_m": vector("CB relative to the body origin, FRD, m", 3, -5.0, 5.0),
}

#: Optional keys (prefixes): absent is fine; present must validate. Every other key of :data:`SCHEMA` is required.
OPTIONAL: tuple[str, ...] = ()


def cross_checks(c: Mapping[str, Any]) -> list[ConfigIssue]:
    """``vehicle.net_buoyancy_n`` within max(0.1 N, 10 %) of (rho V - m) g from ``vehicle.*`` and ``environment.*``."""
    issues: list[ConfigIssue] = []
    if "vehicle.mass_kg" in c and "environment.water_density_kg_m3" in c:
        m, vol = c["vehicle.mass_kg"], c["vehicle.displaced_volume_m3"]
        rho, g = c["environment.water_density_kg_m3"], c["environment.gravity_m_s2"]
        derived = (rho * vol - m) * g
        stated = c["vehicle.net_buoyancy_n"]
        tol = max(0.1, 0.1 * abs(derived))
        if abs(derived - stated) > tol:
            issues.append(ConfigIssue("vehicle.net_buoyancy_n", stated,
                                      f"within {tol:.2f} N of (rho V - m) g = {derived:.3f} N"))
    return issues
