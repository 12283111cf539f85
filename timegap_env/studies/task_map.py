"""The map of where reading the monitor can pay, and the default task's headroom (issue 24; the criterion is in
``docs/task.md``).

For each defensible weighting of the reward terms (:data:`WEIGHTINGS`), each degradation severity
(:data:`SEVERITIES`) and each traffic mix (:data:`TRAFFIC`), and for ``TimeGapMonitor-v1`` itself: the gap on
held-out seeds from the best blind constant (chosen on selection seeds) to each reference that knows more:

- ``v2v_pair``: one constant while every V2V flag is up, another while any is down (chosen on selection seeds);
- ``regime_aware``: per regime of the leader (its family, or the regime now of a leader whose traffic changes), the
  constant best on training seeds (:class:`~timegap_env.agents.oracles.RegimeOracle`);
- ``degradation_aware``: of the lookup oracles (per true condition, the constant best on training seeds) and the
  stability oracles (smallest string-stable setting + a margin), the best on selection seeds;
- ``full_oracle``: knows the regime and the degradation: of the degradation-aware candidates, the regime-aware one
  and the regime-aware one raised to each degradation-aware candidate's setting, the best on selection seeds;
- ``hindsight``: per held-out episode, the best constant for it.

A weighting only reweights the episode's reward terms, so every constant runs once per cell and is scored under
every weighting afterwards; the references whose choices depend on the weighting run once per weighting. Every
episode runs through the rollout harness; the seeds of each step are fixed below (training 0..,
selection from ``SELECTION_SEED_START``, held-out from ``EVAL_SEED_START``).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from timegap_env.agents.oracles import LookupOracle, RegimeOracle, StabilityOracle, TruthPolicy
from timegap_env.agents.protocol import EVAL_SEED_START
from timegap_env.config import REWARD_PRESETS, EnvConfig, RewardPreset
from timegap_env.envs.reward import REWARD_TERMS
from timegap_env.leaders.scenarios import LEADER_FAMILIES, SCENARIOS, family_params
from timegap_env.experiments.backends import Backend
from timegap_env.experiments.rollout import rollout
from timegap_env.tasks import LARGER_DEGRADATIONS, get_task
from timegap_env.experiments.stats import bootstrap_mean
from timegap_env.studies.value import (
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
REFERENCES = ("v2v_pair", "regime_aware", "degradation_aware", "full_oracle", "hindsight")
FRONT_OBJECTIVES = ("efficiency", "string_stability", "tracking")  # capacity, string stability, time-gap variation:
# the reward terms (each summed over the episode, higher is better) whose Pareto fronts the map compares
RECIPE_SEED_START = 6_000  # seeds that choose among learned recipes (train.evaluate_task --split selection) [-]
TARGET_SHARE = 0.15  # the criterion: the degradation-aware oracle (the issue: the full oracle) beats the best blind
# constant by this share [-]
MAX_BLIND_COLLISION_RATE = 0.01  # ... with the best blind constant colliding in at most this share of episodes [-]


@dataclasses.dataclass(frozen=True)
class Plan:
    """How many episodes each step uses, and so which seeds."""

    train: int = 16  # per pinned condition, for the lookup tables: seeds 0..train-1
    selection: int = 32  # seeds from SELECTION_SEED_START: the choices (best blind constant, pair, oracle)
    held_out: int = 100  # seeds from held_out_start: every number of the map
    held_out_start: int = EVAL_SEED_START  # RECIPE_SEED_START: the recipe-selection seeds stand in for the held-out

    def seeds(self) -> tuple[list[int], list[int], list[int]]:
        """Training, selection and held-out (or recipe-selection) seeds, disjoint."""
        if self.held_out_start not in (EVAL_SEED_START, RECIPE_SEED_START):
            raise ValueError(f"held_out_start = {self.held_out_start}: must be {EVAL_SEED_START} (held out) or "
                             f"{RECIPE_SEED_START} (recipe selection)")
        limits = {"train": SELECTION_SEED_START, "selection": RECIPE_SEED_START - SELECTION_SEED_START,
                  "held_out": EVAL_SEED_START - RECIPE_SEED_START if self.held_out_start == RECIPE_SEED_START else 10**6}
        for name, limit in limits.items():
            if not 1 <= getattr(self, name) <= limit:
                raise ValueError(f"{name} = {getattr(self, name)}: must be in [1, {limit}] (the seeds of each step must "
                                 "not reach the next step's)")
        train = list(range(self.train))
        selection = list(range(SELECTION_SEED_START, SELECTION_SEED_START + self.selection))
        held_out = list(range(self.held_out_start, self.held_out_start + self.held_out))
        return train, selection, held_out


def cell_config(severity: str, traffic: str) -> EnvConfig:
    """The env config of one cell of the map (v0's defaults otherwise, the regimes in the info); ``ValueError`` naming
    an unknown one."""
    for name, value, known in (("severity", severity, SEVERITIES), ("traffic", traffic, TRAFFIC)):
        if value not in known:
            raise ValueError(f"{name} = {value!r}: unknown; known: {list(known)}")
    default = EnvConfig()
    return default.with_overrides({"degradation": default.degradation.with_overrides(SEVERITIES[severity]),
                                   "scenario_weights": TRAFFIC[traffic]})


def regime_contexts(config: EnvConfig) -> dict[str, tuple[EnvConfig, dict[str, Any]]]:
    """Each regime the leaders of ``config`` can be in (a name of ``regime_names()``) and how to run it alone:
    (config, reset options). A family is one regime; a family with regimes runs each of its weighted regimes alone
    (its params' ``regime_weights`` pinned to that one); degradations are drawn as the mix draws them."""
    contexts: dict[str, tuple[EnvConfig, dict[str, Any]]] = {}
    params = family_params(config.leader_params)
    for scenario, weight in config.scenario_weights.items():
        name = SCENARIOS[scenario].leader_family  # an alias ("paper") is its family's regime
        family = LEADER_FAMILIES[name]
        if weight <= 0:
            continue
        if not family.regimes:
            contexts[name] = (config, {"scenario": name})
            continue
        weights = getattr(params.get(name) or (family.params and family.params()), "regime_weights", None)
        if not isinstance(weights, Mapping):
            raise ValueError(f"leader family {name!r} names regimes but its params have no regime_weights: the map "
                             "cannot run one of its regimes alone")
        for regime in family.regimes:
            if weights.get(regime, 0.0) > 0:
                pinned = {**config.leader_params.get(name, {}), "regime_weights": {regime: 1.0}}
                contexts[f"{name}:{regime}"] = (config.with_overrides({"leader_params": {**config.leader_params,
                                                                                            name: pinned}}),
                                                {"scenario": name})
    return contexts


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


def best_constant_tables(config: EnvConfig, cases: dict[str, tuple[EnvConfig, dict[str, Any]]], train: Sequence[int],
                         weightings: dict[str, RewardPreset], backend: Backend) -> dict[str, dict[str, float]]:
    """Per weighting, a table: per case of ``cases`` (key -> (config, reset options)), the ladder constant [s] best on
    ``train`` seeds."""
    n_levels = len(config.setting_levels)
    scored = {key: pair_terms(case_config, train, [(level, level) for level in range(n_levels)], backend, options)[0]
              for key, (case_config, options) in cases.items()}
    return {name: {key: float(config.setting_levels[int(np.argmax(weigh(terms, weighting).mean(axis=1)))])
                   for key, terms in scored.items()} for name, weighting in weightings.items()}


def lookup_tables(config: EnvConfig, train: Sequence[int], weightings: dict[str, RewardPreset],
                  backend: Backend) -> dict[str, dict[str, float]]:
    """Per weighting, the lookup oracle's table: per pinned condition, the constant best on ``train`` seeds."""
    return best_constant_tables(config, training_conditions(config), train, weightings, backend)


def regime_tables(config: EnvConfig, train: Sequence[int], weightings: dict[str, RewardPreset],
                  backend: Backend) -> dict[str, dict[str, float]]:
    """Per weighting, the regime-aware oracle's table: per regime (:func:`regime_contexts`), the constant best on
    ``train`` seeds."""
    return best_constant_tables(config, regime_contexts(config), train, weightings, backend)


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
    """The rows of one cell of the map under every weighting (:func:`cell_rows`)."""
    rows, fronts, _ = cell_rows(cell_config(severity, traffic), {"severity": severity, "traffic": traffic}, WEIGHTINGS,
                                plan, backend)
    return rows, fronts


@dataclasses.dataclass(frozen=True)
class References:
    """What one weighting chooses on training and selection seeds: the best blind constant and the references."""

    blind: int  # the best blind constant's ladder index
    pair: tuple[int, int]  # the V2V pair's ladder indices: V2V up, V2V down
    regime_aware: TruthPolicy
    degradation_aware: TruthPolicy
    full_oracle: TruthPolicy  # one of the candidates, maybe one of the two above


def choose_references(config: EnvConfig, weightings: dict[str, RewardPreset], train: Sequence[int],
                      selection: Sequence[int], backend: Backend) -> dict[str, References]:
    """Per weighting, the best blind constant and the references of the module's docstring, their tables built on
    ``train`` seeds and every choice made on ``selection`` seeds (``config`` must put the regime in the info)."""
    n_levels = len(config.setting_levels)
    constants_sel, _ = pair_terms(config, selection, [(level, level) for level in range(n_levels)], backend)
    pairs = [(up, down) for up in range(n_levels) for down in range(n_levels)]
    pairs_sel, _ = pair_terms(config, selection, pairs, backend)
    tables = lookup_tables(config, train, weightings, backend)
    regimes = regime_tables(config, train, weightings, backend)
    stability = [StabilityOracle(config, margin) for margin in MARGINS]
    stability_sel = backend.map(oracle_terms, [(config, selection, oracle) for oracle in stability])
    chosen = {}
    for name, weighting in weightings.items():
        lookups = [LookupOracle(tables[name], config), LookupOracle(tables[name], config, whole_episode=True)]
        lookup_sel = backend.map(oracle_terms, [(config, selection, oracle) for oracle in lookups])
        knowing = [*stability, *lookups]  # the degradation-aware candidates
        regime_aware = RegimeOracle(regimes[name], config)
        combined = [RegimeOracle(regimes[name], config, floor) for floor in knowing]
        regime_sel = backend.map(oracle_terms, [(config, selection, oracle) for oracle in [regime_aware, *combined]])
        scores = [float(weigh(terms, weighting).mean()) for terms, _ in [*stability_sel, *lookup_sel, *regime_sel]]
        chosen[name] = References(
            blind=int(np.argmax(weigh(constants_sel, weighting).mean(axis=1))),
            pair=pairs[int(np.argmax(weigh(pairs_sel, weighting).mean(axis=1)))],
            regime_aware=regime_aware, degradation_aware=knowing[int(np.argmax(scores[: len(knowing)]))],
            full_oracle=[*knowing, regime_aware, *combined][int(np.argmax(scores))])
    return chosen


def cell_rows(config: EnvConfig, cell: dict[str, Any], weightings: dict[str, RewardPreset], plan: Plan,
              backend: Backend, policies: Mapping[str, Any] | None = None, baseline: str | None = None
              ) -> tuple[list[dict[str, Any]], list[dict[str, Any]], list[dict[str, Any]]]:
    """Per weighting, the best blind constant and each reference (:func:`choose_references`) on the held-out seeds of
    ``config`` (a row that starts with ``cell``'s entries; each gain also without the collision term, which one
    episode can dominate); per weighting, the Pareto points (:func:`front_rows`) of the constants and the references;
    and per weighting and policy of ``policies`` (name -> any policy the rollout harness plays), a row of its gain
    over the best blind constant on the same held-out episodes, the share of the full oracle's gain it captures and
    its mean FRONT_OBJECTIVES (and, with ``baseline`` one of their names, its gain over that policy, paired).
    the harness's env puts the regime in the info (info layout "v1")."""
    train, selection, held_out = plan.seeds()
    levels = config.setting_levels
    n_levels = len(levels)
    references = choose_references(config, weightings, train, selection, backend)
    constants_held, collided_held = pair_terms(config, held_out, [(level, level) for level in range(n_levels)], backend)
    policies = dict(policies or {})
    policies_held = dict(zip(policies, backend.map(term_sums, [(config, held_out, policy) for policy in policies.values()])))
    rows, fronts, policy_rows = [], [], []
    for name, weighting in weightings.items():
        blind, (up, down) = references[name].blind, references[name].pair
        blind_return = weigh(constants_held[blind], weighting)
        pair_held = pair_terms(config, held_out, [(up, down)], backend)
        chosen = {key: getattr(references[name], key) for key in ("regime_aware", "degradation_aware", "full_oracle")}
        unique = list(dict.fromkeys(chosen.values()))  # the full oracle may be one of the others
        held = dict(zip(unique, backend.map(oracle_terms, [(config, held_out, oracle) for oracle in unique])))
        hindsight = np.argmax(weigh(constants_held, weighting), axis=0), np.arange(len(held_out))
        reference_terms = {"v2v_pair": pair_held[0][0], **{key: held[oracle][0] for key, oracle in chosen.items()},
                           "hindsight": constants_held[hindsight]}
        reference_collided = {"v2v_pair": pair_held[1][0], **{key: held[oracle][1] for key, oracle in chosen.items()},
                              "hindsight": collided_held[hindsight]}
        described = {"v2v_pair": f"{levels[up]:g} s up / {levels[down]:g} s down", "hindsight": "best constant per episode",
                     **{key: oracle.name for key, oracle in chosen.items()}}
        fronts += front_rows(constants_held, reference_terms, levels, {"weighting": name, **cell})
        blind_mean = float(blind_return.mean())
        row: dict[str, Any] = {"weighting": name, **cell, "best_blind": f"{levels[blind]:g} s",
                               "best_blind_return": blind_mean, "best_blind_collisions": int(collided_held[blind].sum()),
                               "episodes": len(held_out)}
        no_collision = dataclasses.replace(weighting, weights=weighting.weights.with_overrides({"collision": 0.0}))
        for reference in REFERENCES:
            mean, low, high = bootstrap_mean(weigh(reference_terms[reference], weighting) - blind_return)
            rest = bootstrap_mean(weigh(reference_terms[reference], no_collision)
                                  - weigh(constants_held[blind], no_collision))
            row |= {f"{reference}_chosen": described[reference], f"{reference}_gain": mean,
                    f"{reference}_gain_low": low, f"{reference}_gain_high": high,
                    f"{reference}_share": mean / abs(blind_mean),
                    f"{reference}_collisions": int(np.sum(reference_collided[reference])),
                    **dict(zip([f"{reference}_gain_without_collisions{end}" for end in ("", "_low", "_high")], rest))}
        blind_safe = row["best_blind_collisions"] <= MAX_BLIND_COLLISION_RATE * len(held_out)
        for key, reference in (("meets_target", "degradation_aware"), ("full_oracle_meets_target", "full_oracle")):
            row[key] = bool(row[f"{reference}_share"] >= TARGET_SHARE and row[f"{reference}_gain_low"] > 0 and blind_safe)
        rows.append(row)
        for policy, (terms, collided) in policies_held.items():
            returns = weigh(terms, weighting)
            mean, low, high = bootstrap_mean(returns - blind_return)
            gap = row["full_oracle_gain"]
            rest = bootstrap_mean(weigh(terms, no_collision) - weigh(constants_held[blind], no_collision))
            policy_row = {"weighting": name, **cell, "policy": policy, "return": float(returns.mean()),
                          "gain": mean, "gain_low": low, "gain_high": high,
                          "share_of_oracle_gain": mean / gap if gap > 0 else math.nan,
                          "collisions": int(collided.sum()), "episodes": len(held_out),
                          **dict(zip([f"gain_without_collisions{end}" for end in ("", "_low", "_high")], rest)),
                          **{objective: float(terms[:, REWARD_TERMS.index(objective)].mean())
                             for objective in FRONT_OBJECTIVES}}
            if baseline is not None:
                versus = bootstrap_mean(returns - weigh(policies_held[baseline][0], weighting))
                policy_row |= dict(zip(("gain_over_baseline", "gain_over_baseline_low", "gain_over_baseline_high"),
                                       versus))
            policy_rows.append(policy_row)
    return rows, fronts, policy_rows


V1_CELL = {"severity": "default", "traffic": "v1"}  # how TimeGapMonitor-v1's rows name their cell
V1_GROUPS: dict[str, dict[str, Any]] = {  # the held-out groups on v1's task: EnvConfig overrides of v1's defaults
    "v1": {},  # v1's own mix
    "larger_degradations": {"degradation": LARGER_DEGRADATIONS},  # every episode degraded beyond the training ranges
    "regimes": {"scenario_weights": {"regimes": 1.0}},  # traffic that changes within every episode
    "ngsim_in_band": {"scenario_weights": {"ngsim_in_band": 1.0}},  # real drivers (NGSIM I-80 data)
    "openacc": {"scenario_weights": {"openacc": 1.0}},  # real lead cars (OpenACC data)
    "idm": {"scenario_weights": {"idm": 1.0}},  # highway-env's IDM driver behind scripted braking
    "stop_and_go": {"scenario_weights": {"stop_and_go": 1.0}},  # harsh families the training never saw
    "emergency_braking": {"scenario_weights": {"emergency_braking": 1.0}},
}


def v1_headroom(plan: Plan = Plan(), backend: Backend | None = None, policies: Mapping[str, Any] | None = None,
                baseline: str | None = None, group: str = "v1"
                ) -> tuple[list[dict[str, Any]], list[dict[str, Any]], list[dict[str, Any]]]:
    """``TimeGapMonitor-v1``'s own row (its weighting), Pareto points and ``policies``' rows on ``group``
    (:data:`V1_GROUPS`; its references measured on that group's own training and selection seeds), as a cell of
    the map (:func:`cell_rows`); ``ValueError`` naming an unknown group."""
    if group not in V1_GROUPS:
        raise ValueError(f"group = {group!r}: unknown; known: {list(V1_GROUPS)}")
    task = get_task("TimeGapMonitor-v1")
    config = task.config(V1_GROUPS[group])
    weighting = task.overrides["reward_weights"]
    assert WEIGHTINGS[weighting].weights == config.reward_weights
    cell = V1_CELL if group == "v1" else {**V1_CELL, "traffic": group}
    return cell_rows(config, cell, {weighting: WEIGHTINGS[weighting]}, plan, backend or Backend(), policies, baseline)


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


__all__ = ["FRONT_OBJECTIVES", "MAX_BLIND_COLLISION_RATE", "RECIPE_SEED_START", "REFERENCES", "SEVERITIES", "TARGET_SHARE", "TRAFFIC", "V1_CELL", "V1_GROUPS",
           "WEIGHTINGS", "Plan", "References", "cell_config", "cell_rows", "choose_default", "choose_references", "front_rows", "hypervolume", "map_cell",
           "regime_contexts", "task_map", "v1_headroom", "weigh"]
