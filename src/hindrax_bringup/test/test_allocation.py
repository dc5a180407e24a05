"""Tests of hindrax_bringup.allocation.matrix and .allocator ([Hindrax-Drag] eqs. 1 and 9, section 4).

Independent references used here: eq. 9 written out component by component, numpy.linalg.pinv for
the minimum-norm solution, hand-derived geometry of the 55-degree layout, and an axis authority
computed from the matrix and the curve limits alone.
"""

import math
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from hindrax_bringup.allocation.allocator import AXIS_NAMES, InvalidWrenchError, ThrustAllocator
from hindrax_bringup.allocation.from_config import allocation_matrix_from_config
from hindrax_bringup.allocation.matrix import thrust_allocation_matrix
from hindrax_common.base.thrust_curve import ThrustCurve, hindrax_default_curve, point_reflection

COS55 = math.cos(math.radians(55.0))
SIN55 = math.sin(math.radians(55.0))
F_MAX = 15.5283  # [Hindrax-Drag] Table 2 negative row at 1100 us (and the reflected positive row at 1900 us)
X, Y, Z, K, M, N = range(6)


def eq9_column(force_vec, lever):
    """[Hindrax-Drag] eq. 9, component by component: [Fx, Fy, Fz, Fz ly - Fy lz, Fx lz - Fz lx, Fy lx - Fx ly]."""
    fx, fy, fz = force_vec
    lx, ly, lz = lever
    return np.array([fx, fy, fz, fz * ly - fy * lz, fx * lz - fz * lx, fy * lx - fx * ly])


def axis_authority(matrix, lower, upper):
    """Largest |tau_j| reachable on axis j alone (a box vertex, independent of the allocator), per axis (6,)."""
    pos = np.maximum(matrix * lower, matrix * upper).sum(axis=1)
    neg = np.maximum(-matrix * lower, -matrix * upper).sum(axis=1)
    return np.maximum(pos, neg)


def cosine(a, b):
    return float(np.dot(a, b) / (np.linalg.norm(a) * np.linalg.norm(b)))


@pytest.fixture(scope="module")
def layout():
    """The shipped vehicle file's thruster geometry (FRD, about the CG) and its matrix."""
    from hindrax_common.config import default_config_path, load_config

    cfg = load_config(default_config_path())
    matrix = allocation_matrix_from_config(cfg)
    t = cfg.thrusters
    return SimpleNamespace(names=tuple(t.names), positions_m=t.positions_frd_m,
                           directions=t.directions_frd, matrix=matrix.copy)


@pytest.fixture(scope="module")
def curve():
    return hindrax_default_curve()


@pytest.fixture(scope="module")
def allocator(layout, curve):
    return ThrustAllocator(layout.matrix(), curve)


# ---------------------------------------------------------------- matrix
def test_matrix_columns_follow_eq9_for_any_layout():
    rng = np.random.default_rng(0)
    positions = rng.uniform(-0.5, 0.5, (7, 3))
    directions = rng.normal(size=(7, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    b = thrust_allocation_matrix(positions, directions)
    assert b.shape == (6, 7)
    for i in range(7):
        np.testing.assert_allclose(b[:, i], eq9_column(directions[i], positions[i]), atol=1e-12)


@pytest.mark.parametrize("positions, directions", [
    (np.zeros((2, 3)), np.array([[1.0, 0.0, 0.0], [0.0, 2.0, 0.0]])),      # not unit
    (np.zeros((2, 3)), np.zeros((3, 3))),                                 # different n
    (np.zeros((2, 2)), np.array([[1.0, 0.0], [0.0, 1.0]])),               # not (n, 3)
    (np.zeros((0, 3)), np.zeros((0, 3))),                                 # no thrusters
    (np.full((1, 3), math.nan), np.array([[1.0, 0.0, 0.0]])),             # NaN
    ("garbage", np.array([[1.0, 0.0, 0.0]])),
])
def test_matrix_rejects_bad_input(positions, directions):
    with pytest.raises(ValueError):
        thrust_allocation_matrix(positions, directions)


def test_default_layout_geometry(layout):
    assert layout.names == ("t1", "t2", "t3", "t4", "t5", "t6", "t7", "t8")
    expected_dirs = [[COS55, SIN55, 0], [COS55, -SIN55, 0], [-COS55, SIN55, 0], [-COS55, -SIN55, 0]] + [[0, 0, 1]] * 4
    # 55 deg, [Hindrax-Drag] section 4
    np.testing.assert_allclose(layout.directions, expected_dirs, atol=1e-6)
    p = layout.positions_m
    # T1 front-starboard, T2 front-port, T3 rear-starboard, T4 rear-port (FRD: +x forward, +y starboard)
    assert p[0, 0] > 0 and p[0, 1] > 0 and p[1, 0] > 0 and p[1, 1] < 0
    assert p[2, 0] < 0 and p[2, 1] > 0 and p[3, 0] < 0 and p[3, 1] < 0
    # horizontals in the lower layer (+z is down), verticals in the upper layer
    assert np.all(p[:4, 2] > 0) and np.all(p[4:, 2] < 0)
    # inside the 0.59 x 0.47 x 0.40 m envelope ([Hindrax-Drag] section 2.1)
    assert np.all(np.abs(p[:, 0]) <= 0.59 / 2) and np.all(np.abs(p[:, 1]) <= 0.47 / 2)
    assert np.ptp(p[:, 2]) <= 0.40
    assert np.linalg.matrix_rank(layout.matrix()) == 6


def test_seed_pairing_t1_t2_is_surge_with_pitch_moment_from_lower_layer(layout):
    b = layout.matrix()
    force = 10.0
    tau = b @ np.array([force, force, 0, 0, 0, 0, 0, 0])
    z_h = layout.positions_m[0, 2]
    expected = eq9_column(layout.directions[0] * force, layout.positions_m[0]) + \
        eq9_column(layout.directions[1] * force, layout.positions_m[1])
    np.testing.assert_allclose(tau, expected, atol=1e-12)
    assert tau[X] == pytest.approx(2 * COS55 * force)
    np.testing.assert_allclose(tau[[Y, Z, K, N]], 0.0, atol=1e-12)
    # not zero: a horizontal thruster below the centre of gravity pitches the vehicle (M = l_z F_x)
    assert tau[M] == pytest.approx(2 * COS55 * force * z_h)
    assert tau[M] == pytest.approx(1.1472, abs=1e-4)  # 10 N each, z_h = 0.10 m (assumed)


def test_seed_pairing_t1_t3_is_sway_with_roll_moment_from_lower_layer(layout):
    b = layout.matrix()
    force = 10.0
    tau = b @ np.array([force, 0, force, 0, 0, 0, 0, 0])
    z_h = layout.positions_m[0, 2]
    assert tau[Y] == pytest.approx(2 * SIN55 * force)
    np.testing.assert_allclose(tau[[X, Z, M, N]], 0.0, atol=1e-12)  # pure sway in X, Y, N
    assert tau[K] == pytest.approx(-2 * SIN55 * force * z_h)        # K = -l_z F_y
    assert tau[K] == pytest.approx(-1.6383, abs=1e-4)


def test_pure_sway_request_holds_roll_at_zero_with_vertical_thrusters(allocator, layout):
    sway = 20.0
    res = allocator.allocate([0, sway, 0, 0, 0, 0])
    np.testing.assert_allclose(res.achieved_wrench, [0, sway, 0, 0, 0, 0], atol=1e-6)
    b = layout.matrix()
    roll_horizontal = b[K, :4] @ res.force_n[:4]
    roll_vertical = b[K, 4:] @ res.force_n[4:]
    assert roll_horizontal == pytest.approx(-layout.positions_m[0, 2] * sway)  # what T1-T4 create
    assert roll_vertical == pytest.approx(-roll_horizontal, abs=1e-6)          # what T5-T8 cancel
    assert np.all(np.abs(res.force_n[4:]) > 1.0)


def test_weights_reproduce_the_seed_sway_pairing(layout, curve):
    # Heavily weighting T2 and T4 leaves T1 + T3 to push sway, as in [Hindrax-Drag] section 4.1.
    weights = np.array([1, 1e6, 1, 1e6, 1, 1, 1, 1], dtype=float)
    alloc = ThrustAllocator(layout.matrix(), curve, weights=weights)
    sway = 12.0
    res = alloc.allocate([0, sway, 0, 0, 0, 0])
    assert res.allocated_force_n[0] == pytest.approx(sway / (2 * SIN55), rel=1e-4)
    assert res.allocated_force_n[2] == pytest.approx(sway / (2 * SIN55), rel=1e-4)
    assert abs(res.allocated_force_n[1]) < 1e-4 and abs(res.allocated_force_n[3]) < 1e-4
    np.testing.assert_allclose(res.achieved_wrench, [0, sway, 0, 0, 0, 0], atol=1e-3)


# ---------------------------------------------------------------- unsaturated round trip
def test_authority_of_default_layout(layout, curve):
    lower, upper = curve.force_limits_n()
    auth = axis_authority(layout.matrix(), np.full(8, lower), np.full(8, upper))
    assert auth[X] == pytest.approx(4 * COS55 * F_MAX, rel=1e-5)   # four horizontals
    assert auth[Y] == pytest.approx(4 * SIN55 * F_MAX, rel=1e-5)
    assert auth[Z] == pytest.approx(4 * F_MAX, rel=1e-5)           # four verticals
    lever_yaw = 0.20 * SIN55 - 0.15 * COS55
    assert auth[N] == pytest.approx(4 * lever_yaw * F_MAX, rel=1e-5)


@pytest.mark.parametrize("wrench", [
    [20.0, 0, 0, 0, 0, 0],
    [0, 0, 30.0, 0, 0, 0],
    [0, 0, 0, 0, 0, 2.0],
    [10.0, -15.0, 12.0, 1.0, -2.0, 0.8],
])
def test_unsaturated_round_trip(allocator, layout, curve, wrench):
    res = allocator.allocate(wrench)
    assert res.scale == 1.0 and not res.saturated.any()
    # independent forward path: pulse widths -> curves -> eq. 9 matrix
    forces = np.array([curve.thrust_n(p) for p in res.pulse_width_us])
    tau = layout.matrix() @ forces
    lower, upper = curve.force_limits_n()
    auth = axis_authority(layout.matrix(), np.full(8, lower), np.full(8, upper))
    assert np.all(np.abs(tau - np.asarray(wrench)) <= 0.01 * auth)
    np.testing.assert_allclose(res.achieved_wrench, tau, atol=1e-12)


def _feasible_wrench_strategy():
    return st.lists(st.floats(-0.4, 0.4), min_size=6, max_size=6)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.filter_too_much])
@given(_feasible_wrench_strategy())
def test_property_feasible_wrench_is_achieved(allocator, layout, curve, fractions):
    b = layout.matrix()
    lower, upper = curve.force_limits_n()
    auth = axis_authority(b, np.full(8, lower), np.full(8, upper))
    wrench = np.asarray(fractions) * auth
    minimum_norm = np.linalg.pinv(b) @ wrench  # independent minimum-norm allocation
    assume(np.all((minimum_norm < 0.999 * upper) & (minimum_norm > 0.999 * lower)))
    # the [Hindrax-Drag] curve cannot give less than 1.2 N (deadband edge): keep forces clear of that band
    smallest = curve.smallest_forward_n
    assume(np.all(np.abs(minimum_norm) > 1.01 * smallest))
    res = allocator.allocate(wrench)
    assert res.scale == 1.0
    np.testing.assert_allclose(res.allocated_force_n, minimum_norm, atol=1e-9)
    err = np.abs(res.achieved_wrench - wrench)
    assert np.all(err <= 0.01 * auth)
    assert np.all(err <= 1e-3 * np.abs(b).sum(axis=1))  # table cell 0.005 us x slope <= 0.055 N/us


def test_small_forces_error_is_bounded_by_half_the_smallest_thrust(allocator, layout, curve):
    # Inside the band the model cannot follow: the error per thruster is at most half the smallest thrust.
    rng = np.random.default_rng(7)
    bound = np.abs(layout.matrix()) @ np.full(8, 0.5 * curve.smallest_forward_n) + 1e-9
    for _ in range(200):
        res = allocator.allocate(rng.normal(size=6) * [3, 3, 3, 0.5, 0.5, 0.3])
        assert res.scale == 1.0
        assert np.all(np.abs(res.achieved_wrench - res.requested_wrench) <= bound)


# ---------------------------------------------------------------- saturation, uniform mode
@pytest.mark.parametrize("wrench", [
    [200.0, 0, 0, 0, 0, 0],
    [0, -150.0, 0, 0, 0, 0],
    [0, 0, 0, 0, 0, 30.0],
    [80.0, 0, 0, 0, 0, 15.0],
    [0, 0, -150.0, 10.0, 0, 0],
    [71.8, 24.7, 133.8, 0.3, -2.4, 1.5],
])
def test_uniform_saturation_keeps_direction(allocator, curve, wrench):
    res = allocator.allocate(wrench)
    lower, upper = curve.force_limits_n()
    assert 0.0 < res.scale < 1.0
    # cases chosen with every non-zero force clear of the curve's 1.2 N minimum (see the band test below)
    moving = np.abs(res.allocated_force_n) > 1e-9
    assert np.all(np.abs(res.allocated_force_n[moving]) > 1.5 * curve.smallest_forward_n)
    assert res.saturated.any()
    assert np.all(res.allocated_force_n <= upper + 1e-12) and np.all(res.allocated_force_n >= lower - 1e-12)
    np.testing.assert_allclose(allocator.matrix @ res.allocated_force_n, res.scale * np.asarray(wrench), atol=1e-9)
    assert cosine(res.achieved_wrench, wrench) >= 0.9999


@settings(max_examples=150, deadline=None)
@given(st.lists(st.floats(-1.0, 1.0), min_size=6, max_size=6), st.floats(1.5, 100.0))
def test_property_uniform_saturation_direction(allocator, layout, curve, direction, overload):
    direction = np.asarray(direction)
    assume(np.linalg.norm(direction) > 0.1)
    lower, upper = curve.force_limits_n()
    auth = axis_authority(layout.matrix(), np.full(8, lower), np.full(8, upper))
    wrench = direction * auth * overload
    res = allocator.allocate(wrench)
    allocated_wrench = layout.matrix() @ res.allocated_force_n
    assert np.all(res.allocated_force_n <= upper) and np.all(res.allocated_force_n >= lower)
    if res.scale < 1.0:
        assert res.saturated.any()
    # the saturation step alone (the same allocator without the deadband search) keeps the direction exactly
    continuous = ThrustAllocator(layout.matrix(), curve, deadband_search=False).allocate(wrench)
    assert cosine(layout.matrix() @ continuous.allocated_force_n, wrench) >= 1.0 - 1e-12
    assert continuous.scale == res.scale
    moving = continuous.allocated_force_n != 0.0
    if np.all(np.abs(continuous.allocated_force_n[moving]) >= curve.smallest_forward_n):
        np.testing.assert_array_equal(res.allocated_force_n, continuous.allocated_force_n)  # nothing to search
    else:
        # the deadband moves the allocated wrench by at most what one thruster's smallest thrust makes
        worst = np.max(np.linalg.norm(layout.matrix(), axis=0)) * curve.smallest_forward_n
        assert np.linalg.norm(allocated_wrench - res.scale * wrench) <= worst
    if np.all((np.abs(res.allocated_force_n) > 1.01 * curve.smallest_forward_n)):
        assert cosine(res.achieved_wrench, wrench) >= 0.9999


def test_asymmetric_limits_saturate_on_the_right_side(layout):
    # A weaker forward direction (half of the reflected curve), e.g. a thruster with a different propeller.
    neg = (-4.61e-7, 0.001794, -2.2726, 927.1827)
    weak = ThrustCurve(neg, tuple(0.5 * c for c in point_reflection(neg)))
    assert weak.max_forward_n == pytest.approx(0.5 * F_MAX, rel=1e-5)
    assert weak.max_reverse_n == pytest.approx(-F_MAX, rel=1e-5)
    alloc = ThrustAllocator(layout.matrix(), weak)
    res = alloc.allocate([200.0, 0, 0, 0, 0, 0])
    # surge: T1, T2 push forward (weak side) and T3, T4 reverse; the forward side limits the scale
    assert res.saturated[:2].all() and not res.saturated[2:4].any()
    np.testing.assert_allclose(res.allocated_force_n[:2], 0.5 * F_MAX, rtol=1e-5)
    assert res.achieved_wrench[X] == pytest.approx(4 * COS55 * 0.5 * F_MAX, rel=1e-4)


def test_per_thruster_curves(layout, curve):
    neg = (-4.61e-7, 0.001794, -2.2726, 927.1827)
    weak = ThrustCurve(neg, tuple(0.5 * c for c in point_reflection(neg)))
    curves = [weak, curve, curve, curve, curve, curve, curve, curve]
    alloc = ThrustAllocator(layout.matrix(), curves)
    res = alloc.allocate([200.0, 0, 0, 0, 0, 0])
    assert res.saturated[0] and not res.saturated[1]
    assert res.allocated_force_n[0] == pytest.approx(weak.max_forward_n)
    expected = [c.thrust_n(p) for c, p in zip(curves, res.pulse_width_us)]
    np.testing.assert_allclose(res.force_n, expected, atol=1e-12)
    # equal parameters make equal curves (the allocator evaluates them together)
    assert hindrax_default_curve() == curve and hash(hindrax_default_curve()) == hash(curve)
    assert weak != curve
    with pytest.raises(ValueError):
        ThrustAllocator(layout.matrix(), curves[:7])


# ---------------------------------------------------------------- priority mode
def test_priority_keeps_heave_and_yaw_and_reduces_surge(layout, curve):
    alloc = ThrustAllocator(layout.matrix(), curve, mode="priority", priority_groups=(("heave", "yaw"),))
    heave, yaw, surge = 20.0, 1.0, 60.0
    res = alloc.allocate([surge, 0, heave, 0, 0, yaw])
    allocated = layout.matrix() @ res.allocated_force_n
    assert allocated[Z] == pytest.approx(heave, abs=1e-9)
    assert allocated[N] == pytest.approx(yaw, abs=1e-9)
    np.testing.assert_allclose(allocated[[Y, K, M]], 0.0, atol=1e-9)
    # Hand derivation: yaw puts +-yaw/(4 L) on T1-T4 (L = 0.20 sin55 - 0.15 cos55), surge adds
    # +-X/(4 cos55); T1 reaches the limit first: X = 4 cos55 (F_max - yaw/(4 L)).
    lever_yaw = 0.20 * SIN55 - 0.15 * COS55
    expected_surge = 4 * COS55 * (F_MAX - yaw / (4 * lever_yaw))
    assert allocated[X] == pytest.approx(expected_surge, rel=1e-4)
    assert res.saturated[0] and res.saturated[2]
    np.testing.assert_allclose(res.achieved_wrench[[Z, N]], [heave, yaw], atol=1e-3)
    assert res.axis_scale[Z] == 1.0 and res.axis_scale[N] == 1.0
    assert res.axis_scale[X] == pytest.approx(expected_surge / surge, rel=1e-4)
    # uniform mode on the same request gives up heave and yaw as well
    uniform = ThrustAllocator(layout.matrix(), curve).allocate([surge, 0, heave, 0, 0, yaw])
    assert uniform.achieved_wrench[Z] < 0.9 * heave and uniform.achieved_wrench[N] < 0.9 * yaw


def test_priority_group_itself_infeasible_is_scaled_along_its_direction(layout, curve):
    alloc = ThrustAllocator(layout.matrix(), curve, mode="priority")
    res = alloc.allocate([10.0, 0, 100.0, 0, 0, 10.0])
    allocated = layout.matrix() @ res.allocated_force_n
    s = res.axis_scale[Z]
    assert 0.0 < s < 1.0 and res.axis_scale[N] == s
    assert allocated[Z] == pytest.approx(100.0 * s) and allocated[N] == pytest.approx(10.0 * s)
    assert res.scale == min(res.axis_scale)


def test_priority_groups_by_index_and_validation(layout, curve):
    alloc = ThrustAllocator(layout.matrix(), curve, mode="priority", priority_groups=[[2], ["yaw", 0]])
    assert alloc.priority_groups == ((2,), (5, 0), (1, 3, 4))
    for bad in ([["heave", 2]], [["lift"]], [[7]], [[]]):
        with pytest.raises(ValueError):
            ThrustAllocator(layout.matrix(), curve, mode="priority", priority_groups=bad)
    with pytest.raises(ValueError):
        ThrustAllocator(layout.matrix(), curve, mode="fancy")
    assert AXIS_NAMES == ("surge", "sway", "heave", "roll", "pitch", "yaw")


# ---------------------------------------------------------------- bad input
@pytest.mark.parametrize("bad", [
    [math.nan, 0, 0, 0, 0, 0], [0, 0, math.inf, 0, 0, 0], [0, 0, 0, 0, 0, -math.inf],
    [1.0, 2.0, 3.0], np.zeros((6, 1)), "wrench", None, [0, 0, 0, 0, 0, "a"],
])
def test_invalid_wrench_rejected(allocator, bad):
    with pytest.raises(InvalidWrenchError):
        allocator.allocate(bad)
    assert issubclass(InvalidWrenchError, ValueError)


@pytest.mark.parametrize("kwargs", [
    {"matrix": np.zeros((5, 8))}, {"matrix": np.full((6, 8), math.nan)},
    {"weights": np.zeros(8)}, {"weights": np.ones(7)}, {"curves": ["not a curve"] * 8}, {"curves": 5},
    {"pulse_width_step_us": 0.0}, {"pulse_width_step_us": "x"},
])
def test_invalid_configuration_rejected(layout, curve, kwargs):
    args = {"matrix": layout.matrix(), "curves": curve}
    args.update(kwargs)
    with pytest.raises(ValueError):
        ThrustAllocator(**args)


def test_bad_voltage_scale_rejected(allocator):
    for bad in (0.0, -1.0, math.nan):
        with pytest.raises(ValueError):
            allocator.allocate([1, 0, 0, 0, 0, 0], voltage_scale=bad)


def test_repeated_request_returns_the_same_read_only_result(layout, curve):
    """The one-entry memo of allocate: the same request is answered by the same result, which nobody can alter;
    a different request, another voltage scale or a reconfiguration computes afresh."""
    alloc = ThrustAllocator(layout.matrix(), curve)
    wrench = [-2.0, 0.3, 0.5, 0.0, 0.02, 0.1]  # small: the deadband search runs
    first = alloc.allocate(wrench)
    fresh = ThrustAllocator(layout.matrix(), curve).allocate(list(wrench))
    again = alloc.allocate(np.array(wrench))
    assert again is first
    np.testing.assert_array_equal(again.pulse_width_us, fresh.pulse_width_us)
    for arr in (first.pulse_width_us, first.force_n, first.allocated_force_n, first.achieved_wrench,
                first.requested_wrench, first.axis_scale, first.saturated):
        with pytest.raises(ValueError):
            arr[0] = 0
    other = alloc.allocate([2.0, 0.3, 0.5, 0.0, 0.02, 0.1])
    assert other is not first and other.achieved_wrench[X] > 0 > first.achieved_wrench[X]
    assert alloc.allocate(wrench, voltage_scale=0.9) is not first
    alloc.allocate(wrench)
    alloc.reconfigure(weights=[1.0, 1.0, 1.0, 1.0, 2.0, 2.0, 2.0, 2.0])
    assert alloc.allocate(wrench) is not first


# ---------------------------------------------------------------- other layouts
def test_custom_six_thruster_layout_full_rank():
    positions = [[0.3, 0, 0], [-0.3, 0, 0], [0, 0, 0], [0.25, 0, 0], [-0.2, 0.2, 0], [-0.2, -0.2, 0]]
    directions = [[0, 1, 0], [0, 1, 0], [1, 0, 0], [0, 0, 1], [0, 0, 1], [0, 0, 1]]
    b = thrust_allocation_matrix(positions, directions)
    assert np.linalg.matrix_rank(b) == 6
    curve = hindrax_default_curve()
    alloc = ThrustAllocator(b, curve)
    wrench = np.array([5.0, 8.0, 10.0, 0.5, 0.3, 1.0])
    res = alloc.allocate(wrench)
    np.testing.assert_allclose(res.allocated_force_n, np.linalg.solve(b, wrench), atol=1e-9)
    assert np.all(np.abs(res.allocated_force_n) > 1.5 * curve.smallest_forward_n)  # clear of the 1.2 N band
    lower, upper = curve.force_limits_n()
    assert np.all(np.abs(res.achieved_wrench - wrench) <= 0.01 * axis_authority(b, lower, upper))


def test_zero_authority_axis_is_ignored():
    # BlueROV2-like: four vectored horizontals at z = 0 and two verticals on the centreline sides:
    # no pitch authority (the verticals have x = 0), so M cannot be produced.
    s = math.sqrt(0.5)
    positions = [[0.15, 0.1, 0], [0.15, -0.1, 0], [-0.15, 0.1, 0], [-0.15, -0.1, 0], [0, 0.2, 0], [0, -0.2, 0]]
    directions = [[s, -s, 0], [s, s, 0], [s, s, 0], [s, -s, 0], [0, 0, 1], [0, 0, 1]]
    b = thrust_allocation_matrix(positions, directions)
    alloc = ThrustAllocator(b, hindrax_default_curve())
    np.testing.assert_array_equal(alloc.zero_authority_axes, [False, False, False, False, True, False])
    res = alloc.allocate([12.0, 3.0, 8.0, 0.5, 2.0, -0.3])
    assert np.all(np.abs(res.allocated_force_n) > 2.0)  # clear of the 1.2 N band
    np.testing.assert_allclose(res.achieved_wrench, [12.0, 3.0, 8.0, 0.5, 0.0, -0.3], atol=1e-3)
    for pitch in (5.0, 1e300):
        only_pitch = alloc.allocate([0, 0, 0, 0, pitch, 0])
        np.testing.assert_array_equal(only_pitch.allocated_force_n, 0.0)
        np.testing.assert_array_equal(only_pitch.pulse_width_us, 1500.0)
        assert only_pitch.scale == 1.0


# ---------------------------------------------------------------- quantisation, voltage, configuration
def test_quantised_pulse_widths_and_achieved_wrench(layout, curve):
    tick = 31 * 1e6 / 25e6  # PCA9685 PRE_SCALE 30 at 25 MHz: 1.24 us (docs/devices.md §5.1)
    alloc = ThrustAllocator(layout.matrix(), curve, pulse_width_step_us=tick)
    res = alloc.allocate([300.0, 5.0, 12.0, 0.0, 0.5, 0.3])
    counts = res.pulse_width_us / tick
    np.testing.assert_allclose(counts, np.round(counts), atol=1e-9)
    assert np.all(res.pulse_width_us >= 1100.0) and np.all(res.pulse_width_us <= 1900.0)
    forces = np.array([curve.thrust_n(p) for p in res.pulse_width_us])
    np.testing.assert_allclose(res.force_n, forces, atol=1e-12)
    np.testing.assert_allclose(res.achieved_wrench, layout.matrix() @ forces, atol=1e-12)


def test_voltage_scale_lowers_limits_and_keeps_unsaturated_wrench(allocator, curve):
    wrench = np.array([14.7, -3.5, 24.2, 0.1, 0.5, 0.3])
    full = allocator.allocate(wrench)
    assert np.all(np.abs(full.allocated_force_n) > 4.0)  # clear of the 1.2 N (0.96 N at 0.8) band
    low = allocator.allocate(wrench, voltage_scale=0.8)
    np.testing.assert_allclose(low.achieved_wrench, full.achieved_wrench, atol=1e-3)
    moving = np.abs(full.force_n) > 0
    assert np.all(np.abs(low.pulse_width_us[moving] - 1500.0) > np.abs(full.pulse_width_us[moving] - 1500.0))
    sat = allocator.allocate([500.0, 0, 0, 0, 0, 0], voltage_scale=0.8)
    assert np.max(sat.allocated_force_n) == pytest.approx(0.8 * F_MAX, rel=1e-5)


def test_limits_follow_a_reconfigured_curve_at_the_same_voltage_scale(layout, curve):
    """The allocator keeps its limits per voltage scale between calls; a new curve must replace them. A curve whose
    ESC range ends at 1700 us saturates at its own thrust there (the curve's value, not the 1900 us F_MAX), and back
    on the full range the limit is F_MAX again; likewise when the scale alternates between calls."""
    alloc = ThrustAllocator(layout.matrix(), curve)
    push = [500.0, 0, 0, 0, 0, 0]
    assert np.max(alloc.allocate(push).allocated_force_n) == pytest.approx(F_MAX, rel=1e-5)
    short = ThrustCurve(curve.negative_coeffs, curve.positive_coeffs, pulse_width_min_us=1300.0,
                        pulse_width_max_us=1700.0)
    f_1700 = short.thrust_n(1700.0)
    assert 1.0 < f_1700 < 0.8 * F_MAX
    alloc.reconfigure(curves=short)
    assert np.max(alloc.allocate(push).allocated_force_n) == pytest.approx(f_1700, rel=1e-5)
    assert np.max(alloc.allocate(push, voltage_scale=0.5).allocated_force_n) == pytest.approx(0.5 * f_1700, rel=1e-5)
    alloc.reconfigure(curves=curve)
    assert np.max(alloc.allocate(push).allocated_force_n) == pytest.approx(F_MAX, rel=1e-5)


def test_pseudo_inverse_computed_once_and_on_reconfigure(layout, curve):
    alloc = ThrustAllocator(layout.matrix(), curve)
    pinv = alloc.pseudo_inverse
    alloc.allocate([1.0, 2.0, 3.0, 0.1, 0.2, 0.3])
    assert alloc.pseudo_inverse is pinv
    np.testing.assert_allclose(pinv, np.linalg.pinv(layout.matrix()), atol=1e-12)
    alloc.reconfigure(weights=np.arange(1.0, 9.0))
    assert alloc.pseudo_inverse is not pinv
    w_inv = np.diag(1.0 / np.arange(1.0, 9.0))
    b = layout.matrix()
    expected = w_inv @ b.T @ np.linalg.inv(b @ w_inv @ b.T)
    np.testing.assert_allclose(alloc.pseudo_inverse, expected, atol=1e-10)
    before = alloc.pseudo_inverse
    with pytest.raises(ValueError):
        alloc.reconfigure(weights=-np.ones(8))
    assert alloc.pseudo_inverse is before  # failed reconfigure keeps the previous configuration
    alloc.reconfigure(mode="priority")
    assert alloc.mode == "priority" and alloc.pseudo_inverse is not before
    # a new geometry with a kept shared curve: only the first four thrusters
    alloc.reconfigure(matrix=b[:, :4], weights=None)
    assert alloc.n_thrusters == 4 and alloc.pseudo_inverse.shape == (4, 6)
    np.testing.assert_array_equal(alloc.zero_authority_axes, [False, False, True, False, False, False])


# ---------------------------------------------------------------- any finite wrench
@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(allow_nan=False, allow_infinity=False), min_size=6, max_size=6),
       st.sampled_from(["uniform", "priority"]))
def test_property_any_finite_wrench_gives_feasible_output(layout, curve, wrench, mode):
    alloc = ThrustAllocator(layout.matrix(), curve, mode=mode)
    res = alloc.allocate(wrench)
    lower, upper = curve.force_limits_n()
    for forces in (res.allocated_force_n, res.force_n):
        assert np.all(np.isfinite(forces))
        assert np.all(forces <= upper) and np.all(forces >= lower)
    assert np.all((res.pulse_width_us >= 1100.0) & (res.pulse_width_us <= 1900.0))
    np.testing.assert_allclose(res.force_n, [curve.thrust_n(p) for p in res.pulse_width_us], atol=1e-12)
    np.testing.assert_allclose(res.achieved_wrench, layout.matrix() @ res.force_n, atol=1e-9)
    assert 0.0 <= res.scale <= 1.0
    if mode == "uniform":
        assert res.scale > 0.0 or not np.any(wrench)


# ---------------------------------------------------------------- issue 19, faults 10 and 11
TICK_US = 31 * 1e6 / 25e6  # PCA9685 PRE_SCALE 30 at 25 MHz: one count = 1.24 us (docs/devices.md §5.1)


def test_fault10_quantisation_never_rounds_into_the_deadband(layout, curve):
    """1475.00 us (the reverse deadband edge, -1.20 N) used to become 1475.60 us (0 N); now every width is on the
    PCA9685 grid, the nearest grid width to the exact inverse of its allocated force, and outside the 1475-1525 us
    deadband unless it is the grid's neutral (1500.40 us, 0 N)."""
    grid = ThrustAllocator(layout.matrix(), curve, pulse_width_step_us=TICK_US)
    rng = np.random.default_rng(19)
    wrenches = rng.uniform(-1.0, 1.0, (5000, 6)) * np.array([4.0, 4.0, 4.0, 0.4, 0.4, 0.4])
    near_edges = inside = 0
    for w in wrenches:
        res = grid.allocate(w)
        p1 = res.pulse_width_us
        counts = p1 / TICK_US
        np.testing.assert_allclose(counts, np.round(counts), atol=1e-9)  # on the PCA9685 grid
        exact = curve.pulse_width_us(res.allocated_force_n)
        assert np.all(np.abs(p1 - exact) <= 0.5 * TICK_US + 1e-9)  # nearest grid width
        neutral = np.abs(p1 - 1500.0) <= 0.5 * TICK_US
        assert np.array_equal(neutral, res.allocated_force_n == 0.0)
        inside += int(np.sum(~neutral & (p1 > 1475.0) & (p1 < 1525.0)))
        near_edges += int(np.sum((np.abs(p1 - 1475.0) < 2.0) | (np.abs(p1 - 1525.0) < 2.0)))
    assert near_edges > 2_000  # the sample exercises the smallest forces, next to the deadband edges
    assert inside == 0
    # the edge itself, by hand: 1475 / 1.24 = 1189.52 counts -> 1189 counts = 1474.36 us (not 1190 = 1475.60 us)
    one = ThrustAllocator(np.array([[1.0], [0], [0], [0], [0], [0]]), curve, pulse_width_step_us=TICK_US)
    edge_force = curve.thrust_n(1475.0)
    res = one.allocate([edge_force, 0, 0, 0, 0, 0])
    assert res.pulse_width_us[0] == pytest.approx(1189 * TICK_US, abs=1e-9) and res.force_n[0] < edge_force + 1e-12
    mirror = one.allocate([-edge_force, 0, 0, 0, 0, 0])  # forward edge 1525 / 1.24 = 1229.8 -> 1230 counts
    assert mirror.pulse_width_us[0] == pytest.approx(1230 * TICK_US, abs=1e-9) and mirror.force_n[0] > 0.0


def test_fault11_default_mode_keeps_depth_when_surge_saturates():
    """The shipped configuration: [60, 0, -40, 0, 0, 3] (base_link FLU, N and N m) keeps the -40 N heave and the
    3 N m yaw (to the PCA9685 quantisation) and gives surge what is left (it was -17.6 N heave with "uniform")."""
    from hindrax_bringup.allocation.core import AllocationCore
    from hindrax_common.config import default_config_path, load_config

    cfg = load_config(default_config_path())
    res = AllocationCore(cfg).allocate(np.array([60.0, 0.0, -40.0, 0.0, 0.0, 3.0]))
    achieved = res.achieved_wrench_flu
    assert achieved[2] == pytest.approx(-40.0, abs=0.5)  # a few counts of 1.24 us on four thrusters
    assert achieved[5] == pytest.approx(3.0, abs=0.05)
    assert 0.0 < achieved[0] < 60.0  # surge reduced, same sign
    assert bool(np.any(res.saturated))
