"""The monitored platoon: simulator -> sensors -> Bayesian monitor -> control chart.

This is the loop of the paper and of the environment, for ``n_envs`` platoons at
once, a tick (:meth:`MonitoredPlatoon.tick`) or a block of ticks
(:meth:`MonitoredPlatoon.run`, what an env step uses) at a time, with the same
result. Changing a follower's time gap setting ramps it in the simulator and
re-centres that follower's prior and chart on the new setting. :meth:`MonitoredPlatoon.degrade`
(:meth:`MonitoredPlatoon.degrade_many` for many envs at once) degrades followers
(:mod:`timegap_env.sim.degradation`) in the physics and the radar alike.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import numba
import numpy as np

from timegap_env.compiled import STAGE_KERNEL, follow_sources
from timegap_env.config import ChartConfig, MonitorConfig, PlatoonConfig, SensorConfig
from timegap_env.monitoring.charts import ChartMemory, ChartParts, ChartState, chart_dims, make_chart, restart_env
from timegap_env.monitoring.monitor import MonitorParts, TimeGapMonitor, monitor_dims, recenter_env
from timegap_env.monitoring.sensors import Readings, SensorParts, Sensors
from timegap_env.sim.degradation import Degradation, DegradationTable
from timegap_env.sim.platoon import Controller, Platoon, PlatoonParts, PlatoonState, PlatoonTicks, per_env, platoon_dims
from timegap_env.state import State

SAME_SETTING = 1e-6  # settings closer than this are the same setting [s]


class MonitoredTicks(NamedTuple):
    """A block of ticks of :meth:`MonitoredPlatoon.run`, arrays (n_ticks, n_envs, n_followers)."""

    physics: PlatoonTicks  # the simulator's state after each tick
    readings: Readings  # what the sensors measured, NaN = dropout
    tau_mean: np.ndarray  # posterior mean of tau [s]
    chart: ChartState  # the chart after each tick


class LoopParts(NamedTuple):
    """Everything per env a :class:`MonitoredPlatoon` holds."""

    platoon: PlatoonParts
    sensors: SensorParts
    monitor: MonitorParts
    chart: ChartParts


def loop_dims(platoon: PlatoonConfig, monitor: MonitorConfig, chart: ChartConfig) -> dict[str, int]:
    """The sizes of :class:`LoopParts`' dimensions under these configs."""
    return {**platoon_dims(platoon), **monitor_dims(monitor, platoon.n_followers),
            **chart_dims(chart, platoon.n_followers)}


class MonitoredPlatoon:
    """``n_envs`` platoons, each follower with its own sensors, monitor and chart.

    Attributes: ``platoon`` (:class:`~timegap_env.sim.platoon.Platoon`), ``sensors``
    (:class:`~timegap_env.monitoring.sensors.Sensors`), ``monitor``
    (:class:`~timegap_env.monitoring.monitor.TimeGapMonitor`), ``chart`` (a chart from
    :func:`~timegap_env.monitoring.charts.make_chart`), ``degradation``
    (:class:`~timegap_env.sim.degradation.DegradationTable`, none until :meth:`degrade`);
    ``ticks`` (n_envs,) since each env's reset. Their arrays are views of ``state`` at ``path``, a
    :class:`LoopParts` (their own state when None). ``physics``: the platoon to monitor, built for ``platoon`` and
    ``n_envs`` on that state at ``path + ("platoon",)`` (another simulator's, such as
    :class:`~timegap_env.sim.sumo.SumoPlatoon`); None: the native one.
    """

    def __init__(
        self,
        platoon: PlatoonConfig = PlatoonConfig(),
        monitor: MonitorConfig = MonitorConfig(),
        chart: ChartConfig = ChartConfig(),
        sensors: SensorConfig = SensorConfig(),
        n_envs: int = 1,
        seed: int | None = None,
        physics: Platoon | None = None,
        state: State | None = None,
        path: tuple[str, ...] = (),
    ) -> None:
        for name, config in (("monitor", monitor), ("chart", chart)):
            if not np.isclose(config.dt, platoon.dt):
                raise ValueError(f"{name}.dt = {config.dt}: must equal PlatoonConfig.dt = {platoon.dt}")
        if state is None:
            state = State(LoopParts, loop_dims(platoon, monitor, chart), n_envs)
        self.platoon = Platoon(platoon, n_envs, state, (*path, "platoon")) if physics is None else physics
        self.sensors = Sensors(sensors, n_envs, seed, platoon.n_followers, state, (*path, "sensors"))
        self.monitor = TimeGapMonitor(n_envs, platoon.n_followers, platoon.initial_setting, monitor, state,
                                      (*path, "monitor"))
        self.chart = make_chart(n_envs, platoon.n_followers, platoon.initial_setting, chart, state, (*path, "chart"))
        self.degradation = DegradationTable(platoon, n_envs, sensors)

    ticks = property(lambda self: self.platoon.ticks, doc="Ticks since each env's reset (n_envs,) [-].")

    def degrade(self, env: int, degradations: tuple[Degradation, ...], key: int) -> None:
        """Env ``env``'s followers take ``degradations`` (none: nominal) from the next tick on, in the physics
        and the radar; ``key`` (uint64) seeds the packet losses."""
        self.degrade_many(np.array([env]), [degradations], np.array([key], dtype=np.uint64))

    def degrade_many(self, envs: np.ndarray, degradations: Sequence[tuple[Degradation, ...]], keys: np.ndarray) -> None:
        """:meth:`degrade` for each env of ``envs`` (distinct indices) with its entry of ``degradations`` and of
        ``keys`` (uint64), at once."""
        envs = np.asarray(envs, dtype=np.intp)
        table = self.degradation
        table.set_many(envs, degradations)
        table.write_faults_many(self.platoon, envs, keys)
        table.write_levers(self.sensors.faults, envs)

    def reset(
        self,
        leader_speed: np.ndarray | float,
        leader_accel: np.ndarray | float = 0.0,
        mask: np.ndarray | None = None,
        setting: np.ndarray | float | None = None,
        noise_key: np.ndarray | None = None,
        dropout_probability: np.ndarray | None = None,
    ) -> None:
        """Equilibrium platoons for the envs in ``mask`` (None = all) at ``setting`` [s] (default the
        config's initial setting), monitors and charts centred on it.

        Optional, (n_envs,), read where ``mask``: ``noise_key`` (uint64), new sensor-noise keys;
        ``dropout_probability`` [-], new sensor dropout rates.
        """
        env_mask = np.ones(self.platoon.n_envs, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
        self.platoon.reset(leader_speed, leader_accel, mask=env_mask, setting=setting)
        if noise_key is not None:
            self.sensors.keys[env_mask] = np.asarray(noise_key, dtype=np.uint64)[env_mask]
        if dropout_probability is not None:
            self.sensors.dropout_probability[env_mask] = np.asarray(dropout_probability, dtype=float)[env_mask]
        self.monitor.reset(env_mask, self.platoon.setting)
        self.chart.reset(env_mask, self.platoon.setting)

    def change_setting(self, setting: np.ndarray | float, mask: np.ndarray | None = None) -> np.ndarray:
        """Ask for a new setting [s] (broadcast to (n_envs, n_followers)) where ``mask``; return who changed.

        Only a real change moves anything: the simulator ramps to it, and that
        follower's prior and chart are re-centred on it (the chart's history is
        cleared; its centre line then follows the ramp, see :meth:`run`). The
        chart holds its alarms off until the ramp is done plus ``settle_time``.
        """
        platoon = self.platoon
        setting = np.asarray(setting, dtype=float)
        if setting.shape != platoon.setting.shape:
            setting = np.broadcast_to(setting, platoon.setting.shape)
        targets = setting if mask is None else np.where(mask, setting, platoon.setting)
        changed = ~(np.abs(targets - platoon.setting) <= SAME_SETTING)  # NaN counts as a change, refused here
        if changed.any() and not ((setting > 0) & (setting < np.inf)).all():
            raise ValueError(f"setting = {setting}: every value must be finite and > 0 [s]")
        monitor, chart = self.monitor.parts, self.chart.parts
        _change_settings(tuple(platoon.state), tuple(platoon.controller), tuple(monitor.memory), monitor.slot,
                         (tuple(chart.memory), *chart[1:]), tuple(self.chart.rule), self.chart.config.settle_ticks,
                         np.ascontiguousarray(targets), changed)
        self.monitor.restart_posterior(changed)
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
        :meth:`~timegap_env.sim.platoon.Platoon.advance`). Each stage takes the whole block at once,
        with the same result as tick by tick. The chart's limits follow the applied (ramping) setting.
        """
        ticks_before = self.ticks.copy()
        physics = self.platoon.advance(leader_speed, leader_accel, v2v)
        readings = self.sensors.measure(Readings(physics.spacing, physics.speed), ticks_before)
        tau_mean = self.monitor.update_block(readings.speed, readings.spacing).tau_mean
        chart = self.chart.update_block(tau_mean, physics.applied_setting)
        return MonitoredTicks(physics, readings, tau_mean, chart)


@numba.njit(**STAGE_KERNEL)
def change_settings_env(platoon, controller, memory, slot, chart, chart_rule, settle_ticks, targets, changed, e):  # noqa: ANN001, ANN201, PLR0913
    """Env ``e``'s followers asked for the settings ``targets`` (n_followers,) [s] (see
    :meth:`MonitoredPlatoon.change_setting`): which change goes to ``changed`` (n_envs, n_followers); a follower
    whose setting changes ramps to it, its prior and chart are re-centred (the window's data and the chart's
    history cleared) and its alarms held off while it ramps and settles, ``settle_ticks`` more. ``platoon``
    (:class:`~timegap_env.sim.platoon.PlatoonState`), ``controller``, ``memory`` (the monitor's
    :class:`~timegap_env.monitoring.monitor.WindowMemory`), ``slot`` (its next ring slots), ``chart``
    (:class:`~timegap_env.monitoring.charts.ChartParts`) and its ``chart_rule`` come as plain tuples or
    structures; the posterior of a re-centred follower is the prior's once the window runs again."""
    platoon, controller = PlatoonState(*platoon), Controller(*controller)
    chart_memory, center, statistic, chart_tick = chart
    for f in range(targets.shape[0]):
        setting = targets[f]
        changed[e, f] = not abs(setting - platoon.setting[e, f]) <= SAME_SETTING
        if not changed[e, f]:
            continue
        platoon.setting[e, f] = setting
        recenter_env(memory, slot, setting, e, f)
        applied = platoon.applied_setting[e, f]
        restart_env(chart_rule, chart_memory, center, statistic, chart_tick[e], applied, e, f)
        ramp_ticks = math.ceil(abs(setting - applied) / controller.max_setting_change)
        ChartMemory(*chart_memory).hold_off[e, f] = int(ramp_ticks + settle_ticks)


@numba.njit(cache=True, error_model="numpy")
def _change_settings(platoon, controller, memory, slot, chart, chart_rule, settle_ticks, targets, changed):  # noqa: ANN001, ANN202, PLR0913
    """:func:`change_settings_env` for every env, env e to ``targets[e]``."""
    for e in range(targets.shape[0]):
        change_settings_env(platoon, controller, memory, slot, chart, chart_rule, settle_ticks, targets[e], changed, e)


follow_sources(__name__)
