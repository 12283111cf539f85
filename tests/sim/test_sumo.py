"""SUMO as a second simulator (issue 26): the env in SUMO through gymnasium's checker and every policy, the leader on
its profile, the mapped engine lag and headway, one simulation per process, a named error and a clean close.

Marked ``sumo``: run where libsumo is installed (``make sumo``, ``.ci/sumo``); skipped without it. The tests that need
no libsumo (what happens when it is missing, the vector env's refusal) run in the core suite.
"""

from __future__ import annotations

import sys
from pathlib import Path

import gymnasium as gym
from gymnasium.error import ResetNeeded
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import timegap_env
from timegap_env.agents.policies import ChartStepPolicy, FixedPolicy, PaperRulePolicy
from timegap_env.tasks import get_task
from timegap_env.config import EnvConfig, PlatoonConfig, SumoConfig
from timegap_env.envs.vector_env import TimeGapMonitorVectorEnv
from timegap_env.experiments.backends import Backend
from timegap_env.experiments.rollout import Job, rollout, run_jobs
from timegap_env.sim.sumo import SumoBusyError, SumoError, SumoPlatoon, engine_tau

ROOT = Path(__file__).resolve().parents[2]
SUMO = {"simulator": "sumo"}


def test_without_libsumo_the_error_names_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "libsumo", None)  # import libsumo raises ImportError
    with pytest.raises(SumoError, match=r"needs libsumo, which is not installed: pip install 'timegap-env\[sumo\]'"):
        gym.make(timegap_env.LATEST_ENV_ID, config=SUMO)


def test_a_vector_env_of_several_sumo_envs_is_refused_by_name() -> None:
    with pytest.raises(ValueError, match="simulator = 'sumo' with 2 envs: libsumo runs one simulation per process"):
        TimeGapMonitorVectorEnv(2, config=SUMO)


def test_the_engine_constant_gives_the_native_one_tick_response() -> None:
    lag, dt = np.array([0.2, 0.45, 1.5]), 0.1
    alpha = dt / (engine_tau(lag, dt) + dt)  # Plexe's first-order engine, one tick
    np.testing.assert_allclose(alpha, 1.0 - np.exp(-dt / lag), rtol=1e-12)


@pytest.mark.sumo
@pytest.mark.parametrize("model", ["cc", "cacc"])
def test_gymnasiums_checker_passes_in_sumo(model: str) -> None:
    pytest.importorskip("libsumo")
    env = gym.make(timegap_env.LATEST_ENV_ID, config={**SUMO, "sumo": {"model": model}})
    try:
        check_env(env.unwrapped, skip_render_check=True)
    finally:
        env.close()


def episode(env: gym.Env, policy: object, seed: int) -> tuple[float, dict]:
    """One episode of ``policy`` (predict) in ``env``: its return and the last info."""
    obs, info = env.reset(seed=seed)
    total, state, done = 0.0, None, False
    while not done:
        action, state = policy.predict(obs[None], state=state)
        obs, reward, terminated, truncated, info = env.step(np.asarray(action)[0])
        total, done = total + float(reward), terminated or truncated
    return total, info


@pytest.mark.sumo
def test_every_kind_of_policy_steps_an_episode_in_sumo() -> None:
    pytest.importorskip("libsumo")
    from timegap_env.agents.learned import LearnedPolicy

    config = get_task("TimeGapMonitor-v1").config(SUMO)
    learned = LearnedPolicy.load(ROOT / "results" / "ppo_v1")
    policies = [FixedPolicy(1.2), PaperRulePolicy(config), ChartStepPolicy(config), learned]
    for policy in policies:
        mode = getattr(policy, "action_mode", "platoon")
        env = gym.make(timegap_env.LATEST_ENV_ID, config={**SUMO, "action_mode": mode})
        try:
            total, info = episode(env, policy, 10_000)
        finally:
            env.close()
        assert np.isfinite(total) and "episode_collision" in info, policy


@pytest.mark.sumo
def test_the_leader_follows_its_profile_exactly() -> None:
    pytest.importorskip("libsumo")
    env = gym.make(timegap_env.LATEST_ENV_ID, config=SUMO)
    try:
        env.reset(seed=10_003)
        task = env.unwrapped.task
        worst, start = 0.0, task.loop.platoon.x[0, 0]
        dt = task.config.platoon.dt
        for _ in range(60):
            env.step(3)
            tick = task.loop.ticks[0]
            profile = task.episodes.leader_speed[0, min(tick, task.episodes.episode_ticks[0])]
            worst = max(worst, abs(task.loop.platoon.v[0, 0] - profile))
        assert worst <= 1e-6  # well within the 0.1 m/s: SUMO applies each speed as given, in its tick
        speeds = task.episodes.leader_speed[0, :tick + 1]
        travelled = dt * (speeds[:-1] + speeds[1:]).sum() / 2  # SUMO's ballistic update
        np.testing.assert_allclose(task.loop.platoon.x[0, 0] - start, travelled, rtol=1e-9)
    finally:
        env.close()


@pytest.mark.sumo
@pytest.mark.parametrize("model", ["cc", "cacc"])
@pytest.mark.parametrize("v2v", [False, True])
def test_a_steady_platoon_keeps_the_setting_it_was_given(model: str, v2v: bool) -> None:
    pytest.importorskip("libsumo")
    config = PlatoonConfig(n_followers=3, v2v=v2v)
    platoon = SumoPlatoon(config, SumoConfig(model=model), episode_duration=200.0)
    try:
        platoon.reset(25.0, setting=1.2)
        n = 1200
        ticks = platoon.advance(np.full((n, 1), 25.0), np.zeros((n, 1)))
        gap = (ticks.spacing[-1, 0] - config.standstill_spacing) / ticks.speed[-1, 0]
        np.testing.assert_allclose(gap, 1.2, atol=0.02)
        platoon.request_setting(1.6)  # ramps at setting_ramp_rate, pushed to SUMO as it moves
        ticks = platoon.advance(np.full((3000, 1), 25.0), np.zeros((3000, 1)))
        gap = (ticks.spacing[-1, 0] - config.standstill_spacing) / ticks.speed[-1, 0]
        np.testing.assert_allclose(gap, 1.6, atol=0.02)
        assert not platoon.collided.any()
    finally:
        platoon.close()


@pytest.mark.sumo
def test_one_simulation_per_process_and_a_clean_close() -> None:
    pytest.importorskip("libsumo")
    first, second = (gym.make(timegap_env.LATEST_ENV_ID, config=SUMO) for _ in range(2))
    try:
        first.reset(seed=1)
        with pytest.raises(SumoBusyError, match="another SUMO simulation runs in this process"):
            second.reset(seed=1)
        with pytest.raises(ResetNeeded):  # the refused reset leaves it to be reset, naming no episode
            second.step(3)
        assert second.unwrapped.task.scenario[0] == ""
        first.close()
        second.reset(seed=1)  # the first one closed: the second may start
        second.step(3)
    finally:
        first.close()
        second.close()


@pytest.mark.sumo
def test_a_sumo_error_mid_episode_is_named_and_closes_the_simulation() -> None:
    libsumo = pytest.importorskip("libsumo")
    env = gym.make(timegap_env.LATEST_ENV_ID, config=SUMO)
    try:
        env.reset(seed=2)
        env.step(3)
        libsumo.vehicle.remove("v2")  # SUMO loses a follower behind the env's back
        with pytest.raises(SumoError, match=r"SUMO failed while tick \d+ of the episode .*not known"):
            env.step(3)
        assert not env.unwrapped.task.loop.platoon.running
        with pytest.raises(RuntimeError, match="before reset"):
            env.step(3)
        env.reset(seed=2)  # a new episode starts a new simulation
        env.step(3)
    finally:
        env.close()
    assert not env.unwrapped.task.loop.platoon.running


@pytest.mark.sumo
def test_episodes_spread_over_worker_processes_give_the_serial_records() -> None:
    pytest.importorskip("libsumo")
    config = get_task("TimeGapMonitor-v1").config(SUMO)
    jobs = [Job(FixedPolicy(level), config, (10_000, 10_001)) for level in (1.0, 1.6)]
    serial = run_jobs(jobs)
    spread = run_jobs(jobs, Backend("processes", workers=2))
    assert [[r.episode_return for r in b.records] for b in serial] == [[r.episode_return for r in b.records]
                                                                       for b in spread]
    assert rollout(FixedPolicy(1.0), config, [10_000]).records[0].episode_return == serial[0].records[0].episode_return



@pytest.mark.sumo
def test_a_sumo_env_refuses_to_be_copied_by_name() -> None:
    pytest.importorskip("libsumo")
    import copy

    env = gym.make(timegap_env.LATEST_ENV_ID, config=SUMO)
    try:
        with pytest.raises(TypeError, match="a SumoPlatoon cannot be copied or pickled"):
            copy.deepcopy(env.unwrapped)
    finally:
        env.close()


@pytest.mark.sumo
def test_one_env_runs_episode_after_episode() -> None:
    pytest.importorskip("libsumo")
    env = gym.make(timegap_env.LATEST_ENV_ID, config={**SUMO, "episode_duration": 20.0})
    try:
        for seed in range(60):  # each reset starts where the road starts, not where the last episode ended
            env.reset(seed=seed)
            for _ in range(20):
                _, _, terminated, truncated, _ = env.step(3)
                if terminated or truncated:
                    break
    finally:
        env.close()


@pytest.mark.sumo
def test_an_env_dropped_without_closing_frees_the_process() -> None:
    pytest.importorskip("libsumo")
    import gc

    env = gym.make(timegap_env.LATEST_ENV_ID, config=SUMO)
    env.reset(seed=0)
    del env
    gc.collect()
    other = gym.make(timegap_env.LATEST_ENV_ID, config=SUMO)
    try:
        other.reset(seed=0)
        other.step(3)
    finally:
        other.close()


def test_plexe_cannot_hold_a_standstill_spacing_below_its_own() -> None:
    pytest.importorskip("libsumo")
    with pytest.raises(ValueError, match="platoon.standstill_spacing = 1.5: Plexe's CC model holds at least 2.0 m"):
        SumoPlatoon(PlatoonConfig(standstill_spacing=1.5), SumoConfig(), episode_duration=10.0)
