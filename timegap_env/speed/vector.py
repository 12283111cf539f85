"""The native vector env at growing sizes, for ``train.bench``: env-steps/s, peak memory per env and batched reset.

Each size gets a fresh native vector env (what ``gym.make_vec("TimeGapMonitor-v0",
vectorization_mode="vector_entry_point")`` builds) in this process, random actions, one core (numba's kernels are single-threaded). Stepping is timed within episodes: the
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
from collections.abc import Callable
from pathlib import Path

import numpy as np

from timegap_env.compiled import collection_paused
from timegap_env.config import EnvConfig
from timegap_env.envs.episodes import LEADER_BATCH
from timegap_env.envs.vector_env import TimeGapMonitorVectorEnv
from timegap_env.generators import generators
from timegap_env.leaders.scenarios import make_leaders

TRACED_STEPS = 3  # steps taken under tracemalloc after the reset, so that the peak covers stepping too
ACTION_POOL = 16  # distinct random action batches cycled while timing (sampled beforehand, not timed)
TRACE_BUDGET = 60.0  # longest traced set-up (build, reset, TRACED_STEPS steps) allowed, extrapolated [s]
SEEDING_RUNS = 5  # runs of each way of making generators, the best kept
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


def make_native(n_envs: int, step_diagnostics: bool) -> TimeGapMonitorVectorEnv:
    """The native vector env of n_envs platoons."""
    return TimeGapMonitorVectorEnv(num_envs=n_envs, step_diagnostics=step_diagnostics, autoreset_mode="same_step")


class Stepper:
    """Times steps of one vector env under random actions, turn by turn, within episodes: before a step would
    reach the episode limit, the env is reset (untimed) with the next seed."""

    def __init__(self, envs: TimeGapMonitorVectorEnv, since_reset: int) -> None:
        self.envs = envs
        envs.action_space.seed(0)
        self.actions = [envs.action_space.sample() for _ in range(ACTION_POOL)]
        self.limit = int(envs.max_episode_steps)
        self.since_reset = since_reset  # steps since the last reset
        self.resets = 0
        self.steps = 0  # timed, over all turns
        self.seconds = 0.0  # [s]

    def turn(self, min_seconds: float, min_steps: int) -> None:
        """Step at least min_steps times and for at least min_seconds more [s]."""
        seconds, steps = 0.0, 0
        while steps < min_steps or seconds < min_seconds:
            if self.since_reset >= self.limit - 1:
                self.resets += 1
                self.envs.reset(seed=self.resets)
                self.since_reset = 0
            start = time.perf_counter()
            self.envs.step(self.actions[self.steps % ACTION_POOL])
            seconds += time.perf_counter() - start
            steps += 1
            self.steps += 1
            self.since_reset += 1
        self.seconds += seconds

    @property
    def env_steps_per_second(self) -> float:
        """Sub-envs x timed steps per second of them [1/s]."""
        return self.steps * self.envs.num_envs / self.seconds


def set_up(n_envs: int, step_diagnostics: bool, trace: bool, time_reset: bool) -> tuple[Stepper, VectorRun]:
    """Build, reset and step the env TRACED_STEPS times (traced if ``trace``), then time one reset if
    ``time_reset``; its stepper and its figures, the stepping rate still 0."""
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
    rss = None
    if rss_before is not None:
        peak = resident_kib("VmHWM")
        assert peak is not None  # /proc/self/status gave rss_before
        rss = (peak - rss_before) / 1024
    since_reset, reset_seconds = TRACED_STEPS, None
    if time_reset:
        start = time.perf_counter()
        envs.reset(seed=0)
        reset_seconds = time.perf_counter() - start
        since_reset = 0
    return Stepper(envs, since_reset), VectorRun(n_envs, 0.0, set_up_seconds, traced, rss, reset_seconds)


def measure_sizes(sizes: tuple[int, ...], reset_sizes: tuple[int, ...], step_diagnostics: bool, min_seconds: float,
                  min_steps: int, rounds: int) -> list[VectorRun]:
    """Set up every size in turn, tracing while the traced set-up, extrapolated linearly from the size before,
    stays within TRACE_BUDGET; then time their stepping over ``rounds`` rounds, the sizes taking turns (so that a
    slow spell of a shared machine hits all of them), min_seconds [s] and min_steps in all per size."""
    if rounds < 1:
        raise ValueError(f"rounds = {rounds}: must be >= 1")
    steppers: list[Stepper] = []
    runs: list[VectorRun] = []
    for n in sizes:
        trace = not runs or (runs[-1].traced_mib is not None
                             and runs[-1].set_up_seconds * n / runs[-1].n_envs <= TRACE_BUDGET)
        print(f"bench: native vector env, {n} envs{'' if trace else ', not traced'}", file=sys.stderr, flush=True)
        stepper, run = set_up(n, step_diagnostics, trace, n in reset_sizes)
        steppers.append(stepper)
        runs.append(run)
    for _ in range(rounds):
        for stepper in steppers:
            stepper.turn(min_seconds / rounds, -(-min_steps // rounds))
    for stepper in steppers:
        stepper.envs.close()
    return [dataclasses.replace(run, env_steps_per_second=stepper.env_steps_per_second)
            for run, stepper in zip(runs, steppers)]


def seeding_seconds(n: int, seed: int = 0) -> tuple[float, float]:
    """Seconds to make (and hold) n generators seeded ``seed + i`` with :func:`timegap_env.generators.generators` and
    with ``np.random.default_rng`` one by one, both with the garbage collector paused (as ``generators`` pauses it),
    each the best of SEEDING_RUNS runs [s]."""
    seeds = list(range(seed, seed + n))

    def seconds(make: Callable[[], list[np.random.Generator]]) -> float:
        with collection_paused():
            start = time.perf_counter()
            made = make()
            elapsed = time.perf_counter() - start
        del made
        return elapsed

    ours, numpys = (min(seconds(make) for _ in range(SEEDING_RUNS))
                    for make in (lambda: generators(seeds), lambda: [np.random.default_rng(s) for s in seeds]))
    return ours, numpys


def leaders_seconds(n: int, seed: int = 0) -> float:
    """Seconds to build the leaders of n envs of the default mix (``EnvConfig.scenario_weights``), each family its
    share of them (rounded so that the shares add up to n), in batches of LEADER_BATCH as a reset builds them (every
    sample of every profile drawn and integrated): the part of a batched reset that is arithmetic on the profiles
    rather than per-env bookkeeping [s]."""
    config = EnvConfig()
    weights = config.scenario_weights
    bounds = np.rint(n * np.cumsum([0.0, *weights.values()]) / sum(weights.values())).astype(int)
    start = time.perf_counter()
    for family, first, last in zip(weights, bounds[:-1], bounds[1:]):
        for batch in range(seed + first, seed + last, LEADER_BATCH):
            make_leaders(family, list(range(batch, min(batch + LEADER_BATCH, seed + last))), config.leader)
    return time.perf_counter() - start
