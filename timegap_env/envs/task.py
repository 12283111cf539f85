"""The task behind ``TimeGapMonitor-v0`` for ``n_envs`` platoons at once: orchestration only.

Reset: each env draws its episode (:mod:`~timegap_env.envs.episodes`) and the monitored platoon
(:mod:`~timegap_env.monitoring.loop`) restarts on it. Step: the action becomes settings
(:mod:`~timegap_env.envs.action`), ``ticks_per_decision`` ticks run through the monitored
platoon, and the step is scored (:mod:`~timegap_env.envs.reward`) and added to the episode
totals (:mod:`~timegap_env.envs.totals`); the observation is :mod:`~timegap_env.envs.observation`'s.
The single env runs the task with ``n_envs = 1``, the native vector env with ``n_envs = N``:
same code, so they agree step by step.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from typing import Any, NamedTuple

import numpy as np

from timegap_env.config import TIME_GAP_MIN_SPEED, EnvConfig
from timegap_env.envs.action import SettingLadder
from timegap_env.envs.episodes import Episodes, check_reset_options
from timegap_env.envs.info import TRUTH_PREFIX, prefixed
from timegap_env.envs.observation import FollowerState, ObservationScales, observe
from timegap_env.envs.rendering import RenderFrame
from timegap_env.envs.reward import RewardConstants, StepReadouts, StepTicks, score_step, weights_of
from timegap_env.envs.totals import EpisodeTotals
from timegap_env.monitoring.loop import MonitoredPlatoon


@dataclasses.dataclass(frozen=True)
class StepResult:
    """What one step returns for every env, arrays with a leading n_envs axis."""

    reward: np.ndarray  # (n_envs,)
    terms: dict[str, np.ndarray]  # reward term -> (n_envs,), each <= 0
    terminated: np.ndarray  # (n_envs,) a collision ended the episode
    truncated: np.ndarray  # (n_envs,) the episode ran out of time or leader profile


class TraceArrays(NamedTuple):
    """Env 0's monitor and chart at every traced tick."""

    t: np.ndarray  # (n_ticks,) time since reset [s]
    estimate: np.ndarray  # (n_ticks, n_followers) posterior mean of tau [s]
    center: np.ndarray  # (n_ticks, n_followers) the chart's centre line, the applied setting [s]


class Trace:
    """A record of env 0's estimates and chart centre lines, tick by tick, for rendering and profiles."""

    def __init__(self, n_followers: int) -> None:
        self.n_followers = n_followers
        self._blocks: list[TraceArrays] = []

    def add(self, block: TraceArrays) -> None:
        """Append a block of ticks."""
        self._blocks.append(block)

    def clear(self) -> None:
        self._blocks.clear()

    def arrays(self) -> TraceArrays:
        """Every tick recorded so far."""
        if not self._blocks:
            return TraceArrays(np.empty(0), np.empty((0, self.n_followers)), np.empty((0, self.n_followers)))
        return TraceArrays(*(np.concatenate(parts) for parts in zip(*self._blocks)))


class PlatoonTask:
    """Episodes, actions, observations and rewards of ``n_envs`` monitored platoons.

    ``trace``: None, or a :class:`Trace` of env 0 that every step adds to (see :meth:`start_trace`).
    """

    def __init__(self, config: EnvConfig, n_envs: int) -> None:
        self.config = config
        self.n_envs = n_envs
        self.n_followers = config.platoon.n_followers
        self.ticks_per_decision = config.ticks_per_decision
        self.episodes = Episodes(config, n_envs)
        self.ladder = SettingLadder(config, n_envs)
        self.loop = MonitoredPlatoon(config.platoon, config.monitor, config.chart, config.sensors, n_envs)
        self.totals = EpisodeTotals.zeros(n_envs)
        self._previous_accel = np.zeros((n_envs, self.n_followers))  # before the next step's first tick [m/s^2]
        self._accel_envelope = np.zeros((n_envs, self.n_followers + 1))  # decaying peak |acceleration|, leader first [m/s^2]
        self._readouts = StepReadouts.empty(n_envs, self.n_followers)  # of the last step, refilled by every step
        self._readouts.min_ttc[:], self._readouts.jerk_squared[:] = np.inf, 0.0
        self._scales = ObservationScales.from_config(config)
        self._reward_constants = RewardConstants.from_config(config)
        self._weights = weights_of(config)
        self.trace: Trace | None = None

    # ------------------------------------------------------------------ reset
    def reset(self, mask: np.ndarray, rngs: Sequence[np.random.Generator], options: Mapping[str, Any] | None) -> None:
        """Draw a new episode for every env in ``mask``, env i from ``rngs[i]``; ``options`` as in
        :meth:`~timegap_env.envs.episodes.Episodes.draw`."""
        options = check_reset_options(options)
        episodes, loop = self.episodes, self.loop
        for env in np.flatnonzero(mask):
            episodes.draw(env, rngs[env], options)
            loop.degrade(env, episodes.degradations[env], episodes.packet_loss_keys[env])
        loop.reset(episodes.leader_speed[:, 0], episodes.leader_accel[:, 0], mask=mask,
                   setting=episodes.initial_setting[:, None], noise_key=episodes.noise_keys,
                   dropout_probability=episodes.dropout_probability)
        loop.platoon.set_v2v(loop.degradation.v2v_up(loop.ticks), mask=mask)  # the others keep their last tick's
        self._previous_accel[mask] = loop.platoon.a[mask, 1:]
        self._accel_envelope[mask] = np.abs(loop.platoon.a[mask])
        self._readouts.min_ttc[mask] = np.inf
        self._readouts.jerk_squared[mask] = 0.0
        self.totals.restart(mask)

    def start_trace(self) -> Trace:
        """Record env 0 at every tick from now on (cleared at each reset by the env); returns the trace."""
        self.trace = Trace(self.n_followers)
        return self.trace

    # ------------------------------------------------------------------ step
    def step(self, action: np.ndarray) -> StepResult:
        """Apply the action, run one decision interval of ticks, and score it."""
        cfg, loop, platoon = self.config, self.loop, self.loop.platoon
        changed = loop.change_setting(self.ladder.settings(action, platoon.setting))
        ticks = loop.ticks + np.arange(self.ticks_per_decision)[:, None]  # (n_ticks, n_envs), before each tick
        leader_speed, leader_accel = self.episodes.leader_at(ticks + 1)
        block = loop.run(leader_speed, leader_accel, loop.degradation.v2v_up(ticks))
        physics, chart = block.physics, block.chart
        if self.trace is not None:
            self.trace.add(TraceArrays((ticks[:, 0] + 1) * cfg.platoon.dt, block.tau_mean[:, 0], chart.center[:, 0]))

        step = StepTicks(
            tau_mean=block.tau_mean, center=chart.center, applied_setting=physics.applied_setting, alarm=chart.alarm,
            exceedance=chart.exceedance, collisions=physics.collisions, leader_speed=leader_speed,
            leader_accel=leader_accel, speed=physics.speed, spacing=physics.spacing, accel=physics.accel,
        )
        score = score_step(step, self._previous_accel, self._accel_envelope, platoon.setting, changed,
                           self._reward_constants, self._weights, self._readouts)
        self.totals.add_step(self._readouts, platoon.setting, changed, self._reward_constants.gap_per_vehicle)
        self._previous_accel = physics.accel[-1].copy()
        terminated = platoon.collided.any(axis=1)
        truncated = (loop.ticks >= self.episodes.episode_ticks) & ~terminated
        return StepResult(reward=score.reward, terms=score.terms._asdict(), terminated=terminated, truncated=truncated)

    # ------------------------------------------------------------------ read-outs
    @property
    def scenario(self) -> np.ndarray:
        """The leader's name in each env's episode (n_envs,)."""
        return self.episodes.scenario

    def observation(self) -> np.ndarray:
        """Observations (n_envs, n_followers, len(FEATURES)) float32, the features in FEATURES order."""
        moments, chart, platoon = self.loop.monitor.moments, self.loop.chart, self.loop.platoon
        state = FollowerState(
            tau_mean=moments.mean_tau, tau_var=moments.var_tau, center=chart.center, side=chart.side,
            exceedances_in_window=chart.exceedances_in_window, run_length=chart.run_length, setting=platoon.setting,
            speed=platoon.v[:, 1:], v2v=platoon.v2v,
        )
        return observe(state, self._scales)

    def monitor_info(self) -> dict[str, np.ndarray]:
        """Per-step diagnostics, each (n_envs, n_followers) unless noted."""
        monitor, chart, platoon = self.loop.monitor, self.loop.chart, self.loop.platoon
        half_width = self._scales.half_width
        return {
            # (s - s0) / v [s]; inf below TIME_GAP_MIN_SPEED, where it is not defined (never NaN)
            "actual_time_gap": np.where(platoon.v[:, 1:] >= TIME_GAP_MIN_SPEED, platoon.actual_time_gap, np.inf),
            "estimate": monitor.tau_mean,  # posterior mean of tau [s]
            "estimate_std": monitor.tau_std,  # [s]
            "setting": platoon.setting.copy(),  # tau* asked for [s]
            "lcl": chart.center - half_width,  # [s]
            "ucl": chart.center + half_width,  # [s]
            "alarm": chart.alarm.copy(),
            "ttc": self._readouts.min_ttc.copy(),  # smallest time-to-collision during the step [s], inf if never closing
            "jerk": np.sqrt(self._readouts.jerk_squared / self.ticks_per_decision),  # RMS jerk during the step [m/s^3]
            "v2v": platoon.v2v.copy(),
            "collision": platoon.collided.any(axis=1),  # (n_envs,)
            "skipped_measurements": monitor.skipped.copy(),  # since reset [-]
        }

    def step_info(self) -> dict[str, np.ndarray]:
        """Every env's info now, flat (:mod:`~timegap_env.envs.info`): :meth:`monitor_info` and the ground truth as
        ``truth_<name>``, each array with a leading n_envs axis."""
        return {**self.monitor_info(), **prefixed(TRUTH_PREFIX, self.ground_truth())}

    def ground_truth(self) -> dict[str, np.ndarray]:
        """Each follower's degradation now, its true parameters and the smallest string-stable setting for them,
        arrays (n_envs, n_followers) (:meth:`~timegap_env.sim.degradation.DegradationTable.truth`): for
        oracles and evaluation, never in the observation."""
        loop = self.loop
        return loop.degradation.truth(loop.ticks, loop.degradation.v2v_up(loop.ticks) & self.config.platoon.v2v)

    def episode_summary(self) -> dict[str, np.ndarray]:
        """Episode statistics so far, each (n_envs,)."""
        return self.totals.summary(self.config)

    def fingerprint(self, env: int) -> str:
        """A hash of everything random that env ``env``'s current episode drew."""
        return self.episodes.fingerprint(env)

    def render_frame(self, history: float) -> RenderFrame:
        """What env 0 looks like now, with the last ``history`` seconds [s] of its trace (empty without one)."""
        platoon, chart = self.loop.platoon, self.loop.chart
        now = self.loop.ticks[0] * self.config.platoon.dt
        trace = (self.trace or Trace(self.n_followers)).arrays()
        recent = trace.t >= now - history
        centers = trace.center[recent]
        half_width = self._scales.half_width
        return RenderFrame(
            t=now,
            x=platoon.x[0].copy(),
            v=platoon.v[0].copy(),
            vehicle_length=self.config.platoon.vehicle_length,
            history_t=trace.t[recent],
            estimate_history=trace.estimate[recent],
            lcl=chart.center[0] - half_width,
            ucl=chart.center[0] + half_width,
            center=chart.center[0].copy(),
            alarm=chart.alarm[0].copy(),
            v2v=platoon.v2v[0].copy(),
            collided=platoon.collided[0].copy(),
            lcl_history=centers - half_width,
            ucl_history=centers + half_width,
            center_history=centers,
        )
