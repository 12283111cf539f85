"""The map of where reading the monitor can pay, and the default task's criterion (issue 24, docs/task.md).

    python -m train.task_map [--train 16] [--selection 32] [--held-out 100] [--out results/task]
                             [--backend serial|ray] [--address A]

For each weighting x degradation severity x traffic mix of ``timegap_env.studies.task_map``: the best
blind constant (chosen on selection seeds) and the gain of each reference over it on held-out seeds, with
95 % bootstrap intervals, which weighting the criterion picks, and the Pareto fronts (capacity, string
stability, variation) of the constants against the references with their hypervolumes. Then the same for
``TimeGapMonitor-v1`` (its own weighting): its headroom. Writes ``map.md``, ``map.csv``, ``map_fronts.csv``,
``map.png``, ``map_fronts.png``, ``v1.md``, ``v1.csv`` and ``v1_fronts.csv`` to ``--out`` (through a partial
directory: a failed run overwrites nothing); reruns give the same files but the runtime lines.
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

from timegap_env import cli
from timegap_env.experiments.backends import Backend, add_arguments
from timegap_env.studies.task_map import (
    FRONT_OBJECTIVES, MAX_BLIND_COLLISION_RATE, REFERENCES, SEVERITIES, TARGET_SHARE, TRAFFIC, WEIGHTINGS, Plan,
    choose_default, task_map, v1_headroom,
)


def hypervolume_lines(fronts: list[dict[str, Any]], source: str) -> list[str]:
    lines = ["## Pareto fronts", "",
             "Capacity (the efficiency term), string stability and time-gap variation (tracking), each summed over the "
             f"episode and averaged over the held-out seeds ({source}). Hypervolume of the ladder's constants, and "
             "of the constants with each reference added, in units of each objective's spread over the cell's points "
             "above its worst point: a reference that adds volume reaches trade-offs no constant does.", "",
             "| weighting | severity | traffic | constants | " + " | ".join(f"+ {ref}" for ref in REFERENCES) + " |",
             "|---|---|---|---|" + "---|" * len(REFERENCES)]
    for cell in dict.fromkeys((f["weighting"], f["severity"], f["traffic"]) for f in fronts):  # in the map's order
        points = {f["point"]: f for f in fronts if (f["weighting"], f["severity"], f["traffic"]) == cell}
        constants = next(iter(points.values()))["constants_hypervolume"]
        lines.append(f"| {' | '.join(cell)} | {constants:.3f} | "
                     + " | ".join(f"{points[ref]['hypervolume']:.3f}" for ref in REFERENCES) + " |")
    return lines + [""]


def seeds_paragraph(plan: Plan) -> str:
    return ("Seeds: lookup and regime tables on training seeds 0-"
            f"{plan.train - 1}; every choice (best blind constant, V2V pair, which oracle) on {plan.selection} selection "
            f"seeds from 5000; every number below on {plan.held_out} held-out seeds from 10000. Gain: mean return of the "
            "reference minus the best blind constant's, per episode, [95 % bootstrap interval]; share: gain / |best "
            "blind return|; collisions: episodes of the held-out ones.")


def row_table(rows: list[dict[str, Any]]) -> list[str]:
    lines = ["| severity | traffic | best blind | its return | its collisions | "
             + " | ".join(f"{ref} gain [CI] (share; collisions)" for ref in REFERENCES)
             + " | degradation-aware chosen | full oracle chosen |",
             "|---|---|---|---|---|" + "---|" * len(REFERENCES) + "---|---|"]
    for row in rows:
        cells = [f"{row[f'{ref}_gain']:.1f} [{row[f'{ref}_gain_low']:.1f}, {row[f'{ref}_gain_high']:.1f}] "
                 f"({100 * row[f'{ref}_share']:.1f} %; {row[f'{ref}_collisions']})" for ref in REFERENCES]
        lines.append(f"| {row['severity']} | {row['traffic']} | {row['best_blind']} | {row['best_blind_return']:.1f} "
                     f"| {row['best_blind_collisions']} | " + " | ".join(cells)
                     + f" | {row['degradation_aware_chosen']} | {row['full_oracle_chosen']} |")
    return lines + [""]


def target_sentence(row: dict[str, Any], reference: str, met: bool) -> str:
    return (f"{reference} {100 * row[f'{reference}_share']:.1f} % [{row[f'{reference}_gain_low']:.1f}, "
            f"{row[f'{reference}_gain_high']:.1f} per episode], the best blind constant ({row['best_blind']}) colliding "
            f"in {row['best_blind_collisions']} of {row['episodes']}: it {'meets' if met else 'does not meet'} the "
            f"target (at least {100 * TARGET_SHARE:.0f} %, interval above 0, at most "
            f"{100 * MAX_BLIND_COLLISION_RATE:.0f} % collisions of the best blind constant).")


def markdown(rows: list[dict[str, Any]], fronts: list[dict[str, Any]], plan: Plan, chosen: dict[str, Any],
             runtime: str) -> str:
    lines = ["# Where reading the monitor can pay: the map", "",
             "Written by `python -m train.task_map` (criterion and weightings: docs/task.md). " + seeds_paragraph(plan), ""]
    for name, weighting in WEIGHTINGS.items():
        lines += [f"## {name}", "", f"{weighting.why}.", "", *row_table([row for row in rows if row["weighting"] == name])]
    verdict = "meets" if chosen["meets_target"] else "does not meet"
    lines += ["## The criterion", "",
              f"On the default severity and traffic, the weighting whose degradation-aware oracle gains the largest "
              f"share over the best blind constant is **{chosen['weighting']}**: "
              f"{100 * chosen['degradation_aware_share']:.1f} % "
              f"[{chosen['degradation_aware_gain_low']:.1f}, {chosen['degradation_aware_gain_high']:.1f}] per episode, "
              f"the best blind constant ({chosen['best_blind']}) colliding in {chosen['best_blind_collisions']} of "
              f"{chosen['episodes']}. It {verdict} the target (at least {100 * TARGET_SHARE:.0f} %, interval above 0, "
              f"at most {100 * MAX_BLIND_COLLISION_RATE:.0f} % collisions of the best blind constant). By the issue's "
              "form of the target (the full oracle, which knows the regime too): "
              + target_sentence(chosen, "full_oracle", chosen["full_oracle_meets_target"]), "",
              *hypervolume_lines(fronts, "map_fronts.csv"), f"Runtime: {runtime}", ""]
    return "\n".join(lines)


def v1_markdown(row: dict[str, Any], fronts: list[dict[str, Any]], plan: Plan, runtime: str) -> str:
    lines = ["# TimeGapMonitor-v1: its headroom", "",
             f"Written by `python -m train.task_map`. The task (weighting {row['weighting']}, v0's four training leader "
             "families and the regimes family, v0's degradation mix) was fixed in docs/task.md before these numbers "
             "were computed. " + seeds_paragraph(plan), "", *row_table([row]),
             "- Degradation-aware (the criterion as written): " + target_sentence(row, "degradation_aware",
                                                                                  row["meets_target"]),
             "- Full oracle (the issue's target): " + target_sentence(row, "full_oracle", row["full_oracle_meets_target"]),
             "", "Gains without the collision term (a collision costs 1000, so one episode can carry a mean over 100): "
             + "; ".join(f"{ref} {row[f'{ref}_gain_without_collisions']:.1f} [{row[f'{ref}_gain_without_collisions_low']:.1f}, "
                         f"{row[f'{ref}_gain_without_collisions_high']:.1f}]" for ref in REFERENCES) + " per episode.",
             "", *hypervolume_lines(fronts, "v1_fronts.csv"), f"Runtime: {runtime}", ""]
    return "\n".join(lines)


def front_figure(fronts: list[dict[str, Any]], path: Path) -> None:
    """Capacity against string stability (colour: variation) on the default cell, one panel per weighting."""
    x_name, y_name, colour = FRONT_OBJECTIVES
    fig, axes = plt.subplots(1, len(WEIGHTINGS), figsize=(4.2 * len(WEIGHTINGS), 3.8), sharex=True, sharey=True)
    for ax, name in zip(axes, WEIGHTINGS):
        points = [f for f in fronts if f["weighting"] == name and f["severity"] == "default" and f["traffic"] == "default"]
        values = np.array([[p[x_name], p[y_name], p[colour]] for p in points])
        shown = ax.scatter(values[:, 0], values[:, 1], c=values[:, 2], cmap="viridis", s=28)
        for point, (x, y, _) in zip(points, values):
            ax.annotate(point["point"].replace("constant ", ""), (x, y), fontsize=6, xytext=(3, 2),
                        textcoords="offset points")
        ax.set_title(f"{name}: default severity and traffic", fontsize=8)
        ax.set_xlabel(f"{x_name} (capacity) per episode")
    axes[0].set_ylabel(f"{y_name} per episode")
    fig.colorbar(shown, ax=axes, label=f"{colour} (time-gap variation) per episode")
    fig.savefig(path, dpi=110, metadata={"Software": None})
    plt.close(fig)


def figure(rows: list[dict[str, Any]], path: Path) -> None:
    fig, axes = plt.subplots(1, len(WEIGHTINGS), figsize=(4.2 * len(WEIGHTINGS), 4.0), sharey=True)
    cells = [(severity, traffic) for severity in SEVERITIES for traffic in TRAFFIC]
    x = np.arange(len(cells))
    for ax, name in zip(axes, WEIGHTINGS):
        by_cell = {(row["severity"], row["traffic"]): row for row in rows if row["weighting"] == name}
        width = 0.8 / len(REFERENCES)
        for i, ref in enumerate(REFERENCES):
            share = np.array([100 * by_cell[cell][f"{ref}_share"] for cell in cells])
            ax.bar(x + (i - (len(REFERENCES) - 1) / 2) * width, share, width=width, label=ref)
        ax.axhline(100 * TARGET_SHARE, color="k", lw=0.8, ls="--")
        ax.set_xticks(x, [f"{s}\n{t}" for s, t in cells], fontsize=7)
        ax.set_title(name, fontsize=9)
    axes[0].set_ylabel("gain over the best blind constant [% of |its return|]")
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110, metadata={"Software": None})
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    defaults = Plan()
    parser.add_argument("--train", type=cli.count, default=defaults.train, help="training seeds per condition")
    parser.add_argument("--selection", type=cli.count, default=defaults.selection, help="selection seeds")
    parser.add_argument("--held-out", type=cli.count, default=defaults.held_out, help="held-out seeds")
    parser.add_argument("--out", default="runs/task", help="directory for map.md, map.csv, map.png, v1.md, ...")
    add_arguments(parser)
    args = parser.parse_args()
    cli.output_dir(args.out)
    plan, backend = Plan(args.train, args.selection, args.held_out), Backend.from_args(args)
    work = cli.work_directory(args.out, copy=True)  # results/task also holds evaluate_task's folders: kept
    start = time.perf_counter()
    rows, fronts = task_map(plan, backend)
    runtime = f"{time.perf_counter() - start:.0f} s ({backend.name} backend)"
    cli.write_rows(rows, work / "map.csv")
    cli.write_rows(fronts, work / "map_fronts.csv")
    (work / "map.md").write_text(markdown(rows, fronts, plan, choose_default(rows), runtime), encoding="utf-8")
    figure(rows, work / "map.png")
    front_figure(fronts, work / "map_fronts.png")
    start = time.perf_counter()
    v1_rows, v1_fronts, _ = v1_headroom(plan, backend)
    runtime = f"{time.perf_counter() - start:.0f} s ({backend.name} backend)"
    cli.write_rows(v1_rows, work / "v1.csv")
    cli.write_rows(v1_fronts, work / "v1_fronts.csv")
    (work / "v1.md").write_text(v1_markdown(v1_rows[0], v1_fronts, plan, runtime), encoding="utf-8")
    cli.publish(work, args.out)
    print((Path(args.out) / "v1.md").read_text(encoding="utf-8"))
    print((Path(args.out) / "map.md").read_text(encoding="utf-8"))


if __name__ == "__main__":
    cli.run(main, "python -m train.task_map")
