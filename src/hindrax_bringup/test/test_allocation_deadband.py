"""The thrust allocation outside the ESC deadband (allocation/deadband.py, allocator.py step 3).

Independent references used here: the thrust allocation matrix rebuilt from the configured positions and
directions with numpy (columns [d; r x d], [Hindrax-Drag] eq. 9), the thrust curves evaluated from the configured
cubic coefficients with numpy.poly1d and the configured deadband ([Hindrax-Drag] eq. 1, docs/devices.md §5.2),
the PCA9685 count from PRE_SCALE = round(f_osc / (4096 f)) - 1 (docs/devices.md §5.1), and a brute-force solve of
the mixed-integer problem (scipy.optimize.lsq_linear on every one of the 3^8 sign patterns).
"""
from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import lsq_linear

from hindrax_bringup.allocation.allocator import ThrustAllocator
from hindrax_bringup.allocation.deadband import DeadbandSearch
from hindrax_bringup.allocation.from_config import allocator_from_config
from hindrax_common.config import default_config_path, load_config

CFG = load_config(default_config_path())
T = CFG.thrusters
NEUTRAL_US, DEADBAND_US = T.pulse_width_neutral_us, T.deadband_us
NEG, POS = np.poly1d(T.curve_negative), np.poly1d(T.curve_positive)


def pca9685_count_us(frequency_hz: float, oscillator_hz: float = 25e6) -> float:
    """docs/devices.md §5.1: PRE_SCALE = round(f_osc / (4096 f)) - 1, one count = (PRE_SCALE + 1) / f_osc."""
    return (np.floor(oscillator_hz / (4096.0 * frequency_hz) + 0.5)) / oscillator_hz * 1e6


STEP_200HZ = pca9685_count_us(200.0)  # the configured 200 Hz: 1.24 us
STEP_50HZ = pca9685_count_us(50.0)  # 50 Hz: 4.88 us
assert abs(STEP_200HZ - 1.24) < 1e-12 and abs(STEP_50HZ - 4.88) < 1e-12


def matrix_frd() -> np.ndarray:
    """B (6, 8), FRD about the CG: column [d; r x d] ([Hindrax-Drag] eq. 9), from the YAML numbers."""
    cols = []
    for th in T.thrusters:
        r = np.asarray(th.position_frd_m) - CFG.vehicle.centre_of_gravity_frd_m
        d = np.asarray(th.direction_frd)
        cols.append(np.concatenate([d, np.cross(r, d)]))
    return np.array(cols).T


B = matrix_frd()


def thrust(p) -> np.ndarray:
    """[Hindrax-Drag] eq. 1 with the deadband: 0 N strictly inside neutral +- deadband."""
    p = np.asarray(p, dtype=float)
    return np.where(p <= NEUTRAL_US - DEADBAND_US, np.minimum(NEG(p), 0.0),
                    np.where(p >= NEUTRAL_US + DEADBAND_US, np.maximum(POS(p), 0.0), 0.0))


def grid_edges(step: float) -> tuple[float, float]:
    """Last reverse and first forward grid width outside the deadband (us)."""
    return (np.floor((NEUTRAL_US - DEADBAND_US) / step + 1e-9) * step,
            np.ceil((NEUTRAL_US + DEADBAND_US) / step - 1e-9) * step)


def effort_weight(step: float) -> float:
    """rho = min (delta / m)^2: delta the thrust of one count next to the smallest thrust m, both directions."""
    rev, fwd = grid_edges(step)
    return float(min((thrust(fwd + step) - thrust(fwd)) / thrust(fwd),
                     (thrust(rev - step) - thrust(rev)) / thrust(rev)) ** 2)


def largest_count_thrust(step: float) -> float:
    """Largest thrust change of one count anywhere on the curve (N)."""
    p = np.arange(1100.0, 1900.0 + 1e-9, 0.05)
    return float(np.max(np.abs(thrust(np.minimum(p + step, 1900.0)) - thrust(p))))


def allocator(mode: str = "priority", step: float = STEP_200HZ) -> ThrustAllocator:
    alloc = allocator_from_config(CFG)
    alloc.reconfigure(mode=mode, pulse_width_step_us=step)
    return alloc


ALLOCATORS = {(mode, step): allocator(mode, step)
              for mode in ("uniform", "priority") for step in (STEP_200HZ, STEP_50HZ)}


def check_widths_and_achieved(res, step: float, voltage_scale: float = 1.0) -> None:
    p = res.pulse_width_us
    np.testing.assert_allclose(p / step, np.round(p / step), atol=1e-9)  # on the PCA9685 grid
    neutral = np.abs(p - NEUTRAL_US) <= 0.5 * step
    outside = np.abs(p - NEUTRAL_US) >= DEADBAND_US
    assert np.all(neutral | outside), f"width in the deadband: {p}"
    force = voltage_scale * thrust(p)
    np.testing.assert_allclose(res.force_n, force, rtol=0, atol=1e-9)
    np.testing.assert_allclose(res.achieved_wrench, B @ force, rtol=0, atol=1e-9)


# ---------------------------------------------------------------- any request
@settings(max_examples=300, deadline=None)
@given(st.lists(st.floats(-1.0, 1.0), min_size=6, max_size=6), st.sampled_from([0.1, 1.0, 3.0, 30.0, 300.0]),
       st.sampled_from(sorted(ALLOCATORS)), st.floats(0.75, 1.1))
def test_property_no_width_in_the_deadband_and_achieved_wrench_from_the_widths(direction, size, key, voltage_scale):
    res = ALLOCATORS[key].allocate(np.asarray(direction) * size * np.array([1, 1, 1, 0.15, 0.15, 0.15]),
                                   voltage_scale=voltage_scale)
    p = res.pulse_width_us
    step = key[1]
    np.testing.assert_allclose(p / step, np.round(p / step), atol=1e-9)
    assert np.all((np.abs(p - NEUTRAL_US) <= 0.5 * step) | (np.abs(p - NEUTRAL_US) >= DEADBAND_US))
    force = voltage_scale * thrust(p)
    np.testing.assert_allclose(res.force_n, force, rtol=0, atol=1e-9)
    np.testing.assert_allclose(res.achieved_wrench, B @ force, rtol=0, atol=1e-9)
    moving = res.allocated_force_n != 0.0
    assert np.array_equal(moving, np.abs(p - NEUTRAL_US) > 0.5 * step)


# ---------------------------------------------------------------- requests the thrusters can produce
@st.composite
def producible(draw):
    """A wrench some thrusters outside their deadband produce exactly: each thruster off, or on at a grid width
    between its deadband edge and 5 N (so the pseudo-inverse of any such wrench stays within the 15.5 N limits),
    at a battery voltage scale of 0.8, 1 or 1.1."""
    step = draw(st.sampled_from([STEP_200HZ, STEP_50HZ]))
    rev, fwd = grid_edges(step)
    force = []
    for _ in range(8):
        state = draw(st.sampled_from([0, 1, -1]))
        counts = draw(st.integers(0, int(95 / step)))
        p = fwd + counts * step if state > 0 else rev - counts * step
        force.append(0.0 if state == 0 else float(thrust(p)))
    force = np.array(force)
    assert np.all(np.abs(force) < 5.0)  # 95 us beyond the deadband edge: about 4.5 N
    voltage_scale = draw(st.sampled_from([1.0, 0.8, 1.1]))
    return step, voltage_scale * force, draw(st.sampled_from(["uniform", "priority"])), voltage_scale


@settings(max_examples=300, deadline=None)
@given(producible())
def test_property_producible_request_is_produced_to_the_pwm_step(case):
    """Error <= what the PCA9685 step allows: half a count of thrust on every thruster, plus the effort trade
    sqrt(rho sum F^2) that the allocator may prefer to running thrusters against each other (rho = (delta/m)^2)."""
    step, truth, mode, voltage_scale = case
    tau = B @ truth
    res = ALLOCATORS[(mode, step)].allocate(tau, voltage_scale=voltage_scale)
    check_widths_and_achieved(res, step, voltage_scale)
    quantisation = np.abs(B) @ np.full(8, 0.5 * voltage_scale * largest_count_thrust(step))
    trade = np.sqrt(effort_weight(step) * np.sum(truth ** 2))
    assert np.all(np.abs(res.achieved_wrench - tau) <= quantisation + trade + 1e-9)
    assert res.scale == 1.0


def test_the_issue_case_surge_2_n_runs_one_symmetric_pair():
    """Issue 26: [-2 0 0 0 0 0] (FLU) gave -2.77 N surge and 0.28 N m pitch with every horizontal thruster rounded
    up to its smallest thrust; a symmetric pair at 1.73 N gives -2 N with no sway or yaw."""
    res = allocator("priority").allocate([-2.0, 0, 0, 0, 0, 0])  # FRD surge = FLU surge
    check_widths_and_achieved(res, STEP_200HZ)
    horizontal = res.force_n[:4]
    running = np.flatnonzero(horizontal)
    assert running.size == 2 and horizontal[running[0]] == pytest.approx(horizontal[running[1]], abs=1e-12)
    assert abs(horizontal[running[0]]) == pytest.approx(2.0 / (2 * np.cos(np.radians(55.0))), abs=0.02)
    achieved = res.achieved_wrench
    assert achieved[0] == pytest.approx(-2.0, abs=0.05)
    assert np.all(np.abs(achieved[[1, 5]]) < 1e-9)  # sway and yaw cancel exactly in the pair
    assert np.all(np.abs(achieved[[2, 3, 4]]) < 0.05)  # what the verticals leave of the pair's pitch moment


def test_heave_is_kept_when_the_deadband_forces_a_compromise_on_pitch():
    """A pitch moment of 0.1 N m with a 3 N heave: the verticals cannot make 0.1 N m without also moving heave or
    roll unless two of them run against each other; what is left is quantisation, in every mode."""
    for mode in ("uniform", "priority"):
        res = allocator(mode).allocate([0, 0, 3.0, 0, 0.1, 0])
        check_widths_and_achieved(res, STEP_200HZ)
        quantisation = np.abs(B) @ np.full(8, 0.5 * largest_count_thrust(STEP_200HZ))
        assert np.all(np.abs(res.achieved_wrench - [0, 0, 3.0, 0, 0.1, 0]) <= quantisation)
        assert np.all(res.achieved_wrench[[0, 1, 5]] == 0.0)  # the horizontals stay off


def test_requests_below_one_count_of_thrust_stay_neutral():
    """Running two thrusters against each other at 1.2 N to make 0.01 N is not worth it (effort weight)."""
    res = allocator("priority").allocate([0.01, 0, 0, 0, 0, 0.005])
    np.testing.assert_array_equal(res.force_n, 0.0)


def test_same_request_same_widths_and_no_state_between_calls():
    alloc, fresh = allocator(), allocator()
    wrenches = np.random.default_rng(3).normal(size=(50, 6)) * [2, 2, 2, 0.3, 0.3, 0.2]
    first = [alloc.allocate(w).pulse_width_us for w in wrenches]
    for w, p in zip(wrenches[::-1], first[::-1]):
        np.testing.assert_array_equal(fresh.allocate(w).pulse_width_us, p)


def test_without_the_search_and_beyond_the_enumerated_size_widths_still_avoid_the_deadband():
    plain = allocator()
    plain.reconfigure(deadband_search=False)
    res = plain.allocate([-2.0, 0, 0, 0, 0, 0])
    check_widths_and_achieved(res, STEP_200HZ)
    assert res.achieved_wrench[0] < -2.5  # every horizontal rounded up to its smallest thrust: the issue's case
    thirteen = ThrustAllocator(np.tile(B, (1, 2))[:, :13], allocator().curves[0], pulse_width_step_us=STEP_200HZ)
    for w in np.random.default_rng(5).normal(size=(30, 6)):
        p = thirteen.allocate(w).pulse_width_us
        assert np.all((np.abs(p - NEUTRAL_US) <= 0.5 * STEP_200HZ) | (np.abs(p - NEUTRAL_US) >= DEADBAND_US))


def test_search_rejects_bad_configuration():
    ones = np.ones(8)
    with pytest.raises(ValueError, match="matrix"):
        DeadbandSearch(np.ones((6, 13)), np.ones(13), 0.0, -np.ones(13), np.ones(13), np.ones(13), np.ones(13))
    with pytest.raises(ValueError, match="weights"):
        DeadbandSearch(B, -ones, 0.0, -ones, ones, ones, ones)
    with pytest.raises(ValueError, match="lower"):
        DeadbandSearch(B, ones, 0.0, ones, ones, ones, ones)
    with pytest.raises(ValueError, match="effort_weight"):
        DeadbandSearch(B, ones, -1.0, -ones, ones, ones, ones)
    with pytest.raises(ValueError, match="effort_weight"):
        ThrustAllocator(B, allocator().curves[0], effort_weight=float("nan"))


# ---------------------------------------------------------------- against a brute-force solve
def brute_force(search: DeadbandSearch, tau: np.ndarray) -> float:
    """Least J over all 3^8 sign patterns (off, forward >= m, reverse <= -m), each a bounded least squares."""
    a = np.vstack([B, np.diag(np.sqrt(search.effort_weight * search.weights))])
    rhs = np.concatenate([tau, np.zeros(8)])
    best = float(rhs @ rhs)
    for pattern in itertools.product((0, 1, -1), repeat=8):
        sign = np.array(pattern)
        on = sign != 0
        if not on.any():
            continue
        low = np.where(sign > 0, search.smallest_forward, search.lower)[on]
        high = np.where(sign > 0, search.upper, -search.smallest_reverse)[on]
        x = lsq_linear(a[:, on], rhs, bounds=(low, high), method="bvls").x
        r = a[:, on] @ x - rhs
        best = min(best, float(r @ r))
    return best


@pytest.mark.parametrize("wrench", [[-2.0, 0, 0, 0, 0, 0], [8.0, 0, 0, 0, 0, 0]])
def test_the_search_finds_the_brute_force_optimum(wrench):
    """The issue's surge request and the actuation bench's 8 N (whose pitch moment puts the verticals at 1 N)."""
    alloc = allocator("uniform")
    plain = allocator("uniform")
    plain.reconfigure(deadband_search=False)
    tau = B @ plain.allocate(wrench).allocated_force_n  # the wrench the search is given
    search = alloc.search
    found = float(search.objective(alloc.allocate(wrench).allocated_force_n, tau))
    assert found <= brute_force(search, tau) * 1.01 + 1e-12
