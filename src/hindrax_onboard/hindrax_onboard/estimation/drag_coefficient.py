"""Drag coefficients and Reynolds numbers of the identified DOFs ([Hindrax-Drag] Table 4).

[Hindrax-Drag] Table 4 reports, per DOF, a mean drag coefficient C_D with its standard deviation and the Reynolds-number
range of the self-propelled tests, but it prints neither the projected areas, nor the characteristic length, nor the
definition used for the rotational DOFs. What we implement (and what we cannot verify against the paper):

* Translational DOFs, from the quadratic damping (docs/identification.md §1.A (h), [T] 4.6.3):
  C_D = 2 k_q / (rho A_p), A_p the projected area normal to the motion (m^2). Valid when C_D
  does not depend on Re (prisms above Re ~ 1e4, docs/identification.md §1.A flow physics).
  :func:`drag_coefficient` propagates the std of k_q linearly. Rotational DOFs get none:
  [Hindrax-Drag] defines neither their area nor their radius.
* Reynolds number Re = U L / nu ([T] eq. 2.60; [Hindrax-AM] section 4 uses U_m V^(1/3) / nu with
  nu = 1.01e-6 m^2/s). Default characteristic length: L = V^(1/3) ([Hindrax-AM] eq. 10 choice;
  0.2483 m for the Hindrax prototype). [Hindrax-Drag] does not state its L;
  with L = 0.2483 m its surge range 0.5e5-1.1e5 corresponds to 0.20-0.45 m/s, plausible for
  the tests ("0.5 m/s needs about 25 N") but not verifiable."""

from __future__ import annotations

from typing import Tuple

import numpy as np

from .least_squares import EstimationError, as_float_array, positive

__all__ = ["KINEMATIC_VISCOSITY_WATER_M2_S", "characteristic_length_from_volume", "reynolds_number",
           "reynolds_range", "drag_coefficient"]

#: Kinematic viscosity of water used by [Hindrax-AM] (section 4): 1.01e-6 m^2/s.
KINEMATIC_VISCOSITY_WATER_M2_S = 1.01e-6


def characteristic_length_from_volume(volume_m3: float) -> float:
    """L = V^(1/3) in m ([Hindrax-AM] eq. 10: 0.0824 m for the 1:3 model, 0.2483 m prototype).

    Raises:
        EstimationError: volume not > 0."""
    return positive(volume_m3, "volume_m3") ** (1.0 / 3.0)


def reynolds_number(speed, characteristic_length_m: float,
                    kinematic_viscosity_m2_s: float = KINEMATIC_VISCOSITY_WATER_M2_S):
    """Re = |U| L / nu ([T] eq. 2.60; [Hindrax-AM] section 4). Scalar or element-wise on arrays.

    Args:
        speed: U in m/s (for rotations pass |w| R).
        characteristic_length_m: L in m (> 0).
        kinematic_viscosity_m2_s: nu in m^2/s (> 0), default 1.01e-6 ([Hindrax-AM]).

    Raises:
        EstimationError: non-positive L or nu."""
    L = positive(characteristic_length_m, "characteristic_length_m")
    nu = positive(kinematic_viscosity_m2_s, "kinematic_viscosity_m2_s")
    re = np.abs(np.asarray(speed, dtype=float)) * L / nu
    return float(re) if re.ndim == 0 else re


def reynolds_range(speed, characteristic_length_m: float,
                   kinematic_viscosity_m2_s: float = KINEMATIC_VISCOSITY_WATER_M2_S,
                   min_speed: float = 0.0) -> Tuple[float, float]:
    """(min, max) Reynolds number over the samples with |speed| > ``min_speed`` (Table 4 column).

    Args:
        speed: (n,) speeds in m/s (or |w| R for rotations); typically steady-window means.
        characteristic_length_m: L in m.
        kinematic_viscosity_m2_s: nu in m^2/s.
        min_speed: ignore samples at or below this speed (e.g. the zero-thrust level).

    Raises:
        EstimationError: no sample above ``min_speed`` or bad input."""
    u = np.abs(as_float_array(speed, "speed", 1))
    u = u[u > min_speed]
    if u.size == 0:
        raise EstimationError(f"no sample with |speed| > {min_speed}")
    re = reynolds_number(u, characteristic_length_m, kinematic_viscosity_m2_s)
    return float(np.min(re)), float(np.max(re))


def drag_coefficient(quadratic_damping: float, projected_area_m2: float, fluid_density_kg_m3: float = 1000.0,
                     quadratic_damping_std: float = 0.0) -> Tuple[float, float]:
    """C_D = 2 k_q / (rho A_p) and its std (docs/identification.md §1.A (h); [Hindrax-Drag] Table 4).

    Args:
        quadratic_damping: k_q in N/(m/s)^2 = kg/m ([Hindrax-Drag] Table 3).
        projected_area_m2: A_p normal to the motion in m^2 (> 0).
        fluid_density_kg_m3: rho (> 0), default 1000 ([Hindrax-Drag] section 5).
        quadratic_damping_std: std of k_q (>= 0), propagated linearly.

    Returns:
        (c_d, c_d_std), dimensionless.

    Raises:
        EstimationError: non-positive area/density or negative std."""
    A = positive(projected_area_m2, "projected_area_m2")
    rho = positive(fluid_density_kg_m3, "fluid_density_kg_m3")
    if not quadratic_damping_std >= 0:
        raise EstimationError("quadratic_damping_std must be >= 0")
    scale = 2.0 / (rho * A)
    return float(scale * quadratic_damping), float(scale * quadratic_damping_std)

