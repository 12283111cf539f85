"""The reward of ``TimeGapMonitor-v0``: named terms, each <= 0, weighted and summed.

The reward judges what happened to the cars, the true state of the simulator, never the monitor:
the monitor is the agent's view, not its judge (a term on the monitor's estimate could be gamed by
a policy that keeps the estimate quiet while the cars drift).

A step is scored in three steps, each a compiled function over named structures:

1. :func:`step_readouts`: what the step's ticks come down to: per follower the smallest
   time-to-collision, the summed squared jerk and the final speed; per env the growth of the
   acceleration envelopes down the platoon (the envelopes are carried from step to step), the
   summed deviation of the actual time gap from the applied setting, whether a gap reached 0,
   and the monitor's diagnostics (its deviation from the chart's centre line, alarm ticks,
   excursion starts), which the episode totals of :mod:`~timegap_env.envs.totals` report and the
   reward does not use;
2. :func:`reward_terms`: the terms below, per env, from the read-outs;
3. :func:`weighted_sum`: the reward, the terms weighted by :class:`~timegap_env.config.RewardWeights`
   and added in the order of its fields.

:func:`score_step` runs the three in one compiled call, the env's hot path.

The terms are the records of :data:`timegap_env.config.REWARD_TERM_RECORDS`, in the order they are summed: each
its name, default weight (a field of :class:`~timegap_env.config.RewardWeights`), scales (fields of
:class:`~timegap_env.config.RewardScales`, named in the formulas), lowest value, objective, whether it counts in
the cost, and its value and why, which the table at the end of this docstring shows (made of the records at import:
``help(timegap_env.envs.reward)``). A term's value is a mean over followers; the applied setting is the tau* the
controller uses (it ramps after a change of setting), s0 the platoon's. :func:`env_reward_terms` computes the terms,
:func:`env_objectives` their objectives.

Each term is at most a few units per step over 250 steps, so with the default weights a collision
(1000) costs more than any whole episode of everything else: no efficiency gain pays for one, and
ending an episode early never pays. Efficiency and preference pull in opposite directions, so
neither the smallest nor the largest setting wins; tracking and string stability penalise a
setting too small for the cars' true condition (a degraded car keeps its setting badly and
amplifies disturbances); switching and comfort keep the policy from chattering.
"""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING, Annotated, Any, NamedTuple, Self

import numba
import numpy as np

from timegap_env.compiled import STAGE_KERNEL, follow_sources
from timegap_env.config import (
    REWARD_SCALE_RECORDS,
    REWARD_TERM_RECORDS,
    TIME_GAP_MIN_SPEED,
    EnvConfig,
    Objective,
    RewardWeights,
)
from timegap_env.state import PerEnv, State

if TYPE_CHECKING:  # mypy cannot see fields computed at import: a tuple of one term per field, read by name

    class RewardTerms(tuple[Any, ...]):
        _fields: tuple[str, ...]

        def __new__(cls, *terms: Any) -> RewardTerms: ...

        def __getattr__(self, name: str) -> Any: ...

else:  # a float per env each, in a state
    RewardTerms = NamedTuple("RewardTerms", [(field.name, Annotated[np.ndarray, PerEnv(float)])
                                             for field in dataclasses.fields(RewardWeights)])
RewardTerms.__doc__ = """The reward terms, one field per field of RewardWeights: (n_envs,) arrays, or the weights themselves."""
REWARD_TERMS: tuple[str, ...] = RewardTerms._fields
__doc__ = (__doc__ or "") + "\n".join(["\n| term | value | why |", "|---|---|---|", *(
    f"| ``{term.name}`` | {term.value} | {term.why} |" for term in REWARD_TERM_RECORDS.values())]) + "\n"


class StepTicks(NamedTuple):
    """A step's ticks, arrays (n_ticks, n_envs, n_followers) unless noted."""

    tau_mean: np.ndarray  # posterior mean of tau [s]
    center: np.ndarray  # the chart's centre line [s]
    applied_setting: np.ndarray  # the tau* the controller applied during the tick [s]
    alarm: np.ndarray  # the chart is in alarm [bool]
    exceedance: np.ndarray  # an excursion started [bool]
    collisions: np.ndarray  # the gap reached 0 [bool]
    leader_speed: np.ndarray  # (n_ticks, n_envs) [m/s]
    leader_accel: np.ndarray  # (n_ticks, n_envs) [m/s^2]
    speed: np.ndarray  # [m/s]
    spacing: np.ndarray  # bumper-to-bumper gap to the predecessor [m]
    accel: np.ndarray  # [m/s^2]


class StepReadouts(NamedTuple):
    """What a step's ticks come down to, per follower or per env; before any step: an infinite TTC, no jerk."""

    # smallest time-to-collision, inf if never closing in [s]
    min_ttc: Annotated[np.ndarray, PerEnv(float, "followers", fill=np.inf)]
    jerk_squared: Annotated[np.ndarray, PerEnv(float, "followers")]  # sum over the ticks of jerk^2 [m^2/s^6]
    final_speed: Annotated[np.ndarray, PerEnv(float, "followers")]  # speed at the step's last tick [m/s]
    accel_growth: Annotated[np.ndarray, PerEnv(float)]  # sum over vehicles of the envelope's rise over its predecessor's [m/s^2]
    gap_deviation_sum: Annotated[np.ndarray, PerEnv(float)]  # sum over follower-ticks of the tracking term's capped deviation [s]
    deviation_sum: Annotated[np.ndarray, PerEnv(float)]  # sum over follower-ticks of abs(estimate - centre line) [s]
    max_deviation: Annotated[np.ndarray, PerEnv(float)]  # largest abs(estimate - centre line) [s]
    alarm_ticks: Annotated[np.ndarray, PerEnv(float)]  # follower-ticks in alarm [-]
    exceedances: Annotated[np.ndarray, PerEnv(float)]  # excursion starts [-]
    collided: Annotated[np.ndarray, PerEnv(bool)]  # a gap reached 0

    @classmethod
    def empty(cls, n_envs: int, n_followers: int) -> StepReadouts:
        """The read-outs of no step of ``n_envs`` envs of ``n_followers`` followers, in a state of their own."""
        return State(cls, {"followers": n_followers}, n_envs).views


_CONFIG_CONSTANTS: tuple[tuple[str, type], ...] = (  # RewardConstants' fields before the scales: (name, type)
    ("dt", float),  # tick [s]
    ("ticks_per_step", int),  # ticks in a step [-]
    ("smallest_level", float),  # [s]
    ("level_span", float),  # largest level - smallest level [s]
    ("preferred_setting", float),  # [s]
    ("gap_per_vehicle", float),  # standstill spacing + vehicle length [m]
    ("standstill_spacing", float),  # s0 [m]
    ("min_speed", float),  # below it the actual time gap is not tracked [m/s]
    ("envelope_decay", float),  # an acceleration envelope's decay per tick, exp(-dt / accel_envelope_time) [-]
)
if TYPE_CHECKING:  # mypy cannot see fields computed at import: a tuple of numbers, read by name

    class _ConstantFields(tuple[Any, ...]):
        _fields: tuple[str, ...]

        def __new__(cls, *values: Any, **by_name: Any) -> Self: ...

        def __getattr__(self, name: str) -> Any: ...

else:  # the config's numbers, then every reward scale of the records under its name
    _ConstantFields = NamedTuple("RewardConstants", [*_CONFIG_CONSTANTS,
                                                     *((name, float) for name in REWARD_SCALE_RECORDS)])


class RewardConstants(_ConstantFields):
    """The config's numbers scoring needs, by name: dt [s], ticks_per_step [-], smallest_level [s], level_span [s],
    preferred_setting [s], gap_per_vehicle [m], standstill_spacing [m], min_speed [m/s] and envelope_decay [-]
    (``_CONFIG_CONSTANTS``), then each reward scale of :data:`~timegap_env.config.REWARD_SCALE_RECORDS` (a field of
    :class:`~timegap_env.config.RewardScales`) under its name, in its record's unit."""

    __slots__ = ()

    @classmethod
    def from_config(cls, config: EnvConfig) -> RewardConstants:
        scales = config.reward_scales
        return cls(
            dt=float(config.platoon.dt),
            ticks_per_step=config.ticks_per_decision,
            smallest_level=float(config.setting_levels[0]),
            level_span=config.setting_span,
            preferred_setting=float(config.preferred_setting),
            gap_per_vehicle=float(config.platoon.standstill_spacing + config.platoon.vehicle_length),
            standstill_spacing=float(config.platoon.standstill_spacing),
            min_speed=TIME_GAP_MIN_SPEED,
            envelope_decay=math.exp(-config.platoon.dt / scales.accel_envelope_time),
            **{name: float(getattr(scales, name)) for name in REWARD_SCALE_RECORDS},
        )


class StepScore(NamedTuple):
    """What :func:`score_step` gives besides the read-outs."""

    terms: RewardTerms  # each (n_envs,), <= 0
    reward: np.ndarray  # (n_envs,)
    objectives: np.ndarray  # (n_terms, n_envs) each term's objective in its natural unit, REWARD_TERMS order
    cost: np.ndarray  # (n_envs,) -(the sum of COST_TERMS), >= 0


def weights_of(config: EnvConfig) -> RewardTerms:
    """The reward weights as :class:`RewardTerms` of floats, in REWARD_TERMS order."""
    return RewardTerms(*(float(weight) for weight in dataclasses.astuple(config.reward_weights)))


# Reward term -> its objective (its record's), in REWARD_TERMS order: each term is the documented function of its
# objective, so the objectives say in natural units what the terms weigh.
OBJECTIVES: dict[str, Objective] = {name: term.objective for name, term in REWARD_TERM_RECORDS.items()}
COST_TERMS = tuple(name for name, term in REWARD_TERM_RECORDS.items() if term.cost)  # info["cost"] = -(the sum of
# these terms, each clipped to [-1, 0]), in [0, 3]: a step's string instability, TTC shortfall and collision
# (Safety-Gymnasium's convention: >= 0, 0 when safe); env_objectives writes it
COST_ROWS = tuple(REWARD_TERMS.index(name) for name in COST_TERMS)  # their rows in REWARD_TERMS order


def term_lows(config: EnvConfig) -> dict[str, float]:
    """The lowest value of each reward term in a step under ``config`` (its record's ``low``), in REWARD_TERMS
    order; -inf where it has none (safety: a negative TTC once a gap is gone; comfort: jerk squared)."""
    return {name: term.low(config.reward_scales) for name, term in REWARD_TERM_RECORDS.items()}


def step_readouts(step: StepTicks, previous_accel: np.ndarray, envelope: np.ndarray,
                  constants: RewardConstants) -> StepReadouts:
    """The read-outs of ``step``; ``previous_accel`` (n_envs, n_followers) [m/s^2] is the acceleration before
    its first tick, ``envelope`` (n_envs, 1 + n_followers) [m/s^2] each vehicle's acceleration envelope before
    it, the leader first, updated in place."""
    readouts = StepReadouts.empty(*previous_accel.shape)
    _step_readouts(step, previous_accel, envelope, constants, readouts)
    return readouts


def reward_terms(
    readouts: StepReadouts, setting: np.ndarray, changed: np.ndarray, constants: RewardConstants
) -> RewardTerms:
    """The terms of the module docstring per env, each (n_envs,) and <= 0; ``setting`` [s] and ``changed``
    (n_envs, n_followers) are the settings at the end of the step and which of them changed at its start."""
    terms = RewardTerms(*np.empty((len(REWARD_TERMS), setting.shape[0])))
    _reward_terms(readouts, setting, changed, constants, terms)
    return terms


def weighted_sum(terms: RewardTerms, weights: RewardTerms) -> np.ndarray:
    """The reward (n_envs,): the sum of each term times its weight, in REWARD_TERMS order."""
    reward = np.empty(len(terms[0]))
    _weighted_sum(np.array(terms), np.array(weights), reward)
    return reward


def score_step(
    step: StepTicks,
    previous_accel: np.ndarray,
    envelope: np.ndarray,
    setting: np.ndarray,
    changed: np.ndarray,
    constants: RewardConstants,
    weights: RewardTerms,
    readouts: StepReadouts,
) -> StepScore:
    """:func:`step_readouts` into ``readouts`` (the caller's, e.g. from ``StepReadouts.empty``, reused step
    after step), then :func:`reward_terms`, :func:`weighted_sum`, the objectives and the cost, in one compiled
    call."""
    n_envs = setting.shape[0]
    terms = np.empty((len(REWARD_TERMS), n_envs))  # one row a term, in REWARD_TERMS order
    score = StepScore(RewardTerms(*terms), np.empty(n_envs), np.empty((len(REWARD_TERMS), n_envs)), np.empty(n_envs))
    _score(tuple(step), previous_accel, envelope, setting, changed, tuple(constants), np.array(weights),
           tuple(readouts), tuple(score.terms), terms, score.reward, tuple(score.objectives), score.cost)
    return score


@numba.njit(cache=True, error_model="numpy")
def _score(step, previous_accel, envelope, setting, changed, constants, weights, readouts, terms, term_rows, reward,  # noqa: ANN001, ANN202, PLR0913
           objectives, cost):
    """:func:`score_step`; the structures come as plain tuples (see :mod:`timegap_env.sim.platoon`); ``terms``
    are the rows of ``term_rows`` (n_terms, n_envs), written by name and summed by row against ``weights``
    (n_terms,), in REWARD_TERMS order (a tuple indexed by a variable is slow in numba); ``objectives`` the rows
    of the objectives, by term."""
    step, constants, readouts = StepTicks(*step), RewardConstants(*constants), StepReadouts(*readouts)
    terms, objectives = RewardTerms(*terms), RewardTerms(*objectives)
    _step_readouts(step, previous_accel, envelope, constants, readouts)
    _reward_terms(readouts, setting, changed, constants, terms)
    _weighted_sum(term_rows, weights, reward)
    for e in range(setting.shape[0]):
        env_objectives(readouts, setting, changed, term_rows, constants, objectives, cost, e)


@numba.njit(cache=True, error_model="numpy")
def _step_readouts(step, previous_accel, envelope, constants, out):  # noqa: ANN001, ANN202
    for e in range(step.speed.shape[1]):
        env_readouts(step, e, previous_accel, envelope, constants, out, e)


@numba.njit(**STAGE_KERNEL)
def env_readouts(step, column, previous_accel, envelope, constants, out, e):  # noqa: ANN001, ANN201, PLR0913
    """Env ``e``'s read-outs (into ``out``, a :class:`StepReadouts`) of column ``column`` of ``step`` (a
    :class:`StepTicks`); its acceleration envelopes are updated in place."""
    n_ticks, n_followers = step.speed.shape[0], step.speed.shape[2]
    c = column
    for k in range(n_ticks):  # the acceleration envelopes, the leader's in column 0
        envelope[e, 0] = max(abs(step.leader_accel[k, c]), envelope[e, 0] * constants.envelope_decay)
        for f in range(n_followers):
            envelope[e, f + 1] = max(abs(step.accel[k, c, f]), envelope[e, f + 1] * constants.envelope_decay)
    growth = 0.0
    for i in range(1, n_followers + 1):
        growth += max(0.0, envelope[e, i] - envelope[e, i - 1])
    out.accel_growth[e] = growth
    deviation_sum = max_deviation = alarm_ticks = exceedances = gap_deviation_sum = 0.0
    collided = False
    for k in range(n_ticks):
        tick_deviation = tick_gap_deviation = 0.0
        for f in range(n_followers):
            deviation = abs(step.tau_mean[k, c, f] - step.center[k, c, f])
            tick_deviation += deviation
            max_deviation = max(max_deviation, deviation)
            alarm_ticks += step.alarm[k, c, f]
            exceedances += step.exceedance[k, c, f]
            collided = collided or step.collisions[k, c, f]
            speed = step.speed[k, c, f]
            if speed >= constants.min_speed:
                gap = (step.spacing[k, c, f] - constants.standstill_spacing) / speed
                tick_gap_deviation += min(abs(gap - step.applied_setting[k, c, f]), constants.tracking_cap)
        deviation_sum += tick_deviation
        gap_deviation_sum += tick_gap_deviation
    out.deviation_sum[e], out.max_deviation[e], out.collided[e] = deviation_sum, max_deviation, collided
    out.alarm_ticks[e], out.exceedances[e], out.gap_deviation_sum[e] = alarm_ticks, exceedances, gap_deviation_sum
    for f in range(n_followers):
        out.min_ttc[e, f], out.jerk_squared[e, f] = np.inf, 0.0
        for k in range(n_ticks):
            predecessor_speed = step.leader_speed[k, c] if f == 0 else step.speed[k, c, f - 1]
            closing = step.speed[k, c, f] - predecessor_speed  # [m/s], > 0 when the gap shrinks
            if closing > 0:
                out.min_ttc[e, f] = min(out.min_ttc[e, f], step.spacing[k, c, f] / closing)
            before = previous_accel[e, f] if k == 0 else step.accel[k - 1, c, f]
            out.jerk_squared[e, f] += ((step.accel[k, c, f] - before) / constants.dt) ** 2
        out.final_speed[e, f] = step.speed[n_ticks - 1, c, f]


@numba.njit(cache=True, error_model="numpy")
def _reward_terms(readouts, setting, changed, constants, out):  # noqa: ANN001, ANN202
    for e in range(setting.shape[0]):
        env_reward_terms(readouts, setting, changed, constants, out, e)


@numba.njit(**STAGE_KERNEL)
def env_reward_terms(readouts, setting, changed, constants, out, e):  # noqa: ANN001, ANN201, PLR0913
    """Env ``e``'s terms (into ``out``, a :class:`RewardTerms` of (n_envs,) arrays) from its read-outs."""
    n_followers = setting.shape[1]
    n_ticks = constants.ticks_per_step
    follower_ticks = n_ticks * n_followers
    safety = comfort = efficiency = preference = switching = 0.0
    for f in range(n_followers):
        v = readouts.final_speed[e, f]  # [m/s]
        safety += max(0.0, 1.0 - readouts.min_ttc[e, f] / constants.ttc_threshold)
        comfort += readouts.jerk_squared[e, f] / n_ticks
        efficiency += 1.0 - (v * constants.smallest_level + constants.gap_per_vehicle) / (
            v * setting[e, f] + constants.gap_per_vehicle
        )
        preference += abs(setting[e, f] - constants.preferred_setting)
        switching += changed[e, f]
    out.tracking[e] = -readouts.gap_deviation_sum[e] / follower_ticks / constants.tracking_reference
    out.string_stability[e] = -min(1.0, readouts.accel_growth[e] / constants.accel_growth_reference)
    out.safety[e] = -(safety / n_followers)
    out.collision[e] = -1.0 if readouts.collided[e] else -0.0
    out.comfort[e] = -(comfort / n_followers) / constants.jerk_reference**2
    out.efficiency[e] = -(efficiency / n_followers)
    out.preference[e] = -(preference / n_followers) / constants.level_span
    out.switching[e] = -(switching / n_followers)


@numba.njit(**STAGE_KERNEL)
def env_objectives(readouts, setting, changed, term_rows, constants, out, cost, e):  # noqa: ANN001, ANN201, PLR0913
    """Env ``e``'s objectives of :data:`OBJECTIVES` in natural units (into ``out``, a :class:`RewardTerms` of
    (n_envs,) rows, each term's objective under its name) from its read-outs, and its cost (into ``cost``,
    (n_envs,)) from its terms (``term_rows``, (n_terms, n_envs) in REWARD_TERMS order): the rows of COST_TERMS."""
    n_followers = setting.shape[1]
    n_ticks = constants.ticks_per_step
    shortfall = jerk_squared = capacity = preference = switching = 0.0
    for f in range(n_followers):
        v = readouts.final_speed[e, f]  # [m/s]
        shortfall += max(0.0, constants.ttc_threshold - readouts.min_ttc[e, f])
        jerk_squared += readouts.jerk_squared[e, f] / n_ticks
        capacity += 3600.0 * v / (v * setting[e, f] + constants.gap_per_vehicle)
        preference += abs(setting[e, f] - constants.preferred_setting)
        switching += changed[e, f]
    out.tracking[e] = readouts.gap_deviation_sum[e] / (n_ticks * n_followers)  # time_gap_variation [s]
    out.string_stability[e] = readouts.accel_growth[e]  # acceleration_growth [m/s^2]
    out.safety[e] = shortfall / n_followers  # ttc_shortfall [s]
    out.collision[e] = 1.0 if readouts.collided[e] else 0.0
    out.comfort[e] = jerk_squared / n_followers  # jerk_squared [m^2/s^6]
    out.efficiency[e] = capacity / n_followers  # capacity [veh/h]
    out.preference[e] = preference / n_followers  # preference_deviation [s]
    out.switching[e] = switching / n_followers  # [-]
    # each cost term clipped to [-1, 0] (the safety term falls below -1 once a gap is gone, a negative TTC), summed in
    # REWARD_TERMS order; 0.0 - : never -0.0
    total = 0.0
    for t in COST_ROWS:
        total += max(-1.0, term_rows[t, e])
    cost[e] = 0.0 - total


@numba.njit(cache=True, error_model="numpy")
def _weighted_sum(terms, weights, out):  # noqa: ANN001, ANN202
    """``out`` (n_envs,) = sum over t of weights[t] terms[t], ``terms`` (n_terms, n_envs), in row order."""
    for e in range(out.size):
        env_weighted_sum(terms, weights, out, e)


@numba.njit(**STAGE_KERNEL)
def env_weighted_sum(terms, weights, out, e):  # noqa: ANN001, ANN201
    """``out[e]`` of :func:`_weighted_sum`."""
    out[e] = 0.0
    for t in range(terms.shape[0]):
        out[e] += weights[t] * terms[t, e]


follow_sources(__name__)
