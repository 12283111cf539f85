"""Evaluate every policy on the same held-out scenarios and write a table and two figures.

Held out from training:

- **Seeds.** Training uses seeds below ``EVAL_SEED_START`` = 10 000; evaluation episode k
  (k = 0, 1, ..., ``--episodes`` - 1, numbered across groups) is reset with seed 10 000 + k.
- **Groups** (``GROUPS``), each config overrides and reset options: ``training_mix`` (the
  training families and degradation mix on the held-out seeds); ``larger_degradations`` (every
  episode degraded, sizes beyond the training ranges: a generalisation split); human leaders:
  ``ngsim_in_band`` (real NGSIM I-80 drivers, their acceleration integrated within 20-80 mph),
  ``openacc`` (the human lead cars of the OpenACC platoons), each only when its data is found,
  and ``idm`` (highway-env's IDM driver behind scripted braking); and two harsh families the
  training never saw, ``stop_and_go`` and ``emergency_braking``. Episodes are split evenly
  across groups.

Policies, by the names of the policy registry (``timegap_env.experiments.registry``): the paper's rule
(platoon, per vehicle), the chart-step rule (tuned on training seeds by ``train/tune_rule.py``), every
fixed setting, the V2V-aware heuristic, *the* oracle of ``timegap_env.experiments.value`` (reads the
ground truth; its lookup measured on training seeds, chosen on selection seeds) and the trained PPO
model. The groups, the plan, the runs (through the rollout harness) and the statistics are the library's
``timegap_env.experiments.heldout``; this script parses, calls and writes. The share of the oracle gap captured is
(policy - best fixed) / (oracle - best fixed), per group with the best fixed setting of that group.

Every policy runs the same (group, seed) episodes in the native vector env, one batch per
group; after each reset the script fingerprints every episode (leader speed, degradation,
dropout rate, sensor-noise key) and refuses to report if any policy saw a different one,
so platoon-wide and per-vehicle action modes are checked to draw identical scenarios.

Statistics: per policy and group, the mean over episodes with a 95 % percentile bootstrap
interval (``BOOTSTRAP_RESAMPLES`` resamples of the episodes, fixed seed); the collision rate
with a 95 % Wilson score interval; the return's paired difference to ``--reference`` and the
share of the oracle gap with a paired bootstrap (same episodes, resampled together). Min TTC is
capped at ``TTC_CAP`` (inf = never closing in on the predecessor) before averaging. Time below
stable: seconds per follower whose setting at a step's end lies below the smallest string-stable
setting of its true parameters at the step's start.

Writes ``table.md``, ``table.csv`` (one row per policy and group), ``episodes.csv`` (every
episode of every policy), ``profiles.png`` and ``metrics.png`` to ``--out``.

Each (policy, group) batch is one piece of work for ``timegap_env.experiments.backends``: ``--backend serial`` (the
default) runs them one after another here, ``--backend ray`` as Ray tasks, on this machine or on
the cluster at ``--address``; the batches are the same, so the files are too, bit for bit (the
runtime line, which says how the work was spread, aside). The oracle's lookup and choice are
spread the same way.

The learned policy is loaded as it was trained (``timegap_env.agents.learned.LearnedPolicy.load``: ``env.json``
gives the meaning of its actions, and ``vecnormalize.pkl`` must be there if the run normalised), with
torch on one thread, and checked before any other work, as are ``--out`` (not a file) and the NGSIM and
OpenACC data of the planned groups (a file that cannot be read is named before the other groups run).
Bad input stops the command with one line naming it and a non-zero exit, no traceback.

    python -m train.evaluate [--episodes 112] [--policies rule_platoon fixed_1.6 ...] [--out results/eval]
                             [--backend serial|ray] [--address A]
"""

from __future__ import annotations

import argparse
import csv
import math
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from timegap_env import cli
from timegap_env.agents.oracles import TruthPolicy
from timegap_env.agents.policies import NamedPolicy
from timegap_env.agents.protocol import EVAL_SEED_START
from timegap_env.experiments.backends import Backend, add_arguments
from timegap_env.experiments.heldout import (  # the held-out protocol, in the library
    ALL_EPISODES, DEFAULT_EPISODES, DEFAULT_MODEL, DEFAULT_REFERENCE, GROUPS, METRICS, TTC_CAP, PolicyChoiceError, Profile,
    available_groups, check_data, load_ppo, model_exists, plan_episodes, run_all, summarise,
)
from timegap_env.experiments.heldout import build_policies as heldout_policies

from timegap_env.experiments.stats import BOOTSTRAP_RESAMPLES
from timegap_env.experiments.registry import ORACLE
from timegap_env.experiments.value import DEFAULT_TRAIN_EPISODES


DEFAULT_OUT = Path("results/eval")
PROFILE_FOLLOWER = 0  # the follower drawn bold in profiles.png (vehicle 1)

def build_policies(
    names: Sequence[str] | None, model: Path, backend: Backend | None = None, ppo: Any = None
) -> dict[str, NamedPolicy | TruthPolicy]:
    """``heldout.build_policies`` with the oracle's lookup measured on ``DEFAULT_TRAIN_EPISODES`` per condition."""
    return heldout_policies(names, model, backend, ppo, DEFAULT_TRAIN_EPISODES)


# ---------------------------------------------------------------- statistics
FORMATS = {"return": ".1f", "time_out_of_control": ".2f", "exceedances": ".2f", "max_deviation": ".3f",
           "min_ttc": ".1f", "collision": ".2f", "rms_jerk": ".2f", "mean_setting": ".2f", "mean_capacity": ".0f",
           "switches": ".2f", "return_vs_reference": ".1f", "oracle_share": ".2f", "time_below_stable": ".1f"}


def cell(row: dict[str, Any], metric: str) -> str:
    """'mean [low, high]' of ``metric``; collisions as 'count/episodes [low, high]' of the rate."""
    f = FORMATS[metric]
    interval = f"[{row[f'{metric}_ci_low']:{f}}, {row[f'{metric}_ci_high']:{f}}]"
    if metric == "collision":
        return f"{row['collisions']}/{row['episodes']} {interval}"
    if math.isnan(row[f"{metric}_mean"]):
        return "n/a"
    if math.isnan(row[f"{metric}_ci_low"]):  # a share whose gap's own interval reaches 0
        return f"{row[f'{metric}_mean']:{f}} [unbounded]"
    return f"{row[f'{metric}_mean']:{f}} {interval}"


def write_tables(rows: list[dict[str, Any]], header: list[str], reference: str | None, out: Path) -> None:
    """table.csv (every number) and table.md (one table per group)."""
    with open(out / "table.csv", "w", newline="") as file:
        writer = csv.DictWriter(file, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    share = "oracle_share_mean" in rows[0]
    columns = ["return"] + (["return_vs_reference"] if reference else []) + (["oracle_share"] if share else []) \
        + list(METRICS)[1:]
    labels = [METRICS.get(c, "share of the oracle gap" if c == "oracle_share" else f"Δ return vs {reference} (paired)")
              for c in columns]
    lines = header + [""]
    for group in dict.fromkeys(row["group"] for row in rows):
        chosen = [row for row in rows if row["group"] == group]
        title = "All episodes" if group == ALL_EPISODES else f"Group `{group}`"
        blind = f"; best fixed setting: {chosen[0]['best_fixed']}" if share else ""
        lines += [f"## {title} ({chosen[0]['episodes']} episodes per policy{blind})", "",
                  "| policy | " + " | ".join(labels) + " |", "|---" * (len(columns) + 1) + "|"]
        lines += [f"| {row['name']} | " + " | ".join(cell(row, c) for c in columns) + " |" for row in chosen]
        lines.append("")
    (out / "table.md").write_text("\n".join(lines))


def write_episodes(policies: dict[str, NamedPolicy], records: dict[str, list[dict[str, Any]]], out: Path) -> None:
    """episodes.csv: every episode of every policy, as run."""
    rows = [{"policy": key, **record} for key in policies for record in records[key]]
    with open(out / "episodes.csv", "w", newline="") as file:
        writer = csv.DictWriter(file, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def plot_profiles(policies: dict[str, NamedPolicy], profiles: dict[str, Profile], out: Path) -> None:
    """profiles.png: each policy's time gap estimates on the same episode, vehicle 1 bold with its limits."""
    keys = [key for key in policies if key in profiles]
    ncols = min(3, len(keys))
    nrows = math.ceil(len(keys) / ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(5 * ncols, 2.6 * nrows), sharex=True, sharey=True, squeeze=False)
    for ax, key in zip(axes.flat, keys):
        p = profiles[key]
        ax.plot(p.t, np.delete(p.estimate, PROFILE_FOLLOWER, axis=1), color="0.7", lw=0.6)
        ax.plot(p.t, p.estimate[:, PROFILE_FOLLOWER], color="C0", lw=1.2, label=f"vehicle {PROFILE_FOLLOWER + 1} τ̂")
        center = p.center[:, PROFILE_FOLLOWER]
        ax.plot(p.t, center - p.half_width, color="C3", ls="--", lw=0.9, label="LCL / UCL")
        ax.plot(p.t, center + p.half_width, color="C3", ls="--", lw=0.9)
        ax.plot(p.t, center, color="k", ls=":", lw=0.9, label="τ* (CL)")
        for moment, label in ((p.onset, "degradation onset"), (p.end, "its end")):
            if math.isfinite(moment) and moment <= p.t[-1]:
                ax.axvline(moment, color="C2", lw=1.0, ls="-." if label == "its end" else "-", label=label)
        ax.set_title(policies[key].name, fontsize=9)
        ax.grid(alpha=0.3)
    for ax in axes.flat[len(keys):]:
        ax.set_visible(False)
    for ax in axes[-1]:
        ax.set_xlabel("t [s]")
    for ax in axes[:, 0]:
        ax.set_ylabel("time gap [s]")
    axes[0, 0].legend(fontsize=7, loc="upper right")
    first = next(iter(profiles.values()))
    fig.suptitle(f"Time gap estimates, {first.scenario}, {first.degradation} (other followers grey)", fontsize=10)
    fig.tight_layout()
    fig.savefig(out / "profiles.png", dpi=120)
    plt.close(fig)


def plot_metrics(rows: list[dict[str, Any]], out: Path) -> None:
    """metrics.png: every metric over all episodes, mean and 95 % interval per policy."""
    chosen = [row for row in rows if row["group"] == ALL_EPISODES]
    y = np.arange(len(chosen))[::-1]
    ncols = 5
    fig, axes = plt.subplots(math.ceil(len(METRICS) / ncols), ncols, figsize=(18, 0.35 * len(chosen) * 2 + 2),
                             sharey=True, squeeze=False)
    for ax, (metric, label) in zip(axes.flat, METRICS.items()):
        mean = np.array([row[f"{metric}_mean"] for row in chosen])
        low = np.array([row[f"{metric}_ci_low"] for row in chosen])
        high = np.array([row[f"{metric}_ci_high"] for row in chosen])
        ax.errorbar(mean, y, xerr=np.maximum([mean - low, high - mean], 0.0), fmt="o", ms=4, capsize=2)
        ax.set_title(label, fontsize=9)
        ax.grid(alpha=0.3)
    for ax in axes.flat[len(METRICS):]:
        ax.set_visible(False)
    for ax in axes[:, 0]:
        ax.set_yticks(y, [row["name"] for row in chosen], fontsize=8)
    fig.suptitle(f"All {chosen[0]['episodes']} held-out episodes per policy: mean and 95 % interval", fontsize=10)
    fig.tight_layout()
    fig.savefig(out / "metrics.png", dpi=120)
    plt.close(fig)


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m train.evaluate", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--episodes", type=int, default=DEFAULT_EPISODES,
                        help=f"episodes per policy, split across the held-out groups (default {DEFAULT_EPISODES})")
    parser.add_argument("--policies", nargs="+", metavar="NAME",
                        help="rule_platoon rule_per_vehicle chart_step fixed_<level> (e.g. fixed_1.6) v2v_aware oracle "
                             "ppo (default: all, ppo if --model exists)")
    parser.add_argument("--model", type=Path,
                        help="a run of train.train_ppo (its directory or its model.zip; env.json beside it, and "
                             "vecnormalize.pkl if the run normalised, are required and checked against the model) "
                             f"(default {DEFAULT_MODEL}, skipped if absent); or a run of train.train_rllib "
                             "(results/rllib or its checkpoint/; needs the ray extra); checked before any other work")
    parser.add_argument("--reference", default=DEFAULT_REFERENCE,
                        help=f"policy the paired return differences are taken against (default {DEFAULT_REFERENCE})")
    parser.add_argument("--profile-group", default="training_mix",
                        help="group one of whose episodes profiles.png shows: the first with a hidden degradation "
                             "starting midway (default training_mix)")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help=f"output directory (default {DEFAULT_OUT})")
    add_arguments(parser)
    args = parser.parse_args(argv)
    try:
        backend = Backend.from_args(args)
        cli.output_dir(args.out)
    except (ValueError, OSError) as error:
        parser.error(str(error))
    if args.model is not None and not model_exists(args.model):
        parser.error(f"--model {args.model}: no such model zip or RLlib checkpoint")
    args.model = args.model or DEFAULT_MODEL
    ppo = None  # the learned policy, loaded first: a model that cannot be used is named before any other work
    if (args.policies is None or "ppo" in args.policies) and model_exists(args.model):
        try:
            ppo = load_ppo(args.model)
        except PolicyChoiceError as error:
            parser.error(str(error))

    start = time.perf_counter()
    groups, data_note = available_groups()
    plan = plan_episodes(args.episodes, groups)
    planned_groups = list(dict.fromkeys(episode.group for episode in plan))
    profile_group = args.profile_group if args.profile_group in planned_groups else planned_groups[0]
    check_data(plan)  # a truncated data file named now, not after the other groups
    try:
        policies = build_policies(args.policies, args.model, backend, ppo)
    except (PolicyChoiceError, FileNotFoundError) as error:  # unknown names, a model that cannot be used: no traceback
        parser.error(str(error))
    reference = args.reference if args.reference in policies else None
    if reference is None:
        print(f"note: --reference {args.reference} is not among the policies; no paired differences")
    records, profiles, timings = run_all(policies, plan, profile_group, backend)
    elapsed = time.perf_counter() - start

    args.out.mkdir(parents=True, exist_ok=True)
    rows = summarise(policies, records, reference)
    counts = ", ".join(f"{g}: {sum(e.group == g for e in plan)}" for g in planned_groups)
    ppo = policies.get("ppo")
    header = [
        "# Held-out evaluation (`python -m train.evaluate`)", "",
        f"Episodes per policy: {len(plan)} ({counts}), seeds {plan[0].seed}–{plan[-1].seed} "
        f"(training uses seeds < {EVAL_SEED_START}). {data_note}",
        "Groups: " + "; ".join(f"`{g}` = {GROUPS[g].description}" for g in planned_groups) + ". Default env config "
        "otherwise (degradations of the followers, from the default mix, and sensor dropouts drawn from the seed).",
        *([f"Oracle: `{policies[ORACLE].name}` (reads the ground truth, not deployable; chosen on selection seeds by "
           "`train.value_of_information`). Share of the oracle gap = (policy − best fixed) / (oracle − best fixed), "
           "the group's best fixed setting, paired bootstrap interval; n/a where the oracle does not beat it, "
           "[unbounded] where it does not in some resamples (the gap's own interval reaches 0)."]
          if ORACLE in policies else []),
        "Every policy ran the same episodes: the leader, degradation, dropout rate and sensor-noise key of each "
        "episode were fingerprinted after reset and compared across policies and action modes.",
        f"Cells: mean [95 % percentile bootstrap interval, {BOOTSTRAP_RESAMPLES} resamples of the episodes]; "
        "collisions: count/episodes [95 % Wilson interval of the rate]; "
        + (f"Δ return: paired difference to `{policies[reference].name}` on the same episodes (paired bootstrap). "
           if reference else "")
        + f"Min TTC capped at {TTC_CAP:g} s before averaging. Return = undiscounted sum of rewards (episodes differ in "
        "length across groups: NGSIM records are shorter than 250 s).",
        (f"PPO: `{args.model}` ({ppo!r})." if ppo else f"PPO: not evaluated (no model at `{args.model}`)."),
        f"Runtime: {elapsed:.0f} s for {len(policies)} policies "
        f"({', '.join(f'{key} {spent:.0f} s' for key, spent in timings.items())}, each its batches' seconds where "
        f"they ran); spread of the (policy, group) batches: {backend.describe()}"
        + (" (the oracle's lookup and choice before them the same way)." if ORACLE in policies else "."),
    ]
    write_tables(rows, header, reference, args.out)
    write_episodes(policies, records, args.out)
    plot_profiles(policies, profiles, args.out)
    plot_metrics(rows, args.out)
    print(f"wrote {args.out}/table.md, table.csv, episodes.csv, profiles.png, metrics.png in {elapsed:.0f} s\n")
    print((args.out / "table.md").read_text().split("\n## Group")[0])  # the table over all episodes


if __name__ == "__main__":
    cli.run(main, "python -m train.evaluate")
