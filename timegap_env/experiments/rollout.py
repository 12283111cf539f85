"""The rollout harness: policies x configs x seeds (x backend) -> one record per episode.

Every script that plays episodes plays them here (evaluation, sweeps, rule tuning, the value of information, the
learning curve's check episodes), in the native vector env with ``autoreset_mode="same_step"``: one env per seed,
each run until its first episode ends (what the autoreset starts after it is not played).

A policy is any of

- an object with stable-baselines3's ``predict(obs, state=None, episode_start=None, deterministic=True)``
  (``timegap_env.agents.policies``, ``timegap_env.agents.learned.LearnedPolicy``, ``timegap_env.agents.rllib_policy.RLlibPolicy``): called with the
  batch of observations, deterministic, its ``state`` carried from step to step;
- an oracle with ``act(truth)`` (``timegap_env.agents.oracles``): called with the ground truth the infos hold;
- a chooser, a callable ``(observations, infos) -> actions``.

A policy with an ``action_mode`` attribute runs in an env of that action mode, one with a ``monitor_estimator``
attribute (a learned policy trained on the raw-gap ablation's observations) in an env whose monitor reports that.

:func:`rollout` plays one policy (or, :func:`rollout_side_by_side`, several in one vector env, each on its own
copy of the seeds) in the env of a config (an EnvConfig, e.g. a task's ``get_task(id).config(...)``, or
overrides of the default task's config) and returns an :class:`EpisodeRecord` per episode: its return, the reward terms summed over the
episode, the episode summary (``info["final_info"]``'s ``episode_*``), the ground truth at reset, the time spent
below the smallest string-stable setting and the episode's fingerprint (what the reset drew, to check that two
policies saw the same episodes). :func:`run_jobs` spreads :class:`Job` s (policy x config x seeds) over a
:class:`~timegap_env.experiments.backends.Backend`, serially or as Ray tasks, with the same results bit for bit.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from timegap_env.envs.vector_env import TimeGapMonitorVectorEnv
from timegap_env.config import EnvConfig, MonitorConfig
from timegap_env.envs.info import rewards_of, summary_of, truth_of
from timegap_env.experiments.backends import Backend


NOMINAL = "none"  # the ground truth's kind of a follower no degradation hits
STABLE_TOLERANCE = 1e-9  # a setting this close to the smallest string-stable one counts as stable [s]

Config = EnvConfig | Mapping[str, Any] | None  # an EnvConfig, or overrides of the default task's config (None: it)


@dataclasses.dataclass
class EpisodeRecord:
    """One episode of one policy."""

    seed: int
    scenario: str  # the leader family (or data) the reset drew
    degradation: str  # the first degradation kind the reset drew on any follower (NOMINAL: none)
    fingerprint: str  # what the reset drew, as ``PlatoonTask.fingerprint`` writes it
    steps: int  # decisions until the episode ended
    episode_return: float  # the undiscounted sum of the rewards
    summary: dict[str, Any]  # the episode summary, Python scalars (``collision``, ``mean_setting``, ...)
    rewards: dict[str, float] = dataclasses.field(default_factory=dict)  # each reward term summed (diagnostics on)
    truth: dict[str, np.ndarray] = dataclasses.field(default_factory=dict)  # ground truth at reset, per follower
    time_below_stable: float = float("nan")  # [s per follower] below the smallest stable setting (diagnostics on)
    cost: float = float("nan")  # info["cost"] summed over the episode (where the info has it: v1's keys) [-]

    def row(self) -> dict[str, Any]:
        """A flat row: seed, scenario, degradation, steps, return, time below stable, the summary, ``reward_<term>``."""
        return {"seed": self.seed, "scenario": self.scenario, "degradation": self.degradation, "steps": self.steps,
                "return": self.episode_return, "time_below_stable": self.time_below_stable, **self.summary,
                **{f"reward_{name}": value for name, value in self.rewards.items()}}


@dataclasses.dataclass
class Batch:
    """What one vector env played: the records (per policy, for :func:`rollout_side_by_side`), env 0's trace."""

    records: list[EpisodeRecord]
    config: EnvConfig  # the env's config (with the policy's action mode)
    trace: Any = None  # env 0's ``Trace`` at every tick of the whole run, when asked for
    seconds: float = 0.0  # wall time of the rollout where it ran [s]


def env_config(config: Config, action_mode: str | None = None, estimator: str | None = None) -> dict[str, Any]:
    """``gym.make``'s ``config`` for ``config`` (an EnvConfig's top-level fields, or the overrides as given), with
    ``action_mode`` and the monitor's ``estimator`` set when given."""
    if isinstance(config, EnvConfig):
        fields = {field.name: getattr(config, field.name) for field in dataclasses.fields(config)}
    else:
        fields = dict(config or {})
    if action_mode is not None:
        fields["action_mode"] = action_mode
    if estimator is not None:
        monitor = fields.get("monitor") or {}
        fields["monitor"] = (dataclasses.replace(monitor, estimator=estimator) if isinstance(monitor, MonitorConfig)
                             else {**monitor, "estimator": estimator})
    return fields


def monitor_estimator(config: Config, policy: Any) -> str:
    """The monitor's estimator ``policy`` reads: its ``monitor_estimator``, else ``config``'s."""
    own = getattr(policy, "monitor_estimator", None)
    if own is not None:
        return str(own)
    monitor = env_config(config).get("monitor") or {}
    return str(monitor.estimator if isinstance(monitor, MonitorConfig) else monitor.get("estimator", MonitorConfig.estimator))


def chooser(policy: Any) -> Callable[[np.ndarray, dict[str, Any], Any], tuple[np.ndarray, Any]]:
    """``policy`` as ``(observations, infos, state) -> (actions, state)``; see the module's docstring."""
    if hasattr(policy, "predict"):
        return lambda obs, infos, state: policy.predict(obs, state=state, deterministic=True)
    if hasattr(policy, "act"):
        return lambda obs, infos, state: (policy.act(truth_of(infos)), state)
    if callable(policy):
        return lambda obs, infos, state: (policy(obs, infos), state)
    raise TypeError(f"policy {policy!r}: needs predict(obs, ...), act(truth) or to be a callable (obs, infos)")


def _rows(infos: Mapping[str, Any], rows: slice, total: int) -> dict[str, Any]:
    """The sub-envs ``rows`` of batched ``infos`` (``total`` sub-envs), nested dicts included."""
    out: dict[str, Any] = {}
    for key, value in infos.items():
        if isinstance(value, Mapping):
            out[key] = _rows(value, rows, total)
        elif isinstance(value, np.ndarray) and value.ndim and value.shape[0] == total:
            out[key] = value[rows]
        else:
            out[key] = value
    return out


def simulator(config: Config) -> str:
    """The simulator ``config`` names (``EnvConfig.simulator``; overrides without one: the native)."""
    if isinstance(config, EnvConfig):
        return config.simulator
    return str((config or {}).get("simulator", EnvConfig.simulator))


def rollout_side_by_side(policies: Sequence[Any], config: Config, seeds: Sequence[int],
                         options: dict[str, Any] | None = None, *, step_diagnostics: bool = True,
                         trace: bool = False) -> list[Batch]:
    """Every policy of ``policies`` on every seed of ``seeds`` in one native vector env of ``config`` (policy
    ``i`` on envs ``i * len(seeds)`` on), reset with ``options``: a :class:`Batch` per policy.

    ``step_diagnostics=False`` runs faster and leaves the reward terms, the ground truth and the time below the
    stable setting out of the records (the per-step infos hold none of them); oracles and choosers reading the
    infos need it on (it makes the env with ``truth_info=True``). ``trace`` keeps env 0's every tick (of the first policy), for a profile.

    In SUMO (``config``'s simulator "sumo", one simulation per process) every policy plays every seed in an env of
    its own, one after another, with the same records.
    """
    if simulator(config) == "native":
        return _side_by_side(policies, config, seeds, options, step_diagnostics, trace)
    batches = []
    for i, policy in enumerate(policies):
        parts = [_side_by_side([policy], config, [seed], options, step_diagnostics, trace and i == 0 and j == 0)[0]
                 for j, seed in enumerate(seeds)]
        batches.append(Batch([record for part in parts for record in part.records], parts[0].config, parts[0].trace,
                             sum(part.seconds for part in parts)))
    return batches


def _side_by_side(policies: Sequence[Any], config: Config, seeds: Sequence[int], options: dict[str, Any] | None,
                  step_diagnostics: bool, trace: bool) -> list[Batch]:
    """:func:`rollout_side_by_side` in one vector env."""
    start = time.perf_counter()
    n, m = len(seeds), len(policies)
    modes = {getattr(policy, "action_mode", None) for policy in policies}
    if len(modes) > 1:
        raise ValueError(f"policies act in different action modes {sorted(map(str, modes))}: run them apart")
    mode = modes.pop()
    estimators = {monitor_estimator(config, policy) for policy in policies}
    if len(estimators) > 1:
        raise ValueError(f"policies read monitors of different estimators {sorted(estimators)}: run them apart")
    venv = TimeGapMonitorVectorEnv(num_envs=n * m, config=env_config(config, mode, estimators.pop()),
                                   autoreset_mode="same_step", step_diagnostics=step_diagnostics,
                                   truth_info=step_diagnostics)
    try:
        obs, infos = venv.reset(seed=list(seeds) * m, options=options)
        task, env_config_ = venv.unwrapped.task, venv.unwrapped.config
        fingerprints = [task.fingerprint(env) for env in range(n * m)]
        scenarios = [str(name) for name in venv.unwrapped.scenario]
        truth_at_reset = truth_of(infos) if step_diagnostics else venv.unwrapped.ground_truth()
        tracer = task.start_trace(keep=None) if trace else None
        choose = [chooser(policy) for policy in policies]
        states: list[Any] = [None] * m  # a policy's memory (a learned policy's frame stack), from step to step
        returns, steps = np.zeros(n * m), np.zeros(n * m, dtype=np.int64)
        below, cost = np.zeros(n * m), np.zeros(n * m)
        terms: dict[str, np.ndarray] = {}
        active = np.ones(n * m, dtype=bool)
        summaries: list[dict[str, Any]] = [{} for _ in range(n * m)]
        while active.any():
            truth = truth_of(infos) if step_diagnostics else None
            if m == 1:
                action, states[0] = choose[0](obs, infos, states[0])
            else:
                parts = []
                for i in range(m):
                    part, states[i] = choose[i](obs[i * n:(i + 1) * n], _rows(infos, slice(i * n, (i + 1) * n), n * m),
                                                states[i])
                    parts.append(part)
                action = np.concatenate(parts)
            obs, reward, terminated, truncated, infos = venv.step(action)
            returns += np.where(active, reward, 0.0)
            steps += active
            done = terminated | truncated  # those envs were reset: the step's own values are in final_info
            if step_diagnostics:
                assert truth is not None  # read above whenever step_diagnostics
                setting = np.where(done[:, None], infos["final_info"]["setting"], infos["setting"]) if done.any() \
                    else infos["setting"]
                unstable = setting < truth["smallest_stable_setting"] - STABLE_TOLERANCE  # the step's end vs start
                below += np.where(active, unstable.mean(axis=1) * env_config_.decision_interval, 0.0)
                step_terms = rewards_of(infos)
                if done.any():
                    final_terms = rewards_of(infos["final_info"])
                    step_terms = {name: np.where(done, final_terms[name], value) for name, value in step_terms.items()}
                for name, value in step_terms.items():
                    terms[name] = terms.get(name, np.zeros(n * m)) + np.where(active, value, 0.0)
            if "cost" in infos:
                step_cost = np.where(done, infos["final_info"]["cost"], infos["cost"]) if done.any() else infos["cost"]
                cost += np.where(active, step_cost, 0.0)
            ended = done & active
            for env in np.flatnonzero(ended):
                summaries[env] = {name: value[env].item() for name, value in summary_of(infos["final_info"]).items()}
            active &= ~ended
    finally:
        venv.close()
    records = [
        EpisodeRecord(
            seed=int(seeds[env % n]), scenario=scenarios[env],
            degradation=next((str(k) for k in truth_at_reset["kind"][env] if k != NOMINAL), NOMINAL),
            fingerprint=fingerprints[env], steps=int(steps[env]), episode_return=float(returns[env]),
            summary=summaries[env], rewards={name: float(value[env]) for name, value in terms.items()},
            truth={name: np.array(value[env]) for name, value in truth_at_reset.items()} if step_diagnostics else {},
            time_below_stable=float(below[env]) if step_diagnostics else float("nan"),
            cost=float(cost[env]) if "cost" in infos else float("nan"),
        )
        for env in range(n * m)
    ]
    seconds = time.perf_counter() - start
    return [Batch(records[i * n:(i + 1) * n], env_config_, tracer if i == 0 else None, seconds)
            for i in range(m)]


def rollout(policy: Any, config: Config, seeds: Sequence[int], options: dict[str, Any] | None = None, *,
            step_diagnostics: bool = True, trace: bool = False) -> Batch:
    """``policy`` on every seed of ``seeds`` in one native vector env of ``config``, reset with ``options``: a
    record per episode (see :func:`rollout_side_by_side`)."""
    return rollout_side_by_side([policy], config, seeds, options, step_diagnostics=step_diagnostics, trace=trace)[0]


@dataclasses.dataclass(frozen=True)
class Job:
    """A piece of work: ``policy`` on ``seeds`` in an env of ``config`` reset with ``options``."""

    policy: Any
    config: Any = None  # an EnvConfig or gym.make's config overrides
    seeds: tuple[int, ...] = ()
    options: dict[str, Any] | None = None
    trace: bool = False


def run_job(job: Job) -> Batch:
    """:func:`rollout` of ``job``: what a backend runs."""
    return rollout(job.policy, job.config, job.seeds, job.options, trace=job.trace)


def grid(policies: Sequence[Any], configs: Sequence[Any], seeds: Sequence[int], batch: int | None = None,
         options: dict[str, Any] | None = None) -> list[Job]:
    """A job per (config, policy, batch of at most ``batch`` seeds; None: all), configs outermost."""
    size = batch or max(len(seeds), 1)
    batches = [tuple(seeds[i:i + size]) for i in range(0, len(seeds), size)]
    return [Job(policy, config, chunk, options) for config in configs for policy in policies for chunk in batches]


def run_jobs(jobs: Sequence[Job], backend: Backend | None = None) -> list[Batch]:
    """Every job's :class:`Batch`, in order, spread by ``backend`` (default: serial; Ray gives the same bits)."""
    return (backend or Backend()).map(run_job, [(job,) for job in jobs])


__all__ = ["Batch", "EpisodeRecord", "Job", "NOMINAL", "chooser", "env_config", "grid", "monitor_estimator", "simulator", "rollout", "rollout_side_by_side",
           "run_job", "run_jobs"]
