"""The task behind ``TimeGapMonitor-v0`` for ``n_envs`` platoons at once.

Scenarios drawn at reset, actions turned into settings, ``ticks_per_decision``
simulator ticks per step through :class:`MonitoredPlatoon`, then observations,
reward terms and episode statistics. The single env runs it with
``n_envs = 1``, the native vector env with ``n_envs = N``: same code, so they
agree step by step.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from typing import Any, NamedTuple

import numba
import numpy as np

from timegap_env.config import EnvConfig
from timegap_env.leaders import LeaderProfile
from timegap_env.monitor import outside_probability
from timegap_env.monitored import MonitoredPlatoon
from timegap_env.scenarios import SCENARIOS, make_leader

FEATURES = (
    "deviation",  # (posterior mean of tau - tau*) / DEVIATION_SCALE, clipped to [-1, 1]
    "estimate_std",  # posterior std of tau / (L sigma_desired), clipped to [0, 1]
    "prob_outside",  # posterior probability that tau lies outside [LCL, UCL]
    "alarm",  # 1 while the chart is in alarm
    "exceedances",  # exceedances within the chart's trailing window / (2 switch_exceedances), clipped to [0, 1]
    "time_since_alarm",  # time since the last alarm / exceedance_window, clipped to [0, 1]
    "setting",  # (tau* - smallest level) / (largest level - smallest level)
    "speed",  # own speed / SPEED_SCALE, clipped to [0, 1]
    "v2v",  # 1 in CACC (V2V on), 0 in ACC
)
DEVIATION_SCALE = 1.0  # [s]
SPEED_SCALE = 40.0  # [m/s], above the 80 mph band
OBSERVATION_LOW = np.array([-1, 0, 0, 0, 0, 0, 0, 0, 0], dtype=np.float32)
OBSERVATION_HIGH = np.ones(len(FEATURES), dtype=np.float32)
REWARD_TERMS = ("tracking", "alarms", "safety", "collision", "comfort", "efficiency", "preference", "switching")
TOTALS = ("steps", "alarm_ticks", "exceedances", "max_deviation", "jerk_squared", "switches", "setting", "capacity",
          "collision", "min_ttc")  # what an episode adds up, per env


@dataclasses.dataclass(frozen=True)
class StepResult:
    """What one step returns for every env, arrays with a leading n_envs axis."""

    reward: np.ndarray  # (n_envs,)
    terms: dict[str, np.ndarray]  # reward term -> (n_envs,), each <= 0
    terminated: np.ndarray  # (n_envs,) a collision ended the episode
    truncated: np.ndarray  # (n_envs,) the episode ran out of time or leader profile


class PlatoonTask:
    """Scenarios, actions, observations and rewards of ``n_envs`` monitored platoons."""

    def __init__(self, config: EnvConfig, n_envs: int) -> None:
        unknown = sorted(set(config.scenario_weights) - set(SCENARIOS))
        if unknown:
            raise ValueError(f"EnvConfig.scenario_weights has unknown families {unknown}; known: {sorted(SCENARIOS)}")
        self.config = config
        self.n_envs = n_envs
        self.n_followers = config.platoon.n_followers
        self.levels = np.asarray(config.time_gap_levels, dtype=float)
        self.loop = MonitoredPlatoon(config.platoon, config.monitor, config.chart, config.sensors, n_envs)
        self.ticks_per_decision = config.ticks_per_decision
        max_ticks = config.max_episode_steps * self.ticks_per_decision
        self.leader_speed = np.zeros((n_envs, max_ticks + 1))  # [m/s]
        self.leader_accel = np.zeros((n_envs, max_ticks + 1))  # [m/s^2]
        self.episode_ticks = np.full(n_envs, max_ticks)  # ticks in each env's episode
        self.v2v_loss_start = np.zeros((n_envs, self.n_followers), dtype=np.int64)  # first tick without V2V
        self.v2v_loss_end = np.zeros((n_envs, self.n_followers), dtype=np.int64)  # first tick with V2V again
        self.scenario = np.full(n_envs, "", dtype=object)
        self._previous_accel = np.zeros((n_envs, self.n_followers))  # [m/s^2]
        self._min_ttc_step = np.full((n_envs, self.n_followers), np.inf)
        self._rms_jerk_step = np.zeros((n_envs, self.n_followers))
        self._observation_constants = (  # what _observation_kernel needs of the config
            config.chart.limit_width * config.chart.baseline_std, 2 * config.chart.switch_exceedances,
            config.platoon.dt, config.chart.exceedance_window, self.levels[0], self.levels[-1] - self.levels[0],
        )
        self._score_constants = (  # what _score_kernel needs of the config
            config.platoon.dt, config.chart.limit_width * config.chart.baseline_std, config.ttc_threshold,
            config.jerk_reference, self.levels[0], self.levels[-1] - self.levels[0], config.preferred_time_gap,
            config.platoon.standstill_spacing + config.platoon.vehicle_length,
            np.array([getattr(config.reward_weights, name) for name in REWARD_TERMS]),
        )
        self.totals = {name: np.zeros(n_envs) for name in TOTALS}  # this episode's, see episode_summary
        self.totals["min_ttc"][:] = np.inf
        self.trace: list[tuple[float, np.ndarray, np.ndarray]] | None = None  # env 0 per tick, for rendering:
        # (t [s], posterior means of tau [s], chart centre lines [s])
        families = list(config.scenario_weights)
        weights = np.array([config.scenario_weights[f] for f in families], dtype=float)
        self._families, self._family_probabilities = families, weights / weights.sum()

    # ------------------------------------------------------------------ reset
    def reset(self, mask: np.ndarray, rngs: Sequence[np.random.Generator], options: Mapping[str, Any] | None) -> None:
        """Draw a new episode for every env in ``mask``, env i from ``rngs[i]``.

        ``options``: ``{"scenario": name}`` picks a scenario family; ``{"leader_speed": array}``
        runs the user's leader speed series [m/s] at ``platoon.dt`` (truncated to the episode,
        padded to whole decisions by holding its last speed).
        """
        cfg = self.config
        options = dict(options or {})
        unknown = sorted(set(options) - {"scenario", "leader_speed"})
        if unknown:
            raise ValueError(f"reset options {unknown} unknown; known: ['leader_speed', 'scenario']")
        noise_keys = np.zeros(self.n_envs, dtype=np.uint64)
        for env in np.flatnonzero(mask):
            rng = rngs[env]
            if "leader_speed" in options:
                profile = LeaderProfile.from_speed(np.asarray(options["leader_speed"], dtype=float), cfg.platoon.dt, "user")
            else:
                family = options.get("scenario") or self._families[rng.choice(len(self._families), p=self._family_probabilities)]
                profile = make_leader(family, int(rng.integers(2**31)), cfg.leader)
                if not math.isclose(profile.dt, cfg.platoon.dt, rel_tol=1e-9):
                    raise ValueError(f"scenario {family!r} has dt = {profile.dt} s; the env runs at {cfg.platoon.dt} s")
            self._load_leader(env, profile)
            self._draw_disturbances(env, rng)
            noise_keys[env] = rng.integers(0, 2**63, dtype=np.uint64)
        self.loop.reset(self.leader_speed[:, 0], self.leader_accel[:, 0], mask=mask, time_gap=cfg.platoon.time_gap,
                        noise_key=noise_keys)
        self.loop.platoon.set_v2v(self._v2v_at(self.loop.ticks))
        self._previous_accel[mask] = self.loop.platoon.a[mask, 1:]
        self._min_ttc_step[mask] = np.inf
        self._rms_jerk_step[mask] = 0.0
        for name, total in self.totals.items():
            total[mask] = np.inf if name == "min_ttc" else 0.0

    def _load_leader(self, env: int, profile: LeaderProfile) -> None:
        """Put ``profile`` in env's leader buffer, cut to the episode and padded to whole decisions."""
        tpd, capacity = self.ticks_per_decision, self.leader_speed.shape[1] - 1
        ticks = min(profile.speed.size - 1, capacity)
        ticks = -(-ticks // tpd) * tpd  # up to whole decisions
        n = min(profile.speed.size, ticks + 1)
        self.leader_speed[env, :n] = profile.speed[:n]
        self.leader_speed[env, n:] = profile.speed[n - 1]
        self.leader_accel[env, :n] = profile.accel[:n]
        self.leader_accel[env, n:] = 0.0
        self.episode_ticks[env] = ticks
        self.scenario[env] = profile.name

    def _draw_disturbances(self, env: int, rng: np.random.Generator) -> None:
        """V2V loss for some followers, and this episode's sensor dropout rate."""
        cfg = self.config
        self.v2v_loss_start[env] = self.v2v_loss_end[env] = 0
        if rng.random() < cfg.v2v_loss_probability:
            losing = rng.random(self.n_followers) < cfg.v2v_loss_follower_probability
            losing[rng.integers(self.n_followers)] = True  # at least one follower
            episode = self.episode_ticks[env]
            duration = int(round(rng.uniform(*cfg.v2v_loss_duration_range) / cfg.platoon.dt))
            start = int(rng.integers(0, max(episode - duration, 0) + 1))
            self.v2v_loss_start[env, losing] = start
            self.v2v_loss_end[env, losing] = start + duration
        self.loop.dropout_probability[env] = rng.uniform(*cfg.dropout_probability_range)

    # ------------------------------------------------------------------ step
    def settings_for(self, action: np.ndarray) -> np.ndarray:
        """Time gap settings [s] (n_envs, n_followers) for ladder indices: (n_envs,) platoon or (n_envs, N) per vehicle."""
        action = np.asarray(action)
        expected = (self.n_envs,) if self.config.action_mode == "platoon" else (self.n_envs, self.n_followers)
        if action.shape != expected or not np.issubdtype(action.dtype, np.integer):
            raise ValueError(f"action = {action!r}: expected integer ladder indices of shape {expected}")
        if ((action < 0) | (action >= self.levels.size)).any():
            raise ValueError(f"action = {action!r}: every index must be in [0, {self.levels.size - 1}]")
        settings = self.levels[action]
        return np.repeat(settings[:, None], self.n_followers, axis=1) if settings.ndim == 1 else settings

    def _v2v_at(self, ticks: np.ndarray) -> np.ndarray:
        """CACC status of every follower at the given ticks, (..., n_envs) -> (..., n_envs, n_followers)."""
        ticks = ticks[..., None]
        return ~((ticks >= self.v2v_loss_start) & (ticks < self.v2v_loss_end))

    def step(self, action: np.ndarray) -> StepResult:
        """Apply the action, run one decision interval of ticks, and score it."""
        cfg, loop, platoon = self.config, self.loop, self.loop.platoon
        changed = loop.change_time_gap(self.settings_for(action))
        ticks = loop.ticks + np.arange(self.ticks_per_decision)[:, None]  # (n_ticks, n_envs), before each tick
        leader_ticks = np.minimum(ticks + 1, self.episode_ticks)
        rows = np.arange(self.n_envs)
        leader_speed = self.leader_speed[rows, leader_ticks]
        block = loop.run(leader_speed, self.leader_accel[rows, leader_ticks], self._v2v_at(ticks))
        physics, chart = block.physics, block.chart
        if self.trace is not None:
            self.trace.extend(zip((ticks[:, 0] + 1) * cfg.platoon.dt, block.tau_mean[:, 0], chart.center[:, 0]))

        score = _StepScore.empty(self.n_envs, self.n_followers)
        _score_kernel(
            block.tau_mean, chart.center, chart.alarm, chart.exceedance, physics.collisions, leader_speed,
            physics.speed, physics.spacing, physics.accel, self._previous_accel, platoon.time_gap_setting,
            changed, self._score_constants, *score, *(self.totals[name] for name in TOTALS),
        )
        self._previous_accel = physics.accel[-1].copy()
        self._min_ttc_step = score.min_ttc
        self._rms_jerk_step = np.sqrt(score.jerk_squared / self.ticks_per_decision)
        terms = dict(zip(REWARD_TERMS, score.terms))
        terminated = platoon.collided.any(axis=1)
        truncated = (loop.ticks >= self.episode_ticks) & ~terminated
        return StepResult(reward=score.reward, terms=terms, terminated=terminated, truncated=truncated)

    # ------------------------------------------------------------------ read-outs
    def observation(self) -> np.ndarray:
        """Observations (n_envs, n_followers, len(FEATURES)) float32, the features in FEATURES order."""
        monitor, chart, platoon = self.loop.monitor, self.loop.chart, self.loop.platoon
        features = np.empty((self.n_envs, self.n_followers, len(FEATURES)), dtype=np.float32)
        moments = monitor.moments
        _observation_kernel(moments.mean_tau, moments.var_tau, chart.center, chart.side, chart.exceedances_in_window,
                            chart.run_length, platoon.time_gap_setting, platoon.v, platoon.v2v,
                            self._observation_constants, features)
        return features

    def info(self) -> dict[str, np.ndarray]:
        """Per-step diagnostics, each (n_envs, n_followers) unless noted."""
        cfg, monitor, chart, platoon = self.config, self.loop.monitor, self.loop.chart, self.loop.platoon
        half_width = cfg.chart.limit_width * cfg.chart.baseline_std
        with np.errstate(divide="ignore", invalid="ignore"):
            time_gap = (platoon.spacing - cfg.platoon.standstill_spacing) / platoon.v[:, 1:]
        return {
            "time_gap": time_gap,  # actual (s - s0) / v [s]
            "estimate": monitor.tau_mean,  # posterior mean of tau [s]
            "estimate_std": monitor.tau_std,  # [s]
            "setting": platoon.time_gap_setting.copy(),  # tau* [s]
            "lcl": chart.center - half_width,  # [s]
            "ucl": chart.center + half_width,  # [s]
            "alarm": chart.alarm,
            "ttc": self._min_ttc_step.copy(),  # smallest time-to-collision during the step [s], inf if never closing
            "jerk": self._rms_jerk_step.copy(),  # RMS jerk during the step [m/s^3]
            "v2v": platoon.v2v.copy(),
            "collision": platoon.collided.any(axis=1),  # (n_envs,)
            "skipped_measurements": monitor.skipped.copy(),  # since reset [-]
        }

    def episode_summary(self) -> dict[str, np.ndarray]:
        """Episode statistics so far, each (n_envs,)."""
        totals, dt = self.totals, self.config.platoon.dt
        steps = np.maximum(totals["steps"], 1)
        return {
            "time_out_of_control": totals["alarm_ticks"] * dt / self.n_followers,  # per follower [s]
            "exceedances": totals["exceedances"].copy(),  # all followers [-]
            "max_deviation": totals["max_deviation"].copy(),  # largest |estimate - tau*| [s]
            "min_ttc": totals["min_ttc"].copy(),  # [s]
            "rms_jerk": np.sqrt(totals["jerk_squared"] / steps),  # [m/s^3]
            "switches": totals["switches"].copy(),  # follower setting changes [-]
            "mean_setting": totals["setting"] / steps,  # [s]
            "mean_capacity": totals["capacity"] / steps,  # implied by the settings at the speeds driven [veh/h]
            "collision": totals["collision"].astype(bool),
            "duration": totals["steps"] * self.config.decision_interval,  # [s]
        }


class _StepScore(NamedTuple):
    """A step's reward and per-follower safety and comfort, filled by :func:`_score_kernel`."""

    terms: np.ndarray  # (len(REWARD_TERMS), n_envs) the reward terms, each <= 0
    reward: np.ndarray  # (n_envs,) weighted sum of the terms
    min_ttc: np.ndarray  # (n_envs, n_followers) smallest time-to-collision, inf if never closing [s]
    jerk_squared: np.ndarray  # (n_envs, n_followers) sum over the ticks of jerk^2 [m^2/s^6]

    @classmethod
    def empty(cls, n_envs: int, n_followers: int) -> _StepScore:
        per_follower = np.empty((2, n_envs, n_followers))
        return cls(np.empty((len(REWARD_TERMS), n_envs)), np.empty(n_envs), per_follower[0], per_follower[1])


@numba.njit(cache=True)
def _score_kernel(  # noqa: ANN202, PLR0913 -- the kernel takes the step's arrays one by one
    tau_mean, center, alarm, exceedance, collisions, leader_speed, speed, spacing, accel,
    previous_accel, setting, changed, constants,
    terms, reward, min_ttc, jerk_squared,
    steps, alarm_ticks, exceedances, max_deviation, total_jerk_squared, switches, total_setting, capacity,
    collision, total_min_ttc,
):
    """Score a step: block arrays (n_ticks, n_envs, n_followers) in, :class:`_StepScore` arrays filled,
    and the episode totals (``PlatoonTask.totals``, in TOTALS order, each (n_envs,)) carried on.

    The reward terms, in REWARD_TERMS order, each <= 0 (see ``RewardWeights`` for their meaning):
    tracking and alarms over every follower-tick; safety from each follower's smallest TTC;
    comfort from its mean squared jerk; efficiency, preference and switching from the settings
    at the end of the step. One pass in a fixed order, so one env scores the same alone as in a batch.
    """
    (dt, half_width, ttc_threshold, jerk_reference, smallest_level, level_span, preferred_time_gap,
     gap_per_vehicle, weights) = constants
    n_ticks, n_envs, n_followers = tau_mean.shape
    follower_ticks = n_ticks * n_followers
    for e in range(n_envs):
        deviation_sum = step_max_deviation = step_alarm_ticks = step_exceedances = 0.0
        collided = False
        for k in range(n_ticks):
            tick_deviation = 0.0
            for f in range(n_followers):
                deviation = abs(tau_mean[k, e, f] - center[k, e, f])
                tick_deviation += deviation
                step_max_deviation = max(step_max_deviation, deviation)
                step_alarm_ticks += alarm[k, e, f]
                step_exceedances += exceedance[k, e, f]
                collided = collided or collisions[k, e, f]
            deviation_sum += tick_deviation
        safety = comfort = efficiency = preference = switching = 0.0
        jerk_sum = setting_sum = capacity_sum = 0.0
        step_min_ttc = np.inf
        for f in range(n_followers):
            min_ttc[e, f], jerk_squared[e, f] = np.inf, 0.0
            for k in range(n_ticks):
                predecessor_speed = leader_speed[k, e] if f == 0 else speed[k, e, f - 1]
                closing = speed[k, e, f] - predecessor_speed  # [m/s], > 0 when the gap shrinks
                if closing > 0:
                    min_ttc[e, f] = min(min_ttc[e, f], spacing[k, e, f] / closing)
                before = previous_accel[e, f] if k == 0 else accel[k - 1, e, f]
                jerk_squared[e, f] += ((accel[k, e, f] - before) / dt) ** 2
            v = speed[-1, e, f]  # the speed at the end of the step [m/s]
            safety += max(0.0, 1.0 - min_ttc[e, f] / ttc_threshold)
            comfort += jerk_squared[e, f] / n_ticks
            efficiency += 1.0 - (v * smallest_level + gap_per_vehicle) / (v * setting[e, f] + gap_per_vehicle)
            preference += abs(setting[e, f] - preferred_time_gap)
            switching += changed[e, f]
            step_min_ttc = min(step_min_ttc, min_ttc[e, f])
            jerk_sum += jerk_squared[e, f]
            setting_sum += setting[e, f]
            capacity_sum += 3600.0 * v / (v * setting[e, f] + gap_per_vehicle)  # [veh/h] at the current speed
        terms[0, e] = -deviation_sum / follower_ticks / half_width  # tracking
        terms[1, e] = -step_alarm_ticks / follower_ticks  # alarms
        terms[2, e] = -(safety / n_followers)  # safety
        terms[3, e] = -1.0 if collided else -0.0  # collision
        terms[4, e] = -(comfort / n_followers) / jerk_reference**2  # comfort
        terms[5, e] = -(efficiency / n_followers)  # efficiency
        terms[6, e] = -(preference / n_followers) / level_span  # preference
        terms[7, e] = -(switching / n_followers)  # switching
        reward[e] = 0.0
        for t in range(terms.shape[0]):
            reward[e] += weights[t] * terms[t, e]
        steps[e] += 1
        alarm_ticks[e] += step_alarm_ticks
        exceedances[e] += step_exceedances
        max_deviation[e] = max(max_deviation[e], step_max_deviation)
        total_jerk_squared[e] += jerk_sum / n_followers
        switches[e] += switching
        total_setting[e] += setting_sum / n_followers
        capacity[e] += capacity_sum / n_followers
        collision[e] = max(collision[e], 1.0 if collided else 0.0)
        total_min_ttc[e] = min(total_min_ttc[e], step_min_ttc)


@numba.njit(cache=True)
def _observation_kernel(  # noqa: ANN202, PLR0913 -- the kernel takes the state arrays one by one
    tau_mean, tau_var, center, side, exceedances_in_window, run_length, setting, speed, v2v, constants, out
):
    """Fill ``out`` (n_envs, n_followers, len(FEATURES)) float32 with the features, in FEATURES order, clipped
    to [OBSERVATION_LOW, OBSERVATION_HIGH]; ``speed`` (n_envs, n_vehicles) includes the leader."""
    half_width, exceedance_scale, dt, exceedance_window, smallest_level, level_span = constants
    n_envs, n_followers, n_features = out.shape
    for e in range(n_envs):
        for f in range(n_followers):
            mean, variance, line = tau_mean[e, f], tau_var[e, f], center[e, f]
            out[e, f, 0] = (mean - line) / DEVIATION_SCALE
            out[e, f, 1] = math.sqrt(variance) / half_width
            out[e, f, 2] = outside_probability(mean, variance, line - half_width, line + half_width)
            out[e, f, 3] = side[e, f] != 0
            out[e, f, 4] = exceedances_in_window[e, f] / exceedance_scale
            out[e, f, 5] = run_length[e, f] * dt / exceedance_window
            out[e, f, 6] = (setting[e, f] - smallest_level) / level_span
            out[e, f, 7] = speed[e, f + 1] / SPEED_SCALE
            out[e, f, 8] = v2v[e, f]
            for i in range(n_features):
                out[e, f, i] = min(max(out[e, f, i], OBSERVATION_LOW[i]), OBSERVATION_HIGH[i])
