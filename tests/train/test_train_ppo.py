"""train/train_ppo.py: the hyperparameter file in rl-zoo3's layout, short runs that save, load and resume."""

from __future__ import annotations

import inspect
import json
import pickle
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np

import pytest
import torch
import yaml
from stable_baselines3 import PPO
from stable_baselines3.common.logger import configure
from stable_baselines3.common.vec_env import VecNormalize

from timegap_env.agents.learned import LearnedPolicy, RunFileError
from timegap_env.agents.protocol import EVAL_SEED_START, read_env_file
from timegap_env import DEFAULT_TASK, TASKS
from timegap_env.envs.observation import FEATURES, MONITOR_FEATURES
from timegap_env.envs.sb3 import TimeGapVecEnv
from timegap_env.studies import training
from train import train_ppo

ROOT = Path(__file__).resolve().parents[2]


def test_hyperparams_have_rl_zoo3_layout() -> None:
    with open(ROOT / "hyperparams" / "ppo.yml") as file:
        document = yaml.safe_load(file)
    assert list(document) == list(TASKS)  # a section per task
    for env_id, hyperparams in document.items():
        for key in ("n_envs", "n_timesteps", "policy", "normalize", "n_steps", "batch_size", "gamma", "learning_rate",
                    "ent_coef", "policy_kwargs"):
            assert key in hyperparams, key
        assert isinstance(hyperparams["policy_kwargs"], str)
        assert hyperparams["n_steps"] * hyperparams["n_envs"] % hyperparams["batch_size"] == 0
        loaded = train_ppo.load_hyperparams(ROOT / "hyperparams" / "ppo.yml", env_id)
        assert isinstance(loaded["policy_kwargs"], dict)


# What rl-zoo3 (2.9, ExperimentManager._preprocess_hyperparams) takes out of a hyperparameter entry before passing
# the rest to the algorithm; it passes env, seed, tensorboard_log, verbose and device itself.
RL_ZOO3_RUN_KEYS = {"n_envs", "n_timesteps", "policy", "normalize", "frame_stack", "env_wrapper", "vec_env_wrapper",
                    "callback", "env_kwargs", "monitor_kwargs"}
RL_ZOO3_SETS = {"self", "env", "seed", "tensorboard_log", "verbose", "device"}


def test_rl_zoo3_understands_every_key_of_the_hyperparams() -> None:
    with open(ROOT / "hyperparams" / "ppo.yml") as file:
        hyperparams = yaml.safe_load(file)[DEFAULT_TASK]
    ppo_arguments = set(inspect.signature(PPO.__init__).parameters) - RL_ZOO3_SETS
    unknown = set(hyperparams) - RL_ZOO3_RUN_KEYS - ppo_arguments
    assert not unknown, f"keys rl-zoo3 would pass to PPO.__init__, which does not take them: {sorted(unknown)}"
    # rl-zoo3 evaluates a string policy_kwargs in a module that imported torch's nn
    assert isinstance(eval(hyperparams["policy_kwargs"], {"nn": torch.nn}), dict)
    assert training.RUN_KEYS <= RL_ZOO3_RUN_KEYS


def test_the_shipped_warmup_is_the_one_the_committed_model_was_trained_with() -> None:
    steps, env_kwargs = train_ppo.load_warmup(ROOT / "hyperparams" / "ppo_warmup.yml")
    assert steps == 150_000  # results/v0/ppo/training.md: warm-up 151,552 steps (whole rollouts of 4096)
    assert env_kwargs == {"config": {"decision_interval": 5.0, "action_mode": "relative", "random_initial_setting": True}}


def test_warmup_errors_name_the_file(tmp_path: Path) -> None:
    path = tmp_path / "warmup.yml"
    path.write_text(yaml.safe_dump({DEFAULT_TASK: {"n_timesteps": 0, "env_kwargs": {}}}))
    with pytest.raises(ValueError, match="n_timesteps = 0 in .*warmup.yml"):
        train_ppo.load_warmup(path)
    path.write_text(yaml.safe_dump({DEFAULT_TASK: {"n_timesteps": 10}}))
    with pytest.raises(ValueError, match="warmup.yml: needs exactly the keys"):
        train_ppo.load_warmup(path)


def test_hyperparams_errors_name_the_field(tmp_path: Path) -> None:
    path = tmp_path / "bad.yml"
    path.write_text(yaml.safe_dump({DEFAULT_TASK: {"n_envs": 2, "n_timesteps": 10, "policy": "MlpPolicy", "n_stpes": 8}}))
    with pytest.raises(ValueError, match="n_stpes"):
        train_ppo.load_hyperparams(path)
    path.write_text(yaml.safe_dump({"CartPole-v1": {}}))
    with pytest.raises(ValueError, match=DEFAULT_TASK):
        train_ppo.load_hyperparams(path)
    path.write_text(yaml.safe_dump({DEFAULT_TASK: {"n_envs": 2, "n_timesteps": 10, "policy": "MlpPolicy",
                                             "warmup": {"n_timesteps": 5, "env_kwargs": {}}}}))
    with pytest.raises(ValueError, match="warm-up moved to its own file"):  # a yml of before the move
        train_ppo.load_hyperparams(path)


def test_tiny_training_run_saves_loads_and_resumes(tmp_path: Path) -> None:
    hyperparams = tmp_path / "ppo.yml"
    hyperparams.write_text(yaml.safe_dump({DEFAULT_TASK: {
        "n_envs": 4, "n_timesteps": 128, "policy": "MlpPolicy", "normalize": True, "n_steps": 16, "batch_size": 32,
        "n_epochs": 1, "policy_kwargs": "dict(net_arch=[16])", "env_kwargs": {"config": {"episode_duration": 10.0}},
    }}))
    warmup = tmp_path / "warmup.yml"
    warmup.write_text(yaml.safe_dump({DEFAULT_TASK: {
        "n_timesteps": 64, "env_kwargs": {"config": {"episode_duration": 10.0, "decision_interval": 5.0}}}}))
    out = tmp_path / "run"
    common = ["--hyperparams", str(hyperparams), "--warmup", str(warmup), "--out", str(out), "--tensorboard-log",
              str(tmp_path / "runs"), "--no-progress-bar", "--checkpoint-freq", "32"]
    train_ppo.main(common)
    assert sorted(p.name for p in out.iterdir()) == ["curve.csv", "curve.png", "env.json", "model.zip", "training.md",
                                                     "vecnormalize.pkl"]
    assert json.loads((out / "env.json").read_text()) == {"env_kwargs": {"config": {"episode_duration": 10.0}},
                                                          "frame_stack": 1, "normalize": True, "env_id": DEFAULT_TASK,
                                                          "hidden_features": [], "algo": "ppo"}
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
    assert "| timesteps, this command / total | 64 / 192 |" in report and "| warm-up, {" not in report
    curve = (out / "curve.csv").read_text().splitlines()
    assert curve[0] == "timesteps,mean_return,share_of_oracle_gap,best_blind_return,oracle_return" and [row.split(",")[0] for row in curve[1:]][-2:] == [
        "128", "192"]  # the first run's end, then the resumed run's end
    with pytest.raises(ValueError, match="timesteps = 192"):
        train_ppo.main([*common, "--resume", "--timesteps", "192"])
    with pytest.raises(ValueError, match="n_envs = 2"):
        train_ppo.main([*common, "--resume", "--timesteps", "256", "--n-envs", "2"])


def test_a_relative_frame_stacked_run_is_loaded_as_it_was_trained(tmp_path: Path) -> None:
    hyperparams = tmp_path / "ppo.yml"
    hyperparams.write_text(yaml.safe_dump({DEFAULT_TASK: {
        "n_envs": 2, "n_timesteps": 32, "policy": "MlpPolicy", "normalize": True, "frame_stack": 3, "n_steps": 16,
        "batch_size": 32, "n_epochs": 1, "env_kwargs": {"config": {"episode_duration": 5.0, "action_mode": "relative"}},
    }}))
    out = tmp_path / "run"
    train_ppo.main(["--hyperparams", str(hyperparams), "--out", str(out), "--tensorboard-log", str(tmp_path / "runs"),
                    "--no-progress-bar", "--curve-freq", "16"])
    policy = LearnedPolicy.load(out)
    assert policy.action_mode == "relative" and policy.model.action_space.n == 3 and policy.frame_stack == 3
    assert len((out / "curve.csv").read_text().splitlines()) == 1 + 3  # at 16 and 32 steps, and the end
    env = gym.make_vec(DEFAULT_TASK, num_envs=2, vectorization_mode="vector_entry_point",
                       config={"episode_duration": 5.0, "action_mode": "relative"})
    obs, _ = env.reset(seed=[1, 2])
    action, stack = policy.predict(obs)
    assert action.shape == (2,) and stack.shape == (2, 3 * obs.shape[1]) and not stack[:, :-obs.shape[1]].any()
    obs, *_ = env.step(action)
    _, stack = policy.predict(obs, state=stack, episode_start=np.array([False, True]))
    assert stack[0, obs.shape[1]:2 * obs.shape[1]].any() and not stack[1, :-obs.shape[1]].any()


def test_episode_summaries_reach_the_logger() -> None:
    venv = TimeGapVecEnv(2, {"episode_duration": 3.0})
    model = PPO("MlpPolicy", venv, n_steps=8, batch_size=16, device="cpu")
    model.set_logger(configure(None, []))
    callback = train_ppo.EpisodeSummaries()
    callback.init_callback(model)
    venv.reset()
    dones = np.zeros(2, dtype=bool)
    while not dones.any():
        _, _, dones, infos = venv.step(np.ones(2, dtype=np.int64))
    callback.update_locals({"infos": infos})
    callback.on_step()
    assert {f"episode/{name}" for name in train_ppo.SUMMARY_KEYS} <= set(model.logger.name_to_value)


def test_env_config_overrides_merge_into_a_phase_config() -> None:
    kwargs = {"config": {"action_mode": "relative", "decision_interval": 5.0}, "max_episode_steps": 9}
    assert train_ppo.with_env_config(kwargs, {"action_mode": "platoon"}) == {
        "config": {"action_mode": "platoon", "decision_interval": 5.0}, "max_episode_steps": 9}
    assert train_ppo.with_env_config({}, {"action_mode": "platoon"}) == {"config": {"action_mode": "platoon"}}
    assert train_ppo.with_env_config(kwargs, {}) is kwargs


def test_env_config_repeats_merge_left_to_right() -> None:
    args = train_ppo.parse_args(["--env-config", '{"monitor": {"estimator": "bayes"}, "n_followers": 3}',
                                 "--env-config", '{"monitor": {"estimator": "raw_gap"}}'])
    assert args.env_config == {"monitor": {"estimator": "raw_gap"}, "n_followers": 3}
    assert train_ppo.parse_args([]).env_config == {}


def test_training_seeds_stay_below_evaluation_seeds(tmp_path: Path) -> None:
    seed = EVAL_SEED_START - 10
    with pytest.raises(ValueError, match=f"seed = {seed}"):
        train_ppo.main(["--seed", str(seed), "--n-envs", "16", "--out", str(tmp_path)])


def tiny_run(tmp_path: Path) -> list[str]:
    """Arguments of a tiny run in ``tmp_path`` (2 platoons, 5 s episodes, normalised), with the shipped warm-up."""
    hyperparams = tmp_path / "ppo.yml"
    hyperparams.write_text(yaml.safe_dump({DEFAULT_TASK: {
        "n_envs": 2, "n_timesteps": 32, "policy": "MlpPolicy", "normalize": True, "n_steps": 16, "batch_size": 32,
        "n_epochs": 1, "env_kwargs": {"config": {"episode_duration": 5.0}},
    }}))
    return ["--hyperparams", str(hyperparams), "--warmup", str(ROOT / "hyperparams" / "ppo_warmup.yml"),
            "--out", str(tmp_path / "run"), "--tensorboard-log", str(tmp_path / "runs"), "--no-progress-bar"]


def test_a_run_shorter_than_the_warmup_trains_without_it_and_resumes_only_from_usable_files(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # the docstring's short run: --timesteps 20000 with the shipped warm-up of 150 000 steps
    common = tiny_run(tmp_path)
    out = tmp_path / "run"
    train_ppo.main([*common, "--timesteps", "32"])
    assert "timesteps = 32 is no more than the warm-up's 150000" in capsys.readouterr().out
    report = (out / "training.md").read_text()
    assert "| timesteps, this command / total | 32 / 32 |" in report and "| warm-up, {" not in report
    assert "| hyperparameters, warm-up | " in report and "`, none |" in report

    model, stats = (out / "model.zip").read_bytes(), (out / "vecnormalize.pkl").read_bytes()
    resume = [*common, "--resume", "--timesteps", "64"]
    (out / "model.zip").write_bytes(model[:len(model) // 2])
    with pytest.raises(RunFileError, match="model.zip'?: not a readable PPO model zip"):
        train_ppo.main(resume)
    (out / "model.zip").write_bytes(b"garbage")
    with pytest.raises(RunFileError, match="model.zip'?: not a readable PPO model zip"):
        train_ppo.main(resume)
    (out / "model.zip").write_bytes(model)
    (out / "vecnormalize.pkl").write_bytes(b"garbage")
    with pytest.raises(RunFileError, match="vecnormalize.pkl'?: not a readable pickle"):
        train_ppo.main(resume)
    (out / "vecnormalize.pkl").write_bytes(pickle.dumps({"obs_rms": None}))
    with pytest.raises(RunFileError, match="vecnormalize.pkl'?: holds a dict"):
        train_ppo.main(resume)
    VecNormalize(TimeGapVecEnv(2, {"episode_duration": 5.0, "platoon": {"n_followers": 4}})).save(
        out / "vecnormalize.pkl")
    with pytest.raises(RunFileError, match=r"vecnormalize.pkl normalises observations of shape \(36,\), the env "
                                           r"gives \(45,\)"):
        train_ppo.main(resume)
    with pytest.raises(RunFileError, match=r"model.zip takes observations of shape \(45,\), the env gives \(36,\)"):
        train_ppo.main([*resume, "--env-config", '{"platoon": {"n_followers": 4}}'])
    (out / "vecnormalize.pkl").unlink()
    with pytest.raises(FileNotFoundError, match="no statistics .*vecnormalize.pkl"):
        train_ppo.main(resume)
    (out / "vecnormalize.pkl").write_bytes(stats)
    train_ppo.main(resume)  # the files restored: the run continues
    assert PPO.load(out / "model.zip", device="cpu").num_timesteps == 64


def test_the_command_line_names_a_corrupted_checkpoint_without_a_traceback(tmp_path: Path) -> None:
    common = tiny_run(tmp_path)
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "model.zip").write_bytes(b"garbage")
    (tmp_path / "run" / "vecnormalize.pkl").write_bytes(b"garbage")
    done = subprocess.run([sys.executable, "-m", "train.train_ppo", *common, "--resume"], cwd=ROOT,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 1
    assert "Traceback" not in done.stderr and f"{tmp_path / 'run' / 'model.zip'}" in done.stderr
    assert "not a readable PPO model zip" in done.stderr


def test_a_run_names_its_env_and_loading_builds_that_version(tmp_path: Path) -> None:
    """A v1 run's env.json names TimeGapMonitor-v1, and its config is v1's defaults with the run's overrides; an
    env.json naming an unknown id is refused, naming it."""
    v1 = "TimeGapMonitor-v1"
    hyperparams = tmp_path / "ppo.yml"
    hyperparams.write_text(yaml.safe_dump({v1: {
        "n_envs": 2, "n_timesteps": 32, "policy": "MlpPolicy", "normalize": False, "n_steps": 16, "batch_size": 32,
        "n_epochs": 1, "policy_kwargs": "dict(net_arch=[8])", "env_kwargs": {"config": {"episode_duration": 10.0}},
    }}))
    out = tmp_path / "run"
    train_ppo.main(["--env-id", v1, "--hyperparams", str(hyperparams), "--no-warmup", "--out", str(out),
                    "--no-progress-bar", "--curve-freq", "0"])
    assert json.loads((out / "env.json").read_text())["env_id"] == v1
    config = read_env_file(out / "env.json").config
    assert config == gym.make(v1, config={"episode_duration": 10.0}).unwrapped.config
    assert config.reward_weights.preference == 0.0 and config == TASKS[v1].config(config)
    assert LearnedPolicy.load(out).action_mode == "platoon"
    resume = ["--hyperparams", str(hyperparams), "--no-warmup", "--out", str(out), "--no-progress-bar", "--resume",
              "--timesteps", "64"]
    with pytest.raises(ValueError, match="--resume: --hide-features \\['speed'\\], but .* trained with \\[\\]"):
        train_ppo.main(["--env-id", v1, "--hide-features", "speed", *resume])
    with pytest.raises(ValueError, match="--resume with --cost-budget"):
        train_ppo.main(["--env-id", v1, "--cost-budget", "0.1", *resume])
    (out / "env.json").write_text(json.dumps({"env_kwargs": {}, "frame_stack": 1, "env_id": "TimeGapMonitor-v9"}))
    with pytest.raises(RunFileError, match="env_id = 'TimeGapMonitor-v9'"):
        read_env_file(out / "env.json")


def test_hidden_features_are_hidden_in_training_and_when_loaded(tmp_path: Path) -> None:
    """--hide-features monitor: env.json names the six monitor features, the training env reads them as 0, and the
    loaded policy hides them too, so its actions do not depend on them."""
    hyperparams = tmp_path / "ppo.yml"
    hyperparams.write_text(yaml.safe_dump({DEFAULT_TASK: {
        "n_envs": 2, "n_timesteps": 32, "policy": "MlpPolicy", "normalize": True, "n_steps": 16, "batch_size": 32,
        "n_epochs": 1, "policy_kwargs": "dict(net_arch=[8])", "env_kwargs": {"config": {"episode_duration": 10.0}},
    }}))
    out = tmp_path / "run"
    train_ppo.main(["--hyperparams", str(hyperparams), "--no-warmup", "--out", str(out), "--no-progress-bar",
                    "--curve-freq", "0", "--hide-features", "monitor", "speed"])
    assert json.loads((out / "env.json").read_text())["hidden_features"] == [*MONITOR_FEATURES, "speed"]
    policy = LearnedPolicy.load(out)
    assert policy.hidden_features == (*MONITOR_FEATURES, "speed")
    env = TimeGapVecEnv(2, config={"episode_duration": 10.0}, hidden_features=policy.hidden_features)
    obs = env.reset().reshape(2, -1, len(FEATURES))
    assert np.all(obs[..., [FEATURES.index(name) for name in policy.hidden_features]] == 0)
    assert np.any(obs[..., FEATURES.index("setting")] != 0)
    rng = np.random.default_rng(0)
    columns = [FEATURES.index(name) for name in policy.hidden_features]
    for _ in range(5):  # what a hidden feature holds never changes the action
        seen = rng.uniform(0, 1, (2, 5, len(FEATURES))).astype(np.float32)
        other = seen.copy()
        other[..., columns] = rng.uniform(0, 1, (2, 5, len(columns)))
        assert np.array_equal(policy.predict(seen.reshape(2, -1))[0], policy.predict(other.reshape(2, -1))[0])
    with pytest.raises(ValueError, match="hidden_features = \\['radar'\\]"):
        TimeGapVecEnv(1, hidden_features=("radar",))


def test_a_cost_budget_trains_with_a_lagrange_multiplier(tmp_path: Path) -> None:
    """--cost-budget 0: every rollout's cost exceeds it, so the multiplier grows and takes the cost off the rewards."""
    hyperparams = tmp_path / "ppo.yml"
    hyperparams.write_text(yaml.safe_dump({"TimeGapMonitor-v1": {
        "n_envs": 2, "n_timesteps": 64, "policy": "MlpPolicy", "normalize": False, "n_steps": 16, "batch_size": 32,
        "n_epochs": 1, "policy_kwargs": "dict(net_arch=[8])", "env_kwargs": {"config": {"episode_duration": 10.0}},
    }}))
    out = tmp_path / "run"
    train_ppo.main(["--env-id", "TimeGapMonitor-v1", "--hyperparams", str(hyperparams), "--no-warmup", "--out", str(out),
                    "--no-progress-bar", "--curve-freq", "0", "--cost-budget", "0", "--lagrange-rate", "2"])
    row = next(line for line in (out / "training.md").read_text().splitlines() if line.startswith("| constrained"))
    assert float(row.rsplit(";", 1)[1].strip(" |")) > 0
    with pytest.raises(ValueError, match="cost_budget = -1.0"):
        train_ppo.main(["--cost-budget", "-1", "--out", str(tmp_path / "other")])


def test_a_collision_budget_penalises_the_collided_episodes_last_step_and_rises_with_the_rate() -> None:
    model = PPO("MlpPolicy", TimeGapVecEnv(3, {"episode_duration": 3.0}), n_steps=8, batch_size=24, device="cpu")
    model.set_logger(configure(None, []))
    callback = train_ppo.CollisionBudget(budget=0.25, rate=4.0)
    callback.init_callback(model)
    callback.multiplier = 2.0
    rewards = np.array([-1.0, -1.0, -1.0], dtype=np.float32)
    infos = [{"episode_collision": np.True_}, {"episode_collision": np.False_}, {}]
    callback.on_rollout_start()
    callback.update_locals({"rewards": rewards, "dones": np.array([True, True, False]), "infos": infos})
    callback.on_step()
    assert rewards.tolist() == [-3.0, -1.0, -1.0]  # the collided episode's step alone
    callback.on_rollout_end()
    assert callback.multiplier == pytest.approx(2.0 + 4.0 * (1 / 2 - 0.25))
    with pytest.raises(ValueError, match="collision_budget = 2.0"):
        train_ppo.main(["--collision-budget", "2", "--out", "/nonexistent/run"])


def test_the_adapter_takes_the_weighted_cost_off_its_rewards() -> None:
    envs = {weight: TimeGapVecEnv(2, config={"episode_duration": 10.0}, task_id="TimeGapMonitor-v1") for weight in (0.0, 3.0)}
    envs[3.0].cost_weight = 3.0
    for env in envs.values():
        env.seed(4)
        env.reset()
    for _ in range(10):
        steps = {weight: env.step(np.array([4, 4])) for weight, env in envs.items()}
        cost = envs[3.0].venv.step_cost
        np.testing.assert_allclose(steps[3.0][1], (steps[0.0][1] - 3.0 * cost).astype(np.float32), rtol=1e-6)


def test_a_recurrent_run_trains_and_loads_as_recurrent(tmp_path: Path) -> None:
    """--algo ppo_lstm: RecurrentPPO, env.json's algo, and a loaded policy that carries its LSTM state."""
    from sb3_contrib import RecurrentPPO

    hyperparams = tmp_path / "ppo_lstm.yml"
    hyperparams.write_text(yaml.safe_dump({"TimeGapMonitor-v1": {
        "n_envs": 2, "n_timesteps": 32, "policy": "MlpLstmPolicy", "normalize": True, "n_steps": 16, "batch_size": 32,
        "n_epochs": 1, "policy_kwargs": "dict(net_arch=[8], lstm_hidden_size=8)",
        "env_kwargs": {"config": {"episode_duration": 10.0}},
    }}))
    out = tmp_path / "run"
    train_ppo.main(["--algo", "ppo_lstm", "--env-id", "TimeGapMonitor-v1", "--hyperparams", str(hyperparams), "--no-warmup",
                    "--out", str(out), "--no-progress-bar", "--curve-freq", "0"])
    assert json.loads((out / "env.json").read_text())["algo"] == "ppo_lstm"
    policy = LearnedPolicy.load(out)
    assert isinstance(policy.model, RecurrentPPO)
    obs = np.zeros((2, 5 * len(FEATURES)), dtype=np.float32)
    _, state = policy.predict(obs)
    assert state is not None and len(state) == 2  # the LSTM's (hidden, cell), carried to the next step
    with pytest.raises(ValueError, match="frame_stack = 2 with --algo ppo_lstm"):
        train_ppo.main(["--algo", "ppo_lstm", "--env-id", "TimeGapMonitor-v1", "--hyperparams", str(hyperparams),
                        "--frame-stack", "2", "--out", str(tmp_path / "other")])


def test_the_shipped_recurrent_hyperparameters_load() -> None:
    from sb3_contrib import RecurrentPPO

    loaded = training.load_hyperparams(ROOT / "hyperparams" / "ppo_lstm.yml", "TimeGapMonitor-v1", RecurrentPPO)
    assert loaded["policy"] == "MlpLstmPolicy" and loaded["policy_kwargs"]["lstm_hidden_size"] == 64

