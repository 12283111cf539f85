"""The env step as one compiled call: action -> settings -> physics -> sensors -> monitor -> chart -> reward ->
observation, env by env, over state that lives in preallocated arrays.

:func:`fused_step` runs, for each env in turn, what the staged path of
:class:`~timegap_env.envs.task.PlatoonTask` runs stage by stage over every env: the action becomes
settings (:class:`~timegap_env.envs.action.SettingLadder`), a changed setting ramps in the physics and
re-centres that follower's prior and chart (:meth:`~timegap_env.monitoring.loop.MonitoredPlatoon.change_setting`),
then the decision's ticks go through the platoon, the sensors, the monitor and the chart, and the step is
scored, added to the episode totals and observed. Each stage is the same compiled function the staged
path calls (``ladder_env``, ``advance_env``, ``measure_env``, ``update_env``, ``chart_sides_env``,
``count_excursions_env``, ``env_readouts``, ...), so the arithmetic has one source; what is written here again
is the glue the staged path does in NumPy (which followers changed setting and how long their alarms are held off,
the leader's and V2V's ticks), and the tests check the two paths against each other bit for bit.

Working env by env keeps each env's state in cache while all its stages run (the step asks for the next env's
rows ahead: :attr:`~timegap_env.state.Layout.prefetch`, and :func:`_prefetch_inside` for the places inside rows
that move from step to step), and re-centres only the followers whose setting changed. Every env's state is
:class:`EnvState`, one allocation (:mod:`timegap_env.state`) whose components each declare their own fields;
the kernel is handed its few blocks and makes the named views inside (``env_view``), besides the scratch its
ticks go through (:class:`StepScratch`), the config's constants (:class:`StepRules`), the action and the
:class:`~timegap_env.envs.info.InfoBlock` it writes the infos' values into (a single env's info).
"""

from __future__ import annotations

import math
from typing import Annotated, NamedTuple

import numba
import numpy as np

from timegap_env.compiled import NO_ALLOCATION, STAGE_KERNEL, follow_sources, prefetch_item
from timegap_env.config import EnvConfig
from timegap_env.envs.action import LadderRule, ladder_env
from timegap_env.envs.episodes import LeaderTrack, episode_dims
from timegap_env.envs.info import InfoBlock, write_info_env
from timegap_env.envs.observation import FEATURES, FollowerState, ObservationScales, encode_env
from timegap_env.envs.reward import (
    RewardConstants, RewardTerms, StepReadouts, StepTicks, env_objectives, env_readouts, env_reward_terms,
    env_weighted_sum,
)
from timegap_env.envs.totals import EpisodeTotals, add_step_env
from timegap_env.monitoring.charts import ChartMemory, ChartRule, ChartState, chart_sides_env, count_excursions_env, restart_env
from timegap_env.monitoring.loop import SAME_SETTING, LoopParts, loop_dims
from timegap_env.monitoring.monitor import UPDATE_WORK_ROWS, MonitorTicks, WindowRule, recenter_env, update_env
from timegap_env.monitoring.posterior import Prior
from timegap_env.monitoring.sensors import UNIFORM_STREAMS, Readings, measure_env
from timegap_env.sim.platoon import Controller, LeaderTicks, PlatoonState, PlatoonTicks, advance_env
from timegap_env.state import PerEnv, layout_of


class StepOutputs(NamedTuple):
    """What a step writes for each env besides its scores, and what it carries to the next step."""

    changed: Annotated[np.ndarray, PerEnv(bool, "followers")]  # the step changed the follower's setting
    previous_accel: Annotated[np.ndarray, PerEnv(float, "followers")]  # before the next step's first tick [m/s^2]
    envelope: Annotated[np.ndarray, PerEnv(float, "vehicles")]  # decaying peak |acceleration|, leader first [m/s^2]
    reward: Annotated[np.ndarray, PerEnv(float)]
    cost: Annotated[np.ndarray, PerEnv(float)]  # the step's cost, >= 0
    terminated: Annotated[np.ndarray, PerEnv(bool)]  # a collision ended the episode
    truncated: Annotated[np.ndarray, PerEnv(bool)]  # the episode ran out of time or leader profile
    observation: Annotated[np.ndarray, PerEnv(np.float32, "followers", "features")]


class EnvState(NamedTuple):
    """Every env's state: each component's parts, and what the step scores and writes."""

    loop: LoopParts  # the platoon, its sensors, monitor and chart
    leader: LeaderTrack  # the episode's leader
    readouts: StepReadouts  # of the last step
    totals: EpisodeTotals
    terms: RewardTerms  # the last step's reward terms, each <= 0
    objectives: RewardTerms  # each term's objective in its natural unit
    step: StepOutputs


def env_dims(config: EnvConfig) -> dict[str, int]:
    """The sizes of :class:`EnvState`'s dimensions under ``config``."""
    return {**loop_dims(config.platoon, config.monitor, config.chart), **episode_dims(config), "features": len(FEATURES)}


ENV = layout_of(EnvState)
env_view, env_prefetch = ENV.view, ENV.prefetch  # the kernels fused_step inlines, by global name
TERM_BLOCK, FIRST_TERM = ENV.rows[("terms", RewardTerms._fields[0])]  # the terms: rows FIRST_TERM.. of that block
FIRST_OBJECTIVE = ENV.rows[("objectives", RewardTerms._fields[0])][1]  # the objectives: the same block's rows from
N_TERMS = len(RewardTerms._fields)


class StepScratch(NamedTuple):
    """Where the step puts one env's block of ticks, overwritten env by env, allocated once so that the step
    allocates nothing: the staged path's blocks with one env's column, (n_ticks, 1, n_followers) each, stacked by
    dtype so that the step takes a handful of arrays (each stack's rows in the order noted)."""

    floats: np.ndarray  # (8, n_ticks, 1, n_followers): PlatoonTicks' spacing, speed, accel, applied_setting; Readings'
    #                     spacing, speed; MonitorTicks' tau_mean, tau_var
    flags: np.ndarray  # (5, n_ticks, 1, n_followers) bool: LeaderTicks' v2v, PlatoonTicks' collisions, MonitorTicks'
    #                    used, ChartState's alarm, exceedance
    side: np.ndarray  # (n_ticks, 1, n_followers) int8, ChartState's
    counts: np.ndarray  # (2, n_ticks, 1, n_followers) int64: ChartState's exceedances_in_window, run_length
    leader: np.ndarray  # (2, n_ticks, 1): LeaderTicks' speed [m/s] and acceleration [m/s^2]
    targets: np.ndarray  # (n_followers,) the env's settings from its action [s]
    work: np.ndarray  # (rows, n_ticks * n_followers): measure_env's uniforms, then update_env's scratch

    @classmethod
    def empty(cls, n_ticks: int, n_followers: int) -> StepScratch:
        block = (n_ticks, 1, n_followers)
        return cls(floats=np.empty((8, *block)), flags=np.empty((5, *block), dtype=bool),
                   side=np.empty(block, dtype=np.int8), counts=np.empty((2, *block), dtype=np.int64),
                   leader=np.empty((2, n_ticks, 1)), targets=np.empty(n_followers),
                   work=np.empty((max(UPDATE_WORK_ROWS, UNIFORM_STREAMS), n_ticks * n_followers)))


class StepRules(NamedTuple):
    """The config's constants of a step."""

    ladder: tuple  # LadderRule, the action's (timegap_env.envs.action)
    v2v_enabled: bool  # PlatoonConfig.v2v: False keeps every follower in ACC
    ticks_per_step: int
    settle_ticks: int  # alarms wait this long after a change has ramped in [ticks]
    controller: tuple  # Controller, the platoon's (timegap_env.sim.platoon)
    window: tuple  # WindowRule, the monitor's (timegap_env.monitoring.monitor)
    prior: tuple  # Prior, the monitor's
    chart: tuple  # ChartRule, the chart's (timegap_env.monitoring.charts)
    reward: tuple  # RewardConstants
    weights: np.ndarray  # (n_terms,) the reward weights, REWARD_TERMS order
    scales: tuple  # ObservationScales

    @classmethod
    def from_config(cls, config: EnvConfig, ladder: LadderRule, controller: Controller, window: WindowRule,
                    prior: Prior, chart: ChartRule, reward: tuple, weights: np.ndarray, scales: tuple) -> StepRules:
        """The rules of ``config``; the others are the components' own rules."""
        return cls(
            ladder=tuple(ladder), v2v_enabled=bool(config.platoon.v2v),
            ticks_per_step=int(config.ticks_per_decision), settle_ticks=config.chart.settle_ticks,
            controller=tuple(controller), window=tuple(window), prior=tuple(prior), chart=tuple(chart), reward=reward,
            weights=weights, scales=scales,
        )


@numba.njit(cache=True, error_model="numpy", **NO_ALLOCATION)  # allocates nothing (see timegap_env.compiled)
def fused_step(blocks, scratch, rules, action, info):  # noqa: ANN001, ANN201
    """One decision step of every env: ``action`` (n_envs, 1) ladder indices or relative steps, or (n_envs,
    n_followers) indices per follower, int64, checked by :meth:`~timegap_env.envs.action.SettingLadder.check`
    (numba checks no bounds; a raise here would cost seconds of compilation); ``blocks`` (an :class:`EnvState`'s,
    :attr:`~timegap_env.state.State.blocks`) are updated in place under ``rules`` (:class:`StepRules`), the ticks
    going through ``scratch`` (:class:`StepScratch`); each env's per-step info values go into ``info`` (an
    :class:`~timegap_env.envs.info.InfoBlock` of every env, or of none: n_envs 0)."""
    n_envs = action.shape[0]
    state, rules, scratch = env_view(blocks, n_envs), StepRules(*rules), StepScratch(*scratch)
    platoon, sensors, monitor, chart = state.loop.platoon, state.loop.sensors, state.loop.monitor, state.loop.chart
    kinematics, leader, step, constants = platoon.state, state.leader, state.step, RewardConstants(*rules.reward)
    term_rows = blocks[TERM_BLOCK][FIRST_TERM:FIRST_TERM + N_TERMS, :n_envs]  # (n_terms, n_envs), REWARD_TERMS order
    objective_rows = blocks[TERM_BLOCK][FIRST_OBJECTIVE:FIRST_OBJECTIVE + N_TERMS, :n_envs]
    n_followers = kinematics.setting.shape[1]
    n_ticks = rules.ticks_per_step
    floats, flags, counts = scratch.floats, scratch.flags, scratch.counts
    ticks_leader = LeaderTicks(scratch.leader[0], scratch.leader[1], flags[0])
    physics = PlatoonTicks(floats[0], floats[1], floats[2], floats[3], flags[1])
    measured, estimates = Readings(floats[4], floats[5]), MonitorTicks(flags[2], floats[6], floats[7])
    charted = ChartState(physics.applied_setting, flags[3], scratch.side, flags[4], counts[0], counts[1])
    ticks = StepTicks(estimates.tau_mean, charted.center, physics.applied_setting, charted.alarm, charted.exceedance,
                      physics.collisions, ticks_leader.speed, ticks_leader.accel, physics.speed, physics.spacing,
                      physics.accel)
    memory, moments, faults = chart.memory, monitor.posterior, platoon.faults
    follower = FollowerState(moments.mean_tau, moments.var_tau, chart.center, memory.side, memory.exceedances_in_window,
                             memory.run_length, kinematics.setting, kinematics.v[:, 1:], kinematics.v2v)
    half_width = ObservationScales(*rules.scales).half_width
    last, writes_info = n_ticks - 1, InfoBlock(*info).floats.shape[1] > 0
    for e in range(n_envs):
        env_prefetch(blocks, e + 1)  # the next env's rows come in while this env's stages run
        if e + 1 < n_envs:
            _prefetch_inside(leader, kinematics, memory.starts, chart.tick, monitor.memory.slots, monitor.slot, n_ticks,
                             e + 1)
        _change_settings(kinematics, rules.controller, monitor.memory, monitor.slot, chart, rules, action, step.changed,
                         scratch.targets, e)
        ticks_before = kinematics.ticks[e]
        for k in range(n_ticks):  # the leader at the end of each tick (held after its episode), V2V during it
            tick = ticks_before + k
            sample = min(tick + 1, leader.episode_ticks[e])
            ticks_leader.speed[k, 0], ticks_leader.accel[k, 0] = leader.speed[e, sample], leader.accel[e, sample]
            for f in range(n_followers):
                down = faults.start[e, f] <= tick < faults.end[e, f] and faults.v2v_down[e, f]
                ticks_leader.v2v[k, 0, f] = rules.v2v_enabled and not down
        advance_env(kinematics, ticks_leader, platoon.nominal, rules.controller, faults, physics, e, 0)
        measure_env((physics.spacing, physics.speed), ticks_before, sensors.noise, sensors.faults, measured, e, 0,
                    scratch.work[:UNIFORM_STREAMS])
        update_env(measured.speed, measured.spacing, monitor.memory, monitor.slot, rules.window, rules.prior, estimates,
                   moments, e, 0, scratch.work)
        chart_sides_env(rules.chart, estimates.tau_mean, physics.applied_setting, chart.statistic, charted.side, e, 0)
        count_excursions_env(memory, chart.tick[e], charted, e, 0)
        chart.tick[e] += n_ticks
        env_readouts(ticks, 0, step.previous_accel, step.envelope, constants, state.readouts, e)
        collided = False
        for f in range(n_followers):  # element by element: an array assignment compiles its error messages
            kinematics.v2v[e, f] = ticks_leader.v2v[last, 0, f]
            chart.center[e, f] = physics.applied_setting[last, 0, f]
            step.previous_accel[e, f] = physics.accel[last, 0, f]
            collided = collided or kinematics.collided[e, f]
        env_reward_terms(state.readouts, kinematics.setting, step.changed, constants, state.terms, e)
        env_weighted_sum(term_rows, rules.weights, step.reward, e)
        env_objectives(state.readouts, kinematics.setting, step.changed, state.terms, constants, state.objectives,
                       step.cost, e)
        add_step_env(state.totals, state.readouts, kinematics.setting, step.changed, constants.gap_per_vehicle, e)
        step.terminated[e] = collided
        step.truncated[e] = kinematics.ticks[e] >= leader.episode_ticks[e] and not collided
        encode_env(follower, rules.scales, step.observation, e)
        if writes_info:
            write_info_env(moments.mean_tau, moments.var_tau, kinematics.setting, chart.center, half_width, memory.side,
                           kinematics.v2v, monitor.memory.skipped, term_rows, objective_rows, step.cost, info, e)


@numba.njit(inline="always")
def _prefetch_inside(leader, platoon, starts, chart_tick, slots, slot, n_ticks, e):  # noqa: ANN001, ANN202, PLR0913
    """Hint in env ``e``'s cache lines inside its rows that its step reads or writes, which
    :attr:`~timegap_env.state.Layout.prefetch`'s hints (each row's first line) miss: the leader's samples of the
    step's ticks (``leader``, a :class:`LeaderTrack`), for each vehicle the chart ring's slots of the step's ticks
    (``starts``, what they held a window ago, from chart tick ``chart_tick[e]``), the V2V ring (all of it: a step
    writes nearly every slot; ``platoon`` a :class:`PlatoonState`) and the monitor window's slots from ``slot[e]``
    on (-1: no window). The leader's and the chart's were last read a step or a window ago, out of the caches from a
    few hundred envs on; the rings, a few hundred bytes per env, from a few thousand (a ``perf`` profile showed
    them; ``make bench``'s arithmetic per env-step and its vector env are the measure)."""
    first = min(platoon.ticks[e] + 1, leader.speed.shape[1] - 1)
    end = min(first + n_ticks - 1, leader.speed.shape[1] - 1)
    prefetch_item(leader.speed, (e, first))
    prefetch_item(leader.speed, (e, end))
    prefetch_item(leader.accel, (e, first))
    prefetch_item(leader.accel, (e, end))
    ring_length = starts.shape[2]
    first_slot, last_slot = chart_tick[e] % ring_length, (chart_tick[e] + n_ticks - 1) % ring_length
    for i in range(starts.shape[1]):
        prefetch_item(starts, (e, i, first_slot))
        prefetch_item(starts, (e, i, last_slot))
    for row in range(platoon.predecessor_accel.shape[1]):
        prefetch_item(platoon.predecessor_accel, (e, row))
    if slot[e] < 0:
        return
    last_row = slots.shape[2] - 1
    for i in range(slots.shape[1]):
        for row in range(slot[e], min(slot[e] + n_ticks + 1, last_row) + 1):
            prefetch_item(slots, (e, i, row))


@numba.njit(**STAGE_KERNEL)
def _change_settings(platoon, controller, memory, slot, chart, rules, action, changed, targets, e):  # noqa: ANN001, ANN202, PLR0913
    """Env ``e``'s new settings from its action (:func:`~timegap_env.envs.action.ladder_env`, into ``targets``
    (n_followers,)); a follower whose setting changes (``changed``) ramps to it, its prior and chart are re-centred
    (the window's data and the chart's history cleared) and its alarms held off while it ramps and settles (see
    :meth:`~timegap_env.monitoring.loop.MonitoredPlatoon.change_setting`). ``platoon`` (:class:`PlatoonState`),
    ``memory`` (:class:`WindowMemory`), ``slot`` (the window's next slots) and ``chart``
    (:class:`~timegap_env.monitoring.charts.ChartParts`) are :class:`EnvState`'s, ``controller`` the rules'."""
    platoon, controller = PlatoonState(*platoon), Controller(*controller)
    chart_memory, center, statistic, chart_tick = chart
    ladder_env(rules.ladder, action, platoon.setting, e, targets)
    for f in range(targets.shape[0]):
        setting = targets[f]
        changed[e, f] = not abs(setting - platoon.setting[e, f]) <= SAME_SETTING
        if not changed[e, f]:
            continue
        platoon.setting[e, f] = setting
        recenter_env(memory, slot, setting, e, f)
        applied = platoon.applied_setting[e, f]
        restart_env(rules.chart, chart_memory, center, statistic, chart_tick[e], applied, e, f)
        ramp_ticks = math.ceil(abs(setting - applied) / controller.max_setting_change)
        ChartMemory(*chart_memory).hold_off[e, f] = int(ramp_ticks + rules.settle_ticks)


follow_sources(tuple(f"timegap_env.{module}" for module in (  # every kernel the step runs, and the step
    "compiled", "state", "config", "envs.action", "sim.counter_noise", "sim.platoon", "monitoring.sensors",
    "monitoring.monitor", "monitoring.posterior", "monitoring.charts", "envs.reward", "envs.totals",
    "envs.observation", "envs.info", "envs.episodes", "envs.step_kernel")),
    reached=("timegap_env.monitoring.loop",))  # loop: SAME_SETTING, LoopParts

__all__ = ["ENV", "EnvState", "StepOutputs", "StepRules", "StepScratch", "env_dims", "fused_step"]
