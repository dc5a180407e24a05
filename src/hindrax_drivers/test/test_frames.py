"""Frames module: REP-103 (FLU/ENU) <-> marine (FRD/NED) conversions."""
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from hindrax_common.base import frames

finite = st.floats(-1e3, 1e3, allow_nan=False)
vec3 = st.lists(finite, min_size=3, max_size=3)


@given(vec3)
def test_vector_round_trips(v):
    assert np.allclose(frames.frd_to_flu(frames.flu_to_frd(v)), v)
    assert np.allclose(frames.ned_to_enu(frames.ned_to_enu(v)), v)


def test_known_axes():
    # forward stays forward, left becomes minus starboard, up becomes minus down
    assert frames.flu_to_frd([1, 2, 3]).tolist() == [1, -2, -3]
    # east -> NED y, north -> NED x, up -> -down
    assert frames.ned_to_enu([1, 2, 3]).tolist() == [2, 1, -3]
    # arrays of vectors
    assert frames.flu_to_frd(np.ones((5, 3))).shape == (5, 3)
    with pytest.raises(ValueError):
        frames.flu_to_frd([1, 2])


def test_wrench_and_twist():
    w_flu = [10.0, 2.0, -3.0, 0.5, -0.25, 1.0]  # forward, left, down forces; torques about FLU axes
    tau = frames.wrench_flu_to_frd(w_flu)
    assert tau.tolist() == [10.0, -2.0, 3.0, 0.5, 0.25, -1.0]
    # a positive yaw rate in ROS (counter-clockwise seen from above) is a negative r in FRD
    nu = frames.twist_flu_to_frd([0, 0, 0, 0, 0, 0.3])
    assert nu[5] == pytest.approx(-0.3)
    assert np.allclose(frames.wrench_frd_to_flu(tau), w_flu)


@given(st.lists(st.lists(finite, min_size=6, max_size=6), min_size=1, max_size=4))
def test_wrench_conversion_is_the_half_turn_about_x_of_force_and_torque(wrenches):
    # FLU and FRD differ by a half turn about the forward axis (REP-103; Fossen's body frame): scipy's rotation,
    # applied to the force and the torque separately, is the reference for the sign flip frames.py multiplies by
    half_turn = Rotation.from_euler("x", 180.0, degrees=True)
    w = np.array(wrenches)
    expected = np.hstack([half_turn.apply(w[:, :3]), half_turn.apply(w[:, 3:])])
    assert np.allclose(frames.wrench_flu_to_frd(w), expected, atol=1e-9)
    assert np.allclose(frames.wrench_frd_to_flu(w), expected, atol=1e-9)
    assert frames.wrench_flu_to_frd(w).shape == w.shape
    with pytest.raises(ValueError):
        frames.wrench_flu_to_frd(w[:, :5])


def test_known_orientations():
    # base_link facing north in ENU is yaw +90 deg about up; in NED that is heading 0
    q_north = Rotation.from_euler("z", 90, degrees=True).as_quat()
    assert np.allclose(frames.euler_ned_from_quaternion(frames.quaternion_ros_to_marine(q_north)), 0, atol=1e-12)
    # facing east: NED heading +90 deg (clockwise from north seen from above)
    q_east = [0, 0, 0, 1]
    assert np.allclose(frames.euler_ned_from_quaternion(frames.quaternion_ros_to_marine(q_east)),
                       [0, 0, np.pi / 2])
    # facing north, rotated +10 deg about world north (ENU +y): the port side rises, the starboard side goes
    # down, i.e. the vehicle rolls right: NED roll +10 deg
    q = (Rotation.from_euler("y", 10, degrees=True) * Rotation.from_quat(q_north)).as_quat()
    assert np.allclose(np.degrees(frames.euler_ned_from_quaternion(frames.quaternion_ros_to_marine(q))),
                       [10, 0, 0], atol=1e-9)


@given(st.floats(-3, 3), st.floats(-1.5, 1.5), st.floats(-3, 3))
def test_quaternion_round_trip(r, p, y):
    q = frames.quaternion_from_euler_ned([r, p, y])
    back = frames.quaternion_ros_to_marine(frames.quaternion_marine_to_ros(q))
    assert abs(abs(np.dot(back, q)) - 1.0) < 1e-9


@given(vec3)
def test_rotating_a_vector_commutes_with_the_conversion(v):
    # A body vector mapped to the world must agree in both conventions.
    q_ros = Rotation.from_euler("zyx", [0.3, -0.2, 0.1]).as_quat()
    world_enu = Rotation.from_quat(q_ros).apply(v)
    q_mar = frames.quaternion_ros_to_marine(q_ros)
    world_ned = Rotation.from_quat(q_mar).apply(frames.flu_to_frd(v))
    assert np.allclose(frames.ned_to_enu(world_enu), world_ned, atol=1e-9)


def test_quaternion_map_and_euler_angles_agree_with_scipys_rotations():
    """The written-out forms (frames module: the constant product map, Fossen's Euler formulas) against scipy's
    Rotation composition and ``as_euler("ZYX")``, one quaternion at a time (the nodes' path) and in batches; not
    normalised on input, as a message's quaternion may not be."""
    rng = np.random.default_rng(7)
    q = rng.normal(size=(500, 4)) * rng.uniform(0.5, 2.0, size=(500, 1))
    r_flu_frd, r_enu_ned = Rotation.from_matrix(frames.R_FLU_FRD), Rotation.from_matrix(frames.R_ENU_NED)
    want_q = (r_enu_ned * Rotation.from_quat(q) * r_flu_frd).as_quat(canonical=False)
    want_rpy = Rotation.from_quat(q).as_euler("ZYX")[:, ::-1]
    assert np.allclose(frames.quaternion_ros_to_marine(q), want_q, atol=1e-12)
    assert np.allclose(frames.quaternion_marine_to_ros(q), want_q, atol=1e-12)
    wrapped = lambda a: np.angle(np.exp(1j * a))  # noqa: E731
    assert np.allclose(wrapped(frames.euler_ned_from_quaternion(q) - want_rpy), 0.0, atol=1e-9)
    for qi, wq, wr in zip(q[:50], want_q[:50], want_rpy[:50]):
        assert np.allclose(frames.quaternion_ros_to_marine(qi), wq, atol=1e-12)
        assert np.allclose(wrapped(frames.euler_ned_from_quaternion(qi) - wr), 0.0, atol=1e-9)
    for bad in ([0.0, 0.0, 0.0, 0.0], [np.nan, 0.0, 0.0, 1.0]):
        with pytest.raises(ValueError):
            frames.quaternion_ros_to_marine(bad)


angle = st.floats(-3.2, 3.2, allow_nan=False)


@given(st.lists(angle, min_size=3, max_size=3), st.lists(finite, min_size=4, max_size=4),
       st.lists(finite, min_size=4, max_size=4))
def test_numpy_rotations_agree_with_scipy(rpy, a, b):
    """frames' own rotation functions (node processes do not import scipy: ~21 MB each) give scipy's results."""
    from hindrax_drivers.icm20948.mounting import mounting_rotation

    assert np.allclose(frames.quaternion_from_euler_ned(rpy), Rotation.from_euler("ZYX", rpy[::-1]).as_quat())
    assert np.allclose(mounting_rotation(rpy), Rotation.from_euler("xyz", rpy).as_matrix())
    assert np.allclose(frames.rotation_matrix_from_quaternion(frames.quaternion_from_euler_ned(rpy)),
                       Rotation.from_euler("ZYX", rpy[::-1]).as_matrix())
    rotvec = np.asarray(rpy) / 2.0  # |v| <= 2.8 < pi: scipy's quaternion has w >= 0, as ours
    assert np.allclose(frames.quaternion_from_rotvec(rotvec), Rotation.from_rotvec(rotvec).as_quat())
    if min(np.linalg.norm(a), np.linalg.norm(b)) > 1e-3:
        expected = (Rotation.from_quat(a) * Rotation.from_quat(b)).as_quat(canonical=False)
        product = frames.quaternion_multiply(np.asarray(a) / np.linalg.norm(a), np.asarray(b) / np.linalg.norm(b))
        assert np.allclose(product, expected)
