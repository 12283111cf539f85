"""Seeded synthetic leaders: the same seed gives the same profile.

- :func:`aggressive_cycles`: the paper's leader, alternating hard acceleration and deceleration;
- :func:`sinusoid`: a speed oscillation;
- :func:`hard_braking`: cruising with hard braking events;
- :func:`stochastic_human`: a human-like wandering speed.

Each takes a seed, its own parameters (a config of :mod:`timegap_env.config`) and the
:class:`~timegap_env.config.LeaderConfig` every profile shares (tick, length, speed band).
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from timegap_env.config import (
    AggressiveCyclesConfig,
    HardBrakingConfig,
    LeaderConfig,
    SinusoidConfig,
    StochasticHumanConfig,
)
from timegap_env.leaders.profile import LeaderProfile


def aggressive_cycles(
    seed: int | None,
    params: AggressiveCyclesConfig = AggressiveCyclesConfig(),
    leader: LeaderConfig = LeaderConfig(),
) -> LeaderProfile:
    """The paper's leader: alternating acceleration and deceleration phases, e.g. +/-1.5-3.5 m/s^2 for 3-9 s.

    The acceleration moves between phases at ``max_jerk``. A phase whose sign
    would drive the speed out of the band takes the other sign, and is cut
    short where it would still leave the band.
    """
    rng = np.random.default_rng(seed)
    low, high = leader.speed_band
    jerk_step = params.max_jerk * leader.dt  # largest change of acceleration in one tick [m/s^2]
    accel = np.zeros(leader.n_samples)
    sign = rng.choice([-1.0, 1.0])
    speed, current, k = leader.initial_speed, 0.0, 0
    while k < leader.n_samples:  # phase by phase, then tick by tick: each phase depends on the speed reached
        length = int(round(rng.uniform(*params.phase_duration_range) / leader.dt))
        magnitude = rng.uniform(*params.accel_range)
        target = 0.0
        if rng.random() >= params.cruise_probability:
            if not low <= speed + sign * magnitude * length * leader.dt <= high:
                sign = -sign
            ramp_margin = (magnitude + abs(current)) ** 2 / params.max_jerk  # gained while ramping in and out [m/s]
            room = (high - speed if sign > 0 else speed - low) - ramp_margin  # [m/s]
            length = max(1, min(length, int(room / (magnitude * leader.dt))))
            target = sign * magnitude
            sign = -sign
        ticks = min(length, leader.n_samples - k)
        current, speed = _jerk_limited_phase(accel[k : k + ticks], current, target, jerk_step, speed, leader.dt)
        k += ticks
    return LeaderProfile.from_acceleration(accel, leader, name="aggressive_cycles")


def sinusoid(
    seed: int | None, params: SinusoidConfig = SinusoidConfig(), leader: LeaderConfig = LeaderConfig()
) -> LeaderProfile:
    """Speed oscillation around the initial speed with a seeded amplitude, period and phase, inside the band."""
    rng = np.random.default_rng(seed)
    low, high = leader.speed_band
    amplitude = min(rng.uniform(*params.amplitude_range), 0.5 * (high - low))
    period = rng.uniform(*params.period_range)
    phase = rng.uniform(0.0, 2.0 * np.pi)
    mean = min(max(leader.initial_speed, low + amplitude), high - amplitude)
    omega = 2.0 * np.pi / period
    t = np.arange(leader.n_samples) * leader.dt
    speed = mean + amplitude * np.sin(omega * t + phase)
    accel = amplitude * omega * np.cos(omega * t + phase)
    return LeaderProfile(speed=speed, accel=accel, dt=leader.dt, name="sinusoid")


def hard_braking(
    seed: int | None, params: HardBrakingConfig = HardBrakingConfig(), leader: LeaderConfig = LeaderConfig()
) -> LeaderProfile:
    """Cruise at the initial speed, brake hard ``n_events`` times at seeded moments, recover each time."""
    rng = np.random.default_rng(seed)
    accel = np.zeros(leader.n_samples)
    slot = leader.n_samples // params.n_events  # one event per slot, so events never overlap
    for event in range(params.n_events):
        decel = rng.uniform(*params.decel_range)
        drop = min(rng.uniform(*params.speed_drop_range), leader.initial_speed - leader.speed_band[0])
        brake_ticks = int(round(drop / decel / leader.dt))
        recover_ticks = int(round(drop / params.recovery_accel / leader.dt))
        latest_start = max(slot - brake_ticks - recover_ticks, 1)
        start = event * slot + int(rng.integers(0, latest_start))
        accel[start : start + brake_ticks] = -decel
        accel[start + brake_ticks : start + brake_ticks + recover_ticks] = params.recovery_accel
    return LeaderProfile.from_acceleration(accel, leader, name="hard_braking")


class _HumanDraws(NamedTuple):
    """The stochastic human's random draws, one per tick."""

    innovations: np.ndarray  # (n,) innovations of the AR(1) acceleration noise [m/s^2]
    target_changes: np.ndarray  # (n,) the target speed changes at this tick [bool]
    new_targets: np.ndarray  # (n,) the target speed if it changes [m/s]


class _HumanMotion(NamedTuple):
    """The stochastic human's constants."""

    initial_speed: float  # [m/s]
    noise_decay: float  # AR(1) factor of the acceleration noise per tick [-]
    speed_gain: float  # pull of the speed towards the target [1/s]
    dt: float  # [s]
    low: float  # speed band [m/s]
    high: float  # [m/s]


def stochastic_human(
    seed: int | None,
    params: StochasticHumanConfig = StochasticHumanConfig(),
    leader: LeaderConfig = LeaderConfig(),
) -> LeaderProfile:
    """A human-like leader: a target speed that changes at random moments, pursued with correlated noise.

    acceleration = speed_gain (target - v) + eta, eta an Ornstein-Uhlenbeck process.
    """
    rng = np.random.default_rng(seed)
    low, high = leader.speed_band
    n, dt = leader.n_samples, leader.dt
    decay = np.exp(-dt / params.accel_correlation_time)
    draws = _HumanDraws(
        innovations=params.accel_std * np.sqrt(1.0 - decay**2) * rng.standard_normal(n),
        target_changes=rng.random(n) < dt / params.target_change_interval,
        new_targets=rng.uniform(low, high, size=n),
    )
    motion = _HumanMotion(*(float(value) for value in (leader.initial_speed, decay, params.speed_gain, dt, low, high)))
    return LeaderProfile.from_acceleration(_pursue_targets(tuple(draws), tuple(motion)), leader, name="stochastic_human")


# Compiled loops; each runs in order because every step depends on the speed reached so far.
@numba.njit(cache=True)
def _jerk_limited_phase(accel, current, target, jerk_step, speed, dt):  # noqa: ANN001, ANN202
    """Fill ``accel`` [m/s^2] moving from ``current`` towards ``target`` by at most ``jerk_step`` a tick;
    returns the final acceleration and the speed [m/s] reached from ``speed``."""
    for k in range(accel.size):
        current += min(max(target - current, -jerk_step), jerk_step)
        accel[k] = current
        speed += current * dt
    return current, speed


@numba.njit(cache=True)
def _pursue_targets(draws, motion):  # noqa: ANN001, ANN202
    """The stochastic human's acceleration [m/s^2]: speed_gain (target - v) plus an AR(1) noise; ``draws``
    (:class:`_HumanDraws`) and ``motion`` (:class:`_HumanMotion`) come as plain tuples, as in every kernel."""
    draws, motion = _HumanDraws(*draws), _HumanMotion(*motion)
    accel = np.empty(draws.innovations.size)
    speed, target, noise = motion.initial_speed, motion.initial_speed, 0.0
    for k in range(draws.innovations.size):
        if draws.target_changes[k]:
            target = draws.new_targets[k]
        noise = motion.noise_decay * noise + draws.innovations[k]
        accel[k] = motion.speed_gain * (target - speed) + noise
        speed = min(max(speed + accel[k] * motion.dt, motion.low), motion.high)
    return accel
