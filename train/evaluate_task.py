"""Policies on the default task, ``TimeGapMonitor-v1``, against its best blind constant and its full oracle (issue 25).

    python -m train.evaluate_task [--policies rule_platoon chart_step v2v_aware] [--model RUN ...]
                                  [--selection 32] [--held-out 100] [--split held_out|selection]
                                  [--out results/task/policies]

Every policy of ``--policies`` (the policy registry's names) and every trained run of ``--model`` (loaded as it was
trained: its ``env.json`` must name ``TimeGapMonitor-v1``) plays the same held-out episodes of v1 (seeds from
10 000) as the references of ``results/task/v1.md`` (``timegap_env.experiments.task_map.v1_headroom``: the best blind
constant chosen on selection seeds from 5 000, the oracles' tables on training seeds 0..15). Per policy: its return,
its gain over the best blind constant and over a baseline (``--baseline``; default the paper's rule, the first of
``--policies``), paired, with 95 %
bootstrap intervals (also without the collision term, which one episode can carry), the share of the full oracle's
gain it captures, and its collisions. ``--split selection`` plays seeds from 6 000 instead (below every held-out
one), where learned recipes are chosen; the held-out seeds only report. Writes ``policies.md``, ``policies.csv`` and
``pareto.png`` (capacity, string stability and variation of the policies beside the constants') to ``--out``
(through a partial directory: a failed run overwrites nothing).
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import torch

from timegap_env import ENV_IDS, cli
from timegap_env.agents.protocol import ENV_FILE, EVAL_SEED_START, read_env_file
from timegap_env.config import EnvConfig
from timegap_env.experiments.backends import Backend, add_arguments
from timegap_env.experiments.registry import load_learned, tuned_chart_step
from timegap_env.experiments.stats import wilson_interval
from timegap_env.experiments.registry import make as make_policy
from timegap_env.experiments.task_map import (
    FRONT_OBJECTIVES, RECIPE_SEED_START, REFERENCES, V1_GROUPS, Plan, v1_headroom,
)
from timegap_env.leaders.scenarios import missing_data

DEFAULT_POLICIES = ("rule_platoon", "chart_step", "v2v_aware")


def learned(path: Path, config: EnvConfig) -> Any:
    """The run at ``path``, which must have been trained in TimeGapMonitor-v1; ``ValueError`` naming it otherwise."""
    run = read_env_file(path / ENV_FILE)
    if run.env_id != ENV_IDS[1]:
        raise ValueError(f"--model {path}: trained in {run.env_id}, not {ENV_IDS[1]} (its env.json)")
    return load_learned(path, config)


def share(value: float) -> str:
    """A share as a percentage; "n/a" where the oracle gains nothing (no gap to share)."""
    return "n/a" if math.isnan(value) else f"{100 * value:.0f} %"


def group_lines(group: str, reference: dict[str, Any], rows: list[dict[str, Any]], baseline: str) -> list[str]:
    """One group's section: its best blind constant, its policies' table, its references."""
    lines = [f"## {group}", "",
             f"Best blind constant {reference['best_blind']} (return {reference['best_blind_return']:.1f}, "
             f"{reference['best_blind_collisions']} collisions); the full oracle's gain over it "
             f"{reference['full_oracle_gain']:.1f} (`{reference['full_oracle_chosen']}`).", "",
             "| policy | return | gain over best blind [CI] | the same without the collision term [CI] "
             f"| gain over {baseline} [CI] | share of the oracle's gain | collisions [95 % Wilson CI of the rate] |",
             "|---|---|---|---|---|---|---|"]
    for row in rows:
        _, low, high = wilson_interval(row["collisions"], row["episodes"])
        lines.append(f"| {row['policy']} | {row['return']:.1f} | {row['gain']:.1f} [{row['gain_low']:.1f}, "
                     f"{row['gain_high']:.1f}] | {row['gain_without_collisions']:.1f} "
                     f"[{row['gain_without_collisions_low']:.1f}, {row['gain_without_collisions_high']:.1f}] | "
                     f"{row['gain_over_baseline']:.1f} [{row['gain_over_baseline_low']:.1f}, "
                     f"{row['gain_over_baseline_high']:.1f}] | {share(row['share_of_oracle_gain'])} | "
                     f"{row['collisions']}/{row['episodes']} [{low:.2f}, {high:.2f}] |")
    return lines + ["", "References (gain over the best blind constant): " + "; ".join(
        f"{ref} {reference[f'{ref}_gain']:.1f} [{reference[f'{ref}_gain_low']:.1f}, {reference[f'{ref}_gain_high']:.1f}]"
        for ref in REFERENCES) + ".", ""]


def figure(fronts: dict[str, list[dict[str, Any]]], rows: list[dict[str, Any]], path: Path) -> None:
    """Per group, capacity (the efficiency term) against string stability, colour the time-gap variation (tracking),
    each summed over an episode and averaged: the ladder's constants joined by a line, the references and the
    policies as labelled points (higher is better on every axis)."""
    x_name, y_name, colour = FRONT_OBJECTIVES
    groups = list(fronts)
    fig, axes = plt.subplots(1, len(groups), figsize=(4.4 * len(groups), 4.0), squeeze=False)
    for ax, group in zip(axes[0], groups):
        constants = [f for f in fronts[group] if f["point"].startswith("constant")]
        ax.plot([f[x_name] for f in constants], [f[y_name] for f in constants], "-", color="0.7", lw=1, zorder=0)
        points = [*fronts[group], *(row | {"point": row["policy"]} for row in rows if row["traffic"] == group)]
        values = np.array([[p[x_name], p[y_name], p[colour]] for p in points])
        shown = ax.scatter(values[:, 0], values[:, 1], c=values[:, 2], cmap="viridis", s=22)
        for point, (x, y, _) in zip(points, values):
            label = point["point"].replace("constant ", "")
            ax.annotate(label, (x, y), fontsize=5.5, xytext=(3, 2), textcoords="offset points")
        ax.set_title(group, fontsize=9)
        ax.set_xlabel(f"{x_name} (capacity) per episode", fontsize=8)
    axes[0][0].set_ylabel(f"{y_name} per episode", fontsize=8)
    fig.colorbar(shown, ax=axes[0].tolist(), label=f"{colour} (time-gap variation) per episode")
    fig.savefig(path, dpi=110, metadata={"Software": None})
    plt.close(fig)


def markdown(sections: list[list[str]], plan: Plan, runtime: str, notes: list[str]) -> str:
    split = ("held-out episodes (seeds from 10000)" if plan.held_out_start == EVAL_SEED_START else
             f"recipe-selection episodes (seeds from {plan.held_out_start}; not held out: for choosing among recipes)")
    lines = ["# Policies on TimeGapMonitor-v1", "",
             f"Written by `python -m train.evaluate_task`. Per group (`timegap_env.experiments.task_map.V1_GROUPS`: "
             f"v1's task with that group's leaders or degradations), {plan.held_out} {split}, the same for every policy "
             f"and reference; the best blind constant chosen on {plan.selection} selection seeds from 5000 and the "
             f"oracles' tables on training seeds 0-{plan.train - 1}, both of that group. Gains: mean per episode, "
             "paired, [95 % bootstrap interval]; share: the policy's gain over the best blind constant / the full "
             "oracle's.", ""]
    for section in sections:
        lines += section
    return "\n".join([*lines, *notes, f"Runtime: {runtime}", ""])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    defaults = Plan()
    parser.add_argument("--policies", nargs="+", default=list(DEFAULT_POLICIES),
                        help="registry policies; the first is the default --baseline (default: %(default)s)")
    parser.add_argument("--model", type=Path, nargs="*", default=[], help="trained runs (directories) of v1")
    parser.add_argument("--baseline", default=None,
                        help="the policy 'gain over the baseline' is paired against: a name of --policies or a --model "
                             "run's directory name (default: the first of --policies, the paper's rule)")
    parser.add_argument("--chart-step-tuning", type=Path, default=None,
                        help="a tune_rule --env-id TimeGapMonitor-v1 run's tuning.csv: chart_step takes its best cell "
                             "(default: the registered parameters, tuned for v0)")
    parser.add_argument("--train", type=cli.count, default=defaults.train, help="training seeds per condition")
    parser.add_argument("--selection", type=cli.count, default=defaults.selection, help="selection seeds")
    parser.add_argument("--held-out", type=cli.count, default=defaults.held_out, help="held-out seeds")
    parser.add_argument("--split", choices=["held_out", "selection"], default="held_out",
                        help="the episodes: held out (seeds from 10000), or the recipe-selection seeds (from "
                             f"{RECIPE_SEED_START}), where recipes are chosen (default: %(default)s)")
    parser.add_argument("--groups", nargs="+", default=["v1"], choices=list(V1_GROUPS),
                        help="the groups of episodes (default: %(default)s; a group whose data is not found is left "
                             "out, and says so)")
    parser.add_argument("--out", default="results/task/policies", help="directory for policies.md and policies.csv")
    add_arguments(parser)
    args = parser.parse_args()
    cli.output_dir(args.out)
    torch.set_num_threads(1)
    config = EnvConfig.from_dict(version=1)
    tuned = tuned_chart_step(args.chart_step_tuning) if args.chart_step_tuning else {}
    policies = {name: make_policy(name, config, **(tuned if name == "chart_step" else {})) for name in args.policies}
    for path in args.model:
        if path.name in policies:
            raise ValueError(f"--model {path}: its name {path.name!r} is taken by another policy; rename the directory")
        policies[path.name] = learned(path, config)
    start_seed = EVAL_SEED_START if args.split == "held_out" else RECIPE_SEED_START
    plan, backend = Plan(args.train, args.selection, args.held_out, start_seed), Backend.from_args(args)
    work = cli.work_directory(args.out)
    start = time.perf_counter()
    baseline = args.baseline or args.policies[0]
    if baseline not in policies:
        raise ValueError(f"--baseline {baseline!r}: not one of the policies played {list(policies)}")
    rows, sections, notes = [], [], []
    fronts: dict[str, list[dict[str, Any]]] = {}  # group -> the constants' and references' Pareto points
    for group in args.groups:
        missing = missing_data(group)  # a group of a recorded leader is named after its scenario
        if missing:
            notes.append(f"- group {group} left out: {missing}")
            continue
        (reference,), fronts[group], group_rows = v1_headroom(plan, backend, policies, baseline=baseline, group=group)
        rows += group_rows
        sections.append(group_lines(group, reference, group_rows, baseline))
    if not rows:
        raise ValueError(f"--groups {args.groups}: none could run ({'; '.join(notes)})")
    runtime = f"{time.perf_counter() - start:.0f} s ({backend.name} backend)"
    cli.write_rows(rows, work / "policies.csv")
    notes += [f"- {name}: {policy!r}" for name, policy in policies.items()]
    notes.append(f"- chart_step's parameters: {'the best cell of ' + str(args.chart_step_tuning) if tuned else 'registered (tuned for v0)'}")
    figure(fronts, rows, work / "pareto.png")
    notes.append("- pareto.png: per group, capacity against string stability (colour: time-gap variation) of the "
                 "constants, the references and the policies")
    (work / "policies.md").write_text(markdown(sections, plan, runtime, [*notes, ""]), encoding="utf-8")
    cli.publish(work, args.out)
    print((Path(args.out) / "policies.md").read_text(encoding="utf-8"))


if __name__ == "__main__":
    cli.run(main, "python -m train.evaluate_task")
