"""SUMO against the native simulator (issue 26): the same leaders, settings and V2V through both, and the same
policies on the same episodes.

:func:`drive` runs one monitored platoon (sensors, monitor, chart as in the env) behind a recorded or synthetic leader
at one constant setting, with or without V2V, no degradation, in the simulator its config names, and measures:

- ``amplification``: the largest ratio of a follower's peak |acceleration| to its predecessor's (the leader's
  profile's for the first follower) [-]; above 1 a disturbance grew down the platoon (``string_stable`` is all
  ratios <= 1 + STABLE_TOLERANCE);
- ``gap_std``: the actual time gap's (s - s0) / v standard deviation over the ticks at speeds of at least
  TIME_GAP_MIN_SPEED, averaged over the followers [s]; ``gap_error``: its mean minus the setting [s];
- ``alarm_rate``: the share of follower-ticks the chart is in alarm [-];
- ``collision``: a gap of 0 or less was reached.

:func:`crosscheck_rows` does it for every leader piece of :data:`SOURCES` x ladder setting x V2V x simulator of
:data:`SIMULATORS`, a piece per backend job (SUMO runs one simulation per process: the processes backend spreads the
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
SIMULATORS: dict[str, dict[str, Any]] = {  # name -> EnvConfig overrides
    "native": {},
    "sumo_cc": {"simulator": "sumo", "sumo": {"model": "cc"}},
    "sumo_cacc": {"simulator": "sumo", "sumo": {"model": "cacc"}},
}
METRICS = ("amplification", "string_stable", "gap_std", "gap_error", "alarm_rate", "collision")
STABLE_TOLERANCE = 0.01  # a peak ratio up to 1 + this counts as no growth [-]
PIECE_SEED_START = 10_000  # the leader pieces' seeds (never used for any choice) [-]


def drive(config: EnvConfig, profile: LeaderProfile, setting: float, v2v: bool, seed: int) -> dict[str, float]:
    """One platoon of ``config`` (its simulator) behind ``profile`` at ``setting`` [s], V2V on or off, sensor noise
    seeded by ``seed``: the module docstring's metrics."""
    platoon = config.platoon.with_overrides({"v2v": v2v})
    simulator = None
    if config.simulator == "sumo":
        from timegap_env.sim.sumo import SumoPlatoon  # libsumo only when asked for

        simulator = SumoPlatoon(platoon, config.sumo, profile.duration)
    loop = MonitoredPlatoon(platoon, config.monitor, config.chart, config.sensors, 1, seed=seed, simulator=simulator)
    try:
        loop.reset(float(profile.speed[0]), float(profile.accel[0]), setting=setting)
        block = loop.run(profile.speed[1:, None], profile.accel[1:, None])
    finally:
        if simulator is not None:
            simulator.close()
    accel, speed, spacing = block.physics.accel[:, 0], block.physics.speed[:, 0], block.physics.spacing[:, 0]
    peaks = np.concatenate([[np.abs(profile.accel[1:]).max()], np.abs(accel).max(axis=0)])
    ratios = peaks[1:] / np.maximum(peaks[:-1], 1e-9)
    moving = speed >= TIME_GAP_MIN_SPEED
    gap = np.where(moving, (spacing - platoon.standstill_spacing) / np.where(moving, speed, 1.0), np.nan)
    return {"amplification": float(ratios.max()), "string_stable": float(np.all(ratios <= 1.0 + STABLE_TOLERANCE)),
            "gap_std": float(np.nanmean(np.nanstd(gap, axis=0))), "gap_error": float(np.nanmean(gap) - setting),
            "alarm_rate": float(block.chart.alarm.mean()), "collision": float(block.physics.collisions.any())}


def piece_rows(source: str, seed: int, config: EnvConfig) -> list[dict[str, Any]]:
    """Every ladder setting x V2V x simulator behind the leader piece ``seed`` of ``source`` (a row each)."""
    profile = make_leader(SOURCES[source], seed, config.leader)
    rows = []
    for simulator, overrides in SIMULATORS.items():
        sim_config = config.nested_overrides(overrides)
        for v2v in (False, True):
            for setting in config.setting_levels:
                rows.append({"source": source, "piece": profile.name, "seed": seed, "simulator": simulator,
                             "v2v": v2v, "setting": setting, "duration": profile.duration,
                             **drive(sim_config, profile, setting, v2v, seed)})
    return rows


def crosscheck_rows(config: EnvConfig, pieces: Mapping[str, int], backend: Backend) -> list[dict[str, Any]]:
    """:func:`piece_rows` of ``pieces[source]`` pieces of each source (seeds from PIECE_SEED_START), a backend job
    each; ``ValueError`` naming an unknown source."""
    unknown = sorted(set(pieces) - set(SOURCES))
    if unknown:
        raise ValueError(f"sources {unknown}: unknown; known: {list(SOURCES)}")
    jobs = [(source, PIECE_SEED_START + i, config) for source, count in pieces.items() for i in range(count)]
    return [row for rows in backend.map(piece_rows, jobs) for row in rows]


def policy_returns(config: EnvConfig, seeds: Sequence[int], policy: Any) -> np.ndarray:
    """``policy``'s return on each of ``seeds`` in ``config``'s env (n_seeds,)."""
    return np.array([record.episode_return for record in rollout(policy, config, seeds).records])


def transfer_returns(config: EnvConfig, seeds: Sequence[int], policies: Mapping[str, Any], backend: Backend
                     ) -> dict[str, dict[str, np.ndarray]]:
    """Per simulator of SIMULATORS, per policy, its returns on ``seeds`` of ``config``'s env run there; a backend job
    per (simulator, policy)."""
    configs = {name: config.nested_overrides(overrides) for name, overrides in SIMULATORS.items()}
    jobs = [(configs[simulator], list(seeds), policy) for simulator in configs for policy in policies.values()]
    results = iter(backend.map(policy_returns, jobs))
    return {simulator: {name: next(results) for name in policies} for simulator in configs}


__all__ = ["METRICS", "PIECE_SEED_START", "SIMULATORS", "SOURCES", "STABLE_TOLERANCE", "crosscheck_rows", "drive",
           "piece_rows", "policy_returns", "transfer_returns"]
