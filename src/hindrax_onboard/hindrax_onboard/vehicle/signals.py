"""ROS messages -> sensor samples: the pure adapters the identification node, the controller and offline tools share.

The identification executive (:class:`~hindrax_onboard.vehicle.state.SensorState`) consumes samples in the simulator's
form (:mod:`hindrax_sim.sensors`: a device name and a namespace with ``stamp_s`` and the measured values).
These functions make such samples from the drivers' ROS messages, rclpy or bag-decoded alike (they only read
attributes), so the live node (:mod:`..identification.online.node`), the controller (:mod:`..control.node`) and the
bag analysis (:mod:`..identification.bag_input.from_bag`) see the same numbers.
They also hold the thrust model of the widths the ESC node wrote (:func:`thrust_of_written_widths`) and the
status prefix that marks the still window (:data:`STILL_MESSAGE`). No rclpy import: usable offline."""
from __future__ import annotations

import math
from types import SimpleNamespace
from typing import Any, Sequence

import numpy as np

from hindrax_common.base import frames
from hindrax_common.config import VehicleConfig

__all__ = ["STILL_MESSAGE", "samples_from_dvl", "samples_from_imu", "sample_from_pressure", "sample_from_range",
           "thrust_of_written_widths"]

#: Message prefix of the status while the gyro/accelerometer biases are averaged (the vehicle is held still);
#: :mod:`..identification.bag_input.from_bag` finds the still window by it.
STILL_MESSAGE = "still: averaging gyro and accelerometer bias"


def _stamp_s(header) -> float:
    return header.stamp.sec + header.stamp.nanosec * 1e-9


def samples_from_dvl(msg) -> list[tuple[str, Any]]:
    """Samples of one hindrax_msgs/Dvl message in the simulator's sample form (:mod:`hindrax_sim.sensors`).

    Returns ``[("dvl75_attitude", ns(stamp_s, roll_rad, pitch_rad, yaw_rad))]`` (NED Euler angles of body FRD,
    via :func:`hindrax_common.base.frames.quaternion_ros_to_marine`; left out when the quaternion is all zero)
    followed by ``("dvl75", ns(stamp_s, velocity_frd_m_s (3,), locked, at_body_origin=True, beam_range_m (4,)))``
    (velocity FLU -> FRD; NaN and ``locked`` False without a valid velocity; the range along beams A-D, NaN for a beam
    without lock). Works on rclpy and bag-decoded messages alike.

    ``at_body_origin``: the driver publishes the velocity of base_link (it removes the lever arm with the
    ``$DVPDL`` rotation, :mod:`hindrax_drivers.dvl75.report`), unlike the simulator's transducer-velocity
    samples, so :class:`~hindrax_onboard.vehicle.state.SensorState` must not remove it again.

    Times: the header stamp is the velocity's time of validity, the middle of the ``$DVPDL`` interval; the attitude
    comes from the driver's latest ``$DVEXT``, which is the one of the same ping when the DVL sends it first (as the
    emulator does; the real order is undocumented, docs/devices.md §1.3: check a pool capture), i.e. measured at the end
    of that interval: stamp + ``delta_time_s`` / 2 (the stamp when the interval is unknown). A 50 ms error there shows
    up in roll and pitch as a restoring moment out of phase, i.e. as damping."""
    t = _stamp_s(msg.header)
    half = 0.5 * float(msg.delta_time_s)
    t_att = t + half if math.isfinite(half) and half > 0.0 else t
    out: list[tuple[str, Any]] = []
    q = np.array([msg.orientation.x, msg.orientation.y, msg.orientation.z, msg.orientation.w], dtype=float)
    if np.all(np.isfinite(q)) and np.linalg.norm(q) > 0.5:
        rpy = frames.euler_ned_from_quaternion(frames.quaternion_ros_to_marine(q))
        out.append(("dvl75_attitude", SimpleNamespace(stamp_s=t_att, roll_rad=float(rpy[0]), pitch_rad=float(rpy[1]),
                                                      yaw_rad=float(rpy[2]))))
    v = np.array([msg.velocity_m_s.x, msg.velocity_m_s.y, msg.velocity_m_s.z], dtype=float)
    locked = bool(msg.velocity_valid) and bool(np.all(np.isfinite(v)))
    beams = np.asarray(list(msg.beam_range_m), dtype=float) if len(msg.beam_range_m) == 4 else np.full(4, np.nan)
    lock = list(msg.beam_lock) if len(msg.beam_lock) == 4 else [False] * 4
    beams = np.where(np.asarray(lock, dtype=bool) & np.isfinite(beams) & (beams > 0.0), beams, np.nan)
    out.append(("dvl75", SimpleNamespace(stamp_s=t, velocity_frd_m_s=frames.flu_to_frd(v) if locked
                                         else np.full(3, np.nan), locked=locked, at_body_origin=True,
                                         beam_range_m=beams)))
    return out


def samples_from_imu(msg, mounting_frd_from_flu: np.ndarray | None = None) -> list[tuple[str, Any]]:
    """``icm20948_gyro`` and ``icm20948_accel`` samples of a sensor_msgs/Imu (base_link FLU).

    The simulator's samples are in the sensor axes, which :class:`~hindrax_onboard.vehicle.state.SensorState` rotates
    with the configured mounting; the driver has already applied it, so the FLU vectors are taken back to sensor axes
    with ``mounting_frd_from_flu`` = R_mount^T (3, 3) (identity when None). Angular rate rad/s, specific
    force m/s^2."""
    t = _stamp_s(msg.header)
    r = np.eye(3) if mounting_frd_from_flu is None else mounting_frd_from_flu
    w = r @ np.array([msg.angular_velocity.x, msg.angular_velocity.y, msg.angular_velocity.z], dtype=float)
    a = r @ np.array([msg.linear_acceleration.x, msg.linear_acceleration.y, msg.linear_acceleration.z], dtype=float)
    return [("icm20948_gyro", SimpleNamespace(stamp_s=t, angular_rate_rad_s=w)),
            ("icm20948_accel", SimpleNamespace(stamp_s=t, specific_force_m_s2=a))]


def sample_from_pressure(msg) -> tuple[str, Any]:
    """``ms5837`` sample (absolute pressure, Pa) of a sensor_msgs/FluidPressure."""
    return "ms5837", SimpleNamespace(stamp_s=_stamp_s(msg.header), pressure_pa=float(msg.fluid_pressure))


def sample_from_range(msg) -> tuple[str, Any]:
    """``ping1d`` sample of a sensor_msgs/Range: distance (m), valid when finite and within [min, max] range."""
    r = float(msg.range)
    valid = math.isfinite(r) and msg.min_range <= r <= msg.max_range
    return "ping1d", SimpleNamespace(stamp_s=_stamp_s(msg.header), distance_m=r, valid=valid)


def thrust_of_written_widths(cfg: VehicleConfig, curve, written_us: Sequence[float]) -> np.ndarray:
    """Thruster forces (n,) N of the WIRE pulse widths (n,) the ESC wrote (``thrusters/pulse_width``); (k, n) of (k, n).

    The ESC applies reversal (2 neutral - w) and trim after the allocation
    (:class:`hindrax_drivers.pca9685.node.EscOutput`); both are undone here, then the allocation's thrust curve
    ([Hindrax-Drag] eq. 1) gives the force along each thruster's configured direction. Raises
    ``ValueError`` for a wrong number of widths."""
    w = np.asarray(written_us, dtype=float)
    th = cfg.thrusters.thrusters
    if w.shape[-1:] != (len(th),) or w.ndim > 2:
        raise ValueError(f"{w.size} pulse widths, expected {len(th)}")
    neutral = float(cfg.thrusters.pulse_width_neutral_us)
    trim = np.array([t.trim_us for t in th], dtype=float)
    rev = np.array([t.reversed for t in th], dtype=bool)
    logical = w - trim
    logical = np.where(rev, 2.0 * neutral - logical, logical)
    return np.asarray(curve.thrust_n(logical), dtype=float)
