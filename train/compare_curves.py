"""The learning curves of several train_ppo runs side by side (issue 25: every recipe tried, its curve).

    python -m train.compare_curves RUN [RUN ...] [--out results/recipes/curves]

Reads each run's ``curve.csv`` (the deterministic policy's mean return on the run's check episodes, seeds 9000 on,
below every selection and held-out seed; the best blind constant's and the oracle's returns there) and ``env.json``
(what the run trained: env, algorithm, hidden features, monitor), and writes ``curves.png`` (every run's return
against its steps, the references dashed) and ``curves.md`` (per run: its last and best point, the references) to
``--out`` (through a partial directory: a failed run overwrites nothing). The runs must share their check episodes'
references (one env version, one reward), or their returns could not be compared; it says which does not.
"""

from __future__ import annotations

import argparse
import csv
import math
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from timegap_env import cli
from timegap_env.agents.protocol import ENV_FILE, read_env_file
from timegap_env.config import MonitorConfig
from timegap_env.studies.training import CURVE_COLUMNS, CURVE_FILE


def read_run(path: Path) -> dict[str, Any]:
    """A run's curve points and what it trained; ``ValueError`` naming the file that is missing or malformed."""
    run = read_env_file(path / ENV_FILE)
    curve_path = path / CURVE_FILE
    try:
        with open(curve_path, newline="") as file:
            rows = list(csv.DictReader(file))
        points = [{name: float(row[name]) for name in CURVE_COLUMNS} for row in rows]
    except (OSError, UnicodeDecodeError, csv.Error, KeyError, TypeError, ValueError) as error:
        raise ValueError(f"{curve_path}: not a learning curve of train_ppo with the columns {list(CURVE_COLUMNS)} "
                         f"({type(error).__name__}: {error})") from error
    if not points:
        raise ValueError(f"{curve_path}: no points")
    config = run.config
    recipe = [run.algo, config.action_mode, f"{run.frame_stack} frame(s)"]
    recipe += [f"hidden {', '.join(run.hidden_features)}"] if run.hidden_features else []
    recipe += [f"monitor {config.monitor.estimator}"] if config.monitor.estimator != MonitorConfig.estimator else []
    return {"name": path.name, "env_id": run.env_id, "recipe": "; ".join(recipe), "points": points}


def references(runs: list[dict[str, Any]]) -> tuple[float, float]:
    """The best blind constant's and the oracle's return on the check episodes, the same for every run; ``ValueError``
    naming the runs that differ."""
    seen: dict[tuple[str, float, float], list[str]] = {}
    for run in runs:
        key = (run["env_id"], run["points"][0]["best_blind_return"], run["points"][0]["oracle_return"])
        seen.setdefault(key, []).append(run["name"])
    if len(seen) > 1:
        groups = "; ".join(f"{', '.join(names)}: {key}" for key, names in seen.items())
        raise ValueError("the runs' check episodes have different references (env id, best blind return, oracle "
                         f"return): {groups}; compare runs of one env version and reward")
    (_, blind, oracle), = seen
    return blind, oracle


def table(runs: list[dict[str, Any]], blind: float, oracle: float) -> list[str]:
    """curves.md's lines."""
    share = "share of the oracle's gap" if math.isfinite(runs[0]["points"][-1]["share_of_oracle_gap"]) else ""
    lines = ["# Learning curves on the check episodes", "",
             f"Check episodes: train_ppo's (seeds 9000 on, below every selection and held-out seed) in {runs[0]['env_id']}; "
             f"the best blind constant returns {blind:.1f} there, the oracle {oracle:.1f}. The curves choose nothing: "
             "recipes are chosen on the recipe-selection seeds (`train.evaluate_task --split selection`).", "",
             "| run | recipe | steps | last return | best return (at steps) |" + (f" {share} (last) |" if share else ""),
             "|---|---|---|---|---|" + ("---|" if share else "")]
    for run in runs:
        last, best = run["points"][-1], max(run["points"], key=lambda point: point["mean_return"])
        lines.append(f"| {run['name']} | {run['recipe']} | {last['timesteps']:,.0f} | {last['mean_return']:.1f} | "
                     f"{best['mean_return']:.1f} ({best['timesteps']:,.0f}) |"
                     + (f" {last['share_of_oracle_gap']:.2f} |" if share else ""))
    if not share:
        lines += ["", "No share of the oracle's gap: on these episodes the oracle does not beat the best blind constant "
                      "with a 95 % interval above 0 (each run's training.md gives the interval)."]
    return lines + [""]


def figure(runs: list[dict[str, Any]], blind: float, oracle: float, path: Path) -> None:
    """Every run's mean return on the check episodes against its steps; the references dashed."""
    fig, ax = plt.subplots(figsize=(9, 5))
    for i, run in enumerate(runs):  # line styles cycle too: runs that share their start overlap there
        ax.plot([p["timesteps"] for p in run["points"]], [p["mean_return"] for p in run["points"]],
                ("-", "--", "-.", ":")[i // 10 % 4], lw=1.2, label=run["name"])
    ax.axhline(blind, color="k", ls="--", lw=1, label="best blind constant")
    ax.axhline(oracle, color="0.5", ls=":", lw=1, label="oracle")
    ax.set_xlabel("timesteps")
    ax.set_ylabel("mean return, check episodes")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=110, metadata={"Software": None})
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("runs", type=Path, nargs="*", help="train_ppo run directories")
    parser.add_argument("--out", default="runs/recipes/curves", help="directory for curves.md and curves.png")
    args = parser.parse_args()
    cli.output_dir(args.out)
    if not args.runs:
        raise ValueError("no runs given: name train_ppo run directories")
    runs = [read_run(path) for path in args.runs]
    blind, oracle = references(runs)
    work = cli.work_directory(args.out)
    figure(runs, blind, oracle, work / "curves.png")
    (work / "curves.md").write_text("\n".join(table(runs, blind, oracle)), encoding="utf-8")
    cli.publish(work, args.out)
    print((Path(args.out) / "curves.md").read_text(encoding="utf-8"))


if __name__ == "__main__":
    cli.run(main, "python -m train.compare_curves")
