"""Episodes: what each reset draws, reproducible from the env's generator alone, and the user's own leader."""

import numpy as np
import pytest

from timegap_env.config import EnvConfig
from timegap_env.envs.episodes import Episodes, check_reset_options

CONFIG = EnvConfig.from_dict({"v2v_loss_probability": 1.0, "v2v_loss_follower_probability": 0.5})


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
    for seed in range(20):
        episodes = draw(CONFIG, 1, 0, seed)
        start, end = episodes.v2v_loss_start[0], episodes.v2v_loss_end[0]
        lost = end > start
        assert lost.any()  # at least one follower loses V2V when the outage happens
        assert np.all((end[lost] - start[lost]) * 0.1 >= 20.0 - 1e-9) and np.all((end - start) * 0.1 <= 80.0 + 1e-9)
        assert 0.0 <= episodes.dropout_probability[0] <= 0.05
        assert episodes.scenario[0] in CONFIG.scenario_weights


def test_v2v_is_down_exactly_during_the_outage():
    episodes = draw(CONFIG, 1, 0, seed=1)
    ticks = np.arange(episodes.episode_ticks[0] + 1)[:, None]
    v2v = episodes.v2v_at(ticks)[:, 0]  # (n_ticks, n_followers)
    start, end = episodes.v2v_loss_start[0], episodes.v2v_loss_end[0]
    np.testing.assert_array_equal(v2v, ~((ticks >= start) & (ticks < end)))


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
