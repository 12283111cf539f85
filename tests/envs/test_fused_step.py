"""The fused step (one compiled call per step) against the components' methods composed stage by stage, bit for bit.

Two native vector envs run the same seeds and actions, one as it steps and one by the reference
(``tests.envs.reference.use_reference``); every observation, reward, flag and info must be the same bytes, over
episodes that cover every degradation kind, same-step and next-step autoresets, the three action
modes, the three charts, a monitor without a window and a platoon without V2V.
"""

from __future__ import annotations

import os

import numpy as np
import pytest

from tests.envs.reference import use_reference
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
    envs = {fused: TimeGapMonitorVectorEnv(n_envs, config=config, autoreset_mode=autoreset_mode, truth_info=True)
            for fused in (True, False)}  # truth_info: the platoon's true state and the ground truth compared too
    use_reference(envs[False].task)
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
    {"scenario_weights": {"regimes": 1.0, "hard_braking": 1.0}},
    {"monitor": {"estimator": "raw_gap"}, "chart": {"kind": "ewma"}},
], ids=["per_vehicle", "relative", "ewma", "cusum", "forgetting", "acc_3_followers", "half_second_steps",
        "v1_objectives_and_cost", "raw_gap"])
def test_fused_equals_staged_under_other_configs(overrides: dict) -> None:
    assert run_both({**ALL_KINDS, **SHORT, **overrides}, 100) >= 4


def test_fused_equals_staged_with_the_default_config() -> None:
    run_both({}, 40, n_envs=3)


def test_the_fused_step_records_the_trace_the_reference_records() -> None:
    """A traced task (rendering) still steps in one compiled call; its trace hook writes env 0's ticks."""
    envs = [TimeGapMonitorVectorEnv(2, config=SHORT) for _ in range(2)]
    use_reference(envs[1].task)
    traces = []
    for env in envs:
        env.reset(seed=3)
        traces.append(env.task.start_trace(keep=None))
        env.action_space.seed(3)
        for _ in range(12):
            env.step(env.action_space.sample())
    fused, reference = (trace.arrays() for trace in traces)
    assert fused.t.size == 12 * envs[0].task.ticks_per_decision
    for part in ("t", "estimate", "center"):
        same_bytes(getattr(fused, part), getattr(reference, part), f"trace {part}")


def test_single_env_fused_equals_staged_in_every_action_mode() -> None:
    """The single env runs the same task: fused and staged agree over two episodes, pinned degradations included."""
    from timegap_env.envs.env import TimeGapMonitorEnv

    for mode in ("platoon", "per_vehicle", "relative"):
        envs = {fused: TimeGapMonitorEnv({**SHORT, "action_mode": mode}, truth_info=True) for fused in (True, False)}
        use_reference(envs[False].task)
        envs[True].action_space.seed(1)
        for episode, kind in enumerate(("packet_loss", "radar_bias")):
            options = {"degradation": {"kind": kind, "size": 0.5, "followers": [2], "onset": 10.0}}
            resets = {fused: env.reset(seed=episode, options=options) for fused, env in envs.items()}
            same_bytes(resets[True][0], resets[False][0], f"{mode} reset")
            done = False
            while not done:
                action = envs[True].action_space.sample()
                outputs = {fused: env.step(action) for fused, env in envs.items()}
                for part, (a, b) in enumerate(zip(outputs[True], outputs[False])):
                    same_bytes(a, b, f"{mode} episode {episode} part {part}")
                done = outputs[True][2] or outputs[True][3]


def test_without_step_diagnostics_infos_hold_only_episode_summaries() -> None:
    import gymnasium as gym

    env = gym.make("TimeGapMonitor-v0", config={"episode_duration": 3.0}, step_diagnostics=False)
    full = gym.make("TimeGapMonitor-v0", config={"episode_duration": 3.0})
    assert env.reset(seed=2)[1] == {}
    full.reset(seed=2)
    for _ in range(3):
        obs, reward, terminated, truncated, info = env.step(4)
        want = full.step(4)
        same_bytes(obs, want[0], "observation")
        assert reward == want[1] and (terminated, truncated) == want[2:4]
    assert truncated and sorted(info) == sorted(key for key in want[4] if key.startswith("episode_"))


def test_the_vector_env_gives_the_ground_truth_without_step_diagnostics() -> None:
    from timegap_env.envs.info import truth_of

    options = {"degradation": {"kind": "gain", "size": 0.7, "followers": [1, 3]}}
    lean = TimeGapMonitorVectorEnv(2, step_diagnostics=False)
    full = TimeGapMonitorVectorEnv(2, truth_info=True)
    assert lean.reset(seed=5, options=options)[1] == {}
    want = truth_of(full.reset(seed=5, options=options)[1])
    got = lean.ground_truth()
    assert got.keys() == want.keys()
    for name in want:
        np.testing.assert_array_equal(got[name], want[name], err_msg=name)
    assert list(got["kind"][0]) == ["gain", "none", "gain", "none", "none"]


@pytest.mark.parametrize("value", ["no", 0, None])
def test_step_diagnostics_must_be_a_bool(value: object) -> None:
    import gymnasium as gym

    with pytest.raises(ValueError, match="step_diagnostics"):
        gym.make("TimeGapMonitor-v0", step_diagnostics=value)
    with pytest.raises(ValueError, match="step_diagnostics"):
        TimeGapMonitorVectorEnv(2, step_diagnostics=value)


@pytest.mark.parametrize("value", ["yes", 1, None])
def test_truth_info_must_be_a_bool(value: object) -> None:
    import gymnasium as gym

    import timegap_env
    from timegap_env.envs.env import TimeGapMonitorEnv

    with pytest.raises(ValueError, match="truth_info"):
        gym.make("TimeGapMonitor-v0", truth_info=value)
    with pytest.raises(ValueError, match="truth_info"):
        gym.make(timegap_env.MO_ENV_ID, truth_info=value)
    with pytest.raises(ValueError, match="truth_info"):
        TimeGapMonitorEnv(truth_info=value)
    with pytest.raises(ValueError, match="truth_info"):
        TimeGapMonitorVectorEnv(2, truth_info=value)
    with pytest.raises(ValueError, match="truth_info"):
        gym.make_vec("TimeGapMonitor-v0", num_envs=2, vectorization_mode="vector_entry_point", truth_info=value)


def test_truth_info_needs_step_diagnostics() -> None:
    """The ground truth is a per-step key: asking for it while leaving every per-step key out is refused."""
    import gymnasium as gym

    import timegap_env
    from timegap_env.envs.env import TimeGapMonitorEnv

    makers = [lambda: gym.make("TimeGapMonitor-v0", step_diagnostics=False, truth_info=True),
              lambda: gym.make("TimeGapMonitor-v1", step_diagnostics=False, truth_info=True),
              lambda: gym.make(timegap_env.MO_ENV_ID, step_diagnostics=False, truth_info=True),
              lambda: TimeGapMonitorEnv(step_diagnostics=False, truth_info=True),
              lambda: TimeGapMonitorVectorEnv(2, step_diagnostics=False, truth_info=True),
              lambda: gym.make_vec("TimeGapMonitor-v0", num_envs=2, vectorization_mode="vector_entry_point",
                                   step_diagnostics=False, truth_info=True)]
    for make in makers:
        with pytest.raises(ValueError, match="truth_info"):
            make()
    for step_diagnostics, truth_info in ((True, False), (True, True), (False, False)):  # the other three are fine
        env = TimeGapMonitorVectorEnv(2, step_diagnostics=step_diagnostics, truth_info=truth_info)
        assert (env.step_diagnostics, env.truth_info) == (step_diagnostics, truth_info)


@pytest.mark.slow
def test_an_edit_to_a_stage_function_recompiles_the_fused_step(tmp_path):
    """The fused step inlines or calls kernels of other files; numba's cache checks only the kernel's own file, so
    the caches of the step and of every kernel it runs follow all those files (a copy of the package is edited,
    never the repository's): an edit to a called stage's file (action.py) recompiles the step as one to an inlined
    one's (platoon.py) does."""
    import shutil
    import subprocess
    import sys
    from pathlib import Path

    import timegap_env

    package = tmp_path / "src" / "timegap_env"
    shutil.copytree(Path(timegap_env.__file__).parent, package, ignore=shutil.ignore_patterns("__pycache__"))
    code = ("import gymnasium as gym, timegap_env\n"
            "from timegap_env.envs.step_kernel import fused_step\n"
            "env = gym.make('TimeGapMonitor-v0', step_diagnostics=False); env.reset(seed=0); env.step(0)\n"
            "print(sum(fused_step.stats.cache_hits.values()), sum(fused_step.stats.cache_misses.values()))")
    environment = {**os.environ, "PYTHONPATH": str(tmp_path / "src"), "NUMBA_CACHE_DIR": str(tmp_path / "cache")}

    def hits_and_misses() -> list[int]:
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, env=environment,
                             cwd=tmp_path)  # not the repository's, which python -c would import first
        return [int(word) for word in out.stdout.split()]

    assert hits_and_misses() == [0, 1]  # compiled and cached
    assert hits_and_misses() == [1, 0]  # loaded from the cache
    for edited in (package / "sim" / "platoon.py", package / "envs" / "action.py"):
        edited.write_text(edited.read_text() + "\n# an edit\n")
        assert hits_and_misses() == [0, 1]  # compiled again


def test_without_v2v_the_followers_stay_in_acc() -> None:
    """PlatoonConfig.v2v = False keeps every follower in ACC: the flag, the observation and the physics (the
    degradations' V2V schedule once overrode it)."""
    import gymnasium as gym

    from timegap_env.envs.observation import FEATURES

    acc = gym.make("TimeGapMonitor-v0", config={"platoon": {"v2v": False}}, truth_info=True)
    no_feed_forward = gym.make("TimeGapMonitor-v0", config={"platoon": {"v2v": False, "k_f": 0.0}}, truth_info=True)
    for env in (acc, no_feed_forward):
        env.reset(seed=4, options={"degradation": None})
    for _ in range(20):
        obs, _, _, _, info = acc.step(4)
        assert not info["v2v"].any() and not obs.reshape(-1, len(FEATURES))[:, FEATURES.index("v2v")].any()
        same_bytes(info["actual_time_gap"], no_feed_forward.step(4)[4]["actual_time_gap"], "ACC is k_f = 0")


def test_the_task_checks_actions_before_the_kernel_sees_them() -> None:
    env = TimeGapMonitorVectorEnv(2)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="every entry must be in"):
        env.task.step(np.array([40, 0]))


def test_actions_of_any_memory_layout_share_one_compiled_step() -> None:
    from timegap_env.envs.step_kernel import fused_step

    env = TimeGapMonitorVectorEnv(4, config={"action_mode": "per_vehicle"})
    env.reset(seed=0)
    env.step(np.zeros((4, 5), dtype=np.int64))
    compiled = len(fused_step.signatures)
    env.step(np.asfortranarray(np.ones((4, 5), dtype=np.int32)))
    env.step(np.ones((8, 5), dtype=np.int64)[::2])
    env.step(np.broadcast_to(np.int64(2), (4, 5)))  # read-only: the task calls one compiled entry for one type
    assert len(fused_step.signatures) == compiled
    assert env.task.ladder.check(np.broadcast_to(np.int64(2), (4, 5))).flags.writeable


@pytest.mark.parametrize("chart", ["shewhart", "ewma", "cusum"])
def test_the_params_made_from_the_config_are_the_components_own_constants(chart):
    """``EnvParams.from_config`` gives each section exactly the record the component running alone makes."""
    from timegap_env.config import EnvConfig
    from timegap_env.envs.task import PlatoonTask

    config = EnvConfig.from_dict({"chart": {"kind": chart}, "monitor": {"forgetting": 0.99}})
    task = PlatoonTask(config, 2)
    params, loop = task.params, task.loop
    sections = {"ladder": task.ladder.rule, "controller": loop.platoon.controller, "window": loop.monitor.rule,
                "prior": loop.monitor.prior, "chart": loop.chart.rule}
    for name, own in sections.items():
        same_bytes(dict(getattr(params, name)._asdict()), dict(own._asdict()), name)
    assert params.chart.half_width == loop.chart.half_width and params.ticks_per_step == config.ticks_per_decision
