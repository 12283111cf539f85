"""Actions: ladder indices to settings, for the platoon or per follower, relative steps, and what is refused."""

import numpy as np
import pytest
from gymnasium import spaces

from timegap_env.config import EnvConfig
from timegap_env.envs.action import SettingLadder, action_space

PLATOON = EnvConfig()
PER_VEHICLE = EnvConfig.from_dict({"action_mode": "per_vehicle", "platoon": {"n_followers": 3}})
RELATIVE = EnvConfig.from_dict({"action_mode": "relative"})
NOW = np.full((2, 5), 1.6)  # the platoon's current settings [s]


def test_spaces_follow_the_action_mode_and_the_ladder():
    assert action_space(PLATOON) == spaces.Discrete(len(PLATOON.setting_levels))
    assert action_space(PER_VEHICLE) == spaces.MultiDiscrete([len(PER_VEHICLE.setting_levels)] * 3)
    assert action_space(RELATIVE) == spaces.Discrete(3)


def test_indices_become_settings():
    levels = np.array(PLATOON.setting_levels)
    np.testing.assert_array_equal(SettingLadder(PLATOON, 2).settings(np.array([0, 8]), NOW), np.repeat(levels[[0, 8], None], 5, axis=1))
    np.testing.assert_array_equal(SettingLadder(PER_VEHICLE, 1).settings(np.array([[0, 4, 8]]), NOW[:1, :3]), [levels[[0, 4, 8]]])


@pytest.mark.parametrize(
    "action, message",
    [
        (np.array([1, 2, 3]), r"shape \(2,\)"),
        (np.array([1.0, 2.0]), "integer actions"),
        (np.array([0, 9]), r"in \[0, 8\]"),
        (np.array([-1, 0]), r"in \[0, 8\]"),
    ],
)
def test_bad_actions_are_refused_naming_the_action(action, message):
    with pytest.raises(ValueError, match=message):
        SettingLadder(PLATOON, 2).settings(action, NOW)


def test_relative_steps_move_the_platoon_one_level_and_stop_at_the_ends():
    ladder = SettingLadder(RELATIVE, 3)
    now = np.array([[1.6] * 5, [0.6] * 5, [2.2] * 5])
    np.testing.assert_allclose(ladder.settings(np.array([0, 0, 2]), now)[:, 0], [1.4, 0.6, 2.2])
    np.testing.assert_allclose(ladder.settings(np.array([2, 1, 0]), now), np.repeat([[1.8], [0.6], [2.0]], 5, axis=1))
    with pytest.raises(ValueError, match=r"in \[0, 2\]"):
        ladder.settings(np.array([3, 0, 0]), now)


def test_the_relative_env_steps_its_setting():
    import gymnasium as gym

    import timegap_env

    env = gym.make(timegap_env.ENV_ID, config={"action_mode": "relative"})
    env.reset(seed=0)
    for action, expected in [(2, 1.8), (2, 2.0), (1, 2.0), (0, 1.8)]:
        env.step(action)
        np.testing.assert_allclose(env.unwrapped.task.loop.platoon.setting, expected)
