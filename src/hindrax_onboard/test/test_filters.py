"""Tests of hindrax_onboard.estimation.filters (constant-acceleration Kalman filter, RTS smoother).

Error bounds are set against the naive alternative the design forbids (finite differences):
with position noise sigma = 0.01 m at ~20 Hz, a first difference has velocity noise
sigma sqrt(2) / dt ~ 0.28 m/s and a second difference acceleration noise
sigma sqrt(6) / dt^2 ~ 10 m/s^2, on a trajectory of velocity and acceleration amplitude 0.5.
"""

import numpy as np
import pytest

from hindrax_onboard.estimation.filters import (
    KinematicKalmanFilter,
    process_noise,
    smooth_kinematics,
    transition_matrix,
)
from hindrax_onboard.estimation.least_squares import EstimationError

A_M, W_RAD_S = 0.5, 1.0     # x = A sin(w t): v amplitude 0.5 m/s, a amplitude 0.5 m/s^2


def trajectory(rng, n=400, noise=0.01, dropouts=True):
    t = np.cumsum(rng.uniform(0.03, 0.07, n))          # non-uniform, ~20 Hz
    x = A_M * np.sin(W_RAD_S * t)
    v = A_M * W_RAD_S * np.cos(W_RAD_S * t)
    a = -A_M * W_RAD_S**2 * np.sin(W_RAD_S * t)
    z = x + rng.normal(0, noise, n)
    if dropouts:
        z[150:170] = np.nan                             # 1 s sonar dropout
        z[rng.choice(n, 20, replace=False)] = np.nan    # isolated missing samples
    return t, x, v, a, z


def rms(e):
    return float(np.sqrt(np.mean(np.square(e))))


def test_transition_and_process_noise_matrices():
    F = transition_matrix(0.1)
    np.testing.assert_allclose(F @ [1.0, 2.0, 3.0], [1 + 0.2 + 0.015, 2 + 0.3, 3.0])
    Q = process_noise(0.1, 2.0)
    dt = 0.1
    expected = 2.0 * np.array([[dt**5 / 20, dt**4 / 8, dt**3 / 6],
                               [dt**4 / 8, dt**3 / 3, dt**2 / 2],
                               [dt**3 / 6, dt**2 / 2, dt]])
    np.testing.assert_allclose(Q, expected, rtol=1e-12)
    np.testing.assert_array_equal(process_noise(0.0, 2.0), np.zeros((3, 3)))
    # the same matrix as filterpy's own construction (block_diag of the white-noise model), over sample intervals
    # from an IMU's to a long DVL gap
    from filterpy.common import Q_continuous_white_noise

    for dt, psd in ((0.0098, 2.0), (0.1, 0.05), (1.7, 30.0)):
        np.testing.assert_allclose(process_noise(dt, psd), Q_continuous_white_noise(3, dt, psd), rtol=1e-12, atol=0)


def test_smoother_velocity_and_acceleration_from_noisy_position():
    rng = np.random.default_rng(0)
    t, x, v, a, z = trajectory(rng)
    pos, vel, acc = smooth_kinematics(t, z, measured="position", jerk_psd=0.5, measurement_std=0.01)
    inner = slice(20, -20)          # away from the record ends
    assert rms(pos[inner] - x[inner]) < 0.01
    assert rms(vel[inner] - v[inner]) < 0.03          # vs 0.28 m/s finite differences
    assert rms(acc[inner] - a[inner]) < 0.15          # vs ~10 m/s^2 second differences
    # the dropout is bridged (predicted) and still close to the truth
    gap = slice(150, 170)
    assert np.all(np.isfinite(vel[gap]))
    assert rms(vel[gap] - v[gap]) < 0.06


def test_smoother_from_velocity_measurements():
    """DVL/gyro mode: acceleration from noisy velocity; position = integral from the start."""
    rng = np.random.default_rng(1)
    t, x, v, a, _ = trajectory(rng, dropouts=False)
    zv = v + rng.normal(0, 0.02, t.size)
    pos, vel, acc = smooth_kinematics(t, zv, measured="velocity", jerk_psd=0.5,
                                      measurement_std=0.02)
    inner = slice(20, -20)
    assert rms(vel[inner] - v[inner]) < 0.015          # below the 0.02 m/s sensor noise
    assert rms(acc[inner] - a[inner]) < 0.12          # vs 0.02 sqrt(2) / 0.05 = 0.57 m/s^2
    assert pos[0] == 0.0
    assert np.max(np.abs(pos - (x - x[0]))) < 0.1


def test_constant_acceleration_is_tracked_exactly():
    """The model is exact for x = x0 + v0 t + a t^2 / 2: with tiny noise a is recovered."""
    t = np.linspace(0.0, 5.0, 101)
    x = 1.0 + 0.2 * t + 0.5 * 0.3 * t**2
    pos, vel, acc = smooth_kinematics(t, x, jerk_psd=1e-6, measurement_std=1e-4)
    np.testing.assert_allclose(acc[10:], 0.3, atol=2e-3)
    np.testing.assert_allclose(vel[10:], 0.2 + 0.3 * t[10:], atol=2e-3)


def test_online_filter_with_dropouts_and_irregular_times():
    rng = np.random.default_rng(2)
    t, x, v, a, z = trajectory(rng)
    kf = KinematicKalmanFilter("position", jerk_psd=0.5, measurement_std=0.01)
    assert not kf.initialised
    est = np.array([kf.step(ti, zi) for ti, zi in zip(t, z)])
    settled = slice(40, None)
    assert rms(est[settled, 1] - v[settled]) < 0.1      # causal: worse than the smoother
    assert rms(est[settled, 2] - a[settled]) < 0.4
    assert kf.initialised and kf.t_s == t[-1]
    assert kf.state_tuple()[1] == est[-1, 1]
    assert kf.covariance[1, 1] > 0 and kf.covariance[2, 2] > 0
    # predictions bridge a missing sample: covariance grows, estimate moves with the model
    p_before = kf.covariance[0, 0]
    kf.step(t[-1] + 0.5, None)
    assert kf.covariance[0, 0] > p_before


def test_online_filter_before_first_measurement_and_equal_times():
    kf = KinematicKalmanFilter("velocity", measurement_std=0.02)
    assert np.all(np.isnan(kf.step(0.0, np.nan)))
    assert np.isnan(kf.state_tuple()[1]) and np.all(np.isnan(kf.covariance))
    pos, vel, acc = kf.step(0.1, 0.3)
    assert (pos, vel, acc) == (0.0, 0.3, 0.0)
    kf.step(0.1, 0.31)              # same time stamp: fused without prediction
    assert kf.t_s == 0.1
    with pytest.raises(EstimationError, match="backwards"):
        kf.step(0.05, 0.3)
    kf.reset()
    assert not kf.initialised


def test_leading_missing_samples_are_nan():
    rng = np.random.default_rng(3)
    t, x, v, a, z = trajectory(rng, dropouts=False)
    z[:5] = np.nan
    pos, vel, acc = smooth_kinematics(t, z, jerk_psd=0.5)
    assert np.all(np.isnan(vel[:5])) and np.all(np.isfinite(vel[5:]))


@pytest.mark.parametrize("call", [
    lambda: smooth_kinematics([0.0, 1.0], [np.nan, np.nan]),
    lambda: smooth_kinematics([0.0, 1.0, 1.0], [1.0, 2.0, 3.0]),
    lambda: smooth_kinematics([0.0, 1.0], [1.0, np.inf]),
    lambda: smooth_kinematics([0.0, 1.0, 2.0], [1.0, 2.0]),
    lambda: smooth_kinematics([0.0, 1.0], [1.0, 2.0], measured="acceleration"),
    lambda: smooth_kinematics([0.0, 1.0], [1.0, 2.0], jerk_psd=0.0),
    lambda: KinematicKalmanFilter(measurement_std=-1.0),
    lambda: KinematicKalmanFilter().step(np.nan, 1.0),
])
def test_errors(call):
    with pytest.raises(EstimationError):
        call()


def test_linear_kalman_steps_as_filterpy_does():
    """The online filters' own predict/update (estimation/kalman.py, kept out of filterpy for its scipy.stats import)
    give filterpy's KalmanFilter state and covariance, step for step: time-varying F and Q, a two-row H with a zero
    row (a missing measurement, as AccelAidedFilter fuses), and R given per update."""
    from filterpy.kalman import KalmanFilter

    from hindrax_onboard.estimation.kalman import LinearKalman

    rng = np.random.default_rng(7)
    ref, own = KalmanFilter(dim_x=3, dim_z=2), LinearKalman(3)
    x0, p0 = rng.normal(size=(3, 1)), np.diag(rng.uniform(0.1, 2.0, 3))
    ref.x, ref.P = x0.copy(), p0.copy()
    own.x, own.P = x0.copy(), p0.copy()
    for k in range(200):
        dt = float(rng.uniform(0.005, 0.1))
        F, Q = transition_matrix(dt), process_noise(dt, float(rng.uniform(0.1, 10.0)))
        ref.predict(F=F, Q=Q)
        own.predict(F, Q)
        H = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
        if k % 3 == 0:
            H[1] = 0.0  # the second sensor missing this step: no information from its row
        R = np.diag(rng.uniform(1e-4, 1e-1, 2))
        z = rng.normal(size=(2, 1))
        ref.update(z, R=R, H=H)
        own.update(z, H=H, R=R)
        np.testing.assert_allclose(own.x, ref.x, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(own.P, ref.P, rtol=1e-12, atol=1e-12)
    assert own.P[2, 2] < p0[2, 2]  # the filter did fuse: the acceleration is known better than at the start


@pytest.mark.parametrize("rows", [[0], [2], [0, 2], [1, 2]])
def test_linear_kalman_update_of_one_or_two_rows_is_the_textbook_one(rows):
    """One or two measurement rows (the closed-form inverse of estimation/kalman.py) give the
    gain of K = P H^T (H P H^T + R)^-1 with ``numpy.linalg.inv`` ([Bar-Shalom2001] §5.2), and a
    singular innovation covariance raises ``LinAlgError`` as ``numpy.linalg.inv`` does."""
    from hindrax_onboard.estimation.kalman import LinearKalman

    rng = np.random.default_rng(len(rows) * 10 + rows[0])
    a = rng.normal(size=(3, 3))
    p, x = a @ a.T + np.eye(3), rng.normal(size=(3, 1))
    H = np.eye(3)[rows]
    R = np.diag(rng.uniform(1e-3, 1.0, len(rows)))
    z = rng.normal(size=(len(rows), 1))
    gain = p @ H.T @ np.linalg.inv(H @ p @ H.T + R)
    own = LinearKalman(3)
    own.x, own.P = x.copy(), p.copy()
    own.update(z, H=H, R=R)
    np.testing.assert_allclose(own.x, x + gain @ (z - H @ x), rtol=1e-12, atol=1e-12)
    i_kh = np.eye(3) - gain @ H
    np.testing.assert_allclose(own.P, i_kh @ p @ i_kh.T + gain @ R @ gain.T, rtol=1e-12, atol=1e-12)
    own.P = np.zeros((3, 3))
    with pytest.raises(np.linalg.LinAlgError):
        own.update(z, H=H, R=np.zeros_like(R))
