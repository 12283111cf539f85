"""Reward kernels: step_readouts, reward_terms, weighted_sum and score_step against NumPy references of their documented formulas."""

from __future__ import annotations

import dataclasses
import re

import numpy as np
import pytest

from timegap_env.config import REWARD_SCALE_RECORDS, REWARD_TERM_RECORDS, EnvConfig, RewardScales, RewardWeights
from timegap_env.envs import reward
from timegap_env.envs.reward import (
    COST_TERMS,
    OBJECTIVES,
    REWARD_TERMS,
    RewardConstants,
    RewardTerms,
    StepReadouts,
    StepTicks,
    reward_terms,
    score_step,
    step_readouts,
    term_lows,
    weighted_sum,
    weights_of,
)

CONFIG = EnvConfig()
CONSTANTS = RewardConstants.from_config(CONFIG)
LEVELS = np.array(CONFIG.setting_levels)
DT = CONFIG.platoon.dt
N_TICKS, N_ENVS = 10, 4
COLLIDING_ENV = 2  # the only env with a collision
NEVER_CLOSING = (0, 1)  # (env, follower) always slower than its predecessor


def random_step(seed: int, n_followers: int = 5):
    """A step's ticks, the acceleration before them, the settings at its end and which changed."""
    rng = np.random.default_rng(seed)
    shape = (N_TICKS, N_ENVS, n_followers)
    leader_speed = rng.uniform(10.0, 35.0, (N_TICKS, N_ENVS))
    speed = leader_speed[..., None] + rng.normal(0.0, 2.0, shape)
    speed = np.where(rng.random(shape) < 0.1, rng.uniform(0.0, 1.0, shape), speed)  # some below 1 m/s: not tracked
    env, follower = NEVER_CLOSING
    speed[:, env, follower] = speed[:, env, follower - 1] - rng.uniform(0.1, 1.0, N_TICKS)
    collisions = np.zeros(shape, dtype=bool)
    collisions[rng.integers(N_TICKS), COLLIDING_ENV, rng.integers(n_followers)] = True
    step = StepTicks(
        tau_mean=rng.normal(1.6, 0.3, shape),
        center=rng.uniform(LEVELS[0], LEVELS[-1], shape),
        applied_setting=rng.uniform(LEVELS[0], LEVELS[-1], shape),
        alarm=rng.random(shape) < 0.3,
        exceedance=rng.random(shape) < 0.1,
        collisions=collisions,
        leader_speed=leader_speed,
        leader_accel=rng.normal(0.0, 1.0, (N_TICKS, N_ENVS)),
        speed=speed,
        spacing=rng.uniform(1.0, 40.0, shape),
        accel=rng.normal(0.0, 1.5, shape),
    )
    previous_accel = rng.normal(0.0, 1.5, (N_ENVS, n_followers))
    setting = rng.choice(LEVELS, (N_ENVS, n_followers))
    changed = rng.random((N_ENVS, n_followers)) < 0.4
    return step, previous_accel, setting, changed


def envelope_before(n_followers: int = 5) -> np.ndarray:
    """Acceleration envelopes before a step, the leader first (fresh each call: the kernels update them in place)."""
    return np.random.default_rng(99).uniform(0.0, 2.0, (N_ENVS, n_followers + 1))


def reference_readouts(step: StepTicks, previous_accel: np.ndarray, dt: float, c: RewardConstants = CONSTANTS) -> StepReadouts:
    envelope = envelope_before(step.speed.shape[2])
    accel = np.concatenate([step.leader_accel[..., None], step.accel], axis=-1)
    for k in range(len(accel)):
        envelope = np.maximum(np.abs(accel[k]), envelope * c.envelope_decay)
    with np.errstate(divide="ignore", invalid="ignore"):
        gap = (step.spacing - c.standstill_spacing) / step.speed
    gap_deviation = np.where(step.speed >= 1.0, np.minimum(np.abs(gap - step.applied_setting), c.tracking_cap), 0.0)
    predecessor_speed = np.concatenate([step.leader_speed[..., None], step.speed[..., :-1]], axis=-1)
    closing = step.speed - predecessor_speed
    with np.errstate(divide="ignore"):
        ttc = np.where(closing > 0, step.spacing / closing, np.inf)
    jerk = np.diff(np.concatenate([previous_accel[None], step.accel]), axis=0) / dt
    deviation = np.abs(step.tau_mean - step.center)
    return StepReadouts(
        min_ttc=ttc.min(axis=0),
        jerk_squared=(jerk**2).sum(axis=0),
        final_speed=step.speed[-1],
        accel_growth=np.maximum(0.0, np.diff(envelope, axis=1)).sum(axis=1),
        gap_deviation_sum=gap_deviation.sum(axis=(0, 2)),
        deviation_sum=deviation.sum(axis=(0, 2)),
        max_deviation=deviation.max(axis=(0, 2)),
        alarm_ticks=step.alarm.sum(axis=(0, 2)).astype(float),
        exceedances=step.exceedance.sum(axis=(0, 2)).astype(float),
        collided=step.collisions.any(axis=(0, 2)),
    )


def reference_terms(readouts: StepReadouts, setting, changed, c: RewardConstants) -> dict[str, np.ndarray]:
    n_followers = setting.shape[1]
    v = readouts.final_speed
    capacity_ratio = (v * c.smallest_level + c.gap_per_vehicle) / (v * setting + c.gap_per_vehicle)
    return {
        "tracking": -readouts.gap_deviation_sum / (c.ticks_per_step * n_followers) / c.tracking_reference,
        "string_stability": -np.minimum(1.0, readouts.accel_growth / c.accel_growth_reference),
        "safety": -np.mean(np.maximum(0.0, 1.0 - readouts.min_ttc / c.ttc_threshold), axis=1),
        "collision": -readouts.collided.astype(float),
        "comfort": -np.mean(readouts.jerk_squared / c.ticks_per_step, axis=1) / c.jerk_reference**2,
        "efficiency": -np.mean(1.0 - capacity_ratio, axis=1),
        "preference": -np.mean(np.abs(setting - c.preferred_setting), axis=1) / c.level_span,
        "switching": -np.mean(changed, axis=1),
    }


@pytest.mark.parametrize(("seed", "n_followers"), [(0, 5), (1, 3), (2, 5)])
def test_step_readouts_match_the_numpy_reference(seed, n_followers):
    step, previous_accel, _, _ = random_step(seed, n_followers)
    readouts = step_readouts(step, previous_accel, envelope_before(), CONSTANTS)
    expected = reference_readouts(step, previous_accel, DT)
    for name, got, want in zip(StepReadouts._fields, readouts, expected):
        np.testing.assert_allclose(got, want, rtol=1e-12, err_msg=name)
    np.testing.assert_array_equal(readouts.collided, np.arange(N_ENVS) == COLLIDING_ENV)
    assert readouts.min_ttc[NEVER_CLOSING] == np.inf
    assert np.any(readouts.min_ttc < CONSTANTS.ttc_threshold)  # the safety term has something to score
    assert np.all(readouts.gap_deviation_sum > 0) and np.all(readouts.accel_growth > 0)


def test_the_first_tick_jerk_is_taken_against_the_previous_acceleration():
    step, previous_accel, _, _ = random_step(3)
    accel = np.ones_like(step.accel)
    readouts = step_readouts(step._replace(accel=accel), np.zeros_like(previous_accel), envelope_before(), CONSTANTS)
    np.testing.assert_allclose(readouts.jerk_squared, (1.0 / DT) ** 2, rtol=1e-12)  # only the first tick jerks


@pytest.mark.parametrize(("seed", "n_followers"), [(0, 5), (1, 3), (2, 5)])
def test_reward_terms_match_the_numpy_reference(seed, n_followers):
    step, previous_accel, setting, changed = random_step(seed, n_followers)
    readouts = reference_readouts(step, previous_accel, DT)
    terms = reward_terms(readouts, setting, changed, CONSTANTS)
    expected = reference_terms(readouts, setting, changed, CONSTANTS)
    assert terms._fields == REWARD_TERMS
    for name in REWARD_TERMS:
        np.testing.assert_allclose(getattr(terms, name), expected[name], rtol=1e-12, err_msg=name)
    np.testing.assert_array_equal(terms.collision, np.where(np.arange(N_ENVS) == COLLIDING_ENV, -1.0, 0.0))


@pytest.mark.parametrize("seed", range(5))
def test_reward_terms_are_never_positive(seed):
    step, previous_accel, setting, changed = random_step(seed)
    terms = reward_terms(step_readouts(step, previous_accel, envelope_before(), CONSTANTS), setting, changed, CONSTANTS)
    for name in REWARD_TERMS:
        assert np.all(getattr(terms, name) <= 0.0), name


def test_weights_of_the_default_config_are_the_reward_weights_in_field_order():
    names = tuple(field.name for field in dataclasses.fields(RewardWeights))
    assert REWARD_TERMS == names
    weights = weights_of(EnvConfig())
    assert isinstance(weights, RewardTerms)
    for name in names:
        assert getattr(weights, name) == getattr(RewardWeights(), name)
    custom = weights_of(EnvConfig.from_dict({"reward_weights": {"comfort": 0.3, "switching": 0.0}}))
    assert (custom.comfort, custom.switching, custom.collision) == (0.3, 0.0, 1000.0)


def test_reward_constants_come_from_the_config():
    config = EnvConfig.from_dict({"chart": {"limit_width": 3.0}, "setting_levels": [0.8, 1.2, 2.0],
                                  "reward_scales": {"ttc_threshold": 5.0},
                                  "platoon": {"standstill_spacing": 2.0, "initial_setting": 1.2}})
    constants = RewardConstants.from_config(config)
    assert constants.tracking_reference == config.reward_scales.tracking_reference  # the reward's own, not the chart's
    assert (constants.smallest_level, constants.level_span) == (0.8, pytest.approx(1.2, rel=1e-15))
    assert (constants.ttc_threshold, constants.gap_per_vehicle) == (5.0, 2.0 + config.platoon.vehicle_length)
    assert (constants.jerk_reference, constants.preferred_setting) == (config.reward_scales.jerk_reference, config.preferred_setting)


def test_what_a_term_touches_follows_its_record():
    """RewardWeights, RewardScales, REWARD_TERMS, OBJECTIVES, COST_TERMS, term_lows, the constants' scales and the
    module docstring's table are made of REWARD_TERM_RECORDS, in its order."""
    records = list(REWARD_TERM_RECORDS.values())
    weight_fields = tuple(field.name for field in dataclasses.fields(RewardWeights))
    assert REWARD_TERMS == tuple(REWARD_TERM_RECORDS) == weight_fields
    assert REWARD_TERMS[:3] == ("tracking", "string_stability", "safety") and REWARD_TERMS[-1] == "switching"
    assert dataclasses.astuple(RewardWeights()) == tuple(term.weight for term in records)
    scales = [scale for term in records for scale in term.scales]
    assert [field.name for field in dataclasses.fields(RewardScales)] == [scale.name for scale in scales]
    assert list(REWARD_SCALE_RECORDS.values()) == scales
    assert dataclasses.astuple(RewardScales()) == tuple(scale.default for scale in scales)
    assert OBJECTIVES == {term.name: term.objective for term in records}
    assert COST_TERMS == tuple(term.name for term in records if term.cost)
    assert COST_TERMS == ("string_stability", "safety", "collision")
    config = EnvConfig.from_dict({"reward_scales": {"tracking_cap": 1.0, "tracking_reference": 0.5}})
    assert term_lows(config) == {term.name: term.low(config.reward_scales) for term in records}
    assert term_lows(config)["tracking"] == -2.0 and term_lows(config)["safety"] == -np.inf
    constants = RewardConstants.from_config(config)
    assert {scale.name: getattr(constants, scale.name) for scale in scales} == dataclasses.asdict(config.reward_scales)
    for term in records:
        assert f"| ``{term.name}`` | {term.value} | {term.why} |" in (reward.__doc__ or "")
        assert f"{term.name} = {term.weight:g}" in (RewardWeights.__doc__ or "")
    for scale in scales:
        assert f"- {scale.name} = {scale.default:g} [{scale.unit}], {scale.bounds}: " in (RewardScales.__doc__ or "")


@pytest.mark.parametrize("scale", REWARD_SCALE_RECORDS.values(), ids=lambda scale: scale.name)
def test_a_scale_beyond_its_records_bounds_is_refused_naming_field_and_value(scale):
    bounds = scale.bounds
    for bad in (bounds.high * 2 + 1, bounds.low if bounds.open_low else bounds.low / 2 - 1):
        message = f"RewardScales.{scale.name} = {bad!r}: must be in {bounds}"
        with pytest.raises(ValueError, match=re.escape(message)):
            RewardScales(**{scale.name: bad})
        with pytest.raises(ValueError, match=re.escape(message)):
            EnvConfig.from_dict({"reward_scales": {scale.name: bad}})
    edge = bounds.high if not bounds.open_high else bounds.low
    assert getattr(RewardScales(**{scale.name: edge}), scale.name) == edge


@pytest.mark.parametrize("name", REWARD_TERMS)
def test_weighted_sum_with_a_one_hot_weight_picks_that_term(name):
    step, previous_accel, setting, changed = random_step(4)
    terms = reward_terms(step_readouts(step, previous_accel, envelope_before(), CONSTANTS), setting, changed, CONSTANTS)
    one_hot = RewardTerms(*(float(term == name) for term in REWARD_TERMS))
    np.testing.assert_array_equal(weighted_sum(terms, one_hot), getattr(terms, name))


@pytest.mark.parametrize("seed", range(3))
def test_weighted_sum_is_the_terms_times_their_weights(seed):
    step, previous_accel, setting, changed = random_step(seed)
    terms = reward_terms(step_readouts(step, previous_accel, envelope_before(), CONSTANTS), setting, changed, CONSTANTS)
    weights = weights_of(CONFIG)
    expected = np.sum(np.array(weights)[:, None] * np.array(terms), axis=0)
    np.testing.assert_allclose(weighted_sum(terms, weights), expected, rtol=1e-12)
    assert weighted_sum(terms, weights)[COLLIDING_ENV] < -CONFIG.reward_weights.collision + 1e-9


@pytest.mark.parametrize("env", range(N_ENVS))
def test_an_env_scores_the_same_alone_as_in_a_batch(env):
    step, previous_accel, setting, changed = random_step(5)
    alone = StepTicks(*(ticks[:, [env]] for ticks in step))
    weights = weights_of(CONFIG)
    batch_readouts = step_readouts(step, previous_accel, envelope_before(), CONSTANTS)
    alone_readouts = step_readouts(alone, previous_accel[[env]], envelope_before()[[env]], CONSTANTS)
    for batch_field, alone_field in zip(batch_readouts, alone_readouts):
        np.testing.assert_array_equal(alone_field, batch_field[[env]])
    batch_terms = reward_terms(batch_readouts, setting, changed, CONSTANTS)
    alone_terms = reward_terms(alone_readouts, setting[[env]], changed[[env]], CONSTANTS)
    for batch_term, alone_term in zip(batch_terms, alone_terms):
        np.testing.assert_array_equal(alone_term, batch_term[[env]])
    np.testing.assert_array_equal(weighted_sum(alone_terms, weights), weighted_sum(batch_terms, weights)[[env]])


@pytest.mark.parametrize("seed", range(3))
def test_score_step_is_the_three_steps_in_one_call(seed):
    step, previous_accel, setting, changed = random_step(seed)
    weights = weights_of(CONFIG)
    readouts = StepReadouts.empty(N_ENVS, 5)
    score = score_step(step, previous_accel, envelope_before(), setting, changed, CONSTANTS, weights, readouts)
    expected_readouts = step_readouts(step, previous_accel, envelope_before(), CONSTANTS)
    expected_terms = reward_terms(expected_readouts, setting, changed, CONSTANTS)
    for got, want in zip(readouts, expected_readouts):
        np.testing.assert_array_equal(got, want)
    for got, want in zip(score.terms, expected_terms):
        np.testing.assert_array_equal(got, want)
    np.testing.assert_array_equal(score.reward, weighted_sum(expected_terms, weights))
    # the cost: COST_TERMS' rows, each clipped to [-1, 0], summed in REWARD_TERMS order (bit for bit as written out)
    t = expected_terms
    np.testing.assert_array_equal(score.cost, 0.0 - (t.string_stability + np.maximum(-1.0, t.safety) + t.collision))


def test_a_static_offset_of_the_gaps_costs_no_string_stability():
    """Followers at different constant gaps (a biased radar keeps one closer) with no acceleration: no growth."""
    step, previous_accel, setting, changed = random_step(7)
    still = step._replace(accel=np.zeros_like(step.accel), leader_accel=np.zeros_like(step.leader_accel),
                          spacing=np.linspace(10.0, 40.0, 5) * np.ones_like(step.spacing))
    readouts = step_readouts(still, np.zeros_like(previous_accel), np.zeros((N_ENVS, 6)), CONSTANTS)
    assert np.all(reward_terms(readouts, setting, changed, CONSTANTS).string_stability == 0.0)
