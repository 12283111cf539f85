"""estimate_time_gap: the env's monitor streamed over measured records of one follower or many."""

import numpy as np
import pytest

from timegap_env.config import MonitorConfig
from timegap_env.leaders import default_openacc_dir, openacc_paths, read_openacc
from timegap_env.monitoring.estimate import estimate_time_gap
from timegap_env.monitoring.monitor import TimeGapMonitor


def records(n_ticks: int, taus: list[float], seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Speeds [m/s] wandering around 15 m/s and spacings s0 + tau v + noise [m], s0 = 5 m, one column a follower."""
    rng = np.random.default_rng(seed)
    speed = 15.0 + np.cumsum(rng.normal(0.0, 0.05, (n_ticks, len(taus))), axis=0)
    return speed, 5.0 + np.array(taus) * speed + rng.normal(0.0, 0.1, speed.shape)


def test_the_estimate_finds_each_followers_time_gap():
    speed, spacing = records(600, [1.0, 1.6, 2.4])
    estimate = estimate_time_gap(speed, spacing)
    assert estimate.mean.shape == estimate.std.shape == estimate.used.shape == (600, 3)
    np.testing.assert_allclose(estimate.mean[-100:].mean(axis=0), [1.0, 1.6, 2.4], atol=0.01)
    assert np.all(estimate.std > 0) and estimate.used.all()


def test_one_follower_is_a_column_of_many_and_the_envs_monitor():
    speed, spacing = records(300, [1.2, 2.0])
    many = estimate_time_gap(speed, spacing, setting=1.4)
    one = estimate_time_gap(speed[:, 1], spacing[:, 1], setting=1.4)
    assert one.mean.shape == (300,)
    np.testing.assert_array_equal(one.mean, many.mean[:, 1])
    np.testing.assert_array_equal(one.std, many.std[:, 1])
    monitor = TimeGapMonitor(1, 2, 1.4, MonitorConfig())
    for k in range(300):
        monitor.update(speed[k][None], spacing[k][None])
    np.testing.assert_array_equal(many.mean[-1], monitor.tau_mean[0])
    np.testing.assert_array_equal(many.std[-1], monitor.tau_std[0])


def test_gaps_are_skipped_and_nothing_nan_comes_out():
    speed, spacing = records(400, [1.5])
    spacing[100:160, 0] = np.nan  # a 6 s gap in the record
    speed[200, 0] = np.nan
    estimate = estimate_time_gap(speed, spacing)
    assert np.isfinite(estimate.mean).all() and np.isfinite(estimate.std).all()
    assert not estimate.used[100:160].any() and not estimate.used[200, 0] and estimate.used.sum() == 400 - 61
    assert estimate.std[159, 0] > 10 * estimate.std[99, 0]  # after 6 s without data the window holds only the prior


@pytest.mark.parametrize(
    "speed, spacing, message",
    [
        (np.ones(5), np.ones(6), r"shapes \(5,\), \(6,\)"),
        (np.ones((2, 2, 2)), np.ones((2, 2, 2)), r"shapes \(2, 2, 2\)"),
        (np.ones(0), np.ones(0), r"shapes \(0,\), \(0,\)"),
    ],
)
def test_bad_records_are_named(speed, spacing, message):
    with pytest.raises(ValueError, match=message):
        estimate_time_gap(speed, spacing)


def test_real_acc_cars_with_gaps_give_finite_estimates():
    directory = default_openacc_dir()
    if not directory.exists():
        pytest.skip(f"OpenACC data absent at {directory} (set $TIMEGAP_OPENACC_PATH)")
    for path in openacc_paths(directory)[:6]:
        run = read_openacc(path)
        estimate = estimate_time_gap(run.speed[:, 1:], run.spacing)
        assert np.isfinite(estimate.mean).all() and np.isfinite(estimate.std).all(), run.name
