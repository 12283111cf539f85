"""How the package's numba kernels are compiled.

A stage kernel (``ladder_env``, ``chart_sides_env``, ``count_excursions_env``, ``env_readouts``, ``encode_env``,
...) works on one env and is called only from compiled code: the fused step and the staged path's loops over envs.
It is compiled once and cached on its own (``STAGE_KERNEL``), without NumPy allocation (numba's reference counting
off, so that an allocation fails to compile rather than costing time at every call) and without the wrappers that
would let Python call it. Inlining every stage into the fused step instead made the fused step's compilation most of
a fresh install's first step (2.5 CPU-s more, issue 27).

The three heaviest stages, ``advance_env`` (the physics), ``measure_env`` (the sensors) and ``update_env`` (the
monitor), are inlined into their callers (``INLINED_STAGE_KERNEL``): called env by env with ~40 arrays each, a call
cost more than the work of a short block (the batched simulator ran at 60 M vehicle-ticks/s against 133 M inlined,
and the fused step 10 % slower), while inlining these three added no measurable compile time. ``_nrt`` is a private
numba option (as of numba 0.60-0.68); the tests compile every kernel.
"""

from __future__ import annotations

from typing import Any

NO_ALLOCATION: dict[str, Any] = {"_nrt": False}  # numba's reference counting off: an allocation fails to compile
STAGE_KERNEL: dict[str, Any] = {"cache": True, "error_model": "numpy", **NO_ALLOCATION, "no_cpython_wrapper": True,
                                "no_cfunc_wrapper": True}

INLINED_STAGE_KERNEL: dict[str, Any] = {"cache": True, "error_model": "numpy", "inline": "always"}

__all__ = ["INLINED_STAGE_KERNEL", "NO_ALLOCATION", "STAGE_KERNEL"]
