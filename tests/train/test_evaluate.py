"""``train.evaluate``: held-out plan, identical scenarios for every policy, statistics, outputs."""

import csv

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3 import PPO

import timegap_env
from agents.policies import FixedPolicy, PaperRulePolicy
from train import evaluate


def test_plan_uses_held_out_seeds_split_across_groups():
    plan = evaluate.plan_episodes(7, ["ngsim_in_band", "idm", "training_mix"])
    assert [e.group for e in plan] == ["ngsim_in_band"] * 3 + ["idm"] * 2 + ["training_mix"] * 2
    assert [e.seed for e in plan] == list(range(evaluate.EVAL_SEED_START, evaluate.EVAL_SEED_START + 7))
    with pytest.raises(ValueError, match="episodes = 0"):
        evaluate.plan_episodes(0, ["idm"])


def test_without_ngsim_data_the_groups_are_synthetic_and_the_header_says_so(monkeypatch, tmp_path):
    monkeypatch.setenv("TIMEGAP_NGSIM_PATH", str(tmp_path / "absent.csv"))
    groups, note = evaluate.available_groups()
    assert groups == ["idm", "training_mix"]
    assert "NGSIM data not found" in note and "absent.csv" in note


def test_platoon_and_per_vehicle_envs_draw_identical_scenarios():
    seeds = [evaluate.EVAL_SEED_START, evaluate.EVAL_SEED_START + 1]
    platoon = evaluate.run_batch(PaperRulePolicy(), "training_mix", seeds, record_profile=False)
    per_vehicle = evaluate.run_batch(PaperRulePolicy({"action_mode": "per_vehicle"}), "training_mix", seeds, False)
    assert platoon[1] == per_vehicle[1]
    assert platoon[1][0] != platoon[1][1], "the fingerprint tells episodes apart"
    assert [r["scenario"] for r in platoon[0]] == [r["scenario"] for r in per_vehicle[0]]


def test_statistics():
    mean, low, high = evaluate.bootstrap_mean(np.full(5, 2.5))
    assert mean == low == high == 2.5
    mean, low, high = evaluate.bootstrap_mean(np.arange(20.0))
    assert low < mean == 9.5 < high
    rate, low, high = evaluate.wilson_interval(0, 20)
    assert rate == 0 and low == pytest.approx(0, abs=1e-12) and high == pytest.approx(0.1611, abs=1e-4)


def test_policy_selection():
    with pytest.raises(ValueError, match="fixed_1.5"):
        evaluate.build_policies(["fixed_1.5"], evaluate.DEFAULT_MODEL)
    with pytest.raises(FileNotFoundError, match="--policies ppo"):
        evaluate.build_policies(["ppo"], evaluate.DEFAULT_MODEL.with_name("absent.zip"))
    defaults = evaluate.build_policies(None, evaluate.DEFAULT_MODEL.with_name("absent.zip"))
    assert "ppo" not in defaults and {"rule_platoon", "rule_per_vehicle", "fixed_1.0", "v2v_aware"} <= set(defaults)
    assert isinstance(defaults["fixed_2.2"], FixedPolicy)


def test_two_episodes_write_tables_and_figures(tmp_path):
    model = PPO("MlpPolicy", gym.make(timegap_env.ENV_ID), n_steps=64, batch_size=32, n_epochs=1, seed=0, device="cpu")
    model.learn(64).save(tmp_path / "model.zip")
    out = tmp_path / "eval"
    evaluate.main(["--episodes", "2", "--policies", "rule_platoon", "rule_per_vehicle", "fixed_1.6", "ppo",
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
        (p, g) for g in groups for p in ("rule_platoon", "rule_per_vehicle", "fixed_1.6", "ppo")]
    assert all(r["episodes"] == "2" for r in rows if r["group"] == evaluate.ALL_EPISODES)
    # the rule and fixed 1.6 s start equal; the paired difference of a policy to itself is exactly 0
    reference = next(r for r in rows if r["policy"] == "rule_platoon" and r["group"] == evaluate.ALL_EPISODES)
    assert float(reference["return_vs_reference_mean"]) == 0.0
    table = (out / "table.md").read_text()
    assert "paper rule (per vehicle)" in table and "PPO" in table and "Wilson" in table
