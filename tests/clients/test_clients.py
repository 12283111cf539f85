"""``TimeGapMonitor-v0`` driven by the RL libraries the README names, each through its own public API (issue 14).

Slow (a few minutes in all) and needing the ``clients`` extra, whose ``ray[rllib]`` pins gymnasium to an older
release than the core venv's, so they run in their own venv: ``bash .ci/clients``. A test whose library is
missing skips and says how to install it.

Episodes are 20 decisions long (``episode_duration`` 20 s) so that every library sees whole episodes, and the
episode lengths each library reports are checked against the plain env's.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

from timegap_env import ENV_ID
from timegap_env.config import EnvConfig

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[2]
QUALIFIED_ID = f"timegap_env:{ENV_ID}"  # gymnasium imports timegap_env, which registers the id, in any process
SHORT = {"episode_duration": 20.0}  # [s]
EPISODE_STEPS = EnvConfig.from_dict(SHORT).max_episode_steps  # 20 decisions, 1 s apart
INSTALL = "needs the clients extra: pip install -e '.[clients]' (or run bash .ci/clients)"
KEEP_1_6_S = 5  # platoon action: index of 1.6 s in the default ladder 0.6, 0.8, ..., 2.2 s


def _plain_episode_length(seed: int = 0) -> int:
    """Steps of one episode of ``gym.make(ENV_ID, config=SHORT)`` at a fixed 1.6 s setting."""
    env = gym.make(ENV_ID, config=SHORT)
    env.reset(seed=seed)
    steps, done = 0, False
    while not done:
        _, _, terminated, truncated, _ = env.step(KEEP_1_6_S)
        steps, done = steps + 1, terminated or truncated
    return steps


def test_short_episodes_last_episode_steps() -> None:
    assert _plain_episode_length() == EPISODE_STEPS == 20


# --- Stable-Baselines3 and sb3-contrib ------------------------------------------------------------------------


@pytest.mark.parametrize("algo", ["PPO", "DQN", "A2C"])
def test_stable_baselines3_learns_then_evaluates_whole_episodes(algo: str) -> None:
    sb3 = pytest.importorskip("stable_baselines3", reason=INSTALL)
    from stable_baselines3.common.evaluation import evaluate_policy
    from stable_baselines3.common.monitor import Monitor

    small = {
        "PPO": {"n_steps": 32, "batch_size": 32, "n_epochs": 1},
        "DQN": {"learning_starts": 16, "buffer_size": 1_000, "train_freq": 4},
        "A2C": {"n_steps": 8},
    }[algo]
    model = getattr(sb3, algo)("MlpPolicy", gym.make(ENV_ID, config=SHORT), seed=0, device="cpu", **small)
    model.learn(total_timesteps=3 * EPISODE_STEPS)
    evaluation = Monitor(gym.make(ENV_ID, config=SHORT))
    evaluation.reset(seed=0)  # the evaluation's episodes carry on this seed's stream
    returns, lengths = evaluate_policy(model, evaluation, n_eval_episodes=2, return_episode_rewards=True)
    assert lengths == [EPISODE_STEPS, EPISODE_STEPS]
    assert np.all(np.isfinite(returns))


def test_sb3_contrib_recurrent_ppo_carries_its_lstm_state_through_an_episode() -> None:
    sb3_contrib = pytest.importorskip("sb3_contrib", reason=INSTALL)
    model = sb3_contrib.RecurrentPPO("MlpLstmPolicy", gym.make(ENV_ID, config=SHORT), n_steps=32, batch_size=32,
                                     n_epochs=1, seed=0, device="cpu")
    model.learn(total_timesteps=64)
    env = gym.make(ENV_ID, config=SHORT)
    obs, _ = env.reset(seed=0)
    state, episode_start, steps, done = None, np.ones(1, dtype=bool), 0, False
    while not done:
        action, state = model.predict(obs, state=state, episode_start=episode_start, deterministic=True)
        obs, _, terminated, truncated, _ = env.step(action)
        episode_start, steps, done = np.zeros(1, dtype=bool), steps + 1, terminated or truncated
    assert steps == EPISODE_STEPS
    assert state is not None and state[0].shape[-1] == model.policy.lstm_hidden_state_shape[-1]


def test_sb3_subproc_vec_env_makes_the_env_from_its_qualified_id_in_fresh_workers() -> None:
    """``spawn`` workers start a new interpreter that never imported timegap_env: the id must do it."""
    pytest.importorskip("stable_baselines3", reason=INSTALL)
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import SubprocVecEnv

    venv = make_vec_env(QUALIFIED_ID, n_envs=2, seed=0, env_kwargs={"config": SHORT}, vec_env_cls=SubprocVecEnv,
                        vec_env_kwargs={"start_method": "spawn"})
    try:
        model = PPO("MlpPolicy", venv, n_steps=EPISODE_STEPS, batch_size=EPISODE_STEPS, n_epochs=1, seed=0,
                    device="cpu")
        model.learn(total_timesteps=2 * 2 * EPISODE_STEPS)  # two rollouts of one whole episode per worker
        lengths = [episode["l"] for episode in model.ep_info_buffer]  # from the workers' Monitor wrappers
    finally:
        venv.close()
    assert lengths == [EPISODE_STEPS] * 4


# --- Gymnasium: env checker, wrappers, RecordVideo -------------------------------------------------------------


def test_gymnasium_env_checker_passes_with_rendering() -> None:
    from gymnasium.utils.env_checker import check_env

    check_env(gym.make(ENV_ID, config=SHORT, render_mode="rgb_array").unwrapped)


def test_gymnasium_wrappers_stack_on_the_env() -> None:
    limit = EPISODE_STEPS // 2
    env = gym.make(ENV_ID, config=SHORT, max_episode_steps=limit)  # gym.make's TimeLimit cuts the episode first
    env = gym.wrappers.RecordEpisodeStatistics(env)
    env = gym.wrappers.NormalizeReward(gym.wrappers.NormalizeObservation(env))
    env = gym.wrappers.FlattenObservation(gym.wrappers.FrameStackObservation(env, stack_size=4))
    obs_dim = env.unwrapped.observation_space.shape[0]
    obs, _ = env.reset(seed=0)
    assert obs.shape == (4 * obs_dim,)
    env.action_space.seed(0)
    steps, terminated, truncated = 0, False, False
    while not (terminated or truncated):
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        steps += 1
        assert obs.shape == (4 * obs_dim,) and np.all(np.isfinite(obs)) and np.isfinite(reward)
    assert truncated and not terminated and steps == limit
    assert info["episode"]["l"] == limit


def test_gymnasium_vector_wrappers_on_the_native_vector_env() -> None:
    n = 2
    envs = gym.make_vec(ENV_ID, num_envs=n, vectorization_mode="vector_entry_point", config=SHORT)
    envs = gym.wrappers.vector.DictInfoToList(gym.wrappers.vector.RecordEpisodeStatistics(envs))
    envs.reset(seed=0)
    for _ in range(EPISODE_STEPS):
        _, _, terminated, truncated, infos = envs.step(np.full(n, KEEP_1_6_S))
    assert isinstance(infos, list) and len(infos) == n
    assert np.all(truncated) and not np.any(terminated)
    assert [info["episode"]["l"] for info in infos] == [EPISODE_STEPS] * n


def test_gymnasium_vector_observation_wrappers_need_next_step_autoreset() -> None:
    """Gymnasium's vector observation wrappers refuse same-step autoreset (they would leave ``final_obs``
    untransformed); the native vector env made with ``autoreset_mode="next_step"`` takes them."""
    n = 2
    envs = gym.make_vec(ENV_ID, num_envs=n, vectorization_mode="vector_entry_point", config=SHORT,
                        autoreset_mode="next_step")
    assert envs.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
    envs = gym.wrappers.vector.NormalizeObservation(envs)
    envs.reset(seed=0)
    for _ in range(EPISODE_STEPS):
        obs, _, terminated, truncated, _ = envs.step(np.full(n, KEEP_1_6_S))
    assert np.all(truncated) and not np.any(terminated)
    obs, rewards, terminated, truncated, _ = envs.step(np.full(n, KEEP_1_6_S))  # next step: the resets
    assert np.all(rewards == 0) and not np.any(terminated | truncated)
    assert obs.shape == (n, *envs.single_observation_space.shape) and np.all(np.isfinite(obs))


def test_record_video_writes_one_episode(tmp_path: Path) -> None:
    pytest.importorskip("moviepy", reason=INSTALL)
    env = gym.make(ENV_ID, config=SHORT, render_mode="rgb_array")
    env = gym.wrappers.RecordVideo(env, video_folder=str(tmp_path), episode_trigger=lambda episode: episode == 0,
                                   disable_logger=True)
    env.reset(seed=0)
    done = False
    while not done:
        _, _, terminated, truncated, _ = env.step(KEEP_1_6_S)
        done = terminated or truncated
    env.close()
    videos = sorted(tmp_path.glob("*.mp4"))
    assert len(videos) == 1 and videos[0].stat().st_size > 0
    from moviepy import VideoFileClip

    with VideoFileClip(str(videos[0])) as clip:  # a frame at reset and after each step, at render_fps
        assert clip.duration == pytest.approx((EPISODE_STEPS + 1) / env.metadata["render_fps"], abs=0.15)


# --- CleanRL-style loop over gymnasium.make_vec ------------------------------------------------------------------


def _assert_info_masks(infos: dict[str, Any], n: int, where: str = "infos") -> None:
    """Every key of a vector env's infos has its ``_key`` mask, a bool array (n,); nested dicts too."""
    for key, value in infos.items():
        if key.startswith("_"):
            continue
        mask = infos.get(f"_{key}")
        assert mask is not None, f"{where}[{key!r}] has no mask {where}['_{key}']"
        assert isinstance(mask, np.ndarray) and mask.dtype == bool and mask.shape == (n,), \
            f"{where}['_{key}'] = {mask!r}: must be a bool array of shape ({n},)"
        if isinstance(value, dict):
            _assert_info_masks(value, n, f"{where}[{key!r}]")


@pytest.mark.parametrize("mode", ["sync", "vector_entry_point"])
def test_cleanrl_style_loop_reads_final_obs_and_info_masks(mode: str) -> None:
    """The loop of CleanRL's PPO: the true next observation of a finished episode is ``infos["final_obs"][i]``."""
    n = 3
    same_step = {"vector_kwargs": {"autoreset_mode": AutoresetMode.SAME_STEP}} if mode == "sync" else \
        {"autoreset_mode": "same_step"}  # CleanRL's loop reads final_obs, which same-step autoresets give
    envs = gym.make_vec(ENV_ID, num_envs=n, vectorization_mode=mode, config=SHORT, **same_step)
    assert envs.metadata["autoreset_mode"] == AutoresetMode.SAME_STEP
    space = envs.single_observation_space
    _, infos = envs.reset(seed=0)
    _assert_info_masks(infos, n)
    envs.action_space.seed(0)
    lengths, finished = np.zeros(n, dtype=np.int64), []
    for _ in range(2 * EPISODE_STEPS):
        next_obs, rewards, terminated, truncated, infos = envs.step(envs.action_space.sample())
        _assert_info_masks(infos, n)
        assert next_obs.dtype == np.float32 and next_obs.shape == (n, *space.shape)
        lengths += 1
        done = terminated | truncated
        real_next_obs = next_obs.copy()
        if done.any():
            assert np.array_equal(infos["_final_obs"], done)
            for i in np.flatnonzero(done):
                row = infos["final_obs"][i]
                assert isinstance(row, np.ndarray) and row.dtype == np.float32 and row.shape == space.shape, \
                    f"infos['final_obs'][{i}] = {row!r}: must be a float32 array of shape {space.shape}"
                assert space.contains(row)
                real_next_obs[i] = row
            finished += lengths[done].tolist()
            lengths[done] = 0
        else:
            assert "final_obs" not in infos
        assert np.all(np.isfinite(real_next_obs)) and np.all(np.isfinite(rewards))
    assert finished == [EPISODE_STEPS] * (2 * n)
    envs.close()


# --- TorchRL ------------------------------------------------------------------------------------------------------


def test_torchrl_gym_env_rolls_out_one_env() -> None:
    torchrl_envs = pytest.importorskip("torchrl.envs", reason=INSTALL)
    from torchrl.envs.utils import check_env_specs

    env = torchrl_envs.GymEnv(ENV_ID, config=SHORT)
    check_env_specs(env)
    rollout = env.rollout(EPISODE_STEPS + 5, break_when_any_done=False)
    done = rollout["next", "done"].reshape(-1).numpy()
    assert np.flatnonzero(done).tolist() == [EPISODE_STEPS - 1]


def test_torchrl_gym_env_rolls_out_three_envs() -> None:
    """``num_envs`` makes a gymnasium ``AsyncVectorEnv`` whose workers are spawned: they import timegap_env
    through the qualified id."""
    torchrl_envs = pytest.importorskip("torchrl.envs", reason=INSTALL)
    from torchrl.envs.utils import check_env_specs

    env = torchrl_envs.GymEnv(QUALIFIED_ID, num_envs=3, config=SHORT)
    try:
        check_env_specs(env)
        rollout = env.rollout(EPISODE_STEPS + 5, break_when_any_done=False)
    finally:
        env.close()
    assert rollout.batch_size == (3, EPISODE_STEPS + 5)
    done = rollout["next", "done"].reshape(3, -1).numpy()
    assert [np.flatnonzero(row).tolist() for row in done] == [[EPISODE_STEPS - 1]] * 3


def test_torchrl_auto_register_info_dict_reads_every_info_key() -> None:
    torchrl_envs = pytest.importorskip("torchrl.envs", reason=INSTALL)
    env = gym.make(ENV_ID, config=SHORT)
    _, reset_info = env.reset(seed=0)
    _, _, _, _, step_info = env.step(KEEP_1_6_S)
    assert set(step_info) == set(reset_info), "TorchRL reads the keys of reset's info on every step"
    for key, value in reset_info.items():
        assert np.asarray(value).dtype.kind in "biuf", f"info[{key!r}] = {value!r}: TorchRL needs numbers"
    wrapped = torchrl_envs.GymEnv(ENV_ID, config=SHORT).auto_register_info_dict()
    rollout = wrapped.rollout(EPISODE_STEPS + 5, break_when_any_done=False)
    for key, value in reset_info.items():
        assert rollout["next", key].shape == (EPISODE_STEPS + 5, *np.shape(value)), key


# --- Tianshou -----------------------------------------------------------------------------------------------------


def test_tianshou_collects_whole_episodes_and_trains_dqn() -> None:
    pytest.importorskip("tianshou", reason=INSTALL)
    from tianshou.algorithm import DQN
    from tianshou.algorithm.modelfree.dqn import DiscreteQLearningPolicy
    from tianshou.algorithm.optim import AdamOptimizerFactory
    from tianshou.data import Collector, CollectStats, VectorReplayBuffer
    from tianshou.env import DummyVectorEnv
    from tianshou.trainer import OffPolicyTrainerParams
    from tianshou.utils.net.common import Net

    n = 2
    envs = DummyVectorEnv([lambda: gym.make(ENV_ID, config=SHORT) for _ in range(n)])
    envs.seed(0)
    env = gym.make(ENV_ID, config=SHORT)
    net = Net(state_shape=env.observation_space.shape, action_shape=int(env.action_space.n), hidden_sizes=[32])
    policy = DiscreteQLearningPolicy(model=net, action_space=env.action_space, eps_training=0.1)
    algorithm = DQN(policy=policy, optim=AdamOptimizerFactory(lr=1e-3), target_update_freq=EPISODE_STEPS)
    collector = Collector[CollectStats](algorithm, envs, VectorReplayBuffer(1_000, n), exploration_noise=True)
    collector.reset()
    stats = collector.collect(n_step=n * EPISODE_STEPS)
    assert stats.n_collected_episodes == n and stats.lens.tolist() == [EPISODE_STEPS] * n
    result = algorithm.run_training(OffPolicyTrainerParams(
        training_collector=collector, test_collector=None, max_epochs=1, epoch_num_steps=4 * EPISODE_STEPS,
        collection_step_num_env_steps=10, batch_size=16, update_step_num_gradient_steps_per_sample=0.1,
    ))
    assert result.train_step >= 4 * EPISODE_STEPS and result.update_step > 0 and result.train_episode >= 2 * n
    envs.close()


# --- rl-zoo3 ------------------------------------------------------------------------------------------------------


def test_rl_zoo3_trains_from_the_repository_yml(tmp_path: Path) -> None:
    """``python -m rl_zoo3.train`` reads hyperparams/ppo.yml as it is; only its size is cut down from the CLI."""
    pytest.importorskip("rl_zoo3", reason=INSTALL)
    command = [
        sys.executable, "-m", "rl_zoo3.train", "--algo", "ppo", "--env", ENV_ID, "--gym-packages", "timegap_env",
        "-c", str(REPO / "hyperparams" / "ppo.yml"), "-n", "64", "--hyperparams", "n_envs:2", "n_steps:32",
        "batch_size:32", "n_epochs:1", "--eval-freq", "-1", "--seed", "0", "--device", "cpu", "-f", str(tmp_path),
    ]
    run = subprocess.run(command, cwd=tmp_path, capture_output=True, text=True, timeout=600)
    output = run.stdout[-3000:] + run.stderr[-3000:]
    assert run.returncode == 0, f"{' '.join(command)} exited {run.returncode}:\n{output}"
    folder = tmp_path / "ppo" / f"{ENV_ID}_1"
    assert (folder / f"{ENV_ID}.zip").is_file()
    assert (folder / ENV_ID / "vecnormalize.pkl").is_file()  # the yml's normalize: true


# --- Ray RLlib (new API stack) --------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def ray_cluster() -> Any:
    ray = pytest.importorskip("ray", reason=INSTALL)
    pytest.importorskip("ray.rllib", reason=INSTALL)
    ray.init(num_cpus=2, include_dashboard=False)
    yield ray
    ray.shutdown()


def _rllib_episode_lengths(env: str, env_config: dict[str, Any], vectorize_mode: str = "sync") -> list[int]:
    """Train PPO two iterations on one remote EnvRunner with two sub-envs; return each iteration's min and max
    episode length [steps] as RLlib reports them."""
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.utils.metrics import ENV_RUNNER_RESULTS, EPISODE_LEN_MAX, EPISODE_LEN_MIN, NUM_EPISODES

    config = (
        PPOConfig()
        .environment(env, env_config=env_config)
        .env_runners(num_env_runners=1, num_envs_per_env_runner=2, gym_env_vectorize_mode=vectorize_mode)
        .training(train_batch_size_per_learner=8 * EPISODE_STEPS, minibatch_size=4 * EPISODE_STEPS, num_epochs=1)
        .debugging(seed=0)
    )
    algo = config.build_algo()
    try:
        results = [algo.train()[ENV_RUNNER_RESULTS] for _ in range(2)]
    finally:
        algo.stop()
    assert all(result[NUM_EPISODES] > 0 for result in results)
    return [int(result[key]) for result in results for key in (EPISODE_LEN_MIN, EPISODE_LEN_MAX)]


def test_rllib_ppo_makes_the_env_from_its_qualified_id_in_its_workers(ray_cluster: Any) -> None:
    """The EnvRunner actors are other processes: ``import timegap_env`` in the driver registers nothing there."""
    lengths = _rllib_episode_lengths(QUALIFIED_ID, {"config": SHORT})
    assert lengths == [_plain_episode_length()] * 4


def test_rllib_ppo_with_the_env_registered_through_tune(ray_cluster: Any) -> None:
    from ray.tune.registry import register_env

    register_env(ENV_ID, lambda env_config: gym.make(QUALIFIED_ID, **env_config))  # sent to the workers
    lengths = _rllib_episode_lengths(ENV_ID, {"config": SHORT})
    assert lengths == [_plain_episode_length()] * 4


def test_rllib_ppo_on_the_native_vector_env_with_next_step_autoreset(ray_cluster: Any) -> None:
    """RLlib's SingleAgentEnvRunner assumes next-step autoreset (it takes the observation after a finished step
    as the next episode's first); the native vector env's default is same-step, so RLlib needs ``next_step``."""
    env_config = {"config": SHORT, "autoreset_mode": "next_step"}
    envs = gym.make_vec(ENV_ID, num_envs=2, vectorization_mode="vector_entry_point", **env_config)
    assert envs.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
    lengths = _rllib_episode_lengths(QUALIFIED_ID, env_config, vectorize_mode="vector_entry_point")
    assert lengths == [_plain_episode_length()] * 4
