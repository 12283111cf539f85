"""The IDM leader: highway-env's IDM driver following a scripted disturbance."""

import numpy as np
import pytest
from highway_env.vehicle.behavior import IDMVehicle

from timegap_env.config import LeaderConfig
from timegap_env.leaders.idm import build_scene, idm_leader
from timegap_env.leaders import LeaderProfile

DT = 0.1  # [s]
GAP = 40.0  # initial bumper-to-bumper gap where a test sets it [m]


def sinusoid(seconds: float = 60.0, mean: float = 22.0, amplitude: float = 4.0, period: float = 20.0) -> LeaderProfile:
    t = np.arange(int(round(seconds / DT)) + 1) * DT
    return LeaderProfile.from_speed(mean + amplitude * np.sin(2 * np.pi * t / period), dt=DT)


def braking(decel: float, brake_s: float, recover: float = 0.0, seconds: float = 40.0, cruise: float = 25.0) -> LeaderProfile:
    """Cruise, brake at ``decel`` [m/s^2] for ``brake_s`` [s] from t = 10 s, then accelerate back to ``cruise`` [m/s] at ``recover`` [m/s^2]."""
    accel = np.zeros(int(round(seconds / DT)) + 1)
    start = int(round(10.0 / DT))
    end = start + int(round(brake_s / DT))
    accel[start:end] = -decel
    accel[end:] = recover
    return LeaderProfile.from_acceleration(accel, LeaderConfig(dt=DT, initial_speed=cruise, speed_band=(0.0, cruise)))


def bumper_gap(disturbance: LeaderProfile, follower: LeaderProfile, initial_gap: float) -> np.ndarray:
    """Gap [m] at every sample, integrating both speeds as highway-env does (position += speed * dt)."""
    closing = (disturbance.speed[:-1] - follower.speed[:-1]) * DT
    return initial_gap + np.concatenate([[0.0], np.cumsum(closing)])


def test_follows_the_disturbance_at_a_bounded_gap():
    disturbance = sinusoid()
    leader = idm_leader(disturbance, initial_gap=GAP)
    assert leader.name == "idm" and leader.dt == DT and leader.speed.shape == disturbance.speed.shape
    later = slice(-400, None)  # the last two periods
    assert abs(leader.speed[later].mean() - disturbance.speed[later].mean()) < 0.3
    assert leader.speed.std() > 0.5 * disturbance.speed.std()  # it reacts, it does not just cruise
    gap = bumper_gap(disturbance, leader, GAP)
    assert 10.0 < gap.min() and gap.max() < 80.0


def test_default_initial_gap_is_an_equilibrium():
    leader = idm_leader(braking(decel=4.0, brake_s=2.0))
    assert np.abs(leader.speed[:100] - 25.0).max() < 0.05  # steady before the braking at t = 10 s


def test_reacts_to_braking_with_a_lag():
    disturbance = braking(decel=5.0, brake_s=2.0, recover=1.0)  # a single speed minimum, at t = 12 s
    leader = idm_leader(disturbance)
    lag = (np.argmin(leader.speed) - np.argmin(disturbance.speed)) * DT
    assert 0.3 < lag < 8.0
    drop, leader_drop = 25.0 - disturbance.speed.min(), 25.0 - leader.speed.min()
    assert 0.3 * drop < leader_drop < 1.2 * drop


def test_speed_above_highway_envs_default_lane_limit():
    disturbance = sinusoid(mean=33.0, amplitude=1.0)  # the default straight road would cap it at 30 m/s
    leader = idm_leader(disturbance)
    assert leader.speed[-100:].mean() > 32.0


def test_acceleration_is_the_speed_derivative():
    for disturbance in (sinusoid(), braking(decel=5.0, brake_s=2.0), braking(decel=6.0, brake_s=4.0)):
        leader = idm_leader(disturbance, seed=3)
        np.testing.assert_allclose(np.diff(leader.speed) / DT, leader.accel[:-1], atol=1e-9)


def test_stops_at_standstill_without_reversing():
    disturbance = braking(decel=6.0, brake_s=5.0)  # 25 m/s to a stop, then stays stopped
    assert disturbance.speed[-1] == 0.0
    leader = idm_leader(disturbance, initial_gap=GAP)
    assert np.all(np.isfinite(leader.speed)) and np.all(np.isfinite(leader.accel))
    assert leader.speed.min() >= 0.0 and leader.speed[-1] == 0.0
    assert bumper_gap(disturbance, leader, GAP)[-1] > 1.0


def test_same_seed_same_arrays_and_global_random_state_untouched():
    disturbance = sinusoid(seconds=30.0)
    np.random.seed(12345)
    state = np.random.get_state()[1].copy()
    first = idm_leader(disturbance, seed=7)
    second = idm_leader(disturbance, seed=7)
    np.testing.assert_array_equal(first.speed, second.speed)
    np.testing.assert_array_equal(first.accel, second.accel)
    np.testing.assert_array_equal(np.random.get_state()[1], state)


def test_different_seeds_give_different_drivers():
    disturbance = sinusoid(seconds=30.0)
    speeds = [idm_leader(disturbance, seed=seed).speed for seed in (0, 1)]
    assert np.abs(speeds[0] - speeds[1]).max() > 0.1
    unseeded = build_scene(disturbance)[2]
    seeded = build_scene(disturbance, seed=0)[2]
    assert (unseeded.DELTA, unseeded.TIME_WANTED) == (IDMVehicle.DELTA, IDMVehicle.TIME_WANTED)
    assert IDMVehicle.DELTA_RANGE[0] <= seeded.DELTA <= IDMVehicle.DELTA_RANGE[1]
    assert seeded.DELTA != IDMVehicle.DELTA and seeded.TIME_WANTED != IDMVehicle.TIME_WANTED


def test_scene_is_a_highway_env_road_with_an_idm_driver():
    disturbance = sinusoid(seconds=10.0)
    road, scripted, driver = build_scene(disturbance, initial_gap=GAP)
    assert isinstance(driver, IDMVehicle) and not driver.enable_lane_change
    assert road.vehicles == [scripted, driver]
    assert road.neighbour_vehicles(driver) == (scripted, None)
    assert driver.lane_distance_to(scripted) == pytest.approx(GAP + driver.LENGTH)


def test_realised_acceleration_is_highway_envs_idm_output(monkeypatch):
    monkeypatch.setattr(IDMVehicle, "acceleration", lambda self, *args, **kwargs: 0.5)
    leader = idm_leader(sinusoid(seconds=5.0), initial_gap=GAP)
    np.testing.assert_array_equal(leader.accel, 0.5)


def test_collision_raises():
    speed = np.r_[np.full(10, 30.0), np.zeros(200)]  # an instant stop from 30 m/s: a wall
    with pytest.raises(RuntimeError, match="collides with the disturbance"):
        idm_leader(LeaderProfile.from_speed(speed, dt=DT))


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"target_speed": -1.0}, "target_speed"),
        ({"target_speed": float("nan")}, "target_speed"),
        ({"initial_gap": 0.0}, "initial_gap"),
        ({"initial_gap": 1e4}, "initial_gap"),
        ({"target_speed": 20.0}, "target_speed"),  # below the initial 25 m/s: no equilibrium gap
    ],
)
def test_bad_arguments_name_the_field(kwargs, field):
    with pytest.raises(ValueError, match=field):
        idm_leader(braking(decel=4.0, brake_s=2.0, seconds=5.0), **kwargs)
