"""SUMO against the native simulator (issue 26): the same leaders, settings and V2V through both, and the same
policies on the same episodes.

:func:`drive` runs one monitored platoon (sensors, monitor, chart as in the env) behind a recorded or synthetic leader
at one constant setting, with or without V2V, no degradation, in the simulator its config names, and measures:

- ``amplification``: the largest ratio of a follower's peak |acceleration| to its predecessor's (the leader's
  profile's for the first follower), each peak at least MIN_PEAK (a leader that hardly accelerates would make any
  ratio huge) [-]; above 1 a disturbance grew down the platoon (``string_stable`` is all ratios <= 1 +
  STABLE_TOLERANCE);
- ``gap_std``: the actual time gap's (s - s0) / v standard deviation over the ticks at speeds of at least
  TIME_GAP_MIN_SPEED, averaged over the followers [s]; ``gap_error``: its mean minus the setting [s];
- ``alarm_rate``: the share of follower-ticks the chart is in alarm [-];
- ``collision``: a gap of 0 or less was reached.

:func:`crosscheck_rows` does it for every leader piece of :data:`SOURCES` (distinct pieces: a recorded source has
few) x ladder setting x V2V x simulator setup of :data:`SETUPS`, a piece per backend job (SUMO runs one simulation per process: the processes backend spreads the
pieces). :func:`transfer_rows` plays policies on the same held-out episodes of ``TimeGapMonitor-v1`` natively and in
SUMO, through the rollout harness.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from timegap_env.config import TIME_GAP_MIN_SPEED, EnvConfig
from timegap_env.experiments.backends import Backend
from timegap_env.experiments.rollout import rollout
from timegap_env.leaders import make_leader
from timegap_env.leaders.profile import LeaderProfile
from timegap_env.monitoring.loop import MonitoredPlatoon

SOURCES = {"paper": "paper", "ngsim": "ngsim_in_band", "openacc": "openacc"}  # name -> the leader scenario
SETUPS: dict[str, dict[str, Any]] = {  # the simulators compared: name -> EnvConfig overrides
    "native": {},
    "sumo_cc": {"simulator": "sumo", "sumo": {"model": "cc"}},
    "sumo_cacc": {"simulator": "sumo", "sumo": {"model": "cacc"}},
}
METRICS = ("amplification", "string_stable", "gap_std", "gap_error", "alarm_rate", "collision")
STABLE_TOLERANCE = 0.01  # a peak ratio up to 1 + this counts as no growth [-]
MIN_PEAK = 0.1  # the smallest peak |acceleration| a ratio divides by [m/s^2]
PIECE_SEED_START = 10_000  # the leader pieces' seeds (never used for any choice) [-]
MAX_DRAWS = 10  # seeds tried per distinct piece wanted (a recorded source repeats pieces) [-]


def drive(config: EnvConfig, profile: LeaderProfile, setting: float, v2v: bool, seed: int) -> dict[str, float]:
    """One platoon of ``config`` (its simulator) behind ``profile`` at ``setting`` [s], V2V on or off, sensor noise
    seeded by ``seed``: the module docstring's metrics."""
    platoon = config.platoon.with_overrides({"v2v": v2v})
    physics = None
    if config.simulator == "sumo":
        from timegap_env.sim.sumo import SumoPlatoon  # libsumo only when asked for

        physics = SumoPlatoon(platoon, config.sumo, profile.duration)
    loop = MonitoredPlatoon(platoon, config.monitor, config.chart, config.sensors, 1, seed=seed, physics=physics)
    try:
        loop.reset(float(profile.speed[0]), float(profile.accel[0]), setting=setting)
        block = loop.run(profile.speed[1:, None], profile.accel[1:, None])
    finally:
        if physics is not None:
            physics.close()
    accel, speed, spacing = block.physics.accel[:, 0], block.physics.speed[:, 0], block.physics.spacing[:, 0]
    peaks = np.concatenate([[np.abs(profile.accel[1:]).max()], np.abs(accel).max(axis=0)])
    peaks = np.maximum(peaks, MIN_PEAK)
    ratios = peaks[1:] / peaks[:-1]
    moving = speed >= TIME_GAP_MIN_SPEED
    gap = np.where(moving, (spacing - platoon.standstill_spacing) / np.where(moving, speed, 1.0), np.nan)
    return {"amplification": float(ratios.max()), "string_stable": float(np.all(ratios <= 1.0 + STABLE_TOLERANCE)),
            "gap_std": float(np.nanmean(np.nanstd(gap, axis=0))), "gap_error": float(np.nanmean(gap) - setting),
            "alarm_rate": float(block.chart.alarm.mean()), "collision": float(block.physics.collisions.any())}


def piece_rows(source: str, seed: int, config: EnvConfig) -> list[dict[str, Any]]:
    """Every ladder setting x V2V x simulator behind the leader piece ``seed`` of ``source`` (a row each)."""
    profile = make_leader(SOURCES[source], seed, config.leader)
    rows = []
    for simulator, overrides in SETUPS.items():
        sim_config = config.nested_overrides(overrides)
        for v2v in (False, True):
            for setting in config.setting_levels:
                rows.append({"source": source, "piece": profile.name, "seed": seed, "simulator": simulator,
                             "v2v": v2v, "setting": setting, "duration": profile.duration,
                             **drive(sim_config, profile, setting, v2v, seed)})
    return rows


def distinct_seeds(source: str, count: int, config: EnvConfig) -> list[int]:
    """Seeds from PIECE_SEED_START of up to ``count`` distinct leader pieces of ``source`` (distinct speed profiles),
    at most MAX_DRAWS * count seeds tried."""
    seeds, seen = [], set()
    for seed in range(PIECE_SEED_START, PIECE_SEED_START + MAX_DRAWS * count):
        profile = make_leader(SOURCES[source], seed, config.leader).speed.tobytes()
        if profile not in seen:
            seen.add(profile)
            seeds.append(seed)
        if len(seeds) == count:
            break
    return seeds


def crosscheck_rows(config: EnvConfig, pieces: Mapping[str, int], backend: Backend) -> list[dict[str, Any]]:
    """:func:`piece_rows` of up to ``pieces[source]`` distinct pieces of each source (:func:`distinct_seeds`), a
    backend job each; ``ValueError`` naming an unknown source."""
    unknown = sorted(set(pieces) - set(SOURCES))
    if unknown:
        raise ValueError(f"sources {unknown}: unknown; known: {list(SOURCES)}")
    jobs = [(source, seed, config) for source, count in pieces.items()
            for seed in distinct_seeds(source, count, config)]
    return [row for rows in backend.map(piece_rows, jobs) for row in rows]


def policy_returns(config: EnvConfig, seeds: Sequence[int], policy: Any) -> np.ndarray:
    """``policy``'s return on each of ``seeds`` in ``config``'s env (n_seeds,)."""
    return np.array([record.episode_return for record in rollout(policy, config, seeds).records])


def transfer_returns(config: EnvConfig, seeds: Sequence[int], policies: Mapping[str, Any], backend: Backend
                     ) -> dict[str, dict[str, np.ndarray]]:
    """Per simulator setup of SETUPS, per policy, its returns on ``seeds`` of ``config``'s env run there; a backend job
    per (simulator, policy)."""
    configs = {name: config.nested_overrides(overrides) for name, overrides in SETUPS.items()}
    jobs = [(configs[simulator], list(seeds), policy) for simulator in configs for policy in policies.values()]
    results = iter(backend.map(policy_returns, jobs))
    return {simulator: {name: next(results) for name in policies} for simulator in configs}


__all__ = ["MAX_DRAWS", "METRICS", "MIN_PEAK", "PIECE_SEED_START", "SETUPS", "SOURCES", "STABLE_TOLERANCE",
           "crosscheck_rows", "distinct_seeds", "drive", "piece_rows", "policy_returns", "transfer_returns"]
