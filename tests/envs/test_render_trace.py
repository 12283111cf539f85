"""The render trace stays bounded over a long episode (issue 22, item 10), late frames show what the whole trace
would show, the evaluation profile still gets the whole episode, and the committed frame is what the script draws."""

from __future__ import annotations

import tracemalloc
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import timegap_env
from timegap_env.agents.policies import PaperRulePolicy
from timegap_env.envs.rendering import DEFAULT_TIME_WINDOW
from timegap_env.envs.task import Trace, TraceArrays
from timegap_env.agents.protocol import EVAL_SEED_START
from timegap_env.studies import heldout

LONG = {"episode_duration": 5000.0, "degradation": {"kind_weights": {"none": 1.0}}}  # [s]
DT = 0.1  # [s], the default tick
WINDOW_TICKS = round(DEFAULT_TIME_WINDOW / DT) + 1  # ticks of [now - window, now], both ends included
REPO = Path(__file__).resolve().parents[2]


def long_env() -> gym.Env:
    env = gym.make(timegap_env.ENV_ID, render_mode="rgb_array", config=LONG)
    env.reset(seed=3)
    return env


def action(step: int) -> int:
    """A setting that changes now and then, so the centre lines in the trace move."""
    return (5, 2, 7)[(step // 37) % 3]


def test_the_render_trace_holds_only_the_last_window():
    env = long_env()
    trace = env.unwrapped.task.trace
    held = []
    for step in range(400):
        env.step(action(step))
        if step + 1 in (100, 250, 400):
            held.append(trace.arrays().t.size)
    assert held == [WINDOW_TICKS] * 3  # was 1000, 2500, 4000: every tick since reset
    assert trace.n_ticks == WINDOW_TICKS


def test_the_render_trace_memory_does_not_grow_with_the_episode():
    """Once the window is full, stepping on allocates nothing that stays (was 2.8 KB per step)."""
    env = long_env()
    tracemalloc.start()
    try:
        # the trace's blocks are then all allocated under tracemalloc, and Python's free lists (tuples the step
        # drops, about 100 kB) full
        for step in range(2500):
            env.step(action(step))
        before = tracemalloc.get_traced_memory()[0]
        for step in range(2500, 3500):
            env.step(action(step))
        grown = tracemalloc.get_traced_memory()[0] - before
    finally:
        tracemalloc.stop()
    assert grown < 20_000, f"{grown} B after 1000 more steps"  # at 2.8 KB/step: 2.8 MB


def test_late_frames_show_what_the_whole_trace_shows():
    bounded, whole = long_env(), long_env()
    everything = whole.unwrapped.task.start_trace(keep=None)
    for step in range(300):
        bounded.step(action(step))
        whole.step(action(step))
    assert everything.n_ticks == 3000
    frame, reference = (env.unwrapped.task.render_frame(DEFAULT_TIME_WINDOW) for env in (bounded, whole))
    for name in ("history_t", "estimate_history", "lcl_history", "center_history", "ucl_history", "settling"):
        np.testing.assert_array_equal(getattr(frame, name), getattr(reference, name), err_msg=name)
    assert frame.history_t[0] == pytest.approx(300.0 - DEFAULT_TIME_WINDOW) and frame.history_t[-1] == 300.0
    np.testing.assert_array_equal(bounded.render(), whole.render())


def test_a_reset_empties_the_bounded_trace():
    env = long_env()
    for step in range(70):
        env.step(action(step))
    env.reset(seed=4)
    assert env.unwrapped.task.trace.n_ticks == 0
    env.step(5)
    assert env.unwrapped.task.trace.arrays().t.size == 10


def test_a_trace_keeps_exactly_the_last_keep_seconds():
    trace = Trace(2, keep=1.0)
    for block in range(5):  # ticks 1 .. 50, t = 0.1 .. 5.0 s
        t = (np.arange(10) + 10 * block + 1) * 0.1
        trace.add(TraceArrays(t, np.c_[t, -t], np.ones((10, 2))))
    arrays = trace.arrays()
    np.testing.assert_array_equal(arrays.t, (np.arange(40, 51)) * 0.1)  # [4.0, 5.0] s
    np.testing.assert_array_equal(arrays.estimate[:, 1], -arrays.t)
    everything = Trace(2, keep=None)
    for block in range(5):
        t = (np.arange(10) + 10 * block + 1) * 0.1
        everything.add(TraceArrays(t, np.zeros((10, 2)), np.zeros((10, 2))))
    assert everything.n_ticks == 50
    for bad in (-1.0, np.inf, np.nan):
        with pytest.raises(ValueError, match="keep"):
            Trace(2, keep=bad)


def test_a_trace_copies_what_it_is_given():
    """It holds its own arrays: a view into a step's (n_ticks, n_envs, n_followers) block would change with the
    block, and keep all n_envs of it alive."""
    block = np.zeros((10, 64, 2))
    trace = Trace(2)
    trace.add(TraceArrays(np.arange(1, 11) * 0.1, block[:, 0], block[:, 0]))
    block[:] = 1.0
    assert trace.arrays().estimate.max() == 0.0


def test_a_frame_cannot_ask_for_more_history_than_the_trace_keeps():
    env = long_env()
    env.step(5)
    with pytest.raises(ValueError, match="keeps only the last 60.0 s"):
        env.unwrapped.task.render_frame(history=2 * DEFAULT_TIME_WINDOW)


def test_the_evaluation_profile_keeps_the_whole_episode():
    """``train.evaluate`` traces env 0's whole episode (250 s), not the last rendered window."""
    _, _, profile = heldout.run_batch(PaperRulePolicy(), "training_mix", [EVAL_SEED_START], True)
    episode = timegap_env.EnvConfig().episode_duration
    assert profile.t.size == round(episode / DT) and profile.t[0] == pytest.approx(DT)
    assert profile.t[-1] == pytest.approx(episode)


def test_the_committed_frame_is_what_the_script_draws(tmp_path, monkeypatch):
    """``python -m train.render_frame`` gives results/env_frame.png bit for bit (it was stale since a change of the
    episode draw): refresh the picture when a change alters it."""
    import sys

    from train import render_frame

    out = tmp_path / "frame.png"
    monkeypatch.setattr(sys, "argv", ["render_frame", "--out", str(out)])
    render_frame.main()
    assert out.read_bytes() == (REPO / "results" / "env_frame.png").read_bytes()
