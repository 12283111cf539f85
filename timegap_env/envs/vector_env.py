"""A native vector ``TimeGapMonitor-v0``: N platoons stepped in the same calls.

``gym.make_vec("TimeGapMonitor-v0", num_envs=N, vectorization_mode="vector_entry_point")``.
Sub-env i seeded with ``seed + i`` equals a single env seeded with ``seed + i``,
step by step (same-step autoreset, as ``SyncVectorEnv(..., autoreset_mode=SAME_STEP)``).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from gymnasium.error import ResetNeeded
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from timegap_env.config import EnvConfig
from timegap_env.envs.action import action_space
from timegap_env.envs.observation import observation_space
from timegap_env.envs.task import PlatoonTask


class TimeGapMonitorVectorEnv(VectorEnv):
    """``num_envs`` copies of :class:`~timegap_env.envs.env.TimeGapMonitorEnv` in one batched task.

    When a sub-env's episode ends, it is reset in the same step: the returned
    observation is the new episode's, the last one is in ``infos["final_obs"]``
    and its summary in ``infos["episode_summary"]`` (masks ``_final_obs`` and
    ``_episode_summary``). ``infos["degradation"]`` is the ground truth of the
    returned observations (after the autoresets). ``step_diagnostics=False`` leaves
    the per-step diagnostics (estimates, limits, reward terms, ground truth, ...) out
    of ``step``'s infos, for learners that never read them.
    """

    metadata = {"autoreset_mode": AutoresetMode.SAME_STEP, "render_modes": []}

    def __init__(
        self,
        num_envs: int = 1,
        config: Mapping[str, Any] | None = None,
        max_episode_steps: int | None = None,
        step_diagnostics: bool = True,
    ) -> None:
        if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)) or num_envs < 1:
            raise ValueError(f"num_envs = {num_envs!r}: must be an integer >= 1")
        self.num_envs = int(num_envs)
        self.config = EnvConfig.from_dict(config)
        self.max_episode_steps = max_episode_steps or self.config.max_episode_steps
        self.task = PlatoonTask(self.config, self.num_envs)
        self.single_observation_space = observation_space(self.config)
        self.single_action_space = action_space(self.config)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._rngs = [seeding.np_random()[0] for _ in range(self.num_envs)]
        self._steps = np.zeros(self.num_envs, dtype=np.int64)
        self.step_diagnostics = bool(step_diagnostics)
        self._was_reset = False  # step() before the first reset() raises gymnasium's ResetNeeded

    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        if seed is None:
            seeds: list[int | None] = [None] * self.num_envs
        elif isinstance(seed, (int, np.integer)):
            seeds = [int(seed) + i for i in range(self.num_envs)]
        else:
            seeds = list(seed)
            if len(seeds) != self.num_envs:
                raise ValueError(f"seed has {len(seeds)} entries: must have num_envs = {self.num_envs}")
        if seed is not None:  # otherwise each sub-env's generator carries on, as a single env's would
            self._rngs = [seeding.np_random(s)[0] for s in seeds]
        everyone = np.ones(self.num_envs, dtype=bool)
        self.task.reset(everyone, self._rngs, options)
        self._was_reset = True
        self._steps[:] = 0
        return self._observations(), self._infos()

    def step(self, actions: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        if not self._was_reset:
            raise ResetNeeded("TimeGapMonitorVectorEnv.step() called before reset(): call reset() first")
        result = self.task.step(np.asarray(actions))  # checks them against the action space
        self._steps += 1
        truncated = result.truncated | ((self._steps >= self.max_episode_steps) & ~result.terminated)
        infos: dict[str, Any] = {}
        if self.step_diagnostics:
            infos = self._infos()
            infos["rewards"] = result.terms
        done = result.terminated | truncated
        if done.any():
            infos["final_obs"] = np.array(list(self._observations()), dtype=object)
            infos["_final_obs"] = done
            infos["episode_summary"] = self.task.episode_summary()
            infos["_episode_summary"] = done
            self.task.reset(done, self._rngs, None)
            self._steps[done] = 0
        if self.step_diagnostics:
            infos["degradation"] = self.task.ground_truth()
        return self._observations(), result.reward, result.terminated, truncated, infos

    def _observations(self) -> np.ndarray:
        return self.task.observation().reshape(self.num_envs, -1)

    def _infos(self) -> dict[str, Any]:
        infos: dict[str, Any] = self.task.info()
        infos["scenario"] = self.task.scenario.copy()
        infos["degradation"] = self.task.ground_truth()
        return infos


__all__ = ["TimeGapMonitorVectorEnv"]
