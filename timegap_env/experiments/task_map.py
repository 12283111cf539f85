"""The map of where reading the monitor can pay (issue 24; the criterion is in ``docs/task.md``).

For each defensible weighting of the reward terms (:data:`WEIGHTINGS`), each degradation severity
(:data:`SEVERITIES`) and each traffic mix (:data:`TRAFFIC`): the gap on held-out seeds from the best
blind constant (chosen on selection seeds) to each reference that knows more:

- ``v2v_pair``: one constant while every V2V flag is up, another while any is down (chosen on selection seeds);
- ``degradation_aware``: of the lookup oracles (per true condition, the constant best on training seeds) and the
  stability oracles (smallest string-stable setting + a margin), the best on selection seeds;
- ``hindsight``: per held-out episode, the best constant for it.

A weighting only reweights the episode's reward terms, so every constant runs once per cell and is scored under
every weighting afterwards; the references whose choices depend on the weighting run once per weighting. Every
episode runs through the rollout harness; the seeds of each step are fixed below (training 0..,
selection from ``SELECTION_SEED_START``, held-out from ``EVAL_SEED_START``).
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Sequence
from typing import Any

import numpy as np

from timegap_env.agents.oracles import LookupOracle, StabilityOracle, TruthPolicy
from timegap_env.agents.protocol import EVAL_SEED_START
from timegap_env.config import REWARD_PRESETS, EnvConfig, RewardPreset
from timegap_env.envs.reward import REWARD_TERMS
from timegap_env.experiments.backends import Backend
from timegap_env.experiments.heldout import LARGER_DEGRADATIONS
from timegap_env.experiments.rollout import rollout
from timegap_env.experiments.stats import bootstrap_mean
from timegap_env.experiments.value import (
    MARGINS, SELECTION_SEED_START, oracle_actions, pair_pieces, training_conditions,
)


WEIGHTINGS: dict[str, RewardPreset] = REWARD_PRESETS  # the defensible weightings, the config's presets
SEVERITIES: dict[str, dict[str, Any]] = {  # EnvConfig.degradation overrides
    "none": {"kind_weights": {"none": 1.0}},
    "default": {},
    "severe": LARGER_DEGRADATIONS,
}
TRAFFIC: dict[str, dict[str, float]] = {  # EnvConfig.scenario_weights
    "default": dict(EnvConfig().scenario_weights),
    "harsh": {"stop_and_go": 1.0, "emergency_braking": 1.0},
    "changing": {"regimes": 1.0},  # regimes that change within an episode (timegap_env.leaders.regimes)
}
REFERENCES = ("v2v_pair", "degradation_aware", "hindsight")
FRONT_OBJECTIVES = ("efficiency", "string_stability", "tracking")  # capacity, string stability, time-gap variation:
# the reward terms (each summed over the episode, higher is better) whose Pareto fronts the map compares
TARGET_SHARE = 0.15  # the criterion: the degradation-aware oracle beats the best blind constant by this share [-]
MAX_BLIND_COLLISION_RATE = 0.01  # ... with the best blind constant colliding in at most this share of episodes [-]


@dataclasses.dataclass(frozen=True)
class Plan:
    """How many episodes each step uses, and so which seeds."""

    train: int = 16  # per pinned condition, for the lookup tables: seeds 0..train-1
    selection: int = 32  # seeds from SELECTION_SEED_START: the choices (best blind constant, pair, oracle)
    held_out: int = 100  # seeds from EVAL_SEED_START: every number of the map

    def seeds(self) -> tuple[list[int], list[int], list[int]]:
        """Training, selection and held-out seeds, disjoint."""
        train = list(range(self.train))
        selection = list(range(SELECTION_SEED_START, SELECTION_SEED_START + self.selection))
        held_out = list(range(EVAL_SEED_START, EVAL_SEED_START + self.held_out))
        assert train[-1] < selection[0] and selection[-1] < held_out[0]
        return train, selection, held_out


def cell_config(severity: str, traffic: str) -> EnvConfig:
    """The env config of one cell of the map (v0's defaults otherwise); ``ValueError`` naming an unknown one."""
    for name, value, known in (("severity", severity, SEVERITIES), ("traffic", traffic, TRAFFIC)):
        if value not in known:
            raise ValueError(f"{name} = {value!r}: unknown; known: {list(known)}")
    default = EnvConfig()
    return default.with_overrides({"degradation": default.degradation.with_overrides(SEVERITIES[severity]),
                                   "scenario_weights": TRAFFIC[traffic]})


def term_sums(config: EnvConfig, seeds: Sequence[int], choose: Any, options: dict[str, Any] | None = None
              ) -> tuple[np.ndarray, np.ndarray]:
    """One episode per seed under ``choose``: each reward term summed, (n_seeds, n_terms) in REWARD_TERMS order,
    and whether it collided, (n_seeds,)."""
    records = rollout(choose, config, seeds, options).records
    terms = np.array([[record.rewards[name] for name in REWARD_TERMS] for record in records])
    return terms, np.array([bool(record.summary["collision"]) for record in records])


def pair_terms(config: EnvConfig, seeds: Sequence[int], pairs: Sequence[tuple[int, int]], backend: Backend,
               options: dict[str, Any] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Term sums (n_pairs, n_seeds, n_terms) and collisions (n_pairs, n_seeds) of every pair of levels."""
    parts = backend.map(term_sums, pair_pieces(config, seeds, pairs, options))
    terms = np.concatenate([part[0] for part in parts]).reshape(len(seeds), len(pairs), len(REWARD_TERMS))
    collided = np.concatenate([part[1] for part in parts]).reshape(len(seeds), len(pairs))
    return terms.transpose(1, 0, 2), collided.T


def weigh(terms: np.ndarray, weighting: RewardPreset) -> np.ndarray:
    """The return under ``weighting`` of term sums (..., n_terms)."""
    return terms @ np.array([getattr(weighting.weights, name) for name in REWARD_TERMS])


def lookup_tables(config: EnvConfig, train: Sequence[int], backend: Backend) -> dict[str, dict[str, float]]:
    """Per weighting, the lookup oracle's table: per pinned condition, the constant best on ``train`` seeds."""
    conditions = training_conditions(config)
    n_levels = len(config.setting_levels)
    scored = {key: pair_terms(condition_config, train, [(level, level) for level in range(n_levels)], backend, options)[0]
              for key, (condition_config, options) in conditions.items()}
    return {name: {key: float(config.setting_levels[int(np.argmax(weigh(terms, weighting).mean(axis=1)))])
                   for key, terms in scored.items()} for name, weighting in WEIGHTINGS.items()}


def oracle_terms(config: EnvConfig, seeds: Sequence[int], oracle: TruthPolicy) -> tuple[np.ndarray, np.ndarray]:
    """Term sums and collisions of ``oracle`` on ``seeds``."""
    return term_sums(config, seeds, functools.partial(oracle_actions, oracle))


def hypervolume(points: np.ndarray, reference: np.ndarray) -> float:
    """The volume dominated by ``points`` (n, 3), every objective maximised, above ``reference`` (3,) (below every
    point): slices along the first objective, each the 2-D area dominated by the points at or beyond it."""
    points = points[np.argsort(-points[:, 0], kind="stable")]
    total = 0.0
    for i in range(len(points)):
        width = points[i, 0] - (points[i + 1, 0] if i + 1 < len(points) else reference[0])
        if width <= 0:
            continue
        layer = points[: i + 1, 1:][np.argsort(-points[: i + 1, 1], kind="stable")]
        tallest = np.maximum.accumulate(layer[:, 1])
        edges = np.append(layer[1:, 0], reference[1])
        total += width * float(np.sum((layer[:, 0] - edges) * np.maximum(tallest - reference[2], 0.0)))
    return total


def front_rows(constants: np.ndarray, references: dict[str, np.ndarray], levels: Sequence[float],
               cell: dict[str, Any]) -> list[dict[str, Any]]:
    """The constants' and the references' mean FRONT_OBJECTIVES ((n_seeds, n_terms) term sums each; constants
    (n_levels, n_seeds, n_terms)) and the hypervolume of the constants alone and with each reference, in units of
    each objective's spread over the cell's points, above the worst point."""
    columns = [REWARD_TERMS.index(name) for name in FRONT_OBJECTIVES]
    points = {f"constant {level:g} s": constants[i].mean(axis=0)[columns] for i, level in enumerate(levels)}
    points |= {name: terms.mean(axis=0)[columns] for name, terms in references.items()}
    every = np.array(list(points.values()))
    low, spread = every.min(axis=0), np.maximum(every.max(axis=0) - every.min(axis=0), 1e-12)
    scaled = {name: (point - low) / spread for name, point in points.items()}
    blind = np.array([scaled[f"constant {level:g} s"] for level in levels])
    origin = np.zeros(3)
    constants_volume = hypervolume(blind, origin)
    rows = []
    for name, point in points.items():
        volume = constants_volume if name.startswith("constant") else hypervolume(np.vstack([blind, scaled[name]]), origin)
        rows.append({**cell, "point": name, **dict(zip(FRONT_OBJECTIVES, point.tolist())),
                     "hypervolume": volume, "constants_hypervolume": constants_volume})
    return rows


def map_cell(severity: str, traffic: str, plan: Plan, backend: Backend
             ) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """The rows of one cell: per weighting, the best blind constant and each reference on the held-out seeds; and
    per weighting, the Pareto points (:func:`front_rows`) of the constants and the references."""
    config = cell_config(severity, traffic)
    train, selection, held_out = plan.seeds()
    levels = config.setting_levels
    n_levels = len(levels)
    constants_sel, _ = pair_terms(config, selection, [(level, level) for level in range(n_levels)], backend)
    constants_held, collided_held = pair_terms(config, held_out, [(level, level) for level in range(n_levels)], backend)
    pairs = [(up, down) for up in range(n_levels) for down in range(n_levels)]
    pairs_sel, _ = pair_terms(config, selection, pairs, backend)
    tables = lookup_tables(config, train, backend)
    stability = [StabilityOracle(config, margin) for margin in MARGINS]
    stability_sel = backend.map(oracle_terms, [(config, selection, oracle) for oracle in stability])
    stability_held = backend.map(oracle_terms, [(config, held_out, oracle) for oracle in stability])
    rows, fronts = [], []
    for name, weighting in WEIGHTINGS.items():
        blind = int(np.argmax(weigh(constants_sel, weighting).mean(axis=1)))
        blind_return = weigh(constants_held[blind], weighting)
        up, down = pairs[int(np.argmax(weigh(pairs_sel, weighting).mean(axis=1)))]
        pair_held = pair_terms(config, held_out, [(up, down)], backend)
        lookups = [LookupOracle(tables[name], config), LookupOracle(tables[name], config, whole_episode=True)]
        lookup_sel = backend.map(oracle_terms, [(config, selection, oracle) for oracle in lookups])
        lookup_held = backend.map(oracle_terms, [(config, held_out, oracle) for oracle in lookups])
        candidates = list(zip([*stability, *lookups], [*stability_sel, *lookup_sel], [*stability_held, *lookup_held]))
        best = int(np.argmax([weigh(sel[0], weighting).mean() for _, sel, _ in candidates]))
        oracle, _, oracle_held = candidates[best]
        hindsight = np.argmax(weigh(constants_held, weighting), axis=0), np.arange(len(held_out))
        reference_terms = {"v2v_pair": pair_held[0][0], "degradation_aware": oracle_held[0],
                           "hindsight": constants_held[hindsight]}
        references = {
            "v2v_pair": (f"{levels[up]:g} s up / {levels[down]:g} s down", weigh(pair_held[0][0], weighting),
                         pair_held[1][0]),
            "degradation_aware": (f"{oracle.name}", weigh(oracle_held[0], weighting), oracle_held[1]),
            "hindsight": ("best constant per episode", weigh(constants_held[hindsight], weighting),
                          collided_held[hindsight]),
        }
        fronts += front_rows(constants_held, reference_terms, levels,
                             {"weighting": name, "severity": severity, "traffic": traffic})
        blind_mean = float(blind_return.mean())
        row: dict[str, Any] = {"weighting": name, "severity": severity, "traffic": traffic, "best_blind": f"{levels[blind]:g} s",
               "best_blind_return": blind_mean, "best_blind_collisions": int(collided_held[blind].sum()),
               "episodes": len(held_out)}
        for reference, (chosen, returns, collided) in references.items():
            mean, low, high = bootstrap_mean(returns - blind_return)
            row |= {f"{reference}_chosen": chosen, f"{reference}_gain": mean, f"{reference}_gain_low": low,
                    f"{reference}_gain_high": high, f"{reference}_share": mean / abs(blind_mean),
                    f"{reference}_collisions": int(np.sum(collided))}
        row["meets_target"] = bool(row["degradation_aware_share"] >= TARGET_SHARE and row["degradation_aware_gain_low"] > 0
                                   and row["best_blind_collisions"] <= MAX_BLIND_COLLISION_RATE * len(held_out))
        rows.append(row)
    return rows, fronts


def task_map(plan: Plan = Plan(), backend: Backend | None = None) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """Every cell's rows and Pareto points (:func:`map_cell`): weightings x severities x traffic mixes."""
    backend = backend or Backend()
    rows, fronts = [], []
    for severity in SEVERITIES:
        for traffic in TRAFFIC:
            cell_rows, cell_fronts = map_cell(severity, traffic, plan, backend)
            rows += cell_rows
            fronts += cell_fronts
    return rows, fronts


def choose_default(rows: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """The criterion of docs/task.md: on the default severity and traffic, the weighting whose degradation-aware
    oracle gains the largest share over the best blind constant (its row, with ``meets_target``)."""
    candidates = [row for row in rows if row["severity"] == "default" and row["traffic"] == "default"]
    return max(candidates, key=lambda row: row["degradation_aware_share"])


__all__ = ["FRONT_OBJECTIVES", "MAX_BLIND_COLLISION_RATE", "REFERENCES", "SEVERITIES", "TARGET_SHARE", "TRAFFIC", "WEIGHTINGS", "Plan",
           "cell_config", "choose_default", "front_rows", "hypervolume", "map_cell", "task_map", "weigh"]
