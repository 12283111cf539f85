"""TimeGapMonitor: a platoon simulator, a Bayesian time-gap monitor, control charts, and the
Gymnasium environments built from them (registered on import: every task of :mod:`timegap_env.tasks`, one record
per id; ``DEFAULT_TASK`` is the default).

The package follows the data flow, one folder a stage:

- :mod:`timegap_env.config`: every default, with units (the one source of truth);
- :mod:`timegap_env.tasks`: the tasks, one record per registered id (config, info layout, seeds, held-out groups);
- :mod:`timegap_env.leaders`: the human-driven leader (synthetic families, NGSIM, highway-env's IDM);
- :mod:`timegap_env.sim`: the platoon's physics, string stability, ``simulate(...) -> Trajectory``;
- :mod:`timegap_env.monitoring`: sensors, the Bayesian monitor, control charts, the monitored loop;
- :mod:`timegap_env.envs`: the task, observation, reward, the env and vector env, rendering, the SB3 adapter.

What users call is importable from here.
"""

import logging
import os
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

from gymnasium.envs.registration import register, registry

try:
    __version__: str = version("timegap_env")  # the one source is pyproject.toml's [project] version
except PackageNotFoundError:  # a clone on sys.path that was never installed
    __version__ = "0+unknown"

_log = logging.getLogger("timegap_env")


def _say_when_compiling() -> None:
    """numba compiles the kernels at their first call and caches them where its locators say (``NUMBA_CACHE_DIR``;
    else ``__pycache__`` beside the sources, or numba's user-wide cache where those are read-only): say so while
    the env's fused step is cached in none of them, so that the first run's wait is not a mystery.

    Said through the ``timegap_env`` logger at WARNING level, never printed: with logging unconfigured, Python's
    last-resort handler shows it on stderr; ``logging.getLogger("timegap_env").setLevel(logging.ERROR)`` before the
    import silences it."""
    kernel = "step_kernel.fused_step-*.nbi"
    cached: list[Path]
    if os.environ.get("NUMBA_CACHE_DIR"):
        cached = list(Path(os.environ["NUMBA_CACHE_DIR"]).glob(f"envs_*/{kernel}"))
    else:
        from numba.misc.appdirs import AppDirs

        user_wide = Path(AppDirs(appname="numba", appauthor=False).user_cache_dir)
        in_tree = Path(__file__).parent / "envs" / "__pycache__"  # numba uses it only where it may write there
        cached = [*(in_tree.glob(kernel) if os.access(in_tree, os.W_OK) else []), *user_wide.glob(f"envs_*/{kernel}")]
    if not cached:
        _log.warning("timegap_env: the first run compiles the simulator's kernels (about 10 CPU-seconds, "
                     "cached for every later run)")


_say_when_compiling()  # before the imports below, some of which compile a kernel

from timegap_env.config import (
    MONITOR_PRESETS, AggressiveCyclesConfig, ChartConfig, DegradationConfig, EnvConfig, HardBrakingConfig,
    HumanLeaderConfig, LeaderConfig, MonitorConfig, PlatoonConfig, RewardScales, RewardWeights, SensorConfig,
    SinusoidConfig, StochasticHumanConfig,
)
from timegap_env.leaders import (
    SCENARIOS, LeaderFamily, LeaderProfile, OpenAccRun, aggressive_cycles, default_ngsim_path, default_openacc_dir,
    hard_braking, idm_leader, make_leader, openacc_paths, read_ngsim, read_openacc, register_family, sinusoid,
    stochastic_human, vehicle_ids, vehicle_profile,
)
from timegap_env.monitoring import TimeGapEstimate, TimeGapMonitor, estimate_time_gap, posterior
from timegap_env.sim import (
    COMMERCIAL_ACC, Trajectory, acc_platoon, acc_presets, platoon_string_stability, simulate, string_stability,
)

from timegap_env.tasks import DEFAULT_TASK, TASKS, Task, get_task

ENV_ID = list(TASKS)[0]  # the first task, kept bit for bit; a config given as a dict overrides its defaults
LATEST_ENV_ID = list(TASKS)[-1]  # the newest task
MO_ENV_ID = "mo-TimeGapMonitor-v1"  # DEFAULT_TASK with the reward terms as a vector (MO-Gymnasium's API)

# The id is the task: its record gives the env everything (the env refuses another task_id under it). No
# max_episode_steps: the env truncates itself at EnvConfig.episode_duration. No passive env checker: the tests run
# gymnasium's check_env, and the checker (gymnasium 1.2-1.4) breaks every step() after a reset() that raised (e.g. on a
# bad option) with "cannot unpack non-iterable NoneType object", even after a good reset.
for _id in TASKS:
    if _id not in registry:
        register(id=_id, disable_env_checker=True, entry_point="timegap_env.envs.env:TimeGapMonitorEnv",
                 vector_entry_point="timegap_env.envs.vector_env:TimeGapMonitorVectorEnv", kwargs={"task_id": _id})
if MO_ENV_ID not in registry:
    register(id=MO_ENV_ID, disable_env_checker=True, entry_point="timegap_env.envs.mo_env:MOTimeGapMonitorEnv",
             kwargs={"task_id": DEFAULT_TASK})

__all__ = [
    "__version__", "COMMERCIAL_ACC", "ENV_ID", "DEFAULT_TASK", "LATEST_ENV_ID", "MO_ENV_ID", "MONITOR_PRESETS", "SCENARIOS", "AggressiveCyclesConfig", "ChartConfig", "DegradationConfig", "EnvConfig",
    "HardBrakingConfig", "HumanLeaderConfig", "LeaderConfig", "LeaderFamily", "LeaderProfile", "MonitorConfig", "OpenAccRun",
    "PlatoonConfig", "RewardScales", "RewardWeights", "SensorConfig", "SinusoidConfig", "StochasticHumanConfig", "TASKS", "Task", "TimeGapEstimate", "TimeGapMonitor",
    "Trajectory", "acc_platoon", "acc_presets", "aggressive_cycles", "default_ngsim_path", "default_openacc_dir", "estimate_time_gap", "get_task", "hard_braking", "idm_leader",
    "make_leader", "openacc_paths", "platoon_string_stability", "posterior", "read_ngsim", "read_openacc", "register_family", "simulate",
    "sinusoid", "stochastic_human", "string_stability", "vehicle_ids", "vehicle_profile",
]
