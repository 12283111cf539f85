"""``TimeGapMonitor-v1`` (and every task of ``timegap_env.tasks``): choose automated vehicles' time gap setting from a Bayesian monitor's view of it."""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import gymnasium as gym
from gymnasium.error import ResetNeeded
import numpy as np

from timegap_env.config import shown
from timegap_env.envs.action import action_space
from timegap_env.envs.info import EPISODE_PREFIX, EnvInfoPool, EnvInfoSet, info_flags, of_env, prefixed
from timegap_env.envs.observation import observation_space
from timegap_env.envs.rendering import DEFAULT_TIME_WINDOW
from timegap_env.envs.task import PlatoonTask
from timegap_env.tasks import DEFAULT_TASK, OneTask, get_task

if TYPE_CHECKING:
    from timegap_env.envs.rendering import PlatoonRenderer


class TimeGapMonitorEnv(OneTask, gym.Env):
    """
    ## Description

    A human-driven leader and N automated followers (default 5) drive a single
    lane at 10 Hz. Each follower runs a constant-time-headway controller with a
    time gap setting tau*; its *actual* time gap drifts from tau* when the
    leader accelerates and brakes. A closed-form Bayesian monitor (Kontar & Ahn)
    estimates every follower's actual time gap from its own noisy spacing and
    speed measurements, and a Shewhart chart raises alarms when the estimate
    leaves [tau* - L sigma, tau* + L sigma]. The agent sees the monitor and the
    charts and chooses the settings: small settings carry more traffic and, with
    V2V, track better; without V2V (ACC) small settings are string unstable.

    ## Action Space

    An index into ``setting_levels`` (default 0.6, 0.8, ..., 2.2 s).
    ``action_mode="platoon"``: ``Discrete(L)``, one setting for every follower;
    ``action_mode="per_vehicle"``: ``MultiDiscrete([L] * N)``;
    ``action_mode="relative"``: ``Discrete(3)``, the platoon's setting one level
    down (0), kept (1) or one level up (2), clipped to the ladder. A new setting is
    ramped by the controller (``platoon.setting_ramp_rate``) and re-centres that
    follower's prior and chart. An action outside the space raises ``ValueError``.

    ## Observation Space

    ``Box(low, high, (N * 9,), float32)``: nine features per follower, follower 1
    first (``obs.reshape(N, 9)`` gives one row per follower):

    | Num | Feature          | Meaning                                                    | Min | Max |
    |-----|------------------|------------------------------------------------------------|-----|-----|
    | 0   | deviation        | (posterior mean of tau - centre line tau*) / 1 s           | -1  | 1   |
    | 1   | estimate_std     | posterior std of tau / (L sigma)                           | 0   | 1   |
    | 2   | prob_outside     | posterior P(tau outside [LCL, UCL])                        | 0   | 1   |
    | 3   | alarm            | 1 while the chart is in alarm                              | 0   | 1   |
    | 4   | exceedances      | exceedances in the trailing window / (2 k)                 | 0   | 1   |
    | 5   | time_since_alarm | time since the last alarm / exceedance window              | 0   | 1   |
    | 6   | setting          | (tau* - smallest level) / (largest - smallest level)       | 0   | 1   |
    | 7   | speed            | own speed / 40 m/s                                         | 0   | 1   |
    | 8   | v2v              | 1 in CACC (V2V on), 0 in ACC                                | 0   | 1   |

    Values are clipped to these bounds; ``timegap_env.envs.observation`` encodes them
    and ``decode_observation`` reads them back.

    ## Rewards

    A weighted sum of named terms (the fields of :class:`timegap_env.config.RewardWeights`: tracking,
    string stability, safety, collision, comfort, ...), each <= 0 and about -1 at its worst, each in
    ``info["reward_<term>"]``. They judge the true state, never the monitor. Their formulas and the
    reasons for the default weights are in :mod:`timegap_env.envs.reward`; the weights are
    ``config["reward_weights"]``, the scales of one unit of each ``config["reward_scales"]``
    (:class:`timegap_env.config.RewardScales`).

    ## Info

    Flat and numeric, the same keys from reset on (:mod:`timegap_env.envs.info`): the monitor's
    view (``estimate``, ``estimate_std``, ``setting``, ``lcl``, ``ucl``, ``alarm``, ``v2v``,
    ``skipped_measurements``), ``reward_<term>`` (0 at reset), and at the step that ends an episode
    its summary ``episode_<name>``. ``truth_info=True`` adds what only the simulator knows: the
    platoon's true state (``actual_time_gap``, ``ttc``, ``jerk``, ``collision``) and the ground truth
    ``truth_<name>``, which oracles read. ``timegap_env.envs.info.truth_of(info)`` and
    ``summary_of(info)`` read the groups back as dicts. ``env.unwrapped.scenario`` names the leader. v1's
    info layout (``Task.info_layout``) adds ``vector_reward``, ``cost``, ``objectives`` (and with ``truth_info``
    ``truth_regime``). The step writes the info's values into arrays the env reuses, but only once nothing
    references them any more (:class:`timegap_env.envs.info.EnvInfoPool`): an info you keep, or a value or view of
    it, never changes.

    ## Starting State

    Each reset draws a leader from ``scenario_weights`` (default: aggressive cycles,
    sinusoid, hard braking, stochastic human driving, 250 s in 20-80 mph), a degradation
    of some followers from ``degradation`` (:class:`timegap_env.config.DegradationConfig`:
    a longer actuation lag, a lower gain, V2V latency or packet loss, a V2V outage, a biased
    or noisy radar, commercial ACC cars, or none; only the outage shows in the V2V flag) and
    a sensor dropout rate (0-5 %), all from the env's seed. The followers start in equilibrium
    at ``platoon.initial_setting`` (1.6 s; with ``random_initial_setting``, at a ladder level drawn
    from the seed). ``reset(options={"scenario": name})`` picks a family
    (see ``timegap_env.SCENARIOS``, e.g. ``"ngsim_in_band"``, ``"idm"``);
    ``reset(options={"leader_speed": array})`` runs your own leader speed series
    [m/s at 10 Hz]; ``reset(options={"degradation": {"kind": "gain", "size": 0.7,
    "followers": [1, 2], "onset": 60.0, "end": None}})`` pins the degradation (a list of such
    dicts for several, None for none; see :mod:`timegap_env.sim.degradation`).
    ``truth_of(info)`` (with ``truth_info=True``) is the ground truth of every step: each
    follower's degradation, its true parameters and the smallest string-stable setting for them.
    It is for oracles and evaluation; the observation never holds it.

    ## Episode End

    Terminated when a follower's gap reaches 0 (collision). Truncated when the
    leader profile or ``episode_duration`` (default 250 s = 250 steps) runs out; the env
    truncates itself, so a longer ``episode_duration`` needs nothing else. ``step()`` after
    the end (or before the first ``reset()``) raises gymnasium's ``ResetNeeded``.

    ## Arguments

    ``gym.make("TimeGapMonitor-v1", config={...}, render_mode=None | "rgb_array" | "human", step_diagnostics=True,
    truth_info=False)``;
    ``config`` overrides the task's config (its record in ``timegap_env.tasks.TASKS``: overrides of
    :class:`timegap_env.config.EnvConfig`, units in its comments; ``task_id`` is the registered id's, and no other
    may be given under it), nested configs as dicts, e.g. ``{"action_mode": "per_vehicle", "platoon": {"n_followers": 3}}``.
    Unknown keys and bad values raise ``ValueError``. ``step_diagnostics=False`` leaves the per-step keys
    (monitor, reward terms) out of ``reset``'s and ``step``'s info, for learners that never read them; the
    episode summary stays. ``truth_info=True`` adds the platoon's true state and the ground truth (see Info);
    working out the ground truth costs several times the rest of a step, so it is off unless asked for.

    ## Version History

    * Since 2026-11-27 (issue 27) the ground truth and the platoon's true state are in the info only with
      ``truth_info=True`` (every version; episodes are unchanged bit for bit).
    * Since 2026-12-05 (issue 38) a task is one record (``timegap_env.tasks``) and the env takes its id
      (``task_id``), not a version number; ``EnvConfig.info_keys`` is gone (the layout is the task's).
      Built directly, the class gives ``DEFAULT_TASK`` (v1). Episodes are unchanged bit for bit.
    * v1: the default task (``timegap_env.tasks.TASKS["TimeGapMonitor-v1"]``, docs/task.md): the ``variation_first`` reward weighting,
      the ``regimes`` leader family beside v0's four, and in the info ``vector_reward`` (the terms; the reward is
      the weights times it), ``cost``, ``objectives`` (natural units) and ``truth_regime``.
      ``mo-TimeGapMonitor-v1`` returns the terms as the reward vector.
    * v0: initial version, kept bit for bit.
    """

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 10}

    def __init__(self, config: Mapping[str, Any] | None = None, render_mode: str | None = None,
                 step_diagnostics: bool = True, task_id: str = DEFAULT_TASK, truth_info: bool = False) -> None:
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode = {render_mode!r}: must be None or one of {self.metadata['render_modes']}")
        record = get_task(task_id)
        self.task_id = record.id
        self.config = record.config(config)
        self.render_mode = render_mode
        self.task = PlatoonTask(self.config, n_envs=1, info_layout=record.info_layout)
        if render_mode is not None:
            self.task.start_trace()
        self.observation_space = observation_space(self.config)
        self.action_space = action_space(self.config)
        self._renderer: PlatoonRenderer | None = None
        self._needs_reset = True  # step() before reset() or after the episode ended raises gymnasium's ResetNeeded
        self.step_diagnostics, self.truth_info = info_flags(step_diagnostics, truth_info)
        self._action = np.zeros((1, 1), dtype=np.int64)  # a Discrete action, as the task takes it
        self._infos = EnvInfoPool(self.config.platoon.n_followers, record.info_layout)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        self._needs_reset = True  # stays so if the reset below raises (a bad seed too)
        super().reset(seed=seed)
        self.task.reset(np.ones(1, dtype=bool), [self.np_random], options)
        self._needs_reset = False
        if self.task.trace is not None:
            self.task.trace.clear()
        info = {}
        if self.step_diagnostics:
            info_set = self._infos.take()
            self.task.write_info(info_set.block, scored=False)
            info = self._info(info_set)
        return self.task.observation().ravel(), info

    def __getstate__(self) -> dict[str, Any]:
        """For copy and pickle: everything but the renderer (pygame surfaces and fonts do not pickle), which the next
        render() builds again."""
        return {**self.__dict__, "_renderer": None}

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict]:
        if self._needs_reset:
            raise ResetNeeded("TimeGapMonitorEnv.step() called before reset() or after the episode ended "
                              "(terminated or truncated): call reset() first")
        info_set = self._infos.take() if self.step_diagnostics else None
        result = self.task._run_step(self._checked(action), None if info_set is None else info_set.block)
        info = {} if info_set is None else self._info(info_set)
        terminated, truncated = bool(result.terminated[0]), bool(result.truncated[0])
        if terminated or truncated:
            info.update(of_env(prefixed(EPISODE_PREFIX, self.task.episode_summary()), 0))
            self._needs_reset = True
        if self.render_mode == "human":
            self.render()
        return self.task.observation().ravel(), float(result.reward[0]), terminated, truncated, info  # its one env's

    def _checked(self, action: Any) -> np.ndarray:
        """``action`` as the task takes it, int64 (1, 1) or (1, N); ``ValueError`` unless the action space's ``contains``
        takes it (gymnasium's rule: Python bools are 0 and 1, NumPy bools and floats are not actions of a Discrete)."""
        if isinstance(self.action_space, gym.spaces.Discrete) and isinstance(action, (int, np.integer)) \
                and 0 <= action < self.action_space.n:
            self._action[0, 0] = action  # the common case, without NumPy's checks
            return self._action
        if not self.action_space.contains(action):
            raise ValueError(f"action = {shown(action)} is outside the action space {self.action_space}")
        return self.task.ladder.check(np.asarray(action, dtype=np.int64)[None])

    @property
    def scenario(self) -> str:
        """The name of the current episode's leader (a family of ``timegap_env.SCENARIOS``, NGSIM's, or "user")."""
        return str(self.task.scenario[0])

    def _info(self, info_set: EnvInfoSet) -> dict[str, np.ndarray]:
        """The per-step info, its values ``info_set``'s (just written): the monitor's view and the scores, and with
        ``truth_info`` the platoon's true state and the ground truth between them (:mod:`timegap_env.envs.info`)."""
        if self.truth_info:  # truth_info's arrays are fresh: views of their rows suffice
            return {**info_set.monitor, **of_env(self.task.truth_info(), 0, copy=False), **info_set.scored}
        return info_set.info.copy()

    def render(self) -> np.ndarray | None:
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode='rgb_array' or 'human'")
            return None
        from timegap_env.envs.rendering import PlatoonRenderer

        if self._renderer is None:
            self._renderer = PlatoonRenderer(self.config.platoon.n_followers)
        frame = self.task.render_frame(history=DEFAULT_TIME_WINDOW)
        if self.render_mode == "human":
            self._renderer.show(frame)
            return None
        return self._renderer.render(frame)

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
        self.task.close()
