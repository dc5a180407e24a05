"""``hydrodynamics.*``: added mass and damping per DOF (positive numbers; [Hindrax-AM] Table 6,
[Hindrax-Drag] Table 3), and their typed view per DOF (:class:`DofHydrodynamics`)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from ..spec import ROTATIONAL_DOFS, TRANSLATIONAL_DOFS, ConfigIssue, Spec, real, section, vector

_KEYS: dict[str, Spec] = {
    "added_mass_coupling": vector(
            "off-diagonal added-mass terms added to diag(added_mass), row-major 6x6 (kg, kg m, kg m^2); "
            "diagonal entries must be 0", 36, -1e4, 1e4),
}
for _dof in TRANSLATIONAL_DOFS:
    _KEYS[f"{_dof}.added_mass_kg"] = real(f"{_dof} added mass, kg", 0.0, 1e4)
    if _dof == "heave":
        for _d in ("positive", "negative"):
            _KEYS[f"heave.linear_damping_{_d}_kg_s"] = real(
                  f"heave linear damping for {_d} w (positive = down), kg/s", 0.0, 1e4)
            _KEYS[f"heave.quadratic_damping_{_d}_kg_m"] = real(
                  f"heave quadratic damping for {_d} w (positive = down), kg/m", 0.0, 1e4)
    else:
        _KEYS[f"{_dof}.linear_damping_kg_s"] = real(f"{_dof} linear damping, kg/s", 0.0, 1e4)
        _KEYS[f"{_dof}.quadratic_damping_kg_m"] = real(f"{_dof} quadratic damping, kg/m", 0.0, 1e4)
for _dof in ROTATIONAL_DOFS:
    _KEYS[f"{_dof}.added_mass_kg_m2"] = real(f"{_dof} added moment of inertia, kg m^2", 0.0, 1e3)
    _KEYS[f"{_dof}.linear_damping_kg_m2_s"] = real(f"{_dof} linear damping, N m/(rad/s) = kg m^2/s", 0.0, 1e3)
    _KEYS[f"{_dof}.quadratic_damping_kg_m2"] = real(f"{_dof} quadratic damping, N m/(rad/s)^2 = kg m^2", 0.0, 1e3)
SCHEMA, OPTIONAL = section("hydrodynamics", _KEYS)


def cross_checks(c: Mapping[str, Any]) -> list[ConfigIssue]:
    """``hydrodynamics.added_mass_coupling``: zero diagonal, and the added-mass matrix with it positive definite."""
    issues: list[ConfigIssue] = []
    if "hydrodynamics.added_mass_coupling" in c:
        coup = np.asarray(c["hydrodynamics.added_mass_coupling"]).reshape(6, 6)
        if np.any(np.diag(coup) != 0.0):
            issues.append(ConfigIssue("hydrodynamics.added_mass_coupling", c["hydrodynamics.added_mass_coupling"],
                                      "a 6x6 row-major matrix with zero diagonal"))
        elif "hydrodynamics.surge.added_mass_kg" in c:
            ma = added_mass_matrix_from_flat(c)
            if np.min(np.linalg.eigvalsh(0.5 * (ma + ma.T))) <= 0.0:
                issues.append(ConfigIssue("hydrodynamics.added_mass_coupling", c["hydrodynamics.added_mass_coupling"],
                                          "couplings keeping the added-mass matrix positive definite"))
    return issues


def added_mass_matrix_from_flat(c: Mapping[str, Any]) -> np.ndarray:
    """6x6 added-mass matrix M_A (positive definite, FRD, SNAME order) from validated flat keys."""
    diag = [c[f"hydrodynamics.{d}.added_mass_kg"] for d in TRANSLATIONAL_DOFS] + \
           [c[f"hydrodynamics.{d}.added_mass_kg_m2"] for d in ROTATIONAL_DOFS]
    return np.diag(diag) + np.asarray(c["hydrodynamics.added_mass_coupling"], dtype=float).reshape(6, 6)

@dataclass(frozen=True)
class DofHydrodynamics:
    """Hydrodynamic coefficients of one DOF (positive numbers, SI).

    added_mass: kg (translation) or kg m^2 (rotation). linear_damping: kg/s or kg m^2/s.
    quadratic_damping: kg/m or kg m^2. Heave has direction-dependent damping ([Hindrax-Drag] Table 3:
    positive heave = moving down, w > 0 in FRD); for the other DOFs the positive and negative values are equal.
    Damping force/moment opposing motion: D(v) = linear v + quadratic |v| v, with the coefficient
    chosen by the sign of v."""

    dof: str
    added_mass: float
    linear_damping_positive: float
    linear_damping_negative: float
    quadratic_damping_positive: float
    quadratic_damping_negative: float

    def damping(self, velocity: float) -> float:
        """Damping force (N) or moment (N m) opposing ``velocity`` (m/s or rad/s), signed like velocity."""
        if velocity >= 0.0:
            return self.linear_damping_positive * velocity + self.quadratic_damping_positive * velocity * velocity
        return self.linear_damping_negative * velocity - self.quadratic_damping_negative * velocity * velocity
