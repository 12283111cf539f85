"""``train.sweep``: the grid and its errors, the tidy table, resuming, bit-identical reruns (serial, short episodes)."""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any

import pytest
import yaml

from train import sweep
from timegap_env.experiments.backends import Backend
from timegap_env.tasks import get_task

TINY = {  # 2 cells x 2 policies x 2 seed batches = 8 pieces of 2 episodes of 20 s
    "axes": {"monitor.window": [1.0, 2.0]},
    "base": {"episode_duration": 20.0, "degradation": {"kind_weights": {"gain": 1.0}}},
    "policies": ["rule_platoon", "fixed_1.6"],
    "seeds": {"start": 10_000, "count": 4, "batch": 2},
}


def write_grid(folder: Path, grid: dict[str, Any], name: str = "grid.yml") -> Path:
    path = folder / name
    path.write_text(yaml.safe_dump(grid, sort_keys=False))
    return path


class Counting(Backend):
    """The serial backend, remembering the pieces it ran; with ``fail_after`` calls it raises on the next one."""

    def __init__(self, fail_after: int | None = None) -> None:
        super().__init__("serial")
        self.pieces: list[tuple[Any, ...]] = []
        self.calls, self.fail_after = 0, fail_after

    def map(self, function, pieces):
        if self.calls == self.fail_after:
            raise KeyboardInterrupt("interrupted")
        self.calls += 1
        self.pieces += list(pieces)
        return super().map(function, pieces)


def run(folder: Path, grid_path: Path, backend: Backend | None = None, chunk: int = sweep.DEFAULT_CHUNK) -> str:
    return sweep.sweep(sweep.load_grid(grid_path), folder, backend or Backend("serial"), chunk)


def rows_of(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as file:
        return list(csv.DictReader(file))


def all_but_last_line(text: str) -> list[str]:
    lines = text.rstrip("\n").split("\n")
    assert lines[-1].startswith("Runtime: ")
    return lines[:-1]


# ---------------------------------------------------------------- the grid
def test_axes_make_the_product_of_cells_with_the_base_merged_in(tmp_path):
    grid = sweep.load_grid(write_grid(tmp_path, {
        **TINY, "axes": {"reward_weights.efficiency": [0.5, 1.0, 2.0],
                         "degradation.gain_range": [[0.6, 0.85], [0.4, 0.6]]}}))
    assert grid.columns == ("reward_weights.efficiency", "degradation.gain_range")
    assert len(grid.cells) == 6 and grid.cells[1] == {"reward_weights.efficiency": 0.5,
                                                      "degradation.gain_range": [0.4, 0.6]}
    assert grid.overrides(grid.cells[1]) == {
        "episode_duration": 20.0, "reward_weights": {"efficiency": 0.5},
        "degradation": {"kind_weights": {"gain": 1.0}, "gain_range": [0.4, 0.6]}}
    assert grid.seeds == (10_000, 10_001, 10_002, 10_003) and grid.batches() == [(10_000, 10_001), (10_002, 10_003)]
    assert grid.held_out and grid.model is None


def test_explicit_cells_take_the_union_of_their_fields_as_columns(tmp_path):
    cells = [{"monitor.window": 1.0}, {"chart.switch_exceedances": 4, "monitor.window": 5.0}]
    grid = sweep.load_grid(write_grid(tmp_path, {**{k: v for k, v in TINY.items() if k != "axes"}, "cells": cells}))
    assert grid.columns == ("monitor.window", "chart.switch_exceedances") and list(grid.cells) == cells


def test_cell_and_piece_keys_are_stable_hashes_of_what_runs(tmp_path):
    pieces, cells, _ = sweep.plan(sweep.load_grid(write_grid(tmp_path, TINY)))
    reordered = {**TINY, "base": {"degradation": {"kind_weights": {"gain": 1.0}}, "episode_duration": 20.0}}
    again, same_cells, _ = sweep.plan(sweep.load_grid(write_grid(tmp_path, reordered, "b.yml")))
    assert [p.key for p in again] == [p.key for p in pieces] and same_cells == cells
    assert len({p.key for p in pieces}) == 8 and len(set(cells)) == 2
    other, other_cells, _ = sweep.plan(sweep.load_grid(write_grid(tmp_path, {**TINY, "axes": {
        "monitor.window": [1.0, 5.0]}}, "c.yml")))
    assert other_cells[0] == cells[0] and other_cells[1] != cells[1]
    assert [p.key for p in other[:4]] == [p.key for p in pieces[:4]]


@pytest.mark.parametrize("change, message", [
    ({"axes": {"reward_weights.eficiency": [1.0]}}, r"'reward_weights.eficiency'.*RewardWeights has no field"),
    ({"axes": {"monitr.window": [1.0]}}, r"unknown field 'monitr.window'"),
    ({"axes": {"episode_duration.x": [1.0]}}, r"'episode_duration.x'.*not a nested config"),
    ({"axes": {"action_mode": ["per_vehicle"]}}, r"'action_mode' cannot be swept"),
    ({"axes": {"degradation.gain_range": [[0.85, 0.6]]}}, r"gain_range = \[0.85, 0.6\].*low < high"),
    ({"axes": {"monitor.window": 1.0}}, r"monitor.window = 1.0: must be a non-empty list"),
    ({"axes": {"degradation": [{}], "degradation.gain_range": [[0.4, 0.6]]}}, r"'degradation' and .* overlap"),
    ({"cells": [{"monitor.window": 1.0}]}, r"either axes .* or cells"),
    ({"base": {"reward_weights": {"speed": 1.0}}}, r"unknown RewardWeights field\(s\) \['speed'\]"),
    ({"base": {"scenario_weights": {"traffic_jam": 1.0}}}, r"unknown families \['traffic_jam'\]"),
    ({"policies": ["rule_platoon", "greedy", "fixed_x"]}, r"unknown policies \['greedy'\]"),
    ({"policies": ["fixed_x"]}, r"policy 'fixed_x'.*'x' is not a number"),
    ({"policies": ["fixed_1.7"]}, r"policy 'fixed_1.7'.*setting = 1.7 s: must be one of setting_levels"),
    ({"seeds": {"start": 0, "count": 4}}, r"seeds.start = 0: held-out seeds start at 10000"),
    ({"seeds": {"start": 9_998, "count": 4, "held_out": False}}, r"seeds.start \+ seeds.count = 10002"),
    ({"seeds": {"start": 10_000, "count": 0}}, r"seeds.count = 0: must be an integer >= 1"),
    ({"seeds": {"start": 10_000, "count": 4, "batches": 2}}, r"seeds: unknown key\(s\) \['batches'\]"),
    ({"policy": ["rule_platoon"]}, r"unknown key\(s\) \['policy'\]"),
])
def test_a_bad_grid_is_a_value_error_naming_what_is_wrong(tmp_path, change, message):
    with pytest.raises(ValueError, match=message):
        sweep.load_grid(write_grid(tmp_path, {**TINY, **change}))


def test_the_command_line_reports_a_bad_grid_as_a_usage_error(tmp_path, capsys):
    path = write_grid(tmp_path, {**TINY, "axes": {"reward_weights.eficiency": [1.0]}})
    with pytest.raises(SystemExit) as exit_:
        sweep.main([str(path), "--out", str(tmp_path / "out")])
    assert exit_.value.code == 2 and "reward_weights.eficiency" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_training_seeds_run_when_the_grid_says_so(tmp_path):
    grid = sweep.load_grid(write_grid(tmp_path, {**TINY, "seeds": {"start": 100, "count": 2, "held_out": False}}))
    assert grid.seeds == (100, 101) and not grid.held_out


# ---------------------------------------------------------------- the table and resuming
@pytest.fixture(scope="module")
def full_run(tmp_path_factory) -> tuple[Path, Path]:
    """The tiny grid run once: (its grid file, its output folder)."""
    folder = tmp_path_factory.mktemp("sweep")
    grid = write_grid(folder, TINY)
    run(folder / "out", grid)
    return grid, folder / "out"


def test_one_row_per_episode_with_the_overrides_policy_seed_and_summary(full_run):
    _, out = full_run
    rows = rows_of(out / sweep.EPISODES_FILE)
    assert len(rows) == 2 * 2 * 4
    assert list(rows[0])[:9] == ["piece", "cell", "monitor.window", "policy", "seed", "scenario", "degradation",
                                 "return", "collision"]
    assert {"mean_setting", "time_out_of_control", "exceedances", "min_ttc", "duration"} <= set(rows[0])
    assert [(r["monitor.window"], r["policy"], r["seed"]) for r in rows[:5]] == [
        ("1.0", "rule_platoon", "10000"), ("1.0", "rule_platoon", "10001"), ("1.0", "rule_platoon", "10002"),
        ("1.0", "rule_platoon", "10003"), ("1.0", "fixed_1.6", "10000")]
    assert {r["degradation"] for r in rows} == {"gain"} and all(float(r["duration"]) == 20.0 for r in rows)
    assert all(float(r["mean_setting"]) == pytest.approx(1.6) for r in rows if r["policy"] == "fixed_1.6")
    same_seed = [r for r in rows if r["seed"] == "10001"]
    assert len({r["scenario"] for r in same_seed}) == 1  # every cell and policy sees the same leader


def test_the_summary_has_a_row_per_cell_and_policy_and_the_best_per_cell(full_run):
    _, out = full_run
    text = (out / sweep.SUMMARY_FILE).read_text()
    assert text.count("| rule_platoon |") + text.count("| **rule_platoon** |") == 2
    assert "## Best policy per cell" in text and "nan" not in text.lower()
    assert "8 of 8 pieces run now in 1 map call(s)" in text.rstrip().split("\n")[-1]


def test_a_rerun_of_a_finished_sweep_runs_nothing_and_rewrites_the_same_files(full_run, tmp_path):
    grid, out = full_run
    before = {name: (out / name).read_text() for name in (sweep.EPISODES_FILE, sweep.SUMMARY_FILE)}
    backend = Counting()
    text = run(out, grid, backend)
    assert backend.pieces == [] and (out / sweep.EPISODES_FILE).read_text() == before[sweep.EPISODES_FILE]
    assert all_but_last_line(text) == all_but_last_line(before[sweep.SUMMARY_FILE])
    assert "all 8 pieces were already in episodes.csv, none run" in text


def test_a_fresh_run_writes_the_same_bits(full_run, tmp_path):
    grid, out = full_run
    run(tmp_path, grid, chunk=3)  # other chunks, same table
    assert (tmp_path / sweep.EPISODES_FILE).read_bytes() == (out / sweep.EPISODES_FILE).read_bytes()


def test_deleted_rows_rerun_only_their_pieces_and_the_file_equals_the_full_run(full_run, tmp_path):
    grid, out = full_run
    full = (out / sweep.EPISODES_FILE).read_text()
    lines = full.splitlines(keepends=True)
    header, body = lines[0], lines[1:]
    second_piece = {line.split(",")[0] for line in body[2:4]}
    kept = [line for i, line in enumerate(body) if i != 0 and line.split(",")[0] not in second_piece]
    (tmp_path / sweep.EPISODES_FILE).write_text(header + "".join(kept))  # piece 1 lost a row, piece 2 all
    backend = Counting()
    run(tmp_path, grid, backend)
    assert [(policy, seeds) for _, policy, seeds, _ in backend.pieces] == [
        ("rule_platoon", (10_000, 10_001)), ("rule_platoon", (10_002, 10_003))]
    assert backend.pieces[0][0] == get_task(sweep.DEFAULT_TASK).config({**TINY["base"], "monitor": {"window": 1.0}})
    assert (tmp_path / sweep.EPISODES_FILE).read_text() == full


def test_an_interrupted_sweep_keeps_its_finished_chunks_and_resumes(full_run, tmp_path):
    grid, out = full_run
    full = rows_of(out / sweep.EPISODES_FILE)
    with pytest.raises(KeyboardInterrupt):
        run(tmp_path, grid, Counting(fail_after=2), chunk=3)
    assert rows_of(tmp_path / sweep.EPISODES_FILE) == full[:2 * 3 * 2]  # two chunks of 3 pieces of 2 episodes
    assert not (tmp_path / sweep.SUMMARY_FILE).exists()
    backend = Counting()
    run(tmp_path, grid, backend, chunk=3)
    assert len(backend.pieces) == 2 and (tmp_path / sweep.EPISODES_FILE).read_bytes() == \
        (out / sweep.EPISODES_FILE).read_bytes()


def test_rows_of_pieces_the_grid_no_longer_plans_are_kept_and_not_summarised(full_run, tmp_path):
    _, out = full_run
    (tmp_path / sweep.EPISODES_FILE).write_bytes((out / sweep.EPISODES_FILE).read_bytes())
    smaller = write_grid(tmp_path, {**TINY, "policies": ["fixed_1.6"]}, "smaller.yml")
    backend = Counting()
    text = run(tmp_path, smaller, backend)
    assert backend.pieces == [] and "also keeps 8 rows of pieces this grid does not plan" in text
    assert (tmp_path / sweep.EPISODES_FILE).read_bytes() == (out / sweep.EPISODES_FILE).read_bytes()
    assert "rule_platoon" not in text.split("## Mean return")[1]
    wider = write_grid(tmp_path, {**TINY, "policies": ["fixed_1.6", "fixed_1.0"]}, "wider.yml")
    run(tmp_path, wider, backend)  # runs fixed_1.0: the planned rows first, in the plan's order, then the rest
    rows = rows_of(tmp_path / sweep.EPISODES_FILE)
    assert len(backend.pieces) == 4 and [r["policy"] for r in rows] == \
        (["fixed_1.6"] * 4 + ["fixed_1.0"] * 4) * 2 + ["rule_platoon"] * 8


def test_a_table_of_other_axes_is_not_mixed_in(full_run, tmp_path):
    _, out = full_run
    (tmp_path / sweep.EPISODES_FILE).write_bytes((out / sweep.EPISODES_FILE).read_bytes())
    other = write_grid(tmp_path, {**TINY, "axes": {"reward_weights.efficiency": [1.0]}}, "other.yml")
    with pytest.raises(ValueError, match=r"not this grid's .*'reward_weights.efficiency'.*another --out"):
        run(tmp_path, other)


def test_the_trained_policy_runs_from_its_files_and_its_key_follows_the_model(tmp_path):
    grid = {**TINY, "axes": {"monitor.window": [2.0]}, "policies": ["ppo"], "seeds": {"start": 10_000, "count": 2}}
    path = write_grid(tmp_path, grid)
    run(tmp_path / "a", path)
    run(tmp_path / "b", path, Backend("serial"))
    rows = rows_of(tmp_path / "a" / sweep.EPISODES_FILE)
    assert [r["policy"] for r in rows] == ["ppo", "ppo"]
    assert (tmp_path / "a" / sweep.EPISODES_FILE).read_bytes() == (tmp_path / "b" / sweep.EPISODES_FILE).read_bytes()
    files = sweep.model_files(sweep.DEFAULT_MODELS[sweep.DEFAULT_TASK])
    copy = tmp_path / "model"
    copy.mkdir()
    for name, data in files.items():
        (copy / name).write_bytes(data)
    (copy / "env.json").write_text(json.dumps({"env_kwargs": {"config": {"action_mode": "relative"}},
                                               "frame_stack": 1}, indent=2))  # another run's bytes
    moved, _, _ = sweep.plan(sweep.load_grid(write_grid(tmp_path, {**grid, "model": str(copy)}, "moved.yml")))
    assert moved[0].key != rows[0]["piece"]


def test_a_grid_without_a_model_for_ppo_says_so(tmp_path):
    with pytest.raises(FileNotFoundError, match="no model.zip"):
        sweep.load_grid(write_grid(tmp_path, {**TINY, "policies": ["ppo"], "model": str(tmp_path / "absent")}))


def test_the_committed_example_grid_parses(tmp_path):
    grid = sweep.load_grid(Path(sweep.__file__).parent / "sweeps" / "example.yml")
    assert len(grid.cells) * len(grid.policies) >= 6 and grid.held_out
