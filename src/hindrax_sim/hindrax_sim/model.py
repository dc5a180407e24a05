"""6-DOF Fossen model of Hindrax: rigid body + added mass + Coriolis + damping + restoring, pure numpy.

Equations of motion ([NTNU-Thesis] eq. 2.90; each term's form, sign and source:
docs/identification.md §1.A), body frame FRD, world frame NED, nu = [u v w p q r],
tau = [X Y Z K M N]:

    eta_dot = J(eta) nu                      (position in NED, attitude as a unit quaternion)
    (M_RB + M_A) nu_dot + C_RB(nu) nu + C_A(nu) nu + D(nu) nu + g(eta) = tau

* Reference point: the body origin CO. ``vehicle.centre_of_gravity_frd_m`` is r_g and
  ``vehicle.centre_of_buoyancy_frd_m`` is r_b (relative to CO; the Hindrax file puts CO at the CG,
  any r_g is supported); the inertia about the CG is moved to CO by the parallel-axis theorem
  (:func:`rigid_body_mass_matrix`, [NTNU-Thesis] eq. 2.7).
* M_A: the 6x6 added-mass matrix of the configuration (``VehicleConfig.added_mass_matrix``, diagonal
  from [Hindrax-AM] Table 6, optional couplings; not forced symmetric); C_RB in Fossen's
  coordinate-free form, C_A = [0, -S(a1); -S(a1), -S(a2)] with a = M_A nu ([NTNU-Thesis]
  eqs. 2.80-2.83).
* D(nu) nu: per DOF ``k_l v + k_q |v| v`` ([Hindrax-Drag] eq. 2 / Table 3), the coefficient pair
  chosen by the sign of the velocity (heave: ``*_positive`` for w > 0, moving down, [Hindrax-Drag]
  §4.1). No off-diagonal damping.
* g(eta) ([NTNU-Thesis] eqs. 2.22-2.23 with the corrected sign of f_b): W = m g, B = rho g V, B
  times the submerged fraction of a free-surface model when one is given (:mod:`.pool`), else fully submerged.
* Kinematics with a unit quaternion q = (x, y, z, w) of the body FRD in NED (no Euler singularity):
  ``p_dot = R(q) v``, ``q_dot = 1/2 q (x) [w; 0]``. Euler angles (Fossen ZYX, [T] eq. 2.2) are an output only.

Fast path: :meth:`VehicleModel.derivative_list` evaluates the right-hand side on plain Python floats
(3-vectors as scalars, the constant ``(M_RB + M_A)^-1`` precomputed), because numpy's per-call
overhead dominates for 6x6 problems; the tests check it against the matrix form.

State vector (13,): ``[x_n, y_e, z_d (m, NED), q_x, q_y, q_z, q_w, u, v, w (m/s), p, q, r (rad/s)]``.
Not modelled: currents (nu is relative to still water), the variation of added mass and damping near
the surface, floor and walls, thruster-hull interaction ([Hindrax-Drag] §6)."""
from __future__ import annotations

import math
from typing import Callable, Sequence

import numpy as np

from hindrax_common.config import DOFS, VehicleConfig

from hindrax_onboard.vehicle.rigid_body import rigid_body_mass_matrix, skew

__all__ = ["skew", "rigid_body_mass_matrix", "damping_vector", "restoring_vector",
           "rotation_matrix_from_quaternion", "euler_from_rotation_matrix", "VehicleModel"]

#: A free-surface model: (depth of CO m, R20, R21, R22) -> submerged fraction in [0, 1] (see pool.FreeSurface).
SurfaceFraction = Callable[[float, float, float, float], float]


# --------------------------------------------------------------------------------------------- matrix forms
def damping_vector(nu, linear_positive, linear_negative, quadratic_positive, quadratic_negative) -> np.ndarray:
    """D(nu) nu (6,): per DOF k_l v + k_q |v| v, the coefficients chosen by the sign of v ([Hindrax-Drag] eq. 2).

    All coefficient arguments are (6,) positive numbers in SNAME order (kg/s, kg/m; kg m^2/s, kg m^2)."""
    nu = np.asarray(nu, dtype=float)
    pos = nu >= 0.0
    kl = np.where(pos, linear_positive, linear_negative)
    kq = np.where(pos, quadratic_positive, quadratic_negative)
    return kl * nu + kq * np.abs(nu) * nu


def restoring_vector(rotation_ned_from_body, weight_n: float, buoyancy_n: float, r_g_m, r_b_m) -> np.ndarray:
    """g(eta) (6,) on the left-hand side of the equations of motion (docs/identification.md §1.A, [NTNU-Thesis] eq.
    2.22).

    g = -[R^T (f_g + f_b); r_g x R^T f_g + r_b x R^T f_b], f_g = [0, 0, W], f_b = [0, 0, -B] (NED).
    rotation_ned_from_body (3, 3): R, body FRD to NED. W, B in N; r_g, r_b (3,) from CO, FRD, m."""
    down_body = np.asarray(rotation_ned_from_body, dtype=float)[2]  # R^T [0, 0, 1]
    f_g = weight_n * down_body
    f_b = -buoyancy_n * down_body
    return -np.concatenate([f_g + f_b, np.cross(r_g_m, f_g) + np.cross(r_b_m, f_b)])


def rotation_matrix_from_quaternion(q_xyzw) -> np.ndarray:
    """R (3, 3), body FRD to NED, of a unit quaternion (x, y, z, w) (normalised here)."""
    x, y, z, w = np.asarray(q_xyzw, dtype=float) / np.linalg.norm(q_xyzw)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def euler_from_rotation_matrix(r) -> np.ndarray:
    """Fossen ZYX Euler angles [phi theta psi] (rad) of R = Rz(psi) Ry(theta) Rx(phi) ([T] eq. 2.2).

    phi = atan2(R21, R22), theta = -asin(R20), psi = atan2(R10, R00); psi in (-pi, pi]."""
    r = np.asarray(r, dtype=float)
    return np.array([math.atan2(r[2, 1], r[2, 2]), -math.asin(max(-1.0, min(1.0, r[2, 0]))),
                     math.atan2(r[1, 0], r[0, 0])])


# --------------------------------------------------------------------------------------------- the model
class VehicleModel:
    """Fossen 6-DOF model built from a :class:`~hindrax_common.config.VehicleConfig` (module docstring).

    Parameters: ``config`` (every physical parameter comes from it: mass, volume, water density, gravity,
    r_g, r_b, inertia, added-mass matrix, damping); ``surface_fraction`` optional free-surface model
    ``(depth_co_m, R20, R21, R22) -> fraction in [0, 1]`` scaling the buoyancy (None: always submerged).

    Read-only attributes: ``mass_kg``, ``weight_n``, ``buoyancy_n`` (fully submerged), ``r_g_m`` (3,),
    ``r_b_m`` (3,), ``inertia_o_kg_m2`` (3, 3) about CO, ``mass_matrix_rigid_body`` (6, 6),
    ``added_mass_matrix`` (6, 6), ``mass_matrix`` (6, 6) = M_RB + M_A, ``mass_matrix_inverse`` (6, 6),
    ``damping_linear_positive`` / ``damping_linear_negative`` / ``damping_quadratic_positive`` /
    ``damping_quadratic_negative`` (6,). Raises ``ValueError`` when M_RB + M_A is singular."""

    def __init__(self, config: VehicleConfig, surface_fraction: SurfaceFraction | None = None) -> None:
        self.mass_kg = float(config.vehicle.mass_kg)
        self.weight_n = float(config.weight_n)
        self.buoyancy_n = float(config.buoyancy_n)
        self.r_g_m = np.array(config.vehicle.centre_of_gravity_frd_m, dtype=float)
        self.r_b_m = np.array(config.vehicle.centre_of_buoyancy_frd_m, dtype=float)
        self.mass_matrix_rigid_body = rigid_body_mass_matrix(self.mass_kg, self.r_g_m, config.inertia_matrix_kg_m2)
        self.inertia_o_kg_m2 = self.mass_matrix_rigid_body[3:, 3:].copy()
        self.added_mass_matrix = np.array(config.added_mass_matrix, dtype=float)
        self.mass_matrix = self.mass_matrix_rigid_body + self.added_mass_matrix
        if np.linalg.cond(self.mass_matrix) > 1e12:
            raise ValueError("M_RB + M_A is singular; check vehicle.mass_kg, inertia and added masses")
        self.mass_matrix_inverse = np.linalg.inv(self.mass_matrix)
        hydro = [config.dof_hydrodynamics(d) for d in DOFS]
        self.damping_linear_positive = np.array([h.linear_damping_positive for h in hydro])
        self.damping_linear_negative = np.array([h.linear_damping_negative for h in hydro])
        self.damping_quadratic_positive = np.array([h.quadratic_damping_positive for h in hydro])
        self.damping_quadratic_negative = np.array([h.quadratic_damping_negative for h in hydro])
        for arr in (self.r_g_m, self.r_b_m, self.mass_matrix_rigid_body, self.inertia_o_kg_m2,
                    self.added_mass_matrix, self.mass_matrix, self.mass_matrix_inverse, self.damping_linear_positive,
                    self.damping_linear_negative, self.damping_quadratic_positive, self.damping_quadratic_negative):
            arr.flags.writeable = False
        self.surface_fraction = surface_fraction
        # ---- plain-float copies for the fast path
        self._minv = tuple(tuple(float(x) for x in row) for row in self.mass_matrix_inverse)
        self._ma = tuple(tuple(float(x) for x in row) for row in self.added_mass_matrix)
        self._ma_diagonal = bool(np.all(self.added_mass_matrix == np.diag(np.diag(self.added_mass_matrix))))
        self._io = tuple(tuple(float(x) for x in row) for row in self.inertia_o_kg_m2)
        self._rg = tuple(float(x) for x in self.r_g_m)
        self._rb = tuple(float(x) for x in self.r_b_m)
        self._damp = tuple(zip(*(a.tolist() for a in (self.damping_linear_positive, self.damping_linear_negative,
                                                      self.damping_quadratic_positive,
                                                      self.damping_quadratic_negative))))

    # ------------------------------------------------------------------ helpers
    def buoyancy_fraction(self, state) -> float:
        """Submerged fraction in [0, 1] at ``state`` (1.0 without a free-surface model)."""
        if self.surface_fraction is None:
            return 1.0
        r = rotation_matrix_from_quaternion(np.asarray(state, dtype=float)[3:7])
        return float(self.surface_fraction(float(state[2]), r[2, 0], r[2, 1], r[2, 2]))

    def derivative(self, state, tau) -> np.ndarray:
        """State derivative (13,) at ``state`` (13,) for the body wrench ``tau`` (6,) about CO (FRD, N, N m)."""
        return np.array(self.derivative_list(np.asarray(state, dtype=float).tolist(),
                                             np.asarray(tau, dtype=float).tolist()))

    # ------------------------------------------------------------------ fast path
    def derivative_list(self, s: Sequence[float], tau: Sequence[float]) -> list[float]:
        """Fast state derivative on plain floats: ``s`` (13 floats), ``tau`` (6 floats) -> 13 floats.

        The equations of the module docstring (checked by the tests against their matrix form), written with scalar
        3-vector algebra. The quaternion need not be exactly unit (the integrator renormalises after each step)."""
        _, _, z, qx, qy, qz, qw, u, v, w, p, q, r = s
        # rotation body FRD -> NED
        xx, yy, zz = qx * qx, qy * qy, qz * qz
        xy, xz, yz = qx * qy, qx * qz, qy * qz
        xw, yw, zw = qx * qw, qy * qw, qz * qw
        r00 = 1.0 - 2.0 * (yy + zz)
        r01 = 2.0 * (xy - zw)
        r02 = 2.0 * (xz + yw)
        r10 = 2.0 * (xy + zw)
        r11 = 1.0 - 2.0 * (xx + zz)
        r12 = 2.0 * (yz - xw)
        r20 = 2.0 * (xz - yw)
        r21 = 2.0 * (yz + xw)
        r22 = 1.0 - 2.0 * (xx + yy)
        # kinematics: p_dot = R v; q_dot = 1/2 q (x) [0; w]
        xd = r00 * u + r01 * v + r02 * w
        yd = r10 * u + r11 * v + r12 * w
        zd = r20 * u + r21 * v + r22 * w
        qxd = 0.5 * (qw * p + qy * r - qz * q)
        qyd = 0.5 * (qw * q + qz * p - qx * r)
        qzd = 0.5 * (qw * r + qx * q - qy * p)
        qwd = -0.5 * (qx * p + qy * q + qz * r)

        m = self.mass_kg
        xg, yg, zg = self._rg
        xb, yb, zb = self._rb
        # restoring g(eta): -[(W - B) k; W r_g x k - B r_b x k], k = R^T e_z = (r20, r21, r22)
        wt = self.weight_n
        bu = self.buoyancy_n
        if self.surface_fraction is not None:
            bu *= self.surface_fraction(z, r20, r21, r22)
        net = wt - bu
        g0, g1, g2 = -net * r20, -net * r21, -net * r22
        mx = wt * xg - bu * xb
        my = wt * yg - bu * yb
        mz = wt * zg - bu * zb  # sum W r_g - B r_b; moment part = -(that x k)
        g3 = -(my * r22 - mz * r21)
        g4 = -(mz * r20 - mx * r22)
        g5 = -(mx * r21 - my * r20)

        # rigid-body Coriolis: [m (w x v + w x (w x r_g)); m r_g x (w x v) + w x (I_o w)]
        wvx = q * w - r * v
        wvy = r * u - p * w
        wvz = p * v - q * u
        wrx = q * zg - r * yg
        wry = r * xg - p * zg
        wrz = p * yg - q * xg
        c0 = m * (wvx + (q * wrz - r * wry))
        c1 = m * (wvy + (r * wrx - p * wrz))
        c2 = m * (wvz + (p * wry - q * wrx))
        (i00, i01, i02), (i10, i11, i12), (i20, i21, i22) = self._io
        hx = i00 * p + i01 * q + i02 * r
        hy = i10 * p + i11 * q + i12 * r
        hz = i20 * p + i21 * q + i22 * r
        c3 = m * (yg * wvz - zg * wvy) + (q * hz - r * hy)
        c4 = m * (zg * wvx - xg * wvz) + (r * hx - p * hz)
        c5 = m * (xg * wvy - yg * wvx) + (p * hy - q * hx)

        # added-mass Coriolis: a = M_A nu; [w x a1; v x a1 + w x a2]
        ma = self._ma
        if self._ma_diagonal:
            a0, a1, a2 = ma[0][0] * u, ma[1][1] * v, ma[2][2] * w
            a3, a4, a5 = ma[3][3] * p, ma[4][4] * q, ma[5][5] * r
        else:
            nu = (u, v, w, p, q, r)
            a0, a1, a2, a3, a4, a5 = (row[0] * nu[0] + row[1] * nu[1] + row[2] * nu[2] + row[3] * nu[3]
                                      + row[4] * nu[4] + row[5] * nu[5] for row in ma)
        c0 += q * a2 - r * a1
        c1 += r * a0 - p * a2
        c2 += p * a1 - q * a0
        c3 += (v * a2 - w * a1) + (q * a5 - r * a4)
        c4 += (w * a0 - u * a2) + (r * a3 - p * a5)
        c5 += (u * a1 - v * a0) + (p * a4 - q * a3)

        # damping D(nu) nu and the right-hand side
        rhs = []
        for i, (vel, c, g, (klp, kln, kqp, kqn)) in enumerate(zip((u, v, w, p, q, r), (c0, c1, c2, c3, c4, c5),
                                                                 (g0, g1, g2, g3, g4, g5), self._damp)):
            if vel >= 0.0:
                d = (klp + kqp * vel) * vel
            else:
                d = (kln - kqn * vel) * vel
            rhs.append(tau[i] - c - d - g)
        f0, f1, f2, f3, f4, f5 = rhs
        acc = [row[0] * f0 + row[1] * f1 + row[2] * f2 + row[3] * f3 + row[4] * f4 + row[5] * f5 for row in self._minv]
        return [xd, yd, zd, qxd, qyd, qzd, qwd, *acc]
