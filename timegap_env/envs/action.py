"""The action: an index into the ladder of time gap settings, for the platoon or for each follower, or a step of
the platoon's setting along the ladder."""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

from timegap_env.config import EnvConfig, shown


RELATIVE_STEPS = (-1, 0, 1)  # action_mode="relative": action i moves the platoon's setting this many levels [-]


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
        self.levels = np.asarray(config.setting_levels, dtype=float)  # [s]
        self.n_followers = config.platoon.n_followers
        self.relative = config.action_mode == "relative"
        self.shape = (n_envs, self.n_followers) if config.action_mode == "per_vehicle" else (n_envs,)  # of an action
        self.n_actions = len(RELATIVE_STEPS) if self.relative else self.levels.size  # per entry of an action

    def check(self, action: np.ndarray) -> np.ndarray:
        """``action`` (integers of shape ``shape``, each in [0, n_actions); bools count as 0 and 1, as gymnasium's
        spaces take them) as int64 (n_envs, 1), or (n_envs, N) per vehicle, the layout of the fused step;
        ``ValueError`` naming the action otherwise."""
        action = np.asarray(action)
        if action.shape != self.shape or action.dtype.kind not in "iub":
            raise ValueError(f"action = {shown(action)}: expected integer actions of shape {self.shape}")
        if ((action < 0) | (action >= self.n_actions)).any():
            raise ValueError(f"action = {shown(action)}: every entry must be in [0, {self.n_actions - 1}]")
        return np.ascontiguousarray(action, dtype=np.int64).reshape(self.shape[0], -1)  # one layout: one compile

    def settings(self, action: np.ndarray, current: np.ndarray) -> np.ndarray:
        """Settings [s] (n_envs, n_followers) for an action: ladder indices, (n_envs,) platoon or (n_envs, N) per
        vehicle, or relative steps (n_envs,) from the platoon's ``current`` settings [s] (n_envs, n_followers),
        clipped to the ladder (its largest follower's, should they differ)."""
        action = self.check(action).reshape(self.shape)
        if self.relative:
            now = np.abs(self.levels[None, :] - np.asarray(current).max(axis=1)[:, None]).argmin(axis=1)
            action = np.clip(now + np.asarray(RELATIVE_STEPS)[action], 0, self.levels.size - 1)
        settings = self.levels[action]
        return np.repeat(settings[:, None], self.n_followers, axis=1) if settings.ndim == 1 else settings
