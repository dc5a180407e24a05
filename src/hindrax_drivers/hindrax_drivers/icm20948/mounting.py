"""Mounting of the ICM-20948 on the vehicle: the rotation from sensor axes to base_link (pure, no rclpy).

Shared by the driver node (:class:`~hindrax_drivers.icm20948.node.Icm20948Node` rotates every sample into
base_link FLU) and by the identification code, which takes the driver's FLU vectors back to sensor axes
(:func:`hindrax_onboard.vehicle.signals.samples_from_imu`)."""
from __future__ import annotations

from typing import Sequence

import numpy as np

from hindrax_common.base.frames import quaternion_from_euler_ned, rotation_matrix_from_quaternion

__all__ = ["mounting_rotation"]


def mounting_rotation(rpy_rad: Sequence[float]) -> np.ndarray:
    """3x3 rotation taking sensor-axis vectors into base_link (FLU) axes: Rz(yaw) Ry(pitch) Rx(roll).

    rpy_rad: (3,) roll, pitch, yaw of the sensor in base_link, rad (``sensors.icm20948.mounting_rpy_rad``).
    Raises ``ValueError`` unless three finite angles are given."""
    rpy = np.asarray(rpy_rad, dtype=float)
    if rpy.shape != (3,) or not np.all(np.isfinite(rpy)):
        raise ValueError(f"mounting_rpy_rad must be 3 finite angles, got {rpy_rad!r}")
    return rotation_matrix_from_quaternion(quaternion_from_euler_ned(rpy))  # Rz Ry Rx: the ZYX convention
