"""What training and evaluation agree on: the seed split and the files of a trained run.

Training (``train/train_ppo.py``) seeds its envs below ``EVAL_SEED_START``; the held-out
evaluation (``train/benchmark.py``) seeds its episodes from ``EVAL_SEED_START`` on, so no
evaluation episode was seen in training (``timegap_env.tasks.Seeds``: every step's seeds). A trained run is a directory holding ``MODEL_FILE``,
``ENV_FILE`` and, when observations were normalised, ``VECNORMALIZE_FILE`` (all three read by
``timegap_env.agents.learned``). ``ENV_FILE`` is a JSON object:

- ``env_kwargs``: the ``gym.make`` keyword arguments of the env the run was trained in (its
  ``config``, the action mode among it: the meaning of the model's actions);
- ``frame_stack``: the observations the model reads at once;
- ``normalize``: true if the model reads observations normalised by ``VECNORMALIZE_FILE``, false if
  it reads them as the env gives them. Runs written before the field existed leave it out; then
  ``VECNORMALIZE_FILE`` beside the model says the run normalised, and its absence is an error
  (the model cannot be told apart from one whose statistics were lost);
- ``hidden_features``: the observation's features the model never saw (read as 0, an ablation), a list of names
  of ``timegap_env.envs.observation.FEATURES``; absent: none;
- ``algo``: the learning algorithm, rl-zoo3's name: ``ppo`` (stable-baselines3's PPO) or ``ppo_lstm``
  (sb3-contrib's RecurrentPPO); absent: ``ppo``;
- ``env_id``: the registered id of the env (``TimeGapMonitor-v1``, ...), whose task's config the ``config``
  overrides; runs written before the field existed leave it out and were trained in ``TimeGapMonitor-v0``.

:func:`read_env_file` reads and checks it, :func:`check_spaces` checks a model against it; a file
that is missing, unreadable or does not fit the model is an error naming it, never a default.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

from timegap_env.tasks import HELD_OUT_SEED_START, TASKS, get_task

EVAL_SEED_START = HELD_OUT_SEED_START  # evaluation seeds are >= this, training seeds < this [-]
MODEL_FILE = "model.zip"  # the SB3 model of a run
VECNORMALIZE_FILE = "vecnormalize.pkl"  # SB3 VecNormalize statistics of a run, if it normalised
ENV_FILE = "env.json"  # the env a run was trained in, its frame stacking and normalisation (JSON)
ENV_FILE_KEYS = {"env_kwargs", "frame_stack", "normalize", "env_id", "hidden_features", "algo"}  # all but the first
# two may be absent
ALGORITHMS = ("ppo", "ppo_lstm")  # ENV_FILE's algo: stable-baselines3's PPO, sb3-contrib's RecurrentPPO
OLDER_RUNS_ENV_ID = "TimeGapMonitor-v0"  # the env of a run whose ENV_FILE names none


class RunFileError(ValueError):
    """A run's file (model zip, ``VecNormalize`` pickle, ``env.json``) that is missing, cannot be used, or does not
    fit the others; the message names it."""


@dataclasses.dataclass(frozen=True)
class RunEnv:
    """A run's ``ENV_FILE``, checked."""

    path: Path  # the file
    env_kwargs: dict[str, Any]  # gym.make's keyword arguments
    frame_stack: int  # observations the model reads at once
    normalize: bool | None  # observations normalised by VECNORMALIZE_FILE; None: not recorded (an older run)
    env_id: str = OLDER_RUNS_ENV_ID  # the registered env
    hidden_features: tuple[str, ...] = ()  # read as 0 in the observations the model saw
    algo: str = "ppo"  # one of ALGORITHMS

    @property
    def config(self) -> Any:
        """The env's ``EnvConfig``: its task's config with ``env_kwargs``' config (checked by
        :func:`read_env_file`)."""
        return get_task(self.env_id).config(self.env_kwargs.get("config"))

    @property
    def action_mode(self) -> str:
        """What the model's actions mean: the config's ``action_mode``."""
        return self.config.action_mode


def read_env_file(path: str | Path) -> RunEnv:
    """The run's ``ENV_FILE`` at ``path``: ``RunFileError`` naming it if it is missing, not such a JSON object, or its
    env config is not one ``gym.make`` accepts."""
    path = Path(path)
    if not path.is_file():
        raise RunFileError(f"{path}: missing; a run's {ENV_FILE} says what the model's actions mean (the env it was "
                           "trained in), how many observations it reads at once and whether they were normalised; "
                           "without it the model cannot be evaluated as it was trained")
    try:
        run = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, RecursionError) as error:  # (nested beyond Python's stack)
        raise RunFileError(f"{path}: not readable JSON ({type(error).__name__}: {error})") from error
    if not isinstance(run, dict) or not {"env_kwargs", "frame_stack"} <= set(run) or set(run) - ENV_FILE_KEYS:
        unknown = sorted(set(run) - ENV_FILE_KEYS) if isinstance(run, dict) else []
        raise RunFileError((f"{path}: must be a JSON object with the keys env_kwargs, frame_stack and optionally "
                            f"{', '.join(sorted(ENV_FILE_KEYS - {'env_kwargs', 'frame_stack'}))}"
                            + (f"; unknown keys {unknown}" if unknown else "") + f"; holds {run!r}")[:400])
    env_kwargs, frame_stack, normalize = run["env_kwargs"], run["frame_stack"], run.get("normalize")
    env_id, hidden_features = run.get("env_id", OLDER_RUNS_ENV_ID), run.get("hidden_features", [])
    algo = run.get("algo", "ppo")
    if algo not in ALGORITHMS:
        raise RunFileError(f"{path}: algo = {algo!r}: must be one of {list(ALGORITHMS)}")
    if algo == "ppo_lstm" and frame_stack != 1:
        raise RunFileError(f"{path}: algo = 'ppo_lstm' with frame_stack = {frame_stack}: a recurrent policy reads one "
                           "observation at a time")
    if not isinstance(env_kwargs, dict) or not isinstance(env_kwargs.get("config", {}) or {}, dict):
        raise RunFileError(f"{path}: env_kwargs = {env_kwargs!r}: must be an object (gym.make's keyword arguments, "
                           "the env's config among them)")
    if isinstance(frame_stack, bool) or not isinstance(frame_stack, int) or frame_stack < 1:
        raise RunFileError(f"{path}: frame_stack = {frame_stack!r}: must be an integer >= 1")
    if normalize is not None and not isinstance(normalize, bool):
        raise RunFileError(f"{path}: normalize = {normalize!r}: must be true or false")
    try:
        if not isinstance(env_id, str):
            raise ValueError(f"env_id = {env_id!r}: must be an env id (a string)")
        task = get_task(env_id)
    except ValueError as error:
        raise RunFileError(f"{path}: env_id = {env_id!r}: not a task of this env; known: {list(TASKS)}") from error
    try:
        task.config(env_kwargs.get("config"))
    except ValueError as error:
        raise RunFileError(f"{path}: env_kwargs.config is not a config of this env: {error}") from error
    from timegap_env.envs.observation import feature_columns

    try:
        if not isinstance(hidden_features, list) or not all(isinstance(name, str) for name in hidden_features):
            raise ValueError(f"hidden_features = {hidden_features!r}: must be a list of feature names")
        feature_columns(hidden_features)
    except ValueError as error:
        raise RunFileError(f"{path}: {error}") from error
    return RunEnv(path, env_kwargs, frame_stack, normalize, env_id, tuple(hidden_features), algo)


def check_spaces(run: RunEnv, action_space: Any, observation_shape: tuple[int, ...], model: str | Path) -> None:
    """``RunFileError`` naming ``run``'s file and ``model`` unless the model's action space is the env's (the same
    meaning of every action: a relative-mode Discrete(3) is not platoon mode's Discrete(9)) and its observations are
    the env's, ``run.frame_stack`` of them side by side."""
    from timegap_env.envs.action import action_space as env_action_space
    from timegap_env.envs.observation import observation_space

    config = run.config
    expected = env_action_space(config)
    if action_space != expected:
        raise RunFileError(f"{run.path} does not fit the model {model}: its env (action_mode = "
                           f"{config.action_mode!r}) has actions {expected}, the model {action_space}")
    *batch, width = observation_space(config).shape
    stacked = (*batch, width * run.frame_stack)
    if tuple(observation_shape) != stacked:
        raise RunFileError(f"{run.path} does not fit the model {model}: its env gives observations of shape "
                           f"{(*batch, width)}, with frame_stack = {run.frame_stack} the model would take {stacked}, "
                           f"it takes {tuple(observation_shape)}")
