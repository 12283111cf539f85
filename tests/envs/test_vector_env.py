"""The native vector env: equal to SyncVectorEnv over single envs, step by step, autoresets included."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode, SyncVectorEnv

from gymnasium.error import ResetNeeded

from timegap_env.config import EnvConfig
from timegap_env.envs.info import summary_of, truth_of
from timegap_env.envs.vector_env import parse_autoreset_mode
from timegap_env.leaders import default_ngsim_path

LEVELS = EnvConfig().setting_levels


def assert_same_infos(got, want, where=""):
    """Equal keys and equal values, nested dicts and object arrays (final_obs) included."""
    assert sorted(got) == sorted(want), f"{where}: keys differ: {sorted(set(got) ^ set(want))}"
    for key, value in want.items():
        if isinstance(value, dict):
            assert_same_infos(got[key], value, f"{where}/{key}")
        elif value.dtype == object:
            assert [None if v is None else v.tolist() for v in got[key]] == \
                   [None if v is None else v.tolist() for v in value], f"{where}/{key}"
            assert all(v is None or v.dtype == np.float32 for v in got[key]), f"{where}/{key}: float32 rows"
        else:
            assert got[key].dtype == value.dtype and got[key].shape == value.shape, f"{where}/{key}"
            np.testing.assert_array_equal(got[key], value, err_msg=f"{where}/{key}")


def native_and_reference(n, config, autoreset_mode="same_step", truth_info=False, **kwargs):
    """The native vector env and SyncVectorEnv over single envs, both with ``truth_info`` (the ground truth in the
    infos, compared too, when True)."""
    native = gym.make_vec("TimeGapMonitor-v0", num_envs=n, vectorization_mode="vector_entry_point", config=config,
                          autoreset_mode=autoreset_mode, truth_info=truth_info, **kwargs)
    reference = SyncVectorEnv([lambda: gym.make("TimeGapMonitor-v0", config=config, truth_info=truth_info)
                               for _ in range(n)], autoreset_mode=parse_autoreset_mode(autoreset_mode))
    return native, reference


@pytest.mark.parametrize("truth_info", [False, True])
@pytest.mark.parametrize("autoreset_mode", ["same_step", "next_step"])
@pytest.mark.parametrize("action_mode", ["platoon", "relative"])
def test_vector_env_equals_sync_vector_env_step_by_step(action_mode, autoreset_mode, truth_info):
    """Observations, rewards, flags and infos (masks, final_obs, final_info) as gymnasium's SyncVectorEnv, with
    the ground truth in the infos or without it."""
    config = {"episode_duration": 6.0, "dropout_probability_range": (0.0, 0.1), "action_mode": action_mode,
              "degradation": {"v2v_outage_duration_range": (1.0, 3.0), "midway_onset_probability": 0.7}}
    native, reference = native_and_reference(3, config, autoreset_mode, truth_info)
    assert native.metadata["autoreset_mode"] == parse_autoreset_mode(autoreset_mode)
    obs_native, info_native = native.reset(seed=7)
    obs_reference, info_reference = reference.reset(seed=7)
    np.testing.assert_array_equal(obs_native, obs_reference)
    assert ("truth_kind" in info_native) == ("actual_time_gap" in info_native) == truth_info
    assert_same_infos(info_native, info_reference, "reset")
    rng = np.random.default_rng(0)
    for step in range(20):  # three episodes of 6 steps each and more: crosses autoresets
        actions = rng.integers(0, len(LEVELS) if action_mode == "platoon" else 3, size=3)
        step_native = native.step(actions)
        step_reference = reference.step(actions)
        for got, want in zip(step_native[:4], step_reference[:4]):
            np.testing.assert_array_equal(got, want, err_msg=f"step {step}")
        assert_same_infos(step_native[4], step_reference[4], f"step {step}")


@pytest.mark.parametrize("kind, size", [("lag", 2.0), ("gain", 0.7), ("v2v_latency", 0.5), ("packet_loss", 0.6),
                                        ("radar_bias", 2.0), ("radar_noise", 0.8), ("commercial_acc", None),
                                        ("v2v_outage", None)])
def test_vector_env_equals_sync_vector_env_under_every_degradation(kind, size):
    """Pinned at reset with a midway onset; autoresets then draw their own from the default mix."""
    config = {"episode_duration": 8.0}
    pinned = {"degradation": {"kind": kind, "onset": 2.0, **({} if size is None else {"size": size})}}
    if kind == "commercial_acc":
        pinned["degradation"]["onset"] = 0.0
    native, reference = native_and_reference(3, config, truth_info=True)
    _, info_native = native.reset(seed=11, options=pinned)
    _, info_reference = reference.reset(seed=11, options=pinned)
    assert set(truth_of(info_native)["kind"].ravel()) == {kind}
    assert_same_infos(info_native, info_reference, "reset")
    rng = np.random.default_rng(1)
    for step in range(20):
        actions = rng.integers(0, len(LEVELS), size=3)
        step_native, step_reference = native.step(actions), reference.step(actions)
        for got, want in zip(step_native[:4], step_reference[:4]):
            np.testing.assert_array_equal(got, want, err_msg=f"{kind}, step {step}")
        assert_same_infos(step_native[4], step_reference[4], f"{kind}, step {step}")


def test_vector_env_without_autoreset_waits_for_a_masked_reset():
    config = {"episode_duration": 3.0}
    native, reference = native_and_reference(2, config, "disabled", truth_info=True)
    native.reset(seed=5)
    reference.reset(seed=5)
    for step in range(3):
        got, want = native.step(np.array([5, 5])), reference.step(np.array([5, 5]))
        for a, b in zip(got[:4], want[:4]):
            np.testing.assert_array_equal(a, b)
        assert_same_infos(got[4], want[4], f"step {step}")
    assert got[3].all()
    with pytest.raises(ResetNeeded, match=r"sub-envs \[0, 1\] ended"):
        native.step(np.array([5, 5]))
    mask = np.array([True, False])
    got, want = native.reset(options={"reset_mask": mask}), reference.reset(options={"reset_mask": mask})
    np.testing.assert_array_equal(got[0][0], want[0][0])
    assert_same_infos(got[1], want[1], "masked reset")
    with pytest.raises(ResetNeeded, match=r"sub-envs \[1\] ended"):
        native.step(np.array([5, 5]))
    with pytest.raises(ValueError, match="reset_mask"):  # a refused reset: every sub-env it might have reset waits
        native.reset(options={"reset_mask": np.array([1, 0])})
    with pytest.raises(ResetNeeded, match=r"sub-envs \[0, 1\] are half reset"):
        native.step(np.array([5, 5]))


def test_bad_autoreset_mode_is_named():
    with pytest.raises(ValueError, match="autoreset_mode = 'later'"):
        gym.make_vec("TimeGapMonitor-v0", num_envs=2, vectorization_mode="vector_entry_point", autoreset_mode="later")


def test_next_step_autoreset_loses_no_step_of_an_episode():
    """RLlib and CleanRL-style loops expect next-step autoresets: every episode keeps its full length."""
    config = {"episode_duration": 5.0}
    envs = gym.make_vec("TimeGapMonitor-v0", num_envs=2, vectorization_mode="vector_entry_point", config=config,
                        autoreset_mode="next_step")
    envs.reset(seed=0)
    lengths, running, restart = [], np.zeros(2, dtype=int), np.zeros(2, dtype=bool)
    for _ in range(18):
        _, reward, terminated, truncated, infos = envs.step(np.array([5, 5]))
        assert (reward[restart] == 0).all()
        running[~restart] += 1
        done = terminated | truncated
        lengths += running[done].tolist()
        np.testing.assert_array_equal(infos.get("_episode_duration", np.zeros(2, bool)), done)
        running[done], restart = 0, done
    assert lengths == [5] * 6


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
        assert ("final_info" in got[4]) == ("final_info" in want[4])
        if "final_info" in got[4]:
            assert_same_infos(summary_of(got[4]["final_info"]), summary_of(want[4]["final_info"]))


def test_a_finished_episode_reports_its_last_observation_and_summary_then_restarts():
    config = {"episode_duration": 3.0}
    envs = gym.make_vec("TimeGapMonitor-v0", num_envs=2, vectorization_mode="vector_entry_point", config=config,
                        autoreset_mode="same_step")
    envs.reset(seed=0)
    for _ in range(2):
        _, _, terminated, truncated, infos = envs.step(np.array([5, 5]))
        assert not (terminated | truncated).any() and "final_obs" not in infos
    obs, _, _, truncated, infos = envs.step(np.array([5, 5]))
    assert truncated.all() and infos["_final_obs"].all() and infos["_final_info"].all()
    assert infos["final_obs"].shape == (2,) and infos["final_obs"][0].dtype == np.float32
    np.testing.assert_array_equal(summary_of(infos["final_info"])["duration"], [3.0, 3.0])
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
    native = gym.make_vec("TimeGapMonitor-v0", num_envs=n, vectorization_mode="vector_entry_point", config=config,
                          autoreset_mode="same_step")
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


def test_the_default_autoreset_is_gymnasiums_and_its_vector_wrappers_take_the_env():
    """Issue 22: switching vectorization_mode between "sync" and "vector_entry_point" changes nothing by default
    (the native env autoreset same-step while gymnasium's default is next-step), and gymnasium's vector observation
    wrappers, which assert next-step autoresets, wrap the native env as it comes."""
    from gymnasium.wrappers.vector import NormalizeObservation

    config = {"episode_duration": 3.0}
    native = gym.make_vec("TimeGapMonitor-v0", num_envs=2, vectorization_mode="vector_entry_point", config=config)
    synced = gym.make_vec("TimeGapMonitor-v0", num_envs=2, vectorization_mode="sync", config=config)
    assert native.metadata["autoreset_mode"] == synced.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
    for envs in (native, synced):
        envs.reset(seed=5)
    for step in range(8):
        actions = np.array([step % 9, (step * 4) % 9])
        got, want = native.step(actions), synced.step(actions)
        for a, b in zip(got[:4], want[:4]):
            np.testing.assert_array_equal(a, b)
        assert_same_infos(got[4], want[4], f"step {step}")
    wrapped = NormalizeObservation(gym.make_vec("TimeGapMonitor-v0", num_envs=2, vectorization_mode="vector_entry_point"))
    wrapped.reset(seed=0)
    wrapped.step(np.array([1, 2]))
