"""What a policy does behind each kind of traffic, beside the paper's rule (issue 39, item 6): its setting over one
episode of every kind, where the charts alarmed, and over many episodes how often it changes the setting and what
it does after an alarm.

    python -m train.policy_behaviour --policy ppo=results/ppo_v1 --out runs/behaviour
    python -m train.policy_behaviour --policy real=runs/real/seed0 --policy ppo=results/ppo_v1 --episodes 200

``--policy NAME=RUN`` (a trained run) or a registry name (``rule_platoon``, ``v2v_aware``, ``fixed_1.6``), repeatable;
the paper's rule is always drawn. The kinds of traffic: each leader family of the default task's mix alone, and
the benchmark's groups of other traffic (``KINDS``). Every kind plays selection episodes, seeds from 5000
(``--episodes`` of them; the figure shows the first), in the default task's config with that kind's overrides.

Per kind and policy (``behaviour.md``): setting changes per episode (platoon mean setting moved), the mean setting,
the share of decisions at the driver's preferred setting, alarms per episode (decisions where any follower's chart
alarmed) and the answer to an alarm: the share of alarm onsets after which the setting went up, or down, within
``ANSWER_WINDOW`` decisions. Writes ``behaviour.png`` and ``behaviour.md`` into ``--out`` (which must not exist;
``--force`` replaces it).
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path
from typing import Any

import gymnasium as gym
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from timegap_env import DEFAULT_TASK, cli
from timegap_env.config import EnvConfig
from timegap_env.experiments import registry
from timegap_env.experiments.rollout import chooser, env_config, monitor_estimator
from timegap_env.leaders.scenarios import missing_data
from timegap_env.tasks import SELECTION_SEED_START, get_task

RULE = "rule_platoon"
DEFAULT_POLICIES = ("ppo_real_fast=results/recipes/ppo_real_fast_seed0", "ppo_real=results/recipes/ppo_real_seed0",
                    "ppo=results/ppo_v1")
ANSWER_WINDOW = 5  # decisions after an alarm's onset in which a setting change counts as its answer [-]


def kinds() -> dict[str, tuple[dict[str, Any], str]]:
    """Kind of traffic -> (overrides of the default task's config, the data it needs or "")."""
    task = get_task(DEFAULT_TASK)
    found = {family: ({"scenario_weights": {family: 1.0}}, "") for family in task.config().scenario_weights}
    for name in ("ngsim", "openacc", "stop_and_go", "emergency_braking"):
        group = task.group(name)
        found[name] = (dict(group.overrides), group.data)
    return found


@dataclasses.dataclass
class Episode:
    """One episode of one policy, decision by decision."""

    time: np.ndarray  # at each decision's end [s]
    setting: np.ndarray  # the platoon's mean setting [s]
    alarm: np.ndarray  # any follower's chart in alarm [bool]


def play(policy: Any, config: EnvConfig, seed: int) -> Episode:
    """``policy`` on one episode of ``config`` seeded ``seed``."""
    env = gym.make(DEFAULT_TASK, config=env_config(config, getattr(policy, "action_mode", None),
                                                   monitor_estimator(config, policy)))
    choose = chooser(policy)
    obs, info = env.reset(seed=seed)
    state: Any = None
    time, setting, alarm = [], [], []
    done = False
    while not done:
        batched = {key: np.asarray(value)[None] for key, value in info.items()}
        action, state = choose(obs[None], batched, state)
        obs, _, terminated, truncated, info = env.step(np.asarray(action)[0])
        done = terminated or truncated
        time.append((len(time) + 1) * config.decision_interval)
        setting.append(float(np.mean(info["setting"])))
        alarm.append(bool(np.any(info["alarm"])))
    env.close()
    return Episode(np.array(time), np.array(setting), np.array(alarm))


def statistics(episodes: list[Episode], preferred: float) -> dict[str, float]:
    """Per-episode means of what a policy did (see the module's docstring)."""
    changes = [np.count_nonzero(np.diff(e.setting, prepend=e.setting[0]) != 0) for e in episodes]
    onsets = up = down = 0
    for e in episodes:
        for i in np.flatnonzero(e.alarm & ~np.concatenate([[False], e.alarm[:-1]])):
            onsets += 1
            before = e.setting[i - 1] if i else e.setting[0]
            after = e.setting[i:i + ANSWER_WINDOW]
            up += bool(np.any(after > before + 1e-9))
            down += bool(np.any(after < before - 1e-9))
    return {"changes": float(np.mean(changes)),
            "mean_setting": float(np.mean([e.setting.mean() for e in episodes])),
            "at_preferred": float(np.mean([np.mean(np.isclose(e.setting, preferred)) for e in episodes])),
            "alarms": float(np.mean([np.count_nonzero(e.alarm) for e in episodes])),
            "onsets": float(onsets), "answered_up": up / onsets if onsets else float("nan"),
            "answered_down": down / onsets if onsets else float("nan")}


def make_policy(spec: str, config: EnvConfig) -> Any:
    """``NAME=RUN`` (a trained run) or a registry name, built for ``config``."""
    name, equals, run = spec.partition("=")
    return registry.load_learned(Path(run), config) if equals else registry.make(name, config)


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="python -m train.policy_behaviour", description=__doc__.split("\n")[0])
    parser.add_argument("--policy", action="append", metavar="NAME=RUN|NAME",
                        help="a trained run or a registry name (repeatable; default: " + ", ".join(DEFAULT_POLICIES)
                             + "); the paper's rule is always added")
    parser.add_argument("--episodes", type=cli.count, default=100,
                        help="selection episodes per kind of traffic, seeds from 5000 (default: %(default)s)")
    parser.add_argument("--out", type=Path, default=Path("runs/behaviour"), help="output directory (default: %(default)s)")
    parser.add_argument("--force", action="store_true", help="replace --out if it exists")
    args = parser.parse_args(argv)
    args.policy = args.policy or list(DEFAULT_POLICIES)
    return args


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    cli.output_dir(args.out)
    if args.out.exists() and any(args.out.iterdir()) and not args.force:
        raise FileExistsError(f"--out {args.out}: exists; --force replaces it (or give another --out)")
    specs = list(dict.fromkeys([*args.policy, RULE]))
    task = get_task(DEFAULT_TASK)
    played: dict[str, dict[str, list[Episode]]] = {}
    for kind, (overrides, data) in kinds().items():
        if data and (reason := missing_data(data)):
            print(f"{kind}: left out, {reason}")
            continue
        config = task.config(overrides)
        seeds = range(SELECTION_SEED_START, SELECTION_SEED_START + args.episodes)
        played[kind] = {spec.partition("=")[0]: [play(make_policy(spec, config), config, seed) for seed in seeds]
                        for spec in specs}
        print(f"{kind}: played", flush=True)
    names = [spec.partition("=")[0] for spec in specs]
    preferred = task.config().preferred_setting
    work = cli.work_directory(args.out)
    figure, axes = plt.subplots(len(played), 1, figsize=(9, 1.9 * len(played)), sharex=False, squeeze=False)
    for axis, (kind, by_policy) in zip(axes[:, 0], played.items()):
        for offset, name in enumerate(names):
            episode = by_policy[name][0]
            line, = axis.step(episode.time, episode.setting, where="post", label=name, linewidth=1.2)
            alarms = episode.time[episode.alarm]
            axis.plot(alarms, np.full(alarms.size, 0.5 - 0.08 * offset), "|", color=line.get_color(), markersize=6)
        axis.set_ylim(0.35, 2.3)
        axis.set_ylabel("setting [s]")
        axis.set_title(f"{kind} (seed {SELECTION_SEED_START}; ticks at the bottom: alarms)", fontsize=9)
    axes[0, 0].legend(fontsize=8, ncol=len(names), loc="upper right")
    axes[-1, 0].set_xlabel("time [s]")
    figure.tight_layout()
    figure.savefig(work / "behaviour.png", dpi=90)
    lines = ["# What each policy does behind each kind of traffic", "",
             f"Selection episodes {SELECTION_SEED_START}-{SELECTION_SEED_START + args.episodes - 1} of each kind; "
             f"policies: {', '.join(specs)}. An alarm's answer: the setting went up / down within {ANSWER_WINDOW} "
             "decisions of its onset.", "",
             "| traffic | policy | setting changes /episode | mean setting [s] | at the preferred setting | "
             "alarm decisions /episode | alarm onsets | answered up | answered down |", "|---|---|---|---|---|---|---|---|---|"]
    for kind, by_policy in played.items():
        for name in names:
            s = statistics(by_policy[name], preferred)
            lines.append(f"| {kind} | {name} | {s['changes']:.1f} | {s['mean_setting']:.2f} | {s['at_preferred']:.0%} | "
                         f"{s['alarms']:.1f} | {s['onsets']:.0f} | {s['answered_up']:.0%} | {s['answered_down']:.0%} |")
    (work / "behaviour.md").write_text("\n".join(lines) + "\n")
    cli.publish(work, args.out)
    print("\n".join(lines))


if __name__ == "__main__":
    cli.run(main, "python -m train.policy_behaviour")
