"""Default parameters of the platoon, its leader and the monitor: the one source of truth.

Every config is a frozen dataclass. Its fields carry units in comments, its
``__post_init__`` validates every field (type, finiteness, lower and upper bound;
the bounds are in the comment after each field's unit, e.g. ``[s], (0, 10]``), and
``with_overrides`` builds a copy from a dict of overrides. A bad value or an unknown
key raises ``ValueError`` naming the class, the field and the value. A bool is never
a number, an integer field takes only integers, a pair only two numbers. The fields of
``RewardWeights`` and ``RewardScales`` are made of the reward terms' records,
``REWARD_TERM_RECORDS`` (their defaults, units and bounds are the records').

The upper bounds are generous for research and keep one env's memory modest. With
every memory-relevant field at its bound (``MAX_FOLLOWERS`` followers, the shortest tick
``MIN_DT``, ``MAX_EPISODE_TICKS``, ``MAX_WINDOW_TICKS``, ``MAX_DECISION_TICKS``), one env
holds about: leader buffers 2 x 1,000,001 ticks x 8 B = 16 MB; the monitor's window
6,001 x 5 sums x 100 followers x 8 B = 24 MB; the chart's exceedance window
6,000 x 100 x 8 B = 4.8 MB; a step's per-tick arrays 1,000 x 101 vehicles x 8 B = 0.8 MB
each (tests/test_config_fields.py builds and steps that env and measures it).
"""

from __future__ import annotations

import dataclasses
import inspect
import math
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any, ClassVar, NamedTuple, NoReturn, Self, TypeVar, cast

import numpy as np

MPH = 0.44704  # [m/s per mph]
ACTION_MODES = ("platoon", "per_vehicle", "relative")  # one setting for all followers, one each, or one step
# of the platoon's setting down the ladder, none, or up
MONITOR_ESTIMATORS = ("bayes", "raw_gap")  # what the monitor reports as tau: the paper's posterior, or (s - s0) / v
SIMULATORS = ("native", "sumo")  # EnvConfig.simulator: this package's platoon, or SUMO's (timegap_env.sim.sumo)
SUMO_MODELS = ("cc", "cacc")  # SumoConfig.model: Plexe's CC model, or SUMO's CACC model
CHART_KINDS = ("shewhart", "ewma", "cusum")  # the charts of timegap_env.monitoring.charts.CHARTS

# Bounds shared by several fields (each field's own are in its comment).
TIME_GAP_MIN_SPEED = 1.0  # below this speed (s - s0) / v says nothing of the time gap: the monitor leaves such
# measurements out (MonitorConfig.min_speed), the tracking reward ignores them, the env's info reports the actual
# time gap as inf and a Trajectory (an analysis array) as NaN [m/s]
MIN_DT, MAX_DT = 0.01, 1.0  # simulator and measurement tick, 100 Hz to 1 Hz [s]
MAX_FOLLOWERS = 100  # followers in one platoon [-]
MAX_EPISODE_TICKS = 1_000_000  # ticks of an episode or a synthetic leader (28 h at dt = 0.1 s, 16 MB of leader per env) [-]
MAX_WINDOW_TICKS = 6_000  # ticks in the monitor's window or the chart's exceedance window (600 s at dt = 0.1 s) [-]
MAX_DECISION_TICKS = 1_000  # ticks in one env step (100 s at dt = 0.1 s) [-]
MAX_SETTING_LEVELS = 100  # time gap settings on the ladder [-]
MAX_TIME_GAP = 10.0  # largest time gap setting, actuation lag or V2V latency [s]
MAX_SPEED = 100.0  # fastest speed anywhere (360 km/h) [m/s]
MAX_ACCEL = 20.0  # largest magnitude of any acceleration (about 2 g) [m/s^2]
MAX_JERK = 100.0  # largest jerk [m/s^3]
MAX_DURATION = 3600.0  # longest phase, interval, pause or time constant [s]
MAX_WEIGHT = 1e6  # largest reward, scenario or degradation weight [-]
MAX_WIDTH = 1e6  # largest chart limit, allowance or decision interval, in baseline sigmas (train/detection_benchmark.py
# searches up to 1e5 of its statistic's small in-control sigma) [-]


def is_real(value: Any) -> bool:
    """A real number (Python's or NumPy's int or float), never a bool."""
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))


def _is_integer(value: Any) -> bool:
    """An integer (Python's or NumPy's), never a bool."""
    return isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))


def is_finite(value: Any) -> bool:
    """A real number that is not NaN or infinite and fits a float (an integer beyond 1.8e308 does not)."""
    try:
        return math.isfinite(float(value))
    except OverflowError:
        return False


def _items(value: Any) -> tuple[Any, ...] | None:
    """The items of a tuple, list or array (arrays as nested lists of Python numbers), else None."""
    if isinstance(value, np.ndarray):
        value = value.tolist()
    return tuple(value) if isinstance(value, (tuple, list)) else None


def shown(value: Any, limit: int = 200) -> str:
    """``repr(value)`` for an error message, at most ``limit`` characters (an integer too long to print by its bits)."""
    if _is_integer(value) and abs(int(value)) >= 10**limit:
        return f"<an integer of {int(value).bit_length()} bits>"
    text = repr(value)
    return text if len(text) <= limit else f"{text[: limit - 3]}..."


def _interval(low: float, high: float, open_low: bool = False, open_high: bool = False) -> str:
    """``[low, high]`` with round brackets at open ends."""
    return f"{'(' if open_low else '['}{low:g}, {high:g}{')' if open_high else ']'}"


def _within(value: float, low: float, high: float, open_low: bool = False, open_high: bool = False) -> bool:
    """``value`` lies in the interval ``[low, high]``, without an end that is open."""
    return (low < value if open_low else low <= value) and (value < high if open_high else value <= high)


class ConfigMixin:
    """``with_overrides`` and field checks shared by the config dataclasses."""

    def with_overrides(self, overrides: Mapping[str, Any] | None = None) -> Self:
        """Copy of this config with ``overrides`` applied; unknown keys raise ``ValueError``."""
        name = type(self).__name__
        if overrides is not None and not isinstance(overrides, Mapping):
            raise ValueError(f"{name} overrides = {shown(overrides)}: must be a dict of {name} fields")
        overrides = dict(overrides or {})
        known = {f.name for f in dataclasses.fields(self)}  # type: ignore[arg-type]
        unknown = sorted(set(overrides) - known, key=repr)
        if unknown:
            raise ValueError(f"unknown {name} field(s) {unknown}; known fields: {sorted(known)}")
        return dataclasses.replace(self, **overrides)  # type: ignore[type-var]

    def _fail(self, field: str, value: Any, rule: str) -> NoReturn:
        raise ValueError(f"{type(self).__name__}.{field} = {shown(value)}: {rule}")

    def _number(self, field: str, low: float, high: float, *, open_low: bool = False, open_high: bool = False,
                integer: bool = False) -> float:
        """The field's value as a float, checked: a number (an integer if ``integer``), finite, in the interval."""
        value = getattr(self, field)
        if not (_is_integer(value) if integer else is_real(value)):
            self._fail(field, value, "must be an integer" if integer else "must be a number")
        if not is_finite(value):
            self._fail(field, value, "must be finite")
        if not _within(value, low, high, open_low, open_high):
            self._fail(field, value, f"must be in {_interval(low, high, open_low, open_high)}")
        object.__setattr__(self, field, int(value) if integer else float(value))  # Python's, whatever was passed
        return float(value)

    def _flag(self, field: str) -> None:
        if not isinstance(getattr(self, field), (bool, np.bool_)):
            self._fail(field, getattr(self, field), "must be True or False")
        object.__setattr__(self, field, bool(getattr(self, field)))

    def _choice(self, field: str, options: tuple[str, ...]) -> None:
        value = getattr(self, field)
        if not isinstance(value, str) or value not in options:
            self._fail(field, value, f"must be one of {options}")

    def _pair(self, field: str, low: float, high: float, *, open_low: bool = False, open_high: bool = False,
              strict: bool = True, integer: bool = False) -> tuple[float, float]:
        """The field's (low, high) as floats, checked: two numbers (integers if ``integer``), finite, both in the
        interval, low < high (low <= high unless ``strict``)."""
        value = getattr(self, field)
        pair = _items(value)
        is_number = _is_integer if integer else is_real
        if pair is None or len(pair) != 2 or not all(is_number(end) for end in pair):
            self._fail(field, value, f"must be a pair (low, high) of {'integers' if integer else 'numbers'}")
        if not all(is_finite(end) for end in pair):
            self._fail(field, value, "must be finite")
        if not all(_within(end, low, high, open_low, open_high) for end in pair):
            self._fail(field, value, f"both ends must lie in {_interval(low, high, open_low, open_high)}")
        if pair[0] > pair[1] or (strict and pair[0] == pair[1]):
            self._fail(field, value, "must satisfy low < high (the band is reversed or empty)" if strict
                       else "must satisfy low <= high")
        object.__setattr__(self, field, tuple(int(end) if integer else float(end) for end in pair))
        return float(pair[0]), float(pair[1])

    def _weights(self, field: str, what: str, known: tuple[str, ...] | None = None) -> None:
        """A non-empty dict ``what`` -> weight, keys strings (of ``known`` if given), weights in [0, MAX_WEIGHT],
        not all 0."""
        value = getattr(self, field)
        if not isinstance(value, Mapping) or not value or not all(isinstance(key, str) for key in value):
            self._fail(field, value, f"must be a non-empty dict {what} (a string) -> weight"
                       + (f", {what}s {known}" if known else ""))
        unknown = sorted(set(value) - set(known)) if known else []
        if unknown:
            assert known is not None  # unknown is empty unless known is given
            self._fail(field, value, f"unknown {what}s {unknown}; known: {list(known)}")
        weights = list(value.values())
        if not all(is_real(w) and is_finite(w) and 0 <= w <= MAX_WEIGHT for w in weights) or sum(weights) <= 0:
            self._fail(field, value, f"weights must be finite numbers in [0, {MAX_WEIGHT:g}], not all 0")
        object.__setattr__(self, field, {key: float(weight) for key, weight in value.items()})

    def _ticks(self, field: str, dt: float, max_ticks: int, dt_name: str = "dt") -> int:
        """The field's value [s] in ticks of ``dt`` [s], checked: a whole number of ticks, 1 to ``max_ticks``."""
        value = getattr(self, field)
        ticks = value / dt
        if ticks < 1 - 1e-9 or abs(ticks - round(ticks)) > 1e-9:
            self._fail(field, value, f"must be a positive multiple of {dt_name} = {dt}")
        if round(ticks) > max_ticks:
            self._fail(field, value, f"must span at most {max_ticks} ticks of {dt_name} = {dt} s "
                       f"(<= {max_ticks * dt:g} s), which bounds the memory it takes")
        return int(round(ticks))


@dataclasses.dataclass(frozen=True)
class PlatoonConfig(ConfigMixin):
    """A human leader and ``n_followers`` automated followers (GLVD + CTH controller)."""

    n_followers: int = 5  # automated followers behind the leader [-], 1 to MAX_FOLLOWERS
    dt: float = 0.1  # simulator tick [s] (10 Hz), [MIN_DT, MAX_DT]
    actuation_lag: float | tuple[float, ...] = 0.45  # GLVD lag T, one value or one per follower [s], each (0, 10]
    actuation_gain: float | tuple[float, ...] = 1.0  # GLVD gain K, one value or one per follower [-], each (0, 10]
    initial_setting: float = 1.6  # time gap setting tau* at reset [s], (0, MAX_TIME_GAP]
    setting_ramp_rate: float = 0.2  # rate at which the applied setting follows a new setting [s/s], (0, 100]
    standstill_spacing: float = 5.0  # s0 of the CTH policy [m], [0, 100]
    vehicle_length: float = 5.0  # bumper to bumper length of every vehicle [m], (0, 50]
    k_s: float = 0.2  # gain on the spacing error [1/s^2], [0, 10]
    k_v: float = 0.7  # gain on the speed difference to the predecessor [1/s], [0, 10]
    k_a: float = -0.3  # gain on own acceleration [-], [-10, 10]
    k_f: float = 0.6  # feed-forward gain on the predecessor's acceleration over V2V [-], [0, 10]
    v2v_delay: float = 0.1  # V2V delay theta of the feed-forward, a multiple of dt [s], [0, 5]
    max_v2v_latency: float = 1.0  # longest extra V2V delay a degradation may add; sizes the message buffer [s],
    # a multiple of dt in [0, MAX_TIME_GAP]
    v2v: bool = True  # followers start in CACC (True) or ACC, k_f = 0 (False)
    accel_min: float = -8.0  # lowest commanded acceleration (hard braking, ~0.8 g) [m/s^2], [-MAX_ACCEL, 0)
    accel_max: float = 4.0  # highest commanded acceleration [m/s^2], (0, MAX_ACCEL]

    def __post_init__(self) -> None:
        self._number("n_followers", 1, MAX_FOLLOWERS, integer=True)
        self._number("dt", MIN_DT, MAX_DT)
        self._number("initial_setting", 0.0, MAX_TIME_GAP, open_low=True)
        self._number("setting_ramp_rate", 0.0, 100.0, open_low=True)
        self._number("standstill_spacing", 0.0, 100.0)
        self._number("vehicle_length", 0.0, 50.0, open_low=True)
        for field in ("k_s", "k_v", "k_f"):
            self._number(field, 0.0, 10.0)
        self._number("k_a", -10.0, 10.0)
        self._number("v2v_delay", 0.0, 5.0)
        self._number("max_v2v_latency", 0.0, MAX_TIME_GAP)
        self._flag("v2v")
        self._number("accel_min", -MAX_ACCEL, 0.0, open_high=True)
        self._number("accel_max", 0.0, MAX_ACCEL, open_low=True)
        for field in ("v2v_delay", "max_v2v_latency"):
            delay_ticks = getattr(self, field) / self.dt
            if abs(delay_ticks - round(delay_ticks)) > 1e-9:
                self._fail(field, getattr(self, field), f"must be a multiple of dt = {self.dt}")
        for field in ("actuation_lag", "actuation_gain"):
            self.per_follower(field)
            raw = getattr(self, field)
            object.__setattr__(self, field, float(raw) if is_real(raw)
                               else tuple(float(v) for v in cast(tuple[Any, ...], _items(raw))))  # checked above

    @property
    def v2v_delay_ticks(self) -> int:
        """V2V delay theta in ticks [-]."""
        return int(round(self.v2v_delay / self.dt))

    @property
    def max_v2v_latency_ticks(self) -> int:
        """``max_v2v_latency`` in ticks [-]."""
        return int(round(self.max_v2v_latency / self.dt))

    def per_follower(self, field: str) -> np.ndarray:
        """``actuation_lag`` or ``actuation_gain`` as an array of shape (n_followers,), validated."""
        raw = getattr(self, field)
        values = (raw,) if is_real(raw) else _items(raw)
        if values is None or len(values) not in (1, self.n_followers) or not all(is_real(v) for v in values):
            self._fail(field, raw, f"must be one number or {self.n_followers} numbers (one per follower)")
        if not all(is_finite(v) and 0 < v <= 10.0 for v in values):
            self._fail(field, raw, "every value must be finite and in (0, 10]")
        array = np.asarray(values, dtype=float)
        return np.broadcast_to(array, (self.n_followers,)).copy()


RECORDED_PARTS = ("all", "train", "held_out")  # LeaderConfig.recorded_part's values
HELD_OUT_EVERY = 4  # the held-out part of the recorded leaders: every this-th of them, the first included [-]


@dataclasses.dataclass(frozen=True)
class LeaderConfig(ConfigMixin):
    """What every leader profile shares: its tick, length and speed band."""

    dt: float = PlatoonConfig.dt  # sample period of the profile [s], [MIN_DT, MAX_DT]
    duration: float = 250.0  # length of a synthetic profile [s], at least one tick dt, at most MAX_EPISODE_TICKS ticks;
    # in the env it is EnvConfig.episode_duration
    speed_band: tuple[float, float] = (20 * MPH, 80 * MPH)  # speeds a profile is kept within [m/s], in [0, MAX_SPEED]
    initial_speed: float = 22.0  # speed at t = 0 of an integrated profile [m/s], within speed_band
    min_recorded_duration: float = 30.0  # shortest recorded leader (NGSIM vehicle, OpenACC lead car) drawn [s],
    # (0, MAX_DURATION]
    recorded_part: str = "all"  # which recorded leaders are drawn, one of RECORDED_PARTS: "all"; "held_out", a fixed
    # quarter (every HELD_OUT_EVERY-th NGSIM vehicle by id, OpenACC run by name), which the benchmark holds out;
    # "train", the rest

    def __post_init__(self) -> None:
        self._number("dt", MIN_DT, MAX_DT)
        self._number("duration", self.dt, MAX_EPISODE_TICKS * self.dt)
        self._number("min_recorded_duration", 0.0, MAX_DURATION, open_low=True)
        self._choice("recorded_part", RECORDED_PARTS)
        low, high = self._pair("speed_band", 0.0, MAX_SPEED)
        speed = self._number("initial_speed", 0.0, MAX_SPEED)
        if not low <= speed <= high:
            self._fail("initial_speed", speed, f"must lie in speed_band {self.speed_band}")

    @property
    def n_samples(self) -> int:
        """Samples in a synthetic profile, t = 0 included [-]."""
        return int(round(self.duration / self.dt)) + 1


@dataclasses.dataclass(frozen=True)
class AggressiveCyclesConfig(ConfigMixin):
    """The paper's leader: alternating hard acceleration and deceleration phases."""

    accel_range: tuple[float, float] = (1.5, 3.5)  # magnitude of each phase's acceleration [m/s^2], in (0, MAX_ACCEL]
    phase_duration_range: tuple[float, float] = (3.0, 9.0)  # length of each phase [s], in (0, MAX_DURATION]
    cruise_probability: float = 0.25  # chance that a phase is a cruise (a = 0) instead [-], [0, 1)
    max_jerk: float = 10.0  # how fast the leader moves between phase accelerations; aggressive drivers reach ~10
    # [m/s^3], (0, MAX_JERK]

    def __post_init__(self) -> None:
        self._pair("accel_range", 0.0, MAX_ACCEL, open_low=True)
        self._pair("phase_duration_range", 0.0, MAX_DURATION, open_low=True)
        self._number("cruise_probability", 0.0, 1.0, open_high=True)
        self._number("max_jerk", 0.0, MAX_JERK, open_low=True)


@dataclasses.dataclass(frozen=True)
class SinusoidConfig(ConfigMixin):
    """Speed oscillation v = mean + amplitude sin(2 pi t / period + phase), all drawn per seed."""

    amplitude_range: tuple[float, float] = (2.0, 6.0)  # speed amplitude [m/s], in (0, MAX_SPEED / 2]
    period_range: tuple[float, float] = (10.0, 40.0)  # oscillation period [s], in [1, MAX_DURATION]

    def __post_init__(self) -> None:
        self._pair("amplitude_range", 0.0, MAX_SPEED / 2, open_low=True)
        self._pair("period_range", 1.0, MAX_DURATION)


@dataclasses.dataclass(frozen=True)
class HardBrakingConfig(ConfigMixin):
    """Cruising interrupted by hard braking events, each followed by a gentler recovery."""

    n_events: int = 3  # braking events per profile [-], 1 to 100
    decel_range: tuple[float, float] = (4.0, 7.0)  # magnitude of the braking deceleration [m/s^2], in (0, MAX_ACCEL]
    speed_drop_range: tuple[float, float] = (5.0, 12.0)  # speed lost in one event [m/s], in (0, MAX_SPEED]
    recovery_accel: float = 1.5  # acceleration back to the cruise speed [m/s^2], (0, MAX_ACCEL]

    def __post_init__(self) -> None:
        self._number("n_events", 1, 100, integer=True)
        self._pair("decel_range", 0.0, MAX_ACCEL, open_low=True)
        self._pair("speed_drop_range", 0.0, MAX_SPEED, open_low=True)
        self._number("recovery_accel", 0.0, MAX_ACCEL, open_low=True)


@dataclasses.dataclass(frozen=True)
class StochasticHumanConfig(ConfigMixin):
    """Human-like speed: acceleration is an Ornstein-Uhlenbeck process pulled to a wandering target speed."""

    accel_std: float = 0.6  # stationary std of the acceleration noise [m/s^2], (0, MAX_ACCEL]
    accel_correlation_time: float = 2.0  # correlation time of the acceleration noise [s], (0, MAX_DURATION]
    speed_gain: float = 0.1  # pull of the speed towards the target speed [1/s], (0, 10]
    target_change_interval: float = 30.0  # mean time between changes of the target speed [s], (0, MAX_DURATION]

    def __post_init__(self) -> None:
        self._number("accel_std", 0.0, MAX_ACCEL, open_low=True)
        self._number("accel_correlation_time", 0.0, MAX_DURATION, open_low=True)
        self._number("speed_gain", 0.0, 10.0, open_low=True)
        self._number("target_change_interval", 0.0, MAX_DURATION, open_low=True)


@dataclasses.dataclass(frozen=True)
class HumanLeaderConfig(ConfigMixin):
    """highway-env's IDM driver as a human leader behind a scripted disturbance (``timegap_env.leaders.idm``)."""

    desired_speed_factor: float = 1.2  # driver's desired speed over the disturbance's top speed, above 1 so that it
    # follows the disturbance rather than cruising below it [-], (1, 10]
    time_wanted_range: tuple[float, float] = (1.0, 2.0)  # desired time gap of a seeded driver (highway-env: 1.5) [s],
    # in (0, MAX_TIME_GAP]
    comfort_accel_range: tuple[float, float] = (2.0, 4.0)  # desired acceleration of a seeded driver (highway-env: 3)
    # [m/s^2], in (0, MAX_ACCEL]
    max_initial_gap: float = 500.0  # longest accepted initial bumper-to-bumper gap [m], (0, 10000]

    def __post_init__(self) -> None:
        self._number("desired_speed_factor", 1.0, 10.0, open_low=True)
        self._pair("time_wanted_range", 0.0, MAX_TIME_GAP, open_low=True)
        self._pair("comfort_accel_range", 0.0, MAX_ACCEL, open_low=True)
        self._number("max_initial_gap", 0.0, 10_000.0, open_low=True)


@dataclasses.dataclass(frozen=True)
class SensorConfig(ConfigMixin):
    """What each follower measures of its own spacing and speed, once per tick."""

    spacing_noise_std: float = 0.1  # radar range noise; matches the spacing model's sigma^2 = 0.01 m^2 [m], [0, 100]
    speed_noise_std: float = 0.1  # own-speed noise [m/s], [0, MAX_SPEED]
    dropout_probability: float = 0.0  # chance that a tick's measurement of a follower is missing (NaN) [-], [0, 1)

    def __post_init__(self) -> None:
        self._number("spacing_noise_std", 0.0, 100.0)
        self._number("speed_noise_std", 0.0, MAX_SPEED)
        self._number("dropout_probability", 0.0, 1.0, open_high=True)


@dataclasses.dataclass(frozen=True)
class MonitorConfig(ConfigMixin):
    """Bayesian monitor of [s0, tau] from spacing and speed measurements (the paper's spacing model).

    The default prior's standstill spacing and tick follow ``PlatoonConfig``'s defaults;
    ``MONITOR_PRESETS["paper"]`` keeps the paper's printed numbers. The paper leaves open
    how old data are forgotten: ``window`` and ``forgetting`` both count age in ticks, so a
    skipped (invalid) measurement still ages the data, and the window always spans
    ``window`` seconds of time.
    """

    noise_variance: float = 0.01  # sigma^2 of the spacing model S = s0 + tau V + eps [m^2], (0, 1e4]
    prior_standstill_spacing: float = PlatoonConfig.standstill_spacing  # prior mean of s0 [m], [0, 100]; tau's is
    # the setting
    prior_cov: tuple[tuple[float, float], tuple[float, float]] = ((1e-4, -1e-5), (-1e-5, 0.125))  # Sigma_b of
    # [s0 [m], tau [s]], symmetric positive definite, entries within [-1e6, 1e6]
    window: float | None = 2.0  # sliding window, a multiple of dt; chosen by train/choose_window.py [s]; None keeps
    # all; at most MAX_WINDOW_TICKS ticks
    forgetting: float = 1.0  # exponential forgetting factor per tick, 1 = none [-], (0, 1]
    dt: float = PlatoonConfig.dt  # measurement period [s], [MIN_DT, MAX_DT]
    max_speed: float = 100.0  # speeds above this are implausible and skipped [m/s], (0, 1000]
    max_spacing: float = 1000.0  # spacings above this are implausible and skipped [m], (0, 1e5]
    min_speed: float = TIME_GAP_MIN_SPEED  # measurements below this speed carry no evidence on tau and are left
    # out (not counted as skipped): at a standstill the posterior returns to the prior, the setting [m/s], [0, 10]
    estimator: str = "bayes"  # one of MONITOR_ESTIMATORS: "bayes", the Proposition's posterior over the window;
    # "raw_gap", an ablation: each tick's (s - s0) / v with s0 the prior's mean, variance sigma^2 / v^2 (the prior
    # when the tick is left out), the window unused

    def __post_init__(self) -> None:
        self._choice("estimator", MONITOR_ESTIMATORS)
        self._number("noise_variance", 0.0, 1e4, open_low=True)
        self._number("prior_standstill_spacing", 0.0, 100.0)
        self._number("forgetting", 0.0, 1.0, open_low=True)
        self._number("dt", MIN_DT, MAX_DT)
        self._number("max_speed", 0.0, 1000.0, open_low=True)
        self._number("max_spacing", 0.0, 1e5, open_low=True)
        self._number("min_speed", 0.0, 10.0)
        if self.min_speed >= self.max_speed:
            self._fail("min_speed", self.min_speed, f"must be below max_speed = {self.max_speed}")
        rows = _items(self.prior_cov)
        matrix = None if rows is None or len(rows) != 2 else tuple(_items(row) for row in rows)
        if (matrix is None or any(row is None or len(row) != 2 for row in matrix)
                or not all(is_real(x) for row in cast(tuple[tuple[Any, ...], ...], matrix) for x in row)):
            self._fail("prior_cov", self.prior_cov, "must be a 2x2 matrix of numbers")
        matrix = cast(tuple[tuple[Any, ...], ...], matrix)  # no row is None: checked just above
        if not all(is_finite(x) and abs(x) <= 1e6 for row in matrix for x in row):
            self._fail("prior_cov", self.prior_cov, "entries must be finite and within [-1e6, 1e6]")
        cov = np.asarray(matrix, dtype=float)
        if not np.allclose(cov, cov.T) or np.any(np.linalg.eigvalsh(cov) <= 0):
            self._fail("prior_cov", self.prior_cov, "must be symmetric positive definite")
        object.__setattr__(self, "prior_cov", tuple(tuple(float(x) for x in row) for row in matrix))
        if self.window is not None:
            self._number("window", 0.0, math.inf, open_low=True)
            self._ticks("window", self.dt, MAX_WINDOW_TICKS)

    @property
    def window_ticks(self) -> int | None:
        """Length of the sliding window in ticks, None when all data are kept [-]."""
        return None if self.window is None else int(round(self.window / self.dt))


@dataclasses.dataclass(frozen=True)
class ChartConfig(ConfigMixin):
    """Control chart on the posterior mean of tau (Shewhart, EWMA or CUSUM), and the paper's switching rule."""

    kind: str = "shewhart"  # chart used by make_chart, one of CHART_KINDS
    baseline_std: float = 0.125  # sigma_desired of the baseline N(tau*, sigma_desired^2) [s], (0, MAX_TIME_GAP]
    limit_width: float = 2.0  # L: Shewhart limits at tau* -/+ L sigma_desired [-], (0, MAX_WIDTH]
    ewma_lambda: float = 0.2  # EWMA weight of the newest estimate [-], (0, 1]
    ewma_width: float = 3.0  # EWMA limits at tau* -/+ width sigma_desired sqrt(lambda / (2 - lambda)) [-],
    # (0, MAX_WIDTH]
    cusum_k: float = 0.5  # CUSUM reference value (allowance) [sigma_desired], [0, MAX_WIDTH]
    cusum_h: float = 5.0  # CUSUM decision interval [sigma_desired], (0, MAX_WIDTH]
    exceedance_window: float = 35.0  # trailing window in which exceedances are counted, a multiple of dt [s],
    # at most MAX_WINDOW_TICKS ticks
    switch_exceedances: int = 3  # paper's rule: this many exceedances within the window ... [-], 1 to the window's
    # ticks (more can never happen)
    switch_to: float = 1.0  # ... switch the setting to this time gap [s], (0, MAX_TIME_GAP]
    settle_time: float = 8.0  # alarms wait this long after a commanded change has ramped in; long enough
    # for the slowest change of the default ladder, 0.6 -> 2.2 s (tests/monitoring/test_loop.py) [s], [0, MAX_DURATION]
    dt: float = PlatoonConfig.dt  # chart tick, one estimate per tick [s], [MIN_DT, MAX_DT]

    def __post_init__(self) -> None:
        self._choice("kind", CHART_KINDS)
        self._number("baseline_std", 0.0, MAX_TIME_GAP, open_low=True)
        self._number("ewma_lambda", 0.0, 1.0, open_low=True)
        for field in ("limit_width", "ewma_width", "cusum_h"):
            self._number(field, 0.0, MAX_WIDTH, open_low=True)
        self._number("cusum_k", 0.0, MAX_WIDTH)
        self._number("switch_to", 0.0, MAX_TIME_GAP, open_low=True)
        self._number("settle_time", 0.0, MAX_DURATION)
        self._number("dt", MIN_DT, MAX_DT)
        self._number("exceedance_window", 0.0, math.inf, open_low=True)
        ticks = self._ticks("exceedance_window", self.dt, MAX_WINDOW_TICKS)
        self._number("switch_exceedances", 1, ticks, integer=True)

    @property
    def exceedance_window_ticks(self) -> int:
        """Length of the exceedance-counting window in ticks [-]."""
        return int(round(self.exceedance_window / self.dt))

    @property
    def settle_ticks(self) -> int:
        """``settle_time`` in ticks [-]."""
        return int(round(self.settle_time / self.dt))

    @property
    def half_width(self) -> float:
        """L sigma_desired: from the centre line to either Shewhart limit [s]."""
        return self.limit_width * self.baseline_std


MONITOR_PRESETS: dict[str, MonitorConfig] = {
    "default": MonitorConfig(),
    "paper": MonitorConfig(  # the paper's printed prior and noise, s0 = 1 m although its simulator uses 5 m
        noise_variance=0.01,
        prior_standstill_spacing=1.0,
        prior_cov=((1e-4, -1e-5), (-1e-5, 0.125)),
    ),
}


class Interval(NamedTuple):
    """The numbers from ``low`` to ``high``, each end closed unless it is open."""

    low: float
    high: float
    open_low: bool = False
    open_high: bool = False

    def __contains__(self, value: object) -> bool:
        return is_real(value) and _within(float(cast(float, value)), *self)

    def __str__(self) -> str:
        return _interval(*self)


class Objective(NamedTuple):
    """What a reward term measures, in natural units, and how the term is made of it."""

    name: str  # its name in objectives_of(info) (TimeGapMonitor-v1's info["objectives"])
    unit: str
    term: str  # the term as a function of the objective (per follower, then the mean, where it says so)


@dataclasses.dataclass(frozen=True)
class RewardScale:
    """A reference scale of a reward term: a field of :class:`RewardScales` and, by the same name, of the reward's
    constants (``timegap_env.envs.reward.RewardConstants``)."""

    name: str
    default: float
    unit: str
    bounds: Interval  # a value must lie in it
    meaning: str  # what it is (and, where it is not plain, why its bounds)


@dataclasses.dataclass(frozen=True)
class RewardTerm:
    """A term of ``TimeGapMonitor-v0``'s reward, one record of :data:`REWARD_TERM_RECORDS`: everything about it but
    its formula and its objective's, which the compiled kernels of :mod:`timegap_env.envs.reward` compute
    (``env_reward_terms``, ``env_objectives``)."""

    name: str  # a field of RewardWeights and of reward.RewardTerms; info's "reward_<name>"
    weight: float  # its default weight [-]
    value: str  # its value per step (<= 0), as env_reward_terms computes it
    why: str
    objective: Objective  # what it measures in natural units, as env_objectives computes it
    scales: tuple[RewardScale, ...] = ()  # its reference scales, fields of RewardScales in this order
    lowest: float | Callable[[RewardScales], float] = -1.0  # its lowest value in a step, or that as a function of
    # the scales; -inf where it has none
    cost: bool = False  # it counts in info["cost"] (reward.COST_TERMS), clipped to [-1, 0]

    def low(self, scales: RewardScales) -> float:
        """The term's lowest value in a step under ``scales``; -inf where it has none."""
        return self.lowest(scales) if callable(self.lowest) else self.lowest


REWARD_TERM_RECORDS: dict[str, RewardTerm] = {term.name: term for term in (  # in the order the terms are summed
    RewardTerm(
        "tracking", 1.0,
        "-mean over follower-ticks of min(abs((s - s0)/v - applied setting), tracking_cap) / tracking_reference, "
        "at v >= 1 m/s",
        "keep the actual gap at the setting; capped at 0.5 s (-2) because at low speed (s - s0)/v explodes",
        Objective("time_gap_variation", "s", "-time_gap_variation / tracking_reference: the mean over "
                  "follower-ticks of min(abs(actual time gap - applied setting), tracking_cap), 0 below 1 m/s"),
        (RewardScale("tracking_reference", 0.25, "s", Interval(0.001, MAX_TIME_GAP), "a tick's |actual time gap - "
                     "setting| costing one tracking unit (smaller would make the term, tracking_cap over it, absurdly "
                     "large)"),
         RewardScale("tracking_cap", 0.5, "s", Interval(0.0, MAX_TIME_GAP, open_low=True),
                     "a tick's |actual time gap - setting| counts up to this in the tracking term")),
        lowest=lambda scales: -scales.tracking_cap / scales.tracking_reference),
    RewardTerm(
        "string_stability", 1.0,
        "-min(1, sum over vehicles of max(0, envelope of the vehicle - envelope of its predecessor) / "
        "accel_growth_reference) at the step's end, a vehicle's envelope its peak abs(acceleration) decaying with "
        "time constant accel_envelope_time, the leader first",
        "disturbances must not grow down the platoon (string stability is about accelerations; a static offset of "
        "the gap does not count)",
        Objective("acceleration_growth", "m/s^2", "-min(1, acceleration_growth / accel_growth_reference): the rise "
                  "of the acceleration envelopes down the platoon"),
        (RewardScale("accel_growth_reference", 1.0, "m/s^2", Interval(0.001, MAX_ACCEL),
                     "growth of the peak acceleration down the platoon costing one string-stability unit"),
         RewardScale("accel_envelope_time", 5.0, "s", Interval(0.0, MAX_DURATION, open_low=True),
                     "time constant of the decaying peak acceleration the growth compares")),
        cost=True),
    RewardTerm(
        "safety", 2.0,
        "-max(0, 1 - TTC / ttc_threshold), TTC the step's smallest (below -1 once a gap is gone)",
        "keep a margin to the predecessor",
        Objective("ttc_shortfall", "s", "-ttc_shortfall / ttc_threshold: the mean over followers of "
                  "max(0, ttc_threshold - the step's smallest time-to-collision)"),
        (RewardScale("ttc_threshold", 4.0, "s", Interval(0.0, 60.0, open_low=True),
                     "time-to-collision below which safety is penalised"),),
        lowest=-math.inf, cost=True),  # a negative TTC once a gap is gone
    RewardTerm(
        "collision", 1000.0,
        "-1 on the step a collision ends the episode",
        "outweighs any whole episode of the rest",
        Objective("collision", "-", "-collision: 1 on the step a gap reaches 0"),
        cost=True),
    RewardTerm(
        "comfort", 0.05,
        "-mean over ticks of (jerk / jerk_reference)^2",
        "no chattering",
        Objective("jerk_squared", "m^2/s^6", "-jerk_squared / jerk_reference^2: the mean over follower-ticks of "
                  "jerk^2"),
        (RewardScale("jerk_reference", 2.0, "m/s^3", Interval(0.01, MAX_JERK),
                     "jerk that costs one comfort unit (smaller would let the squared term overflow)"),),
        lowest=-math.inf),  # jerk squared has no bound
    RewardTerm(
        "efficiency", 1.0,
        "-(1 - capacity(tau*) / capacity(smallest level)) at the current speed",
        "a smaller setting moves more vehicles per hour",
        Objective("capacity", "veh/h", "-mean over followers of (1 - capacity / capacity at the smallest level); "
                  "capacity = 3600 v / (v tau* + s0 + vehicle length) at the step's final speed v, the objective its "
                  "mean over followers")),
    RewardTerm(
        "preference", 0.5,
        "-abs(tau* - preferred_setting) / span of the levels",
        "the driver chose 1.6 s",
        Objective("preference_deviation", "s", "-preference_deviation / span of the levels: the mean over followers "
                  "of abs(tau* - preferred_setting)")),
    RewardTerm(
        "switching", 0.2,
        "-share of followers whose setting changed",
        "no chattering",
        Objective("switching", "-", "-switching: the share of followers whose setting changed")),
)}
REWARD_SCALE_RECORDS: dict[str, RewardScale] = {  # every term's scales, in the order of the terms
    scale.name: scale for term in REWARD_TERM_RECORDS.values() for scale in term.scales}

_Config = TypeVar("_Config", bound=ConfigMixin)


def _float_fields(fields: dict[str, float], listing: str) -> Callable[[type[_Config]], type[_Config]]:
    """Makes the decorated config class a frozen dataclass of ``fields`` (name -> default), one float each in their
    order, and adds ``listing``, what they are, to its docstring (for configs whose fields come from records)."""

    def make(cls: type[_Config]) -> type[_Config]:
        cls.__annotations__ = {name: float for name in fields}
        for name, default in fields.items():
            setattr(cls, name, default)
        cls.__doc__ = f"{inspect.cleandoc(cls.__doc__ or '')}\n\n{listing}"
        return dataclasses.dataclass(frozen=True)(cls)

    return make


@_float_fields({term.name: term.weight for term in REWARD_TERM_RECORDS.values()},
               "Fields (made at import from REWARD_TERM_RECORDS), default weights [-]: "
               + ", ".join(f"{term.name} = {term.weight:g}" for term in REWARD_TERM_RECORDS.values()) + ".")
class RewardWeights(ConfigMixin):
    """Weight of each reward term of ``TimeGapMonitor-v0``, one field per record of :data:`REWARD_TERM_RECORDS` in the
    order the terms are summed, its default the record's ``weight`` (the fields are listed below).

    The terms themselves (each <= 0, about -1 at its worst) are in their records and
    :mod:`timegap_env.envs.reward`, whose ``RewardTerms`` takes its field names from this class.
    Every weight lies in [0, MAX_WEIGHT].
    """

    if TYPE_CHECKING:  # the fields come from the records at import: one float per term
        __dataclass_fields__: ClassVar[dict[str, dataclasses.Field[Any]]]

        def __init__(self, *weights: float, **by_name: float) -> None: ...

        def __getattr__(self, name: str) -> float: ...

    def __post_init__(self) -> None:
        for field in dataclasses.fields(self):
            self._number(field.name, 0.0, MAX_WEIGHT)

    @classmethod
    def of(cls, value: Any, field: str = "reward_weights") -> RewardWeights:
        """``value`` as weights: RewardWeights, a preset's name (:data:`REWARD_PRESETS`) or a sequence of one weight
        per field in field order; ``ValueError`` naming ``field`` and the value otherwise. (A dict of some weights
        overrides the task's or EnvConfig's: :meth:`EnvConfig.from_dict` and :meth:`EnvConfig.nested_overrides` take it.)"""
        names = [f.name for f in dataclasses.fields(cls)]
        if isinstance(value, cls):
            return value
        if isinstance(value, str):
            if value not in REWARD_PRESETS:
                raise ValueError(f"{field} = {value!r}: unknown preset; known: {list(REWARD_PRESETS)}")
            return REWARD_PRESETS[value].weights
        items = None if isinstance(value, Mapping) else _items(value)
        if items is None:
            raise ValueError(f"{field} = {shown(value)}: must be a preset's name {list(REWARD_PRESETS)}, a sequence of "
                             f"{len(names)} weights in the order {names}, or (through EnvConfig.from_dict) a dict of "
                             "weights")
        if len(items) != len(names):
            raise ValueError(f"{field} = {shown(value)}: has {len(items)} weights; needs {len(names)}, one per term "
                             f"in the order {names}")
        try:
            return cls(*items)
        except ValueError as error:
            raise ValueError(f"{field}: {error}") from error


@dataclasses.dataclass(frozen=True)
class RewardPreset:
    """A whole weighting of the reward terms a traffic engineer could defend, and why (docs/task.md)."""

    name: str
    weights: RewardWeights
    why: str


REWARD_PRESETS: dict[str, RewardPreset] = {preset.name: preset for preset in (
    RewardPreset("driver_preference", RewardWeights(), "TimeGapMonitor-v0's default: the driver chose 1.6 s"),
    RewardPreset("variation_first", RewardWeights(tracking=2.0, efficiency=0.0, preference=0.0),
                 "the paper's measure: the actual time gap kept at its setting; no capacity pressure, no preference"),
    RewardPreset("capacity_first", RewardWeights(tracking=0.5, string_stability=2.0, efficiency=2.0, preference=0.0),
                 "an operator's: capacity, guarded by string stability and safety; no driver preference"),
)}


@_float_fields({scale.name: scale.default for scale in REWARD_SCALE_RECORDS.values()},
               "Fields (made at import from the records' scales), default [unit], bounds: what it is:\n\n"
               + "\n".join(f"- {scale.name} = {scale.default:g} [{scale.unit}], {scale.bounds}: {scale.meaning}"
                           for scale in REWARD_SCALE_RECORDS.values()))
class RewardScales(ConfigMixin):
    """What one unit of each reward term is, in natural units: the reference scales beside :class:`RewardWeights`,
    one field per :class:`RewardScale` of the records of :data:`REWARD_TERM_RECORDS` (listed below), its default,
    unit and bounds the record's (:mod:`timegap_env.envs.reward` gives each term's formula)."""

    if TYPE_CHECKING:  # the fields come from the records at import: one float per scale
        __dataclass_fields__: ClassVar[dict[str, dataclasses.Field[Any]]]

        def __init__(self, *scales: float, **by_name: float) -> None: ...

        def __getattr__(self, name: str) -> float: ...

    def __post_init__(self) -> None:
        for scale in REWARD_SCALE_RECORDS.values():
            bounds = scale.bounds
            self._number(scale.name, bounds.low, bounds.high, open_low=bounds.open_low, open_high=bounds.open_high)


@dataclasses.dataclass(frozen=True)
class Lever:
    """A follower's parameter that degradations set, as one record of :data:`LEVERS`: the
    :class:`~timegap_env.sim.degradation.DegradationTable` holds it per follower (nominal while no degradation acts)
    and copies it into every structure with a field of its name, the physics'
    :class:`~timegap_env.sim.platoon.FollowerFaults` and the sensors'
    :class:`~timegap_env.monitoring.sensors.SensorFaults`, whose kernels give it its effect; the ground truth
    reports it among the true parameters under ``truth``."""

    name: str  # the table's array, and the field of FollowerFaults or SensorFaults that reads it
    dtype: type  # float, np.int64 (ticks) or bool (a flag)
    unit: str
    nominal: Callable[[PlatoonConfig, SensorConfig], float | np.ndarray]  # its value while no degradation acts (one,
    # or one per follower)
    truth: str | None = None  # its name among the ground truth's true parameters; None: not reported
    # its value as the ground truth reports it, in that parameter's unit
    reported: Callable[[np.ndarray | float, PlatoonConfig], np.ndarray | float] = lambda value, platoon: value


LEVERS: dict[str, Lever] = {lever.name: lever for lever in (  # the true parameters are reported in this order
    Lever("lag", float, "s", lambda platoon, sensors: platoon.per_follower("actuation_lag"), "lag"),  # GLVD lag T
    Lever("gain", float, "-", lambda platoon, sensors: platoon.per_follower("actuation_gain"), "gain"),  # GLVD gain K
    Lever("k_s", float, "1/s^2", lambda platoon, sensors: platoon.k_s, "k_s"),  # controller gain on the spacing error
    Lever("k_v", float, "1/s", lambda platoon, sensors: platoon.k_v, "k_v"),  # controller gain on the speed difference
    Lever("accel_max", float, "m/s^2", lambda platoon, sensors: platoon.accel_max),  # highest command
    Lever("extra_delay", np.int64, "ticks", lambda platoon, sensors: 0, "v2v_delay",  # V2V delay added; reported:
          lambda ticks, platoon: platoon.v2v_delay + ticks * platoon.dt),  # the whole V2V delay theta [s]
    Lever("packet_loss", float, "-", lambda platoon, sensors: 0.0, "packet_loss"),  # chance a V2V message is lost
    Lever("radar_bias", float, "m", lambda platoon, sensors: 0.0, "radar_bias"),  # added to the radar's spacing
    Lever("radar_noise", float, "m", lambda platoon, sensors: sensors.spacing_noise_std, "radar_noise"),  # std of
    # the radar's spacing noise
    Lever("v2v_down", bool, "-", lambda platoon, sensors: False),  # the V2V link is down (the flag shows it)
)}


@dataclasses.dataclass(frozen=True)
class DegradationKind:
    """What can go wrong with a follower, as one record of :data:`DEGRADATIONS` (:mod:`timegap_env.sim.degradation`
    draws it, writes it into the physics and the sensors, and reports its ground truth from these fields alone).

    A kind sets one parameter of the follower, its ``lever``, a record of :data:`LEVERS` read by the physics, the
    sensors and the ground truth: ``lag`` [s], ``gain`` [-], ``k_s`` [1/s^2], ``k_v`` [1/s], ``accel_max``
    [m/s^2], ``extra_delay`` [ticks], ``packet_loss`` [-], ``radar_bias`` [m], ``radar_noise`` [m] or the flag
    ``v2v_down`` (a kind without a size sets a flag). The smallest string-stable setting follows from the lever's
    new value.
    """

    name: str
    effect: str  # what happens while it acts, for the docs
    lever: str | None  # the name of the LEVERS record it sets; None: commercial_acc, which replaces the car's model
    size: str | None = None  # what its size is, with its unit; None: the kind has no size (a flag lever is set)
    size_bounds: Interval | None = None  # a size given by hand (reset options) must lie in it
    range_field: str | None = None  # the DegradationConfig field its drawn sizes come from (a magnitude if signed)
    range_bounds: Interval | None = None  # that field's ends must lie in it
    scales: bool = False  # the size multiplies the lever's nominal value instead of replacing it
    signed: bool = False  # the draw flips the size's sign with chance 1/2
    whole_ticks: bool = False  # the size is a time: drawn on whole ticks of dt, and the lever holds it in ticks
    duration_field: str | None = None  # the DegradationConfig field of how long it lasts when drawn: it starts
    # anywhere it fits and always ends (without one it starts at 0 or midway and ends with recovery_probability)
    default_weight: float = 1.0  # its weight in the default DegradationConfig.kind_weights [-]


DEGRADATIONS: dict[str, DegradationKind] = {kind.name: kind for kind in (  # in the order of their int8 codes (1, 2, ...)
    DegradationKind("lag", "the GLVD lag grows (brake fade, load)", "lag", "factor on the lag T [-]",
                    Interval(0.0, 10.0, open_low=True), "lag_factor_range", Interval(1.0, 10.0), scales=True),
    DegradationKind("gain", "the car realises less of the command (grade, weight)", "gain", "gain K [-]",
                    Interval(0.0, 10.0, open_low=True), "gain_range", Interval(0.0, 1.0, open_low=True)),
    DegradationKind("v2v_latency", "V2V messages arrive later; the flag stays up", "extra_delay",
                    "added V2V delay [s]", Interval(0.0, MAX_TIME_GAP), "v2v_latency_range", Interval(0.0, MAX_TIME_GAP),
                    whole_ticks=True),
    DegradationKind("packet_loss", "V2V messages are lost, the feed-forward holds the last one received; the flag "
                    "stays up", "packet_loss", "chance per tick [-]", Interval(0.0, 1.0, open_high=True),
                    "packet_loss_range", Interval(0.0, 1.0, open_high=True), default_weight=4.0),
    DegradationKind("v2v_outage", "the link is down and the flag shows it: ACC", "v2v_down",
                    duration_field="v2v_outage_duration_range"),
    DegradationKind("radar_bias", "the radar reads the spacing off by it, for the controller and the monitor alike: "
                    "with a positive bias the car keeps less than its setting, by bias / v", "radar_bias",
                    "spacing bias [m]", Interval(-100.0, 100.0), "radar_bias_range", Interval(0.0, 100.0), signed=True),
    DegradationKind("radar_noise", "the radar's spacing reading is this noisy (the monitor's view; the controller "
                    "filters)", "radar_noise", "spacing noise std [m]", Interval(0.0, 100.0), "radar_noise_range",
                    Interval(0.0, 100.0), default_weight=4.0),
    DegradationKind("commercial_acc", "the follower is a commercial ACC car calibrated to OpenACC "
                    "(timegap_env.sim.presets): its lag, gains and highest command, and no V2V", None),
)}
def write_nominal_levers(faults: tuple, platoon: PlatoonConfig, sensors: SensorConfig) -> None:
    """Set every array of ``faults`` (a NamedTuple, e.g. FollowerFaults) whose field is named as a lever of
    :data:`LEVERS` to that lever's nominal value under ``platoon`` and ``sensors``."""
    for name, values in zip(faults._fields, faults):  # type: ignore[attr-defined]
        if name in LEVERS:
            values[...] = LEVERS[name].nominal(platoon, sensors)


if not all(kind.lever is None or kind.lever in LEVERS for kind in DEGRADATIONS.values()):
    raise ImportError(f"timegap_env.config.DEGRADATIONS: each kind's lever must be one of LEVERS {list(LEVERS)}")
DEGRADATION_KINDS = tuple(DEGRADATIONS)  # what can go wrong with a follower; only v2v_outage shows (the flag drops)


def _default_degradation_weights() -> dict[str, float]:
    """Chosen by measurement (``python -m train.choose_degradation_mix``, ``results/degradation/mix.md``): of the mixes
    keeping every kind at weight 1, 2 or 4, the one where knowing the hidden degradations is worth most (2 % of the
    best blind constant's return; every kind at 1: 1 %)."""
    return {"none": 4.0, **{name: kind.default_weight for name, kind in DEGRADATIONS.items()}}


@dataclasses.dataclass(frozen=True)
class DegradationConfig(ConfigMixin):
    """What degradation each episode draws (:mod:`timegap_env.sim.degradation`): one kind, or none.

    The kind comes from ``kind_weights``; it hits each follower with ``follower_probability`` (at
    least one), with a size drawn from the kind's range; it starts at 0 or, with
    ``midway_onset_probability``, somewhere in the episode's middle half, and ends before the
    episode with ``recovery_probability``. A V2V outage always ends (it lasts
    ``v2v_outage_duration_range``); a commercial ACC car is what it is from start to end.
    """

    kind_weights: dict[str, float] = dataclasses.field(default_factory=_default_degradation_weights)  # kind -> weight,
    # kinds "none" and DEGRADATION_KINDS, weights in [0, MAX_WEIGHT], not all 0
    lag_factor_range: tuple[float, float] = (1.5, 2.5)  # actuation lag T multiplied by [-], in [1, 10]
    gain_range: tuple[float, float] = (0.6, 0.85)  # actuation gain K [-], in (0, 1]
    v2v_latency_range: tuple[float, float] = (0.2, 0.6)  # V2V delay added, a multiple of dt when drawn [s], in
    # [0, MAX_TIME_GAP] (and within PlatoonConfig.max_v2v_latency)
    packet_loss_range: tuple[float, float] = (0.3, 0.9)  # chance per tick that a V2V message is lost [-], in [0, 1)
    v2v_outage_duration_range: tuple[float, float] = (20.0, 80.0)  # how long the V2V link is down [s], in
    # [0, MAX_DURATION]
    radar_bias_range: tuple[float, float] = (1.0, 4.0)  # |bias| of the radar's spacing, sign drawn [m], in [0, 100]
    radar_noise_range: tuple[float, float] = (0.3, 1.0)  # std of the radar's spacing noise while degraded [m], in
    # [0, 100]
    follower_probability: float = 1.0  # chance each follower is hit; at least one is [-], [0, 1]
    midway_onset_probability: float = 0.5  # chance the degradation starts mid-episode rather than at 0 [-], [0, 1]
    recovery_probability: float = 0.3  # chance it ends before the episode does [-], [0, 1]

    def __post_init__(self) -> None:
        self._weights("kind_weights", "kind", ("none", *DEGRADATION_KINDS))
        for kind in DEGRADATIONS.values():
            if kind.range_field is not None:
                assert kind.range_bounds is not None  # a record with a range field bounds it
                bounds = kind.range_bounds
                self._pair(kind.range_field, bounds.low, bounds.high, open_low=bounds.open_low,
                           open_high=bounds.open_high)
            if kind.duration_field is not None:
                self._pair(kind.duration_field, 0.0, MAX_DURATION)
        for field in ("follower_probability", "midway_onset_probability", "recovery_probability"):
            self._number(field, 0.0, 1.0)

    def size_range(self, kind: str) -> tuple[float, float]:
        """The range a sized ``kind``'s size is drawn from (of a signed kind, its magnitude); ``KeyError`` for a kind
        without one."""
        field = DEGRADATIONS[kind].range_field
        if field is None:
            raise KeyError(f"degradation kind {kind!r} has no size range")
        return cast(tuple[float, float], getattr(self, field))


@dataclasses.dataclass(frozen=True)
class SumoConfig(ConfigMixin):
    """How SUMO simulates the platoon when ``EnvConfig.simulator`` is "sumo" (``timegap_env.sim.sumo``)."""

    model: str = "cc"  # one of SUMO_MODELS: "cc", Plexe's CC model (ACC without V2V, Ploeg's CACC with it; the
    # engine lag and the controller gains mapped from PlatoonConfig); "cacc", SUMO's CACC model with its defaults
    ballistic: bool = True  # SUMO's ballistic position update (False: its Euler update)

    def __post_init__(self) -> None:
        self._choice("model", SUMO_MODELS)
        self._flag("ballistic")


def _default_scenario_weights() -> dict[str, float]:
    return {"aggressive_cycles": 1.0, "sinusoid": 1.0, "hard_braking": 1.0, "stochastic_human": 1.0}


NESTED_CONFIGS: dict[str, type[ConfigMixin]] = {  # EnvConfig's nested configs, each given as a dict of its fields
    "platoon": PlatoonConfig, "leader": LeaderConfig, "sensors": SensorConfig, "monitor": MonitorConfig,
    "chart": ChartConfig, "reward_weights": RewardWeights, "reward_scales": RewardScales,
    "degradation": DegradationConfig, "sumo": SumoConfig,
}


@dataclasses.dataclass(frozen=True)
class EnvConfig(ConfigMixin):
    """Every field of an env's config, with the base defaults (``TimeGapMonitor-v0``'s). A task's config is these
    defaults with its record's overrides (``timegap_env.tasks.get_task(id).config()``); ``gym.make(id, config={...})``
    overrides that.

    Nested configs take dicts of their own fields, e.g. ``{"platoon": {"n_followers": 3}}``.
    A synthetic leader lasts the episode: ``leader.duration`` follows ``episode_duration``
    (left at its default it is set to it; any other value must equal it).
    """

    platoon: PlatoonConfig = PlatoonConfig()
    leader: LeaderConfig = LeaderConfig()
    sensors: SensorConfig = SensorConfig()
    monitor: MonitorConfig = MonitorConfig()
    chart: ChartConfig = ChartConfig()
    reward_weights: RewardWeights = RewardWeights()  # noqa: RUF009 (frozen, a dataclass made by _float_fields)
    reward_scales: RewardScales = RewardScales()  # noqa: RUF009 (frozen, a dataclass made by _float_fields)
    decision_interval: float = 1.0  # time between two actions, a multiple of platoon.dt [s], at most
    # MAX_DECISION_TICKS ticks and episode_duration
    episode_duration: float = 250.0  # [s], a multiple of platoon.dt, at most MAX_EPISODE_TICKS ticks
    action_mode: str = "platoon"  # one of ACTION_MODES: one setting for all followers, one each, or a relative step
    random_initial_setting: bool = False  # each episode starts at a ladder level drawn from the seed, not at
    # platoon.initial_setting (for training: a relative policy then learns to reach a setting, not only to keep one)
    setting_levels: tuple[float, ...] = (0.6, 0.8, 1.0, 1.2, 1.4, 1.6, 1.8, 2.0, 2.2)  # settings to choose from [s],
    # 2 to MAX_SETTING_LEVELS increasing values in (0, MAX_TIME_GAP]
    preferred_setting: float = 1.6  # the setting the driver chose [s], within the ladder [setting_levels[0],
    # setting_levels[-1]] (so the preference term stays in [-1, 0])
    scenario_weights: dict[str, float] = dataclasses.field(default_factory=_default_scenario_weights)  # family ->
    # weight in [0, MAX_WEIGHT], not all 0; the families are checked against SCENARIOS when the env is built
    degradation: DegradationConfig = DegradationConfig()  # what can go wrong with the followers, drawn per episode
    leader_params: dict[str, dict[str, Any]] = dataclasses.field(default_factory=dict)  # synthetic leader family ->
    # overrides of its parameter dataclass (its LeaderFamily record's params, timegap_env.leaders), e.g. {"sinusoid":
    # {"amplitude_range": (4.0, 8.0)}}; the families and fields are checked when the env is built
    dropout_probability_range: tuple[float, float] = (0.0, 0.05)  # per-episode sensor dropout rate drawn from [-],
    # 0 <= low <= high < 1
    simulator: str = "native"  # one of SIMULATORS: "native", this package's compiled platoon; "sumo", SUMO through
    # libsumo (the sumo extra; one env at a time per process), configured by ``sumo``
    sumo: SumoConfig = SumoConfig()

    def __post_init__(self) -> None:
        object.__setattr__(self, "reward_weights", RewardWeights.of(self.reward_weights, "EnvConfig.reward_weights"))
        for field, kind in NESTED_CONFIGS.items():
            if not isinstance(getattr(self, field), kind):
                self._fail(field, getattr(self, field), f"must be a {kind.__name__} (or a dict of its fields)")
        dt = self.platoon.dt
        for name, config in (("monitor", self.monitor), ("chart", self.chart), ("leader", self.leader)):
            if not math.isclose(config.dt, dt):
                self._fail(f"{name}.dt", config.dt, f"must equal platoon.dt = {dt}")
        for field in ("decision_interval", "episode_duration"):
            self._number(field, 0.0, math.inf, open_low=True)
        self._ticks("episode_duration", dt, MAX_EPISODE_TICKS, "platoon.dt")
        self._ticks("decision_interval", dt, MAX_DECISION_TICKS, "platoon.dt")
        if self.decision_interval > self.episode_duration:
            self._fail("decision_interval", self.decision_interval,
                       f"must be at most episode_duration = {self.episode_duration} s")
        if not math.isclose(self.leader.duration, self.episode_duration):
            if self.leader.duration != LeaderConfig.duration:
                self._fail("leader.duration", self.leader.duration,
                           f"a synthetic leader lasts the episode: leave it out or make it episode_duration = "
                           f"{self.episode_duration}")
            object.__setattr__(self, "leader", self.leader.with_overrides({"duration": float(self.episode_duration)}))
        self._choice("action_mode", ACTION_MODES)
        self._flag("random_initial_setting")
        levels = _items(self.setting_levels)
        if (levels is None or not 2 <= len(levels) <= MAX_SETTING_LEVELS or not all(is_real(x) for x in levels)
                or not all(is_finite(x) and 0 < x <= MAX_TIME_GAP for x in levels)):
            self._fail("setting_levels", self.setting_levels,
                       f"must be 2 to {MAX_SETTING_LEVELS} finite settings in (0, {MAX_TIME_GAP:g}]")
        if np.any(np.diff(np.asarray(levels, dtype=float)) <= 0):
            self._fail("setting_levels", self.setting_levels, "must increase strictly")
        object.__setattr__(self, "setting_levels", tuple(float(level) for level in levels))
        if not np.any(np.isclose(levels, self.platoon.initial_setting)):
            self._fail("platoon.initial_setting", self.platoon.initial_setting, f"must be one of {self.setting_levels}")
        self._number("preferred_setting", levels[0], levels[-1])
        self._weights("scenario_weights", "family")
        params = self.leader_params
        if not isinstance(params, Mapping) or not all(isinstance(family, str) and isinstance(fields, Mapping)
                                                       for family, fields in params.items()):
            self._fail("leader_params", params, "must be a dict family (a string) -> dict of its parameters")
        object.__setattr__(self, "leader_params", {family: dict(fields) for family, fields in params.items()})
        if self.degradation.v2v_latency_range[1] > self.platoon.max_v2v_latency + 1e-9:
            self._fail("degradation.v2v_latency_range", self.degradation.v2v_latency_range,
                       f"must stay within platoon.max_v2v_latency = {self.platoon.max_v2v_latency} s")
        self._pair("dropout_probability_range", 0.0, 1.0, open_high=True, strict=False)
        self._choice("simulator", SIMULATORS)

    @classmethod
    def from_dict(cls, overrides: Mapping[str, Any] | EnvConfig | None = None) -> EnvConfig:
        """EnvConfig's own defaults with ``overrides`` (a task's config is ``timegap_env.tasks.get_task(id).config``);
        nested configs take dicts of their own fields, ``reward_weights`` also a preset's name or a sequence of
        weights (:meth:`RewardWeights.of`). An EnvConfig is already whole: it is returned as it is."""
        if isinstance(overrides, EnvConfig):
            return overrides
        return cls().nested_overrides(overrides)

    def nested_overrides(self, overrides: Mapping[str, Any] | None) -> EnvConfig:
        """Copy of this config with ``overrides``, nested configs as dicts of their fields over this one's (a preset's
        name or a sequence for ``reward_weights``); ``ValueError`` naming an unknown or bad field."""
        if overrides is not None and not isinstance(overrides, Mapping):
            raise ValueError(f"EnvConfig config = {shown(overrides)}: must be a dict of EnvConfig fields "
                             f"(nested configs as dicts) or None")
        overrides = dict(overrides or {})
        for field in NESTED_CONFIGS:
            if isinstance(overrides.get(field), Mapping):
                try:
                    overrides[field] = getattr(self, field).with_overrides(overrides[field])
                except ValueError as error:
                    raise ValueError(f"EnvConfig.{field}: {error}") from error
        if isinstance(overrides.get("setting_levels"), (list, np.ndarray)):
            overrides["setting_levels"] = tuple(overrides["setting_levels"])
        return self.with_overrides(overrides)

    @property
    def ticks_per_decision(self) -> int:
        """Simulator ticks per environment step [-]."""
        return int(round(self.decision_interval / self.platoon.dt))

    @property
    def max_episode_steps(self) -> int:
        """Environment steps in a full episode [-]."""
        return int(round(self.episode_duration / self.decision_interval))

    @property
    def setting_span(self) -> float:
        """Largest setting level minus the smallest [s]."""
        return float(self.setting_levels[-1]) - float(self.setting_levels[0])
