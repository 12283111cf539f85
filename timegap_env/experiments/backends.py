"""Where a script's independent pieces of work run: in this process, or as Ray tasks.

A piece is a call ``function(*arguments)`` whose result depends on its arguments alone (an episode
batch, say: the env seeds everything it draws), so both backends return the same results, in order,
bit for bit. ``--backend serial`` (the default) runs the pieces one after another here;
``--backend ray`` runs each as a Ray task (one CPU each): with no ``--address`` Ray starts on this
machine and stops with the script, with ``--address`` (e.g. ``ray://head:10001`` or ``auto``) the
script joins that cluster. Ray comes with the ``ray`` extra (``pip install -e '.[ray]'``).

On a cluster the workers get this repository's code (Ray's ``working_dir``) and read the data from
the paths of ``TIMEGAP_NGSIM_PATH`` / ``TIMEGAP_OPENACC_PATH`` as the driver resolves them: the data
must be at those paths on every node.
"""

from __future__ import annotations

import argparse
import os
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[2]  # the repository (a clone): what Ray ships to a cluster
BACKENDS = ("serial", "ray")
NOT_SHIPPED = [".git", ".venv", ".venv-clients", "results", "runs", "*.egg-info", "__pycache__"]  # of working_dir


def call(function: Callable[..., Any], *arguments: Any) -> Any:
    """``function(*arguments)``: what a Ray task runs, so that any callable can be a backend's function."""
    return function(*arguments)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``--backend`` and ``--address`` on a script's command line."""
    parser.add_argument("--backend", choices=BACKENDS, default="serial",
                        help="serial: here, one piece after another (default); ray: each piece a Ray task")
    parser.add_argument("--address", default=None,
                        help="with --backend ray: the cluster to join (default: start Ray on this machine)")


class Backend:
    """Runs pieces of work serially or on Ray; :meth:`describe` says how the last :meth:`map` spread them."""

    def __init__(self, name: str = "serial", address: str | None = None) -> None:
        if name not in BACKENDS:
            raise ValueError(f"backend = {name!r}: must be one of {BACKENDS}")
        if address is not None and name != "ray":
            raise ValueError(f"address = {address!r}: only with the ray backend")
        self.name, self.address = name, address
        self._spread = "not used yet"

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> Backend:
        return cls(args.backend, args.address)

    def map(self, function: Callable[..., Any], pieces: Sequence[tuple[Any, ...]]) -> list[Any]:
        """``[function(*piece) for piece in pieces]``, here or as Ray tasks, in the order of ``pieces``."""
        start = time.perf_counter()
        if self.name == "serial":
            results = [function(*piece) for piece in pieces]
            self._spread = f"serial: {len(pieces)} pieces one after another in this process"
        else:
            results = self._ray_map(function, pieces)
        self._spread += f", {time.perf_counter() - start:.1f} s wall"
        return results

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
