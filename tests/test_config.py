"""Config validation: every bad value raises ValueError naming the field and the value."""

import pytest

from timegap_env.config import EnvConfig, LeaderConfig, MonitorConfig, PlatoonConfig


@pytest.mark.parametrize(
    "overrides, message",
    [
        ({"actuation_lag": 0.0}, r"actuation_lag = 0.0"),
        ({"actuation_lag": -0.45}, r"actuation_lag = -0.45"),
        ({"actuation_gain": 0.0}, r"actuation_gain = 0.0"),
        ({"actuation_lag": (0.4, 0.5)}, r"actuation_lag = \(0.4, 0.5\): must be one number or 5"),
        ({"dt": 0.0}, r"dt = 0.0"),
        ({"dt": -0.1}, r"dt = -0.1"),
        ({"initial_setting": 0.0}, r"initial_setting = 0.0"),
        ({"initial_setting": float("nan")}, r"initial_setting = nan: must be finite"),
        ({"n_followers": 0}, r"n_followers = 0"),
        ({"v2v_delay": 0.15}, r"v2v_delay = 0.15: must be a multiple of dt"),
        ({"accel_max": -1.0}, r"PlatoonConfig.accel_max = -1.0: must be in \(0, 20\]"),
        ({"k_s": "high"}, r"k_s = 'high': must be a number"),
        ({"warp_speed": 9}, r"unknown PlatoonConfig field\(s\) \['warp_speed'\]"),
    ],
)
def test_bad_platoon_config_is_named(overrides, message):
    with pytest.raises(ValueError, match=message):
        PlatoonConfig().with_overrides(overrides)


@pytest.mark.parametrize(
    "overrides, message",
    [
        ({"speed_band": (35.0, 9.0)}, r"speed_band = \(35.0, 9.0\): must satisfy low < high"),
        ({"speed_band": (-1.0, 9.0)}, r"speed_band"),
        ({"initial_speed": 50.0}, r"initial_speed = 50.0: must lie in speed_band"),
        ({"duration": 0.0}, r"duration = 0.0"),
    ],
)
def test_bad_leader_config_is_named(overrides, message):
    with pytest.raises(ValueError, match=message):
        LeaderConfig().with_overrides(overrides)


def test_per_follower_dynamics_accept_one_value_per_follower():
    config = PlatoonConfig(actuation_lag=(0.3, 0.4, 0.5, 0.6, 0.7))
    assert config.per_follower("actuation_lag").tolist() == [0.3, 0.4, 0.5, 0.6, 0.7]
    assert config.per_follower("actuation_gain").tolist() == [1.0] * 5


def test_default_monitor_prior_matches_the_simulator():
    assert MonitorConfig().prior_standstill_spacing == PlatoonConfig().standstill_spacing


def test_the_envs_leader_lasts_the_episode():
    assert EnvConfig().leader.duration == EnvConfig().episode_duration == 250.0
    assert EnvConfig.from_dict({"episode_duration": 500}).leader.duration == 500.0
    assert EnvConfig.from_dict({"episode_duration": 60.0, "leader": {"duration": 60.0}}).leader.duration == 60.0
    with pytest.raises(ValueError, match=r"EnvConfig.leader.duration = 100.0: a synthetic leader lasts the episode"):
        EnvConfig.from_dict({"leader": {"duration": 100.0}})


def test_derived_quantities_come_from_their_fields():
    config = EnvConfig.from_dict({"chart": {"limit_width": 3.0}, "setting_levels": (0.8, 1.6, 2.0)})
    assert config.chart.half_width == 3.0 * config.chart.baseline_std
    assert config.setting_span == pytest.approx(1.2, rel=1e-15)


def test_the_monitors_speed_band_cannot_be_empty():
    with pytest.raises(ValueError, match=r"MonitorConfig.min_speed = 6.0: must be below max_speed = 5.0"):
        MonitorConfig(min_speed=6.0, max_speed=5.0)


# Issue 22, item 3: integers that pass validation must run as the floats they stand for.
INTEGER_CONFIGS = [
    ({"platoon": {"initial_setting": 2}, "setting_levels": (1.0, 2.0, 3.0)},
     {"platoon": {"initial_setting": 2.0}, "setting_levels": (1.0, 2.0, 3.0)}),
    ({"setting_levels": [1, 2, 3], "platoon": {"initial_setting": 2.0}},
     {"setting_levels": [1.0, 2.0, 3.0], "platoon": {"initial_setting": 2.0}}),
    ({"setting_levels": [1, 2, 3], "platoon": {"initial_setting": 2}, "random_initial_setting": True},
     {"setting_levels": [1.0, 2.0, 3.0], "platoon": {"initial_setting": 2.0}, "random_initial_setting": True}),
    ({"sensors": {"dropout_probability": 0}}, {"sensors": {"dropout_probability": 0.0}}),
    ({"dropout_probability_range": (0, 0)}, {"dropout_probability_range": (0.0, 0.0)}),
    ({"platoon": {"actuation_lag": 1, "n_followers": 2}, "episode_duration": 20, "decision_interval": 2},
     {"platoon": {"actuation_lag": 1.0, "n_followers": 2}, "episode_duration": 20.0, "decision_interval": 2.0}),
]


@pytest.mark.parametrize("integers, floats", INTEGER_CONFIGS)
def test_integer_values_run_as_the_floats_they_stand_for(integers, floats):
    import gymnasium as gym
    import numpy as np

    import timegap_env  # noqa: F401

    assert EnvConfig.from_dict(integers) == EnvConfig.from_dict(floats)
    runs = []
    for config in (integers, floats):
        env = gym.make("TimeGapMonitor-v0", config=config)
        obs, _ = env.reset(seed=3)
        steps = [obs]
        for action in (0, 1, 2, 1):
            obs, reward, *_ = env.step(action % env.action_space.n)
            steps += [obs, np.float64(reward)]
        runs.append(steps)
    for a, b in zip(*runs):
        assert np.array_equal(a, b)


def test_numbers_of_any_type_are_stored_as_pythons():
    import numpy as np

    from timegap_env.config import HardBrakingConfig

    config = HardBrakingConfig(n_events=np.int8(3), decel_range=(np.float32(4.0), 7))
    assert type(config.n_events) is int and config.n_events == 3
    assert all(type(end) is float for end in config.decel_range)
    platoon = PlatoonConfig(initial_setting=np.int64(2), v2v=np.bool_(True))
    assert type(platoon.initial_setting) is float and type(platoon.v2v) is bool


@pytest.mark.parametrize(
    "overrides, field",
    [
        ({"episode_duration": 10**400}, "EnvConfig.episode_duration"),
        ({"reward_scales": {"ttc_threshold": 10**5000}}, "RewardScales.ttc_threshold"),
        ({"chart": {"exceedance_window": 10**400}}, "ChartConfig.exceedance_window"),
        ({"monitor": {"window": 10**400}}, "MonitorConfig.window"),
        ({"monitor": {"prior_cov": ((10**400, 0), (0, 1))}}, "MonitorConfig.prior_cov"),
        ({"platoon": {"actuation_lag": 10**400}}, "PlatoonConfig.actuation_lag"),
        ({"platoon": {"n_followers": 10**400}}, "PlatoonConfig.n_followers"),
        ({"leader": {"speed_band": (0, 10**400)}}, "LeaderConfig.speed_band"),
        ({"reward_weights": {"tracking": 10**400}}, "RewardWeights.tracking"),
    ],
)
def test_huge_integers_are_refused_by_name(overrides, field):
    """An integer beyond a float's range is no finite number: ValueError naming the field (was OverflowError)."""
    with pytest.raises(ValueError, match=f"{field} = "):
        EnvConfig.from_dict(overrides)
