"""One multi-objective learner on ``mo-TimeGapMonitor-v1``: MORL-Baselines' Envelope Q-learning, giving a front
rather than a point (issue 25).

    python -m train.train_morl [--timesteps 35000] [--selection 32] [--held-out 100] [--out results/morl]

Needs the ``mo`` extra (``pip install -e '.[mo]'``; ``.venv-clients`` has it). Trains Envelope (seed 0, one torch
thread, on the CPU, small nets) on the reward terms efficiency, string stability, tracking and collision, its
training episodes reset with seeds 0, 1, 2, ... (all below ``EVAL_SEED_START``). Then plays the learned Q-network
for each of :data:`WEIGHTS` through the rollout harness in ``TimeGapMonitor-v1`` (action mode "platoon": the MO env's
Discrete(9), the same levels): the weight vector whose v1 return is best on the selection seeds is compared on the
held-out seeds with the best blind constant (the ladder constant best on the same selection seeds), with a paired
bootstrap interval; and every weight vector's mean held-out (capacity, string stability, variation) point is set
beside the constants', with hypervolumes. Writes ``front.md``, ``front.csv`` and ``front.png`` to ``--out`` (through
a partial directory: a failed run overwrites nothing); reruns give the same files but the runtime line.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

import gymnasium as gym
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from timegap_env import MO_ENV_ID, cli
from timegap_env._extras import require
from timegap_env.agents.protocol import EVAL_SEED_START
from timegap_env.config import REWARD_PRESETS, EnvConfig
from timegap_env.envs.reward import REWARD_TERMS
from timegap_env.experiments.backends import Backend
from timegap_env.experiments.rollout import rollout
from timegap_env.experiments.stats import bootstrap_mean
from timegap_env.tasks import get_task
from timegap_env.studies.task_map import FRONT_OBJECTIVES, front_rows, hypervolume, pair_terms, weigh
from timegap_env.studies.value import SELECTION_SEED_START

PROG = "python -m train.train_morl"
OBJECTIVES = ("efficiency", "string_stability", "tracking", "collision")  # the MO env's reward terms, in this order
WEIGHTING = "variation_first"  # TimeGapMonitor-v1's weighting (its record in timegap_env.tasks)
DEFAULT_TIMESTEPS = 35_000  # about 3 min of training on one torch thread (measured: 3000 steps in 14.5 s)
NET_ARCH = [64, 64]
BUFFER_SIZE = 10_000
LEARNING_STARTS = 500
SEED = 0


def v1_weights() -> np.ndarray:
    """v1's weights of OBJECTIVES (the other terms left out), normalised to sum 1."""
    weights = REWARD_PRESETS[WEIGHTING].weights
    w = np.array([getattr(weights, name) for name in OBJECTIVES])
    return w / w.sum()


def weight_vectors() -> dict[str, np.ndarray]:
    """The weight vectors played: the simplex's 4 corners, its centre, 4 interior points leaning to one objective each,
    and v1's own weights restricted to OBJECTIVES and normalised."""
    vectors = {f"corner {name}": np.eye(len(OBJECTIVES))[i] for i, name in enumerate(OBJECTIVES)}
    vectors["centre"] = np.full(len(OBJECTIVES), 1 / len(OBJECTIVES))
    for i, name in enumerate(OBJECTIVES):
        lean = np.full(len(OBJECTIVES), 0.2)
        lean[i] = 0.4
        vectors[f"lean {name}"] = lean
    vectors["v1 weights"] = v1_weights()
    return {label: w.astype(np.float32) for label, w in vectors.items()}


class SeededResets(gym.Wrapper):
    """Resets with seeds 0, 1, 2, ... in turn (Envelope's ``train`` resets without a seed), all below EVAL_SEED_START."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.next_seed = 0

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict]:
        if self.next_seed >= EVAL_SEED_START:
            raise ValueError(f"training reached seed {EVAL_SEED_START}, the first held-out one: fewer --timesteps")
        seed, self.next_seed = self.next_seed, self.next_seed + 1
        return self.env.reset(seed=seed, options=options)


def train(timesteps: int) -> tuple[Any, int]:
    """Envelope trained for ``timesteps`` steps; and how many training episodes (seeds 0..) it reset."""
    import mo_gymnasium as mo_gym
    import torch
    from mo_gymnasium.wrappers import MORecordEpisodeStatistics
    from morl_baselines.multi_policy.envelope.envelope import Envelope

    torch.set_num_threads(1)  # small networks: one thread runs steadier (and the same) than a pool
    torch.manual_seed(SEED)
    np.random.seed(SEED)  # MORL-Baselines' prioritized replay buffer samples from numpy's global generator
    seeded = SeededResets(mo_gym.make(MO_ENV_ID, objectives=list(OBJECTIVES)))
    env = MORecordEpisodeStatistics(seeded)
    env.reset()  # seed 0; train() resets without a seed: the next seeds follow
    env.action_space.seed(SEED)  # the random actions before learning_starts
    agent = Envelope(env, net_arch=NET_ARCH, buffer_size=BUFFER_SIZE, learning_starts=LEARNING_STARTS, log=False,
                     seed=SEED, device="cpu")
    agent.train(total_timesteps=timesteps, eval_env=None)
    return agent, seeded.next_seed


def agent_chooser(agent: Any, w: np.ndarray) -> Any:
    """The rollout harness's chooser: the agent's greedy action for ``w``, row by row."""
    def choose(obs: np.ndarray, infos: dict[str, Any]) -> np.ndarray:
        return np.array([int(agent.eval(row, w)) for row in obs], dtype=np.int64)
    return choose


def play(agent: Any, w: np.ndarray, config: EnvConfig, seeds: list[int]) -> dict[str, np.ndarray]:
    """The agent for ``w`` on ``seeds``: v1 returns, term sums (n, n_terms) in REWARD_TERMS order, collisions."""
    records = rollout(agent_chooser(agent, w), config, seeds).records
    return {"returns": np.array([record.episode_return for record in records]),
            "terms": np.array([[record.rewards[name] for name in REWARD_TERMS] for record in records]),
            "collisions": np.array([bool(record.summary["collision"]) for record in records])}


def scaled_volumes(points: dict[str, np.ndarray], groups: dict[str, list[str]]) -> dict[str, float]:
    """Hypervolume of each group of ``points`` (mean FRONT_OBJECTIVES), scaled as ``front_rows`` scales: each objective
    over its spread among all points, above the worst point."""
    every = np.array(list(points.values()))
    low, spread = every.min(axis=0), np.maximum(every.max(axis=0) - every.min(axis=0), 1e-12)
    return {group: hypervolume(np.array([(points[name] - low) / spread for name in names]), np.zeros(3))
            for group, names in groups.items()}


def figure(rows: list[dict[str, Any]], path: Path) -> None:
    """Capacity against string stability (colour: variation): the constants and the Envelope's weight vectors."""
    x_name, y_name, colour = FRONT_OBJECTIVES
    fig, ax = plt.subplots(figsize=(6.4, 4.8))
    values = np.array([[row[x_name], row[y_name], row[colour]] for row in rows])
    norm = matplotlib.colors.Normalize(values[:, 2].min(), values[:, 2].max())
    constant = np.array([row["kind"] == "constant" for row in rows])
    for mask, marker, label in ((constant, "o", "constant settings"), (~constant, "^", "Envelope, per weight vector")):
        shown = ax.scatter(values[mask, 0], values[mask, 1], c=values[mask, 2], cmap="viridis", norm=norm, s=36,
                           marker=marker, label=label, edgecolors="k", linewidths=0.4)
    labels: dict[tuple[float, float], list[str]] = {}  # points that coincide share one label
    for row, (x, y, _) in zip(rows, values):
        labels.setdefault((round(float(x), 6), round(float(y), 6)), []).append(row["point"].replace("constant ", ""))
    for (x, y), names in labels.items():
        ax.annotate(" = ".join(names), (x, y), fontsize=6, xytext=(3, 2), textcoords="offset points")
    ax.set_xlabel(f"{x_name} (capacity) per episode")
    ax.set_ylabel(f"{y_name} per episode")
    ax.set_title("mo-TimeGapMonitor-v1: mean held-out term sums", fontsize=9)
    ax.legend(fontsize=7)
    fig.colorbar(shown, ax=ax, label=f"{colour} (time-gap variation) per episode")
    fig.tight_layout()
    fig.savefig(path, dpi=110, metadata={"Software": None})
    plt.close(fig)


def markdown(rows: list[dict[str, Any]], summary: dict[str, Any], runtime: str) -> str:
    s = summary
    weights = ", ".join(f"{name} {value:.4g}" for name, value in zip(OBJECTIVES, s["v1_weights"]))
    lines = [
        "# Envelope Q-learning on mo-TimeGapMonitor-v1: a front, not a point", "",
        f"Written by `{PROG} --timesteps {s['timesteps']} --selection {s['selection']} --held-out {s['held_out']}`. "
        "MORL-Baselines' Envelope (net_arch "
        f"{NET_ARCH}, buffer {BUFFER_SIZE}, learning_starts {LEARNING_STARTS}, seed {SEED}, one torch thread, CPU, "
        f"log=False) on the reward terms {', '.join(OBJECTIVES)}, for {s['timesteps']} steps.", "",
        f"Seeds: training episodes reset with seeds 0-{s['train_episodes'] - 1} ({s['train_episodes']} episodes); "
        f"the weight vector and the best blind constant chosen on {s['selection']} selection seeds from "
        f"{SELECTION_SEED_START}; every number below on {s['held_out']} held-out seeds from {EVAL_SEED_START}. "
        "Every episode is TimeGapMonitor-v1's (action mode platoon, Discrete(9): the MO env's action space), played "
        "through the rollout harness with the agent's greedy action for the weight vector; the return is v1's scalar "
        f"return ({WEIGHTING}, every term).", "",
        "Weight vectors (efficiency, string_stability, tracking, collision): the simplex's 4 corners, its centre, "
        "4 interior points with 0.4 on one objective and 0.2 on the others, and v1's own weights of these four terms "
        f"normalised to sum 1 ({weights}; v1's safety, comfort and switching terms are not among the objectives).", "",
        "## The chosen weight vector against the best blind constant", "",
        f"On the selection seeds the weight vector with the best v1 return is **{s['chosen']}** "
        f"({s['chosen_selection_return']:.1f} per episode; the best blind constant there: {s['best_blind']}, "
        f"{s['best_blind_selection_return']:.1f}). On the held-out seeds it returns {s['chosen_return']:.1f} "
        f"(collisions: {s['chosen_collisions']} of {s['held_out']}) against the best blind constant's "
        f"{s['best_blind_return']:.1f} (collisions: {s['best_blind_collisions']}): a gain of **{s['gain']:.1f} "
        f"[{s['gain_low']:.1f}, {s['gain_high']:.1f}]** per episode (mean of the paired differences, 95 % bootstrap "
        f"interval); without the collision term {s['gain_nc']:.1f} [{s['gain_nc_low']:.1f}, {s['gain_nc_high']:.1f}]. "
        + ("The interval lies above 0." if s["gain_low"] > 0 else
           "The interval does not lie above 0: no measurable gain over the best blind constant."), "",
        "## Every point", "",
        "Mean held-out sums per episode of capacity (efficiency), string stability and time-gap variation (tracking), "
        "the v1 return on the selection and held-out seeds, and held-out collisions. Hypervolume (in units of each "
        "objective's spread over all the points below, above the worst point; `task_map.front_rows`): of the "
        "constants with that point added. Same as: the constant whose held-out sums the point repeats (the agent "
        "then played that constant, or the same sums, on every held-out seed).", "",
        "| point | efficiency | string_stability | tracking | v1 return (selection) | v1 return (held-out) "
        "| collisions | hypervolume | same as |",
        "|---|---|---|---|---|---|---|---|---|"]
    for row in rows:
        lines.append(f"| {row['point']} | {row['efficiency']:.2f} | {row['string_stability']:.2f} | "
                     f"{row['tracking']:.2f} | {row['selection_return']:.1f} | {row['held_out_return']:.1f} | "
                     f"{row['collisions']} | {row['hypervolume']:.3f} | {row['same_as']} |")
    lines += ["", f"Hypervolume of the 9 constants alone: {s['hv_constants']:.3f}; of the Envelope's "
              f"{len(rows) - 9} points alone: {s['hv_envelope']:.3f}; of both together: {s['hv_both']:.3f} "
              + ("(the Envelope's points add volume: trade-offs no constant reaches)." if s["hv_both"]
                 > s["hv_constants"] * (1 + 1e-6) else "(the Envelope's points add no volume to the constants' front)."), "",
              f"Runtime: {runtime}", ""]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--timesteps", type=cli.count, default=DEFAULT_TIMESTEPS, help="Envelope's training steps")
    parser.add_argument("--selection", type=cli.count, default=32, help="selection seeds (from 5000)")
    parser.add_argument("--held-out", type=cli.count, default=100, help="held-out seeds (from 10000)")
    parser.add_argument("--out", default="runs/morl", help="directory for front.md, front.csv, front.png")
    args = parser.parse_args()
    cli.output_dir(args.out)
    try:
        require("mo", "mo_gymnasium", "morl_baselines", "torch", needed_for=PROG)
    except ImportError as error:
        sys.exit(f"{PROG}: error: {error}")
    work = cli.work_directory(args.out)
    start = time.perf_counter()
    agent, train_episodes = train(args.timesteps)
    trained = time.perf_counter() - start

    config = get_task("TimeGapMonitor-v1").config()
    preset = REWARD_PRESETS[WEIGHTING]
    assert config.reward_weights == preset.weights and config.action_mode == "platoon"
    selection = list(range(SELECTION_SEED_START, SELECTION_SEED_START + args.selection))
    held_out = list(range(EVAL_SEED_START, EVAL_SEED_START + args.held_out))
    levels = list(config.setting_levels)
    constant_pairs = [(level, level) for level in range(len(levels))]
    backend = Backend()
    constants_selection = pair_terms(config, selection, constant_pairs, backend)[0]
    constants_held, constants_collided = pair_terms(config, held_out, constant_pairs, backend)
    best = int(np.argmax(weigh(constants_selection, preset).mean(axis=1)))

    vectors = weight_vectors()
    on_selection = {label: play(agent, w, config, selection) for label, w in vectors.items()}
    chosen = max(vectors, key=lambda label: float(on_selection[label]["returns"].mean()))  # first of ties
    on_held = {label: play(agent, w, config, held_out) for label, w in vectors.items()}
    runtime = f"{time.perf_counter() - start:.0f} s ({trained:.0f} s training, serial backend)"

    blind = weigh(constants_held[best], preset)
    collision = REWARD_TERMS.index("collision")
    without = preset.weights.collision
    chosen_returns = on_held[chosen]["returns"]
    gain = bootstrap_mean(chosen_returns - blind)
    gain_nc = bootstrap_mean((chosen_returns - without * on_held[chosen]["terms"][:, collision])
                             - (blind - without * constants_held[best][:, collision]))
    fronts = front_rows(constants_held, {label: on_held[label]["terms"] for label in vectors}, levels, {})
    columns = [REWARD_TERMS.index(name) for name in FRONT_OBJECTIVES]
    points = {row["point"]: np.array([row[name] for name in FRONT_OBJECTIVES]) for row in fronts}
    constant_names = [f"constant {level:g} s" for level in levels]
    volumes = scaled_volumes(points, {"constants": constant_names, "envelope": list(vectors),
                                      "both": constant_names + list(vectors)})
    rows = []
    for row in fronts:
        name = row["point"]
        is_constant = name in constant_names
        i = constant_names.index(name) if is_constant else -1
        selection_return = (weigh(constants_selection[i], preset) if is_constant else on_selection[name]["returns"]).mean()
        held_return = (weigh(constants_held[i], preset) if is_constant else on_held[name]["returns"]).mean()
        collisions = int(constants_collided[i].sum()) if is_constant else int(on_held[name]["collisions"].sum())
        rows.append({"point": name, "kind": "constant" if is_constant else "envelope",
                     **{f"w_{objective}": "" if is_constant else float(vectors[name][k])
                        for k, objective in enumerate(OBJECTIVES)},  # constants: no weights
                     **{objective: float(row[objective]) for objective in FRONT_OBJECTIVES},
                     "selection_return": float(selection_return), "held_out_return": float(held_return),
                     "collisions": collisions, "hypervolume": float(row["hypervolume"]),
                     "constants_hypervolume": float(row["constants_hypervolume"]),
                     "same_as": "" if is_constant else next(
                         (other for j, other in enumerate(constant_names)
                          if np.array_equal(on_held[name]["terms"], constants_held[j])), "")})
    assert np.allclose([points[name] for name in constant_names],
                       constants_held.mean(axis=1)[:, columns])  # front_rows' points are the mean held-out sums
    summary = {"timesteps": args.timesteps, "selection": args.selection, "held_out": args.held_out,
               "train_episodes": train_episodes, "v1_weights": v1_weights(), "chosen": chosen,
               "chosen_selection_return": float(on_selection[chosen]["returns"].mean()),
               "best_blind": constant_names[best],
               "best_blind_selection_return": float(weigh(constants_selection[best], preset).mean()),
               "chosen_return": float(chosen_returns.mean()), "chosen_collisions": int(on_held[chosen]["collisions"].sum()),
               "best_blind_return": float(blind.mean()), "best_blind_collisions": int(constants_collided[best].sum()),
               **dict(zip(("gain", "gain_low", "gain_high"), gain)),
               **dict(zip(("gain_nc", "gain_nc_low", "gain_nc_high"), gain_nc)),
               "hv_constants": volumes["constants"], "hv_envelope": volumes["envelope"], "hv_both": volumes["both"]}
    cli.write_rows(rows, work / "front.csv")
    figure(rows, work / "front.png")
    (work / "front.md").write_text(markdown(rows, summary, runtime), encoding="utf-8")
    cli.publish(work, args.out)
    print((Path(args.out) / "front.md").read_text(encoding="utf-8"))


if __name__ == "__main__":
    cli.run(main, "python -m train.train_morl")
