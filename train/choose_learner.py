"""Choose PPO's learner setting for the default task by throughput *and* by score at equal env steps (issue 39,
item 3): each candidate below trains the same number of steps on ``--seeds`` training seeds and is scored on
selection episodes; its learning throughput is measured in this process against today's setting's.

    python -m train.choose_learner                        # the study: writes runs/learner/ (results/learner: --out)
    python -m train.choose_learner --seeds 1 --timesteps 200000 --episodes 100 --out /tmp/learner   # a quick look

The candidates (``CANDIDATES``) are overrides of ``hyperparams/ppo.yml``'s default-task section; each is written as
a hyperparameter file of its own, ``<runs>/<candidate>/ppo.yml`` (``train_ppo --hyperparams`` reads it; the rest of
``hyperparams/ppo.yml`` copied as it is), ``base`` that section unchanged. The rule, fixed before any candidate trained:
**the chosen setting is the fastest candidate whose mean selection return is not shown worse than base's** (the
95 % interval of candidate minus base, paired by episode and pooled over training seeds, reaches 0 or above); a
candidate that is faster but shown worse is reported, not chosen.

Seeds: training seeds 0 .. ``--seeds`` - 1 (``train_ppo --seed``; its sub-envs below 10,000), scored on the default
task's selection episodes 5000 .. 5000 + ``--episodes`` - 1 (never held-out ones). Each run trains with
``python -m train.train_ppo`` in a child process into ``<runs>/<candidate>/seed<k>``; a run already there with its
``training.md`` (a finished run) is scored again, not retrained. Throughput is ``timegap_env.speed.ppo.measure``'s on the
candidate's file (``make bench``'s PPO row): ``--rollouts`` timed rollouts with their updates, one torch thread.

Writes ``<out>/learner.csv`` (a row per candidate and seed) and ``<out>/README.md``; ``--out`` must not exist
(``--force`` replaces it; a failed run leaves it as it was).
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from timegap_env import DEFAULT_TASK, cli
from timegap_env.experiments import registry
from timegap_env.experiments.rollout import rollout
from timegap_env.experiments.stats import bootstrap_mean, paired_mde
from timegap_env.tasks import SELECTION_SEED_START, get_task
from timegap_env.speed import ppo as speed_ppo

SMALL_RELU = "dict(net_arch=dict(pi=[32, 32], vf=[32, 32]), activation_fn=nn.ReLU)"
HYPERPARAMS = Path("hyperparams/ppo.yml")  # the file the candidates override
CANDIDATES: dict[str, dict[str, Any]] = {  # name: overrides of HYPERPARAMS' default-task section
    "base": {},
    "wide_rollout": dict(n_envs=256, n_steps=64, batch_size=2048),
    "wide_4_epochs": dict(n_envs=256, n_steps=32, batch_size=2048, n_epochs=4),
    "small_relu_256": dict(n_envs=256, n_steps=32, batch_size=2048, n_epochs=4, policy_kwargs=SMALL_RELU),
    "small_relu_256_lr3e-3": dict(n_envs=256, n_steps=32, batch_size=2048, n_epochs=4, policy_kwargs=SMALL_RELU,
                                  learning_rate=3e-3),
    "small_relu_1024_lr3e-3": dict(n_envs=1024, n_steps=32, batch_size=4096, n_epochs=4, policy_kwargs=SMALL_RELU,
                                   learning_rate=3e-3),
}
COLUMNS = ("candidate", "seed", "overrides", "steps_per_second", "speed_ratio", "timesteps", "train_seconds",
           "episodes", "mean_return", "collision_rate", "difference", "difference_low", "difference_high", "mde")


@dataclasses.dataclass(frozen=True)
class Scored:
    """One trained run on the selection episodes."""

    returns: np.ndarray  # per episode [-]
    collided: np.ndarray  # per episode [bool]
    train_seconds: float  # the run's wall time as its training.md gives it [s]


def choose(speed: dict[str, float], upper: dict[str, float]) -> str:
    """The rule: the fastest of ``base`` and the candidates whose difference to base has an upper 95 % bound
    ``upper[name]`` >= 0 (not shown worse); ``speed`` [env steps/s] of every one, base included."""
    eligible = ["base", *(name for name, high in upper.items() if high >= 0.0)]
    return max(eligible, key=lambda name: speed[name])


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="python -m train.choose_learner", description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=cli.count, default=3, help="training seeds per candidate (default: %(default)s)")
    parser.add_argument("--timesteps", type=cli.count, default=None,
                        help="env steps of every run (default: the yml's n_timesteps)")
    parser.add_argument("--episodes", type=cli.count, default=2000,
                        help="selection episodes each run is scored on (default: %(default)s)")
    parser.add_argument("--rollouts", type=cli.count, default=6,
                        help="rollouts timed per candidate for its throughput (default: %(default)s)")
    parser.add_argument("--candidates", nargs="+", default=list(CANDIDATES), choices=list(CANDIDATES),
                        help="which candidates (default: all; base is always measured)")
    parser.add_argument("--runs", type=Path, default=Path("runs/learner"),
                        help="where the trained runs go (default: %(default)s)")
    parser.add_argument("--out", type=Path, default=Path("runs/learner-report"),
                        help="the report's directory (default: %(default)s)")
    parser.add_argument("--force", action="store_true", help="replace --out if it exists")
    return parser.parse_args(argv)


def write_hyperparams(name: str, runs: Path) -> Path:
    """``HYPERPARAMS`` with candidate ``name``'s overrides in the default task's section, as ``<runs>/<name>/ppo.yml``
    (kept if it is there with the same content; a different one is refused: its runs were trained with it)."""
    document = yaml.safe_load(HYPERPARAMS.read_text())
    document[DEFAULT_TASK] = {**document[DEFAULT_TASK], **CANDIDATES[name]}
    text = (f"# {HYPERPARAMS} with candidate {name!r} of train.choose_learner: {CANDIDATES[name] or 'unchanged'}\n"
            + yaml.safe_dump(document, sort_keys=False))
    path = runs / name / "ppo.yml"
    if path.is_file() and path.read_text() != text:
        raise FileExistsError(f"{path}: holds other hyperparameters than candidate {name!r}'s; its runs were trained "
                              "with them: move them away")
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


def train(name: str, seed: int, timesteps: int | None, runs: Path) -> Path:
    """Train candidate ``name`` with ``seed`` in a child ``train_ppo`` (unless a finished run is there): its run."""
    run = runs / name / f"seed{seed}"
    if (run / "training.md").is_file():
        print(f"{run}: a finished run, scored again", flush=True)
        return run
    command = [sys.executable, "-m", "train.train_ppo", "--seed", str(seed), "--out", str(run), "--curve-freq", "0",
               "--no-progress-bar", "--hyperparams", str(runs / name / "ppo.yml"),
               *(["--timesteps", str(timesteps)] if timesteps else [])]
    print("$", " ".join(command), flush=True)
    subprocess.run(command, check=True, stdout=subprocess.DEVNULL)
    return run


def train_seconds(run: Path) -> float:
    """The wall time a run's training.md gives [s]."""
    for line in (run / "training.md").read_text().splitlines():
        if line.startswith("| wall time"):
            return float(line.split("|")[2].strip().removesuffix(" s"))
    raise ValueError(f"{run / 'training.md'}: no wall-time row")


def score(run: Path, episodes: int) -> Scored:
    """The run's deterministic policy on the default task's first ``episodes`` selection episodes."""
    config = get_task(DEFAULT_TASK).config()
    records = rollout(registry.load_learned(run, config), config,
                      range(SELECTION_SEED_START, SELECTION_SEED_START + episodes)).records
    return Scored(np.array([record.episode_return for record in records]),
                  np.array([bool(record.summary["collision"]) for record in records]), train_seconds(run))


def report(rows: list[dict[str, Any]], chosen: str, args: argparse.Namespace) -> str:
    """The README of the study."""
    lines = [
        "# PPO's learner setting for the default task: throughput and score at equal steps",
        "",
        f"Command: `python -m train.choose_learner --seeds {args.seeds} --episodes {args.episodes}"
        f"{f' --timesteps {args.timesteps}' if args.timesteps else ''} --out {args.out}` (training seeds "
        f"0-{args.seeds - 1}; selection episodes {SELECTION_SEED_START}-{SELECTION_SEED_START + args.episodes - 1}).",
        "",
        "Rule, fixed before training: the fastest candidate whose return is not shown worse than base's (the 95 % "
        "interval of the difference, paired by episode and pooled over the training seeds, reaches 0).",
        "",
        f"n: {args.seeds} training seeds x {args.episodes} episodes per candidate; mde: the smallest difference to base "
        "detectable at 80 % power (paired by episode, seeds pooled); collisions apart from the return.",
        "",
        "| candidate | overrides of hyperparams/ppo.yml's section | env steps/s of learning (x base) | mean return per seed "
        "| collisions /100 | difference to base [95 % CI] | mde |",
        "|---|---|---|---|---|---|---|",
    ]
    for name in dict.fromkeys(row["candidate"] for row in rows):
        mine = [row for row in rows if row["candidate"] == name]
        first = mine[0]
        returns = ", ".join(f"{row['mean_return']:.1f}" for row in mine)
        collisions = 100 * np.mean([row["collision_rate"] for row in mine])
        mde = "" if name == "base" else f"{first['mde']:.1f}"
        difference = (f"{first['pooled_difference']:+.1f} [{first['pooled_low']:+.1f}, {first['pooled_high']:+.1f}]"
                      if name != "base" else "")
        lines.append(f"| {'**' + name + '**' if name == chosen else name} | `{first['overrides'] or '-'}` | "
                     f"{first['steps_per_second']:,.0f} (x{first['speed_ratio']:.2f}) | {returns} | {collisions:.2f} "
                     f"| {difference} | {mde} |")
    lines += ["", f"Chosen: **{chosen}**.", ""]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    cli.output_dir(args.out)
    if args.out.exists() and any(args.out.iterdir()) and not args.force:
        raise FileExistsError(f"--out {args.out}: exists; --force replaces it (or give another --out)")
    names = ["base", *(name for name in args.candidates if name != "base")]
    files = {name: write_hyperparams(name, args.runs) for name in names}
    speed = {name: speed_ppo.measure(args.rollouts, hyperparams=files[name]).steps_per_second for name in names}
    for name in names:
        print(f"{name}: {speed[name]:,.0f} env steps/s of learning (x{speed[name] / speed['base']:.2f})", flush=True)
    scored = {name: [score(train(name, seed, args.timesteps, args.runs), args.episodes) for seed in range(args.seeds)]
              for name in names}
    base = np.mean([run.returns for run in scored["base"]], axis=0)  # per episode, over the seeds
    rows: list[dict[str, Any]] = []
    for name in names:
        pooled = np.mean([run.returns for run in scored[name]], axis=0)
        difference, low, high = bootstrap_mean(pooled - base)
        mde = paired_mde(pooled - base) if name != "base" else float("nan")
        for seed, run in enumerate(scored[name]):
            per_seed = bootstrap_mean(run.returns - scored["base"][seed].returns)
            rows.append({"candidate": name, "seed": seed, "overrides": CANDIDATES[name],
                         "steps_per_second": speed[name], "speed_ratio": speed[name] / speed["base"],
                         "timesteps": args.timesteps or "yml", "train_seconds": run.train_seconds,
                         "episodes": args.episodes, "mean_return": float(run.returns.mean()),
                         "collision_rate": float(run.collided.mean()), "difference": per_seed[0],
                         "difference_low": per_seed[1], "difference_high": per_seed[2],
                         "pooled_difference": difference, "pooled_low": low, "pooled_high": high, "mde": mde})
    chosen = choose(speed, {row["candidate"]: row["pooled_high"] for row in rows if row["candidate"] != "base"})
    work = cli.work_directory(args.out)
    with open(work / "learner.csv", "w", newline="") as file:
        writer = csv.DictWriter(file, fieldnames=COLUMNS, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)
    (work / "README.md").write_text(report(rows, chosen, args))
    cli.publish(work, args.out)
    print((args.out / "README.md").read_text())


if __name__ == "__main__":
    cli.run(main, "python -m train.choose_learner")
