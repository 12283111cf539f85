"""Sweep a grid of config overrides x policies x seeds: one tidy table of episodes and a summary; resumable.

    python -m train.sweep GRID.yml [--out DIR] [--backend serial|ray] [--address A] [--chunk 16]

The grid is a YAML file (``train/sweeps/example.yml`` is one):

- ``axes``: dotted ``EnvConfig`` fields, each with a list of values (``reward_weights.efficiency: [0.5, 1.0]``,
  ``degradation.gain_range: [[0.6, 0.85], [0.4, 0.6]]``, ``monitor.window: [1.0, 2.0]``); the cells are the
  product of the axes, the first axis outermost. Or ``cells``: an explicit list of such ``{field: value}`` maps.
- ``task`` (optional): the registered task whose config the cells override (default ``timegap_env.DEFAULT_TASK``);
- ``base`` (optional): overrides every cell shares, as ``gym.make``'s ``config`` (nested configs as dicts); a
  cell's dotted fields go into them.
- ``policies``: by name, from the policy registry (``timegap_env.experiments.registry``: the paper's rule, the
  chart-step rule, the V2V-aware heuristic),
  ``fixed_<setting>`` for any ladder level, and ``ppo``, the trained model at ``model`` (default: the task's committed PPO, ``DEFAULT_MODELS``).
- ``seeds``: ``{start, count, batch}``: episodes reset with seeds start .. start + count - 1, run ``batch`` at a
  time. Held out from training (start >= ``EVAL_SEED_START``) unless the grid states ``held_out: false`` (then
  every seed lies below it).
- ``description`` (optional): a sentence for the summary.

Every field and value is checked before anything runs (the task's config with each cell's overrides, every policy built
for each cell's config): an unknown field or policy, or a bad value, is a ``ValueError`` naming it.

A piece of work is (cell, policy, seed batch): one native vector env, ``batch`` episodes, the policy built for
the cell's config in its own action mode (as ``train.evaluate`` runs it). Pieces go through
:class:`timegap_env.experiments.backends.Backend` (serial, or Ray tasks) ``--chunk`` at a time; an episode depends on its seed,
cell and policy alone, so both backends write the same bits. The trained model travels with the pieces as
bytes, so cluster workers need no copy of ``results/``.

Writes to ``--out`` (default ``runs/sweep/<grid name>``):

- ``episodes.csv``: one row per episode: ``piece`` and ``cell`` (stable hashes: the task and the cell's overrides; those, the
  policy, the model's bytes for ``ppo`` and the seed batch), one column per axis (its value; lists and maps as
  JSON), ``policy``, ``seed``, ``scenario`` (the leader family), ``degradation`` (the kind drawn, ``none`` if no
  follower is hit), ``return`` (undiscounted), ``collision`` (0/1) and the episode summary
  (:func:`timegap_env.envs.info.summary_of`). Rewritten whole, atomically, after each chunk, in the plan's order
  (cells, then policies, then seed batches), so an interrupted sweep keeps every finished chunk and never a
  half-written row. A rerun skips every piece whose rows are all there and runs the rest; a finished sweep
  reruns nothing. Rows of pieces the grid no longer plans are kept at the end, left out of the summary.
- ``summary.md``: per cell and policy the mean return with a 95 % bootstrap interval (fixed seed), collisions and
  the mean setting; per cell the best policy and its paired difference to the next best; the grid; how the work
  was spread and the runtime on its last line, the only line a rerun changes.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import hashlib
import itertools
import json
import math
import os
import tempfile
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from timegap_env.agents.policies import NamedPolicy, seconds
from timegap_env.agents.protocol import ENV_FILE, EVAL_SEED_START, MODEL_FILE, VECNORMALIZE_FILE
from timegap_env import DEFAULT_TASK, cli
from timegap_env.config import NESTED_CONFIGS, EnvConfig
from timegap_env.envs.observation import observation_space
from timegap_env.leaders import SCENARIOS
from timegap_env.experiments.backends import Backend, add_arguments
from timegap_env.experiments.registry import FIXED_PREFIX, POLICIES, PPO
from timegap_env.experiments.registry import make as make_policy
from timegap_env.experiments.rollout import rollout
from timegap_env.experiments.stats import BOOTSTRAP_RESAMPLES, BOOTSTRAP_SEED, bootstrap_mean
from timegap_env.tasks import get_task

DEFAULT_OUT = Path("runs/sweep")  # a grid's results go to DEFAULT_OUT / its file's stem
DEFAULT_MODELS = {"TimeGapMonitor-v0": Path("results/v0/ppo"), "TimeGapMonitor-v1": Path("results/ppo_v1")}  # task ->
# its committed PPO run (make train)
DEFAULT_BATCH = 16  # episodes per piece, one vector env [-]
DEFAULT_CHUNK = 16  # pieces per Backend.map call, after each of which episodes.csv is written [-]
EPISODES_FILE, SUMMARY_FILE = "episodes.csv", "summary.md"
GRID_KEYS = ("description", "task", "axes", "cells", "base", "policies", "seeds", "model")
SEED_KEYS = ("start", "count", "batch", "held_out")
HASH_CHARS = 12  # hex digits of a piece's or cell's hash [-]
LEADING_COLUMNS = ("piece", "cell")  # then one column per axis, then EPISODE_COLUMNS, then the episode summary
EPISODE_COLUMNS = ("policy", "seed", "scenario", "degradation", "return", "collision")


# ---------------------------------------------------------------- the grid
@dataclasses.dataclass(frozen=True)
class Grid:
    """A parsed, checked grid: cells (flat ``{dotted field: value}``), the overrides they share, policies, seeds."""

    path: Path
    description: str
    task: str  # the registered task whose config the cells override
    columns: tuple[str, ...]  # the dotted fields the cells set, one CSV column each
    cells: tuple[dict[str, Any], ...]
    base: dict[str, Any]
    policies: tuple[str, ...]
    seeds: tuple[int, ...]
    batch: int  # episodes per piece [-]
    held_out: bool
    model: Path | None  # the trained model's run directory when ``ppo`` is among the policies

    def overrides(self, cell: Mapping[str, Any]) -> dict[str, Any]:
        """``gym.make``'s ``config`` for ``cell``: the base with the cell's dotted fields put into it."""
        return with_fields(self.base, cell)

    def config(self, cell: Mapping[str, Any]) -> EnvConfig:
        """The env's config in ``cell``: the task's with the cell's overrides."""
        return get_task(self.task).config(self.overrides(cell))

    def batches(self) -> list[tuple[int, ...]]:
        """The seeds, ``batch`` at a time."""
        return [self.seeds[i:i + self.batch] for i in range(0, len(self.seeds), self.batch)]


def with_fields(base: Mapping[str, Any], fields: Mapping[str, Any]) -> dict[str, Any]:
    """``base`` (nested overrides) with the dotted ``fields`` set: ``{"a.b": v}`` sets ``base["a"]["b"]``."""
    merged = {key: dict(value) if isinstance(value, Mapping) else value for key, value in base.items()}
    for name, value in fields.items():
        top, _, sub = name.partition(".")
        if sub:
            merged[top] = {**merged.get(top, {}), sub: value}
        else:
            merged[top] = value
    return merged


def check_field(name: Any, where: str) -> str:
    """``name`` if it is a dotted ``EnvConfig`` field a cell may set (``field`` or ``nested.field``), else a
    ``ValueError`` naming it and ``where`` it was found."""
    if not isinstance(name, str):
        raise ValueError(f"{where}: field {name!r} must be a string such as 'reward_weights.efficiency'")
    known = [field.name for field in dataclasses.fields(EnvConfig)]
    top, dot, sub = name.partition(".")
    if top not in known:
        raise ValueError(f"{where}: unknown field {name!r}: EnvConfig has no field {top!r}; known: {known}")
    if top == "action_mode":
        raise ValueError(f"{where}: field {name!r} cannot be swept: each policy runs in its own action mode")
    if dot:
        if top not in NESTED_CONFIGS:
            raise ValueError(f"{where}: unknown field {name!r}: EnvConfig.{top} is not a nested config; "
                             f"nested: {sorted(NESTED_CONFIGS)}")
        nested = [field.name for field in dataclasses.fields(NESTED_CONFIGS[top])]
        if sub not in nested:
            raise ValueError(f"{where}: unknown field {name!r}: {NESTED_CONFIGS[top].__name__} has no field "
                             f"{sub!r}; known: {nested}")
    return name


def parse_cells(raw: Mapping[str, Any], where: str) -> tuple[tuple[str, ...], list[dict[str, Any]]]:
    """The columns and cells of a grid's ``axes`` (their product) or ``cells`` (a list), checked by name."""
    if ("axes" in raw) == ("cells" in raw):
        raise ValueError(f"{where}: give either axes (a map field -> list of values, the cells their product) or "
                         "cells (a list of {field: value} maps), not both or neither")
    if "axes" in raw:
        axes = raw["axes"]
        if not isinstance(axes, Mapping) or not axes:
            raise ValueError(f"{where}: axes = {axes!r}: must be a non-empty map field -> list of values")
        for name, values in axes.items():
            check_field(name, f"{where}: axes")
            if not isinstance(values, list) or not values:
                raise ValueError(f"{where}: axes: {name} = {values!r}: must be a non-empty list of values")
        columns = tuple(axes)
        cells = [dict(zip(columns, values)) for values in itertools.product(*axes.values())]
    else:
        listed = raw["cells"]
        if not isinstance(listed, list) or not listed or not all(isinstance(cell, Mapping) for cell in listed):
            raise ValueError(f"{where}: cells = {listed!r}: must be a non-empty list of {{field: value}} maps")
        cells = [dict(cell) for cell in listed]
        for i, cell in enumerate(cells):
            for name in cell:
                check_field(name, f"{where}: cells[{i}]")
        columns = tuple(dict.fromkeys(name for cell in cells for name in cell))
    for name in columns:
        covering = [other for other in columns if other != name and other.startswith(name + ".")]
        if covering:
            raise ValueError(f"{where}: field {name!r} and {covering} overlap: sweep the whole config or its fields")
    return columns, cells


def parse_seeds(raw: Any, where: str) -> tuple[tuple[int, ...], int, bool]:
    """The seeds, the batch size and whether they are held out, from a grid's ``seeds`` map."""
    if not isinstance(raw, Mapping) or not {"start", "count"} <= set(raw):
        raise ValueError(f"{where}: seeds = {raw!r}: must be a map with start and count (and optionally batch, "
                         "held_out)")
    unknown = sorted(set(raw) - set(SEED_KEYS))
    if unknown:
        raise ValueError(f"{where}: seeds: unknown key(s) {unknown}; known: {list(SEED_KEYS)}")
    start, count, batch = raw["start"], raw["count"], raw.get("batch", DEFAULT_BATCH)
    held_out = raw.get("held_out", True)
    for name, value, low in (("start", start, 0), ("count", count, 1), ("batch", batch, 1)):
        if isinstance(value, bool) or not isinstance(value, int) or value < low:
            raise ValueError(f"{where}: seeds.{name} = {value!r}: must be an integer >= {low}")
    if not isinstance(held_out, bool):
        raise ValueError(f"{where}: seeds.held_out = {held_out!r}: must be true or false")
    if held_out and start < EVAL_SEED_START:
        raise ValueError(f"{where}: seeds.start = {start}: held-out seeds start at {EVAL_SEED_START} (training uses "
                         "those below); state held_out: false to run training seeds")
    if not held_out and start + count > EVAL_SEED_START:
        raise ValueError(f"{where}: seeds.start + seeds.count = {start + count} with held_out: false: training seeds "
                         f"lie below {EVAL_SEED_START}")
    return tuple(range(start, start + count)), batch, held_out


def load_grid(path: Path) -> Grid:
    """The grid in the YAML file ``path``, every cell and policy checked; ``ValueError`` naming what is wrong."""
    where = str(path)
    try:
        raw = yaml.safe_load(path.read_text())
    except yaml.YAMLError as error:
        raise ValueError(f"{where}: not valid YAML ({error})") from error
    if not isinstance(raw, Mapping):
        raise ValueError(f"{where}: must be a YAML map with axes or cells, policies and seeds")
    unknown = sorted(set(raw) - set(GRID_KEYS), key=str)
    if unknown:
        raise ValueError(f"{where}: unknown key(s) {unknown}; known: {list(GRID_KEYS)}")
    task = raw.get("task", DEFAULT_TASK)
    try:
        get_task(task)
    except ValueError as error:
        raise ValueError(f"{where}: task: {error}") from error
    columns, cells = parse_cells(raw, where)
    base = raw.get("base") or {}
    if not isinstance(base, Mapping):
        raise ValueError(f"{where}: base = {base!r}: must be a map of EnvConfig overrides")
    for name in base:
        check_field(name, f"{where}: base")
        if "." in name:
            raise ValueError(f"{where}: base: {name!r}: write base as nested maps ({{{name.split('.')[0]}: ...}})")
    policies = raw.get("policies")
    if not isinstance(policies, list) or not policies or not all(isinstance(p, str) for p in policies):
        raise ValueError(f"{where}: policies = {policies!r}: must be a non-empty list of policy names")
    if len(set(policies)) != len(policies):
        raise ValueError(f"{where}: policies = {policies}: each at most once")
    unknown = [p for p in policies if p not in POLICIES and p != PPO and not p.startswith(FIXED_PREFIX)]
    if unknown:
        raise ValueError(f"{where}: unknown policies {unknown}; known: {sorted(POLICIES)}, {FIXED_PREFIX}<setting> "
                         f"(a ladder level, e.g. {FIXED_PREFIX}1.6) and {PPO}")
    seeds, batch, held_out = parse_seeds(raw.get("seeds"), where)
    if PPO in policies and "model" not in raw and task not in DEFAULT_MODELS:
        raise ValueError(f"{where}: policy {PPO} in task {task!r}: no committed model; give model: RUN_DIR")
    model = Path(raw.get("model", DEFAULT_MODELS.get(task, ""))) if PPO in policies else None
    grid = Grid(path, str(raw.get("description", "")).strip(), task, columns, tuple(cells), dict(base), tuple(policies),
                seeds, batch, held_out, model)
    learned = load_learned(model_files(model)) if model is not None else None
    for i, cell in enumerate(cells):
        label = f"{where}: cell {i} {json.dumps(cell)}"
        try:
            config = grid.config(cell)
        except ValueError as error:
            raise ValueError(f"{label}: {error}") from error
        unknown_families = sorted(set(config.scenario_weights) - set(SCENARIOS))
        if unknown_families:
            raise ValueError(f"{label}: scenario_weights has unknown families {unknown_families}; "
                             f"known: {sorted(SCENARIOS)}")
        for name in policies:
            if name == PPO:
                expected = observation_space(config).shape
                if learned.observation_shape != expected:
                    raise ValueError(f"{label}: policy {PPO}: the model at {model} takes observations of shape "
                                     f"{learned.observation_shape}, this cell's env gives {expected}")
                continue
            try:
                make_policy(name, config)
            except ValueError as error:
                raise ValueError(f"{label}: policy {name!r}: {error}") from error
    return grid


# ---------------------------------------------------------------- policies and pieces
def model_files(run: Path) -> dict[str, bytes]:
    """The files of a trained run that :meth:`timegap_env.agents.learned.LearnedPolicy.load` reads, as bytes (they travel
    with the pieces); ``FileNotFoundError`` if the model is missing."""
    if not (run / MODEL_FILE).is_file():
        raise FileNotFoundError(f"model = {str(run)!r}: no {MODEL_FILE} there (policy {PPO} needs a trained run)")
    return {name: (run / name).read_bytes() for name in (MODEL_FILE, VECNORMALIZE_FILE, ENV_FILE)
            if (run / name).is_file()}


def digest(files: Mapping[str, bytes]) -> str:
    """A hash of a run's files."""
    hasher = hashlib.sha256()
    for name in sorted(files):
        hasher.update(name.encode() + b"\0" + files[name])
    return hasher.hexdigest()


_LOADED: dict[str, NamedPolicy] = {}  # model digest -> the loaded policy, once per process


def load_learned(files: Mapping[str, bytes]) -> NamedPolicy:
    """The learned policy of a run's ``files`` (see :func:`model_files`), loaded once per process."""
    key = digest(files)
    if key not in _LOADED:
        from timegap_env.agents.learned import LearnedPolicy  # torch is slow to import; only when needed

        with tempfile.TemporaryDirectory() as folder:
            for name, data in files.items():
                Path(folder, name).write_bytes(data)
            _LOADED[key] = LearnedPolicy.load(folder)
    return _LOADED[key]


def stable_hash(value: Any) -> str:
    """A hash of a JSON-able value, the same in every process and on every machine."""
    text = json.dumps(value, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:HASH_CHARS]


def run_piece(config: EnvConfig, policy_name: str, seeds: tuple[int, ...],
              model: dict[str, bytes] | None) -> list[dict[str, Any]]:
    """One episode per seed of ``policy_name`` in the native vector env of ``config`` (the policy's action mode
    set); ``model``: the run's files for ``ppo``. Per episode: seed, scenario, degradation kind, return, collision
    and the episode summary."""
    if policy_name != PPO:
        return play(make_policy(policy_name, config), config, seeds)
    import torch  # one thread, as a Ray task of one CPU has: on a busy machine two threads made PPO 100 x slower

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        return play(load_learned(model), config, seeds)
    finally:
        torch.set_num_threads(threads)


def play(policy: NamedPolicy, config: EnvConfig, seeds: tuple[int, ...]) -> list[dict[str, Any]]:
    """The episodes of :func:`run_piece` under ``policy``."""
    rows = []
    for episode in rollout(policy, config, seeds).records:
        summary = dict(episode.summary)
        collision = int(summary.pop("collision"))
        rows.append({"seed": episode.seed, "scenario": episode.scenario, "degradation": episode.degradation,
                     "return": episode.episode_return, "collision": collision, **summary})
    return rows


@dataclasses.dataclass(frozen=True)
class Piece:
    """One piece of work: a cell, a policy, a batch of seeds, and the stable key its rows carry."""

    cell: int  # index into Grid.cells
    policy: str
    seeds: tuple[int, ...]
    key: str


def plan(grid: Grid) -> tuple[list[Piece], list[str], dict[str, bytes] | None]:
    """Every piece, cells outermost then policies then seed batches; each cell's id; the model's files if needed."""
    files = model_files(grid.model) if grid.model is not None else None
    model_hash = digest(files) if files is not None else None
    cell_ids = [stable_hash([grid.task, grid.overrides(cell)]) for cell in grid.cells]
    pieces = []
    for index, cell in enumerate(grid.cells):
        for policy in grid.policies:
            identity = policy if policy != PPO else f"{PPO}:{model_hash}"
            for seeds in grid.batches():
                key = stable_hash([grid.task, grid.overrides(cell), identity, list(seeds)])
                pieces.append(Piece(index, policy, seeds, key))
    return pieces, cell_ids, files


# ---------------------------------------------------------------- the table
def axis_text(value: Any) -> str:
    """An axis value in its CSV column: strings as they are, anything else as JSON."""
    return value if isinstance(value, str) else json.dumps(value)


def table_rows(grid: Grid, piece: Piece, cell_id: str, episodes: Sequence[dict[str, Any]]) -> list[dict[str, str]]:
    """The CSV rows of a piece's episodes (:func:`run_piece`'s): its key, its cell's id and axis values (empty for a
    field the cell leaves at its default), the policy, then each episode's values (a float's str is its shortest
    exact repr, so a row read back holds the same bits)."""
    cell = grid.cells[piece.cell]
    axes = {column: axis_text(cell[column]) if column in cell else "" for column in grid.columns}
    return [{"piece": piece.key, "cell": cell_id, **axes, "policy": piece.policy,
             **{name: str(value) for name, value in episode.items()}} for episode in episodes]


def read_table(path: Path, grid: Grid) -> tuple[list[str] | None, list[dict[str, str]]]:
    """The header and rows of an existing ``episodes.csv`` (None, [] if there is none); ``ValueError`` if its
    leading columns are not this grid's."""
    if not path.is_file():
        return None, []
    with path.open(newline="") as file:
        reader = csv.DictReader(file)
        header = list(reader.fieldnames or [])
        rows = list(reader)
    leading = [*LEADING_COLUMNS, *grid.columns, *EPISODE_COLUMNS]
    if header[:len(leading)] != leading:
        raise ValueError(f"{path}: its columns {header[:len(leading)]} are not this grid's {leading}: "
                         "a sweep over other axes; give another --out")
    return header, rows


def write_table(path: Path, header: list[str], rows: list[dict[str, str]]) -> None:
    """``rows`` under ``header`` into ``path``, atomically (a temporary file renamed over it)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    temporary = path.with_name(path.name + ".tmp")
    with temporary.open("w", newline="") as file:
        writer = csv.DictWriter(file, fieldnames=header, lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
    os.replace(temporary, path)


def finished(pieces: Sequence[Piece], rows: Sequence[dict[str, str]]) -> dict[str, list[dict[str, str]]]:
    """The rows of each piece whose every seed has exactly one row (a piece with a seed missing or repeated
    reruns)."""
    by_key: dict[str, list[dict[str, str]]] = {}
    for row in rows:
        by_key.setdefault(row["piece"], []).append(row)
    done = {}
    for piece in pieces:
        have = by_key.get(piece.key, [])
        if sorted(int(row["seed"]) for row in have) == sorted(piece.seeds):
            done[piece.key] = sorted(have, key=lambda row: piece.seeds.index(int(row["seed"])))
    return done


def sweep(grid: Grid, out: Path, backend: Backend, chunk: int = DEFAULT_CHUNK) -> str:
    """Run every piece of ``grid`` not yet in ``out/episodes.csv``, ``chunk`` pieces per ``backend.map``, writing
    the table after each; then write ``summary.md``. Returns the summary's text."""
    if isinstance(chunk, bool) or not isinstance(chunk, int) or chunk < 1:
        raise ValueError(f"chunk = {chunk!r}: must be an integer >= 1")
    started = time.perf_counter()
    pieces, cell_ids, files = plan(grid)
    path = out / EPISODES_FILE
    header, existing = read_table(path, grid)
    done = finished(pieces, existing)
    planned = {piece.key for piece in pieces}
    others = [row for row in existing if row["piece"] not in planned]  # kept, not summarised
    todo = [piece for piece in pieces if piece.key not in done]
    calls = 0
    for start in range(0, len(todo), chunk):
        part = todo[start:start + chunk]
        results = backend.map(run_piece, [(grid.config(grid.cells[p.cell]), p.policy, p.seeds,
                                           files if p.policy == PPO else None) for p in part])
        calls += 1
        for piece, episodes in zip(part, results):
            done[piece.key] = table_rows(grid, piece, cell_ids[piece.cell], episodes)
        written = list(done[part[0].key][0])
        if header is not None and written != header:
            raise ValueError(f"{path}: its columns {header} are not the ones this sweep writes {written}; "
                             "give another --out")
        header = written
        write_table(path, header, [row for p in pieces if p.key in done for row in done[p.key]] + others)
    runtime = time.perf_counter() - started
    if todo:
        spread = (f"{len(todo)} of {len(pieces)} pieces run now in {calls} map call(s) of up to {chunk}; the last: "
                  f"{backend.describe()}")
    else:
        spread = f"all {len(pieces)} pieces were already in {EPISODES_FILE}, none run"
    text = summary(grid, pieces, cell_ids, done, len(others), f"Runtime: {runtime:.1f} s; {spread}.")
    (out / SUMMARY_FILE).write_text(text)
    return text


# ---------------------------------------------------------------- the summary
def summary(grid: Grid, pieces: Sequence[Piece], cell_ids: Sequence[str], done: Mapping[str, list[dict[str, str]]],
            n_others: int, runtime_line: str) -> str:
    """summary.md: the grid, a table per cell and policy, the best policy per cell, and ``runtime_line`` last."""
    returns: dict[tuple[int, str], np.ndarray] = {}
    rows: dict[tuple[int, str], list[dict[str, str]]] = {}
    for piece in pieces:
        rows.setdefault((piece.cell, piece.policy), []).extend(done[piece.key])
    for key, chosen in rows.items():
        returns[key] = np.array([float(row["return"]) for row in chosen])
    axes = list(grid.columns)
    first, last = grid.seeds[0], grid.seeds[-1]
    lines = [f"# Sweep `{grid.path.stem}` (`python -m train.sweep {grid.path}`)", ""]
    if grid.description:
        lines += [grid.description, ""]
    lines += [
        f"Task `{grid.task}`; {len(grid.cells)} cells ({' × '.join(f'`{a}`' for a in axes)}), each with the shared overrides "
        f"`{json.dumps(grid.base)}`; policies {', '.join(f'`{p}`' for p in grid.policies)}"
        + (f" (`{PPO}`: the model in `{grid.model}`)" if grid.model is not None else "")
        + f"; seeds {first}-{last} ({'held out' if grid.held_out else 'training seeds'}), {grid.batch} per piece: "
        f"{len(pieces)} pieces of (cell, policy, seed batch), {len(grid.cells) * len(grid.policies) * len(grid.seeds)} "
        f"episodes. "
        f"Returns are undiscounted sums of the reward; intervals are 95 % percentile bootstraps over the episodes "
        f"({BOOTSTRAP_RESAMPLES} resamples, seed {BOOTSTRAP_SEED}). Every episode is a row of `{EPISODES_FILE}`.", "",
        "## Mean return per cell and policy (the cell's best in bold)", "",
        "| cell | " + " | ".join(f"`{a}`" for a in axes) + " | policy | episodes | mean return [95 % CI] | collisions "
        "| mean τ* [s] |",
        "|---|" + "---|" * len(axes) + "---|---|---|---|---|",
    ]
    best: dict[int, list[str]] = {}  # per cell, the policies with the best mean return (several on a tie)
    for index, cell in enumerate(grid.cells):
        top = max(returns[index, p].mean() for p in grid.policies)
        best[index] = [p for p in grid.policies if returns[index, p].mean() == top]
        values = " | ".join(axis_text(cell[a]) if a in cell else "(default)" for a in axes)
        for policy in grid.policies:
            chosen = rows[index, policy]
            mean, low, high = bootstrap_mean(returns[index, policy])
            text = f"{mean:.1f} [{low:.1f}, {high:.1f}]"
            name = f"**{policy}**" if policy in best[index] else policy
            collisions = sum(int(row["collision"]) for row in chosen)
            setting = np.mean([float(row["mean_setting"]) for row in chosen])
            lines.append(f"| `{cell_ids[index]}` | {values} | {name} | {len(chosen)} | {text} | {collisions} | "
                         f"{seconds(setting) if math.isfinite(setting) else 'n/a'} |")
    lines += ["", "## Best policy per cell", "",
              ("Best by mean return (policies with the same mean joined by =); the difference to the next best is "
               "paired (the same seeds), with its 95 % bootstrap interval: an interval that holds 0 does not separate "
               "the two."), "",
              "| cell | " + " | ".join(f"`{a}`" for a in axes) + " | best policy | mean return | next best | "
              "best − next [95 % CI] |",
              "|---|" + "---|" * len(axes) + "---|---|---|---|"]
    for index, cell in enumerate(grid.cells):
        values = " | ".join(axis_text(cell[a]) if a in cell else "(default)" for a in axes)
        top = best[index][0]
        rest = [p for p in grid.policies if p not in best[index]]
        if rest:
            second = max(rest, key=lambda p: returns[index, p].mean())  # the first in grid order on a tie
            mean, low, high = bootstrap_mean(returns[index, top] - returns[index, second])
            versus = f"{second} | {mean:+.1f} [{low:+.1f}, {high:+.1f}]"
        else:
            versus = "none | n/a"
        lines.append(f"| `{cell_ids[index]}` | {values} | {' = '.join(best[index])} | "
                     f"{returns[index, top].mean():.1f} | {versus} |")
    if n_others:
        lines += ["", (f"{EPISODES_FILE} also keeps {n_others} rows of pieces this grid does not plan (an earlier "
                       "grid's), left out above.")]
    lines += ["", runtime_line, ""]
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m train.sweep", description=__doc__.split("\n")[0])
    parser.add_argument("grid", type=Path, help="the grid, a YAML file (see train/sweeps/example.yml)")
    parser.add_argument("--out", type=Path, default=None,
                        help=f"output directory (default {DEFAULT_OUT}/<the grid file's stem>)")
    parser.add_argument("--chunk", type=int, default=DEFAULT_CHUNK,
                        help="pieces per batch of work, after which episodes.csv is written (default %(default)s); "
                             "at least the cluster's CPUs keeps them all busy")
    add_arguments(parser)
    args = parser.parse_args(argv)
    cli.output_dir(args.out if args.out is not None else DEFAULT_OUT / args.grid.stem)
    backend = Backend.from_args(args)
    try:
        grid = load_grid(args.grid)
    except (ValueError, FileNotFoundError) as error:
        parser.error(str(error))
    print(sweep(grid, args.out if args.out is not None else DEFAULT_OUT / args.grid.stem, backend, args.chunk))


if __name__ == "__main__":
    cli.run(main, "python -m train.sweep")
