"""The native vector env at growing sizes, for ``train.bench``: env-steps/s, peak memory per env and batched reset.

Each size gets a fresh ``gym.make_vec("TimeGapMonitor-v0", vectorization_mode="vector_entry_point")`` in this
process, random actions, one core (numba's kernels are single-threaded). Stepping is timed within episodes: the
envs are reset before the episode limit, so that the synchronised end of every episode (all sub-envs reset in
the same step) does not land in some sizes' timing and not in others'; batched resets are timed on their own.

Peak memory is tracemalloc's (Python's and NumPy's allocations). Tracing slows a reset that loops over envs in
Python several times over (more at large sizes), so a size whose traced set-up would take longer than
TRACE_BUDGET (extrapolated from the size before) is not traced; it reports the growth of the process's peak
resident memory instead (Linux: ``VmHWM``, reset through ``/proc/self/clear_refs``), measured for every size.
"""

from __future__ import annotations

import dataclasses
import gc
import sys
import time
import tracemalloc
from pathlib import Path

import gymnasium as gym
import numpy as np

from timegap_env import ENV_ID

TRACED_STEPS = 3  # steps taken under tracemalloc after the reset, so that the peak covers stepping too
ACTION_POOL = 16  # distinct random action batches cycled while timing (sampled beforehand, not timed)
TRACE_BUDGET = 60.0  # longest traced set-up (build, reset, TRACED_STEPS steps) allowed, extrapolated [s]
STATUS, CLEAR_REFS = Path("/proc/self/status"), Path("/proc/self/clear_refs")


@dataclasses.dataclass(frozen=True)
class VectorRun:
    """One size's figures."""

    n_envs: int
    env_steps_per_second: float  # sub-envs x steps per second of stepping [1/s]
    set_up_seconds: float  # building, resetting and stepping the env TRACED_STEPS times, traced or not [s]
    traced_mib: float | None  # tracemalloc peak of that set-up [MiB]; None when not traced
    rss_mib: float | None  # growth of the peak resident memory over it [MiB]; None off Linux
    reset_seconds: float | None  # one envs.reset(seed=0) of the stepped env [s]; None when not asked for


def per_env_kib(mib: float, n_envs: int) -> float:
    """MiB over n_envs envs in KiB per env."""
    return mib * 1024 / n_envs


def resident_kib(field: str) -> int | None:
    """A memory field of /proc/self/status (VmRSS, VmHWM) [KiB]; None where there is none."""
    if not STATUS.exists():
        return None
    for line in STATUS.read_text().splitlines():
        if line.startswith(f"{field}:"):
            return int(line.split()[1])
    raise RuntimeError(f"{STATUS} has no {field} line")


def restart_peak_rss() -> int | None:
    """Reset the process's peak resident memory to the current one; the current one [KiB] (None off Linux)."""
    if not CLEAR_REFS.exists():
        return None
    CLEAR_REFS.write_text("5")
    return resident_kib("VmRSS")


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


def measure(n_envs: int, step_diagnostics: bool, trace: bool, time_reset: bool, min_seconds: float,
            min_steps: int) -> VectorRun:
    """Peak memory of building, resetting and stepping the env (traced if ``trace``), then, untraced, the time of
    one reset (if ``time_reset``) and the stepping rate."""
    gc.collect()
    rss_before = restart_peak_rss()
    if trace:
        tracemalloc.start()
    start = time.perf_counter()
    try:
        envs = make_native(n_envs, step_diagnostics)
        envs.reset(seed=0)
        for _ in range(TRACED_STEPS):
            envs.step(envs.action_space.sample())
        traced = tracemalloc.get_traced_memory()[1] / 2**20 if trace else None
    finally:
        if trace:
            tracemalloc.stop()
    set_up_seconds = time.perf_counter() - start
    rss = None if rss_before is None else (resident_kib("VmHWM") - rss_before) / 1024
    since_reset, reset_seconds = TRACED_STEPS, None
    if time_reset:
        start = time.perf_counter()
        envs.reset(seed=0)
        reset_seconds = time.perf_counter() - start
        since_reset = 0
    rate = stepping_rate(envs, since_reset, min_seconds, min_steps)
    envs.close()
    return VectorRun(n_envs, rate, set_up_seconds, traced, rss, reset_seconds)


def measure_sizes(sizes: tuple[int, ...], reset_sizes: tuple[int, ...], min_seconds: float,
                  min_steps: int) -> list[VectorRun]:
    """``measure`` each size in turn (step_diagnostics=False), tracing while the traced set-up, extrapolated
    linearly from the size before, stays within TRACE_BUDGET."""
    runs: list[VectorRun] = []
    for n in sizes:
        trace = not runs or (runs[-1].traced_mib is not None
                             and runs[-1].set_up_seconds * n / runs[-1].n_envs <= TRACE_BUDGET)
        print(f"bench: native vector env, {n} envs{'' if trace else ', not traced'}", file=sys.stderr, flush=True)
        runs.append(measure(n, False, trace, n in reset_sizes, min_seconds, min_steps))
    return runs


def generators_seconds(n: int, seed: int = 0) -> float:
    """Seconds to create (and hold) n NumPy generators ``np.random.default_rng(seed + i)``: the floor of seeding
    n envs one generator each, a reference for the batched reset [s]."""
    start = time.perf_counter()
    generators = [np.random.default_rng(seed + i) for i in range(n)]
    seconds = time.perf_counter() - start
    del generators
    return seconds
