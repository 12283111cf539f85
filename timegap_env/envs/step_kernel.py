"""The env step, one compiled call: action -> settings -> physics -> sensors -> monitor -> chart -> reward ->
observation, env by env, over state that lives in preallocated arrays.

:func:`fused_step` is the step, read top to bottom: for each env in turn, :func:`_prepare_env` turns the action
into settings (:func:`~timegap_env.envs.action.ladder_env`; a changed setting ramps in the physics and re-centres
that follower's prior and chart, :func:`~timegap_env.monitoring.loop.change_settings_env`) and lays out the
leader's and V2V's ticks; ``advance_env`` runs the physics; :func:`_finish_env` runs the ticks through the
sensors, the monitor and the chart, scores the step, adds it to the episode totals, sets the flags and writes
the observation, the info's values and, when a trace is recorded, env 0's estimate and centre line. Each stage
is a per-env kernel owned by its component, the one the component's own methods run over every env, so the
arithmetic has one source and the glue is written here only. Another simulator's physics (SUMO's, in Python)
runs between :func:`prepare_step` and :func:`finish_step`, the same two halves. The tests hold the step to the
components' methods composed stage by stage (``tests/envs/reference.py``), bit for bit.

Working env by env keeps each env's state in cache while all its stages run (the step asks for the next env's
rows ahead: :attr:`~timegap_env.state.Layout.prefetch`, and :func:`_prefetch_inside` for the places inside rows
that move from step to step), and re-centres only the followers whose setting changed. Every env's state is
:class:`EnvState`, one allocation (:mod:`timegap_env.state`) whose components each declare their own fields;
the kernel is handed its few blocks and makes the named views inside (``env_view``), besides the scratch its
ticks go through (:class:`StepScratch`), the config's constants (:class:`EnvParams`), the action and the
:class:`~timegap_env.envs.info.InfoBlock` it writes the infos' values into (a single env's info).
"""

from __future__ import annotations

from typing import Annotated, NamedTuple

import numba
import numpy as np

from timegap_env.compiled import NO_ALLOCATION, follow_sources, prefetch_item
from timegap_env.config import EnvConfig
from timegap_env.envs.action import LadderRule, ladder_env
from timegap_env.envs.episodes import LeaderTrack, episode_dims
from timegap_env.envs.info import InfoBlock, write_info_env
from timegap_env.envs.observation import FEATURES, FollowerState, ObservationScales, encode_env
from timegap_env.envs.reward import (
    RewardConstants, RewardTerms, StepReadouts, StepTicks, env_objectives, env_readouts, env_reward_terms,
    env_weighted_sum, weights_of,
)
from timegap_env.envs.totals import EpisodeTotals, add_step_env
from timegap_env.monitoring.charts import ChartRule, ChartState, chart_sides_env, count_excursions_env
from timegap_env.monitoring.loop import LoopParts, change_settings_env, loop_dims
from timegap_env.monitoring.monitor import UPDATE_WORK_ROWS, MonitorTicks, WindowRule, monitor_prior, update_env
from timegap_env.monitoring.posterior import Prior
from timegap_env.monitoring.sensors import UNIFORM_STREAMS, Readings, measure_env
from timegap_env.sim.platoon import Controller, LeaderTicks, PlatoonTicks, advance_env
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
    allocates nothing: the components' blocks of ticks with one env's column, (n_ticks, 1, n_followers) each,
    stacked by dtype so that the step takes a handful of arrays (each stack's rows in the order noted)."""

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


class EnvParams(NamedTuple):
    """Every constant of a step, made from the config once (gymnax's ``EnvParams``): each component's section, the
    record its kernels take (and its own methods, when it runs alone), and the step's own."""

    ladder: LadderRule  # the action's (timegap_env.envs.action)
    controller: Controller  # the platoon's (timegap_env.sim.platoon)
    window: WindowRule  # the monitor's (timegap_env.monitoring.monitor)
    prior: Prior  # the monitor's
    chart: ChartRule  # the chart's (timegap_env.monitoring.charts)
    reward: RewardConstants  # the scores' (timegap_env.envs.reward)
    weights: np.ndarray  # (n_terms,) the reward weights, REWARD_TERMS order
    scales: ObservationScales  # the observation's (timegap_env.envs.observation)
    v2v_enabled: bool  # PlatoonConfig.v2v: False keeps every follower in ACC
    ticks_per_step: int
    settle_ticks: int  # alarms wait this long after a change has ramped in [ticks]

    @classmethod
    def from_config(cls, config: EnvConfig) -> EnvParams:
        return cls(
            ladder=LadderRule.from_config(config), controller=Controller.from_config(config.platoon),
            window=WindowRule.from_config(config.monitor), prior=monitor_prior(config.monitor),
            chart=ChartRule.from_config(config.chart, config.chart.kind), reward=RewardConstants.from_config(config),
            weights=np.array(weights_of(config)), scales=ObservationScales.from_config(config),
            v2v_enabled=bool(config.platoon.v2v), ticks_per_step=int(config.ticks_per_decision),
            settle_ticks=config.chart.settle_ticks,
        )


@numba.njit(cache=True, error_model="numpy", **NO_ALLOCATION)  # allocates nothing (see timegap_env.compiled)
def fused_step(blocks, scratch, params, action, info, trace):  # noqa: ANN001, ANN201
    """One decision step of every env: ``action`` (n_envs, 1) ladder indices or relative steps, or (n_envs,
    n_followers) indices per follower, int64, checked by :meth:`~timegap_env.envs.action.SettingLadder.check`
    (numba checks no bounds; a raise here would cost seconds of compilation); ``blocks`` (an :class:`EnvState`'s,
    :attr:`~timegap_env.state.State.blocks`) are updated in place under ``params`` (:class:`EnvParams`), the ticks
    going through ``scratch`` (:class:`StepScratch`); each env's per-step info values go into ``info`` (an
    :class:`~timegap_env.envs.info.InfoBlock` of every env, or of none: n_envs 0), and env 0's estimate and centre
    line at each tick into ``trace`` (n_ticks, 2, n_followers), unless it has no ticks."""
    n_envs = action.shape[0]
    state = env_view(blocks, n_envs)
    platoon, monitor, chart = state.loop.platoon, state.loop.monitor, state.loop.chart
    for e in range(n_envs):
        env_prefetch(blocks, e + 1)  # the next env's rows come in while this env's stages run
        if e + 1 < n_envs:
            _prefetch_inside(state.leader, platoon.state, chart.memory.starts, chart.tick, monitor.memory.slots,
                             monitor.slot, params.ticks_per_step, e + 1)
        leader, physics = _prepare_env(state, params, scratch, action, e)
        advance_env(platoon.state, leader, platoon.nominal, params.controller, platoon.faults, physics, e, 0)
        _finish_env(blocks, state, params, scratch, info, trace, e)


@numba.njit(cache=True, error_model="numpy", **NO_ALLOCATION)
def prepare_step(blocks, scratch, params, action):  # noqa: ANN001, ANN201
    """The part of :func:`fused_step` before the physics, for a simulator whose ticks run outside (SUMO's, one env):
    the settings, and the leader's and V2V's ticks in ``scratch`` (:class:`StepScratch`: ``leader`` and the first
    row of ``flags``). The simulator then writes the platoon's state and its ticks' records (``floats`` 0-3, the
    second row of ``flags``), and :func:`finish_step` goes on."""
    n_envs = action.shape[0]
    state = env_view(blocks, n_envs)
    for e in range(n_envs):
        _prepare_env(state, params, scratch, action, e)


@numba.njit(cache=True, error_model="numpy", **NO_ALLOCATION)
def finish_step(blocks, scratch, params, n_envs, info, trace):  # noqa: ANN001, ANN201, PLR0913
    """The part of :func:`fused_step` after the physics for ``n_envs`` envs (see :func:`prepare_step`)."""
    state = env_view(blocks, n_envs)
    for e in range(n_envs):
        _finish_env(blocks, state, params, scratch, info, trace, e)


@numba.njit(inline="always")
def _prepare_env(state, params, scratch, action, e):  # noqa: ANN001, ANN202, PLR0913
    """Env ``e``'s settings from its action (:func:`~timegap_env.envs.action.ladder_env`,
    :func:`~timegap_env.monitoring.loop.change_settings_env`), and the leader at the end of each tick of the
    step (held after its episode) and each follower's V2V during it, into ``scratch``; returns the
    :class:`LeaderTicks` and the :class:`PlatoonTicks` the physics fills, views of the scratch."""
    platoon, leader, scratch = state.loop.platoon, state.leader, StepScratch(*scratch)
    kinematics, faults, flags = platoon.state, platoon.faults, scratch.flags
    ladder_env(params.ladder, action, kinematics.setting, e, scratch.targets)  # the action's settings
    change_settings_env(kinematics, params.controller, state.loop.monitor.memory, state.loop.monitor.slot,
                        state.loop.chart, params.chart, params.settle_ticks, scratch.targets, state.step.changed, e)
    ticks = LeaderTicks(scratch.leader[0], scratch.leader[1], flags[0])
    for k in range(params.ticks_per_step):
        tick = kinematics.ticks[e] + k
        sample = min(tick + 1, leader.episode_ticks[e])
        ticks.speed[k, 0], ticks.accel[k, 0] = leader.speed[e, sample], leader.accel[e, sample]
        for f in range(kinematics.setting.shape[1]):
            down = faults.start[e, f] <= tick < faults.end[e, f] and faults.v2v_down[e, f]
            ticks.v2v[k, 0, f] = params.v2v_enabled and not down
    floats = scratch.floats
    return ticks, PlatoonTicks(floats[0], floats[1], floats[2], floats[3], flags[1])


@numba.njit(inline="always")
def _finish_env(blocks, state, params, scratch, info, trace, e):  # noqa: ANN001, ANN202, PLR0913
    """Env ``e``'s ticks, their physics done, through the sensors, the monitor and the chart; the step's scores, the
    episode's totals, the flags, the observation and the info's values (and env 0's trace)."""
    scratch, constants = StepScratch(*scratch), params.reward
    sensors, monitor, chart = state.loop.sensors, state.loop.monitor, state.loop.chart
    kinematics, step, memory, moments = state.loop.platoon.state, state.step, chart.memory, monitor.posterior
    n_envs, n_followers, n_ticks = step.reward.shape[0], kinematics.setting.shape[1], params.ticks_per_step
    term_rows = blocks[TERM_BLOCK][FIRST_TERM:FIRST_TERM + N_TERMS, :n_envs]  # (n_terms, n_envs), REWARD_TERMS order
    objective_rows = blocks[TERM_BLOCK][FIRST_OBJECTIVE:FIRST_OBJECTIVE + N_TERMS, :n_envs]
    floats, flags, counts, last = scratch.floats, scratch.flags, scratch.counts, n_ticks - 1
    leader = LeaderTicks(scratch.leader[0], scratch.leader[1], flags[0])
    physics = PlatoonTicks(floats[0], floats[1], floats[2], floats[3], flags[1])
    measured, estimates = Readings(floats[4], floats[5]), MonitorTicks(flags[2], floats[6], floats[7])
    charted = ChartState(physics.applied_setting, flags[3], scratch.side, flags[4], counts[0], counts[1])
    ticks = StepTicks(estimates.tau_mean, charted.center, physics.applied_setting, charted.alarm, charted.exceedance,
                      physics.collisions, leader.speed, leader.accel, physics.speed, physics.spacing, physics.accel)
    ticks_before = kinematics.ticks[e] - n_ticks  # the physics counted the step's ticks
    measure_env((physics.spacing, physics.speed), ticks_before, sensors.noise, sensors.faults, measured, e, 0,
                scratch.work[:UNIFORM_STREAMS])
    update_env(measured.speed, measured.spacing, monitor.memory, monitor.slot, params.window, params.prior, estimates,
               moments, e, 0, scratch.work)
    chart_sides_env(params.chart, estimates.tau_mean, physics.applied_setting, chart.statistic, charted.side, e, 0)
    count_excursions_env(memory, chart.tick[e], charted, e, 0)
    chart.tick[e] += n_ticks
    env_readouts(ticks, 0, step.previous_accel, step.envelope, constants, state.readouts, e)
    collided = False
    for f in range(n_followers):  # element by element: an array assignment compiles its error messages
        kinematics.v2v[e, f] = leader.v2v[last, 0, f]
        chart.center[e, f] = physics.applied_setting[last, 0, f]
        step.previous_accel[e, f] = physics.accel[last, 0, f]
        collided = collided or kinematics.collided[e, f]
    env_reward_terms(state.readouts, kinematics.setting, step.changed, constants, state.terms, e)
    env_weighted_sum(term_rows, params.weights, step.reward, e)
    env_objectives(state.readouts, kinematics.setting, step.changed, term_rows, constants, state.objectives,
                   step.cost, e)
    add_step_env(state.totals, state.readouts, kinematics.setting, step.changed, constants.gap_per_vehicle, e)
    step.terminated[e] = collided
    step.truncated[e] = kinematics.ticks[e] >= state.leader.episode_ticks[e] and not collided
    follower = FollowerState(moments.mean_tau, moments.var_tau, chart.center, memory.side, memory.exceedances_in_window,
                             memory.run_length, kinematics.setting, kinematics.v[:, 1:], kinematics.v2v)
    encode_env(follower, params.scales, step.observation, e)
    if InfoBlock(*info).floats.shape[1] > 0:
        write_info_env(moments.mean_tau, moments.var_tau, kinematics.setting, chart.center,
                       params.scales.half_width, memory.side, kinematics.v2v, monitor.memory.skipped,
                       term_rows, objective_rows, step.cost, info, e)
    if e == 0 and trace.shape[0] > 0:  # the trace hook: env 0's estimate and centre line at each tick
        for k in range(n_ticks):
            for f in range(n_followers):
                trace[k, 0, f], trace[k, 1, f] = estimates.tau_mean[k, 0, f], charted.center[k, 0, f]


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


follow_sources(__name__)

__all__ = ["ENV", "EnvParams", "EnvState", "StepOutputs", "StepScratch", "env_dims", "finish_step", "fused_step",
           "prepare_step"]
