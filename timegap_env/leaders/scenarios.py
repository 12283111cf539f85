"""Named scenarios: which leader family a name stands for.

``make_leader(name, seed, leader)`` builds the leader profile of a scenario, ``make_leaders(name,
seeds, leader)`` those of many seeds at once (what a batched reset uses); ``SCENARIOS`` lists them. ``paper`` is the paper's leader (aggressive
acceleration/deceleration cycles in 20-80 mph, 250 s at 0.1 s ticks); the rest of
the paper's Table 1 (T = 0.45 s, K = 1, tau* = 1.6 s, s0 = 5 m, five followers) is
the default :class:`~timegap_env.config.PlatoonConfig`.

A scenario names a leader only: the platoon, the tick and the length of a profile
are the caller's (``simulate``'s ``config``, the env's ``EnvConfig``).
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from timegap_env.config import (
    AggressiveCyclesConfig, HardBrakingConfig, LeaderConfig, SinusoidConfig, StochasticHumanConfig,
)
from timegap_env.leaders import idm, ngsim, openacc, synthetic
from timegap_env.leaders.profile import LeaderProfile, LeaderProfiles

LeaderFamily = Callable[..., LeaderProfile]  # (seed, leader config, params=None) -> profile
LeaderBatchFamily = Callable[..., LeaderProfiles]  # (seeds, leader config, params=None) -> a profile per seed


@functools.lru_cache(maxsize=2)
def _ngsim_table(path: Path) -> ngsim.NgsimTable:
    """The NGSIM file at ``path``, read once per process."""
    return ngsim.read_ngsim(path)


def ngsim_leader(seed: int | None, leader: LeaderConfig, *, within_band: bool) -> LeaderProfile:
    """A real NGSIM vehicle drawn by ``seed``: its recorded speed, or its acceleration integrated within the band."""
    path = ngsim.default_ngsim_path()
    if not path.exists():
        raise FileNotFoundError(
            f"NGSIM data not found at {path}: set ${ngsim.PATH_VARIABLE} to an NGSIM trajectory CSV"
        )
    if path.is_dir():
        raise IsADirectoryError(f"NGSIM data at {path} is a directory: set ${ngsim.PATH_VARIABLE} to an NGSIM "
                                "trajectory CSV (.csv or .csv.gz)")
    table = _ngsim_table(path)
    ids = ngsim.vehicle_ids(table, min_duration=leader.min_recorded_duration)
    if not ids:
        raise ValueError(f"{ngsim.no_vehicle_reason(table, leader.min_recorded_duration)} (a leader needs "
                         f"LeaderConfig.min_recorded_duration = {leader.min_recorded_duration} s)")
    vehicle = np.random.default_rng(seed).choice(ids)
    return ngsim.vehicle_profile(table, int(vehicle), within_band=leader if within_band else None)


# The synthetic families' parameters: family -> its parameter dataclass, the defaults of which the functions below
# use unless given one (``EnvConfig.leader_params`` reaches them from gym.make).
FAMILY_PARAMS: dict[str, type] = {
    "aggressive_cycles": AggressiveCyclesConfig, "sinusoid": SinusoidConfig, "hard_braking": HardBrakingConfig,
    "stochastic_human": StochasticHumanConfig, "stop_and_go": synthetic.StopAndGoConfig,
    "emergency_braking": synthetic.EmergencyBrakingConfig,
}


def _params(family: str, params: Any) -> Any:
    """``params`` for ``family``, or its parameter dataclass's defaults when None."""
    return FAMILY_PARAMS[family]() if params is None else params


LEADER_FAMILIES: dict[str, LeaderFamily] = {
    **{family: (lambda seed, leader, params=None, family=family:
                getattr(synthetic, family)(seed, _params(family, params), leader)) for family in FAMILY_PARAMS},
    "ngsim": lambda seed, leader, params=None: ngsim_leader(seed, leader, within_band=False),
    "ngsim_in_band": lambda seed, leader, params=None: ngsim_leader(seed, leader, within_band=True),
    # the human-driven lead car of a real ACC platoon (OpenACC AstaZero)
    "openacc": lambda seed, leader, params=None: openacc.openacc_leader(seed, leader),
    # highway-env's IDM driver reacting to scripted hard braking ahead of it
    "idm": lambda seed, leader, params=None: idm.idm_leader(synthetic.hard_braking(seed, leader=leader), seed=seed),
}

# The families that build many seeds' profiles at once (all of one length), each the batch its single-seed
# function above builds from one seed.
LEADER_BATCHES: dict[str, LeaderBatchFamily] = {
    family: (lambda seeds, leader, params=None, family=family:
             getattr(synthetic, f"{family}_batch")(seeds, _params(family, params), leader)) for family in FAMILY_PARAMS
}

# Harsh leaders the default training mix (EnvConfig.scenario_weights) never draws: for held-out evaluation.
HELD_OUT_FAMILIES: tuple[str, ...] = ("stop_and_go", "emergency_braking")


@dataclasses.dataclass(frozen=True)
class Scenario:
    """A name for a leader family."""

    name: str
    leader_family: str  # a key of LEADER_FAMILIES
    description: str


SCENARIOS: dict[str, Scenario] = {
    "paper": Scenario(
        "paper",
        "aggressive_cycles",
        "The paper's experiment: aggressive cycles in 20-80 mph, 250 s, behind the default platoon "
        "(five CACC followers at tau* = 1.6 s).",
    ),
    **{
        family: Scenario(family, family, f"The {family.replace('_', ' ')} leader family.")
        for family in LEADER_FAMILIES
    },
}


def get_scenario(name: str) -> Scenario:
    """The scenario called ``name``; an unknown name raises ``ValueError`` listing the known ones."""
    if name not in SCENARIOS:
        raise ValueError(f"scenario = {name!r}: unknown; known scenarios: {sorted(SCENARIOS)}")
    return SCENARIOS[name]


def make_leader(name: str, seed: int | None = 0, leader: LeaderConfig = LeaderConfig(),
                params: Any = None) -> LeaderProfile:
    """The leader profile of scenario ``name`` for ``seed`` (same seed, identical profile) with ``leader``'s
    tick, length and speed band, and ``params`` (its family's parameter dataclass of FAMILY_PARAMS; None: the
    defaults)."""
    family = LEADER_FAMILIES[get_scenario(name).leader_family]
    return family(seed, leader) if params is None else family(seed, leader, params)  # (a family may take no params)


def make_leaders(name: str, seeds: Sequence[int | None], leader: LeaderConfig = LeaderConfig(),
                 params: Any = None) -> list[LeaderProfiles]:
    """The leader profiles of scenario ``name`` for each of ``seeds``, as :func:`make_leader` builds them, in
    batches whose rows, batch after batch, are the seeds' profiles in order: one batch for a family of
    LEADER_BATCHES, one per seed for the others (recorded leaders differ in length)."""
    family = get_scenario(name).leader_family
    if family in LEADER_BATCHES:
        return [LEADER_BATCHES[family](list(seeds), leader, params)] if len(seeds) else []
    return [LeaderProfiles.of(make_leader(name, seed, leader, params)) for seed in seeds]


def family_params(overrides: Mapping[str, Any]) -> dict[str, Any]:
    """``EnvConfig.leader_params`` (family -> a dict of its parameter dataclass's fields) as family -> the dataclass;
    ``ValueError`` naming an unknown family (or one without parameters) or a bad field."""
    params = {}
    for family, fields in overrides.items():
        if family not in FAMILY_PARAMS:
            raise ValueError(f"EnvConfig.leader_params has family {family!r}: the families with parameters are "
                             f"{sorted(FAMILY_PARAMS)}")
        try:
            params[family] = FAMILY_PARAMS[family]().with_overrides(fields)
        except ValueError as error:
            raise ValueError(f"EnvConfig.leader_params[{family!r}]: {error}") from error
    return params
