"""The closed loop: sensors feed the monitor, setting changes re-centre prior and chart."""

import numpy as np
import pytest

from timegap_env.config import MonitorConfig, PlatoonConfig, SensorConfig
from timegap_env.monitoring.loop import MonitoredPlatoon
from timegap_env.monitoring.sensors import Readings


def test_estimate_tracks_the_actual_time_gap_through_dropouts():
    loop = MonitoredPlatoon(sensors=SensorConfig(dropout_probability=0.2), n_envs=2, seed=3)
    assert loop.sensors.dropout_probability.tolist() == [0.2, 0.2]
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
    changed = loop.change_setting(1.0, mask)
    np.testing.assert_array_equal(changed, mask)
    assert loop.monitor.prior_mean[0, 0, 1] == 1.0
    loop.tick([25.0, 25.0], 0.0)
    assert loop.chart.center[0, 0] == pytest.approx(1.6 - 0.02)  # the limits follow the 0.2 s/s ramp
    assert loop.chart.center[1, 0] == 1.6
    assert not loop.change_setting(1.0, mask).any()  # asking again changes nothing
    for _ in range(300):
        loop.tick([25.0, 25.0], 0.0)
    assert loop.platoon.applied_setting[0, 0] == pytest.approx(1.0) and loop.chart.center[0, 0] == pytest.approx(1.0)
    assert loop.monitor.tau_mean[0, 0] == pytest.approx(1.0, abs=0.02)
    assert loop.monitor.tau_mean[1, 0] == pytest.approx(1.6, abs=0.02)


def test_configs_must_share_the_tick():
    with pytest.raises(ValueError, match="monitor.dt"):
        MonitoredPlatoon(PlatoonConfig(dt=0.2, v2v_delay=0.2), MonitorConfig(dt=0.1))


def test_a_commanded_change_raises_no_alarm_but_a_real_excursion_after_it_does():
    loop = MonitoredPlatoon(n_envs=1, seed=0)
    loop.reset(25.0, setting=0.6)
    loop.change_setting(2.2)  # the slowest transition of the ladder
    assert not any(loop.tick(25.0, 0.0)[1].alarm.any() for _ in range(300))
    loop.platoon.x[0, 0] += 15.0  # the leader jumps 15 m ahead: a real gap excursion
    assert any(loop.tick(25.0, 0.0)[1].alarm.any() for _ in range(20))


@pytest.mark.parametrize("kind", ["shewhart", "ewma", "cusum"])
def test_a_block_of_ticks_equals_the_same_ticks_one_by_one(kind):
    """run() with compiled physics and block-wise sensors, monitor and chart gives, bit for bit,
    what tick() gives tick by tick, through a ramp, a V2V loss, dropouts and excursions."""
    from timegap_env.config import ChartConfig

    def make() -> MonitoredPlatoon:
        loop = MonitoredPlatoon(chart=ChartConfig(kind=kind), sensors=SensorConfig(dropout_probability=0.05),
                                n_envs=3, seed=4)
        loop.reset([25.0, 15.0, 30.0])
        loop.change_setting(np.array([[1.0] * 5, [1.6] * 5, [2.2] * 5]))
        return loop

    rng = np.random.default_rng(0)
    n_ticks = 60
    speed = np.array([25.0, 15.0, 30.0]) + np.cumsum(rng.normal(0, 0.3, (n_ticks, 3)), axis=0)
    accel = rng.normal(0, 1.0, (n_ticks, 3))
    v2v = np.ones((n_ticks, 3, 5), dtype=bool)
    v2v[20:40, 1] = False
    by_block, by_tick = make(), make()
    blocks, states = [], []
    for k in range(0, n_ticks, 10):
        if k == 30:  # env 1's leader (no change of setting, so no hold-off) jumps 15 m ahead: excursions
            by_block.platoon.x[1, 0] += 15.0
            by_tick.platoon.x[1, 0] += 15.0
        blocks.append(by_block.run(speed[k : k + 10], accel[k : k + 10], v2v[k : k + 10]))
        for j in range(k, k + 10):
            by_tick.platoon.set_v2v(v2v[j])
            states.append(by_tick.tick(speed[j], accel[j])[1])
    alarm = np.concatenate([block.chart.alarm for block in blocks])
    assert alarm[:, 1].any() and not alarm[:, [0, 2]].any()
    np.testing.assert_array_equal(alarm, [state.alarm for state in states])
    np.testing.assert_array_equal(np.concatenate([block.chart.exceedances_in_window for block in blocks]),
                                  [state.exceedances_in_window for state in states])
    for name in ("x", "v", "a", "u", "applied_setting"):
        np.testing.assert_array_equal(getattr(by_block.platoon, name), getattr(by_tick.platoon, name))
    np.testing.assert_array_equal(by_block.monitor.mean, by_tick.monitor.mean)
    np.testing.assert_array_equal(by_block.monitor.cov, by_tick.monitor.cov)
    np.testing.assert_array_equal(by_block.monitor.skipped, by_tick.monitor.skipped)
    assert by_block.monitor.skipped.sum() > 0


def test_the_loop_measures_with_its_sensors_from_the_ticks_since_reset():
    """run() hands the block's true spacings and speeds to its Sensors, counting ticks from each env's reset."""
    loop = MonitoredPlatoon(sensors=SensorConfig(dropout_probability=0.2), n_envs=4, seed=9)
    loop.reset(np.array([10.0, 20.0, 25.0, 30.0]))
    loop.run(np.full((7, 4), 20.0), np.zeros((7, 4)))  # the ticks no longer start at 0
    assert loop.ticks.tolist() == [7] * 4
    block = loop.run(np.full((10, 4), 20.0), np.zeros((10, 4)))
    expected = loop.sensors.measure(Readings(block.physics.spacing, block.physics.speed), np.full(4, 7))
    np.testing.assert_array_equal(block.readings.spacing, expected.spacing)
    np.testing.assert_array_equal(block.readings.speed, expected.speed)
    assert np.isnan(expected.spacing).any()
