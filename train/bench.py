"""``make bench``: how much the environment, its simulator and monitor cost, as ratios against reference runs.

Every figure is measured in this process (or, for the cold start, in child processes it launches), the same
way, and set against a reference measured alongside it; ratios survive a busy machine better than absolute
rates. The targets are issue 16's, raised by issue 27 (the default env against CartPole-v1, the vector env's rate).

1. single env steps/s of ``TimeGapMonitor-v0`` as ``gym.make`` gives it (the default info), with
   ``truth_info=True`` and with ``step_diagnostics=False``, against gymnasium's ``CartPole-v1``, the envs taking
   turns over several rounds in an order that rotates, then against highway-env's ``highway-fast-v0`` timed apart,
   and ``TimeGapMonitor-v1`` (the vector reward, cost, objectives and
   regime in its info) against v0 (issue 24: within 10 %); then where its step goes (:mod:`timegap_env.speed.single`): a fused
   step's call, numba's unpacking of its arguments, and its arithmetic per env-step;
2. the native vector env (``step_diagnostics=False``) from 256 to 65,536 envs on one core: env-steps/s
   against the 256-env figure and CartPole-v1's steps/s, peak memory per env (tracemalloc), 256 envs with
   the per-step diagnostics on, and 64 envs against a ``SyncVectorEnv`` of single envs;
3. batched reset, ``envs.reset(seed=0)`` at 4,096 and 65,536 envs, against creating as many NumPy generators one by
   one (the collector paused; at 65,536 also ``timegap_env.generators``' way, and the leaders alone);
4. cold start: a child process's CPU and wall seconds to its first ``env.step``: right after ``pip install`` of
   the package's wheel (whose build compiled the kernels into it), with an empty numba cache and with a warm
   one, against a child stepping CartPole-v1;
5. the share of PPO's time (``make train``'s setting) spent in the env, and the most a free env could gain;
6. the batched simulator (vehicle-ticks/s) and the batched monitor (against a NumPy add of the same arrays).

Writes ``results/bench.md``.

    python -m train.bench [--quick] [--out results/bench.md]
"""

from __future__ import annotations

import argparse
import dataclasses
import platform
import sys
import time
from collections.abc import Callable
from pathlib import Path

import gymnasium as gym
import numpy as np

import timegap_env
from timegap_env import cli
from timegap_env.config import MonitorConfig, PlatoonConfig
from timegap_env.generators import HASHED_FROM
from timegap_env.sim import Platoon
from timegap_env.speed import cold as bench_cold
from timegap_env.speed import ppo as bench_ppo
from timegap_env.speed import single as bench_single
from timegap_env.speed import vector as bench_vector
from timegap_env.speed.monitor import bench as bench_monitor

TARGET_VS_HIGHWAY = 100.0  # single env steps/s over highway-fast-v0's [-]
TARGET_VS_CARTPOLE = 0.5  # single env as gym.make gives it, steps/s over CartPole-v1's (issue 27) [-]
TARGET_V1_VS_V0 = 0.9  # TimeGapMonitor-v1's single env steps/s over v0's, default info and lean alike (issue 24) [-]
TARGET_VEHICLE_TICKS = 10e6  # batched simulator at 1024 envs [vehicle-ticks/s]
TARGET_VECTOR_RATE = 250e3  # native vector env at TARGET_VECTOR_BASE envs, one core (issue 27) [env-steps/s]
TARGET_VECTOR_BASE = 256  # envs
TARGET_VECTOR_SPREAD = 0.2  # every size's env-steps/s within this fraction of the base size's [-]
TARGET_RESET_SECONDS = 2.0  # envs.reset(seed=0) at TARGET_RESET_ENVS envs [s]
TARGET_RESET_ENVS = 65_536
TARGET_COLD_CPU = 5.0  # first step after a fresh install of the wheel [CPU s]


@dataclasses.dataclass(frozen=True)
class Sizes:
    """How long each measurement runs."""

    rounds: int  # single-env measurements alternate between the envs this many times (a multiple of their 6)
    split_calls: int  # fused-step calls timed for the single env's split (per timing)
    env_steps: int  # steps of TimeGapMonitor-v0 and CartPole-v1 per round
    highway_steps: int  # steps of highway-fast-v0 per round (far slower: the bench's row says how much)
    ticks: dict[int, int]  # simulator ticks timed per batch size, in blocks of TICKS_PER_BLOCK
    vector_sizes: tuple[int, ...]  # native vector env sizes; the first is the reference size
    vector_seconds: float  # at least this much stepping timed per size [s]
    vector_min_steps: int  # and at least this many steps
    vector_rounds: int  # the sizes take turns stepping over this many rounds
    reset_sizes: tuple[int, ...]  # sizes whose batched reset is timed (each one of vector_sizes)
    sync_envs: int  # sub-envs of the native against SyncVectorEnv comparison
    sync_steps: int
    monitor_ticks: int
    cold_repeats: int  # warm-cache and CartPole-v1 child runs (one empty-cache run)
    ppo_rollouts: int  # rollouts (with their updates) timed
    ppo_shrink: dict[str, int] | None  # overrides of hyperparams/ppo.yml's n_envs, n_steps, ... (None: as trained)


FULL = Sizes(12, 20000, 1000, 25, {1: 20000, 64: 5000, 1024: 1000}, (256, 1024, 4096, 16384, 65536), 2.0, 4, 4,
             (4096, 65536), 64, 100, 300, 3, 8, None)
QUICK = Sizes(1, 20, 20, 3, {1: 20, 64: 10, 1024: 10}, (4, 8, 16), 0.0, 2, 2, (8, 16), 4, 5, 5, 1, 1,
              {"n_envs": 4, "n_steps": 8, "batch_size": 16, "n_epochs": 1})
FAST_HYPERPARAMS = bench_ppo.HYPERPARAMS.parent / "ppo_fast.yml"  # train.choose_learner's choice (results/learner)
TICKS_PER_BLOCK = 10  # the simulator advances a decision's ticks in one call, as the env does
WARM_UP_STEPS = 20  # untimed steps first: numba kernels load (or compile) on their first call


@dataclasses.dataclass(frozen=True)
class Row:
    """One line of the table."""

    measure: str
    value: str
    reference: str = ""  # what it is set against, measured alongside
    ratio: str = ""  # value over reference
    target: str = ""  # the target and whether it is met


def say(stage: str) -> None:
    """Progress on stderr (the full run takes minutes)."""
    print(f"bench: {stage}", file=sys.stderr, flush=True)


def verdict(target: str, met: bool) -> str:
    return f"{target}: {'met' if met else 'NOT met'}"


def timed(run: Callable[[], int]) -> float:
    """Units of work per second of ``run()``, which returns how many units it did."""
    start = time.perf_counter()
    units = run()
    return units / (time.perf_counter() - start)


def env_steps_per_second(env: gym.Env, n_steps: int) -> float:
    """Steps/s of one env under uniformly random actions, resets included (the env carries on from where it was)."""

    def run() -> int:
        for _ in range(n_steps):
            _, _, terminated, truncated, _ = env.step(env.action_space.sample())
            if terminated or truncated:
                env.reset()
        return n_steps

    return timed(run)


def interleaved_steps_per_second(envs: dict[str, tuple[gym.Env, int]], rounds: int) -> dict[str, float]:
    """Steps/s of each env {name: (env, steps per round)} over all its rounds, the envs taking turns round
    by round, so that a slow spell of a shared machine hits all of them rather than one. The order rotates by one
    env each round, so that no env always runs right after the same one: an env runs its first steps with what the
    one before left in the caches (after highway-env's, slower; ``rounds`` a multiple of the number of
    envs gives each the same turns)."""
    for env, _ in envs.values():
        env.reset(seed=0)
        env.action_space.seed(0)
        env_steps_per_second(env, WARM_UP_STEPS)
    names, seconds = list(envs), dict.fromkeys(envs, 0.0)
    for round_ in range(rounds):
        shift = round_ % len(names)
        for name in names[shift:] + names[:shift]:
            env, n_steps = envs[name]
            seconds[name] += n_steps / env_steps_per_second(env, n_steps)
    return {name: rounds * n_steps / seconds[name] for name, (_, n_steps) in envs.items()}


def vector_env_steps_per_second(envs: gym.vector.VectorEnv, n_steps: int) -> float:
    """Env-steps/s (sub-envs x steps) of a vector env under random actions, autoresets included."""
    envs.reset(seed=0)
    envs.action_space.seed(0)
    envs.step(envs.action_space.sample())  # warm-up

    def run() -> int:
        for _ in range(n_steps):
            envs.step(envs.action_space.sample())
        return n_steps * envs.num_envs

    return timed(run)


def vehicle_ticks_per_second(n_envs: int, n_ticks: int) -> float:
    """Vehicle-ticks/s of the batched simulator: n_envs platoons of 1 + 5 vehicles behind a braking leader,
    advanced TICKS_PER_BLOCK ticks per call."""
    platoon = Platoon(PlatoonConfig(), n_envs)
    platoon.reset(np.full(n_envs, 25.0))
    n_blocks = max(n_ticks // TICKS_PER_BLOCK, 1)
    speeds = 25.0 - 0.1 * np.arange(1, n_blocks * TICKS_PER_BLOCK + 1)  # a gentle 1 m/s^2 deceleration
    speeds = np.repeat(speeds.reshape(n_blocks, TICKS_PER_BLOCK, 1), n_envs, axis=2)
    accels = np.full(speeds.shape[1:], -1.0)
    platoon.advance(speeds[0], accels)  # warm-up: the kernel loads on its first call

    def run() -> int:
        for block in speeds:
            platoon.advance(block, accels)
        return n_blocks * TICKS_PER_BLOCK * n_envs * (platoon.n_followers + 1)

    return timed(run)


def single_env_rows(sizes: Sizes) -> tuple[list[Row], float]:
    """Rows of measurement 1, and CartPole-v1's steps/s (the vector env's reference too)."""
    import highway_env  # noqa: F401  (registers highway-fast-v0)

    task, v0 = timegap_env.DEFAULT_TASK, timegap_env.ENV_ID
    envs = {
        "ours": (gym.make(task), sizes.env_steps),
        "truth": (gym.make(task, truth_info=True), sizes.env_steps),
        "lean": (gym.make(task, step_diagnostics=False), sizes.env_steps),
        "v0": (gym.make(v0), sizes.env_steps),
        "v0 lean": (gym.make(v0, step_diagnostics=False), sizes.env_steps),
        "cartpole": (gym.make("CartPole-v1"), sizes.env_steps),
    }
    rates = interleaved_steps_per_second(envs, sizes.rounds)
    highway_fast = {"highway": (gym.make("highway-fast-v0"), sizes.highway_steps)}  # far slower (its row says how
    highway = interleaved_steps_per_second(highway_fast, sizes.rounds)["highway"]  # much), heavy on the caches: apart
    envs.update(highway_fast)  # closed with the others below
    ours, cartpole = rates["ours"], rates["cartpole"]
    against_cartpole = f"CartPole-v1, one env: {cartpole:,.0f}"
    target = f">= {TARGET_VS_CARTPOLE}x CartPole-v1"
    rows = [
        Row(f"{task} (the default task) as gym.make gives it (default info) [steps/s]", f"{ours:,.0f}",
            against_cartpole, f"{ours / cartpole:.3f}x", verdict(target, ours / cartpole >= TARGET_VS_CARTPOLE)),
        Row(f"{task}, one env, truth_info=True (+ true state and ground truth) [steps/s]",
            f"{rates['truth']:,.0f}", against_cartpole, f"{rates['truth'] / cartpole:.3f}x", ""),
        Row(f"{task}, one env, step_diagnostics=False [steps/s]", f"{rates['lean']:,.0f}",
            against_cartpole, f"{rates['lean'] / cartpole:.3f}x", ""),
        Row(f"{task}, one env, default info (+ vector reward, cost, objectives) against {v0} [steps/s]",
            f"{ours:,.0f}", f"{v0}, default info: {rates['v0']:,.0f}", f"{ours / rates['v0']:.3f}x",
            verdict(f">= {TARGET_V1_VS_V0}x v0's", ours / rates["v0"] >= TARGET_V1_VS_V0)),
        Row(f"{task}, one env, step_diagnostics=False against {v0} [steps/s]", f"{rates['lean']:,.0f}",
            f"{v0}, step_diagnostics=False: {rates['v0 lean']:,.0f}", f"{rates['lean'] / rates['v0 lean']:.3f}x",
            verdict(f">= {TARGET_V1_VS_V0}x v0's", rates["lean"] / rates["v0 lean"] >= TARGET_V1_VS_V0)),
        Row(f"{task}, one env, default info [steps/s] against highway-env", f"{ours:,.0f}",
            f"highway-fast-v0, one env: {highway:,.1f}", f"{ours / highway:,.1f}x",
            verdict(f">= {TARGET_VS_HIGHWAY:.0f}x highway-fast-v0", ours / highway >= TARGET_VS_HIGHWAY)),
    ]
    for env, _ in envs.values():
        env.close()
    return rows, cartpole


def single_env_split_rows(sizes: Sizes, cartpole: float) -> list[Row]:
    """Where a single env's step goes (:mod:`timegap_env.speed.single`), against CartPole-v1's whole step."""
    split = bench_single.measure(sizes.split_calls)
    step = f"CartPole-v1 step: {1e6 / cartpole:.2f}"
    return [
        Row("one env: a fused_step call [µs]", f"{split.call:.2f}", step, f"{split.call * cartpole / 1e6:.2f}x"),
        Row("one env: of that call, numba unpacking the state arrays (a kernel that only unpacks them) [µs]",
            f"{split.unpacking:.2f}", f"the call: {split.call:.2f}", f"{split.unpacking / split.call:.2f}x"),
        Row(f"fused_step's arithmetic per env-step, {bench_single.ARITHMETIC_ENVS} envs in one call [µs]",
            f"{split.arithmetic:.2f}", step, f"{split.arithmetic * cartpole / 1e6:.2f}x"),
    ]


def memory_row(run: bench_vector.VectorRun) -> Row:
    """Peak memory per env: tracemalloc's, with the resident memory's growth beside it; the latter alone for a
    size that was not traced."""
    def per_env(mib: float) -> str:
        return f"{bench_vector.per_env_kib(mib, run.n_envs):,.1f} KiB ({mib:,.1f} MiB in all)"

    measure = f"native vector env, {run.n_envs} envs: peak memory"
    rss = "n/a (no /proc/self/status)" if run.rss_mib is None else per_env(run.rss_mib)
    if run.traced_mib is not None:
        return Row(f"{measure}, tracemalloc [KiB per env]", per_env(run.traced_mib), f"peak RSS growth: {rss}")
    return Row(f"{measure}, peak RSS growth (not traced: the set-up took {run.set_up_seconds:,.0f} s untraced, "
               f"tracing would exceed {bench_vector.TRACE_BUDGET:.0f} s) [KiB per env]", rss)


def vector_rows(sizes: Sizes, cartpole: float) -> list[Row]:
    """Rows of measurements 2 and 3."""
    runs = bench_vector.measure_sizes(sizes.vector_sizes, sizes.reset_sizes, False, sizes.vector_seconds,
                                      sizes.vector_min_steps, sizes.vector_rounds)
    base = runs[0]
    rows = []
    for run in runs:
        ratio = run.env_steps_per_second / base.env_steps_per_second
        if run is base:
            target = (verdict(f">= {TARGET_VECTOR_RATE / 1e3:.0f} k", run.env_steps_per_second >= TARGET_VECTOR_RATE)
                      if run.n_envs == TARGET_VECTOR_BASE else "")
        else:
            target = verdict(f"within ±{TARGET_VECTOR_SPREAD:.0%} of {base.n_envs} envs'",
                             abs(ratio - 1.0) <= TARGET_VECTOR_SPREAD)
        rows.append(Row(f"native vector env, {run.n_envs} envs, one core [env-steps/s]",
                        f"{run.env_steps_per_second:,.0f}",
                        f"{base.n_envs} envs: {base.env_steps_per_second:,.0f} / CartPole-v1, one env: {cartpole:,.0f}",
                        f"{ratio:.2f}x / {run.env_steps_per_second / cartpole:.2f}x", target))
    rows += [memory_row(run) for run in runs]
    [with_info] = bench_vector.measure_sizes((base.n_envs,), (), True, sizes.vector_seconds, sizes.vector_min_steps, 1)
    rows.append(Row(f"native vector env, {base.n_envs} envs, step_diagnostics=True (default info) [env-steps/s]",
                    f"{with_info.env_steps_per_second:,.0f}",
                    f"step_diagnostics=False: {base.env_steps_per_second:,.0f}",
                    f"{with_info.env_steps_per_second / base.env_steps_per_second:.2f}x"))
    n = sizes.sync_envs
    say(f"native vector env against SyncVectorEnv, {n} envs")
    native = vector_env_steps_per_second(
        gym.make_vec(timegap_env.DEFAULT_TASK, num_envs=n, vectorization_mode="vector_entry_point"), sizes.sync_steps)
    synced = vector_env_steps_per_second(gym.make_vec(timegap_env.DEFAULT_TASK, num_envs=n, vectorization_mode="sync"),
                                         max(sizes.sync_steps // 4, 1))
    rows.append(Row(f"native vector env, {n} envs, default info [env-steps/s]", f"{native:,.0f}",
                    f"SyncVectorEnv of {n} single envs: {synced:,.0f}", f"{native / synced:,.1f}x"))
    for run in runs:
        if run.reset_seconds is None:
            continue
        ours, reference = bench_vector.seeding_seconds(run.n_envs)  # the floor of one NumPy generator per env
        target = (verdict(f"< {TARGET_RESET_SECONDS:.0f} s", run.reset_seconds < TARGET_RESET_SECONDS)
                  if run.n_envs == TARGET_RESET_ENVS else "")
        rows.append(Row(f"batched reset, envs.reset(seed=0), {run.n_envs} envs [s]",
                        f"{run.reset_seconds:,.3f} s ({run.reset_seconds / run.n_envs * 1e6:,.1f} µs per env)",
                        f"{run.n_envs} x np.random.default_rng(seed + i): {reference:,.3f} s "
                        f"({reference / run.n_envs * 1e6:,.2f} µs per env)",
                        f"{run.reset_seconds / reference:,.1f}x", target))
        if run.n_envs == TARGET_RESET_ENVS:
            for n, (made, numpys) in ((HASHED_FROM, bench_vector.seeding_seconds(HASHED_FROM)),
                                      (run.n_envs, (ours, reference))):
                rows.append(Row(f"its generators: timegap_env.generators of {n} seeds [s]", f"{made:,.4f} s",
                                f"{n} x np.random.default_rng: {numpys:,.4f} s", f"{made / numpys:.2f}x"))
            leaders = bench_vector.leaders_seconds(run.n_envs)
            rows.append(Row(f"of that reset: building {run.n_envs} leaders of the default mix alone, each family its "
                            "share (make_leaders) [s]", f"{leaders:,.3f} s",
                            f"the reset: {run.reset_seconds:,.3f} s", f"{leaders / run.reset_seconds:.2f}x"))
    return rows


def cold_start_rows(sizes: Sizes) -> list[Row]:
    """Rows of measurement 4."""
    start = bench_cold.measure(timegap_env.DEFAULT_TASK, sizes.cold_repeats)
    ref = start.reference
    rows = []
    for label, run in (("after pip install of the wheel", start.installed), ("empty numba cache", start.cold),
                       ("warm numba cache", start.warm)):
        target = (verdict(f"< {TARGET_COLD_CPU:.0f} CPU s", run.cpu_seconds < TARGET_COLD_CPU)
                  if run is start.installed else "")
        rows += [
            Row(f"first step from python -c, {label} [CPU s]", f"{run.cpu_seconds:.2f}",
                f"CartPole-v1 child: {ref.cpu_seconds:.2f}", f"{run.cpu_seconds / ref.cpu_seconds:.1f}x", target),
            Row(f"first step from python -c, {label} [wall s]", f"{run.wall_seconds:.2f}",
                f"CartPole-v1 child: {ref.wall_seconds:.2f}", f"{run.wall_seconds / ref.wall_seconds:.1f}x"),
        ]
    rows.append(Row("building the wheel, its kernels compiled into it (pip wheel) [wall s]",
                    f"{start.wheel_build_seconds:.1f}"))
    rows.append(Row("numba functions compiled by the empty-cache run [.nbi files]", f"{start.compiled}"))
    return rows


def ppo_rows(sizes: Sizes) -> list[Row]:
    """Rows of measurement 5."""
    split = bench_ppo.measure(sizes.ppo_rollouts, sizes.ppo_shrink)
    fast = bench_ppo.measure(sizes.ppo_rollouts, sizes.ppo_shrink, FAST_HYPERPARAMS)
    setting = ", ".join(f"{key} {value}" for key, value in split.setting.items())
    return [
        Row(f"PPO, make train's setting ({setting}): env's share of model.learn [%]", f"{split.env_share:.1%}",
            f"learner: {split.learner_share:.1%}, VecNormalize: {split.normalize_share:.1%}", "",
            "learner-bound: report"),
        Row("PPO: the most its throughput could gain with a free env, 1 / (1 - env share)",
            f"{split.most_gain_if_env_free:.2f}x", "", "", "claim no more"),
        Row("PPO, make train's setting [env steps/s of learning]", f"{split.steps_per_second:,.0f}"),
        Row("PPO, hyperparams/ppo_fast.yml (train.choose_learner's choice) [env steps/s of learning]",
            f"{fast.steps_per_second:,.0f}", f"{split.steps_per_second:,.0f} (make train's setting)",
            f"{fast.steps_per_second / split.steps_per_second:.2f}x",
            "issue 39: >= 5x: " + ("met" if fast.steps_per_second >= 5 * split.steps_per_second else "NOT met")),
    ]


def kernel_rows(sizes: Sizes) -> list[Row]:
    """Rows of measurement 6."""
    rows = []
    for n, n_ticks in sizes.ticks.items():
        rate = vehicle_ticks_per_second(n, n_ticks)
        target = verdict(f">= {TARGET_VEHICLE_TICKS / 1e6:.0f} M", rate >= TARGET_VEHICLE_TICKS) if n == 1024 else ""
        rows.append(Row(f"simulator, {n} envs [vehicle-ticks/s]", f"{rate / 1e6:,.2f} M", target=target))
    monitor = bench_monitor(1024, 5, sizes.monitor_ticks, MonitorConfig())
    rows.append(Row("monitor, 1024 x 5 [vehicle-updates/s]", f"{1024 * 5 / monitor['monitor'] / 1e6:,.1f} M",
                    "NumPy add of the same arrays (time per tick)", f"{monitor['monitor'] / monitor['add']:,.0f}x"))
    return rows


def table(rows: list[Row], quick: bool) -> str:
    """The markdown of results/bench.md."""
    lines = [
        f"# Benchmarks (`python -m train.bench{' --quick' if quick else ''}`)",
        "",
        (f"Python {platform.python_version()}, NumPy {np.__version__}, {platform.machine()}. Each figure is set against "
        "a reference measured alongside it in the same process (cold start: in child processes launched alike); "
        "the ratios are the figures to compare, absolute rates move with the machine's load. Numba kernels are "
        "loaded (or compiled) before timing, except in the cold start."),
        "",
        "- Single envs take turns over several rounds, their order rotating each round (an env runs its first steps "
        "with what the one before left in the caches), random actions, resets included; highway-fast-v0 is timed "
        "apart after them (whichever env ran right after it ran slower).",
        ("- The native vector env runs in this one process on one core (numba's kernels are single-threaded), "
        "random actions, the sizes taking turns over several rounds (all of them held at once); its stepping is "
        "timed within episodes (all sub-envs start together, so their episodes "
        "end in the same step: the envs are reset, untimed, before that step; resets are timed on their own). "
        "Peak memory: tracemalloc's peak (NumPy's allocations included) while building, resetting and stepping; "
        "beside it, the growth of the process's peak resident memory (RSS), which stands in for it at a size whose "
        f"traced set-up would take over {bench_vector.TRACE_BUDGET:.0f} s (tracing slows a per-env Python reset "
        "loop several times over)."),
        ("- Cold start: CPU seconds (the child's `time.process_time()`) and wall seconds from `python -c` to the "
        "first `env.step` returning (imports, `gym.make`, reset, one step). After pip install: the wheel built "
        "from a copy of this tree (`pip wheel`, whose build compiles the kernels into the wheel: "
        "`timegap_env.precompile`), installed into an empty folder, imported from there with `NUMBA_CACHE_DIR` "
        "unset. Empty cache: `NUMBA_CACHE_DIR` a fresh directory (what an editable install's first run, or a "
        "wheel built without its cache, compiles); warm: the same directory again (median of the runs). The "
        "reference child steps CartPole-v1 once."),
        ("- PPO: `hyperparams/ppo.yml` as `make train` runs it (TimeGapVecEnv, VecNormalize, MlpPolicy, CPU, one "
        "torch thread), after one untimed rollout; the env's share is the time in its `step_wait` and `reset`."),
        "",
        "| measure | value | reference (same process) | ratio | target |",
        "|---|---|---|---|---|",
        *[f"| {row.measure} | {row.value} | {row.reference} | {row.ratio} | {row.target} |" for row in rows],
    ]
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="tiny sizes, for a smoke test (numbers meaningless)")
    parser.add_argument("--out", type=Path, default=Path("runs/bench.md"),
                        help="the report (default: %(default)s; make bench writes results/bench.md)")
    args = parser.parse_args()
    cli.output_file(args.out)
    sizes = QUICK if args.quick else FULL
    started = time.perf_counter()

    say("single envs")
    rows, cartpole = single_env_rows(sizes)
    rows += single_env_split_rows(sizes, cartpole)
    rows += vector_rows(sizes, cartpole)
    say("cold start (child processes)")
    rows += cold_start_rows(sizes)
    say("PPO")
    rows += ppo_rows(sizes)
    say("simulator and monitor")
    rows += kernel_rows(sizes)

    text = table(rows, args.quick) + f"\nThe whole benchmark took {time.perf_counter() - started:,.0f} s.\n"
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text)
    print(text)


if __name__ == "__main__":
    cli.run(main, "python -m train.bench")
