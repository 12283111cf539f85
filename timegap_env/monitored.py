"""The monitored platoon: simulator -> sensors -> Bayesian monitor -> control chart, one tick at a time.

This is the loop of the paper and of the environment, for ``n_envs`` platoons at
once. Changing a follower's time gap setting ramps it in the simulator and
re-centres that follower's prior and chart on the new setting.
"""

from __future__ import annotations

import numpy as np

from timegap_env.charts import ChartState, make_chart
from timegap_env.config import ChartConfig, MonitorConfig, PlatoonConfig, SensorConfig
from timegap_env.monitor import TimeGapMonitor
from timegap_env.platoon import Platoon


def measure(
    spacing: np.ndarray, speed: np.ndarray, config: SensorConfig, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """Noisy spacing [m] and speed [m/s] measurements; a dropout is NaN in both."""
    measured_spacing = spacing + config.spacing_noise_std * rng.standard_normal(spacing.shape)
    measured_speed = speed + config.speed_noise_std * rng.standard_normal(speed.shape)
    if config.dropout_probability > 0:
        dropped = rng.random(spacing.shape) < config.dropout_probability
        measured_spacing[dropped] = np.nan
        measured_speed[dropped] = np.nan
    return measured_spacing, measured_speed


class MonitoredPlatoon:
    """``n_envs`` platoons, each follower with its own sensors, monitor and chart.

    Attributes: ``platoon`` (:class:`Platoon`), ``monitor`` (:class:`TimeGapMonitor`),
    ``chart`` (a chart from :func:`make_chart`), ``sensors`` (:class:`SensorConfig`).
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
        for name, config, expected in (("monitor", monitor, MonitorConfig), ("chart", chart, ChartConfig)):
            if not np.isclose(config.dt, platoon.dt):
                raise ValueError(f"{name}.dt = {config.dt}: must equal PlatoonConfig.dt = {platoon.dt}")
        self.platoon = Platoon(platoon, n_envs)
        self.monitor = TimeGapMonitor(n_envs, platoon.n_followers, platoon.time_gap, monitor)
        self.chart = make_chart(n_envs, platoon.n_followers, platoon.time_gap, chart)
        self.sensors = sensors
        self.rng = np.random.default_rng(seed)
        self.measured_spacing = np.zeros((n_envs, platoon.n_followers))  # last measurements, NaN = dropout [m]
        self.measured_speed = np.zeros((n_envs, platoon.n_followers))  # [m/s]

    def reset(
        self,
        leader_speed: np.ndarray | float,
        leader_accel: np.ndarray | float = 0.0,
        mask: np.ndarray | None = None,
        time_gap: np.ndarray | float | None = None,
    ) -> None:
        """Equilibrium platoons for the envs in ``mask`` (None = all), monitors and charts centred on the setting."""
        env_mask = np.ones(self.platoon.n_envs, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
        self.platoon.reset(leader_speed, leader_accel, mask=env_mask, time_gap=time_gap)
        setting = self.platoon.time_gap_setting
        self.monitor.reset(env_mask, setting)
        self.chart.reset(env_mask, setting)

    def change_time_gap(self, setting: np.ndarray | float, mask: np.ndarray | None = None) -> np.ndarray:
        """Ask for a new setting [s] (broadcast to (n_envs, n_followers)) where ``mask``; return who changed.

        Only a real change moves anything: the simulator ramps to it, and that
        follower's prior and chart are re-centred on it.
        """
        current = self.platoon.time_gap_setting
        setting = np.broadcast_to(np.asarray(setting, dtype=float), current.shape)
        selected = np.ones(current.shape, dtype=bool) if mask is None else np.broadcast_to(mask, current.shape)
        changed = selected & ~np.isclose(setting, current)
        if changed.any():
            self.platoon.set_time_gap(setting, mask=changed)
            self.monitor.recenter(setting, changed)
            self.chart.recenter(setting, changed)
        return changed

    def tick(self, leader_speed: np.ndarray | float, leader_accel: np.ndarray | float) -> tuple[np.ndarray, ChartState]:
        """One tick: move the platoons, measure, update monitors and charts.

        Returns the followers that collided this tick (n_envs, n_followers) and the charts' state.
        """
        collisions = self.platoon.step(leader_speed, leader_accel)
        self.measured_spacing, self.measured_speed = measure(
            self.platoon.spacing, self.platoon.v[:, 1:], self.sensors, self.rng
        )
        self.monitor.update(self.measured_speed, self.measured_spacing)
        return collisions, self.chart.update(self.monitor.tau_mean)
