"""``mo-TimeGapMonitor-v1``: ``TimeGapMonitor-v1`` whose reward is the vector of its terms (MO-Gymnasium's API).

``step`` returns, in place of the scalar, the reward terms (:data:`~timegap_env.envs.reward.REWARD_TERMS`, or the
ones chosen with ``objectives``) as a float32 vector, each <= 0; ``reward_space`` and ``reward_dim`` say its shape.
The scalar env's reward is ``RewardWeights`` times this vector (all terms), so MO-Gymnasium's
``LinearReward(env, weight=...)`` with the weights of a preset gives back that preset's scalar env. What each term
measures in natural units is in the info (``objectives``) and in :data:`~timegap_env.envs.reward.OBJECTIVES`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import gymnasium as gym
import numpy as np

from timegap_env.config import shown
from timegap_env.envs.env import TimeGapMonitorEnv
from timegap_env.envs.reward import OBJECTIVES, REWARD_TERMS, term_lows
from timegap_env.tasks import DEFAULT_TASK

def chosen_objectives(objectives: Sequence[str] | None) -> tuple[str, ...]:
    """``objectives`` checked, as reward terms: None (every term), or distinct names of REWARD_TERMS or of their
    objectives (``OBJECTIVES``: "capacity" is the efficiency term); ``ValueError`` naming the value."""
    if objectives is None:
        return REWARD_TERMS
    if isinstance(objectives, str) or not isinstance(objectives, (Sequence, np.ndarray)) or not len(objectives):
        raise ValueError(f"objectives = {shown(objectives)}: must be None (all) or a non-empty list of reward terms "
                         f"among {list(REWARD_TERMS)}")
    terms = {**{objective.name: term for term, objective in OBJECTIVES.items()}, **{term: term for term in REWARD_TERMS}}
    unknown = [name for name in objectives if name not in terms]
    if unknown:
        raise ValueError(f"objectives = {shown(objectives)}: unknown objective(s) {unknown}; known: the reward terms "
                         f"{list(REWARD_TERMS)} or their objectives {[o.name for o in OBJECTIVES.values()]}")
    chosen = tuple(terms[str(name)] for name in objectives)
    if len(set(chosen)) != len(chosen):
        raise ValueError(f"objectives = {shown(objectives)}: each may appear once")
    return chosen


class MOTimeGapMonitorEnv(TimeGapMonitorEnv):
    """``TimeGapMonitorEnv`` with a vector reward: ``gym.make("mo-TimeGapMonitor-v1", objectives=None | [terms],
    config=..., ...)`` (or ``mo_gymnasium.make``). ``objectives`` picks reward terms (by name, in the given order) for
    the vector; the default is all of them. Everything else is ``TimeGapMonitor-v1``'s, the task it is registered for.
    """

    def __init__(self, config: Mapping[str, Any] | None = None, render_mode: str | None = None,
                 step_diagnostics: bool = True, task_id: str = DEFAULT_TASK,
                 objectives: Sequence[str] | None = None, truth_info: bool = False) -> None:
        self.objectives = chosen_objectives(objectives)
        super().__init__(config, render_mode, step_diagnostics, task_id, truth_info)
        self._rows = np.array([REWARD_TERMS.index(name) for name in self.objectives])
        self.reward_dim = len(self.objectives)
        lows = term_lows(self.config)
        self.reward_space = gym.spaces.Box(low=np.array([lows[name] for name in self.objectives], np.float32),
                                           high=np.zeros(self.reward_dim, np.float32), dtype=np.float32)

    def step(self, action: Any) -> tuple[np.ndarray, np.ndarray, bool, bool, dict]:  # type: ignore[override]
        obs, _, terminated, truncated, info = super().step(action)
        vector = self.task._result.term_rows[self._rows, 0].astype(np.float32)
        return obs, vector, terminated, truncated, info


__all__ = ["MOTimeGapMonitorEnv", "chosen_objectives"]
