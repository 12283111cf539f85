"""TimeGapMonitor-v0 as a single env: config, spaces, scenarios, rewards, info, checkers, rendering."""

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import timegap_env
from timegap_env.config import EnvConfig, RewardWeights
from timegap_env.envs.info import KIND_NAMES, rewards_of, summary_of, truth_of
from timegap_env.envs.observation import FEATURES

LEVELS = np.array(EnvConfig().setting_levels)
N_FEATURES = len(FEATURES)
MONITOR_KEYS = {"estimate", "estimate_std", "setting", "lcl", "ucl", "alarm", "v2v", "skipped_measurements"}  # always
TRUE_STATE_KEYS = {"actual_time_gap", "ttc", "jerk", "collision"}  # with truth_info=True, beside the truth_* keys
REWARD_KEYS = {f"reward_{name}" for name in ("tracking", "string_stability", "safety", "collision", "comfort",
                                             "efficiency", "preference", "switching")}


def level_index(setting: float) -> int:
    return int(np.argmin(np.abs(LEVELS - setting)))


def run_episode(env: gym.Env, policy, seed: int, options=None) -> tuple[float, list[dict]]:
    obs, info = env.reset(seed=seed, options=options)
    total, infos = 0.0, [info]
    while True:
        obs, reward, terminated, truncated, info = env.step(policy(obs))
        total += reward
        infos.append(info)
        if terminated or truncated:
            return total, infos


def test_spaces():
    env = gym.make("TimeGapMonitor-v0")
    assert env.action_space == gym.spaces.Discrete(len(LEVELS))
    assert {1.0, 1.6} <= set(np.round(LEVELS, 3)) and LEVELS[0] == pytest.approx(0.6) and LEVELS[-1] == pytest.approx(2.2)
    box = env.observation_space
    assert box.shape == (5 * N_FEATURES,) and box.dtype == np.float32
    assert np.all(np.isfinite(box.low)) and np.all(np.isfinite(box.high))
    per_vehicle = gym.make("TimeGapMonitor-v0", config={"action_mode": "per_vehicle", "platoon": {"n_followers": 3}})
    assert per_vehicle.action_space == gym.spaces.MultiDiscrete([len(LEVELS)] * 3)
    assert per_vehicle.observation_space.shape == (3 * N_FEATURES,)


@pytest.mark.parametrize(
    "config, message",
    [
        ({"decision_interval_s": 1.0}, r"unknown EnvConfig field\(s\) \['decision_interval_s'\]"),
        ({"platoon": {"initial_setting": -1.0}}, r"PlatoonConfig.initial_setting = -1.0"),
        ({"platoon": {"initial_setting": 1.7}}, r"platoon.initial_setting = 1.7: must be one of"),
        ({"action_mode": "fleet"}, r"action_mode = 'fleet'"),
        ({"setting_levels": (1.0,)}, r"setting_levels = \(1.0,\)"),
        ({"reward_weights": {"safety": -1.0}}, r"RewardWeights.safety = -1.0"),
        ({"scenario_weights": {"rush_hour": 1.0}}, r"unknown families \['rush_hour'\]"),
        ({"degradation": {"recovery_probability": 2.0}}, r"DegradationConfig.recovery_probability = 2.0"),
        ({"degradation": {"kind_weights": {"brake_fade": 1.0}}}, r"unknown kinds \['brake_fade'\]"),
    ],
)
def test_bad_config_is_named(config, message):
    with pytest.raises(ValueError, match=message):
        gym.make("TimeGapMonitor-v0", config=config)


@pytest.mark.parametrize("action", [len(LEVELS), -1, 1.5, "fast", np.array([1, 2])])
def test_action_outside_the_space_is_refused(action):
    env = gym.make("TimeGapMonitor-v0")
    env.reset(seed=0)
    with pytest.raises(ValueError, match="outside the action space"):
        env.step(action)


@pytest.mark.parametrize("truth_info", [False, True])
def test_observations_stay_in_bounds_and_info_is_complete(truth_info):
    env = gym.make("TimeGapMonitor-v0", config={"dropout_probability_range": (0.05, 0.05)}, truth_info=truth_info)
    env.action_space.seed(0)
    _, infos = run_episode(env, lambda obs: env.action_space.sample(), seed=3)
    if truth_info:  # the monitor's view, the platoon's true state and the ground truth
        step_keys = {"actual_time_gap", "estimate", "estimate_std", "setting", "lcl", "ucl", "alarm", "ttc", "jerk",
                     "v2v", "collision", "skipped_measurements"}
        assert step_keys <= set(infos[1])
        truth_keys = {f"truth_{name}" for name in truth_of(infos[1])}
        assert {"truth_kind", "truth_onset", "truth_end", "truth_active", "truth_smallest_stable_setting"} <= truth_keys
        assert set(infos[1]) == MONITOR_KEYS | TRUE_STATE_KEYS | REWARD_KEYS | truth_keys
    else:  # the monitor's view only
        assert set(infos[1]) == MONITOR_KEYS | REWARD_KEYS
    assert set(rewards_of(infos[1])) == {"tracking", "string_stability", "safety", "collision", "comfort", "efficiency",
                                         "preference", "switching"}
    summary = summary_of(infos[-1])
    assert {"time_out_of_control", "exceedances", "max_deviation", "min_ttc", "rms_jerk", "switches",
            "mean_setting", "mean_capacity", "collision"} <= set(summary)
    assert infos[-1]["skipped_measurements"].sum() > 0  # 5 % dropouts are skipped, not fatal
    assert all(np.all(np.isfinite(info["estimate"])) for info in infos)


@pytest.mark.parametrize("truth_info", [False, True])
def test_info_has_the_same_numeric_keys_from_reset_on(truth_info):
    """TorchRL and gymnasium's vector envs batch info by key: every value an array of a fixed shape and dtype,
    no nested dicts, no strings, the same keys at reset and at every step (the summary only at the end)."""
    env = gym.make("TimeGapMonitor-v0", config={"episode_duration": 5.0}, truth_info=truth_info)
    _, infos = run_episode(env, lambda obs: level_index(1.0), seed=0)
    layout = {key: (value.shape, value.dtype) for key, value in infos[0].items()}
    assert all(isinstance(value, np.ndarray) and value.dtype.kind in "biuf" for info in infos for value in info.values())
    for info in infos[1:]:
        assert {key: (value.shape, value.dtype) for key, value in info.items() if key in layout} == layout
        assert set(info) - set(layout) == {f"episode_{name}" for name in summary_of(info)}
    assert summary_of(infos[-1]) and not any(summary_of(info) for info in infos[:-1])
    if truth_info:
        assert set(truth_of(infos[0])["kind"]) <= set(KIND_NAMES)
    else:
        with pytest.raises(KeyError, match="truth_info=True"):
            truth_of(infos[0])


def is_truth_key(key: str) -> bool:
    """What only truth_info=True puts in an info (a vector env's masks ``_<key>`` of them too)."""
    key = key.removeprefix("_")
    return key in TRUE_STATE_KEYS or key.startswith("truth_")


def assert_within(lean, full, where: str) -> None:
    """``lean`` holds every key of ``full`` but the ground truth's, with the same bits (nested dicts and object arrays,
    a vector env's final_obs, element by element); ``full`` holds the ground truth."""
    if isinstance(full, dict):
        assert not any(is_truth_key(key) for key in lean), f"{where}: {sorted(lean)}"
        assert set(lean) == {key for key in full if not is_truth_key(key)}, f"{where}: {sorted(set(full) ^ set(lean))}"
        for key in lean:
            assert_within(lean[key], full[key], f"{where}[{key!r}]")
        return
    if isinstance(full, tuple):  # what reset or step returns
        assert isinstance(lean, tuple) and len(lean) == len(full), where
        for i, (a, b) in enumerate(zip(lean, full)):
            assert_within(a, b, f"{where}[{i}]")
        return
    lean, full = np.asarray(lean), np.asarray(full)
    assert lean.dtype == full.dtype and lean.shape == full.shape, where
    if full.dtype == object:
        for i, (a, b) in enumerate(zip(lean.ravel(), full.ravel())):
            assert (a is None) == (b is None), f"{where}[{i}]"
            if a is not None:
                assert_within(a, b, f"{where}[{i}]")
        return
    assert lean.tobytes() == full.tobytes(), where


@pytest.mark.parametrize("env_id", ["TimeGapMonitor-v0", "TimeGapMonitor-v1", timegap_env.MO_ENV_ID])
def test_truth_info_adds_the_ground_truth_and_changes_nothing_else(env_id):
    """By default the info is the monitor's view: no truth_* keys and none of the platoon's true state
    (actual_time_gap, ttc, jerk, collision). truth_info=True adds them and nothing else: the same seed and actions
    give the same observations, rewards and flags bit for bit, and every key of the default info has the same value."""
    config = {"episode_duration": 12.0}
    options = {"degradation": {"kind": "gain", "size": 0.7, "followers": [2], "onset": 5.0}}
    lean, full = (gym.make(env_id, config=config, truth_info=truth_info) for truth_info in (False, True))
    assert (lean.unwrapped.truth_info, full.unwrapped.truth_info) == (False, True)
    rng = np.random.default_rng(0)
    lean.action_space.seed(0)
    for episode in range(2):
        got, want = lean.reset(seed=episode, options=options), full.reset(seed=episode, options=options)
        assert_within(got, want, f"episode {episode} reset")
        extra = set(want[1]) - set(got[1])
        assert TRUE_STATE_KEYS | {"truth_kind", "truth_active", "truth_smallest_stable_setting"} <= extra
        assert ("truth_regime" in extra) == (env_id != "TimeGapMonitor-v0")
        assert truth_of(want[1])["kind"].tolist() == ["none", "gain", "none", "none", "none"]
        with pytest.raises(KeyError, match="truth_info=True"):
            truth_of(got[1])
        for step in range(20):
            action = lean.action_space.sample() if step % 3 else int(rng.integers(len(LEVELS)))
            got, want = lean.step(action), full.step(action)
            assert_within(got, want, f"episode {episode} step {step}")  # observation, reward, flags, info
            if got[2] or got[3]:
                break
        assert got[3] and summary_of(got[4]) and set(want[4]) - set(got[4]) == extra  # the episode ran to its end


def test_the_vector_envs_truth_info_adds_the_ground_truth_and_changes_nothing_else():
    """The same for the native vector env, across same-step autoresets (final_obs, final_info) and for
    gymnasium's SyncVectorEnv over single envs."""
    config = {"episode_duration": 5.0}
    options = {"degradation": {"kind": "lag", "size": 2.0, "onset": 2.0}}
    for make in (lambda truth_info: gym.make_vec("TimeGapMonitor-v1", num_envs=3,
                                                 vectorization_mode="vector_entry_point", config=config,
                                                 autoreset_mode="same_step", truth_info=truth_info),
                 lambda truth_info: gym.vector.SyncVectorEnv(
                     [lambda: gym.make("TimeGapMonitor-v1", config=config, truth_info=truth_info)] * 3,
                     autoreset_mode=gym.vector.AutoresetMode.SAME_STEP)):
        lean, full = make(False), make(True)
        got, want = lean.reset(seed=[3, 4, 5], options=options), full.reset(seed=[3, 4, 5], options=options)
        assert_within(got, want, "reset")
        assert "truth_kind" in want[1] and "_truth_kind" in want[1] and "actual_time_gap" in want[1]
        ended = 0
        for step in range(12):
            actions = np.array([step % len(LEVELS), 4, (3 * step) % len(LEVELS)])
            got, want = lean.step(actions), full.step(actions)
            assert_within(got, want, f"step {step}")
            if "final_info" in want[4]:
                assert "truth_kind" in want[4]["final_info"] and "actual_time_gap" in want[4]["final_info"]
                ended += 1
        assert ended == 2  # two autoresets of all three


def test_observation_bounds_hold_every_step():
    env = gym.make("TimeGapMonitor-v0")
    env.action_space.seed(1)
    obs, _ = env.reset(seed=1)
    for _ in range(60):
        obs, *_ = env.step(env.action_space.sample())
        assert env.observation_space.contains(obs)


def test_reward_is_the_weighted_sum_of_its_terms():
    env = gym.make("TimeGapMonitor-v0")
    env.reset(seed=2)
    weights = RewardWeights()
    for action in (level_index(1.0), level_index(2.2), level_index(0.6)):
        _, reward, _, _, info = env.step(action)
        assert reward == pytest.approx(sum(getattr(weights, k) * v for k, v in rewards_of(info).items()))
        assert all(v <= 0 for v in rewards_of(info).values())
    assert info["reward_switching"] == -1.0  # every follower changed setting on that step


def test_setting_change_ramps_and_recentres_the_chart():
    env = gym.make("TimeGapMonitor-v0", config={"degradation": {"kind_weights": {"none": 1.0}}})
    env.reset(seed=4)
    _, _, _, _, info = env.step(level_index(1.0))
    assert np.allclose(info["setting"], 1.0)
    ramp_end = 1.6 - 0.2 * 1.0  # 0.2 s/s over one 1 s step
    assert np.allclose((info["lcl"] + info["ucl"]) / 2, ramp_end)
    for _ in range(10):
        _, _, _, _, info = env.step(level_index(1.0))
    assert np.allclose(info["lcl"], 0.75) and np.allclose(info["ucl"], 1.25)


def test_named_scenario_and_user_leader():
    env = gym.make("TimeGapMonitor-v0")
    env.reset(seed=0, options={"scenario": "sinusoid"})
    assert env.unwrapped.scenario == "sinusoid"
    speed = 20.0 + 3.0 * np.sin(np.arange(455) * 0.02)  # 45.4 s of field data at 10 Hz
    total, infos = run_episode(env, lambda obs: level_index(1.6), seed=0, options={"leader_speed": speed})
    assert env.unwrapped.scenario == "user" and len(infos) - 1 == 46  # padded to whole decisions
    assert infos[-1]["episode_duration"] == pytest.approx(46.0)
    with pytest.raises(ValueError, match="scenario = 'rush_hour'"):
        env.reset(options={"scenario": "rush_hour"})
    with pytest.raises(ValueError, match=r"reset options \['weather'\] unknown"):
        env.reset(options={"weather": "rain"})
    with pytest.raises(ValueError, match=r"speed\[1\] = nan"):
        env.reset(options={"leader_speed": [20.0, np.nan, 20.0]})


def test_v2v_outages_happen_and_show_in_the_observation():
    env = gym.make("TimeGapMonitor-v0", config={"degradation": {"kind_weights": {"v2v_outage": 1.0}}})
    obs, _ = env.reset(seed=5)
    seen_acc = False
    for _ in range(250):
        obs, _, terminated, truncated, info = env.step(level_index(1.6))
        if not info["v2v"].all():
            seen_acc = True
            assert np.all(obs.reshape(5, N_FEATURES)[~info["v2v"], FEATURES.index("v2v")] == 0)
        if terminated or truncated:
            break
    assert seen_acc


def test_collision_terminates_with_the_collision_penalty():
    speed = np.r_[np.full(30, 30.0), np.maximum(30.0 - 2.0 * np.arange(1, 20), 0.0), np.zeros(300)]  # 20 m/s^2 stop
    env = gym.make("TimeGapMonitor-v0", config={"degradation": {"kind_weights": {"none": 1.0}}}, truth_info=True)
    env.reset(seed=0, options={"leader_speed": speed})
    for _ in range(60):
        _, reward, terminated, truncated, info = env.step(level_index(0.6))
        if terminated:
            break
    assert terminated and not truncated and info["collision"]
    assert info["reward_collision"] == -1.0 and reward < -RewardWeights().collision * 0.99
    assert info["episode_collision"]


def test_same_seed_same_episode():
    first = run_episode(gym.make("TimeGapMonitor-v0"), lambda obs: level_index(1.0), seed=11)
    again = run_episode(gym.make("TimeGapMonitor-v0"), lambda obs: level_index(1.0), seed=11)
    assert first[0] == again[0]
    np.testing.assert_array_equal(first[1][-1]["estimate"], again[1][-1]["estimate"])


def test_constant_extremes_lose_to_a_v2v_aware_policy():
    """The reward is not won by a constant: always 0.6 s and always 2.2 s both score below
    '1.0 s while every follower has V2V, 1.6 s (string stable in ACC) otherwise', over 30 episodes."""
    n = 30

    def mean_return(policy) -> float:
        env = gym.make_vec("TimeGapMonitor-v0", num_envs=n, vectorization_mode="vector_entry_point")
        obs, _ = env.reset(seed=100)
        returns, done = np.zeros(n), np.zeros(n, dtype=bool)
        while not done.all():
            obs, reward, terminated, truncated, _ = env.step(policy(obs))
            returns += np.where(done, 0.0, reward)
            done |= terminated | truncated
        return float(returns.mean())

    v2v_column = FEATURES.index("v2v")

    def v2v_aware(obs: np.ndarray) -> np.ndarray:
        all_connected = obs.reshape(n, -1, N_FEATURES)[:, :, v2v_column].min(axis=1) > 0.5
        return np.where(all_connected, level_index(1.0), level_index(1.6))

    adaptive = mean_return(v2v_aware)
    smallest = mean_return(lambda obs: np.full(n, 0))
    largest = mean_return(lambda obs: np.full(n, len(LEVELS) - 1))
    assert adaptive > smallest + 20 and adaptive > largest + 20, (adaptive, smallest, largest)


def test_checkers_pass_without_warnings_on_every_registered_id():
    """Every scalar version passes gymnasium's and SB3's checkers; v0 warns only that it is out of date (gymnasium's
    convention once a newer version exists)."""
    ids = [env_id for env_id in gym.registry if env_id.startswith(timegap_env.ENV_ID.split("-")[0])]
    assert ids == list(timegap_env.TASKS) and timegap_env.LATEST_ENV_ID == "TimeGapMonitor-v1"
    for env_id in ids:
        for config in ({}, {"action_mode": "per_vehicle"}, {"action_mode": "relative"}):
            with warnings.catch_warnings():
                warnings.simplefilter("error")
                warnings.filterwarnings("ignore", "(?s).*TimeGapMonitor-v0 is out of date", DeprecationWarning)
                env = gym.make(env_id, config=config)
                check_env(env.unwrapped, skip_render_check=True)
                sb3_check_env(env.unwrapped, warn=True)


def test_rgb_array_frames_are_drawn_and_change():
    env = gym.make("TimeGapMonitor-v0", render_mode="rgb_array")
    env.reset(seed=0)
    env.step(level_index(1.6))
    first = env.render()
    for _ in range(5):
        env.step(level_index(1.0))
    second = env.render()
    assert first.ndim == 3 and first.shape[2] == 3 and first.dtype == np.uint8
    assert len(np.unique(first.reshape(-1, 3), axis=0)) > 50 and first.mean() > 40  # not a blank or black frame
    assert np.abs(first.astype(int) - second.astype(int)).sum() > 0
    env.close()


def test_whole_numbers_in_the_config_run_as_their_floats():
    """Integer-valued overrides (weights, thresholds, gains, noise) give bit for bit what the same floats give."""
    as_int = {"reward_weights": {"safety": 3, "collision": 1000}, "reward_scales": {"ttc_threshold": 4, "jerk_reference": 2},
              "platoon": {"k_a": 0, "standstill_spacing": 5, "vehicle_length": 5}, "monitor": {"forgetting": 1},
              "sensors": {"spacing_noise_std": 0}, "chart": {"limit_width": 2}}
    as_float = {"reward_weights": {"safety": 3.0, "collision": 1000.0}, "reward_scales": {"ttc_threshold": 4.0, "jerk_reference": 2.0},
                "platoon": {"k_a": 0.0, "standstill_spacing": 5.0, "vehicle_length": 5.0},
                "monitor": {"forgetting": 1.0}, "sensors": {"spacing_noise_std": 0.0}, "chart": {"limit_width": 2.0}}
    first = run_episode(gym.make("TimeGapMonitor-v0", config=as_int), lambda obs: level_index(1.0), seed=3)
    again = run_episode(gym.make("TimeGapMonitor-v0", config=as_float), lambda obs: level_index(1.0), seed=3)
    assert first[0] == again[0]
    np.testing.assert_array_equal(first[1][-1]["estimate"], again[1][-1]["estimate"])


def test_a_random_initial_setting_starts_the_platoon_there():
    env = gym.make(timegap_env.ENV_ID, config={"random_initial_setting": True, "action_mode": "relative"})
    starts = set()
    for seed in range(8):
        obs, info = env.reset(seed=seed)
        np.testing.assert_array_equal(info["setting"], info["setting"][0])
        starts.add(float(info["setting"][0]))
    assert len(starts) >= 3


@pytest.mark.parametrize("make", [
    lambda: gym.make(timegap_env.ENV_ID).unwrapped,
    lambda: gym.make_vec(timegap_env.ENV_ID, num_envs=2, vectorization_mode="vector_entry_point"),
])
def test_stepping_before_reset_raises_reset_needed(make):
    env = make()
    action = env.action_space.sample()
    with pytest.raises(gym.error.ResetNeeded, match="before reset"):
        env.step(action)
    env.reset(seed=0)
    env.step(action)


def test_an_env_copies_and_pickles_after_rendering():
    import copy
    import pickle

    env = gym.make(timegap_env.ENV_ID, render_mode="rgb_array")
    env.reset(seed=0)
    frame = env.render()
    for twin in (copy.deepcopy(env), pickle.loads(pickle.dumps(env))):
        np.testing.assert_array_equal(twin.render(), frame)
        twin.step(0)
    env.step(0)


@pytest.mark.parametrize("ending", ["terminated", "truncated"])
def test_step_after_the_episode_ended_raises_until_reset(ending):
    """Stepping on silently after the end ran on a collided platoon or past the leader's profile."""
    env = gym.make("TimeGapMonitor-v0", config={"episode_duration": 60.0, "degradation": {"kind_weights": {"none": 1.0}}})
    speed = np.r_[np.full(30, 30.0), np.maximum(30.0 - 2.0 * np.arange(1, 20), 0.0), np.zeros(300)]  # a 20 m/s^2 stop
    options = {"leader_speed": speed} if ending == "terminated" else None
    env.reset(seed=0, options=options)
    while True:
        _, _, terminated, truncated, _ = env.step(level_index(0.6 if ending == "terminated" else 1.6))
        if terminated or truncated:
            break
    assert (terminated, truncated) == (ending == "terminated", ending == "truncated")
    for _ in range(2):
        with pytest.raises(gym.error.ResetNeeded, match="after the episode ended"):
            env.step(level_index(1.6))
    env.reset(seed=1)
    env.step(level_index(1.6))


@pytest.mark.parametrize("monitor", [{}, {"window": 7.3}, {"window": None, "forgetting": 0.99},
                                     {"window": 3.0, "forgetting": 0.98}])
def test_reset_with_a_seed_gives_the_same_bits_whatever_ran_before(monitor):
    """The monitor's window ring restarts at reset: an episode does not depend on earlier ones' lengths."""
    config = {"monitor": monitor, "episode_duration": 20.0}

    def episode(env):
        obs, info = env.reset(seed=42)
        steps = [(obs, 0.0, info)]
        for action in [0, 8, 3, 3, 5, 1, 7, 2] * 3:
            obs, reward, terminated, truncated, info = env.step(action)
            steps.append((obs, reward, info))
            if terminated or truncated:
                break
        return steps

    env = gym.make("TimeGapMonitor-v0", config=config, truth_info=True)  # the whole info, ground truth included
    first = episode(env)
    env.reset(seed=3)
    for _ in range(7):  # a partial episode of another length shifts where a shared ring would stand
        env.step(4)
    for (obs, reward, info), (obs2, reward2, info2) in zip(first, episode(env), strict=True):
        assert obs.tobytes() == obs2.tobytes() and reward == reward2
        assert all(info[key].tobytes() == info2[key].tobytes() for key in info)


def test_a_standing_platoon_has_no_nan_and_no_alarms():
    """Below TIME_GAP_MIN_SPEED (s - s0) / v says nothing of the time gap: the monitor leaves such measurements
    out, so its estimate returns to the setting and the chart stays quiet; the actual time gap is inf, never NaN."""
    env = gym.make("TimeGapMonitor-v0", config={"degradation": {"kind_weights": {"none": 1.0}}, "episode_duration": 30.0,
                                                "dropout_probability_range": (0.0, 0.0)}, truth_info=True)
    _, infos = run_episode(env, lambda obs: level_index(1.4), seed=0, options={"leader_speed": np.zeros(400)})
    assert not any(np.isnan(value).any() for info in infos for value in info.values())
    assert not any(info["alarm"].any() for info in infos)
    assert np.isinf(infos[-1]["actual_time_gap"]).all() and np.allclose(infos[-1]["estimate"], 1.4)
    assert infos[-1]["skipped_measurements"].sum() == 0  # not sensor faults


@pytest.mark.parametrize("scenario", ["stop_and_go", "emergency_braking", "hard_braking"])
def test_stopping_leaders_give_no_nan(scenario):
    env = gym.make("TimeGapMonitor-v0", config={"episode_duration": 120.0}, truth_info=True)  # actual_time_gap, ttc too
    for seed in range(3):
        obs, info = env.reset(seed=seed, options={"scenario": scenario})
        while True:
            assert not np.isnan(obs).any() and not any(np.isnan(value).any() for value in info.values())
            obs, reward, terminated, truncated, info = env.step(level_index(1.6))
            assert np.isfinite(reward)
            if terminated or truncated:
                break
