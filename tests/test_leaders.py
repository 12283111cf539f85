"""Leader profile sources: integration within a band, synthetic families, user arrays and CSV."""

import numpy as np
import pytest

from timegap_env import leaders
from timegap_env.config import MPH, AggressiveCyclesConfig, LeaderConfig
from timegap_env.leaders import LeaderProfile
from timegap_env.ngsim import default_ngsim_path
from timegap_env.scenarios import SCENARIOS, make_leader

FAMILIES = ["aggressive_cycles", "hard_braking", "sinusoid", "stochastic_human"]


def test_from_acceleration_integrates_and_holds_the_band():
    leader = LeaderConfig(initial_speed=20.0)
    profile = LeaderProfile.from_acceleration(np.r_[np.full(30, 1.0), np.full(400, 3.0), np.full(600, -3.0)], leader)
    assert profile.speed[30] == pytest.approx(23.0)
    low, high = leader.speed_band
    assert profile.speed.min() == pytest.approx(low) and profile.speed.max() == pytest.approx(high)
    assert (low, high) == pytest.approx((20 * MPH, 80 * MPH))
    np.testing.assert_allclose(np.diff(profile.speed) / profile.dt, profile.accel[:-1], atol=1e-9)
    assert np.all(profile.accel[profile.speed >= high - 1e-12][:-1] <= 1e-9)


@pytest.mark.parametrize("family", FAMILIES)
def test_family_is_reproducible_from_its_seed(family):
    first, again, other = make_leader(family, 7), make_leader(family, 7), make_leader(family, 8)
    np.testing.assert_array_equal(first.speed, again.speed)
    np.testing.assert_array_equal(first.accel, again.accel)
    assert not np.array_equal(first.speed, other.speed)


@pytest.mark.parametrize("family", FAMILIES)
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_family_stays_in_band_with_consistent_acceleration(family, seed):
    leader = LeaderConfig()
    profile = make_leader(family, seed)
    assert profile.speed.size == leader.n_samples and profile.dt == leader.dt
    low, high = leader.speed_band
    assert low - 1e-9 <= profile.speed.min() and profile.speed.max() <= high + 1e-9
    integrated = profile.speed[0] + np.r_[0.0, np.cumsum(0.5 * (profile.accel[:-1] + profile.accel[1:]))] * profile.dt
    # The acceleration integrates to the speed, within one tick's worth of acceleration [m/s].
    assert np.abs(integrated - profile.speed).max() <= np.abs(profile.accel).max() * profile.dt
    assert np.ptp(profile.speed) > 3.0  # a disturbance, not a constant


def test_aggressive_cycles_match_the_paper_description():
    params = AggressiveCyclesConfig()
    profile = leaders.aggressive_cycles(3, params)
    accel = profile.accel
    assert accel.max() > params.accel_range[0] and accel.min() < -params.accel_range[0]
    assert np.abs(accel).max() <= params.accel_range[1] + 1e-9
    sign_changes = np.count_nonzero(np.diff(np.sign(accel[np.abs(accel) > 1.0])) != 0)
    assert sign_changes >= 10  # many cycles in 250 s
    assert np.abs(np.diff(accel)).max() <= params.max_jerk * profile.dt + 1e-9


def test_hard_braking_brakes_hard():
    profile = make_leader("hard_braking", 0)
    assert profile.accel.min() <= -4.0


def test_paper_scenario_is_250_s_at_10_hz():
    profile = make_leader("paper", 0)
    assert profile.duration == pytest.approx(250.0) and profile.dt == pytest.approx(0.1)
    assert SCENARIOS["paper"].platoon.n_followers == 5


def test_user_array_becomes_a_profile():
    profile = LeaderProfile.from_speed(np.linspace(20, 25, 51), dt=0.1, name="mine")
    np.testing.assert_allclose(profile.accel, 1.0)
    assert profile.name == "mine" and profile.duration == pytest.approx(5.0)


def test_user_csv_with_and_without_time(tmp_path):
    with_time = tmp_path / "lead.csv"
    with_time.write_text("time,speed\n" + "".join(f"{0.2 * k:.1f},{20 + k}\n" for k in range(5)))
    profile = LeaderProfile.from_csv(with_time)
    assert profile.dt == pytest.approx(0.2)
    np.testing.assert_allclose(profile.accel, 5.0)
    speed_only = tmp_path / "speed.csv"
    speed_only.write_text("speed,accel\n20,0.5\n20.05,0.5\n20.1,0.5\n")
    profile = LeaderProfile.from_csv(speed_only)
    assert profile.dt == pytest.approx(0.1) and profile.name == "speed"
    np.testing.assert_allclose(profile.accel, 0.5)


@pytest.mark.parametrize(
    "content, message",
    [
        ("velocity\n1\n2\n", "missing column 'speed'"),
        ("speed\n20\nfast\n", "row 3, column 'speed' = 'fast'"),
        ("time,speed\n0,20\n0.1,20\n0.3,20\n", "even steps"),
        ("speed\n20\nnan\n", r"speed\[1\] = nan"),
    ],
)
def test_malformed_user_csv_is_named(tmp_path, content, message):
    path = tmp_path / "bad.csv"
    path.write_text(content)
    with pytest.raises(ValueError, match=message):
        LeaderProfile.from_csv(path)


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda: LeaderProfile.from_speed(np.array([20.0, np.nan, 21.0])), r"speed\[1\] = nan"),
        (lambda: LeaderProfile(np.ones(3), np.r_[0.0, np.inf, 0.0], 0.1), r"accel\[1\] = inf"),
        (lambda: LeaderProfile(np.ones(3), np.zeros(4), 0.1), "shape"),
        (lambda: LeaderProfile(np.ones((2, 3)), np.zeros((2, 3)), 0.1), "shape"),
        (lambda: LeaderProfile(np.r_[1.0, -1.0], np.zeros(2), 0.1), r"speed\[1\] = -1"),
        (lambda: LeaderProfile(np.ones(3), np.zeros(3), 0.0), "dt = 0"),
        (lambda: LeaderProfile.from_acceleration(np.r_[0.0, np.nan]), r"accel\[1\] = nan"),
        (lambda: make_leader("rush_hour"), "scenario = 'rush_hour'"),
    ],
)
def test_bad_profiles_are_named(make, message):
    with pytest.raises(ValueError, match=message):
        make()


@pytest.mark.parametrize("family", ["ngsim", "ngsim_in_band"])
def test_ngsim_families_draw_real_vehicles_by_seed(family):
    if not default_ngsim_path().exists():
        pytest.skip(f"NGSIM data absent at {default_ngsim_path()}")
    first, again = make_leader(family, 4), make_leader(family, 4)
    np.testing.assert_array_equal(first.speed, again.speed)
    assert first.name.startswith("ngsim-") and first.duration >= LeaderConfig().ngsim_min_duration
    names = {make_leader(family, seed).name for seed in range(6)}
    assert len(names) > 1
    if family == "ngsim_in_band":
        low, high = LeaderConfig().speed_band
        assert low - 1e-9 <= first.speed.min() and first.speed.max() <= high + 1e-9


def test_idm_family_is_a_human_driver_behind_scripted_braking():
    first, again = make_leader("idm", 2), make_leader("idm", 2)
    np.testing.assert_array_equal(first.speed, again.speed)
    disturbance = make_leader("hard_braking", 2)
    assert first.name == "idm" and first.speed.size == disturbance.speed.size
    assert first.accel.min() < -1.0  # it brakes in answer to the disturbance ...
    assert first.accel.min() > disturbance.accel.min()  # ... more gently than the scripted braking
