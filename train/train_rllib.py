"""Train PPO (Ray RLlib, new API stack) on ``TimeGapMonitor-v0`` with several env runners, each a native vector env.

    python -m train.train_rllib                                   # the committed run in results/rllib/ (Ray here)
    python -m train.train_rllib --timesteps 50000 --out /tmp/rllib  # a short run elsewhere
    python -m train.train_rllib --address auto --env-runners 16   # join a running Ray cluster

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
to [-1, 1] and go in as they are). RLlib's own settings, set to what SB3's PPO does, are in ``RLLIB_OWN``.
The SB3 run's warm-up (hyperparams/ppo_warmup.yml) is not repeated. ``--timesteps`` defaults to
``DEFAULT_TIMESTEPS``, 1 M env steps, about 2-3 minutes on this 2-core machine: half the SB3 run's 2 M.

Runner w (1, 2, ...) steps platoons seeded (seed + w) x envs-per-runner + i, i < envs-per-runner (RLlib
seeds runner w's vector env with seed + w; ``ForRLlib`` spreads that over its platoons), so runners never
share a platoon's stream; all below ``agents.protocol.EVAL_SEED_START``, where the evaluation's seeds begin.

``--out`` (default ``results/rllib``) receives ``checkpoint/`` (RLlib's ``algo.save``, the env's
``env.json`` added), which ``agents.rllib_policy.RLlibPolicy.load`` reads, and ``training.md``: the
command, every iteration (env steps, episodes ended and their mean return, time, throughput), the wall time
and, unless ``--eval-episodes 0``, the policy's mean return on ``train.evaluate``'s held-out episodes
beside the paper's rule and the fixed 1.6 s setting.
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
import time
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from agents.protocol import ENV_FILE, EVAL_SEED_START
from agents.rllib_policy import CHECKPOINT_DIR, RLlibPolicy
from timegap_env import ENV_ID
from train.backends import NOT_SHIPPED, REPO

QUALIFIED_ID = f"timegap_env:{ENV_ID}"  # gymnasium imports timegap_env, which registers the id, in any process
RLLIB_ENV = "timegap_rllib"  # RLlib's name of make_env
REPORT_FILE = "training.md"
DEFAULT_TIMESTEPS = 1_000_000  # about 2-3 min on this 2-core machine, half the SB3 run's 2 M [env steps]
DEFAULT_ENV_RUNNERS = 2  # one per core of this machine
EVAL_POLICIES = ("rule_platoon", "fixed_1.6")  # train.evaluate's policies the report compares with
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
REWARD_SCALE = 1 / 30  # normalize's counterpart: about 1 / the std of the discounted return (gamma 0.99) that
# VecNormalize divided the rewards by at the end of the SB3 run (results/ppo/vecnormalize.pkl: variance 880); not
# tuned. SB3 also clips the scaled rewards at 10, which caps a collision's cost; not done here.
RLLIB_OWN = {  # PPOConfig.training settings ppo.yml has no key for, set as SB3's PPO behaves
    "use_kl_loss": False,  # RLlib adds a KL penalty by default, SB3 does not
    "vf_clip_param": math.inf,  # RLlib clips the value loss at 10 by default, SB3 (clip_range_vf None) does not
    "vf_loss_coeff": 0.5,  # SB3's vf_coef
}


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
    parser.add_argument("--out", type=Path, default=Path("results/rllib"),
                        help="run directory: checkpoint/ and training.md (default: %(default)s)")
    parser.add_argument("--seed", type=int, default=0,
                        help="seed of RLlib and the envs: runner w's platoon i gets (seed + w) x envs + i (default: 0)")
    parser.add_argument("--hyperparams", type=Path, default=Path("hyperparams/ppo.yml"),
                        help="the SB3 run's rl-zoo3-style yml the env and PPO settings come from (default: %(default)s)")
    parser.add_argument("--env-config", type=json.loads, default={},
                        help="EnvConfig overrides as JSON, merged into env_kwargs' config (default: none)")
    parser.add_argument("--eval-episodes", type=int, default=None,
                        help="held-out episodes of train.evaluate for the report, 0: none (default: its 112)")
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
            raise ValueError(f"hyperparams {ENV_ID}.policy_kwargs.net_arch = {arch!r} in {where}: RLlib's default "
                             "module needs pi and vf of the same sizes")
        arch = arch["pi"]
    extra = set(policy_kwargs) - {"net_arch"}
    if extra:
        raise ValueError(f"hyperparams {ENV_ID}.policy_kwargs keys {sorted(extra)} in {where}: no RLlib counterpart")
    return list(arch)


def runtime_env(address: str | None) -> dict[str, Any]:
    """What the runners need to import this repository (``train``, for make_env): its folder on their path here,
    its code as ``working_dir`` on a cluster."""
    if address is None:
        path = os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")]))
        return {"env_vars": {"PYTHONPATH": path}}
    return {"working_dir": str(REPO), "excludes": NOT_SHIPPED}


@dataclasses.dataclass(frozen=True)
class HeldOut:
    """train.evaluate's summary rows over all its held-out episodes, for the policy and EVAL_POLICIES."""

    episodes: int  # per policy
    rows: list[dict[str, Any]]  # summarise's rows of the group "all"
    seconds: float  # wall time of the evaluation [s]


def held_out_returns(policy: Any, episodes: int | None) -> HeldOut:
    """``policy`` and EVAL_POLICIES on ``episodes`` (None: train.evaluate's default) of train.evaluate's held-out
    episodes: its groups, plan, runs and statistics."""
    from train import evaluate

    start = time.perf_counter()
    groups, _ = evaluate.available_groups()
    plan = evaluate.plan_episodes(episodes or evaluate.DEFAULT_EPISODES, groups)
    policies = {"rllib_ppo": policy, **evaluate.build_policies(list(EVAL_POLICIES), evaluate.DEFAULT_MODEL)}
    records, _, _ = evaluate.run_all(policies, plan, None)
    rows = evaluate.summarise(policies, records, evaluate.DEFAULT_REFERENCE)
    return HeldOut(len(plan), [row for row in rows if row["group"] == evaluate.ALL_EPISODES],
                   time.perf_counter() - start)


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
        # SB3's parser of the yml and its env_kwargs
        from train.train_ppo import load_hyperparams, with_env_config

        hyperparams = load_hyperparams(args.hyperparams)
        unknown = set(hyperparams) - set(MAPPED) - UNMAPPED
        if unknown:
            raise ValueError(f"hyperparams {ENV_ID} keys {sorted(unknown)} in {args.hyperparams}: no RLlib "
                             f"counterpart here; mapped: {sorted(MAPPED)}, read apart: {sorted(UNMAPPED)}")
        if hyperparams["policy"] != "MlpPolicy":
            raise ValueError(f"hyperparams {ENV_ID}.policy = {hyperparams['policy']!r} in {args.hyperparams}: only "
                             "'MlpPolicy' has an RLlib counterpart here (its default MLP module)")
        runners = args.env_runners
        envs = max(1, hyperparams["n_envs"] // max(runners, 1)) if args.envs_per_runner is None else args.envs_per_runner
        for name, value in (("--timesteps", args.timesteps), ("--env-runners", runners), ("--envs-per-runner", envs)):
            if value < 1:
                raise ValueError(f"{name} = {value}: must be >= 1")
        if args.eval_episodes is not None and args.eval_episodes < 0:
            raise ValueError(f"--eval-episodes = {args.eval_episodes}: must be >= 0 (0: no held-out evaluation)")
        normalize = hyperparams.get("normalize", False)  # rl-zoo3's: a bool or VecNormalize's keyword arguments
        scale_rewards = normalize.get("norm_reward", True) if isinstance(normalize, dict) else bool(normalize)
        last_seed = (args.seed + runners) * envs + envs - 1
        if args.seed < 0 or last_seed >= EVAL_SEED_START:
            raise ValueError(f"--seed {args.seed}: the runners' platoons are seeded up to {last_seed}, must stay in "
                             f"[0, {EVAL_SEED_START}) (the evaluation's seeds start there)")
        return cls(
            runners=runners,
            envs=envs,
            n_steps=int(hyperparams.get("n_steps", 2048)),  # SB3's default
            env_kwargs=with_env_config(hyperparams.get("env_kwargs") or {}, args.env_config),
            training={MAPPED[key]: value for key, value in hyperparams.items() if key in MAPPED},
            hidden=net_arch_of(hyperparams.get("policy_kwargs") or {}, args.hyperparams),
            reward_scale=REWARD_SCALE if scale_rewards else 1.0,
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
class Run:
    """A finished run, for its report."""

    command: str
    settings: Settings
    seed: int
    ray: str  # where Ray ran, its CPUs and version
    iterations: list[Iteration]
    training_seconds: float  # the iterations' wall time [s]
    wall_seconds: float  # the command's start to the checkpoint [s]
    checkpoint: Path

    def recent_return(self) -> tuple[float, int]:
        """The mean return of the training episodes of the last iterations, back to at least one per platoon (or
        all), and how many they are."""
        total, count = 0.0, 0
        for row in reversed(self.iterations):
            if row.episodes:
                total, count = total + row.episode_return * row.episodes, count + row.episodes
            if count >= self.settings.runners * self.settings.envs:
                break
        return (total / count if count else math.nan), count

    def report(self, hyperparams: Path, policy: Any, held_out: HeldOut | None) -> str:
        """training.md: the command, the settings, the iterations, throughput, and the held-out returns."""
        s, steps = self.settings, self.iterations[-1].steps
        size = sum(path.stat().st_size for path in self.checkpoint.rglob("*") if path.is_file())
        recent, episodes = self.recent_return()
        lines = [
            f"# PPO (Ray RLlib, new API stack) on {ENV_ID}", "",
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
             f"rewards x {s.reward_scale:.4g} (returns below in the env's units), no observation filter, no warm-up |"),
            f"| iterations, env steps | {len(self.iterations)}, {steps:,} |",
            (f"| training time, throughput | {self.training_seconds:.0f} s, "
             f"{steps / self.training_seconds:,.0f} env steps/s |"),
            f"| wall time, the command's start (imports, Ray, training) to the checkpoint | {self.wall_seconds:.0f} s |",
            f"| mean return, last {episodes} training episodes (stochastic policy) | {recent:.1f} |",
            f"| checkpoint | `{self.checkpoint}/` ({size / 1e6:.1f} MB), `{policy!r}` |", "",
        ]
        if held_out is not None:
            lines += [
                f"## Held-out evaluation ({held_out.episodes} episodes per policy, {held_out.seconds:.0f} s)", "",
                ("By this command, through `train.evaluate`'s functions (`available_groups`, `plan_episodes`, "
                 "`build_policies`, `run_all`, `summarise`): its held-out groups and seeds, deterministic actions. "
                 "Mean return [95 % bootstrap interval]; Δ: paired difference to the paper's rule on the same "
                 "episodes; switches: follower setting changes per episode."), "",
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
            *(row.row() for row in self.iterations),
            "",
        ])


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    started = time.perf_counter()
    settings = Settings.from_args(args)
    runners, envs = settings.runners, settings.envs
    import ray
    import torch
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.core.rl_module.default_model_config import DefaultModelConfig
    from ray.rllib.utils.metrics import (
        ENV_RUNNER_RESULTS,
        EPISODE_RETURN_MEAN,
        NUM_ENV_STEPS_SAMPLED_LIFETIME,
        NUM_EPISODES,
    )
    from ray.tune.registry import register_env

    # ---------------------------------------------------------------- Ray and the algorithm
    torch.set_num_threads(1)  # the learner here: with 2 threads its update took 5-30 times longer on this machine
    ray.init(address=args.address, runtime_env=runtime_env(args.address), include_dashboard=False,
             logging_level="WARNING")
    try:
        cpus = int(ray.cluster_resources().get("CPU", 0))
        if cpus < runners:
            raise ValueError(f"--env-runners {runners}: needs a CPU each, the cluster has {cpus}")
        register_env(RLLIB_ENV, make_env)
        config = (
            PPOConfig()
            .environment(RLLIB_ENV, env_config=settings.env_config)
            .env_runners(num_env_runners=runners, num_envs_per_env_runner=envs,
                         gym_env_vectorize_mode="vector_entry_point", rollout_fragment_length=settings.n_steps)
            .training(train_batch_size_per_learner=settings.train_batch, **settings.training, **RLLIB_OWN)
            .rl_module(model_config=DefaultModelConfig(fcnet_hiddens=settings.hidden, fcnet_activation="tanh",
                                                       vf_share_layers=False))
            .debugging(seed=args.seed)
        )
        algo = config.build_algo()
        where = "started on this machine" if args.address is None else f"cluster at {args.address}"
        print(f"Ray {where}: {cpus} CPUs, {len([n for n in ray.nodes() if n['Alive']])} node(s); {runners} env "
              f"runners x {envs} envs, train batch {settings.train_batch}")
        rows: list[Iteration] = []
        steps, clock = 0, time.perf_counter()
        while steps < args.timesteps:
            tick = time.perf_counter()
            result = algo.train()[ENV_RUNNER_RESULTS]
            previous, steps = steps, int(result[NUM_ENV_STEPS_SAMPLED_LIFETIME])
            rows.append(Iteration(len(rows) + 1, steps, steps - previous, int(result.get(NUM_EPISODES, 0)),
                                  float(result.get(EPISODE_RETURN_MEAN, math.nan)) / settings.reward_scale,
                                  time.perf_counter() - tick))
            print(rows[-1].line(), flush=True)
        training_seconds = time.perf_counter() - clock
        checkpoint = args.out / CHECKPOINT_DIR
        if checkpoint.exists():
            shutil.rmtree(checkpoint)
        checkpoint.mkdir(parents=True)
        algo.save(checkpoint.resolve())
        algo.stop()
    finally:
        ray.shutdown()
    (checkpoint / ENV_FILE).write_text(json.dumps({"env_kwargs": settings.env_kwargs, "frame_stack": 1}, indent=2) + "\n")
    wall = time.perf_counter() - started  # the command's start to the checkpoint

    # ---------------------------------------------------------------- held-out evaluation and report
    policy = RLlibPolicy.load(checkpoint)
    held_out = held_out_returns(policy, args.eval_episodes) if args.eval_episodes != 0 else None
    command = shlex.join(["python", "-m", "train.train_rllib", *(sys.argv[1:] if argv is None else argv)])
    run = Run(command, settings, args.seed, f"{where}, {cpus} CPUs, Ray {ray.__version__}", rows,
              training_seconds, wall, checkpoint)
    report = run.report(args.hyperparams, policy, held_out)
    (args.out / REPORT_FILE).write_text(report)
    print(report)


if __name__ == "__main__":
    try:
        main()
    except ValueError as error:  # a setting to fix, not a bug: its message, no traceback
        sys.exit(f"python -m train.train_rllib: error: {error}")
