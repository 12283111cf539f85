"""The tasks: each registered id is one :class:`Task` record, and the id is the whole task.

A task is its config (overrides of :class:`~timegap_env.config.EnvConfig`'s defaults), the layout of its info, the
seeds each step of a study uses, the held-out groups the benchmark plays (``train/benchmark.py``) and the references
that know the truth. Nothing switches a task behind its id: ``gym.make(id)`` builds the record's env (a ``config``
overrides fields of it, as it always did, and the env refuses a ``task_id`` other than the one it was made under),
and a new reward, dynamics, info layout or default is a new record with a new id, the older ones kept bit for bit.

    from timegap_env.tasks import TASKS, get_task
    task = get_task("TimeGapMonitor-v1")
    config = task.config({"episode_duration": 60.0})   # the task's config with overrides, an EnvConfig
"""

from __future__ import annotations

import dataclasses
import types
from collections.abc import Mapping
from typing import Any

import gymnasium as gym

from timegap_env.config import EnvConfig, _default_scenario_weights

INFO_LAYOUTS = ("v0", "v1")  # Task.info_layout: v0's keys; v1's add vector_reward, cost, objectives, truth_regime
SELECTION_SEED_START = 5_000  # choices (a constant, a reference, a recipe) on seeds from here [-]
CHECK_SEED_START = 9_000  # the end-of-training check and learning curve: seeds from here [-]
HELD_OUT_SEED_START = 10_000  # held-out episodes (the benchmark, every evaluation): seeds from here on [-]

LARGER_DEGRADATIONS = {  # every episode degraded, every size beyond the training range (DegradationConfig's)
    "kind_weights": {"lag": 1.0, "gain": 1.0, "v2v_latency": 1.0, "packet_loss": 1.0, "radar_bias": 1.0,
                     "radar_noise": 1.0},
    "lag_factor_range": (2.5, 3.5), "gain_range": (0.45, 0.6), "v2v_latency_range": (0.6, 0.9),
    "packet_loss_range": (0.9, 0.97), "radar_bias_range": (4.0, 6.0), "radar_noise_range": (1.0, 1.5),
}


@dataclasses.dataclass(frozen=True)
class Seeds:
    """Which seeds each step uses: training below ``held_out_start`` (tables built before a choice below
    ``selection_start``), choices from ``selection_start``, the check from ``check_start``, held-out episodes from
    ``held_out_start`` on, never used for a choice."""

    check_episodes: int  # episodes of the end-of-training check, seeds from CHECK_SEED_START [-]
    selection_start: int = SELECTION_SEED_START  # choices made before the held-out episodes [-]
    check_start: int = CHECK_SEED_START  # the end-of-training check [-]
    held_out_start: int = HELD_OUT_SEED_START  # held-out episodes, never used for a choice [-]

    @property
    def check(self) -> list[int]:
        """The seeds of the end-of-training check and the learning curve."""
        return list(range(self.check_start, self.check_start + self.check_episodes))


@dataclasses.dataclass(frozen=True)
class HeldOutGroup:
    """A group of held-out episodes the benchmark plays: the task's config with ``overrides``."""

    name: str
    description: str
    overrides: Mapping[str, Any]  # EnvConfig overrides of the task's config
    episodes: int  # held-out episodes: from the benchmark's pilot (--size) for its effect at its power [-]
    data: str = ""  # the scenario whose recorded data the group needs ("": none)
    references: bool = True  # the references play it (their tables need runs of every training condition)
    selection: int = 1_000  # the constants' selection episodes, seeds from Seeds.selection_start [-]
    capped: str = ""  # why ``episodes`` is below what power asks for ("": it is not)


@dataclasses.dataclass(frozen=True)
class Task:
    """One registered task: its id, config, info layout, seeds, held-out groups and references."""

    id: str  # the registered id, e.g. "TimeGapMonitor-v1"
    description: str  # what changed from the task before it (the env's version history)
    overrides: Mapping[str, Any]  # its config, as overrides of EnvConfig's defaults (nested configs as dicts)
    info_layout: str  # one of INFO_LAYOUTS
    seeds: Seeds
    groups: tuple[HeldOutGroup, ...] = ()  # the benchmark's groups, in its leaderboard's order; the first: its mix
    references: tuple[str, ...] = ()  # registry names of the policies that know the truth the benchmark plays

    def __post_init__(self) -> None:
        if self.info_layout not in INFO_LAYOUTS:
            raise ValueError(f"Task {self.id!r}: info_layout = {self.info_layout!r}: must be one of {INFO_LAYOUTS}")
        object.__setattr__(self, "overrides", types.MappingProxyType(dict(self.overrides)))

    def config(self, overrides: Mapping[str, Any] | EnvConfig | None = None) -> EnvConfig:
        """The task's config with ``overrides`` (nested configs as dicts of their fields; an EnvConfig is whole and
        returned as it is); ``ValueError`` naming a bad or unknown field."""
        if isinstance(overrides, EnvConfig):
            return overrides
        return EnvConfig().nested_overrides(dict(self.overrides)).nested_overrides(overrides)

    def group(self, name: str) -> HeldOutGroup:
        """The held-out group ``name``; ``ValueError`` naming it and the known ones otherwise."""
        for group in self.groups:
            if group.name == name:
                return group
        raise ValueError(f"group {name!r}: not a held-out group of {self.id}; known: {[g.name for g in self.groups]}")


V1_GROUPS = (  # sizes: `python -m train.benchmark --size` (docs/benchmark.md), rounded up to 250, at least 1000
    HeldOutGroup("default", "the task's own mix (TimeGapMonitor-v1)", {}, 2_500),
    HeldOutGroup("regimes", "traffic that changes within every episode", {"scenario_weights": {"regimes": 1.0}}, 3_250),
    HeldOutGroup("larger_degradations", "every episode degraded beyond the training ranges",
                 {"degradation": LARGER_DEGRADATIONS}, 2_000),
    HeldOutGroup("commercial_acc", "every follower a commercial ACC car calibrated to OpenACC",
                 {"degradation": {"kind_weights": {"commercial_acc": 1.0}}}, 1_500),
    HeldOutGroup("stop_and_go", "congestion waves, a family the training never drew",
                 {"scenario_weights": {"stop_and_go": 1.0}}, 2_750),
    HeldOutGroup("emergency_braking", "emergency stops at 6-7.5 m/s^2, never drawn in training",
                 {"scenario_weights": {"emergency_braking": 1.0}}, 3_500),
    HeldOutGroup("ngsim", "real drivers: the held-out quarter of the NGSIM I-80 vehicles (55 of 217), within the band",
                 {"scenario_weights": {"ngsim_in_band": 1.0}, "leader": {"recorded_part": "held_out"}}, 1_000,
                 data="ngsim_in_band"),
    HeldOutGroup("openacc", "real lead cars: the held-out quarter of the OpenACC runs (5 of 19)",
                 {"scenario_weights": {"openacc": 1.0}, "leader": {"recorded_part": "held_out"}}, 1_000,
                 data="openacc"),
    HeldOutGroup("idm", "highway-env's IDM driver behind scripted braking", {"scenario_weights": {"idm": 1.0}}, 1_000,
                 data="idm"),
    HeldOutGroup("sumo", "SUMO's Plexe CC model for the platoon", {"simulator": "sumo", "sumo": {"model": "cc"}}, 50,
                 references=False, selection=100, capped="SUMO runs one episode at a time, 0.7 s each"),
)

TASKS: dict[str, Task] = {task.id: task for task in (
    Task("TimeGapMonitor-v0", "the initial task, kept bit for bit (its studies: results/v0, timegap_env.studies.heldout)",
         {}, "v0", Seeds(check_episodes=32)),
    Task("TimeGapMonitor-v1",
         "the default task (docs/task.md): the variation_first reward weighting, the regimes leader family beside "
         "v0's four, and in the info vector_reward, cost, objectives and truth_regime",
         {"reward_weights": "variation_first", "scenario_weights": {**_default_scenario_weights(), "regimes": 1.0}},
         "v1", Seeds(check_episodes=100), V1_GROUPS,
         ("v2v_pair", "regime_aware", "degradation_aware", "full_oracle")),
)}


DEFAULT_TASK = "TimeGapMonitor-v1"  # the default task of every script, the benchmark, the docs and the env classes
# (docs/task.md: how it was chosen); TimeGapMonitor-v0 stays reproducible bit for bit by its id


def get_task(task_id: str) -> Task:
    """The task registered as ``task_id``; ``ValueError`` naming it and the known ids otherwise."""
    if not isinstance(task_id, str) or task_id not in TASKS:
        raise ValueError(f"task_id = {task_id!r}: not a task of this env; known: {list(TASKS)}")
    return TASKS[task_id]


class OneTask:
    """What the env classes share: the task they were built for (``task_id``), and, made by ``gym.make`` or
    ``gym.make_vec`` under a registered id, a ``ValueError`` if that id was registered for another task (a
    ``task_id=`` given to ``make`` cannot switch the task behind an id)."""

    task_id: str
    _spec: gym.envs.registration.EnvSpec | None = None

    @property
    def spec(self) -> gym.envs.registration.EnvSpec | None:
        """The EnvSpec ``gym.make`` made the env under (None if built directly)."""
        return self._spec

    @spec.setter
    def spec(self, spec: gym.envs.registration.EnvSpec | None) -> None:
        registered = gym.registry.get(spec.id) if spec is not None else None
        expected = registered.kwargs.get("task_id") if registered is not None else None
        if spec is not None and expected is not None and expected != self.task_id:
            raise ValueError(f"task_id = {self.task_id!r} under the id {spec.id!r}: the id is the task "
                             f"({expected!r}); make {self.task_id!r} instead")
        self._spec = spec


__all__ = ["CHECK_SEED_START", "DEFAULT_TASK", "HELD_OUT_SEED_START", "INFO_LAYOUTS", "LARGER_DEGRADATIONS", "SELECTION_SEED_START", "OneTask",
           "TASKS", "HeldOutGroup", "Seeds", "Task", "get_task"]
