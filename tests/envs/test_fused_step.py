"""The fused step (one compiled call per step) against the staged reference path, bit for bit.

Two native vector envs run the same seeds and actions, one fused (the default) and one staged
(``task.fused = False``); every observation, reward, flag and info must be the same bytes, over
episodes that cover every degradation kind, same-step and next-step autoresets, the three action
modes, the three charts, a monitor without a window and a platoon without V2V.
"""

from __future__ import annotations

import numpy as np
import pytest

from timegap_env.envs.vector_env import TimeGapMonitorVectorEnv
from timegap_env.sim.degradation import KINDS

ALL_KINDS = {"degradation": {"kind_weights": {kind: 1.0 for kind in KINDS}, "midway_onset_probability": 0.5,
                             "recovery_probability": 0.5}}
SHORT = {"episode_duration": 40.0, "scenario_weights": {"hard_braking": 1.0, "aggressive_cycles": 1.0,
                                                        "stochastic_human": 1.0}}


def same_bytes(fused: object, staged: object, where: str) -> None:
    """Equal values of equal dtypes, compared as bytes (so -0.0 differs from 0.0 and NaN equals NaN)."""
    if isinstance(fused, dict):
        assert fused.keys() == staged.keys(), where
        for key in fused:
            same_bytes(fused[key], staged[key], f"{where}[{key!r}]")
        return
    fused, staged = np.asarray(fused), np.asarray(staged)
    assert fused.dtype == staged.dtype and fused.shape == staged.shape, where
    if fused.dtype == object:
        for i, (a, b) in enumerate(zip(fused.ravel(), staged.ravel())):
            assert (a is None) == (b is None), f"{where}[{i}]"
            if a is not None:
                same_bytes(a, b, f"{where}[{i}]")
        return
    assert fused.tobytes() == staged.tobytes(), where


def run_both(config: dict, n_steps: int, autoreset_mode: str = "same_step", n_envs: int = 4, seed: int = 7) -> int:
    """Step a fused and a staged vector env alike and compare everything they return; the number of episodes ended."""
    envs = {fused: TimeGapMonitorVectorEnv(n_envs, config=config, autoreset_mode=autoreset_mode) for fused in (True, False)}
    envs[False].task.fused = False
    outputs = {fused: env.reset(seed=seed) for fused, env in envs.items()}
    same_bytes(outputs[True][0], outputs[False][0], "reset observation")
    same_bytes(outputs[True][1], outputs[False][1], "reset info")
    actions = envs[True].action_space
    actions.seed(seed)
    ended = 0
    for step in range(n_steps):
        action = actions.sample()
        outputs = {fused: env.step(action) for fused, env in envs.items()}
        for name, fused_part, staged_part in zip(("observation", "reward", "terminated", "truncated", "info"),
                                                 outputs[True], outputs[False]):
            same_bytes(fused_part, staged_part, f"step {step} {name}")
        ended += int(np.sum(outputs[True][2] | outputs[True][3]))
    return ended


@pytest.mark.parametrize("autoreset_mode", ["same_step", "next_step"])
def test_fused_equals_staged_over_every_degradation_kind(autoreset_mode: str) -> None:
    assert run_both({**ALL_KINDS, **SHORT}, 130, autoreset_mode, n_envs=8) >= 16


@pytest.mark.parametrize("overrides", [
    {"action_mode": "per_vehicle"},
    {"action_mode": "relative"},
    {"chart": {"kind": "ewma"}},
    {"chart": {"kind": "cusum"}},
    {"monitor": {"window": None, "forgetting": 0.99}},
    {"platoon": {"v2v": False, "n_followers": 3}},
    {"random_initial_setting": True, "decision_interval": 0.5},
], ids=["per_vehicle", "relative", "ewma", "cusum", "forgetting", "acc_3_followers", "half_second_steps"])
def test_fused_equals_staged_under_other_configs(overrides: dict) -> None:
    assert run_both({**ALL_KINDS, **SHORT, **overrides}, 100) >= 4


def test_fused_equals_staged_with_the_default_config() -> None:
    run_both({}, 40, n_envs=3)


def test_staged_only_while_tracing() -> None:
    """A traced task (rendering) steps stage by stage; the fused one does not record a trace."""
    env = TimeGapMonitorVectorEnv(1)
    env.reset(seed=0)
    trace = env.task.start_trace()
    env.step(env.action_space.sample())
    assert trace.arrays().t.size == env.task.ticks_per_decision
