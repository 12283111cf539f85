"""Oracles: they read the ground truth, pick the ladder level it calls for, and act in both action modes."""

import gymnasium as gym
import numpy as np
import pytest

from timegap_env.agents.oracles import LookupOracle, StabilityOracle, condition_keys, size_bin
from timegap_env.config import EnvConfig
from timegap_env.envs.info import truth_of

CONFIG = EnvConfig()
LEVELS = np.asarray(CONFIG.setting_levels)


def truth_after(options: dict, steps: int = 3, config: dict | None = None) -> dict:
    env = gym.make("TimeGapMonitor-v0", config=config, truth_info=True)
    env.reset(seed=0, options=options)
    for _ in range(steps):
        _, _, _, _, info = env.step(2)
    return truth_of(info)


def test_the_stability_oracle_takes_the_smallest_level_above_the_stable_setting_plus_margin():
    nominal = truth_after({"degradation": None})
    assert LEVELS[StabilityOracle(CONFIG, margin=0.1).act(nominal)] == 1.0  # nominal: stable from 0.89 s
    weak = truth_after({"degradation": {"kind": "gain", "size": 0.7, "followers": [3]}})
    stable = weak["smallest_stable_setting"]
    assert stable[2] > stable[0]
    assert LEVELS[StabilityOracle(CONFIG, margin=0.1).act(weak)] == LEVELS[np.searchsorted(LEVELS, stable[2] + 0.1)]
    per_vehicle = StabilityOracle(CONFIG.with_overrides({"action_mode": "per_vehicle"}), margin=0.1).act(weak)
    assert per_vehicle.shape == (5,) and LEVELS[per_vehicle].tolist() == [1.0, 1.0, 1.6, 1.0, 1.0]


def test_the_oracles_act_on_a_batch_of_envs_from_the_vector_envs_truth():
    envs = gym.make_vec("TimeGapMonitor-v0", num_envs=3, vectorization_mode="vector_entry_point", truth_info=True)
    _, infos = envs.reset(seed=[1, 2, 3])
    actions = StabilityOracle(CONFIG).act(truth_of(infos))
    assert actions.shape == (3,) and actions.dtype == np.int64
    envs.step(actions)


def test_condition_keys_bin_the_active_degradations_size():
    config = CONFIG.degradation
    assert size_bin("gain", 0.6, config) == "0" and size_bin("gain", 0.85, config) == "2"
    assert size_bin("radar_bias", -3.9, config) == "-2" and size_bin("lag", 9.0, config) == "2"  # clipped to the range
    before = truth_after({"degradation": {"kind": "gain", "size": 0.62, "onset": 10.0}})
    assert set(condition_keys(before, config)) == {"none"}  # not acting yet
    assert set(condition_keys(before, config, whole_episode=True)) == {"gain:0"}  # the schedule, read ahead
    after = truth_after({"degradation": {"kind": "gain", "size": 0.62, "onset": 1.0}})
    assert set(condition_keys(after, config)) == {"gain:0"}


def test_the_lookup_oracle_reads_its_table_and_needs_the_nominal_entry():
    table = {"none": 1.0, "gain:0": 1.8}
    weak = truth_after({"degradation": {"kind": "gain", "size": 0.62, "followers": [2]}})
    assert LEVELS[LookupOracle(table, CONFIG).act(weak)] == 1.8
    assert LEVELS[LookupOracle(table, CONFIG).act(truth_after({"degradation": {"kind": "lag", "size": 2.0}}))] == 1.0
    with pytest.raises(ValueError, match="must hold the nominal condition 'none'"):
        LookupOracle({"gain:0": 1.8}, CONFIG)


def test_the_whole_episode_lookup_oracle_prepares_before_the_onset():
    table = {"none": 1.0, "gain:0": 1.8}
    before = truth_after({"degradation": {"kind": "gain", "size": 0.62, "followers": [2], "onset": 10.0}})
    assert LEVELS[LookupOracle(table, CONFIG).act(before)] == 1.0
    episode = LookupOracle(table, CONFIG, whole_episode=True)
    assert LEVELS[episode.act(before)] == 1.8 and episode.name == "oracle_lookup_episode"
