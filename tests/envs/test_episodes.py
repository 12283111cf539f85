"""Episodes: what each reset draws, reproducible from the env's generator alone, and the user's own leader."""

import gc

import numpy as np
import pytest

from timegap_env.tasks import get_task
from timegap_env.config import EnvConfig, LeaderConfig
from timegap_env.compiled import collection_paused
from timegap_env.envs.episodes import Episodes, check_reset_options
from timegap_env.leaders.profile import LeaderProfile
from timegap_env.leaders.regimes import RegimesConfig, regime_schedule
from timegap_env.leaders.scenarios import LEADER_FAMILIES, LeaderFamily, register_family, regime_names

CONFIG = EnvConfig.from_dict({"degradation": {"follower_probability": 0.5}})


def draw(config: EnvConfig, n_envs: int, env: int, seed: int, options: dict | None = None) -> Episodes:
    episodes = Episodes(config, n_envs)
    episodes.draw(env, np.random.default_rng(seed), check_reset_options(options))
    return episodes


def test_an_env_draws_the_same_episode_alone_or_in_a_batch():
    alone, batch = draw(CONFIG, 1, 0, seed=5), draw(CONFIG, 3, 2, seed=5)
    assert alone.fingerprint(0) == batch.fingerprint(2)
    assert alone.scenario[0] == batch.scenario[2]
    assert alone.fingerprint(0) != draw(CONFIG, 1, 0, seed=6).fingerprint(0)


def test_every_draw_is_in_its_configured_range():
    ranges = {"lag": CONFIG.degradation.lag_factor_range, "gain": CONFIG.degradation.gain_range,
              "v2v_latency": CONFIG.degradation.v2v_latency_range, "packet_loss": CONFIG.degradation.packet_loss_range,
              "radar_noise": CONFIG.degradation.radar_noise_range}
    uniform = CONFIG.with_overrides({"degradation": CONFIG.degradation.with_overrides(
        {"kind_weights": {kind: 1.0 for kind in CONFIG.degradation.kind_weights}})})
    kinds = set()
    for seed in range(60):
        episodes = draw(uniform, 1, 0, seed)
        duration = episodes.episode_ticks[0] * 0.1
        for degradation in episodes.degradations[0]:
            kinds.add(degradation.kind)
            assert degradation.followers and 0 <= degradation.onset < duration
            assert degradation.end is None or degradation.onset < degradation.end < duration
            if degradation.kind in ranges:
                low, high = ranges[degradation.kind]
                assert low - 0.05 <= degradation.size <= high + 0.05, degradation  # latency rounded to ticks
            if degradation.kind == "radar_bias":
                assert 1.0 <= abs(degradation.size) <= 4.0
            if degradation.kind == "v2v_outage":
                assert 20.0 - 1e-9 <= degradation.end - degradation.onset <= 80.0 + 1e-9
        assert 0.0 <= episodes.dropout_probability[0] <= 0.05
        assert episodes.scenario[0] in CONFIG.scenario_weights
    assert kinds == set(CONFIG.degradation.kind_weights) - {"none"}  # every kind is drawn in 60 episodes of a uniform mix


def test_a_pinned_degradation_leaves_the_other_draws_as_they_were():
    drawn = draw(CONFIG, 1, 0, seed=3)
    pinned = draw(CONFIG, 1, 0, seed=3, options={"degradation": {"kind": "gain", "size": 0.7, "followers": [2]}})
    assert [(d.kind, d.size, d.followers) for d in pinned.degradations[0]] == [("gain", 0.7, (2,))]
    assert pinned.scenario[0] == drawn.scenario[0] and pinned.noise_keys[0] == drawn.noise_keys[0]
    np.testing.assert_array_equal(pinned.leader_speed, drawn.leader_speed)
    assert draw(CONFIG, 1, 0, seed=3, options={"degradation": None}).degradations[0] == ()


def test_the_users_leader_is_cut_to_the_episode_and_padded_to_whole_decisions():
    speed = 20.0 + np.arange(55) * 0.01  # 5.4 s: not a whole number of 1 s decisions
    episodes = draw(EnvConfig(), 1, 0, seed=0, options={"leader_speed": speed})
    assert episodes.scenario[0] == "user" and episodes.episode_ticks[0] == 60
    leader_speed, leader_accel = episodes.leader_at(np.array([[0], [54], [55], [60], [70]]))
    np.testing.assert_array_equal(leader_speed[:, 0], [speed[0], speed[54], speed[54], speed[54], speed[54]])
    assert leader_accel[2, 0] == 0.0  # held after the profile
    long = draw(EnvConfig(), 1, 0, seed=0, options={"leader_speed": np.full(5000, 25.0)})
    assert long.episode_ticks[0] == 2500  # cut to the 250 s episode


def test_unknown_options_and_families_are_named():
    with pytest.raises(ValueError, match=r"reset options \['leader'\] unknown"):
        check_reset_options({"leader": 1})
    with pytest.raises(ValueError, match=r"unknown families \['rush_hour'\]"):
        Episodes(EnvConfig.from_dict({"scenario_weights": {"rush_hour": 1.0}}), 1)
    with pytest.raises(ValueError, match="scenario = 'rush_hour'"):
        draw(EnvConfig(), 1, 0, seed=0, options={"scenario": "rush_hour"})


def test_a_random_initial_setting_is_drawn_last_and_leaves_the_episode_as_it_was():
    random = CONFIG.with_overrides({"random_initial_setting": True})
    settings = set()
    for seed in range(12):
        plain, drawn = draw(CONFIG, 1, 0, seed), draw(random, 1, 0, seed)
        assert plain.initial_setting[0] == CONFIG.platoon.initial_setting
        assert drawn.initial_setting[0] in CONFIG.setting_levels
        settings.add(float(drawn.initial_setting[0]))
        np.testing.assert_array_equal(drawn.leader_speed, plain.leader_speed)
        assert drawn.degradations[0] == plain.degradations[0] and drawn.noise_keys[0] == plain.noise_keys[0]
    assert len(settings) >= 4


def expected_regimes(episodes: Episodes, env: int, family: str, codes: np.ndarray,
                     names: tuple[str, ...]) -> np.ndarray:
    """``env``'s regime row from its family's schedule (``codes`` into ``names``): the ground truth's codes, cut to
    the episode and held at the last one after it."""
    lookup = {name: code for code, name in enumerate(regime_names())}
    row = np.array([lookup[f"{family}:{name}"] for name in names])[codes[: episodes.episode_ticks[env] + 1]]
    return np.concatenate((row, np.full(episodes.regime.shape[1] - row.size, row[-1])))


def test_the_regimes_of_v1_episodes_are_their_leaders_schedules():
    config = get_task("TimeGapMonitor-v1").config({"episode_duration": 60.0})
    episodes = Episodes(config, 5)
    rngs = [np.random.default_rng(seed) for seed in range(5)]
    episodes.draw_many(np.arange(5), rngs, check_reset_options({"scenario": "regimes"}))
    for env in range(5):
        leader_seed = int(np.random.default_rng(env).integers(2**31))  # the first draw with the scenario pinned
        codes, names = regime_schedule(leader_seed, RegimesConfig(), config.leader)
        np.testing.assert_array_equal(episodes.regime[env], expected_regimes(episodes, env, "regimes", codes, names))


def test_a_familys_schedule_gives_the_regimes_when_its_batch_does_not():
    def flat(seed: int | None, params: None, leader: LeaderConfig) -> LeaderProfile:
        return LeaderProfile.from_speed(np.full(leader.n_samples, 20.0), dt=leader.dt, name="flat")

    def schedule(seed: int | None, params: None, leader: LeaderConfig) -> tuple[np.ndarray, tuple[str, ...]]:
        change = seed % leader.n_samples  # the tick it turns busy
        return (np.arange(leader.n_samples) >= change).astype(np.int8), ("calm", "busy")

    saved = dict(LEADER_FAMILIES)
    try:
        register_family(LeaderFamily("flat", flat, "20 m/s.", regimes=("calm", "busy"), schedule=schedule))
        config = get_task("TimeGapMonitor-v1").config({"episode_duration": 60.0})
        episodes = Episodes(config, 3)
        episodes.draw_many(np.arange(3), [np.random.default_rng(seed) for seed in range(3)],
                           check_reset_options({"scenario": "flat"}))
        for env in range(3):
            leader_seed = int(np.random.default_rng(env).integers(2**31))
            codes, names = schedule(leader_seed, None, config.leader)
            np.testing.assert_array_equal(episodes.regime[env], expected_regimes(episodes, env, "flat", codes, names))
    finally:
        LEADER_FAMILIES.clear()
        LEADER_FAMILIES.update(saved)


@pytest.mark.parametrize("enabled", [True, False])
def test_the_garbage_collector_is_paused_in_a_batched_draw_and_left_as_it_was(enabled):
    was = gc.isenabled()
    try:
        (gc.enable if enabled else gc.disable)()
        with collection_paused():
            assert not gc.isenabled()
        assert gc.isenabled() == enabled
        with pytest.raises(ZeroDivisionError), collection_paused():
            1 / 0
        assert gc.isenabled() == enabled
    finally:
        (gc.enable if was else gc.disable)()
