"""Where a single env's step goes: the fused kernel's call, the part of it numba spends unpacking its arguments,
and its arithmetic per env-step at 256 envs, in microseconds, all measured in this process (``make bench``). The
one env's call writes its info values as the default single env's step does; the 256 envs' write none, as the
vector env's.

Both kernels are called as the task calls the fused step, through their compiled entry for the arguments' types
(``timegap_env.compiled.compiled_entry``, without numba's dispatcher). The unpacking is timed with a kernel that
takes the same arguments and only reads one value: what numba does to turn the state's blocks (a few arrays:
``timegap_env.state``), the scratch and the rules' constants into native values at every call, whatever the kernel
then computes.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable

import numba
import numpy as np

from timegap_env.compiled import NO_ALLOCATION, compiled_entry, follow_sources
from timegap_env.envs.step_kernel import fused_step
from timegap_env.envs.vector_env import TimeGapMonitorVectorEnv


@dataclasses.dataclass(frozen=True)
class SingleEnvSplit:
    """Microseconds of a fused step's parts."""

    call: float  # one call of fused_step for one env [µs]
    unpacking: float  # one call of a kernel that only unpacks the same arguments [µs]
    arithmetic: float  # fused_step per env-step at ARITHMETIC_ENVS envs, where the call's cost is spread thin [µs]


ARITHMETIC_ENVS = 256


@numba.njit(cache=True, **NO_ALLOCATION)
def _unpack_only(blocks, scratch, rules, action, info, trace):  # noqa: ANN001, ANN202
    """Reads one value of what fused_step takes, compiled as fused_step is; its cost is numba's unpacking of the
    arguments."""
    return blocks[0][0, 0, 0]


def microseconds(call: Callable[[], object], calls: int) -> float:
    """The fastest of five timings of ``calls`` calls, per call [µs]."""
    call()  # loads (or compiles) the kernel
    best = np.inf
    for _ in range(5):
        start = time.perf_counter()
        for _ in range(calls):
            call()
        best = min(best, (time.perf_counter() - start) / calls)
    return best * 1e6


def measure(calls: int) -> SingleEnvSplit:
    """The split, each timing ``calls`` calls (a few for 256 envs)."""
    times = {}
    for n_envs in (1, ARITHMETIC_ENVS):
        env = TimeGapMonitorVectorEnv(n_envs, step_diagnostics=False, autoreset_mode="same_step")
        env.reset(seed=0)
        task = env.task
        action = task.ladder.check(np.full(task.ladder.shape, 5))
        info = task._info_block if n_envs == 1 else task._no_info  # the single env writes its info values
        arguments = (task.state.blocks, task._scratch, task.params, action, info, task._no_trace)
        step = compiled_entry(fused_step, *arguments)
        times[n_envs] = microseconds(lambda: step(*arguments), max(calls // n_envs, 2))
        if n_envs == 1:
            unpack = compiled_entry(_unpack_only, *arguments)
            unpacking = microseconds(lambda: unpack(*arguments), calls)
    return SingleEnvSplit(call=times[1], unpacking=unpacking, arithmetic=times[ARITHMETIC_ENVS] / ARITHMETIC_ENVS)


# Its kernel: numba's cache by content
follow_sources(__name__)
