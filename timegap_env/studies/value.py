"""The value of information: every constant setting and every oracle on the same episodes, and the lookup table.

Shared by ``train.value_of_information`` (its tables), ``train.evaluate`` (the oracle), ``train.train_ppo`` (the
learning curve's yardsticks), ``train.choose_degradation_mix`` and ``train.detection_benchmark``.

- :func:`constants`: every ladder setting held for whole episodes (or, ``flag_aware``, every pair of settings, one
  while every V2V flag is up and one while any is down), in vector-env batches of at most ``BATCH`` episodes;
- :func:`measure_lookup`: the lookup oracle's table, per true condition the constant that scored best on training
  seeds (each condition pinned from the start);
- :func:`all_oracles`, :func:`choose_oracle`: the oracles of ``timegap_env.agents.oracles`` and *the* oracle, the best on
  ``SELECTION_EPISODES`` selection episodes (seeds from ``SELECTION_SEED_START``, below the held-out seeds).

Every batch is one piece of work for a :class:`~timegap_env.experiments.backends.Backend` and runs through the
rollout harness (:func:`timegap_env.experiments.rollout.rollout`).
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from timegap_env.agents.oracles import NOMINAL, LookupOracle, StabilityOracle, TruthPolicy, bin_centres
from timegap_env.agents.policies import seconds
from timegap_env.agents.protocol import EVAL_SEED_START
from timegap_env.config import DEGRADATION_KINDS, DEGRADATIONS, EnvConfig
from timegap_env.envs.info import truth_of
from timegap_env.experiments.backends import Backend
from timegap_env.experiments.rollout import rollout
from timegap_env.sim.degradation import round_to_tick
from timegap_env.tasks import SELECTION_SEED_START

DEFAULT_TRAIN_EPISODES = 16
MARGINS = (0.0, 0.1, 0.2)  # stability oracle margins above the smallest string-stable setting [s]
BATCH = 1024  # envs per vector env when running many episodes [-]
SELECTION_EPISODES = 48  # the oracle is chosen on this many selection episodes of the default mix [-]
TARGET_SHARE = 0.25  # the target: oracle - best blind constant >= this share of |best blind| [-]
MONITOR_SIGNALS = ("time_out_of_control", "exceedances")  # episode summary read-outs of the monitor's chart

Chooser = Callable[[np.ndarray, dict[str, Any]], np.ndarray]  # (observations, infos) -> actions


def run(config: EnvConfig, seeds: Sequence[int], choose: Chooser, options: dict[str, Any] | None = None) -> dict[str, Any]:
    """One episode per seed in the native vector env under ``choose`` (through :func:`rollout`); per episode, arrays:
    return, collision, the kind of degradation drawn (or pinned) and ``MONITOR_SIGNALS`` of the episode summary."""
    records = rollout(choose, config, seeds, options).records
    return {"return": np.array([record.episode_return for record in records]),
            "collision": np.array([record.summary["collision"] for record in records], dtype=bool),
            "kind": np.array([record.degradation for record in records], dtype=object),
            **{signal: np.array([float(record.summary[signal]) for record in records]) for signal in MONITOR_SIGNALS}}


def flag_aware_actions(up: np.ndarray, down: np.ndarray, obs: np.ndarray, infos: dict[str, Any]) -> np.ndarray:
    """Per env, level ``up`` while every follower's V2V flag is up, else ``down`` (a chooser, with both bound)."""
    return np.where(infos["v2v"].all(axis=1), up, down)


def oracle_actions(oracle: TruthPolicy, obs: np.ndarray, infos: dict[str, Any]) -> np.ndarray:
    """``oracle``'s action on the ground truth in ``infos`` (a chooser, with the oracle bound)."""
    return oracle.act(truth_of(infos))


def oracle_piece(config: EnvConfig, seeds: Sequence[int], oracle: TruthPolicy) -> tuple[Any, ...]:
    """The arguments of :func:`run` that run ``oracle`` on ``seeds``: a piece of work for a backend."""
    return config, list(seeds), functools.partial(oracle_actions, oracle), None


def constant_pieces(config: EnvConfig, seeds: Sequence[int], options: dict[str, Any] | None = None,
                    flag_aware: bool = False) -> list[tuple[Any, ...]]:
    """The arguments of :func:`run` for :func:`constants`: every job (seed, level up, level down) in batches of at
    most BATCH envs, each a piece of work for a backend."""
    n_levels = len(config.setting_levels)
    pairs = [(up, down) for up in range(n_levels) for down in range(n_levels)] if flag_aware else \
        [(level, level) for level in range(n_levels)]
    return pair_pieces(config, seeds, pairs, options)


def pair_pieces(config: EnvConfig, seeds: Sequence[int], pairs: Sequence[tuple[int, int]],
                options: dict[str, Any] | None = None) -> list[tuple[Any, ...]]:
    """The arguments of :func:`run` (or any function of the same arguments) that play each (level while every V2V
    flag is up, level while any is down) of ``pairs`` on every seed, seed after seed, in batches of at most BATCH
    envs: each a piece of work for a backend."""
    jobs = [(seed, up, down) for seed in seeds for up, down in pairs]
    pieces = []
    for start in range(0, len(jobs), BATCH):
        chunk = jobs[start:start + BATCH]
        up, down = (np.array([job[i] for job in chunk]) for i in (1, 2))
        pieces.append((config, [job[0] for job in chunk], functools.partial(flag_aware_actions, up, down), options))
    return pieces


def gather_constants(parts: Sequence[dict[str, Any]], config: EnvConfig, n_seeds: int,
                     flag_aware: bool = False) -> dict[str, np.ndarray]:
    """The results of :func:`constant_pieces`' pieces, in order, as :func:`constants` returns them."""
    n_levels = len(config.setting_levels)
    shape = (n_seeds, n_levels, n_levels) if flag_aware else (n_seeds, n_levels)
    return {name: np.concatenate([part[name] for part in parts]).reshape(shape) for name in parts[0]}


def constants(config: EnvConfig, seeds: Sequence[int], options: dict[str, Any] | None = None,
              flag_aware: bool = False, backend: Backend | None = None) -> dict[str, np.ndarray]:
    """Every constant on every seed: arrays (n_seeds, n_levels). With ``flag_aware``, every pair of constants, one
    while every follower's V2V flag is up and one while any is down: arrays (n_seeds, n_levels while up, n_levels
    while down), whose diagonal holds the plain constants. Run in batches of at most BATCH envs, spread by
    ``backend`` (default: serial)."""
    parts = (backend or Backend()).map(run, constant_pieces(config, seeds, options, flag_aware))
    return gather_constants(parts, config, len(seeds), flag_aware)


def sized(kind: str, size: float, config: EnvConfig) -> float:
    """``size`` as a degradation of ``kind`` takes it: a time (a V2V latency) on whole ticks."""
    return round_to_tick(size, config.platoon.dt) if DEGRADATIONS[kind].whole_ticks else size


def diagonal(pairs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The plain constants of flag-aware pairs (n_seeds, n_levels, n_levels): arrays (n_seeds, n_levels)."""
    return {name: np.diagonal(value, axis1=1, axis2=2) for name, value in pairs.items()}


def training_conditions(config: EnvConfig) -> dict[str, tuple[EnvConfig, dict[str, Any]]]:
    """Each condition of the lookup oracle and how to run it: (config, reset options). A sized kind is pinned at
    its bin's centre from the start on every follower; a commercial ACC platoon draws its cars as the mix does."""
    conditions: dict[str, tuple[EnvConfig, dict[str, Any]]] = {NOMINAL: (config, {"degradation": None})}
    for kind in DEGRADATION_KINDS:
        if DEGRADATIONS[kind].range_field is not None:
            conditions |= {f"{kind}:{b}": (config, {"degradation": {"kind": kind, "size": sized(kind, size, config)}})
                           for b, size in bin_centres(kind, config.degradation).items()}
        elif kind == "commercial_acc":
            only = config.with_overrides({"degradation": config.degradation.with_overrides({"kind_weights": {kind: 1.0}})})
            conditions[kind] = (only, {})
        else:
            conditions[kind] = (config, {"degradation": {"kind": kind}})
    return conditions


def measure_lookup(config: EnvConfig, train_episodes: int,
                   backend: Backend | None = None) -> tuple[dict[str, float], list[dict[str, Any]]]:
    """The lookup table (condition -> best constant [s]) from training seeds, and a row per condition; every
    condition's batches in one map of ``backend`` (default: serial)."""
    seeds = list(range(train_episodes))
    assert seeds[-1] < EVAL_SEED_START
    conditions = training_conditions(config)
    pieces = {key: constant_pieces(condition_config, seeds, options)
              for key, (condition_config, options) in conditions.items()}
    parts = iter((backend or Backend()).map(run, [piece for chunks in pieces.values() for piece in chunks]))
    table, rows = {}, []
    for key, (condition_config, _) in conditions.items():
        result = gather_constants([next(parts) for _ in pieces[key]], condition_config, len(seeds))
        means = result["return"].mean(axis=0)
        best = int(np.argmax(means))
        table[key] = float(config.setting_levels[best])
        rows.append({"condition": key, "best_setting": table[key], "collisions_at_best": int(result["collision"][:, best].sum()),
                     **{f"return_{seconds(level)}": float(m) for level, m in zip(config.setting_levels, means)}})
    return table, rows


def all_oracles(config: EnvConfig, table: dict[str, float]) -> list[TruthPolicy]:
    """Every oracle: the stability oracle at each margin of MARGINS, the lookup oracle (``table``, see
    :func:`measure_lookup`) on the condition acting now and on the episode's whole schedule."""
    return [*(StabilityOracle(config, margin) for margin in MARGINS),
            LookupOracle(table, config), LookupOracle(table, config, whole_episode=True)]


def choose_oracle(config: EnvConfig, oracles: Sequence[TruthPolicy], backend: Backend | None = None) -> TruthPolicy:
    """*The* oracle: of ``oracles``, the best by mean return on the SELECTION_EPISODES selection episodes, each
    oracle's episodes one piece of ``backend`` (default: serial)."""
    selection = list(range(SELECTION_SEED_START, SELECTION_SEED_START + SELECTION_EPISODES))
    assert selection[-1] < EVAL_SEED_START
    results = (backend or Backend()).map(run, [oracle_piece(config, selection, oracle) for oracle in oracles])
    return oracles[int(np.argmax([result["return"].mean() for result in results]))]


def make_oracle(config: EnvConfig | None = None, train_episodes: int | None = None, backend: Any = None) -> Any:
    """*The* oracle for ``config`` (default: the default env): the lookup table measured on ``train_episodes``
    training episodes per condition (default ``DEFAULT_TRAIN_EPISODES``), every oracle built and the best on
    the selection seeds chosen, the episodes spread by ``backend`` (default: serial)."""
    config = config or EnvConfig()
    table, _ = measure_lookup(config, DEFAULT_TRAIN_EPISODES if train_episodes is None else train_episodes, backend)
    return choose_oracle(config, all_oracles(config, table), backend)


def kind_groups(kinds: np.ndarray) -> list[tuple[str, np.ndarray]]:
    """("all", every episode), then each kind present, NOMINAL first: (label, mask)."""
    present = [NOMINAL] + [k for k in DEGRADATION_KINDS if k in set(kinds)]
    return [("all", np.ones(kinds.size, dtype=bool))] + [(k, kinds == k) for k in present if (kinds == k).any()]


__all__ = ["BATCH", "DEFAULT_TRAIN_EPISODES", "MARGINS", "MONITOR_SIGNALS", "SELECTION_EPISODES", "SELECTION_SEED_START",
           "TARGET_SHARE", "all_oracles", "choose_oracle", "constant_pieces", "constants", "diagonal", "gather_constants",
           "kind_groups", "make_oracle", "measure_lookup", "oracle_piece", "pair_pieces", "run", "training_conditions"]
