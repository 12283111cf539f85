"""Where a script's independent pieces of work run: in this process, in worker processes, or as Ray tasks.

A piece is a call ``function(*arguments)`` whose result depends on its arguments alone (an episode
batch, say: the env seeds everything it draws), so every backend returns the same results, in order,
bit for bit. ``--backend serial`` (the default) runs the pieces one after another here;
``--backend processes`` in a pool of worker processes on this machine (``--workers``, default one per CPU; each
piece's function and arguments are pickled to a worker, as SUMO needs: libsumo runs one simulation per process;
the pool starts at the first ``map`` and serves every later one, so what a worker builds once, compiled kernels
and memoised leaders, serves many pieces; ``close`` or the end of the process stops it);
``--backend ray`` runs each as a Ray task (one CPU each): with no ``--address`` Ray starts on this
machine and stops with the script, with ``--address`` (e.g. ``ray://head:10001`` or ``auto``) the
script joins that cluster. Ray comes with the ``ray`` extra (``pip install -e '.[ray]'``).

On a cluster the workers get this repository's code (Ray's ``working_dir``) and read the data from
the paths of ``TIMEGAP_NGSIM_PATH`` / ``TIMEGAP_OPENACC_PATH`` as the driver resolves them: the data
must be at those paths on every node.
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import time
import weakref
from concurrent.futures import ProcessPoolExecutor
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[2]  # the repository (a clone): what Ray ships to a cluster
BACKENDS = ("serial", "processes", "ray")
NOT_SHIPPED = [".git", ".venv", ".venv-clients", "results", "runs", "*.egg-info", "__pycache__"]  # of working_dir


def call(function: Callable[..., Any], *arguments: Any) -> Any:
    """``function(*arguments)``: what a Ray task runs, so that any callable can be a backend's function."""
    return function(*arguments)


def call_piece(work: tuple[Callable[..., Any], tuple[Any, ...]]) -> Any:
    """``function(*piece)`` of ``work = (function, piece)``: what a worker process runs."""
    function, piece = work
    return function(*piece)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``--backend`` and ``--address`` on a script's command line."""
    parser.add_argument("--backend", choices=BACKENDS, default="serial",
                        help="serial: here, one piece after another (default); processes: a pool of worker "
                             "processes here; ray: each piece a Ray task")
    parser.add_argument("--address", default=None,
                        help="with --backend ray: the cluster to join (default: start Ray on this machine)")
    parser.add_argument("--workers", type=int, default=None,
                        help="with --backend processes: worker processes (default: one per CPU)")


class Backend:
    """Runs pieces of work serially, in worker processes (``workers``: how many; None: one per CPU) or on Ray
    (``address``: the cluster); :meth:`describe` says how the last :meth:`map` spread them."""

    def __init__(self, name: str = "serial", address: str | None = None, workers: int | None = None) -> None:
        if name not in BACKENDS:
            raise ValueError(f"backend = {name!r}: must be one of {BACKENDS}")
        if address is not None and name != "ray":
            raise ValueError(f"address = {address!r}: only with the ray backend")
        if workers is not None and (name != "processes" or isinstance(workers, bool) or not isinstance(workers, int)
                                    or workers < 1):
            raise ValueError(f"workers = {workers!r}: an integer >= 1, only with the processes backend")
        self.name, self.address, self.workers = name, address, workers
        self._spread = "not used yet"
        self._pool: ProcessPoolExecutor | None = None  # the processes backend's, from the first map on

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> Backend:
        return cls(args.backend, args.address, getattr(args, "workers", None))

    def map(self, function: Callable[..., Any], pieces: Sequence[tuple[Any, ...]]) -> list[Any]:
        """``[function(*piece) for piece in pieces]``, here, in worker processes or as Ray tasks, in the order of
        ``pieces``."""
        start = time.perf_counter()
        if self.name == "serial":
            results = [function(*piece) for piece in pieces]
            self._spread = f"serial: {len(pieces)} pieces one after another in this process"
        elif self.name == "processes":
            workers = self.workers or os.cpu_count() or 1
            if self._pool is None:
                self._pool = ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn"))
                weakref.finalize(self, self._pool.shutdown)  # at the latest when the backend or the process ends
            try:
                results = list(self._pool.map(call_piece, [(function, piece) for piece in pieces]))
            except BaseException:  # a piece that raised, a worker that died, an interrupt: no half-used pool kept
                self.close()
                raise
            self._spread = f"processes: {len(pieces)} pieces on {workers} worker processes"
        else:
            results = self._ray_map(function, pieces)
        self._spread += f", {time.perf_counter() - start:.1f} s wall"
        return results

    def close(self) -> None:
        """Stop the processes backend's worker processes (the next map starts new ones); nothing for the others."""
        if self._pool is not None:
            self._pool.shutdown(cancel_futures=True)
            self._pool = None

    def describe(self) -> str:
        """How the last map spread its work, for a results table's header."""
        return self._spread

    def _ray_map(self, function: Callable[..., Any], pieces: Sequence[tuple[Any, ...]]) -> list[Any]:
        try:
            import ray
        except ImportError as error:
            raise RuntimeError("--backend ray needs Ray: pip install -e '.[ray]'") from error
        if not ray.is_initialized():
            ray.init(address=self.address, runtime_env=runtime_env(self.address), include_dashboard=False,
                     logging_level="WARNING", log_to_driver=True)
        task = ray.remote(num_cpus=1)(call)  # ray.remote takes Python functions only, not a builtin or a partial
        shared = ray.put(function)  # serialised once, not once per task
        results = ray.get([task.remote(shared, *piece) for piece in pieces])
        nodes = [node for node in ray.nodes() if node["Alive"]]
        cpus = int(ray.cluster_resources().get("CPU", 0))
        where = "started on this machine" if self.address is None else f"cluster at {self.address}"
        self._spread = f"ray ({where}): {len(pieces)} tasks of 1 CPU on {cpus} CPUs, {len(nodes)} node(s)"
        return results

def runtime_env(address: str | None) -> dict[str, Any]:
    """What Ray's workers need: this repository's code and where the data are. On this machine (``address``
    None) the workers share its install and only the scripts' folder is added to their path; on a cluster the
    repository is shipped as Ray's ``working_dir``."""
    from timegap_env.leaders import default_ngsim_path, default_openacc_dir

    data = {"TIMEGAP_NGSIM_PATH": str(default_ngsim_path()), "TIMEGAP_OPENACC_PATH": str(default_openacc_dir())}
    if address is None:
        path = os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")]))
        return {"env_vars": {**data, "PYTHONPATH": path}}
    return {"working_dir": str(REPO), "excludes": NOT_SHIPPED, "env_vars": data}


__all__ = ["BACKENDS", "Backend", "add_arguments", "runtime_env"]
