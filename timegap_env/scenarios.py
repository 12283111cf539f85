"""Named scenarios: a leader family plus the platoon and leader configs it runs with.

``make_leader(name, seed)`` builds the leader profile of a scenario;
``SCENARIOS`` lists them. ``paper`` follows the paper's Table 1: 250 s at
0.1 s ticks, T = 0.45 s, K = 1, tau* = 1.6 s, s0 = 5 m, five followers, and
the aggressive acceleration/deceleration leader in 20-80 mph.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from pathlib import Path

import numpy as np

from timegap_env import human_leader, leaders, ngsim
from timegap_env.config import LeaderConfig, PlatoonConfig
from timegap_env.leaders import LeaderProfile

LeaderFamily = Callable[[int | None, LeaderConfig], LeaderProfile]


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
    table = _ngsim_table(path)
    vehicle = np.random.default_rng(seed).choice(ngsim.vehicle_ids(table, min_duration=leader.ngsim_min_duration))
    return ngsim.vehicle_profile(table, int(vehicle), within_band=leader if within_band else None)


LEADER_FAMILIES: dict[str, LeaderFamily] = {
    "aggressive_cycles": lambda seed, leader: leaders.aggressive_cycles(seed, leader=leader),
    "sinusoid": lambda seed, leader: leaders.sinusoid(seed, leader=leader),
    "hard_braking": lambda seed, leader: leaders.hard_braking(seed, leader=leader),
    "stochastic_human": lambda seed, leader: leaders.stochastic_human(seed, leader=leader),
    "ngsim": lambda seed, leader: ngsim_leader(seed, leader, within_band=False),
    "ngsim_in_band": lambda seed, leader: ngsim_leader(seed, leader, within_band=True),
    # highway-env's IDM driver reacting to scripted hard braking ahead of it
    "idm": lambda seed, leader: human_leader.idm_leader(leaders.hard_braking(seed, leader=leader), seed=seed),
}


@dataclasses.dataclass(frozen=True)
class Scenario:
    """A leader family with the configs it runs with."""

    name: str
    leader_family: str
    description: str
    platoon: PlatoonConfig = PlatoonConfig()
    leader: LeaderConfig = LeaderConfig()


PAPER_PLATOON = PlatoonConfig(
    n_followers=5, dt=0.1, actuation_lag=0.45, actuation_gain=1.0, time_gap=1.6, standstill_spacing=5.0
)
PAPER_LEADER = LeaderConfig(dt=0.1, duration=250.0)

SCENARIOS: dict[str, Scenario] = {
    "paper": Scenario(
        "paper",
        "aggressive_cycles",
        "The paper's experiment: aggressive cycles in 20-80 mph, 250 s, five CACC followers at tau* = 1.6 s.",
        PAPER_PLATOON,
        PAPER_LEADER,
    ),
    **{
        family: Scenario(family, family, f"The {family.replace('_', ' ')} leader family with default configs.")
        for family in LEADER_FAMILIES
    },
}


def get_scenario(name: str) -> Scenario:
    """The scenario called ``name``; an unknown name raises ``ValueError`` listing the known ones."""
    if name not in SCENARIOS:
        raise ValueError(f"scenario = {name!r}: unknown; known scenarios: {sorted(SCENARIOS)}")
    return SCENARIOS[name]


def make_leader(name: str, seed: int | None = 0, leader: LeaderConfig | None = None) -> LeaderProfile:
    """The leader profile of scenario ``name`` for ``seed`` (same seed, identical profile)."""
    scenario = get_scenario(name)
    return LEADER_FAMILIES[scenario.leader_family](seed, leader or scenario.leader)
