"""Tune the chart step rule (``timegap_env.agents.policies.ChartStepPolicy``) on training seeds: a small grid, mean return per cell.

    python -m train.tune_rule [--episodes 256] [--out runs/rule] [--env-id TimeGapMonitor-v1|-v0]
                              [--k-up 1 2 3 4 6] [--quiet-time 10 20 35] [--min-setting 1.0 1.2 1.4 1.6]

Every cell of the grid k_up x quiet_time x min_setting runs the platoon-wide rule on the same episodes of
the task of ``--env-id`` (its leader families, degradation mix and reward; seeds ``TUNING_SEED_START`` on: training seeds below
``EVAL_SEED_START``, apart from ``train.value_of_information``'s lookup seeds 0-15 and selection seeds
5000-5047), beside the paper's rule and fixed 1.6 s and 1.0 s for reference, all in one native vector env.
The best cell has the largest mean return (the first in grid order on a tie). Writes ``tuning.md`` and
``tuning.csv`` (one row per policy) to ``--out``; reruns give the same files. The defaults of
``ChartStepPolicy`` are the best cell of the committed run.
"""

from __future__ import annotations

import argparse
import csv
import itertools
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from timegap_env.agents.policies import ChartStepPolicy, FixedPolicy, NamedPolicy, seconds
from timegap_env.agents.protocol import EVAL_SEED_START
from timegap_env import DEFAULT_TASK, ENV_ID, TASKS, cli
from timegap_env.config import EnvConfig
from timegap_env.tasks import get_task
from timegap_env.experiments.registry import fixed_name
from timegap_env.experiments.registry import make as make_policy
from timegap_env.experiments.rollout import rollout_side_by_side
from timegap_env.studies.value import SELECTION_SEED_START, kind_groups

DEFAULT_EPISODES = 256
DEFAULT_OUT = Path("runs/rule")  # never a committed result: make reproduce writes results/rule (v1), results/v0/rule
TUNING_SEED_START = 3_000  # first tuning seed, below SELECTION_SEED_START and EVAL_SEED_START [-]
K_UP = (1, 2, 3, 4, 6)  # exceedances within the chart's window that send a follower up [-]
QUIET_TIMES = (10.0, 20.0, 35.0)  # time without an alarm that sends a follower down, at most the window [s]
MIN_SETTINGS = (1.0, 1.2, 1.4, 1.6)  # floors of the rule [s]
REFERENCE_SETTINGS = (1.6, 1.0)  # fixed settings beside the grid, the first the yardstick of the differences [s]
SUMMARY = ("collision", "mean_setting", "switches", "min_ttc")  # episode summary read-outs kept per episode


def run(seeds: Sequence[int], policies: Sequence[NamedPolicy], config: EnvConfig | None = None) -> dict[str, np.ndarray]:
    """Every policy on every seed in one native vector env of ``config`` (default: v0's; the rollout harness, policies
    side by side): return, ``SUMMARY``, arrays (n_policies, n_seeds), and the kind of degradation of each seed's
    episode (n_seeds,)."""
    batches = rollout_side_by_side(policies, config, seeds, step_diagnostics=False)
    table = {name: np.array([[record.summary[name] for record in batch.records] for batch in batches], dtype=float)
             for name in SUMMARY}
    return {"return": np.array([[record.episode_return for record in batch.records] for batch in batches]), **table,
            "kind": np.array([record.degradation for record in batches[0].records], dtype=object)}


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m train.tune_rule", description=__doc__.split("\n")[0])
    parser.add_argument("--episodes", type=int, default=DEFAULT_EPISODES,
                        help=f"tuning episodes, seeds {TUNING_SEED_START} on (default %(default)s)")
    parser.add_argument("--out", type=Path, default=None,
                        help=f"output directory (default {DEFAULT_OUT}/<env id>)")
    parser.add_argument("--env-id", default=DEFAULT_TASK, choices=list(TASKS),
                        help="the task the rule is tuned for (default: %(default)s)")
    parser.add_argument("--k-up", type=int, nargs="+", default=K_UP, help="grid of k_up (default %(default)s)")
    parser.add_argument("--quiet-time", type=float, nargs="+", default=QUIET_TIMES,
                        help="grid of quiet_time [s] (default %(default)s)")
    parser.add_argument("--min-setting", type=float, nargs="+", default=MIN_SETTINGS,
                        help="grid of min_setting [s] (default %(default)s)")
    args = parser.parse_args(argv)
    if args.out is None:
        args.out = DEFAULT_OUT / args.env_id
    cli.output_dir(args.out)
    if not 1 <= args.episodes <= SELECTION_SEED_START - TUNING_SEED_START:
        parser.error(f"--episodes {args.episodes}: must be in [1, {SELECTION_SEED_START - TUNING_SEED_START}], "
                     f"the seeds below the selection seeds")
    started = time.perf_counter()
    config = get_task(args.env_id).config()
    seeds = list(range(TUNING_SEED_START, TUNING_SEED_START + args.episodes))
    assert seeds[-1] < min(SELECTION_SEED_START, EVAL_SEED_START)
    grid = list(itertools.product(args.k_up, args.quiet_time, args.min_setting))
    cells = [make_policy("chart_step", config, k_up=k_up, quiet_time=quiet, min_setting=floor)
             for k_up, quiet, floor in grid]
    references = [make_policy("rule_platoon", config), *(make_policy(fixed_name(setting), config)
                                                         for setting in REFERENCE_SETTINGS)]
    results = run(seeds, [*cells, *references], config)
    best = int(np.argmax(results["return"][:len(cells)].mean(axis=1)))

    args.out.mkdir(parents=True, exist_ok=True)
    write_csv(args.out / "tuning.csv", config, [*cells, *references], results, best)
    report = write_report(args.out / "tuning.md", config, seeds, cells, references, results, best, args.env_id)
    print(report)
    print(f"Best: k_up = {cells[best].k_up}, quiet_time = {seconds(cells[best].quiet_time)} s, "
          f"min_setting = {seconds(cells[best].min_setting)} s; mean return {results['return'][best].mean():.1f}")
    print(f"Runtime: {time.perf_counter() - started:.0f} s")


def cell_parameters(policy: NamedPolicy) -> list[str]:
    """A policy's grid coordinates for the tables: k_up, quiet time [s], floor [s]; blanks for a reference."""
    if isinstance(policy, ChartStepPolicy):
        return [str(policy.k_up), seconds(policy.quiet_time), seconds(policy.min_setting)]
    return ["", "", ""]


def paired_difference(values: np.ndarray, reference: np.ndarray) -> tuple[float, float]:
    """Mean of ``values - reference`` per episode and the half-width of its 95 % normal interval (NaN for one)."""
    difference = values - reference
    if difference.size == 1:
        return float(difference[0]), float("nan")
    return float(difference.mean()), float(1.96 * difference.std(ddof=1) / np.sqrt(difference.size))


def close_calls(min_ttc: np.ndarray, config: EnvConfig) -> int:
    """Episodes whose smallest time-to-collision fell below the reward's ``config.reward_scales.ttc_threshold`` [-]."""
    return int((min_ttc < config.reward_scales.ttc_threshold).sum())


def write_csv(path: Path, config: EnvConfig, policies: Sequence[NamedPolicy], results: dict[str, np.ndarray],
              best: int) -> None:
    """One row per policy: its grid coordinates, whether it is the best cell, mean return, collisions, mean setting,
    follower switches, close calls."""
    with open(path, "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["policy", "k_up", "quiet_time", "min_setting", "best", "mean_return", "collisions",
                         "mean_setting", "switches_per_episode", "close_calls"])
        for i, policy in enumerate(policies):
            writer.writerow([policy.name, *cell_parameters(policy), int(i == best),
                             f"{results['return'][i].mean():.4f}", int(results["collision"][i].sum()),
                             f"{results['mean_setting'][i].mean():.4f}", f"{results['switches'][i].mean():.4f}",
                             close_calls(results["min_ttc"][i], config)])


def write_report(path: Path, config: EnvConfig, seeds: Sequence[int], cells: Sequence[ChartStepPolicy],
                 references: Sequence[NamedPolicy], results: dict[str, np.ndarray], best: int,
                 env_id: str = DEFAULT_TASK) -> str:
    """tuning.md: the references, the grid by mean return, the best cell per degradation kind."""
    policies = [*cells, *references]
    yardstick = next(i for i, policy in enumerate(policies) if isinstance(policy, FixedPolicy))  # the first constant
    returns = results["return"]
    grid = sorted(range(len(cells)), key=lambda i: -returns[i].mean())  # stable: grid order on a tie

    def row(i: int) -> str:
        difference, half_width = paired_difference(returns[i], returns[yardstick])
        name = f"**{policies[i].name}**" if i == best else policies[i].name
        return (f"| {name} | {' | '.join(cell_parameters(policies[i]))} | {returns[i].mean():.1f} | "
                f"{difference:+.1f} ± {half_width:.1f} | {int(results['collision'][i].sum())} | "
                f"{results['mean_setting'][i].mean():.2f} | {results['switches'][i].mean():.1f} | "
                f"{close_calls(results['min_ttc'][i], config)} |")

    header = [f"| policy | k_up | quiet time [s] | floor [s] | mean return | vs {policies[yardstick].name} (95 %) | "
              f"collisions | mean setting [s] | follower switches per episode | episodes with TTC < "
              f"{config.reward_scales.ttc_threshold:g} s |", "|" + "---|" * 10]
    defaults = ", the defaults of `ChartStepPolicy`" if env_id == ENV_ID else ""  # v0's committed grid set them
    lines = [
        "# Tuning the chart step rule (`python -m train.tune_rule`)", "",
        f"{len(seeds)} training episodes of {env_id} (seeds {seeds[0]}-{seeds[-1]}, below the evaluation's "
        f"{EVAL_SEED_START} and apart from the value-of-information lookup and selection seeds; its leader "
        "families, degradation mix and reward), platoon-wide action, every policy on the same episodes. Returns are "
        "undiscounted sums of the reward; differences are paired per episode, with a 95 % normal interval.", "",
        "The rule (`timegap_env.agents.policies.ChartStepPolicy`), per follower at each decision: at least `k_up` exceedances "
        f"within the chart's {seconds(config.chart.exceedance_window)} s window -> one ladder level up; otherwise no "
        "alarm for `quiet time` s -> one level down, never below the floor; the platoon takes the largest level any "
        f"follower asks for. It starts at the env's {seconds(config.platoon.initial_setting)} s.", "",
        "## References", "", *header, *(row(i) for i in range(len(cells), len(policies))), "",
        f"## The grid, by mean return ({len(cells)} cells; the best in bold)", "", *header, *(row(i) for i in grid), "",
        f"Best: k_up = {cells[best].k_up}, quiet time = {seconds(cells[best].quiet_time)} s, floor = "
        f"{seconds(cells[best].min_setting)} s{defaults}. It was picked on these episodes, "
        f"so its return here is optimistic; only held-out episodes (seeds >= {EVAL_SEED_START}) can judge it.", "",
        "## The best cell per degradation kind", "", "Mean return (collisions) per kind.", "",
        "| kind | episodes | " + " | ".join(policies[i].name for i in (best, *range(len(cells), len(policies))))
        + " |", "|---|---|" + "---|" * (1 + len(references)),
    ]
    kinds = results["kind"]
    for label, mask in kind_groups(kinds):
        entries = [f"{returns[i][mask].mean():.1f} ({int(results['collision'][i][mask].sum())})"
                   for i in (best, *range(len(cells), len(policies)))]
        lines.append(f"| {label} | {int(mask.sum())} | " + " | ".join(entries) + " |")
    lines.append("")
    text = "\n".join(lines)
    path.write_text(text)
    return text


if __name__ == "__main__":
    cli.run(main, "python -m train.tune_rule")
