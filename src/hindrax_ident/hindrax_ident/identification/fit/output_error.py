"""The one-DOF model's regressor columns, shared by the batch and online fits of :mod:`.dof_model`.

Model (docs/identification.md; [Hindrax-Drag] eq. 2 with the inertia term; Fossen/SNAME positive
coefficients), body FRD, for the DOF under test with velocity nu (m/s or rad/s) and thrust-model force tau
(N or N m)::

    M nu_dot + k_q |nu| nu + k_l nu + b (+ k_r s(eta)) = tau

``theta = [M, k_q, k_l, b (, k_r)]`` in :func:`model_terms` column order; heave has ``k_q`` and ``k_l`` per sign
of w (down positive): ``[M, k_q+, k_q-, k_l+, k_l-, b]``. Roll and pitch add the restoring moment ``k_r s(eta)``,
``s`` = cos(theta) sin(phi) (roll) or sin(theta) (pitch) ([NTNU-Thesis] eq. 2.23). The output-error
fit itself (segments, the RK4 simulation, robust least squares, intervals) is :mod:`.fit_core`
(docs/identification.md §7).
"""
from __future__ import annotations

import numpy as np

__all__ = ["model_terms"]


def model_terms(dof: str, velocity, restoring=None) -> np.ndarray:
    """The model's columns after the inertia column, shape (..., p - 1), for velocity (...) and, roll and pitch,
    the restoring regressor s(eta) (...; zeros when None): ``[|nu| nu, nu, 1 (, s)]``; heave
    ``[|w| w (w > 0), |w| w (w <= 0), w (w > 0), w (w <= 0), 1]``."""
    v = np.asarray(velocity, dtype=float)
    q = np.abs(v) * v
    one = np.ones_like(v)
    if dof == "heave":
        pos = v > 0
        cols = [np.where(pos, q, 0.0), np.where(pos, 0.0, q), np.where(pos, v, 0.0), np.where(pos, 0.0, v), one]
    else:
        cols = [q, v, one]
        if dof in ("roll", "pitch"):
            cols.append(np.zeros_like(v) if restoring is None else np.asarray(restoring, dtype=float))
    return np.stack(cols, axis=-1)

