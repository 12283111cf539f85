"""A single env's per-step info: written by the step into arrays the env reuses only once nothing holds them
(``timegap_env.envs.info.EnvInfoPool``), so a kept info never changes; the same bytes on the staged path and in a copy.
"""

from __future__ import annotations

import copy
import pickle

import gymnasium as gym
import numpy as np
import pytest

import timegap_env  # noqa: F401  (registers the envs)
from tests.envs.reference import use_reference
from timegap_env.envs import info as info_module
from tests.envs.test_fused_step import same_bytes

SHORT = {"episode_duration": 30.0}


def make(version: int = 0, **kwargs: object) -> gym.Env:
    return gym.make(f"TimeGapMonitor-v{version}", config=SHORT, **kwargs).unwrapped


def same_outputs(first: tuple, other: tuple, where: str) -> None:
    """The same observation, reward, flags and info (bytes, dtypes and the info's key order)."""
    for name, a, b in zip(("observation", "reward", "terminated", "truncated", "info"), first, other):
        same_bytes(a, b, f"{where} {name}")
    assert list(first[-1]) == list(other[-1]), f"{where}: the info's key order"


def step_alike(envs: list[gym.Env], n_steps: int, seed: int = 3) -> None:
    """Step ``envs`` with the same actions, resetting them together, and compare everything they return."""
    outputs = [env.reset(seed=seed) for env in envs]
    for other in outputs[1:]:
        same_outputs(outputs[0], other, "reset")
    actions = envs[0].action_space
    actions.seed(seed)
    for step in range(n_steps):
        action = actions.sample()
        outputs = [env.step(action) for env in envs]
        for other in outputs[1:]:
            same_outputs(outputs[0], other, f"step {step}")
        if outputs[0][2] or outputs[0][3]:
            outputs = [env.reset() for env in envs]


@pytest.mark.parametrize("version", [0, 1])
@pytest.mark.parametrize("truth_info", [False, True])
def test_the_fused_steps_infos_equal_the_staged_paths(version: int, truth_info: bool) -> None:
    fused, staged = make(version, truth_info=truth_info), make(version, truth_info=truth_info)
    use_reference(staged.task)
    step_alike([fused, staged], 70)


def test_a_copied_or_unpickled_env_writes_its_own_infos_alike() -> None:
    env = make(1)
    env.reset(seed=5)
    for action in range(4):
        kept = env.step(action)[4]
    twins = [copy.deepcopy(env), pickle.loads(pickle.dumps(env))]
    for twin in twins:
        assert twin._infos._sets == type(twin._infos._sets)()  # a copy starts with no sets of its own
    for step in range(40):
        outputs = [e.step(step % 9) for e in (env, *twins)]
        for other in outputs[1:]:
            same_outputs(outputs[0], other, f"step {step}")
            assert not np.shares_memory(outputs[0][4]["estimate"], other[4]["estimate"])
        if outputs[0][2] or outputs[0][3]:
            break
    assert kept["reward_tracking"].shape == ()


@pytest.mark.parametrize("version", [0, 1])
def test_a_kept_info_never_changes(version: int) -> None:
    env = make(version)
    env.reset(seed=11)
    kept: dict[str, object] = {}
    for step in range(60):
        _, _, terminated, truncated, info = env.step(step % 9)
        if terminated or truncated:
            info = env.reset()[1]
        if step == 3:
            kept["dict"], kept["dict copy"] = info, copy.deepcopy(info)
        elif step == 4:
            kept["estimate"], kept["estimate copy"] = info["estimate"], info["estimate"].copy()
        elif step == 5:
            kept["lcl tail"], kept["lcl tail copy"] = info["lcl"][1:], info["lcl"][1:].copy()  # a view of a view
        elif step == 6:
            kept["reward"], kept["reward copy"] = info["reward_tracking"], info["reward_tracking"].copy()
        del info
    same_bytes(kept["dict"], kept["dict copy"], "the kept dict")
    for name in ("estimate", "lcl tail", "reward"):
        same_bytes(kept[name], kept[f"{name} copy"], f"the kept {name}")
    latest = env.step(0)[4]
    assert not np.array_equal(latest["estimate"], kept["estimate"])  # what was kept would have been overwritten


def test_dropped_infos_are_written_into_the_same_two_sets(monkeypatch: pytest.MonkeyPatch) -> None:
    made = []
    original = info_module.EnvInfoSet.__init__

    def counted(self: info_module.EnvInfoSet, *args: object) -> None:
        made.append(1)
        original(self, *args)

    monkeypatch.setattr(info_module.EnvInfoSet, "__init__", counted)
    env = make(1)
    _, info = env.reset(seed=2)
    for step in range(50):  # the usual loop: the last info is held while the next step runs
        _, _, terminated, truncated, info = env.step(step % 9)
        if terminated or truncated:
            _, info = env.reset()
    assert len(made) == info_module.INFO_SETS
    del info
    kept = [env.step(0)[4] for _ in range(4)]  # kept infos: the two free sets, then a new set for each step
    assert len(made) == info_module.INFO_SETS + 2 and len({id(info["estimate"].base) for info in kept}) == 4


def test_without_step_diagnostics_no_sets_are_made() -> None:
    env = make(0, step_diagnostics=False)
    env.reset(seed=0)
    assert env.step(1)[4] == {} and len(env._infos._sets) == 0


def test_a_step_refuses_an_info_block_of_another_number_of_envs() -> None:
    env = make(0)
    env.reset(seed=0)
    action = env._checked(1)
    with pytest.raises(ValueError, match="an InfoBlock of 2 envs: must be of n_envs = 1 or 0"):
        env.task._run_step(action, info_module.InfoBlock.empty(2, env.task.n_followers, "v0"))
