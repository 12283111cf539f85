"""A trained SB3 model as a policy: loaded with or without its VecNormalize statistics, errors that name the file."""

import json
import pickle

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import DummyVecEnv, VecFrameStack, VecNormalize

import timegap_env
from timegap_env.agents.learned import LearnedPolicy, RunFileError
from timegap_env.envs.observation import FEATURES


def real_observation() -> np.ndarray:
    """A reset observation of the default env (5 * 9,)."""
    obs, _ = gym.make(timegap_env.ENV_ID).reset(seed=0)
    return obs


def with_feature(obs: np.ndarray, feature: str, value: float) -> np.ndarray:
    """``obs`` with one feature of every follower set to ``value``."""
    rows = obs.reshape(-1, len(FEATURES)).copy()
    rows[:, FEATURES.index(feature)] = value
    return rows.reshape(obs.shape)


def tiny_ppo(env) -> PPO:
    model = PPO("MlpPolicy", env, n_steps=64, batch_size=32, n_epochs=1, seed=0, device="cpu")
    return model.learn(64)


def write_env_file(run, normalize: bool, config: dict | None = None, frame_stack: int = 1) -> None:
    """The run's env.json, as train_ppo writes it."""
    (run / "env.json").write_text(json.dumps({"env_kwargs": {"config": config or {}}, "frame_stack": frame_stack,
                                              "normalize": normalize}))


def test_learned_policy_without_vecnormalize(tmp_path):
    env = gym.make(timegap_env.ENV_ID)
    model = tiny_ppo(env)
    model.save(tmp_path / "model.zip")
    write_env_file(tmp_path, normalize=False)
    policy = LearnedPolicy.load(tmp_path)
    assert policy.normalizer is None and policy.action_mode == "platoon"
    obs = real_observation()
    batch = np.stack([obs, with_feature(obs, "v2v", 0.0)])
    action, _ = policy.predict(obs)
    assert action.shape == () and env.action_space.contains(action)
    assert action == model.predict(obs, deterministic=True)[0]
    np.testing.assert_array_equal(policy.predict(batch)[0], model.predict(batch, deterministic=True)[0])


def test_learned_policy_applies_saved_vecnormalize_statistics(tmp_path):
    venv = VecNormalize(DummyVecEnv([lambda: gym.make(timegap_env.ENV_ID, config={"action_mode": "per_vehicle"})]))
    model = tiny_ppo(venv)
    model.save(tmp_path / "model.zip")
    venv.save(tmp_path / "vecnormalize.pkl")
    write_env_file(tmp_path, normalize=True, config={"action_mode": "per_vehicle"})
    policy = LearnedPolicy.load(tmp_path / "model.zip")
    assert policy.normalizer is not None and policy.action_mode == "per_vehicle"
    obs = real_observation()
    batch = np.stack([obs, with_feature(obs, "exceedances", 1.0)])
    venv.training = False
    np.testing.assert_allclose(policy.normalizer(batch), venv.normalize_obs(batch), rtol=1e-6)
    expected, _ = model.predict(venv.normalize_obs(batch), deterministic=True)
    np.testing.assert_array_equal(policy.predict(batch)[0], expected)
    assert policy.predict(obs)[0].shape == (5,)
    # statistics elsewhere, given explicitly
    (tmp_path / "vecnormalize.pkl").rename(tmp_path / "stats.pkl")
    assert LearnedPolicy.load(tmp_path, vecnormalize=tmp_path / "stats.pkl").normalizer is not None


def test_learned_policy_load_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="no model zip"):
        LearnedPolicy.load(tmp_path)
    tiny_ppo(gym.make(timegap_env.ENV_ID)).save(tmp_path / "model.zip")
    write_env_file(tmp_path, normalize=True)
    with pytest.raises(FileNotFoundError, match="vecnormalize = "):
        LearnedPolicy.load(tmp_path, vecnormalize=tmp_path / "missing.pkl")


def test_unusable_run_files_are_errors_that_name_the_file(tmp_path):
    venv = VecNormalize(DummyVecEnv([lambda: gym.make(timegap_env.ENV_ID)]))
    model = tiny_ppo(venv)
    model.save(tmp_path / "model.zip")
    venv.save(tmp_path / "vecnormalize.pkl")
    write_env_file(tmp_path, normalize=True)
    saved = (tmp_path / "model.zip").read_bytes()
    for corrupted in (saved[:len(saved) // 2], b"", b"not a zip"):
        (tmp_path / "model.zip").write_bytes(corrupted)
        with pytest.raises(RunFileError, match=r"model.zip'?: not a readable PPO model zip"):
            LearnedPolicy.load(tmp_path)
    (tmp_path / "model.zip").write_bytes(saved)
    stats = tmp_path / "vecnormalize.pkl"
    for corrupted, message in ((b"garbage", "not a readable pickle"), (b"", "not a readable pickle"),
                               (pickle.dumps([1.0, 2.0]), "holds a list, not a VecNormalize")):
        stats.write_bytes(corrupted)
        with pytest.raises(RunFileError, match=f"vecnormalize.pkl'?: {message}"):
            LearnedPolicy.load(tmp_path)
    smaller = {"platoon": {"n_followers": 4}}
    VecNormalize(DummyVecEnv([lambda: gym.make(timegap_env.ENV_ID, config=smaller)])).save(stats)
    with pytest.raises(RunFileError, match=r"vecnormalize.pkl'?: normalises observations of shape \(36,\), the model "
                                           r".*model.zip takes \(45,\)"):
        LearnedPolicy.load(tmp_path)
    stats.unlink()
    (tmp_path / "env.json").write_bytes(b"\xff\xfe")
    with pytest.raises(RunFileError, match="env.json: not readable JSON"):
        LearnedPolicy.load(tmp_path)
    (tmp_path / "env.json").write_text(json.dumps({"env_kwargs": {"config": {"action_mode": "per_vehicle"}},
                                                   "frame_stack": 1, "normalize": False}))
    with pytest.raises(RunFileError, match="env.json does not fit the model .*action_mode = 'per_vehicle'"):
        LearnedPolicy.load(tmp_path)


def test_a_frame_stacked_policy_takes_observations_of_the_env_shape(tmp_path):
    venv = VecNormalize(DummyVecEnv([lambda: gym.make(timegap_env.ENV_ID)]))
    tiny_ppo(VecFrameStack(venv, 2)).save(tmp_path / "model.zip")
    venv.save(tmp_path / "vecnormalize.pkl")
    (tmp_path / "env.json").write_text(json.dumps({"env_kwargs": {}, "frame_stack": 2}))
    policy = LearnedPolicy.load(tmp_path)
    assert policy.observation_shape == real_observation().shape == (45,)
    assert policy.model.observation_space.shape == (90,)
    (tmp_path / "env.json").write_text(json.dumps({"env_kwargs": {}, "frame_stack": 4}))
    with pytest.raises(RunFileError, match="frame_stack = 4: does not divide the model's observation width 90"):
        LearnedPolicy.load(tmp_path)
