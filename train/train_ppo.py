"""Train PPO (Stable-Baselines3) on ``TimeGapMonitor-v0``, every platoon in one native vector env.

    python -m train.train_ppo                                    # the committed model in results/ppo/
    python -m train.train_ppo --timesteps 20000 --out /tmp/ppo   # a short run elsewhere
    python -m train.train_ppo --resume --timesteps 3000000       # continue results/ppo/ to 3 M steps in all

Hyperparameters come from ``hyperparams/ppo.yml`` (rl-zoo3's layout: the env id, then
``n_envs``, ``n_timesteps``, ``policy``, ``normalize``, ``env_kwargs`` and PPO's own
arguments); ``--timesteps`` and ``--n-envs`` override them. An optional ``warmup``
(``n_timesteps``, ``env_kwargs``) trains the first steps in another env config (the
default: a decision every 5 s), then the run switches to ``env_kwargs``, keeping the
normalisation statistics. The run directory ``--out`` holds exactly:

- ``model.zip``: the PPO model, also the checkpoint (replaced every ``--checkpoint-freq``
  steps and at the end; it stores the timestep count, so ``--resume`` continues from it);
- ``vecnormalize.pkl``: ``VecNormalize``'s running statistics, when ``normalize`` is on;
- ``training.md``: command, timesteps, wall time, throughput and returns, written at the end.

Sub-env i of phase k's env is seeded ``--seed + k * n_envs + i``; all training seeds stay below
``agents.protocol.EVAL_SEED_START`` (10 000), where the evaluation's seeds begin. The final check runs the
deterministic policy and the best constant setting on ``EVAL_EPISODES`` episodes seeded
``EVAL_SEED + i``, also below 10 000. TensorBoard logs go to ``--tensorboard-log``.
"""

from __future__ import annotations

import argparse
import inspect
import os
import shlex
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch
import yaml
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import VecEnv, VecNormalize

from agents.protocol import EVAL_SEED_START, MODEL_FILE, VECNORMALIZE_FILE
from timegap_env import ENV_ID
from timegap_env.envs.sb3 import TimeGapVecEnv

REPORT_FILE = "training.md"
EVAL_SEED = 9_000  # first seed of the end-of-training check, below EVAL_SEED_START [-]
EVAL_EPISODES = 32  # episodes of the end-of-training check [-]
REFERENCE_SETTING = 1.0  # the best constant setting on the default mix, the check's reference [s]
RUN_KEYS = {"n_envs", "n_timesteps", "policy", "normalize", "env_kwargs", "warmup"}  # the rest of the yml is PPO's
SUMMARY_KEYS = {"collision", "mean_setting", "switches", "time_out_of_control"}  # logged per episode
STRING_KWARGS = ("policy_kwargs", "normalize")  # may be Python expressions as in rl-zoo3: "dict(net_arch=[64])"


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="python -m train.train_ppo", description=__doc__.split("\n")[0])
    parser.add_argument("--timesteps", type=int, default=None,
                        help="total environment steps of the run, warm-up included (default: n_timesteps of the yml)")
    parser.add_argument("--seed", type=int, default=0,
                        help="seed of PyTorch and the envs; phase k's sub-env i gets seed + k n_envs + i (default: 0)")
    parser.add_argument("--n-envs", type=int, default=None,
                        help="platoons stepped together (default: n_envs of the yml)")
    parser.add_argument("--hyperparams", type=Path, default=Path("hyperparams/ppo.yml"),
                        help="rl-zoo3-style yml keyed by env id (default: %(default)s)")
    parser.add_argument("--out", type=Path, default=Path("results/ppo"),
                        help="run directory: model.zip, vecnormalize.pkl, training.md (default: %(default)s)")
    parser.add_argument("--resume", action="store_true",
                        help="continue from <out>/model.zip (and its VecNormalize stats) up to --timesteps in all")
    parser.add_argument("--checkpoint-freq", type=int, default=100_000,
                        help="replace <out>/model.zip and vecnormalize.pkl every so many steps (default: %(default)s)")
    parser.add_argument("--tensorboard-log", type=Path, default=Path("runs"),
                        help="TensorBoard log directory (default: %(default)s)")
    parser.add_argument("--progress-bar", action=argparse.BooleanOptionalAction, default=True,
                        help="show SB3's progress bar (default: on)")
    return parser.parse_args(argv)


def load_hyperparams(path: Path) -> dict[str, Any]:
    """The ``ENV_ID`` section of an rl-zoo3-style yml, expressions in ``STRING_KWARGS`` evaluated."""
    with open(path) as file:
        document = yaml.safe_load(file)
    if not isinstance(document, dict) or ENV_ID not in document:
        raise ValueError(f"hyperparams = {str(path)!r}: needs a top-level key {ENV_ID!r}")
    hyperparams = dict(document[ENV_ID])
    allowed = RUN_KEYS | (set(inspect.signature(PPO).parameters) - {"env", "seed", "tensorboard_log", "device"})
    for key, value in hyperparams.items():
        if key not in allowed:
            raise ValueError(f"hyperparams {ENV_ID}.{key} = {value!r}: unknown; allowed: {sorted(allowed)}")
        if key in STRING_KWARGS and isinstance(value, str):
            try:
                hyperparams[key] = eval(value, {"__builtins__": {}}, {"dict": dict, "nn": torch.nn})
            except Exception as error:
                raise ValueError(f"hyperparams {ENV_ID}.{key} = {value!r}: not an expression ({error})") from error
    for key in ("n_envs", "n_timesteps", "policy"):
        if key not in hyperparams:
            raise ValueError(f"hyperparams {ENV_ID}.{key}: missing")
    return hyperparams


def save_run(model: PPO, out: Path) -> None:
    """Write model.zip (and vecnormalize.pkl) in ``out``, each replaced atomically."""
    model.save(out / f"{MODEL_FILE}.tmp.zip")
    os.replace(out / f"{MODEL_FILE}.tmp.zip", out / MODEL_FILE)
    if isinstance(model.get_env(), VecNormalize):
        model.get_env().save(out / f"{VECNORMALIZE_FILE}.tmp")
        os.replace(out / f"{VECNORMALIZE_FILE}.tmp", out / VECNORMALIZE_FILE)


class Checkpoint(BaseCallback):
    """Replace the run's model.zip and vecnormalize.pkl every ``every`` environment steps."""

    def __init__(self, every: int, out: Path) -> None:
        super().__init__()
        self.every, self.out = every, out
        self.last = 0  # timestep count of the last checkpoint

    def _on_training_start(self) -> None:
        self.last = self.num_timesteps

    def _on_step(self) -> bool:
        if self.num_timesteps - self.last >= self.every:
            save_run(self.model, self.out)
            self.last = self.num_timesteps
        return True


class EpisodeSummaries(BaseCallback):
    """Log the ``episode_summary`` of finished episodes to TensorBoard (``episode/...``, mean per rollout)."""

    def _on_step(self) -> bool:
        for info in self.locals["infos"]:
            for name in SUMMARY_KEYS & info.get("episode_summary", {}).keys():
                self.logger.record_mean(f"episode/{name}", float(info["episode_summary"][name]))
        return True


def mean_return(act: Callable[[np.ndarray], np.ndarray], env_kwargs: dict[str, Any]) -> float:
    """Mean return of one episode in each of ``EVAL_EPISODES`` platoons seeded ``EVAL_SEED + i``."""
    env = TimeGapVecEnv(EVAL_EPISODES, **env_kwargs)
    env.seed(EVAL_SEED)
    obs = env.reset()
    returns = np.full(EVAL_EPISODES, np.nan)
    while np.isnan(returns).any():
        obs, _, dones, infos = env.step(act(obs))
        for i in np.flatnonzero(dones & np.isnan(returns)):
            returns[i] = infos[i]["episode"]["r"]
    env.close()
    return float(returns.mean())


def main(argv: list[str] | None = None) -> None:
    started = time.perf_counter()
    args = parse_args(argv)
    hyperparams = load_hyperparams(args.hyperparams)  # what is left after the pops below goes to PPO
    n_envs = args.n_envs or int(hyperparams["n_envs"])
    total_timesteps = args.timesteps or int(hyperparams["n_timesteps"])
    del hyperparams["n_envs"], hyperparams["n_timesteps"]
    policy = hyperparams.pop("policy")
    normalize = hyperparams.pop("normalize", False)
    env_kwargs = hyperparams.pop("env_kwargs", None) or {}
    warmup = hyperparams.pop("warmup", None)
    if warmup is not None and (not isinstance(warmup, dict) or set(warmup) != {"n_timesteps", "env_kwargs"}
                               or not 0 < int(warmup["n_timesteps"]) < total_timesteps):
        raise ValueError(f"hyperparams {ENV_ID}.warmup = {warmup!r}: needs env_kwargs and n_timesteps "
                         f"in (0, timesteps = {total_timesteps})")
    # Phases (end [total steps], env_kwargs): the warm-up's coarser decisions, then the env as evaluated.
    phases = [(int(warmup["n_timesteps"]), warmup["env_kwargs"])] if warmup else []
    phases.append((total_timesteps, env_kwargs))
    if n_envs < 1:
        raise ValueError(f"n_envs = {n_envs}: must be >= 1")
    if total_timesteps < 1:
        raise ValueError(f"timesteps = {total_timesteps}: must be >= 1")
    if args.checkpoint_freq < 1:
        raise ValueError(f"checkpoint_freq = {args.checkpoint_freq}: must be >= 1")
    if not 0 <= args.seed <= EVAL_SEED_START - len(phases) * n_envs:
        raise ValueError(f"seed = {args.seed}: sub-env seeds seed .. seed + {len(phases) * n_envs - 1} "
                         f"must lie in [0, {EVAL_SEED_START})")
    if not isinstance(normalize, (bool, dict)):
        raise ValueError(f"hyperparams {ENV_ID}.normalize = {normalize!r}: "
                         "must be true, false or a dict of VecNormalize arguments")
    # One thread: the network is tiny, the 2 cores are better left to the env (two threads measured 7x slower).
    torch.set_num_threads(1)
    args.out.mkdir(parents=True, exist_ok=True)

    # ---------------------------------------------------------------- model
    model_path, stats_path = args.out / MODEL_FILE, args.out / VECNORMALIZE_FILE
    model: PPO | None = None
    if args.resume:
        if not model_path.is_file():
            raise FileNotFoundError(f"--resume: no checkpoint {model_path}")
        if normalize and not stats_path.is_file():
            raise FileNotFoundError(f"--resume with normalize = {normalize!r}: no statistics {stats_path}")
        model = PPO.load(model_path, device="cpu", tensorboard_log=str(args.tensorboard_log))
        model.set_random_seed(args.seed)
        if model.num_timesteps >= total_timesteps:
            raise ValueError(f"--resume: {model_path} has trained {model.num_timesteps} steps, "
                             f"already >= timesteps = {total_timesteps}")
        if model.n_envs != n_envs:
            raise ValueError(f"--resume: n_envs = {n_envs}, but {model_path} was trained with {model.n_envs}")
    else:
        (args.out / REPORT_FILE).unlink(missing_ok=True)  # rewritten when this run ends
        stats_path.unlink(missing_ok=True)  # a stale one would mislead the evaluation
    steps_before = model.num_timesteps if model else 0

    # ---------------------------------------------------------------- train, phase by phase
    env: VecEnv | None = None
    timings: list[tuple[str, int, float]] = []  # (phase, steps, seconds)
    for phase, (phase_end, phase_env_kwargs) in enumerate(phases):
        if model is not None and model.num_timesteps >= phase_end:
            continue
        phase_env: VecEnv = TimeGapVecEnv(n_envs, **phase_env_kwargs)
        if normalize and env is None and args.resume:
            phase_env = VecNormalize.load(str(stats_path), phase_env)
        elif normalize:
            phase_env = VecNormalize(phase_env, gamma=model.gamma if model else hyperparams.get("gamma", 0.99),
                                     **({} if normalize is True else normalize))
            if isinstance(env, VecNormalize):  # features and per-step rewards (means over ticks) keep their scale
                phase_env.obs_rms, phase_env.ret_rms = env.obs_rms.copy(), env.ret_rms.copy()
        if env is not None:
            env.close()
        env = phase_env
        if model is None:
            model = PPO(policy, env, seed=args.seed, device="cpu", tensorboard_log=str(args.tensorboard_log),
                        **hyperparams)
        else:
            model.set_env(env)
        env.seed(args.seed + phase * n_envs)
        phase_start, clock = model.num_timesteps, time.perf_counter()
        model.learn(
            total_timesteps=phase_end - model.num_timesteps,
            callback=[Checkpoint(args.checkpoint_freq, args.out), EpisodeSummaries()],
            tb_log_name="ppo",
            reset_num_timesteps=not args.resume and not timings,
            progress_bar=args.progress_bar,
        )
        label = f"warm-up, {phase_env_kwargs}" if phase < len(phases) - 1 else "main"
        timings.append((label, model.num_timesteps - phase_start, time.perf_counter() - clock))
    assert model is not None and env is not None  # the last phase always trains: total_timesteps > steps_before
    save_run(model, args.out)

    # ---------------------------------------------------------------- check and report
    normalize_obs = env.normalize_obs if isinstance(env, VecNormalize) else (lambda obs: obs)
    learned = mean_return(lambda obs: model.predict(normalize_obs(obs), deterministic=True)[0], env_kwargs)
    reference_level = int(np.argmin(np.abs(np.asarray(env.unwrapped.config.setting_levels) - REFERENCE_SETTING)))
    reference = mean_return(lambda obs: np.full((len(obs), *env.action_space.shape), reference_level), env_kwargs)
    episodes = [info["r"] for info in model.ep_info_buffer]
    final_return = f"{np.mean(episodes):.1f}" if episodes else "n/a (no episode ended)"
    command = shlex.join(["python", "-m", "train.train_ppo", *(sys.argv[1:] if argv is None else argv)])
    phase_rows = "\n".join(f"| {label}: steps, time, throughput | {steps:,}, {seconds:.0f} s, "
                           f"{steps / seconds:,.0f} steps/s |" for label, steps, seconds in timings)
    files = f"`{MODEL_FILE}`" + (f", `{VECNORMALIZE_FILE}`" if isinstance(env, VecNormalize) else "")
    report = f"""# PPO on {ENV_ID}

Command: `{command}` ({f"resumed from a checkpoint at {steps_before:,} steps" if args.resume else "fresh run"})

| | |
|---|---|
| timesteps, this command / total | {model.num_timesteps - steps_before:,} / {model.num_timesteps:,} |
| platoons (n_envs), seed | {n_envs}, {args.seed} (phase k, sub-env i: seed + k n_envs + i) |
| hyperparameters | `{args.hyperparams}` |
| wall time, whole command after imports | {time.perf_counter() - started:.0f} s |
{phase_rows}
| final mean episode return, last {len(episodes)} training episodes (stochastic policy) | {final_return} |
| mean return, deterministic policy, {EVAL_EPISODES} episodes seeded {EVAL_SEED}+ | {learned:.1f} |
| mean return, constant {REFERENCE_SETTING} s, same episodes | {reference:.1f} |

Files: {files}, this report; TensorBoard logs in `{args.tensorboard_log}/`.
"""
    (args.out / REPORT_FILE).write_text(report)
    env.close()
    print(report)


if __name__ == "__main__":
    main()
