"""Train PPO (Ray RLlib, new API stack) on the default task (``timegap_env.DEFAULT_TASK``) with several env runners,
each a native vector env. (The committed run, ``results/v0/rllib``, learned ``TimeGapMonitor-v0`` with an earlier
version of this script.)

    python -m train.train_rllib                                   # a run into runs/rllib/ (Ray here)
    python -m train.train_rllib --timesteps 50000 --out /tmp/rllib  # a short run elsewhere
    python -m train.train_rllib --address auto --env-runners 16   # join a running Ray cluster
    python -m train.train_rllib --select-scale 1 1/30 0.02        # choose the reward scale (v0's: results/v0/rllib)

Ray starts on this machine (``ray.init()``) unless ``--address`` names a cluster to join (e.g. ``auto`` or
``ray://head:10001``); there the runners get this repository's code as Ray's ``working_dir``. Each of the
``--env-runners`` runners is a Ray actor of one CPU stepping ``--envs-per-runner`` platoons in one native
vector env (next-step autoreset, as RLlib assumes); the learner updates in this process. Ray comes with the
``ray`` extra (``pip install -e '.[ray]'``; ``.venv-clients`` has it).

The env and PPO's hyperparameters come from ``hyperparams/ppo.yml`` (``--hyperparams``), the SB3 run's,
mapped where RLlib has a counterpart (``MAPPED``): env_kwargs -> env_config, gamma, gae_lambda -> lambda_,
learning_rate -> lr, clip_range -> clip_param, ent_coef -> entropy_coeff, batch_size -> minibatch_size,
n_epochs -> num_epochs, n_steps -> rollout_fragment_length with a train batch of runners x envs x n_steps
(n_envs x n_steps when runners x envs = n_envs, the default), policy_kwargs' net_arch -> two separate
tanh MLPs (fcnet_hiddens, vf_share_layers off), normalize -> the rewards times ``REWARD_SCALE`` (RLlib's new
API stack has no running reward normalisation like SB3's VecNormalize; the observations are already scaled
to [-1, 1] and go in as they are; ``--reward-scale`` sets another). RLlib's own settings, set to what SB3's PPO
does, are in ``RLLIB_OWN``.
The SB3 run's warm-up (hyperparams/ppo_warmup.yml) is not repeated. ``--timesteps`` defaults to
``DEFAULT_TIMESTEPS``, 1 M env steps, about 2-3 minutes on this 2-core machine: half the SB3 run's 2 M.

Runner w (1, 2, ...) steps platoons seeded (seed + w) x envs-per-runner + i, i < envs-per-runner (RLlib
seeds runner w's vector env with seed + w; ``ForRLlib`` spreads that over its platoons), so runners never
share a platoon's stream; all below ``timegap_env.agents.protocol.EVAL_SEED_START``, where the evaluation's seeds begin.

``--select-scale`` chooses the reward scale: it trains one run per candidate (the same seed, steps and
settings), scores each run's deterministic policy on the task's check episodes (``timegap_env.tasks.Seeds.check``: 100
episodes seeded 9000-9099 in v1, below the held-out seeds, in the env trained in) and writes
``selection.md`` to ``--out``: the candidates' returns there and the one with the highest mean, which
``REWARD_SCALE`` is set to. It keeps no checkpoint and runs no held-out episode; the runners' platoons must be
seeded below the check episodes'.

``--out`` (default ``runs/rllib``) receives ``checkpoint/`` (RLlib's ``algo.save``, the env's
``env.json`` added), which ``timegap_env.agents.rllib_policy.RLlibPolicy.load`` reads, and ``training.md``: the
command, every iteration (env steps, episodes ended and their mean return, time, throughput), the wall time,
the policy's mean return on the check episodes and, unless ``--eval-episodes 0``, on the default task's
held-out episodes beside the paper's rule and the fixed 1.2 s setting (the benchmark compares it in full). The run writes into
``<out>.partial-<random>`` (a copy of ``--out``, so its ``selection.md`` stays) and replaces ``--out`` only when
it has ended: stopped or failed before, it leaves ``--out`` as it was.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import shlex
import shutil
import sys
import tempfile
import time
from fractions import Fraction
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from timegap_env.agents.protocol import ENV_FILE, EVAL_SEED_START
from timegap_env.agents.rllib_policy import CHECKPOINT_DIR, RLlibPolicy
from timegap_env import DEFAULT_TASK, cli
from timegap_env.tasks import CHECK_SEED_START, get_task
from timegap_env.experiments.backends import runtime_env

QUALIFIED_ID = f"timegap_env:{DEFAULT_TASK}"  # gymnasium imports timegap_env, which registers the id, in any process
RLLIB_ENV = "timegap_rllib"  # RLlib's name of make_env
REPORT_FILE = "training.md"
SELECTION_FILE = "selection.md"  # --select-scale's report
DEFAULT_TIMESTEPS = 1_000_000  # about 2-3 min on this 2-core machine, half the SB3 run's 2 M [env steps]
DEFAULT_ENV_RUNNERS = 2  # one per core of this machine
EVAL_POLICIES = ("rule_platoon", "fixed_1.2")  # the paper's rule (the reference) and the default task's best constant
DEFAULT_EVAL_EPISODES = 1_000  # held-out episodes of the report's check (the benchmark's own are sized by power)
MAPPED = {  # ppo.yml's PPO key -> PPOConfig.training's; the keys of UNMAPPED: see Settings.from_args
    "gamma": "gamma",
    "gae_lambda": "lambda_",
    "learning_rate": "lr",
    "clip_range": "clip_param",
    "ent_coef": "entropy_coeff",
    "batch_size": "minibatch_size",
    "n_epochs": "num_epochs",
}
UNMAPPED = {"n_envs", "n_steps", "n_timesteps", "policy", "normalize", "policy_kwargs", "env_kwargs"}  # read apart;
# n_timesteps is the SB3 run's length, not this one's (--timesteps)
REWARD_SCALE = 1 / 30  # normalize's counterpart, chosen by --select-scale 1 1/30 0.02 on the check episodes
# (results/v0/rllib/selection.md); 1/30 is about 1 / the std of the discounted return (gamma 0.99) that VecNormalize
# divided the rewards by at the end of the SB3 run (results/v0/ppo/vecnormalize.pkl: variance 880). SB3 also clips
# the scaled rewards at 10, which caps a collision's cost; not done here.
SCALE_CHOICE = (  # how REWARD_SCALE was chosen, for the report of a run that uses it
    "chosen by `python -m train.train_rllib --select-scale 1 1/30 0.02` among no scaling, 1/30 (about 1 / the std "
    "of the discounted return the SB3 run's VecNormalize divided by) and 0.02: one run of each at the default "
    "seed and length (0, 1 M env steps), the highest mean return on `train.train_ppo`'s 32 check episodes (seeds "
    f"9000-9031; no held-out episode); its table: `results/v0/rllib/{SELECTION_FILE}`. An earlier version had set 1/30 "
    "after comparing these candidates' returns on the held-out episodes below, so those were seen before this choice.")
RLLIB_OWN = {  # PPOConfig.training settings ppo.yml has no key for, set as SB3's PPO behaves
    "use_kl_loss": False,  # RLlib adds a KL penalty by default, SB3 does not
    "vf_clip_param": math.inf,  # RLlib clips the value loss at 10 by default, SB3 (clip_range_vf None) does not
    "vf_loss_coeff": 0.5,  # SB3's vf_coef
}


def parse_scale(text: str) -> float:
    """A reward scale from the command line: a positive number or fraction ("0.02", "1/30") [-]."""
    try:
        value = Fraction(text)
    except (ValueError, ZeroDivisionError) as error:
        raise argparse.ArgumentTypeError(f"reward scale {text!r}: not a number or fraction such as 1/30") from error
    if value <= 0:
        raise argparse.ArgumentTypeError(f"reward scale {text!r}: must be > 0")
    return float(value)


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="python -m train.train_rllib", description=__doc__.split("\n")[0])
    parser.add_argument("--timesteps", type=int, default=DEFAULT_TIMESTEPS,
                        help="environment steps to sample, at least; whole iterations (default: %(default)s)")
    parser.add_argument("--env-runners", type=int, default=DEFAULT_ENV_RUNNERS,
                        help="Ray actors stepping envs, one CPU each (default: %(default)s)")
    parser.add_argument("--envs-per-runner", type=int, default=None,
                        help="platoons in each runner's native vector env (default: the yml's n_envs / runners)")
    parser.add_argument("--address", default=None,
                        help="Ray cluster to join, e.g. auto or ray://head:10001 (default: start Ray here)")
    parser.add_argument("--out", type=Path, default=Path("runs/rllib"),
                        help="run directory: checkpoint/ and training.md (default: %(default)s)")
    parser.add_argument("--seed", type=int, default=0,
                        help="seed of RLlib and the envs: runner w's platoon i gets (seed + w) x envs + i (default: 0)")
    parser.add_argument("--hyperparams", type=Path, default=Path("hyperparams/ppo.yml"),
                        help="the SB3 run's rl-zoo3-style yml the env and PPO settings come from (default: %(default)s)")
    parser.add_argument("--env-config", type=cli.json_object, default={},
                        help="EnvConfig overrides as JSON, merged into env_kwargs' config (default: none)")
    parser.add_argument("--eval-episodes", type=int, default=None,
                        help="held-out episodes of the default task for the report's check, 0: none (default: "
                             f"{DEFAULT_EVAL_EPISODES}; the full comparison: python -m train.benchmark --policy <out>)")
    parser.add_argument("--reward-scale", type=parse_scale, default=None,
                        help="the rewards PPO learns from: the env's times this, e.g. 1/30 (default: REWARD_SCALE "
                             f"= {REWARD_SCALE:.4g} if the yml normalizes rewards, else 1)")
    parser.add_argument("--select-scale", type=parse_scale, nargs="+", default=None, metavar="SCALE",
                        help="train one run per reward scale, score them on the check episodes (seeds 9000-9031) "
                             f"and write {SELECTION_FILE}; no checkpoint, no held-out episode (default: off)")
    return parser.parse_args(argv)


class ForRLlib(gym.vector.VectorWrapper):
    """The native vector env as RLlib's runners step it: ``reset(seed=s)`` seeds platoon i with s x num_envs + i,
    so vector envs given consecutive seeds (RLlib's runners: seed + worker index) draw disjoint platoons; the
    infos are left out (PPO reads none; RLlib would keep them in its episodes and ship them to the learner: with
    the per-step diagnostics 4.5 MB per 2048 steps, which made sampling 5-10 times slower); the rewards are
    multiplied by ``reward_scale``."""

    def __init__(self, env: gym.vector.VectorEnv, reward_scale: float = 1.0) -> None:
        super().__init__(env)
        self.reward_scale = reward_scale

    def reset(self, *, seed: int | list[int | None] | None = None,
              options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        if isinstance(seed, (int, np.integer)):
            seed = [int(seed) * self.num_envs + i for i in range(self.num_envs)]
        obs, _ = self.env.reset(seed=seed, options=options)
        return obs, {}

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        obs, rewards, terminated, truncated, _ = self.env.step(actions)
        return obs, rewards * self.reward_scale, terminated, truncated, {}


def make_env(env_config: dict[str, Any]) -> gym.vector.VectorEnv:
    """RLlib's env creator: ``env_config`` (gym.make's keyword arguments, ``reward_scale`` and ``num_envs``, added by
    RLlib's vector_entry_point) -> the native vector env, without its per-step diagnostics, in :class:`ForRLlib`."""
    kwargs = dict(env_config)
    if "num_envs" not in kwargs:
        raise ValueError(f"env_config = {env_config!r}: has no num_envs; the runners must use "
                         "gym_env_vectorize_mode='vector_entry_point'")
    num_envs, reward_scale = kwargs.pop("num_envs"), kwargs.pop("reward_scale", 1.0)
    envs = gym.make_vec(QUALIFIED_ID, num_envs=num_envs, vectorization_mode="vector_entry_point",
                        step_diagnostics=False, **kwargs)
    return ForRLlib(envs, reward_scale)


def net_arch_of(policy_kwargs: dict[str, Any], where: Path) -> list[int]:
    """The hidden layer sizes of policy_kwargs' net_arch; RLlib's default module takes one list for both MLPs."""
    arch = policy_kwargs.get("net_arch", [64, 64])  # SB3's default for PPO's MlpPolicy
    if isinstance(arch, dict):
        if arch.get("pi") != arch.get("vf"):
            raise ValueError(f"hyperparams {DEFAULT_TASK}.policy_kwargs.net_arch = {arch!r} in {where}: RLlib's default "
                             "module needs pi and vf of the same sizes")
        arch = arch["pi"]
    extra = set(policy_kwargs) - {"net_arch"}
    if extra:
        raise ValueError(f"hyperparams {DEFAULT_TASK}.policy_kwargs keys {sorted(extra)} in {where}: no RLlib counterpart")
    return list(arch)


@dataclasses.dataclass(frozen=True)
class HeldOut:
    """The policy and EVAL_POLICIES on the default task's held-out episodes: a summary row each."""

    episodes: int  # per policy
    rows: list[dict[str, Any]]  # name, return_mean/_ci_low/_ci_high, return_vs_reference_*, collisions, episodes, ...
    seconds: float  # wall time of the evaluation [s]


def held_out_returns(policy: Any, episodes: int | None) -> HeldOut:
    """``policy`` and EVAL_POLICIES on ``episodes`` (None: DEFAULT_EVAL_EPISODES) held-out episodes of the default
    task (seeds from EVAL_SEED_START), each in its own action mode, paired against the paper's rule. The full
    comparison is the benchmark's: ``python -m train.benchmark --policy <out>``."""
    from timegap_env.experiments import registry
    from timegap_env.experiments.rollout import rollout
    from timegap_env.experiments.stats import bootstrap_mean

    start = time.perf_counter()
    config = get_task(DEFAULT_TASK).config()
    seeds = list(range(EVAL_SEED_START, EVAL_SEED_START + (episodes or DEFAULT_EVAL_EPISODES)))
    policies = {"rllib_ppo": policy, **{name: registry.make(name, config) for name in EVAL_POLICIES}}
    records = {name: rollout(each, config, seeds, step_diagnostics=False).records for name, each in policies.items()}
    reference = np.array([record.episode_return for record in records[EVAL_POLICIES[0]]])
    rows = []
    for name, played in records.items():
        returns = np.array([record.episode_return for record in played])
        mean, low, high = bootstrap_mean(returns)
        versus = bootstrap_mean(returns - reference)
        rows.append({"name": name, "return_mean": mean, "return_ci_low": low, "return_ci_high": high,
                     "return_vs_reference_mean": versus[0], "return_vs_reference_ci_low": versus[1],
                     "return_vs_reference_ci_high": versus[2], "episodes": len(played),
                     "collisions": sum(bool(record.summary["collision"]) for record in played),
                     "mean_setting_mean": float(np.mean([record.summary["mean_setting"] for record in played])),
                     "switches_mean": float(np.mean([record.summary["switches"] for record in played]))})
    return HeldOut(len(seeds), rows, time.perf_counter() - start)


@dataclasses.dataclass(frozen=True)
class Checked:
    """The deterministic policy on train.train_ppo's check episodes, as its learning curve scores a run."""

    seeds: list[int]
    returns: np.ndarray  # per episode, the env's rewards
    collisions: int  # episodes that ended in a collision

    def mean_interval(self) -> str:
        """Mean return [95 % bootstrap interval], as the reports print it."""
        from timegap_env.experiments.stats import bootstrap_mean

        mean, low, high = bootstrap_mean(self.returns)
        return f"{mean:.1f} [{low:.1f}, {high:.1f}]"


def check_returns(policy: Any, env_kwargs: dict[str, Any]) -> Checked:
    """``policy``'s deterministic actions on the default task's check episodes (its ``seeds.check``, below the
    held-out seeds) in the env of ``env_kwargs`` (gym.make's), through value_of_information.run as train_ppo's
    learning curve does."""
    from timegap_env.studies.value import run

    task = get_task(DEFAULT_TASK)
    seeds = task.seeds.check
    result = run(task.config(env_kwargs.get("config")), seeds,
                 lambda obs, infos: policy.predict(obs, deterministic=True)[0])
    return Checked(seeds, result["return"], int(result["collision"].sum()))


def check_candidates(args: argparse.Namespace) -> None:
    """``--select-scale``'s candidates: at least two, all different, and no --reward-scale or --eval-episodes beside
    them (the selection runs no held-out episode); ValueError naming the conflict."""
    scales = args.select_scale
    if len(scales) < 2 or len(set(scales)) < len(scales):
        raise ValueError(f"--select-scale {' '.join(f'{scale:g}' for scale in scales)}: needs two or more different "
                         "scales")
    for name, value in (("--reward-scale", args.reward_scale), ("--eval-episodes", args.eval_episodes)):
        if value is not None:
            raise ValueError(f"{name} {value:g} with --select-scale: the selection sets the scale of each run and "
                             "scores it on the check episodes only")


@dataclasses.dataclass(frozen=True)
class Settings:
    """What a run trains with: the command line's, and the env and PPO's from the SB3 run's yml (``MAPPED``)."""

    runners: int  # env runners
    envs: int  # platoons per runner
    n_steps: int  # steps per platoon per iteration
    env_kwargs: dict[str, Any]  # gym.make's keyword arguments
    training: dict[str, Any]  # PPOConfig.training's, mapped from the yml
    hidden: list[int]  # hidden layer sizes of the policy's and the value function's MLPs
    reward_scale: float  # the rewards PPO learns from: the env's times this [-]

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> Settings:
        """The settings of ``args``; a yml key with no counterpart, sizes below 1 or seeds reaching the evaluation's
        raise ValueError naming them."""
        # SB3's parser of the yml and its env_kwargs; the first seed of its check episodes
        from timegap_env.studies.training import load_hyperparams, with_env_config

        hyperparams = load_hyperparams(args.hyperparams)
        unknown = set(hyperparams) - set(MAPPED) - UNMAPPED
        if unknown:
            raise ValueError(f"hyperparams {DEFAULT_TASK} keys {sorted(unknown)} in {args.hyperparams}: no RLlib "
                             f"counterpart here; mapped: {sorted(MAPPED)}, read apart: {sorted(UNMAPPED)}")
        if hyperparams["policy"] != "MlpPolicy":
            raise ValueError(f"hyperparams {DEFAULT_TASK}.policy = {hyperparams['policy']!r} in {args.hyperparams}: only "
                             "'MlpPolicy' has an RLlib counterpart here (its default MLP module)")
        runners = args.env_runners
        envs = max(1, hyperparams["n_envs"] // max(runners, 1)) if args.envs_per_runner is None else args.envs_per_runner
        for name, value in (("--timesteps", args.timesteps), ("--env-runners", runners), ("--envs-per-runner", envs)):
            if value < 1:
                raise ValueError(f"{name} = {value}: must be >= 1")
        if args.eval_episodes is not None and args.eval_episodes < 0:
            raise ValueError(f"--eval-episodes = {args.eval_episodes}: must be >= 0 (0: no held-out evaluation)")
        if args.select_scale is not None:
            check_candidates(args)
        normalize = hyperparams.get("normalize", False)  # rl-zoo3's: a bool or VecNormalize's keyword arguments
        scale_rewards = normalize.get("norm_reward", True) if isinstance(normalize, dict) else bool(normalize)
        last_seed = (args.seed + runners) * envs + envs - 1
        if args.seed < 0 or last_seed >= EVAL_SEED_START:
            raise ValueError(f"--seed {args.seed}: the runners' platoons are seeded up to {last_seed}, must stay in "
                             f"[0, {EVAL_SEED_START}) (the evaluation's seeds start there)")
        if args.select_scale is not None and last_seed >= CHECK_SEED_START:
            raise ValueError(f"--seed {args.seed} with --select-scale: the runners' platoons are seeded up to "
                             f"{last_seed}, must stay below {CHECK_SEED_START} (the check episodes' seeds start there)")
        if args.reward_scale is not None:
            reward_scale = args.reward_scale
        else:
            reward_scale = REWARD_SCALE if scale_rewards else 1.0
        return cls(
            runners=runners,
            envs=envs,
            n_steps=int(hyperparams.get("n_steps", 2048)),  # SB3's default
            env_kwargs=with_env_config(hyperparams.get("env_kwargs") or {}, args.env_config),
            training={MAPPED[key]: value for key, value in hyperparams.items() if key in MAPPED},
            hidden=net_arch_of(hyperparams.get("policy_kwargs") or {}, args.hyperparams),
            reward_scale=reward_scale,
        )

    @property
    def train_batch(self) -> int:
        """Env steps per iteration: runners x envs x n_steps."""
        return self.runners * self.envs * self.n_steps

    @property
    def env_config(self) -> dict[str, Any]:
        """RLlib's env_config, make_env's: gym.make's keyword arguments, next-step autoreset (RLlib takes the observation
        after a finished step as the next episode's first) and the reward scale."""
        return {**self.env_kwargs, "autoreset_mode": "next_step", "reward_scale": self.reward_scale}


@dataclasses.dataclass(frozen=True)
class Iteration:
    """One ``algo.train()``: what the runners sampled and the episodes that ended in it."""

    number: int
    steps: int  # env steps sampled so far
    sampled: int  # env steps sampled in this iteration
    episodes: int  # episodes that ended in this iteration
    episode_return: float  # their mean return, the env's rewards (not scaled; NaN: none ended)
    seconds: float  # wall time of the iteration, sampling and update [s]

    def line(self) -> str:
        """The iteration as a line of the log."""
        ended = f"{self.episodes:3d} episodes ended, mean return {self.episode_return:7.1f}" if self.episodes else \
            "no episode ended" + " " * 23
        return (f"iteration {self.number:4d}  env steps {self.steps:>9,}  {ended}  {self.seconds:5.2f} s  "
                f"{self.sampled / self.seconds:6,.0f} steps/s")

    def row(self) -> str:
        """The iteration as a row of the report's table."""
        ended = f"{self.episodes} | {self.episode_return:.1f}" if self.episodes else "0 | –"
        return f"| {self.number} | {self.steps:,} | {ended} | {self.seconds:.2f} | {self.sampled / self.seconds:,.0f} |"


@dataclasses.dataclass(frozen=True)
class Trained:
    """A run's training: its iterations and checkpoint."""

    iterations: list[Iteration]
    seconds: float  # the iterations' wall time [s]
    checkpoint: Path  # algo.save's directory, with env.json

    def recent_return(self, platoons: int) -> tuple[float, int]:
        """The mean return of the training episodes of the last iterations, back to at least one per platoon (or
        all), and how many they are."""
        total, count = 0.0, 0
        for row in reversed(self.iterations):
            if row.episodes:
                total, count = total + row.episode_return * row.episodes, count + row.episodes
            if count >= platoons:
                break
        return (total / count if count else math.nan), count


def scale_text(scale: float) -> str:
    """A reward scale as the reports print it: 1/30 rather than 0.0333333, 0.02 as it is."""
    fraction = Fraction(scale).limit_denominator(1000)
    return str(fraction) if len(f"{scale:g}") > 6 and float(fraction) == scale else f"{scale:g}"


def train(settings: Settings, seed: int, timesteps: int, out: Path) -> Trained:
    """PPO with ``settings`` for ``timesteps`` env steps at least (whole iterations) on the running Ray session, whose
    env registry holds RLLIB_ENV; saved as ``out``/checkpoint/ (replaced) with the env's env.json."""
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.core.rl_module.default_model_config import DefaultModelConfig
    from ray.rllib.utils.metrics import (
        ENV_RUNNER_RESULTS,
        EPISODE_RETURN_MEAN,
        NUM_ENV_STEPS_SAMPLED_LIFETIME,
        NUM_EPISODES,
    )

    config = (
        PPOConfig()
        .environment(RLLIB_ENV, env_config=settings.env_config)
        .env_runners(num_env_runners=settings.runners, num_envs_per_env_runner=settings.envs,
                     gym_env_vectorize_mode="vector_entry_point", rollout_fragment_length=settings.n_steps)
        .training(train_batch_size_per_learner=settings.train_batch, **settings.training, **RLLIB_OWN)
        .rl_module(model_config=DefaultModelConfig(fcnet_hiddens=settings.hidden, fcnet_activation="tanh",
                                                   vf_share_layers=False))
        .debugging(seed=seed)
    )
    algo = config.build_algo()
    try:
        rows: list[Iteration] = []
        steps, clock = 0, time.perf_counter()
        while steps < timesteps:
            tick = time.perf_counter()
            result = algo.train()[ENV_RUNNER_RESULTS]
            previous, steps = steps, int(result[NUM_ENV_STEPS_SAMPLED_LIFETIME])
            rows.append(Iteration(len(rows) + 1, steps, steps - previous, int(result.get(NUM_EPISODES, 0)),
                                  float(result.get(EPISODE_RETURN_MEAN, math.nan)) / settings.reward_scale,
                                  time.perf_counter() - tick))
            print(rows[-1].line(), flush=True)
        seconds = time.perf_counter() - clock
        checkpoint = out / CHECKPOINT_DIR
        if checkpoint.exists():
            shutil.rmtree(checkpoint)
        checkpoint.mkdir(parents=True)
        algo.save(checkpoint.resolve())
    finally:
        algo.stop()
    (checkpoint / ENV_FILE).write_text(json.dumps({"env_kwargs": settings.env_kwargs, "frame_stack": 1,
                                                   "normalize": False}, indent=2) + "\n")  # observations as they come
    return Trained(rows, seconds, checkpoint)


@dataclasses.dataclass(frozen=True)
class Run:
    """A finished run, for its report."""

    command: str
    settings: Settings
    seed: int
    ray: str  # where Ray ran, its CPUs and version
    trained: Trained
    wall_seconds: float  # the command's start to the checkpoint [s]
    checked: Checked  # the policy on the check episodes

    def report(self, hyperparams: Path, policy: Any, held_out: HeldOut | None, out: Path) -> str:
        """training.md: the command, the settings, the iterations, throughput, the return on the check episodes,
        how the reward scale was chosen and the held-out returns."""
        s, trained = self.settings, self.trained
        steps, checkpoint = trained.iterations[-1].steps, out / CHECKPOINT_DIR  # where the run is published
        size = sum(path.stat().st_size for path in trained.checkpoint.rglob("*") if path.is_file())
        recent, episodes = trained.recent_return(s.runners * s.envs)
        default_scale = s.reward_scale == REWARD_SCALE
        c = self.checked
        lines = [
            f"# PPO (Ray RLlib, new API stack) on {DEFAULT_TASK}", "",
            f"Command: `{self.command}`", "",
            "| | |", "|---|---|",
            f"| Ray | {self.ray} |",
            (f"| env runners x platoons each, seed | {s.runners} x {s.envs}, {self.seed} (runner w's platoon i: "
             f"({self.seed} + w) x {s.envs} + i) |"),
            f"| env (gym.make's keyword arguments) | `{json.dumps(s.env_kwargs)}`, next-step autoreset |",
            (f"| PPO, from `{hyperparams}` | train batch {s.train_batch} ({s.runners * s.envs} platoons x {s.n_steps} "
             f"steps), {', '.join(f'{key} {value}' for key, value in s.training.items())}, two MLPs {s.hidden} "
             "(tanh) |"),
            (f"| PPO, RLlib's own | {', '.join(f'{key} {value}' for key, value in RLLIB_OWN.items())}; "
             f"rewards x {scale_text(s.reward_scale)}{' (REWARD_SCALE: see below)' if default_scale else ''} "
             "(returns below in the env's units), no observation filter, no warm-up |"),
            f"| iterations, env steps | {len(trained.iterations)}, {steps:,} |",
            f"| training time, throughput | {trained.seconds:.0f} s, {steps / trained.seconds:,.0f} env steps/s |",
            f"| wall time, the command's start (imports, Ray, training) to the checkpoint | {self.wall_seconds:.0f} s |",
            f"| mean return, last {episodes} training episodes (stochastic policy) | {recent:.1f} |",
            (f"| mean return [95 % bootstrap], deterministic policy, {len(c.seeds)} check episodes (seeds "
             f"{c.seeds[0]}-{c.seeds[-1]}); collisions | {c.mean_interval()}; {c.collisions}/{len(c.seeds)} |"),
            f"| checkpoint | `{checkpoint}/` ({size / 1e6:.1f} MB), `{policy!r}` |", "",
        ]
        if default_scale:
            lines += ["## Reward scale", "", f"Rewards x {scale_text(s.reward_scale)}, `REWARD_SCALE`: {SCALE_CHOICE}",
                      ""]
        if held_out is not None:
            lines += [
                f"## Held-out evaluation ({held_out.episodes} episodes per policy, {held_out.seconds:.0f} s)", "",
                (f"By this command: the default task's held-out seeds from {EVAL_SEED_START}, deterministic actions, "
                 "each policy in its own action mode. Mean return [95 % bootstrap interval]; Δ: paired difference "
                 "to the paper's rule on the same episodes; switches: follower setting changes per episode. The "
                 f"full comparison: `python -m train.benchmark --policy {out}`."), "",
                "| policy | return | Δ return vs paper rule (platoon) | collisions | mean τ* [s] | switches |",
                "|---|---|---|---|---|---|",
                *(f"| {r['name']} | {r['return_mean']:.1f} [{r['return_ci_low']:.1f}, {r['return_ci_high']:.1f}] | "
                  f"{r['return_vs_reference_mean']:.1f} [{r['return_vs_reference_ci_low']:.1f}, "
                  f"{r['return_vs_reference_ci_high']:.1f}] | {r['collisions']}/{r['episodes']} | "
                  f"{r['mean_setting_mean']:.2f} | {r['switches_mean']:.2f} |" for r in held_out.rows),
                "",
            ]
        return "\n".join([
            *lines,
            "## Iterations", "",
            "| iteration | env steps | episodes ended | their mean return | time [s] | env steps/s |",
            "|---|---|---|---|---|---|",
            *(row.row() for row in trained.iterations),
            "",
        ])


@dataclasses.dataclass(frozen=True)
class Candidate:
    """One run of --select-scale: its reward scale, training and score on the check episodes."""

    scale: float
    trained: Trained  # its checkpoint is gone with the selection's temporary directory
    checked: Checked


def best_candidate(candidates: list[Candidate]) -> Candidate:
    """The candidate of the highest mean return on the check episodes (the first of equal ones)."""
    return max(candidates, key=lambda candidate: float(candidate.checked.returns.mean()))


def selection_report(command: str, settings: Settings, seed: int, ray: str, candidates: list[Candidate],
                     wall_seconds: float) -> str:
    """selection.md: how the candidates were trained and scored, their returns and the scale chosen."""
    from timegap_env.experiments.stats import bootstrap_mean

    chosen = best_candidate(candidates)
    platoons = settings.runners * settings.envs
    seeds = chosen.checked.seeds
    rows = []
    for candidate in candidates:
        trained, checked = candidate.trained, candidate.checked
        recent, episodes = trained.recent_return(platoons)
        delta, low, high = bootstrap_mean(checked.returns - chosen.checked.returns)
        label = scale_text(candidate.scale) + (" (chosen)" if candidate is chosen else "")
        rows.append(f"| {label} | {checked.mean_interval()} | {delta:.1f} [{low:.1f}, {high:.1f}] | "
                    f"{checked.collisions}/{len(checked.seeds)} | {recent:.1f} ({episodes}) | {trained.iterations[-1].steps:,} | {trained.seconds:.0f} |")
    named = scale_text(chosen.scale)
    chosen_text = f"{chosen.scale:.6g}" + (f" ({named})" if named != f"{chosen.scale:g}" else "")
    verdict = "the chosen scale" if chosen.scale == REWARD_SCALE else "not the chosen scale: set it to the chosen one"
    return "\n".join([
        f"# Reward scale of train.train_rllib, chosen on the check episodes ({DEFAULT_TASK})", "",
        f"Command: `{command}` ({ray}; {wall_seconds / 60:.1f} min in all)", "",
        (f"One run per candidate scale, each as the command without `--select-scale` would train it with "
         f"`--reward-scale` set to the candidate: seed {seed}, {settings.runners} env runners x {settings.envs} "
         f"platoons, train batch {settings.train_batch}, the same number of env steps. Each run's deterministic "
         f"policy is scored on `train.train_ppo`'s check episodes, the {len(seeds)} episodes its learning curve "
         f"uses (seeds {seeds[0]}-{seeds[-1]}, below the held-out seeds from {EVAL_SEED_START}; the training "
         f"platoons' seeds stay below {seeds[0]}), in the env trained in; the highest mean return is chosen. No "
         "held-out episode is run and no checkpoint is kept."), "",
        ("Return: mean [95 % bootstrap interval] in the env's units; Δ: paired difference to the chosen scale on "
         "the same episodes; training return: the last iterations' episodes of the stochastic policy (how many)."), "",
        ("| reward scale | return, check episodes | Δ return vs chosen | collisions | training return (episodes) | "
         "env steps | training time [s] |"),
        "|---|---|---|---|---|---|---|",
        *rows, "",
        (f"Chosen: rewards x {chosen_text}. `REWARD_SCALE` in train/train_rllib.py is {REWARD_SCALE:.6g}, "
         f"{verdict}."),
        "",
    ])


def select_scale(args: argparse.Namespace, settings: Settings, command: str, ray: str, started: float) -> str:
    """--select-scale on the running Ray session: a run per candidate in a temporary directory, each scored on the
    check episodes; selection.md written to ``args.out`` and returned."""
    candidates = []
    with tempfile.TemporaryDirectory(prefix="select_scale_") as scratch:
        for number, scale in enumerate(args.select_scale):
            print(f"reward scale {scale_text(scale)}: training", flush=True)
            run_settings = dataclasses.replace(settings, reward_scale=scale)
            trained = train(run_settings, args.seed, args.timesteps, Path(scratch, f"candidate_{number}"))
            checked = check_returns(RLlibPolicy.load(trained.checkpoint), settings.env_kwargs)
            print(f"reward scale {scale_text(scale)}: mean return {checked.mean_interval()} on the check episodes",
                  flush=True)
            candidates.append(Candidate(scale, trained, checked))
    report = selection_report(command, settings, args.seed, ray, candidates, time.perf_counter() - started)
    args.out.mkdir(parents=True, exist_ok=True)
    partial = args.out / f"{SELECTION_FILE}.tmp"
    partial.write_text(report)
    os.replace(partial, args.out / SELECTION_FILE)  # whole or not at all
    return report


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    cli.output_dir(args.out)
    started = time.perf_counter()
    settings = Settings.from_args(args)
    command = shlex.join(["python", "-m", "train.train_rllib", *(sys.argv[1:] if argv is None else argv)])
    import ray
    import torch
    from ray.tune.registry import register_env

    # ---------------------------------------------------------------- Ray, then the run or the selection's runs
    torch.set_num_threads(1)  # the learner here: with 2 threads its update took 5-30 times longer on this machine
    ray.init(address=args.address, runtime_env=runtime_env(args.address), include_dashboard=False,
             logging_level="WARNING")
    try:
        cpus = int(ray.cluster_resources().get("CPU", 0))
        if cpus < settings.runners:
            raise ValueError(f"--env-runners {settings.runners}: needs a CPU each, the cluster has {cpus}")
        register_env(RLLIB_ENV, make_env)
        where = "started on this machine" if args.address is None else f"cluster at {args.address}"
        print(f"Ray {where}: {cpus} CPUs, {len([n for n in ray.nodes() if n['Alive']])} node(s); {settings.runners} "
              f"env runners x {settings.envs} envs, train batch {settings.train_batch}")
        description = f"{where}, {cpus} CPUs, Ray {ray.__version__}"
        if args.select_scale is not None:
            print(select_scale(args, settings, command, description, started))
            return
        work = cli.work_directory(args.out, copy=True)  # --out's other files (selection.md) kept; --out whole till the end
        try:
            trained = train(settings, args.seed, args.timesteps, work)
        except BaseException:
            shutil.rmtree(work, ignore_errors=True)
            raise
    finally:
        ray.shutdown()
    wall = time.perf_counter() - started  # the command's start to the checkpoint

    # ---------------------------------------------------------------- check and held-out episodes, report
    try:
        policy = RLlibPolicy.load(trained.checkpoint)
        checked = check_returns(policy, settings.env_kwargs)
        held_out = held_out_returns(policy, args.eval_episodes) if args.eval_episodes != 0 else None
        run = Run(command, settings, args.seed, description, trained, wall, checked)
        report = run.report(args.hyperparams, policy, held_out, args.out)
        (work / REPORT_FILE).write_text(report)
        cli.publish(work, args.out)
    except BaseException:  # the trained checkpoint is kept: the checks and the report can be run again on it
        if work.exists():
            print(f"train_rllib: stopped after training; --out {args.out} is unchanged. The trained checkpoint is in "
                  f"{work / CHECKPOINT_DIR} (timegap_env.agents.rllib_policy.RLlibPolicy.load reads it); delete {work} if not "
                  "wanted", file=sys.stderr)
        raise
    print(report)


if __name__ == "__main__":
    cli.run(main, "python -m train.train_rllib")
