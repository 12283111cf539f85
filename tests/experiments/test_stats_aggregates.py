"""The power of a paired comparison and the run-and-task aggregates of stats.py (Agarwal et al. 2021): hand-computed
values, the stratification of the bootstrap, brute-force cross-checks of the vectorised paths, determinism."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
from scipy.stats import trim_mean

from timegap_env.experiments.stats import (
    BOOTSTRAP_RESAMPLES, BOOTSTRAP_SEED, POWER_Z, WILSON_Z, episodes_for, iqm, paired_mde, performance_profile,
    performance_profile_interval, probability_of_improvement, probability_of_improvement_interval,
    stratified_bootstrap,
)


def standardised(n: int, seed: int = 3) -> np.ndarray:
    """n differences with sample standard deviation (ddof=1) exactly 1 (up to rounding)."""
    values = np.random.default_rng(seed).normal(size=n)
    values -= values.mean()
    return values / values.std(ddof=1)


def runs_by_tasks(n_runs: int = 5, n_tasks: int = 10, seed: int = 1) -> np.ndarray:
    return np.random.default_rng(seed).normal(size=(n_runs, n_tasks)) + np.arange(n_tasks)


# --- power ---------------------------------------------------------------------------------------------------------

def test_the_power_quantile_is_the_normal_quantile_of_0_8():
    from scipy.stats import norm

    assert POWER_Z == pytest.approx(norm.ppf(0.8), abs=1e-15)


def test_paired_mde_by_hand():
    # sd(1..5, ddof=1) = sqrt(2.5), n = 5: sd / sqrt(n) = sqrt(0.5)
    assert paired_mde(np.arange(1.0, 6.0)) == pytest.approx((WILSON_Z + 0.8416212335729143) * math.sqrt(0.5))
    # power 0.5: z_power = 0, only the confidence quantile remains
    assert paired_mde(np.arange(1.0, 6.0), power=0.5) == pytest.approx(WILSON_Z * math.sqrt(0.5))
    assert paired_mde(np.arange(1.0, 6.0), power=0.9) > paired_mde(np.arange(1.0, 6.0))


def test_paired_mde_halves_with_four_times_the_episodes():
    assert paired_mde(standardised(25)) / paired_mde(standardised(100)) == pytest.approx(2.0, rel=1e-12)


@pytest.mark.parametrize("n", [2, 3, 10, 37, 100, 1000])
def test_episodes_for_the_mde_of_n_episodes_is_n(n):
    differences = standardised(n)
    mde = paired_mde(differences)
    assert episodes_for(float(differences.std(ddof=1)), mde) == n
    assert episodes_for(3.0, 3.0 * mde) == n  # the units cancel


def test_episodes_for_by_hand_and_its_floor():
    z = WILSON_Z + 0.8416212335729143
    assert episodes_for(1.0, z / 10) == 100  # exactly 100 up to rounding, not 101
    assert episodes_for(1.0, 0.99 * paired_mde(standardised(10))) == 11  # a hair smaller effect: one more episode
    assert episodes_for(2.0, z) == 4
    assert episodes_for(1.0, 100.0) == 2
    assert episodes_for(0.0, 1.0) == 2


def test_the_power_functions_refuse_what_they_cannot_compute():
    with pytest.raises(ValueError):
        paired_mde(np.array([1.0]))
    with pytest.raises(ValueError):
        episodes_for(1.0, 0.0)
    with pytest.raises(ValueError):
        paired_mde(np.arange(5.0), power=1.0)


# --- IQM -----------------------------------------------------------------------------------------------------------

def test_iqm_by_hand():
    assert iqm(np.arange(1.0, 9.0)) == 4.5  # mean of 3, 4, 5, 6
    assert iqm(np.arange(1.0, 9.0).reshape(2, 4)) == 4.5  # all values, flattened
    assert iqm(np.array([[1.0, 2.0, 3.0, 1e9]])) == 2.5  # the outlier is cut


@pytest.mark.parametrize("n", range(1, 23))
def test_iqm_is_scipy_s_quarter_trimmed_mean(n):
    values = np.random.default_rng(n).normal(size=n)
    assert iqm(values) == pytest.approx(trim_mean(values, 0.25, axis=None), rel=1e-12, abs=1e-15)


# --- stratified bootstrap ------------------------------------------------------------------------------------------

def test_the_stratified_bootstrap_keeps_each_task_s_runs_in_its_column():
    scores = runs_by_tasks(5, 4)
    scores[:, 0] -= 100  # column 0 far below the others: a pooled resample would reach above its max

    def column_0_max(sample: np.ndarray) -> float:
        return float(sample[:, 0].max())

    point, low, high = stratified_bootstrap(scores, column_0_max, resamples=500)
    assert point == scores[:, 0].max()
    assert high <= scores[:, 0].max()
    assert low >= scores[:, 0].min()

    def every_column_from_its_own(sample: np.ndarray) -> float:  # each resampled column is a multiset of its own
        return float(all(np.isin(sample[:, task], scores[:, task]).all() for task in range(scores.shape[1])))

    assert stratified_bootstrap(scores, every_column_from_its_own, resamples=500) == (1.0, 1.0, 1.0)


def test_the_stratified_bootstrap_resamples_with_replacement():
    scores = runs_by_tasks(5, 3)

    def distinct_in_column_0(sample: np.ndarray) -> float:
        return float(np.unique(sample[:, 0]).size)

    _, low, high = stratified_bootstrap(scores, distinct_in_column_0, resamples=1000)
    assert low < 5  # with replacement: most resamples repeat a run
    assert high <= 5


def test_the_stratified_bootstrap_applies_the_statistic_once_per_resample_and_to_the_original():
    calls = []

    def mean(sample: np.ndarray) -> float:
        calls.append(sample.shape)
        return float(sample.mean())

    stratified_bootstrap(runs_by_tasks(4, 3), mean, resamples=123)
    assert len(calls) == 124 and set(calls) == {(4, 3)}


def test_the_iqm_interval_contains_its_point_and_its_fast_path_is_the_slow_one():
    scores = runs_by_tasks()
    start = time.perf_counter()
    fast = stratified_bootstrap(scores, iqm)
    assert time.perf_counter() - start < 1.0  # 10,000 resamples of 5 runs x 10 tasks (takes about 0.01 s)
    slow = stratified_bootstrap(scores, lambda sample: iqm(sample))  # not the registered function: one by one
    np.testing.assert_allclose(fast, slow, rtol=1e-12)
    point, low, high = fast
    assert point == iqm(scores)
    assert low < point < high


def test_a_single_run_per_task_has_no_spread():
    scores = runs_by_tasks(1, 6)
    assert stratified_bootstrap(scores, iqm) == (iqm(scores),) * 3


def test_the_stratified_bootstrap_is_deterministic():
    scores = runs_by_tasks()
    first = stratified_bootstrap(scores, iqm)
    np.random.seed(12345)  # the global generator does not matter
    np.random.default_rng().normal(size=100)
    assert stratified_bootstrap(scores, iqm) == first
    assert stratified_bootstrap(scores, lambda s: float(np.median(s))) == stratified_bootstrap(
        scores, lambda s: float(np.median(s)))


def test_the_stratified_bootstrap_refuses_a_flat_array():
    with pytest.raises(ValueError):
        stratified_bootstrap(np.arange(5.0), iqm)


# --- probability of improvement -------------------------------------------------------------------------------------

def test_probability_of_improvement_by_hand():
    x, y = np.array([[1.0, 10.0], [3.0, 11.0]]), np.array([[2.0, 0.0], [3.0, 1.0]])
    # task 0: 1 > 2 no, 1 > 3 no, 3 > 2 yes, 3 = 3 half: 1.5 / 4; task 1: all four pairs: 1
    assert probability_of_improvement(x, y) == pytest.approx((0.375 + 1.0) / 2)
    assert probability_of_improvement(y, x) == pytest.approx((0.625 + 0.0) / 2)


def test_probability_of_improvement_of_dominance_and_identity():
    y = runs_by_tasks(4, 5)
    x = y + 100  # strictly dominates on every pair
    assert probability_of_improvement(x, y) == 1.0
    assert probability_of_improvement(y, x) == 0.0
    assert probability_of_improvement(y, y) == 0.5
    assert probability_of_improvement_interval(x, y) == (1.0, 1.0, 1.0)


def test_probability_of_improvement_is_complementary_with_ties():
    rng = np.random.default_rng(7)
    x, y = rng.integers(0, 4, size=(5, 6)).astype(float), rng.integers(0, 4, size=(3, 6)).astype(float)
    assert probability_of_improvement(x, y) + probability_of_improvement(y, x) == pytest.approx(1.0, abs=1e-15)


def test_a_deterministic_policy_is_one_run():
    deterministic = np.arange(4.0)[None, :]  # (1 run, 4 tasks)
    seeds = np.array([[0.5, 0.5, 2.5, 3.5], [-1.0, 1.5, 1.5, 2.5]])
    # per task: 0 beats neither; 1 beats both; 2 beats one; 3 beats one
    assert probability_of_improvement(deterministic, seeds) == pytest.approx((0 + 1 + 0.5 + 0.5) / 4)
    point, low, high = probability_of_improvement_interval(deterministic, seeds)
    assert low <= point <= high and low < high
    assert probability_of_improvement_interval(deterministic, deterministic - 1) == (1.0, 1.0, 1.0)


def test_the_probability_of_improvement_interval_is_a_brute_force_stratified_bootstrap():
    x, y = runs_by_tasks(5, 4, seed=1), runs_by_tasks(3, 4, seed=2)
    rng = np.random.default_rng(BOOTSTRAP_SEED)  # x's runs drawn, then y's, each within each task
    x_index = rng.integers(0, 5, size=(BOOTSTRAP_RESAMPLES, 5, 4))
    y_index = rng.integers(0, 3, size=(BOOTSTRAP_RESAMPLES, 3, 4))
    xs, ys = x[x_index, np.arange(4)][:, :, None, :], y[y_index, np.arange(4)][:, None, :, :]
    values = ((xs > ys) + 0.5 * (xs == ys)).mean(axis=(1, 2)).mean(axis=1)
    point, low, high = probability_of_improvement_interval(x, y)
    assert point == probability_of_improvement(x, y)
    np.testing.assert_allclose((low, high), np.quantile(values, [0.025, 0.975]), rtol=1e-12)
    assert low < point < high
    assert probability_of_improvement_interval(x, y) == (point, low, high)  # deterministic


def test_probability_of_improvement_needs_the_same_tasks():
    with pytest.raises(ValueError):
        probability_of_improvement(np.zeros((2, 3)), np.zeros((2, 4)))


# --- performance profile -------------------------------------------------------------------------------------------

def test_performance_profile_by_hand():
    scores = np.array([[1.0, 2.0], [3.0, 4.0]])
    profile = performance_profile(scores, np.array([0.0, 1.0, 2.5, 4.0]))
    np.testing.assert_array_equal(profile, [1.0, 0.75, 0.5, 0.0])  # strictly above


def test_the_performance_profile_and_its_band_are_non_increasing_fractions():
    scores, thresholds = runs_by_tasks(), np.linspace(-3.0, 12.0, 61)
    profile, low, high = performance_profile_interval(scores, thresholds)
    np.testing.assert_array_equal(profile, performance_profile(scores, thresholds))
    assert profile.shape == low.shape == high.shape == thresholds.shape
    for curve in (profile, low, high):
        assert np.all(np.diff(curve) <= 0)
        assert np.all((curve >= 0) & (curve <= 1))
    assert np.all(low <= profile) and np.all(profile <= high)
    assert np.any(low < high)
    assert profile[0] == 1.0 and profile[-1] == 0.0


def test_the_performance_profile_band_is_the_stratified_bootstrap_at_each_threshold():
    scores, thresholds = runs_by_tasks(), np.array([0.0, 2.0, 4.5, 7.0])
    profile, low, high = performance_profile_interval(scores, thresholds)
    for k, threshold in enumerate(thresholds):
        point, low_k, high_k = stratified_bootstrap(scores, lambda sample: float((sample > threshold).mean()))
        assert point == profile[k]
        assert low_k == pytest.approx(low[k], abs=1e-12) and high_k == pytest.approx(high[k], abs=1e-12)
    again = performance_profile_interval(scores, thresholds)
    for first, second in zip((profile, low, high), again):
        np.testing.assert_array_equal(first, second)
