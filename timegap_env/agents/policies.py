"""Hand-written policies for ``TimeGapMonitor-v0``: the paper's rule, a chart-driven step rule, fixed settings, a
V2V-aware heuristic.

Every policy here has stable-baselines3's interface,
``predict(obs, state=None, episode_start=None, deterministic=True) -> (action, state)``,
so one evaluation loop runs them and trained SB3 models alike (see ``timegap_env.agents.learned``).
``obs`` is one observation (obs_dim,) or a batch (n_envs, obs_dim); the action is
shaped like SB3's: ``()`` or ``(n_envs,)`` for ``action_mode="platoon"``,
``(N,)`` or ``(n_envs, N)`` for ``"per_vehicle"``, ladder indices (int64).

The policies are stateless: they read all they need from the observation
(:func:`timegap_env.envs.observation.decode_observation`, :func:`time_since_alarm`), never from the env,
and return ``state`` unchanged.
Each is built for one :class:`EnvConfig` (the env's), which fixes the action
mode, the ladder of settings and the scaling of the features.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, NamedTuple, Protocol, runtime_checkable

import numpy as np

from timegap_env.config import EnvConfig
from timegap_env.envs.observation import FEATURES, FollowerView, decode_observation, exceedance_scale
from timegap_env.monitoring.charts import switch_rule
from timegap_env.tasks import DEFAULT_TASK, get_task

V2V_SETTING = 1.0  # string stable with V2V (CACC) from 1.0 s with the default gains [s]
ACC_SETTING = 1.6  # string stable without V2V (ACC) from about 1.6 s with the default gains [s]
# ChartStepPolicy's defaults: the best cell of `python -m train.tune_rule` on training seeds (results/v0/rule/tuning.md).
CHART_STEP_K_UP = 4  # exceedances within the chart's window that send a follower one level up [-]
CHART_STEP_QUIET_TIME = 35.0  # time without an alarm that sends a follower one level down [s]
CHART_STEP_MIN_SETTING = 1.6  # the lowest level the rule asks for, the driver's preferred setting [s]


@runtime_checkable
class Policy(Protocol):
    """What the evaluation calls: stable-baselines3's ``predict``."""

    def predict(
        self,
        observation: np.ndarray,
        state: Any = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = True,
    ) -> tuple[np.ndarray, Any]: ...


@runtime_checkable
class NamedPolicy(Policy, Protocol):
    """A policy that also says what to call it and which env it acts in (all policies in ``agents``)."""

    name: str  # label in tables and figures
    action_mode: str  # "platoon" (Discrete action) or "per_vehicle" (MultiDiscrete)


def as_config(config: EnvConfig | Mapping[str, Any] | None) -> EnvConfig:
    """An :class:`EnvConfig` from itself, or from a dict of overrides of the default task's config (``gym.make
    (DEFAULT_TASK, config=...)``'s) or None (that config)."""
    return get_task(DEFAULT_TASK).config(config)


def seconds(setting: float) -> str:
    """A setting for names and labels: '1.0', '0.6', '1.25'."""
    return str(round(float(setting), 3))


def level_index(config: EnvConfig, setting: float, field: str = "setting") -> int:
    """Index of ``setting`` [s] in ``config.setting_levels``; ``ValueError`` naming ``field`` if it is not a level."""
    levels = np.asarray(config.setting_levels)
    matches = np.flatnonzero(np.isclose(levels, setting))
    if matches.size == 0:
        raise ValueError(f"{field} = {setting!r} s: must be one of setting_levels {config.setting_levels}")
    return int(matches[0])


def exceedance_threshold(config: EnvConfig, count: Any, field: str) -> None:
    """``ValueError`` naming ``field`` unless ``count`` is an integer the observation can tell: 1 to 2 x the env's
    ``chart.switch_exceedances``, where the exceedance feature saturates."""
    saturation = exceedance_scale(config)
    if isinstance(count, bool) or not isinstance(count, (int, np.integer)):
        raise ValueError(f"{field} = {count!r}: must be an integer")
    if not 1 <= count <= saturation:
        raise ValueError(
            f"{field} = {count}: must be in [1, {saturation}]; the observation's "
            f"exceedance feature saturates at 2 x the env's chart.switch_exceedances = {saturation}"
        )


def time_since_alarm(observation: np.ndarray, config: EnvConfig) -> np.ndarray:
    """Each follower's time since its chart's last alarm or re-centring [s], (n_envs, n_followers), from observations
    (n_envs, obs_dim): the feature times ``config.chart.exceedance_window``, where it saturates (longer reads as it)."""
    features = observation.reshape(observation.shape[0], config.platoon.n_followers, len(FEATURES))
    return features[..., FEATURES.index("time_since_alarm")] * np.float64(config.chart.exceedance_window)


class ObservationPolicy:
    """Base of the hand-written policies: shape checks, decoding, and SB3's ``predict`` signature.

    A subclass sets ``name`` and defines ``_platoon_action(view) -> (n_envs,)`` and
    ``_per_vehicle_action(view) -> (n_envs, n_followers)``, both ladder indices; ``view`` is what ``_view``
    reads from the observations (by default :func:`decode_observation`'s :class:`FollowerView`).
    """

    name = "policy"

    def __init__(self, config: EnvConfig | Mapping[str, Any] | None = None) -> None:
        self.config = as_config(config)
        self.action_mode = self.config.action_mode
        self.obs_dim = self.config.platoon.n_followers * len(FEATURES)

    def predict(
        self,
        observation: np.ndarray,
        state: Any = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = True,
    ) -> tuple[np.ndarray, Any]:
        """Ladder indices for one observation (obs_dim,) or a batch (n_envs, obs_dim); ``state`` is passed through."""
        obs = np.asarray(observation, dtype=np.float64)
        if obs.ndim not in (1, 2) or obs.shape[-1] != self.obs_dim:
            raise ValueError(f"observation shape {obs.shape}: expected ({self.obs_dim},) or (n_envs, {self.obs_dim})")
        view = self._view(np.atleast_2d(obs))
        if self.action_mode == "platoon":
            action = self._platoon_action(view)
        else:
            action = self._per_vehicle_action(view)
        action = np.asarray(action, dtype=np.int64)
        return (action[0] if obs.ndim == 1 else action), state

    def _view(self, observation: np.ndarray) -> Any:
        """What the actions are chosen from, for observations (n_envs, obs_dim)."""
        return decode_observation(observation, self.config)

    def _platoon_action(self, view: Any) -> np.ndarray:  # view: what _view returns
        raise NotImplementedError

    def _per_vehicle_action(self, view: Any) -> np.ndarray:
        raise NotImplementedError

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.name!r}, action_mode={self.action_mode!r})"


class PaperRulePolicy(ObservationPolicy):
    """The paper's rule: ``switch_exceedances`` exceedances within ``exceedance_window`` -> ``switch_to``.

    Paper: 3 exceedances within 35 s -> 1.6 s becomes 1.0 s. Defaults come from
    ``config.chart``. The rule is :func:`timegap_env.monitoring.charts.switch_rule` on the decoded
    observation: a follower triggers when its count reaches k and its setting is not ``switch_to``
    already; otherwise the current setting is kept (the env's re-centring clears the count after a
    switch, so the rule fires once).

    - ``action_mode="platoon"``: everyone switches when any follower triggers;
    - ``action_mode="per_vehicle"``: each follower switches on its own chart.

    The count in the observation is the env's, over ``config.chart.exceedance_window``; a rule
    with another window cannot be read from it, so ``exceedance_window`` must equal the env's
    (change the env's ``chart.exceedance_window`` instead). k may be at most 2 ×
    ``config.chart.switch_exceedances``, where the feature saturates. The rule acts on the count
    at each decision (every ``decision_interval``), not at the tick the count reaches k.
    """

    def __init__(
        self,
        config: EnvConfig | Mapping[str, Any] | None = None,
        *,
        switch_exceedances: int | None = None,
        exceedance_window: float | None = None,
        switch_to: float | None = None,
    ) -> None:
        super().__init__(config)
        chart = self.config.chart
        self.switch_exceedances = chart.switch_exceedances if switch_exceedances is None else switch_exceedances
        self.exceedance_window = chart.exceedance_window if exceedance_window is None else exceedance_window
        self.switch_to = chart.switch_to if switch_to is None else switch_to
        exceedance_threshold(self.config, self.switch_exceedances, "switch_exceedances")
        if not np.isclose(self.exceedance_window, chart.exceedance_window):
            raise ValueError(
                f"exceedance_window = {self.exceedance_window} s: the observation counts exceedances over the env's "
                f"chart.exceedance_window = {chart.exceedance_window} s; set that in the env config instead"
            )
        self.switch_index = level_index(self.config, self.switch_to, "switch_to")
        self.rule = chart.with_overrides({"switch_exceedances": self.switch_exceedances, "switch_to": self.switch_to})
        scope = "platoon" if self.action_mode == "platoon" else "per vehicle"
        self.name = f"paper rule ({scope})"

    def _triggered(self, view: FollowerView) -> np.ndarray:
        """Followers whose chart says switch (n_envs, n_followers)."""
        return switch_rule(view.exceedances, view.setting, self.rule)

    def _platoon_action(self, view: FollowerView) -> np.ndarray:
        return np.where(self._triggered(view).any(axis=1), self.switch_index, view.setting_index[:, 0])

    def _per_vehicle_action(self, view: FollowerView) -> np.ndarray:
        return np.where(self._triggered(view), self.switch_index, view.setting_index)


class ChartView(NamedTuple):
    """What :class:`ChartStepPolicy` reads from a batch of observations."""

    follower: FollowerView  # the decoded features (n_envs, n_followers)
    time_since_alarm: np.ndarray  # since each chart's last alarm or re-centring, saturating (n_envs, n_followers) [s]


class ChartStepPolicy(ObservationPolicy):
    """One ladder level up when a chart shows excursions, one level down when it has been quiet, never below a floor.

    A generalisation of the paper's rule (``k`` exceedances within ``W`` s -> 1.0 s) in which the chart
    picks the direction. Per follower, at each decision:

    - at least ``k_up`` exceedances within the env's ``chart.exceedance_window`` -> one level up (safer);
    - otherwise, no alarm for at least ``quiet_time`` s -> one level down;
    - otherwise its setting is kept;

    and the result is clipped to [``min_setting``, the ladder's top] (a setting below the floor goes straight
    to it). The env re-centres a follower's chart when its setting changes, clearing the count and restarting
    the time since the last alarm, so every step needs fresh evidence: at most one level down per
    ``quiet_time``. The policy is stateless: the count, the time since the last alarm and the setting are in
    the observation.

    - ``action_mode="platoon"``: the largest level any follower asks for (one up-step outvotes the rest);
    - ``action_mode="per_vehicle"``: each follower its own.

    Defaults: the best cell of ``python -m train.tune_rule`` on training seeds (``results/v0/rule/tuning.md``),
    ``CHART_STEP_K_UP``, ``CHART_STEP_QUIET_TIME``, ``CHART_STEP_MIN_SETTING``; the tuned floor is the env's
    starting setting, so with the defaults the rule only rises above it and comes back. ``k_up`` may be at most 2 ×
    ``config.chart.switch_exceedances`` and ``quiet_time`` at most ``config.chart.exceedance_window``, where the
    observation's features saturate.
    """

    def __init__(
        self,
        config: EnvConfig | Mapping[str, Any] | None = None,
        *,
        k_up: int = CHART_STEP_K_UP,
        quiet_time: float = CHART_STEP_QUIET_TIME,
        min_setting: float = CHART_STEP_MIN_SETTING,
    ) -> None:
        super().__init__(config)
        exceedance_threshold(self.config, k_up, "k_up")
        window = self.config.chart.exceedance_window
        number = isinstance(quiet_time, (int, float, np.integer, np.floating)) and not isinstance(quiet_time, bool)
        if not (number and 0 < quiet_time <= window):
            raise ValueError(f"quiet_time = {quiet_time!r} s: must be in (0, {window}]; the observation's time since "
                             f"the last alarm saturates at the env's chart.exceedance_window = {window} s")
        self.k_up, self.quiet_time, self.min_setting = int(k_up), float(quiet_time), float(min_setting)
        self.floor_index = level_index(self.config, min_setting, "min_setting")
        self.top_index = len(self.config.setting_levels) - 1
        self.quiet_tolerance = self.config.platoon.dt / 2  # absorbs the float32 feature's rounding [s]
        self.name = (f"chart steps (up at {self.k_up}, down after {seconds(quiet_time)} s, "
                     f"floor {seconds(min_setting)} s)")
        if self.action_mode == "per_vehicle":
            self.name += " per vehicle"

    def _view(self, observation: np.ndarray) -> ChartView:
        return ChartView(decode_observation(observation, self.config), time_since_alarm(observation, self.config))

    def _asked(self, view: ChartView) -> np.ndarray:
        """The level each follower asks for (n_envs, n_followers)."""
        up = view.follower.exceedances >= self.k_up
        down = ~up & (view.time_since_alarm >= self.quiet_time - self.quiet_tolerance)
        return np.clip(view.follower.setting_index + up - down, self.floor_index, self.top_index)

    def _platoon_action(self, view: ChartView) -> np.ndarray:
        return self._asked(view).max(axis=1)

    def _per_vehicle_action(self, view: ChartView) -> np.ndarray:
        return self._asked(view)


class FixedPolicy(ObservationPolicy):
    """Always the same ``setting`` [s], one of ``config.setting_levels``."""

    def __init__(self, setting: float, config: EnvConfig | Mapping[str, Any] | None = None) -> None:
        super().__init__(config)
        self.setting = setting
        self.index = level_index(self.config, setting)
        self.name = f"fixed {seconds(setting)} s"

    def _platoon_action(self, view: FollowerView) -> np.ndarray:
        return np.full(view.setting_index.shape[0], self.index)

    def _per_vehicle_action(self, view: FollowerView) -> np.ndarray:
        return np.full(view.setting_index.shape, self.index)


class V2VAwarePolicy(ObservationPolicy):
    """``connected`` [s] while V2V is up, ``acc`` [s] without it (string stable in ACC).

    Platoon: ``connected`` only while every follower has V2V; per vehicle: each follower by its own link.
    """

    def __init__(
        self,
        config: EnvConfig | Mapping[str, Any] | None = None,
        *,
        connected: float = V2V_SETTING,
        acc: float = ACC_SETTING,
    ) -> None:
        super().__init__(config)
        self.connected_index = level_index(self.config, connected, "connected")
        self.acc_index = level_index(self.config, acc, "acc")
        self.name = f"V2V-aware {seconds(connected)}/{seconds(acc)} s"
        if self.action_mode == "per_vehicle":
            self.name += " (per vehicle)"

    def _platoon_action(self, view: FollowerView) -> np.ndarray:
        return np.where(view.v2v.all(axis=1), self.connected_index, self.acc_index)

    def _per_vehicle_action(self, view: FollowerView) -> np.ndarray:
        return np.where(view.v2v, self.connected_index, self.acc_index)


def fixed_policies(config: EnvConfig | Mapping[str, Any] | None = None) -> list[FixedPolicy]:
    """One :class:`FixedPolicy` per level of the ladder, smallest first."""
    config = as_config(config)
    return [FixedPolicy(level, config) for level in config.setting_levels]
