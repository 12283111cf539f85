"""The benchmark runs on tiny sizes and writes every row with finite positive numbers (their sizes are not
asserted: machines are noisy)."""

import math
import re
import sys

from timegap_env.speed import vector as bench_vector
from train import bench

NUMBER = re.compile(r"[-+]?\d[\d,]*(?:\.\d+)?(?:e[-+]?\d+)?|nan|inf", re.IGNORECASE)


def first_number(cell: str) -> float:
    match = NUMBER.search(cell)
    assert match, f"no number in {cell!r}"
    return float(match.group().replace(",", ""))


def expected_measures(sizes: bench.Sizes) -> list[str]:
    """The start of every row's measure, in order of the sizes."""
    vector = [f"native vector env, {n} envs, one core" for n in sizes.vector_sizes]
    memory = [f"native vector env, {n} envs: peak memory" for n in sizes.vector_sizes]
    reset = [f"batched reset, envs.reset(seed=0), {n} envs" for n in sizes.reset_sizes]
    return [
        "TimeGapMonitor-v1 (the default task) as gym.make gives it (default info) [steps/s]",
        "TimeGapMonitor-v1, one env, truth_info=True",
        "TimeGapMonitor-v1, one env, step_diagnostics=False",
        "TimeGapMonitor-v1, one env, default info (+ vector reward, cost, objectives) against TimeGapMonitor-v0",
        "TimeGapMonitor-v1, one env, step_diagnostics=False against TimeGapMonitor-v0",
        "TimeGapMonitor-v1, one env, default info [steps/s] against highway-env",
        "one env: a fused_step call",
        "one env: of that call, numba unpacking",
        "fused_step's arithmetic per env-step",
        *vector, *memory,
        f"native vector env, {sizes.vector_sizes[0]} envs, step_diagnostics=True",
        f"native vector env, {sizes.sync_envs} envs, default info",
        *reset,
        "first step from python -c, after pip install of the wheel [CPU s]",
        "first step from python -c, after pip install of the wheel [wall s]",
        "first step from python -c, empty numba cache [CPU s]",
        "first step from python -c, empty numba cache [wall s]",
        "first step from python -c, warm numba cache [CPU s]",
        "first step from python -c, warm numba cache [wall s]",
        "building the wheel, its kernels compiled into it",
        "numba functions compiled by the empty-cache run",
        "PPO, make train's setting (",
        "PPO: the most its throughput could gain",
        "PPO, make train's setting [env steps/s",
        "PPO, hyperparams/ppo_fast.yml",
        *[f"simulator, {n} envs" for n in sizes.ticks],
        "monitor, 1024 x 5",
    ]


def test_bench_runs_quick(tmp_path, monkeypatch, capsys):
    out = tmp_path / "bench.md"
    monkeypatch.setattr(sys, "argv", ["bench", "--quick", "--out", str(out)])
    bench.main()
    text = out.read_text()
    assert text in capsys.readouterr().out
    rows = [line.split(" | ") for line in text.splitlines() if line.startswith("| ") and not line.startswith("| measure")]
    measures = [row[0].removeprefix("| ") for row in rows]
    expected = expected_measures(bench.QUICK)
    assert len(measures) == len(expected), measures
    for (measure, value, _, ratio, _), start in zip(rows, expected):
        assert measure.removeprefix("| ").startswith(start), (measure, start)
        for cell in (value, ratio) if ratio else (value,):
            number = first_number(cell)
            assert math.isfinite(number) and number > 0, (measure, cell)


def test_sizes_whose_traced_set_up_would_exceed_the_budget_are_not_traced(monkeypatch):
    calls = []

    class FakeStepper:
        def __init__(self, n):
            self.envs, self.env_steps_per_second = self, 1e5

        def turn(self, min_seconds, min_steps):
            pass

        def close(self):
            pass

    def fake_set_up(n, step_diagnostics, trace, time_reset):
        calls.append((n, trace, time_reset))
        seconds = 1e-3 * n  # traced set-up: 1 ms per env
        return FakeStepper(n), bench_vector.VectorRun(n, 0.0, seconds, 0.1 * n if trace else None, 0.1 * n, None)

    monkeypatch.setattr(bench_vector, "set_up", fake_set_up)
    monkeypatch.setattr(bench_vector, "TRACE_BUDGET", 20.0)
    runs = bench_vector.measure_sizes((1024, 4096, 16384, 65536), (4096,), False, 0.0, 1, 2)
    # 4096: 4.1 s extrapolated, traced; 16384: 16.4 s, traced; 65536: 65.5 s > 20 s, not traced
    assert calls == [(1024, True, False), (4096, True, True), (16384, True, False), (65536, False, False)]
    assert [run.env_steps_per_second for run in runs] == [1e5] * 4
    rows = [bench.memory_row(run) for run in runs]
    assert "tracemalloc" in rows[2].measure and "peak RSS growth" in rows[2].reference
    assert "not traced" in rows[3].measure and first_number(rows[3].value) == 0.1 * 1024
