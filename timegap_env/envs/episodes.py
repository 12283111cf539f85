"""What each env's episode is made of, drawn at reset from the env's own generator.

An episode is a leader speed profile (a family drawn from ``EnvConfig.scenario_weights``, a
named scenario, or the user's own speed series), a degradation of some followers (drawn from
``EnvConfig.degradation``, or pinned, see :mod:`timegap_env.sim.degradation`), a sensor dropout
rate and a noise key. The draws use the generator in a fixed order, so an env seeded alike draws
alike whether it runs alone or in a batch, and pinning the leader or the degradation leaves the
other draws as they were.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Mapping, Sequence
from typing import Annotated, Any, NamedTuple

import numpy as np

from timegap_env.compiled import collection_paused
from timegap_env.config import EnvConfig, shown
from timegap_env.leaders.profile import LeaderProfile, LeaderProfiles
from timegap_env.leaders.scenarios import (
    LEADER_FAMILIES,
    SCENARIOS,
    USER,
    LeaderFamily,
    family_params,
    make_leaders,
    regime_names,
)
from timegap_env.sim.degradation import Categorical, Degradation, DegradationDraw, parse_degradations
from timegap_env.state import OnState, PerEnv, State

RESET_OPTIONS = ("leader_speed", "scenario", "degradation")  # the keys reset(options=...) takes
LEADER_BATCH = 256  # leaders built at once: a few MB of temporaries, reused rather than mapped afresh
PACKET_LOSS_STREAM = np.uint64(0x5DEECE66D)  # the packet-loss key is the noise key xor this (another stream)


def check_reset_options(options: Mapping[str, Any] | None) -> dict[str, Any]:
    """``options`` as a dict, ``leader_speed`` as a float array and a ``scenario`` of None left out; ``ValueError``
    naming any unknown key, a scenario that is not one of ``SCENARIOS``' names, a ``leader_speed`` that is not a
    series of numbers, or both of these at once."""
    if options is not None and not isinstance(options, Mapping):
        raise ValueError(f"reset options = {shown(options)}: must be a dict with keys among {list(RESET_OPTIONS)}")
    options = dict(options or {})
    unknown = sorted(set(options) - set(RESET_OPTIONS), key=repr)
    if unknown:
        raise ValueError(f"reset options {unknown} unknown; known: {list(RESET_OPTIONS)}")
    if options.get("scenario", "") is None:
        del options["scenario"]  # None: drawn from scenario_weights, as without the option
    if "scenario" in options and (not isinstance(options["scenario"], str) or options["scenario"] not in SCENARIOS):
        raise ValueError(f"reset option scenario = {shown(options['scenario'])}: must be None (drawn) or one of "
                         f"{sorted(SCENARIOS)}")
    if "leader_speed" in options:
        if "scenario" in options:
            raise ValueError("reset options scenario and leader_speed: give one (leader_speed is the user's own leader)")
        speed = options["leader_speed"]
        try:
            kind = np.asarray(speed).dtype.kind
            options["leader_speed"] = np.asarray(speed, dtype=float)
        except (TypeError, ValueError, OverflowError) as error:
            raise ValueError(f"reset option leader_speed = {shown(speed)}: must be a series of speeds [m/s] "
                             f"({error})") from None
        if kind not in "iuf":  # NumPy would read strings ("20") and bools as speeds
            raise ValueError(f"reset option leader_speed = {shown(speed)}: must be a series of numbers [m/s], "
                             f"not of {np.asarray(speed).dtype}")
    return options


class LeaderTrack(NamedTuple):
    """The leader of each env's episode at every tick ("samples": max_ticks + 1), held at its last value beyond
    the profile."""

    speed: Annotated[np.ndarray, PerEnv(float, "samples")]  # [m/s]
    accel: Annotated[np.ndarray, PerEnv(float, "samples")]  # [m/s^2]
    episode_ticks: Annotated[np.ndarray, PerEnv(np.int64)]  # ticks in the episode [-]


def episode_dims(config: EnvConfig) -> dict[str, int]:
    """The size of :class:`LeaderTrack`'s dimension under ``config``."""
    return {"samples": config.max_episode_steps * config.ticks_per_decision + 1}


class Episodes(OnState):
    """The current episode of each of ``n_envs`` envs.

    Per env: ``leader_speed`` [m/s] and ``leader_accel`` [m/s^2] (n_envs, max_ticks + 1), the
    leader at every tick, held at its last value beyond the profile; ``episode_ticks`` (n_envs,)
    ticks in the episode; ``degradations`` (a tuple of :class:`~timegap_env.sim.degradation.Degradation`
    per env); ``dropout_probability`` (n_envs,) [-]; ``initial_setting`` (n_envs,) [s], the setting the episode
    starts at; ``noise_keys`` (n_envs,) uint64 of the sensor noise
    and ``packet_loss_keys`` of the V2V losses; ``scenario`` (n_envs,), the leader's name; with ``record_regime`` (info layout "v1"),
    ``regime`` (n_envs, max_ticks + 1) int16, the leader's regime at every tick (an index into
    :func:`~timegap_env.leaders.scenarios.regime_names`, held at its last value beyond the profile), else None.
    The leader's arrays are :attr:`parts` (:class:`LeaderTrack`), views of ``state`` at ``path`` (their own
    state when None).
    """

    def __init__(self, config: EnvConfig, n_envs: int, record_regime: bool = True, state: State | None = None,
                 path: tuple[str, ...] = ()) -> None:
        unknown = sorted(set(config.scenario_weights) - set(SCENARIOS))
        if unknown:
            raise ValueError(f"EnvConfig.scenario_weights has unknown families {unknown}; known: {sorted(SCENARIOS)}")
        self.config = config
        self.ticks_per_decision = config.ticks_per_decision
        max_ticks = config.max_episode_steps * self.ticks_per_decision
        self._bind(State(LeaderTrack, episode_dims(config), n_envs) if state is None else state, path)
        self.parts.episode_ticks[:] = max_ticks
        self.degradations: list[tuple[Degradation, ...]] = [() for _ in range(n_envs)]
        self.dropout_probability = np.zeros(n_envs)
        self.initial_setting = np.full(n_envs, config.platoon.initial_setting)  # [s]
        self.noise_keys = np.zeros(n_envs, dtype=np.uint64)
        self.scenario = np.full(n_envs, "", dtype=object)
        self.regime = np.zeros((n_envs, max_ticks + 1), dtype=np.int16) if record_regime else None
        self._params = family_params(config.leader_params)  # leader family -> its parameter dataclass, as configured
        self._defaults: dict[str, tuple[LeaderFamily, Any]] = {}  # leader family -> (its record, its default parameters)
        self._families = list(config.scenario_weights)
        self._family_draw = Categorical([config.scenario_weights[f] for f in self._families])
        self._degradation_draw = DegradationDraw(config.degradation, config.platoon.n_followers, config.platoon.dt)

    leader_speed = property(lambda self: self.parts.speed, doc="The leader's speed at every tick (n_envs, max_ticks + 1) [m/s].")
    leader_accel = property(lambda self: self.parts.accel, doc="Its acceleration (n_envs, max_ticks + 1) [m/s^2].")
    episode_ticks = property(lambda self: self.parts.episode_ticks, doc="Ticks in each env's episode (n_envs,) [-].")

    def draw(self, env: int, rng: np.random.Generator, options: Mapping[str, Any]) -> None:
        """A new episode for ``env`` from ``rng``; ``options`` as checked by :func:`check_reset_options`.

        ``{"scenario": name}`` picks a scenario; ``{"leader_speed": array}`` runs the user's leader
        speed series [m/s] at ``platoon.dt`` (truncated to the episode, padded to whole decisions by
        holding its last speed); ``{"degradation": ...}`` pins the degradation (a dict of
        :data:`~timegap_env.sim.degradation.DESCRIPTION_KEYS`, a list of them, or None for none).
        """
        self.draw_many(np.array([env]), {env: rng}, options)

    @collection_paused()
    def draw_many(self, envs: np.ndarray, rngs: Sequence[np.random.Generator] | Mapping[int, np.random.Generator],
                  options: Mapping[str, Any]) -> None:
        """:meth:`draw` for each env of ``envs`` (distinct indices) from its own generator ``rngs[env]``, the same
        draws in the same order per env, with the leaders of each family built in one batch.

        Per env, its generator draws the family (unless pinned) and the leader's seed, then (the leader
        drawing from a generator of its own seed) the degradation, the dropout rate, the noise key and, with
        ``random_initial_setting``, the initial setting.
        """
        cfg = self.config
        envs = np.asarray(envs, dtype=np.intp)
        n_followers, dt = cfg.platoon.n_followers, cfg.platoon.dt
        pinned = parse_degradations(options["degradation"], n_followers) if "degradation" in options else None
        if "leader_speed" in options:
            try:
                profile = LeaderProfile.from_speed(options["leader_speed"], dt, "user")
            except ValueError as error:
                raise ValueError(f"reset option leader_speed: {error}") from None
            profiles = LeaderProfiles.of(profile)
            self._load_leaders(envs, profiles)
            self._load_regimes(envs, USER, profiles, [None] * len(envs))
        else:
            families: dict[str, tuple[list[int], list[int]]] = {}  # family -> its envs and their leaders' seeds
            for env in envs.tolist():
                rng = rngs[env]
                family = options["scenario"] if "scenario" in options else self._families[self._family_draw.draw(rng)]
                members, seeds = families.setdefault(family, ([], []))
                members.append(env)
                seeds.append(int(rng.integers(2**31)))
            for family, (members, seeds) in families.items():
                for first in range(0, len(seeds), LEADER_BATCH):  # a batch's arrays stay small enough to reuse
                    loaded = first
                    try:
                        batches = list(make_leaders(family, seeds[first : first + LEADER_BATCH], cfg.leader,
                                                    self._leader_params(family)))
                    except ValueError as error:  # e.g. a recorded family at another tick than platoon.dt
                        raise ValueError(f"scenario {family!r} with platoon.dt = {dt} s: {error}") from error
                    for batch in batches:
                        if not math.isclose(batch.dt, dt, rel_tol=1e-9):
                            raise ValueError(f"scenario {family!r} has dt = {batch.dt} s; the env runs at {dt} s")
                        batch_envs = np.array(members[loaded : loaded + len(batch)])
                        self._load_leaders(batch_envs, batch)
                        self._load_regimes(batch_envs, family, batch, seeds[loaded : loaded + len(batch)])
                        loaded += len(batch)
        durations = (self.episode_ticks * dt).tolist()  # [s]
        dropout_low, dropout_high = cfg.dropout_probability_range
        dropouts, keys = [], []  # each env's, written after the loop
        for env in envs.tolist():
            rng = rngs[env]
            drawn = self._degradation_draw.draw(rng, durations[env])
            self.degradations[env] = drawn if pinned is None else pinned
            dropouts.append(dropout_low + (dropout_high - dropout_low) * rng.random())  # rng.uniform's draw
            keys.append(rng.integers(0, 2**63, dtype=np.uint64))
            if cfg.random_initial_setting:  # drawn last: the rest of the episode is the one it would be without
                self.initial_setting[env] = cfg.setting_levels[int(rng.integers(len(cfg.setting_levels)))]
        self.dropout_probability[envs] = dropouts
        self.noise_keys[envs] = np.array(keys, dtype=np.uint64)

    def _leader_params(self, scenario: str) -> Any:
        """The parameters scenario ``scenario``'s leader family is built with: ``leader_params``' for it, else its
        defaults (None for a family without parameters), made once per registered family record (a family
        registered again with ``replace=True`` gets its own)."""
        family = SCENARIOS[scenario].leader_family
        if family in self._params:
            return self._params[family]
        record = LEADER_FAMILIES[family]
        made = self._defaults.get(family)
        if made is None or made[0] is not record:
            made = self._defaults[family] = (record, None if record.params is None else record.params())
        return made[1]

    def _load_leaders(self, envs: np.ndarray, profiles: LeaderProfiles) -> None:
        """Put ``profiles`` (a row per env of ``envs``, or one row for all) in the envs' leader buffers, cut to the
        episode and padded to whole decisions."""
        tpd, capacity = self.ticks_per_decision, self.leader_speed.shape[1] - 1
        length = profiles.speed.shape[1]
        ticks = min(length - 1, capacity)
        ticks = -(-ticks // tpd) * tpd  # up to whole decisions
        n = min(length, ticks + 1)
        self.leader_speed[envs, :n] = profiles.speed[:, :n]
        self.leader_speed[envs, n:] = profiles.speed[:, n - 1 : n]
        self.leader_accel[envs, :n] = profiles.accel[:, :n]
        self.leader_accel[envs, n:] = 0.0
        self.episode_ticks[envs] = ticks
        self.scenario[envs] = profiles.name

    def _load_regimes(self, envs: np.ndarray, scenario: str, profiles: LeaderProfiles,
                      seeds: Sequence[int | None]) -> None:
        """Each env of ``envs``'s regime at every tick (with ``record_regime``), cut and padded as
        :meth:`_load_leaders` cuts and pads ``profiles``, its leaders (a row per env, or one row for all; after
        :meth:`_load_leaders`): the regimes ``profiles`` give, else its family's schedule for its leader's seed, or the
        family (USER: the user's leader) throughout."""
        if self.regime is None:
            return
        names = {name: code for code, name in enumerate(regime_names())}
        family = None if scenario == USER else LEADER_FAMILIES[SCENARIOS[scenario].leader_family]
        if family is None or family.schedule is None:
            self.regime[envs] = names[USER if family is None else family.name]
            return

        def ground_truth_codes(codes: np.ndarray, regimes: Sequence[str]) -> np.ndarray:
            """``codes`` (indices into the family's ``regimes``) as indices into regime_names()."""
            return np.array([names[f"{family.name}:{regime}"] for regime in regimes], dtype=np.int16)[codes]

        if profiles.regime is not None:
            rows = ground_truth_codes(profiles.regime, family.regimes)
        else:
            params = self._leader_params(scenario)
            rows = np.stack([ground_truth_codes(*family.schedule(seed, params, self.config.leader)) for seed in seeds])
        n = min(rows.shape[1], int(self.episode_ticks[envs[0]]) + 1)
        self.regime[envs, :n] = rows[:, :n]
        self.regime[envs, n:] = rows[:, n - 1 : n]

    def leader_at(self, ticks: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The leader's speed [m/s] and acceleration [m/s^2] at ``ticks`` (n_ticks, n_envs), held after the episode."""
        ticks = np.minimum(ticks, self.episode_ticks)
        envs = np.arange(ticks.shape[-1])
        return self.leader_speed[envs, ticks], self.leader_accel[envs, ticks]

    @property
    def packet_loss_keys(self) -> np.ndarray:
        """Each env's key of its V2V packet losses (n_envs,) uint64, another stream than its sensor noise."""
        return self.noise_keys ^ PACKET_LOSS_STREAM

    def fingerprint(self, env: int) -> str:
        """A hash of everything ``env``'s episode drew: leader, degradation, dropout rate and noise key."""
        digest = hashlib.sha256()
        ticks = int(self.episode_ticks[env])
        for array in (self.leader_speed[env, : ticks + 1], self.episode_ticks[env], self.dropout_probability[env],
                      self.noise_keys[env]):
            digest.update(np.ascontiguousarray(array).tobytes())
        digest.update(repr(self.degradations[env]).encode())
        return digest.hexdigest()
