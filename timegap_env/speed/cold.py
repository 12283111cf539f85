"""Cold start, for ``train.bench``: the time from ``python -c`` to the first ``env.step`` returning, in a child process.

The child imports gymnasium (and ``timegap_env``), makes the env, resets it, takes one random step and prints
its CPU seconds so far (``time.process_time()``: interpreter start-up, imports, numba's compilation or cache
loading, the step) and the wall seconds since the parent launched it. ``NUMBA_CACHE_DIR`` points the child at a
cache directory of the parent's choosing: a fresh, empty one for the cold run, the same one again for a warm
run. The reference child does the same with gymnasium's ``CartPole-v1``.

The fresh-install run is what a user gets from ``pip install``: the package's wheel is built from a copy of this
tree (its build compiles the kernels into the wheel, :mod:`timegap_env.precompile`), installed into an empty
folder, and the child imports it from there with ``NUMBA_CACHE_DIR`` unset, as a user's would be.
"""

from __future__ import annotations

import dataclasses
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]  # the repository: timegap_env/speed/cold.py -> .
SOURCES = ("pyproject.toml", "README.md", "LICENSE", "MANIFEST.in", "CHANGELOG.md", "CITATION.cff", "build_backend",
           "timegap_env")  # what a wheel is built from (an sdist's contents)
CHILD = """\
import sys, time
import gymnasium as gym
{imports}
env = gym.make({env_id!r})
env.reset(seed=0)
env.step(env.action_space.sample())
cpu, wall = time.process_time(), time.time() - float(sys.argv[1])
{after}print(cpu, wall)
"""
LOADED = """\
from timegap_env.precompile import compiled_not_loaded
assert not compiled_not_loaded(), f"compiled, not loaded from the wheel's cache: {compiled_not_loaded()}"
"""  # after the step is timed: the installed wheel's cache served every kernel the step ran


@dataclasses.dataclass(frozen=True)
class FirstStep:
    """CPU and wall seconds from a child's start to its first step returning."""

    cpu_seconds: float  # the child's user + system time [s]
    wall_seconds: float  # [s]


@dataclasses.dataclass(frozen=True)
class ColdStart:
    """The figures of ``measure``."""

    cold: FirstStep  # TimeGapMonitor-v0, empty numba cache
    installed: FirstStep  # TimeGapMonitor-v0, first run after installing the wheel (its numba cache)
    wheel_build_seconds: float  # wall time of building that wheel, its kernels' compilation included [s]
    warm: FirstStep  # TimeGapMonitor-v0, the cache the cold run filled (median of the runs)
    reference: FirstStep  # CartPole-v1 (median of the runs)
    compiled: int  # numba functions the cold run compiled and cached (.nbi index files)


def first_step(env_id: str, imports: str, cache_dir: Path | None, site: Path | None = None, after: str = ""
               ) -> FirstStep:
    """Run one child with NUMBA_CACHE_DIR = cache_dir (None: unset) and, given ``site``, the package imported from
    that folder rather than from this tree, ``after`` run after its step; its first step's CPU and wall seconds."""
    code = CHILD.format(imports=imports, env_id=env_id, after=after)
    environment = {name: value for name, value in os.environ.items() if name != "NUMBA_CACHE_DIR"}
    if cache_dir is not None:
        environment["NUMBA_CACHE_DIR"] = str(cache_dir)
    if site is not None:
        environment["PYTHONPATH"] = str(site)
    launched = time.time()
    result = subprocess.run([sys.executable, "-c", code, repr(launched)], cwd=REPO if site is None else site.parent,
                            env=environment, capture_output=True, text=True, check=False)
    if result.returncode != 0:
        raise RuntimeError(f"cold-start child for {env_id} exited with {result.returncode}: {result.stderr[-2000:]}")
    last = result.stdout.strip().splitlines()[-1]
    try:
        cpu, wall = (float(word) for word in last.split())
    except ValueError as error:
        raise RuntimeError(f"cold-start child for {env_id}: last line {last!r} is not 'cpu wall'") from error
    return FirstStep(cpu, wall)


def install_wheel(work: Path) -> tuple[Path, float]:
    """Build the package's wheel from a copy of this tree's sources in ``work`` (with this interpreter's packages:
    ``--no-build-isolation``) and install it, without dependencies, into ``work/site``; that folder and the build's
    wall seconds."""
    tree = work / "tree"
    tree.mkdir()
    for name in SOURCES:
        source = REPO / name
        if source.is_dir():
            shutil.copytree(source, tree / name, ignore=shutil.ignore_patterns("__pycache__"))
        else:
            shutil.copy2(source, tree / name)
    pip = [sys.executable, "-m", "pip", "--disable-pip-version-check", "--no-input"]
    start = time.perf_counter()
    built = subprocess.run([*pip, "wheel", "--no-deps", "--no-build-isolation", "--wheel-dir", str(work / "dist"),
                            str(tree)], capture_output=True, text=True, check=False)
    seconds = time.perf_counter() - start
    if built.returncode != 0:
        raise RuntimeError(f"building the wheel failed ({built.returncode}): "
                           f"{built.stdout[-2000:]}{built.stderr[-2000:]}")
    wheel = next((work / "dist").glob("*.whl"))
    installed = subprocess.run([*pip, "install", "--no-deps", "--target", str(work / "site"), str(wheel)],
                               capture_output=True, text=True, check=False)
    if installed.returncode != 0:
        raise RuntimeError(f"installing {wheel.name} failed ({installed.returncode}): {installed.stderr[-2000:]}")
    return work / "site", seconds


def median(runs: list[FirstStep]) -> FirstStep:
    """Median CPU and wall seconds of several runs (each taken on its own)."""
    return FirstStep(statistics.median(run.cpu_seconds for run in runs),
                     statistics.median(run.wall_seconds for run in runs))


def measure(env_id: str, repeats: int) -> ColdStart:
    """One cold run of env_id (``timegap_env`` imported) on an empty numba cache, one run after a fresh install of
    the wheel, ``repeats`` warm runs on the cache the cold run filled and ``repeats`` CartPole-v1 runs, warm and
    reference runs taking turns."""
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
    with tempfile.TemporaryDirectory(prefix="bench_fresh_install_") as directory:
        site, build_seconds = install_wheel(Path(directory))
        check = f"import timegap_env\nassert timegap_env.__file__.startswith({str(site)!r}), timegap_env.__file__"
        installed = first_step(env_id, check, None, site, after=LOADED)
    return ColdStart(cold, installed, build_seconds, median(warm), median(reference), compiled)
