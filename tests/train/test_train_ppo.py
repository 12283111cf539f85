"""train/train_ppo.py: the hyperparameter file in rl-zoo3's layout, short runs that save, load and resume."""

from __future__ import annotations

import json
import pickle
from pathlib import Path

import gymnasium as gym
import numpy as np

import pytest
import yaml
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import VecNormalize

from agents.learned import LearnedPolicy
from agents.protocol import EVAL_SEED_START
from timegap_env import ENV_ID
from timegap_env.envs.sb3 import TimeGapVecEnv
from train import train_ppo

ROOT = Path(__file__).resolve().parents[2]


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
    assert sorted(p.name for p in out.iterdir()) == ["curve.csv", "curve.png", "env.json", "model.zip", "training.md",
                                                     "vecnormalize.pkl"]
    assert json.loads((out / "env.json").read_text()) == {"env_kwargs": {"config": {"episode_duration": 10.0}},
                                                          "frame_stack": 1}
    assert LearnedPolicy.load(out).action_mode == "platoon"
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
    curve = (out / "curve.csv").read_text().splitlines()
    assert curve[0] == "timesteps,mean_return,share_of_oracle_gap" and [row.split(",")[0] for row in curve[1:]][-2:] == [
        "128", "192"]  # the first run's end, then the resumed run's end
    with pytest.raises(ValueError, match="timesteps = 192"):
        train_ppo.main([*common, "--resume", "--timesteps", "192"])
    with pytest.raises(ValueError, match="n_envs = 2"):
        train_ppo.main([*common, "--resume", "--timesteps", "256", "--n-envs", "2"])


def test_a_relative_frame_stacked_run_is_loaded_as_it_was_trained(tmp_path: Path) -> None:
    hyperparams = tmp_path / "ppo.yml"
    hyperparams.write_text(yaml.safe_dump({ENV_ID: {
        "n_envs": 2, "n_timesteps": 32, "policy": "MlpPolicy", "normalize": True, "frame_stack": 3, "n_steps": 16,
        "batch_size": 32, "n_epochs": 1, "env_kwargs": {"config": {"episode_duration": 5.0, "action_mode": "relative"}},
    }}))
    out = tmp_path / "run"
    train_ppo.main(["--hyperparams", str(hyperparams), "--out", str(out), "--tensorboard-log", str(tmp_path / "runs"),
                    "--no-progress-bar", "--curve-freq", "16"])
    policy = LearnedPolicy.load(out)
    assert policy.action_mode == "relative" and policy.model.action_space.n == 3 and policy.frame_stack == 3
    assert len((out / "curve.csv").read_text().splitlines()) == 1 + 3  # at 16 and 32 steps, and the end
    env = gym.make_vec(ENV_ID, num_envs=2, vectorization_mode="vector_entry_point",
                       config={"episode_duration": 5.0, "action_mode": "relative"})
    obs, _ = env.reset(seed=[1, 2])
    action, stack = policy.predict(obs)
    assert action.shape == (2,) and stack.shape == (2, 3 * obs.shape[1]) and not stack[:, :-obs.shape[1]].any()
    obs, *_ = env.step(action)
    _, stack = policy.predict(obs, state=stack, episode_start=np.array([False, True]))
    assert stack[0, obs.shape[1]:2 * obs.shape[1]].any() and not stack[1, :-obs.shape[1]].any()


def test_env_config_overrides_merge_into_a_phase_config() -> None:
    kwargs = {"config": {"action_mode": "relative", "decision_interval": 5.0}, "max_episode_steps": 9}
    assert train_ppo.with_env_config(kwargs, {"action_mode": "platoon"}) == {
        "config": {"action_mode": "platoon", "decision_interval": 5.0}, "max_episode_steps": 9}
    assert train_ppo.with_env_config({}, {"action_mode": "platoon"}) == {"config": {"action_mode": "platoon"}}
    assert train_ppo.with_env_config(kwargs, {}) is kwargs


def test_training_seeds_stay_below_evaluation_seeds(tmp_path: Path) -> None:
    seed = EVAL_SEED_START - 10
    with pytest.raises(ValueError, match=f"seed = {seed}"):
        train_ppo.main(["--seed", str(seed), "--n-envs", "16", "--out", str(tmp_path)])
