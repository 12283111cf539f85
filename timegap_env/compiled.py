"""How the package's numba kernels are compiled.

A stage kernel (``advance_env``, ``measure_env``, ``update_env``, ``chart_sides_env``, ``ladder_env``, ...) works on
one env and is called only from compiled code: the fused step and the staged path's loops over envs. It is compiled
once and cached on its own, without NumPy allocation (numba's reference counting off, so that an allocation fails to
compile rather than costing time at every call) and without the wrappers that would let Python call it. Inlining
every stage into the fused step instead made the fused step's compilation most of a fresh install's first step
(issue 27). ``_nrt`` is a private numba option (as of numba 0.60-0.68); the tests compile every kernel.
"""

from __future__ import annotations

from typing import Any

NO_ALLOCATION: dict[str, Any] = {"_nrt": False}  # numba's reference counting off: an allocation fails to compile
STAGE_KERNEL: dict[str, Any] = {"cache": True, "error_model": "numpy", **NO_ALLOCATION, "no_cpython_wrapper": True,
                                "no_cfunc_wrapper": True}

__all__ = ["NO_ALLOCATION", "STAGE_KERNEL"]
