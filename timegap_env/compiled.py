"""How the package's numba kernels are compiled.

A stage kernel (``ladder_env``, ``chart_sides_env``, ``count_excursions_env``, ``env_readouts``, ``encode_env``,
...) works on one env and is called only from compiled code: the fused step and the staged path's loops over envs.
It is compiled once and cached on its own (``STAGE_KERNEL``), without NumPy allocation (numba's reference counting
off, so that an allocation fails to compile rather than costing time at every call) and without the wrappers that
would let Python call it. Inlining every stage into the fused step instead made the fused step's compilation
most of a fresh install's first step (``make bench``'s cold start; issue 27's commits give the A/B).

The three heaviest stages, ``advance_env`` (the physics), ``measure_env`` (the sensors) and ``update_env`` (the
monitor), are inlined into their callers (``INLINED_STAGE_KERNEL``): called env by env with ~40 arrays each, a call
cost more than the work of a short block (compiled apart, ``make bench``'s batched simulator ran at half its speed),
while inlining these three added no measurable compile time. ``_nrt`` is a private numba option (as of numba
0.60-0.68); the tests compile every kernel.
"""

from __future__ import annotations

import hashlib
import sys
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from numba.core.dispatcher import Dispatcher

NO_ALLOCATION: dict[str, Any] = {"_nrt": False}  # numba's reference counting off: an allocation fails to compile
STAGE_KERNEL: dict[str, Any] = {"cache": True, "error_model": "numpy", **NO_ALLOCATION, "no_cpython_wrapper": True,
                                "no_cfunc_wrapper": True}

INLINED_STAGE_KERNEL: dict[str, Any] = {"cache": True, "error_model": "numpy", "inline": "always"}



def follow_sources(modules: tuple[str, ...]) -> None:
    """Make the numba cache of every kernel in ``modules`` (imported, by name) go stale when any of those modules'
    files changes, as when its own file does.

    numba reloads a cached kernel while the kernel's own file is unchanged; a kernel carries the compiled code of
    the kernels it calls, inlined or not, also those of other files (the fused step every stage's, a stage the
    kernels it calls in turn), so an edit there alone would leave it running the old code. Each cache's source
    stamp becomes its own file's and a hash of all ``modules``' contents. numba 0.68 keeps it in the dispatcher's
    ``_cache._cache_file._source_stamp``; should that move, the kernel's own file alone decides, as numba does.
    """
    digest = hashlib.sha256()
    for module in modules:
        source = sys.modules[module].__file__
        assert source is not None  # the package's modules are files
        digest.update(Path(source).read_bytes())
    for kernel in _kernels(modules):
        cache_file = getattr(getattr(kernel, "_cache", None), "_cache_file", None)
        if cache_file is not None and hasattr(cache_file, "_source_stamp"):
            cache_file._source_stamp = (cache_file._source_stamp, digest.hexdigest())


def _kernels(modules: tuple[str, ...]) -> Iterable[Dispatcher]:
    """Every numba kernel defined in ``modules``, once each."""
    seen: set[int] = set()
    for module in modules:
        for value in vars(sys.modules[module]).values():
            if isinstance(value, Dispatcher) and value.py_func.__module__ == module and id(value) not in seen:
                seen.add(id(value))
                yield value


__all__ = ["INLINED_STAGE_KERNEL", "NO_ALLOCATION", "STAGE_KERNEL", "follow_sources"]
