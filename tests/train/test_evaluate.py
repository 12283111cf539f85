"""``train.evaluate``: held-out plan, identical scenarios for every policy, statistics, outputs."""

import csv
import json

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import DummyVecEnv, VecFrameStack, VecNormalize

import timegap_env
from timegap_env.envs.info import truth_of
from timegap_env.leaders.scenarios import HELD_OUT_FAMILIES
from timegap_env.agents.policies import FixedPolicy, PaperRulePolicy
from timegap_env.agents.protocol import EVAL_SEED_START
from timegap_env.config import EnvConfig
from timegap_env.experiments import heldout, stats, value
from train import evaluate


def test_plan_uses_held_out_seeds_split_across_groups():
    plan = evaluate.plan_episodes(7, ["ngsim_in_band", "idm", "training_mix"])
    assert [e.group for e in plan] == ["ngsim_in_band"] * 3 + ["idm"] * 2 + ["training_mix"] * 2
    assert [e.seed for e in plan] == list(range(EVAL_SEED_START, EVAL_SEED_START + 7))
    with pytest.raises(ValueError, match="episodes = 0"):
        evaluate.plan_episodes(0, ["idm"])


def test_without_data_the_groups_are_synthetic_and_the_header_says_so(monkeypatch, tmp_path):
    monkeypatch.setenv("TIMEGAP_NGSIM_PATH", str(tmp_path / "absent.csv"))
    monkeypatch.setenv("TIMEGAP_OPENACC_PATH", str(tmp_path / "absent_dir"))
    groups, note = evaluate.available_groups()
    assert groups == ["training_mix", "larger_degradations", "idm", "stop_and_go", "emergency_braking"]
    assert "ngsim data not found" in note and "absent.csv" in note and "openacc data not found" in note


def test_every_held_out_family_is_a_group_and_none_is_trained_on():
    for family in HELD_OUT_FAMILIES:
        assert evaluate.GROUPS[family].options == {"scenario": family}
        assert family not in EnvConfig().scenario_weights


def test_the_larger_degradations_lie_beyond_the_training_ranges():
    default = EnvConfig().degradation
    larger = EnvConfig.from_dict(evaluate.GROUPS["larger_degradations"].config).degradation
    assert larger.kind_weights.get("none", 0.0) == 0.0
    assert larger.lag_factor_range[0] >= default.lag_factor_range[1] and larger.gain_range[1] <= default.gain_range[0]
    for field in ("v2v_latency_range", "packet_loss_range", "radar_bias_range", "radar_noise_range"):
        assert getattr(larger, field)[0] >= getattr(default, field)[1], field


def test_the_profile_episode_is_one_degraded_midway():
    seeds = list(range(EVAL_SEED_START, EVAL_SEED_START + 12))
    ordered = heldout.profile_first("training_mix", seeds)
    assert sorted(ordered) == seeds
    venv = gym.make_vec(timegap_env.ENV_ID, num_envs=1, vectorization_mode="vector_entry_point", truth_info=True)
    _, infos = venv.reset(seed=ordered[:1])
    truth = truth_of(infos)
    assert ((truth["kind"] != "none") & (truth["onset"] > 0) & np.isfinite(truth["onset"])).any()


def test_the_share_of_the_oracle_gap():
    blind, oracle = np.zeros(4), np.array([2.0, 4.0, 2.0, 4.0])
    share, low, high = stats.oracle_share(np.array([1.0, 2.0, 1.0, 2.0]), blind, oracle)
    assert share == 0.5 and low == high == 0.5  # every resample captures half
    assert np.isnan(stats.oracle_share(blind, blind, -oracle)).all()  # an oracle below the constant: no gap


def test_platoon_and_per_vehicle_envs_draw_identical_scenarios():
    seeds = [EVAL_SEED_START, EVAL_SEED_START + 1]
    platoon = heldout.run_batch(PaperRulePolicy(), "training_mix", seeds, record_profile=False)
    per_vehicle = heldout.run_batch(PaperRulePolicy({"action_mode": "per_vehicle"}), "training_mix", seeds, False)
    assert platoon[1] == per_vehicle[1]
    assert platoon[1][0] != platoon[1][1], "the fingerprint tells episodes apart"
    assert [r["scenario"] for r in platoon[0]] == [r["scenario"] for r in per_vehicle[0]]


def test_statistics():
    mean, low, high = stats.bootstrap_mean(np.full(5, 2.5))
    assert mean == low == high == 2.5
    mean, low, high = stats.bootstrap_mean(np.arange(20.0))
    assert low < mean == 9.5 < high
    rate, low, high = stats.wilson_interval(0, 20)
    assert rate == 0 and low == pytest.approx(0, abs=1e-12) and high == pytest.approx(0.1611, abs=1e-4)


def test_policy_selection():
    with pytest.raises(ValueError, match="fixed_1.5"):
        evaluate.build_policies(["fixed_1.5"], evaluate.DEFAULT_MODEL)
    with pytest.raises(FileNotFoundError, match="--policies ppo"):
        evaluate.build_policies(["ppo"], evaluate.DEFAULT_MODEL.with_name("absent.zip"))
    defaults = evaluate.build_policies(None, evaluate.DEFAULT_MODEL.with_name("absent.zip"))
    assert "ppo" not in defaults and {"rule_platoon", "rule_per_vehicle", "fixed_1.0", "v2v_aware"} <= set(defaults)
    assert isinstance(defaults["fixed_2.2"], FixedPolicy)


def test_two_episodes_write_tables_and_figures(tmp_path, monkeypatch):
    monkeypatch.setattr(evaluate, "DEFAULT_TRAIN_EPISODES", 1)  # a quick oracle
    monkeypatch.setattr(value, "SELECTION_EPISODES", 2)
    model = PPO("MlpPolicy", gym.make(timegap_env.ENV_ID), n_steps=64, batch_size=32, n_epochs=1, seed=0, device="cpu")
    model.learn(64).save(tmp_path / "model.zip")
    (tmp_path / "env.json").write_text(json.dumps({"env_kwargs": {}, "frame_stack": 1, "normalize": False}))
    out = tmp_path / "eval"
    evaluate.main(["--episodes", "2", "--policies", "rule_platoon", "rule_per_vehicle", "fixed_1.6", "oracle", "ppo",
                   "--model", str(tmp_path / "model.zip"), "--out", str(out)])
    for name in ("table.md", "table.csv", "episodes.csv", "profiles.png", "metrics.png"):
        assert (out / name).stat().st_size > 0, name
    with open(out / "table.csv") as file:
        rows = list(csv.DictReader(file))
    expected = {"policy", "group", "episodes", "collisions", "return_vs_reference_mean"} | {
        f"{metric}_{stat}" for metric in evaluate.METRICS for stat in ("mean", "ci_low", "ci_high")}
    assert expected <= set(rows[0])
    groups = [evaluate.ALL_EPISODES] + [g for g, _ in zip(evaluate.available_groups()[0], range(2))]
    assert [(r["policy"], r["group"]) for r in rows] == [
        (p, g) for g in groups for p in ("rule_platoon", "rule_per_vehicle", "fixed_1.6", "oracle", "ppo")]
    assert {r["best_fixed"] for r in rows} == {"fixed_1.6"}
    assert all(float(r["oracle_share_mean"]) == 0.0 or np.isnan(float(r["oracle_share_mean"]))
               for r in rows if r["policy"] == "fixed_1.6")
    assert all(r["episodes"] == "2" for r in rows if r["group"] == evaluate.ALL_EPISODES)
    # the rule and fixed 1.6 s start equal; the paired difference of a policy to itself is exactly 0
    reference = next(r for r in rows if r["policy"] == "rule_platoon" and r["group"] == evaluate.ALL_EPISODES)
    assert float(reference["return_vs_reference_mean"]) == 0.0
    table = (out / "table.md").read_text()
    assert "paper rule (per vehicle)" in table and "PPO" in table and "Wilson" in table


def test_a_frame_stacked_run_directory_is_evaluated(tmp_path):
    venv = VecNormalize(DummyVecEnv([lambda: gym.make(timegap_env.ENV_ID)]))
    model = PPO("MlpPolicy", VecFrameStack(venv, 3), n_steps=64, batch_size=32, n_epochs=1, seed=0, device="cpu")
    model.learn(64).save(tmp_path / "model.zip")
    venv.save(tmp_path / "vecnormalize.pkl")
    (tmp_path / "env.json").write_text(json.dumps({"env_kwargs": {}, "frame_stack": 3}))
    policies = evaluate.build_policies(["ppo"], tmp_path)  # a directory, as LearnedPolicy.load takes
    assert policies["ppo"].frame_stack == 3  # it used to be refused: "takes observations of shape (135,)"
    obs, _ = gym.make(timegap_env.ENV_ID).reset(seed=EVAL_SEED_START)
    action, stack = policies["ppo"].predict(obs)
    assert gym.make(timegap_env.ENV_ID).action_space.contains(action) and stack.shape == (3 * obs.size,)


def test_a_missing_or_corrupted_model_is_named_without_a_traceback(tmp_path, capsys):
    with pytest.raises(SystemExit):
        evaluate.main(["--episodes", "1", "--policies", "ppo", "--model", str(tmp_path / "absent.zip")])
    assert f"--model {tmp_path / 'absent.zip'}: no such model zip" in capsys.readouterr().err
    with pytest.raises(SystemExit):  # explicitly asked for, even with the default policies
        evaluate.main(["--episodes", "1", "--model", str(tmp_path / "absent.zip")])
    (tmp_path / "model.zip").write_bytes(b"garbage")
    (tmp_path / "env.json").write_text(json.dumps({"env_kwargs": {}, "frame_stack": 1, "normalize": False}))
    with pytest.raises(SystemExit):
        evaluate.main(["--episodes", "1", "--policies", "ppo", "--model", str(tmp_path / "model.zip")])
    assert f"model = '{tmp_path / 'model.zip'}': not a readable PPO model zip" in capsys.readouterr().err
    PPO("MlpPolicy", gym.make(timegap_env.ENV_ID), device="cpu").save(tmp_path / "model.zip")
    (tmp_path / "env.json").write_text(json.dumps({"env_kwargs": {}, "frame_stack": 1, "normalize": True}))
    (tmp_path / "vecnormalize.pkl").write_bytes(b"garbage")
    with pytest.raises(SystemExit):
        evaluate.main(["--episodes", "1", "--policies", "ppo", "--model", str(tmp_path)])
    assert f"vecnormalize = '{tmp_path / 'vecnormalize.pkl'}': not a readable pickle" in capsys.readouterr().err
