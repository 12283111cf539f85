"""Write one rendered frame of ``TimeGapMonitor-v0`` to ``results/env_frame.png``.

The platoon starts at 1.6 s, switches to 1.0 s after 10 s, and is drawn at
t = 40 s with highway-env's road graphics beside the control chart.

    python -m train.render_frame [--seed 0] [--out results/env_frame.png]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import gymnasium as gym
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

import timegap_env
from timegap_env import cli

SWITCH_STEP, FRAME_STEP = 10, 40  # [steps of 1 s]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=Path("runs/env_frame.png"),
                        help="the frame (default: %(default)s; make reproduce writes results/env_frame.png)")
    args = parser.parse_args()
    cli.output_file(args.out)
    levels = list(timegap_env.EnvConfig().setting_levels)
    env = gym.make(timegap_env.DEFAULT_TASK, render_mode="rgb_array", config={"degradation": {"kind_weights": {"none": 1.0}}})
    env.reset(seed=args.seed, options={"scenario": "aggressive_cycles"})
    for step in range(FRAME_STEP):
        env.step(levels.index(1.6) if step < SWITCH_STEP else levels.index(1.0))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    plt.imsave(args.out, env.render())
    env.close()
    print(f"wrote {args.out}")


if __name__ == "__main__":
    cli.run(main, "python -m train.render_frame")
