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


def settings_for(action: np.ndarray, config: EnvConfig, n_envs: int) -> np.ndarray:
    """Time gap settings [s] (n_envs, n_followers) for ladder indices: (n_envs,) platoon or (n_envs, N) per vehicle."""
    action = np.asarray(action)
    n_followers = config.platoon.n_followers
    expected = (n_envs,) if config.action_mode == "platoon" else (n_envs, n_followers)
    if action.shape != expected or not np.issubdtype(action.dtype, np.integer):
        raise ValueError(f"action = {action!r}: expected integer ladder indices of shape {expected}")
    levels = np.asarray(config.setting_levels, dtype=float)
    if ((action < 0) | (action >= levels.size)).any():
        raise ValueError(f"action = {action!r}: every index must be in [0, {levels.size - 1}]")
    settings = levels[action]
    return np.repeat(settings[:, None], n_followers, axis=1) if settings.ndim == 1 else settings
