"""``vehicle.*``: the vehicle's name and rigid-body data ([Hindrax-AM] §2, [Hindrax-Drag] §2.1)."""
from __future__ import annotations

from typing import Any, Mapping

from ..spec import ROS_NAME_TOKEN, STR, ConfigIssue, Spec, real, section, vector

SCHEMA, OPTIONAL = section("vehicle", {
    "name": Spec(STR, "the vehicle's name: its namespace on the topside graph (docs/architecture.md "
                       "§8.2), unique among the vehicles on one topside domain", pattern=ROS_NAME_TOKEN),
    "mass_kg": real("total mass in air, kg ([Hindrax-Drag] §2.1)", 0.1, 1000.0),
    "displaced_volume_m3": real("displaced volume, m^3 ([Hindrax-Drag] §2.1)", 1e-5, 10.0),
    "length_m": real("overall length (x), m ([Hindrax-Drag] §2.1)", 0.01, 10.0),
    "width_m": real("overall width (y), m ([Hindrax-Drag] §2.1)", 0.01, 10.0),
    "height_m": real("overall height (z), m ([Hindrax-Drag] §2.1)", 0.01, 10.0),
    "net_buoyancy_n": real("stated net buoyancy (buoyancy - weight), N; checked against (rho V - m) g", -100.0, 100.0),
    "inertia_kg_m2": vector("principal moments of inertia [Ixx, Iyy, Izz] about the CG, kg m^2", 3, 1e-6, 1e4),
    "products_of_inertia_kg_m2": vector("products of inertia [Ixy, Ixz, Iyz], kg m^2", 3, -1e4, 1e4),
    "centre_of_gravity_frd_m": vector("CG relative to the body origin, FRD, m", 3, -5.0, 5.0),
    "centre_of_buoyancy_frd_m": vector("CB relative to the body origin, FRD, m", 3, -5.0, 5.0),
})


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
