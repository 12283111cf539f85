"""Issue 22: bad input to the env and the vector env is refused by name, and a reset that raises leaves nothing
half done that could step on."""

import tracemalloc

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.error import ResetNeeded

import timegap_env  # noqa: F401
from timegap_env.config import EnvConfig
from timegap_env.envs.task import PlatoonTask
from timegap_env.envs.vector_env import TimeGapMonitorVectorEnv, check_fits

# A degradation its own description accepts but the platoon does not (latency beyond platoon.max_v2v_latency): the
# reset raises after it has drawn the leaders.
TOO_LATE = {"kind": "v2v_latency", "size": 5.0}


def vector(n=3, **kwargs):
    return gym.make_vec("TimeGapMonitor-v0", num_envs=n, vectorization_mode="vector_entry_point", **kwargs)


def test_a_vector_reset_that_raises_leaves_its_sub_envs_refusing_to_step():
    envs = vector()
    envs.reset(seed=0)
    envs.step(np.zeros(3, dtype=np.int64))
    mask = np.array([True, False, True])
    with pytest.raises(ValueError, match="v2v_latency"):
        envs.reset(options={"degradation": TOO_LATE, "reset_mask": mask})
    assert list(envs.unwrapped.scenario[mask]) == ["", ""]  # they name no episode
    with pytest.raises(ResetNeeded, match=r"sub-envs \[0, 2\] are half reset"):
        envs.step(np.zeros(3, dtype=np.int64))
    envs.reset(options={"reset_mask": mask})
    envs.step(np.zeros(3, dtype=np.int64))


def test_a_first_vector_reset_that_raises_leaves_the_env_unstepped():
    envs = vector()
    with pytest.raises(ValueError, match="v2v_latency"):
        envs.reset(seed=0, options={"degradation": TOO_LATE})
    with pytest.raises(ResetNeeded):
        envs.step(np.zeros(3, dtype=np.int64))


@pytest.mark.parametrize("autoreset_mode", ["same_step", "next_step"])
def test_an_autoreset_that_raises_leaves_the_sub_env_refusing_to_step(autoreset_mode):
    envs = vector(2, config={"episode_duration": 2.0}, autoreset_mode=autoreset_mode)
    envs.reset(seed=0)
    task = envs.unwrapped.task

    def failing_draw(*args, **kwargs):
        raise RuntimeError("a leader that cannot be built")

    task.episodes.draw_many = failing_draw
    with pytest.raises(RuntimeError, match="cannot be built"):
        for _ in range(4):
            envs.step(np.zeros(2, dtype=np.int64))
    with pytest.raises(ResetNeeded, match="half reset"):
        envs.step(np.zeros(2, dtype=np.int64))


def test_a_single_reset_that_raises_names_no_episode_and_refuses_to_step():
    env = gym.make("TimeGapMonitor-v0")
    env.reset(seed=0)
    with pytest.raises(ValueError, match="v2v_latency"):
        env.reset(options={"degradation": TOO_LATE})
    assert env.unwrapped.scenario == ""
    with pytest.raises(ResetNeeded):
        env.step(0)


@pytest.mark.parametrize(
    "degradation, field",
    [
        ({"kind": "lag", "size": 1e200}, "size"),
        ({"kind": "gain", "size": 1e300}, "size"),
        ({"kind": "gain", "size": 11.0}, "size"),
        ({"kind": "radar_bias", "size": -1e9}, "size"),
        ({"kind": "radar_noise", "size": 1e9}, "size"),
        ({"kind": "v2v_latency", "size": 50.0}, "size"),
        ({"kind": "lag", "size": 10**400}, "size"),
        ({"kind": "lag", "size": 2.0, "onset": 1e300}, "onset"),
        ({"kind": "lag", "size": 2.0, "onset": 10**400}, "onset"),
        ({"kind": "lag", "size": 2.0, "onset": 1.0, "end": 1e300}, "end"),
        ({"kind": "lag", "size": "2"}, "size"),
        ({"kind": ["lag"], "size": 2.0}, "kind"),
        ({"kind": "v2v_outage", "car": 3}, "car"),
        ({1: "lag", "kind": "lag", "size": 2.0}, "keys"),
    ],
)
def test_pinned_degradations_are_bounded_and_named(degradation, field):
    env = gym.make("TimeGapMonitor-v0")
    with pytest.raises(ValueError, match=f"degradation {field}"):
        env.reset(seed=0, options={"degradation": degradation})


def test_a_pinned_degradation_of_numpy_numbers_runs_as_pythons():
    env = gym.make("TimeGapMonitor-v0")
    runs = []
    for degradation in ({"kind": "gain", "size": np.float32(0.75), "followers": [np.int64(1)], "onset": np.int64(3)},
                        {"kind": "gain", "size": 0.75, "followers": [1], "onset": 3.0}):
        env.reset(seed=1, options={"degradation": degradation})
        runs.append([env.step(2)[0] for _ in range(8)])
    assert all(np.array_equal(a, b) for a, b in zip(*runs))


@pytest.mark.parametrize(
    "options, message",
    [
        ({"scenario": ["paper"]}, r"reset option scenario = \['paper'\]"),
        ({"scenario": ""}, r"reset option scenario = ''"),
        ({"scenario": "nonsense"}, r"reset option scenario = 'nonsense'"),
        ({"scenario": 3}, r"reset option scenario = 3"),
        ({"leader_speed": {"a": 1}}, r"reset option leader_speed = \{'a': 1\}"),
        ({"leader_speed": "fast"}, r"reset option leader_speed = 'fast'"),
        ({"leader_speed": np.ones(30) * 20, "scenario": "paper"}, r"scenario and leader_speed"),
        ({("scenario",): "paper"}, r"reset options \[\('scenario',\)\] unknown"),
        ({1: 2, "x": 3}, r"reset options \['x', 1\] unknown"),
    ],
)
def test_bad_reset_options_are_named(options, message):
    for env in (gym.make("TimeGapMonitor-v0"), vector(2)):
        with pytest.raises(ValueError, match=message):
            env.reset(seed=0, options=options)


def test_options_that_are_not_a_dict_are_named():
    with pytest.raises(ValueError, match=r"reset options = \['paper'\]"):
        gym.make("TimeGapMonitor-v0").reset(seed=0, options=["paper"])


def test_a_scenario_of_none_is_drawn():
    env = gym.make("TimeGapMonitor-v0")
    drawn, _ = env.reset(seed=4)
    named, _ = env.reset(seed=4, options={"scenario": None})
    assert np.array_equal(drawn, named)


def test_bools_are_actions_as_the_space_says():
    env = gym.make("TimeGapMonitor-v0")
    assert env.action_space.contains(True)
    results = []
    for action in (True, 1):
        env.reset(seed=0)
        results.append(env.step(action))
    assert np.array_equal(results[0][0], results[1][0]) and results[0][1] == results[1][1]
    envs = vector(2, config={"action_mode": "per_vehicle"})
    envs.reset(seed=0)
    assert envs.action_space.contains(np.ones((2, 5), dtype=bool))
    envs.step(np.ones((2, 5), dtype=bool))


def test_num_envs_that_cannot_fit_is_refused_by_name():
    with pytest.raises(ValueError, match=r"num_envs = 1000000000000000000000000000000: .* GB"):
        vector(10**30)
    with pytest.raises(ValueError, match=r"num_envs = 100000: the sub-envs' state needs about 6\.\d+ GB .* more than the "
                                         r"1 GB of memory available"):
        check_fits(100_000, 63_000, 10**9)
    check_fits(100_000, 63_000, None)  # unknown memory: nothing refused
    check_fits(10, 63_000, 10**9)


def test_bytes_per_env_is_what_sub_envs_take():
    """The estimate against what tracemalloc sees the state of 400 more sub-envs take (reset and a step included)."""
    config = {"episode_duration": 100.0, "platoon": {"n_followers": 3}}
    per_env = PlatoonTask.bytes_per_env(EnvConfig.from_dict(config))
    taken = []
    for n in (100, 500):
        tracemalloc.start()
        envs = TimeGapMonitorVectorEnv(n, config=config)
        envs.reset(seed=0)
        envs.step(np.zeros(n, dtype=np.int64))
        taken.append(tracemalloc.get_traced_memory()[0])
        tracemalloc.stop()
        del envs
    measured = (taken[1] - taken[0]) / 400
    assert 0.8 < per_env / measured < 1.25, (per_env, measured)


@pytest.mark.parametrize("speed", [np.full(50, 1000.0), np.full(30, np.nan), np.ones((3, 3)), np.array([20.0])])
def test_a_leader_speed_the_profile_refuses_is_named_as_the_option(speed):
    with pytest.raises(ValueError, match="reset option leader_speed: "):
        gym.make("TimeGapMonitor-v0").reset(seed=0, options={"leader_speed": speed})
