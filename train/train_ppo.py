"""Train PPO (Stable-Baselines3) on the default task (``timegap_env.DEFAULT_TASK``, ``TimeGapMonitor-v1``) or
another (``--env-id``), every platoon in one native vector env.

    python -m train.train_ppo                                    # a run of the default task into runs/ppo/
    python -m train.train_ppo --out results/ppo_v1               # the committed model of the default task (make train)
    python -m train.train_ppo --timesteps 20000 --out /tmp/ppo   # a short run elsewhere (no warm-up: see below)
    python -m train.train_ppo --resume --timesteps 3000000       # continue runs/ppo/ to 3 M steps in all
    python -m train.train_ppo --env-config '{"action_mode": "platoon"}' --frame-stack 4 --out /tmp/ppo  # a variant

Hyperparameters come from ``hyperparams/ppo.yml`` (rl-zoo3's layout, which rl-zoo3 trains from as it
is: the env id, then ``n_envs``, ``n_timesteps``, ``policy``, ``normalize``, ``frame_stack``,
``env_kwargs`` and PPO's own arguments); ``--timesteps`` and ``--n-envs`` override them. The warm-up,
a project setting rl-zoo3 does not know, comes from ``--warmup`` (default ``hyperparams/ppo_warmup.yml``,
keyed by env id: ``n_timesteps``, ``env_kwargs``): the first ``n_timesteps`` steps of the run train in
that env (a decision every 5 s), then the run switches to ``env_kwargs``, keeping the normalisation
statistics. A run of no more steps than the warm-up (such as ``--timesteps 20000``) trains without
it, and says so; ``--no-warmup`` leaves it out.

**Nothing is lost.** A run never writes into ``--out`` while it trains: it works in a new directory beside
it, ``<out>.partial-<random>`` (a copy of ``--out`` with ``--resume``), where its checkpoints go too, and
moves it to ``--out`` when it has ended, the run that was there deleted only then. Stopped or failed
before that (Ctrl-C, a crash, a full disk), ``--out`` is as it was; the work directory is deleted, or, if
it holds a checkpoint of this run, kept and named (``--resume --out <it>`` continues it). So ``make train``
regenerates the committed runs in place (the default ``--out`` is ``runs/ppo``, never a committed one), and a run into an existing run directory replaces it
only by a finished run. ``--out`` must be absent, empty or a run directory (only the files below): a
directory holding anything else is refused before any work (a finished run replaces the whole
directory), as is ``--out`` naming a file. The run directory holds exactly:

- ``model.zip``: the PPO model, also the checkpoint (replaced every ``--checkpoint-freq``
  steps and at the end; it stores the timestep count, so ``--resume`` continues from it);
- ``vecnormalize.pkl``: ``VecNormalize``'s running statistics, when ``normalize`` is on;
- ``env.json``: the ``gym.make`` keyword arguments of the env as evaluated (its action mode among them), the
  frame stack and ``normalize`` (whether ``vecnormalize.pkl`` belongs to the run; ``timegap_env.agents.protocol``);
- ``curve.csv`` and ``curve.png``: the learning curve, every ``--curve-freq`` steps (0: only at the
  end) and at the end: the deterministic policy's mean return on the check episodes, and the share
  of the oracle gap it captures there, (policy - best blind constant) / (oracle - best blind
  constant), the constant and the oracle (``train.value_of_information``'s) measured once on the
  same episodes; a resumed run continues the curve;
- ``training.md``: command, timesteps, wall time, throughput and returns, written at the end; the share
  of the oracle gap is "n/a" with the reason when the oracle does not beat the best constant there (the
  95 % interval of its gain above 0);
- ``tensorboard/``: TensorBoard's logs (``--tensorboard-log`` puts them elsewhere).

Sub-env i of phase k's env is seeded ``--seed + k * n_envs + i``; all training seeds stay below
``timegap_env.agents.protocol.EVAL_SEED_START`` (10 000), where the evaluation's seeds begin. The check episodes of
the learning curve are ``check_seeds(task)``: 32 episodes seeded from 9000 in v0, 100 from v1 on (whose
collision term needs more), also below 10 000; their references are v0's oracle and best constant there, or, from v1
on, the best blind constant and the full oracle of ``results/task`` (chosen on its training and selection seeds).
A ``--resume`` from a checkpoint or statistics that cannot be read, or that take observations of
another shape or actions of another meaning than the env's, stops with a message naming the file; so do
bad settings (an unknown ``--env-config`` field, a hyperparameter), each before any work, as one line
without a traceback on the command line. Torch runs on one thread (the network is tiny; more threads
fight the simulator for the cores).
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import json
import math
import os
import shlex
import shutil
import sys
import time
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import torch
import yaml
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import VecEnv, VecFrameStack, VecNormalize

from timegap_env.agents.learned import (
    LearnedPolicy, ObservationNormalizer, RunFileError, algorithm_class, load_model, load_vecnormalize,
)
from timegap_env.agents.policies import seconds
from timegap_env.agents.protocol import (
    ALGORITHMS, ENV_FILE, EVAL_SEED_START, MODEL_FILE, VECNORMALIZE_FILE, read_env_file,
)
from timegap_env import DEFAULT_TASK, ENV_ID, TASKS, cli
from timegap_env.config import EnvConfig
from timegap_env.tasks import get_task
from timegap_env.envs.action import action_space
from timegap_env.envs.info import summary_of, truth_of
from timegap_env.envs.observation import MONITOR_FEATURES, feature_columns, observation_space
from timegap_env.envs.sb3 import TimeGapVecEnv
from timegap_env.studies.training import (
    CURVE_COLUMNS, CURVE_FILE, check_seeds, load_hyperparams, with_env_config,
)
from timegap_env.experiments.backends import Backend
from timegap_env.experiments.stats import bootstrap_mean
from timegap_env.studies.task_map import WEIGHTINGS, Plan, choose_references
from timegap_env.studies.value import DEFAULT_TRAIN_EPISODES, all_oracles, choose_oracle, constants, measure_lookup, run

REPORT_FILE = "training.md"
CURVE_FIGURE = "curve.png"
TENSORBOARD_DIR = "tensorboard"  # TensorBoard's logs in the run directory, unless --tensorboard-log
RUN_CONTENTS = {MODEL_FILE, VECNORMALIZE_FILE, ENV_FILE, REPORT_FILE, CURVE_FILE, CURVE_FIGURE, TENSORBOARD_DIR}
WARMUP_KEYS = {"n_timesteps", "env_kwargs"}  # of the warm-up file's env section
SUMMARY_KEYS = {"collision", "mean_setting", "switches", "time_out_of_control"}  # logged per episode


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="python -m train.train_ppo", description=__doc__.split("\n")[0])
    parser.add_argument("--algo", default="ppo", choices=list(ALGORITHMS),
                        help="ppo (stable-baselines3) or ppo_lstm (sb3-contrib's RecurrentPPO); the default "
                             "--hyperparams is hyperparams/<algo>.yml (default: %(default)s)")
    parser.add_argument("--env-id", default=DEFAULT_TASK, choices=list(TASKS),
                        help="the env, and the section of --hyperparams and --warmup to read (default: %(default)s)")
    parser.add_argument("--timesteps", type=cli.count, default=None,
                        help="total environment steps of the run, warm-up included (default: n_timesteps of the yml)")
    parser.add_argument("--seed", type=int, default=0,
                        help="seed of PyTorch and the envs; phase k's sub-env i gets seed + k n_envs + i (default: 0)")
    parser.add_argument("--n-envs", type=cli.count, default=None,
                        help="platoons stepped together (default: n_envs of the yml)")
    parser.add_argument("--env-config", type=cli.json_object, action="append", default=[],
                        help="EnvConfig overrides as JSON, merged into the config of env_kwargs and of the warm-up's; "
                             "repeatable, later top-level fields replacing earlier ones (default: none), e.g. "
                             "'{\"action_mode\": \"platoon\"}'")
    parser.add_argument("--hide-features", nargs="+", default=[], metavar="FEATURE",
                        help="observation features the policy never sees (read as 0; an ablation): names of "
                             "timegap_env.envs.observation.FEATURES, or 'monitor' for the monitor's six (default: none)")
    parser.add_argument("--cost-budget", type=float, default=None,
                        help="constrained PPO: the mean step cost (info['cost']) allowed; a Lagrange multiplier on the "
                             "cost, raised by dual ascent while the cost exceeds it (default: unconstrained)")
    parser.add_argument("--collision-budget", type=float, default=None,
                        help="constrained PPO on safety alone: the collisions per training episode allowed; a Lagrange "
                             "multiplier taken off the reward of each step that ends an episode in a collision, raised "
                             "by dual ascent while the rollout's collision rate exceeds it (default: unconstrained)")
    parser.add_argument("--lagrange-rate", type=float, default=1.0,
                        help="the multipliers' step per unit of cost (or collision rate) over the budget, per rollout "
                             "(default: %(default)s)")
    parser.add_argument("--frame-stack", type=cli.count, default=None,
                        help="observations the policy reads at once (default: frame_stack of the yml, else 1)")
    parser.add_argument("--hyperparams", type=Path, default=None,
                        help="rl-zoo3-style yml keyed by env id (default: hyperparams/<algo>.yml)")
    parser.add_argument("--warmup", type=Path, default=Path("hyperparams/ppo_warmup.yml"),
                        help="yml keyed by env id: the warm-up's n_timesteps and env_kwargs (default: %(default)s)")
    parser.add_argument("--no-warmup", dest="warmup", action="store_const", const=None,
                        help="train in env_kwargs from the start")
    parser.add_argument("--out", type=Path, default=Path("runs/ppo"),
                        help="run directory: model.zip, vecnormalize.pkl, training.md, ...; written when the run ends, "
                             "replacing a run there (default: %(default)s)")
    parser.add_argument("--resume", action="store_true",
                        help="continue from <out>/model.zip (and its VecNormalize stats) up to --timesteps in all")
    parser.add_argument("--checkpoint-freq", type=cli.count, default=100_000,
                        help="replace <out>/model.zip and vecnormalize.pkl every so many steps (default: %(default)s)")
    parser.add_argument("--curve-freq", type=int, default=100_000,
                        help="a point of the learning curve every so many steps, 0: none (default: %(default)s)")
    parser.add_argument("--tensorboard-log", type=Path, default=None,
                        help=f"TensorBoard log directory (default: <out>/{TENSORBOARD_DIR})")
    parser.add_argument("--progress-bar", action=argparse.BooleanOptionalAction, default=True,
                        help="show SB3's progress bar (default: on)")
    args = parser.parse_args(argv)
    args.env_config = {field: value for overrides in args.env_config for field, value in overrides.items()}
    if args.hyperparams is None:
        args.hyperparams = Path(f"hyperparams/{args.algo}.yml")
    return args


def load_warmup(path: Path, env_id: str = DEFAULT_TASK) -> tuple[int, dict[str, Any]]:
    """The warm-up in ``path``'s ``env_id`` section: its steps and its env's gym.make keyword arguments."""
    with open(path) as file:
        document = yaml.safe_load(file)
    if not isinstance(document, dict) or not isinstance(document.get(env_id), dict):
        raise ValueError(f"warmup = {str(path)!r}: needs a top-level key {env_id!r} holding {sorted(WARMUP_KEYS)}")
    warmup = document[env_id]
    if set(warmup) != WARMUP_KEYS:
        raise ValueError(f"warmup {env_id} = {warmup!r} in {path}: needs exactly the keys {sorted(WARMUP_KEYS)}")
    steps, env_kwargs = warmup["n_timesteps"], warmup["env_kwargs"]
    if (isinstance(steps, bool) or not isinstance(steps, (int, float)) or not math.isfinite(steps) or steps != int(steps)
            or steps < 1):
        raise ValueError(f"warmup {env_id}.n_timesteps = {steps!r} in {path}: must be an integer >= 1")
    if not isinstance(env_kwargs, dict):
        raise ValueError(f"warmup {env_id}.env_kwargs = {env_kwargs!r} in {path}: must be a mapping")
    return int(steps), env_kwargs


def save_run(model: BaseAlgorithm, out: Path) -> None:
    """Write model.zip (and vecnormalize.pkl) in ``out``, each replaced atomically."""
    model.save(out / f"{MODEL_FILE}.tmp.zip")
    os.replace(out / f"{MODEL_FILE}.tmp.zip", out / MODEL_FILE)
    if model.get_vec_normalize_env() is not None:
        model.get_vec_normalize_env().save(out / f"{VECNORMALIZE_FILE}.tmp")
        os.replace(out / f"{VECNORMALIZE_FILE}.tmp", out / VECNORMALIZE_FILE)


class Checkpoint(BaseCallback):
    """Replace the run's model.zip and vecnormalize.pkl every ``every`` environment steps."""

    def __init__(self, every: int, out: Path) -> None:
        super().__init__()
        self.every, self.out = every, out
        self.last = 0  # timestep count of the last checkpoint (or of the phase's start)
        self.saved_at: int | None = None  # timestep count of the last checkpoint written; None: none yet

    def _on_training_start(self) -> None:
        self.last = self.num_timesteps

    def _on_step(self) -> bool:
        if self.every and self.num_timesteps - self.last >= self.every:
            save_run(self.model, self.out)
            self.last = self.saved_at = self.num_timesteps
        return True


class EpisodeSummaries(BaseCallback):
    """Log the summaries of finished episodes (``episode_<name>`` in their info) to TensorBoard (``episode/<name>``,
    mean per rollout)."""

    def _on_step(self) -> bool:
        for info in self.locals["infos"]:
            summary = summary_of(info)
            for name in SUMMARY_KEYS & summary.keys():
                self.logger.record_mean(f"episode/{name}", float(summary[name]))
        return True


class DualAscent(BaseCallback):
    """A Lagrange multiplier raised by dual ascent: after every rollout :meth:`ascend` sets ``multiplier`` <-
    max(0, multiplier + ``rate`` (what the rollout measured - ``budget``)); a subclass measures and applies it."""

    def __init__(self, budget: float, rate: float) -> None:
        super().__init__()
        self.budget, self.rate = budget, rate
        self.multiplier = 0.0

    def ascend(self, measured: float) -> None:
        self.multiplier = max(0.0, self.multiplier + self.rate * (measured - self.budget))


class LagrangeMultiplier(DualAscent):
    """Constrained PPO on the env's step cost (``info["cost"]``'s, reward.COST_TERMS): the rewards PPO learns from
    are the env's minus ``multiplier`` times the cost, the multiplier ascending on the rollout's mean cost per step;
    logged as ``lagrange/*``."""

    def __init__(self, budget: float, rate: float) -> None:
        super().__init__(budget, rate)
        self.cost_sum, self.steps = 0.0, 0

    def adapter(self) -> TimeGapVecEnv:
        adapter = self.training_env.unwrapped
        assert isinstance(adapter, TimeGapVecEnv)  # train_ppo trains in one
        return adapter

    def _on_training_start(self) -> None:
        self.adapter().cost_weight = self.multiplier  # a new phase's env starts where the last one's ended

    def _on_rollout_start(self) -> None:
        self.cost_sum, self.steps = 0.0, 0

    def _on_step(self) -> bool:
        cost = self.adapter().venv.step_cost
        self.cost_sum, self.steps = self.cost_sum + float(cost.sum()), self.steps + cost.size
        return True

    def _on_rollout_end(self) -> None:
        mean_cost = self.cost_sum / max(self.steps, 1)
        self.ascend(mean_cost)
        self.adapter().cost_weight = self.multiplier
        self.logger.record("lagrange/mean_cost", mean_cost)
        self.logger.record("lagrange/multiplier", self.multiplier)


class CollisionBudget(DualAscent):
    """Constrained PPO on the collision rate: ``multiplier`` is taken off the reward PPO learns from (after
    VecNormalize's scaling: in its units) on each step that ends an episode in a collision, the multiplier ascending
    on the rollout's collisions per ended episode; the env's own collision term stays in the reward. Logged as
    ``collision_budget/*``."""

    def __init__(self, budget: float, rate: float) -> None:
        super().__init__(budget, rate)
        self.collisions, self.episodes = 0, 0

    def _on_rollout_start(self) -> None:
        self.collisions, self.episodes = 0, 0

    def _on_step(self) -> bool:
        rewards, infos = self.locals["rewards"], self.locals["infos"]  # rewards: the array the rollout buffer stores
        for i in np.flatnonzero(self.locals["dones"]):
            self.episodes += 1
            if summary_of(infos[i]).get("collision"):
                self.collisions += 1
                rewards[i] -= self.multiplier
        return True

    def _on_rollout_end(self) -> None:
        if self.episodes:
            rate = self.collisions / self.episodes
            self.ascend(rate)
            self.logger.record("collision_budget/collision_rate", rate)
        self.logger.record("collision_budget/multiplier", self.multiplier)


@dataclasses.dataclass(frozen=True)
class CurveReference:
    """What the learning curve compares with, on the check episodes (seeds ``seeds``)."""

    seeds: list[int]
    blind_setting: float  # the best constant setting there [s]
    blind_return: float  # its mean return
    oracle: str  # the oracle's name
    oracle_return: float  # its mean return
    gap_interval: tuple[float, float]  # the 95 % bootstrap interval of the oracle's mean gain over the constant there

    @classmethod
    def measure(cls, config: EnvConfig, task_id: str) -> CurveReference:
        """The best constant and the oracle on the check episodes (``check_seeds(task_id)``) in ``config``'s env
        (one setting for the platoon). v0: the constant best on those episodes and the oracle
        train.value_of_information chooses; later tasks: the best blind constant and the full oracle of
        ``results/task`` (``choose_references``: tables on its training seeds, choices on its selection seeds)."""
        platoon = config.with_overrides({"action_mode": "platoon"})
        seeds = check_seeds(task_id)
        fixed = constants(platoon, seeds)["return"]  # (episodes, levels)
        if task_id == ENV_ID:
            table, _ = measure_lookup(platoon, DEFAULT_TRAIN_EPISODES)
            oracle = choose_oracle(platoon, all_oracles(platoon, table))
            best = int(np.argmax(fixed.mean(axis=0)))
        else:
            train, selection, _ = Plan().seeds()
            weighting = get_task(task_id).overrides["reward_weights"]
            chosen = choose_references(platoon, {weighting: WEIGHTINGS[weighting]}, train, selection, Backend())
            oracle, best = chosen[weighting].full_oracle, chosen[weighting].blind
        oracle_returns = run(platoon, seeds, lambda obs, infos: oracle.act(truth_of(infos)))["return"]
        _, low, high = bootstrap_mean(oracle_returns - fixed[:, best])
        return cls(seeds, float(platoon.setting_levels[best]), float(fixed[:, best].mean()), oracle.name,
                   float(oracle_returns.mean()), (low, high))

    def share(self, policy_return: float) -> float:
        """The share of the oracle gap captured: (policy - blind) / (oracle - blind) [-]; NaN unless the oracle beats
        the best blind constant there, its interval above 0 (no gap to capture, or one too small to divide by)."""
        gap = self.oracle_return - self.blind_return
        return (policy_return - self.blind_return) / gap if self.gap_interval[0] > 0 else math.nan


class LearningCurve(BaseCallback):
    """Every ``every`` steps (and at the end), the deterministic policy's mean return on the reference's episodes in
    ``config``'s env; written to ``out``'s curve.csv and curve.png each time."""

    def __init__(self, every: int, config: EnvConfig, reference: CurveReference, out: Path,
                 points: list[tuple[int, float]], frame_stack: int,
                 hidden_features: tuple[str, ...] = ()) -> None:  # every = 0: only when add_point is called
        super().__init__()
        self.every, self.config, self.reference, self.out = every, config, reference, out
        self.frame_stack, self.hidden_features = frame_stack, hidden_features
        self.points = points  # (timesteps, mean return), shared across the phases of a run
        self.last = 0

    def _on_training_start(self) -> None:
        self.last = self.num_timesteps

    def _on_step(self) -> bool:
        if self.every and self.num_timesteps - self.last >= self.every:
            self.add_point()
            self.last = self.num_timesteps
        return True

    def add_point(self) -> None:
        """Measure the policy now and rewrite the curve's files."""
        statistics = self.model.get_vec_normalize_env()
        policy = LearnedPolicy(self.model, ObservationNormalizer.of(statistics) if statistics else None,
                               action_mode=self.config.action_mode, frame_stack=self.frame_stack,
                               hidden_features=self.hidden_features)
        state = None  # the frame stack, carried from step to step; every episode starts together

        def choose(obs: np.ndarray, infos: dict[str, Any]) -> np.ndarray:
            nonlocal state
            action, state = policy.predict(obs, state=state, deterministic=True)
            return action

        result = run(self.config, self.reference.seeds, choose)
        self.points.append((self.model.num_timesteps, float(result["return"].mean())))
        write_curve(self.points, self.reference, self.out)


def write_curve(points: list[tuple[int, float]], reference: CurveReference, out: Path) -> None:
    """curve.csv (timesteps, mean return, share of the oracle gap; the best blind constant's and the oracle's mean
    returns on the same episodes) and curve.png."""
    with open(out / CURVE_FILE, "w", newline="") as file:
        writer = csv.writer(file)
        writer.writerow(CURVE_COLUMNS)
        writer.writerows([(steps, f"{value:.4f}", f"{reference.share(value):.4f}", f"{reference.blind_return:.4f}",
                           f"{reference.oracle_return:.4f}") for steps, value in points])
    steps, values = np.array([p[0] for p in points]), np.array([p[1] for p in points])
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
    top.plot(steps, values, "o-", ms=3, label="PPO, deterministic")
    top.axhline(reference.blind_return, color="C1", ls="--", label=f"best blind constant ({seconds(reference.blind_setting)} s)")
    top.axhline(reference.oracle_return, color="C2", ls=":", label=f"oracle ({reference.oracle})")
    top.set_ylabel(f"mean return, {len(reference.seeds)} episodes")
    top.legend(fontsize=8)
    bottom.plot(steps, [reference.share(v) for v in values], "o-", ms=3)
    bottom.axhline(0.0, color="C1", ls="--")
    bottom.axhline(1.0, color="C2", ls=":")
    bottom.set_ylabel("share of the oracle gap")
    bottom.set_xlabel("timesteps")
    for ax in (top, bottom):
        ax.grid(alpha=0.3)
    fig.suptitle(f"Learning curve on the check episodes (seeds {reference.seeds[0]}-{reference.seeds[-1]})", fontsize=10)
    fig.tight_layout()
    fig.savefig(out / CURVE_FIGURE, dpi=110)
    plt.close(fig)


def check_out(out: Path, resume: bool) -> None:
    """Before any work: ``out`` must be a directory to resume from (``--resume``), or absent, empty or one holding
    only a run's files (``RUN_CONTENTS``), which this run replaces when it ends; anything else is refused."""
    cli.output_dir(out)
    if resume or not out.is_dir():
        return
    foreign = sorted(path.name for path in out.iterdir() if path.name not in RUN_CONTENTS)
    if foreign:
        raise ValueError(f"--out {out}: holds {foreign[:5]}{' ...' if len(foreign) > 5 else ''}, not only a "
                         f"training run's files ({', '.join(sorted(RUN_CONTENTS))}); a run replaces the whole "
                         "directory when it ends, so give a new directory (or one holding a run)")


def check_config(env_kwargs: dict[str, Any], source: str, overrides: dict[str, Any], task_id: str) -> EnvConfig:
    """``env_kwargs``' config over task ``task_id``'s, as an EnvConfig; a ValueError naming where it came from (and
    the field) if it is not one."""
    try:
        return get_task(task_id).config(env_kwargs.get("config"))
    except ValueError as error:
        given = f"--env-config {json.dumps(overrides)} merged into {source}" if overrides else source
        raise ValueError(f"{given}: {error}") from error


def read_curve(path: Path) -> list[tuple[int, float]]:
    """The (timesteps, mean return) points of a curve.csv; RunFileError naming it if it cannot be read."""
    try:
        with open(path, newline="") as file:
            return [(int(row["timesteps"]), float(row["mean_return"])) for row in csv.DictReader(file)]
    except (OSError, UnicodeDecodeError, csv.Error, KeyError, TypeError, ValueError) as error:
        raise RunFileError(f"{path}: not a learning curve of train_ppo ({type(error).__name__}: {error})") from error


def share_text(reference: CurveReference, learned: float) -> str:
    """The share of the oracle gap captured for training.md, or why there is none."""
    share = reference.share(learned)
    if math.isfinite(share):
        return f"{share:.2f}"
    low, high = reference.gap_interval
    return (f"n/a: the oracle ({reference.oracle_return:.1f}) does not measurably beat the best constant "
            f"({reference.blind_return:.1f}) on these episodes, its gain's interval [{low:.1f}, {high:.1f}] not above 0, "
            "so there is no gap to capture")


def main(argv: list[str] | None = None) -> None:
    started = time.perf_counter()
    args = parse_args(argv)
    if args.cost_budget is not None and not (math.isfinite(args.cost_budget) and args.cost_budget >= 0):
        raise ValueError(f"cost_budget = {args.cost_budget}: must be a finite number >= 0")
    if not (math.isfinite(args.lagrange_rate) and args.lagrange_rate > 0):
        raise ValueError(f"lagrange_rate = {args.lagrange_rate}: must be a finite number > 0")
    if args.collision_budget is not None and not (math.isfinite(args.collision_budget) and 0 <= args.collision_budget <= 1):
        raise ValueError(f"collision_budget = {args.collision_budget}: must be a number in [0, 1] (collisions per episode)")
    lagrange = LagrangeMultiplier(args.cost_budget, args.lagrange_rate) if args.cost_budget is not None else None
    collision_budget = (CollisionBudget(args.collision_budget, args.lagrange_rate)
                        if args.collision_budget is not None else None)
    hidden_features = tuple(dict.fromkeys(feature for name in args.hide_features
                                          for feature in (MONITOR_FEATURES if name == "monitor" else (name,))))
    feature_columns(hidden_features)
    algorithm = algorithm_class(args.algo)
    hyperparams = load_hyperparams(args.hyperparams, args.env_id, algorithm)  # what is left after the pops goes to it
    n_envs = args.n_envs or int(hyperparams["n_envs"])
    total_timesteps = args.timesteps or int(hyperparams["n_timesteps"])
    del hyperparams["n_envs"], hyperparams["n_timesteps"]
    policy = hyperparams.pop("policy")
    normalize = hyperparams.pop("normalize", False)
    frame_stack = hyperparams.pop("frame_stack", 1) if args.frame_stack is None else args.frame_stack
    env_kwargs = with_env_config(hyperparams.pop("env_kwargs", None) or {}, args.env_config)
    warmup = load_warmup(args.warmup, args.env_id) if args.warmup is not None else None
    if warmup is not None and warmup[0] >= total_timesteps:
        print(f"note: timesteps = {total_timesteps} is no more than the warm-up's {warmup[0]} ({args.warmup}): "
              "the run trains without a warm-up")
        warmup = None
    # Phases (end [total steps], env_kwargs): the warm-up's coarser decisions, then the env as evaluated.
    phases = [(warmup[0], with_env_config(warmup[1], args.env_config))] if warmup else []
    phases.append((total_timesteps, env_kwargs))
    if n_envs < 1:
        raise ValueError(f"n_envs = {n_envs}: must be >= 1")
    if total_timesteps < 1:
        raise ValueError(f"timesteps = {total_timesteps}: must be >= 1")
    if args.curve_freq < 0:
        raise ValueError(f"curve_freq = {args.curve_freq}: must be >= 0 (0: no learning curve)")
    if args.checkpoint_freq < 1:
        raise ValueError(f"checkpoint_freq = {args.checkpoint_freq}: must be >= 1")
    if not 0 <= args.seed <= EVAL_SEED_START - len(phases) * n_envs:
        raise ValueError(f"seed = {args.seed}: sub-env seeds seed .. seed + {len(phases) * n_envs - 1} "
                         f"must lie in [0, {EVAL_SEED_START})")
    if isinstance(frame_stack, bool) or not isinstance(frame_stack, int) or frame_stack < 1:
        raise ValueError(f"hyperparams {args.env_id}.frame_stack = {frame_stack!r}: must be an integer >= 1")
    if args.algo == "ppo_lstm" and frame_stack != 1:
        raise ValueError(f"frame_stack = {frame_stack} with --algo ppo_lstm: a recurrent policy reads one observation "
                         "at a time")
    if not isinstance(normalize, (bool, dict)):
        raise ValueError(f"hyperparams {args.env_id}.normalize = {normalize!r}: "
                         "must be true, false or a dict of VecNormalize arguments")
    evaluated = check_config(env_kwargs, f"{args.hyperparams} env_kwargs", args.env_config, args.env_id)
    if warmup:
        check_config(phases[0][1], f"{args.warmup} env_kwargs (the warm-up)", args.env_config, args.env_id)
    check_out(args.out, args.resume)
    # One thread: the network is tiny, the 2 cores are better left to the env (two threads measured 7x slower).
    torch.set_num_threads(1)

    # ---------------------------------------------------------------- model
    model_path, stats_path = args.out / MODEL_FILE, args.out / VECNORMALIZE_FILE
    model: BaseAlgorithm | None = None
    saved_statistics: VecNormalize | None = None  # --resume's, given the first phase's env below
    curve: list[tuple[int, float]] = []  # (timesteps, mean return) of the learning curve, a resumed run's first
    if args.resume:  # every file checked before anything is written
        if not model_path.is_file():
            raise FileNotFoundError(f"--resume: no checkpoint {model_path}")
        if lagrange is not None or collision_budget is not None:
            raise ValueError("--resume with --cost-budget or --collision-budget: the Lagrange multiplier is not saved "
                             "with the checkpoint; train a constrained run in one go")
        if normalize and not stats_path.is_file():
            raise FileNotFoundError(f"--resume with normalize = {normalize!r}: no statistics {stats_path}")
        if not normalize and stats_path.is_file():
            raise ValueError(f"--resume with normalize = {normalize!r}: {stats_path} says the run normalised its "
                             f"observations; resume with the hyperparameters it was trained with")
        model = load_model(model_path, algorithm, device="cpu")
        saved = read_env_file(args.out / ENV_FILE)
        for what, was, now in (("--env-id", saved.env_id, args.env_id), ("--algo", saved.algo, args.algo),
                               ("--hide-features", list(saved.hidden_features), list(hidden_features))):
            if was != now:
                raise ValueError(f"--resume: {what} {now!r}, but {args.out / ENV_FILE} says the run was trained with "
                                 f"{was!r}; resume it as it was trained")
        model.set_random_seed(args.seed)
        if model.num_timesteps >= total_timesteps:
            raise ValueError(f"--resume: {model_path} has trained {model.num_timesteps} steps, "
                             f"already >= timesteps = {total_timesteps}")
        if model.n_envs != n_envs:
            raise ValueError(f"--resume: n_envs = {n_envs}, but {model_path} was trained with {model.n_envs}")
        *batch, width = observation_space(evaluated).shape
        if model.observation_space.shape != (*batch, width * frame_stack):
            raise RunFileError(f"--resume: {model_path} takes observations of shape {model.observation_space.shape}, "
                               f"the env gives {(*batch, width)} with frame_stack = {frame_stack}")
        if model.action_space != action_space(evaluated):
            raise RunFileError(f"--resume: {model_path} has actions {model.action_space}, the env (action_mode = "
                               f"{evaluated.action_mode!r}) {action_space(evaluated)}")
        if normalize:
            saved_statistics = load_vecnormalize(stats_path)
            if saved_statistics.observation_space.shape != (*batch, width):
                raise RunFileError(f"--resume: {stats_path} normalises observations of shape "
                                   f"{saved_statistics.observation_space.shape}, the env gives {(*batch, width)}")
        if (args.out / CURVE_FILE).is_file():
            curve = read_curve(args.out / CURVE_FILE)
    elif args.out.is_dir() and any(args.out.iterdir()):
        print(f"note: --out {args.out} holds a run; this run replaces it when it ends (until then it stays whole)")
    steps_before = model.num_timesteps if model else 0

    # ---------------------------------------------------------------- train, phase by phase, in a work directory
    work = cli.work_directory(args.out, copy=args.resume)
    tensorboard = args.tensorboard_log if args.tensorboard_log is not None else work / TENSORBOARD_DIR
    shown_tensorboard = args.tensorboard_log if args.tensorboard_log is not None else args.out / TENSORBOARD_DIR
    checkpoint = Checkpoint(args.checkpoint_freq, work)
    env: VecEnv | None = None  # the phase's env, normalised; the model steps it through VecFrameStack if frame_stack > 1
    try:
        (work / ENV_FILE).write_text(json.dumps({"env_kwargs": env_kwargs, "frame_stack": frame_stack,
                                                 "normalize": bool(normalize), "env_id": args.env_id,
                                                 "hidden_features": list(hidden_features), "algo": args.algo},
                                                indent=1, sort_keys=True) + "\n")
        if model is not None:
            model.tensorboard_log = str(tensorboard)
        reference = CurveReference.measure(evaluated, args.env_id)
        timings: list[tuple[str, int, float]] = []  # (phase, steps, seconds)
        for phase, (phase_end, phase_env_kwargs) in enumerate(phases):
            if model is not None and model.num_timesteps >= phase_end:
                continue
            phase_env: VecEnv = TimeGapVecEnv(n_envs, **phase_env_kwargs, task_id=args.env_id,
                                              hidden_features=hidden_features)
            if saved_statistics is not None and env is None:
                saved_statistics.set_venv(phase_env)
                phase_env = saved_statistics
            elif normalize:
                phase_env = VecNormalize(phase_env, gamma=model.gamma if model else hyperparams.get("gamma", 0.99),
                                         **({} if normalize is True else normalize))
                if isinstance(env, VecNormalize):  # features and per-step rewards (means over ticks) keep their scale
                    phase_env.obs_rms, phase_env.ret_rms = env.obs_rms.copy(), env.ret_rms.copy()
            if env is not None:
                env.close()
            env = phase_env
            stepped = VecFrameStack(env, frame_stack) if frame_stack > 1 else env
            if model is None:
                model = algorithm(policy, stepped, seed=args.seed, device="cpu", tensorboard_log=str(tensorboard),
                                  **hyperparams)
            else:
                model.set_env(stepped)
            stepped.seed(args.seed + phase * n_envs)
            phase_start, clock = model.num_timesteps, time.perf_counter()
            callbacks = [checkpoint, EpisodeSummaries(),
                         LearningCurve(args.curve_freq, evaluated, reference, work, curve, frame_stack, hidden_features),
                         *([lagrange] if lagrange else []), *([collision_budget] if collision_budget else [])]
            model.learn(
                total_timesteps=phase_end - model.num_timesteps,
                callback=callbacks,
                tb_log_name="ppo",
                reset_num_timesteps=not args.resume and not timings,
                progress_bar=args.progress_bar,
            )
            label = f"warm-up, {phase_env_kwargs}" if phase < len(phases) - 1 else "main"
            timings.append((label, model.num_timesteps - phase_start, time.perf_counter() - clock))
        assert model is not None and env is not None  # the last phase always trains: total_timesteps > steps_before
        save_run(model, work)
        checkpoint.saved_at = model.num_timesteps  # the finished model: whatever fails from here on keeps it
        final = LearningCurve(args.curve_freq, evaluated, reference, work, curve, frame_stack, hidden_features)
        final.init_callback(model)
        final.add_point()  # the end of the run

        # ------------------------------------------------------------ check and report
        learned = curve[-1][1]
        episodes = [info["r"] for info in model.ep_info_buffer]
        final_return = f"{np.mean(episodes):.1f}" if episodes else "n/a (no episode ended)"
        command = shlex.join(["python", "-m", "train.train_ppo", *(sys.argv[1:] if argv is None else argv)])
        phase_rows = "\n".join(f"| {label}: steps, time, throughput | {steps:,}, {seconds:.0f} s, "
                               f"{steps / seconds:,.0f} steps/s |" for label, steps, seconds in timings)
        files = ", ".join(f"`{name}`" for name in (MODEL_FILE, ENV_FILE, CURVE_FILE, CURVE_FIGURE)) + (
            f", `{VECNORMALIZE_FILE}`" if isinstance(env, VecNormalize) else "")
        lagrange_row = "" if lagrange is None else (
            f"\n| constrained: mean step cost budget, rate; the multiplier at the end | {lagrange.budget:g}, "
            f"{lagrange.rate:g}; {lagrange.multiplier:.3f} |")
        lagrange_row += "" if collision_budget is None else (
            f"\n| constrained: collisions per episode budget, rate; the multiplier at the end | "
            f"{collision_budget.budget:g}, {collision_budget.rate:g}; {collision_budget.multiplier:.3f} |")
        hidden_row = f"\n| hidden features (read as 0) | {', '.join(hidden_features)} |" if hidden_features else ""
        report = f"""# {type(model).__name__} on {args.env_id}

Command: `{command}` ({f"resumed from a checkpoint at {steps_before:,} steps" if args.resume else "fresh run"})

| | |
|---|---|
| timesteps, this command / total | {model.num_timesteps - steps_before:,} / {model.num_timesteps:,} |
| platoons (n_envs), seed | {n_envs}, {args.seed} (phase k, sub-env i: seed + k n_envs + i) |
| hyperparameters, warm-up | `{args.hyperparams}`, {f"`{args.warmup}`" if warmup else "none"} |
| wall time, whole command after imports | {time.perf_counter() - started:.0f} s |
{phase_rows}{lagrange_row}{hidden_row}
| final mean episode return, last {len(episodes)} training episodes (stochastic policy) | {final_return} |
| mean return, deterministic policy, {len(reference.seeds)} episodes seeded {reference.seeds[0]}+ | {learned:.1f} |
| mean return, best constant ({seconds(reference.blind_setting)} s), same episodes | {reference.blind_return:.1f} |
| mean return, oracle ({reference.oracle}), same episodes | {reference.oracle_return:.1f} |
| share of the oracle gap captured | {share_text(reference, learned)} |

Files: {files}, this report; TensorBoard logs in `{shown_tensorboard}/`.
"""
        (work / REPORT_FILE).write_text(report)
        env.close()
        cli.publish(work, args.out)
    except BaseException:  # interrupted or failed: args.out stays as it was, unless publish got as far as moving it
        if env is not None:
            env.close()
        if not work.exists():
            print(f"train_ppo: the run was published to --out {args.out} before it stopped", file=sys.stderr)
        elif checkpoint.saved_at is not None:
            print(f"train_ppo: stopped; --out {args.out} is unchanged. This run's checkpoint at "
                  f"{checkpoint.saved_at:,} steps is in {work}: to continue it, move it to --out's place (replacing "
                  f"the run there) and run again with --resume --out {args.out}; or delete it", file=sys.stderr)
        else:
            shutil.rmtree(work, ignore_errors=True)
        raise
    print(report)


if __name__ == "__main__":
    cli.run(main, "python -m train.train_ppo")
