"""The pool box: floor, walls and free surface, with contact handling and reporting. Pure numpy.

Geometry ([Hindrax-Drag] §4: a 10 x 6 x 1.8 m pool; configuration ``pool.length_m``, ``pool.width_m``,
``pool.depth_m``): world frame NED with the origin at a pool corner on the water surface, x north along the
length (0 .. length_m), y east along the width (0 .. width_m), z down (surface 0, floor depth_m).

Hull (ASSUMPTION, the papers give only the envelope): a box of ``vehicle.length_m x width_m x height_m``
([Hindrax-Drag] §2.1: 0.59 x 0.47 x 0.40 m) centred on the centre of buoyancy, aligned with the body axes. Its
displaced volume is taken as uniformly distributed over its height, so the volume centroid is the CB.

Floor: z_f(x, y) = p(x) + g_n (x - length_m / 2) + g_e (y - width_m / 2), with (g_n, g_e) the
truth's ``disturbances.floor.gradient`` (:meth:`Pool.set_floor_gradient`; 0 by default) and
p(x) = ``depth_m`` or the piecewise-linear profile along north of :meth:`Pool.set_floor_profile`.
Altitudes (DVL: vertical; Ping1D: along the body z axis), rays and the floor contact use it; the
contact takes the floor depth under the hull centre (the floor's tilt across the hull is neglected).

Free surface (:class:`FreeSurface`): the submerged fraction of the hull is the part of its vertical extent
below z = 0, ``f = clip((z_c + h) / (2 h), 0, 1)`` with z_c the depth of the hull centre (CB) and
``h = a |R20| + b |R21| + c |R22|`` the vertical half-extent of the (possibly tilted) box (a, b, c its half
dimensions, R the body-to-NED rotation). The buoyancy is ``f B``; a vehicle with W < B therefore floats
with ``f = W / B`` at a stable waterline (for Hindrax about 2 mm of the 0.40 m height out of the water,
heave stiffness B / (2h) = 375 N/m) instead of leaving the water. Wave making at the surface and the
shift of the CB of the emerged hull are not modelled (a vertical CB shift makes no moment).

Contact (:meth:`Pool.resolve`): after every integration step, if the hull box crosses a wall or the
floor, the position is clamped back (the box touches the face) and the NED velocity component into the
face is removed (a perfectly inelastic, frictionless contact); the same happens at the surface if the
hull were ever completely out of the water. Reported faces: ``north_wall`` (x = length), ``south_wall``
(x = 0), ``east_wall`` (y = width), ``west_wall`` (y = 0), ``floor`` (z = depth) and ``surface`` (the hull
breaks the surface: submerged fraction below 1), each with the time the contact started."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence


from hindrax_common.config import VehicleConfig

__all__ = ["FACES", "ContactState", "FreeSurface", "Pool"]

#: Faces of the pool box in report order.
FACES: tuple[str, ...] = ("north_wall", "south_wall", "east_wall", "west_wall", "floor", "surface")


@dataclass(frozen=True)
class ContactState:
    """Contact report at time ``t_s`` (s, simulated).

    ``since_s``: face name -> simulated time the current contact with that face started (only faces in
    contact now). ``faces``: the names, in :data:`FACES` order."""

    t_s: float
    since_s: dict[str, float] = field(default_factory=dict)

    @property
    def faces(self) -> tuple[str, ...]:
        return tuple(f for f in FACES if f in self.since_s)

class FreeSurface:
    """Submerged fraction of a box hull at the free surface (module docstring).

    hull_half_extents_m (3,): half length, width and height of the hull box, m (> 0). hull_centre_frd_m (3,): box centre
    relative to the body origin CO, FRD, m. Raises ``ValueError`` for non-positive extents."""

    def __init__(self, hull_half_extents_m: Sequence[float], hull_centre_frd_m: Sequence[float]) -> None:
        a, b, c = (float(x) for x in hull_half_extents_m)
        if min(a, b, c) <= 0.0:
            raise ValueError(f"hull half extents must be positive, got {list(hull_half_extents_m)}")
        self.hull_half_extents_m = (a, b, c)
        self.hull_centre_frd_m = tuple(float(x) for x in hull_centre_frd_m)

    def vertical_half_extent_m(self, r20: float, r21: float, r22: float) -> float:
        """Vertical half-extent h (m) of the hull box for the last row (R20, R21, R22) of body-to-NED R."""
        a, b, c = self.hull_half_extents_m
        return a * abs(r20) + b * abs(r21) + c * abs(r22)

    def __call__(self, depth_co_m: float, r20: float, r21: float, r22: float) -> float:
        """Submerged fraction in [0, 1]: clip((z_c + h) / (2 h), 0, 1) (module docstring)."""
        h = self.vertical_half_extent_m(r20, r21, r22)
        cx, cy, cz = self.hull_centre_frd_m
        zc = depth_co_m + r20 * cx + r21 * cy + r22 * cz
        f = (zc + h) / (2.0 * h)
        return 0.0 if f <= 0.0 else (1.0 if f >= 1.0 else f)


class Pool:
    """Pool box with floor, walls and free surface (module docstring).

    length_m, width_m, depth_m: box size (north, east, down), m. free_surface: the hull model (its box is
    used for contacts too). Raises ``ValueError`` for a pool not larger than the hull in every direction."""

    def __init__(self, length_m: float, width_m: float, depth_m: float, free_surface: FreeSurface) -> None:
        self.length_m, self.width_m, self.depth_m = float(length_m), float(width_m), float(depth_m)
        self.free_surface = free_surface
        a, b, c = free_surface.hull_half_extents_m
        diag = 2.0 * math.sqrt(a * a + b * b + c * c)
        if min(self.length_m, self.width_m, self.depth_m) <= diag:
            raise ValueError(f"pool {self.length_m} x {self.width_m} x {self.depth_m} m must exceed the hull "
                             f"diagonal {diag:.3f} m in every direction")
        self._since: dict[str, float] = {}
        self._t = 0.0
        self.floor_gradient = (0.0, 0.0)
        self.floor_profile: tuple[tuple[float, float], ...] = ()

    @classmethod
    def from_config(cls, config: VehicleConfig) -> "Pool":
        """Pool and hull from ``pool.*`` and ``vehicle.length_m/width_m/height_m``, hull centred on the CB."""
        v, pool = config.vehicle, config.pool
        surface = FreeSurface((0.5 * v.length_m, 0.5 * v.width_m, 0.5 * v.height_m), v.centre_of_buoyancy_frd_m)
        return cls(pool.length_m, pool.width_m, pool.depth_m, surface)

    # ------------------------------------------------------------------ geometry queries
    def set_floor_gradient(self, gradient_ne: Sequence[float]) -> None:
        """Slope the floor (module docstring): (north, east) depth change per metre (each |g| <= 0.5). Raises
        ``ValueError`` for a gradient that is not two finite numbers within that bound."""
        g = tuple(float(x) for x in gradient_ne)
        if len(g) != 2 or not all(math.isfinite(x) and abs(x) <= 0.5 for x in g):
            raise ValueError(f"floor gradient must be two numbers in [-0.5, 0.5], got {list(gradient_ne)}")
        self.floor_gradient = g

    def set_floor_profile(self, points_north_depth_m: Sequence[Sequence[float]]) -> None:
        """Give the floor a piecewise-linear profile along north (module docstring): ``points_north_depth_m`` is a
        sequence of (x north, floor depth) pairs, m, x strictly increasing; the depth is interpolated linearly between
        them and kept constant beyond the ends (``pool.depth_m`` is then not used). An empty sequence restores the
        flat floor at ``pool.depth_m``. Raises ``ValueError`` for fewer than two points, a non-finite value, an x
        not increasing, a depth not positive, or a segment steeper than 1:1 (the ray caster assumes the floor is
        a function of x)."""
        pts = tuple((float(x), float(z)) for x, z in points_north_depth_m)
        if not pts:
            self.floor_profile = ()
            return
        ok = len(pts) >= 2 and all(math.isfinite(x) and math.isfinite(z) and z > 0.0 for x, z in pts)
        ok = ok and all(b[0] > a[0] and abs(b[1] - a[1]) <= b[0] - a[0] for a, b in zip(pts, pts[1:]))
        if not ok:
            raise ValueError("floor profile must be at least two (x north, depth) points in m, x increasing, depth "
                             f"positive, slopes within 1:1; got {list(points_north_depth_m)}")
        self.floor_profile = pts

    def _profile_segments(self) -> list[tuple[float, float, float, float]]:
        """(x_lo, x_hi, depth at x_lo, slope) of the profile's pieces, the constant ends from -inf and to +inf."""
        pts = self.floor_profile
        segs = [(-math.inf, pts[0][0], pts[0][1], 0.0)]
        segs += [(a[0], b[0], a[1], (b[1] - a[1]) / (b[0] - a[0])) for a, b in zip(pts, pts[1:])]
        segs.append((pts[-1][0], math.inf, pts[-1][1], 0.0))
        return segs

    def _profile_depth_m(self, x: float) -> float:
        pts = self.floor_profile
        if not pts:
            return self.depth_m
        if x <= pts[0][0]:
            return pts[0][1]
        for a, b in zip(pts, pts[1:]):
            if x <= b[0]:
                return a[1] + (b[1] - a[1]) * (x - a[0]) / (b[0] - a[0])
        return pts[-1][1]

    def floor_depth_m(self, x_m: float, y_m: float) -> float:
        """Depth (m, NED z) of the floor at the horizontal position (x, y) (module docstring)."""
        gn, ge = self.floor_gradient
        return (self._profile_depth_m(float(x_m)) + gn * (float(x_m) - 0.5 * self.length_m)
                + ge * (float(y_m) - 0.5 * self.width_m))

    def altitude_m(self, point_ned_m: Sequence[float]) -> float:
        """Vertical distance (m) from a point to the floor (negative below the floor)."""
        return self.floor_depth_m(point_ned_m[0], point_ned_m[1]) - float(point_ned_m[2])

    def wall_distance_m(self, point_ned_m: Sequence[float]) -> float:
        """Horizontal distance (m) from a point to the nearest wall (negative outside the box)."""
        x, y = float(point_ned_m[0]), float(point_ned_m[1])
        return min(x, self.length_m - x, y, self.width_m - y)

    def ray_distance_m(self, origin_ned_m: Sequence[float], direction_ned: Sequence[float]) -> float:
        """Distance (m) along a unit ray from ``origin_ned_m`` to the first wall or the floor it hits.

        Used for the sonar's slant range along the vehicle's down axis. Returns ``inf`` when the ray only
        leaves through the surface (points upwards) or the origin is outside the box."""
        ox, oy, oz = (float(v) for v in origin_ned_m)
        dx, dy, dz = (float(v) for v in direction_ned)
        best = math.inf
        for o, d, hi in ((ox, dx, self.length_m), (oy, dy, self.width_m)):
            if d > 1e-12:
                best = min(best, (hi - o) / d)
            elif d < -1e-12:
                best = min(best, (0.0 - o) / d)
        gn, ge = self.floor_gradient  # the floor plane z = z_f(x, y): oz + t dz = z_f(o + t d)
        if not self.floor_profile:
            den = dz - gn * dx - ge * dy
            if den > 1e-12:
                best = min(best, (self.floor_depth_m(ox, oy) - oz) / den)
            return best if best >= 0.0 else math.inf
        if best < 0.0 or self.floor_depth_m(ox, oy) - oz < 0.0:
            return math.inf  # outside the box or under the floor
        for x_lo, x_hi, z_lo, slope in self._profile_segments():  # each piece's plane, hit inside its x range
            den = dz - (gn + slope) * dx - ge * dy
            if den <= 1e-12:
                continue
            z_here = (z_lo + slope * (ox - x_lo) if math.isfinite(x_lo) else z_lo) + gn * (ox - 0.5 * self.length_m) \
                + ge * (oy - 0.5 * self.width_m)
            t = (z_here - oz) / den
            if 0.0 <= t < best and x_lo - 1e-9 <= ox + t * dx <= x_hi + 1e-9:
                best = t
        return best

    # ------------------------------------------------------------------ contact
    @property
    def contact(self) -> ContactState:
        """The latest contact report (after the last :meth:`resolve`)."""
        return ContactState(self._t, dict(self._since))

    def reset_contacts(self) -> None:
        """Forget all contacts (new run)."""
        self._since.clear()
        self._t = 0.0

    def resolve(self, state: list[float], t_s: float) -> None:
        """Enforce the box on ``state`` (13 floats, modified in place) at simulated time ``t_s``.

        Clamps the position so the hull box is inside the pool and removes the velocity into a touched face
        (module docstring); updates the contact report (:attr:`contact`)."""
        _, _, _, qx, qy, qz, qw = state[:7]
        xx, yy, zz = qx * qx, qy * qy, qz * qz
        r = ((1.0 - 2.0 * (yy + zz), 2.0 * (qx * qy - qz * qw), 2.0 * (qx * qz + qy * qw)),
             (2.0 * (qx * qy + qz * qw), 1.0 - 2.0 * (xx + zz), 2.0 * (qy * qz - qx * qw)),
             (2.0 * (qx * qz - qy * qw), 2.0 * (qy * qz + qx * qw), 1.0 - 2.0 * (xx + yy)))
        a, b, c = self.free_surface.hull_half_extents_m
        cx, cy, cz = self.free_surface.hull_centre_frd_m
        touched: list[str] = []
        v_ned = None
        floor = self.depth_m
        if self.floor_gradient != (0.0, 0.0) or self.floor_profile:
            floor = self.floor_depth_m(state[0] + r[0][0] * cx + r[0][1] * cy + r[0][2] * cz,
                                       state[1] + r[1][0] * cx + r[1][1] * cy + r[1][2] * cz)
        for axis, (lo_face, hi_face, hi) in enumerate((("south_wall", "north_wall", self.length_m),
                                                       ("west_wall", "east_wall", self.width_m),
                                                       (None, "floor", floor))):
            row = r[axis]
            centre = state[axis] + row[0] * cx + row[1] * cy + row[2] * cz
            ext = a * abs(row[0]) + b * abs(row[1]) + c * abs(row[2])
            if centre + ext > hi:
                state[axis] -= centre + ext - hi
                touched.append(hi_face)
                v_ned = self._remove_velocity(state, r, axis, +1.0, v_ned)
            elif lo_face is not None and centre - ext < 0.0:
                state[axis] += ext - centre
                touched.append(lo_face)
                v_ned = self._remove_velocity(state, r, axis, -1.0, v_ned)
            elif lo_face is None and centre + ext < 0.0:  # hull completely out of the water
                state[axis] -= centre + ext
                v_ned = self._remove_velocity(state, r, axis, -1.0, v_ned)
        fraction = self.free_surface(state[2], r[2][0], r[2][1], r[2][2])
        if fraction < 1.0:
            touched.append("surface")
        for face in list(self._since):
            if face not in touched:
                del self._since[face]
        for face in touched:
            self._since.setdefault(face, t_s)
        self._t = t_s

    @staticmethod
    def _remove_velocity(state: list[float], r, axis: int, sign: float, v_ned):
        """Remove the NED velocity component along ``sign * e_axis`` if it points into the face."""
        u, v, w = state[7], state[8], state[9]
        if v_ned is None:
            v_ned = [r[i][0] * u + r[i][1] * v + r[i][2] * w for i in range(3)]
        if v_ned[axis] * sign > 0.0:
            v_ned[axis] = 0.0
            # back to body: v_body = R^T v_ned
            state[7] = r[0][0] * v_ned[0] + r[1][0] * v_ned[1] + r[2][0] * v_ned[2]
            state[8] = r[0][1] * v_ned[0] + r[1][1] * v_ned[1] + r[2][1] * v_ned[2]
            state[9] = r[0][2] * v_ned[0] + r[1][2] * v_ned[1] + r[2][2] * v_ned[2]
        return v_ned
