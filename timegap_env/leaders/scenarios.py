"""The leader families and the scenario names that stand for them.

A leader family is one :class:`LeaderFamily` record (its builder, its parameter dataclass, its batch builder) in
:data:`LEADER_FAMILIES`; :func:`register_family` adds one. ``SCENARIOS`` lists the scenario names: every family's,
and ``paper``, the paper's leader (aggressive acceleration/deceleration cycles in 20-80 mph, 250 s at 0.1 s ticks;
the rest of the paper's Table 1, T = 0.45 s, K = 1, tau* = 1.6 s, s0 = 5 m, five followers, is the default
:class:`~timegap_env.config.PlatoonConfig`). ``make_leader(name, seed, leader)`` builds the leader profile of a
scenario, ``make_leaders(name, seeds, leader)`` those of many seeds at once (what a batched reset uses).

A scenario names a leader only: the platoon, the tick and the length of a profile
are the caller's (``simulate``'s ``config``, the env's ``EnvConfig``).
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any, NoReturn

import numpy as np

from timegap_env.config import (
    AggressiveCyclesConfig, ConfigMixin, HardBrakingConfig, LeaderConfig, SinusoidConfig, StochasticHumanConfig, shown,
)
from timegap_env.leaders import idm, ngsim, openacc, regimes, synthetic
from timegap_env.leaders.profile import LeaderProfile, LeaderProfiles, recorded_part

Build = Callable[[int | None, Any, LeaderConfig], LeaderProfile]  # (seed, params, leader) -> profile
BatchBuild = Callable[[Sequence[int | None], Any, LeaderConfig], LeaderProfiles]  # (seeds, params, leader) -> rows
Schedule = Callable[[int | None, Any, LeaderConfig], tuple[np.ndarray, tuple[str, ...]]]  # (seed, params, leader) ->
# (the regime of each tick as codes, the regimes' names)
USER = "user"  # the scenario of the user's own leader (reset(options={"leader_speed": ...}))


@dataclasses.dataclass(frozen=True)
class LeaderFamily:
    """A leader family: how its leader is built for a seed, and with which parameters.

    ``build(seed, params, leader)`` returns the :class:`~timegap_env.leaders.profile.LeaderProfile` of ``seed`` (an
    int or None; the same seed, the same profile): speeds [m/s] and accelerations [m/s^2] at ``leader.dt`` [s] for
    ``leader.duration`` [s], ``leader`` the env's :class:`~timegap_env.config.LeaderConfig`. ``params`` is the
    family's parameter dataclass (a :class:`~timegap_env.config.ConfigMixin` subclass: its defaults are the family's,
    ``EnvConfig.leader_params`` overrides its fields), or None for a family without parameters, whose ``build`` gets
    None. ``batch(seeds, params, leader)``, optional, builds many seeds' profiles at once (one length), row ``i``
    equal to ``build(seeds[i], params, leader)``: batched resets use it. A family whose traffic changes within an
    episode names its ``regimes`` and gives their ``schedule(seed, params, leader)``: a code per tick of ``build``'s
    profile (an index into ``regimes``) and the names; the ground truth reports it (:func:`regime_names`). Its
    ``batch`` may give those codes with the profiles (``LeaderProfiles.regime``, indices into ``regimes``), worked
    out once for both: a batched reset then reads them there instead of calling ``schedule``. A family without
    regimes is one regime throughout, named after itself.
    """

    name: str  # the scenario name that draws it
    build: Build
    description: str
    params: type[ConfigMixin] | None = None
    batch: BatchBuild | None = None
    regimes: tuple[str, ...] = ()
    schedule: Schedule | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            self._fail("name", self.name, "must be a non-empty str")
        if not callable(self.build):
            self._fail("build", self.build, "must be callable as build(seed, params, leader) -> LeaderProfile")
        if not isinstance(self.description, str):
            self._fail("description", self.description, "must be a str")
        if self.params is not None and not (isinstance(self.params, type) and dataclasses.is_dataclass(self.params)
                                            and issubclass(self.params, ConfigMixin)):
            self._fail("params", self.params, "must be None (no parameters) or a dataclass type subclassing "
                       "timegap_env.config.ConfigMixin")
        if self.batch is not None and not callable(self.batch):
            self._fail("batch", self.batch, "must be None or callable as batch(seeds, params, leader) -> "
                       "LeaderProfiles")
        if not isinstance(self.regimes, tuple) or not all(isinstance(name, str) and name for name in self.regimes):
            self._fail("regimes", self.regimes, "must be a tuple of non-empty names")
        if (self.schedule is None) != (not self.regimes) or (self.schedule is not None and not callable(self.schedule)):
            self._fail("schedule", self.schedule, "must be callable as schedule(seed, params, leader) -> (codes, "
                       "names) when the family names regimes, else None")

    def _fail(self, field: str, value: Any, rule: str) -> NoReturn:
        raise ValueError(f"LeaderFamily.{field} = {shown(value)}: {rule}")


@dataclasses.dataclass(frozen=True)
class Scenario:
    """A name for a leader family."""

    name: str
    leader_family: str  # a key of LEADER_FAMILIES
    description: str


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
    ids = recorded_part(ngsim.vehicle_ids(table, min_duration=leader.min_recorded_duration), leader.recorded_part)
    if not ids:
        raise ValueError(f"{ngsim.no_vehicle_reason(table, leader.min_recorded_duration)} (a leader needs "
                         f"LeaderConfig.min_recorded_duration = {leader.min_recorded_duration} s, from "
                         f"LeaderConfig.recorded_part = {leader.recorded_part!r})")
    vehicle = np.random.default_rng(seed).choice(ids)
    return ngsim.vehicle_profile(table, int(vehicle), within_band=leader if within_band else None)


@functools.lru_cache(maxsize=4096)
def _seeded_idm_leader(seed: int, leader: LeaderConfig) -> LeaderProfile:
    """:func:`idm_leader` of an int seed, kept: highway-env's driver takes about 0.3 s a profile, and every policy
    of an evaluation replays the same seeds."""
    return idm.idm_leader(synthetic.hard_braking(seed, leader=leader), seed=seed)


def idm_leader(seed: int | None, leader: LeaderConfig) -> LeaderProfile:
    """highway-env's IDM driver reacting to scripted hard braking ahead of it (the same profile for the same seed)."""
    if seed is None:
        return idm.idm_leader(synthetic.hard_braking(seed, leader=leader), seed=seed)
    return _seeded_idm_leader(int(seed), leader)


# The leader families, name -> record: the one place a family is written (register_family adds one at run time).
LEADER_FAMILIES: dict[str, LeaderFamily] = {family.name: family for family in (
    LeaderFamily("aggressive_cycles", synthetic.aggressive_cycles,
                 "The paper's leader: alternating hard acceleration and deceleration phases.",
                 AggressiveCyclesConfig, synthetic.aggressive_cycles_batch),
    LeaderFamily("sinusoid", synthetic.sinusoid, "A speed oscillation.", SinusoidConfig, synthetic.sinusoid_batch),
    LeaderFamily("hard_braking", synthetic.hard_braking, "Cruising with hard braking events.",
                 HardBrakingConfig, synthetic.hard_braking_batch),
    LeaderFamily("stochastic_human", synthetic.stochastic_human, "A human-like wandering speed.",
                 StochasticHumanConfig, synthetic.stochastic_human_batch),
    LeaderFamily("stop_and_go", synthetic.stop_and_go, "Congestion waves: braking to a crawl (0-5 m/s) and back.",
                 synthetic.StopAndGoConfig, synthetic.stop_and_go_batch),
    LeaderFamily("emergency_braking", synthetic.emergency_braking,
                 "Highway cruising with emergency stops at 6-7.5 m/s^2.",
                 synthetic.EmergencyBrakingConfig, synthetic.emergency_braking_batch),
    LeaderFamily("regimes", regimes.regimes,
                 "Traffic that changes within an episode: free flow, slow oscillation, aggressive cycles, "
                 "stop-and-go and hard braking regimes in turn.", regimes.RegimesConfig, regimes.regimes_batch,
                 regimes=regimes.REGIMES, schedule=regimes.regime_schedule),
    LeaderFamily("ngsim", lambda seed, params, leader: ngsim_leader(seed, leader, within_band=False),
                 "A real NGSIM I-80 driver's recorded speed."),
    LeaderFamily("ngsim_in_band", lambda seed, params, leader: ngsim_leader(seed, leader, within_band=True),
                 "A real NGSIM I-80 driver's acceleration, integrated within the speed band."),
    LeaderFamily("openacc", lambda seed, params, leader: openacc.openacc_leader(seed, leader),
                 "The human-driven lead car of a real ACC platoon (OpenACC AstaZero)."),
    LeaderFamily("idm", lambda seed, params, leader: idm_leader(seed, leader),
                 "highway-env's IDM driver reacting to scripted hard braking ahead of it."),
)}

# Scenario names that are not a family's own.
_ALIASES: dict[str, Scenario] = {
    "paper": Scenario("paper", "aggressive_cycles", "The paper's experiment: aggressive cycles in 20-80 mph, 250 s, "
                      "behind the default platoon (five CACC followers at tau* = 1.6 s)."),
}

# Harsh leaders the default training mix (EnvConfig.scenario_weights) never draws: for held-out evaluation.
HELD_OUT_FAMILIES: tuple[str, ...] = ("stop_and_go", "emergency_braking")


def register_family(family: LeaderFamily, *, replace: bool = False) -> None:
    """Make ``family`` a scenario of this process: ``EnvConfig.scenario_weights`` draws it, ``reset(options=
    {"scenario": family.name})`` picks it, ``EnvConfig.leader_params`` sets its parameters (if it has any) and
    ``timegap_env.simulate(family.name)`` runs behind it (its speeds in m/s, at the env's tick ``LeaderConfig.dt``).

    ``ValueError`` if ``family`` is not a :class:`LeaderFamily` or its name is a scenario already (a family's, which
    ``replace=True`` replaces; ``"paper"``, which nothing replaces). The registry lives in this process: another
    process (a spawned vector env's worker, a sweep's) has the family only if it imports the module that registers
    it, e.g. through ``gym.make("your_module:TimeGapMonitor-v0", ...)``, which imports ``your_module`` first.
    """
    if not isinstance(family, LeaderFamily):
        raise ValueError(f"register_family: family = {shown(family)} must be a LeaderFamily")
    if family.name == USER:
        raise ValueError(f"LeaderFamily.name = {family.name!r}: the name of the user's own leader; choose another")
    if family.name in _ALIASES:
        raise ValueError(f"LeaderFamily.name = {family.name!r}: a scenario name already (the "
                         f"{_ALIASES[family.name].leader_family} family's); choose another")
    if family.name in LEADER_FAMILIES and not replace:
        raise ValueError(f"LeaderFamily.name = {family.name!r}: a leader family already; register_family(..., "
                         "replace=True) replaces it")
    LEADER_FAMILIES[family.name] = family


class _Scenarios(Mapping[str, Scenario]):
    """Scenario name -> :class:`Scenario`: the aliases', then each family's of LEADER_FAMILIES, read at every
    lookup (a family registered later is a scenario at once)."""

    def __getitem__(self, name: str) -> Scenario:
        if name in _ALIASES:
            return _ALIASES[name]
        return Scenario(name, name, LEADER_FAMILIES[name].description)

    def __iter__(self) -> Iterator[str]:
        return iter([*_ALIASES, *LEADER_FAMILIES])

    def __len__(self) -> int:
        return len(_ALIASES) + len(LEADER_FAMILIES)


SCENARIOS: Mapping[str, Scenario] = _Scenarios()


def regime_names() -> tuple[str, ...]:
    """Every regime a leader can be in, the ground truth's ``regime`` codes (indices into it): each family of
    LEADER_FAMILIES in turn, as its own name, or ``"<family>:<regime>"`` for each regime of a family that names
    them; then USER. A family registered later adds its names at the end (the codes before stay)."""
    names: list[str] = []
    for name, family in LEADER_FAMILIES.items():
        names += [f"{name}:{regime}" for regime in family.regimes] if family.regimes else [name]
    return (*names, USER)


def get_scenario(name: str) -> Scenario:
    """The scenario called ``name``; an unknown name raises ``ValueError`` listing the known ones."""
    if name not in SCENARIOS:
        raise ValueError(f"scenario = {name!r}: unknown; known scenarios: {sorted(SCENARIOS)}")
    return SCENARIOS[name]


def _family_and_params(name: str, params: Any) -> tuple[LeaderFamily, Any]:
    """The family of scenario ``name`` and ``params`` for it (None: its defaults, or None for a family without
    parameters); ``ValueError`` for params of another type."""
    family = LEADER_FAMILIES[get_scenario(name).leader_family]
    if params is None:
        return family, None if family.params is None else family.params()
    if family.params is None or not isinstance(params, family.params):
        wanted = "no parameters" if family.params is None else f"a {family.params.__name__}"
        raise ValueError(f"params = {shown(params)}: scenario {name!r} takes {wanted}")
    return family, params


def make_leader(name: str, seed: int | None = 0, leader: LeaderConfig = LeaderConfig(),
                params: Any = None) -> LeaderProfile:
    """The leader profile of scenario ``name`` for ``seed`` (same seed, identical profile) with ``leader``'s
    tick, length and speed band, and ``params`` (an instance of its family's parameter dataclass; None: the
    defaults)."""
    family, params = _family_and_params(name, params)
    return family.build(seed, params, leader)


def make_leaders(name: str, seeds: Sequence[int | None], leader: LeaderConfig = LeaderConfig(),
                 params: Any = None) -> list[LeaderProfiles]:
    """The leader profiles of scenario ``name`` for each of ``seeds``, as :func:`make_leader` builds them, in
    batches whose rows, batch after batch, are the seeds' profiles in order: one batch for a family with a
    ``batch`` builder, one per seed for the others (recorded leaders differ in length)."""
    family, params = _family_and_params(name, params)
    if family.batch is None:
        return [LeaderProfiles.of(family.build(seed, params, leader)) for seed in seeds]
    return [family.batch(list(seeds), params, leader)] if len(seeds) else []


def family_params(overrides: Mapping[str, Any]) -> dict[str, Any]:
    """``EnvConfig.leader_params`` (family -> a dict of its parameter dataclass's fields) as family -> the dataclass;
    ``ValueError`` naming an unknown family (or one without parameters) or a bad field."""
    params = {}
    for name, fields in overrides.items():
        family = LEADER_FAMILIES.get(name)
        if family is None or family.params is None:
            with_params = sorted(known for known, record in LEADER_FAMILIES.items() if record.params is not None)
            raise ValueError(f"EnvConfig.leader_params has family {name!r}: the families with parameters are "
                             f"{with_params}")
        try:
            params[name] = family.params().with_overrides(fields)
        except ValueError as error:
            raise ValueError(f"EnvConfig.leader_params[{name!r}]: {error}") from error
    return params


def missing_data(scenario: str) -> str:
    """Why the leaders of ``scenario`` cannot be built here ("" if they can): the NGSIM or OpenACC data they are
    read from is not found (the path and the variable that sets it)."""
    if scenario.startswith("ngsim") and not ngsim.default_ngsim_path().is_file():
        return f"no NGSIM data at {ngsim.default_ngsim_path()} (${ngsim.PATH_VARIABLE})"
    if scenario == "openacc":
        try:
            found = bool(openacc.openacc_paths(openacc.default_openacc_dir()))
        except OSError:
            found = False
        if not found:
            return f"no OpenACC data in {openacc.default_openacc_dir()} (${openacc.PATH_VARIABLE})"
    return ""
