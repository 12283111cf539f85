"""The rollout harness gives, bit for bit, what each of the four loops it replaced gave (copied here as they were:
train/evaluate.py's run_batch, train/sweep.py's play, train/tune_rule.py's run, train/value_of_information.py's run)."""

from __future__ import annotations

import dataclasses
import functools
import pickle

import gymnasium as gym
import numpy as np
import pytest

import timegap_env
from timegap_env.agents.oracles import NOMINAL, StabilityOracle, TruthPolicy
from timegap_env.agents.policies import ChartStepPolicy, FixedPolicy, PaperRulePolicy, V2VAwarePolicy
from timegap_env.config import EnvConfig
from timegap_env.tasks import get_task
from timegap_env.envs.info import summary_of, truth_of
from timegap_env.envs.reward import weights_of
from timegap_env.experiments import rollout as harness
from timegap_env.studies import value
from timegap_env.experiments.backends import Backend

SEEDS = [10_000, 10_001, 10_002]


# ---------------------------------------------------------------- the old loops, as they were
def old_evaluate(policy, config_overrides, options, seeds):
    n = len(seeds)
    venv = gym.make_vec(timegap_env.DEFAULT_TASK, num_envs=n, vectorization_mode="vector_entry_point",
                        config={**config_overrides, "action_mode": policy.action_mode}, autoreset_mode="same_step",
                        truth_info=True)
    obs, infos = venv.reset(seed=seeds, options=options)
    task, config = venv.unwrapped.task, venv.unwrapped.config
    prints = [task.fingerprint(env) for env in range(n)]
    scenarios = list(venv.unwrapped.scenario)
    returns, steps, below = np.zeros(n), np.zeros(n, dtype=np.int64), np.zeros(n)
    active = np.ones(n, dtype=bool)
    summaries = [{} for _ in range(n)]
    state = None
    while active.any():
        truth = truth_of(infos)
        if isinstance(policy, TruthPolicy):
            action = policy.act(truth)
        else:
            action, state = policy.predict(obs, state=state, deterministic=True)
        obs, reward, terminated, truncated, infos = venv.step(action)
        returns += np.where(active, reward, 0.0)
        steps += active
        done = terminated | truncated
        setting = np.where(done[:, None], infos["final_info"]["setting"], infos["setting"]) if done.any() \
            else infos["setting"]
        unstable = setting < truth["smallest_stable_setting"] - 1e-9
        below += np.where(active, unstable.mean(axis=1) * config.decision_interval, 0.0)
        ended = (terminated | truncated) & active
        for env in np.flatnonzero(ended):
            summaries[env] = {name: float(value[env]) for name, value in summary_of(infos["final_info"]).items()}
        active &= ~ended
    venv.close()
    records = [{"seed": seed, "scenario": scenarios[env], "steps": int(steps[env]), "return": float(returns[env]),
                "time_below_stable": float(below[env]), **summaries[env]} for env, seed in enumerate(seeds)]
    return records, prints


def old_sweep(policy, overrides, seeds):
    n = len(seeds)
    venv = gym.make_vec(timegap_env.DEFAULT_TASK, num_envs=n, vectorization_mode="vector_entry_point",
                        config={**overrides, "action_mode": policy.action_mode}, autoreset_mode="same_step",
                        truth_info=True)
    obs, infos = venv.reset(seed=list(seeds))
    scenarios = [str(name) for name in venv.unwrapped.scenario]
    kinds = [next((str(k) for k in row if k != NOMINAL), NOMINAL) for row in truth_of(infos)["kind"]]
    returns, active = np.zeros(n), np.ones(n, dtype=bool)
    summaries = [{} for _ in range(n)]
    state = None
    while active.any():
        action, state = policy.predict(obs, state=state, deterministic=True)
        obs, reward, terminated, truncated, infos = venv.step(action)
        returns += np.where(active, reward, 0.0)
        ended = (terminated | truncated) & active
        for env in np.flatnonzero(ended):
            summaries[env] = {name: value[env].item() for name, value in summary_of(infos["final_info"]).items()}
        active &= ~ended
    venv.close()
    rows = []
    for env, seed in enumerate(seeds):
        summary = dict(summaries[env])
        collision = int(summary.pop("collision"))
        rows.append({"seed": seed, "scenario": scenarios[env], "degradation": kinds[env],
                     "return": float(returns[env]), "collision": collision, **summary})
    return rows


TUNE_SUMMARY = ("collision", "mean_setting", "switches", "min_ttc")


def old_tune_rule(seeds, policies):
    n, m = len(seeds), len(policies)
    venv = gym.make_vec(timegap_env.DEFAULT_TASK, num_envs=n * m, vectorization_mode="vector_entry_point",
                        step_diagnostics=False, autoreset_mode="same_step")
    obs, _ = venv.reset(seed=list(seeds) * m)
    kinds = np.array([next((k for k in row if k != NOMINAL), NOMINAL) for row in venv.ground_truth()["kind"][:n]],
                     dtype=object)
    returns, active = np.zeros(n * m), np.ones(n * m, dtype=bool)
    summary = {name: np.zeros(n * m) for name in TUNE_SUMMARY}
    while active.any():
        actions = np.concatenate([policy.predict(obs[i * n:(i + 1) * n])[0] for i, policy in enumerate(policies)])
        obs, reward, terminated, truncated, infos = venv.step(actions)
        returns += np.where(active, reward, 0.0)
        ended = (terminated | truncated) & active
        if ended.any():
            for name in TUNE_SUMMARY:
                summary[name][ended] = summary_of(infos["final_info"])[name][ended]
        active &= ~ended
    venv.close()
    return {"return": returns.reshape(m, n), **{name: value.reshape(m, n) for name, value in summary.items()},
            "kind": kinds}


def old_value_run(config, seeds, choose, options=None):
    n = len(seeds)
    fields = {field.name: getattr(config, field.name) for field in dataclasses.fields(config)}
    venv = gym.make_vec(timegap_env.DEFAULT_TASK, num_envs=n, vectorization_mode="vector_entry_point", config=fields,
                        autoreset_mode="same_step", truth_info=True)
    obs, infos = venv.reset(seed=list(seeds), options=options)
    kinds = [next((k for k in row if k != NOMINAL), NOMINAL) for row in truth_of(infos)["kind"]]
    returns, active = np.zeros(n), np.ones(n, dtype=bool)
    summaries = [{} for _ in range(n)]
    while active.any():
        obs, reward, terminated, truncated, infos = venv.step(choose(obs, infos))
        returns += np.where(active, reward, 0.0)
        ended = (terminated | truncated) & active
        for env in np.flatnonzero(ended):
            summaries[env] = {name: float(value[env]) for name, value in summary_of(infos["final_info"]).items()}
        active &= ~ended
    venv.close()
    return {"return": returns, "collision": np.array([s["collision"] for s in summaries], dtype=bool),
            "kind": np.array(kinds, dtype=object),
            **{signal: np.array([s[signal] for s in summaries]) for signal in value.MONITOR_SIGNALS}}


# ---------------------------------------------------------------- the harness equals them
def same(a, b):
    """Equal, NaN equal to NaN, arrays element by element and of the same dtype kind."""
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b))
    if isinstance(a, np.ndarray):
        return a.shape == b.shape and a.dtype == b.dtype and bool(np.all((a == b) | (a != a) & (b != b)))
    return type(a) is type(b) and (a == b or a != a and b != b)


@pytest.mark.parametrize("policy, overrides, options", [
    (PaperRulePolicy(EnvConfig()), {}, None),
    (PaperRulePolicy(EnvConfig().with_overrides({"action_mode": "per_vehicle"})), {}, {"scenario": "stop_and_go"}),
    (StabilityOracle(EnvConfig(), 0.1), {"degradation": {"kind_weights": {"lag": 1.0}}}, None),
])
def test_the_harness_gives_evaluates_records_and_fingerprints(policy, overrides, options):
    records, prints = old_evaluate(policy, overrides, options, SEEDS)
    batch = harness.rollout(policy, overrides, SEEDS, options)
    new = [{"seed": seed, "scenario": e.scenario, "steps": e.steps, "return": e.episode_return,
            "time_below_stable": e.time_below_stable, **{k: float(v) for k, v in e.summary.items()}}
           for e, seed in zip(batch.records, SEEDS)]
    assert same(new, records)
    assert [e.fingerprint for e in batch.records] == prints


@pytest.mark.parametrize("policy", [V2VAwarePolicy(EnvConfig()), FixedPolicy(2.0, EnvConfig())])
def test_the_harness_gives_the_sweeps_rows(policy):
    overrides = {"degradation": {"kind_weights": {"gain": 1.0, "v2v_outage": 1.0}}}
    rows = old_sweep(policy, overrides, tuple(SEEDS))
    new = []
    for e in harness.rollout(policy, overrides, tuple(SEEDS)).records:
        summary = dict(e.summary)
        collision = int(summary.pop("collision"))
        new.append({"seed": e.seed, "scenario": e.scenario, "degradation": e.degradation, "return": e.episode_return,
                    "collision": collision, **summary})
    assert same(new, rows)


def test_policies_side_by_side_give_tune_rules_tables():
    config = EnvConfig()
    policies = [ChartStepPolicy(config), PaperRulePolicy(config), FixedPolicy(1.0, config)]
    old = old_tune_rule(SEEDS, policies)
    batches = harness.rollout_side_by_side(policies, None, SEEDS, step_diagnostics=False)
    assert same(np.array([[e.episode_return for e in b.records] for b in batches]), old["return"])
    for name in TUNE_SUMMARY:
        assert same(np.array([[e.summary[name] for e in b.records] for b in batches], dtype=float), old[name])
    assert list(old["kind"]) == [e.degradation for e in batches[0].records]
    alone = harness.rollout(policies[1], None, SEEDS)  # side by side or alone: the same episodes
    assert [e.episode_return for e in alone.records] == [e.episode_return for e in batches[1].records]


def test_value_of_informations_run_is_the_harness():
    config = EnvConfig()
    oracle = StabilityOracle(config, 0.0)
    for choose, options in [(functools.partial(value.flag_aware_actions, np.full(3, 4), np.full(3, 1)), None),
                            (functools.partial(value.oracle_actions, oracle), {"degradation": {"kind": "lag", "size": 2.0}})]:
        assert same(value.run(config, SEEDS, choose, options), old_value_run(config, SEEDS, choose, options))


def test_a_record_holds_the_reward_terms_the_truth_and_a_row():
    batch = harness.rollout(FixedPolicy(1.4, EnvConfig()), None, SEEDS[:2], trace=True)
    assert batch.trace is not None
    for record in batch.records:
        weights = weights_of(batch.config)._asdict()  # the terms are unweighted; the reward is their weighted sum
        assert sum(weights[name] * term for name, term in record.rewards.items()) == pytest.approx(record.episode_return,
                                                                                                  rel=1e-9, abs=1e-9)
        assert set(record.truth) >= {"kind", "onset", "end", "smallest_stable_setting"}
        assert record.row()["return"] == record.episode_return and "reward_" + next(iter(record.rewards)) in record.row()
    quiet = harness.rollout(FixedPolicy(1.4, EnvConfig()), None, SEEDS[:2], step_diagnostics=False)
    assert [r.episode_return for r in quiet.records] == [r.episode_return for r in batch.records]
    assert quiet.records[0].rewards == {} and np.isnan(quiet.records[0].time_below_stable)


def test_jobs_run_serially_give_what_rollout_gives_and_pickle():
    config = EnvConfig()
    jobs = harness.grid([PaperRulePolicy(config), FixedPolicy(1.0, config)], [{}, {"preferred_setting": 1.0}], SEEDS,
                        batch=2)
    assert len(jobs) == 2 * 2 * 2 and jobs[0].seeds == tuple(SEEDS[:2]) and jobs[1].seeds == (SEEDS[2],)
    for job in jobs:
        pickle.loads(pickle.dumps(job))  # what a Ray task gets
    batches = harness.run_jobs(jobs, Backend("serial"))
    direct = harness.rollout(jobs[5].policy, jobs[5].config, jobs[5].seeds)
    assert [e.row() for e in batches[5].records] == [e.row() for e in direct.records]


def test_mixed_action_modes_cannot_share_an_env():
    config = EnvConfig()
    with pytest.raises(ValueError, match="action modes"):
        harness.rollout_side_by_side([PaperRulePolicy(config),
                                      PaperRulePolicy(config.with_overrides({"action_mode": "per_vehicle"}))], None, SEEDS)


class RawGapReader(PaperRulePolicy):
    """The paper's rule reading the raw-gap ablation's monitor, as a learned policy trained on it declares."""

    monitor_estimator = "raw_gap"


def test_a_policy_that_read_the_raw_gap_plays_in_an_env_whose_monitor_reports_it():
    config = get_task(timegap_env.DEFAULT_TASK).config()  # what overrides as a dict go over
    raw = harness.rollout(RawGapReader(config), config, SEEDS)
    assert raw.config.monitor.estimator == "raw_gap"
    as_config = harness.rollout(PaperRulePolicy(config), {"monitor": {"estimator": "raw_gap"}}, SEEDS)
    assert [r.episode_return for r in raw.records] == [r.episode_return for r in as_config.records]
    bayes = harness.rollout(PaperRulePolicy(config), config, SEEDS)
    assert bayes.config.monitor.estimator == "bayes"
    assert [r.fingerprint for r in raw.records] == [r.fingerprint for r in bayes.records]  # the same episodes
    with pytest.raises(ValueError, match=r"different estimators \['bayes', 'raw_gap'\]"):
        harness.rollout_side_by_side([RawGapReader(config), PaperRulePolicy(config)], config, SEEDS)


class PicklingBackend(Backend):
    """What Ray does to a piece, without Ray: the function and every piece pickled out, the results pickled back."""

    def map(self, function, pieces):
        function = pickle.loads(pickle.dumps(function))
        return [pickle.loads(pickle.dumps(function(*pickle.loads(pickle.dumps(piece))))) for piece in pieces]


def test_jobs_shipped_as_ray_ships_them_give_the_same_bits():
    config = EnvConfig()
    jobs = harness.grid([StabilityOracle(config, 0.1), V2VAwarePolicy(config)], [{}], SEEDS, batch=2)
    serial = harness.run_jobs(jobs, Backend("serial"))
    shipped = harness.run_jobs(jobs, PicklingBackend("serial"))
    assert [repr([r.row() for r in b.records]) for b in shipped] == [repr([r.row() for r in b.records]) for b in serial]
    assert [[r.fingerprint for r in b.records] for b in shipped] == [[r.fingerprint for r in b.records] for b in serial]
