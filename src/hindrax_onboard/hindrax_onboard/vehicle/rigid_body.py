"""Rigid-body terms of the vehicle: the skew matrix and the mass matrix M_RB about the body origin (pure numpy).

M_RB = [m I3, -m S(r_g); m S(r_g), I_o] ([NTNU-Thesis] eq. 2.7), body frame FRD, with the
inertia moved from the CG to the body origin by the parallel-axis theorem. The simulator's model
(:mod:`hindrax_sim.model`), the identification's priors and posterior use this one definition."""
from __future__ import annotations

import numpy as np

__all__ = ["skew", "rigid_body_mass_matrix"]


def skew(a) -> np.ndarray:
    """Skew-symmetric matrix S(a) (3x3) with S(a) b = a x b ([NTNU-Thesis] eq. 2.7 notation). a: (3,)."""
    x, y, z = np.asarray(a, dtype=float)
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def rigid_body_mass_matrix(mass_kg: float, r_g_m, inertia_cg_kg_m2) -> np.ndarray:
    """M_RB (6x6) about the body origin CO: [m I3, -m S(r_g); m S(r_g), I_o] ([NTNU-Thesis] eq. 2.7).

    mass_kg: m. r_g_m (3,): CG relative to CO, FRD, m. inertia_cg_kg_m2 (3, 3): inertia tensor about the CG;
    moved to CO with the parallel-axis theorem I_o = I_cg - m S(r_g)^2."""
    s = skew(r_g_m)
    i_o = np.asarray(inertia_cg_kg_m2, dtype=float) - mass_kg * s @ s
    return np.block([[mass_kg * np.eye(3), -mass_kg * s], [mass_kg * s, i_o]])
