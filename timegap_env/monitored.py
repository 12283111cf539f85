"""The monitored platoon: simulator -> sensors -> Bayesian monitor -> control chart.

This is the loop of the paper and of the environment, for ``n_envs`` platoons at
once, a tick (:meth:`MonitoredPlatoon.tick`) or a block of ticks
(:meth:`MonitoredPlatoon.run`, what an env step uses) at a time, with the same
result. Changing a follower's time gap setting ramps it in the simulator and
re-centres that follower's prior and chart on the new setting.

Sensor noise is counter-based (:func:`counter_uniforms`): a hash of (env key,
tick, follower, stream), so no random generator state is carried between ticks.
"""

from __future__ import annotations

import dataclasses

import numba
import numpy as np

from timegap_env.charts import ChartState, make_chart
from timegap_env.config import ChartConfig, MonitorConfig, PlatoonConfig, SensorConfig
from timegap_env.monitor import TimeGapMonitor
from timegap_env.platoon import Platoon, PlatoonTicks, per_env


_SPLITMIX_INCREMENT = np.uint64(0x9E3779B97F4A7C15)  # SplitMix64 constants (Steele, Lea & Flood 2014)
_SPLITMIX_MULTIPLIERS = (np.uint64(0xBF58476D1CE4E5B9), np.uint64(0x94D049BB133111EB))
_UNIFORM_STREAMS = 3  # per follower and tick: two for the Gaussian pair, one for dropouts
SAME_SETTING = 1e-6  # settings closer than this are the same setting [s]


def counter_uniforms(keys: np.ndarray, ticks: np.ndarray, n_followers: int) -> np.ndarray:
    """Uniforms in (0, 1), shape (3, *ticks.shape, n_followers), a pure function of (key, tick, follower, stream).

    ``keys`` (n_envs,); ``ticks`` (n_envs,) or (n_ticks, n_envs). Counter-based: an env's
    draws depend only on its own key and tick, never on which other envs share the batch
    or how ticks are grouped, so a vector of envs reproduces the same envs run one by one.
    """
    ticks = np.asarray(ticks).astype(np.uint64)
    by_tick = ticks.reshape(-1, ticks.shape[-1])  # (n_ticks, n_envs)
    uniforms = np.empty((_UNIFORM_STREAMS, *by_tick.shape, n_followers))
    _counter_uniforms_kernel(np.asarray(keys, dtype=np.uint64), by_tick, uniforms)
    return uniforms.reshape((_UNIFORM_STREAMS, *ticks.shape, n_followers))


@numba.njit(cache=True)
def _counter_uniforms_kernel(keys, ticks, out):  # noqa: ANN001, ANN202
    """Fill ``out`` (3, n_ticks, n_envs, n_followers) with :func:`_uniform` of each (env, tick, follower, stream)."""
    n_streams, n_ticks, n_envs, n_followers = out.shape
    for k in range(n_ticks):
        for e in range(n_envs):
            for f in range(n_followers):
                for stream in range(n_streams):
                    out[stream, k, e, f] = _uniform(keys[e], ticks[k, e], f, stream, n_followers)


@numba.njit(cache=True)
def _uniform(key, tick, follower, stream, n_followers):  # noqa: ANN001, ANN202
    """The uniform in (0, 1) of counter tick * 3 n_followers + 3 follower + stream, hashed with the env's key."""
    counter = np.uint64(tick) * np.uint64(_UNIFORM_STREAMS * n_followers) + np.uint64(_UNIFORM_STREAMS * follower + stream)
    bits = _splitmix64(_splitmix64(counter * _SPLITMIX_INCREMENT + key))
    return (float(bits >> np.uint64(11)) + 0.5) * 2.0**-53


@numba.njit(cache=True)
def _splitmix64(x):  # noqa: ANN001, ANN202
    """SplitMix64 finaliser: a well-mixed uint64 hash of the uint64 ``x``."""
    x = (x ^ (x >> np.uint64(30))) * _SPLITMIX_MULTIPLIERS[0]
    x = (x ^ (x >> np.uint64(27))) * _SPLITMIX_MULTIPLIERS[1]
    return x ^ (x >> np.uint64(31))


def measure(
    spacing: np.ndarray, speed: np.ndarray, config: SensorConfig, uniforms: np.ndarray, dropout_probability: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Noisy spacing [m] and speed [m/s], each (..., n_envs, n_followers) like ``uniforms[0]`` from
    ``counter_uniforms``; a dropout is NaN in both.

    ``dropout_probability`` (n_envs,) is each env's chance per tick that a follower's measurement is missing.
    """
    shape = uniforms.shape[1:]  # (..., n_envs, n_followers)
    blocks = (-1, *shape[-2:])  # (n_ticks, n_envs, n_followers)

    def as_blocks(values: np.ndarray) -> np.ndarray:
        values = np.asarray(values, dtype=float)
        return np.ascontiguousarray(values if values.shape == shape else np.broadcast_to(values, shape)).reshape(blocks)

    measured_spacing, measured_speed = np.empty(shape), np.empty(shape)
    _measure_kernel(
        as_blocks(spacing), as_blocks(speed), uniforms.reshape(_UNIFORM_STREAMS, *blocks),
        np.asarray(dropout_probability, dtype=float), config.spacing_noise_std, config.speed_noise_std,
        measured_spacing.reshape(blocks), measured_speed.reshape(blocks),
    )
    return measured_spacing, measured_speed


@numba.njit(cache=True)
def _measure_kernel(  # noqa: ANN202 -- arrays (n_ticks, n_envs, n_followers), uniforms with a leading stream axis
    spacing, speed, uniforms, dropout_probability, spacing_noise_std, speed_noise_std, out_spacing, out_speed
):
    """:func:`measure`, element by element."""
    n_ticks, n_envs, n_followers = spacing.shape
    for k in range(n_ticks):
        for e in range(n_envs):
            for f in range(n_followers):
                out_spacing[k, e, f], out_speed[k, e, f] = _sensor_reading(
                    spacing[k, e, f], speed[k, e, f], uniforms[0, k, e, f], uniforms[1, k, e, f],
                    uniforms[2, k, e, f], dropout_probability[e], spacing_noise_std, speed_noise_std,
                )


@numba.njit(cache=True)
def _sensor_kernel(  # noqa: ANN202, PLR0913 -- :func:`measure` of :func:`counter_uniforms`, fused for the hot path
    spacing, speed, keys, first_tick, dropout_probability, spacing_noise_std, speed_noise_std, out_spacing, out_speed
):
    """Readings of ticks first_tick[e] + 1 + k, arrays (n_ticks, n_envs, n_followers), noise drawn on the fly."""
    n_ticks, n_envs, n_followers = spacing.shape
    for k in range(n_ticks):
        for e in range(n_envs):
            tick = first_tick[e] + 1 + k
            for f in range(n_followers):
                out_spacing[k, e, f], out_speed[k, e, f] = _sensor_reading(
                    spacing[k, e, f], speed[k, e, f], _uniform(keys[e], tick, f, 0, n_followers),
                    _uniform(keys[e], tick, f, 1, n_followers), _uniform(keys[e], tick, f, 2, n_followers),
                    dropout_probability[e], spacing_noise_std, speed_noise_std,
                )


@numba.njit(cache=True)
def _sensor_reading(spacing, speed, u0, u1, u2, dropout_probability, spacing_noise_std, speed_noise_std):  # noqa: ANN001, ANN202, PLR0913
    """One follower's noisy (spacing [m], speed [m/s]) from three uniforms; (NaN, NaN) if dropped (u2 < p)."""
    if u2 < dropout_probability:
        return np.nan, np.nan
    radius = np.sqrt(-2.0 * np.log(u0))  # Box-Muller: two independent standard normals
    angle = 2.0 * np.pi * u1
    return spacing + spacing_noise_std * radius * np.cos(angle), speed + speed_noise_std * radius * np.sin(angle)


@dataclasses.dataclass(frozen=True)
class MonitoredTicks:
    """A block of ticks of :meth:`MonitoredPlatoon.run`, arrays (n_ticks, n_envs, n_followers)."""

    physics: PlatoonTicks  # the simulator's state after each tick
    measured_spacing: np.ndarray  # [m], NaN = dropout
    measured_speed: np.ndarray  # [m/s], NaN = dropout
    tau_mean: np.ndarray  # posterior mean of tau [s]
    chart: ChartState  # the chart after each tick


class MonitoredPlatoon:
    """``n_envs`` platoons, each follower with its own sensors, monitor and chart.

    Attributes: ``platoon`` (:class:`Platoon`), ``monitor`` (:class:`TimeGapMonitor`),
    ``chart`` (a chart from :func:`make_chart`), ``sensors`` (:class:`SensorConfig`);
    per env, shaped (n_envs,): ``ticks`` since reset, ``noise_keys`` of the
    sensor noise (see :func:`counter_uniforms`), ``dropout_probability``.
    """

    def __init__(
        self,
        platoon: PlatoonConfig = PlatoonConfig(),
        monitor: MonitorConfig = MonitorConfig(),
        chart: ChartConfig = ChartConfig(),
        sensors: SensorConfig = SensorConfig(),
        n_envs: int = 1,
        seed: int | None = None,
    ) -> None:
        for name, config in (("monitor", monitor), ("chart", chart)):
            if not np.isclose(config.dt, platoon.dt):
                raise ValueError(f"{name}.dt = {config.dt}: must equal PlatoonConfig.dt = {platoon.dt}")
        self.platoon = Platoon(platoon, n_envs)
        self.monitor = TimeGapMonitor(n_envs, platoon.n_followers, platoon.time_gap, monitor)
        self.chart = make_chart(n_envs, platoon.n_followers, platoon.time_gap, chart)
        self.sensors = sensors
        self.ticks = np.zeros(n_envs, dtype=np.int64)
        self.noise_keys = np.random.default_rng(seed).integers(0, 2**63, size=n_envs, dtype=np.uint64)
        self.dropout_probability = np.full(n_envs, sensors.dropout_probability)
        self.measured_spacing = np.zeros((n_envs, platoon.n_followers))  # last measurements, NaN = dropout [m]
        self.measured_speed = np.zeros((n_envs, platoon.n_followers))  # [m/s]

    def reset(
        self,
        leader_speed: np.ndarray | float,
        leader_accel: np.ndarray | float = 0.0,
        mask: np.ndarray | None = None,
        time_gap: np.ndarray | float | None = None,
        noise_key: np.ndarray | None = None,
    ) -> None:
        """Equilibrium platoons for the envs in ``mask`` (None = all), monitors and charts centred on the setting.

        ``noise_key`` (n_envs,) uint64, optional: new sensor-noise keys for the envs in ``mask``.
        """
        env_mask = np.ones(self.platoon.n_envs, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
        self.platoon.reset(leader_speed, leader_accel, mask=env_mask, time_gap=time_gap)
        self.ticks[env_mask] = 0
        if noise_key is not None:
            self.noise_keys[env_mask] = np.asarray(noise_key, dtype=np.uint64)[env_mask]
        setting = self.platoon.time_gap_setting
        self.monitor.reset(env_mask, setting)
        self.chart.reset(env_mask, setting)

    def change_time_gap(self, setting: np.ndarray | float, mask: np.ndarray | None = None) -> np.ndarray:
        """Ask for a new setting [s] (broadcast to (n_envs, n_followers)) where ``mask``; return who changed.

        Only a real change moves anything: the simulator ramps to it, and that
        follower's prior and chart are re-centred on it (the chart's history is
        cleared; its centre line then follows the ramp, see :meth:`run`). The
        chart holds its alarms off until the ramp is done plus ``settle_time``.
        """
        current = self.platoon.time_gap_setting
        setting = np.asarray(setting, dtype=float)
        if setting.shape != current.shape:
            setting = np.broadcast_to(setting, current.shape)
        changed = ~(np.abs(setting - current) <= SAME_SETTING)  # NaN counts as a change, refused below
        if mask is not None:
            changed &= mask
        if changed.any():
            self.platoon.set_time_gap(setting, mask=changed)  # checks the settings
            self.monitor._recenter(setting, changed)  # noqa: SLF001 -- checked just above
            self.chart._recenter(self.platoon.time_gap, changed)  # noqa: SLF001
            config, chart_config = self.platoon.config, self.chart.config
            ramp_ticks = np.ceil(np.abs(setting - self.platoon.time_gap) / (config.time_gap_ramp_rate * config.dt))
            self.chart.hold(ramp_ticks + round(chart_config.settle_time / config.dt), changed)
        return changed

    def tick(self, leader_speed: np.ndarray | float, leader_accel: np.ndarray | float) -> tuple[np.ndarray, ChartState]:
        """One tick to a leader at ``leader_speed`` [m/s] with ``leader_accel`` [m/s^2] (scalars or (n_envs,)).

        Returns the followers that collided this tick (n_envs, n_followers) and the charts' state.
        """
        n_envs = self.platoon.n_envs
        speed, accel = per_env("leader_speed", leader_speed, n_envs), per_env("leader_accel", leader_accel, n_envs)
        block = self.run(speed[None], accel[None])
        return block.physics.collisions[0], block.chart.tick(0)

    def run(self, leader_speed: np.ndarray, leader_accel: np.ndarray, v2v: np.ndarray | None = None) -> MonitoredTicks:
        """A block of ticks: move the platoons, measure, update monitors and charts.

        ``leader_speed`` [m/s], ``leader_accel`` [m/s^2]: (n_ticks, n_envs), the leader at the end of each
        tick; ``v2v`` (n_ticks, n_envs, n_followers), optional: CACC status during each tick (see
        :meth:`Platoon.advance`). The physics is a compiled loop; sensors, monitors and charts take
        the whole block at once, with the same result as tick by tick.
        """
        physics = self.platoon.advance(leader_speed, leader_accel, v2v)
        spacing, speed = np.empty_like(physics.spacing), np.empty_like(physics.speed)
        _sensor_kernel(physics.spacing, physics.speed, self.noise_keys, self.ticks, self.dropout_probability,
                       self.sensors.spacing_noise_std, self.sensors.speed_noise_std, spacing, speed)
        self.ticks += len(spacing)
        self.measured_spacing, self.measured_speed = spacing[-1], speed[-1]
        tau_mean = self.monitor.update_block(speed, spacing).tau_mean
        # Unchecked: the estimates are finite by construction. The limits follow a ramping setting.
        chart = self.chart._update_block(tau_mean, physics.time_gap)  # noqa: SLF001
        return MonitoredTicks(physics, spacing, speed, tau_mean, chart)
