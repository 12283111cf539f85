"""The task as the env and scripts read it: step results, fingerprints, the trace and the render frame."""

import gymnasium as gym
import numpy as np

import timegap_env
from timegap_env.config import EnvConfig
from timegap_env.envs.reward import REWARD_TERMS
from timegap_env.envs.task import PlatoonTask


def reset_task(config: EnvConfig, n_envs: int, seed: int) -> PlatoonTask:
    task = PlatoonTask(config, n_envs)
    task.reset(np.ones(n_envs, dtype=bool), [np.random.default_rng(seed + i) for i in range(n_envs)], None)
    return task


def test_a_step_returns_every_reward_term_per_env():
    task = reset_task(EnvConfig(), 3, seed=0)
    result = task.step(np.array([2, 5, 8]))
    assert list(result.terms) == list(REWARD_TERMS)
    assert all(term.shape == (3,) and np.all(term <= 0) for term in result.terms.values())
    assert result.reward.shape == result.terminated.shape == result.truncated.shape == (3,)


def test_fingerprints_tell_episodes_apart_whatever_the_action_mode():
    platoon = reset_task(EnvConfig(), 2, seed=4)
    per_vehicle = reset_task(EnvConfig.from_dict({"action_mode": "per_vehicle"}), 2, seed=4)
    assert [platoon.fingerprint(e) for e in range(2)] == [per_vehicle.fingerprint(e) for e in range(2)]
    assert platoon.fingerprint(0) != platoon.fingerprint(1)


def test_the_trace_records_env_0_at_every_tick():
    task = reset_task(EnvConfig(), 2, seed=1)
    trace = task.start_trace()
    for action in (5, 5, 2):
        task.step(np.array([action, action]))
    arrays = trace.arrays()
    np.testing.assert_allclose(arrays.t, np.arange(1, 31) * 0.1)
    assert arrays.estimate.shape == arrays.center.shape == (30, 5)
    np.testing.assert_allclose(arrays.center[19], 1.6)  # the centre line ramps towards 1.0 s after the third action
    assert 1.0 < arrays.center[-1, 0] < 1.6
    trace.clear()
    assert trace.arrays().t.size == 0 and trace.arrays().estimate.shape == (0, 5)


def test_the_render_frame_shows_the_last_history_seconds_with_the_limits_of_their_time():
    env = gym.make(timegap_env.ENV_ID, render_mode="rgb_array")
    env.reset(seed=0)
    for step in range(80):
        env.step(5 if step < 70 else 2)
    frame = env.unwrapped.task.render_frame(history=60.0)
    assert frame.t == 80.0 and frame.history_t[0] >= 20.0 and frame.history_t[-1] == 80.0
    assert frame.estimate_history.shape == frame.center_history.shape == (frame.history_t.size, 5)
    np.testing.assert_allclose(frame.ucl_history - frame.lcl_history, 0.5)
    assert frame.center_history[0, 0] == 1.6 and frame.center_history[-1, 0] < 1.6  # ramping to 1.0 s
    bare = reset_task(EnvConfig(), 1, seed=0).render_frame(history=60.0)  # no trace: no history
    assert bare.history_t.size == 0 and bare.estimate_history.shape == (0, 5)
