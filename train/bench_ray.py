"""Serial against Ray on this machine, and what a full evaluation sweep would take on N nodes (issue 15).

Measured in this one process, back to back, in this order (the driver warmed up first: its
compiled kernels loaded by a short batch of each kind of policy):

1. the evaluation workload of ``python -m train.evaluate`` (every policy, ``--episodes`` split over
   the held-out groups, the oracle's lookup and choice first) run serially here: its wall time and
   each policy's seconds per episode;
2. Ray's fixed start-up (``ray.init`` on this machine and a first task that does nothing), one more
   empty task, the cost per task of ``NOOP_TASKS`` empty tasks mapped at once, and how many CPUs'
   worth the machine really gives: a CPU-bound sum alone here against one per CPU as Ray tasks at
   once (a virtual machine's CPUs may share their host's cores), here and again at the end;
3. the same evaluation workload on Ray three times: with fresh workers (each imports the package
   and loads its kernels on its first piece), then twice with warm ones, then serially once more;
   the records must equal the first serial ones bit for bit. Other processes may share the CPUs:
   the faster of the two serial runs and of the two warm Ray runs are compared;
4. ``train.value_of_information`` and ``train.detection_benchmark`` at their default sizes, serially
   and on the (warm) Ray, their files compared byte for byte.

From these, a paper estimate of a sweep of ``SWEEP_CELLS`` config cells, each the full evaluation
(its own oracle lookup included), on N nodes of ``CPUS_PER_NODE`` CPUs like this machine's (see
:func:`sweep_seconds` for the model), and where Ray starts to pay. Writes ``--out``; only the
measured times (and the machine's load) change from run to run.

    .venv-clients/bin/python -m train.bench_ray [--quick] [--out results/ray/scaling.md]
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import io
import math
import os
import platform
import runpy
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from timegap_env import cli
from timegap_env.agents.protocol import EVAL_SEED_START
from timegap_env.studies import heldout
from timegap_env.experiments.backends import Backend
from timegap_env.experiments.registry import make as make_policy

DEFAULT_OUT = Path("runs/ray/scaling.md")
NOOP_TASKS = 200  # empty tasks mapped at once to measure Ray's cost per task [-]
SPIN_ITERATIONS = 100_000_000  # integers summed: a CPU-bound task of about a second [-]
SWEEP_CELLS = 20  # config cells of the estimated sweep, each a full evaluation [-]
CPUS_PER_NODE = 2  # the estimate's nodes: like this machine [-]
NODES = (1, 2, 4, 8, 16, 32)


@dataclasses.dataclass(frozen=True)
class Size:
    """How much work each measurement does."""

    episodes: int  # evaluation episodes per policy [-]
    policies: list[str] | None  # evaluate's --policies; None: its default set
    noop_tasks: int  # empty Ray tasks [-]
    spin: int  # integers the CPU-bound task sums [-]
    value_of_information: list[str]  # the script's size arguments
    detection: list[str]


FULL = Size(heldout.DEFAULT_EPISODES, None, NOOP_TASKS, SPIN_ITERATIONS, [], [])
QUICK = Size(14, ["rule_platoon", "fixed_1.6", "ppo"], 20, SPIN_ITERATIONS // 10,
             ["--episodes", "4", "--train-episodes", "1"], ["--episodes", "2", "--nominal-episodes", "3"])


def capacity(backend: Backend, cpus: int, iterations: int) -> float:
    """How many CPUs' worth ``cpus`` CPU-bound tasks at once get: cpus x (a sum of ``iterations`` integers here) /
    (the wall of ``cpus`` such sums as tasks at once). Builtins: the workers import nothing of this project."""
    started = time.perf_counter()
    sum(range(iterations))
    alone = time.perf_counter() - started
    started = time.perf_counter()
    backend.map(sum, [(range(iterations),)] * cpus)
    return cpus * alone / (time.perf_counter() - started)


class Counting(Backend):
    """A backend that counts the pieces it was given."""

    def __init__(self, name: str = "serial") -> None:
        super().__init__(name)
        self.pieces = 0

    def map(self, function: Callable[..., Any], pieces: Sequence[tuple[Any, ...]]) -> list[Any]:
        self.pieces += len(pieces)
        return super().map(function, pieces)


@dataclasses.dataclass
class Evaluation:
    """The evaluation workload, run once with one backend."""

    seconds: float  # wall: the policies built (the oracle's lookup and choice), then every (policy, group) batch [s]
    oracle_seconds: float  # wall of building the policies alone [s]
    summary_seconds: float  # the statistics over the records (serial, in this process) [s]
    pieces: int  # pieces mapped: the oracle's and the (policy, group) batches [-]
    batch_pieces: int  # (policy, group) batches [-]
    episodes: int  # per policy [-]
    groups: int  # held-out groups, a batch each per policy [-]
    records: dict[str, list[dict[str, Any]]]
    timings: dict[str, float]  # per policy, seconds inside its pieces [s]
    names: dict[str, str]  # policy key -> name


def run_evaluation(backend: Counting, size: Size) -> Evaluation:
    """``train.evaluate``'s workload with ``backend``: policies (the oracle's pieces), then the episode batches."""
    groups, _ = heldout.available_groups()
    plan = heldout.plan_episodes(size.episodes, groups)
    profile_group = "training_mix" if "training_mix" in groups else groups[0]  # evaluate's default
    counted = backend.pieces
    start = time.perf_counter()
    with contextlib.redirect_stdout(io.StringIO()):  # the per-policy lines
        policies = heldout.build_policies(size.policies, heldout.DEFAULT_MODEL, backend)
        built = time.perf_counter()
        records, _, timings = heldout.run_all(policies, plan, profile_group, backend)
    seconds = time.perf_counter() - start
    summarised = time.perf_counter()
    reference = heldout.DEFAULT_REFERENCE if heldout.DEFAULT_REFERENCE in policies else None
    heldout.summarise(policies, records, reference)
    return Evaluation(seconds, built - start, time.perf_counter() - summarised, backend.pieces - counted,
                      len(policies) * len(groups), len(plan), len(groups), records, timings,
                      {key: policy.name for key, policy in policies.items()})


def warm_up_driver() -> None:
    """Load the env's, the monitor's and the rule's compiled kernels in this process (one short batch each) and
    import torch and SB3 for PPO."""
    import timegap_env.agents.learned  # noqa: F401  (torch, stable-baselines3)

    seeds = [EVAL_SEED_START]
    for name in ("fixed_1.6", "rule_platoon", "rule_per_vehicle"):
        heldout.run_batch(make_policy(name), "training_mix", seeds, record_profile=True)


def run_script(module: str, arguments: list[str], backend: str, out: Path) -> float:
    """Wall seconds of ``python -m module`` (a script) run in this process, as the command line runs it, writing to
    ``out`` with ``--backend backend``; its printout dropped. (In this process: it joins the Ray session started
    here, which is what is timed.)"""
    argv, start = sys.argv, time.perf_counter()
    sys.argv = [module, *arguments, "--out", str(out), "--backend", backend]
    try:
        with contextlib.redirect_stdout(io.StringIO()):
            runpy.run_module(module, run_name="__main__", alter_sys=True)
    finally:
        sys.argv = argv
    return time.perf_counter() - start


def same_files(first: Path, second: Path) -> bool:
    """Whether two directories hold the same files with the same bytes."""
    names = sorted(path.name for path in first.iterdir())
    return names == sorted(path.name for path in second.iterdir()) and all(
        (first / name).read_bytes() == (second / name).read_bytes() for name in names)


@dataclasses.dataclass(frozen=True)
class Costs:
    """What the estimate is made of, all measured here."""

    work: float  # serial seconds of one cell's spread work (oracle and episode batches) [s]
    pieces: int  # pieces per cell [-]
    driver: float  # serial seconds per cell that stay in the driver (the statistics) [s]
    start: float  # Ray's start-up: init and a first task [s]
    warm_up: float  # fresh workers' extra on their first pieces (imports, kernels) [s]
    per_task: float  # Ray's cost per task, the driver's submitting and collecting [s]
    efficiency: float  # work / (CPUs x warm Ray wall) on this machine: the share of each CPU Ray's pieces get [-]


def serial_seconds(costs: Costs, cells: int) -> float:
    """A sweep of ``cells`` cells run serially in one process [s]."""
    return cells * (costs.work + costs.driver)


def sweep_seconds(costs: Costs, cells: int, nodes: int, cpus_per_node: int) -> float:
    """A sweep of ``cells`` cells on Ray over ``nodes`` nodes [s]: start-up, workers' warm-up (in parallel on every
    node: once), then the pieces in rounds of one per CPU, each round as long as a mean piece at this machine's
    efficiency, or the driver's cost per task if that is longer, then the driver's serial statistics per cell."""
    pieces = cells * costs.pieces
    rounds = math.ceil(pieces / (nodes * cpus_per_node))
    compute = rounds * (costs.work / costs.pieces) / costs.efficiency
    return costs.start + costs.warm_up + max(compute, pieces * costs.per_task) + cells * costs.driver


def break_even_work(costs: Costs, cpus: int) -> float:
    """The serial seconds of spread work above which Ray on ``cpus`` CPUs of this machine beats serial [s]:
    W > start + warm-up + W / (cpus x efficiency), for pieces small against W (inf if Ray never wins)."""
    speed_up = cpus * costs.efficiency
    return (costs.start + costs.warm_up) / (1 - 1 / speed_up) if speed_up > 1 else math.inf


def load() -> str:
    """The machine's 1-minute load average (other processes share the CPUs)."""
    return f"{os.getloadavg()[0]:.1f}"


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m train.bench_ray", description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="tiny sizes, for a smoke test (numbers meaningless)")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="output file (default %(default)s)")
    args = parser.parse_args(argv)
    cli.output_file(args.out)
    size = QUICK if args.quick else FULL
    try:
        import ray
    except ImportError:
        parser.error("needs Ray: pip install -e '.[ray]' (or run it with .venv-clients/bin/python)")

    loads = {"start": load()}
    warm_up_driver()
    serial = run_evaluation(Counting(), size)
    loads["after the serial evaluation"] = load()

    ray_backend = Counting("ray")
    started = time.perf_counter()
    ray_backend.map(int, [()])  # ray.init here, then the first task: int() is 0, a builtin: nothing to import
    start = time.perf_counter() - started
    started = time.perf_counter()
    ray_backend.map(int, [()])
    one_task = time.perf_counter() - started
    started = time.perf_counter()
    ray_backend.map(int, [()] * size.noop_tasks)
    per_task = (time.perf_counter() - started) / size.noop_tasks
    cpus = int(ray.cluster_resources().get("CPU", 0))
    capacities = [capacity(ray_backend, cpus, size.spin)]

    fresh = run_evaluation(ray_backend, size)
    loads["after Ray's first evaluation"] = load()
    warm_runs = [run_evaluation(ray_backend, size) for _ in range(2)]
    spread = ray_backend.describe()
    loads["after Ray's third evaluation"] = load()
    serial_runs = [serial, run_evaluation(Counting(), size)]
    loads["after the second serial evaluation"] = load()
    runs = [*serial_runs, fresh, *warm_runs]
    identical = all(repr(run.records) == repr(serial.records) for run in runs)  # floats exactly, NaN too
    serial, warm = (min(pair, key=lambda run: run.seconds) for pair in (serial_runs, warm_runs))

    scripts = {}
    with tempfile.TemporaryDirectory() as scratch:
        for name, arguments in (("train.value_of_information", size.value_of_information),
                                ("train.detection_benchmark", size.detection)):
            times = {backend: run_script(name, arguments, backend, Path(scratch, name, backend))
                     for backend in ("serial", "ray")}
            scripts[name] = (times, same_files(Path(scratch, name, "serial"), Path(scratch, name, "ray")), arguments)
    capacities.append(capacity(ray_backend, cpus, size.spin))
    loads["end"] = load()
    ray.shutdown()

    costs = Costs(work=serial.seconds, pieces=serial.pieces, driver=serial.summary_seconds, start=start,
                  warm_up=max(fresh.seconds - warm.seconds, 0.0), per_task=per_task,
                  efficiency=serial.seconds / (cpus * warm.seconds))
    text = report(args, size, serial, (serial_runs[0].seconds, serial_runs[1].seconds), fresh, warm, costs, cpus,
                  one_task, spread, identical, scripts, loads, capacities)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text)
    print(text)


def report(args: argparse.Namespace, size: Size, serial: Evaluation, serial_runs: tuple[float, float],
           fresh: Evaluation, warm: Evaluation, costs: Costs, cpus: int, one_task: float, spread: str, identical: bool,
           scripts: dict[str, tuple[dict[str, float], bool, list[str]]], loads: dict[str, str],
           capacities: list[float]) -> str:
    """The markdown of ``--out``."""
    import ray
    import torch

    cells = SWEEP_CELLS
    n_policies = len(serial.timings)
    episodes = serial.episodes
    mean_piece = serial.seconds / serial.pieces
    per_batch = episodes / serial.groups  # episodes in a (policy, group) batch
    lines = [
        "# Serial against Ray, and a sweep on N nodes (`python -m train.bench_ray`)", "",
        *(["**Quick run: tiny sizes, the numbers mean nothing.**", ""] if args.quick else []),
        f"Machine: {os.cpu_count()} CPUs (`os.cpu_count()`), {platform.machine()}, Python "
        f"{platform.python_version()}, Ray {ray.__version__}, torch {torch.__version__} ({torch.get_num_threads()} "
        f"threads in this process; Ray's workers run with 1). Ray started on this machine with {cpus} CPUs. Load "
        "average (1 min) as the measurements went: " + ", ".join(f"{when} {value}" for when, value in loads.items())
        + " (other processes share the CPUs; times taken on a busier machine are longer).", "",
        "Everything below was measured in this one process, back to back: the driver warmed up first (its compiled "
        "kernels loaded), so the serial times hold no start-up; Ray's start-up is measured on its own.", "",
        "## 1. The evaluation workload: serial against Ray on this machine", "",
        f"`train.evaluate`'s work: {n_policies} policies x {episodes} episodes over the held-out groups, "
        f"{serial.batch_pieces} (policy, group) batches"
        + (f", after the oracle's lookup and choice ({serial.pieces - serial.batch_pieces} pieces)"
           if serial.pieces > serial.batch_pieces else "")
        + f": {serial.pieces} pieces in all. The statistics over the records ({serial.summary_seconds:.1f} s) "
        "stay in the driver with either backend and are not in these times.", "",
        "| run | wall [s] | of which building the policies (the oracle's lookup and choice, loading PPO) [s] | "
        "speed-up vs serial |", "|---|---|---|---|",
        f"| serial, this process (the faster of {serial_runs[0]:.1f} s before Ray and {serial_runs[1]:.1f} s after) | "
        f"{serial.seconds:.1f} | {serial.oracle_seconds:.1f} | 1.00 |",
        f"| Ray, fresh workers (each imports the package on its first piece) | {fresh.seconds:.1f} | "
        f"{fresh.oracle_seconds:.1f} | {serial.seconds / fresh.seconds:.2f} |",
        f"| Ray, warm workers (the faster of two runs) | {warm.seconds:.1f} | {warm.oracle_seconds:.1f} | "
        f"{serial.seconds / warm.seconds:.2f} |",
        "",
        f"Records of every episode equal to the serial ones, bit for bit, in the Ray runs: "
        f"**{'yes' if identical else 'NO'}**. The last map: {spread}.", "",
        f"A fresh `--backend ray` command pays Ray's start-up too: {costs.start:.1f} s (below), so the command's "
        f"work takes about {costs.start + fresh.seconds:.0f} s on Ray against {serial.seconds:.0f} s serially "
        "(the command line adds the same imports, statistics and figures to both).", "",
        "## 2. Ray's own costs", "",
        "| measure | value |", "|---|---|",
        f"| start-up: `ray.init` on this machine and a first empty task | {costs.start:.2f} s |",
        f"| one more empty task, alone | {1000 * one_task:.1f} ms |",
        f"| cost per task, {size.noop_tasks} empty tasks mapped at once | {1000 * costs.per_task:.2f} ms |",
        f"| fresh workers' warm-up (first evaluation minus the faster warm one, 0 if not longer) | "
        f"{costs.warm_up:.1f} s |",
        f"| CPUs' worth the machine gave {cpus} CPU-bound tasks at once (before the evaluations on Ray, at the end) | "
        + ", ".join(f"{value:.2f}" for value in capacities) + " |",
        f"| efficiency: serial work / ({cpus} CPUs x warm Ray wall) | {costs.efficiency:.2f} |",
        f"| mean piece of the evaluation (serial) | {1000 * mean_piece:.0f} ms, {mean_piece / costs.per_task:.0f}x "
        "the cost per task |", "",
        "## 3. Per-episode cost of each policy (serial, this process)", "",
        f"Each policy's seconds inside its batches (vector envs of {per_batch:.0f} episodes), over its {episodes} "
        "episodes; on Ray, the same batches' seconds inside the (warm) workers.",
        "", "| policy | seconds per episode | its batches on Ray, warm [s] |", "|---|---|---|",
        *(f"| {serial.names[key]} | {spent / episodes:.3f} | {warm.timings[key]:.1f} |"
          for key, spent in serial.timings.items()),
        "",
        "## 4. The other scripts, serial against Ray (warm: Ray already started in this process)", "",
        "| command | serial [s] | Ray [s] | speed-up | files identical |", "|---|---|---|---|---|",
        *(f"| `python -m {name}{''.join(' ' + a for a in arguments)}` | {times['serial']:.1f} | {times['ray']:.1f} | "
          f"{times['serial'] / times['ray']:.2f} | {'yes' if same else 'NO'} |"
          for name, (times, same, arguments) in scripts.items()),
        "",
        f"## 5. Paper estimate: a sweep of {cells} config cells on N nodes", "",
        f"The sweep: {cells} config cells (reward weights, degradation sizes, monitor windows, ...), each the full "
        f"evaluation above: {n_policies} policies x {episodes} episodes x {cells} cells = "
        f"{n_policies * episodes * cells:,} episodes, {cells * serial.pieces:,} pieces "
        f"({cells * serial.batch_pieces:,} episode batches and {cells * (serial.pieces - serial.batch_pieces)} for "
        f"the oracle each cell measures again), {cells * costs.work:.0f} s of serial work and "
        f"{cells * costs.driver:.0f} s of statistics in the driver. Nodes of {CPUS_PER_NODE} CPUs like this one. "
        "Model: start-up + workers' warm-up (on every node at once) + the pieces in rounds of one per CPU, each round "
        f"a mean piece ({mean_piece:.2f} s) / efficiency ({costs.efficiency:.2f}), or the driver's cost per task "
        f"({1000 * costs.per_task:.2f} ms) x pieces if longer, + the driver's statistics per cell. Not measured: "
        "joining a remote cluster and shipping the repository (`working_dir`) to it, taken as this machine's "
        "start-up; the network (a piece's records are a few kB).", "",
        "| nodes | CPUs | rounds | estimated wall | speed-up vs serial | share that does not shrink (start-up, "
        "warm-up, statistics) |", "|---|---|---|---|---|---|",
        f"| serial, one process | 1 | – | {duration(serial_seconds(costs, cells))} | 1.0 | – |",
    ]
    for nodes in NODES:
        wall = sweep_seconds(costs, cells, nodes, CPUS_PER_NODE)
        fixed = costs.start + costs.warm_up + cells * costs.driver
        lines.append(f"| {nodes} | {nodes * CPUS_PER_NODE} | {math.ceil(cells * serial.pieces / (nodes * CPUS_PER_NODE))} "
                     f"| {duration(wall)} | {serial_seconds(costs, cells) / wall:.1f} | {100 * fixed / wall:.0f} % |")
    even = break_even_work(costs, cpus)
    fresh_cost = costs.start + costs.warm_up  # what a fresh --backend ray command pays before its work speeds up
    verdicts = [("the evaluation", serial.seconds, fresh_cost + warm.seconds)] + [
        (f"`{name}`", times["serial"], fresh_cost + times["ray"]) for name, (times, _, _) in scripts.items()]
    lines += [
        "", "## Where Ray pays, and where it does not", "",
        f"- **On this {cpus}-CPU machine** the evaluation's work runs {serial.seconds / warm.seconds:.2f}x faster on "
        f"warm Ray workers than serially (efficiency {costs.efficiency:.2f}; 1 would be all {cpus} CPUs fully used"
        + (": above 1 because the serial run was slowed, its torch running PPO on several threads that crawl when "
           "other processes load the CPUs, where Ray's workers use one thread each" if costs.efficiency > 1 else "")
        + f"; the machine itself gave {min(capacities):.2f}-{max(capacities):.2f} CPUs' worth to {cpus} CPU-bound "
        "tasks at once, its virtual CPUs sharing the host's cores with other work, which bounds any speed-up here"
        + "). A fresh `--backend ray` command first pays Ray's start-up and its workers' warm-up "
        f"({fresh_cost:.0f} s here), so Ray pays once the spread work is worth more than about "
        + (f"**{even:.0f} s serially**" if math.isfinite(even) else "**never** (no speed-up here)") + ". Here: "
        + "; ".join(f"{what}: {alone:.0f} s serial against about {spread_out:.0f} s for a fresh Ray command "
                    f"({'Ray pays' if spread_out < alone else 'Ray does not pay'})"
                    for what, alone, spread_out in verdicts)
        + ". Tests and small runs (`--episodes 14`) are faster serially.",
        f"- **Per piece**: Ray costs {1000 * costs.per_task:.2f} ms per task in the driver; a piece must take much "
        f"longer than that. The evaluation's pieces take {1000 * mean_piece:.0f} ms ({mean_piece / costs.per_task:.0f}x); "
        f"pieces of one episode (about {1000 * mean_piece / per_batch:.0f} ms) would still pay, a single env step "
        "(about 0.2 ms, `results/bench.md`) would not: keep a vector env's batch as the piece.",
        f"- **Across nodes**: the sweep's {cells * serial.pieces:,} pieces keep "
        f"{NODES[-1] * CPUS_PER_NODE} CPUs busy for {math.ceil(cells * serial.pieces / (NODES[-1] * CPUS_PER_NODE))} "
        "rounds, so the speed-up grows with the nodes until the parts that do not shrink (start-up, warm-up, the "
        "driver's statistics per cell) dominate; beyond that, more nodes buy nothing: spread the statistics as "
        "pieces too, or sweep more cells.",
        "",
    ]
    return "\n".join(lines)


def duration(seconds: float) -> str:
    """Seconds as '12 s', '3.4 min' or '1.2 h'."""
    if seconds < 120:
        return f"{seconds:.0f} s"
    return f"{seconds / 60:.1f} min" if seconds < 7200 else f"{seconds / 3600:.1f} h"


if __name__ == "__main__":
    cli.run(main, "python -m train.bench_ray")
