"""Stable-Baselines3 adapter: the native vector ``TimeGapMonitor`` (v0 or v1) as an SB3 ``VecEnv``.

``TimeGapVecEnv(n_envs=16, config={...})`` steps all platoons in one batched NumPy
call (the native vector env, as ``gym.make_vec(..., vectorization_mode="vector_entry_point")`` builds it) instead of
N Python envs in a ``DummyVecEnv``, and follows SB3's conventions:

- ``reset()`` returns the observations only; seeds set by ``seed(s)`` (sub-env i
  gets ``s + i``) and options set by ``set_options`` apply to that reset only;
- ``step_wait()`` returns ``(obs, rewards float32, dones, infos)``, ``infos`` a list
  of N dicts, empty unless that platoon's episode ended; then the done env is
  already reset (``obs[i]`` is the new episode's) and ``infos[i]`` holds
  ``terminal_observation``, ``TimeLimit.truncated``, ``episode`` =
  ``{"r": return, "l": length [steps], "t": time since creation [s]}`` (as
  ``Monitor`` writes it) and the env's summary ``episode_<name>`` (Python numbers, so
  that loggers can write them). The native env's per-step diagnostics (reward terms, estimates,
  ...) are not passed on.

Sub-env i seeded with ``s + i`` equals ``gym.make(task_id)`` seeded
with ``s + i`` in a ``DummyVecEnv``, step by step.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvIndices, VecEnvStepReturn

from timegap_env.envs.info import of_env
from timegap_env.envs.observation import feature_columns, hidden
from timegap_env.envs.vector_env import TimeGapMonitorVectorEnv
from timegap_env.tasks import DEFAULT_TASK


class TimeGapVecEnv(VecEnv):
    """``n_envs`` platoons of a ``TimeGapMonitor`` task behind SB3's ``VecEnv`` API.

    ``config`` overrides the config of task ``task_id`` (default: ``DEFAULT_TASK``) as in ``gym.make(task_id)``; ``hidden_features`` (names of the
    observation's features) are read as 0 in every observation, an ablation of what a policy may see; a
    ``cost_weight`` (attribute, default 0) takes that many times the env's step cost (``venv.step_cost``) off every
    reward, for a Lagrangian learner;
    ``max_episode_steps``, optional, cuts episodes shorter than ``episode_duration``.

    The sub-envs are rows of one native vector env, not objects of their own:
    ``get_attr``, ``set_attr`` and ``env_method`` reach that shared vector env
    (``self.venv``), so a value is the same for every index, and ``set_attr`` and
    ``env_method`` must address all envs. ``env_is_wrapped(Monitor)`` is True because
    the adapter records ``Monitor``'s episode statistics itself; no other wrapper is applied.
    """

    def __init__(
        self, n_envs: int = 1, config: Mapping[str, Any] | None = None, max_episode_steps: int | None = None,
        task_id: str = DEFAULT_TASK, hidden_features: tuple[str, ...] = (),
    ) -> None:
        feature_columns(hidden_features)  # checked before any work
        self.venv = TimeGapMonitorVectorEnv(num_envs=n_envs, config=config, max_episode_steps=max_episode_steps,
                                            step_diagnostics=False, autoreset_mode="same_step", task_id=task_id)
        super().__init__(n_envs, self.venv.single_observation_space, self.venv.single_action_space)
        self.config = self.venv.config
        self._actions: np.ndarray | None = None
        self._returns = np.zeros(n_envs)  # of the running episodes [-]
        self._lengths = np.zeros(n_envs, dtype=np.int64)  # of the running episodes [steps]
        self._t_start = time.time()  # [s]
        self.hidden_features = tuple(hidden_features)  # read as 0 in every observation (an ablation)
        self.cost_weight = 0.0  # the rewards returned are the env's minus this times its step cost (a Lagrangian)

    def reset(self) -> np.ndarray:
        seeds = None if all(seed is None for seed in self._seeds) else list(self._seeds)
        options = self._options[0]
        if any(other != options for other in self._options[1:]):
            raise ValueError(f"options = {self._options}: the sub-envs share one reset, so they need the same options")
        obs, _ = self.venv.reset(seed=seeds, options=options or None)
        self._reset_seeds()
        self._reset_options()
        self._returns[:] = 0.0
        self._lengths[:] = 0
        return hidden(obs, self.hidden_features) if self.hidden_features else obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self) -> VecEnvStepReturn:
        if self._actions is None:
            raise RuntimeError("step_wait() called without step_async(actions)")
        obs, reward, terminated, truncated, info = self.venv.step(self._actions)
        self._actions = None
        dones = terminated | truncated
        self._returns += reward  # the env's: the episode statistics stay the env's whatever the cost weight
        self._lengths += 1
        infos: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        if dones.any():
            elapsed = round(time.time() - self._t_start, 6)
            for i in np.flatnonzero(dones):
                infos[i] = {
                    "terminal_observation": hidden(info["final_obs"][i], self.hidden_features),
                    "TimeLimit.truncated": bool(truncated[i] and not terminated[i]),
                    "episode": {"r": round(float(self._returns[i]), 6), "l": int(self._lengths[i]), "t": elapsed},
                    **{key: value.item() for key, value in of_env(info["final_info"], int(i)).items()},
                }
            self._returns[dones] = 0.0
            self._lengths[dones] = 0
        if self.cost_weight:
            reward = reward - self.cost_weight * self.venv.step_cost
        return hidden(obs, self.hidden_features) if self.hidden_features else obs, reward.astype(np.float32), dones, infos

    def close(self) -> None:
        self.venv.close()

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        """The shared vector env's attribute, once per index; AttributeError if it has none."""
        value = getattr(self.venv, attr_name)
        return [value for _ in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        """Set an attribute of the shared vector env; ``indices`` must address every env."""
        self._require_all(indices, "set_attr")
        setattr(self.venv, attr_name, value)

    def env_method(
        self, method_name: str, *method_args: Any, indices: VecEnvIndices = None, **method_kwargs: Any
    ) -> list[Any]:
        """Call a method of the shared vector env once (``indices`` must address every env); its result once per env."""
        self._require_all(indices, "env_method")
        result = getattr(self.venv, method_name)(*method_args, **method_kwargs)
        return [result for _ in range(self.num_envs)]

    def env_is_wrapped(self, wrapper_class: type[gym.Wrapper], indices: VecEnvIndices = None) -> list[bool]:
        return [wrapper_class is Monitor for _ in self._get_indices(indices)]

    def _require_all(self, indices: VecEnvIndices, method: str) -> None:
        if sorted(int(i) for i in self._get_indices(indices)) != list(range(self.num_envs)):
            raise ValueError(f"{method}: indices = {indices!r}: the sub-envs share one vector env, "
                             f"so address all {self.num_envs}")


__all__ = ["TimeGapVecEnv"]
