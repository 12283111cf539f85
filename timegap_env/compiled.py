"""How the package's numba kernels are compiled.

A stage kernel (``ladder_env``, ``chart_sides_env``, ``count_excursions_env``, ``env_readouts``, ``encode_env``,
...) works on one env and is called only from compiled code: the fused step and the components' loops over envs.
It is compiled once and cached on its own (``STAGE_KERNEL``), without NumPy allocation (numba's reference counting
off, so that an allocation fails to compile rather than costing time at every call) and without the wrappers that
would let Python call it. Inlining every stage into the fused step instead made the fused step's compilation
most of a fresh install's first step (``make bench``'s cold start; issue 27's commits give the A/B).

The three heaviest stages, ``advance_env`` (the physics), ``measure_env`` (the sensors) and ``update_env`` (the
monitor), are inlined into their callers (``INLINED_STAGE_KERNEL``): called env by env with ~40 arrays each, a call
cost more than the work of a short block (compiled apart, ``make bench``'s batched simulator ran at half its speed),
while inlining these three added no measurable compile time. ``_nrt`` is a private numba option (as of numba
0.60-0.68); the tests compile every kernel.

A kernel called from Python pays for each array it is handed, at every call (numba unpacks them one by one):
the fused step is handed the env's state as a few blocks (:mod:`timegap_env.state`). :func:`prefetch_env` and
:func:`prefetch_rows` ask the CPU for an env's rows ahead of their use (a layout's ``prefetch`` for all of a
state's), :func:`prefetch_item` for one element where an env reads a row in the middle.
"""

from __future__ import annotations

import contextlib
import functools
import gc
import hashlib
import pickle
import re
import sys
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from types import CodeType, ModuleType
from typing import Any

import numba
import numpy as np
from llvmlite import ir  # numba's code generator, a dependency of numba: what its extensions build code with
from numba.core import cgutils, types
from numba.core.dispatcher import Dispatcher
from numba.extending import intrinsic

NO_ALLOCATION: dict[str, Any] = {"_nrt": False}  # numba's reference counting off: an allocation fails to compile
STAGE_KERNEL: dict[str, Any] = {"cache": True, "error_model": "numpy", **NO_ALLOCATION, "no_cpython_wrapper": True,
                                "no_cfunc_wrapper": True}

INLINED_STAGE_KERNEL: dict[str, Any] = {"cache": True, "error_model": "numpy", "inline": "always"}



@intrinsic
def prefetch_env(typingctx, value, e):  # noqa: ANN001, ANN201
    """Hint env ``e``'s first cache line of ``value`` in, to be read and written soon: ``value[e, 0, ...]`` of an
    array whose first axis is the envs' (LLVM's prefetch, which never changes a result nor faults, whatever the
    address); of anything else, nothing. Compiled code only."""
    return types.none(value, e), _prefetch_codegen(axis=0)


@intrinsic
def prefetch_rows(typingctx, stack, e):  # noqa: ANN001, ANN201
    """Hint env ``e``'s first cache line of every row of ``stack`` (rows, n_envs, ...) in (see :func:`prefetch_env`)."""
    return types.none(stack, e), _prefetch_codegen(axis=1)


@intrinsic
def prefetch_item(typingctx, array, index):  # noqa: ANN001, ANN201
    """Hint the cache line of ``array[index]`` in, to be read and written soon, ``index`` a tuple of integers, the
    array's remaining indices 0: for rows an env reads at a place that moves from step to step (the leader's
    samples, a ring's slots), which :func:`prefetch_env` (the row's start) misses. Never changes a result nor
    faults (see :func:`prefetch_env`). Compiled code only."""
    if not (isinstance(array, types.Array) and isinstance(index, types.UniTuple)
            and isinstance(index.dtype, types.Integer) and index.count <= array.ndim):
        return None  # a typing error: an array and a tuple of at most ndim integers

    def codegen(context, builder, signature, args):  # noqa: ANN001, ANN202
        array_type, index_type = signature.args
        indices = [context.cast(builder, value, index_type.dtype, types.intp)
                   for value in cgutils.unpack_tuple(builder, args[1], index_type.count)]
        zero = context.get_constant(types.intp, 0)
        _hint(context, builder, array_type, args[0], indices + [zero] * (array_type.ndim - index_type.count))
        return context.get_dummy_value()

    return types.none(array, index), codegen


def _prefetch_codegen(axis: int) -> Callable:
    """The code of a hint at index ``e`` on ``axis`` (0, or 1 with every index of axis 0), the other indices 0."""

    def codegen(context, builder, signature, args):  # noqa: ANN001, ANN202
        array_type, index_type = signature.args
        if not isinstance(array_type, types.Array) or array_type.ndim <= axis:
            return context.get_dummy_value()
        array = context.make_array(array_type)(context, builder, args[0])
        zero, env = context.get_constant(types.intp, 0), context.cast(builder, args[1], index_type, types.intp)
        rows = cgutils.unpack_tuple(builder, array.shape)[0] if axis else context.get_constant(types.intp, 1)
        with cgutils.for_range(builder, rows) as loop:
            indices = ([loop.index, env] if axis else [env]) + [zero] * (array_type.ndim - axis - 1)
            _hint(context, builder, array_type, args[0], indices)
        return context.get_dummy_value()

    return codegen


def _hint(context: Any, builder: ir.IRBuilder, array_type: types.Array, value: Any, indices: list) -> None:
    """LLVM's prefetch (to be written soon, kept in every cache level) of the element at ``indices`` of the array
    ``value``, no bounds checked."""
    array = context.make_array(array_type)(context, builder, value)
    shape, strides = cgutils.unpack_tuple(builder, array.shape), cgutils.unpack_tuple(builder, array.strides)
    pointer = cgutils.get_item_pointer2(context, builder, array.data, shape, strides, array_type.layout, indices,
                                        wraparound=False, boundscheck=False)
    byte_pointer, flag = ir.IntType(8).as_pointer(), ir.IntType(32)
    hint = cgutils.get_or_insert_function(
        builder.module, ir.FunctionType(ir.VoidType(), [byte_pointer, flag, flag, flag]), "llvm.prefetch.p0i8")
    builder.call(hint, [builder.bitcast(pointer, byte_pointer), flag(1), flag(3), flag(1)])  # write, keep, data


def compiled_entry(kernel: Dispatcher, *args: Any) -> Callable:
    """``kernel``'s compiled function for the types of ``args`` (compiled, or loaded from numba's cache, if need be),
    for a caller whose arguments keep exactly those types from call to call: numba's dispatcher works out the type
    of every argument again at each call (for the fused step's ~110, more than the unpacking), the compiled function
    does not. It reads whatever it is given as those types, so arguments of other types are the caller's error to
    prevent. Python's garbage collector is paused while it compiles: numba makes objects by the hundred thousand,
    and collecting as they come walked them again and again."""
    with collection_paused():
        return kernel.compile(tuple(numba.typeof(arg) for arg in args))


@contextlib.contextmanager
def collection_paused() -> Iterator[None]:
    """Python's garbage collector paused in the block, then as it was: for work that makes many objects that live on
    (numba's compilation; a batched draw of episodes, several objects per env), which collecting as they come would
    walk again and again."""
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if enabled:
            gc.enable()


def follow_sources(module: str, reached: tuple[str, ...] = ()) -> None:
    """Make the numba cache of every kernel defined in ``module`` (imported, by name) fresh exactly while the
    contents of the files its compiled code comes from are unchanged: those of the modules of its package that its
    kernels reach (:func:`reached_modules`) and of ``reached`` (modules outside the package). Every module of
    kernels calls it once, after its last kernel.

    numba stamps a cache with its kernel's own file only (0.68: a hash of its contents; before: its modification
    time and size) and reloads it while that is unchanged. Two things break that. A kernel carries the compiled
    code of the kernels it calls, inlined or not, also those of other files (the fused step every stage's, a stage
    the kernels it calls in turn), and the values of the constants it reads, so an edit there alone would leave it
    running the old code. And, before numba 0.68, installing a file gave it a new modification time, so the cache a
    wheel ships (:mod:`timegap_env.precompile`) would always look stale. Each cache's source stamp becomes a hash of
    all these contents instead. numba 0.68 keeps the stamp in the dispatcher's ``_cache._cache_file._source_stamp``;
    should that move, numba's own stamp decides.

    An index numba cannot read back counts as stale too: numba unpickles a cache's index before it compares the
    stamps, and an index written by an older version of these modules may name a class that is gone (a NamedTuple
    of a cached signature, renamed), which would raise at the kernel's first call instead of compiling it again.
    """
    kernels = list(_kernels(module))
    sources = sorted({module, *reached}.union(*(reached_modules(kernel) for kernel in kernels)))
    digest = hashlib.sha256()
    for name in sources:
        digest.update(_source(name).encode())
    stamp, call = f"sha256 of {', '.join(sources)}: {digest.hexdigest()}", (module, reached)
    for kernel in kernels:
        cache_file = getattr(getattr(kernel, "_cache", None), "_cache_file", None)
        if cache_file is None:
            continue
        if getattr(cache_file, "_followed", call) != call:  # the same call again (a module reloaded) may restamp
            raise ValueError(f"follow_sources: kernel {kernel.py_func.__qualname__} of {kernel.py_func.__module__} "
                             "is stamped by two calls")
        cache_file._followed = call
        if hasattr(cache_file, "_source_stamp"):
            cache_file._source_stamp = stamp
        if hasattr(cache_file, "_load_index") and not hasattr(cache_file, "_load_numba_index"):
            cache_file._load_numba_index = cache_file._load_index
            cache_file._load_index = _readable_or_stale(cache_file._load_numba_index)


def reached_modules(kernel: Dispatcher) -> set[str]:
    """The modules of ``kernel``'s package whose code or constants compile into it: its own; for each global name
    its code reads, the module that defines the value (a class's, a function's: its ``__module__``) and the module
    it is imported from; those of every kernel it calls, in turn; and every module of the package these import
    from (a constant may be computed from theirs at import: ``EWMA = CHART_KINDS.index("ewma")``). Over-counting
    costs a recompilation after an edit, under-counting a stale cache: a name counts wherever it could come from."""
    package = kernel.py_func.__module__.partition(".")[0]
    modules: set[str] = set()
    seen: set[int] = set()
    functions = [kernel.py_func]
    while functions:
        function = functions.pop()
        if id(function) in seen:
            continue
        seen.add(id(function))
        home = function.__globals__.get("__name__")  # None: generated code (a Layout's views)
        imported = _imported_names(home) if home else {}
        modules.update({home} if home else set())
        for name in _global_names(function.__code__):
            if name not in function.__globals__:
                continue
            value = function.__globals__[name]
            if isinstance(value, Dispatcher):
                functions.append(value.py_func)
            source = value.__name__ if isinstance(value, ModuleType) else getattr(value, "__module__", None)
            modules.update(candidate for candidate in (source, imported.get(name))
                           if isinstance(candidate, str) and candidate.partition(".")[0] == package)
    imports = {source for name in modules for source in _imported_names(name).values()
               if source.partition(".")[0] == package}  # what their constants may have been computed from
    return {name for name in modules | imports if name in sys.modules}


def _global_names(code: CodeType) -> set[str]:
    """The names ``code`` and the code nested in it read, globals among them."""
    names = set(code.co_names)
    for constant in code.co_consts:
        if isinstance(constant, CodeType):
            names |= _global_names(constant)
    return names


_FROM_IMPORT = re.compile(r"^from\s+([\w.]+)\s+import\s+(\([^)]*\)|[^\n]*)", flags=re.MULTILINE)


@functools.cache
def _imported_names(module: str) -> dict[str, str]:
    """Each name ``module`` imports with ``from ... import``, and the module it comes from."""
    names = {}
    for source, imported in _FROM_IMPORT.findall(_source(module)):
        for item in re.sub(r"#[^\n]*", "", imported).strip("()").split(","):
            parts = item.split()
            if parts:
                names[parts[-1]] = source  # "name" or "name as alias"
    return names


@functools.cache
def _source(module: str) -> str:
    """The text of ``module``'s file."""
    path = sys.modules[module].__file__
    assert path is not None  # kernels live in files
    return Path(path).read_text(encoding="utf-8")


def _readable_or_stale(load_index: Callable[[], dict]) -> Callable[[], dict]:
    """numba's index loader, an index it cannot unpickle read as an empty one (stale: compiled and written anew)."""

    def load() -> dict:
        try:
            return load_index()
        except (AttributeError, ImportError, EOFError, pickle.UnpicklingError):
            return {}

    return load


def _kernels(module: str) -> Iterable[Dispatcher]:
    """Every numba kernel defined in ``module``, once each."""
    seen: set[int] = set()
    for value in vars(sys.modules[module]).values():
        if isinstance(value, Dispatcher) and value.py_func.__module__ == module and id(value) not in seen:
            seen.add(id(value))
            yield value


__all__ = ["INLINED_STAGE_KERNEL", "NO_ALLOCATION", "STAGE_KERNEL", "collection_paused", "compiled_entry",
           "follow_sources", "prefetch_env", "prefetch_item", "prefetch_rows", "reached_modules"]
