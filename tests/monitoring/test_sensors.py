"""Sensors: Gaussian noise and dropouts, counter-based so that an env's readings depend on nothing but its own key and ticks."""

import numpy as np
import pytest

from timegap_env.config import SensorConfig
from timegap_env.monitoring.sensors import Readings, Sensors


def truth(n_ticks: int, n_envs: int, spacing: float = 40.0, speed: float = 20.0) -> Readings:
    return Readings(np.full((n_ticks, n_envs, 5), spacing), np.full((n_ticks, n_envs, 5), speed))


def test_noise_is_gaussian_with_the_configured_spread_and_dropouts():
    sensors = Sensors(SensorConfig(spacing_noise_std=0.1, speed_noise_std=0.3), n_envs=200, seed=1)
    sensors.dropout_probability[:] = 0.1
    measured = sensors.measure(truth(20, 200), np.zeros(200, dtype=np.int64))
    dropped = np.isnan(measured.spacing)
    assert 0.08 < dropped.mean() < 0.12
    np.testing.assert_array_equal(dropped, np.isnan(measured.speed))  # a dropout loses the whole reading
    spacing_error, speed_error = measured.spacing[~dropped] - 40.0, measured.speed[~dropped] - 20.0
    assert np.std(spacing_error) == pytest.approx(0.1, rel=0.05) and abs(np.mean(spacing_error)) < 0.005
    assert np.std(speed_error) == pytest.approx(0.3, rel=0.05) and abs(np.mean(speed_error)) < 0.015
    assert abs(np.corrcoef(spacing_error, speed_error)[0, 1]) < 0.05


def test_without_noise_or_dropouts_the_readings_are_the_truth():
    sensors = Sensors(SensorConfig(spacing_noise_std=0.0, speed_noise_std=0.0), n_envs=3, seed=0)
    true = Readings(*np.random.default_rng(0).uniform(5.0, 50.0, (2, 4, 3, 5)))
    measured = sensors.measure(true, np.zeros(3, dtype=np.int64))
    np.testing.assert_array_equal(measured.spacing, true.spacing)
    np.testing.assert_array_equal(measured.speed, true.speed)


def test_readings_depend_only_on_key_tick_and_follower():
    alone = Sensors(n_envs=1)
    alone.keys[:] = 42
    batch = Sensors(n_envs=3)
    batch.keys[:] = [7, 42, 3]
    one = alone.measure(truth(1, 1), np.array([8]))
    three = batch.measure(truth(1, 3), np.array([0, 8, 8]))
    np.testing.assert_array_equal(one.spacing[:, 0], three.spacing[:, 1])
    np.testing.assert_array_equal(one.speed[:, 0], three.speed[:, 1])
    assert not np.array_equal(three.spacing[:, 1], three.spacing[:, 2])  # another key
    assert not np.array_equal(one.spacing, alone.measure(truth(1, 1), np.array([9])).spacing)  # another tick
    assert len(np.unique(one.spacing)) == 5  # every follower draws its own noise


def test_a_block_of_ticks_reads_what_its_ticks_read_one_by_one():
    sensors = Sensors(SensorConfig(dropout_probability=0.3), n_envs=2, seed=5)
    before = np.array([3, 8])
    block = sensors.measure(truth(3, 2), before)
    for k in range(3):
        tick = sensors.measure(truth(1, 2), before + k)
        np.testing.assert_array_equal(block.spacing[k], tick.spacing[0])
        np.testing.assert_array_equal(block.speed[k], tick.speed[0])


def test_seeds_draw_the_noise_keys():
    assert np.array_equal(Sensors(n_envs=4, seed=2).keys, Sensors(n_envs=4, seed=2).keys)
    assert not np.array_equal(Sensors(n_envs=4, seed=2).keys, Sensors(n_envs=4, seed=3).keys)
    assert Sensors(SensorConfig(dropout_probability=0.2), n_envs=2).dropout_probability.tolist() == [0.2, 0.2]
