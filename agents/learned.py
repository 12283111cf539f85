"""A trained stable-baselines3 model as a policy, with the observation scaling it was trained under.

    policy = LearnedPolicy.load("results/ppo")          # results/ppo/model.zip (+ vecnormalize.pkl if present)
    action, _ = policy.predict(obs, deterministic=True)

A model trained inside ``VecNormalize`` expects normalised observations. ``VecNormalize.load``
needs a venv; instead :class:`ObservationNormalizer` reads the pickle's running mean and
variance (``obs_rms``), ``clip_obs`` and ``epsilon`` and applies SB3's formula
clip((obs - mean) / sqrt(var + epsilon), -clip_obs, clip_obs). Without a pickle the
observations go to the model unchanged.
"""

from __future__ import annotations

import dataclasses
import json
import pickle
from pathlib import Path
from typing import Any

import numpy as np
from gymnasium import spaces
from stable_baselines3 import PPO
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.vec_env import VecNormalize

from agents.protocol import ENV_FILE, MODEL_FILE, VECNORMALIZE_FILE


@dataclasses.dataclass(frozen=True)
class ObservationNormalizer:
    """SB3 ``VecNormalize``'s observation scaling, frozen (no more updates)."""

    mean: np.ndarray  # running mean of each observation entry
    var: np.ndarray  # running variance of each observation entry
    clip_obs: float  # normalised observations are clipped to [-clip_obs, clip_obs]
    epsilon: float  # added to the variance before the square root

    @classmethod
    def from_vecnormalize(cls, path: str | Path) -> ObservationNormalizer | None:
        """The statistics in a ``VecNormalize.save`` pickle; None if it was saved with ``norm_obs=False``."""
        with open(path, "rb") as file:
            saved = pickle.load(file)
        if not isinstance(saved, VecNormalize):
            raise ValueError(f"vecnormalize = {str(path)!r}: holds a {type(saved).__name__}, not a VecNormalize")
        if not saved.norm_obs:
            return None
        if isinstance(saved.obs_rms, dict):
            raise ValueError(f"vecnormalize = {str(path)!r}: normalises dict observations; TimeGapMonitor's are a Box")
        return cls(
            mean=np.asarray(saved.obs_rms.mean, dtype=np.float64),
            var=np.asarray(saved.obs_rms.var, dtype=np.float64),
            clip_obs=float(saved.clip_obs),
            epsilon=float(saved.epsilon),
        )

    def __call__(self, observation: np.ndarray) -> np.ndarray:
        """Normalised float32 observations, same shape as ``observation``."""
        scaled = (np.asarray(observation, dtype=np.float64) - self.mean) / np.sqrt(self.var + self.epsilon)
        return np.clip(scaled, -self.clip_obs, self.clip_obs).astype(np.float32)


class LearnedPolicy:
    """An SB3 model behind the same ``predict`` as the hand-written policies.

    ``action_mode``: as given (a run's ``ENV_FILE`` gives it), else from the model's action space:
    ``Discrete`` -> "platoon", ``MultiDiscrete`` -> "per_vehicle".
    """

    def __init__(self, model: BaseAlgorithm, normalizer: ObservationNormalizer | None = None, name: str = "PPO",
                 action_mode: str | None = None) -> None:
        expected = {"platoon": spaces.Discrete, "relative": spaces.Discrete, "per_vehicle": spaces.MultiDiscrete}
        if action_mode is None:
            action_mode = "per_vehicle" if isinstance(model.action_space, spaces.MultiDiscrete) else "platoon"
        if action_mode not in expected or not isinstance(model.action_space, expected[action_mode]):
            raise ValueError(f"action_mode = {action_mode!r}: does not fit model.action_space = {model.action_space}")
        self.action_mode = action_mode
        self.model = model
        self.normalizer = normalizer
        self.name = name

    @classmethod
    def load(
        cls,
        path: str | Path,
        vecnormalize: str | Path | None = None,
        algorithm: type[BaseAlgorithm] = PPO,
        name: str = "PPO",
    ) -> LearnedPolicy:
        """Load ``path`` (a model zip, or a directory holding ``model.zip``) on the CPU.

        ``vecnormalize``: the ``VecNormalize`` pickle; by default ``vecnormalize.pkl`` beside the
        model if it exists, else no normalisation. An explicit path that does not exist is an error.
        The action mode comes from ``env.json`` beside the model if it exists.
        """
        path = Path(path)
        model_path = path / MODEL_FILE if path.is_dir() else path
        if not model_path.is_file():
            raise FileNotFoundError(f"path = {str(path)!r}: no model zip found at {model_path}")
        if vecnormalize is None:
            stats_path = model_path.parent / VECNORMALIZE_FILE
            normalizer = ObservationNormalizer.from_vecnormalize(stats_path) if stats_path.is_file() else None
        else:
            if not Path(vecnormalize).is_file():
                raise FileNotFoundError(f"vecnormalize = {str(vecnormalize)!r}: no such file")
            normalizer = ObservationNormalizer.from_vecnormalize(vecnormalize)
        env_path = model_path.parent / ENV_FILE
        action_mode = None
        if env_path.is_file():
            try:
                action_mode = json.loads(env_path.read_text()).get("config", {}).get("action_mode", "platoon")
            except (json.JSONDecodeError, AttributeError) as error:
                raise ValueError(f"{env_path}: not a JSON object of gym.make keyword arguments ({error})") from error
        return cls(algorithm.load(model_path, device="cpu"), normalizer, name, action_mode)

    @property
    def observation_shape(self) -> tuple[int, ...]:
        """Shape of one observation the model takes."""
        return tuple(self.model.observation_space.shape)

    def predict(
        self,
        observation: np.ndarray,
        state: Any = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = True,
    ) -> tuple[np.ndarray, Any]:
        """The model's action for one observation (obs_dim,) or a batch (n_envs, obs_dim), observations normalised first."""
        obs = np.asarray(observation, dtype=np.float32)
        if self.normalizer is not None:
            obs = self.normalizer(obs)
        return self.model.predict(obs, state=state, episode_start=episode_start, deterministic=deterministic)

    def __repr__(self) -> str:
        return f"LearnedPolicy({self.name!r}, action_mode={self.action_mode!r}, normalized={self.normalizer is not None})"
