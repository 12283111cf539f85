"""The benchmark script runs on tiny sizes and writes its table (its numbers are not asserted: machines are noisy)."""

import sys

from train import bench


def test_bench_runs_quick(tmp_path, monkeypatch, capsys):
    out = tmp_path / "bench.md"
    monkeypatch.setattr(sys, "argv", ["bench", "--quick", "--out", str(out)])
    bench.main()
    table = out.read_text()
    for measure in ("TimeGapMonitor-v0 / highway-fast-v0", "simulator, 1024 envs", "native / SyncVectorEnv",
                    "monitor, 1024 x 5", "PPO, training setting: TimeGapMonitor-v0 / CartPole-v1", "peak memory"):
        assert measure in table
    assert "| TimeGapMonitor-v0 / highway-fast-v0 |" in capsys.readouterr().out
