"""Per-env state, declared once and allocated once.

A component declares its per-env arrays as the fields of a NamedTuple, each annotated with its :class:`PerEnv`:
its dtype, its shape after the env axis (names of dimensions, sized by the owner) and its first value::

    class PlatoonState(NamedTuple):
        x: Annotated[np.ndarray, PerEnv(float, "vehicles")]  # front-bumper position [m]
        ticks: Annotated[np.ndarray, PerEnv(np.int64)]  # ticks since each env's reset [-]

A field annotated with another such NamedTuple nests it. :class:`Layout` reads a root structure's declarations
and groups its array fields, nested ones included, by dtype and dimension names into *blocks*; :class:`State`
allocates each block as one array, (rows, n_envs, *shape), a field one row, and makes the root structure of views
of them (:attr:`State.views`): the only arrays there are, which the components read and write in place. A copy or
a pickle of a state copies its blocks and makes the views again.

A kernel is handed :attr:`State.blocks`, a handful of arrays however many fields (numba unpacks each array handed
from Python at every call), and makes the same views inside with :attr:`Layout.view`, a kernel inlined into its
caller; :attr:`Layout.prefetch` asks the CPU for one env's rows of every block ahead of their use
(:func:`~timegap_env.compiled.prefetch_rows`). Both are generated from the declarations.
"""

from __future__ import annotations

import functools
import math
import typing
from collections.abc import Callable, Mapping
from typing import Annotated, Any

import numba
import numpy as np

from timegap_env.compiled import prefetch_rows

__all__ = ["Layout", "PerEnv", "State", "layout_of"]


class PerEnv:
    """A per-env array field's declaration: ``dtype``; its shape after the env axis, ``dims`` (names the owner sizes,
    e.g. "followers"; none: one value per env); ``fill``, its value when allocated."""

    def __init__(self, dtype: Any, *dims: str, fill: float = 0) -> None:
        self.dtype, self.dims, self.fill = np.dtype(dtype), tuple(dims), fill

    def __repr__(self) -> str:
        return f"PerEnv({self.dtype}, {', '.join(map(repr, self.dims))}, fill={self.fill!r})"


def _fields(structure: type) -> list[tuple[str, PerEnv | type]]:
    """Each field of NamedTuple ``structure`` with its declaration: a :class:`PerEnv`, or a nested structure."""
    hints = typing.get_type_hints(structure, include_extras=True)
    fields: list[tuple[str, PerEnv | type]] = []
    for name in structure._fields:  # type: ignore[attr-defined]
        hint = hints.get(name)
        declared = [item for item in getattr(hint, "__metadata__", ()) if isinstance(item, PerEnv)]
        if typing.get_origin(hint) is Annotated and len(declared) == 1:
            fields.append((name, declared[0]))
        elif isinstance(hint, type) and issubclass(hint, tuple) and hasattr(hint, "_fields"):
            fields.append((name, hint))
        else:
            raise TypeError(f"{structure.__name__}.{name}: annotated {hint!r}; a state field is "
                            "Annotated[np.ndarray, PerEnv(dtype, *dims)] or a nested NamedTuple of such fields")
    return fields


class Layout:
    """Where each array field of ``root`` (a NamedTuple of :class:`PerEnv` fields and nested such NamedTuples)
    lives: ``blocks``, each block's (dtype, dims) in order of first use; ``rows``, each field's (block, row) by
    its path of field names. The layout depends on the declarations only, never on the dimensions' sizes."""

    def __init__(self, root: type) -> None:
        self.root = root
        self.blocks: list[tuple[np.dtype, tuple[str, ...]]] = []
        self.fills: list[list[float]] = []  # each block's rows' first values
        self.rows: dict[tuple[str, ...], tuple[int, int]] = {}
        namespace: dict[str, Any] = {"__name__": __name__, "prefetch_rows": prefetch_rows}  # generated here
        expression = self._place(root, (), namespace)
        source = (f"def view(blocks, n):\n    return {expression}\n\n\ndef prefetch(blocks, e):\n"
                  + "".join(f"    prefetch_rows(blocks[{b}], e)\n" for b in range(len(self.blocks))))
        exec(compile(source, f"<{root.__name__}'s Layout>", "exec"), namespace)  # noqa: S102
        self._view: Callable[[tuple, int], Any] = namespace["view"]
        # the views of a kernel's blocks for n envs, made inside it; env e's first cache line of every row, asked
        # for ahead
        self.view: Callable[[tuple, int], Any] = numba.njit(inline="always")(namespace["view"])
        self.prefetch: Callable[[tuple, int], None] = numba.njit(inline="always")(namespace["prefetch"])

    def _place(self, structure: type, path: tuple[str, ...], namespace: dict[str, Any]) -> str:
        """The expression that makes ``structure`` of views of ``blocks``; gives each of its fields a row."""
        name = f"S{len(namespace)}_{structure.__name__}"
        namespace[name] = structure
        parts = []
        for field, declared in _fields(structure):
            if isinstance(declared, PerEnv):
                key = (declared.dtype, declared.dims)
                if key not in self.blocks:
                    self.blocks.append(key)
                    self.fills.append([])
                block = self.blocks.index(key)
                self.rows[(*path, field)] = (block, len(self.fills[block]))
                parts.append(f"blocks[{block}][{len(self.fills[block])}][:n]")
                self.fills[block].append(declared.fill)
            else:
                parts.append(self._place(declared, (*path, field), namespace))
        return f"{name}({', '.join(parts)})"

    def allocate(self, dims: Mapping[str, int], n_envs: int) -> tuple[np.ndarray, ...]:
        """Every block for ``n_envs`` envs with dimensions ``dims`` (name -> size), each row at its field's fill.

        A block's rows hold :func:`padded` envs, the first ``n_envs`` of them the envs': rows a multiple of 4 KiB
        apart would all fall in the same few sets of the CPU's cache, and an env's ~30 rows of a block would evict
        each other there (``make bench``'s vector env and simulator at 1,024 envs and more)."""
        blocks = []
        for (dtype, names), fills in zip(self.blocks, self.fills):
            missing = [name for name in names if name not in dims]
            if missing:
                raise ValueError(f"{self.root.__name__}'s state: dimensions {missing} are not sized (dims {dict(dims)})")
            shape = tuple(int(dims[name]) for name in names)
            block = np.empty((len(fills), padded(n_envs, dtype.itemsize * math.prod(shape)), *shape), dtype=dtype)
            for row, fill in zip(block, fills):
                row[...] = fill
            blocks.append(block)
        return tuple(blocks)

    def views(self, blocks: tuple[np.ndarray, ...], n_envs: int) -> Any:
        """The root structure of views of ``blocks`` (as :meth:`allocate` makes them) for ``n_envs`` envs."""
        return self._view(blocks, n_envs)


def padded(n_envs: int, env_bytes: int) -> int:
    """The envs a row of ``env_bytes`` bytes per env holds for ``n_envs`` envs: ``n_envs``, or when a row spans
    4 KiB or more, the fewest envs from ``n_envs`` whose row is an odd number of 64-byte cache lines long, so that
    the rows of a block start in distinct cache sets (``n_envs`` if no such count is within a sixteenth more)."""
    if n_envs * env_bytes < 4096:
        return n_envs
    for count in range(n_envs, n_envs + n_envs // 16 + 1):
        if count * env_bytes % 128 == 64:
            return count
    return n_envs


@functools.cache
def layout_of(root: type) -> Layout:
    """The one :class:`Layout` of ``root`` (a layout's kernels compile once per process)."""
    return Layout(root)


class State:
    """The per-env state of ``n_envs`` envs laid out by ``root`` with dimensions ``dims``: :attr:`blocks` and
    :attr:`views` of them (see the module docstring). Copies and pickles copy the blocks and make new views."""

    def __init__(self, root: type, dims: Mapping[str, int], n_envs: int) -> None:
        self.root, self.dims, self.n_envs = root, dict(dims), int(n_envs)
        self.blocks = layout_of(root).allocate(self.dims, self.n_envs)
        self.views = layout_of(root).views(self.blocks, self.n_envs)

    def at(self, path: tuple[str, ...]) -> Any:
        """The nested structure of :attr:`views` at ``path`` (field names; () the root)."""
        value = self.views
        for name in path:
            value = getattr(value, name)
        return value

    def rows(self, path: tuple[str, ...]) -> np.ndarray:
        """The fields of the structure at ``path``, all of one block, as that block's consecutive rows (a view)."""
        layout = layout_of(self.root)
        places = [place for key, place in layout.rows.items() if key[:len(path)] == path]
        blocks = {block for block, _ in places}
        first = min(row for _, row in places)
        if len(blocks) != 1 or sorted(row for _, row in places) != list(range(first, first + len(places))):
            raise ValueError(f"{self.root.__name__}.{'.'.join(path)}: its fields are not consecutive rows of one block")
        return self.blocks[blocks.pop()][first:first + len(places), :self.n_envs]

    @property
    def bytes_per_env(self) -> int:
        """Bytes of one env's rows of every block [B]."""
        return sum(block.nbytes // block.shape[1] for block in self.blocks)

    def __getstate__(self) -> dict[str, Any]:
        return {"root": self.root, "dims": self.dims, "n_envs": self.n_envs, "blocks": self.blocks}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self.views = layout_of(self.root).views(self.blocks, self.n_envs)


class OnState:
    """A component whose arrays are the views of a :class:`State` at ``path``, :attr:`parts`: its own state when it
    stands alone, its owner's inside one. Copies and pickles take the views from the copied state again."""

    parts: Any

    def _bind(self, state: State, path: tuple[str, ...] = ()) -> None:
        self._state, self._path = state, path
        self.parts = state.at(path)

    def __getstate__(self) -> dict[str, Any]:
        return {key: value for key, value in self.__dict__.items() if key != "parts"}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self.parts = self._state.at(self._path)
