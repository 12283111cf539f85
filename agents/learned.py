"""A trained stable-baselines3 model as a policy, with the observation scaling it was trained under.

    policy = LearnedPolicy.load("results/ppo")          # results/ppo/model.zip (+ vecnormalize.pkl if present)
    action, _ = policy.predict(obs, deterministic=True)

A model trained inside ``VecNormalize`` expects normalised observations. ``VecNormalize.load``
needs a venv; instead :class:`ObservationNormalizer` reads the pickle's running mean and
variance (``obs_rms``), ``clip_obs`` and ``epsilon`` and applies SB3's formula
clip((obs - mean) / sqrt(var + epsilon), -clip_obs, clip_obs). Without a pickle the
observations go to the model unchanged. A run's file that cannot be used (not a model zip, not a
``VecNormalize`` pickle, observations of another shape) raises :class:`RunFileError` naming it.
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


class RunFileError(ValueError):
    """A run's file (model zip, ``VecNormalize`` pickle, ``env.json``) that cannot be used; the message names it."""


def load_model(path: str | Path, algorithm: type[BaseAlgorithm] = PPO, **kwargs: Any) -> BaseAlgorithm:
    """``algorithm.load(path, **kwargs)``; a file it cannot read (truncated, not a zip) raises RunFileError."""
    if not Path(path).is_file():
        raise FileNotFoundError(f"model = {str(path)!r}: no such file")
    try:
        return algorithm.load(path, **kwargs)
    except Exception as error:  # SB3 raises ValueError, AssertionError, KeyError, pickle's errors... for a bad zip
        raise RunFileError(f"model = {str(path)!r}: not a readable {algorithm.__name__} model zip "
                           f"({type(error).__name__}: {error})") from error


def load_vecnormalize(path: str | Path) -> VecNormalize:
    """The ``VecNormalize`` in a ``VecNormalize.save`` pickle, without a venv (``set_venv`` gives it one);
    a file that is not one raises RunFileError."""
    if not Path(path).is_file():
        raise FileNotFoundError(f"vecnormalize = {str(path)!r}: no such file")
    try:
        with open(path, "rb") as file:
            saved = pickle.load(file)
    except Exception as error:  # UnpicklingError, EOFError, or whatever the garbage's opcodes lead to
        raise RunFileError(f"vecnormalize = {str(path)!r}: not a readable pickle "
                           f"({type(error).__name__}: {error})") from error
    if not isinstance(saved, VecNormalize):
        raise RunFileError(f"vecnormalize = {str(path)!r}: holds a {type(saved).__name__}, not a VecNormalize")
    return saved


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
        return cls.of(load_vecnormalize(path), str(path))

    @classmethod
    def of(cls, saved: VecNormalize, where: str = "the VecNormalize") -> ObservationNormalizer | None:
        """A frozen copy of ``saved``'s statistics now; None if it does not normalise observations."""
        if not saved.norm_obs:
            return None
        if isinstance(saved.obs_rms, dict):
            raise RunFileError(f"vecnormalize = {where!r}: normalises dict observations; TimeGapMonitor's are a Box")
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
    ``Discrete`` -> "platoon", ``MultiDiscrete`` -> "per_vehicle". ``frame_stack`` k > 1: the model
    reads the last k normalised observations side by side, oldest first, zeros before the first (as
    SB3's ``VecFrameStack``); ``predict`` then carries them as its ``state``: pass back the state it
    returned, None at the episodes' start.
    """

    def __init__(self, model: BaseAlgorithm, normalizer: ObservationNormalizer | None = None, name: str = "PPO",
                 action_mode: str | None = None, frame_stack: int = 1) -> None:
        expected = {"platoon": spaces.Discrete, "relative": spaces.Discrete, "per_vehicle": spaces.MultiDiscrete}
        if action_mode is None:
            action_mode = "per_vehicle" if isinstance(model.action_space, spaces.MultiDiscrete) else "platoon"
        if action_mode not in expected or not isinstance(model.action_space, expected[action_mode]):
            raise ValueError(f"action_mode = {action_mode!r}: does not fit model.action_space = {model.action_space}")
        if isinstance(frame_stack, bool) or not isinstance(frame_stack, int) or frame_stack < 1:
            raise ValueError(f"frame_stack = {frame_stack!r}: must be an integer >= 1")
        if model.observation_space.shape[-1] % frame_stack:
            raise ValueError(f"frame_stack = {frame_stack}: does not divide the model's observation width "
                             f"{model.observation_space.shape[-1]}")
        self.action_mode = action_mode
        self.frame_stack = frame_stack
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
        The action mode comes from ``env.json`` beside the model if it exists. A missing file raises
        FileNotFoundError; one that cannot be read, or statistics of another observation shape than the
        model's, RunFileError naming it.
        """
        path = Path(path)
        model_path = path / MODEL_FILE if path.is_dir() else path
        if not model_path.is_file():
            raise FileNotFoundError(f"path = {str(path)!r}: no model zip found at {model_path}")
        stats_path = Path(vecnormalize) if vecnormalize is not None else model_path.parent / VECNORMALIZE_FILE
        normalizer = None
        if vecnormalize is not None or stats_path.is_file():
            normalizer = ObservationNormalizer.from_vecnormalize(stats_path)
        env_path = model_path.parent / ENV_FILE
        action_mode, frame_stack = None, 1
        if env_path.is_file():
            try:
                run = json.loads(env_path.read_text())
                action_mode = run["env_kwargs"].get("config", {}).get("action_mode", "platoon")
                frame_stack = run["frame_stack"]
            except (UnicodeDecodeError, json.JSONDecodeError, AttributeError, KeyError, TypeError) as error:
                raise RunFileError(f"{env_path}: not a JSON object with env_kwargs (gym.make's) and frame_stack "
                                   f"({error!r})") from error
        model = load_model(model_path, algorithm, device="cpu")
        try:
            policy = cls(model, normalizer, name, action_mode, frame_stack)
        except ValueError as error:  # the action mode or frame stack (env.json's, or the defaults) does not fit the model
            source = env_path if env_path.is_file() else f"the defaults (no {env_path})"
            raise RunFileError(f"{source} does not fit the model {model_path}: {error}") from error
        if normalizer is not None and normalizer.mean.shape != policy.observation_shape:
            raise RunFileError(f"vecnormalize = {str(stats_path)!r}: normalises observations of shape "
                               f"{normalizer.mean.shape}, the model {model_path} takes {policy.observation_shape}")
        return policy

    @property
    def observation_shape(self) -> tuple[int, ...]:
        """Shape of one observation the policy takes (with frame stacking, the model reads frame_stack of them)."""
        *batch, width = self.model.observation_space.shape
        return (*batch, width // self.frame_stack)

    def predict(
        self,
        observation: np.ndarray,
        state: Any = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = True,
    ) -> tuple[np.ndarray, Any]:
        """The model's action for one observation (obs_dim,) or a batch (n_envs, obs_dim), observations normalised first;
        with frame stacking, ``state`` is the stack so far (None: a new episode) and the new stack is returned."""
        obs = np.asarray(observation, dtype=np.float32)
        if self.normalizer is not None:
            obs = self.normalizer(obs)
        if self.frame_stack == 1:
            return self.model.predict(obs, state=state, episode_start=episode_start, deterministic=deterministic)
        width = obs.shape[-1]
        stack = np.zeros((*obs.shape[:-1], width * self.frame_stack), dtype=np.float32) if state is None else state
        stack = np.concatenate([stack[..., width:], obs], axis=-1)
        if episode_start is not None and np.ndim(obs) == 2:  # episodes that start now see zeros before them
            starting = np.asarray(episode_start, dtype=bool)
            stack[starting, :-width] = 0.0
        action, _ = self.model.predict(stack, deterministic=deterministic)
        return action, stack

    def __repr__(self) -> str:
        return (f"LearnedPolicy({self.name!r}, action_mode={self.action_mode!r}, normalized={self.normalizer is not None}, "
                f"frame_stack={self.frame_stack})")
