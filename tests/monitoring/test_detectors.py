"""Tests of the non-Bayesian baselines: the raw time gap and recursive least squares with forgetting."""

from __future__ import annotations

import numpy as np
import pytest

from timegap_env.monitoring.detectors import RecursiveLeastSquares, raw_time_gap
from timegap_env.config import TIME_GAP_MIN_SPEED

S0, TAU = 5.0, 1.6  # standstill spacing [m], time gap [s]


def speeds(n_ticks: int, n_envs: int, n_vehicles: int = 1, seed: int = 0) -> np.ndarray:
    """Speeds varying from tick to tick, uniform in 10-30 m/s, (n_ticks, n_envs, n_vehicles) [m/s]."""
    return np.random.default_rng(seed).uniform(10.0, 30.0, (n_ticks, n_envs, n_vehicles))


# ---- raw time gap ----------------------------------------------------------------------------


def test_raw_time_gap_is_the_instantaneous_gap_and_nan_below_the_minimum_speed():
    speed = np.array([[20.0, TIME_GAP_MIN_SPEED, 0.99 * TIME_GAP_MIN_SPEED, 0.0, np.nan, 20.0]])
    spacing = np.array([[37.0, 6.6, 6.6, 5.0, 37.0, np.nan]])
    gap = raw_time_gap(speed, spacing, S0)
    np.testing.assert_allclose(gap[0, :2], [1.6, 1.6])
    assert np.isnan(gap[0, 2:]).all()
    assert np.isnan(raw_time_gap([[5.0]], [[20.0]], S0, min_speed=6.0)).all()


# ---- recursive least squares -----------------------------------------------------------------


def test_rls_starts_at_the_prior_and_the_setting():
    rls = RecursiveLeastSquares(2, 3, setting=[[1.0], [1.6]], prior_standstill_spacing=4.0,
                                prior_cov=((0.5, 0.01), (0.01, 0.2)), noise_variance=0.01)
    np.testing.assert_array_equal(rls.tau, [[1.0] * 3, [1.6] * 3])
    np.testing.assert_array_equal(rls.memory.s0, 4.0)
    np.testing.assert_allclose(rls.initial_p, [[50.0, 1.0], [1.0, 20.0]])
    np.testing.assert_array_equal(rls.memory.p_s0_tau, 1.0)


def test_rls_recovers_s0_and_tau_from_noise_free_readings():
    speed = speeds(2000, 4)  # long enough for the prior's weight, 0.99^t, to vanish
    rls = RecursiveLeastSquares(4, 1, setting=1.0, forgetting=0.99, prior_standstill_spacing=3.0)
    tau = rls.update_block(speed, S0 + TAU * speed)
    np.testing.assert_allclose(tau[-1], TAU, atol=1e-9)
    np.testing.assert_allclose(rls.memory.s0, S0, atol=1e-7)


def test_rls_recovers_s0_and_tau_from_noisy_readings():
    n_envs, noise_std, forgetting = 500, 0.1, 0.995  # spacing noise [m], the sensors' default
    speed = speeds(2000, n_envs, seed=1)
    spacing = S0 + TAU * speed + np.random.default_rng(2).normal(0.0, noise_std, speed.shape)
    rls = RecursiveLeastSquares(n_envs, 1, setting=1.0, forgetting=forgetting, noise_variance=noise_std**2)
    tau = rls.update_block(speed, spacing)[-1, :, 0]
    assert abs(tau.mean() - TAU) < 4 * tau.std() / np.sqrt(n_envs)  # unbiased
    # The spread of least squares over (1 + lambda) / (1 - lambda) readings (weights lambda^age), V ~ U(10, 30) [s]:
    n_effective, speed_variance = (1 + forgetting) / (1 - forgetting), 20.0**2 / 12
    assert tau.std() == pytest.approx(noise_std / np.sqrt(n_effective * speed_variance), rel=0.2)
    assert abs(rls.memory.s0.mean() - S0) < 0.01


@pytest.mark.parametrize("forgetting", [0.99, 0.999])
def test_rls_tracks_a_step_of_tau_with_a_time_constant_of_its_memory(forgetting):
    """After a step of tau the old readings' weight decays as forgetting^n: 1/e of the step is left
    after about 1 / (1 - forgetting) ticks."""
    memory = 1.0 / (1.0 - forgetting)  # [ticks]
    step, n_ticks, new_tau = int(10 * memory), int(13 * memory), 2.0
    speed = speeds(n_ticks, 200, seed=3)
    tau = np.where(np.arange(n_ticks)[:, None, None] < step, TAU, new_tau)
    rls = RecursiveLeastSquares(200, 1, setting=TAU, forgetting=forgetting)
    estimate = rls.update_block(speed, S0 + tau * speed)[step:, :, 0].mean(axis=1)
    left = (new_tau - estimate) / (new_tau - TAU)  # share of the step not yet followed [-]
    assert np.argmax(left < np.exp(-1.0)) + 1 == pytest.approx(memory, rel=0.1)
    assert left[-1] < 0.1


def test_rls_skips_missing_readings_but_ages_the_data():
    speed = speeds(300, 2, 2, seed=4)
    spacing = S0 + TAU * speed + np.random.default_rng(5).normal(0.0, 0.1, speed.shape)
    missing = np.random.default_rng(6).random(speed.shape) < 0.3
    missing[:, 1, 1] = False  # one vehicle keeps all its readings
    kind = np.arange(300)[:, None, None] % 3  # 0: a NaN speed, 1: a NaN spacing, 2: both
    speed[missing & (kind != 1)] = np.nan
    spacing[missing & (kind != 0)] = np.nan
    rls = RecursiveLeastSquares(2, 2, setting=1.0, forgetting=0.99)
    memories = []
    for v, s in zip(speed, spacing):
        rls.update(v, s)
        memories.append([field.copy() for field in rls.memory])
    for k in range(1, 300):  # a skipped reading keeps the estimate; P ages by one tick
        (s0, tau, *p), (s0_before, tau_before, *p_before) = memories[k], memories[k - 1]
        skipped = missing[k]
        np.testing.assert_array_equal(s0[skipped], s0_before[skipped])
        np.testing.assert_array_equal(tau[skipped], tau_before[skipped])
        for entry, entry_before in zip(p, p_before):
            np.testing.assert_array_equal(entry[skipped], entry_before[skipped] / 0.99)
        assert (tau[~skipped] != tau_before[~skipped]).all()  # the others moved
    alone = RecursiveLeastSquares(1, 1, setting=1.0, forgetting=0.99)  # others' dropouts do not matter
    alone_tau = alone.update_block(speed[:, 1:, 1:], spacing[:, 1:, 1:])
    assert alone_tau[-1, 0, 0] == rls.tau[1, 1] and np.isfinite(rls.tau).all()


def test_rls_blocks_equal_ticks_bit_for_bit():
    speed = speeds(250, 3, 2, seed=7)
    spacing = S0 + TAU * speed + np.random.default_rng(8).normal(0.0, 0.1, speed.shape)
    spacing[::17, 1, 0] = np.nan
    by_block, by_tick = RecursiveLeastSquares(3, 2, 1.6), RecursiveLeastSquares(3, 2, 1.6)
    blocks = np.concatenate([by_block.update_block(speed[a:b], spacing[a:b]) for a, b in ((0, 1), (1, 100), (100, 250))])
    ticks = np.stack([by_tick.update(v, s) for v, s in zip(speed, spacing)])
    np.testing.assert_array_equal(blocks, ticks)
    for block_field, tick_field in zip(by_block.memory, by_tick.memory):
        np.testing.assert_array_equal(block_field, tick_field)


def test_rls_reset_restarts_only_the_masked_envs():
    speed = speeds(50, 2, 2, seed=9)
    rls = RecursiveLeastSquares(2, 2, setting=1.0)
    rls.update_block(speed, S0 + TAU * speed)
    before = [field[1].copy() for field in rls.memory]
    rls.reset(np.array([True, False]), setting=1.2)
    np.testing.assert_array_equal(rls.tau[0], [1.2, 1.2])
    np.testing.assert_array_equal(rls.memory.s0[0], S0)
    np.testing.assert_array_equal(rls.memory.p_tau[0], rls.initial_p[1, 1])
    for field, kept in zip(rls.memory, before):
        np.testing.assert_array_equal(field[1], kept)


@pytest.mark.parametrize(
    "call, message",
    [
        (lambda: RecursiveLeastSquares(2, 3, 1.6, forgetting=0.0), r"forgetting = 0.0: must be in \(0, 1\]"),
        (lambda: RecursiveLeastSquares(2, 3, 1.6, forgetting=1.01), r"forgetting = 1.01: must be in \(0, 1\]"),
        (lambda: RecursiveLeastSquares(2, 3, 1.6, forgetting=float("nan")), "forgetting = nan: must be a finite number"),
        (lambda: RecursiveLeastSquares(2, 3, 1.6, forgetting="0.99"), "forgetting = '0.99': must be a finite number"),
        (lambda: RecursiveLeastSquares(0, 3, 1.6), "n_envs = 0"),
        (lambda: RecursiveLeastSquares(2, 3, [1.6, 1.0]), r"setting has shape \(2,\)"),
        (lambda: RecursiveLeastSquares(2, 3, 1.6, prior_standstill_spacing=np.inf), "prior_standstill_spacing = inf"),
        (lambda: RecursiveLeastSquares(2, 3, 1.6, prior_cov=((1.0, 2.0), (2.0, 1.0))), "prior_cov = "),
        (lambda: RecursiveLeastSquares(2, 3, 1.6, prior_cov=(1.0, 1.0)), "prior_cov = "),
        (lambda: RecursiveLeastSquares(2, 3, 1.6, noise_variance=0.0), "noise_variance = 0.0: must be > 0"),
        (lambda: RecursiveLeastSquares(2, 3, 1.6).update(np.ones((3, 2)), np.ones((2, 3))), r"speed has shape \(3, 2\)"),
        (lambda: RecursiveLeastSquares(2, 3, 1.6).update_block(np.ones((4, 2, 3)), np.ones((5, 2, 3))),
         r"speed, spacing have shapes \(4, 2, 3\), \(5, 2, 3\)"),
        (lambda: RecursiveLeastSquares(2, 3, 1.6).update_block(np.ones((0, 2, 3)), np.ones((0, 2, 3))),
         r"expected \(n_ticks >= 1, \*\(2, 3\)\)"),
        (lambda: RecursiveLeastSquares(2, 3, 1.6).reset(np.ones(3, dtype=bool), 1.6), r"must be bool of shape \(2,\)"),
        (lambda: raw_time_gap(np.ones((4, 2)), np.ones((4, 3)), S0), r"speed, spacing have shapes \(4, 2\), \(4, 3\)"),
        (lambda: raw_time_gap(1.0, 1.0, S0, min_speed=0.0), "min_speed = 0.0: must be > 0"),
        (lambda: raw_time_gap(1.0, 1.0, np.nan), "standstill_spacing = nan: must be a finite number"),
    ],
)
def test_bad_arguments_are_named(call, message):
    with pytest.raises(ValueError, match=message):
        call()
