"""The control law: depth / altitude, heading, roll, pitch and surge/sway velocity holds from a model (pure numpy).

Per held DOF, with the model of :mod:`.model` (inertia M, damping D(v), constant force b, restoring k_r), the law of
docs/control.md §2 (its items 1-6 give the reasons and the numbers):

* a **reference model** (:class:`ReferenceModel`, [Fossen2011] §10.2) turns the setpoint r into a
  smooth desired state, rate- and acceleration-limited; surge and sway velocities pass a first-order
  filter. Engaging a hold starts it at the measured state (bumpless transfer);
* **feedforward** of the model at the desired state ([Fossen2011] §13.2):
  tau_ff = M x_d'' + D(x_d') + b + k_r sin(x_d) (heave: b = the net buoyancy B - W; roll, pitch: the
  restoring moment);
* **feedback** PID on e = x_d - x ([Fossen2011] §12.2): tau_fb = M (k_p e + k_d e' + k_i int e) with
  k_p = w_c^2, k_d = 2 zeta w_c, k_i = w_c k_p / 10 (velocity holds k_v = w_c, k_i = w_c k_v / 10),
  at the bandwidth w_c = w (1 - 1.96 sigma) that the inertia's relative 1-sigma sigma allows (not
  below w / 2, :func:`design_gains`);
* **saturation and anti-windup**: each wrench component clipped to ``hold_fraction`` of the axis' authority per
  direction; conditional integration ([AstromHagglund2006] Ch. 3) stops while the output is clipped or the allocation
  reported the axis short (:meth:`Controller.note_allocation`) in the direction of the error.

Depth is NED z of the body origin (down positive); the heave force is projected on the body z axis
as Z = F / (cos(roll) cos(pitch)). **Altitude** mode holds the Ping1D range over a local floor plane
(:class:`FloorEstimator`, fed with the Ping1D and the DVL-75 beam ranges as floor points), whose
rate and acceleration under the moving vehicle are fed forward (:meth:`Controller._vertical`).

Why our own code: the reference model, feedforward and anti-windup are a few lines each around the model, and no
maintained Python library implements marine model-based PID with reference feedforward. The floor filter steps with
:class:`~hindrax_onboard.estimation.kalman.LinearKalman`, filterpy's predict/update equations without scipy (that
module's docstring).

Frames: body FRD, NED, SNAME order (docs/architecture.md §3); angles in rad, heading clockwise from north."""
from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Mapping, Sequence

import numpy as np

from hindrax_common.config import DOFS, VehicleConfig
from hindrax_common.base.frames import wrap_angle

from ..estimation.kalman import LinearKalman
from ..vehicle.state import all_finite, finite_or_zero, finite_or_zeros, rotation_ned_from_body
from .model import AxisModel, ControlModel

__all__ = ["ControlSettings", "AxisGains", "design_gains", "ReferenceModel", "PositionAxis", "VelocityAxis",
           "FloorEstimator", "ControlInput", "Controller", "UNCERTAINTY_Z", "MIN_BANDWIDTH_FACTOR"]

#: Quantile of the inertia's uncertainty the bandwidth is designed for (95 %, two-sided).
UNCERTAINTY_Z = 1.96
#: The uncertainty never lowers the feedback bandwidth below this fraction of the target.
MIN_BANDWIDTH_FACTOR = 0.5
#: The integral gain as a fraction of the bandwidth times the proportional gain ([Fossen2011] §12.2).
INTEGRAL_RATIO = 0.1
#: Share of an axis' force limit the reference model's acceleration may ask for (times the model's inertia).
REFERENCE_ACCEL_FRACTION = 0.5
#: Largest reference-model sub-step, s (semi-implicit Euler).
_REF_STEP_S = 0.005
#: ASSUMPTION: 1-sigma of one Ping1D range for the floor filter, m, and of a DVL beam range as a fraction of it
#: (the vehicle file declares neither; the virtual pool uses 5 mm and 1 %).
PING_RANGE_STD_M = 0.01
DVL_BEAM_RANGE_STD_FRACTION = 0.02
#: Without any floor point (Ping1D or DVL beam) for this long the floor estimate is held where it was, s.
FLOOR_TIMEOUT_S = 1.0
#: ASSUMPTION: random walk of the floor's slope per metre travelled, 1/sqrt(m): a slope change of 0.25 (a pool's 1:12
#: shallow part to its 1:3 deep-end transition, or a bed's edge) within the 0.4 m that the DVL-75 beams' footprints
#: span at 0.5 m altitude: 0.25 / sqrt(0.4) = 0.4.
FLOOR_GRADIENT_WALK_PER_SQRT_M = 0.4
#: ASSUMPTION: 1-sigma change of the floor's slope between a DVL beam's footprint and the altimeter's (dimensionless;
#: the error of the local plane at horizontal distance d from the altimeter's footprint is this times d, added to the
#: beam's range noise): without it a beam still on the old slope behind the altimeter's footprint
#: holds the plane's gradient back (docs/control.md §6).
FLOOR_SLOPE_CHANGE_STD = 0.1
#: Time constant of the low-pass on the time derivative of the floor gradient estimate, s: two reports of the DVL-75
#: beams at their 10 Hz (docs/devices.md §1), the shortest window that smooths the steps of the 10 Hz updates.
FLOOR_GRADIENT_RATE_FILTER_S = 0.2


@dataclass(frozen=True)
class ControlSettings:
    """Tuning of the holds (section ``control`` of the vehicle file, all optional; docs/control.md §3).

    rate_hz: control rate (the node's timer). *_bandwidth_rad_s: target bandwidth w of the depth (and altitude),
    heading, roll/pitch and surge/sway velocity holds. damping_ratio: zeta of the reference models and the PID.
    hold_fraction: fraction of each axis' authority the holds may use. max_depth_rate_m_s, max_yaw_rate_rad_s: rate
    limits of the reference models. sensor_timeout_s: the node stops when the depth or attitude is older than this."""

    rate_hz: float = 50.0
    depth_bandwidth_rad_s: float = 2.0
    heading_bandwidth_rad_s: float = 2.0
    attitude_bandwidth_rad_s: float = 2.0
    velocity_bandwidth_rad_s: float = 3.0
    damping_ratio: float = 1.0
    hold_fraction: float = 0.6
    max_depth_rate_m_s: float = 0.3
    max_yaw_rate_rad_s: float = 0.6
    sensor_timeout_s: float = 0.5

    @classmethod
    def from_config(cls, cfg: VehicleConfig) -> "ControlSettings":
        """The ``control.*`` keys of the vehicle file (validated by its schema), defaults for the absent ones."""
        given = {f.name: getattr(cfg.control, f.name) for f in fields(cls)}
        return cls(**{k: float(v) for k, v in given.items() if v is not None})

    def bandwidth(self, dof: str) -> float:
        """Target bandwidth w of one DOF's hold, rad/s."""
        return {"surge": self.velocity_bandwidth_rad_s, "sway": self.velocity_bandwidth_rad_s,
                "heave": self.depth_bandwidth_rad_s, "roll": self.attitude_bandwidth_rad_s,
                "pitch": self.attitude_bandwidth_rad_s, "yaw": self.heading_bandwidth_rad_s}[dof]


@dataclass(frozen=True)
class AxisGains:
    """Feedback gains of one hold (module docstring), per unit inertia: k_p (1/s^2), k_d (1/s), k_i (1/s^3) for a
    position hold; velocity holds use k_p = k_v (1/s), k_d = 0, k_i (1/s^2).

    w_target, w: target and feedback bandwidth (rad/s); factor = w / w_target; inertia: M of the model; source: where
    M came from; rel_std: its relative 1-sigma."""

    dof: str
    w_target: float
    w: float
    factor: float
    kp: float
    kd: float
    ki: float
    inertia: float
    rel_std: float
    source: str

    def describe(self) -> str:
        """One line: the gains in force units and where they came from."""
        m = self.inertia
        rot = self.dof in ("roll", "pitch", "yaw")
        if self.dof in ("surge", "sway"):
            g = f"Kv {m * self.kp:.3g} N s/m, Ki {m * self.ki:.3g} N/m"
        else:
            f, x = ("N m", "rad") if rot else ("N", "m")
            g = (f"Kp {m * self.kp:.3g} {f}/{x}, Kd {m * self.kd:.3g} {f} s/{x}, Ki {m * self.ki:.3g} {f}/({x} s)")
        low = "" if self.factor >= 1.0 else (f", lowered x{self.factor:.2f} by the inertia's "
                                             f"{100 * self.rel_std:.1f} % std")
        return (f"{self.dof}: {g} at {self.w:.2f} rad/s (target {self.w_target:.2f}{low}); inertia {m:.4g} "
                f"[{self.source}]")


def design_gains(axis: AxisModel, w_target: float, zeta: float = 1.0, velocity: bool = False) -> AxisGains:
    """Gains of one hold for the target bandwidth ``w_target`` (rad/s > 0), lowered by the model's inertia uncertainty
    (module docstring). Raises ``ValueError`` for a bandwidth or damping ratio that is not > 0."""
    if not (math.isfinite(w_target) and w_target > 0 and math.isfinite(zeta) and zeta > 0):
        raise ValueError(f"{axis.dof}: bandwidth and damping ratio must be > 0, got {w_target}, {zeta}")
    factor = max(MIN_BANDWIDTH_FACTOR, 1.0 - UNCERTAINTY_Z * max(0.0, float(axis.inertia_rel_std)))
    w = w_target * factor
    if velocity:
        kp, kd, ki = w, 0.0, INTEGRAL_RATIO * w * w
    else:
        kp, kd, ki = w * w, 2.0 * zeta * w, INTEGRAL_RATIO * w ** 3
    return AxisGains(axis.dof, float(w_target), float(w), float(factor), float(kp), float(kd), float(ki),
                     float(axis.inertia), float(axis.inertia_rel_std), axis.sources.get("inertia", "?"))


class ReferenceModel:
    """Critically damped (``zeta``) second-order reference x_d'' = w^2 (r - x_d) - 2 zeta w x_d', with the rate limited
    to ``max_rate`` and the acceleration to ``max_accel`` while speeding up (the saturating elements of [Fossen2011]
    §10.2), ``1 / REFERENCE_ACCEL_FRACTION`` times that while braking (a hold engaged on a moving
    vehicle brakes with the whole limit, as the feedback would); angles wrap (``angle``).
    :meth:`step` integrates one control tick in sub-steps of at most 5 ms (semi-implicit Euler) and
    returns (x_d, x_d', x_d'')."""

    def __init__(self, w: float, zeta: float = 1.0, max_rate: float = math.inf, angle: bool = False,
                 max_accel: float = math.inf) -> None:
        self.w, self.zeta, self.max_rate, self.angle = float(w), float(zeta), float(max_rate), bool(angle)
        self.max_accel = float(max_accel)
        self.x = math.nan
        self.v = 0.0
        self.a = 0.0

    def copy_empty(self) -> "ReferenceModel":
        """A new reference model with the same settings and no state."""
        return ReferenceModel(self.w, self.zeta, self.max_rate, self.angle, self.max_accel)

    @property
    def ready(self) -> bool:
        """True once :meth:`reset` gave it a state."""
        return math.isfinite(self.x)

    def reset(self, x: float, v: float = 0.0) -> None:
        """Start at the state (x, v); NaN rate counts as 0."""
        self.x = wrap_angle(x) if self.angle else float(x)
        self.v = finite_or_zero(v)
        self.v = max(-self.max_rate, min(self.max_rate, self.v))
        self.a = 0.0

    def step(self, r: float, dt: float) -> tuple[float, float, float]:
        """Advance by ``dt`` (s) towards the setpoint ``r``; returns (x_d, x_d', x_d'')."""
        if not self.ready:
            self.reset(r)
        n = max(1, int(math.ceil(dt / _REF_STEP_S - 1e-9)))
        h = dt / n
        w2, c, am = self.w * self.w, 2.0 * self.zeta * self.w, self.max_accel
        for _ in range(n):
            e = wrap_angle(r - self.x) if self.angle else r - self.x
            v0 = self.v
            a = w2 * e - c * v0
            lim = am if a * v0 >= 0.0 else am / REFERENCE_ACCEL_FRACTION  # speeding up / braking
            a = max(-lim, min(lim, a))
            self.v = max(-self.max_rate, min(self.max_rate, v0 + h * a))
            self.a = (self.v - v0) / h
            self.x = self.x + h * self.v
            if self.angle:
                self.x = wrap_angle(self.x)
        return self.x, self.v, self.a


class _Axis:
    """Common part of the holds: limits, integrator, anti-windup (module docstring)."""

    def __init__(self, model: AxisModel, gains: AxisGains, limit_neg: float, limit_pos: float) -> None:
        self.model = model
        self.gains = gains
        self.lo = -abs(float(limit_neg))
        self.hi = abs(float(limit_pos))
        self.integral = 0.0
        self.engaged = False
        self.saturated_dir = 0  # from the allocation: +1 the axis got less than asked upwards, -1 downwards

    def release(self) -> None:
        """The DOF is free (or its measurement invalid): the next hold starts from the measured state."""
        self.engaged = False

    def reset_integral(self) -> None:
        """Clear the integrator."""
        self.integral = 0.0

    def _close(self, ff: float, fb: float, e: float, dt: float, proj: float) -> float:
        """Body force of feedforward ``ff`` + feedback ``fb`` (axis units) + the integral, projected by ``proj``,
        clipped, with conditional integration."""
        m, ki = self.model.inertia, self.gains.ki
        cand = self.integral + e * dt
        tau_i = m * ki * cand
        total = proj * (ff + fb + tau_i)
        blocked = (total > self.hi and e > 0) or (total < self.lo and e < 0) or (self.saturated_dir * e > 0)
        if not blocked:
            self.integral = cand
        if m * ki > 0:  # the integral term alone stays within the limits
            self.integral = min(max(self.integral, self.lo / (m * ki) / max(proj, 1e-6)),
                                self.hi / (m * ki) / max(proj, 1e-6))
        out = proj * (ff + fb + m * ki * self.integral)
        return float(min(max(out, self.lo), self.hi))


class PositionAxis(_Axis):
    """Hold of a position-like DOF (depth, roll, pitch, heading): reference model + feedforward + PID (module
    docstring). ``angle``: the coordinate wraps (roll, pitch, yaw). ``max_rate``, ``max_accel``: the reference model's
    rate and acceleration limits."""

    def __init__(self, model: AxisModel, gains: AxisGains, limit_neg: float, limit_pos: float, zeta: float = 1.0,
                 max_rate: float = math.inf, angle: bool = False, max_accel: float = math.inf) -> None:
        super().__init__(model, gains, limit_neg, limit_pos)
        self.angle = angle
        self.ref = ReferenceModel(gains.w_target, zeta, max_rate, angle, max_accel)

    def update(self, setpoint: float, x: float, v: float, dt: float, proj: float = 1.0) -> float:
        """Body force or moment for the measured state (x, v) towards ``setpoint`` over one tick ``dt``."""
        if not self.engaged:
            self.ref.reset(x, v)
            self.engaged = True
        xd, vd, ad = self.ref.step(setpoint, dt)
        return self.track(xd, vd, ad, x, v, dt, proj)

    def track(self, xd: float, vd: float, ad: float, x: float, v: float, dt: float, proj: float = 1.0) -> float:
        """Body force or moment tracking the desired state (x_d, x_d', x_d'') (module docstring)."""
        self.engaged = True
        m = self.model
        e = wrap_angle(xd - x) if self.angle else xd - x
        de = vd - finite_or_zero(v)
        ff = m.inertia * ad + m.damping(vd) + m.bias + m.restoring * math.sin(xd)
        fb = m.inertia * (self.gains.kp * e + self.gains.kd * de)
        return self._close(ff, fb, e, dt, proj)


class VelocityAxis(_Axis):
    """Hold of a body velocity (surge, sway): first-order reference at the target bandwidth, feedforward
    M u_d' + D(u_d), PI feedback (module docstring)."""

    def __init__(self, model: AxisModel, gains: AxisGains, limit_neg: float, limit_pos: float) -> None:
        super().__init__(model, gains, limit_neg, limit_pos)
        self.ud = 0.0
        self.ud_rate = 0.0

    def release(self) -> None:
        """The DOF is free: the reference restarts from the measured velocity, with no acceleration."""
        super().release()
        self.ud_rate = 0.0

    def update(self, setpoint: float, u: float, dt: float) -> float:
        """Body force for the measured velocity ``u`` (m/s) towards ``setpoint`` over one tick ``dt``."""
        if not self.engaged:
            self.ud = float(u)
            self.engaged = True
        a = self.gains.w_target * (setpoint - self.ud)
        self.ud += a * dt
        self.ud_rate = a
        m = self.model
        e = self.ud - u
        ff = m.inertia * a + m.damping(self.ud)
        fb = m.inertia * self.gains.kp * e
        return self._close(ff, fb, e, dt, 1.0)


class FloorEstimator:
    """The floor under the vehicle as a local plane (docs/control.md §2 item 6): depth z_f at the body origin's
    horizontal position (NED z, m) and its gradient (g_n, g_e) (depth change per metre north and east); a linear
    Kalman filter (:class:`~hindrax_onboard.estimation.kalman.LinearKalman`).

    Each range is a floor point at a horizontal offset (dN, dE) from the body origin, a measurement z_f + g_n dN + g_e
    dE (:meth:`update_point`); between points the state advances as z_f += g . v dt (:meth:`predict_to`). The slope
    walks in time and per metre travelled (:data:`FLOOR_GRADIENT_WALK_PER_SQRT_M`). Without any range for
    :data:`FLOOR_TIMEOUT_S` the floor is held (``stale``)."""

    def __init__(self) -> None:
        self.kf = LinearKalman(3)
        # random walk in time: depth 0.005 m/sqrt(s), gradient 0.02 1/sqrt(s)
        self.q = np.diag([0.005, 0.02, 0.02]) ** 2
        self.q_per_m = np.diag([0.0, 1.0, 1.0]) * FLOOR_GRADIENT_WALK_PER_SQRT_M ** 2
        self.prior_std = 0.2  # 1-sigma of the gradient before the first point
        self.t_s: float | None = None
        self.last_update_s = -math.inf

    @property
    def ready(self) -> bool:
        """True once a floor point was fused."""
        return self.t_s is not None

    def stale(self, t_s: float) -> bool:
        """True when no floor point came for :data:`FLOOR_TIMEOUT_S` before ``t_s``."""
        return t_s - self.last_update_s > FLOOR_TIMEOUT_S

    def predict_to(self, t_s: float, velocity_ne_m_s) -> None:
        """Advance to ``t_s`` with the horizontal velocity (north, east; m/s) held since the filter's time."""
        if self.t_s is None or t_s <= self.t_s:
            return
        dt = t_s - self.t_s
        vn, ve = (finite_or_zero(x) for x in velocity_ne_m_s)
        self.kf.predict(F=np.array([[1.0, vn * dt, ve * dt], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]),
                        Q=self.q * dt + self.q_per_m * (math.hypot(vn, ve) * dt))
        self.t_s = float(t_s)

    def update_point(self, t_s: float, offset_ne_m, depth_m: float, std_m: float, velocity_ne_m_s) -> None:
        """Fuse one floor point at horizontal ``offset_ne_m`` (north, east; m) from the body origin and ``depth_m``
        (NED z), 1-sigma ``std_m``, seen at ``t_s`` (an older point is fused at the filter's time)."""
        if not (math.isfinite(depth_m) and math.isfinite(std_m) and std_m > 0):
            return
        dn, de = (float(x) for x in offset_ne_m)
        if self.t_s is None:
            self.kf.x = np.array([[float(depth_m)], [0.0], [0.0]])
            self.kf.P = np.diag([std_m ** 2, self.prior_std ** 2, self.prior_std ** 2])
            self.t_s = float(t_s)
        else:
            self.predict_to(max(float(t_s), self.t_s), velocity_ne_m_s)
        self.kf.update(np.array([[float(depth_m)]]), R=np.array([[std_m ** 2]]), H=np.array([[1.0, dn, de]]))
        self.last_update_s = max(self.last_update_s, float(t_s))

    def floor_at(self, t_s: float, velocity_ne_m_s) -> tuple[float, float, float]:
        """(depth m, g_n, g_e) of the floor under the body origin at ``t_s`` (extrapolated with the velocity, not
        stored); NaN before the first point."""
        if self.t_s is None:
            return math.nan, math.nan, math.nan
        z, gn, ge = (float(v) for v in self.kf.x[:, 0])
        if not self.stale(t_s):
            vn, ve = (finite_or_zero(x) for x in velocity_ne_m_s)
            z += (gn * vn + ge * ve) * max(0.0, t_s - self.t_s)
        return z, gn, ge


@dataclass
class ControlInput:
    """What the holds measure at one tick (NaN = not available): time t_s; depth_m (NED z of the body origin) and
    depth_rate_m_s; rpy_rad (3,) roll, pitch, heading; rates_frd_rad_s (3,); velocity_frd_m_s (>= 2,) body u, v;
    altitude_m (Ping1D range along the body z axis) with altitude_stamp_s (its time of validity); dvl_beam_range_m
    (4,) the DVL's beam ranges A-D (NaN without lock) with dvl_beam_stamp_s."""

    t_s: float
    depth_m: float = math.nan
    depth_rate_m_s: float = math.nan
    rpy_rad: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    rates_frd_rad_s: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    velocity_frd_m_s: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    altitude_m: float = math.nan
    altitude_stamp_s: float = math.nan
    dvl_beam_range_m: np.ndarray = field(default_factory=lambda: np.full(4, np.nan))
    dvl_beam_stamp_s: float = math.nan


class Controller:
    """The six holds from one :class:`~.model.ControlModel` (module docstring).

    authority: (6,) or (6, 2) [positive, negative] largest wrench per axis (N, N m, > 0) from the thrust allocation.
    settings: :class:`ControlSettings`. reference_accel: DOF -> acceleration limit of its reference model (m/s^2,
    rad/s^2; default :data:`REFERENCE_ACCEL_FRACTION` of the axis' limit over the model's inertia: a model that knows
    the true inertia plans what the thrusters can do). ping_position_frd_m (3,): where the altimeter sits (FRD, m);
    dvl_position_frd_m (3,) and dvl_beams_frd (4, 3): the DVL and its beam directions in the body frame (None: the
    beams are not used).

    Setpoints (attributes; NaN = not held): ``depth_m``; ``altitude_m`` (finite: altitude mode, when ranges arrive);
    ``heading_rad``; ``velocity_frd_m_s`` (2,) surge, sway; ``attitude_rad`` (2,) roll, pitch. :meth:`wrench` returns
    the body FRD wrench (6,) for one tick. Raises ``ValueError`` for an authority of the wrong shape or not > 0."""

    def __init__(self, model: ControlModel, authority, settings: ControlSettings | None = None,
                 ping_position_frd_m: Sequence[float] = (0.0, 0.0, 0.0),
                 dvl_position_frd_m: Sequence[float] = (0.0, 0.0, 0.0), dvl_beams_frd=None,
                 reference_accel: Mapping[str, float] | None = None) -> None:
        a = np.asarray(authority, dtype=float)
        if a.shape == (6,):
            a = np.stack([a, a], axis=1)
        if a.shape != (6, 2) or not np.all(np.isfinite(a)) or np.any(a <= 0):
            raise ValueError(f"authority must be (6,) or (6, 2) numbers > 0, got {np.asarray(authority).tolist()}")
        self.model = model
        self.settings = settings or ControlSettings()
        s = self.settings
        lim = s.hold_fraction * a
        # the default of the class docstring, on the smaller of the axis' two limits
        self.reference_accel = {d: REFERENCE_ACCEL_FRACTION * float(np.min(lim[i])) / model.axis(d).inertia
                                for i, d in enumerate(DOFS)}
        if reference_accel:
            self.reference_accel.update({k: float(v) for k, v in reference_accel.items()})
        self.gains: dict[str, AxisGains] = {}
        self.axes: dict[str, _Axis] = {}
        for i, dof in enumerate(DOFS):
            velocity = dof in ("surge", "sway")
            g = design_gains(model.axis(dof), s.bandwidth(dof), s.damping_ratio, velocity)
            self.gains[dof] = g
            if velocity:
                self.axes[dof] = VelocityAxis(model.axis(dof), g, lim[i, 1], lim[i, 0])
            else:
                rate = {"heave": s.max_depth_rate_m_s, "yaw": s.max_yaw_rate_rad_s}.get(dof, math.inf)
                self.axes[dof] = PositionAxis(model.axis(dof), g, lim[i, 1], lim[i, 0], s.damping_ratio, rate,
                                              angle=dof != "heave", max_accel=self.reference_accel[dof])
        self.altitude_ref = ReferenceModel(s.depth_bandwidth_rad_s, s.damping_ratio, s.max_depth_rate_m_s,
                                           max_accel=self.reference_accel["heave"])
        self.ping_position_frd_m = np.asarray(ping_position_frd_m, dtype=float)
        self.dvl_position_frd_m = np.asarray(dvl_position_frd_m, dtype=float)
        self.dvl_beams_frd = None if dvl_beams_frd is None else np.asarray(dvl_beams_frd, dtype=float).reshape(4, 3)
        self.depth_m = math.nan
        self.altitude_m = math.nan
        self.heading_rad = math.nan
        self.velocity_frd_m_s = np.zeros(2)
        self.attitude_rad = np.zeros(2)
        self.mode = "none"  # vertical hold of the last tick: depth | altitude | waiting_altitude | none
        self.reset()

    # ------------------------------------------------------------------ reporting
    def gain_report(self) -> list[str]:
        """One line per DOF: gains, bandwidth, and the source of every model value (docs/control.md §4)."""
        out = []
        for dof in DOFS:
            a = self.model.axis(dof)
            extra = [f"damping [{a.sources.get('damping', '?')}]"]
            if dof == "heave":
                extra.append(f"net buoyancy {a.bias:+.3f} N [{a.sources.get('bias', '?')}]")
            if dof in ("roll", "pitch"):
                extra.append(f"restoring {a.restoring:.3g} N m [{a.sources.get('restoring', '?')}]")
            out.append(self.gains[dof].describe() + "; " + "; ".join(extra))
        return out

    # ------------------------------------------------------------------ inputs
    def reset(self) -> None:
        """Forget the references, integrators, floor estimate and allocation feedback (e.g. after a disarm)."""
        for ax in self.axes.values():
            ax.release()
            ax.reset_integral()
            ax.saturated_dir = 0
        self.altitude_ref = self.altitude_ref.copy_empty()
        self.floor = FloorEstimator()
        self._last_alt_stamp = -math.inf
        self._last_beam_stamp = -math.inf
        #: (t_s, gradient) of the last altitude tick
        self._gradient_prev: tuple[float, np.ndarray] | None = None
        #: low-passed d/dt of the floor gradient estimate (north, east), 1/s
        self.gradient_rate = np.zeros(2)

    def _floor_gradient_rate(self, t_s: float, gradient: np.ndarray) -> np.ndarray:
        """The time derivative of the floor gradient estimate (north, east; 1/s), differenced between altitude ticks
        and low-passed with :data:`FLOOR_GRADIENT_RATE_FILTER_S` (first order, backward Euler). Under a vehicle
        moving at v over a floor whose slope changes, the floor's vertical acceleration is g . a + g' . v: the second
        term is what a slope change asks of the depth hold, and without it the reference's acceleration is not the
        derivative of its rate (the feedback alone then has to produce the inertia force, late)."""
        if self._gradient_prev is not None:
            t0, g0 = self._gradient_prev
            dt = t_s - t0
            if dt > 0.0:
                raw = (gradient - g0) / dt
                self.gradient_rate = self.gradient_rate + dt / (FLOOR_GRADIENT_RATE_FILTER_S + dt) * (
                    raw - self.gradient_rate)
        self._gradient_prev = (float(t_s), gradient.copy())
        return self.gradient_rate

    def note_allocation(self, requested_frd, achieved_frd) -> None:
        """Anti-windup from the thrust allocation (``allocation/status``): an axis whose achieved wrench falls short of
        the requested one by more than 2 % of its limit (and 0.05 N or N m) stops integrating towards the shortfall
        until the next report; arguments (6,) FRD."""
        req = np.asarray(requested_frd, dtype=float)
        ach = np.asarray(achieved_frd, dtype=float)
        for i, dof in enumerate(DOFS):
            ax = self.axes[dof]
            d = req[i] - ach[i] if (math.isfinite(req[i]) and math.isfinite(ach[i])) else 0.0
            tol = max(0.05, 0.02 * max(ax.hi, -ax.lo))
            ax.saturated_dir = int(np.sign(d)) if abs(d) > tol else 0

    @staticmethod
    def _velocity_ne(inp: ControlInput) -> np.ndarray:
        """Measured horizontal velocity (north, east; m/s): the DVL's body velocity turned by the heading (0 when
        unknown)."""
        u, v = (finite_or_zero(x) for x in inp.velocity_frd_m_s[:2])
        psi = finite_or_zero(inp.rpy_rad[2])
        return np.array([math.cos(psi) * u - math.sin(psi) * v, math.sin(psi) * u + math.cos(psi) * v])

    def _floor_samples(self, inp: ControlInput) -> None:
        """Fuse the new Ping1D range and DVL beam ranges of ``inp`` as floor points (:class:`FloorEstimator`)."""
        if not math.isfinite(inp.depth_m) or not all_finite(inp.rpy_rad):
            return
        rot = rotation_ned_from_body(*inp.rpy_rad)
        v_ne = self._velocity_ne(inp)
        if math.isfinite(inp.altitude_m) and math.isfinite(inp.altitude_stamp_s) \
                and inp.altitude_stamp_s > self._last_alt_stamp:
            self._last_alt_stamp = inp.altitude_stamp_s
            p = rot @ (self.ping_position_frd_m + np.array([0.0, 0.0, float(inp.altitude_m)]))
            self.floor.update_point(inp.altitude_stamp_s, p[:2], inp.depth_m + p[2], PING_RANGE_STD_M, v_ne)
        # the altimeter's footprint (horizontal offset from the body origin, NED): where the hold needs the floor
        alt = next((float(a) for a in (self.altitude_m, inp.altitude_m) if math.isfinite(a)), 0.0)
        foot_ne = (rot @ (self.ping_position_frd_m + np.array([0.0, 0.0, alt])))[:2]
        if self.dvl_beams_frd is not None and math.isfinite(inp.dvl_beam_stamp_s) \
                and inp.dvl_beam_stamp_s > self._last_beam_stamp:
            self._last_beam_stamp = inp.dvl_beam_stamp_s
            for rng, b in zip(np.asarray(inp.dvl_beam_range_m, dtype=float), self.dvl_beams_frd):
                if math.isfinite(rng) and rng > 0:
                    p = rot @ (self.dvl_position_frd_m + rng * b)
                    # the plane's own error at the beam's footprint: a slope change between it and the altimeter's
                    d_m = float(np.hypot(*(p[:2] - foot_ne)))
                    std = float(np.linalg.norm([DVL_BEAM_RANGE_STD_FRACTION * rng, 0.005,
                                                FLOOR_SLOPE_CHANGE_STD * d_m]))
                    self.floor.update_point(inp.dvl_beam_stamp_s, p[:2], inp.depth_m + p[2], std, v_ne)

    def _horizontal_reference(self, inp: ControlInput) -> tuple[np.ndarray, np.ndarray]:
        """(velocity, acceleration) (north, east) the vehicle is being driven at: the surge/sway references while
        those holds are engaged, else the measured velocity and no acceleration."""
        su, sw = self.axes["surge"], self.axes["sway"]
        if not (su.engaged and sw.engaged):
            return self._velocity_ne(inp), np.zeros(2)
        psi = finite_or_zero(inp.rpy_rad[2])
        c, s_ = math.cos(psi), math.sin(psi)
        rot = np.array([[c, -s_], [s_, c]])
        return rot @ np.array([su.ud, sw.ud]), rot @ np.array([su.ud_rate, sw.ud_rate])

    # ------------------------------------------------------------------ the law
    def wrench(self, inp: ControlInput, dt: float, free: Sequence[str] = ()) -> np.ndarray:
        """Body FRD wrench (6,) (N, N m) of the holds for one tick of ``dt`` s; DOFs in ``free`` get 0 and are
        released (module docstring)."""
        w = np.zeros(6)
        rpy = finite_or_zeros(inp.rpy_rad)
        rates = finite_or_zeros(inp.rates_frd_rad_s)
        vel = np.asarray(inp.velocity_frd_m_s, dtype=float)
        self._floor_samples(inp)
        for k, dof in enumerate(("surge", "sway")):
            ax = self.axes[dof]
            sp = float(self.velocity_frd_m_s[k])
            if dof in free or not math.isfinite(vel[k]) or not math.isfinite(sp):
                ax.release()
                continue
            w[k] = ax.update(sp, float(vel[k]), dt)
        w[2] = self._vertical(inp, dt, free, rpy)
        for k, dof, sp, measured in ((3, "roll", self.attitude_rad[0], inp.rpy_rad[:2]),
                                     (4, "pitch", self.attitude_rad[1], inp.rpy_rad[:2]),
                                     (5, "yaw", self.heading_rad, inp.rpy_rad[2:])):
            ax = self.axes[dof]
            if dof in free or not math.isfinite(sp) or not all_finite(measured):
                ax.release()
                continue
            w[k] = ax.update(float(sp), float(rpy[k - 3]), float(rates[k - 3]), dt)
        return w

    def _vertical(self, inp: ControlInput, dt: float, free: Sequence[str], rpy: np.ndarray) -> float:
        """Heave force of the depth or altitude hold. Altitude: the depth hold follows
        x_d = z_f(footprint) - (R r_ping)_z - a_d cos(roll) cos(pitch), x_d' = g . v_ref - a_d',
        x_d'' = g . a_ref + g' . v_ref - a_d'', with g the floor gradient, g' its low-passed time
        derivative (:meth:`_floor_gradient_rate`), v_ref and a_ref the surge/sway references in NED
        and a_d the reference model of the altitude setpoint."""
        ax = self.axes["heave"]
        z, zr = inp.depth_m, inp.depth_rate_m_s
        if "heave" in free or not math.isfinite(z) or not (math.isfinite(self.depth_m)
                                                            or math.isfinite(self.altitude_m)):
            ax.release()
            self.altitude_ref = self.altitude_ref.copy_empty()
            self.mode = "none"
            return 0.0
        zr = finite_or_zero(zr)
        proj = 1.0 / max(0.5, math.cos(rpy[0]) * math.cos(rpy[1]))
        if math.isfinite(self.altitude_m) and self.floor.ready:
            v_ne, a_ne = self._horizontal_reference(inp)
            zf, gn, ge = self.floor.floor_at(inp.t_s, self._velocity_ne(inp))
            if self.floor.stale(inp.t_s):
                v_ne, a_ne = np.zeros(2), np.zeros(2)
            rot = rotation_ned_from_body(*rpy)
            foot = rot @ (self.ping_position_frd_m + np.array([0.0, 0.0, float(self.altitude_m)]))
            zfp = zf + gn * foot[0] + ge * foot[1]  # floor depth under the altimeter's footprint
            engaging = not (self.mode == "altitude" and self.altitude_ref.ready and ax.engaged)
            if engaging or self.floor.stale(inp.t_s):
                self._gradient_prev, self.gradient_rate = None, np.zeros(2)
            g_rate = self._floor_gradient_rate(inp.t_s, np.array([gn, ge]))
            zf_rate = gn * v_ne[0] + ge * v_ne[1]
            # the floor's vertical acceleration under the footprint: g . a_ref + g' . v_ref (a slope change), the
            # second term no larger than the reference model's acceleration limit
            acc_lim = self.reference_accel["heave"]
            zf_acc = gn * a_ne[0] + ge * a_ne[1] + float(np.clip(g_rate @ v_ne, -acc_lim, acc_lim))
            tilt = math.cos(rpy[0]) * math.cos(rpy[1])
            offset = float((rot @ self.ping_position_frd_m)[2])
            if engaging:
                # bumpless: the altitude reference starts at the altitude the depth reference is at now
                xd0 = ax.ref.x if (ax.engaged and ax.ref.ready) else z
                vd0 = ax.ref.v if (ax.engaged and ax.ref.ready) else zr
                self.altitude_ref.reset((zfp - offset - xd0) / tilt, zf_rate - vd0)
            a_d, a_rate, a_acc = self.altitude_ref.step(float(self.altitude_m), dt)
            self.mode = "altitude"
            xd, vd, ad = zfp - offset - a_d * tilt, zf_rate - a_rate, zf_acc - a_acc
            out = ax.track(xd, vd, ad, z, zr, dt, proj)
            ax.ref.reset(xd, vd)  # a later switch to depth mode continues from here
            return out
        if not math.isfinite(self.depth_m):
            # altitude asked, no range yet: hold the depth the reference is at (the measured depth when engaging)
            self.mode = "waiting_altitude"
            return ax.update(ax.ref.x if (ax.engaged and ax.ref.ready) else z, z, zr, dt, proj)
        self.mode = "depth"
        return ax.update(float(self.depth_m), z, zr, dt, proj)
