"""``python -m train.train_rllib`` and ``agents.rllib_policy`` (issue 15).

The settings and the runners' env are checked without Ray (fast, any venv); the end-to-end run needs the ``ray``
extra (``.venv-clients``, ``bash .ci/clients``) and is slow: a tiny run of two runners with two platoons each and
short episodes, its checkpoint loaded by :class:`RLlibPolicy` and its report holding the held-out returns.
"""

from __future__ import annotations

import json
import pickle
import re
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import yaml

from agents.learned import RunFileError
from agents.rllib_policy import CHECKPOINT_DIR, RLlibPolicy, find_checkpoint
from timegap_env import ENV_ID
from timegap_env.config import EnvConfig
from timegap_env.envs.observation import observation_space
from train.train_rllib import (
    REPORT_FILE,
    REWARD_SCALE,
    Settings,
    main,
    make_env,
    parse_args,
)

REPO = Path(__file__).resolve().parents[2]
PPO_YML = REPO / "hyperparams" / "ppo.yml"
SHORT = {"episode_duration": 20.0}  # [s]: 20 decisions
INSTALL = "needs the ray extra: pip install -e '.[ray]' (or run bash .ci/clients)"


def _yml(tmp_path: Path, **changes: object) -> Path:
    """hyperparams/ppo.yml with ``changes`` to its env section (None: key removed), written in ``tmp_path``."""
    document = yaml.safe_load(PPO_YML.read_text())
    section = document[ENV_ID]
    for key, value in changes.items():
        if value is None:
            section.pop(key)
        else:
            section[key] = value
    path = tmp_path / "ppo.yml"
    path.write_text(yaml.safe_dump(document))
    return path


def test_settings_map_the_sb3_yml() -> None:
    yml = yaml.safe_load(PPO_YML.read_text())[ENV_ID]
    settings = Settings.from_args(parse_args(["--hyperparams", str(PPO_YML)]))
    assert (settings.runners, settings.envs, settings.n_steps) == (2, yml["n_envs"] // 2, yml["n_steps"])
    assert settings.train_batch == yml["n_envs"] * yml["n_steps"]
    assert settings.training == {
        "gamma": yml["gamma"], "lambda_": yml["gae_lambda"], "lr": yml["learning_rate"],
        "clip_param": yml["clip_range"], "entropy_coeff": yml["ent_coef"], "minibatch_size": yml["batch_size"],
        "num_epochs": yml["n_epochs"],
    }
    assert settings.hidden == [64, 64]
    assert settings.env_kwargs == yml["env_kwargs"]
    assert yml["normalize"] is True and settings.reward_scale == REWARD_SCALE
    assert settings.env_config == {**yml["env_kwargs"], "autoreset_mode": "next_step", "reward_scale": REWARD_SCALE}


def test_rewards_are_scaled_only_when_the_yml_normalizes_them(tmp_path: Path) -> None:
    for normalize, scale in ((False, 1.0), ("dict(norm_obs=True, norm_reward=False)", 1.0), (True, REWARD_SCALE)):
        settings = Settings.from_args(parse_args(["--hyperparams", str(_yml(tmp_path, normalize=normalize))]))
        assert settings.reward_scale == scale, normalize


def test_settings_refuse_what_rllib_cannot_map(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="vf_coef"):
        Settings.from_args(parse_args(["--hyperparams", str(_yml(tmp_path, vf_coef=0.5))]))
    with pytest.raises(ValueError, match="net_arch"):
        Settings.from_args(parse_args(["--hyperparams", str(_yml(
            tmp_path, policy_kwargs="dict(net_arch=dict(pi=[64, 64], vf=[32]))"))]))
    with pytest.raises(ValueError, match="CnnPolicy"):
        Settings.from_args(parse_args(["--hyperparams", str(_yml(tmp_path, policy="CnnPolicy"))]))
    with pytest.raises(ValueError, match="--seed 400"):  # (400 + 2) x 32 + 31 reaches the evaluation's seeds
        Settings.from_args(parse_args(["--hyperparams", str(PPO_YML), "--seed", "400"]))
    with pytest.raises(ValueError, match="--envs-per-runner"):
        Settings.from_args(parse_args(["--hyperparams", str(PPO_YML), "--envs-per-runner", "0"]))
    with pytest.raises(ValueError, match="--eval-episodes"):
        Settings.from_args(parse_args(["--hyperparams", str(PPO_YML), "--eval-episodes", "-1"]))


def test_runner_env_spreads_seeds_scales_rewards_and_leaves_infos_out() -> None:
    """Runner w's vector env, seeded seed + w by RLlib, steps platoons (seed + w) x num_envs + i."""
    n, scale = 3, 0.5
    envs = make_env({"config": SHORT, "autoreset_mode": "next_step", "reward_scale": scale, "num_envs": n})
    native = gym.make_vec(ENV_ID, num_envs=n, vectorization_mode="vector_entry_point", config=SHORT,
                          autoreset_mode="next_step")
    obs, infos = envs.reset(seed=2)
    expected, _ = native.reset(seed=[2 * n + i for i in range(n)])
    assert infos == {} and np.array_equal(obs, expected)
    actions = np.ones(n, dtype=np.int64)
    for _ in range(EnvConfig.from_dict(SHORT).max_episode_steps + 1):  # through the episodes' end and the resets
        obs, rewards, terminated, truncated, infos = envs.step(actions)
        expected, expected_rewards, expected_terminated, expected_truncated, _ = native.step(actions)
        assert infos == {}
        assert np.array_equal(obs, expected) and np.array_equal(rewards, expected_rewards * scale)
        assert np.array_equal(terminated, expected_terminated) and np.array_equal(truncated, expected_truncated)
    with pytest.raises(ValueError, match="num_envs"):
        make_env({"config": SHORT})


def test_rllib_policy_load_names_what_is_missing_or_broken(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="no RLlib checkpoint"):
        RLlibPolicy.load(tmp_path)
    assert find_checkpoint(tmp_path) is None and find_checkpoint(tmp_path / "model.zip") is None
    (tmp_path / CHECKPOINT_DIR).mkdir()
    (tmp_path / CHECKPOINT_DIR / "rllib_checkpoint.json").write_text("{}")
    assert find_checkpoint(tmp_path) == find_checkpoint(tmp_path / CHECKPOINT_DIR) == tmp_path / CHECKPOINT_DIR
    with pytest.raises(RunFileError, match="without the RLModule"):
        RLlibPolicy.load(tmp_path)
    module_dir = tmp_path / CHECKPOINT_DIR / "learner_group" / "learner" / "rl_module" / "default_policy"
    module_dir.mkdir(parents=True)
    with pytest.raises(FileNotFoundError, match="env.json"):
        RLlibPolicy.load(tmp_path)
    (tmp_path / CHECKPOINT_DIR / "env.json").write_text("[1, 2]")
    with pytest.raises(RunFileError, match="env.json"):
        RLlibPolicy.load(tmp_path / CHECKPOINT_DIR)


@pytest.mark.slow
def test_train_rllib_end_to_end_then_the_policy_acts(tmp_path: Path) -> None:
    ray = pytest.importorskip("ray", reason=INSTALL)
    pytest.importorskip("ray.rllib", reason=INSTALL)
    yml = _yml(tmp_path, n_envs=4, n_steps=20, batch_size=40, n_epochs=1)  # 2 x 2 platoons x 20 steps an iteration
    out = tmp_path / "run"
    try:
        main(["--timesteps", "160", "--env-runners", "2", "--envs-per-runner", "2", "--hyperparams", str(yml),
              "--env-config", json.dumps(SHORT), "--out", str(out), "--seed", "1", "--eval-episodes", "7"])
    finally:
        ray.shutdown()  # main shuts Ray down; this covers a failure before it did
    report = (out / REPORT_FILE).read_text()
    iterations = [line for line in report.splitlines() if re.fullmatch(r"\| \d+ \| [\d,]+ \| .*", line)]
    assert len(iterations) >= 2  # 80 env steps each, up to 160
    assert "## Held-out evaluation (7 episodes per policy" in report
    for name in ("RLlib PPO", "paper rule (platoon)", "fixed 1.6 s"):
        assert f"| {name} | " in report
    assert json.loads((out / CHECKPOINT_DIR / "env.json").read_text())["env_kwargs"]["config"] == {
        "action_mode": "relative", "random_initial_setting": True, **SHORT}

    policy = RLlibPolicy.load(out)
    assert policy.action_mode == "relative"
    assert policy.observation_shape == observation_space(EnvConfig()).shape
    envs = gym.make_vec(ENV_ID, num_envs=5, vectorization_mode="vector_entry_point",
                        config={**SHORT, "action_mode": "relative"})
    obs, _ = envs.reset(seed=10_000)
    for _ in range(3):
        actions, state = policy.predict(obs, deterministic=True)
        assert state is None and actions.shape == (5,) and actions.dtype.kind == "i"
        assert all(envs.single_action_space.contains(action) for action in actions)
        assert np.array_equal(policy.predict(obs[::-1])[0], actions[::-1])  # row by row, whatever the batch
        assert [policy.predict(row)[0] for row in obs] == list(actions)
        assert np.array_equal(RLlibPolicy.load(out / CHECKPOINT_DIR).predict(obs)[0], actions)
        sampled, _ = policy.predict(obs, deterministic=False)
        assert all(envs.single_action_space.contains(action) for action in sampled)
        obs, *_ = envs.step(actions)
    shipped = pickle.loads(pickle.dumps(policy))  # as train.evaluate --backend ray sends it to its tasks
    assert np.array_equal(shipped.predict(obs)[0], policy.predict(obs)[0])
    with pytest.raises(ValueError, match="observation of shape"):
        policy.predict(obs[:, :-1])
