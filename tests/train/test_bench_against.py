"""train.bench_against: both benches by turns, their rows side by side with this tree's mean over the commit's."""

from __future__ import annotations

import types
from pathlib import Path

import pytest

from train import bench_against

TABLE = """| measure | value | reference (same process) | ratio | target |
|---|---|---|---|---|
| single env [steps/s] | {single} | CartPole-v1, one env: 100,000 | {ratio}x | >= 0.5x |
| native vector env, 256 envs, one core [env-steps/s] | 200,000 | 256 envs: 200,000 / CartPole-v1 | 1.00x / {vector}x | |
| peak memory [KiB per env] | 64.0 KiB | | | |
"""


def test_rows_take_the_ratio_against_the_outer_reference_else_the_value(tmp_path: Path):
    table = tmp_path / "t.md"
    table.write_text(TABLE.format(single="50,000", ratio="0.50", vector="2.00"))
    assert bench_against.rows(table) == {"single env [steps/s]": "0.50x",
                                         "native vector env, 256 envs, one core [env-steps/s]": "2.00x",
                                         "peak memory [KiB per env]": "64.0 KiB"}
    assert bench_against.number("1,350.4x") == 1350.4 and bench_against.number("n/a") is None


def test_the_comparison_runs_both_trees_by_turns(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    calls = []
    figures = iter([("0.50", "2.00"), ("0.55", "2.10"), ("0.50", "2.00"), ("0.45", "1.90")])  # ref, this, ref, this

    def fake_bench(tree: Path, out: Path) -> None:
        calls.append(tree == bench_against.ROOT)
        ratio, vector = next(figures)
        out.write_text(TABLE.format(single="1", ratio=ratio, vector=vector))

    monkeypatch.setattr(bench_against, "bench", fake_bench)
    table = bench_against.compare("HEAD", 2, tmp_path / "against.md")
    assert calls == [False, True, False, True]
    single = next(line for line in table.splitlines() if line.startswith("| single env"))
    assert single.endswith("| 1.000 |") and "0.55x" in single  # (0.55 + 0.45) / (0.50 + 0.50)
    assert sorted(path.name for path in tmp_path.iterdir()) == ["against.ref1.md", "against.ref2.md", "against.this1.md",
                                                                "against.this2.md"]


def test_a_relative_out_is_written_here_not_in_the_tree(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    commands = []
    monkeypatch.setattr(bench_against.subprocess, "run", lambda command, **kwargs: commands.append((command, kwargs)))
    monkeypatch.chdir(tmp_path)
    bench_against.bench(tmp_path / "ref", Path("runs/against.ref1.md"))
    (command, kwargs), = commands
    assert command[command.index("--out") + 1] == str(tmp_path / "runs" / "against.ref1.md")
    assert kwargs["cwd"] == tmp_path / "ref"


def test_first_steps_build_each_wheel_beside_the_worktree(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    (tmp_path / "ref").mkdir()  # compare's worktree of the reference lives in the same folder
    builds = []
    monkeypatch.setattr(bench_against.subprocess, "run", lambda command, **kwargs: builds.append(kwargs["cwd"]))
    sites = []

    def fake_first_step(env_id, check, config, site, after):
        sites.append(site)
        return types.SimpleNamespace(cpu_seconds=float(len(sites)))

    monkeypatch.setattr(bench_against.cold, "first_step", fake_first_step)
    seconds = bench_against.first_steps({"ref": tmp_path / "ref", "this": bench_against.ROOT}, tmp_path, 2)
    assert builds == [tmp_path / "ref", bench_against.ROOT]
    assert seconds == {"ref": [1.0, 3.0], "this": [2.0, 4.0]}  # by turns
    assert sites == [tmp_path / "wheel_ref" / "site", tmp_path / "wheel_this" / "site"] * 2
