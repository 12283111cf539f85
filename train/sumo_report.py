"""SUMO as a second simulator (issue 26): the physics cross-check and the policies' transfer, one command.

    python -m train.sumo_report [--pieces 3 10 10] [--held-out 50] [--model results/ppo_v1]
                                [--chart-step-tuning results/rule/tuning.csv] [--backend processes]
                                [--out results/sumo]

Needs the sumo extra (``pip install -e '.[sumo]'``; ``make sumo`` sets it up and runs this).

1. **Cross-check** (``crosscheck.md``, ``crosscheck.csv``, ``crosscheck.png``): the paper's scenario, NGSIM and OpenACC
   lead cars (``--pieces``: how many of each, seeds from 10 000) drive a platoon natively and in SUMO (Plexe's CC
   model; SUMO's CACC model), at every ladder setting, without and with V2V, no degradation
   (``timegap_env.studies.crosscheck``): acceleration amplification down the platoon and whether it stays string
   stable, the actual time gap's variation, the monitor's alarm rate, collisions; SUMO minus native with 95 %
   bootstrap intervals over the pieces. A source whose data is absent is left out, and the report says so.
2. **Transfer** (``transfer.md``, ``transfer.csv``): every ladder constant, the paper's rule, the chart-step rule
   (``--chart-step-tuning``: its best cell on v1; default: the registered parameters) and the learned runs of
   ``--model`` on ``--held-out`` held-out episodes of ``TimeGapMonitor-v1`` (seeds from 10 000), natively and in each
   SUMO model: mean returns with intervals, gains over the paper's rule (paired), and the rankings with Kendall's
   tau between the native one and each SUMO one.

Writes through a partial directory: a failed run overwrites nothing.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import torch
from scipy.stats import kendalltau

from timegap_env import cli
from timegap_env.agents.protocol import EVAL_SEED_START
from timegap_env.config import EnvConfig
from timegap_env.tasks import get_task
from timegap_env.experiments.backends import Backend, add_arguments
from timegap_env.studies.crosscheck import SETUPS, SOURCES, crosscheck_rows, transfer_returns
from timegap_env.experiments.registry import fixed_name, load_learned, tuned_chart_step
from timegap_env.experiments.registry import make as make_policy
from timegap_env.experiments.stats import bootstrap_mean
from timegap_env.leaders.scenarios import missing_data
from timegap_env.sim.sumo import import_libsumo

DIFFERENCES = ("amplification", "gap_std", "alarm_rate")  # the metrics whose SUMO - native difference gets an interval


def crosscheck_lines(rows: list[dict[str, Any]]) -> list[str]:
    """crosscheck.md's tables: per source and V2V, per setting, each simulator's means; the differences."""
    lines = ["# SUMO against the native simulator: the physics", "",
             "Each leader piece drives a platoon of five followers at one constant setting, no degradation, with the "
             "env's sensors, monitor and chart (`timegap_env.studies.crosscheck`). Amplification: the largest ratio "
             "of a follower's peak |acceleration| to its predecessor's, each peak at least 0.1 m/s^2 (above 1: a "
             "disturbance grew); stable: the share "
             "of pieces where no ratio exceeds 1.01; gap std: the actual time gap's standard deviation [s]; alarms: the "
             "share of follower-ticks the chart is in alarm; collisions: pieces with one.", ""]
    sims = list(SETUPS)
    for source in SOURCES:
        for v2v in (False, True):
            subset = [row for row in rows if row["source"] == source and row["v2v"] == v2v]
            if not subset:
                continue
            pieces = len({row["seed"] for row in subset})
            lines += [f"## {source}, {'with' if v2v else 'without'} V2V ({pieces} pieces)", "",
                      "| setting | " + " | ".join(f"{metric} ({'/'.join(sims)})" for metric in
                                                  ("amplification", "stable", "gap std", "alarms", "collisions")) + " |",
                      "|---|---|---|---|---|---|"]
            for setting in sorted({row["setting"] for row in subset}):
                cells = []
                for metric, form in (("amplification", "{:.2f}"), ("string_stable", "{:.0%}"), ("gap_std", "{:.3f}"),
                                     ("alarm_rate", "{:.3f}"), ("collision", "{:.0f}")):
                    values = [np.mean([row[metric] for row in subset if row["simulator"] == sim and
                                       row["setting"] == setting]) * (pieces if metric == "collision" else 1)
                              for sim in sims]
                    cells.append(" / ".join(form.format(value) for value in values))
                lines.append(f"| {setting:g} s | " + " | ".join(cells) + " |")
            lines.append("")
    lines += ["## SUMO minus native", "",
              "Each piece's difference averaged over the settings, the mean over the pieces with its 95 % bootstrap "
              "interval over the pieces; in brackets after it, the largest difference at any one piece and setting.",
              "", "| source | V2V | SUMO model | pieces | " + " | ".join(f"{metric} [95 % CI] (largest)"
                                                                       for metric in DIFFERENCES)
              + " | same stability verdict |", "|---|---|---|---|" + "---|" * (len(DIFFERENCES) + 1)]
    for row in difference_rows(rows):
        lines.append(f"| {row['source']} | {'on' if row['v2v'] else 'off'} | {row['simulator']} | {row['pieces']} | "
                     + " | ".join(f"{row[m]:+.3f} [{row[m + '_low']:+.3f}, {row[m + '_high']:+.3f}] "
                                  f"({row[m + '_largest']:+.2f})" for m in DIFFERENCES)
                     + f" | {row['same_verdict']:.0%} |")
    return lines + [""]


def difference_rows(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per source, V2V and SUMO model: the paired differences (SUMO - native) of DIFFERENCES, each piece's averaged
    over the settings, with bootstrap intervals over the pieces (the settings of a piece are not independent), the
    largest difference at any (piece, setting), and the share of (piece, setting) with the same stability verdict."""
    native = {(r["source"], r["seed"], r["v2v"], r["setting"]): r for r in rows if r["simulator"] == "native"}
    out = []
    for source in SOURCES:
        for v2v in (False, True):
            for sim in [name for name in SETUPS if name != "native"]:
                pairs = [(r, native[(r["source"], r["seed"], r["v2v"], r["setting"])]) for r in rows
                         if r["source"] == source and r["v2v"] == v2v and r["simulator"] == sim]
                if not pairs:
                    continue
                seeds = sorted({a["seed"] for a, _ in pairs})
                row: dict[str, Any] = {"source": source, "v2v": v2v, "simulator": sim, "pieces": len(seeds)}
                for metric in DIFFERENCES:
                    per_piece = [np.mean([a[metric] - b[metric] for a, b in pairs if a["seed"] == seed])
                                 for seed in seeds]
                    mean, low, high = bootstrap_mean(np.array(per_piece))
                    largest = max((a[metric] - b[metric] for a, b in pairs), key=abs)
                    row |= {metric: mean, f"{metric}_low": low, f"{metric}_high": high, f"{metric}_largest": largest}
                row["same_verdict"] = float(np.mean([a["string_stable"] == b["string_stable"] for a, b in pairs]))
                out.append(row)
    return out


def crosscheck_figure(rows: list[dict[str, Any]], path: Path) -> None:
    """Amplification against the setting, a panel per source and V2V, a line per simulator (mean over pieces)."""
    sources = [source for source in SOURCES if any(row["source"] == source for row in rows)]
    fig, axes = plt.subplots(2, len(sources), figsize=(4.2 * len(sources), 6.5), squeeze=False, sharex=True)
    for column, source in enumerate(sources):
        for line, v2v in enumerate((False, True)):
            ax = axes[line][column]
            for sim in SETUPS:
                subset = [row for row in rows if row["source"] == source and row["v2v"] == v2v and row["simulator"] == sim]
                settings = sorted({row["setting"] for row in subset})
                ax.plot(settings, [np.mean([r["amplification"] for r in subset if r["setting"] == s]) for s in settings],
                        "o-", ms=3, label=sim)
            ax.axhline(1.0, color="0.5", lw=0.8, ls="--")
            ax.set_title(f"{source}, V2V {'on' if v2v else 'off'}", fontsize=9)
            ax.grid(alpha=0.3)
    for ax in axes[-1]:
        ax.set_xlabel("time gap setting [s]")
    for ax in axes[:, 0]:
        ax.set_ylabel("acceleration amplification [-]")
    axes[0][0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110, metadata={"Software": None})
    plt.close(fig)


def transfer_lines(returns: dict[str, dict[str, np.ndarray]], seeds: list[int]) -> tuple[list[str], list[dict[str, Any]]]:
    """transfer.md's table and transfer.csv's rows."""
    sims, policies = list(returns), list(returns["native"])
    rows = []
    for policy in policies:
        row: dict[str, Any] = {"policy": policy}
        for sim in sims:
            mean, low, high = bootstrap_mean(returns[sim][policy])
            gain = bootstrap_mean(returns[sim][policy] - returns[sim]["rule_platoon"])
            row |= {f"{sim}_return": mean, f"{sim}_return_low": low, f"{sim}_return_high": high,
                    f"{sim}_gain_over_rule": gain[0], f"{sim}_gain_over_rule_low": gain[1],
                    f"{sim}_gain_over_rule_high": gain[2]}
        rows.append(row)
    for sim in sims:
        order = sorted(policies, key=lambda name: -float(returns[sim][name].mean()))
        for row in rows:
            row[f"{sim}_rank"] = order.index(row["policy"]) + 1
    lines = ["# Policies natively and in SUMO: does the ranking transfer?", "",
             f"{len(seeds)} held-out episodes of TimeGapMonitor-v1 (seeds {seeds[0]}-{seeds[-1]}), the same episodes "
             "(leader, degradations, sensor noise) in each simulator; in SUMO a degradation acts only where it maps "
             "(the engine lag; V2V down switches to ACC): its gain, V2V latency and loss, controller gains and the "
             "radar bias inside the controller do not exist there (docs/sumo.md).", "",
             "| policy | " + " | ".join(f"{sim}: return [CI] (rank) | {sim}: gain over the rule [CI]" for sim in sims) + " |",
             "|---|" + "---|---|" * len(sims)]
    for row in rows:
        lines.append(f"| {row['policy']} | " + " | ".join(
            f"{row[f'{sim}_return']:.1f} [{row[f'{sim}_return_low']:.1f}, {row[f'{sim}_return_high']:.1f}] "
            f"({row[f'{sim}_rank']}) | {row[f'{sim}_gain_over_rule']:+.1f} [{row[f'{sim}_gain_over_rule_low']:+.1f}, "
            f"{row[f'{sim}_gain_over_rule_high']:+.1f}]" for sim in sims) + " |")
    lines.append("")
    for sim in sims[1:]:
        tau, p_value = kendalltau([row["native_rank"] for row in rows], [row[f"{sim}_rank"] for row in rows])
        lines.append(f"- Kendall's tau of the native ranking and {sim}'s: {tau:.2f} (p = {p_value:.3f}, "
                     f"{len(rows)} policies).")
    return lines + [""], rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--pieces", type=cli.count, nargs=len(SOURCES), default=[3, 10, 10], metavar="N",
                        help=f"distinct leader pieces of each of {list(SOURCES)}, at most (default: %(default)s)")
    parser.add_argument("--held-out", type=cli.count, default=50, help="held-out episodes of the transfer")
    parser.add_argument("--model", type=Path, nargs="*", default=[Path("results/ppo_v1")], help="learned v1 runs")
    parser.add_argument("--chart-step-tuning", type=Path, default=None,
                        help="a tune_rule --env-id TimeGapMonitor-v1 tuning.csv (default: the registered parameters)")
    parser.add_argument("--out", default="runs/sumo", help="directory of the report")
    add_arguments(parser)
    args = parser.parse_args()
    cli.output_dir(args.out)
    import_libsumo()  # before any work: the extra must be installed
    torch.set_num_threads(1)
    backend, start = Backend.from_args(args), time.perf_counter()
    notes = []
    pieces = {}
    for source, count in zip(SOURCES, args.pieces):
        missing = missing_data(SOURCES[source])
        if missing:
            notes.append(f"- source {source} left out: {missing}")
        else:
            pieces[source] = count
    config = get_task("TimeGapMonitor-v1").config()
    tuned = tuned_chart_step(args.chart_step_tuning) if args.chart_step_tuning else {}
    policies: dict[str, Any] = {fixed_name(level): make_policy(fixed_name(level), config) for level in config.setting_levels}
    policies |= {"rule_platoon": make_policy("rule_platoon", config), "chart_step": make_policy("chart_step", config, **tuned)}
    for path in args.model:
        policies[path.name] = load_learned(path, config)
    work = cli.work_directory(args.out)
    rows = crosscheck_rows(EnvConfig(), pieces, backend)
    cli.write_rows(rows, work / "crosscheck.csv")
    crosscheck_figure(rows, work / "crosscheck.png")
    seeds = list(range(EVAL_SEED_START, EVAL_SEED_START + args.held_out))
    returns = transfer_returns(config, seeds, policies, backend)
    transfer, transfer_rows = transfer_lines(returns, seeds)
    cli.write_rows(transfer_rows, work / "transfer.csv")
    runtime = f"Runtime: {time.perf_counter() - start:.0f} s ({backend.describe()})."
    notes.append(f"- chart_step's parameters: {'the best cell of ' + str(args.chart_step_tuning) if tuned else 'registered'}")
    (work / "crosscheck.md").write_text("\n".join([*crosscheck_lines(rows), *notes, "", runtime, ""]), encoding="utf-8")
    (work / "transfer.md").write_text("\n".join([*transfer, *notes, "", runtime, ""]), encoding="utf-8")
    cli.publish(work, args.out)
    print((Path(args.out) / "transfer.md").read_text(encoding="utf-8"))


if __name__ == "__main__":
    cli.run(main, "python -m train.sumo_report")
