"""Benchmark of the streaming monitor: updates per second, and ratios against reference work.

    python -m train.bench_monitor            # 1024 envs x 5 vehicles, and 1 x 1
    python -m train.bench_monitor --quick    # tiny sizes, seconds (used by the tests)

References, timed in the same process on the same shapes:
- ``numpy add``: one ``np.add(a, b, out=c)`` on (n_envs, n_vehicles) arrays, the floor of any
  vectorised per-tick work;
- ``window recompute``: the naive O(W) alternative to the monitor's O(1) update, summing the
  sufficient statistics over the whole window buffer every tick.
Timing depends on the machine: this script prints and never asserts.
"""

from __future__ import annotations

import argparse

from timegap_env import cli
from timegap_env.config import MonitorConfig
from timegap_env.speed.monitor import bench


def report(n_envs: int, n_vehicles: int, n_ticks: int, config: MonitorConfig) -> None:
    t = bench(n_envs, n_vehicles, n_ticks, config)
    print(f"{n_envs} envs x {n_vehicles} vehicles, window {config.window} s = {config.window_ticks} ticks,", end=" ")
    print(f"{n_ticks} ticks timed:")
    print(f"  monitor update:      {t['monitor'] * 1e6:10.1f} us/tick (worst tick {t['monitor_worst'] * 1e6:.1f} us)")
    print(f"  batch-updates/s:     {1 / t['monitor']:12.0f}")
    print(f"  vehicle-updates/s:   {n_envs * n_vehicles / t['monitor']:12.0f}")
    print(f"  ratio monitor / numpy add:        {t['monitor'] / t['add']:8.1f}")
    print(f"  ratio window recompute / monitor: {t['recompute'] / t['monitor']:8.1f}")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n-envs", type=int, default=1024, help="envs in the batch (default 1024)")
    parser.add_argument("--n-vehicles", type=int, default=5, help="vehicles per env (default 5)")
    parser.add_argument("--ticks", type=int, default=2000, help="ticks timed per run (default 2000)")
    parser.add_argument("--window", type=float, default=MonitorConfig().window, help="sliding window [s]")
    parser.add_argument("--quick", action="store_true", help="tiny sizes and few ticks, for tests")
    args = parser.parse_args(argv)
    if args.quick:
        args.n_envs, args.n_vehicles, args.ticks = 4, 2, 50
    config = MonitorConfig(window=args.window)
    report(args.n_envs, args.n_vehicles, args.ticks, config)
    report(1, 1, args.ticks, config)


if __name__ == "__main__":
    cli.run(main, "python -m train.bench_monitor")
