"""Where the time of a QD iteration goes, and its env-steps/s against bare stepping.

Compiles the physics kernels, steps a few iterations of a recipe (default: the laptop
Walker2d PPGA recipe) from Python while ``qdil.timing`` totals its sections, then steps the
same task with random actions to measure the bare stepping rate of the environment, in the
same process:

- physics: ``MujocoBatch.step`` and ``reset`` (the numba kernels);
- policy inference: sampling actions during rollouts and evaluations;
- PPO updates: GAE and the minibatch epochs;
- reward model: ``predict_reward`` and ``update``;
- archive work: the pyribs scheduler's ask/tell and the passive archives' inserts;
- other: Python around them (rollout bookkeeping, env step bookkeeping, metrics).

Usage::

    python benchmarks/bench_iteration.py [RECIPE] [--iterations 3] [--clock wall|cpu] \
        [--KEY VALUE ...]

``--clock cpu`` times with this process's CPU time (for a machine other processes load);
further ``--KEY VALUE`` pairs override the recipe, e.g. ``--env.num_envs 1026``.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def warm_up() -> None:
    """Compile the physics kernels before anything is timed.

    numba compiles the step and reset kernels at their first call, in this process once
    (they call MuJoCo through pointers, so they cannot be cached on disk). Left in, that
    one-time cost would land in the first iteration's physics and lower a few-iteration
    ratio that a 120-iteration run never sees. Every task shares the kernels' signature.
    """
    from qdil.envs.vector import LocomotionVectorEnv

    env = LocomotionVectorEnv("Hopper-v5", 2, autoreset_mode="Disabled")
    env.reset(seed=0)
    env.step(np.zeros((2, 3)), mask=np.array([True, False]))


def bare_rate(
    task: str,
    num_envs: int,
    steps: int,
    repeats: int = 3,
    clock: Callable[[], float] = time.perf_counter,
) -> float:
    """Env-steps/s of random actions on the task's batched env (median of ``repeats``).

    A median of several passes, because one pass of a few hundred steps moved by about
    10 % between runs on a loaded machine, as much as the changes it is compared with.
    """
    import gymnasium as gym

    env = gym.make_vec(f"qdil/{task}", num_envs=num_envs, autoreset_mode="SameStep")
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    low, high = env.single_action_space.low, env.single_action_space.high
    actions = rng.uniform(low, high, size=(steps, num_envs, low.size))
    env.step(actions[0])
    rates = []
    for _ in range(repeats):
        start = clock()
        for a in actions:
            env.step(a)
        rates.append(steps * num_envs / (clock() - start))
    return float(np.median(rates))


def main() -> None:
    """Step the recipe's iterations with the sections totalled; print the breakdown."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("recipe", nargs="?", default=str(ROOT / "recipes" / "walker_ppga.yaml"))
    parser.add_argument("--iterations", type=int, default=3)
    parser.add_argument(
        "--clock",
        choices=("wall", "cpu"),
        default="wall",
        help="cpu: time with this process's CPU time (all its threads), for comparisons on a "
        "machine that other processes load; meaningful with one physics and torch thread",
    )
    # anything else is a recipe override, e.g. ``--env.num_envs 255`` for the scaling
    # ratios (N must split among the k+1 VPPO copies: 3 on Walker2d)
    args, overrides = parser.parse_known_args()
    clock = time.process_time if args.clock == "cpu" else time.perf_counter
    warm_up()
    import qdil
    from qdil.timing import SECTIONS, recording

    seconds: dict[str, float] = defaultdict(float)
    total = 0.0
    start = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        settings = ["--logging.wandb", "disabled", "--logging.progress", "false"]
        settings += ["--logging.checkpoint_every", str(10**6), "--qd.iterations"]
        settings += [str(args.iterations), *overrides]
        with qdil.Experiment.from_recipe(args.recipe, settings, root=tmp, name="bench") as run:
            task, num_envs = run.run.config["env"]["task"], run.run.config["env"]["num_envs"]
            while not run.finished:
                with recording(clock) as inside:
                    tic = clock()
                    metrics = run.step()
                    total += clock() - tic  # the iteration, timed like its sections
                for name, value in inside.items():
                    seconds[name] += value
            steps = metrics["perf/env_steps"]  # every iteration's, from the run's start
    bare = bare_rate(task, num_envs, steps=300, clock=clock)
    wall = time.perf_counter() - start
    print(
        f"# {Path(args.recipe).name}: {args.iterations} iterations of {task}, "
        f"qdil {qdil.__version__}, {os.cpu_count()} CPUs, wall {wall:.0f} s, "
        f"{args.clock} clock"
    )
    print("| component | seconds per iteration | share |\n|---|---|---|")
    for label in SECTIONS:
        print(
            f"| {label} | {seconds[label] / args.iterations:.2f} "
            f"| {100 * seconds[label] / total:.1f} % |"
        )
    other = total - sum(seconds[label] for label in SECTIONS)
    print(f"| other | {other / args.iterations:.2f} | {100 * other / total:.1f} % |")
    print(f"| **iteration** | **{total / args.iterations:.2f}** | 100 % |")
    rate = steps / total
    print(
        f"\nenv-steps/s over whole iterations: {rate:,.0f}; bare stepping of {task} with "
        f"{num_envs} envs (random actions): {bare:,.0f}; ratio {rate / bare:.2f}"
    )
    sys.stdout.flush()


if __name__ == "__main__":
    main()
