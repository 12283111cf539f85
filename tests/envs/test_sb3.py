"""The Stable-Baselines3 adapter: the native vector env as an SB3 VecEnv, equal to a DummyVecEnv of single envs."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3 import PPO
from stable_baselines3.common.env_checker import check_env
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

from timegap_env import DEFAULT_TASK as ENV_ID  # the adapter's default task
from timegap_env.envs.sb3 import TimeGapVecEnv

SHORT = {"episode_duration": 5.0}  # 5-step episodes


def _dummy(n_envs: int, config: dict) -> DummyVecEnv:
    return DummyVecEnv([lambda: gym.make(ENV_ID, config=config) for _ in range(n_envs)])


@pytest.mark.parametrize("config", [SHORT, {**SHORT, "action_mode": "per_vehicle"}])
def test_adapter_equals_dummy_vec_env_of_single_envs(config: dict) -> None:
    n_envs = 3
    adapter, reference = TimeGapVecEnv(n_envs, config), _dummy(n_envs, config)
    assert adapter.observation_space == reference.observation_space
    assert adapter.action_space == reference.action_space
    adapter.seed(7)
    reference.seed(7)
    obs, expected = adapter.reset(), reference.reset()
    assert obs.dtype == np.float32 and np.array_equal(obs, expected)
    rng = np.random.default_rng(0)
    ends = 0
    for step in range(12):  # two whole episodes and two steps of the third
        actions = rng.integers(0, 9, size=(n_envs, *adapter.action_space.shape))
        obs, rewards, dones, infos = adapter.step(actions)
        expected_obs, expected_rewards, expected_dones, expected_infos = reference.step(actions)
        assert np.array_equal(obs, expected_obs), step
        assert rewards.dtype == np.float32 and np.array_equal(rewards, expected_rewards), step
        assert dones.dtype == bool and np.array_equal(dones, expected_dones), step
        for info, expected_info, done in zip(infos, expected_infos, dones):
            if not done:
                assert info == {}
                continue
            ends += 1
            terminal = info["terminal_observation"]
            assert terminal.dtype == np.float32 and np.array_equal(terminal, expected_info["terminal_observation"])
            assert info["TimeLimit.truncated"] is expected_info["TimeLimit.truncated"] is True
            assert info["episode"]["l"] == 5
            summary = {key: float(value) for key, value in info.items() if key.startswith("episode_")}
            assert summary and summary == pytest.approx(
                {key: float(value) for key, value in expected_info.items() if key.startswith("episode_")})
    assert ends == 2 * n_envs
    adapter.close()


def test_adapter_episode_stats_match_monitor() -> None:
    adapter = TimeGapVecEnv(2, SHORT)
    monitored = DummyVecEnv([lambda: Monitor(gym.make(ENV_ID, config=SHORT)) for _ in range(2)])
    adapter.seed(3)
    monitored.seed(3)
    adapter.reset()
    monitored.reset()
    for _ in range(5):
        _, _, _, infos = adapter.step(np.array([2, 6]))
        _, _, _, expected = monitored.step(np.array([2, 6]))
    for info, expected_info in zip(infos, expected):
        assert info["episode"]["r"] == pytest.approx(expected_info["episode"]["r"], abs=1e-5)
        assert info["episode"]["l"] == expected_info["episode"]["l"]
    assert adapter.env_is_wrapped(Monitor) == [True, True]
    assert adapter.env_is_wrapped(gym.wrappers.TimeLimit, indices=[1]) == [False]


def test_adapter_sb3_api() -> None:
    check_env(gym.make(ENV_ID, config=SHORT))  # the env the adapter batches
    adapter = TimeGapVecEnv(2, SHORT)
    assert adapter.seed(11) == [11, 12]
    first = adapter.reset()
    adapter.seed(11)
    assert np.array_equal(adapter.reset(), first)
    assert not np.array_equal(adapter.reset(), first)  # seeds apply to one reset only
    assert adapter.get_attr("config", indices=[1])[0].episode_duration == 5.0
    assert adapter.has_attr("config") and not adapter.has_attr("no_such_attribute")
    adapter.set_attr("max_episode_steps", 3)
    assert adapter.get_attr("max_episode_steps") == [3, 3]
    with pytest.raises(ValueError, match="indices"):
        adapter.set_attr("max_episode_steps", 4, indices=[0])
    adapter.set_options({"scenario": "sinusoid"})
    adapter.reset()
    assert list(adapter.venv.task.scenario) == ["sinusoid", "sinusoid"]
    model = PPO("MlpPolicy", VecNormalize(adapter), n_steps=8, batch_size=8, n_epochs=1, seed=0, device="cpu")
    rewards, lengths = evaluate_policy(model, adapter, n_eval_episodes=4, return_episode_rewards=True)
    assert lengths == [3, 3, 3, 3] and all(r < 0 for r in rewards)
