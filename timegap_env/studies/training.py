"""What training (``train.train_ppo``), its learning curve and RLlib's runs (``train.train_rllib``) agree on: the
check episodes, and reading an rl-zoo3-style hyperparameter file.

``load_hyperparams`` imports torch and stable-baselines3 (the ``train`` extra) when called; importing this module does
not.
"""

from __future__ import annotations

import inspect
from pathlib import Path
from typing import Any

import yaml

from timegap_env import DEFAULT_TASK
from timegap_env.tasks import get_task



def check_seeds(task_id: str) -> list[int]:
    """The seeds of the end-of-training check (and the learning curve) of a run in task ``task_id`` (its record's
    ``seeds.check``: 32 from 9000 in v0, 100 in v1, whose collision term, a rare 1000-point loss, needs more)."""
    return get_task(task_id).seeds.check


CURVE_FILE = "curve.csv"  # a run's learning curve (train_ppo writes it, compare_curves reads it)
CURVE_COLUMNS = ("timesteps", "mean_return", "share_of_oracle_gap", "best_blind_return", "oracle_return")
RUN_KEYS = {"n_envs", "n_timesteps", "policy", "normalize", "frame_stack", "env_kwargs"}  # rl-zoo3's; the rest: PPO's
STRING_KWARGS = ("policy_kwargs", "normalize")  # may be Python expressions as in rl-zoo3: "dict(net_arch=[64])"


def load_hyperparams(path: Path, env_id: str = DEFAULT_TASK, algorithm: Any = None) -> dict[str, Any]:
    """The ``env_id`` section of an rl-zoo3-style yml, expressions in ``STRING_KWARGS`` evaluated, its keys checked
    against ``algorithm``'s arguments (default: stable-baselines3's PPO)."""
    import torch  # only here: the library steps the env without torch
    from stable_baselines3 import PPO

    algorithm = algorithm or PPO

    with open(path) as file:
        document = yaml.safe_load(file)
    if not isinstance(document, dict) or env_id not in document:
        raise ValueError(f"hyperparams = {str(path)!r}: needs a top-level key {env_id!r}")
    hyperparams = dict(document[env_id])
    allowed = RUN_KEYS | (set(inspect.signature(algorithm).parameters) - {"env", "seed", "tensorboard_log", "device"})
    for key, value in hyperparams.items():
        if key == "warmup":
            raise ValueError(f"hyperparams {env_id}.warmup in {path}: the warm-up moved to its own file (rl-zoo3 "
                             "refuses the key): put it in hyperparams/ppo_warmup.yml's layout and pass --warmup FILE")
        if key not in allowed:
            raise ValueError(f"hyperparams {env_id}.{key} = {value!r}: unknown; allowed: {sorted(allowed)}")
        if key in STRING_KWARGS and isinstance(value, str):
            try:
                hyperparams[key] = eval(value, {"__builtins__": {}}, {"dict": dict, "nn": torch.nn})
            except Exception as error:
                raise ValueError(f"hyperparams {env_id}.{key} = {value!r}: not an expression ({error})") from error
    for key in ("n_envs", "n_timesteps", "policy"):
        if key not in hyperparams:
            raise ValueError(f"hyperparams {env_id}.{key}: missing")
    return hyperparams



def with_env_config(env_kwargs: dict[str, Any], overrides: dict[str, Any]) -> dict[str, Any]:
    """``env_kwargs`` (gym.make's) with ``overrides`` merged into its ``config``."""
    return {**env_kwargs, "config": {**(env_kwargs.get("config") or {}), **overrides}} if overrides else env_kwargs


__all__ = ["CURVE_COLUMNS", "CURVE_FILE", "RUN_KEYS",
           "STRING_KWARGS", "check_seeds", "load_hyperparams", "with_env_config"]
