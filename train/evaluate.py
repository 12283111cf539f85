"""Evaluate every policy on the same held-out scenarios and write a table and two figures.

Held out from training:

- **Seeds.** Training uses seeds below ``EVAL_SEED_START`` = 10 000; evaluation episode k
  (k = 0, 1, ..., ``--episodes`` - 1, numbered across groups) is reset with seed 10 000 + k.
- **Groups** (``GROUPS``), each config overrides and reset options: ``training_mix`` (the
  training families and degradation mix on the held-out seeds); ``larger_degradations`` (every
  episode degraded, sizes beyond the training ranges: a generalisation split); human leaders:
  ``ngsim_in_band`` (real NGSIM I-80 drivers, their acceleration integrated within 20-80 mph),
  ``openacc`` (the human lead cars of the OpenACC platoons), each only when its data is found,
  and ``idm`` (highway-env's IDM driver behind scripted braking); and two harsh families the
  training never saw, ``stop_and_go`` and ``emergency_braking``. Episodes are split evenly
  across groups.

Policies: the paper's rule (platoon, per vehicle), the chart-step rule (tuned on training seeds by
``train/tune_rule.py``), every fixed setting, the V2V-aware heuristic, *the* oracle of
``train/value_of_information.py`` (reads the ground truth; its lookup measured on training seeds,
chosen on selection seeds) and the trained PPO model. The share of the oracle gap captured is
(policy - best fixed) / (oracle - best fixed), per group with the best fixed setting of that group.

Every policy runs the same (group, seed) episodes in the native vector env, one batch per
group; after each reset the script fingerprints every episode (leader speed, degradation,
dropout rate, sensor-noise key) and refuses to report if any policy saw a different one,
so platoon-wide and per-vehicle action modes are checked to draw identical scenarios.

Statistics: per policy and group, the mean over episodes with a 95 % percentile bootstrap
interval (``BOOTSTRAP_RESAMPLES`` resamples of the episodes, fixed seed); the collision rate
with a 95 % Wilson score interval; the return's paired difference to ``--reference`` and the
share of the oracle gap with a paired bootstrap (same episodes, resampled together). Min TTC is
capped at ``TTC_CAP`` (inf = never closing in on the predecessor) before averaging. Time below
stable: seconds per follower whose setting at a step's end lies below the smallest string-stable
setting of its true parameters at the step's start.

Writes ``table.md``, ``table.csv`` (one row per policy and group), ``episodes.csv`` (every
episode of every policy), ``profiles.png`` and ``metrics.png`` to ``--out``.

Each (policy, group) batch is one piece of work for ``train.backends``: ``--backend serial`` (the
default) runs them one after another here, ``--backend ray`` as Ray tasks, on this machine or on
the cluster at ``--address``; the batches are the same, so the files are too, bit for bit (the
runtime line, which says how the work was spread, aside). The oracle's lookup and choice are
spread the same way.

The learned policy is loaded as it was trained (``agents.learned.LearnedPolicy.load``: ``env.json``
gives the meaning of its actions, and ``vecnormalize.pkl`` must be there if the run normalised), with
torch on one thread, and checked before any other work, as are ``--out`` (not a file) and the NGSIM and
OpenACC data of the planned groups (a file that cannot be read is named before the other groups run).
Bad input stops the command with one line naming it and a non-zero exit, no traceback.

    python -m train.evaluate [--episodes 112] [--policies rule_platoon fixed_1.6 ...] [--out results/eval]
                             [--backend serial|ray] [--address A]
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import math
import os
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import timegap_env
from timegap_env import cli
from agents.oracles import TruthPolicy
from agents.policies import ChartStepPolicy, NamedPolicy, PaperRulePolicy, V2VAwarePolicy, fixed_policies, seconds
from agents.protocol import EVAL_SEED_START, MODEL_FILE
from agents.rllib_policy import find_checkpoint
from timegap_env.config import EnvConfig
from timegap_env.envs.info import summary_of, truth_of
from timegap_env.envs.observation import observation_space
from timegap_env.leaders import default_ngsim_path, default_openacc_dir, openacc_paths
from train.backends import Backend, add_arguments
from train.value_of_information import DEFAULT_TRAIN_EPISODES, all_oracles, choose_oracle, measure_lookup


@dataclasses.dataclass(frozen=True)
class Group:
    """A held-out group of episodes: the env's config overrides and the reset options, and the data it needs."""

    description: str
    config: dict[str, Any] = dataclasses.field(default_factory=dict)  # EnvConfig overrides
    options: dict[str, Any] | None = None  # reset options
    data: str | None = None  # "ngsim" or "openacc": only run when that data is found


LARGER_DEGRADATIONS = {  # every episode degraded, every size beyond the training range (DegradationConfig's)
    "kind_weights": {"lag": 1.0, "gain": 1.0, "v2v_latency": 1.0, "packet_loss": 1.0, "radar_bias": 1.0,
                     "radar_noise": 1.0},
    "lag_factor_range": (2.5, 3.5), "gain_range": (0.45, 0.6), "v2v_latency_range": (0.6, 0.9),
    "packet_loss_range": (0.9, 0.97), "radar_bias_range": (4.0, 6.0), "radar_noise_range": (1.0, 1.5),
}
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
REPO = Path(__file__).resolve().parents[1]
DEFAULT_EPISODES = 112  # per policy, split across the groups
DEFAULT_MODEL = Path("results/ppo", MODEL_FILE)
DEFAULT_OUT = Path("results/eval")
DEFAULT_REFERENCE = "rule_platoon"
ORACLE = "oracle"  # the policy key of the oracle
FIXED_PREFIX = "fixed_"  # the policy keys of the fixed settings
ALL_EPISODES = "all"  # the group name of the rows over every episode
BOOTSTRAP_RESAMPLES = 10_000
BOOTSTRAP_SEED = 0
CONFIDENCE = 0.95
WILSON_Z = 1.959963984540054  # standard normal quantile of 0.975
TTC_CAP = 30.0  # min TTCs above this are all safe; averaged as this [s]
PROFILE_FOLLOWER = 0  # the follower drawn bold in profiles.png (vehicle 1)

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


class PolicyChoiceError(ValueError):
    """A policy name or a model that ``--policies`` / ``--model`` cannot use."""


def model_exists(model: Path) -> bool:
    """Whether ``model`` is an SB3 model zip, a run directory holding one, or an RLlib run."""
    return model.is_file() or (model / MODEL_FILE).is_file() or find_checkpoint(model) is not None


def load_ppo(model: Path) -> Any:
    """The learned policy of ``model`` (an SB3 zip or run directory, or a train.train_rllib run), loaded as it was
    trained (``env.json``, its statistics: ``LearnedPolicy.load``; torch on one thread), checked to take the
    evaluation env's observations; ``PolicyChoiceError`` naming what does not fit."""
    from agents.learned import LearnedPolicy, RunFileError  # torch is slow to import; only when needed

    rllib = find_checkpoint(model)  # a train.train_rllib run rather than an SB3 model
    try:
        if rllib is not None:
            from agents.rllib_policy import RLlibPolicy  # loading needs the ray extra

            policy = RLlibPolicy.load(rllib)
        else:
            policy = LearnedPolicy.load(model)
    except (RunFileError, FileNotFoundError) as error:
        raise PolicyChoiceError(str(error)) from error
    expected = observation_space(EnvConfig()).shape
    if policy.observation_shape != expected:
        raise PolicyChoiceError(f"--model {model}: takes observations of shape {policy.observation_shape}, the env "
                                f"gives {expected}")
    return policy


def build_policies(
    names: Sequence[str] | None, model: Path, backend: Backend | None = None, ppo: Any = None
) -> dict[str, NamedPolicy | TruthPolicy]:
    """Policies by CLI name; ``names=None`` is the default set (PPO only if ``model``, a zip or a run directory,
    exists). The learned policy is ``ppo`` if given, else loaded from ``model`` (before the oracle, which takes a
    while). The oracle's lookup is measured on training seeds and the oracle chosen on selection seeds
    (``train.value_of_information``), their episodes spread by ``backend`` (default: serial)."""
    config = EnvConfig()  # the default, whose action mode is one setting for the platoon
    policies: dict[str, Any] = {
        "rule_platoon": PaperRulePolicy(config),
        "rule_per_vehicle": PaperRulePolicy(config.with_overrides({"action_mode": "per_vehicle"})),
        "chart_step": ChartStepPolicy(config),
        **{f"{FIXED_PREFIX}{seconds(policy.setting)}": policy for policy in fixed_policies(config)},
        "v2v_aware": V2VAwarePolicy(config),
    }
    wanted = list(policies) + [ORACLE, "ppo"] if names is None else list(names)
    unknown = sorted(set(wanted) - set(policies) - {ORACLE, "ppo"})
    if unknown:
        raise PolicyChoiceError(f"--policies {unknown}: unknown; known: {sorted(policies) + [ORACLE, 'ppo']}")
    if "ppo" in wanted:
        if ppo is not None:
            policies["ppo"] = ppo
        elif model_exists(model):
            policies["ppo"] = load_ppo(model)
        elif names is None:
            print(f"note: no trained model at {model}; PPO skipped")
            wanted.remove("ppo")
        else:
            raise FileNotFoundError(f"--policies ppo: no trained model at {model} (see --model)")
    if ORACLE in wanted:
        table, _ = measure_lookup(config, DEFAULT_TRAIN_EPISODES, backend)
        policies[ORACLE] = choose_oracle(config, all_oracles(config, table), backend)
    return {name: policies[name] for name in wanted}


def check_data(plan: list[Episode]) -> None:
    """Read the data of every planned group that needs it (the NGSIM file, the OpenACC runs) before any other work,
    by resetting one env as its first episode will be: a file that cannot be used raises a ``ValueError`` naming the
    group and (the leaders' message) the file, now rather than after the other policies have run."""
    for group in dict.fromkeys(episode.group for episode in plan):
        if GROUPS[group].data is None:
            continue
        seed = next(episode.seed for episode in plan if episode.group == group)
        venv = gym.make_vec(timegap_env.ENV_ID, num_envs=1, vectorization_mode="vector_entry_point",
                            config=GROUPS[group].config, autoreset_mode="same_step")
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
    n = len(seeds)
    venv = gym.make_vec(timegap_env.ENV_ID, num_envs=n, vectorization_mode="vector_entry_point",
                        config={**GROUPS[group].config, "action_mode": policy.action_mode}, autoreset_mode="same_step")
    obs, infos = venv.reset(seed=seeds, options=GROUPS[group].options)
    task, config = venv.unwrapped.task, venv.unwrapped.config
    prints = [task.fingerprint(env) for env in range(n)]
    scenarios = list(venv.unwrapped.scenario)
    truth0 = {name: value[0] for name, value in truth_of(infos).items()}  # env 0's schedule, for the profile
    trace = task.start_trace(keep=None) if record_profile else None  # env 0 at every tick of the whole run
    returns, steps, below = np.zeros(n), np.zeros(n, dtype=np.int64), np.zeros(n)
    active = np.ones(n, dtype=bool)
    summaries: list[dict[str, float]] = [{} for _ in range(n)]
    state = None  # a policy's memory (a learned policy's frame stack), carried from step to step
    while active.any():
        truth = truth_of(infos)
        if isinstance(policy, TruthPolicy):
            action = policy.act(truth)
        else:
            action, state = policy.predict(obs, state=state, deterministic=True)
        obs, reward, terminated, truncated, infos = venv.step(action)
        returns += np.where(active, reward, 0.0)
        steps += active
        done = terminated | truncated  # those envs were reset: the step's own setting is in final_info
        setting = np.where(done[:, None], infos["final_info"]["setting"], infos["setting"]) if done.any() \
            else infos["setting"]
        unstable = setting < truth["smallest_stable_setting"] - 1e-9  # (n, N), the step's end vs its start
        below += np.where(active, unstable.mean(axis=1) * config.decision_interval, 0.0)
        ended = (terminated | truncated) & active
        for env in np.flatnonzero(ended):
            summaries[env] = {name: float(value[env]) for name, value in summary_of(infos["final_info"]).items()}
        active &= ~ended
    venv.close()
    records = [
        {"group": group, "seed": seed, "scenario": scenarios[env], "steps": int(steps[env]),
         "return": float(returns[env]), "time_below_stable": float(below[env]), **summaries[env]}
        for env, seed in enumerate(seeds)
    ]
    profile = None
    if trace is not None:
        episode = slice(int(steps[0]) * config.ticks_per_decision)  # env 0's episode, not its autoreset successor
        arrays = trace.arrays()
        hit = truth0["kind"] != "none"
        onset = float(truth0["onset"][hit].min()) if hit.any() else math.inf
        end = float(truth0["end"][hit].max()) if hit.any() else math.inf
        profile = Profile(
            t=arrays.t[episode],
            estimate=arrays.estimate[episode],
            center=arrays.center[episode],
            half_width=config.chart.half_width,
            scenario=f"{group} seed {seeds[0]} ({scenarios[0]})",
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
    venv = gym.make_vec(timegap_env.ENV_ID, num_envs=len(seeds), vectorization_mode="vector_entry_point",
                        config=GROUPS[group].config, autoreset_mode="same_step")
    _, infos = venv.reset(seed=seeds, options=GROUPS[group].options)
    venv.close()
    truth = truth_of(infos)
    midway = ((truth["kind"] != "none") & (truth["kind"] != "v2v_outage") & (truth["onset"] > 0)
              & np.isfinite(truth["onset"])).any(axis=1)
    if not midway.any():
        return seeds
    first = int(np.argmax(midway))
    return [seeds[first]] + seeds[:first] + seeds[first + 1:]


# ---------------------------------------------------------------- statistics
def bootstrap_mean(values: np.ndarray) -> tuple[float, float, float]:
    """Mean and its 95 % percentile bootstrap interval (BOOTSTRAP_RESAMPLES resamples, fixed seed)."""
    values = np.asarray(values, dtype=float)
    rng = np.random.default_rng(BOOTSTRAP_SEED)
    means = values[rng.integers(0, values.size, size=(BOOTSTRAP_RESAMPLES, values.size))].mean(axis=1)
    low, high = np.quantile(means, [(1 - CONFIDENCE) / 2, (1 + CONFIDENCE) / 2])
    return float(values.mean()), float(low), float(high)


def wilson_interval(successes: int, trials: int) -> tuple[float, float, float]:
    """Rate and its 95 % Wilson score interval."""
    rate, z2 = successes / trials, WILSON_Z**2
    centre = (rate + z2 / (2 * trials)) / (1 + z2 / trials)
    half = WILSON_Z * math.sqrt(rate * (1 - rate) / trials + z2 / (4 * trials**2)) / (1 + z2 / trials)
    return rate, max(0.0, centre - half), min(1.0, centre + half)


def metric_values(records: list[dict[str, Any]], metric: str) -> np.ndarray:
    """One value per episode; min TTC capped at TTC_CAP."""
    values = np.array([float(record[metric]) for record in records])
    return np.minimum(values, TTC_CAP) if metric == "min_ttc" else values


def oracle_share(policy: np.ndarray, blind: np.ndarray, oracle: np.ndarray) -> tuple[float, float, float]:
    """The share of the oracle gap captured, mean(policy - blind) / mean(oracle - blind), with its 95 % paired
    bootstrap interval (the episodes resampled together); NaN where the oracle does not beat the blind constant."""
    gained, gap = np.asarray(policy) - np.asarray(blind), np.asarray(oracle) - np.asarray(blind)
    if gap.mean() <= 0:
        return math.nan, math.nan, math.nan
    rng = np.random.default_rng(BOOTSTRAP_SEED)
    index = rng.integers(0, gap.size, size=(BOOTSTRAP_RESAMPLES, gap.size))
    resampled_gap = gap[index].mean(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        shares = np.where(resampled_gap > 0, gained[index].mean(axis=1) / resampled_gap, np.nan)
    if np.isnan(shares).any():  # a resample where the oracle gains nothing: no interval
        return float(gained.mean() / gap.mean()), math.nan, math.nan
    low, high = np.quantile(shares, [(1 - CONFIDENCE) / 2, (1 + CONFIDENCE) / 2])
    return float(gained.mean() / gap.mean()), float(low), float(high)


def best_fixed(records: dict[str, list[dict[str, Any]]], group: str) -> str | None:
    """The fixed setting with the best mean return over ``group``'s episodes (``all``: every episode)."""
    fixed = {key: metric_values([r for r in rows if group in (ALL_EPISODES, r["group"])], "return").mean()
             for key, rows in records.items() if key.startswith(FIXED_PREFIX)}
    return max(fixed, key=fixed.get) if fixed else None


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
FORMATS = {"return": ".1f", "time_out_of_control": ".2f", "exceedances": ".2f", "max_deviation": ".3f",
           "min_ttc": ".1f", "collision": ".2f", "rms_jerk": ".2f", "mean_setting": ".2f", "mean_capacity": ".0f",
           "switches": ".2f", "return_vs_reference": ".1f", "oracle_share": ".2f", "time_below_stable": ".1f"}


def cell(row: dict[str, Any], metric: str) -> str:
    """'mean [low, high]' of ``metric``; collisions as 'count/episodes [low, high]' of the rate."""
    f = FORMATS[metric]
    interval = f"[{row[f'{metric}_ci_low']:{f}}, {row[f'{metric}_ci_high']:{f}}]"
    if metric == "collision":
        return f"{row['collisions']}/{row['episodes']} {interval}"
    if math.isnan(row[f"{metric}_mean"]):
        return "n/a"
    if math.isnan(row[f"{metric}_ci_low"]):  # a share whose gap's own interval reaches 0
        return f"{row[f'{metric}_mean']:{f}} [unbounded]"
    return f"{row[f'{metric}_mean']:{f}} {interval}"


def write_tables(rows: list[dict[str, Any]], header: list[str], reference: str | None, out: Path) -> None:
    """table.csv (every number) and table.md (one table per group)."""
    with open(out / "table.csv", "w", newline="") as file:
        writer = csv.DictWriter(file, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    share = "oracle_share_mean" in rows[0]
    columns = ["return"] + (["return_vs_reference"] if reference else []) + (["oracle_share"] if share else []) \
        + list(METRICS)[1:]
    labels = [METRICS.get(c, "share of the oracle gap" if c == "oracle_share" else f"Δ return vs {reference} (paired)")
              for c in columns]
    lines = header + [""]
    for group in dict.fromkeys(row["group"] for row in rows):
        chosen = [row for row in rows if row["group"] == group]
        title = "All episodes" if group == ALL_EPISODES else f"Group `{group}`"
        blind = f"; best fixed setting: {chosen[0]['best_fixed']}" if share else ""
        lines += [f"## {title} ({chosen[0]['episodes']} episodes per policy{blind})", "",
                  "| policy | " + " | ".join(labels) + " |", "|---" * (len(columns) + 1) + "|"]
        lines += [f"| {row['name']} | " + " | ".join(cell(row, c) for c in columns) + " |" for row in chosen]
        lines.append("")
    (out / "table.md").write_text("\n".join(lines))


def write_episodes(policies: dict[str, NamedPolicy], records: dict[str, list[dict[str, Any]]], out: Path) -> None:
    """episodes.csv: every episode of every policy, as run."""
    rows = [{"policy": key, **record} for key in policies for record in records[key]]
    with open(out / "episodes.csv", "w", newline="") as file:
        writer = csv.DictWriter(file, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def plot_profiles(policies: dict[str, NamedPolicy], profiles: dict[str, Profile], out: Path) -> None:
    """profiles.png: each policy's time gap estimates on the same episode, vehicle 1 bold with its limits."""
    keys = [key for key in policies if key in profiles]
    ncols = min(3, len(keys))
    nrows = math.ceil(len(keys) / ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(5 * ncols, 2.6 * nrows), sharex=True, sharey=True, squeeze=False)
    for ax, key in zip(axes.flat, keys):
        p = profiles[key]
        ax.plot(p.t, np.delete(p.estimate, PROFILE_FOLLOWER, axis=1), color="0.7", lw=0.6)
        ax.plot(p.t, p.estimate[:, PROFILE_FOLLOWER], color="C0", lw=1.2, label=f"vehicle {PROFILE_FOLLOWER + 1} τ̂")
        center = p.center[:, PROFILE_FOLLOWER]
        ax.plot(p.t, center - p.half_width, color="C3", ls="--", lw=0.9, label="LCL / UCL")
        ax.plot(p.t, center + p.half_width, color="C3", ls="--", lw=0.9)
        ax.plot(p.t, center, color="k", ls=":", lw=0.9, label="τ* (CL)")
        for moment, label in ((p.onset, "degradation onset"), (p.end, "its end")):
            if math.isfinite(moment) and moment <= p.t[-1]:
                ax.axvline(moment, color="C2", lw=1.0, ls="-." if label == "its end" else "-", label=label)
        ax.set_title(policies[key].name, fontsize=9)
        ax.grid(alpha=0.3)
    for ax in axes.flat[len(keys):]:
        ax.set_visible(False)
    for ax in axes[-1]:
        ax.set_xlabel("t [s]")
    for ax in axes[:, 0]:
        ax.set_ylabel("time gap [s]")
    axes[0, 0].legend(fontsize=7, loc="upper right")
    first = next(iter(profiles.values()))
    fig.suptitle(f"Time gap estimates, {first.scenario}, {first.degradation} (other followers grey)", fontsize=10)
    fig.tight_layout()
    fig.savefig(out / "profiles.png", dpi=120)
    plt.close(fig)


def plot_metrics(rows: list[dict[str, Any]], out: Path) -> None:
    """metrics.png: every metric over all episodes, mean and 95 % interval per policy."""
    chosen = [row for row in rows if row["group"] == ALL_EPISODES]
    y = np.arange(len(chosen))[::-1]
    ncols = 5
    fig, axes = plt.subplots(math.ceil(len(METRICS) / ncols), ncols, figsize=(18, 0.35 * len(chosen) * 2 + 2),
                             sharey=True, squeeze=False)
    for ax, (metric, label) in zip(axes.flat, METRICS.items()):
        mean = np.array([row[f"{metric}_mean"] for row in chosen])
        low = np.array([row[f"{metric}_ci_low"] for row in chosen])
        high = np.array([row[f"{metric}_ci_high"] for row in chosen])
        ax.errorbar(mean, y, xerr=np.maximum([mean - low, high - mean], 0.0), fmt="o", ms=4, capsize=2)
        ax.set_title(label, fontsize=9)
        ax.grid(alpha=0.3)
    for ax in axes.flat[len(METRICS):]:
        ax.set_visible(False)
    for ax in axes[:, 0]:
        ax.set_yticks(y, [row["name"] for row in chosen], fontsize=8)
    fig.suptitle(f"All {chosen[0]['episodes']} held-out episodes per policy: mean and 95 % interval", fontsize=10)
    fig.tight_layout()
    fig.savefig(out / "metrics.png", dpi=120)
    plt.close(fig)


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m train.evaluate", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--episodes", type=int, default=DEFAULT_EPISODES,
                        help=f"episodes per policy, split across the held-out groups (default {DEFAULT_EPISODES})")
    parser.add_argument("--policies", nargs="+", metavar="NAME",
                        help="rule_platoon rule_per_vehicle chart_step fixed_<level> (e.g. fixed_1.6) v2v_aware oracle "
                             "ppo (default: all, ppo if --model exists)")
    parser.add_argument("--model", type=Path,
                        help="a run of train.train_ppo (its directory or its model.zip; env.json beside it, and "
                             "vecnormalize.pkl if the run normalised, are required and checked against the model) "
                             f"(default {DEFAULT_MODEL}, skipped if absent); or a run of train.train_rllib "
                             "(results/rllib or its checkpoint/; needs the ray extra); checked before any other work")
    parser.add_argument("--reference", default=DEFAULT_REFERENCE,
                        help=f"policy the paired return differences are taken against (default {DEFAULT_REFERENCE})")
    parser.add_argument("--profile-group", default="training_mix",
                        help="group one of whose episodes profiles.png shows: the first with a hidden degradation "
                             "starting midway (default training_mix)")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help=f"output directory (default {DEFAULT_OUT})")
    add_arguments(parser)
    args = parser.parse_args(argv)
    try:
        backend = Backend.from_args(args)
        cli.output_dir(args.out)
    except (ValueError, OSError) as error:
        parser.error(str(error))
    if args.model is not None and not model_exists(args.model):
        parser.error(f"--model {args.model}: no such model zip or RLlib checkpoint")
    args.model = args.model or DEFAULT_MODEL
    ppo = None  # the learned policy, loaded first: a model that cannot be used is named before any other work
    if (args.policies is None or "ppo" in args.policies) and model_exists(args.model):
        try:
            ppo = load_ppo(args.model)
        except PolicyChoiceError as error:
            parser.error(str(error))

    start = time.perf_counter()
    groups, data_note = available_groups()
    plan = plan_episodes(args.episodes, groups)
    planned_groups = list(dict.fromkeys(episode.group for episode in plan))
    profile_group = args.profile_group if args.profile_group in planned_groups else planned_groups[0]
    check_data(plan)  # a truncated data file named now, not after the other groups
    try:
        policies = build_policies(args.policies, args.model, backend, ppo)
    except (PolicyChoiceError, FileNotFoundError) as error:  # unknown names, a model that cannot be used: no traceback
        parser.error(str(error))
    reference = args.reference if args.reference in policies else None
    if reference is None:
        print(f"note: --reference {args.reference} is not among the policies; no paired differences")
    records, profiles, timings = run_all(policies, plan, profile_group, backend)
    elapsed = time.perf_counter() - start

    args.out.mkdir(parents=True, exist_ok=True)
    rows = summarise(policies, records, reference)
    counts = ", ".join(f"{g}: {sum(e.group == g for e in plan)}" for g in planned_groups)
    ppo = policies.get("ppo")
    header = [
        "# Held-out evaluation (`python -m train.evaluate`)", "",
        f"Episodes per policy: {len(plan)} ({counts}), seeds {plan[0].seed}–{plan[-1].seed} "
        f"(training uses seeds < {EVAL_SEED_START}). {data_note}",
        "Groups: " + "; ".join(f"`{g}` = {GROUPS[g].description}" for g in planned_groups) + ". Default env config "
        "otherwise (degradations of the followers, from the default mix, and sensor dropouts drawn from the seed).",
        *([f"Oracle: `{policies[ORACLE].name}` (reads the ground truth, not deployable; chosen on selection seeds by "
           "`train.value_of_information`). Share of the oracle gap = (policy − best fixed) / (oracle − best fixed), "
           "the group's best fixed setting, paired bootstrap interval; n/a where the oracle does not beat it, "
           "[unbounded] where it does not in some resamples (the gap's own interval reaches 0)."]
          if ORACLE in policies else []),
        "Every policy ran the same episodes: the leader, degradation, dropout rate and sensor-noise key of each "
        "episode were fingerprinted after reset and compared across policies and action modes.",
        f"Cells: mean [95 % percentile bootstrap interval, {BOOTSTRAP_RESAMPLES} resamples of the episodes]; "
        "collisions: count/episodes [95 % Wilson interval of the rate]; "
        + (f"Δ return: paired difference to `{policies[reference].name}` on the same episodes (paired bootstrap). "
           if reference else "")
        + f"Min TTC capped at {TTC_CAP:g} s before averaging. Return = undiscounted sum of rewards (episodes differ in "
        "length across groups: NGSIM records are shorter than 250 s).",
        (f"PPO: `{args.model}` ({ppo!r})." if ppo else f"PPO: not evaluated (no model at `{args.model}`)."),
        f"Runtime: {elapsed:.0f} s for {len(policies)} policies "
        f"({', '.join(f'{key} {spent:.0f} s' for key, spent in timings.items())}, each its batches' seconds where "
        f"they ran); spread of the (policy, group) batches: {backend.describe()}"
        + (" (the oracle's lookup and choice before them the same way)." if ORACLE in policies else "."),
    ]
    write_tables(rows, header, reference, args.out)
    write_episodes(policies, records, args.out)
    plot_profiles(policies, profiles, args.out)
    plot_metrics(rows, args.out)
    print(f"wrote {args.out}/table.md, table.csv, episodes.csv, profiles.png, metrics.png in {elapsed:.0f} s\n")
    print((args.out / "table.md").read_text().split("\n## Group")[0])  # the table over all episodes


if __name__ == "__main__":
    cli.run(main, "python -m train.evaluate")
