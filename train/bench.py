"""``make bench``: how much the simulator, the monitor and the environment cost, against reference environments.

Every figure is measured in this process, the same way, back to back, and the
table reports ratios, which survive a busy machine better than absolute times:

1. env steps/s of ``TimeGapMonitor-v0`` (one env, random actions) against
   highway-env's ``highway-fast-v0`` and gymnasium's ``CartPole-v1``, the three
   taking turns over several rounds;
2. vehicle-ticks/s of the batched simulator (``Platoon.advance``, a decision's
   10 ticks per call) at 1, 64 and 1024 envs, and the native vector env against
   a ``SyncVectorEnv`` of single envs;
3. monitor updates/s, batched (1024 envs x 5 vehicles);
4. PPO training steps/s on ``TimeGapMonitor-v0`` against PPO on ``CartPole-v1``
   with the same hyperparameters, the two taking turns;
5. peak memory of a 1024-env vector env (tracemalloc: NumPy allocations included).

Writes ``results/bench.md``.

    python -m train.bench [--quick] [--out results/bench.md]
"""

from __future__ import annotations

import argparse
import dataclasses
import platform
import time
import tracemalloc
from collections.abc import Callable
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch

import timegap_env
from timegap_env.config import MonitorConfig, PlatoonConfig
from timegap_env.sim import Platoon
from train.bench_monitor import bench as bench_monitor

TARGET_VS_HIGHWAY = 100.0  # single env steps/s over highway-fast-v0's [-]
TARGET_VEHICLE_TICKS = 10e6  # batched simulator at 1024 envs [vehicle-ticks/s]
TARGET_PPO_VS_CARTPOLE = 0.8  # PPO steps/s on TimeGapMonitor-v0 over CartPole-v1's [-]
PPO_SMALL = dict(n_envs=8, n_steps=128, batch_size=256, n_epochs=4, learning_rate=3e-4)  # a small, common setting
PPO_TRAINING = dict(n_envs=64, n_steps=64, batch_size=512, n_epochs=10, learning_rate=1e-3)  # hyperparams/ppo.yml's


@dataclasses.dataclass(frozen=True)
class Sizes:
    """How long each measurement runs."""

    rounds: int  # single-env and PPO measurements alternate between the envs this many times
    env_steps: int  # steps of TimeGapMonitor-v0 and CartPole-v1 per round
    highway_steps: int  # steps of highway-fast-v0 per round (it is about 100x slower)
    ticks: dict[int, int]  # simulator ticks timed per batch size, in blocks of TICKS_PER_BLOCK
    vector_envs: int  # sub-envs of the vector env comparison
    vector_steps: int
    monitor_ticks: int
    ppo_timesteps: int
    ppo_n_steps: int  # rollout length per env; 0 = the setting's own
    memory_envs: int


FULL = Sizes(10, 1000, 25, {1: 20000, 64: 5000, 1024: 1000}, 64, 100, 300, 4096, 0, 1024)  # 0: each setting's n_steps
QUICK = Sizes(1, 20, 3, {1: 20, 64: 10, 1024: 10}, 4, 5, 5, 64, 1, 16)
TICKS_PER_BLOCK = 10  # the simulator advances a decision's ticks in one call, as the env does
WARM_UP_STEPS = 20  # untimed steps first: numba kernels load (or compile) on their first call


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
    by round, so that a slow spell of a shared machine hits all of them rather than one."""
    for env, _ in envs.values():
        env.reset(seed=0)
        env.action_space.seed(0)
        env_steps_per_second(env, WARM_UP_STEPS)
    seconds = dict.fromkeys(envs, 0.0)
    for _ in range(rounds):
        for name, (env, n_steps) in envs.items():
            seconds[name] += n_steps / env_steps_per_second(env, n_steps)
    return {name: rounds * n_steps / seconds[name] for name, (_, n_steps) in envs.items()}


def vector_env_steps_per_second(envs: gym.vector.VectorEnv, n_steps: int) -> float:
    """Env-steps/s (sub-envs x steps) of a vector env under random actions."""
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


def ppo_steps_per_second(
    make_venvs: dict[str, Callable[[int], object]], setting: dict, timesteps: int, n_steps: int, rounds: int
) -> dict[str, float]:
    """Environment steps/s of PPO learning with ``setting`` on each env {name: make_venv(n_envs)}, over all rounds.

    Each model first learns one rollout (torch start-up and kernel loading excluded); then the
    models take turns, ``timesteps`` each per round, so machine noise hits them alike.
    """
    from stable_baselines3 import PPO

    settings = {key: value for key, value in setting.items() if key != "n_envs"}
    settings["n_steps"] = n_steps or setting["n_steps"]
    settings["batch_size"] = min(settings["batch_size"], settings["n_steps"] * setting["n_envs"])
    models = {name: PPO("MlpPolicy", make(setting["n_envs"]), seed=0, device="cpu", verbose=0, **settings)
              for name, make in make_venvs.items()}
    for model in models.values():
        model.learn(setting["n_envs"] * settings["n_steps"])
    seconds = dict.fromkeys(models, 0.0)
    for _ in range(rounds):
        for name, model in models.items():
            start = time.perf_counter()
            model.learn(timesteps, reset_num_timesteps=False)
            seconds[name] += time.perf_counter() - start
    return {name: rounds * timesteps / seconds[name] for name in models}


def peak_memory_mib(n_envs: int, n_steps: int = 10) -> float:
    """Peak traced memory of building, resetting and stepping an n_envs vector env [MiB]."""
    tracemalloc.start()
    envs = gym.make_vec(timegap_env.ENV_ID, num_envs=n_envs, vectorization_mode="vector_entry_point")
    envs.reset(seed=0)
    for _ in range(n_steps):
        envs.step(envs.action_space.sample())
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    envs.close()
    return peak / 2**20


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="tiny sizes, for a smoke test (numbers meaningless)")
    parser.add_argument("--out", type=Path, default=Path("results/bench.md"))
    args = parser.parse_args()
    sizes = QUICK if args.quick else FULL

    from stable_baselines3.common.env_util import make_vec_env

    from timegap_env.envs.sb3 import TimeGapVecEnv

    import highway_env  # noqa: F401  (registers highway-fast-v0)

    rows: list[tuple[str, str, str]] = []  # (measure, value, verdict)

    single = interleaved_steps_per_second({
        "ours": (gym.make(timegap_env.ENV_ID), sizes.env_steps),
        "highway": (gym.make("highway-fast-v0"), sizes.highway_steps),
        "cartpole": (gym.make("CartPole-v1"), sizes.env_steps),
    }, sizes.rounds)
    ours, highway, cartpole = single["ours"], single["highway"], single["cartpole"]
    rows += [
        ("TimeGapMonitor-v0, one env [steps/s]", f"{ours:,.0f}", ""),
        ("highway-fast-v0, one env [steps/s]", f"{highway:,.1f}", ""),
        ("CartPole-v1, one env [steps/s]", f"{cartpole:,.0f}", ""),
        ("TimeGapMonitor-v0 / highway-fast-v0", f"{ours / highway:,.1f}x",
         f"target >= {TARGET_VS_HIGHWAY:.0f}x: {'met' if ours / highway >= TARGET_VS_HIGHWAY else 'NOT met'}"),
        ("TimeGapMonitor-v0 / CartPole-v1", f"{ours / cartpole:.3f}x", ""),
    ]

    ticks = {n: vehicle_ticks_per_second(n, k) for n, k in sizes.ticks.items()}
    for n, rate in ticks.items():
        verdict = ""
        if n == 1024:
            verdict = f"target >= {TARGET_VEHICLE_TICKS / 1e6:.0f} M: {'met' if rate >= TARGET_VEHICLE_TICKS else 'NOT met'}"
        rows.append((f"simulator, {n} envs [vehicle-ticks/s]", f"{rate / 1e6:,.2f} M", verdict))

    n = sizes.vector_envs
    native = vector_env_steps_per_second(
        gym.make_vec(timegap_env.ENV_ID, num_envs=n, vectorization_mode="vector_entry_point"), sizes.vector_steps)
    synced = vector_env_steps_per_second(gym.make_vec(timegap_env.ENV_ID, num_envs=n, vectorization_mode="sync"),
                                         max(sizes.vector_steps // 4, 1))
    rows += [
        (f"native vector env, {n} envs [env-steps/s]", f"{native:,.0f}", ""),
        (f"SyncVectorEnv, {n} envs [env-steps/s]", f"{synced:,.0f}", ""),
        ("native / SyncVectorEnv", f"{native / synced:,.1f}x", ""),
    ]

    monitor = bench_monitor(1024, 5, sizes.monitor_ticks, MonitorConfig())
    rows += [
        ("monitor, 1024 x 5 [vehicle-updates/s]", f"{1024 * 5 / monitor['monitor'] / 1e6:,.1f} M", ""),
        ("monitor / NumPy add of the same arrays [time ratio]", f"{monitor['monitor'] / monitor['add']:,.0f}x", ""),
    ]

    torch.set_num_threads(1)  # as train_ppo does
    for label, setting in (("small setting", PPO_SMALL), ("training setting", PPO_TRAINING)):
        timesteps = max(sizes.ppo_timesteps, 2 * setting["n_envs"] * (sizes.ppo_n_steps or setting["n_steps"]))
        ppo = ppo_steps_per_second({
            "ours": lambda n: TimeGapVecEnv(n_envs=n),
            "cartpole": lambda n: make_vec_env("CartPole-v1", n_envs=n, seed=0),
        }, setting, timesteps, sizes.ppo_n_steps, sizes.rounds)
        ppo_ours, ppo_cartpole = ppo["ours"], ppo["cartpole"]
        ratio = ppo_ours / ppo_cartpole
        rows += [
            (f"PPO, {label} {setting}: TimeGapMonitor-v0 [steps/s]", f"{ppo_ours:,.0f}", ""),
            (f"PPO, {label}: CartPole-v1 [steps/s]", f"{ppo_cartpole:,.0f}", ""),
            (f"PPO, {label}: TimeGapMonitor-v0 / CartPole-v1", f"{ratio:.2f}x",
             f"target >= {TARGET_PPO_VS_CARTPOLE:.0%}: {'met' if ratio >= TARGET_PPO_VS_CARTPOLE else 'NOT met'}"),
        ]

    rows.append((f"peak memory, {sizes.memory_envs}-env vector env [MiB]", f"{peak_memory_mib(sizes.memory_envs):,.1f}", ""))

    lines = [
        f"# Benchmarks (`python -m train.bench{' --quick' if args.quick else ''}`)",
        "",
        f"Python {platform.python_version()}, NumPy {np.__version__}, {platform.machine()}; one process, "
        "single envs and PPO runs take turns over several rounds. Ratios are the figures to compare; absolute rates move "
        "with the machine's load. Numba kernels are loaded (or compiled) before timing.",
        "PPO: each setting runs on both envs alike, MlpPolicy, CPU, one torch thread; "
        "TimeGapMonitor-v0 through the native vector env (`timegap_env.envs.sb3.TimeGapVecEnv`), CartPole-v1 through DummyVecEnv.",
        "",
        "| measure | value | target |",
        "|---|---|---|",
        *[f"| {measure} | {value} | {verdict} |" for measure, value, verdict in rows],
    ]
    text = "\n".join(lines) + "\n"
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text)
    print(text)


if __name__ == "__main__":
    main()
