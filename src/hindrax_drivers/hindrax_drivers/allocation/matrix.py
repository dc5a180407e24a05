"""Thrust allocation matrix ([Hindrax-Drag] eq. 9) and the default Hindrax thruster layout, pure numpy.

Frame: marine body frame FRD (x forward, y starboard, z down), origin at the centre of gravity
(docs/architecture.md §3; [Hindrax-Drag] Figure 2). A thruster ``i`` at position ``r_i`` (m) pushing along the
unit vector ``d_i`` with thrust ``F_i`` (N) applies the wrench ``tau_i = [d_i; r_i x d_i] F_i``
([Hindrax-Drag] eq. 9, after Fossen 1994), ``tau = [X Y Z K M N]`` in N and N m. Stacking the columns
``[d_i; r_i x d_i]`` gives the 6 x n thrust allocation matrix ``B`` with ``tau = B F``.

Conversions between ROS ``base_link`` (FLU) and FRD are done by the project's frames module, not here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["HINDRAX_HORIZONTAL_ANGLE_RAD", "ThrusterLayout", "thrust_allocation_matrix",
           "horizontal_direction", "hindrax_default_layout"]

#: Rotation of the horizontal thrusters T1-T4 from the x axis, [Hindrax-Drag] section 4 (55 degrees).
HINDRAX_HORIZONTAL_ANGLE_RAD = math.radians(55.0)

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
    non-finite values, different n, or a direction whose norm differs from 1 by more than 1e-6.
    """
    r = _as_n_by_3(positions_m, "positions_m")
    d = _as_n_by_3(directions, "directions")
    if r.shape != d.shape:
        raise ValueError(f"positions_m {r.shape} and directions {d.shape} must have the same shape")
    norms = np.linalg.norm(d, axis=1)
    bad = np.flatnonzero(np.abs(norms - 1.0) > _UNIT_TOLERANCE)
    if bad.size:
        raise ValueError(f"directions must be unit vectors; rows {bad.tolist()} have norms {norms[bad].tolist()}")
    return np.vstack([d.T, np.cross(r, d).T])


def horizontal_direction(angle_rad) -> np.ndarray:
    """Unit thrust direction(s) in the horizontal FRD plane: ``(cos a, sin a, 0)``.

    ``angle_rad`` is measured from +x (forward) towards +y (starboard), the decomposition of [Hindrax-Drag]
    section 4 (``F_x = cos(a) F``, ``F_y = sin(a) F``). Scalar in: shape (3,); array of shape (n,) in:
    shape (n, 3). Raises ``ValueError`` for non-finite angles.
    """
    try:
        a = np.asarray(angle_rad, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"angle_rad: expected numbers, got {angle_rad!r}") from exc
    if not np.all(np.isfinite(a)) or a.ndim > 1:
        raise ValueError(f"angle_rad must be a finite scalar or 1-D array, got {angle_rad!r}")
    return np.stack([np.cos(a), np.sin(a), np.zeros_like(a)], axis=-1)


@dataclass(frozen=True, eq=False)
class ThrusterLayout:
    """Thruster geometry: ``names`` (n,), ``positions_m`` (n, 3) and unit ``directions`` (n, 3), FRD,
    origin at the centre of gravity. ``matrix()`` gives the (6, n) thrust allocation matrix ([Hindrax-Drag]
    eq. 9) via :func:`thrust_allocation_matrix`."""

    names: tuple[str, ...]
    positions_m: np.ndarray
    directions: np.ndarray

    def __post_init__(self) -> None:
        positions = _as_n_by_3(self.positions_m, "positions_m").copy()
        directions = _as_n_by_3(self.directions, "directions").copy()
        names = tuple(str(n) for n in self.names)
        if len(names) != positions.shape[0] or len(set(names)) != len(names):
            raise ValueError(f"names must be {positions.shape[0]} distinct strings, got {names!r}")
        thrust_allocation_matrix(positions, directions)  # validates shapes and unit directions
        positions.flags.writeable = False
        directions.flags.writeable = False
        object.__setattr__(self, "names", names)
        object.__setattr__(self, "positions_m", positions)
        object.__setattr__(self, "directions", directions)

    def matrix(self) -> np.ndarray:
        """Thrust allocation matrix (6, n), [Hindrax-Drag] eq. 9."""
        return thrust_allocation_matrix(self.positions_m, self.directions)


def hindrax_default_layout(horizontal_x_m: float = 0.20, horizontal_y_m: float = 0.15, horizontal_z_m: float = 0.10,
                           vertical_x_m: float = 0.20, vertical_y_m: float = 0.17, vertical_z_m: float = -0.12,
                           horizontal_angle_rad: float = HINDRAX_HORIZONTAL_ANGLE_RAD) -> ThrusterLayout:
    """Default Hindrax geometry, eight thrusters T1-T8 (FRD, origin at the centre of gravity).

    What the paper fixes ([Hindrax-Drag] sections 2.2 and 4, Figures 2 and 5): two layers; the lower layer
    holds the horizontal thrusters T1-T4 (surge, sway, yaw), the upper layer the vertical thrusters
    T5-T8 (heave, roll, pitch); T1-T4 are rotated 55 degrees, T1 decomposing as ``F_x = cos(a) F``,
    ``F_y = sin(a) F``, ``F_z = 0``; the vehicle is symmetric about the xz and yz planes; in the
    self-propelled tests T1+T2 push surge and T1+T3 push sway.

    What follows from that: with T1 front-starboard, T2 front-port, T3 rear-starboard, T4 rear-port
    and directions T1 ``(cos a, sin a, 0)``, T2 ``(cos a, -sin a, 0)``, T3 ``(-cos a, sin a, 0)``,
    T4 ``(-cos a, -sin a, 0)``, equal thrust on T1+T2 cancels Y and (by the mirror symmetry) the yaw
    moment N, giving surge; equal thrust on T1+T3 cancels X and N, giving sway. Positive thrust of
    T5-T8 pushes along +z (down, FRD); T5 front-starboard, T6 front-port, T7 rear-starboard,
    T8 rear-port (ordering ASSUMED, same as T1-T4).

    ASSUMPTIONS: [Hindrax-Drag] prints no thruster coordinates. The defaults (horizontals at x = +-0.20,
    y = +-0.15, z = +0.10 m, i.e. below the centre of gravity; verticals at x = +-0.20, y = +-0.17,
    z = -0.12 m, above it) are chosen inside the 0.59 x 0.47 x 0.40 m envelope ([Hindrax-Drag] section 2.1)
    and must be replaced by measured values. Because the horizontals sit below the centre of gravity,
    their thrust also makes roll and pitch moments (eq. 9: ``K = -l_z F_y``, ``M = l_z F_x`` for a
    horizontal thruster), which the vertical thrusters can cancel.

    Raises ``ValueError`` for non-finite arguments.
    """
    raw = [horizontal_x_m, horizontal_y_m, horizontal_z_m, vertical_x_m, vertical_y_m, vertical_z_m,
           horizontal_angle_rad]
    try:
        values = [float(v) for v in raw]
    except (TypeError, ValueError) as exc:
        raise ValueError(f"layout dimensions and angle must be finite numbers, got {raw!r}") from exc
    if not all(math.isfinite(v) for v in values):
        raise ValueError(f"layout dimensions and angle must be finite numbers, got {raw!r}")
    hx, hy, hz, vx, vy, vz, a = values
    positions = np.array([
        [hx, hy, hz], [hx, -hy, hz], [-hx, hy, hz], [-hx, -hy, hz],      # T1..T4, lower layer
        [vx, vy, vz], [vx, -vy, vz], [-vx, vy, vz], [-vx, -vy, vz],      # T5..T8, upper layer
    ])
    horizontal = horizontal_direction(np.array([a, -a, math.pi - a, -(math.pi - a)]))
    vertical = np.tile([0.0, 0.0, 1.0], (4, 1))
    return ThrusterLayout(names=tuple(f"T{i}" for i in range(1, 9)), positions_m=positions,
                          directions=np.vstack([horizontal, vertical]))
