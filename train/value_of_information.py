"""How much is knowing worth? Blind constants, the hindsight-best constant and the oracles, on the same episodes.

    python -m train.value_of_information [--episodes 120] [--train-episodes 16] [--out results/degradation]
                                         [--config '{"preferred_setting": 1.0}'] [--backend serial|ray] [--address A]

On a fixed set of held-out episodes of the default env (seeds ``EVAL_SEED_START`` on, the default
leader and degradation mix), every ladder setting is held for whole episodes:

- **best blind constant**: the one setting with the best mean return over all episodes, what a
  policy that knows nothing of the episode can do with a constant;
- **hindsight-best constant**: per episode, the best of the constants, knowing the episode in advance;
- **oracles** (``timegap_env.agents.oracles``), reading the ground truth step by step: the stability oracle
  (smallest level ``margin`` above the smallest string-stable setting of the true parameters, for
  each margin of ``MARGINS``) and the lookup oracle (per true condition, the constant that scored
  best on training seeds < ``EVAL_SEED_START``, measured here: each condition pinned from the start
  on ``--train-episodes`` episodes, every constant tried), once for the condition acting now and once
  for the episode's whole schedule from reset on (it sees the future). The best by mean return on
  ``SELECTION_EPISODES`` selection episodes (seeds from ``SELECTION_SEED_START``) is *the* oracle.

Also, per degradation kind: the best constant (no constant wins everywhere), and what the
monitor shows at the best blind constant (its chart's time out of control and exceedances per
episode, and how well each separates that kind's episodes from nominal ones, as an AUC). Writes
``value.md``, ``value.csv`` (per episode), ``lookup.csv`` (per training condition) and
``value.png`` to ``--out``; reruns give the same files.

Each vector-env batch of episodes (a lookup condition, a chunk of at most ``BATCH`` held-out
constant runs, an oracle on the selection or held-out seeds) is one piece of work for
``timegap_env.experiments.backends``: ``--backend serial`` (the default) runs them here one after another,
``--backend ray`` as Ray tasks; the batches are the same, so the files are too, bit for bit.
How the work was spread is printed with the runtime.
"""

from __future__ import annotations

import argparse
import csv
import json
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from timegap_env.agents.oracles import NOMINAL
from timegap_env.agents.policies import seconds
from timegap_env.agents.protocol import EVAL_SEED_START
from timegap_env import cli
from timegap_env.config import EnvConfig
from timegap_env.experiments.backends import Backend, add_arguments
from timegap_env.studies.value import (
    DEFAULT_TRAIN_EPISODES, MONITOR_SIGNALS, SELECTION_EPISODES, SELECTION_SEED_START, TARGET_SHARE, all_oracles, choose_oracle, constants,
    diagonal, kind_groups, measure_lookup, oracle_piece, run,
)

DEFAULT_EPISODES = 120
DEFAULT_OUT = Path("runs/degradation")
def auc(positive: np.ndarray, negative: np.ndarray) -> float:
    """P(a positive scores above a negative), ties counting half (the Mann-Whitney AUC)."""
    if positive.size == 0 or negative.size == 0:
        return float("nan")
    greater = (positive[:, None] > negative[None, :]).mean()
    ties = (positive[:, None] == negative[None, :]).mean()
    return float(greater + 0.5 * ties)


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m train.value_of_information", description=__doc__.split("\n")[0])
    parser.add_argument("--episodes", type=int, default=DEFAULT_EPISODES, help="held-out episodes (default %(default)s)")
    parser.add_argument("--train-episodes", type=int, default=DEFAULT_TRAIN_EPISODES,
                        help="training episodes per condition for the lookup oracle (default %(default)s)")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="output directory (default %(default)s)")
    parser.add_argument("--config", type=json.loads, default={},
                        help="EnvConfig overrides as JSON, e.g. '{\"preferred_setting\": 1.0}' (default: none)")
    add_arguments(parser)
    args = parser.parse_args(argv)
    cli.output_dir(args.out)
    try:
        backend = Backend.from_args(args)
    except ValueError as error:
        parser.error(str(error))
    started = time.perf_counter()
    config = EnvConfig.from_dict(args.config)
    levels = np.asarray(config.setting_levels)
    seeds = list(range(EVAL_SEED_START, EVAL_SEED_START + args.episodes))

    spread = {}  # stage -> how its pieces were spread
    table, lookup_rows = measure_lookup(config, args.train_episodes, backend)
    spread["lookup"] = backend.describe()
    pairs = constants(config, seeds, flag_aware=True, backend=backend)
    spread["held-out constants"] = backend.describe()
    fixed = diagonal(pairs)
    kinds = fixed["kind"][:, 0]
    blind = int(np.argmax(fixed["return"].mean(axis=0)))
    flag_aware = np.unravel_index(int(np.argmax(pairs["return"].mean(axis=0))), pairs["return"].shape[1:])
    hindsight = fixed["return"].max(axis=1)
    oracles = all_oracles(config, table)
    best_oracle = choose_oracle(config, oracles, backend).name  # chosen before the held-out episodes
    spread["oracle choice"] = backend.describe()
    results = backend.map(run, [oracle_piece(config, seeds, oracle) for oracle in oracles])
    spread["held-out oracles"] = backend.describe()
    oracle_results = {oracle.name: result for oracle, result in zip(oracles, results)}
    for name, result in oracle_results.items():
        assert list(result["kind"]) == list(kinds), f"{name} saw other episodes"

    args.out.mkdir(parents=True, exist_ok=True)
    write_episodes(args.out / "value.csv", seeds, kinds, levels, fixed, oracle_results)
    write_lookup(args.out / "lookup.csv", lookup_rows)
    plot(args.out / "value.png", kinds, fixed, blind, hindsight, oracle_results[best_oracle], best_oracle, levels)
    report = write_report(args.out / "value.md", args, config, kinds, fixed, blind, hindsight, oracle_results,
                          best_oracle, pairs, flag_aware)
    print(report)
    print(f"Runtime: {time.perf_counter() - started:.0f} s; spread: "
          + "; ".join(f"{stage}: {how}" for stage, how in spread.items()))


def write_report(path: Path, args: argparse.Namespace, config: EnvConfig, kinds: np.ndarray, fixed: dict[str, np.ndarray],
                 blind: int, hindsight: np.ndarray, oracle_results: dict[str, dict[str, Any]], best_oracle: str,
                 pairs: dict[str, np.ndarray], flag_aware: tuple[int, int]) -> str:
    """value.md: the value-of-information table, the best constant per kind, what the monitor shows."""
    levels = np.asarray(config.setting_levels)
    returns = fixed["return"]
    best_blind = returns[:, blind].mean()
    oracle = oracle_results[best_oracle]["return"].mean()
    gap = oracle - best_blind
    weights = config.degradation.kind_weights
    lines = [
        "# How much is knowing worth? (`python -m train.value_of_information`)", "",
        f"{args.episodes} held-out episodes of the "
        f"{'default env' if not args.config else f'env with overrides `{json.dumps(args.config)}`'} (seeds {EVAL_SEED_START}-{EVAL_SEED_START + args.episodes - 1}; "
        f"leader families {sorted(config.scenario_weights)}; degradation mix `kind_weights` = {dict(weights)}), each run "
        f"with every constant setting and with each oracle. Lookup oracle: per condition, the constant with the best mean "
        f"return on {args.train_episodes} training episodes (seeds 0-{args.train_episodes - 1}) with that condition pinned "
        f"from the start on every follower (`lookup.csv`). The oracle: the best by mean return on {SELECTION_EPISODES} "
        f"selection episodes (seeds {SELECTION_SEED_START}-{SELECTION_SEED_START + SELECTION_EPISODES - 1}). Returns "
        "are undiscounted sums of the reward.", "",
        "| policy | mean return | vs best blind constant | collisions |", "|---|---|---|---|",
        f"| best blind constant ({seconds(levels[blind])} s) | {best_blind:.1f} | 0 | {int(fixed['collision'][:, blind].sum())} |",
        f"| best V2V-aware pair of constants ({seconds(levels[flag_aware[0]])} s with V2V, "
        f"{seconds(levels[flag_aware[1]])} s without) | {pairs['return'][:, flag_aware[0], flag_aware[1]].mean():.1f} | "
        f"{pairs['return'][:, flag_aware[0], flag_aware[1]].mean() - best_blind:+.1f} | "
        f"{int(pairs['collision'][:, flag_aware[0], flag_aware[1]].sum())} |",
        f"| hindsight-best constant per episode | {hindsight.mean():.1f} | {hindsight.mean() - best_blind:+.1f} | "
        f"{int(fixed['collision'][np.arange(len(kinds)), returns.argmax(axis=1)].sum())} |",
    ]
    for name, result in oracle_results.items():
        star = " (**the oracle**)" if name == best_oracle else ""
        lines.append(f"| {name}{star} | {result['return'].mean():.1f} | {result['return'].mean() - best_blind:+.1f} | "
                     f"{int(result['collision'].sum())} |")
    share = gap / abs(best_blind)
    undrivable = int((fixed["collision"].all(axis=1)).sum())
    flag_mean = pairs["return"][:, flag_aware[0], flag_aware[1]].mean()
    lines += ["", f"The oracle beats the best blind constant by {gap:.1f} per episode, {100 * share:.0f} % of its |return| "
              f"(the target: at least {100 * TARGET_SHARE:.0f} %: {'met' if share >= TARGET_SHARE else 'not met'}), and "
              f"the best V2V-aware pair, which already knows what the flag shows, by {oracle - flag_mean:.1f} "
              f"({100 * (oracle - flag_mean) / abs(flag_mean):.0f} %): what knowing the hidden degradations is worth, the "
              f"most a policy reading the monitor could add. Episodes in which every constant collides: {undrivable} of "
              f"{len(kinds)}.", "",
              "## Per degradation kind: no constant wins everywhere", "",
              "| kind | episodes | best constant [s] | its mean return | best blind constant's | hindsight | oracle | "
              "collisions at the best blind constant |", "|---|---|---|---|---|---|---|---|"]
    for label, mask in kind_groups(kinds):
        means = returns[mask].mean(axis=0)
        lines.append(f"| {label} | {int(mask.sum())} | {seconds(levels[int(np.argmax(means))])} | {means.max():.1f} | "
                     f"{means[blind]:.1f} | {hindsight[mask].mean():.1f} | "
                     f"{oracle_results[best_oracle]['return'][mask].mean():.1f} | {int(fixed['collision'][mask, blind].sum())} |")
    lines += ["", "Mean return of every constant per kind:", "",
              "| kind | " + " | ".join(f"{seconds(level)} s" for level in levels) + " |", "|---|" + "---|" * len(levels)]
    for label, mask in kind_groups(kinds):
        lines.append(f"| {label} | " + " | ".join(f"{value:.1f}" for value in returns[mask].mean(axis=0)) + " |")
    nominal = kinds == NOMINAL
    nominal_best = int(np.argmax(returns[nominal].mean(axis=0))) if nominal.any() else blind
    shown = sorted({blind, nominal_best})
    lines += ["", "## What the monitor shows", "",
              "Per episode, the chart's time out of control [s per follower] and exceedances [all followers] (the "
              f"episode summary) at the best blind constant ({seconds(levels[blind])} s) and at the best constant in "
              f"nominal episodes ({seconds(levels[nominal_best])} s); AUC: how well the read-out separates that "
              "kind's episodes from nominal ones (0.5: not at all, 1: perfectly). A blind policy sees only its speed "
              "and the V2V flag, which shows the outage and the commercial ACC cars, nothing else.", "",
              "| kind | episodes | " + " | ".join(f"{seconds(levels[level])} s: {name}" for level in shown
                                                  for name in ("time out of control", "AUC", "exceedances", "AUC"))
              + " |", "|---|---|" + "---|" * (4 * len(shown))]
    for label, mask in kind_groups(kinds)[1:]:
        cells = []
        for level in shown:
            for signal in MONITOR_SIGNALS:
                values = fixed[signal][:, level]
                separation = auc(values[mask], values[nominal])  # NaN without nominal episodes
                cells += [f"{values[mask].mean():.1f}", "–" if label == NOMINAL or np.isnan(separation) else f"{separation:.2f}"]
        lines.append(f"| {label} | {int(mask.sum())} | " + " | ".join(cells) + " |")
    lines += ["", "![value of information](value.png)", ""]
    text = "\n".join(lines)
    path.write_text(text)
    return text


def write_episodes(path: Path, seeds: Sequence[int], kinds: np.ndarray, levels: np.ndarray, fixed: dict[str, np.ndarray],
                   oracle_results: dict[str, dict[str, Any]]) -> None:
    """One row per held-out episode: its kind, every constant's return and collision, every oracle's."""
    with open(path, "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["seed", "kind", *(f"return_{seconds(level)}" for level in levels),
                         *(f"collision_{seconds(level)}" for level in levels),
                         *(f"return_{name}" for name in oracle_results), *(f"collision_{name}" for name in oracle_results)])
        for i, seed in enumerate(seeds):
            writer.writerow([seed, kinds[i], *(f"{value:.4f}" for value in fixed["return"][i]),
                             *(int(value) for value in fixed["collision"][i]),
                             *(f"{result['return'][i]:.4f}" for result in oracle_results.values()),
                             *(int(result["collision"][i]) for result in oracle_results.values())])


def write_lookup(path: Path, rows: list[dict[str, Any]]) -> None:
    """The lookup oracle's table with every constant's mean training return per condition."""
    with open(path, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        for row in rows:
            writer.writerow({k: (f"{v:.4f}" if isinstance(v, float) else v) for k, v in row.items()})


def plot(path: Path, kinds: np.ndarray, fixed: dict[str, np.ndarray], blind: int, hindsight: np.ndarray,
         oracle: dict[str, Any], oracle_name: str, levels: np.ndarray) -> None:
    """Mean return per kind: the best blind constant, the hindsight-best constant and the oracle."""
    groups = kind_groups(kinds)
    x = np.arange(len(groups))
    fig, ax = plt.subplots(figsize=(11, 4.5))
    bars = {f"best blind constant ({seconds(levels[blind])} s)": fixed["return"][:, blind], "hindsight-best constant": hindsight,
            oracle_name: oracle["return"]}
    for k, (label, values) in enumerate(bars.items()):
        ax.bar(x + (k - 1) * 0.27, [values[mask].mean() for _, mask in groups], width=0.27, label=label)
    ax.set_xticks(x, [f"{label}\n({int(mask.sum())})" for label, mask in groups], fontsize=8)
    ax.set_ylabel("mean return per episode")
    ax.grid(axis="y", alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title("Value of information per degradation kind (held-out episodes)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    cli.run(main, "python -m train.value_of_information")
