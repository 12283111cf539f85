"""Fuzz of long random-action runs (issue 22): the single env and the native vector env under many configs,
action modes, autoreset modes, scenarios, pinned degradations (extreme sizes included), the user's own leader
speeds and short episodes.

Every step: the observation is float32, finite and within the observation space; the reward is finite; nothing in
the info is NaN, and inf only in the keys documented to be inf (``actual_time_gap`` below 1 m/s, ``ttc``,
``episode_min_ttc``, ``truth_onset``/``truth_end``/``truth_smallest_stable_setting``); no exception. Runs with the
same seeds give the same bits (in one process and, slow, across processes); the native vector env equals
gymnasium's ``SyncVectorEnv`` over single envs with the same seeds and ``autoreset_mode``, step by step, infos
included. A pinned degradation or leader the env refuses must be a ``ValueError`` naming the option.

Fast: about 10^4 steps in all. ``-m slow``: 10^6 single-env steps and 10^6 vector env-steps, figures printed.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import SyncVectorEnv
from hypothesis import given
from hypothesis import strategies as st

import timegap_env  # noqa: F401 - registers the env
from timegap_env.config import DEGRADATION_KINDS, MAX_SPEED, EnvConfig
from timegap_env.envs.vector_env import parse_autoreset_mode
from timegap_env.leaders.scenarios import SCENARIOS
from timegap_env.sim.presets import acc_presets
from tests.fuzz.fuzzing import (
    ENV_ID, PLAYABLE, RECORDED_SCENARIOS, Defects, Digest, bad_step, bad_values, call, first, fuzz_settings,
    same_infos, short, skip_without_data,
)

FAMILIES = PLAYABLE
SYNTHETIC = [name for name in sorted(SCENARIOS) if name not in (*RECORDED_SCENARIOS, "idm")]
ALL_BUT_IDM = PLAYABLE

# Valid configs (every field within its documented bounds), chosen where things meet: action modes, short and long
# episodes, coarse and fine ticks, one or many followers, charts, dropouts, wild but valid gains and sizes.
CONFIGS: dict[str, dict[str, Any]] = {
    "default": {},
    "per_vehicle, 3 followers": {"action_mode": "per_vehicle", "platoon": {"n_followers": 3}},
    "relative, random start": {"action_mode": "relative", "random_initial_setting": True},
    "2 s episodes, held-out families": {"episode_duration": 2.0,
                                        "scenario_weights": {"emergency_braking": 1.0, "stop_and_go": 1.0}},
    "2.5 s episodes, every family": {"episode_duration": 2.5, "decision_interval": 0.5,
                                     "scenario_weights": {family: 1.0 for family in ALL_BUT_IDM}},
    "20 s episodes, recorded leaders": {"episode_duration": 20.0,
                                        "scenario_weights": {"ngsim": 1.0, "ngsim_in_band": 1.0, "openacc": 1.0}},
    "ewma, half the measurements lost": {"chart": {"kind": "ewma"}, "sensors": {"dropout_probability": 0.5}},
    "cusum, ACC": {"chart": {"kind": "cusum"}, "platoon": {"v2v": False}},
    "dt 0.05, 0.5 s decisions": {"platoon": {"dt": 0.05}, "monitor": {"dt": 0.05}, "chart": {"dt": 0.05},
                                 "leader": {"dt": 0.05}, "decision_interval": 0.5, "episode_duration": 30.0},
    "dt 1, one follower": {"platoon": {"dt": 1.0, "n_followers": 1, "v2v_delay": 0.0, "max_v2v_latency": 1.0},
                           "monitor": {"dt": 1.0}, "chart": {"dt": 1.0}, "leader": {"dt": 1.0},
                           "decision_interval": 1.0, "episode_duration": 60.0},
    "lag x10": {"degradation": {"kind_weights": {"lag": 1.0}, "lag_factor_range": (9.0, 10.0)}},
    "gain 1e-9": {"degradation": {"kind_weights": {"gain": 1.0}, "gain_range": (1e-9, 2e-9)}},
    "radar 100 m": {"degradation": {"kind_weights": {"radar_noise": 1.0, "radar_bias": 1.0},
                                    "radar_noise_range": (50.0, 100.0), "radar_bias_range": (50.0, 100.0)},
                    "sensors": {"spacing_noise_std": 100.0, "speed_noise_std": 100.0}},
    "V2V at its worst": {"degradation": {"kind_weights": {"packet_loss": 1.0, "v2v_outage": 1.0, "v2v_latency": 1.0},
                                         "packet_loss_range": (0.99, 0.999999), "v2v_latency_range": (0.9, 1.0),
                                         "v2v_outage_duration_range": (0.0, 3600.0)}},
    "dropouts 90-99 %": {"dropout_probability_range": (0.9, 0.99)},
    "20 followers per vehicle": {"platoon": {"n_followers": 20}, "action_mode": "per_vehicle",
                                 "episode_duration": 50.0},
    "speed band 0-100 m/s": {"leader": {"speed_band": (0.0, MAX_SPEED), "initial_speed": 0.0}},
    "no window": {"monitor": {"window": None}, "episode_duration": 500.0},
    "forgetting 0.5, 0.1 s window": {"monitor": {"forgetting": 0.5, "window": 0.1}},
    "slow, strong cars, tight chart": {"platoon": {"actuation_lag": 10.0, "accel_min": -20.0, "accel_max": 20.0},
                                       "chart": {"limit_width": 1e-6, "baseline_std": 1e-6}},
    "wild gains": {"platoon": {"k_s": 10.0, "k_v": 10.0, "k_a": -10.0, "k_f": 10.0}},
    "ladder 0.1-10 s": {"setting_levels": (0.1, 10.0), "platoon": {"initial_setting": 0.1}, "preferred_setting": 0.1},
    "every kind midway, recovering": {"degradation": {"kind_weights": {kind: 1.0 for kind in DEGRADATION_KINDS},
                                                      "midway_onset_probability": 1.0, "recovery_probability": 1.0},
                                      "episode_duration": 40.0},
}
CONFIG_NAMES = list(CONFIGS)


@pytest.mark.parametrize("name", CONFIG_NAMES)
def test_fuzzed_configs_are_valid(name):
    """The configs above are within the documented bounds: the env must build them."""
    gym.make(ENV_ID, config=CONFIGS[name])

# Pinned degradations at the ends of their documented ranges (timegap_env.config.DEGRADATIONS' size_bounds), onsets and ends
# anywhere up to the longest episode. The env runs them clean or refuses them with a ValueError naming the option.
EXTREME_SIZES: dict[str, list[float | None]] = {
    "lag": [1e-300, 1e-6, 1.0, 10.0], "gain": [1e-300, 1e-6, 1.0, 10.0], "v2v_latency": [0.0, 0.1, 1.0],
    "packet_loss": [0.0, 0.999999], "radar_bias": [-100.0, -1e-9, 100.0], "radar_noise": [0.0, 1e-300, 100.0],
    "v2v_outage": [None], "commercial_acc": [None],
}
CARS = sorted(acc_presets())


@st.composite
def degradations(draw: st.DrawFn, n_followers: int) -> dict[str, Any]:
    kind = draw(st.sampled_from(sorted(EXTREME_SIZES)))
    description: dict[str, Any] = {"kind": kind}
    size = draw(st.sampled_from(EXTREME_SIZES[kind]))
    if size is not None:
        description["size"] = size
    if draw(st.booleans()):
        description["followers"] = sorted(draw(st.sets(st.integers(1, n_followers), min_size=1)))
    onset = draw(st.sampled_from([0.0, 0.0, 0.1, 1.0, 2.5, 100.0, 1e6]))
    if kind != "commercial_acc" or onset:
        description["onset"] = onset
    end = draw(st.sampled_from([None, None, 0.1, 1.0, 1e6]))
    if end is not None and end > onset:
        description["end"] = end
    if kind == "commercial_acc" and draw(st.booleans()):
        description["car"] = draw(st.sampled_from(CARS))
    return description


def leader_speeds(rng: np.random.Generator, kind: str) -> np.ndarray:
    """A leader speed series [m/s] within [0, MAX_SPEED], ``kind`` its shape."""
    n = int(rng.integers(2, 4000))
    if kind == "standstill":
        return np.zeros(n)
    if kind == "fastest":
        return np.full(n, MAX_SPEED)
    if kind == "ramp":
        return np.linspace(0.0, MAX_SPEED, n)
    if kind == "jumps":  # every sample anywhere in [0, MAX_SPEED]: accelerations of hundreds of m/s^2
        return rng.uniform(0.0, MAX_SPEED, n)
    if kind == "stop and go":
        return np.where((np.arange(n) // 50) % 2 == 0, 0.0, 30.0)
    return np.clip(25.0 + np.cumsum(rng.normal(0.0, 0.3, n)), 0.0, MAX_SPEED)  # a random walk


LEADER_KINDS = ["standstill", "fastest", "ramp", "jumps", "stop and go", "walk"]


@st.composite
def reset_options(draw: st.DrawFn, n_followers: int) -> dict[str, Any] | None:
    """Options of one reset: none, a scenario, the user's leader, a pinned degradation, or some of them."""
    options: dict[str, Any] = {}
    leader = draw(st.sampled_from(["drawn", "drawn", "scenario", "scenario", "speed"]))
    if leader == "scenario":
        options["scenario"] = draw(st.sampled_from(FAMILIES))
    elif leader == "speed":
        options["leader_speed"] = ("speed", draw(st.sampled_from(LEADER_KINDS)), draw(st.integers(0, 2**16)))
    pinned = draw(st.sampled_from(["drawn", "drawn", "one", "several", "none"]))
    if pinned == "one":
        options["degradation"] = draw(degradations(n_followers))
    elif pinned == "several":
        first_ = draw(degradations(n_followers))
        first_["followers"] = [1]
        options["degradation"] = [first_, {**draw(degradations(n_followers)), "followers": list(range(2, n_followers + 1))}] \
            if n_followers > 1 else [first_]
    elif pinned == "none":
        options["degradation"] = None
    return options or None


def materialise(options: dict[str, Any] | None) -> dict[str, Any] | None:
    """Options with the leader speed series built (hypothesis draws its shape and seed, not the array)."""
    if options is None or "leader_speed" not in options:
        return options
    _, kind, seed = options["leader_speed"]
    return {**options, "leader_speed": leader_speeds(np.random.default_rng(seed), kind)}


def random_action(space: gym.Space, rng: np.random.Generator) -> Any:
    if isinstance(space, gym.spaces.Discrete):
        return int(rng.integers(space.n))
    return rng.integers(0, space.nvec)


def refused_by_name(error: BaseException, options: dict[str, Any] | None) -> bool:
    """A reset refused with a ValueError that names the option at fault."""
    return isinstance(error, ValueError) and any(key in str(error) for key in (options or {}))


# ----------------------------------------------------------------------------------------------- single env

def run_single(config: dict[str, Any], seed: int, episodes: list[dict[str, Any] | None], steps: int,
               defects: Defects, case: str, digest: Digest | None = None) -> dict[str, int]:
    """``steps`` random-action steps of one single env, resetting with the next of ``episodes``' options when an
    episode ends; every output checked. Returns counts of steps, episodes and refused resets."""
    counts = {"steps": 0, "episodes": 0, "refused_resets": 0}
    env = gym.make(ENV_ID, config=config, truth_info=True)  # the true state's keys are checked for NaN too
    rng = np.random.default_rng(seed)
    space = env.observation_space
    k = 0

    def reset() -> bool:
        nonlocal k
        options = materialise(episodes[k % len(episodes)])
        k += 1
        result, error = call(lambda: env.reset(seed=seed + k, options=options))
        if error is not None:
            if refused_by_name(error, options):
                counts["refused_resets"] += 1
                defects.note(f"reset refused: {error}")
                result = env.reset(seed=seed + k)
            else:
                defects.exception("reset", error, f"{case}, options {short(episodes[(k - 1) % len(episodes)])}")
                return False
        counts["episodes"] += 1
        obs, info = result
        for problem in bad_step(space, obs) + bad_values(info):
            defects.add("bad reset output", problem, f"{case}, options {short(episodes[(k - 1) % len(episodes)])}")
        if digest is not None:
            digest.add(obs, info)
        return True

    if not reset():
        return counts
    for _ in range(steps):
        action = random_action(env.action_space, rng)
        result, error = call(lambda: env.step(action))
        if error is not None:
            defects.exception("step", error, f"{case}, options {short(episodes[(k - 1) % len(episodes)])}")
            return counts
        obs, reward, terminated, truncated, info = result
        counts["steps"] += 1
        problems = bad_step(space, obs, reward) + bad_values(info)
        for problem in problems:
            defects.add("bad step output", problem, f"{case}, options {short(episodes[(k - 1) % len(episodes)])}")
        if digest is not None:
            digest.add(obs, np.float64(reward), terminated, truncated, info)
        if terminated or truncated:
            if not reset():
                return counts
    return counts


def fuzz_single(name: str, max_examples: int, steps: int, area: str, rerun_every: int) -> None:
    """``max_examples`` runs of config ``name``, each with its own seed and reset options (hypothesis)."""
    defects = Defects(area)
    totals = {"steps": 0, "episodes": 0, "refused_resets": 0, "reruns_same_bits": 0}
    config = CONFIGS[name]
    skip_without_data(config)
    n_followers = EnvConfig.from_dict(config).platoon.n_followers

    @fuzz_settings(max_examples)
    @given(seed=st.integers(0, 2**20), episodes=st.lists(reset_options(n_followers), min_size=1, max_size=4))
    def example(seed: int, episodes: list[dict[str, Any] | None]) -> None:
        case = f"config {name!r}, seed {seed}"
        defects.case("run")
        digest = Digest()
        counts = run_single(config, seed, episodes, steps, defects, case, digest)
        for key, value in counts.items():
            totals[key] += value
        if defects.cases % rerun_every == 1:  # the same seeds again: the same bits
            again = Digest()
            run_single(config, seed, episodes, steps, Defects("rerun"), case, again)
            totals["reruns_same_bits"] += 1
            if again.hexdigest() != digest.hexdigest():
                defects.add("different bits for the same seeds", "a rerun in the same process differs",
                            f"{case}, episodes {short(episodes)}")

    example()
    defects.check(totals)


@pytest.mark.parametrize("name", CONFIG_NAMES)
def test_fuzz_single_env_steps(name):
    """Two runs of 110 random-action steps per config (about 5,000 steps over all), the first run twice."""
    fuzz_single(name, max_examples=2, steps=110, area="steps/single env", rerun_every=2)


@pytest.mark.slow
@pytest.mark.parametrize("name", CONFIG_NAMES)
def test_fuzz_single_env_steps_long(name):
    """10^6 single-env steps over all configs: 22 runs of 2,000 steps per config."""
    fuzz_single(name, max_examples=22, steps=2000, area="steps/single env (10^6)", rerun_every=11)


# ----------------------------------------------------------------------------------------------- vector env

def run_vector(config: dict[str, Any], num_envs: int, autoreset_mode: str, seed: int,
               options: dict[str, Any] | None, steps: int, defects: Defects, case: str) -> dict[str, int]:
    """``steps`` random-action steps of a native vector env; with autoresets disabled, the ended sub-envs (and a
    few others) are reset through ``reset_mask``. Every output checked."""
    counts = {"env_steps": 0, "episodes_ended": 0, "masked_resets": 0}
    envs = gym.make_vec(ENV_ID, num_envs=num_envs, vectorization_mode="vector_entry_point", config=config,
                        autoreset_mode=autoreset_mode, truth_info=True)
    rng = np.random.default_rng(seed)
    result, error = call(lambda: envs.reset(seed=seed, options=materialise(options)))
    if error is not None:
        if not refused_by_name(error, options):
            defects.exception("vector reset", error, f"{case}, options {short(options)}")
            return counts
        defects.note(f"reset refused: {error}")
        result = envs.reset(seed=seed)
    obs, info = result
    for problem in bad_step(envs.observation_space, obs) + bad_values(info):
        defects.add("bad vector reset output", problem, case)
    ended = np.zeros(num_envs, dtype=bool)
    for _ in range(steps):
        if autoreset_mode == "disabled" and ended.any():
            mask = ended | (rng.random(num_envs) < 0.1)
            result, error = call(lambda: envs.reset(options={"reset_mask": mask}))
            if error is not None:
                defects.exception("vector masked reset", error, case)
                return counts
            counts["masked_resets"] += 1
            for problem in bad_step(envs.observation_space, result[0]) + bad_values(result[1]):
                defects.add("bad vector masked reset output", problem, case)
            ended[:] = False
        actions = np.stack([np.asarray(random_action(envs.single_action_space, rng)) for _ in range(num_envs)])
        result, error = call(lambda: envs.step(actions))
        if error is not None:
            defects.exception("vector step", error, case)
            return counts
        obs, reward, terminated, truncated, info = result
        counts["env_steps"] += num_envs
        ended = terminated | truncated
        counts["episodes_ended"] += int(ended.sum())
        for problem in bad_step(envs.observation_space, obs, reward) + bad_values(info):
            defects.add("bad vector step output", problem, case)
    return counts


def fuzz_vector(name: str, autoreset_mode: str, max_examples: int, num_envs: int, steps: int, area: str) -> None:
    defects = Defects(area)
    totals = {"env_steps": 0, "episodes_ended": 0, "masked_resets": 0}
    config = CONFIGS[name]
    skip_without_data(config)

    @fuzz_settings(max_examples)
    @given(seed=st.integers(0, 2**20), options=reset_options(EnvConfig.from_dict(config).platoon.n_followers))
    def example(seed: int, options: dict[str, Any] | None) -> None:
        defects.case(autoreset_mode)
        counts = run_vector(config, num_envs, autoreset_mode, seed, options, steps, defects,
                            f"config {name!r}, {autoreset_mode}, seed {seed}, {num_envs} envs")
        for key, value in counts.items():
            totals[key] += value

    example()
    defects.check(totals)


AUTORESET_MODES = ("same_step", "next_step", "disabled")
VECTOR_CASES = [(name, AUTORESET_MODES[i % 3]) for i, name in enumerate(CONFIG_NAMES)]  # each config, modes in turn


@pytest.mark.parametrize("name, autoreset_mode", VECTOR_CASES[::2])
def test_fuzz_vector_env_steps(name, autoreset_mode):
    """About 5,000 env-steps of the native vector env (16 sub-envs, 25 steps) over half the configs."""
    fuzz_vector(name, autoreset_mode, max_examples=1, num_envs=16, steps=25, area="steps/vector env")


@pytest.mark.slow
@pytest.mark.parametrize("name, autoreset_mode", VECTOR_CASES)
def test_fuzz_vector_env_steps_long(name, autoreset_mode):
    """10^6 env-steps of the native vector env over all configs: 256 sub-envs x 170 steps per config."""
    fuzz_vector(name, autoreset_mode, max_examples=1, num_envs=256, steps=170, area="steps/vector env (10^6)")


# ----------------------------------------------------------------------------------------------- vector = sync

def compare_with_sync(config: dict[str, Any], num_envs: int, autoreset_mode: str, seed: int,
                      options: dict[str, Any] | None, steps: int, defects: Defects, case: str) -> int:
    """The native vector env against SyncVectorEnv over single envs, step by step; returns the steps compared."""
    native = gym.make_vec(ENV_ID, num_envs=num_envs, vectorization_mode="vector_entry_point", config=config,
                          autoreset_mode=autoreset_mode, truth_info=True)
    reference = SyncVectorEnv([lambda: gym.make(ENV_ID, config=config, truth_info=True) for _ in range(num_envs)],
                              autoreset_mode=parse_autoreset_mode(autoreset_mode))
    options = materialise(options)
    got, error = call(lambda: native.reset(seed=seed, options=options))
    want, error_reference = call(lambda: reference.reset(seed=seed, options=options))
    if (error is None) != (error_reference is None):
        defects.add("vector and sync disagree on a reset", f"native: {error!r}; sync: {error_reference!r}", case)
        return 0
    if error is not None:
        got, want = native.reset(seed=seed), reference.reset(seed=seed)
    rng = np.random.default_rng(seed)

    def differences(a: tuple, b: tuple, where: str) -> None:
        problems = [f"{where}: {name} differ" for name, x, y in zip(("obs", "reward", "terminated", "truncated"),
                                                                     a[:-1], b[:-1])
                    if not np.array_equal(np.asarray(x), np.asarray(y))]
        problems += same_infos(a[-1], b[-1], where)
        if problems:
            defects.add("native vector env differs from SyncVectorEnv", first(problems), f"{case}, {where}")

    differences(got, want, "reset")
    ended = np.zeros(num_envs, dtype=bool)
    for step in range(steps):
        if autoreset_mode == "disabled" and ended.any():
            mask = ended | (rng.random(num_envs) < 0.2)
            got = native.reset(options={"reset_mask": mask.copy()})
            want = reference.reset(options={"reset_mask": mask.copy()})
            differences(got, want, f"masked reset before step {step}")
            ended[:] = False
        actions = np.stack([np.asarray(random_action(native.single_action_space, rng)) for _ in range(num_envs)])
        got, error = call(lambda: native.step(actions))
        want, error_reference = call(lambda: reference.step(actions))
        if error is not None or error_reference is not None:
            defects.add("vector or sync step raised", f"native: {error!r}; sync: {error_reference!r}", case)
            return step
        differences(got, want, f"step {step}")
        ended = got[2] | got[3]
    return steps


def fuzz_sync(name: str, autoreset_mode: str, max_examples: int, steps: int, area: str) -> None:
    skip_without_data(CONFIGS[name])
    defects = Defects(area)
    totals = {"steps_compared": 0}

    @fuzz_settings(max_examples)
    @given(seed=st.integers(0, 2**20), num_envs=st.integers(1, 4), duration=st.sampled_from([2.0, 3.0, 5.0, 8.0]),
           data=st.data())
    def example(seed: int, num_envs: int, duration: float, data: st.DataObject) -> None:
        config = {**CONFIGS[name], "episode_duration": 5.0 if name.startswith("dt 1") else duration}
        if config.get("decision_interval", 1.0) > 1.0:
            config["decision_interval"] = 1.0
        options = data.draw(reset_options(EnvConfig.from_dict(config).platoon.n_followers))
        defects.case(autoreset_mode)
        totals["steps_compared"] += compare_with_sync(
            config, num_envs, autoreset_mode, seed, options, steps, defects,
            f"config {name!r} + {config['episode_duration']} s episodes, {num_envs} envs, {autoreset_mode}, "
            f"seed {seed}, options {short(options, 200)}")

    example()
    defects.check(totals)


SYNC_CASES = [(name, AUTORESET_MODES[i % 3]) for i, name in enumerate(
    n for n in CONFIG_NAMES if "20 followers" not in n and "no window" not in n)]


@pytest.mark.parametrize("name, autoreset_mode", SYNC_CASES)
def test_fuzz_vector_env_equals_sync_vector_env(name, autoreset_mode):
    """Short episodes (many autoresets), options at reset, masked resets when autoresets are disabled."""
    fuzz_sync(name, autoreset_mode, max_examples=1, steps=16, area="steps/vector = sync")


@pytest.mark.slow
@pytest.mark.parametrize("autoreset_mode", AUTORESET_MODES)
@pytest.mark.parametrize("name", [name for name, _ in SYNC_CASES])
def test_fuzz_vector_env_equals_sync_vector_env_long(name, autoreset_mode):
    fuzz_sync(name, autoreset_mode, max_examples=8, steps=40, area="steps/vector = sync (long)")


# ----------------------------------------------------------------------------------------------- same bits

def digest_of_run(name: str, seed: int, steps: int) -> str:
    """The digest of a fixed run (config ``name``, its reset options drawn from ``seed``): for the cross-process
    comparison."""
    rng = np.random.default_rng(seed)
    episodes = [None, {"scenario": FAMILIES[int(rng.integers(len(FAMILIES)))]},
                {"leader_speed": ("speed", LEADER_KINDS[int(rng.integers(len(LEADER_KINDS)))], seed)},
                {"degradation": {"kind": "lag", "size": 2.0, "onset": 1.0}}]
    digest = Digest()
    defects = Defects("digest")
    skip_without_data(CONFIGS[name])
    run_single(CONFIGS[name], seed, episodes, steps, defects, name, digest)
    assert not defects.groups, defects.report()
    return digest.hexdigest()


SAME_BITS = [("default", 1), ("2.5 s episodes, every family", 2), ("per_vehicle, 3 followers", 3),
             ("V2V at its worst", 4), ("dropouts 90-99 %", 5)]


def test_same_seeds_same_bits_in_one_process():
    for name, seed in SAME_BITS:
        assert digest_of_run(name, seed, 120) == digest_of_run(name, seed, 120), name


@pytest.mark.slow
def test_same_seeds_same_bits_across_processes():
    """Another Python process (its own hash seed) gives the same bits."""
    script = ("import json, sys; from tests.fuzz.test_fuzz_steps import SAME_BITS, digest_of_run; "
              "print(json.dumps([digest_of_run(name, seed, 300) for name, seed in SAME_BITS]))")
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True,
                         env={**os.environ, "PYTHONHASHSEED": "12345"})
    theirs = json.loads(out.stdout.strip().splitlines()[-1])
    ours = [digest_of_run(name, seed, 300) for name, seed in SAME_BITS]
    assert theirs == ours
