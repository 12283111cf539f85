"""The native vector env at growing sizes, for ``train.bench``: env-steps/s, peak memory per env and batched reset.

Each size gets a fresh ``gym.make_vec("TimeGapMonitor-v0", vectorization_mode="vector_entry_point")`` in this
process, random actions, one core (numba's kernels are single-threaded). Stepping is timed within episodes: the
envs are reset before the episode limit, so that the synchronised end of every episode (all sub-envs reset in
the same step) does not land in some sizes' timing and not in others'; batched resets are timed on their own.
"""

from __future__ import annotations

import dataclasses
import gc
import time
import tracemalloc

import gymnasium as gym
import numpy as np

from timegap_env import ENV_ID

TRACED_STEPS = 3  # steps taken under tracemalloc after the reset, so that the peak covers stepping too
ACTION_POOL = 16  # distinct random action batches cycled while timing (sampled beforehand, not timed)


@dataclasses.dataclass(frozen=True)
class VectorRun:
    """One size's figures."""

    n_envs: int
    env_steps_per_second: float  # sub-envs x steps per second of stepping [1/s]
    peak_mib: float  # tracemalloc peak of building, resetting and stepping the env [MiB]
    reset_seconds: float | None  # one envs.reset(seed=0) of the stepped env [s]; None when not asked for

    @property
    def kib_per_env(self) -> float:
        """Peak memory per sub-env [KiB]."""
        return self.peak_mib * 1024 / self.n_envs


def make_native(n_envs: int, step_diagnostics: bool) -> gym.vector.VectorEnv:
    """The native vector env of n_envs platoons."""
    return gym.make_vec(ENV_ID, num_envs=n_envs, vectorization_mode="vector_entry_point",
                        step_diagnostics=step_diagnostics)


def stepping_rate(envs: gym.vector.VectorEnv, since_reset: int, min_seconds: float, min_steps: int) -> float:
    """Env-steps/s of ``envs`` under random actions, over at least min_steps steps and min_seconds of stepping.

    ``since_reset``: steps the envs took since their last reset. Before a step would reach the episode limit,
    the envs are reset (untimed) with the next seed.
    """
    envs.action_space.seed(0)
    actions = [envs.action_space.sample() for _ in range(ACTION_POOL)]
    limit = int(envs.max_episode_steps)
    seconds, steps, resets = 0.0, 0, 0
    while steps < min_steps or seconds < min_seconds:
        if since_reset >= limit - 1:
            resets += 1
            envs.reset(seed=resets)
            since_reset = 0
        start = time.perf_counter()
        envs.step(actions[steps % ACTION_POOL])
        seconds += time.perf_counter() - start
        steps += 1
        since_reset += 1
    return steps * envs.num_envs / seconds


def measure(n_envs: int, step_diagnostics: bool, time_reset: bool, min_seconds: float, min_steps: int) -> VectorRun:
    """Peak memory (traced), then, untraced, the time of one reset (if ``time_reset``) and the stepping rate."""
    gc.collect()
    tracemalloc.start()
    try:
        envs = make_native(n_envs, step_diagnostics)
        envs.reset(seed=0)
        for _ in range(TRACED_STEPS):
            envs.step(envs.action_space.sample())
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    since_reset, reset_seconds = TRACED_STEPS, None
    if time_reset:
        start = time.perf_counter()
        envs.reset(seed=0)
        reset_seconds = time.perf_counter() - start
        since_reset = 0
    rate = stepping_rate(envs, since_reset, min_seconds, min_steps)
    envs.close()
    return VectorRun(n_envs, rate, peak / 2**20, reset_seconds)


def generators_seconds(n: int, seed: int = 0) -> float:
    """Seconds to create (and hold) n NumPy generators ``np.random.default_rng(seed + i)``: the floor of seeding
    n envs one generator each, a reference for the batched reset [s]."""
    start = time.perf_counter()
    generators = [np.random.default_rng(seed + i) for i in range(n)]
    seconds = time.perf_counter() - start
    del generators
    return seconds
