"""Compile the kernels a first step needs into numba's cache, ahead of that step: ``python -m timegap_env.precompile``.

Building the wheel runs it (``pip install .``, ``pip wheel``, ``python -m build``: the package's build backend,
``build_backend/timegap_build.py``), on the built copy of the package, so that the wheel carries the cache in its
``__pycache__`` folders and the first ``env.step`` after installing it loads the kernels instead of compiling them
(about 1 CPU-second instead of about 12: ``make bench``'s cold start). numba uses that cache where the installed
package's folders are writable, ``NUMBA_CACHE_DIR`` is unset, and the Python minor version, the numba release and
the CPU are the build's (numba keys each kernel by CPU name and features and drops an index another release
wrote; pip's isolated build takes the newest numba, ``pip install --no-build-isolation .`` the venv's own);
anywhere else the first step compiles, as it would without it.

It makes, resets and steps ``TimeGapMonitor-v0`` and ``-v1``, one env and a native vector env of each (what
``gym.make`` and ``gym.make_vec`` give), behind every leader family that draws its episodes in a batch (the
synthetic ones, whichever ``scenario_weights`` picks), which compiles every kernel their steps and resets run.
Other paths (SUMO's step halves, the components' own methods, ``truth_info``, the detectors, calibration) compile at
their first use, as before.
"""

from __future__ import annotations

import os
import sys
import time
import warnings
from pathlib import Path

import gymnasium as gym
from numba.core.dispatcher import Dispatcher

from timegap_env.tasks import TASKS
from timegap_env.leaders.scenarios import LEADER_FAMILIES

STEPS = 3  # steps after each reset: the first compiles the step, the rest check it runs


def precompile() -> int:
    """Make, reset and step every env version, single and vectorised, behind each batched leader family; the
    number of numba cache index files (``*.nbi``) the package's ``__pycache__`` folders then hold."""
    batched = [name for name, family in LEADER_FAMILIES.items() if family.batch is not None]
    warnings.filterwarnings("ignore", message=".*is out of date", category=DeprecationWarning)  # v0, on purpose
    for env_id in TASKS:
        for family in batched:
            config = {"scenario_weights": {family: 1.0}}
            env = gym.make(env_id, config=config)
            env.reset(seed=0)
            for _ in range(STEPS):
                env.step(env.action_space.sample())
            vector = gym.make_vec(env_id, num_envs=2, vectorization_mode="vector_entry_point", config=config)
            vector.reset(seed=0)
            for _ in range(STEPS):
                vector.step(vector.action_space.sample())
    return sum(1 for _ in Path(__file__).parent.rglob("__pycache__/*.nbi"))


def compiled_not_loaded() -> list[str]:
    """The package's kernels that this process compiled rather than loaded from numba's cache (``module.name``):
    none, after a first step from an installed wheel whose cache is used."""
    return sorted(f"{name}.{kernel.py_func.__name__}" for name, module in list(sys.modules.items())
                  if name.split(".")[0] == __package__ for kernel in vars(module).values()
                  if isinstance(kernel, Dispatcher) and kernel.py_func.__module__ == name
                  and sum(kernel.stats.cache_misses.values()) > 0)


def main() -> None:
    """Precompile into the package's own ``__pycache__`` folders; refused while ``NUMBA_CACHE_DIR`` sends the cache
    elsewhere."""
    if os.environ.get("NUMBA_CACHE_DIR"):
        sys.exit(f"python -m timegap_env.precompile: NUMBA_CACHE_DIR={os.environ['NUMBA_CACHE_DIR']!r} would send the "
                 "cache there, not beside the package; unset it")
    start = time.process_time()
    indexes = precompile()
    if indexes == 0:
        sys.exit(f"python -m timegap_env.precompile: no numba cache in {Path(__file__).parent}/**/__pycache__ (is the "
                 "package's folder writable?)")
    print(f"timegap_env.precompile: {indexes} compiled kernels cached beside {Path(__file__).parent} "
          f"in {time.process_time() - start:.1f} CPU-s")


if __name__ == "__main__":
    main()
