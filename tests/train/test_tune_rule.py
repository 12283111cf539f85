"""The rule's tuning on a tiny grid: files written, same bytes on a rerun; the policy's defaults are the committed best."""

import csv
from pathlib import Path

from timegap_env.agents.policies import ChartStepPolicy
from timegap_env.experiments.registry import tuned_chart_step
from train import tune_rule

COMMITTED = Path(__file__).resolve().parents[2] / "results" / "v0" / "rule" / "tuning.csv"  # v0 set the defaults


def test_tuning_writes_the_same_files_twice(tmp_path):
    outputs = []
    for run in ("a", "b"):
        out = tmp_path / run
        tune_rule.main(["--episodes", "2", "--k-up", "2", "--quiet-time", "20", "--min-setting", "1.2",
                        "--out", str(out)])
        outputs.append({name: (out / name).read_bytes() for name in ("tuning.md", "tuning.csv")})
    assert outputs[0] == outputs[1]
    report = outputs[0]["tuning.md"].decode()
    assert "**chart steps (up at 2, down after 20.0 s, floor 1.2 s)**" in report and "| fixed 1.0 s |" in report
    rows = list(csv.DictReader(outputs[0]["tuning.csv"].decode().splitlines()))
    assert [row["policy"] for row in rows] == ["chart steps (up at 2, down after 20.0 s, floor 1.2 s)",
                                               "paper rule (platoon)", "fixed 1.6 s", "fixed 1.0 s"]
    assert [row["best"] for row in rows] == ["1", "0", "0", "0"]


def test_the_policy_s_defaults_are_the_committed_best_cell():
    best = [row for row in csv.DictReader(COMMITTED.read_text().splitlines()) if row["best"] == "1"]
    assert len(best) == 1
    policy = ChartStepPolicy()
    assert (policy.k_up, policy.quiet_time, policy.min_setting) == (
        int(best[0]["k_up"]), float(best[0]["quiet_time"]), float(best[0]["min_setting"]))


def test_tuning_for_v1_runs_v1_and_its_best_cell_reaches_the_benchmark(tmp_path):
    out = tmp_path / "v1"
    tune_rule.main(["--episodes", "2", "--k-up", "2", "3", "--quiet-time", "20", "--min-setting", "1.2",
                    "--out", str(out), "--env-id", "TimeGapMonitor-v1"])
    report = (out / "tuning.md").read_text()
    assert "training episodes of TimeGapMonitor-v1" in report and "the defaults of `ChartStepPolicy`" not in report
    best = tuned_chart_step(out / "tuning.csv")
    assert best["k_up"] in (2, 3) and best["quiet_time"] == 20.0 and best["min_setting"] == 1.2
    (tmp_path / "bad.csv").write_text("policy,best\nx,0\n")
    try:
        tuned_chart_step(tmp_path / "bad.csv")
    except ValueError as error:
        assert "bad.csv" in str(error)
    else:
        raise AssertionError("a tuning.csv without a best cell was taken")
