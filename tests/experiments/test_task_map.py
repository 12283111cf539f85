"""The map of issue 24: its post-hoc weighting is the env's reward, its seeds are disjoint, its references behave."""

from __future__ import annotations

import numpy as np
import pytest

from timegap_env.agents.oracles import LookupOracle, RegimeOracle, StabilityOracle, size_bin
from timegap_env.config import EnvConfig
from timegap_env.envs.info import truth_of
from timegap_env.experiments.backends import Backend
from timegap_env.experiments.rollout import rollout
from timegap_env.studies.task_map import (
    REFERENCES, SEVERITIES, TRAFFIC, V1_CELL, WEIGHTINGS, Plan, cell_config, choose_default, hypervolume, map_cell,
    regime_contexts, term_sums, v1_headroom, weigh,
)
from timegap_env.leaders.regimes import REGIMES


def constant(level: int):
    return lambda obs, infos: np.full(len(obs), level)


@pytest.mark.parametrize("name", sorted(WEIGHTINGS))
def test_weighing_the_terms_afterwards_is_the_env_s_reward_under_that_weighting(name):
    weighting = WEIGHTINGS[name]
    config = cell_config("default", "default").with_overrides({"episode_duration": 40.0})
    terms, _ = term_sums(config, [5, 6, 7], constant(2))
    weighted = config.with_overrides({"reward_weights": weighting.weights})
    returns = [record.episode_return for record in rollout(constant(2), weighted, [5, 6, 7]).records]
    np.testing.assert_allclose(weigh(terms, weighting), returns, rtol=1e-9, atol=1e-9)


def test_the_seeds_of_each_step_are_disjoint():
    train, selection, held_out = Plan(train=16, selection=32, held_out=100).seeds()
    assert not (set(train) & set(selection)) and not (set(selection) & set(held_out)) and not (set(train) & set(held_out))
    assert min(held_out) == 10_000


def test_every_cell_is_a_valid_config_and_unknown_ones_are_named():
    for severity in SEVERITIES:
        for traffic in TRAFFIC:
            assert isinstance(cell_config(severity, traffic), EnvConfig)
    with pytest.raises(ValueError, match="severity = 'mild'"):
        cell_config("mild", "default")
    with pytest.raises(ValueError, match="traffic = 'jam'"):
        cell_config("default", "jam")


def test_a_cell_gives_every_weighting_and_reference_and_hindsight_never_loses():
    rows, fronts = map_cell("default", "default", Plan(train=2, selection=3, held_out=4), Backend())
    assert [row["weighting"] for row in rows] == list(WEIGHTINGS)
    for row in rows:
        for reference in REFERENCES:
            assert row[f"{reference}_gain_low"] <= row[f"{reference}_gain"] <= row[f"{reference}_gain_high"]
        assert row["hindsight_gain_low"] >= 0  # the best constant per episode includes the blind one
        assert isinstance(row["meets_target"], bool)
    chosen = choose_default(rows)
    assert chosen["degradation_aware_share"] == max(row["degradation_aware_share"] for row in rows)
    assert len(fronts) == len(WEIGHTINGS) * (len(EnvConfig().setting_levels) + len(REFERENCES))
    for front in fronts:  # adding a point never loses volume
        assert front["hypervolume"] >= front["constants_hypervolume"] - 1e-12


def test_hypervolume_of_known_boxes():
    origin = np.zeros(3)
    assert hypervolume(np.array([[1.0, 1.0, 1.0]]), origin) == pytest.approx(1.0)
    two = np.array([[1.0, 0.5, 0.5], [0.5, 1.0, 1.0]])  # 0.25 + 0.5 - their overlap 0.125
    assert hypervolume(two, origin) == pytest.approx(0.625)
    assert hypervolume(np.vstack([two, [[0.4, 0.4, 0.4]]]), origin) == pytest.approx(0.625)  # a dominated point adds 0
    rng = np.random.default_rng(0)
    points = rng.uniform(0, 1, (6, 3))
    samples = rng.uniform(0, 1, (200_000, 3))
    dominated = (samples[:, None, :] <= points[None, :, :]).all(axis=2).any(axis=1).mean()
    assert hypervolume(points, origin) == pytest.approx(dominated, abs=0.01)


def test_each_regime_context_runs_that_regime_alone():
    config = cell_config("default", "changing")
    contexts = regime_contexts(config)
    assert list(contexts) == [f"regimes:{regime}" for regime in REGIMES]
    for key, (context_config, options) in contexts.items():
        seen: set[str] = set()

        def note_regime(obs, infos):
            seen.update(truth_of(infos)["regime"].tolist())
            return np.full(len(obs), 5)

        records = rollout(note_regime, context_config.with_overrides({"episode_duration": 60.0}), [0, 1], options).records
        assert all(record.scenario == "regimes" for record in records) and seen == {key}
    assert list(regime_contexts(cell_config("default", "default"))) == list(EnvConfig().scenario_weights)


def test_regime_oracle_reads_the_regime_and_raises_to_its_floor():
    config = cell_config("default", "changing")
    table = {f"regimes:{regime}": 0.8 for regime in REGIMES}
    truth = {"regime": np.array(["regimes:free_flow", "regimes:stop_and_go"], dtype=object),
             "kind": np.array([["none", "lag"], ["none", "none"]], dtype=object),
             "size": np.array([[0.0, 0.9], [0.0, 0.0]]), "active": np.ones((2, 2), dtype=bool),
             "smallest_stable_setting": np.array([[0.5, 1.5], [0.5, 0.5]])}
    levels = np.asarray(config.setting_levels)
    assert np.array_equal(RegimeOracle(table, config).act(truth), np.searchsorted(levels, [0.8, 0.8]))
    floored = RegimeOracle(table, config, StabilityOracle(config, 0.1)).act(truth)
    assert np.array_equal(levels[floored], [1.6, 0.8])  # the lagging car needs 1.5 + 0.1 s
    lag_key = f"lag:{size_bin('lag', 0.9, config.degradation)}"
    lookup = RegimeOracle(table, config, LookupOracle({"none": 2.2, lag_key: 2.0}, config))
    assert np.array_equal(levels[lookup.act(truth)], [2.0, 0.8])  # the lookup's nominal entry does not raise it
    with pytest.raises(KeyError, match="regimes:free_flow"):
        RegimeOracle({"regimes:stop_and_go": 1.0}, config).act(truth)
    with pytest.raises(KeyError, match="info layout 'v1'"):
        RegimeOracle(table, config).act({key: value for key, value in truth.items() if key != "regime"})


def test_v1_headroom_is_a_row_of_its_own_weighting():
    rows, fronts, policy_rows = v1_headroom(Plan(train=1, selection=2, held_out=3), policies={"fixed_1.0": constant(2)})
    assert len(rows) == 1 and rows[0]["weighting"] == "variation_first"
    assert {key: rows[0][key] for key in V1_CELL} == V1_CELL
    for reference in REFERENCES:
        assert rows[0][f"{reference}_gain_low"] <= rows[0][f"{reference}_gain"] <= rows[0][f"{reference}_gain_high"]
    assert isinstance(rows[0]["full_oracle_meets_target"], bool) and fronts
    assert [row["policy"] for row in policy_rows] == ["fixed_1.0"]
    if rows[0]["best_blind"] == "1 s":  # the same constant: no gain
        assert policy_rows[0]["gain"] == 0 and policy_rows[0]["return"] == rows[0]["best_blind_return"]


def test_an_alias_is_its_family_s_regime_and_bad_counts_are_named():
    config = cell_config("default", "default").with_overrides({"scenario_weights": {"paper": 1.0}})
    assert list(regime_contexts(config)) == ["aggressive_cycles"]
    with pytest.raises(ValueError, match="selection = 2000: must be in"):
        Plan(selection=2000).seeds()
