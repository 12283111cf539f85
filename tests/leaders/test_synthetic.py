"""The seeded synthetic leader families: reproducible, in band, and what each one promises."""

import numpy as np
import pytest

from timegap_env.config import AggressiveCyclesConfig, LeaderConfig
from timegap_env.leaders import make_leader, synthetic

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
