"""The disturbances of a truth file (:mod:`.truth`) as the simulator applies them. Pure numpy.

:class:`DisturbanceModel` turns the validated ``disturbances.*`` values into

* a thrust factor per thruster (n,) multiplying the thrust of the curves: static per-thruster and per-direction
  scales, the battery law (V(t) / V_nom)^exponent, the inflow loss 1 - k V_a (:meth:`thrust_factor`);
* an extra body wrench about the body origin (6,), FRD, N / N m, held over one integration step (:meth:`wrench`):
  damping on the velocity relative to a current instead of the velocity through the pool, cross-coupled linear damping,
  the moment of the translational drag acting at an offset centre, the tether's lumped drag and tension, and the floor's
  extra heave added mass as -dM w_dot (previous step's w_dot; explicit, stable for dM below M_RB + M_A).

Frames: body FRD about the body origin CO (= CG for Hindrax); pool NED (:mod:`.pool`). The physical source of
each term is in :mod:`.truth`."""
from __future__ import annotations

import math

import numpy as np

from hindrax_common.config import VehicleConfig

from .model import damping_vector, rotation_matrix_from_quaternion
from .truth import Disturbances

__all__ = ["DisturbanceModel"]


class DisturbanceModel:
    """Runtime form of :class:`~.truth.Disturbances` for one simulator (module docstring).

    config: the truth configuration; dist: the disturbances; model: the :class:`~.model.VehicleModel` (its
    damping coefficients and added-mass matrix); pool: the :class:`~.pool.Pool` or None.
    Attributes: ``thrust_active`` / ``wrench_active`` (anything to do), ``esc_latency_s``."""

    def __init__(self, config: VehicleConfig, dist: Disturbances, model, pool) -> None:
        self.model = model
        self.pool = pool
        t = config.thrusters
        n = len(t.names)
        per = dist.thrust.per_thruster or (1.0,) * n
        base = float(dist.thrust.scale) * np.asarray(per, dtype=float)
        self.scale_positive = base * float(dist.thrust.positive)
        self.scale_negative = base * float(dist.thrust.negative)
        self.battery = float(dist.battery.voltage_start_v) > 0.0
        self.v0 = float(dist.battery.voltage_start_v)
        self.v1 = float(dist.battery.voltage_end_v)
        self.v_nom = float(dist.battery.nominal_voltage_v)
        self.battery_s = float(dist.battery.duration_s)
        self.battery_exp = float(dist.battery.exponent)
        self.inflow_k = float(dist.inflow.loss_per_m_s)
        self.positions = np.asarray(t.positions_frd_m, dtype=float)
        self.directions = np.asarray(t.directions_frd, dtype=float)
        self.thrust_active = dist.is_set("thrust.", "battery.", "inflow.")
        self.esc_latency_s = float(config.esc.output_latency_s)
        # wrench terms
        dc = np.asarray(dist.hydrodynamics.damping_coupling_linear, dtype=float).reshape(6, 6)
        self.damping_coupling = dc - np.diag(np.diag(dc))
        self.drag_offset = np.asarray(dist.hydrodynamics.drag_centre_offset_frd_m, dtype=float)
        self.current0 = np.asarray(dist.current.velocity_ned_m_s, dtype=float)
        self.current_amp = np.asarray(dist.current.amplitude_ned_m_s, dtype=float)
        self.current_period = float(dist.current.period_s)
        self.tether_anchor = np.asarray(dist.tether.anchor_ned_m, dtype=float)
        self.tether_r = np.asarray(dist.tether.attachment_frd_m, dtype=float)
        self.tether_c = float(dist.tether.drag_n_s2_m3)
        self.tether_tension = float(dist.tether.tension_n)
        self.floor_fraction = float(dist.floor.heave_added_mass_fraction)
        self.floor_ref = float(dist.floor.reference_altitude_m)
        self.hull_half_height = 0.5 * float(config.vehicle.height_m)
        self.ma33 = float(model.added_mass_matrix[2, 2])
        self.m33 = float(model.mass_matrix[2, 2])
        self.wrench_active = bool(dist.is_set("hydrodynamics.", "current.", "tether.", "floor.heave"))

    # ------------------------------------------------------------------ thrust
    def battery_factor(self, t_s: float) -> float:
        """(V(t) / V_nom)^exponent, V falling linearly from voltage_start_v to voltage_end_v (1 when off)."""
        if not self.battery:
            return 1.0
        v = self.v0 + (self.v1 - self.v0) * min(1.0, max(0.0, t_s / self.battery_s))
        return (v / self.v_nom) ** self.battery_exp

    def current_ned(self, t_s: float) -> np.ndarray:
        """Water velocity (3,) in NED, m/s, at ``t_s``."""
        if not np.any(self.current_amp):
            return self.current0
        return self.current0 + self.current_amp * math.sin(2.0 * math.pi * t_s / self.current_period)

    def relative_nu(self, t_s: float, state) -> np.ndarray:
        """nu_r (6,): the body velocity relative to the water (FRD)."""
        nu = np.asarray(state[7:13], dtype=float)
        vc = self.current_ned(t_s)
        if not np.any(vc):
            return nu
        r = rotation_matrix_from_quaternion(state[3:7])
        nu = nu.copy()
        nu[:3] -= r.T @ vc
        return nu

    def thrust_factor(self, t_s: float, state, base_force_n: np.ndarray) -> np.ndarray:
        """Factor (n,) multiplying each thruster's curve thrust ``base_force_n`` (n,), N (module docstring)."""
        f = np.where(base_force_n >= 0.0, self.scale_positive, self.scale_negative) * self.battery_factor(t_s)
        if self.inflow_k > 0.0:
            nu_r = self.relative_nu(t_s, state)
            v_pt = nu_r[:3] + np.cross(nu_r[3:], self.positions)  # (n, 3) water speed at each thruster, body
            v_axial = np.einsum("ij,ij->i", v_pt, self.directions)
            v_a = np.sign(base_force_n) * v_axial  # inflow into the propeller along its thrust
            f = f * np.clip(1.0 - self.inflow_k * v_a, 0.0, 1.5)
        return f

    # ------------------------------------------------------------------ wrench
    def wrench(self, t_s: float, state, nu_dot_prev) -> list[float]:
        """Extra body wrench (6,) about CO, FRD, N / N m, for the step starting at ``t_s`` (module docstring)."""
        m = self.model
        nu = np.asarray(state[7:13], dtype=float)
        nu_r = self.relative_nu(t_s, state)
        damp = (m.damping_linear_positive, m.damping_linear_negative, m.damping_quadratic_positive,
                m.damping_quadratic_negative)
        out = np.zeros(6)
        d_r = damping_vector(nu_r, *damp)
        if nu_r is not nu:
            out += damping_vector(nu, *damp) - d_r  # the model applies -D(nu) nu; the water sees nu_r
        out -= self.damping_coupling @ nu_r
        if np.any(self.drag_offset):
            out[3:] += np.cross(self.drag_offset, -d_r[:3])
        if self.tether_c > 0.0 or self.tether_tension > 0.0:
            r = rotation_matrix_from_quaternion(state[3:7])
            pos = np.asarray(state[0:3], dtype=float)
            p_att = pos + r @ self.tether_r
            to_anchor = self.tether_anchor - p_att
            length = float(np.linalg.norm(to_anchor))
            v_att = r @ (nu[:3] + np.cross(nu[3:], self.tether_r)) - self.current_ned(t_s)
            f_ned = -self.tether_c * length * float(np.linalg.norm(v_att)) * v_att
            if length > 1e-6:
                f_ned = f_ned + self.tether_tension * to_anchor / length
            f_body = r.T @ f_ned
            out[:3] += f_body
            out[3:] += np.cross(self.tether_r, f_body)
        if self.floor_fraction > 0.0 and self.pool is not None:
            h = max(self.pool.altitude_m(state[0:3]) - self.hull_half_height, 0.05)
            # capped at half the heave inertia: the explicit -dM w_dot stays stable
            dm = min(self.floor_fraction * self.ma33 * (self.floor_ref / h) ** 3, 0.5 * self.m33)
            out[2] -= dm * float(nu_dot_prev[2])
        return out.tolist()
