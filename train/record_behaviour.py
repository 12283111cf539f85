"""Record what the public API returns, bit for bit, to check that a refactoring changes nothing.

    python -m train.record_behaviour --out /tmp/before.pkl                       # record
    python -m train.record_behaviour --out /tmp/after.pkl --compare /tmp/before.pkl  # record again and compare
    python -m train.record_behaviour --out /tmp/after.pkl --compare /tmp/old.pkl \
        --rename time_gap=actual_time_gap --rename time_gap_setting=setting   # against a recording of eed82b7

Records, through ``gym.make``, ``gym.make_vec`` and ``timegap_env.simulate`` only:

- full episodes of ``TimeGapMonitor-v0`` (observation, reward, terminated, truncated and the
  whole info of every step, the ground truth's keys included: ``truth_info=True``) in the platoon and per-vehicle action modes, several seeds, leader
  families (synthetic, NGSIM when the data is present, highway-env's IDM driver, the user's own
  speed series) and configs (EWMA and CUSUM charts, forgetting, dropouts, three followers);
- the native vector env over more steps than an episode, so autoresets are included;
- the same of ``TimeGapMonitor-v1`` (fewer episodes: its regimes leader, the relative action mode, the raw-gap
  monitor);
- one rendered frame;
- ``simulate("paper")`` and ``simulate`` with a schedule of settings and a V2V outage.

Actions come from a seeded generator, so they exercise changes of setting. The recording is a
pickle of nested dicts and lists of NumPy arrays; ``--compare`` reports every path whose dtype,
shape or bytes differ (NaN included) and exits 1 if any does. ``--rename old=new`` reads the
earlier recording's dict key ``old`` as ``new``, for a key the API has renamed.
"""

from __future__ import annotations

import argparse
import pickle
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import timegap_env
from timegap_env import cli

EPISODES: list[dict[str, Any]] = [  # gym.make config, reset seed and options, action generator seed
    {"config": None, "seed": 0, "options": None, "actions": 100},
    {"config": None, "seed": 1, "options": {"scenario": "hard_braking"}, "actions": 101},
    {"config": {"action_mode": "per_vehicle"}, "seed": 2, "options": None, "actions": 102},
    {"config": {"action_mode": "per_vehicle"}, "seed": 3, "options": {"scenario": "ngsim_in_band"}, "actions": 103},
    {"config": None, "seed": 4, "options": {"scenario": "idm"}, "actions": 104},
    {"config": {"platoon": {"n_followers": 3}, "chart": {"kind": "ewma"}, "sensors": {"dropout_probability": 0.1},
                "monitor": {"forgetting": 0.98}}, "seed": 5, "options": {"scenario": "sinusoid"}, "actions": 105},
    {"config": {"action_mode": "per_vehicle", "chart": {"kind": "cusum"}, "monitor": {"window": None}},
     "seed": 6, "options": {"scenario": "stochastic_human"}, "actions": 106},
    {"config": None, "seed": 7, "options": {"leader_speed": 20.0 + 3.0 * np.sin(np.arange(1500) * 0.02)},
     "actions": 107},
    {"config": {"platoon": {"actuation_lag": 1.0, "actuation_gain": 0.6, "initial_setting": 0.6},
                "degradation": {"kind_weights": {"v2v_outage": 1.0}}, "setting_levels": (0.6, 0.7), "preferred_setting": 0.6},
     "seed": 0, "options": {"scenario": "hard_braking"}, "actions": 108},
]
V1_EPISODES: list[dict[str, Any]] = [  # the same, of TimeGapMonitor-v1
    {"config": None, "seed": 0, "options": None, "actions": 300},
    {"config": None, "seed": 1, "options": {"scenario": "regimes"}, "actions": 301},
    {"config": {"action_mode": "per_vehicle"}, "seed": 2, "options": None, "actions": 302},
    {"config": {"action_mode": "relative", "monitor": {"estimator": "raw_gap"}}, "seed": 3, "options": None,
     "actions": 303},
]
ENV_KWARGS: dict[str, Any] = {"truth_info": True}  # every info key, the ground truth's included
VECTOR_ENVS, VECTOR_STEPS = 4, 300
SWITCH_CHANCE = 0.15  # chance per step that the action generator picks a new setting [-]


def canonical(value: Any) -> Any:
    """``value`` with every leaf an ndarray (scalars, bools and strings included), dicts and lists kept."""
    if isinstance(value, dict):
        return {str(key): canonical(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [canonical(item) for item in value]
    if isinstance(value, np.ndarray) and value.dtype == object:
        return [canonical(item) for item in value]
    return np.asarray(value)


def actions(levels: int, shape: tuple[int, ...], seed: int) -> Iterator[np.ndarray]:
    """Ladder indices of ``shape`` that stay put most steps and jump to a random level now and then."""
    rng = np.random.default_rng(seed)
    current = rng.integers(0, levels, size=shape)
    while True:
        if rng.random() < SWITCH_CHANCE:
            current = rng.integers(0, levels, size=shape)
        yield current.astype(np.int64)


def record_episode(spec: dict[str, Any], env_id: str = timegap_env.ENV_ID) -> dict[str, Any]:
    env = gym.make(env_id, config=spec["config"], **ENV_KWARGS)
    obs, info = env.reset(seed=spec["seed"], options=spec["options"])
    steps = [{"obs": obs, "info": info}]
    space = env.action_space  # Discrete(levels) or MultiDiscrete([levels] * N); Discrete(3) in the relative mode
    levels = int(space.n) if isinstance(space, gym.spaces.Discrete) else int(space.nvec[0])
    for action in actions(levels, env.action_space.shape, spec["actions"]):
        obs, reward, terminated, truncated, info = env.step(action)
        steps.append({"action": action, "obs": obs, "reward": reward, "terminated": terminated,
                      "truncated": truncated, "info": info})
        if terminated or truncated:
            break
    env.close()
    return canonical({"steps": steps})


def record_vector_env(env_id: str = timegap_env.ENV_ID) -> dict[str, Any]:
    envs = gym.make_vec(env_id, num_envs=VECTOR_ENVS, vectorization_mode="vector_entry_point",
                        config={"action_mode": "per_vehicle"}, autoreset_mode="same_step", **ENV_KWARGS)
    obs, infos = envs.reset(seed=20)
    steps = [{"obs": obs, "infos": infos}]
    generator = actions(len(envs.unwrapped.config.setting_levels), envs.action_space.shape, 200)
    for _ in range(VECTOR_STEPS):
        obs, reward, terminated, truncated, infos = envs.step(next(generator))
        steps.append({"obs": obs, "reward": reward, "terminated": terminated, "truncated": truncated,
                      "infos": infos})
    envs.close()
    return canonical({"steps": steps})


def record_render() -> np.ndarray:
    env = gym.make(timegap_env.ENV_ID, render_mode="rgb_array", config={"degradation": {"kind_weights": {"none": 1.0}}})
    env.reset(seed=0, options={"scenario": "aggressive_cycles"})
    for step in range(40):
        env.step(5 if step < 10 else 2)
    frame = env.render()
    env.close()
    return np.asarray(frame)


def record_simulations() -> dict[str, Any]:
    runs = {"paper": timegap_env.simulate("paper", seed=0)}
    n_ticks = 2501
    settings = np.where(np.arange(n_ticks)[:, None] < 1000, 1.6, 1.0) * np.ones(5)
    v2v = ~((np.arange(n_ticks)[:, None] >= 500) & (np.arange(n_ticks)[:, None] < 900)) & np.ones(5, dtype=bool)
    runs["schedule"] = timegap_env.simulate("hard_braking", seed=3, setting=settings, v2v=v2v)
    fields = ("t", "x", "v", "a", "u", "setting", "v2v", "leader_name", "spacing")
    return {
        name: canonical({**{field: getattr(run, field) for field in fields},
                         "applied": run.applied_setting, "actual": run.actual_time_gap,
                         "collision": str(run.collision)})
        for name, run in runs.items()
    }


def record() -> dict[str, Any]:
    return {
        "episodes": [record_episode(spec) for spec in EPISODES],
        "vector_env": record_vector_env(),
        "v1_episodes": [record_episode(spec, "TimeGapMonitor-v1") for spec in V1_EPISODES],
        "v1_vector_env": record_vector_env("TimeGapMonitor-v1"),
        "render": record_render(),
        "simulate": record_simulations(),
    }


def differences(before: Any, after: Any, renamed: dict[str, str], path: str = "", key_order: bool = True
                ) -> Iterator[str]:
    """Paths where ``after`` differs from ``before`` (its dict keys read through ``renamed``) in structure,
    key order (unless ``key_order`` is False), dtype, shape or bytes."""
    if isinstance(before, dict) or isinstance(after, dict):
        if not (isinstance(before, dict) and isinstance(after, dict)):
            yield f"{path}: a dict on one side only"
            return
        before = {renamed.get(key, key): value for key, value in before.items()}
        if (list(before) if key_order else sorted(before)) != (list(after) if key_order else sorted(after)):
            yield f"{path}: keys {list(before)} -> {list(after)}"
        for key in before.keys() & after.keys():
            yield from differences(before[key], after[key], renamed, f"{path}/{key}", key_order)
    elif isinstance(before, list) or isinstance(after, list):
        if not (isinstance(before, list) and isinstance(after, list)) or len(before) != len(after):
            yield f"{path}: list lengths {len(before)} -> {len(after)}"
            return
        for i, (a, b) in enumerate(zip(before, after)):
            yield from differences(a, b, renamed, f"{path}[{i}]", key_order)
    elif before.dtype != after.dtype or before.shape != after.shape:
        yield f"{path}: {before.dtype}{before.shape} -> {after.dtype}{after.shape}"
    elif before.tobytes() != after.tobytes():
        yield f"{path}: values differ ({before!r} -> {after!r})"[:300]


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m train.record_behaviour", description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, required=True, help="where to write the recording (a pickle)")
    parser.add_argument("--compare", type=Path, help="an earlier recording to compare this one with")
    parser.add_argument("--rename", action="append", default=[], metavar="OLD=NEW",
                        help="read the earlier recording's dict key OLD as NEW (repeatable)")
    parser.add_argument("--any-key-order", action="store_true",
                        help="compare dicts' keys as sets (for a change that only reorders an info's keys)")
    args = parser.parse_args(argv)
    cli.output_file(args.out)
    for pair in args.rename:
        if "=" not in pair:
            raise ValueError(f"--rename {pair!r}: must be OLD=NEW")
    renamed = dict(pair.split("=", 1) for pair in args.rename)
    earlier = None
    if args.compare is not None:  # read before the recording's work: a file that cannot be read is named now
        try:
            earlier = pickle.loads(args.compare.read_bytes())
        except (pickle.UnpicklingError, EOFError, AttributeError, ImportError, IndexError, TypeError) as error:
            raise ValueError(f"--compare {args.compare}: not a recording of train.record_behaviour "
                             f"({type(error).__name__}: {error})") from error
    recording = record()
    args.out.write_bytes(pickle.dumps(recording))
    print(f"wrote {args.out}")
    if args.compare is not None:
        found = list(differences(earlier, recording, renamed, key_order=not args.any_key_order))
        for line in found[:50]:
            print(line)
        print(f"{len(found)} difference(s) from {args.compare}")
        sys.exit(1 if found else 0)


if __name__ == "__main__":
    cli.run(main, "python -m train.record_behaviour")
