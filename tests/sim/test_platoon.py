"""Platoon physics: exact discretisation, equilibrium, ramping, V2V switching, collisions, batching."""

import numpy as np
import pytest

from timegap_env.config import PlatoonConfig
from timegap_env.leaders import LeaderProfile
from timegap_env.sim.platoon import Platoon, ZOHCoefficients
from timegap_env.sim import simulate


@pytest.mark.parametrize("lag, gain", [(0.45, 1.0), (0.2, 0.8), (1.3, 1.2)])
def test_zoh_matches_closed_form_step_response(lag, gain):
    """From rest under a unit step command, 100 exact ticks land on the continuous solution."""
    dt, n_ticks, command = 0.1, 100, 1.0
    zoh = ZOHCoefficients.for_glvd(np.array([lag]), np.array([gain]), dt)
    x = v = a = np.zeros(1)
    for _ in range(n_ticks):
        x, v, a = zoh.step(x, v, a, np.array([command]), dt)
    t = n_ticks * dt
    decay = np.exp(-t / lag)
    assert a[0] == pytest.approx(gain * command * (1 - decay), rel=1e-12)
    assert v[0] == pytest.approx(gain * command * (t - lag * (1 - decay)), rel=1e-12)
    assert x[0] == pytest.approx(gain * command * (t**2 / 2 - lag * t + lag**2 * (1 - decay)), rel=1e-12)


def test_zoh_is_not_euler():
    """One Euler tick would give a = K u dt / T; the exact lag gives K u (1 - exp(-dt/T)), which differs."""
    zoh = ZOHCoefficients.for_glvd(np.array([0.45]), np.array([1.0]), 0.1)
    _, _, a = zoh.step(np.zeros(1), np.zeros(1), np.zeros(1), np.ones(1), 0.1)
    assert a[0] == pytest.approx(1 - np.exp(-0.1 / 0.45), rel=1e-12)
    assert abs(a[0] - 0.1 / 0.45) > 1e-2


def test_equilibrium_is_kept_behind_a_constant_speed_leader():
    trajectory = simulate(np.full(300, 25.0))
    assert np.allclose(trajectory.v, 25.0, atol=1e-9)
    assert np.allclose(trajectory.actual_time_gap, 1.6, atol=1e-9)
    assert np.allclose(trajectory.spacing, 5.0 + 1.6 * 25.0, atol=1e-9)


def test_setting_change_is_ramped_and_the_platoon_settles_on_it():
    config = PlatoonConfig(setting_ramp_rate=0.2)
    n_ticks = 600
    setting = np.full((n_ticks, config.n_followers), 1.6)
    setting[100:] = 1.0
    trajectory = simulate(np.full(n_ticks, 25.0), config, setting=setting)
    applied = trajectory.applied_setting[:, 0]
    assert np.max(np.abs(np.diff(applied))) <= 0.2 * config.dt + 1e-12
    ramp_ticks = int(round(0.6 / (0.2 * config.dt)))
    assert applied[100 + ramp_ticks // 2] == pytest.approx(1.3, abs=0.011)
    assert np.allclose(trajectory.actual_time_gap[-1], 1.0, atol=1e-3)


def test_v2v_loss_switches_to_acc_during_a_run():
    """Without feed-forward a follower brakes later: 1 s into the leader's braking it decelerates less."""
    leader = LeaderProfile.from_acceleration(np.r_[np.zeros(50), np.full(30, -3.0), np.zeros(120)])
    cacc = simulate(leader, v2v=True)
    acc = simulate(leader, v2v=False)
    mixed_schedule = np.ones((leader.speed.size, 5), dtype=bool)
    mixed_schedule[40:, 0] = False  # follower 1 loses V2V just before the braking
    mixed = simulate(leader, v2v=mixed_schedule)
    assert not mixed.v2v[60, 0] and mixed.v2v[20, 0]
    np.testing.assert_allclose(mixed.a[:, 1], acc.a[:, 1], atol=1e-12)
    one_second_in = 50 + 10
    assert cacc.a[one_second_in, 1] < acc.a[one_second_in, 1] - 0.5


def test_collision_is_detected_and_stops_the_run():
    """A leader that stops dead at 12 m/s^2 from 30 m/s with a tiny time gap gets hit."""
    speed = np.r_[np.full(20, 30.0), np.maximum(30.0 - 1.2 * np.arange(1, 40), 0.0), np.zeros(100)]
    trajectory = simulate(speed, PlatoonConfig(initial_setting=0.3, standstill_spacing=1.0), v2v=False)
    assert trajectory.collision is not None
    assert trajectory.collision.gap <= 0
    assert trajectory.t[-1] == pytest.approx(trajectory.collision.time)
    assert trajectory.spacing[-1, trajectory.collision.follower - 1] <= 0
    assert np.all(trajectory.spacing[:-1] > 0)


def test_batched_platoons_equal_single_ones():
    """Three platoons stepped together give the same arrays as each stepped alone."""
    config = PlatoonConfig()
    rng = np.random.default_rng(0)
    speeds = 20 + np.cumsum(rng.normal(0, 0.2, size=(3, 200)), axis=1)
    accels = np.gradient(speeds, config.dt, axis=1)
    lags = np.array([[0.3], [0.45], [0.7]])
    batch = Platoon(config, n_envs=3)
    batch.set_dynamics(lags, 1.0)
    batch.reset(speeds[:, 0], accels[:, 0])
    singles = [Platoon(config) for _ in range(3)]
    for env, single in enumerate(singles):
        single.set_dynamics(lags[env], 1.0)
        single.reset(speeds[env, 0], accels[env, 0])
    for k in range(1, 200):
        batch.step(speeds[:, k], accels[:, k])
        for env, single in enumerate(singles):
            single.step(speeds[env, k], accels[env, k])
    for env, single in enumerate(singles):
        np.testing.assert_array_equal(batch.x[env], single.x[0])
        np.testing.assert_array_equal(batch.a[env], single.a[0])


def test_partial_reset_leaves_other_platoons_alone():
    platoon = Platoon(PlatoonConfig(), n_envs=2)
    platoon.reset([20.0, 30.0])
    for _ in range(10):
        platoon.step([21.0, 31.0], [1.0, 1.0])
    before = platoon.x[1].copy()
    platoon.reset([25.0, 0.0], mask=[True, False])
    np.testing.assert_array_equal(platoon.x[1], before)
    assert np.all(platoon.v[0] == 25.0)


def test_followers_do_not_reverse():
    speed = np.r_[np.full(20, 5.0), np.maximum(5.0 - 0.5 * np.arange(1, 30), 0.0), np.zeros(200)]
    trajectory = simulate(speed)
    assert trajectory.v.min() >= 0.0


@pytest.mark.parametrize(
    "call, field",
    [
        (lambda p: p.set_dynamics(np.zeros(5), 1.0), "actuation_lag"),
        (lambda p: p.set_dynamics(0.45, -1.0), "actuation_gain"),
        (lambda p: p.set_dynamics(np.ones(4), 1.0), "actuation_lag"),
        (lambda p: p.request_setting(0.0), "setting"),
        (lambda p: p.step([20.0, 20.0], 0.0), "leader_speed"),
        (lambda p: p.step(np.nan, 0.0), "leader_speed"),
        (lambda p: p.reset(-1.0), "leader_speed"),
    ],
)
def test_platoon_rejects_bad_input(call, field):
    with pytest.raises(ValueError, match=field):
        call(Platoon(PlatoonConfig()))


def test_platoon_rejects_bad_n_envs():
    with pytest.raises(ValueError, match="n_envs"):
        Platoon(PlatoonConfig(), n_envs=0)
