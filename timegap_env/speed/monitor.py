"""The streaming monitor's cost per tick against reference work in the same process (``python -m train.bench_monitor``
prints it; ``make bench`` reports it).

References, timed on the same shapes:
- ``numpy add``: one ``np.add(a, b, out=c)`` on (n_envs, n_vehicles) arrays, the floor of any vectorised per-tick
  work;
- ``window recompute``: the naive O(W) alternative to the monitor's O(1) update, summing the sufficient statistics
  over the whole window buffer every tick.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from timegap_env.config import MonitorConfig
from timegap_env.monitoring.monitor import N_SUMS, TimeGapMonitor, monitor_prior
from timegap_env.monitoring.posterior import WindowSums, posterior_moments


def seconds_per_call(step: Callable[[int], object], n_calls: int) -> tuple[float, float]:
    """Mean and worst wall-clock time of ``step(tick)`` over n_calls ticks [s]."""
    worst, start = 0.0, time.perf_counter()
    for tick in range(n_calls):
        before = time.perf_counter()
        step(tick)
        worst = max(worst, time.perf_counter() - before)
    return (time.perf_counter() - start) / n_calls, worst


def measurements(n_envs: int, n_vehicles: int, n_distinct: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """n_distinct ticks of speeds [m/s] and spacings [m], with 1 % dropouts (NaN), cycled by the benchmark."""
    rng = np.random.default_rng(seed)
    speed = rng.uniform(8.94, 35.76, (n_distinct, n_envs, n_vehicles))
    spacing = 5.0 + 1.6 * speed + rng.normal(0.0, 0.1, speed.shape)
    spacing[rng.random(speed.shape) < 0.01] = np.nan
    return speed, spacing


def bench(n_envs: int, n_vehicles: int, n_ticks: int, config: MonitorConfig) -> dict[str, float]:
    """Seconds per tick of the monitor and of the two references."""
    speed, spacing = measurements(n_envs, n_vehicles, n_distinct=64)
    monitor = TimeGapMonitor(n_envs, n_vehicles, setting=1.6, config=config)
    monitor.update(speed[-1], spacing[-1])  # loads (or compiles) the kernel before the timing
    monitor_mean, monitor_worst = seconds_per_call(lambda t: monitor.update(speed[t % 64], spacing[t % 64]), n_ticks)

    a, b, out = speed[0], speed[1], np.empty_like(speed[0])
    add_mean, _ = seconds_per_call(lambda t: np.add(a, b, out=out), n_ticks)

    window = config.window_ticks or 1
    buffer = np.zeros((window, N_SUMS, n_envs, n_vehicles))
    prior = monitor_prior(config)
    prior_tau = np.full((n_envs, n_vehicles), 1.6)

    def recompute(t: int) -> None:
        v, s = speed[t % 64], spacing[t % 64]
        valid = np.isfinite(s)
        v, s = np.where(valid, v, 0.0), np.where(valid, s, 0.0)
        buffer[t % window] = np.stack([valid, v, v * v, s, v * s])
        posterior_moments(WindowSums(*buffer.sum(axis=0)), prior_tau, prior)

    recompute_mean, _ = seconds_per_call(recompute, n_ticks)
    return {"monitor": monitor_mean, "monitor_worst": monitor_worst, "add": add_mean, "recompute": recompute_mean}
