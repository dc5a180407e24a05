"""The one place that converts between ROS frames and marine (Fossen/SNAME) frames.

ROS side (REP-103/105): ``base_link`` is FLU (x forward, y left, z up); ``odom`` is ENU (x east, y north,
z up). Marine side (Fossen 2011 §2.1, docs/identification.md §0): body frame FRD (x forward, y starboard,
z down); world frame NED (x north, y east, z down). Both pairs share their origin:

- FLU <-> FRD is a rotation of pi about x: ``diag(1, -1, -1)``.
- ENU <-> NED swaps x and y and negates z: ``[[0, 1, 0], [1, 0, 0], [0, 0, -1]]``.

Both matrices are proper rotations (det = +1) and their own inverses, so the same matrix maps vectors
*and* pseudo-vectors (angular velocity, torque) in both directions. Orientations are quaternions in ROS
order (x, y, z, w), composed by the Hamilton product (:func:`quaternion_multiply`, scipy's ``Rotation``
convention: ``a * b`` applies b first); the tests compare every function with ``scipy.spatial.transform``, which
no node process imports (it would add ~21 MB of private memory to each of them).

Nothing else in the stack converts frames: drivers, emulators and tools call these functions and matrices at
their ROS boundary (test/test_docs_truth.py checks that no other module spells the matrices out). A device's
own sign conventions (the DVL-75's pitch, docs/devices.md §1.5) stay in its protocol.

Angles: :func:`wrap_angle` is the one angle wrap of the repository (headings, attitude errors, the DVL-75
emulator's attitude rates)."""
from __future__ import annotations

import math

import numpy as np

#: Rotation matrix between base_link (FLU) and the marine body frame (FRD); its own inverse.
R_FLU_FRD = np.diag([1.0, -1.0, -1.0])
#: Rotation matrix between odom (ENU) and the marine world frame (NED); its own inverse.
R_ENU_NED = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])

#: the same two rotations as quaternions (x, y, z, w): pi about x; pi about (x + y) / sqrt(2)
_Q_FLU_FRD = np.array([1.0, 0.0, 0.0, 0.0])
_Q_ENU_NED = np.array([math.sqrt(0.5), math.sqrt(0.5), 0.0, 0.0])


def quaternion_multiply(a, b) -> np.ndarray:
    """Hamilton product ``a * b`` of (..., 4) quaternions (x, y, z, w): the rotation b, then a (scipy's
    ``Rotation.__mul__`` order). Not normalised."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    ax, ay, az, aw = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    bx, by, bz, bw = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    return np.stack([aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw,
                     aw * bw - ax * bx - ay * by - az * bz], axis=-1)


def quaternion_from_rotvec(rotvec) -> np.ndarray:
    """Quaternion (x, y, z, w) of the rotation by |rotvec| rad about rotvec's direction ((3,) rad)."""
    v = np.asarray(rotvec, dtype=float)
    angle = float(np.linalg.norm(v))
    if angle == 0.0:
        return np.array([0.0, 0.0, 0.0, 1.0])
    return np.concatenate([v / angle * math.sin(angle / 2.0), [math.cos(angle / 2.0)]])


def _product_map(left: np.ndarray, right: np.ndarray) -> np.ndarray:
    """The (4, 4) matrix M with ``left * q * right == M @ q`` (x, y, z, w): a quaternion product is bilinear, so
    fixed factors on both sides make a linear map, whose columns are the products of the basis quaternions."""
    return np.stack([quaternion_multiply(quaternion_multiply(left, e), right) for e in np.eye(4)], axis=1)


#: q(body FRD in NED) = M q(base_link FLU in odom ENU), and back (both factors are their own inverses)
_Q_ROS_MARINE = _product_map(_Q_ENU_NED, _Q_FLU_FRD)


def _unit_quaternions(q_xyzw) -> np.ndarray:
    """(..., 4) quaternions scaled to unit norm; ValueError for a zero or non-finite one (as scipy's from_quat)."""
    q = np.asarray(q_xyzw, dtype=float)
    if q.shape[-1:] != (4,):
        raise ValueError(f"expected quaternions of shape (..., 4), got {q.shape}")
    if q.ndim == 1:  # one quaternion (every message): plain floats, a fraction of numpy's per-call cost
        n = math.sqrt(sum(v * v for v in q.tolist()))
        if not (math.isfinite(n) and n > 0.0):
            raise ValueError("found zero-norm or non-finite quaternions")
        return q / n
    n = np.sqrt(np.einsum("...i,...i->...", q, q))
    if not np.all(np.isfinite(n)) or np.any(n == 0.0):
        raise ValueError("found zero-norm or non-finite quaternions")
    return q / n[..., None]


def _last_axis(v, n: int, what: str = "vectors") -> np.ndarray:
    a = np.asarray(v, dtype=float)
    if a.shape[-1] != n:
        raise ValueError(f"expected {what} of length {n} (shape (..., {n})), got shape {a.shape}")
    return a


def flu_to_frd(v) -> np.ndarray:
    """Vector(s) from base_link FLU to body FRD, and back (:func:`frd_to_flu`). v: (..., 3), any
    unit (m, m/s, rad/s, N, N m)."""
    return _last_axis(v, 3) @ R_FLU_FRD.T


frd_to_flu = flu_to_frd


def ned_to_enu(v) -> np.ndarray:
    """Vector(s) from world NED to odom ENU, and back (its own inverse). v: (..., 3)."""
    return _last_axis(v, 3) @ R_ENU_NED.T


def wrap_angle(angle_rad: float) -> float:
    """``angle_rad`` wrapped to [-pi, pi), rad."""
    return (float(angle_rad) + math.pi) % (2.0 * math.pi) - math.pi


#: R_FLU_FRD is diagonal, so a wrench changes between FLU and FRD by the signs of its diagonal, force and torque
#: alike: one multiplication instead of two 3x3 products (the allocation converts two wrenches per command)
_WRENCH_FLU_FRD_SIGNS = np.tile(np.diag(R_FLU_FRD), 2)


def wrench_flu_to_frd(w) -> np.ndarray:
    """Wrench [Fx Fy Fz Tx Ty Tz] (N, N m) base_link FLU -> body FRD tau = [X Y Z K M N], and back;
    a twist (m/s, rad/s) -> nu = [u v w p q r] alike (:func:`twist_flu_to_frd`). w: (..., 6)."""
    return _last_axis(w, 6, "[force(3), torque(3)]") * _WRENCH_FLU_FRD_SIGNS


wrench_frd_to_flu = twist_flu_to_frd = twist_frd_to_flu = wrench_flu_to_frd


def quaternion_ros_to_marine(q_xyzw) -> np.ndarray:
    """Orientation of base_link (FLU) in odom (ENU) -> orientation of the body (FRD) in NED.

    q_xyzw: (..., 4) quaternion(s) in ROS order (x, y, z, w), normalised here. Returns (..., 4) in the same order.
    R_ned_frd = R_ned_enu . R_enu_flu . R_flu_frd, applied as the constant linear map :data:`_Q_ROS_MARINE` that
    the Hamilton product defines (the same result as composing scipy Rotations, without their cost per call).
    Raises ValueError for a zero or non-finite quaternion. The same map takes the body in NED back
    to base_link in odom (:func:`quaternion_marine_to_ros`): both factors are their own inverses."""
    return _unit_quaternions(q_xyzw) @ _Q_ROS_MARINE.T


quaternion_marine_to_ros = quaternion_ros_to_marine


def euler_ned_from_quaternion(q_xyzw) -> np.ndarray:
    """Fossen ZYX Euler angles [phi theta psi] (rad) of a body-FRD-in-NED quaternion (x, y, z, w).

    Theta = [roll, pitch, yaw] with R = Rz(psi) Ry(theta) Rx(phi) (Fossen eq. 2.18; docs/identification.md §1.A,
    [NTNU-Thesis] eq. 2.2), from the unit quaternion's rotation matrix entries (Fossen 2011 eqs. 2.50 and 2.68):
    phi = atan2(R32, R33), theta = -asin(R31), psi = atan2(R21, R11). Written out (scipy's ``as_euler`` costs
    more per call, for every DVL message in three nodes); the tests compare both. At theta = +-pi/2 (gimbal
    lock, outside any ROV's envelope) phi and psi are not unique; this gives one valid pair."""
    q = _unit_quaternions(q_xyzw)
    if q.ndim == 1:
        x, y, z, w = q.tolist()
        return np.array([math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y)),
                         math.asin(min(1.0, max(-1.0, 2.0 * (w * y - x * z)))),
                         math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))])
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    phi = np.arctan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    theta = np.arcsin(np.clip(2.0 * (w * y - x * z), -1.0, 1.0))
    psi = np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return np.stack([phi, theta, psi], axis=-1)


def quaternion_from_euler_ned(rpy) -> np.ndarray:
    """Quaternion (x, y, z, w) of body FRD in NED from Fossen ZYX Euler angles [phi theta psi] in rad, (..., 3) ->
    (..., 4): q = q_z(psi) q_y(theta) q_x(phi) (Fossen 2011 eq. 2.18 as quaternions; scipy's
    ``from_euler("ZYX", [psi, theta, phi])``, also ``from_euler("xyz", [phi, theta, psi])``, the same rotation)."""
    a = np.asarray(rpy, dtype=float)
    cr, sr = np.cos(a[..., 0] / 2.0), np.sin(a[..., 0] / 2.0)
    cp, sp = np.cos(a[..., 1] / 2.0), np.sin(a[..., 1] / 2.0)
    cy, sy = np.cos(a[..., 2] / 2.0), np.sin(a[..., 2] / 2.0)
    return np.stack([sr * cp * cy - cr * sp * sy,
                     cr * sp * cy + sr * cp * sy,
                     cr * cp * sy - sr * sp * cy,
                     cr * cp * cy + sr * sp * sy], axis=-1)


def rotation_matrix_from_quaternion(q_xyzw) -> np.ndarray:
    """(..., 3, 3) rotation matrix of (..., 4) quaternion(s) (x, y, z, w), normalised here (Fossen 2011 eq. 2.65).
    Raises ValueError for a zero or non-finite quaternion."""
    q = _unit_quaternions(q_xyzw)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack([np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], axis=-1),
                     np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], axis=-1),
                     np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], axis=-1)],
                    axis=-2)
