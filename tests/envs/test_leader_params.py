"""A synthetic leader family's parameters reach the env through its config (issue 23, item 3):
``EnvConfig.leader_params`` maps a family to overrides of its parameter dataclass."""

import gymnasium as gym
import numpy as np
import pytest

import timegap_env  # noqa: F401
from timegap_env.config import SinusoidConfig
from timegap_env.leaders.scenarios import LEADER_FAMILIES, make_leader


def leader_speed(config: dict, scenario: str, seed: int = 3) -> np.ndarray:
    env = gym.make("TimeGapMonitor-v0", config={"episode_duration": 60.0, **config})
    env.reset(seed=seed, options={"scenario": scenario})
    episodes = env.unwrapped.task.episodes
    return episodes.leader_speed[0, : episodes.episode_ticks[0] + 1].copy()


def test_a_familys_parameters_reach_its_leader_and_no_other():
    wide = {"leader_params": {"sinusoid": {"amplitude_range": (8.0, 9.0)}}}
    narrow = leader_speed({}, "sinusoid")
    widened = leader_speed(wide, "sinusoid")
    assert np.ptp(widened) > np.ptp(narrow) + 4.0  # amplitude 8-9 m/s against the default 2-6 m/s
    params = SinusoidConfig(amplitude_range=(8.0, 9.0))
    leader = gym.make("TimeGapMonitor-v0", config={"episode_duration": 60.0}).unwrapped.config.leader
    seed = int(np.random.default_rng(3).integers(2**31))  # what the env's reset draws as the leader's seed
    assert np.array_equal(widened, make_leader("sinusoid", seed, leader, params).speed)
    assert np.array_equal(leader_speed(wide, "hard_braking"), leader_speed({}, "hard_braking"))


@pytest.mark.parametrize("family", sorted(name for name, family in LEADER_FAMILIES.items() if family.params))
def test_default_parameters_given_explicitly_change_nothing(family):
    defaults = {"leader_params": {family: {}}}
    assert np.array_equal(leader_speed(defaults, family), leader_speed({}, family))


@pytest.mark.parametrize(
    "leader_params, message",
    [
        ({"ngsim": {}}, r"EnvConfig.leader_params has family 'ngsim': the families with parameters are"),
        ({"sinusoid": {"amplitude": 3}}, r"EnvConfig.leader_params\['sinusoid'\]: unknown SinusoidConfig field"),
        ({"sinusoid": {"period_range": (0.0, 1.0)}}, r"SinusoidConfig.period_range = \(0.0, 1.0\)"),
        ({"sinusoid": 3}, r"EnvConfig.leader_params = \{'sinusoid': 3\}: must be a dict family"),
        ([("sinusoid", {})], r"EnvConfig.leader_params = \[\('sinusoid', \{\}\)\]"),
    ],
)
def test_bad_leader_params_are_named(leader_params, message):
    with pytest.raises(ValueError, match=message):
        gym.make("TimeGapMonitor-v0", config={"leader_params": leader_params})
