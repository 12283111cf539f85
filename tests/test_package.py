"""The package as users meet it: registration, the episode length, what the top level exports."""

import os
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import timegap_env


def test_makeable_by_module_prefix_without_importing_first():
    code = "import gymnasium as gym; env = gym.make('timegap_env:TimeGapMonitor-v0'); env.reset(seed=0); print('ok')"
    assert subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip() == "ok"


@pytest.mark.parametrize("duration, decision_interval", [(None, None), (500.0, None), (60.0, 2.0)])
def test_episodes_last_episode_duration_without_max_episode_steps(duration, decision_interval):
    """The synthetic leaders last the episode too: nothing else is needed for a longer one."""
    config = {key: value for key, value in (("episode_duration", duration), ("decision_interval", decision_interval))
              if value is not None}
    env = gym.make(timegap_env.ENV_ID, config=config)
    expected = env.unwrapped.config.max_episode_steps
    assert expected == round((duration or 250.0) / (decision_interval or 1.0))
    for family in ("aggressive_cycles", "hard_braking"):
        env.reset(seed=0, options={"scenario": family})
        for step in range(1, expected + 1):
            _, _, terminated, truncated, _ = env.step(5)
            assert not terminated and truncated == (step == expected), (family, step)
    vector = gym.make_vec(timegap_env.ENV_ID, num_envs=2, vectorization_mode="vector_entry_point", config=config)
    vector.reset(seed=0)
    for step in range(1, expected + 1):
        _, _, _, truncated, _ = vector.step(np.full(2, 5))
        assert truncated.tolist() == [step == expected] * 2


def test_what_users_call_is_importable_from_the_top_level():
    for name in ("simulate", "Trajectory", "posterior", "TimeGapMonitor", "LeaderProfile", "make_leader", "SCENARIOS",
                 "aggressive_cycles", "sinusoid", "hard_braking", "stochastic_human", "read_ngsim", "vehicle_profile",
                 "idm_leader", "string_stability", "EnvConfig", "PlatoonConfig", "MonitorConfig", "ChartConfig",
                 "SensorConfig", "LeaderConfig", "RewardWeights", "MONITOR_PRESETS", "ENV_ID"):
        assert name in timegap_env.__all__ and hasattr(timegap_env, name), name
    assert all(hasattr(timegap_env, name) for name in timegap_env.__all__)
    mean, cov = timegap_env.posterior([20.0, 25.0], [37.0, 45.0], [5.0, 1.6], [[1e-4, -1e-5], [-1e-5, 0.125]], 0.01)
    assert mean.shape == (2,) and cov.shape == (2, 2)


def test_the_policies_are_installed_inside_the_package():
    """The policies live in ``timegap_env.agents`` (no generically named top-level ``agents`` is installed): importable
    outside the repository, without torch (the learned policies import it only when loaded)."""
    code = ("import importlib.util, sys, timegap_env.agents.policies, timegap_env.agents.protocol; "
            "print(timegap_env.agents.policies.__file__, importlib.util.find_spec('agents'), 'torch' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd="/").stdout
    path, spec, torch_loaded = out.split()
    assert Path(path).parts[-3:] == ("timegap_env", "agents", "policies.py") and spec == "None" and torch_loaded == "False"


def test_the_first_import_says_the_kernels_will_compile_once(tmp_path):
    """A new user's first step waits on numba; the import says why, only while nothing is cached, and through the
    ``timegap_env`` logger (Python's last-resort handler shows it on stderr), never a print: a program that sets the
    logger's level silences it."""
    code = "import timegap_env"
    environ = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    empty = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, env=environ)
    assert "compiles the simulator's kernels" in empty.stderr and not empty.stdout
    quiet = "import logging; logging.getLogger('timegap_env').setLevel(logging.ERROR); import timegap_env"
    silenced = subprocess.run([sys.executable, "-c", quiet], capture_output=True, text=True, check=True, env=environ)
    assert silenced.stderr == "" and silenced.stdout == ""
    configured = ("import logging, sys; logging.basicConfig(stream=sys.stdout, format='%(name)s %(levelname)s'); "
                  "import timegap_env")
    logged = subprocess.run([sys.executable, "-c", configured], capture_output=True, text=True, check=True, env=environ)
    assert logged.stdout.strip() == "timegap_env WARNING" and logged.stderr == ""
    (tmp_path / "envs_0").mkdir()
    (tmp_path / "envs_0" / "step_kernel.fused_step-123.py311.nbi").write_bytes(b"")
    cached = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, env=environ)
    assert "compiles" not in cached.stderr


def test_a_reset_that_raised_leaves_the_env_usable():
    env = gym.make(timegap_env.ENV_ID)
    with pytest.raises(ValueError, match="weather"):
        env.reset(options={"weather": "rain"})
    with pytest.raises(gym.error.ResetNeeded):
        env.step(4)
    env.reset(seed=0)
    _, reward, *_ = env.step(4)
    assert np.isfinite(reward)
