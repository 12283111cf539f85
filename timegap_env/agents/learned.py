"""A trained stable-baselines3 model as a policy, with the observation scaling it was trained under.

    policy = LearnedPolicy.load("results/v0/ppo")          # results/v0/ppo/model.zip, env.json (+ vecnormalize.pkl)
    action, _ = policy.predict(obs, deterministic=True)

A run is read as it was trained, or not at all: ``env.json`` (``timegap_env.agents.protocol``) says what the
model's actions mean, how many observations it reads at once and whether they were normalised;
a missing ``env.json``, one whose env does not fit the model (another action space: a relative-mode
Discrete(3) read as platoon mode's Discrete(9)), or statistics missing where the run normalised,
present where it did not, of another shape or not finite, raise :class:`RunFileError` naming the
file. A model trained inside ``VecNormalize`` expects normalised observations. ``VecNormalize.load``
needs a venv; instead :class:`ObservationNormalizer` reads the pickle's running mean and
variance (``obs_rms``), ``clip_obs`` and ``epsilon`` and applies SB3's formula
clip((obs - mean) / sqrt(var + epsilon), -clip_obs, clip_obs).

``LearnedPolicy.load`` sets torch to one thread (``threads``): the network is tiny, and torch's
default of a thread per core fights the simulator's numba threads for the cores (on 2 cores a
16-episode evaluation batch took 2-3 s instead of 0.1-0.2 s, and up to 51 s on a busy machine).
"""

from __future__ import annotations

import dataclasses
import pickle
from pathlib import Path
from typing import Any

import numpy as np
import torch
from gymnasium import spaces
from stable_baselines3 import PPO
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.vec_env import VecNormalize

from timegap_env.agents.protocol import (
    ALGORITHMS, ENV_FILE, MODEL_FILE, VECNORMALIZE_FILE, RunFileError, check_spaces, read_env_file,
)
from timegap_env.config import MonitorConfig
from timegap_env.envs.observation import feature_columns, hidden

__all__ = ["LearnedPolicy", "ObservationNormalizer", "RunFileError", "load_model", "load_vecnormalize"]


def algorithm_class(algo: str) -> type[BaseAlgorithm]:
    """The class of ``algo`` (protocol.ALGORITHMS): ``ppo`` -> PPO, ``ppo_lstm`` -> sb3-contrib's RecurrentPPO (an
    ``ImportError`` naming the package without it)."""
    if algo == "ppo":
        return PPO
    if algo == "ppo_lstm":
        try:
            from sb3_contrib import RecurrentPPO
        except ImportError as error:
            raise ImportError("algo = 'ppo_lstm' needs sb3-contrib: pip install 'timegap_env[train]'") from error
        return RecurrentPPO
    raise ValueError(f"algo = {algo!r}: must be one of {list(ALGORITHMS)}")


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
    check_statistics(saved, str(path))
    return saved


def check_statistics(saved: VecNormalize, where: str) -> None:
    """RunFileError naming ``where``, the field and its bad values unless ``saved``'s statistics can scale anything:
    finite running means, finite variances >= 0, a finite epsilon >= 0, finite clips > 0 (a NaN mean turns every
    observation into NaN, and the model's actions with it)."""
    rules = {"mean": ("finite", lambda v: np.isfinite(v)), "var": (">= 0", lambda v: np.isfinite(v) & (v >= 0)),
             "epsilon": (">= 0", lambda v: np.isfinite(v) & (v >= 0)), "clip": ("> 0", lambda v: np.isfinite(v) & (v > 0))}
    fields: dict[str, tuple[str, Any]] = {name: ("clip", getattr(saved, name, None)) for name in ("clip_obs", "clip_reward")}
    fields["epsilon"] = ("epsilon", getattr(saved, "epsilon", None))
    for name in ("obs_rms", "ret_rms"):
        statistics = getattr(saved, name, None)
        parts = statistics.items() if isinstance(statistics, dict) else [("", statistics)]
        for key, part in parts:
            if part is not None:
                prefix = f"{name}[{key!r}]" if key else name
                mean: Any = getattr(part, "mean", None)  # np.shape(None) is (), as for any scalar
                var: Any = getattr(part, "var", None)
                fields[f"{prefix}.mean"], fields[f"{prefix}.var"] = ("mean", mean), ("var", var)
                if np.shape(mean) != np.shape(var):
                    raise RunFileError(f"vecnormalize = {where!r}: {prefix}.mean has shape {np.shape(mean)}, its var "
                                       f"{np.shape(var)}: they must match (is the file damaged?)")
    for name, (kind, value) in fields.items():
        try:
            values = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError):
            values = None
        if value is None or values is None:
            raise RunFileError(f"vecnormalize = {where!r}: {name} = {value!r}: not a number (is the file from another "
                               "SB3 version?)")
        rule, check = rules[kind]
        bad = ~check(values)
        if bad.any():
            entries = f" at entries {np.flatnonzero(bad).tolist()[:10]}" if values.ndim else ""
            shown = values.ravel()[bad.ravel()][:5].tolist() if values.ndim else float(values)
            raise RunFileError(f"vecnormalize = {where!r}: {name} = {shown}{entries}: must be finite"
                               f"{'' if rule == 'finite' else ' and ' + rule}; these statistics would turn the "
                               "observations into NaN or inf")


def _shape(space: spaces.Space) -> tuple[int, ...]:
    """``space.shape``: a model's observation space is a Box, which has one."""
    shape = space.shape
    assert shape is not None
    return shape


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
    returned, None at the episodes' start. ``hidden_features``: observation features read as 0 before the model
    sees them (a run trained without them, an ablation). ``monitor_estimator``: the monitor whose observations the
    model learned from (``MonitorConfig.estimator``; the rollout harness plays it in such an env), None: any.
    """

    def __init__(self, model: BaseAlgorithm, normalizer: ObservationNormalizer | None = None, name: str = "PPO",
                 action_mode: str | None = None, frame_stack: int = 1, hidden_features: tuple[str, ...] = (),
                 monitor_estimator: str | None = None) -> None:
        expected = {"platoon": spaces.Discrete, "relative": spaces.Discrete, "per_vehicle": spaces.MultiDiscrete}
        if action_mode is None:
            action_mode = "per_vehicle" if isinstance(model.action_space, spaces.MultiDiscrete) else "platoon"
        if action_mode not in expected or not isinstance(model.action_space, expected[action_mode]):
            raise ValueError(f"action_mode = {action_mode!r}: does not fit model.action_space = {model.action_space}")
        if isinstance(frame_stack, bool) or not isinstance(frame_stack, int) or frame_stack < 1:
            raise ValueError(f"frame_stack = {frame_stack!r}: must be an integer >= 1")
        if _shape(model.observation_space)[-1] % frame_stack:
            raise ValueError(f"frame_stack = {frame_stack}: does not divide the model's observation width "
                             f"{_shape(model.observation_space)[-1]}")
        feature_columns(hidden_features)
        self.action_mode = action_mode
        self.frame_stack = frame_stack
        self.hidden_features = tuple(hidden_features)  # read as 0 before the model sees an observation, as in training
        self.monitor_estimator = monitor_estimator
        self.model = model
        self.normalizer = normalizer
        self.name = name

    @classmethod
    def load(
        cls,
        path: str | Path,
        vecnormalize: str | Path | None = None,
        algorithm: type[BaseAlgorithm] | None = None,
        name: str = "PPO",
        threads: int | None = 1,
    ) -> LearnedPolicy:
        """Load a run, ``path`` (its directory, or the model zip in it), on the CPU, as it was trained.

        ``env.json`` beside the model gives the action mode (checked against the model's action space), the frame
        stack, whether observations were normalised and the algorithm (``algorithm``, if given, overrides it).
        ``vecnormalize``: the ``VecNormalize`` pickle; by default
        ``vecnormalize.pkl`` beside the model, required when the run normalised (``normalize: true``, or not
        recorded), refused when it did not. ``threads``: torch's threads from now on (None: leave them). A missing
        model zip raises FileNotFoundError; a missing ``env.json``, missing or extra statistics, or a file that
        cannot be read or does not fit the others, RunFileError naming it.
        """
        path = Path(path)
        model_path = path / MODEL_FILE if path.is_dir() else path
        if not model_path.is_file():
            raise FileNotFoundError(f"path = {str(path)!r}: no model zip found at {model_path}")
        run = read_env_file(model_path.parent / ENV_FILE)
        beside = model_path.parent / VECNORMALIZE_FILE
        stats_path = Path(vecnormalize) if vecnormalize is not None else beside
        normalizer = None
        if run.normalize is False:
            if vecnormalize is not None or beside.is_file():
                raise RunFileError(f"{stats_path}: {'given' if vecnormalize is not None else 'present'}, but "
                                   f"{run.path} says the run did not normalise observations (normalize: false); "
                                   "one of the two is not this run's")
        else:
            if vecnormalize is not None and not stats_path.is_file():
                raise FileNotFoundError(f"vecnormalize = {str(stats_path)!r}: no such file")
            if not stats_path.is_file():
                said = ("says the run normalised observations (normalize: true)" if run.normalize else
                        "does not say whether the run normalised observations (no normalize field)")
                raise RunFileError(f"{stats_path}: missing; {run.path} {said}, and without the statistics the model "
                                   "would read unscaled observations. Restore the file"
                                   + ("" if run.normalize else f", or add \"normalize\": false to {ENV_FILE} if the "
                                      "run trained without VecNormalize"))
            normalizer = ObservationNormalizer.from_vecnormalize(stats_path)
        if threads is not None:
            torch.set_num_threads(threads)
        model = load_model(model_path, algorithm or algorithm_class(run.algo), device="cpu")
        try:
            policy = cls(model, normalizer, name, run.action_mode, run.frame_stack, run.hidden_features,
                         run.config.monitor.estimator)
        except ValueError as error:  # the action mode or frame stack of env.json does not fit the model
            raise RunFileError(f"{run.path} does not fit the model {model_path}: {error}") from error
        check_spaces(run, model.action_space, _shape(model.observation_space), model_path)
        if normalizer is not None and normalizer.mean.shape != policy.observation_shape:
            raise RunFileError(f"vecnormalize = {str(stats_path)!r}: normalises observations of shape "
                               f"{normalizer.mean.shape}, the model {model_path} takes {policy.observation_shape}")
        return policy

    @property
    def observation_shape(self) -> tuple[int, ...]:
        """Shape of one observation the policy takes (with frame stacking, the model reads frame_stack of them)."""
        *batch, width = _shape(self.model.observation_space)
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
        obs = hidden(observation, self.hidden_features) if self.hidden_features else np.asarray(observation, np.float32)
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
        hiding = f", hidden_features={list(self.hidden_features)}" if self.hidden_features else ""
        hiding += f", monitor_estimator={self.monitor_estimator!r}" if self.monitor_estimator not in (None, MonitorConfig.estimator) else ""
        return (f"LearnedPolicy({self.name!r}, action_mode={self.action_mode!r}, normalized={self.normalizer is not None}, "
                f"frame_stack={self.frame_stack}{hiding})")
