"""The action: an index into the ladder of time gap settings, for the platoon or for each follower, or a step of
the platoon's setting along the ladder."""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np
from gymnasium import spaces

from timegap_env.compiled import STAGE_KERNEL, follow_sources
from timegap_env.config import ACTION_MODES, EnvConfig, shown


RELATIVE_STEPS = (-1, 0, 1)  # action_mode="relative": action i moves the platoon's setting this many levels [-]
PLATOON, PER_VEHICLE, RELATIVE = (ACTION_MODES.index(mode) for mode in ("platoon", "per_vehicle", "relative"))
if len(ACTION_MODES) != 3:  # ladder_env handles these three; a new mode is a branch there
    raise ImportError(f"timegap_env.config.ACTION_MODES {ACTION_MODES}: ladder_env knows platoon, per_vehicle, relative")


class LadderRule(NamedTuple):
    """The ladder's constants, as :func:`ladder_env` takes them."""

    mode: int  # index of ACTION_MODES
    levels: np.ndarray  # the settings an action picks from [s]
    relative_steps: np.ndarray  # int64, levels moved by each relative action [-]

    @classmethod
    def from_config(cls, config: EnvConfig) -> LadderRule:
        return cls(mode=ACTION_MODES.index(config.action_mode), levels=np.asarray(config.setting_levels, dtype=float),
                   relative_steps=np.asarray(RELATIVE_STEPS, dtype=np.int64))


def action_space(config: EnvConfig) -> spaces.Space:
    """Discrete(L) for one platoon-wide setting, MultiDiscrete([L] * N) for one setting per follower, Discrete(3)
    for a relative step (0: one level down, 1: stay, 2: one level up)."""
    levels = len(config.setting_levels)
    if config.action_mode == "platoon":
        return spaces.Discrete(levels)
    if config.action_mode == "relative":
        return spaces.Discrete(len(RELATIVE_STEPS))
    return spaces.MultiDiscrete([levels] * config.platoon.n_followers)


class SettingLadder:
    """Actions to time gap settings [s] for ``n_envs`` envs under ``config``."""

    def __init__(self, config: EnvConfig, n_envs: int) -> None:
        self.rule = LadderRule.from_config(config)
        self.levels = self.rule.levels  # [s]
        self.n_followers = config.platoon.n_followers
        self.shape = (n_envs, self.n_followers) if config.action_mode == "per_vehicle" else (n_envs,)  # of an action
        self.n_actions = len(RELATIVE_STEPS) if self.rule.mode == RELATIVE else self.levels.size  # per entry of an action

    def check(self, action: np.ndarray) -> np.ndarray:
        """``action`` (integers of shape ``shape``, each in [0, n_actions); bools count as 0 and 1, as gymnasium's
        spaces take them) as int64 (n_envs, 1), or (n_envs, N) per vehicle, the layout of the fused step;
        ``ValueError`` naming the action otherwise."""
        action = np.asarray(action)
        if action.shape != self.shape or action.dtype.kind not in "iub":
            raise ValueError(f"action = {shown(action)}: expected integer actions of shape {self.shape}")
        if ((action < 0) | (action >= self.n_actions)).any():
            raise ValueError(f"action = {shown(action)}: every entry must be in [0, {self.n_actions - 1}]")
        checked = np.ascontiguousarray(action, dtype=np.int64).reshape(self.shape[0], -1)  # one layout: one compile
        return checked if checked.flags.writeable and checked.flags.aligned else checked.copy()  # the fused step's type

    def settings(self, action: np.ndarray, current: np.ndarray) -> np.ndarray:
        """Settings [s] (n_envs, n_followers) for an action: ladder indices, (n_envs,) platoon or (n_envs, N) per
        vehicle, or relative steps (n_envs,) from the platoon's ``current`` settings [s] (n_envs, n_followers),
        clipped to the ladder (its largest follower's, should they differ)."""
        action = self.check(action)
        current = np.ascontiguousarray(current, dtype=float)
        settings = np.empty((action.shape[0], self.n_followers))
        _ladder(tuple(self.rule), action, current, settings)
        return settings


@numba.njit(cache=True)
def _ladder(rule, action, current, settings):  # noqa: ANN001, ANN202
    """:func:`ladder_env` env by env."""
    for e in range(action.shape[0]):
        ladder_env(rule, action, current, e, settings[e])


@numba.njit(**STAGE_KERNEL)
def ladder_env(rule, action, current, e, out):  # noqa: ANN001, ANN201
    """Env ``e``'s settings [s] for its action, into ``out`` (n_followers,): ``action`` is int64 (n_envs, 1) (a
    ladder index or a relative step for the platoon) or (n_envs, N) (an index per follower), checked by
    :meth:`SettingLadder.check`; ``current`` the settings now (n_envs, N) [s], from which a relative step moves the
    ladder level nearest the platoon's largest setting, clipped to the ladder; ``rule`` is :class:`LadderRule`."""
    rule = LadderRule(*rule)
    levels, n_followers = rule.levels, out.shape[0]
    level = 0
    if rule.mode == RELATIVE:
        largest = current[e, 0]
        for f in range(1, n_followers):
            largest = max(largest, current[e, f])
        for i in range(1, levels.size):
            if abs(levels[i] - largest) < abs(levels[level] - largest):
                level = i
        level = min(max(level + rule.relative_steps[action[e, 0]], 0), levels.size - 1)
    elif rule.mode == PLATOON:
        level = action[e, 0]
    for f in range(n_followers):
        out[f] = levels[action[e, f] if rule.mode == PER_VEHICLE else level]


follow_sources(__name__)
