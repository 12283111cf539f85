"""Traffic that changes within an episode: a leader that strings driving regimes.

The leader passes from regime to regime, each for a seeded duration, never the same one twice in a row (unless it
is the only one weighted):

- ``free_flow``: a near-constant cruise with small fluctuations;
- ``slow_oscillation``: long-period speed waves;
- ``aggressive_cycles``: hard acceleration and deceleration cycles;
- ``stop_and_go``: waves down to near standstill and back;
- ``hard_braking``: a sharp brake, then recovery.

Every regime is a chain of moves, each a jerk-limited trapezoid of acceleration that changes the speed to a target
(:func:`~timegap_env.leaders.synthetic._speed_change`) followed by a tick or more at a = 0. So the acceleration is
0 at every regime boundary and changes by at most ``smooth_jerk`` or ``max_jerk`` a second, the speed (its
integral) never jumps, and every target lies in [0, speed_band[1]], the band this family keeps (it leaves the
band's low end, as stop-and-go traffic must). A move that does not fit in what is left of its regime is left out
and the leader holds its speed to the regime's end. :func:`regime_schedule` gives the regime of every tick, from
the same plan as the profile.

Where the defaults come from (:func:`traffic_statistics`, run by ``train/measure_regimes.py`` on the shared data;
speeds smoothed over 1 s before differencing):

- NGSIM I-80, 4:00-4:15 pm (217 vehicles with >= 30 s of data, congested, 2-22 m/s): speed oscillation amplitude
  (half the 5-95 % spread of a vehicle's speed) 1.8 / 2.6 / 3.9 m/s at the 10th / 50th / 90th percentile; period
  (time between upward crossings of the vehicle's mean speed) 11.5 / 16 / 34 s at the 25th / 50th / 90th
  percentile, biased short by the 30-74 s records; a vehicle's mean speed 6.6 / 13.6 m/s at the 5th / 95th
  percentile, its lowest speed 2.6 m/s at the 5th; speed fluctuation about a 10 s moving average 0.53 m/s
  (median std); |a| 0.32 / 1.3 / 2.9 m/s^2 at the 50th / 95th / 99th percentile, a 2.1 m/s^2 at the 99th;
  |jerk| 1.1 / 2.4 m/s^3 at the 95th / 99th.
- OpenACC AstaZero lead cars (19 runs): accelerating or braking (|a| > 0.1 m/s^2) 4 % of the time, then a
  -2.8 / -2.4 / -1.0 and 1.0 / 1.5 / 1.9 m/s^2 at the 1st / 5th / 25th and 75th / 95th / 99th percentile, never
  below -3.1 m/s^2; |jerk| 2.0 / 2.5 m/s^3 at the 90th / 99th percentile while accelerating or braking; speed
  fluctuation about a 10 s moving average 0.25 m/s (median std; the lead cars mostly held a set speed).

Neither data set holds free-flow highway cruising or hard braking (NGSIM's recorded accelerations are capped at
+/-3.4 m/s^2): those defaults are the other families' (:class:`~timegap_env.config.HardBrakingConfig`,
:class:`~timegap_env.leaders.synthetic.EmergencyBrakingConfig`, the paper's
:class:`~timegap_env.config.AggressiveCyclesConfig`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence

import numpy as np

from timegap_env.config import MAX_ACCEL, MAX_DURATION, MAX_JERK, MAX_SPEED, ConfigMixin, LeaderConfig
from timegap_env.leaders.profile import LeaderProfile, LeaderProfiles
from timegap_env.leaders.synthetic import _down_to_standstill, _speed_change, _ticks

REGIMES = ("free_flow", "slow_oscillation", "aggressive_cycles", "stop_and_go", "hard_braking")  # in code order


@dataclasses.dataclass(frozen=True)
class RegimesConfig(ConfigMixin):
    """A leader that strings driving regimes (:data:`REGIMES`), each for a duration drawn from its range."""

    regime_weights: dict[str, float] = dataclasses.field(default_factory=lambda: dict.fromkeys(REGIMES, 1.0))
    # how often each regime is drawn next [-], regimes of REGIMES, weights in [0, MAX_WEIGHT], not all 0
    free_flow_duration: tuple[float, float] = (30.0, 90.0)  # time in a regime [s], in (0, MAX_DURATION]
    slow_oscillation_duration: tuple[float, float] = (40.0, 120.0)  # [s], in (0, MAX_DURATION]
    aggressive_cycles_duration: tuple[float, float] = (20.0, 60.0)  # [s], in (0, MAX_DURATION]
    stop_and_go_duration: tuple[float, float] = (40.0, 120.0)  # [s], in (0, MAX_DURATION]
    hard_braking_duration: tuple[float, float] = (20.0, 40.0)  # [s], in (0, MAX_DURATION]
    smooth_jerk: float = 2.5  # jerk of every move but the aggressive ones (OpenACC lead cars' 99th percentile)
    # [m/s^3], (0, MAX_JERK]
    max_jerk: float = 10.0  # jerk of aggressive cycles and of the hard brake (the paper's aggressive driver)
    # [m/s^3], (0, MAX_JERK]
    transition_accel: float = 1.3  # acceleration towards a new regime's speed (NGSIM's 95th percentile of |a|)
    # [m/s^2], (0, MAX_ACCEL]
    free_flow_speed_range: tuple[float, float] = (25.0, 33.0)  # cruise speed, one per regime (56-74 mph) [m/s], in
    # (0, MAX_SPEED]
    free_flow_speed_std: float = 0.5  # spread of the fluctuations about the cruise (NGSIM: 0.53) [m/s],
    # [0, MAX_SPEED]
    free_flow_accel: float = 0.3  # acceleration of a fluctuation (NGSIM's median |a|) [m/s^2], (0, MAX_ACCEL]
    free_flow_hold_range: tuple[float, float] = (2.0, 10.0)  # time between fluctuations [s], in [0, MAX_DURATION]
    slow_oscillation_amplitude_range: tuple[float, float] = (1.8, 3.9)  # speed amplitude, one per regime (NGSIM's
    # 10th-90th percentile) [m/s], in (0, MAX_SPEED / 2]
    slow_oscillation_period_range: tuple[float, float] = (11.5, 34.0)  # wave period, one per regime (NGSIM's
    # 25th-90th percentile) [s], in [1, MAX_DURATION]
    aggressive_cycles_accel_range: tuple[float, float] = (1.5, 3.5)  # acceleration of a phase (the paper's) [m/s^2],
    # in (0, MAX_ACCEL]
    aggressive_cycles_phase_range: tuple[float, float] = (3.0, 9.0)  # length of a phase at that acceleration (the
    # paper's) [s], in (0, MAX_DURATION]
    stop_and_go_top_speed_range: tuple[float, float] = (6.6, 13.6)  # speed between waves, one per wave (NGSIM's
    # mean speeds, 5th-95th percentile) [m/s], in (0, MAX_SPEED], above stop_and_go_crawl_speed_range
    stop_and_go_crawl_speed_range: tuple[float, float] = (0.0, 2.6)  # speed at a wave's bottom, one per wave (up
    # to NGSIM's lowest speeds, 5th percentile) [m/s], in [0, MAX_SPEED]
    stop_and_go_decel_range: tuple[float, float] = (1.0, 2.4)  # braking into a wave (OpenACC's 25th-5th
    # percentile) [m/s^2], in (0, MAX_ACCEL]
    stop_and_go_accel_range: tuple[float, float] = (1.0, 2.1)  # acceleration out of a wave (OpenACC's 75th
    # percentile to NGSIM's 99th) [m/s^2], in (0, MAX_ACCEL]
    stop_and_go_hold_range: tuple[float, float] = (2.0, 10.0)  # time at a wave's bottom and top [s], in
    # [0, MAX_DURATION]
    hard_braking_decel_range: tuple[float, float] = (4.0, 7.0)  # the brake (HardBrakingConfig's) [m/s^2], in
    # (0, MAX_ACCEL]
    hard_braking_drop_range: tuple[float, float] = (5.0, 12.0)  # speed the brake sheds (HardBrakingConfig's)
    # [m/s], in (0, MAX_SPEED]
    hard_braking_recovery_accel_range: tuple[float, float] = (1.0, 2.1)  # acceleration back to the speed before
    # the brake (OpenACC's 75th percentile to NGSIM's 99th) [m/s^2], in (0, MAX_ACCEL]

    def __post_init__(self) -> None:
        self._weights("regime_weights", "regime", REGIMES)
        for regime in REGIMES:
            self._pair(f"{regime}_duration", 0.0, MAX_DURATION, open_low=True)
        for field in ("smooth_jerk", "max_jerk"):
            self._number(field, 0.0, MAX_JERK, open_low=True)
        for field in ("transition_accel", "free_flow_accel"):
            self._number(field, 0.0, MAX_ACCEL, open_low=True)
        self._number("free_flow_speed_std", 0.0, MAX_SPEED)
        for field in ("free_flow_speed_range", "stop_and_go_top_speed_range", "hard_braking_drop_range"):
            self._pair(field, 0.0, MAX_SPEED, open_low=True)
        self._pair("stop_and_go_crawl_speed_range", 0.0, MAX_SPEED)
        self._pair("slow_oscillation_amplitude_range", 0.0, MAX_SPEED / 2, open_low=True)
        self._pair("slow_oscillation_period_range", 1.0, MAX_DURATION)
        self._pair("aggressive_cycles_phase_range", 0.0, MAX_DURATION, open_low=True)
        for field in ("free_flow_hold_range", "stop_and_go_hold_range"):
            self._pair(field, 0.0, MAX_DURATION)
        for field in ("aggressive_cycles_accel_range", "stop_and_go_decel_range", "stop_and_go_accel_range",
                      "hard_braking_decel_range", "hard_braking_recovery_accel_range"):
            self._pair(field, 0.0, MAX_ACCEL, open_low=True)
        if self.stop_and_go_crawl_speed_range[1] >= self.stop_and_go_top_speed_range[0]:
            self._fail("stop_and_go_crawl_speed_range", self.stop_and_go_crawl_speed_range,
                       f"must lie below stop_and_go_top_speed_range {self.stop_and_go_top_speed_range}")


def regimes(seed: int | None, params: RegimesConfig = RegimesConfig(),
            leader: LeaderConfig = LeaderConfig()) -> LeaderProfile:
    """A leader that strings seeded regimes of seeded durations (see the module's docstring); speeds [m/s] in
    [0, ``leader.speed_band[1]``] from ``leader.initial_speed``, at ``leader.dt`` [s] for ``leader.duration`` [s]."""
    return regimes_batch([seed], params, leader).profile(0)


def regimes_batch(seeds: Sequence[int | None], params: RegimesConfig = RegimesConfig(),
                  leader: LeaderConfig = LeaderConfig()) -> LeaderProfiles:
    """:func:`regimes` of each seed, a row each, with the regime of each sample (``regime``, indices into
    :data:`REGIMES`) from the same plan."""
    plans = [_plan(seed, params, leader) for seed in seeds]
    return LeaderProfiles.from_acceleration(np.stack([accel for accel, _ in plans]), _down_to_standstill(leader),
                                            name="regimes", regime=np.stack([codes for _, codes in plans]))


def regime_schedule(seed: int | None, params: RegimesConfig = RegimesConfig(),
                    leader: LeaderConfig = LeaderConfig()) -> tuple[np.ndarray, tuple[str, ...]]:
    """The regime acting at each tick of ``regimes(seed, params, leader)``: codes (n_samples,) int8, indices into
    the names returned with them (:data:`REGIMES`). Both come from one plan; ``seed=None`` draws a fresh one each
    call."""
    return _plan(seed, params, leader)[1], REGIMES


class _Plan:
    """One regime's accelerations [m/s^2], move by move, and the speed they reach [m/s]."""

    def __init__(self, speed: float, ticks: int, dt: float, high: float) -> None:
        self.speed, self.left, self.dt, self.high = speed, ticks, dt, high  # [m/s], [-], [s], [m/s]
        self.segments: list[np.ndarray] = []

    def move(self, target: float, accel: float, jerk: float) -> bool:
        """Change the speed to ``target`` [m/s] (clipped to [0, high]) at up to ``accel`` [m/s^2] and ``jerk``
        [m/s^3], then one tick at a = 0 (so a move of the other sign may follow at once). False, and nothing
        added, if the move does not fit in the ticks left."""
        shape = _move(min(max(target, 0.0), self.high) - self.speed, accel, jerk, self.dt)
        if shape.size > self.left:
            return False
        self.segments.append(shape)
        self.left -= shape.size
        self.speed = min(max(target, 0.0), self.high)
        return True

    def approach(self, target: float, accel: float, jerk: float, time: float) -> None:
        """Move towards ``target`` [m/s] as far as a move at ``accel`` [m/s^2] and ``jerk`` [m/s^3] gets in
        ``time`` [s] (a trapezoid changes the speed by accel (time - accel / jerk))."""
        reach = max(accel * (time - accel / jerk), 0.0)  # [m/s]
        self.move(self.speed + min(max(target - self.speed, -reach), reach), accel, jerk)

    def hold(self, time: float) -> None:
        """Hold the speed for ``time`` [s] (whole ticks, none if ``time`` <= 0, at most those left)."""
        ticks = min(max(round(time / self.dt), 0), self.left)
        self.segments.append(np.zeros(ticks))
        self.left -= ticks

    def accel(self) -> np.ndarray:
        """The regime's accelerations [m/s^2], the speed held over the ticks left."""
        return np.concatenate([*self.segments, np.zeros(self.left)])


def _move(change: float, accel: float, jerk: float, dt: float) -> np.ndarray:
    """The accelerations [m/s^2] of a move changing the speed by ``change`` [m/s] at up to ``accel`` [m/s^2] and
    ``jerk`` [m/s^3], one a tick of ``dt`` [s], the last at a = 0."""
    shape = _speed_change(change, accel, jerk, dt)
    move = np.zeros(shape.size + 1)
    move[:-1] = shape
    return move


def _free_flow(rng: np.random.Generator, params: RegimesConfig, plan: _Plan) -> None:
    """Head for a cruise speed, then fluctuate about it: small moves to cruise + N(0, std), holds between."""
    plan.approach(rng.uniform(*params.free_flow_speed_range), params.transition_accel, params.smooth_jerk,
                  plan.left * plan.dt / 2)
    cruise = plan.speed
    while plan.move(cruise + params.free_flow_speed_std * rng.standard_normal(), params.free_flow_accel,
                    params.smooth_jerk):
        plan.hold(rng.uniform(*params.free_flow_hold_range))


def _slow_oscillation(rng: np.random.Generator, params: RegimesConfig, plan: _Plan) -> None:
    """Swing between centre +/- amplitude, half a period a swing, at the peak acceleration of a sine wave of that
    amplitude and period; the centre is the speed, moved into the band if the swing would leave it."""
    amplitude = min(rng.uniform(*params.slow_oscillation_amplitude_range), plan.high / 2)  # [m/s]
    period = rng.uniform(*params.slow_oscillation_period_range)  # [s]
    plan.approach(min(max(plan.speed, amplitude), plan.high - amplitude), params.transition_accel,
                  params.smooth_jerk, plan.left * plan.dt / 2)
    centre, accel, sign = plan.speed, 2 * math.pi * amplitude / period, (-1.0, 1.0)[int(rng.integers(2))]
    while True:
        before = plan.left
        if not plan.move(centre + sign * amplitude, accel, params.smooth_jerk):
            return
        plan.hold(period / 2 - (before - plan.left) * plan.dt)
        sign = -sign


def _aggressive_cycles(rng: np.random.Generator, params: RegimesConfig, plan: _Plan) -> None:
    """Alternate hard phases up and down, each changing the speed by accel x phase length (the other way if that
    would leave the band)."""
    sign = (-1.0, 1.0)[int(rng.integers(2))]
    while True:
        accel = rng.uniform(*params.aggressive_cycles_accel_range)
        change = accel * rng.uniform(*params.aggressive_cycles_phase_range)  # [m/s]
        if not 0.0 <= plan.speed + sign * change <= plan.high:
            sign = -sign
        if not plan.move(plan.speed + sign * change, accel, params.max_jerk):
            return
        sign = -sign


def _stop_and_go(rng: np.random.Generator, params: RegimesConfig, plan: _Plan) -> None:
    """Waves: brake to a crawl, hold, accelerate to a top speed, hold, again."""
    while (plan.move(rng.uniform(*params.stop_and_go_crawl_speed_range), rng.uniform(*params.stop_and_go_decel_range),
                     params.smooth_jerk)):
        plan.hold(rng.uniform(*params.stop_and_go_hold_range))
        if not plan.move(rng.uniform(*params.stop_and_go_top_speed_range),
                         rng.uniform(*params.stop_and_go_accel_range), params.smooth_jerk):
            return
        plan.hold(rng.uniform(*params.stop_and_go_hold_range))


def _hard_braking(rng: np.random.Generator, params: RegimesConfig, plan: _Plan) -> None:
    """Gain the speed to shed if below it, cruise for a seeded while, brake hard, recover to the speed before."""
    decel, drop = rng.uniform(*params.hard_braking_decel_range), rng.uniform(*params.hard_braking_drop_range)
    recovery = rng.uniform(*params.hard_braking_recovery_accel_range)
    plan.approach(max(plan.speed, drop), params.transition_accel, params.smooth_jerk, plan.left * plan.dt / 2)
    cruise = plan.speed
    bottom = max(cruise - drop, 0.0)
    event = (_move(bottom - cruise, decel, params.max_jerk, plan.dt).size
             + _move(cruise - bottom, recovery, params.smooth_jerk, plan.dt).size)  # [ticks]
    plan.hold(rng.uniform(0.0, max(plan.left - event, 0)) * plan.dt)
    if plan.move(bottom, decel, params.max_jerk):
        plan.move(cruise, recovery, params.smooth_jerk)


_PLANNERS: tuple[Callable[[np.random.Generator, RegimesConfig, _Plan], None], ...] = (
    _free_flow, _slow_oscillation, _aggressive_cycles, _stop_and_go, _hard_braking)  # in the order of REGIMES


def _plan(seed: int | None, params: RegimesConfig, leader: LeaderConfig) -> tuple[np.ndarray, np.ndarray]:
    """The accelerations [m/s^2] (n_samples,) of the profile of ``seed`` and the regime code (int8) of each tick:
    regime after regime, each drawn by weight (not the one before, unless it is the only one weighted) with a
    duration drawn from its range, until the profile is full."""
    rng = np.random.default_rng(seed)
    weights = np.array([params.regime_weights.get(name, 0.0) for name in REGIMES])
    n, dt = leader.n_samples, leader.dt
    speed, filled, code = leader.initial_speed, 0, -1
    accels, codes, lengths = [], [], []
    while filled < n:
        choice = weights.copy()
        if code >= 0 and np.count_nonzero(choice) > 1:
            choice[code] = 0.0
        code = int(rng.choice(len(REGIMES), p=choice / choice.sum()))
        ticks = _ticks(rng.uniform(*getattr(params, f"{REGIMES[code]}_duration")), dt)
        plan = _Plan(speed, ticks, dt, leader.speed_band[1])
        _PLANNERS[code](rng, params, plan)
        accels.append(plan.accel())
        codes.append(code)
        lengths.append(ticks)
        speed, filled = plan.speed, filled + ticks
    return np.concatenate(accels)[:n], np.repeat(np.array(codes, dtype=np.int8), lengths)[:n]


def traffic_statistics(speeds: Sequence[np.ndarray], dt: float) -> dict[str, float]:
    """What the defaults of :class:`RegimesConfig` are measured from: percentiles over recorded vehicles' speed series
    ``speeds`` [m/s] at ``dt`` [s], each longer than 10 s and smoothed over 1 s before it is differenced.

    Keys, ``<name>_p<percentile>``: ``amplitude`` (half the 5-95 % spread of a vehicle's speed [m/s]), ``period``
    (time between upward crossings of a vehicle's mean speed [s]), ``mean_speed`` and ``min_speed`` (a vehicle's
    [m/s]), ``fluctuation_std`` (a vehicle's speed std about its 10 s moving average [m/s]), ``accel`` and
    ``abs_accel`` [m/s^2] and ``abs_jerk`` [m/s^3] over all ticks, ``active_accel`` [m/s^2] and ``active_abs_jerk``
    [m/s^3] over the ticks accelerating or braking (|a| > 0.1 m/s^2); and ``active_share``, the share of those [-].
    """
    second, trend = max(1, round(1.0 / dt)), round(10.0 / dt)  # [ticks]
    per_vehicle: dict[str, list[float]] = {"amplitude": [], "mean_speed": [], "min_speed": [], "fluctuation_std": []}
    periods, accels, jerks = [], [], []
    for speed in speeds:
        smooth = _moving_average(speed, second)
        low, high = np.percentile(smooth, [5, 95])
        above = smooth >= smooth.mean()
        periods.append(np.diff(np.flatnonzero(~above[:-1] & above[1:])) * dt)
        centred = speed[trend // 2: trend // 2 + speed.size - trend + 1]  # aligned with its moving average
        for name, value in zip(per_vehicle, ((high - low) / 2, speed.mean(), speed.min(),
                                             np.std(centred - _moving_average(speed, trend)))):
            per_vehicle[name].append(float(value))
        accel = np.gradient(smooth, dt)
        accels.append(accel)
        jerks.append(np.gradient(np.convolve(accel, np.ones(second) / second, mode="same"), dt))
    accel, jerk = np.concatenate(accels), np.abs(np.concatenate(jerks))
    active = np.abs(accel) > 0.1
    samples = {"amplitude": (per_vehicle["amplitude"], (10, 50, 90)), "period": (np.concatenate(periods), (25, 50, 90)),
               "mean_speed": (per_vehicle["mean_speed"], (5, 95)), "min_speed": (per_vehicle["min_speed"], (5,)),
               "fluctuation_std": (per_vehicle["fluctuation_std"], (50,)), "accel": (accel, (1, 99)),
               "abs_accel": (np.abs(accel), (50, 95, 99)), "abs_jerk": (jerk, (95, 99)),
               "active_accel": (accel[active], (1, 5, 25, 75, 95, 99)), "active_abs_jerk": (jerk[active], (90, 99))}
    measured = {f"{name}_p{q}": float(np.percentile(values, q)) for name, (values, qs) in samples.items() for q in qs}
    return {**measured, "active_share": float(active.mean())}


def _moving_average(series: np.ndarray, ticks: int) -> np.ndarray:
    """The means of ``series`` over each ``ticks`` consecutive samples (``series.size - ticks + 1`` of them)."""
    return np.convolve(series, np.ones(ticks) / ticks, mode="valid")
