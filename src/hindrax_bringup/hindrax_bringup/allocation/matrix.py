"""Thrust allocation matrix ([Hindrax-Drag] eq. 9), pure numpy.

Frame: marine body frame FRD (x forward, y starboard, z down), origin at the centre of gravity
(docs/architecture.md §3; [Hindrax-Drag] Figure 2). A thruster ``i`` at position ``r_i`` (m) pushing along the
unit vector ``d_i`` with thrust ``F_i`` (N) applies the wrench ``tau_i = [d_i; r_i x d_i] F_i``
([Hindrax-Drag] eq. 9, after Fossen 1994), ``tau = [X Y Z K M N]`` in N and N m. Stacking the columns
``[d_i; r_i x d_i]`` gives the 6 x n thrust allocation matrix ``B`` with ``tau = B F``.

Conversions between ROS ``base_link`` (FLU) and FRD are done by the project's frames module, not here."""

from __future__ import annotations

import numpy as np

__all__ = ["thrust_allocation_matrix"]

_UNIT_TOLERANCE = 1e-6


def _as_n_by_3(values, name: str) -> np.ndarray:
    try:
        arr = np.asarray(values, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: expected an (n, 3) array of numbers, got {values!r}") from exc
    if arr.ndim != 2 or arr.shape[1] != 3 or arr.shape[0] < 1:
        raise ValueError(f"{name}: expected shape (n, 3) with n >= 1, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: all values must be finite")
    return arr


def thrust_allocation_matrix(positions_m, directions) -> np.ndarray:
    """Thrust allocation matrix ``B`` (6, n) with columns ``[d_i; r_i x d_i]`` ([Hindrax-Drag] eq. 9).

    ``positions_m`` (n, 3): thruster positions in FRD relative to the centre of gravity (m).
    ``directions`` (n, 3): unit vectors (FRD) of the force a positive thrust applies to the vehicle.
    Rows of ``B`` are surge X, sway Y, heave Z (N per N) and roll K, pitch M, yaw N (N m per N).
    Works for any number and arrangement of thrusters. Raises ``ValueError`` for wrong shapes,
    non-finite values, different n, or a direction whose norm differs from 1 by more than 1e-6."""
    r = _as_n_by_3(positions_m, "positions_m")
    d = _as_n_by_3(directions, "directions")
    if r.shape != d.shape:
        raise ValueError(f"positions_m {r.shape} and directions {d.shape} must have the same shape")
    norms = np.linalg.norm(d, axis=1)
    bad = np.flatnonzero(np.abs(norms - 1.0) > _UNIT_TOLERANCE)
    if bad.size:
        raise ValueError(f"directions must be unit vectors; rows {bad.tolist()} have norms {norms[bad].tolist()}")
    return np.vstack([d.T, np.cross(r, d).T])
