"""LeaderProfile: integration within a band, the user's arrays and CSV files, errors that name what is wrong."""

import numpy as np
import pytest

from timegap_env.config import MPH, LeaderConfig
from timegap_env.leaders import LeaderProfile, make_leader


def test_from_acceleration_integrates_and_holds_the_band():
    leader = LeaderConfig(initial_speed=20.0)
    profile = LeaderProfile.from_acceleration(np.r_[np.full(30, 1.0), np.full(400, 3.0), np.full(600, -3.0)], leader)
    assert profile.speed[30] == pytest.approx(23.0)
    low, high = leader.speed_band
    assert profile.speed.min() == pytest.approx(low) and profile.speed.max() == pytest.approx(high)
    assert (low, high) == pytest.approx((20 * MPH, 80 * MPH))
    np.testing.assert_allclose(np.diff(profile.speed) / profile.dt, profile.accel[:-1], atol=1e-9)
    assert np.all(profile.accel[profile.speed >= high - 1e-12][:-1] <= 1e-9)


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
        ("speed\n20\nnan\n", "row 3, column 'speed' = 'nan' is not a finite number"),
        ("speed\n20\n\n21\nfast\n", "row 5, column 'speed' = 'fast'"),  # a blank line is skipped, yet counted
        ("time,speed\n0,20\n0.1\n", r"row 3 has fewer fields than the header \(2\)"),
        ("speed\n20\n", "one data row after the header; a profile needs at least 2"),
    ],
)
def test_malformed_user_csv_is_named(tmp_path, content, message):
    path = tmp_path / "bad.csv"
    path.write_text(content)
    with pytest.raises(ValueError, match=message) as error:
        LeaderProfile.from_csv(path)
    assert str(error.value).startswith(f"{path}: ")


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
