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

A kernel called from Python pays for each array it is handed, at every call (numba unpacks them one by one):
:class:`Stacked` hands the fused step a structure's arrays of one dtype and shape as the rows of one
stack, which the structure's owner allocates as such. :func:`prefetch_env` and :func:`prefetch_rows` ask the CPU
for an env's rows ahead of their use (each layout's ``prefetch`` for all of a structure's), :func:`prefetch_item`
for one element where an env reads a row in the middle.
"""

from __future__ import annotations

import contextlib
import gc
import hashlib
import pickle
import sys
from collections.abc import Callable, Iterable, Iterator, Mapping
from pathlib import Path
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



class Stacked:
    """How a NamedTuple of arrays is handed to a kernel as a few arrays, its *form*, and made again inside.

    Each group of ``groups`` names fields of one dtype and shape that its owner allocates as the rows, in the
    group's order, of one C-contiguous stack (``np.zeros((len(group), *shape))[i]``); the form holds that stack at
    the place of the group's first field, each other field as it is, and a field of ``nested`` in that
    structure's own form. :attr:`unstack` (a kernel inlined into its caller) makes the plain tuple of the fields
    again, views of the stacks, as the stage kernels take their structures (``tuple(value)``).
    """

    def __init__(self, cls: type, groups: tuple[tuple[str, ...], ...], nested: Mapping[str, Stacked] | None = None
                 ) -> None:
        self.cls, self.groups, self.nested = cls, groups, dict(nested or {})
        STACKED[cls] = self
        fields: tuple[str, ...] = cls._fields  # type: ignore[attr-defined]
        named = [name for group in groups for name in group] + list(self.nested)
        if sorted(set(named)) != sorted(named) or not set(named) <= set(fields):
            raise ValueError(f"Stacked {cls.__name__}: groups {groups} and nested {list(self.nested)} must name "
                             f"distinct fields of {fields}")
        where = {name: (g, row) for g, group in enumerate(groups) for row, name in enumerate(group)}
        self._places: list[tuple[str, Any]] = []  # what each place of the form holds: a group, a nested or a field
        rows, hints = [], []  # each field's expression in unstack, each place's hint in prefetch
        for name in fields:
            if name in where:
                group, row = where[name]
                if ("group", group) not in self._places:
                    self._places.append(("group", group))
                    hints.append(f"prefetch_rows(form[{len(self._places) - 1}], e)")
                rows.append(f"form[{self._places.index(('group', group))}][{row}]")
            elif name in self.nested:
                self._places.append(("nested", name))
                rows.append(f"unstack_{name}(form[{len(self._places) - 1}])")
                hints.append(f"prefetch_{name}(form[{len(self._places) - 1}], e)")
            else:
                self._places.append(("field", name))
                rows.append(f"form[{len(self._places) - 1}]")
                hints.append(f"prefetch_env(form[{len(self._places) - 1}], e)")
        namespace: dict[str, Any] = {"prefetch_rows": prefetch_rows, "prefetch_env": prefetch_env}
        for name, inner in self.nested.items():
            namespace[f"unstack_{name}"], namespace[f"prefetch_{name}"] = inner.unstack, inner.prefetch
        source = (f"def unstack(form):\n    return ({', '.join(rows)},)\n\n\ndef prefetch(form, e):\n"
                  + "".join(f"    {hint}\n" for hint in hints))
        exec(compile(source, f"<{cls.__name__}'s Stacked.unstack>", "exec"), namespace)  # noqa: S102
        self.unstack: Callable[[tuple], tuple] = numba.njit(inline="always")(namespace["unstack"])
        # hints env e's first cache line of every array of the form in (the envs' axis: a stack's second, a field's
        # first): the fused step asks for the next env's while it works on one
        self.prefetch: Callable[[tuple, int], None] = numba.njit(inline="always")(namespace["prefetch"])

    def form(self, value: tuple) -> tuple:
        """``value`` (a ``cls``) as its kernel takes it; ``ValueError`` if a group's fields are not the rows of one
        stack."""
        form: list[Any] = []
        for kind, key in self._places:
            if kind == "group":
                form.append(self._stack(value, self.groups[key]))
            elif kind == "nested":
                form.append(self.nested[key].form(getattr(value, key)))
            else:
                form.append(getattr(value, key))
        return tuple(form)

    def _stack(self, value: tuple, group: tuple[str, ...]) -> np.ndarray:
        """The stack whose rows are ``group``'s fields of ``value``, a view of their memory."""
        rows = [getattr(value, name) for name in group]
        first = rows[0]
        stack = np.lib.stride_tricks.as_strided(first, (len(rows), *first.shape), (first.nbytes, *first.strides))
        if not (stack.flags.c_contiguous and all(
                row.dtype == first.dtype and row.shape == first.shape and row.flags.writeable
                and row.__array_interface__["data"][0] == first.__array_interface__["data"][0] + i * first.nbytes
                for i, row in enumerate(rows))):
            raise ValueError(f"{self.cls.__name__} fields {group}: must be the rows, in this order, of one "
                             "C-contiguous stack (allocate them as np.zeros((len(group), *shape)))")
        return stack


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


STACKED: dict[type, Stacked] = {}  # each Stacked structure's layout, by its class
_PACKAGE = __name__.split(".")[0]


def restack(root: Any) -> None:
    """Make the groups of every :class:`Stacked` structure reachable from ``root`` (through tuples, lists, dicts and
    the attributes of the package's objects) the rows of one stack again, copies of their values, and every reference
    to a row in that graph the new row: what a copy or a pickle undoes, as it copies each row of a stack apart. For
    ``__setstate__``."""
    rows: dict[int, np.ndarray] = {}  # id of an old row -> its new row
    for value in _reachable(root):
        stacked = STACKED.get(type(value))
        if stacked is None:
            continue
        for group in stacked.groups:
            old = [getattr(value, name) for name in group]
            if not all(isinstance(row, np.ndarray) for row in old) or len({(row.shape, row.dtype) for row in old}) != 1:
                continue  # not arrays of one shape (e.g. a structure of scalars): nothing to stack
            try:
                stacked._stack(value, group)
            except ValueError:
                rows.update({id(row): new for row, new in zip(old, np.stack(old))})
    if rows:
        _replace_rows(root, rows, {})


def _reachable(root: Any) -> Iterable[Any]:
    """Every object reachable from ``root`` through attributes, tuples, lists and dicts, once each."""
    seen: set[int] = set()
    stack = [root]
    while stack:
        item = stack.pop()
        if id(item) in seen or isinstance(item, (np.ndarray, str, bytes, int, float, type)):
            continue
        seen.add(id(item))
        yield item
        if isinstance(item, (list, tuple)):
            stack.extend(item)
        elif isinstance(item, dict):
            stack.extend(item.values())
        elif _ours(item):
            stack.extend(vars(item).values())


def _ours(item: Any) -> bool:
    """``item`` is an object of one of the package's classes or of a subclass of one, with attributes."""
    return hasattr(item, "__dict__") and any(
        cls.__module__.split(".")[0] == _PACKAGE for cls in type(item).__mro__[:-1])


def _replace_rows(item: Any, rows: dict[int, np.ndarray], done: dict[int, Any]) -> Any:
    """``item`` with every array of ``rows`` replaced by its new row: tuples made anew, lists, dicts and attributes
    changed in place."""
    if isinstance(item, np.ndarray):
        return rows.get(id(item), item)
    if id(item) in done or isinstance(item, (str, bytes, int, float, type)):
        return done.get(id(item), item)
    done[id(item)] = item
    if isinstance(item, tuple):
        parts = [_replace_rows(part, rows, done) for part in item]
        if any(new is not old for new, old in zip(parts, item)):
            rebuilt = type(item)._make(parts) if hasattr(item, "_fields") else tuple(parts)  # type: ignore[attr-defined]
            done[id(item)] = rebuilt
    elif isinstance(item, list):
        item[:] = [_replace_rows(part, rows, done) for part in item]
    elif isinstance(item, dict):
        for key, value in item.items():
            item[key] = _replace_rows(value, rows, done)
    elif _ours(item):
        for key, value in vars(item).items():
            new = _replace_rows(value, rows, done)
            if new is not value:
                object.__setattr__(item, key, new)
    return done[id(item)]


def follow_sources(modules: tuple[str, ...], reached: tuple[str, ...] = ()) -> None:
    """Make the numba cache of every kernel defined in ``modules`` (imported, by name) fresh exactly while the
    contents of ``modules``' and ``reached``'s files are unchanged; ``reached``: modules whose kernels or constants
    those kernels compile in but which this call does not stamp (each kernel is stamped by one call only).

    numba stamps a cache with its kernel's own file only (0.68: a hash of its contents; before: its modification
    time and size) and reloads it while that is unchanged. Two things break that. A kernel carries the compiled
    code of the kernels it calls, inlined or not, also those of other files (the fused step every stage's, a stage
    the kernels it calls in turn), so an edit there alone would leave it running the old code. And, before numba
    0.68, installing a file gave it a new modification time, so the cache a wheel ships
    (:mod:`timegap_env.precompile`) would always look stale. Each cache's source stamp becomes a hash of all these
    contents instead. numba 0.68 keeps the stamp in the dispatcher's ``_cache._cache_file._source_stamp``;
    should that move, numba's own stamp decides.

    An index numba cannot read back counts as stale too: numba unpickles a cache's index before it compares the
    stamps, and an index written by an older version of these modules may name a class that is gone (a NamedTuple
    of a cached signature, renamed), which would raise at the kernel's first call instead of compiling it again.
    """
    digest = hashlib.sha256()
    for module in modules + reached:
        source = sys.modules[module].__file__
        assert source is not None  # the package's modules are files
        digest.update(Path(source).read_bytes())
    stamp, call = f"sha256 of {', '.join(modules + reached)}: {digest.hexdigest()}", (modules, reached)
    for kernel in _kernels(modules):
        cache_file = getattr(getattr(kernel, "_cache", None), "_cache_file", None)
        if cache_file is None:
            continue
        if getattr(cache_file, "_followed", call) != call:  # the same call again (a module reloaded) may restamp
            raise ValueError(f"follow_sources: kernel {kernel.py_func.__qualname__} of {kernel.py_func.__module__} "
                             "is stamped by two calls; list its module in one call's modules, in others' reached")
        cache_file._followed = call
        if hasattr(cache_file, "_source_stamp"):
            cache_file._source_stamp = stamp
        if hasattr(cache_file, "_load_index") and not hasattr(cache_file, "_load_numba_index"):
            cache_file._load_numba_index = cache_file._load_index
            cache_file._load_index = _readable_or_stale(cache_file._load_numba_index)


def _readable_or_stale(load_index: Callable[[], dict]) -> Callable[[], dict]:
    """numba's index loader, an index it cannot unpickle read as an empty one (stale: compiled and written anew)."""

    def load() -> dict:
        try:
            return load_index()
        except (AttributeError, ImportError, EOFError, pickle.UnpicklingError):
            return {}

    return load


def _kernels(modules: tuple[str, ...]) -> Iterable[Dispatcher]:
    """Every numba kernel defined in ``modules``, once each."""
    seen: set[int] = set()
    for module in modules:
        for value in vars(sys.modules[module]).values():
            if isinstance(value, Dispatcher) and value.py_func.__module__ == module and id(value) not in seen:
                seen.add(id(value))
                yield value


__all__ = ["INLINED_STAGE_KERNEL", "NO_ALLOCATION", "STACKED", "STAGE_KERNEL", "Stacked", "collection_paused",
           "compiled_entry", "follow_sources", "prefetch_env", "prefetch_item", "prefetch_rows", "restack"]
