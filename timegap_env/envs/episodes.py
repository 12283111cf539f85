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
from collections.abc import Mapping
from typing import Any

import numpy as np

from timegap_env.config import EnvConfig
from timegap_env.leaders.profile import LeaderProfile
from timegap_env.leaders.scenarios import SCENARIOS, make_leader
from timegap_env.sim.degradation import Degradation, draw_degradation, parse_degradations

RESET_OPTIONS = ("leader_speed", "scenario", "degradation")  # the keys reset(options=...) takes
PACKET_LOSS_STREAM = np.uint64(0x5DEECE66D)  # the packet-loss key is the noise key xor this (another stream)


def check_reset_options(options: Mapping[str, Any] | None) -> dict[str, Any]:
    """``options`` as a dict; ``ValueError`` naming any unknown key."""
    options = dict(options or {})
    unknown = sorted(set(options) - set(RESET_OPTIONS))
    if unknown:
        raise ValueError(f"reset options {unknown} unknown; known: {list(RESET_OPTIONS)}")
    return options


class Episodes:
    """The current episode of each of ``n_envs`` envs.

    Per env: ``leader_speed`` [m/s] and ``leader_accel`` [m/s^2] (n_envs, max_ticks + 1), the
    leader at every tick, held at its last value beyond the profile; ``episode_ticks`` (n_envs,)
    ticks in the episode; ``degradations`` (a tuple of :class:`~timegap_env.sim.degradation.Degradation`
    per env); ``dropout_probability`` (n_envs,) [-]; ``initial_setting`` (n_envs,) [s], the setting the episode
    starts at; ``noise_keys`` (n_envs,) uint64 of the sensor noise
    and ``packet_loss_keys`` of the V2V losses; ``scenario`` (n_envs,), the leader's name.
    """

    def __init__(self, config: EnvConfig, n_envs: int) -> None:
        unknown = sorted(set(config.scenario_weights) - set(SCENARIOS))
        if unknown:
            raise ValueError(f"EnvConfig.scenario_weights has unknown families {unknown}; known: {sorted(SCENARIOS)}")
        self.config = config
        self.ticks_per_decision = config.ticks_per_decision
        max_ticks = config.max_episode_steps * self.ticks_per_decision
        self.leader_speed = np.zeros((n_envs, max_ticks + 1))  # [m/s]
        self.leader_accel = np.zeros((n_envs, max_ticks + 1))  # [m/s^2]
        self.episode_ticks = np.full(n_envs, max_ticks)
        self.degradations: list[tuple[Degradation, ...]] = [() for _ in range(n_envs)]
        self.dropout_probability = np.zeros(n_envs)
        self.initial_setting = np.full(n_envs, config.platoon.initial_setting)  # [s]
        self.noise_keys = np.zeros(n_envs, dtype=np.uint64)
        self.scenario = np.full(n_envs, "", dtype=object)
        families = list(config.scenario_weights)
        weights = np.array([config.scenario_weights[f] for f in families], dtype=float)
        self._families, self._family_probabilities = families, weights / weights.sum()

    def draw(self, env: int, rng: np.random.Generator, options: Mapping[str, Any]) -> None:
        """A new episode for ``env`` from ``rng``; ``options`` as checked by :func:`check_reset_options`.

        ``{"scenario": name}`` picks a scenario; ``{"leader_speed": array}`` runs the user's leader
        speed series [m/s] at ``platoon.dt`` (truncated to the episode, padded to whole decisions by
        holding its last speed); ``{"degradation": ...}`` pins the degradation (a dict of
        :data:`~timegap_env.sim.degradation.DESCRIPTION_KEYS`, a list of them, or None for none).
        """
        cfg = self.config
        if "leader_speed" in options:
            profile = LeaderProfile.from_speed(np.asarray(options["leader_speed"], dtype=float), cfg.platoon.dt, "user")
        else:
            family = options.get("scenario") or self._families[rng.choice(len(self._families), p=self._family_probabilities)]
            profile = make_leader(family, int(rng.integers(2**31)), cfg.leader)
            if not math.isclose(profile.dt, cfg.platoon.dt, rel_tol=1e-9):
                raise ValueError(f"scenario {family!r} has dt = {profile.dt} s; the env runs at {cfg.platoon.dt} s")
        self._load_leader(env, profile)
        n_followers, dt = cfg.platoon.n_followers, cfg.platoon.dt
        drawn = draw_degradation(rng, cfg.degradation, n_followers, self.episode_ticks[env] * dt, dt)
        self.degradations[env] = parse_degradations(options["degradation"], n_followers) if "degradation" in options else drawn
        self.dropout_probability[env] = rng.uniform(*cfg.dropout_probability_range)
        self.noise_keys[env] = rng.integers(0, 2**63, dtype=np.uint64)
        if cfg.random_initial_setting:  # drawn last: the rest of the episode is the one it would be without
            self.initial_setting[env] = cfg.setting_levels[int(rng.integers(len(cfg.setting_levels)))]

    def _load_leader(self, env: int, profile: LeaderProfile) -> None:
        """Put ``profile`` in env's leader buffer, cut to the episode and padded to whole decisions."""
        tpd, capacity = self.ticks_per_decision, self.leader_speed.shape[1] - 1
        ticks = min(profile.speed.size - 1, capacity)
        ticks = -(-ticks // tpd) * tpd  # up to whole decisions
        n = min(profile.speed.size, ticks + 1)
        self.leader_speed[env, :n] = profile.speed[:n]
        self.leader_speed[env, n:] = profile.speed[n - 1]
        self.leader_accel[env, :n] = profile.accel[:n]
        self.leader_accel[env, n:] = 0.0
        self.episode_ticks[env] = ticks
        self.scenario[env] = profile.name

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
