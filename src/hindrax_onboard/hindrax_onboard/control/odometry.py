"""The vehicle's estimate as ROS odometry (REP-105): ``odom -> base_link`` pose and twist from the conditioned sensors.

The controller's sensor conditioning (:class:`~hindrax_onboard.vehicle.state.SensorState`: the
dead-reckoned horizontal position from the DVL velocity and heading, the depth of the body origin, the attitude,
the DVL velocity and the gyro rates) is turned into what a ROS tool (Foxglove's 3D panel, RViz) expects: the pose
of ``base_link`` (FLU, REP-103) in ``odom`` (ENU, REP-105; origin at the pool start position of the vehicle file,
continuous, drifting with the dead reckoning), and the twist in ``base_link``. Frames: docs/architecture.md §3;
conversions: :mod:`hindrax_common.base.frames`. Pure, no ROS."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hindrax_common.base import frames

__all__ = ["OdometryEstimate", "odometry_estimate"]


@dataclass(frozen=True)
class OdometryEstimate:
    """position_enu_m (3,): base_link origin in odom, m (ENU). orientation_xyzw (4,): base_link (FLU) in odom
    (ENU). linear_flu_m_s / angular_flu_rad_s (3,): twist in base_link; velocity_known: False when the DVL had
    no lock (the linear twist is then zero and must be read as unknown)."""

    position_enu_m: np.ndarray
    orientation_xyzw: np.ndarray
    linear_flu_m_s: np.ndarray
    angular_flu_rad_s: np.ndarray
    velocity_known: bool


def odometry_estimate(position_ned_m, rpy_rad, velocity_frd_m_s, rates_frd_rad_s) -> OdometryEstimate | None:
    """The odometry of the estimate: position (3,) NED m, Fossen ZYX attitude (3,) rad, body velocity FRD (3,)
    m/s (NaN without DVL lock), body rates FRD (3,) rad/s. Returns None while the position or the attitude is not
    known yet (NaN: before the first depth, attitude sample)."""
    pos = np.asarray(position_ned_m, dtype=float)
    rpy = np.asarray(rpy_rad, dtype=float)
    if not (np.all(np.isfinite(pos)) and np.all(np.isfinite(rpy))):
        return None
    v = np.asarray(velocity_frd_m_s, dtype=float)
    w = np.asarray(rates_frd_rad_s, dtype=float)
    known = bool(np.all(np.isfinite(v)))
    twist = frames.twist_frd_to_flu(np.concatenate([v if known else np.zeros(3), np.where(np.isfinite(w), w, 0.0)]))
    q = frames.quaternion_marine_to_ros(frames.quaternion_from_euler_ned(rpy))
    return OdometryEstimate(frames.ned_to_enu(pos), np.asarray(q, dtype=float), twist[:3], twist[3:], known)


