"""Where PPO's time goes in the ``make train`` setting, for ``train.bench``: the env against the learner.

The model is built as ``train.train_ppo`` builds its main phase from ``hyperparams/ppo.yml`` (PPO's arguments,
``env_kwargs``, VecNormalize when ``normalize`` is on, MlpPolicy on the CPU, one torch thread) over
``TimeGapVecEnv``. Stopwatches around the env's ``step_wait`` and ``reset`` and around VecNormalize's
split ``model.learn``'s wall time into the env, the normalisation and the rest (the learner: the rollout's
policy forward passes, advantage estimation and the gradient updates).
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path
from typing import Any

import torch
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper, VecNormalize
from stable_baselines3.common.vec_env.base_vec_env import VecEnvObs, VecEnvStepReturn

from timegap_env.envs.sb3 import TimeGapVecEnv
from timegap_env.studies.training import load_hyperparams

HYPERPARAMS = Path(__file__).resolve().parents[2] / "hyperparams" / "ppo.yml"  # in a clone of the repository


class Stopwatch(VecEnvWrapper):
    """Passes everything through to ``venv`` and adds the wall time of its ``step_wait`` and ``reset`` to
    ``seconds`` [s]."""

    def __init__(self, venv: VecEnv) -> None:
        super().__init__(venv)
        self.seconds = 0.0

    def reset(self) -> VecEnvObs:
        start = time.perf_counter()
        obs = self.venv.reset()
        self.seconds += time.perf_counter() - start
        return obs

    def step_wait(self) -> VecEnvStepReturn:
        start = time.perf_counter()
        result = self.venv.step_wait()
        self.seconds += time.perf_counter() - start
        return result


@dataclasses.dataclass(frozen=True)
class PPOSplit:
    """Shares of ``model.learn``'s wall time."""

    setting: dict[str, Any]  # n_envs and PPO's arguments that set the work: n_steps, batch_size, n_epochs
    timesteps: int  # env steps timed
    seconds: float  # wall time of the timed model.learn [s]
    env_seconds: float  # in TimeGapVecEnv's step_wait and reset [s]
    normalize_seconds: float  # in VecNormalize around them (0 without normalisation) [s]

    @property
    def env_share(self) -> float:
        """Share of the time in the env [-]."""
        return self.env_seconds / self.seconds

    @property
    def normalize_share(self) -> float:
        """Share of the time in VecNormalize's own work [-]."""
        return self.normalize_seconds / self.seconds

    @property
    def learner_share(self) -> float:
        """Share of the rest: rollout forward passes, advantages, gradient updates [-]."""
        return 1.0 - self.env_share - self.normalize_share

    @property
    def steps_per_second(self) -> float:
        """PPO's env steps per second of learning [1/s]."""
        return self.timesteps / self.seconds

    @property
    def most_gain_if_env_free(self) -> float:
        """PPO throughput with a free env over today's, at most: 1 / (1 - env share) [-]."""
        return 1.0 / (1.0 - self.env_share)


def measure(rollouts: int, shrink: dict[str, int] | None = None, hyperparams: Path = HYPERPARAMS) -> PPOSplit:
    """Time ``rollouts`` rollouts and updates of PPO after one untimed rollout (torch's start-up).

    ``shrink`` overrides n_envs, n_steps, batch_size or n_epochs (for a smoke test).
    """
    if rollouts < 1:
        raise ValueError(f"rollouts = {rollouts}: must be >= 1")
    arguments = load_hyperparams(hyperparams)
    n_envs = int(arguments.pop("n_envs"))
    policy = arguments.pop("policy")
    normalize = arguments.pop("normalize", False)
    env_kwargs = arguments.pop("env_kwargs", None) or {}
    for key in ("n_timesteps", "frame_stack"):
        arguments.pop(key, None)
    for key, value in (shrink or {}).items():
        if key == "n_envs":
            n_envs = value
        elif key in ("n_steps", "batch_size", "n_epochs"):
            arguments[key] = value
        else:
            raise ValueError(f"shrink[{key!r}] = {value}: only n_envs, n_steps, batch_size and n_epochs")
    torch.set_num_threads(1)  # as train_ppo does
    env = Stopwatch(TimeGapVecEnv(n_envs, **env_kwargs))
    outer: Stopwatch = env
    if normalize:
        outer = Stopwatch(VecNormalize(env, gamma=arguments.get("gamma", 0.99),
                                       **({} if normalize is True else normalize)))
    model = PPO(policy, outer, seed=0, device="cpu", verbose=0, **arguments)
    per_rollout = n_envs * model.n_steps
    model.learn(per_rollout)
    env.seconds = outer.seconds = 0.0
    before, start = model.num_timesteps, time.perf_counter()
    model.learn(rollouts * per_rollout, reset_num_timesteps=False)
    seconds = time.perf_counter() - start
    setting = {"n_envs": n_envs, "n_steps": model.n_steps, "batch_size": model.batch_size, "n_epochs": model.n_epochs}
    normalize_seconds = outer.seconds - env.seconds if outer is not env else 0.0
    return PPOSplit(setting, model.num_timesteps - before, seconds, env.seconds, normalize_seconds)
