"""The held-out evaluation protocol of ``train.evaluate`` (and of ``train.train_rllib``'s held-out check): the groups of
episodes, the plan of seeds, every policy on every planned episode through the rollout harness, and the summary
statistics per group.

Held out from training: seeds from ``EVAL_SEED_START`` (10 000), split evenly across ``GROUPS`` (config overrides
and reset options; the NGSIM and OpenACC groups only when their data is found). Every policy runs the same (group,
seed) episodes, one vector-env batch per (policy, group), a piece of work for a
:class:`~timegap_env.experiments.backends.Backend`; the episodes' fingerprints are compared across policies.
"""

from __future__ import annotations

import dataclasses
import math
import os
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from timegap_env.envs.vector_env import TimeGapMonitorVectorEnv
from timegap_env.agents.oracles import TruthPolicy
from timegap_env.agents.policies import NamedPolicy
from timegap_env.agents.protocol import EVAL_SEED_START, MODEL_FILE
from timegap_env.config import EnvConfig
from timegap_env import cli
from timegap_env.experiments.backends import Backend
from timegap_env.experiments.registry import (
    FIXED_PREFIX, ORACLE, PPO, LearnedPolicyError, fixed_names, learned_exists, load_learned,
)
from timegap_env.experiments.registry import make as make_policy
from timegap_env.experiments.rollout import rollout
from timegap_env.experiments.stats import bootstrap_mean, oracle_share, wilson_interval
from timegap_env.studies.value import DEFAULT_TRAIN_EPISODES, make_oracle
from timegap_env.leaders import default_ngsim_path, default_openacc_dir, openacc_paths
from timegap_env.tasks import LARGER_DEGRADATIONS


REPO = Path(__file__).resolve().parents[2]  # data paths in the table are written relative to it
DEFAULT_EPISODES = 112  # per policy, split across the groups
DEFAULT_REFERENCE = "rule_platoon"  # the policy the paired differences are taken against
ALL_EPISODES = "all"  # the group name of the rows over every episode
TTC_CAP = 30.0  # min TTCs above this are all safe; averaged as this [s]
DEFAULT_MODEL = Path("results/v0/ppo", MODEL_FILE)  # the committed trained model, relative to the working directory
DEFAULT_POLICIES = ("rule_platoon", "rule_per_vehicle", "chart_step", "v2v_aware")  # the fixed settings after the third

@dataclasses.dataclass(frozen=True)
class Group:
    """A held-out group of episodes: the env's config overrides and the reset options, and the data it needs."""

    description: str
    config: dict[str, Any] = dataclasses.field(default_factory=dict)  # EnvConfig overrides
    options: dict[str, Any] | None = None  # reset options
    data: str | None = None  # "ngsim" or "openacc": only run when that data is found


GROUPS: dict[str, Group] = {
    "training_mix": Group("the training families and degradation mix on held-out seeds"),
    "larger_degradations": Group("every episode degraded, sizes beyond the training ranges (lag x2.5-3.5, gain "
                                 "0.45-0.6, V2V latency 0.6-0.9 s, packet loss 90-97 %, radar bias 4-6 m, radar "
                                 "noise 1-1.5 m)", config={"degradation": LARGER_DEGRADATIONS}),
    "ngsim_in_band": Group("NGSIM I-80 drivers' acceleration integrated within 20-80 mph",
                           options={"scenario": "ngsim_in_band"}, data="ngsim"),
    "openacc": Group("the human lead cars of the OpenACC platoons", options={"scenario": "openacc"}, data="openacc"),
    "idm": Group("highway-env's IDM driver behind scripted braking", options={"scenario": "idm"}),
    "stop_and_go": Group("a harsh family the training never saw: congestion waves down to a crawl",
                         options={"scenario": "stop_and_go"}),
    "emergency_braking": Group("a harsh family the training never saw: emergency stops from highway speed",
                               options={"scenario": "emergency_braking"}),
}
METRICS: dict[str, str] = {  # column -> label; "return" is the undiscounted sum of rewards, the rest the episode summary
    "return": "return",
    "time_out_of_control": "time out of control [s / follower]",
    "exceedances": "exceedances [all followers]",
    "max_deviation": "max |τ̂ − τ*| [s]",
    "min_ttc": f"min TTC [s, capped at {TTC_CAP:g}]",
    "collision": "collision rate",
    "time_below_stable": "time below the smallest stable setting [s / follower]",
    "rms_jerk": "RMS jerk [m/s³]",
    "mean_setting": "mean τ* [s]",
    "mean_capacity": "capacity implied [veh/h]",
    "switches": "switches [follower changes]",
}


@dataclasses.dataclass(frozen=True)
class Episode:
    """One evaluation episode: a group (reset options) and a seed."""

    group: str
    seed: int


@dataclasses.dataclass(frozen=True)
class Profile:
    """One episode of one policy, for profiles.png: env 0 of the profile group's batch, every tick."""

    t: np.ndarray  # (n_ticks,) [s]
    estimate: np.ndarray  # (n_ticks, n_followers) posterior mean of tau [s]
    center: np.ndarray  # (n_ticks, n_followers) chart centre line, the applied (ramped) setting tau* [s]
    half_width: float  # control limits at center -/+ half_width [s]
    scenario: str
    degradation: str  # what degraded which followers
    onset: float  # the degradation's onset [s] (inf: none)
    end: float  # its end [s] (inf: never)


def available_groups() -> tuple[list[str], str]:
    """The held-out groups to run (those whose data is found), and a note for the table header."""
    found = {"ngsim": default_ngsim_path().exists(),
             "openacc": default_openacc_dir().is_dir() and bool(openacc_paths(default_openacc_dir()))}
    where = {kind: os.path.relpath(path.resolve(), REPO)  # relative, so the committed table holds no machine path
             for kind, path in (("ngsim", default_ngsim_path()), ("openacc", default_openacc_dir()))}
    groups = [name for name, group in GROUPS.items() if group.data is None or found[group.data]]
    notes = [f"{kind} data from `{where[kind]}`." if ok else
             f"**{kind} data not found at `{where[kind]}`**: its group is left out." for kind, ok in found.items()]
    return groups, " ".join(notes)


def plan_episodes(episodes: int, groups: Sequence[str]) -> list[Episode]:
    """``episodes`` split evenly across ``groups`` (earlier groups take the remainder), seeds from EVAL_SEED_START."""
    if episodes < 1:
        raise ValueError(f"episodes = {episodes}: must be >= 1")
    per_group = [episodes // len(groups) + (i < episodes % len(groups)) for i in range(len(groups))]
    plan, seed = [], EVAL_SEED_START
    for group, count in zip(groups, per_group):
        plan += [Episode(group, seed + i) for i in range(count)]
        seed += count
    return plan


PolicyChoiceError = LearnedPolicyError  # a policy name or a model that --policies / --model cannot use
model_exists = learned_exists


def load_ppo(model: Path) -> Any:
    """The learned policy of ``model`` (an SB3 zip or run directory, or a train.train_rllib run), loaded as it was
    trained, checked to take the evaluation env's observations (the registry's ``load_learned``)."""
    return load_learned(model, EnvConfig())


def build_policies(
    names: Sequence[str] | None, model: Path, backend: Backend | None = None, ppo: Any = None,
    train_episodes: int = DEFAULT_TRAIN_EPISODES,
) -> dict[str, NamedPolicy | TruthPolicy]:
    """Policies by registry name (``timegap_env.experiments.registry``); ``names=None`` is the default set
    (``DEFAULT_POLICIES``, the fixed settings of the ladder, the oracle, and PPO only if ``model``, a zip or a run
    directory, exists). The learned policy is ``ppo`` if given, else loaded from ``model`` (before the oracle, which
    takes a while). The oracle's lookup is measured on training seeds and the oracle chosen on selection seeds
    (``value.make_oracle``, ``train_episodes`` per condition), their episodes spread by ``backend`` (default:
    serial)."""
    config = EnvConfig()  # the default, whose action mode is one setting for the platoon
    defaults = [*DEFAULT_POLICIES[:3], *fixed_names(config), *DEFAULT_POLICIES[3:]]
    wanted = defaults + [ORACLE, PPO] if names is None else list(names)
    policies: dict[str, Any] = {}
    for name in wanted:
        if name in (ORACLE, PPO):
            continue
        try:
            policies[name] = make_policy(name, config)
        except ValueError as error:
            raise PolicyChoiceError(f"--policies {name}: {error}") from error
    if PPO in wanted:
        if ppo is not None:
            policies[PPO] = ppo
        elif model_exists(model):
            policies[PPO] = load_ppo(model)
        elif names is None:
            print(f"note: no trained model at {model}; PPO skipped")
            wanted.remove(PPO)
        else:
            raise FileNotFoundError(f"--policies ppo: no trained model at {model} (see --model)")
    if ORACLE in wanted:
        policies[ORACLE] = make_oracle(config, train_episodes, backend)
    return {name: policies[name] for name in wanted}


def check_data(plan: list[Episode]) -> None:
    """Read the data of every planned group that needs it (the NGSIM file, the OpenACC runs) before any other work,
    by resetting one env as its first episode will be: a file that cannot be used raises a ``ValueError`` naming the
    group and (the leaders' message) the file, now rather than after the other policies have run."""
    for group in dict.fromkeys(episode.group for episode in plan):
        if GROUPS[group].data is None:
            continue
        seed = next(episode.seed for episode in plan if episode.group == group)
        venv = TimeGapMonitorVectorEnv(num_envs=1, config=GROUPS[group].config, autoreset_mode="same_step")
        try:
            venv.reset(seed=[seed], options=GROUPS[group].options)
        except cli.INPUT_ERRORS as error:
            raise ValueError(f"held-out group {group!r} ({GROUPS[group].data} data): {error}") from error
        finally:
            venv.close()


def run_batch(
    policy: NamedPolicy | TruthPolicy, group: str, seeds: list[int], record_profile: bool
) -> tuple[list[dict[str, Any]], list[str], Profile | None]:
    """Run ``policy`` once on every seed of ``group`` (in the policy's action mode); an oracle reads the ground truth.

    Returns a record and a scenario fingerprint per episode, and env 0's profile if ``record_profile``.
    """
    batch = rollout(policy, GROUPS[group].config, seeds, GROUPS[group].options, trace=record_profile)
    config, trace, episodes = batch.config, batch.trace, batch.records
    prints = [episode.fingerprint for episode in episodes]
    records = [
        {"group": group, "seed": seed, "scenario": episode.scenario, "steps": episode.steps,
         "return": episode.episode_return, "time_below_stable": episode.time_below_stable,
         **{name: float(value) for name, value in episode.summary.items()}}
        for episode, seed in zip(episodes, seeds)
    ]
    truth0 = episodes[0].truth  # env 0's schedule, for the profile
    steps0 = episodes[0].steps
    profile = None
    if trace is not None:
        episode = slice(steps0 * config.ticks_per_decision)  # env 0's episode, not its autoreset successor
        arrays = trace.arrays()
        hit = truth0["kind"] != "none"
        onset = float(truth0["onset"][hit].min()) if hit.any() else math.inf
        end = float(truth0["end"][hit].max()) if hit.any() else math.inf
        profile = Profile(
            t=arrays.t[episode],
            estimate=arrays.estimate[episode],
            center=arrays.center[episode],
            half_width=config.chart.half_width,
            scenario=f"{group} seed {seeds[0]} ({episodes[0].scenario})",
            degradation=(f"{next(k for k in truth0['kind'] if k != 'none')} on followers "
                         f"{[int(f) + 1 for f in np.flatnonzero(hit)]}" if hit.any() else "no degradation"),
            onset=onset, end=end,
        )
    return records, prints, profile


def timed_batch(
    policy: NamedPolicy | TruthPolicy, group: str, seeds: list[int], record_profile: bool
) -> tuple[list[dict[str, Any]], list[str], Profile | None, float]:
    """:func:`run_batch` and the seconds it took where it ran: one piece of work for a backend."""
    start = time.perf_counter()
    records, prints, profile = run_batch(policy, group, seeds, record_profile)
    return records, prints, profile, time.perf_counter() - start


def run_all(
    policies: dict[str, NamedPolicy], plan: list[Episode], profile_group: str | None, backend: Backend | None = None
) -> tuple[dict[str, list[dict[str, Any]]], dict[str, Profile], dict[str, float]]:
    """Every policy on every planned episode, one piece per (policy, group) batch spread by ``backend`` (default:
    serial): records, profiles, and per policy the seconds its pieces took where they ran.

    Raises ``RuntimeError`` if two policies were given different scenarios for the same episode.
    """
    backend = backend or Backend()
    groups = list(dict.fromkeys(episode.group for episode in plan))
    batches = {group: [episode.seed for episode in plan if episode.group == group] for group in groups}
    if profile_group is not None:
        batches[profile_group] = profile_first(profile_group, batches[profile_group])
    pieces = [(policy, group, batches[group], group == profile_group) for policy in policies.values() for group in groups]
    results = iter(backend.map(timed_batch, pieces))
    records: dict[str, list[dict[str, Any]]] = {}
    profiles: dict[str, Profile] = {}
    timings: dict[str, float] = {}
    reference_prints: list[str] | None = None
    for key, policy in policies.items():
        records[key], prints, timings[key] = [], [], 0.0
        for group in groups:
            batch, batch_prints, profile, seconds_spent = next(results)
            records[key] += batch
            prints += batch_prints
            timings[key] += seconds_spent
            if profile is not None:
                profiles[key] = profile
        if reference_prints is None:
            reference_prints = prints
        elif prints != reference_prints:
            differ = [plan[i] for i, (a, b) in enumerate(zip(prints, reference_prints)) if a != b]
            raise RuntimeError(f"policy {key!r} saw different scenarios than {next(iter(policies))!r} in {differ}")
        print(f"{policy.name:>28}: {len(plan)} episodes in {timings[key]:.1f} s")
    return records, profiles, timings


def profile_first(group: str, seeds: list[int]) -> list[int]:
    """``seeds`` with the first one whose episode degrades a follower midway (a hidden kind) moved to the front, so
    that profiles.png shows an onset; unchanged if there is none."""
    venv = TimeGapMonitorVectorEnv(num_envs=len(seeds), config=GROUPS[group].config, autoreset_mode="same_step")
    venv.reset(seed=seeds, options=GROUPS[group].options)
    truth = venv.ground_truth()
    venv.close()
    midway = ((truth["kind"] != "none") & (truth["kind"] != "v2v_outage") & (truth["onset"] > 0)
              & np.isfinite(truth["onset"])).any(axis=1)
    if not midway.any():
        return seeds
    first = int(np.argmax(midway))
    return [seeds[first]] + seeds[:first] + seeds[first + 1:]


def metric_values(records: list[dict[str, Any]], metric: str) -> np.ndarray:
    """One value per episode; min TTC capped at TTC_CAP."""
    values = np.array([float(record[metric]) for record in records])
    return np.minimum(values, TTC_CAP) if metric == "min_ttc" else values


def best_fixed(records: dict[str, list[dict[str, Any]]], group: str) -> str | None:
    """The fixed setting with the best mean return over ``group``'s episodes (``all``: every episode)."""
    fixed = {key: metric_values([r for r in rows if group in (ALL_EPISODES, r["group"])], "return").mean()
             for key, rows in records.items() if key.startswith(FIXED_PREFIX)}
    return max(fixed, key=fixed.__getitem__) if fixed else None


def summarise(
    policies: dict[str, NamedPolicy | TruthPolicy], records: dict[str, list[dict[str, Any]]], reference: str | None
) -> list[dict[str, Any]]:
    """One row per group (``all`` first) and policy: mean, CI low, CI high of every metric, the paired difference to
    ``reference`` and the share of the oracle gap against the group's best fixed setting (when both were run)."""
    groups = [ALL_EPISODES] + list(dict.fromkeys(record["group"] for record in next(iter(records.values()))))
    rows = []
    for group in groups:
        blind = best_fixed(records, group)
        for key, policy in policies.items():
            chosen = [r for r in records[key] if group in (ALL_EPISODES, r["group"])]
            row: dict[str, Any] = {"policy": key, "name": policy.name, "action_mode": policy.action_mode,
                                   "group": group, "episodes": len(chosen)}
            for metric in METRICS:
                values = metric_values(chosen, metric)
                if metric == "collision":
                    row["collisions"] = int(values.sum())
                    stats = wilson_interval(int(values.sum()), values.size)
                else:
                    stats = bootstrap_mean(values)
                row.update(zip((f"{metric}_mean", f"{metric}_ci_low", f"{metric}_ci_high"), stats))
            if reference is not None:
                baseline = [r for r in records[reference] if group in (ALL_EPISODES, r["group"])]
                difference = metric_values(chosen, "return") - metric_values(baseline, "return")
                row.update(zip(("return_vs_reference_mean", "return_vs_reference_ci_low",
                                "return_vs_reference_ci_high"), bootstrap_mean(difference)))
            if blind is not None and ORACLE in records:
                returns = {name: metric_values([r for r in records[name] if group in (ALL_EPISODES, r["group"])],
                                               "return") for name in (key, blind, ORACLE)}
                row["best_fixed"] = blind
                row.update(zip(("oracle_share_mean", "oracle_share_ci_low", "oracle_share_ci_high"),
                               oracle_share(returns[key], returns[blind], returns[ORACLE])))
            rows.append(row)
    return rows


# ---------------------------------------------------------------- outputs


__all__ = ["ALL_EPISODES", "DEFAULT_EPISODES", "DEFAULT_MODEL", "DEFAULT_POLICIES", "PolicyChoiceError", "build_policies",
           "load_ppo", "model_exists", "DEFAULT_REFERENCE", "Episode", "GROUPS", "Group", "LARGER_DEGRADATIONS",
           "METRICS", "Profile", "TTC_CAP", "available_groups", "best_fixed", "check_data", "metric_values", "plan_episodes",
           "profile_first", "run_all", "run_batch", "summarise", "timed_batch"]
