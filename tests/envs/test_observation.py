"""Observation kernel: observe() against a NumPy reference of FEATURES, its space, and decode_observation()."""

from __future__ import annotations

import math

import numpy as np
import pytest

from timegap_env.config import EnvConfig
from timegap_env.envs.observation import (
    FEATURES,
    OBSERVATION_HIGH,
    OBSERVATION_LOW,
    FollowerState,
    FollowerView,
    ObservationScales,
    decode_observation,
    observation_space,
    observe,
)

CONFIG = EnvConfig.from_dict({"platoon": {"n_followers": 3}})
SCALES = ObservationScales.from_config(CONFIG)
LEVELS = np.array(CONFIG.setting_levels)
N_ENVS, N_FOLLOWERS = 4, 3
MAX_COUNT = 2 * CONFIG.chart.switch_exceedances
normal_cdf = np.vectorize(lambda z: 0.5 * math.erfc(-z / math.sqrt(2.0)))


def random_state(seed: int) -> FollowerState:
    """Random follower states, with one value past each clipped feature's bounds."""
    rng = np.random.default_rng(seed)
    shape = (N_ENVS, N_FOLLOWERS)
    center = rng.choice(LEVELS, shape)
    state = FollowerState(
        tau_mean=center + rng.normal(0.0, 0.3, shape),
        tau_var=rng.uniform(1e-4, 0.05, shape),
        center=center,
        side=rng.integers(-1, 2, shape).astype(np.int8),
        exceedances_in_window=rng.integers(0, MAX_COUNT + 1, shape),
        run_length=rng.integers(0, 300, shape),
        setting=rng.choice(LEVELS, shape),
        speed=rng.uniform(0.0, 38.0, shape),
        v2v=rng.random(shape) < 0.5,
    )
    state.tau_mean[0, 0] = center[0, 0] + 1.4  # deviation beyond +1 s
    state.tau_mean[1, 2] = center[1, 2] - 2.5  # deviation beyond -1 s
    state.tau_var[2, 1] = 0.3  # std beyond L sigma_desired
    state.exceedances_in_window[3, 0] = MAX_COUNT + 5  # more than 2k
    state.run_length[0, 2] = 10_000  # longer than the exceedance window
    state.speed[1, 1] = 45.0  # above 40 m/s
    return state


def reference_features(state: FollowerState, scales: ObservationScales) -> np.ndarray:
    """FEATURES' comments as NumPy, clipped to [OBSERVATION_LOW, OBSERVATION_HIGH]."""
    std = np.sqrt(state.tau_var)
    lower, upper = state.center - scales.half_width, state.center + scales.half_width
    prob_outside = normal_cdf((lower - state.tau_mean) / std) + 1.0 - normal_cdf((upper - state.tau_mean) / std)
    raw = np.stack([
        state.tau_mean - state.center,
        std / scales.half_width,
        prob_outside,
        state.side != 0,
        state.exceedances_in_window / scales.exceedance_scale,
        state.run_length * scales.dt / scales.exceedance_window,
        (state.setting - scales.smallest_level) / scales.level_span,
        state.speed / 40.0,
        state.v2v,
    ], axis=-1).astype(float)
    return np.clip(raw, OBSERVATION_LOW, OBSERVATION_HIGH).astype(np.float32)


@pytest.mark.parametrize("seed", range(4))
def test_observe_matches_the_numpy_reference(seed):
    state = random_state(seed)
    observation = observe(state, SCALES)
    assert observation.shape == (N_ENVS, N_FOLLOWERS, len(FEATURES)) and observation.dtype == np.float32
    np.testing.assert_allclose(observation, reference_features(state, SCALES), rtol=1e-6)
    prob_outside = observation[..., FEATURES.index("prob_outside")]
    assert np.any((0.01 < prob_outside) & (prob_outside < 0.99))  # the CDF is exercised, not only its tails


def test_out_of_range_values_are_clipped_to_the_bounds():
    observation = observe(random_state(0), SCALES)
    column = {name: observation[..., i] for i, name in enumerate(FEATURES)}
    assert column["deviation"][0, 0] == 1.0 and column["deviation"][1, 2] == -1.0
    assert column["estimate_std"][2, 1] == 1.0
    assert column["exceedances"][3, 0] == 1.0
    assert column["time_since_alarm"][0, 2] == 1.0
    assert column["speed"][1, 1] == 1.0
    assert np.all(observation >= OBSERVATION_LOW) and np.all(observation <= OBSERVATION_HIGH)


def test_prob_outside_is_a_half_on_a_limit_and_small_deep_inside():
    state = random_state(1)
    on_upper_limit = state._replace(tau_mean=state.center + SCALES.half_width, tau_var=np.full_like(state.tau_var, 1e-6))
    on_center = on_upper_limit._replace(tau_mean=state.center.copy())
    prob = FEATURES.index("prob_outside")
    np.testing.assert_allclose(observe(on_upper_limit, SCALES)[..., prob], 0.5, rtol=1e-6)
    assert np.all(observe(on_center, SCALES)[..., prob] < 1e-30)


@pytest.mark.parametrize("config", [EnvConfig(), CONFIG], ids=["5 followers", "3 followers"])
def test_observation_space_tiles_the_feature_bounds_per_follower(config):
    n = config.platoon.n_followers
    space = observation_space(config)
    assert space.shape == (n * len(FEATURES),) and space.dtype == np.float32
    np.testing.assert_array_equal(space.low, np.tile(OBSERVATION_LOW, n))
    np.testing.assert_array_equal(space.high, np.tile(OBSERVATION_HIGH, n))
    assert len(OBSERVATION_LOW) == len(OBSERVATION_HIGH) == len(FEATURES)


def test_observations_lie_in_the_observation_space():
    space = observation_space(CONFIG)
    for row in observe(random_state(2), SCALES).reshape(N_ENVS, -1):
        assert space.contains(row)


def test_observation_scales_come_from_the_config():
    config = EnvConfig.from_dict({"chart": {"switch_exceedances": 4, "limit_width": 3.0, "exceedance_window": 20.0},
                                  "setting_levels": [0.8, 1.6, 2.0], "platoon": {"initial_setting": 1.6}})
    scales = ObservationScales.from_config(config)
    assert scales.half_width == pytest.approx(3.0 * config.chart.baseline_std, rel=1e-15)
    assert (scales.exceedance_scale, scales.dt, scales.exceedance_window) == (8, config.platoon.dt, 20.0)
    assert (scales.smallest_level, scales.level_span) == (0.8, pytest.approx(1.2, rel=1e-15))


def test_decode_round_trips_counts_settings_and_v2v():
    rng = np.random.default_rng(7)
    n_envs = len(LEVELS)  # every level, and every count 0..2k, at least once
    shape = (n_envs, N_FOLLOWERS)
    index = (np.arange(n_envs)[:, None] + np.arange(N_FOLLOWERS)) % len(LEVELS)
    counts = (np.arange(n_envs)[:, None] * N_FOLLOWERS + np.arange(N_FOLLOWERS)) % (MAX_COUNT + 1)
    state = random_state(0)._replace(
        tau_mean=rng.normal(1.6, 0.3, shape), tau_var=rng.uniform(1e-4, 0.05, shape), center=rng.choice(LEVELS, shape),
        side=np.zeros(shape, dtype=np.int8), exceedances_in_window=counts, run_length=rng.integers(0, 300, shape),
        setting=LEVELS[index], speed=rng.uniform(0.0, 38.0, shape), v2v=rng.random(shape) < 0.5,
    )
    view = decode_observation(observe(state, SCALES).reshape(n_envs, -1), CONFIG)
    assert isinstance(view, FollowerView)
    np.testing.assert_array_equal(view.exceedances, counts)
    np.testing.assert_array_equal(view.setting_index, index)
    np.testing.assert_array_equal(view.setting, LEVELS[index])
    np.testing.assert_array_equal(view.v2v, state.v2v)


def test_decode_reads_counts_above_2k_as_2k():
    state = random_state(3)
    view = decode_observation(observe(state, SCALES).reshape(N_ENVS, -1), CONFIG)
    np.testing.assert_array_equal(view.exceedances, np.minimum(state.exceedances_in_window, MAX_COUNT))
    assert view.exceedances[3, 0] == MAX_COUNT


def test_decode_rejects_a_setting_off_the_ladder():
    observation = observe(random_state(0), SCALES)
    observation[2, 1, FEATURES.index("setting")] = (0.7 - LEVELS[0]) / (LEVELS[-1] - LEVELS[0])  # halfway 0.6 -> 0.8
    with pytest.raises(ValueError, match="setting_levels"):
        decode_observation(observation.reshape(N_ENVS, -1), CONFIG)


@pytest.mark.parametrize("env", range(N_ENVS))
def test_an_env_is_observed_the_same_alone_as_in_a_batch(env):
    state = random_state(5)
    alone = FollowerState(*(field[[env]] for field in state))
    np.testing.assert_array_equal(observe(alone, SCALES), observe(state, SCALES)[[env]])
