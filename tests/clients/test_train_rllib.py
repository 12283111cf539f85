"""``python -m train.train_rllib`` and ``timegap_env.agents.rllib_policy`` (issue 15).

The settings, the runners' env, the reward scale's selection and its report are checked without Ray (fast, any
venv); the end-to-end runs need the ``ray`` extra (``.venv-clients``, ``bash .ci/clients``) and are slow: a tiny run
of two runners with two platoons each and short episodes, its checkpoint loaded by :class:`RLlibPolicy` and its
report holding the returns on the check and held-out episodes; a tiny ``--select-scale`` of two candidates.
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

from timegap_env.agents.learned import RunFileError
from timegap_env.agents.rllib_policy import CHECKPOINT_DIR, RLlibPolicy, find_checkpoint
from timegap_env import DEFAULT_TASK
from timegap_env.config import EnvConfig
from timegap_env.envs.observation import observation_space
from timegap_env.tasks import get_task
from train.train_rllib import (
    REPORT_FILE,
    REWARD_SCALE,
    SELECTION_FILE,
    Candidate,
    Checked,
    Iteration,
    Settings,
    Trained,
    best_candidate,
    main,
    make_env,
    parse_args,
    scale_text,
    selection_report,
)

EVAL_SEED, EVAL_EPISODES = get_task(DEFAULT_TASK).seeds.check_start, get_task(DEFAULT_TASK).seeds.check_episodes

REPO = Path(__file__).resolve().parents[2]
PPO_YML = REPO / "hyperparams" / "ppo.yml"
COMMITTED_SELECTION = REPO / "results" / "v0" / "rllib" / SELECTION_FILE
SHORT = {"episode_duration": 20.0}  # [s]: 20 decisions
INSTALL = "needs the ray extra: pip install -e '.[ray]' (or run bash .ci/clients)"


def _yml(tmp_path: Path, **changes: object) -> Path:
    """hyperparams/ppo.yml with ``changes`` to its env section (None: key removed), written in ``tmp_path``."""
    document = yaml.safe_load(PPO_YML.read_text())
    section = document[DEFAULT_TASK]
    for key, value in changes.items():
        if value is None:
            section.pop(key)
        else:
            section[key] = value
    path = tmp_path / "ppo.yml"
    path.write_text(yaml.safe_dump(document))
    return path


def test_settings_map_the_sb3_yml() -> None:
    yml = yaml.safe_load(PPO_YML.read_text())[DEFAULT_TASK]
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


def test_reward_scale_is_read_as_a_positive_number_or_fraction(capsys: pytest.CaptureFixture[str]) -> None:
    args = parse_args(["--hyperparams", str(PPO_YML), "--reward-scale", "1/30"])
    assert args.reward_scale == 1 / 30 and Settings.from_args(args).reward_scale == 1 / 30
    assert parse_args(["--select-scale", "1", "1/30", "0.02"]).select_scale == [1.0, 1 / 30, 0.02]
    for text in ("0", "-0.1", "abc", "1/0"):
        with pytest.raises(SystemExit):
            parse_args(["--reward-scale", text])
        assert f"reward scale {text!r}" in capsys.readouterr().err
    assert [scale_text(scale) for scale in (1.0, 1 / 30, 0.02, 0.0333)] == ["1", "1/30", "0.02", "0.0333"]


def test_select_scale_refuses_what_would_not_be_a_fair_choice() -> None:
    base = ["--hyperparams", str(PPO_YML), "--select-scale"]
    for extra, message in ((["1"], "two or more different"), (["1", "1/30", "1/30"], "two or more different"),
                           (["1", "0.02", "--reward-scale", "1"], "--reward-scale 1 with --select-scale"),
                           (["1", "0.02", "--eval-episodes", "0"], "--eval-episodes 0 with --select-scale")):
        with pytest.raises(ValueError, match=message):
            Settings.from_args(parse_args(base + extra))
    # (280 + 2) x 32 + 31 = 9055: below the held-out seeds, so a plain run may, but among the check episodes' seeds
    assert Settings.from_args(parse_args(["--hyperparams", str(PPO_YML), "--seed", "280"])).runners == 2
    with pytest.raises(ValueError, match=f"must stay below {EVAL_SEED}"):
        Settings.from_args(parse_args(base + ["1", "0.02", "--seed", "280"]))


def _candidate(scale: float, returns: list[float]) -> Candidate:
    """A --select-scale candidate with ``returns`` on the check episodes and one iteration of 4 ended episodes."""
    seeds = list(range(EVAL_SEED, EVAL_SEED + len(returns)))
    trained = Trained([Iteration(1, 4096, 4096, 4, -200.0, 0.5)], 0.5, Path("gone"))
    return Candidate(scale, trained, Checked(seeds, np.array(returns), 1))


def test_selection_chooses_the_highest_mean_return_on_the_check_episodes() -> None:
    candidates = [_candidate(1.0, [-20.0, -10.0]), _candidate(1 / 30, [-12.0, -11.0]), _candidate(0.02, [-11.0, -12.0])]
    assert best_candidate(candidates) is candidates[1]  # -11.5, equal to 0.02's: the first of equal ones
    settings = Settings.from_args(parse_args(["--hyperparams", str(PPO_YML)]))
    report = selection_report("python -m train.train_rllib --select-scale 1 1/30 0.02", settings, 0, "here",
                              candidates, 60.0)
    assert "| 1/30 (chosen) | -11.5 [" in report and "| 1 | -15.0 [" in report and "| 0.02 | -11.5 [" in report
    assert "| 1 | -15.0 [-20.0, -10.0] | -3.5 [" in report  # paired with the chosen: (-8 + 1) / 2
    assert f"seeds {EVAL_SEED}-{EVAL_SEED + 1}" in report and "1/32" not in report and "1/2 |" in report
    assert "Chosen: rewards x 0.0333333 (1/30). `REWARD_SCALE` in train/train_rllib.py is 0.0333333, the chosen" \
        in report
    assert "not the chosen scale" in selection_report("c", settings, 0, "here", candidates[:1], 1.0)


def test_reward_scale_is_the_one_the_committed_selection_chose() -> None:
    """REWARD_SCALE was once set after a look at held-out returns; it must be what --select-scale chose on the check
    episodes (results/v0/rllib/selection.md), among no scaling, 1/30 and 0.02, scored on the check episodes."""
    report = COMMITTED_SELECTION.read_text()
    chosen = re.search(r"^Chosen: rewards x ([0-9.e-]+)", report, re.MULTILINE)
    assert chosen is not None, f"{COMMITTED_SELECTION}: no 'Chosen: rewards x' line"
    assert float(chosen.group(1)) == pytest.approx(REWARD_SCALE, rel=1e-5)
    assert "--select-scale 1 1/30 0.02" in report
    v0_check = get_task("TimeGapMonitor-v0").seeds.check  # the committed selection ran on v0
    assert f"seeds {v0_check[0]}-{v0_check[-1]}" in report
    assert len(re.findall(r"^\| (1|1/30|0\.02)( \(chosen\))? \| ", report, re.MULTILINE)) == 3


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
    native = gym.make_vec(DEFAULT_TASK, num_envs=n, vectorization_mode="vector_entry_point", config=SHORT,
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
    assert not any(".partial-" in path.name for path in tmp_path.iterdir())  # the work directory became --out
    assert f"`{out / CHECKPOINT_DIR}/`" in report  # where the run was published, not where it worked
    iterations = [line for line in report.splitlines() if re.fullmatch(r"\| \d+ \| [\d,]+ \| .*", line)]
    assert len(iterations) >= 2  # 80 env steps each, up to 160
    assert "## Held-out evaluation (7 episodes per policy" in report
    assert re.search(rf"{EVAL_EPISODES} check episodes \(seeds {EVAL_SEED}-{EVAL_SEED + EVAL_EPISODES - 1}\); "
                     rf"collisions \| -?[\d.]+ \[-?[\d.]+, -?[\d.]+\]; \d+/{EVAL_EPISODES} \|", report)
    assert "## Reward scale" in report and "seen before this choice" in report
    for name in ("RLlib PPO", "paper rule (platoon)", "fixed 1.6 s"):
        assert f"| {name} | " in report
    assert json.loads((out / CHECKPOINT_DIR / "env.json").read_text())["env_kwargs"]["config"] == {
        "action_mode": "relative", "random_initial_setting": True, **SHORT}

    policy = RLlibPolicy.load(out)
    assert policy.action_mode == "relative"
    assert policy.observation_shape == observation_space(EnvConfig()).shape
    envs = gym.make_vec(DEFAULT_TASK, num_envs=5, vectorization_mode="vector_entry_point",
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


@pytest.mark.slow
def test_select_scale_trains_each_candidate_and_keeps_only_the_table(tmp_path: Path) -> None:
    ray = pytest.importorskip("ray", reason=INSTALL)
    pytest.importorskip("ray.rllib", reason=INSTALL)
    yml = _yml(tmp_path, n_envs=4, n_steps=20, batch_size=40, n_epochs=1)
    out = tmp_path / "selection"
    try:
        main(["--select-scale", "1", "1/30", "--timesteps", "80", "--env-runners", "2", "--envs-per-runner", "2",
              "--hyperparams", str(yml), "--env-config", json.dumps(SHORT), "--out", str(out)])
    finally:
        ray.shutdown()
    assert sorted(path.name for path in out.iterdir()) == [SELECTION_FILE]  # no checkpoint, no training.md
    report = (out / SELECTION_FILE).read_text()
    rows = re.findall(r"^\| (1|1/30)( \(chosen\))? \| -?[\d.]+ \[.*\| [\d,]+ \| \d+ \|$", report, re.MULTILINE)
    assert [row[0] for row in rows] == ["1", "1/30"] and sum(bool(row[1]) for row in rows) == 1
    assert "--select-scale 1 1/30 --timesteps 80" in report and "No held-out episode is run" in report
