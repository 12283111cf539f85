"""The regimes family (issue 24, item 2): a leader that strings free flow, slow oscillation, aggressive cycles,
stop-and-go and hard braking, seeded, smooth, in band, with the regime of every tick recoverable."""

import gymnasium as gym
import numpy as np
import pytest

import timegap_env
from timegap_env.config import LeaderConfig
from timegap_env.leaders import default_ngsim_path, default_openacc_dir, make_leader, read_ngsim, vehicle_ids
from timegap_env.leaders import vehicle_profile
from timegap_env.leaders.openacc import lead_car_speeds
from timegap_env.leaders.regimes import (
    REGIMES, RegimesConfig, regime_schedule, regimes, regimes_batch, traffic_statistics,
)

LEADER = LeaderConfig()
SEEDS = range(40)
SMOOTH = ("free_flow", "slow_oscillation", "stop_and_go")  # regimes whose every move keeps to smooth_jerk


def only(regime: str, **fields: object) -> RegimesConfig:
    """Parameters that draw ``regime`` alone."""
    return RegimesConfig(regime_weights={regime: 1.0}, **fields)


def runs(codes: np.ndarray) -> list[tuple[int, int, int]]:
    """(code, first tick, ticks) of each run of one regime in ``codes``."""
    starts = np.r_[0, np.flatnonzero(np.diff(codes)) + 1]
    return [(int(codes[start]), int(start), int(end - start)) for start, end in zip(starts, np.r_[starts[1:], codes.size])]


def jerk(profile) -> np.ndarray:
    """The change of acceleration from each tick to the next, the first from a = 0 [m/s^3]."""
    return np.diff(np.r_[0.0, profile.accel]) / profile.dt


def test_the_same_seed_gives_the_same_profile_and_schedule_other_seeds_differ():
    first, again, other = regimes(7), regimes(7), regimes(8)
    np.testing.assert_array_equal(first.speed, again.speed)
    np.testing.assert_array_equal(first.accel, again.accel)
    np.testing.assert_array_equal(regime_schedule(7)[0], regime_schedule(7)[0])
    assert not np.array_equal(first.speed, other.speed)
    assert first.name == "regimes" and first.speed.size == LEADER.n_samples and first.dt == LEADER.dt


def test_a_batch_holds_each_seeds_own_profile():
    seeds = [5, 0, None, 123, 2**31 - 1]
    batch = regimes_batch([seed if seed is not None else 9 for seed in seeds])
    for row, seed in enumerate(seeds):
        np.testing.assert_array_equal(batch.speed[row], regimes(seed if seed is not None else 9).speed)
        np.testing.assert_array_equal(batch.regime[row], regime_schedule(seed if seed is not None else 9)[0])


@pytest.mark.parametrize(("dt", "duration"), [(0.1, 0.1), (0.1, 2.0), (0.01, 1.37), (1.0, 3.0), (0.5, 4.5),
                                             (0.1, 3600.0)])
def test_a_profile_of_any_length_is_built_in_band(dt, duration):
    leader = LeaderConfig(dt=dt, duration=duration)
    batch = regimes_batch([0, 1, 2**31 - 1], leader=leader)
    assert batch.speed.shape == (3, leader.n_samples) and batch.dt == dt
    assert batch.speed.min() >= 0.0 and batch.speed.max() <= leader.speed_band[1]
    assert regime_schedule(1, leader=leader)[0].size == leader.n_samples


def test_every_regime_appears_across_seeds_and_never_twice_in_a_row():
    seen = set()
    for seed in SEEDS:
        codes, names = regime_schedule(seed)
        assert names == REGIMES and codes.dtype == np.int8 and codes.size == LEADER.n_samples
        regimes_in_order = [code for code, _, _ in runs(codes)]
        assert len(regimes_in_order) >= 2  # 250 s holds several regimes
        seen.update(regimes_in_order)
    assert seen == set(range(len(REGIMES)))


def test_each_regime_lasts_a_duration_within_its_range():
    params = RegimesConfig()
    for seed in SEEDS:
        codes, _ = regime_schedule(seed)
        for code, _, ticks in runs(codes)[:-1]:  # the last one is cut at the profile's end
            low, high = getattr(params, f"{REGIMES[code]}_duration")
            assert low - LEADER.dt / 2 <= ticks * LEADER.dt <= high + LEADER.dt / 2, (seed, REGIMES[code], ticks)


@pytest.mark.parametrize("seed", SEEDS)
def test_speed_stays_in_band_without_jumps_and_acceleration_and_jerk_keep_their_limits(seed):
    params, profile = RegimesConfig(), regimes(seed)
    codes, _ = regime_schedule(seed)
    assert profile.speed.min() >= 0.0 and profile.speed.max() <= LEADER.speed_band[1]
    assert profile.speed[0] == LEADER.initial_speed
    np.testing.assert_allclose(np.diff(profile.speed), profile.accel[:-1] * profile.dt, atol=1e-9)  # integrated
    assert np.abs(profile.accel).max() <= params.hard_braking_decel_range[1] + 1e-9
    assert profile.accel.max() <= params.aggressive_cycles_accel_range[1] + 1e-9  # below the followers' 4 m/s^2
    assert np.abs(jerk(profile)).max() <= params.max_jerk + 1e-6
    smooth = np.isin(codes, [REGIMES.index(name) for name in SMOOTH])
    assert np.abs(jerk(profile)[smooth]).max(initial=0.0) <= params.smooth_jerk + 1e-6


def test_the_acceleration_is_zero_where_one_regime_hands_over_to_the_next():
    for seed in SEEDS:
        profile, (codes, _) = regimes(seed), regime_schedule(seed)
        boundaries = np.flatnonzero(np.diff(codes)) + 1
        np.testing.assert_array_equal(profile.accel[boundaries - 1], 0.0)  # each regime's last tick


@pytest.mark.parametrize("regime", REGIMES)
def test_a_single_regime_config_gives_that_regime_throughout(regime):
    codes, names = regime_schedule(3, only(regime))
    assert set(codes.tolist()) == {names.index(regime)}


def test_each_regime_has_its_character():
    def profile(regime: str, seed: int = 1, **fields: object):
        return regimes(seed, only(regime, **fields))

    free = profile("free_flow")
    cruise = free.speed[free.speed.size // 2:]  # reached by then
    assert 25.0 - 1.5 <= cruise.mean() <= 33.0 + 1.5 and cruise.std() < 1.5 and np.abs(free.accel).max() <= 1.3 + 1e-9
    waves = profile("slow_oscillation")
    assert 2 * 1.8 - 0.5 <= np.ptp(waves.speed[waves.speed.size // 2:]) and waves.speed.min() > 5.0
    aggressive = profile("aggressive_cycles")
    assert aggressive.accel.max() >= 1.5 and aggressive.accel.min() <= -1.5
    assert np.count_nonzero(np.diff(np.sign(aggressive.accel[np.abs(aggressive.accel) > 1.0]))) >= 10
    stop_and_go = profile("stop_and_go")
    assert stop_and_go.speed.min() <= 2.6 + 1e-9 and np.count_nonzero(np.diff((stop_and_go.speed < 3.0).astype(int))
                                                                      == 1) >= 3
    braking = profile("hard_braking")
    assert braking.accel.min() <= -4.0


def test_every_hard_brake_recovers_within_its_regime():
    params = RegimesConfig(regime_weights={"hard_braking": 1.0, "free_flow": 1.0})
    braking = REGIMES.index("hard_braking")
    for seed in SEEDS:
        profile, (codes, _) = regimes(seed, params), regime_schedule(seed, params)
        for code, start, ticks in runs(codes)[:-1]:
            if code == braking:
                # the brake's whole ticks may round its peak a little below the drawn 4-7 m/s^2
                assert profile.accel[start: start + ticks].min() <= -0.9 * params.hard_braking_decel_range[0]
                assert profile.speed[start + ticks] >= profile.speed[start] - 1e-9  # back up to the speed before


def test_the_schedule_names_the_regime_that_shapes_each_tick():
    """The schedule and the profile come from one plan: the harsh moves sit in the harsh regimes' ticks."""
    params = RegimesConfig()
    for seed in SEEDS:
        profile, (codes, _) = regimes(seed), regime_schedule(seed)
        hard = profile.accel < -params.stop_and_go_decel_range[1] - 1e-9  # harder than any smooth regime brakes
        assert set(codes[hard].tolist()) <= {REGIMES.index("aggressive_cycles"), REGIMES.index("hard_braking")}
        free = codes == REGIMES.index("free_flow")
        assert np.abs(profile.accel[free]).max(initial=0.0) <= params.transition_accel + 1e-9


@pytest.mark.parametrize(
    ("fields", "message"),
    [
        ({"hard_braking_duration": (0.0, 10.0)}, r"RegimesConfig.hard_braking_duration = \(0.0, 10.0\)"),
        ({"free_flow_duration": (-5.0, 10.0)}, r"RegimesConfig.free_flow_duration = \(-5.0, 10.0\)"),
        ({"regime_weights": {"rush_hour": 1.0}},
         r"RegimesConfig.regime_weights = \{'rush_hour': 1.0\}: unknown regimes \['rush_hour'\]"),
        ({"regime_weights": dict.fromkeys(REGIMES, 0.0)}, r"RegimesConfig.regime_weights = .*not all 0"),
        ({"stop_and_go_crawl_speed_range": (0.0, 8.0)},
         r"RegimesConfig.stop_and_go_crawl_speed_range = \(0.0, 8.0\): must lie below stop_and_go_top_speed_range"),
        ({"max_jerk": 0.0}, r"RegimesConfig.max_jerk = 0.0"),
    ],
)
def test_bad_parameters_are_refused_naming_the_field_and_value(fields, message):
    with pytest.raises(ValueError, match=message):
        RegimesConfig(**fields)


def test_weights_may_leave_regimes_out():
    codes, _ = regime_schedule(0, RegimesConfig(regime_weights={"free_flow": 1.0, "hard_braking": 2.0}))
    assert set(codes.tolist()) <= {REGIMES.index("free_flow"), REGIMES.index("hard_braking")}


def test_reachable_from_gym_make_leader_params_and_simulate():
    env = gym.make("TimeGapMonitor-v0", config={"scenario_weights": {"regimes": 1.0}, "episode_duration": 60.0})
    env.reset(seed=1)
    assert env.unwrapped.scenario == "regimes"

    params = {"regimes": {"regime_weights": {"stop_and_go": 1.0}}}
    configured = gym.make("TimeGapMonitor-v0", config={"episode_duration": 60.0, "leader_params": params})
    configured.reset(seed=2, options={"scenario": "regimes"})
    episodes = configured.unwrapped.task.episodes
    speed = episodes.leader_speed[0, : episodes.episode_ticks[0] + 1]
    leader = configured.unwrapped.config.leader
    seed = int(np.random.default_rng(2).integers(2**31))  # what the reset draws as the leader's seed
    expected = make_leader("regimes", seed, leader, RegimesConfig(regime_weights={"stop_and_go": 1.0}))
    np.testing.assert_array_equal(speed, expected.speed)

    trajectory = timegap_env.simulate("regimes", seed=0)
    assert trajectory.leader_name == "regimes"
    np.testing.assert_array_equal(trajectory.v[:, 0], regimes(0).speed[: trajectory.v.shape[0]])  # column 0: leader


def test_an_episode_behind_it_runs_to_its_end():
    env = gym.make("TimeGapMonitor-v0", config={"scenario_weights": {"regimes": 1.0}, "episode_duration": 100.0})
    env.reset(seed=4)
    terminated = truncated = False
    steps = 0
    while not (terminated or truncated):
        _, reward, terminated, truncated, _ = env.step(env.action_space.sample())
        assert np.isfinite(reward)
        steps += 1
    assert steps > 1


def test_traffic_statistics_of_a_known_wave():
    dt, t = 0.1, np.arange(0.0, 120.0, 0.1)
    stats = traffic_statistics([10.0 + 2.0 * np.sin(2 * np.pi * t / 20.0)], dt)  # 2 m/s, 20 s
    assert stats["amplitude_p50"] == pytest.approx(2.0 * np.sin(0.45 * np.pi), rel=0.02)  # half the 5-95 % spread
    assert stats["period_p50"] == pytest.approx(20.0, abs=dt)
    assert stats["abs_accel_p99"] == pytest.approx(2.0 * 2 * np.pi / 20.0, rel=0.02)
    assert stats["mean_speed_p5"] == pytest.approx(10.0, abs=0.1)
    # a 10 s moving average keeps 2 / pi of a 20 s wave: the rest, a sine of 2 (1 - 2 / pi) m/s, is the fluctuation
    assert stats["fluctuation_std_p50"] == pytest.approx(2.0 * (1 - 2 / np.pi) / np.sqrt(2), rel=0.02)


def test_the_defaults_are_what_the_shared_data_measure():
    """The numbers the defaults cite, measured again (skipped without the shared NGSIM and OpenACC data)."""
    if not default_ngsim_path().exists() or not default_openacc_dir().exists():
        pytest.skip(f"NGSIM or OpenACC data absent at {default_ngsim_path()}, {default_openacc_dir()}")
    table = read_ngsim(default_ngsim_path())
    ngsim = traffic_statistics([vehicle_profile(table, vehicle).speed for vehicle in vehicle_ids(table, 30.0)], 0.1)
    lead_cars = traffic_statistics([speed for _, speed in lead_car_speeds(default_openacc_dir())], 0.1)
    params = RegimesConfig()
    measured = {
        "slow_oscillation_amplitude_range": (ngsim["amplitude_p10"], ngsim["amplitude_p90"]),
        "slow_oscillation_period_range": (ngsim["period_p25"], ngsim["period_p90"]),
        "stop_and_go_top_speed_range": (ngsim["mean_speed_p5"], ngsim["mean_speed_p95"]),
        "stop_and_go_crawl_speed_range": (0.0, ngsim["min_speed_p5"]),
        "stop_and_go_decel_range": (-lead_cars["active_accel_p25"], -lead_cars["active_accel_p5"]),
        "stop_and_go_accel_range": (lead_cars["active_accel_p75"], ngsim["accel_p99"]),
        "free_flow_speed_std": ngsim["fluctuation_std_p50"],
        "free_flow_accel": ngsim["abs_accel_p50"],
        "transition_accel": ngsim["abs_accel_p95"],
        "smooth_jerk": lead_cars["active_abs_jerk_p99"],
    }
    for field, value in measured.items():
        assert getattr(params, field) == pytest.approx(value, abs=0.06), field
