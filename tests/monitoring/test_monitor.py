"""The streaming monitor: the Proposition over a sliding window, forgetting, invalid data, changes of setting."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from timegap_env.config import MONITOR_PRESETS, MonitorConfig, PlatoonConfig
from timegap_env.monitoring.monitor import TimeGapMonitor
from timegap_env.monitoring.posterior import posterior

PAPER_PRIOR_COV = np.array([[1e-4, -1e-5], [-1e-5, 0.125]])


def synthetic(rng: np.random.Generator, shape: tuple[int, ...], tau: float = 1.6, s0: float = 5.0):
    """Speeds [m/s] in the paper's band and spacings S = s0 + tau V + noise [m]."""
    speed = rng.uniform(8.94, 35.76, shape)
    return speed, s0 + tau * speed + rng.normal(0.0, 0.1, shape)


def corrupt(rng: np.random.Generator, speed: np.ndarray, spacing: np.ndarray, rate: float = 0.15):
    """Replace a fraction of the measurements with every kind of invalid value."""
    speed, spacing = speed.copy(), spacing.copy()
    bad_values = np.array([np.nan, np.inf, -np.inf, -1.0, 1e9])
    for array in (speed, spacing):
        hit = rng.random(array.shape) < rate / 2
        array[hit] = rng.choice(bad_values, hit.sum())
    return speed, spacing


def is_valid(speed, spacing, config: MonitorConfig):
    return (speed >= 0) & (speed <= config.max_speed) & (spacing >= 0) & (spacing <= config.max_spacing)


def reference_posterior(config: MonitorConfig, tau_prior, speeds, spacings):
    """posterior() on each vehicle's valid data of the last window, weighted by forgetting^age."""
    n_ticks = len(speeds)
    start = max(0, n_ticks - (config.window_ticks or n_ticks))
    age = np.arange(n_ticks - start)[::-1]
    n_envs, n_vehicles = speeds.shape[1:]
    means, covs = np.empty((n_envs, n_vehicles, 2)), np.empty((n_envs, n_vehicles, 2, 2))
    for e in range(n_envs):
        for i in range(n_vehicles):
            V, S = speeds[start:, e, i], spacings[start:, e, i]
            ok = is_valid(V, S, config)
            means[e, i], covs[e, i] = posterior(
                V[ok],
                S[ok],
                [config.prior_standstill_spacing, tau_prior],
                config.prior_cov,
                config.noise_variance,
                weights=config.forgetting ** age[ok],
            )
    return means, covs


def assert_spd(cov: np.ndarray) -> None:
    assert np.all(np.isfinite(cov))
    np.testing.assert_array_equal(cov, np.swapaxes(cov, -1, -2))
    np.linalg.cholesky(cov)  # raises unless positive definite


# ---- the streaming monitor against posterior() -------------------------------------------------


@pytest.mark.parametrize("window", [0.5, 1.0, None])
@pytest.mark.parametrize("forgetting", [1.0, 0.9])
def test_monitor_matches_posterior_of_the_window(window, forgetting):
    config = MonitorConfig(window=window, forgetting=forgetting)
    rng = np.random.default_rng(1)
    n_ticks, shape = 83, (3, 2)  # the 5-tick window wraps 16 times
    speeds, spacings = corrupt(rng, *synthetic(rng, (n_ticks,) + shape))
    monitor = TimeGapMonitor(*shape, setting=1.6, config=config)
    for t in range(n_ticks):
        used = monitor.update(speeds[t], spacings[t])
        np.testing.assert_array_equal(used, is_valid(speeds[t], spacings[t], config))
        if t % 7 == 0 or t == n_ticks - 1:
            mean, cov = reference_posterior(config, 1.6, speeds[: t + 1], spacings[: t + 1])
            np.testing.assert_allclose(monitor.mean, mean, rtol=1e-9)
            np.testing.assert_allclose(monitor.cov, cov, rtol=1e-8, atol=1e-16)


def long_run(n_ticks: int, config: MonitorConfig, check_every: int) -> None:
    """Stream n_ticks of (2 x 3) data, check SPD along the way and the final posterior exactly."""
    rng = np.random.default_rng(2)
    shape, chunk = (2, 3), 1000
    monitor = TimeGapMonitor(*shape, setting=1.6, config=config)
    for start in range(0, n_ticks, chunk):
        speeds, spacings = corrupt(rng, *synthetic(rng, (chunk,) + shape), rate=0.05)
        for t in range(min(chunk, n_ticks - start)):
            monitor.update(speeds[t], spacings[t])
            if (start + t) % check_every == 0:
                assert_spd(monitor.cov)
                assert np.all(np.isfinite(monitor.mean))
    last = min(chunk, n_ticks - start)
    mean, cov = reference_posterior(config, 1.6, speeds[:last], spacings[:last])
    assert_spd(monitor.cov)
    np.testing.assert_allclose(monitor.mean, mean, rtol=1e-9)
    np.testing.assert_allclose(monitor.cov, cov, rtol=1e-8, atol=1e-16)


@pytest.mark.parametrize("forgetting", [1.0, 0.99])
def test_long_run_stays_exact_and_positive_definite(forgetting):
    long_run(10_000, MonitorConfig(window=2.0, forgetting=forgetting), check_every=97)


@pytest.mark.slow
@pytest.mark.parametrize("window", [10.0, 60.0])
def test_million_updates_stay_exact_and_positive_definite(window):
    long_run(1_000_000, MonitorConfig(window=window), check_every=10_007)


def test_estimate_follows_a_change_of_the_actual_time_gap():
    rng = np.random.default_rng(3)
    monitor = TimeGapMonitor(1, 1, setting=1.6, config=MonitorConfig(window=5.0))
    for tau in (1.6, 1.9):
        for _ in range(50):
            monitor.update(*synthetic(rng, (1, 1), tau=tau))
        assert monitor.tau_mean[0, 0] == pytest.approx(tau, abs=0.01)


# ---- invalid measurements -------------------------------------------------------------------


def test_invalid_measurements_are_skipped_per_vehicle():
    config = MonitorConfig(window=None)
    rng = np.random.default_rng(4)
    monitor = TimeGapMonitor(1, 6, setting=1.6, config=config)
    for _ in range(20):
        monitor.update(*synthetic(rng, (1, 6)))
    mean, cov = monitor.mean.copy(), monitor.cov.copy()
    speed, spacing = synthetic(rng, (1, 6))
    speed[0, :4] = [np.nan, np.inf, -1e3, 1e3]  # dropout, inf, implausible either way
    spacing[0, 4] = -1.0
    used = monitor.update(speed, spacing)
    np.testing.assert_array_equal(used, [[False] * 5 + [True]])
    np.testing.assert_array_equal(monitor.skipped, [[1, 1, 1, 1, 1, 0]])
    np.testing.assert_array_equal(monitor.mean[0, :5], mean[0, :5])  # carried over, bit for bit
    np.testing.assert_array_equal(monitor.cov[0, :5], cov[0, :5])
    assert not np.array_equal(monitor.mean[0, 5], mean[0, 5])
    assert np.all(np.isfinite(monitor.mean)) and np.all(np.isfinite(monitor.cov))


def test_measurements_below_the_minimum_speed_are_left_out_but_not_skipped():
    """At a crawl (s - s0) / v says nothing of tau; a noisy negative reading about a standstill is no fault."""
    monitor = TimeGapMonitor(1, 4, setting=1.6, config=MonitorConfig(window=2.0))
    slow = np.array([[0.0, -0.3, 0.99 * MonitorConfig.min_speed, MonitorConfig.min_speed]])
    for _ in range(40):
        used = monitor.update(slow, np.full((1, 4), 2.5))
    np.testing.assert_array_equal(used, [[False, False, False, True]])
    np.testing.assert_array_equal(monitor.skipped, [[0, 0, 0, 0]])
    np.testing.assert_array_equal(monitor.tau_mean[0, :3], [1.6, 1.6, 1.6])  # back at the prior: the setting


def test_a_long_dropout_empties_the_window_back_to_the_prior():
    config = MonitorConfig(window=1.0)
    rng = np.random.default_rng(5)
    monitor = TimeGapMonitor(1, 1, setting=1.6, config=config)
    for _ in range(15):
        monitor.update(*synthetic(rng, (1, 1), tau=1.9))
    for tick in range(config.window_ticks):
        monitor.update([[np.nan]], [[np.nan]])
        assert monitor.n_measurements[0, 0] == config.window_ticks - 1 - tick  # a skip still takes a slot
    np.testing.assert_allclose(monitor.mean[0, 0], [5.0, 1.6], rtol=1e-12)
    np.testing.assert_allclose(monitor.cov[0, 0], config.prior_cov, rtol=1e-9)
    assert monitor.skipped[0, 0] == config.window_ticks


def test_update_rejects_wrong_shapes():
    monitor = TimeGapMonitor(2, 3, setting=1.6)
    with pytest.raises(ValueError, match=r"speed has shape \(3, 2\)"):
        monitor.update(np.zeros((3, 2)), np.zeros((2, 3)))
    with pytest.raises(ValueError, match="spacing"):
        monitor.update(np.zeros((2, 3)), "far")


@pytest.mark.parametrize(
    ("args", "message"),
    [((0, 3, 1.6), "n_envs = 0"), ((2, 2.5, 1.6), "n_vehicles = 2.5"), ((2, 3, -1.0), r"setting\[0, 0\] = -1.0")],
)
def test_monitor_constructor_rejects_bad_arguments(args, message):
    with pytest.raises(ValueError, match=message):
        TimeGapMonitor(*args)


# ---- recenter and reset ---------------------------------------------------------------------


def test_recenter_moves_the_prior_and_clears_the_window():
    config = MonitorConfig(window=2.0)
    rng = np.random.default_rng(6)
    monitor = TimeGapMonitor(2, 2, setting=1.6, config=config)
    for _ in range(30):
        monitor.update(*synthetic(rng, (2, 2), tau=1.8))
    before = monitor.mean.copy()
    switched = np.array([[True, False], [False, False]])
    monitor.recenter(1.0, switched)
    np.testing.assert_allclose(monitor.mean[0, 0], [5.0, 1.0], rtol=1e-12)
    np.testing.assert_allclose(monitor.cov[0, 0], config.prior_cov, rtol=1e-9)
    np.testing.assert_array_equal(monitor.mean[~switched], before[~switched])

    # After the switch the estimate uses the new prior and only data measured since.
    speeds, spacings = synthetic(rng, (7, 2, 2), tau=1.1)
    for t in range(7):
        monitor.update(speeds[t], spacings[t])
    mean, cov = reference_posterior(config, 1.0, speeds, spacings)
    np.testing.assert_allclose(monitor.mean[0, 0], mean[0, 0], rtol=1e-9)
    np.testing.assert_allclose(monitor.cov[0, 0], cov[0, 0], rtol=1e-8)


@settings(max_examples=40, deadline=None)
@given(window_ticks=st.integers(2, 12), forgetting=st.sampled_from([1.0, 0.97]), seed=st.integers(0, 2**32 - 1),
       blocks=st.lists(st.tuples(st.integers(1, 30), st.booleans()), min_size=1, max_size=12))
def test_a_marked_clearing_gives_the_bits_of_a_written_one(window_ticks, forgetting, seed, blocks):
    """A change of setting marks the ring as cleared (``cleared_below``) instead of writing zeros into it: every
    tick's estimate is the one a monitor whose ring is zeroed at each change gives, bit for bit, whatever slot of the
    block the change comes at, changes in the same block, and resets."""
    config = MonitorConfig(window=window_ticks * 0.1, forgetting=forgetting)
    marked, written = (TimeGapMonitor(2, 3, setting=1.6, config=config) for _ in range(2))
    rng = np.random.default_rng(seed)
    for n_ticks, reset in blocks:
        speeds, spacings = corrupt(rng, *synthetic(rng, (n_ticks, 2, 3), tau=rng.uniform(0.8, 2.0)))
        for monitor in (marked, written):
            ticks = monitor.update_block(speeds, spacings)
            if monitor is marked:
                expected = ticks
        np.testing.assert_array_equal(ticks.tau_mean, expected.tau_mean)
        np.testing.assert_array_equal(ticks.tau_var, expected.tau_var)
        switched, setting = rng.random((2, 3)) < 0.5, rng.uniform(0.8, 2.0, (2, 3))
        for monitor in (marked, written):
            if reset:
                monitor.reset(switched[:, 0], setting)
            else:
                monitor.recenter(setting, switched)
        cleared = np.broadcast_to(switched[:, :1], (2, 3)) if reset else switched
        written.parts.memory.slots[cleared] = 0.0  # what a clearing wrote before the mark, and no mark:
        written.parts.memory.cleared_below[cleared] = -1  # the ring read as it is
        np.testing.assert_array_equal(marked.mean, written.mean)
        np.testing.assert_array_equal(marked.cov, written.cov)


def test_reset_restarts_envs_and_their_skip_counters():
    monitor = TimeGapMonitor(2, 2, setting=1.6)
    rng = np.random.default_rng(7)
    for _ in range(10):
        monitor.update(*corrupt(rng, *synthetic(rng, (2, 2)), rate=0.5))
    skipped = monitor.skipped.copy()
    monitor.reset(np.array([False, True]), setting=[[1.2, 1.4]])
    np.testing.assert_array_equal(monitor.skipped[0], skipped[0])
    np.testing.assert_array_equal(monitor.skipped[1], 0)
    np.testing.assert_allclose(monitor.tau_mean[1], [1.2, 1.4])
    assert np.all(monitor.n_measurements[1] == 0) and np.all(monitor.n_measurements[0] > 0)


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda m: m.reset(np.array([True]), 1.6), r"mask has dtype bool and shape \(1,\)"),
        (lambda m: m.reset(np.array([1, 0]), 1.6), "mask has dtype int"),
        (lambda m: m.recenter(1.0, np.ones((3, 3), dtype=bool)), r"mask has shape \(3, 3\)"),
        (lambda m: m.recenter(np.nan), r"setting\[0, 0\] = nan"),
        (lambda m: m.recenter([1.0, 1.0, 1.0]), r"setting has shape \(3,\)"),
        (lambda m: m.prob_outside(1.85, 1.35), "need lcl <= ucl"),
    ],
)
def test_changes_of_setting_reject_bad_arguments(call, message):
    with pytest.raises(ValueError, match=message):
        call(TimeGapMonitor(2, 2, setting=1.6))


# ---- read-outs ------------------------------------------------------------------------------


def test_prob_outside_matches_the_normal_marginal():
    rng = np.random.default_rng(8)
    monitor = TimeGapMonitor(3, 4, setting=1.6, config=MonitorConfig(window=0.3))
    monitor.update(*synthetic(rng, (3, 4), tau=1.7))
    lcl, ucl = 1.35, rng.uniform(1.6, 1.9, (3, 4))
    p = monitor.prob_outside(lcl, ucl)
    for (e, i), value in np.ndenumerate(p):
        m, s = monitor.tau_mean[e, i], monitor.tau_std[e, i]
        scale = s * math.sqrt(2)
        expected = 0.5 * math.erfc((m - lcl) / scale) + 0.5 * math.erfc((ucl[e, i] - m) / scale)
        assert value == pytest.approx(expected, rel=1e-12, abs=1e-15)
    np.testing.assert_array_equal(monitor.prob_outside(-np.inf, np.inf), 0.0)
    np.testing.assert_allclose(monitor.prob_outside(monitor.tau_mean, monitor.tau_mean), 1.0, rtol=1e-6)


def test_sufficient_statistics_are_exposed():
    monitor = TimeGapMonitor(1, 1, setting=1.6, config=MonitorConfig(window=None))
    monitor.update([[10.0]], [[21.0]])
    monitor.update([[20.0]], [[37.0]])
    np.testing.assert_allclose(monitor.ztz[0, 0], [[2, 30], [30, 500]])
    np.testing.assert_allclose(monitor.zts[0, 0], [58, 950])


# ---- presets --------------------------------------------------------------------------------


def test_presets():
    paper, default = MONITOR_PRESETS["paper"], MONITOR_PRESETS["default"]
    assert paper.noise_variance == 0.01
    assert paper.prior_standstill_spacing == 1.0
    np.testing.assert_array_equal(paper.prior_cov, PAPER_PRIOR_COV)
    assert default.prior_standstill_spacing == PlatoonConfig().standstill_spacing == 5.0
    monitor = TimeGapMonitor(1, 2, setting=1.6, config=paper)
    np.testing.assert_allclose(monitor.mean[0], [[1.0, 1.6], [1.0, 1.6]], rtol=1e-12)


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"window": 0.25}, "window = 0.25"),
        ({"window": 0.0}, "window"),
        ({"forgetting": 0.0}, "forgetting"),
        ({"max_speed": -1.0}, "max_speed"),
        ({"estimator": "kalman"}, "estimator = 'kalman'"),
    ],
)
def test_monitor_config_rejects_bad_values(overrides, message):
    with pytest.raises(ValueError, match=message):
        MonitorConfig().with_overrides(overrides)


# ---- properties -----------------------------------------------------------------------------

any_float = st.floats(allow_nan=True, allow_infinity=True)


@settings(max_examples=60, deadline=None)
@given(
    ticks=st.lists(st.tuples(*[any_float] * 8), min_size=1, max_size=12),
    window=st.sampled_from([None, 0.1, 0.3]),
    forgetting=st.floats(0.5, 1.0),
)
def test_any_input_keeps_the_posterior_finite_and_positive_definite(ticks, window, forgetting):
    monitor = TimeGapMonitor(2, 2, setting=1.6, config=MonitorConfig(window=window, forgetting=forgetting))
    for values in ticks:
        monitor.update(np.reshape(values[:4], (2, 2)), np.reshape(values[4:], (2, 2)))
        assert_spd(monitor.cov)
        assert np.all(np.isfinite(monitor.mean))
        assert np.all(np.isfinite(monitor.prob_outside(1.35, 1.85)))


def test_raw_gap_reports_each_ticks_gap_and_the_prior_when_a_tick_is_left_out():
    config = MonitorConfig(estimator="raw_gap", min_speed=1.0)
    monitor = TimeGapMonitor(1, 3, 1.2, config)
    s0 = config.prior_standstill_spacing
    speed = np.array([[[20.0, 0.5, 25.0]], [[10.0, 0.5, np.nan]]])  # follower 1 below min_speed, 2 NaN at tick 2
    spacing = s0 + np.array([[[1.5, 0.9, 1.1]], [[0.8, 0.9, 1.1]]]) * np.nan_to_num(speed)
    ticks = monitor.update_block(speed, spacing)
    prior = TimeGapMonitor(1, 3, 1.2, MonitorConfig()).moments  # the prior, the monitor fresh from reset
    np.testing.assert_allclose(ticks.tau_mean[:, 0, 0], [1.5, 0.8])  # (s - s0) / v, tick by tick, nothing carried
    np.testing.assert_allclose(ticks.tau_var[:, 0, 0], config.noise_variance / np.array([20.0, 10.0]) ** 2)
    assert ticks.tau_mean[0, 0, 1] == ticks.tau_mean[1, 0, 1] == 1.2  # too slow: the setting
    assert ticks.tau_var[1, 0, 1] == prior.var_tau[0, 1]
    assert ticks.tau_mean[1, 0, 2] == 1.2 and monitor.skipped[0, 2] == 1  # NaN: skipped, the setting
    np.testing.assert_allclose(monitor.tau_mean[0], [0.8, 1.2, 1.2])
    assert np.all(np.linalg.eigvalsh(monitor.cov) > 0)


def test_raw_gap_differs_from_the_posterior_only_in_what_it_reports():
    rng = np.random.default_rng(3)
    speed = rng.uniform(15.0, 30.0, (50, 2, 2))
    spacing = 2.0 + rng.normal(1.4, 0.05, speed.shape) * speed
    bayes, raw = (TimeGapMonitor(2, 2, 1.4, MonitorConfig(estimator=kind)) for kind in ("bayes", "raw_gap"))
    bayes.update_block(speed, spacing)
    raw.update_block(speed, spacing)
    np.testing.assert_array_equal(raw.n_measurements, bayes.n_measurements)  # the same window, kept
    np.testing.assert_array_equal(raw.zts, bayes.zts)
    assert not np.allclose(raw.tau_mean, bayes.tau_mean)


def test_a_raw_gap_recentre_resets_only_the_followers_it_names():
    monitor = TimeGapMonitor(1, 2, 1.2, MonitorConfig(estimator="raw_gap"))
    s0 = MonitorConfig().prior_standstill_spacing
    monitor.update_block(np.full((3, 1, 2), 20.0), s0 + np.full((3, 1, 2), 1.5 * 20.0))
    monitor.recenter(1.6, np.array([[True, False]]))
    np.testing.assert_allclose(monitor.tau_mean[0], [1.6, 1.5])  # the other keeps its last tick's gap
