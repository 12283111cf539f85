"""A native vector ``TimeGapMonitor-v0``: N platoons stepped in the same calls.

``gym.make_vec("TimeGapMonitor-v0", num_envs=N, vectorization_mode="vector_entry_point")``.
Sub-env i seeded with ``seed + i`` equals a single env seeded with ``seed + i``,
step by step, and the whole equals ``SyncVectorEnv`` over single envs with the same
``autoreset_mode`` (observations, rewards, flags and infos).
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from gymnasium.error import ResetNeeded
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from timegap_env.config import shown
from timegap_env.envs.action import action_space
from timegap_env.envs.info import (
    EPISODE_PREFIX, TRUTH_PREFIX, info_flags, no_scores, prefixed, step_scores, truth_of, with_masks,
)
from timegap_env.envs.episodes import RESET_OPTIONS
from timegap_env.envs.observation import observation_space
from timegap_env.envs.task import PlatoonTask
from timegap_env.generators import generators, unseeded_generators
from timegap_env.tasks import DEFAULT_TASK, OneTask, get_task


def available_memory() -> int | None:
    """Bytes of memory the system can give now without swapping (Linux's MemAvailable, else the free pages), None if
    neither can be read [B]."""
    try:
        with open("/proc/meminfo") as meminfo:
            for line in meminfo:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, AttributeError):
        return None


def check_fits(num_envs: int, bytes_per_env: int, available: int | None) -> None:
    """``ValueError`` naming ``num_envs`` and what it costs when ``num_envs`` sub-envs of ``bytes_per_env`` [B] each
    need more than ``available`` [B] (None: unknown, nothing refused)."""
    needed = num_envs * bytes_per_env
    if available is not None and needed > available:
        gigabytes = f"{needed / 1e9:.3g}" if needed < 1e300 else "more than 1e291"
        raise ValueError(f"num_envs = {shown(num_envs)}: the sub-envs' state needs about {gigabytes} GB "
                         f"({bytes_per_env / 1e3:.3g} kB each with this config), more than the {available / 1e9:.3g} GB "
                         "of memory available now; use fewer envs (or a shorter episode_duration, fewer followers)")


def parse_autoreset_mode(mode: str | AutoresetMode) -> AutoresetMode:
    """gymnasium's AutoresetMode from itself, its value ("SameStep") or its name ("same_step")."""
    if isinstance(mode, AutoresetMode):
        return mode
    for known in AutoresetMode:
        if mode in (known.value, known.name.lower()):
            return known
    raise ValueError(f"autoreset_mode = {mode!r}: must be one of {[known.name.lower() for known in AutoresetMode]}")


class TimeGapMonitorVectorEnv(OneTask, VectorEnv):
    """``num_envs`` copies of :class:`~timegap_env.envs.env.TimeGapMonitorEnv` of task ``task_id`` in one batched task.

    Its infos are what gymnasium's own vector envs make of the single env's flat info
    (:mod:`timegap_env.envs.info`): each key an array with a leading num_envs axis and a ``_<key>`` mask.
    ``autoreset_mode`` (gymnasium's :class:`~gymnasium.vector.AutoresetMode` or its name) says what
    happens when a sub-env's episode ends, as in ``SyncVectorEnv``:

    - ``"next_step"`` (default, as in gymnasium's own vector envs): the step returns the last observation and info
      (with ``episode_<name>``); the next step ignores that sub-env's action and returns its reset (reward 0, not
      terminated or truncated);
    - ``"same_step"`` (what Stable-Baselines3 expects; :class:`~timegap_env.envs.sb3.TimeGapVecEnv` uses it): it is
      reset in the same step; the returned observation and infos are the new episode's, the last observation is in
      ``infos["final_obs"]`` (an object array of float32 rows, None where no episode ended) and the last step's
      info, its summary ``episode_<name>`` included, in ``infos["final_info"]``;
    - ``"disabled"``: the caller resets ended sub-envs with ``reset(options={"reset_mask": mask})``;
      stepping one before raises ``ResetNeeded``.

    A ``reset`` that raises leaves the sub-envs it was to reset (every one, if it raised before its mask was read)
    refusing to step, with ``ResetNeeded``, until a reset of theirs succeeds, as a single env does.

    ``step_diagnostics=False`` leaves the per-step keys (monitor, reward terms) out of ``reset``'s and
    ``step``'s infos, for learners that never read them; the episode summaries stay. ``truth_info=True`` adds the
    platoon's true state and the ground truth (``truth_<name>``, what oracles read); without it the ground truth
    is never worked out (its smallest string-stable settings take milliseconds per episode) unless
    :meth:`ground_truth` asks.
    """

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": []}

    def __init__(
        self,
        num_envs: int = 1,
        config: Mapping[str, Any] | None = None,
        max_episode_steps: int | None = None,
        step_diagnostics: bool = True,
        autoreset_mode: str | AutoresetMode = AutoresetMode.NEXT_STEP,
        task_id: str = DEFAULT_TASK,
        truth_info: bool = False,
    ) -> None:
        if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)) or num_envs < 1:
            raise ValueError(f"num_envs = {shown(num_envs)}: must be an integer >= 1")
        self.autoreset_mode = parse_autoreset_mode(autoreset_mode)
        self.metadata = {**type(self).metadata, "autoreset_mode": self.autoreset_mode}
        self.num_envs = int(num_envs)
        record = get_task(task_id)
        self.task_id, self.info_layout = record.id, record.info_layout
        self.config = record.config(config)
        check_fits(self.num_envs, PlatoonTask.bytes_per_env(self.config), available_memory())
        self.max_episode_steps = max_episode_steps or self.config.max_episode_steps
        self.task = PlatoonTask(self.config, self.num_envs, info_layout=self.info_layout)
        self.single_observation_space = observation_space(self.config)
        self.single_action_space = action_space(self.config)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._rngs = unseeded_generators(self.num_envs)
        self._steps = np.zeros(self.num_envs, dtype=np.int64)
        self.step_diagnostics, self.truth_info = info_flags(step_diagnostics, truth_info)
        self._was_reset = False  # step() before the first reset() raises gymnasium's ResetNeeded
        self._ended = np.zeros(self.num_envs, dtype=bool)  # episodes that ended and are not reset yet
        self._half_reset = np.zeros(self.num_envs, dtype=bool)  # sub-envs whose last reset raised: step() refuses
        self.step_cost = np.zeros(self.num_envs)  # the last step's cost per sub-env (reward.COST_TERMS; 0 for a
        # next-step autoreset), whatever step_diagnostics and the info keys: for constrained learners

    @property
    def scenario(self) -> np.ndarray:
        """The name of each sub-env's current leader (num_envs,) object array of str."""
        return self.task.scenario.copy()

    def reset(
        self, *, seed: int | Sequence[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Reset every sub-env, or those of ``options["reset_mask"]`` ((num_envs,) bool); sub-env i is seeded
        with ``seed + i`` (an int) or ``seed[i]`` (a list); other options as the single env's."""
        mask = np.ones(self.num_envs, dtype=bool)  # until the options say which
        try:  # a reset that raises leaves its sub-envs (all, if it did not get as far as the mask) refusing to step
            if options is not None and not isinstance(options, Mapping):
                raise ValueError(f"reset options = {shown(options)}: must be a dict with keys among "
                                 f"{list(RESET_OPTIONS)} and 'reset_mask'")
            options = dict(options or {})
            mask = self._reset_mask(options.pop("reset_mask", None))
            seeds = self._seeds(seed)
            seeded = [env for env in np.flatnonzero(mask).tolist() if seeds[env] is not None]  # unseeded, a sub-env's
            # generator carries on, as a single env's would
            for env in seeded:
                seed_of_env = seeds[env]
                if not (isinstance(seed_of_env, int) and seed_of_env >= 0):
                    seeding.np_random(seed_of_env)  # raises gymnasium's error for this seed
            for env, rng in zip(seeded, generators([seeds[env] for env in seeded])):  # np_random(seed)'s generators
                self._rngs[env] = rng
            self._reset_task(mask, options or None)
        except BaseException:
            self._half_reset |= mask & self._was_reset
            raise
        self._was_reset = True
        self._steps[mask] = 0
        self._ended[mask] = False
        if not self.step_diagnostics:
            return self._observations(), {}
        infos = {**self.task.step_info(self.truth_info), **no_scores(self.num_envs, self.info_layout)}
        return self._observations(), with_masks(infos, mask)

    def ground_truth(self) -> dict[str, np.ndarray]:
        """The ground truth now, as :func:`~timegap_env.envs.info.truth_of` reads it from an info (``kind`` as
        names), arrays (num_envs, n_followers), whatever ``step_diagnostics`` and ``truth_info`` put in the infos: for oracles and
        evaluation, never in the observation."""
        return truth_of(prefixed(TRUTH_PREFIX, self.task.ground_truth()))

    def _seeds(self, seed: int | Sequence[int | None] | None) -> list[int | None]:
        """Each sub-env's seed: None, ``seed + i`` for an int, ``seed[i]`` for a list."""
        if seed is None:
            return [None] * self.num_envs
        if isinstance(seed, (int, np.integer)):
            return [int(seed) + i for i in range(self.num_envs)]
        seeds = list(seed)
        if len(seeds) != self.num_envs:
            raise ValueError(f"seed has {len(seeds)} entries: must have num_envs = {self.num_envs}")
        return seeds

    def _reset_mask(self, mask: Any) -> np.ndarray:
        if mask is None:
            return np.ones(self.num_envs, dtype=bool)
        mask = np.asarray(mask)
        if mask.shape != (self.num_envs,) or mask.dtype != np.bool_ or not mask.any():
            raise ValueError(f"options['reset_mask'] = {mask!r}: must be a bool array of shape ({self.num_envs},) "
                             "with at least one True")
        if not self._was_reset and not mask.all():
            raise ResetNeeded("the first reset() must reset every sub-env: options['reset_mask'] has False entries")
        return mask

    def step(self, actions: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        if not self._was_reset:
            raise ResetNeeded("TimeGapMonitorVectorEnv.step() called before reset(): call reset() first")
        if self._half_reset.any():
            raise ResetNeeded(f"sub-envs {np.flatnonzero(self._half_reset).tolist()} are half reset (their last reset "
                              "raised): reset them first, e.g. reset(options={'reset_mask': mask})")
        restarting = self._ended.copy()
        if restarting.any() and self.autoreset_mode == AutoresetMode.DISABLED:
            raise ResetNeeded(f"sub-envs {np.flatnonzero(restarting).tolist()} ended and autoreset_mode is "
                              "'disabled': reset them first with reset(options={'reset_mask': mask})")
        result = self.task.step(np.asarray(actions))  # checks them against the action space
        self._steps += 1
        done = (result.terminated | result.truncated | (self._steps >= self.max_episode_steps)) & ~restarting
        terminated, truncated = result.terminated & done, ~result.terminated & done
        reward, terms, objectives = result.reward.copy(), result.term_rows.copy(), _copied(self.task.objectives())
        self.step_cost = result.cost.copy()
        if restarting.any():  # next_step: their step above ran past the episode's end and is dropped
            self._reset_task(restarting, None)
            self._steps[restarting] = 0
            reward[restarting] = self.step_cost[restarting] = 0.0
            _zero(terms, objectives, restarting)
        everyone = np.ones(self.num_envs, dtype=bool)
        infos: dict[str, Any] = {}
        if self.autoreset_mode == AutoresetMode.SAME_STEP and done.any():
            final_info = prefixed(EPISODE_PREFIX, self.task.episode_summary())
            if self.step_diagnostics:
                final_info = {**self.task.step_info(self.truth_info), **step_scores(terms, objectives), **final_info}
            final_obs = np.full(self.num_envs, None, dtype=object)
            for env, row in zip(np.flatnonzero(done), self._observations()[done]):
                final_obs[env] = row
            infos = {"final_obs": final_obs, "_final_obs": done.copy(),
                     "final_info": with_masks(final_info, done), "_final_info": done.copy()}
            self._reset_task(done, None)
            self._steps[done] = 0
            terms, objectives = terms.copy(), _copied(objectives)  # final_info keeps the step's; the envs just
            _zero(terms, objectives, done)  # reset get the reset's, as reset() gives
        if self.step_diagnostics:
            infos.update(with_masks({**self.task.step_info(self.truth_info), **step_scores(terms, objectives)}, everyone))
        if self.autoreset_mode != AutoresetMode.SAME_STEP:
            if done.any():
                infos.update(with_masks(prefixed(EPISODE_PREFIX, self.task.episode_summary()), done))
            self._ended = done
        return self._observations(), reward, terminated, truncated, infos

    def _reset_task(self, mask: np.ndarray, options: dict[str, Any] | None) -> None:
        """Reset the task's envs of ``mask``; if that raises, they are half reset and :meth:`step` refuses until a
        reset of theirs succeeds."""
        self._half_reset |= mask
        self.task.reset(mask, self._rngs, options)
        self._half_reset &= ~mask

    def _observations(self) -> np.ndarray:
        return self.task.observation().reshape(self.num_envs, -1)

    def close_extras(self, **kwargs: Any) -> None:
        """End what the simulator holds (SUMO's simulation)."""
        self.task.close()


def _copied(objectives: tuple[np.ndarray, np.ndarray] | None) -> tuple[np.ndarray, np.ndarray] | None:
    """A copy of the objectives and cost of ``PlatoonTask.objectives`` (None stays None)."""
    return None if objectives is None else (objectives[0].copy(), objectives[1].copy())


def _zero(terms: np.ndarray, objectives: tuple[np.ndarray, np.ndarray] | None, mask: np.ndarray) -> None:
    """The scores of the envs of ``mask`` set to 0 in place: the terms (n_terms, num_envs), the objectives and cost."""
    terms[:, mask] = 0.0
    if objectives is not None:
        objectives[0][:, mask] = 0.0
        objectives[1][mask] = 0.0


__all__ = ["TimeGapMonitorVectorEnv"]
