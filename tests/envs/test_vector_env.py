"""The native vector env: equal to SyncVectorEnv over single envs, step by step, autoresets included."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode, SyncVectorEnv

from timegap_env.config import EnvConfig
from timegap_env.leaders import default_ngsim_path

LEVELS = EnvConfig().setting_levels


@pytest.mark.parametrize("action_mode", ["platoon", "relative"])
def test_vector_env_equals_single_envs_step_by_step(action_mode):
    config = {"episode_duration": 6.0, "dropout_probability_range": (0.0, 0.1), "action_mode": action_mode,
              "degradation": {"v2v_outage_duration_range": (1.0, 3.0), "midway_onset_probability": 0.7}}
    n = 3
    native = gym.make_vec("TimeGapMonitor-v0", num_envs=n, vectorization_mode="vector_entry_point", config=config)
    reference = SyncVectorEnv([lambda: gym.make("TimeGapMonitor-v0", config=config) for _ in range(n)],
                              autoreset_mode=AutoresetMode.SAME_STEP)
    obs_native, _ = native.reset(seed=7)
    obs_reference, _ = reference.reset(seed=7)
    np.testing.assert_array_equal(obs_native, obs_reference)
    rng = np.random.default_rng(0)
    for step in range(20):  # three episodes of 6 steps each and more: crosses autoresets
        actions = rng.integers(0, len(LEVELS) if action_mode == "platoon" else 3, size=n)
        step_native = native.step(actions)
        step_reference = reference.step(actions)
        for got, want in zip(step_native[:4], step_reference[:4]):
            np.testing.assert_array_equal(got, want, err_msg=f"step {step}")
        np.testing.assert_array_equal(step_native[4]["estimate"][~step_native[3]], step_reference[4]["estimate"][~step_native[3]])


@pytest.mark.parametrize("kind, size", [("lag", 2.0), ("gain", 0.7), ("v2v_latency", 0.5), ("packet_loss", 0.6),
                                        ("radar_bias", 2.0), ("radar_noise", 0.8), ("commercial_acc", None),
                                        ("v2v_outage", None)])
def test_vector_env_equals_single_envs_under_every_degradation(kind, size):
    """Pinned at reset with a midway onset; autoresets then draw their own from the default mix."""
    config = {"episode_duration": 8.0}
    pinned = {"degradation": {"kind": kind, "onset": 2.0, **({} if size is None else {"size": size})}}
    if kind == "commercial_acc":
        pinned["degradation"]["onset"] = 0.0
    n = 3
    native = gym.make_vec("TimeGapMonitor-v0", num_envs=n, vectorization_mode="vector_entry_point", config=config)
    reference = SyncVectorEnv([lambda: gym.make("TimeGapMonitor-v0", config=config) for _ in range(n)],
                              autoreset_mode=AutoresetMode.SAME_STEP)
    _, info_native = native.reset(seed=11, options=pinned)
    _, info_reference = reference.reset(seed=11, options=pinned)
    assert set(info_native["degradation"]["kind"].ravel()) == {kind}
    rng = np.random.default_rng(1)
    for step in range(20):
        actions = rng.integers(0, len(LEVELS), size=n)
        step_native, step_reference = native.step(actions), reference.step(actions)
        for got, want in zip(step_native[:4], step_reference[:4]):
            np.testing.assert_array_equal(got, want, err_msg=f"{kind}, step {step}")
        running = ~(step_native[2] | step_native[3])  # after an autoreset the single envs' info is the old episode's
        truth_native, truth_reference = step_native[4]["degradation"], step_reference[4]["degradation"]
        assert set(truth_native) == {name for name in truth_reference if not name.startswith("_")}  # SyncVectorEnv masks
        for name in truth_native:
            np.testing.assert_array_equal(truth_native[name][running], truth_reference[name][running], err_msg=name)


def test_vector_env_without_step_diagnostics_steps_the_same():
    config = {"episode_duration": 4.0}
    full = gym.make_vec("TimeGapMonitor-v0", num_envs=2, vectorization_mode="vector_entry_point", config=config)
    lean = gym.make_vec("TimeGapMonitor-v0", num_envs=2, vectorization_mode="vector_entry_point", config=config,
                        step_diagnostics=False)
    full.reset(seed=3)
    lean.reset(seed=3)
    for step in range(6):  # past the end of the 4-step episodes
        actions = np.array([step % len(LEVELS), 2])
        got, want = lean.step(actions), full.step(actions)
        for a, b in zip(got[:4], want[:4]):
            np.testing.assert_array_equal(a, b)
        assert "estimate" in want[4] and "estimate" not in got[4]
        assert ("episode_summary" in got[4]) == ("episode_summary" in want[4])


def test_a_finished_episode_reports_its_last_observation_and_summary_then_restarts():
    config = {"episode_duration": 3.0}
    envs = gym.make_vec("TimeGapMonitor-v0", num_envs=2, vectorization_mode="vector_entry_point", config=config)
    envs.reset(seed=0)
    for _ in range(2):
        _, _, terminated, truncated, infos = envs.step(np.array([5, 5]))
        assert not (terminated | truncated).any() and "final_obs" not in infos
    obs, _, _, truncated, infos = envs.step(np.array([5, 5]))
    assert truncated.all() and infos["_final_obs"].all() and infos["_episode_summary"].all()
    np.testing.assert_array_equal(infos["episode_summary"]["duration"], [3.0, 3.0])
    assert not np.array_equal(np.stack(infos["final_obs"]), obs)  # obs is the new episode's first
    _, _, _, truncated, _ = envs.step(np.array([5, 5]))
    assert not truncated.any()


def test_envs_that_do_not_reset_keep_their_v2v_status_when_others_do():
    """Episodes of different lengths (NGSIM leaders) reset at different steps; an outage starting or ending
    exactly then must show in the observations as it does in single envs."""
    if not default_ngsim_path().exists():
        pytest.skip(f"NGSIM data absent at {default_ngsim_path()}")
    config = {"degradation": {"kind_weights": {"v2v_outage": 1.0}, "v2v_outage_duration_range": (3.0, 6.0)},
              "episode_duration": 40.0}
    n = 32
    native = gym.make_vec("TimeGapMonitor-v0", num_envs=n, vectorization_mode="vector_entry_point", config=config)
    reference = SyncVectorEnv([lambda: gym.make("TimeGapMonitor-v0", config=config) for _ in range(n)],
                              autoreset_mode=AutoresetMode.SAME_STEP)
    options = {"scenario": "ngsim_in_band"}
    native.reset(seed=3, options=options)
    reference.reset(seed=3, options=options)
    rng, partial_resets = np.random.default_rng(0), 0
    for step in range(200):
        actions = rng.integers(0, len(LEVELS), size=n)
        got, want = native.step(actions), reference.step(actions)
        np.testing.assert_array_equal(got[0], want[0], err_msg=f"step {step}")
        done = got[2] | got[3]
        partial_resets += bool(done.any() and not done.all())
    assert partial_resets > 10
