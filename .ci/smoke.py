"""The core install's smoke test (run by .ci/package from outside the tree, in a venv without extras).

python .ci/smoke.py LABEL: exits non-zero, saying why, unless the installed timegap_env makes, resets and steps
TimeGapMonitor-v1 with none of the extras' packages importable, every kernel of those steps loaded from the numba
cache its wheel carries (compiled while it was built: timegap_env.precompile).
"""

import importlib.metadata
import importlib.resources
import importlib.util
import sys
import time

import gymnasium as gym
import numpy as np

import timegap_env

label = sys.argv[1] if len(sys.argv) > 1 else "timegap_env"
extras_only = ("torch", "stable_baselines3", "highway_env", "pygame", "matplotlib", "tensorboard", "ray")
importable = [name for name in extras_only if importlib.util.find_spec(name) is not None]
assert not importable, f"the core install brings {importable}"
assert "site-packages" in timegap_env.__file__, f"imported {timegap_env.__file__}, not the installed package"
assert timegap_env.__version__ == importlib.metadata.version("timegap_env"), timegap_env.__version__
package = importlib.resources.files("timegap_env")
for data in ("py.typed", "sim/acc_presets.json"):
    assert package.joinpath(data).is_file(), f"{data} is not installed"

start = time.perf_counter()
env = gym.make("TimeGapMonitor-v1")
obs, info = env.reset(seed=0)
assert env.observation_space.contains(obs)
for _ in range(20):
    obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
    assert np.isfinite(reward) and env.observation_space.contains(obs)
vector = gym.make_vec("TimeGapMonitor-v1", num_envs=4, vectorization_mode="vector_entry_point")
vector.reset(seed=0)
vector.step(vector.action_space.sample())
stepped = time.perf_counter() - start
from timegap_env.precompile import compiled_not_loaded  # noqa: E402  after the steps it checks

compiled = compiled_not_loaded()
assert not compiled, f"the installed package compiled {compiled} instead of loading them from the wheel's numba cache"

rendering = gym.make("TimeGapMonitor-v1", render_mode="rgb_array")
rendering.reset(seed=0)
try:
    rendering.render()
except ImportError as error:
    assert "timegap_env[render]" in str(error), error
else:
    raise AssertionError("rendering without the render extra did not raise ImportError")

print(f"== smoke ({label}): timegap_env {timegap_env.__version__} made, reset and stepped TimeGapMonitor-v1 "
      f"(and its vector env) in {stepped:.1f} s, its kernels loaded from the wheel's cache; no torch, SB3, highway-env, pygame or "
      f"matplotlib; rendering asks for timegap_env[render]")
