"""How often gymnasium's per-step rewards fall below −offset of the offset QD-Score.

PPGA's offset QD-Score adds a per-step offset (QDax's, tuned for Brax) so that every elite
counts positively. This script steps each task with uniform random actions and reports the
minimum per-step reward and the share of steps below −offset.

Usage::

    python benchmarks/probes/reward_offsets.py [--steps 500] [--num-envs 16]
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np

import qdil  # noqa: F401
from qdil.qd.archives import QD_OFFSETS


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--steps", type=int, default=500)
    parser.add_argument("--num-envs", type=int, default=16)
    args = parser.parse_args()
    print("| task | offset | min per-step reward | 1 % quantile | steps below −offset |")
    print("|---|---|---|---|---|")
    for task, offset in QD_OFFSETS.items():
        env = gym.make_vec(f"qdil/{task}", num_envs=args.num_envs)
        env.reset(seed=0)
        rng = np.random.default_rng(0)
        low, high = env.single_action_space.low, env.single_action_space.high
        rewards = np.concatenate(
            [
                env.step(rng.uniform(low, high, (args.num_envs, low.size)))[1]
                for _ in range(args.steps)
            ]
        )
        print(
            f"| {task} | {offset} | {rewards.min():.3f} | {np.quantile(rewards, 0.01):.3f} | "
            f"{100 * np.mean(rewards < -offset):.2f} % |"
        )


if __name__ == "__main__":
    main()
