"""The benchmark (issue 38): every policy on the same held-out episodes of the default task's groups, safety and
efficiency apart, the constants' frontier, learned recipes over their training seeds, and a leaderboard.

    python -m train.benchmark [--policy NAME|MODULE:NAME|RUN_DIR ...] [--groups default regimes ...]
                              [--episodes N] [--first-seed 10000] [--out runs/benchmark] [--force]
                              [--cache runs/benchmark-cache] [--backend serial|processes|ray]
    python -m train.benchmark --size        # the pilot that sized the groups (selection seeds only)

The task is ``timegap_env.DEFAULT_TASK``; its record (``timegap_env.tasks``) holds the groups (:data:`GROUPS`), each
the task's config with a few overrides, and the references.
Per group, with the seeds of each step fixed and disjoint:

- the **constants** (every ladder setting) play selection seeds 5000-5999: the best constant (the highest mean
  return) and the best *safe* constant (the highest among those colliding in at most SAFE_BUDGET of them) are
  chosen there;
- the **references** that know the truth (``timegap_env.studies.task_map.choose_references``: the V2V pair,
  regime-aware, degradation-aware and full oracles) build their tables on training seeds 0-15 and are chosen on
  selection seeds 5000-5127; ``hindsight`` is the best constant of each held-out episode;
- **every policy** (the constants, the paper's rule, the other rules, the references, every training seed of the
  learned recipes of :data:`RECIPES`, and each ``--policy``) plays the group's held-out episodes, seeds from
  ``--first-seed`` (10000), the same for all (their fingerprints are compared; a mismatch stops the run).

Per group and policy (``scores.csv``): safety (collisions, the rate's Wilson interval, the mean cost) and
efficiency (the reward without its collision term, per second driven times the episode's full length: an episode
cut short by a crash is scored at the rate it drove, not rewarded for its missing seconds) apart, the scalar
return beside them, each with a 95 % percentile bootstrap interval over episodes (RESAMPLES resamples, the same
for every policy of a group: paired); ``mde``, the smallest paired difference of return from the best constant
detectable at 80 % power; gains over the best, best safe constant and the paper's rule; and the place against the
constants' frontier: ``frontier_efficiency_gain`` (efficiency beyond the best any mix of constants reaches at the
same collision rate) and ``frontier_safety_gain`` (collision rate below the least any mix reaches at the same
efficiency), each with its interval; ``beyond_frontier`` when either interval is above 0.

Learned recipes are aggregated over their training seeds (``aggregates.csv``): per group, the score is the return's
difference from the best constant's, in % of the latter's |return|; over seeds x groups, the interquartile mean with
a stratified bootstrap interval, the probability of improvement over the paper's rule, and a performance profile
(Agarwal et al. 2021; ``timegap_env.experiments.stats``).

Every result is cached by what determines it (task, group, seeds, policy, the package's code) under ``--cache``:
adding a policy to a computed benchmark plays that policy alone. Writes ``leaderboard.md``, ``scores.csv``,
``aggregates.csv``, ``pairwise.csv``, ``frontier.png`` and ``profile.png`` to ``--out`` (through a partial
directory moved there at the end; an existing ``--out`` is replaced only with ``--force``).

From Python: ``run_benchmark(...)`` returns a :class:`Benchmark`; ``write(benchmark, out)`` writes it.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import hashlib
import importlib
import inspect
import json
import math
import os
import pickle
import shutil
import signal
import sys
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

import timegap_env
from timegap_env import cli
from timegap_env.config import REWARD_PRESETS, EnvConfig
from timegap_env.experiments import registry
from timegap_env.experiments.backends import Backend, add_arguments
from timegap_env.experiments.rollout import rollout
from timegap_env.experiments.stats import (
    WILSON_Z, episodes_for, iqm, paired_mde, performance_profile, probability_of_improvement,
    probability_of_improvement_interval,
    stratified_bootstrap, wilson_interval,
)
from timegap_env.studies.task_map import Plan, References, choose_references
from timegap_env.studies.value import flag_aware_actions
from timegap_env.tasks import SELECTION_SEED_START, HeldOutGroup, get_task
from timegap_env.leaders.scenarios import missing_data

TASK = timegap_env.DEFAULT_TASK
TASK_RECORD = get_task(TASK)  # its config, seeds, held-out groups and references
HELD_OUT_START = TASK_RECORD.seeds.held_out_start  # the held-out episodes' first seed, of every group [-]
REFERENCE_PLAN = Plan(train=16, selection=128)  # the references' training seeds 0-15, selection 5000-5127
SAFE_BUDGET = 0.01  # a constant is safe when it collides in at most this share of the selection episodes [-]
EFFECT = 0.05  # the groups are sized to detect this share of the best constant's |return| ... [-]
POWER = 0.8  # ... at this power, two-sided at 95 % [-]
RESAMPLES = 2_000  # bootstrap resamples of the episodes per group, shared by its policies (paired) [-]
CHUNK = 500  # episodes per rollout (one vector env), a piece of work for the backend [-]
ENTRIES_PER_MAP = 8  # policies whose pieces go to the backend at once [-]
PILOT = 400  # --size: selection episodes per group the sizes were measured on [-]
TUNING = Path("results/rule/tuning.csv")  # train.tune_rule's tuning of chart_step on the task
RULE = "rule_platoon"  # the paper's rule: every gain is also stated over it
DEFAULT_GROUP = "default"  # the task's own mix: the leaderboard's ranking


# The groups, in the leaderboard's order: the task record's. Sizes: `python -m train.benchmark --size`
# (docs/benchmark.md) gives the episodes each needs to see EFFECT at POWER; a group gets that, rounded up to 250, at
# least 1000 (the default mix at least 2500), except where ``capped`` says why not.
GROUPS: dict[str, HeldOutGroup] = {group.name: group for group in TASK_RECORD.groups}

# The learned recipes: each a run directory per training seed (train.train_ppo --seed k; make train).
RECIPES: dict[str, tuple[str, ...]] = {
    "ppo": ("results/ppo_v1", *(f"results/recipes/ppo_seed{seed}" for seed in range(1, 5))),
    "ppo_nomonitor": ("results/ppo_v1_nomonitor", *(f"results/recipes/ppo_nomonitor_seed{seed}" for seed in range(1, 5))),
    "ppo_rawgap": ("results/ppo_v1_rawgap", *(f"results/recipes/ppo_rawgap_seed{seed}" for seed in range(1, 5))),
    # issue 39: the default mix plus the training part of the real drivers, real-car followers 4x as often
    "ppo_real": tuple(f"results/recipes/ppo_real_seed{seed}" for seed in range(5)),
    # and its twins: the monitor's posterior replaced by the raw gap, the monitor's features hidden
    "ppo_real_rawgap": tuple(f"results/recipes/ppo_real_rawgap_seed{seed}" for seed in range(5)),
    "ppo_real_nomonitor": tuple(f"results/recipes/ppo_real_nomonitor_seed{seed}" for seed in range(5)),
    # ppo_real with the fast learner (hyperparams/ppo_fast.yml) for 8 M steps; ppo_real starting at 1.6 s as every
    # held-out episode does (training otherwise starts at a random setting)
    "ppo_real_fast": tuple(f"results/recipes/ppo_real_fast_seed{seed}" for seed in range(5)),
    "ppo_real_start": tuple(f"results/recipes/ppo_real_start_seed{seed}" for seed in range(5)),
    # ppo_real with a budget on collisions (0.5 per 100 training episodes, half the V2V-aware heuristic's rate on the
    # default mix's selection episodes; Lagrange rate 10), set before it trained: safety as a constraint (item 1)
    "ppo_real_safe": tuple(f"results/recipes/ppo_real_safe_seed{seed}" for seed in range(5)),
}
RULES = (RULE, "chart_step", "v2v_aware")  # the rules every benchmark plays
REFERENCES = TASK_RECORD.references  # played; "hindsight" is derived
KIND_NAMES = {"constant": "constant", "rule": "rule", "reference": "reference (knows the truth)",
              "learned": "learned (seeds pooled)", "policy": "policy"}  # an entry's kind, as the leaderboard names it


# --- what a policy played --------------------------------------------------------------------------------------------

@dataclasses.dataclass
class Played:
    """One policy on a group's held-out episodes, per episode."""

    returns: np.ndarray  # the scalar return [-]
    efficiency: np.ndarray  # the return without its collision term, per second driven x the episode's length [-]
    collided: np.ndarray  # bool
    cost: np.ndarray  # info["cost"] summed [-]
    duration: np.ndarray  # seconds driven [s]
    fingerprints: np.ndarray  # what each reset drew (a digest of PlatoonTask.fingerprint), str

    def take(self, index: np.ndarray) -> Played:
        """The episodes ``index`` picks (one per held-out episode: hindsight's choice)."""
        return Played(*(getattr(self, field.name)[index] for field in dataclasses.fields(self)))


def efficiency(episode_return: float, collision_term: float, duration: float, config: EnvConfig) -> float:
    """The efficiency of an episode: its return without the collision term, per second driven (at least one
    decision), times the episode's full length [s]: equal to that return for an episode driven to the end."""
    rest = episode_return - config.reward_weights.collision * collision_term
    return rest / max(duration, config.decision_interval) * config.episode_duration


def play(policy: Any, config: EnvConfig, seeds: Sequence[int]) -> Played:
    """``policy`` on ``seeds`` in the env of ``config`` (the rollout harness): what it played."""
    if "torch" in sys.modules:  # a learned policy: one thread (torch's default, one per core, fights the workers)
        sys.modules["torch"].set_num_threads(1)
    records = rollout(policy, config, seeds).records
    durations = [record.summary["duration"] for record in records]
    return Played(
        returns=np.array([record.episode_return for record in records]),
        efficiency=np.array([efficiency(record.episode_return, record.rewards["collision"], duration, config)
                             for record, duration in zip(records, durations)]),
        collided=np.array([bool(record.summary["collision"]) for record in records]),
        cost=np.array([record.cost for record in records]),
        duration=np.array(durations, dtype=float),
        fingerprints=np.array([hashlib.sha256(record.fingerprint.encode()).hexdigest()[:16] for record in records]))


def join(parts: Sequence[Played]) -> Played:
    """Chunks of episodes, in order, as one."""
    return Played(*(np.concatenate([getattr(part, field.name) for part in parts])
                    for field in dataclasses.fields(Played)))


# --- the cache ------------------------------------------------------------------------------------------------------

def code_digest() -> str:
    """A digest of the package's code and data files (its study code, timegap_env/studies, included) and of this
    script's functions whose results are cached (what an episode plays and how it is recorded, the constants'
    choice): an edit to any of them makes every key new. Scores are computed from the cached episodes at every run,
    so their code is not in it."""
    digest = hashlib.sha256()
    package = Path(timegap_env.__file__).parent
    for path in sorted([*package.rglob("*.py"), *package.rglob("*.json")]):
        digest.update(str(path.relative_to(package.parent)).encode())
        digest.update(path.read_bytes())
    for cached in CACHED_CODE:
        digest.update(inspect.getsource(cached).encode())
    digest.update(repr((CHUNK, REFERENCE_PLAN, SAFE_BUDGET)).encode())
    return digest.hexdigest()[:16]


class Cache:
    """Results by what determines them, one pickle a key, under ``root`` (None: no cache)."""

    def __init__(self, root: Path | None) -> None:
        self.root = root
        self.code = code_digest()

    def key(self, *parts: Any) -> str:
        """The key of ``parts`` (JSON-able) under this code."""
        return hashlib.sha256(json.dumps([self.code, *parts], sort_keys=True, default=str).encode()).hexdigest()[:24]

    def get(self, key: str) -> Any:
        """What was put under ``key``, or None (also for an entry this code cannot read: it is computed again)."""
        if self.root is None or not (self.root / f"{key}.pkl").is_file():
            return None
        with open(self.root / f"{key}.pkl", "rb") as file:
            try:
                return pickle.load(file)
            except (pickle.UnpicklingError, AttributeError, ImportError, EOFError):
                return None

    def put(self, key: str, value: Any) -> None:
        """Keep ``value`` under ``key`` (written whole, then renamed: a killed run leaves no half file)."""
        if self.root is None:
            return
        self.root.mkdir(parents=True, exist_ok=True)
        part = self.root / f"{key}.pkl.{os.getpid()}"
        with open(part, "wb") as file:
            pickle.dump(value, file)
        os.replace(part, self.root / f"{key}.pkl")

    def through(self, key: str, compute: Callable[[], Any]) -> Any:
        """The cached value of ``key``, computed and kept if there is none."""
        value = self.get(key)
        if value is None:
            value = compute()
            self.put(key, value)
        return value


# --- the policies -----------------------------------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class Entry:
    """A policy the benchmark plays: ``make(config, references)`` builds it for a group (references: that group's
    :class:`References`, None where it has none)."""

    name: str
    kind: str  # one of KIND_NAMES
    make: Callable[[EnvConfig, References | None], Any]
    key: str  # what determines its play, for the cache ("": never cached)
    recipe: str = ""  # a learned recipe's name: this entry is one of its training seeds
    seed: int | None = None  # the training seed


def files_digest(*paths: Path) -> str:
    """A digest of the files' bytes (a run directory: every file in it but its TensorBoard logs)."""
    digest = hashlib.sha256()
    for path in paths:
        files = sorted(p for p in path.rglob("*") if p.is_file() and "tensorboard" not in p.parts) \
            if path.is_dir() else [path]
        for file in files:
            digest.update(file.name.encode())
            digest.update(file.read_bytes())
    return digest.hexdigest()[:16]


def registered(name: str, **parameters: Any) -> Entry:
    """A policy of the registry (``fixed_<setting>`` included)."""
    kind = "constant" if name.startswith(registry.FIXED_PREFIX) else "rule" if name in RULES else "policy"
    return Entry(name, kind, lambda config, _: registry.make(name, config, **parameters),
                 f"registry:{name}:{json.dumps(parameters, sort_keys=True)}")


def learned(path: Path, name: str, recipe: str = "", seed: int | None = None) -> Entry:
    """A trained run (``train.train_ppo``'s directory) of the task."""
    from timegap_env.agents.protocol import ENV_FILE, read_env_file

    if not registry.learned_exists(path):
        raise FileNotFoundError(f"--policy {path}: no trained run there (an SB3 model.zip, or an RLlib run)")
    env_file = path / ENV_FILE
    if env_file.is_file() and read_env_file(env_file).env_id != TASK:
        raise ValueError(f"--policy {path}: trained in {read_env_file(env_file).env_id}, not {TASK} (its {ENV_FILE})")
    return Entry(name, "learned" if recipe else "policy", lambda config, _: registry.load_learned(path, config),
                 f"run:{files_digest(path)}", recipe, seed)


def module_policy(spec: str) -> Entry:
    """``MODULE:NAME``: a class (built with each group's config in its ``action_mode``, default the platoon's) or an
    object (SB3's ``predict``, an oracle's ``act`` or a chooser ``(obs, infos) -> actions``)."""
    module_name, _, attribute = spec.partition(":")
    try:
        module = importlib.import_module(module_name)
    except ImportError as error:
        raise ValueError(f"--policy {spec}: cannot import {module_name!r} ({error})") from error
    if not hasattr(module, attribute):
        raise ValueError(f"--policy {spec}: module {module_name!r} has no {attribute!r}")
    target = getattr(module, attribute)
    source = getattr(module, "__file__", None)
    key = f"module:{spec}:{files_digest(Path(source))}" if source else ""

    def make(config: EnvConfig, _: References | None) -> Any:
        if isinstance(target, type):
            policy = target(registry.in_mode(config, getattr(target, "action_mode", None) or "platoon"))
        else:
            policy = target
        if not (hasattr(policy, "predict") or hasattr(policy, "act") or callable(policy)):
            raise ValueError(f"--policy {spec}: {policy!r} has no predict(obs, ...), no act(truth) and is not callable")
        return policy
    return Entry(attribute, "policy", make, key)


def policy_entry(spec: str) -> Entry:
    """The entry of a ``--policy``: a registered name, ``MODULE:NAME`` or a trained run's directory."""
    if registry.is_known(spec) and spec not in (registry.ORACLE, registry.PPO):
        return registered(spec)
    if Path(spec).exists():
        return learned(Path(spec), Path(spec).name)
    if ":" in spec:
        return module_policy(spec)
    raise ValueError(f"--policy {spec}: unknown; give a registered name ({', '.join(registry.known())}), "
                     "MODULE:NAME or a trained run's directory")


def reference_entry(name: str, cache_key: str) -> Entry:
    """A reference of the group's :class:`References`."""
    def make(config: EnvConfig, references: References | None) -> Any:
        assert references is not None  # only played where the group has references
        if name == "v2v_pair":
            return functools.partial(flag_aware_actions, *references.pair)  # a chooser (obs, infos) -> actions
        return getattr(references, name)
    return Entry(name, "reference", make, f"reference:{name}:{cache_key}")


def default_entries(config: EnvConfig) -> list[Entry]:
    """The constants, the rules (chart_step with its tuning on the task where it is found) and every seed of
    every recipe whose runs are found."""
    tuned = registry.tuned_chart_step(TUNING) if TUNING.is_file() else {}
    entries = [registered(name) for name in registry.fixed_names(config)]
    entries += [registered(name, **(tuned if name == "chart_step" else {})) for name in RULES]
    for recipe, runs in RECIPES.items():
        entries += [learned(Path(run), f"{recipe}@{seed}", recipe, seed) for seed, run in enumerate(runs)
                    if Path(run).is_dir()]
    return entries


# --- statistics ---------------------------------------------------------------------------------------------------------

class Resampler:
    """The bootstrap resamples of a group's episodes, shared by its policies: every interval is paired."""

    def __init__(self, n: int) -> None:
        self.index = np.random.default_rng(0).integers(0, n, size=(RESAMPLES, n))

    def means(self, values: np.ndarray) -> np.ndarray:
        """The mean of ``values`` (n,) in each resample, (RESAMPLES,)."""
        return np.asarray(values, dtype=float)[self.index].mean(axis=1)

    def interval(self, values: np.ndarray) -> tuple[float, float, float]:
        """Mean and 95 % percentile interval."""
        low, high = np.quantile(self.means(values), [0.025, 0.975])
        return float(np.mean(values)), float(low), float(high)


def frontier_efficiency(rates: np.ndarray, efficiencies: np.ndarray, rate: np.ndarray) -> np.ndarray:
    """The highest efficiency a mix of constants (each episode one constant, drawn) reaches at a collision rate
    <= ``rate``: the constants' points ``rates``, ``efficiencies`` (..., k), ``rate`` (...,). Below every constant's
    rate, the efficiency of the safest constant (in the policy's disfavour)."""
    rate = rate[..., None]
    single = np.where(rates <= rate, efficiencies, -np.inf).max(axis=-1)
    ri, rj = rates[..., :, None], rates[..., None, :]
    ei, ej = efficiencies[..., :, None], efficiencies[..., None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        mixed = np.where((ri <= rate[..., None]) & (rate[..., None] < rj),
                         ei + (ej - ei) * (rate[..., None] - ri) / (rj - ri), -np.inf).max(axis=(-2, -1))
    safest = np.take_along_axis(efficiencies, np.argmin(rates, axis=-1)[..., None], axis=-1)[..., 0]
    best = np.maximum(single, mixed)
    return np.where(np.isfinite(best), best, safest)


def frontier_rate(rates: np.ndarray, efficiencies: np.ndarray, target: np.ndarray) -> np.ndarray:
    """The lowest collision rate at which a mix of constants reaches an efficiency >= ``target`` (the dual of
    :func:`frontier_efficiency`). Above every constant's efficiency, the rate of the most efficient one."""
    target = target[..., None]
    single = np.where(efficiencies >= target, rates, np.inf).min(axis=-1)
    ri, rj = rates[..., :, None], rates[..., None, :]
    ei, ej = efficiencies[..., :, None], efficiencies[..., None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        mixed = np.where((ei < target[..., None]) & (target[..., None] <= ej),
                         ri + (rj - ri) * (target[..., None] - ei) / (ej - ei), np.inf).min(axis=(-2, -1))
    richest = np.take_along_axis(rates, np.argmax(efficiencies, axis=-1)[..., None], axis=-1)[..., 0]
    best = np.minimum(single, mixed)
    return np.where(np.isfinite(best), best, richest)


@dataclasses.dataclass(frozen=True)
class Frontier:
    """The constants' points on a group's safety/efficiency plane, on its episodes and in each bootstrap resample."""

    rates: np.ndarray  # (k,) collision rates [-]
    efficiencies: np.ndarray  # (k,)
    resampled_rates: np.ndarray  # (RESAMPLES, k)
    resampled_efficiencies: np.ndarray  # (RESAMPLES, k)

    @classmethod
    def of(cls, constants: Sequence[Played], resampler: Resampler) -> Frontier:
        rates = [constant.collided.astype(float) for constant in constants]
        efficiencies = [constant.efficiency for constant in constants]
        return cls(np.array([r.mean() for r in rates]), np.array([e.mean() for e in efficiencies]),
                   np.stack([resampler.means(r) for r in rates], axis=-1),
                   np.stack([resampler.means(e) for e in efficiencies], axis=-1))


def frontier_gains(played: Played, frontier: Frontier, resampler: Resampler) -> dict[str, Any]:
    """``played``'s efficiency beyond the constants' frontier at its collision rate, and its collision rate below
    the frontier's at its efficiency, each with its paired 95 % interval."""
    point = (frontier.rates, frontier.efficiencies, np.asarray(played.collided.mean()),
             np.asarray(played.efficiency.mean()))
    resampled = (frontier.resampled_rates, frontier.resampled_efficiencies,
                 resampler.means(played.collided.astype(float)), resampler.means(played.efficiency))
    row: dict[str, Any] = {}
    for name, gain in (("frontier_efficiency_gain", lambda r, e, pr, pe: pe - frontier_efficiency(r, e, pr)),
                       ("frontier_safety_gain", lambda r, e, pr, pe: frontier_rate(r, e, pe) - pr)):
        low, high = np.quantile(gain(*resampled), [0.025, 0.975])
        row |= {name: float(gain(*point)), f"{name}_low": float(low), f"{name}_high": float(high)}
    row["beyond_frontier"] = bool(row["frontier_efficiency_gain_low"] > 0 or row["frontier_safety_gain_low"] > 0)
    return row


# --- one group ------------------------------------------------------------------------------------------------------------

@dataclasses.dataclass
class GroupResult:
    """What one group measured."""

    group: HeldOutGroup
    seeds: tuple[int, int]  # the held-out seeds: first, count
    best: str  # the best constant's name (chosen on selection seeds)
    best_safe: str  # the best safe constant's name
    selection_rates: dict[str, float]  # each constant's collision rate on the selection seeds
    played: dict[str, Played]  # every entry's (and hindsight's) episodes
    entries: dict[str, Entry]
    rows: list[dict[str, Any]]  # scores.csv's rows


def group_config(group: HeldOutGroup) -> EnvConfig:
    """The task's config with the group's overrides."""
    return TASK_RECORD.config(group.overrides)


def select_constants(config: EnvConfig, episodes: int, backend: Backend) -> tuple[str, str, dict[str, float]]:
    """The best and the best safe constant on ``episodes`` selection seeds, and each constant's collision rate
    there."""
    seeds = range(SELECTION_SEED_START, SELECTION_SEED_START + episodes)
    names = registry.fixed_names(config)
    played = {name: join(backend.map(play, [(registry.make(name, config), config, list(seeds[i:i + CHUNK]))
                                            for i in range(0, len(seeds), CHUNK)])) for name in names}
    means = {name: float(p.returns.mean()) for name, p in played.items()}
    rates = {name: float(p.collided.mean()) for name, p in played.items()}
    safe = [name for name in names if rates[name] <= SAFE_BUDGET]
    best_safe = max(safe, key=means.__getitem__) if safe else min(names, key=rates.__getitem__)
    return max(names, key=means.__getitem__), best_safe, rates


CACHED_CODE = (Played, efficiency, play, join, select_constants)  # the code whose results the cache keeps, as
# defined here (a test's stand-in for play changes no key)


def run_group(group: HeldOutGroup, entries: Sequence[Entry], first_seed: int, episodes: int, cache: Cache,
              backend: Backend, progress: Callable[[str], None] = lambda _: None) -> GroupResult:
    """Every entry on the group's held-out episodes (and the references and the constants' choices), scored."""
    config = group_config(group)
    base = [TASK, group.name, group.overrides]
    best, best_safe, selection_rates = cache.through(
        cache.key("constants", *base, SELECTION_SEED_START, group.selection),
        lambda: select_constants(config, group.selection, backend))
    references: References | None = None
    entries = list(entries)
    if group.references:
        references_key = cache.key("references", *base, dataclasses.asdict(REFERENCE_PLAN))
        weighting = TASK_RECORD.overrides["reward_weights"]
        references = cache.through(references_key, lambda: choose_references(
            config, {weighting: REWARD_PRESETS[weighting]}, *REFERENCE_PLAN.seeds()[:2], backend)[weighting])
        entries += [reference_entry(name, references_key) for name in REFERENCES]
    seeds = list(range(first_seed, first_seed + episodes))
    chunks = [seeds[i:i + CHUNK] for i in range(0, len(seeds), CHUNK)]
    keys = {entry.name: cache.key("played", *base, first_seed, episodes, entry.key) if entry.key else ""
            for entry in entries}
    played: dict[str, Played] = {}
    for entry in entries:
        if keys[entry.name] and isinstance(kept := cache.get(keys[entry.name]), dict):  # else not kept, or unreadable
            played[entry.name] = Played(**kept)
            progress(f"{group.name}: {entry.name} (cached)")
    pending = [entry for entry in entries if entry.name not in played]
    for start in range(0, len(pending), ENTRIES_PER_MAP):  # a map of several policies: the workers stay busy
        batch = pending[start:start + ENTRIES_PER_MAP]
        parts = backend.map(play, [(entry.make(config, references), config, chunk) for entry in batch
                                   for chunk in chunks])
        for i, entry in enumerate(batch):
            played[entry.name] = join(parts[i * len(chunks):(i + 1) * len(chunks)])
            if keys[entry.name]:  # kept as plain arrays: `python -m` and an import name this class apart
                cache.put(keys[entry.name], dataclasses.asdict(played[entry.name]))
            progress(f"{group.name}: {entry.name}")
    played = {entry.name: played[entry.name] for entry in entries}  # in the entries' order
    constants = [name for name in registry.fixed_names(config) if name in played]
    returns = np.stack([played[name].returns for name in constants])
    played["hindsight"] = join([played[constants[c]].take(np.array([i])) for i, c in enumerate(returns.argmax(axis=0))])
    entries.append(Entry("hindsight", "reference", lambda *_: None, ""))
    reference = played[constants[0]].fingerprints
    for name, p in played.items():
        if not np.array_equal(p.fingerprints, reference):
            raise RuntimeError(f"group {group.name}: {name} played other episodes than {constants[0]} (fingerprints)")
    result = GroupResult(group, (first_seed, episodes), best, best_safe, selection_rates, played,
                         {entry.name: entry for entry in entries}, [])
    result.rows = score_rows(result, [played[name] for name in constants])
    return result


def score_rows(result: GroupResult, constants: Sequence[Played]) -> list[dict[str, Any]]:
    """scores.csv's rows of one group: one per entry."""
    played, resampler = result.played, Resampler(result.seeds[1])
    frontier = Frontier.of(constants, resampler)
    best, safe, rule = played[result.best], played[result.best_safe], played.get(RULE)
    rows = []
    for name, p in played.items():
        entry = result.entries[name]
        n, collisions = p.returns.size, int(p.collided.sum())
        rate, rate_low, rate_high = wilson_interval(collisions, n)
        against = rule if name == result.best and rule is not None else best  # the best constant: its mde vs the rule
        row: dict[str, Any] = {
            "group": result.group.name, "policy": name, "kind": entry.kind, "recipe": entry.recipe,
            "seed": "" if entry.seed is None else entry.seed, "episodes": n, "collisions": collisions,
            "collision_rate": rate, "collision_rate_low": rate_low, "collision_rate_high": rate_high,
            **dict(zip(("efficiency", "efficiency_low", "efficiency_high"), resampler.interval(p.efficiency))),
            **dict(zip(("return", "return_low", "return_high"), resampler.interval(p.returns))),
            "mde": paired_mde(p.returns - against.returns, POWER) if against is not p else math.nan,
            **dict(zip(("cost", "cost_low", "cost_high"), resampler.interval(p.cost))),
        }
        row["mde_share"] = row["mde"] / abs(float(best.returns.mean()))
        for label, other in (("best", best), ("best_safe", safe), ("rule", rule)):
            if other is not None:
                row |= dict(zip((f"gain_over_{label}", f"gain_over_{label}_low", f"gain_over_{label}_high"),
                                resampler.interval(p.returns - other.returns)))
        rows.append(row | frontier_gains(p, frontier, resampler))
    return rows


# --- the whole benchmark -----------------------------------------------------------------------------------------------

@dataclasses.dataclass
class Benchmark:
    """Every group's result, the recipes' aggregates and the left-out groups' reasons."""

    groups: dict[str, GroupResult]
    aggregates: list[dict[str, Any]]
    left_out: dict[str, str]
    first_seed: int


def missing(group: HeldOutGroup) -> str:
    """Why ``group`` cannot run here ("" if it can): its data, or SUMO, is not found."""
    if group.data == "idm":
        try:
            import highway_env  # noqa: F401
        except ImportError:
            return "highway-env is not installed (pip install '.[idm]')"
        return ""
    if group.data:
        return missing_data(group.data)
    if group.overrides.get("simulator") == "sumo":
        try:
            import libsumo  # noqa: F401
        except ImportError:
            return "libsumo is not installed (pip install '.[sumo]'; make benchmark installs it)"
    return ""


def run_benchmark(policies: Sequence[str] = (), groups: Sequence[str] | None = None, episodes: int | None = None,
                  first_seed: int = HELD_OUT_START, cache: Path | None = Path("runs/benchmark-cache"),
                  backend: Backend | None = None, progress: Callable[[str], None] = lambda _: None) -> Benchmark:
    """The benchmark: the default entries and ``policies`` (``--policy``'s specs) on ``groups`` (default: all), each
    on ``episodes`` held-out episodes (default: the group's) from ``first_seed``; ``ValueError`` naming bad input."""
    unknown = [name for name in groups or () if name not in GROUPS]
    if unknown:
        raise ValueError(f"--groups {' '.join(unknown)}: unknown; known: {', '.join(GROUPS)}")
    if episodes is not None and episodes < 1:
        raise ValueError(f"--episodes {episodes}: must be an integer >= 1")
    if first_seed < HELD_OUT_START:
        raise ValueError(f"--first-seed {first_seed}: must be >= {HELD_OUT_START} (lower seeds train and select)")
    entries = default_entries(group_config(GROUPS[DEFAULT_GROUP]))
    for spec in policies:
        entry = policy_entry(spec)
        if entry.name in {e.name for e in entries} | {*REFERENCES, "hindsight"}:
            if any(e.name == entry.name and e.key == entry.key for e in entries):
                continue  # one of the defaults already
            raise ValueError(f"--policy {spec}: its name {entry.name!r} is taken; rename it")
        entries.append(entry)
    backend, cache_ = backend or Backend(), Cache(cache)
    results, left_out = {}, {}
    for name in groups or GROUPS:
        group = GROUPS[name]
        why = missing(group)
        if why:
            left_out[name] = why
            progress(f"{name}: left out: {why}")
            continue
        results[name] = run_group(group, entries, first_seed, episodes or group.episodes, cache_, backend, progress)
    if not results:
        raise ValueError(f"--groups {' '.join(groups or GROUPS)}: none could run ({'; '.join(left_out.values())})")
    return Benchmark(results, aggregate(results), left_out, first_seed)


def normalised(result: GroupResult, name: str) -> float:
    """``name``'s return in the group, as a difference from the best constant's in % of the latter's |return|."""
    best = float(result.played[result.best].returns.mean())
    return 100.0 * (float(result.played[name].returns.mean()) - best) / abs(best)


def score_matrix(results: Mapping[str, GroupResult], names: Sequence[str]) -> np.ndarray:
    """(runs, groups) normalised scores of ``names`` (a recipe's seeds, or one policy)."""
    return np.array([[normalised(result, name) for result in results.values()] for name in names])


def recipe_runs(results: Mapping[str, GroupResult]) -> dict[str, list[str]]:
    """Per recipe, or per other non-constant policy (one run), its entries' names present in every group."""
    first = next(iter(results.values()))
    runs: dict[str, list[str]] = {}
    for name, entry in first.entries.items():
        if entry.kind == "constant" or not all(name in result.played for result in results.values()):
            continue
        runs.setdefault(entry.recipe or name, []).append(name)
    return runs


def aggregate(results: Mapping[str, GroupResult]) -> list[dict[str, Any]]:
    """aggregates.csv's rows: per recipe (its seeds) and per other policy (one run), over the groups: the IQM of
    the normalised scores and the probability of improvement over the paper's rule, each with its stratified
    bootstrap interval."""
    runs = recipe_runs(results)
    rule = score_matrix(results, [RULE]) if RULE in runs else None
    rows = []
    for policy, names in runs.items():
        scores = score_matrix(results, names)
        row: dict[str, Any] = {"policy": policy, "runs": len(names), "groups": len(results),
                               **dict(zip(("iqm", "iqm_low", "iqm_high"), stratified_bootstrap(scores, iqm))),
                               "median_seed_default": float(np.median(scores[:, 0]))}
        if rule is not None:
            row |= dict(zip(("poi_over_rule", "poi_over_rule_low", "poi_over_rule_high"),
                            probability_of_improvement_interval(scores, rule)))
        rows.append(row)
    return rows


TWINS = {"rawgap": "the raw gap (s - s0)/v for the posterior", "nomonitor": "the monitor's features hidden"}


def monitor_question(results: Mapping[str, GroupResult]) -> list[dict[str, Any]]:
    """Issue 39's monitor question: per recipe with an ablated twin (recipe + ``_rawgap`` or ``_nomonitor``, its
    own training seeds), per group and over all groups: the mean normalised score of each and the probability that
    a seed of the recipe beats a seed of its twin (all groups: with its stratified bootstrap interval)."""
    runs = recipe_runs(results)
    rows: list[dict[str, Any]] = []
    for recipe, names in runs.items():
        for suffix, what in TWINS.items():
            if (twin := f"{recipe}_{suffix}") not in runs:
                continue
            mine, theirs = score_matrix(results, names), score_matrix(results, runs[twin])
            for column, group in enumerate(results):
                rows.append({"recipe": recipe, "twin": twin, "ablation": what, "group": group,
                             "score": float(mine[:, column].mean()), "twin_score": float(theirs[:, column].mean()),
                             "poi": probability_of_improvement(mine[:, [column]], theirs[:, [column]]),
                             "poi_low": math.nan, "poi_high": math.nan})
            poi = probability_of_improvement_interval(mine, theirs)
            rows.append({"recipe": recipe, "twin": twin, "ablation": what, "group": "all (IQM)",
                         "score": iqm(mine.ravel()), "twin_score": iqm(theirs.ravel()),
                         **dict(zip(("poi", "poi_low", "poi_high"), poi))})
    return rows


# --- writing ------------------------------------------------------------------------------------------------------------

def fmt(value: float, digits: int = 1) -> str:
    return "n/a" if value is None or (isinstance(value, float) and math.isnan(value)) else f"{value:.{digits}f}"


def ci(row: Mapping[str, Any], name: str, digits: int = 1, scale: float = 1.0) -> str:
    """``name`` [low, high] of a row."""
    return (f"{fmt(row[name] * scale, digits)} [{fmt(row[name + '_low'] * scale, digits)}, "
            f"{fmt(row[name + '_high'] * scale, digits)}]")


def pooled(result: GroupResult, names: Sequence[str]) -> Played:
    """A recipe's seeds as one policy: per episode, the mean over its seeds (collisions as a share)."""
    parts = [result.played[name] for name in names]
    return Played(*(np.mean([getattr(p, field) for p in parts], axis=0) for field in
                    ("returns", "efficiency", "collided", "cost", "duration")), parts[0].fingerprints)


def leaderboard(benchmark: Benchmark) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """The ranking on the default group (else the first run): one row per policy (a recipe's seeds pooled), by mean
    return, with who it beats (paired interval of the return's difference above 0); and every pair's difference."""
    result = benchmark.groups.get(DEFAULT_GROUP) or next(iter(benchmark.groups.values()))
    resampler = Resampler(result.seeds[1])
    members: dict[str, list[str]] = {}
    for name, entry in result.entries.items():
        members.setdefault(entry.recipe or name, []).append(name)
    played = {policy: pooled(result, names) if len(names) > 1 else result.played[names[0]]
              for policy, names in members.items()}
    aggregates = {row["policy"]: row for row in benchmark.aggregates}
    frontier = Frontier.of([result.played[name] for name in registry.fixed_names(group_config(result.group))],
                           resampler)
    pairwise, rows = [], []
    for policy, p in played.items():
        row: dict[str, Any] = {"policy": policy, "kind": result.entries[members[policy][0]].kind,
                               "runs": len(members[policy]),
                               **dict(zip(("return", "return_low", "return_high"), resampler.interval(p.returns))),
                               **dict(zip(("collision_rate", "collision_rate_low", "collision_rate_high"),
                                          resampler.interval(p.collided))),
                               **dict(zip(("efficiency", "efficiency_low", "efficiency_high"),
                                          resampler.interval(p.efficiency))),
                               "cost": float(p.cost.mean()), **frontier_gains(p, frontier, resampler)}
        best = result.played[result.best]
        against = result.played[RULE] if p is best and RULE in result.played else best
        row["mde"] = paired_mde(p.returns - against.returns, POWER) if against is not p else math.nan
        beaten = []
        for other, q in played.items():
            if other == policy:
                continue
            gain, low, high = resampler.interval(p.returns - q.returns)
            pairwise.append({"group": result.group.name, "policy": policy, "other": other, "gain": gain,
                             "gain_low": low, "gain_high": high})
            if low > 0:
                beaten.append(other)
        row["beats"] = beaten
        row |= {key: aggregates.get(policy, {}).get(key, math.nan)
                for key in ("iqm", "iqm_low", "iqm_high", "poi_over_rule", "poi_over_rule_low", "poi_over_rule_high")}
        rows.append(row)
    rows.sort(key=lambda row: -row["return"])
    return rows, pairwise


def beats_text(beaten: Sequence[str], kinds: Mapping[str, str]) -> str:
    """Who a policy beats: the constants counted, the others named."""
    constants = [name for name in beaten if kinds.get(name) == "constant"]
    others = [name for name in beaten if kinds.get(name) != "constant"]
    parts = ([f"{len(constants)} constants"] if constants else []) + others
    return ", ".join(parts) or "-"


def markdown(benchmark: Benchmark, board: Sequence[Mapping[str, Any]]) -> str:
    """leaderboard.md."""
    ranked = benchmark.groups.get(DEFAULT_GROUP) or next(iter(benchmark.groups.values()))
    kinds = {row["policy"]: row["kind"] for row in board}
    lines = [f"# The benchmark: {TASK}", "",
             "Written by `python -m train.benchmark` (docs/benchmark.md says what every column means). Every policy "
             "plays the same held-out episodes of each group (their fingerprints checked); intervals are 95 % "
             f"(percentile bootstrap over episodes, {RESAMPLES} resamples shared by a group's policies; Wilson for "
             "a single policy's collision rate). Seeds: held-out from "
             f"{benchmark.first_seed}; the constants' choices on selection seeds from {SELECTION_SEED_START} (each "
             "group's count below); the references' tables on training seeds "
             f"0-{REFERENCE_PLAN.train - 1} and their choices on selection seeds {SELECTION_SEED_START}-"
             f"{SELECTION_SEED_START + REFERENCE_PLAN.selection - 1}.", "",
             f"## Leaderboard: {ranked.group.name} ({ranked.group.description}), {ranked.seeds[1]} episodes", "",
             "Ranked by mean return. A recipe's training seeds are pooled (per episode, the mean over its seeds); "
             "IQM and P(improvement over the paper's rule) are over seeds x every group, in % of each group's best "
             "constant. mde: the smallest difference of return from the best constant detectable at 80 % power "
             "(paired). Frontier: efficiency beyond the best mix of constants at the same collision rate.", "",
             "| rank | policy | kind | runs | return [CI] | mde | collisions per 100 episodes [CI] | efficiency [CI] "
             "| beyond the constants' frontier: efficiency [CI] | IQM over groups, % [CI] | P(beats the rule) [CI] "
             "| beats (paired, on return) |", "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for rank, row in enumerate(board, start=1):
        lines.append(f"| {rank} | {row['policy']} | {KIND_NAMES[row['kind']]} | {row['runs']} | {ci(row, 'return')} | "
                     f"{fmt(row['mde'])} | "
                     f"{ci(row, 'collision_rate', 2, 100.0)} | {ci(row, 'efficiency')} | "
                     f"{ci(row, 'frontier_efficiency_gain')}{' **beyond**' if row['beyond_frontier'] else ''} | "
                     f"{ci(row, 'iqm')} | {ci(row, 'poi_over_rule', 2)} | {beats_text(row['beats'], kinds)} |")
    for name, result in benchmark.groups.items():
        lines += ["", f"## {name}: {result.group.description}", "",
                  f"{result.seeds[1]} episodes (seeds {result.seeds[0]}-{sum(result.seeds) - 1}). Best constant "
                  f"(selection seeds {SELECTION_SEED_START}-{SELECTION_SEED_START + result.group.selection - 1}): "
                  f"{result.best}; best safe constant (at most {SAFE_BUDGET:.0%} collisions "
                  f"there): {result.best_safe}. mde: the smallest difference of return from the best constant "
                  f"detectable at {POWER:.0%} power (the best constant's row: from the rule).", "",
                  "| policy | collisions [Wilson CI of the rate, %] | cost | efficiency [CI] | return [CI] | mde "
                  "(% of the best's) | gain over the best constant [CI] | over the best safe [CI] | over the rule "
                  "[CI] | frontier: efficiency [CI] | frontier: collisions per 100 [CI] |",
                  "|---|---|---|---|---|---|---|---|---|---|---|"]
        for row in sorted(result.rows, key=lambda row: -row["return"]):
            lines.append(
                f"| {row['policy']} | {row['collisions']} [{100 * row['collision_rate_low']:.1f}, "
                f"{100 * row['collision_rate_high']:.1f}] | {fmt(row['cost'])} | {ci(row, 'efficiency')} | "
                f"{ci(row, 'return')} | {fmt(row['mde'])} ({fmt(100 * row['mde_share'])} %) | "
                f"{ci(row, 'gain_over_best')} | {ci(row, 'gain_over_best_safe')} | "
                f"{ci(row, 'gain_over_rule') if 'gain_over_rule' in row else 'n/a'} | "
                f"{ci(row, 'frontier_efficiency_gain')} | {ci(row, 'frontier_safety_gain', 2, 100.0)} |")
    lines += ["", "## Recipes and policies over the groups", "",
              "| policy | runs | groups | IQM of % over the best constant [CI] | P(improvement over the rule) [CI] |",
              "|---|---|---|---|---|"]
    for row in benchmark.aggregates:
        lines.append(f"| {row['policy']} | {row['runs']} | {row['groups']} | {ci(row, 'iqm')} | "
                     f"{ci(row, 'poi_over_rule', 2) if 'poi_over_rule' in row else 'n/a'} |")
    if twins := monitor_question(benchmark.groups):
        lines += ["", "## The monitor question: each recipe against its twins", "",
                  "A twin is the recipe trained the same way on its own seeds with the monitor's posterior replaced by "
                  "the raw gap, or with the monitor's features hidden. Scores in % over each group's best constant "
                  "(seed means; all groups: the IQM over seeds x groups); P: the probability that a seed of the "
                  "recipe beats a seed of the twin in that group (all groups: averaged, with its stratified bootstrap "
                  "interval).", "",
                  "| recipe | twin | group | recipe's score | twin's score | P(recipe beats twin) |", "|---|---|---|---|---|---|"]
        lines += [f"| {row['recipe']} | {row['twin']} | {row['group']} | {row['score']:+.1f} | {row['twin_score']:+.1f} "
                  f"| {ci(row, 'poi', 2) if not math.isnan(row['poi_low']) else fmt(row['poi'], 2)} |" for row in twins]
    lines += ["", *(f"- group {name} left out: {why}" for name, why in benchmark.left_out.items()), ""]
    return "\n".join(lines)


def figures(benchmark: Benchmark, out: Path) -> None:
    """frontier.png (per group, the constants' points and frontier on the safety/efficiency plane, the rules,
    references and recipes' seeds beside them) and profile.png (performance profiles over every group)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    results = list(benchmark.groups.values())
    columns = min(4, len(results))
    rows_ = math.ceil(len(results) / columns)
    fig, axes = plt.subplots(rows_, columns, figsize=(4.2 * columns, 3.6 * rows_), squeeze=False)
    colours = {"rule": "tab:red", "reference": "tab:green", "learned": "tab:blue", "policy": "tab:purple"}
    for ax, result in zip(axes.flat, results):
        constants = registry.fixed_names(group_config(result.group))
        rates = np.array([100 * result.played[name].collided.mean() for name in constants])
        effs = np.array([result.played[name].efficiency.mean() for name in constants])
        grid = np.linspace(0, max(rates.max(), 1e-9) * 1.05, 200)
        ax.plot(grid, frontier_efficiency(rates, effs, grid), color="0.6", lw=1, zorder=0)
        ax.scatter(rates, effs, color="0.4", s=14)
        for name, x, y in zip(constants, rates, effs):
            ax.annotate(name.removeprefix(registry.FIXED_PREFIX), (x, y), fontsize=5.5, xytext=(2, 2),
                        textcoords="offset points")
        for name, played in result.played.items():
            kind = result.entries[name].kind
            if kind == "constant":
                continue
            x, y = 100 * played.collided.mean(), played.efficiency.mean()
            ax.scatter([x], [y], color=colours[kind], s=10 if kind == "learned" else 18,
                       marker="o" if kind == "learned" else "^")
            if kind != "learned" or result.entries[name].seed == 0:
                label = result.entries[name].recipe or name
                ax.annotate(label, (x, y), fontsize=5.5, xytext=(2, -6), textcoords="offset points",
                            color=colours[kind])
        ax.set_title(f"{result.group.name} ({result.seeds[1]} episodes)", fontsize=9)
        ax.set_xlabel("collisions per 100 episodes", fontsize=8)
        ax.set_ylabel("efficiency per episode", fontsize=8)
        ax.tick_params(labelsize=7)
    for ax in list(axes.flat)[len(results):]:
        ax.set_visible(False)
    fig.tight_layout()
    fig.savefig(out / "frontier.png", dpi=110, metadata={"Software": None})
    plt.close(fig)

    runs = recipe_runs(benchmark.groups)
    matrices = {policy: score_matrix(benchmark.groups, names) for policy, names in runs.items()
                if benchmark.groups[next(iter(benchmark.groups))].entries[names[0]].kind != "reference"}
    every = np.concatenate([m.ravel() for m in matrices.values()])
    thresholds = np.linspace(np.quantile(every, 0.02), np.quantile(every, 0.98), 200)
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for policy, scores in matrices.items():
        ax.plot(thresholds, performance_profile(scores, thresholds), lw=1.5 if len(runs[policy]) > 1 else 1,
                label=f"{policy} ({len(runs[policy])} run{'s' if len(runs[policy]) > 1 else ''})")
    ax.axvline(0, color="0.5", lw=0.8, ls="--")
    ax.set_xlabel("return: % over the group's best constant (tau)")
    ax.set_ylabel("fraction of runs x groups with score > tau")
    ax.set_title(f"Performance profiles over {len(benchmark.groups)} groups", fontsize=9)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "profile.png", dpi=110, metadata={"Software": None})
    plt.close(fig)


def write(benchmark: Benchmark, out: Path) -> None:
    """The benchmark's files into the directory ``out`` (which must exist)."""
    board, pairwise = leaderboard(benchmark)
    rows = [row for result in benchmark.groups.values() for row in result.rows]
    cli.write_rows(rows, out / "scores.csv")
    cli.write_rows(benchmark.aggregates, out / "aggregates.csv")
    cli.write_rows(pairwise, out / "pairwise.csv")
    (out / "leaderboard.md").write_text(markdown(benchmark, board), encoding="utf-8")
    figures(benchmark, out)


# --- the command line -----------------------------------------------------------------------------------------------------

@contextmanager
def claimed(out: Path) -> Iterator[None]:
    """Hold ``<out>.lock`` while the run writes towards ``out``: a second writer refuses; a lock whose process is
    gone is taken over."""
    lock = out.parent / f"{out.name}.lock"
    out.parent.mkdir(parents=True, exist_ok=True)
    for _ in range(2):
        try:
            descriptor = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
            break
        except FileExistsError:
            try:
                owner = int(lock.read_text() or "0")
                os.kill(owner, 0)
            except (ValueError, ProcessLookupError, FileNotFoundError):
                lock.unlink(missing_ok=True)  # its writer is gone
                continue
            raise FileExistsError(f"--out {out}: another run (process {owner}) is writing it ({lock})") from None
    else:
        raise FileExistsError(f"--out {out}: cannot take its lock {lock}")
    os.write(descriptor, str(os.getpid()).encode())
    os.close(descriptor)
    try:
        yield
    finally:
        lock.unlink(missing_ok=True)


def size_groups(names: Sequence[str]) -> str:
    """The pilot: per group, on PILOT selection seeds, the largest standard deviation of a paired difference of
    return from the best constant there (the paper's rule's, and the constants' one ladder step either side), and
    the episodes that see EFFECT of the best constant's |return| at POWER with it."""
    lines = [f"| group | best constant's return | largest sd of a paired difference from it (whose) | episodes for "
             f"{EFFECT:.0%} at {POWER:.0%} power | given |", "|---|---|---|---|---|"]
    seeds = list(range(SELECTION_SEED_START, SELECTION_SEED_START + PILOT))
    for name in names:
        group = GROUPS[name]
        if missing(group) or group.capped:
            lines.append(f"| {name} | not measured: {missing(group) or group.capped} | | | {group.episodes} |")
            continue
        config = group_config(group)
        constants = registry.fixed_names(config)
        played = {policy: play(registry.make(policy, config), config, seeds) for policy in [*constants, RULE]}
        best = max(constants, key=lambda policy: played[policy].returns.mean())
        near = [constants[i] for i in (constants.index(best) - 1, constants.index(best) + 1) if 0 <= i < len(constants)]
        sds = {policy: float(np.std(played[policy].returns - played[best].returns, ddof=1)) for policy in [RULE, *near]}
        widest = max(sds, key=sds.__getitem__)
        level = abs(float(played[best].returns.mean()))
        lines.append(f"| {name} | {-level:.1f} ({best}) | {sds[widest]:.1f} ({widest}) | "
                     f"{episodes_for(sds[widest], EFFECT * level, POWER)} | {group.episodes} |")
        print(lines[-1], flush=True)
    return "\n".join(lines)


def one_line_error(message: str) -> None:
    """argparse's usage error as one line (no usage block), exit status 2."""
    print(f"python -m train.benchmark: error: {message}", file=sys.stderr)
    sys.exit(2)


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--policy", action="append", default=[], metavar="SPEC",
                        help="a policy to add (repeatable): a registered name (fixed_1.4, rule_per_vehicle, ...), "
                             "MODULE:NAME (a class built with the env's config, or an object with predict), or a "
                             "trained run's directory")
    parser.add_argument("--groups", nargs="+", default=None, metavar="GROUP",
                        help=f"the groups (default: all): {', '.join(GROUPS)}")
    parser.add_argument("--episodes", type=cli.count, default=None,
                        help="held-out episodes per group (default: each group's, sized by power)")
    parser.add_argument("--first-seed", type=int, default=HELD_OUT_START,
                        help=f"the held-out episodes' first seed (default: %(default)s; >= {HELD_OUT_START}): "
                             "another range checks the benchmark on seeds of your own")
    parser.add_argument("--out", type=Path, default=Path("runs/benchmark"),
                        help="output directory (default: %(default)s; an existing one is replaced only with --force)")
    parser.add_argument("--force", action="store_true", help="replace an existing --out")
    parser.add_argument("--cache", type=Path, default=Path("runs/benchmark-cache"),
                        help="where results are kept by what determines them (default: %(default)s)")
    parser.add_argument("--no-cache", action="store_true", help="compute everything, keep nothing")
    parser.add_argument("--size", action="store_true", help="print the pilot that sized the groups and stop")
    add_arguments(parser)
    parser.error = one_line_error  # type: ignore[method-assign]
    args = parser.parse_args(argv)
    try:
        backend = Backend.from_args(args)
    except ValueError as error:
        parser.error(str(error))
    unknown = [name for name in args.groups or () if name not in GROUPS]
    if unknown:
        raise ValueError(f"--groups {' '.join(unknown)}: unknown; known: {', '.join(GROUPS)}")
    if args.size:
        print(size_groups(args.groups or list(GROUPS)))
        return
    out = cli.output_dir(args.out)
    if out.exists() and any(out.iterdir()) and not args.force:
        raise FileExistsError(f"--out {out}: exists; --force replaces it (or give another --out)")
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))  # a kill runs the clean-up below
    start = time.perf_counter()
    with claimed(out):
        from tqdm import tqdm

        bar = tqdm(desc="benchmark", unit=" policy x group", disable=None, file=sys.stderr)
        say = (lambda text: (bar.set_postfix_str(text), bar.update())) if not bar.disable else \
            (lambda text: print(f"  {text}", file=sys.stderr, flush=True))
        benchmark = run_benchmark(args.policy, args.groups, args.episodes, args.first_seed,
                                  None if args.no_cache else args.cache, backend, say)
        bar.close()
        work = cli.work_directory(out)
        try:
            write(benchmark, work)
            cli.publish(work, out)
        finally:
            shutil.rmtree(work, ignore_errors=True)  # gone once published; a failed write leaves no partial folder
    print((out / "leaderboard.md").read_text(encoding="utf-8").split("\n## ", 2)[1].join(["## ", "\n"]))
    sizes = ", ".join(f"{name} {result.seeds[1]}" for name, result in benchmark.groups.items())
    print(f"wrote {out}/ (leaderboard.md, scores.csv, aggregates.csv, pairwise.csv, frontier.png, profile.png): "
          f"episodes per group {sizes}; {time.perf_counter() - start:.0f} s (the last piece of work: {backend.describe()})")


if __name__ == "__main__":
    cli.run(main, "python -m train.benchmark")
