"""Config validation: every bad value raises ValueError naming the field and the value."""

import pytest

from timegap_env.config import LeaderConfig, MonitorConfig, PlatoonConfig


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
        ({"accel_max": -1.0}, r"accel_min"),
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
