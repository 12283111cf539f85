"""The closed loop: sensors feed the monitor, setting changes re-centre prior and chart."""

import numpy as np
import pytest

from timegap_env.config import MonitorConfig, PlatoonConfig, SensorConfig
from timegap_env.monitored import MonitoredPlatoon, counter_uniforms, measure


def test_counter_noise_is_gaussian_with_dropouts():
    keys = np.arange(1, 201, dtype=np.uint64)
    uniforms = counter_uniforms(keys, np.full(200, 7), 5)
    assert uniforms.shape == (3, 200, 5) and 0 < uniforms.min() and uniforms.max() < 1
    spacing, speed = np.full((200, 5), 40.0), np.full((200, 5), 20.0)
    measured_spacing, measured_speed = measure(spacing, speed, SensorConfig(), uniforms, np.full(200, 0.1))
    dropped = np.isnan(measured_spacing)
    assert 0.05 < dropped.mean() < 0.15
    np.testing.assert_array_equal(dropped, np.isnan(measured_speed))
    assert np.std(measured_spacing[~dropped] - 40.0) == pytest.approx(0.1, rel=0.1)
    assert abs(np.corrcoef(measured_spacing[~dropped], measured_speed[~dropped])[0, 1]) < 0.1


def test_counter_noise_depends_only_on_key_tick_and_follower():
    alone = counter_uniforms(np.array([42], dtype=np.uint64), np.array([9]), 5)
    batched = counter_uniforms(np.array([7, 42, 3], dtype=np.uint64), np.array([1, 9, 9]), 5)
    np.testing.assert_array_equal(alone[:, 0], batched[:, 1])
    assert not np.array_equal(batched[:, 1], batched[:, 2])
    assert not np.array_equal(alone, counter_uniforms(np.array([42], dtype=np.uint64), np.array([10]), 5))


def test_estimate_tracks_the_actual_time_gap_through_dropouts():
    loop = MonitoredPlatoon(sensors=SensorConfig(dropout_probability=0.2), n_envs=2, seed=3)
    assert loop.dropout_probability.tolist() == [0.2, 0.2]
    loop.reset([25.0, 15.0])
    for _ in range(100):
        _, state = loop.tick([25.0, 15.0], 0.0)
    assert np.all(np.isfinite(loop.monitor.tau_mean))
    np.testing.assert_allclose(loop.monitor.tau_mean, 1.6, atol=0.02)
    assert loop.monitor.skipped.sum() > 0
    assert not state.alarm.any()


def test_change_of_setting_ramps_and_recentres_only_who_changed():
    loop = MonitoredPlatoon(n_envs=2, seed=0)
    loop.reset(25.0)
    mask = np.zeros((2, 5), dtype=bool)
    mask[0, 0] = True
    changed = loop.change_time_gap(1.0, mask)
    np.testing.assert_array_equal(changed, mask)
    assert loop.monitor.prior_mean[0, 0, 1] == 1.0
    loop.tick([25.0, 25.0], 0.0)
    assert loop.chart.center[0, 0] == pytest.approx(1.6 - 0.02)  # the limits follow the 0.2 s/s ramp
    assert loop.chart.center[1, 0] == 1.6
    assert not loop.change_time_gap(1.0, mask).any()  # asking again changes nothing
    for _ in range(300):
        loop.tick([25.0, 25.0], 0.0)
    assert loop.platoon.time_gap[0, 0] == pytest.approx(1.0) and loop.chart.center[0, 0] == pytest.approx(1.0)
    assert loop.monitor.tau_mean[0, 0] == pytest.approx(1.0, abs=0.02)
    assert loop.monitor.tau_mean[1, 0] == pytest.approx(1.6, abs=0.02)


def test_configs_must_share_the_tick():
    with pytest.raises(ValueError, match="monitor.dt"):
        MonitoredPlatoon(PlatoonConfig(dt=0.2, v2v_delay=0.2), MonitorConfig(dt=0.1))


def test_a_commanded_change_raises_no_alarm_but_a_real_excursion_after_it_does():
    loop = MonitoredPlatoon(n_envs=1, seed=0)
    loop.reset(25.0, time_gap=0.6)
    loop.change_time_gap(2.2)  # the slowest transition of the ladder
    assert not any(loop.tick(25.0, 0.0)[1].alarm.any() for _ in range(300))
    loop.platoon.x[0, 0] += 15.0  # the leader jumps 15 m ahead: a real gap excursion
    assert any(loop.tick(25.0, 0.0)[1].alarm.any() for _ in range(20))
