"""timegap_env.generators: many generators at once, each drawing what np.random.default_rng(seed) draws."""

from __future__ import annotations

import copy
import pickle

import gymnasium
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from timegap_env.envs.vector_env import TimeGapMonitorVectorEnv
import timegap_env.generators
from timegap_env.generators import HASHED_FROM, SeedWords, generators, seed_words, unseeded_generators

EDGES = [0, 1, 2**31 - 1, 2**32 - 1, 2**32, 2**63, 2**64 - 1, 2**64, 2**127, 2**128 - 1, 2**128, 2**130 + 7, 10**60]


def draws(rng: np.random.Generator) -> list:
    """A few draws of each kind a leader or an episode takes: uniform, bounded integers (32- and 64-bit), normal."""
    return [*rng.random(3), int(rng.integers(2**31)), int(rng.integers(0, 2**63, dtype=np.uint64)),
            *rng.standard_normal(3), int(rng.integers(7))]


@pytest.fixture(params=[True, False], ids=["hashed", "below HASHED_FROM"])
def hashed(request, monkeypatch):
    """Both ways generators() makes a few generators: hashed in arrays (HASHED_FROM lowered to 1) or, below
    HASHED_FROM, by default_rng one by one."""
    if request.param:
        monkeypatch.setattr(timegap_env.generators, "HASHED_FROM", 1)
    return request.param


@settings(max_examples=300, deadline=None)
@given(st.lists(st.integers(0, 2**300), min_size=1, max_size=20))
def test_the_words_are_seed_sequences(seeds):
    expected = np.array([np.random.SeedSequence(seed).generate_state(4, np.uint64) for seed in seeds])
    np.testing.assert_array_equal(seed_words(seeds), expected)


def test_each_generator_draws_what_default_rng_draws(hashed):
    seeds = [*EDGES, 5, np.int64(12), np.uint32(4_000_000_000), True, False, [1, 2], np.random.SeedSequence(3)]
    for seed, rng in zip(seeds, generators(seeds), strict=True):
        assert draws(rng) == draws(np.random.default_rng(seed)), seed


def test_a_generator_pickles_copies_and_spawns_as_default_rngs_do(hashed):
    ours, numpys = generators([11])[0], np.random.default_rng(11)
    ours.random(), numpys.random()
    expected = draws(copy.deepcopy(numpys))
    assert draws(copy.deepcopy(ours)) == expected
    for protocol in range(pickle.HIGHEST_PROTOCOL + 1):
        assert draws(pickle.loads(pickle.dumps(ours, protocol=protocol))) == expected, protocol
    for _ in range(2):  # the second spawn's children follow on from the first's
        assert [draws(child) for child in ours.spawn(2)] == [draws(child) for child in numpys.spawn(2)]


def test_a_bad_seed_raises_what_default_rng_raises(hashed):
    with pytest.raises(ValueError, match="negative") as ours:
        generators([3, -1])
    with pytest.raises(ValueError) as numpys:
        np.random.default_rng(-1)
    assert str(ours.value) == str(numpys.value)


def test_other_requests_go_to_a_seed_sequence():
    words = SeedWords(99, seed_words([99])[0])
    for n_words, dtype in ((4, np.uint64), (8, np.uint32), (2, np.uint64), (4, np.uint32)):
        np.testing.assert_array_equal(words.generate_state(n_words, dtype),
                                      np.random.SeedSequence(99).generate_state(n_words, dtype))
    assert words.generate_state(4, np.uint64) is not words.words  # a copy: the generator may keep it


def test_unseeded_generators_differ():
    first = [rng.random() for rng in unseeded_generators(64)]
    assert len(set(first)) == 64


def test_a_sub_env_draws_the_episode_a_single_env_of_its_seed_draws():
    n_envs = HASHED_FROM + 4
    envs = TimeGapMonitorVectorEnv(n_envs)
    try:
        envs.reset(seed=[7, None, 2**70, *range(n_envs - 3)])
        assert isinstance(envs._rngs[0].bit_generator.seed_seq, SeedWords)  # hashed in arrays
        for sub_env, seed in ((0, 7), (2, 2**70), (n_envs - 1, n_envs - 4)):
            single = gymnasium.make(timegap_env.DEFAULT_TASK).unwrapped
            single.reset(seed=seed)
            assert envs.task.episodes.fingerprint(sub_env) == single.task.episodes.fingerprint(0)
        states = [rng.bit_generator.state for rng in envs._rngs]
        for seed in (-1, 1.5, np.int64(3)):  # raises, and no sub-env's generator changes (not even those before)
            with pytest.raises(gymnasium.error.Error, match="Seed must"):
                envs.reset(seed=[0, seed, *range(1, n_envs - 1)])
            assert [rng.bit_generator.state for rng in envs._rngs] == states
    finally:
        envs.close()
