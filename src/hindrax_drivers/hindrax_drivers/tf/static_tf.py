"""Static transforms of the vehicle, computed from the configured geometry (no ROS imports).

The vehicle file gives every position in the marine body frame FRD about the centre of gravity
(``docs/architecture.md`` §3); ROS frames follow REP-103 (``base_link`` FLU, origin at the CG) and REP-105.
The conversion is :func:`hindrax_common.base.frames.frd_to_flu`, the one module that converts frames.

Frames (child of ``base_link``; ids are parameters of the static TF node):

=================  =======================================  ================================================
frame              origin (vehicle file key)                orientation
=================  =======================================  ================================================
``imu_link``       ``sensors.icm20948.position_frd_m``      ``sensors.icm20948.mounting_rpy_rad`` (roll,
                                                            pitch, yaw about fixed FLU axes, REP-103)
``dvl_link``       ``sensors.dvl75.position_frd_m``         x along the beam axis, pointing down (pitch
                                                            +pi/2): sensor_msgs/Range measures along x
``ping_link``      ``sensors.ping1d.position_frd_m``        as dvl_link (downward-looking altimeter)
``pressure_link``  ``sensors.ms5837.position_frd_m``        base_link axes
``thruster_<k>``   ``thrusters.<name>.position_frd_m``      x along ``thrusters.<name>.direction_frd``
                   (k = 1-based index in thrusters.names)   (positive thrust), the smallest rotation from
                                                            base_link's x
=================  =======================================  ================================================
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping

import numpy as np

from hindrax_common.config import VehicleConfig
from hindrax_common.base.frames import frd_to_flu, quaternion_from_euler_ned, quaternion_from_rotvec

__all__ = ["StaticTransform", "DEFAULT_FRAME_IDS", "vehicle_transforms", "thruster_frame_id", "TF_KEYS"]

#: Default frame ids (parameters ``<name>_frame`` of the static TF node).
DEFAULT_FRAME_IDS: dict[str, str] = {
    "base": "base_link", "imu": "imu_link", "dvl": "dvl_link", "ping": "ping_link", "pressure": "pressure_link",
    "thruster_prefix": "thruster_",
}

#: Vehicle keys the transforms are computed from (the static TF node declares exactly these).
TF_KEYS = ("thrusters.names", "thrusters.<thruster>.position_frd_m", "thrusters.<thruster>.direction_frd",
           "sensors.icm20948.position_frd_m", "sensors.icm20948.mounting_rpy_rad", "sensors.dvl75.position_frd_m",
           "sensors.ping1d.position_frd_m", "sensors.ms5837.position_frd_m")

#: Downward-looking range sensor: the frame's x axis points along -z of base_link (pitch +90 deg, FLU).
_DOWN = quaternion_from_rotvec([0.0, math.pi / 2, 0.0])
#: no rotation (x, y, z, w)
_IDENTITY = np.array([0.0, 0.0, 0.0, 1.0])


@dataclass(frozen=True)
class StaticTransform:
    """One static transform: ``child`` in ``parent``; translation (3,) m and quaternion (x, y, z, w), FLU."""

    parent: str
    child: str
    translation_m: np.ndarray
    quaternion_xyzw: np.ndarray


def thruster_frame_id(index: int, prefix: str = DEFAULT_FRAME_IDS["thruster_prefix"]) -> str:
    """Frame id of the thruster at 0-based ``index`` in ``thrusters.names``: ``thruster_1`` for index 0."""
    return f"{prefix}{index + 1}"


def _align_x(direction_flu: np.ndarray) -> np.ndarray:
    """Smallest rotation taking base_link's x axis onto the unit vector ``direction_flu``, quaternion (x, y, z, w)."""
    x = np.array([1.0, 0.0, 0.0])
    d = direction_flu / np.linalg.norm(direction_flu)
    axis = np.cross(x, d)
    s, c = np.linalg.norm(axis), float(np.dot(x, d))
    if s < 1e-12:
        return _IDENTITY if c > 0 else quaternion_from_rotvec([0.0, 0.0, math.pi])
    return quaternion_from_rotvec(axis / s * math.atan2(s, c))


def vehicle_transforms(cfg: VehicleConfig, frame_ids: Mapping[str, str] | None = None) -> list[StaticTransform]:
    """Every static transform of the vehicle (see the module docstring for frames and conventions).

    cfg: a configuration holding at least :data:`TF_KEYS`. frame_ids: overrides of :data:`DEFAULT_FRAME_IDS`.
    Returns sensors first (imu, dvl, ping, pressure), then thrusters in allocation order."""
    ids = dict(DEFAULT_FRAME_IDS, **(frame_ids or {}))
    sensors = cfg.sensors
    base = ids["base"]

    def tf(child: str, position_frd, rotation: np.ndarray) -> StaticTransform:
        return StaticTransform(base, child, frd_to_flu(np.asarray(position_frd, dtype=float)),
                               np.asarray(rotation, dtype=float))

    out = [
        tf(ids["imu"], sensors.icm20948.position_frd_m,
           quaternion_from_euler_ned(list(sensors.icm20948.mounting_rpy_rad))),  # Rz Ry Rx, as mounting.py
        tf(ids["dvl"], sensors.dvl75.position_frd_m, _DOWN),
        tf(ids["ping"], sensors.ping1d.position_frd_m, _DOWN),
        tf(ids["pressure"], sensors.ms5837.position_frd_m, _IDENTITY),
    ]
    for i, thruster in enumerate(cfg.thrusters.thrusters):
        direction = frd_to_flu(thruster.direction_frd)  # unit already; _align_x normalises again
        out.append(tf(thruster_frame_id(i, ids["thruster_prefix"]), thruster.position_frd_m, _align_x(direction)))
    return out
