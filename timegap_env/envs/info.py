"""What ``info`` holds: flat, numeric, and the same keys from reset on.

Every value is a NumPy array, shaped (n_followers,) per follower or () per platoon, under a
plain string key (no nested dicts, no strings), so that gymnasium's vector envs, TorchRL's
``auto_register_info_dict`` and RLlib batch it as it is. A single env's info holds:

- the monitor's view now (:meth:`~timegap_env.envs.task.PlatoonTask.monitor_info`: ``estimate``,
  ``estimate_std``, ``setting``, ``lcl``, ``ucl``, ``alarm``, ``v2v``, ``skipped_measurements``);
- ``reward_<term>`` for each term of :data:`~timegap_env.envs.reward.REWARD_TERMS`, the last step's
  (0 at reset);
- at the step that ends an episode, ``episode_<name>``, its summary
  (:meth:`~timegap_env.envs.totals.EpisodeTotals.summary`);
- only when the env is made with ``truth_info=True`` (it costs several times the rest of the step), what only
  the simulator knows (:meth:`~timegap_env.envs.task.PlatoonTask.truth_info`): the platoon's true state
  (``actual_time_gap``, ``ttc``, ``jerk``, ``collision``) and ``truth_<name>``, the ground truth
  (:meth:`~timegap_env.sim.degradation.DegradationTable.truth`; ``truth_kind`` is an index of
  :data:`KIND_NAMES`): for oracles and evaluation, never in the observation.

``step_diagnostics=False`` leaves every per-step key out (the summary stays).

With the info layout "v1" (``TimeGapMonitor-v1``'s, ``timegap_env.tasks.Task.info_layout``) it also holds, the last step's (0 at reset):

- ``vector_reward`` (n_terms,): the reward terms in REWARD_TERMS order, so that the reward is the weights
  (``RewardWeights``, in the same order) times it (MO-Gymnasium's ``LinearReward`` convention);
- ``cost`` (): the step's string instability, TTC shortfall and collision, each in [0, 1]
  (:data:`~timegap_env.envs.reward.COST_TERMS`; Safety-Gymnasium's convention: >= 0, 0 when safe);
- ``objectives`` (n_terms,): what each term measures, in natural units, in the same order
  (:data:`~timegap_env.envs.reward.OBJECTIVES`: capacity [veh/h], time-gap variation [s], ...;
  :func:`objectives_of` gives them by name);
- with ``truth_info=True``, ``truth_regime`` (): the leader's regime now, an index into
  :func:`~timegap_env.leaders.scenarios.regime_names` (:func:`truth_of` gives the name).

A single env writes its per-step values into arrays it reuses (:class:`EnvInfoPool`), but only arrays nothing
outside the env references any more: an info's arrays never change while anything holds them, as if they were fresh.

The native vector env's infos are what gymnasium's own vector envs make of these (arrays with a
leading num_envs axis, a boolean ``_<key>`` mask beside each key, ``final_obs`` and ``final_info``
at same-step autoresets). :func:`truth_of`, :func:`summary_of` and :func:`rewards_of` read the
groups back as dicts, with the kinds as names.
"""

from __future__ import annotations

import math
import sys
from collections import deque
from collections.abc import Mapping
from typing import NamedTuple

import numba
import numpy as np

from timegap_env.compiled import STAGE_KERNEL, follow_sources
from timegap_env.envs.reward import OBJECTIVES, REWARD_TERMS
from timegap_env.leaders.scenarios import regime_names
from timegap_env.sim.degradation import KINDS

KIND_NAMES = np.array(KINDS, dtype=object)  # truth_kind -> the degradation's name ("none": not hit)
REWARD_PREFIX, TRUTH_PREFIX, EPISODE_PREFIX = "reward_", "truth_", "episode_"
VECTOR_REWARD, COST, OBJECTIVES_KEY = "vector_reward", "cost", "objectives"  # info layout "v1"'s keys beside the terms


_REWARD_KEYS = tuple(REWARD_PREFIX + name for name in REWARD_TERMS)
VIEW_FLOATS = ("estimate", "estimate_std", "setting", "lcl", "ucl")  # the monitor's view, InfoBlock.floats' rows
VIEW_FLAGS = ("alarm", "v2v")  # and InfoBlock.flags' rows


class InfoBlock(NamedTuple):
    """The per-step values an info holds, as a step writes them (:func:`write_info_env`), arrays with an n_envs axis (of
    length 0 when nothing is to be written): the monitor's view and the scores. Kernels take it as a plain tuple
    (``tuple(block)``), as every structure (see :mod:`timegap_env.sim.platoon`)."""

    floats: np.ndarray  # (len(VIEW_FLOATS), n_envs, n_followers) estimate, estimate_std, setting, lcl, ucl [s]
    flags: np.ndarray  # (len(VIEW_FLAGS), n_envs, n_followers) bool alarm, v2v
    skipped: np.ndarray  # (n_envs, n_followers) int64 skipped measurements since reset [-]
    scores: np.ndarray  # (n_scores, n_envs) the reward terms; with info layout "v1" then the terms again (vector_reward),
    #                     the objectives and the cost

    @classmethod
    def empty(cls, n_envs: int, n_followers: int, info_layout: str) -> InfoBlock:
        n_terms = len(REWARD_TERMS)
        return cls(np.empty((len(VIEW_FLOATS), n_envs, n_followers)),
                   np.empty((len(VIEW_FLAGS), n_envs, n_followers), dtype=bool),
                   np.empty((n_envs, n_followers), dtype=np.int64),
                   np.empty((n_terms if info_layout == "v0" else 3 * n_terms + 1, n_envs)))


@numba.njit(**STAGE_KERNEL)
def write_info_env(mean_tau, var_tau, setting, center, half_width, side, v2v, skipped,  # noqa: ANN001, ANN201
                   term_rows, objective_rows, cost, block, e):
    """Env ``e``'s per-step info values into ``block`` (an :class:`InfoBlock`): the posterior mean ``mean_tau`` [s] and
    the square root of ``var_tau`` [s^2], the ``setting`` [s], the chart's limits, ``center`` [s] -/+ ``half_width``
    [s], whether the chart's ``side`` is not 0, the ``v2v`` flag, the ``skipped`` count, and the scores: the reward
    terms (``term_rows`` (n_terms, n_envs)), then, if ``block.scores`` has more rows (info layout "v1"), the terms
    again, the ``objective_rows`` and the ``cost``. The fused step calls it for every env, :func:`write_info_envs` for
    the task's other paths."""
    floats, flags, skipped_out, scores = block
    for f in range(mean_tau.shape[1]):
        floats[0, e, f], floats[1, e, f] = mean_tau[e, f], math.sqrt(var_tau[e, f])
        floats[2, e, f] = setting[e, f]
        floats[3, e, f], floats[4, e, f] = center[e, f] - half_width, center[e, f] + half_width
        flags[0, e, f], flags[1, e, f] = side[e, f] != 0, v2v[e, f]
        skipped_out[e, f] = skipped[e, f]
    n_terms = term_rows.shape[0]
    for i in range(n_terms):
        scores[i, e] = term_rows[i, e]
    if scores.shape[0] > n_terms:
        for i in range(n_terms):
            scores[n_terms + i, e], scores[2 * n_terms + i, e] = term_rows[i, e], objective_rows[i, e]
        scores[3 * n_terms, e] = cost[e]


@numba.njit(cache=True, error_model="numpy")
def write_info_envs(mean_tau, var_tau, setting, center, half_width, side, v2v, skipped,  # noqa: ANN001, ANN201
                    term_rows, objective_rows, cost, block):
    """:func:`write_info_env` for every env."""
    for e in range(mean_tau.shape[0]):
        write_info_env(mean_tau, var_tau, setting, center, half_width, side, v2v, skipped, term_rows, objective_rows,
                       cost, block, e)


INFO_SETS = 2  # sets an EnvInfoPool reuses: the info being returned and the one the caller may still hold


class EnvInfoSet:
    """One :class:`InfoBlock` of a single env (n_envs 1, a plain tuple) and the info's values as views of it: the
    monitor's view and the scores (the reward terms, 0-d views, and with info layout "v1" ``vector_reward``,
    ``objectives`` and ``cost``)."""

    def __init__(self, n_followers: int, info_layout: str) -> None:
        n_terms = len(REWARD_TERMS)
        self.block = tuple(InfoBlock.empty(1, n_followers, info_layout))  # as the step takes it
        floats, flags, skipped, scores = self.block
        self.monitor = {**dict(zip(VIEW_FLOATS, floats[:, 0])), **dict(zip(VIEW_FLAGS, flags[:, 0])),
                        "skipped_measurements": skipped[0]}
        self.scored = {key: scores[i, 0, ...] for i, key in enumerate(_REWARD_KEYS)}
        if info_layout != "v0":
            self.scored[VECTOR_REWARD] = scores[n_terms : 2 * n_terms, 0]
            self.scored[OBJECTIVES_KEY] = scores[2 * n_terms : 3 * n_terms, 0]
            self.scored[COST] = scores[3 * n_terms, 0, ...]
        self.info = {**self.monitor, **self.scored}  # what an info holds, its keys in order
        self._held = (*self.block, *self.info.values())
        del floats, flags, skipped, scores  # so that the counts below see only this set's own references
        self._count = _reference_count(self._held)  # with nothing outside holding any of them

    def unheld(self) -> bool:
        """Whether nothing but this set references its arrays and views: no info dict, none of its values, no view
        of them (a view of a view references the array that owns the memory). While the set holds them no count
        falls below its own, so the sum is its own only when every count is."""
        return _reference_count(self._held) == self._count


def _reference_count(objects: tuple[object, ...]) -> int:
    """The sum of ``objects``' reference counts."""
    return sum(map(sys.getrefcount, objects))


class EnvInfoPool:
    """The :class:`EnvInfoSet` a single env writes its per-step infos into, reused once nothing outside holds them.

    Fresh arrays for every info (a dozen and a half NumPy objects) cost much of a single env's step.
    Instead the pool keeps ``INFO_SETS`` sets and hands out the one given out longest ago if CPython's reference
    counts show that nothing else references it (a loop holds the last info while it takes the next step: hence two
    sets); else it leaves that set to whoever holds it and makes a new one. So a kept info's arrays never change.
    Only references count: a weak reference to a value, or a raw address of its memory, may see later steps. A
    copy or pickle of the pool is an empty pool (a copied view would no longer be a view of the copied set)."""

    def __init__(self, n_followers: int, info_layout: str) -> None:
        self.n_followers, self.info_layout = n_followers, info_layout
        self._sets: deque[EnvInfoSet] = deque()

    def take(self) -> EnvInfoSet:
        """A set to write the next info into: one nothing else references."""
        if len(self._sets) == INFO_SETS:
            oldest = self._sets.popleft()
            if oldest.unheld():
                self._sets.append(oldest)
                return oldest
        fresh = EnvInfoSet(self.n_followers, self.info_layout)
        self._sets.append(fresh)
        return fresh

    def __getstate__(self) -> dict[str, object]:
        return {"n_followers": self.n_followers, "info_layout": self.info_layout}

    def __setstate__(self, state: dict[str, object]) -> None:
        self.__init__(**state)  # type: ignore[misc]


def info_flags(step_diagnostics: object, truth_info: object) -> tuple[bool, bool]:
    """The envs' ``step_diagnostics`` (whether infos hold the per-step keys) and ``truth_info`` (whether they also
    hold the ground truth) arguments checked: True or False each, ``truth_info`` only with ``step_diagnostics``;
    else ``ValueError`` naming the value."""
    for name, value in (("step_diagnostics", step_diagnostics), ("truth_info", truth_info)):
        if not isinstance(value, (bool, np.bool_)):
            raise ValueError(f"{name} = {value!r}: must be True or False")
    if truth_info and not step_diagnostics:
        raise ValueError("truth_info = True with step_diagnostics = False: the ground truth is a per-step key; "
                         "step_diagnostics=False leaves every per-step key out")
    return bool(step_diagnostics), bool(truth_info)


def prefixed(prefix: str, values: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """``values`` under ``prefix + name``."""
    return {prefix + name: value for name, value in values.items()}


def step_scores(term_rows: np.ndarray, objectives: tuple[np.ndarray, np.ndarray] | None) -> dict[str, np.ndarray]:
    """A step's scores as the info holds them, from its reward terms (n_terms, n_envs): ``reward_<term>``; with
    ``objectives`` (given with info layout "v1": the objectives (n_terms, n_envs) in natural units and the cost
    (n_envs,)) also ``vector_reward`` (n_envs, n_terms), ``cost`` and ``objectives`` (n_envs, n_terms). The values
    are views of the arguments."""
    scores = {REWARD_PREFIX + name: row for name, row in zip(REWARD_TERMS, term_rows)}
    if objectives is not None:
        scores[VECTOR_REWARD], scores[OBJECTIVES_KEY], scores[COST] = term_rows.T, objectives[0].T, objectives[1]
    return scores


def no_scores(n_envs: int, info_layout: str) -> dict[str, np.ndarray]:
    """:func:`step_scores` of no step, zeros: what reset's info holds, so that step's keys are there too."""
    zeros = np.zeros((len(REWARD_TERMS), n_envs))
    return step_scores(zeros, None if info_layout == "v0" else (zeros.copy(), np.zeros(n_envs)))


def with_masks(infos: Mapping[str, np.ndarray], mask: np.ndarray) -> dict[str, np.ndarray]:
    """Batched ``infos`` as gymnasium's vector envs give them for the sub-envs in ``mask`` ((num_envs,) bool):
    zero in the other rows, and a ``_<key>`` mask (a copy of ``mask``) beside each key."""
    if mask.all():
        return {**infos, **{"_" + key: mask.copy() for key in infos}}
    out: dict[str, np.ndarray] = {}
    for key, value in infos.items():
        out[key] = np.where(mask.reshape(-1, *([1] * (value.ndim - 1))), value, np.zeros((), value.dtype))
        out["_" + key] = mask.copy()
    return out


def of_env(infos: Mapping[str, np.ndarray], env: int, copy: bool = True) -> dict[str, np.ndarray]:
    """Env ``env``'s info out of batched ``infos`` (masks left out), each value a copy, or with ``copy`` False a view
    (for ``infos`` whose arrays nothing else holds)."""
    if not copy:
        return {key: value[env, ...] for key, value in infos.items() if not key.startswith("_")}
    return {key: np.array(value[env]) for key, value in infos.items() if not key.startswith("_")}


def _group(info: Mapping[str, np.ndarray], prefix: str) -> dict[str, np.ndarray]:
    return {key[len(prefix):]: value for key, value in info.items() if key.startswith(prefix)}


def truth_of(info: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The ground truth in ``info`` (a single env's or batched) as ``{name: array}``, ``kind`` as names."""
    truth = _group(info, TRUTH_PREFIX)
    if "kind" not in truth:
        raise KeyError(f"info has no ground truth ({TRUTH_PREFIX}* keys): make the env with truth_info=True; its keys: "
                       f"{sorted(info)}")
    truth["kind"] = KIND_NAMES[np.asarray(truth["kind"], dtype=np.intp)]
    if "regime" in truth:
        truth["regime"] = np.array(regime_names(), dtype=object)[np.asarray(truth["regime"], dtype=np.intp)]
    return truth


def summary_of(info: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The episode summary in ``info`` as ``{name: value}`` (empty unless an episode ended)."""
    return _group(info, EPISODE_PREFIX)


def rewards_of(info: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The reward terms in ``info`` as ``{term: value}``."""
    return _group(info, REWARD_PREFIX)


def objectives_of(info: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The objectives in ``info`` (info layout "v1") as ``{name: value}`` in natural units (OBJECTIVES' names)."""
    values = np.asarray(info[OBJECTIVES_KEY])
    return {objective.name: values[..., i] for i, objective in enumerate(OBJECTIVES.values())}


follow_sources(__name__)

__all__ = ["COST", "EPISODE_PREFIX", "KIND_NAMES", "OBJECTIVES_KEY", "REWARD_PREFIX", "TRUTH_PREFIX", "VECTOR_REWARD",
           "EnvInfoPool", "EnvInfoSet", "InfoBlock", "info_flags", "no_scores", "objectives_of", "of_env", "prefixed",
           "rewards_of", "step_scores", "summary_of", "truth_of", "with_masks"]
