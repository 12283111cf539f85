"""Default parameters of the platoon, its leader and the monitor: the one source of truth.

Every config is a frozen dataclass. Its fields carry units in comments, its
``__post_init__`` validates them, and ``with_overrides`` builds a copy from a
dict of overrides, raising ``ValueError`` that names the field and the value
for an unknown key or a bad value.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any, Self

import numpy as np

MPH = 0.44704  # [m/s per mph]
ACTION_MODES = ("platoon", "per_vehicle", "relative")  # one setting for all followers, one each, or one step
# of the platoon's setting down the ladder, none, or up
CHART_KINDS = ("shewhart", "ewma", "cusum")  # the charts of timegap_env.monitoring.charts.CHARTS
# What can go wrong with a follower (timegap_env.sim.degradation); only v2v_outage shows (the V2V flag drops).
DEGRADATION_KINDS = (
    "lag", "gain", "v2v_latency", "packet_loss", "v2v_outage", "radar_bias", "radar_noise", "commercial_acc",
)


class ConfigMixin:
    """``with_overrides`` and field checks shared by the config dataclasses."""

    def with_overrides(self, overrides: Mapping[str, Any] | None = None) -> Self:
        """Copy of this config with ``overrides`` applied; unknown keys raise ``ValueError``."""
        overrides = dict(overrides or {})
        known = {f.name for f in dataclasses.fields(self)}  # type: ignore[arg-type]
        unknown = sorted(set(overrides) - known)
        if unknown:
            raise ValueError(
                f"unknown {type(self).__name__} field(s) {unknown}; known fields: {sorted(known)}"
            )
        return dataclasses.replace(self, **overrides)  # type: ignore[type-var]

    def _fail(self, field: str, value: Any, rule: str) -> None:
        raise ValueError(f"{type(self).__name__}.{field} = {value!r}: {rule}")

    def _finite(self, field: str) -> float:
        value = getattr(self, field)
        if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
            self._fail(field, value, "must be a number")
        if not math.isfinite(value):
            self._fail(field, value, "must be finite")
        return float(value)

    def _positive(self, *fields: str) -> None:
        for field in fields:
            if self._finite(field) <= 0:
                self._fail(field, getattr(self, field), "must be > 0")

    def _band(self, field: str, low_min: float = 0.0) -> None:
        band = getattr(self, field)
        try:
            low, high = (float(b) for b in band)
        except (TypeError, ValueError):
            self._fail(field, band, "must be a pair (low, high)")
        if not (math.isfinite(low) and math.isfinite(high)):
            self._fail(field, band, "must be finite")
        if low < low_min:
            self._fail(field, band, f"low end must be >= {low_min}")
        if low >= high:
            self._fail(field, band, "must satisfy low < high (the band is reversed or empty)")


@dataclasses.dataclass(frozen=True)
class PlatoonConfig(ConfigMixin):
    """A human leader and ``n_followers`` automated followers (GLVD + CTH controller)."""

    n_followers: int = 5  # automated followers behind the leader [-]
    dt: float = 0.1  # simulator tick [s] (10 Hz)
    actuation_lag: float | tuple[float, ...] = 0.45  # GLVD lag T, one value or one per follower [s]
    actuation_gain: float | tuple[float, ...] = 1.0  # GLVD gain K, one value or one per follower [-]
    initial_setting: float = 1.6  # time gap setting tau* at reset [s]
    setting_ramp_rate: float = 0.2  # rate at which the applied setting follows a new setting [s/s]
    standstill_spacing: float = 5.0  # s0 of the CTH policy [m]
    vehicle_length: float = 5.0  # bumper to bumper length of every vehicle [m]
    k_s: float = 0.2  # gain on the spacing error [1/s^2]
    k_v: float = 0.7  # gain on the speed difference to the predecessor [1/s]
    k_a: float = -0.3  # gain on own acceleration [-]
    k_f: float = 0.6  # feed-forward gain on the predecessor's acceleration over V2V [-]
    v2v_delay: float = 0.1  # V2V delay theta of the feed-forward, a multiple of dt [s]
    max_v2v_latency: float = 1.0  # longest extra V2V delay a degradation may add; sizes the message buffer [s]
    v2v: bool = True  # followers start in CACC (True) or ACC, k_f = 0 (False)
    accel_min: float = -8.0  # lowest commanded acceleration (hard braking, ~0.8 g) [m/s^2]
    accel_max: float = 4.0  # highest commanded acceleration [m/s^2]

    def __post_init__(self) -> None:
        if isinstance(self.n_followers, bool) or not isinstance(self.n_followers, (int, np.integer)):
            self._fail("n_followers", self.n_followers, "must be an integer")
        if self.n_followers < 1:
            self._fail("n_followers", self.n_followers, "must be >= 1")
        self._positive("dt", "initial_setting", "setting_ramp_rate", "vehicle_length")
        for field in ("standstill_spacing", "v2v_delay", "max_v2v_latency"):
            if self._finite(field) < 0:
                self._fail(field, getattr(self, field), "must be >= 0")
        for field in ("k_s", "k_v", "k_a", "k_f", "accel_min", "accel_max"):
            self._finite(field)
        if not self.accel_min < 0 < self.accel_max:
            self._fail("accel_min", (self.accel_min, self.accel_max), "need accel_min < 0 < accel_max")
        if not isinstance(self.v2v, (bool, np.bool_)):
            self._fail("v2v", self.v2v, "must be True or False")
        for field in ("v2v_delay", "max_v2v_latency"):
            delay_ticks = getattr(self, field) / self.dt
            if abs(delay_ticks - round(delay_ticks)) > 1e-9:
                self._fail(field, getattr(self, field), f"must be a multiple of dt = {self.dt}")
        for field in ("actuation_lag", "actuation_gain"):
            self.per_follower(field)

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
        values = np.atleast_1d(np.asarray(raw, dtype=float))
        if values.ndim != 1 or values.size not in (1, self.n_followers):
            self._fail(field, raw, f"must be one number or {self.n_followers} numbers (one per follower)")
        if not np.all(np.isfinite(values)) or np.any(values <= 0):
            self._fail(field, raw, "every value must be finite and > 0")
        return np.broadcast_to(values, (self.n_followers,)).copy()


@dataclasses.dataclass(frozen=True)
class LeaderConfig(ConfigMixin):
    """What every leader profile shares: its tick, length and speed band."""

    dt: float = PlatoonConfig.dt  # sample period of the profile [s]
    duration: float = 250.0  # length of a synthetic profile [s]; in the env it is EnvConfig.episode_duration
    speed_band: tuple[float, float] = (20 * MPH, 80 * MPH)  # speeds a profile is kept within [m/s]
    initial_speed: float = 22.0  # speed at t = 0 of an integrated profile [m/s]
    min_recorded_duration: float = 30.0  # shortest recorded leader (NGSIM vehicle, OpenACC lead car) drawn [s]

    def __post_init__(self) -> None:
        self._positive("dt", "duration", "min_recorded_duration")
        self._band("speed_band")
        speed = self._finite("initial_speed")
        low, high = self.speed_band
        if not low <= speed <= high:
            self._fail("initial_speed", speed, f"must lie in speed_band {self.speed_band}")

    @property
    def n_samples(self) -> int:
        """Samples in a synthetic profile, t = 0 included [-]."""
        return int(round(self.duration / self.dt)) + 1


@dataclasses.dataclass(frozen=True)
class AggressiveCyclesConfig(ConfigMixin):
    """The paper's leader: alternating hard acceleration and deceleration phases."""

    accel_range: tuple[float, float] = (1.5, 3.5)  # magnitude of each phase's acceleration [m/s^2]
    phase_duration_range: tuple[float, float] = (3.0, 9.0)  # length of each phase [s]
    cruise_probability: float = 0.25  # chance that a phase is a cruise (a = 0) instead [-]
    max_jerk: float = 10.0  # how fast the leader moves between phase accelerations; aggressive drivers reach ~10 [m/s^3]

    def __post_init__(self) -> None:
        self._band("accel_range", low_min=1e-9)
        self._band("phase_duration_range", low_min=1e-9)
        self._positive("max_jerk")
        if not 0 <= self._finite("cruise_probability") < 1:
            self._fail("cruise_probability", self.cruise_probability, "must be in [0, 1)")


@dataclasses.dataclass(frozen=True)
class SinusoidConfig(ConfigMixin):
    """Speed oscillation v = mean + amplitude sin(2 pi t / period + phase), all drawn per seed."""

    amplitude_range: tuple[float, float] = (2.0, 6.0)  # speed amplitude [m/s]
    period_range: tuple[float, float] = (10.0, 40.0)  # oscillation period [s]

    def __post_init__(self) -> None:
        self._band("amplitude_range", low_min=1e-9)
        self._band("period_range", low_min=1e-9)


@dataclasses.dataclass(frozen=True)
class HardBrakingConfig(ConfigMixin):
    """Cruising interrupted by hard braking events, each followed by a gentler recovery."""

    n_events: int = 3  # braking events per profile [-]
    decel_range: tuple[float, float] = (4.0, 7.0)  # magnitude of the braking deceleration [m/s^2]
    speed_drop_range: tuple[float, float] = (5.0, 12.0)  # speed lost in one event [m/s]
    recovery_accel: float = 1.5  # acceleration back to the cruise speed [m/s^2]

    def __post_init__(self) -> None:
        if isinstance(self.n_events, bool) or not isinstance(self.n_events, (int, np.integer)) or self.n_events < 1:
            self._fail("n_events", self.n_events, "must be an integer >= 1")
        self._band("decel_range", low_min=1e-9)
        self._band("speed_drop_range", low_min=1e-9)
        self._positive("recovery_accel")


@dataclasses.dataclass(frozen=True)
class StochasticHumanConfig(ConfigMixin):
    """Human-like speed: acceleration is an Ornstein-Uhlenbeck process pulled to a wandering target speed."""

    accel_std: float = 0.6  # stationary std of the acceleration noise [m/s^2]
    accel_correlation_time: float = 2.0  # correlation time of the acceleration noise [s]
    speed_gain: float = 0.1  # pull of the speed towards the target speed [1/s]
    target_change_interval: float = 30.0  # mean time between changes of the target speed [s]

    def __post_init__(self) -> None:
        self._positive("accel_std", "accel_correlation_time", "speed_gain", "target_change_interval")


@dataclasses.dataclass(frozen=True)
class HumanLeaderConfig(ConfigMixin):
    """highway-env's IDM driver as a human leader behind a scripted disturbance (``timegap_env.leaders.idm``)."""

    desired_speed_factor: float = 1.2  # driver's desired speed over the disturbance's top speed [-]
    time_wanted_range: tuple[float, float] = (1.0, 2.0)  # desired time gap of a seeded driver (highway-env: 1.5) [s]
    comfort_accel_range: tuple[float, float] = (2.0, 4.0)  # desired acceleration of a seeded driver (highway-env: 3) [m/s^2]
    max_initial_gap: float = 500.0  # longest accepted initial bumper-to-bumper gap [m]

    def __post_init__(self) -> None:
        self._positive("desired_speed_factor", "max_initial_gap")
        self._band("time_wanted_range", low_min=1e-9)
        self._band("comfort_accel_range", low_min=1e-9)


@dataclasses.dataclass(frozen=True)
class SensorConfig(ConfigMixin):
    """What each follower measures of its own spacing and speed, once per tick."""

    spacing_noise_std: float = 0.1  # radar range noise; matches the spacing model's sigma^2 = 0.01 m^2 [m]
    speed_noise_std: float = 0.1  # own-speed noise [m/s]
    dropout_probability: float = 0.0  # chance that a tick's measurement of a follower is missing (NaN) [-]

    def __post_init__(self) -> None:
        for field in ("spacing_noise_std", "speed_noise_std"):
            if self._finite(field) < 0:
                self._fail(field, getattr(self, field), "must be >= 0")
        if not 0 <= self._finite("dropout_probability") < 1:
            self._fail("dropout_probability", self.dropout_probability, "must be in [0, 1)")


@dataclasses.dataclass(frozen=True)
class MonitorConfig(ConfigMixin):
    """Bayesian monitor of [s0, tau] from spacing and speed measurements (the paper's spacing model).

    The default prior's standstill spacing and tick follow ``PlatoonConfig``'s defaults;
    ``MONITOR_PRESETS["paper"]`` keeps the paper's printed numbers. The paper leaves open
    how old data are forgotten: ``window`` and ``forgetting`` both count age in ticks, so a
    skipped (invalid) measurement still ages the data, and the window always spans
    ``window`` seconds of time.
    """

    noise_variance: float = 0.01  # sigma^2 of the spacing model S = s0 + tau V + eps [m^2]
    prior_standstill_spacing: float = PlatoonConfig.standstill_spacing  # prior mean of s0 [m]; tau's is the setting
    prior_cov: tuple[tuple[float, float], tuple[float, float]] = ((1e-4, -1e-5), (-1e-5, 0.125))  # Sigma_b of [s0 [m], tau [s]]
    window: float | None = 2.0  # sliding window, a multiple of dt; chosen by train/choose_window.py [s]; None keeps all
    forgetting: float = 1.0  # exponential forgetting factor per tick, 1 = none [-]
    dt: float = PlatoonConfig.dt  # measurement period [s]
    max_speed: float = 100.0  # speeds above this are implausible and skipped [m/s]
    max_spacing: float = 1000.0  # spacings above this are implausible and skipped [m]

    def __post_init__(self) -> None:
        self._positive("noise_variance", "dt", "max_speed", "max_spacing")
        self._finite("prior_standstill_spacing")
        cov = np.asarray(self.prior_cov, dtype=float)
        if cov.shape != (2, 2) or not np.all(np.isfinite(cov)):
            self._fail("prior_cov", self.prior_cov, "must be a finite 2x2 matrix")
        if not np.allclose(cov, cov.T) or np.any(np.linalg.eigvalsh(cov) <= 0):
            self._fail("prior_cov", self.prior_cov, "must be symmetric positive definite")
        if self.window is not None:
            ticks = self._finite("window") / self.dt
            if ticks < 1 - 1e-9 or abs(ticks - round(ticks)) > 1e-9:
                self._fail("window", self.window, f"must be None or a positive multiple of dt = {self.dt}")
        if not 0 < self._finite("forgetting") <= 1:
            self._fail("forgetting", self.forgetting, "must be in (0, 1]")

    @property
    def window_ticks(self) -> int | None:
        """Length of the sliding window in ticks, None when all data are kept [-]."""
        return None if self.window is None else int(round(self.window / self.dt))


@dataclasses.dataclass(frozen=True)
class ChartConfig(ConfigMixin):
    """Control chart on the posterior mean of tau (Shewhart, EWMA or CUSUM), and the paper's switching rule."""

    kind: str = "shewhart"  # chart used by make_chart, one of CHART_KINDS
    baseline_std: float = 0.125  # sigma_desired of the baseline N(tau*, sigma_desired^2) [s]
    limit_width: float = 2.0  # L: Shewhart limits at tau* -/+ L sigma_desired [-]
    ewma_lambda: float = 0.2  # EWMA weight of the newest estimate [-]
    ewma_width: float = 3.0  # EWMA limits at tau* -/+ width sigma_desired sqrt(lambda / (2 - lambda)) [-]
    cusum_k: float = 0.5  # CUSUM reference value (allowance) [sigma_desired]
    cusum_h: float = 5.0  # CUSUM decision interval [sigma_desired]
    exceedance_window: float = 35.0  # trailing window in which exceedances are counted, a multiple of dt [s]
    switch_exceedances: int = 3  # paper's rule: this many exceedances within the window ... [-]
    switch_to: float = 1.0  # ... switch the setting to this time gap [s]
    settle_time: float = 8.0  # alarms wait this long after a commanded change has ramped in; long enough
    # for the slowest change of the default ladder, 0.6 -> 2.2 s (tests/monitoring/test_loop.py) [s]
    dt: float = PlatoonConfig.dt  # chart tick, one estimate per tick [s]

    def __post_init__(self) -> None:
        if self.kind not in CHART_KINDS:
            self._fail("kind", self.kind, f"must be one of {CHART_KINDS}")
        self._positive("baseline_std", "limit_width", "ewma_width", "cusum_h", "exceedance_window", "switch_to", "dt")
        if not 0 < self._finite("ewma_lambda") <= 1:
            self._fail("ewma_lambda", self.ewma_lambda, "must be in (0, 1]")
        for field in ("cusum_k", "settle_time"):
            if self._finite(field) < 0:
                self._fail(field, getattr(self, field), "must be >= 0")
        ticks = self.exceedance_window / self.dt
        if ticks < 1 - 1e-9 or abs(ticks - round(ticks)) > 1e-9:
            self._fail("exceedance_window", self.exceedance_window, f"must be a positive multiple of dt = {self.dt}")
        if isinstance(self.switch_exceedances, bool) or not isinstance(self.switch_exceedances, (int, np.integer)) or self.switch_exceedances < 1:
            self._fail("switch_exceedances", self.switch_exceedances, "must be an integer >= 1")

    @property
    def exceedance_window_ticks(self) -> int:
        """Length of the exceedance-counting window in ticks [-]."""
        return int(round(self.exceedance_window / self.dt))

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


@dataclasses.dataclass(frozen=True)
class RewardWeights(ConfigMixin):
    """Weight of each reward term of ``TimeGapMonitor-v0``, one field per term in the order they are summed.

    The terms themselves (each <= 0, about -1 at its worst) and the reasons for these weights are in
    :mod:`timegap_env.envs.reward`, whose ``RewardTerms`` takes its field names from this class.
    """

    tracking: float = 1.0  # [-]
    string_stability: float = 1.0  # [-]
    safety: float = 2.0  # [-]
    collision: float = 1000.0  # [-], outweighs any whole episode of the other terms
    comfort: float = 0.05  # [-]
    efficiency: float = 1.0  # [-]
    preference: float = 0.5  # [-]
    switching: float = 0.2  # [-]

    def __post_init__(self) -> None:
        for field in dataclasses.fields(self):
            if self._finite(field.name) < 0:
                self._fail(field.name, getattr(self, field.name), "must be >= 0")


SIZE_RANGE_FIELDS = {  # each sized degradation kind and the DegradationConfig field holding its range
    "lag": "lag_factor_range", "gain": "gain_range", "v2v_latency": "v2v_latency_range",
    "packet_loss": "packet_loss_range", "radar_bias": "radar_bias_range", "radar_noise": "radar_noise_range",
}


def _default_degradation_weights() -> dict[str, float]:
    """Chosen by measurement (``python -m train.choose_degradation_mix``, ``results/degradation/mix.md``): of the mixes
    keeping every kind at weight 1, 2 or 4, the one where knowing the hidden degradations is worth most (2 % of the
    best blind constant's return; every kind at 1: 1 %)."""
    return {"none": 4.0, **{kind: 1.0 for kind in DEGRADATION_KINDS}, "packet_loss": 4.0, "radar_noise": 4.0}


@dataclasses.dataclass(frozen=True)
class DegradationConfig(ConfigMixin):
    """What degradation each episode draws (:mod:`timegap_env.sim.degradation`): one kind, or none.

    The kind comes from ``kind_weights``; it hits each follower with ``follower_probability`` (at
    least one), with a size drawn from the kind's range; it starts at 0 or, with
    ``midway_onset_probability``, somewhere in the episode's middle half, and ends before the
    episode with ``recovery_probability``. A V2V outage always ends (it lasts
    ``v2v_outage_duration_range``); a commercial ACC car is what it is from start to end.
    """

    kind_weights: dict[str, float] = dataclasses.field(default_factory=_default_degradation_weights)  # kind -> weight
    lag_factor_range: tuple[float, float] = (1.5, 2.5)  # actuation lag T multiplied by [-]
    gain_range: tuple[float, float] = (0.6, 0.85)  # actuation gain K [-]
    v2v_latency_range: tuple[float, float] = (0.2, 0.6)  # V2V delay added, a multiple of dt when drawn [s]
    packet_loss_range: tuple[float, float] = (0.3, 0.9)  # chance per tick that a V2V message is lost [-]
    v2v_outage_duration_range: tuple[float, float] = (20.0, 80.0)  # how long the V2V link is down [s]
    radar_bias_range: tuple[float, float] = (1.0, 4.0)  # |bias| of the radar's spacing, sign drawn [m]
    radar_noise_range: tuple[float, float] = (0.3, 1.0)  # std of the radar's spacing noise while degraded [m]
    follower_probability: float = 1.0  # chance each follower is hit; at least one is [-]
    midway_onset_probability: float = 0.5  # chance the degradation starts mid-episode rather than at 0 [-]
    recovery_probability: float = 0.3  # chance it ends before the episode does [-]

    def __post_init__(self) -> None:
        known = ("none", *DEGRADATION_KINDS)
        if not isinstance(self.kind_weights, Mapping) or not self.kind_weights:
            self._fail("kind_weights", self.kind_weights, f"must be a non-empty dict kind -> weight, kinds {known}")
        unknown = sorted(set(self.kind_weights) - set(known))
        if unknown:
            self._fail("kind_weights", self.kind_weights, f"unknown kinds {unknown}; known: {list(known)}")
        weights = list(self.kind_weights.values())
        if (not all(isinstance(w, (int, float)) and not isinstance(w, bool) and math.isfinite(w) and w >= 0 for w in weights)
                or sum(weights) <= 0):
            self._fail("kind_weights", self.kind_weights, "weights must be finite numbers >= 0, not all 0")
        for field in ("lag_factor_range", "gain_range", "v2v_latency_range", "packet_loss_range",
                      "v2v_outage_duration_range", "radar_bias_range", "radar_noise_range"):
            self._band(field)
        if self.lag_factor_range[0] < 1:
            self._fail("lag_factor_range", self.lag_factor_range, "a degraded lag is at least the nominal one (>= 1)")
        if not (0 < self.gain_range[0] and self.gain_range[1] <= 1):
            self._fail("gain_range", self.gain_range, "a degraded gain lies in (0, 1]")
        if self.packet_loss_range[1] >= 1:
            self._fail("packet_loss_range", self.packet_loss_range, "a loss probability must stay below 1")
        for field in ("follower_probability", "midway_onset_probability", "recovery_probability"):
            if not 0 <= self._finite(field) <= 1:
                self._fail(field, getattr(self, field), "must be in [0, 1]")

    def size_range(self, kind: str) -> tuple[float, float]:
        """The range a sized ``kind``'s size is drawn from (for radar_bias, its magnitude); ``KeyError`` otherwise."""
        return getattr(self, SIZE_RANGE_FIELDS[kind])


def _default_scenario_weights() -> dict[str, float]:
    return {"aggressive_cycles": 1.0, "sinusoid": 1.0, "hard_braking": 1.0, "stochastic_human": 1.0}


@dataclasses.dataclass(frozen=True)
class EnvConfig(ConfigMixin):
    """Everything ``TimeGapMonitor-v0`` runs with; ``gym.make(..., config={...})`` overrides it.

    Nested configs take dicts of their own fields, e.g. ``{"platoon": {"n_followers": 3}}``.
    A synthetic leader lasts the episode: ``leader.duration`` follows ``episode_duration``
    (left at its default it is set to it; any other value must equal it).
    """

    platoon: PlatoonConfig = PlatoonConfig()
    leader: LeaderConfig = LeaderConfig()
    sensors: SensorConfig = SensorConfig()
    monitor: MonitorConfig = MonitorConfig()
    chart: ChartConfig = ChartConfig()
    reward_weights: RewardWeights = RewardWeights()
    decision_interval: float = 1.0  # time between two actions, a multiple of platoon.dt [s]
    episode_duration: float = 250.0  # [s]
    action_mode: str = "platoon"  # one of ACTION_MODES: one setting for all followers, one each, or a relative step
    random_initial_setting: bool = False  # each episode starts at a ladder level drawn from the seed, not at
    # platoon.initial_setting (for training: a relative policy then learns to reach a setting, not only to keep one)
    setting_levels: tuple[float, ...] = (0.6, 0.8, 1.0, 1.2, 1.4, 1.6, 1.8, 2.0, 2.2)  # settings to choose from [s]
    preferred_setting: float = 1.6  # the setting the driver chose [s]
    scenario_weights: dict[str, float] = dataclasses.field(default_factory=_default_scenario_weights)  # family -> weight
    degradation: DegradationConfig = DegradationConfig()  # what can go wrong with the followers, drawn per episode
    dropout_probability_range: tuple[float, float] = (0.0, 0.05)  # per-episode sensor dropout rate drawn from [-]
    ttc_threshold: float = 4.0  # time-to-collision below which safety is penalised [s]
    jerk_reference: float = 2.0  # jerk that costs one comfort unit [m/s^3]
    tracking_reference: float = 0.25  # a tick's |actual time gap - setting| costing one tracking unit [s]
    tracking_cap: float = 0.5  # a tick's |actual time gap - setting| counts up to this in the tracking term [s]
    accel_growth_reference: float = 1.0  # growth of the peak acceleration down the platoon costing one unit [m/s^2]
    accel_envelope_time: float = 5.0  # time constant of the decaying peak acceleration the growth compares [s]

    def __post_init__(self) -> None:
        nested = {"platoon": PlatoonConfig, "leader": LeaderConfig, "sensors": SensorConfig, "monitor": MonitorConfig,
                  "chart": ChartConfig, "reward_weights": RewardWeights, "degradation": DegradationConfig}
        for field, kind in nested.items():
            if not isinstance(getattr(self, field), kind):
                self._fail(field, getattr(self, field), f"must be a {kind.__name__} (or a dict of its fields)")
        self._positive("decision_interval", "episode_duration", "preferred_setting", "ttc_threshold", "jerk_reference",
                       "tracking_reference", "tracking_cap", "accel_growth_reference", "accel_envelope_time")
        dt = self.platoon.dt
        for field in ("decision_interval", "episode_duration"):
            ticks = getattr(self, field) / dt
            if abs(ticks - round(ticks)) > 1e-9:
                self._fail(field, getattr(self, field), f"must be a multiple of platoon.dt = {dt}")
        if not math.isclose(self.leader.duration, self.episode_duration):
            if self.leader.duration != LeaderConfig.duration:
                self._fail("leader.duration", self.leader.duration,
                           f"a synthetic leader lasts the episode: leave it out or make it episode_duration = "
                           f"{self.episode_duration}")
            object.__setattr__(self, "leader", self.leader.with_overrides({"duration": float(self.episode_duration)}))
        for name, config in (("monitor", self.monitor), ("chart", self.chart), ("leader", self.leader)):
            if not math.isclose(config.dt, dt):
                self._fail(f"{name}.dt", config.dt, f"must equal platoon.dt = {dt}")
        if not isinstance(self.random_initial_setting, (bool, np.bool_)):
            self._fail("random_initial_setting", self.random_initial_setting, "must be True or False")
        if self.action_mode not in ACTION_MODES:
            self._fail("action_mode", self.action_mode, f"must be one of {ACTION_MODES}")
        levels = np.asarray(self.setting_levels, dtype=float)
        if levels.ndim != 1 or levels.size < 2 or not np.all(np.isfinite(levels)) or np.any(levels <= 0):
            self._fail("setting_levels", self.setting_levels, "must be at least two finite settings > 0")
        if np.any(np.diff(levels) <= 0):
            self._fail("setting_levels", self.setting_levels, "must increase strictly")
        if not np.any(np.isclose(levels, self.platoon.initial_setting)):
            self._fail("platoon.initial_setting", self.platoon.initial_setting, f"must be one of {self.setting_levels}")
        if not isinstance(self.scenario_weights, Mapping) or not self.scenario_weights:
            self._fail("scenario_weights", self.scenario_weights, "must be a non-empty dict family -> weight")
        weights = list(self.scenario_weights.values())
        if not all(isinstance(w, (int, float)) and math.isfinite(w) and w >= 0 for w in weights) or sum(weights) <= 0:
            self._fail("scenario_weights", self.scenario_weights, "weights must be finite, >= 0, not all 0")
        if self.degradation.v2v_latency_range[1] > self.platoon.max_v2v_latency + 1e-9:
            self._fail("degradation.v2v_latency_range", self.degradation.v2v_latency_range,
                       f"must stay within platoon.max_v2v_latency = {self.platoon.max_v2v_latency} s")
        low, high = self.dropout_probability_range
        if not 0 <= low <= high < 1:
            self._fail("dropout_probability_range", self.dropout_probability_range, "need 0 <= low <= high < 1")

    @classmethod
    def from_dict(cls, overrides: Mapping[str, Any] | None = None) -> EnvConfig:
        """The default config with ``overrides``; nested configs take dicts of their own fields."""
        overrides = dict(overrides or {})
        default = cls()
        for field in dataclasses.fields(cls):
            value = overrides.get(field.name)
            if isinstance(value, Mapping) and isinstance(getattr(default, field.name), ConfigMixin):
                overrides[field.name] = getattr(default, field.name).with_overrides(value)
        if "setting_levels" in overrides:
            overrides["setting_levels"] = tuple(overrides["setting_levels"])
        return default.with_overrides(overrides)

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
