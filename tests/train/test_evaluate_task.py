"""train.evaluate_task: policies on TimeGapMonitor-v1's held-out episodes against its references (issue 25)."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from timegap_env.config import EnvConfig
from timegap_env.experiments.stats import wilson_interval
from train import evaluate_task

ROOT = Path(__file__).resolve().parents[2]


def test_a_model_of_another_env_is_refused_naming_it():
    with pytest.raises(ValueError, match="trained in TimeGapMonitor-v0, not TimeGapMonitor-v1"):
        evaluate_task.learned(ROOT / "results" / "ppo", EnvConfig.from_dict(version=1))


def test_a_tiny_evaluation_writes_its_table(tmp_path, monkeypatch, capsys):
    out = tmp_path / "eval"
    monkeypatch.setattr(sys, "argv", ["evaluate_task", "--train", "1", "--selection", "2", "--held-out", "3",
                                      "--policies", "rule_platoon", "fixed_1.0", "--out", str(out)])
    evaluate_task.main()
    table = (out / "policies.md").read_text()
    assert "| rule_platoon |" in table and "| fixed_1.0 |" in table and "0.0 [0.0, 0.0]" in table  # rule vs itself
    assert sorted(path.name for path in out.iterdir()) == ["pareto.png", "policies.csv", "policies.md"]


def test_an_unknown_baseline_is_refused(tmp_path, monkeypatch):
    monkeypatch.setattr(sys, "argv", ["evaluate_task", "--train", "1", "--selection", "2", "--held-out", "2",
                                      "--policies", "rule_platoon", "--baseline", "ppo", "--out", str(tmp_path / "e")])
    with pytest.raises(ValueError, match="--baseline 'ppo': not one of the policies played"):
        evaluate_task.main()
    assert not (tmp_path / "e").exists()


def test_the_committed_v1_runs_load_as_v1():
    config = EnvConfig.from_dict(version=1)
    assert evaluate_task.learned(ROOT / "results" / "ppo_v1", config).hidden_features == ()
    assert len(evaluate_task.learned(ROOT / "results" / "ppo_v1_nomonitor", config).hidden_features) == 6


def test_a_group_without_its_data_is_left_out_and_says_so(tmp_path, monkeypatch):
    monkeypatch.setenv("TIMEGAP_OPENACC_PATH", str(tmp_path / "nowhere"))
    out = tmp_path / "eval"
    monkeypatch.setattr(sys, "argv", ["evaluate_task", "--train", "1", "--selection", "2", "--held-out", "2",
                                      "--policies", "rule_platoon", "--groups", "stop_and_go", "openacc", "--out", str(out)])
    evaluate_task.main()
    table = (out / "policies.md").read_text()
    assert "## stop_and_go" in table and "## openacc" not in table and "group openacc left out: no OpenACC data" in table
    rule_row = next(line for line in table.splitlines() if line.startswith("| rule_platoon |"))
    collided = int(rule_row.split("|")[-2].split("/")[0])
    _, low, high = wilson_interval(collided, 2)  # the collisions' rate with its Wilson interval
    assert rule_row.endswith(f"{collided}/2 [{low:.2f}, {high:.2f}] |")
    monkeypatch.setattr(sys, "argv", ["evaluate_task", "--policies", "rule_platoon", "--groups", "openacc", "--out",
                                      str(tmp_path / "none")])
    with pytest.raises(ValueError, match="none could run"):
        evaluate_task.main()
