"""The agent's view: what each follower's monitor, chart and own car show, scaled to [-1, 1] or [0, 1].

:func:`observe` encodes the features below for every follower of every env (a compiled kernel
over the named :class:`FollowerState`); :func:`decode_observation` undoes the scaling for the
hand-written policies, so the scaling is written once, here.

The observation holds only what a car knows: its monitor's posterior and chart, its own
setting and speed, and its V2V link flag; nothing of the true state.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np
from gymnasium import spaces

from timegap_env.compiled import STAGE_KERNEL, follow_sources
from timegap_env.config import EnvConfig
from timegap_env.monitoring.posterior import outside_probability

FEATURES = (
    "deviation",  # (posterior mean of tau - the chart's centre line) / DEVIATION_SCALE, clipped to [-1, 1]
    "estimate_std",  # posterior std of tau / (L sigma_desired), clipped to [0, 1]
    "prob_outside",  # posterior probability that tau lies outside [LCL, UCL]
    "alarm",  # 1 while the chart is in alarm
    "exceedances",  # exceedances within the chart's trailing window / (2 switch_exceedances), clipped to [0, 1]
    "time_since_alarm",  # time since the last alarm / exceedance_window, clipped to [0, 1]
    "setting",  # (tau* - smallest level) / (largest level - smallest level)
    "speed",  # own speed / SPEED_SCALE, clipped to [0, 1]
    "v2v",  # 1 in CACC (V2V on), 0 in ACC
)
DEVIATION_SCALE = 1.0  # [s]
SPEED_SCALE = 40.0  # [m/s], above the 80 mph band
OBSERVATION_LOW = np.array([-1 if feature == "deviation" else 0 for feature in FEATURES], dtype=np.float32)
OBSERVATION_HIGH = np.ones(len(FEATURES), dtype=np.float32)
# Where each feature sits in a follower's row, for the kernel.
(_DEVIATION, _ESTIMATE_STD, _PROB_OUTSIDE, _ALARM, _EXCEEDANCES, _TIME_SINCE_ALARM, _SETTING, _SPEED,
 _V2V) = (FEATURES.index(name) for name in ("deviation", "estimate_std", "prob_outside", "alarm", "exceedances",
                                            "time_since_alarm", "setting", "speed", "v2v"))
LADDER_TOLERANCE = 1e-3  # a decoded setting farther than this from every level means a config mismatch [s]


def exceedance_scale(config: EnvConfig) -> int:
    """The exceedance count at which the ``exceedances`` feature reaches 1: twice the paper's rule's k [-]."""
    return 2 * config.chart.switch_exceedances


MONITOR_FEATURES = FEATURES[:6]  # what the monitor and its chart give; the rest (setting, speed, V2V) a car knows


def hidden(observations: np.ndarray, features: tuple[str, ...]) -> np.ndarray:
    """``observations`` (..., n_followers * len(FEATURES)) with ``features`` (names of FEATURES) read as 0 for every
    follower, a copy: what a policy sees when an ablation hides them (a run's ``hidden_features``)."""
    columns = feature_columns(features)
    out = np.array(observations, dtype=np.float32)
    if columns:
        out.reshape(*out.shape[:-1], -1, len(FEATURES))[..., columns] = 0.0
    return out


def feature_columns(features: tuple[str, ...] | list[str]) -> list[int]:
    """Each feature's column in a follower's row; ``ValueError`` naming a name not in FEATURES (or one twice)."""
    unknown = [name for name in features if name not in FEATURES]
    if unknown or len(set(features)) != len(features):
        problem = f"unknown {unknown}" if unknown else "a name twice"
        raise ValueError(f"hidden_features = {list(features)!r}: {problem}; must be distinct names of {list(FEATURES)}")
    return [FEATURES.index(name) for name in features]


def observation_space(config: EnvConfig) -> spaces.Box:
    """Box (n_followers * len(FEATURES),) float32: follower 1's features, then follower 2's, ..."""
    n = config.platoon.n_followers
    return spaces.Box(np.tile(OBSERVATION_LOW, n), np.tile(OBSERVATION_HIGH, n), dtype=np.float32)


class FollowerState(NamedTuple):
    """What the observation reads, arrays (n_envs, n_followers)."""

    tau_mean: np.ndarray  # posterior mean of tau [s]
    tau_var: np.ndarray  # posterior variance of tau [s^2]
    center: np.ndarray  # the chart's centre line, the applied setting [s]
    side: np.ndarray  # the chart's side: -1, 0, +1 [-]
    exceedances_in_window: np.ndarray  # the chart's count [-]
    run_length: np.ndarray  # ticks since the last alarm [ticks]
    setting: np.ndarray  # the setting asked for [s]
    speed: np.ndarray  # own speed [m/s]
    v2v: np.ndarray  # CACC on [bool]


class ObservationScales(NamedTuple):
    """The config's numbers that scale the features."""

    half_width: float  # L sigma_desired, from the centre line to a limit [s]
    exceedance_scale: float  # 2 switch_exceedances [-]
    dt: float  # tick [s]
    exceedance_window: float  # [s]
    smallest_level: float  # [s]
    level_span: float  # largest level - smallest level [s]

    @classmethod
    def from_config(cls, config: EnvConfig) -> ObservationScales:
        return cls(
            half_width=float(config.chart.half_width),
            exceedance_scale=float(exceedance_scale(config)),
            dt=float(config.platoon.dt),
            exceedance_window=float(config.chart.exceedance_window),
            smallest_level=float(config.setting_levels[0]),
            level_span=config.setting_span,
        )


def observe(state: FollowerState, scales: ObservationScales) -> np.ndarray:
    """Observations (n_envs, n_followers, len(FEATURES)) float32, the features in FEATURES order."""
    features = np.empty((*state.setting.shape, len(FEATURES)), dtype=np.float32)
    _encode(tuple(state), tuple(scales), features)
    return features


def observe_into(state: FollowerState, scales: ObservationScales, out: np.ndarray, mask: np.ndarray) -> None:
    """:func:`observe` for the envs in ``mask`` (n_envs,) bool only, into their rows of ``out``."""
    _encode_envs(tuple(state), tuple(scales), out, np.flatnonzero(mask))


@numba.njit(cache=True, error_model="numpy")
def _encode_envs(state, scales, out, envs):  # noqa: ANN001, ANN202
    """:func:`_encode` for the envs ``envs`` only."""
    for e in envs:
        encode_env(state, scales, out, e)


@numba.njit(cache=True, error_model="numpy")
def _encode(state, scales, out):  # noqa: ANN001, ANN202
    """Fill ``out`` (n_envs, n_followers, len(FEATURES)) float32 with the features of ``state``
    (:class:`FollowerState`) under ``scales`` (:class:`ObservationScales`), both plain tuples (see
    :mod:`timegap_env.sim.platoon`), in FEATURES order, clipped to [OBSERVATION_LOW, OBSERVATION_HIGH]."""
    for e in range(out.shape[0]):
        encode_env(state, scales, out, e)


@numba.njit(**STAGE_KERNEL)
def encode_env(state, scales, out, e):  # noqa: ANN001, ANN201
    """Env ``e``'s row of :func:`_encode`."""
    state, scales = FollowerState(*state), ObservationScales(*scales)
    n_followers, n_features = out.shape[1], out.shape[2]
    for f in range(n_followers):
        mean, variance, line = state.tau_mean[e, f], state.tau_var[e, f], state.center[e, f]
        out[e, f, _DEVIATION] = (mean - line) / DEVIATION_SCALE
        out[e, f, _ESTIMATE_STD] = math.sqrt(variance) / scales.half_width
        out[e, f, _PROB_OUTSIDE] = outside_probability(
            mean, variance, line - scales.half_width, line + scales.half_width
        )
        out[e, f, _ALARM] = state.side[e, f] != 0
        out[e, f, _EXCEEDANCES] = state.exceedances_in_window[e, f] / scales.exceedance_scale
        out[e, f, _TIME_SINCE_ALARM] = state.run_length[e, f] * scales.dt / scales.exceedance_window
        out[e, f, _SETTING] = (state.setting[e, f] - scales.smallest_level) / scales.level_span
        out[e, f, _SPEED] = state.speed[e, f] / SPEED_SCALE
        out[e, f, _V2V] = state.v2v[e, f]
        for i in range(n_features):
            out[e, f, i] = min(max(out[e, f, i], OBSERVATION_LOW[i]), OBSERVATION_HIGH[i])


class FollowerView(NamedTuple):
    """What :func:`decode_observation` reads back from a batch of observations, arrays (n_envs, n_followers)."""

    exceedances: np.ndarray  # exceedances in the chart's trailing window, exact up to 2 switch_exceedances [-]
    setting_index: np.ndarray  # index of the setting tau* in setting_levels [-]
    setting: np.ndarray  # the setting tau* itself, a level [s]
    v2v: np.ndarray  # follower in CACC (V2V on) [bool]


def decode_observation(observation: np.ndarray, config: EnvConfig) -> FollowerView:
    """Undo the scaling of :func:`observe` for (n_envs, n_followers * len(FEATURES)) observations.

    - ``exceedances`` = count / :func:`exceedance_scale` (2 k, k = ``config.chart.switch_exceedances``), clipped
      to [0, 1]: count = round(feature * 2 k), exact for counts up to 2 k (larger counts read as 2 k);
    - ``setting`` = (tau* - smallest level) / (largest - smallest level): tau* is the setting last
      asked for (not the ramped value the controller applies yet), mapped to its ladder index;
    - ``v2v`` is 1 in CACC, 0 in ACC.
    """
    n_followers, n_features = config.platoon.n_followers, len(FEATURES)
    features = observation.reshape(observation.shape[0], n_followers, n_features)
    counts = np.rint(features[..., FEATURES.index("exceedances")] * exceedance_scale(config))
    levels = np.asarray(config.setting_levels)
    setting = levels[0] + features[..., FEATURES.index("setting")] * np.float64(config.setting_span)  # [s]
    distance = np.abs(setting[..., None] - levels)
    index = distance.argmin(axis=-1)
    if np.any(np.take_along_axis(distance, index[..., None], axis=-1) > LADDER_TOLERANCE):
        raise ValueError(
            f"observation feature 'setting' decodes to {setting.ravel()[:5]} s, not on setting_levels "
            f"{config.setting_levels}: was the policy built with the env's config?"
        )
    return FollowerView(
        exceedances=counts.astype(np.int64),
        setting_index=index.astype(np.int64),
        setting=levels[index],
        v2v=features[..., FEATURES.index("v2v")] > 0.5,
    )


follow_sources(__name__)
