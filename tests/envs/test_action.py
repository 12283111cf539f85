"""Actions: ladder indices to settings, for the platoon or per follower, and what is refused."""

import numpy as np
import pytest
from gymnasium import spaces

from timegap_env.config import EnvConfig
from timegap_env.envs.action import SettingLadder, action_space

PLATOON = EnvConfig()
PER_VEHICLE = EnvConfig.from_dict({"action_mode": "per_vehicle", "platoon": {"n_followers": 3}})


def test_spaces_follow_the_action_mode_and_the_ladder():
    assert action_space(PLATOON) == spaces.Discrete(len(PLATOON.setting_levels))
    assert action_space(PER_VEHICLE) == spaces.MultiDiscrete([len(PER_VEHICLE.setting_levels)] * 3)


def test_indices_become_settings():
    levels = np.array(PLATOON.setting_levels)
    np.testing.assert_array_equal(SettingLadder(PLATOON, 2).settings(np.array([0, 8])), np.repeat(levels[[0, 8], None], 5, axis=1))
    np.testing.assert_array_equal(SettingLadder(PER_VEHICLE, 1).settings(np.array([[0, 4, 8]])), [levels[[0, 4, 8]]])


@pytest.mark.parametrize(
    "action, message",
    [
        (np.array([1, 2, 3]), r"shape \(2,\)"),
        (np.array([1.0, 2.0]), "integer ladder indices"),
        (np.array([0, 9]), r"in \[0, 8\]"),
        (np.array([-1, 0]), r"in \[0, 8\]"),
    ],
)
def test_bad_actions_are_refused_naming_the_action(action, message):
    with pytest.raises(ValueError, match=message):
        SettingLadder(PLATOON, 2).settings(action)
