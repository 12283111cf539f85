"""Choose the default degradation mix by measurement: the mix that poses the problem best.

    python -m train.choose_degradation_mix [--episodes 24] [--out results/degradation]

Each kind (and nominal driving) is run alone, ``--episodes`` episodes on selection seeds
(``SELECTION_SEED_START`` on: below the held-out seeds and apart from the lookup oracle's training
seeds), with every pair of constants (one while the V2V flag is up, one while it is down; equal
pairs are the plain constants) and every oracle of ``train/value_of_information.py``. A mix
(weights per kind) then has, from these per-kind means, a best blind constant, a best V2V-aware
pair, and an oracle (the best oracle's weighted mean). The V2V flag shows the outage and the
commercial ACC cars, so what only the ground truth adds is the oracle's gain over the best
V2V-aware pair: the most a policy reading the monitor could add. Every mix of ``WEIGHT_GRID`` per
kind (every kind stays in) is scored by that gain relative to the pair's |return|; the largest wins
(ties: the smallest total weight). When no mix gives the oracle a positive gain, no mix poses the
problem and weighting would only pick noise: every kind then keeps weight 1. Writes ``mix.md`` and ``mix.csv`` (the per-kind means) to
``--out``; the chosen weights are ``DegradationConfig.kind_weights``'s default.
"""

from __future__ import annotations

import argparse
import csv
import itertools
import time
from collections.abc import Sequence
from pathlib import Path
from typing import NamedTuple

import numpy as np

from timegap_env.agents.oracles import NOMINAL
from timegap_env.agents.policies import seconds
from timegap_env.agents.protocol import EVAL_SEED_START
from timegap_env import cli
from timegap_env.config import DEGRADATION_KINDS, EnvConfig
from timegap_env.envs.info import truth_of
from timegap_env.studies.value import (
    DEFAULT_TRAIN_EPISODES, SELECTION_SEED_START, TARGET_SHARE, all_oracles, constants, measure_lookup,
    run,
)

DEFAULT_OUT = Path("runs/degradation")  # beside train.value_of_information's files
WEIGHT_GRID = (1, 2, 4)  # the weights tried for each kind: every kind stays in the mix [-]

DEFAULT_EPISODES = 24  # per kind


def per_kind(config: EnvConfig, episodes: int, table: dict[str, float]) -> dict[str, dict[str, np.ndarray]]:
    """Per kind run alone: every pair of constants' returns (n_episodes, n_levels, n_levels) and collisions, and
    each oracle's returns (n_episodes,)."""
    seeds = list(range(SELECTION_SEED_START, SELECTION_SEED_START + episodes))
    assert seeds[-1] < EVAL_SEED_START
    results = {}
    for kind in (NOMINAL, *DEGRADATION_KINDS):
        alone = config.with_overrides({"degradation": config.degradation.with_overrides({"kind_weights": {kind: 1.0}})})
        pairs = constants(alone, seeds, flag_aware=True)
        oracles = all_oracles(alone, table)
        results[kind] = {"return": pairs["return"], "collision": pairs["collision"],
                         **{f"oracle:{o.name}": run(alone, seeds, lambda obs, infos, o=o: o.act(truth_of(infos)))["return"]
                            for o in oracles}}
    return results


class MixScore(NamedTuple):
    """What a mix gives, from the per-kind means."""

    gain: float  # (oracle - best V2V-aware pair) / |best pair| [-]
    blind_gain: float  # (oracle - best blind constant) / |best blind constant| [-]
    blind: int  # the best blind constant's level
    blind_mean: float
    pair: tuple[int, int]  # the best V2V-aware pair's levels (V2V up, V2V down)
    pair_mean: float
    oracle_mean: float


def score(weights: np.ndarray, pair_means: np.ndarray, oracle_means: np.ndarray) -> MixScore:
    """A mix's :class:`MixScore`; ``pair_means`` (n_kinds, n_levels, n_levels), ``oracle_means`` (n_oracles, n_kinds)."""
    share = weights / weights.sum()
    mixed = np.tensordot(share, pair_means, axes=1)  # (n_levels, n_levels)
    blind = int(np.argmax(np.diagonal(mixed)))
    pair = np.unravel_index(int(np.argmax(mixed)), mixed.shape)
    oracle = float((oracle_means @ share).max())
    blind_mean, pair_mean = float(mixed[blind, blind]), float(mixed[pair])
    return MixScore((oracle - pair_mean) / abs(pair_mean), (oracle - blind_mean) / abs(blind_mean), blind, blind_mean,
                    (int(pair[0]), int(pair[1])), pair_mean, oracle)


def choose(n_kinds: int, pair_means: np.ndarray, oracle_means: np.ndarray) -> list[tuple[tuple[int, ...], MixScore]]:
    """Every mix of the grid with its score, best first."""
    scored = [(combo, score(np.array(combo, dtype=float), pair_means, oracle_means))
              for combo in itertools.product(WEIGHT_GRID, repeat=n_kinds)]
    scored.sort(key=lambda item: (-item[1].gain, sum(item[0])))
    return scored


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m train.choose_degradation_mix", description=__doc__.split("\n")[0])
    parser.add_argument("--episodes", type=int, default=DEFAULT_EPISODES, help="episodes per kind (default %(default)s)")
    parser.add_argument("--train-episodes", type=int, default=DEFAULT_TRAIN_EPISODES,
                        help="training episodes per condition of the lookup oracle (default %(default)s)")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="output directory (default %(default)s)")
    args = parser.parse_args(argv)
    cli.output_dir(args.out)
    started = time.perf_counter()
    config = EnvConfig()
    levels = config.setting_levels
    table, _ = measure_lookup(config, args.train_episodes)
    results = per_kind(config, args.episodes, table)
    kinds = list(results)
    pair_means = np.array([results[k]["return"].mean(axis=0) for k in kinds])
    constant_means = np.array([np.diagonal(m) for m in pair_means])
    oracle_names = [name for name in results[NOMINAL] if name.startswith("oracle:")]
    oracle_means = np.array([[results[k][name].mean() for k in kinds] for name in oracle_names])
    ranking = choose(len(kinds), pair_means, oracle_means)
    uniform = score(np.ones(len(kinds)), pair_means, oracle_means)
    chosen, best = ranking[0]
    poses_problem = best.gain > 0
    if not poses_problem:
        chosen, best = tuple(1 for _ in kinds), uniform
    undrivable = {k: int(np.diagonal(results[k]["collision"], axis1=1, axis2=2).all(axis=1).sum()) for k in kinds}

    args.out.mkdir(parents=True, exist_ok=True)
    with open(args.out / "mix.csv", "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["kind", *(f"return_{seconds(level)}" for level in levels), *oracle_names, "collisions_all_constants"])
        for i, kind in enumerate(kinds):
            writer.writerow([kind, *(f"{v:.4f}" for v in constant_means[i]), *(f"{v:.4f}" for v in oracle_means[:, i]),
                             undrivable[kind]])
    lines = [
        "# The default degradation mix, chosen by measurement (`python -m train.choose_degradation_mix`)", "",
        f"Each kind alone on {args.episodes} selection episodes (seeds {SELECTION_SEED_START}-"
        f"{SELECTION_SEED_START + args.episodes - 1}), every constant and every oracle (lookup table from "
        f"{args.train_episodes} training episodes per condition, seeds 0-{args.train_episodes - 1}). Mean return:", "",
        "| kind | " + " | ".join(f"{seconds(level)} s" for level in levels) + " | best constant | "
        + " | ".join(name.split(":", 1)[1] for name in oracle_names) + " | episodes where every constant collides |",
        "|---|" + "---|" * (len(levels) + 1 + len(oracle_names) + 1)]
    for i, kind in enumerate(kinds):
        lines.append(f"| {kind} | " + " | ".join(f"{v:.1f}" for v in constant_means[i])
                     + f" | {seconds(levels[int(np.argmax(constant_means[i]))])} s | "
                     + " | ".join(f"{v:.1f}" for v in oracle_means[:, i]) + f" | {undrivable[kind]} |")
    lines += ["", f"Mixes: every kind weighted from {WEIGHT_GRID} ({len(ranking)} mixes). The best ten by the oracle's gain "
              "over the best V2V-aware pair of constants, relative to its |return|, and beside it the gain over the best "
              "blind constant:", "",
              "| " + " | ".join(kinds) + " | best blind constant: mean | best V2V-aware pair: mean | oracle mean | "
              "gain over the pair | gain over the blind constant |", "|" + "---|" * (len(kinds) + 5)]
    for combo, mix in ranking[:10]:
        lines.append("| " + " | ".join(str(w) for w in combo) + f" | {seconds(levels[mix.blind])} s: {mix.blind_mean:.1f} | "
                     f"{seconds(levels[mix.pair[0]])} / {seconds(levels[mix.pair[1]])} s: {mix.pair_mean:.1f} | "
                     f"{mix.oracle_mean:.1f} | {100 * mix.gain:.0f} % | {100 * mix.blind_gain:.0f} % |")
    verdict = ("" if poses_problem else "No mix gives the oracle a positive gain over the best V2V-aware pair: no mix "
               "poses the problem, so every kind keeps weight 1. ")
    lines += ["", verdict + f"Chosen: {dict(zip(kinds, chosen))}: the oracle gains {100 * best.gain:.0f} % over the best V2V-aware "
              f"pair and {100 * best.blind_gain:.0f} % over the best blind constant (the issue's target "
              f"{100 * TARGET_SHARE:.0f} %: {'met' if best.blind_gain >= TARGET_SHARE else 'not met'}); every kind at "
              f"weight 1 gives {100 * uniform.gain:.0f} % and {100 * uniform.blind_gain:.0f} %.", ""]
    text = "\n".join(lines)
    (args.out / "mix.md").write_text(text)
    print(text)
    print(f"Runtime: {time.perf_counter() - started:.0f} s")


if __name__ == "__main__":
    cli.run(main, "python -m train.choose_degradation_mix")
