"""Manoeuvre planning and holding control for the self-propelled tests ([Hindrax-Drag] §4; docs/architecture.md §5).

Pure numpy, no ROS. Everything here uses the vehicle configuration and SENSOR samples only (never the
simulator's truth):

* :func:`dof_authority` - the largest feasible wrench along one body axis, from the thrust allocator
  (same curves and thrust allocation matrix as the allocation node, [Hindrax-Drag] eqs. 1 and 9).
* :func:`level_ladder` - the ladder of constant thrust/moment levels, fractions
  ``identification.level_fraction_min .. level_fraction_max`` of the authority ([Hindrax-Drag] §4: constant
  known forces/torques, one DOF at a time).
* :class:`PoolBox` - where the body origin may go: the pool (``pool.*``) shrunk by ``pool.margin_m`` plus
  half the vehicle's extent at walls and floor, ``limits.max_depth_m`` / ``limits.min_altitude_m`` below
  and half the vehicle height plus :data:`SURFACE_CLEARANCE_M` at the free surface (the margin key is
  documented for walls and floor only). Run lengths are planned from the distance left in the box.
* :class:`HoldController` - holds for depth (or altitude), roll, pitch, heading and surge/sway velocity: the
  model-based law of :mod:`hindrax_onboard.control.law` with the vehicle file's model (or an identified one); the
  former PD/PI law is :class:`hindrax_onboard.control.legacy.LegacyPDHold`.

Frames: body FRD, world NED (docs/architecture.md §3); conversions through :mod:`hindrax_common.base.frames`."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from hindrax_bringup.allocation.core import AllocationCore
from hindrax_common.config import DOFS, VehicleConfig
from hindrax_drivers.dvl75.protocol import beam_directions_frd

from .law import ControlInput, ControlSettings, Controller
from .model import ControlModel, model_from_config, prior_inertia
from ..vehicle.state import SensorState, rotation_ned_from_body

__all__ = ["DOF_INDEX", "SURFACE_CLEARANCE_M", "dof_authority",
           "level_ladder", "prior_inertia", "PoolBox", "HoldController"]

#: DOF name -> index in nu / tau (SNAME order).
DOF_INDEX = {d: i for i, d in enumerate(DOFS)}
#: Clearance between the hull top and the free surface, m (the hull must not emerge: buoyancy would change).
SURFACE_CLEARANCE_M = 0.1


def dof_authority(core: AllocationCore, dof: str) -> tuple[float, float]:
    """(positive, negative) authority along one body axis, N or N m (both > 0).

    The allocator is asked for a very large pure wrench along the FRD axis; with uniform scaling it
    returns the largest feasible multiple, whose achieved component (thrust curves at the quantised pulse
    widths, times the thrust allocation matrix) is the authority. Raises ``KeyError`` for an unknown DOF."""
    i = DOF_INDEX[dof]
    out = []
    for sign in (1.0, -1.0):
        w = np.zeros(6)
        w[i] = sign * 1e4
        res = core.allocator.allocate(w)
        out.append(abs(float(res.achieved_wrench[i])))
    return out[0], out[1]


def level_ladder(cfg: VehicleConfig, authority: float, levels: int | None = None) -> list[float]:
    """Constant levels (N or N m), evenly spaced fractions of ``authority`` ([Hindrax-Drag] §4).

    Fractions from ``identification.level_fraction_min`` to ``level_fraction_max``;
    ``levels`` defaults to ``identification.levels_per_dof``. Raises ``ValueError`` for levels < 1."""
    n = int(cfg.identification.levels_per_dof if levels is None else levels)
    if n < 1:
        raise ValueError(f"levels must be >= 1, got {levels}")
    lo = float(cfg.identification.level_fraction_min)
    hi = float(cfg.identification.level_fraction_max)
    fr = [hi] if n == 1 else list(np.linspace(lo, hi, n))
    return [float(f * authority) for f in fr]


def tilt_test_angle_rad(cfg: VehicleConfig, dof: str) -> float:
    """``identification.roll_test_angle_rad`` or ``pitch_test_angle_rad``: where the roll or pitch test turns back,
    rad ([Hindrax-Drag] §4.2). Raises KeyError for another DOF."""
    ident = cfg.identification
    return {"roll": ident.roll_test_angle_rad, "pitch": ident.pitch_test_angle_rad}[dof]


@dataclass(frozen=True)
class PoolBox:
    """Allowed region of the body origin (NED, m): x in [x_min, x_max], y in [y_min, y_max], z in [z_min, z_max].

    :meth:`from_config` builds it from ``pool.*``, ``limits.*`` and the vehicle size (module docstring)."""

    x_min: float
    x_max: float
    y_min: float
    y_max: float
    z_min: float
    z_max: float

    @classmethod
    def from_config(cls, cfg: VehicleConfig) -> "PoolBox":
        """Box of the configuration. Raises ``ValueError`` when the margins leave no room."""
        pool, v, limits = cfg.pool, cfg.vehicle, cfg.limits
        m = float(pool.margin_m)
        hl, hw, hh = 0.5 * v.length_m, 0.5 * v.width_m, 0.5 * v.height_m
        half_xy = max(hl, hw)  # the heading changes in yaw tests: keep the larger half extent everywhere
        z_floor = pool.depth_m - m - hh
        z_floor = min(z_floor, float(limits.max_depth_m) - 0.05,
                      pool.depth_m - float(limits.min_altitude_m) - hh - 0.05)
        box = cls(m + half_xy, pool.length_m - m - half_xy, m + half_xy, pool.width_m - m - half_xy,
                  hh + SURFACE_CLEARANCE_M, z_floor)
        if box.x_min >= box.x_max or box.y_min >= box.y_max or box.z_min >= box.z_max:
            raise ValueError(f"the pool with its margins leaves no room for the vehicle: {box}")
        return box

    @property
    def centre(self) -> np.ndarray:
        """(3,) centre of the box, NED, m."""
        return np.array([0.5 * (self.x_min + self.x_max), 0.5 * (self.y_min + self.y_max),
                         0.5 * (self.z_min + self.z_max)])

    def room_m(self, p_ned_m: Sequence[float], direction_ned: Sequence[float]) -> float:
        """Distance (m) from ``p_ned_m`` along the unit ``direction_ned`` (3,) to the box boundary (0 if outside)."""
        p = np.asarray(p_ned_m, dtype=float)
        d = np.asarray(direction_ned, dtype=float)
        lo = np.array([self.x_min, self.y_min, self.z_min])
        hi = np.array([self.x_max, self.y_max, self.z_max])
        best = math.inf
        for k in range(3):
            if d[k] > 1e-9:
                best = min(best, (hi[k] - p[k]) / d[k])
            elif d[k] < -1e-9:
                best = min(best, (lo[k] - p[k]) / d[k])
        return max(0.0, best)


class HoldController:
    """Holds for depth (or altitude), roll, pitch, heading and body velocities from sensor values: the model-based law
    of :mod:`hindrax_onboard.control.law` (docs/control.md §2).

    cfg: the vehicle file. authority (6,) or (6, 2): largest wrench per axis (N, N m) from the thrust allocation
    (:func:`dof_authority`). natural_frequency_rad_s: target bandwidth w of the position holds; the velocity holds use
    ``velocity_gain`` w. hold_fraction: share of each axis' authority the holds may use. model: the
    :class:`~hindrax_onboard.control.model.ControlModel` (default: the vehicle file's, the campaign's model before any
    identification exists). reference_accel: DOF -> acceleration limit of the reference models (default: from the model,
    :class:`~hindrax_onboard.control.law.Controller`). settings: a :class:`~hindrax_onboard.control.law.ControlSettings`
    replacing the bandwidths and hold fraction above (the controller node's ``control.*``).

    ``wrench(state, free)`` returns the FRD wrench (6,) holding every DOF not in ``free``: depth (Z) to
    ``depth_setpoint_m`` on ``depth_estimate_m`` and ``depth_rate_m_s`` (which the caller sets from a
    :class:`DepthEstimator`; the latest ``state.depth_m`` while ``depth_estimate_m`` is NaN), or, when
    ``altitude_setpoint_m`` is finite, the Ping1D altitude; roll/pitch to ``attitude_setpoint_rad``; heading to
    ``heading_setpoint_rad``; surge/sway body velocity to ``velocity_setpoint_m_s``. A DOF in ``free`` gets 0 and, held
    again, starts from its measured state. ``net_buoyancy_n`` is the model's.
    ``note_allocation(requested_frd, achieved_frd)`` passes the allocation's result for the anti-windup."""

    def __init__(self, cfg: VehicleConfig, authority, natural_frequency_rad_s: float = 2.0,
                 hold_fraction: float = 0.6, model: ControlModel | None = None, velocity_gain: float = 1.5,
                 reference_accel=None, settings: ControlSettings | None = None) -> None:
        self.model = model if model is not None else model_from_config(cfg)
        self.net_buoyancy_n = float(self.model.axis("heave").bias)  # FRD force holding depth (down)
        self.depth_setpoint_m = math.nan
        self.altitude_setpoint_m = math.nan
        self.heading_setpoint_rad = 0.0
        self.velocity_setpoint_m_s = np.zeros(2)
        self.attitude_setpoint_rad = np.zeros(2)
        self.depth_rate_m_s = 0.0
        self.depth_estimate_m = math.nan
        wn = float(natural_frequency_rad_s)
        settings = settings or ControlSettings(
            depth_bandwidth_rad_s=wn, heading_bandwidth_rad_s=wn, attitude_bandwidth_rad_s=wn,
            velocity_bandwidth_rad_s=float(velocity_gain) * wn, hold_fraction=float(hold_fraction))
        dvl = cfg.sensors.dvl75
        rot = rotation_ned_from_body(*dvl.sensor_orientation_rpy_rad)
        beams = rot @ np.asarray(beam_directions_frd()).T
        self.core = Controller(self.model, np.asarray(authority, dtype=float), settings,
                               ping_position_frd_m=cfg.sensors.ping1d.position_frd_m,
                               dvl_position_frd_m=dvl.position_frd_m, dvl_beams_frd=beams.T,
                               reference_accel=reference_accel)

    def reset_integral(self) -> None:
        """Clear the depth integrator."""
        self.core.axes["heave"].reset_integral()

    def note_allocation(self, requested_frd, achieved_frd) -> None:
        """Anti-windup from the thrust allocation's result.

        As :meth:`~hindrax_onboard.control.law.Controller.note_allocation`."""
        self.core.note_allocation(requested_frd, achieved_frd)

    def control_input(self, st: SensorState, t_s: float | None = None) -> ControlInput:
        """The :class:`~hindrax_onboard.control.law.ControlInput` of a :class:`SensorState` and the depth estimate."""
        depth = self.depth_estimate_m if math.isfinite(self.depth_estimate_m) else st.depth_m
        alt = st.log["altitude"][-1] if st.log.get("altitude") else (math.nan, (math.nan,))
        t = t_s if t_s is not None else max((log[-1][0] for log in st.log.values() if log), default=0.0)
        return ControlInput(t_s=float(t), depth_m=float(depth), depth_rate_m_s=float(self.depth_rate_m_s),
                            rpy_rad=st.rpy_now(), rates_frd_rad_s=np.asarray(st.rates_frd_rad_s, dtype=float),
                            velocity_frd_m_s=np.asarray(st.velocity_frd_m_s, dtype=float),
                            altitude_m=float(alt[1][0]), altitude_stamp_s=float(alt[0]),
                            dvl_beam_range_m=st.dvl_beam_range_m, dvl_beam_stamp_s=st.dvl_beam_stamp_s)

    def wrench(self, st: SensorState, free: Sequence[str] = (), dt_s: float = 0.02,
               t_s: float | None = None) -> np.ndarray:
        """FRD wrench (6,) of the holds (N, N m) for the DOFs not in ``free``, one tick of ``dt_s`` ending at ``t_s``
        (default: the newest sample's time)."""
        c = self.core
        c.depth_m = float(self.depth_setpoint_m)
        c.altitude_m = float(self.altitude_setpoint_m)
        c.heading_rad = float(self.heading_setpoint_rad)
        c.velocity_frd_m_s = np.asarray(self.velocity_setpoint_m_s, dtype=float)
        c.attitude_rad = np.asarray(self.attitude_setpoint_rad, dtype=float)
        return c.wrench(self.control_input(st, t_s), float(dt_s), free)
