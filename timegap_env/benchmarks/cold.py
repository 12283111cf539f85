"""Cold start, for ``train.bench``: the time from ``python -c`` to the first ``env.step`` returning, in a child process.

The child imports gymnasium (and ``timegap_env``), makes the env, resets it, takes one random step and prints
its CPU seconds so far (``time.process_time()``: interpreter start-up, imports, numba's compilation or cache
loading, the step) and the wall seconds since the parent launched it. ``NUMBA_CACHE_DIR`` points the child at a
cache directory of the parent's choosing: a fresh, empty one for the cold run, the same one again for a warm
run. The reference child does the same with gymnasium's ``CartPole-v1``.
"""

from __future__ import annotations

import dataclasses
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]  # the repository: timegap_env/benchmarks/cold.py -> .
CHILD = """\
import sys, time
import gymnasium as gym
{imports}
env = gym.make({env_id!r})
env.reset(seed=0)
env.step(env.action_space.sample())
print(time.process_time(), time.time() - float(sys.argv[1]))
"""


@dataclasses.dataclass(frozen=True)
class FirstStep:
    """CPU and wall seconds from a child's start to its first step returning."""

    cpu_seconds: float  # the child's user + system time [s]
    wall_seconds: float  # [s]


@dataclasses.dataclass(frozen=True)
class ColdStart:
    """The figures of ``measure``."""

    cold: FirstStep  # TimeGapMonitor-v0, empty numba cache
    warm: FirstStep  # TimeGapMonitor-v0, the cache the cold run filled (median of the runs)
    reference: FirstStep  # CartPole-v1 (median of the runs)
    compiled: int  # numba functions the cold run compiled and cached (.nbi index files)


def first_step(env_id: str, imports: str, cache_dir: Path) -> FirstStep:
    """Run one child with NUMBA_CACHE_DIR = cache_dir; its first step's CPU and wall seconds."""
    code = CHILD.format(imports=imports, env_id=env_id)
    environment = {**os.environ, "NUMBA_CACHE_DIR": str(cache_dir)}
    launched = time.time()
    result = subprocess.run([sys.executable, "-c", code, repr(launched)], cwd=REPO, env=environment,
                            capture_output=True, text=True, check=False)
    if result.returncode != 0:
        raise RuntimeError(f"cold-start child for {env_id} exited with {result.returncode}: {result.stderr[-2000:]}")
    last = result.stdout.strip().splitlines()[-1]
    try:
        cpu, wall = (float(word) for word in last.split())
    except ValueError as error:
        raise RuntimeError(f"cold-start child for {env_id}: last line {last!r} is not 'cpu wall'") from error
    return FirstStep(cpu, wall)


def median(runs: list[FirstStep]) -> FirstStep:
    """Median CPU and wall seconds of several runs (each taken on its own)."""
    return FirstStep(statistics.median(run.cpu_seconds for run in runs),
                     statistics.median(run.wall_seconds for run in runs))


def measure(env_id: str, repeats: int) -> ColdStart:
    """One cold run of env_id (``timegap_env`` imported) on an empty numba cache, ``repeats`` warm runs on the
    cache it filled and ``repeats`` CartPole-v1 runs, warm and reference runs taking turns."""
    if repeats < 1:
        raise ValueError(f"repeats = {repeats}: must be >= 1")
    with tempfile.TemporaryDirectory(prefix="bench_numba_cache_") as directory:
        cache = Path(directory)
        cold = first_step(env_id, "import timegap_env", cache)
        compiled = sum(1 for _ in cache.rglob("*.nbi"))
        warm, reference = [], []
        for _ in range(repeats):
            warm.append(first_step(env_id, "import timegap_env", cache))
            reference.append(first_step("CartPole-v1", "", cache))
    return ColdStart(cold, median(warm), median(reference), compiled)
