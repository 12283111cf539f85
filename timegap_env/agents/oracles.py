"""Oracles: policies that read the ground truth, ``truth_of(info)``. An upper reference, not deployable.

No car knows its own degradation; these policies do, so they say how much knowing is worth: what
a policy reading the monitor could at best recover. Each takes the ground truth of the envs'
current observations (:func:`timegap_env.envs.info.truth_of` of the native vector env's infos, arrays (n_envs,
n_followers); of a single env, (n_followers,)) and returns ladder indices shaped like the env's
action: (n_envs,) or () for ``action_mode="platoon"`` (one setting for the platoon: the largest
any follower needs), (n_envs, N) or (N,) for ``"per_vehicle"``.

- :class:`StabilityOracle`: the smallest setting on the ladder at least ``margin`` above the
  smallest string-stable setting for the true parameters and link;
- :class:`LookupOracle`: the setting that scored best under the reward, on training seeds, for
  the true condition (the active degradation's kind and size bin), from a table measured by
  ``train/value_of_information.py``; with ``whole_episode=True`` it reads the episode's schedule
  instead (it sees the future) and holds the setting for the episode's condition from reset on,
  so that the platoon is ready before the onset;
- :class:`RegimeOracle`: the setting that scored best for the leader's regime now (its family, or the regime of a
  leader whose traffic changes within the episode: ``truth["regime"]``, which envs of info layout "v1" (TimeGapMonitor-v1) report),
  on training seeds; with a ``floor`` (another oracle), at least the floor's setting for each follower: it then knows
  the traffic and the car's condition together.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, cast

import numpy as np

from timegap_env.agents.policies import as_config
from timegap_env.config import DEGRADATIONS, DegradationConfig, EnvConfig

NOMINAL = "none"  # the condition of a follower no degradation acts on
SIZE_BINS = 3  # a sized degradation's range is cut into this many equal bins (per sign for a signed kind)


def condition_keys(truth: Mapping[str, np.ndarray], config: DegradationConfig, whole_episode: bool = False) -> np.ndarray:
    """Each follower's true condition as a string key, shaped like ``truth["kind"]``: "none" when nothing
    acts, "<kind>:<bin>" for a sized kind (bin 0 .. SIZE_BINS - 1 of its drawn range, "-" before the bin
    of a negative size of a signed kind: radar bias), else the kind (a commercial ACC: whichever car). With ``whole_episode`` the
    follower's degradation counts whether it acts now or not (before its onset, after its end)."""
    kinds, sizes, active = np.asarray(truth["kind"]), np.asarray(truth["size"]), np.asarray(truth["active"])
    keys = np.full(kinds.shape, NOMINAL, dtype=object)
    for index in np.ndindex(kinds.shape):
        kind = cast(str, kinds[index])  # one element (a full index): the kind's name
        if not (whole_episode or active[index]) or kind == NOMINAL:
            continue
        if DEGRADATIONS[kind].range_field is not None:
            keys[index] = f"{kind}:{size_bin(kind, float(sizes[index]), config)}"
        else:
            keys[index] = kind
    return keys


def size_bin(kind: str, size: float, config: DegradationConfig) -> str:
    """The bin of ``size`` in ``kind``'s drawn range (clipped to it): "0" .. "2", with a "-" for a negative bias."""
    low, high = config.size_range(kind)
    signed = DEGRADATIONS[kind].signed
    magnitude = abs(size) if signed else size
    index = int(np.clip(np.floor((magnitude - low) / (high - low) * SIZE_BINS), 0, SIZE_BINS - 1))
    return ("-" if signed and size < 0 else "") + str(index)


def bin_centres(kind: str, config: DegradationConfig) -> dict[str, float]:
    """Each bin of ``kind`` and the size at its centre (both signs for a signed kind)."""
    low, high = config.size_range(kind)
    centres = {str(i): low + (i + 0.5) * (high - low) / SIZE_BINS for i in range(SIZE_BINS)}
    if DEGRADATIONS[kind].signed:
        centres |= {f"-{key}": -value for key, value in centres.items()}
    return centres


class TruthPolicy:
    """Base of the oracles: per-follower ladder levels from the truth, combined for the env's action mode."""

    name = "oracle"

    def __init__(self, config: EnvConfig | Mapping[str, Any] | None = None) -> None:
        self.config = as_config(config)
        self.action_mode = self.config.action_mode
        self.levels = np.asarray(self.config.setting_levels)

    def act(self, truth: Mapping[str, np.ndarray]) -> np.ndarray:
        """Ladder indices for the ground truth of one env (n_followers,) or several (n_envs, n_followers)."""
        single = np.ndim(truth["kind"]) == 1
        batch = {name: np.atleast_2d(value) for name, value in truth.items()}
        settings = self._settings(batch)  # (n_envs, n_followers) [s]
        if self.action_mode == "platoon":
            settings = settings.max(axis=1)
        indices = np.minimum(np.searchsorted(self.levels, settings - 1e-9), len(self.levels) - 1).astype(np.int64)
        return indices[0] if single else indices

    def _settings(self, truth: Mapping[str, np.ndarray]) -> np.ndarray:
        raise NotImplementedError


class StabilityOracle(TruthPolicy):
    """The smallest level at least ``margin`` [s] above the smallest string-stable setting of each follower's true
    parameters and link (the largest level where none is stable)."""

    def __init__(self, config: EnvConfig | Mapping[str, Any] | None = None, margin: float = 0.1) -> None:
        super().__init__(config)
        self.margin = margin
        self.name = f"oracle_stability+{margin:g}"

    def _settings(self, truth: Mapping[str, np.ndarray]) -> np.ndarray:
        return np.minimum(truth["smallest_stable_setting"] + self.margin, self.levels[-1])


class LookupOracle(TruthPolicy):
    """Each follower's setting [s] from ``table`` (condition key, see :func:`condition_keys` -> setting); a
    condition missing from the table takes the nominal one's. ``whole_episode``: the key of the episode's
    degradation from reset on, not of the one acting now."""

    def __init__(self, table: Mapping[str, float], config: EnvConfig | Mapping[str, Any] | None = None,
                 whole_episode: bool = False) -> None:
        super().__init__(config)
        if NOMINAL not in table:
            raise ValueError(f"table keys {sorted(table)}: must hold the nominal condition {NOMINAL!r}")
        self.table = dict(table)
        self.whole_episode = whole_episode
        self.name = "oracle_lookup_episode" if whole_episode else "oracle_lookup"

    def _settings(self, truth: Mapping[str, np.ndarray]) -> np.ndarray:
        keys = condition_keys(truth, self.config.degradation, self.whole_episode)
        return np.vectorize(lambda key: self.table.get(key, self.table[NOMINAL]), otypes=[float])(keys)


class RegimeOracle(TruthPolicy):
    """Every follower's setting [s] from ``table`` (the leader's regime, a name of
    :func:`~timegap_env.leaders.scenarios.regime_names` -> setting), raised for each follower to ``floor``'s setting
    when a floor is given (for a :class:`LookupOracle` floor, only where a degradation acts: its nominal entry does
    not raise it). ``KeyError`` naming a regime missing from the table."""

    def __init__(self, table: Mapping[str, float], config: EnvConfig | Mapping[str, Any] | None = None,
                 floor: TruthPolicy | None = None) -> None:
        super().__init__(config)
        self.table = dict(table)
        self.floor = floor
        if isinstance(floor, LookupOracle):  # its nominal entry is the traffic's best, which the regime knows better
            self.floor = LookupOracle({**floor.table, NOMINAL: 0.0}, floor.config, floor.whole_episode)
        self.name = "oracle_regime" + ("" if floor is None else "+" + floor.name.removeprefix("oracle_"))

    def _settings(self, truth: Mapping[str, np.ndarray]) -> np.ndarray:
        if "regime" not in truth:
            raise KeyError("the ground truth has no regime: run an env of info layout 'v1' (TimeGapMonitor-v1)")
        regimes = np.asarray(truth["regime"]).reshape(-1)
        missing = sorted(set(regimes.tolist()) - set(self.table))
        if missing:
            raise KeyError(f"regimes {missing} are not in the table (it has {sorted(self.table)})")
        settings = np.array([self.table[regime] for regime in regimes])[:, None] * np.ones_like(truth["size"], float)
        return settings if self.floor is None else np.maximum(settings, self.floor._settings(truth))
