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
rows ahead: :func:`_prefetch`), and re-centres only the followers whose setting changed. The kernel takes two
structures, :class:`StepState` (every array it reads or writes, the objects' own) and :class:`StepRules` (the
config's constants), as plain tuples (see :mod:`timegap_env.sim.platoon`), besides the action and the
:class:`~timegap_env.envs.info.InfoBlock` it writes the infos' values into (a single env's info). numba unpacks
every array handed to it from Python at every call, so the state's structures come in their
:class:`~timegap_env.compiled.Stacked` forms (a few stacks each, about 50 arrays in all rather than about 120) and
are made again inside.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np

from timegap_env.compiled import NO_ALLOCATION, STAGE_KERNEL, follow_sources, prefetch_env, prefetch_item
from timegap_env.config import EnvConfig
from timegap_env.envs.action import LadderRule, ladder_env
from timegap_env.envs.info import InfoBlock, write_info_env
from timegap_env.envs.observation import FollowerState, ObservationScales, encode_env
from timegap_env.envs.reward import (
    READOUT_STACKS, TERM_STACKS, RewardConstants, RewardTerms, StepReadouts, StepTicks, env_objectives, env_readouts,
    env_reward_terms, env_weighted_sum,
)
from timegap_env.envs.totals import TOTAL_STACKS, add_step_env
from timegap_env.monitoring.charts import (
    CHART_MEMORY_STACKS, ChartMemory, ChartRule, ChartState, chart_sides_env, count_excursions_env, restart_env,
)
from timegap_env.monitoring.loop import SAME_SETTING
from timegap_env.monitoring.monitor import (
    UPDATE_WORK_ROWS,
    WINDOW_STACKS,
    MonitorTicks,
    WindowMemory,
    recenter_env,
    update_env,
)
from timegap_env.monitoring.posterior import MOMENT_STACKS, Moments
from timegap_env.monitoring.sensors import SENSOR_FAULT_STACKS, UNIFORM_STREAMS, Readings, measure_env
from timegap_env.sim.platoon import (
    FAULT_STACKS, PLATOON_STACKS, ZOH_STACKS, Controller, LeaderTicks, PlatoonState, PlatoonTicks, advance_env,
)




class StepState(NamedTuple):
    """Every array the step reads or writes, the objects' own (in place); shapes as noted. A structure with a
    ``Stacked`` layout comes in its form (:meth:`~timegap_env.compiled.Stacked.form`)."""

    platoon: tuple  # PlatoonState, PLATOON_STACKS' form
    zoh: tuple  # ZOHCoefficients, nominal, ZOH_STACKS' form
    controller: tuple  # Controller
    faults: tuple  # FollowerFaults, FAULT_STACKS' form
    v2v_down: np.ndarray  # (n_envs, n_followers) the follower's degradation takes V2V down while it acts [bool]
    leader_speed: np.ndarray  # (n_envs, max_ticks + 1) the leader's speed at every tick [m/s]
    leader_accel: np.ndarray  # (n_envs, max_ticks + 1) [m/s^2]
    episode_ticks: np.ndarray  # (n_envs,) ticks in each env's episode
    noise: tuple  # NoiseModel
    sensor_faults: tuple  # SensorFaults, SENSOR_FAULT_STACKS' form
    monitor: tuple  # (WindowMemory, slot, WindowRule, Prior, Moments) of TimeGapMonitor.kernel_args, the memory in
    #                 WINDOW_STACKS' form, the moments in MOMENT_STACKS'
    chart: tuple  # (ChartMemory, center, statistic, tick) of ControlChart.kernel_args, the memory in
    #               CHART_MEMORY_STACKS' form
    readouts: tuple  # StepReadouts of the last step, READOUT_STACKS' form
    previous_accel: np.ndarray  # (n_envs, n_followers) acceleration before the step's first tick [m/s^2]
    envelope: np.ndarray  # (n_envs, 1 + n_followers) acceleration envelopes, the leader first [m/s^2]
    totals: tuple  # EpisodeTotals, TOTAL_STACKS' form
    changed: np.ndarray  # (n_envs, n_followers) the step changed the follower's setting [bool]
    terms: tuple  # RewardTerms in TERM_STACKS' form: (term_rows,), the terms (n_terms, n_envs) in REWARD_TERMS order
    reward: np.ndarray  # (n_envs,)
    objectives: tuple  # RewardTerms, each term's objective in its natural unit, TERM_STACKS' form
    cost: np.ndarray  # (n_envs,) the step's cost, >= 0
    terminated: np.ndarray  # (n_envs,) a collision ended the episode [bool]
    truncated: np.ndarray  # (n_envs,) the episode ran out of time or leader profile [bool]
    observation: np.ndarray  # (n_envs, n_followers, n_features) float32
    scratch: tuple  # StepScratch


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
    chart: tuple  # ChartRule, the chart's (timegap_env.monitoring.charts)
    reward: tuple  # RewardConstants
    weights: np.ndarray  # (n_terms,) the reward weights, REWARD_TERMS order
    scales: tuple  # ObservationScales

    @classmethod
    def from_config(cls, config: EnvConfig, ladder: LadderRule, chart: ChartRule, reward: tuple, weights: np.ndarray,
                    scales: tuple) -> StepRules:
        """The rules of ``config``; ``ladder`` and ``chart`` are the action's and the chart's own rules."""
        return cls(
            ladder=tuple(ladder), v2v_enabled=bool(config.platoon.v2v),
            ticks_per_step=int(config.ticks_per_decision), settle_ticks=config.chart.settle_ticks,
            chart=tuple(chart), reward=reward, weights=weights, scales=scales,
        )


@numba.njit(cache=True, error_model="numpy", **NO_ALLOCATION)  # allocates nothing (see timegap_env.compiled)
def fused_step(state, rules, action, info):  # noqa: ANN001, ANN201
    """One decision step of every env: ``action`` (n_envs, 1) ladder indices or relative steps, or (n_envs,
    n_followers) indices per follower, int64, checked by :meth:`~timegap_env.envs.action.SettingLadder.check`
    (numba checks no bounds; a raise here would cost seconds of compilation); ``state`` (:class:`StepState`) is
    updated in place under ``rules`` (:class:`StepRules`); each env's per-step info values go into ``info`` (an
    :class:`~timegap_env.envs.info.InfoBlock` of every env, or of none: n_envs 0)."""
    state, rules = StepState(*state), StepRules(*rules)
    platoon_args, zoh, faults = unstack_platoon(state.platoon), unstack_zoh(state.zoh), unstack_faults(state.faults)
    sensor_faults, readout_args = unstack_sensor_faults(state.sensor_faults), unstack_readouts(state.readouts)
    window_form, slot, rule, prior, moment_form = state.monitor
    memory, posterior = unstack_window(window_form), unstack_moments(moment_form)
    chart_form, center, statistic, chart_tick = state.chart
    chart_memory = unstack_chart_memory(chart_form)
    chart_args = (chart_memory, center, statistic, chart_tick)
    platoon = PlatoonState(*platoon_args)
    n_envs, n_followers = platoon.setting.shape
    n_ticks = rules.ticks_per_step
    scratch = StepScratch(*state.scratch)
    floats, flags, counts = scratch.floats, scratch.flags, scratch.counts
    leader = LeaderTicks(scratch.leader[0], scratch.leader[1], flags[0])
    physics = PlatoonTicks(floats[0], floats[1], floats[2], floats[3], flags[1])
    measured, estimates = Readings(floats[4], floats[5]), MonitorTicks(flags[2], floats[6], floats[7])
    charted = ChartState(physics.applied_setting, flags[3], scratch.side, flags[4], counts[0], counts[1])
    ticks = StepTicks(estimates.tau_mean, charted.center, physics.applied_setting, charted.alarm, charted.exceedance,
                      physics.collisions, leader.speed, leader.accel, physics.speed, physics.spacing, physics.accel)
    chart, moments = ChartMemory(*chart_memory), Moments(*posterior)
    follower = FollowerState(moments.mean_tau, moments.var_tau, center, chart.side, chart.exceedances_in_window,
                             chart.run_length, platoon.setting, platoon.v[:, 1:], platoon.v2v)
    terms, objectives = RewardTerms(*unstack_terms(state.terms)), RewardTerms(*unstack_terms(state.objectives))
    readouts, totals = StepReadouts(*readout_args), unstack_totals(state.totals)
    constants = RewardConstants(*rules.reward)
    faults_start, faults_end = faults[0], faults[1]
    window, half_width = WindowMemory(*memory), ObservationScales(*rules.scales).half_width
    last, writes_info = n_ticks - 1, InfoBlock(*info).floats.shape[1] > 0
    ring_length = chart.starts.shape[2]  # the chart ring's slots this step writes, the same in every env
    first_slot, last_slot = chart_tick[0] % ring_length, (chart_tick[0] + last) % ring_length
    for e in range(n_envs):
        _prefetch(state, e + 1)  # the next env's rows come in while this env's stages run
        if e + 1 < n_envs:
            _prefetch_inside(state.leader_speed, state.leader_accel, platoon, chart.starts, first_slot, last_slot,
                             window.slots, slot, n_ticks, e + 1)
        _change_settings(platoon_args, state.controller, memory, slot, chart_args, rules, action, state.changed,
                         scratch.targets, e)
        ticks_before = platoon.ticks[e]
        for k in range(n_ticks):  # the leader at the end of each tick (held after its episode), V2V during it
            tick = ticks_before + k
            sample = min(tick + 1, state.episode_ticks[e])
            leader.speed[k, 0], leader.accel[k, 0] = state.leader_speed[e, sample], state.leader_accel[e, sample]
            for f in range(n_followers):
                down = faults_start[e, f] <= tick < faults_end[e, f] and state.v2v_down[e, f]
                leader.v2v[k, 0, f] = rules.v2v_enabled and not down
        advance_env(platoon_args, leader, zoh, state.controller, faults, physics, e, 0)
        measure_env((physics.spacing, physics.speed), ticks_before, state.noise, sensor_faults, measured, e, 0,
                    scratch.work[:UNIFORM_STREAMS])
        update_env(measured.speed, measured.spacing, memory, slot, rule, prior, estimates, posterior, e, 0,
                   scratch.work)
        chart_sides_env(rules.chart, estimates.tau_mean, physics.applied_setting, statistic, charted.side, e, 0)
        count_excursions_env(chart_memory, chart_tick[0], charted, e, 0)
        env_readouts(ticks, 0, state.previous_accel, state.envelope, constants, readouts, e)
        collided = False
        for f in range(n_followers):  # element by element: an array assignment compiles its error messages
            platoon.v2v[e, f] = leader.v2v[last, 0, f]
            center[e, f] = physics.applied_setting[last, 0, f]
            state.previous_accel[e, f] = physics.accel[last, 0, f]
            collided = collided or platoon.collided[e, f]
        env_reward_terms(readouts, platoon.setting, state.changed, constants, terms, e)
        env_weighted_sum(state.terms[0], rules.weights, state.reward, e)
        env_objectives(readouts, platoon.setting, state.changed, terms, constants, objectives, state.cost, e)
        add_step_env(totals, readout_args, platoon.setting, state.changed, constants.gap_per_vehicle, e)
        state.terminated[e] = collided
        state.truncated[e] = platoon.ticks[e] >= state.episode_ticks[e] and not collided
        encode_env(follower, rules.scales, state.observation, e)
        if writes_info:
            write_info_env(moments.mean_tau, moments.var_tau, platoon.setting, center, half_width, chart.side,
                           platoon.v2v, window.skipped, state.terms[0], state.objectives[0], state.cost, info, e)
    chart_tick[0] += n_ticks


@numba.njit(inline="always")
def _prefetch(state, e):  # noqa: ANN001, ANN202
    """Hint env ``e``'s first cache line of every array of ``state`` (a :class:`StepState`) in
    (:func:`~timegap_env.compiled.prefetch_env`; past the last env, a hint that does nothing). From a few thousand
    envs on a step's arrays no longer stay in cache, and each env's rows lie in ~50 of them, more streams than the
    CPU's own prefetcher follows: asked for one env ahead, they arrive while that env's stages run (``make bench``'s
    vector env at large sizes; the commit that added the hints gives the A/B)."""
    prefetch_platoon(state.platoon, e)
    prefetch_zoh(state.zoh, e)
    prefetch_faults(state.faults, e)
    prefetch_env(state.v2v_down, e)
    prefetch_env(state.episode_ticks, e)
    prefetch_env(state.noise[0], e)
    prefetch_env(state.noise[1], e)
    prefetch_sensor_faults(state.sensor_faults, e)
    window_form, slot, _, _, moment_form = state.monitor
    prefetch_window(window_form, e)
    prefetch_env(slot, e)
    prefetch_moments(moment_form, e)
    chart_form, center, statistic, _ = state.chart
    prefetch_chart_memory(chart_form, e)
    prefetch_env(center, e)
    prefetch_env(statistic, e)
    prefetch_readouts(state.readouts, e)
    prefetch_env(state.previous_accel, e)
    prefetch_env(state.envelope, e)
    prefetch_totals(state.totals, e)
    prefetch_env(state.changed, e)
    prefetch_terms(state.terms, e)
    prefetch_env(state.reward, e)
    prefetch_terms(state.objectives, e)
    prefetch_env(state.cost, e)
    prefetch_env(state.terminated, e)
    prefetch_env(state.truncated, e)
    prefetch_env(state.observation, e)


@numba.njit(inline="always")
def _prefetch_inside(leader_speed, leader_accel, platoon, starts, first_slot, last_slot, slots, slot, n_ticks, e):  # noqa: ANN001, ANN202, PLR0913
    """Hint in env ``e``'s cache lines inside its rows that its step reads or writes, which :func:`_prefetch`'s
    hints (each row's first line) miss: the leader's samples of the step's ticks, for each vehicle the chart ring's
    slots ``first_slot`` to ``last_slot`` (``starts``, what they held a window ago), the V2V ring (all of it: a step
    writes nearly every slot; ``platoon`` a :class:`PlatoonState`) and the monitor window's slots from ``slot[e]``
    on (-1: no window). The leader's and the chart's were last read a step or a window ago, out of the caches from a
    few hundred envs on; the rings, a few hundred bytes per env, from a few thousand (a ``perf`` profile showed
    them; ``make bench``'s arithmetic per env-step and its vector env are the measure)."""
    first = min(platoon.ticks[e] + 1, leader_speed.shape[1] - 1)
    end = min(first + n_ticks - 1, leader_speed.shape[1] - 1)
    prefetch_item(leader_speed, (e, first))
    prefetch_item(leader_speed, (e, end))
    prefetch_item(leader_accel, (e, first))
    prefetch_item(leader_accel, (e, end))
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
    :meth:`~timegap_env.monitoring.loop.MonitoredPlatoon.change_setting`). ``platoon``, ``controller``, ``memory``
    (:class:`WindowMemory`), ``slot`` (the window's next slots) and ``chart`` are :class:`StepState`'s."""
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
        restart_env(rules.chart, chart_memory, center, statistic, chart_tick[0], applied, e, f)
        ramp_ticks = math.ceil(abs(setting - applied) / controller.max_setting_change)
        ChartMemory(*chart_memory).hold_off[e, f] = int(ramp_ticks + rules.settle_ticks)


unstack_platoon, unstack_zoh, unstack_faults = PLATOON_STACKS.unstack, ZOH_STACKS.unstack, FAULT_STACKS.unstack
unstack_sensor_faults, unstack_window = SENSOR_FAULT_STACKS.unstack, WINDOW_STACKS.unstack
unstack_moments, unstack_chart_memory = MOMENT_STACKS.unstack, CHART_MEMORY_STACKS.unstack
unstack_readouts, unstack_totals, unstack_terms = READOUT_STACKS.unstack, TOTAL_STACKS.unstack, TERM_STACKS.unstack
prefetch_platoon, prefetch_zoh, prefetch_faults = PLATOON_STACKS.prefetch, ZOH_STACKS.prefetch, FAULT_STACKS.prefetch
prefetch_sensor_faults, prefetch_window = SENSOR_FAULT_STACKS.prefetch, WINDOW_STACKS.prefetch
prefetch_moments, prefetch_chart_memory = MOMENT_STACKS.prefetch, CHART_MEMORY_STACKS.prefetch
prefetch_readouts, prefetch_totals = READOUT_STACKS.prefetch, TOTAL_STACKS.prefetch
prefetch_terms = TERM_STACKS.prefetch
follow_sources(tuple(f"timegap_env.{module}" for module in (  # every kernel the step runs, and the step
    "compiled", "config", "envs.action", "sim.counter_noise", "sim.platoon", "monitoring.sensors", "monitoring.monitor",
    "monitoring.posterior", "monitoring.charts", "envs.reward", "envs.totals", "envs.observation", "envs.info",
    "envs.step_kernel")), reached=("timegap_env.monitoring.loop",))  # loop: SAME_SETTING

__all__ = ["StepRules", "StepScratch", "StepState", "fused_step"]
