"""The vehicle's estimate as nav_msgs/Odometry and odom -> base_link (REP-103/105)."""
import math

import numpy as np
import pytest

from hindrax_onboard.control.odometry import odometry_estimate


def test_a_vehicle_heading_east_is_base_link_along_odom_x():
    # NED (north 1, east 2, depth 3), heading 90 deg (east), FRD velocity and rates
    est = odometry_estimate([1.0, 2.0, 3.0], [0.0, 0.0, math.pi / 2], [1.0, 0.5, 0.2], [0.1, 0.2, 0.3])
    np.testing.assert_allclose(est.position_enu_m, [2.0, 1.0, -3.0])  # ENU: east, north, up
    q = est.orientation_xyzw  # FLU x (forward) points east = odom x: the identity rotation (either sign)
    assert abs(abs(q[3]) - 1.0) < 1e-12 and np.allclose(q[:3], 0.0, atol=1e-12)
    np.testing.assert_allclose(est.linear_flu_m_s, [1.0, -0.5, -0.2])  # right -> left, down -> up
    np.testing.assert_allclose(est.angular_flu_rad_s, [0.1, -0.2, -0.3])
    assert est.velocity_known


def test_heading_north_is_a_quarter_turn_about_up_and_roll_keeps_its_sign():
    est = odometry_estimate([0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0])
    # north in ENU is +y: base_link yawed +90 deg about z (up)
    assert est.orientation_xyzw == pytest.approx([0.0, 0.0, math.sqrt(0.5), math.sqrt(0.5)], abs=1e-12) or \
        est.orientation_xyzw == pytest.approx([0.0, 0.0, -math.sqrt(0.5), -math.sqrt(0.5)], abs=1e-12)
    rolled = odometry_estimate([0.0, 0.0, 0.0], [0.2, 0.0, math.pi / 2], [0.0] * 3, [0.0] * 3)
    x, y, z, w = rolled.orientation_xyzw
    roll_flu = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    assert roll_flu == pytest.approx(0.2)  # starboard down (FRD +roll) is FLU +roll about x forward


def test_nothing_before_position_and_attitude_and_unknown_velocity_is_said():
    assert odometry_estimate([math.nan] * 3, [0.0] * 3, [0.0] * 3, [0.0] * 3) is None
    assert odometry_estimate([0.0] * 3, [math.nan] * 3, [0.0] * 3, [0.0] * 3) is None
    est = odometry_estimate([0.0] * 3, [0.0] * 3, [math.nan] * 3, [0.1, 0.0, 0.0])
    assert not est.velocity_known and np.all(est.linear_flu_m_s == 0.0)
    assert est.angular_flu_rad_s[0] == pytest.approx(0.1)
