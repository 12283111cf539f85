"""The action: an index into the ladder of time gap settings, for the platoon or for each follower."""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

from timegap_env.config import EnvConfig


def action_space(config: EnvConfig) -> spaces.Space:
    """Discrete(L) for one platoon-wide setting, MultiDiscrete([L] * N) for one setting per follower."""
    levels = len(config.setting_levels)
    if config.action_mode == "platoon":
        return spaces.Discrete(levels)
    return spaces.MultiDiscrete([levels] * config.platoon.n_followers)


class SettingLadder:
    """Ladder indices to time gap settings [s] for ``n_envs`` envs under ``config``."""

    def __init__(self, config: EnvConfig, n_envs: int) -> None:
        self.levels = np.asarray(config.setting_levels, dtype=float)  # [s]
        self.n_followers = config.platoon.n_followers
        self.shape = (n_envs,) if config.action_mode == "platoon" else (n_envs, self.n_followers)  # of an action

    def settings(self, action: np.ndarray) -> np.ndarray:
        """Settings [s] (n_envs, n_followers) for ladder indices: (n_envs,) platoon or (n_envs, N) per vehicle."""
        action = np.asarray(action)
        if action.shape != self.shape or action.dtype.kind not in "iu":
            raise ValueError(f"action = {action!r}: expected integer ladder indices of shape {self.shape}")
        if ((action < 0) | (action >= self.levels.size)).any():
            raise ValueError(f"action = {action!r}: every index must be in [0, {self.levels.size - 1}]")
        settings = self.levels[action]
        return np.repeat(settings[:, None], self.n_followers, axis=1) if settings.ndim == 1 else settings
