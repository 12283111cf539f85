"""The harsh, held-out leader families (stop-and-go waves, emergency braking): reproducible, within their
limits, showing what defines them, and runnable in the env but never drawn by the default training mix."""

import gymnasium as gym
import numpy as np
import pytest

import timegap_env
from timegap_env.config import EnvConfig, LeaderConfig, PlatoonConfig
from timegap_env.leaders import (
    HELD_OUT_FAMILIES,
    SCENARIOS,
    EmergencyBrakingConfig,
    StopAndGoConfig,
    make_leader,
    synthetic,
)

PARAMS = {"stop_and_go": StopAndGoConfig(), "emergency_braking": EmergencyBrakingConfig()}
CRAWL_SPEED = 5.0  # a stop-and-go wave reaches this or less [m/s]


def crawls(speed: np.ndarray) -> int:
    """Times the speed drops to CRAWL_SPEED or below."""
    below = speed <= CRAWL_SPEED + 1e-9
    return int(below[0]) + np.count_nonzero(below[1:] & ~below[:-1])


def test_held_out_families_are_scenarios_outside_the_default_training_mix():
    assert set(HELD_OUT_FAMILIES) == {"stop_and_go", "emergency_braking"}
    for family in HELD_OUT_FAMILIES:
        assert SCENARIOS[family].leader_family == family
    assert not set(HELD_OUT_FAMILIES) & set(EnvConfig().scenario_weights)


@pytest.mark.parametrize("family", HELD_OUT_FAMILIES)
def test_family_is_reproducible_from_its_seed(family):
    first, again, other = make_leader(family, 7), make_leader(family, 7), make_leader(family, 8)
    np.testing.assert_array_equal(first.speed, again.speed)
    np.testing.assert_array_equal(first.accel, again.accel)
    assert not np.array_equal(first.speed, other.speed)
    assert first.name == family
    np.testing.assert_array_equal(first.speed, getattr(synthetic, family)(7).speed)


@pytest.mark.parametrize("family", HELD_OUT_FAMILIES)
@pytest.mark.parametrize("seed", range(10))
def test_family_stays_within_its_limits(family, seed):
    leader, platoon, params = LeaderConfig(), PlatoonConfig(), PARAMS[family]
    profile = make_leader(family, seed)
    assert profile.speed.size == leader.n_samples and profile.dt == leader.dt
    assert profile.speed[0] == pytest.approx(leader.initial_speed)
    # From standstill (below the band's low end, on purpose) up to the band's high end [m/s].
    assert profile.speed.min() >= 0.0 and profile.speed.max() <= leader.speed_band[1] + 1e-9
    assert profile.speed.max() <= params.cruise_speed_range[1] + 1e-9
    # Within the followers' command limits, so a follower can always brake harder than the leader [m/s^2] ...
    assert platoon.accel_min <= profile.accel.min() and profile.accel.max() <= platoon.accel_max
    # ... and the family's own limits [m/s^2], changing by at most max_jerk [m/s^3].
    assert -profile.accel.min() <= params.decel_range[1] + 1e-9
    assert np.abs(np.diff(profile.accel)).max() <= params.max_jerk * profile.dt + 1e-9
    integrated = profile.speed[0] + np.r_[0.0, np.cumsum(profile.accel[:-1])] * profile.dt
    np.testing.assert_allclose(integrated, profile.speed, atol=1e-6)  # the acceleration is the speed's [m/s]


@pytest.mark.parametrize("seed", range(10))
def test_stop_and_go_crawls_again_and_again(seed):
    profile = make_leader("stop_and_go", seed)
    assert crawls(profile.speed) >= 2  # more than one wave down to 0-5 m/s in 250 s
    assert profile.accel.min() <= -StopAndGoConfig().decel_range[0] + 1e-9  # each wave brakes hard
    assert profile.speed.max() >= StopAndGoConfig().cruise_speed_range[0] - 1e-9  # and returns to cruise


@pytest.mark.parametrize("seed", range(10))
def test_emergency_braking_stops_from_highway_speed(seed):
    params = EmergencyBrakingConfig()
    profile = make_leader("emergency_braking", seed)
    assert profile.accel.min() < -5.0  # an emergency deceleration [m/s^2]
    assert profile.accel.min() <= -params.decel_range[0] + 1e-9
    assert profile.speed.min() <= params.low_speed_range[1] + 1e-9  # down to a low speed or standstill
    assert profile.speed[-1] >= params.cruise_speed_range[0] - 1e-9  # back to highway speed by the end
    assert params.n_events_range[0] <= crawls(profile.speed) <= params.n_events_range[1]


def test_some_emergency_stops_reach_standstill():
    assert any(make_leader("emergency_braking", seed).speed.min() == 0.0 for seed in range(10))


def test_params_are_validated():
    with pytest.raises(ValueError, match="crawl_speed_range"):
        StopAndGoConfig(crawl_speed_range=(0.0, 20.0))
    with pytest.raises(ValueError, match="n_events_range"):
        EmergencyBrakingConfig(n_events_range=(0, 2))
    with pytest.raises(ValueError, match="standstill_probability"):
        EmergencyBrakingConfig(standstill_probability=1.5)


def test_short_profiles_drop_the_stops_that_do_not_fit():
    leader = LeaderConfig(duration=5.0)
    profile = synthetic.emergency_braking(0, leader=leader)
    assert profile.speed.size == leader.n_samples and profile.speed.min() > CRAWL_SPEED
    assert synthetic.stop_and_go(0, leader=leader).speed.size == leader.n_samples


@pytest.mark.parametrize("family", HELD_OUT_FAMILIES)
def test_env_and_simulate_run_the_family(family):
    env = gym.make("TimeGapMonitor-v0")
    obs, info = env.reset(seed=3, options={"scenario": family})
    assert env.unwrapped.scenario == family
    setting = int(np.argmin(np.abs(np.array(EnvConfig().setting_levels) - 1.6)))
    for _ in range(5):
        obs, reward, terminated, _, info = env.step(setting)
        assert np.all(np.isfinite(obs)) and np.isfinite(reward) and not terminated
    trajectory = timegap_env.simulate(family, seed=3)
    assert not trajectory.collision
