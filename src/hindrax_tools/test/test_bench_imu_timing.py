"""The stack benchmark's IMU timing (hindrax_tools.benchmarks.stack.imu_timing and its rows):
the rate, the largest
gap and the sample age of the IMU as the recorder receives it in the launch layout."""
import pytest

from hindrax_tools.benchmarks import stack

MS = 1_000_000


def _samples(count: int, period_ms: float, age_ms: float, missed: range = range(0)) -> list:
    """(reception, stamp) ns of ``count`` polls every ``period_ms``, each received ``age_ms`` after its stamp;
    the polls ``missed`` never came (the executor was busy)."""
    return [(int((k * period_ms + age_ms) * MS), int(k * period_ms * MS)) for k in range(count) if k not in missed]


def test_a_steady_imu_gives_its_rate_its_period_as_largest_gap_and_its_age():
    timing = stack.imu_timing(_samples(101, 20.0, 3.0))
    assert timing["rate_hz"] == pytest.approx(50.0)
    assert timing["gap_max_s"] == pytest.approx(0.020)
    assert timing["stamp_gap_max_s"] == pytest.approx(0.020)
    assert timing["age_p50_ms"] == pytest.approx(3.0) and timing["age_max_ms"] == pytest.approx(3.0)


def test_missed_polls_show_as_a_gap_of_stamps_and_receptions():
    # polls 50-56 never came: 160 ms between polls 49 and 57; 94 messages, 93 intervals over 2 s
    timing = stack.imu_timing(_samples(101, 20.0, 3.0, missed=range(50, 57)))
    assert timing["gap_max_s"] == pytest.approx(0.160)
    assert timing["stamp_gap_max_s"] == pytest.approx(0.160)
    assert timing["rate_hz"] == pytest.approx(46.5)


def test_a_slow_delivery_raises_the_age_not_the_stamp_gap():
    samples = _samples(200, 20.0, 2.0)
    samples[100] = (samples[100][0] + 90 * MS, samples[100][1])  # this one received 90 ms late (92 ms old)
    samples[101] = (max(samples[101][0], samples[100][0]), samples[101][1])  # the next waited behind it
    timing = stack.imu_timing(samples)
    assert timing["age_max_ms"] == pytest.approx(92.0)
    assert timing["age_p50_ms"] == pytest.approx(2.0)
    assert timing["stamp_gap_max_s"] == pytest.approx(0.020)
    assert timing["gap_max_s"] == pytest.approx(0.110)


def test_rows_report_the_median_rate_and_the_worst_gap_of_the_windows_and_fewer_than_two_samples_refuse():
    wins = [{"imu": stack.imu_timing(_samples(101, 20.0, 3.0))},
            {"imu": stack.imu_timing(_samples(101, 20.0, 3.0, missed=range(10, 17)))},
            {"imu": stack.imu_timing(_samples(101, 20.0, 5.0))}]
    rows = {r["name"]: r for r in stack._imu_rows(wins)}
    assert rows["launch_running_imu_rate_hz"]["value"] == pytest.approx(50.0)
    assert rows["launch_running_imu_gap_max_s"]["value"] == pytest.approx(0.160)
    assert rows["launch_running_imu_age_p99_ms"]["value"] == pytest.approx(3.0)
    assert stack._imu_rows([{"imu": None}]) == []
    with pytest.raises(ValueError, match="1 sample"):
        stack.imu_timing(_samples(1, 20.0, 3.0))
