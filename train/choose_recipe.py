"""Compare learned recipes on selection episodes, before the benchmark's held-out ones (issue 39, item 4): per
group, each recipe's training seeds pooled against every constant of the ladder, the paper's rule and the V2V-aware
heuristic on the same episodes.

    python -m train.choose_recipe --recipe ppo=results/ppo_v1,results/recipes/ppo_seed1 --recipe real='runs/real/seed*'
    python -m train.choose_recipe --recipe real='runs/real/seed*' --groups default ngsim openacc sumo --out runs/choice

A recipe is ``NAME=RUNS``: its run directories (``train.train_ppo``'s), comma-separated, each a glob. Every
policy plays the default task's group's selection episodes, seeds from 5000 (``--episodes`` per group; SUMO's
``selection`` of the task record at most), never held-out ones. Per group and policy: the mean return with its 95 %
bootstrap interval and the minimum detectable effect of its paired difference (80 % power), collisions per 100
episodes apart, and the paired difference to the best constant of these same episodes (as a share of its |return|, the benchmark's
"loses at most 2 %" scale) and to the paper's rule. The best constant is chosen on the episodes it is compared on,
so it is a generous reference.

The rule, fixed before the recipes it chooses among were trained: the chosen recipe is the one whose worst group
loses least to that group's best constant (the largest minimum over groups of "vs the best constant", in % of its
|return|), the scale of the benchmark's "loses at most 2 %"; ties go to the recipe named first.

Writes ``<out>/selection.csv`` and ``<out>/README.md`` (``--out`` must not exist; ``--force`` replaces it).
"""

from __future__ import annotations

import argparse
import glob
from pathlib import Path
from typing import Any

import numpy as np

from timegap_env import DEFAULT_TASK, cli
from timegap_env.agents.policies import seconds
from timegap_env.experiments import registry
from timegap_env.experiments.rollout import rollout
from timegap_env.experiments.stats import bootstrap_mean, paired_mde
from timegap_env.leaders.scenarios import missing_data
from timegap_env.tasks import SELECTION_SEED_START, get_task

GROUPS = ("default", "ngsim", "openacc")  # the groups the recipes are chosen on, unless --groups
REFERENCES = ("rule_platoon", "v2v_aware")  # the paper's rule and the V2V-aware heuristic
RULE = "rule_platoon"
DEFAULT_RECIPES = ("ppo=results/ppo_v1,results/recipes/ppo_seed?", "ppo_real=results/recipes/ppo_real_seed?",
                   "ppo_real_fast=results/recipes/ppo_real_fast_seed?", "ppo_real_start=results/recipes/ppo_real_start_seed?",
                   "ppo_real_safe=results/recipes/ppo_real_safe_seed?")


def parse_recipe(text: str) -> tuple[str, list[Path]]:
    """``NAME=RUNS`` as (name, run directories); each comma-separated part a glob that must match."""
    name, equals, runs = text.partition("=")
    if not equals or not name:
        raise ValueError(f"--recipe {text!r}: must be NAME=RUN[,RUN...]")
    paths: list[Path] = []
    for part in runs.split(","):
        matched = sorted(glob.glob(part))
        if not matched:
            raise ValueError(f"--recipe {name}: {part!r} matches no run directory")
        paths += [Path(path) for path in matched]
    return name, paths


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="python -m train.choose_recipe", description=__doc__.split("\n")[0])
    parser.add_argument("--recipe", type=parse_recipe, action="append", metavar="NAME=RUNS",
                        help="a recipe and its runs (repeatable; default: " + ", ".join(DEFAULT_RECIPES) + ")")
    parser.add_argument("--groups", nargs="+", default=list(GROUPS),
                        help="groups of the default task to play (default: %(default)s)")
    parser.add_argument("--episodes", type=cli.count, default=1000,
                        help="selection episodes per group, seeds from 5000 (default: %(default)s)")
    parser.add_argument("--out", type=Path, default=Path("runs/recipe-choice"),
                        help="the report's directory (default: %(default)s)")
    parser.add_argument("--force", action="store_true", help="replace --out if it exists")
    args = parser.parse_args(argv)
    if args.recipe is None:
        args.recipe = [parse_recipe(recipe) for recipe in DEFAULT_RECIPES]
    names = [name for name, _ in args.recipe]
    if clash := sorted({name for name in names if names.count(name) > 1 or name.startswith("fixed_")
                        or name in REFERENCES}):
        parser.error(f"--recipe {clash}: each recipe's name once, and none a constant's or a reference's")
    return args


def returns_of(policy: Any, config: Any, seeds: range) -> tuple[np.ndarray, np.ndarray]:
    """Per episode: the return and whether it collided."""
    records = rollout(policy, config, seeds).records
    return (np.array([record.episode_return for record in records]),
            np.array([bool(record.summary["collision"]) for record in records]))


def choose(rows: list[dict[str, Any]], recipes: list[str]) -> tuple[str, float]:
    """The recipe of :data:`rows` (``main``'s) whose worst group's ``vs_best_percent`` is largest, and that value."""
    worst = {recipe: min(row["vs_best_percent"] for row in rows if row["policy"] == recipe) for recipe in recipes}
    chosen = max(recipes, key=lambda recipe: worst[recipe])  # max keeps the first of equals
    return chosen, worst[chosen]


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    cli.output_dir(args.out)
    if args.out.exists() and any(args.out.iterdir()) and not args.force:
        raise FileExistsError(f"--out {args.out}: exists; --force replaces it (or give another --out)")
    task = get_task(DEFAULT_TASK)
    groups = [task.group(name) for name in args.groups]
    rows: list[dict[str, Any]] = []
    for group in groups:
        if group.data and (reason := missing_data(group.data)):
            print(f"group {group.name}: left out, {reason}")
            continue
        config = task.config(group.overrides)
        episodes = min(args.episodes, group.selection) if group.capped else args.episodes
        seeds = range(SELECTION_SEED_START, SELECTION_SEED_START + episodes)
        played: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        for setting in config.setting_levels:
            played[f"fixed_{seconds(setting)}"] = returns_of(registry.make(f"fixed_{seconds(setting)}", config),
                                                              config, seeds)
        best = max(played, key=lambda name: played[name][0].mean())
        for name in REFERENCES:
            played[name] = returns_of(registry.make(name, config), config, seeds)
        for recipe, runs in args.recipe:
            per_run = [returns_of(registry.load_learned(run, config), config, seeds) for run in runs]
            played[recipe] = (np.mean([r for r, _ in per_run], axis=0), np.mean([c for _, c in per_run], axis=0))
            for run, (returns, _) in zip(runs, per_run):
                print(f"{group.name} {recipe} {run}: {returns.mean():.1f}", flush=True)
        scale = abs(played[best][0].mean())
        for name, (returns, collided) in played.items():
            mean, low, high = bootstrap_mean(returns)
            gap = bootstrap_mean((returns - played[best][0]) / scale * 100)
            rule = bootstrap_mean(returns - played[RULE][0])
            mde = paired_mde(returns - played[best if name != best else RULE][0])  # the best constant's: from the rule
            rows.append({"group": group.name, "policy": name, "episodes": episodes, "best_constant": best,
                         "return": mean, "return_low": low, "return_high": high,
                         "collisions_per_100": 100 * float(collided.mean()),
                         "vs_best_percent": gap[0], "vs_best_low": gap[1], "vs_best_high": gap[2],
                         "vs_rule": rule[0], "vs_rule_low": rule[1], "vs_rule_high": rule[2], "mde": mde})
            print(f"{group.name:8s} {name:14s} {mean:8.1f} [{low:.1f}, {high:.1f}] coll {rows[-1]['collisions_per_100']:.2f}"
                  f" vs best {gap[0]:+.1f} % [{gap[1]:+.1f}, {gap[2]:+.1f}] vs rule {rule[0]:+.1f}", flush=True)
    work = cli.work_directory(args.out)
    cli.write_rows(rows, work / "selection.csv")
    recipes = "; ".join(f"{name}: {', '.join(str(run) for run in runs)}" for name, runs in args.recipe)
    lines = ["# Recipes on selection episodes", "", f"Recipes: {recipes}.", "",
             "mde: the smallest difference of return from the best constant (the best constant's row: from the rule) "
             "detectable at 80 % power, paired, in points per episode.", "",
             "| group | policy | return [95 % CI] | mde | collisions /100 | vs the best constant [% of its return] "
             "| vs the paper's rule |", "|---|---|---|---|---|---|---|"]
    lines += [f"| {row['group']} ({row['episodes']} eps, best {row['best_constant']}) | {row['policy']} | "
              f"{row['return']:.1f} [{row['return_low']:.1f}, {row['return_high']:.1f}] | {row['mde']:.1f} | "
              f"{row['collisions_per_100']:.2f} | "
              f"{row['vs_best_percent']:+.1f} [{row['vs_best_low']:+.1f}, {row['vs_best_high']:+.1f}] | "
              f"{row['vs_rule']:+.1f} [{row['vs_rule_low']:+.1f}, {row['vs_rule_high']:+.1f}] |"
              for row in rows if not row["policy"].startswith("fixed_") or row["policy"] == row["best_constant"]]
    names = [name for name, _ in args.recipe]
    chosen, worst = choose(rows, names)
    lines += ["", f"Chosen: **{chosen}**, whose worst group loses {-worst:.1f} % of the best constant's |return| "
              "(the rule: the largest worst-group share; " + ", ".join(
                  f"{name} {min(row['vs_best_percent'] for row in rows if row['policy'] == name):+.1f} %"
                  for name in names) + ")."]
    (work / "README.md").write_text("\n".join(lines) + "\n")
    cli.publish(work, args.out)


if __name__ == "__main__":
    cli.run(main, "python -m train.choose_recipe")
