"""Seeded synthetic leaders: the same seed gives the same profile.

- :func:`aggressive_cycles`: the paper's leader, alternating hard acceleration and deceleration;
- :func:`sinusoid`: a speed oscillation;
- :func:`hard_braking`: cruising with hard braking events;
- :func:`stochastic_human`: a human-like wandering speed;
- :func:`stop_and_go`: congestion waves, braking to a crawl (0-5 m/s) and back, again and again;
- :func:`emergency_braking`: highway cruising with emergency stops at 6-7.5 m/s^2.

Each takes a seed, its own parameters (a config of :mod:`timegap_env.config`) and the
:class:`~timegap_env.config.LeaderConfig` every profile shares (tick, length, speed band).

The last two are harsh, held-out families (:data:`~timegap_env.leaders.scenarios.HELD_OUT_FAMILIES`):
the default training mix (``EnvConfig.scenario_weights``) never draws them. They leave the band's
low end on purpose (their speeds lie in [0, speed_band[1]]), their accelerations stay within the
followers' command limits [``PlatoonConfig.accel_min``, ``PlatoonConfig.accel_max``] = [-8, 4] m/s^2
(a follower can always brake harder than the leader) and change by at most their ``max_jerk``.
Their parameters (:class:`StopAndGoConfig`, :class:`EmergencyBrakingConfig`) live here for now, with
the same validation as the configs of :mod:`timegap_env.config`.
"""

from __future__ import annotations

import dataclasses
import math
from typing import NamedTuple

import numba
import numpy as np

from timegap_env.config import (
    MAX_ACCEL,
    MAX_DURATION,
    MAX_JERK,
    MAX_SPEED,
    AggressiveCyclesConfig,
    ConfigMixin,
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


@dataclasses.dataclass(frozen=True)
class StopAndGoConfig(ConfigMixin):
    """Congestion waves: cruise, brake hard to a crawl, crawl, accelerate back to the cruise speed, repeat."""

    cruise_speed_range: tuple[float, float] = (15.0, 25.0)  # speed between the waves, one per seed [m/s], in
    # (0, MAX_SPEED]
    crawl_speed_range: tuple[float, float] = (0.0, 5.0)  # speed at the bottom of a wave, one per wave [m/s], in
    # [0, MAX_SPEED], below cruise_speed_range
    decel_range: tuple[float, float] = (2.0, 4.0)  # magnitude of a wave's braking [m/s^2], in (0, MAX_ACCEL]
    accel_range: tuple[float, float] = (1.0, 2.5)  # acceleration out of a wave (and to the first cruise) [m/s^2], in
    # (0, MAX_ACCEL]
    crawl_duration_range: tuple[float, float] = (2.0, 10.0)  # time at the crawl speed [s], in (0, MAX_DURATION]
    cruise_duration_range: tuple[float, float] = (10.0, 40.0)  # time at the cruise speed before each wave [s], in
    # (0, MAX_DURATION]
    max_jerk: float = 5.0  # largest rate of change of the acceleration, a brisk human driver [m/s^3], (0, MAX_JERK]

    def __post_init__(self) -> None:
        self._pair("cruise_speed_range", 0.0, MAX_SPEED, open_low=True)
        self._pair("crawl_speed_range", 0.0, MAX_SPEED)
        for field in ("decel_range", "accel_range"):
            self._pair(field, 0.0, MAX_ACCEL, open_low=True)
        for field in ("crawl_duration_range", "cruise_duration_range"):
            self._pair(field, 0.0, MAX_DURATION, open_low=True)
        self._number("max_jerk", 0.0, MAX_JERK, open_low=True)
        if self.crawl_speed_range[1] >= self.cruise_speed_range[0]:
            self._fail("crawl_speed_range", self.crawl_speed_range,
                       f"must lie below cruise_speed_range {self.cruise_speed_range}")


@dataclasses.dataclass(frozen=True)
class EmergencyBrakingConfig(ConfigMixin):
    """Highway cruising with emergency stops: near-full braking to a low speed or standstill, a pause, recovery."""

    cruise_speed_range: tuple[float, float] = (25.0, 33.0)  # highway speed (56-74 mph), one per seed [m/s], in
    # (0, MAX_SPEED]
    n_events_range: tuple[int, int] = (1, 3)  # emergency stops per profile, both ends included [-], integers
    # 1 <= low <= high <= 100
    decel_range: tuple[float, float] = (6.0, 7.5)  # braking: near a car's ~8-9, below the followers' 8 [m/s^2], in
    # (0, MAX_ACCEL]
    standstill_probability: float = 0.5  # chance that a stop ends at standstill, not at a low speed [-], [0, 1]
    low_speed_range: tuple[float, float] = (1.0, 5.0)  # speed a stop ends at when not at standstill [m/s], in
    # (0, MAX_SPEED], below cruise_speed_range
    pause_duration_range: tuple[float, float] = (2.0, 8.0)  # time at the low speed or standstill [s], in
    # (0, MAX_DURATION]
    recovery_accel_range: tuple[float, float] = (1.5, 3.0)  # re-acceleration to the cruise speed [m/s^2], in
    # (0, MAX_ACCEL]
    min_cruise_duration: float = 10.0  # least cruising before each stop [s], (0, MAX_DURATION]
    max_jerk: float = 15.0  # largest rate of change of the acceleration; full braking builds up in 0.4-0.5 s
    # [m/s^3], (0, MAX_JERK]

    def __post_init__(self) -> None:
        self._pair("n_events_range", 1, 100, strict=False, integer=True)
        for field in ("cruise_speed_range", "low_speed_range"):
            self._pair(field, 0.0, MAX_SPEED, open_low=True)
        for field in ("decel_range", "recovery_accel_range"):
            self._pair(field, 0.0, MAX_ACCEL, open_low=True)
        self._pair("pause_duration_range", 0.0, MAX_DURATION, open_low=True)
        self._number("standstill_probability", 0.0, 1.0)
        self._number("min_cruise_duration", 0.0, MAX_DURATION, open_low=True)
        self._number("max_jerk", 0.0, MAX_JERK, open_low=True)
        if self.low_speed_range[1] >= self.cruise_speed_range[0]:
            self._fail("low_speed_range", self.low_speed_range,
                       f"must lie below cruise_speed_range {self.cruise_speed_range}")


def stop_and_go(
    seed: int | None, params: StopAndGoConfig = StopAndGoConfig(), leader: LeaderConfig = LeaderConfig()
) -> LeaderProfile:
    """Congestion waves: reach a seeded cruise speed [m/s], then repeat until the profile ends: cruise, brake at
    2-4 m/s^2 to a crawl of 0-5 m/s, crawl for 2-10 s, accelerate at 1-2.5 m/s^2 back to the cruise speed.

    Every speed change is a jerk-limited trapezoid (:func:`_speed_change`). Speeds lie in
    [0, speed_band[1]]; with the defaults a 250 s profile holds at least two crawls.
    """
    rng = np.random.default_rng(seed)
    cruise = min(rng.uniform(*params.cruise_speed_range), leader.speed_band[1])
    start = _speed_change(cruise - leader.initial_speed, rng.uniform(*params.accel_range), params.max_jerk, leader.dt)
    segments, length = [start], start.size
    while length < leader.n_samples:  # wave after wave until the profile is full
        crawl = rng.uniform(*params.crawl_speed_range)
        wave = (
            np.zeros(_ticks(rng.uniform(*params.cruise_duration_range), leader.dt)),
            _speed_change(crawl - cruise, rng.uniform(*params.decel_range), params.max_jerk, leader.dt),
            np.zeros(_ticks(rng.uniform(*params.crawl_duration_range), leader.dt)),
            _speed_change(cruise - crawl, rng.uniform(*params.accel_range), params.max_jerk, leader.dt),
        )
        segments.extend(wave)
        length += sum(segment.size for segment in wave)
    accel = np.concatenate(segments)[: leader.n_samples]
    return LeaderProfile.from_acceleration(accel, _down_to_standstill(leader), name="stop_and_go")


def emergency_braking(
    seed: int | None, params: EmergencyBrakingConfig = EmergencyBrakingConfig(), leader: LeaderConfig = LeaderConfig()
) -> LeaderProfile:
    """Highway cruising at a seeded speed [m/s] with 1-3 emergency stops at seeded moments: brake at 6-7.5 m/s^2
    to standstill (half the stops) or to 1-5 m/s, pause 2-8 s, re-accelerate at 1.5-3 m/s^2 to the cruise speed.

    Every speed change is a jerk-limited trapezoid (:func:`_speed_change`). Each stop follows at least
    ``min_cruise_duration`` of cruising; the rest of the cruising time is split at random between the gaps
    before the stops and after the last. Stops that do not fit in the profile are dropped, last first.
    Speeds lie in [0, speed_band[1]].
    """
    rng = np.random.default_rng(seed)
    cruise = min(rng.uniform(*params.cruise_speed_range), leader.speed_band[1])
    start = _speed_change(cruise - leader.initial_speed, rng.uniform(*params.recovery_accel_range), params.max_jerk,
                          leader.dt)
    events: list[np.ndarray] = []
    for _ in range(int(rng.integers(params.n_events_range[0], params.n_events_range[1] + 1))):
        stop = 0.0 if rng.random() < params.standstill_probability else rng.uniform(*params.low_speed_range)
        events.append(np.concatenate((
            _speed_change(stop - cruise, rng.uniform(*params.decel_range), params.max_jerk, leader.dt),
            np.zeros(_ticks(rng.uniform(*params.pause_duration_range), leader.dt)),
            _speed_change(cruise - stop, rng.uniform(*params.recovery_accel_range), params.max_jerk, leader.dt),
        )))
    min_cruise = _ticks(params.min_cruise_duration, leader.dt)
    while events and start.size + sum(event.size + min_cruise for event in events) > leader.n_samples:
        events.pop()
    spare = leader.n_samples - start.size - sum(event.size + min_cruise for event in events)  # [ticks]
    shares = rng.random(len(events) + 1)
    cruises = np.floor(spare * shares / shares.sum()).astype(int) + min_cruise  # before each stop, then after the last
    segments = [start]
    for event, ticks in zip(events, cruises[:-1], strict=True):  # the last cruise is the zeros after
        segments.extend((np.zeros(ticks), event))
    accel = np.zeros(leader.n_samples)
    body = np.concatenate(segments)
    accel[: body.size] = body
    return LeaderProfile.from_acceleration(accel, _down_to_standstill(leader), name="emergency_braking")


def _ticks(duration: float, dt: float) -> int:
    """Whole ticks in ``duration`` [s] at ``dt`` [s], at least one."""
    return max(1, int(round(duration / dt)))


def _down_to_standstill(leader: LeaderConfig) -> LeaderConfig:
    """``leader`` with its speed band opened down to standstill: [0, speed_band[1]] [m/s]."""
    return leader.with_overrides({"speed_band": (0.0, leader.speed_band[1])})


def _speed_change(change: float, magnitude: float, max_jerk: float, dt: float) -> np.ndarray:
    """Accelerations [m/s^2], one a tick, that change the speed by exactly ``change`` [m/s] when integrated at
    ``dt`` [s]: a trapezoid rising by at most ``max_jerk`` [m/s^3] to a plateau of at most ``magnitude``
    [m/s^2] and falling back the same way (its last tick is the last non-zero one)."""
    size = abs(change)
    if size == 0.0:
        return np.zeros(0)
    planned = min(magnitude, math.sqrt(size * max_jerk))  # a short change never reaches ``magnitude`` [m/s^2]
    ramp = max(1, math.ceil(planned / (max_jerk * dt) - 1e-9))  # ticks up to the plateau
    plateau = max(0, math.ceil(size / (planned * dt) - ramp - 1e-9))  # ticks at the plateau
    peak = size / (dt * (ramp + plateau))  # <= planned: the shape below sums to ramp + plateau
    shape = np.concatenate((np.arange(1, ramp + 1) / ramp, np.ones(plateau), np.arange(ramp - 1, 0, -1) / ramp))
    return math.copysign(peak, change) * shape


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
