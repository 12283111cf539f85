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
from collections.abc import Sequence
from typing import NamedTuple, TypeVar

import numba
import numpy as np

from timegap_env.compiled import follow_sources
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
from timegap_env.generators import generators
from timegap_env.leaders.profile import LeaderProfile, LeaderProfiles, _step_in_band

DRAWS_PER_PHASE = 3  # uniform numbers an aggressive cycle's phase draws: duration, magnitude, cruise or not


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
    return aggressive_cycles_batch([seed], params, leader).profile(0)


def aggressive_cycles_batch(
    seeds: Sequence[int | None],
    params: AggressiveCyclesConfig = AggressiveCyclesConfig(),
    leader: LeaderConfig = LeaderConfig(),
) -> LeaderProfiles:
    """:func:`aggressive_cycles` of each seed, a row each.

    Each seed's generator gives the first phase's sign, then three numbers per phase (its
    duration, its magnitude, whether it is a cruise), all uniform draws: they are drawn in bulk
    and the phases laid out by :func:`_cycle_phases`, with more draws if the profile needs them.
    """
    low, high = leader.speed_band
    constants = _CycleConstants(
        *(float(value) for value in (*params.phase_duration_range, *params.accel_range, params.cruise_probability,
                                     params.max_jerk, params.max_jerk * leader.dt, leader.initial_speed, low, high,
                                     leader.dt, 2.0)))
    accel = np.zeros((len(seeds), leader.n_samples))
    n_draws = DRAWS_PER_PHASE * (math.ceil(leader.n_samples * leader.dt / params.phase_duration_range[0]) + 16)
    for row, rng in enumerate(generators(seeds)):
        sign = (-1.0, 1.0)[int(rng.integers(2))]  # what rng.choice([-1.0, 1.0]) draws, without building an array
        draws = rng.random(n_draws)
        while _cycle_phases(accel[row], sign, draws, tuple(constants)) < 0:  # ran out: draw as many again
            draws = np.concatenate((draws, rng.random(draws.size)))
    return LeaderProfiles.from_acceleration(accel, leader, name="aggressive_cycles")


def sinusoid(
    seed: int | None, params: SinusoidConfig = SinusoidConfig(), leader: LeaderConfig = LeaderConfig()
) -> LeaderProfile:
    """Speed oscillation around the initial speed with a seeded amplitude, period and phase, inside the band."""
    return sinusoid_batch([seed], params, leader).profile(0)


def sinusoid_batch(
    seeds: Sequence[int | None], params: SinusoidConfig = SinusoidConfig(), leader: LeaderConfig = LeaderConfig()
) -> LeaderProfiles:
    """:func:`sinusoid` of each seed, a row each: each seed's generator draws three uniform numbers, for the
    amplitude [m/s], the period [s] and the phase [rad]."""
    low, high = leader.speed_band
    drawn = np.empty((len(seeds), 3))
    for row, rng in enumerate(generators(seeds)):
        rng.random(out=drawn[row])
    amplitude = np.minimum(_uniform(params.amplitude_range, drawn[:, 0]), 0.5 * (high - low))
    period = _uniform(params.period_range, drawn[:, 1])
    phase = _uniform((0.0, 2.0 * np.pi), drawn[:, 2])
    mean = np.minimum(np.maximum(leader.initial_speed, low + amplitude), high - amplitude)
    omega = 2.0 * np.pi / period
    speed, accel = np.empty((len(seeds), leader.n_samples)), np.empty((len(seeds), leader.n_samples))
    _sinusoid_rows(amplitude, omega, phase, mean, float(leader.dt), speed, accel)
    return LeaderProfiles(speed=speed, accel=accel, dt=leader.dt, name="sinusoid")


_Uniform = TypeVar("_Uniform", float, np.ndarray)  # a number in [0, 1), or an array of them


def _uniform(bounds: tuple[float, float], u: _Uniform) -> _Uniform:
    """What ``rng.uniform(*bounds)`` draws from the uniform number ``u`` in [0, 1) (a float or an array of them) that
    ``rng.random()`` would have drawn in its place: low + (high - low) u, in numpy's order of operations."""
    low, high = float(bounds[0]), float(bounds[1])
    return low + (high - low) * u


def hard_braking(
    seed: int | None, params: HardBrakingConfig = HardBrakingConfig(), leader: LeaderConfig = LeaderConfig()
) -> LeaderProfile:
    """Cruise at the initial speed, brake hard ``n_events`` times at seeded moments, recover each time."""
    return hard_braking_batch([seed], params, leader).profile(0)


def hard_braking_batch(
    seeds: Sequence[int | None], params: HardBrakingConfig = HardBrakingConfig(), leader: LeaderConfig = LeaderConfig()
) -> LeaderProfiles:
    """:func:`hard_braking` of each seed, a row each."""
    accel = np.zeros((len(seeds), leader.n_samples))
    slot = leader.n_samples // params.n_events  # one event per slot, so events never overlap
    for row, rng in enumerate(generators(seeds)):
        for event in range(params.n_events):
            decel_draw, drop_draw = rng.random(2).tolist()
            decel = _uniform(params.decel_range, decel_draw)
            drop = min(_uniform(params.speed_drop_range, drop_draw), leader.initial_speed - leader.speed_band[0])
            brake_ticks = int(round(drop / decel / leader.dt))
            recover_ticks = int(round(drop / params.recovery_accel / leader.dt))
            latest_start = max(slot - brake_ticks - recover_ticks, 1)
            start = event * slot + int(rng.integers(0, latest_start))
            accel[row, start : start + brake_ticks] = -decel
            accel[row, start + brake_ticks : start + brake_ticks + recover_ticks] = params.recovery_accel
    return LeaderProfiles.from_acceleration(accel, leader, name="hard_braking")


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
    return stop_and_go_batch([seed], params, leader).profile(0)


def stop_and_go_batch(
    seeds: Sequence[int | None], params: StopAndGoConfig = StopAndGoConfig(), leader: LeaderConfig = LeaderConfig()
) -> LeaderProfiles:
    """:func:`stop_and_go` of each seed, a row each."""
    accel = np.stack([_stop_and_go_accel(rng, params, leader) for rng in generators(seeds)])
    return LeaderProfiles.from_acceleration(accel, _down_to_standstill(leader), name="stop_and_go")


def _stop_and_go_accel(rng: np.random.Generator, params: StopAndGoConfig, leader: LeaderConfig) -> np.ndarray:
    """The accelerations [m/s^2] of one :func:`stop_and_go` profile drawn from ``rng``."""
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
    return np.concatenate(segments)[: leader.n_samples]


def emergency_braking(
    seed: int | None, params: EmergencyBrakingConfig = EmergencyBrakingConfig(), leader: LeaderConfig = LeaderConfig()
) -> LeaderProfile:
    """Highway cruising at a seeded speed [m/s] with 1-3 emergency stops at seeded moments: brake at 6-7.5 m/s^2
    to standstill (half the stops) or to 1-5 m/s, pause 2-8 s, re-accelerate at 1.5-3 m/s^2 to the cruise speed.

    Every speed change is a jerk-limited trapezoid (:func:`_speed_change`). Each stop follows at least
    ``min_cruise_duration`` of cruising; the rest of the cruising time is split at random between the gaps
    before the stops and after the last. Stops that do not fit in the profile are dropped, last first; a profile too
    short for even the way to the cruise speed is that way cut short. Speeds lie in [0, speed_band[1]].
    """
    return emergency_braking_batch([seed], params, leader).profile(0)


def emergency_braking_batch(
    seeds: Sequence[int | None],
    params: EmergencyBrakingConfig = EmergencyBrakingConfig(),
    leader: LeaderConfig = LeaderConfig(),
) -> LeaderProfiles:
    """:func:`emergency_braking` of each seed, a row each."""
    accel = np.stack([_emergency_braking_accel(rng, params, leader) for rng in generators(seeds)])
    return LeaderProfiles.from_acceleration(accel, _down_to_standstill(leader), name="emergency_braking")


def _emergency_braking_accel(rng: np.random.Generator, params: EmergencyBrakingConfig,
                             leader: LeaderConfig) -> np.ndarray:
    """The accelerations [m/s^2] of one :func:`emergency_braking` profile drawn from ``rng``."""
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
    body = np.concatenate(segments)[: leader.n_samples]  # in a short profile even the way to the cruise may not fit
    accel[: body.size] = body
    return accel


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
    ticks = np.arange(1, 2 * ramp + plateau)
    steps = np.minimum(np.minimum(ticks, ticks[::-1]), ramp)  # 1, 2, .., ramp, then ramp for the plateau, .., 2, 1
    return math.copysign(peak, change) * (steps / ramp)


class _HumanMotion(NamedTuple):
    """The stochastic human's constants."""

    initial_speed: float  # [m/s]
    noise_decay: float  # AR(1) factor of the acceleration noise per tick [-]
    innovation_std: float  # std of the noise's innovation per tick [m/s^2]
    change_chance: float  # chance per tick that the target speed changes [-]
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
    return stochastic_human_batch([seed], params, leader).profile(0)


def stochastic_human_batch(
    seeds: Sequence[int | None],
    params: StochasticHumanConfig = StochasticHumanConfig(),
    leader: LeaderConfig = LeaderConfig(),
) -> LeaderProfiles:
    """:func:`stochastic_human` of each seed, a row each: each seed's generator draws n standard normal numbers (the
    noise), then 2n uniform ones (where the target changes, then to what), n samples a profile."""
    n, dt = leader.n_samples, leader.dt
    decay = np.exp(-dt / params.accel_correlation_time)
    normal, uniform = np.empty((len(seeds), n)), np.empty((len(seeds), 2 * n))
    for row, rng in enumerate(generators(seeds)):
        rng.standard_normal(out=normal[row])
        rng.random(out=uniform[row])
    motion = _HumanMotion(*(float(value) for value in (
        leader.initial_speed, decay, params.accel_std * np.sqrt(1.0 - decay**2), dt / params.target_change_interval,
        params.speed_gain, dt, *leader.speed_band)))
    speed, accel = _pursue_targets(normal, uniform, tuple(motion))
    return LeaderProfiles(speed=speed, accel=accel, dt=dt, name="stochastic_human")


class _CycleConstants(NamedTuple):
    """The aggressive cycles' constants."""

    duration_low: float  # phase_duration_range [s]
    duration_high: float  # [s]
    accel_low: float  # accel_range [m/s^2]
    accel_high: float  # [m/s^2]
    cruise_probability: float  # [-]
    max_jerk: float  # [m/s^3]
    jerk_step: float  # largest change of acceleration in one tick [m/s^2]
    initial_speed: float  # [m/s]
    low: float  # speed band [m/s]
    high: float  # [m/s]
    dt: float  # [s]
    square: float  # 2.0: the exponent of a square, passed in so that it is computed by libm's pow, as Python's
    # float ** 2 is (pow differs from x * x in the last bit for about one value in a thousand)


# Compiled loops; each runs in order because every step depends on the speed reached so far.
@numba.njit(cache=True)
def _cycle_phases(accel, sign, draws, constants):  # noqa: ANN001, ANN202
    """Fill ``accel`` [m/s^2] with aggressive cycles phase by phase, the first phase's sign ``sign`` (+/-1), each
    phase taking three uniform numbers of ``draws`` in [0, 1) (its duration, magnitude and whether it is a cruise:
    a uniform draw of numpy's Generator is low + (high - low) u); ``constants`` is a :class:`_CycleConstants`
    tuple. Returns the draws used, or -1 if ``draws`` ran out first."""
    c = _CycleConstants(*constants)
    speed, current, k, used = c.initial_speed, 0.0, 0, 0
    while k < accel.size:
        if used + DRAWS_PER_PHASE > draws.size:
            return -1
        length = int(np.rint((c.duration_low + (c.duration_high - c.duration_low) * draws[used]) / c.dt))
        magnitude = c.accel_low + (c.accel_high - c.accel_low) * draws[used + 1]
        cruise = draws[used + 2] < c.cruise_probability
        used += DRAWS_PER_PHASE
        target = 0.0
        if not cruise:
            if not c.low <= speed + sign * magnitude * length * c.dt <= c.high:
                sign = -sign
            ramp_margin = (magnitude + abs(current)) ** c.square / c.max_jerk  # gained while ramping in and out [m/s]
            room = (c.high - speed if sign > 0 else speed - c.low) - ramp_margin  # [m/s]
            length = max(1, min(length, int(room / (magnitude * c.dt))))
            target = sign * magnitude
            sign = -sign
        for _ in range(min(length, accel.size - k)):  # the phase: towards target, jerk-limited
            current += min(max(target - current, -c.jerk_step), c.jerk_step)
            accel[k] = current
            speed += current * c.dt
            k += 1
    return used


@numba.njit(cache=True)
def _sinusoid_rows(amplitude, omega, phase, mean, dt, speed, accel):  # noqa: ANN001, ANN202
    """Fill row i of ``speed`` [m/s] with mean + amplitude sin(omega t + phase) and of ``accel`` [m/s^2] with
    amplitude omega cos(omega t + phase), t = k dt [s] at sample k, from row i's ``amplitude`` [m/s], ``omega``
    [rad/s], ``phase`` [rad] and ``mean`` [m/s]: NumPy's operations on the whole arrays, in the same order, so the
    same numbers bit for bit, without their temporaries."""
    for row in range(speed.shape[0]):
        for k in range(speed.shape[1]):
            angle = omega[row] * (k * dt) + phase[row]
            speed[row, k] = mean[row] + amplitude[row] * np.sin(angle)
            accel[row, k] = amplitude[row] * omega[row] * np.cos(angle)


@numba.njit(cache=True)
def _pursue_targets(normal, uniform, motion):  # noqa: ANN001, ANN202
    """The stochastic human's speeds [m/s] and accelerations [m/s^2] (n_profiles, n): it pursues a target speed at
    speed_gain (target - v) plus an AR(1) noise, within the band (:func:`_step_in_band`). A profile's row of
    ``normal`` holds n standard normal numbers (the noise's innovations, in units of innovation_std), its row of
    ``uniform`` 2n numbers in [0, 1): the target changes at tick k if the k-th is below change_chance, to
    low + (high - low) times the (n + k)-th (what numpy's uniform draws); ``motion`` is a :class:`_HumanMotion`
    tuple."""
    motion = _HumanMotion(*motion)
    n = normal.shape[1]
    speed, accel = np.empty(normal.shape), np.empty(normal.shape)
    for row in range(normal.shape[0]):
        now, target, noise = motion.initial_speed, motion.initial_speed, 0.0
        for k in range(n):
            if uniform[row, k] < motion.change_chance:
                target = motion.low + (motion.high - motion.low) * uniform[row, n + k]
            noise = motion.noise_decay * noise + motion.innovation_std * normal[row, k]
            speed[row, k] = now
            now, accel[row, k] = _step_in_band(now, motion.speed_gain * (target - now) + noise, motion.dt, motion.low,
                                               motion.high)
    return speed, accel


# Its kernels: numba's cache by content
follow_sources(__name__)
