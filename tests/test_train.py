"""PPO training: the SB3 adapter over the native vector env, the hyperparameter file, short runs of train_ppo."""

from __future__ import annotations

import pickle
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import yaml
from stable_baselines3 import PPO
from stable_baselines3.common.env_checker import check_env
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

from timegap_env import ENV_ID
from timegap_env.sb3 import TimeGapVecEnv
from train import train_ppo

ROOT = Path(__file__).resolve().parents[1]
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
            assert info["episode_summary"] == pytest.approx(expected_info["episode_summary"])
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


def test_hyperparams_have_rl_zoo3_layout() -> None:
    with open(ROOT / "hyperparams" / "ppo.yml") as file:
        document = yaml.safe_load(file)
    assert list(document) == [ENV_ID]
    hyperparams = document[ENV_ID]
    for key in ("n_envs", "n_timesteps", "policy", "normalize", "n_steps", "batch_size", "gamma", "learning_rate",
                "ent_coef", "policy_kwargs"):
        assert key in hyperparams, key
    assert isinstance(hyperparams["policy_kwargs"], str)
    assert hyperparams["n_steps"] * hyperparams["n_envs"] % hyperparams["batch_size"] == 0
    loaded = train_ppo.load_hyperparams(ROOT / "hyperparams" / "ppo.yml")
    assert isinstance(loaded["policy_kwargs"], dict)


def test_hyperparams_errors_name_the_field(tmp_path: Path) -> None:
    path = tmp_path / "bad.yml"
    path.write_text(yaml.safe_dump({ENV_ID: {"n_envs": 2, "n_timesteps": 10, "policy": "MlpPolicy", "n_stpes": 8}}))
    with pytest.raises(ValueError, match="n_stpes"):
        train_ppo.load_hyperparams(path)
    path.write_text(yaml.safe_dump({"CartPole-v1": {}}))
    with pytest.raises(ValueError, match=ENV_ID):
        train_ppo.load_hyperparams(path)


def test_tiny_training_run_saves_loads_and_resumes(tmp_path: Path) -> None:
    hyperparams = tmp_path / "ppo.yml"
    hyperparams.write_text(yaml.safe_dump({ENV_ID: {
        "n_envs": 4, "n_timesteps": 128, "policy": "MlpPolicy", "normalize": True, "n_steps": 16, "batch_size": 32,
        "n_epochs": 1, "policy_kwargs": "dict(net_arch=[16])", "env_kwargs": {"config": {"episode_duration": 10.0}},
        "warmup": {"n_timesteps": 64, "env_kwargs": {"config": {"episode_duration": 10.0, "decision_interval": 5.0}}},
    }}))
    out = tmp_path / "run"
    common = ["--hyperparams", str(hyperparams), "--out", str(out), "--tensorboard-log", str(tmp_path / "runs"),
              "--no-progress-bar", "--checkpoint-freq", "32"]
    train_ppo.main(common)
    assert sorted(p.name for p in out.iterdir()) == ["model.zip", "training.md", "vecnormalize.pkl"]
    model = PPO.load(out / "model.zip", device="cpu")
    assert model.num_timesteps == 128
    with open(out / "vecnormalize.pkl", "rb") as file:
        count = pickle.load(file).obs_rms.count
    assert count > 128  # carried over from the warm-up's 64 steps, then 64 more
    env = VecNormalize.load(str(out / "vecnormalize.pkl"), TimeGapVecEnv(2, {"episode_duration": 10.0}))
    actions, _ = model.predict(env.reset(), deterministic=True)
    assert actions.shape == (2,) and env.action_space.contains(int(actions[0]))
    report = (out / "training.md").read_text()
    assert "| timesteps, this command / total | 128 / 128 |" in report
    assert "| warm-up, {'config': {'decision_interval': 5.0, 'episode_duration': 10.0}}: steps, time, " in report
    assert "| main: steps, time, throughput | 64," in report

    train_ppo.main([*common, "--resume", "--timesteps", "192", "--seed", "5"])
    resumed = PPO.load(out / "model.zip", device="cpu")
    assert resumed.num_timesteps == 192
    with open(out / "vecnormalize.pkl", "rb") as file:
        assert pickle.load(file).obs_rms.count > count + 63  # continued the saved statistics
    report = (out / "training.md").read_text()
    assert "| timesteps, this command / total | 64 / 192 |" in report and "warm-up" not in report
    with pytest.raises(ValueError, match="timesteps = 192"):
        train_ppo.main([*common, "--resume", "--timesteps", "192"])
    with pytest.raises(ValueError, match="n_envs = 2"):
        train_ppo.main([*common, "--resume", "--timesteps", "256", "--n-envs", "2"])


def test_training_seeds_stay_below_evaluation_seeds(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="seed = 9990"):
        train_ppo.main(["--seed", "9990", "--n-envs", "16", "--out", str(tmp_path)])
