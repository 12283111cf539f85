"""``train.benchmark``: the efficiency basis, the constants' frontier, a user's policy against the constant it holds,
the cache, the lock, and bad command lines as one line (short episodes, small groups)."""

from __future__ import annotations

import dataclasses
import os
import pickle
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import timegap_env
from timegap_env.tasks import HeldOutGroup, get_task
from timegap_env.config import EnvConfig
from timegap_env.experiments import registry
from train import benchmark
from train.benchmark import Cache, efficiency, frontier_efficiency, frontier_rate, run_group

REPO = Path(__file__).resolve().parents[2]
SHORT = {"episode_duration": 20.0}  # 20-s episodes: a group of a few dozen plays in seconds
TINY = HeldOutGroup("tiny", "short episodes of the task's mix", SHORT, 24, references=False, selection=24)

HOLDER = '''
import numpy as np


class HoldOne:
    """Holds the ladder's 1.4 s for the whole episode, the platoon's setting."""

    action_mode = "platoon"

    def __init__(self, config):
        self.index = list(config.setting_levels).index(1.4)

    def predict(self, obs, state=None, episode_start=None, deterministic=True):
        return np.full(obs.shape[0], self.index), state
'''


def constants_and(*extra: benchmark.Entry) -> list[benchmark.Entry]:
    config = benchmark.group_config(TINY)
    return [benchmark.registered(name) for name in registry.fixed_names(config)] + [benchmark.registered("rule_platoon"),
                                                                                  *extra]


@pytest.fixture
def holder_module(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> str:
    (tmp_path / "holder_policy.py").write_text(HOLDER)
    monkeypatch.syspath_prepend(str(tmp_path))
    return "holder_policy:HoldOne"


def test_the_default_task_is_v1() -> None:
    assert timegap_env.DEFAULT_TASK == "TimeGapMonitor-v1" == benchmark.TASK


def test_efficiency_is_per_second_driven_so_crashing_early_pays_nothing() -> None:
    config = get_task("TimeGapMonitor-v1").config()
    full = efficiency(-100.0, 0.0, config.episode_duration, config)
    assert full == -100.0  # an episode driven to the end: its return without the collision term
    # the same rate of reward, cut short by a crash after 50 s: the collision term is left out, the rest scaled up
    crashed = efficiency(-20.0 - config.reward_weights.collision, -1.0, 50.0, config)
    assert crashed == pytest.approx(full)
    # the return without the collision term would have rewarded the crash (-20 > -100)
    assert -20.0 > full


def test_the_frontier_of_constants_and_its_mixes() -> None:
    rates = np.array([0.04, 0.01, 0.0])  # three constants: risky and efficient ... safe and slow
    effs = np.array([-50.0, -80.0, -120.0])
    assert frontier_efficiency(rates, effs, np.array(0.01)) == pytest.approx(-80.0)
    assert frontier_efficiency(rates, effs, np.array(0.025)) == pytest.approx(-65.0)  # a mix of the first two
    assert frontier_efficiency(rates, effs, np.array(0.5)) == pytest.approx(-50.0)  # more risk buys nothing more
    assert frontier_rate(rates, effs, np.array(-65.0)) == pytest.approx(0.025)
    assert frontier_rate(rates, effs, np.array(-130.0)) == pytest.approx(0.0)
    # a dominated constant does not lower the frontier
    assert frontier_efficiency(np.append(rates, 0.03), np.append(effs, -200.0), np.array(0.03)) == pytest.approx(-60.0)
    # batched over resamples: (B, k) points, (B,) rates
    batch = frontier_efficiency(np.stack([rates, rates]), np.stack([effs, effs + 10]), np.array([0.01, 0.01]))
    assert batch == pytest.approx([-80.0, -70.0])


def test_a_users_policy_holding_one_setting_scores_exactly_as_that_constant(holder_module: str, tmp_path: Path) -> None:
    entries = constants_and(benchmark.policy_entry(holder_module))
    result = run_group(TINY, entries, 10_000, TINY.episodes, Cache(tmp_path / "cache"), benchmark.Backend())
    rows = {row["policy"]: row for row in result.rows}
    mine, constant = rows["HoldOne"], rows["fixed_1.4"]
    different = {key for key in constant if key not in ("policy", "kind") and
                 not (mine[key] == constant[key] or (mine[key] != mine[key] and constant[key] != constant[key]))}
    assert not different
    assert np.array_equal(result.played["HoldOne"].fingerprints, result.played["fixed_1.4"].fingerprints)
    assert rows["fixed_1.4"]["frontier_efficiency_gain"] <= 1e-9  # no constant beats the constants' frontier


def test_a_computed_group_plays_only_what_it_has_not_played(monkeypatch: pytest.MonkeyPatch, holder_module: str,
                                                            tmp_path: Path) -> None:
    cache = tmp_path / "cache"
    first = run_group(TINY, constants_and(), 10_000, TINY.episodes, Cache(cache), benchmark.Backend())
    played: list[Any] = []
    original = benchmark.play
    monkeypatch.setattr(benchmark, "play", lambda *args: played.append(args) or original(*args))
    again = run_group(TINY, constants_and(benchmark.policy_entry(holder_module)), 10_000, TINY.episodes,
                      Cache(cache), benchmark.Backend())
    assert len(played) == 1 and played[0][0].__class__.__name__ == "HoldOne"  # the new policy alone
    assert [row for row in again.rows if row["policy"] != "HoldOne"] == first.rows


class ScriptFreeUnpickler(pickle.Unpickler):
    """Refuses a class defined in the script: ``python -m train.benchmark`` names it ``__main__``, an import
    ``train.benchmark``, so a cache holding one could not be read by the other."""

    def find_class(self, module: str, name: str) -> Any:
        if module in ("__main__", "train.benchmark"):
            raise pickle.UnpicklingError(f"{module}.{name} in the cache")
        return super().find_class(module, name)


def test_the_cache_holds_no_class_of_the_script_so_the_command_and_the_python_call_share_it(tmp_path: Path) -> None:
    cache = tmp_path / "cache"
    run_group(TINY, constants_and(), 10_000, TINY.episodes, Cache(cache), benchmark.Backend())
    files = sorted(cache.glob("*.pkl"))
    assert len(files) == len(constants_and()) + 1  # every policy's episodes and the constants' choice
    for path in files:
        with open(path, "rb") as file:
            ScriptFreeUnpickler(file).load()


def test_an_unreadable_cache_entry_is_played_again(tmp_path: Path) -> None:
    cache = tmp_path / "cache"
    first = run_group(TINY, constants_and(), 10_000, TINY.episodes, Cache(cache), benchmark.Backend())
    played = sorted(path for path in cache.glob("*.pkl") if isinstance(Cache(cache).get(path.stem), dict))
    played[0].write_bytes(b"not a pickle")  # a torn or foreign file
    with open(played[1], "wb") as file:
        pickle.dump(("an", "object", "of", "another", "layout"), file)
    again = run_group(TINY, constants_and(), 10_000, TINY.episodes, Cache(cache), benchmark.Backend())
    assert again.rows == first.rows
    assert all(isinstance(Cache(cache).get(path.stem), dict) for path in played[:2])  # written again


def test_the_lock_refuses_a_second_writer_and_takes_over_a_dead_ones(tmp_path: Path) -> None:
    out = tmp_path / "bench"
    with benchmark.claimed(out):
        with pytest.raises(FileExistsError, match="another run"):
            with benchmark.claimed(out):
                pass
    assert not (tmp_path / "bench.lock").exists()
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    (tmp_path / "bench.lock").write_text(dead.stdout.strip())
    with benchmark.claimed(out):
        assert (tmp_path / "bench.lock").read_text() == str(os.getpid())


@pytest.mark.parametrize(("arguments", "says"), [
    (["--policy", "no_such_policy"], "--policy no_such_policy: unknown"),
    (["--policy", "no_such_module_xyz:Thing"], "cannot import 'no_such_module_xyz'"),
    (["--groups", "default", "nowhere"], "--groups nowhere: unknown"),
    (["--episodes", "0"], "--episodes: '0': must be an integer >= 1"),
    (["--episodes", "-3"], "must be an integer >= 1"),
    (["--first-seed", "12"], "--first-seed 12: must be >= 10000"),
    (["--out", "results"], "--out results: exists; --force replaces it"),
])
def test_bad_command_lines_give_one_line(arguments: list[str], says: str, tmp_path: Path) -> None:
    run = subprocess.run([sys.executable, "-m", "train.benchmark", "--cache", str(tmp_path / "c"), *arguments],
                         capture_output=True, text=True, cwd=REPO, timeout=300)
    assert run.returncode != 0
    lines = [line for line in run.stderr.splitlines() if line.strip() and "first run compiles" not in line]
    assert len(lines) == 1 and says in lines[0], run.stderr
    assert not list(tmp_path.glob("*partial*"))


def test_the_held_out_recorded_leaders_are_a_fixed_quarter() -> None:
    from timegap_env.leaders.profile import recorded_part

    items = list(range(10))
    held_out, train = recorded_part(items, "held_out"), recorded_part(items, "train")
    assert held_out == [0, 4, 8] and sorted(held_out + train) == items
    with pytest.raises(ValueError, match="recorded_part = 'some'"):
        recorded_part(items, "some")


def test_the_collision_rate_of_1_0_s_agrees_on_another_range_of_seeds() -> None:
    """The issue's check: the held-out range (from 10000) and an independent one (from 100000) draw the same mix.
    1,500 episodes each (~3 % collide): a two-proportion z-test at the 0.1 % level."""
    config = get_task("TimeGapMonitor-v1").config()
    policy = registry.make("fixed_1.0", config)
    n = 1_500
    counts = [int(benchmark.play(policy, config, list(range(start, start + n))).collided.sum())
              for start in (10_000, 100_000)]
    pooled = sum(counts) / (2 * n)
    z = (counts[0] - counts[1]) / n / np.sqrt(pooled * (1 - pooled) * 2 / n)
    assert 0.015 < pooled < 0.06 and abs(z) < 3.29, (counts, z)


def test_the_monitor_question_sets_each_recipe_against_its_twins() -> None:
    def played(mean: float) -> benchmark.Played:
        n = 4
        return benchmark.Played(np.full(n, mean), np.zeros(n), np.zeros(n, bool), np.zeros(n), np.ones(n),
                                np.array(["x"] * n))

    def group(name: str, means: dict[str, float]) -> benchmark.GroupResult:
        entries = {policy: benchmark.Entry(policy, "constant" if policy == "fixed_1.0" else "learned",
                                           lambda config, refs: None, "", policy.rsplit("@", 1)[0], 0)
                   for policy in means}
        return benchmark.GroupResult(dataclasses.replace(TINY, name=name), (10_000, 4), "fixed_1.0", "fixed_1.0", {},
                                     {policy: played(mean) for policy, mean in means.items()}, entries, [])

    results = {"a": group("a", {"fixed_1.0": -100.0, "r@0": -90.0, "r@1": -95.0, "r_rawgap@0": -99.0,
                                "r_rawgap@1": -98.0}),
               "b": group("b", {"fixed_1.0": -100.0, "r@0": -110.0, "r@1": -95.0, "r_rawgap@0": -100.0,
                                "r_rawgap@1": -100.0})}
    rows = benchmark.monitor_question(results)
    assert [(row["twin"], row["group"]) for row in rows] == [("r_rawgap", "a"), ("r_rawgap", "b"),
                                                              ("r_rawgap", "all (IQM)")]
    assert rows[0]["score"] == pytest.approx(7.5) and rows[0]["twin_score"] == pytest.approx(1.5)
    assert rows[0]["poi"] == 1.0 and rows[1]["poi"] == 0.5  # b: one seed ahead of both twins', one behind both
    assert rows[2]["poi"] == 0.75 and rows[2]["poi_low"] <= 0.75 <= rows[2]["poi_high"]
