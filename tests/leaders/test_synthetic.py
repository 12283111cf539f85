"""The seeded synthetic leader families: reproducible, in band, and what each one promises."""

import math

import numpy as np
import pytest

from timegap_env.config import AggressiveCyclesConfig, LeaderConfig, StochasticHumanConfig
from timegap_env.leaders import make_leader, synthetic
from timegap_env.leaders.profile import LeaderProfiles

FAMILIES = ["aggressive_cycles", "hard_braking", "sinusoid", "stochastic_human"]


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
    profile = synthetic.aggressive_cycles(3, params)
    accel = profile.accel
    assert accel.max() > params.accel_range[0] and accel.min() < -params.accel_range[0]
    assert np.abs(accel).max() <= params.accel_range[1] + 1e-9
    sign_changes = np.count_nonzero(np.diff(np.sign(accel[np.abs(accel) > 1.0])) != 0)
    assert sign_changes >= 10  # many cycles in 250 s
    assert np.abs(np.diff(accel)).max() <= params.max_jerk * profile.dt + 1e-9


def test_hard_braking_brakes_hard():
    profile = make_leader("hard_braking", 0)
    assert profile.accel.min() <= -4.0


@pytest.mark.parametrize("family", [*FAMILIES, "stop_and_go", "emergency_braking"])
def test_a_batch_holds_each_seeds_own_profile(family):
    seeds = [5, 0, 123, 5, 2**31 - 1]
    batch = getattr(synthetic, f"{family}_batch")(seeds)
    for row, seed in enumerate(seeds):
        single = getattr(synthetic, family)(seed)
        np.testing.assert_array_equal(batch.speed[row], single.speed)
        np.testing.assert_array_equal(batch.accel[row], single.accel)
        assert batch.profile(row).name == single.name


def test_the_first_cycle_sign_is_what_choice_of_two_draws():
    for seed in range(5000):
        ours, numpy = np.random.default_rng(seed), np.random.default_rng(seed)
        assert (-1.0, 1.0)[int(ours.integers(2))] == numpy.choice([-1.0, 1.0])
        assert ours.bit_generator.state == numpy.bit_generator.state


@pytest.mark.parametrize("dt", [0.01, 0.1, 1.0])
def test_the_sinusoid_kernel_is_numpys_formula_bit_for_bit(dt):
    rng = np.random.default_rng(int(100 * dt))
    rows, n = 64, 3001
    amplitude, omega = rng.uniform(0.1, 10.0, rows), rng.uniform(0.01, 3.0, rows)
    phase, mean = rng.uniform(0.0, 2.0 * np.pi, rows), rng.uniform(5.0, 30.0, rows)
    speed, accel = np.empty((rows, n)), np.empty((rows, n))
    synthetic._sinusoid_rows(amplitude, omega, phase, mean, dt, speed, accel)
    t = np.arange(n) * dt
    a, w, p, m = (values[:, None] for values in (amplitude, omega, phase, mean))
    assert speed.tobytes() == (m + a * np.sin(w * t + p)).tobytes()
    assert accel.tobytes() == (a * w * np.cos(w * t + p)).tobytes()


def test_uniform_numbers_scale_as_numpys_uniform_draws():
    bounds = np.random.default_rng(1).uniform(-50.0, 50.0, (500, 2))
    for seed, (low, high) in enumerate(np.sort(bounds).tolist()):
        ours, numpy = np.random.default_rng(seed), np.random.default_rng(seed)
        assert synthetic._uniform((low, high), ours.random()).hex() == numpy.uniform(low, high).hex()
        assert synthetic._uniform((low, high), ours.random(50)).tobytes() == numpy.uniform(low, high, 50).tobytes()


def test_the_stochastic_human_is_its_draws_pursued_tick_by_tick_then_integrated_in_band():
    """Its one kernel (pursuit and integration in one pass, from the raw draws) gives what the draws as numpy
    makes them, the pursuit written out and LeaderProfiles.from_acceleration give, bit for bit."""
    params, leader = StochasticHumanConfig(), LeaderConfig(duration=60.0)
    seeds = [0, 3, 2**31 - 1]
    batch = synthetic.stochastic_human_batch(seeds, params, leader)
    n, dt, (low, high) = leader.n_samples, leader.dt, leader.speed_band
    decay = np.exp(-dt / params.accel_correlation_time)
    for row, seed in enumerate(seeds):
        rng = np.random.default_rng(seed)
        innovations = params.accel_std * np.sqrt(1.0 - decay**2) * rng.standard_normal(n)
        changes, targets = rng.random(n) < dt / params.target_change_interval, rng.uniform(low, high, size=n)
        accel, speed, target, noise = np.empty(n), leader.initial_speed, leader.initial_speed, 0.0
        for k in range(n):
            target = targets[k] if changes[k] else target
            noise = decay * noise + innovations[k]
            accel[k] = params.speed_gain * (target - speed) + noise
            speed = min(max(speed + accel[k] * dt, low), high)
        expected = LeaderProfiles.from_acceleration(accel[None], leader)
        assert batch.speed[row].tobytes() == expected.speed[0].tobytes()
        assert batch.accel[row].tobytes() == expected.accel[0].tobytes()


def concatenated_trapezoid(change: float, magnitude: float, max_jerk: float, dt: float) -> np.ndarray:
    """``_speed_change`` as it was written before (ebee3a3): the ramp up, the plateau and the ramp down concatenated."""
    size = abs(change)
    planned = min(magnitude, math.sqrt(size * max_jerk))
    ramp = max(1, math.ceil(planned / (max_jerk * dt) - 1e-9))
    plateau = max(0, math.ceil(size / (planned * dt) - ramp - 1e-9))
    peak = size / (dt * (ramp + plateau))
    shape = np.concatenate((np.arange(1, ramp + 1) / ramp, np.ones(plateau), np.arange(ramp - 1, 0, -1) / ramp))
    return math.copysign(peak, change) * shape


@pytest.mark.parametrize("dt", [0.01, 0.1, 1.0])
def test_a_speed_change_is_the_ramp_up_the_plateau_and_the_ramp_down_bit_for_bit(dt):
    draws = np.random.default_rng(3).uniform((-20.0, 0.1, 0.5), (20.0, 8.0, 30.0), (3000, 3))
    for change, magnitude, max_jerk in [*draws.tolist(), (1e-6, 2.0, 5.0), (-1e-6, 2.0, 5.0), (30.0, 8.0, 0.5)]:
        shape = synthetic._speed_change(change, magnitude, max_jerk, dt)
        assert shape.tobytes() == concatenated_trapezoid(change, magnitude, max_jerk, dt).tobytes()
        assert math.isclose(shape.sum() * dt, change, rel_tol=1e-9)
