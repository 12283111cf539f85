"""Calibration: a follower simulated with known parameters and sensor noise is recovered; the replay is the platoon's physics."""

import numpy as np
import pytest

import timegap_env
from timegap_env.config import AggressiveCyclesConfig, LeaderConfig, PlatoonConfig, SensorConfig
from timegap_env.sim.calibration import (
    FollowerModel, Segment, fit_follower, record_segments, simulate_follower,
)

TRUE = FollowerModel(lag=0.8, k_s=0.12, k_v=0.45, standstill_spacing=3.0, accel_min=-3.0, accel_max=1.5)
SETTINGS = {"S": 1.2, "L": 2.4}
KNOWN = PlatoonConfig(standstill_spacing=TRUE.standstill_spacing, accel_min=TRUE.accel_min)  # what the fit holds


def recorded_follower(seed: int, setting: float, noise: SensorConfig) -> list[Segment]:
    """A follower with TRUE parameters behind a leader with slow accelerations and brakings, as records with noise."""
    leader = timegap_env.aggressive_cycles(seed, AggressiveCyclesConfig(accel_range=(0.5, 2.0)),
                                           LeaderConfig(duration=200.0, initial_speed=12.0, speed_band=(3.0, 25.0)))
    config = PlatoonConfig(n_followers=1, v2v=False, initial_setting=setting, actuation_lag=TRUE.lag, k_s=TRUE.k_s,
                           k_v=TRUE.k_v, standstill_spacing=TRUE.standstill_spacing, accel_min=TRUE.accel_min,
                           accel_max=TRUE.accel_max)
    run = timegap_env.simulate(leader, config)
    rng = np.random.default_rng(seed)
    noisy = [values + rng.normal(0.0, std, values.shape) for values, std in (
        (run.v[:, 1], noise.speed_noise_std), (run.v[:, 0], noise.speed_noise_std), (run.spacing[:, 0], noise.spacing_noise_std))]
    return record_segments(*noisy, config.dt, min_duration=30.0)


def fit_three_runs(noise: SensorConfig, seeds: tuple[int, int, int] = (1, 2, 3)):
    """The fit on three recorded runs of the TRUE follower: two at setting S, one at L."""
    segments, names = [], []
    for seed, name in zip(seeds, ("S", "L", "S")):
        found = recorded_follower(seed, SETTINGS[name], noise)
        segments += found
        names += [name] * len(found)
    return segments, names, fit_follower(segments, names, KNOWN)


@pytest.mark.parametrize(
    "noise, tolerance",
    [
        # GNSS-grade records: 5 cm spacing, 2 cm/s speed noise
        (SensorConfig(spacing_noise_std=0.05, speed_noise_std=0.02),
         {"setting": 0.01, "k_s": 0.05, "k_v": 0.05, "lag": 0.10, "accel_max": 0.05}),
        # the project's sensors (0.1 m, 0.1 m/s): the speed noise, integrated into the predecessor's position,
        # biases the lag most; over six triples of seeds the errors reached lag -40 %, k_s +16 %, k_v -9 %,
        # highest command -0.03 m/s^2, tau* 0.007 s (these seeds: the worst)
        (SensorConfig(), {"setting": 0.02, "k_s": 0.25, "k_v": 0.15, "lag": 0.5, "accel_max": 0.1}),
    ],
)
def test_the_fit_recovers_known_parameters_from_noisy_records(noise, tolerance):
    """s0 and the lowest command are held at the truth, as the calibration holds them (its braking stays above
    accel_min in these runs: that bound is not recoverable from them)."""
    segments, names, fit = fit_three_runs(noise)
    assert fit.settings == pytest.approx(SETTINGS, abs=tolerance["setting"])
    assert (fit.model.standstill_spacing, fit.model.accel_min) == (TRUE.standstill_spacing, TRUE.accel_min)
    assert fit.model.k_s == pytest.approx(TRUE.k_s, rel=tolerance["k_s"])
    assert fit.model.k_v == pytest.approx(TRUE.k_v, rel=tolerance["k_v"])
    assert fit.model.lag == pytest.approx(TRUE.lag, rel=tolerance["lag"])
    assert fit.model.accel_max == pytest.approx(TRUE.accel_max, abs=tolerance["accel_max"])
    default = fit_follower(segments, names, free=False)
    assert default.model == FollowerModel.of(PlatoonConfig()) and default.spacing_rmse > 3 * fit.spacing_rmse


def test_without_noise_the_fit_is_exact():
    segments = recorded_follower(1, 1.2, SensorConfig(spacing_noise_std=0.0, speed_noise_std=0.0))
    fit = fit_follower(segments, ["S"] * len(segments), KNOWN)
    assert fit.settings["S"] == pytest.approx(1.2, abs=1e-3) and fit.model.k_s == pytest.approx(TRUE.k_s, rel=1e-2)
    assert fit.spacing_rmse < 0.01


def test_the_replay_follows_a_recorded_predecessor_like_the_platoon():
    """simulate_follower behind the platoon's own leader gives the platoon's follower (to the integration of positions)."""
    leader = timegap_env.hard_braking(0, leader=LeaderConfig(duration=120.0))
    config = PlatoonConfig(n_followers=1, v2v=False, initial_setting=1.6)
    run = timegap_env.simulate(leader, config)
    (segment,) = record_segments(run.v[:, 1], run.v[:, 0], run.spacing[:, 0], config.dt, min_duration=30.0)
    spacing, speed = simulate_follower(segment, FollowerModel.of(config), 1.6, config)
    np.testing.assert_allclose(speed, run.v[:, 1], atol=1e-3)
    np.testing.assert_allclose(spacing, run.spacing[:, 0], atol=0.05)


def test_segments_skip_gaps_and_short_stretches():
    speed, spacing = np.full(1000, 10.0), np.full(1000, 20.0)
    spacing[300] = np.nan  # a gap
    spacing[600:610] = -0.5  # GNSS puts the cars into each other: not a spacing
    segments = record_segments(speed, speed, spacing, 0.1, min_duration=29.85)
    assert [segment.speed.size for segment in segments] == [300, 390]  # 29.9 s and 38.9 s stay, 29.8 s goes
    np.testing.assert_allclose(segments[1].predecessor_position, 20.0 + np.arange(390) * 1.0)  # 10 m/s, 0.1 s ticks
